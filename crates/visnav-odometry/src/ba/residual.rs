//! The whitened stereo reprojection residual and its analytic Jacobians (module doc of
//! [`super`]).

use nalgebra::{Matrix3, Matrix3x6, Point3, Vector3};
use visnav_core::{Pose, StereoCamera};

use super::problem::Observation;

/// Smallest depth in front of the camera a point may have to be used, metres.
const MIN_DEPTH_M: f64 = 1e-3;

/// One observation's residual `r = ((u_l − û_l) / σ, (v_l − v̂_l) / σ, (u_r − û_r) / σ_r)` (the
/// third component is 0 without a right match).
#[derive(Debug, Clone, Copy)]
pub struct StereoResidual<'a> {
    rig: &'a StereoCamera,
    obs: &'a Observation,
}

/// The residual with its Jacobians with respect to the left pose increment `ξ = (v, ω)` of
/// `cam_from_world` and to the world point.
#[derive(Debug, Clone, Copy)]
pub struct Linearised {
    /// Whitened residual.
    pub r: Vector3<f64>,
    /// `∂r/∂ξ`.
    pub d_pose: Matrix3x6<f64>,
    /// `∂r/∂X_w`.
    pub d_point: Matrix3<f64>,
    /// `∂r/∂ε` for the rig's right principal-point offset `ε`
    /// ([`StereoCamera::right_cx_offset_px`]): `−1/σ_r` in the right row, 0 without a right match.
    pub d_offset: Vector3<f64>,
}

impl<'a> StereoResidual<'a> {
    /// The residual of `obs` seen by `rig`.
    #[must_use]
    pub fn new(rig: &'a StereoCamera, obs: &'a Observation) -> Self {
        Self { rig, obs }
    }

    /// The whitened residual; `None` when the point is not in front of the camera.
    #[must_use]
    pub fn value(&self, cam_from_world: &Pose, point_w: &Point3<f64>) -> Option<Vector3<f64>> {
        let p = cam_from_world * point_w;
        (p.z > MIN_DEPTH_M).then(|| self.residual_at(&p.coords))
    }

    fn residual_at(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let c = &self.rig.left;
        let inv_sigma = 1.0 / self.obs.sigma_px;
        let inv_sigma_right = 1.0 / self.obs.right_sigma_px;
        let u = c.fx * p.x / p.z + c.cx;
        let v = c.fy * p.y / p.z + c.cy;
        let ur = self.obs.right_u_px.map_or(0.0, |ur| {
            ur - (c.fx * (p.x - self.rig.baseline_m) / p.z + c.cx + self.rig.right_cx_offset_px)
        });
        Vector3::new(
            (self.obs.left_px.x - u) * inv_sigma,
            (self.obs.left_px.y - v) * inv_sigma,
            ur * inv_sigma_right,
        )
    }

    /// The residual and its Jacobians; `None` when the point is not in front of the camera.
    #[must_use]
    pub fn linearise(&self, cam_from_world: &Pose, point_w: &Point3<f64>) -> Option<Linearised> {
        let p = (cam_from_world * point_w).coords;
        if p.z <= MIN_DEPTH_M {
            return None;
        }
        let c = &self.rig.left;
        let (iz, iz2) = (1.0 / p.z, 1.0 / (p.z * p.z));
        // ∂(projection)/∂p_cam, rows u_l, v_l, u_r
        let mut d_proj = Matrix3::new(
            c.fx * iz,
            0.0,
            -c.fx * p.x * iz2,
            0.0,
            c.fy * iz,
            -c.fy * p.y * iz2,
            c.fx * iz,
            0.0,
            -c.fx * (p.x - self.rig.baseline_m) * iz2,
        );
        if self.obs.right_u_px.is_none() {
            d_proj.row_mut(2).fill(0.0);
        }
        // r = (observed − projected) / σ
        let whiten = Matrix3::from_diagonal(&Vector3::new(
            1.0 / self.obs.sigma_px,
            1.0 / self.obs.sigma_px,
            1.0 / self.obs.right_sigma_px,
        ));
        let d_r_d_p = -whiten * d_proj;
        // p' = exp(ξ)·p ≈ p + v + ω × p: ∂p/∂v = I, ∂p/∂ω = −[p]×
        let mut d_p_d_xi = Matrix3x6::zeros();
        d_p_d_xi.fixed_view_mut::<3, 3>(0, 0).fill_with_identity();
        d_p_d_xi
            .fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-visnav_core::se3::skew(&p)));
        let rotation = cam_from_world.rotation.to_rotation_matrix();
        let d_offset = if self.obs.right_u_px.is_some() {
            Vector3::new(0.0, 0.0, -1.0 / self.obs.right_sigma_px)
        } else {
            Vector3::zeros()
        };
        Some(Linearised {
            r: self.residual_at(&p),
            d_pose: d_r_d_p * d_p_d_xi,
            d_point: d_r_d_p * rotation.matrix(),
            d_offset,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point2, Vector6};
    use visnav_core::PinholeCamera;
    use visnav_core::se3::se3_exp;

    #[test]
    fn analytic_jacobians_match_finite_differences() {
        let rig = StereoCamera::new(PinholeCamera::kitti_default(), 0.54).unwrap();
        let obs = Observation {
            frame: 0,
            point: 0,
            left_px: Point2::new(600.0, 180.0),
            right_u_px: Some(560.0),
            sigma_px: 0.7,
            right_sigma_px: 1.3,
        };
        let res = StereoResidual::new(&rig, &obs);
        let pose = se3_exp(&Vector6::new(0.3, -0.1, 1.2, 0.02, -0.05, 0.01));
        let x = Point3::new(1.5, -0.7, 14.0);
        let lin = res.linearise(&pose, &x).unwrap();
        let h = 1e-6;
        for i in 0..6 {
            let mut d = Vector6::zeros();
            d[i] = h;
            let plus = res.value(&(se3_exp(&d) * pose), &x).unwrap();
            let minus = res.value(&(se3_exp(&(-d)) * pose), &x).unwrap();
            let numeric = (plus - minus) / (2.0 * h);
            let err = (numeric - lin.d_pose.column(i)).norm();
            assert!(
                err < 1e-5 * (1.0 + numeric.norm()),
                "pose column {i}: {err}"
            );
        }
        for i in 0..3 {
            let mut d = Vector3::zeros();
            d[i] = h;
            let numeric = (res.value(&pose, &(x + d)).unwrap()
                - res.value(&pose, &(x - d)).unwrap())
                / (2.0 * h);
            let err = (numeric - lin.d_point.column(i)).norm();
            assert!(
                err < 1e-5 * (1.0 + numeric.norm()),
                "point column {i}: {err}"
            );
        }
        let shifted = |e: f64| rig.with_right_cx_offset(e);
        let (rp, rm) = (shifted(h), shifted(-h));
        let numeric = (StereoResidual::new(&rp, &obs).value(&pose, &x).unwrap()
            - StereoResidual::new(&rm, &obs).value(&pose, &x).unwrap())
            / (2.0 * h);
        assert!((numeric - lin.d_offset).norm() < 1e-6, "offset: {numeric}");
        // without a right match the third row is zero
        let mono = Observation {
            right_u_px: None,
            ..obs
        };
        let lin = StereoResidual::new(&rig, &mono)
            .linearise(&pose, &x)
            .unwrap();
        assert_eq!(lin.r.z, 0.0);
        assert_eq!(lin.d_pose.row(2).norm(), 0.0);
        assert_eq!(lin.d_offset.norm(), 0.0);
        // behind the camera: no residual
        assert!(
            res.value(&Pose::identity(), &Point3::new(0.0, 0.0, -5.0))
                .is_none()
        );
    }
}
