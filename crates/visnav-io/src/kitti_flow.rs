//! KITTI optical-flow ground truth (`flow_noc/`, `flow_occ/`): a 16-bit RGB PNG per pair with
//! `u = (R - 2^15) / 64`, `v = (G - 2^15) / 64` pixels and `B > 0` where the flow is known.

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
}
