//! Filtered texture lookups through OpenImageIO's `TextureSystem`: [`OiioTextureSystem`]
//! implements the core's [`TextureSampler`] for texture displacement and texture shading.
//!
//! Each system owns a private `ImageCache` (not OpenImageIO's process-wide shared one) with a
//! byte budget — 10 MB by default, the paper's texture cache — so its statistics are its own and
//! two systems can be compared (the paper's §6.3.3: with every lookup at the finest MIP level the
//! 10 MB cache thrashed; with levels chosen from ray differentials reads did not matter). Tiled,
//! MIP-mapped files (`maketx` output) are what it is for; untiled or un-MIP-mapped images still
//! work, through OpenImageIO's `autotile` and `automip` emulation.
//!
//! Coordinates are the core's ([`mipray::texture`]): `st` with t up, derivatives in texture units
//! per step; the flip to OpenImageIO's t-down is done in C++.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;

use mipray::texture::serde_json::{json, Map, Value};
use mipray::texture::{texels_by_lookups, FilterMode, Lookup, Texels, TextureError, TextureHandle, TextureSampler, Wrap};

use crate::ffi::bridge as ffi;

/// Settings of an [`OiioTextureSystem`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OiioTextureOptions {
    /// Tile cache budget, MB (OpenImageIO's `max_memory_MB`).
    pub max_memory_mb: f32,
    /// File handles kept open (`max_open_files`).
    pub max_open_files: u32,
    /// Tile size emulated for untiled files, texels (`autotile`; 0 reads an untiled file as one
    /// tile).
    pub autotile: u32,
    /// Emulate MIP levels of un-MIP-mapped files (`automip`).
    pub automip: bool,
    /// Which MIP levels lookups read.
    pub filter: FilterMode,
    /// Most textures one system opens (the size of its lock-free handle table).
    pub max_textures: u32,
}

impl OiioTextureOptions {
    /// 10 MB (the paper's default texture cache), 100 open files, 64-texel autotile, automip,
    /// filter widths from the differentials, up to 4096 textures.
    pub const DEFAULT: OiioTextureOptions = OiioTextureOptions {
        max_memory_mb: 10.0,
        max_open_files: 100,
        autotile: 64,
        automip: true,
        filter: FilterMode::Differentials,
        max_textures: 4096,
    };
}

impl Default for OiioTextureOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// [`TextureSampler`] by OpenImageIO's `TextureSystem`. One value serves every render thread.
pub struct OiioTextureSystem {
    sys: cxx::UniquePtr<ffi::OiioTexSys>,
    options: OiioTextureOptions,
    /// Path → handle, and handle → path (for stats), written under the lock; lookups never take
    /// it.
    opened: Mutex<(HashMap<String, TextureHandle>, Vec<String>)>,
    lookups: AtomicU64,
    failed: AtomicU64,
    warned: AtomicBool,
}

impl std::fmt::Debug for OiioTextureSystem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OiioTextureSystem")
            .field("options", &self.options)
            .field("lookups", &self.lookups.load(Ordering::Relaxed))
            .finish_non_exhaustive()
    }
}

fn system_error(message: impl Into<String>) -> TextureError {
    TextureError { path: "(texture system)".into(), message: message.into() }
}

fn wrap_code(w: Wrap) -> u8 {
    match w {
        Wrap::FromFile => 0,
        Wrap::Black => 1,
        Wrap::Clamp => 2,
        Wrap::Periodic => 3,
        Wrap::Mirror => 4,
    }
}

impl OiioTextureSystem {
    /// A texture system with its own tile cache.
    ///
    /// # Errors
    /// [`TextureError`] (path `(texture system)`) for a non-positive budget, a table size out of
    /// 1..=2²⁴, or if OpenImageIO cannot create the cache.
    pub fn new(options: OiioTextureOptions) -> Result<Self, TextureError> {
        let raw = ffi::OiioTexOptions {
            max_memory_mb: options.max_memory_mb,
            max_open_files: i32::try_from(options.max_open_files).unwrap_or(i32::MAX),
            autotile: i32::try_from(options.autotile).unwrap_or(i32::MAX),
            automip: options.automip,
            max_textures: options.max_textures,
            finest: options.filter == FilterMode::Finest,
        };
        let sys = ffi::oiio_texsys_new(&raw).map_err(|e| system_error(e.what()))?;
        Ok(OiioTextureSystem {
            sys,
            options,
            opened: Mutex::new((HashMap::new(), Vec::new())),
            lookups: AtomicU64::new(0),
            failed: AtomicU64::new(0),
            warned: AtomicBool::new(false),
        })
    }

    /// The options it was made with.
    pub fn options(&self) -> &OiioTextureOptions {
        &self.options
    }

    /// OpenImageIO's own statistics report (verbosity 1..=5), for logs.
    pub fn report(&self, level: i32) -> String {
        self.sys.report(level).unwrap_or_default()
    }

    /// Paths opened so far, in handle order.
    pub fn paths(&self) -> Vec<String> {
        match self.opened.lock() {
            Ok(g) => g.1.clone(),
            Err(poisoned) => poisoned.into_inner().1.clone(),
        }
    }

    fn note_failure(&self, handle: TextureHandle) {
        self.failed.fetch_add(1, Ordering::Relaxed);
        // Read (and so clear) this thread's error either way; log only the first.
        let message = self.sys.take_error().unwrap_or_default();
        if !self.warned.swap(true, Ordering::Relaxed) {
            let path = self.paths().get(handle.index() as usize).cloned().unwrap_or_else(|| format!("handle {}", handle.index()));
            log::warn!("texture {path}: lookup failed: {message} (further failures are only counted)");
        }
    }
}

impl TextureSampler for OiioTextureSystem {
    /// Opens the file once (later calls with the same path return the same handle), reading its
    /// header so that a missing or unreadable file fails here rather than at every lookup.
    ///
    /// # Errors
    /// [`TextureError`] naming the path, with OpenImageIO's reason.
    fn handle(&self, path: &str) -> Result<TextureHandle, TextureError> {
        let mut guard = match self.opened.lock() {
            Ok(g) => g,
            Err(poisoned) => poisoned.into_inner(),
        };
        if let Some(&h) = guard.0.get(path) {
            return Ok(h);
        }
        let index = self.sys.open(path).map_err(|e| TextureError { path: path.to_string(), message: e.what().to_string() })?;
        let h = TextureHandle::new(index);
        guard.0.insert(path.to_string(), h);
        guard.1.push(path.to_string());
        Ok(h)
    }

    fn sample(&self, handle: TextureHandle, st: [f32; 2], dst_dx: [f32; 2], dst_dy: [f32; 2], lookup: &Lookup, out: &mut [f32]) -> bool {
        self.lookups.fetch_add(1, Ordering::Relaxed);
        let (dx, dy) = self.options.filter.widths(dst_dx, dst_dy);
        let raw = ffi::OiioLookup {
            handle: handle.index(),
            s: st[0],
            t: st[1],
            dsdx: dx[0],
            dtdx: dx[1],
            dsdy: dy[0],
            dtdy: dy[1],
            first_channel: i32::try_from(lookup.first_channel).unwrap_or(i32::MAX),
            wrap_s: wrap_code(lookup.wrap_s),
            wrap_t: wrap_code(lookup.wrap_t),
            fill: lookup.fill,
        };
        let ok = st[0].is_finite() && st[1].is_finite() && self.sys.sample(&raw, out);
        if !ok {
            self.note_failure(handle);
        }
        ok
    }

    fn resolution(&self, handle: TextureHandle) -> Option<[u32; 2]> {
        let mut r = [0i32; 2];
        if !self.sys.resolution(handle.index(), &mut r) {
            return None;
        }
        Some([u32::try_from(r[0]).ok()?, u32::try_from(r[1]).ok()?])
    }

    /// The MIP level through the ImageCache (`get_pixels` of the first level at most
    /// `max_width` wide, automip's emulated levels for un-MIP-mapped files). If that fails, one
    /// lookup per texel (the trait's default), after one warning naming the file.
    fn texels(&self, handle: TextureHandle, max_width: u32, channels: u32) -> Option<Texels> {
        let mut dims = [0i32; 3];
        match self.sys.texels(handle.index(), max_width.max(1), channels.clamp(1, 4), &mut dims) {
            Ok(data) => {
                let [w, h, c] = dims.map(|d| u32::try_from(d).unwrap_or(0));
                if w == 0 || h == 0 || c == 0 || data.len() != (w * h * c) as usize {
                    return None;
                }
                Some(Texels { width: w, height: h, channels: c, data })
            }
            Err(e) => {
                let path = self.paths().get(handle.index() as usize).cloned().unwrap_or_else(|| format!("handle {}", handle.index()));
                log::warn!("texture {path}: cannot read a MIP level ({}); reading it by lookups", e.what());
                texels_by_lookups(self, handle, max_width, channels)
            }
        }
    }

    fn filter_mode(&self) -> FilterMode {
        self.options.filter
    }

    /// The stats JSON's `texture_cache` object:
    ///
    /// - `kind` = `"oiio"`, `filter_mode`, `max_memory_mb`, `lookups`, `failed_lookups`,
    ///   `textures` (opened);
    /// - from the ImageCache (OpenImageIO's `stat:` attributes): `bytes_read` (uncompressed pixel
    ///   bytes read from files, `stat:bytes_read`), `tiles_read` (`stat:tiles_created`: every tile
    ///   brought into the cache, re-reads of evicted tiles included), `tiles_current`,
    ///   `tiles_peak`, `cache_memory_used_bytes`, `open_files_created`, `open_files_current`,
    ///   `open_files_peak`, `find_tile_calls`, `unique_files`, `image_size_bytes`,
    ///   `file_size_bytes`, `fileio_time_s`, `fileopen_time_s`, `file_locking_time_s`,
    ///   `tile_locking_time_s`, `find_file_time_s`, `find_tile_time_s`;
    /// - `files[]`, one per texture: `path`, `tiles_read`, `bytes_read`, `redundant_tiles`
    ///   (tiles read again after eviction), `redundant_bytes_read`, `times_opened`, `io_time_s`.
    fn stats(&self) -> Value {
        let mut m = Map::new();
        m.insert("kind".into(), json!("oiio"));
        m.insert("filter_mode".into(), json!(self.options.filter.name()));
        m.insert("max_memory_mb".into(), json!(self.options.max_memory_mb));
        m.insert("lookups".into(), json!(self.lookups.load(Ordering::Relaxed)));
        m.insert("failed_lookups".into(), json!(self.failed.load(Ordering::Relaxed)));
        let paths = self.paths();
        m.insert("textures".into(), json!(paths.len()));
        for s in self.sys.cache_stats().unwrap_or_default() {
            m.insert(s.name, number(s.value));
        }
        let files: Vec<Value> = paths
            .iter()
            .enumerate()
            .map(|(i, path)| {
                let mut f = Map::new();
                f.insert("path".into(), json!(path));
                for s in self.sys.file_stats(i as u32).unwrap_or_default() {
                    f.insert(s.name, number(s.value));
                }
                Value::Object(f)
            })
            .collect();
        m.insert("files".into(), Value::Array(files));
        Value::Object(m)
    }
}

/// A statistic as a JSON number: an integer when it is one (counts, bytes), else a float
/// (seconds); non-finite values become 0.
fn number(v: f64) -> Value {
    if !v.is_finite() {
        json!(0)
    } else if v.fract() == 0.0 && v.abs() < 9.0e15 {
        json!(v as i64)
    } else {
        json!(v)
    }
}
