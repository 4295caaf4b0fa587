//! Content-hash cache of stage results: a stage whose inputs and settings hash to a key it has
//! seen before copies its files from `<out>/.cache/<stage>-<key>/` instead of recomputing them.
//!
//! An entry is a folder holding the stage's files under their scene-relative paths plus
//! `stage.json` (what the stage reported) and `files.json` (each file's size and sha256, so a
//! cached build need not hash them again for its manifest). Entries are written to a uniquely
//! named temporary folder and renamed into place, so a half-written entry is never read.
//!
//! Keys are salted by the crate version and each stage's algorithm version, so a newer binary
//! whose stage writes other bytes never reads an older entry. After each build, `used-by/<scene>.json`
//! names the entries the scene was built from: `verdant cache prune` keeps those of the scene folders
//! still present and removes the rest; `verdant cache clean` removes the whole cache.

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

/// [`sha256_hex`] of the file at `path` (at most `limit` bytes, as [`crate::input::read_limited`]
/// checks), read in pieces: the file is never held whole.
pub fn sha256_hex_of_file(path: &Path, limit: u64, what: &'static str) -> Result<String, crate::input::ReadError> {
    use std::io::Read;
    let (file, _) = crate::input::open_limited(path, limit, what)?;
    let (read, hash) = sha256_hex_of_reader(file.take(limit + 1))
        .map_err(|source| crate::input::ReadError::Io { path: path.to_path_buf(), source })?;
    if read > limit {
        return Err(crate::input::ReadError::TooLarge { path: path.to_path_buf(), size: read, limit, what });
    }
    Ok(hash)
}

/// [`sha256_hex_of_file`] of an input a build reads again and again (the heightmap: every stage
/// and unit whose key holds it asks, seven times in a merge), hashed once per process while the
/// file stays as it was: a hash is remembered by the file's device, inode, size and modification
/// time, and only for a file last modified over [`SETTLED`] before it was hashed (a file written
/// within the file system's clock tick could change again under the same time, as in Git's "racy
/// clean" case: such a file is hashed every time it is asked for).
pub fn sha256_hex_of_input(path: &Path, limit: u64, what: &'static str) -> Result<String, crate::input::ReadError> {
    use std::collections::HashMap;
    use std::sync::{Mutex, OnceLock};
    static KNOWN: OnceLock<Mutex<HashMap<(PathBuf, FileStamp), String>>> = OnceLock::new();
    let known = KNOWN.get_or_init(Default::default);
    let stamp = FileStamp::of(path);
    if let Some(stamp) = stamp {
        if let Some(hash) = known.lock().unwrap_or_else(|e| e.into_inner()).get(&(path.to_path_buf(), stamp)) {
            return Ok(hash.clone());
        }
    }
    let started = std::time::SystemTime::now();
    let hash = sha256_hex_of_file(path, limit, what)?;
    // (kept only when the file was the same before and after it was read, and settled before)
    if let Some(stamp) = stamp.filter(|s| Some(*s) == FileStamp::of(path) && s.settled_before(started)) {
        known.lock().unwrap_or_else(|e| e.into_inner()).insert((path.to_path_buf(), stamp), hash.clone());
    }
    Ok(hash)
}

/// How long before it is hashed a file must have been last modified for its hash to be
/// remembered ([`sha256_hex_of_input`]): well over any file system's time stamp granularity.
const SETTLED: std::time::Duration = std::time::Duration::from_secs(2);

/// What tells one version of a file from another without reading it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct FileStamp {
    device: u64,
    inode: u64,
    len: u64,
    modified: std::time::SystemTime,
}

impl FileStamp {
    fn of(path: &Path) -> Option<FileStamp> {
        let meta = fs::metadata(path).ok()?;
        #[cfg(unix)]
        let (device, inode) = {
            use std::os::unix::fs::MetadataExt;
            (meta.dev(), meta.ino())
        };
        #[cfg(not(unix))]
        let (device, inode) = (0, 0);
        Some(FileStamp { device, inode, len: meta.len(), modified: meta.modified().ok()? })
    }

    fn settled_before(&self, time: std::time::SystemTime) -> bool {
        time.duration_since(self.modified).is_ok_and(|age| age > SETTLED)
    }
}

/// The sha256 of every file of the cache entry folder `entry`, by its path inside the entry
/// (`/`-separated): what a shard records of each entry it built and a merge checks the entry it
/// is given against (a shard folder copied between machines, damaged on the way, is refused
/// instead of merged into a wrong scene). The files are hashed in parallel, read in pieces.
pub fn entry_digests(entry: &Path) -> io::Result<BTreeMap<String, String>> {
    use rayon::prelude::*;
    let mut files = Vec::new();
    let mut stack = vec![entry.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for item in fs::read_dir(&dir)? {
            let item = item?;
            if item.file_type()?.is_dir() {
                stack.push(item.path());
            } else {
                files.push(item.path());
            }
        }
    }
    files
        .par_iter()
        .map(|path| {
            let rel = path.strip_prefix(entry).unwrap_or(path).to_string_lossy().replace('\\', "/");
            let (_, hash) = sha256_hex_of_reader(fs::File::open(path)?)?;
            Ok((rel, hash))
        })
        .collect()
}

/// `src` hard-linked at `dst`, or copied there where a link is not possible (another file
/// system); the bytes at `dst`. A file already named `dst` is unlinked first, never written
/// through (it may be a link to `src` or into another entry: a copy onto it would truncate both).
fn link_or_copy(src: &Path, dst: &Path) -> io::Result<u64> {
    if fs::symlink_metadata(dst).is_ok() {
        fs::remove_file(dst)?;
    }
    match fs::hard_link(src, dst) {
        Ok(()) => Ok(fs::metadata(dst)?.len()),
        Err(_) => {
            // (`create_new`: a copy never truncates a file that is there, least of all `src`)
            let mut from = fs::File::open(src)?;
            let mut to = fs::OpenOptions::new().write(true).create_new(true).open(dst)?;
            io::copy(&mut from, &mut to)
        }
    }
}

/// The bytes read from `reader` to its end and their [`sha256_hex`], in 1 MiB pieces.
fn sha256_hex_of_reader(mut reader: impl io::Read) -> io::Result<(u64, String)> {
    let mut hasher = Sha256::new();
    let mut buffer = vec![0u8; 1 << 20];
    let mut read = 0u64;
    loop {
        let n = match reader.read(&mut buffer) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        read += n as u64;
        hasher.update(&buffer[..n]);
    }
    Ok((read, hex(&hasher.finalize())))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Incremental key: feed every input and setting a stage depends on.
#[derive(Default)]
pub struct KeyBuilder(Sha256);

impl KeyBuilder {
    /// A key for `stage` whose output algorithm is at `algorithm_version`: entries of an older
    /// version (or another crate version) are never served.
    pub fn new(stage: &str, algorithm_version: u32) -> Self {
        let mut k = KeyBuilder(Sha256::new());
        k.add(stage.as_bytes());
        k.add(env!("CARGO_PKG_VERSION").as_bytes());
        k.add(&algorithm_version.to_le_bytes());
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

/// What [`Cache::prune`] or [`Cache::clean`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CacheCleanup {
    pub entries_removed: usize,
    pub entries_kept: usize,
    /// Bytes of the removed entries and leftover temporary folders.
    pub bytes_freed: u64,
}

/// Whether process `pid` is running (Linux: /proc; elsewhere every process counts as running, so
/// nothing another build may still be writing is removed).
pub fn process_alive(pid: u32) -> bool {
    if cfg!(target_os = "linux") {
        Path::new("/proc").join(pid.to_string()).exists()
    } else {
        true
    }
}

/// The process id a temporary name ends with (`….tmp-<pid>-<n>`, `….building-<pid>`, `….old-<pid>`).
pub fn temp_owner(name: &str, marker: &str) -> Option<u32> {
    let rest = &name[name.find(marker)? + marker.len()..];
    rest.split('-').next()?.parse().ok()
}

fn size_of(path: &Path) -> u64 {
    let Ok(meta) = fs::symlink_metadata(path) else { return 0 };
    if !meta.is_dir() {
        return meta.len();
    }
    fs::read_dir(path).map(|d| d.flatten().map(|e| size_of(&e.path())).sum()).unwrap_or(0)
}

/// An entry folder's name: `<stage>-<32 hex digits>`.
fn is_entry_name(name: &str) -> bool {
    name.rsplit_once('-').is_some_and(|(stage, key)| {
        !stage.is_empty() && !stage.starts_with('.') && key.len() == 32 && key.bytes().all(|b| b.is_ascii_hexdigit())
    })
}

impl Cache {
    pub fn new(out_dir: &Path) -> Self {
        Cache { root: out_dir.join(".cache") }
    }

    fn entry(&self, stage: &str, key: &str) -> PathBuf {
        self.root.join(Self::entry_name(stage, key))
    }

    /// The folder name of `stage`'s entry under `key`.
    pub fn entry_name(stage: &str, key: &str) -> String {
        format!("{stage}-{key}")
    }

    fn used_by(&self) -> PathBuf {
        self.root.join("used-by")
    }

    /// Records the entries scene `scene` was just built from (what [`Cache::prune`] keeps).
    pub fn record_scene(&self, scene: &str, entries: &[String]) -> io::Result<()> {
        let dir = self.used_by();
        fs::create_dir_all(&dir)?;
        let text = serde_json::to_string_pretty(entries).map_err(io::Error::other)?;
        crate::export::write_atomic(&dir.join(format!("{scene}.json")), text.as_bytes()).map_err(io::Error::other)
    }

    /// Removes every entry that no scene folder of `out_dir` was last built from, the records of
    /// scenes whose folder is gone, and temporary folders of processes that are no longer running.
    pub fn prune(&self, out_dir: &Path) -> io::Result<CacheCleanup> {
        let mut done = CacheCleanup::default();
        if !self.root.is_dir() {
            return Ok(done);
        }
        let mut keep = std::collections::BTreeSet::new();
        if let Ok(records) = fs::read_dir(self.used_by()) {
            for record in records.flatten() {
                let path = record.path();
                let scene = path.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
                let entries: Option<Vec<String>> =
                    fs::read_to_string(&path).ok().and_then(|t| serde_json::from_str(&t).ok());
                match entries {
                    Some(entries) if out_dir.join(&scene).join("manifest.json").is_file() => keep.extend(entries),
                    _ => {
                        let _ = fs::remove_file(&path);
                    }
                }
            }
        }
        for item in fs::read_dir(&self.root)?.flatten() {
            let name = item.file_name().to_string_lossy().to_string();
            let path = item.path();
            let remove = if is_entry_name(&name) {
                !keep.contains(&name)
            } else if name.starts_with('.') {
                temp_owner(&name, ".tmp-").is_some_and(|pid| !process_alive(pid))
            } else {
                false
            };
            if remove {
                done.bytes_freed += size_of(&path);
                fs::remove_dir_all(&path)?;
                done.entries_removed += usize::from(is_entry_name(&name));
            } else if is_entry_name(&name) {
                done.entries_kept += 1;
            }
        }
        Ok(done)
    }

    /// Removes the whole cache folder.
    pub fn clean(&self) -> io::Result<CacheCleanup> {
        if !self.root.exists() {
            return Ok(CacheCleanup::default());
        }
        let entries =
            fs::read_dir(&self.root)?.flatten().filter(|e| is_entry_name(&e.file_name().to_string_lossy())).count();
        let bytes_freed = size_of(&self.root);
        fs::remove_dir_all(&self.root)?;
        Ok(CacheCleanup { entries_removed: entries, entries_kept: 0, bytes_freed })
    }

    /// A temporary folder name for entry `name`, `.<name>.tmp-<pid>-<n><ns>`: unique per process
    /// and call (threads of one batch may store the same key at once), and with the clock's
    /// nanoseconds across containers whose processes share a pid (1) and a cache. [`Cache::prune`]
    /// removes those of processes that are gone.
    fn temp_for(&self, name: &str) -> PathBuf {
        static SERIAL: AtomicU64 = AtomicU64::new(0);
        let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.subsec_nanos());
        self.root.join(format!(
            ".{name}.tmp-{}-{}{nanos:09}",
            std::process::id(),
            SERIAL.fetch_add(1, Ordering::Relaxed)
        ))
    }

    /// Brings the entry folder `src` of another cache (a shard's) into this one under its own name:
    /// linked (or copied) under a temporary name and renamed into place, so a stopped import never
    /// leaves half an entry. An entry already here is kept (same name, same contents); another
    /// process putting it in place first is not an error. Returns whether it was brought.
    pub fn import(&self, src: &Path) -> io::Result<bool> {
        let name = src.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        let dst = self.root.join(name);
        if dst.join("stage.json").is_file() {
            return Ok(false);
        }
        fs::create_dir_all(&self.root)?;
        let tmp = self.temp_for(name);
        fn walk(from: &Path, to: &Path) -> io::Result<()> {
            fs::create_dir_all(to)?;
            for item in fs::read_dir(from)? {
                let item = item?;
                let (s, d) = (item.path(), to.join(item.file_name()));
                if item.file_type()?.is_dir() {
                    walk(&s, &d)?;
                } else if fs::hard_link(&s, &d).is_err() {
                    fs::copy(&s, &d)?;
                }
            }
            Ok(())
        }
        let result = walk(src, &tmp).and_then(|()| fs::rename(&tmp, &dst));
        if result.is_err() {
            let _ = fs::remove_dir_all(&tmp);
        }
        match result {
            Ok(()) => Ok(true),
            Err(_) if dst.join("stage.json").is_file() => Ok(false),
            Err(e) => Err(e),
        }
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
    pub fn store(
        &self,
        stage: &str,
        key: &str,
        scene_dir: &Path,
        files: &[PathBuf],
        stage_json: &str,
    ) -> io::Result<FileHashes> {
        self.store_entry(stage, key, scene_dir, files, stage_json, None)
    }

    /// Stores an entry of no scene files: `stage_json` and `blob` (written as `blob.bin` in the
    /// entry folder, e.g. arrays too large for JSON), replacing one of the same key.
    pub fn store_blob(&self, stage: &str, key: &str, stage_json: &str, blob: &[u8]) -> io::Result<()> {
        self.store_entry(stage, key, Path::new(""), &[], stage_json, Some(blob)).map(|_| ())
    }

    /// An entry's `blob.bin` (see [`Cache::store_blob`]).
    pub fn read_blob(entry: &Path) -> io::Result<Vec<u8>> {
        fs::read(entry.join("blob.bin"))
    }

    fn store_entry(
        &self,
        stage: &str,
        key: &str,
        scene_dir: &Path,
        files: &[PathBuf],
        stage_json: &str,
        blob: Option<&[u8]>,
    ) -> io::Result<FileHashes> {
        let dir = self.entry(stage, key);
        fs::create_dir_all(&self.root)?;
        let tmp = self.temp_for(&Self::entry_name(stage, key));
        let mut hashes = FileHashes::new();
        let result = (|| {
            use rayon::prelude::*;
            fs::create_dir_all(&tmp)?;
            let mut linked: Vec<(String, PathBuf, PathBuf, u64)> = Vec::with_capacity(files.len());
            let mut seen = std::collections::HashSet::with_capacity(files.len());
            for rel in files {
                // a file named twice is stored once (a copy onto its own link would empty it)
                let key = rel_key(rel);
                if !seen.insert(key.clone()) {
                    continue;
                }
                let (src, dst) = (scene_dir.join(rel), tmp.join(rel));
                if let Some(parent) = dst.parent() {
                    fs::create_dir_all(parent)?;
                }
                // a hard link, as [`Cache::restore`] makes the other way (every writer replaces
                // files by rename, so no build writes through it into the entry): a scene's
                // outputs are not read into memory and written again (scene.glb reaches hundreds
                // of MB); a copy where links are not possible (another file system)
                let len = link_or_copy(&src, &dst)?;
                linked.push((key, src, dst, len));
            }
            // hashed in parallel (a world's view stage stores about 1 GB of scene files)
            let hashed: Vec<io::Result<(String, (u64, String))>> = linked
                .par_iter()
                .map(|(key, src, dst, len)| {
                    let (read, hash) = sha256_hex_of_reader(fs::File::open(dst)?)?;
                    if read != *len {
                        return Err(io::Error::other(format!("{} changed while it was stored", src.display())));
                    }
                    Ok((key.clone(), (*len, hash)))
                })
                .collect();
            for h in hashed {
                let (key, value) = h?;
                hashes.insert(key, value);
            }
            let table = serde_json::to_string(&hashes).map_err(io::Error::other)?;
            fs::write(tmp.join("files.json"), table)?;
            if let Some(blob) = blob {
                fs::write(tmp.join("blob.bin"), blob)?;
            }
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
        let table: FileHashes =
            serde_json::from_str(&fs::read_to_string(entry.join("files.json"))?).map_err(io::Error::other)?;
        let mut hashes = FileHashes::new();
        for rel in files {
            let key = rel_key(rel);
            let recorded =
                table.get(&key).ok_or_else(|| io::Error::other(format!("{key} is not recorded in the entry")))?;
            if hashes.contains_key(&key) {
                continue; // named twice: restored once
            }
            let dst = scene_dir.join(rel);
            if let Some(parent) = dst.parent() {
                fs::create_dir_all(parent)?;
            }
            // a hard link costs nothing whatever the size (placement tables reach hundreds of MB);
            // copy where links are not possible (another file system). Every writer replaces
            // files by rename, so rebuilding never writes through a link into the cache.
            let copied = link_or_copy(&entry.join(rel), &dst)?;
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
            let mut k = KeyBuilder::new(stage, 1);
            for p in parts {
                k.add(p.as_bytes());
            }
            k.finish()
        };
        assert_eq!(key("terrain", &["ab", "c"]), key("terrain", &["ab", "c"]));
        assert_ne!(key("terrain", &["ab", "c"]), key("terrain", &["a", "bc"]));
        assert_ne!(key("terrain", &["x"]), key("preview", &["x"]));
        let versioned = |v: u32| KeyBuilder::new("terrain", v).finish();
        assert_ne!(versioned(1), versioned(2), "a bumped algorithm version gives new keys");
        assert_eq!(sha256_hex(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    }

    #[test]
    fn an_inputs_hash_is_remembered_only_while_the_file_stays_as_it_was_and_settled() {
        use std::time::{Duration, SystemTime};
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.png");
        let put = |bytes: &[u8], modified: SystemTime| {
            fs::write(&path, bytes).unwrap();
            fs::File::options().write(true).open(&path).unwrap().set_modified(modified).unwrap();
        };
        let hash = || sha256_hex_of_input(&path, 1 << 20, "a heightmap").unwrap();
        // a file just written: hashed every time, even rewritten under the same size and time
        let now = SystemTime::now();
        put(b"aaaa", now);
        assert_eq!(hash(), sha256_hex(b"aaaa"));
        put(b"bbbb", now);
        assert_eq!(hash(), sha256_hex(b"bbbb"), "a file of this clock tick is never taken from memory");
        // a settled file: a new time is a new version
        let hour_ago = now - Duration::from_secs(3600);
        put(b"cccc", hour_ago);
        assert_eq!(hash(), sha256_hex(b"cccc"));
        put(b"dddd", hour_ago - Duration::from_secs(1));
        assert_eq!(hash(), sha256_hex(b"dddd"));
        // ... and the same device, inode, size and time the same version: read once
        put(b"eeee", hour_ago - Duration::from_secs(1));
        assert_eq!(hash(), sha256_hex(b"dddd"), "a settled file's hash is remembered by its stamp");
        // errors are the file's
        let missing = sha256_hex_of_input(&dir.path().join("none.png"), 1 << 20, "a heightmap").unwrap_err();
        assert!(missing.to_string().contains("none.png"), "{missing}");
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

    /// Files are stored and restored by link: a file named twice (two species writing one
    /// name) is stored once, whole, and neither it nor the scene's file is emptied; a restore
    /// onto a name already there replaces the name, not the bytes behind it.
    #[test]
    fn a_file_named_twice_or_restored_over_a_name_keeps_its_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("scene");
        fs::create_dir_all(scene.join("atlases")).unwrap();
        fs::write(scene.join("atlases/g_blade.png"), b"blade bytes").unwrap();
        let cache = Cache::new(dir.path());
        let files = vec![PathBuf::from("atlases/g_blade.png"), PathBuf::from("atlases/g_blade.png")];
        cache.store("plants", "k", &scene, &files, "{}").unwrap();
        assert_eq!(fs::read(scene.join("atlases/g_blade.png")).unwrap(), b"blade bytes");
        let (_, entry) = cache.lookup("plants", "k").unwrap();
        assert_eq!(fs::read(entry.join("atlases/g_blade.png")).unwrap(), b"blade bytes");
        // restored over a name that is a link to another file: that file keeps its bytes
        let other = dir.path().join("other");
        fs::create_dir_all(other.join("atlases")).unwrap();
        fs::write(dir.path().join("elsewhere.png"), b"someone else's").unwrap();
        fs::hard_link(dir.path().join("elsewhere.png"), other.join("atlases/g_blade.png")).unwrap();
        let hashes = Cache::restore(&entry, &other, &files).unwrap();
        assert_eq!(hashes["atlases/g_blade.png"], (11, sha256_hex(b"blade bytes")));
        assert_eq!(fs::read(other.join("atlases/g_blade.png")).unwrap(), b"blade bytes");
        assert_eq!(fs::read(dir.path().join("elsewhere.png")).unwrap(), b"someone else's");
    }

    #[test]
    fn prune_keeps_what_present_scenes_were_built_from() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        let scene = out.join("work");
        fs::create_dir_all(&scene).unwrap();
        fs::write(scene.join("a.png"), b"png").unwrap();
        let cache = Cache::new(out);
        let files = vec![PathBuf::from("a.png")];
        let key = |n: u32| KeyBuilder::new("preview", n).finish();
        for n in 1..=3 {
            cache.store("preview", &key(n), &scene, &files, "{}").unwrap();
        }
        // scene `meadow` is present and was built from entry 1; `gone` (entry 2) has no folder
        fs::create_dir_all(out.join("meadow")).unwrap();
        fs::write(out.join("meadow/manifest.json"), b"{}").unwrap();
        cache.record_scene("meadow", &[Cache::entry_name("preview", &key(1))]).unwrap();
        cache.record_scene("gone", &[Cache::entry_name("preview", &key(2))]).unwrap();
        // a temporary entry of a process that is gone, and one of this (running) process
        let dead = cache.root.join(".preview-x.tmp-4294967295-0");
        let live = cache.root.join(format!(".preview-y.tmp-{}-0", std::process::id()));
        fs::create_dir_all(&dead).unwrap();
        fs::create_dir_all(&live).unwrap();
        let done = cache.prune(out).unwrap();
        assert_eq!((done.entries_removed, done.entries_kept), (2, 1));
        assert!(done.bytes_freed > 0);
        assert!(cache.lookup("preview", &key(1)).is_some());
        assert!(cache.lookup("preview", &key(2)).is_none() && cache.lookup("preview", &key(3)).is_none());
        assert!(!dead.exists() && live.exists());
        assert!(!cache.used_by().join("gone.json").exists());
        // pruning again removes nothing; clean removes everything
        assert_eq!(cache.prune(out).unwrap().entries_removed, 0);
        assert_eq!(cache.clean().unwrap().entries_removed, 1);
        assert!(!cache.root.exists());
        assert_eq!(cache.clean().unwrap(), CacheCleanup::default());
    }

    #[test]
    fn temporary_names_tell_their_process() {
        assert_eq!(temp_owner(".terrain-abc.tmp-123-4", ".tmp-"), Some(123));
        assert_eq!(temp_owner(".demo.building-77", ".building-"), Some(77));
        assert_eq!(temp_owner(".demo.building-x", ".building-"), None);
        assert!(process_alive(std::process::id()));
        assert!(is_entry_name(&Cache::entry_name("scatter", &KeyBuilder::new("scatter", 2).finish())));
        assert!(!is_entry_name("used-by") && !is_entry_name(".scatter-0123.tmp-1-2"));
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
