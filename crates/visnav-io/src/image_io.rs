//! Image files to and from [`GrayImage`]: PNG (8 or 16 bit) and JPEG, gray or colour.

use std::path::{Path, PathBuf};

use visnav_core::GrayImage;

use crate::error::{IoError, Result};

/// Extensions of the image files that frame folders are listed by (case-insensitive).
pub const IMAGE_EXTENSIONS: [&str; 3] = ["png", "jpg", "jpeg"];

/// Whether `path` has one of [`IMAGE_EXTENSIONS`].
#[must_use]
pub fn is_image_file(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.iter().any(|x| e.eq_ignore_ascii_case(x)))
}

/// The PNG and JPEG files of `dir` in frame order (frames of a folder sequence): by the number in
/// their names ([`crate::frame_order`]). macOS metadata files (`._*` resource forks, which carry
/// the image's extension, and `.DS_Store`) are skipped with a note ([`list_frames`]).
///
/// # Errors
/// [`IoError::NotFound`] / [`IoError::Io`] when the directory cannot be read;
/// [`IoError::Format`] when the order of the names is ambiguous.
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>> {
    list_frames(dir, is_image_file)
}

/// Whether `name` is a file macOS leaves beside the real ones: an AppleDouble resource fork
/// (`._000001.png`, written on FAT/exFAT/SMB volumes and by `tar`/`zip`) or `.DS_Store`.
#[must_use]
pub fn is_macos_metadata(name: &std::ffi::OsStr) -> bool {
    let name = name.as_encoded_bytes();
    name.starts_with(b"._") || name == b".DS_Store"
}

/// The files of `dir` that `is_frame` keeps, in frame order ([`crate::frame_order`]), without
/// macOS metadata files ([`is_macos_metadata`]; one note a folder says how many were skipped).
///
/// # Errors
/// [`IoError::NotFound`] / [`IoError::Io`] when the directory cannot be read;
/// [`IoError::Format`] when the order of the names is ambiguous.
pub fn list_frames(dir: &Path, is_frame: impl Fn(&Path) -> bool) -> Result<Vec<PathBuf>> {
    let rd = std::fs::read_dir(dir).map_err(|e| IoError::io(dir, e))?;
    let mut out = Vec::new();
    let mut skipped = 0usize;
    for entry in rd {
        let entry = entry.map_err(|e| IoError::io(dir, e))?;
        if is_macos_metadata(&entry.file_name()) {
            skipped += 1;
            continue;
        }
        let p = entry.path();
        if is_frame(&p) {
            out.push(p);
        }
    }
    if skipped > 0 {
        log::info!(
            "{}: skipped {skipped} macOS metadata file(s) (._* resource forks, .DS_Store)",
            dir.display()
        );
    }
    crate::frame_order::frame_order(dir, out)
}

/// Reads an image file (PNG or JPEG, by content) as grayscale intensities in 0..=255 (16-bit images are scaled by 1/257,
/// colour images converted with the Rec. 601 luma weights).
///
/// # Errors
/// [`IoError::NotFound`] for a missing file, [`IoError::Image`] for an undecodable one,
/// including a truncated one ([`decode_gray`]).
pub fn load_gray(path: &Path) -> Result<GrayImage> {
    // a link that does not resolve is read, so that its error names the loop
    if !crate::text::entry_exists(path) {
        return Err(IoError::NotFound {
            path: path.to_path_buf(),
            what: "image file".into(),
        });
    }
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    decode_gray(&bytes).map_err(|message| IoError::Image {
        path: path.to_path_buf(),
        message,
    })
}

/// Decodes a PNG or JPEG (by content) as [`load_gray`] does. A JPEG whose markers do not run to
/// its end-of-image marker is refused: the `image` crate's decoder fills the missing part of a
/// truncated JPEG with grey and reports no error (issue 53). PNG's decoder refuses truncated
/// data and bad checksums itself.
///
/// # Errors
/// The decoder's message, or why the JPEG is truncated.
pub fn decode_gray(bytes: &[u8]) -> std::result::Result<GrayImage, String> {
    if let Some(why) = jpeg_truncation(bytes) {
        return Err(why);
    }
    image::load_from_memory(bytes)
        .map(gray_from_dynamic)
        .map_err(|e| e.to_string())
}

/// Why the JPEG `bytes` are truncated: `None` when its segments run to the end-of-image marker
/// FFD9 (anything after it is ignored) or when `bytes` is not a JPEG. Segment lengths are
/// followed; the entropy-coded data after each start-of-scan runs to the next marker (`FF`
/// followed by neither `00`, a restart marker nor fill).
fn jpeg_truncation(bytes: &[u8]) -> Option<String> {
    if !bytes.starts_with(&[0xFF, 0xD8]) {
        return None;
    }
    let cut = |what: String| {
        Some(format!(
            "truncated JPEG: {what}; no end-of-image marker (FFD9) in its {} bytes",
            bytes.len()
        ))
    };
    let mut i = 2;
    loop {
        // the next marker: stray bytes before it are skipped (as libjpeg does), then fill bytes
        while bytes.get(i).is_some_and(|&b| b != 0xFF) {
            i += 1;
        }
        while bytes.get(i) == Some(&0xFF) {
            i += 1;
        }
        let Some(&marker) = bytes.get(i) else {
            return cut("the data ends between two segments".into());
        };
        let at = i - 1;
        i += 1;
        match marker {
            0xD9 => return None,
            0x00 | 0x01 | 0xD0..=0xD8 => {}
            _ => {
                let Some(len) = bytes
                    .get(i..i + 2)
                    .map(|b| usize::from(u16::from_be_bytes([b[0], b[1]])))
                else {
                    return cut(format!(
                        "the segment FF{marker:02X} at byte {at} has no length"
                    ));
                };
                if i + len > bytes.len() {
                    return cut(format!(
                        "the segment FF{marker:02X} at byte {at} ends past the end of the file"
                    ));
                }
                i += len;
                if marker == 0xDA {
                    let Some(end) = entropy_data_end(bytes, i) else {
                        return cut(format!("the scan starting at byte {at} is cut"));
                    };
                    i = end;
                }
            }
        }
    }
}

/// The position of the marker that ends the entropy-coded data starting at `start`; `None`
/// when the data runs to the end of `bytes`.
fn entropy_data_end(bytes: &[u8], start: usize) -> Option<usize> {
    let mut i = start;
    loop {
        let ff = i + bytes.get(i..)?.iter().position(|&b| b == 0xFF)?;
        match bytes.get(ff + 1)? {
            // a stuffed zero or a restart marker: still inside the scan
            0x00 | 0xD0..=0xD7 => i = ff + 2,
            // fill byte before a marker
            0xFF => i = ff + 1,
            _ => return Some(ff),
        }
    }
}

/// `img` when it is `(width, height)` pixels, else [`IoError::SizeMismatch`] naming `path` (a
/// frame of a sequence whose size differs from the first frame's).
///
/// # Errors
/// The size differs.
pub fn check_size(img: GrayImage, path: &Path, (w, h): (usize, usize)) -> Result<GrayImage> {
    if (img.width(), img.height()) == (w, h) {
        Ok(img)
    } else {
        Err(IoError::SizeMismatch {
            path: path.to_path_buf(),
            expected_w: w,
            expected_h: h,
            got_w: img.width(),
            got_h: img.height(),
        })
    }
}

/// Any decoded image as gray intensities 0–255: 8-bit gray as is, 16-bit gray divided by 257,
/// colour through the `image` crate's luma conversion.
#[must_use]
pub fn gray_from_dynamic(img: image::DynamicImage) -> GrayImage {
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
    // the buffer holds w*h values by construction
    GrayImage::from_vec(w, h, data).unwrap_or_else(|| GrayImage::new(w, h, 0.0))
}

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

/// Writes a grayscale image as a baseline JPEG of `quality` 1..=100 (values rounded and clamped
/// to 0..=255).
///
/// # Errors
/// [`IoError::Io`] / [`IoError::Image`] when the file cannot be written or encoded.
pub fn save_gray_jpeg(img: &GrayImage, path: &Path, quality: u8) -> Result<()> {
    let buf: Vec<u8> = img
        .data()
        .iter()
        .map(|v| v.round().clamp(0.0, 255.0) as u8)
        .collect();
    let file = std::fs::File::create(path).map_err(|e| IoError::io(path, e))?;
    let mut writer = std::io::BufWriter::new(file);
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut writer, quality.clamp(1, 100))
        .encode(
            &buf,
            img.width() as u32,
            img.height() as u32,
            image::ExtendedColorType::L8,
        )
        .map_err(|e| IoError::Image {
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

    #[test]
    fn jpeg_round_trip_and_listing() {
        let dir = tempfile::tempdir().unwrap();
        // a smooth image survives quality-95 JPEG within a few grey levels
        let img = GrayImage::from_fn(40, 24, |x, y| 60.0 + 2.0 * x as f32 + 3.0 * y as f32);
        let p = dir.path().join("00001.jpg");
        save_gray_jpeg(&img, &p, 95).unwrap();
        let back = load_gray(&p).unwrap();
        assert_eq!((back.width(), back.height()), (40, 24));
        let worst = img
            .data()
            .iter()
            .zip(back.data())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(worst < 4.0, "{worst}");
        save_gray_png(&img, &dir.path().join("00000.png")).unwrap();
        std::fs::write(dir.path().join("00002.JPEG"), b"not a jpeg").unwrap();
        std::fs::write(dir.path().join("notes.txt"), b"").unwrap();
        let names: Vec<String> = list_images(dir.path())
            .unwrap()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["00000.png", "00001.jpg", "00002.JPEG"]);
        let e = load_gray(&dir.path().join("00002.JPEG"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("00002.JPEG"), "{e}");
    }
}
