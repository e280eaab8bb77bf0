//! AOV descriptors (Hydra's `HdAovDescriptor`): the format, clear value and file channels of
//! each AOV the delegate can render, and what it holds — its meaning, units and space
//! ([`mipray::aov::AOV_TABLE`]). Names are Hydra's (`HdAovTokens`) where Hydra has one:
//! `color`, `depth`, `cameraDepth`, `Peye`, `normal`, `Neye`, `primId`, `instanceId`,
//! `elementId`. Two differ from Hydra on purpose: `depth` is camera-space depth along the view
//! axis (EXR's `Z`), not Hydra's clip-space depth in [0, 1] — `cameraDepth` holds the same
//! values under Hydra's name, with Hydra's clear value 0 where nothing is hit (Hydra's example
//! delegate, HdEmbree, writes the ray's hit distance there instead, which is longer off the view
//! axis by 1 / cos); and `primId` is the patch index within the mesh hit, not a render-index
//! id.

use mipray::aov::Aov;
use mipray::image_io::ChannelFormat;

/// How an AOV is stored and cleared.
#[derive(Clone, Debug, PartialEq)]
pub struct AovDescriptor {
    pub name: &'static str,
    /// What the AOV holds, its units and its space.
    pub meaning: &'static str,
    pub channels: usize,
    pub format: ChannelFormat,
    /// The value a pixel has where nothing renders.
    pub clear_value: f32,
    pub file_channels: Vec<String>,
}

impl From<Aov> for AovDescriptor {
    /// The descriptor is the core's row for the AOV ([`mipray::aov::AOV_TABLE`]).
    fn from(aov: Aov) -> Self {
        let info = aov.info();
        AovDescriptor {
            name: info.name,
            meaning: info.meaning,
            channels: info.channels,
            format: info.format,
            clear_value: info.clear,
            file_channels: aov.file_channel_names(),
        }
    }
}

/// The descriptor of a named AOV, or `None` for an unknown name.
pub fn default_aov_descriptor(name: &str) -> Option<AovDescriptor> {
    Aov::from_name(name).map(AovDescriptor::from)
}

/// Every AOV the delegate supports.
pub fn supported_aovs() -> Vec<AovDescriptor> {
    Aov::ALL.into_iter().map(AovDescriptor::from).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use mipray::film::AOV_NAMES;

    #[test]
    fn every_aov_says_what_it_holds_and_hydras_geometric_ones_are_there() {
        let all = supported_aovs();
        assert_eq!(all.len(), AOV_NAMES.len());
        for d in &all {
            assert!(d.meaning.len() > 20, "{}: {}", d.name, d.meaning);
        }
        let camera_depth = default_aov_descriptor("cameraDepth").unwrap();
        assert_eq!((camera_depth.channels, camera_depth.format, camera_depth.clear_value), (1, ChannelFormat::Float, 0.0));
        assert!(camera_depth.meaning.contains("camera-space") && camera_depth.meaning.contains("−Peye.z"), "{}", camera_depth.meaning);
        let peye = default_aov_descriptor("Peye").unwrap();
        assert_eq!(
            (peye.channels, peye.format, peye.file_channels.clone()),
            (3, ChannelFormat::Float, vec!["Peye.x".into(), "Peye.y".into(), "Peye.z".into()])
        );
        assert!(default_aov_descriptor("depth").unwrap().meaning.contains("EXR"));
        assert!(default_aov_descriptor("nonsense").is_none());
    }
}
