//! Atomic writes: a file appears whole or not at all.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::export::error::ExportError;

/// Writes `bytes` to `path` atomically: a temporary file in the same folder, then renamed over
/// `path`, so a reader sees the old file or the new one, never a part. Creates missing parent
/// folders. On failure the temporary file is removed and whatever was at `path` before is left as
/// it was. No fsync: like other build tools we guard against failed and interrupted runs, not power
/// loss, and on ext4 an fsync also flushes every other file written before it (a cached scene
/// build spent most of its time there).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Like [`write_atomic`], streaming the contents from `fill` (for outputs too big to hold twice).
/// An error from `fill` aborts the write the same way an I/O error does.
pub fn write_atomic_with<F>(path: &Path, fill: F) -> Result<(), ExportError>
where
    F: FnOnce(&mut dyn Write) -> io::Result<()>,
{
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let io_err = |source: io::Error| ExportError::Io { path: path.to_path_buf(), source };
    let file_name = path
        .file_name()
        .ok_or_else(|| io_err(io::Error::new(io::ErrorKind::InvalidInput, "the path has no file name")))?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    fs::create_dir_all(&dir).map_err(io_err)?;
    if path.is_dir() {
        return Err(io_err(io::Error::new(io::ErrorKind::AlreadyExists, "a folder has this name")));
    }
    let tmp = dir.join(format!(
        ".{}.{}-{}.tmp",
        file_name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let file = fs::OpenOptions::new().write(true).create_new(true).open(&tmp)?;
        let mut w = io::BufWriter::new(file);
        fill(&mut w)?;
        drop(w.into_inner().map_err(|e| e.into_error())?);
        fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        return Err(io_err(e));
    }
    Ok(())
}
