//! Instance transforms the tracer can invert. Rays enter an instance through the inverse of its
//! render-from-object transform, so a transform without an accurate inverse would send NaN or
//! Inf rays into the BVH. Animators hide objects by scaling them to zero and flatten them by
//! scaling one axis to zero; USD allows projective matrices and any scale. Here a flattened
//! object keeps a thickness far below any pixel, so it renders as the flat shape it is; one
//! scaled to a line or a point (no area, nothing to see), a projective matrix and scales beyond
//! [`MAX_SCALE`] are refused with the reason, and the caller names the prim.

use glam::{Mat3A, Mat4, Vec3A, Vec4};
use thiserror::Error;

/// The largest stretch, and the inverse of the smallest, a transform may apply. Beyond it
/// object-space coordinates of render-space rays leave [`crate::bounds::MAX_COORDINATE`]
/// for scenes of ordinary size, and their products overflow.
pub const MAX_SCALE: f32 = 1e12;

/// The thickness, relative to its largest scale, given to an object flattened onto a plane
/// (one axis scaled to zero): 1 mm on a 100 m object, never visible, and thick enough that the
/// transform's inverse stays accurate in `f32`.
pub const FLAT_THICKNESS: f32 = 1e-5;

/// Why an instance transform cannot be traced.
#[derive(Debug, Error, Clone, Copy, PartialEq)]
pub enum TransformError {
    #[error("transform is not finite")]
    NotFinite,
    /// USD's 4th matrix column (its perspective terms), expected (0, 0, 0, w ≠ 0).
    #[error("transform is projective (perspective terms {0:?}); only affine transforms can be traced")]
    Projective([f32; 4]),
    /// Scaled to zero on two or three axes: a line or a point, which covers no pixel.
    #[error("transform scales the object to a line or a point (zero scale)")]
    Collapsed,
    /// The largest or the smallest scale, outside `1/MAX_SCALE ..= MAX_SCALE`.
    #[error("transform scales by {0:e}, outside the traceable range 1e-12 to 1e12")]
    Scale(f32),
}

/// `render_from_object` as the tracer should use it: unchanged when it is affine and well
/// conditioned; with the homogeneous `w` divided out; or, for an object flattened onto a plane,
/// with the flattened axis given [`FLAT_THICKNESS`] along the plane's normal.
///
/// # Errors
/// See [`TransformError`].
pub fn traceable(render_from_object: Mat4) -> Result<Mat4, TransformError> {
    let m = render_from_object;
    if !m.is_finite() {
        return Err(TransformError::NotFinite);
    }
    let perspective = m.row(3);
    if perspective.truncate() != glam::Vec3::ZERO || perspective.w == 0.0 {
        return Err(TransformError::Projective(perspective.to_array()));
    }
    // A homogeneous scale w: the same transform as m / w.
    let m = if perspective.w == 1.0 { m } else { m * (1.0 / perspective.w) };
    if !m.is_finite() {
        return Err(TransformError::NotFinite);
    }
    let l = Mat3A::from_mat4(m);
    let cols = [l.x_axis, l.y_axis, l.z_axis];
    // Within √3 of the largest column length, without squares that underflow at 1e-30.
    let largest = cols.iter().map(|c| c.abs().max_element()).fold(0.0, f32::max);
    if !(largest > 0.0) {
        return Err(TransformError::Collapsed);
    }
    if !(1.0 / MAX_SCALE..=MAX_SCALE).contains(&largest) {
        return Err(TransformError::Scale(largest));
    }
    // σ₁σ₂ within a factor √3: the largest parallelogram two of the columns span. Zero means
    // every column lies on one line.
    let (area, image_normal) = largest_cross(&cols);
    if !(area > FLAT_THICKNESS * largest * largest) {
        return Err(TransformError::Collapsed);
    }
    // The thickness the transform leaves along its thinnest direction: σ₃ = det / (σ₁σ₂).
    let thickness = l.determinant().abs() / area;
    let l = if thickness < FLAT_THICKNESS * largest {
        // Flattened onto a plane: give the object-space direction it flattens (the rows' common
        // normal, where l·v ≈ 0) a thickness along the image plane's normal.
        let rows = [l.row(0), l.row(1), l.row(2)];
        let (_, flattened) = largest_cross(&rows);
        let v = flattened.normalize();
        let u = image_normal.normalize();
        let add = FLAT_THICKNESS * largest;
        Mat3A::from_cols(l.x_axis + u * (add * v.x), l.y_axis + u * (add * v.y), l.z_axis + u * (add * v.z))
    } else {
        l
    };
    let smallest = l.determinant().abs() / largest_cross(&[l.x_axis, l.y_axis, l.z_axis]).0;
    if !(smallest >= 1.0 / MAX_SCALE) {
        return Err(TransformError::Scale(smallest));
    }
    Ok(Mat4::from_cols(Vec4::from((l.x_axis, 0.0)), Vec4::from((l.y_axis, 0.0)), Vec4::from((l.z_axis, 0.0)), m.w_axis))
}

/// The longest cross product of two of `v` (its length and the vector).
fn largest_cross(v: &[Vec3A; 3]) -> (f32, Vec3A) {
    [v[0].cross(v[1]), v[1].cross(v[2]), v[2].cross(v[0])].into_iter().map(|c| (c.length(), c)).fold((0.0, Vec3A::ZERO), |a, b| {
        if b.0 > a.0 {
            b
        } else {
            a
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn ordinary_transforms_are_kept_exactly() {
        let m = Mat4::from_scale_rotation_translation(Vec3::new(2.0, 0.5, 3.0), glam::Quat::from_rotation_y(0.7), Vec3::X);
        assert_eq!(traceable(m), Ok(m));
        assert_eq!(traceable(Mat4::IDENTITY), Ok(Mat4::IDENTITY));
        // A very thin but not flat object keeps its own thickness.
        let thin = Mat4::from_scale(Vec3::new(1.0, 1.0, 1e-4));
        assert_eq!(traceable(thin), Ok(thin));
    }

    #[test]
    fn an_object_flattened_by_a_rotated_parent_keeps_its_plane() {
        // A child rotated 30° about x under a parent scaled to zero along z: the columns are
        // all non-zero but coplanar (the z = 0 plane).
        let m = Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0))
            * Mat4::from_scale(Vec3::new(2.0, 2.0, 0.0))
            * Mat4::from_rotation_x(30f32.to_radians());
        let t = traceable(m).unwrap();
        let inv = t.inverse();
        assert!(inv.is_finite());
        // Points map where the flat transform puts them, to within the added thickness…
        for p in [Vec3::new(0.3, -0.2, 0.9), Vec3::new(-1.0, 1.0, 1.0)] {
            let (a, b) = (m.transform_point3(p), t.transform_point3(p));
            assert!((a - b).length() <= 2.0 * FLAT_THICKNESS * 2.0 * p.length(), "{a} {b}");
        }
        // …and the thickness is along the plane's normal, z.
        let up = t.transform_vector3(Mat4::from_rotation_x(30f32.to_radians()).inverse().transform_vector3(Vec3::Z));
        assert!(up.normalize().z > 0.999, "{up}");
    }

    #[test]
    fn degenerate_transforms_are_refused_with_the_reason() {
        assert_eq!(traceable(Mat4::from_scale(Vec3::ZERO)), Err(TransformError::Collapsed));
        assert_eq!(traceable(Mat4::from_scale(Vec3::new(1.0, 0.0, 0.0))), Err(TransformError::Collapsed));
        assert!(matches!(traceable(Mat4::from_scale(Vec3::splat(1e-30))), Err(TransformError::Scale(_))));
        assert!(matches!(traceable(Mat4::from_scale(Vec3::splat(1e20))), Err(TransformError::Scale(_))));
        let mut projective = Mat4::IDENTITY;
        projective.x_axis.w = 0.5;
        assert!(matches!(traceable(projective), Err(TransformError::Projective(_))));
        let mut nan = Mat4::IDENTITY;
        nan.w_axis.x = f32::NAN;
        assert_eq!(traceable(nan), Err(TransformError::NotFinite));
    }

    #[test]
    fn a_homogeneous_w_is_divided_out() {
        let mut m = Mat4::from_translation(Vec3::new(2.0, 4.0, 6.0));
        m.w_axis.w = 2.0;
        let t = traceable(m).unwrap();
        assert_eq!(t.transform_point3(Vec3::ZERO), Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(t.transform_point3(Vec3::X), Vec3::new(1.5, 2.0, 3.0));
    }
}
