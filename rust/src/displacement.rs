//! Displacement applied at tessellation time, along the limit normal (the paper's §3: "the
//! ability to cache displaced tessellations ensures that we rarely need to run the displacement
//! shader repeatedly").
//!
//! Two shaders ([`DisplacementShader`]): the built-in procedural [`Displacement`], and
//! [`TextureDisplacement`] — UsdPreviewSurface `displacement` fed by a UsdUVTexture — which reads
//! the texture at each grid vertex's `st` with filter widths of one grid step in `st`, so a
//! coarse tier reads a coarse MIP level and a fine tier a fine one: the texture counterpart of
//! the tessellation MIP map (the paper's §2.6). The texture's levels are kept and filtered by
//! the core's displacement texture store ([`crate::displacement_texture`]), read once through
//! the texture sampler; a sampler that gives no levels is asked point by point.
//!
//! The built-in procedural displacement is fBm of gradient noise over object-space position, so
//! tests and benchmarks need no image files. It is filtered at the grid's own spacing: octaves
//! whose wavelength is shorter than two grid spacings are faded out, so a coarse tier reads a
//! smoother surface, as a coarse MIP level of a displacement texture would. Hand-written rather
//! than taken from a noise crate because the band limit per octave is the point, and it must be
//! bit-reproducible across platforms and thread counts.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

use glam::Vec3A;

use crate::displacement_texture::{DisplacementTextures, TexturePyramid};
use crate::patch::{LimitSurface, UvRect};
use crate::texture::{Lookup, SourceColorSpace, TextureError, TextureHandle, TextureSampler};

/// Grid spacings per wavelength from which the procedural displacement keeps a detail at full
/// weight ([`Displacement::offset`]).
pub const FULL_WEIGHT_SPACINGS: f32 = 4.0;

/// fBm displacement: `amplitude · Σ gainⁱ · noise(2ⁱ · frequency · p)`, i < octaves.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Displacement {
    /// Object units.
    pub amplitude: f32,
    /// Cycles per object unit of the first octave.
    pub frequency: f32,
    pub octaves: u32,
    /// Amplitude ratio between octaves (0.5 is classic fBm).
    pub gain: f32,
}

impl Displacement {
    /// Checks values a user can get wrong.
    ///
    /// # Errors
    /// A one-line description naming the attribute.
    pub fn validate(&self) -> Result<(), String> {
        if !self.amplitude.is_finite() {
            return Err(format!("mipray:displacement:amplitude = {} is not finite", self.amplitude));
        }
        if !(self.frequency.is_finite() && self.frequency > 0.0) {
            return Err(format!("mipray:displacement:frequency = {} must be positive", self.frequency));
        }
        if self.octaves == 0 || self.octaves > 16 {
            return Err(format!("mipray:displacement:octaves = {} must be within 1..=16", self.octaves));
        }
        if !(self.gain.is_finite() && self.gain > 0.0 && self.gain < 1.0) {
            return Err(format!("mipray:displacement:gain = {} must be within (0, 1)", self.gain));
        }
        Ok(())
    }

    /// The largest displacement this can produce (object units): the exact bound, since the
    /// noise is within [−1, 1].
    pub fn bound(&self) -> f32 {
        self.amplitude.abs() * (0..self.octaves).map(|i| self.gain.powi(i as i32)).sum::<f32>()
    }

    /// The wavelength of the finest octave (object units).
    pub fn shortest_wavelength(&self) -> f32 {
        1.0 / (self.frequency * 2f32.powi(self.octaves.max(1) as i32 - 1))
    }

    /// Displacement at object-space `p`, band-limited for a grid of `spacing` object units
    /// (0 = unfiltered): octave i is weighted by a smooth step from 1 (wavelength ≥
    /// [`FULL_WEIGHT_SPACINGS`] spacings) to 0 (wavelength ≤ 2 spacings).
    pub fn offset(&self, p: Vec3A, spacing: f32) -> f32 {
        let mut sum = 0.0;
        let mut f = self.frequency;
        let mut a = self.amplitude;
        for _ in 0..self.octaves {
            let wavelength = 1.0 / f;
            let w = if spacing > 0.0 { smoothstep(2.0 * spacing, FULL_WEIGHT_SPACINGS * spacing, wavelength) } else { 1.0 };
            if w <= 0.0 {
                break;
            }
            sum += a * w * gradient_noise(p * f);
            f *= 2.0;
            a *= self.gain;
        }
        sum
    }
}

/// UsdPreviewSurface `displacement` fed by a UsdUVTexture: at each vertex,
/// `texel[channel] · scale + bias` object units along the limit normal, the texel filtered over one
/// grid step in `st` (see [`TextureDisplacement::grid_offsets`]).
pub struct TextureDisplacement {
    store: Arc<DisplacementTextures>,
    sampler: Arc<dyn TextureSampler>,
    texture: TextureHandle,
    path: String,
    /// The surface's 2-float primvar channel holding `st` ([`LimitSurface::face_varying`]).
    pub st_channel: usize,
    /// Channel (UsdUVTexture output `r` = 0, `g` = 1, …) and wrap modes. The channel is read
    /// from the store at the first lookup: set it before.
    pub lookup: Lookup,
    /// UsdUVTexture `scale` and `bias` of that channel: object units per texel unit, and object
    /// units.
    pub scale: f32,
    pub bias: f32,
    /// Displacement (object units, not scaled) where a lookup fails: UsdUVTexture `fallback`.
    pub fallback: f32,
    /// `st` where the surface has no `st` channel: UsdPrimvarReader_float2's `fallback`.
    pub st_fallback: [f32; 2],
    /// The range texel values lie in, for [`TextureDisplacement::bound`]: [0, 1] (the default)
    /// for integer images; a float image's own range if it strays outside.
    pub value_range: [f32; 2],
    failed: AtomicU64,
    /// The store's pyramid of the channel, found at the first lookup (`None`: looked up point
    /// by point through the sampler).
    pyramid: OnceLock<Option<Arc<TexturePyramid>>>,
}

impl std::fmt::Debug for TextureDisplacement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TextureDisplacement")
            .field("path", &self.path)
            .field("texture", &self.texture)
            .field("st_channel", &self.st_channel)
            .field("lookup", &self.lookup)
            .field("scale", &self.scale)
            .field("bias", &self.bias)
            .field("fallback", &self.fallback)
            .field("value_range", &self.value_range)
            .finish_non_exhaustive()
    }
}

impl TextureDisplacement {
    /// Opens `path` through `sampler`; `st` comes from the surface's primvar channel
    /// `st_channel`. Scale 1, bias 0, channel 0, fallback 0, values in [0, 1]: set the public
    /// fields to match the UsdUVTexture.
    ///
    /// # Errors
    /// The sampler's [`TextureError`] (naming the path) when the texture cannot be read: the
    /// caller drops the displacement (or uses `fallback` as a constant) and warns.
    pub fn new(sampler: Arc<dyn TextureSampler>, path: &str, st_channel: usize) -> Result<Self, TextureError> {
        Self::new_encoded(sampler, path, SourceColorSpace::Raw, st_channel)
    }

    /// [`TextureDisplacement::new`] for a file whose values are encoded as `space` says
    /// (UsdUVTexture `sourceColorSpace`; the displacement is the decoded, linear value).
    ///
    /// # Errors
    /// As [`TextureDisplacement::new`].
    pub fn new_encoded(
        sampler: Arc<dyn TextureSampler>,
        path: &str,
        space: SourceColorSpace,
        st_channel: usize,
    ) -> Result<Self, TextureError> {
        Self::in_store(&Arc::new(DisplacementTextures::new(sampler)), path, space, st_channel)
    }

    /// [`TextureDisplacement::new_encoded`] through `store`'s sampler, its texels kept in
    /// `store` (shared with every displacement made with it: a texture is kept once).
    ///
    /// # Errors
    /// As [`TextureDisplacement::new`].
    pub fn in_store(
        store: &Arc<DisplacementTextures>,
        path: &str,
        space: SourceColorSpace,
        st_channel: usize,
    ) -> Result<Self, TextureError> {
        let sampler = store.sampler().clone();
        let texture = sampler.handle_encoded(path, space)?;
        Ok(TextureDisplacement {
            store: store.clone(),
            sampler,
            texture,
            path: path.to_string(),
            st_channel,
            lookup: Lookup::DEFAULT,
            scale: 1.0,
            bias: 0.0,
            fallback: 0.0,
            st_fallback: [0.0; 2],
            value_range: [0.0, 1.0],
            failed: AtomicU64::new(0),
            pyramid: OnceLock::new(),
        })
    }

    /// The store its texels are kept in.
    pub fn store(&self) -> &Arc<DisplacementTextures> {
        &self.store
    }

    /// The kept levels it filters, read at the first call; `None` when they could not be had
    /// (lookups then go through the sampler).
    pub fn pyramid(&self) -> Option<&Arc<TexturePyramid>> {
        self.pyramid.get_or_init(|| self.store.pyramid(self.texture, self.lookup.first_channel, &self.path)).as_ref()
    }

    /// The texture's handle in its sampler.
    pub fn texture(&self) -> TextureHandle {
        self.texture
    }

    /// The texture's path, as given.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// Checks values a user can get wrong.
    ///
    /// # Errors
    /// A one-line description naming the texture and the input.
    pub fn validate(&self) -> Result<(), String> {
        let p = &self.path;
        for (name, v) in [("scale", self.scale), ("bias", self.bias), ("fallback", self.fallback)] {
            if !v.is_finite() {
                return Err(format!("displacement texture {p}: {name} = {v} is not finite"));
            }
        }
        let [lo, hi] = self.value_range;
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(format!("displacement texture {p}: value range [{lo}, {hi}] is not an interval"));
        }
        Ok(())
    }

    /// The largest displacement this can produce (object units), given texel values within
    /// `value_range`.
    pub fn bound(&self) -> f32 {
        let [lo, hi] = self.value_range;
        (lo * self.scale + self.bias).abs().max((hi * self.scale + self.bias).abs()).max(self.fallback.abs())
    }

    /// Lookups that failed so far (each displaced by `fallback`).
    pub fn failed_lookups(&self) -> u64 {
        self.failed.load(Ordering::Relaxed)
    }

    /// Displacement (object units) at `st`, the texel filtered over the footprint spanned by
    /// `dst_dx`, `dst_dy` (texture units per step; see [`crate::texture`]) by the store's
    /// trilinear filter ([`TexturePyramid::sample`]), or through the sampler when the store
    /// has no levels of it.
    #[inline]
    pub fn offset_st(&self, st: [f32; 2], dst_dx: [f32; 2], dst_dy: [f32; 2]) -> f32 {
        let Some(p) = self.pyramid() else {
            return self.offset_st_sampled(st, dst_dx, dst_dy);
        };
        match p.sample(st, dst_dx, dst_dy, [self.lookup.wrap_s, self.lookup.wrap_t]) {
            Some(v) if v.is_finite() => v * self.scale + self.bias,
            _ => self.failed_lookup(),
        }
    }

    /// [`TextureDisplacement::offset_st`] through the sampler's own filter, one lookup
    /// (OpenImageIO's `texture()` in the bridge): the path when the store has no levels, and
    /// the reference the store's filter is measured against.
    pub fn offset_st_sampled(&self, st: [f32; 2], dst_dx: [f32; 2], dst_dy: [f32; 2]) -> f32 {
        let mut texel = [0.0f32; 1];
        if self.sampler.sample(self.texture, st, dst_dx, dst_dy, &self.lookup, &mut texel) && texel[0].is_finite() {
            texel[0] * self.scale + self.bias
        } else {
            self.failed_lookup()
        }
    }

    #[cold]
    fn failed_lookup(&self) -> f32 {
        self.failed.fetch_add(1, Ordering::Relaxed);
        self.fallback
    }

    /// Displacement (object units) at (u, v) of `patch`, filtered over a step of `uv_step` in
    /// the patch's u and v (0: the finest level, unfiltered), `st` and its derivatives from the
    /// surface as in [`TextureDisplacement::grid_offsets`].
    pub fn offset_on_patch(&self, surface: &dyn LimitSurface, patch: usize, u: f32, v: f32, uv_step: f32) -> f32 {
        let (st, dx, dy) = match surface.face_varying(self.st_channel, patch, u, v) {
            Some((st, dsdu, dsdv)) => (st, [dsdu[0] * uv_step, dsdu[1] * uv_step], [dsdv[0] * uv_step, dsdv[1] * uv_step]),
            None => (self.st_fallback, [0.0; 2], [0.0; 2]),
        };
        self.offset_st(st, dx, dy)
    }

    /// Quads a side at which a grid over the whole of `patch` reads only the finest MIP level
    /// (every step's footprint at most one finest-level texel, so [`TexturePyramid::level`] is
    /// 0 and the lookup is bilinear in level 0 alone): the largest of `|∂st/∂u|` and `|∂st/∂v|`
    /// in finest-level texels, over a 3 × 3 sampling of the patch's (u, v) (corners, edge
    /// middles, centre), × 1.25 for the derivatives' growth between samples. The texture's
    /// shortest wavelength is two texels of that level, so grids this fine or finer all read the
    /// same surface and differ only by their chords' sag (issue 23, docs/cracks.md rule 4).
    /// `None` when the finest level's size is unknown (the store holds no levels: looked up
    /// through the sampler); 0 where every lookup reads level 0 anyway ([`FilterMode::Finest`])
    /// or the surface has no `st` (the fallback is one point).
    ///
    /// [`FilterMode::Finest`]: crate::texture::FilterMode::Finest
    pub fn finest_level_rate(&self, surface: &dyn LimitSurface, patch: usize) -> Option<f32> {
        if self.sampler.filter_mode() == crate::texture::FilterMode::Finest {
            return Some(0.0);
        }
        let level0 = self.pyramid()?.levels().first()?;
        let (w, h) = (level0.width as f32, level0.height as f32);
        let texels = |d: [f32; 2]| ((d[0] * w) * (d[0] * w) + (d[1] * h) * (d[1] * h)).sqrt();
        let mut most = 0.0f32;
        for j in 0..3 {
            for i in 0..3 {
                if let Some((_, dsdu, dsdv)) = surface.face_varying(self.st_channel, patch, 0.5 * i as f32, 0.5 * j as f32) {
                    most = most.max(texels(dsdu)).max(texels(dsdv));
                }
            }
        }
        Some(if most.is_finite() { 1.25 * most } else { f32::INFINITY })
    }

    /// Re-filters the boundary offsets `out` of [`TextureDisplacement::grid_offsets`] so that a
    /// neighbour read at the same rate displaces their shared edge alike: each edge's inner
    /// vertices read the texture with an isotropic footprint of the edge's own mean step in `st`
    /// (the same points and steps from both sides where `st` is continuous across the edge),
    /// its corners at the finest level. Filtered with each grid's own `∂st/∂u · Δu`, `∂st/∂v ·
    /// Δv`, two neighbours read one edge through different footprints (the one across the edge
    /// differs) and can leave a crack even at one rate.
    pub fn filter_edges_alike(&self, surface: &dyn LimitSurface, patch: usize, rect: UvRect, n: usize, out: &mut [f32]) {
        use crate::seam::{edge_vertex, SeamEdges, DIAGONAL};
        if n < 2 || out.len() < n * n {
            return;
        }
        let st_at = |(i, j): (usize, usize)| {
            let (u, v) = rect.grid_uv(i, j, n);
            surface.face_varying(self.st_channel, patch, u, v).map(|(st, _, _)| st)
        };
        let domain = crate::tessellate::GridDomain::of(surface.patch_param(patch).kind, &rect);
        let edges = SeamEdges::ALL.within(domain);
        let mut st = Vec::with_capacity(n);
        for e in (0..=DIAGONAL).filter(|&e| edges.contains(e)) {
            st.clear();
            st.extend((0..n).map(|k| st_at(edge_vertex(e, k, n))));
            // No `st` along the edge: its vertices read the fallback, as the grid did.
            if st.iter().any(Option::is_none) {
                continue;
            }
            let st: Vec<[f32; 2]> = st.iter().flatten().copied().collect();
            let len: f32 = st.windows(2).map(|p| ((p[1][0] - p[0][0]).powi(2) + (p[1][1] - p[0][1]).powi(2)).sqrt()).sum();
            let step = len / (n - 1) as f32;
            for (k, &p) in st.iter().enumerate() {
                let (i, j) = edge_vertex(e, k, n);
                let w = if k == 0 || k == n - 1 { 0.0 } else { step };
                out[j * n + i] = self.offset_st(p, [w, 0.0], [0.0, w]);
            }
        }
    }

    /// Displacements (object units) of an n×n vertex grid over `rect` of `patch`, u fastest, into
    /// `out` (cleared first). Each vertex reads the texture at its `st` with filter widths of one
    /// grid step: `dst_dx = ∂st/∂u · Δu`, `dst_dy = ∂st/∂v · Δv`, where Δu, Δv are the grid's
    /// spacing in the patch's (u, v). A vertex where the surface has no `st` reads
    /// `st_fallback` with zero widths.
    pub fn grid_offsets(&self, surface: &dyn LimitSurface, patch: usize, rect: UvRect, n: usize, out: &mut Vec<f32>) {
        out.clear();
        let steps = (n.max(2) - 1) as f32;
        let (du, dv) = ((rect.u1 - rect.u0) / steps, (rect.v1 - rect.v0) / steps);
        let mut st_grid = Vec::with_capacity(n * n);
        surface.face_varying_grid(self.st_channel, patch, rect, n, &mut st_grid);
        for value in st_grid {
            let (st, dx, dy) = match value {
                Some((st, dsdu, dsdv)) => (st, [dsdu[0] * du, dsdu[1] * du], [dsdv[0] * dv, dsdv[1] * dv]),
                None => (self.st_fallback, [0.0; 2], [0.0; 2]),
            };
            out.push(self.offset_st(st, dx, dy));
        }
    }
}

/// What a mesh is displaced by.
#[derive(Clone, Debug)]
pub enum DisplacementShader {
    /// The built-in fBm.
    Procedural(Displacement),
    /// A displacement texture (shared: one per material, many meshes).
    Texture(Arc<TextureDisplacement>),
}

/// Procedural shaders are equal when their parameters are; texture shaders when they are the same
/// shared value (what a dirty check needs: a new texture shader is a change).
impl PartialEq for DisplacementShader {
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (DisplacementShader::Procedural(a), DisplacementShader::Procedural(b)) => a == b,
            (DisplacementShader::Texture(a), DisplacementShader::Texture(b)) => Arc::ptr_eq(a, b),
            _ => false,
        }
    }
}

impl From<Displacement> for DisplacementShader {
    fn from(d: Displacement) -> Self {
        DisplacementShader::Procedural(d)
    }
}

impl From<TextureDisplacement> for DisplacementShader {
    fn from(d: TextureDisplacement) -> Self {
        DisplacementShader::Texture(Arc::new(d))
    }
}

impl DisplacementShader {
    /// Checks values a user can get wrong.
    ///
    /// # Errors
    /// A one-line description naming the attribute or texture.
    pub fn validate(&self) -> Result<(), String> {
        match self {
            DisplacementShader::Procedural(d) => d.validate(),
            DisplacementShader::Texture(t) => t.validate(),
        }
    }

    /// The largest displacement this can produce (object units).
    pub fn bound(&self) -> f32 {
        match self {
            DisplacementShader::Procedural(d) => d.bound(),
            DisplacementShader::Texture(t) => t.bound(),
        }
    }

    /// Displacement (object units, along the limit normal) at one point: (u, v) of `patch`, where
    /// the undisplaced surface is at `p` (object space), filtered as a grid whose steps are
    /// `spacing` object units and `uv_step` in the patch's (u, v) would be (both 0: unfiltered).
    /// For shading and error measurement at a hit; [`DisplacementShader::grid_offsets`] at the
    /// same spacing gives the same values at grid vertices.
    pub fn offset_at(&self, surface: &dyn LimitSurface, patch: usize, uv: (f32, f32), p: Vec3A, spacing: f32, uv_step: f32) -> f32 {
        match self {
            DisplacementShader::Procedural(d) => d.offset(p, spacing),
            DisplacementShader::Texture(t) => t.offset_on_patch(surface, patch, uv.0, uv.1, uv_step),
        }
    }

    /// Re-filters the boundary offsets `out` of [`DisplacementShader::grid_offsets`] so that
    /// neighbours read at one rate displace their shared edge alike (the procedural shader; see
    /// [`filter_edges_alike`]): what the tessellation stores there is then not
    /// [`DisplacementShader::offset_at`] at the grid's spacing, which the interior still is.
    /// A texture's boundary reads the edge's own step in `st`
    /// ([`TextureDisplacement::filter_edges_alike`]; the tessellation asks for it only with the
    /// displaced rate floor on, `DisplaceParams::texture_edges_alike`).
    pub fn filter_edges(&self, surface: &dyn LimitSurface, patch: usize, rect: UvRect, verts: &[[f32; 3]], n: usize, out: &mut [f32]) {
        match self {
            DisplacementShader::Procedural(d) => filter_edges_alike(d, surface, patch, rect, verts, n, out),
            DisplacementShader::Texture(t) => t.filter_edges_alike(surface, patch, rect, n, out),
        }
    }

    /// The shortest wavelength of the detail (object units), where the shader knows it in object
    /// units (the procedural fBm's finest octave); `None` for a texture, whose detail is in `st`
    /// ([`TextureDisplacement::finest_level_rate`] gives its rate floor instead).
    pub fn shortest_wavelength(&self) -> Option<f32> {
        match self {
            DisplacementShader::Procedural(d) => Some(d.shortest_wavelength()),
            DisplacementShader::Texture(_) => None,
        }
    }

    /// Displacements (object units, along the limit normal) of the n×n grid `verts` (object
    /// space, undisplaced, u fastest) over `rect` of `patch`, filtered at the grid's own spacing,
    /// into `out` (cleared first; `verts.len()` values). The procedural shader filters at
    /// [`grid_spacing`] in object space, exactly as tessellation always did; the texture shader at
    /// one grid step in `st` ([`TextureDisplacement::grid_offsets`]).
    pub fn grid_offsets(&self, surface: &dyn LimitSurface, patch: usize, rect: UvRect, verts: &[[f32; 3]], n: usize, out: &mut Vec<f32>) {
        match self {
            DisplacementShader::Procedural(d) => {
                out.clear();
                let spacing = grid_spacing(verts, n);
                out.extend(verts.iter().map(|v| d.offset(Vec3A::from(*v), spacing)));
            }
            DisplacementShader::Texture(t) => t.grid_offsets(surface, patch, rect, n, out),
        }
    }
}

/// Re-displaces the boundary vertices of the n×n grid `verts` (undisplaced, object space) so
/// that a neighbour read at the same rate displaces the points of their shared edge as this
/// grid does: each edge's inner vertices filtered at that edge's own mean chord length (the
/// same chords on both sides), its corners unfiltered (a corner is shared by every patch around
/// the vertex, whose edges differ). Filtered at each grid's own spacing, neighbours of
/// different shapes read the same edge through different band limits and left cracks between
/// them even at one rate (issue 23).
fn filter_edges_alike(
    d: &Displacement,
    surface: &dyn LimitSurface,
    patch: usize,
    rect: UvRect,
    verts: &[[f32; 3]],
    n: usize,
    out: &mut [f32],
) {
    use crate::seam::{edge_vertex, SeamEdges, DIAGONAL};
    if n < 2 || verts.len() < n * n || out.len() < n * n {
        return;
    }
    let at = |(i, j): (usize, usize)| Vec3A::from(verts[j * n + i]);
    let domain = crate::tessellate::GridDomain::of(surface.patch_param(patch).kind, &rect);
    let edges = SeamEdges::ALL.within(domain);
    for e in (0..=DIAGONAL).filter(|&e| edges.contains(e)) {
        let len: f32 = (0..n - 1).map(|k| (at(edge_vertex(e, k + 1, n)) - at(edge_vertex(e, k, n))).length()).sum();
        let spacing = len / (n - 1) as f32;
        for k in 0..n {
            let (i, j) = edge_vertex(e, k, n);
            let corner = k == 0 || k == n - 1;
            out[j * n + i] = d.offset(at((i, j)), if corner { 0.0 } else { spacing });
        }
    }
}

/// Mean edge length of an n×n grid's middle row and column (object units): the spacing the
/// procedural displacement is filtered at. 0 for n < 2.
pub fn grid_spacing(verts: &[[f32; 3]], n: usize) -> f32 {
    if n < 2 || verts.len() < n * n {
        return 0.0;
    }
    let m = n / 2;
    let at = |i: usize, j: usize| Vec3A::from(verts[j * n + i]);
    let mut len = 0.0;
    for k in 0..n - 1 {
        len += (at(k + 1, m) - at(k, m)).length() + (at(m, k + 1) - at(m, k)).length();
    }
    len / (2 * (n - 1)) as f32
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[inline]
fn hash3(x: i32, y: i32, z: i32) -> u32 {
    let mut h = (x as u32).wrapping_mul(0x8da6_b343) ^ (y as u32).wrapping_mul(0xd816_3841) ^ (z as u32).wrapping_mul(0xcb1a_b31f);
    h ^= h >> 15;
    h = h.wrapping_mul(0x2c1b_3c6d);
    h ^= h >> 12;
    h = h.wrapping_mul(0x297a_2d39);
    h ^ (h >> 15)
}

#[inline]
fn grad(h: u32, d: Vec3A) -> f32 {
    // Twelve edge directions of a cube (Perlin's improved noise).
    match h % 12 {
        0 => d.x + d.y,
        1 => -d.x + d.y,
        2 => d.x - d.y,
        3 => -d.x - d.y,
        4 => d.x + d.z,
        5 => -d.x + d.z,
        6 => d.x - d.z,
        7 => -d.x - d.z,
        8 => d.y + d.z,
        9 => -d.y + d.z,
        10 => d.y - d.z,
        _ => -d.y - d.z,
    }
}

/// Perlin gradient noise, scaled to lie within [−1, 1].
pub fn gradient_noise(p: Vec3A) -> f32 {
    let c = p.floor();
    let f = p - c;
    let (x, y, z) = (c.x as i32, c.y as i32, c.z as i32);
    let fade = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (u, v, w) = (fade(f.x), fade(f.y), fade(f.z));
    let g = |i: i32, j: i32, k: i32| grad(hash3(x + i, y + j, z + k), f - Vec3A::new(i as f32, j as f32, k as f32));
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let x00 = lerp(g(0, 0, 0), g(1, 0, 0), u);
    let x10 = lerp(g(0, 1, 0), g(1, 1, 0), u);
    let x01 = lerp(g(0, 0, 1), g(1, 0, 1), u);
    let x11 = lerp(g(0, 1, 1), g(1, 1, 1), u);
    // Improved noise peaks near ±1.04; scale into [−1, 1] so `bound` is exact.
    (lerp(lerp(x00, x10, v), lerp(x01, x11, v), w) * 0.96).clamp(-1.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_bounded_continuous_and_varied() {
        let mut lo: f32 = 0.0;
        let mut hi: f32 = 0.0;
        for i in 0..20_000 {
            let p = Vec3A::new(i as f32 * 0.0137, (i % 97) as f32 * 0.31, (i % 13) as f32 * 0.77);
            let n = gradient_noise(p);
            lo = lo.min(n);
            hi = hi.max(n);
            let e = (gradient_noise(p + Vec3A::splat(1e-4)) - n).abs();
            assert!(e < 1e-2, "continuous: {e}");
        }
        assert!(lo >= -1.0 && hi <= 1.0 && lo < -0.5 && hi > 0.5, "{lo} {hi}");
    }

    #[test]
    fn offset_stays_within_bound_and_coarse_grids_see_fewer_octaves() {
        let d = Displacement { amplitude: 0.2, frequency: 2.0, octaves: 5, gain: 0.5 };
        assert!((d.bound() - 0.2 * 1.9375).abs() < 1e-6);
        let mut rough_fine = 0.0;
        let mut rough_coarse = 0.0;
        let h = 1e-3;
        for i in 0..2000 {
            let p = Vec3A::new(i as f32 * 0.011, 0.3, 0.7);
            let o = d.offset(p, 0.0);
            assert!(o.abs() <= d.bound());
            rough_fine += (d.offset(p + Vec3A::X * h, 0.0) - o).abs();
            rough_coarse += (d.offset(p + Vec3A::X * h, 0.1) - d.offset(p, 0.1)).abs();
        }
        // A 0.1-unit grid keeps octaves of wavelength ≥ 0.2 (frequency ≤ 5): the first two only.
        assert!(rough_coarse < 0.6 * rough_fine, "{rough_coarse} vs {rough_fine}");
        assert!(Displacement { octaves: 0, ..d }.validate().is_err());
        assert!(Displacement { gain: 1.5, ..d }.validate().is_err());
    }
}
