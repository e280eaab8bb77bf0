//! Numerically hard cases, each a named test whose assertion fails if the case breaks: high
//! valences, creases, holes, non-manifold and degenerate meshes, thin and flat geometry, huge and
//! tiny scales, far-off geometry, grazing rays and lights, cracks between rates, non-finite
//! inputs and samples.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::sync::Arc;

use common::{beam_ray, boxed, cube_sphere, grid, quad_pole, triangle_fan, Rng};
use glam::{Mat4, Vec3, Vec3A};
use hd_mipray::subdiv_compare::{compare, CompareOptions};
use mipray::aov::Aov;
use mipray::bilinear::BilinearSurface;
use mipray::camera::Camera;
use mipray::differential::RayDifferential;
use mipray::film::Film;
use mipray::geometry_cache::CacheConfig;
use mipray::integrator::shading_point;
use mipray::patch::LimitSurface;
use mipray::prelude::*;
use mipray::ray::{Ray, RayKind};
use mipray::trace::{TraceCounters, Tracer};
use mipray_bridge::OsdSurface;
use serde_json::Value;

fn osd(name: &str, (topo, pts): (MeshTopology, Vec<[f32; 3]>)) -> Arc<OsdSurface> {
    Arc::new(OsdSurface::new(name, &topo, &pts).unwrap_or_else(|e| panic!("{e}")))
}

fn scene_of(surface: Arc<dyn LimitSurface>) -> Scene {
    let mut scene = Scene::default();
    let mesh = scene.add_mesh(Mesh::new("/mesh", surface));
    scene.add_instance(mesh, Mat4::IDENTITY);
    scene
}

fn render_of(scene: &Scene, size: usize, aovs: &[&str]) -> (Film, Value) {
    let options = RenderOptions {
        width: size,
        height: size,
        threads: 2,
        aovs: aovs.iter().map(|s| Aov::from_name(s).unwrap()).collect(),
        ..Default::default()
    };
    let out = render(scene, &options, &NoProgress).unwrap_or_else(|e| panic!("{e}"));
    (out.film, out.stats)
}

/// Every value of every AOV is finite.
fn all_finite(film: &Film) -> bool {
    film.aovs.iter().all(|a| a.data.iter().all(|v| v.is_finite()))
}

fn dropped(stats: &Value) -> u64 {
    stats["render"]["dropped_samples"].as_u64().expect("render.dropped_samples")
}

fn coverage(film: &Film) -> usize {
    film.aov("alpha").unwrap().data.iter().filter(|a| **a > 0.5).count()
}

/// A camera at `eye` looking at the origin, vertical field of view about 40°.
fn look(eye: Vec3, near: f32, far: f32) -> Camera {
    let mut c = Camera::perspective(
        Camera::look_at(eye, Vec3::ZERO, if eye.cross(Vec3::Y).length() > 1e-6 * eye.length() { Vec3::Y } else { Vec3::X }),
        20.0,
    );
    c.vertical_aperture = c.horizontal_aperture;
    c.clipping_range = (near, far);
    c
}

fn lit(mut scene: Scene, eye: Vec3) -> Scene {
    scene.camera = look(eye, 1e-3 * eye.length(), 1e3 * eye.length());
    scene.lights.push(Light::distant("/sun", Vec3A::new(-0.3, -0.4, -1.0), Vec3A::ONE));
    scene
}

// --- extraordinary vertices -------------------------------------------------------------------

#[test]
fn extraordinary_vertices_of_valence_3_to_64_match_opensubdiv_and_render_finite() {
    for n in [3usize, 5, 6, 8, 12, 16, 24, 32, 48, 64] {
        for (kind, mesh) in [("pole", quad_pole(n)), ("fan", triangle_fan(n))] {
            let name = format!("/{kind}{n}");
            let r = compare(&name, &mesh.0, &mesh.1, &CompareOptions::quick()).unwrap();
            assert!(r.max_rel_position_error <= 1e-5, "{name}: limit position error {:.2e}", r.max_rel_position_error);
            assert!(r.max_normal_angle_beyond_rounding_deg <= 0.05, "{name}: normal angle {}", r.max_normal_angle_deg);
            assert!(r.watertight, "{name}: {:?}", r.watertight_detail);
            let scene = lit(scene_of(osd(&name, mesh)), Vec3::new(0.3, 0.2, 4.0));
            let (film, stats) = render_of(&scene, 24, &["color", "alpha", "normal", "depth"]);
            assert!(all_finite(&film) && dropped(&stats) == 0, "{name}: non-finite output");
            assert!(coverage(&film) > 10, "{name}: the mesh covers {} of 576 pixels", coverage(&film));
        }
    }
}

// --- creases ----------------------------------------------------------------------------------

/// A Catmull-Clark cube whose twelve edges all have crease sharpness `s`.
fn creased_cube(s: f32) -> (MeshTopology, Vec<[f32; 3]>) {
    let (mut t, p) = boxed([1.0; 3], Scheme::CatmullClark);
    let edges = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)];
    t.crease_indices = edges.iter().flat_map(|&(a, b)| [a, b]).collect();
    t.crease_lengths = vec![2; 12];
    t.crease_sharpnesses = vec![s; 12];
    (t, p)
}

/// The limit surface's largest reach toward the cube's corners: max of (x + y + z)/√3 and of
/// the largest coordinate over a 9×9 grid of every patch.
fn reach(s: &dyn LimitSurface) -> (f32, f32) {
    let (mut diag, mut face) = (0.0f32, 0.0f32);
    for p in 0..s.patch_count() {
        for j in 0..9 {
            for i in 0..9 {
                let q = s.evaluate(p, i as f32 / 8.0, j as f32 / 8.0).p;
                diag = diag.max((q.x + q.y + q.z) / 3f32.sqrt());
                face = face.max(q.abs().max_element());
            }
        }
    }
    (diag, face)
}

#[test]
fn infinitely_sharp_creases_keep_the_cube_and_semi_sharp_ones_lie_between() {
    // Infinitely sharp: every limit point lies on the cube's faces and the corners are kept.
    let sharp = osd("/sharp", creased_cube(10.0));
    for p in 0..sharp.patch_count() {
        for j in 0..5 {
            for i in 0..5 {
                let q = sharp.evaluate(p, i as f32 / 4.0, j as f32 / 4.0).p;
                assert!((q.abs().max_element() - 1.0).abs() < 1e-5, "patch {p}: {q:?} is off the cube");
            }
        }
    }
    assert!((reach(sharp.as_ref()).0 - 3f32.sqrt()).abs() < 1e-5);
    // Semi-sharp: the corner reach grows with sharpness and stays inside the cube.
    let mut last = 0.0;
    for s in [0.0f32, 0.5, 1.0, 2.0, 3.0] {
        let (d, face) = reach(osd("/semi", creased_cube(s)).as_ref());
        assert!(d > last && d < 3f32.sqrt() - 1e-3 && face <= 1.0 + 1e-5, "sharpness {s}: reach {d} after {last}");
        last = d;
        let r = compare("/semi", &creased_cube(s).0, &creased_cube(s).1, &CompareOptions::quick()).unwrap();
        assert!(
            r.max_rel_position_error <= 1e-5 && r.watertight,
            "sharpness {s}: {:.2e}, watertight {}",
            r.max_rel_position_error,
            r.watertight
        );
    }
    let (film, stats) = render_of(&lit(scene_of(sharp), Vec3::new(3.0, 2.5, 4.0)), 24, &["color", "normal"]);
    assert!(all_finite(&film) && dropped(&stats) == 0);
}

/// Rays crossing the seams between the end caps around the centre of `quad_pole(n)` and their
/// regular neighbours that pass through the disk: (passed, rays). At the default isolation
/// level 4 the end cap of each face spans ptex (u, v) ∈ [0, 1/16]² at the centre; its edges
/// u = 1/16 and v = 1/16 meet regular patches. For points `a` of such an edge as the end cap
/// evaluates it, `b` is the nearest of 129 points of the edge as the neighbour evaluates it
/// (the curves may agree as sets where their parameterizations differ). A ray aims at the
/// midpoint of `a` and `b` (a point of the surface when they agree) across the gap between them
/// (perpendicular to the gap and the edge, or the surface's normal where there is no gap), both
/// ways and tilted by ±30° towards the gap, from 0.05 before it; it has passed through when it
/// finds no hit up to 1e-3 beyond that point (the tessellations of these small patches are
/// within 1e-5 of the limit). Beam widths from 1 to 64 quads a patch side, so every pair of rates
/// meets at the seam.
fn end_cap_seam_passes(n: usize, seams: bool) -> (usize, usize) {
    let surface = osd(&format!("/pole{n}"), quad_pole(n));
    // The limit point at (u, v) of face f as the patch holding `inside` evaluates it (each
    // patch here spans 1/16 of the face, so its own (s, t) moves 16 times as fast).
    let side = |f: u32, u: f32, v: f32, inside: (f32, f32)| {
        let (p, s, t) = surface.find_patch(f, inside.0, inside.1).expect("a patch");
        surface.evaluate(p, s + 16.0 * (u - inside.0), t + 16.0 * (v - inside.1)).p
    };
    let scene = scene_of(surface.clone());
    let mut tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
    tracer.set_seams(seams);
    let mut c = TraceCounters::default();
    let mut rng = Rng(15);
    let (e, lead, beyond) = (1.0f32 / 16.0, 0.05f32, 1e-3f32);
    let (mut passed, mut rays) = (0, 0);
    for f in (0..n as u32).step_by(5) {
        for along_v in [true, false] {
            // (u, v) of the edge at parameter t, and a point inside the end cap / the neighbour
            // that picks the patch.
            let at = |t: f32| if along_v { (e, t) } else { (t, e) };
            let cap_in = (e * 0.5, e * 0.5);
            let nb_in = if along_v { (e * 1.5, e * 0.5) } else { (e * 0.5, e * 1.5) };
            let curve: Vec<Vec3A> = (0..=128)
                .map(|j| {
                    let (u, v) = at(e * j as f32 / 128.0);
                    side(f, u, v, nb_in)
                })
                .collect();
            for k in 0..=8 {
                let (u, v) = at(e * k as f32 / 8.0);
                let a = side(f, u, v, cap_in);
                let b = *curve.iter().min_by(|p, q| (**p - a).length().total_cmp(&(**q - a).length())).unwrap();
                let sp = surface.limit_at(f, u, v).expect("on the disk");
                let tangent = if along_v { sp.dpdv } else { sp.dpdu }.normalize();
                let gap = b - a;
                let (w, g) = if gap.length() > 1e-6 {
                    (tangent.cross(gap).normalize(), gap.normalize())
                } else {
                    (sp.dpdu.cross(sp.dpdv).normalize(), Vec3A::ZERO)
                };
                let target = a.lerp(b, 0.5);
                for sign in [1.0f32, -1.0] {
                    for tilt in [0.0f32, 0.5, -0.5] {
                        let d = (w * sign + g * tilt).normalize();
                        let spread = 2.0 * 2f32.powf(-8.0 * rng.f32());
                        let r = beam_ray(target - lead * d, d, 0.0, spread, RayKind::Camera);
                        passed += usize::from(tracer.intersect(&r, &mut c).is_none_or(|h| h.t > lead + beyond));
                        rays += 1;
                    }
                }
            }
        }
    }
    eprintln!("valence {n}, seams {seams}: {passed} of {rays} rays passed through");
    (passed, rays)
}

/// A closed lens: two `quad_pole(n)`-like disks (centres at z = ±0.3, so two vertices of valence
/// `n`) sharing their rim (ring vertices at radius 1, corner vertices at 1.4, all at z = 0; the
/// corner vertices have valence 2).
fn pole_lens(n: usize) -> (MeshTopology, Vec<[f32; 3]>) {
    let mut pts = vec![[0.0, 0.0, 0.3], [0.0, 0.0, -0.3]];
    for i in 0..n {
        let a = std::f32::consts::TAU * i as f32 / n as f32;
        pts.push([a.cos(), a.sin(), 0.0]);
        let b = std::f32::consts::TAU * (i as f32 + 0.5) / n as f32;
        pts.push([1.4 * b.cos(), 1.4 * b.sin(), 0.0]);
    }
    let r = |i: usize| (2 + 2 * (i % n)) as i32;
    let q = |i: usize| (3 + 2 * (i % n)) as i32;
    let mut idx: Vec<i32> = (0..n).flat_map(|i| [0, r(i), q(i), r(i + 1)]).collect();
    idx.extend((0..n).flat_map(|i| [1, r(i + 1), q(i), r(i)]));
    (MeshTopology { scheme: Scheme::CatmullClark, face_vertex_counts: vec![4; 2 * n], face_vertex_indices: idx, ..Default::default() }, pts)
}

#[test]
fn end_cap_seams_at_valence_256_and_300_let_no_ray_through() {
    // Gregory end caps at 256, bilinear ones at 300 (OsdSurface's `simplified`): their straight
    // edges run between refined points where the neighbours' edges are the limit's curves, 3.5e-3
    // of the diagonal apart at equal parameters but 2e-4 apart as curves (docs/subdivision-
    // compare.md, "Above valence 256"); the seam boxes close both. Without seams rays pass.
    for n in [256, 300] {
        let (passed, rays) = end_cap_seam_passes(n, true);
        assert_eq!(passed, 0, "valence {n}: {passed} of {rays} rays passed between an end cap and its neighbour");
    }
    assert!(end_cap_seam_passes(256, false).0 > 0, "without seams the measurement sees cracks");
}

#[test]
fn closed_lens_with_poles_of_valence_300_traced_from_inside_never_lets_a_ray_out() {
    let scene = scene_of(osd("/lens300", pole_lens(300)));
    assert!(scene.meshes[0].surface.patch_count() > 0);
    let (escapes, unoccluded, _) = crack_escapes(&scene, 10_000, 7, true);
    assert_eq!((escapes, unoccluded), (0, 0), "rays escaped the lens through cracks");
    assert!(crack_escapes(&scene, 10_000, 7, false).0 > 0, "without seams the measurement sees cracks");
}

// --- holes ------------------------------------------------------------------------------------

fn down_ray(x: f32, y: f32) -> Ray {
    Ray {
        o: Vec3A::new(x, y, 5.0),
        d: Vec3A::NEG_Z,
        t_min: 0.0,
        t_max: f32::INFINITY,
        diff: RayDifferential::default(),
        kind: RayKind::Camera,
        time: 0.0,
    }
}

#[test]
fn hole_faces_let_rays_through_and_the_rest_is_hit() {
    let (mut topo, pts) = grid(4, 2.0, Scheme::CatmullClark);
    topo.hole_indices = vec![5]; // face (1, 1): x, y in [-1, 0]
    let r = compare("/holed", &topo, &pts, &CompareOptions::quick()).unwrap();
    assert!(r.max_rel_position_error <= 1e-5 && r.watertight);
    let scene = scene_of(Arc::new(OsdSurface::new("/holed", &topo, &pts).unwrap()));
    let tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
    let mut c = TraceCounters::default();
    assert!(tracer.intersect(&down_ray(-0.5, -0.5), &mut c).is_none(), "the hole's centre is open");
    assert!(!tracer.occluded(&down_ray(-0.5, -0.5), &mut c));
    for (x, y) in [(0.5, 0.5), (-0.5, 0.5), (0.5, -0.5), (-1.3, -0.5), (-0.5, -1.3)] {
        assert!(tracer.intersect(&down_ray(x, y), &mut c).is_some(), "({x}, {y}) next to the hole is surface");
    }
}

// --- non-manifold -----------------------------------------------------------------------------

#[test]
fn non_manifold_edges_and_vertices_evaluate_and_render_finite() {
    // A book of three pages on one spine (an edge shared by three faces), and two pyramids
    // touching at their apex (a vertex shared by two fans of faces).
    let mut pts = vec![[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let mut idx = Vec::new();
    for k in 0..3 {
        let a = std::f32::consts::TAU * k as f32 / 3.0;
        pts.push([a.cos(), 0.0, a.sin()]);
        pts.push([a.cos(), 1.0, a.sin()]);
        idx.extend([0, 2 + 2 * k, 3 + 2 * k, 1]);
    }
    let apex = pts.len() as i32;
    pts.push([3.0, 0.5, 0.0]);
    for (k, z) in [(0, 1.0f32), (1, -1.0)] {
        let base = pts.len() as i32;
        for [x, y] in [[2.0, 0.0], [2.0, 1.0], [4.0, 1.0], [4.0, 0.0]] {
            pts.push([x, y, z]);
        }
        for e in 0..4 {
            let (a, b) = (base + e, base + (e + 1) % 4);
            if k == 0 {
                idx.extend([apex, a, b])
            } else {
                idx.extend([apex, b, a])
            }
        }
    }
    let counts = [vec![4; 3], vec![3; 8]].concat();
    let topo = MeshTopology { scheme: Scheme::CatmullClark, face_vertex_counts: counts, face_vertex_indices: idx, ..Default::default() };
    let r = compare("/nonmanifold", &topo, &pts, &CompareOptions::quick()).unwrap();
    assert!(r.max_rel_position_error <= 1e-5, "{:.2e}", r.max_rel_position_error);
    let scene = lit(scene_of(osd("/nonmanifold", (topo, pts))), Vec3::new(1.5, 3.0, 6.0));
    let (film, stats) = render_of(&scene, 32, &["color", "alpha", "normal", "depth"]);
    assert!(all_finite(&film) && dropped(&stats) == 0 && coverage(&film) > 50);
}

// --- degenerate faces -------------------------------------------------------------------------

#[test]
fn zero_area_faces_and_coincident_vertices_render_finite() {
    let (topo, mut pts) = grid(3, 1.5, Scheme::CatmullClark);
    // Coincident vertices: 5 onto 6. A zero-area face: face 8's corners 10, 11, 15, 14 onto
    // one line (10 onto 11, 14 onto 15).
    pts[5] = pts[6];
    pts[10] = pts[11];
    pts[14] = pts[15];
    for scheme in [Scheme::CatmullClark, Scheme::None] {
        let topo = MeshTopology { scheme, ..topo.clone() };
        let surface: Arc<dyn LimitSurface> = if scheme == Scheme::None {
            Arc::new(BilinearSurface::new(&topo, &pts).unwrap())
        } else {
            osd("/degenerate", (topo.clone(), pts.clone()))
        };
        for p in 0..surface.patch_count() {
            for (u, v) in [(0.0, 0.0), (0.5, 0.5), (1.0, 1.0), (0.0, 1.0)] {
                assert!(surface.evaluate(p, u, v).p.is_finite(), "{scheme:?} patch {p} at ({u}, {v})");
            }
        }
        let scene = lit(scene_of(surface), Vec3::new(0.4, -0.3, 5.0));
        let (film, stats) = render_of(&scene, 32, &["color", "alpha", "normal", "depth"]);
        assert!(all_finite(&film), "{scheme:?}: a non-finite pixel");
        assert_eq!(dropped(&stats), 0, "{scheme:?}: degenerate faces must shade with the triangle normal, not drop");
        assert!(coverage(&film) > 300, "{scheme:?}");
    }
}

// --- thin and flat ----------------------------------------------------------------------------

#[test]
fn very_thin_box_is_hit_on_the_side_the_ray_comes_from() {
    for scheme in [Scheme::None, Scheme::CatmullClark] {
        let mesh = boxed([1.0, 1.0, 1e-5], scheme);
        let surface: Arc<dyn LimitSurface> =
            if scheme == Scheme::None { Arc::new(BilinearSurface::new(&mesh.0, &mesh.1).unwrap()) } else { osd("/thin", mesh) };
        let scene = scene_of(surface);
        let tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
        let mut c = TraceCounters::default();
        let mut rng = Rng(3);
        for _ in 0..500 {
            let (x, y) = (rng.f32() - 0.5, rng.f32() - 0.5);
            for sign in [1.0f32, -1.0] {
                let r = Ray {
                    o: Vec3A::new(x, y, 3.0 * sign),
                    d: Vec3A::new(0.01, 0.02, -sign).normalize(),
                    t_min: 0.0,
                    t_max: f32::INFINITY,
                    diff: RayDifferential::default(),
                    kind: RayKind::Camera,
                    time: 0.0,
                };
                let h = tracer.intersect(&r, &mut c).unwrap_or_else(|| panic!("{scheme:?}: ({x}, {y}) from {sign} misses the box"));
                assert!(h.p.z * sign >= -1e-6, "{scheme:?}: the ray from {sign} went through to the far sheet (z = {})", h.p.z);
                assert!(h.ng.is_finite() && h.ng.dot(r.d) < 0.0, "{scheme:?}: the near sheet faces the ray");
            }
        }
    }
}

#[test]
fn nearly_flat_geometry_keeps_unit_normals_near_the_plane_normal() {
    let (topo, mut pts) = grid(6, 1.0, Scheme::CatmullClark);
    let mut rng = Rng(5);
    for p in &mut pts {
        p[2] = 1e-6 * (rng.f32() - 0.5);
    }
    let scene = scene_of(osd("/flatish", (topo, pts)));
    let tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
    let mut c = TraceCounters::default();
    for _ in 0..300 {
        let r = down_ray(1.6 * rng.f32() - 0.8, 1.6 * rng.f32() - 0.8);
        let h = tracer.intersect(&r, &mut c).expect("hit");
        let sp = shading_point(&tracer, &scene, &r, &h);
        assert!((sp.ns.length() - 1.0).abs() < 1e-4 && sp.ns.z > 0.999, "{:?}", sp.ns);
        assert!(h.p.z.abs() < 1e-5);
    }
}

// --- scales and far-off geometry --------------------------------------------------------------

/// Alpha mask of a unit-radius sphere scaled by `s` and moved by `offset`, seen from 4·s away.
fn sphere_mask(s: f32, offset: Vec3) -> (Vec<bool>, Film, Value) {
    let (topo, pts) = cube_sphere(2, Scheme::CatmullClark);
    let pts: Vec<[f32; 3]> = pts.iter().map(|p| (Vec3::from(*p) * s + offset).into()).collect();
    let mut scene = scene_of(osd("/sphere", (topo, pts)));
    let eye = offset + Vec3::new(0.0, 0.0, 4.0 * s);
    scene.camera = Camera::perspective(Camera::look_at(eye, offset, Vec3::Y), 20.0);
    scene.camera.vertical_aperture = scene.camera.horizontal_aperture;
    scene.camera.clipping_range = (0.01 * s, 100.0 * s);
    scene.lights.push(Light::distant("/sun", Vec3A::new(-0.3, -0.4, -1.0), Vec3A::ONE));
    let (film, stats) = render_of(&scene, 40, &["color", "alpha", "normal", "depth"]);
    let mask = film.aov("alpha").unwrap().data.iter().map(|a| *a > 0.5).collect();
    (mask, film, stats)
}

#[test]
fn scene_scales_from_1e_minus_4_to_1e6_render_the_same_silhouette() {
    let (reference, _, _) = sphere_mask(1.0, Vec3::ZERO);
    let covered = reference.iter().filter(|m| **m).count();
    assert!(covered > 150, "{covered}");
    for s in [1e-4f32, 1e-2, 1e2, 1e4, 1e6] {
        let (mask, film, stats) = sphere_mask(s, Vec3::ZERO);
        assert!(all_finite(&film) && dropped(&stats) == 0, "scale {s}: non-finite output");
        let differ = mask.iter().zip(&reference).filter(|(a, b)| a != b).count();
        assert!(differ <= 2, "scale {s}: {differ} silhouette pixels differ from scale 1");
    }
}

/// Pixels within one pixel (8-neighbourhood) of the edge of `mask` (`w` wide, square).
fn outline_ring(mask: &[bool], w: usize) -> Vec<bool> {
    let at = |x: i64, y: i64| x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < w && mask[y as usize * w + x as usize];
    (0..w * w)
        .map(|k| {
            let (x, y) = ((k % w) as i64, (k / w) as i64);
            let me = at(x, y);
            (-1..=1).any(|dy| (-1..=1).any(|dx| at(x + dx, y + dy) != me))
        })
        .collect()
}

#[test]
fn geometry_1e5_units_from_the_origin_keeps_its_silhouette_and_finite_normals() {
    let (reference, _, _) = sphere_mask(1.0, Vec3::ZERO);
    for offset in [Vec3::new(1e5, 0.0, 0.0), Vec3::new(-7e4, 7e4, 3e4)] {
        let (mask, film, stats) = sphere_mask(1.0, offset);
        assert!(all_finite(&film) && dropped(&stats) == 0, "{offset}: non-finite output");
        let normals = film.aov("normal").unwrap();
        let alpha = film.aov("alpha").unwrap();
        for (k, a) in alpha.data.iter().enumerate() {
            if *a > 0.5 {
                let n = Vec3::from_slice(&normals.data[3 * k..3 * k + 3]);
                assert!((n.length() - 1.0).abs() < 1e-3, "{offset}: normal {n}");
            }
        }
        // At 1e5 an f32 is 0.008 apart and the seam boxes' rounding margin is a few of those:
        // the outline may move by a pixel (here 0.06 units), no more, and only outward.
        let ring = outline_ring(&reference, 40);
        for (k, (a, b)) in mask.iter().zip(&reference).enumerate() {
            assert!(a == b || (ring[k] && *a), "{offset}: pixel {k} differs from the sphere at the origin beyond its outline");
        }
    }
}

// --- grazing rays and lights ------------------------------------------------------------------

fn plane(scheme: Scheme) -> Arc<dyn LimitSurface> {
    let mesh = grid(6, 1.0, scheme);
    if scheme == Scheme::None {
        Arc::new(BilinearSurface::new(&mesh.0, &mesh.1).unwrap())
    } else {
        osd("/plane", mesh)
    }
}

#[test]
fn plane_seen_at_89_9_degrees_is_hit_and_never_leaks() {
    let elev = 0.1f32.to_radians();
    for scheme in [Scheme::None, Scheme::CatmullClark] {
        let scene = scene_of(plane(scheme));
        let tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
        let mut c = TraceCounters::default();
        let d = Vec3A::new(0.0, elev.cos(), -elev.sin());
        for k in 0..400 {
            // Aimed at (x, y, 0) from 20 units away along the grazing direction.
            let x = -0.9 + 1.8 * (k % 20) as f32 / 19.0;
            let y = -0.9 + 1.8 * (k / 20) as f32 / 19.0;
            let target = Vec3A::new(x, y, 0.0);
            let r = Ray {
                o: target - d * 20.0,
                d,
                t_min: 0.0,
                t_max: f32::INFINITY,
                diff: RayDifferential::from_pinhole(d, Vec3A::X * 1e-3, Vec3A::Y * 1e-3),
                kind: RayKind::Camera,
                time: 0.0,
            };
            let h = tracer.intersect(&r, &mut c).unwrap_or_else(|| panic!("{scheme:?}: grazing ray at ({x}, {y}) slipped through"));
            assert!(h.t.is_finite() && h.ng.is_finite() && h.p.z.abs() < 1e-4, "{scheme:?}: {h:?}");
            let sp = shading_point(&tracer, &scene, &r, &h);
            assert!(sp.ns.is_finite() && sp.ns.z.abs() > 0.999);
            // Just above the far edge: nothing to hit.
            let over = Ray { o: Vec3A::new(x, 1.0, 1e-3) - d * 20.0, ..r };
            assert!(tracer.intersect(&over, &mut c).is_none(), "{scheme:?}: a hit above the plane");
        }
        let mut scene = scene;
        scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, -20.0, 20.0 * elev.tan()), Vec3::ZERO, Vec3::Z), 50.0);
        let (film, stats) = render_of(&scene, 32, &["color", "alpha", "normal", "depth"]);
        assert!(all_finite(&film) && dropped(&stats) == 0);
    }
}

/// Colour of every pixel of a plane lit by a distant light `elev_deg` above the horizon, with
/// or without shadow rays.
fn lit_plane(scheme: Scheme, elev_deg: f32, shadows: bool) -> Vec<f32> {
    let mut scene = scene_of(plane(scheme));
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 18.0, 18.0);
    let e = elev_deg.to_radians();
    let mut sun = Light::distant("/sun", Vec3A::new(-0.6 * e.cos(), -0.8 * e.cos(), -e.sin()), Vec3A::ONE);
    sun.casts_shadows = shadows;
    scene.lights.push(sun);
    render_of(&scene, 48, &["color"]).0.aov("color").unwrap().data.clone()
}

#[test]
fn plane_lit_by_a_grazing_distant_light_has_no_self_shadowed_pixel() {
    for scheme in [Scheme::None, Scheme::CatmullClark] {
        for elev in [5.0f32, 0.5, 0.1] {
            let with = lit_plane(scheme, elev, true);
            let without = lit_plane(scheme, elev, false);
            let lit_px = without.iter().filter(|c| **c > 0.0).count();
            assert!(lit_px > 3 * 48 * 48 * 3 / 4, "{scheme:?} {elev}°: the plane fills the view");
            let shadowed = with.iter().zip(&without).filter(|(a, b)| a != b).count();
            assert_eq!(shadowed, 0, "{scheme:?}, light {elev}° above the plane: {shadowed} self-shadowed channels");
        }
    }
}

#[test]
fn sphere_lit_from_the_side_has_no_shadow_acne_at_subpatch_seams() {
    // Seam boxes must not shadow the surface next to them: away from the terminator (where the
    // facets themselves turn from the light) shadows on and off give the same pixels.
    let make = |shadows: bool| {
        let mut scene = scene_of(osd("/sphere", cube_sphere(3, Scheme::CatmullClark)));
        scene.camera = look(Vec3::new(0.0, 0.0, 4.0), 0.1, 100.0);
        let mut sun = Light::distant("/sun", Vec3A::new(-1.0, -0.2, -0.3), Vec3A::ONE);
        sun.casts_shadows = shadows;
        scene.lights.push(sun);
        render_of(&scene, 64, &["color", "normal"]).0
    };
    let (with, without) = (make(true), make(false));
    let wi = -Vec3::new(-1.0, -0.2, -0.3).normalize();
    let (cw, cwo, n) = (&with.aov("color").unwrap().data, &without.aov("color").unwrap().data, &without.aov("normal").unwrap().data);
    let mut checked = 0;
    for k in 0..64 * 64 {
        let ns = Vec3::from_slice(&n[3 * k..3 * k + 3]);
        if ns.dot(wi) > 0.15 {
            checked += 1;
            assert_eq!(cw[3 * k], cwo[3 * k], "pixel {k}: shadowed although it faces the light (n·l = {})", ns.dot(wi));
        }
    }
    assert!(checked > 300, "{checked}");
}

// --- cracks between rates (the paper's §7.1) --------------------------------------------------

/// The smallest distance from the origin to the limit surface of mesh 0, on a 9×9 grid of every
/// patch.
fn inner_radius(scene: &Scene) -> f32 {
    let s = &scene.meshes[0].surface;
    let mut r = f32::INFINITY;
    for p in 0..s.patch_count() {
        for j in 0..9 {
            for i in 0..9 {
                r = r.min(s.evaluate(p, i as f32 / 8.0, j as f32 / 8.0).p.length());
            }
        }
    }
    r
}

/// Rays from inside a closed surface that found no hit (escapes, through `intersect` and
/// through `occluded`), out of `rays`. Beam widths are drawn log-uniformly so neighbouring
/// subpatches are tested at every mix of rates (1 to 16 quads a side, splits to depth 2); origins
/// up to 85% of the way to the surface, so rays meet seams obliquely, as slivers need.
fn crack_escapes(scene: &Scene, rays: usize, seed: u64, seams: bool) -> (usize, usize, TraceCounters) {
    let mut tracer = Tracer::new(scene, CacheConfig::unbounded(), 1.0);
    tracer.set_seams(seams);
    let mut c = TraceCounters::default();
    let mut rng = Rng(seed);
    let inner = 0.85 * inner_radius(scene);
    let (mut escapes, mut unoccluded) = (0, 0);
    for _ in 0..rays {
        let o = rng.unit() * (inner * rng.f32().sqrt());
        let d = rng.unit();
        // Spread from 1/128 to 2 radians per unit distance: 1 to 64 quads per patch side.
        let spread = 2.0 * 2f32.powf(-8.0 * rng.f32());
        let r = beam_ray(o, d, 0.0, spread, RayKind::Camera);
        escapes += usize::from(tracer.intersect(&r, &mut c).is_none());
        unoccluded += usize::from(!tracer.occluded(&Ray { kind: RayKind::Shadow, ..r }, &mut c));
    }
    (escapes, unoccluded, c)
}

fn sphere_scene(m: usize) -> Scene {
    scene_of(osd("/sphere", cube_sphere(m, Scheme::CatmullClark)))
}

#[test]
fn closed_sphere_traced_from_inside_never_lets_a_ray_out() {
    // MIPRAY_CRACK_RAYS raises the count (docs/cracks.md uses 200000 per sphere).
    let rays: usize = std::env::var("MIPRAY_CRACK_RAYS").ok().and_then(|s| s.parse().ok()).unwrap_or(20_000);
    let mut before_total = 0;
    for m in [1usize, 3] {
        let scene = sphere_scene(m);
        let t0 = std::time::Instant::now();
        let (before, before_occ, _) = crack_escapes(&scene, rays, 7, false);
        let t1 = std::time::Instant::now();
        let (after, after_occ, c) = crack_escapes(&scene, rays, 7, true);
        let (s_off, s_on) = ((t1 - t0).as_secs_f64(), t1.elapsed().as_secs_f64());
        println!(
            "cube sphere m={m}: patches={} rays={rays} escapes without seams={before} (shadow rays {before_occ}) with seams={after} (shadow rays {after_occ}); time {s_off:.2} s → {s_on:.2} s; subpatch tests by rate 1/2/4/8/16 = {:?}, split = {}",
            scene.meshes[0].surface.patch_count(),
            c.rate_tests,
            c.finer_than_fine
        );
        before_total += before + before_occ;
        assert_eq!((after, after_occ), (0, 0), "m={m}: rays escaped through cracks");
        assert!(c.rate_tests.iter().all(|&n| n > 0) && c.finer_than_fine > 0, "every rate and splits were exercised");
    }
    assert!(before_total > 0, "the measurement must see the cracks that seams close");
}

// --- non-finite inputs and samples ------------------------------------------------------------

#[test]
fn nan_and_infinite_inputs_are_refused_with_a_clear_error() {
    let (topo, pts) = boxed([1.0; 3], Scheme::CatmullClark);
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut p = pts.clone();
        p[3][1] = bad;
        let e = OsdSurface::new("/bad", &topo, &p).unwrap_err().to_string();
        assert!(e.contains("/bad") && e.contains("non-finite") && e.contains("point 3"), "{e}");
        let e = compare("/bad", &topo, &p, &CompareOptions::quick()).unwrap_err().to_string();
        assert!(e.contains("/bad") && e.contains("non-finite"), "{e}");
        let e = BilinearSurface::new(&MeshTopology { scheme: Scheme::None, ..topo.clone() }, &p).unwrap_err().to_string();
        assert!(e.contains("points[3]"), "{e}");
        let mut t = topo.clone();
        t.crease_indices = vec![0, 1];
        t.crease_lengths = vec![2];
        t.crease_sharpnesses = vec![bad];
        let e = OsdSurface::new("/bad", &t, &pts).unwrap_err().to_string();
        assert!(e.contains("/bad") && e.contains("sharpness"), "{e}");
        // A camera or a setting that cannot work stops the render before it starts.
        let mut scene = scene_of(osd("/box", (topo.clone(), pts.clone())));
        scene.camera.render_from_camera.w_axis.x = bad;
        let e =
            render(&scene, &RenderOptions { width: 4, height: 4, ..Default::default() }, &NoProgress).err().expect("refused").to_string();
        assert!(e.contains("transform is not finite"), "{e}");
        let scene = scene_of(osd("/box", (topo.clone(), pts.clone())));
        let e = render(&scene, &RenderOptions { width: 4, height: 4, tess_factor: bad, ..Default::default() }, &NoProgress)
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("tessFactor"), "{e}");
    }
    // The delegate refuses a mesh whose transform is not finite, naming the prim.
    let data = hd_mipray::mesh::MeshData {
        topology: topo,
        points: pts,
        transform: Mat4::from_translation(Vec3::new(f32::NAN, 0.0, 0.0)),
        ..Default::default()
    };
    let e = hd_mipray::mesh::MeshPrim::new("/World/box", data, 0).sync().expect_err("refused").to_string();
    assert!(e.contains("/World/box") && e.contains("not finite"), "{e}");
}

#[test]
fn no_pixel_is_ever_non_finite_and_dropped_samples_are_counted() {
    for (radiance, spp) in [(Vec3A::splat(f32::NAN), 1u32), (Vec3A::splat(f32::INFINITY), 2)] {
        let mut scene = scene_of(osd("/box", boxed([1.0; 3], Scheme::CatmullClark)));
        scene.camera = look(Vec3::new(2.0, 1.5, 3.0), 0.1, 100.0);
        scene.lights.push(Light::distant("/sun", Vec3A::new(-0.3, -0.4, -1.0), radiance));
        let options = RenderOptions {
            width: 16,
            height: 16,
            samples: spp,
            threads: 2,
            aovs: vec![Aov::Color, Aov::Alpha, Aov::Depth, Aov::Normal],
            ..Default::default()
        };
        let out = render(&scene, &options, &NoProgress).unwrap();
        assert!(all_finite(&out.film), "{radiance}: a non-finite pixel reached the film");
        // Alpha averages the kept samples only; depth is the first sample's.
        let covered = out.film.aov("depth").unwrap().data.iter().filter(|z| **z < 100.0).count() as u64;
        // Every sample of a covered pixel is lit by the bad light; uncovered ones are finite.
        let d = dropped(&out.stats);
        assert!(covered > 0 && d >= covered * u64::from(spp), "{radiance}: {d} dropped for {covered} covered pixels × {spp}");
    }
}

// --- Loop (triangle) patches ------------------------------------------------------------------

#[test]
fn loop_patches_are_hit_only_inside_their_triangles() {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/osd-shapes/loop_icosahedron.obj"));
    let Ok(text) = text else { return };
    let shape = mipray::obj_shape::parse_obj_shape("loop_icosahedron", &text).unwrap();
    let surface = osd("/icosahedron", (shape.topology.clone(), shape.points.clone()));
    let scene = scene_of(surface.clone());
    let tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
    let mut c = TraceCounters::default();
    let mut rng = Rng(17);
    let (mut hits, mut outside) = (0, 0);
    for _ in 0..2000 {
        let target = rng.unit() * 0.3;
        let o = rng.unit() * 5.0;
        let r = beam_ray(o, (target - o).normalize(), 0.0, 0.02 * (1.0 + 10.0 * rng.f32()), RayKind::Camera);
        if let Some(h) = tracer.intersect(&r, &mut c) {
            hits += 1;
            let tri = surface.patch_param(h.patch as usize).kind.is_triangle();
            let off = (surface.evaluate(h.patch as usize, h.u, h.v).p - h.p).length();
            if tri && (h.u + h.v > 1.0 + 1e-4 || off > 0.05) {
                outside += 1;
            }
        }
    }
    assert!(hits > 1500, "{hits}");
    assert_eq!(outside, 0, "{outside} of {hits} hits lie outside their triangle patch's domain");
}

// --- self-occlusion across rates ---------------------------------------------------------------

#[test]
fn coarse_grids_of_a_surface_do_not_shadow_the_rays_leaving_it() {
    // A Catmull-Clark cube alone: a rounded, (near-)convex box that cannot shadow itself but
    // through its own tessellation. AO rays start on the camera rays' fine grids; the coarser
    // grids of the same surface near their origin — their own subpatch's, and a neighbour's
    // across a patch edge, whose facets touch the limit surface at their corners where the fine
    // chords sag below it — must not count as occluders however coarse the AO rays' rate is
    // forced. Skipping only the own subpatch, 268 of 690 pixels went dark at
    // tessFactorIncoherent 16 (mean AO 0.959, lowest 0.19; 0.991 and 0.19 at 4); skipping the
    // neighbours too leaves 5–13 pixels with one to three of 32 rays stopped (mean ≥ 0.9991,
    // lowest ≥ 0.906 at every factor): grazing rays meeting far subpatches' seam boxes, which
    // stand up to the coarse grid's chord error off the surface (`seam.rs`), a tessellation
    // error of the forced rate rather than self-intersection.
    let mut scene = scene_of(osd("/cube", common::cube()));
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(3.0, 2.5, 4.0), Vec3::ZERO, Vec3::Y), 50.0);
    for factor in [1.0f32, 4.0, 16.0, 64.0] {
        let opts = RenderOptions {
            width: 40,
            height: 30,
            ao_samples: 32,
            ao_distance: 100.0,
            tess_factor_incoherent: factor,
            aovs: vec![Aov::Ao, Aov::Alpha],
            ..Default::default()
        };
        let out = render(&scene, &opts, &NoProgress).unwrap();
        let (ao, alpha) = (&out.film.aov("ao").unwrap().data, &out.film.aov("alpha").unwrap().data);
        let covered: Vec<f32> = ao.iter().zip(alpha).filter(|(_, a)| **a > 0.0).map(|(o, _)| *o).collect();
        assert!(covered.len() > 300, "the cube fills the view: {} pixels", covered.len());
        let dark = covered.iter().filter(|o| **o < 1.0).count();
        let worst = covered.iter().cloned().fold(1.0f32, f32::min);
        let mean = covered.iter().sum::<f32>() / covered.len() as f32;
        println!("tessFactorIncoherent {factor}: {dark} of {} pixels occluded, mean AO {mean}, lowest {worst}", covered.len());
        assert!(
            mean > 0.998 && worst > 0.8,
            "tessFactorIncoherent {factor}: the surface shadowed itself: mean AO {mean}, lowest {worst}, {dark} pixels"
        );
        if factor >= 16.0 {
            let rates = &out.stats["render"]["rate_tests_by_ray"]["ao"];
            assert!(rates["1"].as_u64().unwrap() > 0, "AO rays did use coarse grids: {rates}");
        }
    }
}

#[test]
fn the_seams_setting_shows_what_seam_boxes_add_to_coarse_occluders() {
    // The cube above, AO rays at tessFactorIncoherent 16 and camera rays at finer rates than the
    // default (where the cube's AO rays used to meet far subpatches' seam boxes, which stand up to
    // the coarse chord error off the surface: 5 pixels had a ray stopped with seams, 0 without).
    // A ray leaving a surface now ignores its own instance within the two grids' chord errors
    // (a merged stride's error scaled by the stride squared), seam boxes included: with or
    // without them (`seams`, the render setting for measuring), no pixel shadows itself.
    let mut scene = scene_of(osd("/cube", common::cube()));
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(3.0, 2.5, 4.0), Vec3::ZERO, Vec3::Y), 50.0);
    let occluded = |seams: bool, tess_factor: f32| {
        let opts = RenderOptions {
            width: 40,
            height: 30,
            ao_samples: 32,
            ao_distance: 100.0,
            tess_factor,
            tess_factor_incoherent: 16.0,
            seams,
            aovs: vec![Aov::Ao, Aov::Alpha],
            ..Default::default()
        };
        let out = render(&scene, &opts, &NoProgress).unwrap();
        let (ao, alpha) = (&out.film.aov("ao").unwrap().data, &out.film.aov("alpha").unwrap().data);
        let stopped = ao.iter().zip(alpha).filter(|(o, a)| **a > 0.0 && **o < 1.0).count();
        let seam_rates = out.stats["render"]["rate_tests_by_ray"]["ao"]["1"].as_u64().unwrap();
        (stopped, seam_rates)
    };
    for tess_factor in [0.25, 0.5] {
        let ((with, rates_with), (without, rates_without)) = (occluded(true, tess_factor), occluded(false, tess_factor));
        println!("tessFactor {tess_factor}: pixels with an AO ray stopped: {with} with seam boxes, {without} without");
        assert!(rates_with > 0 && rates_without > 0, "AO rays used coarse grids");
        assert_eq!((with, without), (0, 0), "tessFactor {tess_factor}: seams {with}, no seams {without}");
    }
}

#[test]
fn a_flat_subdivision_surface_has_zero_tessellation_error_at_every_rate() {
    // A Catmull-Clark grid whose control points lie in z = 0 but are unevenly spaced: its limit
    // surface is that plane, every patch is flat but not a parallelogram (so it is tessellated at
    // the beam's rate like any patch), and every tessellation lies exactly on it. tessError is
    // zero at every rate, splits included; the tess factors below reach all of them.
    let (topo, mut pts) = grid(6, 2.0, Scheme::CatmullClark);
    let mut rng = Rng(0x5eed);
    for p in pts.iter_mut() {
        p[0] += 0.12 * (rng.f32() - 0.5);
        p[1] += 0.12 * (rng.f32() - 0.5);
    }
    let scene0 = scene_of(osd("/flat", (topo, pts)));
    let mut rates = std::collections::BTreeSet::new();
    for tess_factor in [0.02f32, 0.08, 0.3, 1.0, 4.0, 16.0, 64.0] {
        let mut scene = scene0.clone();
        scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.4, -3.0, 2.5), Vec3::ZERO, Vec3::Z), 35.0);
        let aovs = vec![Aov::TessError, Aov::TessRate, Aov::Alpha];
        let out = render(&scene, &RenderOptions { width: 32, height: 24, tess_factor, aovs, ..Default::default() }, &NoProgress).unwrap();
        let (e, rate, alpha) = (out.film.aov("tessError").unwrap(), out.film.aov("tessRate").unwrap(), out.film.aov("alpha").unwrap());
        let covered = alpha.data.iter().filter(|a| **a > 0.0).count();
        assert!(covered > 200, "tessFactor {tess_factor}: the grid fills the view ({covered} pixels)");
        let worst = e.data.iter().step_by(2).cloned().fold(0.0f32, |a, x| a.max(x.abs()));
        assert!(worst < 1e-5, "tessFactor {tess_factor}: tessError {worst} on a flat surface");
        rates.extend(rate.data.iter().zip(&alpha.data).filter(|(_, a)| **a > 0.0).map(|(r, _)| *r as u32));
    }
    for want in [1, 4, 16] {
        assert!(rates.contains(&want), "rate {want} was exercised: {rates:?}");
    }
    assert!(rates.iter().any(|&r| r > 16), "split subpatches were exercised: {rates:?}");
}
