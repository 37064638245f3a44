//! The typed camera descriptions every calibration reader produces: the entries of a camera
//! file ([`CameraFile`], [`CameraEntry`]: projection and distortion models, intrinsics, a 4x4
//! extrinsic), a rig's [`RigCalibration`], and the checked constructors the readers share
//! (`camera_from_parts`, `rigid_pose`). Below the readers ([`crate::calibration`]'s camera file
//! and EuRoC `sensor.yaml`, [`crate::orb_slam`]'s settings files), which are peers.

use std::path::Path;

use nalgebra::Matrix4;
use serde::Deserialize;
use visnav_core::distortion::{CalibratedCamera, Distortion};
use visnav_core::{PinholeCamera, Pose};

use crate::error::{IoError, Result};

/// The projection model of a camera entry (only the pinhole projection is supported).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ProjectionModel {
    /// Pinhole projection (with a distortion model).
    Pinhole,
}

/// The distortion model name of a camera entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DistortionModel {
    /// No distortion.
    None,
    /// Radial–tangential, `k1 k2 p1 p2 [k3]`.
    #[serde(
        alias = "radial-tangential",
        alias = "plumb_bob",
        alias = "radial_tangential"
    )]
    Radtan,
    /// Equidistant fisheye, `k1 k2 k3 k4`.
    #[serde(alias = "fisheye", alias = "kannala-brandt", alias = "kannala_brandt")]
    Equidistant,
    /// Field-of-view / ATAN (Devernay–Faugeras, DSO `FOV`), `omega` in radians.
    #[serde(alias = "atan")]
    Fov,
}

/// A 4x4 transform as a list of rows, 16 row-major numbers, or OpenCV's `{rows, cols, data}`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum MatrixEntry {
    /// Four rows of four numbers.
    Rows(Vec<Vec<f64>>),
    /// Sixteen numbers, row-major.
    Flat(Vec<f64>),
    /// OpenCV / EuRoC form.
    Sized {
        /// Number of rows (4).
        rows: usize,
        /// Number of columns (4).
        cols: usize,
        /// Row-major values.
        data: Vec<f64>,
    },
}

impl MatrixEntry {
    /// The rigid transform, checked to be 4x4 with a rotation block (tolerance 1e-3).
    pub(crate) fn to_pose(&self, path: &Path, what: &str) -> Result<Pose> {
        let bad = |message: String| IoError::Format {
            path: path.to_path_buf(),
            message: format!("{what}: {message}"),
        };
        let values: Vec<f64> = match self {
            Self::Rows(rows) => {
                if rows.len() != 4 || rows.iter().any(|r| r.len() != 4) {
                    return Err(bad("expected 4 rows of 4 numbers".into()));
                }
                rows.concat()
            }
            Self::Flat(v) => v.clone(),
            Self::Sized { rows, cols, data } => {
                if (*rows, *cols) != (4, 4) {
                    return Err(bad(format!("expected a 4x4 matrix, found {rows}x{cols}")));
                }
                data.clone()
            }
        };
        rigid_pose(&values).map_err(bad)
    }
}

/// The rigid transform of 16 row-major numbers, checked: finite, and an upper-left 3x3 block that
/// is a rotation (tolerance 1e-3; projected onto SO(3)).
///
/// # Errors
/// What is wrong, for a message.
pub(crate) fn rigid_pose(values: &[f64]) -> std::result::Result<Pose, String> {
    if values.len() != 16 || values.iter().any(|v| !v.is_finite()) {
        return Err(format!(
            "expected 16 finite numbers (row-major 4x4), found {}",
            values.len()
        ));
    }
    let m = Matrix4::from_row_slice(values);
    let r = m.fixed_view::<3, 3>(0, 0).into_owned();
    if (r.transpose() * r - nalgebra::Matrix3::identity())
        .abs()
        .max()
        > 1e-3
        || r.determinant() < 0.0
    {
        return Err("the upper-left 3x3 block is not a rotation".into());
    }
    let rotation = visnav_core::se3::project_to_so3(&r);
    Ok(Pose::from_parts(
        nalgebra::Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
        nalgebra::UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}

/// One camera of a camera file (Kalibr `camchain` keys).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraEntry {
    /// Projection model (`pinhole`).
    pub camera_model: ProjectionModel,
    /// `fx fy cx cy`, pixels.
    pub intrinsics: Vec<f64>,
    /// Distortion model name.
    pub distortion_model: DistortionModel,
    /// Distortion coefficients (none for `none`).
    #[serde(default, alias = "distortion_coefficients")]
    pub distortion_coeffs: Vec<f64>,
    /// Image `width height`, pixels.
    pub resolution: [u32; 2],
    /// `cam1_from_cam0` (this camera from the previous one), 4x4, metres; second camera only.
    #[serde(default, rename = "T_cn_cnm1")]
    pub t_cn_cnm1: Option<MatrixEntry>,
    /// Kalibr extras, accepted and ignored.
    #[serde(default, rename = "T_cam_imu")]
    pub t_cam_imu: Option<MatrixEntry>,
    /// Kalibr extra, ignored.
    #[serde(default)]
    pub cam_overlaps: Option<Vec<u32>>,
    /// Kalibr extra, ignored.
    #[serde(default)]
    pub rostopic: Option<String>,
    /// Kalibr extra, ignored.
    #[serde(default)]
    pub timeshift_cam_imu: Option<f64>,
}

impl CameraEntry {
    /// The calibrated camera, checking the number of intrinsics and distortion coefficients.
    ///
    /// # Errors
    /// [`IoError::Format`] naming `path` and `what` (e.g. `cam0`).
    pub fn camera(&self, path: &Path, what: &str) -> Result<CalibratedCamera> {
        camera_from_parts(
            &self.intrinsics,
            self.distortion_model,
            &self.distortion_coeffs,
            self.resolution,
            path,
            what,
        )
    }
}

pub(crate) fn camera_from_parts(
    intrinsics: &[f64],
    model: DistortionModel,
    coeffs: &[f64],
    resolution: [u32; 2],
    path: &Path,
    what: &str,
) -> Result<CalibratedCamera> {
    let bad = |message: String| IoError::Format {
        path: path.to_path_buf(),
        message: format!("{what}: {message}"),
    };
    let [fx, fy, cx, cy] = intrinsics else {
        return Err(bad(format!(
            "intrinsics: expected 4 numbers (fx fy cx cy), found {}",
            intrinsics.len()
        )));
    };
    if resolution[0] == 0 || resolution[1] == 0 {
        return Err(bad("resolution: width and height must be positive".into()));
    }
    let pinhole = PinholeCamera::new(*fx, *fy, *cx, *cy, resolution[0], resolution[1])
        .map_err(|e| bad(e.to_string()))?;
    if coeffs.iter().any(|c| !c.is_finite()) {
        return Err(bad("distortion coefficients must be finite".into()));
    }
    let distortion = match (model, coeffs) {
        (DistortionModel::None, []) => Distortion::None,
        (DistortionModel::Radtan, [k1, k2, p1, p2]) => Distortion::RadialTangential {
            k1: *k1,
            k2: *k2,
            p1: *p1,
            p2: *p2,
            k3: 0.0,
        },
        (DistortionModel::Radtan, [k1, k2, p1, p2, k3]) => Distortion::RadialTangential {
            k1: *k1,
            k2: *k2,
            p1: *p1,
            p2: *p2,
            k3: *k3,
        },
        (DistortionModel::Equidistant, [k1, k2, k3, k4]) => Distortion::Equidistant {
            k1: *k1,
            k2: *k2,
            k3: *k3,
            k4: *k4,
        },
        (DistortionModel::Fov, [omega]) => {
            if !(0.0..std::f64::consts::PI).contains(omega) {
                return Err(bad(format!(
                    "fov: omega = {omega} must be in [0, π) radians"
                )));
            }
            Distortion::Fov { omega: *omega }
        }
        (m, c) => {
            let expected = match m {
                DistortionModel::None => "none",
                DistortionModel::Radtan => "4 or 5 (k1 k2 p1 p2 [k3])",
                DistortionModel::Equidistant => "4 (k1 k2 k3 k4)",
                DistortionModel::Fov => "1 (omega)",
            };
            return Err(bad(format!(
                "distortion model {m:?} needs {expected} coefficients, found {}",
                c.len()
            )));
        }
    };
    Ok(CalibratedCamera {
        pinhole,
        distortion,
    })
}

/// A user's camera file: one camera, or a stereo pair with its extrinsics.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// The (left) camera.
    pub cam0: CameraEntry,
    /// The right camera, with `T_cn_cnm1` = `cam1_from_cam0`.
    #[serde(default)]
    pub cam1: Option<CameraEntry>,
    /// Frame rate, Hz, for inputs without timestamps (image folders); default 10 Hz.
    #[serde(default)]
    pub rate_hz: Option<f64>,
}

/// Calibration of a rig: the left camera and optionally the right one with `right_from_left`.
#[derive(Debug, Clone, PartialEq)]
pub struct RigCalibration {
    /// Left (reference) camera.
    pub left: CalibratedCamera,
    /// Right camera and `right_from_left` (metres).
    pub right: Option<(CalibratedCamera, Pose)>,
    /// Frame rate, Hz, when the file gives one.
    pub rate_hz: Option<f64>,
}
