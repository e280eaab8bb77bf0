//! Texture lookups and texture coordinates.
//!
//! **Lookups.** [`TextureSampler`] is how the core reads filtered texture values without depending
//! on OpenImageIO: the bridge implements it with OpenImageIO's `TextureSystem` (tiled MIP maps
//! behind a bounded tile cache), and [`CheckerSampler`] is a procedural stand-in so core tests need
//! no C++ and no files. Filter widths come from ray differentials (DESIGN.md: "differentials also
//! choose texture filter widths") or, for displacement, from the tessellation grid's own spacing.
//! This is what makes a small texture cache work for ray tracing (the paper's §2.6): incoherent
//! rays are wide, so their lookups read coarse MIP levels, few tiles. [`FilterMode::Finest`]
//! ignores the widths and reads the finest level everywhere: the paper's §6.3.3 experiment, in
//! which the same 10 MB cache thrashed.
//!
//! **Texture coordinates.** [`Primvar2`] is a 2-float primvar as USD authors it (`st`, any
//! interpolation, optionally indexed). Every interpolation resolves to one value per face-vertex
//! ([`Primvar2::face_varying_indices`]), which is exactly a face-varying channel: the bridge hands
//! those to OpenSubdiv, which interpolates them smoothly with the mesh's
//! `faceVaryingLinearInterpolation`. [`BaseFacePrimvar`] interpolates them linearly over each base
//! face in the core: exact for constant, uniform and varying primvars on any mesh and for every
//! interpolation on polygonal meshes. Surfaces expose them through
//! [`crate::patch::LimitSurface::face_varying`].
//!
//! Conventions: `st` is in texture space, [0, 1]² over the image, **s to the right and t up**
//! (USD's and OpenGL's: (0, 0) is the image's bottom-left corner; a sampler whose images start at
//! the top, as OpenImageIO's do, flips t). Values outside [0, 1] wrap as the lookup says.
//! Derivatives `dst_dx = (ds/dx, dt/dx)` and `dst_dy = (ds/dy, dt/dy)` are texture-space units per
//! step of two independent screen or parameter directions x and y — a pixel for a camera ray, a
//! grid step for tessellation — as OpenImageIO takes them; the footprint is the parallelogram they
//! span.

use std::sync::atomic::{AtomicU64, Ordering};

/// The JSON crate of [`TextureSampler::stats`], re-exported so implementations (the bridge) build
/// their stats with the very version the trait names.
pub use serde_json;
use serde_json::{json, Value};
use thiserror::Error;

use crate::error::MeshError;
use crate::patch::PatchParam;
use crate::topology::{MeshTopology, Scheme};

/// An opened texture of one [`TextureSampler`]: cheap to copy, valid only with the sampler that
/// made it (another sampler reads whatever texture has the same index, or fails the lookup).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TextureHandle(u32);

impl TextureHandle {
    /// For implementations: the handle of their `index`-th texture.
    pub const fn new(index: u32) -> Self {
        TextureHandle(index)
    }

    /// The index the implementation gave it.
    pub const fn index(self) -> u32 {
        self.0
    }
}

/// A texture that cannot be used: the path and why, on one line. The caller falls back (to the
/// UsdUVTexture's `fallback` value, say) and warns once.
#[derive(Debug, Error, Clone, PartialEq)]
#[error("texture {path}: {message}")]
pub struct TextureError {
    pub path: String,
    pub message: String,
}

/// How lookups outside [0, 1] wrap (UsdUVTexture's `wrapS` / `wrapT`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Wrap {
    /// What the file says (`useMetadata`); periodic when it says nothing.
    #[default]
    FromFile,
    /// Zero outside.
    Black,
    /// The edge texel continues.
    Clamp,
    /// `repeat`.
    Periodic,
    Mirror,
}

impl Wrap {
    /// UsdUVTexture's token: `black`, `clamp`, `repeat`, `mirror`, `useMetadata`.
    pub fn from_usd(token: &str) -> Option<Wrap> {
        match token {
            "black" => Some(Wrap::Black),
            "clamp" => Some(Wrap::Clamp),
            "repeat" => Some(Wrap::Periodic),
            "mirror" => Some(Wrap::Mirror),
            "useMetadata" => Some(Wrap::FromFile),
            _ => None,
        }
    }
}

/// How a texture file encodes its values: UsdUVTexture's `sourceColorSpace`.
///
/// Lookups always return linear values: a sampler decodes an sRGB-encoded file before it filters
/// (OpenImageIO's, by converting the file once into a linear MIP map, see the bridge), because
/// filtering encoded values and decoding the result darkens every minified lookup — exactly the
/// wide, incoherent lookups this renderer makes coarse. The transfer curve applies to colour
/// channels (r, g, b), never to alpha.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum SourceColorSpace {
    /// Decide from the file as Hydra's Storm does (so images match usdview): 8-bit images with 3
    /// or 4 channels are sRGB, everything else is raw. The UsdPreviewSurface default.
    #[default]
    Auto,
    /// Values as stored (linear data: heights, roughness, normals, float colour).
    Raw,
    /// sRGB transfer curve, no other colour-space change.
    Srgb,
}

impl SourceColorSpace {
    /// UsdUVTexture's token: `auto`, `raw`, `sRGB`.
    pub fn from_usd(token: &str) -> Option<SourceColorSpace> {
        match token {
            "auto" => Some(SourceColorSpace::Auto),
            "raw" => Some(SourceColorSpace::Raw),
            "sRGB" => Some(SourceColorSpace::Srgb),
            _ => None,
        }
    }

    /// The USD token.
    pub const fn usd_name(self) -> &'static str {
        match self {
            SourceColorSpace::Auto => "auto",
            SourceColorSpace::Raw => "raw",
            SourceColorSpace::Srgb => "sRGB",
        }
    }
}

/// The sRGB transfer curve, encoded value → linear (IEC 61966-2-1).
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Which MIP level a lookup reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum FilterMode {
    /// The filter footprint is the one the derivatives span, so the level is the one whose texels
    /// are about that wide (anisotropic where the implementation can). The default.
    #[default]
    Differentials,
    /// Derivatives ignored: every lookup reads the finest level, interpolated bilinearly. Aliases
    /// and thrashes the cache; it exists to measure that (the paper's §6.3.3).
    Finest,
}

impl FilterMode {
    /// The name used in render settings and stats: `differentials`, `finest`.
    pub const fn name(self) -> &'static str {
        match self {
            FilterMode::Differentials => "differentials",
            FilterMode::Finest => "finest",
        }
    }

    /// Parses [`FilterMode::name`].
    pub fn from_name(name: &str) -> Option<FilterMode> {
        match name {
            "differentials" => Some(FilterMode::Differentials),
            "finest" => Some(FilterMode::Finest),
            _ => None,
        }
    }

    /// The derivatives a lookup in this mode filters with: zero for [`FilterMode::Finest`], and
    /// for [`FilterMode::Differentials`] the given ones with non-finite components set to zero (a
    /// broken differential reads the finest level rather than poisoning the filter).
    pub fn widths(self, dst_dx: [f32; 2], dst_dy: [f32; 2]) -> ([f32; 2], [f32; 2]) {
        match self {
            FilterMode::Finest => ([0.0; 2], [0.0; 2]),
            FilterMode::Differentials => {
                let clean = |d: [f32; 2]| d.map(|c| if c.is_finite() { c } else { 0.0 });
                (clean(dst_dx), clean(dst_dy))
            }
        }
    }
}

/// Per-lookup options (UsdUVTexture's inputs other than `st`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lookup {
    /// First channel read (r = 0, g = 1, b = 2, a = 3); `out.len()` channels from there.
    pub first_channel: u32,
    pub wrap_s: Wrap,
    pub wrap_t: Wrap,
    /// Value of requested channels the file does not have.
    pub fill: f32,
}

impl Lookup {
    /// Channel 0, wrap as the file says, fill 0.
    pub const DEFAULT: Lookup = Lookup { first_channel: 0, wrap_s: Wrap::FromFile, wrap_t: Wrap::FromFile, fill: 0.0 };
}

/// Where UsdUVTexture reads output channel `channel` (r = 0, g = 1, b = 2, a = 3) of a file with
/// `file_channels` channels, by the UsdPreviewSurface specification's rule for channels a file
/// lacks: a one-channel (grey) file gives its channel as r, g and b; a two-channel (grey and
/// alpha) file gives its first channel as r, g and b and its second as a; a file without alpha
/// gives a = 1. `Some(c)`: the file's channel `c`; `None`: a constant, 1 for alpha and the
/// lookup's fill beyond it. `file_channels` 0 (unknown) reads the channel as asked.
pub fn usd_uv_channel(file_channels: u32, channel: u32) -> Option<u32> {
    match (file_channels, channel) {
        (0, c) => Some(c),
        (1 | 2, 0..=2) => Some(0),
        (2, 3) => Some(1),
        (n, c) if c < n.min(4) => Some(c),
        _ => None,
    }
}

impl Default for Lookup {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Filtered texture lookups, shared by every render thread.
///
/// Implementations keep whatever per-thread state they need themselves (OpenImageIO's
/// `Perthread`), so a `&self` lookup from any thread is all a caller does. Lookups never panic
/// and never block on another thread's file I/O longer than the tile they need.
pub trait TextureSampler: Send + Sync {
    /// Opens (or finds already open) the texture at `path` (a file path or whatever the
    /// implementation resolves; UTF-8).
    ///
    /// # Errors
    /// [`TextureError`] naming the path when the texture cannot be read (missing, unreadable, not
    /// an image). The caller falls back and warns; it should not retry per lookup.
    fn handle(&self, path: &str) -> Result<TextureHandle, TextureError>;

    /// [`TextureSampler::handle`] for a file whose values are encoded as `space` says, so that
    /// lookups return linear values. The same path in two encodings is two handles.
    ///
    /// The default serves samplers whose values are linear by construction (procedural ones):
    /// `Auto` and `Raw` open the path as it is, `Srgb` is refused.
    ///
    /// # Errors
    /// As [`TextureSampler::handle`]; also when the sampler cannot decode `space`, or cannot write
    /// the decoded copy.
    fn handle_encoded(&self, path: &str, space: SourceColorSpace) -> Result<TextureHandle, TextureError> {
        match space {
            SourceColorSpace::Auto | SourceColorSpace::Raw => self.handle(path),
            SourceColorSpace::Srgb => {
                Err(TextureError { path: path.to_string(), message: "this texture sampler cannot decode sRGB".into() })
            }
        }
    }

    /// Whether `handle` reads a linear copy decoded from an sRGB file (so a caller can warn when
    /// `auto` decoded a file that feeds data rather than colour). The default: never.
    fn decoded_from_srgb(&self, _handle: TextureHandle) -> bool {
        false
    }

    /// Filtered value of `out.len()` channels (from `lookup.first_channel`) at `st`, over the
    /// footprint spanned by `dst_dx = (ds/dx, dt/dx)` and `dst_dy = (ds/dy, dt/dy)` (texture-space
    /// units per step; see the module doc), as the sampler's [`FilterMode`] says. Returns false,
    /// leaving `out` unspecified, for an unknown handle or a read failure; the failure is counted
    /// in [`TextureSampler::stats`].
    fn sample(&self, handle: TextureHandle, st: [f32; 2], dst_dx: [f32; 2], dst_dy: [f32; 2], lookup: &Lookup, out: &mut [f32]) -> bool;

    /// The finest level's resolution in texels (width, height), if known.
    fn resolution(&self, _handle: TextureHandle) -> Option<[u32; 2]> {
        None
    }

    /// The whole texture at a reduced resolution, at most `max_width` texels wide: the first MIP
    /// level that narrow (each texel the average of the finest texels it covers), `channels`
    /// channels from channel 0. What importance tables are built from (the dome light's, see
    /// [`crate::light::EnvTexture`]); not for shading. `None` when the texture cannot be read.
    ///
    /// The default makes one lookup per texel at its centre, filtered over exactly that texel
    /// (derivatives of one texel): right for any sampler whose lookups box-filter their
    /// footprint. Implementations with direct access to MIP levels (OpenImageIO's `get_texels`)
    /// override it.
    fn texels(&self, handle: TextureHandle, max_width: u32, channels: u32) -> Option<Texels> {
        texels_by_lookups(self, handle, max_width, channels)
    }

    /// Every MIP level of UsdUVTexture output channel `channel` (r = 0, g = 1, …; mapped onto the
    /// file's channels by [`usd_uv_channel`]) of `handle`, finest first, each texel in the
    /// file's own format, with the wrap modes the file names: what the core's displacement
    /// texture store ([`crate::displacement_texture`]) keeps and filters itself.
    ///
    /// `None` (the default) when the sampler does not hand out its levels, or the channel is a
    /// constant the file lacks: the caller then looks each point up through
    /// [`TextureSampler::sample`]. `Some(Err(reason))` when it should have but could not (the
    /// caller warns once, naming the file, and looks points up the same way).
    fn channel_levels(&self, _handle: TextureHandle, _channel: u32) -> Option<Result<ChannelLevels, String>> {
        None
    }

    /// The filter mode every lookup uses.
    fn filter_mode(&self) -> FilterMode;

    /// Counters for the stats JSON's `texture_cache` object: plain JSON numbers (and a few
    /// strings), names documented by the implementation.
    fn stats(&self) -> Value;
}

impl std::fmt::Debug for dyn TextureSampler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TextureSampler({:?})", self.filter_mode())
    }
}

/// One MIP level's texels of one channel, as the file stores them ([`TextureSampler::channel_levels`]):
/// row-major, the **first row at the top** of the image (t = 1), as [`Texels`].
#[derive(Clone, Debug, PartialEq)]
pub struct TexelLevel {
    pub width: u32,
    pub height: u32,
    pub texels: LevelTexels,
}

/// Texel values in the file's own format, so that keeping them loses nothing: a texel's value
/// is what OpenImageIO reads it as (an 8-bit value v as v / 255, a 16-bit one as v / 65535).
#[derive(Clone, Debug, PartialEq)]
pub enum LevelTexels {
    U8(Vec<u8>),
    U16(Vec<u16>),
    /// IEEE 754 binary16 bit patterns (OpenEXR's half).
    Half(Vec<u16>),
    F32(Vec<f32>),
}

impl LevelTexels {
    /// Texels held.
    pub fn len(&self) -> usize {
        match self {
            LevelTexels::U8(v) => v.len(),
            LevelTexels::U16(v) | LevelTexels::Half(v) => v.len(),
            LevelTexels::F32(v) => v.len(),
        }
    }

    /// Whether it holds no texel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes a texel takes.
    pub fn texel_bytes(&self) -> usize {
        match self {
            LevelTexels::U8(_) => 1,
            LevelTexels::U16(_) | LevelTexels::Half(_) => 2,
            LevelTexels::F32(_) => 4,
        }
    }

    /// The format's name for stats: `uint8`, `uint16`, `half`, `float`.
    pub fn format_name(&self) -> &'static str {
        match self {
            LevelTexels::U8(_) => "uint8",
            LevelTexels::U16(_) => "uint16",
            LevelTexels::Half(_) => "half",
            LevelTexels::F32(_) => "float",
        }
    }
}

/// A texture channel's MIP levels, finest first ([`TextureSampler::channel_levels`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelLevels {
    pub levels: Vec<TexelLevel>,
    /// The wrap modes (s, t) the file names, what [`Wrap::FromFile`] reads as (never
    /// `FromFile` itself).
    pub file_wrap: [Wrap; 2],
}

/// A texture's texels at one resolution (see [`TextureSampler::texels`]): row-major, `channels`
/// floats per texel, the **first row at the top** of the image (t = 1) and s increasing along a
/// row, so texel (i, j) covers s ∈ [i/width, (i+1)/width], t ∈ [1 − (j+1)/height, 1 − j/height].
#[derive(Clone, Debug, PartialEq)]
pub struct Texels {
    pub width: u32,
    pub height: u32,
    pub channels: u32,
    pub data: Vec<f32>,
}

impl Texels {
    /// Channel `c` of texel (column `i`, row `j` from the top).
    pub fn at(&self, i: u32, j: u32, c: u32) -> f32 {
        self.data[((j as usize * self.width as usize + i as usize) * self.channels as usize) + c as usize]
    }
}

/// The resolution of the first MIP level at most `max_width` wide: halve (rounding down, at
/// least 1) from the finest `resolution`, as MIP levels are made.
pub fn reduced_resolution(resolution: [u32; 2], max_width: u32) -> ([u32; 2], u32) {
    let [mut w, mut h] = resolution.map(|x| x.max(1));
    let mut level = 0;
    while w > max_width.max(1) {
        w = (w / 2).max(1);
        h = (h / 2).max(1);
        level += 1;
    }
    ([w, h], level)
}

/// [`TextureSampler::texels`] by one box-filtered lookup per texel (the trait's default). A
/// texture of unknown resolution is read at `max_width` × `max_width / 2` (a latlong's shape).
pub fn texels_by_lookups<S: TextureSampler + ?Sized>(sampler: &S, handle: TextureHandle, max_width: u32, channels: u32) -> Option<Texels> {
    let [w, h] = match sampler.resolution(handle) {
        Some(r) => reduced_resolution(r, max_width).0,
        None => [max_width.max(1), (max_width / 2).max(1)],
    };
    let channels = channels.clamp(1, 4);
    let lookup = Lookup { first_channel: 0, wrap_s: Wrap::Clamp, wrap_t: Wrap::Clamp, fill: 0.0 };
    let mut data = vec![0.0f32; (w * h * channels) as usize];
    let (dx, dy) = ([1.0 / w as f32, 0.0], [0.0, 1.0 / h as f32]);
    for j in 0..h {
        for i in 0..w {
            let st = [(i as f32 + 0.5) / w as f32, 1.0 - (j as f32 + 0.5) / h as f32];
            let k = ((j * w + i) * channels) as usize;
            if !sampler.sample(handle, st, dx, dy, &lookup, &mut data[k..k + channels as usize]) {
                return None;
            }
        }
    }
    Some(Texels { width: w, height: h, channels, data })
}

/// Width of the lookup footprint in texels of the finest level: the longer side of the
/// parallelogram spanned by the derivatives, measured in texels (`resolution` = finest width,
/// height). 0 for zero derivatives.
pub fn footprint_texels(dst_dx: [f32; 2], dst_dy: [f32; 2], resolution: [u32; 2]) -> f32 {
    let (w, h) = (resolution[0] as f32, resolution[1] as f32);
    let len = |d: [f32; 2]| ((d[0] * w).powi(2) + (d[1] * h).powi(2)).sqrt();
    len(dst_dx).max(len(dst_dy))
}

/// The MIP level (0 = finest) whose texels are as wide as the footprint: log₂ of
/// [`footprint_texels`], clamped to [0, `max_level`]. The isotropic choice (major axis), as a
/// trilinear lookup makes it; an anisotropic filter reads up to log₂(anisotropy) levels finer.
pub fn mip_level(dst_dx: [f32; 2], dst_dy: [f32; 2], resolution: [u32; 2], max_level: u32) -> f32 {
    let texels = footprint_texels(dst_dx, dst_dy, resolution);
    // NaN reads the finest level too.
    if texels.is_nan() || texels <= 1.0 {
        return 0.0;
    }
    texels.log2().min(max_level as f32)
}

/// Levels the [`CheckerSampler`] histograms (level ≥ this goes in the last bin).
pub const CHECKER_LEVELS: usize = 16;

/// A procedural black-and-white checker standing in for an image texture in core tests.
///
/// It serves one texture, named at construction: a `resolution`² image of `squares`² squares,
/// value 0 where the square's column + row is even (the bottom-left square is 0) and 1 elsewhere,
/// in every channel, repeating outside [0, 1]² (wrap modes are ignored). A lookup returns the
/// exact average of the checker over the footprint's bounding box in (s, t) — the ideal box filter
/// a MIP map approximates — so a lookup that covers many squares returns 0.5. It records the MIP
/// level ([`mip_level`]) each lookup would read from a `resolution`² MIP map, so tests can check
/// which levels a computation asks for.
#[derive(Debug)]
pub struct CheckerSampler {
    name: String,
    resolution: u32,
    squares: u32,
    filter: FilterMode,
    lookups: AtomicU64,
    failed: AtomicU64,
    /// Lookups per MIP level (`floor` of the fractional level).
    levels: [AtomicU64; CHECKER_LEVELS],
    /// Sum of fractional levels × 1024, for the mean.
    level_sum_milli: AtomicU64,
}

impl CheckerSampler {
    /// A checker served under `name`.
    ///
    /// # Panics
    /// If `resolution` or `squares` is 0 (a test's mistake).
    pub fn new(name: &str, resolution: u32, squares: u32, filter: FilterMode) -> Self {
        assert!(resolution > 0 && squares > 0, "checker needs a positive resolution and square count");
        CheckerSampler {
            name: name.to_string(),
            resolution,
            squares,
            filter,
            lookups: AtomicU64::new(0),
            failed: AtomicU64::new(0),
            levels: Default::default(),
            level_sum_milli: AtomicU64::new(0),
        }
    }

    /// The coarsest MIP level: log₂ of the resolution, rounded down.
    pub fn max_level(&self) -> u32 {
        31 - self.resolution.leading_zeros()
    }

    /// Lookups per MIP level so far (index = level, the last bin holds deeper ones).
    pub fn level_histogram(&self) -> Vec<u64> {
        self.levels.iter().map(|a| a.load(Ordering::Relaxed)).collect()
    }

    /// Mean fractional MIP level of the lookups so far (0 when there were none).
    pub fn mean_level(&self) -> f64 {
        let n = self.lookups.load(Ordering::Relaxed);
        if n == 0 {
            return 0.0;
        }
        self.level_sum_milli.load(Ordering::Relaxed) as f64 / 1024.0 / n as f64
    }

    /// Zeroes the counters.
    pub fn reset(&self) {
        self.lookups.store(0, Ordering::Relaxed);
        self.failed.store(0, Ordering::Relaxed);
        self.level_sum_milli.store(0, Ordering::Relaxed);
        for a in &self.levels {
            a.store(0, Ordering::Relaxed);
        }
    }

    /// The checker's exact average over [s0, s1] × [t0, t1] (a degenerate interval is a point).
    pub fn box_average(&self, s0: f32, s1: f32, t0: f32, t1: f32) -> f32 {
        // checker = (1 − q(s)·q(t)) / 2 with q = ±1 the square wave, so the box average factors.
        let n = self.squares as f64;
        let qs = square_wave_mean(s0 as f64 * n, s1 as f64 * n);
        let qt = square_wave_mean(t0 as f64 * n, t1 as f64 * n);
        (0.5 * (1.0 - qs * qt)) as f32
    }
}

/// Mean over [a, b] of the square wave that is +1 on [0, 1) and −1 on [1, 2), period 2.
fn square_wave_mean(a: f64, b: f64) -> f64 {
    // Its integral from 0 is the triangle wave r ↦ r on [0, 1], 2 − r on [1, 2] (r = y mod 2).
    let tri = |y: f64| {
        let r = y.rem_euclid(2.0);
        if r < 1.0 {
            r
        } else {
            2.0 - r
        }
    };
    if b - a > 1e-9 {
        (tri(b) - tri(a)) / (b - a)
    } else if a.rem_euclid(2.0) < 1.0 {
        1.0
    } else {
        -1.0
    }
}

impl TextureSampler for CheckerSampler {
    fn handle(&self, path: &str) -> Result<TextureHandle, TextureError> {
        if path == self.name {
            Ok(TextureHandle::new(0))
        } else {
            Err(TextureError { path: path.to_string(), message: format!("no such texture (the checker serves only {:?})", self.name) })
        }
    }

    fn sample(&self, handle: TextureHandle, st: [f32; 2], dst_dx: [f32; 2], dst_dy: [f32; 2], _lookup: &Lookup, out: &mut [f32]) -> bool {
        if handle.index() != 0 || !(st[0].is_finite() && st[1].is_finite()) {
            self.failed.fetch_add(1, Ordering::Relaxed);
            return false;
        }
        let (dx, dy) = self.filter.widths(dst_dx, dst_dy);
        let res = [self.resolution; 2];
        let level = mip_level(dx, dy, res, self.max_level());
        self.lookups.fetch_add(1, Ordering::Relaxed);
        self.levels[(level as usize).min(CHECKER_LEVELS - 1)].fetch_add(1, Ordering::Relaxed);
        self.level_sum_milli.fetch_add((level * 1024.0) as u64, Ordering::Relaxed);
        let ws = 0.5 * dx[0].abs().max(dy[0].abs());
        let wt = 0.5 * dx[1].abs().max(dy[1].abs());
        let v = self.box_average(st[0] - ws, st[0] + ws, st[1] - wt, st[1] + wt);
        out.fill(v);
        true
    }

    fn resolution(&self, handle: TextureHandle) -> Option<[u32; 2]> {
        (handle.index() == 0).then_some([self.resolution; 2])
    }

    fn filter_mode(&self) -> FilterMode {
        self.filter
    }

    /// `kind` ("checker"), `filter_mode`, `lookups`, `failed_lookups`, `lookups_by_level` (one
    /// count per MIP level, finest first), `mean_level`.
    fn stats(&self) -> Value {
        json!({
            "kind": "checker",
            "filter_mode": self.filter.name(),
            "lookups": self.lookups.load(Ordering::Relaxed),
            "failed_lookups": self.failed.load(Ordering::Relaxed),
            "lookups_by_level": self.level_histogram(),
            "mean_level": self.mean_level(),
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Texture coordinates

/// USD's primvar interpolation: how many values a primvar has and how they spread over a face.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Interpolation {
    /// One value for the whole mesh.
    Constant,
    /// One value per face.
    Uniform,
    /// One value per point, interpolated linearly over each face.
    Varying,
    /// One value per point, interpolated like the points (the subdivision basis).
    Vertex,
    /// One value per face-vertex, discontinuous across faces where the values differ (UV seams).
    #[default]
    FaceVarying,
}

impl Interpolation {
    /// USD's token: `constant`, `uniform`, `varying`, `vertex`, `faceVarying`.
    pub fn from_usd(token: &str) -> Option<Interpolation> {
        match token {
            "constant" => Some(Interpolation::Constant),
            "uniform" => Some(Interpolation::Uniform),
            "varying" => Some(Interpolation::Varying),
            "vertex" => Some(Interpolation::Vertex),
            "faceVarying" => Some(Interpolation::FaceVarying),
            _ => None,
        }
    }

    /// How many elements a primvar of this interpolation has on `topology` with `points` points.
    pub fn element_count(self, topology: &MeshTopology, points: usize) -> usize {
        match self {
            Interpolation::Constant => 1,
            Interpolation::Uniform => topology.face_count(),
            Interpolation::Varying | Interpolation::Vertex => points,
            Interpolation::FaceVarying => topology.face_vertex_indices.len(),
        }
    }
}

/// A 2-float primvar (`st`) as USD authors it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Primvar2 {
    /// The primvar's name (`st`), for messages.
    pub name: String,
    pub interpolation: Interpolation,
    pub values: Vec<[f32; 2]>,
    /// USD's `indices`: element i takes `values[indices[i]]`. Empty: element i takes `values[i]`.
    pub indices: Vec<i32>,
}

impl Primvar2 {
    /// A primvar of 1 to 3 components (a float, a colour, a normal) as 2-float channels:
    /// (c0, c1), then (c2, 0) for a third component; a float's second lane is 0. Every
    /// interpolation is linear in each component, so the channels together interpolate as the
    /// primvar would.
    pub fn split(name: &str, interpolation: Interpolation, values: &[[f32; 3]], components: usize, indices: &[i32]) -> Vec<Primvar2> {
        let channel = |lanes: [usize; 2], used: usize| Primvar2 {
            name: name.to_string(),
            interpolation,
            values: values.iter().map(|v| [v[lanes[0]], if used > 1 { v[lanes[1]] } else { 0.0 }]).collect(),
            indices: indices.to_vec(),
        };
        match components {
            0 | 1 => vec![channel([0, 0], 1)],
            2 => vec![channel([0, 1], 2)],
            _ => vec![channel([0, 1], 2), channel([2, 2], 1)],
        }
    }

    /// Resolves the primvar to one index into `values` per face-vertex (in `faceVertexIndices`
    /// order): the face-varying channel that represents it exactly. `points` is the mesh's point
    /// count.
    ///
    /// # Errors
    /// [`MeshError::Invalid`] naming the primvar when the element count (or index count) does not
    /// match the interpolation, or an index is out of range; [`MeshError::NonFinite`] for a NaN
    /// or infinite value.
    pub fn face_varying_indices(&self, topology: &MeshTopology, points: usize) -> Result<Vec<i32>, MeshError> {
        let name = &self.name;
        let elements = self.interpolation.element_count(topology, points);
        if let Some((i, v)) = self.values.iter().enumerate().find(|(_, v)| !(v[0].is_finite() && v[1].is_finite())) {
            return Err(MeshError::NonFinite(format!("primvar {name}: value [{i}] = {v:?}")));
        }
        let element_source = if self.indices.is_empty() { self.values.len() } else { self.indices.len() };
        if element_source != elements {
            let what = if self.indices.is_empty() { "values" } else { "indices" };
            return Err(MeshError::Invalid(format!(
                "primvar {name}: {element_source} {what} for {:?} interpolation, which needs {elements}",
                self.interpolation
            )));
        }
        if let Some((i, &bad)) = self.indices.iter().enumerate().find(|(_, &k)| k < 0 || k as usize >= self.values.len()) {
            return Err(MeshError::Invalid(format!("primvar {name}: indices[{i}] = {bad} is out of range [0, {})", self.values.len())));
        }
        let value_of = |element: usize| {
            if self.indices.is_empty() {
                element as i32
            } else {
                self.indices[element]
            }
        };
        let mut out = Vec::with_capacity(topology.face_vertex_indices.len());
        let mut fv = 0usize;
        for (face, &n) in topology.face_vertex_counts.iter().enumerate() {
            for _ in 0..n.max(0) {
                let element = match self.interpolation {
                    Interpolation::Constant => 0,
                    Interpolation::Uniform => face,
                    Interpolation::Varying | Interpolation::Vertex => {
                        topology.face_vertex_indices.get(fv).map_or(0, |&p| p.max(0) as usize)
                    }
                    Interpolation::FaceVarying => fv,
                };
                out.push(value_of(element));
                fv += 1;
            }
        }
        Ok(out)
    }
}

/// A value with its derivatives with respect to a patch's own (u, v).
pub type Value2 = ([f32; 2], [f32; 2], [f32; 2]);

/// A 2-float primvar interpolated linearly over each base face, by ptex face: bilinearly over a
/// quad, over each quad sub-face of an n-gon (corner, next edge midpoint, centroid, previous edge
/// midpoint — OpenSubdiv's split, as [`crate::bilinear::BilinearSurface`] makes it), and
/// barycentrically over a Loop mesh's triangles. Exact for constant, uniform and varying
/// primvars on any scheme, and for every interpolation on a polygonal (`none` or bilinear) mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct BaseFacePrimvar {
    /// Per ptex face: its corner values at (0,0), (1,0), (1,1), (0,1); a triangle's are at
    /// (0,0), (1,0), (0,1) and the fourth repeats the third.
    corners: Vec<[[f32; 2]; 4]>,
    triangles: bool,
}

impl BaseFacePrimvar {
    /// Builds the per-ptex-face corners of `primvar` on `topology` (with `points` points).
    ///
    /// # Errors
    /// As [`Primvar2::face_varying_indices`], and [`MeshError::Invalid`] for a Loop mesh with a
    /// non-triangle.
    pub fn new(topology: &MeshTopology, points: usize, primvar: &Primvar2) -> Result<Self, MeshError> {
        let idx = primvar.face_varying_indices(topology, points)?;
        let triangles = topology.scheme == Scheme::Loop;
        let mut corners = Vec::with_capacity(topology.face_count());
        let mut start = 0usize;
        for (face, &n) in topology.face_vertex_counts.iter().enumerate() {
            let n = n.max(0) as usize;
            let fv: Vec<[f32; 2]> = idx[start..start + n].iter().map(|&k| primvar.values[k as usize]).collect();
            start += n;
            if triangles {
                if n != 3 {
                    return Err(MeshError::Invalid(format!("primvar {}: Loop face {face} has {n} vertices", primvar.name)));
                }
                corners.push([fv[0], fv[1], fv[2], fv[2]]);
            } else if n == 4 {
                corners.push([fv[0], fv[1], fv[2], fv[3]]);
            } else {
                let mid = |a: [f32; 2], b: [f32; 2]| [(a[0] + b[0]) * 0.5, (a[1] + b[1]) * 0.5];
                let inv = 1.0 / n as f32;
                let centroid = fv.iter().fold([0.0f32; 2], |c, v| [c[0] + v[0] * inv, c[1] + v[1] * inv]);
                for i in 0..n {
                    corners.push([fv[i], mid(fv[i], fv[(i + 1) % n]), centroid, mid(fv[i], fv[(i + n - 1) % n])]);
                }
            }
        }
        Ok(BaseFacePrimvar { corners, triangles })
    }

    /// Number of ptex faces it covers.
    pub fn ptex_face_count(&self) -> usize {
        self.corners.len()
    }

    /// The value at (face u, face v) of a ptex face, with derivatives with respect to them.
    pub fn at_face(&self, ptex_face: u32, u: f32, v: f32) -> Option<Value2> {
        let [c0, c1, c2, c3] = *self.corners.get(ptex_face as usize)?;
        let mut val = [0.0; 2];
        let mut du = [0.0; 2];
        let mut dv = [0.0; 2];
        for k in 0..2 {
            if self.triangles {
                val[k] = (1.0 - u - v) * c0[k] + u * c1[k] + v * c2[k];
                du[k] = c1[k] - c0[k];
                dv[k] = c2[k] - c0[k];
            } else {
                val[k] = (1.0 - u) * (1.0 - v) * c0[k] + u * (1.0 - v) * c1[k] + u * v * c2[k] + (1.0 - u) * v * c3[k];
                du[k] = (1.0 - v) * (c1[k] - c0[k]) + v * (c2[k] - c3[k]);
                dv[k] = (1.0 - u) * (c3[k] - c0[k]) + u * (c2[k] - c1[k]);
            }
        }
        Some((val, du, dv))
    }

    /// The value at a patch's own (u, v), with derivatives with respect to them (the chain rule
    /// through [`PatchParam::to_face_uv`]). `None` for a ptex face it does not cover.
    pub fn at_patch(&self, param: &PatchParam, u: f32, v: f32) -> Option<Value2> {
        let (fu, fv) = param.to_face_uv(u, v);
        let (val, du, dv) = self.at_face(param.ptex_face, fu, fv)?;
        let s = param.size;
        Some((val, [du[0] * s, du[1] * s], [dv[0] * s, dv[1] * s]))
    }
}

/// The UDIM tile holding `st` (`1001 + ⌊s⌋ + 10 ⌊t⌋`, the convention of Mari and USD's
/// `<UDIM>` paths: tile 1001 is st ∈ [0, 1)², 1002 one to the right, 1011 one up) and `st`
/// within it; `None` outside the ten columns (s ∉ [0, 10)), below t = 0, or not finite.
pub fn udim_tile(st: [f32; 2]) -> Option<(u32, [f32; 2])> {
    let (u, v) = (st[0].floor(), st[1].floor());
    if !(u.is_finite() && v.is_finite()) || !(0.0..10.0).contains(&u) || !(0.0..100.0).contains(&v) {
        return None;
    }
    Some((1001 + u as u32 + 10 * v as u32, [st[0] - u, st[1] - v]))
}

/// A UDIM tile set as one texture: each lookup reads the tile its `st` falls in (see
/// [`udim_tile`]), at `st` within the tile, through the sampler that opened the tiles. A lookup
/// in a tile the set lacks fails, so the input takes its fallback there (as a missing file
/// does). Filter footprints stay in their tile: tiles are separate images.
pub struct UdimSampler {
    inner: std::sync::Arc<dyn TextureSampler>,
    /// (tile number, the inner sampler's handle), sorted by tile.
    tiles: Vec<(u32, TextureHandle)>,
}

impl UdimSampler {
    /// The set of `tiles` (tile number, handle of `inner`); the handle a [`UdimSampler`] is
    /// looked up with is ignored.
    pub fn new(inner: std::sync::Arc<dyn TextureSampler>, mut tiles: Vec<(u32, TextureHandle)>) -> Self {
        tiles.sort_by_key(|t| t.0);
        tiles.dedup_by_key(|t| t.0);
        UdimSampler { inner, tiles }
    }

    fn tile(&self, number: u32) -> Option<TextureHandle> {
        self.tiles.binary_search_by_key(&number, |t| t.0).ok().map(|i| self.tiles[i].1)
    }
}

impl TextureSampler for UdimSampler {
    fn handle(&self, path: &str) -> Result<TextureHandle, TextureError> {
        Err(TextureError { path: path.to_string(), message: "a UDIM set opens its tiles through its inner sampler".into() })
    }

    fn decoded_from_srgb(&self, _handle: TextureHandle) -> bool {
        self.tiles.iter().any(|t| self.inner.decoded_from_srgb(t.1))
    }

    fn sample(&self, _handle: TextureHandle, st: [f32; 2], dst_dx: [f32; 2], dst_dy: [f32; 2], lookup: &Lookup, out: &mut [f32]) -> bool {
        let Some((number, local)) = udim_tile(st) else { return false };
        let Some(handle) = self.tile(number) else { return false };
        self.inner.sample(handle, local, dst_dx, dst_dy, lookup, out)
    }

    fn filter_mode(&self) -> FilterMode {
        self.inner.filter_mode()
    }

    fn stats(&self) -> Value {
        self.inner.stats()
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    #[test]
    fn missing_channels_follow_usd_uv_texture() {
        // (file channels, [r, g, b, a] sources)
        let cases = [
            (1, [Some(0), Some(0), Some(0), None]),
            (2, [Some(0), Some(0), Some(0), Some(1)]),
            (3, [Some(0), Some(1), Some(2), None]),
            (4, [Some(0), Some(1), Some(2), Some(3)]),
            (0, [Some(0), Some(1), Some(2), Some(3)]),
        ];
        for (n, want) in cases {
            let got: Vec<Option<u32>> = (0..4).map(|c| usd_uv_channel(n, c)).collect();
            assert_eq!(got, want, "{n} channels");
        }
        assert_eq!(usd_uv_channel(4, 4), None);
    }

    use super::*;

    #[test]
    fn udim_tiles_follow_the_convention_and_lookups_read_their_own_tile() {
        assert_eq!(udim_tile([0.25, 0.5]), Some((1001, [0.25, 0.5])));
        assert_eq!(udim_tile([1.5, 0.25]), Some((1002, [0.5, 0.25])));
        assert_eq!(udim_tile([0.5, 1.75]), Some((1011, [0.5, 0.75])));
        assert_eq!(udim_tile([9.5, 2.5]), Some((1030, [0.5, 0.5])));
        assert_eq!(udim_tile([10.5, 0.5]), None);
        assert_eq!(udim_tile([-0.5, 0.5]), None);
        assert_eq!(udim_tile([f32::NAN, 0.5]), None);
        // A checker as tile 1012: a lookup there at st + (1, 1) reads it exactly as a lookup of
        // it alone at st.
        let inner: std::sync::Arc<dyn TextureSampler> = std::sync::Arc::new(CheckerSampler::new("c", 1024, 8, FilterMode::Differentials));
        let b = inner.handle("c").unwrap();
        let udim = UdimSampler::new(inner.clone(), vec![(1012, b)]);
        let lookup = Lookup::DEFAULT;
        for st in [[0.06f32, 0.06], [0.19, 0.06], [0.31, 0.81]] {
            let (mut want, mut got) = ([0.0f32; 1], [0.0f32; 1]);
            assert!(inner.sample(b, st, [1e-3, 0.0], [0.0, 1e-3], &lookup, &mut want));
            assert!(udim.sample(TextureHandle::new(99), [st[0] + 1.0, st[1] + 1.0], [1e-3, 0.0], [0.0, 1e-3], &lookup, &mut got));
            assert_eq!(got, want, "{st:?}");
        }
        // Tile 1002 is not in the set: the lookup fails (the input's fallback).
        assert!(!udim.sample(TextureHandle::new(0), [1.5, 0.5], [1e-3, 0.0], [0.0, 1e-3], &lookup, &mut [0.0]));
    }

    #[test]
    fn checker_box_average_is_exact() {
        let c = CheckerSampler::new("c", 1024, 8, FilterMode::Differentials);
        // Points: the bottom-left square is 0, its right neighbour 1.
        assert_eq!(c.box_average(0.06, 0.06, 0.06, 0.06), 0.0);
        assert_eq!(c.box_average(0.19, 0.19, 0.06, 0.06), 1.0);
        // A box over exactly two squares side by side, or over whole periods: 0.5.
        assert!((c.box_average(0.0, 0.25, 0.0, 0.125) - 0.5).abs() < 1e-6);
        assert!((c.box_average(0.1, 0.85, 0.2, 0.7) - 0.5).abs() < 0.07);
        // 1¼ squares wide, one square high: 1/5 of the box is over the neighbouring 1-square.
        assert!((c.box_average(0.0, 0.15625, 0.0, 0.125) - 0.2).abs() < 1e-6);
    }

    #[test]
    fn checker_lookups_record_levels_and_finest_ignores_widths() {
        let c = CheckerSampler::new("c", 1024, 8, FilterMode::Differentials);
        let h = c.handle("c").unwrap();
        assert!(c.handle("other").unwrap_err().to_string().contains("other"));
        let mut out = [0.0f32; 3];
        // One texel wide: level 0. 64 texels: level 6. The whole texture: level 10, value 0.5.
        assert!(c.sample(h, [0.06, 0.06], [1.0 / 1024.0, 0.0], [0.0, 1.0 / 1024.0], &Lookup::DEFAULT, &mut out));
        assert_eq!(out, [0.0; 3]);
        c.sample(h, [0.5, 0.5], [64.0 / 1024.0, 0.0], [0.0, 64.0 / 1024.0], &Lookup::DEFAULT, &mut out);
        c.sample(h, [0.3, 0.7], [1.0, 0.0], [0.0, 1.0], &Lookup::DEFAULT, &mut out);
        assert!((out[0] - 0.5).abs() < 1e-6, "{out:?}");
        let hist = c.level_histogram();
        assert_eq!((hist[0], hist[6], hist[10]), (1, 1, 1));
        let f = CheckerSampler::new("c", 1024, 8, FilterMode::Finest);
        f.sample(h, [0.3, 0.7], [1.0, 0.0], [0.0, 1.0], &Lookup::DEFAULT, &mut out);
        assert_eq!(f.level_histogram()[0], 1);
        assert!(out[0] == 0.0 || out[0] == 1.0);
        assert_eq!(c.stats()["lookups"], 3);
        assert!(!c.sample(TextureHandle::new(7), [0.5, 0.5], [0.0; 2], [0.0; 2], &Lookup::DEFAULT, &mut out));
        assert_eq!(c.stats()["failed_lookups"], 1);
    }

    #[test]
    fn non_finite_widths_read_the_finest_level() {
        let (dx, dy) = FilterMode::Differentials.widths([f32::NAN, 0.5], [f32::INFINITY, 0.25]);
        assert_eq!((dx, dy), ([0.0, 0.5], [0.0, 0.25]));
        assert_eq!(mip_level([0.0; 2], [0.0; 2], [512, 512], 9), 0.0);
        assert!((mip_level([0.25, 0.0], [0.0, 0.0], [512, 256], 9) - 7.0).abs() < 1e-6);
    }

    fn two_quads_and_a_triangle() -> MeshTopology {
        MeshTopology {
            scheme: Scheme::None,
            face_vertex_counts: vec![4, 4, 3],
            face_vertex_indices: vec![0, 1, 4, 3, 1, 2, 5, 4, 3, 4, 6],
            ..Default::default()
        }
    }

    #[test]
    fn every_interpolation_resolves_to_face_vertex_indices() {
        let t = two_quads_and_a_triangle();
        let pv = |interpolation, values: Vec<[f32; 2]>, indices: Vec<i32>| Primvar2 { name: "st".into(), interpolation, values, indices };
        let c = pv(Interpolation::Constant, vec![[0.5, 0.5]], vec![]);
        assert_eq!(c.face_varying_indices(&t, 7).unwrap(), vec![0; 11]);
        let u = pv(Interpolation::Uniform, vec![[0.0; 2]; 3], vec![]);
        assert_eq!(u.face_varying_indices(&t, 7).unwrap(), vec![0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2]);
        let v = pv(Interpolation::Vertex, vec![[0.0; 2]; 7], vec![]);
        assert_eq!(v.face_varying_indices(&t, 7).unwrap(), t.face_vertex_indices);
        let fv = pv(Interpolation::FaceVarying, vec![[0.0; 2], [1.0; 2]], vec![0, 1, 1, 0, 0, 1, 1, 0, 0, 1, 1]);
        assert_eq!(fv.face_varying_indices(&t, 7).unwrap(), fv.indices);
        let short = pv(Interpolation::Vertex, vec![[0.0; 2]; 6], vec![]);
        assert!(short.face_varying_indices(&t, 7).unwrap_err().to_string().contains("primvar st: 6 values"));
        let bad = pv(Interpolation::Uniform, vec![[0.0; 2]], vec![0, 0, 3]);
        assert!(bad.face_varying_indices(&t, 7).unwrap_err().to_string().contains("indices[2] = 3"));
        let nan = pv(Interpolation::Constant, vec![[f32::NAN, 0.0]], vec![]);
        assert!(matches!(nan.face_varying_indices(&t, 7), Err(MeshError::NonFinite(_))));
    }

    #[test]
    fn base_face_primvar_is_bilinear_per_ptex_face() {
        let t = two_quads_and_a_triangle();
        let st: Vec<[f32; 2]> = vec![[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [0.0, 1.0], [0.5, 1.0], [1.0, 1.0], [0.25, 2.0]];
        let p =
            BaseFacePrimvar::new(&t, 7, &Primvar2 { name: "st".into(), interpolation: Interpolation::Vertex, values: st, indices: vec![] })
                .unwrap();
        // Two quads and a triangle split into three: five ptex faces.
        assert_eq!(p.ptex_face_count(), 5);
        let (v, du, dv) = p.at_face(1, 0.5, 0.25).unwrap();
        assert_eq!((v, du, dv), ([0.75, 0.25], [0.5, 0.0], [0.0, 1.0]));
        // The triangle's first sub-face: corner 3 at (0,0), the centroid at (1,1).
        let (v, _, _) = p.at_face(2, 1.0, 1.0).unwrap();
        assert!((v[0] - 0.25).abs() < 1e-6 && (v[1] - 4.0 / 3.0).abs() < 1e-6, "{v:?}");
        // Through a patch param: a quarter-size patch at (0.5, 0.5) of face 0.
        let param = PatchParam {
            base_face: 0,
            ptex_face: 0,
            u0: 0.5,
            v0: 0.5,
            size: 0.25,
            depth: 2,
            boundary_mask: 0,
            transition_mask: 0,
            kind: crate::patch::PatchKind::Regular,
        };
        let (v, du, _) = p.at_patch(&param, 1.0, 0.0).unwrap();
        assert_eq!((v, du), ([0.375, 0.5], [0.125, 0.0]));
        assert!(p.at_face(9, 0.0, 0.0).is_none());
    }

    #[test]
    fn srgb_curve_and_tokens() {
        // The curve's published anchors: 0 and 1 are fixed, 8-bit 128 is 0.2158.
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_to_linear(128.0 / 255.0) - 0.215_861).abs() < 1e-5);
        // Continuous at the knee.
        assert!((srgb_to_linear(0.04045) - srgb_to_linear(0.040_451)).abs() < 1e-6);
        for s in [SourceColorSpace::Auto, SourceColorSpace::Raw, SourceColorSpace::Srgb] {
            assert_eq!(SourceColorSpace::from_usd(s.usd_name()), Some(s));
        }
        assert_eq!(SourceColorSpace::from_usd("srgb"), None);
        // A procedural sampler has nothing to decode: raw and auto open, sRGB is refused by name.
        let c = CheckerSampler::new("c", 64, 8, FilterMode::Differentials);
        assert!(c.handle_encoded("c", SourceColorSpace::Auto).is_ok());
        let e = c.handle_encoded("c", SourceColorSpace::Srgb).unwrap_err();
        assert!(e.to_string().contains("texture c") && e.to_string().contains("sRGB"), "{e}");
    }
}
