//! The one error type of this crate.

use std::path::PathBuf;

/// Everything that can go wrong while loading or querying a robot model.
///
/// Every variant that comes from a file names the file (`path`) and, where it applies, the
/// URDF element (`element`, e.g. `joint 'elbow'`), so that a user can find the line to fix.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RobotError {
    /// The file could not be read.
    #[error("{path}: cannot read: {error}")]
    Io {
        path: PathBuf,
        // Not a `source`: the message already says it, and error chains would repeat it.
        error: std::io::Error,
    },
    /// The XML is not a URDF that can be parsed (syntax, unknown joint type, missing attribute).
    #[error("{path}: not a valid URDF: {message}")]
    Parse { path: PathBuf, message: String },
    /// The URDF parses but describes something that is not a valid robot.
    #[error("{path}: {element}: {message}")]
    Invalid {
        path: PathBuf,
        element: String,
        message: String,
    },
    /// A mesh file referenced by a link could not be found, resolved or decoded.
    #[error("{path}: {element}: mesh '{uri}': {message}")]
    Mesh {
        path: PathBuf,
        element: String,
        uri: String,
        message: String,
    },
    /// A name was asked for that the catalogue does not have.
    #[error(
        "no robot named '{name}' in the catalogue or the robot library (available: {available})"
    )]
    UnknownRobot { name: String, available: String },
    /// A query was given arguments that do not fit the model (wrong number of joints, NaN).
    #[error("{message}")]
    InvalidArgument { message: String },
}

impl RobotError {
    pub(crate) fn invalid(
        path: impl Into<PathBuf>,
        element: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Self::Invalid {
            path: path.into(),
            element: element.into(),
            message: message.into(),
        }
    }
}

/// Result alias of this crate.
pub type Result<T, E = RobotError> = std::result::Result<T, E>;
