//! Image gradients by 3x3 Sobel and Scharr operators, normalised to intensity per pixel
//! (Sobel divided by 8, Scharr by 32, so a ramp `I = a x` gives `gx = a`). Borders replicate.

use rayon::prelude::*;
use visnav_core::GrayImage;

/// Horizontal and vertical derivatives of an image (same size), intensity per pixel.
#[derive(Debug, Clone)]
pub struct Gradients {
    /// `∂I/∂x` (along columns).
    pub gx: GrayImage,
    /// `∂I/∂y` (along rows).
    pub gy: GrayImage,
}

/// The 3x3 Sobel gradients (smoothing `[1 2 1]`, difference `[-1 0 1]`) divided by 8.
#[must_use]
pub fn sobel(img: &GrayImage) -> Gradients {
    separable_gradient(img, [1.0, 2.0, 1.0], 8.0)
}

/// The 3x3 Scharr gradients (smoothing `[3 10 3]`, difference `[-1 0 1]`) divided by 32; more
/// rotation-invariant than Sobel, used for Lucas–Kanade.
#[must_use]
pub fn scharr(img: &GrayImage) -> Gradients {
    separable_gradient(img, [3.0, 10.0, 3.0], 32.0)
}

fn separable_gradient(img: &GrayImage, smooth: [f32; 3], norm: f32) -> Gradients {
    let (w, h) = (img.width(), img.height());
    let mut gx = vec![0.0f32; w * h];
    let mut gy = vec![0.0f32; w * h];
    if w > 0 && h > 0 {
        gx.par_chunks_mut(w)
            .zip(gy.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (ox, oy))| gradient_row(img, y, smooth, norm, ox, oy));
    }
    Gradients {
        gx: GrayImage::from_vec(w, h, gx).unwrap_or_else(|| GrayImage::new(w, h, 0.0)),
        gy: GrayImage::from_vec(w, h, gy).unwrap_or_else(|| GrayImage::new(w, h, 0.0)),
    }
}

/// The Sobel gradients of row `y` into `ox`, `oy` (length `width`), borders replicated.
pub(crate) fn sobel_row(img: &GrayImage, y: usize, ox: &mut [f32], oy: &mut [f32]) {
    gradient_row(img, y, [1.0, 2.0, 1.0], 8.0, ox, oy);
}

/// One row of a 3x3 separable gradient (smoothing `smooth`, difference `[-1 0 1]`, / `norm`).
fn gradient_row(
    img: &GrayImage,
    y: usize,
    smooth: [f32; 3],
    norm: f32,
    ox: &mut [f32],
    oy: &mut [f32],
) {
    let (w, h) = (img.width(), img.height());
    if w == 0 || h == 0 {
        return;
    }
    let data = img.data();
    let row = |y: usize| &data[y * w..(y + 1) * w];
    let (a, b, c) = (row(y.saturating_sub(1)), row(y), row((y + 1).min(h - 1)));
    let inv = 1.0 / norm;
    let put = |x: usize, l: usize, r: usize| {
        let dx = smooth[0] * (a[r] - a[l]) + smooth[1] * (b[r] - b[l]) + smooth[2] * (c[r] - c[l]);
        let dy = smooth[0] * (c[l] - a[l]) + smooth[1] * (c[x] - a[x]) + smooth[2] * (c[r] - a[r]);
        (dx * inv, dy * inv)
    };
    (ox[0], oy[0]) = put(0, 0, 1.min(w - 1));
    if w > 2 {
        gradient_interior(a, b, c, smooth, inv, &mut ox[1..w - 1], &mut oy[1..w - 1]);
    }
    if w > 1 {
        (ox[w - 1], oy[w - 1]) = put(w - 1, w - 2, w - 1);
    }
}

visnav_core::simd_kernel! {
    /// The interior pixels `1..w−1` of [`gradient_row`] (the same operations in the same order,
    /// on equal-length slices the compiler vectorises): rows `a`, `b`, `c` above, at and below.
    fn gradient_interior(
        a: &[f32],
        b: &[f32],
        c: &[f32],
        smooth: [f32; 3],
        inv: f32,
        ox: &mut [f32],
        oy: &mut [f32],
    ) {
        let n = ox.len().min(oy.len()).min(a.len().saturating_sub(2));
        let (a0, a1, a2) = (&a[..n], &a[1..=n], &a[2..n + 2]);
        let (b0, b2) = (&b[..n], &b[2..n + 2]);
        let (c0, c1, c2) = (&c[..n], &c[1..=n], &c[2..n + 2]);
        let (ox, oy) = (&mut ox[..n], &mut oy[..n]);
        for i in 0..n {
            let dx = smooth[0] * (a2[i] - a0[i])
                + smooth[1] * (b2[i] - b0[i])
                + smooth[2] * (c2[i] - c0[i]);
            let dy = smooth[0] * (c0[i] - a0[i])
                + smooth[1] * (c1[i] - a1[i])
                + smooth[2] * (c2[i] - a2[i]);
            ox[i] = dx * inv;
            oy[i] = dy * inv;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_equal_the_per_pixel_formula_bit_for_bit() {
        let img = GrayImage::from_fn(37, 5, |x, y| ((x * 7919 + y * 104_729) % 251) as f32 * 0.37);
        let (w, h) = (img.width(), img.height());
        let g = scharr(&img);
        let at = |x: usize, y: usize| img.get(x.min(w - 1), y.min(h - 1));
        for y in 0..h {
            for x in 0..w {
                let (l, r, u, d) = (x.saturating_sub(1), x + 1, y.saturating_sub(1), y + 1);
                let dx = 3.0 * (at(r, u) - at(l, u))
                    + 10.0 * (at(r, y) - at(l, y))
                    + 3.0 * (at(r, d) - at(l, d));
                let dy = 3.0 * (at(l, d) - at(l, u))
                    + 10.0 * (at(x, d) - at(x, u))
                    + 3.0 * (at(r, d) - at(r, u));
                let inv = 1.0f32 / 32.0;
                assert_eq!(
                    g.gx.get(x, y).to_bits(),
                    (dx * inv).to_bits(),
                    "gx at {x},{y}"
                );
                assert_eq!(
                    g.gy.get(x, y).to_bits(),
                    (dy * inv).to_bits(),
                    "gy at {x},{y}"
                );
            }
        }
    }

    #[test]
    fn ramp_gives_its_slope() {
        let img = GrayImage::from_fn(20, 10, |x, y| 2.0 * x as f32 - 0.5 * y as f32);
        for g in [sobel(&img), scharr(&img)] {
            assert!((g.gx.get(5, 5) - 2.0).abs() < 1e-5);
            assert!((g.gy.get(5, 5) + 0.5).abs() < 1e-5);
        }
    }
}
