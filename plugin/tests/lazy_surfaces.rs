//! OpenSubdiv surfaces built when a ray first reaches their mesh (issue 15): a mesh no ray
//! reaches costs its bounds, not its patch table, and the picture is the one every surface
//! built up front gives, bit for bit.

mod common;

use glam::{Mat4, Vec3};
use hd_mipray::mesh::Surface;
use hd_mipray::render_pass::PassResult;
use hd_mipray::{RenderDelegate, RenderPass, RenderSettings};
use mipray::aov::Aov;
use mipray::progress::NoProgress;
use mipray::topology::Scheme;

/// Two spheres and a creased cube in view, shadowing one another,
/// and a sphere behind the camera and off the shadow rays' way (the sun shines down −Z) that no
/// ray reaches.
fn delegate(eager: bool) -> RenderDelegate {
    let mut d = common::delegate_with_camera(Vec3::new(0.5, 1.0, 7.0), Vec3::ZERO, true);
    d.set_eager_surfaces(eager);
    let placed = |name: &str, shape, at: Vec3, grey: f32| {
        let mut m = common::grey_mesh(name, shape, grey);
        m.transform = Mat4::from_translation(at);
        m
    };
    d.set_mesh("/a", placed("/a", common::cube_sphere(3, Scheme::CatmullClark), Vec3::new(-1.2, 0.0, 0.0), 0.7));
    d.set_mesh("/b", placed("/b", common::cube_sphere(2, Scheme::CatmullClark), Vec3::new(1.3, 0.4, -0.5), 0.5));
    let mut cube = common::cube();
    cube.0.crease_indices = vec![0, 1, 2];
    cube.0.crease_lengths = vec![3];
    cube.0.crease_sharpnesses = vec![3.0];
    d.set_mesh("/c", placed("/c", cube, Vec3::new(0.0, -2.5, 0.0), 0.6));
    d.set_mesh("/behind", placed("/behind", common::cube_sphere(3, Scheme::CatmullClark), Vec3::new(15.0, 0.0, 15.0), 0.3));
    d
}

fn render(d: &mut RenderDelegate) -> PassResult {
    let pass = RenderPass {
        camera: "/cam".into(),
        width: 48,
        height: 48,
        aovs: vec![Aov::Color, Aov::Depth, Aov::Normal, Aov::Alpha],
        settings: RenderSettings { samples: 2, threads: 2, ..RenderSettings::default() },
    };
    pass.execute(d, &NoProgress).unwrap()
}

fn is_built(d: &RenderDelegate, path: &str) -> bool {
    match d.mesh(path).and_then(|m| m.surface.as_ref()) {
        Some(Surface::LazyOsd(s)) => s.is_built(),
        Some(_) => true,
        None => panic!("{path} has no surface"),
    }
}

#[test]
fn lazy_surfaces_give_the_eager_image_and_skip_meshes_no_ray_reaches() {
    let eager = render(&mut delegate(true));
    let mut d = delegate(false);
    let lazy = render(&mut d);
    for (e, l) in eager.buffers.iter().zip(&lazy.buffers) {
        assert!(e.data.iter().zip(&l.data).all(|(a, b)| a.to_bits() == b.to_bits()), "{:?} differs", e.aov);
    }
    assert!(lazy.buffers[3].data.contains(&1.0) && lazy.buffers[3].data.contains(&0.0));
    let (es, ls) = (&eager.stats["scene"], &lazy.stats["scene"]);
    assert_eq!(es["meshes_built_on_first_use"], 0);
    assert_eq!(es["meshes_not_reached"], 0);
    assert_eq!(ls["meshes_built_on_first_use"], 3, "{ls}");
    assert_eq!(ls["meshes_not_reached"], 1, "{ls}");
    assert_eq!(ls["lazy_bounds_escaped"], 0);
    // The unreached sphere's roots are not counted: the eager render has as many more as the
    // same shape at /a has patches.
    let sphere_patches = d.mesh("/a").unwrap().surface.as_ref().unwrap().as_limit_surface().patch_count() as u64;
    assert_eq!(es["subpatches"].as_u64().unwrap() - ls["subpatches"].as_u64().unwrap(), sphere_patches);
    assert!(is_built(&d, "/a") && is_built(&d, "/c"));
    assert!(!is_built(&d, "/behind"), "no ray reaches it, so no patch table");

    // A second render keeps the surfaces built by the first, and gives the same image again.
    let again = render(&mut d);
    assert_eq!(again.stats["scene"]["meshes_not_reached"], 1);
    assert!(again.buffers[0].data.iter().zip(&lazy.buffers[0].data).all(|(a, b)| a.to_bits() == b.to_bits()));
    assert_eq!(d.mesh("/a").unwrap().surface_syncs, 1);
}

#[test]
fn new_points_on_a_built_lazy_surface_give_the_eager_image() {
    let mut d = delegate(false);
    render(&mut d);
    let moved = |d: &mut RenderDelegate| {
        let (t, p) = common::cube_sphere(3, Scheme::CatmullClark);
        let p: Vec<[f32; 3]> = p.iter().map(|q| [q[0] * 1.2, q[1] * 0.9, q[2]]).collect();
        let mut m = common::grey_mesh("/a", (t, p), 0.7);
        m.transform = Mat4::from_translation(Vec3::new(-1.2, 0.0, 0.0));
        d.set_mesh("/a", m);
    };
    moved(&mut d);
    assert!(d.sync().is_empty());
    assert_eq!(d.mesh("/a").unwrap().surface_syncs, 2);
    assert!(is_built(&d, "/a"), "refined again in place at sync, not replaced by an unbuilt surface");
    let lazy = render(&mut d);
    let mut e = delegate(true);
    moved(&mut e);
    let eager = render(&mut e);
    for (a, b) in eager.buffers.iter().zip(&lazy.buffers) {
        assert!(a.data.iter().zip(&b.data).all(|(x, y)| x.to_bits() == y.to_bits()), "{:?} differs", a.aov);
    }
}

/// Twelve spheres and creased cubes in a ring around the camera's view, each its own mesh, so
/// that a small geometry budget cannot hold them all.
fn many(eager: bool) -> RenderDelegate {
    let mut d = common::delegate_with_camera(Vec3::new(0.0, 2.0, 9.0), Vec3::ZERO, true);
    d.set_eager_surfaces(eager);
    for k in 0..12 {
        let a = k as f32 * std::f32::consts::TAU / 12.0;
        let at = Vec3::new(3.2 * a.cos(), 0.6 * (k % 3) as f32 - 0.6, 3.2 * a.sin());
        let name = format!("/m{k}");
        let shape = if k % 2 == 0 {
            common::cube_sphere(3 + k % 3, Scheme::CatmullClark)
        } else {
            let mut cube = common::cube();
            cube.0.crease_indices = vec![0, 1, 2, 3];
            cube.0.crease_lengths = vec![4];
            cube.0.crease_sharpnesses = vec![2.0 + k as f32 / 4.0];
            cube
        };
        let mut m = common::grey_mesh(&name, shape, 0.3 + 0.05 * k as f32);
        m.transform = Mat4::from_translation(at) * Mat4::from_rotation_y(a);
        d.set_mesh(&name, m);
    }
    d
}

fn render_with(d: &mut RenderDelegate, budget_mb: f64, threads: usize) -> Result<PassResult, String> {
    let pass = RenderPass {
        camera: "/cam".into(),
        width: 40,
        height: 40,
        aovs: vec![Aov::Color, Aov::Depth, Aov::Normal, Aov::Alpha, Aov::PrimId],
        settings: RenderSettings { samples: 2, threads, ao_samples: 4, geometry_memory_mb: budget_mb, ..RenderSettings::default() },
    };
    pass.execute(d, &NoProgress).map_err(|e| e.to_string())
}

fn same_bits(a: &PassResult, b: &PassResult) {
    assert_eq!(a.buffers.len(), b.buffers.len());
    for (x, y) in a.buffers.iter().zip(&b.buffers) {
        assert!(x.data.iter().zip(&y.data).all(|(p, q)| p.to_bits() == q.to_bits()), "{:?} differs", x.aov);
    }
}

#[test]
fn a_geometry_budget_drops_and_rebuilds_meshes_and_keeps_the_image() {
    let unbounded = render_with(&mut many(false), f64::INFINITY, 2).unwrap();
    assert!(unbounded.stats["geometry_budget"].is_null(), "no budget, no figures");
    assert_eq!(unbounded.stats["scene"]["meshes_built_on_first_use"], 12, "every mesh in view");
    // A budget too large to drop anything tells what the render holds.
    let roomy = render_with(&mut many(false), 1e6, 2).unwrap();
    same_bits(&unbounded, &roomy);
    let b = &roomy.stats["geometry_budget"];
    assert_eq!(b["drops"], 0, "{b}");
    let fixed: u64 = b["fixed_bytes"].as_object().unwrap().values().map(|v| v.as_u64().unwrap()).sum();
    assert_eq!(b["fixed_bytes"]["geometry_cache"], 30_000_000, "the default cache's budget");
    let peak = b["peak_held_bytes"].as_u64().unwrap();
    let held = &b["held_bytes"];
    assert!(held["surfaces"].as_u64().unwrap() > 0 && held["root_subpatches"].as_u64().unwrap() > 0 && held["bvhs"].as_u64().unwrap() > 0);
    assert_eq!(peak, ["surfaces", "root_subpatches", "bvhs"].iter().map(|k| held[k].as_u64().unwrap()).sum::<u64>());

    // Room for about a quarter of the meshes' data: meshes are dropped and built again, on two
    // threads and on three, and every AOV keeps its bits.
    for threads in [2, 3] {
        let tight = fixed as f64 / 1e6 + peak as f64 / 4e6;
        let mut d = many(false);
        let small = render_with(&mut d, tight, threads).unwrap();
        same_bits(&unbounded, &small);
        let s = &small.stats["geometry_budget"];
        assert!(s["drops"].as_u64().unwrap() > 0, "{s}");
        assert!(s["rebuilds"].as_u64().unwrap() > 0, "{s}");
        assert_eq!(small.stats["scene"]["subpatches"], unbounded.stats["scene"]["subpatches"], "dropped meshes' roots still counted");
        // What the budget may hold it holds at the end (one mesh in use may exceed it, counted).
        let limit = s["droppable_limit_bytes"].as_u64().unwrap();
        let now: u64 = ["surfaces", "root_subpatches", "bvhs"].iter().map(|k| s["held_bytes"][k].as_u64().unwrap()).sum();
        assert!(now <= limit || s["builds_over_budget"].as_u64().unwrap() > 0, "{s}");

        // The next render on the same delegate starts from the surfaces this one left built,
        // counts them, and gives the same image again.
        let again = render_with(&mut d, tight, threads).unwrap();
        same_bits(&unbounded, &again);
    }

    // A budget below what cannot be dropped: one line naming the minimum.
    let Err(e) = render_with(&mut many(false), 10.0, 2) else { panic!("a 10 MB budget was taken") };
    assert!(e.contains("geometryMemoryMb=10 cannot hold") && e.contains("it needs at least 30.") && !e.contains('\n'), "{e}");
}

/// The irradiance cache's pre-pass traces on threads of its own chunks (pinned per chunk): under
/// a budget that drops meshes its records, and so the image, are the unbounded ones.
#[test]
fn a_geometry_budget_keeps_the_irradiance_cache_prepass_image() {
    let render_ic = |budget_mb: f64| {
        let pass = RenderPass {
            camera: "/cam".into(),
            width: 32,
            height: 32,
            aovs: vec![Aov::Color, Aov::Depth],
            settings: RenderSettings {
                samples: 1,
                threads: 2,
                ao_samples: 8,
                irradiance_cache: true,
                geometry_memory_mb: budget_mb,
                ..RenderSettings::default()
            },
        };
        pass.execute(&mut many(false), &NoProgress).map_err(|e| e.to_string()).unwrap()
    };
    let unbounded = render_ic(f64::INFINITY);
    let roomy = render_ic(1e6);
    let b = &roomy.stats["geometry_budget"];
    let fixed: u64 = b["fixed_bytes"].as_object().unwrap().values().map(|v| v.as_u64().unwrap()).sum();
    let small = render_ic(fixed as f64 / 1e6 + b["peak_held_bytes"].as_u64().unwrap() as f64 / 4e6);
    assert!(small.stats["geometry_budget"]["drops"].as_u64().unwrap() > 0, "{}", small.stats["geometry_budget"]);
    same_bits(&unbounded, &small);
}
