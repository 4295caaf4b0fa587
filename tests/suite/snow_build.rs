//! The snow stage inside `verdant build` (issue 7): `[snow]` parse errors name their position; a
//! build writes every snow file and reports it; outputs are byte-identical across builds and
//! `--threads`; snow thins grass and flowers (by exactly the reported rule count) and leaves trees
//! alone; the snow cache hits on rebuild and misses when a snow key changes; no `[snow]`, no snow/.
//!
//! Presets are small procedural scenes (129² samples, 2 m cells: 256 m across) written into a
//! temporary folder; the binary runs there with relative paths.

use std::collections::BTreeMap;
use std::fs;
use std::path::Path;

use verdant::scene::preset::{parse_preset, template};

use crate::common::*;

const TREE: &str =
    "[[species]]\nname = \"tree\"\nkind = \"tree\"\nplacement = \"poisson\"\nmax_density = 0.01\nmin_spacing = 5.0\n";
/// No exclusion, so every grass candidate the snow drops would otherwise have been placed.
const GRASS: &str = "[[species]]\nname = \"grass\"\nkind = \"grass\"\nmax_density = 0.3\n";
const FLOWER: &str = "[[species]]\nname = \"bloom\"\nkind = \"flower\"\nmax_density = 0.1\n";

/// Small and fast snow: 500 flakes, a 2×2 atlas of 32 px cells, a 128 px mask.
const SNOW: &str = "[snow]\ntemperature_c = -15.0\nhumidity = 0.6\natlas_cells = [2, 2]\ncell_px = 32\n\
                    near_radius = 10.0\nnear_count = 200\nfar_radius = 40.0\nfar_count = 300\nview_angle = 80.0\n\
                    fall_height = 12.0\nsnow_line = 20.0\nsnow_line_noise = 5.0\nnoise_scale = 80.0\ntransition = 10.0\n\
                    mask_px = 128\nthin_plants = 0.8\n";

/// Snow everywhere at weight 1: a snow line far below, every slope, no wind scouring.
fn full_snow(thin: f64) -> String {
    format!(
        "[snow]\natlas_cells = [2, 2]\ncell_px = 32\nnear_count = 50\nfar_count = 0\nsnow_line = -1000.0\n\
         full_slope = 89.0\nmax_slope = 90.0\nwind_scour = 0.0\nmask_px = 128\nthin_plants = {thin}\n"
    )
}

fn preset(name: &str, body: &str) -> String {
    format!(
        "[scene]\nname = \"{name}\"\nseed = 5\nformats = [\"glb\"]\n\n[terrain]\n\
         procedural = {{ kind = \"fbm\", size = 129, seed = 3, relief = 50.0 }}\n\
         cell_size = 2.0\nmax_error = 0.5\nchunk = 64\nskirt = 2.0\n\n[scatter]\ntile = 64.0\n\n{body}"
    )
}

fn build(d: &Path, preset_rel: &str, out: &str, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["build", preset_rel, "--out", out];
    args.extend_from_slice(extra);
    let o = verdant_in(d, &args);
    ok(&o);
    o
}

fn rows(path: &Path) -> Vec<String> {
    let t = fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    t.lines().skip(1).map(str::to_string).collect()
}

/// The scene's files except report.json / report.md, which carry timings.
fn outputs(scene_dir: &Path) -> BTreeMap<String, Vec<u8>> {
    tree(scene_dir).into_iter().filter(|(k, _)| k != "report.json" && k != "report.md").collect()
}

fn species_stats(scene_dir: &Path, name: &str) -> serde_json::Value {
    let r = read_json(&scene_dir.join("report.json"));
    r["stages"]["scatter"]["species"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == name)
        .unwrap_or_else(|| panic!("no species {name} in the report"))["stats"]
        .clone()
}

fn species_rules(scene_dir: &Path, name: &str) -> serde_json::Value {
    let r = read_json(&scene_dir.join("report.json"));
    r["stages"]["scatter"]["species"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == name)
        .unwrap_or_else(|| panic!("no species {name} in the report"))["rules"]
        .clone()
}

// -------------------------------------------------------------------------------------------- preset

/// (line, column, message) of a preset that must not parse.
fn error_at(text: &str) -> (usize, usize, String) {
    match parse_preset(text, Path::new("w.toml")) {
        Ok(_) => panic!("expected an error for:\n{text}"),
        Err(e) => {
            let (line, column) = e.position().unwrap_or_else(|| panic!("no position in {e}"));
            (line, column, e.to_string())
        }
    }
}

#[test]
fn snow_section_errors_are_positioned_with_a_remedy() {
    let base = preset("w", "");
    let line_of_snow = base.lines().count() + 1;
    // a misspelt key: at the key, with the right spelling
    let (line, column, msg) = error_at(&format!("{base}[snow]\nhumidity = 0.5\ntemprature_c = -10.0\n"));
    assert_eq!((line, column), (line_of_snow + 2, 1), "{msg}");
    assert!(
        msg.contains("unknown key `temprature_c` in [snow]") && msg.contains("did you mean `temperature_c`?"),
        "{msg}"
    );
    // out of range: at the value, naming the range
    let (line, column, msg) = error_at(&format!("{base}[snow]\nhumidity = 1.5\n"));
    assert_eq!((line, column), (line_of_snow + 1, 12), "{msg}");
    assert!(msg.contains("`humidity` must be between 0 and 1"), "{msg}");
    let (line, _, msg) = error_at(&format!("{base}[snow]\ntemperature_c = 5.0\n"));
    assert_eq!(line, line_of_snow + 1);
    assert!(msg.contains("−40 and +2 °C"), "{msg}");
    let (line, column, msg) = error_at(&format!("{base}[snow]\nthin_plants = -0.1\n"));
    assert_eq!((line, column), (line_of_snow + 1, 15), "{msg}");
    // relations between keys: at the later key
    let (line, _, msg) = error_at(&format!("{base}[snow]\nnear_radius = 30.0\nfar_radius = 20.0\n"));
    assert_eq!(line, line_of_snow + 2);
    assert!(msg.contains("must be larger than near_radius"), "{msg}");
    let (line, _, msg) = error_at(&format!("{base}[snow]\nfull_slope = 40.0\nmax_slope = 30.0\n"));
    assert_eq!(line, line_of_snow + 2);
    assert!(msg.contains("full_slope = 40° must be below max_slope = 30°"), "{msg}");
    // wrong types and values
    let (_, _, msg) = error_at(&format!("{base}[snow]\nlayer = \"yes\"\n"));
    assert!(msg.contains("`layer` must be a boolean"), "{msg}");
    let (_, _, msg) = error_at(&format!("{base}[snow]\nrespawn = \"topp\"\n"));
    assert!(msg.contains("did you mean \"top\"?"), "{msg}");
    let (_, _, msg) = error_at(&format!("{base}[snow]\nfar_count = 0\nview_angle = 60.0\n"));
    assert!(msg.contains("far_count = 0 turns it off"), "{msg}");
    let (_, _, msg) = error_at(&format!("{base}[snow]\nwind_direction = [0.0, 0.0]\n"));
    assert!(msg.contains("has no direction"), "{msg}");
    let (line, column, msg) = error_at("[scene]\nname = \"x\"\n\n[snow]\n");
    assert_eq!((line, column), (4, 2), "{msg}");
    assert!(msg.contains("[snow] needs a terrain"), "{msg}");
    // a misspelt section name is caught too
    let (_, _, msg) = error_at(&format!("{base}[snwo]\n"));
    assert!(msg.contains("did you mean `[snow]`?"), "{msg}");

    // defaults: seeded from the scene seed; the shipped winter preset and the template parse
    let p = parse_preset(&format!("{base}[snow]\n"), Path::new("w.toml")).unwrap();
    let s = p.snow.expect("[snow] parsed");
    assert_eq!(s.flakes.seed, verdant::scene::preset::default_snow_seed(5));
    assert!(s.layer && s.thin_plants > 0.0 && s.emitter.far.is_some());
    let winter = fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("presets/winter_valley.toml")).unwrap();
    assert!(parse_preset(&winter, Path::new("presets/winter_valley.toml")).unwrap().snow.is_some());
    let t = template("t");
    assert!(t.contains("# [snow]"), "the template documents [snow]");
    // uncommenting the template's [snow] block gives a preset that parses with it
    let uncommented: String = t
        .lines()
        .skip_while(|l| !l.starts_with("# [snow]"))
        .take_while(|l| l.starts_with('#'))
        .map(|l| l.strip_prefix("# ").unwrap_or(l))
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| format!("{l}\n"))
        .collect();
    assert!(uncommented.contains("temperature_c"), "{uncommented}");
    let p = parse_preset(&format!("{base}{uncommented}"), Path::new("t.toml"))
        .unwrap_or_else(|e| panic!("{e}\n{uncommented}"));
    assert!(p.snow.is_some());
}

// --------------------------------------------------------------------------------------------- build

#[test]
fn build_writes_every_snow_file_reports_it_and_draws_the_cover() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/s.toml", &preset("s", &format!("{TREE}\n{GRASS}\n{SNOW}")));
    write(d, "p/n.toml", &preset("n", &format!("{TREE}\n{GRASS}")));
    build(d, "p/s.toml", "o", &[]);
    build(d, "p/n.toml", "o", &[]);
    let s = d.join("o/s");
    for f in [
        "flakes.png",
        "emitter.json",
        "particles.csv",
        "snowfall.glb",
        "cover_mask.png",
        "snow_layer.glb",
        "terrain_snow.glb",
    ] {
        assert!(s.join("snow").join(f).is_file(), "snow/{f} missing");
    }
    let m = read_json(&s.join("manifest.json"));
    let files: Vec<&str> = m["snow"]["files"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    assert_eq!(files.len(), 7, "{files:?}");
    let listed: Vec<&str> = m["files"].as_array().unwrap().iter().map(|f| f["path"].as_str().unwrap()).collect();
    assert!(files.iter().all(|f| listed.contains(f)), "every snow file is in the manifest's file list");

    // 200 near + 300 far flakes; every one inside the declared volume
    let e = read_json(&s.join("snow/emitter.json"));
    let particles = rows(&s.join("snow/particles.csv"));
    assert_eq!(particles.len(), 500);
    let (r1, r2, h) = (
        e["near_radius_m"].as_f64().unwrap(),
        e["far"]["outer_radius_m"].as_f64().unwrap(),
        e["fall_height_m"].as_f64().unwrap(),
    );
    for row in &particles {
        let f: Vec<&str> = row.split(',').collect();
        let (x, y, z): (f64, f64, f64) = (f[1].parse().unwrap(), f[2].parse().unwrap(), f[3].parse().unwrap());
        let r = x.hypot(z);
        assert!((0.0..=h).contains(&y), "{row}");
        match f[0] {
            "near" => assert!(r <= r1 * (1.0 + 1e-6), "{row}"),
            _ => assert!(
                r >= r1 * (1.0 - 1e-6) && r <= r2 * (1.0 + 1e-6) && x.atan2(-z).to_degrees().abs() <= 40.0 + 1e-3,
                "{row}"
            ),
        }
    }
    let v = e["flake_mass_kg"].as_f64().unwrap() * 9.80665 / e["drag_kg_s"].as_f64().unwrap();
    assert!((e["terminal_velocity_m_s"].as_f64().unwrap() - v).abs() < 1e-4 * v);

    // the mask: 128 px on the long side of a square terrain, some snow and some bare ground
    let mask = image::open(s.join("snow/cover_mask.png")).unwrap().to_luma8();
    assert_eq!((mask.width(), mask.height()), (128, 128));
    let covered = mask.pixels().filter(|p| p.0[0] >= 128).count() as f64 / (128.0 * 128.0);
    assert!(covered > 0.05 && covered < 0.95, "a snow line at 20 m on 0..50 m terrain covers part of it: {covered}");

    // report.json, report.md and the manifest carry the analyzer
    let r = read_json(&s.join("report.json"));
    let a = &r["stages"]["snow"]["analysis"];
    assert_eq!(a["near_particles"], 200);
    assert_eq!(a["far_particles"], 300);
    assert!((a["terminal_velocity_m_s"].as_f64().unwrap() - v).abs() < 1e-4 * v);
    assert!((a["mask_coverage"].as_f64().unwrap() - covered).abs() < 1e-9, "report coverage is the stored mask's");
    assert_eq!(a["cover_by_slope"].as_array().unwrap().len(), 5);
    assert_eq!(a["cover_by_altitude"].as_array().unwrap().len(), 5);
    assert!(r["timing"]["snow"]["seconds"].as_f64().is_some());
    // the manifest has the same figures (report.json widens f32 to f64 on the way, so compare values)
    let ma = &m["snow"]["analysis"];
    assert_eq!(ma["mask_coverage"], a["mask_coverage"]);
    assert_eq!(ma["particles_by_kind"], a["particles_by_kind"]);
    assert!((ma["terminal_velocity_m_s"].as_f64().unwrap() - v).abs() < 1e-4 * v);
    for key in ["cover_by_slope", "cover_by_altitude"] {
        let (x, y) = (ma[key].as_array().unwrap(), a[key].as_array().unwrap());
        assert!(
            x.iter().zip(y).all(|(p, q)| p["vertices"] == q["vertices"] && p["mean_weight"] == q["mean_weight"]),
            "{key}"
        );
    }
    let md = fs::read_to_string(s.join("report.md")).unwrap();
    assert!(
        md.contains("## Snow")
            && md.contains("Terminal velocity")
            && md.contains("| slope band |")
            && md.contains("| altitude band |"),
        "{md}"
    );

    // the preview shows the cover: brighter than the same scene without snow
    let brightness = |p: &Path| {
        let img = image::open(p).unwrap().to_rgba8();
        img.pixels().map(|p| p.0[0] as f64 + p.0[1] as f64 + p.0[2] as f64).sum::<f64>() / img.pixels().len() as f64
    };
    // the top-down drawing: map.png when preview.png is the perspective view
    let top = |dir: &Path| if dir.join("map.png").is_file() { dir.join("map.png") } else { dir.join("preview.png") };
    let (with, without) = (brightness(&top(&s)), brightness(&top(&d.join("o/n"))));
    assert!(with > without + 20.0, "preview with snow {with:.1}, without {without:.1}");
}

#[test]
fn snow_outputs_are_byte_identical_across_builds_and_thread_counts() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/s.toml", &preset("s", &format!("{TREE}\n{GRASS}\n{SNOW}")));
    build(d, "p/s.toml", "o1", &["--threads", "1"]);
    build(d, "p/s.toml", "o2", &["--threads", "2"]);
    // o3 at the default thread count reuses o2's plants (thread independence of the plants stage
    // is o1 against o2) and builds terrain, snow, scatter and view itself
    share_plants_cache(&d.join("o2"), &d.join("o3"));
    build(d, "p/s.toml", "o3", &[]);
    let first = outputs(&d.join("o1/s"));
    assert!(first.keys().any(|k| k.starts_with("snow/")));
    for other in ["o2/s", "o3/s"] {
        let o = outputs(&d.join(other));
        assert_eq!(first.keys().collect::<Vec<_>>(), o.keys().collect::<Vec<_>>());
        for (k, v) in &first {
            assert!(o[k] == *v, "{other}/{k} differs from the --threads 1 build");
        }
    }
}

#[test]
fn snow_thins_grass_and_flowers_by_the_reported_count_and_leaves_trees() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let species = format!("{TREE}\n{GRASS}\n{FLOWER}");
    write(d, "p/bare.toml", &preset("bare", &species));
    write(d, "p/snowy.toml", &preset("snowy", &format!("{species}\n{}", full_snow(0.5))));
    build(d, "p/bare.toml", "o", &[]);
    build(d, "p/snowy.toml", "o", &[]);
    let (bare, snowy) = (d.join("o/bare"), d.join("o/snowy"));
    // the cover is full everywhere
    let mask = image::open(snowy.join("snow/cover_mask.png")).unwrap().to_luma8();
    assert!(mask.pixels().all(|p| p.0[0] == 255), "full snow: every mask pixel at weight 1");

    // trees: untouched
    assert_eq!(
        fs::read(bare.join("placements/tree.csv")).unwrap(),
        fs::read(snowy.join("placements/tree.csv")).unwrap()
    );
    assert_eq!(species_rules(&snowy, "tree")["snow"], 0);
    for name in ["grass", "bloom"] {
        let (before, after) =
            (rows(&bare.join(format!("placements/{name}.csv"))), rows(&snowy.join(format!("placements/{name}.csv"))));
        let thinned = species_rules(&snowy, name)["snow"].as_u64().unwrap() as usize;
        assert_eq!(species_rules(&bare, name)["snow"], 0);
        // the same candidates, some dropped: what is left is a subset, and the count is the rule's
        assert_eq!(
            after.len() + thinned,
            before.len(),
            "{name}: {} kept + {thinned} thinned != {} without snow",
            after.len(),
            before.len()
        );
        let kept: std::collections::BTreeSet<&String> = before.iter().collect();
        assert!(
            after.iter().all(|r| kept.contains(r)),
            "{name}: an instance appears that the bare scene does not have"
        );
        // thin_plants = 0.5 at weight 1: about half survive
        let share = after.len() as f64 / before.len() as f64;
        assert!(
            before.len() > 1000 && (0.45..0.55).contains(&share),
            "{name}: {} of {} kept ({share:.3})",
            after.len(),
            before.len()
        );
        let summary = read_json(&snowy.join(format!("placements/{name}.json")));
        assert_eq!(summary["rules"]["snow"].as_u64().unwrap() as usize, thinned);
        // the analyzer expects what the snow leaves: count / expected near 1 with and without it
        for scene in [&bare, &snowy] {
            let ratio = species_stats(scene, name)["count_ratio"].as_f64().unwrap();
            assert!((0.93..1.07).contains(&ratio), "{name} in {}: count / expected = {ratio}", scene.display());
        }
    }
}

#[test]
fn snow_cache_hits_on_rebuild_and_misses_when_a_snow_key_changes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/c.toml", &preset("c", &format!("{GRASS}\n{SNOW}")));
    let s = d.join("o/c");
    build(d, "p/c.toml", "o", &[]);
    assert!(!timing_cached(&s, "snow"));
    let first = outputs(&s);

    let o = build(d, "p/c.toml", "o", &[]);
    assert_eq!(summary_row(&o, "c")[1], "built*");
    for stage in ["terrain", "snow", "scatter", "preview"] {
        assert!(timing_cached(&s, stage), "{stage} should be cached on an unchanged rebuild");
    }
    assert!(outputs(&s) == first, "a cached build restored different bytes");

    // a crystal setting: the snow recomputes (new atlas), the terrain does not
    write(
        d,
        "p/c.toml",
        &preset("c", &format!("{GRASS}\n{}", SNOW.replace("temperature_c = -15.0", "temperature_c = -6.0"))),
    );
    build(d, "p/c.toml", "o", &[]);
    assert!(timing_cached(&s, "terrain"));
    assert!(!timing_cached(&s, "snow"), "a changed temperature_c must recompute the snow");
    assert_ne!(fs::read(s.join("snow/flakes.png")).unwrap(), first["snow/flakes.png"]);

    // the plant thinning: the snow stage and the scatter that reads its mask both recompute
    write(d, "p/c.toml", &preset("c", &format!("{GRASS}\n{}", SNOW.replace("thin_plants = 0.8", "thin_plants = 0.2"))));
    build(d, "p/c.toml", "o", &[]);
    assert!(timing_cached(&s, "terrain"));
    assert!(!timing_cached(&s, "snow") && !timing_cached(&s, "scatter"));
    assert!(
        rows(&s.join("placements/grass.csv")).len() > rows_of(&first["placements/grass.csv"]),
        "less thinning keeps more grass"
    );

    // back to the first settings: every stage from the cache, the first bytes again
    write(d, "p/c.toml", &preset("c", &format!("{GRASS}\n{SNOW}")));
    build(d, "p/c.toml", "o", &[]);
    assert!(timing_cached(&s, "snow") && timing_cached(&s, "scatter"));
    assert!(outputs(&s) == first);
}

fn rows_of(bytes: &[u8]) -> usize {
    bytes.iter().filter(|&&b| b == b'\n').count() - 1
}

#[test]
fn a_preset_without_snow_writes_no_snow_folder() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/n.toml", &preset("n", GRASS));
    build(d, "p/n.toml", "o", &[]);
    let s = d.join("o/n");
    assert!(!s.join("snow").exists());
    assert!(read_json(&s.join("manifest.json"))["snow"].is_null());
    let r = read_json(&s.join("report.json"));
    assert!(r["stages"].get("snow").is_none() && r["timing"].get("snow").is_none(), "{r}");
    assert!(!fs::read_to_string(s.join("report.md")).unwrap().contains("## Snow"));
    assert_eq!(species_rules(&s, "grass")["snow"], 0);

    // with [snow] but the stage skipped: no snow/ and no thinning either
    write(d, "p/m.toml", &preset("m", &format!("{GRASS}\n{}", full_snow(1.0))));
    build(d, "p/m.toml", "o", &["--skip", "snow"]);
    assert!(!d.join("o/m/snow").exists());
    assert_eq!(
        fs::read(d.join("o/m/placements/grass.csv")).unwrap(),
        fs::read(s.join("placements/grass.csv")).unwrap()
    );
}

#[test]
fn the_terrain_shows_the_snow_the_cover_puts_down() {
    // issue 15 item 2: terrain layers from the snow cover (winter_valley showed no snow in engines:
    // the layers had a fixed 2,500 m snowline)
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/s.toml", &preset("s", &format!("{GRASS}\n{SNOW}")));
    write(d, "p/n.toml", &preset("n", GRASS));
    build(d, "p/s.toml", "o", &[]);
    build(d, "p/n.toml", "o", &[]);
    let s = d.join("o/s");
    let terrain = verdant::validate::read_scene(&s.join("terrain/terrain.glb")).unwrap();
    let snowy = verdant::validate::read_scene(&s.join("snow/terrain_snow.glb")).unwrap();
    // on every surface vertex, the snow layer is the cover's weight to a byte
    let layers = surface_attribute(&terrain, "_LAYER_WEIGHTS");
    let cover = surface_attribute(&snowy, "_SNOW");
    assert_eq!(layers.len(), cover.len());
    let (mut covered, mut bare) = (0, 0);
    for ((q, l), (q2, c)) in layers.iter().zip(&cover) {
        assert_eq!(q, q2);
        assert!((l[3] - c[0]).abs() <= 1.0 / 255.0 + 1e-6, "at {q:?}: layer snow {} cover {}", l[3], c[0]);
        covered += usize::from(c[0] >= 0.95);
        bare += usize::from(c[0] <= 0.05);
    }
    assert!(covered > 100 && bare > 100, "a snow line at 20 m on 0..50 m terrain: {covered} covered, {bare} bare");

    // the base colour an engine shows: snow-white texels where the cover is full, none where bare
    let material = terrain.materials.iter().find(|m| m.name == "terrain").unwrap();
    let png = &terrain.textures[material.base_color_texture.unwrap()].png;
    let img = image::load_from_memory(png).unwrap().to_rgb8();
    let extent = 128.0 * 2.0;
    let texel = |q: &[f32; 3]| {
        let x = ((q[0] / extent) * img.width() as f32).clamp(0.0, img.width() as f32 - 1.0) as u32;
        let y = ((q[2] / extent) * img.height() as f32).clamp(0.0, img.height() as f32 - 1.0) as u32;
        img.get_pixel(x, y).0
    };
    let white = |p: [u8; 3]| p.iter().all(|&c| c >= 200);
    let (mut agree, mut total) = (0usize, 0usize);
    for (q, c) in &cover {
        if c[0] >= 0.95 || c[0] <= 0.05 {
            total += 1;
            agree += usize::from(white(texel(q)) == (c[0] >= 0.95));
        }
    }
    assert!(agree as f64 >= 0.97 * total as f64, "{agree} of {total} texels white exactly where the cover is full");

    // the report says where the snow came from and how closely the layer follows the cover
    let r = read_json(&s.join("report.json"));
    assert_eq!(r["stages"]["terrain"]["layers"]["snow"], "snow cover");
    let a = &r["stages"]["snow"]["layer_agreement"];
    assert!(a["max_abs_difference"].as_f64().unwrap() <= 1.0 / 255.0 + 1e-6, "{a}");
    assert_eq!(a["vertices"].as_u64().unwrap() as usize, cover.len());
    // without [snow], the fixed snowline (far above this terrain): no snow at all
    let n = read_json(&d.join("o/n/report.json"));
    assert_eq!(n["stages"]["terrain"]["layers"]["snow"], "snowline");
    assert_eq!(n["stages"]["terrain"]["layers"]["coverage"][3], 0.0);
}
