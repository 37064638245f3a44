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
        if source.kind() == std::io::ErrorKind::NotFound {
            return Self::NotFound {
                path: path.into(),
                what: "no such file or directory".into(),
            };
        }
        Self::Io {
            path: path.into(),
            source,
        }
    }
}

/// Result alias of this crate.
pub type Result<T, E = IoError> = std::result::Result<T, E>;
