//! Image output and input as a trait: the bridge implements it with OpenImageIO, so the core
//! writes AOVs without linking C++.

use std::path::Path;

use crate::error::ImageError;

/// Storage type of one channel in the file (the film is always f32 in memory).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChannelFormat {
    Half,
    Float,
    U8,
}

impl ChannelFormat {
    /// Every format, in the order of [`ChannelFormat::NAMES`].
    pub const ALL: [ChannelFormat; 3] = [ChannelFormat::Half, ChannelFormat::Float, ChannelFormat::U8];
    /// The names Python and the AOV table use: `half`, `float`, `uint8`.
    pub const NAMES: [&'static str; 3] = ["half", "float", "uint8"];

    pub const fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// Parses [`ChannelFormat::name`].
    pub fn from_name(name: &str) -> Option<ChannelFormat> {
        Self::NAMES.iter().position(|n| *n == name).map(|i| Self::ALL[i])
    }
}

/// A metadata value attached to an image (EXR header attributes, TIFF tags, PNG text).
#[derive(Clone, Debug, PartialEq)]
pub enum MetaValue {
    Str(String),
    Int(i64),
    Float(f32),
    /// 4×4 matrix, row-major as USD writes it (e.g. `worldtocamera`).
    Matrix44([f32; 16]),
}

/// An image in memory: `pixels` is interleaved, `height × width × channels.len()`, row 0 at the top.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImageBuf {
    pub width: usize,
    pub height: usize,
    pub channels: Vec<String>,
    pub pixels: Vec<f32>,
    /// Metadata read back from the file (strings only; enough for round-trip checks).
    pub metadata: Vec<(String, String)>,
}

/// Writes and reads images; the file format follows the extension (whatever the implementation
/// supports: with OpenImageIO, EXR, PNG, TIFF, JPEG, …).
pub trait ImageIo: Send + Sync {
    /// Writes `image` to `path`, with one storage format per channel (formats a file type
    /// cannot hold are converted by the implementation) and the given metadata.
    ///
    /// # Errors
    /// [`ImageError`] naming the path and what the library reported.
    fn write(&self, path: &Path, image: &ImageBuf, formats: &[ChannelFormat], metadata: &[(String, MetaValue)]) -> Result<(), ImageError>;

    /// Reads a whole image as f32.
    ///
    /// # Errors
    /// [`ImageError`] naming the path and the problem.
    fn read(&self, path: &Path) -> Result<ImageBuf, ImageError>;
}
