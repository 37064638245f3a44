//! Middlebury `.flo` optical flow files: magic `PIEH` (202021.25 as little-endian f32),
//! width and height as little-endian i32, then `(u, v)` f32 pairs row by row.
//! Components above 1e9 mark unknown flow.

use std::path::Path;

use crate::error::{IoError, Result};
use crate::trajectory::write_atomically;
pub use visnav_core::FlowField;

const FLO_MAGIC: f32 = 202_021.25;

/// Reads a `.flo` file.
///
/// # Errors
/// A missing file, a wrong magic number, an implausible size, or a truncated payload.
pub fn read_flo(path: &Path) -> Result<FlowField> {
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    let fmt = |message: String| IoError::Format {
        path: path.to_path_buf(),
        message,
    };
    if bytes.len() < 12 {
        return Err(fmt(format!(
            "{} bytes is too short for a .flo header (12 bytes)",
            bytes.len()
        )));
    }
    let word = |i: usize| [bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]];
    let magic = f32::from_le_bytes(word(0));
    if magic != FLO_MAGIC {
        return Err(fmt(format!(
            "wrong magic {magic} (a .flo file starts with 'PIEH' = 202021.25)"
        )));
    }
    let w = i32::from_le_bytes(word(4));
    let h = i32::from_le_bytes(word(8));
    if !(1..=100_000).contains(&w) || !(1..=100_000).contains(&h) {
        return Err(fmt(format!("implausible size {w}x{h}")));
    }
    let (w, h) = (w as usize, h as usize);
    let expected = 12 + 8 * w * h;
    if bytes.len() != expected {
        return Err(fmt(format!(
            "{} bytes, expected {expected} for {w}x{h}",
            bytes.len()
        )));
    }
    let uv = bytes[12..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Ok(FlowField {
        width: w,
        height: h,
        uv,
    })
}

/// Writes a `.flo` file.
///
/// # Errors
/// The file cannot be written.
pub fn write_flo(path: &Path, flow: &FlowField) -> Result<()> {
    let mut out = Vec::with_capacity(12 + 4 * flow.uv.len());
    out.extend_from_slice(&FLO_MAGIC.to_le_bytes());
    out.extend_from_slice(&(flow.width as i32).to_le_bytes());
    out.extend_from_slice(&(flow.height as i32).to_le_bytes());
    for v in &flow.uv {
        out.extend_from_slice(&v.to_le_bytes());
    }
    write_atomically(path, &out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flo_round_trip_and_bad_magic() {
        let dir = tempfile::tempdir().unwrap();
        let mut f = FlowField::zeros(5, 3);
        f.set(4, 2, 1.5, -2.25);
        f.set(0, 1, 1e10, 0.0);
        let p = dir.path().join("a.flo");
        write_flo(&p, &f).unwrap();
        let g = read_flo(&p).unwrap();
        assert_eq!(f, g);
        assert!(!g.is_known(0, 1) && g.is_known(4, 2));
        let mut bytes = std::fs::read(&p).unwrap();
        bytes[0] = 0;
        std::fs::write(&p, &bytes).unwrap();
        assert!(
            read_flo(&p)
                .unwrap_err()
                .to_string()
                .contains("wrong magic")
        );
        std::fs::write(&p, &bytes[..20]).unwrap();
        assert!(read_flo(&p).is_err());
    }
}
