//! Camera models: the pinhole camera and the rectified stereo rig.
//!
//! Pixel coordinates are `(u, v)` = (column, row) in pixels with the origin at the *centre* of the
//! top-left pixel (the KITTI / OpenCV convention). Camera frame: x right, y down, z forward, metres.

use nalgebra::{Matrix3, Point2, Point3, Vector3};
use serde::{Deserialize, Serialize};

/// Errors of camera construction.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CameraError {
    /// A focal length is not finite and positive.
    #[error("invalid focal length fx={fx}, fy={fy}: both must be finite and positive")]
    InvalidFocal { fx: f64, fy: f64 },
    /// The stereo baseline is not finite and positive.
    #[error("invalid stereo baseline {baseline_m} m: must be finite and positive")]
    InvalidBaseline { baseline_m: f64 },
    /// A calibrated pair or camera cannot be rectified / undistorted.
    #[error("cannot rectify: {reason}")]
    NotRectifiable { reason: String },
}

/// An ideal (rectified, undistorted) pinhole camera.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PinholeCamera {
    /// Focal length along u, pixels.
    pub fx: f64,
    /// Focal length along v, pixels.
    pub fy: f64,
    /// Principal point u, pixels.
    pub cx: f64,
    /// Principal point v, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

impl PinholeCamera {
    /// A checked pinhole camera.
    ///
    /// # Errors
    /// [`CameraError::InvalidFocal`] when a focal length is not finite and positive.
    pub fn new(
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        width: u32,
        height: u32,
    ) -> Result<Self, CameraError> {
        if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0) {
            return Err(CameraError::InvalidFocal { fx, fy });
        }
        Ok(Self {
            fx,
            fy,
            cx,
            cy,
            width,
            height,
        })
    }

    /// KITTI odometry sequence 00–02 intrinsics at 1241x376 (the synthetic default).
    #[must_use]
    pub fn kitti_default() -> Self {
        Self {
            fx: 718.856,
            fy: 718.856,
            cx: 607.1928,
            cy: 185.2157,
            width: 1241,
            height: 376,
        }
    }

    /// The calibration matrix `K`.
    #[must_use]
    pub fn k(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    /// The inverse calibration matrix `K⁻¹`.
    #[must_use]
    pub fn k_inv(&self) -> Matrix3<f64> {
        Matrix3::new(
            1.0 / self.fx,
            0.0,
            -self.cx / self.fx,
            0.0,
            1.0 / self.fy,
            -self.cy / self.fy,
            0.0,
            0.0,
            1.0,
        )
    }

    /// Projects a point in the camera frame to pixels; `None` behind or on the camera plane.
    #[must_use]
    pub fn project(&self, p_in_cam: &Point3<f64>) -> Option<Point2<f64>> {
        if p_in_cam.z <= 1e-9 {
            return None;
        }
        Some(Point2::new(
            self.fx * p_in_cam.x / p_in_cam.z + self.cx,
            self.fy * p_in_cam.y / p_in_cam.z + self.cy,
        ))
    }

    /// Normalised image coordinates `(x/z, y/z)` of a pixel.
    #[must_use]
    pub fn normalize(&self, px: &Point2<f64>) -> Point2<f64> {
        Point2::new((px.x - self.cx) / self.fx, (px.y - self.cy) / self.fy)
    }

    /// The viewing ray `(x/z, y/z, 1)` of a pixel.
    #[must_use]
    pub fn ray(&self, px: &Point2<f64>) -> Vector3<f64> {
        let n = self.normalize(px);
        Vector3::new(n.x, n.y, 1.0)
    }

    /// The 3-D point at depth `z_m` (along the optical axis) seen at pixel `px`.
    #[must_use]
    pub fn unproject(&self, px: &Point2<f64>, z_m: f64) -> Point3<f64> {
        Point3::from(self.ray(px) * z_m)
    }

    /// Whether a pixel lies inside the image with a margin (pixels).
    #[must_use]
    pub fn contains(&self, px: &Point2<f64>, margin: f64) -> bool {
        px.x >= margin
            && px.y >= margin
            && px.x <= f64::from(self.width) - 1.0 - margin
            && px.y <= f64::from(self.height) - 1.0 - margin
    }

    /// The same camera for an image scaled by `s` (e.g. 1/3 for a pyramid level), using the
    /// pixel-centre convention `u' = (u + 0.5) s - 0.5`.
    #[must_use]
    pub fn scaled(&self, s: f64) -> Self {
        Self {
            fx: self.fx * s,
            fy: self.fy * s,
            cx: (self.cx + 0.5) * s - 0.5,
            cy: (self.cy + 0.5) * s - 0.5,
            width: (f64::from(self.width) * s).round() as u32,
            height: (f64::from(self.height) * s).round() as u32,
        }
    }
}

/// A rectified stereo pair: both cameras share the intrinsics `left`; the right camera sits
/// `baseline_m` metres along the left camera's +x axis (KITTI: `baseline = -P1[0][3] / P1[0][0]`),
/// its principal point `right_cx_offset_px` columns right of the left one's (0 for an ideal
/// rectification): a point at depth `z` has the disparity `u_left − u_right = f b / z − offset`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StereoCamera {
    /// Intrinsics of both rectified cameras.
    pub left: PinholeCamera,
    /// Baseline in metres (positive).
    pub baseline_m: f64,
    /// The right principal point's column minus the left one's, pixels: from the calibration
    /// (`P1`'s `cx` minus `P0`'s), or estimated by the stereo odometry's window adjustment when
    /// asked to (KITTI's rectified pairs measure about +0.16–0.20 px, docs/benchmarks.md).
    #[serde(default)]
    pub right_cx_offset_px: f64,
}

impl StereoCamera {
    /// A checked stereo rig.
    ///
    /// # Errors
    /// [`CameraError::InvalidBaseline`] when the baseline is not finite and positive.
    pub fn new(left: PinholeCamera, baseline_m: f64) -> Result<Self, CameraError> {
        if !(baseline_m.is_finite() && baseline_m > 0.0) {
            return Err(CameraError::InvalidBaseline { baseline_m });
        }
        Ok(Self {
            left,
            baseline_m,
            right_cx_offset_px: 0.0,
        })
    }

    /// The same rig with the right principal point `offset_px` columns right of the left one's.
    #[must_use]
    pub fn with_right_cx_offset(self, offset_px: f64) -> Self {
        Self {
            right_cx_offset_px: offset_px,
            ..self
        }
    }

    /// Depth (metres) of a measured disparity `d_px = u_left - u_right` (pixels):
    /// `f b / (d + offset)`; `None` if that disparity is not positive.
    #[must_use]
    pub fn depth_from_disparity(&self, d_px: f64) -> Option<f64> {
        let d = d_px + self.right_cx_offset_px;
        (d > 0.0).then(|| self.left.fx * self.baseline_m / d)
    }

    /// The disparity `u_left − u_right` (pixels) this rig measures for a point at depth `z_m`:
    /// `f b / z − offset`, the inverse of [`Self::depth_from_disparity`].
    #[must_use]
    pub fn disparity_from_depth(&self, z_m: f64) -> f64 {
        self.left.fx * self.baseline_m / z_m - self.right_cx_offset_px
    }

    /// Projects a point in the *left* camera frame into the right image.
    #[must_use]
    pub fn project_right(&self, p_in_left: &Point3<f64>) -> Option<Point2<f64>> {
        self.left
            .project(&Point3::new(
                p_in_left.x - self.baseline_m,
                p_in_left.y,
                p_in_left.z,
            ))
            .map(|p| Point2::new(p.x + self.right_cx_offset_px, p.y))
    }

    /// Triangulates a rectified correspondence (left pixel and disparity) into the left frame.
    #[must_use]
    pub fn triangulate(&self, px_left: &Point2<f64>, d_px: f64) -> Option<Point3<f64>> {
        self.depth_from_disparity(d_px)
            .map(|z| self.left.unproject(px_left, z))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn project_unproject() {
        let cam = PinholeCamera::kitti_default();
        let p = Point3::new(1.0, -0.5, 12.0);
        let px = cam.project(&p).unwrap();
        assert_relative_eq!(cam.unproject(&px, 12.0), p, epsilon = 1e-12);
        assert_relative_eq!(cam.k() * cam.k_inv(), Matrix3::identity(), epsilon = 1e-12);
        assert!(cam.project(&Point3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn stereo_triangulation() {
        let rig = StereoCamera::new(PinholeCamera::kitti_default(), 0.537).unwrap();
        let p = Point3::new(2.0, 1.0, 20.0);
        let l = rig.left.project(&p).unwrap();
        let r = rig.project_right(&p).unwrap();
        assert_relative_eq!(l.y, r.y, epsilon = 1e-12);
        assert_relative_eq!(rig.triangulate(&l, l.x - r.x).unwrap(), p, epsilon = 1e-9);
        assert!(StereoCamera::new(rig.left, -1.0).is_err());
        assert!(PinholeCamera::new(0.0, 1.0, 0.0, 0.0, 1, 1).is_err());
    }
}
