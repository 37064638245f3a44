//! The one bilinear sampler of row-major grids (images, flow fields, covariance channels):
//! [`Bilinear`] holds the top-left index and the fractional weights of a sample point clamped to
//! the grid, computed once and applied to any number of grids of the same size and to any
//! [`Sample`] type (`f32`, `[f32; N]`).
//!
//! Pixel centres are at integer coordinates; a point outside the grid takes the value at the
//! nearest border point (clamped coordinates), so sampling never fails. Arithmetic is explicit:
//! the coordinates are clamped in the precision they come in ([`Bilinear::clamped_f64`],
//! [`Bilinear::clamped_f32`]), the weights and the interpolation are `f32`. Two interpolation
//! forms exist because callers were tuned on them and give different last bits:
//! [`Bilinear::sample`] (`(a(1−fx) + b fx)(1−fy) + (c(1−fx) + d fx) fy`) and
//! [`Bilinear::sample_lerp`] (`top + (bottom − top) fy` with `top = a + (b − a) fx`).
//!
//! Not merged here, each with a comment at its place: `GrayImage::bilinear` (no clamping: `None`
//! outside the image), the KLT window kernel in `visnav-image` (one set of weights for a whole
//! window of contiguous rows; its warped template, `sample_grid_mapped`, keeps the kernel's
//! product-weight form per sample) and the renderer's inverse-depth interpolation in `visnav-synth`
//! (per-corner validity).

/// A value that can be interpolated bilinearly in `f32`.
pub trait Sample: Copy {
    /// `(a(1−fx) + b fx)(1−fy) + (c(1−fx) + d fx) fy`, per channel.
    fn weighted(a: Self, b: Self, c: Self, d: Self, fx: f32, fy: f32) -> Self;
}

impl Sample for f32 {
    #[inline(always)]
    fn weighted(a: f32, b: f32, c: f32, d: f32, fx: f32, fy: f32) -> f32 {
        (a * (1.0 - fx) + b * fx) * (1.0 - fy) + (c * (1.0 - fx) + d * fx) * fy
    }
}

impl<const N: usize> Sample for [f32; N] {
    #[inline(always)]
    fn weighted(a: Self, b: Self, c: Self, d: Self, fx: f32, fy: f32) -> Self {
        std::array::from_fn(|k| f32::weighted(a[k], b[k], c[k], d[k], fx, fy))
    }
}

/// Top-left index and weights of one bilinear sample of a `w` x `h` grid (at least 1x1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bilinear {
    /// Index of the top-left neighbour, row-major.
    pub i00: usize,
    /// Index step to the right neighbour (0 on a one-column grid).
    pub dx: usize,
    /// Index step to the neighbour below (0 on a one-row grid).
    pub dy: usize,
    /// Weight of the right column, 0..=1.
    pub fx: f32,
    /// Weight of the lower row, 0..=1.
    pub fy: f32,
}

impl Bilinear {
    /// The sample at `(x, y)` (`f64` coordinates, clamped in `f64`; the fractions are rounded
    /// to `f32`).
    #[must_use]
    #[inline]
    pub fn clamped_f64(x: f64, y: f64, w: usize, h: usize) -> Self {
        let xc = x.clamp(0.0, (w - 1) as f64);
        let yc = y.clamp(0.0, (h - 1) as f64);
        // non-negative after the clamp (NaN becomes 0): truncation is the floor
        let x0 = (xc as usize).min(w.saturating_sub(2));
        let y0 = (yc as usize).min(h.saturating_sub(2));
        Self {
            i00: y0 * w + x0,
            dx: usize::from(w > 1),
            dy: if h > 1 { w } else { 0 },
            fx: (xc - x0 as f64) as f32,
            fy: (yc - y0 as f64) as f32,
        }
    }

    /// The sample at `(x, y)` (`f32` coordinates, clamped in `f32`).
    #[must_use]
    #[inline]
    pub fn clamped_f32(x: f32, y: f32, w: usize, h: usize) -> Self {
        let xc = x.clamp(0.0, (w - 1) as f32);
        let yc = y.clamp(0.0, (h - 1) as f32);
        let x0 = (xc as usize).min(w.saturating_sub(2));
        let y0 = (yc as usize).min(h.saturating_sub(2));
        Self {
            i00: y0 * w + x0,
            dx: usize::from(w > 1),
            dy: if h > 1 { w } else { 0 },
            fx: xc - x0 as f32,
            fy: yc - y0 as f32,
        }
    }

    /// The interpolated value of `data` (the grid this sample was made for), weighted form.
    #[must_use]
    #[inline(always)]
    pub fn sample<T: Sample>(&self, data: &[T]) -> T {
        let i = self.i00;
        T::weighted(
            data[i],
            data[i + self.dx],
            data[i + self.dy],
            data[i + self.dy + self.dx],
            self.fx,
            self.fy,
        )
    }

    /// The interpolated value of `data`, in the two-lerp form `top + (bottom − top) fy`.
    #[must_use]
    #[inline(always)]
    pub fn sample_lerp(&self, data: &[f32]) -> f32 {
        let i = self.i00;
        let (a, b) = (data[i], data[i + self.dx]);
        let (c, d) = (data[i + self.dy], data[i + self.dy + self.dx]);
        let top = a + (b - a) * self.fx;
        let bottom = c + (d - c) * self.fx;
        top + (bottom - top) * self.fy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reproduces_planes_and_clamps_to_the_border() {
        let (w, h) = (5, 4);
        let plane: Vec<f32> = (0..w * h)
            .map(|i| 2.0 * (i % w) as f32 + 3.0 * (i / w) as f32 + 1.0)
            .collect();
        let s = Bilinear::clamped_f64(2.25, 1.5, w, h);
        assert!((s.sample(&plane) - (2.0 * 2.25 + 3.0 * 1.5 + 1.0)).abs() < 1e-5);
        assert!((s.sample_lerp(&plane) - (2.0 * 2.25 + 3.0 * 1.5 + 1.0)).abs() < 1e-5);
        // the last column and row are reachable exactly, beyond them the border value
        assert_eq!(
            Bilinear::clamped_f32(4.0, 3.0, w, h).sample(&plane),
            plane[w * h - 1]
        );
        assert_eq!(
            Bilinear::clamped_f64(99.0, -7.0, w, h).sample(&plane),
            plane[w - 1]
        );
        // two channels at once, one-pixel-wide grids
        let two: Vec<[f32; 2]> = plane.iter().map(|v| [*v, -v]).collect();
        let v = Bilinear::clamped_f32(1.5, 2.0, w, h).sample(&two);
        assert_eq!(v, [plane[2 * w + 1] + 1.0, -(plane[2 * w + 1] + 1.0)]);
        let column = [1.0_f32, 3.0];
        assert_eq!(Bilinear::clamped_f32(7.0, 0.5, 1, 2).sample(&column), 2.0);
    }
}
