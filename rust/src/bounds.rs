//! Axis-aligned bounds in `[f32; 3]` form, convertible to obvhs's `Aabb`.

use glam::{Mat4, Vec3A};

/// An axis-aligned box. An empty box has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds3 {
    pub min: Vec3A,
    pub max: Vec3A,
}

impl Default for Bounds3 {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Bounds3 {
    pub const EMPTY: Bounds3 = Bounds3 { min: Vec3A::splat(f32::INFINITY), max: Vec3A::splat(f32::NEG_INFINITY) };

    pub fn from_points<I: IntoIterator<Item = Vec3A>>(pts: I) -> Self {
        let mut b = Self::EMPTY;
        for p in pts {
            b.grow(p);
        }
        b
    }

    #[inline]
    pub fn grow(&mut self, p: Vec3A) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    #[inline]
    pub fn union(&self, o: &Bounds3) -> Bounds3 {
        Bounds3 { min: self.min.min(o.min), max: self.max.max(o.max) }
    }

    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// Grows the box by `d` on every side (world or object units, as the box).
    pub fn expanded(&self, d: f32) -> Bounds3 {
        Bounds3 { min: self.min - Vec3A::splat(d), max: self.max + Vec3A::splat(d) }
    }

    /// True when `p` lies inside or on the box.
    #[inline]
    pub fn contains(&self, p: Vec3A) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    pub fn diagonal(&self) -> Vec3A {
        if self.is_empty() {
            Vec3A::ZERO
        } else {
            self.max - self.min
        }
    }

    pub fn center(&self) -> Vec3A {
        (self.min + self.max) * 0.5
    }

    /// The bounds of this box's eight corners after an affine transform.
    pub fn transformed(&self, m: &Mat4) -> Bounds3 {
        if self.is_empty() {
            return *self;
        }
        let mut b = Bounds3::EMPTY;
        for k in 0..8 {
            let c = Vec3A::new(
                if k & 1 == 0 { self.min.x } else { self.max.x },
                if k & 2 == 0 { self.min.y } else { self.max.y },
                if k & 4 == 0 { self.min.z } else { self.max.z },
            );
            b.grow(m.transform_point3a(c));
        }
        b
    }

    /// Largest absolute coordinate: the scale that floating-point error bounds are relative to.
    pub fn max_abs(&self) -> f32 {
        self.min.abs().max(self.max.abs()).max_element()
    }

    /// True when the box can be traced: not empty and within [`MAX_COORDINATE`] on every axis
    /// (so finite). Anything else is refused before a BVH is built over it (see
    /// [`MAX_COORDINATE`]).
    pub fn is_traceable(&self) -> bool {
        // Finite first: SIMD max does not propagate NaN, so `max_abs` alone could miss one.
        self.min.is_finite() && self.max.is_finite() && !self.is_empty() && self.max_abs() <= MAX_COORDINATE
    }
}

/// The largest coordinate (object or render units) geometry may have. The BVH builder's
/// surface-area costs sum box areas over every node: at 1e12 a node's half area is at most
/// 1.2e25, so a billion nodes stay finite, where beyond about 1e18 a few dozen overflow to Inf
/// and leave the builder no decision. Ray tests multiply coordinates too, and obvhs's compressed
/// nodes quantise them. A 1,000 km scene in micrometres is 1e12.
pub const MAX_COORDINATE: f32 = 1e12;

impl From<Bounds3> for obvhs::aabb::Aabb {
    fn from(b: Bounds3) -> Self {
        obvhs::aabb::Aabb::new(b.min, b.max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transformed_box_contains_transformed_corners() {
        let b = Bounds3 { min: Vec3A::new(-1.0, 0.0, 0.0), max: Vec3A::new(1.0, 2.0, 3.0) };
        let m = Mat4::from_rotation_z(0.7) * Mat4::from_translation(glam::Vec3::new(5.0, 0.0, 0.0));
        let t = b.transformed(&m);
        let c = m.transform_point3a(Vec3A::new(1.0, 2.0, 3.0));
        assert!(c.cmpge(t.min - 1e-5).all() && c.cmple(t.max + 1e-5).all());
        assert!(Bounds3::EMPTY.is_empty());
        assert!(!t.is_empty());
    }

    #[test]
    fn only_finite_boxes_within_the_coordinate_limit_are_traceable() {
        let b = |min: f32, max: f32| Bounds3 { min: Vec3A::splat(min), max: Vec3A::new(max, 1.0, 1.0) };
        assert!(b(-1.0, 1.0).is_traceable() && b(-MAX_COORDINATE, MAX_COORDINATE).is_traceable());
        for bad in [b(0.0, 1e30), b(0.0, f32::INFINITY), b(0.0, f32::NAN), b(f32::NAN, 1.0), Bounds3::EMPTY] {
            assert!(!bad.is_traceable(), "{bad:?}");
        }
    }
}
