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
    let tmp = stage(path, fill)?;
    fs::rename(&tmp, path).map_err(|source| {
        let _ = fs::remove_file(&tmp);
        ExportError::Io { path: path.to_path_buf(), source }
    })
}

/// Writes `fill`'s bytes to a new temporary file beside `path` (same folder, so renaming it over
/// `path` needs no space and cannot cross filesystems) and returns its path; on failure nothing is
/// left behind. Creates missing parent folders; refuses a `path` that is a folder.
fn stage<F>(path: &Path, fill: F) -> Result<PathBuf, ExportError>
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
    // hidden, marked, and ending in the file's own extension (a staged glb can be validated as one)
    let ext = path.extension().map(|e| format!(".{}", e.to_string_lossy())).unwrap_or_default();
    let tmp = dir.join(format!(
        ".{}.{}-{}.tmp{ext}",
        file_name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let file = fs::OpenOptions::new().write(true).create_new(true).open(&tmp)?;
        let mut w = io::BufWriter::new(file);
        fill(&mut w)?;
        drop(w.into_inner().map_err(|e| e.into_error())?);
        Ok(())
    })();
    match result {
        Ok(()) => Ok(tmp),
        Err(e) => {
            let _ = fs::remove_file(&tmp);
            Err(io_err(e))
        }
    }
}

/// Files replaced as one set (a LoD chain with its atlases, a .gltf with its .bin, an .obj with
/// its .mtl and textures): each is written whole to a temporary file beside its final path, and
/// only when every one is written (and checked, see [`FileSet::staged`]) does [`FileSet::commit`]
/// rename them into place, in the order written. Until then nothing the user had is touched: a
/// full disk, an error or a kill while writing leaves the old set as it was (a kill leaves the
/// hidden `.<name>.<pid>-<n>.tmp` files behind; an error or a panic removes them). What is not
/// atomic is the rename loop itself: a kill between two renames leaves a mix, for microseconds
/// instead of the whole write.
#[derive(Debug, Default)]
pub struct FileSet {
    /// (temporary, final) in the order written.
    staged: Vec<(PathBuf, PathBuf)>,
}

impl FileSet {
    pub fn new() -> FileSet {
        FileSet::default()
    }

    /// Stages `bytes` for `path` (replacing what an earlier call staged for the same path).
    pub fn write(&mut self, path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
        self.write_with(path, |w| w.write_all(bytes))
    }

    /// [`FileSet::write`], streaming the contents from `fill`.
    pub fn write_with<F>(&mut self, path: &Path, fill: F) -> Result<(), ExportError>
    where
        F: FnOnce(&mut dyn Write) -> io::Result<()>,
    {
        let tmp = stage(path, fill)?;
        if let Some(i) = self.staged.iter().position(|(_, p)| p == path) {
            let (old, _) = self.staged.remove(i);
            let _ = fs::remove_file(old);
        }
        self.staged.push((tmp, path.to_path_buf()));
        Ok(())
    }

    /// Where `path`'s new contents wait until the commit (to validate them before anything is
    /// replaced).
    pub fn staged(&self, path: &Path) -> Option<&Path> {
        self.staged.iter().find(|(_, p)| p == path).map(|(t, _)| t.as_path())
    }

    /// Renames every staged file over its final path, in the order written; returns the final
    /// paths. A rename that fails (the final path became a folder) stops there: the files renamed
    /// before it are in place, the others' temporaries are removed.
    pub fn commit(mut self) -> Result<Vec<PathBuf>, ExportError> {
        let staged = std::mem::take(&mut self.staged);
        let mut done = Vec::with_capacity(staged.len());
        let mut rest = staged.into_iter();
        while let Some((tmp, path)) = rest.next() {
            if let Err(source) = fs::rename(&tmp, &path) {
                let _ = fs::remove_file(&tmp);
                for (t, _) in rest {
                    let _ = fs::remove_file(t);
                }
                return Err(ExportError::Io { path, source });
            }
            done.push(path);
        }
        Ok(done)
    }
}

impl Drop for FileSet {
    /// An uncommitted set (an error or a panic on the way) leaves nothing behind.
    fn drop(&mut self) {
        for (tmp, _) in &self.staged {
            let _ = fs::remove_file(tmp);
        }
    }
}
