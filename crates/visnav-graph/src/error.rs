//! The error type of visnav-graph.

use std::path::PathBuf;

/// Errors of pose-graph I/O and optimisation.
#[derive(Debug, thiserror::Error)]
pub enum GraphError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A line of a g2o file is malformed.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file (`<memory>` for strings).
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What was expected.
        message: String,
    },
    /// An edge refers to a vertex id that no vertex line declares.
    #[error("{path}:{line}: edge refers to unknown vertex id {id}")]
    UnknownVertex {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The missing id.
        id: u64,
    },
    /// The graph has no vertex.
    #[error("the pose graph has no vertex")]
    Empty,
    /// Some vertex is not connected by edges to a fixed vertex: its pose is undetermined.
    #[error("vertex id {id} is not connected to a fixed vertex")]
    Disconnected {
        /// Id of an unconnected vertex.
        id: u64,
    },
    /// The normal equations could not be factorised (not positive definite).
    #[error("sparse Cholesky of the {stage} normal equations failed: {message}")]
    Factorisation {
        /// Which system (rotation, position, Levenberg–Marquardt).
        stage: &'static str,
        /// The solver's message.
        message: String,
    },
    /// A configuration field is out of range.
    #[error("invalid config field `{field}`: {message}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// What is wrong.
        message: String,
    },
}
