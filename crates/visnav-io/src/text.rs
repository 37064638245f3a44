//! Reading text files for parsers: [`read_text`] is the one way every text parser of visnav
//! reads its file (calibration, timestamps, trajectories, camera files, lists, reports).

use std::path::Path;

use crate::error::{IoError, Result};

/// Largest text file the parsers read, bytes: calibration, timestamp and trajectory files are
/// far smaller (a 100,000-pose KITTI trajectory is about 15 MB), and a bound keeps a wrong path
/// (a video, a disk image) from being read whole into memory.
pub const MAX_TEXT_BYTES: u64 = 1 << 30;

/// Whether anything is at `path`: a file, a directory, or a symbolic link, also one that does
/// not resolve (a loop or a dangling link). Readers probe their optional files (`times.txt`, a
/// folder's `camera.yaml`) with it, so that a link that does not resolve is read, and named as
/// such by [`IoError::io`], instead of being taken for a missing file (issue 53).
#[must_use]
pub fn entry_exists(path: &Path) -> bool {
    path.symlink_metadata().is_ok()
}

/// Reads a text file for the parsers: a UTF-8 byte-order mark is dropped (Windows editors write
/// one, and it would otherwise glue itself to the first key or number), invalid UTF-8 is an
/// error naming the line, and a directory or an oversized file is an error naming the path.
/// CRLF line ends need nothing here: `str::lines` drops the `\r`.
///
/// # Errors
/// A missing or unreadable file, a directory, a file over [`MAX_TEXT_BYTES`], or bytes that are
/// not UTF-8.
pub fn read_text(path: &Path) -> Result<String> {
    let meta = std::fs::metadata(path).map_err(|e| IoError::io(path, e))?;
    if meta.is_dir() {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: "is a directory, expected a text file".into(),
        });
    }
    if meta.len() > MAX_TEXT_BYTES {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!(
                "{} bytes is too large for a text file (limit {MAX_TEXT_BYTES})",
                meta.len()
            ),
        });
    }
    let mut bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    if bytes.starts_with(b"\xEF\xBB\xBF") {
        bytes.drain(..3);
    }
    String::from_utf8(bytes).map_err(|e| {
        let good = &e.as_bytes()[..e.utf8_error().valid_up_to()];
        let line = good.iter().filter(|&&b| b == b'\n').count() + 1;
        IoError::Parse {
            path: path.to_path_buf(),
            line,
            message: "not UTF-8 text (a binary file?)".into(),
        }
    })
}
