//! Configuration of the monocular pipeline, with the paper's defaults (§5).

use serde::{Deserialize, Serialize};
use visnav_geometry::fundamental::EightPointConfig;
use visnav_geometry::plane::GroundPlaneConfig;
use visnav_geometry::pnp::PnpConfig;

use super::covariance::MonoCovarianceConfig;
use super::error::MonoError;
use super::flow::MonoFlowConfig;
use super::trust::TrustConfig;
use super::window::MonoWindowConfig;

/// The parallax test of §5.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ParallaxConfig {
    /// Minimum median Shi–Tomasi/KLT displacement, pixels. Default 2.5 (paper).
    pub min_klt_median_px: f64,
    /// The 75th percentile of the flow magnitude must exceed this, pixels. Default 5 (paper).
    pub min_flow_p75_px: f64,
    /// Run the KLT part of the test (needs the previous image). Default true.
    pub use_klt: bool,
    /// Minimum median *translational* parallax, pixels: the displacement left over after the
    /// frame's rotation is removed through the infinite homography `K R K⁻¹`. Below it (standing
    /// still, rotation on the spot) the eight-point translation direction is undefined and a
    /// triangulation has no baseline, so the pose comes from PnP and the depth map is only
    /// propagated, not re-triangulated. Default 1.0 (at KITTI's 1241-px width). An addition to
    /// the paper: its flow/KLT test above does not separate rotation from translation.
    pub min_translational_parallax_px: f64,
    /// The image width, pixels, at which `min_klt_median_px` and `min_flow_p75_px` hold; an
    /// image of another width uses them times its width over this one (the same share of the
    /// image). Default 1241 (KITTI's, where the paper set them); 0: the thresholds in the
    /// image's own pixels. `min_translational_parallax_px` is not scaled. Before this existed
    /// the demo, the examples and the tests scaled the two by hand, and a 620-px aerial flight
    /// run from the command line without it had a quarter of its frames refused the
    /// eight-point as low parallax (docs/notes/2026-12-02-aerial-history.md, round 3).
    pub reference_width_px: f64,
}

impl ParallaxConfig {
    /// The configuration with `min_klt_median_px` and `min_flow_p75_px` scaled from
    /// `reference_width_px` to an image `width_px` wide (and `reference_width_px` 0).
    #[must_use]
    pub fn for_width(&self, width_px: u32) -> Self {
        if self.reference_width_px <= 0.0 {
            return *self;
        }
        let px_scale = f64::from(width_px) / self.reference_width_px;
        Self {
            min_klt_median_px: self.min_klt_median_px * px_scale,
            min_flow_p75_px: self.min_flow_p75_px * px_scale,
            reference_width_px: 0.0,
            ..*self
        }
    }
}

impl Default for ParallaxConfig {
    fn default() -> Self {
        Self {
            min_klt_median_px: 2.5,
            min_flow_p75_px: 5.0,
            use_klt: true,
            min_translational_parallax_px: 1.0,
            reference_width_px: 1241.0,
        }
    }
}

/// Scale estimation (§5).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScaleConfig {
    /// Camera height above the ground, metres. Default 1.7 (KITTI); the synthetic renderer uses 1.65.
    pub camera_height_m: f64,
    /// Aerial rules: ground plane for the first frame only, depth ratios after. Default false.
    /// The ground is then the dominant plane of the triangulated points in any orientation
    /// (`visnav_geometry::plane::fit_dominant_plane`; a downward- or forward-looking camera),
    /// the camera height the camera's distance from it, and the robustness bounds scale with
    /// that height (`aerial_max_step_heights`, `aerial_max_depth_heights`).
    pub aerial: bool,
    /// Where the ground plane is looked for. Default [`GroundSearch::Auto`].
    pub ground_search: GroundSearch,
    /// Aerial: a known distance between two points of the first image (the paper's tape marks,
    /// 1 m apart on trees) sets the first scale instead of the ground plane and the camera
    /// height. Default none.
    pub known_distance: Option<KnownDistance>,
    /// Aerial: a frame's translation may reach this many camera heights (at least
    /// `max_translation_m`). Default 0.5: a downward KITTI-like view (37° vertical field) spans
    /// 0.67 heights along the flight, so a longer step leaves almost nothing to match.
    pub aerial_max_step_heights: f64,
    /// Aerial: depth cells up to this many camera heights are kept (at least `max_depth_m`).
    /// Default 50: a forward camera pitched 20° down sees the ground up to about 38 heights away
    /// at the top of a KITTI-like image.
    pub aerial_max_depth_heights: f64,
    /// Aerial re-initialisation when fewer than this fraction of the triangulated cells overlap
    /// the previous depth map. Default 0.05 (paper: 5 %).
    pub min_overlap_fraction: f64,
    /// Fewest overlapping cells for a depth-ratio scale. Default 30.
    pub min_ratio_samples: usize,
    /// Ground vehicles average the ground and depth-ratio scales only when they differ by at most
    /// this fraction of the larger; otherwise the one closer to the PnP translation (else the
    /// depth ratio) is used. Default 0.5 (an addition to the paper: guards rotation on the spot).
    pub max_disagreement: f64,
    /// Motion prior: a scale candidate more than this factor above or below the previous
    /// translation length is rejected (then the PnP translation length is used). Default 1.5.
    /// An addition to the paper against gross ground-plane failures.
    pub max_scale_change: f64,
    /// Ground vehicles: when, over the last `reanchor_frames` frames with a ground-plane
    /// candidate, the median ratio between that candidate and the chosen translation length is
    /// above this factor (or below its inverse), the depth-ratio chain has drifted away from the
    /// ground: the frame's scale is multiplied by that median ratio
    /// ([`super::ScaleSource::GroundReanchor`]). Default 1.3. An addition to the paper: the
    /// motion prior (`max_scale_change`) compares each candidate with the previous translation
    /// only, so once the chained depth-ratio scale has drifted more than that factor away from
    /// the ground it rejects every ground candidate and the drift can never be corrected
    /// (measured on the synthetic loop drive: steps of 0.35 m for 1.6 m while the ground said
    /// 1.0–1.8 m). Aerial mode re-anchors once, whatever the ratio, when the first
    /// `reanchor_frames` ground candidates after the initialisation are in: one frame's dominant
    /// plane can be a roof or a facade (a rendered forward flight 30 m up at 620x188: its first
    /// step came out 2.46 times too long, the next ground candidates' median was right).
    pub reanchor_ratio: f64,
    /// Window of the re-anchoring test, frames with a ground candidate. Default 8.
    pub reanchor_frames: usize,
    /// Aerial: weight of the tracked-height ground scale against the depth ratio, in `[0, 1]`.
    /// Default 1 (0: the depth-ratio chain alone after the initialisation, as before). The
    /// paper's aerial mode (§6.2): "the camera height is not assumed constant but is updated
    /// for each motion". The camera's height above the ground starts at the initialisation's
    /// and moves with every accepted step's displacement along the ground's normal, which is
    /// carried in the camera and replaced by each frame's fitted ground. Each frame the ground
    /// is fitted near where the depth-ratio scale `s_d` and the height predict it (normal within
    /// `aerial_ground_max_tilt_rad`, distance within `aerial_ground_gate`, points within
    /// `aerial_ground_max_range_heights`; roofs and crowns are nearer and fall outside), and
    /// `s_g = h / d` (height over the plane's distance in unit-translation units) gives the
    /// scale `s_d^(1−w) s_g^w`. On the rendered 563-frame forward flight (620x188) the chain
    /// alone ends at 0.29 of the true step, Sim(3) ATE 4.75 % of the path; with the tracked
    /// ground 0.72–1.02 of it along the whole flight, 1.05 %
    /// (docs/notes/2026-12-02-aerial-history.md, round 3). Assumes
    /// flat ground on the whole, as the plane fit does.
    pub aerial_ground_weight: f64,
    /// Aerial: the tracked ground is looked for within this factor of the distance the depth
    /// ratio and the height predict (nearer or farther). Default 1.25: roofs of buildings
    /// taller than a fifth of the height are outside.
    pub aerial_ground_gate: f64,
    /// Aerial: largest angle between a frame's fitted ground and the tracked ground normal,
    /// radians. Default 0.15 (8.6°).
    pub aerial_ground_max_tilt_rad: f64,
    /// Aerial: the tracked ground is fitted to the points within this many predicted heights
    /// of the camera. Default 4.
    pub aerial_ground_max_range_heights: f64,
    /// Ground-plane fit.
    pub ground: GroundPlaneConfig,
}

impl Default for ScaleConfig {
    fn default() -> Self {
        Self {
            camera_height_m: 1.7,
            aerial: false,
            ground_search: GroundSearch::Auto,
            known_distance: None,
            aerial_max_step_heights: 0.5,
            aerial_max_depth_heights: 50.0,
            min_overlap_fraction: 0.05,
            min_ratio_samples: 30,
            max_disagreement: 0.5,
            max_scale_change: 1.5,
            reanchor_ratio: 1.3,
            reanchor_frames: 8,
            aerial_ground_weight: 1.0,
            aerial_ground_gate: 1.25,
            aerial_ground_max_tilt_rad: 0.15,
            aerial_ground_max_range_heights: 4.0,
            ground: GroundPlaneConfig::default(),
        }
    }
}

/// Two points of the first image a known distance apart ([`ScaleConfig::known_distance`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KnownDistance {
    /// First point `[x, y]`, pixels of the first image.
    pub a_px: [f64; 2],
    /// Second point `[x, y]`, pixels.
    pub b_px: [f64; 2],
    /// Distance between the two scene points, metres.
    pub distance_m: f64,
}

/// Where the scale's ground plane is looked for ([`ScaleConfig::ground_search`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GroundSearch {
    /// `below` for ground vehicles, `dominant` in aerial mode.
    Auto,
    /// The paper's rule for a forward-looking vehicle camera: points below the camera in the
    /// central half of the image, a plane whose normal is within `ground.max_tilt_rad` of the
    /// camera's y axis; the height measured along that axis
    /// (`visnav_geometry::plane::fit_ground_plane`).
    Below,
    /// The dominant plane of all triangulated points in any orientation, the height its distance
    /// from the camera (`visnav_geometry::plane::fit_dominant_plane`): a downward-looking or
    /// pitched aerial camera. A forward-looking car camera can see more facade than road, so it
    /// is not the ground vehicles' default.
    Dominant,
}

impl GroundSearch {
    /// Whether the dominant plane is used with these aerial rules.
    #[must_use]
    pub fn dominant(self, aerial: bool) -> bool {
        match self {
            Self::Auto => aerial,
            Self::Below => false,
            Self::Dominant => true,
        }
    }
}

/// Where the depth map keeps its points ([`MonoConfig::depth_points`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DepthPoints {
    /// `cell` for ground vehicles, `subpixel` in aerial mode.
    #[default]
    Auto,
    /// The paper's map: a propagated point moves to the pixel of the cell it lands in, the
    /// nearest point wins a cell, and the depth ratio compares depths at the cells' pixels.
    /// Each of the three moves the map a little nearer on a forward-looking view of the ground
    /// (≈ 0.3 % a frame): ground vehicles re-anchor the scale on the road every few frames, so
    /// they keep it (KITTI 00, 300 frames: 1.2817 % / 0.9478 against 1.3465 / 0.9721 with
    /// `subpixel`, docs/notes/2026-12-02-aerial-history.md).
    Cell,
    /// Every point keeps the pixel where it landed ([`super::DepthMap::propagate`]); on one
    /// surface the point nearer to the cell's pixel wins a cell (the nearer depth only across
    /// an occlusion edge); the depth ratio reads the new triangulation at each point's pixel.
    /// Aerial mode, where the scale comes from the depth-ratio chain alone after the first
    /// frames: on a 563-frame rendered forward flight with the exact flow the scale held to
    /// 0.6 % (0.27 of the truth at the end with `cell`).
    Subpixel,
}

impl DepthPoints {
    /// Whether the points keep their sub-pixel positions.
    #[must_use]
    pub fn subpixel(self, aerial: bool) -> bool {
        match self {
            Self::Auto => aerial,
            Self::Cell => false,
            Self::Subpixel => true,
        }
    }
}

/// When the motion may come from a homography ([`HomographyConfig::selection`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HomographySelection {
    /// `on` in aerial mode, `off` for ground vehicles.
    #[default]
    Auto,
    /// Always the eight-point's fundamental matrix (the paper).
    Off,
    /// Fit both models every frame; the homography's motion when it scores as well.
    On,
}

/// Model selection between the fundamental matrix and a homography (a near-planar scene: a
/// downward view of flat ground, the eight-point algorithm's degenerate case) by Torr's GRIC;
/// see `visnav_geometry::homography`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HomographyConfig {
    /// When to fit the homography. Default `auto` (aerial mode only).
    pub selection: HomographySelection,
    /// The motion comes from the homography when its GRIC (Torr's criterion,
    /// `visnav_geometry::homography::gric`) is lower than the fundamental matrix's by more than
    /// this, per correspondence. Default 0 (the lower GRIC wins).
    pub min_gric_gain: f64,
    /// The chosen factorisation needs more points in front of both cameras than `1 / margin`
    /// times any factorisation with another translation direction. Default 0.75.
    pub cheirality_margin: f64,
    /// Aerial mode: the ground's normal in the camera of a level flight, the camera's mount
    /// (x right, y down, z along the optical axis; `[0, 0, 1]`: looking straight down; any
    /// length). When set, every frame's motion is the ground plane's with this normal held
    /// (`visnav_geometry::homography::relative_pose_with_plane_normal`), whichever model wins
    /// the selection, and it decides the baseline test's rotation and a fusion whose
    /// translation directions disagree. Over a weakly textured floor PnP against the depth
    /// map and the homography's factorisation both take a slow flight's sideways step for a
    /// rotation (the rendered indoor flights' legs turned 80–97° off); with the normal held
    /// they keep it within a few degrees. A small drone's roll and pitch in slow flight (a few
    /// degrees) tilt the true normal by as much. The normal tracked from the reconstruction
    /// drifted by 10–25° within 40 frames of the rendered flight and is not used. Default
    /// none (forward-looking flights, whose view is not a plane).
    pub ground_normal: Option<[f64; 3]>,
}

impl Default for HomographyConfig {
    fn default() -> Self {
        Self {
            selection: HomographySelection::Auto,
            min_gric_gain: 0.0,
            cheirality_margin: 0.75,
            ground_normal: None,
        }
    }
}

impl HomographyConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`MonoError::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> Result<(), MonoError> {
        first_broken(&[
            (
                self.min_gric_gain.is_finite(),
                "homography.min_gric_gain",
                self.min_gric_gain,
                "finite",
            ),
            (
                self.cheirality_margin > 0.0 && self.cheirality_margin <= 1.0,
                "homography.cheirality_margin",
                self.cheirality_margin,
                "in (0, 1]",
            ),
            (
                self.ground_normal
                    .is_none_or(|n| n.iter().all(|v| v.is_finite()) && n.iter().any(|v| *v != 0.0)),
                "homography.ground_normal",
                self.ground_normal
                    .map_or(0.0, |n| n[0].hypot(n[1]).hypot(n[2])),
                "finite and not zero",
            ),
        ])
    }

    /// The unit `ground_normal`, when set.
    #[must_use]
    pub fn level_ground_normal(&self) -> Option<nalgebra::Unit<nalgebra::Vector3<f64>>> {
        let n = self.ground_normal?;
        nalgebra::Unit::try_new(nalgebra::Vector3::from(n), 1e-12)
    }

    /// Whether the homography is fitted.
    #[must_use]
    pub fn enabled(&self, aerial: bool) -> bool {
        match self.selection {
            HomographySelection::Auto => aerial,
            HomographySelection::Off => false,
            HomographySelection::On => true,
        }
    }
}

/// Configuration of [`super::MonoOdometry`] and of the flow it consumes ([`super::MonoFlow`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MonoConfig {
    /// Side of the grid cells used to subsample the flow for the eight-point and PnP, pixels.
    /// Default 10 (≈ 4.5k correspondences at 1241x376).
    pub grid_cell_px: usize,
    /// Stride of the depth-map grid (one triangulated depth every `depth_stride_px` pixels).
    /// Default 4.
    pub depth_stride_px: usize,
    /// Eight-point estimator and its RANSAC (threshold χ²₁ 95 % = 3.84).
    pub eight_point: EightPointConfig,
    /// Flow noise assumed by the Euclidean inlier test of the Sampson and algebraic ablation
    /// estimators, pixels: inlier when the Sampson distance is below `1.96 σ` (the Mahalanobis
    /// estimator uses eq. 11 instead; see `mono::eight_point`). Default 1.0.
    pub sampson_inlier_sigma_px: f64,
    /// PnP RANSAC and refinement (threshold χ²₂ 95 % = 5.99).
    pub pnp: PnpConfig,
    /// Parallax test.
    pub parallax: ParallaxConfig,
    /// Scale estimation.
    pub scale: ScaleConfig,
    /// Fuse eight-point and PnP when their translation scales differ by at most this fraction.
    /// Default 0.3 (paper: 30 %).
    pub fusion_max_scale_diff: f64,
    /// … and their rotations by at most this angle, radians. Default 0.5 (paper).
    pub fusion_max_rotation_rad: f64,
    /// … and their translation directions by at most this angle, radians. Default 0.26 (15°).
    /// An addition to the paper, whose test compares only the lengths: averaging two
    /// translations that point apart shortens the result (by `cos(θ/2)`), and when the scale
    /// itself came from PnP the length test always passes. When the directions disagree, the pose
    /// whose translation direction is closer to the previous frame's (the constant-velocity
    /// prediction) is taken instead of the eight-point one: in rotation-dominant frames on small
    /// images the eight-point direction can be off by tens of degrees (measured on the synthetic
    /// loop drive: `git show 0a7500f:docs/benchmarks.md`, *Why the monocular odometry collapsed on
    /// the loop drive*).
    pub fusion_max_translation_angle_rad: f64,
    /// A frame whose translation is longer than this, metres, (or not finite) is rejected: the
    /// pose falls back to the constant-velocity prediction with a logged reason, so a gross
    /// failure (e.g. a degenerate ground plane) cannot make the trajectory diverge. Default 5
    /// (50 m/s at 10 Hz). In aerial mode the bound grows with the camera height
    /// (`scale.aerial_max_step_heights`).
    pub max_translation_m: f64,
    /// Depth cells farther than this are not kept in the depth map, metres. Default 80. In
    /// aerial mode the bound grows with the camera height (`scale.aerial_max_depth_heights`).
    pub max_depth_m: f64,
    /// Relative depth standard deviation above which a triangulated cell is dropped. Default 0.5.
    pub max_relative_depth_sigma: f64,
    /// Fuse the depth map in inverse depth ([`super::DepthMap::fuse_inverse_depth`]) instead of
    /// depth ([`super::DepthMap::fuse`]). Default false. Fusing in depth pulls the map nearer and
    /// with it the depth-ratio scale down; in inverse depth it is unbiased, which keeps the scale
    /// of the synthetic drives with noisy flow, but on KITTI 00 (300 frames) it measured 1.328 % /
    /// 0.914 deg/100 m against 1.282 % / 0.948 in depth
    /// (docs/notes/2026-12-02-mono-history.md), so it is opt-in.
    pub inverse_depth_fusion: bool,
    /// With sub-pixel depth points: every depth cell is measured in inverse depth with no
    /// filter on the measured value (`visnav_geometry::triangulation::triangulate_inverse_depth`;
    /// `max_relative_depth_sigma` does not apply), fused in inverse depth
    /// ([`super::DepthMap::fuse_inverse_measurement`]), and the depth-ratio scale is measured at
    /// the map's own points (`mono::point_scale`). Default false. Unbiased under zero-mean flow
    /// noise: on the 563-frame forward flight with the exact flow plus 0.3 px Gaussian noise the
    /// scale ends at 0.79 of the truth instead of 0.02; but with the dense flow, whose inverse
    /// depth is itself biased by depth (too low near, too high far), it ends at 0.11 instead of
    /// 0.29 (docs/notes/2026-12-02-aerial-history.md, round 2), so it is opt-in.
    pub inverse_depth_filter: bool,
    /// Where the depth map keeps its points. Default `auto` (`subpixel` in aerial mode).
    pub depth_points: DepthPoints,
    /// Homography against fundamental matrix (near-planar scenes). Default: aerial mode only.
    pub homography: HomographyConfig,
    /// Seed of the RANSAC RNGs (re-seeded per frame with the frame index). Default 0.
    pub seed: u64,
    /// The tests that refuse a frame the pipeline cannot trust ([`super::trust`]).
    pub trust: TrustConfig,
    /// The dense flow with uncertainty feeding the pipeline (downsampling factor and
    /// `FlowConfig`). Used by [`super::MonoFlow`], not by [`super::MonoOdometry`] itself.
    pub flow: MonoFlowConfig,
    /// The window adjustment over the flow's tracks (not in the paper; off by default).
    pub window: MonoWindowConfig,
    /// The covariance of each step (issue 55; not in the paper).
    pub covariance: MonoCovarianceConfig,
}

impl Default for MonoConfig {
    fn default() -> Self {
        Self {
            grid_cell_px: 10,
            depth_stride_px: 4,
            eight_point: EightPointConfig::default(),
            sampson_inlier_sigma_px: 1.0,
            pnp: PnpConfig::default(),
            parallax: ParallaxConfig::default(),
            scale: ScaleConfig::default(),
            fusion_max_scale_diff: 0.3,
            fusion_max_rotation_rad: 0.5,
            fusion_max_translation_angle_rad: 0.26,
            max_translation_m: 5.0,
            max_depth_m: 80.0,
            max_relative_depth_sigma: 0.5,
            inverse_depth_fusion: false,
            inverse_depth_filter: false,
            depth_points: DepthPoints::Auto,
            homography: HomographyConfig::default(),
            seed: 0,
            trust: TrustConfig::default(),
            flow: MonoFlowConfig::default(),
            window: MonoWindowConfig::default(),
            covariance: MonoCovarianceConfig::default(),
        }
    }
}

impl MonoConfig {
    /// The real-time preset: the paper's pipeline (the Mahalanobis eight-point, the scale from
    /// the ground and the depth ratios, PnP, fusion, the failure policy) on the fast flow
    /// ([`MonoFlowConfig::realtime`]: dense inverse search with its own uncertainty) instead of
    /// the paper's cost-volume flow. About 3x faster a frame on KITTI at the accuracy of the
    /// paper preset (docs/benchmarks.md, *Real time by design (#51)*).
    ///
    /// The parallax test reads the dense flow only (its 75th percentile and the translational
    /// parallax left after the rotation, [`ParallaxConfig`]), without the KLT median: a second
    /// tracker (corners, two pyramids, KLT) run for that one number cost 12–18 ms a KITTI frame,
    /// and on the 300 frames of the KITTI 00 clip it decided no frame (the trajectory is
    /// byte-identical with and without it); the rendered drive's stop and rotation on the spot
    /// are still caught by the translational parallax (`tests/realtime.rs` in the pipeline).
    ///
    /// The step covariance has its own factors (inflation 110, length σ 0.02, no lengths'
    /// disagreement term, the depth map's relative error 0.05 and the across-view factor 3,
    /// [`MonoCovarianceConfig`]): the fast flow's information is larger than the paper flow's
    /// relative to its errors, and most so for a downward camera (with the paper preset's
    /// factors the drives' mean NEES was 1.0, with the drives' own fit the downward flights'
    /// 27–38). Fitted through the CLI on rendered drives 1–3 and flights forward 1, down 2 and 3:
    /// the point of the grid whose worst group mean (drives, forward, downward) is nearest 6,
    /// each with at most 8 % of the steps above χ²₆'s 95 % quantile (5.12, 5.41, 6.45). Held out:
    /// drives 7–11 4.59, flights forward 8, 9, 12 and down 4, 10, 11, 12 5.68 (docs/benchmarks.md,
    /// *Step covariance*).
    #[must_use]
    pub fn realtime() -> Self {
        Self {
            flow: MonoFlowConfig::realtime(),
            parallax: ParallaxConfig {
                use_klt: false,
                ..ParallaxConfig::default()
            },
            covariance: MonoCovarianceConfig {
                inflation: 110.0,
                scale_sigma: 0.02,
                disagreement_weight: 0.0,
                depth_sigma: 0.05,
                across_view: 3.0,
                ..MonoCovarianceConfig::default()
            },
            ..Self::default()
        }
    }
}

impl MonoConfig {
    /// Checks every field.
    ///
    /// # Errors
    /// [`MonoError::InvalidConfig`] / [`MonoError::Geometry`] naming the first bad field.
    pub fn validate(&self) -> Result<(), MonoError> {
        if let Some((field, value, expected)) = self
            .window
            .invalid_field()
            .or_else(|| self.covariance.invalid_field())
        {
            return Err(MonoError::InvalidConfig {
                field,
                value,
                expected,
            });
        }
        first_broken(&self.grid_rules())?;
        first_broken(&scale_rules(&self.scale))?;
        first_broken(&self.motion_rules())?;
        self.homography.validate()?;
        first_broken(&trust_rules(&self.trust))?;
        self.eight_point.validate()?;
        self.pnp.validate()?;
        self.flow.validate()?;
        self.scale.ground.validate()?;
        Ok(())
    }

    /// The sampling grids' and the Sampson test's rules.
    fn grid_rules(&self) -> Vec<Rule> {
        let p = &self.parallax;
        vec![
            (
                self.grid_cell_px >= 1,
                "grid_cell_px",
                self.grid_cell_px as f64,
                ">= 1",
            ),
            (
                self.depth_stride_px >= 1,
                "depth_stride_px",
                self.depth_stride_px as f64,
                ">= 1",
            ),
            (
                p.reference_width_px >= 0.0 && p.reference_width_px.is_finite(),
                "parallax.reference_width_px",
                p.reference_width_px,
                "finite and >= 0",
            ),
            (
                self.sampson_inlier_sigma_px > 0.0 && self.sampson_inlier_sigma_px.is_finite(),
                "sampson_inlier_sigma_px",
                self.sampson_inlier_sigma_px,
                "finite and > 0",
            ),
        ]
    }

    /// The fusion's, the failure bounds' and the parallax test's rules.
    fn motion_rules(&self) -> Vec<Rule> {
        let p = &self.parallax;
        vec![
            (
                self.fusion_max_scale_diff >= 0.0,
                "fusion_max_scale_diff",
                self.fusion_max_scale_diff,
                ">= 0",
            ),
            (
                self.fusion_max_rotation_rad >= 0.0,
                "fusion_max_rotation_rad",
                self.fusion_max_rotation_rad,
                ">= 0",
            ),
            (
                self.fusion_max_translation_angle_rad >= 0.0,
                "fusion_max_translation_angle_rad",
                self.fusion_max_translation_angle_rad,
                ">= 0",
            ),
            (
                self.max_translation_m > 0.0,
                "max_translation_m",
                self.max_translation_m,
                "> 0",
            ),
            (
                self.max_depth_m > 0.0,
                "max_depth_m",
                self.max_depth_m,
                "> 0",
            ),
            (
                self.max_relative_depth_sigma > 0.0,
                "max_relative_depth_sigma",
                self.max_relative_depth_sigma,
                "> 0",
            ),
            (
                p.min_klt_median_px >= 0.0 && p.min_flow_p75_px >= 0.0,
                "parallax.min_flow_p75_px",
                p.min_flow_p75_px,
                ">= 0 (both thresholds)",
            ),
            (
                p.min_translational_parallax_px >= 0.0
                    && p.min_translational_parallax_px.is_finite(),
                "parallax.min_translational_parallax_px",
                p.min_translational_parallax_px,
                "finite and >= 0",
            ),
        ]
    }
}

/// One rule of [`MonoConfig::validate`]: `(holds, field, value, expected)`.
type Rule = (bool, &'static str, f64, &'static str);

/// The first rule that does not hold, as the error naming its field.
fn first_broken(rules: &[Rule]) -> Result<(), MonoError> {
    match rules.iter().find(|r| !r.0) {
        Some(&(_, field, value, expected)) => Err(MonoError::InvalidConfig {
            field,
            value,
            expected,
        }),
        None => Ok(()),
    }
}

/// The scale estimation's rules ([`MonoConfig::validate`]).
fn scale_rules(s: &ScaleConfig) -> Vec<Rule> {
    let finite_pos = |v: f64| v > 0.0 && v.is_finite();
    let mut rules = Vec::new();
    if let Some(k) = s.known_distance {
        rules.push((
            finite_pos(k.distance_m),
            "scale.known_distance.distance_m",
            k.distance_m,
            "finite and > 0",
        ));
        rules.push((
            k.a_px.iter().chain(&k.b_px).all(|v| v.is_finite()) && k.a_px != k.b_px,
            "scale.known_distance.b_px",
            k.b_px[0],
            "two different finite points",
        ));
    }
    rules.extend([
        (
            finite_pos(s.aerial_max_step_heights),
            "scale.aerial_max_step_heights",
            s.aerial_max_step_heights,
            "finite and > 0",
        ),
        (
            finite_pos(s.aerial_max_depth_heights),
            "scale.aerial_max_depth_heights",
            s.aerial_max_depth_heights,
            "finite and > 0",
        ),
        (
            finite_pos(s.camera_height_m),
            "scale.camera_height_m",
            s.camera_height_m,
            "finite and > 0",
        ),
        (
            (0.0..=1.0).contains(&s.min_overlap_fraction),
            "scale.min_overlap_fraction",
            s.min_overlap_fraction,
            "in [0, 1]",
        ),
        (
            s.max_disagreement >= 0.0,
            "scale.max_disagreement",
            s.max_disagreement,
            ">= 0",
        ),
        (
            s.max_scale_change > 1.0,
            "scale.max_scale_change",
            s.max_scale_change,
            "> 1",
        ),
        (
            (0.0..=1.0).contains(&s.aerial_ground_weight),
            "scale.aerial_ground_weight",
            s.aerial_ground_weight,
            "in [0, 1]",
        ),
        (
            s.aerial_ground_gate > 1.0 && s.aerial_ground_gate.is_finite(),
            "scale.aerial_ground_gate",
            s.aerial_ground_gate,
            "finite and > 1",
        ),
        (
            (0.0..=std::f64::consts::FRAC_PI_2).contains(&s.aerial_ground_max_tilt_rad),
            "scale.aerial_ground_max_tilt_rad",
            s.aerial_ground_max_tilt_rad,
            "in [0, pi/2]",
        ),
        (
            s.aerial_ground_max_range_heights > 1.0,
            "scale.aerial_ground_max_range_heights",
            s.aerial_ground_max_range_heights,
            "> 1",
        ),
        (
            s.reanchor_ratio > 1.0,
            "scale.reanchor_ratio",
            s.reanchor_ratio,
            "> 1",
        ),
        (
            s.reanchor_frames >= 1,
            "scale.reanchor_frames",
            s.reanchor_frames as f64,
            ">= 1",
        ),
    ]);
    rules
}

/// The trust tests' rules ([`MonoConfig::validate`]).
fn trust_rules(t: &TrustConfig) -> Vec<Rule> {
    let mut rules = vec![
        (
            t.thumbnail_px >= 1,
            "trust.thumbnail_px",
            t.thumbnail_px as f64,
            ">= 1",
        ),
        (
            t.min_intensity_std >= 0.0 && t.min_valid_fraction >= 0.0,
            "trust.min_intensity_std",
            t.min_intensity_std,
            ">= 0 (and trust.min_valid_fraction >= 0)",
        ),
        (
            t.min_structure_ratio >= 0.0 && t.max_flip_gain >= 0.0,
            "trust.min_structure_ratio",
            t.min_structure_ratio,
            ">= 0 (and trust.max_flip_gain >= 0)",
        ),
        (
            (0.0..=1.0).contains(&t.min_epipolar_inlier_fraction),
            "trust.min_epipolar_inlier_fraction",
            t.min_epipolar_inlier_fraction,
            "in [0, 1]",
        ),
        (
            (0.0..=1.0).contains(&t.min_consistent_inlier_fraction),
            "trust.min_consistent_inlier_fraction",
            t.min_consistent_inlier_fraction,
            "in [0, 1]",
        ),
        (
            (0.0..=std::f64::consts::PI).contains(&t.max_consistent_rotation_change_rad),
            "trust.max_consistent_rotation_change_rad",
            t.max_consistent_rotation_change_rad,
            "in [0, pi]",
        ),
        (
            (0.0..=std::f64::consts::PI).contains(&t.max_consistent_translation_angle_rad),
            "trust.max_consistent_translation_angle_rad",
            t.max_consistent_translation_angle_rad,
            "in [0, pi]",
        ),
        (
            t.min_consistent_valid_ratio >= 0.0,
            "trust.min_consistent_valid_ratio",
            t.min_consistent_valid_ratio,
            ">= 0",
        ),
        (
            t.valid_history_frames >= 1,
            "trust.valid_history_frames",
            t.valid_history_frames as f64,
            ">= 1",
        ),
    ];
    if let Some(max) = t.max_rotation_change_rad {
        rules.push((max > 0.0, "trust.max_rotation_change_rad", max, "> 0"));
    }
    rules.push((
        t.max_reference_gap_frames >= 1,
        "trust.max_reference_gap_frames",
        t.max_reference_gap_frames as f64,
        ">= 1",
    ));
    rules
}
