//! Magnified views stay exact: subpatches split on demand when rays need more than 16×16 quads
//! (the paper's §5.1), so a narrow-field camera sees a sphere's silhouette within half a pixel
//! of the true surface. An analytic sphere stands in for a limit surface.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::bounds::Bounds3;
use mipray::patch::{LimitSurface, PatchKind, PatchParam, SurfacePoint};
use mipray::prelude::*;

/// A sphere of radius `r` as 8 patches: 4 in longitude × 2 in latitude.
struct Sphere {
    r: f32,
}

impl LimitSurface for Sphere {
    fn patch_count(&self) -> usize {
        8
    }
    fn patch_param(&self, patch: usize) -> PatchParam {
        PatchParam { base_face: patch as u32, ptex_face: patch as u32, u0: 0.0, v0: 0.0, size: 1.0, depth: 0, boundary_mask: 0, transition_mask: 0, kind: PatchKind::Other }
    }
    fn patch_bounds(&self, _patch: usize) -> Bounds3 {
        Bounds3 { min: Vec3A::splat(-self.r), max: Vec3A::splat(self.r) }
    }
    fn evaluate(&self, patch: usize, u: f32, v: f32) -> SurfacePoint {
        let phi = (patch % 4) as f32 * PI / 2.0 + u * PI / 2.0;
        let theta = (patch / 4) as f32 * PI / 2.0 + v * PI / 2.0;
        let p = Vec3A::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()) * self.r;
        let dpdu = Vec3A::new(-theta.sin() * phi.sin(), theta.sin() * phi.cos(), 0.0) * self.r * PI / 2.0;
        let dpdv = Vec3A::new(theta.cos() * phi.cos(), theta.cos() * phi.sin(), -theta.sin()) * self.r * PI / 2.0;
        SurfacePoint { p, dpdu, dpdv, ..Default::default() }
    }
    fn control_face_count(&self) -> usize {
        8
    }
}

#[test]
fn magnified_silhouette_is_within_half_a_pixel_of_the_true_sphere() {
    let r = 1.0;
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/sphere", Arc::new(Sphere { r })));
    scene.add_instance(m, Mat4::IDENTITY);
    scene.lights.push(Light::distant("/sun", Vec3A::new(0.0, -1.0, -1.0), Vec3A::ONE));
    // Look along −y at the silhouette point (1, 0, 0.3) from 10 units away with a 5000 mm lens on
    // a 1 mm back: the view is 0.002 units wide, 0.0001 per pixel at 20 pixels.
    let target = Vec3::new((1.0f32 - 0.09).sqrt(), 0.0, 0.3);
    let eye = target + Vec3::new(0.0, 10.0, 0.0);
    scene.camera = Camera {
        render_from_camera: Camera::look_at(eye, target, Vec3::Z),
        focal_length: 5000.0,
        horizontal_aperture: 1.0,
        vertical_aperture: 1.0,
        clipping_range: (0.1, 100.0),
        ..Default::default()
    };
    let (w, h) = (20, 20);
    let opts = RenderOptions { width: w, height: h, aovs: vec!["alpha".into(), "tessRate".into()], ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let pixel = 0.002 / w as f32 * 10.0 / 10.0;
    let (mut checked, mut inside) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let ray = scene.camera.generate_ray(x as f32 + 0.5, y as f32 + 0.5, w, h);
            // Distance of the ray's closest approach to the centre, against the radius.
            let oc = ray.o;
            let tc = -oc.dot(ray.d);
            let miss_by = (oc + ray.d * tc).length() - r;
            if miss_by.abs() < 0.5 * pixel {
                continue;
            }
            checked += 1;
            let hit = out.film.pixel("alpha", x, y)[0] > 0.5;
            inside += hit as i32;
            assert_eq!(hit, miss_by < 0.0, "pixel ({x}, {y}) misses the sphere by {miss_by} (pixel {pixel})");
        }
    }
    assert!(checked > 300 && inside > 50 && inside < checked - 50, "{checked} {inside}");
    let max_rate = out.film.aov("tessRate").unwrap().data.iter().cloned().fold(0.0, f32::max);
    assert!(max_rate >= 256.0, "the view needs split subpatches, got rate {max_rate}");
    assert!(out.stats["render"]["finer_than_fine_tests"].as_u64().unwrap() > 0);
}
