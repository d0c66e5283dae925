//! File-system helpers: writing a file atomically (a temporary file in the destination
//! folder, then a rename), so a crash or an error never leaves a truncated file behind.
//!
//! The temporary file is `.<name>.<pid>.<n>.tmp` beside the destination (`n` counts the
//! process's writes, so two threads writing the same file never share one);
//! [`temporary_owner`] reads such a name back, for removing those a killed process left.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Error raised by an atomic write.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// Filesystem failure.
    #[error("{path}: cannot write: {source}")]
    Io {
        /// File involved.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The destination exists and overwriting was not requested.
    #[error("{0}: already exists; pass --overwrite to replace it")]
    Exists(PathBuf),
}

/// The temporary file [`write_atomically`] writes before renaming it to `path` (also
/// the one [`crate::io::video`] has ffmpeg write).
pub fn temporary_path(path: &Path) -> PathBuf {
    static WRITES: AtomicU64 = AtomicU64::new(0);
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let n = WRITES.fetch_add(1, Ordering::Relaxed);
    dir.join(format!(".{name}.{}.{n}.tmp", std::process::id()))
}

/// The destination's file name and the writer's process id of a temporary file of
/// [`write_atomically`], from its file name; `None` for any other name.
pub fn temporary_owner(file_name: &str) -> Option<(&str, u32)> {
    let rest = file_name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let (rest, n) = rest.rsplit_once('.')?;
    let (name, pid) = rest.rsplit_once('.')?;
    n.parse::<u64>().ok()?;
    Some((name, pid.parse().ok()?))
}

/// Runs `write` against a temporary file beside `path`, flushes it to the disk, then
/// renames it into place. The temporary file is removed on failure. With
/// `overwrite == false` an existing `path` is an error and is left untouched. `write`
/// returns the caller's error type, which takes this module's errors ([`WriteError`]).
pub fn write_atomically<E: From<WriteError>>(
    path: &Path,
    overwrite: bool,
    write: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> Result<(), E>,
) -> Result<(), E> {
    let exists = || WriteError::Exists(path.to_path_buf());
    if !overwrite && path.exists() {
        return Err(exists().into());
    }
    let io = |source| {
        E::from(WriteError::Io {
            path: path.to_path_buf(),
            source,
        })
    };
    let tmp = temporary_path(path);
    let result = (|| {
        let file = std::fs::File::create(&tmp).map_err(io)?;
        let mut writer = std::io::BufWriter::new(file);
        write(&mut writer)?;
        writer.flush().map_err(io)?;
        let file = writer.into_inner().map_err(|e| io(e.into_error()))?;
        file.sync_all().map_err(io)?;
        drop(file);
        if !overwrite && path.exists() {
            return Err(exists().into());
        }
        std::fs::rename(&tmp, path).map_err(io)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Writes `bytes` to `path` atomically (see [`write_atomically`]).
pub fn write_bytes_atomically(
    path: &Path,
    overwrite: bool,
    bytes: &[u8],
) -> Result<(), WriteError> {
    write_atomically(path, overwrite, |w| {
        w.write_all(bytes).map_err(|source| WriteError::Io {
            path: path.to_path_buf(),
            source,
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporary_names_read_back() {
        let tmp = temporary_path(Path::new("out/frame.00001.png"));
        assert_eq!(tmp.parent(), Some(Path::new("out")));
        let name = tmp.file_name().unwrap().to_str().unwrap();
        assert_eq!(
            temporary_owner(name),
            Some(("frame.00001.png", std::process::id()))
        );
        assert_ne!(tmp, temporary_path(Path::new("out/frame.00001.png")));
        assert_eq!(
            temporary_path(Path::new("x.png")).parent(),
            Some(Path::new("."))
        );
        for other in [
            "frame.png",
            ".frame.png.tmp",
            ".frame.png.12.tmp",
            ".frame.png.x.3.tmp",
            ".frame.png.12.y.tmp",
        ] {
            assert_eq!(temporary_owner(other), None, "{other}");
        }
    }

    #[test]
    fn writes_replace_only_when_asked_and_leave_no_temporary() {
        let dir = std::env::temp_dir().join(format!("verisplat-fsutil-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.txt");
        write_bytes_atomically(&path, false, b"one").unwrap();
        let again = write_bytes_atomically(&path, false, b"two");
        assert!(matches!(again, Err(WriteError::Exists(_))), "{again:?}");
        assert_eq!(std::fs::read(&path).unwrap(), b"one");
        write_bytes_atomically(&path, true, b"two").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"two");
        // A failing writer leaves the destination as it was and no temporary file.
        let failed: Result<(), WriteError> = write_atomically(&path, true, |w| {
            w.write_all(b"partial").unwrap();
            Err(WriteError::Exists(PathBuf::from("stop")))
        });
        assert!(failed.is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"two");
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["a.txt"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
