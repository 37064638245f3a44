//! The eight-point stage of the monocular pipeline with each estimator's own inlier test
//! (Ng, Li, Kim 2021, §4 and the ablation of §6).
//!
//! * [`Estimator::Mahalanobis`] (the paper's method): RANSAC samples drawn with probability
//!   ∝ certainty, inliers by the squared Mahalanobis distance to the epipolar line (eq. 11),
//!   refit by the Mahalanobis-weighted eight-point (eq. 9–12) —
//!   [`visnav_geometry::estimate_fundamental`].
//! * [`Estimator::Sampson`] and [`Estimator::Algebraic`] do not use the flow's uncertainty, so
//!   neither does their RANSAC: uniform sampling and the *Euclidean* Sampson distance in pixels
//!   `d = |x2ᵀ F x1| / sqrt((F x1)₁² + (F x1)₂² + (Fᵀ x2)₁² + (Fᵀ x2)₂²)` (eq. 8's `φ` times the
//!   algebraic residual of eq. 6), normalised by an assumed isotropic flow noise `σ`
//!   (`sampson_inlier_sigma_px`), so the same χ²₁ threshold (3.84) applies: `d < 1.96 σ`. Then
//!   the refit by the Sampson-weighted (eq. 7–8) or plain (eq. 6) eight-point.

use nalgebra::Matrix3;
use visnav_geometry::fundamental::{
    EightPointConfig, Estimator, FundamentalProblem, FundamentalRansacResult, algebraic_residual,
    sampson_weight,
};
use visnav_geometry::{ChaCha8Rng, Correspondence, RansacProblem, estimate_fundamental, ransac};

/// Squared Sampson distance of a correspondence to `F`, px² (infinite when undefined).
#[must_use]
pub fn sampson_distance_sq_px2(f: &Matrix3<f64>, c: &Correspondence) -> f64 {
    let w = sampson_weight(f, c);
    if w <= 0.0 {
        return f64::INFINITY;
    }
    let d = algebraic_residual(f, c) * w;
    if d.is_finite() { d * d } else { f64::INFINITY }
}

/// RANSAC for `F` with the Sampson-distance inlier test (squared distance over `σ²`).
struct SampsonTestProblem {
    inner: FundamentalProblem,
    inv_sigma_sq_px2: f64,
}

impl RansacProblem for SampsonTestProblem {
    type Sample = Correspondence;
    type Model = Matrix3<f64>;
    const MIN_SAMPLES: usize = 8;

    fn fit_minimal(&self, samples: &[&Correspondence]) -> Vec<Matrix3<f64>> {
        self.inner.fit_minimal(samples)
    }

    fn residual_sq(&self, model: &Matrix3<f64>, sample: &Correspondence) -> f64 {
        sampson_distance_sq_px2(model, sample) * self.inv_sigma_sq_px2
    }

    fn refit(&self, inliers: &[&Correspondence], initial: &Matrix3<f64>) -> Option<Matrix3<f64>> {
        self.inner.refit(inliers, initial)
    }
}

/// RANSAC + eight-point with the inlier test natural to `config.estimator` (module docs);
/// `sampson_inlier_sigma_px` is the assumed flow noise of the Euclidean test, pixels.
pub fn estimate_with_own_inlier_test(
    corrs: &[Correspondence],
    config: &EightPointConfig,
    sampson_inlier_sigma_px: f64,
    rng: &mut ChaCha8Rng,
) -> Option<FundamentalRansacResult> {
    match config.estimator {
        Estimator::Mahalanobis => estimate_fundamental(corrs, config, rng),
        Estimator::Sampson | Estimator::Algebraic => {
            let problem = SampsonTestProblem {
                inner: FundamentalProblem {
                    estimator: config.estimator,
                    max_reweight_iterations: config.max_reweight_iterations,
                    convergence_tol: config.convergence_tol,
                },
                inv_sigma_sq_px2: 1.0 / (sampson_inlier_sigma_px * sampson_inlier_sigma_px),
            };
            ransac(&problem, corrs, None, &config.ransac, rng)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Point2};
    use visnav_geometry::seeded_rng;

    /// Pure sideways translation: `F = [t]ₓ` in pixels with `t = (1, 0, 0)`, epipolar lines are
    /// the rows `y2 = y1`.
    fn sideways() -> Matrix3<f64> {
        Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0)
    }

    #[test]
    fn sampson_distance_of_a_row_offset() {
        let f = sideways();
        let c = Correspondence::isotropic(Point2::new(10.0, 20.0), Point2::new(15.0, 23.0), 1.0);
        // residual y1 - y2 = -3, gradient norm sqrt(1 + 1): Sampson distance 3 / sqrt(2)
        let d2 = sampson_distance_sq_px2(&f, &c);
        assert!((d2 - 4.5).abs() < 1e-12, "{d2}");
    }

    /// A certain pixel 3 px off its epipolar line fails the Mahalanobis test but an uncertain one
    /// passes it; the Euclidean test treats both alike.
    #[test]
    fn each_estimator_uses_its_own_inlier_test() {
        let f = sideways();
        let mut corrs = Vec::new();
        for i in 0..200 {
            // disparity (inverse depth) varies: a generic, non-planar scene
            let x = f64::from(i % 20) * 30.0;
            let y = f64::from(i / 20) * 30.0 + 10.0;
            let disparity = 2.0 + f64::from((i * 37) % 23) * 0.7;
            corrs.push(Correspondence::isotropic(
                Point2::new(x, y),
                Point2::new(x + disparity, y),
                4.0,
            ));
        }
        // gross outliers far off their rows, half of them very uncertain
        for i in 0..40 {
            let x = f64::from(i) * 15.0;
            let info = if i % 2 == 0 { 1e-4 } else { 4.0 };
            corrs.push(Correspondence {
                p1_px: Point2::new(x, 50.0),
                p2_px: Point2::new(x + 5.0, 80.0),
                information: Matrix2::new(info, 0.0, 0.0, info),
            });
        }
        let mut cfg = EightPointConfig::default();
        for estimator in [
            Estimator::Mahalanobis,
            Estimator::Sampson,
            Estimator::Algebraic,
        ] {
            cfg.estimator = estimator;
            let r = estimate_with_own_inlier_test(&corrs, &cfg, 1.0, &mut seeded_rng(3)).unwrap();
            let uncertain_outliers_in = (200..240)
                .filter(|&i| (i - 200) % 2 == 0 && r.inliers[i])
                .count();
            if estimator == Estimator::Mahalanobis {
                // 30 px with sigma 100 px is well inside the χ² threshold
                assert_eq!(uncertain_outliers_in, 20, "{estimator:?}");
            } else {
                assert_eq!(uncertain_outliers_in, 0, "{estimator:?}");
            }
            assert!(r.inliers[..200].iter().all(|&v| v), "{estimator:?}");
        }
    }
}
