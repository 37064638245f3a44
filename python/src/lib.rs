//! The native part of the `visnav` Python package (`visnav._visnav`): thin wrappers over the
//! library crates. No pipeline logic lives here: runs are set up by `visnav_pipeline::job`
//! (the same code as `visnav odometry`), flow by `visnav_flow`, scores by `visnav_eval`.
//! Heavy work runs with the GIL released (`Python::detach`, formerly `allow_threads`).

use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyValueError};
use pyo3::prelude::*;
use visnav_pipeline::job::{ErrorKind, JobError, error_chain};

/// mimalloc, as in the CLI: the flow and stereo stages allocate and free image-sized buffers
/// every frame, and with glibc's allocator each is a fresh `mmap` whose pages fault in on first
/// write; the extension ran the 06 stereo clip 15–25 % slower than the CLI without it
/// (docs/notes/2026-12-02-mono-history.md, *Python API*). Only the extension's own Rust
/// allocations use it; arrays handed to
/// numpy are freed by the same allocator when Python drops them.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

mod arrays;
mod batch;
mod odometry;
mod scores;
mod sequence;
mod signals;

/// The Python exception of an error kind, with the whole error chain as its message.
pub(crate) fn to_py_err(kind: ErrorKind, e: &(dyn std::error::Error + 'static)) -> PyErr {
    let message = error_chain(e);
    match kind {
        ErrorKind::NotFound => PyFileNotFoundError::new_err(message),
        ErrorKind::Io => PyOSError::new_err(message),
        ErrorKind::BadInput => PyValueError::new_err(message),
    }
}

/// A [`JobError`] as a Python exception (`FileNotFoundError`, `OSError` or `ValueError`).
pub(crate) fn job_err(e: &JobError) -> PyErr {
    to_py_err(e.kind(), e)
}

/// A `visnav_io` error as a Python exception.
pub(crate) fn io_err(e: &visnav_io::IoError) -> PyErr {
    to_py_err(ErrorKind::of_io(e), e)
}

/// A bad argument.
pub(crate) fn value_err(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}

/// The native module.
#[pymodule]
fn _visnav(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // numpy's C API is loaded now, not by the first array a call returns: loaded then, with a
    // Ctrl-C pending from the call, its import raised KeyboardInterrupt and rust-numpy
    // panicked (issue 53: Ctrl-C during `run_odometry` ended in a PanicException)
    m.py().import("numpy")?;
    let _ = numpy::PyArray1::<f64>::zeros(m.py(), 0, false);
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("Interrupted", m.py().get_type::<signals::Interrupted>())?;
    m.add_class::<sequence::Camera>()?;
    m.add_class::<sequence::Frame>()?;
    m.add_class::<sequence::Sequence>()?;
    m.add_class::<sequence::SequenceIter>()?;
    m.add_class::<odometry::FrameResult>()?;
    m.add_class::<odometry::StereoOdometry>()?;
    m.add_class::<odometry::MonoOdometry>()?;
    m.add_class::<scores::DenseFlow>()?;
    m.add_function(wrap_pyfunction!(sequence::open_sequence, m)?)?;
    m.add_function(wrap_pyfunction!(sequence::load_image, m)?)?;
    m.add_function(wrap_pyfunction!(odometry::run_odometry, m)?)?;
    m.add_function(wrap_pyfunction!(scores::dense_flow, m)?)?;
    m.add_function(wrap_pyfunction!(scores::kitti_errors, m)?)?;
    m.add_function(wrap_pyfunction!(batch::run_manifest_line, m)?)?;
    m.add_function(wrap_pyfunction!(batch::manifest_len, m)?)?;
    Ok(())
}
