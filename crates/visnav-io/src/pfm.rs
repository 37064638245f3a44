//! PFM float images (`Pf` one channel, `PF` three channels). visnav writes little-endian
//! (negative scale) files; rows are stored bottom-to-top as the format requires, while the
//! in-memory [`PfmImage`] is top-to-bottom.

use std::path::Path;

use crate::error::{IoError, Result};
use crate::trajectory::write_atomically;

/// A float image with 1 or 3 interleaved channels, row-major, top row first.
#[derive(Debug, Clone, PartialEq)]
pub struct PfmImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Channels per pixel (1 or 3).
    pub channels: usize,
    /// Interleaved values, top row first.
    pub data: Vec<f32>,
}

/// Writes a PFM file (little-endian).
///
/// # Errors
/// A channel count other than 1 or 3, a buffer of the wrong size, or a write failure.
pub fn write_pfm(path: &Path, img: &PfmImage) -> Result<()> {
    let fmt = |message: String| IoError::Format {
        path: path.to_path_buf(),
        message,
    };
    let tag = match img.channels {
        1 => "Pf",
        3 => "PF",
        c => return Err(fmt(format!("PFM supports 1 or 3 channels, not {c}"))),
    };
    if img.data.len() != img.width * img.height * img.channels {
        return Err(fmt(
            "buffer size does not match width x height x channels".into()
        ));
    }
    let mut out = format!("{tag}\n{} {}\n-1.0\n", img.width, img.height).into_bytes();
    let row_len = img.width * img.channels;
    for y in (0..img.height).rev() {
        for v in &img.data[y * row_len..(y + 1) * row_len] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    write_atomically(path, &out)
}

/// Reads a PFM file (either endianness).
///
/// # Errors
/// A missing file, a bad header (a size that is not a positive integer, a scale of 0 or not a
/// number, which gives no byte order), or a truncated payload.
pub fn read_pfm(path: &Path) -> Result<PfmImage> {
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    let fmt = |message: &str| IoError::Format {
        path: path.to_path_buf(),
        message: message.to_string(),
    };
    // header: three whitespace-separated tokens lines: tag, "w h", scale
    let mut pos = 0;
    let mut tokens = Vec::new();
    while tokens.len() < 4 {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if start == pos {
            return Err(fmt("truncated PFM header"));
        }
        tokens.push(String::from_utf8_lossy(&bytes[start..pos]).to_string());
    }
    pos += 1; // the single whitespace byte after the scale
    let channels = match tokens[0].as_str() {
        "Pf" => 1,
        "PF" => 3,
        _ => return Err(fmt("not a PFM file (header must start with 'Pf' or 'PF')")),
    };
    let dim = |t: &str, what: &str| -> Result<usize> {
        match t.parse::<usize>() {
            Ok(v) if v > 0 => Ok(v),
            _ => Err(IoError::Format {
                path: path.to_path_buf(),
                message: format!("bad PFM {what} '{t}' (expected a positive integer)"),
            }),
        }
    };
    let width = dim(&tokens[1], "width")?;
    let height = dim(&tokens[2], "height")?;
    let scale: f32 = tokens[3].parse().map_err(|_| fmt("bad PFM scale"))?;
    if scale == 0.0 || !scale.is_finite() {
        // the sign of the scale is the byte order: 0 (or -0, NaN) says neither
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!(
                "PFM scale '{}' gives no byte order (negative: little-endian, positive: big-endian)",
                tokens[3]
            ),
        });
    }
    // checked: a huge width in the header must not overflow, nor allocate before the size check
    let payload = bytes.get(pos..).unwrap_or_default();
    let n = width
        .checked_mul(height)
        .and_then(|v| v.checked_mul(channels))
        .filter(|n| n.checked_mul(4).is_some_and(|b| b <= payload.len()))
        .ok_or_else(|| IoError::Format {
            path: path.to_path_buf(),
            message: format!(
                "truncated PFM payload: {width}x{height}x{channels} floats need more than the {} bytes after the header",
                payload.len()
            ),
        })?;
    let little = scale < 0.0;
    let vals: Vec<f32> = payload[..4 * n]
        .chunks_exact(4)
        .map(|c| {
            let b = [c[0], c[1], c[2], c[3]];
            if little {
                f32::from_le_bytes(b)
            } else {
                f32::from_be_bytes(b)
            }
        })
        .collect();
    let row_len = width * channels;
    let mut data = Vec::with_capacity(n);
    for y in (0..height).rev() {
        data.extend_from_slice(&vals[y * row_len..(y + 1) * row_len]);
    }
    Ok(PfmImage {
        width,
        height,
        channels,
        data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pfm_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        for channels in [1, 3] {
            let img = PfmImage {
                width: 4,
                height: 3,
                channels,
                data: (0..12 * channels).map(|i| i as f32 * 0.5).collect(),
            };
            let p = dir.path().join(format!("a{channels}.pfm"));
            write_pfm(&p, &img).unwrap();
            assert_eq!(read_pfm(&p).unwrap(), img);
            // bottom-to-top on disk: the first stored value is the bottom-left pixel
            let bytes = std::fs::read(&p).unwrap();
            let header_len = bytes.len() - 4 * img.data.len();
            let first = f32::from_le_bytes(bytes[header_len..header_len + 4].try_into().unwrap());
            assert_eq!(first, img.data[2 * 4 * channels]);
        }
        let p = dir.path().join("bad.pfm");
        std::fs::write(&p, b"P6\n1 1\n255\n").unwrap();
        assert!(read_pfm(&p).is_err());
    }
}
