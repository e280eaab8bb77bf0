//! `mipray-figures`: renders the pictures of docs/ray-differentials.md — a flat mirror, a convex
//! mirror and an ambient-occlusion ground, with the `beamWidth` and `tessRate` AOVs in false
//! colour — so the paper's point (coherent rays are narrow, incoherent rays are wide) can be
//! seen, and re-made by anyone:
//!
//! ```text
//! cargo run --release -p hd-mipray --bin mipray-figures -- docs/images
//! ```

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use hd_mipray::bench_scene::blob_mesh;
use mipray::aov::Aov;
use mipray::bilinear::BilinearSurface;
use mipray::camera::Camera;
use mipray::image_io::{ChannelFormat, ImageBuf, ImageIo, MetaValue};
use mipray::light::Light;
use mipray::material::Material;
use mipray::options::RenderOptions;
use mipray::progress::NoProgress;
use mipray::render::render;
use mipray::scene::{Mesh, Scene};
use mipray::topology::{MeshTopology, Scheme};
use mipray_bridge::{OiioImageIo, OsdSurface};

fn quad(c: [[f32; 3]; 4]) -> Result<BilinearSurface, mipray::error::MeshError> {
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    BilinearSurface::new(&topo, &c)
}

/// A flat square of `n × n` quads, `half` units from the centre to each side.
fn grid(half: f32, n: i32) -> Result<BilinearSurface, mipray::error::MeshError> {
    let (topo, pts) = mipray::bilinear::grid_mesh(half, n, 0.0);
    BilinearSurface::new(&topo, &pts)
}

fn add(scene: &mut Scene, mesh: Mesh, material: Material, xf: Mat4) {
    let m = scene.add_material(material);
    let mut mesh = mesh;
    mesh.material = m;
    let i = scene.add_mesh(mesh);
    scene.add_instance(i, xf);
}

fn scene() -> Result<Scene, mipray::error::MeshError> {
    let mut s = Scene::default();
    let ground = grid(30.0, 30)?;
    add(&mut s, Mesh::new("/ground", Arc::new(ground)), Material::lambertian("/ground_mat", Vec3A::splat(0.5)).0, Mat4::IDENTITY);
    // A flat mirror standing on the left, facing the camera and the objects.
    let mirror = quad([[-4.5, 2.0, 0.0], [-1.0, 4.5, 0.0], [-1.0, 4.5, 3.0], [-4.5, 2.0, 3.0]])?;
    add(
        &mut s,
        Mesh::new("/flat_mirror", Arc::new(mirror)),
        Material::mirror("/chrome_flat", Vec3A::ZERO, Vec3A::splat(0.9)),
        Mat4::IDENTITY,
    );
    // A convex mirror: a subdivided cube limit surface, scaled into a ball.
    let (t, p) = blob_mesh(4, 0);
    let ball = OsdSurface::new("/convex_mirror", &t, &p)?;
    add(
        &mut s,
        Mesh::new("/convex_mirror", Arc::new(ball)),
        Material::mirror("/chrome_ball", Vec3A::ZERO, Vec3A::splat(0.9)),
        Mat4::from_translation(Vec3::new(2.2, 2.5, 1.2)) * Mat4::from_scale(Vec3::splat(1.1)),
    );
    // Matte things for the mirrors to show.
    for (k, (x, y)) in [(-1.0f32, 0.5f32), (0.8, 5.5), (-3.0, 6.5), (4.5, 6.0)].into_iter().enumerate() {
        let (t, p) = blob_mesh(6, 10 + k as u64);
        let b = OsdSurface::new(&format!("/blob{k}"), &t, &p)?;
        let colour = [Vec3A::new(0.7, 0.25, 0.2), Vec3A::new(0.2, 0.5, 0.7), Vec3A::new(0.8, 0.7, 0.3), Vec3A::new(0.4, 0.7, 0.35)][k];
        add(
            &mut s,
            Mesh::new(format!("/blob{k}"), Arc::new(b)),
            Material::lambertian(format!("/matte{k}"), colour).0,
            Mat4::from_translation(Vec3::new(x, y, 0.6)) * Mat4::from_scale(Vec3::splat(0.6)),
        );
    }
    s.lights.push(Light::distant("/sun", Vec3A::new(0.3, 0.5, -0.8), Vec3A::splat(2.0)));
    s.camera = Camera {
        render_from_camera: Camera::look_at(Vec3::new(0.5, -7.0, 3.2), Vec3::new(0.0, 3.0, 1.0), Vec3::Z),
        focal_length: 30.0,
        horizontal_aperture: 36.0,
        vertical_aperture: 24.0,
        clipping_range: (0.1, 1000.0),
        ..Default::default()
    };
    Ok(s)
}

/// A perceptual-ish ramp (dark blue → teal → yellow) for t in [0, 1].
fn ramp(t: f32) -> [f32; 3] {
    let stops = [[0.05, 0.03, 0.25], [0.15, 0.35, 0.6], [0.2, 0.65, 0.55], [0.65, 0.85, 0.3], [1.0, 0.95, 0.4]];
    let x = t.clamp(0.0, 1.0) * (stops.len() - 1) as f32;
    let i = (x.floor() as usize).min(stops.len() - 2);
    let f = x - i as f32;
    let (a, b) = (stops[i], stops[i + 1]);
    [a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f, a[2] + (b[2] - a[2]) * f]
}

fn write_rgb(path: &Path, w: usize, h: usize, rgb: Vec<f32>, note: &str) -> Result<(), String> {
    let img = ImageBuf { width: w, height: h, channels: vec!["R".into(), "G".into(), "B".into()], pixels: rgb, metadata: Vec::new() };
    OiioImageIo::new()
        .write(path, &img, &[ChannelFormat::U8; 3], &[("ImageDescription".into(), MetaValue::Str(note.into()))])
        .map_err(|e| e.to_string())
}

fn srgb(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

fn main() {
    let out = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "docs/images".into()));
    if let Err(e) = std::fs::create_dir_all(&out) {
        eprintln!("mipray-figures: {}: {e}", out.display());
        std::process::exit(1);
    }
    let scene = match scene() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("mipray-figures: {e}");
            std::process::exit(1);
        }
    };
    let (w, h) = (480, 320);
    let opts = RenderOptions {
        width: w,
        height: h,
        samples: 4,
        ao_samples: 32,
        ao_distance: 4.0,
        aovs: vec![Aov::Color, Aov::BeamWidth, Aov::TessRate],
        ..Default::default()
    };
    let r = match render(&scene, &opts, &NoProgress) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("mipray-figures: {e}");
            std::process::exit(1);
        }
    };
    let film = &r.film;
    let color: Vec<f32> = film.aov("color").map(|a| a.data.iter().map(|c| srgb(*c)).collect()).unwrap_or_default();
    let bw = film.aov("beamWidth").map(|a| a.data.clone()).unwrap_or_default();
    let (lo, hi) = (1e-3f32, 1.0f32);
    let bw_rgb: Vec<f32> = bw
        .iter()
        .flat_map(|b| if *b > 0.0 { ramp(((b.log10() - lo.log10()) / (hi.log10() - lo.log10())).clamp(0.0, 1.0)) } else { [0.0; 3] })
        .collect();
    let rate = film.aov("tessRate").map(|a| a.data.clone()).unwrap_or_default();
    // Discrete: 1 blue, 2 cyan, 4 green, 8 yellow, 16 orange, split (32 and finer) red.
    let palette = [[0.1, 0.2, 0.8], [0.1, 0.7, 0.8], [0.2, 0.7, 0.2], [0.9, 0.85, 0.2], [0.95, 0.5, 0.1], [0.8, 0.1, 0.1]];
    let rate_rgb: Vec<f32> =
        rate.iter().flat_map(|q| if *q > 0.0 { palette[(q.log2().round() as usize).min(5)] } else { [0.0; 3] }).collect();
    let files = [
        ("differentials-color.png", color, "colour: flat mirror (left), convex mirror (right), AO ground"),
        ("differentials-beamwidth.png", bw_rgb, "beamWidth at the camera ray's hit, log scale 1e-3 (blue) to 1 (yellow) scene units"),
        (
            "differentials-tessrate.png",
            rate_rgb,
            "tessRate at the end of the specular chain: 1 blue, 2 cyan, 4 green, 8 yellow, 16 orange, split red",
        ),
    ];
    for (name, rgb, note) in files {
        let p = out.join(name);
        if let Err(e) = write_rgb(&p, w, h, rgb, note) {
            eprintln!("mipray-figures: {e}");
            std::process::exit(1);
        }
        println!("{}", p.display());
    }
    let stats = r.stats.to_string();
    let p = out.join("differentials-stats.json");
    if let Err(e) = std::fs::write(&p, stats) {
        eprintln!("mipray-figures: {}: {e}", p.display());
        std::process::exit(1);
    }
    println!("{}", p.display());
}
