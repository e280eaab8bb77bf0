//! Errors of the delegate: every message names the prim path.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum DelegateError {
    /// A prim's data is unusable; the prim is skipped, the others render.
    #[error("{path}: {message}")]
    Prim { path: String, message: String },
    /// A prim's work panicked (a renderer bug); the prim is dropped, the others render.
    #[error("{path}: internal error, prim dropped: {message}")]
    Internal { path: String, message: String },
    /// A render setting with a bad name or value.
    #[error(transparent)]
    Setting(#[from] mipray::settings::SettingError),
    /// The render pass could not run.
    #[error(transparent)]
    Render(#[from] mipray::error::RenderError),
}

impl DelegateError {
    pub fn prim(path: &str, message: impl std::fmt::Display) -> Self {
        DelegateError::Prim { path: path.to_string(), message: message.to_string() }
    }

    pub fn internal(path: &str, message: impl std::fmt::Display) -> Self {
        DelegateError::Internal { path: path.to_string(), message: message.to_string() }
    }
}
