//! Image operations of visnav.
//!
//! * [`pyramid`]: Gaussian pyramids (factor 2, `[1 4 6 4 1]/16`).
//! * [`gradient`]: Sobel and Scharr gradients, intensity per pixel.
//! * [`corners`]: Shi–Tomasi corners with non-maximum suppression, bucketing and sub-pixel refinement.
//! * [`klt`]: pyramidal inverse-compositional Lucas–Kanade point tracking.
//! * [`ssim`]: structural similarity (Wang et al. 2004).
//! * [`align`]: the dominant integer shift between two images (a global motion prior).
//!
//! Images are [`visnav_core::GrayImage`] (`f32`, 0..255); positions are pixels `(u, v)` =
//! (column, row) with pixel centres at integers.

pub mod align;
pub mod corners;
pub mod gradient;
pub mod klt;
pub mod pyramid;
pub mod ssim;

pub use corners::{Corner, CornerConfig, detect_corners};
pub use gradient::{Gradients, scharr, sobel};
pub use klt::{KltConfig, KltTrack, TrackStatus, fronto_parallel_warp, track, track_warped};
pub use pyramid::Pyramid;

/// Errors of the image operations.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
pub enum ImageError {
    /// A configuration field is out of range.
    #[error("invalid config field `{field}`: {message}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// What is wrong.
        message: String,
    },
    /// Two images that must have the same size do not.
    #[error("image size mismatch: expected {expected_w}x{expected_h}, got {got_w}x{got_h}")]
    SizeMismatch {
        /// Expected width.
        expected_w: usize,
        /// Expected height.
        expected_h: usize,
        /// Actual width.
        got_w: usize,
        /// Actual height.
        got_h: usize,
    },
    /// Two inputs that must have the same length do not.
    #[error("{what}: expected {expected} entries, got {got}")]
    LengthMismatch {
        /// Which input.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        got: usize,
    },
}
