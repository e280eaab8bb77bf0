//! # hd-mipray — the render delegate
//!
//! mipray's renderer in the shape of a Hydra render delegate (as hdEmbree is): one file per Hydra
//! concept. A scene delegate (the USD one lives in Python, `mipray.usd`) inserts prims, marks
//! them dirty and syncs them; a render pass renders the synced scene from a camera into render
//! buffers. Sync costs in proportion to the edit: a transform edit rebuilds no mesh, new points
//! rebuild only that mesh's patches.

pub mod aov;
#[cfg(feature = "tools")]
pub mod bench_scene;
pub mod camera;
pub mod config;
pub mod dirty_bits;
pub mod error;
pub mod instancer;
pub mod light;
pub mod material;
pub mod mesh;
pub mod render_buffer;
pub mod render_delegate;
pub mod render_pass;
#[cfg(feature = "tools")]
pub mod subdiv_compare;

pub use config::RenderSettings;
pub use error::DelegateError;
pub use render_delegate::RenderDelegate;
pub use render_pass::RenderPass;
