//! Trajectory files.
//!
//! * KITTI: one pose per line, 12 numbers, the row-major 3x4 matrix `[R | t]` of
//!   `world_from_cam` (camera-to-world, world = first camera).
//! * TUM: `timestamp tx ty tz qx qy qz qw` per line, `#` comments allowed.

use std::io::Write;
use std::path::Path;

use visnav_core::Pose;
use visnav_core::se3::{pose_from_matrix3x4, pose_to_matrix3x4};

use crate::error::{IoError, Result};
use crate::kitti::parse_3x4;

/// A trajectory: poses `world_from_cam`, with timestamps when the format carries them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trajectory {
    /// Camera-to-world poses, one per frame.
    pub poses: Vec<Pose>,
    /// Timestamps in seconds (same length as `poses`), if known.
    pub timestamps: Option<Vec<f64>>,
}

/// Reads a KITTI-format trajectory (12 numbers a line).
///
/// # Errors
/// A missing file or a line that is not 12 finite numbers (the error names file and line).
pub fn read_kitti(path: &Path) -> Result<Vec<Pose>> {
    let text = std::fs::read_to_string(path).map_err(|e| IoError::io(path, e))?;
    let mut poses = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let m = parse_3x4(line, path, i + 1, "pose")?;
        poses.push(pose_from_matrix3x4(&m));
    }
    Ok(poses)
}

/// Writes a KITTI-format trajectory with 9 significant digits (the devkit's `%e` precision is 6;
/// more keeps round trips tight).
///
/// # Errors
/// The file cannot be written.
pub fn write_kitti(path: &Path, poses: &[Pose]) -> Result<()> {
    let mut out = String::with_capacity(poses.len() * 160);
    for p in poses {
        let m = pose_to_matrix3x4(p);
        let mut first = true;
        for r in 0..3 {
            for c in 0..4 {
                if !first {
                    out.push(' ');
                }
                first = false;
                out.push_str(&format!("{:.9e}", m[(r, c)]));
            }
        }
        out.push('\n');
    }
    write_atomically(path, out.as_bytes())
}

/// Writes `bytes` to `path` (creating parent directories).
///
/// # Errors
/// The directory or file cannot be written.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|e| IoError::io(parent, e))?;
    }
    let mut f = std::fs::File::create(path).map_err(|e| IoError::io(path, e))?;
    f.write_all(bytes).map_err(|e| IoError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector6;
    use visnav_core::se3::se3_exp;

    #[test]
    fn kitti_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sub/poses.txt");
        let poses: Vec<Pose> = (0..20)
            .map(|i| {
                se3_exp(&Vector6::new(
                    i as f64,
                    0.1 * i as f64,
                    -2.0,
                    0.01 * i as f64,
                    0.3,
                    -0.02,
                ))
            })
            .collect();
        write_kitti(&p, &poses).unwrap();
        let back = read_kitti(&p).unwrap();
        assert_eq!(back.len(), poses.len());
        for (a, b) in poses.iter().zip(&back) {
            assert!((a.to_homogeneous() - b.to_homogeneous()).abs().max() < 1e-8);
        }
    }

    #[test]
    fn malformed_pose_line_names_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.txt");
        std::fs::write(&p, "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n").unwrap();
        let e = read_kitti(&p).unwrap_err().to_string();
        assert!(e.contains("bad.txt:2") && e.contains("found 11"), "{e}");
    }
}
