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
    /// The whole geometry memory of the render in MB (10^6 bytes), `geometryMemoryMb`: the
    /// cache's budget plus the meshes' patch data, root subpatches and BVHs
    /// ([`crate::geometry_budget`]). Infinite (the default): no bound beyond the cache's.
    pub geometry_memory_mb: f64,
    /// AOVs to produce (parsed where names come in: an unknown name never gets this far).
    pub aovs: Vec<crate::aov::Aov>,
    /// Ambient-occlusion rays per shading point (0: no ambient occlusion). AO lights diffuse
    /// surfaces as a uniform white sky of radiance `ao_intensity`, occluded within `ao_distance`.
    pub ao_samples: u32,
    /// World units; infinite by default.
    pub ao_distance: f32,
    pub ao_intensity: f32,
    /// Longest chain of bounces after the camera ray's hit: mirror, glossy and refraction
    /// bounces for the classic integrator; every scattering event for the path tracer (0: direct
    /// light only; Mitsuba's `max_depth` is this plus 2).
    pub max_depth: u32,
    /// Light samples per shading point, shared among all the lights by importance (the light
    /// sampler), plus as many BSDF samples for multiple importance sampling: see
    /// [`crate::integrator::direct_light`].
    pub shadow_samples: u32,
    /// Glossy rays (rough reflection and refraction, sampled from the BSDF's non-diffuse lobes)
    /// per shading point at the first non-mirror hit of a camera ray; 1 at hits further along a
    /// glossy path (`glossySamples`, default 4).
    pub glossy_samples: u32,
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
    /// Path tracing: bounces before Russian roulette may end a path (`russianRouletteDepth`).
    /// From there a path survives each bounce with probability min(1, max component of its
    /// throughput) and is reweighted by its inverse, so the mean is unchanged. `max_depth` or
    /// more turns it off.
    pub russian_roulette_depth: u32,
    /// Render in passes of 1, 2, 4, … samples per pixel up to `samples`, reporting the image
    /// after each through [`crate::progress::Progress::pass_finished`]. The final image is
    /// bit-identical to the one rendered without it. The cost: each pass sweeps the whole
    /// image, so a geometry cache smaller than the scene's working set rebuilds tessellations
    /// a one-pass render (a tile's samples together) reuses — on `examples/subdiv_showcase.usda`
    /// at 160 px, 16 path-traced samples, 30 MB: 18× the cache misses and about 2× the time.
    pub progressive: bool,
    /// Seam boxes close the cracks between neighbouring subpatches tested at different rates
    /// ([`crate::seam`], docs/cracks.md). On by default; off only to measure what they cost and
    /// what they change in an image, since rays then slip through the cracks.
    pub seams: bool,
    /// Displaced meshes are read no coarser than the rate at which their largest patch keeps
    /// the displacement's finest detail (the procedural fBm's finest octave; a texture's finest
    /// MIP level over the patches' `st`: [`crate::subpatch::MeshGeometry::rate_floor`]), and a
    /// texture's shared edges are read with their own `st` step: every rate then reads one
    /// surface, so closed displaced shells let no light through (docs/cracks.md, rules 4 and 5).
    /// Off by default: it takes the coarse tiers from finely detailed meshes (2.6-6x the render
    /// time measured there).
    pub displacement_rate_floor: bool,
    /// Camera rays see a dome light as the background (Hydra's `domeLightCameraVisibility`);
    /// off, the dome still lights the scene and shows in reflections, and the background is
    /// black with alpha 0, as usdrecord renders without `--enableDomeLightVisibility`.
    pub dome_light_camera_visibility: bool,
    /// The window of the frame to render, in NDC: xmin, ymin, xmax, ymax, (0, 0) the
    /// bottom-left corner, (1, 1) the top-right (USD's `dataWindowNDC`). A pixel is rendered
    /// when its centre lies in the window ([`RenderOptions::data_window`]); the film holds those
    /// pixels only, each exactly as the whole frame has it (rays, seeds and the irradiance
    /// cache's records are the whole frame's), so tiles assemble into the frame bit for bit.
    pub crop: [f64; 4],
}

/// The pixels a render fills: columns `x` and rows `y` (row 0 at the top) of the whole frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DataWindow {
    pub x: std::ops::Range<usize>,
    pub y: std::ops::Range<usize>,
}

impl DataWindow {
    pub fn width(&self) -> usize {
        self.x.len()
    }

    pub fn height(&self) -> usize {
        self.y.len()
    }
}

/// The `integrator` render setting.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum IntegratorKind {
    /// What the scene calls for: the classic integrator ([`IntegratorKind::Direct`]) plus
    /// ambient occlusion when `ao_samples` > 0. Nothing in a USD scene by itself asks for
    /// indirect diffuse light, so hemisphere rays are traced only where the settings ask for
    /// them (DESIGN.md, "Effects a scene calls for"). See [`crate::integrator::select`].
    #[default]
    Auto,
    /// Direct light, shadows, specular and glossy reflection and refraction to `max_depth`; no
    /// hemisphere rays, even when `ao_samples` is set.
    Direct,
    /// Ambient occlusion only: colour = unoccluded fraction × diffuse albedo × `ao_intensity`,
    /// plus emission. Needs `ao_samples` > 0.
    Ao,
    /// Direct light plus one diffuse bounce of `indirect_samples` hemisphere rays.
    ColorBleeding,
    /// Unidirectional path tracing with Russian roulette.
    Path,
}

impl IntegratorKind {
    /// The setting's tokens, in variant order.
    pub const NAMES: &'static [&'static str] = &["auto", "direct", "ao", "colorBleeding", "path"];

    /// The setting's token.
    pub const fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// Every variant, in the order of [`IntegratorKind::NAMES`].
    pub const ALL: [IntegratorKind; 5] =
        [IntegratorKind::Auto, IntegratorKind::Direct, IntegratorKind::Ao, IntegratorKind::ColorBleeding, IntegratorKind::Path];

    /// Parses [`IntegratorKind::name`].
    pub fn from_name(name: &str) -> Option<Self> {
        Self::NAMES.iter().position(|n| *n == name).map(|i| Self::ALL[i])
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
        crate::settings::check(self).map_err(|e| RenderError::Settings(e.to_string()))?;
        let window = self.data_window();
        if window.x.is_empty() || window.y.is_empty() {
            let [x0, y0, x1, y1] = self.crop;
            return Err(RenderError::Settings(format!(
                "render setting crop={x0},{y0},{x1},{y1}: holds no pixel centre of a {}x{} image",
                self.width, self.height
            )));
        }
        Ok(())
    }

    /// The pixels whose centres lie in the `crop` window: column x when `xmin·W ≤ x + ½ <
    /// xmax·W`, row y (counted from the top, NDC y from the bottom) when `(1 − ymax)·H < y + ½ ≤
    /// (1 − ymin)·H`. A window edge on a pixel edge (`k / W`) is half a pixel from every centre,
    /// so tiles cut at pixel edges share no pixel and miss none, whatever the rounding of `k / W`.
    pub fn data_window(&self) -> DataWindow {
        let [x0, y0, x1, y1] = self.crop;
        let (w, h) = (self.width as f64, self.height as f64);
        let column = |ndc: f64| ((ndc * w - 0.5).ceil().max(0.0) as usize).min(self.width);
        let row = |ndc: f64| (((1.0 - ndc) * h - 0.5).floor() + 1.0).clamp(0.0, h) as usize;
        DataWindow { x: column(x0)..column(x1), y: row(y1)..row(y0) }
    }
}
