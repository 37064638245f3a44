//! One generic RANSAC over a small estimator trait.
//!
//! Minimal samples are drawn by multinomial resampling (as in particle filters, Ng et al. 2021 §4):
//! each datum is picked with probability proportional to its weight (e.g. the flow's certainty),
//! or uniformly when no weights are given. A datum is an inlier when its squared residual (in the
//! problem's units, e.g. a squared Mahalanobis distance) is at most `inlier_threshold`. The
//! iteration count adapts as `N = log(1 − p) / log(1 − wᵐ)` with `w` the best inlier fraction so
//! far and `m` the minimal sample size (the uniform-sampling formula; certainty-weighted sampling
//! draws inliers more often, so it is conservative). A hypothesis scores its inliers, minus the
//! data that contradict it when the problem says so ([`RansacProblem::contradicts`]). The best
//! hypothesis is refitted on its inliers, the inliers are recomputed and the refit repeated once.

use rand::{Rng, SeedableRng};
pub use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::{GeometryError, check};

/// A model-fitting problem for [`ransac`].
pub trait RansacProblem {
    /// One datum (a correspondence, a 3-D point, …).
    type Sample;
    /// The fitted model.
    type Model: Clone;
    /// Minimal sample size.
    const MIN_SAMPLES: usize;
    /// All models through a minimal sample (P3P has up to four); empty when degenerate.
    fn fit_minimal(&self, samples: &[&Self::Sample]) -> Vec<Self::Model>;
    /// Squared residual of a datum under a model, in the units of the inlier threshold.
    fn residual_sq(&self, model: &Self::Model, sample: &Self::Sample) -> f64;
    /// Refit on all inliers (the final, non-minimal estimate); `None` when degenerate.
    fn refit(&self, inliers: &[&Self::Sample], initial: &Self::Model) -> Option<Self::Model>;
    /// Whether a datum that is not an inlier contradicts the model (e.g. a point seen beyond
    /// a supporting plane); a hypothesis scores its inliers minus its contradictions. Default:
    /// none does, the score is the inlier count.
    fn contradicts(&self, _model: &Self::Model, _sample: &Self::Sample, _threshold: f64) -> bool {
        false
    }
}

/// RANSAC parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RansacConfig {
    /// Probability of drawing at least one all-inlier sample, in (0, 1). Default 0.999.
    pub confidence: f64,
    /// Inlier threshold on the squared residual (problem units). Default 3.84 = χ²(1 dof, 95 %),
    /// for squared Mahalanobis distances to epipolar lines (eq. 11).
    pub inlier_threshold: f64,
    /// Minimum number of iterations. Default 20.
    pub min_iterations: usize,
    /// Maximum number of iterations. Default 500.
    pub max_iterations: usize,
    /// Draw samples with probability proportional to the data's certainty. Default true.
    pub guided_sampling: bool,
}

impl Default for RansacConfig {
    fn default() -> Self {
        Self {
            confidence: 0.999,
            inlier_threshold: 3.84,
            min_iterations: 20,
            max_iterations: 500,
            guided_sampling: true,
        }
    }
}

impl RansacConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`GeometryError::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> Result<(), GeometryError> {
        check(
            self.confidence > 0.0 && self.confidence < 1.0,
            "ransac.confidence",
            self.confidence,
            "in (0, 1)",
        )?;
        check(
            self.inlier_threshold > 0.0 && self.inlier_threshold.is_finite(),
            "ransac.inlier_threshold",
            self.inlier_threshold,
            "finite and > 0",
        )?;
        check(
            self.max_iterations >= 1 && self.min_iterations <= self.max_iterations,
            "ransac.max_iterations",
            self.max_iterations as f64,
            ">= 1 and >= min_iterations",
        )
    }
}

/// The seeded RNG used by visnav's estimators (ChaCha8), so callers need no `rand` dependency.
#[must_use]
pub fn seeded_rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Result of [`ransac`].
#[derive(Debug, Clone, PartialEq)]
pub struct RansacResult<M> {
    /// The refitted model.
    pub model: M,
    /// Inlier flag per datum (under the refitted model).
    pub inliers: Vec<bool>,
    /// Number of inliers.
    pub inlier_count: usize,
    /// Iterations run.
    pub iterations: usize,
}

/// Multinomial sampler: draws indices with probability proportional to the given weights.
struct Sampler {
    cumulative: Vec<f64>,
}

impl Sampler {
    fn new(weights: Option<&[f64]>, n: usize) -> Option<Self> {
        let mut cumulative = Vec::with_capacity(n);
        let mut acc = 0.0;
        for i in 0..n {
            let w = weights.map_or(1.0, |w| w[i]);
            acc += if w.is_finite() && w > 0.0 { w } else { 0.0 };
            cumulative.push(acc);
        }
        (acc > 0.0).then_some(Self { cumulative })
    }

    fn draw<R: Rng>(&self, rng: &mut R) -> usize {
        let total = self.cumulative.last().copied().unwrap_or(0.0);
        let u = rng.random::<f64>() * total;
        self.cumulative
            .partition_point(|&c| c <= u)
            .min(self.cumulative.len() - 1)
    }
}

/// Runs RANSAC on `data`; `weights` (one per datum, ≥ 0) guide the sampling when
/// `config.guided_sampling`. `None` when there are too few data or no hypothesis has enough inliers.
pub fn ransac<P: RansacProblem, R: Rng>(
    problem: &P,
    data: &[P::Sample],
    weights: Option<&[f64]>,
    config: &RansacConfig,
    rng: &mut R,
) -> Option<RansacResult<P::Model>> {
    let n = data.len();
    let m = P::MIN_SAMPLES;
    if n < m || weights.is_some_and(|w| w.len() != n) {
        return None;
    }
    let weights = if config.guided_sampling {
        weights
    } else {
        None
    };
    let sampler = Sampler::new(weights, n).or_else(|| Sampler::new(None, n))?;
    // (model, score, inliers)
    let mut best: Option<(P::Model, i64, usize)> = None;
    let mut needed = config.max_iterations;
    let mut iterations = 0;
    let mut sample_idx = Vec::with_capacity(m);
    let mut sample: Vec<&P::Sample> = Vec::with_capacity(m);
    while iterations < needed.max(config.min_iterations).min(config.max_iterations) {
        iterations += 1;
        sample_idx.clear();
        let mut attempts = 0;
        while sample_idx.len() < m && attempts < 50 * m {
            attempts += 1;
            let i = sampler.draw(rng);
            if !sample_idx.contains(&i) {
                sample_idx.push(i);
            }
        }
        while sample_idx.len() < m {
            // weights concentrated on very few data: fill uniformly
            let i = rng.random_range(0..n);
            if !sample_idx.contains(&i) {
                sample_idx.push(i);
            }
        }
        sample.clear();
        sample.extend(sample_idx.iter().map(|&i| &data[i]));
        for model in problem.fit_minimal(&sample) {
            let (count, contradicting) = data.iter().fold((0_usize, 0_usize), |(c, x), d| {
                if problem.residual_sq(&model, d) <= config.inlier_threshold {
                    (c + 1, x)
                } else if problem.contradicts(&model, d, config.inlier_threshold) {
                    (c, x + 1)
                } else {
                    (c, x)
                }
            });
            let score = count as i64 - contradicting as i64;
            if best.as_ref().is_none_or(|(_, s, _)| score > *s) {
                best = Some((model, score, count));
                let w = count as f64 / n as f64;
                let p_good = w.powi(m as i32);
                needed = if p_good >= 1.0 - 1e-12 {
                    0
                } else if p_good <= 1e-12 {
                    config.max_iterations
                } else {
                    let k = (1.0 - config.confidence).ln() / (1.0 - p_good).ln();
                    if k.is_finite() {
                        k.ceil().min(config.max_iterations as f64) as usize
                    } else {
                        config.max_iterations
                    }
                };
            }
        }
    }
    let (mut model, _, count) = best?;
    if count < m {
        return None;
    }
    for _ in 0..2 {
        let subset: Vec<&P::Sample> = data
            .iter()
            .filter(|d| problem.residual_sq(&model, d) <= config.inlier_threshold)
            .collect();
        if subset.len() < m {
            return None;
        }
        model = problem.refit(&subset, &model)?;
    }
    let inliers: Vec<bool> = data
        .iter()
        .map(|d| problem.residual_sq(&model, d) <= config.inlier_threshold)
        .collect();
    let inlier_count = inliers.iter().filter(|&&b| b).count();
    Some(RansacResult {
        model,
        inliers,
        inlier_count,
        iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 1-D location: the model is a number, samples are numbers.
    struct Mean;
    impl RansacProblem for Mean {
        type Sample = f64;
        type Model = f64;
        const MIN_SAMPLES: usize = 1;
        fn fit_minimal(&self, s: &[&f64]) -> Vec<f64> {
            vec![*s[0]]
        }
        fn residual_sq(&self, m: &f64, s: &f64) -> f64 {
            (m - s) * (m - s)
        }
        fn refit(&self, s: &[&f64], _: &f64) -> Option<f64> {
            Some(s.iter().copied().sum::<f64>() / s.len() as f64)
        }
    }

    #[test]
    fn finds_the_majority_and_is_seeded() {
        let mut data: Vec<f64> = (0..60).map(|i| 5.0 + 0.01 * f64::from(i % 7)).collect();
        data.extend((0..40).map(|i| 100.0 + 10.0 * f64::from(i)));
        let cfg = RansacConfig {
            inlier_threshold: 0.01,
            ..RansacConfig::default()
        };
        let a = ransac(&Mean, &data, None, &cfg, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        let b = ransac(&Mean, &data, None, &cfg, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.inlier_count, 60);
        assert!((a.model - 5.03).abs() < 0.02);
    }

    #[test]
    fn weights_steer_the_sampler() {
        let s = Sampler::new(Some(&[0.0, 0.0, 1.0, 0.0]), 4).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        assert!((0..100).all(|_| s.draw(&mut rng) == 2));
        assert!(Sampler::new(Some(&[0.0, 0.0]), 2).is_none());
        assert!(RansacConfig::default().validate().is_ok());
        let bad = RansacConfig {
            confidence: 1.0,
            ..RansacConfig::default()
        };
        assert!(bad.validate().is_err());
    }
}
