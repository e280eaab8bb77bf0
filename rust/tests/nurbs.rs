//! NURBS patches against closed-form surfaces computed here in f64, independently of
//! `mipray::nurbs`: a rational sphere's and a quarter cylinder's hits lie on the analytic
//! surface within the hit's chord error (which the beam bounds), a bicubic plane is hit exactly
//! at one quad, and the image is bit-identical across cache modes.

use std::sync::Arc;

use glam::{DVec3, Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::geometry_cache::CacheConfig;
use mipray::nurbs::{NurbsDesc, NurbsSurface};
use mipray::patch::LimitSurface;
use mipray::prelude::*;
use mipray::trace::{TraceCounters, Tracer};

mod common;

use common::{assert_cache_modes_give_bit_identical_images, d};

/// The unit sphere as a rational biquadratic NURBS: the nine-point circle in u (weights 1 and
/// √½ alternating) swept along the five-point semicircle from pole to pole in v.
struct Sphere {
    points: Vec<[f32; 3]>,
    weights: Vec<f64>,
}

const CIRCLE_KNOTS: [f64; 12] = [0.0, 0.0, 0.0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1.0, 1.0, 1.0];
const HALF_KNOTS: [f64; 8] = [0.0, 0.0, 0.0, 0.5, 0.5, 1.0, 1.0, 1.0];

fn sphere() -> Sphere {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let circle = [(1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (-1.0, 1.0), (-1.0, 0.0), (-1.0, -1.0), (0.0, -1.0), (1.0, -1.0), (1.0, 0.0)];
    let profile = [(0.0, -1.0), (1.0, -1.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
    let (mut points, mut weights) = (Vec::new(), Vec::new());
    for (j, (r, z)) in profile.iter().enumerate() {
        for (i, (x, y)) in circle.iter().enumerate() {
            points.push([(x * r) as f32, (y * r) as f32, *z as f32]);
            weights.push(if i % 2 == 1 { h } else { 1.0 } * if j % 2 == 1 { h } else { 1.0 });
        }
    }
    Sphere { points, weights }
}

impl Sphere {
    fn desc(&self) -> NurbsDesc<'_> {
        NurbsDesc::whole(&self.points, &self.weights, (9, 5), (3, 3), &CIRCLE_KNOTS, &HALF_KNOTS)
    }
}

fn scene_of(surface: NurbsSurface, transform: Mat4, camera: Camera) -> Scene {
    common::scene_of("/nurbs", Arc::new(surface), transform, camera)
}

/// The nearest t > 0 where the ray meets the sphere of radius `r` about `c`.
fn sphere_t(o: DVec3, dir: DVec3, c: DVec3, r: f64) -> Option<f64> {
    let f = o - c;
    let (a, b, cc) = (dir.dot(dir), f.dot(dir), f.dot(f) - r * r);
    let disc = b * b - a * cc;
    (disc >= 0.0).then(|| (-b - disc.sqrt()) / a).filter(|&t| t > 0.0)
}

/// Every pixel's camera ray through the tracer: a hit lies on the surface (`distance` from
/// it) within the hit's chord error, the chord error within the beam, and a ray that misses
/// passes no closer than `miss_margin(beam)` inside the analytic surface. Returns the hits.
fn check_hits(scene: &Scene, w: usize, h: usize, distance: impl Fn(DVec3) -> f64, inside: impl Fn(DVec3, DVec3) -> bool) -> usize {
    let tracer = Tracer::new(scene, CacheConfig::default(), 1.0);
    let mut counters = TraceCounters::default();
    let (mut hits, mut worst, mut worst_chord) = (0, 0.0_f64, 0.0_f64);
    for y in 0..h {
        for x in 0..w {
            let ray = scene.camera.generate_ray(x as f32 + 0.5, y as f32 + 0.5, w, h);
            match tracer.intersect(&ray, &mut counters) {
                Some(hit) => {
                    hits += 1;
                    let off = distance(d(hit.p));
                    let chord = f64::from(hit.chord_error);
                    // The tessellation strays from the surface by at most its chord error, plus
                    // f32 rounding of a unit-sized hit point.
                    assert!(off <= chord + 1e-5, "pixel ({x}, {y}): hit {off} off the surface (chord error {chord})");
                    let beam = f64::from(ray.beam_width(hit.t));
                    assert!(chord <= beam, "pixel ({x}, {y}): chord error {chord} above the beam {beam}");
                    worst = worst.max(off);
                    worst_chord = worst_chord.max(chord);
                }
                None => assert!(!inside(d(ray.o), d(ray.d)), "pixel ({x}, {y}) missed a ray well inside the surface"),
            }
        }
    }
    eprintln!("{hits} hits, worst distance from the surface {worst}, worst chord error {worst_chord}");
    hits
}

#[test]
fn a_rational_sphere_is_hit_on_the_analytic_sphere() {
    let s = sphere();
    let surface = NurbsSurface::new(&s.desc()).unwrap();
    // Four quarter-circle spans around, two half-meridian spans: eight rational patches.
    assert_eq!(surface.patch_count(), 8);
    let centre = DVec3::new(0.3, -0.2, 0.1);
    let camera = Camera::perspective(Camera::look_at(Vec3::new(0.5, 3.0, 4.0), Vec3::new(0.3, -0.2, 0.1), Vec3::Z), 40.0);
    let scene = scene_of(surface, Mat4::from_translation(centre.as_vec3()), camera);
    let (w, h) = (96, 72);
    let hits = check_hits(
        &scene,
        w,
        h,
        |p| ((p - centre).length() - 1.0).abs(),
        // A ray whose closest approach is a beam inside the silhouette must hit.
        |o, dir| {
            let dir = dir.normalize();
            let f = o - centre;
            let closest = (f - dir * f.dot(dir)).length();
            closest < 0.97 && sphere_t(o, dir, centre, 1.0).is_some()
        },
    );
    assert!(hits > 1000, "{hits} hits");
}

#[test]
fn a_rational_quarter_cylinder_is_hit_on_the_analytic_cylinder() {
    let w = std::f64::consts::FRAC_1_SQRT_2;
    let points = [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 2.0], [1.0, 1.0, 2.0], [0.0, 1.0, 2.0]];
    let weights = [1.0, w, 1.0, 1.0, w, 1.0];
    let (uk, vk) = ([0.0, 0.0, 0.0, 1.0, 1.0, 1.0], [0.0, 0.0, 1.0, 1.0]);
    let desc = NurbsDesc::whole(&points, &weights, (3, 2), (3, 2), &uk, &vk);
    let surface = NurbsSurface::new(&desc).unwrap();
    let camera = Camera::perspective(Camera::look_at(Vec3::new(3.0, 3.0, 1.0), Vec3::new(0.5, 0.5, 1.0), Vec3::Z), 45.0);
    let scene = scene_of(surface, Mat4::IDENTITY, camera);
    let hits = check_hits(
        &scene,
        80,
        80,
        |p| (DVec3::new(p.x, p.y, 0.0).length() - 1.0).abs().max((p.z - p.z.clamp(0.0, 2.0)).abs()),
        |_, _| false,
    );
    assert!(hits > 500, "{hits} hits");
}

#[test]
fn a_bicubic_plane_is_hit_exactly_at_one_quad() {
    let mut points = Vec::new();
    for v in 0..5 {
        for u in 0..5 {
            points.push([u as f32 - 2.0, v as f32 - 2.0, 0.0]);
        }
    }
    // Uniform, unclamped cubic knots: two spans each way, every patch a flat square.
    let k = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0];
    let desc = NurbsDesc::whole(&points, &[], (5, 5), (4, 4), &k, &k);
    let surface = NurbsSurface::new(&desc).unwrap();
    assert_eq!(surface.patch_count(), 4);
    assert!((0..4).all(|p| surface.patch_is_affine(p)));
    let camera = Camera::perspective(Camera::look_at(Vec3::new(0.4, -2.0, 3.0), Vec3::ZERO, Vec3::Z), 40.0);
    let scene = scene_of(surface, Mat4::IDENTITY, camera);
    let tracer = Tracer::new(&scene, CacheConfig::default(), 1.0);
    let mut counters = TraceCounters::default();
    let mut hits = 0;
    for y in 0..48 {
        for x in 0..64 {
            let ray = scene.camera.generate_ray(x as f32 + 0.5, y as f32 + 0.5, 64, 48);
            let (o, dir) = (d(ray.o), d(ray.d));
            let t = -o.z / dir.z;
            let p = o + t * dir;
            // The span of a uniform cubic B-spline over points at −2..2 is [−1, 1]².
            let inside = p.x.abs() < 0.99 && p.y.abs() < 0.99;
            let outside = p.x.abs() > 1.01 || p.y.abs() > 1.01;
            match tracer.intersect(&ray, &mut counters) {
                Some(hit) => {
                    hits += 1;
                    assert!(!outside, "pixel ({x}, {y}) hit outside the plane's span");
                    assert_eq!(hit.quads, 1, "an affine patch is tested at one quad");
                    assert!((d(hit.p) - p).length() < 1e-5, "pixel ({x}, {y}): {} vs {p}", hit.p);
                }
                None => assert!(!inside, "pixel ({x}, {y}) missed the plane"),
            }
        }
    }
    assert!(hits > 500, "{hits} hits");
}

#[test]
fn cache_modes_give_bit_identical_nurbs_images() {
    let s = sphere();
    let camera = Camera::perspective(Camera::look_at(Vec3::new(0.5, 3.0, 2.0), Vec3::ZERO, Vec3::Z), 40.0);
    let scene = scene_of(NurbsSurface::new(&s.desc()).unwrap(), Mat4::IDENTITY, camera);
    assert_cache_modes_give_bit_identical_images(&scene);
}

#[test]
fn shading_normals_of_the_sphere_are_radial() {
    let s = sphere();
    let camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, 4.0, 0.5), Vec3::ZERO, Vec3::Z), 40.0);
    let scene = scene_of(NurbsSurface::new(&s.desc()).unwrap(), Mat4::IDENTITY, camera);
    let opts =
        RenderOptions { width: 48, height: 48, samples: 1, aovs: vec![Aov::Color, Aov::Normal, Aov::Position], ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let mut n_hits = 0;
    for y in 0..48 {
        for x in 0..48 {
            let p = out.film.pixel("position", x, y);
            let n = out.film.pixel("normal", x, y);
            if n.iter().all(|c| *c == 0.0) {
                continue;
            }
            n_hits += 1;
            let radial = Vec3A::new(p[0], p[1], p[2]).normalize();
            let n = Vec3A::new(n[0], n[1], n[2]);
            // The shading normal is the exact surface's at the hit's (u, v); the position is the
            // tessellation's, a chord error away.
            assert!(n.dot(radial) > 0.999, "pixel ({x}, {y}): normal {n} vs radial {radial}");
        }
    }
    assert!(n_hits > 300, "{n_hits}");
}
