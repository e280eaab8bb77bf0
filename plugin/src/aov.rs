//! AOV descriptors (Hydra's `HdAovDescriptor`): the format, clear value and file channels of
//! each AOV the delegate can render.

use mipray::film::{aov_channels, default_format, file_channel_names, AOV_NAMES};
use mipray::image_io::ChannelFormat;

/// How an AOV is stored and cleared.
#[derive(Clone, Debug, PartialEq)]
pub struct AovDescriptor {
    pub name: &'static str,
    pub channels: usize,
    pub format: ChannelFormat,
    /// The value a pixel has where nothing renders.
    pub clear_value: f32,
    pub file_channels: Vec<String>,
}

/// The descriptor of a named AOV, or `None` for an unknown name.
pub fn default_aov_descriptor(name: &str) -> Option<AovDescriptor> {
    let &name = AOV_NAMES.iter().find(|n| **n == name)?;
    let channels = aov_channels(name)?;
    Some(AovDescriptor {
        name,
        channels,
        format: default_format(name),
        clear_value: match name {
            "primId" | "instanceId" | "elementId" => -1.0,
            _ => 0.0,
        },
        file_channels: file_channel_names(name, channels),
    })
}

/// Every AOV the delegate supports.
pub fn supported_aovs() -> Vec<AovDescriptor> {
    AOV_NAMES.iter().filter_map(|n| default_aov_descriptor(n)).collect()
}
