//! One budget for the geometry memory of a render (issue 15, part 4): the geometry cache, the
//! patch data of meshes built on first use (OpenSubdiv's tables, points and records) and the
//! tracer's root subpatches and BVHs. The `geometryMemoryMb` setting bounds their sum; the
//! tracer keeps it by dropping the built data of lazy meshes no ray has entered lately and
//! building it again when a ray next reaches them, so a scene larger than the budget still
//! renders, and renders the same image: a rebuilt mesh is the same mesh, bit for bit, and its
//! tessellations keep their cache keys.
//!
//! # Why epochs (and not an `Arc` per use)
//!
//! The hot path reaches a lazy mesh's root subpatches and BVH once per instance a ray enters,
//! and its surface once per tessellation or shading point. Cloning an `Arc` there would write a
//! reference count shared by every render thread on every instance entry (a contended cache
//! line, and ~8 instructions more per entry). With epoch-based reclamation
//! (`crossbeam-epoch`, already in the build through rayon) a reader pays nothing per ray: the
//! render loop pins its thread once per pixel (and the irradiance pre-pass once per chunk of
//! points), and everything a drop unlinks is freed only once every thread pinned at that moment
//! has unpinned. A ray holds plain references for as long as its pixel lasts; a drop under it
//! unlinks the mesh for the rays that come later (they build it again), and the memory goes
//! back when the pixel ends. A tracer without a budget never drops anything, and then nothing
//! needs a pin.

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

pub use crossbeam_epoch::Guard;

/// Pins the calling thread: what a geometry budget drops while the guard lives is freed only
/// after it drops. Render threads hold one per pixel; nested pins are cheap.
#[inline]
pub fn pin() -> Guard {
    crossbeam_epoch::pin()
}

/// Whether the calling thread is pinned (for debug checks of the readers' contract).
#[inline]
pub fn is_pinned() -> bool {
    crossbeam_epoch::is_pinned()
}

/// Frees `value` once no thread pinned now can still hold a reference into it.
pub fn retire<T: Send + 'static>(value: Box<T>) {
    let guard = pin();
    guard.defer(move || drop(value));
    // Hand the garbage to the global queue now, so that it is freed within a few pins rather
    // than when this thread's bag of 64 fills.
    guard.flush();
}

/// Bytes held by one mesh's built data, by component.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HeldBytes {
    /// The surface's patch data ([`crate::patch::LimitSurface::memory_bytes`]).
    pub surface: usize,
    /// Root subpatch records ([`crate::subpatch::RootSubpatch`], 32 bytes each).
    pub roots: usize,
    /// The mesh's bottom-level BVH.
    pub bvh: usize,
}

impl HeldBytes {
    pub fn total(&self) -> usize {
        self.surface + self.roots + self.bvh
    }
}

/// The part of the budget the droppable data may use, and what it holds now.
#[derive(Debug)]
pub struct Budget {
    /// The whole budget (bytes).
    pub total: usize,
    /// What cannot be dropped: the geometry cache's budget, the top-level BVH and instances,
    /// meshes built up front (bytes).
    pub fixed: usize,
    /// `fixed` by part, named as the stats name them.
    pub fixed_parts: Vec<(&'static str, usize)>,
    surface: AtomicUsize,
    roots: AtomicUsize,
    bvh: AtomicUsize,
    peak: AtomicUsize,
    /// Meshes whose built data was dropped to keep the budget.
    pub drops: AtomicU64,
    /// Builds of meshes whose data had been dropped before.
    pub rebuilds: AtomicU64,
    /// Builds after which the budget could not be kept (the meshes in use then needed more).
    pub over: AtomicU64,
    /// The CLOCK hand: the next mesh the drop sweep looks at; the lock serializes sweeps.
    pub(crate) hand: parking_lot::Mutex<usize>,
}

impl Budget {
    /// A budget of `total` bytes of which the `fixed` parts (name, bytes) cannot be dropped.
    ///
    /// # Errors
    /// `total` below the fixed parts' sum: one line with the minimum and the parts.
    pub fn new(total: usize, fixed_parts: Vec<(&'static str, usize)>) -> Result<Budget, String> {
        let fixed = fixed_parts.iter().map(|(_, b)| b).sum();
        if total < fixed {
            let parts: Vec<String> =
                fixed_parts.iter().map(|(n, b)| format!("{} {:.2} MB", n.replace('_', " "), *b as f64 / 1e6)).collect();
            return Err(format!(
                "geometryMemoryMb={} cannot hold what the render cannot drop ({}): it needs at least {} MB",
                total as f64 / 1e6,
                parts.join(", "),
                (fixed as f64 / 1e6 * 100.0).ceil() / 100.0
            ));
        }
        Ok(Budget {
            total,
            fixed,
            fixed_parts,
            surface: AtomicUsize::new(0),
            roots: AtomicUsize::new(0),
            bvh: AtomicUsize::new(0),
            peak: AtomicUsize::new(0),
            drops: AtomicU64::new(0),
            rebuilds: AtomicU64::new(0),
            over: AtomicU64::new(0),
            hand: parking_lot::Mutex::new(0),
        })
    }

    /// Bytes the droppable data may hold.
    pub fn limit(&self) -> usize {
        self.total - self.fixed
    }

    /// What the droppable data holds now, by component.
    pub fn held(&self) -> HeldBytes {
        HeldBytes {
            surface: self.surface.load(Ordering::Relaxed),
            roots: self.roots.load(Ordering::Relaxed),
            bvh: self.bvh.load(Ordering::Relaxed),
        }
    }

    /// The most the droppable data held at once (bytes).
    pub fn peak(&self) -> usize {
        self.peak.load(Ordering::Relaxed)
    }

    /// Counts a mesh's data going from `old` to `new`.
    pub fn account(&self, old: HeldBytes, new: HeldBytes) {
        let apply = |a: &AtomicUsize, o: usize, n: usize| {
            if n >= o {
                a.fetch_add(n - o, Ordering::Relaxed);
            } else {
                a.fetch_sub(o - n, Ordering::Relaxed);
            }
        };
        apply(&self.surface, old.surface, new.surface);
        apply(&self.roots, old.roots, new.roots);
        apply(&self.bvh, old.bvh, new.bvh);
        self.peak.fetch_max(self.held().total(), Ordering::Relaxed);
    }

    /// The stats' `geometry_budget` object: the budget, what each part holds (bytes), the drops
    /// and rebuilds.
    pub fn stats(&self) -> serde_json::Value {
        let held = self.held();
        let fixed: serde_json::Map<String, serde_json::Value> =
            self.fixed_parts.iter().map(|(n, b)| (n.to_string(), (*b).into())).collect();
        serde_json::json!({
            "budget_bytes": self.total,
            "fixed_bytes": fixed,
            "droppable_limit_bytes": self.limit(),
            "held_bytes": {
                "surfaces": held.surface,
                "root_subpatches": held.roots,
                "bvhs": held.bvh,
            },
            "peak_held_bytes": self.peak(),
            "drops": self.drops.load(Ordering::Relaxed),
            "rebuilds": self.rebuilds.load(Ordering::Relaxed),
            "builds_over_budget": self.over.load(Ordering::Relaxed),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn a_budget_below_its_fixed_part_says_the_minimum() {
        let e = Budget::new(1_000_000, vec![("geometry_cache", 2_000_000), ("top_level", 345_678)]).unwrap_err();
        assert_eq!(
            e,
            "geometryMemoryMb=1 cannot hold what the render cannot drop (geometry cache 2.00 MB, top level 0.35 MB): it needs at least 2.35 MB"
        );
        let b = Budget::new(3_000_000, vec![("geometry_cache", 2_000_000)]).unwrap();
        assert_eq!(b.limit(), 1_000_000);
        b.account(HeldBytes::default(), HeldBytes { surface: 10, roots: 20, bvh: 30 });
        b.account(HeldBytes { surface: 10, roots: 20, bvh: 30 }, HeldBytes { surface: 5, roots: 0, bvh: 0 });
        assert_eq!(b.held(), HeldBytes { surface: 5, roots: 0, bvh: 0 });
        assert_eq!(b.peak(), 60);
    }

    #[test]
    fn retired_values_outlive_the_pins_that_saw_them() {
        struct Flag(Arc<std::sync::atomic::AtomicBool>);
        impl Drop for Flag {
            fn drop(&mut self) {
                self.0.store(true, Ordering::SeqCst);
            }
        }
        let freed = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let (pinned_tx, pinned_rx) = std::sync::mpsc::channel();
        let (release_tx, release_rx) = std::sync::mpsc::channel::<()>();
        let reader = std::thread::spawn(move || {
            let _g = pin();
            pinned_tx.send(()).unwrap();
            release_rx.recv().unwrap();
        });
        pinned_rx.recv().unwrap();
        retire(Box::new(Flag(freed.clone())));
        for _ in 0..1000 {
            pin().flush();
        }
        assert!(!freed.load(Ordering::SeqCst), "freed under a thread pinned before the retire");
        release_tx.send(()).unwrap();
        reader.join().unwrap();
        // Other tests' threads pin too: give the epoch time to move past them.
        for _ in 0..5000 {
            if freed.load(Ordering::SeqCst) {
                break;
            }
            pin().flush();
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        assert!(freed.load(Ordering::SeqCst), "never freed once the reader unpinned");
    }
}
