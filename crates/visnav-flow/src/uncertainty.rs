//! Turning the fitted cost curvature (eq. 1–4) into a calibrated, positive definite information
//! matrix, and carrying it to full resolution: information → covariance, bilinear resize,
//! multiplication by the squared scale, inversion (§3.2).

use crate::config::UncertaintyConfig;
use crate::ops::sample_field;
use visnav_core::Information2;

/// The covariance (px²) of an information matrix `(Yxx, Yxy, Yyy)`, or `fallback` if singular.
#[inline]
fn covariance_or(information: [f32; 3], fallback: [f32; 3]) -> [f32; 3] {
    Information2::from_array(information)
        .covariance_px2()
        .unwrap_or(fallback)
}

/// The information of a covariance `(Pxx, Pxy, Pyy)` (px²), or `fallback` if singular,
/// projected onto the eigenvalue range `[lo, hi]` (positive definite, §3.2).
#[inline]
fn clamped_information(covariance_px2: [f32; 3], fallback: [f32; 3], lo: f32, hi: f32) -> [f32; 3] {
    Information2::from_covariance_px2(covariance_px2)
        .unwrap_or(Information2::from_array(fallback))
        .clamp_eigenvalues(lo, hi)
        .to_array()
}

/// Calibrated, positive definite information at the matching level (1/level px²) from the raw
/// fit (cost units per level px²); pixels where `keep` is false get the largest covariance
/// found among kept pixels (the maximum uncertainty, §3.2), as an isotropic matrix.
/// `extra_variance` (level px², per pixel) is added isotropically to the fitted covariance
/// before calibration (variance the cost slice cannot see).
#[must_use]
pub fn calibrate(
    raw: &[[f32; 3]],
    extra_variance: &[f32],
    keep: &[bool],
    scale: f32,
    cfg: &UncertaintyConfig,
) -> Vec<[f32; 3]> {
    let s2 = scale * scale;
    let lo = cfg.min_information * s2;
    let hi = cfg.max_information * s2;
    let mut info: Vec<[f32; 3]> = raw
        .iter()
        .zip(extra_variance.iter().chain(std::iter::repeat(&0.0)))
        .map(|(m, extra)| {
            // the raw fit in cost units: make it PD with generous bounds first
            let fitted = Information2::from_array(*m).clamp_eigenvalues(1e-3, 1e6);
            let cov = covariance_or(fitted.to_array(), [1e3, 0.0, 1e3]);
            let cov = [
                cov[0] + extra * cfg.extra_variance_weight,
                cov[1],
                cov[2] + extra * cfg.extra_variance_weight,
            ];
            Information2::from_covariance_px2(cov)
                .unwrap_or(Information2::new(1e-3, 0.0, 1e-3))
                .scaled(cfg.calibration)
                .clamp_eigenvalues(lo, hi)
                .to_array()
        })
        .collect();
    // smallest eigenvalue among kept pixels = largest variance
    let min_eig = info
        .iter()
        .zip(keep)
        .filter(|(_, k)| **k)
        .map(|(m, _)| {
            // in f32, as before the type existed
            let tr = 0.5 * (m[0] + m[2]);
            let disc = (0.25 * (m[0] - m[2]).powi(2) + m[1] * m[1]).sqrt();
            tr - disc
        })
        .fold(f32::INFINITY, f32::min);
    let worst = if min_eig.is_finite() {
        min_eig.max(lo)
    } else {
        lo
    };
    for (m, k) in info.iter_mut().zip(keep) {
        if !*k {
            *m = [worst, 0.0, worst];
        }
    }
    info
}

/// A validity mask to full resolution: each full-resolution pixel takes the value of the nearest
/// level pixel (level pixel `i` at full-resolution coordinate `scale * i + offset`, as in
/// [`upsample_information`]).
#[must_use]
pub fn upsample_valid_nearest(
    valid: &[bool],
    lw: usize,
    lh: usize,
    w: usize,
    h: usize,
    scale: f32,
    offset: f32,
) -> Vec<bool> {
    (0..w * h)
        .map(|i| {
            let xl = (((i % w) as f32 - offset) / scale)
                .round()
                .clamp(0.0, (lw - 1) as f32) as usize;
            let yl = (((i / w) as f32 - offset) / scale)
                .round()
                .clamp(0.0, (lh - 1) as f32) as usize;
            valid[yl * lw + xl]
        })
        .collect()
}

/// To full resolution (§3.2): covariance, bilinear resize from the level grid (pixel `i` at
/// full-resolution coordinate `scale * i + offset`), times `scale²`, inverted, clamped to the
/// configured eigenvalue range so it stays positive definite.
#[must_use]
pub fn upsample_information(
    info: &[[f32; 3]],
    (lw, lh): (usize, usize),
    (w, h): (usize, usize),
    scale: f32,
    offset: f32,
    cfg: &UncertaintyConfig,
) -> Vec<[f32; 3]> {
    let cov: Vec<[f32; 3]> = info
        .iter()
        .map(|m| {
            covariance_or(
                *m,
                [1.0 / cfg.min_information, 0.0, 1.0 / cfg.min_information],
            )
        })
        .collect();
    // resample the three channels as two 2-channel fields
    let c01: Vec<[f32; 2]> = cov.iter().map(|c| [c[0], c[1]]).collect();
    let c2: Vec<[f32; 2]> = cov.iter().map(|c| [c[2], 0.0]).collect();
    let s2 = scale * scale;
    let mut out = vec![[0.0_f32; 3]; w * h];
    use rayon::prelude::*;
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let yc = (y as f32 - offset) / scale;
        for (x, o) in row.iter_mut().enumerate() {
            let xc = (x as f32 - offset) / scale;
            let a = sample_field(&c01, lw, lh, xc, yc);
            let b = sample_field(&c2, lw, lh, xc, yc);
            let cov_full = [a[0] * s2, a[1] * s2, b[0] * s2];
            *o = clamped_information(
                cov_full,
                [cfg.min_information, 0.0, cfg.min_information],
                cfg.min_information,
                cfg.max_information,
            );
        }
    });
    out
}

/// Per-pixel inputs of the full uncertainty model at full resolution: the calibrated cost-slice
/// fit (eq. 1–4) and the measurements of what that fit cannot see. Returned by
/// [`crate::FlowEstimator::compute_detailed`] for calibration and diagnostics.
#[derive(Debug, Clone, PartialEq)]
pub struct UncertaintyTerms {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Covariance `(Pxx, Pxy, Pyy)` of the calibrated cost-slice fit alone (§3.2), px².
    pub fit_covariance_px2: Vec<[f32; 3]>,
    /// Forward–backward discrepancy `|f(p) + b(p + f(p))|` at the matching level, in px
    /// (capped at [`FB_CAP_LEVEL_PX`] level px, also where `p + f(p)` leaves the image).
    pub fb_discrepancy_px: Vec<f32>,
    /// Geodesic distance to the kept match an interpolated pixel took its flow from, px
    /// (0 for kept pixels).
    pub fill_distance_px: Vec<f32>,
    /// Gradient-normalised brightness residual after refinement above twice the pair's median,
    /// `max(r̄ - 2 median(r̄), 0) / sqrt(ḡ² + floor²)`, px.
    pub normalised_residual_px: Vec<f32>,
    /// Standard deviation of the refined flow over a 5x5 window beyond what a locally linear
    /// flow explains (motion boundaries), px.
    pub flow_variation_px: Vec<f32>,
    /// Length of the refined flow, px.
    pub flow_magnitude_px: Vec<f32>,
    /// Share of matching-level pixels within 3 level px (7x7) that the forward–backward check
    /// removed (occlusions, disocclusions, motion boundaries), 0..1.
    pub removed_share: Vec<f32>,
    /// Distance between the refined flow and the matching result it started from, px.
    pub refinement_change_px: Vec<f32>,
    /// Texture: square root of the smallest eigenvalue of the 7x7 mean structure tensor of the
    /// refined image 1, intensity levels per px.
    pub texture: Vec<f32>,
    /// `1 - NCC` of image 1 and image 2 warped by the flow over 7x7, 0..2.
    pub ncc_dissimilarity: Vec<f32>,
    /// As `flow_variation_px` over 11x11, px.
    pub flow_variation_wide_px: Vec<f32>,
    /// Forward–backward discrepancy of the *refined* full-resolution flows,
    /// `|f(p) + b(p + f(p))|` in px, capped at [`FB_CAP_FULL_PX`] (also where `p + f(p)` leaves
    /// the image). Where no refined backward flow was computed (the model off), the
    /// matching-level discrepancy `fb_discrepancy_px` stands in.
    pub fb_full_px: Vec<f32>,
    /// Variance a second minimum of the regularised slice stands for, px²: `d² exp(-m / τ)` with
    /// `d` its distance to the winner and `m` its cost margin over the winner
    /// ([`crate::volume::second_minimum`], τ = [`UncertaintyConfig::ambiguity_cost_scale`]);
    /// large where the match is ambiguous (repeated texture).
    pub ambiguity_px2: Vec<f32>,
    /// Distance between the flow and a second refinement of the same matching result with a
    /// weaker smoothness term ([`UncertaintyConfig::sensitivity_alpha`]), px: how much of the
    /// flow the regulariser rather than the images decided. 0 where it was not computed.
    pub sensitivity_px: Vec<f32>,
    /// Mean of `ncc_dissimilarity` (clamped to 0..2) over the whole image: how unlike each other
    /// the two images look after warping *everywhere* (sensor noise against texture, blur,
    /// non-Lambertian surfaces, exposure), one value for the pair.
    pub image_ncc_dissimilarity: f32,
}

/// The covariance of the log-linear model at one pixel, px²: the fit's covariance `c` (its
/// orientation and axis ratio), blended towards a circle by `isotropy` (0: the fit's shape,
/// 1: a circle; [`crate::config::VarianceModel::shape_isotropy`]) and scaled so that half its
/// trace is the model's variance `v` px².
#[must_use]
pub fn model_covariance(c: [f32; 3], v: f32, isotropy: f32) -> [f32; 3] {
    let half_trace = (0.5 * (c[0] + c[2])).max(1e-12);
    let b = isotropy.clamp(0.0, 1.0);
    let k = (1.0 - b) * v / half_trace;
    [k * c[0] + b * v, k * c[1], k * c[2] + b * v]
}

/// Number of log-linear predictors ([`UncertaintyTerms::log_features`]), defined beside the
/// coefficients it counts.
pub use crate::config::LOG_FEATURES;

/// Cap of the forward–backward discrepancy, matching-level px.
pub const FB_CAP_LEVEL_PX: f32 = 10.0;

/// Cap of the full-resolution forward–backward discrepancy, px.
pub const FB_CAP_FULL_PX: f32 = 30.0;

impl UncertaintyTerms {
    /// Isotropic variance (px²) the model adds to the fitted covariance at pixel `i`:
    /// `k_fb fb² + k_fill d² + k_res r² + k_var s² + k_mag |f|² + k_0`.
    #[must_use]
    pub fn extra_variance_px2(&self, i: usize, cfg: &UncertaintyConfig) -> f32 {
        cfg.fb_variance_weight * self.fb_discrepancy_px[i].powi(2)
            + cfg.fill_variance_weight * self.fill_distance_px[i].powi(2)
            + cfg.normalised_residual_weight * self.normalised_residual_px[i].powi(2)
            + cfg.flow_variation_weight * self.flow_variation_px[i].powi(2)
            + cfg.flow_magnitude_weight * self.flow_magnitude_px[i].powi(2)
            + cfg.base_variance_px2
    }

    /// The log-linear predictors of [`crate::config::VarianceModel`] at pixel `i`, in the order
    /// of [`crate::config::VarianceModel::coefficients`] (without the constant).
    #[must_use]
    pub fn log_features(&self, i: usize) -> [f32; LOG_FEATURES] {
        let c = self.fit_covariance_px2[i];
        [
            (c[0] + c[2]).max(1e-6).ln(),
            (self.fb_discrepancy_px[i] + 0.1).ln(),
            (self.flow_magnitude_px[i] + 1.0).ln(),
            (self.texture[i] + 1.0).ln(),
            self.removed_share[i],
            (self.refinement_change_px[i] + 0.02).ln(),
            (self.flow_variation_px[i] + 0.05).ln(),
            (self.flow_variation_wide_px[i] + 0.05).ln(),
            (self.ncc_dissimilarity[i].clamp(0.0, 2.0) + 0.1).ln(),
            (self.fb_full_px[i] + 0.05).ln(),
            (self.ambiguity_px2[i] + 0.1).ln(),
            (self.sensitivity_px[i] + 0.05).ln(),
            (self.image_ncc_dissimilarity + 0.1).ln(),
        ]
    }

    /// Variance scale of the log-linear model at pixel `i`, px²: `exp(c + Σ θ_k φ_k)`.
    #[must_use]
    pub fn model_variance_px2(&self, i: usize, cfg: &UncertaintyConfig) -> f32 {
        let m = &cfg.variance_model;
        let th = m.coefficients();
        let s: f32 = self
            .log_features(i)
            .iter()
            .zip(&th)
            .map(|(f, t)| f * t)
            .sum();
        (m.log_scale + s).clamp(-30.0, 30.0).exp()
    }

    /// Whether any term of the model beyond the fit is switched on.
    #[must_use]
    pub fn model_enabled(cfg: &UncertaintyConfig) -> bool {
        cfg.variance_model.enabled
            || cfg.fb_variance_weight > 0.0
            || cfg.fill_variance_weight > 0.0
            || cfg.normalised_residual_weight > 0.0
            || cfg.flow_variation_weight > 0.0
            || cfg.flow_magnitude_weight > 0.0
            || cfg.base_variance_px2 > 0.0
    }

    /// The information matrix of the full model, 1/px²: the fitted covariance (with the
    /// log-linear model on: its shape, scaled to the model's variance, see
    /// [`crate::config::VarianceModel`]) plus the isotropic extra variance, inverted and clamped
    /// to the configured eigenvalue range (always positive definite).
    #[must_use]
    pub fn information(&self, cfg: &UncertaintyConfig) -> Vec<[f32; 3]> {
        use rayon::prelude::*;
        self.fit_covariance_px2
            .par_iter()
            .enumerate()
            .map(|(i, c)| {
                let c = if cfg.variance_model.enabled {
                    model_covariance(
                        *c,
                        self.model_variance_px2(i, cfg),
                        cfg.variance_model.shape_isotropy,
                    )
                } else {
                    *c
                };
                let extra = self.extra_variance_px2(i, cfg);
                clamped_information(
                    [c[0] + extra, c[1], c[2] + extra],
                    [cfg.min_information, 0.0, cfg.min_information],
                    cfg.min_information,
                    cfg.max_information,
                )
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn is_pd(m: [f32; 3]) -> bool {
        Information2::from_array(m).is_positive_definite()
    }

    /// The inverse of a symmetric `(a, b, c)` (information ↔ covariance).
    fn invert(m: [f32; 3]) -> Option<[f32; 3]> {
        Information2::from_array(m).covariance_px2()
    }

    #[test]
    fn upsampling_keeps_information_positive_definite() {
        let cfg = UncertaintyConfig::default();
        // strongly anisotropic and rotated neighbours, plus a near-singular one
        let info = vec![
            [100.0, 99.0, 100.0],
            [1.0, -0.9, 1.0],
            [50.0, 0.0, 0.01],
            [0.01, 0.0, 0.01],
        ];
        let up = upsample_information(&info, (2, 2), (6, 6), 3.0, 1.0, &cfg);
        assert!(up.iter().all(|m| is_pd(*m)));
        // a constant field maps to info / 9
        let flat = vec![[9.0, 0.0, 9.0]; 4];
        let up = upsample_information(&flat, (2, 2), (6, 6), 3.0, 1.0, &cfg);
        assert!((up[14][0] - 1.0).abs() < 1e-4 && up[14][1].abs() < 1e-5);
    }

    #[test]
    fn log_linear_model_scales_the_fit_shape() {
        let terms = UncertaintyTerms {
            width: 2,
            height: 1,
            fit_covariance_px2: vec![[0.5, 0.1, 0.25], [0.02, -0.01, 0.08]],
            fb_discrepancy_px: vec![0.0, 3.0],
            fill_distance_px: vec![0.0, 2.0],
            normalised_residual_px: vec![0.0, 0.5],
            flow_variation_px: vec![0.0, 1.0],
            flow_magnitude_px: vec![2.0, 10.0],
            removed_share: vec![0.0, 0.5],
            refinement_change_px: vec![0.1, 0.5],
            texture: vec![10.0, 0.5],
            ncc_dissimilarity: vec![0.05, 0.8],
            flow_variation_wide_px: vec![0.1, 2.0],
            fb_full_px: vec![1.0, 4.0],
            ambiguity_px2: vec![0.9, 30.0],
            sensitivity_px: vec![0.02, 0.7],
            image_ncc_dissimilarity: 0.2,
        };
        let mut cfg = UncertaintyConfig::default();
        assert!(cfg.variance_model.enabled && UncertaintyTerms::model_enabled(&cfg));
        cfg.variance_model.log_scale = 3.0;
        cfg.variance_model.set_coefficients([
            0.1, 0.2, 0.3, -0.4, 1.5, 0.6, 0.7, 0.8, 0.9, 0.4, 0.3, 0.6, 0.5,
        ]);
        // no eigenvalue clamping in the way of the comparison
        cfg.max_information = 1e5;
        let info = terms.information(&cfg);
        for (i, m) in info.iter().enumerate() {
            let f = terms.log_features(i);
            let z: f32 = 3.0
                + f.iter()
                    .zip(cfg.variance_model.coefficients())
                    .map(|(a, b)| a * b)
                    .sum::<f32>();
            let v = z.exp();
            assert!((terms.model_variance_px2(i, &cfg) - v).abs() < 1e-4 * v);
            // the fit's shape blended a share `b` towards a circle, half trace `v`
            let c = terms.fit_covariance_px2[i];
            let b = cfg.variance_model.shape_isotropy;
            let k = (1.0 - b) * v / (0.5 * (c[0] + c[2]));
            let want = invert([k * c[0] + b * v, k * c[1], k * c[2] + b * v]).unwrap();
            for j in 0..3 {
                assert!(
                    (m[j] - want[j]).abs() < 1e-3 * want[j].abs().max(1.0),
                    "{m:?} {want:?}"
                );
            }
            assert!(is_pd(*m));
            // half the trace of the covariance is the model's variance
            let cov = invert(*m).unwrap();
            assert!((0.5 * (cov[0] + cov[2]) - v).abs() < 1e-3 * v);
        }
        // worse evidence, larger variance
        assert!(terms.model_variance_px2(1, &cfg) > terms.model_variance_px2(0, &cfg));
        // the blend's ends: the fit's own axis ratio, and a circle
        let ratio = |m: [f32; 3]| {
            let c = invert(m).unwrap();
            let disc = (0.25 * (c[0] - c[2]).powi(2) + c[1] * c[1]).sqrt();
            let ht = 0.5 * (c[0] + c[2]);
            (ht + disc) / (ht - disc)
        };
        cfg.variance_model.shape_isotropy = 0.0;
        let fit = terms.fit_covariance_px2[0];
        let r_fit = ratio(invert(fit).unwrap());
        assert!((ratio(terms.information(&cfg)[0]) - r_fit).abs() < 1e-3 * r_fit);
        cfg.variance_model.shape_isotropy = 1.0;
        assert!((ratio(terms.information(&cfg)[0]) - 1.0).abs() < 1e-4);
        // off: the fit alone
        cfg.variance_model.enabled = false;
        assert!(!UncertaintyTerms::model_enabled(&cfg));
    }

    #[test]
    fn model_adds_each_term_as_isotropic_variance() {
        let terms = UncertaintyTerms {
            width: 2,
            height: 1,
            fit_covariance_px2: vec![[0.5, 0.1, 0.25]; 2],
            fb_discrepancy_px: vec![0.0, 1.0],
            fill_distance_px: vec![0.0, 2.0],
            normalised_residual_px: vec![0.0, 0.5],
            flow_variation_px: vec![0.0, 3.0],
            flow_magnitude_px: vec![0.0, 10.0],
            removed_share: vec![0.0; 2],
            refinement_change_px: vec![0.0; 2],
            texture: vec![0.0; 2],
            ncc_dissimilarity: vec![0.0; 2],
            flow_variation_wide_px: vec![0.0; 2],
            fb_full_px: vec![0.0; 2],
            ambiguity_px2: vec![0.0; 2],
            sensitivity_px: vec![0.0; 2],
            image_ncc_dissimilarity: 0.0,
        };
        let cfg = UncertaintyConfig {
            variance_model: crate::config::VarianceModel::off(),
            fb_variance_weight: 1.0,
            fill_variance_weight: 0.5,
            normalised_residual_weight: 4.0,
            flow_variation_weight: 0.1,
            flow_magnitude_weight: 0.001,
            base_variance_px2: 0.05,
            ..UncertaintyConfig::default()
        };
        assert!(UncertaintyTerms::model_enabled(&cfg));
        // the paper's fit alone (what the monocular odometry uses) has every model term off
        let fit_only = UncertaintyConfig::cost_slice_fit();
        assert!(!UncertaintyTerms::model_enabled(&fit_only));
        assert!((fit_only.calibration - 12.4).abs() < 1e-6);
        assert!(UncertaintyTerms::model_enabled(
            &UncertaintyConfig::default()
        ));
        // 1 + 0.5 * 4 + 4 * 0.25 + 0.1 * 9 + 0.001 * 100 + 0.05 = 5.05
        assert!((terms.extra_variance_px2(1, &cfg) - 5.05).abs() < 1e-5);
        let info = terms.information(&cfg);
        for (i, m) in info.iter().enumerate() {
            let e = terms.extra_variance_px2(i, &cfg);
            let want = invert([0.5 + e, 0.1, 0.25 + e]).unwrap();
            for k in 0..3 {
                assert!(
                    (m[k] - want[k]).abs() < 1e-4 * want[k].abs().max(1.0),
                    "{m:?} {want:?}"
                );
            }
            assert!(is_pd(*m));
        }
    }
}
