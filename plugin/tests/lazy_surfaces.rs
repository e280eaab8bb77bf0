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
