//! An emissive mesh as an area light (UsdLux `MeshLightAPI`, `GeometryLight`): triangles (the
//! mesh as tessellated for lighting), sampled uniformly by area and met by rays through a BVH
//! of their own, since lights are not geometry in the scene's BVH. A moving mesh (transform
//! motion blur) keeps its triangles in object space and is posed at each ray's shutter time.
//!
//! Each triangle may emit its own colour ([`MeshEmission`]: UsdLux `materialGlowTintsLight` with
//! the material bound to its face, a GeomSubset's or the mesh's), constant or read from an
//! `emissiveColor` texture at the point's `st`. Triangles are then chosen by area × their
//! emitter's mean colour (channel mean), so a bright subset gets most samples and a black one
//! none (it emits nothing: no bias).

use std::sync::Arc;

use glam::{Mat4, Vec3A};
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray as BvhRay, RayHit};

use super::Distribution1D;
use crate::bounds::Bounds3;
use crate::intersect::WatertightRay;
use crate::material::TexturedColor;
use crate::motion::MotionTransform;

/// What a mesh light's triangle emits, as a factor of the light's radiance (linear RGB).
#[derive(Clone, Debug, PartialEq)]
pub enum Emitter {
    /// The same colour everywhere on the triangle.
    Color(Vec3A),
    /// An `emissiveColor` texture (`texel · scale + bias`, negative and non-finite values read
    /// as 0), looked up at the point's `st` over about one texel.
    Texture(TexturedColor),
}

/// Per-triangle emission of a mesh light: for each triangle given to
/// [`TriangleLight::with_emission`], which emitter it takes and, for textures, its `st` at its
/// three vertices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshEmission {
    pub emitters: Vec<Emitter>,
    /// Per triangle, an index into `emitters` (out of range: emits nothing).
    pub per_triangle: Vec<u32>,
    /// Per triangle, `st` at vertices a, b, c; empty when the mesh has no `st` (a texture then
    /// reads its fallback).
    pub st: Vec<[[f32; 2]; 3]>,
}

/// An emitter with what sampling needs of it.
#[derive(Debug)]
struct Source {
    emitter: Emitter,
    /// Its mean colour (a texture's over the whole image: its coarsest MIP level).
    mean: Vec3A,
    /// A texture's lookup width in `st` units: one texel of its finer axis.
    texel: f32,
}

impl Source {
    fn new(emitter: Emitter) -> Source {
        let clean = |c: Vec3A| if c.is_finite() { c.max(Vec3A::ZERO) } else { Vec3A::ZERO };
        match &emitter {
            Emitter::Color(c) => Source { mean: clean(*c), texel: 0.0, emitter },
            Emitter::Texture(t) => {
                let [w, h] = t.sampler.resolution(t.texture).unwrap_or([1024, 1024]);
                // A footprint of the whole image: its coarsest level, the mean.
                let mean = clean(t.eval_raw(Some([0.5, 0.5]), [1.0, 0.0], [0.0, 1.0], 3));
                Source { mean, texel: 1.0 / w.max(h).max(1) as f32, emitter }
            }
        }
    }

    /// The colour at `st` (`None`: the mesh has no `st`).
    fn at(&self, st: Option<[f32; 2]>) -> Vec3A {
        match &self.emitter {
            Emitter::Color(_) => self.mean,
            Emitter::Texture(t) => {
                let c = t.eval_raw(st, [self.texel, 0.0], [0.0, self.texel], 3);
                if c.is_finite() {
                    c.max(Vec3A::ZERO)
                } else {
                    Vec3A::ZERO
                }
            }
        }
    }
}

/// The triangles of an emissive mesh: render space, or object space under `motion`.
pub struct TriangleLight {
    /// Vertices a, b, c; the emitting side is the one (b − a) × (c − a) points to (for a
    /// moving mesh, the side that normal's pose under the transform points to).
    tris: Vec<[Vec3A; 3]>,
    /// Chooses a triangle with probability ∝ its area (in `tris`' space).
    by_area: Distribution1D,
    /// Render units²: the area at the shutter's open.
    area: f32,
    /// Render units²: the largest area at a motion key (an upper bound for importance).
    max_area: f32,
    /// Render space; a moving mesh's over the whole shutter.
    bounds: Bounds3,
    /// Emits from both sides (the mesh's `doubleSided`).
    pub two_sided: bool,
    bvh: Option<CwBvh>,
    /// Object to render space over the shutter; `None`: `tris` are in render space.
    motion: Option<MotionTransform>,
    /// A deforming mesh's triangles at its samples' shutter times, in `tris`' space (`tris` is
    /// sample 0): a ray or a sample at time t meets the triangles blended between the
    /// bracketing samples ([`crate::deform::bracket`]), as the deforming geometry is.
    deform: Option<DeformTris>,
    /// Per triangle: its area in `tris`' space over the probability of choosing it (the
    /// reciprocal of a point's density there, per unit² of `tris`' space).
    density_area: Vec<f32>,
    /// Per triangle, an index into `sources`; empty: every triangle emits 1.
    source_of: Vec<u32>,
    sources: Vec<Source>,
    /// Per triangle, `st` at its vertices (empty: none).
    st: Vec<[[f32; 2]; 3]>,
    /// Area-weighted mean of what the triangles emit (RGB; 1 without [`MeshEmission`]).
    mean_emission: Vec3A,
}

impl std::fmt::Debug for TriangleLight {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TriangleLight")
            .field("triangles", &self.tris.len())
            .field("area", &self.area)
            .field("two_sided", &self.two_sided)
            .field("moving", &self.motion.is_some())
            .finish_non_exhaustive()
    }
}

/// Where a ray meets the mesh: distance, |cosine| between the ray and the triangle's normal,
/// the area whose reciprocal is the density (per render unit²) with which
/// [`TriangleLight::sample_at`] picks that point (the mesh's area when its triangles are chosen
/// by area and it does not deform them unevenly; infinite where it never picks it), and what
/// the point emits as a factor of the light's radiance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleHit {
    pub t: f32,
    pub cos: f32,
    pub area: f32,
    pub emission: Vec3A,
}

/// A point [`TriangleLight::sample_at`] chose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrianglePoint {
    /// Render space.
    pub p: Vec3A,
    /// Unit normal of the emitting side there.
    pub normal: Vec3A,
    /// As [`TriangleHit::area`]: the point's density per render unit² is 1 / `area`.
    pub area: f32,
    /// As [`TriangleHit::emission`].
    pub emission: Vec3A,
}

impl TriangleLight {
    /// From render-space triangles (oriented: the emitting side is the one their winding's
    /// right-hand normal points to). Triangles with a non-finite vertex or no area are left
    /// out (they could never be sampled or hit); `None` when none is left.
    pub fn new(triangles: Vec<[Vec3A; 3]>, two_sided: bool) -> Option<Arc<TriangleLight>> {
        Self::build(triangles, two_sided, None, None)
    }

    /// As [`TriangleLight::new`] (render-space triangles) or [`TriangleLight::moving`] (object
    /// space, with `motion`), each triangle emitting what `emission` gives it.
    pub fn with_emission(
        triangles: Vec<[Vec3A; 3]>,
        two_sided: bool,
        motion: Option<MotionTransform>,
        emission: MeshEmission,
    ) -> Option<Arc<TriangleLight>> {
        Self::build(triangles, two_sided, motion, Some(emission))
    }

    /// A mesh moving under `motion` (object to render space over the shutter): `triangles`
    /// in object space, oriented as for [`TriangleLight::new`] in that space (a mirroring
    /// pose keeps the emitting side the one the object-space normal's pose points to).
    pub fn moving(triangles: Vec<[Vec3A; 3]>, two_sided: bool, motion: MotionTransform) -> Option<Arc<TriangleLight>> {
        Self::build(triangles, two_sided, Some(motion), None)
    }

    /// A deforming mesh: `samples` are its triangles (the same triangles, in the same order,
    /// in object space with `motion`, else render space) at strictly increasing shutter times
    /// (2 to [`crate::deform::MAX_SAMPLES`]); each triangle emits what `emission` gives it
    /// (`None`: 1). The choice of triangles is by their area at the first sample; a point's
    /// density follows its triangle's area at the ray's time. `None` when the samples do not
    /// fit (times, counts) or nothing has area.
    pub fn deforming(
        samples: Vec<(f32, Vec<[Vec3A; 3]>)>,
        two_sided: bool,
        motion: Option<MotionTransform>,
        emission: Option<MeshEmission>,
    ) -> Option<Arc<TriangleLight>> {
        let times: Vec<f32> = samples.iter().map(|s| s.0).collect();
        crate::deform::check_times(&times).ok()?;
        let n = samples[0].1.len();
        if samples.iter().any(|s| s.1.len() != n) {
            return None;
        }
        let mut all: Vec<Vec<[Vec3A; 3]>> = samples.into_iter().map(|s| s.1).collect();
        let first = std::mem::take(&mut all[0]);
        Self::build_with(first, two_sided, motion, emission, Some(DeformTris { times, tris: all }))
    }

    fn build(
        triangles: Vec<[Vec3A; 3]>,
        two_sided: bool,
        motion: Option<MotionTransform>,
        emission: Option<MeshEmission>,
    ) -> Option<Arc<TriangleLight>> {
        Self::build_with(triangles, two_sided, motion, emission, None)
    }

    /// `deform`: the sample times and every sample's triangles, all of them (sample 0's slot
    /// empty: it is `triangles`).
    fn build_with(
        triangles: Vec<[Vec3A; 3]>,
        two_sided: bool,
        motion: Option<MotionTransform>,
        emission: Option<MeshEmission>,
        deform: Option<DeformTris>,
    ) -> Option<Arc<TriangleLight>> {
        let limit = crate::bounds::MAX_COORDINATE;
        let usable = |t: &[Vec3A; 3]| t.iter().all(|p| p.is_finite() && p.abs().max_element() < limit);
        let keep: Vec<usize> = (0..triangles.len())
            .filter(|&k| {
                let t = &triangles[k];
                let later = deform.as_ref().is_none_or(|d| d.tris.iter().skip(1).all(|s| usable(&s[k])));
                usable(t) && tri_area(t) > 0.0 && later
            })
            .collect();
        if keep.is_empty() {
            return None;
        }
        let tris: Vec<[Vec3A; 3]> = keep.iter().map(|&k| triangles[k]).collect();
        let deform = deform.map(|d| {
            let mut tris_at: Vec<Vec<[Vec3A; 3]>> = d.tris.iter().skip(1).map(|s| keep.iter().map(|&k| s[k]).collect()).collect();
            tris_at.insert(0, tris.clone());
            DeformTris { times: d.times, tris: tris_at }
        });
        let areas: Vec<f32> = tris.iter().map(tri_area).collect();
        let own_area = areas.iter().map(|&a| f64::from(a)).sum::<f64>() as f32;
        let (sources, source_of, st) = match emission {
            None => (Vec::new(), Vec::new(), Vec::new()),
            Some(e) => {
                let n = e.emitters.len() as u32;
                let source_of: Vec<u32> = keep.iter().map(|&k| e.per_triangle.get(k).copied().filter(|&s| s < n).unwrap_or(n)).collect();
                let st = if e.st.len() == triangles.len() { keep.iter().map(|&k| e.st[k]).collect() } else { Vec::new() };
                let mut sources: Vec<Source> = e.emitters.into_iter().map(Source::new).collect();
                // Triangles naming no emitter emit nothing.
                sources.push(Source::new(Emitter::Color(Vec3A::ZERO)));
                (sources, source_of, st)
            }
        };
        // Choice by area × the emitter's mean (channel mean). A texture's mean may be 0 where
        // parts of it emit (a negative bias): it keeps a floor so every emitting point can be
        // picked.
        let strength = |c: Vec3A| (c.x + c.y + c.z) / 3.0;
        let top = sources.iter().map(|s| strength(s.mean)).fold(0.0f32, f32::max);
        let weight_of = |s: &Source| match s.emitter {
            Emitter::Color(_) => strength(s.mean),
            Emitter::Texture(_) => strength(s.mean).max(1e-3 * top).max(f32::MIN_POSITIVE),
        };
        let weights: Vec<f32> = if sources.is_empty() {
            areas.clone()
        } else {
            let w: Vec<f32> = areas.iter().zip(&source_of).map(|(a, &s)| a * weight_of(&sources[s as usize])).collect();
            // Nothing emits: chosen by area (every sample then carries 0).
            if w.iter().any(|&x| x > 0.0) {
                w
            } else {
                areas.clone()
            }
        };
        let total = weights.iter().map(|&w| f64::from(w)).sum::<f64>();
        let density_area: Vec<f32> = areas
            .iter()
            .zip(&weights)
            .map(|(&a, &w)| if w > 0.0 { (f64::from(a) * total / f64::from(w)) as f32 } else { f32::INFINITY })
            .collect();
        let mean_emission = if sources.is_empty() {
            Vec3A::ONE
        } else {
            let sum = areas.iter().zip(&source_of).fold(Vec3A::ZERO, |acc, (&a, &s)| acc + sources[s as usize].mean * a);
            sum / own_area
        };
        // A deforming triangle's box holds it at every sample, so every blend (a box is convex).
        let boxes: Vec<Bounds3> = (0..tris.len())
            .map(|i| match &deform {
                None => Bounds3::from_points(tris[i].iter().copied()),
                Some(d) => Bounds3::from_points(d.tris.iter().flat_map(|s| s[i].iter().copied())),
            })
            .collect();
        let own_bounds = boxes.iter().skip(1).fold(boxes[0], |a, b| a.union(b));
        let bvh = crate::bvh::build_bvh(&boxes);
        // The largest area over the samples: an upper bound for importance (each sample's sum;
        // a blend's area is at most the larger of its two ends' by convexity of the norm).
        let sample_areas = |x: &Mat4| -> f32 {
            let area_of =
                |ts: &[[Vec3A; 3]]| ts.iter().map(|t| f64::from(tri_area(&t.map(|p| x.transform_point3a(p))))).sum::<f64>() as f32;
            match &deform {
                None => area_of(&tris),
                Some(d) => d.tris.iter().map(|s| area_of(s)).fold(0.0f32, f32::max),
            }
        };
        let (area, max_area, bounds) = match &motion {
            None => (own_area, sample_areas(&Mat4::IDENTITY).max(own_area), own_bounds),
            Some(m) => {
                let posed = |x: &Mat4| tris.iter().map(|t| f64::from(tri_area(&t.map(|p| x.transform_point3a(p))))).sum::<f64>() as f32;
                let max_area = m.keys().iter().map(|k| sample_areas(&k.render_from_object)).fold(0.0f32, f32::max);
                (posed(&m.at(0.0)), max_area, m.swept_bounds(&own_bounds))
            }
        };
        if !(area > 0.0 && area.is_finite()) {
            return None;
        }
        Some(Arc::new(TriangleLight {
            by_area: Distribution1D::new(&weights),
            tris,
            area,
            max_area,
            bounds,
            two_sided,
            bvh,
            motion,
            deform,
            density_area,
            source_of,
            sources,
            st,
            mean_emission,
        }))
    }

    /// The area-weighted mean of what the triangles emit, as a factor of the light's radiance
    /// (RGB; a texture counts as its mean): what the light's power is scaled by.
    pub fn mean_emission(&self) -> Vec3A {
        self.mean_emission
    }

    /// Whether the triangles emit their own colours ([`TriangleLight::with_emission`]).
    pub fn has_emission(&self) -> bool {
        !self.sources.is_empty()
    }

    /// What point (barycentrics `b` of a, b, c) of triangle `i` emits, as a factor of the
    /// light's radiance.
    fn emission(&self, i: usize, b: [f32; 3]) -> Vec3A {
        let Some(&s) = self.source_of.get(i) else { return Vec3A::ONE };
        let st = self.st.get(i).map(|t| {
            let f = |c: usize| b[0] * t[0][c] + b[1] * t[1][c] + b[2] * t[2][c];
            [f(0), f(1)]
        });
        self.sources[s as usize].at(st)
    }

    /// Total area, render units² (a moving mesh's at the shutter's open: what `normalize`
    /// divides by).
    pub fn area(&self) -> f32 {
        self.area
    }

    /// The largest area the mesh has at a motion key or deformation sample (its area when it
    /// does not move).
    pub fn max_area(&self) -> f32 {
        self.max_area
    }

    /// True when the mesh moves or deforms over the shutter.
    pub fn is_moving(&self) -> bool {
        self.motion.is_some() || self.deform.is_some()
    }

    /// Triangle count.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// Never true ([`TriangleLight::new`] refuses an empty mesh).
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// Render-space bounds of the triangles (over the whole shutter when moving).
    pub fn bounds(&self) -> Bounds3 {
        self.bounds
    }

    /// A point uniformly distributed over the mesh's area from two uniform numbers: (point, unit
    /// normal of its triangle's emitting side), at the shutter's open.
    pub fn sample(&self, u1: f32, u2: f32) -> (Vec3A, Vec3A) {
        let s = self.sample_at(u1, u2, 0.0);
        (s.p, s.normal)
    }

    /// A point on the mesh posed at shutter time `time` from two uniform numbers: uniform over
    /// its area in its own space. `u1` chooses the triangle and, remapped within its cell, the
    /// first barycentric coordinate, so stratified numbers stay stratified.
    pub fn sample_at(&self, u1: f32, u2: f32, time: f32) -> TrianglePoint {
        let (x, _, i) = self.by_area.sample(u1);
        let n = self.tris.len() as f32;
        let v1 = (x * n - i as f32).clamp(0.0, 1.0);
        let [a, b, c] = self.tri_at(i, time);
        // Uniform over the triangle (the square-root map).
        let s = v1.sqrt();
        let (b0, b1) = (1.0 - s, u2 * s);
        let b2 = 1.0 - b0 - b1;
        let p = a * b0 + b * b1 + c * b2;
        let emission = self.emission(i, [b0, b1, b2]);
        match &self.motion {
            None => {
                let (normal, area) = self.posed_normal(&Mat4::IDENTITY, i, [a, b, c]);
                TrianglePoint { p, normal, area, emission }
            }
            Some(m) => {
                let x = m.at(time);
                let (normal, area) = self.posed_normal(&x, i, [a, b, c]);
                TrianglePoint { p: x.transform_point3a(p), normal, area, emission }
            }
        }
    }

    /// Triangle `i` at shutter time `time`, in `tris`' space (blended between the bracketing
    /// samples of a deforming mesh; `tris[i]` otherwise).
    fn tri_at(&self, i: usize, time: f32) -> [Vec3A; 3] {
        match &self.deform {
            None => self.tris[i],
            Some(d) => {
                let (k0, k1, f) = crate::deform::bracket(&d.times, time);
                let (p, q) = (d.tris[k0][i], d.tris[k1][i]);
                [p[0].lerp(q[0], f), p[1].lerp(q[1], f), p[2].lerp(q[2], f)]
            }
        }
    }

    /// Triangle `i`, as `now` (its vertices at the ray's time), its unit emitting normal under
    /// pose `x`, and the area whose reciprocal is the render-space density of a point sampled
    /// on it: its own-space one at sample 0 times the ratio by which the deformation and the
    /// pose scale this triangle (an affine map scales a triangle's area by one factor). A
    /// triangle deformed to no area has density area 0: it gives nothing.
    fn posed_normal(&self, x: &Mat4, i: usize, now: [Vec3A; 3]) -> (Vec3A, f32) {
        let [a, b, c] = self.tris[i];
        let own = (b - a).cross(c - a);
        let [a, b, c] = now;
        let posed = x.transform_vector3a(b - a).cross(x.transform_vector3a(c - a));
        // (Ma) × (Mb) = det(M) M⁻ᵀ(a × b): a mirroring pose turns it against the covector's pose.
        let sign = if x.determinant() < 0.0 { -1.0 } else { 1.0 };
        let normal = posed.normalize_or_zero() * sign;
        if normal == Vec3A::ZERO {
            return (own.normalize(), 0.0);
        }
        (normal, self.density_area[i] * posed.length() / own.length())
    }

    /// The nearest emitting side the ray from `o` along unit `d` meets in (0, `t_max`) at the
    /// shutter's open: a one-sided mesh's back faces let the ray through, as they emit nothing
    /// toward it.
    pub fn intersect(&self, o: Vec3A, d: Vec3A, t_max: f32) -> Option<TriangleHit> {
        self.intersect_at(o, d, t_max, 0.0)
    }

    /// As [`TriangleLight::intersect`], the mesh posed at shutter time `time`.
    pub fn intersect_at(&self, o: Vec3A, d: Vec3A, t_max: f32, time: f32) -> Option<TriangleHit> {
        if !(o.is_finite() && d.is_finite()) {
            return None;
        }
        let Some(m) = &self.motion else {
            let (t, i, bary) = self.nearest(o, d, t_max, time)?;
            let (normal, area) = self.posed_normal(&Mat4::IDENTITY, i, self.tri_at(i, time));
            return Some(TriangleHit { t, cos: normal.dot(d).abs(), area, emission: self.emission(i, bary) });
        };
        // In object space the ray is o' + t·d' with the same t (d' not unit), and which side
        // it meets is the same: n_render · d = |det M| n_object · M⁻¹d.
        let x = m.at(time);
        let inv = x.inverse();
        let (oo, od) = (inv.transform_point3a(o), inv.transform_vector3a(d));
        if !(oo.is_finite() && od.is_finite()) {
            return None;
        }
        let (t, i, bary) = self.nearest(oo, od, t_max, time)?;
        let (normal, area) = self.posed_normal(&x, i, self.tri_at(i, time));
        Some(TriangleHit { t, cos: normal.dot(d).abs(), area, emission: self.emission(i, bary) })
    }

    /// The nearest emitting triangle along o + t·d, t in (0, `t_max`), in `tris`' space at
    /// shutter time `time`: (t, triangle index, barycentrics of its a, b, c).
    fn nearest(&self, o: Vec3A, d: Vec3A, t_max: f32, time: f32) -> Option<(f32, usize, [f32; 3])> {
        let bvh = self.bvh.as_ref()?;
        let wray = WatertightRay::new(o, d);
        let ray = BvhRay::new(o, crate::trace::positive_zeros(d), 0.0, t_max);
        let mut hit = RayHit::none();
        let mut best: Option<(f32, usize, [f32; 3])> = None;
        bvh.ray_traverse(ray, &mut hit, |r, id| {
            let i = bvh.primitive_indices[id] as usize;
            let [a, b, c] = self.tri_at(i, time);
            let Some((t, b0, b1, b2)) = wray.hit_triangle(a, b, c, r.tmax) else { return f32::INFINITY };
            let cos = -(b - a).cross(c - a).dot(d);
            if !(t > 0.0) || !(cos > 0.0 || (self.two_sided && cos < 0.0)) {
                return f32::INFINITY;
            }
            best = Some((t, i, [b0, b1, b2]));
            t
        });
        best
    }
}

/// A deforming mesh light's triangles at its samples (see [`TriangleLight::deforming`]).
#[derive(Clone, Debug)]
struct DeformTris {
    /// Strictly increasing shutter times.
    times: Vec<f32>,
    /// Per sample, every triangle (kept ones, in `tris`' order).
    tris: Vec<Vec<[Vec3A; 3]>>,
}

fn tri_area(t: &[Vec3A; 3]) -> f32 {
    0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad(z: f32, half: f32, down: bool) -> Vec<[Vec3A; 3]> {
        let p = |x: f32, y: f32| Vec3A::new(x * half, y * half, z);
        // Counter-clockwise seen from +z: the normal is +z.
        let up = vec![[p(-1.0, -1.0), p(1.0, -1.0), p(1.0, 1.0)], [p(-1.0, -1.0), p(1.0, 1.0), p(-1.0, 1.0)]];
        if down {
            up.into_iter().map(|[a, b, c]| [a, c, b]).collect()
        } else {
            up
        }
    }

    #[test]
    fn samples_cover_the_area_uniformly_and_face_the_emitting_side() {
        let light = TriangleLight::new(quad(2.0, 1.0, true), false).unwrap();
        assert!((light.area() - 4.0).abs() < 1e-6);
        // The mean of uniform points over the square is its centre; each quadrant gets a quarter.
        let mut quadrants = [0u32; 4];
        let n = 40_000;
        let mut s = crate::sampling::Sampler::new(7, 0, 0);
        for _ in 0..n {
            let (p, normal) = light.sample(s.next_f32(), s.next_f32());
            assert!((normal - Vec3A::NEG_Z).length() < 1e-6 && (p.z - 2.0).abs() < 1e-6);
            quadrants[usize::from(p.x > 0.0) + 2 * usize::from(p.y > 0.0)] += 1;
        }
        for q in quadrants {
            assert!((f64::from(q) / f64::from(n) - 0.25).abs() < 0.01, "{quadrants:?}");
        }
    }

    #[test]
    fn rays_meet_the_emitting_side_only_unless_two_sided() {
        let light = TriangleLight::new(quad(2.0, 1.0, true), false).unwrap();
        let h = light.intersect(Vec3A::new(0.3, 0.2, 0.0), Vec3A::Z, f32::INFINITY).unwrap();
        assert!((h.t - 2.0).abs() < 1e-6 && (h.cos - 1.0).abs() < 1e-6);
        assert!(light.intersect(Vec3A::new(0.3, 0.2, 0.0), Vec3A::Z, 1.5).is_none());
        assert!(light.intersect(Vec3A::new(0.3, 0.2, 4.0), Vec3A::NEG_Z, f32::INFINITY).is_none());
        assert!(light.intersect(Vec3A::new(3.0, 0.2, 0.0), Vec3A::Z, f32::INFINITY).is_none());
        let both = TriangleLight::new(quad(2.0, 1.0, true), true).unwrap();
        assert!(both.intersect(Vec3A::new(0.3, 0.2, 4.0), Vec3A::NEG_Z, f32::INFINITY).is_some());
        // Nothing usable: no light.
        assert!(TriangleLight::new(vec![[Vec3A::ZERO; 3], [Vec3A::NAN, Vec3A::X, Vec3A::Y]], false).is_none());
    }

    #[test]
    fn a_deforming_mesh_is_sampled_and_met_as_blended_at_the_ray_s_time() {
        // A downward quad at z = 2 growing from half-width 1 (shutter open) to 2 (close).
        let light = TriangleLight::deforming(vec![(0.0, quad(2.0, 1.0, true)), (1.0, quad(2.0, 2.0, true))], false, None, None).unwrap();
        assert!(light.is_moving() && (light.area() - 4.0).abs() < 1e-6 && (light.max_area() - 16.0).abs() < 1e-5);
        let mut s = crate::sampling::Sampler::new(3, 0, 0);
        let mut widest = 0.0f32;
        for _ in 0..4000 {
            let p = light.sample_at(s.next_f32(), s.next_f32(), 0.5);
            // Half-width 1.5 at mid-shutter: the density is uniform over its area, 9.
            assert!((p.area - 9.0).abs() < 1e-4 && (p.normal - Vec3A::NEG_Z).length() < 1e-6, "{p:?}");
            assert!(p.p.x.abs() <= 1.5 + 1e-5 && p.p.y.abs() <= 1.5 + 1e-5 && (p.p.z - 2.0).abs() < 1e-6);
            widest = widest.max(p.p.x.abs());
        }
        assert!(widest > 1.4, "samples cover the blended quad, not the first sample's");
        let up = |x: f32, t: f32| light.intersect_at(Vec3A::new(x, 0.0, 0.0), Vec3A::Z, f32::INFINITY, t);
        assert!(up(1.2, 0.0).is_none() && up(1.2, 0.5).is_some() && up(1.7, 0.5).is_none() && up(1.7, 1.0).is_some());
        let h = up(0.3, 0.5).unwrap();
        assert!((h.t - 2.0).abs() < 1e-6 && (h.area - 9.0).abs() < 1e-4 && (h.cos - 1.0).abs() < 1e-6);
        // Samples that do not fit: no light.
        assert!(TriangleLight::deforming(vec![(0.0, quad(2.0, 1.0, true)), (1.0, quad(2.0, 2.0, true)[..1].to_vec())], false, None, None)
            .is_none());
        assert!(TriangleLight::deforming(vec![(0.5, quad(2.0, 1.0, true)), (0.5, quad(2.0, 2.0, true))], false, None, None).is_none());
    }
}
