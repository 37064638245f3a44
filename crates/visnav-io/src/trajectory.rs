//! Trajectory files.
//!
//! * KITTI: one pose per line, 12 numbers, the row-major 3x4 matrix `[R | t]` of
//!   `world_from_cam` (camera-to-world, world = first camera).
//! * TUM: `timestamp tx ty tz qx qy qz qw` per line, `#` comments allowed.
//! * EuRoC ground truth (`mav0/state_groundtruth_estimate0/data.csv`): comma-separated
//!   `timestamp_ns, px, py, pz, qw, qx, qy, qz[, velocities and biases ...]`, the pose of the
//!   body (IMU) frame in the world, read only.

use std::path::Path;

use nalgebra::{Matrix3x4, Quaternion, Translation3, UnitQuaternion};
use visnav_core::Pose;
use visnav_core::se3::{pose_from_matrix3x4, pose_to_matrix3x4};

use crate::error::{IoError, Result};
use crate::text::parse_3x4;

/// A trajectory: poses `world_from_cam`, with timestamps when the format carries them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trajectory {
    /// Camera-to-world poses, one per frame.
    pub poses: Vec<Pose>,
    /// Timestamps in seconds (same length as `poses`), if known.
    pub timestamps: Option<Vec<f64>>,
}

/// Reads a KITTI-format trajectory (12 numbers a line), rotations projected onto SO(3).
///
/// # Errors
/// A missing file or a line that is not 12 finite numbers (the error names file and line).
pub fn read_kitti(path: &Path) -> Result<Vec<Pose>> {
    Ok(read_kitti_matrices(path)?
        .iter()
        .map(pose_from_matrix3x4)
        .collect())
}

/// Reads a KITTI-format trajectory as the row-major 3x4 matrices exactly as written (no
/// re-orthonormalisation): what the KITTI devkit scores.
///
/// # Errors
/// A missing file or a line that is not 12 finite numbers (the error names file and line).
pub fn read_kitti_matrices(path: &Path) -> Result<Vec<Matrix3x4<f64>>> {
    let text = crate::text::read_text(path)?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let m = parse_3x4(line, path, i + 1, "pose")?;
        check_pose_matrix(&m).map_err(|message| IoError::Parse {
            path: path.to_path_buf(),
            line: i + 1,
            message,
        })?;
        out.push(m);
    }
    Ok(out)
}

pub use visnav_core::se3::{
    MAX_COORDINATE_M, ROTATION_TOLERANCE, check_pose_matrix, check_position,
};

/// Writes a KITTI-format trajectory with 9 significant digits (the devkit's `%e` precision is 6;
/// more keeps round trips tight).
///
/// # Errors
/// The file cannot be written.
pub fn write_kitti(path: &Path, poses: &[Pose]) -> Result<()> {
    let mut out = String::with_capacity(poses.len() * 160);
    for p in poses {
        out.push_str(&kitti_line(p));
    }
    write_atomically(path, out.as_bytes())
}

/// One KITTI pose line (12 numbers of the 3x4 row-major `world_from_cam`, newline-terminated).
#[must_use]
pub fn kitti_line(pose: &Pose) -> String {
    let m = pose_to_matrix3x4(pose);
    let mut out = String::with_capacity(160);
    for r in 0..3 {
        for c in 0..4 {
            if r + c > 0 {
                out.push(' ');
            }
            out.push_str(&format!("{:.9e}", m[(r, c)]));
        }
    }
    out.push('\n');
    out
}

/// Parses the numbers of one line, naming file and line on failure.
pub(crate) fn parse_numbers(line: &str, path: &Path, line_no: usize) -> Result<Vec<f64>> {
    line.split_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| IoError::Parse {
                    path: path.to_path_buf(),
                    line: line_no,
                    message: format!("'{t}' is not a finite number"),
                })
        })
        .collect()
}

/// Whether a line carries no data (empty or a `#` comment).
fn is_blank_or_comment(line: &str) -> bool {
    let t = line.trim();
    t.is_empty() || t.starts_with('#')
}

/// Reads a TUM-format trajectory: `timestamp tx ty tz qx qy qz qw` per line (`world_from_cam`,
/// Hamilton quaternion, scalar last), `#` comments and blank lines skipped. Quaternions are
/// normalised.
///
/// # Errors
/// A missing file, a line that is not 8 finite numbers, or a zero quaternion (the error names
/// file and line).
pub fn read_tum(path: &Path) -> Result<Trajectory> {
    read_stamped(path, |line, line_no| parse_tum_line(line, path, line_no))
}

/// Reads a file of one timestamped pose a line through `parse(line, line_no)`, skipping `#`
/// comments and blank lines.
fn read_stamped(
    path: &Path,
    parse: impl Fn(&str, usize) -> Result<(Pose, f64)>,
) -> Result<Trajectory> {
    let text = crate::text::read_text(path)?;
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if is_blank_or_comment(line) {
            continue;
        }
        let (pose, t) = parse(line, i + 1)?;
        rows.push((t, i + 1, pose));
    }
    let rows = in_time_order(rows, path)?;
    let (stamps, poses) = rows.into_iter().map(|(t, _, p)| (t, p)).unzip();
    Ok(Trajectory {
        poses,
        timestamps: Some(stamps),
    })
}

/// The poses of a timestamped trajectory in time order: lines out of order are sorted (stable),
/// with a warning naming the file and the first line whose timestamp goes back, as an EuRoC
/// `data.csv` is (issue 53: an unsorted ground truth was half-matched in silence, as the
/// timestamp association needs sorted times); two lines with one timestamp (two poses at one
/// instant) are an error naming both lines.
fn in_time_order(
    mut rows: Vec<(f64, usize, Pose)>,
    path: &Path,
) -> Result<Vec<(f64, usize, Pose)>> {
    if let Some(w) = rows.windows(2).find(|w| w[1].0 < w[0].0) {
        log::warn!(
            "{}:{}: timestamps are not in time order ({} after {} on line {}); the poses are taken in timestamp order",
            path.display(),
            w[1].1,
            w[1].0,
            w[0].0,
            w[0].1
        );
        rows.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    if let Some(w) = rows.windows(2).find(|w| w[1].0 == w[0].0) {
        let (first, second) = (w[0].1.min(w[1].1), w[0].1.max(w[1].1));
        return Err(IoError::Parse {
            path: path.to_path_buf(),
            line: second,
            message: format!(
                "the timestamp {} of line {first} again: two poses at one instant",
                w[0].0
            ),
        });
    }
    Ok(rows)
}

fn parse_tum_line(line: &str, path: &Path, line_no: usize) -> Result<(Pose, f64)> {
    let v = parse_numbers(line, path, line_no)?;
    if v.len() != 8 {
        return Err(IoError::Parse {
            path: path.to_path_buf(),
            line: line_no,
            message: format!(
                "expected 8 numbers 'timestamp tx ty tz qx qy qz qw' (TUM), found {}",
                v.len()
            ),
        });
    }
    let q = Quaternion::new(v[7], v[4], v[5], v[6]);
    if q.norm() < 1e-9 || !q.norm().is_finite() {
        return Err(IoError::Parse {
            path: path.to_path_buf(),
            line: line_no,
            message: "quaternion (qx qy qz qw) has zero norm or overflows".into(),
        });
    }
    check_position(v[1], v[2], v[3]).map_err(|message| IoError::Parse {
        path: path.to_path_buf(),
        line: line_no,
        message,
    })?;
    let pose = Pose::from_parts(
        Translation3::new(v[1], v[2], v[3]),
        UnitQuaternion::from_quaternion(q),
    );
    Ok((pose, v[0]))
}

/// Writes a TUM-format trajectory (`timestamp tx ty tz qx qy qz qw`, 9 decimals for the
/// timestamp, 9 significant digits for the rest).
///
/// # Errors
/// `timestamps` and `poses` differ in length, or the file cannot be written.
pub fn write_tum(path: &Path, poses: &[Pose], timestamps: &[f64]) -> Result<()> {
    if poses.len() != timestamps.len() {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!("{} poses but {} timestamps", poses.len(), timestamps.len()),
        });
    }
    let mut out = String::with_capacity(poses.len() * 140 + 40);
    out.push_str("# timestamp tx ty tz qx qy qz qw\n");
    for (p, t) in poses.iter().zip(timestamps) {
        let tr = &p.translation.vector;
        let q = p.rotation.quaternion();
        out.push_str(&format!(
            "{t:.9} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e}\n",
            tr.x, tr.y, tr.z, q.i, q.j, q.k, q.w
        ));
    }
    write_atomically(path, out.as_bytes())
}

/// Reads an EuRoC ground-truth CSV (`state_groundtruth_estimate0/data.csv`): per line
/// `timestamp [ns], p_RS_R_x, p_RS_R_y, p_RS_R_z [m], q_RS_w, q_RS_x, q_RS_y, q_RS_z` followed by
/// any number of further columns (velocity, biases), comma-separated; `#` header lines and blank
/// lines skipped. Poses are `world_from_body` (EuRoC's `R` = world, `S` = the IMU body frame);
/// timestamps come back in seconds. Quaternions (scalar first here) are normalised.
///
/// # Errors
/// A missing file, a line with fewer than 8 fields or a field that is not a finite number, or a
/// zero quaternion (the error names file and line).
pub fn read_euroc_csv(path: &Path) -> Result<Trajectory> {
    read_stamped(path, |line, line_no| parse_euroc_line(line, path, line_no))
}

/// One line of an EuRoC ground-truth CSV: `world_from_body` and the timestamp in seconds.
fn parse_euroc_line(line: &str, path: &Path, line_no: usize) -> Result<(Pose, f64)> {
    let parse_err = |message: String| IoError::Parse {
        path: path.to_path_buf(),
        line: line_no,
        message,
    };
    let fields: Vec<&str> = line.split(',').map(str::trim).collect();
    if fields.len() < 8 {
        return Err(parse_err(format!(
            "expected at least 8 comma-separated fields 'timestamp_ns, px, py, pz, qw, qx, qy, qz' (EuRoC), found {}",
            fields.len()
        )));
    }
    let mut v = [0.0_f64; 8];
    for (slot, field) in v.iter_mut().zip(&fields) {
        *slot = field
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| parse_err(format!("'{field}' is not a finite number")))?;
    }
    let q = Quaternion::new(v[4], v[5], v[6], v[7]);
    if q.norm() < 1e-9 || !q.norm().is_finite() {
        return Err(parse_err(
            "quaternion (qw qx qy qz) has zero norm or overflows".into(),
        ));
    }
    check_position(v[1], v[2], v[3]).map_err(parse_err)?;
    let pose = Pose::from_parts(
        Translation3::new(v[1], v[2], v[3]),
        UnitQuaternion::from_quaternion(q),
    );
    // nanoseconds → seconds (integer part first, so that 19-digit stamps keep their ns)
    let seconds = match fields[0].parse::<u64>() {
        Ok(n) => (n / 1_000_000_000) as f64 + (n % 1_000_000_000) as f64 * 1e-9,
        Err(_) => v[0] * 1e-9,
    };
    Ok((pose, seconds))
}

/// Trajectory file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum TrajectoryFormat {
    /// 12 numbers a line: row-major 3x4 `world_from_cam`.
    Kitti,
    /// 8 numbers a line: `timestamp tx ty tz qx qy qz qw`.
    Tum,
    /// EuRoC ground-truth CSV: `timestamp_ns, px, py, pz, qw, qx, qy, qz, ...` (read only).
    EurocCsv,
}

/// Detects the format of a trajectory file from its first data line (12 numbers: KITTI,
/// 8 numbers: TUM, comma-separated with at least 8 fields: EuRoC CSV; `#` comments and blank
/// lines skipped).
///
/// # Errors
/// A missing file, a file without data lines, or a first data line with another count.
pub fn detect_format(path: &Path) -> Result<TrajectoryFormat> {
    let text = crate::text::read_text(path)?;
    let Some((i, line)) = text
        .lines()
        .enumerate()
        .find(|(_, l)| !is_blank_or_comment(l))
    else {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: "trajectory file has no poses".into(),
        });
    };
    if line.contains(',') && line.split(',').count() >= 8 {
        return Ok(TrajectoryFormat::EurocCsv);
    }
    match line.split_whitespace().count() {
        12 => Ok(TrajectoryFormat::Kitti),
        8 => Ok(TrajectoryFormat::Tum),
        n => Err(IoError::Parse {
            path: path.to_path_buf(),
            line: i + 1,
            message: format!(
                "expected 12 numbers (KITTI 3x4 pose) or 8 (TUM 'timestamp tx ty tz qx qy qz qw'), found {n} (or an EuRoC CSV with 8+ comma-separated fields)"
            ),
        }),
    }
}

/// Reads a trajectory in KITTI, TUM or EuRoC CSV format, detected by [`detect_format`]. KITTI
/// files yield `timestamps: None`.
///
/// # Errors
/// As [`detect_format`], [`read_kitti`], [`read_tum`] and [`read_euroc_csv`].
pub fn read_trajectory(path: &Path) -> Result<Trajectory> {
    match detect_format(path)? {
        TrajectoryFormat::Kitti => Ok(Trajectory {
            poses: read_kitti(path)?,
            timestamps: None,
        }),
        TrajectoryFormat::Tum => read_tum(path),
        TrajectoryFormat::EurocCsv => read_euroc_csv(path),
    }
}

/// A trajectory file as an evaluation needs it: `world_from_cam` as homogeneous matrices exactly
/// as written (KITTI files are not re-orthonormalised: the devkit scores what is in the file),
/// and the timestamps of TUM and EuRoC files.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseMatrices {
    /// One 4x4 `world_from_cam` per line.
    pub poses: Vec<nalgebra::Matrix4<f64>>,
    /// Timestamps, seconds (TUM, EuRoC).
    pub timestamps: Option<Vec<f64>>,
}

/// Reads a KITTI, TUM or EuRoC trajectory file (format detected) as [`PoseMatrices`].
///
/// # Errors
/// As the format's reader: the file, the line and the problem.
pub fn read_pose_matrices(path: &Path) -> Result<PoseMatrices> {
    Ok(match detect_format(path)? {
        TrajectoryFormat::Kitti => PoseMatrices {
            poses: read_kitti_matrices(path)?
                .iter()
                .map(|m| {
                    let mut h = nalgebra::Matrix4::identity();
                    h.fixed_view_mut::<3, 4>(0, 0).copy_from(m);
                    h
                })
                .collect(),
            timestamps: None,
        },
        TrajectoryFormat::Tum | TrajectoryFormat::EurocCsv => {
            let t = read_trajectory(path)?;
            PoseMatrices {
                poses: t.poses.iter().map(Pose::to_homogeneous).collect(),
                timestamps: t.timestamps,
            }
        }
    })
}

/// Writes `bytes` to `path` atomically, creating parent directories (the name the parsers'
/// writers use for [`crate::atomic::write_atomic`]).
pub use crate::atomic::write_atomic as write_atomically;

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

    fn sample_poses(n: usize) -> Vec<Pose> {
        (0..n)
            .map(|i| {
                let f = i as f64;
                se3_exp(&Vector6::new(
                    f,
                    0.1 * f,
                    -2.0,
                    0.01 * f,
                    0.3 - 0.2 * f,
                    -0.02,
                ))
            })
            .collect()
    }

    /// An EuRoC ground-truth CSV (header, 17 columns, scalar-first quaternion, ns stamps) reads
    /// as the same poses and stamps as the equivalent TUM file.
    #[test]
    fn euroc_csv_reads_like_tum() {
        let dir = tempfile::tempdir().unwrap();
        let poses = sample_poses(12);
        let stamps_ns: Vec<u64> = (0..12)
            .map(|i| 1_403_715_273_262_142_976 + i * 5_000_000)
            .collect();
        let mut csv = String::from(
            "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\n",
        );
        for (p, ns) in poses.iter().zip(&stamps_ns) {
            let t = p.translation.vector;
            let q = p.rotation.quaternion();
            csv.push_str(&format!(
                "{ns},{:.12},{:.12},{:.12},{:.12},{:.12},{:.12},{:.12},0.1,0.2,0.3,0,0,0,0,0,0\n",
                t.x, t.y, t.z, q.w, q.i, q.j, q.k
            ));
        }
        let p = dir.path().join("data.csv");
        std::fs::write(&p, csv).unwrap();
        assert_eq!(detect_format(&p).unwrap(), TrajectoryFormat::EurocCsv);
        let back = read_trajectory(&p).unwrap();
        let ts = back.timestamps.unwrap();
        assert_eq!(back.poses.len(), 12);
        for ((a, b), (ns, t)) in poses.iter().zip(&back.poses).zip(stamps_ns.iter().zip(&ts)) {
            assert!((a.to_homogeneous() - b.to_homogeneous()).abs().max() < 1e-9);
            // nanosecond stamps survive the conversion to seconds to within 1 µs
            assert!((*ns as f64 * 1e-9 - t).abs() < 1e-6);
        }
        assert!(
            (ts[1] - ts[0] - 0.005).abs() < 1e-6,
            "f64 seconds near 1.4e9 resolve ~2.4e-7 s"
        );
    }

    #[test]
    fn euroc_csv_errors_name_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("data.csv");
        std::fs::write(
            &p,
            "#h\n1403715273262142976,1,2,3,1,0,0,0\n1403715273267142976,1,2,x,1,0,0,0\n",
        )
        .unwrap();
        let e = read_trajectory(&p).unwrap_err().to_string();
        assert!(
            e.contains("data.csv") && e.contains('3') && e.contains("'x'"),
            "{e}"
        );
        std::fs::write(&p, "1403715273262142976,1,2,3,0,0,0,0\n").unwrap();
        let e = read_trajectory(&p).unwrap_err().to_string();
        assert!(e.contains("zero norm"), "{e}");
        std::fs::write(&p, "1403715273262142976,1,2,3,1,0,0,0\n1,2,3\n").unwrap();
        let e = read_trajectory(&p).unwrap_err().to_string();
        assert!(e.contains("at least 8"), "{e}");
    }

    #[test]
    fn tum_round_trip_and_detection() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("traj.tum");
        let poses = sample_poses(30);
        let stamps: Vec<f64> = (0..30)
            .map(|i| 1_317_000_000.0 + 0.05 * f64::from(i))
            .collect();
        write_tum(&p, &poses, &stamps).unwrap();
        let back = read_trajectory(&p).unwrap();
        assert_eq!(detect_format(&p).unwrap(), TrajectoryFormat::Tum);
        let ts = back.timestamps.unwrap();
        assert_eq!(back.poses.len(), 30);
        for ((a, b), (ta, tb)) in poses.iter().zip(&back.poses).zip(stamps.iter().zip(&ts)) {
            assert!((a.to_homogeneous() - b.to_homogeneous()).abs().max() < 1e-8);
            assert!((ta - tb).abs() < 1e-6);
        }
        let k = dir.path().join("traj.txt");
        write_kitti(&k, &poses).unwrap();
        let kb = read_trajectory(&k).unwrap();
        assert!(kb.timestamps.is_none());
        assert_eq!(kb.poses.len(), 30);
        assert!(write_tum(&p, &poses, &stamps[..3]).is_err());
    }

    #[test]
    fn tum_comments_and_bad_lines() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.txt");
        std::fs::write(&p, "# header\n\n1.0 1 2 3 0 0 0 2\n").unwrap();
        let t = read_tum(&p).unwrap();
        assert_eq!(t.poses.len(), 1);
        assert!((t.poses[0].rotation.angle()).abs() < 1e-12);
        assert_eq!(t.poses[0].translation.vector.y, 2.0);
        std::fs::write(&p, "# header\n1.0 1 2 3 0 0 0 1\n2.0 1 2 3 0 0 1\n").unwrap();
        let e = read_tum(&p).unwrap_err().to_string();
        assert!(e.contains("t.txt:3") && e.contains("found 7"), "{e}");
        std::fs::write(&p, "1.0 1 2 3 0 0 0 0\n").unwrap();
        let e = read_tum(&p).unwrap_err().to_string();
        assert!(e.contains("t.txt:1") && e.contains("zero norm"), "{e}");
        std::fs::write(&p, "1.0 1 2 3 0 nan 0 1\n").unwrap();
        assert!(read_tum(&p).unwrap_err().to_string().contains("t.txt:1"));
        std::fs::write(&p, "# only\n").unwrap();
        assert!(read_trajectory(&p).is_err());
        std::fs::write(&p, "1 2 3\n").unwrap();
        let e = read_trajectory(&p).unwrap_err().to_string();
        assert!(e.contains("t.txt:1") && e.contains("found 3"), "{e}");
    }

    /// Issue 53: lines out of time order were kept in file order, which the timestamp
    /// association (sorted times) half-matched in silence.
    #[test]
    fn tum_and_euroc_lines_out_of_time_order_are_sorted_and_repeats_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("gt.txt");
        std::fs::write(
            &p,
            "# t x y z qx qy qz qw\n3.0 3 0 0 0 0 0 1\n1.0 1 0 0 0 0 0 1\n2.0 2 0 0 0 0 0 1\n",
        )
        .unwrap();
        let t = read_tum(&p).unwrap();
        assert_eq!(t.timestamps, Some(vec![1.0, 2.0, 3.0]));
        let x: Vec<f64> = t.poses.iter().map(|p| p.translation.vector.x).collect();
        assert_eq!(x, [1.0, 2.0, 3.0]);
        std::fs::write(
            &p,
            "1.0 1 0 0 0 0 0 1\n2.0 2 0 0 0 0 0 1\n1.0 3 0 0 0 0 0 1\n",
        )
        .unwrap();
        let e = read_tum(&p).unwrap_err().to_string();
        assert!(
            e.contains("gt.txt:3: the timestamp 1 of line 1 again"),
            "{e}"
        );
        let csv = dir.path().join("data.csv");
        std::fs::write(
            &csv,
            "#t,x,y,z,qw,qx,qy,qz\n2000000000,2,0,0,1,0,0,0\n1000000000,1,0,0,1,0,0,0\n",
        )
        .unwrap();
        let t = read_euroc_csv(&csv).unwrap();
        assert_eq!(t.timestamps, Some(vec![1.0, 2.0]));
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
