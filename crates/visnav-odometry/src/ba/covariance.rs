//! The covariance of a relative pose from a window's Gauss–Newton information (issue 55 item 5).
//!
//! At the solution, the information of the free poses with the points (and the rig's offset,
//! when estimated) marginalised is the reduced camera system `S` of the Schur complement
//! (module doc of [`super`]); its inverse is the poses' joint covariance in the left increments
//! `ξ_k` of `cam_from_world` (`T_k ← exp(ξ_k)·T_k`, `ξ = (v, ω)`). The covariance of the
//! relative motion between two window frames follows by first-order propagation
//! ([`relative_step_covariance`]); it is scaled by the residual variance of the whitened
//! errors (`Σ ρ′·‖r̃‖² / (m − n)`, `m` residual components, `n` unknowns) when asked.

use nalgebra::{DMatrix, Matrix6};
use visnav_core::Pose;

use super::problem::{BaConfig, WindowBa, huber_weight};
use super::schur;

/// How [`WindowBa::relative_covariance`] scales the inverse information.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CovarianceScale {
    /// Multiply by the a-posteriori residual variance of the whitened errors (1 when the
    /// observations' sigmas are right).
    pub residual_variance: bool,
    /// A global inflation factor on top (calibrated on rendered training drives).
    pub inflation: f64,
}

/// The adjoint of `pose` for twists `ξ = (v, ω)`: `exp(Ad·ξ) = pose · exp(ξ) · pose⁻¹`,
/// `Ad = [[R, [t]×R], [0, R]]`.
#[must_use]
pub fn adjoint(pose: &Pose) -> Matrix6<f64> {
    let r = pose.rotation.to_rotation_matrix().into_inner();
    let tx = visnav_core::se3::skew(&pose.translation.vector);
    let mut ad = Matrix6::zeros();
    ad.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    ad.fixed_view_mut::<3, 3>(0, 3).copy_from(&(tx * r));
    ad.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    ad
}

/// The covariance of the step between frames `a` (earlier) and `b` of poses `cam_from_world`
/// with left increments: `cur_from_prev = T_b·T_a⁻¹` perturbs as `exp(ξ_b − Ad(cur_from_prev)·ξ_a)`,
/// so `prev_from_cur = T_a·T_b⁻¹` perturbs on the right by the negative of that twist, in the
/// frame-`b` camera. `joint` is the 12x12 covariance of `(ξ_a, ξ_b)`.
#[must_use]
pub fn relative_step_covariance(
    cur_from_prev: &Pose,
    joint: &nalgebra::SMatrix<f64, 12, 12>,
) -> Matrix6<f64> {
    let mut j = nalgebra::SMatrix::<f64, 6, 12>::zeros();
    j.fixed_view_mut::<6, 6>(0, 0)
        .copy_from(&(-adjoint(cur_from_prev)));
    j.fixed_view_mut::<6, 6>(0, 6)
        .copy_from(&Matrix6::identity());
    let c = j * joint * j.transpose();
    (c + c.transpose()) * 0.5
}

impl WindowBa {
    /// The 6x6 covariance of `prev_from_cur` between window frames `prev` and `cur`
    /// (`cam_from_world[prev]⁻¹`'s frame to `cur`'s): a right perturbation
    /// `prev_from_cur_true = prev_from_cur · exp(ε)`, `ε = (v, ω)` in the `cur` camera's frame
    /// (metres and radians, the order of ROS's `nav_msgs/Odometry`: x, y, z, rotation about x,
    /// y, z), from the information of the observations that are not outliers (`outlier_chi2`)
    /// at the current estimate, Huber-weighted. A fixed frame contributes no uncertainty.
    /// `None` when a frame index is outside the window, both are fixed or the information is
    /// singular.
    #[must_use]
    pub fn relative_covariance(
        &self,
        config: &BaConfig,
        (prev, cur): (usize, usize),
        scale: CovarianceScale,
    ) -> Option<Matrix6<f64>> {
        let n_frames = self.cam_from_world.len();
        let fixed = config.fixed_frames;
        if prev >= n_frames || cur >= n_frames || cur < fixed || fixed >= n_frames {
            return None;
        }
        let active: Vec<bool> = self
            .observations
            .iter()
            .map(|o| !self.is_outlier(o, config))
            .collect();
        let info = schur::NormalEquations::build(self, config, &active).reduced_information();
        let reduced = info.nrows();
        let covariance: DMatrix<f64> = info.cholesky()?.inverse();
        let block = |k: usize, l: usize| -> Matrix6<f64> {
            if k < fixed || l < fixed {
                return Matrix6::zeros();
            }
            covariance
                .fixed_view::<6, 6>(6 * (k - fixed), 6 * (l - fixed))
                .into_owned()
        };
        let mut joint = nalgebra::SMatrix::<f64, 12, 12>::zeros();
        joint
            .fixed_view_mut::<6, 6>(0, 0)
            .copy_from(&block(prev, prev));
        joint
            .fixed_view_mut::<6, 6>(0, 6)
            .copy_from(&block(prev, cur));
        joint
            .fixed_view_mut::<6, 6>(6, 0)
            .copy_from(&block(cur, prev));
        joint
            .fixed_view_mut::<6, 6>(6, 6)
            .copy_from(&block(cur, cur));
        let cur_from_prev = self.cam_from_world[cur] * self.cam_from_world[prev].inverse();
        let mut step = relative_step_covariance(&cur_from_prev, &joint);
        if scale.residual_variance {
            step *= self.residual_variance(config, &active, reduced)?;
        }
        step *= scale.inflation;
        step.iter().all(|v| v.is_finite()).then_some(step)
    }

    /// `Σ ρ′(‖r̃‖²)·‖r̃‖² / (m − n)` over the active observations (`m` residual components, `n`
    /// unknowns: the free poses' and the rig's rows of the reduced system plus 3 per point);
    /// `None` without redundancy or when it is 0 (exact measurements: no variance to scale by).
    fn residual_variance(&self, config: &BaConfig, active: &[bool], reduced: usize) -> Option<f64> {
        let mut sum = 0.0;
        let mut components = 0usize;
        let mut points = vec![false; self.points_w.len()];
        for (o, _) in self.observations.iter().zip(active).filter(|(_, a)| **a) {
            let Some(s) = self.whitened_sq(o) else {
                continue;
            };
            sum += huber_weight(s, config.huber_px) * s;
            components += if o.right_u_px.is_some() { 3 } else { 2 };
            points[o.point] = true;
        }
        let unknowns = reduced + 3 * points.iter().filter(|p| **p).count();
        let variance = sum / components.checked_sub(unknowns).filter(|d| *d > 0)? as f64;
        (variance > 0.0).then_some(variance)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector6};
    use visnav_core::se3::{se3_exp, se3_log};

    /// The propagation of `relative_step_covariance` against finite differences of the step.
    #[test]
    fn relative_step_jacobian_matches_finite_differences() {
        let ta = Isometry3::from_parts(
            Translation3::new(0.3, -0.2, 1.0),
            UnitQuaternion::from_euler_angles(0.1, -0.2, 0.05),
        );
        let tb = Isometry3::from_parts(
            Translation3::new(-0.1, 0.4, 2.5),
            UnitQuaternion::from_euler_angles(-0.05, 0.3, 0.2),
        );
        let prev_from_cur = ta * tb.inverse();
        let h = 1e-6;
        // ε(ξ_a, ξ_b) = log(prev_from_cur⁻¹ · prev_from_cur(ξ)) — column by column
        let mut j = nalgebra::SMatrix::<f64, 6, 12>::zeros();
        for c in 0..12 {
            let mut xi = Vector6::zeros();
            xi[c % 6] = h;
            let (a, b) = if c < 6 {
                (se3_exp(&xi) * ta, tb)
            } else {
                (ta, se3_exp(&xi) * tb)
            };
            let eps = se3_log(&(prev_from_cur.inverse() * (a * b.inverse())));
            j.set_column(c, &(eps / h));
        }
        // a covariance on (ξ_a, ξ_b) with correlations
        let l = nalgebra::SMatrix::<f64, 12, 12>::from_fn(|r, c| {
            if c <= r {
                0.1 + ((r * 7 + c * 3) % 5) as f64 * 0.05
            } else {
                0.0
            }
        });
        let joint = l * l.transpose();
        let expected = j * joint * j.transpose();
        let got = relative_step_covariance(&(tb * ta.inverse()), &joint);
        let err = (got - expected).abs().max();
        assert!(err < 1e-4 * expected.abs().max(), "error {err}");
    }

    /// A window of 4 frames (the first fixed) and 40 points seen by all, noise-free.
    fn window() -> (WindowBa, BaConfig) {
        let rig = visnav_core::StereoCamera::new(visnav_core::PinholeCamera::kitti_default(), 0.54)
            .unwrap();
        let cam_from_world: Vec<Pose> = (0..4)
            .map(|k| {
                let k = f64::from(k);
                Isometry3::from_parts(
                    Translation3::new(0.02 * k, -0.01 * k, -0.8 * k),
                    UnitQuaternion::from_euler_angles(0.003 * k, -0.01 * k, 0.002 * k),
                )
            })
            .collect();
        let points_w: Vec<nalgebra::Point3<f64>> = (0..40)
            .map(|i| {
                let i = f64::from(i);
                nalgebra::Point3::new(
                    (i % 8.0) * 1.5 - 6.0,
                    (i / 8.0).floor() - 2.0,
                    10.0 + (i * 7.0) % 13.0,
                )
            })
            .collect();
        let mut observations = Vec::new();
        for (frame, t) in cam_from_world.iter().enumerate() {
            for (point, x) in points_w.iter().enumerate() {
                let p = t * x;
                let c = &rig.left;
                observations.push(crate::ba::Observation {
                    frame,
                    point,
                    left_px: nalgebra::Point2::new(
                        c.fx * p.x / p.z + c.cx,
                        c.fy * p.y / p.z + c.cy,
                    ),
                    // the last points have no right match
                    right_u_px: (point < 32).then(|| c.fx * (p.x - rig.baseline_m) / p.z + c.cx),
                    sigma_px: 0.5,
                    right_sigma_px: 0.7,
                });
            }
        }
        let ba = WindowBa {
            rig,
            cam_from_world,
            points_w,
            observations,
        };
        (ba, BaConfig::default())
    }

    /// The Schur complement's pose covariance equals the pose block of the inverse of the full
    /// Hessian (poses, points and the rig's offset), formed densely.
    #[test]
    fn the_marginal_equals_the_dense_inverse() {
        for offset in [false, true] {
            let (ba, mut config) = window();
            config.estimate_right_cx_offset = offset;
            let free = ba.cam_from_world.len() - config.fixed_frames;
            let n = 6 * free + 3 * ba.points_w.len() + usize::from(offset);
            let mut h = DMatrix::<f64>::zeros(n, n);
            for o in &ba.observations {
                let lin = crate::ba::StereoResidual::new(&ba.rig, o)
                    .linearise(&ba.cam_from_world[o.frame], &ba.points_w[o.point])
                    .unwrap();
                let mut j = DMatrix::<f64>::zeros(3, n);
                if o.frame >= config.fixed_frames {
                    j.view_mut((0, 6 * (o.frame - 1)), (3, 6))
                        .copy_from(&lin.d_pose);
                }
                j.view_mut((0, 6 * free + 3 * o.point), (3, 3))
                    .copy_from(&lin.d_point);
                if offset {
                    j.view_mut((0, n - 1), (3, 1)).copy_from(&lin.d_offset);
                }
                h += j.transpose() * j;
            }
            let dense = h.cholesky().unwrap().inverse();
            let scale = CovarianceScale {
                residual_variance: false,
                inflation: 1.0,
            };
            // frames 2 and 3: both free
            let mut joint = nalgebra::SMatrix::<f64, 12, 12>::zeros();
            joint.copy_from(&dense.view((6, 6), (12, 12)));
            let expected = relative_step_covariance(
                &(ba.cam_from_world[3] * ba.cam_from_world[2].inverse()),
                &joint,
            );
            let got = ba.relative_covariance(&config, (2, 3), scale).unwrap();
            let err = (got - expected).abs().max();
            assert!(
                err < 1e-6 * expected.abs().max(),
                "offset {offset}: error {err}"
            );
            // a step from the fixed frame: the newest pose's own block
            let from_fixed = ba.relative_covariance(&config, (0, 1), scale).unwrap();
            let own: Matrix6<f64> = dense.fixed_view::<6, 6>(0, 0).into_owned();
            assert!((from_fixed - own).abs().max() < 1e-6 * own.abs().max());
            // noise-free: no residual variance to scale by, so no covariance (not a zero one)
            let scaled = CovarianceScale {
                residual_variance: true,
                inflation: 2.0,
            };
            assert!(ba.relative_covariance(&config, (2, 3), scaled).is_none());
            // the inflation scales it
            let inflated = CovarianceScale {
                residual_variance: false,
                inflation: 2.0,
            };
            let twice = ba.relative_covariance(&config, (2, 3), inflated).unwrap();
            assert!((twice - 2.0 * got).abs().max() < 1e-12 * got.abs().max());
            // indices outside the window or a fixed newest frame: none
            assert!(ba.relative_covariance(&config, (2, 4), scale).is_none());
            assert!(ba.relative_covariance(&config, (1, 0), scale).is_none());
        }
    }
}
