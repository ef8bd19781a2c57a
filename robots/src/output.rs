//! The one way the project writes a file that must never be seen half written: to a
//! temporary name beside it (`dir/.name.tmp`), synced, then renamed over the target. A run
//! stopped at any point leaves the old file or the new one, never a torn one (a stale
//! temporary at most, which the next write replaces).

use std::io::Write as _;
use std::path::{Path, PathBuf};

/// `dir/.name.tmp` for `dir/name`: where [`write_atomic`] writes before the rename.
#[must_use]
pub fn temporary_name(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "file".into(), |n| n.to_string_lossy().into_owned());
    path.with_file_name(format!(".{name}.tmp"))
}

/// Writes `bytes` to `path` atomically.
///
/// # Errors
/// The temporary file cannot be created, written or synced, or the rename fails.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic_with(
        path,
        |tmp| {
            let mut file = std::fs::File::create(tmp)?;
            file.write_all(bytes)
        },
        |e| e,
    )
}

/// Atomically replaces `path` with what `write` puts at the temporary path it is given (for
/// writers that open their file themselves, such as a tensor store): the temporary is
/// synced, then renamed over `path`.
///
/// # Errors
/// What `write` returns, or the I/O error of the sync or the rename as `io_error` makes it.
pub fn write_atomic_with<E>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
    io_error: impl FnOnce(std::io::Error) -> E,
) -> Result<(), E> {
    let tmp = temporary_name(path);
    write(&tmp)?;
    std::fs::File::open(&tmp)
        .and_then(|f| f.sync_data())
        .and_then(|()| std::fs::rename(&tmp, path))
        .map_err(io_error)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_write_replaces_the_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("step.json");
        std::fs::write(&path, b"old").expect("write");
        write_atomic(&path, b"new").expect("atomic write");
        assert_eq!(std::fs::read(&path).expect("read"), b"new");
        assert!(!temporary_name(&path).exists());
        assert_eq!(temporary_name(&path), dir.path().join(".step.json.tmp"));
    }

    #[test]
    fn a_failed_write_leaves_the_old_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("weights.safetensors");
        std::fs::write(&path, b"old").expect("write");
        let result: Result<(), std::io::Error> = write_atomic_with(
            &path,
            |tmp| {
                std::fs::write(tmp, b"half")?;
                Err(std::io::Error::other("the writer failed"))
            },
            |e| e,
        );
        assert!(result.is_err());
        assert_eq!(std::fs::read(&path).expect("read"), b"old");
        // Into a folder that does not exist: an error, nothing written.
        let missing = dir.path().join("no/such/file");
        assert!(write_atomic(&missing, b"x").is_err());
        assert!(!missing.exists());
    }
}
