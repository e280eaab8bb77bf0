//! UsdPreviewSurface inputs at a shading point (textures, one-channel float inputs, normal maps,
//! opacity cutouts), the effects they call for, and the AOVs the classic integrator fills:
//! against analytic values, and the identity color = emission + directDiffuse +
//! indirectDiffuse + specular.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::aov::Aov;
use mipray::light::LightShape;
use mipray::material::{Input, Material, PreviewSurface, TexturedColor};
use mipray::prelude::*;
use mipray::texture::serde_json::{json, Value};
use mipray::texture::{FilterMode, Interpolation, Lookup, Primvar2, TextureError, TextureHandle, TextureSampler};

/// A texture whose texels are `left` (RGBA) where s < 0.5 and `right` elsewhere.
struct SplitSampler {
    left: [f32; 4],
    right: [f32; 4],
}

impl TextureSampler for SplitSampler {
    fn handle(&self, _path: &str) -> Result<TextureHandle, TextureError> {
        Ok(TextureHandle::new(0))
    }
    fn sample(&self, _h: TextureHandle, st: [f32; 2], _dx: [f32; 2], _dy: [f32; 2], lookup: &Lookup, out: &mut [f32]) -> bool {
        let v = if st[0] < 0.5 { self.left } else { self.right };
        for (i, o) in out.iter_mut().enumerate() {
            *o = v.get(lookup.first_channel as usize + i).copied().unwrap_or(lookup.fill);
        }
        true
    }
    fn filter_mode(&self) -> FilterMode {
        FilterMode::Differentials
    }
    fn stats(&self) -> Value {
        json!({})
    }
}

fn texture(left: [f32; 4], right: [f32; 4], first_channel: u32, scale: Vec3A, bias: Vec3A) -> TexturedColor {
    TexturedColor {
        sampler: Arc::new(SplitSampler { left, right }),
        texture: TextureHandle::new(0),
        path: "split.tx".into(),
        lookup: Lookup { first_channel, ..Lookup::DEFAULT },
        scale,
        bias,
        fallback: Vec3A::splat(0.5),
        st_channel: 0,
    }
}

fn topo1() -> MeshTopology {
    MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() }
}

/// A square `half` wide each way at height `z`, facing +z, with `st` running 0..1 over it (s
/// along +x, or along −x with `flip_s`).
fn st_quad(half: f32, z: f32, flip_s: bool) -> Arc<BilinearSurface> {
    st_quad_at([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]], flip_s)
}

/// A quad with corners `pts` (counter-clockwise seen from its front) and `st` over it.
fn st_quad_at(pts: [[f32; 3]; 4], flip_s: bool) -> Arc<BilinearSurface> {
    let s = |x: f32| if flip_s { 1.0 - x } else { x };
    let st = Primvar2 {
        name: "st".into(),
        interpolation: Interpolation::Vertex,
        values: vec![[s(0.0), 0.0], [s(1.0), 0.0], [s(1.0), 1.0], [s(0.0), 1.0]],
        indices: vec![],
    };
    Arc::new(BilinearSurface::new(&topo1(), &pts).unwrap().with_primvars(&topo1(), 4, &[st]).unwrap())
}

fn quad(corners: [[f32; 3]; 4]) -> Arc<BilinearSurface> {
    Arc::new(BilinearSurface::new(&topo1(), &corners).unwrap())
}

fn add(scene: &mut Scene, name: &str, surface: Arc<dyn LimitSurface>, material: Material) -> usize {
    let mat = scene.add_material(material);
    let mut m = Mesh::new(name, surface);
    m.material = mat;
    let i = scene.add_mesh(m);
    scene.add_instance(i, Mat4::IDENTITY);
    i
}

fn preview(name: &str, f: impl FnOnce(&mut PreviewSurface)) -> Material {
    let mut s = PreviewSurface::default();
    f(&mut s);
    Material::preview_surface(name, s).0
}

/// Looking down −z from (0, 0, 5), orthographic, `size` units across.
fn top_camera(size: f32) -> Camera {
    Camera::orthographic(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y), size * 10.0, size * 10.0)
}

fn aovs(names: &[&str]) -> Vec<Aov> {
    names.iter().map(|s| Aov::from_name(s).unwrap()).collect()
}

#[test]
fn a_normal_map_tilts_the_shading_normal_in_the_st_tangent_frame() {
    // Tangent-space normal (0.5, 0, 1)/|·|: tilted toward +s. Stored as (n + 1)/2 and read with
    // UsdUVTexture's scale 2, bias −1. A light from (1, 0, 1)/√2 then meets the mapped normal
    // at cos = 1.5/√2.5; with s running along −x the normal tilts the other way, cos = 0.5/√2.5.
    let nt = Vec3A::new(0.5, 0.0, 1.0).normalize();
    let texel = (nt + Vec3A::ONE) * 0.5;
    let to_light = Vec3A::new(1.0, 0.0, 1.0).normalize();
    for (flip_s, tilt_x) in [(false, 1.0f32), (true, -1.0)] {
        let mut mat = Material::lambertian("/bumpy", Vec3A::splat(0.5)).0;
        let t = [texel.x, texel.y, texel.z, 1.0];
        mat.textures.push((Input::Normal, texture(t, t, 0, Vec3A::splat(2.0), Vec3A::splat(-1.0))));
        let mut scene = Scene::default();
        add(&mut scene, "/plane", st_quad(1.0, 0.0, flip_s), mat);
        scene.lights.push(Light::distant("/sun", -to_light, Vec3A::splat(PI)));
        scene.camera = top_camera(2.0);
        let out =
            render(&scene, &RenderOptions { width: 8, height: 8, aovs: aovs(&["color", "normal"]), ..Default::default() }, &NoProgress)
                .unwrap();
        let n = Vec3A::new(tilt_x * nt.x, 0.0, nt.z);
        let expected = 0.5 * n.dot(to_light);
        for y in 0..8 {
            for x in 0..8 {
                let c = out.film.pixel("color", x, y)[0];
                assert!((c - expected).abs() < 1e-4, "flip {flip_s}: {c} vs {expected}");
                let got = Vec3A::from_slice(out.film.pixel("normal", x, y));
                assert!((got - n).length() < 1e-3, "{got} vs {n}");
            }
        }
    }
}

#[test]
fn textured_inputs_reach_the_bsdf_and_float_inputs_read_one_channel() {
    // Left half / right half of one quad, head on:
    // - emissiveColor from a texture, unclamped (2.5 on the left);
    // - metallic from the texture's green channel: 1 (a mirror of F0 = 0.8) on the left,
    //   0 (a dielectric, F0 = 0.04) on the right, reflecting a lit white ceiling of radiance 2/π.
    let mut emissive = Material::lambertian("/glow", Vec3A::ZERO).0;
    emissive.textures.push((Input::EmissiveColor, texture([2.5, 2.5, 2.5, 1.0], [0.5, 0.25, 0.0, 1.0], 0, Vec3A::ONE, Vec3A::ZERO)));
    let mut metal = preview("/metalMask", |s| {
        s.diffuse_color = Vec3A::splat(0.8);
        s.roughness = 0.0;
    });
    metal.textures.push((Input::Metallic, texture([0.0, 1.0, 0.0, 0.0], [1.0, 0.0, 1.0, 1.0], 1, Vec3A::ONE, Vec3A::ZERO)));
    let render_plate = |mat: Material| {
        let mut scene = Scene::default();
        add(&mut scene, "/plate", st_quad(1.0, 0.0, false), mat);
        add(
            &mut scene,
            "/ceiling",
            quad([[-50.0, -50.0, 10.0], [-50.0, 50.0, 10.0], [50.0, 50.0, 10.0], [50.0, -50.0, 10.0]]),
            Material::lambertian("/white", Vec3A::ONE).0,
        );
        let mut light = Light::distant("/up", Vec3A::Z, Vec3A::splat(2.0));
        light.casts_shadows = false;
        scene.lights.push(light);
        scene.camera = top_camera(2.0);
        render(
            &scene,
            &RenderOptions { width: 8, height: 8, aovs: aovs(&["color", "emission", "specular"]), ..Default::default() },
            &NoProgress,
        )
        .unwrap()
    };
    let out = render_plate(emissive);
    for y in 0..8 {
        assert_eq!(out.film.pixel("color", 1, y), &[2.5, 2.5, 2.5]);
        assert_eq!(out.film.pixel("color", 6, y), &[0.5, 0.25, 0.0]);
        assert_eq!(out.film.pixel("emission", 6, y), out.film.pixel("color", 6, y));
    }
    let out = render_plate(metal);
    let ceiling = 2.0 / PI;
    for y in 0..8 {
        let (l, r) = (out.film.pixel("color", 1, y)[0], out.film.pixel("color", 6, y)[0]);
        assert!((l - 0.8 * ceiling).abs() < 1e-5, "metal {l}");
        assert!((r - 0.04 * ceiling).abs() < 1e-5, "dielectric {r}");
        assert_eq!(out.film.pixel("specular", 1, y)[0], l);
    }
}

#[test]
fn opacity_cutouts_let_every_ray_through() {
    // A card above a lit ground (the light casts no shadows): where its textured opacity is
    // under the threshold the camera sees the ground, its depth and id; elsewhere the card.
    let mut card = preview("/leaf", |s| {
        s.diffuse_color = Vec3A::new(0.0, 1.0, 0.0);
        s.use_specular_workflow = true;
        s.specular_color = Vec3A::ZERO;
        s.opacity_threshold = 0.5;
    });
    card.textures.push((Input::Opacity, texture([0.2; 4], [0.9; 4], 0, Vec3A::ONE, Vec3A::ZERO)));
    let mut scene = Scene::default();
    let ground = add(
        &mut scene,
        "/ground",
        quad([[-5.0, -5.0, 0.0], [5.0, -5.0, 0.0], [5.0, 5.0, 0.0], [-5.0, 5.0, 0.0]]),
        Material::lambertian("/grey", Vec3A::splat(0.5)).0,
    );
    add(&mut scene, "/card", st_quad(1.0, 1.0, false), card);
    let mut sun = Light::distant("/sun", Vec3A::NEG_Z, Vec3A::splat(PI));
    sun.casts_shadows = false;
    scene.lights.push(sun);
    scene.camera = top_camera(2.0);
    let out =
        render(&scene, &RenderOptions { width: 8, height: 8, aovs: aovs(&["color", "depth", "alpha"]), ..Default::default() }, &NoProgress)
            .unwrap();
    for y in 0..8 {
        assert_eq!(out.film.pixel("color", 1, y), &[0.5, 0.5, 0.5], "cut out: the ground");
        assert!((out.film.pixel("depth", 1, y)[0] - 5.0).abs() < 1e-4);
        assert_eq!(out.film.pixel("color", 6, y), &[0.0, 1.0, 0.0], "the card");
        assert!((out.film.pixel("depth", 6, y)[0] - 4.0).abs() < 1e-4);
    }
    assert_eq!(ground, 0);
    // Nothing behind a cut-out card: nothing hit.
    scene.instances.remove(0);
    let out = render(&scene, &RenderOptions { width: 8, height: 8, aovs: aovs(&["alpha"]), ..Default::default() }, &NoProgress).unwrap();
    assert_eq!(out.film.pixel("alpha", 1, 3), &[0.0]);
    assert_eq!(out.film.pixel("alpha", 6, 3), &[1.0]);
}

/// Materials of every kind under a distant and a rect light with ambient occlusion: a lambert
/// floor (two faces), an emissive panel, a rough metal, a mirror, a smooth glass pane and a
/// coated plastic.
fn showcase() -> Scene {
    let mut scene = Scene::default();
    let floor_topo = MeshTopology {
        scheme: Scheme::None,
        face_vertex_counts: vec![4, 4],
        face_vertex_indices: vec![0, 1, 4, 3, 1, 2, 5, 4],
        ..Default::default()
    };
    let pts = [[-6.0, -6.0, 0.0], [0.0, -6.0, 0.0], [6.0, -6.0, 0.0], [-6.0, 6.0, 0.0], [0.0, 6.0, 0.0], [6.0, 6.0, 0.0]];
    let floor = Arc::new(BilinearSurface::new(&floor_topo, &pts).unwrap());
    add(&mut scene, "/floor", floor, Material::lambertian("/matte", Vec3A::new(0.7, 0.6, 0.5)).0);
    add(
        &mut scene,
        "/panel",
        quad([[-4.0, 2.0, 0.5], [-2.0, 2.0, 0.5], [-2.0, 4.0, 0.5], [-4.0, 4.0, 0.5]]),
        preview("/glow", |s| {
            s.emissive_color = Vec3A::new(2.0, 1.0, 0.5);
            s.diffuse_color = Vec3A::ZERO;
        }),
    );
    add(
        &mut scene,
        "/metal",
        quad([[1.0, 1.0, 0.3], [3.0, 1.0, 0.8], [3.0, 3.0, 0.8], [1.0, 3.0, 0.3]]),
        preview("/roughMetal", |s| {
            s.diffuse_color = Vec3A::new(0.9, 0.7, 0.3);
            s.metallic = 1.0;
            s.roughness = 0.3;
        }),
    );
    add(
        &mut scene,
        "/mirror",
        quad([[-3.0, -3.0, 0.2], [-1.0, -3.0, 0.6], [-1.0, -1.0, 0.6], [-3.0, -1.0, 0.2]]),
        Material::mirror("/chrome", Vec3A::ZERO, Vec3A::splat(0.9)),
    );
    add(
        &mut scene,
        "/pane",
        quad([[1.0, -3.0, 1.0], [3.0, -3.0, 1.0], [3.0, -1.0, 1.0], [1.0, -1.0, 1.0]]),
        preview("/glass", |s| {
            s.opacity = 0.0;
            s.roughness = 0.0;
        }),
    );
    add(
        &mut scene,
        "/coated",
        quad([[-1.0, -1.0, 0.4], [1.0, -1.0, 0.4], [1.0, 1.0, 0.4], [-1.0, 1.0, 0.4]]),
        preview("/lacquer", |s| {
            s.diffuse_color = Vec3A::new(0.8, 0.1, 0.1);
            s.clearcoat = 1.0;
            s.clearcoat_roughness = 0.1;
            s.roughness = 0.2;
        }),
    );
    scene.lights.push(Light::distant("/sun", Vec3A::new(0.3, 0.2, -1.0), Vec3A::splat(2.0)));
    let rect = LightShape::Rect { center: Vec3A::new(0.0, 0.0, 6.0), u: Vec3A::X, v: Vec3A::Y, normal: Vec3A::NEG_Z };
    scene.lights.push(Light::usd_area("/rect", rect, 3.0, 0.0, Vec3A::ONE, false));
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, -9.0, 8.0), Vec3::ZERO, Vec3::Z), 30.0);
    scene
}

#[test]
fn the_light_aovs_add_up_to_the_colour() {
    let scene = showcase();
    let names = [
        "color",
        "emission",
        "directDiffuse",
        "indirectDiffuse",
        "specular",
        "albedo",
        "position",
        "depth",
        "normal",
        "Neye",
        "elementId",
        "primId",
    ];
    let opts = RenderOptions { width: 48, height: 36, samples: 2, ao_samples: 4, aovs: aovs(&names), ..Default::default() };
    let out = render(&scene, &opts, &NoProgress).unwrap();
    let mut nonzero = [0usize; 4];
    let cam = &scene.camera;
    let to_cam = glam::Mat3A::from_mat4(cam.render_from_camera).transpose();
    let mut element = [0usize; 2];
    for y in 0..36 {
        for x in 0..48 {
            let c = Vec3A::from_slice(out.film.pixel("color", x, y));
            let parts = ["emission", "directDiffuse", "indirectDiffuse", "specular"].map(|a| Vec3A::from_slice(out.film.pixel(a, x, y)));
            let sum = parts.iter().fold(Vec3A::ZERO, |a, b| a + *b);
            assert!((c - sum).abs().max_element() <= 1e-5 * c.abs().max_element().max(1.0), "({x}, {y}): {c} vs {sum}");
            for (k, p) in parts.iter().enumerate() {
                nonzero[k] += usize::from(p.max_element() > 1e-4);
            }
            // Position, depth and Neye describe the same hit.
            let p = Vec3A::from_slice(out.film.pixel("position", x, y));
            if out.film.pixel("primId", x, y)[0] >= 0.0 {
                assert!((cam.depth(p) - out.film.pixel("depth", x, y)[0]).abs() < 1e-3);
                let n = Vec3A::from_slice(out.film.pixel("normal", x, y));
                let neye = Vec3A::from_slice(out.film.pixel("Neye", x, y));
                assert!((to_cam * n - neye).length() < 1e-3, "{neye} vs {}", to_cam * n);
                // Facing the camera: camera space looks down −z.
                assert!(neye.dot(Vec3A::from(cam.render_from_camera.inverse().transform_point3(p.into())).normalize()) <= 1e-3);
                // The floor's two control faces split at x = 0.
                if p.z.abs() < 1e-4 {
                    let e = out.film.pixel("elementId", x, y)[0];
                    let want = if p.x < 0.0 { 0.0 } else { 1.0 };
                    if p.x.abs() > 0.05 {
                        assert_eq!(e, want, "floor face at x = {}", p.x);
                        element[want as usize] += 1;
                    }
                }
            } else {
                assert_eq!(out.film.pixel("elementId", x, y), &[-1.0]);
            }
        }
    }
    assert!(nonzero.iter().all(|&n| n > 10), "each part lights something: {nonzero:?}");
    assert!(element.iter().all(|&n| n > 10), "{element:?}");
    let rays = &out.stats["render"]["rays"];
    for kind in ["reflection", "refraction", "glossy", "ao", "shadow"] {
        assert!(rays[kind].as_u64().unwrap() > 0, "{kind}");
    }
}

#[test]
fn effects_name_the_materials_that_call_for_them() {
    let out = render(&showcase(), &RenderOptions { width: 8, height: 6, ..Default::default() }, &NoProgress).unwrap();
    let fx: Vec<(String, String)> = out.stats["effects"]["enabled"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| (e["name"].as_str().unwrap().to_string(), e["why"].as_str().unwrap().to_string()))
        .collect();
    let why = |name: &str| fx.iter().find(|(n, _)| n == name).map(|(_, w)| w.clone()).unwrap_or_else(|| panic!("{name} missing: {fx:?}"));
    for m in ["/chrome", "/glass"] {
        assert!(why("reflection").contains(m), "{fx:?}");
    }
    assert!(!why("reflection").contains("/roughMetal") && !why("reflection").contains("/matte"));
    assert!(why("refraction").contains("/glass") && !why("refraction").contains("/chrome"));
    assert!(why("glossy").contains("/roughMetal") && why("glossy").contains("/lacquer") && !why("glossy").contains("/chrome"));
    assert!(why("emission").contains("/glow"));

    // UsdPreviewSurface's fallback material (a dielectric of roughness 0.5) and lambertians call
    // for nothing but camera and shadow rays; its highlight still comes from the light.
    let mut scene = Scene::default();
    add(
        &mut scene,
        "/ground",
        quad([[-5.0, -5.0, 0.0], [5.0, -5.0, 0.0], [5.0, 5.0, 0.0], [-5.0, 5.0, 0.0]]),
        preview("/fallback", |_| {}),
    );
    add(&mut scene, "/box", quad([[-1.0, -1.0, 1.0], [1.0, -1.0, 1.0], [1.0, 1.0, 1.0], [-1.0, 1.0, 1.0]]), Material::default());
    scene.lights.push(Light::distant("/sun", Vec3A::new(0.2, 0.1, -1.0), Vec3A::ONE));
    scene.camera = Camera::perspective(Camera::look_at(Vec3::new(0.0, -8.0, 6.0), Vec3::ZERO, Vec3::Z), 35.0);
    let out =
        render(&scene, &RenderOptions { width: 16, height: 12, aovs: aovs(&["color", "specular"]), ..Default::default() }, &NoProgress)
            .unwrap();
    let rays = &out.stats["render"]["rays"];
    for kind in ["reflection", "refraction", "glossy", "diffuse", "ao"] {
        assert_eq!(rays[kind].as_u64(), Some(0), "{kind}");
    }
    let names: Vec<&str> = out.stats["effects"]["enabled"].as_array().unwrap().iter().map(|e| e["name"].as_str().unwrap()).collect();
    assert_eq!(names, vec!["camera", "shadows"]);
    assert!(out.film.aov("specular").unwrap().data.iter().any(|v| *v > 0.0), "the dielectric's highlight");
    let e = render(&scene, &RenderOptions { glossy_samples: 0, ..Default::default() }, &NoProgress).err().unwrap().to_string();
    assert!(e.contains("glossySamples"), "{e}");
}

#[test]
fn every_effect_is_the_same_with_one_and_two_threads() {
    let scene = showcase();
    let base = RenderOptions { width: 40, height: 30, samples: 2, ao_samples: 4, aovs: aovs(&["color", "specular"]), ..Default::default() };
    let one = render(&scene, &RenderOptions { threads: 1, ..base.clone() }, &NoProgress).unwrap();
    let two = render(&scene, &RenderOptions { threads: 2, ..base }, &NoProgress).unwrap();
    assert_eq!(one.film.aov("color").unwrap().data, two.film.aov("color").unwrap().data);
    assert_eq!(one.film.aov("specular").unwrap().data, two.film.aov("specular").unwrap().data);
}

#[test]
fn extreme_inputs_never_reach_the_film_as_nan() {
    let extremes: Vec<(&str, PreviewSurface)> = vec![
        ("tinyIor", PreviewSurface { opacity: 0.0, roughness: 1e-3, ior: 1e-3, ..Default::default() }),
        (
            "hugeIor",
            PreviewSurface { opacity: 0.3, roughness: 0.0, ior: 50.0, clearcoat: 1.0, clearcoat_roughness: 0.0, ..Default::default() },
        ),
        ("ior1", PreviewSurface { opacity: 0.0, roughness: 0.7, ior: 1.0, ..Default::default() }),
        ("blackMetal", PreviewSurface { diffuse_color: Vec3A::ZERO, metallic: 1.0, roughness: 1.0, ..Default::default() }),
        (
            "whiteMirror",
            PreviewSurface {
                use_specular_workflow: true,
                specular_color: Vec3A::ONE,
                diffuse_color: Vec3A::ONE,
                roughness: 0.0,
                ..Default::default()
            },
        ),
    ];
    let mut scene = Scene::default();
    for (i, (name, s)) in extremes.into_iter().enumerate() {
        let x = i as f32 * 2.5 - 5.0;
        let mut m = Material::preview_surface(format!("/{name}"), s).0;
        // A normal map pointing straight into the surface: bent back above the horizon.
        m.textures.push((Input::Normal, texture([0.5, 0.5, 0.0, 1.0], [1.0, 0.5, 0.5, 1.0], 0, Vec3A::splat(2.0), Vec3A::splat(-1.0))));
        let p = |a: f32, b: f32, z: f32| [x + a, b, z];
        add(&mut scene, name, st_quad_at([p(-1.0, -1.0, 0.0), p(1.0, -1.0, 1.5), p(1.0, 1.0, 1.5), p(-1.0, 1.0, 0.0)], false), m);
    }
    scene.lights.push(Light::distant("/sun", Vec3A::new(0.1, 0.7, -0.3), Vec3A::splat(5.0)));
    scene.lights.push(Light::usd_area("/dome", LightShape::Dome(None), 0.5, 0.0, Vec3A::ONE, false));
    // Grazing and head-on views.
    for eye in [Vec3::new(0.0, -12.0, 0.05), Vec3::new(0.0, -1.0, 12.0)] {
        scene.camera = Camera::perspective(Camera::look_at(eye, Vec3::ZERO, Vec3::Z), 25.0);
        let names = ["color", "emission", "directDiffuse", "indirectDiffuse", "specular", "albedo", "normal", "Neye", "position"];
        let out = render(
            &scene,
            &RenderOptions { width: 32, height: 24, samples: 2, ao_samples: 2, aovs: aovs(&names), ..Default::default() },
            &NoProgress,
        )
        .unwrap();
        for a in names {
            assert!(out.film.aov(a).unwrap().data.iter().all(|v| v.is_finite()), "{a}");
        }
        assert_eq!(out.stats["render"]["dropped_samples"].as_u64(), Some(0));
    }
}

#[test]
fn a_network_feeds_an_input_and_its_non_finite_values_never_reach_the_image() {
    use glam::Vec4;
    use mipray::material::network::{NetworkLookup, Op, StTransform};
    use mipray::material::InputNetwork;
    // diffuseColor = a ÷ b of two split textures: on the left (0.2, 0.4, 0.1) ÷ 0.5, on the right
    // (0.3, 0, 0.6) ÷ 0 = (inf, NaN, inf), which the input clamps as a texture's value: (1, 0, 1).
    let lookup = |left: [f32; 4], right: [f32; 4]| NetworkLookup {
        sampler: Arc::new(SplitSampler { left, right }),
        texture: TextureHandle::new(0),
        path: "split.tx".into(),
        lookup: Lookup::DEFAULT,
        channels: 3,
        fallback: Vec4::ZERO,
        st_transform: StTransform::IDENTITY,
    };
    let a = lookup([0.2, 0.4, 0.1, 1.0], [0.3, 0.0, 0.6, 1.0]);
    let b = lookup([0.5; 4], [0.0; 4]);
    let net = InputNetwork::new(vec![Op::Texture(0), Op::Texture(1), Op::Divide], vec![a, b]).unwrap();
    let mut mat = Material::lambertian("/ratio", Vec3A::splat(0.18)).0;
    mat.networks.push((Input::DiffuseColor, net));
    assert!(mat.varies(Input::DiffuseColor));
    let mut scene = Scene::default();
    add(&mut scene, "/plate", st_quad(1.0, 0.0, false), mat);
    scene.lights.push(Light::distant("/sun", -Vec3A::Z, Vec3A::splat(PI)));
    scene.camera = top_camera(2.0);
    let options = RenderOptions { width: 8, height: 8, aovs: aovs(&["color", "albedo"]), ..Default::default() };
    let out = render(&scene, &options, &NoProgress).unwrap();
    for y in 0..8 {
        for (x, want) in [(1, [0.4, 0.8, 0.2]), (6, [1.0, 0.0, 1.0])] {
            let albedo = out.film.pixel("albedo", x, y);
            let color = out.film.pixel("color", x, y);
            for c in 0..3 {
                assert!((albedo[c] - want[c]).abs() < 1e-6, "({x}, {y}) albedo {albedo:?} vs {want:?}");
                // Lambertian under irradiance π head on: the albedo itself.
                assert!((color[c] - want[c]).abs() < 1e-5, "({x}, {y}) color {color:?} vs {want:?}");
            }
        }
    }
}
