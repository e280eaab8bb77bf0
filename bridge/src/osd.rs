//! Subdivision surfaces through OpenSubdiv's Far: [`OsdSurface`] implements the core's
//! [`LimitSurface`] with an adaptive `Far::PatchTable` (Gregory-basis end caps), so every patch
//! is one root subpatch of the paper's §5.1 and evaluation is exact on the limit surface.
//!
//! Construction validates the mesh on the Rust side, builds a `Far::TopologyRefiner` (scheme,
//! boundary and face-varying rules, creases, corners, holes), refines adaptively, builds the patch
//! table, and makes every refined and end-cap ("local") point from the mesh's points level by
//! level (`Far::PrimvarRefiner`, then the patch table's local-point stencils): linear in the mesh,
//! where OpenSubdiv's factorized stencil tables cost the cube of a vertex's valence. The control
//! points and the patch table are kept, the refiner is not, so evaluation is a basis evaluation
//! and a weighted sum; [`OsdSurface::update_points`] refines the same topology again for animated
//! points.
//!
//! Coordinates: positions and derivatives are in the mesh's object space. A patch's own (u, v) is
//! in [0, 1]² (the triangle u + v ≤ 1 for Loop patches), and [`LimitSurface::evaluate`]'s
//! derivatives are taken with respect to it. [`PatchParam`] maps it into the ptex face
//! (`Far::PtexIndices`: one per quad, one per corner of a non-quad in Catmull-Clark and bilinear,
//! one per triangle in Loop); [`OsdSurface::limit_at`] works in that ptex parameterization.
//!
//! Primvars: [`OsdSurface::with_primvars`] takes 2-float primvars (`st`) of any interpolation.
//! Face-varying ones become OpenSubdiv face-varying channels — refined through every level with
//! `Far::PrimvarRefiner`, end caps by the patch table's face-varying local-point stencils,
//! evaluated on its face-varying patches (`EvaluateBasisFaceVarying` / `GetPatchFVarValues`), so
//! the mesh's `faceVaryingLinearInterpolation` decides how they smooth and where seams stay
//! sharp. Vertex ones are refined as the points are and evaluated on their patches; constant, uniform and
//! varying ones are interpolated over the base faces in the core
//! ([`mipray::texture::BaseFacePrimvar`]). All are read through [`LimitSurface::face_varying`].
//!
//! Rotated triangles: adaptive Loop refinement makes the middle child of a triangle point the
//! other way (`Far::PatchParam::IsTriangleRotated`). Its [`PatchParam`] has its origin at the
//! corner the local (0, 0) maps to and a **negative** `size`, so `to_face_uv` stays the exact map.

use glam::Vec3A;
use mipray::bounds::Bounds3;
use mipray::error::MeshError;
use mipray::patch::{EdgeKnots, GridSamples, LimitSurface, PatchKind, PatchParam, SurfacePoint, UvRect};
use mipray::texture::{BaseFacePrimvar, Interpolation, Primvar2, Value2};
use mipray::topology::{BoundaryInterpolation, FaceVaryingInterpolation, MeshTopology, Scheme, TriangleSubdivision};

use crate::ffi::bridge as ffi;

/// Refinement settings of an [`OsdSurface`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OsdOptions {
    /// Adaptive isolation level of sharp features (creases, corners), 1..=10. Deeper isolates
    /// semi-sharp creases more exactly at the price of more patches.
    pub isolation_level: u8,
    /// Isolation level of smooth extraordinary vertices (≤ `isolation_level`): their Gregory end
    /// caps approximate the limit surface better the deeper they sit.
    pub secondary_level: u8,
}

impl OsdOptions {
    /// Level 4 for both: OpenSubdiv's usual choice for rendering.
    pub const DEFAULT: OsdOptions = OsdOptions { isolation_level: 4, secondary_level: 4 };
}

impl Default for OsdOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A uniformly refined mesh: points (object space) and faces (indices into the points).
pub type UniformMesh = (Vec<[f32; 3]>, Vec<Vec<u32>>);

/// A limit-surface sample from OpenSubdiv's own evaluation ([`limit_reference`]).
///
/// Derivatives are as `PatchTable::EvaluateBasis` (and so OpenSubdiv's limit stencils) give
/// them: with respect to the ptex face's
/// (u, v) for quads and triangles, and with respect to *half* the ptex sub-face's (u, v) for the
/// sub-faces of a non-quad (OpenSubdiv scales them by 2^depth, and a sub-face sits at depth 1).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LimitSample {
    pub p: Vec3A,
    pub dpdu: Vec3A,
    pub dpdv: Vec3A,
}

/// Where a primvar channel of an [`OsdSurface`] is evaluated.
#[derive(Clone, Debug)]
enum PrimvarSource {
    /// OpenSubdiv face-varying channel k.
    FaceVarying(usize),
    /// OpenSubdiv vertex primvar k (through the points' stencils and patches).
    Vertex(usize),
    /// Linear over the base faces, in the core.
    BaseFace(BaseFacePrimvar),
}

/// A subdivision mesh's limit surface as OpenSubdiv patches. `Send + Sync`: after construction
/// the tables are only read (see the `SAFETY` notes in `ffi.rs`).
pub struct OsdSurface {
    name: String,
    mesh: cxx::UniquePtr<ffi::OsdMesh>,
    /// The topology as OpenSubdiv saw it, for uniform refinement on demand.
    desc: ffi::OsdMeshDesc,
    params: Vec<PatchParam>,
    control_faces: usize,
    warnings: String,
    /// What was made cheaper than the exact limit to bound the work (empty: nothing).
    simplified: String,
    /// Primvar channels, in the order given to [`OsdSurface::with_primvars`].
    primvars: Vec<PrimvarSource>,
}

impl std::fmt::Debug for OsdSurface {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OsdSurface")
            .field("name", &self.name)
            .field("patches", &self.params.len())
            .field("control_faces", &self.control_faces)
            .finish_non_exhaustive()
    }
}

impl OsdSurface {
    /// Builds the patches of a subdivision mesh with [`OsdOptions::DEFAULT`].
    ///
    /// `name` (the prim path, say) prefixes every error message. `Scheme::None` is built as
    /// bilinear (the control polygons, split into quads). `left_handed` is not passed on: the
    /// patches keep the given winding and the core flips normals of left-handed meshes itself.
    /// No primvars are built (see [`OsdSurface::with_primvars`]).
    ///
    /// # Errors
    /// [`MeshError::Invalid`] for topology that [`MeshTopology::validate`] refuses or a Loop mesh
    /// with non-triangles, [`MeshError::NonFinite`] naming the first non-finite point,
    /// [`MeshError::Subdivision`] with OpenSubdiv's own messages when it refuses the mesh.
    pub fn new(name: &str, topology: &MeshTopology, points: &[[f32; 3]]) -> Result<OsdSurface, MeshError> {
        Self::with_options(name, topology, points, &OsdOptions::DEFAULT)
    }

    /// [`OsdSurface::new`] with explicit refinement options.
    ///
    /// # Errors
    /// As [`OsdSurface::new`], and [`MeshError::Invalid`] for out-of-range options.
    pub fn with_options(name: &str, topology: &MeshTopology, points: &[[f32; 3]], options: &OsdOptions) -> Result<OsdSurface, MeshError> {
        Self::with_primvars(name, topology, points, options, &[])
    }

    /// [`OsdSurface::with_options`] with 2-float primvars (texture coordinates `st`, …): channel
    /// i of [`LimitSurface::face_varying`] is `primvars[i]`. Face-varying primvars are smoothed
    /// by OpenSubdiv under `topology.face_varying` (`faceVaryingLinearInterpolation`: `all`
    /// keeps them linear, `none` smooths them everywhere, the others keep seams and corners as
    /// USD says); vertex primvars follow the points; constant, uniform and varying ones are
    /// linear over each base face. Face-varying channels make OpenSubdiv isolate their features
    /// too, so the patch count can grow.
    ///
    /// # Errors
    /// As [`OsdSurface::with_options`], and [`MeshError::Invalid`] / [`MeshError::NonFinite`]
    /// naming the mesh and the primvar when its values or indices do not fit the topology.
    pub fn with_primvars(
        name: &str,
        topology: &MeshTopology,
        points: &[[f32; 3]],
        options: &OsdOptions,
        primvars: &[Primvar2],
    ) -> Result<OsdSurface, MeshError> {
        let mut desc = mesh_desc(name, topology, points, options)?;
        let mut sources = Vec::with_capacity(primvars.len());
        let (mut fvar, mut vertex) = (0usize, 0usize);
        for p in primvars {
            let indices = p.face_varying_indices(topology, points.len()).map_err(|e| named(name, e))?;
            match p.interpolation {
                Interpolation::FaceVarying => {
                    let count = i32::try_from(p.values.len())
                        .map_err(|_| MeshError::Invalid(format!("{name}: primvar {} has too many values", p.name)))?;
                    desc.fvar_value_counts.push(count);
                    desc.fvar_values.extend(p.values.iter().flatten());
                    desc.fvar_indices.extend(indices);
                    sources.push(PrimvarSource::FaceVarying(fvar));
                    fvar += 1;
                }
                Interpolation::Vertex => {
                    // One value per point: the point's element, through USD's indices.
                    desc.vertex_primvars.extend((0..points.len()).flat_map(|i| {
                        let k = if p.indices.is_empty() { i } else { p.indices[i] as usize };
                        p.values[k]
                    }));
                    sources.push(PrimvarSource::Vertex(vertex));
                    vertex += 1;
                }
                Interpolation::Constant | Interpolation::Uniform | Interpolation::Varying => {
                    let b = BaseFacePrimvar::new(topology, points.len(), p).map_err(|e| named(name, e))?;
                    sources.push(PrimvarSource::BaseFace(b));
                }
            }
        }
        let mesh = ffi::osd_mesh_new(&desc, points.as_flattened()).map_err(|e| subdivision_error(name, &e))?;
        if mesh.fvar_channel_count() != fvar || mesh.vertex_primvar_count() != vertex {
            return Err(subdivision_error(name, &"OpenSubdiv did not build every primvar channel"));
        }
        let warnings = mesh.warnings();
        for w in warnings.lines() {
            log::warn!("{name}: OpenSubdiv: {w}");
        }
        let simplified = mesh.simplified().to_string();
        if !simplified.is_empty() {
            log::warn!("{name}: {simplified}");
        }
        let params = mesh.patch_infos().map_err(|e| subdivision_error(name, &e))?.iter().map(patch_param_of).collect();
        Ok(OsdSurface {
            name: name.to_string(),
            mesh,
            desc,
            params,
            control_faces: topology.face_count(),
            warnings,
            simplified,
            primvars: sources,
        })
    }

    /// Bytes this surface holds, by part (docs/memory.md): OpenSubdiv's tables and points (C++),
    /// then its own records. Capacities, not lengths; without the patch map's quadtree and the
    /// allocator's headers, which only a malloc count sees.
    ///
    /// # Errors
    /// The C++ side failing to allocate the report.
    pub fn memory(&self) -> Result<Vec<(&'static str, usize)>, MeshError> {
        let parts = self.mesh.memory_parts().map_err(|e| subdivision_error(&self.name, &e))?;
        let names = [
            "control points (refined and end-cap)",
            "patch control-vertex indices",
            "patch params and crease sharpness (OpenSubdiv)",
            "end-cap stencils",
            "patch arrays, ptex map",
            "primvar values",
        ];
        let mut out: Vec<(&'static str, usize)> = names.iter().zip(parts).map(|(n, b)| (*n, b as usize)).collect();
        fn bytes<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        let d = &self.desc;
        let desc = bytes(&d.face_vertex_counts)
            + bytes(&d.face_vertex_indices)
            + bytes(&d.crease_pairs)
            + bytes(&d.crease_weights)
            + bytes(&d.corner_indices)
            + bytes(&d.corner_weights)
            + bytes(&d.hole_indices)
            + bytes(&d.fvar_value_counts)
            + bytes(&d.fvar_values)
            + bytes(&d.fvar_indices)
            + bytes(&d.vertex_primvars);
        out.push(("topology descriptor (kept to refine again)", desc));
        out.push(("patch params (mipray)", bytes(&self.params)));
        Ok(out)
    }

    /// The mesh's name, as given at construction.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Warnings OpenSubdiv reported while building (also logged), one per line.
    pub fn warnings(&self) -> &str {
        &self.warnings
    }

    /// Number of ptex faces (`Far::PtexIndices`): the faces [`OsdSurface::limit_at`] takes.
    pub fn ptex_face_count(&self) -> usize {
        self.mesh.ptex_face_count()
    }

    /// New positions for the same topology (animation): refines them as at construction (the
    /// refiner is built again: it is not kept) and recomputes the patch bounds. The patch table
    /// is not rebuilt.
    ///
    /// # Errors
    /// [`MeshError::Invalid`] if the point count differs, [`MeshError::NonFinite`] naming the
    /// first non-finite point; the surface is unchanged then.
    pub fn update_points(&mut self, points: &[[f32; 3]]) -> Result<(), MeshError> {
        if points.len() != self.desc.num_vertices as usize {
            return Err(MeshError::Invalid(format!(
                "{}: {} points given, the mesh has {}",
                self.name,
                points.len(),
                self.desc.num_vertices
            )));
        }
        check_finite(&self.name, points)?;
        self.mesh.pin_mut().update_points(&self.desc, points.as_flattened()).map_err(|e| subdivision_error(&self.name, &e))
    }

    /// The patch holding (u, v) of a ptex face (`Far::PatchMap`) and the patch's own (u, v)
    /// there; `None` in a hole or for a face or (u, v) out of range.
    pub fn find_patch(&self, ptex_face: u32, u: f32, v: f32) -> Option<(usize, f32, f32)> {
        // PatchMap's quadtree descent assumes (u, v) in the face (it only asserts it).
        if !((0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v)) {
            return None;
        }
        let face = i32::try_from(ptex_face).ok()?;
        let mut local = [0.0f32; 2];
        let patch = self.mesh.find_patch(face, u, v, &mut local);
        usize::try_from(patch).ok().map(|p| (p, local[0], local[1]))
    }

    /// The limit surface at (u, v) ∈ [0, 1]² of a ptex face (equal to the base face for a mesh of
    /// quads, or of triangles under Loop), with derivatives with respect to the ptex face's
    /// (u, v). `None` in a hole or out of range.
    pub fn limit_at(&self, ptex_face: u32, u: f32, v: f32) -> Option<SurfacePoint> {
        let (patch, s, t) = self.find_patch(ptex_face, u, v)?;
        let sp = self.evaluate(patch, s, t);
        // Local (s, t) = (face − u0) / size: chain rule, once per derivative order.
        let inv = 1.0 / self.params[patch].size;
        Some(SurfacePoint {
            p: sp.p,
            dpdu: sp.dpdu * inv,
            dpdv: sp.dpdv * inv,
            dpduu: sp.dpduu * (inv * inv),
            dpduv: sp.dpduv * (inv * inv),
            dpdvv: sp.dpdvv * (inv * inv),
        })
    }

    /// OpenSubdiv's uniform refinement of the control mesh to `level` (0..=10): the last level's
    /// points (object space) and faces (point indices; hole faces left out).
    ///
    /// # Errors
    /// [`MeshError::Invalid`] for a level out of range, [`MeshError::Subdivision`] if OpenSubdiv
    /// fails.
    pub fn uniform_refinement(&self, level: u32) -> Result<UniformMesh, MeshError> {
        if level > 10 {
            return Err(MeshError::Invalid(format!("{}: uniform level {level} is above 10", self.name)));
        }
        let points = self.base_points()?;
        let r = ffi::osd_uniform_refine(&self.desc, &points, level as i32).map_err(|e| subdivision_error(&self.name, &e))?;
        let pts = r.points.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let mut faces = Vec::with_capacity(r.face_vertex_counts.len());
        let mut start = 0usize;
        for &n in &r.face_vertex_counts {
            let n = n.max(0) as usize;
            let Some(idx) = r.face_vertex_indices.get(start..start + n) else {
                return Err(subdivision_error(&self.name, &"uniform refinement returned short face indices"));
            };
            faces.push(idx.iter().map(|&i| i.max(0) as u32).collect());
            start += n;
        }
        Ok((pts, faces))
    }

    /// The mesh's current points, read back from the control points (they come first there).
    fn base_points(&self) -> Result<Vec<f32>, MeshError> {
        let n = self.desc.num_vertices as usize;
        let mut out = vec![0.0f32; 3 * n];
        if !self.mesh.base_points(&mut out) {
            return Err(subdivision_error(&self.name, &"could not read back the mesh points"));
        }
        Ok(out)
    }
}

/// OpenSubdiv's limit surface at (ptex face, u, v) locations: the reference path for tests and
/// `mipray-subdiv-compare`. It builds its own refiner (every semi-sharp crease fully isolated)
/// and patch table with the options `Far::LimitStencilTableFactory` uses (Gregory end caps at
/// every valence, no single-crease patches), refines the points level by level, finds each
/// location's patch with `Far::PatchMap` and evaluates `PatchTable::EvaluateBasis` there, in
/// double. It shares none of [`OsdSurface`]'s tables, parameter decoding, basis evaluation or
/// derivative conversion. Unlike the limit stencils it does not factorize the refined points
/// down to the mesh's, which costs O(n³) at a vertex of valence n; this is linear in the mesh
/// (but the Gregory end caps' local points: O(n²) weights at valence n, a few MB at 360).
/// Derivatives are per unit of the ptex face's parameters.
///
/// # Errors
/// As [`OsdSurface::new`], and [`MeshError::Subdivision`] if a location has no patch (a hole).
pub fn limit_reference(
    name: &str,
    topology: &MeshTopology,
    points: &[[f32; 3]],
    options: &OsdOptions,
    locations: &[(u32, f32, f32)],
) -> Result<Vec<LimitSample>, MeshError> {
    let desc = mesh_desc(name, topology, points, options)?;
    let mut faces = Vec::with_capacity(locations.len());
    for &(f, _, _) in locations {
        faces.push(i32::try_from(f).map_err(|_| MeshError::Invalid(format!("{name}: ptex face {f} is out of range")))?);
    }
    let us: Vec<f32> = locations.iter().map(|l| l.1).collect();
    let vs: Vec<f32> = locations.iter().map(|l| l.2).collect();
    let r = ffi::osd_limit_reference_eval(&desc, points.as_flattened(), &faces, &us, &vs).map_err(|e| subdivision_error(name, &e))?;
    let v3 = |a: &[f32], i: usize| Vec3A::new(a[3 * i], a[3 * i + 1], a[3 * i + 2]);
    Ok((0..locations.len()).map(|i| LimitSample { p: v3(&r.p, i), dpdu: v3(&r.dpdu, i), dpdv: v3(&r.dpdv, i) }).collect())
}

/// A face-varying primvar's value and first derivatives from OpenSubdiv's own evaluation (the
/// reference path for tests), at (ptex face, u, v) locations; derivatives as [`LimitSample`]'s.
/// The patch table `Far::LimitStencilTableFactory` builds in face-varying mode, evaluated as
/// [`limit_reference`] evaluates points: values refined level by level, no limit stencils. The primvar must be
/// face-varying; `topology.face_varying` sets its linear interpolation.
///
/// # Errors
/// As [`limit_reference`], and [`MeshError::Invalid`] for a primvar that is not
/// face-varying or does not fit the topology.
pub fn limit_fvar_reference(
    name: &str,
    topology: &MeshTopology,
    points: &[[f32; 3]],
    options: &OsdOptions,
    primvar: &Primvar2,
    locations: &[(u32, f32, f32)],
) -> Result<Vec<Value2>, MeshError> {
    if primvar.interpolation != Interpolation::FaceVarying {
        return Err(MeshError::Invalid(format!("{name}: primvar {} is not face-varying", primvar.name)));
    }
    let mut desc = mesh_desc(name, topology, points, options)?;
    let indices = primvar.face_varying_indices(topology, points.len()).map_err(|e| named(name, e))?;
    desc.fvar_value_counts.push(
        i32::try_from(primvar.values.len())
            .map_err(|_| MeshError::Invalid(format!("{name}: primvar {} has too many values", primvar.name)))?,
    );
    desc.fvar_values.extend(primvar.values.iter().flatten());
    desc.fvar_indices.extend(indices);
    let mut faces = Vec::with_capacity(locations.len());
    for &(f, _, _) in locations {
        faces.push(i32::try_from(f).map_err(|_| MeshError::Invalid(format!("{name}: ptex face {f} is out of range")))?);
    }
    let us: Vec<f32> = locations.iter().map(|l| l.1).collect();
    let vs: Vec<f32> = locations.iter().map(|l| l.2).collect();
    let r = ffi::osd_limit_reference_fvar_eval(&desc, 0, &faces, &us, &vs).map_err(|e| subdivision_error(name, &e))?;
    let v2 = |a: &[f32], i: usize| [a[3 * i], a[3 * i + 1]];
    Ok((0..locations.len()).map(|i| (v2(&r.p, i), v2(&r.dpdu, i), v2(&r.dpdv, i))).collect())
}

impl LimitSurface for OsdSurface {
    fn patch_count(&self) -> usize {
        self.params.len()
    }

    /// # Panics
    /// If `patch >= patch_count()`.
    fn patch_param(&self, patch: usize) -> PatchParam {
        self.params[patch]
    }

    /// # Panics
    /// If `patch >= patch_count()`.
    /// Computed on each call (a Bézier conversion of 16 points, or a hull of 20) rather than kept:
    /// the tracer asks once per patch and render, and keeps them in its root subpatches.
    fn edge_knots(&self, patch: usize) -> EdgeKnots {
        let mut k = [f32::NAN; 2];
        match self.mesh.edge_knots(patch, &mut k) {
            1 => EdgeKnots { u: k, v: [f32::NAN; 2] },
            2 => EdgeKnots { u: [f32::NAN; 2], v: k },
            _ => EdgeKnots::NONE,
        }
    }

    fn patch_bounds(&self, patch: usize) -> Bounds3 {
        let mut b = [0.0f32; 6];
        if !self.mesh.patch_bound(patch, &mut b) {
            return Bounds3::EMPTY;
        }
        Bounds3 { min: Vec3A::new(b[0], b[1], b[2]), max: Vec3A::new(b[3], b[4], b[5]) }
    }

    /// Regular patches only (from their Bézier nets, see the bridge's `patch_normal_cone`);
    /// `None` for end caps and patches whose normals turn too far.
    fn patch_normal_cone(&self, patch: usize) -> Option<mipray::patch::NormalCone> {
        let mut c = [0.0f32; 4];
        if !self.mesh.patch_normal_cone(patch, &mut c) {
            return None;
        }
        // Widened a little for the rounding to f32 of the axis and sine.
        let sin_half_angle = (c[3] + 1e-5).min(1.0);
        (sin_half_angle < 1.0).then(|| mipray::patch::NormalCone { axis: Vec3A::new(c[0], c[1], c[2]), sin_half_angle })
    }

    /// # Panics
    /// If `patch >= patch_count()`.
    fn evaluate(&self, patch: usize, u: f32, v: f32) -> SurfacePoint {
        let mut o = [0.0f32; 18];
        let ok = self.mesh.evaluate(patch, u, v, &mut o);
        assert!(ok, "{}: patch {patch} out of range ({} patches)", self.name, self.params.len());
        let v3 = |k: usize| Vec3A::new(o[k], o[k + 1], o[k + 2]);
        SurfacePoint { p: v3(0), dpdu: v3(3), dpdv: v3(6), dpduu: v3(9), dpduv: v3(12), dpdvv: v3(15) }
    }

    /// One call into C++ for the whole grid; the vertices equal [`LimitSurface::evaluate`] at
    /// [`UvRect::grid_uv`].
    ///
    /// # Panics
    /// If `patch >= patch_count()`.
    fn evaluate_grid(&self, patch: usize, rect: UvRect, n: usize, derivatives: bool, out: &mut GridSamples) {
        out.n = n;
        out.p.clear();
        out.dpdu.clear();
        out.dpdv.clear();
        if n == 0 {
            return;
        }
        out.p.resize(n * n, [0.0; 3]);
        if derivatives {
            out.dpdu.resize(n * n, [0.0; 3]);
            out.dpdv.resize(n * n, [0.0; 3]);
        }
        let ok = self.mesh.evaluate_grid(
            patch,
            rect.u0,
            rect.v0,
            rect.u1,
            rect.v1,
            n,
            out.p.as_flattened_mut(),
            out.dpdu.as_flattened_mut(),
            out.dpdv.as_flattened_mut(),
        );
        assert!(ok, "{}: patch {patch} out of range ({} patches)", self.name, self.params.len());
    }

    /// One call into C++ for all the points; positions only.
    ///
    /// # Panics
    /// If `patch >= patch_count()`.
    fn evaluate_points(&self, patch: usize, uv: &[[f32; 2]], out: &mut Vec<[f32; 3]>) {
        out.clear();
        out.resize(uv.len(), [0.0; 3]);
        let ok = self.mesh.evaluate_points(patch, uv.as_flattened(), out.as_flattened_mut());
        assert!(ok, "{}: patch {patch} out of range ({} patches)", self.name, self.params.len());
    }

    fn control_face_count(&self) -> usize {
        self.control_faces
    }

    fn simplified(&self) -> Option<&str> {
        (!self.simplified.is_empty()).then_some(self.simplified.as_str())
    }

    /// [`OsdSurface::memory`]'s parts summed (without the patch map's quadtree and the
    /// allocator's headers, about a tenth more: docs/memory.md); 0 when the report fails.
    fn memory_bytes(&self) -> usize {
        self.memory().map_or(0, |parts| parts.iter().map(|(_, b)| b).sum())
    }

    /// Primvar channel `channel` (in [`OsdSurface::with_primvars`] order) at the patch's own
    /// (u, v), with derivatives with respect to them. `None` for an unknown channel or patch.
    fn face_varying(&self, channel: usize, patch: usize, u: f32, v: f32) -> Option<Value2> {
        let (vertex, k) = match self.primvars.get(channel)? {
            PrimvarSource::BaseFace(b) => return b.at_patch(self.params.get(patch)?, u, v),
            PrimvarSource::FaceVarying(k) => (false, *k),
            PrimvarSource::Vertex(k) => (true, *k),
        };
        let mut o = [0.0f32; 6];
        self.mesh.evaluate_primvar(vertex, k, patch, u, v, &mut o).then_some(([o[0], o[1]], [o[2], o[3]], [o[4], o[5]]))
    }

    /// Vertex primvars on regular patches contracted row by row in one call (see
    /// `evaluate_primvar_grid`), other channels point by point in that call.
    fn face_varying_grid(&self, channel: usize, patch: usize, rect: UvRect, n: usize, out: &mut Vec<Option<Value2>>) {
        out.clear();
        let (vertex, k) = match self.primvars.get(channel) {
            Some(PrimvarSource::FaceVarying(k)) => (false, *k),
            Some(PrimvarSource::Vertex(k)) => (true, *k),
            Some(PrimvarSource::BaseFace(b)) => {
                let param = self.params.get(patch);
                out.extend((0..n * n).map(|k| {
                    let (u, v) = rect.grid_uv(k % n, k / n, n);
                    param.and_then(|p| b.at_patch(p, u, v))
                }));
                return;
            }
            None => {
                out.resize(n * n, None);
                return;
            }
        };
        let mut o = vec![0.0f32; 6 * n * n];
        if self.mesh.evaluate_primvar_grid(vertex, k, patch, rect.u0, rect.v0, rect.u1, rect.v1, n, &mut o) {
            out.extend(o.chunks_exact(6).map(|o| Some(([o[0], o[1]], [o[2], o[3]], [o[4], o[5]]))));
        } else {
            out.resize(n * n, None);
        }
    }
}

/// The same error with the mesh's name in front of its message.
fn named(name: &str, e: MeshError) -> MeshError {
    match e {
        MeshError::Invalid(m) => MeshError::Invalid(format!("{name}: {m}")),
        MeshError::NonFinite(m) => MeshError::NonFinite(format!("{name}: {m}")),
        MeshError::Subdivision(m) => MeshError::Subdivision(format!("{name}: {m}")),
        MeshError::Unsupported(m) => MeshError::Unsupported(format!("{name}: {m}")),
    }
}

fn subdivision_error(name: &str, e: &dyn std::fmt::Display) -> MeshError {
    MeshError::Subdivision(format!("{name}: {e}"))
}

fn check_finite(name: &str, points: &[[f32; 3]]) -> Result<(), MeshError> {
    if let Some((i, p)) = points.iter().enumerate().find(|(_, p)| p.iter().any(|c| !c.is_finite())) {
        return Err(MeshError::NonFinite(format!("{name}: point {i} is {p:?}")));
    }
    Ok(())
}

/// Validates a mesh and translates it into OpenSubdiv's terms.
fn mesh_desc(name: &str, topology: &MeshTopology, points: &[[f32; 3]], options: &OsdOptions) -> Result<ffi::OsdMeshDesc, MeshError> {
    let invalid = |m: String| MeshError::Invalid(format!("{name}: {m}"));
    topology.validate(points.len()).map_err(|e| named(name, e))?;
    check_finite(name, points)?;
    let num_vertices = i32::try_from(points.len()).map_err(|_| invalid(format!("{} points is too many", points.len())))?;
    if topology.face_count() == 0 {
        return Err(invalid("the mesh has no faces".into()));
    }
    if let Some((f, v)) = repeated_vertex_opensubdiv_cannot_take(topology) {
        return Err(invalid(format!(
            "face {f} is pinched at vertex {v} (visits it twice, apart) where the other faces \
             do not make a fan: not supported (OpenSubdiv would abort); split the face"
        )));
    }
    if !(1..=10).contains(&options.isolation_level) || options.secondary_level > options.isolation_level {
        return Err(invalid(format!(
            "isolation levels {} / {} are not in 1..=10 with secondary ≤ primary",
            options.isolation_level, options.secondary_level
        )));
    }
    let scheme = match topology.scheme {
        Scheme::CatmullClark => 0,
        Scheme::Loop => {
            if let Some((f, n)) = topology.face_vertex_counts.iter().enumerate().find(|(_, &n)| n != 3) {
                return Err(invalid(format!("the Loop scheme needs triangles, but face {f} has {n} vertices")));
            }
            1
        }
        // A polygonal mesh through OpenSubdiv: bilinear patches are its control polygons.
        Scheme::Bilinear | Scheme::None => 2,
    };
    let edges = topology.crease_edges();
    Ok(ffi::OsdMeshDesc {
        scheme,
        boundary: match topology.boundary {
            BoundaryInterpolation::None => 0,
            BoundaryInterpolation::EdgeOnly => 1,
            BoundaryInterpolation::EdgeAndCorner => 2,
        },
        fvar: match topology.face_varying {
            FaceVaryingInterpolation::None => 0,
            FaceVaryingInterpolation::CornersOnly => 1,
            FaceVaryingInterpolation::CornersPlus1 => 2,
            FaceVaryingInterpolation::CornersPlus2 => 3,
            FaceVaryingInterpolation::Boundaries => 4,
            FaceVaryingInterpolation::All => 5,
        },
        triangle_subdivision: match topology.triangle_subdivision {
            TriangleSubdivision::CatmullClark => 0,
            TriangleSubdivision::Smooth => 1,
        },
        isolation_level: options.isolation_level,
        secondary_level: options.secondary_level,
        num_vertices,
        face_vertex_counts: topology.face_vertex_counts.clone(),
        face_vertex_indices: topology.face_vertex_indices.clone(),
        crease_pairs: edges.iter().flat_map(|&(a, b, _)| [a, b]).collect(),
        // Negative sharpness means smooth, as in OpenSubdiv's own shape reader.
        crease_weights: edges.iter().map(|&(_, _, s)| s.max(0.0)).collect(),
        corner_indices: topology.corner_indices.clone(),
        corner_weights: topology.corner_sharpnesses.iter().map(|s| s.max(0.0)).collect(),
        hole_indices: topology.hole_indices.clone(),
        fvar_value_counts: Vec::new(),
        fvar_values: Vec::new(),
        fvar_indices: Vec::new(),
        vertex_primvars: Vec::new(),
    })
}

/// A face pinched at a vertex — visiting it twice, apart, with four different neighbours — at a
/// vertex whose face corners and edges do not pair up (a fan has as many of each): OpenSubdiv
/// 3.5 can take such a vertex for a smooth interior one and abort on its own assertion
/// (`Sdc::Scheme::assignSmoothMaskForVertex`), so it must never see one. Returns (face, vertex).
/// Faces visiting a vertex twice in a row (a collapsed edge) or coming back along an edge (a
/// fold), and pinched vertices that still pair up, are left to OpenSubdiv, which takes them (its
/// regression shapes have them). Found by tests/fuzz_topology.rs.
fn repeated_vertex_opensubdiv_cannot_take(topology: &MeshTopology) -> Option<(usize, i32)> {
    use std::collections::{HashMap, HashSet};
    let mut suspects = Vec::new();
    let mut start = 0usize;
    for (f, &n) in topology.face_vertex_counts.iter().enumerate() {
        let n = n.max(0) as usize;
        // The face with runs of one vertex (collapsed edges, wrapping round) merged.
        let face = &topology.face_vertex_indices[start..start + n];
        let mut runs: Vec<i32> = Vec::with_capacity(n);
        for &v in face {
            if runs.last() != Some(&v) {
                runs.push(v);
            }
        }
        while runs.len() > 1 && runs.first() == runs.last() {
            runs.pop();
        }
        // Two visits whose four neighbours all differ pinch the face at the vertex; a face
        // that comes back along one of its edges instead is a fold OpenSubdiv tags as
        // non-manifold, and takes.
        let m = runs.len();
        let around = |k: usize| [runs[(k + m - 1) % m], runs[(k + 1) % m]];
        for k in 0..m {
            for j in 0..k {
                if runs[j] == runs[k] {
                    let (a, b) = (around(j), around(k));
                    if a.iter().all(|x| !b.contains(x)) {
                        suspects.push((f, runs[k]));
                    }
                }
            }
        }
        start += n;
    }
    if suspects.is_empty() {
        return None;
    }
    let watch: HashSet<i32> = suspects.iter().map(|&(_, v)| v).collect();
    let mut corners: HashMap<i32, usize> = HashMap::new();
    let mut edges: HashMap<i32, HashSet<i32>> = HashMap::new();
    let mut start = 0usize;
    for &n in &topology.face_vertex_counts {
        let n = n.max(0) as usize;
        let face = &topology.face_vertex_indices[start..start + n];
        for k in 0..n {
            let (v, next) = (face[k], face[(k + 1) % n]);
            if watch.contains(&v) {
                *corners.entry(v).or_default() += 1;
                edges.entry(v).or_default().insert(next);
            }
            if watch.contains(&next) {
                edges.entry(next).or_default().insert(v);
            }
        }
        start += n;
    }
    suspects.into_iter().find(|(_, v)| corners.get(v).copied().unwrap_or(0) != edges.get(v).map_or(0, HashSet::len))
}

fn patch_param_of(info: &ffi::OsdPatchInfo) -> PatchParam {
    PatchParam {
        base_face: info.base_face.max(0) as u32,
        ptex_face: info.ptex_face.max(0) as u32,
        u0: info.u0,
        v0: info.v0,
        size: info.size,
        depth: info.depth,
        boundary_mask: info.boundary,
        transition_mask: info.transition,
        kind: match info.kind {
            0 => PatchKind::Bilinear,
            1 => PatchKind::Regular,
            2 => PatchKind::GregoryBasis,
            3 => PatchKind::LoopRegular,
            4 => PatchKind::GregoryTriangle,
            _ => PatchKind::Other,
        },
    }
}
