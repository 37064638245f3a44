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

use super::{BaConfig, WindowBa, huber_weight, schur};

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
    /// `None` without redundancy.
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
        (components > unknowns).then(|| sum / (components - unknowns) as f64)
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
}
