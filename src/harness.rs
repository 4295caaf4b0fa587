//! Entry points that take untrusted bytes: one per input verdant reads from a user, each running
//! the same code a command runs on that input, at the default budgets. The fuzz targets (`fuzz/`)
//! are one line each around these, and the regression tests (`tests/suite/fuzz_regressions.rs`)
//! run them on the reproducers the fuzzers found and on seeded mutations of small valid inputs.
//!
//! Contract: an entry returns (whatever the bytes: errors are the expected outcome for most of
//! them) within a few seconds and bounded memory. It panics only where one of verdant's own
//! promises breaks on an input that was accepted: an accepted tree or model that does not export
//! and re-import cleanly, a terrain whose measured error exceeds its bound, a placement table that
//! does not read back as written. Those panics are bugs for the fuzzer to find.

use std::path::{Path, PathBuf};

use crate::heightfield::{self, DecodeOptions, Encoding};
use crate::validate::{self, Severity, ValidateOptions};

/// Maps up to this many samples are also meshed (TIN at the default bound) and measured.
pub const MESH_SAMPLES: usize = 64 * 64;

/// `.ls` bytes (dialect detected as `verdant tree` does): parse, expand, turtle and mesh at the
/// default budgets; an accepted tree must export to GLB and re-import without a validation error.
pub fn lsystem(data: &[u8]) {
    let path = Path::new("fuzz.ls");
    let Ok(parsed) = crate::lsystem::parse::parse_bytes(data, path, None) else { return };
    let options = crate::plants::tree::TreeOptions::default();
    let Ok(tree) = crate::plants::tree::build_tree(&parsed.system, &options) else { return };
    roundtrip_glb(&tree.scene, "the tree");
}

/// Heightmap bytes decoded with every encoding (an `.r16` as one row, as `--size N×1` would);
/// a decoded map holds only finite heights, and a small one meshes within its error bound.
pub fn heightmap(data: &[u8]) {
    let encodings = [
        Encoding::Auto,
        Encoding::Gray,
        Encoding::TerrainRgb,
        Encoding::Terrarium,
        Encoding::Hgt,
        Encoding::R16,
        Encoding::Float,
    ];
    for encoding in encodings {
        let opts = DecodeOptions { encoding, size: Some((data.len() / 2, 1)), ..DecodeOptions::default() };
        let Ok(decoded) = heightfield::decode(Path::new("fuzz.png"), data, &opts) else { continue };
        let hf = &decoded.heightfield;
        assert_eq!(hf.width * hf.height, hf.heights.len(), "{encoding}: a decoded map's size and samples disagree");
        assert!(hf.heights.iter().all(|h| h.is_finite()), "{encoding}: a decoded map holds a non-finite height");
        if hf.heights.len() <= MESH_SAMPLES {
            let opts = crate::terrain::tin::TinOptions::default();
            if let Ok(tin) = crate::terrain::tin::tin(hf, &opts) {
                let measured = crate::terrain::error::measure(hf, &tin.mesh);
                assert!(
                    tin.hit_triangle_limit || measured.max_error_m <= opts.max_error_m,
                    "{encoding}: the TIN's measured error {} m exceeds its bound {} m",
                    measured.max_error_m,
                    opts.max_error_m
                );
            }
        }
    }
}

/// Preset bytes: parsed and checked as `verdant preset check` does (paths resolve inside an empty
/// folder, so file inputs are reported missing).
pub fn preset(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        // a preset that is not UTF-8 is refused with a position by the loader
        let dir = Scratch::new("preset");
        let path = dir.write("fuzz.toml", data);
        assert!(crate::scene::preset::load_preset(&path).is_err(), "a preset that is not UTF-8 was accepted");
        return;
    };
    let path = std::env::temp_dir().join("verdant-fuzz-no-such-folder").join("fuzz.toml");
    if let Ok(p) = crate::scene::preset::parse_preset(text, &path) {
        let _ = crate::scene::preset::instance_estimates_over_limit(&p);
    }
}

/// An OBJ model with its material library and one texture, as `verdant mesh` reads them: the
/// bytes are `obj \0 mtl \0 texture` (missing parts are empty files), written as `model.obj`,
/// `model.mtl` and `texture.png` in a scratch folder. An accepted model must export to GLB and
/// re-import without a validation error.
pub fn obj(data: &[u8]) {
    let mut parts = data.splitn(3, |&b| b == 0);
    let (obj, mtl, texture) = (parts.next().unwrap_or(&[]), parts.next().unwrap_or(&[]), parts.next().unwrap_or(&[]));
    let dir = Scratch::new("obj");
    dir.write("model.mtl", mtl);
    dir.write("texture.png", texture);
    let path = dir.write("model.obj", obj);
    let options = crate::plants::mesh_asset::ObjOptions::default();
    if let Ok(model) = crate::plants::mesh_asset::load_obj(&path, &options) {
        roundtrip_glb(&model.scene, "the OBJ model");
    }
    // the validator's own OBJ reader on the same file
    let _ = validate::validate_file(&path, &ValidateOptions::default());
}

/// glTF bytes (GLB when they start with `glTF`, JSON otherwise) validated and re-imported as
/// `verdant validate` and the scene stages do, from a scratch folder holding nothing else.
pub fn gltf(data: &[u8]) {
    let dir = Scratch::new("gltf");
    let name = if data.starts_with(b"glTF") { "model.glb" } else { "model.gltf" };
    let path = dir.write(name, data);
    let _ = validate::validate_file(&path, &ValidateOptions::default());
    let _ = validate::read_scene(&path);
}

/// A placement table (CSV) read back as the view stage reads it; accepted rows must write out
/// and read back equal.
pub fn placements(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(rows) = crate::export::table::parse_placements_csv(text) else { return };
    let bytes = crate::export::table::placements_csv(&rows).expect("finite rows that were read must format");
    let again =
        crate::export::table::parse_placements_csv(std::str::from_utf8(&bytes).expect("the writer writes UTF-8"))
            .expect("a table the writer wrote must read back");
    assert!(again == rows, "a placement table does not read back as it was written");
    // the same rows as a binary table read back equal
    let bin = crate::export::table_bin::placements_bin(&rows).expect("finite rows that were read must write");
    let back =
        crate::export::table_bin::parse_placements_bin(&bin).expect("a binary table the writer wrote must read back");
    assert!(back == rows, "a binary placement table does not read back as it was written");
}

/// Any bytes as a binary placement table: an error or rows that write back to the same bytes.
pub fn placements_bin(data: &[u8]) {
    let Ok(rows) = crate::export::table_bin::parse_placements_bin(data) else { return };
    let bytes = crate::export::table_bin::placements_bin(&rows).expect("finite rows that were read must write");
    assert!(bytes == data, "a binary placement table does not write back to its bytes");
}

/// Writes `scene` as GLB, reads it back and validates it: the promise every writer makes.
fn roundtrip_glb(scene: &crate::mesh::Scene, what: &str) {
    let bytes =
        crate::export::gltf::to_glb(scene).unwrap_or_else(|e| panic!("{what} was built but does not export: {e}"));
    let dir = Scratch::new("roundtrip");
    let path = dir.write("out.glb", &bytes);
    let report = validate::validate_file(&path, &ValidateOptions::default())
        .unwrap_or_else(|e| panic!("{what} does not re-import: {e}"));
    if let Some(i) = report.issues.iter().find(|i| i.severity == Severity::Error) {
        panic!("{what} re-imports with a validation error: {}: {}", i.location, i.message);
    }
}

/// A folder of its own per call (process id and a counter), removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(what: &str) -> Scratch {
        use std::sync::atomic::{AtomicU64, Ordering};
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("verdant-harness-{what}-{}-{n}", std::process::id()));
        std::fs::create_dir_all(&dir)
            .unwrap_or_else(|e| panic!("cannot make the scratch folder {}: {e}", dir.display()));
        Scratch(dir)
    }

    fn write(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let path = self.0.join(name);
        std::fs::write(&path, bytes).unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
        path
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
