//! Trimmed NURBS patches against closed-form answers computed here: a flat bicubic square
//! whose parameters are its x and y (control points at the Greville abscissae), trimmed by
//! its outer boundary and an exact rational circle, is hit by every camera ray through the
//! kept ring and by none through the hole (whose rays go on to the ground behind), to within
//! the flattening's tolerance of the circle; and its shadow on the ground has the hole in it,
//! light for light, through the direct-lighting integrator's shadow rays.

use std::sync::Arc;

use glam::{DVec3, Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::differential::RayDifferential;
use mipray::geometry_cache::CacheConfig;
use mipray::nurbs::{NurbsDesc, NurbsSurface};
use mipray::options::IntegratorKind;
use mipray::prelude::*;
use mipray::ray::{Ray, RayKind};
use mipray::trace::{TraceCounters, Tracer};
use mipray::trim::{TrimDesc, TrimRegion};

mod common;

use common::d;

/// Two cubic spans in u over [0, 2], one in v over [0, 2].
const U_KNOTS: [f64; 9] = [0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 2.0, 2.0, 2.0];
const V_KNOTS: [f64; 8] = [0.0, 0.0, 0.0, 0.0, 2.0, 2.0, 2.0, 2.0];
/// The hole: centre and radius in (u, v) = (x, y). It crosses the knot u = 1 (two patches).
const CENTRE: [f64; 2] = [1.1, 0.9];
const RADIUS: f64 = 0.6;
/// The ground's height: more than the camera's default near clipping distance (1) below the
/// patch, so a camera between them sees it.
const GROUND_Z: f64 = -3.0;

/// The plane z = `z` with x = u, y = v: cubic B-splines reproduce the linear function through
/// control points at their Greville abscissae (the means of `order − 1` successive knots).
fn plane_points(z: f32) -> Vec<[f32; 3]> {
    let greville =
        |knots: &[f64], n: usize| -> Vec<f32> { (0..n).map(|i| ((knots[i + 1] + knots[i + 2] + knots[i + 3]) / 3.0) as f32).collect() };
    let (gu, gv) = (greville(&U_KNOTS, 5), greville(&V_KNOTS, 4));
    gv.iter().flat_map(|&y| gu.iter().map(move |&x| [x, y, z])).collect()
}

/// The square's boundary (an order-2 polyline) and the exact circle (rational quadratic,
/// homogeneous points), as `trimCurve:*` attributes.
struct Trim {
    knots: Vec<f64>,
    points: Vec<[f64; 3]>,
}

fn trim() -> Trim {
    let mut points: Vec<[f64; 3]> =
        [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0], [0.0, 0.0]].iter().map(|p| [p[0], p[1], 1.0]).collect();
    let mut knots = vec![0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 4.0];
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let unit = [(1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (-1.0, 1.0), (-1.0, 0.0), (-1.0, -1.0), (0.0, -1.0), (1.0, -1.0), (1.0, 0.0)];
    for (i, &(x, y)) in unit.iter().enumerate() {
        let w = if i % 2 == 1 { h } else { 1.0 };
        points.push([(CENTRE[0] + RADIUS * x) * w, (CENTRE[1] + RADIUS * y) * w, w]);
    }
    knots.extend([0.0, 0.0, 0.0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1.0, 1.0, 1.0]);
    Trim { knots, points }
}

impl Trim {
    fn desc(&self) -> TrimDesc<'_> {
        TrimDesc { counts: &[1, 1], orders: &[2, 3], vertex_counts: &[5, 9], knots: &self.knots, ranges: &[], points: &self.points }
    }
}

fn trimmed_square(z: f32) -> (NurbsSurface, f64) {
    let points = plane_points(z);
    let desc = NurbsDesc::whole(&points, &[], (5, 4), (4, 4), &U_KNOTS, &V_KNOTS);
    let t = trim();
    let region = TrimRegion::new(&t.desc()).unwrap();
    let tol = region.tolerance();
    (NurbsSurface::new(&desc).unwrap().with_trim(region), tol)
}

fn ground(z: f32) -> NurbsSurface {
    let points = [[-6.0, -6.0, z], [8.0, -6.0, z], [-6.0, 8.0, z], [8.0, 8.0, z]];
    let k = [0.0, 0.0, 1.0, 1.0];
    NurbsSurface::new(&NurbsDesc::whole(&points, &[], (2, 2), (2, 2), &k, &k)).unwrap()
}

/// Where (u, v) = (x, y) lies: `Some(true)` kept (in the square, outside the hole), `Some(false)`
/// cut away, `None` within `margin` of an edge of either (either answer is right there).
fn kept(x: f64, y: f64, margin: f64) -> Option<bool> {
    let r = ((x - CENTRE[0]).powi(2) + (y - CENTRE[1]).powi(2)).sqrt();
    let edge = x.min(y).min(2.0 - x).min(2.0 - y);
    if (r - RADIUS).abs() <= margin || edge.abs() <= margin {
        return None;
    }
    Some(edge > 0.0 && r > RADIUS)
}

/// The patch at z = 0 above a ground at [`GROUND_Z`], each a mesh of its own.
fn scene(camera: Camera, light: Vec3A) -> (Scene, f64) {
    let mut scene = Scene::default();
    let mat = scene.add_material(Material::lambertian("/half", Vec3A::splat(0.5)).0);
    let (square, tol) = trimmed_square(0.0);
    for (name, surface) in [("/square", Arc::new(square) as Arc<dyn LimitSurface>), ("/ground", Arc::new(ground(GROUND_Z as f32)))] {
        let mut mesh = Mesh::new(name, surface);
        mesh.material = mat;
        let m = scene.add_mesh(mesh);
        scene.add_instance(m, Mat4::IDENTITY);
    }
    scene.lights.push(Light::distant("/sun", light, Vec3A::splat(2.0)));
    scene.camera = camera;
    (scene, tol)
}

#[test]
fn camera_rays_pass_through_the_hole_and_hit_the_ring() {
    let camera = Camera::perspective(Camera::look_at(Vec3::new(1.0, 1.0, 4.0), Vec3::new(1.0, 1.0, 0.0), Vec3::Y), 30.0);
    let (scene, tol) = scene(camera, Vec3A::new(0.0, 0.0, -1.0));
    let tracer = Tracer::new(&scene, CacheConfig::default(), 1.0);
    let mut counters = TraceCounters::default();
    let (w, h) = (160, 160);
    // The flattened circle strays by the tolerance; f32 rounding of the hit's (u, v) adds ~1e-6.
    let margin = tol + 1e-5;
    let (mut ring, mut hole, mut outside) = (0, 0, 0);
    for y in 0..h {
        for x in 0..w {
            let ray = scene.camera.generate_ray(x as f32 + 0.5, y as f32 + 0.5, w, h);
            let (o, dir) = (d(ray.o), d(ray.d));
            let at = |z: f64| o + dir * ((z - o.z) / dir.z);
            let top = at(0.0);
            let Some(want) = kept(top.x, top.y, margin) else { continue };
            let hit = tracer.intersect(&ray, &mut counters).unwrap_or_else(|| panic!("pixel ({x}, {y}) met nothing"));
            let p = d(hit.p);
            if want {
                ring += 1;
                assert!((p - top).length() < 1e-4, "pixel ({x}, {y}): kept point {top} hit at {p}");
                assert_eq!(scene.meshes[hit.mesh as usize].name, "/square");
            } else {
                // Through the hole, or past the square: the ground behind.
                let below = at(GROUND_Z);
                assert!(
                    (p - below).length() < 1e-4,
                    "pixel ({x}, {y}): {top} is cut away but the ray stopped at {p}, not the ground at {below}"
                );
                if top.x > 0.0 && top.x < 2.0 && top.y > 0.0 && top.y < 2.0 {
                    hole += 1;
                } else {
                    outside += 1;
                }
            }
        }
    }
    eprintln!("{ring} ring, {hole} hole, {outside} outside pixels; tolerance {tol:e}");
    assert!(ring > 5000 && hole > 3000 && outside > 1000, "{ring} {hole} {outside}");
}

/// The hole's shadow, through the direct-lighting integrator: a ground point is lit when its
/// ray toward the sun crosses z = 0 in the hole or past the square, and black otherwise (one
/// light, no bounce). Seen from between the planes, looking down.
#[test]
fn the_shadow_has_the_hole_in_it() {
    let light = Vec3A::new(-0.4, 0.3, -1.0).normalize();
    let camera = Camera::perspective(Camera::look_at(Vec3::new(-0.2, 1.9, -0.05), Vec3::new(-0.2, 1.9, -3.0), Vec3::Y), 25.0);
    let (scene, tol) = scene(camera, light);
    let (w, h) = (128, 128);
    let opts = RenderOptions {
        width: w,
        height: h,
        samples: 1,
        integrator: IntegratorKind::Direct,
        aovs: vec![Aov::Color, Aov::Peye],
        ..Default::default()
    };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let lit_value = 0.5 / std::f32::consts::PI * 2.0 * (-light.z);
    let l = DVec3::new(f64::from(light.x), f64::from(light.y), f64::from(light.z));
    let (mut lit, mut dark) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let ray = scene.camera.generate_ray(x as f32 + 0.5, y as f32 + 0.5, w, h);
            let (o, dir) = (d(ray.o), d(ray.d));
            let g = o + dir * ((GROUND_Z - o.z) / dir.z);
            // Toward the sun from the ground point, up to z = 0.
            let up = g - l * (g.z / l.z);
            // The pixel centre's own answer: its footprint plays no part at one centred sample.
            let Some(blocked) = kept(up.x, up.y, tol + 1e-5) else { continue };
            let got = out.film.pixel("color", x, y)[0];
            if blocked {
                dark += 1;
                assert!(got == 0.0, "pixel ({x}, {y}): ground {g} under the ring at {up} is lit ({got})");
            } else {
                lit += 1;
                assert!((got - lit_value).abs() < 2e-3, "pixel ({x}, {y}): ground {g} under the hole at {up}: {got} vs {lit_value}");
            }
        }
    }
    eprintln!("{lit} lit, {dark} dark pixels");
    assert!(lit > 2000 && dark > 2000, "{lit} {dark}");
}

/// A ray leaving the ground straight up through the hole escapes, and one under the ring is
/// blocked: shadow rays ask `occluded`, which stops at the first hit it accepts.
#[test]
fn occlusion_queries_see_the_hole() {
    let camera = Camera::perspective(Camera::look_at(Vec3::new(1.0, 1.0, 4.0), Vec3::new(1.0, 1.0, 0.0), Vec3::Y), 30.0);
    let (scene, tol) = scene(camera, Vec3A::new(0.0, 0.0, -1.0));
    let tracer = Tracer::new(&scene, CacheConfig::default(), 1.0);
    let mut counters = TraceCounters::default();
    let mut checked = 0;
    for j in 0..60 {
        for i in 0..60 {
            let (x, y) = (-0.2 + 2.4 * (i as f64 + 0.5) / 60.0, -0.2 + 2.4 * (j as f64 + 0.5) / 60.0);
            let Some(blocked) = kept(x, y, tol + 1e-5) else { continue };
            let ray = Ray {
                o: Vec3A::new(x as f32, y as f32, -0.5),
                d: Vec3A::Z,
                t_min: 0.0,
                t_max: 10.0,
                diff: RayDifferential::default(),
                kind: RayKind::Shadow,
                time: 0.0,
            };
            assert_eq!(tracer.occluded(&ray, &mut counters), blocked, "({x}, {y})");
            checked += 1;
        }
    }
    assert!(checked > 3000, "{checked}");
}
