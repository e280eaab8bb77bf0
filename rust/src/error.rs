//! Error types of the core. Messages are one line and name what is wrong; the caller (plugin,
//! Python) adds the prim path as context.

use thiserror::Error;

/// A mesh the core cannot use.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MeshError {
    /// Topology or values that contradict each other or USD's rules.
    #[error("invalid mesh: {0}")]
    Invalid(String),
    /// A point or value that is NaN or infinite.
    #[error("non-finite value: {0}")]
    NonFinite(String),
    /// The patch source (OpenSubdiv) refused the mesh.
    #[error("subdivision failed: {0}")]
    Subdivision(String),
    /// A feature the renderer does not implement, refused rather than drawn wrong.
    #[error("not supported: {0}")]
    Unsupported(String),
}

/// Image input/output failed.
#[derive(Debug, Error, Clone, PartialEq)]
#[error("{path}: {message}")]
pub struct ImageError {
    pub path: String,
    pub message: String,
}

/// A render that could not start or finish.
#[derive(Debug, Error)]
pub enum RenderError {
    #[error("invalid render settings: {0}")]
    Settings(String),
    #[error("no camera: {0}")]
    Camera(String),
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error("render cancelled")]
    Cancelled,
    /// A panic in the renderer outside any one prim's work (a bug); the render stopped.
    #[error("internal error: {0}")]
    Internal(String),
}
