//! What the monocular odometry reports of a frame: which estimator gave the pose, where its
//! scale came from, the stage measurements and timings (§5).

use std::time::Instant;

use serde::{Deserialize, Serialize};
use visnav_core::Pose;

use crate::RelativeMotion;

/// Which estimator produced a frame's pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseSource {
    /// The first frame (identity).
    Initial,
    /// The Mahalanobis (or ablation) eight-point with the estimated scale.
    EightPoint,
    /// PnP on the previous depth map (low parallax, or no eight-point solution).
    Pnp,
    /// Average of the eight-point and PnP poses (§5 fusion rule).
    Fused,
    /// Constant-velocity prediction (the frame failed).
    ConstantVelocity,
}

/// Where the eight-point translation scale came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScaleSource {
    /// No eight-point pose this frame.
    None,
    /// Ground plane and camera height only.
    Ground,
    /// Median depth ratio against the previous depth map only.
    DepthRatio,
    /// Average of both (ground vehicles); aerial: the depth ratio combined with the tracked
    /// ground (`ScaleConfig::aerial_ground_weight`).
    GroundAndDepth,
    /// Aerial re-initialisation from the ground with the re-estimated height.
    GroundReinit,
    /// Aerial, without a depth ratio: the ground tracked from the initialisation, found near
    /// where the previous scale expects it, with the tracked camera height.
    TrackedGround,
    /// Aerial initialisation from a known distance between two points of the first image.
    KnownDistance,
    /// Ground vehicles: the chosen scale multiplied by the median ratio of the recent ground-plane
    /// candidates to the chosen scales, when the depth-ratio chain has drifted from the ground
    /// (see `ScaleConfig::reanchor_ratio`).
    GroundReanchor,
    /// Neither available or plausible: the PnP translation length.
    Pnp,
    /// Neither available or plausible and no PnP: the previous frame's translation length.
    Previous,
}

/// Outcome of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrameStatus {
    /// A pose was estimated.
    Ok,
    /// Too little parallax: the pose comes from PnP alone (or from the eight-point when no depth
    /// prior exists yet).
    LowParallax,
    /// No estimator succeeded: constant-velocity prediction.
    Failed,
}

/// Wall-clock time per stage, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct StageTimings {
    /// Grid subsampling of the flow.
    pub correspondences_ms: f64,
    /// Shi–Tomasi + KLT and flow percentile.
    pub parallax_ms: f64,
    /// Guided RANSAC, eight-point refinement and essential decomposition.
    pub eight_point_ms: f64,
    /// Dense triangulation on the depth grid (both passes).
    pub triangulation_ms: f64,
    /// Ground plane and depth ratio.
    pub scale_ms: f64,
    /// PnP RANSAC and refinement.
    pub pnp_ms: f64,
    /// Depth-map fusion and propagation.
    pub depth_ms: f64,
    /// The window adjustment (`window.mode`): tracks and bundle adjustment.
    #[serde(default)]
    pub window_ms: f64,
    /// The whole frame.
    pub total_ms: f64,
}

/// Result of one frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MonoFrameResult {
    /// Frame index (0 = the first image).
    pub frame: usize,
    /// Pose of the current camera in the world (= first camera) frame.
    pub world_from_cam: Pose,
    /// The pose of this camera in the previous camera's frame (`x_prev = prev_from_cur · x_cur`),
    /// metres; the identity's inverse at a first image.
    pub prev_from_cur: Pose,
    /// The frame's motion as the odometry computed it (`prev_from_cur` with its inverse, both
    /// as first computed), `None` at a first image (and after a restart): the constant-velocity
    /// prior the driver keeps and hands to the next [`super::MonoOdometry::process`] (a frame
    /// without one leaves the prior as it was).
    #[serde(skip)]
    pub motion: Option<RelativeMotion>,
    /// The 6x6 covariance of `prev_from_cur` (right perturbation in this
    /// camera, `(v, ω)`, metres and radians; [`super::covariance`]); `None` without an estimate
    /// of its own or without PnP.
    #[serde(skip)]
    pub prev_from_cur_covariance: Option<nalgebra::Matrix6<f64>>,
    /// Which estimator produced the pose.
    pub source: PoseSource,
    /// Where the scale came from.
    pub scale_source: ScaleSource,
    /// Eight-point translation length, metres (NaN without an eight-point pose).
    pub scale_m: f64,
    /// Ground-plane scale candidate, metres.
    pub scale_ground_m: Option<f64>,
    /// Depth-ratio scale candidate, metres.
    pub scale_depth_m: Option<f64>,
    /// Median KLT displacement, pixels (None when not run or nothing tracked).
    pub klt_median_px: Option<f64>,
    /// 75th percentile of the valid flow magnitude, pixels.
    pub flow_p75_px: f64,
    /// Median translational parallax (flow after removing the rotation), pixels; None when no
    /// rotation estimate exists. See [`super::translational_parallax_px`].
    pub translational_parallax_px: Option<f64>,
    /// Grid correspondences used by the eight-point.
    pub correspondences: usize,
    /// Eight-point RANSAC inliers.
    pub eight_point_inliers: usize,
    /// GRIC of the fundamental matrix minus the homography's, per correspondence, when the
    /// homography was fitted (`homography.selection`); the eight-point stage's motion came from
    /// the homography when it exceeds `homography.min_gric_gain`.
    pub homography_gric_gain: Option<f64>,
    /// PnP correspondences and inliers.
    pub pnp_correspondences: usize,
    /// PnP inliers.
    pub pnp_inliers: usize,
    /// Known cells of the fused depth map.
    pub depth_cells: usize,
    /// Points of the window adjustment (0 when off or when it did not run).
    pub window_points: usize,
    /// Stage timings.
    pub timings: StageTimings,
    /// Outcome.
    pub status: FrameStatus,
}

/// Milliseconds since `t`.
pub(super) fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
