//! Camera calibration files: the user's camera file (`camera.yaml` / `camera.toml`, Kalibr
//! `camchain` keys) and EuRoC `sensor.yaml`, read into [`CalibratedCamera`]s and turned into a
//! [`Rectifier`] that undistorts (one camera) or rectifies (two cameras) images on load.
//!
//! Camera file (YAML shown; TOML takes the same keys, `[cam0]`, `[cam1]` tables):
//!
//! ```yaml
//! cam0:
//!   camera_model: pinhole                 # the only projection model
//!   intrinsics: [458.654, 457.296, 367.215, 248.375]   # fx fy cx cy, pixels
//!   distortion_model: radtan              # radtan | equidistant | fov | none
//!   distortion_coeffs: [-0.2834, 0.0740, 0.00019, 1.76e-05]  # k1 k2 p1 p2 [k3] | k1 k2 k3 k4 | omega
//!   resolution: [752, 480]                # width height, pixels
//! cam1:                                   # optional second (right) camera
//!   camera_model: pinhole
//!   intrinsics: [457.587, 456.134, 379.999, 255.238]
//!   distortion_model: radtan
//!   distortion_coeffs: [-0.2837, 0.0745, -0.0001, -3.6e-05]
//!   resolution: [752, 480]
//!   T_cn_cnm1:                            # cam1_from_cam0, 4x4 row-major, metres
//!   - [1.0, 0.0, 0.0, -0.110]
//!   - [0.0, 1.0, 0.0, 0.0]
//!   - [0.0, 0.0, 1.0, 0.0]
//!   - [0.0, 0.0, 0.0, 1.0]
//! rate_hz: 20                             # optional: frame rate of folders without timestamps
//! ```
//!
//! A YAML camera file may also be an ORB-SLAM2/3 or OpenCV settings file (`%YAML:1.0`,
//! `Camera.fx: …`): [`crate::orb_slam`].

use std::path::Path;
use std::sync::Arc;

use nalgebra::{Point2, Rotation3};
use serde::Deserialize;
use visnav_core::distortion::CalibratedCamera;
use visnav_core::rectify::{RemapMap, stereo_rectify, undistorted_pinhole};
use visnav_core::{GrayImage, PinholeCamera, Pose};

use crate::error::{IoError, Result};

pub(crate) use crate::camera_model::camera_from_parts;
pub use crate::camera_model::{
    CameraEntry, CameraFile, DistortionModel, MatrixEntry, ProjectionModel, RigCalibration,
};

/// Frame rate assumed for folders and videos when the camera file has no `rate_hz`, Hz.
pub const DEFAULT_RATE_HZ: f64 = 10.0;

/// Checks the size of a raw image (a layout's first frame) against its calibration.
pub(crate) fn check_size(
    image: &Path,
    got: (usize, usize),
    calib: &visnav_core::CalibratedCamera,
    calib_path: &Path,
) -> Result<()> {
    let want = (calib.pinhole.width as usize, calib.pinhole.height as usize);
    if got != want {
        return Err(IoError::Format {
            path: calib_path.to_path_buf(),
            message: format!(
                "the calibration is for {}x{} images but {} is {}x{}",
                want.0,
                want.1,
                image.display(),
                got.0,
                got.1
            ),
        });
    }
    Ok(())
}

/// Reads a camera file (`.yaml`/`.yml` or `.toml`, by extension): a Kalibr-style file (module
/// docs) or an ORB-SLAM2/3 / OpenCV settings file (`Camera.fx: …`, [`crate::orb_slam`]). A
/// stereo baseline no camera rig has (a translation in millimetres) is read with a warning
/// naming the file and the field ([`crate::baseline`]).
///
/// # Errors
/// A missing or malformed file, missing or unknown fields, wrong numbers of intrinsics or
/// distortion coefficients, a second camera without `T_cn_cnm1`, or a non-rigid transform; every
/// message names the file.
pub fn read_camera_file(path: &Path) -> Result<RigCalibration> {
    let text = crate::text::read_text(path)?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let file: CameraFile = match ext.as_str() {
        "toml" => toml::from_str(&text).map_err(|e| IoError::Format {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?,
        "yaml" | "yml" => {
            let value = crate::yaml::parse(&text, path)?;
            if crate::orb_slam::is_settings_file(&value) {
                let (rig, field) = crate::orb_slam::read_settings(&value, &text, path)?;
                warn_implausible_baseline(&rig, path, field.unwrap_or("the stereo baseline"));
                return Ok(rig);
            }
            serde_json::from_value(value).map_err(|e| IoError::Format {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?
        }
        _ => {
            return Err(IoError::Format {
                path: path.to_path_buf(),
                message: "camera file must end in .yaml, .yml or .toml".into(),
            });
        }
    };
    let left = file.cam0.camera(path, "cam0")?;
    let right = match &file.cam1 {
        Some(c1) => {
            let cam = c1.camera(path, "cam1")?;
            let Some(t) = &c1.t_cn_cnm1 else {
                return Err(IoError::Format {
                    path: path.to_path_buf(),
                    message: "cam1: missing T_cn_cnm1 (cam1_from_cam0, 4x4) for the stereo pair"
                        .into(),
                });
            };
            Some((cam, t.to_pose(path, "cam1.T_cn_cnm1")?))
        }
        None => None,
    };
    if let Some(r) = file.rate_hz
        && !(r.is_finite() && r > 0.0)
    {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!("rate_hz = {r} must be positive"),
        });
    }
    let rig = RigCalibration {
        left,
        right,
        rate_hz: file.rate_hz,
    };
    warn_implausible_baseline(&rig, path, "cam1.T_cn_cnm1");
    Ok(rig)
}

/// The warning of [`crate::baseline::warn_if_implausible`] for a stereo rig's translation.
fn warn_implausible_baseline(rig: &RigCalibration, path: &Path, field: &str) {
    if let Some((_, right_from_left)) = &rig.right {
        let baseline_m = right_from_left.translation.vector.norm();
        crate::baseline::warn_if_implausible(path, field, baseline_m, &rig.left.pinhole);
    }
}

/// Deserialises a typed struct from the YAML subset of [`crate::yaml`].
fn from_yaml<T: serde::de::DeserializeOwned>(text: &str, path: &Path) -> Result<T> {
    let value = crate::yaml::parse(text, path)?;
    serde_json::from_value(value).map_err(|e| IoError::Format {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// EuRoC / ASL `sensor.yaml` of a camera.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EurocSensor {
    /// `camera`.
    pub sensor_type: String,
    /// Free text.
    #[serde(default)]
    pub comment: Option<String>,
    /// `body_from_sensor` (camera to body / IMU), 4x4.
    #[serde(rename = "T_BS")]
    pub t_bs: MatrixEntry,
    /// Frame rate, Hz.
    pub rate_hz: f64,
    /// `width height`, pixels.
    pub resolution: [u32; 2],
    /// `pinhole`.
    pub camera_model: ProjectionModel,
    /// `fu fv cu cv`, pixels.
    pub intrinsics: Vec<f64>,
    /// `radial-tangential` or `equidistant`.
    pub distortion_model: DistortionModel,
    /// Coefficients.
    pub distortion_coefficients: Vec<f64>,
}

/// Reads an EuRoC `sensor.yaml`: the camera and `body_from_cam` (`T_BS`).
///
/// # Errors
/// A missing or malformed file, a missing field, or wrong numbers of values.
pub fn read_euroc_sensor(path: &Path) -> Result<(CalibratedCamera, Pose)> {
    let text = crate::text::read_text(path)?;
    let s: EurocSensor = from_yaml(&text, path)?;
    if s.sensor_type != "camera" {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!("sensor_type is '{}', expected 'camera'", s.sensor_type),
        });
    }
    let cam = camera_from_parts(
        &s.intrinsics,
        s.distortion_model,
        &s.distortion_coefficients,
        s.resolution,
        path,
        "camera",
    )?;
    Ok((cam, s.t_bs.to_pose(path, "T_BS")?))
}

/// Undistortion (one camera) or rectification (two cameras) applied to images on load: the
/// remap maps are built once per sequence.
#[derive(Debug, Clone)]
pub struct Rectifier {
    /// The pinhole camera of the output images.
    pub camera: PinholeCamera,
    /// Baseline of the rectified pair, metres.
    pub baseline_m: Option<f64>,
    /// Rotation of raw left-camera vectors into the output (rectified) left frame.
    pub left_rect_from_cam: Rotation3<f64>,
    left: Option<RemapMap>,
    right: Option<RemapMap>,
}

impl Rectifier {
    /// Builds the maps for `calib`; with `stereo` and a right camera, rectifies the pair, else
    /// undistorts the left camera only. A camera without distortion and no rotation needs no map.
    ///
    /// # Errors
    /// [`IoError::Format`] naming `calib_path` when the pair cannot be rectified.
    pub fn new(calib: &RigCalibration, stereo: bool, calib_path: &Path) -> Result<Arc<Self>> {
        let bad = |e: visnav_core::camera::CameraError| IoError::Format {
            path: calib_path.to_path_buf(),
            message: e.to_string(),
        };
        match (&calib.right, stereo) {
            (Some((right, right_from_left)), true) => {
                let rect = stereo_rectify(&calib.left, right, right_from_left).map_err(bad)?;
                Ok(Arc::new(Self {
                    camera: rect.rectified,
                    baseline_m: Some(rect.baseline_m),
                    left_rect_from_cam: rect.left_rect_from_cam,
                    left: Some(RemapMap::new(
                        &calib.left,
                        &rect.left_rect_from_cam,
                        &rect.rectified,
                    )),
                    right: Some(RemapMap::new(
                        right,
                        &rect.right_rect_from_cam,
                        &rect.rectified,
                    )),
                }))
            }
            _ if calib.left.distortion.is_identity() => Ok(Arc::new(Self {
                camera: calib.left.pinhole,
                baseline_m: None,
                left_rect_from_cam: Rotation3::identity(),
                left: None,
                right: None,
            })),
            _ => {
                let camera = undistorted_pinhole(&calib.left).map_err(bad)?;
                Ok(Arc::new(Self {
                    camera,
                    baseline_m: None,
                    left_rect_from_cam: Rotation3::identity(),
                    left: Some(RemapMap::new(&calib.left, &Rotation3::identity(), &camera)),
                    right: None,
                }))
            }
        }
    }

    /// Undistortion of one camera into a given pinhole `output` camera (any size), e.g. a TUM
    /// monoVO `camera.txt` output line.
    #[must_use]
    pub fn undistort_to(camera: &CalibratedCamera, output: PinholeCamera) -> Arc<Self> {
        let identity = camera.distortion.is_identity() && camera.pinhole == output;
        Arc::new(Self {
            camera: output,
            baseline_m: None,
            left_rect_from_cam: Rotation3::identity(),
            left: (!identity).then(|| RemapMap::new(camera, &Rotation3::identity(), &output)),
            right: None,
        })
    }

    /// The rectified / undistorted left image.
    #[must_use]
    pub fn left(&self, raw: GrayImage) -> GrayImage {
        match &self.left {
            Some(m) => m.apply(&raw),
            None => raw,
        }
    }

    /// The rectified right image.
    #[must_use]
    pub fn right(&self, raw: GrayImage) -> GrayImage {
        match &self.right {
            Some(m) => m.apply(&raw),
            None => raw,
        }
    }

    /// The raw left pixel sampled at output pixel `(u, v)` (for checks and tools).
    #[must_use]
    pub fn left_source(&self, u: usize, v: usize) -> Option<Point2<f64>> {
        match &self.left {
            Some(m) => m.source(u, v),
            None => Some(Point2::new(u as f64, v as f64)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use visnav_core::distortion::Distortion;

    const STEREO_YAML: &str = "cam0:\n  camera_model: pinhole\n  intrinsics: [458.654, 457.296, 367.215, 248.375]\n  distortion_model: radtan\n  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]\n  resolution: [752, 480]\ncam1:\n  camera_model: pinhole\n  intrinsics: [457.587, 456.134, 379.999, 255.238]\n  distortion_model: radtan\n  distortion_coeffs: [-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05]\n  resolution: [752, 480]\n  T_cn_cnm1:\n  - [0.9999972, -0.0023171, -0.0002337, -0.1100741]\n  - [0.0023118, 0.9998725, -0.0157260, 0.0003991]\n  - [0.0002701, 0.0157254, 0.9998763, -0.0008531]\n  - [0.0, 0.0, 0.0, 1.0]\n";

    #[test]
    fn yaml_and_toml_camera_files_agree() {
        let dir = tempfile::tempdir().unwrap();
        let yaml = dir.path().join("camera.yaml");
        std::fs::write(&yaml, STEREO_YAML).unwrap();
        let a = read_camera_file(&yaml).unwrap();
        let toml_path = dir.path().join("camera.toml");
        std::fs::write(
            &toml_path,
            "rate_hz = 20.0\n[cam0]\ncamera_model = \"pinhole\"\nintrinsics = [458.654, 457.296, 367.215, 248.375]\ndistortion_model = \"radtan\"\ndistortion_coeffs = [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]\nresolution = [752, 480]\n",
        )
        .unwrap();
        let b = read_camera_file(&toml_path).unwrap();
        assert_eq!(a.left, b.left);
        assert_eq!(b.rate_hz, Some(20.0));
        let (_, right_from_left) = a.right.unwrap();
        assert!((right_from_left.translation.vector.x + 0.110_074_1).abs() < 1e-12);
        let rect = Rectifier::new(&read_camera_file(&yaml).unwrap(), true, &yaml).unwrap();
        let b = rect.baseline_m.unwrap();
        assert!((b - 0.110).abs() < 0.001, "{b}");
    }

    #[test]
    fn fov_camera_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("camera.yaml");
        let fov = "cam0:\n  camera_model: pinhole\n  intrinsics: [446.9, 447.1, 630.7, 510.5]\n  distortion_model: fov\n  distortion_coeffs: [0.933271]\n  resolution: [1280, 1024]\n";
        std::fs::write(&p, fov).unwrap();
        let calib = read_camera_file(&p).unwrap();
        assert_eq!(calib.left.distortion, Distortion::Fov { omega: 0.933_271 });
        for (text, what) in [
            (fov.replace("[0.933271]", "[0.9, 0.1]"), "needs 1 (omega)"),
            (fov.replace("[0.933271]", "[4.0]"), "must be in [0, π)"),
        ] {
            std::fs::write(&p, text).unwrap();
            let e = read_camera_file(&p).unwrap_err().to_string();
            assert!(e.contains("camera.yaml") && e.contains(what), "{what}: {e}");
        }
    }

    #[test]
    fn bad_calibration_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("camera.yaml");
        let cases = [
            (
                STEREO_YAML.replace(
                    "distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]",
                    "distortion_coeffs: [-0.28340811, 0.07395907]",
                ),
                "needs 4 or 5",
            ),
            (
                STEREO_YAML.replace("  distortion_model: radtan\n", ""),
                "missing field `distortion_model`",
            ),
            (
                STEREO_YAML.replace("  T_cn_cnm1:\n", "  T_other:\n"),
                "unknown field `T_other`",
            ),
            (STEREO_YAML.replace("[458.654, ", "["), "expected 4 numbers"),
            (
                STEREO_YAML.replace("[0.9999972, -0.0023171", "[0.5, -0.0023171"),
                "not a rotation",
            ),
        ];
        for (text, what) in cases {
            std::fs::write(&p, &text).unwrap();
            let e = read_camera_file(&p).unwrap_err().to_string();
            assert!(e.contains("camera.yaml") && e.contains(what), "{what}: {e}");
        }
        // a pair whose right camera is on the left cannot be rectified
        std::fs::write(&p, STEREO_YAML.replace("-0.1100741]", "0.1100741]")).unwrap();
        let calib = read_camera_file(&p).unwrap();
        let e = Rectifier::new(&calib, true, &p).unwrap_err().to_string();
        assert!(e.contains("camera.yaml") && e.contains("swap"), "{e}");
    }
}
