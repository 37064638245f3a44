//! Calibrated layouts opened as a [`Sequence`] that undistorts / rectifies on load:
//!
//! * EuRoC MAV (ASL): `[SEQ/]mav0/cam0|cam1/data.csv` (`#timestamp [ns],filename`),
//!   `data/*.png`, `sensor.yaml` (intrinsics, distortion, `T_BS` = `body_from_cam`). The stereo
//!   pair is rectified (Bouguet, alpha = 0); frames of the two cameras are paired by timestamp.
//!   Timestamps in seconds (`ns · 1e-9`), kept for a TUM-format output.
//! * TUM RGB-D: `rgb.txt` (`timestamp rgb/NAME.png`, `#` comments) + a camera file; the colour
//!   images are read as gray and undistorted.
//! * (TUM monoVO, `times.txt` + `camera.txt` + `images/`, is its own peer, [`crate::tum_mono`].)
//! * A folder of PNG or JPEG images (name order) + a camera file, or `left/` + `right/` sub-folders
//!   with a stereo camera file. Timestamps from the camera file's `rate_hz` (default 10 Hz).
//!
//! The camera file is `--camera FILE`, or `camera.yaml` / `camera.yml` / `camera.toml` in the
//! folder (see [`crate::calibration`]).

use std::path::{Path, PathBuf};

use visnav_core::Pose;

use crate::calibration::{
    Rectifier, RigCalibration, check_size, read_camera_file, read_euroc_sensor,
};
use crate::error::{IoError, Result};
use crate::image_io::{list_images, load_gray};
use crate::lines::parse_data_lines;
use crate::sequence::{FrameFiles, Sequence, SequenceLayout};

/// Largest timestamp difference of a left and a right EuRoC frame paired as one stereo frame, s.
const STEREO_PAIR_MAX_DT_S: f64 = 1e-3;
pub use crate::calibration::DEFAULT_RATE_HZ;

/// The `mav0` directory of an EuRoC sequence given as `SEQ/` or `SEQ/mav0/`, when `root` is one.
pub(crate) fn euroc_root(root: &Path) -> Option<PathBuf> {
    [root.join("mav0"), root.to_path_buf()]
        .into_iter()
        .find(|m| crate::text::entry_exists(&m.join("cam0").join("data.csv")))
}

/// Whether `root` is a TUM RGB-D folder (`rgb.txt`).
pub(crate) fn is_tum_rgbd(root: &Path) -> bool {
    crate::text::entry_exists(&root.join("rgb.txt"))
}

/// The camera file given, or one found in `dir` (a `camera.yaml` link that does not resolve is
/// found, so that reading it names the loop or the dangling link).
fn camera_file(dir: &Path, camera: Option<&Path>) -> Option<PathBuf> {
    camera.map(Path::to_path_buf).or_else(|| {
        ["camera.yaml", "camera.yml", "camera.toml"]
            .into_iter()
            .map(|n| dir.join(n))
            .find(|p| crate::text::entry_exists(p))
    })
}

/// The raw size of the first image of each camera, checked against the calibration.
/// `calib_paths`: the files of the left and the right calibration (the same for camera files).
fn checked_raw_size(
    calib: &RigCalibration,
    calib_paths: [&Path; 2],
    left: &[PathBuf],
    right: Option<&[PathBuf]>,
) -> Result<(usize, usize)> {
    let first = load_gray(&left[0])?;
    let size = (first.width(), first.height());
    check_size(&left[0], size, &calib.left, calib_paths[0])?;
    if let (Some(r), Some((right_cam, _))) = (right, &calib.right) {
        let img = load_gray(&r[0])?;
        check_size(
            &r[0],
            (img.width(), img.height()),
            right_cam,
            calib_paths[1],
        )?;
    }
    Ok(size)
}

/// `#timestamp [ns],filename` lines of an EuRoC `data.csv`: `(seconds, path)`.
///
/// # Errors
/// A missing file or a malformed line (named with its line number).
pub fn read_euroc_csv(path: &Path) -> Result<Vec<(f64, PathBuf)>> {
    Ok(read_euroc_rows(path)?
        .into_iter()
        .map(|r| (r.t_ns as f64 * 1e-9, r.path))
        .collect())
}

/// One row of an EuRoC `data.csv`.
#[derive(Debug, Clone)]
struct EurocRow {
    /// Timestamp, nanoseconds.
    t_ns: u64,
    /// The image, `data/<filename>` next to the file.
    path: PathBuf,
    /// 1-based line in the file.
    line: usize,
}

/// The rows of an EuRoC `data.csv` with their lines: exactly two fields, a timestamp in ns and a
/// non-empty file name.
fn read_euroc_rows(path: &Path) -> Result<Vec<EurocRow>> {
    let data_dir = path.with_file_name("data");
    parse_data_lines(path, |line| {
        let fields: Vec<&str> = line.text.split(',').map(str::trim).collect();
        let [t, name] = fields[..] else {
            return Err(line.error(format!(
                "expected 2 fields 'timestamp_ns,filename', found {} in '{}'",
                fields.len(),
                line.text
            )));
        };
        let t_ns: u64 = t
            .parse()
            .map_err(|_| line.error(format!("'{t}' is not a timestamp in ns")))?;
        if name.is_empty() {
            return Err(line.error("the file name after the timestamp is empty".into()));
        }
        Ok(EurocRow {
            t_ns,
            path: data_dir.join(name),
            line: line.number,
        })
    })
}

/// The frames of an EuRoC `data.csv` sorted by timestamp (rows out of order are sorted, with a
/// warning), as `(seconds, path)`; two rows with one timestamp are an error naming both lines.
fn in_time_order(mut rows: Vec<EurocRow>, csv: &Path) -> Result<Vec<(f64, PathBuf)>> {
    if rows.windows(2).any(|w| w[1].t_ns < w[0].t_ns) {
        log::warn!(
            "{}: rows are not in time order; frames are taken in timestamp order",
            csv.display()
        );
        // stable: rows with one timestamp stay in file order
        rows.sort_by_key(|r| r.t_ns);
    }
    if let Some(w) = rows.windows(2).find(|w| w[1].t_ns == w[0].t_ns) {
        let (first, second) = if w[0].line < w[1].line {
            (&w[0], &w[1])
        } else {
            (&w[1], &w[0])
        };
        return Err(IoError::Parse {
            path: csv.to_path_buf(),
            line: second.line,
            message: format!(
                "the timestamp {} ns of line {} again ({} and {})",
                second.t_ns,
                first.line,
                first.path.display(),
                second.path.display()
            ),
        });
    }
    Ok(rows
        .into_iter()
        .map(|r| (r.t_ns as f64 * 1e-9, r.path))
        .collect())
}

/// Pairs every left frame with the right frame nearest in time (within
/// [`STEREO_PAIR_MAX_DT_S`]); both lists in time order. A left frame without a right row keeps
/// its place (one pose per left frame, always): it is paired with the right image of the same
/// name in `cam1/data/` (EuRoC names images by their timestamp), and when that file does not
/// exist either, loading the frame's right image is an error naming it, which the odometry turns
/// into a skipped frame with a constant-velocity pose. Both cases are warned about; right frames
/// without a left one are ignored with a warning.
fn pair_stereo(
    left: &[(f64, PathBuf)],
    right: &[(f64, PathBuf)],
    cam1_csv: &Path,
) -> Result<(Vec<f64>, Vec<PathBuf>, Vec<PathBuf>)> {
    let mut t = Vec::with_capacity(left.len());
    let mut l = Vec::with_capacity(left.len());
    let mut r = Vec::with_capacity(left.len());
    let mut j = 0;
    for (tl, pl) in left {
        while j < right.len() && right[j].0 < tl - STEREO_PAIR_MAX_DT_S {
            j += 1;
        }
        // the nearest of the (at most two) right frames within the window
        let nearest = (j..right.len().min(j + 2))
            .filter(|&k| (right[k].0 - tl).abs() <= STEREO_PAIR_MAX_DT_S)
            .min_by(|&a, &b| (right[a].0 - tl).abs().total_cmp(&(right[b].0 - tl).abs()));
        let Some(k) = nearest else {
            let same_name = cam1_csv
                .with_file_name("data")
                .join(pl.file_name().unwrap_or_default());
            log::warn!(
                "{}: no right frame within 1 ms of the left frame {} ({tl:.9} s); using {}{}",
                cam1_csv.display(),
                pl.display(),
                same_name.display(),
                if same_name.is_file() {
                    ""
                } else {
                    ", which does not exist: the frame will be skipped"
                }
            );
            t.push(*tl);
            l.push(pl.clone());
            r.push(same_name);
            continue;
        };
        t.push(*tl);
        l.push(pl.clone());
        r.push(right[k].1.clone());
        j = k + 1;
    }
    if right.len() > left.len() {
        log::warn!(
            "{}: {} right frames have no left frame within 1 ms and are not used",
            cam1_csv.display(),
            right.len() - left.len()
        );
    }
    Ok((t, l, r))
}

pub(crate) fn open_euroc(root: &Path, mav0: &Path, camera: Option<&Path>) -> Result<Sequence> {
    let cam0_csv = mav0.join("cam0").join("data.csv");
    let cam1_csv = mav0.join("cam1").join("data.csv");
    let left_frames = read_euroc_rows(&cam0_csv)?;
    if left_frames.is_empty() {
        return Err(IoError::EmptySequence { path: cam0_csv });
    }
    let right_frames = if cam1_csv.is_file() {
        Some(read_euroc_rows(&cam1_csv)?)
    } else {
        None
    };
    let sensor1 = mav0.join("cam1").join("sensor.yaml");
    let (calib, calib_path, right_calib_path, body_from_cam0) = match camera {
        Some(c) => (read_camera_file(c)?, c.to_path_buf(), c.to_path_buf(), None),
        None => {
            let s0 = mav0.join("cam0").join("sensor.yaml");
            let (cam0, body_from_cam0) = read_euroc_sensor(&s0)?;
            let right = if right_frames.is_some() {
                let (cam1, body_from_cam1) = read_euroc_sensor(&sensor1)?;
                let cam1_from_cam0 = body_from_cam1.inverse() * body_from_cam0;
                crate::baseline::warn_if_implausible(
                    &sensor1,
                    "T_BS (with cam0's: the stereo baseline)",
                    cam1_from_cam0.translation.vector.norm(),
                    &cam0.pinhole,
                );
                Some((cam1, cam1_from_cam0))
            } else {
                None
            };
            let calib = RigCalibration {
                left: cam0,
                right,
                rate_hz: None,
            };
            (calib, s0, sensor1.clone(), Some(body_from_cam0))
        }
    };
    let left_frames = in_time_order(left_frames, &cam0_csv)?;
    let (timestamps, left, right) = match right_frames {
        Some(rf) if calib.right.is_some() => {
            let rf = in_time_order(rf, &cam1_csv)?;
            let (t, l, r) = pair_stereo(&left_frames, &rf, &cam1_csv)?;
            (t, l, Some(r))
        }
        _ => {
            let (t, l): (Vec<f64>, Vec<PathBuf>) = left_frames.into_iter().unzip();
            (t, l, None)
        }
    };
    let raw_size = checked_raw_size(
        &calib,
        [&calib_path, &right_calib_path],
        &left,
        right.as_deref(),
    )?;
    let rectifier = Rectifier::new(&calib, right.is_some(), &calib_path)?;
    let cam0_from_rect = Pose::from_parts(
        nalgebra::Translation3::identity(),
        nalgebra::UnitQuaternion::from_rotation_matrix(&rectifier.left_rect_from_cam.inverse()),
    );
    let mut seq = Sequence::with_rectifier(
        root,
        SequenceLayout::Euroc,
        rectifier,
        raw_size,
        FrameFiles {
            timestamps,
            timestamped: true,
            left,
            right,
        },
        None,
    );
    seq.body_from_cam = body_from_cam0.map(|b| b * cam0_from_rect);
    Ok(seq)
}

/// `timestamp filename` lines of a TUM `rgb.txt` (`#` comments): `(seconds, path)`.
///
/// # Errors
/// A missing file or a malformed line.
pub fn read_tum_list(path: &Path) -> Result<Vec<(f64, PathBuf)>> {
    let dir = path.parent().unwrap_or(Path::new("."));
    parse_data_lines(path, |line| {
        let mut it = line.text.split_whitespace();
        let (Some(t), Some(name)) = (it.next(), it.next()) else {
            return Err(line.error(format!(
                "expected 'timestamp filename', found '{}'",
                line.text
            )));
        };
        let t = line.number(t, "a timestamp in seconds")?;
        Ok((t, dir.join(name)))
    })
}

pub(crate) fn open_tum(root: &Path, camera: Option<&Path>) -> Result<Sequence> {
    let list = root.join("rgb.txt");
    let Some(calib_path) = camera_file(root, camera) else {
        return Err(IoError::NotFound {
            path: root.to_path_buf(),
            what: "a camera file for this TUM sequence: pass --camera FILE or put camera.yaml in the folder".into(),
        });
    };
    let calib = read_camera_file(&calib_path)?;
    let frames = read_tum_list(&list)?;
    if frames.is_empty() {
        return Err(IoError::EmptySequence { path: list });
    }
    let (timestamps, left): (Vec<f64>, Vec<PathBuf>) = frames.into_iter().unzip();
    let raw_size = checked_raw_size(&calib, [&calib_path; 2], &left, None)?;
    let rectifier = Rectifier::new(&calib, false, &calib_path)?;
    Ok(Sequence::with_rectifier(
        root,
        SequenceLayout::TumRgbd,
        rectifier,
        raw_size,
        FrameFiles {
            timestamps,
            timestamped: true,
            left,
            right: None,
        },
        None,
    ))
}

pub(crate) fn open_folder(root: &Path, camera: Option<&Path>) -> Result<Sequence> {
    let stereo_dirs = root.join("left").is_dir() && root.join("right").is_dir();
    let (left, right) = if stereo_dirs {
        let l = list_images(&root.join("left"))?;
        let r = list_images(&root.join("right"))?;
        if l.len() != r.len() {
            return Err(IoError::Format {
                path: root.join("right"),
                message: format!("{} right images but {} left images", r.len(), l.len()),
            });
        }
        (l, Some(r))
    } else {
        (list_images(root)?, None)
    };
    if left.is_empty() {
        return Err(IoError::NotFound {
            path: root.to_path_buf(),
            what: "a sequence: expected a KITTI sequence (image_0/ + calib.txt, or a raw drive with image_00/data/), an EuRoC sequence (mav0/cam0/data.csv), a TUM RGB-D folder (rgb.txt), a TUM monoVO sequence (times.txt + camera.txt + images/), or a folder of PNG/JPEG images (or left/ + right/) with a camera file".into(),
        });
    }
    let Some(calib_path) = camera_file(root, camera) else {
        return Err(IoError::NotFound {
            path: root.to_path_buf(),
            what: "a camera file for this image folder: pass --camera FILE or put camera.yaml in the folder".into(),
        });
    };
    let calib = read_camera_file(&calib_path)?;
    let right = right.filter(|_| calib.right.is_some());
    let raw_size = checked_raw_size(&calib, [&calib_path; 2], &left, right.as_deref())?;
    let rectifier = Rectifier::new(&calib, right.is_some(), &calib_path)?;
    let rate_hz = calib.rate_hz.unwrap_or(DEFAULT_RATE_HZ);
    let timestamps = (0..left.len()).map(|i| i as f64 / rate_hz).collect();
    Ok(Sequence::with_rectifier(
        root,
        SequenceLayout::ImageFolder,
        rectifier,
        raw_size,
        FrameFiles {
            timestamps,
            timestamped: false,
            left,
            right,
        },
        None,
    ))
}
