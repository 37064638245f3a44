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
}

impl Pyramid {
    /// Builds up to `num_levels` levels (at least one); stops early when a level would be smaller
    /// than 8 pixels on a side.
    #[must_use]
    pub fn build(image: &GrayImage, num_levels: usize) -> Self {
        let mut images = vec![image.clone()];
        while images.len() < num_levels.max(1) {
            let last = &images[images.len() - 1];
            if last.width() < 16 || last.height() < 16 {
                break;
            }
            let next = pyr_down(last);
            images.push(next);
        }
        let levels = images
            .into_iter()
            .map(|image| PyramidLevel { image })
            .collect();
        Self { levels }
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
    let (w, h) = (img.width(), img.height());
    let (w2, h2) = (w.div_ceil(2), h.div_ceil(2));
    if w == 0 || h == 0 {
        return GrayImage::new(w2, h2, 0.0);
    }
    // horizontal pass at even columns, all rows
    let mut tmp = vec![0.0f32; w2 * h];
    tmp.par_chunks_mut(w2).enumerate().for_each(|(y, out)| {
        let row = img.row(y);
        let at = |x: isize| row[x.clamp(0, w as isize - 1) as usize];
        for (x2, o) in out.iter_mut().enumerate() {
            let x = (2 * x2) as isize;
            *o = (at(x - 2) + 4.0 * at(x - 1) + 6.0 * at(x) + 4.0 * at(x + 1) + at(x + 2)) / 16.0;
        }
    });
    let mut out = vec![0.0f32; w2 * h2];
    out.par_chunks_mut(w2).enumerate().for_each(|(y2, o)| {
        let y = (2 * y2) as isize;
        let r = |dy: isize| {
            let yy = (y + dy).clamp(0, h as isize - 1) as usize;
            &tmp[yy * w2..(yy + 1) * w2]
        };
        let (a, b, c, d, e) = (r(-2), r(-1), r(0), r(1), r(2));
        for x in 0..w2 {
            o[x] = (a[x] + 4.0 * b[x] + 6.0 * c[x] + 4.0 * d[x] + e[x]) / 16.0;
        }
    });
    GrayImage::from_vec(w2, h2, out).unwrap_or_else(|| GrayImage::new(w2, h2, 0.0))
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
    fn linear_ramp_maps_coordinates_by_half() {
        // I(x) = 3x at level 0 => I1(x1) = 3 * 2 x1 away from the border
        let img = GrayImage::from_fn(64, 32, |x, _| 3.0 * x as f32);
        let l1 = pyr_down(&img);
        for x1 in 2..28 {
            assert!((l1.get(x1, 5) - 6.0 * x1 as f32).abs() < 1e-3);
        }
    }
}
