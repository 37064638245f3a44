//! Configuration of the stereo pipeline ([`StereoConfig`]), one nested struct per stage.
//!
//! The paper (Buczko & Willert) gives the structure of RotROCC but not its numbers (`b`, the fixed
//! limits, `i_max`, `j_max`, window sizes); the defaults below are ours, chosen on synthetic data
//! and the KITTI 06 clip, and documented with units.

use serde::{Deserialize, Serialize};
use visnav_image::{CornerConfig, KltConfig};

use super::error::StereoError;
use crate::ba::{BaConfig, CovarianceScale};

/// The outlier criterion of the motion estimation (the paper's comparisons, §VI).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum OutlierMode {
    /// RotROCC: rotation phase on the reprojection error (eq. 25–26), then translation phase on the
    /// decoupled normalized reprojection error (eq. 24, 27–30).
    #[default]
    Dnre,
    /// Phase 1 only: reprojection error with threshold `max(b-th largest, fixed limit)` (eq. 26).
    Re,
    /// Phase 1 with the mean-based rule of eq. 31: keep `ε − μ < 1.5 σ`.
    Mean,
    /// Phase 1 with the rule of eq. 32: keep `ε < 3² μ`.
    Std,
}

/// SAD block matching along the rectified row (stereo depth at t-1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MatchConfig {
    /// Half-size of the SAD block, pixels (block `2r+1` square). Default 3 (7x7).
    pub block_radius: usize,
    /// Smallest disparity searched, pixels. Default 1.
    pub min_disparity_px: usize,
    /// Largest disparity searched, pixels. Default 128.
    pub max_disparity_px: usize,
    /// Uniqueness: the best SAD must be below `ratio` times the best SAD at least 2 px away.
    /// Default 0.9.
    pub uniqueness_ratio: f32,
    /// Left–right consistency: matching the right block back into the left row must land within
    /// this many pixels. Default 1.
    pub lr_tolerance_px: f64,
    /// Refine the SAD disparity by Lucas–Kanade from left to right (not in the paper). Default
    /// false: on KITTI 06 it enlarged the scale bias (see docs/notes/2026-12-02-stereo-history.md).
    pub refine_lk: bool,
    /// Refine the SAD disparity along the rectified row: Gauss–Newton on the disparity and a
    /// brightness offset between the two images over the SAD block, both blocks sampled at the
    /// feature's sub-pixel position ([`crate::stereo::matching::refine_disparity_on_row`]; not in
    /// the paper). Ignored when [`Self::refine_lk`] is set. Default false (the paper's
    /// frame-to-frame RotROCC); the window's front end turns it on
    /// ([`WindowConfig::refine_on_row`]).
    pub refine_on_row: bool,
}

impl Default for MatchConfig {
    fn default() -> Self {
        Self {
            block_radius: 3,
            min_disparity_px: 1,
            max_disparity_px: 128,
            uniqueness_ratio: 0.9,
            lr_tolerance_px: 1.0,
            refine_lk: false,
            refine_on_row: false,
        }
    }
}

/// One robust estimation phase: iterate least squares, drop features whose error is at least
/// `max(b-th largest error, fixed_limit)`, stop when the set is unchanged or at `max_iterations`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PhaseConfig {
    /// `b`: at most this many features are dropped per iteration (the b-th largest error sets the
    /// threshold). Default 20 (rotation) and 10 (translation).
    pub b: usize,
    /// Fixed termination limit: reprojection error in pixels (rotation phase) or DNRE, unitless
    /// (translation phase). Default 1.0 px and 0.05 (the expected final `|E − 1|`).
    pub fixed_limit: f64,
    /// `i_max` / `j_max`. Default 30.
    pub max_iterations: usize,
    /// Gauss–Newton steps per least-squares solve. Default 8.
    pub gauss_newton_steps: usize,
}

impl PhaseConfig {
    fn rotation_default() -> Self {
        Self {
            b: 20,
            fixed_limit: 1.0,
            max_iterations: 30,
            gauss_newton_steps: 8,
        }
    }
    fn translation_default() -> Self {
        Self {
            b: 10,
            fixed_limit: 0.05,
            max_iterations: 30,
            gauss_newton_steps: 8,
        }
    }
}

impl Default for PhaseConfig {
    fn default() -> Self {
        Self::rotation_default()
    }
}

/// Configuration of [`crate::stereo::StereoOdometry`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StereoConfig {
    /// Shi–Tomasi detection in the left image at t-1.
    pub corners: CornerConfig,
    /// Stereo block matching at t-1.
    pub matching: MatchConfig,
    /// Pyramidal Lucas–Kanade tracking t-1 → t (left and right).
    pub klt: KltConfig,
    /// Track t-1 → t with each feature's window warped as its patch is predicted to look at t
    /// (its depth, a surface facing the camera, the motion guess:
    /// [`visnav_image::fronto_parallel_warp`]) instead of translated only: a translated window
    /// of a patch that grows by a few per cent a frame is tracked a fraction of a pixel off, and
    /// a persistent track accumulates it. Default false (the paper's tracker, kept by the
    /// frame-to-frame front end); the window's front end warps by default
    /// ([`WindowConfig::warp_tracks`]; docs/notes/2026-12-02-stereo-history.md, *Warped tracking
    /// windows*).
    pub warp_tracks: bool,
    /// The largest predicted change of a window's area, `|det A − 1|`, that is warped; a patch
    /// deforming more (a near point, mostly on the road or a guard rail, whose slanted surface the
    /// facing-surface warp does not describe) is tracked translated. Default 0.2 (measured: 0.1,
    /// 0.2, 0.3, 0.5 and no limit on KITTI 06 and three rendered highway drives,
    /// docs/notes/2026-12-02-stereo-history.md).
    pub max_warp_area_change: f64,
    /// Circular check tolerance, pixels: the right position at t reached through the left image
    /// must agree with the one tracked in the right image. Default 1.0.
    pub circular_tolerance_px: f64,
    /// Rotation phase (eq. 25–26).
    pub rotation: PhaseConfig,
    /// Translation phase (eq. 27–30); `fixed_limit` is a DNRE (unitless).
    pub translation: PhaseConfig,
    /// Outlier criterion. Default [`OutlierMode::Dnre`].
    pub outlier: OutlierMode,
    /// Low-speed rule: when the median rotation-compensated flow is below this (pixels), phases 2
    /// and 3 are skipped and phase 1's motion is kept. Default 1.0.
    pub low_speed_flow_px: f64,
    /// Also use the right image at t in the least squares (4 residuals per feature instead of 2).
    /// Default true.
    pub use_right_reprojection: bool,
    /// Fewer tracked features than this fails the frame (constant-velocity fallback). Default 20.
    pub min_features: usize,
    /// Points farther than this are not used, metres. Default 400: beyond the depth of a
    /// 1-pixel disparity of KITTI's rig (385 m at 1241 px), so `matching.min_disparity_px` is
    /// the bound there. Far points fix the rotation: on the rendered 1,000-frame highway drive
    /// 80 m gave r_err 0.1253 (frame-to-frame) and 0.1204 deg/100 m (window), 400 m 0.0752 and
    /// 0.0822 (docs/notes/2026-12-02-stereo-history.md).
    pub max_depth_m: f64,
    /// A frame-to-frame translation above this is treated as a failure, metres. Default 5.
    pub max_translation_m: f64,
    /// Re-prediction (not in the paper): when fewer than this fraction of the features of t-1
    /// pass tracking and the circular check, or fewer than this fraction of those are rotation
    /// inliers, the features are tracked again from the motion just estimated (zero motion if
    /// none) and the pass with more rotation inliers is kept. Catches a constant-turn-rate
    /// prediction that is far off when the turn rate changes quickly. 0 disables. Default 0.6.
    pub retrack_fraction: f64,
    /// Consistency check (not in the paper): a tracked feature is consistent with an estimated
    /// motion when its reprojection error (eq. 2) under it is below this, pixels. Default 2.0,
    /// twice the rotation phase's limit (`rotation.fixed_limit`).
    pub consistency_limit_px: f64,
    /// A motion consistent with fewer than this fraction of the features that passed tracking
    /// and the circular check is refused ([`crate::stereo::FailReason::InconsistentMotion`],
    /// constant-velocity fallback): the rank-based phases (eq. 26, 30) always keep some subset,
    /// and on a wrong motion that subset is a small minority of the tracks. Default 0.5 (the
    /// motion must explain most tracks); 0 disables.
    pub min_consistent_fraction: f64,
    /// Persistent tracks and the sliding-window bundle adjustment (issue #25, not in the paper).
    pub window: WindowConfig,
    /// Each step's covariance (issue 55 item 5, not in the paper; [`super::covariance`]).
    pub covariance: CovarianceConfig,
}

/// Persistent feature tracks and the sliding-window bundle adjustment on top of RotROCC's
/// frame-to-frame estimate ([`crate::stereo::window`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WindowConfig {
    /// Carry features that RotROCC kept as inliers to the next frame (with their ids), instead of
    /// detecting every feature afresh; new corners only fill the gaps. Default true.
    pub persistent_tracks: bool,
    /// Refine the last [`Self::window_frames`] poses and the points they observe by bundle
    /// adjustment after every frame (needs `persistent_tracks`). Default true.
    pub bundle_adjustment: bool,
    /// Carry every tracked feature consistent with the estimated motion (reprojection error
    /// below `consistency_limit_px`) instead of only the inliers of RotROCC's final phase, whose
    /// rank-based rule (eq. 30) also drops good features. Default true.
    pub carry_consistent: bool,
    /// Measure a carried feature's disparity afresh at every frame by the SAD matching of new
    /// features ([`crate::stereo::matching`], at its tracked left pixel; the track ends when the
    /// match fails or lands more than `circular_tolerance_px` from the tracked right pixel)
    /// instead of taking the difference of the left and right tracks, whose independent
    /// Lucas–Kanade drifts add up over the track's life. Default true.
    pub rematch_stereo: bool,
    /// Refine the re-measured disparity of a carried feature by Lucas–Kanade from left to right
    /// at its sub-pixel left position ([`MatchConfig::refine_lk`] for carried features only):
    /// the SAD disparity holds for the rounded pixel. Default false.
    pub rematch_refine_lk: bool,
    /// With `persistent_tracks`, track with warped windows ([`StereoConfig::warp_tracks`]): a
    /// persistent track accumulates the translated window's error on patches that grow from
    /// frame to frame. Default true (with [`Self::refine_on_row`] and `sigma_px` 0.3: ten
    /// rendered 1,000-frame highway drives, the 2,000-frame rendered lap and KITTI 06 all score
    /// better than with translated windows; docs/notes/2026-12-02-stereo-history.md, *Disparities
    /// refined along the row*).
    pub warp_tracks: bool,
    /// With `persistent_tracks`, refine every stereo match of the front end (new corners and
    /// carried tracks' re-matches) along the rectified row ([`MatchConfig::refine_on_row`]):
    /// the window keeps a point's disparity over many frames, and the SAD parabola's holds only
    /// for the rounded pixel. Default true (docs/notes/2026-12-02-stereo-history.md, *Disparities
    /// refined along the row*).
    pub refine_on_row: bool,
    /// `K`: frames in the window (the oldest is held fixed). Default 7
    /// (docs/notes/2026-12-02-stereo-history.md).
    pub window_frames: usize,
    /// A new corner closer than this to a carried track is not added, pixels. Default 10.
    pub min_track_distance_px: f64,
    /// Standard deviation of a tracked pixel coordinate, pixels: whitens the BA residuals (the
    /// Huber and χ² limits of [`Self::ba`] are in units of it). Default 0.3 (the warped windows'
    /// tracks; 0.5 suits translated ones).
    pub sigma_px: f64,
    /// Standard deviation of a carried feature's right column, pixels: whitens the BA's
    /// disparity residual (the SAD disparity holds for the rounded left pixel). Default 0.5.
    pub right_sigma_px: f64,
    /// A point enters the window BA when observed in at least this many window frames. Default 2.
    pub min_observations: usize,
    /// A carried track whose whitened squared error in the newest frame exceeds
    /// `ba.outlier_chi2` after the adjustment is ended. Default true.
    pub drop_ba_outliers: bool,
    /// Start the next frame's tracking from the adjusted 3-D points (in the current camera)
    /// instead of the points triangulated from the current stereo pair alone. Default true.
    pub use_window_points: bool,
    /// Report the adjusted motion of the newest frame pair (`prev_from_cur` between the two
    /// newest adjusted poses), chained onto the poses already reported, instead of the newest
    /// adjusted pose itself, whose step from the pose reported for t-1 also carries the
    /// adjustment's revision of t-1. Default false: the relative report was worse on KITTI 06
    /// and on the highway drive (docs/notes/2026-12-02-stereo-history.md).
    pub report_relative: bool,
    /// The solver: Huber threshold, χ² rounds, Levenberg–Marquardt limits; with
    /// `ba.estimate_right_cx_offset` each adjustment also measures the rig's disparity offset
    /// ([`visnav_core::StereoCamera::right_cx_offset_px`]), which the odometry then uses.
    /// Default [`BaConfig::default`] with `min_relative_decrease` 1e-4 (its own default 1e-6):
    /// a step that lowers the cost by less than 0.01 % ends the round. Measured on KITTI 06
    /// and the three rendered highway drives: the same accuracy to 1 % and 20 % less time in
    /// the adjustment (docs/notes/2026-12-02-realtime-history.md, #24 step 15).
    pub ba: BaConfig,
    /// The rig's disparity offset is the running mean of the adjustments' measurements over
    /// this many frames (the first ones: the mean of all so far). Default 20.
    pub offset_horizon_frames: usize,
    /// A measurement of the offset beyond this is not taken, pixels. Default 1.
    pub max_right_cx_offset_px: f64,
}

impl Default for WindowConfig {
    fn default() -> Self {
        Self {
            persistent_tracks: true,
            bundle_adjustment: true,
            carry_consistent: true,
            rematch_stereo: true,
            rematch_refine_lk: false,
            warp_tracks: true,
            refine_on_row: true,
            window_frames: 7,
            min_track_distance_px: 10.0,
            sigma_px: 0.3,
            right_sigma_px: 0.5,
            min_observations: 2,
            drop_ba_outliers: true,
            use_window_points: true,
            report_relative: false,
            ba: BaConfig {
                min_relative_decrease: 1e-4,
                ..BaConfig::default()
            },
            offset_horizon_frames: 20,
            max_right_cx_offset_px: 1.0,
        }
    }
}

impl WindowConfig {
    fn validate(&self) -> Result<(), StereoError> {
        let bad = |field: &str, message: &str| {
            Err(StereoError::InvalidConfig {
                field: format!("window.{field}"),
                message: message.to_string(),
            })
        };
        if self.window_frames < 2 {
            return bad("window_frames", "must be at least 2");
        }
        if !(self.min_track_distance_px.is_finite() && self.min_track_distance_px >= 0.0) {
            return bad("min_track_distance_px", "must be finite and >= 0");
        }
        if !(self.sigma_px.is_finite() && self.sigma_px > 0.0) {
            return bad("sigma_px", "must be finite and > 0");
        }
        if !(self.right_sigma_px.is_finite() && self.right_sigma_px > 0.0) {
            return bad("right_sigma_px", "must be finite and > 0");
        }
        if self.min_observations < 2 {
            return bad("min_observations", "must be at least 2");
        }
        if self.offset_horizon_frames == 0 {
            return bad("offset_horizon_frames", "must be at least 1");
        }
        if !(self.max_right_cx_offset_px.is_finite() && self.max_right_cx_offset_px >= 0.0) {
            return bad("max_right_cx_offset_px", "must be finite and >= 0");
        }
        let b = &self.ba;
        if b.fixed_frames == 0 || b.fixed_frames >= self.window_frames {
            return bad("ba.fixed_frames", "must be in 1..window_frames");
        }
        if !(b.huber_px.is_finite() && b.huber_px > 0.0) {
            return bad("ba.huber_px", "must be finite and > 0");
        }
        if !(b.outlier_chi2.is_finite() && b.outlier_chi2 > 0.0) {
            return bad("ba.outlier_chi2", "must be finite and > 0");
        }
        if !(b.initial_lambda.is_finite() && b.initial_lambda > 0.0) {
            return bad("ba.initial_lambda", "must be finite and > 0");
        }
        if !(b.min_relative_decrease.is_finite() && b.min_relative_decrease >= 0.0) {
            return bad("ba.min_relative_decrease", "must be finite and >= 0");
        }
        Ok(())
    }
}

impl Default for StereoConfig {
    fn default() -> Self {
        Self {
            // sub-pixel corner positions do not matter for VO: KLT tracks whatever point it is given
            corners: CornerConfig {
                max_per_bucket: 6,
                bucket_cols: 20,
                bucket_rows: 6,
                quality: 0.01,
                subpixel: false,
                ..CornerConfig::default()
            },
            matching: MatchConfig::default(),
            warp_tracks: false,
            max_warp_area_change: 0.2,
            klt: KltConfig {
                // 9x9 windows: against 11x11, r_err lower on KITTI 06 (1.5808 → 1.5358), the
                // rendered highway (0.0749 → 0.0714) and lap, 11.5 % less time; t_err mixed
                // (docs/notes/2026-12-02-stereo-history.md)
                window_radius: 4,
                // 4 levels (top at 1/8 scale): Lucas–Kanade converges from a prediction that is off
                // by ~30 px, e.g. when the turn rate jumps by 5°/frame
                // (docs/notes/2026-12-02-stereo-history.md)
                levels: 4,
                max_residual: 25.0,
                ..KltConfig::default()
            },
            circular_tolerance_px: 1.0,
            rotation: PhaseConfig::rotation_default(),
            translation: PhaseConfig::translation_default(),
            outlier: OutlierMode::Dnre,
            low_speed_flow_px: 1.0,
            use_right_reprojection: true,
            min_features: 20,
            max_depth_m: 400.0,
            max_translation_m: 5.0,
            retrack_fraction: 0.6,
            consistency_limit_px: 2.0,
            min_consistent_fraction: 0.5,
            window: WindowConfig::default(),
            covariance: CovarianceConfig::default(),
        }
    }
}

impl StereoConfig {
    /// The stereo matching of the front end's new corners: [`Self::matching`], refined along the
    /// row when the window's tracks ask for it ([`WindowConfig::refine_on_row`]).
    #[must_use]
    pub fn front_end_matching(&self) -> MatchConfig {
        MatchConfig {
            refine_on_row: self.matching.refine_on_row
                || (self.window.persistent_tracks && self.window.refine_on_row),
            ..self.matching.clone()
        }
    }

    /// Whether the front end tracks with warped windows: [`Self::warp_tracks`], or the window's
    /// tracks asking for it ([`WindowConfig::warp_tracks`]).
    #[must_use]
    pub fn warps_tracks(&self) -> bool {
        self.warp_tracks || (self.window.persistent_tracks && self.window.warp_tracks)
    }

    /// Checks every field.
    ///
    /// # Errors
    /// [`StereoError::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> Result<(), StereoError> {
        let bad = |field: &str, message: &str| {
            Err(StereoError::InvalidConfig {
                field: field.to_string(),
                message: message.to_string(),
            })
        };
        self.covariance.validate()?;
        self.corners
            .validate()
            .map_err(|e| StereoError::InvalidConfig {
                field: "corners".into(),
                message: e.to_string(),
            })?;
        self.klt
            .validate()
            .map_err(|e| StereoError::InvalidConfig {
                field: "klt".into(),
                message: e.to_string(),
            })?;
        let m = &self.matching;
        if m.block_radius == 0 || m.block_radius > 15 {
            return bad("matching.block_radius", "must be in 1..=15");
        }
        if m.min_disparity_px >= m.max_disparity_px {
            return bad(
                "matching.min_disparity_px",
                "must be below max_disparity_px",
            );
        }
        if !(m.uniqueness_ratio > 0.0 && m.uniqueness_ratio <= 1.0) {
            return bad("matching.uniqueness_ratio", "must be in (0, 1]");
        }
        if !(m.lr_tolerance_px.is_finite() && m.lr_tolerance_px >= 0.0) {
            return bad("matching.lr_tolerance_px", "must be finite and >= 0");
        }
        if !(self.max_warp_area_change.is_finite() && self.max_warp_area_change >= 0.0) {
            return bad("max_warp_area_change", "must be finite and >= 0");
        }
        if !(self.circular_tolerance_px.is_finite() && self.circular_tolerance_px > 0.0) {
            return bad("circular_tolerance_px", "must be finite and > 0");
        }
        for (name, p) in [
            ("rotation", &self.rotation),
            ("translation", &self.translation),
        ] {
            if p.b == 0 {
                return bad(name, "b must be > 0");
            }
            if !(p.fixed_limit.is_finite() && p.fixed_limit > 0.0) {
                return bad(name, "fixed_limit must be finite and > 0");
            }
            if p.max_iterations == 0 || p.gauss_newton_steps == 0 {
                return bad(name, "max_iterations and gauss_newton_steps must be > 0");
            }
        }
        if !(self.low_speed_flow_px.is_finite() && self.low_speed_flow_px >= 0.0) {
            return bad("low_speed_flow_px", "must be finite and >= 0");
        }
        if self.min_features < 6 {
            return bad("min_features", "must be at least 6");
        }
        if !(self.max_depth_m.is_finite() && self.max_depth_m > 0.0) {
            return bad("max_depth_m", "must be finite and > 0");
        }
        if !(self.max_translation_m.is_finite() && self.max_translation_m > 0.0) {
            return bad("max_translation_m", "must be finite and > 0");
        }
        if !(0.0..=1.0).contains(&self.retrack_fraction) {
            return bad("retrack_fraction", "must be in [0, 1]");
        }
        if !(self.consistency_limit_px.is_finite() && self.consistency_limit_px > 0.0) {
            return bad("consistency_limit_px", "must be finite and > 0");
        }
        if !(0.0..=1.0).contains(&self.min_consistent_fraction) {
            return bad("min_consistent_fraction", "must be in [0, 1]");
        }
        self.window.validate()
    }
}

/// How each step's covariance is computed ([`crate::stereo::FrameResult::prev_from_cur_covariance`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CovarianceConfig {
    /// Compute it. Default true.
    pub enabled: bool,
    /// Scale the inverse information by the residual variance of the whitened reprojection
    /// errors. Default true.
    pub residual_variance: bool,
    /// A global factor on the window's covariance, calibrated on rendered training sequences
    /// only (the drives of seeds 1–3, the forward flight of seed 1 and the downward one of seed
    /// 2, 60 frames of 620x188, `visnav synth`) so that the normalized estimation error squared
    /// (NEES) follows χ²₆: their mean NEES with factor 1 was 20.8 (the residual variance of a
    /// window that fits its own tracks underestimates the step's error, and the reported step
    /// also carries the window's revision of the previous pose); 3.5 gave a mean of 6.0 with
    /// 9.5 % of the steps above χ²₆'s 95 % quantile, and 5 % more (3.7) keeps that share below
    /// 8 %, a margin under the 10 % the issue allows, at a mean of 5.7. Default 3.7
    /// (docs/notes/2026-12-02-stereo-history.md, *Step covariance*).
    pub inflation: f64,
    /// The same for the two-frame covariance (without the window, `--no-ba`, or a frame the
    /// window did not adjust): mean NEES 6.7 on the same training sequences with factor 1;
    /// 1.1 for a mean of 6, with the same 5 % margin. Default 1.15.
    pub two_frame_inflation: f64,
}

impl Default for CovarianceConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            residual_variance: true,
            inflation: 3.7,
            two_frame_inflation: 1.15,
        }
    }
}

impl CovarianceConfig {
    /// The window's scale handed to [`crate::ba::WindowBa::relative_covariance`]; `None` when disabled.
    #[must_use]
    pub fn scale(&self) -> Option<CovarianceScale> {
        self.enabled.then_some(CovarianceScale {
            residual_variance: self.residual_variance,
            inflation: self.inflation,
        })
    }

    /// The two-frame covariance's scale ([`super::covariance::two_frame_covariance`]); `None` when disabled.
    #[must_use]
    pub fn two_frame_scale(&self) -> Option<CovarianceScale> {
        self.enabled.then_some(CovarianceScale {
            residual_variance: self.residual_variance,
            inflation: self.two_frame_inflation,
        })
    }

    pub(super) fn validate(&self) -> Result<(), StereoError> {
        for (field, v) in [
            ("inflation", self.inflation),
            ("two_frame_inflation", self.two_frame_inflation),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(StereoError::InvalidConfig {
                    field: format!("covariance.{field}"),
                    message: format!("must be finite and > 0, got {v}"),
                });
            }
        }
        Ok(())
    }
}
