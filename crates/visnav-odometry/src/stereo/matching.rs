//! Stereo correspondence of features at t-1 by SAD block matching along the rectified row
//! (Buczko & Willert §V-A), with a parabola fit for sub-pixel disparity, a uniqueness ratio, a
//! left–right consistency check, an optional Lucas–Kanade refinement, and triangulation
//! `z = f b / d`.

use nalgebra::{Point2, Vector3};
use visnav_core::{GrayImage, StereoCamera};
use visnav_image::Pyramid;
use visnav_image::klt::{KltConfig, TrackStatus, track_one};

use crate::stereo::config::MatchConfig;

/// A feature with its stereo match and 3-D point at one time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoFeature {
    /// Left pixel.
    pub left_px: Point2<f64>,
    /// Right pixel (same row up to sub-pixel noise).
    pub right_px: Point2<f64>,
    /// Disparity `u_left − u_right`, pixels.
    pub disparity_px: f64,
    /// The triangulated point in the left camera frame, metres.
    pub p_in_cam: Vector3<f64>,
}

/// Best disparity of the block at `(x, y)` of `src` searched in `dst` at `x - sign * d`; returns
/// `(d, sub-pixel offset, uniqueness ok)`.
fn search(
    src: &GrayImage,
    dst: &GrayImage,
    x: usize,
    y: usize,
    sign: isize,
    cfg: &MatchConfig,
) -> Option<(usize, f64, bool)> {
    let r = cfg.block_radius;
    let n = 2 * r + 1;
    let w = dst.width();
    let (sd, dd) = (src.data(), dst.data());
    // the source block, copied once (validate() bounds r to 15)
    let mut block = [0.0f32; 31 * 31];
    for k in 0..n {
        let start = (y - r + k) * w + x - r;
        block[k * n..(k + 1) * n].copy_from_slice(&sd[start..start + n]);
    }
    let costs = block_costs(&block[..n * n], dd, (x, y, w), sign, cfg);
    let (bi, &(bd, bc)) = costs
        .iter()
        .enumerate()
        .filter(|(_, (d, _))| *d >= cfg.min_disparity_px && *d <= cfg.max_disparity_px)
        .min_by(|a, b| a.1.1.total_cmp(&b.1.1))?;
    let second = costs
        .iter()
        .filter(|(d, _)| d.abs_diff(bd) >= 2)
        .map(|(_, c)| *c)
        .fold(f32::INFINITY, f32::min);
    let unique = bc < cfg.uniqueness_ratio * second;
    let offset =
        if bi > 0 && bi + 1 < costs.len() && costs[bi - 1].0 + 1 == bd && costs[bi + 1].0 == bd + 1
        {
            let (cm, c0, cp) = (
                f64::from(costs[bi - 1].1),
                f64::from(bc),
                f64::from(costs[bi + 1].1),
            );
            let den = cm - 2.0 * c0 + cp;
            if den > 1e-9 {
                (0.5 * (cm - cp) / den).clamp(-0.5, 0.5)
            } else {
                0.0
            }
        } else {
            0.0
        };
    Some((bd, offset, unique))
}

/// The SAD of `block` (`n x n`, centred at `(x, y)`) against `dst` (`w` wide) at every
/// disparity `d` from `min − 1` to `max + 1` whose block lies inside `dst` (columns
/// `x − sign d ± r`), as `(d, cost)` in increasing `d`.
///
/// The disparities form one run of pixels in each block row, so the costs of all of them grow
/// together, pixel after pixel of the block (a loop over `d` the compiler vectorises); each
/// cost still sums its block in row-major order from zero, so it is bit-identical to summing
/// one disparity at a time.
fn block_costs(
    block: &[f32],
    dd: &[f32],
    (x, y, w): (usize, usize, usize),
    sign: isize,
    cfg: &MatchConfig,
) -> Vec<(usize, f32)> {
    let r = cfg.block_radius;
    let n = 2 * r + 1;
    let inside = |d: usize| {
        let xd = x as isize - sign * d as isize;
        xd >= r as isize && (xd as usize) + r < w
    };
    // the block's columns move monotonically with d: the valid disparities are one interval
    let (lo, hi) = (
        cfg.min_disparity_px.saturating_sub(1),
        cfg.max_disparity_px + 1,
    );
    let Some(first) = (lo..=hi).find(|&d| inside(d)) else {
        return Vec::new();
    };
    let last = (first..=hi)
        .take_while(|&d| inside(d))
        .last()
        .unwrap_or(first);
    let count = last - first + 1;
    // acc[j] is the cost of the j-th disparity in memory order: d = last − j looking left
    // (sign > 0), d = first + j looking right
    let mut acc = vec![0.0f32; count];
    // the block's pixel (k, i) meets the disparities' pixels from `origin + k w + i` on
    let origin = if sign > 0 {
        (y - r) * w + x - r - last
    } else {
        (y - r) * w + x + first - r
    };
    accumulate_sad(&mut acc, &block[..n * n], dd, origin, w, n);
    (first..=last)
        .map(|d| {
            let j = if sign > 0 { last - d } else { d - first };
            (d, acc[j])
        })
        .collect()
}

visnav_core::simd_kernel! {
    /// Adds `|dd[origin + k stride + i + j] − block[k n + i]|` to `acc[j]` for every pixel
    /// `(k, i)` of the `n x n` block, pixel after pixel (each cost summed in the block's order).
    fn accumulate_sad(
        acc: &mut [f32],
        block: &[f32],
        dd: &[f32],
        origin: usize,
        stride: usize,
        n: usize,
    ) {
        let count = acc.len();
        for k in 0..n {
            for i in 0..n {
                let b = block[k * n + i];
                let start = origin + k * stride + i;
                for (a, &v) in acc.iter_mut().zip(&dd[start..start + count]) {
                    *a += (v - b).abs();
                }
            }
        }
    }
}

/// Matches one left feature into the right image; `None` when no unique, consistent match exists.
#[must_use]
pub fn match_feature(
    rig: &StereoCamera,
    left: &Pyramid,
    right: &Pyramid,
    left_px: Point2<f64>,
    cfg: &MatchConfig,
    klt: &KltConfig,
) -> Option<StereoFeature> {
    let (l, rimg) = (left.base(), right.base());
    let r = cfg.block_radius;
    let x = left_px.x.round();
    let y = left_px.y.round();
    if x < r as f64 || y < r as f64 || x as usize + r >= l.width() || y as usize + r >= l.height() {
        return None;
    }
    let (x, y) = (x as usize, y as usize);
    let (d, offset, unique) = search(l, rimg, x, y, 1, cfg)?;
    if !unique {
        return None;
    }
    // left–right consistency: the right block matched back into the left row
    let xr = x - d;
    let (d_back, _, _) = search(rimg, l, xr, y, -1, cfg)?;
    if (d_back as f64 - d as f64).abs() > cfg.lr_tolerance_px {
        return None;
    }
    // the disparity of the rounded pixel holds for the sub-pixel feature (locally constant)
    let mut disparity = d as f64 + offset;
    let mut right_px = Point2::new(left_px.x - disparity, left_px.y);
    if cfg.refine_lk {
        let single = KltConfig {
            levels: 1,
            ..klt.clone()
        };
        let t = track_one(left, right, left_px, right_px, &single);
        if t.status != TrackStatus::Tracked {
            return None;
        }
        let d_lk = left_px.x - t.position.x;
        if (d_lk - disparity).abs() > 1.0 || (t.position.y - left_px.y).abs() > 1.0 {
            return None;
        }
        disparity = d_lk;
        right_px = t.position;
    } else if cfg.refine_on_row {
        let refined = refine_disparity_on_row(l, rimg, left_px, disparity, r)?;
        if (refined.disparity_px - disparity).abs() > 1.0 {
            return None;
        }
        disparity = refined.disparity_px;
        right_px = Point2::new(left_px.x - disparity, left_px.y);
    }
    let p = rig.triangulate(&left_px, disparity)?;
    Some(StereoFeature {
        left_px,
        right_px,
        disparity_px: disparity,
        p_in_cam: p.coords,
    })
}

/// A disparity refined along the rectified row ([`refine_disparity_on_row`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowRefinement {
    /// Disparity `u_left − u_right`, pixels.
    pub disparity_px: f64,
    /// Brightness of the right block minus the left one, grey levels.
    pub brightness_offset: f64,
    /// Gauss–Newton iterations taken.
    pub iterations: usize,
}

/// Gauss–Newton steps at most; the refinement stops earlier once a step moves the disparity by
/// less than [`ROW_REFINE_TOLERANCE_PX`].
const ROW_REFINE_ITERATIONS: usize = 15;
const ROW_REFINE_TOLERANCE_PX: f64 = 1e-3;

/// Refines `disparity_px` of the feature at `left_px` along its rectified row: minimises
/// `Σ (R(u + i − d, v + j) − L(u + i, v + j) − β)²` over the `(2 radius + 1)²` block around
/// the feature by Gauss–Newton on the disparity `d` and a brightness offset `β` (the two
/// cameras' exposures differ), both images sampled bilinearly at the sub-pixel position — a
/// one-dimensional Lucas–Kanade: the rectified pair's match lies on the row, so the vertical
/// shift a two-dimensional tracker would also estimate only adds noise. `None` when a sample
/// leaves an image, the system is singular (no horizontal texture), or the disparity wanders
/// more than 2 px from the start.
#[must_use]
pub fn refine_disparity_on_row(
    left: &GrayImage,
    right: &GrayImage,
    left_px: Point2<f64>,
    disparity_px: f64,
    radius: usize,
) -> Option<RowRefinement> {
    let (u, v) = (left_px.x, left_px.y);
    let n = 2 * radius + 1;
    // every sample of the block shares one pair of bilinear weights: the rows are v + j and the
    // columns x + i for integer i, j
    let rows = BlockRows::new(left, v, radius)?;
    let mut block = vec![0.0f32; n * n];
    rows.sample(left, u - radius as f64, n, &mut block)?;
    let rows = BlockRows::new(right, v, radius)?;
    // the right block with one more column on each side for the central-difference gradient
    let mut wide = vec![0.0f32; n * (n + 2)];
    let (mut d, mut beta) = (disparity_px, 0.0f64);
    for iteration in 1..=ROW_REFINE_ITERATIONS {
        rows.sample(right, u - d - radius as f64 - 1.0, n + 2, &mut wide)?;
        // Gauss–Newton on e = R(u + i − d, v + j) − L(u + i, v + j) − β:
        // de/dd = −∂R/∂x, de/dβ = −1
        let (mut gg, mut g1, mut ge, mut se) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for (l_row, r_row) in block.chunks_exact(n).zip(wide.chunks_exact(n + 2)) {
            for (i, &l) in l_row.iter().enumerate() {
                let gx = 0.5 * f64::from(r_row[i + 2] - r_row[i]);
                let e = f64::from(r_row[i + 1]) - f64::from(l) - beta;
                gg += gx * gx;
                g1 += gx;
                ge += gx * e;
                se += e;
            }
        }
        let count = (n * n) as f64;
        let det = gg * count - g1 * g1;
        if det.is_nan() || det <= 1e-9 * gg * count {
            return None;
        }
        // [gg g1; g1 count] (Δd, Δβ) = (ge, se)
        let step_d = (ge * count - g1 * se) / det;
        let step_beta = (gg * se - g1 * ge) / det;
        d += step_d;
        beta += step_beta;
        if !d.is_finite() || (d - disparity_px).abs() > 2.0 {
            return None;
        }
        if step_d.abs() < ROW_REFINE_TOLERANCE_PX {
            return Some(RowRefinement {
                disparity_px: d,
                brightness_offset: beta,
                iterations: iteration,
            });
        }
    }
    Some(RowRefinement {
        disparity_px: d,
        brightness_offset: beta,
        iterations: ROW_REFINE_ITERATIONS,
    })
}

/// The `2 radius + 1` rows `v + j` of a block (`|j| ≤ radius`) with their shared vertical
/// bilinear weight.
struct BlockRows {
    top: usize,
    fy: f32,
    count: usize,
}

impl BlockRows {
    /// `None` when a row (or the one below it, which the interpolation reads) leaves `image`.
    fn new(image: &GrayImage, v: f64, radius: usize) -> Option<Self> {
        let y0 = v.floor() - radius as f64;
        if y0.is_nan() || y0 < 0.0 || y0 as usize + 2 * radius + 1 >= image.height() {
            return None;
        }
        Some(Self {
            top: y0 as usize,
            fy: (v - v.floor()) as f32,
            count: 2 * radius + 1,
        })
    }

    /// Samples columns `x, x + 1, …, x + width − 1` of every row into `out` (row-major,
    /// `width` a row), bilinearly as [`GrayImage::bilinear`] does; `None` when a column (or the
    /// one right of it) leaves the image.
    fn sample(&self, image: &GrayImage, x: f64, width: usize, out: &mut [f32]) -> Option<()> {
        let x0 = x.floor();
        if x0.is_nan() || x0 < 0.0 || x0 as usize + width >= image.width() {
            return None;
        }
        let (x0, fx, fy) = (x0 as usize, (x - x0) as f32, self.fy);
        let (w, data) = (image.width(), image.data());
        for (k, row) in out.chunks_exact_mut(width).take(self.count).enumerate() {
            let top = &data[(self.top + k) * w + x0..][..=width];
            let bottom = &data[(self.top + k + 1) * w + x0..][..=width];
            for (i, o) in row.iter_mut().enumerate() {
                *o = (top[i] * (1.0 - fx) + top[i + 1] * fx) * (1.0 - fy)
                    + (bottom[i] * (1.0 - fx) + bottom[i + 1] * fx) * fy;
            }
        }
        Some(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use visnav_core::PinholeCamera;

    /// The vectorised costs equal one disparity at a time, bit for bit, on non-integer data,
    /// looking both ways, with the search window cut by either image border.
    #[test]
    fn block_costs_are_the_sums_of_one_disparity_at_a_time() {
        let (w, h) = (90usize, 20usize);
        let dd: Vec<f32> = (0..w * h)
            .map(|i| ((i * 7919) % 251) as f32 * 0.37 + (i % 13) as f32 * 0.011)
            .collect();
        let cfg = MatchConfig {
            min_disparity_px: 2,
            max_disparity_px: 40,
            ..MatchConfig::default()
        };
        let r = cfg.block_radius;
        let n = 2 * r + 1;
        let block: Vec<f32> = (0..n * n).map(|i| (i as f32 * 3.3) % 17.0).collect();
        for (x, sign) in [(60, 1), (12, 1), (45, 1), (10, -1), (70, -1), (40, -1)] {
            let y = 9;
            let mut expected = Vec::new();
            for d in cfg.min_disparity_px - 1..=cfg.max_disparity_px + 1 {
                let xd = x as isize - sign * d as isize;
                if xd < r as isize || xd as usize + r >= w {
                    continue;
                }
                let mut s = 0.0f32;
                for k in 0..n {
                    for i in 0..n {
                        s += (dd[(y - r + k) * w + xd as usize - r + i] - block[k * n + i]).abs();
                    }
                }
                expected.push((d, s));
            }
            let got = block_costs(&block, &dd, (x, y, w), sign, &cfg);
            assert_eq!(got.len(), expected.len(), "x {x} sign {sign}");
            for (g, e) in got.iter().zip(&expected) {
                assert_eq!(g.0, e.0);
                assert_eq!(g.1.to_bits(), e.1.to_bits(), "x {x} sign {sign} d {}", g.0);
            }
        }
    }

    fn texture(x: f64, y: f64) -> f32 {
        (128.0
            + 45.0 * (0.047 * x + 0.031 * y).sin()
            + 35.0 * (0.071 * x - 0.089 * y + 1.0).sin()
            + 20.0 * (0.19 * x + 0.13 * y + 2.0).cos()
            + 12.0 * (0.31 * x - 0.23 * y + 0.5).sin()
            + 8.0 * (0.11 * x + 0.43 * y).sin()) as f32
    }

    /// A fronto-parallel textured plane: the right image is the left shifted by the disparity.
    #[test]
    fn sad_disparity_error_small() {
        let cam = PinholeCamera::new(500.0, 500.0, 200.0, 120.0, 400, 240).unwrap();
        let rig = StereoCamera::new(cam, 0.5).unwrap();
        let cfg = MatchConfig::default();
        let klt = KltConfig::default();
        for &d_true in &[7.3, 23.64, 41.5] {
            let l = GrayImage::from_fn(400, 240, |x, y| texture(x as f64, y as f64));
            let r = GrayImage::from_fn(400, 240, |x, y| texture(x as f64 + d_true, y as f64));
            let (pl, pr) = (Pyramid::build(&l, 1), Pyramid::build(&r, 1));
            let sad_only = MatchConfig {
                refine_lk: false,
                refine_on_row: false,
                ..cfg.clone()
            };
            let lk = MatchConfig {
                refine_lk: true,
                ..cfg.clone()
            };
            let on_row = MatchConfig {
                refine_on_row: true,
                ..cfg.clone()
            };
            for raw in [sad_only, on_row, lk] {
                let mut worst = 0.0f64;
                for i in 0..10 {
                    let p = Point2::new(120.0 + 23.3 * f64::from(i), 60.0 + 11.0 * f64::from(i));
                    let f = match_feature(&rig, &pl, &pr, p, &raw, &klt).unwrap();
                    worst = worst.max((f.disparity_px - d_true).abs());
                    let z = 500.0 * 0.5 / d_true;
                    assert!((f.p_in_cam.z - z).abs() < 0.05 * z, "{f:?} d {d_true}");
                }
                let refined = raw.refine_lk || raw.refine_on_row;
                let tol = if refined { 0.02 } else { 0.25 };
                assert!(
                    worst < tol,
                    "d {d_true} refine {refined}: worst error {worst}"
                );
            }
        }
    }

    /// The row refinement recovers a sub-pixel disparity with a brightness offset between the
    /// images (which a refinement without the offset would turn into a disparity error), and
    /// refuses a block without horizontal texture.
    #[test]
    fn row_refinement_measures_disparity_and_brightness_offset() {
        let l = GrayImage::from_fn(400, 240, |x, y| texture(x as f64, y as f64));
        let d_true = 17.37;
        let r = GrayImage::from_fn(400, 240, |x, y| texture(x as f64 + d_true, y as f64) + 6.0);
        let mut sum_abs = 0.0;
        for i in 0..10 {
            let p = Point2::new(100.0 + 21.7 * f64::from(i), 50.0 + 13.1 * f64::from(i));
            let start = d_true.round() + 0.4;
            let got = refine_disparity_on_row(&l, &r, p, start, 3).unwrap();
            let e = got.disparity_px - d_true;
            assert!(e.abs() < 0.05, "{got:?} at {p:?}");
            assert!((got.brightness_offset - 6.0).abs() < 0.5, "{got:?}");
            sum_abs += e.abs();
        }
        assert!(sum_abs / 10.0 < 0.02, "mean |error| {}", sum_abs / 10.0);
        let flat = GrayImage::from_fn(400, 240, |_, y| 100.0 + y as f32);
        assert!(
            refine_disparity_on_row(&flat, &flat, Point2::new(200.0, 100.0), 10.0, 3).is_none()
        );
        // a block whose samples leave the right image
        assert!(refine_disparity_on_row(&l, &r, Point2::new(12.0, 100.0), 20.0, 3).is_none());
    }

    #[test]
    fn repetitive_texture_is_not_unique() {
        let cam = PinholeCamera::new(500.0, 500.0, 200.0, 120.0, 400, 240).unwrap();
        let rig = StereoCamera::new(cam, 0.5).unwrap();
        // a pure vertical stripe pattern with a 10 px period: every 10 px matches equally
        let l = GrayImage::from_fn(400, 240, |x, _| if (x / 5) % 2 == 0 { 200.0 } else { 50.0 });
        let (pl, pr) = (Pyramid::build(&l, 1), Pyramid::build(&l, 1));
        let f = match_feature(
            &rig,
            &pl,
            &pr,
            Point2::new(250.0, 100.0),
            &MatchConfig::default(),
            &KltConfig::default(),
        );
        assert!(f.is_none());
    }
}
