//! The displacement texture store: a displacement texture's MIP levels kept in the core and
//! filtered here, so that making a displaced grid costs a few tens of instructions a vertex for
//! its texture rather than a general-purpose texture lookup (OpenImageIO's `texture()` took
//! ~7,700 instructions a vertex: anisotropic probes, bicubic weights, tile look-ups behind a
//! shared cache; docs/throughput-callgrind.md).
//!
//! Each (texture, channel) a displacement reads is read once through the [`TextureSampler`]
//! ([`TextureSampler::channel_levels`]: every level the file has, or the ones OpenImageIO makes
//! for a file without them), at the first grid that needs it, into a [`TexturePyramid`] kept in
//! the texel format of the file (8- and 16-bit integers, half or float: nothing is lost by
//! keeping it). Lookups after that read immutable memory: no lock, no cache, no tile.
//!
//! The filter ([`TexturePyramid::sample`]) is trilinear: bilinear within a level, linear between
//! the two levels around the footprint's, the level chosen from the lookup's derivatives as
//! [`crate::texture::mip_level`] chooses it (the longer side of the footprint, so isotropic:
//! where the grid's steps in `st` differ in length the longer one sets the blur). Texel centres,
//! the t flip and the wrap modes are OpenImageIO's, so the result differs from its `texture()` by
//! the filter only (its anisotropic probes and bicubic weights); the figures are in
//! docs/throughput-callgrind.md. A constant texture gives exactly its constant, and a linear
//! ramp (whose box-filtered levels are the same ramp) exactly the ramp, to float rounding.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

use serde_json::{json, Value};

use crate::texture::{ChannelLevels, FilterMode, LevelTexels, TexelLevel, TextureHandle, TextureSampler, Wrap};

/// Levels a pyramid may hold: a 2³¹-texel-wide image has 32.
const MAX_LEVELS: usize = 32;

/// Bytes one texture's levels may take before the store declines to keep them (and its lookups
/// go through the sampler, warned once): the store keeps whole pyramids resident.
pub const MAX_PYRAMID_BYTES: usize = 2 << 30;

/// One channel of a texture's MIP levels, filtered trilinearly (see the module doc).
#[derive(Debug)]
pub struct TexturePyramid {
    path: String,
    channel: u32,
    levels: Vec<TexelLevel>,
    file_wrap: [Wrap; 2],
    filter: FilterMode,
    /// The finest level's width and height, texels.
    res: [f32; 2],
    /// The coarsest level's index.
    max_level: f32,
}

impl TexturePyramid {
    /// Keeps `levels` (finest first) of `path`'s channel `channel`, filtered in `filter` mode.
    ///
    /// # Errors
    /// One line naming the file when the levels are unusable: none, more than 32, a level of
    /// zero width or height, texels not filling a level, or more than [`MAX_PYRAMID_BYTES`].
    pub fn new(path: &str, channel: u32, levels: ChannelLevels, filter: FilterMode) -> Result<Self, String> {
        let ChannelLevels { levels, file_wrap } = levels;
        let Some(first) = levels.first() else {
            return Err(format!("texture {path}: no MIP level to read"));
        };
        if levels.len() > MAX_LEVELS {
            return Err(format!("texture {path}: {} MIP levels (at most {MAX_LEVELS})", levels.len()));
        }
        let mut bytes = 0usize;
        for (i, l) in levels.iter().enumerate() {
            let texels = (l.width as usize).checked_mul(l.height as usize);
            if l.width == 0 || l.height == 0 || texels != Some(l.texels.len()) {
                return Err(format!("texture {path}: MIP level {i} is {}x{} with {} texels", l.width, l.height, l.texels.len()));
            }
            bytes = bytes.saturating_add(l.texels.len() * l.texels.texel_bytes());
        }
        if bytes > MAX_PYRAMID_BYTES {
            return Err(format!(
                "texture {path}: its MIP levels take {} MB, more than the {} MB the displacement texture store keeps of one texture",
                bytes >> 20,
                MAX_PYRAMID_BYTES >> 20
            ));
        }
        // What OpenImageIO reads when the file names no wrap mode.
        let file_wrap = file_wrap.map(|w| if w == Wrap::FromFile { Wrap::Black } else { w });
        Ok(TexturePyramid {
            path: path.to_string(),
            channel,
            res: [first.width as f32, first.height as f32],
            max_level: (levels.len() - 1) as f32,
            levels,
            file_wrap,
            filter,
        })
    }

    /// The texture's path.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The UsdUVTexture output channel kept (r = 0, …).
    pub fn channel(&self) -> u32 {
        self.channel
    }

    /// The levels, finest first.
    pub fn levels(&self) -> &[TexelLevel] {
        &self.levels
    }

    /// Bytes the texels take.
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(|l| l.texels.len() * l.texels.texel_bytes()).sum()
    }

    /// The wrap modes [`Wrap::FromFile`] reads as (s, t).
    pub fn file_wrap(&self) -> [Wrap; 2] {
        self.file_wrap
    }

    /// The fractional MIP level (0 = finest) a lookup with derivatives `dst_dx`, `dst_dy`
    /// (texture units per step) reads: log₂ of the footprint's longer side in finest-level
    /// texels, within [0, the coarsest level]; 0 in [`FilterMode::Finest`] and for footprints
    /// of at most a texel. Non-finite derivatives count as 0.
    #[inline]
    pub fn level(&self, dst_dx: [f32; 2], dst_dy: [f32; 2]) -> f32 {
        let (dx, dy) = self.filter.widths(dst_dx, dst_dy);
        let [w, h] = self.res;
        let sq = |d: [f32; 2]| (d[0] * w) * (d[0] * w) + (d[1] * h) * (d[1] * h);
        let m = sq(dx).max(sq(dy));
        // log₂ of the length is half that of its square (no square root).
        if m > 1.0 {
            (0.5 * m.log2()).min(self.max_level)
        } else {
            0.0
        }
    }

    /// The texel value (the file's units) at `st` (texture space, t up) filtered over the
    /// footprint `dst_dx`, `dst_dy` (texture units per step), wrapped as `wrap` (s, t) says:
    /// bilinear in the two levels around [`TexturePyramid::level`], linear between them.
    /// `None` for a non-finite `st`.
    #[inline]
    pub fn sample(&self, st: [f32; 2], dst_dx: [f32; 2], dst_dy: [f32; 2], wrap: [Wrap; 2]) -> Option<f32> {
        if !(st[0].is_finite() && st[1].is_finite()) {
            return None;
        }
        let wrap = [self.resolve(wrap[0], 0), self.resolve(wrap[1], 1)];
        // OpenImageIO's t runs down from the first row, as the levels' rows do.
        let (s, y) = (st[0], 1.0 - st[1]);
        let level = self.level(dst_dx, dst_dy);
        let l0 = level as usize;
        let f = level - l0 as f32;
        let a = self.bilinear(l0, s, y, wrap);
        if f > 0.0 && l0 + 1 < self.levels.len() {
            let b = self.bilinear(l0 + 1, s, y, wrap);
            Some(a + (b - a) * f)
        } else {
            Some(a)
        }
    }

    fn resolve(&self, w: Wrap, axis: usize) -> Wrap {
        if w == Wrap::FromFile {
            self.file_wrap[axis]
        } else {
            w
        }
    }

    /// Level `l` (clamped to the coarsest) at (s, y), y the down-running t, bilinearly.
    ///
    /// Nearly every lookup reads four texels inside the level, where no wrap mode moves or
    /// blackens any: those are read directly ([`inside`]), with the arithmetic of the general
    /// path ([`TexturePyramid::bilinear_wrapped`]) and so its bits (test
    /// `bilinear_inside_the_image_is_the_general_path_bit_for_bit`), without its per-texel
    /// wrap factors. The general path took ~190 instructions a level, most of a displaced
    /// vertex's lookup (docs/throughput-callgrind.md).
    #[inline]
    fn bilinear(&self, l: usize, s: f32, y: f32, wrap: [Wrap; 2]) -> f32 {
        let level = &self.levels[l.min(self.levels.len() - 1)];
        let (Some((i, fx)), Some((j, fy))) = (inside(s, level.width, wrap[0]), inside(y, level.height, wrap[1])) else {
            return Self::bilinear_wrapped(level, s, y, wrap);
        };
        let w = level.width as usize;
        let (k0, k1) = (j * w + i, (j + 1) * w + i);
        match &level.texels {
            LevelTexels::U8(d) => mix_inside(d, k0, k1, fx, fy, |x| f32::from(x) * (1.0 / 255.0)),
            LevelTexels::U16(d) => mix_inside(d, k0, k1, fx, fy, |x| f32::from(x) * (1.0 / 65535.0)),
            LevelTexels::Half(d) => mix_inside(d, k0, k1, fx, fy, half_to_f32),
            LevelTexels::F32(d) => mix_inside(d, k0, k1, fx, fy, |x| x),
        }
    }

    /// [`TexturePyramid::bilinear`] in `level` through the wrap modes: every lookup, the
    /// edges' and the outside's included.
    fn bilinear_wrapped(level: &TexelLevel, s: f32, y: f32, wrap: [Wrap; 2]) -> f32 {
        let ax = Axis::new(s, level.width, wrap[0]);
        let ay = Axis::new(y, level.height, wrap[1]);
        let w = level.width as usize;
        match &level.texels {
            LevelTexels::U8(d) => ax.mix(&ay, w, |k| f32::from(d[k]) * (1.0 / 255.0)),
            LevelTexels::U16(d) => ax.mix(&ay, w, |k| f32::from(d[k]) * (1.0 / 65535.0)),
            LevelTexels::Half(d) => ax.mix(&ay, w, |k| half_to_f32(d[k])),
            LevelTexels::F32(d) => ax.mix(&ay, w, |k| d[k]),
        }
    }
}

/// The two texels a bilinear lookup reads along one axis, the fraction of the way from the first
/// to the second, and whether each lies inside the image (`keep` 0 for a texel of
/// [`Wrap::Black`]'s outside).
struct Axis {
    i: [usize; 2],
    keep: [f32; 2],
    f: f32,
}

impl Axis {
    /// Along an axis of `n` texels at coordinate `c` (texture units, 0 at the first texel's
    /// edge): texel centres at (i + ½)/n, as OpenImageIO places them.
    #[inline(always)]
    fn new(c: f32, n: u32, wrap: Wrap) -> Axis {
        let nf = n as f32;
        let last = i64::from(n) - 1;
        let split = |x: f32| {
            let i = floor(x);
            (i as i64, x - i)
        };
        match wrap {
            Wrap::Clamp => {
                // Beyond a texel outside, every position reads the edge texel alone.
                let (i, f) = split((c * nf - 0.5).clamp(-1.0, nf));
                Axis { i: [i.clamp(0, last) as usize, (i + 1).clamp(0, last) as usize], keep: [1.0; 2], f }
            }
            Wrap::Black | Wrap::FromFile => {
                let (i, f) = split((c * nf - 0.5).clamp(-2.0, nf + 1.0));
                let inside = |k: i64| if (0..=last).contains(&k) { 1.0 } else { 0.0 };
                Axis { i: [i.clamp(0, last) as usize, (i + 1).clamp(0, last) as usize], keep: [inside(i), inside(i + 1)], f }
            }
            Wrap::Periodic => {
                let (i, f) = split((c - floor(c)) * nf - 0.5);
                // i within [−1, n − 1] (n − 1 when the product rounds up to n).
                let a = if i < 0 { last } else { i.min(last) };
                let b = if i + 1 > last { 0 } else { i + 1 };
                Axis { i: [a as usize, b as usize], keep: [1.0; 2], f }
            }
            Wrap::Mirror => {
                // One period is the image and its mirror image: 2n texels.
                let (i, f) = split((c - 2.0 * floor(c * 0.5)) * nf - 0.5);
                let period = 2 * i64::from(n);
                let fold = |k: i64| {
                    let k = k.rem_euclid(period);
                    (if k < i64::from(n) { k } else { period - 1 - k }).clamp(0, last) as usize
                };
                Axis { i: [fold(i), fold(i + 1)], keep: [1.0; 2], f }
            }
        }
    }

    /// Bilinear mix over this axis (x) and `ay` (y) of a level `w` texels wide, texel k read by
    /// `at`. Interpolated as a + (b − a)·f so that equal texels give exactly their value.
    #[inline(always)]
    fn mix(&self, ay: &Axis, w: usize, at: impl Fn(usize) -> f32) -> f32 {
        let row = |r: usize, keep: f32| {
            let a = at(r * w + self.i[0]) * (self.keep[0] * keep);
            let b = at(r * w + self.i[1]) * (self.keep[1] * keep);
            a + (b - a) * self.f
        };
        let r0 = row(ay.i[0], ay.keep[0]);
        let r1 = row(ay.i[1], ay.keep[1]);
        r0 + (r1 - r0) * ay.f
    }
}

/// Where a lookup at `c` (texture units) along an axis of `n` texels reads, as [`Axis::new`]
/// computes it for `wrap` (the same operations): the first of its two texels and the fraction
/// toward the second, when both lie inside the image as computed, so that no wrap mode moves,
/// clamps or blackens either (their `keep` factors are 1, and multiplying by 1 changes no
/// bits). `None` otherwise (an edge, the outside, a level one texel wide), left to the general
/// path.
#[inline(always)]
fn inside(c: f32, n: u32, wrap: Wrap) -> Option<(usize, f32)> {
    let nf = n as f32;
    // Axis::new's clamps change nothing inside (they pin outside values, which stay outside).
    let x = match wrap {
        Wrap::Clamp | Wrap::Black | Wrap::FromFile => c * nf - 0.5,
        Wrap::Periodic => (c - floor(c)) * nf - 0.5,
        Wrap::Mirror => (c - 2.0 * floor(c * 0.5)) * nf - 0.5,
    };
    // floor(x) and its integer, as `floor` and the general path's cast give them, without
    // the casts' saturation (beyond 2²³ the general path).
    if !(x.abs() < 8_388_608.0) {
        return None;
    }
    // SAFETY: |x| < 2²³, so its truncation fits an i32.
    let t = unsafe { x.to_int_unchecked::<i32>() };
    let (k, i) = if t as f32 > x { (t - 1, t as f32 - 1.0) } else { (t, t as f32) };
    (k >= 0 && (k as u32) + 1 < n).then_some((k as usize, x - i))
}

/// The bilinear mix of texels `k0`, `k0 + 1` (a row) and `k1`, `k1 + 1` (the next) of `d`, read
/// as values by `at`, at fractions `fx` along the rows and `fy` between them: [`Axis::mix`]'s
/// operations with every `keep` factor 1.
#[inline(always)]
fn mix_inside<T: Copy>(d: &[T], k0: usize, k1: usize, fx: f32, fy: f32, at: impl Fn(T) -> f32) -> f32 {
    let row = |k: usize| {
        let (a, b) = (at(d[k]), at(d[k + 1]));
        a + (b - a) * fx
    };
    let (r0, r1) = (row(k0), row(k1));
    r0 + (r1 - r0) * fy
}

/// `x.floor()` without a call: x86-64's baseline (SSE2) has no rounding instruction, so
/// `f32::floor` calls libm's, which cost more than the rest of a bilinear lookup. Exact: a
/// float of magnitude 2²³ or more is an integer already; NaN stays NaN (−0 becomes +0).
#[inline(always)]
fn floor(x: f32) -> f32 {
    if x.abs() < 8_388_608.0 {
        // SAFETY: |x| < 2²³, so its truncation fits an i32 (`as` would add saturation's tests).
        let i = unsafe { x.to_int_unchecked::<i32>() } as f32;
        if i > x {
            i - 1.0
        } else {
            i
        }
    } else {
        x
    }
}

/// An IEEE 754 binary16 value (bit pattern) as f32: exact, every half being a float.
#[inline]
pub fn half_to_f32(h: u16) -> f32 {
    let sign = u32::from(h & 0x8000) << 16;
    let exp = u32::from(h >> 10) & 0x1f;
    let man = u32::from(h & 0x3ff);
    match exp {
        0 => {
            // Zero or subnormal: man · 2⁻²⁴, exact in f32.
            let v = man as f32 * (1.0 / 16_777_216.0);
            if sign != 0 {
                -v
            } else {
                v
            }
        }
        0x1f => f32::from_bits(sign | 0x7f80_0000 | (man << 13)),
        e => f32::from_bits(sign | ((e + 112) << 23) | (man << 13)),
    }
}

/// The pyramid of one (texture, channel), read once: `None` when the sampler gives no levels.
type Slot = Arc<OnceLock<Option<Arc<TexturePyramid>>>>;

/// The displacement texture store of one [`TextureSampler`]: each (texture, channel) a
/// displacement reads, read once and kept ([`TexturePyramid`]). One per sampler, shared by every
/// [`crate::displacement::TextureDisplacement`] made with it, so a texture bound by many meshes
/// (or materials) is kept once.
pub struct DisplacementTextures {
    sampler: Arc<dyn TextureSampler>,
    slots: Mutex<HashMap<(TextureHandle, u32), Slot>>,
}

impl std::fmt::Debug for DisplacementTextures {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DisplacementTextures").field("sampler", &self.sampler).finish_non_exhaustive()
    }
}

impl DisplacementTextures {
    /// An empty store reading through `sampler`.
    pub fn new(sampler: Arc<dyn TextureSampler>) -> Self {
        DisplacementTextures { sampler, slots: Mutex::new(HashMap::new()) }
    }

    /// The sampler it reads through.
    pub fn sampler(&self) -> &Arc<dyn TextureSampler> {
        &self.sampler
    }

    /// The pyramid of UsdUVTexture output channel `channel` of `texture` (opened as `path`),
    /// read through the sampler at the first call (a thread asking meanwhile waits for it);
    /// `None` when the sampler gives no levels for it (warned once, naming the file, when it
    /// should have), and the caller looks points up through the sampler.
    pub fn pyramid(&self, texture: TextureHandle, channel: u32, path: &str) -> Option<Arc<TexturePyramid>> {
        let slot = {
            let mut slots = self.slots.lock().unwrap_or_else(PoisonError::into_inner);
            slots.entry((texture, channel)).or_default().clone()
        };
        slot.get_or_init(|| {
            let levels = match self.sampler.channel_levels(texture, channel)? {
                Ok(l) => l,
                Err(e) => {
                    log::warn!(
                        "displacement texture {path}: cannot keep its MIP levels ({e}); looking each point up through the texture system"
                    );
                    return None;
                }
            };
            match TexturePyramid::new(path, channel, levels, self.sampler.filter_mode()) {
                Ok(p) => Some(Arc::new(p)),
                Err(e) => {
                    log::warn!("{e}; looking each displacement point up through the texture system");
                    None
                }
            }
        })
        .clone()
    }

    /// The pyramids read so far.
    pub fn pyramids(&self) -> Vec<Arc<TexturePyramid>> {
        let slots = self.slots.lock().unwrap_or_else(PoisonError::into_inner);
        let mut v: Vec<Arc<TexturePyramid>> = slots.values().filter_map(|s| s.get().cloned().flatten()).collect();
        v.sort_by(|a, b| (a.path.as_str(), a.channel).cmp(&(b.path.as_str(), b.channel)));
        v
    }

    /// Bytes its pyramids take.
    pub fn bytes(&self) -> usize {
        self.pyramids().iter().map(|p| p.bytes()).sum()
    }

    /// Textures (channels) whose levels could not be kept, so that their points are looked up
    /// through the sampler.
    pub fn declined(&self) -> usize {
        let slots = self.slots.lock().unwrap_or_else(PoisonError::into_inner);
        slots.values().filter(|s| matches!(s.get(), Some(None))).count()
    }
}

/// The stats JSON's `displacement_textures` object for the stores of a scene's displacement
/// shaders (each store counted once): `bytes` (texels kept, all stores), `textures` (pyramids
/// kept), `looked_up_by_sampler` (texture channels whose levels could not be kept, read point by
/// point through the sampler), and `files[]`: `path`, `channel`, `format` (`uint8`, `uint16`,
/// `half`, `float`: the file's own), `resolution` (finest level), `levels`, `bytes`.
pub fn stats<'a>(stores: impl IntoIterator<Item = &'a Arc<DisplacementTextures>>) -> Value {
    let mut seen: Vec<*const DisplacementTextures> = Vec::new();
    let (mut bytes, mut declined) = (0usize, 0usize);
    let mut files = Vec::new();
    for store in stores {
        if seen.contains(&Arc::as_ptr(store)) {
            continue;
        }
        seen.push(Arc::as_ptr(store));
        declined += store.declined();
        for p in store.pyramids() {
            bytes += p.bytes();
            files.push(json!({
                "path": p.path,
                "channel": p.channel,
                "format": p.levels[0].texels.format_name(),
                "resolution": [p.levels[0].width, p.levels[0].height],
                "levels": p.levels.len(),
                "bytes": p.bytes(),
            }));
        }
    }
    json!({ "bytes": bytes, "textures": files.len(), "looked_up_by_sampler": declined, "files": files })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// Levels of a `n`×`n` image (n a power of two) given by `f(i, j)` at the finest level, each
    /// coarser level the 2×2 box average of the one above (as maketx's box filter makes them).
    fn box_levels(n: u32, f: impl Fn(u32, u32) -> f32) -> Vec<TexelLevel> {
        let mut levels = vec![TexelLevel { width: n, height: n, texels: LevelTexels::F32((0..n * n).map(|k| f(k % n, k / n)).collect()) }];
        while levels.last().unwrap().width > 1 {
            let prev = levels.last().unwrap();
            let LevelTexels::F32(d) = &prev.texels else { unreachable!() };
            let (w, m) = (prev.width as usize, prev.width / 2);
            let mut next = Vec::new();
            for j in 0..m as usize {
                for i in 0..m as usize {
                    next.push(
                        (d[2 * j * w + 2 * i] + d[2 * j * w + 2 * i + 1] + d[(2 * j + 1) * w + 2 * i] + d[(2 * j + 1) * w + 2 * i + 1])
                            / 4.0,
                    );
                }
            }
            levels.push(TexelLevel { width: m, height: m, texels: LevelTexels::F32(next) });
        }
        levels
    }

    fn pyramid(levels: Vec<TexelLevel>, wrap: Wrap) -> TexturePyramid {
        TexturePyramid::new("t.tx", 0, ChannelLevels { levels, file_wrap: [wrap; 2] }, FilterMode::Differentials).unwrap()
    }

    #[test]
    fn floor_is_std_floor() {
        for x in [
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.5,
            -1.5,
            2.999_999_8,
            -2.999_999_8,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            1e20,
            -1e20,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ] {
            assert_eq!(floor(x), x.floor(), "{x}");
        }
        for k in 0..100_000 {
            let x = (k as f32 - 50_000.0) * 0.013_7;
            assert_eq!(floor(x), x.floor(), "{x}");
        }
        assert!(floor(f32::NAN).is_nan());
    }

    #[test]
    fn half_bits_convert_exactly() {
        for h in 0..=u16::MAX {
            let got = half_to_f32(h);
            let sign = if h & 0x8000 != 0 { -1.0f64 } else { 1.0 };
            let (e, m) = (i32::from((h >> 10) & 0x1f), f64::from(h & 0x3ff));
            let want = match e {
                0 => sign * m * 2f64.powi(-24),
                31 if m == 0.0 => sign * f64::INFINITY,
                31 => f64::NAN,
                _ => sign * (1.0 + m / 1024.0) * 2f64.powi(e - 15),
            };
            if want.is_nan() {
                assert!(got.is_nan(), "{h:#06x}");
            } else {
                assert_eq!(f64::from(got), want, "{h:#06x}");
                assert_eq!(got.is_sign_negative(), h & 0x8000 != 0, "{h:#06x}");
            }
        }
    }

    #[test]
    fn a_constant_texture_reads_exactly_its_constant() {
        let p = pyramid(box_levels(64, |_, _| 0.3), Wrap::Periodic);
        for k in 0..2000 {
            let t = k as f32 * 0.618_034;
            let st = [(t * 1.7).sin() * 3.0, (t * 0.9).cos() * 2.0 + 0.5];
            let d = (k % 13) as f32 * 0.01;
            for wrap in [Wrap::Periodic, Wrap::Clamp, Wrap::Mirror] {
                assert_eq!(p.sample(st, [d, 0.0], [0.0, d * 0.5], [wrap; 2]), Some(0.3), "{st:?} {d} {wrap:?}");
            }
        }
    }

    #[test]
    fn a_linear_ramp_reads_exactly_linear_at_every_level() {
        // Value s·(n texels) along s: texel i holds i + ½, its centre's s·n; every box level
        // is the same ramp, so any trilinear lookup away from the clamped edges is s·n.
        let n = 256;
        let p = pyramid(box_levels(n, |i, _| i as f32 + 0.5), Wrap::Clamp);
        let mut worst = 0.0f32;
        for k in 0..5000 {
            let s = 0.1 + 0.8 * (k as f32 / 5000.0);
            let t = (k as f32 * 0.37).fract();
            // Footprints from under a texel to 16 texels (levels 0 to 4, fractional).
            let d = (1 + k % 16) as f32 / n as f32;
            let got = p.sample([s, t], [d, 0.0], [0.0, d], [Wrap::Clamp; 2]).unwrap();
            worst = worst.max((got - s * n as f32).abs() / (s * n as f32));
        }
        assert!(worst < 4.0 * f32::EPSILON, "relative error {worst}");
        // Along t the ramp is constant, however wide the footprint.
        let q = pyramid(box_levels(n, |i, _| i as f32 + 0.5), Wrap::Clamp);
        assert_eq!(q.sample([0.5, 0.1], [0.0; 2], [0.0; 2], [Wrap::Clamp; 2]), q.sample([0.5, 0.9], [0.0; 2], [0.0; 2], [Wrap::Clamp; 2]));
    }

    #[test]
    fn levels_follow_the_footprint_and_blend_linearly() {
        // Level l holds the constant l: a lookup reads exactly its fractional level.
        let levels: Vec<TexelLevel> = (0..7)
            .map(|l| TexelLevel { width: 64 >> l, height: 64 >> l, texels: LevelTexels::F32(vec![l as f32; (64usize >> l).pow(2)]) })
            .collect();
        let p = pyramid(levels, Wrap::Periodic);
        for (texels, want) in [(0.5f32, 0.0f32), (1.0, 0.0), (2.0, 1.0), (4.0, 2.0), (2.0f32.powf(2.5), 2.5), (64.0, 6.0), (1e6, 6.0)] {
            let d = texels / 64.0;
            let got = p.sample([0.3, 0.6], [d, 0.0], [0.0, d * 0.25], [Wrap::FromFile; 2]).unwrap();
            assert!((got - want).abs() < 1e-5, "{texels} texels: {got}, want {want}");
            // The longer side sets the level, whichever derivative it is.
            let swapped = p.sample([0.3, 0.6], [0.0, d * 0.25], [d, 0.0], [Wrap::FromFile; 2]).unwrap();
            assert_eq!(got, swapped);
        }
        // Non-finite derivatives read the finest level; a non-finite st reads nothing.
        assert_eq!(p.sample([0.3, 0.6], [f32::NAN, f32::INFINITY], [0.0; 2], [Wrap::Periodic; 2]), Some(0.0));
        assert_eq!(p.sample([f32::NAN, 0.6], [0.0; 2], [0.0; 2], [Wrap::Periodic; 2]), None);
        // Finest mode ignores the footprint.
        let finest =
            TexturePyramid::new("t", 0, ChannelLevels { levels: p.levels.clone(), file_wrap: [Wrap::Periodic; 2] }, FilterMode::Finest)
                .unwrap();
        assert_eq!(finest.sample([0.3, 0.6], [1.0, 0.0], [0.0, 1.0], [Wrap::Periodic; 2]), Some(0.0));
    }

    #[test]
    fn bilinear_texels_and_wraps_are_openimageios() {
        // A 4×2 level, rows top first; texel centres at (i + ½)/4 along s and t = 1 − (j + ½)/2.
        let d = vec![1.0, 2.0, 3.0, 4.0, 10.0, 20.0, 30.0, 40.0];
        let p = pyramid(vec![TexelLevel { width: 4, height: 2, texels: LevelTexels::F32(d) }], Wrap::Black);
        let at = |s: f32, t: f32, w: Wrap| p.sample([s, t], [0.0; 2], [0.0; 2], [w; 2]).unwrap();
        // Centres read their texel; halfway between two reads their mean.
        assert_eq!(at(0.125, 0.75, Wrap::Clamp), 1.0);
        assert_eq!(at(0.375, 0.25, Wrap::Clamp), 20.0);
        assert_eq!(at(0.25, 0.75, Wrap::Clamp), 1.5);
        assert_eq!(at(0.125, 0.5, Wrap::Clamp), 5.5);
        // At s = 0 (half a texel left of the first centre): clamp reads the edge texel,
        // periodic averages the first and last, mirror the first with itself, black half of it.
        assert_eq!(at(0.0, 0.75, Wrap::Clamp), 1.0);
        assert_eq!(at(0.0, 0.75, Wrap::Periodic), 2.5);
        assert_eq!(at(0.0, 0.75, Wrap::Mirror), 1.0);
        assert_eq!(at(0.0, 0.75, Wrap::Black), 0.5);
        // The file's mode for FromFile (black here), and far outside the image.
        assert_eq!(at(0.0, 0.75, Wrap::FromFile), 0.5);
        assert_eq!(at(-7.0, 0.75, Wrap::Black), 0.0);
        assert_eq!(at(-7.0, 0.75, Wrap::Clamp), 1.0);
        assert_eq!(at(2.125, 0.75, Wrap::Periodic), 1.0);
        assert_eq!(at(-0.625, 0.75, Wrap::Periodic), 2.0);
        // Mirror: s in [1, 2) reads the image reversed.
        assert_eq!(at(1.125, 0.75, Wrap::Mirror), 4.0);
        assert_eq!(at(-0.125, 0.75, Wrap::Mirror), 1.0);
        assert_eq!(at(1e9, 0.75, Wrap::Periodic), at(0.0, 0.75, Wrap::Periodic));
    }

    #[test]
    fn bilinear_inside_the_image_is_the_general_path_bit_for_bit() {
        // Levels of every texel format and of awkward sizes (one texel, one row, odd widths),
        // texels of mixed signs and magnitudes; lookups near and across every edge and far
        // outside, at every level, in every wrap mode.
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let mut uniform = move || (next() >> 40) as f32 / (1u64 << 24) as f32;
        let sizes = [(64u32, 64u32), (37, 5), (2, 2), (1, 1), (1, 9), (8, 1), (3, 2)];
        let mut levels = Vec::new();
        for (k, &(w, h)) in sizes.iter().enumerate() {
            let len = (w * h) as usize;
            let texels = match k % 4 {
                0 => LevelTexels::F32((0..len).map(|_| (uniform() - 0.3) * 7.0).collect()),
                1 => LevelTexels::U8((0..len).map(|_| (uniform() * 256.0) as u8).collect()),
                2 => LevelTexels::U16((0..len).map(|_| (uniform() * 65536.0) as u16).collect()),
                _ => LevelTexels::Half(
                    (0..len).map(|_| (0x3000 + (uniform() * 8192.0) as u32) as u16 | (0x8000 * u16::from(uniform() < 0.3))).collect(),
                ),
            };
            levels.push(TexelLevel { width: w, height: h, texels });
        }
        let p = pyramid(levels, Wrap::Black);
        let wraps = [Wrap::Clamp, Wrap::Periodic, Wrap::Mirror, Wrap::Black];
        let (mut fast, mut total) = (0, 0);
        for _ in 0..200_000 {
            // Mostly inside [0, 1]; a fifth near an edge (within two texels of the finest
            // level), a tenth far outside.
            let coordinate = |u: f32, r: f32| {
                if r < 0.7 {
                    u
                } else if r < 0.9 {
                    (u - 0.5) * 4.0 / 64.0 + if r < 0.8 { 0.0 } else { 1.0 }
                } else {
                    (u - 0.5) * 40.0
                }
            };
            let (s, y) = (coordinate(uniform(), uniform()), coordinate(uniform(), uniform()));
            let wrap = [wraps[(next() % 4) as usize], wraps[(next() % 4) as usize]];
            for l in 0..sizes.len() + 1 {
                let level = &p.levels[l.min(sizes.len() - 1)];
                let got = p.bilinear(l, s, y, wrap);
                let want = TexturePyramid::bilinear_wrapped(level, s, y, wrap);
                assert_eq!(got.to_bits(), want.to_bits(), "level {l} at ({s}, {y}) {wrap:?}: {got} against {want}");
                total += 1;
                fast += usize::from(inside(s, level.width, wrap[0]).is_some() && inside(y, level.height, wrap[1]).is_some());
            }
        }
        // Both paths were exercised.
        assert!(fast > total / 8 && fast < total * 7 / 8, "{fast} of {total} lookups inside");
    }

    #[test]
    fn integer_and_half_texels_read_as_openimageio_converts_them() {
        let one = |texels| {
            pyramid(vec![TexelLevel { width: 1, height: 1, texels }], Wrap::Clamp)
                .sample([0.5; 2], [0.0; 2], [0.0; 2], [Wrap::Clamp; 2])
                .unwrap()
        };
        assert_eq!(one(LevelTexels::U8(vec![51])), 51.0 * (1.0 / 255.0));
        assert_eq!(one(LevelTexels::U8(vec![255])), 1.0);
        assert_eq!(one(LevelTexels::U16(vec![65535])), 1.0);
        assert_eq!(one(LevelTexels::Half(vec![0x3c00])), 1.0);
        assert_eq!(one(LevelTexels::Half(vec![0xc000])), -2.0);
    }

    #[test]
    fn bad_levels_are_refused_naming_the_file() {
        let bad = |levels| {
            TexturePyramid::new("dir/h.tx", 0, ChannelLevels { levels, file_wrap: [Wrap::Clamp; 2] }, FilterMode::Differentials)
                .unwrap_err()
        };
        assert!(bad(vec![]).contains("dir/h.tx"));
        let short = TexelLevel { width: 2, height: 2, texels: LevelTexels::F32(vec![0.0; 3]) };
        assert!(bad(vec![short]).contains("level 0 is 2x2 with 3 texels"));
        let empty = TexelLevel { width: 0, height: 2, texels: LevelTexels::F32(vec![]) };
        assert!(bad(vec![empty]).contains("dir/h.tx"));
    }
}
