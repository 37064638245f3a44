//! Reading text files for parsers: [`read_text`] is the one way every text parser of visnav
//! reads its file (calibration, timestamps, trajectories, camera files, lists, reports);
//! `parse_3x4` the one way they read a row-major 3x4 matrix (a KITTI projection or pose).

use std::path::Path;

use nalgebra::Matrix3x4;

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

/// Parses twelve whitespace-separated numbers into a row-major 3x4 matrix.
pub(crate) fn parse_3x4(
    text: &str,
    path: &Path,
    line: usize,
    what: &str,
) -> Result<Matrix3x4<f64>> {
    let vals: Vec<f64> = text
        .split_whitespace()
        .map(|t| {
            t.parse::<f64>().map_err(|_| IoError::Parse {
                path: path.to_path_buf(),
                line,
                message: format!("{what}: '{t}' is not a number"),
            })
        })
        .collect::<Result<_>>()?;
    if vals.len() != 12 {
        return Err(IoError::Parse {
            path: path.to_path_buf(),
            line,
            message: format!(
                "{what}: expected 12 numbers (a row-major 3x4 matrix), found {}",
                vals.len()
            ),
        });
    }
    if vals.iter().any(|v| !v.is_finite()) {
        return Err(IoError::Parse {
            path: path.to_path_buf(),
            line,
            message: format!("{what}: non-finite value"),
        });
    }
    Ok(Matrix3x4::from_row_slice(&vals))
}
