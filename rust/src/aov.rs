//! The AOVs, stated once: [`Aov`] and its row of [`AOV_TABLE`] — name, channels, meaning,
//! averaging, clear value, file channels and file format. The film, the render loop, the
//! delegate's AOV descriptors and (through `_mipray.aovs()`) the Python side's RenderVar names
//! and EXR pixel types all read it. Adding an AOV is one variant and its row, plus the field of
//! [`crate::integrator::SampleValue`] the integrators fill.
//!
//! Names are Hydra's (`HdAovTokens`) where Hydra has one (`color`, `depth`, `cameraDepth`,
//! `normal`, `Neye`, `Peye`, `primId`, `instanceId`, `elementId`). Camera space is USD's: +x
//! right, +y up, the camera looking down −z; its units are scene units for a camera whose
//! transform does not scale. The light AOVs add up to the colour: `color = emission +
//! directDiffuse + indirectDiffuse + specular` (ambient occlusion's sky light counts as
//! indirect diffuse).
//!
//! File formats: half floats for colour-like data — `color`, its light parts, `albedo`, `alpha`
//! (all in [0, 1] or radiance, where half's 11-bit mantissa is below what a display shows) and
//! the unit normals `normal`, `Neye`; full floats for everything whose precision matters far
//! from the origin or the camera (depths, positions, beam widths, errors) or that must stay
//! exact integers (ids, rates). Every writer — the delegate's render buffers and
//! `mipray-record`'s EXRs — uses these.

use crate::image_io::ChannelFormat;

/// How a pixel's samples make its value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Averaging {
    /// The mean over the pixel's finite samples (radiance, coverage, occlusion, albedo).
    Mean,
    /// The pixel centre's value (sample 0's): never a blend of two surfaces (depths, normals,
    /// positions, ids, debug values).
    PixelCentre,
}

/// How an AOV's channels are named in a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileChannels {
    /// These names (`color` → `R`, `G`, `B`; `depth` → `Z`).
    Fixed(&'static [&'static str]),
    /// The AOV's name with these suffixes (`Peye` → `Peye.x`, ...).
    Suffixed(&'static [&'static str]),
    /// One channel, named as the AOV.
    Name,
}

/// One row of [`AOV_TABLE`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AovInfo {
    pub name: &'static str,
    pub channels: usize,
    /// What it holds, its units and its space (the AOV descriptors' and README's text).
    pub meaning: &'static str,
    pub averaging: Averaging,
    /// The value of a pixel where nothing renders (Hydra's clear value).
    pub clear: f32,
    pub file_channels: FileChannels,
    /// The pixel type in a file that keeps per-channel types (EXR).
    pub format: ChannelFormat,
}

/// Every AOV the renderer can produce, in the order listings show them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Aov {
    Color,
    Alpha,
    Depth,
    CameraDepth,
    Peye,
    Normal,
    PrimId,
    InstanceId,
    BeamWidth,
    TessRate,
    Ao,
    TessError,
    Position,
    ElementId,
    Neye,
    Albedo,
    Emission,
    DirectDiffuse,
    IndirectDiffuse,
    Specular,
}

const XYZ: FileChannels = FileChannels::Suffixed(&["x", "y", "z"]);
const RGB: FileChannels = FileChannels::Suffixed(&["R", "G", "B"]);

const fn row(
    name: &'static str,
    channels: usize,
    averaging: Averaging,
    clear: f32,
    file_channels: FileChannels,
    format: ChannelFormat,
    meaning: &'static str,
) -> AovInfo {
    AovInfo { name, channels, meaning, averaging, clear, file_channels, format }
}

use Averaging::{Mean, PixelCentre};
use ChannelFormat::{Float, Half};
use FileChannels::{Fixed, Name};

/// The rows of [`Aov`], in variant order.
pub const AOV_TABLE: [AovInfo; 20] = [
    row(
        "color",
        3,
        Mean,
        0.0,
        Fixed(&["R", "G", "B"]),
        Half,
        "linear RGB radiance toward the camera, in the lights' units: emission + directDiffuse + indirectDiffuse + specular",
    ),
    row("alpha", 1, Mean, 0.0, Fixed(&["A"]), Half, "fraction of the pixel's camera rays that hit a surface, in [0, 1]"),
    row(
        "depth",
        1,
        PixelCentre,
        0.0,
        Fixed(&["Z"]),
        Float,
        "camera-space depth of the hit: distance along the view axis (−z in camera space), camera-space units; the far clipping distance where nothing is hit. EXR's Z channel; not Hydra's clip-space depth",
    ),
    row(
        "cameraDepth",
        1,
        PixelCentre,
        0.0,
        Name,
        Float,
        "Hydra's cameraDepth: camera-space depth of the hit, −Peye.z, positive in front of the camera, camera-space units (the same values as depth); 0 where nothing is hit",
    ),
    row(
        "Peye",
        3,
        PixelCentre,
        0.0,
        XYZ,
        Float,
        "Hydra's Peye: camera-space position of the hit (z < 0 in front of the camera), camera-space units; 0 where nothing is hit",
    ),
    row(
        "normal",
        3,
        PixelCentre,
        0.0,
        Fixed(&["N.x", "N.y", "N.z"]),
        Half,
        "world-space unit shading normal at the hit (normal-mapped), facing the camera; 0 where nothing is hit",
    ),
    row("primId", 1, PixelCentre, -1.0, Name, Float, "index of the patch hit within its mesh; −1 where nothing is hit"),
    row("instanceId", 1, PixelCentre, -1.0, Name, Float, "the scene's id of the instance hit; −1 where nothing is hit"),
    row(
        "beamWidth",
        1,
        PixelCentre,
        0.0,
        Name,
        Float,
        "world-space width of the ray beam (render units) at the hit that ends the camera ray's specular chain (the paper's figure 2)",
    ),
    row(
        "tessRate",
        1,
        PixelCentre,
        0.0,
        Name,
        Float,
        "effective tessellation rate at that hit: quads per side of its root subpatch (1, 2, 4, 8, 16, 16·2^depth when split); 0 on implicit prims and points, which are intersected exactly",
    ),
    row(
        "ao",
        1,
        Mean,
        0.0,
        Name,
        Float,
        "unoccluded fraction of the cosine-weighted hemisphere within aoDistance, in [0, 1]; 0 when ambient occlusion is off",
    ),
    row(
        "tessError",
        2,
        PixelCentre,
        0.0,
        Fixed(&["tessError.world", "tessError.beam"]),
        Float,
        "distance along the camera ray between its hit on the tessellation and the exact limit surface (render units), and that distance over the beam width there (unitless)",
    ),
    row("position", 3, PixelCentre, 0.0, XYZ, Float, "world-space position of the hit, render units; 0 where nothing is hit"),
    row("elementId", 1, PixelCentre, -1.0, Name, Float, "Hydra's elementId: the control (base) face of the mesh hit; −1 where nothing is hit"),
    row("Neye", 3, PixelCentre, 0.0, XYZ, Half, "Hydra's Neye: the shading normal in camera space, unit, facing the camera; 0 where nothing is hit"),
    row("albedo", 3, Mean, 0.0, RGB, Half, "diffuse reflectance of the hit toward the camera, linear RGB in [0, 1]"),
    row(
        "emission",
        3,
        Mean,
        0.0,
        RGB,
        Half,
        "radiance emitted toward the camera (emissive surfaces, lights seen directly, a dome as the background), linear RGB",
    ),
    row("directDiffuse", 3, Mean, 0.0, RGB, Half, "the lights' direct light reflected by the hit's diffuse lobe, linear RGB radiance"),
    row(
        "indirectDiffuse",
        3,
        Mean,
        0.0,
        RGB,
        Half,
        "light from other surfaces (and the ambient-occlusion sky) reflected by the hit's diffuse lobe, linear RGB radiance",
    ),
    row("specular", 3, Mean, 0.0, RGB, Half, "everything the hit's non-diffuse lobes reflect or refract toward the camera, linear RGB radiance"),
];

impl Aov {
    /// Every AOV, in [`AOV_TABLE`] order.
    pub const ALL: [Aov; 20] = [
        Aov::Color,
        Aov::Alpha,
        Aov::Depth,
        Aov::CameraDepth,
        Aov::Peye,
        Aov::Normal,
        Aov::PrimId,
        Aov::InstanceId,
        Aov::BeamWidth,
        Aov::TessRate,
        Aov::Ao,
        Aov::TessError,
        Aov::Position,
        Aov::ElementId,
        Aov::Neye,
        Aov::Albedo,
        Aov::Emission,
        Aov::DirectDiffuse,
        Aov::IndirectDiffuse,
        Aov::Specular,
    ];

    /// Its row of [`AOV_TABLE`].
    pub const fn info(self) -> &'static AovInfo {
        &AOV_TABLE[self as usize]
    }

    /// The AOV's name (Hydra's where Hydra has one).
    pub const fn name(self) -> &'static str {
        self.info().name
    }

    pub const fn channels(self) -> usize {
        self.info().channels
    }

    /// Averaged over a pixel's samples ([`Averaging::Mean`]).
    pub fn averaged(self) -> bool {
        self.info().averaging == Averaging::Mean
    }

    /// The AOV called `name`.
    pub fn from_name(name: &str) -> Option<Aov> {
        Aov::ALL.into_iter().find(|a| a.name() == name)
    }

    /// The AOV called `name`, where names come in (a render's AOV list, a RenderVar).
    ///
    /// # Errors
    /// [`UnknownAov`], naming it and listing the valid names.
    pub fn parse(name: &str) -> Result<Aov, UnknownAov> {
        Aov::from_name(name).ok_or_else(|| UnknownAov(name.to_string()))
    }

    /// The channel names in a file: color → R, G, B; alpha → A; depth → Z; normal → N.x, N.y,
    /// N.z; colour-like AOVs `name.R`, ...; vectors `name.x`, ...; one channel its name.
    pub fn file_channel_names(self) -> Vec<String> {
        match self.info().file_channels {
            FileChannels::Fixed(names) => names.iter().map(|n| n.to_string()).collect(),
            FileChannels::Suffixed(suffixes) => suffixes.iter().map(|s| format!("{}.{s}", self.name())).collect(),
            FileChannels::Name => vec![self.name().to_string()],
        }
    }
}

/// An AOV name the renderer does not know.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown AOV '{0}'; valid AOVs: {names}", names = AOV_NAMES.join(", "))]
pub struct UnknownAov(pub String);

/// `[N]` names of [`AOV_TABLE`]'s rows, computed at compile time.
const fn names() -> [&'static str; 20] {
    let mut out = [""; 20];
    let mut i = 0;
    while i < 20 {
        out[i] = AOV_TABLE[i].name;
        i += 1;
    }
    out
}

/// Every AOV's name, in table order.
pub const AOV_NAMES: [&str; 20] = names();

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variants_and_rows_line_up() {
        for (i, aov) in Aov::ALL.into_iter().enumerate() {
            assert_eq!(aov as usize, i);
            assert_eq!(Aov::from_name(aov.name()), Some(aov));
            assert_eq!(aov.file_channel_names().len(), aov.channels(), "{}", aov.name());
        }
        let names: std::collections::HashSet<_> = AOV_NAMES.iter().collect();
        assert_eq!(names.len(), AOV_NAMES.len(), "names are unique");
        assert_eq!(Aov::from_name("nonsense"), None);
        let e = Aov::parse("colour").unwrap_err().to_string();
        assert!(e.starts_with("unknown AOV 'colour'; valid AOVs: color, alpha,") && e.ends_with("specular"), "{e}");
    }
}
