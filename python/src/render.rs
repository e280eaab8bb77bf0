//! `RenderDelegate.render` for Python: settings from a dict, the render with the GIL released,
//! and Python callables told of the progress and handed each pass's image.
//!
//! The render runs on a thread of its own while the calling thread, without the GIL, watches
//! for Ctrl-C: Python runs signal handlers only on its main thread, so the render threads cannot
//! see a KeyboardInterrupt; the caller's thread polls them (`PyErr_CheckSignals`) every
//! [`SIGNAL_POLL`], and a pending KeyboardInterrupt cancels the render (sync, pre-pass and
//! tiles check the flag) and is raised as soon as the render threads have stopped. The
//! callables are called from the render thread, which takes the GIL only for the call. An
//! exception in the `on_update` callable is kept, cancels the render (no further pass starts),
//! and is raised to `render`'s caller as it was raised: nothing unwinds through Rust. With
//! `pass_output`, each pass but the last is written to an image file by the render thread
//! ([`hd_mipray::render_buffer::write_buffers`]), with no Python in between.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

use hd_mipray::render_buffer::{write_buffers, RenderBuffer};
use hd_mipray::render_pass::PassUpdate;
use hd_mipray::{RenderDelegate as Delegate, RenderPass};
use mipray::image_io::MetaValue;
use mipray::image_output::WriteOptions;
use mipray::progress::Progress;
use numpy::ndarray::ArrayView3;
use numpy::{PyArray3, PyArrayMethods};
use pyo3::exceptions::{PyKeyError, PyKeyboardInterrupt, PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyIterator, PyList};

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
        // JSON has no infinity (serde_json would make it null, refused as "not a finite
        // number"): the settings table spells it `inf` (`aoDistance`, `geometryMemoryMb`).
        if f == f64::INFINITY {
            return Ok("inf".into());
        }
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

/// How often the calling thread runs Python's signal handlers while a render runs: Ctrl-C
/// stops a render within this plus the time a render thread takes to reach its next check (a
/// pixel's samples, a mesh's sync).
pub(crate) const SIGNAL_POLL: Duration = Duration::from_millis(20);

/// Forwards progress to a Python callable `(done, total)` about every 1%; cancelled by Ctrl-C
/// (see [`run_watched`]) or a failed `on_update` or pass write.
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
        if let Some(cb) = &self.callback {
            Python::attach(|py| {
                if let Err(e) = cb.call1(py, (done, total)) {
                    log::warn!("progress callback failed: {e}");
                }
            });
        }
    }

    fn cancelled(&self) -> bool {
        self.cancelled.load(Ordering::Relaxed)
    }
}

/// A render's (or one pass's) AOVs, kept in the buffers the render filled: a read-only mapping
/// from AOV name to an H×W×C float32 numpy array that views the buffer in place. Each
/// `buffers[name]` is a new array object over the same memory, which it keeps alive; nothing is
/// copied, neither here nor when `write_image` writes the arrays. The arrays are read-only:
/// `frozen` makes the buffers immutable for Rust (the writer reads them with the GIL released),
/// and numpy refuses to make a borrowed array writeable again. Not a module attribute: only
/// `render` makes these, and the stub calls it a `Mapping`.
#[pyclass(module = "mipray._mipray", frozen)]
pub(crate) struct RenderBuffers {
    buffers: Vec<RenderBuffer>,
}

impl RenderBuffers {
    fn find(&self, name: &str) -> PyResult<&RenderBuffer> {
        self.buffers.iter().find(|b| b.aov == name).ok_or_else(|| PyKeyError::new_err(name.to_string()))
    }

    /// A read-only H×W×C view of `this`'s AOV `name`, whose base is `this`.
    fn view<'py>(this: &Bound<'py, Self>, name: &str) -> PyResult<Bound<'py, PyArray3<f32>>> {
        let b = this.get().find(name)?;
        let shaped =
            ArrayView3::from_shape((b.height, b.width, b.channels), &b.data).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        // SAFETY: the array's base is `this`, which owns `b.data`; the class is frozen and has no
        // method that touches `buffers`, so the Vec is neither dropped nor reallocated while
        // the array (or any array over it) lives.
        let array = unsafe { PyArray3::borrow_from_array(&shaped, this.clone().into_any()) };
        // A new array has no other borrow, so taking it writable cannot fail.
        let readonly = array.try_readwrite().map_err(|e| PyRuntimeError::new_err(e.to_string()))?.make_nonwriteable();
        Ok((*readonly).clone())
    }
}

#[pymethods]
impl RenderBuffers {
    fn __len__(&self) -> usize {
        self.buffers.len()
    }

    fn __contains__(&self, name: &str) -> bool {
        self.buffers.iter().any(|b| b.aov == name)
    }

    fn __getitem__<'py>(this: &Bound<'py, Self>, name: &str) -> PyResult<Bound<'py, PyArray3<f32>>> {
        Self::view(this, name)
    }

    fn __iter__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyIterator>> {
        PyList::new(py, self.keys())?.as_any().try_iter()
    }

    /// The AOV names, in the render's order.
    fn keys(&self) -> Vec<String> {
        self.buffers.iter().map(|b| b.aov.clone()).collect()
    }

    /// A view of each AOV, in the render's order.
    fn values<'py>(this: &Bound<'py, Self>) -> PyResult<Vec<Bound<'py, PyArray3<f32>>>> {
        this.get().buffers.iter().map(|b| Self::view(this, &b.aov)).collect()
    }

    /// `(name, view)` for each AOV, in the render's order.
    fn items<'py>(this: &Bound<'py, Self>) -> PyResult<Vec<(String, Bound<'py, PyArray3<f32>>)>> {
        this.get().buffers.iter().map(|b| Ok((b.aov.clone(), Self::view(this, &b.aov)?))).collect()
    }

    /// A view of AOV `name`, or `default` when the render has none.
    #[pyo3(signature = (name, default=None))]
    fn get<'py>(this: &Bound<'py, Self>, name: &str, default: Option<Bound<'py, PyAny>>) -> PyResult<Option<Bound<'py, PyAny>>> {
        if this.get().__contains__(name) {
            return Ok(Some(Self::view(this, name)?.into_any()));
        }
        Ok(default)
    }

    fn __repr__(&self) -> String {
        let shapes: Vec<String> = self.buffers.iter().map(|b| format!("'{}': {}x{}x{}", b.aov, b.height, b.width, b.channels)).collect();
        format!("RenderBuffers({{{}}})", shapes.join(", "))
    }
}

/// `{aov: read-only H×W×C float32 view}` over `buffers`, moved into a [`RenderBuffers`] that the
/// views keep alive: a caller may keep one pass's arrays while later passes render (each pass
/// has buffers of its own).
fn buffers_dict(py: Python<'_>, buffers: Vec<RenderBuffer>) -> PyResult<Bound<'_, PyDict>> {
    let owner = Bound::new(py, RenderBuffers { buffers })?;
    let dict = PyDict::new(py);
    for (name, view) in RenderBuffers::items(&owner)? {
        dict.set_item(name, view)?;
    }
    Ok(dict)
}

/// Where `render`'s `pass_output` writes each pass but the last.
pub(crate) struct PassOutput {
    pub path: PathBuf,
    /// `atomic`: a reader of the file never sees half an image.
    pub options: WriteOptions,
}

impl PassOutput {
    /// `{"path": str, "aovs": [names] (default: all rendered), "color_correction": "sRGB" or
    /// "disabled", "metadata": {name: value}}`, as `write_image` takes them.
    pub(crate) fn from_py(d: &Bound<'_, PyDict>) -> PyResult<Self> {
        let mut path = None;
        let mut options = WriteOptions { atomic: true, ..Default::default() };
        for (k, v) in d.iter() {
            let key: String = k.extract()?;
            match key.as_str() {
                "path" => path = Some(PathBuf::from(v.extract::<String>()?)),
                "aovs" => options.order = v.extract()?,
                "color_correction" => options.color_correction = crate::color_correction(&v.extract::<String>()?)?,
                "metadata" => options.metadata = crate::metadata(Some(v.cast::<PyDict>()?))?,
                _ => {
                    return Err(PyValueError::new_err(format!("pass_output: unknown key '{key}' (path, aovs, color_correction, metadata)")))
                }
            }
        }
        let path = path.ok_or_else(|| PyValueError::new_err("pass_output needs a 'path'"))?;
        Ok(PassOutput { path, options })
    }

    /// Writes pass `update` (not the last: that one is the caller's to write with the render's
    /// stats), tagged with its samples per pixel.
    fn write(&self, update: &PassUpdate) -> Result<(), mipray::error::ImageError> {
        let mut options = self.options.clone();
        options.metadata.push(("mipray:progressiveSamples".into(), MetaValue::Int(i64::from(update.samples))));
        write_buffers(&self.path, &update.buffers, &options)
    }
}

/// Hands one pass to `pass_output` (written from the render thread, no GIL) and to `on_update`
/// as `(samples, converged, {aov: array})`. The first failure (an exception of `on_update`, an
/// `OSError` of the write) is kept in `failed` and cancels the render; after it (or after
/// Ctrl-C) no further update is delivered.
fn deliver(
    on_update: Option<&Py<PyAny>>,
    output: Option<&PassOutput>,
    update: PassUpdate,
    progress: &PyProgress,
    failed: &Mutex<Option<PyErr>>,
) {
    if progress.cancelled() {
        return;
    }
    if let Some(out) = output.filter(|_| !update.converged) {
        if let Err(e) = out.write(&update) {
            failed.lock().unwrap_or_else(PoisonError::into_inner).get_or_insert(PyOSError::new_err(e.to_string()));
            progress.cancel();
            return;
        }
    }
    let Some(on_update) = on_update else { return };
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

/// Runs `work` on a thread of its own while this thread (the caller's, without the GIL) runs
/// Python's signal handlers every [`SIGNAL_POLL`] until it ends: the first exception they raise
/// (KeyboardInterrupt for Ctrl-C) is kept in `interrupted` and cancels `progress`, so the work
/// stops at its next check. Returns the work's result, or its panic's payload.
fn run_watched<T: Send>(
    work: impl FnOnce() -> T + Send,
    progress: &PyProgress,
    interrupted: &Mutex<Option<PyErr>>,
) -> std::thread::Result<T> {
    std::thread::scope(|scope| {
        let worker = scope.spawn(work);
        while !worker.is_finished() {
            std::thread::park_timeout(SIGNAL_POLL);
            if interrupted.lock().unwrap_or_else(PoisonError::into_inner).is_some() {
                continue;
            }
            Python::attach(|py| {
                if let Err(e) = py.check_signals() {
                    interrupted.lock().unwrap_or_else(PoisonError::into_inner).get_or_insert(e);
                    progress.cancel();
                }
            });
        }
        worker.join()
    })
}

/// Runs `pass` on `delegate` with the GIL released; returns the AOVs (a [`RenderBuffers`]:
/// `{aov: H×W×C float32}` viewed in place) and the stats JSON. With `on_update`, it is called after every pass (one for a render of fixed sample
/// count; 1, 2, 4, … samples with the `progressive` setting), the last with `converged` true;
/// with `pass_output`, every pass but the last is written to its file.
///
/// # Errors
/// `KeyboardInterrupt` (or what another signal handler raised) when Ctrl-C stopped the render,
/// `ValueError` for bad prims or settings, the callback's own exception when `on_update` raised
/// (even on the last pass), `OSError` when a pass could not be written, else `RuntimeError` (an
/// internal error: a panic outside any one prim's work).
pub(crate) fn render<'py>(
    py: Python<'py>,
    delegate: &mut Delegate,
    pass: &RenderPass,
    progress: Option<Py<PyAny>>,
    on_update: Option<Py<PyAny>>,
    pass_output: Option<PassOutput>,
) -> PyResult<(Bound<'py, RenderBuffers>, String)> {
    let prog = PyProgress::new(progress);
    let failed: Mutex<Option<PyErr>> = Mutex::new(None);
    let interrupted: Mutex<Option<PyErr>> = Mutex::new(None);
    let work = || {
        if on_update.is_none() && pass_output.is_none() {
            return pass.execute(delegate, &prog);
        }
        let on_pass = |u: PassUpdate| deliver(on_update.as_ref(), pass_output.as_ref(), u, &prog, &failed);
        pass.execute_with_updates(delegate, &prog, &on_pass)
    };
    // The last line of defence: a panic that escaped the per-prim isolation (sync, tracing) is
    // one error line, never a `PanicException` (which is not an `Exception`) in the host.
    let result = py.detach(|| run_watched(work, &prog, &interrupted)).unwrap_or_else(|payload| {
        Err(hd_mipray::DelegateError::Render(mipray::error::RenderError::Internal(mipray::dropped::panic_message(payload.as_ref()))))
    });
    forward_logs(py);
    // Ctrl-C first: whatever else happened to the render, the user asked it to stop.
    if let Some(e) = interrupted.into_inner().unwrap_or_else(PoisonError::into_inner) {
        return Err(e);
    }
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
        // Settings the render refused (a resolution whose image cannot fit, …): the caller's
        // to fix, not an internal error.
        Err(hd_mipray::DelegateError::Render(mipray::error::RenderError::Settings(e))) => return Err(PyValueError::new_err(e)),
        Err(e) => return Err(PyRuntimeError::new_err(e.to_string())),
    };
    Ok((Bound::new(py, RenderBuffers { buffers: result.buffers })?, result.stats.to_string()))
}
