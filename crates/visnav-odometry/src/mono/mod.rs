//! Monocular visual odometry from dense optical flow with uncertainty (Ng, Li, Kim 2021, §4–5).
//!
//! Per frame `k`, given the dense flow `k−1 → k` with its information matrices
//! ([`visnav_flow::DenseFlow`]):
//!
//! 1. **Correspondences** ([`correspondences_from_flow`]): the flow is subsampled on a grid of
//!    `grid_cell_px` cells, keeping in each cell the valid pixel of highest certainty
//!    `sqrt(det Y)` (a few thousand matches instead of ~100k; RANSAC and the re-weighted
//!    eight-point then cost a few ms).
//! 2. **Parallax test** (§5): median Shi–Tomasi/KLT displacement ≥ 2.5 px *and* 75th percentile of
//!    the flow magnitude > 5 px; otherwise the motion comes from PnP alone. In addition (not in
//!    the paper) the *translational* parallax — the median flow left after removing the rotation
//!    through `K R K⁻¹` ([`translational_parallax_px`]) — must reach
//!    `parallax.min_translational_parallax_px`: standing still or rotating on the spot, the
//!    eight-point translation is undefined and a triangulation has no baseline, so the pose comes
//!    from PnP and the depth map is propagated without new triangulations (fusing those
//!    near-zero depths used to lock the depth-ratio scale near zero after a spin).
//! 3. **Eight-point** (§4): uncertainty-guided RANSAC + Mahalanobis eight-point (or the ablation
//!    estimators), `E = KᵀFK`, cheirality → a unit-translation motion (computed as
//!    `cur_from_prev`, the convention of the epipolar geometry and of projecting into the
//!    current image).
//! 4. **Scale** (§5): dense triangulation on the depth grid (`depth_stride_px`) with per-cell
//!    depth variance; (a) ground plane `s = −(b·h)/d`, (b) median ratio of the previous fused depth
//!    map to the new unit-scale depths. Ground vehicles average both; `aerial` uses the ground for
//!    the first frame only and depth ratios after, re-initialising from the ground with the
//!    re-estimated height when fewer than 5 % of the cells overlap.
//! 5. **PnP** from the previous depth map and the flow, **fusion** (scales within 30 %,
//!    rotations within 0.5 rad → average; else eight-point).
//! 6. **Depth maps**: the scaled triangulation fused with the prior by inverse variance, then
//!    propagated into frame `k` by the estimated pose (prior and scale reference of frame `k+1`).
//!
//! The code follows the stages: [`MonoOdometry`] (`odometry.rs`) runs the **tracker**
//! (`tracker.rs`: steps 1–3 and 5, the motion; it keeps the last accepted image and returns
//! `Estimate::Accepted` or `Estimate::Refused(reason)`), then the **mapper** (`mapper.rs`: the
//! scale of step 4 through the scale keeper `scale/` — the ground vehicles' rules there, the
//! aerial ones in `scale/aerial.rs` — the window, and the depth maps of step 6), and commits
//! their results only when it accepts the frame. The report types are in `result.rs`.
//!
//! Frames: `world_from_cam` with world = the first camera; a frame's motion is reported as
//! `prev_from_cur` (the current camera in the previous camera's frame,
//! [`MonoFrameResult::prev_from_cur`]) and handed between the stages as a
//! [`crate::RelativeMotion`], which names the direction at every use; the estimators and the
//! projections inside compute `cur_from_prev` (maps points of the previous camera into the
//! current one). Depths are metres along the optical axis.

mod config;
mod context;
mod correspondence;
pub mod covariance;
mod depth;
pub mod eight_point;
mod error;
mod evidence;
mod flow;
mod mapper;
mod odometry;
mod point_scale;
mod relative;
mod result;
pub mod rigidity;
mod scale;
mod tracker;
pub mod trust;
mod window;

pub use config::{
    DepthPoints, GroundSearch, HomographyConfig, HomographySelection, KnownDistance, MonoConfig,
    ParallaxConfig, ScaleConfig,
};
pub use correspondence::{
    correspondences_from_flow, flow_percentile_px, translational_parallax_px,
};
pub use depth::DepthMap;
pub use error::MonoError;
pub use flow::{MonoFlow, MonoFlowConfig, upsample_dense_flow};
pub use odometry::MonoOdometry;
pub use relative::{RelativePose, relative_pose_from_flow};
pub use result::{FrameStatus, MonoFrameResult, PoseSource, ScaleSource, StageTimings};
pub use trust::{TrustConfig, UntrustedReason};
pub use window::{MonoWindowConfig, WindowMode, WindowScale, flow_jacobian, follow_flow};
