//! Evaluation of visnav; depends on no estimator.
//!
//! * [`kitti`]: the KITTI odometry metric exactly as the official devkit
//!   (`evaluate_odometry.cpp`) computes it, with per-length and per-speed breakdowns.
//! * [`align`]: Umeyama SE(3)/Sim(3) alignment and the absolute trajectory error (ATE).
//! * [`rpe`]: relative pose error.
//! * [`associate`]: matching frames by timestamp.
//! * [`report`]: [`evaluate`] scores one or several (ground truth, estimate) pairs at once.
//! * [`plot`]: top view and error-vs-length plots (PNG and SVG).
//! * [`flow`]: flow metrics.
//! * [`palindrome`]: the drift of a palindrome run (§6.2 of the monocular paper).

pub mod align;
pub mod associate;
pub mod error;
pub mod flow;
pub mod kitti;
pub mod palindrome;
pub mod plot;
pub mod report;
pub mod rpe;

pub use error::EvalError;

/// A `world_from_cam` pose as a homogeneous 4x4 matrix, kept exactly as read from a trajectory
/// file (not re-orthonormalised), which is what the devkit scores.
pub type PoseMatrix = nalgebra::Matrix4<f64>;

pub use visnav_core::se3::path_length_m;

/// The homogeneous matrices of poses.
#[must_use]
pub fn pose_matrices(poses: &[visnav_core::Pose]) -> Vec<PoseMatrix> {
    poses
        .iter()
        .map(visnav_core::Pose::to_homogeneous)
        .collect()
}
pub use report::{EvalConfig, EvalReport, TrajectoryPair, evaluate};
