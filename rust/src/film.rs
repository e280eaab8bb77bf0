//! The film: named AOV buffers (color, depth, normal, ...), filled by the render and handed to an
//! [`crate::image_io::ImageIo`] or to Python as arrays. Non-finite samples never reach it: they
//! are counted and dropped.

use crate::error::RenderError;
use crate::image_io::ChannelFormat;

use crate::aov::{Aov, AOV_NAMES as AOV_NAME_ARRAY};

/// Every AOV with its channel count, in [`Aov`]'s order (read from [`crate::aov::AOV_TABLE`]).
pub const AOVS: &[(&str, usize)] = &{
    let mut out = [("", 0); Aov::ALL.len()];
    let mut i = 0;
    while i < out.len() {
        out[i] = (crate::aov::AOV_TABLE[i].name, crate::aov::AOV_TABLE[i].channels);
        i += 1;
    }
    out
};

/// The AOV names, for messages.
pub const AOV_NAMES: &[&str] = &AOV_NAME_ARRAY;

/// What each AOV holds, its units and its space, in [`AOVS`] order (read from
/// [`crate::aov::AOV_TABLE`]).
pub const AOV_MEANINGS: &[(&str, &str)] = &{
    let mut out = [("", ""); Aov::ALL.len()];
    let mut i = 0;
    while i < out.len() {
        out[i] = (crate::aov::AOV_TABLE[i].name, crate::aov::AOV_TABLE[i].meaning);
        i += 1;
    }
    out
};

/// What AOV `name` holds, its units and space, or `None` for an unknown name.
pub fn aov_meaning(name: &str) -> Option<&'static str> {
    Aov::from_name(name).map(|a| a.info().meaning)
}

/// Channel count of a named AOV, or `None` if the renderer does not know it.
pub fn aov_channels(name: &str) -> Option<usize> {
    Aov::from_name(name).map(Aov::channels)
}

/// Channel names in a file ([`Aov::file_channel_names`]); a name the renderer does not know
/// keeps its name for one channel, `name.x`, `name.y`, ... for more.
pub fn file_channel_names(aov: &str, channels: usize) -> Vec<String> {
    match Aov::from_name(aov) {
        Some(a) if a.channels() == channels => a.file_channel_names(),
        _ if channels == 1 => vec![aov.to_string()],
        _ => ["x", "y", "z", "w"].iter().take(channels).map(|c| format!("{aov}.{c}")).collect(),
    }
}

/// The storage format of an AOV in a file ([`crate::aov::AovInfo::format`]); float for a name the renderer
/// does not know.
pub fn default_format(aov: &str) -> ChannelFormat {
    Aov::from_name(aov).map_or(ChannelFormat::Float, |a| a.info().format)
}

/// One AOV: `height × width × channels` f32, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct AovBuffer {
    pub aov: Aov,
    pub channels: usize,
    pub data: Vec<f32>,
}

/// Bytes a film of `aovs` at `width`×`height` holds (f32 channels).
pub fn film_bytes(width: usize, height: usize, aovs: &[Aov]) -> u128 {
    let channels: u128 = aovs.iter().map(|a| a.channels() as u128).sum();
    width as u128 * height as u128 * channels * 4
}

/// Copies of the film a render may hold at once: the film, and the caller's converted copy
/// while the image is written.
pub const FILM_COPIES: u128 = 2;

/// Refuses, before anything is allocated, a film and its AOVs that would not fit in the memory
/// available (`MemAvailable` of `/proc/meminfo`; no check where that cannot be read), rather
/// than let the allocation abort the process.
///
/// # Errors
/// [`RenderError::Settings`] naming the resolution, the AOVs and both sizes.
pub fn check_film_memory(width: usize, height: usize, aovs: &[Aov]) -> Result<(), RenderError> {
    let need = film_bytes(width, height, aovs) * FILM_COPIES;
    let Some(available) = available_memory() else { return Ok(()) };
    if need > u128::from(available) {
        let names: Vec<&str> = aovs.iter().map(|a| a.name()).collect();
        return Err(RenderError::Settings(format!(
            "resolution {width}x{height} with AOVs {}: the image needs {:.1} GB, more than the {:.1} GB of memory available; render it smaller or in tiles (the crop setting)",
            names.join(", "),
            need as f64 / 1e9,
            available as f64 / 1e9
        )));
    }
    Ok(())
}

/// The memory the system can give without swapping, bytes (`MemAvailable`), if known.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb.saturating_mul(1024))
}

/// A set of AOV buffers of one resolution.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    pub width: usize,
    pub height: usize,
    pub aovs: Vec<AovBuffer>,
}

impl Film {
    /// A film with zeroed buffers for `aovs`.
    pub fn new(width: usize, height: usize, aovs: &[Aov]) -> Self {
        let aovs =
            aovs.iter().map(|&aov| AovBuffer { aov, channels: aov.channels(), data: vec![0.0; width * height * aov.channels()] }).collect();
        Film { width, height, aovs }
    }

    pub fn aov(&self, name: &str) -> Option<&AovBuffer> {
        self.aovs.iter().find(|a| a.aov.name() == name)
    }

    pub fn aov_mut(&mut self, name: &str) -> Option<&mut AovBuffer> {
        self.aovs.iter_mut().find(|a| a.aov.name() == name)
    }

    /// The channels of AOV `name` at pixel (x, y).
    ///
    /// # Panics
    /// If the AOV is not on the film or (x, y) is outside it.
    pub fn pixel(&self, name: &str, x: usize, y: usize) -> &[f32] {
        let a = self.aov(name).unwrap_or_else(|| panic!("AOV {name} is not on the film"));
        let i = (y * self.width + x) * a.channels;
        &a.data[i..i + a.channels]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_aov_has_one_name_and_file_channels() {
        assert_eq!(AOVS.len(), AOV_NAMES.len());
        assert_eq!(AOVS.len(), AOV_MEANINGS.len());
        for ((&(name, channels), &listed), &(described, _)) in AOVS.iter().zip(AOV_NAMES).zip(AOV_MEANINGS) {
            assert_eq!(name, listed);
            assert_eq!(name, described);
            let files = file_channel_names(name, channels);
            assert_eq!(files.len(), channels, "{name}");
        }
        assert_eq!(file_channel_names("specular", 3), ["specular.R", "specular.G", "specular.B"]);
        assert_eq!(file_channel_names("Neye", 3), ["Neye.x", "Neye.y", "Neye.z"]);
        assert_eq!(default_format("directDiffuse"), ChannelFormat::Half);
        assert_eq!(default_format("position"), ChannelFormat::Float);
        assert_eq!(file_channel_names("Peye", 3), ["Peye.x", "Peye.y", "Peye.z"]);
        assert_eq!(file_channel_names("cameraDepth", 1), ["cameraDepth"]);
        assert_eq!((default_format("cameraDepth"), default_format("Peye")), (ChannelFormat::Float, ChannelFormat::Float));
    }

    #[test]
    fn the_readme_lists_every_aov_with_its_meaning() {
        let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md")).unwrap();
        for (name, meaning) in AOV_MEANINGS {
            let row = format!("| `{name}` | {} | {meaning} |", aov_channels(name).unwrap());
            assert!(readme.contains(&row), "README.md has no row {row}");
        }
    }
}
