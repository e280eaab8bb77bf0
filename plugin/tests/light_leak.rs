//! No light crosses a closed surface (issue 23): a camera inside a closed, bumpy shell lit only
//! from outside sees exactly nothing, and a shell lit only from inside shows nothing outside —
//! for every integrator, subdivision scheme and tessellation rate, displaced or not.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::sync::Arc;

use common::{beam_ray, cube_sphere, Rng};
use glam::{Mat4, Vec3, Vec3A};
use mipray::camera::Camera;
use mipray::displacement::{Displacement, TextureDisplacement};
use mipray::geometry_cache::CacheConfig;
use mipray::image_io::{ChannelFormat, ImageBuf, ImageIo};
use mipray::light::LightShape;
use mipray::material::{Material, PreviewSurface};
use mipray::options::IntegratorKind;
use mipray::prelude::*;
use mipray::ray::{Ray, RayKind};
use mipray::texture::{Interpolation, Primvar2, Wrap};
use mipray::trace::{TraceCounters, Tracer};
use mipray_bridge::{OiioImageIo, OiioTextureOptions, OiioTextureSystem, OsdOptions, OsdSurface};

/// Radius of the shells, render units.
const RADIUS: f32 = 3.0;

/// The cube sphere of `m × m` quads a face, scaled to [`RADIUS`] and bumped along the radius by
/// 8 % (a few waves across each face), so the surface is concave and convex by turns.
fn bumpy_points(m: usize) -> (mipray::topology::MeshTopology, Vec<[f32; 3]>) {
    let (topo, pts) = cube_sphere(m, Scheme::CatmullClark);
    let pts = pts
        .into_iter()
        .map(|p| {
            let v = Vec3A::from(p);
            let bump = 1.0 + 0.08 * (5.0 * v.x).sin() * (4.0 * v.y).cos() * (3.0 * v.z + 1.0).sin();
            (v * (RADIUS * bump)).into()
        })
        .collect();
    (topo, pts)
}

/// The same shell as triangles (each quad cut along a diagonal), for Loop subdivision.
fn triangulated(topo: &mipray::topology::MeshTopology) -> mipray::topology::MeshTopology {
    let idx: Vec<i32> = topo.face_vertex_indices.chunks(4).flat_map(|q| [q[0], q[1], q[2], q[0], q[2], q[3]]).collect();
    mipray::topology::MeshTopology {
        scheme: Scheme::Loop,
        face_vertex_counts: vec![3; idx.len() / 3],
        face_vertex_indices: idx,
        ..Default::default()
    }
}

#[derive(Clone, Copy, Debug)]
enum Shell {
    CatmullClark,
    Loop,
    Displaced,
    /// Displaced by a bumpy height texture read through `st` (docs/cracks.md rules 4 and 5 for
    /// textures).
    Textured,
}

/// Texels a side of the height texture.
const HEIGHT_RES: usize = 64;

/// A bumpy height texture (one float channel in [0, 1], waves of 5 to 16 texels), written once
/// per test process; its path.
fn height_texture() -> &'static str {
    static PATH: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    PATH.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("mipray-light-leak-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("height.exr");
        let tau = std::f32::consts::TAU;
        let n = HEIGHT_RES as f32;
        let pixels = (0..HEIGHT_RES * HEIGHT_RES)
            .map(|k| {
                let (s, t) = ((k % HEIGHT_RES) as f32 / n, (k / HEIGHT_RES) as f32 / n);
                let h = 0.6 * (tau * 4.0 * s).sin() * (tau * 5.0 * t).cos() + 0.4 * (tau * (11.0 * s + 7.0 * t)).sin();
                0.5 + 0.5 * h
            })
            .collect();
        let image = ImageBuf { width: HEIGHT_RES, height: HEIGHT_RES, channels: vec!["Y".into()], pixels, metadata: Vec::new() };
        OiioImageIo.write(&file, &image, &[ChannelFormat::Float], &[]).unwrap();
        file.to_str().unwrap().to_string()
    })
}

/// The shell's `st` (vertex interpolated, so continuous across every edge): a projection of
/// the unit cube sphere's points `unit` onto a plane, within [0.16, 0.84]².
fn shell_st(unit: &[[f32; 3]]) -> Primvar2 {
    Primvar2 {
        name: "st".into(),
        interpolation: Interpolation::Vertex,
        values: unit.iter().map(|p| [0.5 + 0.3 * (p[0] + 0.5 * p[2]), 0.5 + 0.3 * (p[1] - 0.5 * p[2])]).collect(),
        indices: Vec::new(),
    }
}

/// A scene holding one closed shell of a grey, partly glossy material (diffuse, a rough
/// specular lobe, so light and BSDF samples both count).
fn shell_scene(shell: Shell) -> Scene {
    let (topo, pts) = bumpy_points(6);
    let (topo, displacement) = match shell {
        Shell::CatmullClark | Shell::Textured => (topo, None),
        Shell::Loop => (triangulated(&topo), None),
        Shell::Displaced => (topo, Some(Displacement { amplitude: 0.15, frequency: 1.5, octaves: 3, gain: 0.5 })),
    };
    let surface = match shell {
        Shell::Textured => {
            let (_, unit) = cube_sphere(6, Scheme::CatmullClark);
            OsdSurface::with_primvars("/shell", &topo, &pts, &OsdOptions::DEFAULT, &[shell_st(&unit)])
        }
        _ => OsdSurface::new("/shell", &topo, &pts),
    };
    let surface = Arc::new(surface.unwrap_or_else(|e| panic!("{e}")));
    let mut scene = Scene::default();
    let mut mesh = Mesh::new("/shell", surface);
    if let Some(d) = displacement {
        mesh.displacement_bound = d.bound();
        mesh.displacement = Some(d.into());
    }
    if let Shell::Textured = shell {
        let sampler = Arc::new(OiioTextureSystem::new(OiioTextureOptions::default()).unwrap());
        let mut t = TextureDisplacement::new(sampler, height_texture(), 0).unwrap();
        // Texel values in [0, 1] as ±0.15 units, the procedural shell's amplitude.
        (t.scale, t.bias) = (0.3, -0.15);
        (t.lookup.wrap_s, t.lookup.wrap_t) = (Wrap::Periodic, Wrap::Periodic);
        mesh.displacement_bound = t.bound();
        mesh.displacement = Some(t.into());
    }
    let surface = PreviewSurface {
        diffuse_color: Vec3A::splat(0.7),
        use_specular_workflow: true,
        specular_color: Vec3A::splat(0.3),
        roughness: 0.4,
        ..PreviewSurface::default()
    };
    mesh.material = scene.add_material(Material::preview_surface("/grey", surface).0);
    let m = scene.add_mesh(mesh);
    scene.add_instance(m, Mat4::IDENTITY);
    scene
}

/// Lights all outside the shell (a dome, a sun with a disc, a sphere, a rect facing it).
fn lights_outside() -> Vec<Light> {
    let area = |name: &str, shape| Light::usd_area(name, shape, 50.0, 0.0, Vec3A::ONE, false);
    vec![
        area("/dome", LightShape::Dome(None)),
        Light::usd_distant("/sun", &Camera::look_at(Vec3::ZERO, Vec3::new(-0.3, -0.4, -1.0), Vec3::Y), 20.0, 0.0, Vec3A::ONE, 1.0, false),
        area("/sphere", LightShape::Sphere { center: Vec3A::new(6.0, 2.0, 1.0), radius: 1.0 }),
        area("/rect", LightShape::Rect { center: Vec3A::new(0.0, -6.0, 0.0), u: Vec3A::X * 2.0, v: Vec3A::Z * 2.0, normal: Vec3A::Y }),
    ]
}

/// Lights inside the shell only.
fn lights_inside() -> Vec<Light> {
    let area = |name: &str, shape| Light::usd_area(name, shape, 50.0, 0.0, Vec3A::ONE, false);
    vec![
        area("/sphere", LightShape::Sphere { center: Vec3A::new(0.5, 0.3, -0.2), radius: 0.5 }),
        area("/rect", LightShape::Rect { center: Vec3A::new(0.0, -1.5, 0.0), u: Vec3A::X * 0.8, v: Vec3A::Z * 0.8, normal: Vec3A::Y }),
    ]
}

/// A 90° camera at `eye` looking at `target`.
fn camera(eye: Vec3, target: Vec3) -> Camera {
    let mut c = Camera::perspective(Camera::look_at(eye, target, Vec3::Y), 10.0);
    c.vertical_aperture = c.horizontal_aperture;
    c.clipping_range = (1e-3, 1e3);
    c
}

/// The brightest colour channel of the render and how many pixels are not exactly 0.
fn brightest(scene: &Scene, integrator: IntegratorKind, tess_factor: f32, incoherent: f32, floor: bool) -> (f32, usize) {
    let options = RenderOptions {
        width: 12,
        height: 12,
        samples: 2,
        threads: 2,
        tess_factor,
        tess_factor_incoherent: incoherent,
        integrator,
        shadow_samples: 2,
        indirect_samples: 4,
        ao_samples: if integrator == IntegratorKind::Ao { 4 } else { 0 },
        max_depth: 3,
        // Rule 4 of docs/cracks.md, off by default: without it the displaced shells leak.
        displacement_rate_floor: floor,
        ..Default::default()
    };
    let out = render(scene, &options, &NoProgress).unwrap_or_else(|e| panic!("{e}"));
    let c = &out.film.aov("color").unwrap().data;
    (c.iter().copied().fold(0.0, f32::max), c.chunks(3).filter(|p| p.iter().any(|x| *x != 0.0)).count())
}

const INTEGRATORS: [IntegratorKind; 4] = [IntegratorKind::Direct, IntegratorKind::Ao, IntegratorKind::ColorBleeding, IntegratorKind::Path];

/// The integrators whose images depend on the lights: ambient occlusion does not (it is the
/// open sky's share, lit or not), so it can only show a leak from inside the shell looking at
/// its inner side, where every occlusion ray must be blocked.
const LIT_INTEGRATORS: [IntegratorKind; 3] = [IntegratorKind::Direct, IntegratorKind::ColorBleeding, IntegratorKind::Path];

/// Every (shell, integrator, tess factor) whose render is not exactly 0 everywhere, for the
/// `shells`, `lights`, the camera placements `views` and `integrators`, with the displaced
/// rate floor (`displacementRateFloor`) on or off.
fn leaks(shells: &[Shell], lights: fn() -> Vec<Light>, views: &[(Vec3, Vec3)], integrators: &[IntegratorKind], floor: bool) -> Vec<String> {
    let mut leaks = Vec::new();
    for &shell in shells {
        let mut scene = shell_scene(shell);
        scene.lights = lights();
        for &(eye, target) in views {
            scene.camera = camera(eye, target);
            for &integrator in integrators {
                for (tess, incoherent) in [(0.25, 1.0), (1.0, 1.0), (4.0, 1.0), (16.0, 1.0), (16.0, 32.0)] {
                    let (max, lit) = brightest(&scene, integrator, tess, incoherent, floor);
                    println!("{shell:?} {integrator:?} tess {tess} incoherent {incoherent}: max {max:.3e} over {lit} pixels");
                    if lit > 0 {
                        leaks.push(format!("{shell:?} {integrator:?} tess {tess}/{incoherent}: {lit} pixels, max {max:.3e}"));
                    }
                }
            }
        }
    }
    leaks
}

const OUTSIDE_VIEWS: [(Vec3, Vec3); 2] = [(Vec3::ZERO, Vec3::new(1.0, 0.2, 0.3)), (Vec3::new(0.5, -0.5, 0.5), Vec3::new(-1.0, 0.3, -0.6))];
const INSIDE_VIEWS: [(Vec3, Vec3); 2] = [(Vec3::new(0.0, 2.0, 9.0), Vec3::ZERO), (Vec3::new(-7.0, -3.0, 1.0), Vec3::ZERO)];

#[test]
fn no_light_from_outside_reaches_a_camera_inside_a_closed_shell() {
    let leaks = leaks(&[Shell::CatmullClark, Shell::Loop], lights_outside, &OUTSIDE_VIEWS, &INTEGRATORS, true);
    assert!(leaks.is_empty(), "light crossed the shell:\n{}", leaks.join("\n"));
}

#[test]
fn no_light_from_inside_a_closed_shell_gets_out() {
    let leaks = leaks(&[Shell::CatmullClark, Shell::Loop], lights_inside, &INSIDE_VIEWS, &LIT_INTEGRATORS, true);
    assert!(leaks.is_empty(), "light crossed the shell:\n{}", leaks.join("\n"));
}

/// The displaced shell, both ways (docs/cracks.md, "Displaced shells"): its rates never
/// coarser than the displacement's detail, shared edges displaced alike, and rays leaving it
/// reading the surface near their origin at their origin's rate.
#[test]
fn no_light_crosses_a_closed_displaced_shell() {
    let mut found = leaks(&[Shell::Displaced], lights_outside, &OUTSIDE_VIEWS, &INTEGRATORS, true);
    found.extend(leaks(&[Shell::Displaced], lights_inside, &INSIDE_VIEWS, &LIT_INTEGRATORS, true));
    assert!(found.is_empty(), "light crossed the shell:\n{}", found.join("\n"));
}

/// The texture-displaced shell, both ways, with `floor` (`displacementRateFloor`): the lit
/// pixels and the renders they were in.
fn texture_shell_leaks(floor: bool) -> (usize, Vec<String>) {
    let mut found = leaks(&[Shell::Textured], lights_outside, &OUTSIDE_VIEWS, &INTEGRATORS, floor);
    found.extend(leaks(&[Shell::Textured], lights_inside, &INSIDE_VIEWS, &LIT_INTEGRATORS, floor));
    let pixels = found.iter().filter_map(|l| l.split(": ").nth(1)?.split(' ').next()?.parse::<usize>().ok()).sum();
    (pixels, found)
}

/// The texture-displaced shell, both ways, with the rate floor on: the floor from the finest
/// MIP level's texels over the patches' `st`, shared edges read with their own `st` step, and
/// rule 6 (docs/cracks.md).
#[test]
fn no_light_crosses_a_closed_texture_displaced_shell() {
    let scene = shell_scene(Shell::Textured);
    let mut tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
    tracer.set_displacement_rate_floor(true);
    let mut c = TraceCounters::default();
    let _ = tracer.intersect(&beam_ray(Vec3A::ZERO, Vec3A::X, 0.0, 0.01, RayKind::Camera), &mut c);
    let floor = tracer.mesh_geometry().filter_map(|g| g.texture_rate_floor_computed()).fold(0.0, f32::max);
    println!("texture-displaced shell: rate floor {floor}");
    // Patches span about 0.1 in `st`, some 6-7 of the 64 texels: a floor between the medium and
    // the fine tier, from the texture, not the cap.
    assert!(floor > 4.0 && floor < 16.0, "the floor follows the texels: {floor}");
    let (pixels, found) = texture_shell_leaks(true);
    assert_eq!(pixels, 0, "light crossed the shell:\n{}", found.join("\n"));
}

/// Rays through the wall of the closed displaced shell, each with its own beam spread (so
/// neighbouring subpatches are tested at every mix of the rates its floor leaves and of split
/// depths): from inside the
/// cavity outward, and from outside inward. Returns (rays that got through, shadow rays that
/// got through) of `rays` each way, the rates used and the shell's rate floor.
fn displaced_crack_escapes(rays: usize, seed: u64) -> (usize, usize, TraceCounters, f32) {
    let scene = shell_scene(Shell::Displaced);
    let mut tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
    tracer.set_displacement_rate_floor(true);
    let mut c = TraceCounters::default();
    let mut rng = Rng(seed);
    let (mut escapes, mut unoccluded) = (0, 0);
    // The wall lies within 3 ± (8 % of 3 + the displacement bound) of the centre.
    let (inner, outer) = (0.85 * (RADIUS * 0.92 - 0.27), 1.2 * (RADIUS * 1.08 + 0.27));
    for k in 0..2 * rays {
        // Spread from 1/256 to 2 radians per unit distance.
        let spread = 2.0 * 2f32.powf(-9.0 * rng.f32());
        let r = if k % 2 == 0 {
            beam_ray(rng.unit() * (inner * rng.f32().sqrt()), rng.unit(), 0.0, spread, RayKind::Camera)
        } else {
            // From outside to a point of the cavity.
            let o = rng.unit() * outer;
            let to = rng.unit() * (inner * rng.f32().sqrt()) - o;
            Ray { t_max: to.length(), ..beam_ray(o, to.normalize(), 0.0, spread, RayKind::Camera) }
        };
        escapes += usize::from(tracer.intersect(&r, &mut c).is_none());
        unoccluded += usize::from(!tracer.occluded(&Ray { kind: RayKind::Shadow, ..r }, &mut c));
    }
    let floor = tracer.mesh_geometry().map(|g| g.rate_floor).fold(0.0, f32::max);
    (escapes, unoccluded, c, floor)
}

/// Before the rate floor about one ray in 6,000 got through (docs/cracks.md).
#[test]
fn no_ray_gets_through_a_closed_displaced_shell_at_any_mix_of_rates() {
    let rays: usize = std::env::var("MIPRAY_CRACK_RAYS").ok().and_then(|s| s.parse().ok()).unwrap_or(20_000);
    let (escapes, unoccluded, c, floor) = displaced_crack_escapes(rays, 11);
    println!(
        "displaced shell: {rays} rays each way: through {escapes} (shadow rays {unoccluded}); subpatch tests by rate 1/2/4/8/16 = {:?}, split = {}",
        c.rate_tests, c.finer_than_fine
    );
    // The shell's fBm has detail down to 1/6 unit on patches of about 0.8: its floor is the fine
    // tier, so the rates it mixes are 16 × 16 and every split depth the beams ask for.
    assert!(floor >= 16.0, "the shell's rate floor is the fine tier: {floor}");
    assert!(c.rate_tests[..4].iter().all(|&n| n == 0), "no subpatch was read below the floor: {:?}", c.rate_tests);
    assert!(c.rate_tests[4] > 0 && c.finer_than_fine > 0, "the fine rate and splits were exercised");
    assert_eq!((escapes, unoccluded), (0, 0), "rays got through the displaced shell's cracks");
}

/// Secondary rays from points of a displaced shell's wall, seen from the cavity, aimed at points
/// far outside on the viewer's side of the hit (so each must cross the wall), without the rate
/// floor: (rays sent, rays that got through). Each camera and secondary ray has its own beam
/// spread, from 1/256 to 2 radians a unit, so origins lie on grids of every rate and split depth
/// and the rays read their neighbours at every rate.
fn secondary_escapes(shell: Shell, cameras: usize, seed: u64) -> (usize, usize) {
    let scene = shell_scene(shell);
    let tracer = Tracer::new(&scene, CacheConfig::unbounded(), 1.0);
    let mut c = TraceCounters::default();
    let mut rng = Rng(seed);
    let inner = 0.85 * (RADIUS * 0.92 - 0.27);
    let (mut sent, mut escapes) = (0, 0);
    for _ in 0..cameras {
        let spread = 2.0 * 2f32.powf(-9.0 * rng.f32());
        let r = beam_ray(rng.unit() * (inner * rng.f32().sqrt()), rng.unit(), 0.0, spread, RayKind::Camera);
        let Some(h) = tracer.intersect(&r, &mut c) else { continue };
        let view_ng = if r.d.dot(h.ng) < 0.0 { h.ng } else { -h.ng };
        for k in 0..8 {
            let target = rng.unit() * 20.0;
            let wi = (target - h.p).normalize();
            if wi.dot(view_ng) <= 0.0 {
                continue;
            }
            let spread = 2.0 * 2f32.powf(-9.0 * rng.f32());
            let kind = if k % 2 == 0 { RayKind::Shadow } else { RayKind::Diffuse };
            let o = mipray::ray::offset_origin(h.p, h.p_error, view_ng, wi);
            let ray = Ray { t_max: (target - o).length(), ..beam_ray(o, wi, h.chord_error.max(1e-4), spread, kind) };
            sent += 1;
            escapes += usize::from(!tracer.occluded_from(&ray, &h, &mut c));
        }
    }
    (sent, escapes)
}

/// Rules 6 and 8 of docs/cracks.md, without the rate floor: a ray leaving a displaced shell reads
/// the whole shell at its origin's rate and is stopped by the seam boxes around its origin where
/// it heads through the surface. Here (4,000 camera rays a shell) 32 of 18,266 secondary rays got
/// through the fBm shell before them, 1 and 2 of the two shells' about 18,000 with them; the rest
/// go through cracks the displaced seams leave open at one rate (the floor closes those;
/// docs/cracks.md). The bound fails if the rules go.
#[test]
fn secondary_rays_leaving_a_displaced_shell_cross_it_without_the_rate_floor() {
    for shell in [Shell::Displaced, Shell::Textured] {
        let (sent, escapes) = secondary_escapes(shell, 4_000, 7);
        println!("{shell:?}: {escapes} of {sent} secondary rays got through the wall");
        assert!(sent > 15_000, "{sent}");
        assert!(escapes * 2000 <= sent, "{shell:?}: {escapes} of {sent} secondary rays got through the wall");
    }
}

/// The light-leak renders without the rate floor: lit pixels outside in / inside out (a
/// measurement, docs/cracks.md; `--ignored --nocapture`).
#[test]
#[ignore = "measurement"]
fn displaced_shells_without_the_rate_floor() {
    let px = |v: &[String]| v.iter().filter_map(|l| l.split(": ").nth(1)?.split(' ').next()?.parse::<usize>().ok()).sum::<usize>();
    for shell in [Shell::Displaced, Shell::Textured] {
        let outside_in = leaks(&[shell], lights_outside, &OUTSIDE_VIEWS, &INTEGRATORS, false);
        let inside_out = leaks(&[shell], lights_inside, &INSIDE_VIEWS, &LIT_INTEGRATORS, false);
        println!("{shell:?} without the floor: outside in {} px, inside out {} px", px(&outside_in), px(&inside_out));
        println!("{}\n{}", outside_in.join("\n"), inside_out.join("\n"));
    }
}
