//! Progressive rendering through the render pass: the buffers after every pass reach the caller
//! in order, the last one is the finished (and one-pass) image, and the settings parse.

mod common;

use std::sync::Mutex;

use glam::Vec3;
use hd_mipray::render_pass::PassUpdate;
use hd_mipray::{RenderPass, RenderSettings};
use mipray::aov::Aov;
use mipray::options::IntegratorKind;
use mipray::progress::NoProgress;
use serde_json::json;

fn settings(pairs: serde_json::Value) -> RenderSettings {
    RenderSettings::from_pairs(pairs.as_object().unwrap().iter().map(|(k, v)| (k.as_str(), v))).unwrap()
}

#[test]
fn the_settings_parse_and_reach_the_core() {
    let s = settings(json!({"progressive": 1, "russianRouletteDepth": 5, "integrator": "path"}));
    let o = s.to_options(8, 8, &[Aov::Color]);
    assert!(o.progressive);
    assert_eq!(o.russian_roulette_depth, 5);
    assert_eq!(o.integrator, IntegratorKind::Path);
    let d = RenderSettings::default().to_options(8, 8, &[]);
    assert!(!d.progressive && d.russian_roulette_depth == 3 && d.integrator == IntegratorKind::Auto);
    assert!(settings(json!({"progressive": true})).progressive);
    assert!(RenderSettings::from_pairs([("progressive", &json!("yes"))]).is_err());
    let e = RenderSettings::from_pairs([("integrator", &json!("ao"))]).unwrap_err().to_string();
    assert!(e.contains("aoSamples"), "{e}");
    assert!(settings(json!({"integrator": "ao", "aoSamples": 4})).ao_samples == 4);
    for key in ["progressive", "russianRouletteDepth"] {
        assert!(hd_mipray::config::SETTINGS.iter().any(|d| d.key == key), "{key} is described");
    }
}

#[test]
fn each_pass_reaches_the_caller_as_render_buffers() {
    let mut delegate = common::delegate_with_camera(Vec3::new(0.0, -3.0, 4.0), Vec3::ZERO, true);
    delegate.set_mesh("/cube", common::grey_mesh("/cube", common::cube(), 0.6));
    let pass = |progressive: bool| RenderPass {
        camera: "/cam".into(),
        width: 24,
        height: 20,
        aovs: vec![Aov::Color, Aov::Depth],
        settings: RenderSettings { samples: 8, integrator: IntegratorKind::Path, progressive, ..RenderSettings::default() },
    };
    let seen: Mutex<Vec<PassUpdate>> = Mutex::new(Vec::new());
    let result = pass(true).execute_with_updates(&mut delegate, &NoProgress, &|u| seen.lock().unwrap().push(u)).unwrap();
    let seen = seen.into_inner().unwrap();
    assert_eq!(seen.iter().map(|u| u.samples).collect::<Vec<_>>(), [1, 2, 4, 8]);
    assert_eq!(seen.iter().map(|u| u.converged).collect::<Vec<_>>(), [false, false, false, true]);
    for u in &seen {
        assert_eq!(u.buffers.iter().map(|b| b.aov.as_str()).collect::<Vec<_>>(), ["color", "depth"]);
        assert_eq!(u.buffers[0].data.len(), 24 * 20 * 3);
    }
    assert_eq!(seen.last().unwrap().buffers, result.buffers, "the last update is the result");
    assert_ne!(seen[0].buffers[0].data, result.buffers[0].data, "the first pass is a rougher image");
    // Against a one-pass render on the same delegate, whose geometry cache the first render
    // left warm: the cache changes the cost, never the answer (tests/warm_cache.rs).
    let one_pass = pass(false).execute(&mut delegate, &NoProgress).unwrap();
    assert_eq!(one_pass.buffers, result.buffers, "progressive ends where one pass does");
}
