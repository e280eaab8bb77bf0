//! The mesh Rprim: a USD mesh's data as the scene delegate gives it, and its synced state —
//! the limit surface (OpenSubdiv for subdivision schemes, bilinear patches for `none`, the
//! core's exact surfaces for implicit gprims and points, the core's curves for BasisCurves, its
//! rational Bézier patches for NurbsPatch).

use std::sync::Arc;

use glam::Mat4;
use mipray::bilinear::BilinearSurface;
use mipray::curves::{Basis, CurveType, CurvesDesc, CurvesSurface, Interpolation, Style, Wrap};
use mipray::implicit::{ImplicitSurface, PointsSurface, Shape};
use mipray::lazy_surface::LazySurface;
use mipray::nurbs::{NurbsDesc, NurbsSurface};
use mipray::patch::LimitSurface;
use mipray::topology::{MeshTopology, Scheme};
use mipray::trim::{TrimDesc, TrimRegion};
use mipray_bridge::OsdSurface;

use crate::dirty_bits::DirtyBits;
use crate::error::DelegateError;
use crate::material::{FaceMaterials, SurfaceInputs, TextureInput};
use mipray::material::{Input, PrimvarInput};
use mipray::texture::Primvar2;

/// What the scene delegate knows about a mesh. Object space; `transform` is object-to-world
/// (column-vector convention).
#[derive(Clone, Debug, PartialEq)]
pub struct MeshData {
    pub topology: MeshTopology,
    pub points: Vec<[f32; 3]>,
    pub transform: Mat4,
    pub double_sided: bool,
    /// The mesh's UsdPreviewSurface: the bound material's inputs, or for a mesh without one
    /// its display colour as a lambertian surface ([`SurfaceInputs::lambertian`]); `None`
    /// renders UsdPreviewSurface's 0.18 grey, lambertian.
    pub material: Option<SurfaceInputs>,
    /// Object units; `None` uses the procedural displacement's own bound, else the render
    /// setting.
    pub displacement_bound: Option<f32>,
    /// Built-in procedural displacement (`mipray:displacement:*` attributes).
    pub displacement: Option<mipray::displacement::Displacement>,
    /// A prototype of instancers: rendered only where an instancer places it, and `transform`
    /// is then relative to the prototype's root (see [`crate::instancer`]).
    pub prototype: bool,
    /// Materials of their own on some faces (GeomSubsets bound to UsdPreviewSurfaces, textures
    /// included; per-face display colours as lambertian surfaces), over `material`.
    pub face_materials: Option<FaceMaterials>,
    /// The `st` primvar the textures read (face-varying through OpenSubdiv).
    pub st: Option<Primvar2>,
    /// Authored normals of a polygonal mesh (`normals`, `primvars:normals`), as the two
    /// 2-float channels of [`Primvar2::split`]; used for shading.
    pub normals: Vec<Primvar2>,
    /// UsdPreviewSurface inputs fed by a primvar interpolated as authored (`displayColor` on a
    /// mesh without a material, a `UsdPrimvarReader_*`): each primvar as the channels of
    /// [`Primvar2::split`] (one for a float, two for a colour).
    pub primvar_inputs: Vec<(Input, Vec<Primvar2>)>,
    /// Primvars node networks read by name (MaterialX `geompropvalue` of a primvar varying
    /// over the mesh), each as the channels of [`Primvar2::split`] (one or two).
    pub network_primvars: Vec<(String, Vec<Primvar2>)>,
    /// `displacement` from a texture (replaces the procedural displacement).
    pub displacement_texture: Option<TextureInput>,
    /// Set for gprims other than meshes, which are intersected exactly: their shape replaces
    /// `topology` (and, for an implicit gprim, `points`).
    pub gprim: Option<Gprim>,
    /// UsdLux `MeshLightAPI` (or a `GeometryLight` naming this prim): the surface is then a
    /// light and not geometry ([`crate::light::mesh_light`]).
    pub light: Option<crate::light::MeshLightData>,
}

/// Where each primvar sits among a surface's 2-float channels ([`MeshData::channels`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Channels {
    /// The channel textures read `st` from; `usize::MAX` (no channel) without `st`.
    pub st: usize,
    pub normals: Option<[usize; 2]>,
    pub inputs: Vec<(Input, PrimvarInput)>,
    /// [`MeshData::network_primvars`]' channels, by name.
    pub named: Vec<(String, [usize; 2])>,
}

impl Channels {
    /// Sets each network primvar's channels: the mesh's primvar of that name, else none (the
    /// primvar's fallback is read).
    pub fn place(&self, primvars: &mut [mipray::material::network::NetworkPrimvar]) {
        for p in primvars {
            p.channels = self.named.iter().find(|(n, _)| *n == p.name).map(|(_, c)| *c);
        }
    }
}

impl MeshData {
    /// The surface's primvar channels in order: `st` first (channel 0), then the normals, then
    /// the primvar-fed inputs' ([`MeshData::channels`] says where each is).
    pub fn primvar_list(&self) -> Vec<Primvar2> {
        let mut list: Vec<Primvar2> = self.st.iter().cloned().collect();
        if self.normals.len() == 2 {
            list.extend(self.normals.iter().cloned());
        }
        for (_, parts) in &self.primvar_inputs {
            list.extend(parts.iter().take(2).cloned());
        }
        for (_, parts) in &self.network_primvars {
            list.extend(parts.iter().take(2).cloned());
        }
        list
    }

    /// Where each primvar is among [`MeshData::primvar_list`]'s channels.
    pub fn channels(&self) -> Channels {
        let mut next = 0;
        let mut channels = Channels { st: usize::MAX, ..Channels::default() };
        if self.st.is_some() {
            channels.st = 0;
            next = 1;
        }
        if self.normals.len() == 2 {
            channels.normals = Some([next, next + 1]);
            next += 2;
        }
        for (input, parts) in &self.primvar_inputs {
            let n = parts.len().min(2);
            if n == 0 {
                continue;
            }
            channels.inputs.push((*input, PrimvarInput { channels: [next, next + n - 1] }));
            next += n;
        }
        for (name, parts) in &self.network_primvars {
            let n = parts.len().min(2);
            if n == 0 {
                continue;
            }
            channels.named.push((name.clone(), [next, next + n - 1]));
            next += n;
        }
        channels
    }

    /// Every check of a mesh's data, once (the delegate's [`crate::RenderDelegate::set_mesh`]
    /// makes it): finite points, the topology ([`MeshTopology::validate`]), the face table,
    /// the primvars against the topology, a finite transform, the displacement and its bound,
    /// a Points gprim's widths. A mesh that passes builds, or fails only where OpenSubdiv or a
    /// gprim's own constructor refuses it.
    ///
    /// # Errors
    /// The first problem, one line naming the USD attribute (without the prim's path).
    pub fn validate(&self) -> Result<(), String> {
        if let Some(i) = self.points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            let [x, y, z] = self.points[i].map(py_float);
            return Err(format!("points[{i}] = ({x}, {y}, {z}) is not finite"));
        }
        let reason = |e: mipray::error::MeshError| match e {
            mipray::error::MeshError::Invalid(m) => m,
            e => e.to_string(),
        };
        self.topology.validate(self.points.len()).map_err(reason)?;
        if self.topology.scheme == Scheme::Loop {
            // OpenSubdiv's guard in the bridge refuses this too, but only when the surface is
            // built: here the mesh is refused when it is set.
            if let Some((f, n)) = self.topology.face_vertex_counts.iter().enumerate().find(|(_, &n)| n != 3) {
                return Err(format!("subdivisionScheme loop needs triangles, but face {f} has {n} vertices"));
            }
        }
        if let Some(table) = &self.face_materials {
            table.validate(self.face_count())?;
        }
        let channels = self
            .st
            .iter()
            .chain(&self.normals)
            .chain(self.primvar_inputs.iter().flat_map(|(_, c)| c))
            .chain(self.network_primvars.iter().flat_map(|(_, c)| c));
        for c in channels {
            c.face_varying_indices(&self.topology, self.points.len()).map_err(|e| e.to_string())?;
        }
        if !self.transform.is_finite() {
            return Err("transform is not finite".into());
        }
        if let Some(d) = &self.displacement {
            d.validate()?;
        }
        if let Some(b) = self.displacement_bound.filter(|b| !(b.is_finite() && *b >= 0.0)) {
            return Err(format!("primvars:displacementBound = {b} must be a non-negative number"));
        }
        if let Some(Gprim::Points { widths }) = &self.gprim {
            PointsSurface::check(&self.points, widths)?;
        }
        if let Some(Gprim::Curves(c)) = &self.gprim {
            CurvesSurface::new(&c.desc(&self.points))?;
        }
        if let Some(Gprim::Nurbs(n)) = &self.gprim {
            NurbsSurface::check(&n.desc(&self.points))?;
            if let Some(t) = &n.trim {
                t.desc().check()?;
            }
        }
        Ok(())
    }

    /// The faces [`MeshData::face_materials`] indexes: the topology's, or for Points one per
    /// point (each point's sphere is a patch of its own base face).
    pub fn face_count(&self) -> usize {
        match self.gprim {
            Some(Gprim::Points { .. }) => self.points.len(),
            // Each curve is a face: uniform displayColor colours it.
            Some(Gprim::Curves(ref c)) => c.counts.len(),
            // The front end sends NURBS no face table (a NurbsPatch has one colour).
            Some(Gprim::Nurbs(_)) => 1,
            _ => self.topology.face_vertex_counts.len(),
        }
    }
}

/// A gprim that is not a polygon or subdivision mesh (see [`mipray::implicit`]).
#[derive(Clone, Debug, PartialEq)]
pub enum Gprim {
    /// `Sphere`, `Cube`, `Cylinder`, `Cone`, `Capsule`, `Plane` and the `_1` forms.
    Implicit(Shape),
    /// `Points`: spheres at [`MeshData::points`] of diameters `widths` (one for all, one per
    /// point, or none for USD's default width 1).
    Points { widths: Vec<f32> },
    /// `BasisCurves` (and `NurbsCurves`, converted to Bézier segments in Python): vertices
    /// in [`MeshData::points`].
    Curves(CurvesSpec),
    /// `NurbsPatch`: control points in [`MeshData::points`] (u fastest).
    Nurbs(NurbsSpec),
}

/// A NurbsPatch prim's attributes besides its points (see [`mipray::nurbs`]).
#[derive(Clone, Debug, PartialEq)]
pub struct NurbsSpec {
    pub u_count: usize,
    pub v_count: usize,
    pub u_order: usize,
    pub v_order: usize,
    pub u_knots: Vec<f64>,
    pub v_knots: Vec<f64>,
    /// `uRange` / `vRange`; `None` for the knots' whole domain.
    pub u_range: Option<[f64; 2]>,
    pub v_range: Option<[f64; 2]>,
    /// `pointWeights`; empty for a polynomial surface.
    pub weights: Vec<f64>,
    /// `trimCurve:*`; `None` for an untrimmed patch (boxed: most patches have none).
    pub trim: Option<Box<TrimSpec>>,
}

/// A NurbsPatch's `trimCurve:*` attributes (see [`mipray::trim`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TrimSpec {
    pub counts: Vec<i64>,
    pub orders: Vec<i64>,
    pub vertex_counts: Vec<i64>,
    pub knots: Vec<f64>,
    /// Empty for each curve's whole domain.
    pub ranges: Vec<[f64; 2]>,
    /// Homogeneous `(u w, v w, w)`.
    pub points: Vec<[f64; 3]>,
}

impl TrimSpec {
    /// The core's description of these trim curves.
    pub fn desc(&self) -> TrimDesc<'_> {
        TrimDesc {
            counts: &self.counts,
            orders: &self.orders,
            vertex_counts: &self.vertex_counts,
            knots: &self.knots,
            ranges: &self.ranges,
            points: &self.points,
        }
    }
}

impl NurbsSpec {
    /// The core's description of this patch over `points`.
    pub fn desc<'a>(&'a self, points: &'a [[f32; 3]]) -> NurbsDesc<'a> {
        NurbsDesc {
            points,
            weights: &self.weights,
            u_count: self.u_count,
            v_count: self.v_count,
            u_order: self.u_order,
            v_order: self.v_order,
            u_knots: &self.u_knots,
            v_knots: &self.v_knots,
            u_range: self.u_range,
            v_range: self.v_range,
        }
    }
}

/// A BasisCurves prim's attributes besides its points (see [`mipray::curves`]).
#[derive(Clone, Debug, PartialEq)]
pub struct CurvesSpec {
    pub counts: Vec<i32>,
    pub curve_type: CurveType,
    pub basis: Basis,
    pub wrap: Wrap,
    /// Diameters; empty for USD's fallback width 1.
    pub widths: Vec<f32>,
    pub widths_interpolation: Interpolation,
    /// Ribbon orientation; empty for none.
    pub normals: Vec<[f32; 3]>,
    pub normals_interpolation: Interpolation,
    pub style: Style,
}

impl CurvesSpec {
    /// The core's description of these curves over `points`.
    pub fn desc<'a>(&'a self, points: &'a [[f32; 3]]) -> CurvesDesc<'a> {
        CurvesDesc {
            points,
            counts: &self.counts,
            curve_type: self.curve_type,
            basis: self.basis,
            wrap: self.wrap,
            widths: &self.widths,
            widths_interpolation: self.widths_interpolation,
            normals: &self.normals,
            normals_interpolation: self.normals_interpolation,
            style: self.style,
        }
    }
}

impl Default for MeshData {
    /// No faces, identity transform, UsdPreviewSurface's 0.18 grey.
    fn default() -> Self {
        MeshData {
            topology: MeshTopology::default(),
            points: Vec::new(),
            transform: Mat4::IDENTITY,
            double_sided: false,
            material: None,
            displacement_bound: None,
            displacement: None,
            prototype: false,
            face_materials: None,
            st: None,
            normals: Vec::new(),
            primvar_inputs: Vec::new(),
            network_primvars: Vec::new(),
            displacement_texture: None,
            gprim: None,
            light: None,
        }
    }
}

/// The synced surface, kept by kind so new points can update an OpenSubdiv surface in place.
#[derive(Clone)]
pub enum Surface {
    Osd(Arc<OsdSurface>),
    /// An OpenSubdiv surface built when a ray first reaches the mesh (the default).
    LazyOsd(Arc<LazySurface<OsdSurface>>),
    Bilinear(Arc<BilinearSurface>),
    Implicit(Arc<ImplicitSurface>),
    Points(Arc<PointsSurface>),
    Curves(Arc<CurvesSurface>),
    Nurbs(Arc<NurbsSurface>),
    /// A mesh whose points move within the shutter ([`mipray::deform`]): one surface per time
    /// sample, over OpenSubdiv (built on first use, unless the prim is eager) or bilinear faces.
    Deforming(Arc<dyn LimitSurface>),
}

impl Surface {
    pub fn as_limit_surface(&self) -> Arc<dyn LimitSurface> {
        match self {
            Surface::Osd(s) => s.clone(),
            Surface::LazyOsd(s) => s.clone(),
            Surface::Bilinear(s) => s.clone(),
            Surface::Implicit(s) => s.clone(),
            Surface::Points(s) => s.clone(),
            Surface::Curves(s) => s.clone(),
            Surface::Nurbs(s) => s.clone(),
            Surface::Deforming(s) => s.clone(),
        }
    }
}

/// A mesh prim in the delegate.
pub struct MeshPrim {
    pub path: String,
    pub data: MeshData,
    pub surface: Option<Surface>,
    pub dirty: DirtyBits,
    /// Times this prim's surface was (re)built or updated: tests count these.
    pub surface_syncs: u64,
    /// Bumped whenever the surface changes, so the geometry cache never serves old entries.
    pub generation: u32,
    /// The last sync's error, if the prim could not be built.
    pub error: Option<String>,
    /// Why the data last set is unusable ([`MeshData::validate`], made by `set_mesh`); such a
    /// prim is not built, and each render reports it.
    pub invalid: Option<String>,
    /// The mesh's key in the delegate's geometry cache, fixed for the prim's life.
    pub cache_id: u32,
    /// Its world transform over the camera's shutter, when it moves within it (set by
    /// [`crate::render_delegate::Delegate::set_motion`]); replaces `data.transform` for renders.
    pub motion: Option<std::sync::Arc<mipray::motion::MotionTransform>>,
    /// Build an OpenSubdiv surface when a ray first reaches it rather than at sync (the
    /// default): a mesh no ray reaches then costs its bounds, not its patch table.
    pub lazy: bool,
    /// Its points at times across the camera's shutter, when they move within it (set by
    /// [`crate::render_delegate::Delegate::set_deformation`]): the surface is then built at
    /// each sample ([`mipray::deform`]) and `data.points` stands for nothing but the bounds.
    pub deformation: Option<Arc<DeformSamples>>,
    /// A Points or curves prim's widths at the times of `deformation`, one list per sample,
    /// when they change within the shutter; `None` for the data's widths at every sample.
    pub deformation_widths: Option<Arc<Vec<Vec<f32>>>>,
    /// An implicit prim's shape at the times of `deformation`, one per sample, when its sizes
    /// change within the shutter.
    pub deformation_shapes: Option<Arc<Vec<Shape>>>,
}

/// A mesh's points at shutter times (0 = open, 1 = close), strictly increasing.
pub type DeformSamples = Vec<(f32, Vec<[f32; 3]>)>;

/// Why `samples` cannot deform a mesh of `points` points, if they cannot: one line.
pub fn check_deformation(samples: &DeformSamples, points: usize) -> Result<(), String> {
    let max = mipray::deform::MAX_SAMPLES;
    if !(2..=max).contains(&samples.len()) {
        return Err(format!("{} deformation samples (2 to {max} are traced)", samples.len()));
    }
    if samples.iter().any(|s| !s.0.is_finite()) || samples.windows(2).any(|w| !(w[0].0 < w[1].0)) {
        return Err("deformation sample times are not finite and strictly increasing".into());
    }
    for (t, p) in samples {
        if p.len() != points {
            return Err(format!("the points at shutter time {t} are {} (the mesh has {points})", p.len()));
        }
        if let Some(i) = p.iter().position(|q| !q.iter().all(|c| c.is_finite())) {
            return Err(format!("points[{i}] at shutter time {t} is not finite"));
        }
    }
    Ok(())
}

/// Why `widths` (one list per sample of `samples`, or none) cannot be the widths over the
/// shutter of the prim of `data`, if they cannot: one line. Only Points and curves have
/// widths; a Points sample's widths are checked against its points
/// ([`PointsSurface::check`]), a curves sample's must have as many values as the prim's own
/// (so they keep their interpolation).
pub fn check_deformation_widths(widths: &[Vec<f32>], samples: &DeformSamples, data: &MeshData) -> Result<(), String> {
    if widths.is_empty() {
        return Ok(());
    }
    if widths.len() != samples.len() {
        return Err(format!("{} widths samples for {} points samples", widths.len(), samples.len()));
    }
    for ((t, points), w) in samples.iter().zip(widths) {
        match &data.gprim {
            Some(Gprim::Points { .. }) => PointsSurface::check(points, w).map_err(|e| format!("{e} at shutter time {t}"))?,
            Some(Gprim::Curves(c)) if w.len() == c.widths.len() => {}
            Some(Gprim::Curves(c)) => {
                return Err(format!("widths at shutter time {t} has {} values (the curves have {})", w.len(), c.widths.len()))
            }
            _ => return Err("widths over the shutter for a prim without widths (only Points and curves have them)".into()),
        }
        if let Some(i) = w.iter().position(|x| !(x.is_finite() && *x >= 0.0)) {
            return Err(format!("widths[{i}] = {} at shutter time {t} must be a non-negative number", w[i]));
        }
    }
    Ok(())
}

/// Why `shapes` (one per sample of `samples`, or none) cannot be the shapes over the shutter
/// of the prim of `data`, if they cannot: one line. Only implicit prims take shapes, and an
/// implicit prim's samples need them ([`ImplicitSurface::deforming`] checks them).
pub fn check_deformation_shapes(shapes: &[Shape], samples: &DeformSamples, data: &MeshData) -> Result<(), String> {
    match &data.gprim {
        Some(Gprim::Implicit(_)) if shapes.len() == samples.len() => {
            ImplicitSurface::deforming(samples.iter().map(|s| s.0).zip(shapes.iter().copied()).collect()).map(|_| ())
        }
        Some(Gprim::Implicit(_)) => Err(format!("{} shapes for {} deformation samples of an implicit prim", shapes.len(), samples.len())),
        _ if shapes.is_empty() => Ok(()),
        _ => Err("shapes over the shutter for a prim other than an implicit one".into()),
    }
}

impl MeshPrim {
    pub fn new(path: &str, data: MeshData, cache_id: u32) -> Self {
        let invalid = data.validate().err();
        MeshPrim {
            path: path.to_string(),
            data,
            surface: None,
            dirty: DirtyBits::ALL,
            surface_syncs: 0,
            generation: 0,
            error: None,
            invalid,
            cache_id,
            motion: None,
            lazy: true,
            deformation: None,
            deformation_widths: None,
            deformation_shapes: None,
        }
    }

    /// What differs between the current data and `new`.
    pub fn diff(&self, new: &MeshData) -> DirtyBits {
        let mut d = DirtyBits::CLEAN;
        if self.data.topology != new.topology
            || self.data.st != new.st
            || self.data.normals != new.normals
            || self.data.primvar_inputs != new.primvar_inputs
            || self.data.network_primvars != new.network_primvars
            || self.data.gprim != new.gprim
        {
            d = d | DirtyBits::TOPOLOGY;
        }
        if self.data.points != new.points {
            d = d | DirtyBits::POINTS;
        }
        if self.data.transform != new.transform {
            d = d | DirtyBits::TRANSFORM;
        }
        if self.data.double_sided != new.double_sided
            || self.data.face_materials != new.face_materials
            || self.data.material != new.material
            || self.data.light != new.light
        {
            d = d | DirtyBits::MATERIAL;
        }
        if self.data.prototype != new.prototype {
            d = d | DirtyBits::VISIBILITY;
        }
        if self.data.displacement != new.displacement
            || self.data.displacement_bound != new.displacement_bound
            || self.data.displacement_texture != new.displacement_texture
        {
            // Displacement changes the tessellated shape: new cache generation.
            d = d | DirtyBits::POINTS;
        }
        d
    }

    /// Brings the surface up to date with the data. Only topology or points changes touch the
    /// surface; new points on an OpenSubdiv surface re-apply its stencils without rebuilding
    /// topology when no render holds the surface.
    ///
    /// Returns whether the surface changed (so its cache entries are stale).
    ///
    /// # Errors
    /// The mesh's data is unusable; the message names the prim.
    pub fn sync(&mut self) -> Result<bool, DelegateError> {
        let dirty = self.dirty;
        self.dirty = DirtyBits::CLEAN;
        if let Some(problem) = &self.invalid {
            // Left out until fixed; the fix rebuilds the surface (a rare case, kept simple).
            self.surface = None;
            let e = DelegateError::prim(&self.path, problem);
            self.error = Some(e.to_string());
            return Err(e);
        }
        if !(dirty.contains(DirtyBits::TOPOLOGY) || dirty.contains(DirtyBits::POINTS)) && self.surface.is_some() {
            return Ok(false);
        }
        let result = self.build(dirty);
        self.generation = self.generation.wrapping_add(1);
        self.surface_syncs += 1;
        match result {
            Ok(s) => {
                self.surface = Some(s);
                self.error = None;
                Ok(true)
            }
            Err(e) => {
                self.surface = None;
                let e = DelegateError::prim(&self.path, e);
                self.error = Some(e.to_string());
                Err(e)
            }
        }
    }

    fn build(&mut self, dirty: DirtyBits) -> Result<Surface, mipray::error::MeshError> {
        match &self.data.gprim {
            Some(Gprim::Implicit(shape)) => {
                if let (Some(samples), Some(shapes)) = (self.checked_deformation(), self.deformation_shapes.as_deref()) {
                    match ImplicitSurface::deforming(samples.iter().map(|s| s.0).zip(shapes.iter().copied()).collect()) {
                        Ok(s) => return Ok(Surface::Implicit(Arc::new(s))),
                        Err(e) => self.warn_not_blurred(&e),
                    }
                }
                return Ok(Surface::Implicit(Arc::new(ImplicitSurface::new(*shape).map_err(mipray::error::MeshError::Invalid)?)));
            }
            Some(Gprim::Points { widths }) => {
                if let Some(samples) = self.checked_deformation() {
                    let w = self.deformation_widths.as_deref().cloned().unwrap_or_else(|| vec![widths.clone()]);
                    match PointsSurface::deforming(samples.as_ref().clone(), &w) {
                        Ok(s) => return Ok(Surface::Points(Arc::new(s))),
                        Err(e) => self.warn_not_blurred(&e),
                    }
                }
                return Ok(Surface::Points(Arc::new(
                    PointsSurface::new(self.data.points.clone(), widths).map_err(mipray::error::MeshError::Invalid)?,
                )));
            }
            Some(Gprim::Curves(c)) => {
                let curves = CurvesSurface::new(&c.desc(&self.data.points)).map_err(mipray::error::MeshError::Invalid)?;
                if let Some(note) = curves.fallbacks() {
                    log::warn!("{}: {note}", self.path);
                }
                if let Some(samples) = self.checked_deformation() {
                    match self.deforming_curves(c, &samples) {
                        Ok(s) => return Ok(Surface::Curves(Arc::new(s))),
                        Err(e) => self.warn_not_blurred(&e),
                    }
                }
                return Ok(Surface::Curves(Arc::new(curves)));
            }
            Some(Gprim::Nurbs(n)) => {
                let mut surface = NurbsSurface::new(&n.desc(&self.data.points)).map_err(mipray::error::MeshError::Invalid)?;
                if let Some(t) = &n.trim {
                    surface = surface.with_trim(TrimRegion::new(&t.desc()).map_err(mipray::error::MeshError::Invalid)?);
                }
                return Ok(Surface::Nurbs(Arc::new(surface)));
            }
            None => {}
        }
        let t = &self.data.topology;
        let primvars = self.data.primvar_list();
        if let Some(samples) = self.checked_deformation() {
            return self.build_deforming(&samples, primvars);
        }
        let points_only = !dirty.contains(DirtyBits::TOPOLOGY) && primvars.is_empty();
        if let (true, Some(Surface::Osd(s))) = (points_only, self.surface.as_mut()) {
            if let Some(osd) = Arc::get_mut(s) {
                osd.update_points(&self.data.points)?;
                return Ok(Surface::Osd(s.clone()));
            }
        }
        if let (true, Some(Surface::LazyOsd(s))) = (points_only, self.surface.as_ref()) {
            // A built lazy surface refines its kept topology again, as an eager one does.
            let mut s = s.clone();
            self.surface = None;
            if let Some(lazy) = Arc::get_mut(&mut s) {
                if let Some(osd) = lazy.built_mut().and_then(Arc::get_mut) {
                    osd.update_points(&self.data.points)?;
                    lazy.rebase(self.hull(), self.osd_builder(Vec::new()));
                    return Ok(Surface::LazyOsd(s));
                }
            }
        }
        if self.lazy && t.scheme != Scheme::None {
            return Ok(Surface::LazyOsd(Arc::new(self.lazy_osd(primvars))));
        }
        Ok(match t.scheme {
            Scheme::None => Surface::Bilinear(Arc::new(BilinearSurface::new(t, &self.data.points)?.with_primvars(
                t,
                self.data.points.len(),
                &primvars,
            )?)),
            _ if primvars.is_empty() => Surface::Osd(Arc::new(OsdSurface::new(&self.path, t, &self.data.points)?)),
            _ => Surface::Osd(Arc::new(OsdSurface::with_primvars(
                &self.path,
                t,
                &self.data.points,
                &mipray_bridge::OsdOptions::default(),
                &primvars,
            )?)),
        })
    }
}

impl MeshPrim {
    /// The deformation samples when they fit the data as it is now (the data may have changed
    /// since they were set); `None` without any.
    fn checked_deformation(&self) -> Option<Arc<DeformSamples>> {
        self.deformation.clone().filter(|d| check_deformation(d, self.data.points.len()).is_ok())
    }

    /// The curves `c` at each of `samples` (their widths, if sampled, from
    /// `deformation_widths`), as one moving [`CurvesSurface`].
    fn deforming_curves(&self, c: &CurvesSpec, samples: &DeformSamples) -> Result<CurvesSurface, String> {
        let widths = self.deformation_widths.as_deref();
        let mut built = Vec::with_capacity(samples.len());
        for (k, (t, points)) in samples.iter().enumerate() {
            let mut desc = c.desc(points);
            if let Some(w) = widths.and_then(|w| w.get(k)) {
                desc.widths = w;
            }
            built.push((*t, CurvesSurface::new(&desc).map_err(|e| format!("{e} at shutter time {t}"))?));
        }
        CurvesSurface::deforming(built)
    }

    /// One line: the prim's deformation samples cannot be built (`why`), so it renders at the
    /// frame's time.
    fn warn_not_blurred(&self, why: &str) {
        log::warn!("{}: {why}; rendering it at the frame's time without motion blur", self.path);
    }

    /// The mesh at each of its deformation `samples`, as one [`mipray::deform::DeformingSurface`]:
    /// over OpenSubdiv built on first use (placed by the hull of every sample's points) unless
    /// the prim is eager, or over bilinear faces.
    fn build_deforming(&self, samples: &DeformSamples, primvars: Vec<Primvar2>) -> Result<Surface, mipray::error::MeshError> {
        let invalid = |e: String| mipray::error::MeshError::Invalid(e);
        let t = &self.data.topology;
        if t.scheme == Scheme::None {
            let mut built: Vec<(f32, Arc<dyn LimitSurface>)> = Vec::with_capacity(samples.len());
            for (time, points) in samples {
                let s = BilinearSurface::new(t, points)?.with_primvars(t, points.len(), &primvars)?;
                built.push((*time, Arc::new(s)));
            }
            return Ok(Surface::Deforming(Arc::new(mipray::deform::DeformingSurface::new(built).map_err(invalid)?)));
        }
        let (path, topology, samples) = (self.path.clone(), t.clone(), samples.clone());
        let hull = mipray::bounds::Bounds3::from_points(samples.iter().flat_map(|(_, p)| p.iter().map(|&q| q.into())));
        let build: mipray::lazy_surface::SurfaceBuilder = Box::new(move || {
            let mut built: Vec<(f32, Arc<dyn LimitSurface>)> = Vec::with_capacity(samples.len());
            for (time, points) in &samples {
                let s = if primvars.is_empty() {
                    OsdSurface::new(&path, &topology, points)
                } else {
                    OsdSurface::with_primvars(&path, &topology, points, &mipray_bridge::OsdOptions::default(), &primvars)
                };
                built.push((*time, Arc::new(s.map_err(|e| e.to_string())?)));
            }
            Ok(Arc::new(mipray::deform::DeformingSurface::new(built)?) as Arc<dyn LimitSurface>)
        });
        if self.lazy {
            return Ok(Surface::Deforming(Arc::new(LazySurface::new(hull, t.face_count(), build).deforming())));
        }
        Ok(Surface::Deforming(build().map_err(invalid)?))
    }

    /// An OpenSubdiv surface of the mesh's data built on first use, placed by the hull of its
    /// control points (which holds its limit surface: every subdivision rule is a convex
    /// combination). It keeps its own copy of the topology, points and primvars to build from.
    fn lazy_osd(&self, primvars: Vec<mipray::texture::Primvar2>) -> LazySurface<OsdSurface> {
        LazySurface::new(self.hull(), self.data.topology.face_count(), self.osd_builder(primvars))
    }

    /// Object space.
    fn hull(&self) -> mipray::bounds::Bounds3 {
        mipray::bounds::Bounds3::from_points(self.data.points.iter().map(|&p| p.into()))
    }

    /// Builds the mesh's OpenSubdiv surface from a copy of its data as it is now.
    fn osd_builder(&self, primvars: Vec<mipray::texture::Primvar2>) -> mipray::lazy_surface::SurfaceBuilder<OsdSurface> {
        let (path, topology, points) = (self.path.clone(), self.data.topology.clone(), self.data.points.clone());
        Box::new(move || {
            let s = if primvars.is_empty() {
                OsdSurface::new(&path, &topology, &points)
            } else {
                OsdSurface::with_primvars(&path, &topology, &points, &mipray_bridge::OsdOptions::default(), &primvars)
            };
            s.map(Arc::new).map_err(|e| e.to_string())
        })
    }
}

/// A float as Python's `repr` writes it (`nan`, `inf`, `1e+20`), so a point named in an error
/// reads as the scene delegate's other messages do.
fn py_float(v: f32) -> String {
    let v = f64::from(v);
    if v.is_nan() {
        return "nan".into();
    }
    if v.is_infinite() {
        return if v > 0.0 { "inf".into() } else { "-inf".into() };
    }
    let s = format!("{v:?}");
    match s.split_once('e') {
        Some((m, e)) if e.starts_with('-') => format!("{m}e-{:0>2}", &e[1..]),
        Some((m, e)) => format!("{m}e+{e:0>2}"),
        None => s,
    }
}
