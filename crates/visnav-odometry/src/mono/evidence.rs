//! What the rigid-motion trust test weighs (`super::rigidity`): the motion's agreement with the
//! previous frame's and the frame's evidence, below both the test and the reasons a frame is
//! refused (`super::trust::UntrustedReason` carries them).

use serde::Serialize;

use crate::RelativeMotion;

/// A previous motion shorter than this has no direction to compare with, metres.
const MIN_DIRECTION_TRANSLATION_M: f64 = 1e-3;

/// How the frame's estimated motion compares with the previous accepted frame's.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MotionAgreement {
    /// Angle of the rotation between the two motions' rotations, degrees.
    pub rotation_change_deg: f64,
    /// Angle between the two motions' translation directions, degrees; `None` when the
    /// previous motion had (almost) no translation.
    pub translation_angle_deg: Option<f64>,
}

impl MotionAgreement {
    /// `motion` (any translation scale) against `last` (the previous frame's motion, metres);
    /// both compared as their `cur_from_prev`, the eight-point's output.
    #[must_use]
    pub fn of(motion: &RelativeMotion, last: &RelativeMotion) -> Self {
        let (cur_from_prev, last) = (motion.cur_from_prev(), last.cur_from_prev());
        let rotation_change_deg = (last.rotation.inverse() * cur_from_prev.rotation)
            .angle()
            .to_degrees();
        let t_last = last.translation.vector;
        let t_cur = cur_from_prev.translation.vector;
        let translation_angle_deg = (t_last.norm() >= MIN_DIRECTION_TRANSLATION_M
            && t_cur.norm() > 0.0)
            .then(|| t_last.angle(&t_cur).to_degrees());
        Self {
            rotation_change_deg,
            translation_angle_deg,
        }
    }
}

/// What the rigid-motion test weighs for one frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RigidMotionEvidence {
    /// Eight-point RANSAC inliers.
    pub inliers: usize,
    /// Grid correspondences.
    pub correspondences: usize,
    /// The estimated motion against the previous accepted frame's; `None` without either.
    pub agreement: Option<MotionAgreement>,
    /// Share of the frame's flow that passed the forward–backward check.
    pub valid_fraction: f64,
    /// Median of that share over the last accepted frames; `None` before the first.
    pub typical_valid_fraction: Option<f64>,
}

impl RigidMotionEvidence {
    /// The evidence of a frame: `inliers` of `correspondences` fit the motion model (the
    /// eight-point model, or the homography where it wins the model selection) whose
    /// motion is `unit_motion` (unit translation); `last_motion` is the previous accepted
    /// frame's motion; `valid_fraction` the flow's forward–backward share,
    /// `typical_valid_fraction` its median over the last accepted frames.
    #[must_use]
    pub fn measure(
        (inliers, correspondences): (usize, usize),
        (unit_motion, last_motion): (Option<&RelativeMotion>, Option<&RelativeMotion>),
        (valid_fraction, typical_valid_fraction): (f64, Option<f64>),
    ) -> Self {
        Self {
            inliers,
            correspondences,
            agreement: unit_motion
                .zip(last_motion)
                .map(|(cur, last)| MotionAgreement::of(cur, last)),
            valid_fraction,
            typical_valid_fraction,
        }
    }

    /// The flow's valid share over the typical one (`None` before the first accepted flow or
    /// when that was empty).
    #[must_use]
    pub fn valid_ratio(&self) -> Option<f64> {
        self.typical_valid_fraction
            .filter(|t| *t > 0.0)
            .map(|t| self.valid_fraction / t)
    }

    /// Share of the correspondences that fit the eight-point model (0 without any).
    #[must_use]
    pub fn inlier_fraction(&self) -> f64 {
        if self.correspondences == 0 {
            0.0
        } else {
            self.inliers as f64 / self.correspondences as f64
        }
    }
}

impl std::fmt::Display for RigidMotionEvidence {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let deg = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.2}°"));
        write!(
            f,
            "{} of {} inliers ({:.2} %), rotation change {}, translation angle {}, flow valid {:.1} % (typical {})",
            self.inliers,
            self.correspondences,
            100.0 * self.inlier_fraction(),
            deg(self.agreement.map(|a| a.rotation_change_deg)),
            deg(self.agreement.and_then(|a| a.translation_angle_deg)),
            100.0 * self.valid_fraction,
            self.typical_valid_fraction
                .map_or_else(|| "-".to_owned(), |t| format!("{:.1} %", 100.0 * t)),
        )
    }
}
