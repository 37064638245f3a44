//! The error type of `visnav-io`.

use std::path::PathBuf;

/// Everything that can go wrong while reading or writing visnav's inputs and outputs.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The file or directory could not be read or written.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A required file or directory does not exist.
    #[error("{path}: not found ({what})")]
    NotFound { path: PathBuf, what: String },
    /// A text file has a line that does not parse.
    #[error("{path}:{line}: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// A binary or image file is malformed.
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    /// An image could not be decoded.
    #[error("{path}: cannot decode image: {message}")]
    Image { path: PathBuf, message: String },
    /// An image has a different size from the rest of its sequence.
    #[error(
        "{path}: image is {got_w}x{got_h}, expected {expected_w}x{expected_h} like the rest of the sequence"
    )]
    SizeMismatch {
        path: PathBuf,
        expected_w: usize,
        expected_h: usize,
        got_w: usize,
        got_h: usize,
    },
    /// A sequence has no frames.
    #[error("{path}: sequence has no frames")]
    EmptySequence { path: PathBuf },
}

impl IoError {
    /// Wraps a `std::io::Error` with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        let path = path.into();
        if source.kind() == std::io::ErrorKind::NotFound {
            // a dangling symlink or a symlink loop exists as a link: "not found" would mislead
            let what = if std::fs::symlink_metadata(&path).is_ok() {
                "a symbolic link that does not resolve (dangling or a loop)"
            } else {
                "no such file or directory"
            };
            return Self::NotFound {
                path,
                what: what.into(),
            };
        }
        let message = match source.kind() {
            std::io::ErrorKind::IsADirectory => Some("is a directory, expected a file"),
            std::io::ErrorKind::NotADirectory => Some("a component of the path is not a directory"),
            _ if is_symlink_loop(&source) => {
                Some("too many levels of symbolic links (a symlink loop)")
            }
            _ => None,
        };
        if let Some(message) = message {
            return Self::Format {
                path,
                message: message.into(),
            };
        }
        Self::Io { path, source }
    }
}

/// Whether an I/O error is ELOOP (`std::io::ErrorKind::FilesystemLoop` is not stable).
fn is_symlink_loop(e: &std::io::Error) -> bool {
    // ELOOP is 40 on Linux, 62 on macOS and the BSDs
    let eloop = if cfg!(target_os = "linux") { 40 } else { 62 };
    cfg!(unix) && e.raw_os_error() == Some(eloop)
}

/// Result alias of this crate.
pub type Result<T, E = IoError> = std::result::Result<T, E>;
