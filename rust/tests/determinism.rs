//! The image is a function of the seed alone: byte-identical with 1 and 2 threads for every
//! integrator, and a progressive render's last pass is byte-identical to the one-pass render.
//! Progressive passes are reported in order and can be cancelled between and within passes.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use glam::{Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::error::RenderError;
use mipray::light::LightShape;
use mipray::material::Material;
use mipray::options::IntegratorKind;
use mipray::prelude::*;
use mipray::render::passes;

fn quads(points: &[[f32; 3]], faces: &[[i32; 4]]) -> Arc<BilinearSurface> {
    let topo = MeshTopology {
        scheme: Scheme::None,
        face_vertex_counts: vec![4; faces.len()],
        face_vertex_indices: faces.iter().flatten().copied().collect(),
        ..Default::default()
    };
    Arc::new(BilinearSurface::new(&topo, points).unwrap())
}

/// A bumpy grid (so tessellation rates follow the beams) of `n`×`n` quads over [-2, 2]².
fn bumps(n: i32) -> Arc<BilinearSurface> {
    let mut pts = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f32 / n as f32 * 4.0 - 2.0, j as f32 / n as f32 * 4.0 - 2.0);
            pts.push([x, y, 0.6 + 0.4 * (x * 2.0).sin() * (y * 3.0).cos()]);
        }
    }
    let mut faces = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let v = |a: i32, b: i32| b * (n + 1) + a;
            faces.push([v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)]);
        }
    }
    quads(&pts, &faces)
}

/// Everything that draws random numbers: a rect light and an angular sun (soft shadows), a
/// dome, a mirror, bumps over a floor that shadow and bounce light onto each other.
fn scene() -> Scene {
    let mut scene = Scene::default();
    let mut add = |name: &str, surface: Arc<BilinearSurface>, material: Material| {
        let mat = scene.add_material(material);
        let mut m = Mesh::new(name, surface);
        m.material = mat;
        let i = scene.add_mesh(m);
        scene.add_instance(i, Mat4::IDENTITY);
    };
    add(
        "/floor",
        quads(&[[-6.0, -6.0, 0.0], [6.0, -6.0, 0.0], [6.0, 6.0, 0.0], [-6.0, 6.0, 0.0]], &[[0, 1, 2, 3]]),
        Material::lambertian("/grey", Vec3A::splat(0.5)).0,
    );
    add("/bumps", bumps(10), Material::lambertian("/red", Vec3A::new(0.8, 0.2, 0.1)).0);
    add(
        "/mirror",
        quads(&[[-3.0, 3.0, 0.0], [3.0, 3.0, 0.0], [3.0, 3.0, 3.0], [-3.0, 3.0, 3.0]], &[[0, 1, 2, 3]]),
        Material::mirror("/mirror", Vec3A::splat(0.1), Vec3A::splat(0.8)),
    );
    scene.lights.push(Light::usd_area(
        "/rect",
        LightShape::Rect { center: Vec3A::new(1.0, -1.0, 4.0), u: Vec3A::X, v: Vec3A::Y, normal: Vec3A::NEG_Z },
        3.0,
        0.0,
        Vec3A::ONE,
        false,
    ));
    let toward = Vec3A::new(0.3, -0.4, -1.0).normalize();
    let mut sun = Light::distant("/sun", toward, Vec3A::splat(2.0));
    sun.shape = LightShape::Distant { direction: toward, angle_deg: 5.0 };
    scene.lights.push(sun);
    scene.lights.push(Light::usd_area("/sky", LightShape::Dome(None), 0.2, 0.0, Vec3A::new(0.6, 0.7, 1.0), false));
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(3.0, -6.0, 5.0), Vec3::new(0.0, 0.0, 0.5), Vec3::Z), 45.0);
    scene
}

const AOVS: &[&str] = &["color", "alpha", "depth", "normal", "primId", "ao", "beamWidth", "tessRate"];

fn options(integrator: IntegratorKind, threads: usize, progressive: bool) -> RenderOptions {
    RenderOptions {
        // Several tiles (16 × 16 pixels each), so two threads really split the work.
        width: 40,
        height: 28,
        samples: 6,
        seed: 11,
        threads,
        integrator,
        ao_samples: 4,
        max_depth: 5,
        russian_roulette_depth: 1,
        progressive,
        aovs: AOVS.iter().map(|s| Aov::from_name(s).unwrap()).collect(),
        ..Default::default()
    }
}

/// Every AOV's bytes.
fn bytes(out: &RenderOutput) -> Vec<(String, Vec<u32>)> {
    out.film.aovs.iter().map(|a| (a.aov.name().to_string(), a.data.iter().map(|v| v.to_bits()).collect())).collect()
}

const INTEGRATORS: [IntegratorKind; 5] =
    [IntegratorKind::Auto, IntegratorKind::Direct, IntegratorKind::Ao, IntegratorKind::ColorBleeding, IntegratorKind::Path];

#[test]
fn one_and_two_threads_give_identical_bytes_for_every_integrator() {
    let scene = scene();
    for integrator in INTEGRATORS {
        let one = render(&scene, &options(integrator, 1, false), &NoProgress).unwrap();
        let two = render(&scene, &options(integrator, 2, false), &NoProgress).unwrap();
        assert_eq!(two.stats["render"]["threads"], 2);
        for ((name, a), (_, b)) in bytes(&one).iter().zip(&bytes(&two)) {
            assert!(a == b, "{integrator:?}: AOV {name} differs between 1 and 2 threads");
        }
        // The scene really exercises randomness: a different seed changes the colour.
        let reseeded = render(&scene, &RenderOptions { seed: 12, ..options(integrator, 2, false) }, &NoProgress).unwrap();
        assert_ne!(reseeded.film.aov("color").unwrap().data, two.film.aov("color").unwrap().data, "{integrator:?}");
        // And the ray counts are a function of the seed too.
        assert_eq!(one.stats["render"]["rays"], two.stats["render"]["rays"], "{integrator:?}");
    }
}

#[test]
fn the_last_progressive_pass_is_the_one_pass_image() {
    let scene = scene();
    for integrator in INTEGRATORS {
        let fixed = render(&scene, &options(integrator, 2, false), &NoProgress).unwrap();
        let progressive = render(&scene, &options(integrator, 2, true), &NoProgress).unwrap();
        assert!(bytes(&fixed) == bytes(&progressive), "{integrator:?}: progressive differs from one pass");
        assert_eq!(fixed.stats["render"]["rays"], progressive.stats["render"]["rays"], "{integrator:?}");
    }
}

/// Records each pass (its sample count and colour), and cancels when told.
#[derive(Default)]
struct Recorder {
    passes: Mutex<Vec<(u32, Vec<f32>)>>,
    done: AtomicU64,
    total: AtomicU64,
    /// Cancel once this many passes are reported (0: never).
    cancel_after_passes: usize,
    /// Cancel once this many pixel samples are done (0: never).
    cancel_after_units: u64,
    cancel: AtomicBool,
}

impl Progress for Recorder {
    fn start(&self, total: u64) {
        self.total.store(total, Ordering::Relaxed);
    }
    fn advance(&self, n: u64) {
        let done = self.done.fetch_add(n, Ordering::Relaxed) + n;
        if self.cancel_after_units > 0 && done >= self.cancel_after_units {
            self.cancel.store(true, Ordering::Relaxed);
        }
    }
    fn pass_finished(&self, samples: u32, film: &Film) {
        let mut p = self.passes.lock().unwrap();
        p.push((samples, film.aov("color").unwrap().data.clone()));
        if self.cancel_after_passes > 0 && p.len() >= self.cancel_after_passes {
            self.cancel.store(true, Ordering::Relaxed);
        }
    }
    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}

fn rmse(a: &[f32], b: &[f32]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

#[test]
fn progressive_passes_refine_in_order_and_report_every_sample() {
    let bounds = |samples: u32, progressive: bool| passes(samples, progressive).iter().map(|r| (r.start, r.end)).collect::<Vec<_>>();
    assert_eq!(bounds(1, true), [(0, 1)]);
    assert_eq!(bounds(6, true), [(0, 1), (1, 2), (2, 4), (4, 6)]);
    assert_eq!(bounds(16, true), [(0, 1), (1, 2), (2, 4), (4, 8), (8, 16)]);
    assert_eq!(bounds(16, false), [(0, 16)]);
    let scene = scene();
    let opts = RenderOptions { samples: 32, ..options(IntegratorKind::Path, 2, true) };
    let rec = Recorder::default();
    let out = render(&scene, &opts, &rec).unwrap();
    let p = rec.passes.into_inner().unwrap();
    assert_eq!(p.iter().map(|(s, _)| *s).collect::<Vec<_>>(), [1, 2, 4, 8, 16, 32]);
    let last = &p.last().unwrap().1;
    assert_eq!(last, &out.film.aov("color").unwrap().data, "the last pass is the image");
    // Each pass is closer to the finished image than the first (noise falls as 1/√samples).
    let errors: Vec<f64> = p.iter().map(|(_, c)| rmse(c, last)).collect();
    assert!(errors[0] > 2.0 * errors[3] && errors[3] > errors[4], "{errors:?}");
    // Progress counts pixel samples, all of them.
    assert_eq!(rec.total.load(Ordering::Relaxed), 40 * 28 * 32);
    assert_eq!(rec.done.load(Ordering::Relaxed), 40 * 28 * 32);
    // A one-pass render reports its one pass too.
    let rec = Recorder::default();
    render(&scene, &RenderOptions { progressive: false, ..opts.clone() }, &rec).unwrap();
    assert_eq!(rec.passes.into_inner().unwrap().iter().map(|(s, _)| *s).collect::<Vec<_>>(), [32]);
}

#[test]
fn progressive_renders_cancel_between_and_within_passes() {
    let scene = scene();
    let opts = RenderOptions { samples: 16, ..options(IntegratorKind::Path, 2, true) };
    // Between passes: stop after the second.
    let rec = Recorder { cancel_after_passes: 2, ..Default::default() };
    assert!(matches!(render(&scene, &opts, &rec), Err(RenderError::Cancelled)));
    assert_eq!(rec.passes.lock().unwrap().len(), 2);
    // Within a pass: stop part-way through the first pass; no pass is reported.
    let rec = Recorder { cancel_after_units: 40 * 28 / 3, ..Default::default() };
    assert!(matches!(render(&scene, &opts, &rec), Err(RenderError::Cancelled)));
    assert!(rec.passes.lock().unwrap().is_empty());
    assert!(rec.done.load(Ordering::Relaxed) < 40 * 28, "stopped within the first pass");
}

/// The frame cut into crop windows at uneven pixel edges (not the render's 16-pixel tiles),
/// each window rendered on its own with a cold cache, assembled: every AOV equals the
/// whole frame's bit for bit, for every integrator and with the irradiance cache.
#[test]
fn crop_windows_assemble_into_the_whole_frame_bit_for_bit() {
    let scene = scene();
    let cases = INTEGRATORS.iter().map(|&k| (k, false)).chain([(IntegratorKind::Ao, true), (IntegratorKind::ColorBleeding, true)]);
    for (integrator, irradiance_cache) in cases {
        let base = RenderOptions { irradiance_cache, ..options(integrator, 2, false) };
        let (w, h) = (base.width, base.height);
        let whole = render(&scene, &base, &NoProgress).unwrap();
        let mut assembled: Vec<Vec<f32>> = whole.film.aovs.iter().map(|a| vec![f32::NAN; a.data.len()]).collect();
        let (columns, rows) = ([0, 7, 23, w], [0, 11, h]);
        for cx in columns.windows(2) {
            for cy in rows.windows(2) {
                // NDC y runs up from the bottom; pixel rows down from the top.
                let crop = [cx[0] as f64 / w as f64, 1.0 - cy[1] as f64 / h as f64, cx[1] as f64 / w as f64, 1.0 - cy[0] as f64 / h as f64];
                let tile = render(&scene, &RenderOptions { crop, ..base.clone() }, &NoProgress).unwrap();
                assert_eq!((tile.film.width, tile.film.height), (cx[1] - cx[0], cy[1] - cy[0]), "{integrator:?} {crop:?}");
                assert_eq!(tile.stats["render"]["data_window"], serde_json::json!([cx[0], cy[0], cx[1], cy[1]]));
                for (a, out) in tile.film.aovs.iter().zip(&mut assembled) {
                    for y in 0..tile.film.height {
                        for x in 0..tile.film.width {
                            for c in 0..a.channels {
                                out[((cy[0] + y) * w + cx[0] + x) * a.channels + c] = a.data[(y * tile.film.width + x) * a.channels + c];
                            }
                        }
                    }
                }
            }
        }
        for (a, b) in whole.film.aovs.iter().zip(&assembled) {
            let same = a.data.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
            assert!(same, "{integrator:?} irradiance cache {irradiance_cache}: AOV {} differs from the whole frame", a.aov.name());
        }
    }
}

#[test]
fn a_crop_window_takes_the_pixels_whose_centres_it_holds() {
    let o = |crop| RenderOptions { width: 10, height: 4, crop, ..Default::default() };
    // Columns 2..5 (centres 2.5..4.5 of 10) and, NDC y up, rows 1..3 from the top.
    let w = o([0.2, 0.25, 0.5, 0.75]).data_window();
    assert_eq!((w.x, w.y), (2..5, 1..3));
    let w = o([0.0, 0.0, 1.0, 1.0]).data_window();
    assert_eq!((w.x, w.y), (0..10, 0..4));
    // A window between two pixel centres holds none: refused, naming the setting.
    let e = render(&scene(), &o([0.21, 0.0, 0.24, 1.0]), &NoProgress).err().expect("refused").to_string();
    assert!(e.contains("crop=0.21,0,0.24,1") && e.contains("no pixel"), "{e}");
    // Out of the unit square or inverted: refused by the settings table.
    let e = render(&scene(), &o([0.5, 0.0, 0.2, 1.0]), &NoProgress).err().expect("refused").to_string();
    assert!(e.contains("render setting crop=0.5,0,0.2,1: out of range"), "{e}");
}
