//! Conversions between numpy arrays and the library's types.

use numpy::ndarray::{Array2, Array3};
use numpy::{PyArray2, PyArray3, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use visnav_core::{GrayImage, Pose};

use crate::value_err;

/// An image as an H×W uint8 array (values rounded and clamped to 0..255).
pub(crate) fn image_u8<'py>(py: Python<'py>, img: &GrayImage) -> Bound<'py, PyArray2<u8>> {
    let data: Vec<u8> = img
        .data()
        .iter()
        .map(|v| v.round().clamp(0.0, 255.0) as u8)
        .collect();
    let a = Array2::from_shape_vec((img.height(), img.width()), data)
        .unwrap_or_else(|_| Array2::zeros((0, 0)));
    PyArray2::from_owned_array(py, a)
}

/// An image as an H×W float32 array (the exact grey values the pipeline sees, 0..255).
pub(crate) fn image_f32<'py>(py: Python<'py>, img: &GrayImage) -> Bound<'py, PyArray2<f32>> {
    let a = Array2::from_shape_vec((img.height(), img.width()), img.data().to_vec())
        .unwrap_or_else(|_| Array2::zeros((0, 0)));
    PyArray2::from_owned_array(py, a)
}

/// An H×W numpy array (uint8, float32 or float64, grey values 0..255) as an image.
///
/// # Errors
/// `ValueError` for another shape or dtype, an empty image or a value that is not finite.
pub(crate) fn to_image(what: &str, array: &Bound<'_, PyAny>) -> PyResult<GrayImage> {
    let (w, h, data) = if let Ok(a) = array.cast::<PyArray2<u8>>() {
        let r = a.readonly();
        let v = r.as_array();
        (
            v.ncols(),
            v.nrows(),
            v.iter().map(|&x| f32::from(x)).collect(),
        )
    } else if let Ok(a) = array.cast::<PyArray2<f32>>() {
        let r = a.readonly();
        let v = r.as_array();
        (
            v.ncols(),
            v.nrows(),
            v.iter().copied().collect::<Vec<f32>>(),
        )
    } else if let Ok(a) = array.cast::<PyArray2<f64>>() {
        let r = a.readonly();
        let v = r.as_array();
        (v.ncols(), v.nrows(), v.iter().map(|&x| x as f32).collect())
    } else {
        return Err(value_err(format!(
            "{what}: expected an H×W numpy array of uint8, float32 or float64 grey values, got {}",
            describe(array)
        )));
    };
    if w == 0 || h == 0 {
        return Err(value_err(format!("{what}: the image is empty ({h}×{w})")));
    }
    if data.iter().any(|v: &f32| !v.is_finite()) {
        return Err(value_err(format!(
            "{what}: the image has a value that is not finite"
        )));
    }
    GrayImage::from_vec(w, h, data).ok_or_else(|| value_err(format!("{what}: bad image size")))
}

/// `type`, shape and dtype of a Python object, for error messages.
fn describe(obj: &Bound<'_, PyAny>) -> String {
    if let Ok(a) = obj.cast::<numpy::PyUntypedArray>() {
        format!("an array of shape {:?} and dtype {}", a.shape(), a.dtype())
    } else {
        obj.get_type()
            .name()
            .map_or_else(|_| "an object".into(), |n| format!("a {n}"))
    }
}

/// A pose as a 4×4 float64 matrix.
pub(crate) fn pose_matrix(p: &Pose) -> Array2<f64> {
    let m = p.to_homogeneous();
    Array2::from_shape_fn((4, 4), |(r, c)| m[(r, c)])
}

/// Poses as an N×4×4 float64 array.
pub(crate) fn poses_array<'py>(py: Python<'py>, poses: &[Pose]) -> Bound<'py, PyArray3<f64>> {
    let a = Array3::from_shape_fn((poses.len(), 4, 4), |(i, r, c)| {
        poses[i].to_homogeneous()[(r, c)]
    });
    PyArray3::from_owned_array(py, a)
}

/// An N×4×4 or N×3×4 float array as 4×4 pose matrices.
///
/// # Errors
/// `ValueError` for another shape or a value that is not finite.
pub(crate) fn to_pose_matrices(
    what: &str,
    array: &Bound<'_, PyAny>,
) -> PyResult<Vec<nalgebra::Matrix4<f64>>> {
    let np = array.py().import("numpy")?;
    let a = np
        .call_method1("asarray", (array, "float64"))
        .map_err(|e| value_err(format!("{what}: not a numeric array ({e})")))?;
    let a = a.cast::<PyArray3<f64>>().map_err(|_| {
        value_err(format!(
            "{what}: expected an N×4×4 or N×3×4 array of poses, got {}",
            describe(array)
        ))
    })?;
    let r = a.readonly();
    let v = r.as_array();
    let (n, rows, cols) = v.dim();
    if !((rows == 4 || rows == 3) && cols == 4) {
        return Err(value_err(format!(
            "{what}: expected an N×4×4 or N×3×4 array of poses, got shape ({n}, {rows}, {cols})"
        )));
    }
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut m = nalgebra::Matrix4::<f64>::identity();
        for r in 0..rows {
            for c in 0..4 {
                let x = v[(i, r, c)];
                if !x.is_finite() {
                    return Err(value_err(format!(
                        "{what}: pose {i} has a value that is not finite at ({r}, {c})"
                    )));
                }
                m[(r, c)] = x;
            }
        }
        out.push(m);
    }
    Ok(out)
}
