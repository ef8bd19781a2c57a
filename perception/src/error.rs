//! The one error type of this crate.

/// What can go wrong while fitting or tracking the arm.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PerceptionError {
    /// Masks, a frame, a camera or a human model that does not fit the request.
    #[error("invalid input: {message}")]
    Input { message: String },
    /// A calibration file is unreadable, malformed, or of other weights.
    #[error("{path}: {message}")]
    Calibration {
        path: std::path::PathBuf,
        message: String,
    },
    /// The network failed (its weights, its input, its backend).
    #[error(transparent)]
    Network(#[from] workcell_procnet::ProcNetError),
    /// The dataset could not be read, or the renderer failed.
    #[error(transparent)]
    Render(#[from] workcell_render::RenderError),
    /// A human model could not be loaded or lacks a part.
    #[error(transparent)]
    Robot(#[from] workcell_robots::RobotError),
}

pub type Result<T, E = PerceptionError> = std::result::Result<T, E>;
