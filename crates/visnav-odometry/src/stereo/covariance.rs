//! The covariance of each stereo step (issue 55 item 5; not in the RotROCC paper).
//!
//! Every estimated frame's `prev_from_cur` gets a 6x6 covariance: a right perturbation
//! `prev_from_cur_true = prev_from_cur · exp(ε)`, `ε = (v, ω)` in the current left camera's
//! frame, metres and radians, in the order of ROS's `nav_msgs/Odometry` (x, y, z, rotation about
//! x, y, z). It is the estimator's own uncertainty:
//!
//! * with the window bundle adjustment (the default), the inverse of the window's reduced camera
//!   system (points and the rig's offset marginalised by the Schur complement) at the solution,
//!   propagated to the step between the two newest frames ([`crate::ba::covariance`]);
//! * without it (`--no-ba`, or a frame the window did not adjust), the same construction on two
//!   frames: the previous frame fixed, RotROCC's inlier points free with their observation at
//!   t-1 (the projection they were triangulated from) and at t, linearised at RotROCC's estimate
//!   ([`two_frame_covariance`]) — the Hessian of the stereo reprojection error (eq. 2) RotROCC's
//!   translation phase minimises on the DNRE.
//!
//! Either is scaled by the a-posteriori residual variance ([`CovarianceConfig::residual_variance`])
//! and a global inflation factor ([`CovarianceConfig::inflation`]) calibrated on rendered
//! training drives (docs/benchmarks.md, *Step covariance*). A frame without an estimate (the
//! first, a fallback, a skipped frame) has none (`None`): its pose is a prediction, not a
//! measurement, and a filter must be able to tell.

use nalgebra::{Matrix6, Point3};
use visnav_core::{Pose, StereoCamera};

use super::estimate::{MotionEstimate, Observation};
use crate::ba::{BaConfig, Observation as BaObservation, WindowBa};

pub use super::config::CovarianceConfig;

/// The covariance of RotROCC's step `est` from its inlier observations `obs` (module doc):
/// `None` when disabled or the information is singular. `sigmas` are the left pixel's and the
/// right column's standard deviations, pixels.
#[must_use]
pub fn two_frame_covariance(
    rig: &StereoCamera,
    est: &MotionEstimate,
    obs: &[Observation],
    sigmas: (f64, f64),
    config: &CovarianceConfig,
) -> Option<Matrix6<f64>> {
    let scale = config.two_frame_scale()?;
    let mut observations = Vec::new();
    let mut points_w = Vec::new();
    for (o, _) in obs.iter().zip(&est.inliers).filter(|(_, i)| **i) {
        let p = o.p_in_prev;
        if p.z <= 0.0 {
            continue;
        }
        let c = &rig.left;
        let left_prev = nalgebra::Point2::new(c.fx * p.x / p.z + c.cx, c.fy * p.y / p.z + c.cy);
        let right_prev = c.fx * (p.x - rig.baseline_m) / p.z + c.cx + rig.right_cx_offset_px;
        let point = points_w.len();
        points_w.push(Point3::from(p));
        for (frame, left_px, right_u_px) in
            [(0, left_prev, right_prev), (1, o.left_px, o.right_px.x)]
        {
            observations.push(BaObservation {
                frame,
                point,
                left_px,
                right_u_px: Some(right_u_px),
                sigma_px: sigmas.0,
                right_sigma_px: sigmas.1,
            });
        }
    }
    let ba = WindowBa {
        rig: *rig,
        cam_from_world: vec![Pose::identity(), est.motion.cur_from_prev()],
        points_w,
        observations,
    };
    let config = BaConfig {
        fixed_frames: 1,
        ..BaConfig::default()
    };
    ba.relative_covariance(&config, (0, 1), scale)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stereo::StereoConfig;

    #[test]
    fn a_non_positive_inflation_is_refused_by_name() {
        for (inflation, two_frame) in [(0.0, 1.0), (-1.0, 1.0), (f64::NAN, 1.0), (1.0, 0.0)] {
            let mut config = StereoConfig::default();
            config.covariance.inflation = inflation;
            config.covariance.two_frame_inflation = two_frame;
            let e = config.validate().unwrap_err().to_string();
            let field = if two_frame > 0.0 {
                "`covariance.inflation`"
            } else {
                "`covariance.two_frame_inflation`"
            };
            assert!(
                e.contains(field) && e.contains("must be finite and > 0"),
                "{e}"
            );
        }
        assert!(StereoConfig::default().validate().is_ok());
        // a table sets them by name, and an unknown key is an error
        let c: CovarianceConfig =
            serde_json::from_str(r#"{"inflation": 2.0, "enabled": false}"#).unwrap();
        assert_eq!((c.inflation, c.enabled), (2.0, false));
        assert!(serde_json::from_str::<CovarianceConfig>(r#"{"inflaton": 2.0}"#).is_err());
    }
}
