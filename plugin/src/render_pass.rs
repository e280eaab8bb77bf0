//! The render pass: syncs the delegate, renders from a camera into render buffers, with
//! progress and cancel. With the `progressive` setting the buffers are also handed over after
//! each pass of 1, 2, 4, … samples per pixel ([`RenderPass::execute_with_updates`]), as Hydra's
//! render buffers are read by a viewer while the render converges.

use mipray::film::Film;
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
    pub aovs: Vec<mipray::aov::Aov>,
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
        self.render(delegate, progress)
    }

    /// As [`RenderPass::execute`], handing `on_pass` the render buffers after every pass (the
    /// AOVs asked for, averaged over the samples so far). Called between passes, in order, from
    /// a render thread; the last call (`converged`) holds the finished image. Cancelling through
    /// `progress` after a pass keeps that pass's buffers with the caller.
    ///
    /// # Errors
    /// As [`RenderPass::execute`].
    pub fn execute_with_updates(
        &self,
        delegate: &mut RenderDelegate,
        progress: &dyn Progress,
        on_pass: &(dyn Fn(PassUpdate) + Sync),
    ) -> Result<PassResult, DelegateError> {
        let total = self.settings.samples;
        self.render(delegate, &Updates { inner: progress, on_pass, total })
    }

    fn render(&self, delegate: &mut RenderDelegate, progress: &dyn Progress) -> Result<PassResult, DelegateError> {
        let options = self.settings.to_options(self.width, self.height, &self.aovs);
        // Before the sync, which may take long: an image that cannot fit is refused first.
        options.validate()?;
        mipray::film::check_film_memory(options.width, options.height, &options.aovs)?;
        let prim_errors = delegate.sync_or_cancel(progress)?;
        delegate.prepare_textures(crate::config::texture_options(&self.settings))?;
        let scene = delegate.build_scene(&self.camera, self.settings.displacement_bound)?;
        let cache = delegate.geometry_cache(options.cache);
        let out = render_with_cache(&scene, &options, Some(cache), progress)?;
        let mut stats = out.stats;
        if let Some(obj) = stats.as_object_mut() {
            // Every prim left out, whether its sync failed or the tracer refused or dropped it.
            let mut listed: Vec<Value> = prim_errors.iter().map(|e| Value::from(e.to_string())).collect();
            if let Some(Value::Array(dropped)) = obj.get("dropped_prims") {
                listed.extend(dropped.iter().cloned());
            }
            obj.insert("prim_errors".into(), Value::from(listed));
            let sync_internal = prim_errors.iter().filter(|e| matches!(e, DelegateError::Internal { .. })).count() as u64;
            let traced_internal = obj.get("internal_errors").and_then(Value::as_u64).unwrap_or(0);
            obj.insert("internal_errors".into(), Value::from(sync_internal + traced_internal));
        }
        Ok(PassResult { buffers: buffers_from_film(out.film), stats, prim_errors })
    }
}

/// The image after one pass of a render.
#[derive(Clone, Debug)]
pub struct PassUpdate {
    /// Samples per pixel so far.
    pub samples: u32,
    /// The last pass: these buffers are the finished image (Hydra's `IsConverged`).
    pub converged: bool,
    /// The AOVs asked for, in the pass's order.
    pub buffers: Vec<RenderBuffer>,
}

/// Forwards a render's progress to the caller's, and each finished pass as render buffers.
struct Updates<'a> {
    inner: &'a dyn Progress,
    on_pass: &'a (dyn Fn(PassUpdate) + Sync),
    total: u32,
}

impl Progress for Updates<'_> {
    fn start(&self, total: u64) {
        self.inner.start(total);
    }

    fn advance(&self, n: u64) {
        self.inner.advance(n);
    }

    fn finish(&self) {
        self.inner.finish();
    }

    fn cancelled(&self) -> bool {
        self.inner.cancelled()
    }

    fn pass_finished(&self, samples: u32, film: &Film) {
        self.inner.pass_finished(samples, film);
        (self.on_pass)(PassUpdate { samples, converged: samples >= self.total, buffers: buffers_from_film(film.clone()) });
    }
}
