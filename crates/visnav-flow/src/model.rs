//! The measurements behind the full uncertainty model ([`UncertaintyTerms`]): what the
//! cost-slice Gaussian fit of eq. 1–4 cannot see. The fit describes how sharply the regularised
//! matching cost rises around the winner at 1/3 resolution; the flow's real error also grows
//!
//! * where the forward and backward matches disagree (continuous forward–backward residual,
//!   not only the binary 0.8 px check),
//! * with the distance of an interpolated pixel to the kept match it took its flow from,
//! * where the brightness residual after refinement is large *relative to the local image
//!   gradient* (a residual of `r` levels on a gradient of `g` levels/px is a displacement of
//!   about `r / g` px; the raw residual instead flags every textured area) and well above the
//!   pair's typical (noise) residual,
//! * at motion boundaries, where the refined flow varies fast in a way a locally linear flow
//!   does not explain,
//! * with the length of the flow (larger displacements, larger errors).
//!
//! Each term is turned into an isotropic variance added to the fitted covariance with one
//! global weight ([`crate::UncertaintyConfig`]), fitted on synthetic pairs
//! (`examples/calibrate_uncertainty.rs`).

use rayon::prelude::*;
use visnav_core::GrayImage;

use crate::config::UncertaintyConfig;
use crate::ops::{box_filter, gradients, sample_field};
use crate::uncertainty::{FB_CAP_LEVEL_PX, UncertaintyTerms, invert};

/// What [`terms`] needs from the flow computation.
pub struct Inputs<'a> {
    /// Image 1 as refined (prefiltered), full resolution.
    pub img1: &'a GrayImage,
    /// Image 2 as refined (prefiltered), full resolution.
    pub img2: &'a GrayImage,
    /// Refined flow, full resolution, px.
    pub flow: &'a [[f32; 2]],
    /// Information of the calibrated cost-slice fit, full resolution, 1/px².
    pub information: &'a [[f32; 3]],
    /// Forward–backward discrepancy at the matching level, level px (infinite off-image).
    pub fb_level: &'a [f32],
    /// Geodesic fill distance at the matching level, level px.
    pub fill_level: &'a [f32],
    /// Matching-level width.
    pub level_width: usize,
    /// Matching-level height.
    pub level_height: usize,
    /// Full-resolution coordinate of level pixel `i` is `scale * i + offset`.
    pub scale: f32,
    /// See `scale`.
    pub offset: f32,
}

/// Computes the per-pixel terms at full resolution.
#[must_use]
pub fn terms(inp: &Inputs<'_>, cfg: &UncertaintyConfig) -> UncertaintyTerms {
    let (w, h) = (inp.img1.width(), inp.img1.height());
    let (lw, lh) = (inp.level_width, inp.level_height);
    let fit_covariance_px2: Vec<[f32; 3]> = inp
        .information
        .par_iter()
        .map(|m| invert(*m).unwrap_or([1.0 / cfg.min_information, 0.0, 1.0 / cfg.min_information]))
        .collect();
    // level terms, capped, to full resolution in px (bilinear)
    let level: Vec<[f32; 2]> = inp
        .fb_level
        .iter()
        .zip(inp.fill_level)
        .map(|(fb, d)| [fb.min(FB_CAP_LEVEL_PX), d.min(1e3)])
        .collect();
    let mut fb_discrepancy_px = vec![0.0_f32; w * h];
    let mut fill_distance_px = vec![0.0_f32; w * h];
    fb_discrepancy_px
        .par_chunks_mut(w)
        .zip(fill_distance_px.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (fb_row, fill_row))| {
            let yc = (y as f32 - inp.offset) / inp.scale;
            for (x, (fb, fill)) in fb_row.iter_mut().zip(fill_row.iter_mut()).enumerate() {
                let xc = (x as f32 - inp.offset) / inp.scale;
                let v = sample_field(&level, lw, lh, xc, yc);
                *fb = v[0] * inp.scale;
                *fill = v[1] * inp.scale;
            }
        });
    // gradient-normalised residual: r̄ / sqrt(ḡ² + floor²) over 7x7
    let (gx, gy) = gradients(inp.img1);
    let mut planes = vec![0.0_f32; w * h * 2];
    planes
        .par_chunks_mut(w * 2)
        .enumerate()
        .for_each(|(y, row)| {
            for x in 0..w {
                let i = y * w + x;
                let [u, v] = inp.flow[i];
                let xs = f64::from(x as f32 + u);
                let ys = f64::from(y as f32 + v);
                row[2 * x] = (inp.img2.bilinear_clamped(xs, ys) - inp.img1.get(x, y)).abs();
                row[2 * x + 1] = gx.data()[i].powi(2) + gy.data()[i].powi(2);
            }
        });
    let means = box_filter(&planes, w, h, 2, 3);
    let floor2 = cfg.residual_gradient_floor.powi(2);
    // only the residual above twice the pair's median counts: the bulk of it is sensor noise
    // and illumination change, whose level differs from camera to camera
    let mut sample: Vec<f32> = means.iter().step_by(2 * 7).copied().collect();
    let noise = if sample.is_empty() {
        0.0
    } else {
        let mid = sample.len() / 2;
        *sample.select_nth_unstable_by(mid, f32::total_cmp).1
    };
    let normalised_residual_px: Vec<f32> = means
        .par_chunks(2)
        .map(|m| (m[0] - 2.0 * noise).max(0.0) / (m[1] + floor2).sqrt())
        .collect();
    // local flow variation over 5x5
    let mut moments = vec![0.0_f32; w * h * 4];
    moments
        .par_chunks_mut(4)
        .zip(inp.flow.par_iter())
        .for_each(|(m, f)| {
            m.copy_from_slice(&[f[0], f[1], f[0] * f[0], f[1] * f[1]]);
        });
    let moments = box_filter(&moments, w, h, 4, 2);
    // the part of the variance a locally linear flow explains (perspective flow on a road
    // varies fast but smoothly): over a 5x5 window var(x) = var(y) = 2 px², so a gradient g
    // contributes 2 |g|²; g from central differences of the window means
    let mean_at = |x: usize, y: usize, c: usize| moments[(y * w + x) * 4 + c];
    let flow_variation_px: Vec<f32> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let m = &moments[i * 4..i * 4 + 4];
            let var = m[2] - m[0] * m[0] + m[3] - m[1] * m[1];
            let (xl, xr) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let (yu, yd) = (y.saturating_sub(1), (y + 1).min(h - 1));
            let mut trend = 0.0;
            for c in 0..2 {
                let gx = (mean_at(xr, y, c) - mean_at(xl, y, c)) / (xr - xl).max(1) as f32;
                let gy = (mean_at(x, yd, c) - mean_at(x, yu, c)) / (yd - yu).max(1) as f32;
                trend += 2.0 * (gx * gx + gy * gy);
            }
            (var - trend).max(0.0).sqrt()
        })
        .collect();
    let flow_magnitude_px: Vec<f32> = inp.flow.par_iter().map(|f| f[0].hypot(f[1])).collect();
    UncertaintyTerms {
        width: w,
        height: h,
        fit_covariance_px2,
        fb_discrepancy_px,
        fill_distance_px,
        normalised_residual_px,
        flow_variation_px,
        flow_magnitude_px,
    }
}

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
                information: &info,
                fb_level: &zeros,
                fill_level: &zeros,
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
        let (lw, lh) = (w / 3, h / 3);
        let fb = vec![0.5_f32; lw * lh];
        let fill = vec![0.0_f32; lw * lh];
        let t = terms(
            &Inputs {
                img1: &img1,
                img2: &img2,
                flow: &flow,
                information: &info,
                fb_level: &fb,
                fill_level: &fill,
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
        assert!((t.fit_covariance_px2[at(5, 5)][0] - 0.25).abs() < 1e-5);
    }
}
