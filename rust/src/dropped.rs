//! Prims a render leaves out, and why: geometry the tracer cannot hold (coordinates beyond
//! [`crate::bounds::MAX_COORDINATE`], transforms [`crate::transform`] refuses) found while the
//! tracer is built, and meshes whose work panicked while rays tested them (a bug, isolated to
//! the prim so the frame completes). Each is logged once, one line naming the prim, and listed
//! in the stats' `dropped_prims`; the panics are also counted as `internal_errors`.

use std::any::Any;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use parking_lot::Mutex;

/// One prim left out. `Display`: `"<prim>: <reason>"`, with the number of instances when more
/// than one was dropped for the same reason.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DroppedPrim {
    /// Prim path.
    pub prim: String,
    pub reason: String,
    /// True when the prim's work panicked: a renderer bug rather than bad input.
    pub internal: bool,
    /// How many of its instances were dropped for this reason.
    pub instances: u64,
}

impl std::fmt::Display for DroppedPrim {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.prim, self.reason)?;
        if self.instances > 1 {
            write!(f, " ({} instances)", self.instances)?;
        }
        Ok(())
    }
}

/// The prims left out of one render, and per mesh whether its work panicked.
#[derive(Debug, Default)]
pub struct DroppedPrims {
    list: Mutex<Vec<DroppedPrim>>,
    /// Per scene mesh: set when its work panicked; rays skip it from then on.
    failed: Vec<AtomicBool>,
    /// Meshes that failed during this render so far.
    failures: AtomicU64,
}

impl DroppedPrims {
    /// For a scene of `meshes` meshes, none failed.
    pub fn new(meshes: usize) -> Self {
        DroppedPrims { failed: (0..meshes).map(|_| AtomicBool::new(false)).collect(), ..Default::default() }
    }

    /// Records that (an instance of) `prim` cannot be traced, logging it the first time.
    pub fn refuse(&self, prim: &str, reason: impl std::fmt::Display) {
        self.add(prim, reason.to_string(), false);
    }

    /// Whether mesh `mesh`'s work has panicked (it is left out from then on).
    #[inline]
    pub fn has_failed(&self, mesh: usize) -> bool {
        self.failed.get(mesh).is_some_and(|f| f.load(Ordering::Relaxed))
    }

    /// Records that work on mesh `mesh` (prim `prim`) panicked with `payload`; the first time,
    /// logs one error line and leaves the mesh out of every later ray test.
    pub fn fail(&self, mesh: usize, prim: &str, payload: &(dyn Any + Send)) {
        if let Some(f) = self.failed.get(mesh) {
            if f.swap(true, Ordering::Relaxed) {
                return;
            }
        }
        self.failures.fetch_add(1, Ordering::Relaxed);
        self.add(prim, format!("internal error, prim dropped: {}", panic_message(payload)), true);
    }

    /// How many meshes have failed so far (a render that saw new failures renders again
    /// without them, so every pixel leaves them out alike).
    pub fn failures(&self) -> u64 {
        self.failures.load(Ordering::Relaxed)
    }

    /// Everything left out, in the order found.
    pub fn list(&self) -> Vec<DroppedPrim> {
        self.list.lock().clone()
    }

    fn add(&self, prim: &str, reason: String, internal: bool) {
        let mut list = self.list.lock();
        if let Some(d) = list.iter_mut().find(|d| d.prim == prim && d.reason == reason) {
            d.instances += 1;
            return;
        }
        let d = DroppedPrim { prim: prim.to_string(), reason, internal, instances: 1 };
        if internal {
            log::error!("{d}");
        } else {
            log::warn!("{d}; not rendered");
        }
        list.push(d);
    }
}

/// The text a panic was raised with (first line), for a one-line message.
pub fn panic_message(payload: &(dyn Any + Send)) -> String {
    let text = payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".to_string());
    text.lines().next().unwrap_or("panic").to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_are_grouped_per_prim_and_reason_and_failures_flag_the_mesh() {
        let d = DroppedPrims::new(2);
        d.refuse("/a", "zero scale");
        d.refuse("/a", "zero scale");
        d.refuse("/b", "zero scale");
        assert!(!d.has_failed(1));
        let payload: Box<dyn Any + Send> = Box::new(String::from("index out of bounds\nsecond line"));
        d.fail(1, "/c", payload.as_ref());
        d.fail(1, "/c", payload.as_ref());
        assert!(d.has_failed(1) && !d.has_failed(0));
        assert_eq!(d.failures(), 1);
        let list: Vec<String> = d.list().iter().map(ToString::to_string).collect();
        assert_eq!(list, ["/a: zero scale (2 instances)", "/b: zero scale", "/c: internal error, prim dropped: index out of bounds"]);
    }
}
