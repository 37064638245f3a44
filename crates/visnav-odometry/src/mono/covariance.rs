//! The covariance of each monocular step (issue 55 item 5; not in the paper).
//!
//! A frame whose pose is the estimator's own (eight-point, PnP or their fusion) gets the 6x6
//! covariance of `prev_from_cur` as a right perturbation `prev_from_cur_true = prev_from_cur ·
//! exp(ε)`, `ε = (v, ω)` in the current camera's frame, metres and radians (ROS's
//! `nav_msgs/Odometry` order), as the stereo steps do (`crate::stereo::covariance`). It has two
//! parts:
//!
//! * **the alignment's**: the inverse of the Gauss–Newton Hessian `Σ Jᵀ Y J` of the PnP inliers
//!   against the fused depth map ([`pnp_information`]), `Y` the flow's per-pixel information
//!   (eq. 1–4, the uncertainty the Mahalanobis eight-point and PnP weigh by), times a global
//!   [`MonoCovarianceConfig::inflation`]: the Hessian treats the depth map as exact (the
//!   real-time preset adds the depth map's relative error to each correspondence,
//!   [`MonoCovarianceConfig::depth_sigma`], and widens steps across the view,
//!   [`MonoCovarianceConfig::across_view`]);
//! * **the scale's**: a monocular step's length is the scale keeper's (the ground plane, the
//!   depth ratios, §4.3), whose error the Hessian does not see; it adds
//!   `(scale_sigma · |t|)²` along the step's direction ([`MonoCovarianceConfig::scale_sigma`]);
//! * **the two lengths' disagreement**: the step has two length estimates, the scale keeper's
//!   (the eight-point translation scaled by the ground and the depth ratios) and the final
//!   step's (PnP against the depth map, fused, refined by the window); where they differ by `Δ`
//!   at least one is off by about that much, so `(disagreement_weight · Δ)²` is added along the
//!   step too ([`MonoCovarianceConfig::disagreement_weight`]). It is what sees a flight's map
//!   scale drifting from the ground's (15 % long steps) and its gross steps (0.9 m off on 2.4 m).
//!
//! The three factors were calibrated on rendered training drives and flights only, so that the
//! normalized estimation error squared follows χ²₆ (docs/benchmarks.md, *Step covariance*; the
//! test `mono_covariance` in `visnav-pipeline` checks held-out drives). A frame without PnP (no depth
//! map yet, too few inliers) or whose pose is a prediction has none (`None`).

use crate::RelativeMotion;
use nalgebra::{Matrix2, Matrix3, Matrix6, Vector2, Vector3};
use serde::{Deserialize, Serialize};
use visnav_core::PinholeCamera;
use visnav_geometry::pnp::{PnpCorrespondence, PnpResult, projection_jacobian};

/// How each monocular step's covariance is computed (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MonoCovarianceConfig {
    /// Compute it. Default true.
    pub enabled: bool,
    /// Factor on the inverse of the PnP Hessian. The Hessian counts every one of the ~3,000
    /// flow correspondences as an independent measurement, but their errors share the depth map
    /// they are measured against: on the rendered training drives (seeds 1–3, 60 frames of
    /// 480x144, the camera height given) its σ were 0.4 mm and 1 mdeg against step errors of
    /// 3–66 mm and 6–26 mdeg. The three factors are fitted together on rendered training drives
    /// (seeds 1–3) and flights (forward seed 1, downward seed 2, 30 m): the triple on a grid
    /// (factor 25 apart; σ 0.02–0.08; weight 0–2 by 0.5) whose mean NEES is nearest 6 with at
    /// most 8 % of the steps above χ²₆'s 95 % quantile (a margin under the 10 %): mean
    /// 6.00, 7.9 %. Default 850.
    pub inflation: f64,
    /// Relative standard deviation of a step's length (the scale keeper's error, which PnP's
    /// Hessian does not see), added along the step's direction. Default 0.04 (fitted with
    /// [`Self::inflation`]).
    pub scale_sigma: f64,
    /// Weight of the disagreement of the step's two lengths (the scale keeper's and the final
    /// step's, see the module docs), added along the step as `(weight · Δ)²`; 0 switches it
    /// off. Default 2 (fitted with [`Self::inflation`]).
    pub disagreement_weight: f64,
    /// Relative standard deviation of the depth map's depths that PnP is measured against
    /// (`σ_Z / Z`), which the Hessian otherwise treats as exact: each inlier's flow information
    /// `Y` becomes `(Y⁻¹ + σ² d dᵀ)⁻¹`, `d` the pixel shift of its projection for a relative
    /// change of its depth (`J_π(p)·(p − c)`, `c` the previous camera's centre in the current
    /// camera). `d` grows with the step's translational flow, so the term weighs most where
    /// the camera moves across the view (a downward camera). 0 switches it off. Default 0 (the
    /// paper preset's three factors were fitted without it).
    pub depth_sigma: f64,
    /// Extra factor on [`Self::inflation`] for a step across the view: the Hessian part is
    /// multiplied by `1 + across_view · sin²θ`, `θ` the angle between the step and the optical
    /// axis (0 for a forward camera driving ahead, 90° for a downward camera flying level).
    /// Across the view a translation and a rotation move the image alike (the flow of a
    /// sideways step of `b` at depth `Z` is that of a rotation by `b/Z`), and the fast flow's
    /// errors, correlated over the image, follow that ambiguity further than the Hessian says.
    /// 0 switches it off. Default 0 (the paper preset's factors were fitted without it).
    pub across_view: f64,
}

impl Default for MonoCovarianceConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            inflation: 850.0,
            scale_sigma: 0.04,
            disagreement_weight: 2.0,
            depth_sigma: 0.0,
            across_view: 0.0,
        }
    }
}

impl MonoCovarianceConfig {
    /// The first invalid field as `(name, value, expected)`.
    #[must_use]
    pub fn invalid_field(&self) -> Option<(&'static str, f64, &'static str)> {
        if !(self.inflation.is_finite() && self.inflation > 0.0) {
            return Some(("covariance.inflation", self.inflation, "finite and > 0"));
        }
        if !(self.scale_sigma.is_finite() && self.scale_sigma >= 0.0) {
            return Some(("covariance.scale_sigma", self.scale_sigma, "finite and ≥ 0"));
        }
        if !(self.disagreement_weight.is_finite() && self.disagreement_weight >= 0.0) {
            return Some((
                "covariance.disagreement_weight",
                self.disagreement_weight,
                "finite and ≥ 0",
            ));
        }
        if !(self.depth_sigma.is_finite() && self.depth_sigma >= 0.0) {
            return Some(("covariance.depth_sigma", self.depth_sigma, "finite and ≥ 0"));
        }
        if !(self.across_view.is_finite() && self.across_view >= 0.0) {
            return Some(("covariance.across_view", self.across_view, "finite and ≥ 0"));
        }
        None
    }
}

/// The Gauss–Newton Hessian `Σ Jᵀ Y J` of `result`'s inliers at its pose (eq. 1's information
/// `Y` of each correspondence's flow), for the left perturbation `exp(δ) · cam_from_world`,
/// `δ = (v, ω)` in the camera (1/m², 1/rad²). The "world" is the previous camera (PnP against
/// its depth map); with `depth_sigma > 0` each `Y` also carries the depth map's relative error
/// ([`MonoCovarianceConfig::depth_sigma`]).
#[must_use]
pub fn pnp_information(
    camera: &PinholeCamera,
    data: &[PnpCorrespondence],
    result: &PnpResult,
    depth_sigma: f64,
) -> Matrix6<f64> {
    // the previous camera's centre (the world's origin) in the current camera
    let prev_centre = result.cam_from_world.translation.vector;
    let mut information = Matrix6::zeros();
    for (c, _) in data.iter().zip(&result.inliers).filter(|(_, ok)| **ok) {
        let p = result.cam_from_world * c.p_in_world;
        if p.z > 0.0 {
            let j = projection_jacobian(camera, &p);
            let y = if depth_sigma > 0.0 {
                // ∂π/∂p (the first three columns) times ∂p/∂ln Z = p − c
                let d: Vector2<f64> = j.fixed_columns::<3>(0) * (p.coords - prev_centre);
                with_depth_error(&c.information, &d, depth_sigma)
            } else {
                c.information
            };
            information += j.transpose() * y * j;
        }
    }
    information
}

/// `(Y⁻¹ + σ² d dᵀ)⁻¹` by Sherman–Morrison: `Y − σ² Y d dᵀ Y / (1 + σ² dᵀ Y d)`.
fn with_depth_error(y: &Matrix2<f64>, d: &Vector2<f64>, sigma: f64) -> Matrix2<f64> {
    let yd = y * d;
    let s2 = sigma * sigma;
    y - yd * yd.transpose() * (s2 / (1.0 + s2 * d.dot(&yd)))
}

/// The covariance of the step's `prev_from_cur` (see the module docs) from the PnP information
/// at the current camera and the disagreement of the step's two lengths,
/// `length_disagreement_m` (the final step's length minus the scale keeper's, metres; 0 when
/// the keeper had none); `None` when disabled or the information is singular.
///
/// `exp(δ)·cur_from_prev` is `prev_from_cur · exp(−δ)`: the left perturbation of `cur_from_prev`
/// and the right one of `prev_from_cur` live in the same (current) camera frame and share their
/// covariance.
#[must_use]
pub fn step_covariance(
    config: &MonoCovarianceConfig,
    pnp_information: &Matrix6<f64>,
    step: &RelativeMotion,
    length_disagreement_m: f64,
) -> Option<Matrix6<f64>> {
    if !config.enabled {
        return None;
    }
    // the step's direction in the current camera: prev_from_cur's translation is R·(−tᶜ) with
    // tᶜ cur_from_prev's, so a longer step moves the current camera along −tᶜ in its own frame
    let t: Vector3<f64> = -step.cur_from_prev().translation.vector;
    let length_m = t.norm();
    let inflation = if config.across_view > 0.0 && length_m > 0.0 {
        // sin² of the angle between the step and the optical axis (z)
        let sin2 = 1.0 - (t.z / length_m).powi(2);
        config.inflation * (1.0 + config.across_view * sin2)
    } else {
        config.inflation
    };
    let mut covariance = pnp_information.try_inverse()? * inflation;
    let disagreement = if length_disagreement_m.is_finite() && length_m > 0.0 {
        (config.disagreement_weight * length_disagreement_m / length_m).powi(2)
    } else {
        0.0
    };
    let along: Matrix3<f64> = t * t.transpose() * (config.scale_sigma.powi(2) + disagreement);
    let mut block = covariance.fixed_view_mut::<3, 3>(0, 0);
    block += along;
    covariance = (covariance + covariance.transpose()) * 0.5;
    let finite = covariance.iter().all(|v| v.is_finite());
    (finite && covariance.cholesky().is_some()).then_some(covariance)
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion};
    use visnav_core::Pose;

    use super::*;

    #[test]
    fn the_scale_term_lies_along_the_step() {
        let info = Matrix6::identity() * 1e6 * MonoCovarianceConfig::default().inflation;
        let step = RelativeMotion::from_cur_from_prev(Pose::from_parts(
            Translation3::new(0.0, 0.0, -1.0),
            UnitQuaternion::identity(),
        ));
        let config = MonoCovarianceConfig::default();
        let c = step_covariance(&config, &info, &step, 0.0).unwrap();
        let s2 = config.scale_sigma.powi(2);
        assert!((c[(2, 2)] - (1e-6 + s2)).abs() < 1e-12);
        assert!((c[(0, 0)] - 1e-6).abs() < 1e-12);
        assert!(step_covariance(&config, &Matrix6::zeros(), &step, 0.0).is_none());
        // a disagreement of the two lengths widens the step's length only
        let d = step_covariance(&config, &info, &step, 0.5).unwrap();
        let w2 = (config.disagreement_weight * 0.5).powi(2);
        assert!((d[(2, 2)] - (1e-6 + s2 + w2)).abs() < 1e-12);
        assert!((d[(0, 0)] - 1e-6).abs() < 1e-12);
        assert_eq!(step_covariance(&config, &info, &step, f64::NAN), Some(c));
        let off = MonoCovarianceConfig {
            enabled: false,
            ..config
        };
        assert!(step_covariance(&off, &info, &step, 0.0).is_none());
        assert!(
            MonoCovarianceConfig {
                inflation: 0.0,
                ..config
            }
            .invalid_field()
            .is_some()
        );
    }

    #[test]
    fn a_step_across_the_view_is_widened_and_one_along_it_is_not() {
        let info = Matrix6::identity() * 1e6;
        let config = MonoCovarianceConfig {
            scale_sigma: 0.0,
            across_view: 3.0,
            ..MonoCovarianceConfig::default()
        };
        let step = |t: Vector3<f64>| {
            RelativeMotion::from_cur_from_prev(Pose::from_parts(
                Translation3::from(-t),
                UnitQuaternion::identity(),
            ))
        };
        let base = config.inflation * 1e-6;
        let ahead = step_covariance(&config, &info, &step(Vector3::z()), 0.0).unwrap();
        assert!((ahead[(4, 4)] - base).abs() < 1e-15);
        let across = step_covariance(&config, &info, &step(Vector3::y()), 0.0).unwrap();
        assert!((across[(4, 4)] - 4.0 * base).abs() < 1e-15);
        // 45°: sin² = 1/2
        let diagonal = step(Vector3::new(0.0, 1.0, 1.0));
        let half = step_covariance(&config, &info, &diagonal, 0.0).unwrap();
        assert!((half[(4, 4)] - 2.5 * base).abs() < 1e-15);
    }

    #[test]
    fn the_depth_error_takes_information_along_the_parallax_only() {
        let y = Matrix2::identity() * 4.0;
        let d = Vector2::new(10.0, 0.0);
        let with = with_depth_error(&y, &d, 0.1);
        // along d: 1 / (1/4 + 0.01·100) = 0.8; across it unchanged
        assert!((with[(0, 0)] - 0.8).abs() < 1e-12);
        assert!((with[(1, 1)] - 4.0).abs() < 1e-12);
        assert!(with[(0, 1)].abs() < 1e-12);
        assert_eq!(with_depth_error(&y, &d, 0.0), y);
    }
}
