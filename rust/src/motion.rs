//! Transform motion blur: an instance's object-to-render transform sampled at times within the
//! camera's shutter, interpolated for each ray's time.
//!
//! Keys are decomposed into scale, rotation and translation, which are interpolated separately
//! (lerp, slerp, lerp), so a spinning object turns rather than shrinking through the middle as
//! an element-wise matrix blend would. A key with shear cannot be decomposed; such a transform
//! falls back to the element-wise blend, which is exact at the keys.

use glam::{Mat4, Quat, Vec3, Vec3A};

use crate::bounds::Bounds3;

/// One key: the transform at `time` (fraction of the shutter interval, 0 = open, 1 = close).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionKey {
    pub time: f32,
    pub render_from_object: Mat4,
}

/// A moving transform: two or more keys in increasing time. Times outside the keys hold the
/// nearest key.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionTransform {
    keys: Vec<MotionKey>,
    /// Per key: (scale, rotation, translation), or `None` for all keys when one has shear.
    parts: Option<Vec<(Vec3, Quat, Vec3)>>,
}

/// Bound samples per key interval when bounding the swept object; the rest is covered by the
/// rotation's chord allowance (see [`MotionTransform::swept_bounds`]).
const BOUND_STEPS: usize = 32;

impl MotionTransform {
    /// The transform through `keys`; `None` unless there are at least two keys with distinct
    /// transforms, finite values and strictly increasing times (a single key is no motion).
    pub fn new(mut keys: Vec<MotionKey>) -> Option<Self> {
        keys.retain(|k| k.time.is_finite() && k.render_from_object.is_finite());
        keys.sort_by(|a, b| a.time.total_cmp(&b.time));
        keys.dedup_by(|b, a| a.time == b.time);
        if keys.len() < 2 || keys.windows(2).all(|w| w[0].render_from_object == w[1].render_from_object) {
            return None;
        }
        let parts: Option<Vec<_>> = keys
            .iter()
            .map(|k| {
                let (s, r, t) = k.render_from_object.to_scale_rotation_translation();
                // Accept the decomposition only if it rebuilds the key: shear does not.
                let back = Mat4::from_scale_rotation_translation(s, r, t);
                let err = (back - k.render_from_object).abs_diff_eq(Mat4::ZERO, 1e-4 * (1.0 + t.abs().max_element()));
                err.then_some((s, r, t))
            })
            .collect();
        Some(MotionTransform { keys, parts })
    }

    /// The keys, in time order.
    pub fn keys(&self) -> &[MotionKey] {
        &self.keys
    }

    /// The object-to-render transform at shutter time `t`.
    pub fn at(&self, t: f32) -> Mat4 {
        let k = &self.keys;
        if !(t > k[0].time) {
            return k[0].render_from_object;
        }
        let last = k.len() - 1;
        if t >= k[last].time {
            return k[last].render_from_object;
        }
        let i = k.partition_point(|key| key.time <= t) - 1;
        let f = (t - k[i].time) / (k[i + 1].time - k[i].time);
        match &self.parts {
            Some(p) => {
                let (s0, r0, t0) = p[i];
                let (s1, r1, t1) = p[i + 1];
                // Take the short way round: q and −q are the same rotation.
                let r1 = if r0.dot(r1) < 0.0 { -r1 } else { r1 };
                Mat4::from_scale_rotation_translation(s0.lerp(s1, f), r0.slerp(r1, f).normalize(), t0.lerp(t1, f))
            }
            None => {
                let a = k[i].render_from_object;
                let b = k[i + 1].render_from_object;
                a * (1.0 - f) + b * f
            }
        }
    }

    /// Render-space bounds of `object` over the whole shutter: the union of its transformed
    /// bounds at [`BOUND_STEPS`] times per key interval, grown by the most a point can stray
    /// from the chord between two of those times (r·Δθ²/8 for a rotation of Δθ radians at
    /// radius r, plus the same for a changing scale), so the bounds are conservative.
    pub fn swept_bounds(&self, object: &Bounds3) -> Bounds3 {
        let mut out = Bounds3::EMPTY;
        let corners = (0..8).map(|c| {
            Vec3A::new(
                if c & 1 == 0 { object.min.x } else { object.max.x },
                if c & 2 == 0 { object.min.y } else { object.max.y },
                if c & 4 == 0 { object.min.z } else { object.max.z },
            )
        });
        let radius = corners.map(|c| c.length()).fold(0.0f32, f32::max);
        for w in self.keys.windows(2) {
            let (a, b) = (w[0], w[1]);
            let (sa, ra, _) = a.render_from_object.to_scale_rotation_translation();
            let (sb, rb, _) = b.render_from_object.to_scale_rotation_translation();
            let angle = ra.angle_between(rb) / BOUND_STEPS as f32;
            let scale = sa.max_element().max(sb.max_element());
            let slack = radius * scale * (angle * angle / 8.0) + radius * (sb - sa).abs().max_element() / BOUND_STEPS as f32;
            for s in 0..=BOUND_STEPS {
                let t = a.time + (b.time - a.time) * s as f32 / BOUND_STEPS as f32;
                out = out.union(&object.transformed(&self.at(t)));
            }
            out = out.expanded(slack);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(time: f32, m: Mat4) -> MotionKey {
        MotionKey { time, render_from_object: m }
    }

    #[test]
    fn static_or_single_key_is_no_motion() {
        assert!(MotionTransform::new(vec![key(0.0, Mat4::IDENTITY)]).is_none());
        assert!(MotionTransform::new(vec![key(0.0, Mat4::IDENTITY), key(1.0, Mat4::IDENTITY)]).is_none());
    }

    #[test]
    fn translation_is_linear_and_keys_are_exact() {
        let a = Mat4::from_translation(Vec3::new(0.0, 0.0, 0.0));
        let b = Mat4::from_translation(Vec3::new(2.0, 0.0, 0.0));
        let m = MotionTransform::new(vec![key(1.0, b), key(0.0, a)]).unwrap();
        assert_eq!(m.at(0.0), a);
        assert_eq!(m.at(1.0), b);
        assert!((m.at(0.25).w_axis.x - 0.5).abs() < 1e-6);
        assert_eq!(m.at(-1.0), a);
        assert_eq!(m.at(2.0), b);
    }

    /// A quarter turn interpolates as a rotation: a point at radius 1 stays at radius 1 halfway
    /// (an element-wise blend would put it at √½).
    #[test]
    fn rotation_keeps_radius() {
        let a = Mat4::IDENTITY;
        let b = Mat4::from_rotation_z(std::f32::consts::FRAC_PI_2);
        let m = MotionTransform::new(vec![key(0.0, a), key(1.0, b)]).unwrap();
        let p = m.at(0.5).transform_point3(Vec3::X);
        assert!((p.length() - 1.0).abs() < 1e-5, "{p}");
        assert!((p.x - p.y).abs() < 1e-5);
    }

    /// Every point of the object at any time lies inside the swept bounds.
    #[test]
    fn swept_bounds_contain_the_motion() {
        let a = Mat4::from_translation(Vec3::new(-3.0, 0.0, 0.0));
        let b = Mat4::from_translation(Vec3::new(3.0, 1.0, 0.0)) * Mat4::from_rotation_z(3.0) * Mat4::from_scale(Vec3::splat(2.0));
        let m = MotionTransform::new(vec![key(0.0, a), key(1.0, b)]).unwrap();
        let obj = Bounds3 { min: Vec3A::new(-1.0, -0.5, -0.2), max: Vec3A::new(1.0, 0.5, 0.2) };
        let swept = m.swept_bounds(&obj);
        for i in 0..=997 {
            let t = i as f32 / 997.0;
            for c in 0..8 {
                let p = Vec3A::new(
                    if c & 1 == 0 { obj.min.x } else { obj.max.x },
                    if c & 2 == 0 { obj.min.y } else { obj.max.y },
                    if c & 4 == 0 { obj.min.z } else { obj.max.z },
                );
                let w = m.at(t).transform_point3a(p);
                assert!(w.cmpge(swept.min - 1e-4).all() && w.cmple(swept.max + 1e-4).all(), "t {t}: {w} outside {swept:?}");
            }
        }
    }

    #[test]
    fn sheared_keys_fall_back_to_blending_and_stay_exact_at_keys() {
        let shear = Mat4::from_cols_array(&[1.0, 0.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        let m = MotionTransform::new(vec![key(0.0, Mat4::IDENTITY), key(1.0, shear)]).unwrap();
        assert!(m.at(1.0).abs_diff_eq(shear, 1e-6));
        assert!(m.at(0.5).is_finite());
    }
}
