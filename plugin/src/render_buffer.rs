//! Render buffers (Hydra's Bprims): one per AOV, filled by a render pass, resolved to arrays or
//! written to image files through OpenImageIO.

use std::path::Path;

use mipray::film::Film;
use mipray::image_output::{write_layers, Layer, WriteOptions};
use mipray_bridge::OiioImageIo;

/// One AOV's pixels: `height × width × channels` f32, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderBuffer {
    pub aov: String,
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

/// The film's AOVs as render buffers, in the film's order.
pub fn buffers_from_film(film: Film) -> Vec<RenderBuffer> {
    let (w, h) = (film.width, film.height);
    film.aovs
        .into_iter()
        .map(|a| RenderBuffer { aov: a.aov.name().to_string(), width: w, height: h, channels: a.channels, data: a.data })
        .collect()
}

impl RenderBuffer {
    /// The buffer as the image writer reads it ([`mipray::image_output::write_layers`]).
    pub fn layer(&self) -> Layer<'_> {
        Layer { name: &self.aov, channels: self.channels, data: &self.data }
    }
}

/// Writes buffers (all one resolution) into one image file through OpenImageIO, as
/// [`mipray::image_output::write_layers`] says (the file type's rules, sRGB for 8-bit files,
/// clamping, the atomic replace).
///
/// # Errors
/// As [`mipray::image_output::write_layers`], naming the path.
pub fn write_buffers(path: &Path, buffers: &[RenderBuffer], options: &WriteOptions) -> Result<(), mipray::error::ImageError> {
    let (width, height) = buffers.first().map_or((0, 0), |b| (b.width, b.height));
    if let Some(b) = buffers.iter().find(|b| (b.width, b.height) != (width, height)) {
        return Err(mipray::error::ImageError {
            path: path.display().to_string(),
            message: format!("AOV {} is {}x{}, the image is {width}x{height}", b.aov, b.width, b.height),
        });
    }
    let layers: Vec<Layer<'_>> = buffers.iter().map(RenderBuffer::layer).collect();
    write_layers(&OiioImageIo, path, width, height, &layers, options)
}
