//! The stereo stream: RotROCC (the stereo paper) on rectified pairs, with the library's failure
//! policy: a frame without a usable pair (missing or unreadable image, no right image) gets the
//! constant-velocity prediction with status [`Status::Skipped`] and the tracking restarts at the
//! next pair; an estimation failure inside the odometry is a [`Status::Fallback`] with the
//! stereo reason.
//!
//! **The constant-velocity model** is this stream's alone ([`StereoStream`]'s `motion`): the
//! odometry is told it as the prediction of each frame (the tracking's first guess, the step of
//! a frame that falls back) and returns the motion to predict the next frame with
//! (`visnav_odometry::stereo::FrameResult::motion`: the estimate or the window-adjusted step),
//! which the stream keeps.
//!
//! **Loop closure** (optional, issue #25): the monocular loop closer (`visnav_loop::LoopCloser`:
//! SSIM candidates, verification by dense flow with uncertainty, robust pose graph) on the left
//! images. Each frame with a stereo pair brings the depth map of its stereo features
//! ([`feature_depth_map`]: the depth of each feature's triangulated or window-adjusted point at
//! its own pixel), so a closure's relative pose is the PnP of the
//! earlier frame's stereo points against the flow into the current image: metric, no scale to
//! recover. The corrected trajectory and the report are those of the mono loop closure.

use std::time::Instant;

use visnav_core::{GrayImage, PinholeCamera, StereoCamera};
use visnav_loop::LoopCloser;
use visnav_odometry::RelativeMotion;
use visnav_odometry::mono::DepthMap;
use visnav_odometry::stereo::{
    FailReason, FrameResult as StereoResult, FrameStatus, StereoConfig, StereoFeature,
    StereoOdometry,
};

use crate::frame::{
    Detail, FallbackReason, FrameInput, FrameResult, FrameTimings, Images, Outputs, Status,
    StereoDetail,
};
use crate::{ImageStore, MonoRunConfig, PipelineError};

/// Standard deviation of a stereo feature's disparity for its depth variance in the loop
/// closer's depth maps, pixels (the SAD matcher's sub-pixel accuracy; the PnP of a closure does
/// not weigh points by it).
const DISPARITY_SIGMA_PX: f64 = 0.5;

/// Grid stride of [`feature_depth_map`], pixels: each feature keeps its own sub-pixel position
/// in its cell (`DepthMap::offset_px`), so the grid only has to be finer than the features'
/// spacing (the corner detector's minimum distance) to keep nearly all of them.
const FEATURE_GRID_STRIDE_PX: usize = 4;

/// The depth map of a frame's stereo features in its left camera: a 4-pixel grid
/// (`FEATURE_GRID_STRIDE_PX`) with the depth (metres) of each feature's point at the feature's
/// own left pixel and the variance `(z² σ_d / (f b))²` of a disparity error `σ_d` = 0.5 px; every
/// other cell unknown (of two features in one cell, the nearer). `None` when no feature has a
/// positive finite depth inside the image.
#[must_use]
pub fn feature_depth_map(rig: &StereoCamera, features: &[StereoFeature]) -> Option<DepthMap> {
    let camera = &rig.left;
    let mut map = DepthMap::empty(
        camera.width as usize,
        camera.height as usize,
        FEATURE_GRID_STRIDE_PX,
    );
    let focal_baseline = camera.fx * rig.baseline_m;
    for f in features {
        let z_m = f.p_in_cam.z;
        if !(z_m.is_finite() && z_m > 0.0) {
            continue;
        }
        let Some(i) = map.cell_of(&f.left_px) else {
            continue;
        };
        if map.get(i).is_some_and(|(d, _)| d <= z_m) {
            continue;
        }
        let sigma_m = z_m * z_m * DISPARITY_SIGMA_PX / focal_baseline;
        map.set_at(i, &f.left_px, z_m, sigma_m * sigma_m);
    }
    (map.known() > 0).then_some(map)
}

/// The stereo stream's state (driven by [`crate::Odometry`]).
pub(crate) struct StereoStream {
    vo: StereoOdometry,
    /// The constant-velocity model (kept here alone): the motion the odometry returned last
    /// (`FrameResult::motion`; the identity before), its prediction for the next frame.
    motion: RelativeMotion,
    closer: Option<(LoopCloser, Box<dyn ImageStore>)>,
}

impl StereoStream {
    pub fn new(rig: StereoCamera, config: StereoConfig) -> Result<Self, PipelineError> {
        Ok(Self {
            vo: StereoOdometry::new(rig, config)?,
            motion: RelativeMotion::identity(),
            closer: None,
        })
    }

    /// Adds the loop-closure stage on the left camera: `config.loop_closure` configures it,
    /// `config.mono` the closures' relative pose (PnP) and `config.mono.flow` their flow;
    /// `store` gives back earlier left images for verification.
    pub fn enable_loop_closure(
        &mut self,
        config: &MonoRunConfig,
        store: Box<dyn ImageStore>,
    ) -> Result<(), PipelineError> {
        let closer = config.loop_closer(self.left_camera())?;
        self.closer = Some((closer, store));
        Ok(())
    }

    /// The rig's left camera.
    pub fn left_camera(&self) -> PinholeCamera {
        self.vo.rig().left
    }

    pub fn closer(&self) -> Option<&LoopCloser> {
        self.closer.as_ref().map(|(c, _)| c)
    }

    /// Feeds the frame to the loop closer: every frame gets a vertex; a frame with a stereo
    /// pair (`left` given) is a candidate and brings the depth map of its features.
    fn close_loops(&mut self, r: &mut FrameResult, left: Option<&GrayImage>) {
        let Some((closer, store)) = &mut self.closer else {
            return;
        };
        let t = Instant::now();
        let depth = left.and_then(|_| feature_depth_map(self.vo.rig(), self.vo.features()));
        if let Some(img) = left {
            store.keep(r.position, img);
        }
        match closer.process(left, &r.prev_from_cur, depth.as_ref(), |p| store.image(p)) {
            Ok(step) => r.loop_closures = step.closures,
            Err(e) => log::warn!("frame {}: loop closure: {e}", r.position),
        }
        r.timings.loop_closure_ms = t.elapsed().as_secs_f64() * 1e3;
    }

    /// Processes the frame at `position`.
    pub fn process(&mut self, input: FrameInput, position: usize, outputs: Outputs) -> FrameResult {
        let t = Instant::now();
        let FrameInput {
            timestamp_s,
            images,
            ..
        } = input;
        // the left image and whether the pair was processed (a loop-closure candidate)
        let (r, image, paired): (StereoResult, Option<GrayImage>, bool) = match images {
            Images::Stereo { left, right } => {
                let r = self.vo.process(&left, &right, &self.motion);
                (r, Some(left), true)
            }
            Images::Mono(left) => (
                self.vo
                    .skip(format!("frame {position} has no right image"), &self.motion),
                Some(left),
                false,
            ),
            Images::Missing { reason } => (self.vo.skip(reason, &self.motion), None, false),
        };
        if let Some(motion) = r.motion {
            self.motion = motion;
        }
        let status = match r.status {
            FrameStatus::First | FrameStatus::Ok => Status::Ok,
            FrameStatus::LowSpeed => Status::LowParallax,
            FrameStatus::Fallback(FailReason::MissingInput { message }) => {
                Status::Skipped { reason: message }
            }
            FrameStatus::Fallback(reason) => Status::Fallback {
                reason: FallbackReason::Stereo { reason },
            },
        };
        let detail = Detail::Stereo(StereoDetail {
            counts: r.counts,
            median_translation_flow_px: r.median_translation_flow_px,
            right_cx_offset_px: self.vo.rig().right_cx_offset_px,
        });
        let reference_position = (!status.is_predicted() && position > 0).then(|| position - 1);
        let mut result = FrameResult {
            position,
            timestamp_s,
            world_from_cam: r.world_from_cam,
            prev_from_cur: r.prev_from_cur,
            prev_from_cur_covariance: r.prev_from_cur_covariance,
            status,
            detail,
            timings: FrameTimings {
                stereo: Some(r.timings),
                total_ms: t.elapsed().as_secs_f64() * 1e3,
                ..FrameTimings::default()
            },
            reference_position,
            flow: None,
            depth: None,
            tracks: outputs.tracks.then_some(r.tracks),
            image: None,
            loop_closures: Vec::new(),
        };
        self.close_loops(&mut result, image.as_ref().filter(|_| paired));
        if outputs.image {
            result.image = image;
        }
        result.timings.total_ms = t.elapsed().as_secs_f64() * 1e3;
        result
    }
}
