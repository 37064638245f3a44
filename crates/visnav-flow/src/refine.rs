//! Dense Lucas–Kanade refinement at full resolution: per pixel, Gauss–Newton steps on the
//! brightness constancy over a `(2r+1)²` window (normal equations box-filtered, Tikhonov
//! damped), starting from the upsampled matching flow. Brings the 1/3-resolution matches to
//! sub-pixel accuracy.

use rayon::prelude::*;
use visnav_core::bilinear::Bilinear;
use visnav_core::{GrayImage, Information2};

use crate::config::RefinementConfig;
use crate::ops::{box_filter, gradients};

/// The images the refinement works on: `I - highpass * box_mean(I)` (or copies when
/// `highpass` is 0).
#[must_use]
pub fn prefilter(
    img1: &GrayImage,
    img2: &GrayImage,
    cfg: &RefinementConfig,
) -> (GrayImage, GrayImage) {
    (prefilter_one(img1, cfg), prefilter_one(img2, cfg))
}

/// One image of [`prefilter`].
#[must_use]
pub fn prefilter_one(img: &GrayImage, cfg: &RefinementConfig) -> GrayImage {
    if cfg.highpass <= 0.0 {
        return img.clone();
    }
    let (w, h) = (img.width(), img.height());
    let mean = box_filter(img.data(), w, h, 1, cfg.highpass_radius);
    let data = img
        .data()
        .iter()
        .zip(&mean)
        .map(|(v, m)| v - cfg.highpass * m)
        .collect();
    GrayImage::from_vec(w, h, data).unwrap_or_else(|| img.clone())
}

/// Refines `flow` (full resolution, `img1` to `img2`) in place.
pub fn refine(img1: &GrayImage, img2: &GrayImage, flow: &mut [[f32; 2]], cfg: &RefinementConfig) {
    let w = img1.width();
    let h = img1.height();
    if cfg.iterations == 0 || w < 2 || h < 2 {
        return;
    }
    let (g1x, g1y) = gradients(img1);
    let warp = warp_sources(img2);
    let i1 = img1.data();
    let (g1x, g1y) = (g1x.data(), g1y.data());
    let mut terms = vec![0.0_f32; w * h * 5];
    for _ in 0..cfg.iterations {
        terms
            .par_chunks_mut(w * 5)
            .zip(flow.par_chunks(w))
            .enumerate()
            .for_each(|(y, (trow, frow))| {
                lucas_kanade_row(y, trow, frow, [i1, g1x, g1y], &warp, w, h);
            });
        let sums = box_filter(&terms, w, h, 5, cfg.window_radius);
        flow.par_iter_mut().enumerate().for_each(|(i, f)| {
            let s = &sums[i * 5..i * 5 + 5];
            let a = s[0] + cfg.damping;
            let b = s[1];
            let c = s[2] + cfg.damping;
            let det = a * c - b * b;
            if det <= 1e-6 {
                return;
            }
            let du = -(c * s[3] - b * s[4]) / det;
            let dv = -(a * s[4] - b * s[3]) / det;
            // a step clearly shorter than the limit needs no (slow, libm) `hypot`: the squared
            // length carries at most a few ulps of error, far inside the 0.1 % margin, so the
            // result is the one `hypot` would give
            let m = cfg.max_step_px;
            let k = if du * du + dv * dv < 0.999 * m * m {
                1.0
            } else {
                let norm = du.hypot(dv);
                if norm > m { m / norm } else { 1.0 }
            };
            f[0] += du * k;
            f[1] += dv * k;
        });
    }
}

/// Image 2 and its x and y gradients interleaved per pixel, `[I2, ∂x I2, ∂y I2, 0]`: a bilinear
/// sample of all three at a warped point reads four 16-byte corners instead of twelve scattered
/// floats (the refinements' sampling is gather-bound; same values, same arithmetic per channel).
fn warp_sources(img2: &GrayImage) -> Vec<[f32; 4]> {
    let (g2x, g2y) = gradients(img2);
    img2.data()
        .iter()
        .zip(g2x.data())
        .zip(g2y.data())
        .map(|((i, gx), gy)| [*i, *gx, *gy, 0.0])
        .collect()
}

/// [`Bilinear::sample_lerp`] of every channel of `data` at once (the same two-lerp arithmetic per
/// channel, so the same bits as four separate samples).
#[inline(always)]
fn sample_lerp4(s: &Bilinear, data: &[[f32; 4]]) -> [f32; 4] {
    let i = s.i00;
    let (a, b) = (data[i], data[i + s.dx]);
    let (c, d) = (data[i + s.dy], data[i + s.dy + s.dx]);
    std::array::from_fn(|k| {
        let top = a[k] + (b[k] - a[k]) * s.fx;
        let bottom = c[k] + (d[k] - c[k]) * s.fx;
        top + (bottom - top) * s.fy
    })
}

visnav_core::simd_kernel! {
    /// Row `y` of the Lucas–Kanade normal-equation terms `gx², gx gy, gy², gx r, gy r` (5 per
    /// pixel) of [`refine`]; `im` = image 1 and its x and y gradients, `warp` = image 2 and
    /// its gradients interleaved ([`warp_sources`]).
    fn lucas_kanade_row(
        y: usize,
        trow: &mut [f32],
        frow: &[[f32; 2]],
        im: [&[f32]; 3],
        warp: &[[f32; 4]],
        w: usize,
        h: usize,
    ) {
        let [i1, g1x, g1y] = im;
        for x in 0..w {
            let [u, v] = frow[x];
            let xs = f64::from(x as f32 + u);
            let ys = f64::from(y as f32 + v);
            let t = &mut trow[x * 5..x * 5 + 5];
            if xs < 0.0 || ys < 0.0 || xs > (w - 1) as f64 || ys > (h - 1) as f64 {
                t.fill(0.0);
                continue;
            }
            // the weights of `GrayImage::bilinear_clamped`, once for three images
            let s = Bilinear::clamped_f64(xs, ys, w, h);
            let i = y * w + x;
            // per channel the same arithmetic as three separate samples
            let [s2, s2x, s2y, _] = s.sample(warp);
            let gx = 0.5 * (s2x + g1x[i]);
            let gy = 0.5 * (s2y + g1y[i]);
            let r = s2 - i1[i];
            t[0] = gx * gx;
            t[1] = gx * gy;
            t[2] = gy * gy;
            t[3] = gx * r;
            t[4] = gy * r;
        }
    }
}

/// Per-pixel data of one colour of the red-black checkerboard, stored row by row with a padded
/// stride so that the neighbours of a pixel of one colour are contiguous slices of the other
/// colour's arrays (pixel `(x, y)` of colour `(x + y) % 2` sits at `y * stride + x / 2 + 1`).
#[derive(Clone, Default)]
struct Colour {
    u: Vec<f32>,
    v: Vec<f32>,
    /// The lagged robust smoothness weight of each pixel (zero in the padding): the weight
    /// between two neighbours is `alpha / 2 * (ws + ws of the neighbour)`, computed in the sweep
    /// rather than stored four times.
    ws: Vec<f32>,
    a12: Vec<f32>,
    c1: Vec<f32>,
    c2: Vec<f32>,
    inv1: Vec<f32>,
    inv2: Vec<f32>,
}

/// One red-black half sweep: updates every pixel of colour `c` (its `u`, `v`) from the current
/// values of the other colour `o`.
fn half_sweep(
    c: &mut Colour,
    o: &Colour,
    colour: usize,
    (w, h, stride): (usize, usize, usize),
    half_alpha: f32,
    omega: f32,
) {
    let Colour {
        u,
        v,
        ws,
        a12,
        c1,
        c2,
        inv1,
        inv2,
    } = c;
    u.par_chunks_mut(stride)
        .zip(v.par_chunks_mut(stride))
        .enumerate()
        .for_each(|(y, (urow, vrow))| {
            let p = (colour + y) % 2;
            let count = (w - p).div_ceil(2);
            let row = y * stride;
            let up = y.saturating_sub(1) * stride;
            let dn = (y + 1).min(h - 1) * stride;
            let r = row + 1..row + 1 + count;
            let own_ws = &ws[r.clone()];
            let (a12, c1, c2) = (&a12[r.clone()], &c1[r.clone()], &c2[r.clone()]);
            let (inv1, inv2) = (&inv1[r.clone()], &inv2[r]);
            let ol_u = &o.u[row + p..row + p + count];
            let or_u = &o.u[row + 1 + p..row + 1 + p + count];
            let ou_u = &o.u[up + 1..up + 1 + count];
            let od_u = &o.u[dn + 1..dn + 1 + count];
            let ol_v = &o.v[row + p..row + p + count];
            let or_v = &o.v[row + 1 + p..row + 1 + p + count];
            let ou_v = &o.v[up + 1..up + 1 + count];
            let od_v = &o.v[dn + 1..dn + 1 + count];
            let ol_w = &o.ws[row + p..row + p + count];
            let or_w = &o.ws[row + 1 + p..row + 1 + p + count];
            let ou_w = &o.ws[up + 1..up + 1 + count];
            let od_w = &o.ws[dn + 1..dn + 1 + count];
            // no neighbour above the first row or below the last (left and right of the row
            // ends lies the other colour's zero padding: weight times a zero flow)
            let vertical = [f32::from(u8::from(y > 0)), f32::from(u8::from(y + 1 < h))];
            sweep_row(
                &mut urow[1..=count],
                &mut vrow[1..=count],
                own_ws,
                [ol_w, or_w, ou_w, od_w],
                (half_alpha, vertical),
                [a12, c1, c2, inv1, inv2],
                [ol_u, or_u, ou_u, od_u],
                [ol_v, or_v, ou_v, od_v],
                omega,
            );
        });
}

visnav_core::simd_kernel! {
    /// The Gauss–Seidel update of one row of one colour: `ws` = the pixels' smoothness weights,
    /// `nw` = those of the left, right, upper and lower neighbour (the weight towards a neighbour
    /// is `alpha / 2 * (ws + nw)`, times `vertical[0]` / `vertical[1]` (0 or 1) upwards /
    /// downwards), `c` = `a12, c1, c2, 1/diag1, 1/diag2`, `nu` / `nv` = the neighbours' `u` / `v`
    /// in the same order (slices as long as `urow`).
    fn sweep_row(
        urow: &mut [f32],
        vrow: &mut [f32],
        ws: &[f32],
        nw: [&[f32]; 4],
        weights: (f32, [f32; 2]),
        c: [&[f32]; 5],
        nu: [&[f32]; 4],
        nv: [&[f32]; 4],
        omega: f32,
    ) {
        let n = urow.len();
        let (half_alpha, [up, down]) = weights;
        let ws = &ws[..n];
        let [nl, nr, nu_w, nd] = nw.map(|s| &s[..n]);
        let [a12, c1, c2, inv1, inv2] = c.map(|s| &s[..n]);
        let [ol_u, or_u, ou_u, od_u] = nu.map(|s| &s[..n]);
        let [ol_v, or_v, ou_v, od_v] = nv.map(|s| &s[..n]);
        let vrow = &mut vrow[..n];
        // the neighbour sums are written out in both loops on purpose: as a shared closure they
        // stop vectorising (the refinement measured 2.3x slower)
        if omega == 1.0 {
            for j in 0..n {
                let wl = half_alpha * (ws[j] + nl[j]);
                let wr = half_alpha * (ws[j] + nr[j]);
                let wu = half_alpha * (ws[j] + nu_w[j]) * up;
                let wd = half_alpha * (ws[j] + nd[j]) * down;
                let su = wl * ol_u[j] + wr * or_u[j] + wu * ou_u[j] + wd * od_u[j];
                let sv = wl * ol_v[j] + wr * or_v[j] + wu * ou_v[j] + wd * od_v[j];
                let tu = (c1[j] - a12[j] * vrow[j] + su) * inv1[j];
                let tv = (c2[j] - a12[j] * tu + sv) * inv2[j];
                urow[j] = tu;
                vrow[j] = tv;
            }
        } else {
            // successive over-relaxation: move past the Gauss–Seidel value by `omega`
            for j in 0..n {
                let wl = half_alpha * (ws[j] + nl[j]);
                let wr = half_alpha * (ws[j] + nr[j]);
                let wu = half_alpha * (ws[j] + nu_w[j]) * up;
                let wd = half_alpha * (ws[j] + nd[j]) * down;
                let su = wl * ol_u[j] + wr * or_u[j] + wu * ou_u[j] + wd * od_u[j];
                let sv = wl * ol_v[j] + wr * or_v[j] + wu * ou_v[j] + wd * od_v[j];
                let gu = (c1[j] - a12[j] * vrow[j] + su) * inv1[j];
                let tu = urow[j] + omega * (gu - urow[j]);
                let gv = (c2[j] - a12[j] * tu + sv) * inv2[j];
                vrow[j] += omega * (gv - vrow[j]);
                urow[j] = tu;
            }
        }
    }
}

/// Variational refinement at full resolution (in the manner of the refinement of DIS, Kroeger et
/// al. 2016, after Brox et al. 2004): minimises `Σ ψ((I2(x + u) - I1(x))²) + alpha Σ ψ(|∇u|² +
/// |∇v|²)` with Charbonnier `ψ(s²) = sqrt(s² + ε²)`, linearised around the current flow (outer
/// fixed-point iterations with re-warping and lagged robust weights) and solved for the new flow
/// `t` by red-black Gauss–Seidel sweeps. Each pixel's data term is weighted by
/// `ζ² / (|∇I|² + ζ²)` ([`RefinementConfig::gradient_normalisation`]). Per pixel
/// `t_u (a11 + Σw) = a11 f_u + a12 f_v - b1 - a12 t_v + Σ w_j t_u,j` and symmetrically for `t_v`.
///
/// The two colours of the checkerboard are stored apart (`Colour`), so a half sweep touches
/// only the pixels it updates, in contiguous, branch-free, auto-vectorisable rows.
#[allow(clippy::too_many_lines)]
pub fn variational(
    img1: &GrayImage,
    img2: &GrayImage,
    flow: &mut [[f32; 2]],
    cfg: &RefinementConfig,
) {
    let w = img1.width();
    let h = img1.height();
    if cfg.variational_outer == 0 || w < 3 || h < 3 {
        return;
    }
    let (g1x, g1y) = gradients(img1);
    let warp = warp_sources(img2);
    let inputs = VariationalInputs {
        i1: img1.data(),
        g1x: g1x.data(),
        g1y: g1y.data(),
        warp: &warp,
    };
    let stride = w.div_ceil(2) + 2;
    // the working arrays of the calling thread, kept from call to call (a fresh ~25 MB a
    // KITTI-sized call is page-faulted and zeroed by the kernel every time: 6 % of the mono
    // pipeline's CPU); a nested call on the same thread gets fresh ones
    SCRATCH.with(|cell| match cell.try_borrow_mut() {
        Ok(mut scratch) => {
            scratch.reset(w * h, stride * h);
            let Scratch { coef, ws, colours } = &mut *scratch;
            solve_outer(flow, &inputs, (coef, ws, colours), cfg, (w, h, stride));
        }
        Err(_) => {
            let mut scratch = Scratch::default();
            scratch.reset(w * h, stride * h);
            let Scratch { coef, ws, colours } = &mut scratch;
            solve_outer(flow, &inputs, (coef, ws, colours), cfg, (w, h, stride));
        }
    });
}

/// The per-call working arrays of [`variational`]: the coefficients `a11, a12, a22, c1, c2`
/// (per image row five planes of `w` values, [`COEF_PLANES`]), the lagged robust smoothness
/// weight, and the two colours of the checkerboard.
#[derive(Default)]
struct Scratch {
    coef: Vec<f32>,
    ws: Vec<f32>,
    colours: [Colour; 2],
}

impl Scratch {
    /// Sized for `n` pixels and colour arrays of `len`, all zero (as freshly allocated).
    fn reset(&mut self, n: usize, len: usize) {
        let zero = |v: &mut Vec<f32>, len: usize| {
            v.clear();
            v.resize(len, 0.0);
        };
        zero(&mut self.coef, COEF_PLANES * n);
        zero(&mut self.ws, n);
        for c in &mut self.colours {
            for v in [
                &mut c.u,
                &mut c.v,
                &mut c.ws,
                &mut c.a12,
                &mut c.c1,
                &mut c.c2,
                &mut c.inv1,
                &mut c.inv2,
            ] {
                zero(v, len);
            }
        }
    }
}

thread_local! {
    /// [`variational`]'s working arrays, one set per thread.
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// The images [`variational`] samples: image 1 and its gradients, image 2 and its gradients
/// interleaved ([`warp_sources`]).
struct VariationalInputs<'a> {
    i1: &'a [f32],
    g1x: &'a [f32],
    g1y: &'a [f32],
    warp: &'a [[f32; 4]],
}

/// The outer iterations of [`variational`] on zeroed working arrays.
#[allow(clippy::type_complexity)]
fn solve_outer(
    flow: &mut [[f32; 2]],
    inputs: &VariationalInputs<'_>,
    (coef, ws, colours): (&mut [f32], &mut [f32], &mut [Colour; 2]),
    cfg: &RefinementConfig,
    (w, h, stride): (usize, usize, usize),
) {
    let VariationalInputs { i1, g1x, g1y, warp } = *inputs;
    let alpha = cfg.variational_alpha;
    let zeta2 = cfg.gradient_normalisation * cfg.gradient_normalisation;
    for _ in 0..cfg.variational_outer {
        coef.par_chunks_mut(COEF_PLANES * w)
            .zip(ws.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (crow, wrow))| {
                coefficient_row(y, crow, wrow, flow, [i1, g1x, g1y], warp, w, h, zeta2);
            });
        // scatter into the two colours: smoothness weights, coefficients, reciprocal diagonals
        // (with the weights towards the four neighbours, zero at the border) and the start flow
        for (colour, col) in colours.iter_mut().enumerate() {
            let Colour {
                u,
                v,
                ws: ws_col,
                a12,
                c1,
                c2,
                inv1,
                inv2,
            } = col;
            u.par_chunks_mut(stride)
                .zip(v.par_chunks_mut(stride))
                .zip(ws_col.par_chunks_mut(stride))
                .zip(a12.par_chunks_mut(stride))
                .zip(c1.par_chunks_mut(stride))
                .zip(c2.par_chunks_mut(stride))
                .zip(inv1.par_chunks_mut(stride))
                .zip(inv2.par_chunks_mut(stride))
                .enumerate()
                .for_each(|(y, (((((((u, v), wsc), a12), c1), c2), inv1), inv2))| {
                    scatter_row(
                        y,
                        colour,
                        [u, v, wsc, a12, c1, c2, inv1, inv2],
                        coef,
                        ws,
                        flow,
                        alpha,
                        w,
                        h,
                    );
                });
        }
        for _ in 0..cfg.variational_inner {
            let [red, black] = &mut *colours;
            half_sweep(red, black, 0, (w, h, stride), alpha * 0.5, cfg.sor_omega);
            half_sweep(black, red, 1, (w, h, stride), alpha * 0.5, cfg.sor_omega);
        }
        let m = cfg.max_step_px;
        flow.par_chunks_mut(w).enumerate().for_each(|(y, frow)| {
            for (x, f) in frow.iter_mut().enumerate() {
                let col = &colours[(x + y) % 2];
                let k = y * stride + x / 2 + 1;
                f[0] += (col.u[k] - f[0]).clamp(-m, m);
                f[1] += (col.v[k] - f[1]).clamp(-m, m);
            }
        });
    }
}

visnav_core::simd_kernel! {
    /// Row `y` of colour `colour` of [`variational`]'s red-black arrays ([`Colour`], in field
    /// order): the flow to start from, the pixels' smoothness weights, the coefficients and the
    /// reciprocal diagonals (which hold the weights towards the four neighbours, zero at the
    /// border).
    fn scatter_row(
        y: usize,
        colour: usize,
        out: [&mut [f32]; 8],
        coef: &[f32],
        ws: &[f32],
        flow: &[[f32; 2]],
        alpha: f32,
        w: usize,
        h: usize,
    ) {
        let [u, v, wsc, a12, c1, c2, inv1, inv2] = out;
        let p = (colour + y) % 2;
        if p >= w {
            return;
        }
        let count = (w - p).div_ceil(2);
        let row = y * w;
        let planes = &coef[y * COEF_PLANES * w..(y + 1) * COEF_PLANES * w];
        // the weight towards a neighbour (`l, r, t, b`, zero where there is none) and the slot
        // of one pixel, the general form for the row's first and last pixel
        let general = |x: usize, o: &mut [&mut [f32]; 8]| {
            let i = row + x;
            let k = x / 2 + 1;
            let smooth = |j: usize| alpha * 0.5 * (ws[i] + ws[j]);
            let l = if x > 0 { smooth(i - 1) } else { 0.0 };
            let r = if x + 1 < w { smooth(i + 1) } else { 0.0 };
            let t = if y > 0 { smooth(i - w) } else { 0.0 };
            let b = if y + 1 < h { smooth(i + w) } else { 0.0 };
            let sw = l + r + t + b;
            let [ca11, ca12, ca22, cc1, cc2] = [0, 1, 2, 3, 4].map(|q| planes[q * w + x]);
            o[2][k] = ws[i];
            o[3][k] = ca12;
            o[4][k] = cc1;
            o[5][k] = cc2;
            o[6][k] = 1.0 / (ca11 + sw + 1e-6);
            o[7][k] = 1.0 / (ca22 + sw + 1e-6);
            o[0][k] = flow[i][0];
            o[1][k] = flow[i][1];
        };
        let mut o = [u, v, wsc, a12, c1, c2, inv1, inv2];
        // slots m (pixel x = p + 2m, slot m + 1) with both horizontal neighbours
        let first = usize::from(p == 0);
        let last = if p + 2 * (count - 1) + 1 < w {
            count
        } else {
            count - 1
        };
        for m in (0..first).chain(last.max(first)..count) {
            general(p + 2 * m, &mut o);
        }
        if last <= first {
            return;
        }
        // the interior, branch-free: a missing upper or lower neighbour contributes its
        // (finite, non-negative) weight times zero, the same +0.0 as the general form
        let (up, fu) = if y > 0 { (row - w, 1.0) } else { (row, 0.0) };
        let (dn, fd) = if y + 1 < h { (row + w, 1.0) } else { (row, 0.0) };
        let [u, v, wsc, a12, c1, c2, inv1, inv2] = o;
        for m in first..last {
            let x = p + 2 * m;
            let i = row + x;
            let k = m + 1;
            let wsi = ws[i];
            let l = alpha * 0.5 * (wsi + ws[i - 1]);
            let r = alpha * 0.5 * (wsi + ws[i + 1]);
            let t = alpha * 0.5 * (wsi + ws[up + x]) * fu;
            let b = alpha * 0.5 * (wsi + ws[dn + x]) * fd;
            let sw = l + r + t + b;
            wsc[k] = wsi;
            a12[k] = planes[w + x];
            c1[k] = planes[3 * w + x];
            c2[k] = planes[4 * w + x];
            inv1[k] = 1.0 / (planes[x] + sw + 1e-6);
            inv2[k] = 1.0 / (planes[2 * w + x] + sw + 1e-6);
            u[k] = flow[i][0];
            v[k] = flow[i][1];
        }
    }
}

visnav_core::simd_kernel! {
    /// Row `y` of the linearised data term of [`variational`] (`a11, a12, a22, c1, c2` into the
    /// five planes of `crow`, [`COEF_PLANES`]) and of the lagged robust smoothness weight (`wrow`). `im` = image 1 and its
    /// x and y gradients, `warp` = image 2 and its gradients interleaved ([`warp_sources`]).
    fn coefficient_row(
        y: usize,
        crow: &mut [f32],
        wrow: &mut [f32],
        flow: &[[f32; 2]],
        im: [&[f32]; 3],
        warp: &[[f32; 4]],
        w: usize,
        h: usize,
        zeta2: f32,
    ) {
        let [i1, g1x, g1y] = im;
        let eps2 = 1e-6_f32;
        let (wf, hf) = ((w - 1) as f32, (h - 1) as f32);
        let row = &flow[y * w..(y + 1) * w];
        // blocks of pixels: the bilinear gathers first (scalar), then the data term's arithmetic
        // (square roots, divisions) in a branch-free loop the compiler vectorises; the same
        // operations per pixel as one fused loop, so the same bits
        let mut x0 = 0;
        while x0 < w {
            let n = COEF_BLOCK.min(w - x0);
            let mut t = DataTermBlock::default();
            for j in 0..n {
                let x = x0 + j;
                let i = y * w + x;
                let [u, v] = row[x];
                let xs = x as f32 + u;
                let ys = y as f32 + v;
                t.inside[j] = xs >= 0.0 && ys >= 0.0 && xs <= wf && ys <= hf;
                if t.inside[j] {
                    let s = Bilinear::clamped_f32(xs, ys, w, h);
                    let [s2, s2x, s2y, _] = sample_lerp4(&s, warp);
                    t.iz[j] = s2 - i1[i];
                    t.ix[j] = 0.5 * (s2x + g1x[i]);
                    t.iy[j] = 0.5 * (s2y + g1y[i]);
                }
            }
            t.solve(&row[x0..x0 + n], crow, x0, zeta2);
            x0 += n;
        }
        let below = &flow[(y + 1).min(h - 1) * w..][..w];
        for x in 0..w {
            let [u, v] = row[x];
            let fx = row[(x + 1).min(w - 1)];
            let fy = below[x];
            let g2 = (fx[0] - u).powi(2)
                + (fx[1] - v).powi(2)
                + (fy[0] - u).powi(2)
                + (fy[1] - v).powi(2);
            wrow[x] = 0.5 / (g2 + eps2).sqrt().max(0.05);
        }
    }
}

/// Pixels per block of [`coefficient_row`].
const COEF_BLOCK: usize = 64;

/// Planes of [`variational`]'s coefficients: per image row `a11`, `a12`, `a22`, `c1`, `c2`, each
/// `w` values (contiguous stores in [`coefficient_row`], stride-2 loads in [`scatter_row`]).
const COEF_PLANES: usize = 5;

/// The sampled data term of a block of pixels of [`coefficient_row`]: whether the warped point
/// is inside image 2, the temporal difference `iz` and the mean gradients `ix`, `iy` (zero
/// outside).
struct DataTermBlock {
    inside: [bool; COEF_BLOCK],
    iz: [f32; COEF_BLOCK],
    ix: [f32; COEF_BLOCK],
    iy: [f32; COEF_BLOCK],
}

impl Default for DataTermBlock {
    fn default() -> Self {
        Self {
            inside: [false; COEF_BLOCK],
            iz: [0.0; COEF_BLOCK],
            ix: [0.0; COEF_BLOCK],
            iy: [0.0; COEF_BLOCK],
        }
    }
}

impl DataTermBlock {
    /// The linearised data term `a11, a12, a22, c1, c2` of each pixel of the block (`flow` as
    /// long as the block), into columns `x0..` of the five planes of the row `crow`
    /// ([`COEF_PLANES`]): Charbonnier weight `wd = norm / (2 sqrt(iz² + 1))`, times the
    /// gradient normalisation `norm` when `zeta2 > 0`; zero outside image 2.
    #[inline(always)]
    fn solve(&self, flow: &[[f32; 2]], crow: &mut [f32], x0: usize, zeta2: f32) {
        let eps_d2 = 1.0_f32; // intensity levels²
        let n = flow.len();
        let w = crow.len() / COEF_PLANES;
        let (o11, rest) = crow.split_at_mut(w);
        let (o12, rest) = rest.split_at_mut(w);
        let (o22, rest) = rest.split_at_mut(w);
        let (oc1, oc2) = rest.split_at_mut(w);
        let (o11, o12, o22) = (
            &mut o11[x0..x0 + n],
            &mut o12[x0..x0 + n],
            &mut o22[x0..x0 + n],
        );
        let (oc1, oc2) = (&mut oc1[x0..x0 + n], &mut oc2[x0..x0 + n]);
        let (inside, iz, ix, iy) = (
            &self.inside[..n],
            &self.iz[..n],
            &self.ix[..n],
            &self.iy[..n],
        );
        let flow = &flow[..n];
        for j in 0..n {
            let (iz, ix, iy) = (iz[j], ix[j], iy[j]);
            let [u, v] = flow[j];
            let norm = if zeta2 > 0.0 {
                zeta2 / (ix * ix + iy * iy + zeta2)
            } else {
                1.0
            };
            let wd = norm * 0.5 / (iz * iz + eps_d2).sqrt();
            let (a11, a12, a22) = (wd * ix * ix, wd * ix * iy, wd * iy * iy);
            let (b1, b2) = (wd * ix * iz, wd * iy * iz);
            let keep = inside[j];
            o11[j] = if keep { a11 } else { 0.0 };
            o12[j] = if keep { a12 } else { 0.0 };
            o22[j] = if keep { a22 } else { 0.0 };
            oc1[j] = if keep { a11 * u + a12 * v - b1 } else { 0.0 };
            oc2[j] = if keep { a22 * v + a12 * u - b2 } else { 0.0 };
        }
    }
}

/// Adds `residual_variance_px2 * (r̄ / residual_scale)²` to the covariance of every pixel, where
/// `r̄` is the mean absolute brightness residual `|I2(x + u) - I1(x)|` over a 7x7 window after
/// refinement: variance the cost-slice fit cannot see (occlusions, non-rigid change).
#[must_use]
pub fn inflate_by_residual(
    img1: &GrayImage,
    img2: &GrayImage,
    flow: &[[f32; 2]],
    information: Vec<[f32; 3]>,
    cfg: &crate::config::UncertaintyConfig,
) -> Vec<[f32; 3]> {
    let w = img1.width();
    let h = img1.height();
    let res: Vec<f32> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let xs = f64::from(x as f32 + flow[i][0]);
            let ys = f64::from(y as f32 + flow[i][1]);
            (img2.bilinear_clamped(xs, ys) - img1.get(x, y)).abs()
        })
        .collect();
    let mean = box_filter(&res, w, h, 1, 3);
    information
        .into_par_iter()
        .zip(mean.par_iter())
        .map(|(m, r)| {
            let q = r / cfg.residual_scale;
            let extra = cfg.residual_variance_px2 * q * q;
            let Some(c) = Information2::from_array(m).covariance_px2() else {
                return m;
            };
            Information2::from_covariance_px2([c[0] + extra, c[1], c[2] + extra])
                .unwrap_or(Information2::from_array(m))
                .clamp_eigenvalues(cfg.min_information, cfg.max_information)
                .to_array()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interleaved_samples_are_bit_identical_to_separate_ones() {
        let (w, h) = (23, 17);
        let img = GrayImage::from_fn(w, h, |x, y| ((x * 37 + y * 91) % 101) as f32 * 0.731);
        let (gx, gy) = gradients(&img);
        let warp = warp_sources(&img);
        let planes = [img.data(), gx.data(), gy.data()];
        for k in 0..400 {
            let x = (k as f32 * 0.377).rem_euclid(w as f32 + 4.0) - 2.0;
            let y = (k as f32 * 0.613).rem_euclid(h as f32 + 4.0) - 2.0;
            let s = Bilinear::clamped_f32(x, y, w, h);
            let lerp = sample_lerp4(&s, &warp);
            let s64 = Bilinear::clamped_f64(f64::from(x), f64::from(y), w, h);
            let weighted: [f32; 4] = s64.sample(&warp);
            for c in 0..3 {
                assert_eq!(lerp[c].to_bits(), s.sample_lerp(planes[c]).to_bits());
                assert_eq!(weighted[c].to_bits(), s64.sample(planes[c]).to_bits());
            }
        }
    }

    #[test]
    fn residual_inflation_lowers_information_only_where_images_disagree() {
        let (w, h) = (20, 10);
        let img1 = GrayImage::from_fn(w, h, |x, y| (x * 10 + y) as f32);
        // image 2 equals image 1 on the left half, differs by 20 levels on the right half
        let img2 = GrayImage::from_fn(w, h, |x, y| {
            (x * 10 + y) as f32 + if x >= 10 { 20.0 } else { 0.0 }
        });
        let flow = vec![[0.0_f32; 2]; w * h];
        let info = vec![[4.0_f32, 0.0, 4.0]; w * h];
        let cfg = crate::config::UncertaintyConfig {
            residual_variance_px2: 1.0,
            ..Default::default()
        };
        let out = inflate_by_residual(&img1, &img2, &flow, info, &cfg);
        assert!((out[5 * w + 2][0] - 4.0).abs() < 1e-4);
        // r̄ = 20, scale 10: variance 0.25 + 4 -> information 1 / 4.25
        assert!(
            (out[5 * w + 17][0] - 1.0 / 4.25).abs() < 1e-3,
            "{:?}",
            out[5 * w + 17]
        );
    }

    /// A low-contrast region (texture at 6 % contrast) moving by (1, 0.4) px beside a
    /// full-contrast one moving by (-1, 0): the refinement starts from zero flow. Mean
    /// end-point error inside the low-contrast region, away from its borders.
    fn low_contrast_error(cfg: &RefinementConfig) -> f64 {
        let (w, h) = (96, 64);
        let tex = crate::synthetic::Texture::new(7);
        let split = 48;
        let look = |x: f64, y: f64, left: bool| {
            let t = tex.at(x, y);
            if left { 127.5 + 0.06 * (t - 127.5) } else { t }
        };
        // image 2 at x shows image 1 at x - motion
        let img1 = GrayImage::from_fn(w, h, |x, y| look(x as f64, y as f64, x < split));
        let img2 = GrayImage::from_fn(w, h, |x, y| {
            if x < split {
                look(x as f64 - 1.0, y as f64 - 0.4, true)
            } else {
                look(x as f64 + 1.0, y as f64, false)
            }
        });
        let mut flow = vec![[0.0_f32; 2]; w * h];
        variational(&img1, &img2, &mut flow, cfg);
        let mut sum = 0.0;
        let mut n = 0;
        for y in 12..h - 12 {
            for x in 12..split - 12 {
                let [u, v] = flow[y * w + x];
                sum += f64::from(u - 1.0).hypot(f64::from(v - 0.4));
                n += 1;
            }
        }
        sum / f64::from(n)
    }

    #[test]
    fn gradient_normalisation_keeps_a_low_contrast_region_from_being_smoothed_over() {
        let plain = RefinementConfig {
            gradient_normalisation: 0.0,
            variational_alpha: 10.0,
            ..RefinementConfig::default()
        };
        let normalised = RefinementConfig {
            gradient_normalisation: 10.0,
            variational_alpha: 3.5,
            ..RefinementConfig::default()
        };
        let (e_plain, e_norm) = (low_contrast_error(&plain), low_contrast_error(&normalised));
        assert!(
            e_norm < 0.7 * e_plain,
            "normalised {e_norm:.3} px, plain {e_plain:.3} px"
        );
    }
}
