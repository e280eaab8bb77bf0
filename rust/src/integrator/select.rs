//! Which integrator renders, from the `integrator` render setting and the effects the scene
//! calls for (DESIGN.md, "Effects a scene calls for").
//!
//! The rule: `auto` (the default) is the classic integrator — direct light with shadows,
//! specular and glossy reflection and refraction to `maxDepth` — plus ambient occlusion when
//! `aoSamples` > 0. Nothing in a USD scene by itself asks for indirect diffuse light, so
//! hemisphere rays are traced only where a setting asks for them: `aoSamples` (ambient
//! occlusion), `integrator = colorBleeding` (one diffuse bounce) or `integrator = path`.
//!
//! | setting | integrator | hemisphere rays |
//! |---|---|---|
//! | `auto` | [`DirectLighting`] | AO rays when `aoSamples` > 0 |
//! | `direct` | [`DirectLighting`] | none, even with `aoSamples` set |
//! | `ao` | [`AmbientOcclusion`] (needs `aoSamples` > 0) | AO rays |
//! | `colorBleeding` | [`ColorBleeding`] | `indirectSamples` diffuse rays per hit |
//! | `path` | [`PathTracer`] | one diffuse or glossy ray per bounce |
//!
//! The stats' `effects.enabled` lists what the chosen integrator traces: [`effects`] starts
//! from [`crate::effects::analyze`] (lights, materials, camera, settings) and adds or removes
//! what the integrator itself calls for, each with the setting that asked.

use crate::effects::{analyze, Effect};
use crate::error::RenderError;
use crate::options::{IntegratorKind, RenderOptions};
use crate::scene::Scene;
use crate::trace::Tracer;

use super::ao::AmbientOcclusion;
use super::bleed::ColorBleeding;
use super::path::PathTracer;
use super::{DirectLighting, Integrator};

/// The integrator `kind` stands for: `Auto` is the classic one ([`IntegratorKind::Direct`],
/// with ambient occlusion when the settings ask for it).
pub fn resolve(kind: IntegratorKind) -> IntegratorKind {
    match kind {
        IntegratorKind::Auto => IntegratorKind::Direct,
        k => k,
    }
}

/// Effects of the ambient-occlusion integrator: it traces camera and AO rays only.
const AO_TRACES: &[&str] = &["camera", "depth_of_field", "motion_blur", "ao"];

/// The effects `scene` rendered with `options` calls for, with the integrator's own: what the
/// stats' `effects.enabled` lists and what the integrator traces.
pub fn effects(scene: &Scene, options: &RenderOptions) -> Vec<Effect> {
    let mut fx = analyze(scene, options);
    let setting = options.integrator.name();
    match (options.integrator, resolve(options.integrator)) {
        (IntegratorKind::Auto, _) => {}
        (_, IntegratorKind::Direct) => fx.retain(|e| e.name != "ao"),
        (_, IntegratorKind::Ao) => {
            fx.retain(|e| AO_TRACES.contains(&e.name.as_str()));
            if let Some(ao) = fx.iter_mut().find(|e| e.name == "ao") {
                ao.why = format!("render settings integrator = ao, aoSamples = {}", options.ao_samples);
            }
        }
        (_, IntegratorKind::ColorBleeding) => {
            if options.indirect_samples > 0 {
                fx.push(Effect {
                    name: "indirect_diffuse".into(),
                    why: format!("render setting integrator = {setting} (indirectSamples = {})", options.indirect_samples),
                });
            }
        }
        (_, IntegratorKind::Path) => {
            if options.max_depth > 0 {
                fx.push(Effect {
                    name: "indirect_diffuse".into(),
                    why: format!("render setting integrator = {setting} (maxDepth = {})", options.max_depth),
                });
            }
        }
        (_, IntegratorKind::Auto) => unreachable!("resolve never returns Auto"),
    }
    fx
}

/// The integrator the settings ask for, tracing `effects` (from [`effects`]).
///
/// # Errors
/// [`RenderError::Settings`] when the integrator cannot run with these settings
/// (`integrator = ao` without `aoSamples`).
pub fn select<'a>(
    tracer: &'a Tracer<'a>,
    scene: &'a Scene,
    effects: &[Effect],
    options: &RenderOptions,
) -> Result<Box<dyn Integrator + 'a>, RenderError> {
    Ok(match resolve(options.integrator) {
        IntegratorKind::Auto | IntegratorKind::Direct => Box::new(DirectLighting::new(tracer, scene, effects, options)),
        IntegratorKind::Ao => {
            if options.ao_samples == 0 {
                return Err(RenderError::Settings(crate::settings::AO_NEEDS_SAMPLES.into()));
            }
            Box::new(AmbientOcclusion::new(tracer, scene, effects, options))
        }
        IntegratorKind::ColorBleeding => Box::new(ColorBleeding::new(tracer, scene, effects, options)),
        IntegratorKind::Path => Box::new(PathTracer::new(tracer, scene, effects, options)),
    })
}
