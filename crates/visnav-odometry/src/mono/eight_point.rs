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
    use nalgebra::Point2;
    use visnav_geometry::seeded_rng;

    /// Pure sideways translation: `F = [t]ₓ` in pixels with `t = (1, 0, 0)`, epipolar lines are
    /// the rows `y2 = y1`.
    fn sideways() -> Matrix3<f64> {
        Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0)
    }

    /// Projection with `f = 500 px`, principal point (320, 240).
    fn project(p: &nalgebra::Vector3<f64>) -> Point2<f64> {
        Point2::new(500.0 * p.x / p.z + 320.0, 500.0 * p.y / p.z + 240.0)
    }

    #[test]
    fn sampson_distance_of_a_row_offset() {
        let f = sideways();
        let c = Correspondence::isotropic(Point2::new(10.0, 20.0), Point2::new(15.0, 23.0), 1.0);
        // residual y1 - y2 = -3, gradient norm sqrt(1 + 1): Sampson distance 3 / sqrt(2)
        let d2 = sampson_distance_sq_px2(&f, &c);
        assert!((d2 - 4.5).abs() < 1e-12, "{d2}");
    }

    /// Uncertain gross outliers pass the Mahalanobis test (eq. 11) but not the Euclidean one.
    #[test]
    fn each_estimator_uses_its_own_inlier_test() {
        let rotation = nalgebra::Rotation3::from_euler_angles(0.01, -0.02, 0.005);
        let t = nalgebra::Vector3::new(0.3, -0.05, 1.0);
        let mut corrs = Vec::new();
        for i in 0..200 {
            // a generic (non-planar) scene in front of both cameras
            let p = nalgebra::Vector3::new(
                f64::from(i % 20) * 0.6 - 6.0,
                f64::from(i / 20) * 0.5 - 2.5,
                8.0 + f64::from((i * 37) % 23) * 0.9,
            );
            corrs.push(Correspondence::isotropic(
                project(&p),
                project(&(rotation * p + t)),
                0.5,
            ));
        }
        // gross outliers 40 px off their epipolar lines (which pass through the epipole, the
        // projection of t), all very uncertain (σ = 100 px)
        let epipole = project(&t);
        for i in 0..40 {
            let p = nalgebra::Vector3::new(f64::from(i) * 0.3 - 6.0, 0.5, 12.0);
            let p2 = project(&(rotation * p + t));
            let along = (p2 - epipole).normalize();
            let across = nalgebra::Vector2::new(-along.y, along.x);
            corrs.push(Correspondence::isotropic(
                project(&p),
                p2 + 40.0 * across,
                100.0,
            ));
        }
        let mut cfg = EightPointConfig::default();
        for estimator in [
            Estimator::Mahalanobis,
            Estimator::Sampson,
            Estimator::Algebraic,
        ] {
            cfg.estimator = estimator;
            let r = estimate_with_own_inlier_test(&corrs, &cfg, 1.0, &mut seeded_rng(3)).unwrap();
            let uncertain_outliers_in = r.inliers[200..].iter().filter(|&&v| v).count();
            let true_in = r.inliers[..200].iter().filter(|&&v| v).count();
            assert_eq!(true_in, 200, "{estimator:?}");
            if estimator == Estimator::Mahalanobis {
                // 40 px with σ = 100 px is well inside the χ²₁ threshold
                assert_eq!(uncertain_outliers_in, 40, "{estimator:?}");
            } else {
                assert_eq!(uncertain_outliers_in, 0, "{estimator:?}");
            }
        }
    }
}
