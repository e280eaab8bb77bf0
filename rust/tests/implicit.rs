//! Implicit gprims and points against closed-form answers computed here in f64, independently
//! of `mipray::implicit`: silhouettes and depths per pixel, normals, the apex of a cone, the caps
//! of a capsule, axis variants, ray differentials against real neighbour rays, instancing,
//! motion blur and a points cloud.

use std::sync::Arc;

use glam::{DVec3, Mat4, Quat, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::differential::UvDifferentials;
use mipray::geometry_cache::CacheConfig;
use mipray::implicit::{Axis, ImplicitSurface, PointsSurface, Shape};
use mipray::integrator::surface::{normal_differentials, shading_point};
use mipray::material::Material;
use mipray::motion::{MotionKey, MotionTransform};
use mipray::prelude::*;
use mipray::trace::{TraceCounters, Tracer};

mod common;

use common::{assert_every_integrator_lights_it_exactly, d, grey_under_the_sun, lit};

fn implicit(scene: &mut Scene, name: &str, shape: Shape) -> usize {
    scene.add_mesh(Mesh::new(name, Arc::new(ImplicitSurface::new(shape).unwrap())))
}

/// The nearest root t > 0 of |o + t d − c|² = r² in f64, or `None`.
fn sphere_t(o: DVec3, dir: DVec3, c: DVec3, r: f64) -> Option<f64> {
    let f = o - c;
    let (a, b, cc) = (dir.dot(dir), f.dot(dir), f.dot(f) - r * r);
    let disc = b * b - a * cc;
    if disc < 0.0 {
        return None;
    }
    [(-b - disc.sqrt()) / a, (-b + disc.sqrt()) / a].into_iter().find(|&t| t > 0.0)
}

/// Every pixel of `out`'s depth and normal AOVs against `truth(o, d) -> Option<(t, normal)>`
/// for the pixel centre's camera ray. A pixel is left out where the truth itself is ambiguous
/// at rounding's scale: when rays moved 1e-5 of the origin's distance across the ray disagree
/// on hit or miss or on the normal (a silhouette or a piece's edge through the pixel centre, a
/// cone's apex). Returns how many pixels were hits.
fn check_pixels(scene: &Scene, out: &RenderOutput, w: usize, h: usize, truth: impl Fn(DVec3, DVec3) -> Option<(f64, DVec3)>) -> usize {
    let mut hits = 0;
    for y in 0..h {
        for x in 0..w {
            let ray = scene.camera.generate_ray(x as f32 + 0.5, y as f32 + 0.5, w, h);
            let (o, dir) = (d(ray.o), d(ray.d));
            let want = truth(o, dir);
            let e1 = dir.any_orthonormal_vector();
            let e2 = dir.normalize().cross(e1);
            let eps = 1e-5 * o.length().max(1e-6);
            let ambiguous = [e1, -e1, e2, -e2].iter().any(|e| match (want, truth(o + *e * eps, dir)) {
                (None, None) => false,
                (Some((_, n0)), Some((_, n1))) => (n0 - n1).length() > 1e-2,
                _ => true,
            });
            if ambiguous {
                continue;
            }
            let depth = out.film.pixel("depth", x, y)[0];
            let normal = out.film.pixel("normal", x, y);
            match want {
                None => assert_eq!(out.film.pixel("alpha", x, y)[0], 0.0, "pixel ({x}, {y}) should miss, depth {depth}"),
                Some((t, n)) => {
                    hits += 1;
                    let p = d(ray.o) + t * d(ray.d);
                    let want_depth = f64::from(scene.camera.depth(Vec3A::new(p.x as f32, p.y as f32, p.z as f32)));
                    // f32 rays through f32 instance transforms: a few ulps of the depth, where
                    // a tessellation's chord error would be ~1e-3.
                    assert!(
                        (f64::from(depth) - want_depth).abs() <= 1e-5 * want_depth.abs().max(1.0),
                        "pixel ({x}, {y}): depth {depth} vs closed form {want_depth}"
                    );
                    // The normal faces the camera; half-float AOV storage rounds it to ~1e-3.
                    let n = if n.dot(d(ray.d)) > 0.0 { -n } else { n };
                    let got = DVec3::new(f64::from(normal[0]), f64::from(normal[1]), f64::from(normal[2]));
                    assert!((got - n).length() < 2e-3, "pixel ({x}, {y}): normal {got} vs analytic {n}");
                }
            }
        }
    }
    hits
}

fn aovs(w: usize, h: usize) -> RenderOptions {
    RenderOptions { width: w, height: h, aovs: vec![Aov::Color, Aov::Depth, Aov::Normal, Aov::Alpha], ..Default::default() }
}

#[test]
fn a_spheres_silhouette_depth_and_normals_are_exact_per_pixel() {
    // Scaled and moved by its instance: radius 1.5 · 0.8 about (0.3, −0.2, 0.1).
    let (c, r) = (DVec3::new(0.3, -0.2, 0.1), 1.5 * 0.8);
    let mut scene = Scene::default();
    let m = implicit(&mut scene, "/sphere", Shape::Sphere { radius: 1.5 });
    scene.add_instance(m, Mat4::from_scale_rotation_translation(Vec3::splat(0.8), Quat::from_rotation_y(0.7), Vec3::new(0.3, -0.2, 0.1)));
    let scene = lit(scene, Camera::perspective(Camera::look_at(Vec3::new(1.0, 2.0, 6.0), Vec3::ZERO, Vec3::Y), 50.0));
    let (w, h) = (96, 72);
    let out = render(&scene, &aovs(w, h), &NoProgress).unwrap();
    let hits = check_pixels(&scene, &out, w, h, |o, dir| sphere_t(o, dir, c, r).map(|t| (t, (o + t * dir - c) / r)));
    assert!(hits > 500, "{hits} hit pixels");
    for y in 0..h {
        for x in 0..w {
            let c = out.film.pixel("color", x, y);
            assert!(c.iter().all(|v| v.is_finite()), "NaN at ({x}, {y})");
        }
    }
}

#[test]
fn huge_and_tiny_spheres_keep_their_depth_and_have_no_acne() {
    for radius in [1e-4_f32, 1e4] {
        let mut scene = Scene::default();
        let m = implicit(&mut scene, "/s", Shape::Sphere { radius });
        scene.add_instance(m, Mat4::IDENTITY);
        let eye = Vec3::new(0.0, 0.0, 4.0 * radius);
        let scene = lit(scene, Camera::perspective(Camera::look_at(eye, Vec3::ZERO, Vec3::Y), 50.0));
        let mut cam = scene.camera.clone();
        cam.clipping_range = (radius * 0.01, radius * 100.0);
        let scene = Scene { camera: cam, ..scene };
        let (w, h) = (48, 48);
        let out = render(&scene, &aovs(w, h), &NoProgress).unwrap();
        let r = f64::from(radius);
        let hits = check_pixels(&scene, &out, w, h, |o, dir| sphere_t(o, dir, DVec3::ZERO, r).map(|t| (t, (o + t * dir) / r)));
        assert!(hits > 200, "radius {radius}: {hits} hits");
        // Lit side: the light reaches every point facing it (no self-shadowing speckle). The
        // colour of a point facing the light is ρ/π·E·cos > 0 wherever cos > 0.05.
        let light = -Vec3A::new(-0.3, -0.5, -1.0).normalize();
        for y in 0..h {
            for x in 0..w {
                let n = Vec3A::from_slice(out.film.pixel("normal", x, y));
                if out.film.pixel("alpha", x, y)[0] == 1.0 && n.dot(light) > 0.05 {
                    let want = 0.18 / std::f32::consts::PI * 3.0 * n.dot(light);
                    let got = out.film.pixel("color", x, y)[0];
                    assert!((got - want).abs() < 0.02 * want + 2e-3, "radius {radius} ({x}, {y}): {got} vs {want}");
                }
            }
        }
    }
}

/// The hit of a ray with the canonical (spine +z) closed frustum from radius `r0` at −hh to
/// `r1` at +hh (textbook quadratic and cap planes, f64).
fn frustum_truth(o: DVec3, dir: DVec3, r0: f64, r1: f64, hh: f64) -> Option<(f64, DVec3)> {
    let k = (r1 - r0) / (2.0 * hh);
    let rho = |z: f64| r0 + k * (z + hh);
    let mut best: Option<(f64, DVec3)> = None;
    let mut take = |t: f64, n: DVec3| {
        if t > 0.0 && best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, n));
        }
    };
    let (ro, rd) = (rho(o.z), k * dir.z);
    let a = dir.x * dir.x + dir.y * dir.y - rd * rd;
    let b = 2.0 * (o.x * dir.x + o.y * dir.y - ro * rd);
    let c = o.x * o.x + o.y * o.y - ro * ro;
    let disc = b * b - 4.0 * a * c;
    if disc >= 0.0 {
        for t in [(-b - disc.sqrt()) / (2.0 * a), (-b + disc.sqrt()) / (2.0 * a)] {
            let p = o + t * dir;
            if p.z.abs() <= hh && rho(p.z) >= 0.0 {
                take(t, DVec3::new(p.x, p.y, -k * rho(p.z)).normalize());
            }
        }
    }
    for (z, r, n) in [(-hh, r0, DVec3::NEG_Z), (hh, r1, DVec3::Z)] {
        if r > 0.0 {
            let t = (z - o.z) / dir.z;
            let p = o + t * dir;
            let rp = (p.x * p.x + p.y * p.y).sqrt();
            if rp <= r {
                take(t, n);
            }
        }
    }
    best
}

#[test]
fn a_cones_apex_is_exact_to_the_pixel() {
    // Side view straight along −y of a cone (axis Z, apex at z = 1), 0.2 units around the apex
    // at 200 pixels: the silhouette |x| ≤ (1 − z)/2 and depth 5 − √(ρ² − x²) per pixel.
    let mut scene = Scene::default();
    let m = implicit(&mut scene, "/cone", Shape::Cylinder { radius_bottom: 1.0, radius_top: 0.0, height: 2.0, axis: Axis::Z });
    scene.add_instance(m, Mat4::IDENTITY);
    let scene = lit(scene, Camera::orthographic(Camera::look_at(Vec3::new(0.0, 5.0, 0.95), Vec3::new(0.0, 0.0, 0.95), Vec3::Z), 2.0, 2.0));
    let (w, h) = (200, 200);
    let out = render(&scene, &aovs(w, h), &NoProgress).unwrap();
    let hits = check_pixels(&scene, &out, w, h, |o, dir| frustum_truth(o, dir, 1.0, 0.0, 1.0));
    // The window (z from 0.85 to 1.05) holds the triangle's tip: 0.15 × 0.15 / 2 of 0.2 × 0.2.
    assert!((10_000..11_300).contains(&hits), "{hits} of 40000 pixels hit");
}

#[test]
fn cylinders_cones_and_frustums_along_each_axis_are_where_usd_puts_them() {
    // Seen from a corner so the body, the base and (for the frustum) the top cap show.
    for (r0, r1) in [(1.0, 0.0), (0.8, 0.8), (0.5, 1.0)] {
        for axis in [Axis::X, Axis::Y, Axis::Z] {
            let mut scene = Scene::default();
            let m = implicit(&mut scene, "/c", Shape::Cylinder { radius_bottom: r0, radius_top: r1, height: 2.0, axis });
            scene.add_instance(m, Mat4::IDENTITY);
            let eye = match axis {
                Axis::Z => Vec3::new(2.0, 3.0, 3.5),
                Axis::X => Vec3::new(3.5, 2.0, 3.0),
                Axis::Y => Vec3::new(3.0, 3.5, 2.0),
            };
            let scene = lit(scene, Camera::perspective(Camera::look_at(eye, Vec3::ZERO, Vec3::Z), 35.0));
            let (w, h) = (64, 64);
            let out = render(&scene, &aovs(w, h), &NoProgress).unwrap();
            // USD: the spine runs along `axis`; canonical (a, b, c = spine) → object cyclically.
            let to_canonical = |v: DVec3| match axis {
                Axis::Z => v,
                Axis::X => DVec3::new(v.y, v.z, v.x),
                Axis::Y => DVec3::new(v.z, v.x, v.y),
            };
            let to_object = |v: DVec3| match axis {
                Axis::Z => v,
                Axis::X => DVec3::new(v.z, v.x, v.y),
                Axis::Y => DVec3::new(v.y, v.z, v.x),
            };
            let hits = check_pixels(&scene, &out, w, h, |o, dir| {
                frustum_truth(to_canonical(o), to_canonical(dir), f64::from(r0), f64::from(r1), 1.0).map(|(t, n)| (t, to_object(n)))
            });
            assert!(hits > 300, "{r0} {r1} {axis:?}: {hits}");
        }
    }
}

#[test]
fn a_capsules_caps_are_hemispheres_and_a_cubes_faces_are_flat() {
    let mut scene = Scene::default();
    let cap = implicit(&mut scene, "/capsule", Shape::Capsule { radius_bottom: 0.5, radius_top: 0.5, height: 1.0, axis: Axis::Y });
    scene.add_instance(cap, Mat4::from_translation(Vec3::new(-1.2, 0.0, 0.0)));
    let cube = implicit(&mut scene, "/cube", Shape::Cube { size: 1.2 });
    let cube_pose = Mat4::from_rotation_translation(Quat::from_euler(glam::EulerRot::XYZ, 0.4, 0.6, 0.1), Vec3::new(1.2, 0.0, 0.0));
    scene.add_instance(cube, cube_pose);
    let scene = lit(scene, Camera::perspective(Camera::look_at(Vec3::new(0.5, 1.5, 6.0), Vec3::ZERO, Vec3::Y), 35.0));
    let (w, h) = (120, 60);
    let out = render(&scene, &aovs(w, h), &NoProgress).unwrap();
    let cube_inv = cube_pose.as_dmat4().inverse();
    let hits = check_pixels(&scene, &out, w, h, |o, dir| {
        // Capsule (axis Y, centre (−1.2, 0, 0)): the union of a cylinder |y| ≤ 0.5 of radius 0.5
        // and two spheres of radius 0.5 at y = ±0.5.
        let oc = o - DVec3::new(-1.2, 0.0, 0.0);
        let mut best: Option<(f64, DVec3)> = None;
        for cy in [-0.5, 0.5] {
            let c = DVec3::new(0.0, cy, 0.0);
            if let Some(t) = sphere_t(oc, dir, c, 0.5) {
                let p = oc + t * dir;
                // Only the cap's outer half is surface; the inner half is inside the body.
                if (p.y - cy) * cy >= 0.0 && best.is_none_or(|(bt, _)| t < bt) {
                    best = Some((t, (p - c) / 0.5));
                }
            }
        }
        // Body: x² + z² = 0.25 with |y| ≤ 0.5.
        let (a, b, c) = (dir.x * dir.x + dir.z * dir.z, oc.x * dir.x + oc.z * dir.z, oc.x * oc.x + oc.z * oc.z - 0.25);
        if b * b - a * c >= 0.0 {
            let t = (-b - (b * b - a * c).sqrt()) / a;
            let p = oc + t * dir;
            if p.y.abs() <= 0.5 && t > 0.0 && best.is_none_or(|(bt, _)| t < bt) {
                best = Some((t, DVec3::new(p.x, 0.0, p.z) / 0.5));
            }
        }
        // Cube: slab test in the cube's frame (t is preserved by the rigid transform).
        let (co, cd) = (cube_inv.transform_point3(o), cube_inv.transform_vector3(dir));
        let (mut t0, mut t1, mut n0) = (0.0_f64, f64::INFINITY, DVec3::ZERO);
        for k in 0..3 {
            let (lo, hi) = ((-0.6 - co[k]) / cd[k], (0.6 - co[k]) / cd[k]);
            let (near, far) = (lo.min(hi), lo.max(hi));
            if near > t0 {
                t0 = near;
                n0 = DVec3::ZERO;
                n0[k] = -cd[k].signum();
            }
            t1 = t1.min(far);
        }
        if t0 <= t1 && t0 > 0.0 && best.is_none_or(|(bt, _)| t0 < bt) {
            best = Some((t0, cube_pose.as_dmat4().transform_vector3(n0)));
        }
        best
    });
    assert!(hits > 1000, "{hits}");
}

#[test]
fn ray_differentials_match_real_neighbour_rays() {
    // dP/dx, dN/dx and d(st)/dx at a hit, from the analytic derivatives, against the hits of
    // the camera rays one pixel to either side (central differences).
    let shapes = [
        (Shape::Sphere { radius: 1.0 }, Mat4::IDENTITY),
        (Shape::Cylinder { radius_bottom: 1.0, radius_top: 0.4, height: 2.0, axis: Axis::Y }, Mat4::from_rotation_x(0.3)),
        (Shape::Capsule { radius_bottom: 0.6, radius_top: 0.6, height: 1.0, axis: Axis::Z }, Mat4::from_rotation_x(-0.8)),
    ];
    for (shape, pose) in shapes {
        let mut scene = Scene::default();
        let m = implicit(&mut scene, "/s", shape);
        scene.add_instance(m, pose);
        scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.4, 0.7, 5.0), Vec3::ZERO, Vec3::Y), 50.0);
        let tracer = Tracer::new(&scene, CacheConfig::default(), 1.0);
        let mut counters = TraceCounters::default();
        let (w, h) = (800, 800);
        let mut checked = 0;
        for (px, py) in [(400.0, 400.0), (430.0, 380.0), (370.0, 450.0), (455.0, 420.0)] {
            let mut at = |x: f32, y: f32| {
                let ray = scene.camera.generate_ray(x, y, w, h);
                tracer.intersect(&ray, &mut counters).map(|hit| (ray, hit))
            };
            let Some((ray, hit)) = at(px, py) else { continue };
            let (Some((rx1, hx1)), Some((rx0, hx0)), Some((ry1, hy1)), Some((ry0, hy0))) =
                (at(px + 1.0, py), at(px - 1.0, py), at(px, py + 1.0), at(px, py - 1.0))
            else {
                continue;
            };
            if [hx1.patch, hx0.patch, hy1.patch, hy0.patch].iter().any(|&p| p != hit.patch) {
                continue; // the neighbours straddle a seam between pieces
            }
            let sp = shading_point(&tracer, &scene, &ray, &hit);
            let footprint = ray.diff.transfer(ray.d, hit.t, sp.ng);
            let (dndx, dndy) = normal_differentials(&tracer, &scene, &hit, &sp, &footprint);
            let uv = UvDifferentials::from_footprint(footprint.dpdx, footprint.dpdy, sp.dpdu, sp.dpdv);
            for (dpd, dnd, (dud, dvd), (r1, h1), (r0, h0)) in [
                (footprint.dpdx, dndx, (uv.dudx, uv.dvdx), (rx1, hx1), (rx0, hx0)),
                (footprint.dpdy, dndy, (uv.dudy, uv.dvdy), (ry1, hy1), (ry0, hy0)),
            ] {
                let fd_p = (h1.p - h0.p) * 0.5;
                let n1 = shading_point(&tracer, &scene, &r1, &h1).ns;
                let n0 = shading_point(&tracer, &scene, &r0, &h0).ns;
                let fd_n = (n1 - n0) * 0.5;
                let fd_uv = ((h1.u - h0.u) * 0.5, (h1.v - h0.v) * 0.5);
                let rel = |a: Vec3A, b: Vec3A| (a - b).length() / b.length().max(1e-12);
                assert!(rel(dpd, fd_p) < 0.02, "{shape:?} ({px}, {py}): dP {dpd} vs neighbours {fd_p}");
                assert!(rel(dnd, fd_n) < 0.05, "{shape:?} ({px}, {py}): dN {dnd} vs neighbours {fd_n}");
                let uv_len = (fd_uv.0.powi(2) + fd_uv.1.powi(2)).sqrt();
                assert!(
                    ((dud - fd_uv.0).powi(2) + (dvd - fd_uv.1).powi(2)).sqrt() < 0.03 * uv_len,
                    "{shape:?}: d(u, v) ({dud}, {dvd}) vs neighbours {fd_uv:?}"
                );
            }
            checked += 1;
        }
        assert!(checked >= 3, "{shape:?}: only {checked} pixels checked");
    }
}

#[test]
fn instanced_spheres_each_render_at_their_own_place() {
    let mut scene = Scene::default();
    let m = implicit(&mut scene, "/proto", Shape::Sphere { radius: 0.5 });
    let centres = [Vec3::new(-1.2, 0.0, 0.0), Vec3::new(0.0, 0.3, -0.5), Vec3::new(1.2, -0.2, 0.4)];
    for c in centres {
        scene.add_instance(m, Mat4::from_translation(c));
    }
    let scene = lit(scene, Camera::perspective(Camera::look_at(Vec3::new(0.0, 0.5, 5.0), Vec3::ZERO, Vec3::Y), 40.0));
    let (w, h) = (96, 48);
    let mut opts = aovs(w, h);
    opts.aovs.push(Aov::InstanceId);
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let mut seen = [0; 3];
    let hits = check_pixels(&scene, &out, w, h, |o, dir| {
        let mut best: Option<(f64, DVec3)> = None;
        for c in centres {
            let c = d(c.into());
            if let Some(t) = sphere_t(o, dir, c, 0.5) {
                if best.is_none_or(|(bt, _)| t < bt) {
                    best = Some((t, (o + t * dir - c) / 0.5));
                }
            }
        }
        best
    });
    for y in 0..h {
        for x in 0..w {
            let id = out.film.pixel("instanceId", x, y)[0];
            if id >= 0.0 {
                seen[id as usize] += 1;
            }
        }
    }
    assert!(hits > 300 && seen.iter().all(|&n| n > 50), "{hits} hits, per instance {seen:?}");
}

#[test]
fn a_moving_sphere_covers_each_pixel_for_its_share_of_the_shutter() {
    let mut scene = Scene::default();
    let mat = scene.add_material(Material::lambertian("/white", Vec3A::ONE).0);
    let mut mesh = Mesh::new("/ball", Arc::new(ImplicitSurface::new(Shape::Sphere { radius: 0.5 }).unwrap()));
    mesh.material = mat;
    let m = scene.add_mesh(mesh);
    let slide = MotionTransform::new(vec![
        MotionKey { time: 0.0, render_from_object: Mat4::from_translation(Vec3::new(-0.5, 0.0, 0.0)) },
        MotionKey { time: 1.0, render_from_object: Mat4::from_translation(Vec3::new(0.5, 0.0, 0.0)) },
    ])
    .unwrap();
    scene.add_moving_instance(m, slide);
    let scene = lit(scene, Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 40.0, 0.4));
    let out = render(
        &scene,
        &RenderOptions { width: 40, height: 4, samples: 256, aovs: vec![Aov::Color, Aov::Alpha], ..Default::default() },
        &NoProgress,
    )
    .unwrap();
    for x in 0..40 {
        // Pixel rows within 0.02 of the equator: the sphere is 0.5 wide there to 1e-3, so a
        // point at x is covered while the centre (−0.5 → 0.5) is within 0.5: 1 − |x| of the time.
        let xc = -2.0 + 0.1 * (x as f32 + 0.5);
        let expected = (1.0 - xc.abs()).max(0.0);
        for y in 1..3 {
            let got = out.film.pixel("alpha", x, y)[0];
            assert!((got - expected).abs() < 0.04, "pixel ({x}, {y}) (x = {xc}): {got} vs {expected}");
        }
    }
}

#[test]
fn a_points_cloud_renders_every_point_at_its_width() {
    // 400 points of varied widths in a box, against brute force over all spheres.
    let mut state = 7u64;
    let mut next = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 40) as f64) / (1u64 << 24) as f64
    };
    let n = 400;
    let points: Vec<[f32; 3]> =
        (0..n).map(|_| [(next() * 4.0 - 2.0) as f32, (next() * 3.0 - 1.5) as f32, (next() * 2.0 - 1.0) as f32]).collect();
    let widths: Vec<f32> = (0..n).map(|_| (0.05 + next() * 0.25) as f32).collect();
    let mut scene = Scene::default();
    let m = scene.add_mesh(Mesh::new("/points", Arc::new(PointsSurface::new(points.clone(), &widths).unwrap())));
    scene.add_instance(m, Mat4::IDENTITY);
    let scene = lit(scene, Camera::perspective(Camera::look_at(Vec3::new(0.5, 0.5, 6.0), Vec3::ZERO, Vec3::Y), 35.0));
    let (w, h) = (128, 96);
    let mut opts = aovs(w, h);
    opts.aovs.push(Aov::ElementId);
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let spheres: Vec<(DVec3, f64)> = points
        .iter()
        .zip(&widths)
        .map(|(p, w)| (DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])), f64::from(*w) * 0.5))
        .collect();
    let hits = check_pixels(&scene, &out, w, h, |o, dir| {
        let mut best: Option<(f64, DVec3, usize)> = None;
        for (i, &(c, r)) in spheres.iter().enumerate() {
            if let Some(t) = sphere_t(o, dir, c, r) {
                if best.is_none_or(|(bt, _, _)| t < bt) {
                    best = Some((t, (o + t * dir - c) / r, i));
                }
            }
        }
        best.map(|(t, n, _)| (t, n))
    });
    assert!(hits > 1000, "{hits}");
    // The element id is the point's index: the nearest sphere along the pixel's ray.
    let ray = scene.camera.generate_ray(64.5, 48.5, w, h);
    let id = out.film.pixel("elementId", 64, 48)[0];
    if id >= 0.0 {
        let (c, r) = spheres[id as usize];
        assert!(sphere_t(d(ray.o), d(ray.d), c, r).is_some(), "elementId {id} is not on the centre pixel's ray");
    }
    // USD's default width (none authored) is 1: radius 0.5.
    let one = PointsSurface::new(vec![[0.0; 3]], &[]).unwrap();
    assert!((one.patch_bounds(0).max.x - 0.5).abs() < 1e-5, "{:?}", one.patch_bounds(0));
}

#[test]
fn every_integrator_sees_an_isolated_convex_shape_unoccluded_and_lit_exactly() {
    // A convex shape alone can neither shadow nor occlude itself nor bounce light onto itself:
    // AO is 1 everywhere (colour = albedo), and every integrator's colour under an angle-0 sun
    // is ρ/π · E · max(0, n·l). Any self-intersection (acne) or light leak shows as a pixel
    // below that. One sample per pixel: the pixel-centre ray the normal AOV also reads.
    let light = Vec3A::new(-0.3, -0.5, -1.0).normalize();
    let shapes: [(&str, Arc<dyn LimitSurface>, Mat4); 4] = [
        ("sphere", Arc::new(ImplicitSurface::new(Shape::Sphere { radius: 1.2 }).unwrap()), Mat4::IDENTITY),
        ("cube", Arc::new(ImplicitSurface::new(Shape::Cube { size: 1.6 }).unwrap()), Mat4::from_euler(glam::EulerRot::XYZ, 0.5, 0.3, 0.2)),
        (
            "capsule",
            Arc::new(ImplicitSurface::new(Shape::Capsule { radius_bottom: 0.6, radius_top: 0.6, height: 1.0, axis: Axis::Y }).unwrap()),
            Mat4::from_rotation_z(0.4),
        ),
        (
            "cylinder",
            Arc::new(ImplicitSurface::new(Shape::Cylinder { radius_bottom: 0.7, radius_top: 0.7, height: 1.5, axis: Axis::X }).unwrap()),
            Mat4::from_rotation_y(0.6),
        ),
    ];
    for (name, surface, pose) in shapes {
        let camera = Camera::perspective(Camera::look_at(Vec3::new(1.0, 1.5, 6.0), Vec3::ZERO, Vec3::Y), 50.0);
        let scene = grey_under_the_sun(name, surface, pose, light, camera);
        assert_every_integrator_lights_it_exactly(&scene, light, (40, 40), name, 100);
    }
}
