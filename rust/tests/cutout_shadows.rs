//! Opacity cut-outs (`opacityThreshold`) in every visibility query: shadow rays toward every
//! kind of light, through light samples and BSDF samples, in every integrator; ambient-occlusion
//! rays, with and without the occlusion cache's pre-pass; and the bound on how many cut-outs a
//! ray passes. Against the analytic radiance of a lambertian plane (ρ/π · E · cos θ) and against
//! the same scene without the card.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::light::LightShape;
use mipray::material::{Input, Material, PreviewSurface, TexturedColor};
use mipray::options::IntegratorKind;
use mipray::prelude::*;
use mipray::texture::serde_json::{json, Value};
use mipray::texture::{FilterMode, Interpolation, Lookup, Primvar2, TextureError, TextureHandle, TextureSampler};

/// A one-channel texture: `left` where s < 0.5, `right` elsewhere.
struct SplitSampler {
    left: f32,
    right: f32,
}

impl TextureSampler for SplitSampler {
    fn handle(&self, _path: &str) -> Result<TextureHandle, TextureError> {
        Ok(TextureHandle::new(0))
    }
    fn sample(&self, _h: TextureHandle, st: [f32; 2], _dx: [f32; 2], _dy: [f32; 2], _lookup: &Lookup, out: &mut [f32]) -> bool {
        out.fill(if st[0] < 0.5 { self.left } else { self.right });
        true
    }
    fn filter_mode(&self) -> FilterMode {
        FilterMode::Differentials
    }
    fn stats(&self) -> Value {
        json!({})
    }
}

fn opacity_texture(left: f32, right: f32) -> TexturedColor {
    TexturedColor {
        sampler: Arc::new(SplitSampler { left, right }),
        texture: TextureHandle::new(0),
        path: "mask.tx".into(),
        lookup: Lookup::DEFAULT,
        scale: Vec3A::ONE,
        bias: Vec3A::ZERO,
        fallback: Vec3A::ONE,
        st_channel: 0,
    }
}

fn topo1() -> MeshTopology {
    MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() }
}

/// The rectangle [x0, x1] × [y0, y1] at height `z`, facing +z, `st` = its (x, y) scaled to 0..1.
fn card(x0: f32, x1: f32, y0: f32, y1: f32, z: f32) -> Arc<BilinearSurface> {
    let st = Primvar2 {
        name: "st".into(),
        interpolation: Interpolation::Vertex,
        values: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
        indices: vec![],
    };
    let pts = [[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]];
    Arc::new(BilinearSurface::new(&topo1(), &pts).unwrap().with_primvars(&topo1(), 4, &[st]).unwrap())
}

fn add(scene: &mut Scene, name: &str, surface: Arc<dyn LimitSurface>, material: Material) {
    let mat = scene.add_material(material);
    let mut m = Mesh::new(name, surface);
    m.material = mat;
    let i = scene.add_mesh(m);
    scene.add_instance(i, Mat4::IDENTITY);
}

/// A grey matte card material: cut out by `opacity` (a constant, or the texture `mask`) under
/// `threshold`.
fn card_material(opacity: f32, threshold: f32, mask: Option<TexturedColor>) -> Material {
    let surface = PreviewSurface {
        diffuse_color: Vec3A::splat(0.5),
        use_specular_workflow: true,
        specular_color: Vec3A::ZERO,
        opacity,
        opacity_threshold: threshold,
        ..PreviewSurface::default()
    };
    let mut m = Material::preview_surface("/leaf", surface).0;
    m.textures.extend(mask.map(|t| (Input::Opacity, t)));
    m
}

const RHO: f32 = 0.5;

/// A lambertian ground (ρ = 0.5) under `card`, seen from above by an orthographic camera
/// framing [cx − w/2, cx + w/2] × [−h/2, h/2].
fn ground_scene(cx: f32, w: f32, h: f32) -> Scene {
    let mut scene = Scene::default();
    add(&mut scene, "/ground", card(-20.0, 20.0, -20.0, 20.0, 0.0), Material::lambertian("/grey", Vec3A::splat(RHO)).0);
    scene.camera = Camera::orthographic(Camera::look_at(Vec3::new(cx, 0.0, 8.0), Vec3::new(cx, 0.0, 0.0), Vec3::Y), w * 10.0, h * 10.0);
    scene
}

/// A ground seen at a grazing angle from below any card: a long lens 0.15 above the ground,
/// 6 back along −y, looking at the origin, on a 16 × 2 image. Its rays fall 1.9–3.1 % (never
/// rising), meeting the ground over y ∈ [−1.2, 1.9], x within ±0.3, and pass under anything
/// higher than 0.15 — so an opaque card over the ground changes only the light, not what the
/// camera sees.
fn grazing(mut scene: Scene) -> Scene {
    scene.camera = Camera {
        render_from_camera: Camera::look_at(Vec3::new(0.0, -6.0, 0.15), Vec3::ZERO, Vec3::Z),
        focal_length: 200.0,
        horizontal_aperture: 20.0,
        vertical_aperture: 2.5,
        ..Default::default()
    };
    scene
}

fn render_with(scene: &Scene, opts: &RenderOptions) -> RenderOutput {
    render(scene, opts, &NoProgress).unwrap()
}

fn red(out: &RenderOutput, aov: &str, x: usize, y: usize) -> f32 {
    out.film.pixel(aov, x, y)[0]
}

#[test]
fn a_cut_out_card_shadows_a_plane_only_where_its_mask_leaves_a_surface() {
    // The sun travels along (−1, 0, −1)/√2 with irradiance π on a surface facing it: the lit
    // ground's radiance is ρ/π · π · cos 45° = 0.5 · 0.7071. A card over x ∈ [3, 5] at height 2
    // casts its shadow on x ∈ [1, 3]: its left half (s < 0.5, opacity 0.2 under the threshold
    // 0.5: cut out) over x ∈ [1, 2], its right half (opacity 0.9: a surface) over x ∈ [2, 3].
    // The camera frames x ∈ [1, 3], 16 pixels: columns 0–7 under the cut-out half, 8–15 under
    // the leaf, and never sees the card itself.
    let lit = RHO * std::f32::consts::FRAC_1_SQRT_2;
    let scene_with = |material: Material| {
        let mut scene = ground_scene(2.0, 2.0, 1.0);
        add(&mut scene, "/card", card(3.0, 5.0, -1.0, 1.0, 2.0), material);
        scene.lights.push(Light::distant("/sun", Vec3A::new(-1.0, 0.0, -1.0), Vec3A::splat(PI)));
        scene
    };
    let masked = scene_with(card_material(1.0, 0.5, Some(opacity_texture(0.2, 0.9))));
    for (integrator, max_depth) in [(IntegratorKind::Direct, 2), (IntegratorKind::Path, 0), (IntegratorKind::ColorBleeding, 0)] {
        let opts = RenderOptions { width: 16, height: 8, integrator, max_depth, indirect_samples: 0, ..Default::default() };
        let out = render_with(&masked, &opts);
        for y in 0..8 {
            for x in 0..8 {
                let c = red(&out, "color", x, y);
                assert!((c - lit).abs() < 1e-4, "{integrator:?}: under the cut-out ({x}, {y}): {c} vs {lit}");
            }
            for x in 8..16 {
                assert_eq!(red(&out, "color", x, y), 0.0, "{integrator:?}: under the leaf ({x}, {y})");
            }
        }
        assert!(out.stats["render"]["cutout_passes"].as_u64().unwrap() > 0, "{}", out.stats["render"]);
        assert_eq!(out.stats["render"]["cutout_limit_rays"].as_u64(), Some(0));
    }
    let opts = RenderOptions { width: 16, height: 8, ..Default::default() };
    // Opacity 0 under a threshold: no card at all, no shadow.
    let out = render_with(&scene_with(card_material(0.0, 0.5, None)), &opts);
    for y in 0..8 {
        for x in 0..16 {
            let c = red(&out, "color", x, y);
            assert!((c - lit).abs() < 1e-4, "opacity 0, threshold 0.5 ({x}, {y}): {c} vs {lit}");
        }
    }
    // Opacity 0.3 without a threshold is glass, not a cut-out: shadow rays do not refract, so
    // it shadows as a surface does (a classic ray tracer's glass).
    let out = render_with(&scene_with(card_material(0.3, 0.0, None)), &opts);
    for y in 0..8 {
        for x in 0..16 {
            assert_eq!(red(&out, "color", x, y), 0.0, "glass shadows ({x}, {y})");
        }
    }
}

#[test]
fn ambient_occlusion_sees_through_a_fully_cut_out_card() {
    // A plane alone is unoccluded: AO = 1. A card 0.3 above it blocks most of the hemisphere
    // where it is a surface, and none of it where it is cut out — with and without the
    // occlusion cache, whose records' rays are a different query (closest hits, for their
    // distances). The camera sees the ground under the card, never the card.
    let with_card = |material: Option<Material>| {
        let mut scene = ground_scene(0.0, 1.0, 1.0);
        if let Some(m) = material {
            add(&mut scene, "/card", card(-3.0, 3.0, -3.0, 3.0, 0.3), m);
        }
        grazing(scene)
    };
    let textured = card_material(1.0, 0.5, Some(opacity_texture(0.1, 0.3)));
    for integrator in [IntegratorKind::Ao, IntegratorKind::Auto, IntegratorKind::Path, IntegratorKind::ColorBleeding] {
        for irradiance_cache in [false, true] {
            let opts = RenderOptions {
                width: 16,
                height: 2,
                integrator,
                ao_samples: 32,
                max_depth: 0,
                irradiance_cache,
                aovs: vec![Aov::Ao],
                ..Default::default()
            };
            let bare = render_with(&with_card(None), &opts);
            let opaque = render_with(&with_card(Some(card_material(1.0, 0.0, None))), &opts);
            for material in [card_material(0.0, 0.5, None), textured.clone()] {
                let cut = render_with(&with_card(Some(material)), &opts);
                for y in 0..2 {
                    for x in 0..16 {
                        let (b, c, o) = (red(&bare, "ao", x, y), red(&cut, "ao", x, y), red(&opaque, "ao", x, y));
                        let case = format!("{integrator:?}, cache {irradiance_cache}, ({x}, {y})");
                        assert!((b - 1.0).abs() < 1e-5, "{case}: a plane alone is unoccluded: {b}");
                        assert!((c - b).abs() < 1e-5, "{case}: the cut-out card occludes nothing: {c} vs {b}");
                        assert!(o < 0.5, "{case}: the opaque card occludes: {o}");
                    }
                }
            }
        }
    }
}

/// The mean of the colour AOV's red channel.
fn mean_red(out: &RenderOutput) -> f32 {
    let c = &out.film.aov("color").unwrap().data;
    c.iter().step_by(3).sum::<f32>() / (c.len() / 3) as f32
}

#[test]
fn every_light_and_integrator_sees_through_a_cut_out_card() {
    // Light samples and BSDF samples (multiple importance sampling) toward a wide sun, a rect,
    // a sphere and a dome, in the classic integrator, the path tracer (next-event estimation
    // and the lights its BSDF rays hit) and color bleeding (its bounce rays too): a card that
    // is cut out everywhere changes the image no more than float rounding can, where the same
    // card opaque darkens it a lot. The camera sees the ground under the card, never the card.
    let sun = Light::usd_distant("/sun", &Mat4::IDENTITY, 1.0, 0.0, Vec3A::ONE, 8.0, true);
    let rect = Light::usd_area(
        "/rect",
        LightShape::Rect { center: Vec3A::new(0.0, 0.0, 3.0), u: Vec3A::X, v: Vec3A::Y, normal: Vec3A::NEG_Z },
        2.0,
        0.0,
        Vec3A::ONE,
        false,
    );
    let sphere =
        Light::usd_area("/bulb", LightShape::Sphere { center: Vec3A::new(0.3, 0.0, 3.0), radius: 0.5 }, 4.0, 0.0, Vec3A::ONE, false);
    let dome = Light::usd_area("/sky", LightShape::Dome(None), 1.0, 0.0, Vec3A::ONE, false);
    for light in [sun, rect, sphere, dome] {
        let scene_with = |material: Option<Material>| {
            let mut scene = ground_scene(0.0, 1.0, 1.0);
            if let Some(m) = material {
                add(&mut scene, "/card", card(-3.0, 3.0, -3.0, 3.0, 1.0), m);
            }
            scene.lights.push(light.clone());
            grazing(scene)
        };
        for integrator in [IntegratorKind::Direct, IntegratorKind::Path, IntegratorKind::ColorBleeding] {
            let opts = RenderOptions {
                width: 16,
                height: 2,
                samples: 4,
                shadow_samples: 4,
                integrator,
                max_depth: 2,
                russian_roulette_depth: 8,
                indirect_samples: 8,
                ..Default::default()
            };
            let bare = mean_red(&render_with(&scene_with(None), &opts));
            let cut = mean_red(&render_with(&scene_with(Some(card_material(1.0, 0.5, Some(opacity_texture(0.2, 0.2))))), &opts));
            let opaque = mean_red(&render_with(&scene_with(Some(card_material(1.0, 0.0, None))), &opts));
            let case = format!("{} with {integrator:?}", light.name);
            assert!(bare > 0.0, "{case}: {bare}");
            assert!((cut - bare).abs() <= 2e-3 * bare, "{case}: cut-out card {cut} vs no card {bare}");
            assert!(opaque < 0.8 * bare, "{case}: an opaque card must shadow: {opaque} vs {bare}");
        }
    }
}

#[test]
fn past_the_bound_a_stack_of_cut_outs_is_opaque_and_counted() {
    // Cards stacked between the sun and the ground, all cut out: a shadow ray passes through
    // up to MAX_CUTOUTS of them, and a deeper stack is taken as opaque and counted.
    use mipray::integrator::visibility::MAX_CUTOUTS;
    let lit = RHO * std::f32::consts::FRAC_1_SQRT_2;
    let stack = |cards: u32| {
        let mut scene = ground_scene(2.0, 2.0, 1.0);
        for i in 0..cards {
            let z = 2.0 + 0.01 * i as f32;
            add(&mut scene, &format!("/card{i}"), card(z + 1.0, z + 3.0, -1.0, 1.0, z), card_material(0.0, 0.5, None));
        }
        scene.lights.push(Light::distant("/sun", Vec3A::new(-1.0, 0.0, -1.0), Vec3A::splat(PI)));
        render_with(&scene, &RenderOptions { width: 16, height: 8, ..Default::default() })
    };
    let shallow = stack(MAX_CUTOUTS);
    let deep = stack(MAX_CUTOUTS + 2);
    for y in 0..8 {
        for x in 0..16 {
            let c = red(&shallow, "color", x, y);
            assert!((c - lit).abs() < 1e-4, "{MAX_CUTOUTS} cut-outs are passed ({x}, {y}): {c}");
            assert_eq!(red(&deep, "color", x, y), 0.0, "{} cut-outs block ({x}, {y})", MAX_CUTOUTS + 2);
        }
    }
    assert_eq!(shallow.stats["render"]["cutout_limit_rays"].as_u64(), Some(0));
    assert_eq!(deep.stats["render"]["cutout_limit_rays"].as_u64(), Some(16 * 8), "one per shadow ray: {}", deep.stats["render"]);
    assert!(deep.stats["render"]["cutout_passes"].as_u64().unwrap() >= u64::from(MAX_CUTOUTS) * 16 * 8);
}
