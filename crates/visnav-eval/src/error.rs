//! The error type of `visnav-eval`.

use std::path::PathBuf;

/// Everything that can go wrong while scoring a trajectory or drawing its plots.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A configuration value is out of range.
    #[error("invalid evaluation config: {field} = {value} ({expected})")]
    InvalidConfig {
        /// The offending field.
        field: &'static str,
        /// Its value, printed.
        value: String,
        /// What is expected instead.
        expected: &'static str,
    },
    /// Estimate and ground truth differ in length and `strict` is set.
    #[error(
        "sequence {sequence}: the estimate has {estimate} poses but the ground truth has {ground_truth} (strict mode)"
    )]
    LengthMismatch {
        /// Index of the (ground truth, estimate) pair, from 0.
        sequence: usize,
        /// Poses in the estimate.
        estimate: usize,
        /// Poses in the ground truth.
        ground_truth: usize,
    },
    /// Nothing to score: an empty trajectory or no matching timestamps.
    #[error("sequence {sequence}: {message}")]
    NothingToScore {
        /// Index of the (ground truth, estimate) pair, from 0.
        sequence: usize,
        /// What is missing.
        message: String,
    },
    /// A pose cannot be scored: not finite, a rotation block that is no rotation, or a position
    /// so far away that its squares overflow.
    #[error("sequence {sequence}: {which} pose {index}: {message}")]
    InvalidPose {
        /// Index of the (ground truth, estimate) pair, from 0.
        sequence: usize,
        /// `ground truth` or `estimate`.
        which: &'static str,
        /// Index of the pose in its trajectory, from 0.
        index: usize,
        /// What is wrong.
        message: String,
    },
    /// A score came out infinite or NaN (never printed as a number).
    #[error("{what} is {value}: the inputs overflow the computation")]
    NonFinite {
        /// The figure.
        what: &'static str,
        /// Its value.
        value: f64,
    },
    /// A plot could not be drawn or written.
    #[error("{path}: cannot draw plot: {message}")]
    Plot {
        /// The output file.
        path: PathBuf,
        /// The backend's message.
        message: String,
    },
}

/// Result alias of this crate.
pub type Result<T, E = EvalError> = std::result::Result<T, E>;
