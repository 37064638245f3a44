//! Flow metrics: end-point error (EPE), Fl (share of outliers with error > 3 px and > 5 % of
//! the true flow, KITTI), the sparsification curve and its area to the oracle (AUSE, Ilg et al.
//! 2018), and the share of ground truth inside the 1- and 2-sigma ellipses of a bivariate
//! Gaussian uncertainty (expected 1 - e^-1/2 = 39.3 % and 1 - e^-2 = 86.5 % when calibrated).
//!
//! Inputs are per-pixel records of pixels with known ground truth; units are pixels.

use serde::{Deserialize, Serialize};

/// One evaluated pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlowPixel {
    /// Estimated minus true flow `(du, dv)`, px.
    pub error_px: [f32; 2],
    /// Magnitude of the true flow, px.
    pub gt_magnitude_px: f32,
    /// Information matrix `(Yxx, Yxy, Yyy)` of the estimate, 1/px² (positive definite).
    pub information: [f32; 3],
}

/// The sparsification curve: mean EPE of the pixels left after removing the given share of the
/// most uncertain ones (by the trace of the covariance), and the same with the oracle order
/// (by true EPE).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sparsification {
    /// Shares removed, 0 to 0.98 in steps of 0.02.
    pub removed: Vec<f64>,
    /// Mean EPE of the rest, removing by estimated uncertainty, px.
    pub by_uncertainty_px: Vec<f64>,
    /// Mean EPE of the rest, removing by true error (the oracle), px.
    pub oracle_px: Vec<f64>,
}

/// Flow accuracy and uncertainty quality over a set of pixels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FlowMetrics {
    /// Pixels evaluated.
    pub pixels: usize,
    /// Mean end-point error, px.
    pub mean_epe_px: f64,
    /// Share of pixels with error > 3 px and > 5 % of the true flow, percent.
    pub fl_percent: f64,
    /// Share of pixels whose error lies inside the 1-sigma ellipse (`d_M² ≤ 1`, eq. 1), percent.
    pub sigma1_percent: f64,
    /// Share inside the 2-sigma ellipse (`d_M² ≤ 4`), percent.
    pub sigma2_percent: f64,
    /// Mean EPE of the 50 % most certain pixels, px.
    pub epe_most_certain_half_px: f64,
    /// Area between the sparsification curve and the oracle (mean over the removed shares), px.
    pub ause_px: f64,
    /// `ause_px / mean_epe_px`.
    pub ause_over_epe: f64,
    /// The curves.
    pub sparsification: Sparsification,
}

impl FlowMetrics {
    /// Mean EPE of the 50 % most certain pixels over the mean EPE of all (0 when the EPE is 0).
    #[must_use]
    pub fn certain_half_over_all(&self) -> f64 {
        self.epe_most_certain_half_px / self.mean_epe_px.max(1e-12)
    }
}

/// End-point error of one pixel, px.
#[must_use]
pub fn epe(p: &FlowPixel) -> f64 {
    f64::from(p.error_px[0]).hypot(f64::from(p.error_px[1]))
}

/// Squared Mahalanobis distance of the error under the information matrix (eq. 1).
#[must_use]
pub fn mahalanobis_sq(p: &FlowPixel) -> f64 {
    let [a, b, c] = p.information.map(f64::from);
    let [u, v] = p.error_px.map(f64::from);
    a * u * u + 2.0 * b * u * v + c * v * v
}

/// Trace of the covariance (inverse of the information), px²; infinite when singular.
#[must_use]
pub fn covariance_trace(p: &FlowPixel) -> f64 {
    let [a, b, c] = p.information.map(f64::from);
    let det = a * c - b * b;
    if det > 0.0 {
        (a + c) / det
    } else {
        f64::INFINITY
    }
}

/// Mean of the first `k` of `sorted` for every removed share, via a prefix sum.
fn curve(sorted_epe: &[f64], removed: &[f64]) -> Vec<f64> {
    let n = sorted_epe.len();
    let mut prefix = Vec::with_capacity(n + 1);
    prefix.push(0.0);
    for e in sorted_epe {
        prefix.push(prefix[prefix.len() - 1] + e);
    }
    removed
        .iter()
        .map(|r| {
            let keep = (((1.0 - r) * n as f64).round() as usize).clamp(1, n);
            prefix[keep] / keep as f64
        })
        .collect()
}

/// The share of `pixels`, in percent, whose error lies inside the `k`-sigma ellipse
/// (`d_M² ≤ k²`, eq. 1) for each `k` of `ks`: the coverage curve of the uncertainty. A
/// calibrated bivariate Gaussian gives `100 (1 − exp(−k²/2))` ([`gaussian_coverage_percent`]).
/// Empty `pixels` give zeros.
#[must_use]
pub fn coverage_percent(pixels: &[FlowPixel], ks: &[f64]) -> Vec<f64> {
    let mut d2: Vec<f64> = pixels.iter().map(mahalanobis_sq).collect();
    d2.sort_by(f64::total_cmp);
    let n = d2.len().max(1) as f64;
    ks.iter()
        .map(|k| 100.0 * d2.partition_point(|v| *v <= k * k) as f64 / n)
        .collect()
}

/// The coverage of the `k`-sigma ellipse under a bivariate Gaussian, percent: `100 (1 − exp(−k²/2))`.
#[must_use]
pub fn gaussian_coverage_percent(k: f64) -> f64 {
    100.0 * (1.0 - (-0.5 * k * k).exp())
}

/// All metrics over `pixels`; `None` when empty.
#[must_use]
pub fn evaluate(pixels: &[FlowPixel]) -> Option<FlowMetrics> {
    let n = pixels.len();
    if n == 0 {
        return None;
    }
    let epes: Vec<f64> = pixels.iter().map(epe).collect();
    let mean_epe_px = epes.iter().sum::<f64>() / n as f64;
    let outliers = pixels
        .iter()
        .zip(&epes)
        .filter(|(p, e)| **e > 3.0 && **e > 0.05 * f64::from(p.gt_magnitude_px))
        .count();
    let d2: Vec<f64> = pixels.iter().map(mahalanobis_sq).collect();
    let share = |t: f64| 100.0 * d2.iter().filter(|d| **d <= t).count() as f64 / n as f64;
    let removed: Vec<f64> = (0..50).map(|k| f64::from(k) * 0.02).collect();
    // most certain first
    let mut order: Vec<usize> = (0..n).collect();
    let unc: Vec<f64> = pixels.iter().map(covariance_trace).collect();
    order.sort_by(|a, b| unc[*a].total_cmp(&unc[*b]));
    let by_unc: Vec<f64> = order.iter().map(|i| epes[*i]).collect();
    let mut oracle = epes.clone();
    oracle.sort_by(f64::total_cmp);
    let by_uncertainty_px = curve(&by_unc, &removed);
    let oracle_px = curve(&oracle, &removed);
    let ause_px = by_uncertainty_px
        .iter()
        .zip(&oracle_px)
        .map(|(a, b)| a - b)
        .sum::<f64>()
        / removed.len() as f64;
    let half = curve(&by_unc, &[0.5])[0];
    Some(FlowMetrics {
        pixels: n,
        mean_epe_px,
        fl_percent: 100.0 * outliers as f64 / n as f64,
        sigma1_percent: share(1.0),
        sigma2_percent: share(4.0),
        epe_most_certain_half_px: half,
        ause_px,
        ause_over_epe: if mean_epe_px > 0.0 {
            ause_px / mean_epe_px
        } else {
            0.0
        },
        sparsification: Sparsification {
            removed,
            by_uncertainty_px,
            oracle_px,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Standard normal sample (Box–Muller).
    fn normal(rng: &mut ChaCha8Rng) -> f64 {
        let u1: f64 = rng.random_range(1e-12..1.0);
        let u2: f64 = rng.random_range(0.0..1.0);
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    #[test]
    fn calibrated_gaussian_errors_give_expected_coverage_and_zero_ause_for_perfect_ranking() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        // sigma varies per pixel: sigma_i; information 1/sigma²
        let pixels: Vec<FlowPixel> = (0..20_000)
            .map(|i| {
                let sigma = 0.2 + (i % 10) as f32 * 0.3;
                let u = normal(&mut rng) as f32 * sigma;
                let v = normal(&mut rng) as f32 * sigma;
                let inf = 1.0 / (sigma * sigma);
                FlowPixel {
                    error_px: [u, v],
                    gt_magnitude_px: 10.0,
                    information: [inf, 0.0, inf],
                }
            })
            .collect();
        let m = evaluate(&pixels).unwrap();
        assert!(
            (m.sigma1_percent - 39.3).abs() < 1.5,
            "{}",
            m.sigma1_percent
        );
        assert!(
            (m.sigma2_percent - 86.5).abs() < 1.5,
            "{}",
            m.sigma2_percent
        );
        assert!(m.epe_most_certain_half_px < 0.6 * m.mean_epe_px);
        assert!(m.ause_px >= 0.0 && m.ause_over_epe < 0.5);
        assert!((m.sparsification.by_uncertainty_px[0] - m.mean_epe_px).abs() < 1e-9);
    }

    #[test]
    fn coverage_curve_matches_the_shares_and_the_gaussian() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let pixels: Vec<FlowPixel> = (0..40_000)
            .map(|_| {
                let (sx, sy) = (0.5_f64, 2.0_f64);
                FlowPixel {
                    error_px: [
                        (normal(&mut rng) * sx) as f32,
                        (normal(&mut rng) * sy) as f32,
                    ],
                    gt_magnitude_px: 5.0,
                    information: [(1.0 / (sx * sx)) as f32, 0.0, (1.0 / (sy * sy)) as f32],
                }
            })
            .collect();
        let ks = [0.0, 1.0, 2.0, 3.0];
        let c = coverage_percent(&pixels, &ks);
        let m = evaluate(&pixels).unwrap();
        assert!((c[1] - m.sigma1_percent).abs() < 1e-9);
        assert!((c[2] - m.sigma2_percent).abs() < 1e-9);
        for (k, got) in ks.iter().zip(&c) {
            let want = gaussian_coverage_percent(*k);
            assert!((got - want).abs() < 1.0, "k {k}: {got} vs {want}");
        }
        assert!(c.windows(2).all(|w| w[0] <= w[1]));
        // errors twice as large as the ellipses say: the curve falls well below the Gaussian
        let wide: Vec<FlowPixel> = pixels
            .iter()
            .map(|p| FlowPixel {
                error_px: p.error_px.map(|e| 2.0 * e),
                ..*p
            })
            .collect();
        let c2 = coverage_percent(&wide, &[2.0]);
        assert!(
            (c2[0] - gaussian_coverage_percent(1.0)).abs() < 1.0,
            "{c2:?}"
        );
        assert_eq!(coverage_percent(&[], &[1.0]), vec![0.0]);
    }

    #[test]
    fn epe_and_fl_on_known_errors() {
        let mk = |e: f32, mag: f32| FlowPixel {
            error_px: [e, 0.0],
            gt_magnitude_px: mag,
            information: [1.0, 0.0, 1.0],
        };
        // 4 px error on 10 px flow: outlier; 4 px on 100 px flow: not (< 5 %); 1 px: not
        let m = evaluate(&[mk(4.0, 10.0), mk(4.0, 100.0), mk(1.0, 1.0), mk(0.0, 1.0)]).unwrap();
        assert!((m.mean_epe_px - 2.25).abs() < 1e-9);
        assert!((m.fl_percent - 25.0).abs() < 1e-9);
        assert!((m.sigma1_percent - 50.0).abs() < 1e-9);
        // oracle ranks perfectly, uncertainty is flat: the AUSE is non-negative
        assert!(m.ause_px >= 0.0);
        assert!(evaluate(&[]).is_none());
    }
}
