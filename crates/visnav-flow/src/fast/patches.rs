//! Dense inverse search on one pyramid level (Kroeger et al. 2016, §2.1): square patches of
//! image 1 on a regular grid, each aligned into image 2 by inverse-compositional Gauss–Newton on
//! its brightness (the 2x2 Hessian of the template computed once), with DIS's mean normalisation
//! and, halfway through the iterations, spatial propagation from the grid neighbours.
//!
//! Each patch also returns what its uncertainty needs: its Hessian `H = Σ ∇T ∇Tᵀ` (projected
//! off the mean when the mean is normalised) and its residual variance `σ²` at the solution, so
//! that `σ² H⁻¹` is the covariance of its flow (the Gauss–Newton / Cramér–Rao covariance of a
//! translation under Gaussian brightness noise: anisotropic along an edge, the aperture problem).
//!
//! Rows of patches run in parallel; every patch's arithmetic depends on its own inputs only (the
//! propagation reads a snapshot of the grid), so the result does not depend on the thread count.

use rayon::prelude::*;
use visnav_core::GrayImage;

use super::config::FastFlowConfig;

/// Top-left corners of the patches along one axis of `len` pixels: every `stride` pixels from 0,
/// plus one flush with the far border so that every pixel is covered.
#[must_use]
pub fn patch_positions(len: usize, size: usize, stride: usize) -> Vec<usize> {
    if len < size {
        return Vec::new();
    }
    let last = len - size;
    let mut out: Vec<usize> = (0..=last).step_by(stride.max(1)).collect();
    if out.last() != Some(&last) {
        out.push(last);
    }
    out
}

/// The patch grid of one level.
#[derive(Debug, Clone)]
pub struct PatchGrid {
    /// Left columns of the patches.
    pub xs: Vec<usize>,
    /// Top rows of the patches.
    pub ys: Vec<usize>,
    /// Side of a patch, pixels.
    pub size: usize,
}

impl PatchGrid {
    /// The grid of a `w` x `h` level.
    #[must_use]
    pub fn new(w: usize, h: usize, size: usize, stride: usize) -> Self {
        Self {
            xs: patch_positions(w, size, stride),
            ys: patch_positions(h, size, stride),
            size,
        }
    }

    /// Number of patches.
    #[must_use]
    pub fn len(&self) -> usize {
        self.xs.len() * self.ys.len()
    }

    /// Whether the grid holds no patch (the level is smaller than a patch).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Centre of patch `(col, row)`, level pixels.
    #[must_use]
    pub fn centre(&self, col: usize, row: usize) -> [f32; 2] {
        let half = (self.size as f32 - 1.0) * 0.5;
        [self.xs[col] as f32 + half, self.ys[row] as f32 + half]
    }
}

/// One aligned patch.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PatchFit {
    /// Flow of the patch, level pixels.
    pub flow: [f32; 2],
    /// Mean of image 2 minus image 1 over the patch at the solution (0 without mean
    /// normalisation), intensity.
    pub mean_diff: f32,
    /// Residual variance at the solution, intensity² (sum of squared residuals over the
    /// degrees of freedom left, not yet floored).
    pub variance: f32,
    /// `(Hxx, Hxy, Hyy)` of the template, intensity² per px².
    pub hessian: [f32; 3],
}

/// The images of one level: image 1 and its gradients, image 2.
pub struct LevelImages<'a> {
    /// Image 1.
    pub img1: &'a GrayImage,
    /// `∂I1/∂x`.
    pub gx: &'a GrayImage,
    /// `∂I1/∂y`.
    pub gy: &'a GrayImage,
    /// Image 2, with a border of replicated pixels.
    pub img2: &'a Padded,
}

/// An image with a border of `pad` replicated pixels on every side, so that a patch displaced
/// up to `pad` pixels past the image is sampled in one pass with the same values as a clamped
/// lookup.
pub struct Padded {
    data: Vec<f32>,
    stride: usize,
    pad: usize,
    width: usize,
    height: usize,
}

impl Padded {
    /// `img` with a replicated border of `pad` pixels.
    #[must_use]
    pub fn new(img: &GrayImage, pad: usize) -> Self {
        let (w, h) = (img.width(), img.height());
        let stride = w + 2 * pad;
        let mut data = vec![0.0_f32; stride * (h + 2 * pad)];
        for (py, row) in data.chunks_exact_mut(stride).enumerate() {
            let src = img.row(py.saturating_sub(pad).min(h - 1));
            let (left, rest) = row.split_at_mut(pad);
            let (mid, right) = rest.split_at_mut(w);
            left.fill(src[0]);
            mid.copy_from_slice(src);
            right.fill(src[w - 1]);
        }
        Self {
            data,
            stride,
            pad,
            width: w,
            height: h,
        }
    }

    /// Width of the image (without the border).
    #[must_use]
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height of the image (without the border).
    #[must_use]
    pub fn height(&self) -> usize {
        self.height
    }
}

/// A patch's template: image 1's values and gradients and the (damped) inverse Hessian.
struct Template {
    t: Vec<f32>,
    gx: Vec<f32>,
    gy: Vec<f32>,
    sum_gx: f32,
    sum_gy: f32,
    hessian: [f32; 3],
    /// Inverse of the damped Hessian, `(a, b, c)` of the symmetric 2x2.
    inv: [f32; 3],
}

impl Template {
    fn new(size: usize) -> Self {
        let n = size * size;
        Self {
            t: vec![0.0; n],
            gx: vec![0.0; n],
            gy: vec![0.0; n],
            sum_gx: 0.0,
            sum_gy: 0.0,
            hessian: [0.0; 3],
            inv: [0.0; 3],
        }
    }

    /// Loads the patch at `(x0, y0)` and its Hessian (projected off the mean when
    /// `mean_normalisation`), damped by `damping` per pixel for the steps.
    fn load(
        &mut self,
        lv: &LevelImages<'_>,
        x0: usize,
        y0: usize,
        size: usize,
        cfg: &FastFlowConfig,
    ) {
        let w = lv.img1.width();
        let (i1, gx, gy) = (lv.img1.data(), lv.gx.data(), lv.gy.data());
        for j in 0..size {
            let src = (y0 + j) * w + x0;
            let dst = j * size;
            self.t[dst..dst + size].copy_from_slice(&i1[src..src + size]);
            self.gx[dst..dst + size].copy_from_slice(&gx[src..src + size]);
            self.gy[dst..dst + size].copy_from_slice(&gy[src..src + size]);
        }
        let [mut sxx, mut sxy, mut syy, sx, sy] = gradient_moments(&self.gx, &self.gy);
        let n = (size * size) as f32;
        if cfg.mean_normalisation {
            sxx -= sx * sx / n;
            sxy -= sx * sy / n;
            syy -= sy * sy / n;
        }
        self.sum_gx = sx;
        self.sum_gy = sy;
        self.hessian = [sxx.max(0.0), sxy, syy.max(0.0)];
        let d = cfg.damping * n;
        let (a, b, c) = (self.hessian[0] + d, self.hessian[1], self.hessian[2] + d);
        let det = a * c - b * b;
        self.inv = if det > 1e-12 {
            [c / det, -b / det, a / det]
        } else {
            [0.0; 3]
        };
    }
}

visnav_core::simd_kernel! {
    /// `(Σgx², Σgx gy, Σgy², Σgx, Σgy)` over a patch, each in [`LANES`] partial sums added up
    /// in a fixed order. One loop a sum: with one accumulator array a loop the compiler
    /// vectorises along the lanes (with five it vectorised across the sums, a lane at a time).
    fn gradient_moments(gx: &[f32], gy: &[f32]) -> [f32; 5] {
        let n = gx.len().min(gy.len());
        let (xc, xr) = gx[..n].as_chunks::<LANES>();
        let (yc, yr) = gy[..n].as_chunks::<LANES>();
        let mut out = [[0.0_f32; LANES]; 5];
        let [sxx, sxy, syy, sx, sy] = &mut out;
        for a in xc {
            for l in 0..LANES {
                sxx[l] += a[l] * a[l];
            }
        }
        for (a, b) in xc.iter().zip(yc) {
            for l in 0..LANES {
                sxy[l] += a[l] * b[l];
            }
        }
        for b in yc {
            for l in 0..LANES {
                syy[l] += b[l] * b[l];
            }
        }
        for a in xc {
            for l in 0..LANES {
                sx[l] += a[l];
            }
        }
        for b in yc {
            for l in 0..LANES {
                sy[l] += b[l];
            }
        }
        for (l, (a, b)) in xr.iter().zip(yr).enumerate() {
            sxx[l] += a * a;
            sxy[l] += a * b;
            syy[l] += b * b;
            sx[l] += a;
            sy[l] += b;
        }
        out.map(|a| a.iter().sum())
    }
}

/// Image 2 sampled over a patch displaced by `u`: one set of bilinear weights for the whole
/// patch (the displacement is the same for every pixel), clamped to the image at its borders.
fn sample_patch(
    img2: &Padded,
    (x0, y0): (usize, usize),
    size: usize,
    u: [f32; 2],
    out: &mut [f32],
    border: &mut BorderIndex,
) {
    let (w, h) = (img2.width, img2.height);
    let xb = x0 as f32 + u[0];
    let yb = y0 as f32 + u[1];
    let (ix, iy) = (floor_index(xb), floor_index(yb));
    let (fx, fy) = (xb - ix as f32, yb - iy as f32);
    let weights = [
        (1.0 - fx) * (1.0 - fy),
        fx * (1.0 - fy),
        (1.0 - fx) * fy,
        fx * fy,
    ];
    let pad = img2.pad as isize;
    let (px, py) = (ix + pad, iy + pad);
    let inside = px >= 0
        && py >= 0
        && px as usize + size < img2.stride
        && py as usize + size < h + 2 * img2.pad;
    if inside {
        let start = py as usize * img2.stride + px as usize;
        bilinear_patch(&img2.data[start..], img2.stride, size, weights, out);
        return;
    }
    // farther out than the border: clamped lookups into the image part, the clamped columns and
    // rows computed once per patch
    let BorderIndex { cols, rows } = border;
    cols.clear();
    rows.clear();
    for k in 0..=size as isize {
        cols.push((ix + k).clamp(0, w as isize - 1) as usize + img2.pad);
        rows.push(((iy + k).clamp(0, h as isize - 1) as usize + img2.pad) * img2.stride);
    }
    let [w00, w01, w10, w11] = weights;
    for (j, o) in out.chunks_exact_mut(size).enumerate() {
        let (ra, rb) = (&img2.data[rows[j]..], &img2.data[rows[j + 1]..]);
        for (k, o) in o.iter_mut().enumerate() {
            let (xa, xb2) = (cols[k], cols[k + 1]);
            *o = w00 * ra[xa] + w01 * ra[xb2] + w10 * rb[xa] + w11 * rb[xb2];
        }
    }
}

/// `⌊v⌋` as an index, without a call to `floorf` (x86-64's baseline has no rounding
/// instruction); `v` is a pixel coordinate, far inside `isize`'s range.
#[inline]
#[must_use]
pub fn floor_index(v: f32) -> isize {
    let t = v as isize;
    t - isize::from((t as f32) > v)
}

visnav_core::simd_kernel! {
    /// A `size` x `size` patch sampled with fixed bilinear weights from `data` (an image of
    /// row stride `w` starting at the patch's top-left sample, with a row and a column more
    /// than the patch inside it) into `out`, row-major. The common sizes run with the size
    /// known to the compiler (a row in whole vector registers, no loop overhead per row).
    fn bilinear_patch(data: &[f32], w: usize, size: usize, weights: [f32; 4], out: &mut [f32]) {
        match size {
            8 => bilinear_fixed::<8>(data, w, weights, out),
            12 => bilinear_fixed::<12>(data, w, weights, out),
            16 => bilinear_fixed::<16>(data, w, weights, out),
            _ => bilinear_any(data, w, size, weights, out),
        }
    }
}

/// [`bilinear_patch`] for patches of side `S`.
#[inline(always)]
fn bilinear_fixed<const S: usize>(data: &[f32], w: usize, weights: [f32; 4], out: &mut [f32]) {
    let [w00, w01, w10, w11] = weights;
    let (rows, _) = out.as_chunks_mut::<S>();
    for (j, o) in rows.iter_mut().enumerate() {
        let (r0, r1) = (&data[j * w..], &data[(j + 1) * w..]);
        let taps = (
            r0.first_chunk::<S>(),
            r0[1..].first_chunk::<S>(),
            r1.first_chunk::<S>(),
            r1[1..].first_chunk::<S>(),
        );
        if let (Some(a), Some(b), Some(c), Some(d)) = taps {
            for k in 0..S {
                o[k] = w00 * a[k] + w01 * b[k] + w10 * c[k] + w11 * d[k];
            }
        }
    }
}

/// [`bilinear_patch`] for any patch side.
#[inline(always)]
fn bilinear_any(data: &[f32], w: usize, size: usize, weights: [f32; 4], out: &mut [f32]) {
    let [w00, w01, w10, w11] = weights;
    for (j, o) in out.chunks_exact_mut(size).enumerate() {
        let r0 = &data[j * w..j * w + size + 1];
        let r1 = &data[(j + 1) * w..(j + 1) * w + size + 1];
        let taps = r0.iter().zip(&r0[1..]).zip(r1.iter().zip(&r1[1..]));
        for (o, ((a, b), (c, d))) in o.iter_mut().zip(taps) {
            *o = w00 * a + w01 * b + w10 * c + w11 * d;
        }
    }
}

/// Lanes of the residual sums' accumulators (a fixed order of additions, vectorisable).
const LANES: usize = 8;

visnav_core::simd_kernel! {
    /// Sums over the patch of the residual `d = I2(x + u) − T`: `(Σd, Σd², Σ gx d, Σ gy d)`,
    /// each in [`LANES`] interleaved partial sums added up in a fixed order, one loop a sum (as
    /// [`gradient_moments`]); the common patch sizes with the length known to the compiler.
    fn residual_sums(t: &[f32], gx: &[f32], gy: &[f32], warped: &[f32]) -> [f32; 4] {
        match warped.len() {
            64 => residual_fixed::<64>(t, gx, gy, warped),
            144 => residual_fixed::<144>(t, gx, gy, warped),
            256 => residual_fixed::<256>(t, gx, gy, warped),
            _ => residual_any(t, gx, gy, warped),
        }
    }
}

/// [`residual_sums`] over `N` pixels (a multiple of [`LANES`]); the same sums as
/// [`residual_any`].
#[inline(always)]
fn residual_fixed<const N: usize>(t: &[f32], gx: &[f32], gy: &[f32], warped: &[f32]) -> [f32; 4] {
    let arrays = (
        t.first_chunk::<N>(),
        gx.first_chunk::<N>(),
        gy.first_chunk::<N>(),
        warped.first_chunk::<N>(),
    );
    match arrays {
        (Some(t), Some(gx), Some(gy), Some(w)) => residual_any(t, gx, gy, w),
        _ => residual_any(t, gx, gy, warped),
    }
}

/// [`residual_sums`] for any patch size.
#[inline(always)]
fn residual_any(t: &[f32], gx: &[f32], gy: &[f32], warped: &[f32]) -> [f32; 4] {
    let n = warped.len().min(t.len()).min(gx.len()).min(gy.len());
    let (wc, wr) = warped[..n].as_chunks::<LANES>();
    let (tc, tr) = t[..n].as_chunks::<LANES>();
    let (xc, xr) = gx[..n].as_chunks::<LANES>();
    let (yc, yr) = gy[..n].as_chunks::<LANES>();
    let mut out = [[0.0_f32; LANES]; 4];
    let [sd, sdd, sgx, sgy] = &mut out;
    for (w, t) in wc.iter().zip(tc) {
        for l in 0..LANES {
            sd[l] += w[l] - t[l];
        }
    }
    for (w, t) in wc.iter().zip(tc) {
        for l in 0..LANES {
            let d = w[l] - t[l];
            sdd[l] += d * d;
        }
    }
    for ((w, t), g) in wc.iter().zip(tc).zip(xc) {
        for l in 0..LANES {
            sgx[l] += g[l] * (w[l] - t[l]);
        }
    }
    for ((w, t), g) in wc.iter().zip(tc).zip(yc) {
        for l in 0..LANES {
            sgy[l] += g[l] * (w[l] - t[l]);
        }
    }
    for (l, (((w, t), gx), gy)) in wr.iter().zip(tr).zip(xr).zip(yr).enumerate() {
        let d = w - t;
        sd[l] += d;
        sdd[l] += d * d;
        sgx[l] += gx * d;
        sgy[l] += gy * d;
    }
    out.map(|a| a.iter().sum())
}

/// [`residual_sums`] of a loaded template.
fn template_sums(tmpl: &Template, warped: &[f32]) -> [f32; 4] {
    residual_sums(&tmpl.t, &tmpl.gx, &tmpl.gy, warped)
}

/// Mean-normalised (or plain) sum of squared residuals from [`residual_sums`], and the mean.
fn ssd_of(sums: [f32; 4], n: f32, mean_normalisation: bool) -> (f32, f32) {
    if mean_normalisation {
        let mean = sums[0] / n;
        ((sums[1] - sums[0] * mean).max(0.0), mean)
    } else {
        (sums[1], 0.0)
    }
}

/// The clamped columns and row offsets of a patch sampled past the padded border.
#[derive(Default)]
struct BorderIndex {
    cols: Vec<usize>,
    rows: Vec<usize>,
}

/// Per-row working buffers.
struct Scratch {
    tmpl: Template,
    warped: Vec<f32>,
    border: BorderIndex,
}

impl Scratch {
    fn new(size: usize) -> Self {
        Self {
            tmpl: Template::new(size),
            warped: vec![0.0; size * size],
            border: BorderIndex::default(),
        }
    }
}

/// `iterations` inverse-compositional Gauss–Newton steps of the loaded template from `u`,
/// returning the flow (DIS's divergence guard: a patch that wandered more than its own size
/// from `start` goes back to `start`).
fn iterate(
    lv: &LevelImages<'_>,
    (x0, y0): (usize, usize),
    scratch: &mut Scratch,
    mut u: [f32; 2],
    start: [f32; 2],
    iterations: usize,
    cfg: &FastFlowConfig,
) -> [f32; 2] {
    let size = cfg.patch_size;
    let n = (size * size) as f32;
    let Scratch {
        tmpl,
        warped,
        border,
    } = scratch;
    for _ in 0..iterations {
        sample_patch(lv.img2, (x0, y0), size, u, warped, border);
        let s = template_sums(tmpl, warped);
        let (mut bx, mut by) = (s[2], s[3]);
        if cfg.mean_normalisation {
            let mean = s[0] / n;
            bx -= mean * tmpl.sum_gx;
            by -= mean * tmpl.sum_gy;
        }
        let [a, b, c] = tmpl.inv;
        let (dx, dy) = (a * bx + b * by, b * bx + c * by);
        u = [u[0] - dx, u[1] - dy];
        if dx * dx + dy * dy < cfg.min_step_px * cfg.min_step_px {
            break;
        }
    }
    let wandered = (u[0] - start[0]).hypot(u[1] - start[1]);
    // a NaN (a diverged step) goes back too
    if wandered.is_nan() || wandered > size as f32 {
        u = start;
    }
    u
}

/// The template's residual at `u`: `(ssd, mean)`.
fn residual_at(
    lv: &LevelImages<'_>,
    (x0, y0): (usize, usize),
    scratch: &mut Scratch,
    u: [f32; 2],
    cfg: &FastFlowConfig,
) -> (f32, f32) {
    let size = cfg.patch_size;
    sample_patch(
        lv.img2,
        (x0, y0),
        size,
        u,
        &mut scratch.warped,
        &mut scratch.border,
    );
    let s = template_sums(&scratch.tmpl, &scratch.warped);
    ssd_of(s, (size * size) as f32, cfg.mean_normalisation)
}

/// Aligns every patch of `grid` from the flow `start(col, row)` (level pixels), returning the
/// fits row-major (`row * grid.xs.len() + col`).
pub fn align(
    lv: &LevelImages<'_>,
    grid: &PatchGrid,
    start: &[[f32; 2]],
    cfg: &FastFlowConfig,
) -> Vec<PatchFit> {
    let (nx, ny) = (grid.xs.len(), grid.ys.len());
    let size = cfg.patch_size;
    let first = if cfg.propagation {
        cfg.iterations.div_ceil(2)
    } else {
        cfg.iterations
    };
    // first half: every patch from its start
    let mut flows = vec![[0.0_f32; 2]; nx * ny];
    flows
        .par_chunks_mut(nx.max(1))
        .enumerate()
        .for_each(|(row, out)| {
            let mut scratch = Scratch::new(size);
            for (col, o) in out.iter_mut().enumerate() {
                let at = (grid.xs[col], grid.ys[row]);
                scratch.tmpl.load(lv, at.0, at.1, size, cfg);
                let s = start[row * nx + col];
                *o = iterate(lv, at, &mut scratch, s, s, first, cfg);
            }
        });
    let rest = cfg.iterations - first;
    let mut fits = vec![PatchFit::default(); nx * ny];
    fits.par_chunks_mut(nx.max(1))
        .enumerate()
        .for_each(|(row, out)| {
            let mut scratch = Scratch::new(size);
            for (col, o) in out.iter_mut().enumerate() {
                let at = (grid.xs[col], grid.ys[row]);
                scratch.tmpl.load(lv, at.0, at.1, size, cfg);
                let own = flows[row * nx + col];
                let mut u = own;
                if cfg.propagation {
                    u = propagated(lv, at, &mut scratch, &flows, (col, row), (nx, ny), cfg);
                }
                if rest > 0 {
                    u = iterate(lv, at, &mut scratch, u, u, rest, cfg);
                }
                let (ssd, mean) = residual_at(lv, at, &mut scratch, u, cfg);
                let dof = (size * size) as f32 - if cfg.mean_normalisation { 3.0 } else { 2.0 };
                *o = PatchFit {
                    flow: u,
                    mean_diff: mean,
                    variance: ssd / dof,
                    hessian: scratch.tmpl.hessian,
                };
            }
        });
    fits
}

/// DIS's spatial propagation: of the patch's own flow and its four grid neighbours' (from the
/// snapshot `flows`), the one whose residual is lowest (ties: its own, then left, right, up,
/// down). A neighbour closer than `propagation_min_px` (L1) to the best so far is not tried:
/// the iterations that follow reach it anyway.
fn propagated(
    lv: &LevelImages<'_>,
    at: (usize, usize),
    scratch: &mut Scratch,
    flows: &[[f32; 2]],
    (col, row): (usize, usize),
    (nx, ny): (usize, usize),
    cfg: &FastFlowConfig,
) -> [f32; 2] {
    let own = flows[row * nx + col];
    let mut best = own;
    let mut best_ssd = f32::INFINITY;
    let neighbours = [
        (col > 0).then(|| flows[row * nx + col - 1]),
        (col + 1 < nx).then(|| flows[row * nx + col + 1]),
        (row > 0).then(|| flows[(row - 1) * nx + col]),
        (row + 1 < ny).then(|| flows[(row + 1) * nx + col]),
    ];
    for cand in neighbours.into_iter().flatten() {
        if (cand[0] - best[0]).abs() + (cand[1] - best[1]).abs() < cfg.propagation_min_px {
            continue;
        }
        if best_ssd.is_infinite() {
            best_ssd = residual_at(lv, at, scratch, own, cfg).0;
        }
        let ssd = residual_at(lv, at, scratch, cand, cfg).0;
        if ssd < best_ssd {
            best_ssd = ssd;
            best = cand;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_cover_every_pixel() {
        assert_eq!(patch_positions(20, 8, 4), vec![0, 4, 8, 12]);
        assert_eq!(patch_positions(21, 8, 4), vec![0, 4, 8, 12, 13]);
        assert_eq!(patch_positions(7, 8, 4), Vec::<usize>::new());
        assert_eq!(patch_positions(8, 8, 4), vec![0]);
    }

    #[test]
    fn a_patch_finds_a_subpixel_shift() {
        // a smooth texture moved by (1.3, -0.6) px
        let f = |x: f32, y: f32| {
            100.0 + 40.0 * (0.31 * x).sin() * (0.23 * y).cos() + 30.0 * (0.17 * x + 0.29 * y).sin()
        };
        let (w, h) = (48, 40);
        let img1 = GrayImage::from_fn(w, h, |x, y| f(x as f32, y as f32));
        let img2 = GrayImage::from_fn(w, h, |x, y| f(x as f32 - 1.3, y as f32 + 0.6));
        let (gx, gy) = crate::ops::gradients(&img1);
        let padded = Padded::new(&img2, 8);
        let lv = LevelImages {
            img1: &img1,
            gx: &gx,
            gy: &gy,
            img2: &padded,
        };
        let cfg = FastFlowConfig {
            iterations: 30,
            damping: 0.0,
            ..FastFlowConfig::default()
        };
        let grid = PatchGrid::new(w, h, cfg.patch_size, cfg.patch_stride);
        let fits = align(&lv, &grid, &vec![[0.0; 2]; grid.len()], &cfg);
        let centre = fits[fits.len() / 2 + grid.xs.len() / 2];
        assert!((centre.flow[0] - 1.3).abs() < 0.05, "{:?}", centre.flow);
        assert!((centre.flow[1] + 0.6).abs() < 0.05, "{:?}", centre.flow);
        assert!(centre.hessian[0] > 0.0 && centre.hessian[2] > 0.0);
    }
}
