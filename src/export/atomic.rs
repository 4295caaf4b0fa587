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
    let dir = prepared_folder(path).map_err(io_err)?;
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

/// The folder `path` goes in (`.` for a bare file name), created if missing and cleared of killed
/// runs' temporaries ([`sweep_once`]).
fn prepared_folder(path: &Path) -> io::Result<PathBuf> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    fs::create_dir_all(&dir)?;
    sweep_once(&dir);
    Ok(dir)
}

/// The process id in a temporary file's name `.<name>.<pid>-<n>.tmp[.<ext>]`, if it is one.
fn temporary_owner(name: &str) -> Option<u32> {
    let stem = &name[..name.rfind(".tmp")?];
    if !name.starts_with('.') || !name[stem.len() + 4..].chars().next().is_none_or(|c| c == '.') {
        return None;
    }
    let (pid, n) = stem[stem.rfind('.')? + 1..].split_once('-')?;
    n.parse::<u64>().ok()?;
    pid.parse().ok()
}

/// Removes, once per folder per run, the temporaries that runs killed before they could clean up
/// left there (a kill signal runs no destructor): those whose process is gone. Only where
/// /proc tells which processes live (Linux); a temporary of a live process (another verdant
/// writing into the same folder) is left alone. Best effort: what cannot be removed stays.
fn sweep_once(dir: &Path) {
    static SWEPT: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return;
    }
    {
        let Ok(mut swept) = SWEPT.lock() else { return };
        let key = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf());
        if swept.contains(&key) {
            return;
        }
        swept.push(key);
    }
    let Ok(entries) = fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(temporary_owner) else { continue };
        if pid != std::process::id() && !proc.join(pid.to_string()).exists() {
            let _ = match entry.file_type() {
                Ok(t) if t.is_dir() => fs::remove_dir_all(entry.path()),
                _ => fs::remove_file(entry.path()),
            };
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
    /// Hidden staging folders ([`FileSet::folder_beside`]), removed with the set.
    folders: Vec<PathBuf>,
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

    /// A new hidden folder beside `path` (`.<name>.<pid>-<n>.tmp.d`), removed when the set is
    /// committed or dropped: files that can only be checked under their final names (a .gltf and
    /// the .bin it names, an .obj and its .mtl) are written there, checked, then
    /// [`FileSet::adopt`]ed.
    pub fn folder_beside(&mut self, path: &Path) -> Result<PathBuf, ExportError> {
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let io_err = |source: io::Error| ExportError::Io { path: path.to_path_buf(), source };
        let name = path.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
        let dir = prepared_folder(path).map_err(io_err)?;
        let folder =
            dir.join(format!(".{name}.{}-{}.tmp.d", std::process::id(), COUNTER.fetch_add(1, Ordering::Relaxed)));
        fs::create_dir(&folder).map_err(io_err)?;
        self.folders.push(folder.clone());
        Ok(folder)
    }

    /// Takes `file`, already written (in a [`FileSet::folder_beside`] of the same filesystem),
    /// into the set as the new contents of `path`.
    pub fn adopt(&mut self, file: PathBuf, path: PathBuf) {
        self.staged.retain(|(_, p)| p != &path);
        self.staged.push((file, path));
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
        for folder in std::mem::take(&mut self.folders) {
            let _ = fs::remove_dir_all(folder);
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
        for folder in &self.folders {
            let _ = fs::remove_dir_all(folder);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporaries_are_told_by_their_names() {
        assert_eq!(temporary_owner(".x.glb.4242-7.tmp.glb"), Some(4242));
        assert_eq!(temporary_owner(".report.json.17-0.tmp.json"), Some(17));
        assert_eq!(temporary_owner(".noext.5-1.tmp"), Some(5));
        for not_ours in
            ["x.glb.4242-7.tmp.glb", ".x.glb.tmp", ".x.4242.tmp.glb", ".x.a-1.tmp", ".x.1-2.tmpfoo", ".x.1-b.tmp"]
        {
            assert_eq!(temporary_owner(not_ours), None, "{not_ours}");
        }
    }
}
