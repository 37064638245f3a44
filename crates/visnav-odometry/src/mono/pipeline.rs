//! The monocular pipeline of §5: [`MonoOdometry::process`] turns one image and the dense flow
//! from the previous image into a pose.

use std::time::Instant;

use nalgebra::{Matrix3, Point2, Point3, UnitQuaternion, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use visnav_core::se3::skew;
use visnav_core::{GrayImage, PinholeCamera, Pose};
use visnav_flow::DenseFlow;
use visnav_geometry::fundamental::mahalanobis_distance_sq;
use visnav_geometry::plane::{
    GroundPlane, Plane, fit_dominant_plane, fit_ground_plane, fit_plane_near,
};
use visnav_geometry::pnp::{PnpCorrespondence, solve_pnp};
use visnav_geometry::triangulation::{
    InverseDepthPoint, TriangulatedPoint, triangulate, triangulate_inverse_depth,
};
use visnav_geometry::{Correspondence, relative_pose_from_fundamental, seeded_rng};
use visnav_image::{CornerConfig, KltConfig, Pyramid, detect_corners, track};

use super::depth::InterpolatedDepth;
use super::eight_point::estimate_with_own_inlier_test;
use super::point_scale::{PointScale, scale_at_map_points};
use super::trust::{self, Thumbnail, UntrustedReason};
use super::window::{MonoWindow, StepChange, WindowScale, WindowStep};
use super::{DepthMap, KnownDistance, MonoConfig, MonoError, ParallaxConfig, rigidity};

/// The depth-ratio scale reads the new triangulation between four cells whose inverse depths
/// are within 10 % of each other (on one surface).
const RATIO_MAX_SPREAD: f64 = 0.1;

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
    /// Motion from the previous camera, metres.
    pub cur_from_prev: Pose,
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
    /// rotation estimate exists. See [`translational_parallax_px`].
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

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// The correspondence of pixel `(x, y)` if its flow is valid, lands inside the image and has a
/// positive-definite information matrix.
fn correspondence_at(flow: &DenseFlow, x: usize, y: usize) -> Option<Correspondence> {
    let i = y * flow.width + x;
    if !flow.valid[i] {
        return None;
    }
    let [u, v] = flow.flow[i];
    let (x2, y2) = (x as f64 + f64::from(u), y as f64 + f64::from(v));
    if !(x2 >= 0.0 && y2 >= 0.0 && x2 <= (flow.width - 1) as f64 && y2 <= (flow.height - 1) as f64)
    {
        return None;
    }
    let c = Correspondence {
        p1_px: Point2::new(x as f64, y as f64),
        p2_px: Point2::new(x2, y2),
        information: flow.information_at(i).to_matrix(),
    };
    (c.certainty() > 0.0).then_some(c)
}

/// Grid subsampling of dense flow: in each `cell_px` x `cell_px` cell, the valid pixel of
/// highest certainty `sqrt(det Y)` (ties: the first in row-major order).
#[must_use]
pub fn correspondences_from_flow(flow: &DenseFlow, cell_px: usize) -> Vec<Correspondence> {
    let cell = cell_px.max(1);
    let cols = flow.width.div_ceil(cell);
    let rows = flow.height.div_ceil(cell);
    (0..rows)
        .into_par_iter()
        .flat_map_iter(|cy| {
            (0..cols).filter_map(move |cx| {
                let mut best: Option<Correspondence> = None;
                for y in cy * cell..((cy + 1) * cell).min(flow.height) {
                    for x in cx * cell..((cx + 1) * cell).min(flow.width) {
                        if let Some(c) = correspondence_at(flow, x, y)
                            && best.as_ref().is_none_or(|b| c.certainty() > b.certainty())
                        {
                            best = Some(c);
                        }
                    }
                }
                best
            })
        })
        .collect()
}

/// The `q`-quantile (0..1) of the magnitude of the valid flow, pixels (every other pixel in
/// both directions); 0 without valid flow.
#[must_use]
pub fn flow_percentile_px(flow: &DenseFlow, q: f64) -> f64 {
    let mut mags: Vec<f32> = (0..flow.height)
        .step_by(2)
        .flat_map(|y| (0..flow.width).step_by(2).map(move |x| y * flow.width + x))
        .filter(|&i| flow.valid[i])
        .map(|i| flow.flow[i][0].hypot(flow.flow[i][1]))
        .collect();
    if mags.is_empty() {
        return 0.0;
    }
    let k = ((mags.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    f64::from(*mags.select_nth_unstable_by(k, f32::total_cmp).1)
}

/// Median translational parallax of `corrs`, pixels: `‖p₂ − π(R K⁻¹ p̃₁)‖`, i.e. the displacement
/// left after the rotation `cur_from_prev_rotation` is removed through the infinite homography
/// `K R K⁻¹` (points at infinity move by the rotation alone). Near zero when the camera stands
/// still or rotates on the spot, where the eight-point translation direction is undefined and a
/// triangulation has no baseline. `None` without correspondences.
#[must_use]
pub fn translational_parallax_px(
    camera: &PinholeCamera,
    corrs: &[Correspondence],
    cur_from_prev_rotation: &UnitQuaternion<f64>,
) -> Option<f64> {
    let mut residuals: Vec<f64> = corrs
        .iter()
        .filter_map(|c| {
            let ray_in_cur = cur_from_prev_rotation * camera.ray(&c.p1_px);
            camera
                .project(&Point3::from(ray_in_cur))
                .map(|px| (c.p2_px - px).norm())
        })
        .collect();
    median(&mut residuals)
}

fn median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mid = values.len() / 2;
    Some(*values.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// The angle between the translation directions of two poses, radians; `None` when either
/// translation is (nearly) zero.
fn translation_angle(a: &Pose, b: &Pose) -> Option<f64> {
    let (ta, tb) = (a.translation.vector, b.translation.vector);
    let n = ta.norm() * tb.norm();
    (n > 1e-12).then(|| (ta.dot(&tb) / n).clamp(-1.0, 1.0).acos())
}

/// The fundamental matrix of a relative pose: `F = K⁻ᵀ [t]ₓ R K⁻¹`.
pub(crate) fn fundamental_of(camera: &PinholeCamera, cur_from_prev: &Pose) -> Matrix3<f64> {
    let k_inv = camera.k_inv();
    let e = skew(&cur_from_prev.translation.vector)
        * cur_from_prev.rotation.to_rotation_matrix().matrix();
    k_inv.transpose() * e * k_inv
}

/// The monocular odometry state machine (see the module docs).
#[derive(Debug, Clone)]
pub struct MonoOdometry {
    config: MonoConfig,
    camera: PinholeCamera,
    frame: usize,
    world_from_cam: Pose,
    last_motion: Option<Pose>,
    prev_pyramid: Option<Pyramid>,
    /// Depth map of the previous frame (propagated and fused), in the previous camera.
    prior: Option<DepthMap>,
    /// Camera height re-estimated from the reconstruction (aerial), metres.
    estimated_height_m: f64,
    aerial_initialised: bool,
    /// Aerial: the one re-anchoring over the first frames after initialisation is done.
    aerial_anchored: bool,
    /// `ln(ground candidate / chosen scale)` of the recent frames with a ground candidate
    /// (the re-anchoring test).
    ground_log_ratios: std::collections::VecDeque<f64>,
    /// Aerial: the ground's normal and the camera's height above it, tracked from the
    /// initialisation (`scale.aerial_ground_weight`).
    tracked_ground: Option<TrackedGround>,
    /// What the trust tests keep of the accepted frames (last thumbnail, flows' valid shares).
    accepted: rigidity::AcceptedFrames,
    /// The window of the last frames and their tracks (`window.mode`).
    window: Option<MonoWindow>,
}

/// Aerial: the ground plane as the paper's aerial mode keeps it (§6.2: the camera height
/// "updated for each motion"): its unit normal in the camera the next frame's scale refers to
/// (pointing from the camera to the ground) and that camera's height above it. The normal is
/// carried in the camera, not in the world, so that a drift of the trajectory's rotation does
/// not turn the forward motion into a climb; each frame whose ground is found replaces it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct TrackedGround {
    normal_in_cam: Vector3<f64>,
    height_m: f64,
}

impl TrackedGround {
    /// After the step `cur_from_prev` (metres): the camera's displacement along the normal
    /// brings it nearer the ground; the normal turns into the new camera.
    fn after_step(self, cur_from_prev: &Pose) -> Self {
        let cur_in_prev = cur_from_prev.inverse().translation.vector;
        Self {
            normal_in_cam: cur_from_prev.rotation * self.normal_in_cam,
            height_m: self.height_m - self.normal_in_cam.dot(&cur_in_prev),
        }
    }

    /// The ground where a reconstruction at the scale `scale_m` (metres a unit of translation)
    /// expects it: a plane in the camera, unit-translation units.
    fn predicted_plane(&self, scale_m: f64) -> Plane {
        Plane {
            normal: self.normal_in_cam,
            offset: -self.height_m / scale_m,
        }
    }
}

/// The outcome of the scale stage.
struct ScaleEstimate {
    /// The chosen translation length, metres.
    scale_m: Option<f64>,
    /// Where it came from.
    source: ScaleSource,
    /// The ground-plane candidate (before the motion-prior gate).
    ground_m: Option<f64>,
    /// The depth-ratio candidate (before the motion-prior gate).
    depth_ratio_m: Option<f64>,
}

/// The scale candidates of a frame (§5), before the motion-prior gate.
struct ScaleCandidates {
    /// The fitted ground plane (unit-translation units).
    ground: Option<visnav_geometry::plane::GroundPlane>,
    /// Ground-plane scale `s = −(b·h)/d` with the configured camera height, metres.
    ground_m: Option<f64>,
    /// Median depth ratio against the previous depth map, metres.
    depth_m: Option<f64>,
    /// Share of the triangulated cells the previous depth map also has.
    overlap: f64,
    /// Scale from `scale.known_distance`, metres (first frame pair only).
    known_m: Option<f64>,
}

/// A dense triangulation on the depth grid.
struct CellPoint {
    cell: usize,
    point: TriangulatedPoint,
}

/// Stage 1 (§5 step 1): the flow subsampled on a grid, the most certain valid pixel per cell.
struct Correspondences {
    list: Vec<Correspondence>,
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
struct ParallaxTest {
    flow_p75_px: f64,
    klt_median_px: Option<f64>,
    ok: bool,
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
struct PnpEstimate {
    /// `cur_from_prev` with at least 10 inliers.
    pose: Option<Pose>,
    correspondences: usize,
    inliers: usize,
}

/// Stage 4 (§4, eq. 6–12): the eight-point pose with a unit translation.
struct EightPointEstimate {
    unit_pose: Option<Pose>,
    inliers: usize,
    /// The model selection's GRIC gain, when the homography was fitted.
    homography_gric_gain: Option<f64>,
}

/// The homography's side of the model selection.
#[derive(Debug, Clone, Copy)]
struct PlanarEstimate {
    /// The motion of the homography (unit translation) when it won the selection.
    unit_pose: Option<Pose>,
    /// GRIC(F) − GRIC(H) per correspondence.
    gric_gain: f64,
}

/// Stage 5: translational parallax. With the rotation removed (PnP's, else the eight-point's),
/// is there a baseline? Without one (standing still, rotation on the spot) the eight-point
/// translation is noise and a triangulation collapses towards zero depth, which would poison
/// the depth map and, through the depth ratio and PnP, lock the scale near zero.
struct BaselineTest {
    translational_parallax_px: Option<f64>,
    has_baseline: bool,
}

impl BaselineTest {
    fn run(
        camera: &PinholeCamera,
        cfg: &ParallaxConfig,
        corrs: &[Correspondence],
        pnp_pose: Option<Pose>,
        unit_pose: Option<Pose>,
    ) -> Self {
        let rotation_estimate = pnp_pose.or(unit_pose).map(|p| p.rotation);
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

/// The scale stage's state for the next frames (committed only when the frame is accepted).
struct ScaleState {
    ground_log_ratios: std::collections::VecDeque<f64>,
    aerial_initialised: bool,
    aerial_anchored: bool,
    estimated_height_m: f64,
    tracked_ground: Option<TrackedGround>,
}

/// Stage 6 (§5): the eight-point pose with its metric scale (ground plane `s = −(b·h)/d`
/// and/or median depth ratio).
struct ScaledEightPoint {
    pose: Option<Pose>,
    estimate: ScaleEstimate,
    /// `None` when no eight-point pose was scaled (the state is unchanged).
    state: Option<ScaleState>,
}

/// Stage 7 (§5 fusion rule and the translation guard): the frame's motion.
struct FusedPose {
    cur_from_prev: Pose,
    source: PoseSource,
    status: FrameStatus,
}

/// Stage 8 (§5): the fused depth map propagated into the current camera.
struct DepthUpdate {
    next: DepthMap,
    known_cells: usize,
}

impl MonoOdometry {
    /// A pipeline for `camera`.
    ///
    /// # Errors
    /// [`MonoError`] when the configuration is invalid.
    pub fn new(camera: PinholeCamera, config: MonoConfig) -> Result<Self, MonoError> {
        config.validate()?;
        Ok(Self {
            estimated_height_m: config.scale.camera_height_m,
            accepted: rigidity::AcceptedFrames::new(config.trust.valid_history_frames),
            config,
            camera,
            frame: 0,
            world_from_cam: Pose::identity(),
            last_motion: None,
            prev_pyramid: None,
            prior: None,
            aerial_initialised: false,
            aerial_anchored: false,
            ground_log_ratios: std::collections::VecDeque::new(),
            tracked_ground: None,
            window: None,
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
        self.prior.as_ref()
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

    /// Processes the next image. `flow` is the dense flow from the previous image to this one;
    /// `None` for the first image (the pose is the identity, or unchanged after a reset).
    ///
    /// Stages (§5, module docs): `Correspondences` (grid), `ParallaxTest`, `PnpEstimate`
    /// (previous depth map), `EightPointEstimate` (§4, eq. 6–12), `BaselineTest`,
    /// `ScaledEightPoint` (ground plane `s = −(b·h)/d` and depth ratio), `FusedPose` (fusion
    /// rule and the translation guard), `DepthUpdate`; the odometry's state is changed only by
    /// the last step, `Self::commit`. The trust tests ([`super::trust`]) run on the image
    /// first, on the flow after the size check, on the eight-point's inlier share and (when
    /// configured) on the fused motion.
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
    ) -> Result<MonoFrameResult, MonoError> {
        let t_total = Instant::now();
        self.check_size("image", image.width(), image.height())?;
        let thumbnail = Thumbnail::of(image, &self.config.trust);
        // the upside-down test needs an up: none in aerial mode (a downward view)
        let last = self
            .accepted
            .last_thumbnail()
            .filter(|_| flow.is_some() && !self.config.scale.aerial);
        trust::check_image(&thumbnail, last, &self.config.trust).map_err(|r| self.untrusted(r))?;
        // the parallax test's KLT and the window's track refinement align patches
        let window = &self.config.window;
        let pyramid = (self.config.parallax.use_klt
            || (window.runs(self.config.scale.aerial) && window.refine_tracks))
            .then(|| Pyramid::build(image, 3));
        let Some(flow) = flow else {
            return Ok(self.first_frame(pyramid, thumbnail, t_total));
        };
        self.check_size("flow", flow.width, flow.height)?;
        trust::check_flow(flow, &self.config.trust).map_err(|r| self.untrusted(r))?;
        let mut timings = StageTimings::default();
        let mut rng =
            seeded_rng(self.config.seed ^ (self.frame as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));

        let t = Instant::now();
        let corrs = Correspondences::from_flow(flow, self.config.grid_cell_px);
        timings.correspondences_ms = ms(t);

        let t = Instant::now();
        let parallax_cfg = self.config.parallax.for_width(self.camera.width);
        let use_klt = parallax_cfg.use_klt;
        let parallax = ParallaxTest::run(
            &parallax_cfg,
            flow,
            self.prev_pyramid.as_ref().filter(|_| use_klt),
            pyramid.as_ref().filter(|_| use_klt),
        );
        timings.parallax_ms = ms(t);

        let t = Instant::now();
        let pnp = self.pnp(flow, &mut rng);
        timings.pnp_ms = ms(t);

        let t = Instant::now();
        let eight_point = self.eight_point(&corrs, parallax.ok || pnp.pose.is_none(), &mut rng);
        timings.eight_point_ms = ms(t);
        let fit = (eight_point.inliers, corrs.list.len(), eight_point.unit_pose);
        let rigid = self.accepted.evidence(fit, self.last_motion.as_ref(), flow);
        rigidity::check_rigid_motion(self.frame, &rigid, &self.config.trust)
            .map_err(|r| self.untrusted(r))?;

        let baseline = BaselineTest::run(
            &self.camera,
            &parallax_cfg,
            &corrs.list,
            pnp.pose,
            eight_point.unit_pose,
        );
        let unit_pose = eight_point
            .unit_pose
            .filter(|_| baseline.has_baseline || pnp.pose.is_none());

        let scaled = self.scaled_eight_point(flow, unit_pose, pnp.pose, &mut rng, &mut timings);

        let fused = self.fuse(&scaled, &pnp, &parallax, &baseline, corrs.list.len());
        let fused = self.guard_translation(fused);
        trust::check_motion(
            &fused.cur_from_prev,
            self.last_motion.as_ref(),
            &self.config.trust,
        )
        .map_err(|r| self.untrusted(r))?;

        let t = Instant::now();
        let images = self.prev_pyramid.as_ref().zip(pyramid.as_ref());
        let (fused, window) =
            self.window_step((flow, images), &corrs.list, fused, scaled.estimate.ground_m);
        timings.window_ms = ms(t);

        let depth = self.depth_update(flow, &fused, baseline.has_baseline, &mut timings);

        let window_points = window.as_ref().map_or(0, |w| w.points);
        self.commit(
            &fused,
            (scaled.state, window.map(|w| w.window)),
            depth.next,
            (pyramid, thumbnail, flow.valid_fraction()),
        );
        timings.total_ms = ms(t_total);
        Ok(MonoFrameResult {
            frame: self.frame - 1,
            world_from_cam: self.world_from_cam,
            cur_from_prev: fused.cur_from_prev,
            source: fused.source,
            scale_source: scaled.estimate.source,
            scale_m: scaled
                .pose
                .map_or(f64::NAN, |p| p.translation.vector.norm()),
            scale_ground_m: scaled.estimate.ground_m,
            scale_depth_m: scaled.estimate.depth_ratio_m,
            klt_median_px: parallax.klt_median_px,
            flow_p75_px: parallax.flow_p75_px,
            translational_parallax_px: baseline.translational_parallax_px,
            correspondences: corrs.list.len(),
            eight_point_inliers: eight_point.inliers,
            homography_gric_gain: eight_point.homography_gric_gain,
            pnp_correspondences: pnp.correspondences,
            pnp_inliers: pnp.inliers,
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
    /// ([`super::TrustConfig::max_reference_gap_frames`]). Not in the paper.
    ///
    /// # Errors
    /// As [`Self::process`]: the size check and the image tests (no texture, noise) run first;
    /// on an error the state is unchanged.
    pub fn restart(
        &mut self,
        image: &GrayImage,
        world_from_cam: Pose,
    ) -> Result<MonoFrameResult, MonoError> {
        let kept_pose = self.world_from_cam;
        self.world_from_cam = world_from_cam;
        match self.process(image, None) {
            Ok(r) => {
                self.aerial_initialised = false;
                self.aerial_anchored = false;
                self.ground_log_ratios.clear();
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
        t_total: Instant,
    ) -> MonoFrameResult {
        let frame = self.frame;
        self.frame += 1;
        self.prev_pyramid = pyramid;
        self.accepted.accept(thumbnail, None);
        self.prior = None;
        self.window = self
            .config
            .window
            .runs(self.config.scale.aerial)
            .then(|| MonoWindow::start(self.world_from_cam));
        MonoFrameResult {
            frame,
            world_from_cam: self.world_from_cam,
            cur_from_prev: Pose::identity(),
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

    /// Eight-point stage (§4): uncertainty-guided RANSAC and the Mahalanobis eight-point (eq.
    /// 6–12), `E = KᵀFK`, cheirality → a unit-translation pose. Run only when `run` (parallax
    /// enough, or no PnP: no depth prior yet, e.g. at start-up, or PnP failed). With the model
    /// selection on ([`Self::planar_motion`]) a near-planar scene's motion comes from the
    /// homography instead.
    fn eight_point(
        &self,
        corrs: &Correspondences,
        run: bool,
        rng: &mut visnav_geometry::ChaCha8Rng,
    ) -> EightPointEstimate {
        let cfg = &self.config;
        let none = EightPointEstimate {
            unit_pose: None,
            inliers: 0,
            homography_gric_gain: None,
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
            .then(|| self.planar_motion(&corrs.list, &r.model, rng))
            .flatten();
        let unit_pose = match planar {
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
                relative_pose_from_fundamental(&r.model, &self.camera, &inl)
                    .map(|p| p.cam2_from_cam1)
            }
        };
        EightPointEstimate {
            unit_pose,
            inliers: r.inlier_count,
            homography_gric_gain: planar.map(|p| p.gric_gain),
        }
    }

    /// Model selection (`visnav_geometry::homography`): a homography by RANSAC, Torr's GRIC of
    /// it and of the fundamental matrix `f`, and when the homography's is lower by more than
    /// `homography.min_gric_gain` a correspondence, the motion of its factorisation chosen by
    /// cheirality (unit translation). `None` without a homography.
    fn planar_motion(
        &self,
        list: &[Correspondence],
        f: &Matrix3<f64>,
        rng: &mut visnav_geometry::ChaCha8Rng,
    ) -> Option<PlanarEstimate> {
        use visnav_geometry::homography::{
            CHI2_2DOF_95, estimate_homography, gric, relative_pose_from_homography,
            transfer_error_sq,
        };
        let cfg = &self.config.homography;
        let ransac = visnav_geometry::RansacConfig {
            inlier_threshold: CHI2_2DOF_95,
            ..self.config.eight_point.ransac
        };
        let h = estimate_homography(list, &ransac, rng)?;
        let g_h = gric(list.iter().map(|c| transfer_error_sq(&h.model, c)), 2, 8);
        let g_f = gric(list.iter().map(|c| mahalanobis_distance_sq(f, c)), 3, 7);
        let gric_gain = (g_f - g_h) / list.len().max(1) as f64;
        let unit_pose = (gric_gain > cfg.min_gric_gain)
            .then(|| {
                let inl: Vec<&Correspondence> = list
                    .iter()
                    .zip(&h.inliers)
                    .filter_map(|(c, &ok)| ok.then_some(c))
                    .collect();
                let (m, _) = relative_pose_from_homography(
                    &h.model,
                    &self.camera,
                    &inl,
                    cfg.cheirality_margin,
                )?;
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
            self.frame,
            if unit_pose.is_some() {
                ", motion from the homography"
            } else {
                ""
            }
        );
        Some(PlanarEstimate {
            unit_pose,
            gric_gain,
        })
    }

    /// Scale stage (§5): the unit-scale dense triangulation, then the scale
    /// ([`Self::scale`]); the eight-point pose scaled by it.
    fn scaled_eight_point(
        &self,
        flow: &DenseFlow,
        unit_pose: Option<Pose>,
        pnp_pose: Option<Pose>,
        rng: &mut visnav_geometry::ChaCha8Rng,
        timings: &mut StageTimings,
    ) -> ScaledEightPoint {
        let Some(unit) = unit_pose else {
            return ScaledEightPoint {
                pose: None,
                estimate: ScaleEstimate {
                    scale_m: None,
                    source: ScaleSource::None,
                    ground_m: None,
                    depth_ratio_m: None,
                },
                state: None,
            };
        };
        // the metric depth limit in units of this frame's translation, predicted from the
        // previous translation length (far points only add noise to the scale)
        let unit_max_depth = self.max_depth_m()
            / self
                .last_motion
                .map_or(1.0, |p| p.translation.vector.norm())
                .max(1e-3);
        let t = Instant::now();
        let cells = self.triangulate_cells(flow, &unit, unit_max_depth);
        timings.triangulation_ms += ms(t);
        let t = Instant::now();
        let pnp_scale = pnp_pose.map(|p| p.translation.vector.norm());
        let at_points = self.scale_at_points(flow, &unit);
        let (estimate, state) = self.scale(&cells, pnp_scale, at_points, rng);
        let pose = estimate.scale_m.map(|s| {
            let mut p = unit;
            p.translation.vector *= s;
            p
        });
        timings.scale_ms = ms(t);
        ScaledEightPoint {
            pose,
            estimate,
            state: Some(state),
        }
    }

    /// Fusion stage (§5): eight-point and PnP averaged when their scales (30 %), rotations
    /// (0.5 rad) and translation directions agree; otherwise one of them; neither gives the
    /// constant-velocity prediction.
    fn fuse(
        &self,
        scaled: &ScaledEightPoint,
        pnp: &PnpEstimate,
        parallax: &ParallaxTest,
        baseline: &BaselineTest,
        n_correspondences: usize,
    ) -> FusedPose {
        let cfg = &self.config;
        let low_parallax_status = if parallax.ok && baseline.has_baseline {
            FrameStatus::Ok
        } else {
            FrameStatus::LowParallax
        };
        let fused = |cur_from_prev, source, status| FusedPose {
            cur_from_prev,
            source,
            status,
        };
        match (scaled.pose, pnp.pose) {
            (Some(e), Some(p)) => {
                let se = e.translation.vector.norm();
                let sp = p.translation.vector.norm();
                let dr = (e.rotation.inverse() * p.rotation).angle();
                let dt = translation_angle(&e, &p);
                if dt.is_some_and(|a| a > cfg.fusion_max_translation_angle_rad) {
                    // the directions disagree: the one closer to the previous motion's
                    let prior = |q: &Pose| {
                        self.last_motion
                            .and_then(|m| translation_angle(q, &m))
                            .unwrap_or(f64::INFINITY)
                    };
                    if prior(&p) < prior(&e) {
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
                    self.frame,
                    parallax.ok,
                );
                self.constant_velocity()
            }
        }
    }

    /// The constant-velocity prediction as a failed frame's pose.
    fn constant_velocity(&self) -> FusedPose {
        FusedPose {
            cur_from_prev: self.last_motion.unwrap_or_else(Pose::identity),
            source: PoseSource::ConstantVelocity,
            status: FrameStatus::Failed,
        }
    }

    /// Whether the depth map is an unfiltered inverse-depth filter (`inverse_depth_filter`,
    /// with sub-pixel points only).
    fn inverse_depth_filter(&self) -> bool {
        self.config.inverse_depth_filter && self.subpixel_depth()
    }

    /// Whether the depth map keeps sub-pixel points (`depth_points`).
    fn subpixel_depth(&self) -> bool {
        self.config.depth_points.subpixel(self.config.scale.aerial)
    }

    /// The translation bound, metres: `max_translation_m`, in aerial mode at least
    /// `aerial_max_step_heights` camera heights (the height the reconstruction last saw).
    fn max_translation_m(&self) -> f64 {
        let cfg = &self.config;
        self.aerial_bound(cfg.max_translation_m, cfg.scale.aerial_max_step_heights)
    }

    /// The depth bound, metres: `max_depth_m`, in aerial mode at least
    /// `aerial_max_depth_heights` camera heights.
    fn max_depth_m(&self) -> f64 {
        let cfg = &self.config;
        self.aerial_bound(cfg.max_depth_m, cfg.scale.aerial_max_depth_heights)
    }

    /// `vehicle_m`, in aerial mode at least `heights` camera heights.
    fn aerial_bound(&self, vehicle_m: f64, heights: f64) -> f64 {
        if self.config.scale.aerial {
            vehicle_m.max(heights * self.estimated_height_m)
        } else {
            vehicle_m
        }
    }

    /// A gross failure must not make the trajectory diverge: an absurd translation is replaced by
    /// the constant-velocity prediction.
    fn guard_translation(&self, fused: FusedPose) -> FusedPose {
        let length = fused.cur_from_prev.translation.vector.norm();
        let max_m = self.max_translation_m();
        if length.is_finite() && length <= max_m {
            fused
        } else {
            log::warn!(
                "mono frame {}: {:?} translation of {length:.3e} m exceeds the bound of {max_m:.3} m (max_translation_m, aerial: scale.aerial_max_step_heights); rejected, constant velocity",
                self.frame,
                fused.source,
            );
            self.constant_velocity()
        }
    }

    /// The window adjustment ([`super::window`], `window.mode`): the frame joins the window,
    /// whose adjustment gives its pose (the fused one where it cannot, or where the adjusted
    /// step breaks the translation bound). A frame without a measurement (constant velocity),
    /// or one the `auto` mode does not adjust (a downward view, or before the ground is known),
    /// starts a new window at its pose. `None` when the window is off.
    fn window_step(
        &self,
        (flow, images): (&DenseFlow, Option<(&Pyramid, &Pyramid)>),
        corrs: &[Correspondence],
        fused: FusedPose,
        ground_m: Option<f64>,
    ) -> (FusedPose, Option<WindowStep>) {
        let Some(window) = self.window.as_ref() else {
            return (fused, None);
        };
        let world_from_cur = self.world_from_cam * fused.cur_from_prev.inverse();
        // (the window exists only where `window.runs`, `first_frame`)
        if fused.source == PoseSource::ConstantVelocity {
            return (fused, Some(WindowStep::restart(world_from_cur)));
        }
        let step = window.advance(
            &self.config.window,
            &self.camera,
            (flow, corrs, self.config.grid_cell_px),
            images,
            world_from_cur,
            // a flight's height above the ground changes: no pull towards a fixed height
            (
                fused.cur_from_prev.translation.vector.norm(),
                ground_m.filter(|_| !self.config.scale.aerial),
            ),
        );
        let adjusted = match self.config.window.scale {
            // the newest pose as the window has it
            WindowScale::Window => step.world_from_cam().map(|w| {
                let mut cur_from_prev = w.inverse() * self.world_from_cam;
                // the product's quaternion is off the unit sphere by the rounding of both; the
                // pose chain would square that error every frame
                cur_from_prev.rotation =
                    UnitQuaternion::new_normalize(cur_from_prev.rotation.into_inner());
                cur_from_prev
            }),
            // the window's last step after the reported previous pose
            WindowScale::Stage => step.cur_from_prev,
        };
        let adjusted = adjusted.filter(|p| {
            let length = p.translation.vector.norm();
            length.is_finite() && length <= self.max_translation_m()
        });
        log::debug!(
            "mono frame {}: window of {} points, {:?}",
            self.frame,
            step.points,
            step.report
        );
        let Some(p) = adjusted else {
            return (fused, Some(step));
        };
        let change = StepChange::between(&p, &fused.cur_from_prev);
        if self.config.window.accepts(&change) {
            return (
                FusedPose {
                    cur_from_prev: p,
                    ..fused
                },
                Some(step),
            );
        }
        log::warn!(
            "mono frame {}: the window's step differs from the fused one by {:.2}° of rotation (window.max_rotation_change_rad) or {:.1}° of direction (window.max_direction_change_rad); the fused step stands and the window restarts",
            self.frame,
            change.rotation_rad.to_degrees(),
            change.direction_rad.to_degrees(),
        );
        (fused, Some(WindowStep::restart(world_from_cur)))
    }

    /// Depth stage (§5): triangulate with the final pose, fuse with the prior by inverse
    /// variance, propagate into the current camera; without a baseline the prior is only
    /// propagated (a rotation moves it exactly).
    fn depth_update(
        &self,
        flow: &DenseFlow,
        fused: &FusedPose,
        has_baseline: bool,
        timings: &mut StageTimings,
    ) -> DepthUpdate {
        let cfg = &self.config;
        let t = Instant::now();
        let measured = fused.source != PoseSource::ConstantVelocity && has_baseline;
        let unfiltered = self.inverse_depth_filter();
        let cells = if measured && !unfiltered {
            self.triangulate_cells(flow, &fused.cur_from_prev, self.max_depth_m())
        } else {
            Vec::new()
        };
        let inverse = if measured && unfiltered {
            self.measure_inverse_depth(flow, &fused.cur_from_prev)
        } else {
            Vec::new()
        };
        timings.triangulation_ms += ms(t);
        let t = Instant::now();
        let mut map = self
            .prior
            .clone()
            .unwrap_or_else(|| DepthMap::empty(flow.width, flow.height, cfg.depth_stride_px));
        let min_inverse_depth = 1.0 / self.max_depth_m();
        for &(cell, m) in &inverse {
            map.fuse_inverse_measurement(
                cell,
                (m.inverse_depth, m.variance),
                3.0,
                min_inverse_depth,
            );
        }
        for c in &cells {
            if cfg.inverse_depth_fusion {
                map.fuse_inverse_depth(c.cell, c.point.depth, c.point.depth_variance, 3.0);
            } else {
                map.fuse(c.cell, c.point.depth, c.point.depth_variance, 3.0);
            }
        }
        let next = map.propagate(
            &self.camera,
            &fused.cur_from_prev,
            0.1,
            self.subpixel_depth(),
        );
        let known_cells = next.known();
        timings.depth_ms = ms(t);
        DepthUpdate { next, known_cells }
    }

    /// The only step that changes the odometry's state: the pose chain, the motion, the scale
    /// state, the window (when it ran), the depth map and the image of the accepted frame.
    fn commit(
        &mut self,
        fused: &FusedPose,
        (scale_state, window): (Option<ScaleState>, Option<MonoWindow>),
        depth: DepthMap,
        (pyramid, thumbnail, valid_fraction): (Option<Pyramid>, Thumbnail, f64),
    ) {
        if window.is_some() {
            self.window = window;
        }
        if let Some(s) = scale_state {
            self.ground_log_ratios = s.ground_log_ratios;
            self.aerial_initialised = s.aerial_initialised;
            self.aerial_anchored = s.aerial_anchored;
            self.estimated_height_m = s.estimated_height_m;
            self.tracked_ground = s.tracked_ground;
        }
        self.tracked_ground = self
            .tracked_ground
            .map(|t| t.after_step(&fused.cur_from_prev));
        self.prior = Some(depth);
        self.world_from_cam *= fused.cur_from_prev.inverse();
        self.last_motion = Some(fused.cur_from_prev);
        self.prev_pyramid = pyramid;
        self.accepted.accept(thumbnail, Some(valid_fraction));
        self.frame += 1;
    }

    /// The error of a frame that failed a trust test, with its warning (the state is unchanged).
    fn untrusted(&self, reason: UntrustedReason) -> MonoError {
        trust::refused(self.frame, reason)
    }

    /// With `inverse_depth_filter`, the depth-ratio scale of the unit-translation pose `unit`
    /// measured at the previous map's points ([`scale_at_map_points`]); `None` otherwise (the
    /// ratio of the filtered triangulations, cell by cell).
    fn scale_at_points(&self, flow: &DenseFlow, unit: &Pose) -> Option<PointScale> {
        if !self.inverse_depth_filter() {
            return None;
        }
        let prior = self.prior.as_ref()?;
        let guess = self
            .last_motion
            .map_or(1.0, |p| p.translation.vector.norm())
            .max(1e-6);
        Some(scale_at_map_points(
            &self.camera,
            flow,
            prior,
            unit,
            &fundamental_of(&self.camera, unit),
            self.config.eight_point.ransac.inlier_threshold,
            guess,
            self.config.scale.min_ratio_samples,
        ))
    }

    /// The inverse depth (metres⁻¹) of every depth-grid cell whose flow is consistent with
    /// `cur_from_prev` (the epipolar test only: no filter on the measured value, see
    /// [`triangulate_inverse_depth`]).
    fn measure_inverse_depth(
        &self,
        flow: &DenseFlow,
        cur_from_prev: &Pose,
    ) -> Vec<(usize, InverseDepthPoint)> {
        self.epipolar_cells(flow, cur_from_prev)
            .into_par_iter()
            .filter_map(|(cell, c)| {
                let m = triangulate_inverse_depth(&self.camera, cur_from_prev, &c)?;
                (m.inverse_depth.is_finite() && m.variance.is_finite()).then_some((cell, m))
            })
            .collect()
    }

    /// The flow's correspondence at every depth-grid cell within the RANSAC threshold of
    /// `cur_from_prev`'s epipolar geometry (squared Mahalanobis distance), in cell order.
    fn epipolar_cells(
        &self,
        flow: &DenseFlow,
        cur_from_prev: &Pose,
    ) -> Vec<(usize, Correspondence)> {
        let grid = DepthMap::empty(flow.width, flow.height, self.config.depth_stride_px);
        let f = fundamental_of(&self.camera, cur_from_prev);
        let threshold = self.config.eight_point.ransac.inlier_threshold;
        (0..grid.depth_m.len())
            .into_par_iter()
            .filter_map(|cell| {
                let px = grid.pixel_of(cell);
                let c = correspondence_at(flow, px.x as usize, px.y as usize)?;
                if mahalanobis_distance_sq(&f, &c) > threshold {
                    None
                } else {
                    Some((cell, c))
                }
            })
            .collect()
    }

    /// Triangulates the flow at every depth-grid cell consistent with `cur_from_prev`
    /// (squared Mahalanobis epipolar distance within the RANSAC threshold, depth positive, relative
    /// depth sigma below the limit). Depths are in the units of the pose's translation.
    /// `max_depth` bounds the depth in the pose's units (infinite for a unit-translation pose).
    fn triangulate_cells(
        &self,
        flow: &DenseFlow,
        cur_from_prev: &Pose,
        max_depth: f64,
    ) -> Vec<CellPoint> {
        let cfg = &self.config;
        let camera = self.camera;
        let max_rel = cfg.max_relative_depth_sigma;
        self.epipolar_cells(flow, cur_from_prev)
            .into_par_iter()
            .filter_map(|(cell, c)| {
                let point = triangulate(&camera, cur_from_prev, &c)?;
                let ok = point.depth > 0.0
                    && point.depth.is_finite()
                    && point.depth_variance.sqrt() <= max_rel * point.depth;
                (ok && point.depth <= max_depth).then_some(CellPoint { cell, point })
            })
            .collect()
    }

    /// The scale candidates (§5): the ground plane `s = −(b·h)/d` (with the fitted plane) and
    /// the median ratio of the previous depth map to the unit-scale depths.
    fn scale_candidates(
        &self,
        cells: &[CellPoint],
        at_points: Option<PointScale>,
        rng: &mut visnav_geometry::ChaCha8Rng,
    ) -> ScaleCandidates {
        let cfg = self.config.scale;
        let grid = DepthMap::empty(
            self.camera.width as usize,
            self.camera.height as usize,
            self.config.depth_stride_px,
        );
        let points: Vec<Point3<f64>> = cells.iter().map(|c| c.point.p_in_cam1).collect();
        let pixels: Vec<Point2<f64>> = cells.iter().map(|c| grid.pixel_of(c.cell)).collect();
        let dominant = cfg.ground_search.dominant(cfg.aerial);
        let ground = if dominant {
            fit_dominant_plane(&points, &cfg.ground, rng)
        } else {
            fit_ground_plane(&self.camera, &points, &pixels, &cfg.ground, rng)
        };
        let (depth_m, overlap) = match (at_points, &self.prior) {
            (Some(at), Some(prior)) => (at.scale_m, at.points as f64 / prior.known().max(1) as f64),
            (None, Some(prior)) => {
                let mut ratios: Vec<f64> = if self.subpixel_depth() {
                    let unit = InterpolatedDepth::new(
                        &grid,
                        cells.iter().map(|c| (c.cell, c.point.depth)),
                    );
                    prior.ratios_to(&unit, RATIO_MAX_SPREAD)
                } else {
                    cells
                        .iter()
                        .filter_map(|c| prior.get(c.cell).map(|(d, _)| d / c.point.depth))
                        .filter(|r| r.is_finite() && *r > 0.0)
                        .collect()
                };
                let overlap = ratios.len() as f64 / cells.len().max(1) as f64;
                let depth_m = (ratios.len() >= cfg.min_ratio_samples)
                    .then(|| median(&mut ratios))
                    .flatten();
                (depth_m, overlap)
            }
            (_, None) => (None, 0.0),
        };
        let ground_m = ground
            .as_ref()
            .map(|g| ground_scale(g, cfg.camera_height_m, dominant))
            .filter(|s| s.is_finite() && *s > 0.0);
        let known_m = cfg
            .known_distance
            .filter(|_| self.frame == 1)
            .and_then(|k| known_distance_scale(&k, cells, &grid, 2.0 * grid.stride as f64));
        ScaleCandidates {
            ground,
            ground_m,
            depth_m,
            overlap,
            known_m,
        }
    }

    /// The eight-point scale (§5): ground plane and/or depth ratio per the vehicle rules, with
    /// the scale state the frame leaves for the next ones (committed only when it is accepted).
    fn scale(
        &self,
        cells: &[CellPoint],
        pnp_scale: Option<f64>,
        at_points: Option<PointScale>,
        rng: &mut visnav_geometry::ChaCha8Rng,
    ) -> (ScaleEstimate, ScaleState) {
        let cfg = self.config.scale;
        let candidates = self.scale_candidates(cells, at_points, rng);
        let mut state = ScaleState {
            ground_log_ratios: self.ground_log_ratios.clone(),
            aerial_initialised: self.aerial_initialised,
            aerial_anchored: self.aerial_anchored,
            estimated_height_m: self.estimated_height_m,
            tracked_ground: self.tracked_ground,
        };
        let s_ground_raw = candidates.ground_m;
        let s_depth_raw = candidates.depth_m;
        let previous = self
            .last_motion
            .map(|p| p.translation.vector.norm())
            .filter(|s| *s > 0.0);
        // motion prior: a candidate changing the speed by more than `max_scale_change` (ratio)
        // in one frame is implausible and dropped; the PnP translation then stands in
        let plausible = |s: &f64| {
            previous
                .is_none_or(|p| *s <= p * cfg.max_scale_change && *s * cfg.max_scale_change >= p)
        };
        let s_ground = s_ground_raw.filter(plausible);
        let s_depth = s_depth_raw.filter(plausible);
        let fallback = match pnp_scale {
            Some(p) if p > 0.0 => (Some(p), ScaleSource::Pnp),
            _ => (previous, ScaleSource::Previous),
        };
        let (scale, source) = if cfg.aerial {
            let s_reinit = candidates
                .ground
                .as_ref()
                .map(|g| {
                    ground_scale(
                        g,
                        state.estimated_height_m,
                        cfg.ground_search.dominant(true),
                    )
                })
                .filter(|s| s.is_finite() && *s > 0.0);
            if !state.aerial_initialised {
                match (candidates.known_m, s_ground) {
                    (Some(s), _) => {
                        state.aerial_initialised = true;
                        // the ground's re-anchoring would undo the known distance
                        state.aerial_anchored = true;
                        (Some(s), ScaleSource::KnownDistance)
                    }
                    (None, Some(s)) => {
                        state.aerial_initialised = true;
                        (Some(s), ScaleSource::Ground)
                    }
                    (None, None) => fallback,
                }
            } else if let (Some(s), true) =
                (s_depth, candidates.overlap >= cfg.min_overlap_fraction)
            {
                self.with_tracked_ground(s, cells, &mut state, rng)
            } else if let Some(s) = s_reinit.filter(plausible) {
                (Some(s), ScaleSource::GroundReinit)
            } else {
                fallback
            }
        } else {
            match (s_ground, s_depth) {
                (Some(g), Some(d)) if (g - d).abs() <= cfg.max_disagreement * g.max(d) => {
                    (Some(0.5 * (g + d)), ScaleSource::GroundAndDepth)
                }
                // disagreement (e.g. rotation on the spot, where the ground fit is ill-posed):
                // the candidate closer to the PnP translation, else the depth ratio
                (Some(g), Some(d)) => match pnp_scale {
                    Some(p) if (g - p).abs() < (d - p).abs() => (Some(g), ScaleSource::Ground),
                    _ => (Some(d), ScaleSource::DepthRatio),
                },
                (Some(g), None) => (Some(g), ScaleSource::Ground),
                (None, Some(d)) => (Some(d), ScaleSource::DepthRatio),
                (None, None) => fallback,
            }
        };
        let (scale, source) = self.reanchor(scale, source, s_ground_raw, &mut state);
        // the camera height seen by the reconstruction at the chosen scale (aerial re-init)
        if let (Some(s), Some(g)) = (scale, &candidates.ground) {
            let h = s * g.camera_height;
            if h.is_finite() && h > 0.0 {
                state.estimated_height_m = h;
                // the tracked ground starts where the aerial scale does
                if cfg.aerial && (!self.aerial_initialised || self.tracked_ground.is_none()) {
                    state.tracked_ground = Some(TrackedGround {
                        normal_in_cam: g.plane.normal,
                        height_m: h,
                    });
                }
            }
        }
        let source = if scale.is_none() {
            ScaleSource::None
        } else {
            source
        };
        let estimate = ScaleEstimate {
            scale_m: scale,
            source,
            ground_m: s_ground_raw,
            depth_ratio_m: s_depth_raw,
        };
        (estimate, state)
    }

    /// Aerial, after the initialisation: the depth-ratio scale `s_depth`, combined with the
    /// tracked-height ground scale when that is on (`scale.aerial_ground_weight`) and the
    /// ground is found near where it is expected; the found ground's normal replaces the
    /// tracked one in `state`.
    fn with_tracked_ground(
        &self,
        s_depth: f64,
        cells: &[CellPoint],
        state: &mut ScaleState,
        rng: &mut visnav_geometry::ChaCha8Rng,
    ) -> (Option<f64>, ScaleSource) {
        let cfg = self.config.scale;
        let w = cfg.aerial_ground_weight;
        let Some(tracked) = self.tracked_ground.filter(|t| w > 0.0 && t.height_m > 0.0) else {
            return (Some(s_depth), ScaleSource::DepthRatio);
        };
        let predicted = tracked.predicted_plane(s_depth);
        // the near ground: a far point's small parallax makes its depth less certain
        let max_range = cfg.aerial_ground_max_range_heights * -predicted.offset;
        let points: Vec<Point3<f64>> = cells
            .iter()
            .map(|c| c.point.p_in_cam1)
            .filter(|p| p.coords.norm() <= max_range)
            .collect();
        let ground = fit_plane_near(
            &points,
            &predicted,
            cfg.aerial_ground_max_tilt_rad,
            cfg.aerial_ground_gate,
            &cfg.ground,
            rng,
        );
        let candidate = ground
            .map(|g| (g.plane.normal, tracked.height_m / g.camera_height))
            .filter(|(_, s)| s.is_finite() && *s > 0.0)
            .map(|(normal_in_cam, s)| {
                state.tracked_ground = Some(TrackedGround {
                    normal_in_cam,
                    ..tracked
                });
                s
            });
        log::debug!(
            "mono frame {}: tracked ground height {:.3} m, scale {candidate:?} against the depth ratio's {s_depth:.4}",
            self.frame,
            tracked.height_m,
        );
        match candidate {
            Some(s_g) => (
                Some(((1.0 - w) * s_depth.ln() + w * s_g.ln()).exp()),
                ScaleSource::GroundAndDepth,
            ),
            None => (Some(s_depth), ScaleSource::DepthRatio),
        }
    }

    /// Ground vehicles: a persistent disagreement between the ground and the chosen scale (the
    /// depth-ratio chain, which the motion prior protects) re-anchors on the ground. Aerial: the
    /// same median ratio once, when the first `reanchor_frames` ground candidates after the
    /// initialisation are in (a single frame's dominant plane can be a roof or a facade).
    fn reanchor(
        &self,
        scale: Option<f64>,
        source: ScaleSource,
        s_ground_raw: Option<f64>,
        state: &mut ScaleState,
    ) -> (Option<f64>, ScaleSource) {
        let cfg = self.config.scale;
        // aerial: once, over the first frames after initialisation (the height is still about
        // the given one), whatever the ratio
        let aerial_window = cfg.aerial && state.aerial_initialised && !state.aerial_anchored;
        match (scale, s_ground_raw) {
            (Some(s), Some(g))
                if g <= self.max_translation_m() && (!cfg.aerial || aerial_window) =>
            {
                let ratios = &mut state.ground_log_ratios;
                ratios.push_back((g / s).ln());
                while ratios.len() > cfg.reanchor_frames {
                    ratios.pop_front();
                }
                let mut window: Vec<f64> = ratios.iter().copied().collect();
                match median(&mut window) {
                    Some(m)
                        if window.len() >= cfg.reanchor_frames
                            && (aerial_window || m.abs() > cfg.reanchor_ratio.ln()) =>
                    {
                        log::info!(
                            "mono frame {}: scale re-anchored on the ground (x{:.3})",
                            self.frame,
                            m.exp()
                        );
                        ratios.clear();
                        state.aerial_anchored = cfg.aerial;
                        (Some(s * m.exp()), ScaleSource::GroundReanchor)
                    }
                    _ => (Some(s), source),
                }
            }
            other => (other.0, source),
        }
    }

    /// PnP of the current camera against the prior depth map (in the previous camera) through the
    /// flow at the known cells (see [`pnp_against_depth`]).
    fn pnp(&self, flow: &DenseFlow, rng: &mut visnav_geometry::ChaCha8Rng) -> PnpEstimate {
        let estimate = |pose, correspondences, inliers| PnpEstimate {
            pose,
            correspondences,
            inliers,
        };
        let Some(prior) = &self.prior else {
            return estimate(None, 0, 0);
        };
        let (data, result) = pnp_against_depth(&self.camera, &self.config.pnp, prior, flow, rng);
        match result {
            Some(r) if r.inlier_count >= 10 => {
                estimate(Some(r.cam_from_world), data.len(), r.inlier_count)
            }
            Some(r) => estimate(None, data.len(), r.inlier_count),
            None => estimate(None, data.len(), 0),
        }
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
/// The scale that makes the two known points of the first image `distance_m` apart: each point
/// is the mean of the triangulated cells within `radius_px` of it (symmetric around it, so a
/// locally planar surface keeps its position and the cells' noise averages), `None` if either
/// has none.
fn known_distance_scale(
    known: &KnownDistance,
    cells: &[CellPoint],
    grid: &DepthMap,
    radius_px: f64,
) -> Option<f64> {
    let near = |px: [f64; 2]| {
        let (sum, n) = cells
            .iter()
            .filter(|c| {
                let p = grid.pixel_of(c.cell);
                (p.x - px[0]).hypot(p.y - px[1]) <= radius_px
            })
            .fold((nalgebra::Vector3::zeros(), 0_usize), |(s, n), c| {
                (s + c.point.p_in_cam1.coords, n + 1)
            });
        (n > 0).then(|| sum / n as f64)
    };
    let unit = (near(known.a_px)? - near(known.b_px)?).norm();
    let s = known.distance_m / unit;
    (s.is_finite() && s > 0.0).then_some(s)
}

/// The scale that puts the camera `height_m` above `ground`: along the camera y axis
/// (`s = −(b·h)/d`, §5) or, for the dominant plane of `GroundSearch::Dominant`, along the
/// plane's normal (`s = h/|d|`).
fn ground_scale(ground: &GroundPlane, height_m: f64, dominant: bool) -> f64 {
    if dominant {
        ground.scale_by_distance(height_m)
    } else {
        ground.scale(height_m)
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;

    fn flow_of(
        w: usize,
        h: usize,
        f: impl Fn(usize, usize) -> ([f32; 2], [f32; 3], bool),
    ) -> DenseFlow {
        let mut flow = Vec::new();
        let mut information = Vec::new();
        let mut valid = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let (uv, info, ok) = f(x, y);
                flow.push(uv);
                information.push(info);
                valid.push(ok);
            }
        }
        DenseFlow {
            width: w,
            height: h,
            flow,
            information,
            valid,
        }
    }

    #[test]
    fn tracked_ground_follows_the_climb() {
        // a camera pitched 20° down, 30 m above flat ground (world y down); it climbs 2 m
        // while flying 5 m forward and turning 10° to the right
        let pitch = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), -20f64.to_radians());
        let yaw = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 10f64.to_radians());
        let world_from_prev = Pose::from_parts(Point3::new(1.0, -30.0, 7.0).into(), pitch);
        let world_from_cur = Pose::from_parts(Point3::new(1.0, -32.0, 12.0).into(), yaw * pitch);
        let cur_from_prev = world_from_cur.inverse() * world_from_prev;
        let down_in = |world_from_cam: &Pose| world_from_cam.rotation.inverse() * Vector3::y();
        let start = TrackedGround {
            normal_in_cam: down_in(&world_from_prev),
            height_m: 30.0,
        };
        let after = start.after_step(&cur_from_prev);
        assert!((after.height_m - 32.0).abs() < 1e-9, "{}", after.height_m);
        assert!((after.normal_in_cam - down_in(&world_from_cur)).norm() < 1e-12);
        // the ground seen from the current camera at 4 m a unit: 8 units away; a point on the
        // ground straight below the camera lies on it
        let plane = after.predicted_plane(4.0);
        assert!((plane.offset + 8.0).abs() < 1e-12, "{}", plane.offset);
        let below = world_from_cur.inverse() * Point3::new(1.0, 0.0, 12.0);
        assert!(plane.distance(&Point3::from(below.coords / 4.0)).abs() < 1e-9);
    }

    #[test]
    fn grid_keeps_the_most_certain_valid_pixel_per_cell() {
        // certainty grows with x inside each 4-px cell; pixel x%4 == 3 is invalid
        let flow = flow_of(16, 8, |x, _| {
            let c = 1.0 + (x % 4) as f32;
            ([1.0, 0.5], [c, 0.0, c], x % 4 != 3)
        });
        let corrs = correspondences_from_flow(&flow, 4);
        assert_eq!(corrs.len(), 8);
        assert!(corrs.iter().all(|c| c.p1_px.x as usize % 4 == 2));
        assert!(
            corrs
                .iter()
                .all(|c| (c.p2_px - c.p1_px - nalgebra::Vector2::new(1.0, 0.5)).norm() < 1e-9)
        );
        // flow leaving the image is dropped
        let out = flow_of(8, 8, |_, _| ([100.0, 0.0], [1.0, 0.0, 1.0], true));
        assert!(correspondences_from_flow(&out, 4).is_empty());
    }

    #[test]
    fn translational_parallax_vanishes_under_pure_rotation() {
        let cam = PinholeCamera::new(500.0, 500.0, 320.0, 240.0, 640, 480).unwrap();
        let rotation = UnitQuaternion::from_euler_angles(0.01, 0.05, -0.02);
        let corr = |p_in_prev: Point3<f64>, cur_from_prev: &Pose| Correspondence {
            p1_px: cam.project(&p_in_prev).unwrap(),
            p2_px: cam.project(&(cur_from_prev * p_in_prev)).unwrap(),
            information: nalgebra::Matrix2::identity(),
        };
        let points: Vec<Point3<f64>> = (0..50)
            .map(|i| {
                let i = f64::from(i);
                Point3::new((i * 0.37).sin() * 3.0, (i * 0.71).cos(), 5.0 + i * 0.3)
            })
            .collect();
        let spin = Pose::from_parts(nalgebra::Translation3::identity(), rotation);
        let corrs: Vec<Correspondence> = points.iter().map(|p| corr(*p, &spin)).collect();
        // large flow (the rotation moves every pixel by ~25 px), no translational parallax
        assert!(corrs.iter().all(|c| (c.p2_px - c.p1_px).norm() > 10.0));
        let tp = translational_parallax_px(&cam, &corrs, &rotation).unwrap();
        assert!(tp < 1e-9, "{tp}");
        // the same rotation with 0.5 m forward motion: parallax of several pixels
        let drive = Pose::from_parts(nalgebra::Translation3::new(0.0, 0.0, -0.5), rotation);
        let corrs: Vec<Correspondence> = points.iter().map(|p| corr(*p, &drive)).collect();
        let tp = translational_parallax_px(&cam, &corrs, &rotation).unwrap();
        assert!(tp > 2.0, "{tp}");
        assert!(translational_parallax_px(&cam, &[], &rotation).is_none());
    }

    #[test]
    fn flow_percentile_ignores_invalid_pixels() {
        let flow = flow_of(20, 20, |x, y| {
            let m = (x + 20 * y) as f32 * 0.01;
            ([m, 0.0], [1.0, 0.0, 1.0], y < 10)
        });
        let p75 = flow_percentile_px(&flow, 0.75);
        // valid rows 0..10 (even), magnitudes 0..~1.98, 75th percentile ≈ 1.4
        assert!(p75 > 1.2 && p75 < 1.6, "{p75}");
        let none = flow_of(4, 4, |_, _| ([9.0, 0.0], [1.0, 0.0, 1.0], false));
        assert!(flow_percentile_px(&none, 0.75).abs() < 1e-12);
    }

    #[test]
    fn low_parallax_frame_uses_pnp_or_fails_softly() {
        let cam = PinholeCamera::new(50.0, 50.0, 15.5, 11.5, 32, 24).unwrap();
        let img = GrayImage::new(32, 24, 100.0);
        // the flat placeholder image is refused by the trust tests (no texture) ...
        let mut trusting = MonoOdometry::new(cam, MonoConfig::default()).unwrap();
        assert!(matches!(
            trusting.process(&img, None),
            Err(MonoError::UntrustedFrame {
                reason: UntrustedReason::NoTexture { .. }
            })
        ));
        // ... which are off here: this test is about the geometric fallback of the flow
        let mut cfg = MonoConfig::default();
        cfg.trust.enabled = false;
        let mut vo = MonoOdometry::new(cam, cfg).unwrap();
        let first = vo.process(&img, None).unwrap();
        assert_eq!(first.source, PoseSource::Initial);
        // zero flow: no parallax, no depth prior → constant velocity (identity), status Failed
        let still = flow_of(32, 24, |_, _| ([0.0, 0.0], [1.0, 0.0, 1.0], true));
        let r = vo.process(&img, Some(&still)).unwrap();
        assert_eq!(r.source, PoseSource::ConstantVelocity);
        assert_eq!(r.status, FrameStatus::Failed);
        assert!(r.world_from_cam.translation.vector.norm() < 1e-12);
        // a wrong-size flow is an error, not a panic
        let small = flow_of(8, 8, |_, _| ([0.0, 0.0], [1.0, 0.0, 1.0], true));
        assert!(matches!(
            vo.process(&img, Some(&small)),
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
