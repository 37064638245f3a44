//! `visnav.StereoOdometry`, `visnav.MonoOdometry` (push frames one at a time) and
//! `visnav.run_odometry` (a whole sequence, set up exactly as `visnav odometry`).

use std::path::PathBuf;
use std::sync::Mutex;

use numpy::{PyArray2, PyArray3};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use visnav_pipeline::job::{ConfigSource, RunSpec};
use visnav_pipeline::{Control, FrameInput, Mode, Odometry, Outputs, Preset, Status};

use crate::arrays::{pose_matrix, poses_array, to_image};
use crate::sequence::Camera;
use crate::{job_err, value_err};

/// The outcome of one frame.
#[pyclass(module = "visnav", frozen)]
pub struct FrameResult {
    /// Position of the frame in the stream (0 for the first frame pushed).
    #[pyo3(get)]
    pub position: usize,
    /// `world_from_cam` of the left camera, 4×4 float64 (frame 0 = identity; metres).
    #[pyo3(get)]
    pub world_from_cam: Py<PyArray2<f64>>,
    /// `prev_from_cur`: the motion since the previous frame, 4×4 float64.
    #[pyo3(get)]
    pub prev_from_cur: Py<PyArray2<f64>>,
    /// The 6×6 covariance of `prev_from_cur` (right perturbation in this frame's camera; x, y,
    /// z, rotation about x, y, z; metres and radians), None without an estimate of its own
    /// (`visnav_pipeline::FrameResult::prev_from_cur_covariance`).
    #[pyo3(get)]
    pub prev_from_cur_covariance: Option<Py<PyArray2<f64>>>,
    /// `"ok"`, `"low_parallax"`, `"fallback"` or `"skipped"`.
    #[pyo3(get)]
    pub status: String,
    /// Why a fallback or a skip happened, else None.
    #[pyo3(get)]
    pub reason: Option<String>,
    /// Milliseconds per stage (`FrameTimings::stages()` names) plus `"total_ms"`.
    #[pyo3(get)]
    pub timings: Py<PyDict>,
    /// Timestamp given with the frame, seconds.
    #[pyo3(get)]
    pub timestamp: Option<f64>,
}

#[pymethods]
impl FrameResult {
    fn __repr__(&self) -> String {
        format!(
            "FrameResult(position={}, status={:?})",
            self.position, self.status
        )
    }
}

fn frame_result(py: Python<'_>, r: &visnav_pipeline::FrameResult) -> PyResult<FrameResult> {
    let timings = PyDict::new(py);
    for (name, ms) in r.timings.stages() {
        timings.set_item(name, ms)?;
    }
    timings.set_item("total_ms", r.timings.total_ms)?;
    let reason = match &r.status {
        Status::Ok | Status::LowParallax => None,
        Status::Skipped { reason } => Some(reason.clone()),
        Status::Fallback { reason } => Some(serde_json::to_string(reason).unwrap_or_default()),
    };
    Ok(FrameResult {
        position: r.position,
        world_from_cam: PyArray2::from_owned_array(py, pose_matrix(&r.world_from_cam)).unbind(),
        prev_from_cur: PyArray2::from_owned_array(py, pose_matrix(&r.prev_from_cur)).unbind(),
        prev_from_cur_covariance: r.prev_from_cur_covariance.map(|c| {
            let a = numpy::ndarray::Array2::from_shape_fn((6, 6), |(i, j)| c[(i, j)]);
            PyArray2::from_owned_array(py, a).unbind()
        }),
        status: r.status.name().to_owned(),
        reason,
        timings: timings.unbind(),
        timestamp: r.timestamp_s,
    })
}

/// A Python configuration (None, a dict with the TOML keys, or a path to a TOML file).
fn config_source(config: Option<&Bound<'_, PyAny>>) -> PyResult<Option<ConfigSource>> {
    let Some(c) = config else { return Ok(None) };
    if c.is_none() {
        return Ok(None);
    }
    if c.is_instance_of::<PyDict>() {
        let json: String = c
            .py()
            .import("json")?
            .call_method1("dumps", (c,))
            .map_err(|e| value_err(format!("config: not a JSON-like dict ({e})")))?
            .extract()?;
        let value = serde_json::from_str(&json)
            .map_err(|e| value_err(format!("config: not a JSON-like dict ({e})")))?;
        return Ok(Some(ConfigSource::Inline(value)));
    }
    let path: PathBuf = c.extract().map_err(|_| {
        value_err("config: expected None, a dict or a path to a TOML file".to_owned())
    })?;
    Ok(Some(ConfigSource::File(path)))
}

/// The shared part of both odometry classes.
struct Inner {
    odometry: Mutex<Odometry>,
    mode: Mode,
}

impl Inner {
    fn process(
        &self,
        py: Python<'_>,
        left: &Bound<'_, PyAny>,
        right: Option<&Bound<'_, PyAny>>,
        timestamp: Option<f64>,
    ) -> PyResult<FrameResult> {
        let left = to_image("left", left)?;
        let input = match (self.mode, right.filter(|r| !r.is_none())) {
            (Mode::Stereo, Some(r)) => {
                let right = to_image("right", r)?;
                if (right.width(), right.height()) != (left.width(), left.height()) {
                    return Err(value_err(format!(
                        "right image is {}×{}, the left one {}×{}",
                        right.height(),
                        right.width(),
                        left.height(),
                        left.width()
                    )));
                }
                FrameInput::stereo(left, right, timestamp)
            }
            (Mode::Stereo, None) => {
                return Err(value_err("StereoOdometry.process needs a right image"));
            }
            (Mode::Mono, Some(_)) => {
                return Err(value_err(
                    "MonoOdometry.process takes one image (right=None)",
                ));
            }
            (Mode::Mono, None) => FrameInput::mono(left, timestamp),
        };
        let odometry = &self.odometry;
        let result = py.detach(|| {
            let mut vo = odometry
                .lock()
                .map_err(|_| "the odometry was poisoned by an earlier panic".to_owned())?;
            vo.process(input)
                .pop()
                .ok_or_else(|| "the odometry gave no result".to_owned())
        });
        frame_result(py, &result.map_err(value_err)?)
    }

    fn trajectory<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let vo = self
            .odometry
            .lock()
            .map_err(|_| value_err("the odometry was poisoned by an earlier panic"))?;
        Ok(poses_array(py, vo.trajectory()))
    }
}

/// Stereo odometry (RotROCC) for a rectified rig: push stereo pairs, get one pose per pair.
#[pyclass(module = "visnav", frozen)]
pub struct StereoOdometry(Inner);

#[pymethods]
impl StereoOdometry {
    #[new]
    #[pyo3(signature = (camera, config=None))]
    fn py_new(camera: &Camera, config: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let rig = camera.stereo()?;
        let mut spec = RunSpec::new("", Mode::Stereo);
        spec.config = config_source(config)?;
        let config = spec.stereo_config().map_err(|e| job_err(&e))?;
        let vo = Odometry::stereo(rig, config)
            .map_err(|e| job_err(&visnav_pipeline::job::JobError::from(e)))?;
        Ok(Self(Inner {
            odometry: Mutex::new(vo),
            mode: Mode::Stereo,
        }))
    }

    /// Processes one rectified stereo pair (H×W uint8 or float32 arrays) and returns its result.
    #[pyo3(signature = (left, right=None, timestamp=None))]
    fn process(
        &self,
        py: Python<'_>,
        left: &Bound<'_, PyAny>,
        right: Option<&Bound<'_, PyAny>>,
        timestamp: Option<f64>,
    ) -> PyResult<FrameResult> {
        self.0.process(py, left, right, timestamp)
    }

    /// `world_from_cam` of every frame processed so far, (N, 4, 4) float64.
    fn trajectory<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        self.0.trajectory(py)
    }
}

/// Monocular odometry from dense flow with uncertainty (synchronous: `process` returns the
/// result of the frame given).
#[pyclass(module = "visnav", frozen)]
pub struct MonoOdometry(Inner);

#[pymethods]
impl MonoOdometry {
    #[new]
    #[pyo3(signature = (camera, config=None, camera_height=None, preset=None))]
    fn py_new(
        camera: &Camera,
        config: Option<&Bound<'_, PyAny>>,
        camera_height: Option<f64>,
        preset: Option<&str>,
    ) -> PyResult<Self> {
        let pinhole = camera.pinhole()?;
        let mut spec = RunSpec::new("", Mode::Mono);
        spec.preset = parse_preset(preset)?;
        spec.config = config_source(config)?;
        spec.camera_height = camera_height;
        let config = spec.mono_config().map_err(|e| job_err(&e))?;
        let vo = Odometry::mono(pinhole, &config)
            .map_err(|e| job_err(&visnav_pipeline::job::JobError::from(e)))?;
        Ok(Self(Inner {
            odometry: Mutex::new(vo),
            mode: Mode::Mono,
        }))
    }

    /// Processes one image (H×W uint8 or float32) and returns its result.
    #[pyo3(signature = (left, right=None, timestamp=None))]
    fn process(
        &self,
        py: Python<'_>,
        left: &Bound<'_, PyAny>,
        right: Option<&Bound<'_, PyAny>>,
        timestamp: Option<f64>,
    ) -> PyResult<FrameResult> {
        self.0.process(py, left, right, timestamp)
    }

    /// `world_from_cam` of every frame processed so far, (N, 4, 4) float64.
    fn trajectory<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        self.0.trajectory(py)
    }
}

/// `None`, `"paper"` or `"realtime"` (`visnav odometry --preset`).
fn parse_preset(preset: Option<&str>) -> PyResult<Preset> {
    match preset {
        None | Some("paper") => Ok(Preset::Paper),
        Some("realtime") => Ok(Preset::Realtime),
        Some(other) => Err(value_err(format!(
            "preset: expected \"paper\" or \"realtime\", got {other:?}"
        ))),
    }
}

fn parse_mode(mode: &str) -> PyResult<Mode> {
    match mode {
        "stereo" => Ok(Mode::Stereo),
        "mono" => Ok(Mode::Mono),
        other => Err(value_err(format!(
            "mode: expected \"stereo\" or \"mono\", got {other:?}"
        ))),
    }
}

/// Runs the odometry over a sequence exactly as `visnav odometry` (same setup code,
/// `visnav_pipeline::job`) and returns `world_from_cam` per frame, (N, 4, 4) float64; with
/// `covariance=True` a tuple of it and each step's covariance, (N, 6, 6) float64, NaN for a frame
/// without one (`visnav_pipeline::FrameResult::prev_from_cur_covariance`). Ctrl-C,
/// SIGTERM or SIGHUP stop it after the frame in progress, as they stop `visnav odometry`, and
/// raise `visnav.Interrupted` (a `KeyboardInterrupt`) whose `poses` holds the frames done
/// (`crate::signals`).
#[pyfunction]
#[pyo3(signature = (path, mode, camera=None, camera_height=None, config=None, max_frames=None, preset=None, covariance=false))]
#[allow(clippy::too_many_arguments)] // Python's keyword arguments, each named at the call
pub fn run_odometry<'py>(
    py: Python<'py>,
    path: PathBuf,
    mode: &str,
    camera: Option<PathBuf>,
    camera_height: Option<f64>,
    config: Option<&Bound<'py, PyAny>>,
    max_frames: Option<usize>,
    preset: Option<&str>,
    covariance: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let mut spec = RunSpec::new(path, parse_mode(mode)?);
    spec.preset = parse_preset(preset)?;
    spec.camera = camera;
    spec.camera_height = camera_height;
    spec.config = config_source(config)?;
    spec.max_frames = max_frames;
    let (outcome, raised) = crate::signals::with_stop_signals(py, |stop| {
        let mut run = spec.prepare(Outputs::default())?;
        let Ok(driven) = run.drive(|_| {
            Ok::<_, std::convert::Infallible>(if stop() {
                Control::Stop
            } else {
                Control::Continue
            })
        });
        let expected = run.expected_poses();
        Ok::<_, visnav_pipeline::job::JobError>((run.finish(&spec, driven), expected))
    })?;
    let (outcome, expected) = outcome.map_err(|e| job_err(&e))?;
    let poses = poses_array(py, &outcome.poses);
    match raised {
        Some(e) => Err(crate::signals::interrupted(
            py,
            e,
            poses.as_any(),
            outcome.poses.len(),
            expected,
        )),
        None if covariance => {
            let frames = &outcome.report.per_frame;
            let c = numpy::ndarray::Array3::from_shape_fn((frames.len(), 6, 6), |(k, i, j)| {
                frames[k]
                    .prev_from_cur_covariance
                    .map_or(f64::NAN, |m| m[i][j])
            });
            let c = numpy::PyArray3::from_owned_array(py, c);
            Ok((poses, c).into_pyobject(py)?.into_any())
        }
        None => Ok(poses.into_any()),
    }
}
