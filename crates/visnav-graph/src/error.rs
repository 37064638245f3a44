//! The error type of visnav-graph.

use std::path::PathBuf;

/// Errors of pose-graph I/O and optimisation.
#[derive(Debug, thiserror::Error)]
pub enum GraphError {
    /// A g2o file could not be read or written, or a line of it is malformed (file and line
    /// named by `visnav_io::g2o`).
    #[error(transparent)]
    File(#[from] visnav_io::IoError),
    /// An edge of a g2o file cannot be used (file and line named).
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file (`<memory>` for strings).
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
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
    /// An edge's information matrix is indefinite (a clearly negative eigenvalue: the objective
    /// would be indefinite and χ² could go negative). [`crate::read_g2o`] projects such matrices; graphs
    /// built in memory get this error from [`crate::solve`].
    #[error(
        "edge {edge} ({from_id} -> {to_id}): the information matrix is indefinite (project it, e.g. with visnav_graph::g2o::project_information)"
    )]
    IndefiniteInformation {
        /// Index of the edge.
        edge: usize,
        /// Vertex id of its first end.
        from_id: u64,
        /// Vertex id of its second end.
        to_id: u64,
    },
    /// An edge's information matrix has no SE-Sync weights (a diagonal block without inverse or
    /// with a non-positive inverse trace): SE-Sync's problem, and its certificate, are undefined.
    #[error(
        "edge {edge} ({from_id} -> {to_id}): no SE-Sync weights (tau = 3/tr(inverse translation information), kappa = 3/(2 tr(inverse rotation information)) must be positive and finite)"
    )]
    NoSeSyncWeights {
        /// Index of the edge.
        edge: usize,
        /// Vertex id of its first end.
        from_id: u64,
        /// Vertex id of its second end.
        to_id: u64,
    },
    /// An edge or a vertex of a graph built in memory lies outside the numeric range of the
    /// solver's `f64` arithmetic ([`crate::numeric`]); a file's gets [`GraphError::Parse`] with
    /// its line.
    #[error("{what}: {message}")]
    NumericRange {
        /// The edge (`edge K (A -> B)`) or vertex (`vertex id A`).
        what: String,
        /// What is out of range.
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
