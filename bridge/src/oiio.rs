//! Image files through OpenImageIO: [`OiioImageIo`] implements the core's [`ImageIo`], so the
//! film's AOVs are written as EXR, PNG, TIFF, … (chosen by the file extension) with per-channel
//! storage formats and metadata (DESIGN.md, data flow step 7).
//!
//! Storage: EXR keeps one format per channel (half color, float depth, say). A format that cannot
//! mix formats stores every channel in the widest one asked for, and PNG, JPEG (and GIF, BMP,
//! WebP) store 8 bits: values are clamped to [0, 1] and quantized, with no color transform — the
//! caller hands display-ready values to such formats.
//!
//! Every file written says `Software = "mipray <version>"`.

use std::path::Path;

use mipray::error::ImageError;
use mipray::image_io::{ChannelFormat, ImageBuf, ImageIo, MetaValue};

use crate::ffi::bridge as ffi;

/// OpenImageIO's version at run time, e.g. `"2.4.7"`.
pub fn oiio_version() -> String {
    ffi::oiio_version()
}

/// The `Software` attribute every image gets.
pub fn software_name() -> String {
    format!("mipray {}", env!("CARGO_PKG_VERSION"))
}

/// [`ImageIo`] by OpenImageIO. Stateless, so one value can serve every thread.
#[derive(Clone, Copy, Debug, Default)]
pub struct OiioImageIo;

impl OiioImageIo {
    pub const fn new() -> Self {
        OiioImageIo
    }
}

fn image_error(path: &Path, message: impl Into<String>) -> ImageError {
    ImageError { path: path.display().to_string(), message: message.into() }
}

fn format_code(f: ChannelFormat) -> u8 {
    match f {
        ChannelFormat::Half => 0,
        ChannelFormat::Float => 1,
        ChannelFormat::U8 => 2,
    }
}

impl ImageIo for OiioImageIo {
    /// Writes `image` to `path`; `formats` has one entry per channel, or a single entry for all.
    /// Integer metadata must fit in 32 bits (file formats store `int`); matrices are written as
    /// `TypeMatrix44`, row-major as given.
    ///
    /// # Errors
    /// [`ImageError`] naming the path: inconsistent sizes, a non-UTF-8 path, or what OpenImageIO
    /// reported (unknown extension, unwritable directory, …).
    fn write(&self, path: &Path, image: &ImageBuf, formats: &[ChannelFormat], metadata: &[(String, MetaValue)]) -> Result<(), ImageError> {
        let nch = image.channels.len();
        if nch == 0 {
            return Err(image_error(path, "an image needs at least one channel"));
        }
        let codes: Vec<u8> = match formats.len() {
            1 => vec![format_code(formats[0]); nch],
            n if n == nch => formats.iter().copied().map(format_code).collect(),
            n => return Err(image_error(path, format!("{n} storage formats given for {nch} channels"))),
        };
        let (Ok(width), Ok(height)) = (u32::try_from(image.width), u32::try_from(image.height)) else {
            return Err(image_error(path, "image dimensions exceed 32 bits"));
        };
        if width == 0 || height == 0 {
            return Err(image_error(path, format!("empty image ({width}×{height})")));
        }
        let expected = image.width.checked_mul(image.height).and_then(|n| n.checked_mul(nch));
        if expected != Some(image.pixels.len()) {
            return Err(image_error(path, format!("{} pixel values for {}×{}×{nch}", image.pixels.len(), image.width, image.height)));
        }
        let path_str = path.to_str().ok_or_else(|| image_error(path, "path is not valid UTF-8"))?;
        let mut attrs = Vec::with_capacity(metadata.len());
        for (name, value) in metadata {
            if name.is_empty() {
                return Err(image_error(path, "metadata attribute with an empty name"));
            }
            let mut a = ffi::OiioAttr { name: name.clone(), ..Default::default() };
            match value {
                MetaValue::Str(s) => {
                    a.kind = 0;
                    a.s = s.clone();
                }
                MetaValue::Int(i) => {
                    a.kind = 1;
                    a.i = i32::try_from(*i).map_err(|_| image_error(path, format!("metadata {name} = {i} does not fit in 32 bits")))?;
                }
                MetaValue::Float(f) => {
                    a.kind = 2;
                    a.f = *f;
                }
                MetaValue::Matrix44(m) => {
                    a.kind = 3;
                    a.m = m.to_vec();
                }
            }
            attrs.push(a);
        }
        ffi::oiio_write(path_str, width, height, &image.channels, &codes, &image.pixels, &attrs, &software_name())
            .map_err(|e| image_error(path, e.what()))
    }

    /// Reads the first subimage as f32, with its channel names (in the file's order: EXR may
    /// reorder them) and every metadata attribute as text (strings as stored; numbers and
    /// matrices as OpenImageIO formats them, comma separated). Names are as the file stores them:
    /// OpenImageIO spells well-known ones the format's way (`worldtocamera` → EXR's
    /// `worldToCamera`).
    ///
    /// # Errors
    /// [`ImageError`] naming the path and what OpenImageIO reported.
    fn read(&self, path: &Path) -> Result<ImageBuf, ImageError> {
        let path_str = path.to_str().ok_or_else(|| image_error(path, "path is not valid UTF-8"))?;
        let mut reader = ffi::oiio_open(path_str).map_err(|e| image_error(path, e.what()))?;
        let width = reader.width() as usize;
        let height = reader.height() as usize;
        let channels = reader.channel_names().map_err(|e| image_error(path, e.what()))?;
        let n =
            width.checked_mul(height).and_then(|n| n.checked_mul(channels.len())).ok_or_else(|| image_error(path, "image too large"))?;
        let mut pixels = vec![0.0f32; n];
        reader.pin_mut().read_pixels(&mut pixels).map_err(|e| image_error(path, e.what()))?;
        let metadata = reader.metadata().map_err(|e| image_error(path, e.what()))?.into_iter().map(|a| (a.name, a.value)).collect();
        Ok(ImageBuf { width, height, channels, pixels, metadata })
    }
}
