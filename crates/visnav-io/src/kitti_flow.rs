//! KITTI optical-flow ground truth (`flow_noc/`, `flow_occ/`): a 16-bit RGB PNG per pair with
//! `u = (R - 2^15) / 64`, `v = (G - 2^15) / 64` pixels and `B > 0` where the flow is known; and
//! KITTI stereo ground truth (`disp_noc_0/`, `disp_occ_0/`): a 16-bit grey PNG with
//! `d = value / 256` pixels and `0` where the disparity is unknown.

use std::path::Path;

use crate::error::{IoError, Result};
use crate::flo::FlowField;

/// Reads a KITTI flow PNG: the flow and the mask of known pixels (`B > 0`). Unknown pixels get a
/// zero flow.
///
/// # Errors
/// A missing or undecodable file, or a PNG that is not 16-bit RGB(A): an 8-bit file scaled up
/// would give flows off by up to 512 px, silently.
pub fn read_kitti_flow_png(path: &Path) -> Result<(FlowField, Vec<bool>)> {
    if std::fs::metadata(path)
        .map_err(|e| IoError::io(path, e))?
        .is_dir()
    {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: "is a directory, expected a KITTI flow PNG".into(),
        });
    }
    let img = image::open(path).map_err(|e| IoError::Image {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let rgb = match img {
        image::DynamicImage::ImageRgb16(i) => i,
        image::DynamicImage::ImageRgba16(i) => image::DynamicImage::ImageRgba16(i).into_rgb16(),
        other => {
            return Err(IoError::Format {
                path: path.to_path_buf(),
                message: format!(
                    "is a {:?} image; KITTI flow ground truth is a 16-bit RGB PNG (u, v, valid)",
                    other.color()
                ),
            });
        }
    };
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let mut flow = FlowField::zeros(w, h);
    let mut known = vec![false; w * h];
    for (x, y, px) in rgb.enumerate_pixels() {
        let [r, g, b] = px.0;
        let (x, y) = (x as usize, y as usize);
        if b > 0 {
            let u = (f32::from(r) - 32768.0) / 64.0;
            let v = (f32::from(g) - 32768.0) / 64.0;
            flow.set(x, y, u, v);
            known[y * w + x] = true;
        }
    }
    Ok((flow, known))
}

/// A disparity map: `width x height` disparities in pixels, row-major, `None` where unknown.
#[derive(Debug, Clone, PartialEq)]
pub struct DisparityMap {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// `u_left − u_right` of each pixel of the left image, pixels; `None` where unknown.
    pub disparity_px: Vec<Option<f32>>,
}

impl DisparityMap {
    /// The disparity at a pixel, `None` outside the map or where unknown.
    #[must_use]
    pub fn get(&self, x: usize, y: usize) -> Option<f32> {
        (x < self.width && y < self.height)
            .then(|| self.disparity_px[y * self.width + x])
            .flatten()
    }
}

/// Reads a KITTI disparity PNG (`disp_noc_0/`, `disp_occ_0/`): 16-bit grey, `d = value / 256`,
/// `0` unknown.
///
/// # Errors
/// A missing or undecodable file, or a PNG that is not 16-bit grey: an 8-bit file would give
/// disparities 256 times too small, silently.
pub fn read_kitti_disparity_png(path: &Path) -> Result<DisparityMap> {
    let img = image::open(path).map_err(|e| IoError::Image {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let image::DynamicImage::ImageLuma16(grey) = img else {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!(
                "is a {:?} image; KITTI disparity ground truth is a 16-bit grey PNG",
                img.color()
            ),
        });
    };
    Ok(DisparityMap {
        width: grey.width() as usize,
        height: grey.height() as usize,
        disparity_px: grey
            .pixels()
            .map(|p| (p.0[0] > 0).then(|| f32::from(p.0[0]) / 256.0))
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eight_bit_kitti_flow_is_an_error_not_scaled_to_16_bit() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("000000_10.png");
        let img = image::RgbImage::from_pixel(4, 2, image::Rgb([128, 128, 1]));
        img.save(&p).unwrap();
        let e = read_kitti_flow_png(&p).unwrap_err().to_string();
        assert!(e.contains("000000_10.png") && e.contains("16-bit"), "{e}");
        // 16 bit: u = 1.5, v = -2 where known
        let mut img16 = image::ImageBuffer::<image::Rgb<u16>, Vec<u16>>::new(4, 2);
        img16.put_pixel(1, 1, image::Rgb([32768 + 96, 32768 - 128, 1]));
        image::DynamicImage::ImageRgb16(img16).save(&p).unwrap();
        let (f, known) = read_kitti_flow_png(&p).unwrap();
        assert_eq!(known.iter().filter(|&&k| k).count(), 1);
        assert!(known[4 + 1]);
        assert_eq!(f.get(1, 1), (1.5, -2.0));
    }

    #[test]
    fn kitti_disparity_is_value_over_256_and_8_bit_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("000000_10.png");
        image::GrayImage::from_pixel(3, 2, image::Luma([7]))
            .save(&p)
            .unwrap();
        let e = read_kitti_disparity_png(&p).unwrap_err().to_string();
        assert!(e.contains("000000_10.png") && e.contains("16-bit"), "{e}");
        let mut img16 = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::new(3, 2);
        img16.put_pixel(2, 1, image::Luma([256 * 20 + 64]));
        image::DynamicImage::ImageLuma16(img16).save(&p).unwrap();
        let d = read_kitti_disparity_png(&p).unwrap();
        assert_eq!((d.width, d.height), (3, 2));
        assert_eq!(d.get(2, 1), Some(20.25));
        assert_eq!(d.get(0, 0), None);
        assert_eq!(d.get(3, 0), None);
    }
}
