//! Structural similarity (SSIM) of Wang, Bovik, Sheikh and Simoncelli, "Image quality assessment:
//! from error visibility to structural similarity", IEEE TIP 2004.
//!
//! The SSIM map (eq. 13 of Wang et al.) is
//! `SSIM = (2 μa μb + C1)(2 σab + C2) / ((μa² + μb² + C1)(σa² + σb² + C2))` with `C1 = (K1 L)²`,
//! `C2 = (K2 L)²`, where the local means, population variances and covariance come from an
//! 11x11 circular-symmetric Gaussian window (σ = 1.5 px, weights normalised to sum 1). The score is
//! the mean of the map over the *valid* region, where the whole window lies inside the image (the
//! image minus a 5-pixel border), exactly as scikit-image crops. All arithmetic is `f64`.
//!
//! The mono pipeline's loop closure (§5 of Ng, Li and Kim 2021) accepts candidates with SSIM ≥ 0.38
//! computed with these settings on thumbnails.

use crate::ImageError;

/// Parameters of SSIM. [`Default`] gives Wang et al. 2004's settings.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SsimConfig {
    /// Half-size of the Gaussian window in pixels (window = `2 r + 1` square); Wang: 5 (11x11).
    pub window_radius: usize,
    /// Standard deviation of the Gaussian window in pixels; Wang: 1.5.
    pub sigma_px: f64,
    /// Luminance stabiliser constant `K1`; Wang: 0.01.
    pub k1: f64,
    /// Contrast stabiliser constant `K2`; Wang: 0.03.
    pub k2: f64,
    /// Dynamic range `L` of the intensities; 255 for 8-bit images.
    pub data_range: f64,
}

impl Default for SsimConfig {
    fn default() -> Self {
        Self {
            window_radius: 5,
            sigma_px: 1.5,
            k1: 0.01,
            k2: 0.03,
            data_range: 255.0,
        }
    }
}

impl SsimConfig {
    /// Checks the parameters.
    ///
    /// # Errors
    /// [`ImageError::InvalidConfig`] when `sigma_px` or `data_range` is not positive and finite,
    /// or `k1`/`k2` is negative.
    pub fn validate(&self) -> Result<(), ImageError> {
        let invalid = |field, message| Err(ImageError::InvalidConfig { field, message });
        if !(self.sigma_px.is_finite() && self.sigma_px > 0.0) {
            return invalid("sigma_px", format!("must be > 0, got {}", self.sigma_px));
        }
        if !(self.data_range.is_finite() && self.data_range > 0.0) {
            return invalid(
                "data_range",
                format!("must be > 0, got {}", self.data_range),
            );
        }
        if self.k1.is_nan() || self.k1 < 0.0 {
            return invalid("k1", format!("must be >= 0, got {}", self.k1));
        }
        if self.k2.is_nan() || self.k2 < 0.0 {
            return invalid("k2", format!("must be >= 0, got {}", self.k2));
        }
        Ok(())
    }
}

/// The SSIM map over the valid region (row-major) and its mean.
#[derive(Debug, Clone, PartialEq)]
pub struct SsimMap {
    /// Width of the valid region: image width minus `2 r`.
    pub width: usize,
    /// Height of the valid region: image height minus `2 r`.
    pub height: usize,
    /// SSIM of the window centred on pixel `(x + r, y + r)` of the images, at `y * width + x`.
    pub values: Vec<f64>,
    /// Mean of `values`: the SSIM score.
    pub mean: f64,
}

/// SSIM score of two images with Wang et al. 2004's settings.
///
/// `None` when the sizes differ or an image is smaller than the 11x11 window.
#[must_use]
pub fn ssim(a: &visnav_core::GrayImage, b: &visnav_core::GrayImage) -> Option<f64> {
    ssim_map(a, b, &SsimConfig::default()).map(|m| m.mean)
}

/// The normalised 1-D Gaussian of `2 r + 1` taps (`exp(-x² / 2σ²)`, summing to 1).
fn gaussian_taps(radius: usize, sigma: f64) -> Vec<f64> {
    let r = radius as f64;
    let taps: Vec<f64> = (0..=2 * radius)
        .map(|i| {
            let x = i as f64 - r;
            (-0.5 * x * x / (sigma * sigma)).exp()
        })
        .collect();
    let sum: f64 = taps.iter().sum();
    taps.into_iter().map(|t| t / sum).collect()
}

/// The SSIM map (eq. 13 of Wang et al. 2004) over the valid region and its mean.
///
/// `None` when the sizes differ, an image is smaller than the window, or `config` is invalid.
#[must_use]
pub fn ssim_map(
    a: &visnav_core::GrayImage,
    b: &visnav_core::GrayImage,
    config: &SsimConfig,
) -> Option<SsimMap> {
    if config.validate().is_err() {
        return None;
    }
    let (width, height) = (a.width(), a.height());
    let win = 2 * config.window_radius + 1;
    if b.width() != width || b.height() != height || width < win || height < win {
        return None;
    }
    let taps = gaussian_taps(config.window_radius, config.sigma_px);
    let (out_w, out_h) = (width + 1 - win, height + 1 - win);

    // Horizontal pass over every row for the valid columns: the five moments a, b, a², b², ab.
    let mut horiz = vec![[0.0_f64; 5]; out_w * height];
    for y in 0..height {
        let (row_a, row_b) = (a.row(y), b.row(y));
        for x in 0..out_w {
            let mut acc = [0.0_f64; 5];
            for (k, &w) in taps.iter().enumerate() {
                let pa = f64::from(row_a[x + k]);
                let pb = f64::from(row_b[x + k]);
                acc[0] += w * pa;
                acc[1] += w * pb;
                acc[2] += w * pa * pa;
                acc[3] += w * pb * pb;
                acc[4] += w * pa * pb;
            }
            horiz[y * out_w + x] = acc;
        }
    }

    let c1 = (config.k1 * config.data_range).powi(2);
    let c2 = (config.k2 * config.data_range).powi(2);
    let mut values = Vec::with_capacity(out_w * out_h);
    for y in 0..out_h {
        for x in 0..out_w {
            let mut m = [0.0_f64; 5];
            for (k, &w) in taps.iter().enumerate() {
                let h = &horiz[(y + k) * out_w + x];
                for (mi, hi) in m.iter_mut().zip(h) {
                    *mi += w * hi;
                }
            }
            let [mu_a, mu_b, e_aa, e_bb, e_ab] = m;
            let var_a = e_aa - mu_a * mu_a;
            let var_b = e_bb - mu_b * mu_b;
            let cov_ab = e_ab - mu_a * mu_b;
            let num = (2.0 * mu_a * mu_b + c1) * (2.0 * cov_ab + c2);
            let den = (mu_a * mu_a + mu_b * mu_b + c1) * (var_a + var_b + c2);
            values.push(num / den);
        }
    }
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    Some(SsimMap {
        width: out_w,
        height: out_h,
        values,
        mean,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use visnav_core::GrayImage;

    fn img_a(x: usize, y: usize) -> f64 {
        ((x * 7 + y * 13 + (x * y) % 17) % 256) as f64
    }
    fn img_b(x: usize, y: usize) -> f64 {
        (img_a(x, y) + ((x * 3 + y * 5) % 21) as f64 - 10.0).clamp(0.0, 255.0)
    }
    fn img_smooth(x: usize, y: usize, dx: f64) -> f64 {
        (127.5 + 100.0 * ((x as f64 + dx) / 9.0).sin() * (y as f64 / 7.0).cos()).floor()
    }
    #[allow(clippy::cast_possible_truncation)]
    fn build(w: usize, h: usize, f: impl Fn(usize, usize) -> f64) -> GrayImage {
        GrayImage::from_fn(w, h, |x, y| f(x, y) as f32)
    }

    /// Rebuilds the closed-form images of `ssim_vectors.json` and checks score, valid shape and the
    /// top-left map value to 1e-9 (scikit-image 0.26 reference).
    #[test]
    fn matches_scikit_image_vectors() {
        let Some(dir) = visnav_core::testdata::shared_data("ssim/ssim_vectors.json") else {
            return;
        };
        let text = std::fs::read_to_string(dir).unwrap();
        let json: serde_json::Value = serde_json::from_str(&text).unwrap();
        let cases = json["cases"].as_array().unwrap();
        assert_eq!(cases.len(), 4);
        for case in cases {
            let name = case["name"].as_str().unwrap();
            let w = usize::try_from(case["width"].as_u64().unwrap()).unwrap();
            let h = usize::try_from(case["height"].as_u64().unwrap()).unwrap();
            let (a, b) = match name {
                "a_vs_b_64x48" => (build(w, h, img_a), build(w, h, img_b)),
                "a_vs_a_64x48" => (build(w, h, img_a), build(w, h, img_a)),
                "smooth_vs_shift_96x80" => (
                    build(w, h, |x, y| img_smooth(x, y, 0.0)),
                    build(w, h, |x, y| img_smooth(x, y, 1.5)),
                ),
                "a_vs_smooth_32x32" => (
                    build(w, h, img_a),
                    build(w, h, |x, y| img_smooth(x, y, 0.0)),
                ),
                other => panic!("unknown case {other}"),
            };
            let map = ssim_map(&a, &b, &SsimConfig::default()).unwrap();
            let expected = case["ssim_wang_gauss11_sigma1_5_pop"].as_f64().unwrap();
            let top_left = case["ssim_map_top_left"].as_f64().unwrap();
            let shape = case["ssim_map_valid_shape"].as_array().unwrap();
            assert_eq!(map.height as u64, shape[0].as_u64().unwrap(), "{name}");
            assert_eq!(map.width as u64, shape[1].as_u64().unwrap(), "{name}");
            assert!(
                (map.mean - expected).abs() < 1e-9,
                "{name}: {} vs {expected}",
                map.mean
            );
            assert!(
                (map.values[0] - top_left).abs() < 1e-9,
                "{name}: top-left {}",
                map.values[0]
            );
            assert!((ssim(&a, &b).unwrap() - expected).abs() < 1e-9);
        }
    }

    #[test]
    fn identical_images_score_one_and_is_symmetric() {
        let a = build(20, 16, img_a);
        let b = build(20, 16, img_b);
        assert!((ssim(&a, &a).unwrap() - 1.0).abs() < 1e-12);
        let ab = ssim(&a, &b).unwrap();
        let ba = ssim(&b, &a).unwrap();
        assert!((ab - ba).abs() < 1e-12);
        assert!(ab < 1.0);
    }

    #[test]
    fn rejects_bad_sizes() {
        let a = build(20, 16, img_a);
        assert!(ssim(&a, &build(20, 15, img_a)).is_none());
        assert!(ssim(&build(10, 16, img_a), &build(10, 16, img_a)).is_none());
        let bad = SsimConfig {
            sigma_px: -1.0,
            ..SsimConfig::default()
        };
        assert!(ssim_map(&a, &a, &bad).is_none());
    }

    #[test]
    fn gaussian_taps_sum_to_one_and_are_symmetric() {
        let t = gaussian_taps(5, 1.5);
        assert_eq!(t.len(), 11);
        assert!((t.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        for k in 0..5 {
            assert!((t[k] - t[10 - k]).abs() < 1e-18);
        }
    }
}
