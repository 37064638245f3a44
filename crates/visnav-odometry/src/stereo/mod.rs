//! Stereo visual odometry: RotROCC (Buczko & Willert, "Flow-Decoupled Normalized Reprojection
//! Error for Visual Odometry", §V).
//!
//! Per stereo frame `t` ([`StereoOdometry::process`]):
//! 1. Gaussian pyramids of the left and right images ([`visnav_image::Pyramid`]).
//! 2. Tracking t-1 → t: every stereo feature of t-1 is predicted in both images at t by
//!    reprojecting its 3-D point with the previous motion (constant turn rate and velocity),
//!    refined by pyramidal Lucas–Kanade in the left and the right image, and kept when the
//!    circular check closes: the right position reached through the left image at t (a left → right
//!    Lucas–Kanade step) agrees with the one tracked in the right image. When that prediction was
//!    poor (few tracks or few rotation inliers, `retrack_fraction`), the features are tracked
//!    again from the motion just estimated and the better pass is kept.
//! 3. Motion: [`estimate::estimate_motion`] — rotation phase (eq. 25–26), rotation compensation
//!    (eq. 27–28), translation phase on the DNRE (eq. 24, 29–30) over the rotation inliers,
//!    low-speed rule.
//! 4. New features at t for the next frame: Shi–Tomasi corners with bucketing, SAD stereo
//!    matching with uniqueness and left–right checks, triangulation ([`matching`]).
//! 5. Persistent tracks and the window bundle adjustment (issue #25, not in the paper;
//!    [`window`], [`StereoConfig::window`]): the tracked features the motion explains are
//!    carried to t with their ids (the corners of step 4 only fill the gaps), and the last
//!    `window.window_frames` frames are bundle-adjusted from the estimate of step 3; the newest
//!    adjusted pose is the frame's pose. Off (`window.persistent_tracks` and
//!    `window.bundle_adjustment` false, `--no-ba`), the pipeline is the frame-to-frame RotROCC.
//!
//! Two `rayon::join`s keep both cores busy: tracking, estimation and carrying (steps 2, 3 and
//! the first half of 5) beside the corner detection of step 4; then the window adjustment
//! beside the corners' stereo matching, which only matches the corners that fill a gap the
//! carried tracks leave (the others would not be kept). The adjustment only uses tracks seen in
//! two frames or more, so the corners of step 4 join the window's newest frame after it.
//!
//! The constant-velocity prediction is the driver's, not the odometry's: each call is told
//! the motion to predict with (`prediction`: the tracking's first guess) and a frame's result
//! returns the motion to predict the next one with ([`FrameResult::motion`]: the estimate, or
//! the window-adjusted step) — `visnav-pipeline`'s stereo stream owns it, and a driver of the
//! odometry alone keeps it with `prediction = result.motion.unwrap_or(prediction)` (starting
//! from [`crate::RelativeMotion::identity`]).
//! A frame that cannot be estimated keeps the constant-velocity prediction and reports why
//! ([`FrameStatus::Fallback`]); [`StereoOdometry::process`] never panics on image content.
//! Poses: a frame's motion is reported as `prev_from_cur` (the left camera at t in the frame of
//! the t-1 left camera, [`FrameResult::prev_from_cur`]) and handed around as a
//! [`crate::RelativeMotion`]; the tracking's predictions and the estimation work on its inverse
//! `cur_from_prev` (maps points of the t-1 left camera into the t left camera, [`estimate`]);
//! `world_from_cam` is the left camera at t in the frame of the first left camera.

pub mod config;
pub mod covariance;
mod error;
pub mod estimate;
pub mod matching;
mod tracking;
pub mod window;

use std::time::Instant;

use crate::RelativeMotion;
use nalgebra::{Matrix6, Point2, UnitQuaternion};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use visnav_core::{GrayImage, Pose, StereoCamera};
use visnav_image::{Corner, Pyramid, detect_corners};
use window::TrackWindow;

pub use config::{MatchConfig, OutlierMode, PhaseConfig, StereoConfig, WindowConfig};
pub use covariance::CovarianceConfig;
pub use error::StereoError;
pub use estimate::{FeatureErrors, MotionEstimate, Observation, estimate_motion, feature_errors};
pub use matching::{StereoFeature, match_feature};

/// Why a frame fell back to the constant-velocity prediction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "reason")]
pub enum FailReason {
    /// The left or right image does not have the rig's size.
    ImageSize {
        /// Expected width and height, pixels.
        expected: (usize, usize),
        /// Left image width and height.
        left: (usize, usize),
        /// Right image width and height.
        right: (usize, usize),
    },
    /// The previous frame had no usable stereo features.
    NoPreviousFeatures,
    /// Too few features survived tracking and the circular check.
    TooFewTracks {
        /// Features that survived.
        found: usize,
        /// The configured minimum.
        needed: usize,
    },
    /// The least squares failed (degenerate geometry).
    EstimationFailed,
    /// The estimated translation exceeds `max_translation_m`.
    ImplausibleMotion {
        /// The estimated translation, metres.
        translation_m: f64,
    },
    /// The estimated motion explains too few of the tracked features (fewer than
    /// `min_consistent_fraction` within `consistency_limit_px`): the tracks do not agree on one
    /// motion, as when a poor prediction let Lucas–Kanade lock onto wrong matches.
    InconsistentMotion {
        /// Tracked features consistent with the best motion found.
        consistent: usize,
        /// Features that passed tracking and the circular check.
        tracked: usize,
    },
    /// The frame's images were missing or unreadable ([`StereoOdometry::skip`]).
    MissingInput {
        /// Why (the file and the problem).
        message: String,
    },
}

/// Status of one processed frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "status")]
pub enum FrameStatus {
    /// The first frame: identity pose, features initialised.
    First,
    /// Estimated by the full scheme (or phase 1 only in `re`/`mean`/`std` modes).
    Ok,
    /// Estimated with the low-speed rule (phase 1 only).
    LowSpeed,
    /// Constant-velocity prediction used.
    Fallback(FailReason),
}

/// Feature counts per stage of one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct FrameCounts {
    /// Shi–Tomasi corners detected in the current left image.
    pub detected: usize,
    /// Of those, with a stereo match. Only the corners that can join the next frame's features
    /// are matched: all of them when the frame starts afresh, else those filling a gap the
    /// carried tracks leave.
    pub stereo_matched: usize,
    /// Features of t-1 tracked in both images at t.
    pub tracked: usize,
    /// Of those, passing the circular check (`N_0`).
    pub circular: usize,
    /// Inliers of the rotation phase.
    pub rotation_inliers: usize,
    /// Iterations of the rotation phase.
    pub rotation_iterations: usize,
    /// Inliers of the translation phase.
    pub translation_inliers: usize,
    /// Iterations of the translation phase.
    pub translation_iterations: usize,
    /// Of the circular-checked features, those consistent with the estimated motion
    /// (`consistency_limit_px`).
    #[serde(default)]
    pub consistent: usize,
    /// Features of t-1 carried to t as persistent tracks (the rest of the features at t are new
    /// corners).
    #[serde(default)]
    pub carried: usize,
    /// Points in the window bundle adjustment (0 when it did not run).
    #[serde(default)]
    pub window_points: usize,
    /// Tracks ended as χ² outliers of the window bundle adjustment.
    #[serde(default)]
    pub window_outliers: usize,
}

/// Wall time per stage of one frame, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct StageTimings {
    /// Pyramids and gradients of both images.
    pub pyramid_ms: f64,
    /// Corner detection in the left image.
    pub corners_ms: f64,
    /// SAD stereo matching and triangulation.
    pub stereo_ms: f64,
    /// Prediction, Lucas–Kanade in both images and the circular check.
    pub tracking_ms: f64,
    /// Rotation and translation phases.
    pub estimation_ms: f64,
    /// Carrying the tracks, filling the gaps and the window bundle adjustment.
    #[serde(default)]
    pub window_ms: f64,
    /// The whole `process` call (stages overlap: tracking and detection run in parallel).
    pub total_ms: f64,
}

/// The result of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameResult {
    /// Index of the frame (0 = first processed).
    pub index: usize,
    /// What happened.
    pub status: FrameStatus,
    /// The motion from this frame's left camera to the previous one's (`prev_from_cur`).
    pub prev_from_cur: Pose,
    /// The motion the driver predicts the next frame with (the constant-velocity model, its
    /// `prediction` for the next [`StereoOdometry::process`]): the frame-to-frame estimate, or
    /// the window-adjusted step when the window was adjusted; `None` for the first frame and on
    /// a fallback (the prediction stands).
    pub motion: Option<RelativeMotion>,
    /// Its 6x6 covariance ([`covariance`]: right perturbation in this camera's frame, x, y, z,
    /// rotation about x, y, z); `None` without an estimate (first frame, fallback).
    pub prev_from_cur_covariance: Option<Matrix6<f64>>,
    /// The left camera at this frame in the first left camera's frame.
    pub world_from_cam: Pose,
    /// Feature counts.
    pub counts: FrameCounts,
    /// Stage timings.
    pub timings: StageTimings,
    /// Median rotation-compensated flow (eq. 28), pixels (0 when not estimated).
    pub median_translation_flow_px: f64,
    /// The feature tracks t-1 → t the motion was estimated from, with their inlier flags (empty
    /// for the first frame and on a fallback): what a plot of the frame shows.
    pub tracks: Vec<Track>,
}

impl FrameResult {
    /// A frame without an estimate of its own (the first frame, a fallback): no motion for the
    /// driver's prediction, no covariance, no tracks.
    fn without_estimate(
        (index, status): (usize, FrameStatus),
        (prev_from_cur, world_from_cam): (Pose, Pose),
        (counts, timings): (FrameCounts, StageTimings),
    ) -> Self {
        Self {
            index,
            status,
            prev_from_cur,
            motion: None,
            prev_from_cur_covariance: None,
            world_from_cam,
            counts,
            timings,
            median_translation_flow_px: 0.0,
            tracks: Vec::new(),
        }
    }
}

/// One feature track of a frame, for plots and reports.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Track {
    /// Left pixel at t-1 (the reprojection of the point triangulated there).
    pub prev_left_px: Point2<f64>,
    /// Measured left pixel at t.
    pub left_px: Point2<f64>,
    /// Depth of the point in the left camera at t under the estimated motion, metres.
    pub depth_m: f64,
    /// Kept by the final phase of the estimation (translation, or rotation when it was skipped).
    pub inlier: bool,
}

/// A motion with the observations it was estimated from (and the index of each observation's
/// feature of t-1), or why there is none.
type Estimated = Result<(MotionEstimate, Vec<Observation>, Vec<usize>), FailReason>;

/// What [`StereoOdometry::track_and_carry`] found.
struct Tracked {
    motion: Estimated,
    counts: FrameCounts,
    tracking_ms: f64,
    estimation_ms: f64,
    /// The carried tracks with their ids (persistent tracks and a motion).
    carried: Option<Vec<(StereoFeature, u64)>>,
    /// The newest frame's pose when the window was pushed with the carried tracks, to be
    /// adjusted before the new corners join it ([`Early`]).
    early_pose: Option<Pose>,
    /// Carrying the tracks and pushing the window.
    window_ms: f64,
}

/// The window adjusted with the carried tracks before the new corners join the newest frame.
struct Early {
    window_pose: Pose,
    adjusted: Option<window::Adjusted>,
}

struct FrameState {
    left: Pyramid,
    right: Pyramid,
    features: Vec<StereoFeature>,
    /// The track id of each feature.
    ids: Vec<u64>,
}

/// The RotROCC stereo odometry: feed stereo frames in order.
pub struct StereoOdometry {
    rig: StereoCamera,
    config: StereoConfig,
    prev: Option<FrameState>,
    world_from_cam: Pose,
    index: usize,
    /// The last frames and their tracks (window bundle adjustment).
    window: TrackWindow,
    /// The newest frame's pose in the window (equals `world_from_cam` unless
    /// `window.report_relative`).
    window_world_from_cam: Pose,
    /// The id of the next new track.
    next_id: u64,
    /// The pyramids of a finished frame, rebuilt in place for the next one (no allocation).
    spare: Option<(Pyramid, Pyramid)>,
    /// The window adjustments' measurements of the disparity offset taken so far.
    offset_measurements: usize,
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

impl StereoOdometry {
    /// A new odometry for a rectified rig.
    ///
    /// # Errors
    /// [`StereoError::InvalidConfig`] when the configuration does not validate.
    pub fn new(rig: StereoCamera, config: StereoConfig) -> Result<Self, StereoError> {
        config.validate()?;
        Ok(Self {
            rig,
            config,
            prev: None,
            world_from_cam: Pose::identity(),
            index: 0,
            window: TrackWindow::default(),
            window_world_from_cam: Pose::identity(),
            next_id: 0,
            spare: None,
            offset_measurements: 0,
        })
    }

    /// The configuration in use.
    #[must_use]
    pub fn config(&self) -> &StereoConfig {
        &self.config
    }

    /// The current left camera pose in the first camera's frame.
    #[must_use]
    pub fn world_from_cam(&self) -> Pose {
        self.world_from_cam
    }

    /// The stereo features of the last processed frame, in its left camera (empty before the
    /// first frame and after a skipped one): the persistent tracks carried to it and the new
    /// corners, each with its triangulated (or window-adjusted) point. The next frame is tracked
    /// from them; the stereo loop closure takes their depths as the frame's depth map.
    #[must_use]
    pub fn features(&self) -> &[StereoFeature] {
        self.prev.as_ref().map_or(&[], |p| p.features.as_slice())
    }

    /// The persistent track id of each of [`Self::features`] (same order): a feature carried from
    /// the frame before keeps its id, a new corner gets a fresh one.
    #[must_use]
    pub fn feature_ids(&self) -> &[u64] {
        self.prev.as_ref().map_or(&[], |p| p.ids.as_slice())
    }

    /// The rectified rig.
    #[must_use]
    pub fn rig(&self) -> &StereoCamera {
        &self.rig
    }

    /// Accounts for a frame whose images are missing or unreadable: it gets the constant-velocity
    /// `prediction` (status [`FrameStatus::Fallback`] with [`FailReason::MissingInput`]) and the
    /// next pair starts the tracking afresh (it is compared with nothing, so it falls back too).
    pub fn skip(&mut self, message: String, prediction: &RelativeMotion) -> FrameResult {
        let start = Instant::now();
        let index = self.index;
        self.index += 1;
        self.prev = None;
        let reason = FailReason::MissingInput { message };
        let nothing = (FrameCounts::default(), StageTimings::default());
        self.fallback(index, (reason, prediction), nothing, start)
    }

    /// Processes the next stereo pair (rectified, same size as the rig). `prediction` is the
    /// constant-velocity model, which the driver keeps: the [`FrameResult::motion`] of the last
    /// frame that had one ([`RelativeMotion::identity`] before): the tracking's first guess,
    /// and the pose step of a frame that falls back.
    pub fn process(
        &mut self,
        left: &GrayImage,
        right: &GrayImage,
        prediction: &RelativeMotion,
    ) -> FrameResult {
        let start = Instant::now();
        let mut timings = StageTimings::default();
        let mut counts = FrameCounts::default();
        let index = self.index;
        self.index += 1;
        let expected = (self.rig.left.width as usize, self.rig.left.height as usize);
        let left_size = (left.width(), left.height());
        let right_size = (right.width(), right.height());
        if left_size != expected || right_size != expected {
            self.prev = None;
            let reason = FailReason::ImageSize {
                expected,
                left: left_size,
                right: right_size,
            };
            return self.fallback(index, (reason, prediction), (counts, timings), start);
        }
        let t = Instant::now();
        let (pl, pr) = self.pyramids(left, right);
        timings.pyramid_ms = ms(t);

        // tracking, estimation and carrying the tracks (they need t-1) beside the corner
        // detection at t; the window adjustment follows, beside the new corners' matching: it
        // only uses tracks seen in two frames or more, so the new corners cannot change it
        let prev = self.prev.take();
        let mut window = std::mem::take(&mut self.window);
        let (tracked, (corners, corners_ms)) = rayon::join(
            || self.track_and_carry(prev.as_ref(), (&pl, &pr), &mut window, prediction),
            || self.detect(&pl),
        );
        timings.tracking_ms = tracked.tracking_ms;
        timings.estimation_ms = tracked.estimation_ms;
        timings.corners_ms = corners_ms;
        counts = FrameCounts {
            detected: corners.len(),
            ..tracked.counts
        };
        let t = Instant::now();
        // the carried tracks with the gaps they leave for new corners
        let carried = match (&tracked.motion, prev.as_ref()) {
            (Ok(_), Some(_)) => tracked.carried.map(|c| {
                let gaps = self.gaps(&c);
                (c, gaps)
            }),
            _ => None,
        };
        // the window adjustment (it cannot see the new corners) beside the corners' matching
        let this = &*self;
        let (early, (detected_features, stereo_ms)) = rayon::join(
            || {
                tracked.early_pose.map(|window_pose| Early {
                    window_pose,
                    adjusted: window.adjust(
                        &this.rig,
                        &this.config.window,
                        this.config.covariance.scale(),
                    ),
                })
            },
            || {
                let t = Instant::now();
                let gaps = carried.as_ref().map(|(_, g)| g);
                let f = this.match_corners(&pl, &pr, &corners, gaps);
                (f, ms(t))
            },
        );
        self.window = window;
        counts.stereo_matched = detected_features.len();
        timings.stereo_ms = stereo_ms;
        let (motion, features, ids) = match (tracked.motion, prev.as_ref()) {
            (Ok((est, obs, _)), Some(_)) => {
                let (features, ids, carried) = self.fill_gaps(carried, detected_features);
                counts.carried = carried;
                (Ok((est, obs)), features, ids)
            }
            (Err(reason), _) => {
                let ids = self.fresh_ids(detected_features.len());
                (Err(reason), detected_features, ids)
            }
            (Ok(_), None) => {
                let ids = self.fresh_ids(detected_features.len());
                (Err(FailReason::NoPreviousFeatures), detected_features, ids)
            }
        };
        let first = prev.is_none();
        self.spare = prev.map(|p| (p.left, p.right));
        let state = FrameState {
            left: pl,
            right: pr,
            features,
            ids,
        };
        if first && index == 0 {
            return self.first_frame(state, (counts, timings), start);
        }
        match motion {
            Ok((est, obs)) => {
                let status = if est.low_speed {
                    FrameStatus::LowSpeed
                } else {
                    FrameStatus::Ok
                };
                let tracks = self.tracks(&est, &obs);
                let (prev_from_cur, motion, covariance) =
                    self.adjust(&est, state, &mut counts, early);
                let prev_from_cur_covariance = covariance.or_else(|| {
                    let w = &self.config.window;
                    let sigmas = (w.sigma_px, w.right_sigma_px);
                    let c = &self.config.covariance;
                    covariance::two_frame_covariance(&self.rig, &est, &obs, sigmas, c)
                });
                timings.window_ms = tracked.window_ms + ms(t);
                timings.total_ms = ms(start);
                FrameResult {
                    index,
                    status,
                    prev_from_cur,
                    motion: Some(motion),
                    prev_from_cur_covariance,
                    world_from_cam: self.world_from_cam,
                    counts,
                    timings,
                    median_translation_flow_px: est.median_translation_flow_px,
                    tracks,
                }
            }
            Err(reason) => {
                self.prev = Some(state);
                self.window.reset();
                self.fallback(index, (reason, prediction), (counts, timings), start)
            }
        }
    }

    /// The result of the first frame (its features in `state`): the identity pose, a new window.
    fn first_frame(
        &mut self,
        state: FrameState,
        (counts, mut timings): (FrameCounts, StageTimings),
        start: Instant,
    ) -> FrameResult {
        self.prev = Some(state);
        self.window.reset();
        timings.total_ms = ms(start);
        FrameResult::without_estimate(
            (0, FrameStatus::First),
            (Pose::identity(), self.world_from_cam),
            (counts, timings),
        )
    }

    /// The image pyramids of a stereo pair, both at once, rebuilt in the previous frame's
    /// spare pyramids when there are.
    fn pyramids(&mut self, left: &GrayImage, right: &GrayImage) -> (Pyramid, Pyramid) {
        let levels = self.config.klt.levels;
        let (spare_l, spare_r) = self.spare.take().unzip();
        let build = |spare: Option<Pyramid>, image: &GrayImage| match spare {
            Some(mut p) => {
                p.rebuild(image, levels);
                p
            }
            None => Pyramid::build(image, levels),
        };
        rayon::join(|| build(spare_l, left), || build(spare_r, right))
    }

    /// Fresh track ids for `n` new features.
    fn fresh_ids(&mut self, n: usize) -> Vec<u64> {
        let first = self.next_id;
        self.next_id += n as u64;
        (first..self.next_id).collect()
    }

    /// The part of a frame that needs t-1, run beside the detection ([`Self::process`]):
    /// tracking and estimation, then the inliers carried as persistent tracks and, when the
    /// window adjustment cannot see the new corners (`window.min_observations` ≥ 2), the window
    /// pushed with the carried tracks (adjusted next, beside the matching of the new corners:
    /// [`Early`]). `prediction` is the driver's constant-velocity model.
    fn track_and_carry(
        &self,
        prev: Option<&FrameState>,
        (pl, pr): (&Pyramid, &Pyramid),
        window: &mut TrackWindow,
        prediction: &RelativeMotion,
    ) -> Tracked {
        let Some(p) = prev else {
            return Tracked {
                motion: Err(FailReason::NoPreviousFeatures),
                counts: FrameCounts::default(),
                tracking_ms: 0.0,
                estimation_ms: 0.0,
                carried: None,
                early_pose: None,
                window_ms: 0.0,
            };
        };
        let (motion, counts, tracking_ms, estimation_ms) =
            self.track_and_estimate(p, (pl, pr), prediction);
        let t = Instant::now();
        let w = &self.config.window;
        let (carried, early_pose) = match &motion {
            Ok((est, obs, idx)) if w.persistent_tracks => {
                let carried: Vec<(StereoFeature, u64)> = obs
                    .par_iter()
                    .zip(&est.inliers)
                    .zip(idx)
                    .filter_map(|((o, &inlier), &i)| self.carry(p, (pl, pr), est, o, inlier, i))
                    .collect();
                let early_pose = (w.bundle_adjustment && w.min_observations >= 2).then(|| {
                    let (features, ids): (Vec<StereoFeature>, Vec<u64>) =
                        carried.iter().copied().unzip();
                    let window_pose = self.window_base(window) * est.motion.prev_from_cur();
                    window.push(window_pose, &ids, &features, w.window_frames);
                    window_pose
                });
                (Some(carried), early_pose)
            }
            _ => (None, None),
        };
        Tracked {
            motion,
            counts,
            tracking_ms,
            estimation_ms,
            carried,
            early_pose,
            window_ms: ms(t),
        }
    }

    /// The pose the window's newest frame is chained from: the last adjusted one, or the
    /// reported pose when the window starts afresh.
    fn window_base(&self, window: &TrackWindow) -> Pose {
        if window.is_empty() {
            self.world_from_cam
        } else {
            self.window_world_from_cam
        }
    }

    /// The gaps the `carried` tracks leave for new corners ([`window::Gaps`]: the corner
    /// buckets, `window.min_track_distance_px` around every track).
    fn gaps(&self, carried: &[(StereoFeature, u64)]) -> window::Gaps {
        let k = &self.config.corners;
        window::Gaps::new(
            carried.iter().map(|(f, _)| &f.left_px),
            (self.rig.left.width as usize, self.rig.left.height as usize),
            (k.bucket_cols, k.bucket_rows, k.max_per_bucket),
            self.config.window.min_track_distance_px,
        )
    }

    /// The features of the current frame for the next one: the `carried` tracks (`None`
    /// without persistent tracks) and the `detected` corners filling their gaps
    /// ([`window::fill_gaps`]); without persistent tracks the detected corners alone. Returns
    /// the features, their track ids and how many were carried.
    fn fill_gaps(
        &mut self,
        carried: Option<(Vec<(StereoFeature, u64)>, window::Gaps)>,
        detected: Vec<StereoFeature>,
    ) -> (Vec<StereoFeature>, Vec<u64>, usize) {
        let Some((carried, mut gaps)) = carried else {
            let ids = self.fresh_ids(detected.len());
            return (detected, ids, 0);
        };
        let (mut features, mut ids): (Vec<StereoFeature>, Vec<u64>) = carried.into_iter().unzip();
        let carried = ids.len();
        window::fill_gaps(
            &mut gaps,
            &mut features,
            &mut ids,
            &detected,
            &mut self.next_id,
        );
        (features, ids, carried)
    }

    /// The feature of t-1 behind observation `o` at t with its id, when it continues its track
    /// ([`Self::next_features`]).
    fn carry(
        &self,
        prev: &FrameState,
        (pl, pr): (&Pyramid, &Pyramid),
        est: &MotionEstimate,
        o: &Observation,
        inlier: bool,
        i: usize,
    ) -> Option<(StereoFeature, u64)> {
        let cfg = &self.config;
        let id = *prev.ids.get(i)?;
        let keep = if cfg.window.carry_consistent {
            estimate::reprojection_error(
                &self.rig,
                o,
                &est.motion.cur_from_prev(),
                cfg.use_right_reprojection,
            ) < cfg.consistency_limit_px
        } else {
            inlier
        };
        if !keep {
            return None;
        }
        let feature = if cfg.window.rematch_stereo {
            let matching = MatchConfig {
                refine_lk: cfg.matching.refine_lk || cfg.window.rematch_refine_lk,
                ..cfg.front_end_matching()
            };
            let f = match_feature(&self.rig, pl, pr, o.left_px, &matching, &cfg.klt)?;
            ((f.right_px.x - o.right_px.x).abs() < cfg.circular_tolerance_px).then_some(f)?
        } else {
            let disparity_px = o.left_px.x - o.right_px.x;
            let p = self.rig.triangulate(&o.left_px, disparity_px)?;
            StereoFeature {
                left_px: o.left_px,
                right_px: o.right_px,
                disparity_px,
                p_in_cam: p.coords,
            }
        };
        (feature.p_in_cam.z < cfg.max_depth_m).then_some((feature, id))
    }

    /// Applies the frame-to-frame estimate `est`, adds the frame to the window and adjusts it
    /// (when enabled; `early` when [`Self::process`] already did with the carried
    /// tracks, the new ones are then appended), ends the tracks the adjustment rejects and
    /// stores `state` for the next frame. Returns the reported `prev_from_cur` (from the pose
    /// reported for t-1), the motion to predict the next frame with (the estimate, or the
    /// adjusted step when the window was adjusted: [`FrameResult::motion`]) and, when the window
    /// was adjusted, its covariance.
    fn adjust(
        &mut self,
        est: &MotionEstimate,
        mut state: FrameState,
        counts: &mut FrameCounts,
        early: Option<Early>,
    ) -> (Pose, RelativeMotion, Option<Matrix6<f64>>) {
        // a copy: the offset measurement below changes the rig
        let w = &self.config.window.clone();
        let mut world_from_cam = self.world_from_cam * est.motion.prev_from_cur();
        let mut covariance = None;
        let mut motion = est.motion;
        if w.persistent_tracks && w.bundle_adjustment {
            let adjusted = match early {
                Some(e) => {
                    let carried = counts.carried;
                    self.window
                        .extend_newest(&state.ids[carried..], &state.features[carried..]);
                    self.window_world_from_cam = e.window_pose;
                    e.adjusted
                }
                None => {
                    let window_pose = self.window_base(&self.window) * est.motion.prev_from_cur();
                    self.window
                        .push(window_pose, &state.ids, &state.features, w.window_frames);
                    self.window_world_from_cam = window_pose;
                    self.window
                        .adjust(&self.rig, w, self.config.covariance.scale())
                }
            };
            if let Some(a) = adjusted {
                if let Some(offset) = a.right_cx_offset_px {
                    self.take_offset_measurement(offset, &mut state.features);
                }
                let adjusted_step = a.prev_world_from_cam.inverse() * a.world_from_cam;
                world_from_cam = if w.report_relative {
                    self.world_from_cam * adjusted_step
                } else {
                    a.world_from_cam
                };
                self.window_world_from_cam = a.world_from_cam;
                covariance = a.step_covariance;
                // (kept as the inverse it has always been computed from: a constant-velocity
                // fallback's `prev_from_cur` is its inverse again, bit for bit)
                motion = RelativeMotion::from_cur_from_prev(adjusted_step.inverse());
                counts.window_points = a.points;
                counts.window_outliers = a.outlier_ids.len();
                let keep: Vec<bool> = state
                    .ids
                    .iter()
                    .map(|id| !(w.drop_ba_outliers && a.outlier_ids.contains(id)))
                    .collect();
                if w.use_window_points {
                    for (f, id) in state.features.iter_mut().zip(&state.ids) {
                        if let Some(p) = self.window.point_in_newest(*id)
                            && p.z > 0.0
                            && p.z < self.config.max_depth_m
                        {
                            f.p_in_cam = p;
                        }
                    }
                }
                let mut k = keep.iter();
                state.features.retain(|_| k.next().copied().unwrap_or(true));
                let mut k = keep.iter();
                state.ids.retain(|_| k.next().copied().unwrap_or(true));
            }
        }
        self.prev = Some(state);
        // `W · (W⁻¹ · X)` squares the norm of W's quaternion (nalgebra inverts a unit
        // quaternion by conjugation): keep the reported pose on the unit sphere
        world_from_cam.rotation =
            UnitQuaternion::new_normalize(world_from_cam.rotation.into_inner());
        let prev_from_cur = self.world_from_cam.inverse() * world_from_cam;
        self.world_from_cam = world_from_cam;
        (prev_from_cur, motion, covariance)
    }

    /// Moves the rig's disparity offset towards a window adjustment's measurement (running mean
    /// over `window.offset_horizon_frames`) and the points of `features`, triangulated with the
    /// offset before, to the depths their disparities have now.
    fn take_offset_measurement(&mut self, measured_px: f64, features: &mut [StereoFeature]) {
        let w = &self.config.window;
        if measured_px.is_nan() || measured_px.abs() > w.max_right_cx_offset_px {
            return;
        }
        self.offset_measurements += 1;
        let n = self.offset_measurements.min(w.offset_horizon_frames) as f64;
        let before = self.rig;
        let offset = before.right_cx_offset_px + (measured_px - before.right_cx_offset_px) / n;
        self.rig = before.with_right_cx_offset(offset);
        log::debug!(
            "stereo frame {}: disparity offset measured {measured_px:.4} px, now {offset:.4}",
            self.index
        );
        for f in features {
            let z = f.p_in_cam.z;
            if z <= 0.0 {
                continue;
            }
            // the disparity the point was triangulated from, at the depth it has now
            if let Some(z_now) = self
                .rig
                .depth_from_disparity(before.disparity_from_depth(z))
            {
                f.p_in_cam *= z_now / z;
            }
        }
    }

    /// The result of a frame that falls back (`reason`) to the driver's constant-velocity
    /// `prediction` (the identity at the first frame), with the `counts` and `timings` it got.
    fn fallback(
        &mut self,
        index: usize,
        (reason, prediction): (FailReason, &RelativeMotion),
        (counts, mut timings): (FrameCounts, StageTimings),
        start: Instant,
    ) -> FrameResult {
        let prev_from_cur = if index == 0 {
            Pose::identity()
        } else {
            prediction.prev_from_cur()
        };
        self.world_from_cam *= prev_from_cur;
        timings.total_ms = ms(start);
        log::warn!("stereo frame {index}: constant-velocity fallback ({reason:?})");
        FrameResult::without_estimate(
            (index, FrameStatus::Fallback(reason)),
            (prev_from_cur, self.world_from_cam),
            (counts, timings),
        )
    }

    /// The tracks of an estimate (`obs` are the observations it was computed from).
    fn tracks(&self, est: &MotionEstimate, obs: &[Observation]) -> Vec<Track> {
        obs.iter()
            .zip(&est.inliers)
            .filter_map(|(o, &inlier)| {
                let prev_left_px = self
                    .rig
                    .left
                    .project(&nalgebra::Point3::from(o.p_in_prev))?;
                let q = est.motion.cur_from_prev() * nalgebra::Point3::from(o.p_in_prev);
                Some(Track {
                    prev_left_px,
                    left_px: o.left_px,
                    depth_m: q.z,
                    inlier,
                })
            })
            .collect()
    }

    /// Shi–Tomasi corners of the current left image: (corners, ms).
    fn detect(&self, pl: &Pyramid) -> (Vec<Corner>, f64) {
        let t = Instant::now();
        let corners = detect_corners(pl.base(), &self.config.corners);
        (corners, ms(t))
    }

    /// The SAD stereo features of the `corners` (in their order) that can join the next frame's
    /// features: every corner when the frame starts afresh (`gaps` is `None`), else only those
    /// filling one of the carried tracks' `gaps` (the others would be refused by
    /// [`Self::fill_gaps`] whatever their match, so they are not matched).
    fn match_corners(
        &self,
        pl: &Pyramid,
        pr: &Pyramid,
        corners: &[Corner],
        gaps: Option<&window::Gaps>,
    ) -> Vec<StereoFeature> {
        let max_z = self.config.max_depth_m;
        let matching = self.config.front_end_matching();
        corners
            .par_iter()
            .filter(|c| gaps.is_none_or(|g| g.admits(&c.px)))
            .filter_map(|c| match_feature(&self.rig, pl, pr, c.px, &matching, &self.config.klt))
            .filter(|f| f.p_in_cam.z < max_z)
            .collect()
    }
}
