//! Gaussian image pyramids with a factor of 2 between levels.
//!
//! Level `l + 1` is level `l` blurred with the 5-tap binomial kernel `[1 4 6 4 1] / 16` (separable,
//! border pixels replicated) and subsampled at the even pixels, as OpenCV's `pyrDown`. A pixel
//! position therefore maps between levels as `u_l = u_0 / 2^l` (pixel centres at integers).
//! Lucas–Kanade computes template gradients on the fly, so levels hold images only.

use rayon::prelude::*;
use visnav_core::GrayImage;

/// One pyramid level.
#[derive(Debug, Clone)]
pub struct PyramidLevel {
    /// The image at this level.
    pub image: GrayImage,
}

/// A Gaussian pyramid: `levels()[0]` is the full-resolution image.
#[derive(Debug, Clone)]
pub struct Pyramid {
    levels: Vec<PyramidLevel>,
    /// The horizontal pass of [`pyr_down_into`], kept for [`Pyramid::rebuild`].
    scratch: Vec<f32>,
}

impl Pyramid {
    /// Builds up to `num_levels` levels (at least one); stops early when a level would be smaller
    /// than 8 pixels on a side.
    #[must_use]
    pub fn build(image: &GrayImage, num_levels: usize) -> Self {
        let mut pyramid = Self {
            levels: Vec::new(),
            scratch: Vec::new(),
        };
        pyramid.rebuild(image, num_levels);
        pyramid
    }

    /// The pyramid [`Self::build`] makes of `image`, written over this one's buffers: a video
    /// front end that recycles the pyramid of an earlier frame allocates (and page-faults)
    /// nothing once the sizes repeat. The levels are the same bit for bit.
    pub fn rebuild(&mut self, image: &GrayImage, num_levels: usize) {
        let mut old = std::mem::take(&mut self.levels).into_iter();
        let mut base = old.next().map_or_else(Vec::new, |l| l.image.into_vec());
        fit(&mut base, image.data().len());
        base.copy_from_slice(image.data());
        let base = GrayImage::from_vec(image.width(), image.height(), base)
            .unwrap_or_else(|| image.clone());
        self.levels.push(PyramidLevel { image: base });
        while self.levels.len() < num_levels.max(1) {
            let last = &self.levels[self.levels.len() - 1].image;
            if last.width() < 16 || last.height() < 16 {
                break;
            }
            let out = old.next().map_or_else(Vec::new, |l| l.image.into_vec());
            let next = pyr_down_into(last, out, &mut self.scratch);
            self.levels.push(PyramidLevel { image: next });
        }
    }

    /// All levels, finest first.
    #[must_use]
    pub fn levels(&self) -> &[PyramidLevel] {
        &self.levels
    }

    /// Level `i` (0 = full resolution); `None` past the coarsest level.
    #[must_use]
    pub fn level(&self, i: usize) -> Option<&PyramidLevel> {
        self.levels.get(i)
    }

    /// The full-resolution image.
    #[must_use]
    pub fn base(&self) -> &GrayImage {
        &self.levels[0].image
    }

    /// Number of levels (at least one).
    #[must_use]
    pub fn len(&self) -> usize {
        self.levels.len()
    }

    /// Always false: a pyramid has at least its base level.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.levels.is_empty()
    }
}

/// Blurs with `[1 4 6 4 1] / 16` and keeps the even pixels: output size `(ceil(w/2), ceil(h/2))`.
#[must_use]
pub fn pyr_down(img: &GrayImage) -> GrayImage {
    pyr_down_into(img, Vec::new(), &mut Vec::new())
}

/// `buf` resized to `n` values; its old values stay where they were (the callers overwrite
/// every one), a fresh buffer comes zeroed from the allocator.
fn fit(buf: &mut Vec<f32>, n: usize) {
    if buf.capacity() < n {
        *buf = vec![0.0; n];
    } else {
        buf.resize(n, 0.0);
    }
}

/// [`pyr_down`] into the buffer `out` (resized, returned as the image), with `tmp` for the
/// horizontal pass: no allocation when both are large enough.
fn pyr_down_into(img: &GrayImage, mut out: Vec<f32>, tmp: &mut Vec<f32>) -> GrayImage {
    let (w, h) = (img.width(), img.height());
    let (w2, h2) = (w.div_ceil(2), h.div_ceil(2));
    if w == 0 || h == 0 {
        return GrayImage::new(w2, h2, 0.0);
    }
    // horizontal pass at even columns, all rows (every value written)
    fit(tmp, w2 * h);
    tmp.par_chunks_mut(w2).enumerate().for_each_init(
        || (Vec::new(), Vec::new()),
        |(even, odd): &mut (Vec<f32>, Vec<f32>), (y, out)| {
            let row = img.row(y);
            let at = |x: isize| row[x.clamp(0, w as isize - 1) as usize];
            let tap = |x2: usize| {
                let x = (2 * x2) as isize;
                (at(x - 2) + 4.0 * at(x - 1) + 6.0 * at(x) + 4.0 * at(x + 1) + at(x + 2)) / 16.0
            };
            // the interior (all five taps inside the row) on the even and odd samples apart
            let interior = 1..w2.min((w - 1) / 2); // x2 ≥ 1 and 2 x2 + 2 ≤ w − 1
            if interior.is_empty() {
                for (x2, o) in out.iter_mut().enumerate() {
                    *o = tap(x2);
                }
                return;
            }
            even.resize(w.div_ceil(2), 0.0);
            odd.resize(w / 2, 0.0);
            deinterleave(row, even, odd);
            out[0] = tap(0);
            binomial_even(even, odd, &mut out[interior.clone()]);
            let end = interior.end;
            for (x2, o) in out.iter_mut().enumerate().skip(end) {
                *o = tap(x2);
            }
        },
    );
    // vertical pass at even rows (every value written)
    let tmp: &[f32] = tmp;
    fit(&mut out, w2 * h2);
    out.par_chunks_mut(w2).enumerate().for_each(|(y2, o)| {
        let y = (2 * y2) as isize;
        let r = |dy: isize| {
            let yy = (y + dy).clamp(0, h as isize - 1) as usize;
            &tmp[yy * w2..(yy + 1) * w2]
        };
        binomial_rows([r(-2), r(-1), r(0), r(1), r(2)], o);
    });
    GrayImage::from_vec(w2, h2, out).unwrap_or_else(|| GrayImage::new(w2, h2, 0.0))
}

visnav_core::simd_kernel! {
    /// `out[i] = (e[i] + 4 o[i] + 6 e[i+1] + 4 o[i+1] + e[i+2]) / 16`: the binomial tap at the
    /// even pixel `2 (i + 1)` of a row whose even and odd samples are `e` and `o` (the same
    /// operations in the same order as at the border).
    fn binomial_even(e: &[f32], o: &[f32], out: &mut [f32]) {
        let n = out.len().min(e.len().saturating_sub(2)).min(o.len().saturating_sub(1));
        let (e0, e1, e2) = (&e[..n], &e[1..=n], &e[2..n + 2]);
        let (o0, o1) = (&o[..n], &o[1..=n]);
        for (i, v) in out[..n].iter_mut().enumerate() {
            *v = (e0[i] + 4.0 * o0[i] + 6.0 * e1[i] + 4.0 * o1[i] + e2[i]) / 16.0;
        }
    }
}

visnav_core::simd_kernel! {
    /// The even samples of `row` into `even` (`ceil(len / 2)`), the odd ones into `odd`.
    fn deinterleave(row: &[f32], even: &mut [f32], odd: &mut [f32]) {
        for ((pair, e), o) in row.chunks_exact(2).zip(even.iter_mut()).zip(odd.iter_mut()) {
            *e = pair[0];
            *o = pair[1];
        }
        if row.len() % 2 == 1
            && let (Some(e), Some(&v)) = (even.last_mut(), row.last())
        {
            *e = v;
        }
    }
}

visnav_core::simd_kernel! {
    /// The vertical binomial tap of five rows.
    fn binomial_rows(rows: [&[f32]; 5], out: &mut [f32]) {
        let n = out.len();
        let [a, b, c, d, e] = rows.map(|r| &r[..n]);
        for x in 0..n {
            out[x] = (a[x] + 4.0 * b[x] + 6.0 * c[x] + 4.0 * d[x] + e[x]) / 16.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_image_stays_constant_and_sizes_halve() {
        let img = GrayImage::new(101, 60, 42.0);
        let p = Pyramid::build(&img, 4);
        assert_eq!(p.len(), 3); // 101x60 -> 51x30 -> 26x15 (stop: 15 < 16)
        assert_eq!(
            (p.levels()[1].image.width(), p.levels()[1].image.height()),
            (51, 30)
        );
        for l in p.levels() {
            assert!(l.image.data().iter().all(|&v| (v - 42.0).abs() < 1e-4));
        }
    }

    #[test]
    fn rows_equal_the_clamped_five_taps_bit_for_bit() {
        for (w, h) in [(37, 9), (38, 8), (5, 4), (4, 5), (3, 3), (1, 6), (2, 1)] {
            let img =
                GrayImage::from_fn(w, h, |x, y| ((x * 7919 + y * 104_729) % 251) as f32 * 0.37);
            let down = pyr_down(&img);
            let at = |x: isize, y: isize| {
                img.get(
                    x.clamp(0, w as isize - 1) as usize,
                    y.clamp(0, h as isize - 1) as usize,
                )
            };
            let row = |x: isize, y: isize| {
                (at(x - 2, y)
                    + 4.0 * at(x - 1, y)
                    + 6.0 * at(x, y)
                    + 4.0 * at(x + 1, y)
                    + at(x + 2, y))
                    / 16.0
            };
            for y2 in 0..down.height() {
                for x2 in 0..down.width() {
                    let (x, y) = (2 * x2 as isize, 2 * y2 as isize);
                    let v = (row(x, y - 2)
                        + 4.0 * row(x, y - 1)
                        + 6.0 * row(x, y)
                        + 4.0 * row(x, y + 1)
                        + row(x, y + 2))
                        / 16.0;
                    assert_eq!(
                        down.get(x2, y2).to_bits(),
                        v.to_bits(),
                        "{w}x{h} at {x2},{y2}"
                    );
                }
            }
        }
    }

    #[test]
    fn rebuild_over_old_buffers_equals_build() {
        let image = |w: usize, h: usize, k: usize| {
            GrayImage::from_fn(w, h, |x, y| {
                ((x * 7919 + y * 104_729 + k) % 251) as f32 * 0.37
            })
        };
        let mut recycled = Pyramid::build(&image(90, 70, 0), 4);
        // the same size (buffers reused), a larger and a smaller image, fewer levels
        for (w, h, levels) in [(90, 70, 4), (131, 77, 4), (40, 33, 4), (90, 70, 2)] {
            let fresh = image(w, h, w + levels);
            recycled.rebuild(&fresh, levels);
            let built = Pyramid::build(&fresh, levels);
            assert_eq!(recycled.len(), built.len(), "{w}x{h}");
            for (a, b) in recycled.levels().iter().zip(built.levels()) {
                assert_eq!(a.image, b.image, "{w}x{h}");
            }
        }
    }

    #[test]
    fn linear_ramp_maps_coordinates_by_half() {
        // I(x) = 3x at level 0 => I1(x1) = 3 * 2 x1 away from the border
        let img = GrayImage::from_fn(64, 32, |x, _| 3.0 * x as f32);
        let l1 = pyr_down(&img);
        for x1 in 2..28 {
            assert!((l1.get(x1, 5) - 6.0 * x1 as f32).abs() < 1e-3);
        }
    }
}
