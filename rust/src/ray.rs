//! Rays that carry their differentials, and the ray types the stats count.

use glam::Vec3A;

use crate::differential::RayDifferential;

/// Why a ray was traced: the paper's ray types (§4), and the stats' `render.rays.*` names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RayKind {
    Camera,
    Shadow,
    Reflection,
    Refraction,
    Glossy,
    Diffuse,
    Ao,
}

impl RayKind {
    pub const ALL: [RayKind; 7] =
        [RayKind::Camera, RayKind::Shadow, RayKind::Reflection, RayKind::Refraction, RayKind::Glossy, RayKind::Diffuse, RayKind::Ao];

    /// Position in [`RayKind::ALL`] (the per-kind counters' index): the declaration order.
    #[inline]
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The stats name (`render.rays.<name>`).
    pub const fn name(self) -> &'static str {
        match self {
            RayKind::Camera => "camera",
            RayKind::Shadow => "shadow",
            RayKind::Reflection => "reflection",
            RayKind::Refraction => "refraction",
            RayKind::Glossy => "glossy",
            RayKind::Diffuse => "diffuse",
            RayKind::Ao => "ao",
        }
    }
}

/// A ray in render (world) space: origin `o`, unit direction `d`, the parametric interval
/// [`t_min`, `t_max`] in world units along `d`, and its differential (beam) with respect to
/// image x and y.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub o: Vec3A,
    pub d: Vec3A,
    pub t_min: f32,
    pub t_max: f32,
    pub diff: RayDifferential,
    pub kind: RayKind,
    /// When the ray exists, as a fraction of the camera's shutter interval: 0 at shutter open, 1
    /// at close. Every ray a camera sample spawns inherits its time, so a moving object is seen,
    /// shadowed and reflected where it was at that instant (transform motion blur).
    pub time: f32,
}

impl Ray {
    /// The point at distance `t` along the ray.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3A {
        self.o + self.d * t
    }

    /// World-space beam width at distance `t` (the paper's §4.1): the size that tessellated
    /// quads hit by this ray should have.
    #[inline]
    pub fn beam_width(&self, t: f32) -> f32 {
        self.diff.beam_width_at(t)
    }
}

/// Offsets a ray origin off a surface along the geometric normal `ng` (on the side of `toward`)
/// by a bound on the floating-point error of the hit point, instead of a global epsilon
/// (pbrt's `OffsetRayOrigin`). `p_error` is a conservative per-axis error of `p`.
#[inline]
pub fn offset_origin(p: Vec3A, p_error: Vec3A, ng: Vec3A, toward: Vec3A) -> Vec3A {
    let d = ng.abs().dot(p_error);
    let mut offset = ng * d;
    if toward.dot(ng) < 0.0 {
        offset = -offset;
    }
    let po = p + offset;
    // Round away from p so the offset survives the addition.
    let bump = |x: f32, o: f32| {
        if o > 0.0 {
            next_up(x)
        } else if o < 0.0 {
            next_down(x)
        } else {
            x
        }
    };
    Vec3A::new(bump(po.x, offset.x), bump(po.y, offset.y), bump(po.z, offset.z))
}

/// The next representable f32 above `x`.
#[inline]
pub fn next_up(x: f32) -> f32 {
    if x.is_infinite() && x > 0.0 {
        return x;
    }
    let x = if x == -0.0 { 0.0 } else { x };
    let bits = x.to_bits();
    f32::from_bits(if x >= 0.0 { bits + 1 } else { bits - 1 })
}

/// The next representable f32 below `x`.
#[inline]
pub fn next_down(x: f32) -> f32 {
    -next_up(-x)
}

/// γ(n) = nε/(1 − nε): the floating-point error bound factor of n operations (pbrt §6.8).
#[inline]
pub const fn gamma(n: i32) -> f32 {
    let e = f32::EPSILON * 0.5;
    (n as f32 * e) / (1.0 - n as f32 * e)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_kind_s_index_is_its_place_in_all() {
        for (i, k) in RayKind::ALL.into_iter().enumerate() {
            assert_eq!(k.index(), i, "{k:?}");
        }
    }

    #[test]
    fn offset_moves_to_the_requested_side_and_is_nonzero() {
        let p = Vec3A::new(1e5, 0.0, 0.0);
        let err = Vec3A::splat(gamma(7)) * p.abs();
        let n = Vec3A::X;
        let up = offset_origin(p, err, n, Vec3A::X);
        let down = offset_origin(p, err, n, -Vec3A::X);
        assert!(up.x > p.x && down.x < p.x);
        assert!(next_up(1.0) > 1.0 && next_down(1.0) < 1.0 && next_up(-0.0) > 0.0);
    }
}
