//! `visnav.open_sequence`: every input layout `visnav_io::Sequence` reads, as a Python sequence
//! of frames; the camera of a sequence.

use std::path::PathBuf;

use numpy::{PyArray1, PyArray2};
use pyo3::exceptions::PyIndexError;
use pyo3::prelude::*;
use visnav_core::{PinholeCamera, StereoCamera};
use visnav_io::FrameSource as _;

use crate::arrays::{image_f32, image_u8};
use crate::{io_err, value_err};

/// A rectified pinhole camera (pixels), with the stereo baseline (metres) when it is the left
/// camera of a rectified stereo rig.
#[pyclass(module = "visnav", frozen, eq)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Focal length along x, pixels.
    #[pyo3(get)]
    pub fx: f64,
    /// Focal length along y, pixels.
    #[pyo3(get)]
    pub fy: f64,
    /// Principal point x, pixels.
    #[pyo3(get)]
    pub cx: f64,
    /// Principal point y, pixels.
    #[pyo3(get)]
    pub cy: f64,
    /// Image width, pixels.
    #[pyo3(get)]
    pub width: u32,
    /// Image height, pixels.
    #[pyo3(get)]
    pub height: u32,
    /// Stereo baseline, metres (right camera at `+baseline_m` along x of the left one).
    #[pyo3(get)]
    pub baseline_m: Option<f64>,
}

#[pymethods]
impl Camera {
    #[new]
    #[pyo3(signature = (fx, fy, cx, cy, width, height, baseline_m=None))]
    fn py_new(
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        width: u32,
        height: u32,
        baseline_m: Option<f64>,
    ) -> PyResult<Self> {
        let c = Self {
            fx,
            fy,
            cx,
            cy,
            width,
            height,
            baseline_m,
        };
        c.pinhole()?;
        if baseline_m.is_some() {
            c.stereo()?;
        }
        Ok(c)
    }

    fn __repr__(&self) -> String {
        format!(
            "Camera(fx={}, fy={}, cx={}, cy={}, width={}, height={}, baseline_m={})",
            self.fx,
            self.fy,
            self.cx,
            self.cy,
            self.width,
            self.height,
            self.baseline_m
                .map_or_else(|| "None".into(), |b| b.to_string())
        )
    }
}

impl Camera {
    /// The camera of a sequence (with its baseline when it has a calibrated right camera).
    pub(crate) fn of(camera: &PinholeCamera, rig: Option<StereoCamera>) -> Self {
        Self {
            fx: camera.fx,
            fy: camera.fy,
            cx: camera.cx,
            cy: camera.cy,
            width: camera.width,
            height: camera.height,
            baseline_m: rig.map(|r| r.baseline_m),
        }
    }

    /// The pinhole camera, checked.
    pub(crate) fn pinhole(&self) -> PyResult<PinholeCamera> {
        let ok = [self.fx, self.fy, self.cx, self.cy]
            .iter()
            .all(|v| v.is_finite())
            && self.fx > 0.0
            && self.fy > 0.0
            && self.width > 0
            && self.height > 0;
        if !ok {
            return Err(value_err(format!(
                "invalid camera {}: focal lengths must be positive and finite, the size positive",
                self.__repr__()
            )));
        }
        Ok(PinholeCamera {
            fx: self.fx,
            fy: self.fy,
            cx: self.cx,
            cy: self.cy,
            width: self.width,
            height: self.height,
        })
    }

    /// The stereo rig.
    pub(crate) fn stereo(&self) -> PyResult<StereoCamera> {
        let Some(b) = self.baseline_m else {
            return Err(value_err(
                "StereoOdometry needs a stereo camera: a Camera with baseline_m (e.g. the .camera of a stereo sequence)",
            ));
        };
        StereoCamera::new(self.pinhole()?, b)
            .map_err(|e| value_err(format!("invalid stereo camera: {e}")))
    }
}

/// One frame of a sequence.
#[pyclass(module = "visnav", frozen)]
pub struct Frame {
    /// Frame index in the sequence.
    #[pyo3(get)]
    pub index: usize,
    /// Left (or only) image, H×W uint8.
    #[pyo3(get)]
    pub left: Py<PyArray2<u8>>,
    /// Right image, H×W uint8, or None.
    #[pyo3(get)]
    pub right: Option<Py<PyArray2<u8>>>,
    /// Left image, H×W float32: the exact grey values (0..255) the odometry sees (they differ from
    /// `left` only for undistorted / rectified inputs).
    #[pyo3(get)]
    pub left_f32: Py<PyArray2<f32>>,
    /// Right image as float32, or None.
    #[pyo3(get)]
    pub right_f32: Option<Py<PyArray2<f32>>>,
    /// Timestamp, seconds, when the dataset has its own (EuRoC, TUM); None otherwise.
    #[pyo3(get)]
    pub timestamp: Option<f64>,
}

/// An opened input (see `visnav.open_sequence`).
#[pyclass(module = "visnav", frozen)]
pub struct Sequence {
    pub(crate) inner: visnav_io::Sequence,
    path: PathBuf,
}

#[pymethods]
impl Sequence {
    fn __len__(&self) -> usize {
        self.inner.len()
    }

    fn __getitem__(&self, py: Python<'_>, index: isize) -> PyResult<Frame> {
        let n = self.inner.len();
        let i = if index < 0 { index + n as isize } else { index };
        if i < 0 || i as usize >= n {
            return Err(PyIndexError::new_err(format!(
                "frame {index} out of range for a sequence of {n} frames"
            )));
        }
        self.frame(py, i as usize)
    }

    fn __iter__(slf: PyRef<'_, Self>) -> SequenceIter {
        SequenceIter {
            sequence: slf.into(),
            next: 0,
        }
    }

    /// The rectified left camera (with the baseline when the sequence is stereo).
    #[getter]
    fn camera(&self) -> Camera {
        Camera::of(&self.inner.camera, self.inner.stereo_camera())
    }

    /// The path given to `open_sequence`.
    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    /// Whether the frames have a right image.
    #[getter]
    fn has_stereo(&self) -> bool {
        self.inner.has_stereo()
    }

    /// Timestamps of the frames, seconds (KITTI: its `times.txt`; without timestamps frame
    /// index × 0.1 s).
    #[getter]
    fn timestamps<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.timestamps)
    }

    fn __repr__(&self) -> String {
        format!(
            "visnav.Sequence({:?}, {} frames, {})",
            self.path.display().to_string(),
            self.inner.len(),
            if self.inner.has_stereo() {
                "stereo"
            } else {
                "mono"
            }
        )
    }
}

impl Sequence {
    fn frame(&self, py: Python<'_>, i: usize) -> PyResult<Frame> {
        let seq = &self.inner;
        let frame = py.detach(|| seq.load(i, true)).map_err(|e| io_err(&e))?;
        Ok(Frame {
            index: i,
            left: image_u8(py, &frame.left).unbind(),
            right: frame.right.as_ref().map(|r| image_u8(py, r).unbind()),
            left_f32: image_f32(py, &frame.left).unbind(),
            right_f32: frame.right.as_ref().map(|r| image_f32(py, r).unbind()),
            timestamp: seq.timestamp_s(i),
        })
    }
}

/// Iterator over the frames of a [`Sequence`].
#[pyclass(module = "visnav")]
pub struct SequenceIter {
    sequence: Py<Sequence>,
    next: usize,
}

#[pymethods]
impl SequenceIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self, py: Python<'_>) -> PyResult<Option<Frame>> {
        let seq = self.sequence.get();
        if self.next >= seq.inner.len() {
            return Ok(None);
        }
        let f = seq.frame(py, self.next)?;
        self.next += 1;
        Ok(Some(f))
    }
}

/// Opens any input `visnav odometry` reads (KITTI odometry or raw, EuRoC, TUM RGB-D, TUM
/// monoVO, image folders, video), with an optional camera file.
#[pyfunction]
#[pyo3(signature = (path, camera=None))]
pub fn open_sequence(py: Python<'_>, path: PathBuf, camera: Option<PathBuf>) -> PyResult<Sequence> {
    let inner = py
        .detach(|| visnav_io::Sequence::open_with_camera(&path, camera.as_deref()))
        .map_err(|e| io_err(&e))?;
    Ok(Sequence { inner, path })
}

/// Loads an image file as the CLI does (grey, float32, 0..255).
#[pyfunction]
pub fn load_image<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let img = py
        .detach(|| visnav_io::image_io::load_gray(&path))
        .map_err(|e| io_err(&e))?;
    Ok(image_f32(py, &img))
}
