//! Densification of the patch flows (Kroeger et al. 2016, eq. 3) and of their uncertainty.
//!
//! Each pixel `x` takes the weighted mean of the flows `u_k` of the patches that cover it, with
//! DIS's weights `λ_k = 1 / max(1, |I2(x + u_k) − I1(x) − m_k|)` (`m_k` the patch's mean
//! brightness difference when the mean is normalised): a patch whose flow does not carry this
//! pixel's brightness counts less. The same weights combine the patches' Gaussians
//! `N(u_k, Σ_k)`, `Σ_k = σ_k² H_k⁻¹` ([`super::patches`]), into the moment-matched Gaussian of
//! their mixture: `Σ(x) = Σ_k λ̂_k Σ_k + s Σ_k λ̂_k (u_k − ū)(u_k − ū)ᵀ` (`λ̂` normalised, `s` the
//! spread weight), so a pixel where overlapping patches disagree — a motion boundary, an
//! occlusion — is uncertain even where each patch alone was sharp.

use rayon::prelude::*;
use visnav_core::GrayImage;

use super::config::FastUncertaintyConfig;
use super::patches::{PatchFit, PatchGrid, floor_index};

/// Smallest eigenvalue a patch Hessian is credited with, intensity² per px²: a flat patch gets a
/// large but finite covariance.
const MIN_HESSIAN: f32 = 1e-2;

/// For each coordinate `0..len`, the range of patch indices along the axis that cover it.
fn covering(positions: &[usize], size: usize, len: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::with_capacity(len);
    let (mut lo, mut hi) = (0_usize, 0_usize);
    for x in 0..len {
        while lo < positions.len() && positions[lo] + size <= x {
            lo += 1;
        }
        while hi < positions.len() && positions[hi] <= x {
            hi += 1;
        }
        out.push((lo, hi.max(lo)));
    }
    out
}

/// The covariance `σ² H⁻¹` of a patch's flow, level px², `(xx, xy, yy)`.
#[must_use]
pub fn patch_covariance(fit: &PatchFit, noise_floor: f32) -> [f32; 3] {
    let var = fit.variance.max(noise_floor).max(1e-6);
    let [a, b, c] = fit.hessian;
    // eigenvalues floored at MIN_HESSIAN: add what the smaller one lacks to both (keeps the
    // orientation)
    let tr = 0.5 * (a + c);
    let disc = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let lift = (MIN_HESSIAN - (tr - disc)).max(0.0);
    let (a, c) = (a + lift, c + lift);
    let det = (a * c - b * b).max(MIN_HESSIAN * MIN_HESSIAN);
    [var * c / det, -var * b / det, var * a / det]
}

/// The densified flow of one level (level px) and, when asked for, its covariance (level px²).
pub struct Dense {
    /// Flow per pixel, level px.
    pub flow: Vec<[f32; 2]>,
    /// Covariance per pixel `(xx, xy, yy)`, level px² (empty unless asked for).
    pub covariance: Vec<[f32; 3]>,
}

/// Where a patch's flow takes a pixel of image 2: the integer offset of the top-left bilinear
/// neighbour and the four weights, the same for every pixel of the patch.
#[derive(Clone, Copy)]
struct Shift {
    dx: isize,
    dy: isize,
    weights: [f32; 4],
}

impl Shift {
    fn of(u: [f32; 2]) -> Self {
        let (dx, dy) = (floor_index(u[0]), floor_index(u[1]));
        let (fx, fy) = (u[0] - dx as f32, u[1] - dy as f32);
        Self {
            dx,
            dy,
            weights: [
                (1.0 - fx) * (1.0 - fy),
                fx * (1.0 - fy),
                (1.0 - fx) * fy,
                fx * fy,
            ],
        }
    }
}

/// One row's weighted moments of the covering patches, per pixel (structure of arrays), the
/// flows taken relative to `origin` (the first covering patch's flow, so that the second
/// moments do not cancel): `Σλ`, `Σλ d`, `Σλ d dᵀ`, `Σλ Σ_k`.
struct RowMoments {
    origin: Vec<[f32; 2]>,
    sum: Vec<f32>,
    first: [Vec<f32>; 2],
    second: [Vec<f32>; 3],
    cov: [Vec<f32>; 3],
}

impl RowMoments {
    fn new(w: usize, with_cov: bool) -> Self {
        let z = |n: usize| vec![0.0_f32; n];
        let c = if with_cov { w } else { 0 };
        Self {
            origin: vec![[0.0; 2]; w],
            sum: z(w),
            first: [z(w), z(w)],
            second: [z(c), z(c), z(c)],
            cov: [z(c), z(c), z(c)],
        }
    }
}

/// What one patch adds to a run of pixels of a row: its flow, mean difference, covariance.
#[derive(Clone, Copy)]
struct Contribution {
    flow: [f32; 2],
    mean_diff: f32,
    cov: [f32; 3],
}

visnav_core::simd_kernel! {
    /// Adds one patch's weighted flow (and, when `m.second` is not empty, its moments) to the
    /// pixels `x0..x0 + v1.len()` of a row: `v2` image 2 at those pixels moved by the patch's
    /// flow, `v1` image 1 there.
    fn accumulate(m: &mut RowMoments, x0: usize, v1: &[f32], v2: &[f32], p: Contribution) {
        let n = v1.len().min(v2.len());
        let x1 = x0 + n;
        let origin = &m.origin[x0..x1];
        let sum = &mut m.sum[x0..x1];
        let [fu, fv] = &mut m.first;
        let (fu, fv) = (&mut fu[x0..x1], &mut fv[x0..x1]);
        if m.second[0].is_empty() {
            for i in 0..n {
                let l = 1.0 / (v2[i] - v1[i] - p.mean_diff).abs().max(1.0);
                sum[i] += l;
                fu[i] += l * (p.flow[0] - origin[i][0]);
                fv[i] += l * (p.flow[1] - origin[i][1]);
            }
            return;
        }
        let [suu, suv, svv] = &mut m.second;
        let (suu, suv, svv) = (&mut suu[x0..x1], &mut suv[x0..x1], &mut svv[x0..x1]);
        let [cxx, cxy, cyy] = &mut m.cov;
        let (cxx, cxy, cyy) = (&mut cxx[x0..x1], &mut cxy[x0..x1], &mut cyy[x0..x1]);
        for i in 0..n {
            let l = 1.0 / (v2[i] - v1[i] - p.mean_diff).abs().max(1.0);
            let du = p.flow[0] - origin[i][0];
            let dv = p.flow[1] - origin[i][1];
            sum[i] += l;
            fu[i] += l * du;
            fv[i] += l * dv;
            suu[i] += l * du * du;
            suv[i] += l * du * dv;
            svv[i] += l * dv * dv;
            cxx[i] += l * p.cov[0];
            cxy[i] += l * p.cov[1];
            cyy[i] += l * p.cov[2];
        }
    }
}

/// Image 2 at pixels `x0..x0 + out.len()` of row `y` moved by `shift`, bilinear, clamped to the
/// image.
fn shifted_run(
    img: &[f32],
    (w, h): (usize, usize),
    y: usize,
    x0: usize,
    shift: Shift,
    out: &mut [f32],
) {
    let [w00, w01, w10, w11] = shift.weights;
    let ya = y as isize + shift.dy;
    let xa = x0 as isize + shift.dx;
    let n = out.len();
    if ya >= 0 && xa >= 0 && (ya as usize) + 1 < h && (xa as usize) + n < w {
        let i = ya as usize * w + xa as usize;
        let (r0, r1) = (&img[i..=i + n], &img[i + w..=i + w + n]);
        for (k, o) in out.iter_mut().enumerate() {
            *o = w00 * r0[k] + w01 * r0[k + 1] + w10 * r1[k] + w11 * r1[k + 1];
        }
        return;
    }
    let cy = |v: isize| v.clamp(0, h as isize - 1) as usize * w;
    let cx = |v: isize| v.clamp(0, w as isize - 1) as usize;
    let (r0, r1) = (cy(ya), cy(ya + 1));
    for (k, o) in out.iter_mut().enumerate() {
        let (a, b) = (cx(xa + k as isize), cx(xa + k as isize + 1));
        *o = w00 * img[r0 + a] + w01 * img[r0 + b] + w10 * img[r1 + a] + w11 * img[r1 + b];
    }
}

/// Densifies the fits of `grid` over the `img1` x `img2` level (eq. 3 of DIS), with the
/// mixture covariance when `uncertainty` is given.
#[must_use]
pub fn densify(
    img1: &GrayImage,
    img2: &GrayImage,
    grid: &PatchGrid,
    fits: &[PatchFit],
    uncertainty: Option<&FastUncertaintyConfig>,
) -> Dense {
    let (w, h) = (img1.width(), img1.height());
    let nx = grid.xs.len();
    let cols = covering(&grid.xs, grid.size, w);
    let rows = covering(&grid.ys, grid.size, h);
    let contributions: Vec<Contribution> = fits
        .iter()
        .map(|f| Contribution {
            flow: f.flow,
            mean_diff: f.mean_diff,
            cov: uncertainty.map_or([0.0; 3], |u| patch_covariance(f, u.noise_floor)),
        })
        .collect();
    let shifts: Vec<Shift> = fits.iter().map(|f| Shift::of(f.flow)).collect();
    let spread = uncertainty.map_or(0.0, |u| u.spread_weight);
    let mut flow = vec![[0.0_f32; 2]; w * h];
    let mut covariance = if uncertainty.is_some() {
        vec![[0.0_f32; 3]; w * h]
    } else {
        Vec::new()
    };
    let (i1, i2) = (img1.data(), img2.data());
    let body = |y: usize, frow: &mut [[f32; 2]], crow: Option<&mut [[f32; 3]]>| {
        let (r0, r1) = rows[y];
        if r0 >= r1 {
            return;
        }
        let mut m = RowMoments::new(w, crow.is_some());
        for (x, o) in m.origin.iter_mut().enumerate() {
            *o = fits[r0 * nx + cols[x].0].flow;
        }
        let mut v2 = vec![0.0_f32; grid.size];
        for r in r0..r1 {
            for (c, &x0) in grid.xs.iter().enumerate() {
                let k = r * nx + c;
                shifted_run(i2, (w, h), y, x0, shifts[k], &mut v2);
                let v1 = &i1[y * w + x0..y * w + x0 + grid.size];
                accumulate(&mut m, x0, v1, &v2, contributions[k]);
            }
        }
        for (x, f) in frow.iter_mut().enumerate() {
            let s = m.sum[x];
            *f = [
                m.origin[x][0] + m.first[0][x] / s,
                m.origin[x][1] + m.first[1][x] / s,
            ];
        }
        if let Some(crow) = crow {
            for (x, c) in crow.iter_mut().enumerate() {
                let s = m.sum[x];
                let mu = [m.first[0][x] / s, m.first[1][x] / s];
                let var = [
                    (m.second[0][x] / s - mu[0] * mu[0]).max(0.0),
                    m.second[1][x] / s - mu[0] * mu[1],
                    (m.second[2][x] / s - mu[1] * mu[1]).max(0.0),
                ];
                *c = [
                    m.cov[0][x] / s + spread * var[0],
                    m.cov[1][x] / s + spread * var[1],
                    m.cov[2][x] / s + spread * var[2],
                ];
            }
        }
    };
    if covariance.is_empty() {
        flow.par_chunks_mut(w)
            .enumerate()
            .for_each(|(y, frow)| body(y, frow, None));
    } else {
        flow.par_chunks_mut(w)
            .zip(covariance.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (frow, crow))| body(y, frow, Some(crow)));
    }
    Dense { flow, covariance }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covering_ranges_hold_every_patch_over_a_pixel() {
        let xs = [0, 4, 8, 12, 13];
        let c = covering(&xs, 8, 21);
        assert_eq!(c[0], (0, 1));
        assert_eq!(c[5], (0, 2));
        assert_eq!(c[12], (2, 4));
        assert_eq!(c[13], (2, 5));
        assert_eq!(c[20], (4, 5));
    }

    #[test]
    fn an_edge_patch_is_uncertain_along_the_edge() {
        // texture in x only: the flow's y component is unknown (the aperture problem)
        let fit = PatchFit {
            flow: [0.0; 2],
            mean_diff: 0.0,
            variance: 4.0,
            hessian: [500.0, 0.0, 0.0],
        };
        let c = patch_covariance(&fit, 1.0);
        assert!(c[0] < 0.01 && c[2] > 100.0, "{c:?}");
    }
}
