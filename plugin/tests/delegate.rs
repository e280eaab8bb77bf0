//! The render delegate end to end in Rust: sync costs in proportion to the edit, and the
//! attributes a renderer must honour change the picture.

mod common;

use glam::{Mat4, Vec3};
use hd_mipray::material::SurfaceInputs;
use hd_mipray::mesh::MeshData;
use hd_mipray::{RenderDelegate, RenderPass, RenderSettings};
use mipray::aov::Aov;
use mipray::progress::NoProgress;
use mipray::topology::{MeshTopology, Scheme};
use serde_json::Value;

/// A 3×3 grid of unit quads in z = 0 centred on the origin, as a subdivision or polygon mesh.
fn grid(scheme: Scheme) -> (MeshTopology, Vec<[f32; 3]>) {
    let (mut topo, pts) = mipray::bilinear::grid_mesh(1.5, 3, 0.0);
    topo.scheme = scheme;
    (topo, pts)
}

fn cube() -> (MeshTopology, Vec<[f32; 3]>) {
    common::cube()
}

fn data(topology: MeshTopology, points: Vec<[f32; 3]>, transform: Mat4) -> MeshData {
    MeshData { topology, points, transform, material: Some(SurfaceInputs::lambertian("/grey", [0.5; 3])), ..Default::default() }
}

fn delegate_with_camera(eye: Vec3, target: Vec3) -> RenderDelegate {
    common::delegate_with_camera(eye, target, true)
}

fn pass(aovs: &[&str]) -> RenderPass {
    RenderPass {
        camera: "/cam".into(),
        width: 32,
        height: 32,
        aovs: aovs.iter().map(|s| Aov::from_name(s).unwrap()).collect(),
        settings: RenderSettings::default(),
    }
}

fn cold(stats: &Value) -> u64 {
    stats["geometry_cache"]["tiers"].as_array().unwrap().iter().map(|t| t["cold_tessellations"].as_u64().unwrap()).sum()
}

#[test]
fn moving_one_prim_rebuilds_no_other_mesh_and_keeps_its_cache_entries() {
    let mut d = delegate_with_camera(Vec3::new(0.0, 0.0, 8.0), Vec3::ZERO);
    let (t, p) = cube();
    d.set_mesh("/a", data(t.clone(), p.clone(), Mat4::from_translation(Vec3::new(-1.5, 0.0, 0.0))));
    d.set_mesh("/b", data(t.clone(), p.clone(), Mat4::from_translation(Vec3::new(1.5, 0.0, 0.0))));
    let first = pass(&["color"]).execute(&mut d, &NoProgress).unwrap();
    assert_eq!((d.mesh("/a").unwrap().surface_syncs, d.mesh("/b").unwrap().surface_syncs), (1, 1));
    // Move /b out of view: nothing is rebuilt, and /a's tessellations are all still cached.
    d.set_mesh("/b", data(t.clone(), p.clone(), Mat4::from_translation(Vec3::new(100.0, 0.0, 0.0))));
    let second = pass(&["color"]).execute(&mut d, &NoProgress).unwrap();
    assert_eq!((d.mesh("/a").unwrap().surface_syncs, d.mesh("/b").unwrap().surface_syncs), (1, 1));
    assert!(cold(&first.stats) > 0);
    assert_eq!(cold(&second.stats), 0, "no new tessellation for the unchanged mesh");
    // New points on /a: only /a is rebuilt, and its entries are invalidated.
    let moved: Vec<[f32; 3]> = p.iter().map(|q| [q[0] * 1.1, q[1], q[2]]).collect();
    d.set_mesh("/a", data(t, moved, Mat4::from_translation(Vec3::new(-1.5, 0.0, 0.0))));
    let third = pass(&["color"]).execute(&mut d, &NoProgress).unwrap();
    assert_eq!((d.mesh("/a").unwrap().surface_syncs, d.mesh("/b").unwrap().surface_syncs), (2, 1));
    assert!(cold(&third.stats) > 0, "the edited mesh is tessellated anew");
}

#[test]
fn a_hole_removes_pixels() {
    let mut d = delegate_with_camera(Vec3::new(0.0, 0.0, 6.0), Vec3::ZERO);
    let (mut t, p) = grid(Scheme::CatmullClark);
    d.set_mesh("/g", data(t.clone(), p.clone(), Mat4::IDENTITY));
    let full = pass(&["alpha"]).execute(&mut d, &NoProgress).unwrap();
    t.hole_indices = vec![4];
    d.set_mesh("/g", data(t, p, Mat4::IDENTITY));
    let holed = pass(&["alpha"]).execute(&mut d, &NoProgress).unwrap();
    let centre = |r: &hd_mipray::render_pass::PassResult| r.buffers[0].data[16 * 32 + 16];
    assert_eq!(centre(&full), 1.0);
    assert_eq!(centre(&holed), 0.0);
    let covered = |r: &hd_mipray::render_pass::PassResult| r.buffers[0].data.iter().filter(|a| **a > 0.5).count();
    assert!(covered(&holed) < covered(&full));
}

#[test]
fn an_infinitely_sharp_crease_changes_the_limit_surface() {
    // Seen edge-on from the side, a smooth subdivided cube is a rounded blob; with every edge
    // creased infinitely sharp it is the cube itself, so it covers more pixels.
    let mut d = delegate_with_camera(Vec3::new(0.0, 0.0, 9.0), Vec3::ZERO);
    let (mut t, p) = cube();
    d.set_mesh("/c", data(t.clone(), p.clone(), Mat4::IDENTITY));
    let smooth = pass(&["alpha"]).execute(&mut d, &NoProgress).unwrap();
    let edges = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)];
    for (a, b) in edges {
        t.crease_indices.extend([a, b]);
        t.crease_lengths.push(2);
        t.crease_sharpnesses.push(10.0);
    }
    d.set_mesh("/c", data(t, p, Mat4::IDENTITY));
    let sharp = pass(&["alpha"]).execute(&mut d, &NoProgress).unwrap();
    let covered = |r: &hd_mipray::render_pass::PassResult| r.buffers[0].data.iter().filter(|a| **a > 0.5).count();
    assert!(covered(&sharp) > covered(&smooth) + 20, "{} vs {}", covered(&sharp), covered(&smooth));
}

#[test]
fn a_broken_prim_is_reported_and_the_others_render() {
    let mut d = delegate_with_camera(Vec3::new(0.0, 0.0, 6.0), Vec3::ZERO);
    let (t, p) = grid(Scheme::None);
    d.set_mesh("/good", data(t.clone(), p.clone(), Mat4::IDENTITY));
    let mut bad = t;
    bad.scheme = Scheme::Loop; // Loop needs triangles: OpenSubdiv refuses quads
    d.set_mesh("/bad", data(bad, p, Mat4::from_translation(Vec3::new(0.0, 0.0, 1.0))));
    let r = pass(&["alpha"]).execute(&mut d, &NoProgress).unwrap();
    assert_eq!(r.prim_errors.len(), 1);
    let msg = r.prim_errors[0].to_string();
    assert!(msg.starts_with("/bad: "), "{msg}");
    assert!(r.buffers[0].data.iter().any(|a| *a > 0.5), "the good mesh still renders");
    assert!(pass(&["alpha"]).execute(&mut d, &NoProgress).is_ok());
    let missing = RenderPass { camera: "/nope".into(), ..pass(&["alpha"]) };
    let e = missing.execute(&mut d, &NoProgress).err().unwrap().to_string();
    assert!(e.contains("/nope") && e.contains("/cam"), "{e}");
}

#[test]
fn each_render_reports_its_own_cache_figures() {
    // The delegate's cache lives across renders; the stats of a render are that render's.
    let mut d = delegate_with_camera(Vec3::new(0.0, 0.0, 8.0), Vec3::ZERO);
    let (t, p) = cube();
    d.set_mesh("/a", data(t, p, Mat4::IDENTITY));
    let first = pass(&["color"]).execute(&mut d, &NoProgress).unwrap();
    let second = pass(&["color"]).execute(&mut d, &NoProgress).unwrap();
    let lookups =
        |s: &Value| -> u64 { s["geometry_cache"]["tiers"].as_array().unwrap().iter().map(|t| t["lookups"].as_u64().unwrap()).sum() };
    assert!(cold(&first.stats) > 0);
    assert_eq!(cold(&second.stats), 0, "everything was tessellated by the first render");
    assert_eq!(lookups(&second.stats), lookups(&first.stats), "the same picture needs the same lookups");
    assert_eq!(second.stats["geometry_cache"]["recomputed_vertices"].as_u64(), Some(0));
}

/// Cancels once `cancelled` has been asked `after` times: a Ctrl-C arriving mid-sync.
struct CancelAfter {
    after: usize,
    asked: std::sync::atomic::AtomicUsize,
}

impl mipray::progress::Progress for CancelAfter {
    fn cancelled(&self) -> bool {
        self.asked.fetch_add(1, std::sync::atomic::Ordering::Relaxed) >= self.after
    }
}

#[test]
fn a_cancel_during_sync_stops_between_meshes_and_the_rest_sync_next_time() {
    let mut d = delegate_with_camera(Vec3::new(0.0, 0.0, 8.0), Vec3::ZERO);
    let (t, p) = cube();
    let paths: Vec<String> = (0..6).map(|i| format!("/m{i}")).collect();
    for (i, path) in paths.iter().enumerate() {
        d.set_mesh(path, data(t.clone(), p.clone(), Mat4::from_translation(Vec3::new(i as f32, 0.0, 0.0))));
    }
    let synced = |d: &RenderDelegate| paths.iter().filter(|p| d.mesh(p).unwrap().surface_syncs > 0).count();
    let cancel = CancelAfter { after: 2, asked: Default::default() };
    let e = pass(&["color"]).execute(&mut d, &cancel).err().expect("a cancelled sync is an error");
    assert!(matches!(e, hd_mipray::DelegateError::Render(mipray::error::RenderError::Cancelled)), "{e}");
    assert_eq!(synced(&d), 2, "the sync stopped at the third mesh");
    let r = pass(&["alpha"]).execute(&mut d, &NoProgress).unwrap();
    assert_eq!(synced(&d), 6, "the meshes left dirty sync on the next render");
    assert!(r.buffers[0].data.iter().any(|a| *a > 0.5));
}

#[test]
fn set_mesh_checks_the_data_once_and_every_render_reports_what_it_refused() {
    let mut d = delegate_with_camera(Vec3::new(0.0, 0.0, 6.0), Vec3::ZERO);
    let (t, p) = grid(Scheme::None);
    let mut bad_points = p.clone();
    // Named as Python's repr names them (the scene delegate's other messages): the truth is
    // `tuple(float(c) for c in np.float32([nan, 2**60, 2**-20]))`.
    bad_points[1] = [f32::NAN, 2f32.powi(60), 2f32.powi(-20)];
    let mut holes = t.clone();
    holes.hole_indices = vec![i32::try_from(t.face_count()).unwrap()];
    let cases = [
        (
            data(t.clone(), bad_points, Mat4::IDENTITY),
            "points[1] = (nan, 1.152921504606847e+18, 9.5367431640625e-07) is not finite".to_string(),
        ),
        (data(t.clone(), p.clone(), Mat4::from_scale(Vec3::splat(f32::INFINITY))), "transform is not finite".to_string()),
        (data(holes, p.clone(), Mat4::IDENTITY), format!("holeIndices[0] = {0} is out of range for {0} faces", t.face_count())),
    ];
    for (mesh, reason) in cases {
        d.set_mesh("/bad", mesh);
        let problem = d.mesh_problem("/bad").map(|e| e.to_string());
        assert_eq!(problem.as_deref(), Some(format!("/bad: {reason}").as_str()));
        let r = pass(&["alpha"]).execute(&mut d, &NoProgress).unwrap();
        assert_eq!(r.prim_errors.iter().map(ToString::to_string).collect::<Vec<_>>(), [format!("/bad: {reason}")]);
        assert!(r.buffers[0].data.iter().all(|a| *a == 0.0), "nothing of the refused mesh is drawn");
    }
    // A transform-only fix clears a refusal that was for the transform alone.
    d.set_mesh("/bad", data(t.clone(), p.clone(), Mat4::from_scale(Vec3::splat(f32::NAN))));
    assert!(d.mesh_problem("/bad").is_some());
    d.set_transform("/bad", Mat4::IDENTITY).unwrap();
    assert!(d.mesh_problem("/bad").is_none());
    let r = pass(&["alpha"]).execute(&mut d, &NoProgress).unwrap();
    assert!(r.prim_errors.is_empty(), "{:?}", r.prim_errors);
    assert!(r.buffers[0].data.iter().any(|a| *a > 0.5), "the mended mesh renders");
}
