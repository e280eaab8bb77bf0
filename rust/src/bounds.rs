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
}

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
}
