//! Render settings the delegate accepts (Hydra's `HdRenderSettingDescriptor`s): the core's
//! table, [`mipray::settings`], is the one statement of every key, type, range, default and
//! description; this module adds only what the delegate's own parts read.

pub use mipray::settings::{RenderSettings, Setting as SettingDescriptor, SETTINGS};

/// OpenImageIO texture-system options for `settings`.
pub fn texture_options(settings: &RenderSettings) -> mipray_bridge::OiioTextureOptions {
    mipray_bridge::OiioTextureOptions { max_memory_mb: settings.texture_cache_mb, filter: settings.texture_filter, ..Default::default() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mipray::geometry_cache::CacheMode;
    use serde_json::json;

    #[test]
    fn defaults_and_overrides() {
        let v = json!({"samples": 4, "cacheMode": "single", "tessFactor": "2"});
        let s = RenderSettings::from_pairs(v.as_object().unwrap().iter().map(|(k, v)| (k.as_str(), v))).unwrap();
        assert_eq!(s.samples, 4);
        assert_eq!(s.cache_mode, CacheMode::Single);
        assert_eq!(s.tess_factor, 2.0);
        assert_eq!(s.seed, 0);
        assert!(s.seams && s.to_options(1, 1, &[]).seams, "seam boxes are on by default");
        let off = json!({"seams": 0});
        let s = RenderSettings::from_pairs(off.as_object().unwrap().iter().map(|(k, v)| (k.as_str(), v))).unwrap();
        assert!(!s.to_options(1, 1, &[]).seams);
    }

    #[test]
    fn per_tier_budgets_override_their_third() {
        let v = json!({"geometryCacheMb": 30, "geometryCacheFineMb": 20});
        let s = RenderSettings::from_pairs(v.as_object().unwrap().iter().map(|(k, v)| (k.as_str(), v))).unwrap();
        assert_eq!(s.to_options(1, 1, &[]).cache.budget_bytes, [10_000_000, 10_000_000, 20_000_000]);
    }

    #[test]
    fn unknown_key_lists_valid_ones() {
        let v = json!(1);
        let e = RenderSettings::from_pairs([("sample", &v)]).unwrap_err().to_string();
        assert!(e.contains("sample") && e.contains("tessFactor"), "{e}");
        let bad_mode = json!("lru");
        assert!(RenderSettings::from_pairs([("cacheMode", &bad_mode)]).is_err());
        let neg = json!(-1);
        assert!(RenderSettings::from_pairs([("tessFactor", &neg)]).is_err());
    }
}
