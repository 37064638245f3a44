//! The TUM monoVO benchmark layout (Engel, Usenko, Cremers, "A Photometrically Calibrated
//! Benchmark For Monocular Visual Odometry", 2016), as read by DSO:
//!
//! ```text
//! sequence_XX/
//!   images/00000.jpg …   frames (JPEG; PNG also accepted), named by the ids of times.txt
//!   times.txt            `id timestamp_s exposure_ms` a line
//!   camera.txt           the geometric calibration (below)
//!   pcalib.txt, vignette.png   photometric calibration: not used (a note is logged)
//! ```
//!
//! `images.zip` (the download's form) is not read: unzip it into `images/`. The ground truth of
//! the benchmark is not part of the layout and is not needed.
//!
//! `camera.txt` (DSO's format, `src/util/Undistort.cpp`), four lines:
//!
//! ```text
//! [FOV] fx fy cx cy omega             input camera: FOV / ATAN model ([`Distortion::Fov`])
//! in_width in_height                  raw image size, pixels
//! crop | full | none | fx fy cx cy 0  output (undistorted pinhole) camera
//! out_width out_height                output image size, pixels
//! ```
//!
//! The first line may instead be `Pinhole fx fy cx cy 0`, `RadTan fx fy cx cy k1 k2 p1 p2`,
//! `EquiDistant …` or `KannalaBrandt fx fy cx cy k1 k2 k3 k4`; without a prefix, 5 numbers are
//! the FOV model (a pinhole when `omega` is 0) and 8 numbers radtan. Intrinsics with `cx < 1` and
//! `cy < 1` are *relative* to the image size, with DSO's half-pixel shift:
//! `fx·w, fy·h, cx·w − 0.5, cy·h − 0.5` (the monoVO files use this form); larger values are
//! pixels. The output line:
//!
//! * `crop`: DSO's largest rectangle whose every pixel reads the raw image
//!   ([`cropped_pinhole`]);
//! * `full`: DSO leaves it unimplemented; visnav keeps the raw image's centre lines from border
//!   to border ([`full_axes_pinhole`]), so a barrel-distorted image loses only its corners;
//! * `none`: the input intrinsics as the output pinhole (same size required), the distortion
//!   removed;
//! * `fx fy cx cy 0`: an explicit pinhole, relative to the output size when `cx < 1` and `cy < 1`
//!   (DSO's convention), else in pixels.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use visnav_core::PinholeCamera;
use visnav_core::distortion::{CalibratedCamera, Distortion};
use visnav_core::rectify::{cropped_pinhole, full_axes_pinhole};

use crate::calibration::check_size;
use crate::calibration::{Rectifier, read_camera_file};
use crate::error::{IoError, Result};
use crate::image_io::load_gray;
use crate::lines::parse_data_lines;
use crate::sequence::{FrameFiles, Sequence, SequenceLayout};
use crate::trajectory::parse_numbers;

/// Extensions tried, in order, for the image of a `times.txt` id.
const FRAME_EXTENSIONS: [&str; 3] = ["jpg", "jpeg", "png"];

/// Whether `root` looks like a TUM monoVO sequence (`times.txt` and `camera.txt`).
#[must_use]
pub fn is_tum_mono(root: &Path) -> bool {
    crate::text::entry_exists(&root.join("times.txt"))
        && crate::text::entry_exists(&root.join("camera.txt"))
}

/// The output (undistorted pinhole) camera rule of a `camera.txt`, line 3.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OutputRule {
    /// DSO `crop`: the largest rectangle with only valid pixels.
    Crop,
    /// `full`: the raw centre lines from border to border (visnav's choice; module doc).
    Full,
    /// `none`: the input intrinsics, distortion removed.
    Keep,
    /// An explicit pinhole `fx fy cx cy` in pixels of the output image.
    Pinhole {
        /// Focal length along u, pixels.
        fx: f64,
        /// Focal length along v, pixels.
        fy: f64,
        /// Principal point u, pixels.
        cx: f64,
        /// Principal point v, pixels.
        cy: f64,
    },
}

/// A parsed `camera.txt`: the raw camera and how its output camera is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DsoCalibration {
    /// The raw (distorted) camera, intrinsics in pixels.
    pub input: CalibratedCamera,
    /// The output camera rule.
    pub output: OutputRule,
    /// Output image `(width, height)`, pixels.
    pub output_size: (u32, u32),
}

impl DsoCalibration {
    /// The output pinhole camera (module doc).
    ///
    /// # Errors
    /// [`IoError::Format`] naming `path` when no valid output camera exists for `crop` / `full`.
    pub fn output_camera(&self, path: &Path) -> Result<PinholeCamera> {
        let (w, h) = self.output_size;
        let bad = |e: visnav_core::camera::CameraError| IoError::Format {
            path: path.to_path_buf(),
            message: format!("output camera: {e}"),
        };
        match self.output {
            OutputRule::Crop => cropped_pinhole(&self.input, w, h).map_err(bad),
            OutputRule::Full => full_axes_pinhole(&self.input, w, h).map_err(bad),
            OutputRule::Keep => Ok(self.input.pinhole),
            OutputRule::Pinhole { fx, fy, cx, cy } => {
                PinholeCamera::new(fx, fy, cx, cy, w, h).map_err(bad)
            }
        }
    }
}

/// DSO's reading of intrinsics relative to the image size (module doc): `(fx, fy, cx, cy)` in
/// pixels.
fn absolute_intrinsics([fx, fy, cx, cy]: [f64; 4], (w, h): (u32, u32)) -> [f64; 4] {
    if cx < 1.0 && cy < 1.0 {
        let (w, h) = (f64::from(w), f64::from(h));
        [fx * w, fy * h, cx * w - 0.5, cy * h - 0.5]
    } else {
        [fx, fy, cx, cy]
    }
}

/// Parses a `width height` line.
fn size_line(text: &str, path: &Path, line: usize, what: &str) -> Result<(u32, u32)> {
    let err = || IoError::Parse {
        path: path.to_path_buf(),
        line,
        message: format!("expected the {what} 'width height' in pixels, found '{text}'"),
    };
    let mut it = text.split_whitespace().map(str::parse::<u32>);
    match (it.next(), it.next(), it.next()) {
        (Some(Ok(w)), Some(Ok(h)), None) if w > 0 && h > 0 => Ok((w, h)),
        _ => Err(err()),
    }
}

/// The input camera of line 1: the model and its parameters.
fn input_line(text: &str, path: &Path) -> Result<(Distortion, [f64; 4])> {
    let bad = |message: String| IoError::Parse {
        path: path.to_path_buf(),
        line: 1,
        message,
    };
    let first = text.split_whitespace().next().unwrap_or("");
    let (prefix, rest) = if first.parse::<f64>().is_ok() || first.is_empty() {
        (None, text)
    } else {
        (Some(first), &text[first.len()..])
    };
    let v = parse_numbers(rest, path, 1)?;
    let k = |v: &[f64]| [v[0], v[1], v[2], v[3]];
    let model = prefix.map(str::to_ascii_lowercase);
    let distortion = match (model.as_deref(), v.len()) {
        (Some("fov"), 5) | (None, 5) if v[4] != 0.0 || model.is_some() => {
            let omega = v[4];
            if !(0.0..std::f64::consts::PI).contains(&omega) {
                return Err(bad(format!(
                    "FOV: omega = {omega} must be in [0, π) radians"
                )));
            }
            Distortion::Fov { omega }
        }
        (None, 5) | (Some("pinhole"), 4 | 5) => Distortion::None,
        (Some("radtan"), 8) | (None, 8) => Distortion::RadialTangential {
            k1: v[4],
            k2: v[5],
            p1: v[6],
            p2: v[7],
            k3: 0.0,
        },
        (Some("equidistant" | "kannalabrandt"), 8) => Distortion::Equidistant {
            k1: v[4],
            k2: v[5],
            k3: v[6],
            k4: v[7],
        },
        (Some(m @ ("fov" | "pinhole" | "radtan" | "equidistant" | "kannalabrandt")), n) => {
            let want = match m {
                "fov" => "5 (fx fy cx cy omega)",
                "pinhole" => "5 (fx fy cx cy 0)",
                _ => "8 (fx fy cx cy and 4 distortion coefficients)",
            };
            return Err(bad(format!(
                "the {} model needs {want} numbers, found {n}",
                prefix.unwrap_or_default()
            )));
        }
        (Some(_), _) => {
            return Err(bad(format!(
                "unknown camera model '{}': expected FOV, Pinhole, RadTan, EquiDistant or KannalaBrandt",
                prefix.unwrap_or_default()
            )));
        }
        (None, n) => {
            return Err(bad(format!(
                "expected 'fx fy cx cy omega' (FOV model), 8 numbers (radtan) or a model prefix, found {n} numbers"
            )));
        }
    };
    Ok((distortion, k(&v)))
}

/// Reads a DSO / TUM monoVO `camera.txt` (module doc).
///
/// # Errors
/// A missing file, a missing or malformed line (named with its number), a non-positive focal
/// length, or `none` with an output size that differs from the input size.
pub fn read_dso_camera(path: &Path) -> Result<DsoCalibration> {
    let text = crate::text::read_text(path)?;
    let lines: Vec<&str> = text.lines().map(str::trim).collect();
    let line = |i: usize, what: &str| -> Result<&str> {
        lines
            .get(i - 1)
            .copied()
            .filter(|l| !l.is_empty())
            .ok_or_else(|| IoError::Parse {
                path: path.to_path_buf(),
                line: i,
                message: format!("missing line: expected {what}"),
            })
    };
    let (distortion, intrinsics) =
        input_line(line(1, "the input camera 'fx fy cx cy omega'")?, path)?;
    let input_size = size_line(line(2, "'in_width in_height'")?, path, 2, "input size")?;
    let [fx, fy, cx, cy] = absolute_intrinsics(intrinsics, input_size);
    let pinhole = PinholeCamera::new(fx, fy, cx, cy, input_size.0, input_size.1).map_err(|e| {
        IoError::Parse {
            path: path.to_path_buf(),
            line: 1,
            message: e.to_string(),
        }
    })?;
    let out_text = line(3, "crop, full, none or 'fx fy cx cy 0'")?;
    let output_size = size_line(line(4, "'out_width out_height'")?, path, 4, "output size")?;
    let output = match out_text {
        "crop" => OutputRule::Crop,
        "full" => OutputRule::Full,
        "none" => {
            if output_size != input_size {
                return Err(IoError::Parse {
                    path: path.to_path_buf(),
                    line: 4,
                    message: format!(
                        "'none' keeps the input camera: the output size {}x{} must equal the input size {}x{}",
                        output_size.0, output_size.1, input_size.0, input_size.1
                    ),
                });
            }
            OutputRule::Keep
        }
        other => {
            let bad = |message: String| IoError::Parse {
                path: path.to_path_buf(),
                line: 3,
                message,
            };
            let v = parse_numbers(other, path, 3).map_err(|_| {
                bad(format!(
                    "expected crop, full, none or 'fx fy cx cy 0', found '{other}'"
                ))
            })?;
            let [ofx, ofy, ocx, ocy, zero] = v[..] else {
                return Err(bad(format!(
                    "an explicit output camera is 'fx fy cx cy 0' (5 numbers), found {}",
                    v.len()
                )));
            };
            if zero != 0.0 {
                return Err(bad(format!(
                    "the output camera is a pinhole: the fifth number must be 0, found {zero}"
                )));
            }
            let [fx, fy, cx, cy] = absolute_intrinsics([ofx, ofy, ocx, ocy], output_size);
            if !(fx > 0.0 && fy > 0.0) {
                return Err(bad(format!(
                    "focal lengths fx={fx}, fy={fy} must be positive"
                )));
            }
            OutputRule::Pinhole { fx, fy, cx, cy }
        }
    };
    Ok(DsoCalibration {
        input: CalibratedCamera {
            pinhole,
            distortion,
        },
        output,
        output_size,
    })
}

/// One line of a monoVO `times.txt`.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTime {
    /// The frame id, the image's file stem (`00042`).
    pub id: String,
    /// Timestamp, seconds.
    pub timestamp_s: f64,
    /// Exposure time, milliseconds, when the line has one.
    pub exposure_ms: Option<f64>,
    /// Line number in `times.txt` (1-based), for messages.
    pub line: usize,
}

/// Reads a monoVO `times.txt`: `id timestamp_s [exposure_ms]` a line (`#` comments, blank lines
/// skipped).
///
/// # Errors
/// A missing file or a malformed line (named with its number).
pub fn read_frame_times(path: &Path) -> Result<Vec<FrameTime>> {
    parse_data_lines(path, |line| {
        let tokens: Vec<&str> = line.text.split_whitespace().collect();
        let (id, t, exposure) = match tokens[..] {
            [id, t] => (id, t, None),
            [id, t, e] => (id, t, Some(e)),
            _ => {
                return Err(line.error(format!(
                    "expected 'id timestamp exposure_ms', found '{}'",
                    line.text
                )));
            }
        };
        Ok(FrameTime {
            id: id.to_string(),
            timestamp_s: line.number(t, "a timestamp in seconds")?,
            exposure_ms: exposure
                .map(|e| line.number(e, "an exposure time in ms"))
                .transpose()?,
            line: line.number,
        })
    })
}

/// The image of frame `id` in `images` (`id.jpg`, `id.jpeg` or `id.png`).
fn frame_image(images: &Path, id: &str) -> Option<PathBuf> {
    FRAME_EXTENSIONS
        .iter()
        .map(|ext| images.join(format!("{id}.{ext}")))
        .find(|p| p.is_file())
}

/// Opens a TUM monoVO sequence (module doc). `camera` overrides `camera.txt`: another
/// `camera.txt`-style file (`.txt`) or a Kalibr-style camera file (`.yaml`/`.toml`).
pub(crate) fn open_tum_mono(root: &Path, camera: Option<&Path>) -> Result<Sequence> {
    let images = root.join("images");
    if !images.is_dir() {
        let zip = root.join("images.zip");
        if zip.is_file() {
            return Err(IoError::Format {
                path: zip,
                message: format!(
                    "zip archives are not read: unzip it into {} (e.g. `unzip images.zip -d images`) so that images/00000.jpg exists",
                    images.display()
                ),
            });
        }
        return Err(IoError::NotFound {
            path: images,
            what: "the images/ folder of this TUM monoVO sequence (times.txt + camera.txt found)"
                .into(),
        });
    }
    let times_path = root.join("times.txt");
    let times = read_frame_times(&times_path)?;
    if times.is_empty() {
        return Err(IoError::EmptySequence { path: times_path });
    }
    // every id must have its image; the line is named for the first that does not
    let mut left = Vec::with_capacity(times.len());
    for t in &times {
        let Some(p) = frame_image(&images, &t.id) else {
            return Err(IoError::Parse {
                path: times_path,
                line: t.line,
                message: format!(
                    "no image for frame id '{}' in {} (looked for {})",
                    t.id,
                    images.display(),
                    FRAME_EXTENSIONS.map(|e| format!("{}.{e}", t.id)).join(", ")
                ),
            });
        };
        left.push(p);
    }
    if ["pcalib.txt", "vignette.png"]
        .iter()
        .any(|f| root.join(f).is_file())
    {
        log::info!(
            "{}: the photometric calibration (pcalib.txt, vignette.png) and exposure times are not used",
            root.display()
        );
    }
    let calib_path = camera.map_or_else(|| root.join("camera.txt"), Path::to_path_buf);
    let is_txt = calib_path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("txt"));
    let (raw_camera, rectifier): (CalibratedCamera, Arc<Rectifier>) = if is_txt {
        let dso = read_dso_camera(&calib_path)?;
        let output = dso.output_camera(&calib_path)?;
        (dso.input, Rectifier::undistort_to(&dso.input, output))
    } else {
        let calib = read_camera_file(&calib_path)?;
        let rectifier = Rectifier::new(&calib, false, &calib_path)?;
        (calib.left, rectifier)
    };
    let first = load_gray(&left[0])?;
    let raw_size = (first.width(), first.height());
    check_size(&left[0], raw_size, &raw_camera, &calib_path)?;
    let timestamps = times.iter().map(|t| t.timestamp_s).collect();
    Ok(Sequence::with_rectifier(
        root,
        SequenceLayout::TumMono,
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

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<DsoCalibration> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("camera.txt");
        std::fs::write(&p, text).unwrap();
        read_dso_camera(&p)
    }

    #[test]
    fn monovo_camera_txt_is_relative_fov() {
        // sequence_01 of the benchmark
        let c = parse("0.349153000000000\t0.436593000000000\t0.493140000000000\t0.499021000000000\t0.933271000000000\n1280 1024\ncrop\n640 480\n").unwrap();
        assert_eq!(c.input.distortion, Distortion::Fov { omega: 0.933_271 });
        let p = c.input.pinhole;
        assert!((p.fx - 0.349_153 * 1280.0).abs() < 1e-9);
        assert!((p.cy - (0.499_021 * 1024.0 - 0.5)).abs() < 1e-9);
        assert_eq!((p.width, p.height), (1280, 1024));
        assert_eq!(c.output, OutputRule::Crop);
        assert_eq!(c.output_size, (640, 480));
        let out = c.output_camera(Path::new("camera.txt")).unwrap();
        assert_eq!((out.width, out.height), (640, 480));
        // the lens sees about ±75° along the horizontal centre line: a wide pinhole
        assert!(out.fx > 50.0 && out.fx < 200.0, "{out:?}");
        assert!(out.fy > 50.0 && out.fy < 200.0, "{out:?}");
    }

    #[test]
    fn prefixes_absolute_values_and_explicit_outputs() {
        let c = parse("FOV 447.0 447.0 639.5 511.5 0.9\n1280 1024\n0.5 0.6 0.5 0.5 0\n640 480\n")
            .unwrap();
        assert!((c.input.pinhole.fx - 447.0).abs() < 1e-12);
        assert_eq!(
            c.output,
            OutputRule::Pinhole {
                fx: 320.0,
                fy: 288.0,
                cx: 319.5,
                cy: 239.5
            }
        );
        let c = parse("Pinhole 300 300 159.5 119.5 0\n320 240\nnone\n320 240\n").unwrap();
        assert_eq!(c.input.distortion, Distortion::None);
        assert_eq!(c.output_camera(Path::new("c")).unwrap(), c.input.pinhole);
        // 5 numbers with omega = 0 are a pinhole; 8 numbers radtan
        let c = parse("300 300 159.5 119.5 0\n320 240\n200 200 159.5 119.5 0\n320 240\n").unwrap();
        assert_eq!(c.input.distortion, Distortion::None);
        assert!(matches!(c.output, OutputRule::Pinhole { fx, .. } if fx == 200.0));
        let c = parse("300 300 159.5 119.5 -0.2 0.05 0.001 0.0\n320 240\nfull\n320 240\n").unwrap();
        assert!(
            matches!(c.input.distortion, Distortion::RadialTangential { k1, .. } if k1 == -0.2)
        );
        let c = parse("KannalaBrandt 300 300 159.5 119.5 0.01 0 0 0\n320 240\ncrop\n300 200\n")
            .unwrap();
        assert!(matches!(c.input.distortion, Distortion::Equidistant { k1, .. } if k1 == 0.01));
    }

    #[test]
    fn malformed_camera_txt_names_file_and_line() {
        for (text, what) in [
            (
                "0.35 0.44 0.49\n1280 1024\ncrop\n640 480\n",
                "camera.txt:1: expected 'fx fy cx cy omega'",
            ),
            (
                "FOV 0.35 0.44 0.49 0.5\n1280 1024\ncrop\n640 480\n",
                "camera.txt:1: the FOV model needs 5",
            ),
            (
                "Ortho 1 1 0.5 0.5 0\n1280 1024\ncrop\n640 480\n",
                "camera.txt:1: unknown camera model 'Ortho'",
            ),
            (
                "0.35 0.44 0.49 0.5 x\n1280 1024\ncrop\n640 480\n",
                "camera.txt:1: 'x' is not a finite number",
            ),
            (
                "0.35 0.44 0.49 0.5 7.0\n1280 1024\ncrop\n640 480\n",
                "camera.txt:1: FOV: omega",
            ),
            (
                "0.35 0.44 0.49 0.5 0.9\n1280\ncrop\n640 480\n",
                "camera.txt:2: expected the input size",
            ),
            (
                "0.35 0.44 0.49 0.5 0.9\n1280 1024\ncropped\n640 480\n",
                "camera.txt:3: expected crop, full, none",
            ),
            (
                "0.35 0.44 0.49 0.5 0.9\n1280 1024\n0.5 0.5 0.5 0.5 1\n640 480\n",
                "camera.txt:3: the output camera is a pinhole",
            ),
            (
                "0.35 0.44 0.49 0.5 0.9\n1280 1024\ncrop\n",
                "camera.txt:4: missing line",
            ),
            (
                "0.35 0.44 0.49 0.5 0.9\n1280 1024\nnone\n640 480\n",
                "camera.txt:4: 'none' keeps the input camera",
            ),
            (
                "-0.35 0.44 0.49 0.5 0.9\n1280 1024\ncrop\n640 480\n",
                "camera.txt:1: invalid focal length",
            ),
        ] {
            let e = parse(text).unwrap_err().to_string();
            assert!(e.contains(what), "{what}: {e}");
        }
    }

    #[test]
    fn times_txt_lines() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("times.txt");
        std::fs::write(&p, "00000 1383315339.1207 15.3\n\n00001 1383315339.1548\n").unwrap();
        let t = read_frame_times(&p).unwrap();
        assert_eq!(t.len(), 2);
        assert_eq!(t[0].id, "00000");
        assert_eq!(t[0].exposure_ms, Some(15.3));
        assert_eq!(t[1].exposure_ms, None);
        assert!((t[1].timestamp_s - 1_383_315_339.154_8).abs() < 1e-6);
        std::fs::write(&p, "00000 1.0 15.3\n00001 one 15.3\n").unwrap();
        let e = read_frame_times(&p).unwrap_err().to_string();
        assert!(e.contains("times.txt:2") && e.contains("'one'"), "{e}");
    }
}
