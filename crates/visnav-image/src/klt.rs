//! Pyramidal Lucas–Kanade point tracking, inverse-compositional for a translation warp
//! (Baker & Matthews 2004; Bouguet's pyramidal scheme).
//!
//! For each point `p` of the previous image `I` and a guess `d` of its displacement, coarse to fine
//! over the pyramid levels: the template `T(x) = I(p_l + x)` over a `(2r+1)²` window and its
//! gradients (central differences of the sampled template) give the constant Hessian
//! `H = Σ ∇T ∇Tᵀ`; each iteration samples the current image `J` at `p_l + d_l + x`, solves
//! `H Δ = Σ ∇T (J − T)` and updates `d_l ← d_l − Δ` until `|Δ| < epsilon_px`. The displacement
//! doubles from one level to the next finer one. All positions are pixels with centres at
//! integers; intensities 0..255.
//!
//! [`track_warped`] takes, per point, a predicted linear map `A` of the window's offsets from the
//! previous image to the current one (the patch's scaling and shear, e.g. from the point's depth
//! and the predicted motion, [`fronto_parallel_warp`]): at the finest level the template is then
//! sampled at `I(p + A⁻¹ x)`, so it looks as the patch will look in `J`, and only the translation
//! is estimated (not in the papers; issue #25). Translation-only tracking of a patch that grows by
//! a few per cent a frame (a near point under forward motion) is biased by a fraction of a pixel,
//! and a track chained frame after frame accumulates that bias.

use nalgebra::{Matrix2, Point2, Vector2};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::ImageError;
use crate::pyramid::{Pyramid, PyramidLevel};

/// Settings of the pyramidal Lucas–Kanade tracker.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct KltConfig {
    /// Half-size of the tracking window, pixels (window `2r+1` square). Default 7 (15x15).
    pub window_radius: usize,
    /// Number of pyramid levels used (1 = full resolution only); capped by the pyramids. Default 4.
    pub levels: usize,
    /// Maximum Gauss–Newton iterations per level. Default 30.
    pub max_iterations: usize,
    /// Convergence threshold on the update length, pixels of the level. Default 0.01.
    pub epsilon_px: f64,
    /// Reject a track whose final mean absolute intensity residual exceeds this (0..255).
    /// Default 20.
    pub max_residual: f32,
    /// Reject a point whose window-averaged structure tensor has a smaller eigenvalue below this
    /// (intensity² per pixel²). Default 1e-2.
    pub min_eigenvalue: f64,
}

impl Default for KltConfig {
    fn default() -> Self {
        Self {
            window_radius: 7,
            levels: 4,
            max_iterations: 30,
            epsilon_px: 0.01,
            max_residual: 20.0,
            min_eigenvalue: 1e-2,
        }
    }
}

impl KltConfig {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`ImageError::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> Result<(), ImageError> {
        let bad = |field: &'static str, message: &str| {
            Err(ImageError::InvalidConfig {
                field,
                message: message.to_string(),
            })
        };
        if self.window_radius == 0 || self.window_radius > 31 {
            return bad("window_radius", "must be in 1..=31");
        }
        if self.levels == 0 || self.levels > 10 {
            return bad("levels", "must be in 1..=10");
        }
        if self.max_iterations == 0 {
            return bad("max_iterations", "must be > 0");
        }
        if !(self.epsilon_px.is_finite() && self.epsilon_px > 0.0) {
            return bad("epsilon_px", "must be finite and > 0");
        }
        if !(self.max_residual.is_finite() && self.max_residual > 0.0) {
            return bad("max_residual", "must be finite and > 0");
        }
        if !(self.min_eigenvalue.is_finite() && self.min_eigenvalue >= 0.0) {
            return bad("min_eigenvalue", "must be finite and >= 0");
        }
        Ok(())
    }
}

/// Outcome of tracking one point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum TrackStatus {
    /// Converged with an acceptable residual.
    Tracked,
    /// The window left the previous or the current image.
    OutOfImage,
    /// The template has too little texture (small eigenvalue of `H`).
    Untextured,
    /// Converged (or ran out of iterations) with a residual above `max_residual`.
    LargeResidual,
}

/// The result for one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KltTrack {
    /// Whether the track is usable.
    pub status: TrackStatus,
    /// Final position in the current image, pixels (the last estimate when not tracked).
    pub position: Point2<f64>,
    /// Mean absolute intensity residual over the window at the final position (0..255).
    pub residual: f32,
}

impl KltTrack {
    /// The position when tracked, else `None`.
    #[must_use]
    pub fn tracked(&self) -> Option<Point2<f64>> {
        (self.status == TrackStatus::Tracked).then_some(self.position)
    }
}

/// Tracks `points` from `prev` to `cur`. `guesses`, when given (same length as `points`), are
/// initial positions in the current image (e.g. predicted by a motion model); otherwise the
/// points start where they were. Points are processed in parallel.
///
/// # Errors
/// [`ImageError::LengthMismatch`] when `guesses` has a different length than `points`, and
/// [`ImageError::SizeMismatch`] when the two pyramids have different base sizes.
pub fn track(
    prev: &Pyramid,
    cur: &Pyramid,
    points: &[Point2<f64>],
    guesses: Option<&[Point2<f64>]>,
    config: &KltConfig,
) -> Result<Vec<KltTrack>, ImageError> {
    track_all(prev, cur, points, guesses, None, config)
}

/// [`track`] with a predicted linear map of each point's window offsets from `prev` to `cur`
/// (`warps`, same length as `points`; see the module documentation): the template is sampled
/// warped by its inverse, the translation estimated as by [`track`]. A warp within 1e-6 of the
/// identity (or one that is not invertible) tracks exactly as [`track`] does.
///
/// # Errors
/// As [`track`], and [`ImageError::LengthMismatch`] when `warps` has a different length than
/// `points`.
pub fn track_warped(
    prev: &Pyramid,
    cur: &Pyramid,
    points: &[Point2<f64>],
    guesses: Option<&[Point2<f64>]>,
    warps: &[Matrix2<f64>],
    config: &KltConfig,
) -> Result<Vec<KltTrack>, ImageError> {
    if warps.len() != points.len() {
        return Err(ImageError::LengthMismatch {
            what: "KLT warps",
            expected: points.len(),
            got: warps.len(),
        });
    }
    track_all(prev, cur, points, guesses, Some(warps), config)
}

/// The linear map of window offsets `x_prev → x_cur` of a point at `p_prev_in_cam` (camera
/// frame of the previous image, metres) on a surface facing the previous camera, seen again
/// after `cur_from_prev`, for a pinhole with focal lengths `fx`, `fy` (pixels): the Jacobian
/// `∂π(R X(x) + t)/∂x` of the back-projection `X(x)` at the point's depth. `None` when either
/// depth is not positive.
#[must_use]
pub fn fronto_parallel_warp(
    p_prev_in_cam: &nalgebra::Vector3<f64>,
    cur_from_prev: &nalgebra::Isometry3<f64>,
    fx: f64,
    fy: f64,
) -> Option<Matrix2<f64>> {
    let z = p_prev_in_cam.z;
    let q = cur_from_prev * nalgebra::Point3::from(*p_prev_in_cam);
    if !(z > 0.0 && q.z > 0.0) {
        return None;
    }
    let r = cur_from_prev.rotation.to_rotation_matrix();
    let r = r.matrix();
    // ∂π/∂X at q (2x3) times R's first two columns scaled by ∂X/∂x = z / f
    let jp = nalgebra::Matrix2x3::new(
        fx / q.z,
        0.0,
        -fx * q.x / (q.z * q.z),
        0.0,
        fy / q.z,
        -fy * q.y / (q.z * q.z),
    );
    let cols = nalgebra::Matrix3x2::new(
        r[(0, 0)] * z / fx,
        r[(0, 1)] * z / fy,
        r[(1, 0)] * z / fx,
        r[(1, 1)] * z / fy,
        r[(2, 0)] * z / fx,
        r[(2, 1)] * z / fy,
    );
    Some(jp * cols)
}

/// [`track`] and [`track_warped`].
fn track_all(
    prev: &Pyramid,
    cur: &Pyramid,
    points: &[Point2<f64>],
    guesses: Option<&[Point2<f64>]>,
    warps: Option<&[Matrix2<f64>]>,
    config: &KltConfig,
) -> Result<Vec<KltTrack>, ImageError> {
    if let Some(g) = guesses
        && g.len() != points.len()
    {
        return Err(ImageError::LengthMismatch {
            what: "KLT guesses",
            expected: points.len(),
            got: g.len(),
        });
    }
    let (a, b) = (prev.base(), cur.base());
    if a.width() != b.width() || a.height() != b.height() {
        return Err(ImageError::SizeMismatch {
            expected_w: a.width(),
            expected_h: a.height(),
            got_w: b.width(),
            got_h: b.height(),
        });
    }
    Ok(points
        .par_iter()
        .enumerate()
        .map_init(Scratch::default, |scratch, (i, p)| {
            let g = guesses.map_or(*p, |g| g[i]);
            let inverse = warps.and_then(|w| template_map(&w[i]));
            track_with(prev, cur, *p, g, inverse, config, scratch)
        })
        .collect())
}

/// The tracker's windows, kept per thread by [`track`] (every value is written before it is
/// read, so they are only resized).
#[derive(Default)]
struct Scratch {
    /// The template grid with one pixel of margin, `(2r+3)²`.
    grid: Vec<f32>,
    /// Template and its gradients `∂x`, `∂y`, `(2r+1)²` each.
    tmpl: Vec<f32>,
    tgx: Vec<f32>,
    tgy: Vec<f32>,
    /// The current image sampled at the warped window, `(2r+1)²`.
    warped: Vec<f32>,
}

/// Tracks a single point (see [`track`]).
#[must_use]
pub fn track_one(
    prev: &Pyramid,
    cur: &Pyramid,
    point: Point2<f64>,
    guess: Point2<f64>,
    config: &KltConfig,
) -> KltTrack {
    track_with(
        prev,
        cur,
        point,
        guess,
        None,
        config,
        &mut Scratch::default(),
    )
}

/// The template's sampling map `A⁻¹` of a warp `A`: `None` (track unwarped) when `A` is within
/// 1e-6 of the identity, not finite or not invertible.
fn template_map(warp: &Matrix2<f64>) -> Option<Matrix2<f64>> {
    if (warp - Matrix2::identity()).amax() < 1e-6 || !warp.iter().all(|v| v.is_finite()) {
        return None;
    }
    warp.try_inverse()
        .filter(|m| m.iter().all(|v| v.is_finite() && v.abs() < 1e3))
}

/// [`track_one`] with the windows in `scratch`; `inverse` samples the template at `p + A⁻¹ x`.
fn track_with(
    prev: &Pyramid,
    cur: &Pyramid,
    point: Point2<f64>,
    guess: Point2<f64>,
    inverse: Option<Matrix2<f64>>,
    config: &KltConfig,
    scratch: &mut Scratch,
) -> KltTrack {
    let levels = config.levels.min(prev.len()).min(cur.len()).max(1);
    let top = levels - 1;
    let scale = f64::from(1u32 << top);
    let mut d = (guess - point) / scale;
    let mut residual = f32::INFINITY;
    let n = 2 * config.window_radius + 1;
    scratch.grid.resize((n + 2) * (n + 2), 0.0);
    scratch.tmpl.resize(n * n, 0.0);
    scratch.warped.resize(n * n, 0.0);
    scratch.tgx.resize(n * n, 0.0);
    scratch.tgy.resize(n * n, 0.0);
    for l in (0..levels).rev() {
        let s = f64::from(1u32 << l);
        let (Some(pl), Some(cl)) = (prev.level(l), cur.level(l)) else {
            break;
        };
        let p = Point2::new(point.x / s, point.y / s);
        // the warp at the finest level only: at the coarser ones the window's scale change moves
        // its samples by less than their precision (KITTI 06 and the rendered highways score
        // as with the warp at every level, at a quarter of its cost)
        let inv = if l == 0 { inverse.as_ref() } else { None };
        let outcome = track_level(pl, cl, p, &mut d, inv, config, scratch);
        match outcome {
            LevelOutcome::Done(res) => residual = res,
            LevelOutcome::Fail(status) => {
                // at a coarse level a border/texture failure can recover at finer ones
                if l == 0 {
                    return KltTrack {
                        status,
                        position: point + d,
                        residual,
                    };
                }
            }
        }
        if l > 0 {
            d *= 2.0;
        }
    }
    let position = point + d;
    let status = if residual > config.max_residual {
        TrackStatus::LargeResidual
    } else {
        TrackStatus::Tracked
    };
    KltTrack {
        status,
        position,
        residual,
    }
}

enum LevelOutcome {
    Done(f32),
    Fail(TrackStatus),
}

/// Samples the `(2r+3)²` grid around `p` (one pixel of margin for the central differences);
/// every sample shares the bilinear weights of `p`'s fractional part. The caller checks bounds.
///
/// Not `visnav_core::bilinear::Bilinear`: one set of weights serves a whole window read from
/// contiguous row slices (no per-sample clamping or index arithmetic, the tracker's inner loop),
/// and its product-weight form `w00 a + w10 b + w01 c + w11 d` gives other last bits than the
/// shared sampler's nested form; switching would change the stereo trajectories.
fn sample_grid(img: &visnav_core::GrayImage, p: Point2<f64>, r: isize, out: &mut [f32]) {
    let x0 = p.x.floor();
    let y0 = p.y.floor();
    let fx = (p.x - x0) as f32;
    let fy = (p.y - y0) as f32;
    let weights = [
        (1.0 - fx) * (1.0 - fy),
        fx * (1.0 - fy),
        (1.0 - fx) * fy,
        fx * fy,
    ];
    let n = (2 * r + 1) as usize;
    let iw = img.width();
    let first = ((y0 as isize - r) as usize) * iw + (x0 as isize - r) as usize;
    sample_rows(img.data(), first, iw, n, weights, out);
}

visnav_core::simd_kernel! {
    /// The `n x n` bilinear samples whose top-left neighbour is `data[first]` (rows `stride`
    /// apart), all with the weights `[w00, w10, w01, w11]`, into `out` row by row.
    fn sample_rows(
        data: &[f32],
        first: usize,
        stride: usize,
        n: usize,
        weights: [f32; 4],
        out: &mut [f32],
    ) {
        let [w00, w10, w01, w11] = weights;
        for (j, o) in out.chunks_exact_mut(n).enumerate() {
            let start = first + j * stride;
            let (a, c) = (&data[start..=start + n], &data[start + stride..=start + stride + n]);
            let (a0, a1, c0, c1) = (&a[..n], &a[1..], &c[..n], &c[1..]);
            for i in 0..n {
                o[i] = w00 * a0[i] + w10 * a1[i] + w01 * c0[i] + w11 * c1[i];
            }
        }
    }
}

/// The `(2r+1)²` grid `out[j n + i] = img(p + m (i − r, j − r))`, each sample bilinear (the
/// warped template of [`track_warped`]). The caller checks bounds.
///
/// Each sample in the window kernel's product-weight form ([`sample_rows`]), not the shared
/// `visnav_core::bilinear::Bilinear` (whose nested form gives other last bits): the warped
/// tracker's measured trajectories (docs/notes/2026-12-02-stereo-history.md,
/// *Warped tracking windows*) are this
/// form's; with the shared sampler they move in the fourth digit (KITTI 06 0.8407 / 1.4947 →
/// 0.8409 / 1.4950, highway r_err 0.0607 / 0.0483 / 0.0709 → 0.0628 / 0.0494 / 0.0696).
fn sample_grid_mapped(
    img: &visnav_core::GrayImage,
    p: Point2<f64>,
    r: isize,
    m: &Matrix2<f64>,
    out: &mut [f32],
) {
    let n = (2 * r + 1) as usize;
    let (iw, data) = (img.width(), img.data());
    for (j, row) in out.chunks_exact_mut(n).enumerate() {
        let dy = (j as isize - r) as f64;
        for (i, o) in row.iter_mut().enumerate() {
            let dx = (i as isize - r) as f64;
            let x = p.x + m[(0, 0)] * dx + m[(0, 1)] * dy;
            let y = p.y + m[(1, 0)] * dx + m[(1, 1)] * dy;
            let (x0, y0) = (x.floor(), y.floor());
            let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
            let k = y0 as usize * iw + x0 as usize;
            *o = (1.0 - fx) * (1.0 - fy) * data[k]
                + fx * (1.0 - fy) * data[k + 1]
                + (1.0 - fx) * fy * data[k + iw]
                + fx * fy * data[k + iw + 1];
        }
    }
}

/// How far from `p` the template grid of radius `r` reaches along x and y under the sampling map
/// `m` (the identity: `r`).
fn grid_reach(r: f64, m: Option<&Matrix2<f64>>) -> (f64, f64) {
    m.map_or((r, r), |m| {
        (
            r * (m[(0, 0)].abs() + m[(0, 1)].abs()),
            r * (m[(1, 0)].abs() + m[(1, 1)].abs()),
        )
    })
}

/// Lanes of [`residual_sums`]' partial sums.
const LANES: usize = 8;

visnav_core::simd_kernel! {
    /// `(Σ|e|, Σ ∂x·e, Σ ∂y·e)` of the residual `e = warped − tmpl` over a window, each in
    /// [`LANES`] interleaved partial sums added up in a fixed order, one loop a sum: the three
    /// sums vectorise along the lanes instead of running as three sequential chains (the
    /// latency of one addition a pixel was most of a tracking iteration).
    fn residual_sums(warped: &[f32], tmpl: &[f32], tgx: &[f32], tgy: &[f32]) -> [f32; 3] {
        let n = warped.len().min(tmpl.len()).min(tgx.len()).min(tgy.len());
        let (wc, wr) = warped[..n].as_chunks::<LANES>();
        let (tc, tr) = tmpl[..n].as_chunks::<LANES>();
        let (xc, xr) = tgx[..n].as_chunks::<LANES>();
        let (yc, yr) = tgy[..n].as_chunks::<LANES>();
        let mut out = [[0.0_f32; LANES]; 3];
        let [sa, sx, sy] = &mut out;
        for (w, t) in wc.iter().zip(tc) {
            for l in 0..LANES {
                sa[l] += (w[l] - t[l]).abs();
            }
        }
        for ((w, t), g) in wc.iter().zip(tc).zip(xc) {
            for l in 0..LANES {
                sx[l] += g[l] * (w[l] - t[l]);
            }
        }
        for ((w, t), g) in wc.iter().zip(tc).zip(yc) {
            for l in 0..LANES {
                sy[l] += g[l] * (w[l] - t[l]);
            }
        }
        for (l, (((w, t), gx), gy)) in wr.iter().zip(tr).zip(xr).zip(yr).enumerate() {
            let e = w - t;
            sa[l] += e.abs();
            sx[l] += gx * e;
            sy[l] += gy * e;
        }
        out.map(|a| a.iter().sum())
    }
}

fn track_level(
    prev: &PyramidLevel,
    cur: &PyramidLevel,
    p: Point2<f64>,
    d: &mut Vector2<f64>,
    inverse: Option<&Matrix2<f64>>,
    config: &KltConfig,
    scratch: &mut Scratch,
) -> LevelOutcome {
    let Scratch {
        grid,
        tmpl,
        tgx,
        tgy,
        warped,
    } = scratch;
    let r = config.window_radius as isize;
    let n = 2 * config.window_radius + 1;
    // the template grid has one pixel of margin for its central differences
    let (reach_x, reach_y) = grid_reach(config.window_radius as f64 + 1.0, inverse);
    let (w, h) = (prev.image.width() as f64, prev.image.height() as f64);
    let inside_xy = |q: Point2<f64>, mx: f64, my: f64| {
        q.x - mx >= 0.0 && q.y - my >= 0.0 && q.x + mx < w - 1.0 && q.y + my < h - 1.0
    };
    let inside = |q: Point2<f64>, m: f64| inside_xy(q, m, m);
    if !inside_xy(p, reach_x, reach_y) {
        return LevelOutcome::Fail(TrackStatus::OutOfImage);
    }
    // template on the grid with margin, then gradients by central differences
    let ng = n + 2;
    match inverse {
        None => sample_grid(&prev.image, p, r + 1, grid),
        Some(m) => sample_grid_mapped(&prev.image, p, r + 1, m, grid),
    }
    let (mut hxx, mut hxy, mut hyy) = (0.0f64, 0.0f64, 0.0f64);
    let mut k = 0;
    for y in 1..=n {
        for x in 1..=n {
            let i = y * ng + x;
            tmpl[k] = grid[i];
            let gx = 0.5 * (grid[i + 1] - grid[i - 1]);
            let gy = 0.5 * (grid[i + ng] - grid[i - ng]);
            tgx[k] = gx;
            tgy[k] = gy;
            hxx += f64::from(gx * gx);
            hxy += f64::from(gx * gy);
            hyy += f64::from(gy * gy);
            k += 1;
        }
    }
    let area = (k as f64).max(1.0);
    let min_eig = 0.5 * (hxx + hyy) - (0.25 * (hxx - hyy) * (hxx - hyy) + hxy * hxy).sqrt();
    if min_eig / area < config.min_eigenvalue {
        return LevelOutcome::Fail(TrackStatus::Untextured);
    }
    let det = hxx * hyy - hxy * hxy;
    let mut residual = f32::INFINITY;
    for _ in 0..config.max_iterations {
        let q = p + *d;
        if !inside(q, config.window_radius as f64) {
            return LevelOutcome::Fail(TrackStatus::OutOfImage);
        }
        sample_grid(&cur.image, q, r, warped);
        let [abs_sum, bx, by] = residual_sums(warped, tmpl, tgx, tgy);
        let (bx, by) = (f64::from(bx), f64::from(by));
        residual = abs_sum / (n * n) as f32;
        let step = Vector2::new((hyy * bx - hxy * by) / det, (hxx * by - hxy * bx) / det);
        *d -= step;
        if step.norm() < config.epsilon_px {
            break;
        }
    }
    if !inside(p + *d, config.window_radius as f64) {
        return LevelOutcome::Fail(TrackStatus::OutOfImage);
    }
    LevelOutcome::Done(residual)
}

#[cfg(test)]
mod tests {
    use super::*;
    use visnav_core::GrayImage;

    /// A smooth procedural texture: a sum of sinusoids with incommensurate frequencies.
    pub(crate) fn texture(x: f64, y: f64) -> f32 {
        // roughly 1/f: coarse structure dominates, so coarse pyramid levels do not alias
        let v = 128.0
            + 45.0 * (0.047 * x + 0.031 * y).sin()
            + 35.0 * (0.071 * x - 0.089 * y + 1.0).sin()
            + 20.0 * (0.19 * x + 0.13 * y + 2.0).cos()
            + 12.0 * (0.31 * x - 0.23 * y + 0.5).sin()
            + 8.0 * (0.11 * x * (1.0 + 0.002 * y) + 0.43 * y).sin();
        v as f32
    }

    #[test]
    fn residual_sums_match_the_plain_sums() {
        // 81 values (a 9x9 window: ten full lanes and one left over) and 7 (no full lane)
        for n in [81_usize, 7] {
            let f = |k: usize, a: f32| (a * k as f32).sin() * 10.0;
            let warped: Vec<f32> = (0..n).map(|k| f(k, 0.37) + 3.0).collect();
            let tmpl: Vec<f32> = (0..n).map(|k| f(k, 0.21)).collect();
            let gx: Vec<f32> = (0..n).map(|k| f(k, 0.13)).collect();
            let gy: Vec<f32> = (0..n).map(|k| f(k, 0.53)).collect();
            let [a, x, y] = residual_sums(&warped, &tmpl, &gx, &gy);
            let (mut pa, mut px, mut py) = (0.0_f64, 0.0_f64, 0.0_f64);
            for k in 0..n {
                let e = f64::from(warped[k] - tmpl[k]);
                pa += e.abs();
                px += f64::from(gx[k]) * e;
                py += f64::from(gy[k]) * e;
            }
            for (got, want) in [(a, pa), (x, px), (y, py)] {
                assert!(
                    (f64::from(got) - want).abs() < 1e-3 * (1.0 + want.abs()),
                    "{got} {want}"
                );
            }
        }
    }

    #[test]
    fn subpixel_translation_recovered() {
        let (w, h) = (240, 180);
        let (tx, ty) = (3.37, -1.81);
        let a = GrayImage::from_fn(w, h, |x, y| texture(x as f64, y as f64));
        // content moves by (tx, ty): J(x) = I(x - t)
        let b = GrayImage::from_fn(w, h, |x, y| texture(x as f64 - tx, y as f64 - ty));
        let cfg = KltConfig::default();
        cfg.validate().unwrap();
        let pa = Pyramid::build(&a, cfg.levels);
        let pb = Pyramid::build(&b, cfg.levels);
        let pts: Vec<_> = (0..8)
            .flat_map(|j| {
                (0..10).map(move |i| {
                    Point2::new(30.0 + 18.0 * f64::from(i), 30.0 + 16.0 * f64::from(j))
                })
            })
            .collect();
        let tracks = track(&pa, &pb, &pts, None, &cfg).unwrap();
        let mut worst = 0.0f64;
        for (p, t) in pts.iter().zip(&tracks) {
            assert_eq!(t.status, TrackStatus::Tracked, "point {p}: {t:?}");
            let q = t.position;
            let err = ((q.x - p.x - tx).powi(2) + (q.y - p.y - ty).powi(2)).sqrt();
            worst = worst.max(err);
        }
        assert!(worst < 0.05, "worst tracking error {worst} px");
    }

    #[test]
    fn large_motion_with_guess_and_failures() {
        let (w, h) = (240, 180);
        let (tx, ty) = (25.4, 6.2);
        let a = GrayImage::from_fn(w, h, |x, y| texture(x as f64, y as f64));
        let b = GrayImage::from_fn(w, h, |x, y| texture(x as f64 - tx, y as f64 - ty));
        let cfg = KltConfig {
            levels: 1,
            ..KltConfig::default()
        };
        let pa = Pyramid::build(&a, 1);
        let pb = Pyramid::build(&b, 1);
        let p = Point2::new(100.0, 80.0);
        let guess = Point2::new(p.x + tx + 0.8, p.y + ty - 0.7);
        let t = track(&pa, &pb, &[p], Some(&[guess]), &cfg).unwrap()[0];
        let q = t.tracked().unwrap();
        assert!((q.x - p.x - tx).abs() < 0.05 && (q.y - p.y - ty).abs() < 0.05);
        // near the border
        let t = track_one(&pa, &pb, Point2::new(2.0, 2.0), Point2::new(2.0, 2.0), &cfg);
        assert_eq!(t.status, TrackStatus::OutOfImage);
        // flat image
        let flat = Pyramid::build(&GrayImage::new(w, h, 7.0), 1);
        let t = track_one(&flat, &flat, p, p, &cfg);
        assert_eq!(t.status, TrackStatus::Untextured);
        // wrong guess length
        assert!(track(&pa, &pb, &[p], Some(&[]), &cfg).is_err());
    }

    /// Two pyramids of the texture shifted by (1.3, −0.4) px and a row of 20 points.
    fn shifted_pair() -> (Pyramid, Pyramid, Vec<Point2<f64>>) {
        let a = GrayImage::from_fn(120, 90, |x, y| texture(x as f64, y as f64));
        let b = GrayImage::from_fn(120, 90, |x, y| texture(x as f64 - 1.3, y as f64 + 0.4));
        let pts: Vec<_> = (0..20)
            .map(|i| Point2::new(20.0 + 4.0 * f64::from(i), 45.0))
            .collect();
        (Pyramid::build(&a, 3), Pyramid::build(&b, 3), pts)
    }

    #[test]
    fn serial_equals_parallel() {
        let (pa, pb, pts) = shifted_pair();
        let cfg = KltConfig::default();
        let par = track(&pa, &pb, &pts, None, &cfg).unwrap();
        for (p, t) in pts.iter().zip(&par) {
            assert_eq!(*t, track_one(&pa, &pb, *p, *p, &cfg));
        }
    }

    /// A patch growing by 8 % a frame (and moving): the translated window is tracked off by a
    /// fraction of a pixel where the texture is not symmetric about the point; the window warped
    /// by the known scale is tracked to a few hundredths.
    #[test]
    fn warped_window_tracks_a_growing_patch() {
        let (w, h) = (240, 180);
        let (s, c, t) = (1.08, Point2::new(120.0, 90.0), Vector2::new(2.3, -1.4));
        let a = GrayImage::from_fn(w, h, |x, y| texture(x as f64, y as f64));
        // J(x) = I(c + (x − c − t) / s): a point p of I is at c + s (p − c) + t in J
        let b = GrayImage::from_fn(w, h, |x, y| {
            let q = (Point2::new(x as f64, y as f64) - c - t) / s;
            texture(c.x + q.x, c.y + q.y)
        });
        let cfg = KltConfig::default();
        let (pa, pb) = (
            Pyramid::build(&a, cfg.levels),
            Pyramid::build(&b, cfg.levels),
        );
        let pts: Vec<_> = (0..6)
            .flat_map(|j| {
                (0..8).map(move |i| {
                    Point2::new(50.0 + 20.0 * f64::from(i), 40.0 + 20.0 * f64::from(j))
                })
            })
            .collect();
        let truth: Vec<Point2<f64>> = pts.iter().map(|p| c + (p - c) * s + t).collect();
        let warps = vec![Matrix2::identity() * s; pts.len()];
        let plain = track(&pa, &pb, &pts, Some(&truth), &cfg).unwrap();
        let warped = track_warped(&pa, &pb, &pts, Some(&truth), &warps, &cfg).unwrap();
        let errors = |tracks: &[KltTrack]| -> Vec<f64> {
            tracks
                .iter()
                .zip(&truth)
                .map(|(k, q)| (k.tracked().expect("tracked") - q).norm())
                .collect()
        };
        let (e_plain, e_warped) = (errors(&plain), errors(&warped));
        let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len() as f64;
        let worst = e_warped.iter().copied().fold(0.0, f64::max);
        assert!(worst < 0.05, "warped: worst error {worst} px");
        assert!(
            mean(&e_warped) < 0.5 * mean(&e_plain),
            "mean error warped {} px, translated {} px",
            mean(&e_warped),
            mean(&e_plain)
        );
    }

    /// An identity warp tracks exactly as [`track`]; a wrong number of warps is refused.
    #[test]
    fn identity_warp_is_plain_tracking() {
        let (pa, pb, pts) = shifted_pair();
        let cfg = KltConfig::default();
        let warps = vec![Matrix2::identity(); pts.len()];
        assert_eq!(
            track(&pa, &pb, &pts, None, &cfg).unwrap(),
            track_warped(&pa, &pb, &pts, None, &warps, &cfg).unwrap()
        );
        assert!(track_warped(&pa, &pb, &pts, None, &warps[1..], &cfg).is_err());
    }

    /// The facing-surface warp is the derivative of the projected back-projection.
    #[test]
    fn fronto_parallel_warp_is_the_projection_derivative() {
        let (fx, fy, cx, cy) = (700.0, 690.0, 320.0, 240.0);
        let p = nalgebra::Vector3::new(1.5, -0.8, 12.0);
        let motion = nalgebra::Isometry3::new(
            nalgebra::Vector3::new(0.2, -0.1, -1.3),
            nalgebra::Vector3::new(0.01, -0.03, 0.02),
        );
        let project = |x: f64, y: f64| {
            // the point of the surface facing the previous camera seen at pixel (x, y)
            let q = nalgebra::Point3::new((x - cx) * p.z / fx, (y - cy) * p.z / fy, p.z);
            let r = motion * q;
            Vector2::new(fx * r.x / r.z + cx, fy * r.y / r.z + cy)
        };
        let (u, v) = (fx * p.x / p.z + cx, fy * p.y / p.z + cy);
        let h = 1e-4;
        let du = (project(u + h, v) - project(u - h, v)) / (2.0 * h);
        let dv = (project(u, v + h) - project(u, v - h)) / (2.0 * h);
        let a = fronto_parallel_warp(&p, &motion, fx, fy).unwrap();
        for (k, d) in [du, dv].iter().enumerate() {
            assert!((a.column(k) - d).amax() < 1e-6, "column {k}: {a} vs {d}");
        }
        // a point that ends behind the camera has none
        let behind = nalgebra::Isometry3::translation(0.0, 0.0, -20.0);
        assert!(fronto_parallel_warp(&p, &behind, fx, fy).is_none());
    }
}
