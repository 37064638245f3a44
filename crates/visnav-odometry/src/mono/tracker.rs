//! The tracker (§4–5): the motion of a frame from its flow. It measures (grid correspondences,
//! the parallax test, PnP against the mapper's depth map, the eight-point or the homography,
//! the translational parallax) and, once the mapper has scaled the eight-point's unit
//! translation, fuses the two motions and bounds the result. Its trust tests
//! ([`super::trust`], [`super::rigidity`]) refuse a frame: [`Estimate::Refused`].
//!
//! The tracker keeps only what it compares a frame with: the last accepted image's pyramid and
//! what the trust tests remember of the accepted frames.

use nalgebra::{Matrix3, Matrix6, Point2};
use visnav_core::{GrayImage, PinholeCamera, Pose};
use visnav_flow::DenseFlow;
use visnav_geometry::fundamental::mahalanobis_distance_sq;
use visnav_geometry::pnp::{PnpCorrespondence, solve_pnp};
use visnav_geometry::{Correspondence, relative_pose_from_fundamental};
use visnav_image::{CornerConfig, KltConfig, Pyramid, detect_corners, track};

use super::config::ParallaxConfig;
use super::context::FrameContext;
use super::correspondence::{
    correspondence_at, correspondences_from_flow, flow_percentile_px, median,
    translational_parallax_px,
};
use super::covariance::pnp_information;
use super::depth::DepthMap;
use super::eight_point::estimate_with_own_inlier_test;
use super::result::{FrameStatus, PoseSource, StageTimings, ms};
use super::rigidity::{self, AcceptedFrames};
use super::trust::{self, Thumbnail, TrustConfig, UntrustedReason};
use crate::RelativeMotion;

/// Stage 1 (§5 step 1): the flow subsampled on a grid, the most certain valid pixel per cell.
pub(super) struct Correspondences {
    pub(super) list: Vec<Correspondence>,
}

impl Correspondences {
    fn from_flow(flow: &DenseFlow, cell_px: usize) -> Self {
        Self {
            list: correspondences_from_flow(flow, cell_px),
        }
    }
}

/// Stage 2, the parallax test of §5: median KLT displacement ≥ `min_klt_median_px` and 75th
/// percentile of the flow magnitude > `min_flow_p75_px`.
pub(super) struct ParallaxTest {
    pub(super) flow_p75_px: f64,
    pub(super) klt_median_px: Option<f64>,
    pub(super) ok: bool,
}

impl ParallaxTest {
    fn run(
        cfg: &ParallaxConfig,
        flow: &DenseFlow,
        prev: Option<&Pyramid>,
        cur: Option<&Pyramid>,
    ) -> Self {
        let flow_p75_px = flow_percentile_px(flow, 0.75);
        let klt_median_px = match (prev, cur) {
            (Some(prev), Some(cur)) => klt_median_displacement(prev, cur),
            _ => None,
        };
        let ok = flow_p75_px > cfg.min_flow_p75_px
            && klt_median_px.is_none_or(|m| m >= cfg.min_klt_median_px);
        Self {
            flow_p75_px,
            klt_median_px,
            ok,
        }
    }
}

/// Stage 3 (§5): PnP of the current camera against the previous depth map.
pub(super) struct PnpEstimate {
    /// `cur_from_prev` with at least 10 inliers.
    pub(super) pose: Option<Pose>,
    pub(super) correspondences: usize,
    pub(super) inliers: usize,
    /// The Gauss–Newton Hessian of the inliers at `pose` ([`super::covariance::pnp_information`]).
    pub(super) information: Option<Matrix6<f64>>,
}

/// Stage 4 (§4, eq. 6–12): the eight-point pose with a unit translation.
pub(super) struct EightPointEstimate {
    /// `cur_from_prev` (the essential matrix's convention), unit translation.
    pub(super) unit_pose: Option<Pose>,
    /// Correspondences the motion model explains: the eight-point RANSAC's inliers, or the
    /// homography's where it wins the model selection and explains more.
    pub(super) inliers: usize,
    /// The model selection's GRIC gain, when the homography was fitted.
    pub(super) homography_gric_gain: Option<f64>,
    /// `unit_pose` is the plane's with the ground's normal held (`homography.ground_normal`).
    pub(super) held_normal: bool,
}

/// The homography's side of the model selection.
#[derive(Debug, Clone, Copy)]
struct PlanarEstimate {
    /// The motion of the homography (unit translation) when it won the selection.
    unit_pose: Option<Pose>,
    /// GRIC(F) − GRIC(H) per correspondence.
    gric_gain: f64,
    /// Whether the homography won the selection (`gric_gain > homography.min_gric_gain`).
    wins: bool,
    /// Correspondences the homography explains (its RANSAC inliers).
    inliers: usize,
}

/// Stage 5: translational parallax. With the rotation removed (PnP's, else the eight-point's;
/// the eight-point's first when it held the ground's normal, PnP against a floor's depth map
/// taking a sideways step for a rotation),
/// is there a baseline? Without one (standing still, rotation on the spot) the eight-point
/// translation is noise and a triangulation collapses towards zero depth, which would poison
/// the depth map and, through the depth ratio and PnP, lock the scale near zero.
pub(super) struct BaselineTest {
    pub(super) translational_parallax_px: Option<f64>,
    pub(super) has_baseline: bool,
}

impl BaselineTest {
    fn run(
        camera: &PinholeCamera,
        cfg: &ParallaxConfig,
        corrs: &[Correspondence],
        pnp_pose: Option<Pose>,
        eight_point: &EightPointEstimate,
    ) -> Self {
        let unit_pose = eight_point.unit_pose;
        let rotation_estimate = if eight_point.held_normal {
            unit_pose.or(pnp_pose)
        } else {
            pnp_pose.or(unit_pose)
        }
        .map(|p| p.rotation);
        let translational_parallax_px =
            rotation_estimate.and_then(|r| translational_parallax_px(camera, corrs, &r));
        let has_baseline =
            translational_parallax_px.is_none_or(|p| p >= cfg.min_translational_parallax_px);
        Self {
            translational_parallax_px,
            has_baseline,
        }
    }
}

/// What the tracker measured of a frame it does not refuse (stages 1–5): the mapper scales
/// `unit_pose`, then [`Tracker::estimate`] fuses it with `pnp`.
pub(super) struct Measured {
    pub(super) corrs: Correspondences,
    pub(super) parallax: ParallaxTest,
    pub(super) pnp: PnpEstimate,
    pub(super) eight_point: EightPointEstimate,
    pub(super) baseline: BaselineTest,
    /// The eight-point's unit-translation motion (`cur_from_prev`) where the frame has a
    /// baseline (or no PnP).
    pub(super) unit_pose: Option<Pose>,
}

/// Stage 7 (§5 fusion rule and the translation guard): the frame's motion.
#[derive(Debug, Clone, Copy)]
pub(super) struct FusedPose {
    pub(super) motion: RelativeMotion,
    pub(super) source: PoseSource,
    pub(super) status: FrameStatus,
}

/// The tracker's verdict on a frame's motion.
#[derive(Debug)]
pub(super) enum Estimate {
    /// The motion (a failed frame's is the constant-velocity prediction, status `Failed`).
    Accepted {
        /// The fused and bounded motion.
        motion: FusedPose,
    },
    /// A trust test refused the frame: it must leave no trace.
    Refused(UntrustedReason),
}

/// The tracker's state: the last accepted image and what the trust tests keep of the accepted
/// frames.
#[derive(Debug, Clone)]
pub(super) struct Tracker {
    /// The pyramid of the last accepted image (the parallax test's KLT, the window's tracks).
    prev_pyramid: Option<Pyramid>,
    /// What the trust tests keep of the accepted frames (last thumbnail, flows' valid shares).
    accepted: AcceptedFrames,
}

impl Tracker {
    /// Nothing accepted yet.
    pub(super) fn new(trust: &TrustConfig) -> Self {
        Self {
            prev_pyramid: None,
            accepted: AcceptedFrames::new(trust.valid_history_frames),
        }
    }

    /// The pyramid of the last accepted image.
    pub(super) fn prev_pyramid(&self) -> Option<&Pyramid> {
        self.prev_pyramid.as_ref()
    }

    /// The image's trust tests ([`trust::check_image`]; the upside-down test only with a flow
    /// and not in aerial mode, a downward view having no up): the image's thumbnail, or the
    /// reason to refuse it.
    pub(super) fn check_image(
        &self,
        ctx: &FrameContext<'_>,
        image: &GrayImage,
        has_flow: bool,
    ) -> Result<Thumbnail, UntrustedReason> {
        let thumbnail = Thumbnail::of(image, &ctx.config.trust);
        let last = self
            .accepted
            .last_thumbnail()
            .filter(|_| has_flow && !ctx.config.scale.aerial);
        trust::check_image(&thumbnail, last, &ctx.config.trust)?;
        Ok(thumbnail)
    }

    /// Stages 1–5 on the flow from the last accepted image (`prior`: the mapper's depth map of
    /// it; `pyramid`: the new image's): the flow's trust test, the grid correspondences, the
    /// parallax test, PnP, the eight-point (with its rigid-motion test) and the baseline test.
    pub(super) fn measure(
        &self,
        ctx: &FrameContext<'_>,
        (flow, prior, pyramid): (&DenseFlow, Option<&DepthMap>, Option<&Pyramid>),
        rng: &mut visnav_geometry::ChaCha8Rng,
        timings: &mut StageTimings,
    ) -> Result<Measured, UntrustedReason> {
        trust::check_flow(flow, &ctx.config.trust)?;
        let t = std::time::Instant::now();
        let corrs = Correspondences::from_flow(flow, ctx.config.grid_cell_px);
        timings.correspondences_ms = ms(t);

        let t = std::time::Instant::now();
        let parallax_cfg = ctx.config.parallax.for_width(ctx.camera.width);
        let use_klt = parallax_cfg.use_klt;
        let parallax = ParallaxTest::run(
            &parallax_cfg,
            flow,
            self.prev_pyramid.as_ref().filter(|_| use_klt),
            pyramid.filter(|_| use_klt),
        );
        timings.parallax_ms = ms(t);

        let t = std::time::Instant::now();
        let pnp = pnp(ctx, prior, flow, rng);
        timings.pnp_ms = ms(t);

        let t = std::time::Instant::now();
        let eight_point = eight_point(ctx, &corrs, parallax.ok || pnp.pose.is_none(), rng);
        timings.eight_point_ms = ms(t);
        let fit = (eight_point.inliers, corrs.list.len(), eight_point.unit_pose);
        let rigid = self.accepted.evidence(fit, ctx.last_motion.as_ref(), flow);
        rigidity::check_rigid_motion(ctx.frame, &rigid, &ctx.config.trust)?;

        let baseline = BaselineTest::run(
            ctx.camera,
            &parallax_cfg,
            &corrs.list,
            pnp.pose,
            &eight_point,
        );
        let unit_pose = eight_point
            .unit_pose
            .filter(|_| baseline.has_baseline || pnp.pose.is_none());
        Ok(Measured {
            corrs,
            parallax,
            pnp,
            eight_point,
            baseline,
            unit_pose,
        })
    }

    /// Stage 7: the frame's motion from the measurements and the scaled eight-point pose
    /// `scaled_pose` (§5 fusion rule), bounded by `max_translation_m`
    /// ([`guard_translation`]), then the motion's trust test ([`trust::check_motion`]).
    pub(super) fn estimate(
        ctx: &FrameContext<'_>,
        measured: &Measured,
        scaled_pose: Option<Pose>,
        max_translation_m: f64,
    ) -> Estimate {
        let fused = fuse(ctx, scaled_pose, measured);
        let fused = guard_translation(ctx, fused, max_translation_m);
        match trust::check_motion(&fused.motion, ctx.last_motion.as_ref(), &ctx.config.trust) {
            Ok(()) => Estimate::Accepted { motion: fused },
            Err(reason) => Estimate::Refused(reason),
        }
    }

    /// Keeps the accepted frame: its image's pyramid and thumbnail, its flow's valid share
    /// (`None` for a first image).
    pub(super) fn accept(
        &mut self,
        pyramid: Option<Pyramid>,
        thumbnail: Thumbnail,
        valid_fraction: Option<f64>,
    ) {
        self.prev_pyramid = pyramid;
        self.accepted.accept(thumbnail, valid_fraction);
    }
}

/// Eight-point stage (§4): uncertainty-guided RANSAC and the Mahalanobis eight-point (eq.
/// 6–12), `E = KᵀFK`, cheirality → a unit-translation pose. Run only when `run` (parallax
/// enough, or no PnP: no depth prior yet, e.g. at start-up, or PnP failed). With the model
/// selection on ([`planar_motion`]) a near-planar scene's motion comes from the
/// homography instead.
fn eight_point(
    ctx: &FrameContext<'_>,
    corrs: &Correspondences,
    run: bool,
    rng: &mut visnav_geometry::ChaCha8Rng,
) -> EightPointEstimate {
    let cfg = ctx.config;
    let none = EightPointEstimate {
        unit_pose: None,
        inliers: 0,
        homography_gric_gain: None,
        held_normal: false,
    };
    if !run {
        return none;
    }
    let Some(r) = estimate_with_own_inlier_test(
        &corrs.list,
        &cfg.eight_point,
        cfg.sampson_inlier_sigma_px,
        rng,
    ) else {
        return none;
    };
    let planar = cfg
        .homography
        .enabled(cfg.scale.aerial)
        .then(|| planar_motion(ctx, &corrs.list, &r.model, rng))
        .flatten();
    let held = cfg
        .homography
        .level_ground_normal()
        .filter(|_| cfg.scale.aerial)
        .and_then(|n| {
            use visnav_geometry::homography::{KnownNormalFit, relative_pose_with_plane_normal};
            relative_pose_with_plane_normal(&corrs.list, ctx.camera, &n, &KnownNormalFit::default())
        })
        .map(|m| m.cam2_from_cam1);
    let unit_pose = match planar {
        _ if held.is_some() => held,
        Some(PlanarEstimate {
            unit_pose: Some(p), ..
        }) => Some(p),
        _ => {
            let inl: Vec<&Correspondence> = corrs
                .list
                .iter()
                .zip(&r.inliers)
                .filter_map(|(c, &ok)| ok.then_some(c))
                .collect();
            relative_pose_from_fundamental(&r.model, ctx.camera, &inl).map(|p| p.cam2_from_cam1)
        }
    };
    // the rigid-motion test asks the model that explains the flow: where the homography wins
    // (a planar view, the eight-point model's degenerate case, whose RANSAC finds few inliers
    // in noisy flow) its inliers count too, so that a frame is refused only when neither model
    // explains the flow (issue 54 item 2)
    let inliers = match planar {
        Some(p) if p.wins => r.inlier_count.max(p.inliers),
        _ => r.inlier_count,
    };
    EightPointEstimate {
        unit_pose,
        inliers,
        homography_gric_gain: planar.map(|p| p.gric_gain),
        held_normal: held.is_some(),
    }
}

/// Model selection (`visnav_geometry::homography`): a homography by RANSAC, Torr's GRIC of
/// it and of the fundamental matrix `f`, and when the homography's is lower by more than
/// `homography.min_gric_gain` a correspondence, the motion of its factorisation chosen by
/// cheirality (unit translation). `None` without a homography.
fn planar_motion(
    ctx: &FrameContext<'_>,
    list: &[Correspondence],
    f: &Matrix3<f64>,
    rng: &mut visnav_geometry::ChaCha8Rng,
) -> Option<PlanarEstimate> {
    use visnav_geometry::homography::{
        CHI2_2DOF_95, estimate_homography, gric, relative_pose_from_homography, transfer_error_sq,
    };
    let cfg = &ctx.config.homography;
    let ransac = visnav_geometry::RansacConfig {
        inlier_threshold: CHI2_2DOF_95,
        ..ctx.config.eight_point.ransac
    };
    let h = estimate_homography(list, &ransac, rng)?;
    let g_h = gric(list.iter().map(|c| transfer_error_sq(&h.model, c)), 2, 8);
    let g_f = gric(list.iter().map(|c| mahalanobis_distance_sq(f, c)), 3, 7);
    let gric_gain = (g_f - g_h) / list.len().max(1) as f64;
    let wins = gric_gain > cfg.min_gric_gain;
    let unit_pose = wins
        .then(|| {
            let inl: Vec<&Correspondence> = list
                .iter()
                .zip(&h.inliers)
                .filter_map(|(c, &ok)| ok.then_some(c))
                .collect();
            let (m, _) =
                relative_pose_from_homography(&h.model, ctx.camera, &inl, cfg.cheirality_margin)?;
            let mut pose = m.cam2_from_cam1;
            let t = pose.translation.vector.norm();
            (t > 0.0).then(|| {
                pose.translation.vector /= t;
                pose
            })
        })
        .flatten();
    log::debug!(
        "mono frame {}: homography GRIC gain {gric_gain:.3} a correspondence{}",
        ctx.frame,
        if unit_pose.is_some() {
            ", motion from the homography"
        } else {
            ""
        }
    );
    Some(PlanarEstimate {
        unit_pose,
        gric_gain,
        wins,
        inliers: h.inlier_count,
    })
}

/// Fusion stage (§5): eight-point (`scaled_pose`) and PnP averaged when their scales (30 %),
/// rotations (0.5 rad) and translation directions agree; otherwise one of them (directions
/// disagreeing: the one nearer the previous motion's, or the eight-point's when it held the
/// ground's normal); neither gives the constant-velocity prediction.
fn fuse(ctx: &FrameContext<'_>, scaled_pose: Option<Pose>, measured: &Measured) -> FusedPose {
    let cfg = ctx.config;
    let (parallax, baseline) = (&measured.parallax, &measured.baseline);
    let n_correspondences = measured.corrs.list.len();
    let low_parallax_status = if parallax.ok && baseline.has_baseline {
        FrameStatus::Ok
    } else {
        FrameStatus::LowParallax
    };
    let fused = |cur_from_prev, source, status| FusedPose {
        motion: RelativeMotion::from_cur_from_prev(cur_from_prev),
        source,
        status,
    };
    match (scaled_pose, measured.pnp.pose) {
        (Some(e), Some(p)) => {
            let se = e.translation.vector.norm();
            let sp = p.translation.vector.norm();
            let dr = (e.rotation.inverse() * p.rotation).angle();
            let dt = translation_angle(&e, &p);
            if dt.is_some_and(|a| a > cfg.fusion_max_translation_angle_rad) {
                // the directions disagree: the one closer to the previous motion's
                let prior = |q: &Pose| {
                    ctx.last_motion
                        .and_then(|m| translation_angle(q, &m.cur_from_prev()))
                        .unwrap_or(f64::INFINITY)
                };
                if !measured.eight_point.held_normal && prior(&p) < prior(&e) {
                    fused(p, PoseSource::Pnp, FrameStatus::Ok)
                } else {
                    fused(e, PoseSource::EightPoint, FrameStatus::Ok)
                }
            } else if (sp - se).abs() <= cfg.fusion_max_scale_diff * se
                && dr <= cfg.fusion_max_rotation_rad
            {
                let t = (e.translation.vector + p.translation.vector) * 0.5;
                let r = e.rotation.slerp(&p.rotation, 0.5);
                fused(
                    Pose::from_parts(t.into(), r),
                    PoseSource::Fused,
                    FrameStatus::Ok,
                )
            } else {
                fused(e, PoseSource::EightPoint, FrameStatus::Ok)
            }
        }
        (Some(e), None) => fused(e, PoseSource::EightPoint, low_parallax_status),
        (None, Some(p)) => fused(p, PoseSource::Pnp, low_parallax_status),
        (None, None) => {
            log::warn!(
                "mono frame {}: no pose (parallax ok: {}, {n_correspondences} correspondences); constant velocity",
                ctx.frame,
                parallax.ok,
            );
            constant_velocity(ctx)
        }
    }
}

/// The constant-velocity prediction as a failed frame's pose.
fn constant_velocity(ctx: &FrameContext<'_>) -> FusedPose {
    FusedPose {
        motion: ctx.last_motion.unwrap_or_else(RelativeMotion::identity),
        source: PoseSource::ConstantVelocity,
        status: FrameStatus::Failed,
    }
}

/// A gross failure must not make the trajectory diverge: an absurd translation (longer than
/// `max_m`, the mapper's bound) is replaced by the constant-velocity prediction.
fn guard_translation(ctx: &FrameContext<'_>, fused: FusedPose, max_m: f64) -> FusedPose {
    let length = fused.motion.length_m();
    if length.is_finite() && length <= max_m {
        fused
    } else {
        log::warn!(
            "mono frame {}: {:?} translation of {length:.3e} m exceeds the bound of {max_m:.3} m (max_translation_m, aerial: scale.aerial_max_step_heights); rejected, constant velocity",
            ctx.frame,
            fused.source,
        );
        constant_velocity(ctx)
    }
}

/// PnP of the current camera against the prior depth map (in the previous camera) through the
/// flow at the known cells (see [`pnp_against_depth`]).
fn pnp(
    ctx: &FrameContext<'_>,
    prior: Option<&DepthMap>,
    flow: &DenseFlow,
    rng: &mut visnav_geometry::ChaCha8Rng,
) -> PnpEstimate {
    let estimate = |pose, correspondences, inliers| PnpEstimate {
        pose,
        correspondences,
        inliers,
        information: None,
    };
    let Some(prior) = prior else {
        return estimate(None, 0, 0);
    };
    let (data, result) = pnp_against_depth(ctx.camera, &ctx.config.pnp, prior, flow, rng);
    match result {
        Some(r) if r.inlier_count >= 10 => {
            PnpEstimate {
                information: ctx.config.covariance.enabled.then(|| {
                    pnp_information(ctx.camera, &data, &r, ctx.config.covariance.depth_sigma)
                }),
                ..estimate(Some(r.cam_from_world), data.len(), r.inlier_count)
            }
        }
        Some(r) => estimate(None, data.len(), r.inlier_count),
        None => estimate(None, data.len(), 0),
    }
}

/// PnP of the second camera of `flow` against `depth` (a depth map in the first camera) through
/// the flow at the known cells (at most ~3000, evenly strided). Returns the correspondences (the
/// "world" is the first camera) and the RANSAC result (`None` with fewer than 10 correspondences
/// or no model).
pub(crate) fn pnp_against_depth(
    camera: &PinholeCamera,
    config: &visnav_geometry::pnp::PnpConfig,
    depth: &DepthMap,
    flow: &DenseFlow,
    rng: &mut visnav_geometry::ChaCha8Rng,
) -> (
    Vec<PnpCorrespondence>,
    Option<visnav_geometry::pnp::PnpResult>,
) {
    let known: Vec<usize> = (0..depth.depth_m.len())
        .filter(|&i| depth.depth_m[i].is_finite())
        .collect();
    let step = (known.len() / 3000).max(1);
    let data: Vec<PnpCorrespondence> = known
        .iter()
        .step_by(step)
        .filter_map(|&i| {
            // the point at its own pixel, its flow from the pixel nearest to it
            let px = depth.point_pixel(i);
            let x = px.x.round().clamp(0.0, (flow.width - 1) as f64);
            let y = px.y.round().clamp(0.0, (flow.height - 1) as f64);
            let c = correspondence_at(flow, x as usize, y as usize)?;
            let (d, _) = depth.get(i)?;
            Some(PnpCorrespondence {
                p_in_world: camera.unproject(&px, d),
                p_px: c.p2_px + (px - c.p1_px),
                information: c.information,
            })
        })
        .collect();
    if data.len() < 10 {
        return (data, None);
    }
    let result = solve_pnp(camera, &data, config, rng);
    (data, result)
}

/// Median displacement of Shi–Tomasi corners of the previous image tracked by KLT into the
/// current one, pixels; `None` when nothing is tracked.
fn klt_median_displacement(prev: &Pyramid, cur: &Pyramid) -> Option<f64> {
    let corners = detect_corners(prev.base(), &CornerConfig::default());
    let points: Vec<Point2<f64>> = corners.iter().map(|c| c.px).collect();
    let tracks = track(prev, cur, &points, None, &KltConfig::default()).ok()?;
    let mut disp: Vec<f64> = points
        .iter()
        .zip(&tracks)
        .filter_map(|(p, t)| t.tracked().map(|q| (q - p).norm()))
        .collect();
    median(&mut disp)
}

/// The angle between the translation directions of two poses, radians; `None` when either
/// translation is (nearly) zero.
fn translation_angle(a: &Pose, b: &Pose) -> Option<f64> {
    let (ta, tb) = (a.translation.vector, b.translation.vector);
    let n = ta.norm() * tb.norm();
    (n > 1e-12).then(|| (ta.dot(&tb) / n).clamp(-1.0, 1.0).acos())
}
