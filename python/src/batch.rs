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
/// Ctrl-C, SIGTERM or SIGHUP stop the run after the frame in progress, as `visnav batch`: the
/// frames done are written, `status.json` says `"interrupted"`, and the signal's exception
/// (`KeyboardInterrupt`) is raised with that status as its `status` attribute.
#[pyfunction]
#[pyo3(signature = (manifest, index, skip_existing=false))]
pub fn run_manifest_line(
    py: Python<'_>,
    manifest: PathBuf,
    index: usize,
    skip_existing: bool,
) -> PyResult<Py<PyAny>> {
    let (outcome, raised) = crate::signals::with_stop_signals(py, |stop| {
        visnav_batch::run_line_until(&manifest, index, skip_existing, stop)
    })?;
    let outcome = outcome.map_err(|e| batch_err(&e))?;
    let json = match outcome {
        LineOutcome::Done(status) | LineOutcome::Interrupted(status) => {
            serde_json::to_value(&*status)
        }
        LineOutcome::Skipped(path) => Ok(serde_json::json!({
            "status": "skipped",
            "status_file": path,
            "index": index,
        })),
    }
    .map_err(|e| crate::value_err(e.to_string()))?;
    let text = json.to_string();
    let status = py.import("json")?.call_method1("loads", (text,))?;
    match raised {
        // the frames done and status.json ("interrupted") are written; the status goes with
        // the exception as its `status`
        Some(e) => {
            if let Err(err) = e.value(py).setattr("status", &status) {
                err.write_unraisable(py, None);
            }
            Err(e)
        }
        None => Ok(status.unbind()),
    }
}

/// The number of runs in a manifest.
#[pyfunction]
pub fn manifest_len(py: Python<'_>, manifest: PathBuf) -> PyResult<usize> {
    py.detach(|| visnav_batch::read_manifest(&manifest))
        .map(|l| l.len())
        .map_err(|e| batch_err(&e))
}
