//! The delegate keeps its geometry cache between renders; the cache changes the cost, never the
//! answer. Magnified views split subpatches into children on demand (the paper's §5.1), whose
//! cache keys must mean the same child in every render: a render on a warm cache must give the
//! same image, bit for bit, as the same render on a cold one, whatever rendered before it.

mod common;

use glam::Vec3;
use hd_mipray::camera::Camera;
use hd_mipray::render_pass::PassResult;
use hd_mipray::{RenderDelegate, RenderPass, RenderSettings};
use mipray::aov::Aov;
use mipray::progress::NoProgress;
use mipray::topology::Scheme;

/// A view of the Catmull-Clark cube sphere (control points on the unit sphere) from 6 units
/// away along `dir`, 0.03 units wide: at 24 pixels a ray is about 0.001 wide where it meets the
/// surface, so its patches (about 0.15 units across) want more than 16·2^3 quads a side and
/// split 4 deep. `dir` picks which patches and which of their children are seen.
fn magnified(dir: Vec3) -> Camera {
    Camera {
        render_from_camera: Camera::look_at(dir.normalize() * 6.0, Vec3::ZERO, Vec3::Y),
        focal_length: 400.0,
        horizontal_aperture: 2.0,
        vertical_aperture: 2.0,
        clipping_range: (0.1, 100.0),
        ..Default::default()
    }
}

fn delegate() -> RenderDelegate {
    let mut d = common::delegate_with_camera(Vec3::new(0.0, 0.0, 6.0), Vec3::ZERO, true);
    d.set_mesh("/sphere", common::grey_mesh("/sphere", common::cube_sphere(2, Scheme::CatmullClark), 0.7));
    d
}

/// The direction of the view every test renders last, and of those that render first.
const VIEW: Vec3 = Vec3::new(1.0, 0.3, 0.2);
const OTHER: Vec3 = Vec3::new(0.2, 1.0, 0.5);
const THIRD: Vec3 = Vec3::new(-0.4, 0.1, 1.0);

fn render(d: &mut RenderDelegate, dir: Vec3, size: usize, threads: usize) -> PassResult {
    d.set_camera("/cam", magnified(dir));
    let pass = RenderPass {
        camera: "/cam".into(),
        width: size,
        height: size,
        aovs: vec![Aov::Color, Aov::Depth, Aov::Normal, Aov::Alpha],
        settings: RenderSettings { samples: 2, threads, ..RenderSettings::default() },
    };
    let out = pass.execute(d, &NoProgress).unwrap();
    assert!(out.stats["scene"]["split_subpatches"].as_u64().unwrap() > 0, "the view splits subpatches");
    out
}

/// Renders each of `first` (direction, size) on one delegate, then `again` on it (a warm
/// cache), and requires `again`'s buffers to equal those of `again` on a fresh (cold) delegate.
fn warm_matches_cold(first: &[(Vec3, usize)], again: (Vec3, usize), threads: usize) {
    let cold = render(&mut delegate(), again.0, again.1, threads);
    assert!(cold.buffers[3].data.iter().all(|&a| a == 1.0), "every pixel sees the sphere");
    let mut d = delegate();
    for &(dir, size) in first {
        render(&mut d, dir, size, threads);
    }
    let warm = render(&mut d, again.0, again.1, threads);
    let hits: u64 = (0..3).map(|t| warm.stats["geometry_cache"]["tiers"][t]["hits"].as_u64().unwrap()).sum();
    assert!(hits > 0, "the last render was served from the warm cache");
    for (w, c) in warm.buffers.iter().zip(&cold.buffers) {
        let differ = w.data.iter().zip(&c.data).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
        assert_eq!(differ, 0, "{}: {differ} of {} values differ after {first:?} on the same delegate", w.aov, w.data.len());
    }
}

#[test]
fn the_same_render_again_on_a_warm_cache_matches_a_cold_one() {
    warm_matches_cold(&[(VIEW, 24)], (VIEW, 24), 1);
}

#[test]
fn a_render_after_other_views_on_a_warm_cache_matches_a_cold_one() {
    // The first views split other patches first (and other children of the patches they share).
    warm_matches_cold(&[(OTHER, 24)], (VIEW, 24), 1);
    warm_matches_cold(&[(THIRD, 24), (OTHER, 24)], (VIEW, 24), 1);
}

#[test]
fn a_render_after_another_image_size_on_a_warm_cache_matches_a_cold_one() {
    // A larger image has narrower rays: it splits deeper, and reaches children in another order.
    warm_matches_cold(&[(VIEW, 48)], (VIEW, 24), 1);
}

#[test]
fn warm_and_cold_renders_match_with_several_threads() {
    // Threads reach children in no fixed order, even for the same view.
    warm_matches_cold(&[(VIEW, 24)], (VIEW, 24), 4);
    warm_matches_cold(&[(OTHER, 32)], (VIEW, 24), 4);
}
