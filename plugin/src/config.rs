//! Render settings the delegate accepts, with defaults and descriptions (Hydra's
//! `HdRenderSettingDescriptor`), and their translation into the core's `RenderOptions`.

use mipray::geometry_cache::{CacheConfig, CacheMode};
use mipray::options::RenderOptions;
use serde_json::Value;

use crate::error::DelegateError;

/// One render setting: its key, default and what it does.
#[derive(Clone, Debug, PartialEq)]
pub struct SettingDescriptor {
    pub key: &'static str,
    pub default: &'static str,
    pub description: &'static str,
}

/// Every setting the delegate accepts.
pub const SETTINGS: &[SettingDescriptor] = &[
    SettingDescriptor { key: "samples", default: "1", description: "camera samples per pixel" },
    SettingDescriptor { key: "seed", default: "0", description: "random seed; the image depends on it alone" },
    SettingDescriptor { key: "threads", default: "0", description: "render threads (0: all cores)" },
    SettingDescriptor { key: "tessFactor", default: "1", description: "tessellated quad size relative to the ray beam width; larger is coarser" },
    SettingDescriptor { key: "tessFactorIncoherent", default: "1", description: "extra tessFactor for incoherent rays (ambient occlusion, diffuse, glossy): the paper's claim is that coarsening them costs little" },
    SettingDescriptor { key: "geometryCacheMb", default: "30", description: "geometry cache budget in MB (10^6 bytes), split evenly over the three tiers in multires mode" },
    SettingDescriptor { key: "geometryCacheCoarseMb", default: "", description: "multires only: the coarse (2×2) tier's budget in MB, overriding its third of geometryCacheMb" },
    SettingDescriptor { key: "geometryCacheMediumMb", default: "", description: "multires only: the medium (5×5) tier's budget in MB" },
    SettingDescriptor { key: "geometryCacheFineMb", default: "", description: "multires only: the fine (17×17) tier's budget in MB" },
    SettingDescriptor { key: "textureFilter", default: "differentials", description: "texture MIP level choice: differentials (filter widths from the ray differentials) or finest (the paper's 6.3.3 experiment)" },
    SettingDescriptor { key: "textureCacheMb", default: "10", description: "OpenImageIO texture cache budget in MB" },
    SettingDescriptor { key: "cacheMode", default: "multires", description: "geometry cache mode: multires, single, unbounded or none" },
    SettingDescriptor { key: "displacementBound", default: "0", description: "displacement bound (object units) for meshes that state none" },
    SettingDescriptor { key: "aoSamples", default: "0", description: "ambient-occlusion rays per shading point (0: off)" },
    SettingDescriptor { key: "aoDistance", default: "inf", description: "ambient-occlusion ray length, scene units" },
    SettingDescriptor { key: "aoIntensity", default: "1", description: "radiance of the white sky ambient occlusion lights with" },
    SettingDescriptor { key: "shadowSamples", default: "4", description: "light samples per shading point, shared among the lights by importance (plus as many BSDF samples)" },
    SettingDescriptor { key: "glossySamples", default: "4", description: "glossy rays per shading point at a camera ray's first non-mirror hit (1 further along)" },
    SettingDescriptor { key: "maxDepth", default: "4", description: "longest chain of specular bounces (and path length for path tracing)" },
    SettingDescriptor { key: "integrator", default: "auto", description: "auto (what the scene calls for), direct, ao, colorBleeding or path" },
    SettingDescriptor { key: "indirectSamples", default: "16", description: "hemisphere rays per shading point for one-bounce indirect diffuse (color bleeding)" },
    SettingDescriptor { key: "irradianceCache", default: "0", description: "interpolate ambient occlusion and irradiance with gradients (the paper's 5.1): 0 or 1" },
    SettingDescriptor { key: "irradianceCacheError", default: "0.2", description: "the irradiance cache's error bound (Ward's a); smaller is more accurate" },
    SettingDescriptor { key: "russianRouletteDepth", default: "3", description: "path tracing: bounces before Russian roulette may end a path (maxDepth or more: never)" },
    SettingDescriptor { key: "progressive", default: "0", description: "render in passes of 1, 2, 4, ... samples per pixel, reporting each; the final image is the same: 0 or 1" },
    SettingDescriptor { key: "seams", default: "1", description: "seam boxes closing cracks between tessellation rates (docs/cracks.md); 0 only to measure them: rays then slip through cracks" },
];

/// The settings a render was asked for, validated.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    pub samples: u32,
    pub seed: u64,
    pub threads: usize,
    pub tess_factor: f32,
    pub tess_factor_incoherent: f32,
    pub geometry_cache_mb: f64,
    /// Per-tier overrides (coarse, medium, fine) in MB, multires mode.
    pub tier_mb: [Option<f64>; 3],
    pub cache_mode: CacheMode,
    pub texture_filter: mipray::texture::FilterMode,
    pub texture_cache_mb: f32,
    pub displacement_bound: f32,
    pub ao_samples: u32,
    pub ao_distance: f32,
    pub ao_intensity: f32,
    pub max_depth: u32,
    pub shadow_samples: u32,
    pub glossy_samples: u32,
    pub integrator: mipray::options::IntegratorKind,
    pub indirect_samples: u32,
    pub irradiance_cache: bool,
    pub irradiance_cache_error: f32,
    pub russian_roulette_depth: u32,
    pub progressive: bool,
    pub seams: bool,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            samples: 1,
            seed: 0,
            threads: 0,
            tess_factor: 1.0,
            tess_factor_incoherent: 1.0,
            geometry_cache_mb: 30.0,
            tier_mb: [None; 3],
            cache_mode: CacheMode::Multires,
            texture_filter: mipray::texture::FilterMode::Differentials,
            texture_cache_mb: 10.0,
            displacement_bound: 0.0,
            ao_samples: 0,
            ao_distance: f32::INFINITY,
            ao_intensity: 1.0,
            max_depth: 4,
            shadow_samples: 4,
            glossy_samples: 4,
            integrator: mipray::options::IntegratorKind::Auto,
            indirect_samples: 16,
            irradiance_cache: false,
            irradiance_cache_error: 0.2,
            russian_roulette_depth: 3,
            progressive: false,
            seams: true,
        }
    }
}

fn bad(name: &str, message: impl Into<String>) -> DelegateError {
    DelegateError::Setting { name: name.to_string(), message: message.into() }
}

fn as_f64(name: &str, v: &Value) -> Result<f64, DelegateError> {
    v.as_f64()
        .or_else(|| v.as_str().and_then(|s| s.parse().ok()))
        .filter(|x| x.is_finite())
        .ok_or_else(|| bad(name, format!("{v} is not a finite number")))
}

impl RenderSettings {
    /// Applies `key = value` pairs over the defaults.
    ///
    /// # Errors
    /// An unknown key (the message lists the valid ones) or a value out of range.
    pub fn from_pairs<'a, I: IntoIterator<Item = (&'a str, &'a Value)>>(pairs: I) -> Result<Self, DelegateError> {
        let mut s = RenderSettings::default();
        for (k, v) in pairs {
            match k {
                "samples" => {
                    let x = as_f64(k, v)?;
                    if !(1.0..=1e6).contains(&x) {
                        return Err(bad(k, format!("{x} must be within 1..=1000000")));
                    }
                    s.samples = x as u32;
                }
                "seed" => s.seed = as_f64(k, v)?.max(0.0) as u64,
                "threads" => s.threads = as_f64(k, v)?.clamp(0.0, 1024.0) as usize,
                "tessFactor" => {
                    let x = as_f64(k, v)?;
                    if x <= 0.0 {
                        return Err(bad(k, format!("{x} must be positive")));
                    }
                    s.tess_factor = x as f32;
                }
                "tessFactorIncoherent" => {
                    let x = as_f64(k, v)?;
                    if x <= 0.0 {
                        return Err(bad(k, format!("{x} must be positive")));
                    }
                    s.tess_factor_incoherent = x as f32;
                }
                "geometryCacheMb" => {
                    let x = as_f64(k, v)?;
                    if x < 0.0 {
                        return Err(bad(k, format!("{x} must not be negative")));
                    }
                    s.geometry_cache_mb = x;
                }
                "geometryCacheCoarseMb" | "geometryCacheMediumMb" | "geometryCacheFineMb" => {
                    let x = as_f64(k, v)?;
                    if x < 0.0 {
                        return Err(bad(k, format!("{x} must not be negative")));
                    }
                    let tier = match k {
                        "geometryCacheCoarseMb" => 0,
                        "geometryCacheMediumMb" => 1,
                        _ => 2,
                    };
                    s.tier_mb[tier] = Some(x);
                }
                "textureFilter" => {
                    let name = v.as_str().ok_or_else(|| bad(k, format!("{v} is not a string")))?;
                    s.texture_filter = mipray::texture::FilterMode::from_name(name)
                        .ok_or_else(|| bad(k, format!("'{name}' is not differentials or finest")))?;
                }
                "textureCacheMb" => {
                    let x = as_f64(k, v)?;
                    if x <= 0.0 {
                        return Err(bad(k, format!("{x} must be positive")));
                    }
                    s.texture_cache_mb = x as f32;
                }
                "cacheMode" => {
                    let name = v.as_str().ok_or_else(|| bad(k, format!("{v} is not a string")))?;
                    s.cache_mode = name.parse().map_err(|e| bad(k, format!("{e}")))?;
                }
                "displacementBound" => s.displacement_bound = as_f64(k, v)?.max(0.0) as f32,
                "aoSamples" => s.ao_samples = as_f64(k, v)?.clamp(0.0, 65_536.0) as u32,
                "aoDistance" => {
                    let x = if v.as_str() == Some("inf") { f64::INFINITY } else { as_f64(k, v)? };
                    if x <= 0.0 {
                        return Err(bad(k, format!("{x} must be positive")));
                    }
                    s.ao_distance = x as f32;
                }
                "aoIntensity" => s.ao_intensity = as_f64(k, v)?.max(0.0) as f32,
                "maxDepth" => s.max_depth = as_f64(k, v)?.clamp(0.0, 64.0) as u32,
                "shadowSamples" => {
                    let x = as_f64(k, v)?;
                    if !(1.0..=4096.0).contains(&x) {
                        return Err(bad(k, format!("{x} must be within 1..=4096")));
                    }
                    s.shadow_samples = x as u32;
                }
                "glossySamples" => {
                    let x = as_f64(k, v)?;
                    if !(1.0..=65_536.0).contains(&x) {
                        return Err(bad(k, format!("{x} must be within 1..=65536")));
                    }
                    s.glossy_samples = x as u32;
                }
                "integrator" => {
                    let name = v.as_str().ok_or_else(|| bad(k, format!("{v} is not a string")))?;
                    s.integrator = mipray::options::IntegratorKind::from_name(name)
                        .ok_or_else(|| bad(k, format!("'{name}' is not one of {}", mipray::options::IntegratorKind::NAMES.join(", "))))?;
                }
                "indirectSamples" => s.indirect_samples = as_f64(k, v)?.clamp(0.0, 65_536.0) as u32,
                "irradianceCache" => {
                    s.irradiance_cache = match v {
                        Value::Bool(b) => *b,
                        _ => as_f64(k, v)? != 0.0,
                    }
                }
                "irradianceCacheError" => {
                    let x = as_f64(k, v)?;
                    if !(x > 0.0 && x <= 10.0) {
                        return Err(bad(k, format!("{x} must be within (0, 10]")));
                    }
                    s.irradiance_cache_error = x as f32;
                }
                "russianRouletteDepth" => s.russian_roulette_depth = as_f64(k, v)?.clamp(0.0, 64.0) as u32,
                "seams" => {
                    s.seams = match v {
                        Value::Bool(b) => *b,
                        _ => as_f64(k, v)? != 0.0,
                    }
                }
                "progressive" => {
                    s.progressive = match v {
                        Value::Bool(b) => *b,
                        _ => as_f64(k, v)? != 0.0,
                    }
                }
                _ => {
                    let keys: Vec<&str> = SETTINGS.iter().map(|d| d.key).collect();
                    return Err(bad(k, format!("unknown setting; valid settings: {}", keys.join(", "))));
                }
            }
        }
        // Settings that only make sense together, checked once all are read.
        if s.integrator == mipray::options::IntegratorKind::Ao && s.ao_samples == 0 {
            return Err(bad("integrator", "ao needs aoSamples > 0 (ambient-occlusion rays per shading point)"));
        }
        Ok(s)
    }

    /// OpenImageIO texture-system options for these settings.
    pub fn texture_options(&self) -> mipray_bridge::OiioTextureOptions {
        mipray_bridge::OiioTextureOptions { max_memory_mb: self.texture_cache_mb, filter: self.texture_filter, ..Default::default() }
    }

    /// The core's options for a render of `width`×`height` with `aovs`.
    pub fn to_options(&self, width: usize, height: usize, aovs: &[String]) -> RenderOptions {
        let bytes = (self.geometry_cache_mb * 1e6) as usize;
        let cache = match self.cache_mode {
            CacheMode::Multires => {
                let mut c = CacheConfig::multires(bytes);
                for (budget, mb) in c.budget_bytes.iter_mut().zip(self.tier_mb) {
                    if let Some(mb) = mb {
                        *budget = (mb * 1e6) as usize;
                    }
                }
                c
            }
            CacheMode::Single => CacheConfig::single(bytes),
            CacheMode::Unbounded => CacheConfig::unbounded(),
            CacheMode::None => CacheConfig::none(),
        };
        RenderOptions {
            width,
            height,
            samples: self.samples,
            seed: self.seed,
            threads: self.threads,
            tess_factor: self.tess_factor,
            tess_factor_incoherent: self.tess_factor_incoherent,
            cache,
            aovs: aovs.to_vec(),
            ao_samples: self.ao_samples,
            ao_distance: self.ao_distance,
            ao_intensity: self.ao_intensity,
            max_depth: self.max_depth,
            shadow_samples: self.shadow_samples,
            glossy_samples: self.glossy_samples,
            integrator: self.integrator,
            indirect_samples: self.indirect_samples,
            irradiance_cache: self.irradiance_cache,
            irradiance_cache_error: self.irradiance_cache_error,
            russian_roulette_depth: self.russian_roulette_depth,
            progressive: self.progressive,
            seams: self.seams,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
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
