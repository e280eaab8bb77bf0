//! Materials: UsdPreviewSurface's inputs, constant or fed by textures; [`Material::resolve`]
//! reads them at a shading point (textures filtered over the ray's footprint, normal mapping),
//! and [`ResolvedSurface::bsdf`] makes the BSDF ([`crate::bsdf::PreviewSurfaceBsdf`]). An
//! input may also be fed by a small node network ([`network::InputNetwork`]: MaterialX nodes
//! the scene delegate could not fold into one affine lookup).

pub mod network;
pub mod noise;

use std::sync::Arc;

use glam::Vec3A;

use crate::bsdf::PreviewSurfaceBsdf;
use crate::differential::{RayDifferential, UvDifferentials};
use crate::hit::{Hit, ShadingPoint};
use crate::patch::LimitSurface;
use crate::texture::{Lookup, TextureHandle, TextureSampler};
pub use network::InputNetwork;

/// A colour input fed by a texture (UsdUVTexture → UsdPreviewSurface `diffuseColor`):
/// `texel.rgb · scale + bias`, looked up at the surface's `st` primvar channel with filter
/// widths from the ray differentials.
#[derive(Clone)]
pub struct TexturedColor {
    pub sampler: Arc<dyn TextureSampler>,
    pub texture: TextureHandle,
    /// The file, for messages.
    pub path: String,
    pub lookup: Lookup,
    pub scale: Vec3A,
    pub bias: Vec3A,
    /// UsdUVTexture `fallback`: the colour where a lookup fails or the surface has no `st`.
    pub fallback: Vec3A,
    /// The surface's 2-float primvar channel holding `st`.
    pub st_channel: usize,
}

impl std::fmt::Debug for TexturedColor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TexturedColor")
            .field("path", &self.path)
            .field("scale", &self.scale)
            .field("bias", &self.bias)
            .finish_non_exhaustive()
    }
}

impl PartialEq for TexturedColor {
    fn eq(&self, o: &Self) -> bool {
        Arc::ptr_eq(&self.sampler, &o.sampler)
            && self.texture == o.texture
            && self.lookup == o.lookup
            && self.scale == o.scale
            && self.bias == o.bias
            && self.fallback == o.fallback
            && self.st_channel == o.st_channel
    }
}

impl TexturedColor {
    /// The filtered colour at `st` over the footprint (ds/dx, dt/dx), (ds/dy, dt/dy), clamped
    /// into [0, 1] like any reflectance.
    pub fn eval(&self, st: Option<[f32; 2]>, dst_dx: [f32; 2], dst_dy: [f32; 2]) -> Vec3A {
        clamp_color(self.eval_raw(st, dst_dx, dst_dy, 3))
    }

    /// `texel · scale + bias`, unclamped (a normal map's components are negative, an `ior` or
    /// an emissive colour above 1), from `channels` channels: 3 for a colour, 1 for a float
    /// input, which is then splatted into all three lanes (`lookup.first_channel` says which
    /// channel of the file; `scale.x`, `bias.x` apply). The fallback where the lookup fails or
    /// there is no `st`.
    pub fn eval_raw(&self, st: Option<[f32; 2]>, dst_dx: [f32; 2], dst_dy: [f32; 2], channels: usize) -> Vec3A {
        let Some(st) = st else { return self.fallback };
        let mut rgb = [0.0f32; 3];
        let n = channels.clamp(1, 3);
        if !self.sampler.sample(self.texture, st, dst_dx, dst_dy, &self.lookup, &mut rgb[..n]) {
            return self.fallback;
        }
        let v = if n == 1 { Vec3A::splat(rgb[0]) } else { Vec3A::from(rgb) };
        let out = v * self.scale + self.bias;
        if n == 1 {
            Vec3A::splat(out.x)
        } else {
            out
        }
    }
}

pub use crate::bsdf::preview::{clamp_color, PreviewSurface};

/// Roughness under which a plain dielectric (metallic workflow, `metallic` 0) calls for glossy
/// rays: its 4 % reflection is a recognisable image of its surroundings only while the lobe is
/// narrow; rougher, it is a faint haze that direct light's highlights already show, not worth
/// `glossySamples` rays per hit. See [`SurfaceCalls::glossy`].
pub const GLOSSY_DIELECTRIC_MAX_ROUGHNESS: f32 = 0.4;

/// Which rays a surface's lobes call for (the effects analysis, DESIGN.md "Effects a scene
/// calls for", and the classic integrator per hit). "Maybe" counts as yes: an input fed by a
/// texture may take any value.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SurfaceCalls {
    /// A delta reflection: the specular lobe (metal, plastic or glass reflection) with
    /// `roughness` < [`crate::bsdf::preview::DELTA_ROUGHNESS`] and a non-zero Fresnel, or a
    /// clearcoat as smooth.
    pub reflection: bool,
    /// Transmission: `opacity` < 1, `opacityThreshold` 0, not entirely metal.
    pub refraction: bool,
    /// Significant rough specular: a rough (roughness ≥ the delta threshold) specular lobe on a
    /// metal (`metallic` > 0), a specular-workflow surface with `specularColor` > 0, or a
    /// dielectric smoother than [`GLOSSY_DIELECTRIC_MAX_ROUGHNESS`]; a rough clearcoat
    /// (`clearcoat` > 0); rough refraction (a transmitting surface, `ior` ≠ 1).
    pub glossy: bool,
    /// `emissiveColor` > 0.
    pub emission: bool,
}

impl PreviewSurface {
    /// The rays these inputs call for; `textured(input)`: a texture feeds it (any value).
    pub fn calls(&self, textured: &dyn Fn(Input) -> bool) -> SurfaceCalls {
        use crate::bsdf::preview::DELTA_ROUGHNESS;
        let s = self;
        let t = |i: Input| textured(i);
        let metallic_may_be = |pred: &dyn Fn(f32) -> bool| !s.use_specular_workflow && (pred(s.metallic) || t(Input::Metallic));
        let metal = metallic_may_be(&|m| m > 0.0) && (s.diffuse_color.max_element() > 0.0 || t(Input::DiffuseColor));
        // The dielectric part (plastic and glass) weighs 1 − metallic.
        let dielectric_weight = s.use_specular_workflow || s.metallic < 1.0 || t(Input::Metallic);
        let dielectric_fresnel = if s.use_specular_workflow {
            s.specular_color.max_element() > 0.0 || t(Input::SpecularColor)
        } else {
            (s.ior - 1.0).abs() >= 1e-3 || t(Input::Ior)
        };
        let dielectric = dielectric_weight && dielectric_fresnel;
        let smooth = s.roughness < DELTA_ROUGHNESS || t(Input::Roughness);
        let rough = s.roughness >= DELTA_ROUGHNESS || t(Input::Roughness);
        let coat = s.clearcoat > 0.0 || t(Input::Clearcoat);
        let coat_smooth = s.clearcoat_roughness < DELTA_ROUGHNESS || t(Input::ClearcoatRoughness);
        let coat_rough = s.clearcoat_roughness >= DELTA_ROUGHNESS || t(Input::ClearcoatRoughness);
        let transmits = (s.opacity < 1.0 || t(Input::Opacity)) && s.opacity_threshold <= 0.0 && dielectric_weight;
        let bends = (s.ior - 1.0).abs() >= 1e-3 || t(Input::Ior);
        let glossy_dielectric =
            dielectric && (s.use_specular_workflow || s.roughness < GLOSSY_DIELECTRIC_MAX_ROUGHNESS || t(Input::Roughness) || transmits);
        SurfaceCalls {
            reflection: (smooth && (metal || dielectric)) || (coat && coat_smooth),
            refraction: transmits,
            glossy: (rough && (metal || glossy_dielectric)) || (coat && coat_rough) || (transmits && rough && bends),
            emission: s.emissive_color.max_element() > 0.0 || t(Input::EmissiveColor),
        }
    }
}

/// A UsdPreviewSurface input that a texture can feed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Input {
    DiffuseColor,
    EmissiveColor,
    SpecularColor,
    Metallic,
    Roughness,
    Clearcoat,
    ClearcoatRoughness,
    Opacity,
    Ior,
    /// A tangent-space normal map (UsdPreviewSurface `normal`): the texel, after scale and bias,
    /// is the normal in the (dP/du, dP/dv, N) frame.
    Normal,
}

impl Input {
    /// UsdPreviewSurface's input name.
    pub const fn usd_name(self) -> &'static str {
        match self {
            Input::DiffuseColor => "diffuseColor",
            Input::EmissiveColor => "emissiveColor",
            Input::SpecularColor => "specularColor",
            Input::Metallic => "metallic",
            Input::Roughness => "roughness",
            Input::Clearcoat => "clearcoat",
            Input::ClearcoatRoughness => "clearcoatRoughness",
            Input::Opacity => "opacity",
            Input::Ior => "ior",
            Input::Normal => "normal",
        }
    }
}

/// A surface material: UsdPreviewSurface's constant inputs and the textures feeding some of
/// them. What rays it calls for is decided from these in [`crate::effects`].
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Prim path of the material (or of the mesh, for a display-color material).
    pub name: String,
    pub surface: PreviewSurface,
    /// Textured inputs, replacing the constant where a lookup succeeds. Float inputs read the
    /// texture's first channel (`lookup.first_channel`).
    pub textures: Vec<(Input, TexturedColor)>,
    /// Inputs fed by a primvar of the surface interpolated as authored (`displayColor`, a
    /// `UsdPrimvarReader_*`); an input is fed by one node, a texture or a primvar. Channel
    /// numbers are the surface's, so a material with these belongs to one mesh.
    pub primvars: Vec<(Input, PrimvarInput)>,
    /// Inputs fed by a node network (evaluated after the textures and primvars, so a network
    /// wins where both feed one input; the scene delegate sends one or the other).
    pub networks: Vec<(Input, InputNetwork)>,
}

/// A UsdPreviewSurface input read from the surface's 2-float primvar channels
/// ([`LimitSurface::face_varying`]): a colour is (channel 0's two values, channel 1's first),
/// a float channel 0's first. Face-varying and vertex interpolation is linear in each
/// component, so three components split over two channels interpolate exactly as one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PrimvarInput {
    pub channels: [usize; 2],
}

impl PrimvarInput {
    /// The primvar's value at the hit as three lanes (a float's splatted), or `None` when the
    /// surface has no such channel.
    pub fn eval(&self, surface: &dyn LimitSurface, hit: &Hit, components: usize) -> Option<Vec3A> {
        let (a, _, _) = surface.face_varying(self.channels[0], hit.patch as usize, hit.u, hit.v)?;
        if components == 1 {
            return Some(Vec3A::splat(a[0]));
        }
        let (b, _, _) = surface.face_varying(self.channels[1], hit.patch as usize, hit.u, hit.v)?;
        Some(Vec3A::new(a[0], a[1], b[0]))
    }
}

impl Default for Material {
    /// A lambertian material of UsdPreviewSurface's fallback diffuseColor (0.18, 0.18, 0.18) and
    /// no specular: what an unbound mesh renders with.
    fn default() -> Self {
        Material::lambertian("default", Vec3A::splat(0.18)).0
    }
}

impl Material {
    /// A lambertian material (specular workflow with zero specular colour). Out-of-range or
    /// non-finite colors are clamped to [0, 1]; the returned flag says whether anything was
    /// clamped, so the caller can warn once.
    pub fn lambertian(name: impl Into<String>, diffuse_color: Vec3A) -> (Self, bool) {
        let c = clamp_color(diffuse_color);
        let clamped = c != diffuse_color;
        let surface =
            PreviewSurface { diffuse_color: c, use_specular_workflow: true, specular_color: Vec3A::ZERO, ..PreviewSurface::default() };
        (Material { name: name.into(), surface, textures: Vec::new(), primvars: Vec::new(), networks: Vec::new() }, clamped)
    }

    /// A smooth specular-workflow surface: diffuse `diffuse_color` under a delta mirror of
    /// normal-incidence reflectance `mirror` (roughness 0). Both clamped into [0, 1].
    pub fn mirror(name: impl Into<String>, diffuse_color: Vec3A, mirror: Vec3A) -> Self {
        let surface = PreviewSurface {
            diffuse_color: clamp_color(diffuse_color),
            use_specular_workflow: true,
            specular_color: clamp_color(mirror),
            roughness: 0.0,
            ..PreviewSurface::default()
        };
        Material { name: name.into(), surface, textures: Vec::new(), primvars: Vec::new(), networks: Vec::new() }
    }

    /// A UsdPreviewSurface material, its inputs clamped into range; the names of the inputs that
    /// were out of range (warn once, naming the material).
    pub fn preview_surface(name: impl Into<String>, surface: PreviewSurface) -> (Self, Vec<&'static str>) {
        let (surface, changed) = surface.clamped();
        (Material { name: name.into(), surface, textures: Vec::new(), primvars: Vec::new(), networks: Vec::new() }, changed)
    }

    /// The texture feeding `input`, if any.
    pub fn texture(&self, input: Input) -> Option<&TexturedColor> {
        self.textures.iter().find(|(i, _)| *i == input).map(|(_, t)| t)
    }

    /// Whether a texture, a primvar or a network feeds `input`: its value varies over the
    /// surface.
    pub fn varies(&self, input: Input) -> bool {
        self.texture(input).is_some() || self.primvars.iter().any(|(i, _)| *i == input) || self.networks.iter().any(|(i, _)| *i == input)
    }

    /// The rays this material may call for anywhere on a surface (textured inputs may take any
    /// value): [`PreviewSurface::calls`].
    pub fn calls(&self) -> SurfaceCalls {
        self.surface.calls(&|i| self.varies(i))
    }

    /// `opacityThreshold` may cut this material out somewhere: a threshold above 0 and either a
    /// constant opacity below it or a texture feeding opacity. False: every hit on it is a
    /// surface, and visibility rays need not look closer.
    pub fn may_cut_out(&self) -> bool {
        let s = &self.surface;
        s.opacity_threshold > 0.0 && (s.opacity < s.opacity_threshold || self.varies(Input::Opacity))
    }

    /// Whether the material is cut out at a hit: [`ResolvedSurface::cut_out`] of
    /// [`Material::resolve`] with the same arguments, reading only the opacity texture (what a
    /// visibility ray needs).
    pub fn cut_out_at(&self, surface: &dyn LimitSurface, hit: &Hit, sp: &ShadingPoint, footprint: &RayDifferential) -> bool {
        if !self.may_cut_out() {
            return false;
        }
        let mut opacity = self.surface.opacity;
        // The last texture feeding opacity wins, as in `resolve`.
        if let Some((_, tex)) = self.textures.iter().rev().find(|(i, _)| *i == Input::Opacity) {
            let uv = UvDifferentials::from_footprint(footprint.dpdx, footprint.dpdy, sp.dpdu, sp.dpdv);
            let mut site = TextureSite { surface, hit, uv, cache: Vec::new() };
            opacity = unit_input(site.lookup(tex, 1).x);
        }
        if let Some(v) = self.primvars.iter().rev().find(|(i, _)| *i == Input::Opacity).and_then(|(_, p)| p.eval(surface, hit, 1)) {
            opacity = unit_input(v.x);
        }
        if let Some((_, net)) = self.networks.iter().rev().find(|(i, _)| *i == Input::Opacity) {
            let uv = UvDifferentials::from_footprint(footprint.dpdx, footprint.dpdy, sp.dpdu, sp.dpdv);
            let mut site = TextureSite { surface, hit, uv, cache: Vec::new() };
            let read = |c: usize| surface.face_varying(c, hit.patch as usize, hit.u, hit.v).map(|(v, _, _)| v);
            opacity = unit_input(net.eval_at(site.st(net.st_channel).map(|v| [v[0], v[1], v[2]]), &read, &network_geometry(sp)).x);
        }
        opacity < self.surface.opacity_threshold
    }
}

/// UsdPreviewSurface's inputs at one shading point, and the shading normal there: what
/// [`Material::resolve`] returns.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResolvedSurface {
    /// The inputs, each the texture's value where one feeds it (clamped into the input's range)
    /// or the constant.
    pub inputs: PreviewSurface,
    /// Shading normal after normal mapping: world space, unit, facing the viewer and in the
    /// geometric normal's hemisphere.
    pub ns: Vec3A,
}

impl ResolvedSurface {
    /// `opacityThreshold` > 0 makes opacity a cutout mask: where opacity is below the threshold
    /// there is no surface, and rays continue through (UsdPreviewSurface; Storm discards the
    /// fragment).
    pub fn cut_out(&self) -> bool {
        self.inputs.opacity_threshold > 0.0 && self.inputs.opacity < self.inputs.opacity_threshold
    }

    /// The BSDF at shading point `sp` (whose geometric normal and side it takes; the shading
    /// normal is [`ResolvedSurface::ns`]).
    pub fn bsdf(&self, sp: &ShadingPoint) -> PreviewSurfaceBsdf {
        PreviewSurfaceBsdf::new(&self.inputs, self.ns, sp.ng, sp.front)
    }
}

/// Filter widths for lookups at one hit: `st` of each primvar channel and its derivatives per
/// pixel, computed once per channel however many textures read it.
struct TextureSite<'a> {
    surface: &'a dyn LimitSurface,
    hit: &'a Hit,
    uv: UvDifferentials,
    /// (channel, st, d(st)/dx, d(st)/dy, d(st)/du, d(st)/dv) of the channels looked up so far.
    cache: Vec<(usize, Option<[[f32; 2]; 5]>)>,
}

impl TextureSite<'_> {
    /// `st` at the hit, (ds/dx, dt/dx), (ds/dy, dt/dy) from the footprint by the chain rule
    /// through the surface's d(st)/du, d(st)/dv (the paper's §2.6 and §6.3.3: wide rays read
    /// coarse MIP levels), and d(st)/du, d(st)/dv themselves.
    fn st(&mut self, channel: usize) -> Option<[[f32; 2]; 5]> {
        if let Some((_, v)) = self.cache.iter().find(|(c, _)| *c == channel) {
            return *v;
        }
        let v = self.surface.face_varying(channel, self.hit.patch as usize, self.hit.u, self.hit.v).map(|(st, du, dv)| {
            let uv = &self.uv;
            let dx = [du[0] * uv.dudx + dv[0] * uv.dvdx, du[1] * uv.dudx + dv[1] * uv.dvdx];
            let dy = [du[0] * uv.dudy + dv[0] * uv.dvdy, du[1] * uv.dudy + dv[1] * uv.dvdy];
            [st, dx, dy, du, dv]
        });
        self.cache.push((channel, v));
        v
    }

    /// The texture's value, unclamped, from `channels` channels.
    fn lookup(&mut self, tex: &TexturedColor, channels: usize) -> Vec3A {
        match self.st(tex.st_channel) {
            Some([st, dx, dy, _, _]) => tex.eval_raw(Some(st), dx, dy, channels),
            None => tex.eval_raw(None, [0.0; 2], [0.0; 2], channels),
        }
    }
}

impl Material {
    /// The inputs at a hit: every textured input looked up with filter widths from the ray
    /// differential (`footprint`: the ray's differential transferred to the hit), exactly as
    /// the diffuse colour always was; float inputs read one channel. Out-of-range texture
    /// values are clamped into the input's range (colours [0, 1], emission ≥ 0, `ior` > 0) —
    /// silently: the material's constants were checked once when it was made.
    ///
    /// **Normal mapping** (`normal`): the texel after scale and bias (UsdUVTexture's usual
    /// `scale = 2, bias = −1`) is a tangent-space normal in the frame (T, B, N) where N is the
    /// surface's outward shading normal, T the direction of increasing `s` on the surface
    /// (dP/ds, made perpendicular to N) and B = N × T, flipped if `t` increases the other way:
    /// the frame Storm's `previewSurface.glslfx` builds from screen-space derivatives of `P` and
    /// `st`. On a mesh whose `st` is its (u, v) that is the (dP/du, dP/dv, N) frame; without
    /// `st` the (dP/du, dP/dv, N) frame is used. The mapped normal is kept in the geometric
    /// normal's hemisphere (tilted back to just above it), so no shading normal faces away.
    pub fn resolve(&self, surface: &dyn LimitSurface, hit: &Hit, sp: &ShadingPoint, footprint: &RayDifferential) -> ResolvedSurface {
        let mut inputs = self.surface;
        let mut ns = sp.ns;
        for (input, pv) in &self.primvars {
            let components = if matches!(input, Input::DiffuseColor | Input::SpecularColor | Input::EmissiveColor) { 3 } else { 1 };
            if let Some(v) = pv.eval(surface, hit, components) {
                set_varying_input(&mut inputs, *input, v, self.surface.ior);
            }
        }
        if self.textures.is_empty() && self.networks.is_empty() {
            return ResolvedSurface { inputs, ns };
        }
        let uv = UvDifferentials::from_footprint(footprint.dpdx, footprint.dpdy, sp.dpdu, sp.dpdv);
        let mut site = TextureSite { surface, hit, uv, cache: Vec::new() };
        let unit = unit_input;
        for (input, tex) in &self.textures {
            match input {
                Input::DiffuseColor => inputs.diffuse_color = clamp_color(site.lookup(tex, 3)),
                Input::SpecularColor => inputs.specular_color = clamp_color(site.lookup(tex, 3)),
                Input::EmissiveColor => {
                    let e = site.lookup(tex, 3);
                    inputs.emissive_color = Vec3A::select(e.is_nan_mask(), Vec3A::ZERO, e).clamp(Vec3A::ZERO, Vec3A::splat(f32::MAX));
                }
                Input::Metallic => inputs.metallic = unit(site.lookup(tex, 1).x),
                Input::Roughness => inputs.roughness = unit(site.lookup(tex, 1).x),
                Input::Clearcoat => inputs.clearcoat = unit(site.lookup(tex, 1).x),
                Input::ClearcoatRoughness => inputs.clearcoat_roughness = unit(site.lookup(tex, 1).x),
                Input::Opacity => inputs.opacity = unit(site.lookup(tex, 1).x),
                Input::Ior => {
                    let v = site.lookup(tex, 1).x;
                    // ior ≤ 0 has no meaning: the constant's own value is the nearest sane one.
                    inputs.ior = if v.is_finite() && v > 0.0 { v } else { self.surface.ior };
                }
                Input::Normal => {
                    let t = site.lookup(tex, 3);
                    let st = site.st(tex.st_channel);
                    ns = normal_mapped(sp, t, st.map(|v| (v[3], v[4])));
                }
            }
        }
        let geom = network_geometry(sp);
        for (input, net) in &self.networks {
            let st = site.st(net.st_channel);
            let read = |c: usize| surface.face_varying(c, hit.patch as usize, hit.u, hit.v).map(|(v, _, _)| v);
            let v = net.eval_at(st.map(|v| [v[0], v[1], v[2]]), &read, &geom);
            match input {
                // MaterialX's normalmap works in the frame of the surface's own texcoord (its
                // `tangent` input defaults to Tworld), whatever place2d does to the lookup's.
                Input::Normal => ns = normal_mapped(sp, v.truncate().into(), st.map(|v| (v[3], v[4]))),
                Input::EmissiveColor => {
                    let e = Vec3A::from(v.truncate());
                    inputs.emissive_color = Vec3A::select(e.is_nan_mask(), Vec3A::ZERO, e).clamp(Vec3A::ZERO, Vec3A::splat(f32::MAX));
                }
                _ => set_varying_input(&mut inputs, *input, v.truncate().into(), self.surface.ior),
            }
        }
        ResolvedSurface { inputs, ns }
    }
}

/// Where a network reads `position` and `normal` at `sp` (before any normal mapping): world
/// space is render space, the normal the outward one (`sp.ns` faces the viewer).
fn network_geometry(sp: &ShadingPoint) -> network::NetworkGeometry {
    let n_world = if sp.front { sp.ns } else { -sp.ns };
    network::NetworkGeometry { p_object: sp.p_object, p_world: sp.p, n_object: sp.n_object, n_world }
}

/// The shading normal for tangent-space normal `t` at `sp` (see [`Material::resolve`]);
/// `dst`: (d(st)/du, d(st)/dv) when the surface has `st`.
fn normal_mapped(sp: &ShadingPoint, t: Vec3A, dst: Option<([f32; 2], [f32; 2])>) -> Vec3A {
    let Some(t) = t.try_normalize() else { return sp.ns };
    // The outward normal: sp.ns faces the viewer, who may be inside.
    let n_out = if sp.front { sp.ns } else { -sp.ns };
    let (mut dps, mut dpt) = (sp.dpdu, sp.dpdv);
    if let Some((du, dv)) = dst {
        // [dP/du dP/dv] = [dP/ds dP/dt] · J with J = ∂(s, t)/∂(u, v): invert J.
        let det = du[0] * dv[1] - dv[0] * du[1];
        if det.abs() > 1e-12 && det.is_finite() {
            dps = (sp.dpdu * dv[1] - sp.dpdv * du[1]) / det;
            dpt = (sp.dpdv * du[0] - sp.dpdu * dv[0]) / det;
        }
    }
    let Some(tan) = (dps - n_out * n_out.dot(dps)).try_normalize() else { return sp.ns };
    let mut bit = n_out.cross(tan);
    if bit.dot(dpt) < 0.0 {
        bit = -bit;
    }
    let Some(n) = (tan * t.x + bit * t.y + n_out * t.z).try_normalize() else { return sp.ns };
    let n = if sp.front { n } else { -n };
    // Keep it in the geometric normal's hemisphere, just above the horizon at worst.
    let c = n.dot(sp.ng);
    const MIN_COS: f32 = 0.01;
    if c >= MIN_COS {
        n
    } else {
        (n + sp.ng * (MIN_COS - c)).try_normalize().unwrap_or(sp.ng)
    }
}

/// Sets `input` to a primvar's value `v` (three lanes; floats read `x`), clamped into the
/// input's range as a texture's value is; `ior` ≤ 0 keeps the constant `ior`.
fn set_varying_input(inputs: &mut PreviewSurface, input: Input, v: Vec3A, ior: f32) {
    match input {
        Input::DiffuseColor => inputs.diffuse_color = clamp_color(v),
        Input::SpecularColor => inputs.specular_color = clamp_color(v),
        Input::EmissiveColor => inputs.emissive_color = Vec3A::select(v.is_nan_mask(), Vec3A::ZERO, v).max(Vec3A::ZERO),
        Input::Metallic => inputs.metallic = unit_input(v.x),
        Input::Roughness => inputs.roughness = unit_input(v.x),
        Input::Clearcoat => inputs.clearcoat = unit_input(v.x),
        Input::ClearcoatRoughness => inputs.clearcoat_roughness = unit_input(v.x),
        Input::Opacity => inputs.opacity = unit_input(v.x),
        Input::Ior => inputs.ior = if v.x.is_finite() && v.x > 0.0 { v.x } else { ior },
        // A primvar is not a tangent-space normal map.
        Input::Normal => {}
    }
}

/// A float input's texture value in its range [0, 1] (NaN to 0).
fn unit_input(v: f32) -> f32 {
    if v.is_nan() {
        0.0
    } else {
        v.clamp(0.0, 1.0)
    }
}
