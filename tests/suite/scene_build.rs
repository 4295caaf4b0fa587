//! `verdant build` and `verdant preset` as a user meets them (issue 3): preset errors with positions,
//! templates, batches where one preset breaks, determinism across --jobs/--threads, the stage cache,
//! the manifest against the files on disk, the preview, stage selection, LoD files and formats.
//!
//! Every test writes small procedural presets (129² samples) into a temporary folder and runs the
//! binary there with relative paths, so the manifests (which record the preset path) compare equal.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use image::{ImageBuffer, Luma};
use verdant::scene::build::{build_batch, build_preset, BuildSettings, PresetSource};
use verdant::scene::cache::sha256_hex;
use verdant::scene::pipeline::Stage;
use verdant::scene::preset::{demo_preset, load_preset};

use crate::common::*;

// ------------------------------------------------------------------------------------------ helpers

/// A small procedural preset: fbm 129², TIN within 0.5 m, 64² chunks with skirts, two LoDs.
fn small_preset(name: &str, seed: u64) -> String {
    format!(
        "[scene]\nname = \"{name}\"\nseed = {seed}\nformats = [\"glb\"]\n\n[terrain]\n\
         procedural = {{ kind = \"fbm\", size = 129, seed = {seed}, relief = 50.0 }}\n\
         cell_size = 2.0\nmax_error = 0.5\nchunk = 64\nskirt = 2.0\nlods = [0.5, 2.0, 8.0]\n"
    )
}

/// A preset reading `maps/<name>.png` (a 16-bit gray map, 97², 120 m of relief).
fn heightmap_preset(name: &str) -> String {
    format!(
        "[scene]\nname = \"{name}\"\nformats = [\"glb\", \"obj\"]\n\n[terrain]\n\
         heightmap = \"maps/{name}.png\"\nencoding = \"gray\"\ncell_size = 3.0\nheight_scale = 120.0\n\
         max_error = 0.4\nlods = [0.4, 1.6]\n"
    )
}

fn write_heightmap(path: &Path, phase: f32) {
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    let img = ImageBuffer::from_fn(97, 97, |i, j| {
        let (x, z) = (i as f32 / 96.0, j as f32 / 96.0);
        let v = 0.5 + 0.3 * (6.0 * x + phase).sin() * (5.0 * z).cos() + 0.15 * (17.0 * x * z).sin();
        Luma([(v.clamp(0.0, 1.0) * 65535.0) as u16])
    });
    img.save(path).unwrap();
}

/// Hidden temporary folders (`.NAME.building-*`, `.NAME.old-*`) left in an output folder.
fn leftovers(out: &Path) -> Vec<String> {
    fs::read_dir(out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".building-") || n.contains(".old-"))
        .collect()
}

fn validate_all(dir: &Path, scene_dir: &Path) -> usize {
    let mut files: Vec<String> = tree(scene_dir)
        .into_keys()
        .filter(|f| f.ends_with(".glb") || f.ends_with(".gltf") || f.ends_with(".obj"))
        .map(|f| scene_dir.join(f).to_string_lossy().into_owned())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no meshes in {}", scene_dir.display());
    let mut args = vec!["validate"];
    args.extend(files.iter().map(String::as_str));
    let o = verdant_in(dir, &args);
    assert_eq!(o.status.code(), Some(0), "verdant validate failed:\n{}", text(&o));
    files.len()
}

// ------------------------------------------------------------------------------------- preset CLI

#[test]
fn preset_check_reports_errors_at_file_line_column() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/good.toml", &small_preset("good", 1));
    let o = verdant_in(d, &["preset", "check", "p/good.toml"]);
    ok(&o);
    assert!(text(&o).contains("ok"), "{}", text(&o));

    // (file, text, expected "file:line:col", words the message must contain)
    let unknown = small_preset("u", 1).replace("max_error = 0.5", "max_eror = 0.5");
    let wrong_type = small_preset("w", 1).replace("chunk = 64", "chunk = \"64\"");
    let float_for_int = small_preset("f", 1).replace("chunk = 64", "chunk = 64.0");
    let missing = "[scene]\nname = \"m\"\n\n[terrain]\nheightmap = \"maps/none.png\"\n".to_string();
    let section = format!("{}\n[species]\nx = 1\n", small_preset("s", 1));
    let line_of = |text: &str, needle: &str| text.lines().position(|l| l.contains(needle)).unwrap() + 1;
    let cases: Vec<(&str, String, String, Vec<&str>)> = vec![
        (
            "p/unknown.toml",
            unknown.clone(),
            format!("p/unknown.toml:{}:1:", line_of(&unknown, "max_eror")),
            vec!["max_eror", "did you mean", "max_error"],
        ),
        (
            "p/type.toml",
            wrong_type.clone(),
            format!("p/type.toml:{}:9:", line_of(&wrong_type, "chunk")),
            vec!["chunk", "integer", "string"],
        ),
        (
            "p/float.toml",
            float_for_int.clone(),
            format!("p/float.toml:{}:9:", line_of(&float_for_int, "chunk")),
            vec!["chunk", "integer"],
        ),
        (
            "p/missing.toml",
            missing.clone(),
            format!("p/missing.toml:{}:13:", line_of(&missing, "heightmap")),
            vec!["p/maps/none.png", "not found"],
        ),
        (
            "p/section.toml",
            section.clone(),
            format!("p/section.toml:{}:", line_of(&section, "[species]")),
            vec!["species", "[scene]", "[terrain]"],
        ),
    ];
    for (file, body, position, words) in &cases {
        write(d, file, body);
        let o = verdant_in(d, &["preset", "check", file]);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{file}: {t}");
        assert!(t.contains(position.as_str()), "{file}: expected position {position:?} in {t}");
        for w in words {
            assert!(t.contains(w), "{file}: {w:?} missing from {t}");
        }
        assert!(!t.contains("panicked"), "{t}");
    }

    // a preset file that does not exist: named, exit 2
    let o = verdant_in(d, &["preset", "check", "p/nope.toml"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("p/nope.toml") && text(&o).contains("cannot read"), "{}", text(&o));

    // several files: each checked, the worst code wins
    let o = verdant_in(d, &["preset", "check", "p/good.toml", "p/unknown.toml"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).contains("p/good.toml: ok"), "{}", text(&o));

    // the same errors stop a build before anything is written, with the same exit code (bad input)
    let o = verdant_in(d, &["build", "p/unknown.toml", "--out", "o"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("max_eror"), "{}", text(&o));
    assert!(!d.join("o/u").exists());
}

/// `preset check` runs what a build would find first without building: the heightmap decodes with
/// the preset's encoding (an RGB map under `auto`, a text file named .png), density maps and masks
/// are images, OBJ models load. Each failure names the preset key's line and column and exits 2;
/// `build` (which only needs the files to exist before it starts) finds the same in its terrain
/// stage and exits 2 as well.
#[test]
fn preset_check_decodes_every_input_as_the_build_would() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let line_of = |text: &str, needle: &str| text.lines().position(|l| l.contains(needle)).unwrap() + 1;
    write(d, "p/ok.toml", &heightmap_preset("ok"));
    write_heightmap(&d.join("p/maps/ok.png"), 0.0);
    ok(&verdant_in(d, &["preset", "check", "p/ok.toml"]));

    // an RGB picture whose channels differ, read with the automatic encoding (which refuses to guess)
    let rgb = heightmap_preset("rgb").replace("encoding = \"gray\"", "encoding = \"auto\"");
    write(d, "p/rgb.toml", &rgb);
    ImageBuffer::from_fn(33, 33, |i, j| image::Rgb([i as u8 * 7, j as u8 * 7, 0]))
        .save(d.join("p/maps/rgb.png"))
        .unwrap();
    // a text file with a .png name
    let text_map = heightmap_preset("text");
    write(d, "p/text.toml", &text_map);
    fs::write(d.join("p/maps/text.png"), b"this is not a png").unwrap();
    // a density map and an OBJ that do not decode
    let species = |key: &str, value: &str, kind: &str| {
        format!(
            "{}\n[[species]]\nname = \"s\"\nkind = \"{kind}\"\nmax_density = 0.01\n{key} = \"{value}\"\n",
            heightmap_preset("ok")
        )
    };
    let density = species("density_map", "maps/density.png", "grass");
    write(d, "p/density.toml", &density);
    fs::write(d.join("p/maps/density.png"), b"GIF89a").unwrap();
    let model = species("obj", "models/rock.obj", "mesh");
    write(d, "p/model.toml", &model);
    write(d, "p/models/rock.obj", "v 0 0 0\nv 1 0 0\nf 1 2 3\n");
    let cases = [
        ("p/rgb.toml", format!("p/rgb.toml:{}:13:", line_of(&rgb, "heightmap")), "does not decode"),
        ("p/text.toml", format!("p/text.toml:{}:13:", line_of(&text_map, "heightmap")), "does not decode"),
        ("p/density.toml", format!("p/density.toml:{}:15:", line_of(&density, "density_map")), "density_map"),
        ("p/model.toml", format!("p/model.toml:{}:7:", line_of(&model, "obj =")), "does not load"),
    ];
    for (file, position, words) in &cases {
        // the files exist: loading for a build passes, the check does not
        if let Err(e) = load_preset(&d.join(file)) {
            panic!("{file}: {e}");
        }
        let o = verdant_in(d, &["preset", "check", file]);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{file}: {t}");
        assert!(t.contains(position.as_str()), "{file}: expected position {position:?} in {t}");
        assert!(t.contains(words), "{file}: {words:?} missing from {t}");
        assert!(!t.contains("panicked"), "{t}");
    }
    // the build finds the bad heightmap in its terrain stage: bad input, exit 2, nothing written
    let o = verdant_in(d, &["build", "p/text.toml", "--out", "o"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("text.png"), "{}", text(&o));
    assert!(!d.join("o/text").exists());
}

#[test]
fn preset_new_writes_a_template_that_checks_and_is_not_overwritten() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    fs::create_dir_all(d.join("presets")).unwrap();
    let o = verdant_in(d, &["preset", "new", "canyon"]);
    ok(&o);
    let path = d.join("presets/canyon.toml");
    let first = fs::read_to_string(&path).expect("presets/canyon.toml written");
    assert!(first.contains("name = \"canyon\""), "{first}");
    assert!(
        first.lines().filter(|l| l.trim_start().starts_with('#')).count() >= 5,
        "the template is not commented:\n{first}"
    );
    ok(&verdant_in(d, &["preset", "check", "presets/canyon.toml"]));

    // a second `new` refuses and leaves the (edited) file alone
    fs::write(&path, format!("{first}\n# my edit\n")).unwrap();
    let o = verdant_in(d, &["preset", "new", "canyon"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("not overwritten") || text(&o).contains("exists"), "{}", text(&o));
    assert_eq!(fs::read_to_string(&path).unwrap(), format!("{first}\n# my edit\n"));

    // --output elsewhere; a bad name writes nothing
    ok(&verdant_in(d, &["preset", "new", "gorge", "--output", "elsewhere.toml"]));
    ok(&verdant_in(d, &["preset", "check", "elsewhere.toml"]));
    let o = verdant_in(d, &["preset", "new", "my valley", "--output", "bad.toml"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(!d.join("bad.toml").exists());

    // and the template builds (quickly enough: it is meant to be edited, not a benchmark)
    let loaded = load_preset(&d.join("elsewhere.toml")).unwrap();
    assert_eq!(loaded.scene.name, "gorge");
}

// ----------------------------------------------------------------------------------------- batches

#[test]
fn a_broken_preset_fails_alone_and_leaves_its_previous_output_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/good.toml", &small_preset("good", 1));
    write(d, "p/victim.toml", &small_preset("victim", 2));
    write(d, "p/mapped.toml", &heightmap_preset("mapped"));
    write_heightmap(&d.join("p/maps/mapped.png"), 0.0);
    let o = verdant_in(d, &["build", "p/good.toml", "p/victim.toml", "p/mapped.toml", "--jobs", "2", "--out", "o"]);
    ok(&o);
    let victim_before = tree(&d.join("o/victim"));
    let mapped_before = tree(&d.join("o/mapped"));
    assert!(victim_before.contains_key("terrain/terrain.glb") && mapped_before.contains_key("terrain/terrain.obj"));

    // 1. the victim's preset no longer parses; 2. the mapped scene's heightmap is no PNG any more
    //    (it still exists, so the preset loads and the terrain stage itself fails mid-build)
    write(d, "p/victim.toml", &small_preset("victim", 2).replace("max_error", "max_eror"));
    fs::write(d.join("p/maps/mapped.png"), b"this is not a png").unwrap();
    // and the good scene changes, so it is really rebuilt
    write(d, "p/good.toml", &small_preset("good", 5));
    for jobs in ["1", "2"] {
        let o =
            verdant_in(d, &["build", "p/victim.toml", "p/good.toml", "p/mapped.toml", "--jobs", jobs, "--out", "o"]);
        let t = text(&o);
        // both failures are the inputs' (a preset that does not parse, a heightmap that does not
        // decode): exit 2, as for any bad input; a failure of the build itself would be 1
        assert_eq!(o.status.code(), Some(2), "--jobs {jobs}: {t}");
        assert!(summary_row(&o, "good")[1].starts_with("built"), "{t}");
        assert_eq!(summary_row(&o, "mapped")[1], "FAILED", "{t}");
        assert!(t.contains("FAILED") && t.contains("p/victim.toml") && t.contains("max_eror"), "{t}");
        assert!(t.contains("mapped.png"), "the failure does not name the heightmap: {t}");
        assert!(!t.contains("panicked"), "{t}");
        assert_eq!(tree(&d.join("o/victim")), victim_before, "the failed victim's old output changed");
        assert_eq!(tree(&d.join("o/mapped")), mapped_before, "the failed mapped scene's old output changed");
        assert!(leftovers(&d.join("o")).is_empty(), "temporary folders left: {:?}", leftovers(&d.join("o")));
        assert_eq!(read_json(&d.join("o/good/manifest.json"))["settings"]["scene"]["seed"], 5);
    }
}

#[test]
fn two_presets_with_one_scene_name_the_second_fails_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/one.toml", &small_preset("same", 1));
    write(d, "p/two.toml", &small_preset("same", 2));
    let o = verdant_in(d, &["build", "p/one.toml", "p/two.toml", "--jobs", "2", "--out", "o"]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(2), "a usage error: {t}");
    assert!(t.contains("already built by p/one.toml"), "{t}");
    assert!(t.contains("p/two.toml") && t.contains("`same`"), "{t}");
    // the first one is the one built
    assert_eq!(read_json(&d.join("o/same/manifest.json"))["settings"]["path"], "p/one.toml");
    assert!(leftovers(&d.join("o")).is_empty());
}

// ------------------------------------------------------------------------------------- determinism

#[test]
fn outputs_are_identical_for_any_jobs_and_threads() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &small_preset("a", 3).replace("[\"glb\"]", "[\"glb\", \"obj\", \"gltf\"]"));
    write(d, "p/b.toml", &small_preset("b", 4).replace("kind = \"fbm\"", "kind = \"ridged\""));
    write(d, "p/c.toml", &heightmap_preset("c"));
    write_heightmap(&d.join("p/maps/c.png"), 1.0);
    let presets = ["p/a.toml", "p/b.toml", "p/c.toml"];
    let runs: [(&str, &str, &str); 3] = [("o1", "1", "1"), ("o2", "2", "2"), ("o3", "2", "1")];
    for (out, jobs, threads) in runs {
        let mut args = vec!["--threads", threads, "build"];
        args.extend(presets);
        args.extend(["--jobs", jobs, "--out", out]);
        ok(&verdant_in(d, &args));
    }
    for scene in ["a", "b", "c"] {
        for (out, ..) in &runs[1..] {
            assert_same_tree(&d.join("o1").join(scene), &d.join(out).join(scene));
        }
    }
    // the cache entries are the same too (their stage.json carries the timing of the run that
    // computed them, so compare the files only)
    let cache = |o: &str| {
        tree(&d.join(o).join(".cache"))
            .into_iter()
            .filter(|(k, _)| !k.ends_with("stage.json"))
            .collect::<BTreeMap<_, _>>()
    };
    assert_eq!(cache("o1"), cache("o2"));
}

// --------------------------------------------------------------------------------------------- cache

#[test]
fn rebuilds_hit_the_cache_and_changed_inputs_or_force_miss_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/proc.toml", &small_preset("proc", 3));
    write(d, "p/map.toml", &heightmap_preset("map"));
    write_heightmap(&d.join("p/maps/map.png"), 0.0);
    let build = |extra: &[&str]| {
        let mut args = vec!["build", "p/proc.toml", "p/map.toml", "--out", "o"];
        args.extend_from_slice(extra);
        let o = verdant_in(d, &args);
        ok(&o);
        o
    };
    let o = build(&[]);
    for s in ["proc", "map"] {
        assert_eq!(summary_row(&o, s)[1], "built", "{}", text(&o));
        assert!(!timing_cached(&d.join("o").join(s), "terrain") && !timing_cached(&d.join("o").join(s), "preview"));
    }
    let first_proc = tree(&d.join("o/proc"));
    let first_map = tree(&d.join("o/map"));

    // unchanged: every stage from the cache, and the same bytes
    let o = build(&[]);
    assert!(text(&o).contains("built*") && text(&o).contains("from the cache"), "{}", text(&o));
    for s in ["proc", "map"] {
        assert_eq!(summary_row(&o, s)[1], "built*", "{}", text(&o));
        assert!(timing_cached(&d.join("o").join(s), "terrain") && timing_cached(&d.join("o").join(s), "preview"));
    }
    let cached_proc = d.join("o/proc");
    fs::create_dir_all(d.join("first")).unwrap();
    for (rel, bytes) in &first_proc {
        write_bytes(&d.join("first/proc").join(rel), bytes);
    }
    assert_same_tree(&d.join("first/proc"), &cached_proc);
    assert_eq!(tree(&d.join("o/map"))["terrain/terrain.glb"], first_map["terrain/terrain.glb"]);

    // the heightmap's bytes change (same path, same settings): the map misses, proc still hits
    write_heightmap(&d.join("p/maps/map.png"), 0.7);
    let o = build(&[]);
    assert_eq!(summary_row(&o, "map")[1], "built", "{}", text(&o));
    assert_eq!(summary_row(&o, "proc")[1], "built*", "{}", text(&o));
    assert!(!timing_cached(&d.join("o/map"), "terrain") && !timing_cached(&d.join("o/map"), "preview"));
    assert_ne!(tree(&d.join("o/map"))["terrain/terrain.glb"], first_map["terrain/terrain.glb"]);
    let m = read_json(&d.join("o/map/report.json"));
    let want = sha256_hex(&fs::read(d.join("p/maps/map.png")).unwrap());
    assert_eq!(m["stages"]["terrain"]["input_sha256"], want.as_str());

    // the procedural seed changes: miss
    write(d, "p/proc.toml", &small_preset("proc", 9));
    let o = build(&[]);
    assert_eq!(summary_row(&o, "proc")[1], "built", "{}", text(&o));
    assert_ne!(tree(&d.join("o/proc"))["terrain/terrain.glb"], first_proc["terrain/terrain.glb"]);

    // back to the first seed: the old entry is still there
    write(d, "p/proc.toml", &small_preset("proc", 3));
    let o = build(&[]);
    assert_eq!(summary_row(&o, "proc")[1], "built*", "{}", text(&o));
    assert_same_tree(&d.join("first/proc"), &d.join("o/proc"));

    // --force recomputes everything, and gives the same bytes
    let o = build(&["--force"]);
    for s in ["proc", "map"] {
        assert_eq!(summary_row(&o, s)[1], "built", "{}", text(&o));
        assert!(!timing_cached(&d.join("o").join(s), "terrain") && !timing_cached(&d.join("o").join(s), "preview"));
    }
    assert_same_tree(&d.join("first/proc"), &d.join("o/proc"));
}

/// A build whose stages all come from the cache writes the same manifest and report as the build
/// that computed them.
#[test]
fn cached_rebuild_manifest_is_byte_identical() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &small_preset("a", 3));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let fresh = tree(&d.join("o/a"));
    let o = verdant_in(d, &["build", "p/a.toml", "--out", "o"]);
    ok(&o);
    assert_eq!(summary_row(&o, "a")[1], "built*");
    let cached = tree(&d.join("o/a"));
    assert_eq!(String::from_utf8_lossy(&cached["manifest.json"]), String::from_utf8_lossy(&fresh["manifest.json"]));
    assert_eq!(
        without_timing("report.json", &cached["report.json"]),
        without_timing("report.json", &fresh["report.json"])
    );
}

fn write_bytes(path: &Path, bytes: &[u8]) {
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    fs::write(path, bytes).unwrap();
}

/// A preview drawn after a cached terrain (re-imported from its primary file) equals the one
/// drawn from the freshly meshed terrain.
#[test]
fn preview_after_a_cached_terrain_is_the_same_glb_first() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &small_preset("a", 3).replace("[\"glb\"]", "[\"glb\", \"obj\"]"));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "fresh"]));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "split", "--only", "terrain"]));
    let o = verdant_in(d, &["build", "p/a.toml", "--out", "split"]);
    ok(&o);
    assert!(timing_cached(&d.join("split/a"), "terrain") && !timing_cached(&d.join("split/a"), "preview"));
    assert_same_tree(&d.join("fresh/a"), &d.join("split/a"));
}

/// Same, with OBJ or glTF (+ .bin) as the primary format.
#[test]
fn preview_after_a_cached_terrain_is_the_same_for_obj_and_gltf_first() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (name, formats) in [("objfirst", "[\"obj\", \"glb\"]"), ("gltfonly", "[\"gltf\"]")] {
        write(d, &format!("p/{name}.toml"), &small_preset(name, 3).replace("[\"glb\"]", formats));
        let preset = format!("p/{name}.toml");
        ok(&verdant_in(d, &["build", &preset, "--out", "fresh"]));
        ok(&verdant_in(d, &["build", &preset, "--out", "split", "--skip", "preview"]));
        let o = verdant_in(d, &["build", &preset, "--out", "split"]);
        ok(&o);
        assert!(timing_cached(&d.join("split").join(name), "terrain"));
        assert!(d.join("split").join(name).join("preview.png").is_file());
        // a stage after a cached terrain makes what it makes after a fresh one (the terrain read back
        // from the same file either way; an OBJ does not read back as the scene written)
        assert_same_tree(&d.join("fresh").join(name), &d.join("split").join(name));
    }
}

/// A cache entry that lost a file is a miss, not a failed build.
#[test]
fn a_damaged_cache_entry_is_recomputed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &small_preset("a", 3));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let entry = |stage: &str| {
        fs::read_dir(d.join("o/.cache")).unwrap().map(|e| e.unwrap().path()).find(|p| {
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            name.strip_prefix(stage).is_some_and(|key| key.len() == 32 && key.bytes().all(|b| b.is_ascii_hexdigit()))
        })
    };
    fs::remove_file(entry("terrain-").unwrap().join("terrain/terrain_LOD1.glb")).unwrap();
    let o = verdant_in(d, &["build", "p/a.toml", "--out", "o"]);
    ok(&o);
    assert!(d.join("o/a/terrain/terrain_LOD1.glb").is_file());
    // the terrain's meshes kept apart (terrain-mesh-…) cut short: meshed again, the same files
    let before = tree(&d.join("o/a/terrain"));
    fs::remove_dir_all(entry("terrain-").unwrap()).unwrap();
    let blob = entry("terrain-mesh-").expect("the terrain's meshes are kept").join("blob.bin");
    let bytes = fs::read(&blob).unwrap();
    fs::write(&blob, &bytes[..bytes.len() / 2]).unwrap();
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    assert_eq!(tree(&d.join("o/a/terrain")), before);
    assert_eq!(fs::read(&blob).unwrap(), bytes, "the damaged entry was replaced");
}

// -------------------------------------------------------------------------------- manifest, preview

#[test]
fn manifest_lists_every_file_with_its_hash_and_lods_are_ordered() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &small_preset("a", 3).replace("[\"glb\"]", "[\"glb\", \"obj\"]"));
    let o = verdant_in(d, &["build", "p/a.toml", "--out", "o"]);
    ok(&o);
    let scene = d.join("o/a");
    let m = read_json(&scene.join("manifest.json"));
    assert_eq!(m["scene"], "a");
    assert_eq!(m["verdant_version"], env!("CARGO_PKG_VERSION"));
    let on_disk = tree(&scene);
    let listed: BTreeMap<String, (u64, String)> = m["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            (
                f["path"].as_str().unwrap().to_string(),
                (f["bytes"].as_u64().unwrap(), f["sha256"].as_str().unwrap().to_string()),
            )
        })
        .collect();
    let expected: Vec<&String> =
        on_disk.keys().filter(|k| !["manifest.json", "report.json", "report.md"].contains(&k.as_str())).collect();
    assert_eq!(listed.keys().collect::<Vec<_>>(), expected, "the manifest does not list exactly the scene's files");
    for (path, (bytes, sha)) in &listed {
        assert_eq!(*bytes, on_disk[path].len() as u64, "{path}: size");
        assert_eq!(*sha, sha256_hex(&on_disk[path]), "{path}: sha256");
    }
    // the summary's file count is every file in the folder
    assert_eq!(summary_row(&o, "a")[2], on_disk.len().to_string(), "{}", text(&o));

    // terrain: files exist, counts, bounds, chunks with AABBs inside the terrain's
    let t = &m["terrain"];
    for f in t["files"].as_array().unwrap() {
        assert!(scene.join(f.as_str().unwrap()).is_file(), "{f}");
    }
    assert_eq!((t["width"].as_u64(), t["height"].as_u64()), (Some(129), Some(129)));
    assert!(t["output_triangles"].as_u64().unwrap() > t["triangles"].as_u64().unwrap(), "skirts add triangles");
    assert!(t["max_error_m"].as_f64().unwrap() <= 0.5);
    let chunks = t["chunks"].as_array().unwrap();
    assert_eq!(chunks.len(), 4, "129² samples in 64² chunks");
    assert_eq!(
        chunks.iter().map(|c| c["triangles"].as_u64().unwrap()).sum::<u64>(),
        t["output_triangles"].as_u64().unwrap()
    );
    let (lo, hi) = (&t["bounds"]["min"], &t["bounds"]["max"]);
    for c in chunks {
        for k in 0..3 {
            assert!(c["bounds"]["min"][k].as_f64().unwrap() >= lo[k].as_f64().unwrap() - 1e-3);
            assert!(c["bounds"]["max"][k].as_f64().unwrap() <= hi[k].as_f64().unwrap() + 1e-3);
        }
    }
    // the resolved settings, so the build can be reproduced from the manifest
    assert_eq!(m["settings"]["terrain"]["lods"], serde_json::json!([0.5, 2.0, 8.0]));
    assert_eq!(m["settings"]["scene"]["formats"], serde_json::json!(["glb", "obj"]));

    // LoDs: one level per requested error, its files on disk, errors within the request,
    // switch distances increasing and triangles decreasing
    let lods = t["lods"].as_array().unwrap();
    assert_eq!(lods.len(), 3);
    let mut last_distance = -1.0;
    let mut last_triangles = u64::MAX;
    for (n, l) in lods.iter().enumerate() {
        assert_eq!(l["level"].as_u64(), Some(n as u64));
        for ext in ["glb", "obj"] {
            let f = format!("terrain/terrain_LOD{n}.{ext}");
            assert!(scene.join(&f).is_file(), "{f} missing");
            assert!(l["files"].as_array().unwrap().iter().any(|x| x == f.as_str()), "{f} not listed in {l}");
        }
        let (req, got) = (l["max_error_requested_m"].as_f64().unwrap(), l["max_error_m"].as_f64().unwrap());
        assert!(got <= req + 1e-9, "LOD{n}: measured {got} > requested {req}");
        let dist = l["switch_distance_m"].as_f64().unwrap();
        assert!(dist > last_distance, "LOD{n}: switch distance {dist} after {last_distance}");
        let tris = l["triangles"].as_u64().unwrap();
        assert!(tris < last_triangles, "LOD{n}: {tris} triangles, not fewer than {last_triangles}");
        assert!(l["rms_error_m"].as_f64().unwrap() <= got);
        last_distance = dist;
        last_triangles = tris;
    }
    assert!(!scene.join("terrain/terrain_LOD3.glb").exists());

    // report.json: the same measurements, timing apart
    let r = read_json(&scene.join("report.json"));
    assert_eq!(r["stages"]["terrain"]["lods"], t["lods"]);
    assert!(r["timing"]["total_seconds"].as_f64().unwrap() >= 0.0);
    assert!(r["stages"]["terrain"].get("seconds").is_none(), "seconds belong in timing");
    let md = fs::read_to_string(scene.join("report.md")).unwrap();
    assert!(md.contains("LOD2") && md.contains("## Timing"), "{md}");

    // every mesh written passes verdant validate
    assert_eq!(validate_all(d, &scene), 8);
}

#[test]
fn preview_has_the_reported_size_and_shows_something() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &small_preset("a", 3));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let scene = d.join("o/a");
    let r = read_json(&scene.join("report.json"));
    let (w, h) =
        (r["stages"]["preview"]["width_px"].as_u64().unwrap(), r["stages"]["preview"]["height_px"].as_u64().unwrap());
    let img = image::open(scene.join("preview.png")).expect("preview.png decodes").to_rgba8();
    assert_eq!((img.width() as u64, img.height() as u64), (w, h));
    if scene.join("scene.glb").is_file() {
        // the first view's perspective render (1920×1080 views at 1280×720); the map beside it
        assert_eq!((w, h), (1280, 720));
        assert_eq!(r["stages"]["preview"]["map"], "map.png");
        let map = image::open(scene.join("map.png")).expect("map.png decodes");
        assert_eq!(map.width().max(map.height()), 1024, "the map is 1024 px on its long side");
        assert!(r["stages"]["preview"]["view"]["instances"].as_u64().unwrap() > 0);
    } else {
        assert_eq!(w.max(h), 1024, "the preview is 1024 px on its long side");
    }
    let mut colours = std::collections::HashMap::new();
    for p in img.pixels() {
        *colours.entry(p.0).or_insert(0usize) += 1;
    }
    assert!(colours.len() >= 64, "only {} distinct colours", colours.len());
    let most = colours.values().max().copied().unwrap();
    assert!(most < img.pixels().len() * 9 / 10, "one colour covers {most} of {} pixels", img.pixels().len());
    assert_eq!(read_json(&scene.join("manifest.json"))["preview"], "preview.png");
}

// ---------------------------------------------------------------------------------- stage selection

#[test]
fn only_skip_and_out_select_what_is_built() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &small_preset("a", 3));

    ok(&verdant_in(d, &["build", "p/a.toml", "--only", "terrain", "--out", "only"]));
    let s = d.join("only/a");
    assert!(s.join("terrain/terrain.glb").is_file() && !s.join("preview.png").exists());
    let m = read_json(&s.join("manifest.json"));
    assert!(m["preview"].is_null());
    assert!(m["files"].as_array().unwrap().iter().all(|f| f["path"] != "preview.png"));
    assert!(read_json(&s.join("report.json"))["stages"].get("preview").is_none());

    ok(&verdant_in(d, &["build", "p/a.toml", "--skip", "preview", "--out", "skip"]));
    assert_same_tree(&s, &d.join("skip/a"));

    ok(&verdant_in(d, &["build", "p/a.toml", "--only", "terrain,preview", "--out", "both"]));
    assert!(d.join("both/a/preview.png").is_file());

    // the preview alone has nothing to draw: an error, and nothing written
    let o = verdant_in(d, &["build", "p/a.toml", "--only", "preview", "--out", "pv"]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(2), "{t}");
    assert!(t.contains("terrain"), "{t}");
    assert!(!d.join("pv/a").exists());
    // nothing left to build at all: usage error
    let o = verdant_in(d, &["build", "p/a.toml", "--skip", "terrain,plants,scatter,preview", "--out", "none"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let o = verdant_in(d, &["build", "p/a.toml", "--only", "grass"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));

    // --out: nothing lands in ./out
    assert!(!d.join("out").exists());
    // a nested --out that does not exist yet is created
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "deep/er/out"]));
    assert!(d.join("deep/er/out/a/manifest.json").is_file());
}

#[test]
fn formats_glb_obj_gltf_are_all_written_and_validate() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &small_preset("a", 3).replace("[\"glb\"]", "[\"glb\", \"obj\", \"gltf\"]"));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let s = d.join("o/a/terrain");
    for stem in ["terrain", "terrain_LOD0", "terrain_LOD1", "terrain_LOD2"] {
        for ext in ["glb", "obj", "mtl", "gltf", "bin"] {
            assert!(s.join(format!("{stem}.{ext}")).is_file(), "{stem}.{ext} missing");
        }
    }
    assert_eq!(validate_all(d, &d.join("o/a")), 12);
    // glb only: no obj, no gltf
    write(d, "p/b.toml", &small_preset("b", 3));
    ok(&verdant_in(d, &["build", "p/b.toml", "--out", "o"]));
    let files: Vec<String> = tree(&d.join("o/b")).into_keys().collect();
    assert!(files.iter().all(|f| !f.ends_with(".obj") && !f.ends_with(".gltf")), "{files:?}");
}

#[test]
fn build_without_a_preset_builds_the_demo() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = verdant_in(d, &["build", "--out", "o", "--jobs", "2"]);
    ok(&o);
    assert!(text(&o).contains("(embedded demo)"), "{}", text(&o));
    let s = d.join("o/demo");
    for f in [
        "terrain/terrain.glb",
        "terrain/terrain_LOD0.glb",
        "terrain/terrain_LOD1.glb",
        "terrain/terrain_LOD2.glb",
        "preview.png",
        "manifest.json",
        "report.json",
        "report.md",
    ] {
        assert!(s.join(f).is_file(), "demo: {f} missing");
    }
    let m = read_json(&s.join("manifest.json"));
    assert!(m["settings"]["path"].is_null());
    assert_eq!(m["terrain"]["width"], 513);
    assert_eq!(m["terrain"]["chunks"].as_array().unwrap().len(), 16);
    validate_all(d, &s);
}

// ------------------------------------------------------------------------------------------ library

#[test]
fn library_batch_keeps_order_and_reports_failures() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let good = write(d, "a.toml", &small_preset("a", 3));
    let bad = write(d, "bad.toml", &small_preset("bad", 3).replace("chunk = 64", "chunk = 1.5"));
    let mut demo = demo_preset();
    demo.scene.name = "mini".into();
    if let Some(t) = demo.terrain.as_mut() {
        t.source = load_preset(&good).unwrap().terrain.unwrap().source;
        t.chunk = Some(64);
    }
    let settings = BuildSettings { out_dir: d.join("out"), ..BuildSettings::default() };
    let sources = vec![
        PresetSource::File(bad.clone()),
        PresetSource::Resolved(Box::new(demo.clone())),
        PresetSource::File(good.clone()),
    ];
    let lines = std::sync::Mutex::new(Vec::<String>::new());
    let progress = |scene: &str, msg: &str| lines.lock().unwrap().push(format!("{scene}: {msg}"));
    let outcomes = build_batch(&sources, &settings, 3, &progress);
    assert_eq!(outcomes.len(), 3);
    assert!(outcomes[0].error.as_deref().unwrap().contains("bad.toml"), "{:?}", outcomes[0]);
    assert_eq!(outcomes[1].scene, "mini");
    assert_eq!(outcomes[1].preset, "(embedded demo)");
    assert_eq!(outcomes[2].scene, "a");
    for o in &outcomes[1..] {
        assert!(o.error.is_none(), "{o:?}");
        assert!(o.triangles > 0 && o.files > 3 && o.cached_stages.is_empty());
        assert!(o.dir.as_ref().unwrap().join("manifest.json").is_file());
    }
    let lines = lines.into_inner().unwrap();
    assert!(lines.iter().any(|l| l == "a: terrain: running"), "{lines:?}");

    // build_preset directly: the second time both stages come from the cache
    let p = load_preset(&good).unwrap();
    let again = build_preset(&p, &settings, &|_, _| {}).unwrap();
    assert_eq!(again.cached_stages, vec![Stage::Terrain, Stage::Preview]);
    let forced = build_preset(&p, &BuildSettings { force: true, ..settings.clone() }, &|_, _| {}).unwrap();
    assert!(forced.cached_stages.is_empty());
}

/// Two scenes of one batch with the same terrain store the same cache entry at the same time.
/// Both use the temporary folder `.cache/.terrain-KEY.tmp-PID` (the same PID), so one can delete
/// the other's half-copied files and rename an incomplete entry into place.
#[test]
fn concurrent_stores_of_one_cache_entry_stay_complete() {
    use verdant::scene::cache::Cache;
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene");
    let files: Vec<PathBuf> = (0..200).map(|i| PathBuf::from(format!("terrain/f{i}.bin"))).collect();
    for f in &files {
        write_bytes(&scene.join(f), &vec![7u8; 20_000]);
    }
    for round in 0..20 {
        let out = dir.path().join(format!("out{round}"));
        let cache = Cache::new(&out);
        let barrier = std::sync::Barrier::new(2);
        std::thread::scope(|s| {
            for _ in 0..2 {
                s.spawn(|| {
                    barrier.wait();
                    let _ = cache.store("terrain", "k", &scene, &files, "{}");
                });
            }
        });
        let (_, entry) = cache.lookup("terrain", "k").expect("an entry");
        let restored = dir.path().join(format!("restored{round}"));
        Cache::restore(&entry, &restored, &files)
            .unwrap_or_else(|e| panic!("round {round}: incomplete cache entry: {e}"));
    }
}

// ------------------------------------------------------------------------------ algorithm versions

/// The algorithm version and output digest of each stage on presets/winter_valley.toml (every stage
/// runs there), presets/meadow.toml (L-system trees and flowers) and presets/alpine.toml (an OBJ
/// model species). When a change alters a stage's output bytes on purpose, bump that stage's
/// `*_ALGORITHM_VERSION` (its cache key then changes, so an older `out/.cache` is never served to
/// the new binary) and put the new digest here; the test prints the whole table to copy. A later
/// stage whose bytes change only because an earlier one's did (its key holds the earlier stage's
/// key) keeps its version; its new digest is pinned all the same.
const PINNED: &[(&str, u32, &str)] = &[
    ("terrain", 14, "e154dc460f3311c0"),
    ("plants", 20, "314b79f5bdaa8936"),
    ("snow", 6, "5b8216b69ff23bf7"),
    ("scatter", 11, "2d5b403c7af5d0fa"),
    ("view", 17, "e5c3b6eb8a7d535f"),
    ("preview", 12, "6bf09146af24fc40"),
];

/// The stage a scene file belongs to (manifest and reports carry timings: not digested).
fn stage_of(rel: &str) -> Option<&'static str> {
    match rel.split('/').next()? {
        "terrain" => Some("terrain"),
        "species" | "atlases" => Some("plants"),
        "snow" => Some("snow"),
        "placements" => Some("scatter"),
        "scene.glb" | "scene_lod.glb" | "scene_tiles.json" | "tiles" => Some("view"),
        "preview.png" | "map.png" => Some("preview"),
        _ => None,
    }
}

#[test]
fn stage_outputs_match_their_pinned_algorithm_versions() {
    use verdant::scene::{plants_stage, preview_stage, scatter_stage, snow_stage, terrain_stage, view_stage};
    let versions = [
        ("terrain", terrain_stage::TERRAIN_ALGORITHM_VERSION),
        ("plants", plants_stage::PLANTS_ALGORITHM_VERSION),
        ("snow", snow_stage::SNOW_ALGORITHM_VERSION),
        ("scatter", scatter_stage::SCATTER_ALGORITHM_VERSION),
        ("view", view_stage::VIEW_ALGORITHM_VERSION),
        ("preview", preview_stage::PREVIEW_ALGORITHM_VERSION),
    ];
    let dir = tempfile::tempdir().unwrap();
    let mut files: BTreeMap<&str, Vec<(String, String)>> = BTreeMap::new();
    for name in ["winter_valley", "meadow", "alpine"] {
        let preset = load_preset(&Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("presets/{name}.toml"))).unwrap();
        let settings = BuildSettings { out_dir: dir.path().to_path_buf(), force: true, ..BuildSettings::default() };
        let scene_dir = build_preset(&preset, &settings, &|_, _| {}).unwrap().dir.unwrap();
        let mut stack = vec![scene_dir.clone()];
        while let Some(d) = stack.pop() {
            for e in fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                    continue;
                }
                let rel = p.strip_prefix(&scene_dir).unwrap().to_string_lossy().replace('\\', "/");
                if let Some(stage) = stage_of(&rel) {
                    files.entry(stage).or_default().push((format!("{name}/{rel}"), sha256_hex(&fs::read(&p).unwrap())));
                }
            }
        }
    }
    let digest = |stage: &str| -> String {
        let mut list = files.get(stage).cloned().unwrap_or_default();
        list.sort();
        assert!(!list.is_empty(), "the reference presets wrote no {stage} files");
        sha256_hex(list.iter().map(|(r, h)| format!("{r} {h}\n")).collect::<String>().as_bytes())[..16].to_string()
    };
    let table: Vec<String> = versions.iter().map(|(s, v)| format!("    (\"{s}\", {v}, \"{}\"),", digest(s))).collect();
    let table = table.join("\n");
    // the stages whose keys hold each stage's key (scene/*_stage.rs): a stage's bytes may change
    // with its algorithm unchanged when one of these changed its output
    let upstream = |stage: &str| -> &[&str] {
        match stage {
            "snow" => &["terrain"],
            "scatter" => &["terrain", "snow"],
            "view" | "preview" => &["terrain", "plants", "snow", "scatter"],
            _ => &[],
        }
    };
    let mut changed: Vec<&str> = Vec::new();
    for ((stage, version), (pinned_stage, pinned_version, pinned_digest)) in versions.iter().zip(PINNED) {
        assert_eq!(stage, pinned_stage);
        let now = digest(stage);
        let cause = upstream(stage).iter().find(|s| changed.contains(s)).copied();
        if now != *pinned_digest {
            changed.push(stage);
        }
        if let (Some(cause), true) = (cause, version == pinned_version) {
            assert_eq!(
                now.as_str(),
                *pinned_digest,
                "{stage}: its output follows {cause}'s changed output; pin the new digest in PINNED:\n{table}"
            );
            continue;
        }
        if now != *pinned_digest && version == pinned_version {
            panic!(
                "the {stage} stage's output changed (digest {now}, pinned {pinned_digest}) but its algorithm \
                 version is still {version}: bump it (so older cache entries are not served) and update PINNED:\n{table}"
            );
        }
        assert_eq!(
            (version, now.as_str()),
            (pinned_version, *pinned_digest),
            "{stage}: the version was bumped; pin the new digest in PINNED:\n{table}"
        );
    }
}

/// Every file the plants stage writes for a species is named its name, or its name followed by
/// `_` and a word the preset refuses as the end of another species' name
/// (`preset::file_name_clash`): so no two species a preset accepts write one file. A new kind of
/// file named otherwise fails here until the preset's check knows its word.
#[test]
fn every_species_file_is_named_by_its_species_and_a_refused_word() {
    use verdant::scene::plants_stage::run_plants;
    use verdant::scene::preset::file_name_clash;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "m.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n");
    write(
        d,
        "p.toml",
        "[scene]\nname = \"names\"\n\n[terrain]\nprocedural = { kind = \"fbm\", size = 33, relief = 5.0 }\n\n\
         [[species]]\nname = \"t\"\nkind = \"tree\"\nlsystem = \"builtin:bush\"\n\
         tree = { variants = 2, height = 3.0, atlas_size = 256, analysis = false }\nmax_density = 0.01\n\
         [[species]]\nname = \"g\"\nkind = \"grass\"\nmax_density = 0.1\n\
         [[species]]\nname = \"f\"\nkind = \"flower\"\nmax_density = 0.1\n\
         [[species]]\nname = \"m\"\nkind = \"mesh\"\nobj = \"m.obj\"\nmax_density = 0.1\n",
    );
    let preset = load_preset(&d.join("p.toml")).unwrap();
    let out = d.join("out");
    let report = run_plants(&preset, &out).unwrap();
    assert_eq!(report.species.len(), 4);
    for s in &report.species {
        assert!(!s.files.is_empty(), "{}", s.name);
        for f in &s.files {
            assert!(out.join(f).is_file(), "{}", f.display());
            let stem = f.file_stem().unwrap().to_str().unwrap();
            assert!(stem == s.name || file_name_clash(&s.name, stem).is_some(), "{} writes {}", s.name, f.display());
        }
    }
    // and so none writes another's
    let all: Vec<_> = report.species.iter().flat_map(|s| &s.files).collect();
    let distinct: std::collections::BTreeSet<_> = all.iter().collect();
    assert_eq!(distinct.len(), all.len());
}
