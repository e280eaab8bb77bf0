//! Progress reporting and cancellation, as a small trait: the command draws a bar on a terminal,
//! Python forwards to a callback, tests ignore it.

use std::sync::atomic::{AtomicBool, Ordering};

/// Receives progress from a render. Called from render threads: implementations must be cheap
/// and thread safe.
pub trait Progress: Sync {
    /// The render is starting `total` units of work (pixel samples: pixels × samples per pixel).
    fn start(&self, _total: u64) {}
    /// `n` more units are done.
    fn advance(&self, _n: u64) {}
    /// A pass over the whole image is done: `film` is the image averaged over the first
    /// `samples` samples per pixel. Called once per pass, in order, between passes (no render
    /// thread is writing the film meanwhile): once for a render of fixed sample count, after
    /// each of the passes of 1, 2, 4, … samples of a progressive one (the last one is the
    /// finished image). An implementation that shows it copies what it needs.
    fn pass_finished(&self, _samples: u32, _film: &crate::film::Film) {}
    /// The render finished (or stopped).
    fn finish(&self) {}
    /// Polled between tiles: returning true stops the render with [`crate::error::RenderError::Cancelled`].
    fn cancelled(&self) -> bool {
        false
    }
}

/// Reports nothing, never cancels.
pub struct NoProgress;

impl Progress for NoProgress {}

/// A cancel flag another thread can set.
#[derive(Default)]
pub struct CancelFlag(pub AtomicBool);

impl Progress for CancelFlag {
    fn cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}
