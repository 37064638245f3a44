//! Outputs that survive interruption.
//!
//! * [`write_atomic`]: a file is written to a temporary file in the same directory, flushed to
//!   disk, then renamed over the target, so a reader (or a crash at any instant) sees either the
//!   previous complete file or the new complete file, never a truncated one.
//! * [`check_writable`]: whether an output can be written, asked before a long run.
//!
//! The per-frame pose journal of a running odometry is [`crate::journal`] (it writes KITTI
//! lines, so it sits above [`crate::trajectory`], which writes through this module).

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{IoError, Result};

/// The directory of `path` (`.` for a bare file name), created if missing.
pub(crate) fn parent_dir(path: &Path) -> Result<PathBuf> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    std::fs::create_dir_all(&dir).map_err(|e| IoError::io(&dir, e))?;
    Ok(dir)
}

/// The directory a file `path` is written into (created if missing); an error when `path` is a
/// directory itself or a read-only file.
///
/// A read-only file is refused (issue 53): the rename of an atomic write replaces a file
/// whatever its permissions (it needs only the directory's), so a result the user protected
/// with `chmod a-w` would be replaced in silence.
fn target_dir(path: &Path) -> Result<PathBuf> {
    if path.is_dir() {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: "is a directory, not a file to write".into(),
        });
    }
    if std::fs::metadata(path).is_ok_and(|m| m.permissions().readonly()) {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message:
                "is read-only: not replaced (make it writable with chmod u+w, or write elsewhere)"
                    .into(),
        });
    }
    parent_dir(path)
}

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, synced, then
/// renamed over `path` (creating parent directories).
///
/// # Errors
/// The directory cannot be created, or the temporary file cannot be written or renamed (the
/// error names `path`); `path` is then unchanged.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = target_dir(path)?;
    let mut builder = tempfile::Builder::new();
    builder.prefix(".visnav-").suffix(".tmp");
    // The mode of a file written in place: the replaced file's, or a new file's (0666 less the
    // umask, as `File::create` gives); a temporary file alone would be 0600, unreadable by the
    // group a cluster's results are shared with.
    #[cfg(unix)]
    builder.permissions(std::fs::metadata(path).map_or_else(
        |_| <std::fs::Permissions as std::os::unix::fs::PermissionsExt>::from_mode(0o666),
        |m| m.permissions(),
    ));
    let mut tmp = builder
        .tempfile_in(&dir)
        .map_err(|e| IoError::io(path, e))?;
    tmp.write_all(bytes).map_err(|e| IoError::io(path, e))?;
    tmp.as_file().sync_all().map_err(|e| IoError::io(path, e))?;
    tmp.persist(path).map_err(|e| IoError::io(path, e.error))?;
    Ok(())
}

/// Checks before a run that `path` can be written: its directory exists or can be created and
/// a file can be created there, and it is not a directory or a read-only file. Nothing is left
/// behind.
///
/// # Errors
/// The [`IoError`] naming `path` and the problem.
pub fn check_writable(path: &Path) -> Result<()> {
    let dir = target_dir(path)?;
    tempfile::Builder::new()
        .prefix(".visnav-check-")
        .tempfile_in(&dir)
        .map(drop)
        .map_err(|e| IoError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_atomic_write_replaces_the_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out/poses.txt");
        write_atomic(&p, b"first\n").unwrap();
        write_atomic(&p, b"second\n").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "second\n");
        let names: Vec<_> = std::fs::read_dir(p.parent().unwrap())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
    }

    #[test]
    fn writing_onto_a_directory_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let e = write_atomic(dir.path(), b"x").unwrap_err().to_string();
        assert!(e.contains("is a directory"), "{e}");
        assert!(check_writable(dir.path()).is_err());
        assert!(check_writable(&dir.path().join("a/b/poses.txt")).is_ok());
    }

    /// Issue 53: the rename of an atomic write replaced a read-only file in silence.
    #[cfg(unix)]
    #[test]
    fn a_written_file_has_the_mode_of_a_created_one_or_of_the_file_it_replaces() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        let created = dir.path().join("created.txt");
        std::fs::write(&created, b"x").unwrap();
        let p = dir.path().join("poses.txt");
        write_atomic(&p, b"1\n").unwrap();
        assert_eq!(
            mode(&p),
            mode(&created),
            "a new file: the umask's mode, not 0600"
        );
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o640)).unwrap();
        write_atomic(&p, b"2\n").unwrap();
        assert_eq!(mode(&p), 0o640, "a replaced file keeps its mode");
        assert_eq!(std::fs::read(&p).unwrap(), b"2\n");
    }

    #[test]
    fn a_read_only_file_is_not_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("poses.txt");
        std::fs::write(&p, "kept\n").unwrap();
        let mut perms = std::fs::metadata(&p).unwrap().permissions();
        perms.set_readonly(true);
        std::fs::set_permissions(&p, perms).unwrap();
        let e = write_atomic(&p, b"new\n").unwrap_err().to_string();
        assert!(e.contains("poses.txt") && e.contains("read-only"), "{e}");
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "kept\n");
        let e = check_writable(&p).unwrap_err().to_string();
        assert!(e.contains("poses.txt") && e.contains("read-only"), "{e}");
        // nothing left behind
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
