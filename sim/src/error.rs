//! The one error type of this crate.

use std::path::PathBuf;

use workcell_robots::RobotError;

/// What can go wrong while reading a scenario or building and running a cell.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// The scenario file could not be read.
    #[error("{path}: cannot read")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file of the output could not be written (a dataset's frames, its manifest).
    #[error("{path}: cannot write")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The scenario is not valid TOML for a scenario (syntax, unknown key, wrong type).
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    /// A value is out of range; `key` is its dotted path (e.g. `robot.base.xyz`), `path` the
    /// file it came from (`None` from `validate`, which sees no file; the loader adds it with
    /// [`SimError::in_file`]).
    #[error("{}{key}: {message}", file_prefix(.path.as_deref()))]
    Invalid {
        path: Option<PathBuf>,
        key: String,
        message: String,
    },
    /// A robot or human model named by the scenario failed to load.
    #[error("{path}: {key}")]
    Robot {
        path: PathBuf,
        key: String,
        #[source]
        source: Box<RobotError>,
    },
    /// Inverse kinematics found no configuration for a task waypoint.
    #[error(
        "{path}: {key}: no joint configuration reaches {target:?} (residual {residual_m:.4} m)"
    )]
    Unreachable {
        path: PathBuf,
        key: String,
        target: [f64; 3],
        residual_m: f64,
    },
    /// A command given to `step` does not fit the robot.
    #[error("{message}")]
    InvalidCommand { message: String },
    /// The physics world could not be built from a model that loaded (reported rather than
    /// a panic; it points at a bug or at a robot rapier cannot represent).
    #[error("physics: {message}")]
    Physics { message: String },
    /// The renderer, or reading or writing an image or a dataset file, failed.
    #[error(transparent)]
    Render(#[from] workcell_render::RenderError),
    /// A recorded clip could not be read.
    #[error(transparent)]
    Mocap(#[from] workcell_mocap::MocapError),
    /// A dataset being generated cannot be written where it is asked to be.
    #[error("{path}: {message}")]
    Dataset { path: PathBuf, message: String },
}

impl SimError {
    /// The error as found in the file at `path`: a value error without a file gets its name.
    #[must_use]
    pub fn in_file(self, path: &std::path::Path) -> Self {
        match self {
            SimError::Invalid {
                path: None,
                key,
                message,
            } => SimError::Invalid {
                path: Some(path.to_path_buf()),
                key,
                message,
            },
            other => other,
        }
    }
}

/// `"path: "`, or nothing without a file.
fn file_prefix(path: Option<&std::path::Path>) -> String {
    path.map_or_else(String::new, |p| format!("{}: ", p.display()))
}

/// Result alias of this crate.
pub type Result<T, E = SimError> = std::result::Result<T, E>;
