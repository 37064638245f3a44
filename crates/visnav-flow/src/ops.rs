//! Small image operations used by the flow stage: box downsampling, gradients, box filters,
//! bilinear sampling of flow fields. Pixel centres are at integer coordinates; a pixel `i` of an
//! image downsampled by `s` covers source pixels `s*i .. s*i+s-1`, so its centre sits at
//! `s*i + (s-1)/2` in the source.

use rayon::prelude::*;
use visnav_core::GrayImage;
use visnav_core::bilinear::Bilinear;

/// Mean of every `s` x `s` block (the image is cropped to a multiple of `s`).
#[must_use]
pub fn downsample_box(img: &GrayImage, s: usize) -> GrayImage {
    let w = img.width() / s;
    let h = img.height() / s;
    let norm = 1.0 / (s * s) as f32;
    let mut data = vec![0.0_f32; w * h];
    data.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                let mut acc = 0.0;
                for dy in 0..s {
                    let src = img.row(y * s + dy);
                    acc += src[x * s..x * s + s].iter().sum::<f32>();
                }
                *out = acc * norm;
            }
        });
    GrayImage::from_vec(w, h, data).unwrap_or_else(|| GrayImage::new(w, h, 0.0))
}

/// Central-difference gradients `(gx, gy)` with replicated borders, intensity per pixel.
#[must_use]
pub fn gradients(img: &GrayImage) -> (GrayImage, GrayImage) {
    let w = img.width();
    let h = img.height();
    let mut gx = vec![0.0_f32; w * h];
    let mut gy = vec![0.0_f32; w * h];
    gx.par_chunks_mut(w.max(1))
        .zip(gy.par_chunks_mut(w.max(1)))
        .enumerate()
        .for_each(|(y, (rx, ry))| {
            let yi = y as isize;
            for (x, (ox, oy)) in rx.iter_mut().zip(ry.iter_mut()).enumerate() {
                let xi = x as isize;
                *ox = 0.5 * (img.get_clamped(xi + 1, yi) - img.get_clamped(xi - 1, yi));
                *oy = 0.5 * (img.get_clamped(xi, yi + 1) - img.get_clamped(xi, yi - 1));
            }
        });
    let image = |data| GrayImage::from_vec(w, h, data).unwrap_or_else(|| GrayImage::new(w, h, 0.0));
    (image(gx), image(gy))
}

/// Gradient magnitude, intensity per pixel.
#[must_use]
pub fn gradient_magnitude(img: &GrayImage) -> Vec<f32> {
    let (gx, gy) = gradients(img);
    gx.data()
        .iter()
        .zip(gy.data())
        .map(|(a, b)| a.hypot(*b))
        .collect()
}

/// Box mean over a `(2r+1)²` window with clamped borders, applied to `channels` interleaved
/// planes of a `w` x `h` buffer.
#[must_use]
pub fn box_filter(src: &[f32], w: usize, h: usize, channels: usize, r: usize) -> Vec<f32> {
    if r == 0 {
        return src.to_vec();
    }
    let stride = w * channels;
    let mut tmp = vec![0.0_f32; src.len()];
    tmp.par_chunks_mut(stride)
        .zip(src.par_chunks(stride))
        .for_each(|(out, row)| horizontal_box_mean(out, row, channels, r));
    vertical_box_mean(&tmp, stride, h, r)
}

visnav_core::simd_kernel! {
    /// The horizontal pass of [`box_filter`] over one row of `channels` interleaved planes.
    ///
    /// Every output is the sum of its window taken from left to right, then divided by the
    /// window's size. Away from the borders the windows are summed tap by tap across the whole
    /// row (contiguous, so the additions vectorise) in that same order, so the result is the
    /// one of the per-pixel loop used at the borders, bit for bit.
    fn horizontal_box_mean(out: &mut [f32], row: &[f32], channels: usize, r: usize) {
        let w = row.len() / channels;
        let interior = if w > 2 * r { r..w - r } else { 0..0 };
        if !interior.is_empty() {
            let (a, b) = (interior.start * channels, interior.end * channels);
            let acc = &mut out[a..b];
            acc.fill(0.0);
            for k in 0..=2 * r {
                let src = &row[k * channels..k * channels + (b - a)];
                for (o, v) in acc.iter_mut().zip(src) {
                    *o += *v;
                }
            }
            let n = (2 * r + 1) as f32;
            for o in acc.iter_mut() {
                *o /= n;
            }
        }
        for x in (0..interior.start).chain(interior.end..w) {
            let lo = x.saturating_sub(r);
            let hi = (x + r).min(w - 1);
            let n = (hi - lo + 1) as f32;
            for c in 0..channels {
                let mut acc = 0.0;
                for xx in lo..=hi {
                    acc += row[xx * channels + c];
                }
                out[x * channels + c] = acc / n;
            }
        }
    }
}

/// As [`box_filter`] (the same clamped windows), with running sums along the rows: the cost no
/// longer grows with `r` there. Sums in f64, so the result equals [`box_filter`]'s up to f32
/// rounding.
#[must_use]
pub fn box_filter_running(src: &[f32], w: usize, h: usize, channels: usize, r: usize) -> Vec<f32> {
    if r == 0 || w == 0 {
        return src.to_vec();
    }
    let stride = w * channels;
    let mut tmp = vec![0.0_f32; src.len()];
    tmp.par_chunks_mut(stride)
        .zip(src.par_chunks(stride))
        .for_each(|(out, row)| horizontal_running_mean(out, row, channels, r));
    vertical_box_mean(&tmp, stride, h, r)
}

/// The horizontal pass of [`box_filter_running`] over one row of `channels` interleaved planes:
/// running sums in f64, each output the clamped window's sum over its size.
pub(crate) fn horizontal_running_mean(out: &mut [f32], row: &[f32], channels: usize, r: usize) {
    let w = row.len() / channels;
    let mut acc = vec![0.0_f64; channels];
    for xx in 0..=r.min(w - 1) {
        for (c, a) in acc.iter_mut().enumerate() {
            *a += f64::from(row[xx * channels + c]);
        }
    }
    for x in 0..w {
        let n = ((x + r).min(w - 1) - x.saturating_sub(r) + 1) as f64;
        for (c, a) in acc.iter_mut().enumerate() {
            out[x * channels + c] = (*a / n) as f32;
        }
        if x + r + 1 < w {
            for (c, a) in acc.iter_mut().enumerate() {
                *a += f64::from(row[(x + r + 1) * channels + c]);
            }
        }
        if x >= r {
            for (c, a) in acc.iter_mut().enumerate() {
                *a -= f64::from(row[(x - r) * channels + c]);
            }
        }
    }
}

/// Row `y` (of `h`) of the vertical pass of [`box_filter`] / [`box_filter_running`] from a band
/// of horizontally filtered rows starting at image row `band_start` (it must hold rows
/// `y - r ..= y + r`, clamped to the image): the same sums in the same order as the whole-image
/// pass, so the same bits.
pub(crate) fn vertical_box_row_in_band(
    y: usize,
    orow: &mut [f32],
    band: &[f32],
    band_start: usize,
    h: usize,
    r: usize,
) {
    let stride = orow.len();
    let lo = y.saturating_sub(r);
    let hi = (y + r).min(h - 1);
    let n = (hi - lo + 1) as f32;
    orow.fill(0.0);
    for yy in lo..=hi {
        let k = yy - band_start;
        for (o, t) in orow.iter_mut().zip(&band[k * stride..(k + 1) * stride]) {
            *o += *t;
        }
    }
    for o in orow.iter_mut() {
        *o /= n;
    }
}

/// The vertical pass shared by [`box_filter`] and [`box_filter_running`]: the mean of the rows
/// `y - r ..= y + r` (clamped to the image) of `tmp`, `stride` values a row.
fn vertical_box_mean(tmp: &[f32], stride: usize, h: usize, r: usize) -> Vec<f32> {
    let mut out = vec![0.0_f32; tmp.len()];
    out.par_chunks_mut(stride)
        .enumerate()
        .for_each(|(y, orow)| vertical_box_row(y, orow, tmp, h, r));
    out
}

visnav_core::simd_kernel! {
    /// Row `y` of [`vertical_box_mean`] (`orow` starts zeroed).
    fn vertical_box_row(y: usize, orow: &mut [f32], tmp: &[f32], h: usize, r: usize) {
        let stride = orow.len();
        let lo = y.saturating_sub(r);
        let hi = (y + r).min(h - 1);
        let n = (hi - lo + 1) as f32;
        for yy in lo..=hi {
            let trow = &tmp[yy * stride..(yy + 1) * stride];
            for (o, t) in orow.iter_mut().zip(trow) {
                *o += *t;
            }
        }
        for o in orow.iter_mut() {
            *o /= n;
        }
    }
}

/// Forward–backward discrepancy `|f(p) + b(p + f(p))|` per pixel of a `w x h` field, px of
/// that field (infinite where `p + f(p)` leaves the image); `b` is sampled bilinearly.
#[must_use]
pub fn forward_backward_discrepancy(
    fwd: &[[f32; 2]],
    bwd: &[[f32; 2]],
    w: usize,
    h: usize,
) -> Vec<f32> {
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let x = (i % w) as f32;
            let y = (i / w) as f32;
            let f = fwd[i];
            let (tx, ty) = (x + f[0], y + f[1]);
            if tx < 0.0 || ty < 0.0 || tx > (w - 1) as f32 || ty > (h - 1) as f32 {
                return f32::INFINITY;
            }
            let b = sample_field(bwd, w, h, tx, ty);
            (f[0] + b[0]).hypot(f[1] + b[1])
        })
        .collect()
}

/// Bilinear sample of a 2-channel field at continuous `(x, y)`, clamped to the grid
/// ([`Bilinear::clamped_f32`]).
#[must_use]
#[inline]
pub fn sample_field(field: &[[f32; 2]], w: usize, h: usize, x: f32, y: f32) -> [f32; 2] {
    Bilinear::clamped_f32(x, y, w, h).sample(field)
}

/// Resamples a flow field from a grid whose pixel `i` sits at source coordinate
/// `scale * i + offset` onto the source grid (`w` x `h`), multiplying the vectors by `scale`.
#[must_use]
pub fn upsample_flow(
    flow: &[[f32; 2]],
    fw: usize,
    fh: usize,
    w: usize,
    h: usize,
    scale: f32,
    offset: f32,
) -> Vec<[f32; 2]> {
    resample_field(flow, (fw, fh), (w, h), scale, offset, scale)
}

/// Resamples an `N`-channel field from a `fw` x `fh` grid whose pixel `i` sits at source
/// coordinate `scale * i + offset` onto the `w` x `h` source grid (bilinear, clamped: the
/// sampler of [`sample_field`]), multiplying every channel by `gain` (`scale` for a flow,
/// `scale²` for a covariance).
#[must_use]
pub fn resample_field<const N: usize>(
    field: &[[f32; N]],
    (fw, fh): (usize, usize),
    (w, h): (usize, usize),
    scale: f32,
    offset: f32,
    gain: f32,
) -> Vec<[f32; N]> {
    let mut out = vec![[0.0_f32; N]; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let yc = (y as f32 - offset) / scale;
        for (x, o) in row.iter_mut().enumerate() {
            let xc = (x as f32 - offset) / scale;
            let f = Bilinear::clamped_f32(xc, yc, fw, fh).sample(field);
            *o = f.map(|v| v * gain);
        }
    });
    out
}

/// Component-wise median of the flow over a `(2r+1)²` window (clamped at the borders).
///
/// Exact, in near-constant time per pixel: each component's values are ranked once over the
/// whole field (sorted in the order of `f32::total_cmp`, ties by position, so every pixel has a
/// distinct rank), and the window slides along each row as a set of ranks (`RankWindow`: a
/// bitmap with counts per block of ranks), where the `⌊len/2⌋`-th smallest rank — the value a
/// selection over the window would return — is found by walking the block counts and then the
/// bitmap's words.
#[must_use]
pub fn median_filter(flow: &[[f32; 2]], w: usize, h: usize, r: usize) -> Vec<[f32; 2]> {
    if r == 0 || w == 0 || h == 0 {
        return flow.to_vec();
    }
    let (u, v) = rayon::join(|| Ranking::new(flow, 0), || Ranking::new(flow, 1));
    let n = w * h;
    let mut out = vec![[0.0_f32; 2]; n];
    out.par_chunks_mut(w).enumerate().for_each_init(
        || [RankWindow::new(n), RankWindow::new(n)],
        |windows, (y, row)| {
            let (y0, y1) = (y.saturating_sub(r), (y + r).min(h - 1));
            let ranks = [&u.rank, &v.rank];
            for (win, rank) in windows.iter_mut().zip(ranks) {
                win.clear();
                for x in 0..=r.min(w - 1) {
                    for yy in y0..=y1 {
                        win.insert(rank[yy * w + x]);
                    }
                }
            }
            for (x, o) in row.iter_mut().enumerate() {
                if x > 0 {
                    for (win, rank) in windows.iter_mut().zip(ranks) {
                        if x > r {
                            for yy in y0..=y1 {
                                win.remove(rank[yy * w + x - r - 1]);
                            }
                        }
                        if x + r < w {
                            for yy in y0..=y1 {
                                win.insert(rank[yy * w + x + r]);
                            }
                        }
                    }
                }
                let k = windows[0].len / 2;
                *o = [
                    u.sorted[windows[0].kth(k) as usize],
                    v.sorted[windows[1].kth(k) as usize],
                ];
            }
        },
    );
    out
}

/// One component of a flow field ranked in the order of `f32::total_cmp` (ties by position).
struct Ranking {
    /// Rank of each pixel's value.
    rank: Vec<u32>,
    /// The values in rank order.
    sorted: Vec<f32>,
}

impl Ranking {
    fn new(flow: &[[f32; 2]], c: usize) -> Self {
        // the total order of f32 as unsigned integers, the position in the low half
        let mut keyed: Vec<u64> = flow
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let b = f[c].to_bits() as i32;
                let key = (b ^ (((b >> 31) as u32) >> 1) as i32) as u32 ^ 0x8000_0000;
                (u64::from(key) << 32) | i as u64
            })
            .collect();
        keyed.sort_unstable();
        let mut rank = vec![0_u32; flow.len()];
        let sorted = keyed
            .iter()
            .enumerate()
            .map(|(k, e)| {
                let i = (e & 0xFFFF_FFFF) as usize;
                rank[i] = k as u32;
                flow[i][c]
            })
            .collect();
        Self { rank, sorted }
    }
}

/// A set of distinct ranks in `0..n`: a bitmap, and the count per block of
/// `64 * RankWindow::BLOCK_WORDS` ranks for a quick walk to the `k`-th smallest.
struct RankWindow {
    bits: Vec<u64>,
    counts: Vec<u32>,
    len: usize,
}

impl RankWindow {
    const BLOCK_WORDS: usize = 16;

    fn new(n: usize) -> Self {
        let words = n.div_ceil(64);
        Self {
            bits: vec![0; words],
            counts: vec![0; words.div_ceil(Self::BLOCK_WORDS)],
            len: 0,
        }
    }

    fn clear(&mut self) {
        self.bits.fill(0);
        self.counts.fill(0);
        self.len = 0;
    }

    #[inline]
    fn insert(&mut self, rank: u32) {
        let r = rank as usize;
        self.bits[r >> 6] |= 1 << (r & 63);
        self.counts[r >> 6 >> 4] += 1;
        self.len += 1;
    }

    #[inline]
    fn remove(&mut self, rank: u32) {
        let r = rank as usize;
        self.bits[r >> 6] &= !(1 << (r & 63));
        self.counts[r >> 6 >> 4] -= 1;
        self.len -= 1;
    }

    /// The `k`-th smallest rank (0-based), `k < len`.
    #[inline]
    fn kth(&self, k: usize) -> u32 {
        let mut k = k as u32;
        let mut block = 0;
        while k >= self.counts[block] {
            k -= self.counts[block];
            block += 1;
        }
        let mut word = block * Self::BLOCK_WORDS;
        loop {
            let c = self.bits[word].count_ones();
            if k < c {
                break;
            }
            k -= c;
            word += 1;
        }
        let mut bits = self.bits[word];
        for _ in 0..k {
            bits &= bits - 1;
        }
        (word * 64) as u32 + bits.trailing_zeros()
    }
}

/// The direct form of [`median_filter`] (a selection per pixel), the reference of its tests.
#[cfg(test)]
fn median_filter_direct(flow: &[[f32; 2]], w: usize, h: usize, r: usize) -> Vec<[f32; 2]> {
    let mut out = vec![[0.0_f32; 2]; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut us = Vec::new();
            let mut vs = Vec::new();
            for yy in y.saturating_sub(r)..=(y + r).min(h - 1) {
                for xx in x.saturating_sub(r)..=(x + r).min(w - 1) {
                    let f = flow[yy * w + xx];
                    us.push(f[0]);
                    vs.push(f[1]);
                }
            }
            let mid = us.len() / 2;
            let mu = *us.select_nth_unstable_by(mid, f32::total_cmp).1;
            let mv = *vs.select_nth_unstable_by(mid, f32::total_cmp).1;
            out[y * w + x] = [mu, mv];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn running_box_filter_matches_the_direct_one() {
        let (w, h) = (13, 9);
        let src: Vec<f32> = (0..w * h * 3)
            .map(|i| ((i * 37) % 101) as f32 - 50.0)
            .collect();
        for r in [1, 2, 5, 20] {
            let a = box_filter(&src, w, h, 3, r);
            let b = box_filter_running(&src, w, h, 3, r);
            for (x, y) in a.iter().zip(&b) {
                assert!((x - y).abs() < 1e-4, "r {r}: {x} {y}");
            }
        }
    }

    #[test]
    fn downsample_averages_blocks() {
        let img = GrayImage::from_fn(7, 6, |x, y| (x + 10 * y) as f32);
        let d = downsample_box(&img, 3);
        assert_eq!((d.width(), d.height()), (2, 2));
        // block (0,0): x 0..3, y 0..3 -> mean x 1, mean y 1
        assert!((d.get(0, 0) - 11.0).abs() < 1e-4);
        assert!((d.get(1, 1) - (4.0 + 40.0)).abs() < 1e-4);
    }

    #[test]
    fn box_filter_keeps_constant_and_averages() {
        let src: Vec<f32> = (0..20).map(|i| (i % 5) as f32).collect();
        let out = box_filter(&src, 5, 4, 1, 1);
        // interior pixel x=2: mean of 1,2,3 = 2
        assert!((out[5 + 2] - 2.0).abs() < 1e-5);
        let c = box_filter(&[3.0; 40], 5, 4, 2, 2);
        assert!(c.iter().all(|v| (v - 3.0).abs() < 1e-5));
    }

    #[test]
    fn box_filter_equals_per_pixel_window_sums_bit_for_bit() {
        let mut state = 7_u32;
        for (w, h, channels, r) in [
            (31_usize, 9_usize, 5_usize, 3_usize),
            (40, 6, 1, 7),
            (14, 5, 1, 7),
            (9, 4, 2, 4),
        ] {
            let src: Vec<f32> = (0..w * h * channels)
                .map(|_| {
                    state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    ((state >> 9) % 10_007) as f32 * 0.013_7 - 60.0
                })
                .collect();
            // the definition: each window summed from left to right, then from top to bottom
            let mut rows = vec![0.0_f32; src.len()];
            for y in 0..h {
                for x in 0..w {
                    let (lo, hi) = (x.saturating_sub(r), (x + r).min(w - 1));
                    for c in 0..channels {
                        let mut acc = 0.0_f32;
                        for xx in lo..=hi {
                            acc += src[(y * w + xx) * channels + c];
                        }
                        rows[(y * w + x) * channels + c] = acc / (hi - lo + 1) as f32;
                    }
                }
            }
            let out = box_filter(&src, w, h, channels, r);
            let expected = vertical_box_mean(&rows, w * channels, h, r);
            assert!(
                out.iter()
                    .zip(&expected)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{w}x{h}x{channels}, r {r}"
            );
        }
    }

    #[test]
    fn ranked_median_equals_a_selection_per_pixel() {
        // pseudo-random values with repeats, signed zeros, negative values and outliers
        let (w, h) = (23, 17);
        let mut state = 12_345_u32;
        let flow: Vec<[f32; 2]> = (0..w * h)
            .map(|_| {
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let a = ((state >> 8) % 41) as f32 * 0.25 - 5.0;
                let b = if state.is_multiple_of(7) {
                    -0.0
                } else if state.is_multiple_of(5) {
                    0.0
                } else {
                    ((state >> 16) % 13) as f32
                };
                [a, if state.is_multiple_of(31) { -1e6 } else { b }]
            })
            .collect();
        for r in [1, 2, 7, 30] {
            let got = median_filter(&flow, w, h, r);
            let want = median_filter_direct(&flow, w, h, r);
            let bits = |f: &[[f32; 2]]| -> Vec<[u32; 2]> {
                f.iter().map(|v| [v[0].to_bits(), v[1].to_bits()]).collect()
            };
            assert_eq!(bits(&got), bits(&want), "radius {r}");
        }
        // a single row / column, and a window wider than a rank block
        let line: Vec<[f32; 2]> = flow[..w].to_vec();
        assert_eq!(
            median_filter(&line, w, 1, 3),
            median_filter_direct(&line, w, 1, 3)
        );
        assert_eq!(
            median_filter(&line, 1, w, 3),
            median_filter_direct(&line, 1, w, 3)
        );
        let (bw, bh) = (300, 9);
        let big: Vec<[f32; 2]> = (0..bw * bh)
            .map(|i| {
                [
                    ((i * 7919) % 1013) as f32,
                    ((i * 104_729) % 97) as f32 - 40.0,
                ]
            })
            .collect();
        assert_eq!(
            median_filter(&big, bw, bh, 7),
            median_filter_direct(&big, bw, bh, 7)
        );
    }

    #[test]
    fn upsample_linear_flow_is_exact_inside() {
        // flow at coarse pixel i = (i, 0) coarse px -> full res flow 3*i at x = 3i+1
        let fw = 6;
        let fh = 4;
        let coarse: Vec<[f32; 2]> = (0..fw * fh).map(|i| [(i % fw) as f32, 0.0]).collect();
        let full = upsample_flow(&coarse, fw, fh, 18, 12, 3.0, 1.0);
        let x = 7; // coarse coordinate 2
        assert!((full[5 * 18 + x][0] - 6.0).abs() < 1e-4);
    }
}
