//! The camera: USD's `UsdGeom.Camera` model (perspective and orthographic, apertures and
//! offsets, clipping range) turned into rays with exact differentials (Igehy 1999).
//!
//! Conventions, as USD's `GfCamera`: the camera looks down its local −Z with +Y up; apertures and
//! focal length share a unit for perspective cameras (their ratio is what matters); for
//! orthographic cameras apertures are in tenths of a scene unit. When the image aspect differs
//! from the aperture's, the window is enlarged to fit (Hydra's `CameraUtilFit`). Pixel (0, 0) is
//! the top-left corner of the image; pixel centres are at half-integers.

use glam::{Mat4, Vec3A};

use crate::differential::RayDifferential;
use crate::ray::{Ray, RayKind};

/// `GfCamera::APERTURE_UNIT`: orthographic apertures are in tenths of a scene unit.
pub const APERTURE_UNIT: f32 = 0.1;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Projection {
    Perspective,
    Orthographic,
}

/// A camera as USD describes it. Lengths in USD's units (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Prim path, for messages and the effects' reasons (empty for a camera no prim made).
    pub name: String,
    /// Camera-to-render (world) transform, column-vector convention.
    pub render_from_camera: Mat4,
    pub projection: Projection,
    pub focal_length: f32,
    pub horizontal_aperture: f32,
    pub vertical_aperture: f32,
    pub horizontal_aperture_offset: f32,
    pub vertical_aperture_offset: f32,
    /// Near and far clipping distances along the view axis, scene units.
    pub clipping_range: (f32, f32),
    /// 0 disables depth of field.
    pub f_stop: f32,
    pub focus_distance: f32,
}

impl Default for Camera {
    /// USD's defaults: a 50 mm lens on a 35 mm academy aperture at the origin.
    fn default() -> Self {
        Camera {
            name: String::new(),
            render_from_camera: Mat4::IDENTITY,
            projection: Projection::Perspective,
            focal_length: 50.0,
            horizontal_aperture: 20.955,
            vertical_aperture: 15.2908,
            horizontal_aperture_offset: 0.0,
            vertical_aperture_offset: 0.0,
            clipping_range: (1.0, 1.0e6),
            f_stop: 0.0,
            focus_distance: 0.0,
        }
    }
}

/// The image-plane window in camera space: at z = −1 for perspective, at z = 0 in scene units
/// for orthographic.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Window {
    x0: f32,
    x1: f32,
    y0: f32,
    y1: f32,
}

impl Camera {
    /// A perspective camera with USD's default film back.
    pub fn perspective(render_from_camera: Mat4, focal_length: f32) -> Self {
        Camera { render_from_camera, focal_length, ..Default::default() }
    }

    /// An orthographic camera; apertures in tenths of a scene unit, as USD stores them.
    pub fn orthographic(render_from_camera: Mat4, horizontal_aperture: f32, vertical_aperture: f32) -> Self {
        Camera {
            render_from_camera,
            projection: Projection::Orthographic,
            horizontal_aperture,
            vertical_aperture,
            clipping_range: (0.0, 1.0e6),
            ..Default::default()
        }
    }

    /// A camera-to-render transform at `eye` looking at `target` with `up` roughly up (the
    /// camera's −Z toward the target, +Y toward `up`).
    pub fn look_at(eye: glam::Vec3, target: glam::Vec3, up: glam::Vec3) -> Mat4 {
        let z = (eye - target).normalize_or(glam::Vec3::Z);
        let x = up.cross(z).normalize_or(glam::Vec3::X);
        let y = z.cross(x);
        Mat4::from_cols(x.extend(0.0), y.extend(0.0), z.extend(0.0), eye.extend(1.0))
    }

    /// Image height for a width, from the aperture aspect ratio (as usdrecord computes it).
    pub fn height_for_width(&self, width: usize) -> usize {
        let aspect = self.vertical_aperture / self.horizontal_aperture.max(f32::MIN_POSITIVE);
        ((width as f32 * aspect).round() as usize).max(1)
    }

    /// Checks the values a renderer cannot use.
    ///
    /// # Errors
    /// A one-line description of the first bad value.
    pub fn validate(&self) -> Result<(), String> {
        let vals = [
            ("focalLength", self.focal_length),
            ("horizontalAperture", self.horizontal_aperture),
            ("verticalAperture", self.vertical_aperture),
        ];
        for (name, v) in vals {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} = {v} must be positive and finite"));
            }
        }
        let (n, f) = self.clipping_range;
        if !(n.is_finite() && n >= 0.0 && f > n) {
            return Err(format!("clippingRange ({n}, {f}) must satisfy 0 <= near < far"));
        }
        if !self.render_from_camera.is_finite() {
            return Err("transform is not finite".into());
        }
        Ok(())
    }

    fn window(&self, width: usize, height: usize) -> Window {
        let (mut ha, mut va) = (self.horizontal_aperture, self.vertical_aperture);
        let image_aspect = width as f32 / height.max(1) as f32;
        if image_aspect > ha / va {
            ha = va * image_aspect;
        } else {
            va = ha / image_aspect;
        }
        let scale = match self.projection {
            Projection::Perspective => 1.0 / self.focal_length,
            Projection::Orthographic => APERTURE_UNIT,
        };
        let (cx, cy) = (self.horizontal_aperture_offset, self.vertical_aperture_offset);
        Window { x0: (cx - ha * 0.5) * scale, x1: (cx + ha * 0.5) * scale, y0: (cy - va * 0.5) * scale, y1: (cy + va * 0.5) * scale }
    }

    /// The camera ray through continuous pixel position (`px`, `py`) of a `width`×`height`
    /// image, with its exact differentials for one-pixel steps in x and y. Render space;
    /// `t_min`/`t_max` follow the clipping range along the view axis.
    pub fn generate_ray(&self, px: f32, py: f32, width: usize, height: usize) -> Ray {
        let w = self.window(width, height);
        let sx = (w.x1 - w.x0) / width as f32;
        let sy = (w.y1 - w.y0) / height as f32;
        let x = w.x0 + px * sx;
        let y = w.y1 - py * sy;
        let m = &self.render_from_camera;
        let (near, far) = self.clipping_range;
        match self.projection {
            Projection::Perspective => {
                let o = m.transform_point3a(Vec3A::ZERO);
                let d_cam = Vec3A::new(x, y, -1.0);
                let d = m.transform_vector3a(d_cam);
                let ddx = m.transform_vector3a(Vec3A::new(sx, 0.0, 0.0));
                let ddy = m.transform_vector3a(Vec3A::new(0.0, -sy, 0.0));
                let len = d.length();
                // The clipping range is camera-space depth: the camera-space ray s·(x, y, −1) is
                // at depth s, and s camera units are s·|d| render units along it (any scale in
                // the camera's transform included).
                Ray {
                    o,
                    d: d / len,
                    t_min: near * len,
                    t_max: far * len,
                    diff: RayDifferential::from_pinhole(d, ddx, ddy),
                    kind: RayKind::Camera,
                    time: 0.0,
                }
            }
            Projection::Orthographic => {
                let o = m.transform_point3a(Vec3A::new(x, y, 0.0));
                let d = m.transform_vector3a(Vec3A::NEG_Z);
                let len = d.length();
                let dpdx = m.transform_vector3a(Vec3A::new(sx, 0.0, 0.0));
                let dpdy = m.transform_vector3a(Vec3A::new(0.0, -sy, 0.0));
                Ray {
                    o,
                    d: d / len,
                    t_min: near * len,
                    t_max: far * len,
                    diff: RayDifferential::from_orthographic(dpdx, dpdy),
                    kind: RayKind::Camera,
                    time: 0.0,
                }
            }
        }
    }

    /// True when the camera asks for depth of field: an f-stop and a focus distance, both
    /// positive, on a perspective camera.
    pub fn has_depth_of_field(&self) -> bool {
        self.projection == Projection::Perspective
            && self.f_stop > 0.0
            && self.focus_distance > 0.0
            && self.f_stop.is_finite()
            && self.focus_distance.is_finite()
    }

    /// Lens radius in camera-space units: focal length (tenths of a scene unit, as USD stores
    /// it) over twice the f-number.
    pub fn lens_radius(&self) -> f32 {
        if self.has_depth_of_field() {
            self.focal_length * APERTURE_UNIT / (2.0 * self.f_stop)
        } else {
            0.0
        }
    }

    /// As [`Camera::generate_ray`], through the lens point `lens` (uniform in [0, 1)²) when the
    /// camera has depth of field: a thin lens focused `focus_distance` along the view axis.
    /// The differentials are those of the rays from the same lens point through the
    /// neighbouring pixels' points on the focal plane (pbrt's thin-lens differentials).
    pub fn generate_ray_lens(&self, px: f32, py: f32, width: usize, height: usize, lens: (f32, f32)) -> Ray {
        let r = self.lens_radius();
        if r <= 0.0 {
            return self.generate_ray(px, py, width, height);
        }
        let w = self.window(width, height);
        let sx = (w.x1 - w.x0) / width as f32;
        let sy = (w.y1 - w.y0) / height as f32;
        let (x, y) = (w.x0 + px * sx, w.y1 - py * sy);
        let fd = self.focus_distance;
        let (lx, ly) = concentric_disk(lens.0, lens.1);
        let lens_p = Vec3A::new(lx * r, ly * r, 0.0);
        let focus_p = Vec3A::new(x, y, -1.0) * fd;
        let m = &self.render_from_camera;
        let d = m.transform_vector3a(focus_p - lens_p);
        let ddx = m.transform_vector3a(Vec3A::new(sx * fd, 0.0, 0.0));
        let ddy = m.transform_vector3a(Vec3A::new(0.0, -sy * fd, 0.0));
        let len = d.length();
        // The camera-space ray lens + s·(focus − lens) is at depth s·fd; render distance s·|d|.
        let (near, far) = self.clipping_range;
        Ray {
            o: m.transform_point3a(lens_p),
            d: d / len,
            t_min: near / fd * len,
            t_max: far / fd * len,
            diff: RayDifferential::from_pinhole(d, ddx, ddy),
            kind: RayKind::Camera,
            time: 0.0,
        }
    }

    /// Camera-space depth (distance along the view axis, camera-space units: scene units for an
    /// unscaled camera) of a render-space point: −z of [`Camera::camera_from_render`].
    pub fn depth(&self, p: Vec3A) -> f32 {
        -self.camera_from_render(p).z
    }

    /// A render-space point in camera space (USD's: +x right, +y up, looking down −z), in
    /// camera-space units.
    pub fn camera_from_render(&self, p: Vec3A) -> Vec3A {
        self.render_from_camera.inverse().transform_point3a(p)
    }

    /// The continuous pixel position a render-space point projects to, or `None` behind a
    /// perspective camera. Inverse of [`Camera::generate_ray`].
    pub fn project(&self, p: Vec3A, width: usize, height: usize) -> Option<(f32, f32)> {
        let c = self.render_from_camera.inverse().transform_point3a(p);
        let (x, y) = match self.projection {
            Projection::Perspective => {
                if c.z >= 0.0 {
                    return None;
                }
                (c.x / -c.z, c.y / -c.z)
            }
            Projection::Orthographic => (c.x, c.y),
        };
        let w = self.window(width, height);
        Some(((x - w.x0) / (w.x1 - w.x0) * width as f32, (w.y1 - y) / (w.y1 - w.y0) * height as f32))
    }
}

/// Shirley–Chiu concentric mapping of the unit square to the unit disk.
fn concentric_disk(u: f32, v: f32) -> (f32, f32) {
    let (a, b) = (2.0 * u - 1.0, 2.0 * v - 1.0);
    if a == 0.0 && b == 0.0 {
        return (0.0, 0.0);
    }
    let (r, phi) = if a.abs() > b.abs() {
        (a, std::f32::consts::FRAC_PI_4 * (b / a))
    } else {
        (b, std::f32::consts::FRAC_PI_2 - std::f32::consts::FRAC_PI_4 * (a / b))
    };
    (r * phi.cos(), r * phi.sin())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn look_from(z: f32) -> Mat4 {
        Mat4::from_translation(Vec3::new(0.0, 0.0, z))
    }

    #[test]
    fn perspective_point_lands_on_the_expected_pixel() {
        // 50 mm lens, 36×24 aperture, 360×240 image: a point at x = 1.8 on the plane 50 units away
        // sits at 1.8/50 = 36/1000 of the focal length... i.e. 1.8 mm on a 36 mm back = 1/20 of
        // the width right of centre: pixel 180 + 18 = 198.
        let cam = Camera { render_from_camera: look_from(50.0), horizontal_aperture: 36.0, vertical_aperture: 24.0, ..Default::default() };
        let (px, py) = cam.project(Vec3A::new(1.8, -1.2, 0.0), 360, 240).unwrap();
        assert!((px - 198.0).abs() < 1e-3 && (py - 132.0).abs() < 1e-3, "{px} {py}");
        // And the ray through that pixel passes through the point.
        let r = cam.generate_ray(px, py, 360, 240);
        let t = (0.0 - r.o.z) / r.d.z;
        assert!((r.at(t) - Vec3A::new(1.8, -1.2, 0.0)).length() < 1e-4);
    }

    #[test]
    fn aperture_offset_shifts_the_image() {
        let mut cam = Camera {
            render_from_camera: look_from(10.0),
            horizontal_aperture: 20.0,
            vertical_aperture: 20.0,
            focal_length: 10.0,
            ..Default::default()
        };
        let (px0, _) = cam.project(Vec3A::ZERO, 100, 100).unwrap();
        cam.horizontal_aperture_offset = 2.0; // a tenth of the aperture: the image shifts 10 px left
        let (px1, _) = cam.project(Vec3A::ZERO, 100, 100).unwrap();
        assert!((px0 - 50.0).abs() < 1e-4 && (px1 - 40.0).abs() < 1e-4, "{px0} {px1}");
    }

    #[test]
    fn orthographic_apertures_are_tenths_of_scene_units() {
        // 40 tenths = 4 units wide, 100 px: one pixel is 0.04 units.
        let cam = Camera::orthographic(look_from(5.0), 40.0, 40.0);
        let (px, py) = cam.project(Vec3A::new(1.0, 1.0, -3.0), 100, 100).unwrap();
        assert!((px - 75.0).abs() < 1e-3 && (py - 25.0).abs() < 1e-3, "{px} {py}");
        let r = cam.generate_ray(75.0, 25.0, 100, 100);
        assert!((r.o - Vec3A::new(1.0, 1.0, 5.0)).length() < 1e-5);
        assert!((r.d - Vec3A::NEG_Z).length() < 1e-6);
    }

    #[test]
    fn clipping_range_is_along_the_view_axis() {
        let cam = Camera { render_from_camera: look_from(0.0), clipping_range: (2.0, 10.0), ..Default::default() };
        let r = cam.generate_ray(0.0, 0.0, 64, 48);
        let near_pt = r.at(r.t_min);
        let far_pt = r.at(r.t_max);
        assert!((near_pt.z + 2.0).abs() < 1e-4 && (far_pt.z + 10.0).abs() < 1e-3);
    }

    #[test]
    fn thin_lens_rays_meet_at_the_focus_distance_and_spread_elsewhere() {
        let mut cam = Camera { render_from_camera: look_from(0.0), f_stop: 2.0, focus_distance: 10.0, ..Default::default() };
        assert!(cam.has_depth_of_field());
        // 50 (tenths) focal length at f/2: a lens of radius 1.25 scene units.
        assert!((cam.lens_radius() - 1.25).abs() < 1e-6);
        let pin = cam.generate_ray(40.0, 30.0, 64, 48);
        let focus = pin.at(10.0 / -pin.d.z);
        for lens in [(0.1, 0.2), (0.9, 0.5), (0.5, 0.95)] {
            let r = cam.generate_ray_lens(40.0, 30.0, 64, 48, lens);
            assert!(r.o.length() > 0.01, "the origin moves over the lens");
            let t = (focus.z - r.o.z) / r.d.z;
            assert!((r.at(t) - focus).length() < 1e-4, "every lens point sees the same focused point");
            let near = r.at((-2.0 - r.o.z) / r.d.z);
            assert!((near - pin.at(-2.0 / pin.d.z)).length() > 0.05, "out of focus elsewhere");
        }
        cam.f_stop = 0.0;
        assert!(!cam.has_depth_of_field());
        assert_eq!(cam.generate_ray_lens(40.0, 30.0, 64, 48, (0.1, 0.2)).o, Vec3A::ZERO);
    }

    #[test]
    fn fit_policy_keeps_the_whole_aperture_visible() {
        // A square aperture on a 2:1 image: the horizontal window widens, the vertical stays.
        let cam = Camera {
            render_from_camera: look_from(10.0),
            horizontal_aperture: 10.0,
            vertical_aperture: 10.0,
            focal_length: 10.0,
            ..Default::default()
        };
        let (_, top) = cam.project(Vec3A::new(0.0, 5.0, 0.0), 200, 100).unwrap();
        let (right, _) = cam.project(Vec3A::new(10.0, 0.0, 0.0), 200, 100).unwrap();
        assert!(top.abs() < 1e-3 && (right - 200.0).abs() < 1e-3, "{top} {right}");
    }
}
