//! A terrain meshed in bands bakes its material layers band by band (src/scene/band_layers.rs),
//! each band's rows kept in a cache entry of their own beside its meshes: a species edit re-bakes
//! every band's layers from its kept meshes (no band is meshed again) and writes the terrain a
//! build without any cache writes; a damaged layers entry is baked again, the same bytes.

use std::fs;
use std::path::Path;

use crate::common::*;

/// fbm 1025² with 2 m cells, chunks of 128 cells: three bands (rows 0-384, 384-768, 768-1024);
/// grass on gentle slopes (the soil layer and `_SURFACE` follow it).
fn preset(max_slope: f64) -> String {
    format!(
        "[scene]\nname = \"bl\"\nseed = 3\nformats = [\"glb\"]\n\n[terrain]\n\
         procedural = {{ kind = \"ridged\", size = 1025, seed = 5, relief = 140.0 }}\n\
         cell_size = 2.0\nmax_error = 0.5\nchunk = 128\nlods = [0.5, 2.0]\n\n[scatter]\ntile = 256.0\n\n\
         [[species]]\nname = \"grass\"\nkind = \"grass\"\nplacement = \"jittered\"\nmax_density = 0.01\n\
         slope = [0.0, {max_slope}]\n"
    )
}

/// The cache's entries whose names start with `prefix`, each with its blob's bytes.
fn entries(out: &Path, prefix: &str) -> Vec<(String, Vec<u8>)> {
    let mut found: Vec<(String, Vec<u8>)> = fs::read_dir(out.join(".cache"))
        .unwrap()
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().to_string();
            let key = name.strip_prefix(prefix)?;
            (key.len() == 32 && key.bytes().all(|b| b.is_ascii_hexdigit()))
                .then(|| (name.clone(), fs::read(e.path().join("blob.bin")).unwrap()))
        })
        .collect();
    found.sort();
    found
}

fn terrain_files(scene: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut t = tree(scene);
    t.retain(|k, _| k.starts_with("terrain/"));
    t
}

#[test]
fn a_species_edit_rebakes_each_bands_layers_from_its_kept_meshes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p.toml", &preset(30.0));
    ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "o"]));
    let out = d.join("o");
    let pieces = entries(&out, "terrain-band-");
    let layers = entries(&out, "terrain-band-layers-");
    assert_eq!(layers.len(), 3, "each band keeps its layer rows");
    assert_eq!(pieces.len(), 3, "and its meshes");
    let piece_times: Vec<_> = pieces
        .iter()
        .map(|(n, _)| fs::metadata(out.join(".cache").join(n).join("blob.bin")).unwrap().modified().unwrap())
        .collect();
    let soil_before = fs::read(out.join("bl/terrain/terrain_layers_1.png")).unwrap();

    // the grass grows on gentler slopes: the soil layer and `_SURFACE` change, the meshes do not
    write(d, "p.toml", &preset(12.0));
    ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "o"]));
    assert!(!timing_cached(&out.join("bl"), "terrain"));
    assert_eq!(entries(&out, "terrain-band-"), pieces, "the bands' meshes are the same entries");
    for ((n, _), before) in pieces.iter().zip(&piece_times) {
        let now = fs::metadata(out.join(".cache").join(n).join("blob.bin")).unwrap().modified().unwrap();
        assert_eq!(&now, before, "band {n} was meshed and stored again");
    }
    let rebaked = entries(&out, "terrain-band-layers-");
    assert_eq!(rebaked.len(), 6, "three new layer entries beside the old ones");
    assert_ne!(fs::read(out.join("bl/terrain/terrain_layers_1.png")).unwrap(), soil_before);
    // byte for byte what a build without any cache writes
    ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "fresh"]));
    let expected = terrain_files(&d.join("fresh/bl"));
    assert_eq!(terrain_files(&out.join("bl")), expected, "the kept meshes changed the terrain");

    // a layers entry cut short: baked again from the band's rows, the same files, entry replaced
    let fresh_layers = entries(&d.join("fresh"), "terrain-band-layers-");
    let (name, bytes) = &fresh_layers[1];
    let blob = d.join("fresh/.cache").join(name).join("blob.bin");
    fs::write(&blob, &bytes[..bytes.len() / 2]).unwrap();
    let terrain_entry = fs::read_dir(d.join("fresh/.cache"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            let n = p.file_name().unwrap().to_string_lossy().to_string();
            n.strip_prefix("terrain-").is_some_and(|k| k.len() == 32 && k.bytes().all(|b| b.is_ascii_hexdigit()))
        })
        .expect("the terrain stage's entry");
    fs::remove_dir_all(terrain_entry).unwrap();
    ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "fresh"]));
    assert_eq!(terrain_files(&d.join("fresh/bl")), expected);
    assert_eq!(&fs::read(&blob).unwrap(), bytes, "the damaged entry was replaced");
}

/// The cache's stage entry `<stage>-<32 hex>`.
fn stage_entry(out: &Path, stage: &str) -> std::path::PathBuf {
    fs::read_dir(out.join(".cache"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            let n = p.file_name().unwrap().to_string_lossy().to_string();
            n.strip_prefix(stage)
                .and_then(|k| k.strip_prefix('-'))
                .is_some_and(|k| k.len() == 32 && k.bytes().all(|b| b.is_ascii_hexdigit()))
        })
        .unwrap_or_else(|| panic!("no {stage} entry"))
}

#[test]
fn the_density_maps_from_the_terrains_cover_equal_those_weighed_by_the_scatter_stage() {
    // a fresh terrain stage hands its ground cover on, and the scatter stage writes the density
    // maps of the species snow does not thin from it; with the terrain served from the cache the
    // scatter stage weighs them itself: the same bytes, banded map or not
    for (name, text) in [
        ("banded", preset(30.0)),
        ("whole", preset(30.0).replace("size = 1025", "size = 257").replace("chunk = 128\n", "")),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        write(d, "p.toml", &text);
        ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "o"]));
        let scene = d.join("o/bl");
        let density = scene.join("placements/density_0.png");
        let first = fs::read(&density).unwrap();
        assert!(!timing_cached(&scene, "terrain"));
        // the scatter stage again, the terrain from the cache
        fs::remove_dir_all(stage_entry(&d.join("o"), "scatter")).unwrap();
        fs::remove_file(&density).unwrap();
        ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "o"]));
        assert!(timing_cached(&scene, "terrain") && !timing_cached(&scene, "scatter"), "{name}");
        assert_eq!(fs::read(&density).unwrap(), first, "{name}: the density maps differ");
        // (and not a map of nothing: the grass grows on part of the terrain only)
        let img = image::load_from_memory(&first).unwrap().into_rgba8();
        let grass: Vec<u8> = img.pixels().map(|p| p[0]).collect();
        assert!(grass.iter().any(|&v| v == 255) && grass.iter().any(|&v| v < 255), "{name}");
    }
}
