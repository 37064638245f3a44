//! `visnav.run_manifest_line`: one line of a batch manifest, exactly as `visnav batch --index`
//! (`visnav_batch::run_line`), for engines driven from Python (Ray).

use std::path::PathBuf;

use pyo3::prelude::*;
use visnav_batch::{BatchError, LineOutcome};

use crate::to_py_err;

fn batch_err(e: &BatchError) -> PyErr {
    to_py_err(e.kind(), e)
}

/// Runs line `index` (0-based, blank and `#` lines not counted) of a JSON-lines manifest and
/// writes `poses.txt`, `report.json` and `status.json` into its output directory. Returns the
/// status as a dict (`{"status": "skipped", ...}` when `skip_existing` found a finished run).
/// Raises `ValueError` (bad input: do not retry), `FileNotFoundError` or `OSError` (I/O: retry).
#[pyfunction]
#[pyo3(signature = (manifest, index, skip_existing=false))]
pub fn run_manifest_line(
    py: Python<'_>,
    manifest: PathBuf,
    index: usize,
    skip_existing: bool,
) -> PyResult<Py<PyAny>> {
    let outcome = py
        .detach(|| visnav_batch::run_line(&manifest, index, skip_existing))
        .map_err(|e| batch_err(&e))?;
    let json = match outcome {
        LineOutcome::Done(status) => serde_json::to_value(&*status),
        LineOutcome::Skipped(path) => Ok(serde_json::json!({
            "status": "skipped",
            "status_file": path,
            "index": index,
        })),
    }
    .map_err(|e| crate::value_err(e.to_string()))?;
    let text = json.to_string();
    Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
}

/// The number of runs in a manifest.
#[pyfunction]
pub fn manifest_len(py: Python<'_>, manifest: PathBuf) -> PyResult<usize> {
    py.detach(|| visnav_batch::read_manifest(&manifest))
        .map(|l| l.len())
        .map_err(|e| batch_err(&e))
}
