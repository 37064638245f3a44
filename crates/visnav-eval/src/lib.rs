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
//!
//! The KITTI metric of an estimate 1 % too long along a straight 400 m drive (a bit over 1 %:
//! as in the devkit, a segment of `L` metres ends at the first frame more than `L` metres on):
//!
//! ```
//! use visnav_eval::kitti::{KittiMetricConfig, kitti_score, sequence_errors};
//! use visnav_eval::PoseMatrix;
//!
//! let along = |z: f64| PoseMatrix::new_translation(&nalgebra::Vector3::new(0.0, 0.0, z));
//! let truth: Vec<PoseMatrix> = (0..401).map(|i| along(f64::from(i))).collect();
//! let estimate: Vec<PoseMatrix> = (0..401).map(|i| along(1.01 * f64::from(i))).collect();
//! let config = KittiMetricConfig::default();
//! let score = kitti_score(&sequence_errors(&truth, &estimate, &config, 0), &config.lengths_m);
//! assert!(score.t_err_percent > 1.0 && score.t_err_percent < 1.02, "{}", score.t_err_percent);
//! assert!(score.r_err_deg_per_100m.abs() < 1e-6);
//! ```

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
