//! The 2x2 information matrix of a flow vector or pixel measurement (paper 000, eq. 1):
//! `Y = Σ⁻¹` in 1/px², symmetric, stored as `(Yxx, Yxy, Yyy)`.
//!
//! Arithmetic choices are explicit and follow the callers that existed before this type:
//! inversion, determinant and the eigenvalue projection compute in `f64` and store `f32`;
//! [`Information2::mahalanobis_sq`] computes in `f32` (the per-pixel hot path of the flow),
//! [`Information2::mahalanobis_sq_f64`] in `f64` (evaluation and geometry).

use nalgebra::Matrix2;
use serde::{Deserialize, Serialize};

/// Symmetric 2x2 information matrix `[[xx, xy], [xy, yy]]`, 1/px² (eq. 1's `Y`).
///
/// The same layout as the `(Yxx, Yxy, Yyy)` triples of `DenseFlow::information`:
/// [`Information2::from_array`] and [`Information2::to_array`] convert without arithmetic.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Information2 {
    /// `Yxx`, 1/px².
    pub xx: f32,
    /// `Yxy` (= `Yyx`), 1/px².
    pub xy: f32,
    /// `Yyy`, 1/px².
    pub yy: f32,
}

/// Inverse of the symmetric `(a, b, c)` = `[[a, b], [b, c]]` in `f64`; `None` if singular
/// (|det| ≤ 1e-30) or not finite.
#[inline]
fn invert_symmetric(m: [f32; 3]) -> Option<[f32; 3]> {
    let [a, b, c] = m.map(f64::from);
    let det = a * c - b * b;
    (det.abs() > 1e-30 && det.is_finite())
        .then(|| [(c / det) as f32, (-b / det) as f32, (a / det) as f32])
}

impl Information2 {
    /// From its three entries, 1/px².
    #[must_use]
    #[inline]
    pub const fn new(xx: f32, xy: f32, yy: f32) -> Self {
        Self { xx, xy, yy }
    }

    /// `1/σ² · I` for a standard deviation `sigma_px` in pixels.
    #[must_use]
    pub fn isotropic_from_sigma_px(sigma_px: f32) -> Self {
        let y = 1.0 / (sigma_px * sigma_px);
        Self::new(y, 0.0, y)
    }

    /// From `(Yxx, Yxy, Yyy)`.
    #[must_use]
    #[inline]
    pub const fn from_array(m: [f32; 3]) -> Self {
        Self::new(m[0], m[1], m[2])
    }

    /// As `(Yxx, Yxy, Yyy)`.
    #[must_use]
    #[inline]
    pub const fn to_array(self) -> [f32; 3] {
        [self.xx, self.xy, self.yy]
    }

    /// The information of the covariance `(Pxx, Pxy, Pyy)` in px² (its inverse, computed in
    /// `f64`); `None` if the covariance is singular or not finite.
    #[must_use]
    #[inline]
    pub fn from_covariance_px2(covariance_px2: [f32; 3]) -> Option<Self> {
        invert_symmetric(covariance_px2).map(Self::from_array)
    }

    /// The covariance `Σ = Y⁻¹` as `(Pxx, Pxy, Pyy)` in px² (computed in `f64`); `None` if the
    /// information is singular or not finite.
    #[must_use]
    pub fn covariance_px2(self) -> Option<[f32; 3]> {
        invert_symmetric(self.to_array())
    }

    /// `det Y = Yxx·Yyy − Yxy²` in `f64`, 1/px⁴.
    #[must_use]
    #[inline]
    pub fn determinant(self) -> f64 {
        let [a, b, c] = self.to_array().map(f64::from);
        a * c - b * b
    }

    /// Eigenvalues `(λ_max, λ_min)` in `f64`, 1/px² (NaN if an entry is NaN).
    #[must_use]
    pub fn eigenvalues(self) -> [f64; 2] {
        let [a, b, c] = self.to_array().map(f64::from);
        let mean = 0.5 * (a + c);
        let disc = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        [mean + disc, mean - disc]
    }

    /// Positive definite: `Yxx > 0` and `det Y > 0` (false for NaN entries).
    #[must_use]
    pub fn is_positive_definite(self) -> bool {
        self.xx > 0.0 && self.determinant() > 0.0
    }

    /// Certainty `sqrt(det Y)`, the inverse area of the 1-σ ellipse up to π, 1/px²; zero for a
    /// matrix that is not positive definite.
    #[must_use]
    pub fn certainty(self) -> f64 {
        if self.is_positive_definite() {
            self.determinant().sqrt()
        } else {
            0.0
        }
    }

    /// Projection onto the matrices with eigenvalues in `[lo, hi]` (1/px²), same eigenvectors,
    /// computed in `f64`; a non-finite eigenvalue becomes `lo`. With `lo > 0` the result is
    /// positive definite (§3.2: the information passed on is always positive definite).
    #[must_use]
    pub fn clamp_eigenvalues(self, lo: f32, hi: f32) -> Self {
        let [a, b, c] = self.to_array().map(f64::from);
        let [l1, l2] = self.eigenvalues();
        // eigenvector of l1
        let (vx, vy) = if b.abs() > 1e-12 {
            let (vx, vy) = (l1 - c, b);
            let n = vx.hypot(vy);
            (vx / n, vy / n)
        } else if a >= c {
            (1.0, 0.0)
        } else {
            (0.0, 1.0)
        };
        let (lo, hi) = (f64::from(lo), f64::from(hi));
        let e1 = if l1.is_finite() { l1.clamp(lo, hi) } else { lo };
        let e2 = if l2.is_finite() { l2.clamp(lo, hi) } else { lo };
        // Y = e1 v vᵀ + e2 w wᵀ with w = (-vy, vx)
        Self::new(
            (e1 * vx * vx + e2 * vy * vy) as f32,
            ((e1 - e2) * vx * vy) as f32,
            (e1 * vy * vy + e2 * vx * vx) as f32,
        )
    }

    /// Whether both eigenvalues lie in `[lo, hi]` (1/px²), decided without an eigen
    /// decomposition: `Y − lo·I` and `hi·I − Y` are both positive semi-definite (computed in
    /// `f64`; false for non-finite entries). Where it holds, [`Self::clamp_eigenvalues`] has
    /// nothing to clamp, so a caller may keep `Y` as it is and skip the decomposition.
    #[must_use]
    #[inline]
    pub fn eigenvalues_within(self, lo: f32, hi: f32) -> bool {
        let [a, b, c] = self.to_array().map(f64::from);
        let (lo, hi) = (f64::from(lo), f64::from(hi));
        let psd = |p: f64, q: f64| p >= 0.0 && q >= 0.0 && p * q >= b * b;
        a.is_finite()
            && b.is_finite()
            && c.is_finite()
            && psd(a - lo, c - lo)
            && psd(hi - a, hi - c)
    }

    /// Each entry times `k`.
    #[must_use]
    pub fn scaled(self, k: f32) -> Self {
        Self::new(self.xx * k, self.xy * k, self.yy * k)
    }

    /// Squared Mahalanobis norm `dᵀ Y d` (eq. 1) of `d = (du, dv)` px, in `f32` arithmetic.
    #[must_use]
    pub fn mahalanobis_sq(self, du: f32, dv: f32) -> f32 {
        self.xx * du * du + 2.0 * self.xy * du * dv + self.yy * dv * dv
    }

    /// Squared Mahalanobis norm `dᵀ Y d` (eq. 1) of `d = (du, dv)` px, in `f64` arithmetic.
    #[must_use]
    pub fn mahalanobis_sq_f64(self, du: f64, dv: f64) -> f64 {
        let [a, b, c] = self.to_array().map(f64::from);
        a * du * du + 2.0 * b * du * dv + c * dv * dv
    }

    /// As an `f64` matrix.
    #[must_use]
    pub fn to_matrix(self) -> Matrix2<f64> {
        let [a, b, c] = self.to_array().map(f64::from);
        Matrix2::new(a, b, b, c)
    }
}

impl From<[f32; 3]> for Information2 {
    fn from(m: [f32; 3]) -> Self {
        Self::from_array(m)
    }
}

impl From<Information2> for [f32; 3] {
    fn from(m: Information2) -> Self {
        m.to_array()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn covariance_is_the_matrix_inverse() {
        let y = Information2::new(3.0, 1.0, 2.0);
        let p = y.covariance_px2().unwrap();
        let prod = y.to_matrix() * Information2::from_array(p).to_matrix();
        assert!((prod - Matrix2::identity()).norm() < 1e-6, "{prod}");
        assert_eq!(y.determinant(), 5.0);
        let back = Information2::from_covariance_px2(p).unwrap();
        assert!((back.xx - 3.0).abs() < 1e-5 && (back.xy - 1.0).abs() < 1e-5);
        assert!(Information2::new(1.0, 1.0, 1.0).covariance_px2().is_none());
        assert!(
            Information2::new(f32::NAN, 0.0, 1.0)
                .covariance_px2()
                .is_none()
        );
    }

    #[test]
    fn positive_definiteness_and_certainty() {
        assert!(Information2::new(2.0, 0.5, 1.0).is_positive_definite());
        assert!(!Information2::new(1.0, 3.0, 1.0).is_positive_definite());
        assert!(!Information2::new(-1.0, 0.0, -1.0).is_positive_definite());
        assert!(!Information2::new(f32::NAN, 0.0, 1.0).is_positive_definite());
        assert_eq!(Information2::new(1.0, 3.0, 1.0).certainty(), 0.0);
        assert_eq!(Information2::new(4.0, 0.0, 9.0).certainty(), 6.0);
        assert_eq!(
            Information2::isotropic_from_sigma_px(0.5).to_array(),
            [4.0, 0.0, 4.0]
        );
    }

    #[test]
    fn clamping_keeps_pd_matrices_and_fixes_indefinite_ones() {
        let m = Information2::new(3.0, 1.0, 2.0);
        let c = m.clamp_eigenvalues(1e-3, 100.0);
        for (got, want) in c.to_array().iter().zip(m.to_array()) {
            assert!((got - want).abs() < 1e-5);
        }
        let bad = Information2::new(1.0, 3.0, 1.0).clamp_eigenvalues(0.5, 100.0);
        assert!(bad.is_positive_definite(), "{bad:?}");
        let [l1, l2] = bad.eigenvalues();
        assert!(
            (l1 - 4.0).abs() < 1e-5 && (l2 - 0.5).abs() < 1e-5,
            "{l1} {l2}"
        );
        let nan = Information2::new(f32::NAN, 0.0, 1.0).clamp_eigenvalues(0.5, 100.0);
        assert!(nan.is_positive_definite(), "{nan:?}");
    }

    #[test]
    fn mahalanobis_norms_agree_with_the_matrix_product() {
        let y = Information2::new(2.0, -0.5, 1.0);
        let d = nalgebra::Vector2::new(1.5, -2.0);
        let want = (d.transpose() * y.to_matrix() * d)[0];
        assert!((y.mahalanobis_sq_f64(1.5, -2.0) - want).abs() < 1e-12);
        assert!((f64::from(y.mahalanobis_sq(1.5, -2.0)) - want).abs() < 1e-5);
    }

    proptest! {
        #[test]
        fn eigenvalues_within_agrees_with_the_eigenvalues(
            a in -200_f32..200.0, b in -100_f32..100.0, c in -200_f32..200.0,
        ) {
            let m = Information2::new(a, b, c);
            let [l1, l2] = m.eigenvalues();
            let (lo, hi) = (0.01, 100.0);
            // away from the bounds (rounding decides exactly at them) the two tests agree
            let margin = 1e-6 * (l1.abs() + 1.0);
            if (l2 - lo).abs() > margin && (l1 - hi).abs() > margin {
                prop_assert_eq!(m.eigenvalues_within(lo as f32, hi as f32), l2 >= lo && l1 <= hi);
            }
        }
    }

    proptest! {
        #[test]
        fn clamped_eigenvalues_stay_in_range(
            a in -1e3_f32..1e3, b in -1e3_f32..1e3, c in -1e3_f32..1e3,
        ) {
            let m = Information2::new(a, b, c).clamp_eigenvalues(0.01, 100.0);
            let [l1, l2] = m.eigenvalues();
            prop_assert!(m.is_positive_definite(), "{m:?}");
            // storing in f32 moves an eigenvalue by at most a few ulps of the largest one
            let ulps = 4.0 * 100.0 * f64::from(f32::EPSILON);
            prop_assert!(l1 <= 100.0 + ulps && l2 >= 0.01 - ulps, "{l1} {l2}");
            prop_assert_eq!(Information2::from_array(m.to_array()), m);
        }
    }
}
