//! The window bundle adjustment's problem: its configuration, data, report and errors, and the
//! Huber kernel (the solver is `WindowBa::solve` in the parent module, the Schur complement in
//! `schur`).

use nalgebra::{Point2, Point3};
use serde::{Deserialize, Serialize};
use visnav_core::{Pose, StereoCamera};

/// Parameters of the window bundle adjustment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BaConfig {
    /// Frames at the start of the window held fixed (gauge and link to the past). Default 1.
    pub fixed_frames: usize,
    /// Huber threshold on the whitened residual norm (pixels at unit sigma). Default 2.0.
    pub huber_px: f64,
    /// Largest number of Levenberg–Marquardt iterations a round. Default 10.
    pub max_iterations: usize,
    /// Rounds of solving; observations beyond `outlier_chi2` are dropped between rounds.
    /// Default 2.
    pub rounds: usize,
    /// Whitened squared error beyond which an observation is an outlier after a round
    /// (χ² with 3 degrees of freedom at 95 %: 7.815). Default 7.815.
    pub outlier_chi2: f64,
    /// Initial damping, relative to the mean diagonal of the reduced system. Default 1e-4.
    pub initial_lambda: f64,
    /// Stop when the relative cost decrease of an accepted step is below this. Default 1e-6.
    pub min_relative_decrease: f64,
    /// Estimate the rig's right principal-point offset ([`StereoCamera::right_cx_offset_px`],
    /// one unknown shared by the window, from the right observations) with the poses and
    /// points. Default false.
    pub estimate_right_cx_offset: bool,
}

impl Default for BaConfig {
    fn default() -> Self {
        Self {
            fixed_frames: 1,
            huber_px: 2.0,
            max_iterations: 10,
            rounds: 2,
            outlier_chi2: 7.815,
            initial_lambda: 1e-4,
            min_relative_decrease: 1e-6,
            estimate_right_cx_offset: false,
        }
    }
}

/// One observation of a point in a window frame (rectified stereo pixels).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Window frame index.
    pub frame: usize,
    /// Point index.
    pub point: usize,
    /// Left-image pixel.
    pub left_px: Point2<f64>,
    /// Right-image column (same row, rectified), when matched.
    pub right_u_px: Option<f64>,
    /// Standard deviation of each pixel coordinate, pixels.
    pub sigma_px: f64,
    /// Standard deviation of the right column, pixels (the disparity's noise).
    pub right_sigma_px: f64,
}

/// The unknowns and data of one window.
#[derive(Debug, Clone)]
pub struct WindowBa {
    /// The rectified rig.
    pub rig: StereoCamera,
    /// `cam_from_world` of each window frame (the first `fixed_frames` are not changed).
    pub cam_from_world: Vec<Pose>,
    /// World positions of the points, metres.
    pub points_w: Vec<Point3<f64>>,
    /// The observations.
    pub observations: Vec<Observation>,
}

/// What a solve did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BaReport {
    /// Robust cost (½ Σ ρ(‖r̃‖²)) before, all observations.
    pub initial_cost: f64,
    /// Robust cost after, the observations kept in the last round.
    pub final_cost: f64,
    /// Levenberg–Marquardt iterations (accepted or not).
    pub iterations: usize,
    /// Observations beyond `outlier_chi2` at the end (dropped, or found in the last round).
    pub outliers: usize,
}

/// Why a window cannot be adjusted.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BaError {
    /// An observation names a frame or point that does not exist.
    #[error("observation {index} refers to frame {frame} / point {point} outside the window")]
    BadIndex {
        /// Observation index.
        index: usize,
        /// Its frame.
        frame: usize,
        /// Its point.
        point: usize,
    },
    /// Nothing to adjust: every frame is fixed or there are no observations.
    #[error("nothing to adjust ({frames} frames, {fixed} fixed, {observations} observations)")]
    Empty {
        /// Frames.
        frames: usize,
        /// Fixed frames.
        fixed: usize,
        /// Observations.
        observations: usize,
    },
}

/// Huber's ρ of a squared norm `s` with threshold `k`: `s` inside, `2k√s − k²` outside.
#[must_use]
pub fn huber_rho(s: f64, k: f64) -> f64 {
    if s <= k * k {
        s
    } else {
        2.0 * k * s.sqrt() - k * k
    }
}

/// The IRLS weight `ρ′(s)` of Huber's kernel: 1 inside, `k/√s` outside.
#[must_use]
pub fn huber_weight(s: f64, k: f64) -> f64 {
    if s <= k * k { 1.0 } else { k / s.sqrt() }
}
