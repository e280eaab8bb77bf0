//! `RenderDelegate.render` for Python: settings from a dict, the render with the GIL released,
//! and Python callables told of the progress and handed each pass's image.
//!
//! The render runs on a rayon thread while the calling thread waits without the GIL; the
//! callables are called from the render thread, which takes the GIL only for the call. An
//! exception in the `on_update` callable is kept, cancels the render (no further pass starts),
//! and is raised to `render`'s caller as it was raised: nothing unwinds through Rust.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Mutex, PoisonError};

use hd_mipray::render_buffer::RenderBuffer;
use hd_mipray::render_pass::PassUpdate;
use hd_mipray::{RenderDelegate as Delegate, RenderPass};
use mipray::progress::Progress;
use numpy::ndarray::Array3;
use numpy::IntoPyArray;
use pyo3::exceptions::{PyKeyboardInterrupt, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::forward_logs;

/// A setting's value from Python as the delegate's settings take it.
pub(crate) fn py_to_json(v: &Bound<'_, PyAny>) -> PyResult<serde_json::Value> {
    if let Ok(b) = v.extract::<bool>() {
        return Ok(b.into());
    }
    if let Ok(i) = v.extract::<i64>() {
        return Ok(i.into());
    }
    if let Ok(f) = v.extract::<f64>() {
        return Ok(f.into());
    }
    if let Ok(s) = v.extract::<String>() {
        return Ok(s.into());
    }
    // A window (`crop`): a tuple or list of numbers.
    if let Ok(items) = v.extract::<Vec<f64>>() {
        return Ok(items.into());
    }
    Err(PyValueError::new_err(format!("setting value {v} must be a bool, number, string or list of numbers")))
}

/// Forwards progress to a Python callable `(done, total)` about every 1%, and turns Ctrl-C
/// (a pending KeyboardInterrupt) into cancellation.
struct PyProgress {
    callback: Option<Py<PyAny>>,
    total: AtomicU64,
    done: AtomicU64,
    last: AtomicU64,
    cancelled: AtomicBool,
}

impl PyProgress {
    fn new(callback: Option<Py<PyAny>>) -> Self {
        PyProgress {
            callback,
            total: AtomicU64::new(0),
            done: AtomicU64::new(0),
            last: AtomicU64::new(0),
            cancelled: AtomicBool::new(false),
        }
    }

    fn cancel(&self) {
        self.cancelled.store(true, Ordering::Relaxed);
    }
}

impl Progress for PyProgress {
    fn start(&self, total: u64) {
        self.total.store(total, Ordering::Relaxed);
    }

    fn advance(&self, n: u64) {
        let done = self.done.fetch_add(n, Ordering::Relaxed) + n;
        let total = self.total.load(Ordering::Relaxed).max(1);
        let last = self.last.load(Ordering::Relaxed);
        if done * 100 / total == last * 100 / total && done < total {
            return;
        }
        self.last.store(done, Ordering::Relaxed);
        Python::attach(|py| {
            if py.check_signals().is_err() {
                self.cancel();
                return;
            }
            if let Some(cb) = &self.callback {
                if let Err(e) = cb.call1(py, (done, total)) {
                    log::warn!("progress callback failed: {e}");
                }
            }
        });
    }

    fn cancelled(&self) -> bool {
        self.cancelled.load(Ordering::Relaxed)
    }
}

/// Render buffers as `{aov: H×W×C float32 array}`, in the pass's order. The arrays own their
/// pixels: a caller may keep one pass's arrays while later passes render.
fn buffers_dict(py: Python<'_>, buffers: Vec<RenderBuffer>) -> PyResult<Bound<'_, PyDict>> {
    let dict = PyDict::new(py);
    for b in buffers {
        let arr = Array3::from_shape_vec((b.height, b.width, b.channels), b.data).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        dict.set_item(b.aov, arr.into_pyarray(py))?;
    }
    Ok(dict)
}

/// Hands one pass to `on_update` as `(samples, converged, {aov: array})`, from the render
/// thread. The first exception is kept in `failed` and cancels the render; after it (or after
/// Ctrl-C) no further update is delivered.
fn deliver(on_update: &Py<PyAny>, update: PassUpdate, progress: &PyProgress, failed: &Mutex<Option<PyErr>>) {
    if progress.cancelled() {
        return;
    }
    Python::attach(|py| {
        // Warnings of the passes so far reach Python's logging while the render converges.
        forward_logs(py);
        let called = buffers_dict(py, update.buffers).and_then(|d| on_update.call1(py, (update.samples, update.converged, d)));
        if let Err(e) = called {
            failed.lock().unwrap_or_else(PoisonError::into_inner).get_or_insert(e);
            progress.cancel();
        }
    });
}

/// Runs `pass` on `delegate` with the GIL released; returns `({aov: H×W×C float32}, stats
/// JSON)`. With `on_update`, it is called after every pass (one for a render of fixed sample
/// count; 1, 2, 4, … samples with the `progressive` setting), the last with `converged` true.
///
/// # Errors
/// `ValueError` for bad prims or settings, `KeyboardInterrupt` when cancelled by Ctrl-C, the
/// callback's own exception when `on_update` raised (even on the last pass), else
/// `RuntimeError` (an internal error: a panic outside any one prim's work).
pub(crate) fn render<'py>(
    py: Python<'py>,
    delegate: &mut Delegate,
    pass: &RenderPass,
    progress: Option<Py<PyAny>>,
    on_update: Option<Py<PyAny>>,
) -> PyResult<(Bound<'py, PyDict>, String)> {
    let prog = PyProgress::new(progress);
    let failed: Mutex<Option<PyErr>> = Mutex::new(None);
    // The last line of defence: a panic that escaped the per-prim isolation (sync, tracing) is
    // one error line, never a `PanicException` (which is not an `Exception`) in the host.
    let run = std::panic::AssertUnwindSafe(|| match &on_update {
        None => py.detach(|| pass.execute(delegate, &prog)),
        Some(cb) => {
            let on_pass = |u: PassUpdate| deliver(cb, u, &prog, &failed);
            py.detach(|| pass.execute_with_updates(delegate, &prog, &on_pass))
        }
    });
    let result = std::panic::catch_unwind(run).unwrap_or_else(|payload| {
        Err(hd_mipray::DelegateError::Render(mipray::error::RenderError::Internal(mipray::dropped::panic_message(payload.as_ref()))))
    });
    forward_logs(py);
    if let Some(e) = failed.into_inner().unwrap_or_else(PoisonError::into_inner) {
        return Err(e);
    }
    let result = match result {
        Ok(r) => r,
        Err(hd_mipray::DelegateError::Render(mipray::error::RenderError::Cancelled)) => {
            return Err(PyKeyboardInterrupt::new_err("render cancelled"))
        }
        Err(e @ hd_mipray::DelegateError::Prim { .. }) => return Err(PyValueError::new_err(e.to_string())),
        Err(e @ hd_mipray::DelegateError::Setting(_)) => return Err(PyValueError::new_err(e.to_string())),
        Err(e) => return Err(PyRuntimeError::new_err(e.to_string())),
    };
    Ok((buffers_dict(py, result.buffers)?, result.stats.to_string()))
}
