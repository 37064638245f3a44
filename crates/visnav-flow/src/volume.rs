//! The 4-D cost volume over a `(2R+1)²` label window per pixel (u8 costs, DCFlow), the optional
//! truncated L2 epipolar cost (§3.1), semi-global matching over the 2-D label space along four
//! scanline directions (DCFlow: P1 for label steps of one, P2 beyond, P2/3 on strong edges),
//! winner-take-all with parabolic sub-pixel refinement, and the bivariate Gaussian fit of eq. 1–4
//! to the regularised cost slice.
//!
//! The window of pixel `p` is centred on an integer prior `c(p)` (level pixels): label
//! `l = (lx, ly)` in `[-R, R]²` means the displacement `c(p) + l`. Along an SGM path from `q` to
//! `p` the same displacement is label `l + c(p) - c(q)` at `q`, so priors may vary per pixel.

use nalgebra::Matrix3;
use rayon::prelude::*;

use crate::descriptor::{self, Descriptors};

/// The fundamental matrix mapped into one level's pixel grid, with the truncated L2 cost.
#[derive(Debug, Clone, Copy)]
pub struct EpipolarLevel {
    /// Fundamental matrix in full-resolution pixels (`x2ᵀ F x1 = 0`).
    pub fundamental: Matrix3<f64>,
    /// Full-resolution coordinate of level pixel `i`: `scale * i + offset`.
    pub scale: f64,
    /// See `scale`.
    pub offset: f64,
    /// Cost per squared level pixel of distance.
    pub weight: f32,
    /// Truncation, u8 cost units.
    pub truncation: f32,
}

/// Inputs of one level's matching.
pub struct LevelProblem<'a> {
    /// Descriptors of the source image.
    pub d1: &'a Descriptors,
    /// Descriptors of the target image.
    pub d2: &'a Descriptors,
    /// Integer window centre per source pixel, level px.
    pub centres: &'a [[i32; 2]],
    /// Window half-width R.
    pub radius: usize,
    /// P2 per source pixel (already reduced on edges).
    pub p2: &'a [u16],
    /// P1.
    pub p1: u16,
    /// Cost of labels whose target leaves the image.
    pub outside_cost: u8,
    /// Optional epipolar cost.
    pub epipolar: Option<EpipolarLevel>,
    /// With the target's [`descriptor::HalfNorms`]: the half-label cost (see [`cost_volume`]).
    pub half: Option<&'a descriptor::HalfNorms>,
    /// What a half-label point gives up against a label, in dot-product units (so that a label
    /// wins a tie and the slice keeps its curvature where the descriptors match equally well).
    pub half_penalty: f32,
}

/// Fit parameters of eq. 1–4.
#[derive(Debug, Clone, Copy)]
pub struct FitParams {
    /// Half-width of the fitted slice, labels.
    pub radius: usize,
    /// Costs more than this above the minimum are left out.
    pub threshold: f32,
    /// Whether to find the slice's second minimum too ([`second_minimum`]; only the
    /// uncertainty model's ambiguity term uses it).
    pub second_minimum: bool,
}

/// Result of one level's matching.
#[derive(Debug, Clone)]
pub struct LevelFlow {
    /// Sub-pixel flow per pixel, level px.
    pub flow: Vec<[f32; 2]>,
    /// Raw fitted information `(Yxx, Yxy, Yyy)` in aggregated cost units per level px²
    /// (not yet calibrated nor made positive definite), when requested.
    pub information: Option<Vec<[f32; 3]>>,
    /// With the fit and when asked for: the second minimum of the regularised slice at least two labels from the
    /// winner, `(cost above the winner's, distance to the winner in level px)` (cost 0 and
    /// distance 0 where the window has no such label).
    pub second_minimum: Option<Vec<[f32; 2]>>,
}

/// Builds the cost volume `cost[p * n² + (ly + R) * n + (lx + R)]`, `n = 2R + 1`.
///
/// With `pb.half` the cost of a label is the lowest over the nine points of the half-label grid
/// around it (the label itself, the four points half-way to its neighbours, the four centres of
/// the label squares it touches), the target's descriptor there being the renormalised mean of
/// its neighbours' ([`descriptor::HalfNorms`]): the 2-D analogue of Birchfield and Tomasi's
/// sampling-insensitive dissimilarity (1998). A true displacement half-way between two labels
/// then costs what it would on a label, so a sharp descriptor does not prefer an alias that
/// happens to fall on the grid (repeated texture).
#[must_use]
pub fn cost_volume(pb: &LevelProblem<'_>) -> Vec<u8> {
    let w = pb.d1.width;
    let h = pb.d1.height;
    let n = 2 * pb.radius + 1;
    let nl = n * n;
    let mut vol = vec![0_u8; w * h * nl];
    match pb.half {
        None => {
            let d2t = descriptor::Transposed::of(pb.d2);
            vol.par_chunks_mut(w * nl)
                .enumerate()
                .for_each(|(y, row)| cost_row(pb, &d2t, y, row));
        }
        Some(half) => vol.par_chunks_mut(w * nl).enumerate().for_each_init(
            || HalfScratch::new(n),
            |sc, (y, row)| cost_row_half(pb, half, y, row, sc),
        ),
    }
    vol
}

/// Scratch buffers of [`cost_row_half`] for one window: the dot products (`n x n`, NaN outside
/// the image) and the half-label points' dot products, padded with `-inf` so every label has its
/// nine candidates at fixed offsets: `px` (`n` rows of `n + 1`: the point between labels
/// `a - 1` and `a` at column `a`), `py` (`n + 1` rows of `n`), `pq` (`(n + 1)²`, square centres).
struct HalfScratch {
    dots: Vec<f32>,
    px: Vec<f32>,
    py: Vec<f32>,
    pq: Vec<f32>,
}

impl HalfScratch {
    fn new(n: usize) -> Self {
        Self {
            dots: vec![f32::NAN; n * n],
            px: vec![f32::NEG_INFINITY; n * (n + 1)],
            py: vec![f32::NEG_INFINITY; (n + 1) * n],
            pq: vec![f32::NEG_INFINITY; (n + 1) * (n + 1)],
        }
    }
}

visnav_core::simd_kernel! {
    /// Row `y` of [`cost_volume`] with the half-label cost.
    fn cost_row_half(
        pb: &LevelProblem<'_>,
        half: &descriptor::HalfNorms,
        y: usize,
        row: &mut [u8],
        sc: &mut HalfScratch,
    ) {
        let w = pb.d1.width;
        let n = 2 * pb.radius + 1;
        let nl = n * n;
        let r = pb.radius as i32;
        let w2 = pb.d2.width as i32;
        let h2 = pb.d2.height as i32;
        let pen = pb.half_penalty;
        for x in 0..w {
            let i = y * w + x;
            let f1 = pb.d1.at(i);
            let c = pb.centres[i];
            let (x0, y0) = (x as i32 + c[0] - r, y as i32 + c[1] - r);
            let inside = x0 >= 0 && y0 >= 0 && x0 + 2 * r < w2 && y0 + 2 * r < h2;
            for b in 0..n {
                let ty = y0 + b as i32;
                for a in 0..n {
                    let tx = x0 + a as i32;
                    sc.dots[b * n + a] = if tx < 0 || tx >= w2 || ty < 0 || ty >= h2 {
                        f32::NAN
                    } else {
                        descriptor::dot(f1, pb.d2.at((ty * w2 + tx) as usize))
                    };
                }
            }
            // the half-label points: a point with a neighbour outside the image stays -inf
            let d = &sc.dots;
            for b in 0..n {
                let ty = y0 + b as i32;
                for a in 0..n {
                    let tx = x0 + a as i32;
                    let ok = |dx: i32, dy: i32| {
                        inside || (tx >= 0 && ty >= 0 && tx + dx < w2 && ty + dy < h2)
                    };
                    let t = if ok(0, 0) { (ty * w2 + tx) as usize } else { 0 };
                    let k = b * n + a;
                    if a + 1 < n {
                        sc.px[b * (n + 1) + a + 1] = if ok(1, 0) {
                            (d[k] + d[k + 1]) * half.x[t]
                        } else {
                            f32::NEG_INFINITY
                        };
                    }
                    if b + 1 < n {
                        sc.py[(b + 1) * n + a] = if ok(0, 1) {
                            (d[k] + d[k + n]) * half.y[t]
                        } else {
                            f32::NEG_INFINITY
                        };
                    }
                    if a + 1 < n && b + 1 < n {
                        sc.pq[(b + 1) * (n + 1) + a + 1] = if ok(1, 1) {
                            (d[k] + d[k + 1] + d[k + n] + d[k + n + 1]) * half.xy[t]
                        } else {
                            f32::NEG_INFINITY
                        };
                    }
                }
            }
            let out = &mut row[x * nl..(x + 1) * nl];
            for b in 0..n {
                for a in 0..n {
                    let d0 = d[b * n + a];
                    if d0.is_nan() {
                        out[b * n + a] = pb.outside_cost;
                        continue;
                    }
                    let (q0, q1) = (b * (n + 1) + a, (b + 1) * (n + 1) + a);
                    let halfway = sc.px[q0]
                        .max(sc.px[q0 + 1])
                        .max(sc.py[b * n + a])
                        .max(sc.py[(b + 1) * n + a])
                        .max(sc.pq[q0])
                        .max(sc.pq[q0 + 1])
                        .max(sc.pq[q1])
                        .max(sc.pq[q1 + 1]);
                    out[b * n + a] = descriptor::cost_of_dot(d0.max(halfway - pen));
                }
            }
            if let Some(epi) = &pb.epipolar {
                add_epipolar(out, x, y, c, r, n, epi);
            }
        }
    }
}

visnav_core::simd_kernel! {
    /// Row `y` of [`cost_volume`]: every pixel's `(2r+1)²` label costs. Eight labels of a
    /// window row whose targets are all inside the image are costed together
    /// ([`descriptor::dots8`], from `d2t`, the target's descriptors by row and component), the
    /// rest one by one ([`descriptor::cost`]): the same values bit for bit.
    fn cost_row(pb: &LevelProblem<'_>, d2t: &descriptor::Transposed, y: usize, row: &mut [u8]) {
        let w = pb.d1.width;
        let n = 2 * pb.radius + 1;
        let nl = n * n;
        let r = pb.radius as i32;
        let w2 = pb.d2.width as i32;
        let h2 = pb.d2.height as i32;
        for x in 0..w {
            let i = y * w + x;
            let f1 = pb.d1.at(i);
            let c = pb.centres[i];
            let out = &mut row[x * nl..(x + 1) * nl];
            for ly in -r..=r {
                let ty = y as i32 + c[1] + ly;
                let base = ((ly + r) as usize) * n;
                if ty < 0 || ty >= h2 {
                    out[base..base + n].fill(pb.outside_cost);
                    continue;
                }
                let tx0 = x as i32 + c[0] - r;
                let mut done = 0;
                while done + 8 <= n && tx0 + done as i32 >= 0 && tx0 + done as i32 + 8 <= w2 {
                    let dots = descriptor::dots8(f1, d2t, ty as usize, (tx0 + done as i32) as usize);
                    descriptor::costs_of_dots(&dots, &mut out[base + done..base + done + 8]);
                    done += 8;
                }
                for l in done..n {
                    let tx = tx0 + l as i32;
                    out[base + l] = if tx < 0 || tx >= w2 {
                        pb.outside_cost
                    } else {
                        descriptor::cost(f1, pb.d2.at((ty * w2 + tx) as usize))
                    };
                }
            }
            if let Some(epi) = &pb.epipolar {
                add_epipolar(out, x, y, c, r, n, epi);
            }
        }
    }
}

/// Adds `min(weight * dist², truncation)` (§3.1) to one pixel's labels.
// `min` then `max`, not `clamp`: a NaN sum would give 254 as the saturating `as u8` after `min` did
#[allow(clippy::manual_clamp)]
#[inline(always)]
fn add_epipolar(
    out: &mut [u8],
    x: usize,
    y: usize,
    c: [i32; 2],
    r: i32,
    n: usize,
    epi: &EpipolarLevel,
) {
    let x1 = nalgebra::Vector3::new(
        epi.scale * x as f64 + epi.offset,
        epi.scale * y as f64 + epi.offset,
        1.0,
    );
    let line = epi.fundamental * x1;
    let norm = line[0].hypot(line[1]);
    if norm.is_nan() || norm <= 1e-12 {
        return;
    }
    // one window row at a time, in a loop the compiler vectorises (the same operations: the
    // row's `line[1] y2` is the same product for every label of it; the rounded sum, limited
    // to 0..=254 as the saturating `as u8` limited it, converts through `i32`)
    for (ly, out_row) in (-r..=r).zip(out.chunks_exact_mut(n)) {
        let y2 = epi.scale * f64::from(y as i32 + c[1] + ly) + epi.offset;
        let line_y = line[1] * y2;
        for (lx, o) in (-r..=r).zip(out_row.iter_mut()) {
            let x2 = epi.scale * f64::from(x as i32 + c[0] + lx) + epi.offset;
            let dist_level = (line[0] * x2 + line_y + line[2]).abs() / norm / epi.scale;
            let add = (epi.weight * (dist_level * dist_level) as f32).min(epi.truncation);
            *o = (f32::from(*o) + add).round().min(254.0).max(0.0) as i32 as u8;
        }
    }
}

/// Penalties towards the left and right neighbour label in the label grid, per label: `p1`,
/// or `u16::MAX` (saturating: no neighbour) in the first / last column, so that the whole
/// window is handled by one loop over the labels in [`sgm_step`].
fn side_penalties(n: usize, p1: u16) -> (Vec<u16>, Vec<u16>) {
    let left = (0..n * n)
        .map(|k| if k % n == 0 { u16::MAX } else { p1 })
        .collect();
    let right = (0..n * n)
        .map(|k| if k % n == n - 1 { u16::MAX } else { p1 })
        .collect();
    (left, right)
}

visnav_core::simd_kernel! {
/// One SGM recursion step (DCFlow): `out[l] = C[l] + min(m[l + δ], prev_min + P2) - prev_min`
/// where `m = min(L_q, L_q at the 4 neighbouring labels + P1)`. Returns `min(out)`.
///
/// Written as loops over the whole `n²` label window (the neighbours as shifted slices, the
/// window's left and right edges masked by the penalties of [`side_penalties`]), which the
/// compiler vectorises.
fn sgm_step(
    prev: &[u16],
    prev_min: u16,
    delta: [i32; 2],
    cost: &[u8],
    n: usize,
    p1: u16,
    p2: u16,
    pens: (&[u16], &[u16]),
    scratch: &mut [u16],
    out: &mut [u16],
) -> u16 {
    let (pen_left, pen_right) = pens;
    let nl = n * n;
    let (prev, cost, out) = (&prev[..nl], &cost[..nl], &mut out[..nl]);
    // m in q's frame
    let m = &mut scratch[..nl];
    m.copy_from_slice(prev);
    for ((mv, pv), pen) in m[1..].iter_mut().zip(&prev[..nl - 1]).zip(&pen_left[1..nl]) {
        *mv = (*mv).min(pv.saturating_add(*pen));
    }
    for ((mv, pv), pen) in m[..nl - 1]
        .iter_mut()
        .zip(&prev[1..])
        .zip(&pen_right[..nl - 1])
    {
        *mv = (*mv).min(pv.saturating_add(*pen));
    }
    for (mv, pv) in m[n..].iter_mut().zip(&prev[..nl - n]) {
        *mv = (*mv).min(pv + p1);
    }
    for (mv, pv) in m[..nl - n].iter_mut().zip(&prev[n..]) {
        *mv = (*mv).min(pv + p1);
    }
    let cap = prev_min + p2;
    if delta == [0, 0] {
        for ((o, c), mv) in out.iter_mut().zip(cost).zip(m.iter()) {
            *o = u16::from(*c) + (*mv).min(cap) - prev_min;
        }
    } else {
        let ni = n as i32;
        for ly in 0..ni {
            let qy = ly + delta[1];
            let orow = &mut out[(ly * ni) as usize..((ly + 1) * ni) as usize];
            let crow = &cost[(ly * ni) as usize..((ly + 1) * ni) as usize];
            if qy < 0 || qy >= ni {
                for (o, c) in orow.iter_mut().zip(crow) {
                    *o = u16::from(*c) + cap - prev_min;
                }
                continue;
            }
            let mrow = &m[(qy * ni) as usize..((qy + 1) * ni) as usize];
            for lx in 0..ni {
                let qx = lx + delta[0];
                let mv = if qx >= 0 && qx < ni {
                    mrow[qx as usize].min(cap)
                } else {
                    cap
                };
                orow[lx as usize] = u16::from(crow[lx as usize]) + mv - prev_min;
            }
        }
    }
    out.iter().copied().fold(u16::MAX, u16::min)
}
}

#[inline]
fn delta(cp: [i32; 2], cq: [i32; 2]) -> [i32; 2] {
    [cp[0] - cq[0], cp[1] - cq[1]]
}

/// Semi-global aggregation along the four scanline directions; returns the sum of the four
/// path costs per pixel and label.
#[must_use]
pub fn aggregate(pb: &LevelProblem<'_>, vol: &[u8]) -> Vec<u16> {
    let w = pb.d1.width;
    let h = pb.d1.height;
    let n = 2 * pb.radius + 1;
    let nl = n * n;
    let p1 = pb.p1;
    let (pen_left, pen_right) = side_penalties(n, p1);
    let pens = (pen_left.as_slice(), pen_right.as_slice());
    let mut sum = vec![0_u16; w * h * nl];
    // horizontal paths, one row per task
    sum.par_chunks_mut(w * nl)
        .enumerate()
        .for_each(|(y, srow)| {
            let mut prev = vec![0_u16; nl];
            let mut cur = vec![0_u16; nl];
            let mut scratch = vec![0_u16; nl];
            for dir in 0..2 {
                let mut prev_min = 0_u16;
                for k in 0..w {
                    let x = if dir == 0 { k } else { w - 1 - k };
                    let i = y * w + x;
                    let c = &vol[i * nl..(i + 1) * nl];
                    if k == 0 {
                        for (p, cv) in cur.iter_mut().zip(c) {
                            *p = u16::from(*cv);
                        }
                        prev_min = cur.iter().copied().min().unwrap_or(0);
                    } else {
                        let q = if dir == 0 { i - 1 } else { i + 1 };
                        prev_min = sgm_step(
                            &prev,
                            prev_min,
                            delta(pb.centres[i], pb.centres[q]),
                            c,
                            n,
                            p1,
                            pb.p2[i],
                            pens,
                            &mut scratch,
                            &mut cur,
                        );
                    }
                    let s = &mut srow[x * nl..(x + 1) * nl];
                    for (sv, cv) in s.iter_mut().zip(&cur) {
                        *sv += *cv;
                    }
                    std::mem::swap(&mut prev, &mut cur);
                }
            }
        });
    // vertical paths: rows in sequence, pixels of a row in parallel
    const CHUNK: usize = 8;
    for dir in 0..2 {
        let mut prev = vec![0_u16; w * nl];
        let mut cur = vec![0_u16; w * nl];
        let mut prev_min = vec![0_u16; w];
        let mut cur_min = vec![0_u16; w];
        for k in 0..h {
            let y = if dir == 0 { k } else { h - 1 - k };
            let srow = &mut sum[y * w * nl..(y + 1) * w * nl];
            cur.par_chunks_mut(CHUNK * nl)
                .zip(cur_min.par_chunks_mut(CHUNK))
                .zip(srow.par_chunks_mut(CHUNK * nl))
                .enumerate()
                .for_each(|(chunk, ((cbuf, cmin), sbuf))| {
                    let mut scratch = vec![0_u16; nl];
                    for j in 0..cmin.len() {
                        let x = chunk * CHUNK + j;
                        let i = y * w + x;
                        let c = &vol[i * nl..(i + 1) * nl];
                        let out = &mut cbuf[j * nl..(j + 1) * nl];
                        if k == 0 {
                            for (o, cv) in out.iter_mut().zip(c) {
                                *o = u16::from(*cv);
                            }
                            cmin[j] = out.iter().copied().min().unwrap_or(0);
                        } else {
                            let q = if dir == 0 { i - w } else { i + w };
                            cmin[j] = sgm_step(
                                &prev[x * nl..(x + 1) * nl],
                                prev_min[x],
                                delta(pb.centres[i], pb.centres[q]),
                                c,
                                n,
                                p1,
                                pb.p2[i],
                                pens,
                                &mut scratch,
                                out,
                            );
                        }
                        for (sv, cv) in sbuf[j * nl..(j + 1) * nl].iter_mut().zip(out.iter()) {
                            *sv += *cv;
                        }
                    }
                });
            std::mem::swap(&mut prev, &mut cur);
            std::mem::swap(&mut prev_min, &mut cur_min);
        }
    }
    sum
}

/// Winner-take-all with parabolic sub-pixel refinement along x and y, and optionally the fit of
/// eq. 4 to the regularised slice around the winner.
#[must_use]
pub fn winner_take_all(pb: &LevelProblem<'_>, sum: &[u16], fit: Option<FitParams>) -> LevelFlow {
    let w = pb.d1.width;
    let h = pb.d1.height;
    let n = 2 * pb.radius + 1;
    let nl = n * n;
    let r = pb.radius as i32;
    let results: Vec<([f32; 2], [f32; 3], [f32; 2])> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let s = &sum[i * nl..(i + 1) * nl];
            let mut best = 0;
            for (k, v) in s.iter().enumerate() {
                if *v < s[best] {
                    best = k;
                }
            }
            let bx = (best % n) as i32;
            let by = (best / n) as i32;
            let at = |x: i32, y: i32| f32::from(s[(y as usize) * n + x as usize]);
            let c0 = at(bx, by);
            let parab = |cm: f32, cp: f32| {
                let den = cm - 2.0 * c0 + cp;
                if den > 1e-6 {
                    (0.5 * (cm - cp) / den).clamp(-0.5, 0.5)
                } else {
                    0.0
                }
            };
            let sx = if bx > 0 && bx + 1 < n as i32 {
                parab(at(bx - 1, by), at(bx + 1, by))
            } else {
                0.0
            };
            let sy = if by > 0 && by + 1 < n as i32 {
                parab(at(bx, by - 1), at(bx, by + 1))
            } else {
                0.0
            };
            let c = pb.centres[i];
            let flow = [(c[0] + bx - r) as f32 + sx, (c[1] + by - r) as f32 + sy];
            let info = fit.map_or([0.0; 3], |f| fit_gaussian(s, n, bx, by, [sx, sy], f));
            let second = if fit.is_some_and(|f| f.second_minimum) {
                second_minimum(s, n, bx, by)
            } else {
                [0.0; 2]
            };
            (flow, info, second)
        })
        .collect();
    let flow = results.iter().map(|r| r.0).collect();
    let information = fit.map(|_| results.iter().map(|r| r.1).collect());
    let second_minimum = fit
        .filter(|f| f.second_minimum)
        .map(|_| results.iter().map(|r| r.2).collect());
    LevelFlow {
        flow,
        information,
        second_minimum,
    }
}

/// The lowest regularised cost of an `n x n` slice at least two labels (Chebyshev) from the
/// winner `(bx, by)`: `(its cost minus the winner's, its distance to the winner in labels)`.
/// A small margin far away marks an ambiguous match (repeated texture, a second surface), whose
/// error the shape of the slice around the winner (eq. 4) does not show.
#[must_use]
pub fn second_minimum(s: &[u16], n: usize, bx: i32, by: i32) -> [f32; 2] {
    let c0 = s[(by as usize) * n + bx as usize];
    let mut best: Option<(u16, i32, i32)> = None;
    for y in 0..n as i32 {
        for x in 0..n as i32 {
            if (x - bx).abs().max((y - by).abs()) < 2 {
                continue;
            }
            let c = s[(y as usize) * n + x as usize];
            if best.is_none_or(|b| c < b.0) {
                best = Some((c, x, y));
            }
        }
    }
    best.map_or([0.0; 2], |(c, x, y)| {
        [
            f32::from(c.saturating_sub(c0)),
            ((x - bx) as f32).hypot((y - by) as f32),
        ]
    })
}

/// Eq. 4: least-squares fit of `d = Yxx x² + 2 Yxy x y + Yyy y²` to the regularised costs
/// (minus the minimum) at offsets `(x, y)` from the sub-pixel winner, using only costs below the
/// threshold. Returns `(Yxx, Yxy, Yyy)` in cost units per label², possibly not positive definite.
#[must_use]
pub fn fit_gaussian(
    s: &[u16],
    n: usize,
    bx: i32,
    by: i32,
    sub: [f32; 2],
    f: FitParams,
) -> [f32; 3] {
    let rf = f.radius as i32;
    let c0 = f32::from(s[(by as usize) * n + bx as usize]);
    let mut ata = [[0.0_f64; 3]; 3];
    let mut atd = [0.0_f64; 3];
    for dy in -rf..=rf {
        let yy = by + dy;
        if yy < 0 || yy >= n as i32 {
            continue;
        }
        for dx in -rf..=rf {
            let xx = bx + dx;
            if xx < 0 || xx >= n as i32 || (dx == 0 && dy == 0) {
                continue;
            }
            let d = f32::from(s[(yy as usize) * n + xx as usize]) - c0;
            if d > f.threshold {
                continue;
            }
            let x = f64::from(dx as f32 - sub[0]);
            let y = f64::from(dy as f32 - sub[1]);
            let a = [x * x, 2.0 * x * y, y * y];
            for r in 0..3 {
                for c in 0..3 {
                    ata[r][c] += a[r] * a[c];
                }
                atd[r] += a[r] * f64::from(d);
            }
        }
    }
    let m = nalgebra::Matrix3::from_fn(|r, c| ata[r][c]);
    let b = nalgebra::Vector3::from_column_slice(&atd);
    match m.try_inverse() {
        Some(inv) if m.determinant().abs() > 1e-9 => {
            let y = inv * b;
            [y[0] as f32, y[1] as f32, y[2] as f32]
        }
        _ => [0.0; 3],
    }
}

/// Runs cost volume, aggregation and winner-take-all for one direction.
#[must_use]
pub fn match_level(pb: &LevelProblem<'_>, fit: Option<FitParams>) -> LevelFlow {
    let vol = cost_volume(pb);
    let sum = aggregate(pb, &vol);
    drop(vol);
    winner_take_all(pb, &sum, fit)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaussian_fit_recovers_known_quadratic() {
        // d = x^T Y x with Y = [[3, 1], [1, 2]] sampled on a 7x7 label window, minimum at centre
        let n = 7;
        let y = [3.0_f32, 1.0, 2.0];
        let mut s = vec![0_u16; n * n];
        for ly in 0..n {
            for lx in 0..n {
                let x = lx as f32 - 3.0;
                let yy = ly as f32 - 3.0;
                let d = y[0] * x * x + 2.0 * y[1] * x * yy + y[2] * yy * yy;
                s[ly * n + lx] = (10.0 * d) as u16 + 50;
            }
        }
        let fit = fit_gaussian(
            &s,
            n,
            3,
            3,
            [0.0, 0.0],
            FitParams {
                radius: 3,
                threshold: 1e6,
                second_minimum: false,
            },
        );
        assert!((fit[0] - 30.0).abs() < 0.5, "{fit:?}");
        assert!((fit[1] - 10.0).abs() < 0.5, "{fit:?}");
        assert!((fit[2] - 20.0).abs() < 0.5, "{fit:?}");
    }

    #[test]
    fn second_minimum_skips_the_winner_neighbourhood_and_finds_the_alias() {
        // a 9x9 slice: the winner at (4, 4) with cost 10, its neighbours cheap (15), a repeated
        // texture's alias at (4, 8) with cost 18, everything else 100
        let n = 9;
        let mut s = vec![100_u16; n * n];
        for dy in -1..=1_i32 {
            for dx in -1..=1_i32 {
                s[((4 + dy) as usize) * n + (4 + dx) as usize] = 15;
            }
        }
        s[4 * n + 4] = 10;
        s[8 * n + 4] = 18;
        assert_eq!(second_minimum(&s, n, 4, 4), [8.0, 4.0]);
        // no alias: the margin is that of the flat background
        s[8 * n + 4] = 100;
        let [m, d] = second_minimum(&s, n, 4, 4);
        assert!((m - 90.0).abs() < 1e-6 && d >= 2.0);
        // a 3x3 slice has no label two away
        assert_eq!(second_minimum(&[5; 9], 3, 1, 1), [0.0, 0.0]);
    }

    /// Costs of pixel `(x, y)`'s window for image 2 = image 1 moved by `shift` px (the texture
    /// drawn at the moved coordinates), plain and with the half-label cost (penalty in cost units).
    fn window_costs(shift: [f32; 2], penalty: f32, x: usize, y: usize) -> (Vec<u8>, Vec<u8>) {
        // a sharp, irregular texture (a sum of incommensurate sines through a steep tanh)
        let tex = |u: f32, v: f32| {
            let s =
                (1.3 * u + 0.4 * v).sin() + (0.5 * u - 1.1 * v).sin() + (0.9 * v + 0.23 * u).cos();
            128.0 + 100.0 * (2.0 * s).tanh()
        };
        let (w, h) = (40, 40);
        let i1 = visnav_core::GrayImage::from_fn(w, h, |u, v| tex(u as f32, v as f32));
        let i2 = visnav_core::GrayImage::from_fn(w, h, |u, v| {
            tex(u as f32 - shift[0], v as f32 - shift[1])
        });
        let (d1, d2) = (descriptor::compute(&i1), descriptor::compute(&i2));
        let half = descriptor::half_norms(&d2);
        let centres = vec![[0, 0]; w * h];
        let p2 = vec![100_u16; w * h];
        let mut pb = LevelProblem {
            d1: &d1,
            d2: &d2,
            centres: &centres,
            radius: 3,
            p2: &p2,
            p1: 7,
            outside_cost: 100,
            epipolar: None,
            half: None,
            half_penalty: penalty / 127.0,
        };
        let nl = 49;
        let at = |vol: Vec<u8>| vol[(y * w + x) * nl..(y * w + x + 1) * nl].to_vec();
        let plain = at(cost_volume(&pb));
        pb.half = Some(&half);
        (plain, at(cost_volume(&pb)))
    }

    #[test]
    fn half_label_cost_matches_a_shift_between_labels() {
        // half a label off in y: the plain cost cannot reach the match, the half-label one does
        let (plain, half) = window_costs([1.0, 0.5], 0.0, 20, 20);
        let (min_p, min_h) = (plain.iter().min().unwrap(), half.iter().min().unwrap());
        assert!(*min_h + 10 < *min_p, "plain {min_p}, half-label {min_h}");
        // the two labels the point lies between share the lowest cost: (1, 0) and (1, 1)
        let label = |lx: usize, ly: usize| half[(ly + 3) * 7 + lx + 3];
        assert_eq!(label(1, 0), *min_h);
        assert_eq!(label(1, 1), *min_h);
        // never above the plain cost; a penalty moves the half-label points up by it
        assert!(half.iter().zip(&plain).all(|(h, p)| h <= p));
        let (_, pen) = window_costs([1.0, 0.5], 4.0, 20, 20);
        let min_pen = pen.iter().min().unwrap();
        assert!(min_pen.abs_diff(min_h + 4) <= 1, "{min_pen} vs {min_h} + 4");
    }

    #[test]
    fn half_label_cost_keeps_an_exact_match_and_the_outside_cost() {
        // an integer shift: the winner is the same label at cost 0 either way
        let (plain, half) = window_costs([2.0, -1.0], 2.0, 20, 20);
        let best = |c: &[u8]| (0..c.len()).min_by_key(|&k| c[k]).unwrap();
        assert_eq!(best(&plain), best(&half));
        assert_eq!(plain[best(&plain)], 0);
        assert_eq!(half[best(&half)], 0);
        // a window that leaves the image keeps the outside cost there
        let (plain, half) = window_costs([0.0, 0.0], 0.0, 1, 1);
        for k in 0..49 {
            let (lx, ly) = (k % 7, k / 7);
            if lx < 2 || ly < 2 {
                assert_eq!((plain[k], half[k]), (100, 100), "label {k}");
            }
        }
    }
}
