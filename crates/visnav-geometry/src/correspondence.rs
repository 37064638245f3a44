//! Pixel correspondences with the uncertainty of the second pixel.

use nalgebra::{Matrix2, Point2};

/// A match `p1_px ↔ p2_px` between two images, pixels.
///
/// Dense flow places `p1_px` exactly on a pixel centre, so only `p2_px` is uncertain; its
/// information matrix (inverse covariance, 1/px²) is `information` (symmetric positive definite).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correspondence {
    /// Pixel in the first image.
    pub p1_px: Point2<f64>,
    /// Matching pixel in the second image.
    pub p2_px: Point2<f64>,
    /// Information matrix `Y = P⁻¹` of `p2_px`, 1/px².
    pub information: Matrix2<f64>,
}

impl Correspondence {
    /// A correspondence with an isotropic information `1/σ²` (σ in pixels).
    #[must_use]
    pub fn isotropic(p1_px: Point2<f64>, p2_px: Point2<f64>, sigma_px: f64) -> Self {
        Self {
            p1_px,
            p2_px,
            information: Matrix2::identity() / (sigma_px * sigma_px),
        }
    }

    /// Certainty used for guided sampling: `sqrt(det Y)`, the inverse area of the 1-σ ellipse
    /// (up to π), in 1/px². Zero for non-positive-definite information.
    #[must_use]
    pub fn certainty(&self) -> f64 {
        let y = &self.information;
        let det = y[(0, 0)] * y[(1, 1)] - y[(0, 1)] * y[(1, 0)];
        if det > 0.0 && y[(0, 0)] > 0.0 {
            det.sqrt()
        } else {
            0.0
        }
    }
}
