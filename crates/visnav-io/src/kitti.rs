//! KITTI sequences: the odometry benchmark layout and the raw-data layout, each opened as a
//! [`Sequence`] (`crate::sequence`) whose frames are read lazily (a 4,500-frame sequence is never
//! held in memory).
//!
//! * Odometry: `XX/image_0..image_3/NNNNNN.png` (or `.jpg`), `XX/calib.txt` (`P0:`..`P3:`,
//!   optional `Tr:`), `XX/times.txt`. Intrinsics from `P0`, baseline `-P1[0][3] / P1[0][0]`.
//! * Raw: `YYYY_MM_DD_drive_NNNN_sync/image_0X/data/NNNNNNNNNN.png`, timestamps in
//!   `image_0X/timestamps.txt`, calibration `calib_cam_to_cam.txt` beside the drive folder
//!   (rectified `P_rect_00`, `P_rect_01`).

use std::path::{Path, PathBuf};

use nalgebra::Matrix3x4;

use crate::error::{IoError, Result};
use crate::image_io::list_images;
use crate::sequence::{FrameFiles, Sequence, SequenceLayout};
use crate::text::parse_3x4;

/// A KITTI odometry sequence: `image_0/` (+ `image_1/`), `calib.txt`, `times.txt`.
pub(crate) fn open_odometry(root: &Path) -> Result<Sequence> {
    let calib_path = root.join("calib.txt");
    let calib = read_odometry_calib(&calib_path)?;
    // PNG as KITTI ships it, or JPEG (a converted copy): listed as image folders are
    let left = list_images(&root.join("image_0"))?;
    if left.is_empty() {
        return Err(IoError::EmptySequence {
            path: root.join("image_0"),
        });
    }
    let right = if root.join("image_1").is_dir() {
        Some(list_images(&root.join("image_1"))?)
    } else {
        None
    };
    let right = right.filter(|r| !r.is_empty());
    let right = pair_by_name(&left, right, &root.join("image_1"))?;
    let timestamps = frame_timestamps(&root.join("times.txt"), &left, read_times)?;
    Sequence::finish(
        root,
        SequenceLayout::KittiOdometry,
        &calib_path,
        (calib.p0, calib.p1),
        FrameFiles {
            timestamps,
            timestamped: false,
            left,
            right,
        },
    )
}

/// The right images paired with the left ones by file name (`image_1/000042.png` with
/// `image_0/000042.png`), never by sort position: a right image missing, renamed or extra is an
/// error naming it, so that no frame is paired with another's partner.
fn pair_by_name(
    left: &[PathBuf],
    right: Option<Vec<PathBuf>>,
    right_dir: &Path,
) -> Result<Option<Vec<PathBuf>>> {
    let Some(right) = right else {
        return Ok(None);
    };
    let names: std::collections::HashSet<&std::ffi::OsStr> =
        right.iter().filter_map(|p| p.file_name()).collect();
    let counts = if right.len() == left.len() {
        String::new()
    } else {
        format!(
            "{} right images but {} left images: ",
            right.len(),
            left.len()
        )
    };
    let mut paired = Vec::with_capacity(left.len());
    for l in left {
        let name = l.file_name().unwrap_or_default();
        if !names.contains(name) {
            return Err(IoError::Format {
                path: right_dir.to_path_buf(),
                message: format!(
                    "{counts}no right image {} for the left image {} (left and right frames are paired by file name)",
                    Path::new(name).display(),
                    l.display()
                ),
            });
        }
        paired.push(right_dir.join(name));
    }
    if right.len() != left.len() {
        let left_names: std::collections::HashSet<&std::ffi::OsStr> =
            left.iter().filter_map(|p| p.file_name()).collect();
        let extra = right
            .iter()
            .find(|r| !left_names.contains(r.file_name().unwrap_or_default()))
            .map_or_else(String::new, |r| format!(" (e.g. {})", r.display()));
        return Err(IoError::Format {
            path: right_dir.to_path_buf(),
            message: format!("{counts}a right image has no left image of the same name{extra}"),
        });
    }
    Ok(Some(paired))
}

/// The frame number of each image (`000042.png` → 42), when every file stem is a number.
fn frame_numbers(frames: &[PathBuf]) -> Option<Vec<usize>> {
    frames
        .iter()
        .map(|p| p.file_stem()?.to_str()?.parse::<usize>().ok())
        .collect()
}

/// The timestamps of `frames` from `path` (read with `read`), or 0.1 s steps (KITTI's 10 Hz)
/// when the file does not exist. Frames named by number take the line of their number (line
/// `number - first` when the file has fewer lines than the last number: a clip's own file), so
/// that a gap in the numbering keeps every frame's own time, and the gap is reported with a
/// warning. Frames not named by number take the lines in order.
fn frame_timestamps(
    path: &Path,
    frames: &[PathBuf],
    read: fn(&Path) -> Result<Vec<f64>>,
) -> Result<Vec<f64>> {
    let numbers = frame_numbers(frames);
    if let Some(n) = &numbers {
        report_gaps(frames, n);
    }
    let Some(numbers) = numbers else {
        // names that are not numbers: the lines in order
        if !crate::text::entry_exists(path) {
            return Ok((0..frames.len()).map(|i| i as f64 * 0.1).collect());
        }
        let t = read(path)?;
        if t.len() < frames.len() {
            return Err(IoError::Format {
                path: path.to_path_buf(),
                message: format!("{} timestamps for {} frames", t.len(), frames.len()),
            });
        }
        return Ok(t[..frames.len()].to_vec());
    };
    let first = numbers.iter().copied().min().unwrap_or(0);
    let last = numbers.iter().copied().max().unwrap_or(0);
    if !crate::text::entry_exists(path) {
        return Ok(numbers.iter().map(|&i| (i - first) as f64 * 0.1).collect());
    }
    let t = read(path)?;
    // KITTI numbers frames from 0 and line i of the file is frame i; a clip whose file starts
    // at its first frame (fewer lines than the last number) is indexed from that frame
    let offset = if t.len() > last {
        0
    } else if t.len() > last - first {
        first
    } else {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!(
                "{} timestamps for {} frames (numbered {first} to {last}{}): the file needs a line per frame number",
                t.len(),
                frames.len(),
                if last - first + 1 > frames.len() {
                    ", with gaps"
                } else {
                    ""
                }
            ),
        });
    };
    Ok(numbers.iter().map(|&i| t[i - offset]).collect())
}

/// Warns about every jump in the frame numbering (`000010.png` then `000012.png`).
fn report_gaps(frames: &[PathBuf], numbers: &[usize]) {
    let mut missing = 0;
    let mut first = None;
    for (k, w) in numbers.windows(2).enumerate() {
        if w[1] != w[0] + 1 {
            missing += w[1].saturating_sub(w[0] + 1);
            first.get_or_insert(k);
        }
    }
    if let Some(k) = first {
        log::warn!(
            "{}: the frame numbering has gaps, {missing} frame(s) missing (first after {}); each frame keeps the timestamp of its own number",
            frames[k].parent().unwrap_or(Path::new(".")).display(),
            frames[k].display()
        );
    }
}

/// The projection matrices of a KITTI odometry `calib.txt`.
#[derive(Debug, Clone, PartialEq)]
pub struct OdometryCalib {
    /// Left gray camera.
    pub p0: Matrix3x4<f64>,
    /// Right gray camera, if present.
    pub p1: Option<Matrix3x4<f64>>,
    /// Left colour camera, if present.
    pub p2: Option<Matrix3x4<f64>>,
    /// Right colour camera, if present.
    pub p3: Option<Matrix3x4<f64>>,
    /// Velodyne-to-camera transform, if present.
    pub tr: Option<Matrix3x4<f64>>,
}

/// The `KEY: values` lines of a calibration file (blank lines skipped): `(line number, trimmed
/// key, the rest)`, or an error naming the file and line when a line has no `:`.
fn calib_entries<'a>(
    text: &'a str,
    path: &'a Path,
    expected: &'static str,
) -> impl Iterator<Item = Result<(usize, &'a str, &'a str)>> + 'a {
    text.lines().enumerate().filter_map(move |(i, line)| {
        let line = line.trim();
        if line.is_empty() {
            return None;
        }
        Some(match line.split_once(':') {
            Some((key, rest)) => Ok((i + 1, key.trim(), rest)),
            None => Err(IoError::Parse {
                path: path.to_path_buf(),
                line: i + 1,
                message: expected.into(),
            }),
        })
    })
}

/// The keys of a calibration file met so far, so that a key given twice is an error (which of
/// two `P0:` lines is meant cannot be guessed; taking the last scaled every pose silently).
#[derive(Default)]
struct SeenKeys(std::collections::HashMap<String, usize>);

impl SeenKeys {
    fn check(&mut self, key: &str, line: usize, path: &Path) -> Result<()> {
        if let Some(first) = self.0.insert(key.to_string(), line) {
            return Err(IoError::Parse {
                path: path.to_path_buf(),
                line,
                message: format!("'{key}:' is given twice (first on line {first})"),
            });
        }
        Ok(())
    }
}

/// Reads a KITTI odometry `calib.txt`; `P0` is required, the rest optional.
///
/// # Errors
/// A missing file, a line without `key:`, a matrix without 12 numbers, or no `P0`.
pub fn read_odometry_calib(path: &Path) -> Result<OdometryCalib> {
    let text = crate::text::read_text(path)?;
    let mut calib = OdometryCalib {
        p0: Matrix3x4::zeros(),
        p1: None,
        p2: None,
        p3: None,
        tr: None,
    };
    let mut have_p0 = false;
    let mut seen = SeenKeys::default();
    for entry in calib_entries(&text, path, "expected 'KEY: 12 numbers' (e.g. 'P0: ...')") {
        let (line_no, key, rest) = entry?;
        if ["P0", "P1", "P2", "P3", "Tr"].contains(&key) {
            seen.check(key, line_no, path)?;
        }
        let slot = match key {
            "P0" => {
                have_p0 = true;
                calib.p0 = parse_3x4(rest, path, line_no, key)?;
                continue;
            }
            "P1" => &mut calib.p1,
            "P2" => &mut calib.p2,
            "P3" => &mut calib.p3,
            "Tr" => &mut calib.tr,
            _ => continue,
        };
        *slot = Some(parse_3x4(rest, path, line_no, key)?);
    }
    if !have_p0 {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: "no 'P0:' line (left camera projection matrix)".into(),
        });
    }
    Ok(calib)
}

/// Reads `times.txt` (one timestamp in seconds per line).
///
/// # Errors
/// A missing file or a line that is not a finite number.
pub fn read_times(path: &Path) -> Result<Vec<f64>> {
    let text = crate::text::read_text(path)?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            l.trim()
                .parse::<f64>()
                .ok()
                .filter(|t| t.is_finite())
                .ok_or_else(|| IoError::Parse {
                    path: path.to_path_buf(),
                    line: i + 1,
                    message: format!("expected a timestamp in seconds, found '{}'", l.trim()),
                })
        })
        .collect()
}

/// Lists the `.png` files of a directory in frame order ([`crate::frame_order`]): by the number
/// in their names (`9.png` before `10.png`). macOS metadata files (`._*`, `.DS_Store`) are
/// skipped with a note ([`crate::image_io::list_frames`]).
///
/// # Errors
/// A missing or unreadable directory, names whose order is ambiguous.
pub fn list_pngs(dir: &Path) -> Result<Vec<PathBuf>> {
    crate::image_io::list_frames(dir, |p| {
        p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"))
    })
}

pub mod raw {
    //! KITTI raw drive layout: `YYYY_MM_DD_drive_NNNN_sync/image_0X/data/NNNNNNNNNN.png`,
    //! `image_0X/timestamps.txt` (`2011-09-26 13:02:25.964389445`), and
    //! `calib_cam_to_cam.txt` in the parent (date) directory with the rectified projection
    //! matrices `P_rect_00` (left gray) and `P_rect_01` (right gray).
    use super::{
        FrameFiles, IoError, Path, PathBuf, Result, Sequence, SequenceLayout, frame_timestamps,
        list_pngs, pair_by_name, parse_3x4,
    };
    use nalgebra::Matrix3x4;

    /// Rectified projection matrices read from a raw `calib_cam_to_cam.txt`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct RawCalib {
        /// `P_rect_00`: left gray camera after rectification.
        pub p_rect_00: Matrix3x4<f64>,
        /// `P_rect_01`: right gray camera after rectification, if present.
        pub p_rect_01: Option<Matrix3x4<f64>>,
    }

    /// Reads the rectified projection matrices of a raw `calib_cam_to_cam.txt`. Other keys
    /// (`calib_time`, `K_00`, `S_rect_00`, ...) are skipped.
    ///
    /// # Errors
    /// A missing file, a line without `key:`, a `P_rect_0X` without 12 numbers, or no `P_rect_00`.
    pub fn read_raw_calib(path: &Path) -> Result<RawCalib> {
        let text = crate::text::read_text(path)?;
        let mut p0 = None;
        let mut p1 = None;
        let expected = "expected 'KEY: values' (e.g. 'P_rect_00: 12 numbers')";
        let mut seen = super::SeenKeys::default();
        for entry in super::calib_entries(&text, path, expected) {
            let (line_no, key, rest) = entry?;
            if key.starts_with("P_rect_0") {
                seen.check(key, line_no, path)?;
            }
            match key {
                "P_rect_00" => p0 = Some(parse_3x4(rest, path, line_no, "P_rect_00")?),
                "P_rect_01" => p1 = Some(parse_3x4(rest, path, line_no, "P_rect_01")?),
                _ => {}
            }
        }
        let Some(p_rect_00) = p0 else {
            return Err(IoError::Format {
                path: path.to_path_buf(),
                message: "no 'P_rect_00:' line (rectified left camera projection matrix)".into(),
            });
        };
        Ok(RawCalib {
            p_rect_00,
            p_rect_01: p1,
        })
    }

    /// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's `days_from_civil`).
    fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
        let y = if m <= 2 { y - 1 } else { y };
        let era = y.div_euclid(400);
        let yoe = y - era * 400;
        let mp = (m + 9) % 12;
        let doy = (153 * mp + 2) / 5 + d - 1;
        let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
        era * 146_097 + doe - 719_468
    }

    /// Parses `2011-09-26 13:02:25.964389445` into seconds since 1970 (UTC, no leap seconds).
    fn parse_raw_timestamp(s: &str) -> Option<f64> {
        let (date, time) = s.trim().split_once(' ')?;
        let mut dp = date.split('-').map(str::parse::<i64>);
        let (y, mo, d) = (dp.next()?.ok()?, dp.next()?.ok()?, dp.next()?.ok()?);
        // four-digit years: a year of 2^32 overflowed the seconds (found by tests/fuzz.rs)
        if dp.next().is_some()
            || !(0..=9999).contains(&y)
            || !(1..=12).contains(&mo)
            || !(1..=31).contains(&d)
        {
            return None;
        }
        let mut tp = time.trim().split(':');
        let h: i64 = tp.next()?.parse().ok()?;
        let mi: i64 = tp.next()?.parse().ok()?;
        let sec: f64 = tp.next()?.parse().ok()?;
        if tp.next().is_some() || !(0..24).contains(&h) || !(0..60).contains(&mi) {
            return None;
        }
        if !(0.0..61.0).contains(&sec) {
            return None;
        }
        let days = days_from_civil(y, mo, d);
        Some((days * 86_400 + h * 3600 + mi * 60) as f64 + sec)
    }

    /// Reads a raw `timestamps.txt` as seconds relative to its first line.
    ///
    /// # Errors
    /// A missing file or a line that is not `YYYY-MM-DD HH:MM:SS.fraction`.
    pub fn read_raw_timestamps(path: &Path) -> Result<Vec<f64>> {
        let text = crate::text::read_text(path)?;
        let mut abs = Vec::new();
        for (i, line) in text.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let t = parse_raw_timestamp(line).ok_or_else(|| IoError::Parse {
                path: path.to_path_buf(),
                line: i + 1,
                message: format!(
                    "expected a timestamp like '2011-09-26 13:02:25.964389445', found '{}'",
                    line.trim()
                ),
            })?;
            abs.push(t);
        }
        let t0 = abs.first().copied().unwrap_or(0.0);
        Ok(abs.into_iter().map(|t| t - t0).collect())
    }

    /// The PNGs of `image_0X/data`, or an error naming the folder.
    fn camera_pngs(root: &Path, cam: &str) -> Result<Option<Vec<PathBuf>>> {
        let dir = root.join(cam).join("data");
        if !dir.is_dir() {
            return Ok(None);
        }
        list_pngs(&dir).map(Some)
    }

    /// Opens a KITTI raw drive directory.
    pub(crate) fn open_raw(root: &Path) -> Result<Sequence> {
        // canonical first, so that `.` or `drive/` still finds the date folder above
        let abs_root = root.canonicalize().unwrap_or_else(|_| root.to_path_buf());
        let calib_path = abs_root.parent().map_or_else(
            || PathBuf::from("calib_cam_to_cam.txt"),
            |p| p.join("calib_cam_to_cam.txt"),
        );
        if !crate::text::entry_exists(&calib_path) {
            return Err(IoError::NotFound {
                path: calib_path,
                what: "raw calibration calib_cam_to_cam.txt (expected beside the drive folder)"
                    .into(),
            });
        }
        let calib = read_raw_calib(&calib_path)?;
        let Some(left) = camera_pngs(root, "image_00")? else {
            return Err(IoError::NotFound {
                path: root.join("image_00").join("data"),
                what: "left camera images of a KITTI raw drive".into(),
            });
        };
        if left.is_empty() {
            return Err(IoError::EmptySequence {
                path: root.join("image_00").join("data"),
            });
        }
        let right = camera_pngs(root, "image_01")?.filter(|r| !r.is_empty());
        let right = pair_by_name(&left, right, &root.join("image_01").join("data"))?;
        let timestamps = frame_timestamps(
            &root.join("image_00").join("timestamps.txt"),
            &left,
            read_raw_timestamps,
        )?;
        Sequence::finish(
            root,
            SequenceLayout::KittiRaw,
            &calib_path,
            (calib.p_rect_00, calib.p_rect_01),
            FrameFiles {
                timestamps,
                timestamped: false,
                left,
                right,
            },
        )
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn raw_timestamps_are_relative_seconds_across_midnight() {
            let dir = tempfile::tempdir().unwrap();
            let p = dir.path().join("timestamps.txt");
            std::fs::write(
                &p,
                "2011-12-31 23:59:59.900000000\n2012-01-01 00:00:00.000000000\n2012-01-01 00:00:01.250000000\n",
            )
            .unwrap();
            let t = read_raw_timestamps(&p).unwrap();
            assert_eq!(t.len(), 3);
            assert!(
                (t[1] - 0.1).abs() < 1e-6 && (t[2] - 1.35).abs() < 1e-6,
                "{t:?}"
            );
            std::fs::write(&p, "2011-09-26 13:02:25.9\n2011-09-26 13:02\n").unwrap();
            let e = read_raw_timestamps(&p).unwrap_err().to_string();
            assert!(e.contains("timestamps.txt:2"), "{e}");
        }

        #[test]
        fn days_from_civil_matches_known_dates() {
            assert_eq!(days_from_civil(1970, 1, 1), 0);
            assert_eq!(days_from_civil(2000, 3, 1), 11_017);
            assert_eq!(days_from_civil(2011, 9, 26), 15_243);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn calib_errors_name_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("calib.txt");
        std::fs::write(&p, "P0: 1 0 0 0 0 1 0 0 0 0 1 0\nP1: 1 2 3\n").unwrap();
        let e = read_odometry_calib(&p).unwrap_err().to_string();
        assert!(
            e.contains("calib.txt:2") && e.contains("expected 12 numbers"),
            "{e}"
        );
        std::fs::write(&p, "P1: 1 0 0 0 0 1 0 0 0 0 1 0\n").unwrap();
        assert!(
            read_odometry_calib(&p)
                .unwrap_err()
                .to_string()
                .contains("P0")
        );
        std::fs::write(&p, "P0: 1 0 0 0 0 1 x 0 0 0 1 0\n").unwrap();
        assert!(
            read_odometry_calib(&p)
                .unwrap_err()
                .to_string()
                .contains("'x' is not a number")
        );
        // a line without 'KEY:' (blank lines do not count), in both calibration layouts
        std::fs::write(&p, "\nP0: 1 0 0 0 0 1 0 0 0 0 1 0\n\nP1 1 0 0\n").unwrap();
        let e = read_odometry_calib(&p).unwrap_err().to_string();
        assert!(
            e.contains("calib.txt:4") && e.contains("KEY: 12 numbers"),
            "{e}"
        );
        let e = raw::read_raw_calib(&p).unwrap_err().to_string();
        assert!(
            e.contains("calib.txt:4") && e.contains("KEY: values"),
            "{e}"
        );
    }
}
