//! Shi–Tomasi corners (Shi & Tomasi, "Good features to track", 1994): the response of a pixel is
//! the smaller eigenvalue of the structure tensor `M = Σ_w [gx² gx·gy; gx·gy gy²]` summed over a
//! square window of Sobel gradients. Corners are 3x3 local maxima above
//! `quality * max response`, spread over the image by keeping the strongest `max_per_bucket` in each
//! cell of a `bucket_cols x bucket_rows` grid and at least `min_distance_px` apart, then refined to
//! sub-pixel by the gradient-orthogonality iteration (Förstner; OpenCV `cornerSubPix`): the corner
//! `q` is where every window gradient `g(p)` is orthogonal to `p - q`, i.e.
//! `q = (Σ g gᵀ)⁻¹ Σ g gᵀ p`. Coordinates are pixels with centres at integers.

use nalgebra::Point2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use visnav_core::GrayImage;

use crate::ImageError;
use crate::gradient::{Gradients, sobel, sobel_row};

/// Settings of the Shi–Tomasi detector.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CornerConfig {
    /// Half-size of the structure-tensor window in pixels (window `2r+1` square). Default 2 (5x5).
    pub window_radius: usize,
    /// Relative threshold: keep responses above `quality * max response`. Default 0.001.
    pub quality: f32,
    /// Absolute threshold on the min-eigenvalue response (intensity² per pixel², window-averaged).
    /// Default 1.0.
    pub min_response: f32,
    /// Minimum distance between two kept corners, pixels. Default 8.
    pub min_distance_px: f64,
    /// Grid columns for bucketing. Default 16.
    pub bucket_cols: usize,
    /// Grid rows for bucketing. Default 6.
    pub bucket_rows: usize,
    /// Maximum corners kept in one grid cell. Default 8.
    pub max_per_bucket: usize,
    /// No corner closer than this to the border, pixels. Default 8.
    pub border_px: usize,
    /// Refine positions to sub-pixel (gradient-orthogonality iteration). Default true.
    pub subpixel: bool,
    /// Half-size of the sub-pixel refinement window, pixels. Default 3 (7x7).
    pub subpixel_radius: usize,
    /// Iterations of the sub-pixel refinement. Default 10.
    pub subpixel_iterations: usize,
}

impl Default for CornerConfig {
    fn default() -> Self {
        Self {
            window_radius: 2,
            quality: 0.001,
            min_response: 1.0,
            min_distance_px: 8.0,
            bucket_cols: 16,
            bucket_rows: 6,
            max_per_bucket: 8,
            border_px: 8,
            subpixel: true,
            subpixel_radius: 3,
            subpixel_iterations: 10,
        }
    }
}

impl CornerConfig {
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
        if self.window_radius == 0 || self.window_radius > 15 {
            return bad("window_radius", "must be in 1..=15");
        }
        if !(self.quality.is_finite() && (0.0..1.0).contains(&self.quality)) {
            return bad("quality", "must be in [0, 1)");
        }
        if !(self.min_response.is_finite() && self.min_response >= 0.0) {
            return bad("min_response", "must be finite and >= 0");
        }
        if !(self.min_distance_px.is_finite() && self.min_distance_px >= 0.0) {
            return bad("min_distance_px", "must be finite and >= 0");
        }
        if self.bucket_cols == 0 || self.bucket_rows == 0 || self.max_per_bucket == 0 {
            return bad(
                "bucket_cols",
                "bucket_cols, bucket_rows, max_per_bucket must be > 0",
            );
        }
        if self.subpixel_radius == 0 || self.subpixel_radius > 15 {
            return bad("subpixel_radius", "must be in 1..=15");
        }
        Ok(())
    }
}

/// A detected corner.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// Position in pixels (sub-pixel when refined).
    pub px: Point2<f64>,
    /// Shi–Tomasi response (smaller eigenvalue of the window-averaged structure tensor).
    pub response: f32,
}

/// The Shi–Tomasi response map: the smaller eigenvalue of the structure tensor averaged over a
/// `(2r+1)²` window; zero within `r + 1` pixels of the border.
#[must_use]
pub fn min_eigen_response(grad: &Gradients, radius: usize) -> GrayImage {
    let (w, h) = (grad.gx.width(), grad.gx.height());
    let mut out = vec![0.0f32; w * h];
    if w <= 2 * radius + 2 || h <= 2 * radius + 2 {
        return GrayImage::from_vec(w, h, out).unwrap_or_else(|| GrayImage::new(w, h, 0.0));
    }
    // products, then a separable box sum: vertical per row, horizontal running sum
    let gx = grad.gx.data();
    let gy = grad.gy.data();
    let area = ((2 * radius + 1) * (2 * radius + 1)) as f32;
    out.par_chunks_mut(w).enumerate().for_each(|(y, orow)| {
        if y <= radius || y + radius + 1 >= h {
            return;
        }
        let mut sxx = vec![0.0f32; w];
        let mut sxy = vec![0.0f32; w];
        let mut syy = vec![0.0f32; w];
        for yy in y - radius..=y + radius {
            let rx = &gx[yy * w..(yy + 1) * w];
            let ry = &gy[yy * w..(yy + 1) * w];
            for x in 0..w {
                sxx[x] += rx[x] * rx[x];
                sxy[x] += rx[x] * ry[x];
                syy[x] += ry[x] * ry[x];
            }
        }
        let mut box_sums = vec![[0.0f32; 3]; w];
        eigen_row(&sxx, &sxy, &syy, radius, area, &mut box_sums, orow);
    });
    GrayImage::from_vec(w, h, out).unwrap_or_else(|| GrayImage::new(w, h, 0.0))
}

/// [`min_eigen_response`] of the Sobel gradients of `img`, computed in strips of rows without
/// full-size gradient images (same values).
#[must_use]
pub fn min_eigen_response_of_image(img: &GrayImage, radius: usize) -> GrayImage {
    const STRIP: usize = 16;
    let (w, h) = (img.width(), img.height());
    let mut out = vec![0.0f32; w * h];
    if w <= 2 * radius + 2 || h <= 2 * radius + 2 {
        return GrayImage::from_vec(w, h, out).unwrap_or_else(|| GrayImage::new(w, h, 0.0));
    }
    let area = ((2 * radius + 1) * (2 * radius + 1)) as f32;
    // per-thread scratch: every value is written before it is read, so buffers are only resized
    out.par_chunks_mut(w * STRIP).enumerate().for_each_init(
        StripScratch::default,
        |scratch, (strip, chunk)| {
            let y0 = strip * STRIP;
            let y1 = (y0 + STRIP).min(h);
            let ya = y0.saturating_sub(radius);
            let yb = (y1 + radius).min(h);
            scratch.fit(yb - ya, w);
            let StripScratch {
                pxx,
                pxy,
                pyy,
                gx,
                gy,
                sxx,
                sxy,
                syy,
                box_sums,
            } = scratch;
            for y in ya..yb {
                sobel_row(img, y, gx, gy);
                let o = (y - ya) * w;
                let out = (&mut pxx[o..o + w], &mut pxy[o..o + w], &mut pyy[o..o + w]);
                tensor_products(gx, gy, out.0, out.1, out.2);
            }
            for y in y0..y1 {
                if y <= radius || y + radius + 1 >= h {
                    continue;
                }
                sxx.fill(0.0);
                sxy.fill(0.0);
                syy.fill(0.0);
                for yy in y - radius..=y + radius {
                    let o = (yy - ya) * w;
                    add_rows(sxx, &pxx[o..o + w]);
                    add_rows(sxy, &pxy[o..o + w]);
                    add_rows(syy, &pyy[o..o + w]);
                }
                let orow = &mut chunk[(y - y0) * w..(y - y0 + 1) * w];
                eigen_row(sxx, sxy, syy, radius, area, box_sums, orow);
            }
        },
    );
    GrayImage::from_vec(w, h, out).unwrap_or_else(|| GrayImage::new(w, h, 0.0))
}

/// The working rows of one strip of [`min_eigen_response_of_image`], kept per thread.
#[derive(Default)]
struct StripScratch {
    pxx: Vec<f32>,
    pxy: Vec<f32>,
    pyy: Vec<f32>,
    gx: Vec<f32>,
    gy: Vec<f32>,
    sxx: Vec<f32>,
    sxy: Vec<f32>,
    syy: Vec<f32>,
    box_sums: Vec<[f32; 3]>,
}

impl StripScratch {
    /// Sizes for `rows` tensor rows of width `w`.
    fn fit(&mut self, rows: usize, w: usize) {
        for v in [&mut self.pxx, &mut self.pxy, &mut self.pyy] {
            v.resize(rows * w, 0.0);
        }
        for v in [
            &mut self.gx,
            &mut self.gy,
            &mut self.sxx,
            &mut self.sxy,
            &mut self.syy,
        ] {
            v.resize(w, 0.0);
        }
        self.box_sums.resize(w, [0.0; 3]);
    }
}

visnav_core::simd_kernel! {
    /// `gx²`, `gx·gy`, `gy²` of one row.
    fn tensor_products(gx: &[f32], gy: &[f32], pxx: &mut [f32], pxy: &mut [f32], pyy: &mut [f32]) {
        let n = gx.len().min(gy.len()).min(pxx.len()).min(pxy.len()).min(pyy.len());
        let (gx, gy) = (&gx[..n], &gy[..n]);
        let (pxx, pxy, pyy) = (&mut pxx[..n], &mut pxy[..n], &mut pyy[..n]);
        for x in 0..n {
            pxx[x] = gx[x] * gx[x];
            pxy[x] = gx[x] * gy[x];
            pyy[x] = gy[x] * gy[x];
        }
    }
}

visnav_core::simd_kernel! {
    /// `sum += row`, element by element.
    fn add_rows(sum: &mut [f32], row: &[f32]) {
        for (s, v) in sum.iter_mut().zip(row) {
            *s += *v;
        }
    }
}

/// Horizontal box sums of the vertically summed tensor row and its smaller eigenvalue: the
/// running sums first (a serial chain, `box_sums` is scratch of the row's length), then the
/// eigenvalues ([`min_eigenvalues`], vectorised).
fn eigen_row(
    sxx: &[f32],
    sxy: &[f32],
    syy: &[f32],
    radius: usize,
    area: f32,
    box_sums: &mut [[f32; 3]],
    orow: &mut [f32],
) {
    let w = sxx.len();
    let (mut a, mut b, mut c) = (0.0f32, 0.0f32, 0.0f32);
    for x in 0..2 * radius + 1 {
        a += sxx[x];
        b += sxy[x];
        c += syy[x];
    }
    let (lo, hi) = (radius + 1, w - radius - 1);
    for x in lo..hi {
        // window covers x - r ..= x + r; slide from the previous centre
        a += sxx[x + radius] - sxx[x - radius - 1];
        b += sxy[x + radius] - sxy[x - radius - 1];
        c += syy[x + radius] - syy[x - radius - 1];
        box_sums[x] = [a, b, c];
    }
    min_eigenvalues(&box_sums[lo..hi], area, &mut orow[lo..hi]);
}

visnav_core::simd_kernel! {
    /// The smaller eigenvalue of each window-averaged tensor `[a b; b c] / area`, floored at 0.
    fn min_eigenvalues(sums: &[[f32; 3]], area: f32, out: &mut [f32]) {
        for (o, &[a, b, c]) in out.iter_mut().zip(sums) {
            let (aa, bb, cc) = (a / area, b / area, c / area);
            let half_trace = 0.5 * (aa + cc);
            let d = (0.25 * (aa - cc) * (aa - cc) + bb * bb).sqrt();
            *o = (half_trace - d).max(0.0);
        }
    }
}

/// Detects Shi–Tomasi corners: response, 3x3 non-maximum suppression, thresholds, bucketing,
/// minimum distance, sub-pixel refinement. Sorted by decreasing response.
#[must_use]
pub fn detect_corners(img: &GrayImage, config: &CornerConfig) -> Vec<Corner> {
    let resp = min_eigen_response_of_image(img, config.window_radius);
    let mut kept = select_corners(&resp, config);
    if config.subpixel {
        let grad = sobel(img);
        refine_all(&grad, &mut kept, config);
    }
    kept
}

/// [`detect_corners`] reusing precomputed Sobel gradients of `img`.
#[must_use]
pub fn detect_corners_with_gradients(
    img: &GrayImage,
    grad: &Gradients,
    config: &CornerConfig,
) -> Vec<Corner> {
    debug_assert_eq!(img.width(), grad.gx.width());
    let resp = min_eigen_response(grad, config.window_radius);
    let mut kept = select_corners(&resp, config);
    if config.subpixel {
        refine_all(grad, &mut kept, config);
    }
    kept
}

fn refine_all(grad: &Gradients, kept: &mut [Corner], config: &CornerConfig) {
    kept.par_iter_mut().for_each(|c| {
        if let Some(p) = refine_subpixel(
            grad,
            c.px,
            config.subpixel_radius,
            config.subpixel_iterations,
        ) {
            c.px = p;
        }
    });
}

visnav_core::simd_kernel! {
    /// The 3x3 non-maximum suppression of one row: `mask[i]` is 1 when the centre
    /// `v = rows[1][i + 1]` passes `!(v <= threshold)` and no neighbour beats it — a neighbour
    /// above or to the left must be strictly smaller (`!(q >= v)`), one to the right or below
    /// not larger (`!(q > v)`), so a plateau keeps exactly one pixel. `rows` are the rows above,
    /// at and below, each one sample wider than `mask` on both sides.
    // the negated comparisons keep the loop this replaced exact for NaN responses too
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    fn local_maxima_row(rows: [&[f32]; 3], threshold: f32, mask: &mut [u8]) {
        let n = mask.len();
        let [up, mid, down] = rows;
        let (up, mid, down) = (&up[..n + 2], &mid[..n + 2], &down[..n + 2]);
        for i in 0..n {
            let v = mid[i + 1];
            let keep = !(v <= threshold)
                & !(up[i] >= v)
                & !(up[i + 1] >= v)
                & !(up[i + 2] >= v)
                & !(mid[i] >= v)
                & !(mid[i + 2] > v)
                & !(down[i] > v)
                & !(down[i + 1] > v)
                & !(down[i + 2] > v);
            mask[i] = u8::from(keep);
        }
    }
}

/// Non-maximum suppression, thresholds, bucketing and minimum distance on a response map.
fn select_corners(resp: &GrayImage, config: &CornerConfig) -> Vec<Corner> {
    let (w, h) = (resp.width(), resp.height());
    let max_resp = resp.data().par_iter().copied().reduce(|| 0.0, f32::max);
    let threshold = (config.quality * max_resp).max(config.min_response);
    let border = config.border_px.max(config.window_radius + 2);
    if w <= 2 * border || h <= 2 * border {
        return Vec::new();
    }
    // local maxima, per row in parallel: a branch-free mask of the row, then its set entries
    let mut candidates: Vec<Corner> = (border..h - border)
        .into_par_iter()
        .map_init(Vec::new, |mask: &mut Vec<u8>, y| {
            let r = resp.data();
            let row = |yy: usize| &r[yy * w + border - 1..yy * w + w - border + 1];
            mask.resize(w - 2 * border, 0);
            local_maxima_row([row(y - 1), row(y), row(y + 1)], threshold, mask);
            mask.iter()
                .enumerate()
                .filter(|&(_, &m)| m != 0)
                .map(|(i, _)| {
                    let x = border + i;
                    Corner {
                        px: Point2::new(x as f64, y as f64),
                        response: r[y * w + x],
                    }
                })
                .collect::<Vec<_>>()
        })
        .flatten_iter()
        .collect();
    candidates.sort_by(|a, b| b.response.total_cmp(&a.response));

    // bucketing + minimum distance (greedy by response)
    let (bc, br) = (config.bucket_cols, config.bucket_rows);
    let mut per_bucket = vec![0usize; bc * br];
    let cell = config.min_distance_px.max(1.0);
    let gw = (w as f64 / cell).ceil() as usize + 1;
    let gh = (h as f64 / cell).ceil() as usize + 1;
    let mut grid: Vec<Vec<Point2<f64>>> = vec![Vec::new(); gw * gh];
    let min_d2 = config.min_distance_px * config.min_distance_px;
    let mut kept = Vec::new();
    for c in candidates {
        let bx = ((c.px.x / w as f64) * bc as f64) as usize;
        let by = ((c.px.y / h as f64) * br as f64) as usize;
        let b = by.min(br - 1) * bc + bx.min(bc - 1);
        if per_bucket[b] >= config.max_per_bucket {
            continue;
        }
        let gx = (c.px.x / cell) as usize;
        let gy = (c.px.y / cell) as usize;
        let mut close = false;
        'g: for yy in gy.saturating_sub(1)..=(gy + 1).min(gh - 1) {
            for xx in gx.saturating_sub(1)..=(gx + 1).min(gw - 1) {
                if grid[yy * gw + xx]
                    .iter()
                    .any(|p| (p - c.px).norm_squared() < min_d2)
                {
                    close = true;
                    break 'g;
                }
            }
        }
        if close {
            continue;
        }
        grid[gy * gw + gx].push(c.px);
        per_bucket[b] += 1;
        kept.push(c);
    }
    kept
}

/// Gradient-orthogonality sub-pixel refinement of a corner near `start` (OpenCV `cornerSubPix`
/// without the Gaussian weight): iterate `q ← (Σ g gᵀ)⁻¹ Σ g gᵀ p` over a `(2r+1)²` window of
/// bilinearly sampled gradients centred at `q`. `None` when the system is singular or the corner
/// leaves the window.
#[must_use]
pub fn refine_subpixel(
    grad: &Gradients,
    start: Point2<f64>,
    radius: usize,
    iterations: usize,
) -> Option<Point2<f64>> {
    let r = radius as isize;
    let mut q = start;
    let w = grad.gx.width() as f64;
    let h = grad.gx.height() as f64;
    let rf = radius as f64;
    // mild Gaussian weight, sigma = radius
    let weights: Vec<f64> = (-r..=r)
        .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
        .map(|(dx, dy)| (-((dx * dx + dy * dy) as f64) / (2.0 * rf * rf)).exp())
        .collect();
    for _ in 0..iterations {
        if q.x - rf - 1.0 < 0.0
            || q.y - rf - 1.0 < 0.0
            || q.x + rf + 1.0 > w - 1.0
            || q.y + rf + 1.0 > h - 1.0
        {
            return None;
        }
        let (mut a, mut b, mut c, mut bx, mut by) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        let mut k = 0;
        for dy in -r..=r {
            for dx in -r..=r {
                let px = q.x + dx as f64;
                let py = q.y + dy as f64;
                let gx = f64::from(grad.gx.bilinear_clamped(px, py));
                let gy = f64::from(grad.gy.bilinear_clamped(px, py));
                let wgt = weights[k];
                k += 1;
                let (gxx, gxy, gyy) = (wgt * gx * gx, wgt * gx * gy, wgt * gy * gy);
                a += gxx;
                b += gxy;
                c += gyy;
                bx += gxx * px + gxy * py;
                by += gxy * px + gyy * py;
            }
        }
        let det = a * c - b * b;
        if det.abs() < 1e-9 * (a * c).max(1e-12) {
            return None;
        }
        let nq = Point2::new((c * bx - b * by) / det, (a * by - b * bx) / det);
        let step = (nq - q).norm();
        q = nq;
        if (q - start).norm() > radius as f64 {
            return None;
        }
        if step < 1e-2 {
            break;
        }
    }
    Some(q)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A checkerboard with squares of `s` pixels whose corners sit at `(x0 + i s, y0 + j s)`,
    /// rendered with 8x8 supersampling per pixel (anti-aliased edges).
    fn checkerboard(w: usize, h: usize, s: f64, x0: f64, y0: f64) -> GrayImage {
        GrayImage::from_fn(w, h, |x, y| {
            let mut acc = 0.0;
            for sy in 0..8 {
                for sx in 0..8 {
                    let u = x as f64 - 0.5 + (sx as f64 + 0.5) / 8.0 - x0;
                    let v = y as f64 - 0.5 + (sy as f64 + 0.5) / 8.0 - y0;
                    let k = (u / s).floor() as i64 + (v / s).floor() as i64;
                    acc += if k.rem_euclid(2) == 0 { 200.0 } else { 40.0 };
                }
            }
            (acc / 64.0) as f32
        })
    }

    #[test]
    fn checkerboard_corners_found_to_subpixel() {
        let (x0, y0, s) = (20.3, 17.7, 16.0);
        let img = checkerboard(160, 120, s, x0, y0);
        let cfg = CornerConfig {
            max_per_bucket: 50,
            border_px: 10,
            ..CornerConfig::default()
        };
        cfg.validate().unwrap();
        let corners = detect_corners(&img, &cfg);
        // interior lattice corners inside the border
        let mut expected = Vec::new();
        for j in -2..10 {
            for i in -2..12 {
                let p = Point2::new(x0 + f64::from(i) * s, y0 + f64::from(j) * s);
                if p.x > 14.0 && p.y > 14.0 && p.x < 146.0 && p.y < 106.0 {
                    expected.push(p);
                }
            }
        }
        assert!(expected.len() > 30);
        for e in &expected {
            let best = corners
                .iter()
                .map(|c| (c.px - e).norm())
                .fold(f64::INFINITY, f64::min);
            assert!(
                best < 0.1,
                "corner {e} missed: nearest detection at {best} px"
            );
        }
        // no detection far from a lattice corner
        for c in &corners {
            let best = expected
                .iter()
                .map(|e| (c.px - e).norm())
                .fold(f64::INFINITY, f64::min);
            assert!(
                best < 3.0 || c.px.x < 16.0 || c.px.y < 16.0 || c.px.x > 144.0 || c.px.y > 104.0
            );
        }
    }

    #[test]
    fn strip_response_equals_gradient_response() {
        let img = checkerboard(97, 61, 7.0, 3.3, 2.9);
        for r in [1, 2, 3] {
            let a = min_eigen_response(&sobel(&img), r);
            let b = min_eigen_response_of_image(&img, r);
            let worst = a
                .data()
                .iter()
                .zip(b.data())
                .map(|(p, q)| (p - q).abs())
                .fold(0.0f32, f32::max);
            assert!(worst <= 1e-3, "radius {r}: {worst}");
        }
    }

    #[test]
    fn row_mask_equals_the_per_pixel_suppression() {
        // values from a small set (plateaus and ties everywhere), a NaN, and a threshold among them
        let (w, h) = (37usize, 9usize);
        let mut state = 12345u64;
        let mut data: Vec<f32> = (0..w * h)
            .map(|_| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((state >> 33) % 5) as f32
            })
            .collect();
        data[4 * w + 10] = f32::NAN;
        let r = &data;
        let mut mask = vec![0u8; w - 2];
        for threshold in [0.5f32, 2.0, 3.0] {
            for y in 1..h - 1 {
                let row = |yy: usize| &r[yy * w..(yy + 1) * w];
                local_maxima_row([row(y - 1), row(y), row(y + 1)], threshold, &mut mask);
                for x in 1..w - 1 {
                    // the loop select_corners ran before the mask
                    let v = r[y * w + x];
                    #[allow(clippy::neg_cmp_op_on_partial_ord)]
                    let mut is_max = !(v <= threshold);
                    for dy in [-1isize, 0, 1] {
                        for dx in [-1isize, 0, 1] {
                            if dx == 0 && dy == 0 {
                                continue;
                            }
                            let q =
                                r[((y as isize + dy) as usize) * w + (x as isize + dx) as usize];
                            if q > v || (q == v && (dy < 0 || (dy == 0 && dx < 0))) {
                                is_max = false;
                            }
                        }
                    }
                    assert_eq!(
                        mask[x - 1] != 0,
                        is_max,
                        "({x}, {y}), threshold {threshold}"
                    );
                }
            }
        }
    }

    #[test]
    fn bucketing_limits_per_cell_and_spreads() {
        let img = checkerboard(160, 120, 8.0, 4.5, 4.5);
        let cfg = CornerConfig {
            bucket_cols: 4,
            bucket_rows: 3,
            max_per_bucket: 2,
            ..CornerConfig::default()
        };
        let corners = detect_corners(&img, &cfg);
        assert!(corners.len() <= 24);
        assert!(corners.len() >= 20, "only {} corners", corners.len());
        let mut counts = [0usize; 12];
        for c in &corners {
            let b = ((c.px.y / 120.0 * 3.0) as usize) * 4 + (c.px.x / 160.0 * 4.0) as usize;
            counts[b] += 1;
        }
        assert!(counts.iter().all(|n| (1..=2).contains(n)), "{counts:?}");
    }

    #[test]
    fn flat_image_has_no_corners_and_bad_config_is_rejected() {
        let img = GrayImage::new(64, 64, 10.0);
        assert!(detect_corners(&img, &CornerConfig::default()).is_empty());
        let bad = CornerConfig {
            quality: 2.0,
            ..CornerConfig::default()
        };
        assert!(bad.validate().is_err());
    }
}
