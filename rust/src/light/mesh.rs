//! An emissive mesh as an area light (UsdLux `MeshLightAPI`, `GeometryLight`): world-space
//! triangles (the mesh as tessellated for lighting), sampled uniformly by area and met by rays
//! through a BVH of their own, since lights are not geometry in the scene's BVH.

use std::sync::Arc;

use glam::Vec3A;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray as BvhRay, RayHit};

use super::Distribution1D;
use crate::bounds::Bounds3;
use crate::intersect::WatertightRay;

/// The triangles of an emissive mesh, render space.
pub struct TriangleLight {
    /// Vertices a, b, c; the emitting side is the one (b − a) × (c − a) points to.
    tris: Vec<[Vec3A; 3]>,
    /// Chooses a triangle with probability ∝ its area.
    by_area: Distribution1D,
    /// Render units².
    area: f32,
    bounds: Bounds3,
    /// Emits from both sides (the mesh's `doubleSided`).
    pub two_sided: bool,
    bvh: Option<CwBvh>,
}

impl std::fmt::Debug for TriangleLight {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TriangleLight")
            .field("triangles", &self.tris.len())
            .field("area", &self.area)
            .field("two_sided", &self.two_sided)
            .finish_non_exhaustive()
    }
}

/// Where a ray meets the mesh: distance, |cosine| between the ray and the triangle's normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleHit {
    pub t: f32,
    pub cos: f32,
}

impl TriangleLight {
    /// From render-space triangles (oriented: the emitting side is the one their winding's
    /// right-hand normal points to). Triangles with a non-finite vertex or no area are left
    /// out (they could never be sampled or hit); `None` when none is left.
    pub fn new(triangles: Vec<[Vec3A; 3]>, two_sided: bool) -> Option<Arc<TriangleLight>> {
        let limit = crate::bounds::MAX_COORDINATE;
        let tris: Vec<[Vec3A; 3]> = triangles
            .into_iter()
            .filter(|t| t.iter().all(|p| p.is_finite() && p.abs().max_element() < limit) && tri_area(t) > 0.0)
            .collect();
        if tris.is_empty() {
            return None;
        }
        let areas: Vec<f32> = tris.iter().map(tri_area).collect();
        let area = areas.iter().map(|&a| f64::from(a)).sum::<f64>() as f32;
        let boxes: Vec<Bounds3> = tris.iter().map(|t| Bounds3::from_points(t.iter().copied())).collect();
        let bounds = boxes.iter().skip(1).fold(boxes[0], |a, b| a.union(b));
        let bvh = crate::bvh::build_bvh(&boxes);
        Some(Arc::new(TriangleLight { by_area: Distribution1D::new(&areas), tris, area, bounds, two_sided, bvh }))
    }

    /// Total area, render units².
    pub fn area(&self) -> f32 {
        self.area
    }

    /// Triangle count.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// Never true ([`TriangleLight::new`] refuses an empty mesh).
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// Render-space bounds of the triangles.
    pub fn bounds(&self) -> Bounds3 {
        self.bounds
    }

    /// A point uniformly distributed over the mesh's area from two uniform numbers: (point, unit
    /// normal of its triangle's emitting side). `u1` chooses the triangle and, remapped within
    /// its cell, the first barycentric coordinate, so stratified numbers stay stratified.
    pub fn sample(&self, u1: f32, u2: f32) -> (Vec3A, Vec3A) {
        let (x, _, i) = self.by_area.sample(u1);
        let n = self.tris.len() as f32;
        let v1 = (x * n - i as f32).clamp(0.0, 1.0);
        let [a, b, c] = self.tris[i];
        // Uniform over the triangle (the square-root map).
        let s = v1.sqrt();
        let (b0, b1) = (1.0 - s, u2 * s);
        let p = a * b0 + b * b1 + c * (1.0 - b0 - b1);
        (p, (b - a).cross(c - a).normalize())
    }

    /// The nearest emitting side the ray from `o` along unit `d` meets in (0, `t_max`): a
    /// one-sided mesh's back faces let the ray through, as they emit nothing toward it.
    pub fn intersect(&self, o: Vec3A, d: Vec3A, t_max: f32) -> Option<TriangleHit> {
        let bvh = self.bvh.as_ref()?;
        if !(o.is_finite() && d.is_finite()) {
            return None;
        }
        let wray = WatertightRay::new(o, d);
        let ray = BvhRay::new(o, crate::trace::positive_zeros(d), 0.0, t_max);
        let mut hit = RayHit::none();
        let mut best: Option<TriangleHit> = None;
        bvh.ray_traverse(ray, &mut hit, |r, id| {
            let [a, b, c] = self.tris[bvh.primitive_indices[id] as usize];
            let Some((t, ..)) = wray.hit_triangle(a, b, c, r.tmax) else { return f32::INFINITY };
            let ng = (b - a).cross(c - a).normalize();
            let cos = -ng.dot(d);
            if !(t > 0.0) || !(cos > 0.0 || (self.two_sided && cos < 0.0)) {
                return f32::INFINITY;
            }
            best = Some(TriangleHit { t, cos: cos.abs() });
            t
        });
        best
    }
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
}
