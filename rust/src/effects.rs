//! Which effects a scene calls for, and why ("Effects a scene calls for" in DESIGN.md): the
//! integrator traces only these, and the stats list each with the prim or setting that asked.

use serde::Serialize;

use crate::options::RenderOptions;
use crate::scene::Scene;

/// One enabled effect and the reason for it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Effect {
    pub name: String,
    pub why: String,
}

/// The effects `scene` rendered with `options` calls for: camera rays always; shadow rays
/// toward each light that casts shadows; mirror reflection from materials with a mirror layer
/// (and a maximum depth above 0); ambient occlusion when the settings ask for AO samples.
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
    let mirrors: Vec<&str> = scene
        .materials
        .iter()
        .enumerate()
        .filter(|(i, m)| {
            let s = &m.surface;
            let specular = if s.use_specular_workflow { s.specular_color.max_element() > 0.0 } else { s.metallic > 0.0 };
            used.contains(i) && specular && s.roughness == 0.0
        })
        .map(|(_, m)| m.name.as_str())
        .collect();
    if !mirrors.is_empty() && options.max_depth > 0 {
        let shown: Vec<&str> = mirrors.iter().take(5).copied().collect();
        let more = if mirrors.len() > 5 { format!(" and {} more", mirrors.len() - 5) } else { String::new() };
        out.push(Effect { name: "reflection".into(), why: format!("mirror materials: {}{more}", shown.join(", ")) });
    }
    let cam = &scene.camera;
    if cam.has_depth_of_field() {
        out.push(Effect { name: "depth_of_field".into(), why: format!("camera fStop {} focused at {}", cam.f_stop, cam.focus_distance) });
    }
    let moving: Vec<&str> = scene
        .moving_instances()
        .filter_map(|i| scene.meshes.get(i.mesh).map(|m| m.name.as_str()))
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
