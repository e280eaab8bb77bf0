//! The render pass: syncs the delegate, renders from a camera into render buffers, with
//! progress and cancel.

use mipray::progress::Progress;
use mipray::render::render_with_cache;
use serde_json::Value;

use crate::config::RenderSettings;
use crate::error::DelegateError;
use crate::render_buffer::{buffers_from_film, RenderBuffer};
use crate::render_delegate::RenderDelegate;

/// What to render: camera, resolution, AOVs, settings.
#[derive(Clone, Debug)]
pub struct RenderPass {
    pub camera: String,
    pub width: usize,
    pub height: usize,
    pub aovs: Vec<String>,
    pub settings: RenderSettings,
}

/// A finished pass: buffers in the order asked, the stats JSON, and the prims that could not
/// be synced (they were left out of the image).
pub struct PassResult {
    pub buffers: Vec<RenderBuffer>,
    pub stats: Value,
    pub prim_errors: Vec<DelegateError>,
}

impl RenderPass {
    /// Syncs dirty prims, then renders.
    ///
    /// # Errors
    /// A missing camera, bad settings, or cancellation. Broken prims are not errors of the pass:
    /// they are returned in [`PassResult::prim_errors`].
    pub fn execute(&self, delegate: &mut RenderDelegate, progress: &dyn Progress) -> Result<PassResult, DelegateError> {
        let prim_errors = delegate.sync();
        delegate.prepare_textures(self.settings.texture_options())?;
        let scene = delegate.build_scene(&self.camera, self.settings.displacement_bound)?;
        let options = self.settings.to_options(self.width, self.height, &self.aovs);
        let cache = delegate.geometry_cache(options.cache);
        let out = render_with_cache(&scene, &options, Some(cache), progress)?;
        let mut stats = out.stats;
        if let Some(obj) = stats.as_object_mut() {
            obj.insert("prim_errors".into(), Value::from(prim_errors.iter().map(|e| e.to_string()).collect::<Vec<_>>()));
        }
        Ok(PassResult { buffers: buffers_from_film(out.film), stats, prim_errors })
    }
}
