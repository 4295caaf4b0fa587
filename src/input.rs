//! Reading user files with limits: every reader checks that the path is a regular file (not a
//! folder, FIFO or device such as /dev/zero) and that its size is within an explicit limit for its
//! kind before reading, then reads with a bounded buffer (a file that grows while it is read is
//! refused at the limit too). The limits are documented in README.md ("Limits").

use std::io::Read;
use std::path::{Component, Path, PathBuf};

/// Largest preset file.
pub const MAX_PRESET_BYTES: u64 = 1 << 20;
/// Largest L-system file.
pub const MAX_LSYSTEM_BYTES: u64 = 4 << 20;
/// Largest heightmap file (an 8193² 16-bit PNG is about 134 MB uncompressed at worst; float TIFFs
/// of that size about 268 MB).
pub const MAX_HEIGHTMAP_BYTES: u64 = 1 << 30;
/// Largest image read as a density map, mask or blade texture.
pub const MAX_IMAGE_BYTES: u64 = 256 << 20;
/// Largest OBJ model.
pub const MAX_OBJ_BYTES: u64 = 512 << 20;
/// Largest MTL material library.
pub const MAX_MTL_BYTES: u64 = 16 << 20;
/// Largest texture an MTL or a glTF names.
pub const MAX_TEXTURE_BYTES: u64 = 256 << 20;
/// Largest glTF / GLB file, and each buffer or image it names.
pub const MAX_GLTF_BYTES: u64 = 2 << 30;
/// Largest binary placement table read back (64 bytes a row: about a billion rows).
pub const MAX_TABLE_BYTES: u64 = 64 << 30;

/// Why a file was not read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{}: {problem}", path.display())]
    NotAFile { path: PathBuf, problem: &'static str },
    #[error("{}: {size} bytes, more than the {limit}-byte limit for {what}; use a smaller file", path.display())]
    TooLarge { path: PathBuf, size: u64, limit: u64, what: &'static str },
    #[error("{}: cannot read: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
}

impl ReadError {
    /// The underlying I/O error kind (NotFound for a missing file), for callers that tell
    /// "missing" from "unreadable".
    pub fn io_kind(&self) -> Option<std::io::ErrorKind> {
        match self {
            ReadError::Io { source, .. } => Some(source.kind()),
            _ => None,
        }
    }

    /// As an I/O error whose message leaves out the path (for errors that name the file
    /// themselves); a missing file stays `NotFound`.
    pub fn into_io(self) -> std::io::Error {
        match self {
            ReadError::Io { source, .. } => source,
            ReadError::NotAFile { problem, .. } => std::io::Error::new(std::io::ErrorKind::InvalidInput, problem),
            ReadError::TooLarge { size, limit, what, .. } => std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("{size} bytes, more than the {limit}-byte limit for {what}; use a smaller file"),
            ),
        }
    }
}

/// The bytes of `path`, a regular file of at most `limit` bytes (`what` names the kind of file in
/// the message: "a preset", "an L-system", …).
pub fn read_limited(path: &Path, limit: u64, what: &'static str) -> Result<Vec<u8>, ReadError> {
    let io = |source| ReadError::Io { path: path.to_path_buf(), source };
    let (file, len) = open_limited(path, limit, what)?;
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(limit + 1).read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 > limit {
        return Err(ReadError::TooLarge { path: path.to_path_buf(), size: bytes.len() as u64, limit, what });
    }
    Ok(bytes)
}

/// `path` opened for reading, with its length: the checks of [`read_limited`] (a regular file of
/// at most `limit` bytes) without reading it, for readers that take only part of a file.
pub fn open_limited(path: &Path, limit: u64, what: &'static str) -> Result<(std::fs::File, u64), ReadError> {
    let io = |source| ReadError::Io { path: path.to_path_buf(), source };
    let meta = std::fs::metadata(path).map_err(io)?;
    if meta.is_dir() {
        return Err(ReadError::NotAFile { path: path.to_path_buf(), problem: "is a folder, not a file" });
    }
    if !meta.is_file() {
        return Err(ReadError::NotAFile {
            path: path.to_path_buf(),
            problem: "is not a regular file (a device, FIFO or socket)",
        });
    }
    if meta.len() > limit {
        return Err(ReadError::TooLarge { path: path.to_path_buf(), size: meta.len(), limit, what });
    }
    let file = std::fs::File::open(path).map_err(io)?;
    Ok((file, meta.len()))
}

/// A relative URI or file name from inside a file (glTF buffer/image URI, MTL `map_Kd`, OBJ
/// `mtllib`), resolved against that file's folder `base`: absolute paths and paths that climb out
/// of `base` (`..`) are refused, so a file cannot make verdant read elsewhere on the disk.
pub fn resolve_inside(base: &Path, reference: &str) -> Result<PathBuf, String> {
    let rel = Path::new(reference);
    let mut depth: i64 = 0;
    for c in rel.components() {
        match c {
            Component::Normal(_) => depth += 1,
            Component::CurDir => {}
            Component::ParentDir => {
                depth -= 1;
                if depth < 0 {
                    return Err(format!(
                        "`{}` points outside the file's folder; only files beside it or below it are read",
                        escape(reference)
                    ));
                }
            }
            Component::RootDir | Component::Prefix(_) => {
                return Err(format!(
                    "`{}` is an absolute path; only relative paths inside the file's folder are read",
                    escape(reference)
                ));
            }
        }
    }
    Ok(base.join(rel))
}

/// tobj's OBJ loader over the bytes of `path` already read (`text`), its `mtllib` files resolved
/// inside the OBJ's folder and read with [`MAX_MTL_BYTES`] (tobj would read any path, of any size).
/// Returns tobj's result and, when a material library could not be read, which one and why.
pub fn load_obj_bounded(
    path: &Path,
    text: &[u8],
    options: &tobj::LoadOptions,
) -> (tobj::LoadResult, Option<(PathBuf, String)>) {
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new(".")).to_path_buf();
    let failed: std::cell::RefCell<Option<(PathBuf, String)>> = std::cell::RefCell::new(None);
    let loader = |mtl: &Path| -> tobj::MTLLoadResult {
        let name = mtl.to_string_lossy();
        let read = resolve_inside(&base, &name).and_then(|file| {
            read_limited(&file, MAX_MTL_BYTES, "a material library")
                .map(|b| (file, b))
                .map_err(|e| e.into_io().to_string())
        });
        match read.and_then(|(file, bytes)| match mtl_problem(&bytes) {
            Some(problem) => Err(format!("{}: {problem}", file.display())),
            None => Ok((file, bytes)),
        }) {
            Ok((_, bytes)) => tobj::load_mtl_buf(&mut std::io::BufReader::new(&bytes[..])),
            Err(problem) => {
                failed.borrow_mut().get_or_insert((base.join(mtl), problem));
                Err(tobj::LoadError::OpenFileFailed)
            }
        }
    };
    let result = tobj::load_obj_buf(&mut std::io::BufReader::new(text), options, loader);
    (result, failed.into_inner())
}

/// A material-library line tobj 4.0.5 would panic on (its `parse_float3` unwraps: `Kd 0.5 0.35`
/// aborts the whole load), as "line N: …"; tobj reports the other malformed lines itself.
fn mtl_problem(bytes: &[u8]) -> Option<String> {
    let text = String::from_utf8_lossy(bytes);
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        if let Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) = words.next() {
            let found = words.count();
            if found < 3 {
                return Some(format!("line {}: `{key}` needs three numbers (r g b), found {found}", n + 1));
            }
        }
    }
    None
}

/// `text` with control characters escaped (`\u{1b}` for ESC), safe to print on a terminal.
pub fn escape(text: &str) -> String {
    text.chars().flat_map(|c| if c.is_control() { c.escape_default().collect::<Vec<_>>() } else { vec![c] }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_folders_and_large_files_are_refused_before_reading() {
        let dir = tempfile::tempdir().unwrap();
        assert!(matches!(read_limited(dir.path(), 10, "a preset"), Err(ReadError::NotAFile { .. })));
        #[cfg(unix)]
        {
            let e = read_limited(Path::new("/dev/zero"), 1 << 20, "a preset").unwrap_err();
            assert!(e.to_string().contains("not a regular file"), "{e}");
        }
        let f = dir.path().join("a.txt");
        std::fs::write(&f, b"0123456789").unwrap();
        assert_eq!(read_limited(&f, 10, "a preset").unwrap(), b"0123456789");
        let e = read_limited(&f, 9, "a preset").unwrap_err();
        assert!(e.to_string().contains("10 bytes, more than the 9-byte limit for a preset"), "{e}");
        let missing = read_limited(&dir.path().join("none"), 9, "a preset").unwrap_err();
        assert_eq!(missing.io_kind(), Some(std::io::ErrorKind::NotFound));
    }

    #[test]
    fn references_stay_inside_the_folder() {
        let base = Path::new("/data/scene");
        assert_eq!(resolve_inside(base, "a.bin").unwrap(), base.join("a.bin"));
        assert_eq!(resolve_inside(base, "tex/../b.png").unwrap(), base.join("tex/../b.png"));
        assert!(resolve_inside(base, "../secret").unwrap_err().contains("outside"));
        assert!(resolve_inside(base, "a/../../b").unwrap_err().contains("outside"));
        assert!(resolve_inside(base, "/etc/passwd").unwrap_err().contains("absolute"));
        assert_eq!(escape("a\u{1b}[31mb"), "a\\u{1b}[31mb");
    }
}
