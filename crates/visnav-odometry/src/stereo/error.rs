//! The stereo pipeline's set-up errors.

/// Errors of the stereo pipeline set-up (per-frame problems are a [`super::FrameStatus`]).
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum StereoError {
    /// A configuration field is out of range.
    #[error("invalid stereo config field `{field}`: {message}")]
    InvalidConfig {
        /// The field (dotted path).
        field: String,
        /// What is wrong.
        message: String,
    },
}
