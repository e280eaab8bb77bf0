//! Which effects a scene calls for, and why ("Effects a scene calls for" in DESIGN.md): the
//! integrator traces only these, and the stats list each with the prim or setting that asked.

use serde::Serialize;

use crate::scene::Scene;

/// One enabled effect and the reason for it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Effect {
    pub name: String,
    pub why: String,
}

/// The effects `scene` calls for. Camera rays always; shadow rays toward each light that
/// casts shadows.
pub fn analyze(scene: &Scene) -> Vec<Effect> {
    let mut out = vec![Effect { name: "camera".into(), why: "primary visibility".into() }];
    let shadow_lights: Vec<&str> = scene.lights.iter().filter(|l| l.casts_shadows).map(|l| l.name.as_str()).collect();
    if !shadow_lights.is_empty() {
        out.push(Effect { name: "shadows".into(), why: format!("lights casting shadows: {}", shadow_lights.join(", ")) });
    }
    out
}

/// True when `name` is among `effects`.
pub fn enabled(effects: &[Effect], name: &str) -> bool {
    effects.iter().any(|e| e.name == name)
}
