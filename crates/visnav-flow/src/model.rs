//! The measurements behind the full uncertainty model ([`UncertaintyTerms`]): what the
//! cost-slice Gaussian fit of eq. 1–4 cannot see. The fit describes how sharply the regularised
//! matching cost rises around the winner at 1/3 resolution; the flow's real error also grows
//!
//! * where the forward and backward matches disagree (continuous forward–backward residual,
//!   not only the binary 0.8 px check, at the matching level and, after both flows are refined,
//!   at full resolution) and near pixels the check removed (occlusions,
//!   disocclusions, motion boundaries: the share of removed pixels around a pixel),
//! * where the regularised cost slice has a second minimum away from the winner with a small
//!   margin (an ambiguous match: repeated texture, a second surface),
//! * with the distance of an interpolated pixel to the kept match it took its flow from,
//! * where image 1 and image 2 warped by the flow do not look alike: the brightness residual
//!   *relative to the local image gradient*, and the normalised cross-correlation of the two
//!   (invariant to local gain and offset, and low on flat patches where the match is a guess),
//! * where the image has little texture in its weakest direction (structure tensor),
//! * where the variational refinement moved the flow far from the matching result,
//! * where the flow depends on the smoothness term rather than on the images: the distance to a
//!   second refinement of the same matching result with a weak smoothness weight (flat or
//!   one-directional texture, regions the regulariser pulled along),
//! * at motion boundaries, where the refined flow varies fast in a way a locally linear flow
//!   does not explain (5x5 and 11x11 windows),
//! * with the length of the flow (larger displacements, larger errors),
//! * and, for the whole pair at once, with how unlike the two images look after warping on
//!   average (the image-wide mean of the NCC dissimilarity: noise against texture, blur,
//!   surfaces that change appearance), which scales every pixel's variance alike.
//!
//! The default model ([`crate::config::VarianceModel`]) scales the fit's covariance shape
//! (blended towards a circle) by a log-linear function of these measurements; the additive
//! isotropic terms of the previous model are still available ([`crate::UncertaintyConfig`]).
//! Coefficients are fitted on synthetic pairs (`examples/calibrate_uncertainty.rs`).

use rayon::prelude::*;
use visnav_core::{GrayImage, Information2};

use crate::config::UncertaintyConfig;
use crate::ops::{
    box_filter_running as box_filter, gradients, horizontal_running_mean, sample_field,
    upsample_flow, vertical_box_row_in_band,
};
use crate::uncertainty::{FB_CAP_FULL_PX, FB_CAP_LEVEL_PX, UncertaintyTerms};

/// What [`terms`] needs from the flow computation.
pub struct Inputs<'a> {
    /// Image 1 as refined (prefiltered), full resolution.
    pub img1: &'a GrayImage,
    /// Image 2 as refined (prefiltered), full resolution.
    pub img2: &'a GrayImage,
    /// Refined flow, full resolution, px.
    pub flow: &'a [[f32; 2]],
    /// Refined backward flow (image 2 to image 1), full resolution, px, when computed.
    pub backward_flow: Option<&'a [[f32; 2]]>,
    /// The same matching result refined with a weaker smoothness term
    /// ([`UncertaintyConfig::sensitivity_alpha`]), full resolution, px, when computed.
    pub weakly_smoothed_flow: Option<&'a [[f32; 2]]>,
    /// Information of the calibrated cost-slice fit, full resolution, 1/px².
    pub information: &'a [[f32; 3]],
    /// Forward–backward discrepancy at the matching level, level px (infinite off-image).
    pub fb_level: &'a [f32],
    /// Geodesic fill distance at the matching level, level px.
    pub fill_level: &'a [f32],
    /// Second minimum of the regularised slice at the matching level, `(cost margin, distance
    /// in level px)` ([`crate::volume::second_minimum`]).
    pub second_minimum_level: &'a [[f32; 2]],
    /// Forward–backward check result at the matching level (true: kept).
    pub keep_level: &'a [bool],
    /// Filtered flow at the matching level (the refinement's start), level px.
    pub flow_level: &'a [[f32; 2]],
    /// Matching-level width.
    pub level_width: usize,
    /// Matching-level height.
    pub level_height: usize,
    /// Full-resolution coordinate of level pixel `i` is `scale * i + offset`.
    pub scale: f32,
    /// See `scale`.
    pub offset: f32,
}

/// Standard deviation of a flow over a `(2r+1)²` window beyond its local linear trend, from the
/// window means of `(u, v, u², v²)`: over the window `var(x) = var(y) = r(r+1)/3` px², so a
/// gradient `g` contributes `r(r+1)/3 |g|²`, `g` from central differences of the window means.
fn detrended_variation(means: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let spread = (r * (r + 1)) as f32 / 3.0;
    let mean_at = |x: usize, y: usize, c: usize| means[(y * w + x) * 4 + c];
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let m = &means[i * 4..i * 4 + 4];
            let var = m[2] - m[0] * m[0] + m[3] - m[1] * m[1];
            let (xl, xr) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let (yu, yd) = (y.saturating_sub(1), (y + 1).min(h - 1));
            let mut trend = 0.0;
            for c in 0..2 {
                let gx = (mean_at(xr, y, c) - mean_at(xl, y, c)) / (xr - xl).max(1) as f32;
                let gy = (mean_at(x, yd, c) - mean_at(x, yu, c)) / (yd - yu).max(1) as f32;
                trend += spread * (gx * gx + gy * gy);
            }
            (var - trend).max(0.0).sqrt()
        })
        .collect()
}

/// The matching-level terms at full resolution (bilinear): the capped forward–backward
/// discrepancy and fill distance (px), the share of pixels the forward–backward check removed
/// over 7x7 level pixels, and the variance a second, ambiguous minimum of the regularised cost
/// slice (of the eq. 1–4 fit) stands for (px²).
struct LevelTerms {
    fb_discrepancy_px: Vec<f32>,
    fill_distance_px: Vec<f32>,
    removed_share: Vec<f32>,
    ambiguity_px2: Vec<f32>,
}

impl LevelTerms {
    fn compute(inp: &Inputs<'_>, cfg: &UncertaintyConfig) -> Self {
        let (w, h) = (inp.img1.width(), inp.img1.height());
        let (lw, lh) = (inp.level_width, inp.level_height);
        let removed: Vec<f32> = inp
            .keep_level
            .iter()
            .map(|k| if *k { 0.0 } else { 1.0 })
            .collect();
        let removed = if removed.len() == lw * lh {
            box_filter(&removed, lw, lh, 1, 3)
        } else {
            vec![0.0; lw * lh]
        };
        let level: Vec<[f32; 2]> = inp
            .fb_level
            .iter()
            .zip(inp.fill_level)
            .map(|(fb, d)| [fb.min(FB_CAP_LEVEL_PX), d.min(1e3)])
            .collect();
        // sampled together with the removed share: the variance a second, ambiguous minimum of
        // the slice stands for, level px², `d² exp(-margin / τ)` (0 where it was not computed)
        let tau = cfg.ambiguity_cost_scale.max(1e-3);
        let removed_and_ambiguity: Vec<[f32; 2]> = removed
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let a = inp
                    .second_minimum_level
                    .get(i)
                    .map_or(0.0, |[margin, d]| d * d * (-margin / tau).exp());
                [*r, a]
            })
            .collect();
        let mut fb_discrepancy_px = vec![0.0_f32; w * h];
        let mut fill_distance_px = vec![0.0_f32; w * h];
        let mut removed_share = vec![0.0_f32; w * h];
        let mut ambiguity_px2 = vec![0.0_f32; w * h];
        let scale2 = inp.scale * inp.scale;
        fb_discrepancy_px
            .par_chunks_mut(w)
            .zip(fill_distance_px.par_chunks_mut(w))
            .zip(removed_share.par_chunks_mut(w))
            .zip(ambiguity_px2.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (((fb_row, fill_row), rm_row), amb_row))| {
                let yc = (y as f32 - inp.offset) / inp.scale;
                for (x, (((fb, fill), rm), amb)) in fb_row
                    .iter_mut()
                    .zip(fill_row.iter_mut())
                    .zip(rm_row.iter_mut())
                    .zip(amb_row.iter_mut())
                    .enumerate()
                {
                    let xc = (x as f32 - inp.offset) / inp.scale;
                    let v = sample_field(&level, lw, lh, xc, yc);
                    *fb = v[0] * inp.scale;
                    *fill = v[1] * inp.scale;
                    let r = sample_field(&removed_and_ambiguity, lw, lh, xc, yc);
                    *rm = r[0];
                    *amb = r[1] * scale2;
                }
            });
        Self {
            fb_discrepancy_px,
            fill_distance_px,
            removed_share,
            ambiguity_px2,
        }
    }
}

/// The refined flow against the other flows of the pair, px: the full-resolution
/// forward–backward discrepancy (the level one upsampled when no backward flow was refined),
/// the distance to the weakly smoothed refinement, and the refinement's change from the
/// matching result.
struct FlowComparisons {
    fb_full_px: Vec<f32>,
    sensitivity_px: Vec<f32>,
    refinement_change_px: Vec<f32>,
}

impl FlowComparisons {
    fn compute(inp: &Inputs<'_>, fb_discrepancy_px: &[f32]) -> Self {
        let (w, h) = (inp.img1.width(), inp.img1.height());
        let (lw, lh) = (inp.level_width, inp.level_height);
        let start = if inp.flow_level.len() == lw * lh {
            upsample_flow(inp.flow_level, lw, lh, w, h, inp.scale, inp.offset)
        } else {
            inp.flow.to_vec()
        };
        let fb_full_px = match inp.backward_flow {
            Some(b) if b.len() == w * h => {
                let mut d = crate::ops::forward_backward_discrepancy(inp.flow, b, w, h);
                d.par_iter_mut().for_each(|v| *v = v.min(FB_CAP_FULL_PX));
                d
            }
            _ => fb_discrepancy_px.to_vec(),
        };
        let sensitivity_px: Vec<f32> = match inp.weakly_smoothed_flow {
            Some(a) if a.len() == w * h => inp
                .flow
                .par_iter()
                .zip(a)
                .map(|(f, g)| (f[0] - g[0]).hypot(f[1] - g[1]))
                .collect(),
            _ => vec![0.0; w * h],
        };
        let refinement_change_px: Vec<f32> = inp
            .flow
            .par_iter()
            .zip(&start)
            .map(|(f, s)| (f[0] - s[0]).hypot(f[1] - s[1]))
            .collect();
        Self {
            fb_full_px,
            sensitivity_px,
            refinement_change_px,
        }
    }
}

/// Over 7x7: the brightness residual `|I2(x + u) - I1(x)|` above the pair's noise relative to
/// the local gradient, the texture (smallest structure-tensor eigenvalue) and `1 - NCC` of
/// image 1 and the warped image 2.
struct PhotometricTerms {
    normalised_residual_px: Vec<f32>,
    texture: Vec<f32>,
    ncc_dissimilarity: Vec<f32>,
}

impl PhotometricTerms {
    /// The terms over 7x7 windows, a band of [`PHOTOMETRIC_BAND_ROWS`] rows at a time (the
    /// nine planes of products and their box means exist for one band and its halo only: about
    /// 50 MB less at KITTI's size than planes for the whole image).
    fn compute(inp: &Inputs<'_>, cfg: &UncertaintyConfig) -> Self {
        let (w, h) = (inp.img1.width(), inp.img1.height());
        let (gx, gy) = gradients(inp.img1);
        let floor2 = cfg.residual_gradient_floor.powi(2);
        // per pixel: the mean residual, the residual's denominator, the texture, 1 - NCC
        let mut out = vec![[0.0_f32; 4]; w * h];
        out.par_chunks_mut(w * PHOTOMETRIC_BAND_ROWS)
            .enumerate()
            .for_each(|(band, rows)| {
                let y0 = band * PHOTOMETRIC_BAND_ROWS;
                photometric_band(inp, (gx.data(), gy.data()), y0, rows, floor2);
            });
        // only the residual above twice the pair's median counts: the bulk of it is sensor
        // noise and illumination change, whose level differs from camera to camera
        let mut sample: Vec<f32> = out.iter().step_by(7).map(|t| t[0]).collect();
        let noise = if sample.is_empty() {
            0.0
        } else {
            let mid = sample.len() / 2;
            *sample.select_nth_unstable_by(mid, f32::total_cmp).1
        };
        let (normalised_residual_px, (texture, ncc_dissimilarity)): (
            Vec<f32>,
            (Vec<f32>, Vec<f32>),
        ) = out
            .par_iter()
            .map(|&[m0, denominator, tex, ncc]| {
                ((m0 - 2.0 * noise).max(0.0) / denominator, (tex, ncc))
            })
            .unzip();
        Self {
            normalised_residual_px,
            texture,
            ncc_dissimilarity,
        }
    }

    /// The image-wide mean of the NCC dissimilarity (clamped to `[0, 2]`).
    fn image_ncc_dissimilarity(&self) -> f32 {
        if self.ncc_dissimilarity.is_empty() {
            0.0
        } else {
            let sum: f64 = self
                .ncc_dissimilarity
                .iter()
                .map(|d| f64::from(d.clamp(0.0, 2.0)))
                .sum();
            (sum / self.ncc_dissimilarity.len() as f64) as f32
        }
    }
}

/// Image rows a band of [`PhotometricTerms::compute`] holds.
const PHOTOMETRIC_BAND_ROWS: usize = 32;

/// Box radius of the photometric terms (7x7 windows).
const PHOTOMETRIC_RADIUS: usize = 3;

/// One band of [`PhotometricTerms::compute`] from image row `y0` (`out`: its rows): the nine
/// planes `|I2(x + u) - I1|, gx², gx gy, gy², I1, I2, I1², I2², I1 I2` over the band and its
/// halo, their 7x7 box means (the whole-image filter's sums, bit for bit) and per pixel the
/// mean residual, its denominator `sqrt(gx² + gy² + floor²)`, the texture (smallest
/// structure-tensor eigenvalue) and `1 - NCC`.
fn photometric_band(
    inp: &Inputs<'_>,
    (gx, gy): (&[f32], &[f32]),
    y0: usize,
    out: &mut [[f32; 4]],
    floor2: f32,
) {
    let (w, h) = (inp.img1.width(), inp.img1.height());
    let r = PHOTOMETRIC_RADIUS;
    let rows = out.len() / w;
    let (lo, hi) = (y0.saturating_sub(r), (y0 + rows + r).min(h));
    let stride = w * PLANES;
    let mut planes = vec![0.0_f32; (hi - lo) * stride];
    let mut filtered = vec![0.0_f32; (hi - lo) * stride];
    for (k, (row, frow)) in planes
        .chunks_mut(stride)
        .zip(filtered.chunks_mut(stride))
        .enumerate()
    {
        let y = lo + k;
        for x in 0..w {
            let i = y * w + x;
            let [u, v] = inp.flow[i];
            let b = inp
                .img2
                .bilinear_clamped(f64::from(x as f32 + u), f64::from(y as f32 + v));
            let a = inp.img1.get(x, y);
            let (p, q) = (gx[i], gy[i]);
            row[PLANES * x..PLANES * (x + 1)].copy_from_slice(&[
                (b - a).abs(),
                p * p,
                p * q,
                q * q,
                a,
                b,
                a * a,
                b * b,
                a * b,
            ]);
        }
        horizontal_running_mean(frow, row, PLANES, r);
    }
    let mut means = planes;
    for (k, orow) in out.chunks_mut(w).enumerate() {
        let mrow = &mut means[..stride];
        vertical_box_row_in_band(y0 + k, mrow, &filtered, lo, h, r);
        for (o, m) in orow.iter_mut().zip(mrow.chunks(PLANES)) {
            // smallest eigenvalue of the structure tensor
            let tr = 0.5 * (m[1] + m[3]);
            let disc = (0.25 * (m[1] - m[3]).powi(2) + m[2] * m[2]).sqrt();
            let tex = (tr - disc).max(0.0).sqrt();
            // 1 - NCC
            let va = (m[6] - m[4] * m[4]).max(0.0);
            let vb = (m[7] - m[5] * m[5]).max(0.0);
            let cov = m[8] - m[4] * m[5];
            let ncc = 1.0 - cov / (va * vb + NCC_EPSILON).sqrt();
            *o = [m[0], (m[1] + m[3] + floor2).sqrt(), tex, ncc];
        }
    }
}

/// Local flow variation beyond a linear trend over 5x5 and 11x11, and the flow's length, px.
struct VariationTerms {
    flow_variation_px: Vec<f32>,
    flow_variation_wide_px: Vec<f32>,
    flow_magnitude_px: Vec<f32>,
}

impl VariationTerms {
    fn compute(inp: &Inputs<'_>) -> Self {
        let (w, h) = (inp.img1.width(), inp.img1.height());
        let mut moments = vec![0.0_f32; w * h * 4];
        moments
            .par_chunks_mut(4)
            .zip(inp.flow.par_iter())
            .for_each(|(m, f)| {
                m.copy_from_slice(&[f[0], f[1], f[0] * f[0], f[1] * f[1]]);
            });
        let flow_variation_px = detrended_variation(&box_filter(&moments, w, h, 4, 2), w, h, 2);
        let flow_variation_wide_px =
            detrended_variation(&box_filter(&moments, w, h, 4, 5), w, h, 5);
        let flow_magnitude_px: Vec<f32> = inp.flow.par_iter().map(|f| f[0].hypot(f[1])).collect();
        Self {
            flow_variation_px,
            flow_variation_wide_px,
            flow_magnitude_px,
        }
    }
}

/// Computes the per-pixel terms at full resolution, in four stages: `LevelTerms`,
/// `FlowComparisons`, `PhotometricTerms`, `VariationTerms`. The fit's covariance is the
/// inverse of the calibrated eq. 4 information.
#[must_use]
pub fn terms(inp: &Inputs<'_>, cfg: &UncertaintyConfig) -> UncertaintyTerms {
    let (w, h) = (inp.img1.width(), inp.img1.height());
    let fit_covariance_px2: Vec<[f32; 3]> = inp
        .information
        .par_iter()
        .map(|m| {
            Information2::from_array(*m).covariance_px2().unwrap_or([
                1.0 / cfg.min_information,
                0.0,
                1.0 / cfg.min_information,
            ])
        })
        .collect();
    let level = LevelTerms::compute(inp, cfg);
    let flows = FlowComparisons::compute(inp, &level.fb_discrepancy_px);
    let photometric = PhotometricTerms::compute(inp, cfg);
    let variation = VariationTerms::compute(inp);
    let image_ncc_dissimilarity = photometric.image_ncc_dissimilarity();
    UncertaintyTerms {
        width: w,
        height: h,
        fit_covariance_px2,
        fb_discrepancy_px: level.fb_discrepancy_px,
        fill_distance_px: level.fill_distance_px,
        normalised_residual_px: photometric.normalised_residual_px,
        flow_variation_px: variation.flow_variation_px,
        flow_magnitude_px: variation.flow_magnitude_px,
        removed_share: level.removed_share,
        refinement_change_px: flows.refinement_change_px,
        texture: photometric.texture,
        ncc_dissimilarity: photometric.ncc_dissimilarity,
        flow_variation_wide_px: variation.flow_variation_wide_px,
        fb_full_px: flows.fb_full_px,
        ambiguity_px2: level.ambiguity_px2,
        sensitivity_px: flows.sensitivity_px,
        image_ncc_dissimilarity,
    }
}

/// Regulariser of the normalised cross-correlation, intensity levels⁴ (under the product of
/// the two variances: flat patches correlate near 0).
pub const NCC_EPSILON: f32 = 1.0;

/// 7x7 planes: residual, structure tensor (3), I1, I2 warped, I1², I2², I1 I2.
const PLANES: usize = 9;

#[cfg(test)]
mod tests {
    use super::*;

    /// Terms of `flow` on a ramp image seen twice (no residual), level terms zero.
    fn terms_of(flow: &[[f32; 2]], w: usize, h: usize) -> UncertaintyTerms {
        let img = GrayImage::from_fn(w, h, |x, y| (x * 3 + y * 5) as f32);
        let info = vec![[1.0_f32, 0.0, 1.0]; w * h];
        let (lw, lh) = (w / 3, h / 3);
        let zeros = vec![0.0_f32; lw * lh];
        terms(
            &Inputs {
                img1: &img,
                img2: &img,
                flow,
                backward_flow: None,
                weakly_smoothed_flow: None,
                information: &info,
                fb_level: &zeros,
                fill_level: &zeros,
                second_minimum_level: &vec![[0.0; 2]; lw * lh],
                keep_level: &vec![true; lw * lh],
                flow_level: &vec![[0.0; 2]; lw * lh],
                level_width: lw,
                level_height: lh,
                scale: 3.0,
                offset: 1.0,
            },
            &UncertaintyConfig::default(),
        )
    }

    #[test]
    fn a_linear_flow_has_no_variation_but_a_step_has() {
        let (w, h) = (30, 20);
        let linear: Vec<[f32; 2]> = (0..w * h)
            .map(|i| [0.3 * (i % w) as f32, -0.2 * (i / w) as f32])
            .collect();
        let v = terms_of(&linear, w, h).flow_variation_px[10 * w + 15];
        assert!(v < 1e-2, "{v}");
        let step: Vec<[f32; 2]> = (0..w * h)
            .map(|i| if i % w < 15 { [0.0, 0.0] } else { [2.0, 0.0] })
            .collect();
        assert!(terms_of(&step, w, h).flow_variation_px[10 * w + 15] > 0.5);
    }

    #[test]
    fn terms_measure_residual_relative_to_gradient_and_flow_variation() {
        let (w, h) = (40, 30);
        // a horizontal ramp of 4 levels/px
        let img1 = GrayImage::from_fn(w, h, |x, _| 4.0 * x as f32);
        let img2 = GrayImage::from_fn(w, h, |x, _| 4.0 * x as f32 + 4.0);
        // I2(x) = I1(x + 1), so the true flow is (-1, 0): right on the left three quarters, 1 px
        // off on the right quarter (the median residual stays 0)
        let flow: Vec<[f32; 2]> = (0..w * h)
            .map(|i| if i % w < 30 { [-1.0, 0.0] } else { [0.0, 0.0] })
            .collect();
        let info = vec![[4.0_f32, 0.0, 4.0]; w * h];
        // the backward flow is right everywhere: (+1, 0)
        let back = vec![[1.0_f32, 0.0]; w * h];
        // the weakly smoothed refinement agrees on the left half, is (0.3, -0.4) off on the right
        let weak: Vec<[f32; 2]> = flow
            .iter()
            .enumerate()
            .map(|(i, f)| {
                if i % w < 20 {
                    *f
                } else {
                    [f[0] + 0.3, f[1] - 0.4]
                }
            })
            .collect();
        let (lw, lh) = (w / 3, h / 3);
        let fb = vec![0.5_f32; lw * lh];
        let fill = vec![0.0_f32; lw * lh];
        let t = terms(
            &Inputs {
                img1: &img1,
                img2: &img2,
                flow: &flow,
                backward_flow: Some(&back),
                weakly_smoothed_flow: Some(&weak),
                information: &info,
                fb_level: &fb,
                fill_level: &fill,
                // an ambiguous second minimum 2 labels away at zero margin everywhere:
                // (2 * 3 px)² = 36 px²
                second_minimum_level: &vec![[0.0, 2.0]; lw * lh],
                keep_level: &vec![true; lw * lh],
                flow_level: &vec![[0.0; 2]; lw * lh],
                level_width: lw,
                level_height: lh,
                scale: 3.0,
                offset: 1.0,
            },
            &UncertaintyConfig::default(),
        );
        let at = |x: usize, y: usize| y * w + x;
        // left interior: no residual, no flow variation
        assert!(t.normalised_residual_px[at(8, 15)] < 1e-4);
        assert!(t.flow_variation_px[at(8, 15)] < 1e-4);
        // right interior: residual 4 levels on a 4 levels/px gradient (floor 2) -> 4/sqrt(20)
        let want = 4.0 / 20.0_f32.sqrt();
        assert!((t.normalised_residual_px[at(35, 15)] - want).abs() < 1e-3);
        // at the flow step the 5x5 window mixes -1 and 0
        assert!(t.flow_variation_px[at(30, 15)] > 0.3);
        assert!((t.flow_magnitude_px[at(8, 15)] - 1.0).abs() < 1e-6);
        // level discrepancy 0.5 level px -> 1.5 px
        assert!((t.fb_discrepancy_px[at(20, 15)] - 1.5).abs() < 1e-4);
        // refined flows at full resolution: consistent on the left, 1 px apart on the right,
        // capped where the forward flow leaves the image
        assert!(t.fb_full_px[at(8, 15)] < 1e-5);
        assert!((t.fb_full_px[at(35, 15)] - 1.0).abs() < 1e-5);
        assert!((t.fb_full_px[at(0, 15)] - FB_CAP_FULL_PX).abs() < 1e-5);
        // a ramp has texture in one direction only
        assert!(t.texture[at(20, 15)] < 1e-3);
        // the warped image 2 matches image 1 on the left and is offset by 4 levels on the
        // right: NCC ignores the offset, both are dissimilarity 0
        assert!(t.ncc_dissimilarity[at(8, 15)] < 1e-3);
        assert!(t.ncc_dissimilarity[at(35, 15)] < 1e-3);
        // the refinement moved the (zero) matching flow by 1 px on the left, not on the right
        assert!((t.refinement_change_px[at(8, 15)] - 1.0).abs() < 1e-5);
        assert!(t.refinement_change_px[at(35, 15)] < 1e-5);
        assert!(t.removed_share.iter().all(|r| *r == 0.0));
        assert!((t.ambiguity_px2[at(20, 15)] - 36.0).abs() < 1e-3);
        assert!(t.sensitivity_px[at(8, 15)] < 1e-6);
        assert!((t.sensitivity_px[at(25, 15)] - 0.5).abs() < 1e-5);
        assert!((t.fit_covariance_px2[at(5, 5)][0] - 0.25).abs() < 1e-5);
    }
}
