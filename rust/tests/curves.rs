//! Curves against closed-form answers computed here in f64, independently of `mipray::curves`:
//! a straight tube's silhouette on screen against the pinhole camera's tangent lines, a
//! Bézier tube's hit points against the analytic curve (and every pixel's hit or miss against
//! brute force), ribbons' widths and normals, bit-identical images across cache modes, and a
//! hair-like count staying within the cache budget.

use std::sync::Arc;

use glam::{DVec3, Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::curves::{Basis, CurveType, CurvesDesc, CurvesSurface, Interpolation, Style, Wrap};
use mipray::geometry_cache::{CacheConfig, CacheMode, Tier};
use mipray::prelude::*;
use mipray::trace::{TraceCounters, Tracer};

mod common;

use common::{assert_cache_modes_give_bit_identical_images, assert_every_integrator_lights_it_exactly, d, grey_under_the_sun};

fn desc<'a>(points: &'a [[f32; 3]], counts: &'a [i32], curve_type: CurveType, basis: Basis, widths: &'a [f32]) -> CurvesDesc<'a> {
    CurvesDesc {
        points,
        counts,
        curve_type,
        basis,
        wrap: Wrap::Nonperiodic,
        widths,
        widths_interpolation: if widths.len() == 1 { Interpolation::Constant } else { Interpolation::Vertex },
        normals: &[],
        normals_interpolation: Interpolation::Vertex,
        style: Style::Tube,
    }
}

fn scene_of(surface: CurvesSurface, camera: Camera) -> Scene {
    common::scene_of("/curves", Arc::new(surface), Mat4::IDENTITY, camera)
}

/// The pixel x (continuous) in row `y` where the hit/miss answer changes between `lo` (hit
/// state `at(lo)`) and `hi`, by bisection.
fn edge(mut lo: f64, mut hi: f64, at: impl Fn(f64) -> bool) -> f64 {
    let start = at(lo);
    assert_ne!(start, at(hi), "no edge between {lo} and {hi}");
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if at(mid) == start {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[test]
fn a_straight_tubes_width_on_screen_is_the_pinhole_cameras() {
    // A vertical tube of width w at distance dist straight ahead of a pinhole camera: its
    // silhouette is the tangent lines at angle asin(r / dist) from the axis, so on the film it
    // spans 2·f·tan(asin(r / dist)) of the aperture's width.
    let (dist, w) = (10.0_f64, 0.3_f64);
    let (width_px, height_px) = (640usize, 480usize);
    for (curve_type, basis, points) in [
        (CurveType::Linear, Basis::Bezier, vec![[0.0, -3.0, 0.0], [0.0, 3.0, 0.0]]),
        // A straight cubic with unevenly spaced control points: tessellated, still straight.
        (CurveType::Cubic, Basis::Bezier, vec![[0.0, -3.0, 0.0], [0.0, -2.5, 0.0], [0.0, 1.0, 0.0], [0.0, 3.0, 0.0]]),
        (CurveType::Cubic, Basis::CatmullRom, vec![[0.0, -5.0, 0.0], [0.0, -3.0, 0.0], [0.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 5.0, 0.0]]),
    ] {
        let counts = [points.len() as i32];
        let widths = [w as f32];
        let surface = CurvesSurface::new(&desc(&points, &counts, curve_type, basis, &widths)).unwrap();
        let camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, 0.0, dist as f32), Vec3::ZERO, Vec3::Y), 50.0);
        let scene = scene_of(surface, camera);
        let tracer = Tracer::new(&scene, CacheConfig::default(), 1.0);
        let hits = |x: f64| {
            let ray = scene.camera.generate_ray(x as f32, height_px as f32 * 0.5 + 0.5, width_px, height_px);
            tracer.intersect(&ray, &mut TraceCounters::default()).is_some()
        };
        let mid = width_px as f64 * 0.5;
        let left = edge(mid - 100.0, mid, hits);
        let right = edge(mid, mid + 100.0, hits);
        let cam = &scene.camera;
        let r = 0.5 * w;
        let span = 2.0 * f64::from(cam.focal_length) * (r / dist).asin().tan() / f64::from(cam.horizontal_aperture) * width_px as f64;
        assert!(((right - left) - span).abs() < 2e-3, "{curve_type:?} {basis:?}: {} px on screen vs {span} predicted", right - left);
        // Centred on the axis.
        assert!(((left + right) * 0.5 - mid).abs() < 2e-3, "{curve_type:?}: centre {}", (left + right) * 0.5);
    }
}

/// A cubic Bézier in f64 (textbook Bernstein form).
fn bezier(c: &[DVec3; 4], t: f64) -> DVec3 {
    let s = 1.0 - t;
    c[0] * (s * s * s) + c[1] * (3.0 * s * s * t) + c[2] * (3.0 * s * t * t) + c[3] * (t * t * t)
}

/// The minimum of `f` over the curve's t in [0, 1]: dense samples refined by golden-section
/// search.
fn minimum_over_curve(f: impl Fn(f64) -> f64) -> f64 {
    let n = 400;
    let i = (0..=n).min_by(|&a, &b| f(a as f64 / n as f64).total_cmp(&f(b as f64 / n as f64))).unwrap();
    let (mut lo, mut hi) = (((i as f64) - 1.0).max(0.0) / n as f64, ((i as f64) + 1.0).min(n as f64) / n as f64);
    for _ in 0..60 {
        let (m1, m2) = (lo + (hi - lo) * 0.382, lo + (hi - lo) * 0.618);
        if f(m1) < f(m2) {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    f(0.5 * (lo + hi))
}

/// Distance from `p` to the curve.
fn distance_to_curve(c: &[DVec3; 4], p: DVec3) -> f64 {
    minimum_over_curve(|t| (bezier(c, t) - p).length())
}

/// Distance from the ray's line to the curve.
fn ray_distance_to_curve(c: &[DVec3; 4], o: DVec3, dir: DVec3) -> f64 {
    let dir = dir.normalize();
    minimum_over_curve(|t| {
        let q = bezier(c, t) - o;
        (q - dir * q.dot(dir)).length()
    })
}

#[test]
fn a_bezier_tubes_hits_lie_on_the_analytic_tube() {
    let cps = [[-2.0_f32, -1.0, 0.0], [-1.0, 2.5, 0.5], [1.0, -2.0, -0.5], [2.0, 1.0, 0.0]];
    let c = cps.map(|p| DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])));
    let r = 0.15;
    let widths = [2.0 * r as f32];
    let counts = [4];
    let surface = CurvesSurface::new(&desc(&cps, &counts, CurveType::Cubic, Basis::Bezier, &widths)).unwrap();
    let camera = Camera::perspective(Camera::look_at(Vec3::new(0.5, 0.3, 7.0), Vec3::ZERO, Vec3::Y), 35.0);
    let scene = scene_of(surface, camera);
    let tracer = Tracer::new(&scene, CacheConfig::default(), 1.0);
    let (w, h) = (160, 120);
    let mut counters = TraceCounters::default();
    let (mut hits, mut worst) = (0, 0.0_f64);
    for y in 0..h {
        for x in 0..w {
            let ray = scene.camera.generate_ray(x as f32 + 0.5, y as f32 + 0.5, w, h);
            let got = tracer.intersect(&ray, &mut counters);
            let near = ray_distance_to_curve(&c, d(ray.o), d(ray.d));
            // The tessellation strays from the curve by at most its chord error (the hit's),
            // which the rate keeps below the beam's width there.
            match got {
                Some(hit) => {
                    hits += 1;
                    let off = (distance_to_curve(&c, d(hit.p)) - r).abs();
                    assert!(
                        off <= f64::from(hit.chord_error) + 1e-4,
                        "pixel ({x}, {y}): hit {off} off the tube (chord error {})",
                        hit.chord_error
                    );
                    worst = worst.max(off);
                    let beam = f64::from(ray.beam_width(hit.t));
                    assert!(f64::from(hit.chord_error) <= beam, "chord error {} above the beam {beam}", hit.chord_error);
                }
                None => {
                    // Misses only where the ray passes outside the tube (within the chord error
                    // of the coarsest rate used here, bounded by the beam).
                    let beam = f64::from(ray.beam_width(7.0));
                    assert!(near >= r - beam, "pixel ({x}, {y}) missed at {near} from the curve (radius {r})");
                }
            }
        }
    }
    assert!(hits > 300, "{hits} hits");
    eprintln!("{hits} hits, worst distance from the tube {worst}");
    // Every tier's tessellation hits the tube at r to within its own chord error, by ray
    // from the side at each u.
    let s = scene.meshes[0].surface.curves().unwrap();
    for tier in [Tier::Coarse, Tier::Medium, Tier::Fine] {
        let tess = s.tessellate(0, mipray::curves::tier_pieces(tier));
        for k in 1..20 {
            let u = k as f64 / 20.0;
            let p = bezier(&c, u);
            let o = p + DVec3::new(0.0, 0.0, 5.0);
            let hit = s.intersect(0, &tess, 1, Vec3A::new(o.x as f32, o.y as f32, o.z as f32), -Vec3A::Z, 0.0, f32::INFINITY);
            // A coarse chord strays further than the tube's radius: it may pass beside u.
            let Some(hit) = hit else {
                assert!(f64::from(tess.chord_error) > 0.5 * r, "{tier:?}: ray down onto u = {u} missed");
                continue;
            };
            let q = o - DVec3::Z * f64::from(hit.t);
            let off = (distance_to_curve(&c, q) - r).abs();
            assert!(off <= f64::from(tess.chord_error) + 1e-5, "{tier:?} u {u}: {off} vs chord error {}", tess.chord_error);
        }
    }
}

#[test]
fn ribbons_face_their_normals_or_the_ray() {
    // A horizontal ribbon along x, 0.4 wide, normals +z, seen from +z: 0.4 tall on screen,
    // shading normal +z. Turned to face +y instead, seen edge-on from +z: nothing.
    let pts = [[-2.0_f32, 0.0, 0.0], [2.0, 0.0, 0.0]];
    let counts = [2];
    let widths = [0.4_f32];
    let ortho = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 20.0, 20.0);
    let (w, h) = (200, 200); // an orthographic aperture is in tenths of a unit: 0.01 units a pixel, the ribbon 40 rows tall
    for (normal, style, rows) in
        [([0.0_f32, 0.0, 1.0], Some(Style::Ribbon), 40), ([0.0, 1.0, 0.0], Some(Style::Ribbon), 0), ([0.0; 3], None, 40)]
    {
        let normals = [normal];
        let mut dsc = desc(&pts, &counts, CurveType::Linear, Basis::Bezier, &widths);
        dsc.style = Style::Ribbon;
        if style.is_some() {
            dsc.normals = &normals;
            dsc.normals_interpolation = Interpolation::Constant;
        }
        let scene = scene_of(CurvesSurface::new(&dsc).unwrap(), ortho.clone());
        let out = render(
            &scene,
            &RenderOptions { width: w, height: h, aovs: vec![Aov::Color, Aov::Alpha, Aov::Normal], ..Default::default() },
            &NoProgress,
        )
        .unwrap();
        let covered = (0..h).filter(|&y| out.film.pixel("alpha", 100, y)[0] > 0.5).count();
        assert_eq!(covered, rows, "normal {normal:?} style {style:?}: {covered} rows");
        if rows > 0 {
            let n = out.film.pixel("normal", 100, 99);
            assert!((n[2] - 1.0).abs() < 1e-4, "normal {n:?}");
        }
    }
}

fn hair(count: usize, segs_per: usize) -> (Vec<[f32; 3]>, Vec<i32>) {
    let mut state = 11u64;
    let mut next = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 40) as f32) / (1u64 << 24) as f32
    };
    let mut pts = Vec::new();
    for _ in 0..count {
        let (x, z) = (next() * 4.0 - 2.0, next() * 4.0 - 2.0);
        let bend = next() - 0.5;
        for k in 0..segs_per + 3 {
            let t = k as f32 / (segs_per + 2) as f32;
            pts.push([x + bend * t * t, -1.5 + 3.0 * t, z + 0.3 * bend * t]);
        }
    }
    (pts, vec![(segs_per + 3) as i32; count])
}

#[test]
fn cache_modes_give_bit_identical_curve_images() {
    let (pts, counts) = hair(300, 4);
    let widths = [0.03_f32];
    let mut dsc = desc(&pts, &counts, CurveType::Cubic, Basis::Bspline, &widths);
    dsc.wrap = Wrap::Nonperiodic;
    let surface = CurvesSurface::new(&dsc).unwrap();
    let camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, 0.5, 6.0), Vec3::ZERO, Vec3::Y), 35.0);
    let scene = scene_of(surface, camera);
    assert_cache_modes_give_bit_identical_images(&scene);
}

#[test]
fn a_million_hair_segments_stay_within_the_cache_budget() {
    let (pts, counts) = hair(250_000, 4);
    let widths = [0.002_f32];
    let surface = CurvesSurface::new(&desc(&pts, &counts, CurveType::Cubic, Basis::Bspline, &widths)).unwrap();
    assert_eq!(surface.segment_count(), 1_000_000);
    let camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, 0.0, 6.0), Vec3::ZERO, Vec3::Y), 35.0);
    let scene = scene_of(surface, camera);
    let budget = [64 << 10, 64 << 10, 128 << 10];
    let cache = CacheConfig { mode: CacheMode::Multires, budget_bytes: budget, ..Default::default() };
    let tracer = Tracer::new(&scene, cache, 1.0);
    let mut counters = TraceCounters::default();
    let (w, h) = (96, 96);
    let mut hits = 0;
    for y in 0..h {
        for x in 0..w {
            hits +=
                usize::from(tracer.intersect(&scene.camera.generate_ray(x as f32 + 0.5, y as f32 + 0.5, w, h), &mut counters).is_some());
        }
    }
    assert!(hits > 1000, "{hits} hits");
    for tier in [Tier::Coarse, Tier::Medium, Tier::Fine] {
        let bytes = tracer.cache.resident_bytes(tier);
        assert!(bytes <= budget[tier.index()], "{tier:?}: {bytes} resident over {}", budget[tier.index()]);
    }
    // The BVH is over segments: one root subpatch each, not one per piece.
    assert_eq!(tracer.subpatch_count(), 1_000_000);
}

/// A scene of one straight linear curve along y from −`half_length` to `half_length`,
/// `width` wide, as mesh "/c" (not yet instanced), and that mesh.
fn vertical_curve(half_length: f32, width: f32) -> (Scene, usize) {
    let pts = [[0.0_f32, -half_length, 0.0], [0.0, half_length, 0.0]];
    let counts = [2];
    let widths = [width];
    let mut scene = Scene::default();
    let m = scene
        .add_mesh(Mesh::new("/c", Arc::new(CurvesSurface::new(&desc(&pts, &counts, CurveType::Linear, Basis::Bezier, &widths)).unwrap())));
    (scene, m)
}

#[test]
fn instanced_and_moving_curves_render_where_placed() {
    let (mut scene, m) = vertical_curve(1.0, 0.2);
    scene.add_instance(m, Mat4::from_translation(Vec3::new(-1.0, 0.0, 0.0)));
    scene.add_instance(m, Mat4::from_translation(Vec3::new(1.0, 0.0, 0.0)));
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 40.0, 40.0);
    let tracer = Tracer::new(&scene, CacheConfig::default(), 1.0);
    let at = |x: f32| {
        let ray = scene.camera.generate_ray(x, 100.0, 200, 200);
        tracer.intersect(&ray, &mut TraceCounters::default()).map(|h| h.instance)
    };
    // 0.02 units a pixel: the instances are at x = ±1, pixels 50 and 150, 10 pixels wide.
    assert_eq!(at(50.0), Some(0));
    assert_eq!(at(150.0), Some(1));
    assert_eq!(at(100.0), None);
    assert_eq!(at(44.0), None);
}

#[test]
fn every_integrator_sees_straight_tubes_and_ribbons_unoccluded_and_lit_exactly() {
    // A straight tube of constant width (a capsule: frustum pieces and round ends), a flat
    // ribbon and a straight ribbon facing each ray are convex: nothing on them can shadow,
    // occlude or light anything else on them,
    // so AO is 1 (colour = albedo) and every integrator's colour under an angle-0 sun is
    // ρ/π · E · max(0, n·l). A self-hit (acne) or a leak shows as a pixel below that.
    let light = Vec3A::new(-0.3, -0.5, -1.0).normalize();
    let tube_pts = [[-1.5_f32, -0.8, 0.0], [-0.5, -0.3, 0.2], [0.5, 0.2, 0.4], [1.5, 0.7, 0.6]];
    let widths = [0.8_f32];
    let counts = [4];
    let tube = CurvesSurface::new(&desc(&tube_pts, &counts, CurveType::Cubic, Basis::Bezier, &widths)).unwrap();
    let normals = [[0.2_f32, 0.3, 1.0]];
    let mut ribbon = desc(&tube_pts, &counts, CurveType::Cubic, Basis::Bezier, &widths);
    ribbon.style = Style::Ribbon;
    ribbon.normals = &normals;
    ribbon.normals_interpolation = Interpolation::Constant;
    let ribbon = CurvesSurface::new(&ribbon).unwrap();
    // A straight ribbon facing each ray is flat to every ray that meets it.
    let line = [[-1.5_f32, -0.8, 0.0], [1.5, 0.7, 0.6]];
    let line_counts = [2];
    let mut facing = desc(&line, &line_counts, CurveType::Linear, Basis::Bezier, &widths);
    facing.style = Style::Ribbon;
    let facing = CurvesSurface::new(&facing).unwrap();
    for (name, surface) in [("tube", tube), ("ribbon", ribbon), ("facing ribbon", facing)] {
        let camera = Camera::perspective(Camera::look_at(Vec3::new(0.5, 1.0, 6.0), Vec3::ZERO, Vec3::Y), 50.0);
        let scene = grey_under_the_sun(name, Arc::new(surface), Mat4::IDENTITY, light, camera);
        assert_every_integrator_lights_it_exactly(&scene, light, (48, 48), name, 50);
    }
}

#[test]
fn a_moving_curve_covers_each_pixel_for_its_share_of_the_shutter() {
    use mipray::motion::{MotionKey, MotionTransform};
    // A vertical tube 0.2 wide slides from x = −0.5 to 0.5 over the shutter: a pixel at x is
    // covered while |x − centre| < 0.1, a fifth of the shutter for |x| < 0.4.
    let (mut scene, m) = vertical_curve(2.0, 0.2);
    let slide = MotionTransform::new(vec![
        MotionKey { time: 0.0, render_from_object: Mat4::from_translation(Vec3::new(-0.5, 0.0, 0.0)) },
        MotionKey { time: 1.0, render_from_object: Mat4::from_translation(Vec3::new(0.5, 0.0, 0.0)) },
    ])
    .unwrap();
    scene.add_moving_instance(m, slide);
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 20.0, 2.0);
    let out =
        render(&scene, &RenderOptions { width: 20, height: 2, samples: 512, aovs: vec![Aov::Alpha], ..Default::default() }, &NoProgress)
            .unwrap();
    for x in 0..20 {
        let xc = -1.0 + 0.1 * (x as f32 + 0.5);
        if xc.abs() > 0.35 {
            continue;
        }
        let got = out.film.pixel("alpha", x, 0)[0];
        assert!((got - 0.2).abs() < 0.05, "pixel {x} (x = {xc}): {got} vs 0.2");
    }
}

#[test]
fn ray_differentials_on_a_curve_match_real_neighbour_rays() {
    use mipray::integrator::surface::shading_point;
    // dP/dx at a hit from the analytic derivatives against the hits of the camera rays one
    // pixel to either side (central differences), on a thick bent tube seen close up.
    let cps = [[-2.0_f32, -1.0, 0.0], [-1.0, 1.5, 0.5], [1.0, -1.0, -0.5], [2.0, 1.0, 0.0]];
    let counts = [4];
    let widths = [1.2_f32];
    let scene = scene_of(
        CurvesSurface::new(&desc(&cps, &counts, CurveType::Cubic, Basis::Bezier, &widths)).unwrap(),
        Camera::perspective(Camera::look_at(Vec3::new(0.3, 0.2, 6.0), Vec3::ZERO, Vec3::Y), 50.0),
    );
    let tracer = Tracer::new(&scene, CacheConfig::default(), 1.0);
    let mut counters = TraceCounters::default();
    let (w, h) = (800, 800);
    let mut checked = 0;
    for (px, py) in [(400.0, 400.0), (380.0, 420.0), (420.0, 390.0), (300.0, 330.0), (500.0, 470.0)] {
        let mut at = |x: f32, y: f32| {
            let ray = scene.camera.generate_ray(x, y, w, h);
            tracer.intersect(&ray, &mut counters).map(|hit| (ray, hit))
        };
        let Some((ray, hit)) = at(px, py) else { continue };
        let (Some((_, hx1)), Some((_, hx0))) = (at(px + 1.0, py), at(px - 1.0, py)) else { continue };
        if hx1.patch != hit.patch || hx0.patch != hit.patch {
            continue;
        }
        let sp = shading_point(&tracer, &scene, &ray, &hit);
        let footprint = ray.diff.transfer(ray.d, hit.t, sp.ng);
        let fd = (hx1.p - hx0.p) * 0.5;
        let rel = (footprint.dpdx - fd).length() / fd.length().max(1e-12);
        assert!(rel < 0.05, "({px}, {py}): dP/dx {} vs neighbours {fd}", footprint.dpdx);
        checked += 1;
    }
    assert!(checked >= 3, "only {checked} pixels checked");
}

/// The exact outward normal of a union of capsules (a polyline tube of radius r) at `p` on its
/// surface: from the nearest point of the polyline.
fn polyline_normal(pts: &[DVec3], p: DVec3) -> DVec3 {
    let mut best = (f64::INFINITY, DVec3::ZERO);
    for w in pts.windows(2) {
        let ab = w[1] - w[0];
        let t = ((p - w[0]).dot(ab) / ab.dot(ab)).clamp(0.0, 1.0);
        let q = w[0] + ab * t;
        let dist = (p - q).length();
        if dist < best.0 {
            best = (dist, (p - q) / dist);
        }
    }
    best.1
}

#[test]
fn a_linear_tube_shades_its_joints_with_the_spheres_normal() {
    // A right-angled bend: the joint's sphere is a quarter of the tube's visible outside, where
    // the tube's parameterization (no normal along the axis) would shade the cylinder going on.
    let pts = [[-1.5_f32, -0.5, 0.0], [0.0, 1.0, 0.0], [1.5, -0.5, 0.0]];
    let r = 0.4;
    let widths = [2.0 * r as f32];
    let counts = [3];
    let surface = CurvesSurface::new(&desc(&pts, &counts, CurveType::Linear, Basis::Bezier, &widths)).unwrap();
    let camera = Camera::perspective(Camera::look_at(Vec3::new(0.3, 1.2, 6.0), Vec3::new(0.0, 0.6, 0.0), Vec3::Y), 30.0);
    let scene = scene_of(surface, camera);
    let tracer = Tracer::new(&scene, CacheConfig::default(), 1.0);
    let poly: Vec<DVec3> = pts.iter().map(|p| DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))).collect();
    let mut counters = TraceCounters::default();
    let (w, h) = (96, 72);
    let (mut on_joint, mut hits) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let ray = scene.camera.generate_ray(x as f32 + 0.5, y as f32 + 0.5, w, h);
            let Some(hit) = tracer.intersect(&ray, &mut counters) else { continue };
            hits += 1;
            let sp = mipray::integrator::surface::shading_point(&tracer, &scene, &ray, &hit);
            let want = polyline_normal(&poly, d(hit.p));
            let got = d(sp.ns);
            assert!(got.dot(want) > 0.9999, "pixel ({x}, {y}): shading normal {got} vs the exact {want}");
            // On the joint's sphere the exact normal leans along both segments' axes.
            let axial = |a: DVec3, b: DVec3| want.dot((b - a).normalize()).abs();
            if axial(poly[0], poly[1]) > 0.05 && axial(poly[1], poly[2]) > 0.05 {
                on_joint += 1;
            }
        }
    }
    assert!(hits > 500 && on_joint > 20, "{hits} hits, {on_joint} on the joint's sphere");
}
