//! Image files to and from [`GrayImage`].

use std::path::Path;

use visnav_core::GrayImage;

use crate::error::{IoError, Result};

/// Reads an image file as grayscale intensities in 0..=255 (16-bit images are scaled by 1/257,
/// colour images converted with the Rec. 601 luma weights).
///
/// # Errors
/// [`IoError::NotFound`] for a missing file, [`IoError::Image`] for an undecodable one.
pub fn load_gray(path: &Path) -> Result<GrayImage> {
    if !path.exists() {
        return Err(IoError::NotFound {
            path: path.to_path_buf(),
            what: "image file".into(),
        });
    }
    let img = image::open(path).map_err(|e| IoError::Image {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let data: Vec<f32> = match img {
        image::DynamicImage::ImageLuma8(g) => g.into_raw().into_iter().map(f32::from).collect(),
        image::DynamicImage::ImageLuma16(g) => g
            .into_raw()
            .into_iter()
            .map(|v| f32::from(v) / 257.0)
            .collect(),
        other => other
            .to_luma32f()
            .into_raw()
            .into_iter()
            .map(|v| v * 255.0)
            .collect(),
    };
    GrayImage::from_vec(w, h, data).ok_or_else(|| IoError::Image {
        path: path.to_path_buf(),
        message: "buffer size mismatch".into(),
    })
}

/// Writes a grayscale image as an 8-bit PNG (values rounded and clamped to 0..=255).
///
/// # Errors
/// [`IoError::Io`] when the file cannot be written.
pub fn save_gray_png(img: &GrayImage, path: &Path) -> Result<()> {
    let buf: Vec<u8> = img
        .data()
        .iter()
        .map(|v| v.round().clamp(0.0, 255.0) as u8)
        .collect();
    let out = image::GrayImage::from_raw(img.width() as u32, img.height() as u32, buf).ok_or_else(
        || IoError::Format {
            path: path.to_path_buf(),
            message: "buffer size mismatch".into(),
        },
    )?;
    out.save(path).map_err(|e| IoError::Image {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trip_and_errors() {
        let dir = tempfile::tempdir().unwrap();
        let img = GrayImage::from_fn(13, 7, |x, y| ((x * 17 + y * 31) % 256) as f32);
        let p = dir.path().join("a.png");
        save_gray_png(&img, &p).unwrap();
        assert_eq!(load_gray(&p).unwrap(), img);
        assert!(matches!(
            load_gray(&dir.path().join("missing.png")),
            Err(IoError::NotFound { .. })
        ));
        let bad = dir.path().join("bad.png");
        std::fs::write(&bad, b"not a png").unwrap();
        let err = load_gray(&bad).unwrap_err();
        assert!(matches!(err, IoError::Image { .. }));
        assert!(err.to_string().contains("bad.png"));
    }
}
