//! A planar grayscale image of `f32` intensities (0..=255 for 8-bit sources).
//!
//! Pixel `(x, y)` is column `x`, row `y`; its value is stored at `data[y * width + x]`. Sampling
//! positions are continuous with pixel centres at integer coordinates.

use crate::bilinear::Bilinear;

/// A row-major grayscale image.
#[derive(Debug, Clone, PartialEq)]
pub struct GrayImage {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

impl GrayImage {
    /// A `width` x `height` image filled with `value`.
    #[must_use]
    pub fn new(width: usize, height: usize, value: f32) -> Self {
        Self {
            width,
            height,
            data: vec![value; width * height],
        }
    }

    /// Wraps a row-major buffer; `None` if its length is not `width * height`.
    #[must_use]
    pub fn from_vec(width: usize, height: usize, data: Vec<f32>) -> Option<Self> {
        (data.len() == width * height).then_some(Self {
            width,
            height,
            data,
        })
    }

    /// An image whose pixel `(x, y)` is `f(x, y)`.
    pub fn from_fn(width: usize, height: usize, mut f: impl FnMut(usize, usize) -> f32) -> Self {
        let mut data = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                data.push(f(x, y));
            }
        }
        Self {
            width,
            height,
            data,
        }
    }

    /// Width in pixels.
    #[must_use]
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    #[must_use]
    pub fn height(&self) -> usize {
        self.height
    }

    /// The row-major pixel buffer.
    #[must_use]
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// The mutable row-major pixel buffer.
    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }

    /// Consumes the image, returning its buffer.
    #[must_use]
    pub fn into_vec(self) -> Vec<f32> {
        self.data
    }

    /// Row `y` as a slice.
    #[must_use]
    pub fn row(&self, y: usize) -> &[f32] {
        &self.data[y * self.width..(y + 1) * self.width]
    }

    /// Pixel value at integer coordinates (panics out of bounds, like slice indexing).
    #[must_use]
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }

    /// Sets a pixel value at integer coordinates.
    #[inline]
    pub fn set(&mut self, x: usize, y: usize, value: f32) {
        self.data[y * self.width + x] = value;
    }

    /// Pixel value with coordinates clamped to the border.
    #[must_use]
    #[inline]
    pub fn get_clamped(&self, x: isize, y: isize) -> f32 {
        let xc = x.clamp(0, self.width as isize - 1) as usize;
        let yc = y.clamp(0, self.height as isize - 1) as usize;
        self.data[yc * self.width + xc]
    }

    /// Bilinear interpolation at `(x, y)`; `None` when the 2x2 neighbourhood leaves the image.
    /// Kept apart from [`crate::bilinear`] for its border semantics (no clamping: a sample
    /// outside the image is `None`, which the renderer and the tests rely on).
    #[must_use]
    #[inline]
    pub fn bilinear(&self, x: f64, y: f64) -> Option<f32> {
        if !(x >= 0.0 && y >= 0.0) {
            return None;
        }
        let x0 = x.floor() as usize;
        let y0 = y.floor() as usize;
        if x0 + 1 >= self.width || y0 + 1 >= self.height {
            // allow sampling exactly on the last row/column
            if x0 < self.width && y0 < self.height && x == x0 as f64 && y == y0 as f64 {
                return Some(self.get(x0, y0));
            }
            return None;
        }
        let fx = (x - x0 as f64) as f32;
        let fy = (y - y0 as f64) as f32;
        let i = y0 * self.width + x0;
        let a = self.data[i];
        let b = self.data[i + 1];
        let c = self.data[i + self.width];
        let d = self.data[i + self.width + 1];
        Some((a * (1.0 - fx) + b * fx) * (1.0 - fy) + (c * (1.0 - fx) + d * fx) * fy)
    }

    /// Bilinear interpolation with coordinates clamped to the image (never fails):
    /// [`crate::bilinear::Bilinear::clamped_f64`].
    #[must_use]
    #[inline]
    pub fn bilinear_clamped(&self, x: f64, y: f64) -> f32 {
        Bilinear::clamped_f64(x, y, self.width, self.height).sample(&self.data)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_matches_plane() {
        let img = GrayImage::from_fn(8, 6, |x, y| 2.0 * x as f32 + 3.0 * y as f32 + 1.0);
        let v = img.bilinear(2.25, 3.5).unwrap();
        assert!((v - (2.0 * 2.25 + 3.0 * 3.5 + 1.0)).abs() < 1e-5);
        assert!(img.bilinear(7.5, 1.0).is_none());
        assert!(img.bilinear(-0.1, 1.0).is_none());
        assert_eq!(img.bilinear(7.0, 5.0), Some(img.get(7, 5)));
        assert!((img.bilinear_clamped(100.0, -3.0) - img.get(7, 0)).abs() < 1e-5);
    }
}
