//! The monocular pipeline of §5: [`MonoOdometry::process`] turns one image and the dense flow
//! from the previous image into a pose, the tracker ([`super::tracker`]: the motion) then the
//! mapper ([`super::mapper`]: the scale, the window and the depth map).
//!
//! The constant-velocity prior is the driver's, not the odometry's: each call is told the last
//! estimated motion (`prior`) and a frame's result returns its own estimate
//! ([`MonoFrameResult::motion`]) for the driver to keep — `visnav-pipeline`'s mono stream owns
//! it, and a driver of the odometry alone keeps it with `prior = result.motion.or(prior)`.

use std::time::Instant;

use visnav_core::{GrayImage, PinholeCamera, Pose};
use visnav_flow::DenseFlow;
use visnav_geometry::seeded_rng;
use visnav_image::Pyramid;

use super::config::MonoConfig;
use super::context::FrameContext;
use super::covariance::step_covariance;
use super::depth::DepthMap;
use super::error::MonoError;
use super::mapper::{MapUpdate, Mapper};
use super::result::{FrameStatus, MonoFrameResult, PoseSource, ScaleSource, StageTimings, ms};
use super::tracker::{Estimate, FusedPose, Tracker};
use super::trust::{Thumbnail, UntrustedReason};
use crate::RelativeMotion;

/// The monocular odometry state machine (see the module docs).
#[derive(Debug, Clone)]
pub struct MonoOdometry {
    config: MonoConfig,
    camera: PinholeCamera,
    frame: usize,
    world_from_cam: Pose,
    /// The motion's side: the last accepted image and the trust tests' memory.
    tracker: Tracker,
    /// The scene's side: the depth map, the scale keeper and the window.
    mapper: Mapper,
}

impl MonoOdometry {
    /// A pipeline for `camera`.
    ///
    /// # Errors
    /// [`MonoError`] when the configuration is invalid.
    pub fn new(camera: PinholeCamera, config: MonoConfig) -> Result<Self, MonoError> {
        config.validate()?;
        Ok(Self {
            tracker: Tracker::new(&config.trust),
            mapper: Mapper::new(&config),
            config,
            camera,
            frame: 0,
            world_from_cam: Pose::identity(),
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &MonoConfig {
        &self.config
    }

    /// The depth map of the latest frame (propagated and fused), if any.
    #[must_use]
    pub fn depth_map(&self) -> Option<&DepthMap> {
        self.mapper.depth_map()
    }

    fn check_size(&self, what: &'static str, w: usize, h: usize) -> Result<(), MonoError> {
        let (ew, eh) = (self.camera.width as usize, self.camera.height as usize);
        if (w, h) == (ew, eh) {
            Ok(())
        } else {
            Err(MonoError::SizeMismatch {
                what,
                expected_w: ew,
                expected_h: eh,
                got_w: w,
                got_h: h,
            })
        }
    }

    /// What the tracker and the mapper read of the odometry for the current frame, with the
    /// driver's constant-velocity `prior`.
    fn context(&self, prior: Option<&RelativeMotion>) -> FrameContext<'_> {
        FrameContext {
            config: &self.config,
            camera: &self.camera,
            frame: self.frame,
            last_motion: prior.copied(),
        }
    }

    /// Processes the next image. `flow` is the dense flow from the previous image to this one;
    /// `None` for the first image (the pose is the identity, or unchanged after a reset).
    /// `prior` is the constant-velocity prior, which the driver keeps: the
    /// [`MonoFrameResult::motion`] of the last frame that had one (`None` before the first
    /// estimate). It is read by the trust tests (rigidity evidence, rotation change), the
    /// scale keeper and the translation guard, and by the tracker's fallback (a frame without
    /// an estimate repeats it).
    ///
    /// Stages (§5, module docs), the tracker's then the mapper's: `Correspondences` (grid),
    /// `ParallaxTest`, `PnpEstimate` (previous depth map), `EightPointEstimate` (§4, eq.
    /// 6–12), `BaselineTest`; `ScaledEightPoint` (ground plane `s = −(b·h)/d` and depth
    /// ratio); the tracker's `FusedPose` (fusion rule and the translation guard); the mapper's
    /// window step and `DepthUpdate`; the odometry's state is changed only by the last step,
    /// `Self::commit`. The trust tests ([`super::trust`]) run on the image first, on the flow
    /// after the size check, on the eight-point's inlier share and (when configured) on the
    /// fused motion.
    ///
    /// # Errors
    /// [`MonoError::SizeMismatch`] when the image or the flow is not the camera's size.
    /// [`MonoError::UntrustedFrame`] when the frame fails a trust test: the state is unchanged
    /// (the frame is as if never seen; the next flow must start from the last accepted image).
    /// Geometric failures are reported in [`MonoFrameResult::status`].
    pub fn process(
        &mut self,
        image: &GrayImage,
        flow: Option<&DenseFlow>,
        prior: Option<&RelativeMotion>,
    ) -> Result<MonoFrameResult, MonoError> {
        let t_total = Instant::now();
        self.check_size("image", image.width(), image.height())?;
        let ctx = self.context(prior);
        let thumbnail = self
            .tracker
            .check_image(&ctx, image, flow.is_some())
            .map_err(|r| self.untrusted(r))?;
        // the parallax test's KLT and the window's track refinement align patches
        let window = &self.config.window;
        let pyramid = (self.config.parallax.use_klt
            || (window.runs(self.config.scale.aerial) && window.refine_tracks))
            .then(|| Pyramid::build(image, 3));
        let Some(flow) = flow else {
            return Ok(self.first_frame(pyramid, thumbnail, prior, t_total));
        };
        self.check_size("flow", flow.width, flow.height)?;
        let mut timings = StageTimings::default();
        let mut rng =
            seeded_rng(self.config.seed ^ (self.frame as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));

        let measured = self
            .tracker
            .measure(
                &ctx,
                (flow, self.mapper.depth_map(), pyramid.as_ref()),
                &mut rng,
                &mut timings,
            )
            .map_err(|r| self.untrusted(r))?;
        let pnp_pose = measured.pnp.pose;
        let scaled = self.mapper.scaled_eight_point(
            &ctx,
            (flow, measured.unit_pose, pnp_pose),
            &mut rng,
            &mut timings,
        );
        let max_translation_m = self.mapper.max_translation_m(&ctx);
        let fused = match Tracker::estimate(&ctx, &measured, scaled.pose, max_translation_m) {
            Estimate::Accepted { motion } => motion,
            Estimate::Refused(reason) => return Err(self.untrusted(reason)),
        };

        let t = Instant::now();
        let images = self.tracker.prev_pyramid().zip(pyramid.as_ref());
        let (fused, window) = self.mapper.window_step(
            &ctx,
            (self.world_from_cam, flow, images),
            &measured.corrs.list,
            fused,
            scaled.estimate.ground_m,
        );
        timings.window_ms = ms(t);

        let has_baseline = measured.baseline.has_baseline;
        let depth = self
            .mapper
            .depth_update(&ctx, (flow, &fused), has_baseline, &mut timings);

        let window_points = window.as_ref().map_or(0, |w| w.points);
        self.commit(
            &fused,
            MapUpdate {
                keeper: scaled.keeper,
                window: window.map(|w| w.window),
                depth: depth.next,
            },
            (pyramid, thumbnail, flow.valid_fraction()),
        );
        timings.total_ms = ms(t_total);
        // the scale keeper's step length (the scaled eight-point), reported and weighed against
        // the final step's in the covariance
        let scale_m = scaled
            .pose
            .map_or(f64::NAN, |p| p.translation.vector.norm());
        Ok(MonoFrameResult {
            frame: self.frame - 1,
            world_from_cam: self.world_from_cam,
            prev_from_cur: fused.motion.prev_from_cur(),
            motion: Some(fused.motion),
            prev_from_cur_covariance: measured
                .pnp
                .information
                .filter(|_| fused.source != PoseSource::ConstantVelocity)
                .and_then(|info| {
                    let disagreement_m = fused.motion.length_m() - scale_m;
                    step_covariance(
                        &self.config.covariance,
                        &info,
                        &fused.motion,
                        disagreement_m,
                    )
                }),
            source: fused.source,
            scale_source: scaled.estimate.source,
            scale_m,
            scale_ground_m: scaled.estimate.ground_m,
            scale_depth_m: scaled.estimate.depth_ratio_m,
            klt_median_px: measured.parallax.klt_median_px,
            flow_p75_px: measured.parallax.flow_p75_px,
            translational_parallax_px: measured.baseline.translational_parallax_px,
            correspondences: measured.corrs.list.len(),
            eight_point_inliers: measured.eight_point.inliers,
            homography_gric_gain: measured.eight_point.homography_gric_gain,
            pnp_correspondences: measured.pnp.correspondences,
            pnp_inliers: measured.pnp.inliers,
            depth_cells: depth.known_cells,
            window_points,
            timings,
            status: fused.status,
        })
    }

    /// Starts a new map at `image`, whose pose is `world_from_cam` (the driver's
    /// constant-velocity prediction): as at the first image, the depth map and the previous
    /// image are dropped, and the scale state too, so the next frame's scale comes from the
    /// ground plane again (aerial: from the last re-estimated camera height). For a driver whose
    /// last accepted image is too old to match against
    /// ([`super::TrustConfig::max_reference_gap_frames`]). Not in the paper. The driver's
    /// `prior` (as for [`Self::process`]) survives the restart: the result has no motion of its
    /// own, so the driver keeps the prior for the next frame.
    ///
    /// # Errors
    /// As [`Self::process`]: the size check and the image tests (no texture, noise) run first;
    /// on an error the state is unchanged.
    pub fn restart(
        &mut self,
        image: &GrayImage,
        world_from_cam: Pose,
        prior: Option<&RelativeMotion>,
    ) -> Result<MonoFrameResult, MonoError> {
        let kept_pose = self.world_from_cam;
        self.world_from_cam = world_from_cam;
        match self.process(image, None, prior) {
            Ok(r) => {
                self.mapper.restart_scale();
                Ok(r)
            }
            Err(e) => {
                self.world_from_cam = kept_pose;
                Err(e)
            }
        }
    }

    /// The first image (no flow): the pose is unchanged, the depth map dropped.
    fn first_frame(
        &mut self,
        pyramid: Option<Pyramid>,
        thumbnail: Thumbnail,
        prior: Option<&RelativeMotion>,
        t_total: Instant,
    ) -> MonoFrameResult {
        let frame = self.frame;
        self.frame += 1;
        self.tracker.accept(pyramid, thumbnail, None);
        let ctx = FrameContext {
            config: &self.config,
            camera: &self.camera,
            frame,
            last_motion: prior.copied(),
        };
        self.mapper.start(&ctx, self.world_from_cam);
        MonoFrameResult {
            frame,
            world_from_cam: self.world_from_cam,
            prev_from_cur: RelativeMotion::identity().prev_from_cur(),
            motion: None,
            prev_from_cur_covariance: None,
            source: PoseSource::Initial,
            scale_source: ScaleSource::None,
            scale_m: f64::NAN,
            scale_ground_m: None,
            scale_depth_m: None,
            klt_median_px: None,
            flow_p75_px: 0.0,
            translational_parallax_px: None,
            correspondences: 0,
            eight_point_inliers: 0,
            homography_gric_gain: None,
            pnp_correspondences: 0,
            pnp_inliers: 0,
            depth_cells: 0,
            window_points: 0,
            timings: StageTimings {
                total_ms: ms(t_total),
                ..StageTimings::default()
            },
            status: FrameStatus::Ok,
        }
    }

    /// The only step that changes the odometry's state: the pose chain, the mapper's update (scale keeper, window when it ran, depth map) and the tracker's image of
    /// the accepted frame.
    fn commit(
        &mut self,
        fused: &FusedPose,
        map: MapUpdate,
        (pyramid, thumbnail, valid_fraction): (Option<Pyramid>, Thumbnail, f64),
    ) {
        self.mapper.commit(map, fused);
        self.world_from_cam *= fused.motion.prev_from_cur();
        self.tracker
            .accept(pyramid, thumbnail, Some(valid_fraction));
        self.frame += 1;
    }

    /// The error of a frame that failed a trust test, with its warning (the state is unchanged).
    fn untrusted(&self, reason: UntrustedReason) -> MonoError {
        super::error::refused(self.frame, reason)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mono::correspondence::flow_of;

    #[test]
    fn low_parallax_frame_uses_pnp_or_fails_softly() {
        let cam = PinholeCamera::new(50.0, 50.0, 15.5, 11.5, 32, 24).unwrap();
        let img = GrayImage::new(32, 24, 100.0);
        // the flat placeholder image is refused by the trust tests (no texture) ...
        let mut trusting = MonoOdometry::new(cam, MonoConfig::default()).unwrap();
        assert!(matches!(
            trusting.process(&img, None, None),
            Err(MonoError::UntrustedFrame {
                reason: UntrustedReason::NoTexture { .. }
            })
        ));
        // ... which are off here: this test is about the geometric fallback of the flow
        let mut cfg = MonoConfig::default();
        cfg.trust.enabled = false;
        let mut vo = MonoOdometry::new(cam, cfg).unwrap();
        let first = vo.process(&img, None, None).unwrap();
        assert_eq!(first.source, PoseSource::Initial);
        assert_eq!(first.motion, None);
        // zero flow: no parallax, no depth prior → constant velocity (identity), status Failed
        let still = flow_of(32, 24, |_, _| ([0.0, 0.0], [1.0, 0.0, 1.0], true));
        let r = vo
            .process(&img, Some(&still), first.motion.as_ref())
            .unwrap();
        assert_eq!(r.source, PoseSource::ConstantVelocity);
        assert_eq!(r.status, FrameStatus::Failed);
        // the prior (none yet: no motion) repeated, returned for the driver to keep
        assert_eq!(r.motion, Some(RelativeMotion::identity()));
        assert!(r.world_from_cam.translation.vector.norm() < 1e-12);
        // a wrong-size flow is an error, not a panic
        let small = flow_of(8, 8, |_, _| ([0.0, 0.0], [1.0, 0.0, 1.0], true));
        assert!(matches!(
            vo.process(&img, Some(&small), r.motion.as_ref()),
            Err(MonoError::SizeMismatch { what: "flow", .. })
        ));
    }

    #[test]
    fn config_serde_and_validation() {
        let cfg: MonoConfig = serde_json::from_str(
            r#"{"scale":{"camera_height_m":1.65,"aerial":true},"eight_point":{"estimator":"sampson"}}"#,
        )
        .unwrap();
        assert!(cfg.scale.aerial);
        assert!(cfg.validate().is_ok());
        assert!(serde_json::from_str::<MonoConfig>(r#"{"nope":1}"#).is_err());
        let mut bad = MonoConfig::default();
        bad.scale.camera_height_m = -1.0;
        assert!(matches!(
            bad.validate(),
            Err(MonoError::InvalidConfig {
                field: "scale.camera_height_m",
                ..
            })
        ));
        let mut bad = MonoConfig::default();
        bad.parallax.min_translational_parallax_px = f64::NAN;
        assert!(matches!(
            bad.validate(),
            Err(MonoError::InvalidConfig {
                field: "parallax.min_translational_parallax_px",
                ..
            })
        ));
    }
}
