//! The monocular pipeline's errors.

use super::trust::UntrustedReason;

/// Errors of the monocular pipeline (configuration, input sizes and frames it cannot trust;
/// degenerate geometry in a frame is a [`super::FrameStatus`], not an error).
#[derive(Debug, PartialEq, thiserror::Error)]
pub enum MonoError {
    /// A configuration field is out of range.
    #[error("invalid mono config: {field} = {value}, expected {expected}")]
    InvalidConfig {
        /// The field, e.g. `camera_height_m`.
        field: &'static str,
        /// The offending value.
        value: f64,
        /// What was expected.
        expected: &'static str,
    },
    /// A nested stage configuration is invalid.
    #[error("invalid mono config: {0}")]
    Geometry(#[from] visnav_geometry::GeometryError),
    /// The dense flow failed (invalid flow configuration, image sizes).
    #[error("dense flow: {0}")]
    Flow(#[from] visnav_flow::FlowError),
    /// The image or the flow does not have the camera's size.
    #[error("{what} is {got_w}x{got_h}, expected {expected_w}x{expected_h} (the camera size)")]
    SizeMismatch {
        /// `"image"` or `"flow"`.
        what: &'static str,
        /// Expected width (pixels).
        expected_w: usize,
        /// Expected height (pixels).
        expected_h: usize,
        /// Actual width.
        got_w: usize,
        /// Actual height.
        got_h: usize,
    },
    /// The frame failed a trust test ([`super::trust`]): it was not used and the odometry's state is
    /// unchanged. The documented fallback (the driver's): the constant-velocity prediction for
    /// this frame, and the next frame's flow from the last accepted image.
    #[error("untrusted frame: {reason}")]
    UntrustedFrame {
        /// The test that failed, with its measurement.
        reason: UntrustedReason,
    },
}

/// The error of the odometry's frame `frame` that failed a trust test, with its warning.
pub(crate) fn refused(frame: usize, reason: UntrustedReason) -> MonoError {
    log::warn!(
        "mono frame {frame}: untrusted, {reason}; not used (the driver gives it the constant-velocity prediction)"
    );
    MonoError::UntrustedFrame { reason }
}
