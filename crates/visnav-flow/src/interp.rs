//! Edge-aware interpolation of the pixels removed by the forward–backward check, after EpicFlow
//! (Revaud et al. 2015): a geodesic distance on an edge map (cost per step
//! `1 + edge_weight * |∇I|`), computed by raster-scan passes, assigns each removed pixel its
//! geodesically nearest kept match (its seed), so flow does not leak across image edges. The
//! removed pixel then takes the flow of a locally weighted affine model fitted to the `K` kept
//! matches geodesically nearest to its seed (EpicFlow's "LA" interpolator, weights
//! `exp(-D_G / τ)`; as EpicFlow, one model per seed serves every pixel of the seed's cell), so the
//! fill follows a zoom, a rotation or a slanted surface into the hole instead of copying one
//! vector; where the fit is ill-conditioned, the seed's own flow is copied.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use rayon::prelude::*;

use crate::config::InterpolationConfig;

const DIAG: f32 = std::f32::consts::SQRT_2;

/// The 8-neighbourhood as `(dx, dy, step length)`: the half a forward raster pass looks back at
/// (left and the row above) ...
const BEFORE: [(isize, isize, f32); 4] =
    [(-1, 0, 1.0), (-1, -1, DIAG), (0, -1, 1.0), (1, -1, DIAG)];
/// ... and the half a backward pass looks back at (right and the row below).
const AFTER: [(isize, isize, f32); 4] = [(1, 0, 1.0), (1, 1, DIAG), (0, 1, 1.0), (-1, 1, DIAG)];

/// Geodesic length of a step of length `len` between pixels `i` and `q`, from the per-pixel
/// step cost `1 + edge_weight * |∇I|`.
#[inline]
fn step(cost: &[f32], i: usize, q: usize, len: f32) -> f32 {
    len * 0.5 * (cost[i] + cost[q])
}

/// Fills `flow` where `keep` is false with the flow of the geodesically nearest kept pixel.
/// `gradient` is the gradient magnitude of the source image. Leaves `flow` untouched when no
/// pixel is kept.
pub fn geodesic_fill(
    flow: &mut [[f32; 2]],
    keep: &[bool],
    gradient: &[f32],
    w: usize,
    h: usize,
    cfg: &InterpolationConfig,
) {
    let _ = geodesic_fill_with_distance(flow, keep, gradient, w, h, cfg);
}

/// As [`geodesic_fill`], returning per pixel the geodesic distance (level px weighted by the
/// edge cost) to the kept match it took its flow from: 0 for kept pixels, infinite everywhere
/// when no pixel is kept.
pub fn geodesic_fill_with_distance(
    flow: &mut [[f32; 2]],
    keep: &[bool],
    gradient: &[f32],
    w: usize,
    h: usize,
    cfg: &InterpolationConfig,
) -> Vec<f32> {
    if !keep.iter().any(|k| *k) {
        return vec![f32::INFINITY; keep.len()];
    }
    let cost: Vec<f32> = gradient.iter().map(|g| 1.0 + cfg.edge_weight * g).collect();
    let mut dist: Vec<f32> = keep
        .iter()
        .map(|k| if *k { 0.0 } else { f32::INFINITY })
        .collect();
    // the seed (nearest kept pixel) each pixel took its flow from
    let mut seed: Vec<u32> = (0..keep.len() as u32).collect();
    let (wi, hi) = (w as isize, h as isize);
    let mut relax = |x: usize, y: usize, nb: &[(isize, isize, f32); 4]| {
        let i = y * w + x;
        for &(dx, dy, len) in nb {
            let qx = x as isize + dx;
            let qy = y as isize + dy;
            if qx < 0 || qy < 0 || qx >= wi || qy >= hi {
                continue;
            }
            let q = (qy * wi + qx) as usize;
            let cand = dist[q] + step(&cost, i, q, len);
            if cand < dist[i] {
                dist[i] = cand;
                flow[i] = flow[q];
                seed[i] = seed[q];
            }
        }
    };
    for _ in 0..cfg.passes.max(1) {
        for y in 0..h {
            for x in 0..w {
                relax(x, y, &BEFORE);
            }
        }
        for y in (0..h).rev() {
            for x in (0..w).rev() {
                relax(x, y, &AFTER);
            }
        }
    }
    if cfg.affine_neighbours > 0 {
        affine_fill(flow, keep, &cost, &seed, w, h, cfg);
    }
    dist
}

/// Affine flow model about a seed: `f(p) = c + J (p - seed)`, `[c_u, c_v, J_uu, J_uv, J_vu,
/// J_vv]` (per level px).
type Affine = [f32; 6];

/// Replaces the flow of every removed pixel by the affine model of its seed (see the module
/// documentation). `cost` is the per-pixel step cost of the geodesic distance.
fn affine_fill(
    flow: &mut [[f32; 2]],
    keep: &[bool],
    cost: &[f32],
    seed: &[u32],
    w: usize,
    h: usize,
    cfg: &InterpolationConfig,
) {
    let mut seeds: Vec<u32> = seed
        .iter()
        .zip(keep)
        .filter(|(_, k)| !**k)
        .map(|(s, _)| *s)
        .collect();
    seeds.sort_unstable();
    seeds.dedup();
    let models: Vec<(u32, Option<Affine>)> = {
        let flow: &[[f32; 2]] = flow;
        seeds
            .par_iter()
            .map(|&s| (s, seed_model(flow, keep, cost, s as usize, w, h, cfg)))
            .collect()
    };
    let mut model_of = vec![None; keep.len()];
    for (s, m) in models {
        model_of[s as usize] = m;
    }
    for (i, f) in flow.iter_mut().enumerate() {
        if keep[i] {
            continue;
        }
        let s = seed[i] as usize;
        if let Some(m) = model_of[s] {
            let dx = (i % w) as f32 - (s % w) as f32;
            let dy = (i / w) as f32 - (s / w) as f32;
            *f = [m[0] + m[2] * dx + m[3] * dy, m[1] + m[4] * dx + m[5] * dy];
        }
    }
}

/// The locally weighted affine model of seed `s`: the `K` kept pixels geodesically nearest to it
/// within a `(2 affine_radius + 1)²` window (Dijkstra on the 8-connected grid with the step cost
/// of the fill), weighted by `exp(-D_G / affine_distance_scale)`, weighted least squares for the
/// two flow components. `None` when fewer than 6 matches are found or the fit is ill-conditioned.
fn seed_model(
    flow: &[[f32; 2]],
    keep: &[bool],
    cost: &[f32],
    s: usize,
    w: usize,
    h: usize,
    cfg: &InterpolationConfig,
) -> Option<Affine> {
    let r = cfg.affine_radius as isize;
    let side = (2 * r + 1) as usize;
    let (sx, sy) = ((s % w) as isize, (s / w) as isize);
    let local = |x: isize, y: isize| ((y - sy + r) as usize) * side + (x - sx + r) as usize;
    let mut dist = vec![f32::INFINITY; side * side];
    let mut heap = BinaryHeap::new();
    dist[local(sx, sy)] = 0.0;
    heap.push(Reverse((0_u32, sx as i32, sy as i32)));
    let mut samples: Vec<(f32, isize, isize)> = Vec::with_capacity(cfg.affine_neighbours);
    while let Some(Reverse((dbits, x, y))) = heap.pop() {
        let (x, y) = (x as isize, y as isize);
        let d = f32::from_bits(dbits);
        if d > dist[local(x, y)] {
            continue;
        }
        let i = y as usize * w + x as usize;
        if keep[i] {
            samples.push((d, x - sx, y - sy));
            if samples.len() >= cfg.affine_neighbours {
                break;
            }
        }
        for &(dx, dy, len) in BEFORE.iter().chain(&AFTER) {
            let (qx, qy) = (x + dx, y + dy);
            if qx < 0 || qy < 0 || qx >= w as isize || qy >= h as isize {
                continue;
            }
            if (qx - sx).abs() > r || (qy - sy).abs() > r {
                continue;
            }
            let q = qy as usize * w + qx as usize;
            let cand = d + step(cost, i, q, len);
            let l = local(qx, qy);
            if cand < dist[l] {
                dist[l] = cand;
                // non-negative floats order as their bit patterns
                heap.push(Reverse((cand.to_bits(), qx as i32, qy as i32)));
            }
        }
    }
    if samples.len() < 6 {
        return None;
    }
    // weighted normal equations of [1, dx, dy] for u and v
    let mut a = nalgebra::Matrix3::<f64>::zeros();
    let mut bu = nalgebra::Vector3::<f64>::zeros();
    let mut bv = nalgebra::Vector3::<f64>::zeros();
    let tau = f64::from(cfg.affine_distance_scale.max(1e-3));
    for &(d, dx, dy) in &samples {
        let wt = (-f64::from(d) / tau).exp();
        let phi = nalgebra::Vector3::new(1.0, dx as f64, dy as f64);
        let f = flow[((sy + dy) as usize) * w + (sx + dx) as usize];
        a += wt * phi * phi.transpose();
        bu += wt * f64::from(f[0]) * phi;
        bv += wt * f64::from(f[1]) * phi;
    }
    // ill-conditioned (matches on a line, or one dominating weight): no affine model
    let eig = a.symmetric_eigenvalues();
    let (lo, hi) = (eig.min(), eig.max());
    if lo.is_nan() || lo <= 1e-3 * hi {
        return None;
    }
    let chol = a.cholesky()?;
    let (pu, pv) = (chol.solve(&bu), chol.solve(&bv));
    let m = [pu[0], pv[0], pu[1], pu[2], pv[1], pv[2]].map(|v| v as f32);
    m.iter().all(|v| v.is_finite()).then_some(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fill_does_not_cross_a_strong_edge() {
        // left half flow (1,0), right half flow (5,0); a hole straddling the edge at x = 5
        let (w, h) = (10, 5);
        let mut flow: Vec<[f32; 2]> = (0..w * h)
            .map(|i| if i % w < 5 { [1.0, 0.0] } else { [5.0, 0.0] })
            .collect();
        let mut keep = vec![true; w * h];
        for y in 0..h {
            for x in 3..7 {
                keep[y * w + x] = false;
                flow[y * w + x] = [0.0, 0.0];
            }
        }
        let grad: Vec<f32> = (0..w * h)
            .map(|i| if i % w == 4 || i % w == 5 { 100.0 } else { 0.0 })
            .collect();
        geodesic_fill(
            &mut flow,
            &keep,
            &grad,
            w,
            h,
            &InterpolationConfig::default(),
        );
        // matches across the edge enter the affine fit only with weights below exp(-12)
        let near = |f: [f32; 2], want: [f32; 2]| (f[0] - want[0]).hypot(f[1] - want[1]) < 1e-3;
        assert!(near(flow[2 * w + 3], [1.0, 0.0]), "{:?}", flow[2 * w + 3]);
        assert!(near(flow[2 * w + 6], [5.0, 0.0]), "{:?}", flow[2 * w + 6]);
    }

    /// A zoom about the image centre, `f(p) = 0.05 (p - c)`, with a 9x9 hole: the affine fill
    /// recovers it exactly, while copying the nearest match is off by up to 0.05 px per px of
    /// distance into the hole.
    #[test]
    fn affine_fill_continues_a_zoom_into_a_hole() {
        let (w, h) = (40, 30);
        let truth = |i: usize| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            [0.05 * (x - 20.0), 0.05 * (y - 15.0)]
        };
        let keep: Vec<bool> = (0..w * h)
            .map(|i| !((16..25).contains(&(i % w)) && (11..20).contains(&(i / w))))
            .collect();
        let start: Vec<[f32; 2]> = (0..w * h)
            .map(|i| if keep[i] { truth(i) } else { [9.0, 9.0] })
            .collect();
        let grad = vec![0.0_f32; w * h];
        let err = |cfg: &InterpolationConfig| {
            let mut flow = start.clone();
            geodesic_fill(&mut flow, &keep, &grad, w, h, cfg);
            (0..w * h)
                .filter(|&i| !keep[i])
                .map(|i| {
                    let t = truth(i);
                    (flow[i][0] - t[0]).hypot(flow[i][1] - t[1])
                })
                .fold(0.0_f32, f32::max)
        };
        let affine = InterpolationConfig::default();
        assert!(affine.affine_neighbours > 0);
        assert!(err(&affine) < 1e-4, "{}", err(&affine));
        let nearest = InterpolationConfig {
            affine_neighbours: 0,
            ..affine
        };
        assert!(err(&nearest) > 0.15, "{}", err(&nearest));
    }

    /// Kept matches all on one line give no affine model: the seed's flow is copied.
    #[test]
    fn affine_fill_falls_back_to_the_seed_on_a_line() {
        let (w, h) = (20, 9);
        let keep: Vec<bool> = (0..w * h).map(|i| i / w == 4).collect();
        let mut flow: Vec<[f32; 2]> = (0..w * h)
            .map(|i| {
                if keep[i] {
                    [0.1 * (i % w) as f32, 0.0]
                } else {
                    [0.0; 2]
                }
            })
            .collect();
        let grad = vec![0.0_f32; w * h];
        geodesic_fill(
            &mut flow,
            &keep,
            &grad,
            w,
            h,
            &InterpolationConfig::default(),
        );
        for x in 0..w {
            let want = [0.1 * x as f32, 0.0];
            for y in [0, 8] {
                let f = flow[y * w + x];
                assert!((f[0] - want[0]).abs() < 1e-5 && f[1].abs() < 1e-5, "{f:?}");
            }
        }
    }
}
