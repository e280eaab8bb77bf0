//! The camera Sprim: a USD camera's values, held until a render pass asks for it.

pub use mipray::camera::{Camera, Projection};

/// A camera prim.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraPrim {
    pub path: String,
    pub camera: Camera,
}
