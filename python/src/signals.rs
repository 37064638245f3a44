//! Stop signals in the long calls (`run_odometry`, `run_manifest_line`), as in the CLI: a run
//! stops after the frame in progress when a signal's Python handler raises, its frames done are
//! kept (returned with the exception, or written by a batch line), and the exception is raised.
//!
//! What Python does without this: the call runs with the GIL released, so the SIGINT handler
//! (`KeyboardInterrupt`) runs only when the whole run has ended, and SIGTERM and SIGHUP, left at
//! their default action, end the process at once, with nothing returned or written. So for the
//! length of the call, on the main thread, SIGTERM and SIGHUP whose handler is the default get
//! Python's SIGINT handler (`signal.default_int_handler`, which raises `KeyboardInterrupt`);
//! the handlers are put back when the call returns. A handler the program installed itself is
//! left alone (and runs between frames).

use std::sync::Mutex;

use pyo3::prelude::*;
use pyo3::types::PyAnyMethods;

pyo3::create_exception!(
    visnav,
    Interrupted,
    pyo3::exceptions::PyKeyboardInterrupt,
    "A run stopped by a signal (Ctrl-C, SIGTERM, SIGHUP) after the frame in progress: a \
     KeyboardInterrupt whose `poses` attribute holds the frames done, (K, 4, 4)."
);

/// SIGTERM and SIGHUP set to raise `KeyboardInterrupt` for the guard's life (module docs).
struct SignalGuard<'py> {
    signal: Bound<'py, PyModule>,
    restore: Vec<(Py<PyAny>, Py<PyAny>)>,
}

impl<'py> SignalGuard<'py> {
    fn install(py: Python<'py>) -> PyResult<Self> {
        let signal = py.import("signal")?;
        let mut restore = Vec::new();
        let main = py
            .import("threading")?
            .call_method0("current_thread")?
            .is(&py.import("threading")?.call_method0("main_thread")?);
        if main {
            let default = signal.getattr("SIG_DFL")?;
            let raise = signal.getattr("default_int_handler")?;
            for name in ["SIGTERM", "SIGHUP"] {
                let Ok(number) = signal.getattr(name) else {
                    continue; // no SIGHUP on Windows
                };
                let old = signal.call_method1("getsignal", (&number,))?;
                if old.eq(&default)? {
                    signal.call_method1("signal", (&number, &raise))?;
                    restore.push((number.unbind(), old.unbind()));
                }
            }
        }
        Ok(Self { signal, restore })
    }
}

impl Drop for SignalGuard<'_> {
    fn drop(&mut self) {
        let py = self.signal.py();
        for (number, old) in &self.restore {
            if let Err(e) = self.signal.call_method1("signal", (number, old)) {
                e.write_unraisable(py, None);
            }
        }
    }
}

/// Runs `f` with the GIL released and a `stop()` that is true once a signal's Python handler
/// has raised (checked by the run after every frame); returns `f`'s result and that exception.
///
/// # Errors
/// The signal module cannot be used.
pub(crate) fn with_stop_signals<T: Send>(
    py: Python<'_>,
    f: impl FnOnce(&dyn Fn() -> bool) -> T + Send,
) -> PyResult<(T, Option<PyErr>)> {
    // a signal that came before the call is raised now, as Python would have
    py.check_signals()?;
    let _guard = SignalGuard::install(py)?;
    let raised: Mutex<Option<PyErr>> = Mutex::new(None);
    let result = py.detach(|| {
        let stop = || {
            Python::attach(|py| match py.check_signals() {
                Ok(()) => false,
                Err(e) => {
                    if let Ok(mut slot) = raised.lock() {
                        slot.get_or_insert(e);
                    }
                    true
                }
            }) || raised.lock().map_or(true, |r| r.is_some())
        };
        f(&stop)
    });
    let mut raised = raised
        .into_inner()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    // a signal after the last frame: the run is complete, the exception is still Python's
    if raised.is_none()
        && let Err(e) = py.check_signals()
    {
        raised = Some(e);
    }
    Ok((result, raised))
}

/// The exception to raise for a run stopped by `raised` with `poses` done: [`Interrupted`]
/// (message "interrupted: K of N poses …", `poses` attribute) for a `KeyboardInterrupt`, else
/// `raised` itself with the `poses` attribute added.
pub(crate) fn interrupted(
    py: Python<'_>,
    raised: PyErr,
    poses: &Bound<'_, PyAny>,
    done: usize,
    expected: usize,
) -> PyErr {
    let err = if raised.is_instance_of::<pyo3::exceptions::PyKeyboardInterrupt>(py) {
        let err = Interrupted::new_err(format!(
            "interrupted: {done} of {expected} poses (the frames done are in this exception's poses)"
        ));
        err.set_cause(py, Some(raised));
        err
    } else {
        raised
    };
    if let Err(e) = err.value(py).setattr("poses", poses) {
        e.write_unraisable(py, None);
    }
    err
}
