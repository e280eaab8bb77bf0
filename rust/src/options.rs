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
        for a in &self.aovs {
            if crate::film::aov_channels(a).is_none() {
                return Err(RenderError::Settings(format!("unknown AOV '{a}'; valid AOVs: {}", crate::film::AOV_NAMES.join(", "))));
            }
        }
        Ok(())
    }
}
