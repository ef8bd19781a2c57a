//! The one error type of this crate.

/// What can go wrong while setting up the safety layer. Per-tick problems (a NaN joint state,
/// an infeasible constraint set) are not errors: they give a braking command and a
/// [`crate::FilterStatus`] that says why.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SafetyError {
    /// A configuration value is out of its range.
    #[error("safety configuration: {key}: {message}")]
    InvalidConfig { key: String, message: String },
    /// The robot cannot be guarded: no collision geometry, too many joints, a missing limit.
    #[error("robot '{robot}': {message}")]
    Robot { robot: String, message: String },
    /// The QP solver refused the problem at setup (a bug: the problem is built here).
    #[error("QP solver setup failed: {message}")]
    Solver { message: String },
}

/// Result with [`SafetyError`].
pub type Result<T, E = SafetyError> = std::result::Result<T, E>;

pub(crate) fn invalid(key: &str, message: impl Into<String>) -> SafetyError {
    SafetyError::InvalidConfig {
        key: key.to_string(),
        message: message.into(),
    }
}
