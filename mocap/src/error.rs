//! Errors of reading and processing recorded motion.

use std::path::PathBuf;

/// What went wrong with a clip; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum MocapError {
    /// The file cannot be read (or is refused: not a regular file, too large).
    #[error("{}: cannot read", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file is not what its format says, at a line (1-based) where one is known.
    #[error("{}{}: {message}", path.display(), line.map_or(String::new(), |l| format!(":{l}")))]
    Parse {
        path: PathBuf,
        line: Option<usize>,
        message: String,
    },
    /// The file parses but cannot be used as motion (a joint the map names is missing, too few
    /// frames, a rate that is not a rate).
    #[error("{}: {message}", path.display())]
    Invalid { path: PathBuf, message: String },
}

pub type Result<T> = std::result::Result<T, MocapError>;
