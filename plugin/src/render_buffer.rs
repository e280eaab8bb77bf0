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
    let clamped = fit_to_formats(&mut pixels, &chan_formats);
    if clamped > 0 {
        log::warn!(
            "{}: {clamped} values the file cannot hold (NaN, infinite, or beyond half float's ±65504) clamped to its range",
            path.display()
        );
    }
    let image = ImageBuf { width: w, height: h, channels, pixels, metadata: Vec::new() };
    OiioImageIo.write(path, &image, &chan_formats, metadata)
}

/// The largest finite half float: anything larger becomes Inf when stored as half.
pub const HALF_MAX: f32 = 65504.0;

/// Makes interleaved `pixels` (channel `c` of each pixel stored as `formats[c]`) representable:
/// NaN becomes 0, and values beyond a channel's finite range are clamped to it (±65504 for half,
/// ±`f32::MAX` for float; 8-bit channels are clamped to [0, 1] by the conversion itself). A
/// written image never holds Inf or NaN. Returns how many values changed.
pub fn fit_to_formats(pixels: &mut [f32], formats: &[ChannelFormat]) -> u64 {
    if formats.is_empty() {
        return 0;
    }
    let mut changed = 0;
    for (k, v) in pixels.iter_mut().enumerate() {
        let limit = match formats[k % formats.len()] {
            ChannelFormat::Half => HALF_MAX,
            ChannelFormat::Float | ChannelFormat::U8 => f32::MAX,
        };
        let fitted = if v.is_nan() { 0.0 } else { v.clamp(-limit, limit) };
        if fitted.to_bits() != v.to_bits() && !(fitted == 0.0 && *v == 0.0) {
            changed += 1;
        }
        *v = fitted;
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_a_format_cannot_hold_are_clamped_and_counted() {
        use ChannelFormat::{Float, Half, U8};
        let mut px = vec![1e5, -1e5, 65504.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.5, f32::NAN, -0.0];
        let changed = fit_to_formats(&mut px, &[Half, Half, Half, Float, Float, Float, U8, U8, Half]);
        assert_eq!(px, [65504.0, -65504.0, 65504.0, 0.0, f32::MAX, f32::MIN, 0.5, 0.0, -0.0]);
        assert_eq!(changed, 6);
    }
}
