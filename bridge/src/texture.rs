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
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::{Mutex, MutexGuard, PoisonError};

use mipray::texture::serde_json::{json, Map, Value};
use mipray::texture::{
    texels_by_lookups, usd_uv_channel, ChannelLevels, FilterMode, LevelTexels, Lookup, SourceColorSpace, TexelLevel, Texels, TextureError,
    TextureHandle, TextureSampler, Wrap,
};

use crate::ffi::bridge as ffi;
use crate::texture_cache;

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
    /// What [`TextureSampler::handle_encoded`] answered, and which handles are linear copies.
    encoded: Mutex<Encoded>,
    /// Where linear copies of sRGB files go ([`OiioTextureSystem::linear_cache_dir`]).
    linear_cache: PathBuf,
    /// Per handle, the channels its file has (0 until opened), read by every lookup without a
    /// lock: what UsdUVTexture's rules for missing channels need.
    file_channels: Box<[AtomicU8]>,
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

fn wrap_of_code(code: u8) -> Wrap {
    match code {
        1 => Wrap::Black,
        2 => Wrap::Clamp,
        3 => Wrap::Periodic,
        4 => Wrap::Mirror,
        _ => Wrap::FromFile,
    }
}

/// Bytes a texel of `OiioLevel` format code `format` takes.
fn texel_size(format: u8) -> usize {
    match format {
        0 => 1,
        1 | 2 => 2,
        _ => 4,
    }
}

/// Texels of format code `format` from `bytes` (native byte order).
fn texels_of(format: u8, bytes: &[u8]) -> LevelTexels {
    let u16s = || bytes.chunks_exact(2).map(|b| u16::from_ne_bytes([b[0], b[1]])).collect();
    match format {
        0 => LevelTexels::U8(bytes.to_vec()),
        1 => LevelTexels::U16(u16s()),
        2 => LevelTexels::Half(u16s()),
        _ => LevelTexels::F32(bytes.chunks_exact(4).map(|b| f32::from_ne_bytes([b[0], b[1], b[2], b[3]])).collect()),
    }
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
            encoded: Mutex::new(Encoded::default()),
            linear_cache: default_linear_cache_dir(),
            file_channels: (0..options.max_textures).map(|_| AtomicU8::new(0)).collect(),
            lookups: AtomicU64::new(0),
            failed: AtomicU64::new(0),
            warned: AtomicBool::new(false),
        })
    }

    /// Puts linear copies of sRGB textures in `dir` instead of the default (see
    /// [`OiioTextureSystem::linear_cache_dir`]).
    pub fn with_linear_cache_dir(mut self, dir: impl Into<PathBuf>) -> Self {
        self.linear_cache = dir.into();
        self
    }

    /// Where sRGB-encoded textures are converted to (once per file content):
    /// `$MIPRAY_TEXTURE_CACHE` if set, else `$XDG_CACHE_HOME/mipray/textures`, else
    /// `~/.cache/mipray/textures`; a private directory (0700, this user's). Each copy is a
    /// half-float tiled OpenEXR MIP map named after the source, a hash of the source's bytes and
    /// a hash of its own bytes (checked on use: a damaged copy is made again); the directory is
    /// kept under `$MIPRAY_TEXTURE_CACHE_MB` (default 4096) by removing the least recently used
    /// copies. See [`crate::texture_cache`].
    pub fn linear_cache_dir(&self) -> &Path {
        &self.linear_cache
    }

    /// The linear copy of the sRGB-encoded `path` in the cache, made if it is not there yet.
    /// A cache directory that cannot be used is warned about and a per-user directory under the
    /// system temporary directory used instead, so an unwritable `$HOME` never costs a render
    /// its textures (and no other user's directory is ever trusted).
    fn linear_copy(&self, path: &str) -> Result<String, TextureError> {
        let err = |message: String| TextureError { path: path.to_string(), message };
        let source = Path::new(path);
        let source_hash = texture_cache::hash_file(source).map_err(|e| err(format!("cannot read: {e}")))?;
        let prefix = texture_cache::entry_prefix(source, source_hash, "linear-v3 unassociated alpha, sRGB->linear half exr");
        let fallback = texture_cache::fallback_dir();
        let mut dirs = vec![(self.linear_cache.clone(), false)];
        if fallback != self.linear_cache {
            dirs.push((fallback, true));
        }
        let mut problem = String::new();
        for (dir, strict) in &dirs {
            if let Err(e) = texture_cache::private_dir(dir, *strict) {
                problem = format!("cannot use the linear texture cache: {e}");
                log::warn!("{problem}; trying the next place");
                continue;
            }
            if let Some(copy) = texture_cache::find(dir, &prefix) {
                return Ok(copy.to_string_lossy().into_owned());
            }
            // Another render may be converting the same file: each writes its own hidden file
            // and the rename is atomic, so a reader sees a whole copy or none.
            let partial = match texture_cache::new_partial(dir, &prefix) {
                Ok(p) => p,
                Err(e) => {
                    problem = format!("cannot write the linear texture cache: {e}");
                    log::warn!("{problem}; trying the next place");
                    continue;
                }
            };
            log::info!("texture {path}: sRGB-encoded; writing its linear MIP map in {}", dir.display());
            if let Err(e) = ffi::oiio_make_linear_texture(&source.to_string_lossy(), &partial.to_string_lossy()) {
                let _ = std::fs::remove_file(&partial);
                return Err(err(format!("cannot convert from sRGB: {}", e.what())));
            }
            match texture_cache::commit(dir, &prefix, &partial) {
                Ok(copy) => {
                    texture_cache::evict(dir, texture_cache::limit_bytes(), &copy);
                    return Ok(copy.to_string_lossy().into_owned());
                }
                Err(e) => {
                    let _ = std::fs::remove_file(&partial);
                    problem = e;
                }
            }
        }
        Err(err(problem))
    }

    /// [`TextureSampler::handle_encoded`]'s work once the request is new.
    fn open_encoded(&self, path: &str, space: SourceColorSpace, encoded: &mut Encoded) -> Result<TextureHandle, TextureError> {
        let request = (path.to_string(), space);
        texture_cache::check_source(Path::new(path), texture_cache::OPEN_TIMEOUT)
            .map_err(|message| TextureError { path: path.to_string(), message })?;
        let srgb = match space {
            SourceColorSpace::Raw => false,
            SourceColorSpace::Srgb => true,
            SourceColorSpace::Auto => {
                ffi::oiio_auto_is_srgb(path).map_err(|e| TextureError { path: path.to_string(), message: e.what().to_string() })?
            }
        };
        let h = if srgb {
            let h = self.handle(&self.linear_copy(path)?)?;
            encoded.decoded_from.insert(h.index(), path.to_string());
            h
        } else {
            self.handle(path)?
        };
        encoded.requests.insert(request, h);
        Ok(h)
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
        lock(&self.opened).1.clone()
    }

    /// One OpenImageIO lookup of `out.len()` channels from `lookup.first_channel`, all of which
    /// the file must have; a failure is counted and its first message logged.
    fn sample_file(
        &self,
        handle: TextureHandle,
        st: [f32; 2],
        dst_dx: [f32; 2],
        dst_dy: [f32; 2],
        lookup: &Lookup,
        out: &mut [f32],
    ) -> bool {
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
        let mut guard = lock(&self.opened);
        if let Some(&h) = guard.0.get(path) {
            return Ok(h);
        }
        texture_cache::check_source(Path::new(path), texture_cache::OPEN_TIMEOUT)
            .map_err(|message| TextureError { path: path.to_string(), message })?;
        let index = self.sys.open(path).map_err(|e| TextureError { path: path.to_string(), message: e.what().to_string() })?;
        let h = TextureHandle::new(index);
        if let Some(c) = self.file_channels.get(index as usize) {
            c.store(u8::try_from(self.sys.channels(index).clamp(0, 255)).unwrap_or(0), Ordering::Relaxed);
        }
        guard.0.insert(path.to_string(), h);
        guard.1.push(path.to_string());
        Ok(h)
    }

    /// `Raw` opens the file as it is. `Srgb` opens a linear copy, made once per file version in
    /// [`OiioTextureSystem::linear_cache_dir`] (OpenImageIO 2.4's TextureSystem cannot decode
    /// while it filters, and decoding after filtering would darken minified lookups). `Auto` is
    /// `Srgb` for 8-bit files of 3 or 4 channels, `Raw` otherwise (Hydra's rule).
    ///
    /// # Errors
    /// [`TextureError`] naming the path: unreadable, or the copy cannot be made.
    fn handle_encoded(&self, path: &str, space: SourceColorSpace) -> Result<TextureHandle, TextureError> {
        // Held throughout: two threads opening one file make one copy, and a file asked for
        // again (every mesh that binds it, every render) reads neither its header nor the cache.
        let mut encoded = lock(&self.encoded);
        let request = (path.to_string(), space);
        if let Some(&h) = encoded.requests.get(&request) {
            return Ok(h);
        }
        let (opened, caught) = texture_cache::catching_stderr(|| self.open_encoded(path, space, &mut encoded));
        texture_cache::pass_on(path, &caught);
        opened
    }
    fn decoded_from_srgb(&self, handle: TextureHandle) -> bool {
        lock(&self.encoded).decoded_from.contains_key(&handle.index())
    }

    /// Channels a file lacks follow UsdUVTexture's rule ([`usd_uv_channel`]): OpenImageIO is
    /// only ever asked for channels the file has (asked for more, 2.4 reads past a tile and
    /// aborts the process).
    fn sample(&self, handle: TextureHandle, st: [f32; 2], dst_dx: [f32; 2], dst_dy: [f32; 2], lookup: &Lookup, out: &mut [f32]) -> bool {
        self.lookups.fetch_add(1, Ordering::Relaxed);
        let n = self.file_channels.get(handle.index() as usize).map_or(0, |c| u32::from(c.load(Ordering::Relaxed)));
        let first = lookup.first_channel;
        let direct = (first..first + out.len() as u32).all(|c| usd_uv_channel(n, c) == Some(c));
        if direct || out.len() > 4 {
            return self.sample_file(handle, st, dst_dx, dst_dy, lookup, out);
        }
        // Every channel the file has (at most rgba), then each output from its source.
        let mut texel = [0.0f32; 4];
        let have = n.min(4) as usize;
        let whole = Lookup { first_channel: 0, ..*lookup };
        if !self.sample_file(handle, st, dst_dx, dst_dy, &whole, &mut texel[..have]) {
            return false;
        }
        for (k, o) in out.iter_mut().enumerate() {
            let c = first + k as u32;
            *o = match usd_uv_channel(n, c) {
                Some(source) => texel[source as usize],
                None if c == 3 => 1.0,
                None => lookup.fill,
            };
        }
        true
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

    /// Read once, in full, through a private ImageCache (OpenImageIO's own levels, or automip's
    /// for a file without them; see `OiioTexSys::channel_levels`), so the lookups' budget and
    /// statistics are untouched. `None` for a channel the file lacks (a constant by
    /// UsdUVTexture's rule: looked up point by point, which answers it).
    fn channel_levels(&self, handle: TextureHandle, channel: u32) -> Option<Result<ChannelLevels, String>> {
        let n = self.file_channels.get(handle.index() as usize).map_or(0, |c| u32::from(c.load(Ordering::Relaxed)));
        let source = usd_uv_channel(n, channel)?;
        let channel = i32::try_from(source).unwrap_or(i32::MAX);
        let mut wrap = [0u8; 2];
        let mut read = || -> Result<ChannelLevels, String> {
            let shapes = self.sys.level_shapes(handle.index(), channel, &mut wrap).map_err(|e| e.what().to_string())?;
            let format = shapes.first().map_or(3, |s| s.format);
            let size = texel_size(format);
            let total = shapes
                .iter()
                .try_fold(0usize, |sum, s| (s.width as usize).checked_mul(s.height as usize)?.checked_mul(size)?.checked_add(sum));
            let total = total.filter(|&t| t <= mipray::displacement_texture::MAX_PYRAMID_BYTES).ok_or_else(|| {
                format!(
                    "its MIP levels take more than the {} MB the store keeps of one texture",
                    mipray::displacement_texture::MAX_PYRAMID_BYTES >> 20
                )
            })?;
            // One buffer the C++ side fills without growing it, split into levels here.
            let mut bytes = vec![0u8; total];
            self.sys.read_levels(handle.index(), channel, format, &mut bytes).map_err(|e| e.what().to_string())?;
            let mut levels = Vec::with_capacity(shapes.len());
            let mut at = 0;
            for s in &shapes {
                let n = s.width as usize * s.height as usize * size;
                levels.push(TexelLevel { width: s.width, height: s.height, texels: texels_of(format, &bytes[at..at + n]) });
                at += n;
            }
            Ok(ChannelLevels { levels, file_wrap: wrap.map(wrap_of_code) })
        };
        Some(read())
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
    ///   (tiles read again after eviction), `redundant_bytes_read`, `times_opened`, `io_time_s`,
    ///   `source_color_space` (`raw`, or `sRGB` for the linear copy of an sRGB file, whose path
    ///   is then `decoded_from`).
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
                let source = lock(&self.encoded).decoded_from.get(&(i as u32)).cloned();
                f.insert("source_color_space".into(), json!(if source.is_some() { "sRGB" } else { "raw" }));
                if let Some(source) = source {
                    f.insert("decoded_from".into(), json!(source));
                }
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

/// [`TextureSampler::handle_encoded`]'s answers, and the linear copies among the handles.
#[derive(Default)]
struct Encoded {
    /// (path, encoding) → handle.
    requests: HashMap<(String, SourceColorSpace), TextureHandle>,
    /// Handle → the sRGB file its linear copy was made from (the handle's path is the copy's).
    decoded_from: HashMap<u32, String>,
}

/// Locks `m`, taking over a lock a panicking thread left: every write under these locks is one
/// insert or push, so the tables are whole either way.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// See [`OiioTextureSystem::linear_cache_dir`].
fn default_linear_cache_dir() -> PathBuf {
    let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
    if let Some(dir) = var("MIPRAY_TEXTURE_CACHE") {
        return dir;
    }
    if let Some(dir) = var("XDG_CACHE_HOME").or_else(|| var("HOME").map(|h| h.join(".cache"))) {
        return dir.join("mipray").join("textures");
    }
    texture_cache::fallback_dir()
}
