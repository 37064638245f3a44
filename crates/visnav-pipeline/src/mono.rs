//! The monocular stream: dense flow from the reference image (§3 of the monocular paper), the
//! monocular odometry (§4–5), the failure policy and the optional loop closure (§5).
//!
//! **Failure policy** (the one of the whole library): a frame whose images are missing, whose
//! flow fails or which the odometry refuses gets the constant-velocity prediction
//! `world_from_cur = world_from_prev · prev_from_cur(last estimated motion)`; the odometry never
//! sees it, and the next frame is matched against the last accepted image (the reference), so
//! its pose stays consistent. A frame the odometry takes but cannot estimate (no eight-point or
//! PnP pose) gets the odometry's own constant-velocity pose and becomes the reference.
//!
//! **The constant-velocity model** is this stream's alone ([`MonoStream`]'s `last_motion`):
//! the odometry is told it as the prior of each frame and returns its estimate
//! ([`MonoFrameResult::motion`]), which the stream keeps; the frames the odometry does not take
//! repeat it (scaled to their time step).

use std::sync::Arc;
use std::time::{Duration, Instant};

use visnav_core::{GrayImage, PinholeCamera, Pose};
use visnav_flow::{DenseFlow, FlowTimings};
use visnav_loop::LoopCloser;
use visnav_odometry::RelativeMotion;
use visnav_odometry::mono::{
    FrameStatus as MonoStatus, MonoError, MonoFlow, MonoFrameResult, MonoOdometry, UntrustedReason,
};

use crate::ahead::{FlowAhead, FlowOutcome, ReadyFlow};
use crate::frame::{
    Detail, FallbackReason, FrameInput, FrameResult, FrameTimings, Images, MonoDetail, Outputs,
    Status,
};
use crate::{ImageStore, MonoRunConfig, PipelineError};

/// The image the next frame is matched against.
struct Reference {
    position: usize,
    image: GrayImage,
    timestamp_s: Option<f64>,
}

/// `motion` extended to `scale` times its span at the same velocity: the rotation's angle and
/// the translation times `scale` (the constant-velocity model over a longer time step).
fn scaled_motion(motion: &Pose, scale: f64) -> Pose {
    if scale == 1.0 {
        return *motion;
    }
    Pose::from_parts(
        (motion.translation.vector * scale).into(),
        motion.rotation.powf(scale),
    )
}

/// The monocular stream's state (driven by [`crate::Odometry`]).
pub(crate) struct MonoStream {
    flow: Arc<MonoFlow>,
    vo: MonoOdometry,
    reference: Option<Reference>,
    /// The constant-velocity model (kept here alone): the odometry's last estimated motion
    /// ([`MonoFrameResult::motion`]; `None` before its first estimate), handed to it as the
    /// prior of the next frame and repeated for the frames it does not take
    /// ([`Self::predicted_motion`]).
    last_motion: Option<RelativeMotion>,
    /// The time `last_motion` spans (its frame's timestamp minus its reference's), seconds.
    last_motion_dt_s: Option<f64>,
    /// The timestamp of the frame processed last, seconds.
    last_time_s: Option<f64>,
    /// The multiple of `last_motion` the current frame's constant-velocity prediction takes:
    /// 1 (one frame, one motion: the paper's model), or, after frames dropped by a live
    /// stream's frame policy, the true time step over `last_motion_dt_s`.
    prediction_scale: f64,
    closer: Option<(LoopCloser, Box<dyn ImageStore>)>,
}

/// What the odometry made of a frame it was given.
struct Estimated {
    result: MonoFrameResult,
    flow: Option<DenseFlow>,
    flow_timings: Option<FlowTimings>,
    flow_wait_ms: f64,
}

impl MonoStream {
    pub fn new(camera: PinholeCamera, config: &MonoRunConfig) -> Result<Self, PipelineError> {
        Ok(Self {
            flow: Arc::new(MonoFlow::new(&config.mono.flow)?),
            vo: MonoOdometry::new(camera, config.mono.clone())?,
            reference: None,
            last_motion: None,
            last_motion_dt_s: None,
            last_time_s: None,
            prediction_scale: 1.0,
            closer: None,
        })
    }

    /// Adds the loop-closure stage; `store` gives back earlier images for verification.
    pub fn enable_loop_closure(
        &mut self,
        camera: PinholeCamera,
        config: &MonoRunConfig,
        store: Box<dyn ImageStore>,
    ) -> Result<(), PipelineError> {
        let closer = config.loop_closer(camera)?;
        self.closer = Some((closer, store));
        Ok(())
    }

    pub fn closer(&self) -> Option<&LoopCloser> {
        self.closer.as_ref().map(|(c, _)| c)
    }

    /// Starts the speculative flow `from → to` on the flow thread (see `ahead.rs`).
    pub fn spawn_ahead(
        &self,
        from: &FrameInput,
        to: &FrameInput,
        from_position: usize,
        to_position: usize,
    ) -> Option<FlowAhead> {
        FlowAhead::spawn(
            &self.flow,
            from.left()?,
            to.left()?,
            from_position,
            to_position,
        )
    }

    /// The flow from the reference to `image`: the one computed ahead when it is this pair's,
    /// else computed now (a flow from another image, when the frame in between was refused, is
    /// dropped).
    fn flow_from_reference(
        &self,
        reference: &Reference,
        image: &GrayImage,
        position: usize,
        ahead: Option<ReadyFlow>,
    ) -> FlowOutcome {
        match ahead {
            Some(a) if a.from_position == reference.position && a.to_position == position => {
                a.outcome
            }
            _ => self.flow.compute_timed(&reference.image, image),
        }
    }

    /// Runs the flow and the odometry on `image`; `Err` with the fallback reason when the flow
    /// fails or the odometry refuses the frame.
    fn estimate(
        &mut self,
        image: &GrayImage,
        position: usize,
        ahead: Option<ReadyFlow>,
    ) -> Result<Estimated, FallbackReason> {
        let t = Instant::now();
        let waited_ms = ahead.as_ref().map_or(0.0, |a| a.wait_ms);
        let (flow, flow_timings) = match &self.reference {
            Some(r) => {
                let (f, ft) = self
                    .flow_from_reference(r, image, position, ahead)
                    .map_err(|e| FallbackReason::Flow {
                        message: format!("flow {} -> {position}: {e}", r.position),
                    })?;
                (Some(f), Some(ft))
            }
            None => (None, None),
        };
        let flow_wait_ms = waited_ms + t.elapsed().as_secs_f64() * 1e3;
        let refused = |e: MonoError| FallbackReason::Refused {
            message: e.to_string(),
        };
        let prior = self.last_motion.as_ref();
        let (result, flow, flow_timings) = match self.vo.process(image, flow.as_ref(), prior) {
            Ok(r) => (r, flow, flow_timings),
            Err(MonoError::UntrustedFrame { reason }) if reason.is_flow_failure() => {
                match self.retry_wide(image, position, reason) {
                    Some(Ok((r, wide, mut wide_timings))) => {
                        // the frame's flow time is both computations'
                        if let Some(first) = flow_timings {
                            wide_timings += first;
                        }
                        (r, Some(wide), Some(wide_timings))
                    }
                    Some(Err(e)) => return Err(refused(e)),
                    None => return Err(refused(MonoError::UntrustedFrame { reason })),
                }
            }
            Err(e) => return Err(refused(e)),
        };
        Ok(Estimated {
            result,
            flow,
            flow_timings,
            flow_wait_ms,
        })
    }

    /// The retry of a frame refused for its flow (`reason`): the flow from the reference again
    /// with the wider search (`MonoFlowConfig::retry_extra_levels`), then the odometry once more.
    /// `None` when the retry is off or there is no reference.
    fn retry_wide(
        &mut self,
        image: &GrayImage,
        position: usize,
        reason: UntrustedReason,
    ) -> Option<Result<(MonoFrameResult, DenseFlow, FlowTimings), MonoError>> {
        let reference = self.reference.as_ref()?;
        let wide = self.flow.compute_wide_timed(&reference.image, image)?;
        log::info!("frame {position}: refused ({reason}); the flow again with a wider search");
        Some(wide.and_then(|(flow, timings)| {
            let r = self
                .vo
                .process(image, Some(&flow), self.last_motion.as_ref())?;
            Ok((r, flow, timings))
        }))
    }

    /// Processes the frame at `position` (with the flow computed ahead for it, if any).
    pub fn process(
        &mut self,
        input: FrameInput,
        position: usize,
        world_from_prev: Option<Pose>,
        ahead: Option<ReadyFlow>,
        outputs: Outputs,
    ) -> FrameResult {
        // the frame's time starts where the wait for its flow computed ahead started
        let waited = Duration::from_secs_f64(ahead.as_ref().map_or(0.0, |a| a.wait_ms) / 1e3);
        let t_frame = Instant::now()
            .checked_sub(waited)
            .unwrap_or_else(Instant::now);
        self.prediction_scale = self.time_scale(input.timestamp_s, input.dropped_before);
        self.last_time_s = input.timestamp_s;
        let FrameInput {
            timestamp_s,
            images,
            ..
        } = input;
        let image = match images {
            Images::Mono(l) | Images::Stereo { left: l, .. } => l,
            Images::Missing { reason } => {
                drop(ahead);
                log::warn!("frame {position}: skipped ({reason}); constant-velocity prediction");
                let status = Status::Skipped { reason };
                return self.predicted(
                    position,
                    timestamp_s,
                    world_from_prev,
                    status,
                    None,
                    t_frame,
                );
            }
        };
        let last_accepted = self.reference.as_ref().map(|r| r.position);
        let gap_frames = last_accepted.map_or(0, |p| position.saturating_sub(p));
        if let Some(last_accepted) =
            last_accepted.filter(|_| gap_frames > self.vo.config().trust.max_reference_gap_frames)
        {
            drop(ahead);
            let image_out = outputs.image.then(|| image.clone());
            let restarted = FallbackReason::Restarted {
                last_accepted,
                gap_frames,
            };
            let mut r = self.restart(image, position, timestamp_s, world_from_prev, restarted);
            r.image = image_out;
            r.timings.total_ms = t_frame.elapsed().as_secs_f64() * 1e3;
            return r;
        }
        match self.estimate(&image, position, ahead) {
            Ok(est) => {
                let mut r = self.accepted(est, position, timestamp_s, world_from_prev, outputs);
                if outputs.image {
                    r.image = Some(image.clone());
                }
                self.close_loops(&mut r, Some(&image));
                self.reference = Some(Reference {
                    position,
                    image,
                    timestamp_s,
                });
                r.timings.total_ms = t_frame.elapsed().as_secs_f64() * 1e3;
                r
            }
            Err(reason) => {
                log::warn!("frame {position}: {reason:?}; constant-velocity prediction");
                let status = Status::Fallback { reason };
                let img = outputs.image.then_some(image);
                self.predicted(position, timestamp_s, world_from_prev, status, img, t_frame)
            }
        }
    }

    /// The result of a frame the odometry took.
    fn accepted(
        &mut self,
        est: Estimated,
        position: usize,
        timestamp_s: Option<f64>,
        world_from_prev: Option<Pose>,
        outputs: Outputs,
    ) -> FrameResult {
        let r = est.result;
        // a first image has no motion of its own: the model stays
        if r.motion.is_some() {
            self.last_motion = r.motion;
        }
        self.last_motion_dt_s = timestamp_s
            .zip(self.reference.as_ref().and_then(|r| r.timestamp_s))
            .map(|(t, t_ref)| t - t_ref)
            .filter(|dt| dt.is_finite() && *dt > 0.0);
        // the step of the trajectory (differs from the odometry's motion when the frame before
        // was predicted: the odometry measured from the reference image)
        let prev_from_cur =
            world_from_prev.map_or_else(Pose::identity, |w| w.inverse() * r.world_from_cam);
        let status = match r.status {
            MonoStatus::Ok => Status::Ok,
            MonoStatus::LowParallax => Status::LowParallax,
            MonoStatus::Failed => Status::Fallback {
                reason: FallbackReason::NoMonoEstimate,
            },
        };
        let flow_figures = est
            .flow
            .as_ref()
            .map(|f| (r.flow_p75_px, f.valid_fraction()));
        let detail = Detail::Mono(MonoDetail {
            source: r.source,
            scale_source: r.scale_source,
            scale_m: r.scale_m.is_finite().then_some(r.scale_m),
            scale_ground_m: r.scale_ground_m,
            scale_depth_m: r.scale_depth_m,
            klt_median_px: r.klt_median_px,
            flow_p75_px: flow_figures.map(|f| f.0),
            flow_valid_fraction: flow_figures.map(|f| f.1),
            correspondences: r.correspondences,
            eight_point_inliers: r.eight_point_inliers,
            homography_gric_gain: r.homography_gric_gain,
            pnp_correspondences: r.pnp_correspondences,
            pnp_inliers: r.pnp_inliers,
            depth_cells: r.depth_cells,
        });
        // the odometry's step covariance is the trajectory's step's only when it measured from
        // the frame just before
        let from_previous = self
            .reference
            .as_ref()
            .is_some_and(|r| r.position + 1 == position);
        FrameResult {
            position,
            timestamp_s,
            world_from_cam: r.world_from_cam,
            prev_from_cur,
            prev_from_cur_covariance: r.prev_from_cur_covariance.filter(|_| from_previous),
            status,
            detail,
            timings: FrameTimings {
                flow: est.flow_timings,
                flow_wait_ms: est.flow_wait_ms,
                mono: Some(r.timings),
                ..FrameTimings::default()
            },
            // the reference is still the image this frame was measured against
            reference_position: self.reference.as_ref().map(|r| r.position),
            flow: if outputs.flow { est.flow } else { None },
            depth: if outputs.depth {
                self.vo.depth_map().cloned()
            } else {
                None
            },
            tracks: None,
            image: None,
            loop_closures: Vec::new(),
        }
    }

    /// A new map at the frame at `position` (`restarted` is the [`FallbackReason::Restarted`]
    /// it gets): its pose is the constant-velocity prediction, given to the odometry as its new
    /// start, and it becomes the reference. When the odometry refuses the image too (a black
    /// frame), the frame is an ordinary refused one and the next frame tries again.
    fn restart(
        &mut self,
        image: GrayImage,
        position: usize,
        timestamp_s: Option<f64>,
        world_from_prev: Option<Pose>,
        restarted: FallbackReason,
    ) -> FrameResult {
        let (world_from_cam, _) = self.constant_velocity(world_from_prev);
        let reason = match self
            .vo
            .restart(&image, world_from_cam, self.last_motion.as_ref())
        {
            Ok(_) => {
                log::warn!(
                    "frame {position}: {restarted:?} (the last accepted frame is too far back to match against); a new map starts here at the constant-velocity pose"
                );
                self.reference = Some(Reference {
                    position,
                    image,
                    timestamp_s,
                });
                restarted
            }
            Err(e) => {
                let refused = FallbackReason::Refused {
                    message: e.to_string(),
                };
                log::warn!("frame {position}: {refused:?}; constant-velocity prediction");
                refused
            }
        };
        let status = Status::Fallback { reason };
        self.predicted(
            position,
            timestamp_s,
            world_from_prev,
            status,
            None,
            Instant::now(),
        )
    }

    /// The `prev_from_cur` the constant-velocity model repeats: the last estimated motion's;
    /// before the first estimate, no motion — the identity as the first image reported it
    /// (`RelativeMotion::identity`'s, once an image was accepted), else `Pose::identity`.
    fn predicted_motion(&self) -> Pose {
        match (&self.last_motion, &self.reference) {
            (Some(m), _) => m.prev_from_cur(),
            (None, Some(_)) => RelativeMotion::identity().prev_from_cur(),
            (None, None) => Pose::identity(),
        }
    }

    /// The constant-velocity model: `(world_from_cur, prev_from_cur)` with the last estimated
    /// motion (the identity for the first frame).
    fn constant_velocity(&self, world_from_prev: Option<Pose>) -> (Pose, Pose) {
        let motion = scaled_motion(&self.predicted_motion(), self.prediction_scale);
        match world_from_prev {
            Some(w) => (w * motion, motion),
            None => (Pose::identity(), Pose::identity()),
        }
    }

    /// The multiple of the last motion a frame's prediction spans ([`Self::prediction_scale`]):
    /// after `dropped_before` dropped frames, the time since the frame processed last over the
    /// time the last motion spans; 1 without drops or without timestamps (recordings keep the
    /// per-frame model, pose for pose).
    fn time_scale(&self, timestamp_s: Option<f64>, dropped_before: usize) -> f64 {
        if dropped_before == 0 {
            return 1.0;
        }
        let dt_s = timestamp_s.zip(self.last_time_s).map(|(t, prev)| t - prev);
        match dt_s.zip(self.last_motion_dt_s) {
            Some((dt, dt_last)) if dt.is_finite() && dt > 0.0 => dt / dt_last,
            _ => 1.0 + dropped_before as f64,
        }
    }

    /// The constant-velocity result of a frame the odometry did not take.
    fn predicted(
        &mut self,
        position: usize,
        timestamp_s: Option<f64>,
        world_from_prev: Option<Pose>,
        status: Status,
        image: Option<GrayImage>,
        t_frame: Instant,
    ) -> FrameResult {
        let (world_from_cam, prev_from_cur) = self.constant_velocity(world_from_prev);
        let mut r = FrameResult {
            position,
            timestamp_s,
            world_from_cam,
            prev_from_cur,
            prev_from_cur_covariance: None,
            status,
            detail: Detail::None,
            timings: FrameTimings::default(),
            reference_position: None,
            flow: None,
            depth: None,
            tracks: None,
            image,
            loop_closures: Vec::new(),
        };
        self.close_loops(&mut r, None);
        r.timings.total_ms = t_frame.elapsed().as_secs_f64() * 1e3;
        r
    }

    /// Feeds the frame to the loop closer (every frame gets a vertex; only accepted frames, the
    /// ones with an image here, are candidates and bring their depth map) and keeps its image for
    /// later verifications.
    fn close_loops(&mut self, r: &mut FrameResult, image: Option<&GrayImage>) {
        let depth = image.and(self.vo.depth_map());
        let Some((closer, store)) = &mut self.closer else {
            return;
        };
        let t = Instant::now();
        if let Some(img) = image {
            store.keep(r.position, img);
        }
        match closer.process(image, &r.prev_from_cur, depth, |p| store.image(p)) {
            Ok(step) => r.loop_closures = step.closures,
            Err(e) => log::warn!("frame {}: loop closure: {e}", r.position),
        }
        r.timings.loop_closure_ms = t.elapsed().as_secs_f64() * 1e3;
    }
}
