//! The one error type of this crate.

use std::path::PathBuf;

/// What can go wrong while rendering, or reading and writing images and datasets.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// A file could not be read.
    #[error("{path}: cannot read")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file could not be written.
    #[error("{path}: cannot write")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A camera, pose, configuration or image size given to the renderer is not usable.
    #[error("render: {message}")]
    InvalidRender { message: String },
    /// The GPU backend failed (no adapter, device lost, a wgpu validation error).
    #[error("gpu: {message}")]
    Gpu { message: String },
    /// A dataset or image file is missing, malformed or inconsistent with its manifest.
    #[error("{path}: {message}")]
    Dataset { path: PathBuf, message: String },
}

/// Result alias of this crate.
pub type Result<T, E = RenderError> = std::result::Result<T, E>;
