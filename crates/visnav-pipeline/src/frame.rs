//! What goes into the odometry (a [`FrameInput`]) and what comes out for every frame (a
//! [`FrameResult`]).

use serde::{Deserialize, Serialize};
use visnav_core::{GrayImage, Pose};
use visnav_flow::{DenseFlow, FlowTimings};
use visnav_odometry::mono::{DepthMap, PoseSource, ScaleSource, StageTimings as MonoStageTimings};
use visnav_odometry::stereo::{FailReason, FrameCounts, StageTimings as StereoStageTimings, Track};

/// The images of one input frame, or why there are none.
#[derive(Debug, Clone)]
pub enum Images {
    /// One image (monocular odometry; a stereo odometry treats it as a missing right image).
    Mono(GrayImage),
    /// A rectified stereo pair.
    Stereo {
        /// Left (reference) image.
        left: GrayImage,
        /// Right image.
        right: GrayImage,
    },
    /// The frame exists but its images could not be had (unreadable file, dropped message): it
    /// still gets a pose, the constant-velocity prediction, with status [`Status::Skipped`].
    Missing {
        /// Why (the file and the problem).
        reason: String,
    },
}

/// One frame pushed into the odometry.
#[derive(Debug, Clone)]
pub struct FrameInput {
    /// Timestamp, seconds, if known (carried into the result).
    pub timestamp_s: Option<f64>,
    /// The images.
    pub images: Images,
    /// Frames of a live stream dropped just before this one (the frame policy `newest`): the
    /// constant-velocity prediction of this frame then spans the true time step (mono).
    pub dropped_before: usize,
}

impl FrameInput {
    /// A monocular frame.
    #[must_use]
    pub fn mono(image: GrayImage, timestamp_s: Option<f64>) -> Self {
        Self {
            timestamp_s,
            images: Images::Mono(image),
            dropped_before: 0,
        }
    }

    /// A stereo frame.
    #[must_use]
    pub fn stereo(left: GrayImage, right: GrayImage, timestamp_s: Option<f64>) -> Self {
        Self {
            timestamp_s,
            images: Images::Stereo { left, right },
            dropped_before: 0,
        }
    }

    /// A frame whose images are missing.
    #[must_use]
    pub fn missing(reason: impl Into<String>, timestamp_s: Option<f64>) -> Self {
        Self {
            timestamp_s,
            images: Images::Missing {
                reason: reason.into(),
            },
            dropped_before: 0,
        }
    }

    /// The frame of a [`visnav_io::SourceItem`]: its images, or `Missing` with the read error.
    #[must_use]
    pub fn from_item(item: visnav_io::SourceItem) -> Self {
        let images = match item.frame {
            Ok(visnav_io::Frame {
                left,
                right: Some(right),
            }) => Images::Stereo { left, right },
            Ok(visnav_io::Frame { left, right: None }) => Images::Mono(left),
            Err(e) => Images::Missing {
                reason: e.to_string(),
            },
        };
        Self {
            timestamp_s: item.timestamp_s,
            images,
            dropped_before: item.dropped_before,
        }
    }

    /// The left (or only) image, if any.
    #[must_use]
    pub fn left(&self) -> Option<&GrayImage> {
        match &self.images {
            Images::Mono(l) | Images::Stereo { left: l, .. } => Some(l),
            Images::Missing { .. } => None,
        }
    }
}

/// Why a frame's pose is the constant-velocity prediction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum FallbackReason {
    /// The stereo estimation failed (see the stereo reason).
    Stereo {
        /// The stereo pipeline's reason.
        reason: FailReason,
    },
    /// No monocular estimator (eight-point, PnP) gave a pose.
    NoMonoEstimate,
    /// The dense flow from the reference image could not be computed.
    Flow {
        /// The flow stage's error.
        message: String,
    },
    /// The monocular odometry refused the frame (wrong size, untrusted content).
    Refused {
        /// The odometry's error.
        message: String,
    },
    /// The last accepted frame was too far back to match against
    /// (`TrustConfig::max_reference_gap_frames`): the monocular odometry started a new map at
    /// this frame, whose pose is the prediction; the next frames are measured from it.
    Restarted {
        /// The stream position of the last accepted frame.
        last_accepted: usize,
        /// Frames between it and this one.
        gap_frames: usize,
    },
}

/// Outcome of a frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "status")]
pub enum Status {
    /// A pose was estimated (the first frame is `Ok` with the identity).
    Ok,
    /// Little motion: mono took the pose from PnP alone (or the eight-point without a depth
    /// prior), stereo from the low-speed rule (rotation phase only).
    LowParallax,
    /// The pipeline could not estimate the motion: constant-velocity prediction.
    Fallback {
        /// Why.
        reason: FallbackReason,
    },
    /// The input had no usable images: constant-velocity prediction.
    Skipped {
        /// Why (the file and the problem).
        reason: String,
    },
}

impl Status {
    /// `true` for a constant-velocity prediction (fallback or skipped input).
    #[must_use]
    pub fn is_predicted(&self) -> bool {
        matches!(self, Self::Fallback { .. } | Self::Skipped { .. })
    }

    /// A short name: `ok`, `low_parallax`, `fallback`, `skipped`.
    #[must_use]
    pub fn name(&self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::LowParallax => "low_parallax",
            Self::Fallback { .. } => "fallback",
            Self::Skipped { .. } => "skipped",
        }
    }
}

/// Monocular figures of a frame (see [`visnav_odometry::mono::MonoFrameResult`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MonoDetail {
    /// Which estimator produced the pose.
    pub source: PoseSource,
    /// Where the translation scale came from.
    pub scale_source: ScaleSource,
    /// Eight-point translation length, metres.
    pub scale_m: Option<f64>,
    /// Ground-plane scale candidate, metres.
    pub scale_ground_m: Option<f64>,
    /// Depth-ratio scale candidate, metres.
    pub scale_depth_m: Option<f64>,
    /// Median KLT displacement, pixels.
    pub klt_median_px: Option<f64>,
    /// 75th percentile of the valid flow magnitude, pixels.
    pub flow_p75_px: Option<f64>,
    /// Share of pixels with a valid flow.
    pub flow_valid_fraction: Option<f64>,
    /// Grid correspondences given to the eight-point.
    pub correspondences: usize,
    /// Eight-point RANSAC inliers.
    pub eight_point_inliers: usize,
    /// GRIC of the fundamental matrix minus the homography's, per correspondence, when the
    /// homography was fitted (aerial mode); positive: the motion came from the homography.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub homography_gric_gain: Option<f64>,
    /// PnP correspondences.
    pub pnp_correspondences: usize,
    /// PnP inliers.
    pub pnp_inliers: usize,
    /// Known cells of the fused depth map.
    pub depth_cells: usize,
}

/// Stereo figures of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StereoDetail {
    /// Feature counts per phase (detected, matched, tracked, inliers).
    pub counts: FrameCounts,
    /// Median flow of the translation inliers after removing the rotation, pixels.
    pub median_translation_flow_px: f64,
    /// The rig's disparity offset after the frame, pixels: the calibration's, or the estimate
    /// so far with `window.ba.estimate_right_cx_offset`
    /// ([`visnav_core::StereoCamera::right_cx_offset_px`]).
    #[serde(default)]
    pub right_cx_offset_px: f64,
}

/// Per-stage detail of a frame, by mode.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Detail {
    /// Monocular.
    Mono(MonoDetail),
    /// Stereo.
    Stereo(StereoDetail),
    /// No estimation ran (skipped input, failed flow).
    None,
}

/// Time per stage of one frame, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct FrameTimings {
    /// Dense flow from the reference image, by stage (mono; it may have run on the flow thread
    /// during the previous frame, see [`crate::Odometry`]'s pipelining).
    pub flow: Option<FlowTimings>,
    /// Time this frame waited for its flow.
    pub flow_wait_ms: f64,
    /// The monocular odometry stages.
    pub mono: Option<MonoStageTimings>,
    /// The stereo odometry stages.
    pub stereo: Option<StereoStageTimings>,
    /// Loop-closure stage (candidates, verification, pose graph).
    pub loop_closure_ms: f64,
    /// The whole frame inside the odometry (flow wait + estimation + loop closure).
    pub total_ms: f64,
}

impl FrameTimings {
    /// Every stage time as `(name, ms)`, totals excluded, in pipeline order.
    #[must_use]
    pub fn stages(&self) -> Vec<(&'static str, f64)> {
        let mut out = Vec::new();
        if let Some(f) = &self.flow {
            out.extend([
                ("flow.features_ms", f.features_ms),
                ("flow.matching_ms", f.matching_ms),
                ("flow.uncertainty_ms", f.uncertainty_ms),
                ("flow.refinement_ms", f.refinement_ms),
            ]);
        }
        if let Some(m) = &self.mono {
            out.extend([
                ("mono.correspondences_ms", m.correspondences_ms),
                ("mono.parallax_ms", m.parallax_ms),
                ("mono.eight_point_ms", m.eight_point_ms),
                ("mono.triangulation_ms", m.triangulation_ms),
                ("mono.scale_ms", m.scale_ms),
                ("mono.pnp_ms", m.pnp_ms),
                ("mono.depth_ms", m.depth_ms),
            ]);
        }
        if let Some(s) = &self.stereo {
            out.extend([
                ("stereo.pyramid_ms", s.pyramid_ms),
                ("stereo.corners_ms", s.corners_ms),
                ("stereo.matching_ms", s.stereo_ms),
                ("stereo.tracking_ms", s.tracking_ms),
                ("stereo.estimation_ms", s.estimation_ms),
                ("stereo.window_ms", s.window_ms),
            ]);
        }
        if self.loop_closure_ms > 0.0 {
            out.push(("loop_closure_ms", self.loop_closure_ms));
        }
        out
    }
}

/// Which optional per-frame outputs a [`FrameResult`] carries (all off by default: they cost
/// memory).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Outputs {
    /// The dense flow (with its information matrices) from the reference image (mono).
    pub flow: bool,
    /// The fused depth map after the frame (mono).
    pub depth: bool,
    /// The feature tracks of the frame (stereo).
    pub tracks: bool,
    /// The frame's left image.
    pub image: bool,
}

/// The result of one frame.
#[derive(Debug, Clone)]
pub struct FrameResult {
    /// Position in the stream (0 = the first frame pushed).
    pub position: usize,
    /// The input's timestamp, seconds.
    pub timestamp_s: Option<f64>,
    /// Pose of the camera (left camera in stereo) in the world (= first camera) frame.
    pub world_from_cam: Pose,
    /// Motion since the previous frame's pose: `world_from_cam = world_from_prev · prev_from_cur`.
    pub prev_from_cur: Pose,
    /// The 6x6 covariance of `prev_from_cur` from the estimator's own uncertainty (issue 55
    /// item 5): a right perturbation `prev_from_cur_true = prev_from_cur · exp(ε)`,
    /// `ε = (v, ω)` in this frame's camera (left camera in stereo), metres and radians, in the
    /// order of ROS's `nav_msgs/Odometry` (x, y, z, rotation about x, y, z;
    /// `visnav_odometry::stereo::covariance`). `None` when the frame has no estimate of its own
    /// (the first frame, a fallback, a skipped frame: their pose is a prediction) or its
    /// estimator gives none.
    pub prev_from_cur_covariance: Option<nalgebra::Matrix6<f64>>,
    /// Outcome.
    pub status: Status,
    /// Figures of the estimation.
    pub detail: Detail,
    /// Time per stage.
    pub timings: FrameTimings,
    /// Position of the image the motion was measured against (mono: the last accepted image;
    /// stereo: the previous frame), `None` for the first frame or a prediction.
    pub reference_position: Option<usize>,
    /// Requested output: the dense flow from the reference image.
    pub flow: Option<DenseFlow>,
    /// Requested output: the fused depth map after this frame.
    pub depth: Option<DepthMap>,
    /// Requested output: the stereo feature tracks.
    pub tracks: Option<Vec<Track>>,
    /// Requested output: the left image.
    pub image: Option<GrayImage>,
    /// Loop closures verified at this frame.
    pub loop_closures: Vec<visnav_loop::ClosureReport>,
}

impl FrameResult {
    /// Translation length of the step, metres.
    #[must_use]
    pub fn step_m(&self) -> f64 {
        self.prev_from_cur.translation.vector.norm()
    }

    /// Inliers of the estimation that produced the pose (eight-point or PnP in mono, translation
    /// phase in stereo); 0 for a prediction.
    #[must_use]
    pub fn inliers(&self) -> usize {
        match &self.detail {
            Detail::Mono(m) => m.eight_point_inliers.max(m.pnp_inliers),
            Detail::Stereo(s) => s.counts.translation_inliers,
            Detail::None => 0,
        }
    }
}
