//! Content-hash cache of stage results: a stage whose inputs and settings hash to a key it has
//! seen before copies its files from `<out>/.cache/<stage>-<key>/` instead of recomputing them.
//!
//! An entry is a folder holding the stage's files under their scene-relative paths plus
//! `stage.json` (what the stage reported) and `files.json` (each file's size and sha256, so a
//! cached build need not hash them again for its manifest). Entries are written to a uniquely
//! named temporary folder and renamed into place, so a half-written entry is never read.

use std::collections::BTreeMap;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use sha2::{Digest, Sha256};

/// Hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Incremental key: feed every input and setting a stage depends on.
#[derive(Default)]
pub struct KeyBuilder(Sha256);

impl KeyBuilder {
    pub fn new(stage: &str) -> Self {
        let mut k = KeyBuilder(Sha256::new());
        k.add(stage.as_bytes());
        k.add(env!("CARGO_PKG_VERSION").as_bytes());
        k
    }
    /// Adds a length-prefixed field, so ("ab", "c") and ("a", "bc") differ.
    pub fn add(&mut self, bytes: &[u8]) -> &mut Self {
        self.0.update((bytes.len() as u64).to_le_bytes());
        self.0.update(bytes);
        self
    }
    pub fn finish(self) -> String {
        hex(&self.0.finalize())[..32].to_string()
    }
}

/// Size and sha256 of files, by scene-relative path with `/` separators.
pub type FileHashes = BTreeMap<String, (u64, String)>;

/// The `/`-separated form of a scene-relative path, as manifests and hash tables name files.
pub fn rel_key(rel: &Path) -> String {
    rel.components().map(|c| c.as_os_str().to_string_lossy()).collect::<Vec<_>>().join("/")
}

pub struct Cache {
    pub root: PathBuf,
}

impl Cache {
    pub fn new(out_dir: &Path) -> Self {
        Cache { root: out_dir.join(".cache") }
    }

    fn entry(&self, stage: &str, key: &str) -> PathBuf {
        self.root.join(format!("{stage}-{key}"))
    }

    /// The stored `stage.json` text and the entry folder, when present.
    pub fn lookup(&self, stage: &str, key: &str) -> Option<(String, PathBuf)> {
        let dir = self.entry(stage, key);
        let text = fs::read_to_string(dir.join("stage.json")).ok()?;
        Some((text, dir))
    }

    /// Stores `files` (scene-relative paths, read from `scene_dir`) and the stage report,
    /// replacing an entry of the same key (which a failed lookup showed to be damaged).
    /// Returns the files' sizes and hashes.
    pub fn store(&self, stage: &str, key: &str, scene_dir: &Path, files: &[PathBuf], stage_json: &str) -> io::Result<FileHashes> {
        static SERIAL: AtomicU64 = AtomicU64::new(0);
        let dir = self.entry(stage, key);
        fs::create_dir_all(&self.root)?;
        // unique per process and call: threads of one batch may store the same key at once
        let tmp = self.root.join(format!(".{stage}-{key}.tmp-{}-{}", std::process::id(), SERIAL.fetch_add(1, Ordering::Relaxed)));
        let mut hashes = FileHashes::new();
        let result = (|| {
            for rel in files {
                let bytes = fs::read(scene_dir.join(rel))?;
                let dst = tmp.join(rel);
                if let Some(parent) = dst.parent() {
                    fs::create_dir_all(parent)?;
                }
                fs::write(dst, &bytes)?;
                hashes.insert(rel_key(rel), (bytes.len() as u64, sha256_hex(&bytes)));
            }
            let table = serde_json::to_string(&hashes).map_err(io::Error::other)?;
            fs::write(tmp.join("files.json"), table)?;
            fs::write(tmp.join("stage.json"), stage_json)?;
            // a store follows a failed lookup: an entry already there is damaged, replace it
            if dir.exists() {
                fs::remove_dir_all(&dir)?;
            }
            fs::rename(&tmp, &dir)
        })();
        if result.is_err() {
            let _ = fs::remove_dir_all(&tmp);
        }
        // another thread may have put an equal entry in place meanwhile: that is fine
        match result {
            Ok(()) => Ok(hashes),
            Err(_) if dir.join("stage.json").exists() => Ok(hashes),
            Err(e) => Err(e),
        }
    }

    /// Links (or copies) an entry's files into `scene_dir`; returns their recorded sizes and
    /// hashes. Fails when a file is missing or its size differs from the record (a damaged entry).
    pub fn restore(entry: &Path, scene_dir: &Path, files: &[PathBuf]) -> io::Result<FileHashes> {
        let table: FileHashes = serde_json::from_str(&fs::read_to_string(entry.join("files.json"))?).map_err(io::Error::other)?;
        let mut hashes = FileHashes::new();
        for rel in files {
            let key = rel_key(rel);
            let recorded = table.get(&key).ok_or_else(|| io::Error::other(format!("{key} is not recorded in the entry")))?;
            let dst = scene_dir.join(rel);
            if let Some(parent) = dst.parent() {
                fs::create_dir_all(parent)?;
            }
            // a hard link costs nothing whatever the size (placement tables reach hundreds of MB);
            // copy where links are not possible (another file system). Every writer replaces
            // files by rename, so rebuilding never writes through a link into the cache.
            let src = entry.join(rel);
            let copied = match fs::hard_link(&src, &dst) {
                Ok(()) => fs::metadata(&dst)?.len(),
                Err(_) => fs::copy(&src, &dst)?,
            };
            if copied != recorded.0 {
                return Err(io::Error::other(format!("{key} has {copied} bytes, the entry recorded {}", recorded.0)));
            }
            hashes.insert(key, recorded.clone());
        }
        Ok(hashes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_separate_fields_and_stages() {
        let key = |stage: &str, parts: &[&str]| {
            let mut k = KeyBuilder::new(stage);
            for p in parts {
                k.add(p.as_bytes());
            }
            k.finish()
        };
        assert_eq!(key("terrain", &["ab", "c"]), key("terrain", &["ab", "c"]));
        assert_ne!(key("terrain", &["ab", "c"]), key("terrain", &["a", "bc"]));
        assert_ne!(key("terrain", &["x"]), key("preview", &["x"]));
        assert_eq!(sha256_hex(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    }

    #[test]
    fn store_then_restore() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("scene");
        fs::create_dir_all(scene.join("terrain")).unwrap();
        fs::write(scene.join("terrain/a.glb"), b"glb").unwrap();
        let cache = Cache::new(dir.path());
        assert!(cache.lookup("terrain", "k1").is_none());
        let files = vec![PathBuf::from("terrain/a.glb")];
        cache.store("terrain", "k1", &scene, &files, "{\"x\":1}").unwrap();
        let (json, entry) = cache.lookup("terrain", "k1").unwrap();
        assert_eq!(json, "{\"x\":1}");
        let other = dir.path().join("other");
        Cache::restore(&entry, &other, &files).unwrap();
        assert_eq!(fs::read(other.join("terrain/a.glb")).unwrap(), b"glb");
    }

    #[test]
    fn a_damaged_entry_is_replaced_by_the_next_store() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("scene");
        fs::create_dir_all(&scene).unwrap();
        fs::write(scene.join("a.png"), b"png").unwrap();
        let cache = Cache::new(dir.path());
        let files = vec![PathBuf::from("a.png")];
        cache.store("preview", "k", &scene, &files, "{}").unwrap();
        let (_, entry) = cache.lookup("preview", "k").unwrap();
        fs::remove_file(entry.join("a.png")).unwrap();
        assert!(Cache::restore(&entry, &dir.path().join("x"), &files).is_err());
        cache.store("preview", "k", &scene, &files, "{}").unwrap();
        let (_, entry) = cache.lookup("preview", "k").unwrap();
        Cache::restore(&entry, &dir.path().join("y"), &files).unwrap();
        assert_eq!(fs::read(dir.path().join("y/a.png")).unwrap(), b"png");
    }
}
