//! Displacement at tessellation time: the surface moves, bounds hold it, shading follows it, and
//! a bound that is too small is counted and warned about rather than clipped.

use std::sync::{Arc, Mutex};

use glam::{Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::displacement::Displacement;
use mipray::geometry_cache::{CacheConfig, CacheKey, GeometryCache, Tier};
use mipray::prelude::*;
use mipray::render::render_with_cache;

fn plane(half: f32, n: i32) -> BilinearSurface {
    let (topo, pts) = mipray::bilinear::grid_mesh(half, n, 0.0);
    BilinearSurface::new(&topo, &pts).unwrap()
}

fn scene(displacement: Option<Displacement>, bound: f32) -> Scene {
    let mut scene = Scene::default();
    let mut mesh = Mesh::new("/ground", Arc::new(plane(2.0, 8)));
    mesh.displacement = displacement.map(Into::into);
    mesh.displacement_bound = bound;
    let m = scene.add_mesh(mesh);
    scene.add_instance(m, Mat4::IDENTITY);
    scene.lights.push(Light::distant("/sun", Vec3A::new(0.4, 0.3, -1.0), Vec3A::ONE));
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), 30.0, 30.0);
    scene
}

#[test]
fn displaced_surface_moves_within_its_bound_and_shades_by_its_own_normal() {
    let d = Displacement { amplitude: 0.1, frequency: 1.5, octaves: 4, gain: 0.5 };
    let flat = render(
        &scene(None, 0.0),
        &RenderOptions { width: 32, height: 32, aovs: vec![Aov::Color, Aov::Depth, Aov::Normal], ..Default::default() },
        &NoProgress,
    )
    .unwrap();
    let opts = RenderOptions { width: 32, height: 32, aovs: vec![Aov::Color, Aov::Depth, Aov::Normal], ..Default::default() };
    let bumpy = render(&scene(Some(d), d.bound()), &opts, &NoProgress).unwrap();
    let depth = &bumpy.film.aov("depth").unwrap().data;
    let moved = depth.iter().filter(|z| (**z - 5.0).abs() > 1e-3).count();
    assert!(moved > depth.len() / 2, "most of the surface moved: {moved}");
    assert!(depth.iter().all(|z| (*z - 5.0).abs() <= d.bound() + 1e-4), "within the bound");
    let normals = &bumpy.film.aov("normal").unwrap().data;
    let tilted = normals.chunks(3).filter(|n| n[2] < 0.999).count();
    assert!(tilted > depth.len() / 2, "shading normals follow the displaced surface: {tilted}");
    assert_ne!(flat.film.aov("color").unwrap().data, bumpy.film.aov("color").unwrap().data);
    assert_eq!(bumpy.stats["scene"]["displaced_vertices_outside_bounds"].as_u64(), Some(0));
}

/// Warnings logged by any test of this binary, as (target, message).
static WARNINGS: Mutex<Vec<(String, String)>> = Mutex::new(Vec::new());

/// A logger that keeps warnings (and worse) for tests to read.
struct Recorder;

impl log::Log for Recorder {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        metadata.level() <= log::Level::Warn
    }
    fn log(&self, record: &log::Record) {
        if self.enabled(record.metadata()) {
            WARNINGS.lock().unwrap().push((record.target().to_string(), record.args().to_string()));
        }
    }
    fn flush(&self) {}
}

fn record_warnings() {
    static RECORDER: Recorder = Recorder;
    // Already set by another test of this binary: the same recorder.
    let _ = log::set_logger(&RECORDER);
    log::set_max_level(log::LevelFilter::Warn);
}

#[test]
fn a_bound_too_small_is_counted_not_clipped() {
    record_warnings();
    let d = Displacement { amplitude: 0.2, frequency: 1.5, octaves: 3, gain: 0.5 };
    let bound = 0.01;
    let mut scene = scene(Some(d), bound);
    let name = "/ground_with_too_small_a_bound";
    scene.meshes[0].name = name.into();
    // An unbounded cache builds each tessellation once and keeps it: afterwards it holds every
    // displaced vertex the render made, to compare with the displacement's own formula.
    let opts =
        RenderOptions { width: 16, height: 16, threads: 2, cache: CacheConfig::unbounded(), aovs: vec![Aov::Depth], ..Default::default() };
    let cache = Arc::new(GeometryCache::new(CacheConfig::unbounded()));
    let out = render_with_cache(&scene, &opts, Some(cache.clone()), &NoProgress).unwrap();
    let counted = out.stats["scene"]["displaced_vertices_outside_bounds"].as_u64().unwrap();
    assert!(counted > 0);

    // Warned once for the render, naming the mesh and the primvar that fixes it.
    let warnings: Vec<String> = WARNINGS.lock().unwrap().iter().filter(|(_, m)| m.contains(name)).map(|(_, m)| m.clone()).collect();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(warnings[0].contains("primvars:displacementBound") && warnings[0].contains(&bound.to_string()), "{}", warnings[0]);

    // Every stored vertex is where the displacement puts it: the plane's exact point at the
    // grid's (u, v), moved along its normal (+z) by the noise filtered at the grid's spacing
    // (0.5-unit patches; on this plane an edge's own chords, which boundary vertices are
    // filtered at, are that spacing too) or, at a patch's corners, unfiltered (docs/cracks.md
    // rule 5: shared edges displaced alike), however far that is outside the subpatch's box;
    // none is clamped.
    let surface = &scene.meshes[0].surface;
    let (mut vertices, mut outside, mut furthest) = (0u64, 0u64, 0.0f32);
    for patch in 0..surface.patch_count() {
        let bounds = surface.patch_bounds(patch).expanded(bound);
        for tier in Tier::ALL {
            let key = CacheKey::new(0, 0, patch as u32, tier);
            if !cache.contains(key) {
                continue;
            }
            let grid = cache.get_or_build(key, || unreachable!("resident"));
            let n = grid.n;
            let spacing = 0.5 / (n - 1) as f32;
            for j in 0..n {
                for i in 0..n {
                    let p = surface.evaluate(patch, i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32).p;
                    let corner = (i == 0 || i == n - 1) && (j == 0 || j == n - 1);
                    let expected = p + Vec3A::Z * d.offset(p, if corner { 0.0 } else { spacing });
                    let got = grid.vert(i, j);
                    assert!((got - expected).abs().max_element() < 1e-5, "patch {patch} {tier:?} ({i}, {j}): {got} vs {expected}");
                    vertices += 1;
                    if !(got.cmpge(bounds.min).all() && got.cmple(bounds.max).all()) {
                        outside += 1;
                    }
                    furthest = furthest.max(got.z.abs());
                }
            }
        }
    }
    assert!(vertices > 0);
    assert!(furthest > 5.0 * bound, "some vertex is far outside its box: {furthest}");
    // Each tessellation was built once, so the count is exactly the stored vertices outside.
    assert_eq!(outside, counted, "of {vertices} stored vertices");
}

/// Two neighbours of different shapes read at one rate displace the points of their shared edge
/// alike (issue 23): each edge is filtered at its own chord length and corners unfiltered, not
/// at each grid's own spacing, which differs with the patch's shape.
#[test]
fn neighbours_of_different_shapes_displace_their_shared_edge_alike() {
    use mipray::patch::{GridSamples, UvRect};
    use mipray::subpatch::Subpatch;
    use mipray::tessellate::{tessellate, DisplaceParams};
    // A unit square and a 2.5-wide rectangle sharing the edge x = 1.13 (off the noise's
    // lattice, where every octave is 0).
    let (x, y) = (0.13, 0.29);
    let pts = vec![[x, y, 0.0], [x + 1.0, y, 0.0], [x + 3.5, y, 0.0], [x, y + 1.0, 0.0], [x + 1.0, y + 1.0, 0.0], [x + 3.5, y + 1.0, 0.0]];
    let topo = MeshTopology {
        scheme: Scheme::None,
        face_vertex_counts: vec![4, 4],
        face_vertex_indices: vec![0, 1, 4, 3, 1, 2, 5, 4],
        ..Default::default()
    };
    let surface = BilinearSurface::new(&topo, &pts).unwrap();
    // Octaves from 1/3 down to 1/24 unit: the two grids' spacings filter them differently.
    let d = Displacement { amplitude: 0.1, frequency: 3.0, octaves: 4, gain: 0.7 };
    let params = DisplaceParams { displacement: d.into(), normal_sign: 1.0, bound: d.bound(), texture_edges_alike: false };
    let bounds = mipray::bounds::Bounds3 { min: Vec3A::new(-1.0, -1.0, -1.0), max: Vec3A::new(4.0, 2.0, 1.0) };
    let mut scratch = GridSamples::default();
    for tier in [Tier::Coarse, Tier::Medium, Tier::Fine] {
        let mut grid = |patch| {
            let sub = Subpatch { patch, rect: UvRect::UNIT, bounds, affine: false };
            tessellate(&surface, &sub, tier, Some(&params), &mut scratch).0
        };
        let (a, b) = (grid(0), grid(1));
        // The plane's normal is z: displaced points keep their (x, y).
        let edge = |t: &mipray::tessellate::Tessellation| {
            let mut e: Vec<[f32; 3]> = t.verts.iter().copied().filter(|p| (p[0] - (x + 1.0)).abs() < 1e-5).collect();
            e.sort_by(|p, q| p[1].total_cmp(&q[1]));
            e
        };
        let (ea, eb) = (edge(&a), edge(&b));
        assert_eq!(ea.len(), tier.verts_per_side() as usize, "{tier:?}: the shared edge's vertices");
        assert_eq!(ea.len(), eb.len());
        for (p, q) in ea.iter().zip(&eb) {
            assert!((p[1] - q[1]).abs() < 1e-6 && (p[2] - q[2]).abs() < 1e-6, "{tier:?}: {p:?} against {q:?}");
        }
        assert!(ea.iter().any(|p| p[2].abs() > 1e-3), "{tier:?}: the edge is displaced");
    }
}
