//! The one error type of the root library (the CLI reports it with its chain of causes).

use std::path::PathBuf;

/// What can go wrong in an evaluation or another job of the root library.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
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
    /// A figure could not be drawn or written.
    #[error("{path}: {message}")]
    Plot { path: PathBuf, message: String },
    /// A configuration file does not parse (syntax, unknown key, wrong type).
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    /// A configuration value is out of range; `key` is its dotted path.
    #[error("{key}: {message}")]
    Config { key: String, message: String },
    /// An error of the thing a configuration key names (`perception.weights`).
    #[error("{key}")]
    At {
        key: String,
        #[source]
        source: Box<Error>,
    },
    /// An error inside a configuration file, named by its path.
    #[error("{path}")]
    InFile {
        path: PathBuf,
        #[source]
        source: Box<Error>,
    },
    #[error(transparent)]
    Robot(#[from] workcell_robots::RobotError),
    #[error(transparent)]
    Sim(#[from] workcell_sim::SimError),
    #[error(transparent)]
    Render(#[from] workcell_render::RenderError),
    #[error(transparent)]
    Perception(#[from] workcell_perception::PerceptionError),
    #[error(transparent)]
    ProcNet(#[from] workcell_procnet::ProcNetError),
    #[error(transparent)]
    Safety(#[from] workcell_safety::SafetyError),
}

impl Error {
    /// A value out of range.
    pub fn config(key: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Config {
            key: key.into(),
            message: message.into(),
        }
    }

    /// This error as one found in the file at `path`.
    #[must_use]
    pub fn in_file(self, path: &std::path::Path) -> Self {
        Error::InFile {
            path: path.to_path_buf(),
            source: Box::new(self),
        }
    }
}

/// Result alias of the root library.
pub type Result<T, E = Error> = std::result::Result<T, E>;
