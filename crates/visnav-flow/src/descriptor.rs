//! Hand-crafted unit-norm per-pixel descriptors at the matching resolution (stand-in for
//! DCFlow's learned 64-D features): intensity gradients sampled on a 3x3 grid at two scales
//! (stride 1 on the image, stride 2 on its 3x3 box blur), 36 values normalised to unit length.
//! The matching cost of two descriptors is `1 - f1·f2` (DCFlow), stored as `127 (1 - f1·f2)`.

use rayon::prelude::*;
use visnav_core::GrayImage;

use crate::ops::{box_filter, gradients};

/// Values per descriptor.
pub const DIM: usize = 36;

/// Descriptors of one image, `data[DIM * (y * width + x) ..][..DIM]`.
#[derive(Debug, Clone)]
pub struct Descriptors {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major descriptors, `DIM` values each, unit norm (or all zero on a flat patch).
    pub data: Vec<f32>,
}

impl Descriptors {
    /// Descriptor of pixel `i`.
    #[must_use]
    #[inline]
    pub fn at(&self, i: usize) -> &[f32] {
        &self.data[i * DIM..(i + 1) * DIM]
    }
}

/// Computes the descriptors of `img` (already at matching resolution).
#[must_use]
pub fn compute(img: &GrayImage) -> Descriptors {
    let w = img.width();
    let h = img.height();
    let (gx, gy) = gradients(img);
    let blurred = GrayImage::from_vec(w, h, box_filter(img.data(), w, h, 1, 1))
        .unwrap_or_else(|| img.clone());
    let (bx, by) = gradients(&blurred);
    let mut data = vec![0.0_f32; w * h * DIM];
    data.par_chunks_mut(w * DIM)
        .enumerate()
        .for_each(|(y, row)| {
            let yi = y as isize;
            for x in 0..w {
                let xi = x as isize;
                let d = &mut row[x * DIM..(x + 1) * DIM];
                let mut k = 0;
                for oy in -1..=1_isize {
                    for ox in -1..=1_isize {
                        d[k] = gx.get_clamped(xi + ox, yi + oy);
                        d[k + 1] = gy.get_clamped(xi + ox, yi + oy);
                        d[k + 2] = bx.get_clamped(xi + 2 * ox, yi + 2 * oy);
                        d[k + 3] = by.get_clamped(xi + 2 * ox, yi + 2 * oy);
                        k += 4;
                    }
                }
                let norm = d.iter().map(|v| v * v).sum::<f32>().sqrt();
                if norm > 1e-3 {
                    for v in d.iter_mut() {
                        *v /= norm;
                    }
                } else {
                    d.fill(0.0);
                }
            }
        });
    Descriptors {
        width: w,
        height: h,
        data,
    }
}

/// Inverse norms of the sums of neighbouring descriptors, for the half-label cost
/// (`FlowConfig::half_label_cost`, [`crate::volume::cost_volume`]): the descriptor of a point
/// half-way between two pixels (or in the middle of four) is taken as the renormalised mean of
/// theirs, so its dot product with `f` is `(f·a + f·b) / |a + b|` — one stored factor per pixel
/// and direction. Zero where a neighbour leaves the image or the sum vanishes (flat patches).
#[derive(Debug, Clone)]
pub struct HalfNorms {
    /// `1 / |d(x, y) + d(x + 1, y)|`.
    pub x: Vec<f32>,
    /// `1 / |d(x, y) + d(x, y + 1)|`.
    pub y: Vec<f32>,
    /// `1 / |d(x, y) + d(x + 1, y) + d(x, y + 1) + d(x + 1, y + 1)|`.
    pub xy: Vec<f32>,
}

/// The [`HalfNorms`] of `d`.
#[must_use]
pub fn half_norms(d: &Descriptors) -> HalfNorms {
    let (w, h) = (d.width, d.height);
    let inv = |sum: &[f32; DIM]| -> f32 {
        let n2: f32 = sum.iter().map(|v| v * v).sum();
        if n2 > 1e-6 { 1.0 / n2.sqrt() } else { 0.0 }
    };
    let mut x = vec![0.0_f32; w * h];
    let mut y = vec![0.0_f32; w * h];
    let mut xy = vec![0.0_f32; w * h];
    x.par_chunks_mut(w)
        .zip(y.par_chunks_mut(w))
        .zip(xy.par_chunks_mut(w))
        .enumerate()
        .for_each(|(row, ((rx, ry), rxy))| {
            for col in 0..w {
                let i = row * w + col;
                let a = d.at(i);
                let right = col + 1 < w;
                let below = row + 1 < h;
                if right {
                    let b = d.at(i + 1);
                    let mut s = [0.0_f32; DIM];
                    for k in 0..DIM {
                        s[k] = a[k] + b[k];
                    }
                    rx[col] = inv(&s);
                    if below {
                        let (c, e) = (d.at(i + w), d.at(i + w + 1));
                        for k in 0..DIM {
                            s[k] += c[k] + e[k];
                        }
                        rxy[col] = inv(&s);
                    }
                }
                if below {
                    let c = d.at(i + w);
                    let mut s = [0.0_f32; DIM];
                    for k in 0..DIM {
                        s[k] = a[k] + c[k];
                    }
                    ry[col] = inv(&s);
                }
            }
        });
    HalfNorms { x, y, xy }
}

/// The u8 cost of a dot product, `127 (1 - dot)`, rounded.
#[must_use]
#[inline]
pub fn cost_of_dot(dot: f32) -> u8 {
    (127.0 * (1.0 - dot) + 0.5).clamp(0.0, 254.0) as u8
}

/// The dot product of two descriptors (eight-lane partial sums).
#[must_use]
#[inline]
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    // eight independent partial sums: the compiler turns them into SIMD lanes (a single
    // running f32 sum cannot be reordered, so it would stay scalar)
    let mut acc = [0.0_f32; 8];
    let (a8, a_rest) = a.split_at(a.len() - a.len() % 8);
    let (b8, b_rest) = b.split_at(a8.len().min(b.len()));
    for (ca, cb) in a8.chunks_exact(8).zip(b8.chunks_exact(8)) {
        for k in 0..8 {
            acc[k] += ca[k] * cb[k];
        }
    }
    let tail: f32 = a_rest.iter().zip(b_rest).map(|(x, y)| x * y).sum();
    acc.iter().sum::<f32>() + tail
}

/// Descriptors by row and component: `data[(y * DIM + k) * width + x]` is component `k` of pixel
/// `(x, y)`, so one component of neighbouring pixels is contiguous ([`dots8`]).
#[derive(Debug, Clone)]
pub struct Transposed {
    width: usize,
    data: Vec<f32>,
}

impl Transposed {
    /// The transposed copy of `d`.
    #[must_use]
    pub fn of(d: &Descriptors) -> Self {
        let w = d.width;
        let mut data = vec![0.0_f32; w * d.height * DIM];
        data.par_chunks_mut(w * DIM)
            .enumerate()
            .for_each(|(y, rows)| {
                for (x, desc) in d.data[y * w * DIM..(y + 1) * w * DIM]
                    .chunks_exact(DIM)
                    .enumerate()
                {
                    for (k, v) in desc.iter().enumerate() {
                        rows[k * w + x] = *v;
                    }
                }
            });
        Self { width: w, data }
    }
}

/// [`dot`] of `a` with the descriptors of the eight pixels `(x..x + 8, y)` of `t`, the same
/// values bit for bit: each label's eight partial sums, their sum and the tail's in [`dot`]'s
/// order, with the eight labels in the lanes of one vector instead of one label's partial sums.
/// The pixels must lie inside `t`.
#[must_use]
#[inline(always)]
pub fn dots8(a: &[f32], t: &Transposed, y: usize, x: usize) -> [f32; 8] {
    let w = t.width;
    let rows = &t.data[y * DIM * w..(y + 1) * DIM * w];
    let lanes = |k: usize| -> [f32; 8] {
        let mut v = [0.0_f32; 8];
        v.copy_from_slice(&rows[k * w + x..k * w + x + 8]);
        v
    };
    let main = DIM - DIM % 8;
    // `Iterator::sum` folds from its own neutral value: start where it does
    let zero: f32 = std::iter::empty::<f32>().sum();
    let (mut sum, mut tail) = ([zero; 8], [zero; 8]);
    // partial sum `k` over the chunks, then added to the sum in `k`'s order: the order of
    // `dot`, which finishes every partial sum before it adds them up
    for k in 0..8 {
        let mut acc = [0.0_f32; 8];
        for chunk in (0..main).step_by(8) {
            let (ak, bk) = (a[chunk + k], lanes(chunk + k));
            for l in 0..8 {
                acc[l] += ak * bk[l];
            }
        }
        for l in 0..8 {
            sum[l] += acc[l];
        }
    }
    for (k, &ak) in a.iter().enumerate().take(DIM).skip(main) {
        let bk = lanes(k);
        for l in 0..8 {
            tail[l] += ak * bk[l];
        }
    }
    let mut out = [0.0_f32; 8];
    for l in 0..8 {
        out[l] = sum[l] + tail[l];
    }
    out
}

/// [`cost_of_dot`] of eight dot products (the same values; the clamped value converted through
/// `i32`, which vectorises, instead of straight to `u8`).
#[inline(always)]
pub fn costs_of_dots(dots: &[f32; 8], out: &mut [u8]) {
    for (o, &d) in out.iter_mut().zip(dots) {
        *o = (127.0 * (1.0 - d) + 0.5).clamp(0.0, 254.0) as i32 as u8;
    }
}

/// DCFlow's u8 cost `127 (1 - a·b)`, rounded.
#[must_use]
#[inline]
pub fn cost(a: &[f32], b: &[f32]) -> u8 {
    cost_of_dot(dot(a, b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn descriptors_are_unit_norm_and_self_cost_zero() {
        let img = GrayImage::from_fn(20, 15, |x, y| ((x * 7 + y * 13) % 17) as f32 * 10.0);
        let d = compute(&img);
        let n: f32 = d.at(50).iter().map(|v| v * v).sum();
        assert!((n - 1.0).abs() < 1e-4);
        assert_eq!(cost(d.at(50), d.at(50)), 0);
        assert!(cost(d.at(50), d.at(51)) > 10);
    }

    #[test]
    fn eight_costs_at_once_equal_cost_of_dot() {
        let values = [
            -3.0,
            -1.0,
            -0.0,
            0.0,
            0.3,
            0.996,
            1.0,
            1.5,
            f32::NAN,
            f32::INFINITY,
            -f32::INFINITY,
        ];
        for start in 0..values.len() {
            let dots: [f32; 8] = std::array::from_fn(|i| values[(start + i) % values.len()]);
            let mut out = [0_u8; 8];
            costs_of_dots(&dots, &mut out);
            for (o, d) in out.iter().zip(dots) {
                assert_eq!(*o, cost_of_dot(d), "{d}");
            }
        }
    }

    #[test]
    fn eight_labels_at_once_equal_dot_bit_for_bit() {
        let img = GrayImage::from_fn(37, 11, |x, y| ((x * 7919 + y * 104_729) % 251) as f32);
        let d = compute(&img);
        let t = Transposed::of(&d);
        // a flat patch's all-zero descriptor too
        let zero = [0.0_f32; DIM];
        for y in [0, 5, 10] {
            for x in [0, 13, 29] {
                for a in [d.at(5 * 37 + 17), d.at(y * 37 + x), &zero[..]] {
                    let lanes = dots8(a, &t, y, x);
                    for (l, v) in lanes.iter().enumerate() {
                        let one = dot(a, d.at(y * 37 + x + l));
                        assert_eq!(v.to_bits(), one.to_bits(), "({x} + {l}, {y})");
                    }
                }
            }
        }
    }

    #[test]
    fn lane_sum_cost_equals_plain_dot_product() {
        let img = GrayImage::from_fn(30, 20, |x, y| ((x * 7 + y * 13) % 17) as f32 * 10.0);
        let d = compute(&img);
        for (i, j) in [(40, 41), (100, 377), (250, 251), (0, 599)] {
            let dot: f32 = d.at(i).iter().zip(d.at(j)).map(|(x, y)| x * y).sum();
            let plain = (127.0 * (1.0 - dot) + 0.5).clamp(0.0, 254.0);
            assert!((f32::from(cost(d.at(i), d.at(j))) - plain).abs() <= 1.0);
        }
    }
}
