//! The film: named AOV buffers (color, depth, normal, ...), filled by the render and handed to an
//! [`crate::image_io::ImageIo`] or to Python as arrays. Non-finite samples never reach it: they
//! are counted and dropped.

use crate::image_io::{ChannelFormat, ImageBuf};

/// Every AOV the renderer can produce, with its channel count. Hydra's names (`HdAovTokens`)
/// where Hydra has one (`color`, `depth`, `cameraDepth`, `normal`, `Neye`, `Peye`, `primId`,
/// `instanceId`, `elementId`); what each holds, in which units and space: [`AOV_MEANINGS`]. The
/// light AOVs add up to the colour: `color = emission + directDiffuse + indirectDiffuse +
/// specular` (ambient occlusion's sky light counts as indirect diffuse).
pub const AOVS: &[(&str, usize)] = &[
    ("color", 3),
    ("alpha", 1),
    ("depth", 1),
    ("cameraDepth", 1),
    ("Peye", 3),
    ("normal", 3),
    ("primId", 1),
    ("instanceId", 1),
    ("beamWidth", 1),
    ("tessRate", 1),
    ("ao", 1),
    ("tessError", 2),
    ("position", 3),
    ("elementId", 1),
    ("Neye", 3),
    ("albedo", 3),
    ("emission", 3),
    ("directDiffuse", 3),
    ("indirectDiffuse", 3),
    ("specular", 3),
];

/// The AOV names, for messages.
pub const AOV_NAMES: &[&str] = &[
    "color",
    "alpha",
    "depth",
    "cameraDepth",
    "Peye",
    "normal",
    "primId",
    "instanceId",
    "beamWidth",
    "tessRate",
    "ao",
    "tessError",
    "position",
    "elementId",
    "Neye",
    "albedo",
    "emission",
    "directDiffuse",
    "indirectDiffuse",
    "specular",
];

/// What each AOV holds, its units and its space, in [`AOVS`] order (the AOV descriptors' and
/// README's text). Camera space is USD's: +x right, +y up, the camera looking down −z; its units
/// are scene units for a camera whose transform does not scale. Colour-like AOVs and `alpha`,
/// `ao` are averaged over a pixel's samples; the others are the pixel centre's (sample 0's), never
/// a blend of two surfaces.
pub const AOV_MEANINGS: &[(&str, &str)] = &[
    ("color", "linear RGB radiance toward the camera, in the lights' units: emission + directDiffuse + indirectDiffuse + specular"),
    ("alpha", "fraction of the pixel's camera rays that hit a surface, in [0, 1]"),
    (
        "depth",
        "camera-space depth of the hit: distance along the view axis (−z in camera space), camera-space units; the far clipping distance where nothing is hit. EXR's Z channel; not Hydra's clip-space depth",
    ),
    (
        "cameraDepth",
        "Hydra's cameraDepth: camera-space depth of the hit, −Peye.z, positive in front of the camera, camera-space units (the same values as depth); 0 where nothing is hit",
    ),
    ("Peye", "Hydra's Peye: camera-space position of the hit (z < 0 in front of the camera), camera-space units; 0 where nothing is hit"),
    ("normal", "world-space unit shading normal at the hit (normal-mapped), facing the camera; 0 where nothing is hit"),
    ("primId", "index of the patch hit within its mesh; −1 where nothing is hit"),
    ("instanceId", "the scene's id of the instance hit; −1 where nothing is hit"),
    (
        "beamWidth",
        "world-space width of the ray beam (render units) at the hit that ends the camera ray's specular chain (the paper's figure 2)",
    ),
    ("tessRate", "effective tessellation rate at that hit: quads per side of its root subpatch (1, 2, 4, 8, 16, 16·2^depth when split)"),
    ("ao", "unoccluded fraction of the cosine-weighted hemisphere within aoDistance, in [0, 1]; 0 when ambient occlusion is off"),
    (
        "tessError",
        "distance along the camera ray between its hit on the tessellation and the exact limit surface (render units), and that distance over the beam width there (unitless)",
    ),
    ("position", "world-space position of the hit, render units; 0 where nothing is hit"),
    ("elementId", "Hydra's elementId: the control (base) face of the mesh hit; −1 where nothing is hit"),
    ("Neye", "Hydra's Neye: the shading normal in camera space, unit, facing the camera; 0 where nothing is hit"),
    ("albedo", "diffuse reflectance of the hit toward the camera, linear RGB in [0, 1]"),
    ("emission", "radiance emitted toward the camera (emissive surfaces, lights seen directly, a dome as the background), linear RGB"),
    ("directDiffuse", "the lights' direct light reflected by the hit's diffuse lobe, linear RGB radiance"),
    (
        "indirectDiffuse",
        "light from other surfaces (and the ambient-occlusion sky) reflected by the hit's diffuse lobe, linear RGB radiance",
    ),
    ("specular", "everything the hit's non-diffuse lobes reflect or refract toward the camera, linear RGB radiance"),
];

/// What AOV `name` holds, its units and space ([`AOV_MEANINGS`]), or `None` for an unknown name.
pub fn aov_meaning(name: &str) -> Option<&'static str> {
    AOV_MEANINGS.iter().find(|(n, _)| *n == name).map(|(_, m)| *m)
}

/// The AOVs holding linear RGB (radiance or reflectance): averaged over a pixel's samples and
/// stored as half floats with `.R`, `.G`, `.B` channels.
const COLOR_AOVS: &[&str] = &["albedo", "emission", "directDiffuse", "indirectDiffuse", "specular"];

/// Channel count of a named AOV, or `None` if the renderer does not know it.
pub fn aov_channels(name: &str) -> Option<usize> {
    AOVS.iter().find(|(n, _)| *n == name).map(|(_, c)| *c)
}

/// Channel names in a file: color → R, G, B; alpha → A; depth → Z; normal → N.x, N.y, N.z;
/// any other single-channel AOV keeps its name.
pub fn file_channel_names(aov: &str, channels: usize) -> Vec<String> {
    match aov {
        "color" => vec!["R".into(), "G".into(), "B".into()],
        "alpha" => vec!["A".into()],
        "depth" => vec!["Z".into()],
        "normal" => vec!["N.x".into(), "N.y".into(), "N.z".into()],
        "tessError" => vec!["tessError.world".into(), "tessError.beam".into()],
        _ if COLOR_AOVS.contains(&aov) && channels == 3 => ["R", "G", "B"].iter().map(|c| format!("{aov}.{c}")).collect(),
        _ if channels == 1 => vec![aov.to_string()],
        _ => ["x", "y", "z", "w"].iter().take(channels).map(|c| format!("{aov}.{c}")).collect(),
    }
}

/// The natural storage format of an AOV in a file: half for colour-like data, float where
/// precision matters (depth, positions, ids).
pub fn default_format(aov: &str) -> ChannelFormat {
    match aov {
        "color" | "alpha" | "normal" | "Neye" => ChannelFormat::Half,
        _ if COLOR_AOVS.contains(&aov) => ChannelFormat::Half,
        _ => ChannelFormat::Float,
    }
}

/// One AOV: `height × width × channels` f32, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct AovBuffer {
    pub name: String,
    pub channels: usize,
    pub data: Vec<f32>,
}

/// A set of AOV buffers of one resolution.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    pub width: usize,
    pub height: usize,
    pub aovs: Vec<AovBuffer>,
}

impl Film {
    /// A film with zeroed buffers for the named AOVs (unknown names are skipped; validate first).
    pub fn new(width: usize, height: usize, names: &[String]) -> Self {
        let aovs = names
            .iter()
            .filter_map(|n| aov_channels(n).map(|c| AovBuffer { name: n.clone(), channels: c, data: vec![0.0; width * height * c] }))
            .collect();
        Film { width, height, aovs }
    }

    pub fn aov(&self, name: &str) -> Option<&AovBuffer> {
        self.aovs.iter().find(|a| a.name == name)
    }

    pub fn aov_mut(&mut self, name: &str) -> Option<&mut AovBuffer> {
        self.aovs.iter_mut().find(|a| a.name == name)
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

    /// The AOVs `names` interleaved into one image with file channel names.
    pub fn to_image(&self, names: &[String]) -> ImageBuf {
        let sel: Vec<&AovBuffer> = names.iter().filter_map(|n| self.aov(n)).collect();
        let nc: usize = sel.iter().map(|a| a.channels).sum();
        let mut pixels = Vec::with_capacity(self.width * self.height * nc);
        for p in 0..self.width * self.height {
            for a in &sel {
                pixels.extend_from_slice(&a.data[p * a.channels..(p + 1) * a.channels]);
            }
        }
        ImageBuf {
            width: self.width,
            height: self.height,
            channels: sel.iter().flat_map(|a| file_channel_names(&a.name, a.channels)).collect(),
            pixels,
            metadata: Vec::new(),
        }
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
