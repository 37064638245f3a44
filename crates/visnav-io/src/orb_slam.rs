//! ORB-SLAM2 / ORB-SLAM3 settings files (OpenCV `FileStorage` YAML, `%YAML:1.0`) read as camera
//! files: the camera files many users already have. What is read (every other key, e.g.
//! `ORBextractor.*`, `Viewer.*`, `IMU.*`, is ignored; an unknown key of the camera's own
//! namespaces `Camera.`, `Camera1.`, `Camera2.`, `Stereo.`, `LEFT.`, `RIGHT.` is an error, as an
//! unknown field of a Kalibr file is):
//!
//! * `Camera.type`: `"PinHole"` (the default; radial–tangential `k1 k2 p1 p2 [k3]`),
//!   `"KannalaBrandt8"` (equidistant fisheye, `k1 k2 k3 k4`) or `"Rectified"` (no distortion);
//! * the (left) camera: ORB-SLAM3's `Camera1.fx fy cx cy [k1 k2 p1 p2 k3 | k1..k4]` or
//!   ORB-SLAM2's `Camera.fx …`, and `Camera.width`, `Camera.height` (pixels, required),
//!   `Camera.fps` (the frame rate of folders without timestamps);
//! * the stereo pair, the first of:
//!   - ORB-SLAM2's pre-rectification `LEFT.K/D/R/P` + `RIGHT.K/D/R/P` (raw images: the raw
//!     cameras are `K`, `D`; `right_from_left = RIGHT.Rᵀ · [I | (−b, 0, 0)] · LEFT.R` with
//!     `b = −RIGHT.P[0][3] / RIGHT.P[0][0]`);
//!   - ORB-SLAM3's `Camera2.*` with `Stereo.T_c1_c2` (`cam1_from_cam2` = `left_from_right`, an
//!     `!!opencv-matrix` 4x4, metres);
//!   - ORB-SLAM3's `Stereo.b` (a rectified pair: baseline, metres);
//!   - ORB-SLAM2's `Camera.bf` (a rectified pair: baseline × fx, so `b = bf / fx`).
//!
//! A rectified pair (`Stereo.b`, `Camera.bf`) has the left camera for its right one and
//! `right_from_left` = translation `(−b, 0, 0)`. The cameras get the checks of a Kalibr file
//! (intrinsics, coefficients, a rotation block that is a rotation, a positive baseline).

use std::path::Path;

use nalgebra::{Translation3, UnitQuaternion, Vector3};
use serde_json::{Map, Value};
use visnav_core::Pose;
use visnav_core::distortion::CalibratedCamera;

use crate::camera_model::{DistortionModel, RigCalibration, camera_from_parts, rigid_pose};
use crate::error::{IoError, Result};

/// The key namespaces of the camera in a settings file: their keys are checked.
const NAMESPACES: [&str; 6] = [
    "Camera.", "Camera1.", "Camera2.", "Stereo.", "LEFT.", "RIGHT.",
];

/// The keys of a camera's own namespace (`Camera1.`, `Camera2.`; ORB-SLAM2's `Camera.`).
const CAMERA_KEYS: [&str; 9] = ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"];

/// Further keys read or knowingly ignored (ignored: colour order, ORB-SLAM3's own resizing of
/// the images, the close/far depth threshold, the rectification's float copy, the columns two
/// fisheye images share).
const OTHER_KEYS: [&str; 33] = [
    "Camera.overlappingBegin",
    "Camera.overlappingEnd",
    "Camera1.overlappingBegin",
    "Camera1.overlappingEnd",
    "Camera2.overlappingBegin",
    "Camera2.overlappingEnd",
    "Camera.type",
    "Camera.width",
    "Camera.height",
    "Camera.fps",
    "Camera.bf",
    "Camera.bFishEye",
    "Camera.RGB",
    "Camera.newWidth",
    "Camera.newHeight",
    "Camera.imageScale",
    "Camera.k4",
    "Camera1.k4",
    "Camera2.k4",
    "Stereo.b",
    "Stereo.T_c1_c2",
    "Stereo.ThDepth",
    "LEFT.width",
    "LEFT.height",
    "LEFT.K",
    "LEFT.D",
    "LEFT.R",
    "LEFT.P",
    "LEFT.Rf",
    "RIGHT.K",
    "RIGHT.D",
    "RIGHT.R",
    "RIGHT.P",
];

/// `RIGHT.` keys beside the ones in [`OTHER_KEYS`].
const RIGHT_EXTRA: [&str; 3] = ["RIGHT.width", "RIGHT.height", "RIGHT.Rf"];

/// Whether a parsed YAML file is an ORB-SLAM / OpenCV settings file (a key of the camera
/// namespaces at the top level).
#[must_use]
pub fn is_settings_file(value: &Value) -> bool {
    value.as_object().is_some_and(|m| {
        m.keys()
            .any(|k| NAMESPACES.iter().any(|n| k.starts_with(n)))
    })
}

/// The settings file's keys and text, for lookups whose errors name the line.
struct Settings<'a> {
    map: &'a Map<String, Value>,
    text: &'a str,
    path: &'a Path,
}

impl Settings<'_> {
    /// An error about `key`, at its line when the text has one.
    fn err(&self, key: &str, message: impl std::fmt::Display) -> IoError {
        let line = self.text.lines().position(|l| {
            l.trim_start()
                .strip_prefix(key)
                .is_some_and(|r| r.trim_start().starts_with(':'))
        });
        match line {
            Some(i) => IoError::Parse {
                path: self.path.to_path_buf(),
                line: i + 1,
                message: format!("{key}: {message}"),
            },
            None => IoError::Format {
                path: self.path.to_path_buf(),
                message: format!("{key}: {message}"),
            },
        }
    }

    fn has(&self, key: &str) -> bool {
        self.map.contains_key(key)
    }

    /// A finite number, `None` when the key is absent.
    fn number(&self, key: &str) -> Result<Option<f64>> {
        match self.map.get(key) {
            None => Ok(None),
            Some(Value::Number(n)) => match n.as_f64() {
                Some(v) if v.is_finite() => Ok(Some(v)),
                _ => Err(self.err(key, format!("{n} is not a finite number"))),
            },
            Some(other) => Err(self.err(key, format!("expected a number, found {other}"))),
        }
    }

    fn required(&self, key: &str, what: &str) -> Result<f64> {
        self.number(key)?
            .ok_or_else(|| self.err(key, format!("missing ({what})")))
    }

    /// A positive whole number of pixels.
    fn pixels(&self, key: &str) -> Result<Option<u32>> {
        let Some(v) = self.number(key)? else {
            return Ok(None);
        };
        if v.fract() != 0.0 || v < 1.0 || v > f64::from(u32::MAX) {
            return Err(self.err(key, format!("{v} is not a positive whole number of pixels")));
        }
        Ok(Some(v as u32))
    }

    fn string(&self, key: &str) -> Result<Option<&str>> {
        match self.map.get(key) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s)),
            Some(other) => Err(self.err(key, format!("expected a string, found {other}"))),
        }
    }

    /// An `!!opencv-matrix` (`rows`, `cols`, `data`), checked to be `rows x cols` of finite
    /// numbers; `None` when the key is absent.
    fn matrix(&self, key: &str) -> Result<Option<(usize, usize, Vec<f64>)>> {
        let Some(v) = self.map.get(key) else {
            return Ok(None);
        };
        let bad = |m: String| self.err(key, m);
        let Some(m) = v.as_object() else {
            return Err(bad("expected an !!opencv-matrix (rows, cols, data)".into()));
        };
        let dim = |k: &str| {
            m.get(k)
                .and_then(Value::as_u64)
                .and_then(|d| usize::try_from(d).ok())
                .filter(|d| (1..=16).contains(d))
                .ok_or_else(|| bad(format!("'{k}' must be a whole number from 1 to 16")))
        };
        let (rows, cols) = (dim("rows")?, dim("cols")?);
        let data: Vec<f64> = match m.get("data").and_then(Value::as_array) {
            Some(d) => d
                .iter()
                .map(|x| x.as_f64().filter(|x| x.is_finite()))
                .collect::<Option<_>>()
                .ok_or_else(|| bad("'data' must hold finite numbers".into()))?,
            None => return Err(bad("'data: [...]' is missing".into())),
        };
        if data.len() != rows * cols {
            return Err(bad(format!(
                "{rows}x{cols} needs {} numbers in 'data', found {}",
                rows * cols,
                data.len()
            )));
        }
        Ok(Some((rows, cols, data)))
    }

    /// A matrix of the given shape (a vector may be a row or a column).
    fn shaped(&self, key: &str, shapes: &[(usize, usize)]) -> Result<Vec<f64>> {
        let (rows, cols, data) = self.matrix(key)?.ok_or_else(|| self.err(key, "missing"))?;
        if !shapes.contains(&(rows, cols)) {
            let want: Vec<String> = shapes.iter().map(|(r, c)| format!("{r}x{c}")).collect();
            return Err(self.err(
                key,
                format!(
                    "expected a {} matrix, found {rows}x{cols}",
                    want.join(" or ")
                ),
            ));
        }
        Ok(data)
    }

    /// An unknown key of the camera namespaces.
    fn check_keys(&self) -> Result<()> {
        for key in self.map.keys() {
            let Some(ns) = NAMESPACES.iter().find(|n| key.starts_with(*n)) else {
                continue;
            };
            let own = ["Camera.", "Camera1.", "Camera2."].contains(ns)
                && CAMERA_KEYS.contains(&&key[ns.len()..]);
            if !own && !OTHER_KEYS.contains(&key.as_str()) && !RIGHT_EXTRA.contains(&key.as_str()) {
                return Err(self.err(
                    key,
                    "unknown key of an ORB-SLAM camera (known: Camera.type, Camera1.fx fy cx cy k1 k2 p1 p2 k3 k4 or Camera.fx …, Camera.width, Camera.height, Camera.fps, Camera.bf, Camera2.*, Stereo.b, Stereo.T_c1_c2, LEFT.* and RIGHT.* K D R P)",
                ));
            }
        }
        Ok(())
    }
}

/// The right camera and `right_from_left` (metres).
type StereoPair = (CalibratedCamera, Pose);

/// `Camera.type`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum CameraType {
    PinHole,
    KannalaBrandt8,
    Rectified,
}

/// Reads an ORB-SLAM / OpenCV settings file (already parsed from `text`) into a rig; with the
/// field that gave the stereo baseline, for the checks of [`crate::baseline`].
///
/// # Errors
/// A missing or malformed value, an unknown key of the camera namespaces, an unsupported
/// `Camera.type`: the file, the line of the key and the problem.
pub fn read_settings(
    value: &Value,
    text: &str,
    path: &Path,
) -> Result<(RigCalibration, Option<&'static str>)> {
    let empty = Map::new();
    let s = Settings {
        map: value.as_object().unwrap_or(&empty),
        text,
        path,
    };
    s.check_keys()?;
    let kind = match s.string("Camera.type")? {
        None | Some("PinHole") => CameraType::PinHole,
        Some("KannalaBrandt8") => CameraType::KannalaBrandt8,
        Some("Rectified") => CameraType::Rectified,
        Some(other) => {
            return Err(s.err(
                "Camera.type",
                format!("\"{other}\" is not supported (\"PinHole\", \"KannalaBrandt8\" or \"Rectified\")"),
            ));
        }
    };
    if s.number("Camera.bFishEye")?.is_some_and(|f| f != 0.0) {
        return Err(s.err(
            "Camera.bFishEye",
            "a fisheye flag is not supported: give Camera.type: \"KannalaBrandt8\" with Camera1.k1 … k4",
        ));
    }
    let rate_hz = match s.number("Camera.fps")? {
        Some(r) if r <= 0.0 => {
            return Err(s.err(
                "Camera.fps",
                format!("{r} must be positive (frames a second)"),
            ));
        }
        r => r,
    };
    let size = resolution(&s)?;
    let first = if s.has("Camera1.fx") {
        "Camera1."
    } else {
        "Camera."
    };
    let (rig, field) = if s.has("LEFT.K") || s.has("RIGHT.K") {
        let (left, right) = pre_rectification(&s, size)?;
        ((left, Some(right)), Some("RIGHT.P"))
    } else {
        let left = camera(&s, first, kind, size)?;
        let (right, field) = right_camera(&s, kind, &left, size)?;
        ((left, right), field)
    };
    Ok((
        RigCalibration {
            left: rig.0,
            right: rig.1,
            rate_hz,
        },
        field,
    ))
}

/// `Camera.width`, `Camera.height` (or `LEFT.width`, `LEFT.height`).
fn resolution(s: &Settings<'_>) -> Result<[u32; 2]> {
    let w = match s.pixels("Camera.width")? {
        Some(w) => Some(w),
        None => s.pixels("LEFT.width")?,
    };
    let h = match s.pixels("Camera.height")? {
        Some(h) => Some(h),
        None => s.pixels("LEFT.height")?,
    };
    match (w, h) {
        (Some(w), Some(h)) => Ok([w, h]),
        (None, _) => Err(s.err(
            "Camera.width",
            "missing: visnav needs the image size (Camera.width and Camera.height, pixels)",
        )),
        (_, None) => Err(s.err(
            "Camera.height",
            "missing: visnav needs the image size (Camera.width and Camera.height, pixels)",
        )),
    }
}

/// The camera of `prefix` (`Camera1.`, `Camera2.` or `Camera.`).
fn camera(
    s: &Settings<'_>,
    prefix: &str,
    kind: CameraType,
    size: [u32; 2],
) -> Result<CalibratedCamera> {
    let key = |k: &str| format!("{prefix}{k}");
    let mut intrinsics = Vec::with_capacity(4);
    for k in ["fx", "fy", "cx", "cy"] {
        intrinsics.push(s.required(&key(k), "pixels")?);
    }
    let names: &[&str] = match kind {
        CameraType::PinHole => &["k1", "k2", "p1", "p2", "k3"],
        CameraType::KannalaBrandt8 => &["k1", "k2", "k3", "k4"],
        CameraType::Rectified => &[],
    };
    let given: Vec<Option<f64>> = names
        .iter()
        .map(|k| s.number(&key(k)))
        .collect::<Result<_>>()?;
    let needed = if kind == CameraType::PinHole {
        4
    } else {
        names.len()
    };
    let (model, coeffs) = if given.iter().all(Option::is_none) {
        (DistortionModel::None, Vec::new())
    } else if let Some(missing) = given[..needed].iter().position(Option::is_none) {
        return Err(s.err(
            &key(names[missing]),
            format!(
                "missing: Camera.type {kind:?} needs {} (the distortion coefficients)",
                names[..needed].join(" ")
            ),
        ));
    } else {
        let model = match kind {
            CameraType::KannalaBrandt8 => DistortionModel::Equidistant,
            _ => DistortionModel::Radtan,
        };
        (model, given.into_iter().flatten().collect())
    };
    if kind == CameraType::Rectified
        && let Some(k) = ["k1", "k2", "p1", "p2", "k3", "k4"]
            .iter()
            .map(|k| key(k))
            .find(|k| s.has(k))
    {
        return Err(s.err(
            &k,
            "Camera.type \"Rectified\" images have no distortion: remove the coefficients or set Camera.type: \"PinHole\"",
        ));
    }
    camera_from_parts(
        &intrinsics,
        model,
        &coeffs,
        size,
        s.path,
        prefix.trim_end_matches('.'),
    )
}

/// The right camera and `right_from_left` of ORB-SLAM3 (`Camera2.*` + `Stereo.T_c1_c2`,
/// `Stereo.b`) or ORB-SLAM2 (`Camera.bf`); `None` for a monocular file.
fn right_camera(
    s: &Settings<'_>,
    kind: CameraType,
    left: &CalibratedCamera,
    size: [u32; 2],
) -> Result<(Option<StereoPair>, Option<&'static str>)> {
    match (s.has("Camera2.fx"), s.has("Stereo.T_c1_c2")) {
        (true, true) => {
            let right = camera(s, "Camera2.", kind, size)?;
            let data = s.shaped("Stereo.T_c1_c2", &[(4, 4)])?;
            let left_from_right = rigid_pose(&data).map_err(|m| s.err("Stereo.T_c1_c2", m))?;
            return Ok((
                Some((right, left_from_right.inverse())),
                Some("Stereo.T_c1_c2"),
            ));
        }
        (true, false) => {
            return Err(s.err(
                "Camera2.fx",
                "a second camera needs Stereo.T_c1_c2 (cam1_from_cam2, 4x4 !!opencv-matrix, metres)",
            ));
        }
        (false, true) => {
            return Err(s.err(
                "Stereo.T_c1_c2",
                "the second camera is missing (Camera2.fx fy cx cy …)",
            ));
        }
        (false, false) => {}
    }
    let (baseline_m, field) = if let Some(b) = s.number("Stereo.b")? {
        (b, "Stereo.b")
    } else if let Some(bf) = s.number("Camera.bf")? {
        (bf / left.pinhole.fx, "Camera.bf")
    } else {
        return Ok((None, None));
    };
    if !(baseline_m.is_finite() && baseline_m > 0.0) {
        return Err(s.err(
            field,
            format!("the stereo baseline {baseline_m} m must be positive (the right camera is on the right)"),
        ));
    }
    if !left.distortion.is_identity() {
        return Err(s.err(
            field,
            "a rectified pair (baseline only) needs undistorted images: the coefficients of the camera are not zero",
        ));
    }
    let right_from_left = Pose::from_parts(
        Translation3::new(-baseline_m, 0.0, 0.0),
        UnitQuaternion::identity(),
    );
    Ok((Some((*left, right_from_left)), Some(field)))
}

/// ORB-SLAM2's pre-rectification of raw images: the raw cameras `LEFT.K`, `LEFT.D`,
/// `RIGHT.K`, `RIGHT.D` and the extrinsics from `LEFT.R`, `RIGHT.R`, `RIGHT.P` (module docs).
fn pre_rectification(s: &Settings<'_>, size: [u32; 2]) -> Result<(CalibratedCamera, StereoPair)> {
    let raw = |side: &str| -> Result<(CalibratedCamera, nalgebra::Rotation3<f64>)> {
        let k = s.shaped(&format!("{side}.K"), &[(3, 3)])?;
        let d = s.shaped(&format!("{side}.D"), &[(1, 4), (4, 1), (1, 5), (5, 1)])?;
        let size = [
            s.pixels(&format!("{side}.width"))?.unwrap_or(size[0]),
            s.pixels(&format!("{side}.height"))?.unwrap_or(size[1]),
        ];
        let cam = camera_from_parts(
            &[k[0], k[4], k[2], k[5]],
            DistortionModel::Radtan,
            &d,
            size,
            s.path,
            &format!("{side}.K"),
        )?;
        let r = s.shaped(&format!("{side}.R"), &[(3, 3)])?;
        let mut m = [0.0; 16];
        for row in 0..3 {
            m[row * 4..row * 4 + 3].copy_from_slice(&r[row * 3..row * 3 + 3]);
        }
        m[15] = 1.0;
        let rect_from_raw = rigid_pose(&m).map_err(|e| s.err(&format!("{side}.R"), e))?;
        Ok((cam, rect_from_raw.rotation.to_rotation_matrix()))
    };
    let (left, rect_from_left) = raw("LEFT")?;
    let (right, rect_from_right) = raw("RIGHT")?;
    let p = s.shaped("RIGHT.P", &[(3, 4)])?;
    let baseline_m = -p[3] / p[0];
    if !(baseline_m.is_finite() && baseline_m > 0.0) {
        return Err(s.err(
            "RIGHT.P",
            format!("the stereo baseline −P[0][3] / P[0][0] = {baseline_m} m must be positive"),
        ));
    }
    // right_from_left = right_from_rect · rectR_from_rectL · rect_from_left
    let rotation = rect_from_right.inverse() * rect_from_left;
    let translation = rect_from_right.inverse() * Vector3::new(-baseline_m, 0.0, 0.0);
    let right_from_left = Pose::from_parts(
        Translation3::from(translation),
        UnitQuaternion::from_rotation_matrix(&rotation),
    );
    Ok((left, (right, right_from_left)))
}
