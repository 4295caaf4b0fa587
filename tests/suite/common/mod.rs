//! Helpers shared by the integration tests that drive the `verdant` binary on scene builds.
#![allow(dead_code)]

pub mod lod;

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

/// Runs verdant in `cwd`.
pub fn verdant_in(cwd: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_verdant")).current_dir(cwd).args(args).output().expect("run verdant")
}

pub fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

pub fn ok(o: &Output) {
    assert_eq!(o.status.code(), Some(0), "verdant failed:\n{}", text(o));
    assert!(!text(o).contains("panicked"), "{}", text(o));
}

pub fn write(dir: &Path, rel: &str, text: &str) -> PathBuf {
    let path = dir.join(rel);
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    fs::write(&path, text).unwrap();
    path
}

/// `h.r16` in `dir`: a 4×4 raw 16-bit heightmap (`--size 4x4`), the smallest terrain every
/// command can mesh.
pub fn write_small_r16(dir: &Path) -> PathBuf {
    let heights: Vec<u8> = (0..16u32).flat_map(|i| ((i * 977) as u16).to_le_bytes()).collect();
    let path = dir.join("h.r16");
    fs::write(&path, heights).unwrap();
    path
}

pub fn read_json(path: &Path) -> Value {
    let text = fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every file under `dir` (relative path with `/` → bytes), hidden folders included.
pub fn tree(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for entry in fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(root, &path, out);
            } else {
                let rel = path.strip_prefix(root).unwrap().to_string_lossy().replace('\\', "/");
                out.insert(rel, fs::read(&path).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

/// The summary row of `scene`, split into columns.
pub fn summary_row(o: &Output, scene: &str) -> Vec<String> {
    let t = text(o);
    t.lines()
        .find(|l| l.split_whitespace().next() == Some(scene))
        .unwrap_or_else(|| panic!("no summary row for {scene}:\n{t}"))
        .split_whitespace()
        .map(str::to_string)
        .collect()
}

pub fn timing_cached(scene_dir: &Path, stage: &str) -> bool {
    let r = read_json(&scene_dir.join("report.json"));
    r["timing"][stage]["cached"].as_bool().unwrap_or_else(|| panic!("report.json timing.{stage}.cached missing: {r}"))
}

/// A GLB of `json` and, when `bin` is not empty, a BIN chunk (both padded to 4 bytes).
pub fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut js = json.as_bytes().to_vec();
    while js.len() % 4 != 0 {
        js.push(b' ');
    }
    let mut bin = bin.to_vec();
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + js.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(js.len() as u32).to_le_bytes());
    out.extend_from_slice(&0x4E4F_534Au32.to_le_bytes());
    out.extend_from_slice(&js);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(&0x004E_4942u32.to_le_bytes());
        out.extend_from_slice(&bin);
    }
    out
}

/// Copies the plants entries of `from`'s stage cache into `to`'s (the other stages stay to be built).
pub fn share_plants_cache(from: &Path, to: &Path) {
    let target = to.join(".cache");
    fs::create_dir_all(&target).unwrap();
    for entry in fs::read_dir(from.join(".cache")).unwrap() {
        let entry = entry.unwrap();
        if entry.file_name().to_string_lossy().starts_with("plants-") {
            copy_dir(&entry.path(), &target.join(entry.file_name()));
        }
    }
}

pub fn copy_dir(from: &Path, to: &Path) {
    fs::create_dir_all(to).unwrap();
    for entry in fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &to.join(entry.file_name()));
        } else {
            fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
        }
    }
}

/// The surface vertices of a terrain scene's primitives (the highest at each x, z: skirts hang
/// below) with their `name` attribute.
pub fn surface_attribute(scene: &verdant::mesh::Scene, name: &str) -> Vec<([f32; 3], [f32; 4])> {
    let mut out = Vec::new();
    for p in scene.meshes.iter().flat_map(|m| &m.primitives) {
        let c = p.custom.iter().find(|c| c.name == name).unwrap_or_else(|| panic!("{name} on every primitive"));
        assert_eq!(c.values.len(), p.positions.len());
        let mut top = std::collections::HashMap::new();
        for q in &p.positions {
            let y = top.entry((q[0].to_bits(), q[2].to_bits())).or_insert(q[1]);
            *y = y.max(q[1]);
        }
        for (q, v) in p.positions.iter().zip(&c.values) {
            if q[1] >= top[&(q[0].to_bits(), q[2].to_bits())] {
                out.push((*q, *v));
            }
        }
    }
    out
}

/// report.json without its `timing` section; report.md without its `## Timing` section.
pub fn without_timing(rel: &str, bytes: &[u8]) -> Vec<u8> {
    if rel.ends_with("report.json") {
        let mut v: Value = serde_json::from_slice(bytes).unwrap();
        assert!(v.get("timing").is_some(), "{rel} has no timing section");
        v.as_object_mut().unwrap().remove("timing");
        serde_json::to_vec_pretty(&v).unwrap()
    } else if rel.ends_with("report.md") {
        let s = String::from_utf8(bytes.to_vec()).unwrap();
        let cut = s.find("## Timing").unwrap_or_else(|| panic!("{rel} has no timing section"));
        s.as_bytes()[..cut].to_vec()
    } else {
        bytes.to_vec()
    }
}

/// Asserts two scene trees are byte-identical, reports compared without their timing.
pub fn assert_same_tree(a: &Path, b: &Path) {
    let (ta, tb) = (tree(a), tree(b));
    assert_eq!(
        ta.keys().collect::<Vec<_>>(),
        tb.keys().collect::<Vec<_>>(),
        "{} and {} hold different files",
        a.display(),
        b.display()
    );
    for (rel, bytes) in &ta {
        assert!(
            without_timing(rel, bytes) == without_timing(rel, &tb[rel]),
            "{rel} differs between {} and {}",
            a.display(),
            b.display()
        );
    }
}
