//! One odometry run from its specification: what `visnav odometry`, the Python package
//! (`visnav.run_odometry`) and a batch manifest line all turn into an [`Odometry`] the same way,
//! so that they give the same trajectory by construction.
//!
//! ```text
//!  RunSpec (CLI flags, Python arguments, a manifest line; serde)
//!     │  prepare(): open the sequence, take the first max_frames (or the palindrome),
//!     │             load the configuration (defaults → TOML file or inline table → overrides),
//!     ▼             build the odometry (stereo rig / mono camera, pipelined, loop closure)
//!  PreparedRun ── drive(callback per frame) ──► DrivenRun ── finish() ──► RunOutcome
//!                                                                   (poses, RunReport)
//! ```
//!
//! Writing files (the pose journal, `--save-*`, the report) stays with the front ends.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};
use visnav_core::Pose;
use visnav_eval::palindrome::palindrome_drift;
use visnav_geometry::fundamental::Estimator;
use visnav_io::{FrameSource, IoError, Palindrome, Sequence, Take};
use visnav_odometry::stereo::{OutlierMode, StereoConfig};

use crate::report::{FrameRecord, LoopClosureSummary, RunReport};
use crate::{
    Arrival, Control, FrameResult, Mode, MonoRunConfig, Odometry, Outputs, PipelineError, Preset,
    RunConfig, SourceStore, run_items,
};

/// Where a run's configuration comes from: a TOML file (the CLI's `--config`) or a table given
/// inline (a Python dict, a JSON object in a manifest line) with the same keys.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ConfigSource {
    /// A TOML file: stereo `StereoConfig` fields (and `[loop_closure]`); mono `[mono]`,
    /// `[mono.flow]`, `[loop_closure]`.
    File(PathBuf),
    /// The same keys as a JSON value (an object).
    Inline(serde_json::Value),
}

/// Everything that defines an odometry run. Missing fields take the CLI's defaults; a manifest
/// line or a Python call maps onto it field by field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    /// The input: any layout `visnav_io::Sequence::open_with_camera` reads.
    pub sequence: PathBuf,
    /// Which odometry.
    pub mode: Mode,
    /// Camera file for inputs without calibration (see `visnav_io::calibration`).
    #[serde(default)]
    pub camera: Option<PathBuf>,
    /// The defaults the configuration is read over (`paper` when absent).
    #[serde(default)]
    pub preset: Preset,
    /// The configuration (the preset's defaults when absent).
    #[serde(default)]
    pub config: Option<ConfigSource>,
    /// Mono: camera height above the ground, metres (overrides the configuration).
    #[serde(default)]
    pub camera_height: Option<f64>,
    /// Process only the first N frames.
    #[serde(default)]
    pub max_frames: Option<usize>,
    /// Mono: aerial vehicle (ground-plane scale for the first frame only).
    #[serde(default)]
    pub aerial: bool,
    /// Mono, aerial: the ground's normal in the camera of a level flight, `[0, 0, 1]` for a
    /// camera looking straight down (overrides `mono.homography.ground_normal`).
    #[serde(default)]
    pub ground_normal: Option<[f64; 3]>,
    /// Mono: the eight-point variant (overrides the configuration).
    #[serde(default)]
    pub estimator: Option<Estimator>,
    /// Stereo: the outlier criterion (overrides the configuration).
    #[serde(default)]
    pub outlier: Option<OutlierMode>,
    /// Stereo: RotROCC frame-to-frame, without persistent tracks and window bundle adjustment
    /// (`window.persistent_tracks` and `window.bundle_adjustment` false; the ablation).
    #[serde(default)]
    pub no_ba: bool,
    /// Mono: play the frames forward then back (`2N − 1` poses, §6.2 drift test).
    #[serde(default)]
    pub palindrome: bool,
    /// The loop-closure stage (mono and stereo).
    #[serde(default)]
    pub loop_closure: bool,
    /// A ROS 2 bag's (left) image topic (default: the bag's only image topic).
    #[serde(default)]
    pub topic: Option<String>,
    /// A ROS 2 bag's right image topic (stereo).
    #[serde(default)]
    pub right_topic: Option<String>,
}

/// Why a run could not be set up. Problems of single frames are never errors (they get a
/// status and the constant-velocity prediction).
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// The sequence could not be opened.
    #[error("opening sequence {}", path.display())]
    OpenSequence {
        /// The sequence path.
        path: PathBuf,
        /// The reader's error (names the file and the problem).
        #[source]
        source: IoError,
    },
    /// The configuration file could not be read.
    #[error("reading config {}", path.display())]
    ReadConfig {
        /// The configuration file.
        path: PathBuf,
        /// The reader's error.
        #[source]
        source: IoError,
    },
    /// The configuration file is not valid TOML for the mode.
    #[error("parsing config {}", path.display())]
    ParseConfig {
        /// The configuration file.
        path: PathBuf,
        /// The parser's error (line, column, key).
        #[source]
        source: toml::de::Error,
    },
    /// The inline configuration does not fit the mode.
    #[error("parsing the inline {mode} config")]
    InlineConfig {
        /// `"mono"` or `"stereo"`.
        mode: &'static str,
        /// The parser's error.
        #[source]
        source: serde_json::Error,
    },
    /// A configuration value is out of range.
    #[error(
        "invalid {mode} configuration{}",
        file.as_ref().map_or_else(String::new, |p| format!(" in {}", p.display()))
    )]
    InvalidConfig {
        /// `"mono"` or `"stereo"`.
        mode: &'static str,
        /// The configuration file, when its values (over the defaults) are what is invalid.
        file: Option<PathBuf>,
        /// The bad field.
        #[source]
        source: PipelineError,
    },
    /// The specification does not fit the input or the mode.
    #[error("{0}")]
    Input(String),
    /// The odometry could not be built.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
}

/// The kind of a [`JobError`], for exit codes and exception types.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// A path that does not exist.
    NotFound,
    /// Input that will never work as given (malformed file, bad value): do not retry.
    BadInput,
    /// The file system failed (permission, disk): a retry may work.
    Io,
}

impl ErrorKind {
    /// The kind of an [`IoError`].
    #[must_use]
    pub fn of_io(e: &IoError) -> Self {
        match e {
            IoError::NotFound { .. } => Self::NotFound,
            IoError::Io { .. } => Self::Io,
            _ => Self::BadInput,
        }
    }
}

impl JobError {
    /// What kind of failure this is.
    #[must_use]
    pub fn kind(&self) -> ErrorKind {
        match self {
            Self::OpenSequence { source, .. } | Self::ReadConfig { source, .. } => {
                ErrorKind::of_io(source)
            }
            _ => ErrorKind::BadInput,
        }
    }
}

/// An error and its causes joined by `: `, each cause left out when the message so far already
/// ends with it (what the CLI prints after `error: `).
#[must_use]
pub fn error_chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut out = String::new();
    let mut cause: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(c) = cause {
        let text = c.to_string();
        if !out.ends_with(&text) {
            if !out.is_empty() {
                out.push_str(": ");
            }
            out.push_str(&text);
        }
        cause = c.source();
    }
    out
}

/// A run ready to drive: the opened input, the frames to push and the odometry.
pub struct PreparedRun {
    /// The opened input.
    pub sequence: Sequence,
    /// The positions pushed: the first `max_frames` frames, or their palindrome.
    pub source: Arc<dyn FrameSource>,
    /// Input frames `N` (before a palindrome doubles them).
    pub input_frames: usize,
    /// The odometry.
    pub odometry: Odometry,
    /// The effective configuration.
    pub config: RunConfig,
}

/// What the frame loop gave.
#[derive(Debug, Clone)]
pub struct DrivenRun {
    /// One record per processed frame.
    pub per_frame: Vec<FrameRecord>,
    /// Wall time of the loop, seconds.
    pub wall_s: f64,
    /// `true` when the loop stopped before the last frame.
    pub interrupted: bool,
}

/// The result of a finished run.
#[derive(Debug, Clone)]
pub struct RunOutcome {
    /// The trajectory to write, `world_from_cam` per processed frame (after loop closure when on).
    pub poses: Vec<Pose>,
    /// The odometry-only trajectory (differs from `poses` with loop closure).
    pub odometry_poses: Vec<Pose>,
    /// The report (`loop_closure.odometry_output` is left for the caller to fill in).
    pub report: RunReport,
}

impl RunSpec {
    /// A specification with the defaults for `sequence` and `mode`.
    #[must_use]
    pub fn new(sequence: impl Into<PathBuf>, mode: Mode) -> Self {
        Self {
            sequence: sequence.into(),
            mode,
            camera: None,
            preset: Preset::Paper,
            config: None,
            camera_height: None,
            max_frames: None,
            aerial: false,
            ground_normal: None,
            estimator: None,
            outlier: None,
            no_ba: false,
            palindrome: false,
            loop_closure: false,
            topic: None,
            right_topic: None,
        }
    }

    /// Relative paths (sequence, camera, configuration file) taken relative to `base`.
    #[must_use]
    pub fn relative_to(mut self, base: &Path) -> Self {
        let join = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        join(&mut self.sequence);
        if let Some(c) = &mut self.camera {
            join(c);
        }
        if let Some(ConfigSource::File(c)) = &mut self.config {
            join(c);
        }
        self
    }

    /// Fields that belong to the other mode are errors.
    ///
    /// # Errors
    /// [`JobError::Input`] naming the field.
    pub fn check_mode_fields(&self) -> Result<(), JobError> {
        let wrong: &[(bool, &str)] = match self.mode {
            Mode::Stereo => &[
                (self.camera_height.is_some(), "camera_height"),
                (self.aerial, "aerial"),
                (self.ground_normal.is_some(), "ground_normal"),
                (self.estimator.is_some(), "estimator"),
                (self.palindrome, "palindrome"),
            ],
            Mode::Mono => &[(self.outlier.is_some(), "outlier"), (self.no_ba, "no_ba")],
        };
        match wrong.iter().find(|(set, _)| *set) {
            Some((_, name)) => Err(JobError::Input(format!(
                "{name} applies to mode {} only",
                other(self.mode).name()
            ))),
            None => Ok(()),
        }
    }

    /// The stereo configuration: defaults, then the file or inline table, then `outlier` and
    /// `no_ba`.
    ///
    /// # Errors
    /// An unreadable or malformed configuration, or a value out of range.
    pub fn stereo_config(&self) -> Result<StereoConfig, JobError> {
        let mut config: StereoConfig =
            self.read_config("stereo", StereoConfig::default(), Some(LOOP_TABLE))?;
        config
            .validate()
            .map_err(|e| self.invalid("stereo", e.into(), true))?;
        if let Some(o) = self.outlier {
            config.outlier = o;
        }
        if self.no_ba {
            config.window.persistent_tracks = false;
            config.window.bundle_adjustment = false;
        }
        config
            .validate()
            .map_err(|e| self.invalid("stereo", e.into(), false))?;
        Ok(config)
    }

    /// The mono configuration: defaults, then the file or inline table, then the overrides
    /// (`camera_height`, `aerial`, `ground_normal`, `estimator`).
    ///
    /// # Errors
    /// An unreadable or malformed configuration, or a value out of range.
    pub fn mono_config(&self) -> Result<MonoRunConfig, JobError> {
        let mut config: MonoRunConfig =
            self.read_config("mono", MonoRunConfig::of_preset(self.preset), None)?;
        config
            .validate()
            .map_err(|e| self.invalid("mono", e, true))?;
        if let Some(h) = self.camera_height {
            config.mono.scale.camera_height_m = h;
        }
        if self.aerial {
            config.mono.scale.aerial = true;
        }
        if let Some(n) = self.ground_normal {
            config.mono.homography.ground_normal = Some(n);
        }
        if let Some(e) = self.estimator {
            config.mono.eight_point.estimator = e;
        }
        config
            .validate()
            .map_err(|e| self.invalid("mono", e, false))?;
        Ok(config)
    }

    /// [`JobError::InvalidConfig`] of `mode`, naming the configuration file when `from_file`: its
    /// values over the defaults fail the check before any option (`outlier`, `camera_height`
    /// …) is applied (issue 53's fuzzing: the error did not say which file held the value).
    fn invalid(&self, mode: &'static str, source: PipelineError, from_file: bool) -> JobError {
        let file = match (&self.config, from_file) {
            (Some(ConfigSource::File(path)), true) => Some(path.clone()),
            _ => None,
        };
        JobError::InvalidConfig { mode, file, source }
    }

    /// The effective configuration of the mode.
    ///
    /// # Errors
    /// As [`Self::stereo_config`] and [`Self::mono_config`].
    pub fn effective_config(&self) -> Result<RunConfig, JobError> {
        Ok(match self.mode {
            Mode::Stereo if self.loop_closure => {
                RunConfig::StereoLoop(Box::new(crate::StereoLoopConfig {
                    stereo: self.stereo_config()?,
                    loop_closure: self.stereo_loop_config()?.loop_closure,
                }))
            }
            Mode::Stereo => RunConfig::Stereo(Box::new(self.stereo_config()?)),
            Mode::Mono => RunConfig::Mono(Box::new(self.mono_config()?)),
        })
    }

    /// The loop closure of a stereo run: the `[loop_closure]` table of its configuration over
    /// the stereo defaults (`LoopConfig::stereo`), and the default monocular settings for the
    /// closures' relative pose (PnP) and flow.
    ///
    /// # Errors
    /// An unreadable or malformed configuration, or a value out of range.
    pub fn stereo_loop_config(&self) -> Result<MonoRunConfig, JobError> {
        let defaults = visnav_loop::LoopConfig::stereo();
        let loop_closure: visnav_loop::LoopConfig = match &self.config {
            None => defaults,
            Some(ConfigSource::File(path)) => {
                let parse = |source| JobError::ParseConfig {
                    path: path.clone(),
                    source,
                };
                let mut table: toml::Table =
                    toml::from_str(&self.config_text(path)?).map_err(parse)?;
                match table.remove(LOOP_TABLE) {
                    Some(toml::Value::Table(over)) => over_defaults_toml(defaults, over, parse)?,
                    Some(other) => other.try_into().map_err(parse)?,
                    None => defaults,
                }
            }
            Some(ConfigSource::Inline(v)) => match v.get(LOOP_TABLE) {
                Some(over) => {
                    over_defaults_json(defaults, over.clone(), |source| JobError::InlineConfig {
                        mode: "stereo",
                        source,
                    })?
                }
                None => defaults,
            },
        };
        let config = MonoRunConfig {
            loop_closure: self.finite("stereo", loop_closure)?,
            ..MonoRunConfig::default()
        };
        config
            .validate()
            .map_err(|e| self.invalid("stereo", e, true))?;
        Ok(config)
    }

    fn config_text(&self, path: &Path) -> Result<String, JobError> {
        visnav_io::text::read_text(path).map_err(|source| JobError::ReadConfig {
            path: path.to_path_buf(),
            source,
        })
    }

    /// The configuration of `mode`: its defaults with the file's or inline table's keys over
    /// them, table by table (a table that sets one field keeps the mode's defaults for the
    /// others, e.g. `[klt] window_radius = 5` keeps the stereo tracker's `max_residual`). `skip`
    /// names a top-level table that belongs to another stage (the stereo run's
    /// `[loop_closure]`) and is left out.
    fn read_config<T: serde::Serialize + serde::de::DeserializeOwned>(
        &self,
        mode: &'static str,
        defaults: T,
        skip: Option<&str>,
    ) -> Result<T, JobError> {
        let config = match &self.config {
            None => return Ok(defaults),
            Some(ConfigSource::File(path)) => {
                let text = self.config_text(path)?;
                let parse = |source| JobError::ParseConfig {
                    path: path.clone(),
                    source,
                };
                let mut table: toml::Table = toml::from_str(&text).map_err(parse)?;
                // without another stage's table, checked as written first: unknown keys and
                // wrong types with their line
                if skip.and_then(|key| table.remove(key)).is_none() {
                    let _: T = toml::from_str(&text).map_err(parse)?;
                }
                over_defaults_toml(defaults, table, parse)?
            }
            Some(ConfigSource::Inline(v)) => {
                let mut v = v.clone();
                if let (Some(key), Some(object)) = (skip, v.as_object_mut()) {
                    object.remove(key);
                }
                over_defaults_json(defaults, v, |source| JobError::InlineConfig {
                    mode,
                    source,
                })?
            }
        };
        self.finite(mode, config)
    }

    /// `config` when every number in it is finite; else an error naming the key, the file and
    /// the key's line (issue 53's fuzzing: `extra_variance_weight = 1e308`, a 32-bit field, was
    /// taken as infinity in silence).
    fn finite<T: serde::Serialize>(&self, mode: &'static str, config: T) -> Result<T, JobError> {
        let Some((key, value)) = toml::Table::try_from(&config)
            .ok()
            .and_then(|t| crate::config::first_non_finite(&t))
        else {
            return Ok(config);
        };
        let what = format!(
            "{key} = {value}: not a finite number (a value too large for the field's type?)"
        );
        Err(JobError::Input(match &self.config {
            Some(ConfigSource::File(path)) => {
                let leaf = key.rsplit('.').next().unwrap_or(&key);
                let line = self.config_text(path).ok().and_then(|text| {
                    text.lines().position(|l| {
                        l.trim_start()
                            .strip_prefix(leaf)
                            .is_some_and(|r| r.trim_start().starts_with('='))
                    })
                });
                match line {
                    Some(i) => format!("{}:{}: {what}", path.display(), i + 1),
                    None => format!("{}: {what}", path.display()),
                }
            }
            _ => format!("the inline {mode} config: {what}"),
        }))
    }

    /// Opens the input with its camera file, if any.
    ///
    /// # Errors
    /// [`JobError::OpenSequence`] with the reader's error.
    pub fn open_sequence(&self) -> Result<Sequence, JobError> {
        let opened = visnav_io::open_input(
            &self.sequence,
            self.camera.as_deref(),
            self.topic.as_deref(),
            self.right_topic.as_deref(),
        );
        opened.map_err(|source| JobError::OpenSequence {
            path: self.sequence.clone(),
            source,
        })
    }

    /// Opens the input, loads the configuration and builds the odometry (stereo: synchronous;
    /// mono: pipelined; the loop closure, when asked, reloads earlier images from the input),
    /// with the optional per-frame `outputs`.
    ///
    /// # Errors
    /// Any [`JobError`]: unreadable input or configuration, no frames, a sequence without stereo
    /// for the stereo mode, fields of the other mode.
    pub fn prepare(&self, outputs: Outputs) -> Result<PreparedRun, JobError> {
        self.check_mode_fields()?;
        let sequence = self.open_sequence()?;
        let n = self
            .max_frames
            .map_or(sequence.len(), |m| m.min(sequence.len()));
        if n == 0 {
            return Err(JobError::Input("no frames to process".into()));
        }
        let source: Arc<dyn FrameSource> = if self.palindrome {
            Arc::new(Palindrome::new(sequence.clone(), Some(n)))
        } else {
            Arc::new(Take::new(sequence.clone(), n))
        };
        let (odometry, config) = match self.mode {
            Mode::Stereo => {
                let config = self.stereo_config()?;
                let Some(rig) = sequence.stereo_camera() else {
                    if sequence.layout == visnav_io::SequenceLayout::RosBag {
                        return Err(JobError::Input(format!(
                            "{}: --mode stereo on a bag needs --right-topic (`visnav info` lists the image topics)",
                            self.sequence.display()
                        )));
                    }
                    return Err(JobError::Input(format!(
                        "{} has no right camera or calibration: --mode stereo needs image_0 + image_1 (or image_00 + image_01) and P1",
                        self.sequence.display()
                    )));
                };
                let vo = Odometry::stereo(rig, config.clone())?.with_outputs(outputs);
                if self.loop_closure {
                    let store = Box::new(SourceStore(Arc::clone(&source)));
                    let loop_config = self.stereo_loop_config()?;
                    let vo = vo.with_loop_closure(rig.left, &loop_config, store)?;
                    let config = crate::StereoLoopConfig {
                        stereo: config,
                        loop_closure: loop_config.loop_closure,
                    };
                    (vo, RunConfig::StereoLoop(Box::new(config)))
                } else {
                    (vo, RunConfig::Stereo(Box::new(config)))
                }
            }
            Mode::Mono => {
                let config = self.mono_config()?;
                let mut vo = Odometry::mono(sequence.camera, &config)?
                    .with_outputs(outputs)
                    .pipelined(true);
                if self.loop_closure {
                    let store = Box::new(SourceStore(Arc::clone(&source)));
                    vo = vo.with_loop_closure(sequence.camera, &config, store)?;
                }
                (vo, RunConfig::Mono(Box::new(config)))
            }
        };
        Ok(PreparedRun {
            sequence,
            source,
            input_frames: n,
            odometry,
            config,
        })
    }

    /// Prepares, drives to the end and finishes the run without writing anything.
    ///
    /// # Errors
    /// As [`Self::prepare`].
    pub fn run(&self) -> Result<RunOutcome, JobError> {
        let mut run = self.prepare(Outputs::default())?;
        let driven = run.drive(|_| Ok::<_, std::convert::Infallible>(Control::Continue));
        let Ok(driven) = driven;
        Ok(run.finish(self, driven))
    }
}

/// The stereo configuration's table for the loop closure.
const LOOP_TABLE: &str = "loop_closure";

/// `over`'s keys over the serialised `defaults`, table by table ([`merge_toml`]): a table that
/// sets one field keeps the defaults' other fields.
fn over_defaults_toml<T: serde::Serialize + serde::de::DeserializeOwned>(
    defaults: T,
    over: toml::Table,
    parse: impl Fn(toml::de::Error) -> JobError,
) -> Result<T, JobError> {
    let mut merged = toml::Table::try_from(defaults)
        .map_err(|e| JobError::Input(format!("configuration defaults: {e}")))?;
    merge_toml(&mut merged, over);
    toml::Value::Table(merged).try_into().map_err(parse)
}

/// As [`over_defaults_toml`] for an inline JSON table ([`merge_json`]).
fn over_defaults_json<T: serde::Serialize + serde::de::DeserializeOwned>(
    defaults: T,
    over: serde_json::Value,
    inline: impl Fn(serde_json::Error) -> JobError,
) -> Result<T, JobError> {
    let mut merged = serde_json::to_value(defaults).map_err(&inline)?;
    merge_json(&mut merged, over);
    serde_json::from_value(merged).map_err(inline)
}

/// `over`'s keys replace `base`'s, tables merged key by key.
fn merge_toml(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_toml(b, o),
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

/// `over`'s keys replace `base`'s, objects merged key by key.
fn merge_json(base: &mut serde_json::Value, over: serde_json::Value) {
    match (base, over) {
        (serde_json::Value::Object(b), serde_json::Value::Object(o)) => {
            for (key, value) in o {
                match b.get_mut(&key) {
                    Some(slot) => merge_json(slot, value),
                    None => {
                        b.insert(key, value);
                    }
                }
            }
        }
        (base, over) => *base = over,
    }
}

fn other(mode: Mode) -> Mode {
    match mode {
        Mode::Stereo => Mode::Mono,
        Mode::Mono => Mode::Stereo,
    }
}

impl PreparedRun {
    /// Pushes every frame of the source (prefetched, see [`crate::run_source`]); `on_frame` gets each
    /// result in order and may stop the run or fail it (its time is the frame's `save_ms`).
    ///
    /// # Errors
    /// The first error of `on_frame` (the run stops after that frame).
    pub fn drive<E>(
        &mut self,
        mut on_frame: impl FnMut(&FrameResult) -> Result<Control, E>,
    ) -> Result<DrivenRun, E> {
        self.drive_with(|r, _| on_frame(r))
    }

    /// As [`Self::drive`], `on_frame` also getting the frame's [`Arrival`] (its latency).
    ///
    /// # Errors
    /// The first error of `on_frame` (the run stops after that frame).
    pub fn drive_with<E>(
        &mut self,
        on_frame: impl FnMut(&FrameResult, &Arrival) -> Result<Control, E>,
    ) -> Result<DrivenRun, E> {
        let source = Arc::clone(&self.source);
        let stereo = self.odometry.mode() == Mode::Stereo;
        let frames = visnav_io::Prefetch::new(Arc::clone(&source), stereo, 2);
        let mut driven = drive_items(&mut self.odometry, frames, on_frame)?;
        driven.interrupted = driven.per_frame.len() < source.len();
        Ok(driven)
    }

    /// The poses and the report of a driven run (loop closure summary, palindrome drift).
    #[must_use]
    pub fn finish(&self, spec: &RunSpec, driven: DrivenRun) -> RunOutcome {
        let odometry_poses = self.odometry.trajectory().to_vec();
        let mut report = RunReport::new(
            std::path::absolute(&spec.sequence).unwrap_or_else(|_| spec.sequence.clone()),
            self.config.clone(),
            self.input_frames,
            driven.per_frame,
            driven.wall_s,
        );
        report.interrupted = driven.interrupted;
        let mut poses = odometry_poses.clone();
        if let Some(closer) = self.odometry.loop_closer() {
            let mut summary = LoopClosureSummary::of(closer);
            summary.odometry_palindrome =
                spec.palindrome.then(|| palindrome_drift(&poses)).flatten();
            report.loop_closure = Some(summary);
            poses = closer.corrected_poses();
        }
        report.palindrome = spec.palindrome.then(|| palindrome_drift(&poses)).flatten();
        RunOutcome {
            poses,
            odometry_poses,
            report,
        }
    }

    /// Poses a complete run writes: one per input frame (`2N − 1` for a palindrome).
    #[must_use]
    pub fn expected_poses(&self) -> usize {
        self.source.len()
    }
}

/// Pushes the items of `frames` into `odometry` (see [`run_items`]), records every frame and
/// hands each result to `on_frame` (its time is the frame's `save_ms`); `interrupted` is left
/// false for the caller to set.
pub(crate) fn drive_items<E>(
    odometry: &mut Odometry,
    frames: impl Iterator<Item = visnav_io::SourceItem>,
    mut on_frame: impl FnMut(&FrameResult, &Arrival) -> Result<Control, E>,
) -> Result<DrivenRun, E> {
    let mut per_frame = Vec::new();
    let mut error: Option<E> = None;
    let start = Instant::now();
    run_items(odometry, frames, |r, arrival| {
        let t_save = Instant::now();
        let control = on_frame(&r, arrival);
        let save_ms = t_save.elapsed().as_secs_f64() * 1e3;
        per_frame.push(
            FrameRecord::new(&r, arrival.index, arrival.wait_ms, save_ms).with_arrival(arrival),
        );
        match control {
            Ok(c) => c,
            Err(e) => {
                error.get_or_insert(e);
                Control::Stop
            }
        }
    });
    if let Some(e) = error {
        return Err(e);
    }
    Ok(DrivenRun {
        wall_s: start.elapsed().as_secs_f64(),
        interrupted: false,
        per_frame,
    })
}

/// For inputs with timestamps, `poses` (one per frame, frame 0 = identity) with their
/// timestamps as written to a TUM file: in the body frame when the dataset defines one
/// (`body0_from_bodyk = B · cam0_from_camk · B⁻¹`, `B = body_from_cam`), else the camera frame.
/// `None` when the input has no timestamps or the poses do not map one-to-one onto frames.
#[must_use]
pub fn tum_poses(seq: &Sequence, poses: &[Pose]) -> Option<(Vec<Pose>, Vec<f64>)> {
    if !seq.timestamped || poses.len() > seq.timestamps.len() {
        return None;
    }
    let poses: Vec<Pose> = match seq.body_from_cam {
        Some(b) => poses.iter().map(|p| b * p * b.inverse()).collect(),
        None => poses.to_vec(),
    };
    let times = seq.timestamps[..poses.len()].to_vec();
    Some((poses, times))
}
