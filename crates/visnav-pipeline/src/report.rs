//! The run report: one typed record of a run (`Serialize + Deserialize`), written by
//! `visnav odometry --json` and read back by `visnav report` through the same type.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use visnav_eval::palindrome::PalindromeDrift;
use visnav_io::live::{FramePolicy, TimestampOrigin};
use visnav_loop::ClosureReport;
use visnav_odometry::mono::PoseSource;

use crate::{Detail, FrameResult, FrameTimings, Mode, RunConfig, Status};

/// One frame of the run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Position in the run (differs from `index` on the way back of a palindrome).
    pub step: usize,
    /// Frame of the sequence.
    pub index: usize,
    /// Timestamp, seconds, when the input has one.
    pub timestamp_s: Option<f64>,
    /// Outcome (`status`, and `reason` for a fallback or a skip).
    #[serde(flatten)]
    pub status: Status,
    /// Translation length of the step, metres.
    pub step_m: f64,
    /// The 6x6 covariance of the step `prev_from_cur` ([`FrameResult::prev_from_cur_covariance`]:
    /// right perturbation in this frame's camera, x, y, z, rotation about x, y, z; metres and
    /// radians), row by row; `null` for a frame without an estimate of its own.
    #[serde(default)]
    pub prev_from_cur_covariance: Option<[[f64; 6]; 6]>,
    /// Figures of the estimation.
    pub detail: Detail,
    /// Time per stage inside the odometry.
    pub timings: FrameTimings,
    /// Time the run waited for the frame's images (decoding runs ahead on a thread).
    pub wait_ms: f64,
    /// Time spent writing the frame's files.
    pub save_ms: f64,
    /// From the frame's arrival (a live frame out of the decoder, a recorded one loaded) to
    /// its pose, milliseconds.
    #[serde(default)]
    pub latency_ms: Option<f64>,
    /// Frames of a live stream dropped just before this one (the frame policy `newest`).
    #[serde(default)]
    pub dropped_before: usize,
}

impl FrameRecord {
    /// The record of a result (`index`: the frame of the sequence).
    #[must_use]
    pub fn new(r: &FrameResult, index: usize, wait_ms: f64, save_ms: f64) -> Self {
        Self {
            step: r.position,
            index,
            timestamp_s: r.timestamp_s,
            status: r.status.clone(),
            step_m: r.step_m(),
            prev_from_cur_covariance: r.prev_from_cur_covariance.map(|c| rows_of(&c)),
            detail: r.detail,
            timings: r.timings,
            wait_ms,
            save_ms,
            latency_ms: None,
            dropped_before: 0,
        }
    }

    /// The record with the frame's latency and the frames dropped before it.
    #[must_use]
    pub fn with_arrival(mut self, arrival: &crate::Arrival) -> Self {
        self.latency_ms = Some(arrival.latency_ms);
        self.dropped_before = arrival.dropped_before;
        self
    }
}

/// The latency from a frame's arrival to its pose over a run, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LatencySummary {
    /// Median.
    pub median_ms: f64,
    /// 95th percentile (nearest rank).
    pub p95_ms: f64,
    /// Largest.
    pub max_ms: f64,
}

impl LatencySummary {
    /// The summary of the frames' latencies, `None` when no frame has one.
    #[must_use]
    pub fn of(frames: &[FrameRecord]) -> Option<Self> {
        let mut ms: Vec<f64> = frames.iter().filter_map(|r| r.latency_ms).collect();
        if ms.is_empty() {
            return None;
        }
        ms.sort_by(f64::total_cmp);
        let rank = |q: f64| ms[((q * ms.len() as f64).ceil() as usize).clamp(1, ms.len()) - 1];
        Some(Self {
            median_ms: rank(0.5),
            p95_ms: rank(0.95),
            max_ms: ms[ms.len() - 1],
        })
    }
}

/// The rows of a 6x6 matrix.
#[must_use]
pub fn rows_of(m: &nalgebra::Matrix6<f64>) -> [[f64; 6]; 6] {
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// Frames per pose source (mono).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SourceCounts {
    /// Eight-point with the estimated scale.
    pub eight_point: usize,
    /// PnP on the previous depth map.
    pub pnp: usize,
    /// Average of both.
    pub fused: usize,
    /// Constant-velocity prediction.
    pub constant_velocity: usize,
}

/// The loop-closure part of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoopClosureSummary {
    /// The odometry-only trajectory file, when written.
    pub odometry_output: Option<PathBuf>,
    /// Palindrome drift of the odometry-only trajectory.
    pub odometry_palindrome: Option<PalindromeDrift>,
    /// Closures that entered the pose graph.
    pub accepted: usize,
    /// Verified candidates rejected.
    pub rejected: usize,
    /// Accepted closures the robust pose graph set aside.
    pub rejected_by_graph: usize,
    /// Pose-graph optimisations.
    pub optimisations: usize,
    /// Every verified candidate.
    pub closures: Vec<ClosureReport>,
}

impl LoopClosureSummary {
    /// The summary of a loop closer's state.
    #[must_use]
    pub fn of(closer: &visnav_loop::LoopCloser) -> Self {
        let closures = closer.closures();
        let accepted = closures.iter().filter(|r| r.accepted).count();
        Self {
            odometry_output: None,
            odometry_palindrome: None,
            accepted,
            rejected: closures.len() - accepted,
            rejected_by_graph: closures.iter().filter(|r| r.rejected_by_graph).count(),
            optimisations: closer.optimisations(),
            closures,
        }
    }
}

/// Mean time per frame over the run, milliseconds.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MeanTimings {
    /// Every stage (see [`FrameTimings::stages`]).
    pub stages: BTreeMap<String, f64>,
    /// The dense flow (mono).
    pub flow_ms: f64,
    /// Waiting for the flow (the part not hidden behind the previous frame's odometry).
    pub flow_wait_ms: f64,
    /// The odometry stages (mono or stereo total).
    pub odometry_ms: f64,
    /// The whole frame inside the odometry.
    pub frame_ms: f64,
    /// Waiting for the decoded images.
    pub wait_ms: f64,
    /// Writing the frame's files.
    pub save_ms: f64,
    /// Wall time of the run divided by its frames.
    pub wall_ms_per_frame: f64,
}

impl MeanTimings {
    /// Means over `frames` with the run's wall time.
    #[must_use]
    pub fn over(frames: &[FrameRecord], wall_s: f64) -> Self {
        let nf = frames.len().max(1) as f64;
        let mean = |f: &dyn Fn(&FrameRecord) -> f64| frames.iter().map(f).sum::<f64>() / nf;
        let mut stages = BTreeMap::new();
        for r in frames {
            for (name, ms) in r.timings.stages() {
                *stages.entry(name.to_owned()).or_insert(0.0) += ms / nf;
            }
        }
        Self {
            stages,
            flow_ms: mean(&|r| r.timings.flow.map_or(0.0, |f| f.total_ms)),
            flow_wait_ms: mean(&|r| r.timings.flow_wait_ms),
            odometry_ms: mean(&|r| {
                r.timings.mono.map_or(0.0, |m| m.total_ms)
                    + r.timings.stereo.map_or(0.0, |s| s.total_ms)
            }),
            frame_ms: mean(&|r| r.timings.total_ms),
            wait_ms: mean(&|r| r.wait_ms),
            save_ms: mean(&|r| r.save_ms),
            wall_ms_per_frame: wall_s * 1e3 / nf,
        }
    }
}

/// The report of one odometry run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// The input (absolute path when it could be resolved).
    pub sequence: PathBuf,
    /// Which odometry.
    pub mode: Mode,
    /// Poses written (`2N − 1` for a palindrome).
    pub frames: usize,
    /// Input frames `N`.
    pub input_frames: usize,
    /// `true` when the run was stopped (Ctrl-C) before its last frame.
    pub interrupted: bool,
    /// Frames estimated normally.
    pub ok_frames: usize,
    /// Frames with little motion (mono low parallax, stereo low speed).
    pub low_parallax_frames: usize,
    /// Frames the pipeline could not estimate (constant-velocity prediction).
    pub failed_frames: usize,
    /// Frames without usable images (constant-velocity prediction).
    pub skipped_frames: usize,
    /// Frames of a live stream dropped by the frame policy (never given to the odometry).
    #[serde(default)]
    pub dropped_frames: usize,
    /// Latency from a frame's arrival to its pose.
    #[serde(default)]
    pub latency: Option<LatencySummary>,
    /// A live input's figures (`None` for recordings).
    #[serde(default)]
    pub live: Option<LiveSummary>,
    /// Frames per pose source (mono).
    pub sources: Option<SourceCounts>,
    /// Palindrome drift (mono `--palindrome`).
    pub palindrome: Option<PalindromeDrift>,
    /// Loop closure (mono `--loop-closure`).
    pub loop_closure: Option<LoopClosureSummary>,
    /// Wall time of the run, seconds.
    pub wall_s: f64,
    /// Mean times per frame.
    pub mean: MeanTimings,
    /// The effective configuration.
    pub config: RunConfig,
    /// Every frame.
    pub per_frame: Vec<FrameRecord>,
}

impl RunReport {
    /// A report with the counts and means computed from `per_frame`.
    #[must_use]
    pub fn new(
        sequence: PathBuf,
        config: RunConfig,
        input_frames: usize,
        per_frame: Vec<FrameRecord>,
        wall_s: f64,
    ) -> Self {
        let count = |f: &dyn Fn(&FrameRecord) -> bool| per_frame.iter().filter(|r| f(r)).count();
        let mode = match config {
            RunConfig::Mono(_) => Mode::Mono,
            RunConfig::Stereo(_) | RunConfig::StereoLoop(_) => Mode::Stereo,
        };
        let source =
            |s: PoseSource| count(&|r| matches!(r.detail, Detail::Mono(m) if m.source == s));
        let sources = (mode == Mode::Mono).then(|| SourceCounts {
            eight_point: source(PoseSource::EightPoint),
            pnp: source(PoseSource::Pnp),
            fused: source(PoseSource::Fused),
            constant_velocity: count(&|r| r.status.is_predicted()),
        });
        Self {
            sequence,
            mode,
            frames: per_frame.len(),
            input_frames,
            interrupted: false,
            ok_frames: count(&|r| r.status == Status::Ok),
            low_parallax_frames: count(&|r| r.status == Status::LowParallax),
            failed_frames: count(&|r| matches!(r.status, Status::Fallback { .. })),
            skipped_frames: count(&|r| matches!(r.status, Status::Skipped { .. })),
            dropped_frames: per_frame.iter().map(|r| r.dropped_before).sum(),
            latency: LatencySummary::of(&per_frame),
            live: None,
            sources,
            palindrome: None,
            loop_closure: None,
            wall_s,
            mean: MeanTimings::over(&per_frame, wall_s),
            config,
            per_frame,
        }
    }

    /// Reads a report written by [`RunReport::to_json`].
    ///
    /// # Errors
    /// A message naming the file and the problem (unreadable, not a run report).
    pub fn read(path: &Path) -> Result<Self, String> {
        let text = visnav_io::text::read_text(path).map_err(|e| e.to_string())?;
        serde_json::from_str(&text).map_err(|e| {
            format!(
                "{}: not a visnav run report (visnav odometry --json): {e}",
                path.display()
            )
        })
    }

    /// The report as pretty JSON.
    ///
    /// # Errors
    /// A message when serialisation fails.
    pub fn to_json(&self) -> Result<String, String> {
        serde_json::to_string_pretty(self).map_err(|e| e.to_string())
    }
}

/// A live input's figures in the run report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LiveSummary {
    /// The frame policy.
    pub policy: FramePolicy,
    /// Frames read from the stream.
    pub frames_received: usize,
    /// Frames the policy dropped.
    pub frames_dropped: usize,
    /// Reconnections after a lost stream.
    pub reconnects: usize,
    /// Where the timestamps came from.
    pub timestamps: TimestampOrigin,
    /// Why the stream ended, when it ended by itself.
    pub end: Option<String>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A report written before the step covariance existed reads as frames without one; a
    /// covariance goes out and comes back row by row.
    #[test]
    fn the_step_covariance_round_trips_and_is_optional() {
        let mut cov = [[0.0; 6]; 6];
        for (r, row) in cov.iter_mut().enumerate() {
            row[r] = 1e-4 * (r + 1) as f64;
        }
        row_check(&cov);
        let record = FrameRecord {
            step: 1,
            index: 1,
            timestamp_s: Some(0.1),
            status: Status::Ok,
            step_m: 1.0,
            prev_from_cur_covariance: Some(cov),
            detail: Detail::None,
            timings: FrameTimings::default(),
            wait_ms: 0.0,
            save_ms: 0.0,
            latency_ms: None,
            dropped_before: 0,
        };
        let mut value = serde_json::to_value(&record).unwrap();
        let back: FrameRecord = serde_json::from_value(value.clone()).unwrap();
        assert_eq!(back, record);
        value
            .as_object_mut()
            .unwrap()
            .remove("prev_from_cur_covariance");
        let old: FrameRecord = serde_json::from_value(value).unwrap();
        assert_eq!(old.prev_from_cur_covariance, None);
    }

    fn row_check(cov: &[[f64; 6]; 6]) {
        let m = nalgebra::Matrix6::from_fn(|r, c| cov[r][c]);
        assert_eq!(&rows_of(&m), cov);
    }
}
