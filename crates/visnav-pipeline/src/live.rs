//! A live run: the monocular odometry over a [`LiveSource`] (a camera or a network stream,
//! `visnav_io::live`), set up from the same [`RunSpec`] as a recording, frames pushed as the
//! frame policy hands them over, until the stream ends or the stop flag is set.
//!
//! ```text
//!  RunSpec + LiveConfig ── prepare_live() ──► LiveRun ── drive_with(callback per frame)
//!                                                    ──► DrivenRun ── finish() ──► RunOutcome
//! ```
//!
//! A live run has no frame count: the report's `input_frames` is the frames received, its
//! `dropped_frames` those the policy dropped, `live` the stream's figures. Timestamps are the
//! stream's (`visnav_io::live`); the monocular prediction spans the true time step after dropped
//! frames (`FrameInput::dropped_before`). Loop closure, the palindrome and stereo need a
//! recording (random access to earlier frames, a second camera) and are refused.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use visnav_io::live::{FramePolicy, LiveConfig, LiveSource};

use crate::job::{DrivenRun, JobError, RunOutcome, RunSpec, drive_items};
pub use crate::report::LiveSummary;
use crate::report::RunReport;
use crate::{Arrival, Control, FrameResult, Mode, Odometry, Outputs, RunConfig};

/// A live run ready to drive.
pub struct LiveRun {
    /// The stream.
    pub source: LiveSource,
    /// The odometry.
    pub odometry: Odometry,
    /// The effective configuration.
    pub config: RunConfig,
    /// The frame policy.
    pub policy: FramePolicy,
}

impl RunSpec {
    /// Opens the live input (`sequence`, [`visnav_io::live::LiveInput`]) with its camera file,
    /// waits for its first frame and builds the monocular odometry, not pipelined: a pipelined
    /// odometry returns a frame's pose only once the next frame is pushed, which adds a camera
    /// interval (or a whole odometry cycle when frames are dropped) to every pose's latency;
    /// the poses are the same (`Odometry::pipelined`). `stop` ends the stream when set (Ctrl-C).
    ///
    /// # Errors
    /// [`JobError::Input`] for stereo, loop closure, palindrome or bag topics;
    /// [`JobError::OpenSequence`] for a stream that cannot be read (no camera file, ffmpeg
    /// missing, unreachable, wrong frame size); an invalid configuration.
    pub fn prepare_live(
        &self,
        live: &LiveConfig,
        stop: Arc<AtomicBool>,
        outputs: Outputs,
    ) -> Result<LiveRun, JobError> {
        let refused: &[(bool, &str)] = &[
            (
                self.mode == Mode::Stereo,
                "--mode stereo (a live input is one camera: --mode mono)",
            ),
            (
                self.loop_closure,
                "loop closure (it reloads earlier frames: record the stream first)",
            ),
            (
                self.palindrome,
                "the palindrome (it plays the frames back: record the stream first)",
            ),
            (
                self.topic.is_some() || self.right_topic.is_some(),
                "bag topics",
            ),
        ];
        if let Some((_, what)) = refused.iter().find(|(set, _)| *set) {
            return Err(JobError::Input(format!(
                "{}: a live input does not support {what}",
                self.sequence.display()
            )));
        }
        self.check_mode_fields()?;
        let config = self.mono_config()?;
        let source = LiveSource::open(&self.sequence, self.camera.as_deref(), live, stop).map_err(
            |source| JobError::OpenSequence {
                path: self.sequence.clone(),
                source,
            },
        )?;
        let odometry = Odometry::mono(source.camera(), &config)?
            .with_outputs(outputs)
            .pipelined(false);
        Ok(LiveRun {
            source,
            odometry,
            config: RunConfig::Mono(Box::new(config)),
            policy: live.policy,
        })
    }
}

impl LiveRun {
    /// Pushes the stream's frames until it ends, the stop flag is set, `max_frames` frames are
    /// processed or `on_frame` stops the run; `on_frame` gets each result with its arrival.
    /// `interrupted` is true when the stream had not ended by itself.
    ///
    /// # Errors
    /// The first error of `on_frame` (the run stops after that frame).
    pub fn drive_with<E>(
        &mut self,
        max_frames: Option<usize>,
        on_frame: impl FnMut(&FrameResult, &Arrival) -> Result<Control, E>,
    ) -> Result<DrivenRun, E> {
        let frames = (&mut self.source).take(max_frames.unwrap_or(usize::MAX));
        let mut driven = drive_items(&mut self.odometry, frames, on_frame)?;
        driven.interrupted = self.source.end_reason().is_none()
            && max_frames.is_none_or(|m| driven.per_frame.len() < m);
        Ok(driven)
    }

    /// The poses and the report of a driven run.
    #[must_use]
    pub fn finish(&self, spec: &RunSpec, driven: DrivenRun) -> RunOutcome {
        let stats = self.source.stats();
        let poses = self.odometry.trajectory().to_vec();
        let mut report = RunReport::new(
            spec.sequence.clone(),
            self.config.clone(),
            stats.frames_received,
            driven.per_frame,
            driven.wall_s,
        );
        report.interrupted = driven.interrupted;
        report.live = Some(LiveSummary {
            policy: self.policy,
            frames_received: stats.frames_received,
            frames_dropped: stats.frames_dropped,
            reconnects: stats.reconnects,
            timestamps: stats.timestamps,
            end: self.source.end_reason(),
        });
        RunOutcome {
            odometry_poses: poses.clone(),
            poses,
            report,
        }
    }
}
