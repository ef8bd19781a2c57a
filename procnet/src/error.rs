//! The one error type of this crate.

use std::path::PathBuf;

/// What can go wrong while building, loading, training or running a ProcNet.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ProcNetError {
    /// A configuration value is out of range; `key` names it.
    #[error("{key}: {message}")]
    Config { key: String, message: String },
    /// A configuration file could not be read or parsed.
    #[error("{path}: {message}")]
    ConfigFile { path: PathBuf, message: String },
    /// A frame handed to the network does not fit it.
    #[error("invalid input: {message}")]
    Input { message: String },
    /// A weight file is missing, corrupt, truncated or of another configuration.
    #[error("{path}: {message}")]
    Weights { path: PathBuf, message: String },
    /// The dataset could not be read, or the renderer failed.
    #[error(transparent)]
    Render(#[from] workcell_render::RenderError),
    /// A human model could not be loaded or lacks a part.
    #[error(transparent)]
    Robot(#[from] workcell_robots::RobotError),
    /// Reading or writing a file of a run (checkpoint, metrics CSV, plot) failed.
    #[error("{path}: cannot read or write")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Training diverged or was given data it cannot learn from.
    #[error("training: {message}")]
    Training { message: String },
    /// The requested backend was not compiled in or failed to start.
    #[error("backend {name}: {message}")]
    Backend { name: String, message: String },
}

pub type Result<T, E = ProcNetError> = std::result::Result<T, E>;
