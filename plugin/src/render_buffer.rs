//! Render buffers (Hydra's Bprims): one per AOV, filled by a render pass, resolved to arrays or
//! written to image files through OpenImageIO.

use std::path::Path;

use mipray::film::Film;
use mipray::image_io::{ChannelFormat, ImageBuf, ImageIo, MetaValue};
use mipray_bridge::OiioImageIo;

use crate::aov::default_aov_descriptor;

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
    film.aovs.into_iter().map(|a| RenderBuffer { aov: a.name, width: w, height: h, channels: a.channels, data: a.data }).collect()
}

/// Writes buffers (all one resolution) into one image file, one storage format per buffer
/// (`None`: the AOV's default), with metadata.
///
/// # Errors
/// Mismatched sizes, or what OpenImageIO reports, naming the path.
pub fn write_buffers(
    path: &Path,
    buffers: &[&RenderBuffer],
    formats: &[Option<ChannelFormat>],
    metadata: &[(String, MetaValue)],
) -> Result<(), mipray::error::ImageError> {
    let err = |m: String| mipray::error::ImageError { path: path.display().to_string(), message: m };
    let first = buffers.first().ok_or_else(|| err("no AOVs to write".into()))?;
    let (w, h) = (first.width, first.height);
    if let Some(b) = buffers.iter().find(|b| b.width != w || b.height != h || b.data.len() != w * h * b.channels) {
        return Err(err(format!("AOV {} is {}x{}x{}, the image is {w}x{h}", b.aov, b.width, b.height, b.channels)));
    }
    let mut channels = Vec::new();
    let mut chan_formats = Vec::new();
    for (i, b) in buffers.iter().enumerate() {
        let desc = default_aov_descriptor(&b.aov);
        let names = desc.as_ref().map(|d| d.file_channels.clone()).unwrap_or_else(|| mipray::film::file_channel_names(&b.aov, b.channels));
        let fmt = formats.get(i).copied().flatten().or(desc.map(|d| d.format)).unwrap_or(ChannelFormat::Float);
        chan_formats.extend(std::iter::repeat_n(fmt, b.channels));
        channels.extend(names.into_iter().take(b.channels));
    }
    let nc = channels.len();
    let mut pixels = Vec::with_capacity(w * h * nc);
    for p in 0..w * h {
        for b in buffers {
            pixels.extend_from_slice(&b.data[p * b.channels..(p + 1) * b.channels]);
        }
    }
    let image = ImageBuf { width: w, height: h, channels, pixels, metadata: Vec::new() };
    OiioImageIo.write(path, &image, &chan_formats, metadata)
}
