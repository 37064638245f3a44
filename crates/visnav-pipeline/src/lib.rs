//! The streaming odometry of visnav: build an [`Odometry`] for a mono camera or a stereo rig,
//! push frames one at a time, get a [`FrameResult`] per frame.
//!
//! ```text
//!  FrameSource ──► Prefetch ──► FrameInput ──► Odometry::push ──► FrameResult ──► front end
//!  (visnav-io:      (thread)      (images or      │                 (pose, status,   (CLI files,
//!   KITTI, EuRoC,                  Missing)        │                  timings, flow,   Python,
//!   TUM, folders,                                  │                  depth, tracks)   report)
//!   video, memory)                                 ▼
//!                          mono:  flow (ahead thread) ─► MonoOdometry ─► LoopCloser (optional)
//!                          stereo: StereoOdometry (RotROCC) ─► LoopCloser (optional)
//! ```
//!
//! The [`Odometry`] owns everything every user of a VO library needs besides the estimators:
//! the failure policy (see `src/mono.rs` and `src/stereo.rs`: a frame that
//! cannot be estimated or has no images gets the constant-velocity prediction and a status, so
//! there is exactly one pose per pushed frame), which image the next frame is matched against,
//! the trajectory so far, the optional loop closure, and the pipelining of the dense flow with
//! the odometry (`src/ahead.rs`, the only threads here).
//!
//! Relative motions follow one convention everywhere: `prev_from_cur`, with
//! `world_from_cur = world_from_prev · prev_from_cur`.
//!
//! A monocular odometry over a few frames of a rendered drive (exact ground truth from
//! `visnav-synth`), one result per frame pushed:
//!
//! ```
//! use visnav_pipeline::{FrameInput, MonoRunConfig, Odometry};
//! use visnav_synth::{Scene, drive_trajectory, kitti_like_camera, render_view};
//!
//! let truth = drive_trajectory(4, 2); // world_from_cam of 4 frames, metres
//! let scene = Scene::along(&truth, 2).unwrap();
//! let camera = kitti_like_camera(320, 96);
//! let mut config = MonoRunConfig::default(); // the paper's defaults
//! config.mono.scale.camera_height_m = scene.config().ground_depth_m;
//! let mut odometry = Odometry::mono(camera, &config).unwrap();
//! let mut results = Vec::new();
//! for world_from_cam in &truth {
//!     let image = render_view(&scene, &camera, world_from_cam).image;
//!     results.extend(odometry.process(FrameInput::mono(image, None)));
//! }
//! assert_eq!(results.len(), 4);
//! assert_eq!(odometry.trajectory().len(), 4);
//! // the camera drives forward along its z axis: the last pose is ahead of the first
//! let (first, last) = (&results[0].world_from_cam, &results[3].world_from_cam);
//! let true_m = (truth[3].translation.vector - truth[0].translation.vector).norm();
//! let estimated_m = (last.translation.vector - first.translation.vector).norm();
//! assert!(last.translation.z > first.translation.z);
//! assert!((estimated_m / true_m - 1.0).abs() < 0.2, "{estimated_m} m for {true_m} m");
//! ```
//!
//! [`run_source`] drives an odometry over a [`visnav_io::FrameSource`]; [`report`] is the typed run
//! report the CLI writes (`visnav odometry --json`) and reads back (`visnav report`).

mod ahead;
mod config;
mod frame;
pub mod job;
pub mod live;
mod mono;
mod pose_line;
pub mod report;
mod run;
mod stereo;

use std::collections::HashMap;

use visnav_core::{GrayImage, PinholeCamera, Pose, StereoCamera};
use visnav_odometry::stereo::StereoConfig;

pub use config::{Mode, MonoRunConfig, Preset, RunConfig, StereoLoopConfig};
pub use frame::{
    Detail, FallbackReason, FrameInput, FrameResult, FrameTimings, Images, MonoDetail, Outputs,
    Status, StereoDetail,
};
pub use pose_line::PoseLine;
pub use run::{Arrival, Control, run_items, run_source};
pub use stereo::feature_depth_map;

/// Errors of building an odometry (per-frame problems are a [`Status`], never an error).
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The monocular configuration is invalid.
    #[error(transparent)]
    Mono(#[from] visnav_odometry::mono::MonoError),
    /// The stereo configuration is invalid.
    #[error(transparent)]
    Stereo(#[from] visnav_odometry::stereo::StereoError),
    /// The loop-closure configuration is invalid.
    #[error(transparent)]
    Loop(#[from] visnav_loop::LoopError),
    /// The input does not fit the mode.
    #[error("{0}")]
    Input(String),
}

/// Where the loop closer gets earlier images back for verification (by stream position).
pub trait ImageStore: Send {
    /// Called with every accepted image as it passes (a store that can reload images from disk
    /// ignores it).
    fn keep(&mut self, position: usize, image: &GrayImage);
    /// The image at `position`.
    ///
    /// # Errors
    /// A message when the image is not available.
    fn image(&mut self, position: usize) -> Result<GrayImage, String>;
}

/// Keeps every image in memory (the default store: fine for short runs; long runs from disk
/// should reload images instead, see [`SourceStore`]).
#[derive(Debug, Default)]
pub struct MemoryStore {
    images: HashMap<usize, GrayImage>,
}

impl ImageStore for MemoryStore {
    fn keep(&mut self, position: usize, image: &GrayImage) {
        self.images.insert(position, image.clone());
    }
    fn image(&mut self, position: usize) -> Result<GrayImage, String> {
        self.images
            .get(&position)
            .cloned()
            .ok_or_else(|| format!("no image at position {position}"))
    }
}

/// Reloads earlier images from a frame source (memory stays flat over long runs).
pub struct SourceStore<S>(pub S);

impl<S: visnav_io::FrameSource> ImageStore for SourceStore<S> {
    fn keep(&mut self, _position: usize, _image: &GrayImage) {}
    fn image(&mut self, position: usize) -> Result<GrayImage, String> {
        self.0
            .load(position, false)
            .map(|f| f.left)
            .map_err(|e| e.to_string())
    }
}

enum Stream {
    Mono(Box<mono::MonoStream>),
    Stereo(Box<stereo::StereoStream>),
}

/// The streaming odometry (see the crate docs).
pub struct Odometry {
    stream: Stream,
    outputs: Outputs,
    pipelined: bool,
    /// A frame received and not yet processed (pipelined mode), with its position.
    pending: Option<(usize, FrameInput)>,
    /// The flow computed ahead for the pending frame.
    ahead: Option<ahead::FlowAhead>,
    next_position: usize,
    trajectory: Vec<Pose>,
}

impl Odometry {
    /// A monocular odometry (dense flow with uncertainty, §3–5 of the monocular paper).
    ///
    /// # Errors
    /// [`PipelineError`] for an invalid configuration.
    pub fn mono(camera: PinholeCamera, config: &MonoRunConfig) -> Result<Self, PipelineError> {
        config.validate()?;
        Ok(Self::with_stream(Stream::Mono(Box::new(
            mono::MonoStream::new(camera, config)?,
        ))))
    }

    /// A stereo odometry (RotROCC, the stereo paper) for a rectified rig.
    ///
    /// # Errors
    /// [`PipelineError`] for an invalid configuration.
    pub fn stereo(rig: StereoCamera, config: StereoConfig) -> Result<Self, PipelineError> {
        let stream = stereo::StereoStream::new(rig, config)?;
        Ok(Self::with_stream(Stream::Stereo(Box::new(stream))))
    }

    fn with_stream(stream: Stream) -> Self {
        Self {
            stream,
            outputs: Outputs::default(),
            pipelined: false,
            pending: None,
            ahead: None,
            next_position: 0,
            trajectory: Vec::new(),
        }
    }

    /// Adds the loop-closure stage (§5 of the monocular paper): `store` gives earlier (left)
    /// images back for verification ([`MemoryStore`] keeps them all; [`SourceStore`] reloads).
    /// `config.loop_closure` configures it and `config.mono` the closures' relative pose and
    /// flow, in both modes. Mono: `camera` is the odometry's camera. Stereo: the closures are
    /// verified on the left images and their pose is the PnP of the earlier frame's stereo
    /// points ([`feature_depth_map`]); `camera` must be the rig's left camera.
    ///
    /// # Errors
    /// [`PipelineError`] for an invalid loop configuration, or a stereo odometry whose left
    /// camera is not `camera`.
    pub fn with_loop_closure(
        mut self,
        camera: PinholeCamera,
        config: &MonoRunConfig,
        store: Box<dyn ImageStore>,
    ) -> Result<Self, PipelineError> {
        match &mut self.stream {
            Stream::Mono(m) => m.enable_loop_closure(camera, config, store)?,
            Stream::Stereo(s) => {
                if s.left_camera() != camera {
                    return Err(PipelineError::Input(format!(
                        "loop closure: the camera {camera:?} is not the stereo rig's left camera {:?}",
                        s.left_camera()
                    )));
                }
                s.enable_loop_closure(config, store)?;
            }
        }
        Ok(self)
    }

    /// Selects the optional per-frame outputs.
    #[must_use]
    pub fn with_outputs(mut self, outputs: Outputs) -> Self {
        self.outputs = outputs;
        self
    }

    /// Pipelined mode (mono): the flow into the next frame runs on a thread while this frame's
    /// odometry runs, so [`push`](Self::push) returns the result of the frame *before* the one
    /// pushed (one frame of latency) and [`finish`](Self::finish) returns the last one. Same
    /// poses as the synchronous mode. Off by default.
    #[must_use]
    pub fn pipelined(mut self, on: bool) -> Self {
        self.pipelined = on;
        self
    }

    /// The mode.
    #[must_use]
    pub fn mode(&self) -> Mode {
        match self.stream {
            Stream::Mono(_) => Mode::Mono,
            Stream::Stereo(_) => Mode::Stereo,
        }
    }

    /// Pushes the next frame. Synchronous mode: returns its result. Pipelined mode: returns
    /// the previous frame's result (`None` for the first push).
    pub fn push(&mut self, input: FrameInput) -> Option<FrameResult> {
        let position = self.next_position;
        self.next_position += 1;
        let pipelined = self.pipelined && matches!(self.stream, Stream::Mono(_));
        if !pipelined {
            return Some(self.run_frame(input, position, None));
        }
        let Some((prev_position, prev)) = self.pending.take() else {
            self.pending = Some((position, input));
            return None;
        };
        // wait for the previous frame's flow before starting the next one: one flow at a time
        let ahead_for_prev = self.ahead.take().map(ahead::FlowAhead::wait);
        if let Stream::Mono(m) = &self.stream {
            self.ahead = m.spawn_ahead(&prev, &input, prev_position, position);
        }
        self.pending = Some((position, input));
        Some(self.run_frame(prev, prev_position, ahead_for_prev))
    }

    /// Processes the frame still pending in pipelined mode (call after the last push).
    pub fn finish(&mut self) -> Option<FrameResult> {
        let (position, input) = self.pending.take()?;
        let ahead = self.ahead.take().map(ahead::FlowAhead::wait);
        Some(self.run_frame(input, position, ahead))
    }

    /// Pushes a frame and returns its own result, whatever the mode (the pending frame of the
    /// pipelined mode, if any, is processed first and its result is returned too, first).
    pub fn process(&mut self, input: FrameInput) -> Vec<FrameResult> {
        let mut out: Vec<FrameResult> = self.push(input).into_iter().collect();
        out.extend(self.finish());
        out
    }

    fn run_frame(
        &mut self,
        input: FrameInput,
        position: usize,
        ahead: Option<ahead::ReadyFlow>,
    ) -> FrameResult {
        let world_from_prev = self.trajectory.last().copied();
        let result = match &mut self.stream {
            Stream::Mono(m) => m.process(input, position, world_from_prev, ahead, self.outputs),
            Stream::Stereo(s) => s.process(input, position, self.outputs),
        };
        self.trajectory.push(result.world_from_cam);
        result
    }

    /// `world_from_cam` of every processed frame (odometry only), in stream order.
    #[must_use]
    pub fn trajectory(&self) -> &[Pose] {
        &self.trajectory
    }

    /// The trajectory after loop closure (the odometry's when loop closure is off).
    #[must_use]
    pub fn corrected_trajectory(&self) -> Vec<Pose> {
        self.loop_closer().map_or_else(
            || self.trajectory.clone(),
            visnav_loop::LoopCloser::corrected_poses,
        )
    }

    /// The loop-closure stage, when enabled.
    #[must_use]
    pub fn loop_closer(&self) -> Option<&visnav_loop::LoopCloser> {
        match &self.stream {
            Stream::Mono(m) => m.closer(),
            Stream::Stereo(s) => s.closer(),
        }
    }
}

impl Drop for Odometry {
    fn drop(&mut self) {
        // never leave a flow thread running behind the caller's back
        if let Some(a) = self.ahead.take() {
            drop(std::panic::catch_unwind(std::panic::AssertUnwindSafe(
                || a.join(),
            )));
        }
    }
}
