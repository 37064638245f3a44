//! `visnav.dense_flow` (what `visnav flow` computes) and `visnav.kitti_errors` (what
//! `visnav eval --json` reports).

use std::path::PathBuf;

use numpy::ndarray::{Array2, Array3};
use numpy::{PyArray2, PyArray3};
use pyo3::prelude::*;
use visnav_core::GrayImage;
use visnav_eval::kitti::KittiMetricConfig;
use visnav_eval::{EvalConfig, TrajectoryPair, evaluate};
use visnav_flow::{AnyFlow, FastFlow, FastFlowConfig, FlowConfig, FlowEstimator, FlowInput};

use crate::arrays::{to_image, to_pose_matrices};
use crate::{io_err, to_py_err, value_err};

/// Dense flow with its per-pixel uncertainty (see `visnav.dense_flow`).
#[pyclass(module = "visnav", frozen)]
pub struct DenseFlow {
    /// `(u, v)` per pixel from the first image to the second, H×W×2 float32, pixels.
    #[pyo3(get)]
    pub flow: Py<PyArray3<f32>>,
    /// Information matrix per pixel `(Yxx, Yxy, Yyy)`, H×W×3 float32, 1/px².
    #[pyo3(get)]
    pub information: Py<PyArray3<f32>>,
    /// Forward–backward consistent pixels, H×W bool.
    #[pyo3(get)]
    pub valid: Py<PyArray2<bool>>,
    /// Milliseconds per stage of the flow.
    #[pyo3(get)]
    pub timings_ms: Py<PyAny>,
}

/// An image argument: an array or a path to an image file (loaded as the CLI does).
fn image_arg(what: &str, obj: &Bound<'_, PyAny>) -> PyResult<GrayImage> {
    if let Ok(path) = obj.extract::<PathBuf>() {
        return obj
            .py()
            .detach(|| visnav_io::image_io::load_gray(&path))
            .map_err(|e| io_err(&e));
    }
    to_image(what, obj)
}

/// A JSON-serialisable value as a Python object (through the `json` module).
fn to_python<T: serde::Serialize>(py: Python<'_>, value: &T) -> PyResult<Py<PyAny>> {
    let text = serde_json::to_string(value).map_err(|e| value_err(e.to_string()))?;
    Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
}

/// Dense flow with uncertainty from `img1` to `img2` with the default (calibrated) flow
/// configuration, or `config` (a dict with `FlowConfig` keys, or `FastFlowConfig` keys with
/// `method="fast"`), exactly as `visnav flow [--method fast]`.
#[pyfunction]
#[pyo3(signature = (img1, img2, config=None, method=None))]
pub fn dense_flow(
    py: Python<'_>,
    img1: &Bound<'_, PyAny>,
    img2: &Bound<'_, PyAny>,
    config: Option<&Bound<'_, PyAny>>,
    method: Option<&str>,
) -> PyResult<DenseFlow> {
    let a = image_arg("img1", img1)?;
    let b = image_arg("img2", img2)?;
    if (a.width(), a.height()) != (b.width(), b.height()) {
        return Err(value_err(format!(
            "img1 is {}×{}, img2 {}×{}: the images must have the same size",
            a.height(),
            a.width(),
            b.height(),
            b.width()
        )));
    }
    let json: Option<String> = match config.filter(|c| !c.is_none()) {
        None => None,
        Some(c) => Some(py.import("json")?.call_method1("dumps", (c,))?.extract()?),
    };
    let parse_err = |e: serde_json::Error| value_err(format!("flow config: {e}"));
    let estimator = match method.unwrap_or("paper") {
        "paper" => {
            let config: FlowConfig = match json {
                None => FlowConfig::default(),
                Some(j) => serde_json::from_str(&j).map_err(parse_err)?,
            };
            AnyFlow::Paper(Box::new(
                FlowEstimator::new(config).map_err(|e| value_err(e.to_string()))?,
            ))
        }
        "fast" => {
            let config: FastFlowConfig = match json {
                None => FastFlowConfig::default(),
                Some(j) => serde_json::from_str(&j).map_err(parse_err)?,
            };
            AnyFlow::Fast(FastFlow::new(config).map_err(|e| value_err(e.to_string()))?)
        }
        other => {
            return Err(value_err(format!(
                "method: expected \"paper\" or \"fast\", got {other:?}"
            )));
        }
    };
    let input = FlowInput {
        fundamental: None,
        prior: None,
    };
    let (flow, timings) = py
        .detach(|| estimator.compute_timed(&a, &b, &input))
        .map_err(|e| value_err(format!("flow: {e}")))?;
    let (h, w) = (flow.height, flow.width);
    // row-major copies of the pixel-major fields (an indexed `from_shape_fn` cost 3 % of a fast
    // flow call)
    let shape_err = |e: numpy::ndarray::ShapeError| value_err(format!("flow arrays: {e}"));
    let uv =
        Array3::from_shape_vec((h, w, 2), flow.flow.as_flattened().to_vec()).map_err(shape_err)?;
    let info = Array3::from_shape_vec((h, w, 3), flow.information.as_flattened().to_vec())
        .map_err(shape_err)?;
    let valid = Array2::from_shape_vec((h, w), flow.valid.clone()).map_err(shape_err)?;
    Ok(DenseFlow {
        flow: PyArray3::from_owned_array(py, uv).unbind(),
        information: PyArray3::from_owned_array(py, info).unbind(),
        valid: PyArray2::from_owned_array(py, valid).unbind(),
        timings_ms: to_python(py, &timings)?,
    })
}

/// KITTI devkit metric, ATE and RPE of `est` against `gt` (N×4×4 or N×3×4 `world_from_cam`),
/// matched by index, as the dict `visnav eval --json` prints (without `files` and `written`).
#[pyfunction]
#[pyo3(signature = (gt, est, lengths=None))]
pub fn kitti_errors(
    py: Python<'_>,
    gt: &Bound<'_, PyAny>,
    est: &Bound<'_, PyAny>,
    lengths: Option<Vec<f64>>,
) -> PyResult<Py<PyAny>> {
    let gt = to_pose_matrices("gt", gt)?;
    let est = to_pose_matrices("est", est)?;
    let config = EvalConfig {
        kitti: KittiMetricConfig {
            lengths_m: lengths.unwrap_or_else(|| KittiMetricConfig::default().lengths_m),
            ..KittiMetricConfig::default()
        },
        ..EvalConfig::default()
    };
    let pairs = [TrajectoryPair {
        gt: &gt,
        est: &est,
        gt_timestamps: None,
        est_timestamps: None,
    }];
    let report = py
        .detach(|| evaluate(&pairs, &config))
        .map_err(|e| to_py_err(visnav_pipeline::job::ErrorKind::BadInput, &e))?;
    let out = to_python(py, &report)?;
    out.bind(py).set_item("config", to_python(py, &config)?)?;
    Ok(out)
}
