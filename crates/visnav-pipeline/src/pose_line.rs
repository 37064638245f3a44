//! One pose as it happens: the JSON line `visnav odometry --poses-out` writes for every frame.

use serde::{Deserialize, Serialize};

use crate::{Arrival, FrameResult, Status};

/// One frame's pose for a consumer downstream (one JSON object a line). Fields are added, never
/// renamed (a consumer ignores the ones it does not know).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseLine {
    /// Position in the run (0 = the first frame processed).
    pub step: usize,
    /// The frame's index in the input (a live stream counts its dropped frames too).
    pub index: usize,
    /// The frame's timestamp, seconds (a live stream's from its first frame).
    pub timestamp_s: Option<f64>,
    /// `world_from_cam` (world = the first camera), 3x4 row-major: rotation | translation in
    /// metres.
    pub world_from_cam: [[f64; 4]; 3],
    /// Outcome (`status`, and `reason` for a fallback or a skip).
    #[serde(flatten)]
    pub status: Status,
    /// From the frame's arrival to this pose, milliseconds.
    pub latency_ms: f64,
    /// Frames of a live stream dropped just before this one.
    pub dropped_before: usize,
    /// The 6x6 covariance of the step from the previous pose, row by row
    /// ([`FrameResult::prev_from_cur_covariance`]: a right perturbation in this frame's camera,
    /// x, y, z, rotation about x, y, z; metres and radians); `null` for a frame without an
    /// estimate of its own (the first, a fallback, a skip) and for mono, which has none yet.
    #[serde(default)]
    pub prev_from_cur_covariance: Option<[[f64; 6]; 6]>,
}

impl PoseLine {
    /// The line of a result and its arrival.
    #[must_use]
    pub fn new(r: &FrameResult, arrival: &Arrival) -> Self {
        let m = r.world_from_cam.to_homogeneous();
        let row = |i: usize| [m[(i, 0)], m[(i, 1)], m[(i, 2)], m[(i, 3)]];
        Self {
            step: r.position,
            index: arrival.index,
            timestamp_s: r.timestamp_s,
            world_from_cam: [row(0), row(1), row(2)],
            status: r.status.clone(),
            latency_ms: arrival.latency_ms,
            dropped_before: arrival.dropped_before,
            prev_from_cur_covariance: r
                .prev_from_cur_covariance
                .map(|c| crate::report::rows_of(&c)),
        }
    }

    /// The line as compact JSON, without the newline.
    ///
    /// # Errors
    /// A message when serialisation fails (a non-finite number).
    pub fn to_json(&self) -> Result<String, String> {
        serde_json::to_string(self).map_err(|e| e.to_string())
    }
}
