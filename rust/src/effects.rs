//! Which effects a scene calls for, and why ("Effects a scene calls for" in DESIGN.md): the
//! integrator traces only these, and the stats list each with the prim or setting that asked.

use serde::Serialize;

use crate::material::SurfaceCalls;
use crate::options::RenderOptions;
use crate::scene::Scene;

/// One enabled effect and the reason for it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Effect {
    pub name: String,
    pub why: String,
}

/// The effects `scene` rendered with `options` calls for: camera rays always; shadow rays
/// toward each light that casts shadows; soft shadows toward wide lights; from the materials of
/// placed meshes ([`crate::material::PreviewSurface::calls`], with a maximum depth above 0):
/// `reflection` from delta-specular lobes, `refraction` from transmitting ones, `glossy` from
/// significant rough specular; `emission` from emissive materials (no rays: it is listed
/// because the image has it); depth of field; ambient occlusion when the settings ask for AO
/// samples. Each names the materials (up to five) or setting that called for it.
pub fn analyze(scene: &Scene, options: &RenderOptions) -> Vec<Effect> {
    let mut out = vec![Effect { name: "camera".into(), why: "primary visibility".into() }];
    let shadow_lights: Vec<&str> = scene.lights.iter().filter(|l| l.casts_shadows).map(|l| l.name.as_str()).collect();
    if !shadow_lights.is_empty() {
        out.push(Effect { name: "shadows".into(), why: format!("lights casting shadows: {}", shadow_lights.join(", ")) });
    }
    // Materials of placed meshes, per-face ones (GeomSubsets) included; each mesh looked at once.
    let placed: std::collections::HashSet<usize> = scene.instances.iter().map(|i| i.mesh).collect();
    let wide: Vec<&str> = scene.lights.iter().filter(|l| l.casts_shadows && !l.is_delta()).map(|l| l.name.as_str()).collect();
    if !wide.is_empty() {
        out.push(Effect { name: "soft_shadows".into(), why: format!("area, dome or angular lights: {}", wide.join(", ")) });
    }
    let mut used = std::collections::HashSet::new();
    for m in placed.iter().filter_map(|&i| scene.meshes.get(i)) {
        used.insert(m.material);
        used.extend(m.face_materials.iter().flat_map(|t| t.iter().map(|&f| f as usize)));
    }
    // What each used material's lobes call for (textured inputs may take any value).
    let calls: Vec<(&str, SurfaceCalls)> =
        scene.materials.iter().enumerate().filter(|(i, _)| used.contains(i)).map(|(_, m)| (m.name.as_str(), m.calls())).collect();
    let named = |pick: fn(&SurfaceCalls) -> bool| -> Vec<&str> { calls.iter().filter(|(_, c)| pick(c)).map(|(n, _)| *n).collect() };
    let list = |names: &[&str]| {
        let shown: Vec<&str> = names.iter().take(5).copied().collect();
        let more = if names.len() > 5 { format!(" and {} more", names.len() - 5) } else { String::new() };
        format!("{}{more}", shown.join(", "))
    };
    if options.max_depth > 0 {
        let mirrors = named(|c| c.reflection);
        if !mirrors.is_empty() {
            out.push(Effect { name: "reflection".into(), why: format!("smooth specular materials: {}", list(&mirrors)) });
        }
        let glass = named(|c| c.refraction);
        if !glass.is_empty() {
            out.push(Effect { name: "refraction".into(), why: format!("transmitting materials (opacity < 1): {}", list(&glass)) });
        }
        let glossy = named(|c| c.glossy);
        if !glossy.is_empty() {
            out.push(Effect { name: "glossy".into(), why: format!("rough specular materials: {}", list(&glossy)) });
        }
    }
    let emissive = named(|c| c.emission);
    if !emissive.is_empty() {
        out.push(Effect { name: "emission".into(), why: format!("emissive materials: {}", list(&emissive)) });
    }
    let cam = &scene.camera;
    if cam.has_depth_of_field() {
        let camera = if cam.name.is_empty() { "camera".to_string() } else { format!("camera {}", cam.name) };
        out.push(Effect {
            name: "depth_of_field".into(),
            why: format!("{camera}: fStop {} focused at {}", cam.f_stop, cam.focus_distance),
        });
    }
    // Moving mesh lights too: their emission is posed at each ray's time.
    let moving_lights = scene.lights.iter().filter(|l| matches!(&l.shape, crate::light::LightShape::Mesh(m) if m.is_moving()));
    let moving: Vec<&str> = scene
        .moving_instances()
        .filter_map(|i| scene.meshes.get(i.mesh).map(|m| m.name.as_str()))
        .chain(moving_lights.map(|l| l.name.as_str()))
        .chain(scene.meshes.iter().filter(|m| m.surface.deforms()).map(|m| m.name.as_str()))
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    if !moving.is_empty() {
        let shown: Vec<&str> = moving.iter().take(5).copied().collect();
        let more = if moving.len() > 5 { format!(" and {} more", moving.len() - 5) } else { String::new() };
        out.push(Effect { name: "motion_blur".into(), why: format!("moving within the shutter: {}{more}", shown.join(", ")) });
    }
    if options.ao_samples > 0 {
        out.push(Effect { name: "ao".into(), why: format!("render setting aoSamples = {}", options.ao_samples) });
    }
    out
}

/// True when `name` is among `effects`.
pub fn enabled(effects: &[Effect], name: &str) -> bool {
    effects.iter().any(|e| e.name == name)
}

#[cfg(test)]
mod tests {
    use glam::{Mat4, Vec3A};

    use super::*;
    use crate::camera::Camera;
    use crate::light::Light;

    fn why<'e>(effects: &'e [Effect], name: &str) -> Option<&'e str> {
        effects.iter().find(|e| e.name == name).map(|e| e.why.as_str())
    }

    #[test]
    fn depth_of_field_names_the_camera_prim_and_its_f_stop() {
        let camera = Camera { name: "/World/shot_cam".into(), f_stop: 2.8, focus_distance: 7.5, ..Camera::default() };
        let mut scene = Scene { camera, ..Scene::default() };
        let effects = analyze(&scene, &RenderOptions::default());
        let reason = why(&effects, "depth_of_field").expect("an f-stop and a focus distance call for depth of field");
        assert!(reason.contains("/World/shot_cam") && reason.contains("2.8") && reason.contains("7.5"), "{reason}");
        scene.camera.f_stop = 0.0;
        assert_eq!(why(&analyze(&scene, &RenderOptions::default()), "depth_of_field"), None);
    }

    #[test]
    fn a_distant_light_with_an_angle_calls_for_soft_shadows_and_one_without_does_not() {
        let mut scene = Scene::default();
        let sun = |angle_deg: f32| Light::usd_distant("/World/sun", &Mat4::IDENTITY, 1.0, 0.0, Vec3A::ONE, angle_deg, false);
        scene.lights.push(sun(0.53));
        let effects = analyze(&scene, &RenderOptions::default());
        let reason = why(&effects, "soft_shadows").expect("an angular sun casts soft shadows");
        assert!(reason.contains("/World/sun"), "{reason}");
        assert!(why(&effects, "shadows").is_some_and(|w| w.contains("/World/sun")));

        scene.lights = vec![sun(0.0)];
        let effects = analyze(&scene, &RenderOptions::default());
        assert_eq!(why(&effects, "soft_shadows"), None, "a point at infinity casts hard shadows: {effects:?}");
        assert!(why(&effects, "shadows").is_some());
        // A sun that casts no shadows calls for no shadow rays at all.
        scene.lights = vec![Light { casts_shadows: false, ..sun(0.53) }];
        let effects = analyze(&scene, &RenderOptions::default());
        assert_eq!((why(&effects, "shadows"), why(&effects, "soft_shadows")), (None, None), "{effects:?}");
    }
}
