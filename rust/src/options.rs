//! Render settings with their defaults. Names follow the render settings the delegate exposes
//! (`samples`, `seed`, `tessFactor`, `geometryCacheMb`, `cacheMode`, ...).

use crate::error::RenderError;
use crate::geometry_cache::CacheConfig;

/// How a render is made. Defaults are what a user gets without asking.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// Image size in pixels.
    pub width: usize,
    pub height: usize,
    /// Camera samples per pixel (stratified jitter; sample 0 is the pixel centre).
    pub samples: u32,
    /// The image is a function of this seed alone.
    pub seed: u64,
    /// Render threads; 0 = all cores.
    pub threads: usize,
    /// Quad size relative to the beam width (the paper's tessellation factor): larger is
    /// coarser. Default 1.
    pub tess_factor: f32,
    /// Extra factor on `tess_factor` for incoherent rays — ambient occlusion, diffuse and glossy
    /// — so the paper's claim can be tested: coarsening wide rays costs little image error.
    /// Default 1.
    pub tess_factor_incoherent: f32,
    /// The geometry cache: mode and per-tier budgets. Default: multires, 30 MB (10 MB a tier,
    /// the paper's).
    pub cache: CacheConfig,
    /// AOVs to produce, by name (see [`crate::film::AOV_NAMES`]).
    pub aovs: Vec<String>,
    /// Ambient-occlusion rays per shading point (0: no ambient occlusion). AO lights diffuse
    /// surfaces as a uniform white sky of radiance `ao_intensity`, occluded within `ao_distance`.
    pub ao_samples: u32,
    /// World units; infinite by default.
    pub ao_distance: f32,
    pub ao_intensity: f32,
    /// Longest chain of mirror bounces.
    pub max_depth: u32,
    /// Shadow rays per shading point toward each area, dome or wide distant light.
    pub shadow_samples: u32,
    /// Which integrator renders (`integrator` setting); `Auto` picks from what the scene calls for.
    pub integrator: IntegratorKind,
    /// Hemisphere rays per shading point for one-bounce indirect diffuse (color bleeding).
    pub indirect_samples: u32,
    /// Interpolate ambient occlusion and irradiance from a cache of hemisphere integrals with
    /// gradients (the paper's §5.1; Ward and Heckbert 1992) instead of sampling at every point.
    pub irradiance_cache: bool,
    /// The irradiance cache's error bound (Ward's a): records are reused within this relative
    /// error estimate; smaller is more accurate and slower.
    pub irradiance_cache_error: f32,
}

/// The `integrator` render setting.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum IntegratorKind {
    /// What the scene calls for: path tracing when asked by the settings; color bleeding when
    /// indirect diffuse is asked for; otherwise the classic direct-lighting ray tracer (with
    /// ambient occlusion when AO samples are set).
    #[default]
    Auto,
    /// Direct light, shadows, specular and glossy reflection and refraction to `max_depth`.
    Direct,
    /// Ambient occlusion only.
    Ao,
    /// Direct light plus one diffuse bounce of `indirect_samples` hemisphere rays.
    ColorBleeding,
    /// Unidirectional path tracing with Russian roulette.
    Path,
}

impl IntegratorKind {
    pub const NAMES: &'static [&'static str] = &["auto", "direct", "ao", "colorBleeding", "path"];

    /// The setting's token.
    pub const fn name(self) -> &'static str {
        match self {
            IntegratorKind::Auto => "auto",
            IntegratorKind::Direct => "direct",
            IntegratorKind::Ao => "ao",
            IntegratorKind::ColorBleeding => "colorBleeding",
            IntegratorKind::Path => "path",
        }
    }

    /// Parses [`IntegratorKind::name`].
    pub fn from_name(name: &str) -> Option<Self> {
        [IntegratorKind::Auto, IntegratorKind::Direct, IntegratorKind::Ao, IntegratorKind::ColorBleeding, IntegratorKind::Path]
            .into_iter()
            .find(|k| k.name() == name)
    }
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            width: 320,
            height: 240,
            samples: 1,
            seed: 0,
            threads: 0,
            tess_factor: 1.0,
            tess_factor_incoherent: 1.0,
            cache: CacheConfig::multires(30_000_000),
            aovs: vec!["color".into()],
            ao_samples: 0,
            ao_distance: f32::INFINITY,
            ao_intensity: 1.0,
            max_depth: 4,
            shadow_samples: 4,
            integrator: IntegratorKind::Auto,
            indirect_samples: 16,
            irradiance_cache: false,
            irradiance_cache_error: 0.2,
        }
    }
}

impl RenderOptions {
    /// Checks every value; the message names the setting and the valid range.
    ///
    /// # Errors
    /// [`RenderError::Settings`] for the first bad value.
    pub fn validate(&self) -> Result<(), RenderError> {
        if self.width == 0 || self.height == 0 || self.width > 65_536 || self.height > 65_536 {
            return Err(RenderError::Settings(format!("resolution {}x{} must be within 1..=65536 on each side", self.width, self.height)));
        }
        if self.samples == 0 {
            return Err(RenderError::Settings("samples must be at least 1".into()));
        }
        if !(self.tess_factor.is_finite() && self.tess_factor > 0.0) {
            return Err(RenderError::Settings(format!("tessFactor {} must be a positive number", self.tess_factor)));
        }
        if !(self.tess_factor_incoherent.is_finite() && self.tess_factor_incoherent > 0.0) {
            return Err(RenderError::Settings(format!("tessFactorIncoherent {} must be a positive number", self.tess_factor_incoherent)));
        }
        if !(self.ao_distance > 0.0) || !(self.ao_intensity.is_finite() && self.ao_intensity >= 0.0) {
            return Err(RenderError::Settings(format!(
                "aoDistance {} must be positive and aoIntensity {} a non-negative number",
                self.ao_distance, self.ao_intensity
            )));
        }
        if self.ao_samples > 65_536 || self.max_depth > 64 {
            return Err(RenderError::Settings(format!(
                "aoSamples {} must be at most 65536 and maxDepth {} at most 64",
                self.ao_samples, self.max_depth
            )));
        }
        if self.indirect_samples > 65_536 {
            return Err(RenderError::Settings(format!("indirectSamples {} must be at most 65536", self.indirect_samples)));
        }
        if !(self.irradiance_cache_error.is_finite() && self.irradiance_cache_error > 0.0 && self.irradiance_cache_error <= 10.0) {
            return Err(RenderError::Settings(format!("irradianceCacheError {} must be within (0, 10]", self.irradiance_cache_error)));
        }
        for a in &self.aovs {
            if crate::film::aov_channels(a).is_none() {
                return Err(RenderError::Settings(format!("unknown AOV '{a}'; valid AOVs: {}", crate::film::AOV_NAMES.join(", "))));
            }
        }
        Ok(())
    }
}
