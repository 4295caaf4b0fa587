//! Preset parsing: the shipped presets and the template parse; every kind of mistake is an error
//! naming file, line and column with a remedy; no text makes the parser panic.

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use verdant::failure::Failure;
use verdant::heightfield::{Encoding, DEFAULT_MAX_SAMPLES};
use verdant::plants::SpeciesKind;
use verdant::scatter::{Exclusion, Placement, UNBOUNDED_ALTITUDE_M};
use verdant::scene::preset::{
    demo_preset, load_preset, parse_preset, procedural_heightfield, template, PresetError, DEFAULT_MAX_INSTANCES,
};
use verdant::scene::{Format, TerrainSource};
use verdant::synth::{self, NoiseKind};
use verdant::terrain::job::MeshMode;

fn manifest_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Parses `text` as `p.toml` and returns the error's display text, panicking if it parsed.
fn error_of(text: &str) -> String {
    match parse_preset(text, Path::new("p.toml")) {
        Ok(p) => panic!("expected an error, parsed {p:?}"),
        Err(e) => {
            assert_eq!(e.exit_code(), 2);
            e.to_string()
        }
    }
}

const MINIMAL: &str = "[scene]\nname = \"x\"\n";

fn with_terrain(terrain: &str) -> String {
    format!("{MINIMAL}[terrain]\n{terrain}\n")
}

const PROC: &str = "procedural = { kind = \"fbm\", size = 65, relief = 10.0 }";

#[test]
fn shipped_presets_load() {
    let mut names = Vec::new();
    for dir in [manifest_dir().join("presets"), manifest_dir().join("presets/worlds")] {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let preset = load_preset(&path).unwrap_or_else(|e| panic!("{e}"));
                assert!(preset.terrain.is_some(), "{}", path.display());
                names.push(preset.scene.name);
            }
        }
    }
    names.sort();
    assert!(names.len() >= 3, "{names:?}");
    for name in ["alpine", "meadow", "highlands"] {
        assert!(names.contains(&name.to_string()), "{name} not in {names:?}");
    }
}

/// Issue 18 item 4: a world-sized procedural preset (8193² samples at 1 m with grass and trees),
/// split by `--shard` into units a machine builds one after another (check.sh step 3d builds it so).
#[test]
fn the_world_preset_is_world_sized_with_grass_and_trees() {
    let p = load_preset(&manifest_dir().join("presets/worlds/highlands.toml")).unwrap();
    let t = p.terrain.as_ref().unwrap();
    match &t.source {
        TerrainSource::Fbm { size, cell_size_m, .. } => assert_eq!((*size, *cell_size_m), (8193, 1.0)),
        other => panic!("{other:?}"),
    }
    let kinds: Vec<String> = p.species.iter().map(|s| format!("{:?}", s.kind)).collect();
    assert!(kinds.iter().any(|k| k == "Tree") && kinds.iter().any(|k| k == "Grass"), "{kinds:?}");
    let out = tempfile::tempdir().unwrap();
    let units = verdant::scene::shard::units(&p, out.path()).unwrap();
    let names: Vec<&str> = units.iter().map(|u| u.name.as_str()).collect();
    // the terrain's 16 bands of 512 rows (its 512-sample chunks), the placements of the two tile
    // rows of 256 m starting in each, then the species
    let bands: Vec<String> =
        (0..16).map(|k| format!("terrain band {k} (rows {}-{})", 512 * k, 512 * (k + 1))).collect();
    assert_eq!(names[..16], bands.iter().map(String::as_str).collect::<Vec<_>>()[..]);
    let placements: Vec<String> =
        (0..16).map(|k| format!("placements of tile rows {}-{} (band {k})", 2 * k, 2 * k + 2)).collect();
    assert_eq!(names[16..32], placements.iter().map(String::as_str).collect::<Vec<_>>()[..]);
    assert_eq!(names[32..], ["species pine", "species grass"]);
}

#[test]
fn alpine_preset_is_what_the_issue_asks() {
    let p = load_preset(&manifest_dir().join("presets/alpine.toml")).unwrap();
    assert_eq!(p.scene.formats, vec![Format::Glb, Format::Obj]);
    let t = p.terrain.unwrap();
    match t.source {
        TerrainSource::Fbm { size, relief_m, cell_size_m, noise, .. } => {
            assert_eq!((size, relief_m, cell_size_m, noise), (1025, 1500.0, 10.0, NoiseKind::Ridged));
        }
        other => panic!("{other:?}"),
    }
    assert_eq!((t.mode, t.max_error_m, t.chunk, t.skirt_m), (MeshMode::Tin, 2.0, Some(256), Some(10.0)));
    assert_eq!(t.lods, vec![2.0, 8.0, 32.0]);
}

#[test]
fn template_parses_and_loads() {
    let text = template("my-scene");
    let p = parse_preset(&text, Path::new("my-scene.toml")).unwrap_or_else(|e| panic!("{e}\n{text}"));
    assert_eq!(p.scene.name, "my-scene");
    let t = p.terrain.unwrap();
    assert!(matches!(t.source, TerrainSource::Fbm { .. }));
    assert!(t.chunk.is_some() && !t.lods.is_empty());
    // every line is a comment, blank, or a key/section (it is meant to be read)
    assert!(text.lines().filter(|l| l.trim_start().starts_with('#')).count() > 20);

    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("my-scene.toml");
    std::fs::write(&file, &text).unwrap();
    assert_eq!(load_preset(&file).unwrap().scene.name, "my-scene");
}

#[test]
fn demo_preset_builds_in_memory() {
    let d = demo_preset();
    assert_eq!(d.path, None);
    assert_eq!(d.scene.name, "demo");
    assert_eq!(d.scene.formats, vec![Format::Glb]);
    let t = d.terrain.unwrap();
    assert!(t.chunk.is_some());
    assert!(t.lods.len() >= 2 && t.lods.windows(2).all(|w| w[0] < w[1]));
    let hf = procedural_heightfield(&t.source).unwrap();
    assert!(hf.heights.iter().all(|h| h.is_finite()));
}

#[test]
fn defaults_fill_absent_keys() {
    let p = parse_preset(&with_terrain(PROC), Path::new("p.toml")).unwrap();
    assert_eq!(p.path.as_deref(), Some(Path::new("p.toml")));
    assert_eq!(p.scene.seed, 0);
    assert_eq!(p.scene.formats, vec![Format::Glb]);
    let t = p.terrain.unwrap();
    assert_eq!(t.mode, MeshMode::Tin);
    assert_eq!(t.max_error_m, 1.0);
    assert_eq!(t.grid_step, 1);
    assert_eq!((t.max_triangles, t.chunk, t.skirt_m, t.base_m), (None, None, None, None));
    assert!(t.lods.is_empty());
    match t.source {
        TerrainSource::Fbm { size, seed, relief_m, cell_size_m, noise } => {
            assert_eq!((size, seed, relief_m, cell_size_m, noise), (65, 0, 10.0, 1.0, NoiseKind::Fbm));
        }
        other => panic!("{other:?}"),
    }
    // a preset without [terrain] is valid (nothing to build there yet)
    assert_eq!(parse_preset(MINIMAL, Path::new("p.toml")).unwrap().terrain, None);
}

#[test]
fn procedural_seed_defaults_to_scene_seed() {
    let text = format!("[scene]\nname = \"x\"\nseed = 99\n[terrain]\n{PROC}\n");
    let p = parse_preset(&text, Path::new("p.toml")).unwrap();
    assert!(matches!(p.terrain.unwrap().source, TerrainSource::Fbm { seed: 99, .. }));
}

#[test]
fn heightmap_keys_have_the_cli_meanings() {
    let text = with_terrain(
        "heightmap = \"maps/h.r16\"\nencoding = \"r16\"\nsize = [33, 17]\ncell_size = 30\n\
         height_scale = 2000.0\nheight_offset = -50\nmax_samples = 1000\nmode = \"grid\"\ngrid_step = 4\n\
         base = 20\nmax_triangles = 5000",
    );
    let p = parse_preset(&text, Path::new("presets/p.toml")).unwrap();
    let t = p.terrain.unwrap();
    let TerrainSource::Heightmap { path, decode } = t.source else { panic!() };
    assert_eq!(path, PathBuf::from("presets/maps/h.r16"));
    assert_eq!(decode.encoding, Encoding::R16);
    assert_eq!(decode.size, Some((33, 17)));
    assert_eq!(decode.cell_size_m, 30.0);
    assert_eq!((decode.height_scale_m, decode.height_offset_m, decode.max_samples), (2000.0, -50.0, 1000));
    assert_eq!((t.mode, t.grid_step, t.base_m, t.max_triangles), (MeshMode::Grid, 4, Some(20.0), Some(5000)));

    let p = parse_preset(&with_terrain("heightmap = \"h.png\""), Path::new("p.toml")).unwrap();
    let TerrainSource::Heightmap { path, decode } = p.terrain.unwrap().source else { panic!() };
    assert_eq!(path, PathBuf::from("h.png"));
    assert_eq!((decode.encoding, decode.cell_size_m, decode.height_scale_m), (Encoding::Auto, 1.0, 100.0));
    assert_eq!((decode.height_offset_m, decode.max_samples), (0.0, DEFAULT_MAX_SAMPLES));
    for name in ["gray", "terrain-rgb", "terrarium", "hgt", "float", "auto"] {
        let text = with_terrain(&format!("heightmap = \"h.png\"\nencoding = \"{name}\""));
        assert!(parse_preset(&text, Path::new("p.toml")).is_ok(), "{name}");
    }
}

#[test]
fn relative_paths_resolve_against_the_preset_folder() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("presets/maps")).unwrap();
    std::fs::write(dir.path().join("presets/maps/h.png"), b"not really a png").unwrap();
    let file = dir.path().join("presets/valley.toml");
    std::fs::write(&file, with_terrain("heightmap = \"maps/h.png\"")).unwrap();
    let p = load_preset(&file).unwrap();
    let TerrainSource::Heightmap { path, .. } = p.terrain.unwrap().source else { panic!() };
    assert_eq!(path, dir.path().join("presets/maps/h.png"));
    assert!(path.is_file());

    // absolute paths stay as they are
    let abs = dir.path().join("presets/maps/h.png");
    let p = parse_preset(&with_terrain(&format!("heightmap = {:?}", abs.display().to_string())), &file).unwrap();
    let TerrainSource::Heightmap { path, .. } = p.terrain.unwrap().source else { panic!() };
    assert_eq!(path, abs);
}

#[test]
fn missing_heightmap_is_named_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("valley.toml");
    std::fs::write(&file, with_terrain("cell_size = 2\nheightmap = \"maps/nowhere.png\"")).unwrap();
    let e = load_preset(&file).unwrap_err();
    let resolved = dir.path().join("maps/nowhere.png");
    match &e {
        PresetError::MissingInput { input, line, column, .. } => {
            assert_eq!(input, &resolved);
            assert_eq!((*line, *column), (5, 13));
        }
        other => panic!("{other:?}"),
    }
    let s = e.to_string();
    assert!(s.starts_with(&format!("{}:5:13: heightmap `{}` not found", file.display(), resolved.display())), "{s}");
    assert_eq!(e.position(), Some((5, 13)));
    // parse_preset does not look at the disk
    assert!(parse_preset(&std::fs::read_to_string(&file).unwrap(), &file).is_ok());
    // a folder is not a heightmap
    std::fs::create_dir_all(dir.path().join("maps/nowhere.png")).unwrap();
    assert!(load_preset(&file).unwrap_err().to_string().contains("is not a file"));
}

#[test]
fn missing_preset_file_is_named() {
    let e = load_preset(Path::new("/nonexistent/x.toml")).unwrap_err();
    assert!(matches!(e, PresetError::Read { .. }));
    assert!(e.to_string().starts_with("/nonexistent/x.toml: cannot read the preset"), "{e}");
    assert_eq!(e.exit_code(), 2);
}

#[test]
fn unknown_key_has_position_and_did_you_mean() {
    let text = with_terrain(&format!("{PROC}\nmax_eror = 2.0"));
    let e = error_of(&text);
    assert_eq!(e, "p.toml:5:1: unknown key `max_eror` in [terrain]; did you mean `max_error`?");

    let e = error_of("[scene]\nname = \"x\"\n  formts = [\"glb\"]\n");
    assert_eq!(e, "p.toml:3:3: unknown key `formts` in [scene]; did you mean `formats`?");

    // a key of another table says where it belongs
    let e = error_of(&with_terrain(&format!("{PROC}\nformats = [\"glb\"]")));
    assert!(e.starts_with("p.toml:5:1: unknown key `formats` in [terrain]; `formats` belongs in [scene]"), "{e}");

    // nothing close: the known keys are listed
    let e = error_of("[scene]\nname = \"x\"\nzzz = 1\n");
    assert!(
        e.starts_with("p.toml:3:1: unknown key `zzz` in [scene]; the keys of [scene] are `name`, `seed`, `formats`"),
        "{e}"
    );

    // inside the procedural table
    let e = error_of(&with_terrain("procedural = { kind = \"fbm\", size = 65, releif = 10.0 }"));
    assert_eq!(e, "p.toml:4:41: unknown key `releif` in `procedural`; did you mean `relief`?");
}

#[test]
fn unknown_section_lists_the_known_ones() {
    let e = error_of(&format!("{MINIMAL}\n[weather]\nflakes = 1\n"));
    assert!(
        e.starts_with("p.toml:4:2: unknown section `[weather]`; known sections are `[scene]`, `[terrain]`, `[[species]]`, `[scatter]`"),
        "{e}"
    );
    let e = error_of(&format!("{MINIMAL}\n[[specie]]\nname = \"a\"\n"));
    assert!(e.starts_with("p.toml:4:3: unknown section `[[specie]]`; did you mean `[[species]]`?"), "{e}");
    let e = error_of(&format!("{MINIMAL}[terain]\n{PROC}\n"));
    assert!(e.starts_with("p.toml:3:2: unknown section `[terain]`; did you mean `[terrain]`?"), "{e}");
    let e = error_of("name = \"x\"\n[scene]\n");
    assert_eq!(e, "p.toml:1:1: key `name` is outside any section; move it under [scene]");
    let e = error_of("scene = 3\n");
    assert!(e.starts_with("p.toml:1:1: `scene` must be a section `[scene]`, found an integer"), "{e}");
    let e = error_of("");
    assert!(e.starts_with("p.toml:1:1: the preset has no [scene] section"), "{e}");
}

#[test]
fn wrong_types_have_positions() {
    let e = error_of(&with_terrain(&format!("{PROC}\nchunk = \"256\"")));
    assert_eq!(e, "p.toml:5:9: `chunk` must be an integer, found a string; write it like `chunk = 256`");
    let e = error_of(&with_terrain(&format!("{PROC}\nchunk = 256.0")));
    assert!(e.starts_with("p.toml:5:9: `chunk` must be an integer, found a float"), "{e}");
    let e = error_of(&with_terrain(&format!("{PROC}\nmax_error = true")));
    assert!(e.starts_with("p.toml:5:13: `max_error` must be a number, found a boolean"), "{e}");
    let e = error_of("[scene]\nname = 5\n");
    assert!(e.starts_with("p.toml:2:8: `name` must be a string, found an integer"), "{e}");
    let e = error_of("[scene]\nname = \"x\"\nformats = \"glb\"\n");
    assert!(e.starts_with("p.toml:3:11: `formats` must be an array of strings, found a string"), "{e}");
    let e = error_of(&with_terrain("procedural = \"fbm\""));
    assert!(e.starts_with("p.toml:4:14: `procedural` must be a table, found a string"), "{e}");
    let e = error_of(&with_terrain(&format!("{PROC}\nlods = [1, \"4\"]")));
    assert!(e.starts_with("p.toml:5:12: `lods` must be a number, found a string"), "{e}");
    // integers are fine where metres are expected
    let p = parse_preset(&with_terrain(&format!("{PROC}\nmax_error = 2\nskirt = 3")), Path::new("p.toml")).unwrap();
    assert_eq!(p.terrain.unwrap().max_error_m, 2.0);
}

#[test]
fn exactly_one_height_source() {
    let e = error_of(&with_terrain(&format!("heightmap = \"h.png\"\n{PROC}")));
    assert!(e.starts_with("p.toml:5:1: [terrain] has both `heightmap` and `procedural`"), "{e}");
    let e = error_of(&with_terrain("max_error = 1.0"));
    assert!(e.starts_with("p.toml:3:2: [terrain] has neither `heightmap` nor `procedural`"), "{e}");
    // heightmap-only keys next to a procedural map
    let e = error_of(&with_terrain(&format!("{PROC}\nencoding = \"gray\"")));
    assert!(e.starts_with("p.toml:5:1: `encoding` applies to a heightmap file, not to a procedural map"), "{e}");
}

#[test]
fn invalid_values_are_refused_where_they_are() {
    let cases: &[(&str, &str)] = &[
        ("max_error = -1.0", "`max_error` must be 0 or more, got -1"),
        ("max_error = nan", "`max_error` must be a finite number"),
        ("max_error = inf", "`max_error` must be a finite number"),
        ("chunk = 1", "`chunk` must be between 2 and"),
        ("chunk = -5", "`chunk` must be between 2 and"),
        ("skirt = 0", "`skirt` must be greater than 0"),
        ("base = -2.5", "`base` must be greater than 0"),
        ("grid_step = 0", "`grid_step` must be between 1 and"),
        ("max_triangles = 1", "`max_triangles` must be between 2 and"),
        ("cell_size = 0", "`cell_size` must be greater than 0"),
        ("lods = [2.0, 2.0]", "`lods` must increase strictly (finest level first), but 2 follows 2"),
        ("lods = [8.0, 2.0]", "`lods` must increase strictly"),
        ("lods = [0.0, 2.0]", "`lods` must be greater than 0"),
        ("mode = \"mesh\"", "unknown `mode` value \"mesh\"; allowed values are tin, grid"),
        ("mode = \"grd\"", "unknown `mode` value \"grd\"; did you mean \"grid\"?"),
    ];
    for (line, expected) in cases {
        let e = error_of(&with_terrain(&format!("{PROC}\n{line}")));
        assert!(e.starts_with("p.toml:5:"), "{line}: {e}");
        assert!(e.contains(expected), "{line}: {e}");
    }
    let e = error_of(&with_terrain(&format!("{PROC}\nmode = \"grid\"\nlods = [1.0, 2.0]")));
    assert!(e.starts_with("p.toml:6:1: `lods` needs mode = \"tin\""), "{e}");
    let procedural: &[(&str, &str)] = &[
        ("size = 1, relief = 10.0", "`size` must be between 2 and 8193, got 1"),
        ("size = 9000, relief = 10.0", "`size` must be between 2 and 8193, got 9000"),
        ("size = 65, relief = 0.0", "`relief` must be greater than 0"),
        ("size = 65", "`procedural` has no `relief`"),
        ("relief = 10.0", "`procedural` has no `size`"),
        (
            "kind = \"perlin\", size = 65, relief = 1.0",
            "unknown `kind` value \"perlin\"; allowed values are fbm, ridged",
        ),
        ("kind = \"ridge\", size = 65, relief = 1.0", "did you mean \"ridged\"?"),
        ("seed = -1, size = 65, relief = 1.0", "`seed` must be between 0 and"),
    ];
    for (inner, expected) in procedural {
        let e = error_of(&with_terrain(&format!("procedural = {{ {inner} }}")));
        assert!(e.starts_with("p.toml:4:"), "{inner}: {e}");
        assert!(e.contains(expected), "{inner}: {e}");
    }
    let scene: &[(&str, &str)] = &[
        ("name = \"my scene\"", "p.toml:2:8: scene name `my scene` contains ' '"),
        ("name = \"../up\"", "p.toml:2:8: scene name `../up` contains '.'"),
        ("name = \"\"", "p.toml:2:8: the scene name is empty"),
        ("name = \"x\"\nformats = []", "p.toml:3:11: `formats` is empty"),
        ("name = \"x\"\nformats = [\"glb\", \"obj\", \"glb\"]", "p.toml:3:26: format \"glb\" is listed twice"),
        (
            "name = \"x\"\nformats = [\"fbx\"]",
            "p.toml:3:12: unknown `formats` value \"fbx\"; allowed values are glb, gltf, obj",
        ),
        ("name = \"x\"\nformats = [\"gltff\"]", "did you mean \"gltf\"?"),
        ("name = \"x\"\nseed = -3", "p.toml:3:8: `seed` must be between 0 and"),
        ("seed = 3", "p.toml:1:2: [scene] has no `name`; add `name = \"my-scene\"`"),
    ];
    for (body, expected) in scene {
        let e = error_of(&format!("[scene]\n{body}\n"));
        assert!(e.contains(expected), "{body}: {e}");
    }
}

#[test]
fn all_formats_parse() {
    let p =
        parse_preset("[scene]\nname = \"x\"\nformats = [\"obj\", \"gltf\", \"glb\"]\n", Path::new("p.toml")).unwrap();
    assert_eq!(p.scene.formats, vec![Format::Obj, Format::Gltf, Format::Glb]);
}

#[test]
fn syntax_errors_have_positions() {
    let e = error_of("[scene]\nname = \"x\n");
    assert!(e.starts_with("p.toml:2:"), "{e}");
    assert!(e.contains("TOML syntax"), "{e}");
    let e = error_of("[scene]\nname = \"x\"\nname = \"y\"\n");
    assert!(e.starts_with("p.toml:3:"), "{e}");
}

#[test]
fn error_display_has_file_line_column_problem_and_remedy() {
    let e = parse_preset(&with_terrain(&format!("{PROC}\nlod = [1.0]")), Path::new("presets/alpine.toml")).unwrap_err();
    assert_eq!(e.position(), Some((5, 1)));
    let PresetError::At { file, line, column, problem, remedy } = &e else { panic!("{e:?}") };
    assert_eq!((file.as_path(), *line, *column), (Path::new("presets/alpine.toml"), 5, 1));
    assert_eq!(e.to_string(), format!("presets/alpine.toml:5:1: {problem}; {remedy}"));
    assert_eq!(remedy, "did you mean `lods`?");
}

#[test]
fn fbm_is_deterministic_and_in_range() {
    let source = TerrainSource::Fbm { size: 97, seed: 3, relief_m: 250.0, cell_size_m: 5.0, noise: NoiseKind::Ridged };
    let a = procedural_heightfield(&source).unwrap();
    let b = procedural_heightfield(&source).unwrap();
    assert_eq!(a, b);
    assert_eq!(a, synth::ridged(97, 5.0, 250.0, 3));
    assert_eq!((a.width, a.height, a.cell_size_m), (97, 97, 5.0));
    assert!(a.heights.iter().all(|h| (0.0..=250.0).contains(h)));
    let f = synth::fbm(97, 5.0, 250.0, 3);
    assert_ne!(a, f);
    assert_eq!(f, synth::fbm(97, 5.0, 250.0, 3));
    assert!(f.heights.iter().all(|h| (0.0..=250.0).contains(h)));
    let heightmap = TerrainSource::Heightmap { path: "h.png".into(), decode: Default::default() };
    assert!(procedural_heightfield(&heightmap).is_none());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    /// Arbitrary text never panics the parser; every error has a position or is a syntax error.
    #[test]
    fn arbitrary_text_never_panics(text in "\\PC{0,200}") {
        let _ = parse_preset(&text, Path::new("p.toml"));
    }

    /// TOML-ish text from the preset vocabulary never panics and errors are well formed.
    #[test]
    fn preset_like_text_never_panics(
        lines in proptest::collection::vec(
            prop_oneof![
                Just("[scene]".to_string()),
                Just("[terrain]".to_string()),
                Just("[species]".to_string()),
                Just("[[species]]".to_string()),
                Just("[scatter]".to_string()),
                "(kind|max_density|placement|min_spacing|slope|altitude|water_level|scale|random_yaw|align_to_normal|max_instances|tile|density_map) = (\"[a-z .]{0,6}\"|-?[0-9]{1,12}|-?[0-9]\\.[0-9]|\\[[0-9, .\"a-z-]{0,12}\\]|true|nan)",
                "exclusion = (\\{ ?(species = \"[a-z]{0,3}\"|radius = -?[0-9]) ?\\}|\\[\\{ ?species = \"[a-z]{0,3}\" ?\\}\\]|[0-9])",
                "(name|seed|formats|heightmap|procedural|chunk|lods|max_error|skirt|base|mode|size|relief|kind|cell_size|encoding) = (\"[a-z .]{0,6}\"|-?[0-9]{1,12}|-?[0-9]\\.[0-9]|\\[[0-9, .\"a-z]{0,12}\\]|\\{ ?(size|relief|kind) = [0-9]{1,5} ?\\}|nan|inf|true)",
                "\\PC{0,20}",
            ],
            0..12,
        )
    ) {
        let text = lines.join("\n");
        if let Err(e) = parse_preset(&text, Path::new("p.toml")) {
            let s = e.to_string();
            prop_assert!(s.starts_with("p.toml:"), "{}", s);
            let (line, column) = e.position().unwrap();
            prop_assert!(line >= 1 && line <= text.lines().count().max(1) + 1 && column >= 1, "{}", s);
        }
    }

    /// Mutating one byte of the template never panics the parser.
    #[test]
    fn mutated_template_never_panics(at in 0usize..2000, byte in 0u8..128) {
        let mut bytes = template("t").into_bytes();
        let i = at % bytes.len();
        bytes[i] = byte;
        let text = String::from_utf8_lossy(&bytes).into_owned();
        let _ = parse_preset(&text, Path::new("t.toml"));
    }
}

#[test]
fn docs_examples_parse() {
    let docs = std::fs::read_to_string(manifest_dir().join("docs/presets.md")).unwrap();
    let mut parsed = 0;
    for block in docs.split("```toml\n").skip(1) {
        let block = block.split("```").next().unwrap();
        let mut text = if block.contains("[scene]") { block.to_string() } else { format!("{MINIMAL}{block}") };
        if text.contains("[[species]]") && !text.contains("[terrain]") {
            text = format!("{text}\n[terrain]\n{PROC}\n");
        }
        parse_preset(&text, Path::new("docs/example.toml")).unwrap_or_else(|e| panic!("{e}\n{text}"));
        parsed += 1;
    }
    assert!(parsed >= 2);
}

// ---------------------------------------------------------------------------------------------
// [[species]] and [scatter]

/// A preset with a small procedural terrain and `rest` after it.
fn with_species(rest: &str) -> String {
    format!("{MINIMAL}[terrain]\n{PROC}\n{rest}\n")
}

/// Line 5 is the first line of `rest` in [`with_species`].
fn species_error(rest: &str) -> String {
    error_of(&with_species(rest))
}

const TREE: &str = "[[species]]\nname = \"oak\"\nkind = \"tree\"\nmax_density = 0.01";

#[test]
fn species_every_key_parses() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("maps")).unwrap();
    std::fs::write(dir.path().join("maps/d.png"), b"x").unwrap();
    std::fs::write(dir.path().join("maps/m.png"), b"x").unwrap();
    let file = dir.path().join("s.toml");
    let text = with_species(
        "[scatter]\ntile = 64\n\
         [[species]]\nname = \"oak\"\nkind = \"tree\"\nmax_density = 0.01\n\
         [[species]]\nname = \"Grass_2\"\nkind = \"grass\"\ndensity_map = \"maps/d.png\"\nmask = \"maps/m.png\"\n\
         max_density = 2\nplacement = \"poisson\"\nmin_spacing = 0.25\nslope = [5, 40.5]\naltitude = [-10.0, 300]\n\
         water_level = 1.5\nscale = [0.5, 2.0]\nrandom_yaw = false\nalign_to_normal = 0.25\n\
         exclusion = [{ species = \"oak\", radius = 1.5 }, { species = \"Grass_2\", radius = 0.1 }]\n\
         seed = 9\nmax_instances = 1234",
    );
    std::fs::write(&file, &text).unwrap();
    let p = load_preset(&file).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(p.scatter.tile_m, 64.0);
    assert_eq!(p.species.len(), 2);
    let g = &p.species[1];
    assert_eq!((g.rules.name.as_str(), g.kind), ("Grass_2", SpeciesKind::Grass));
    assert_eq!(g.rules.density_map.as_deref(), Some(dir.path().join("maps/d.png").as_path()));
    assert_eq!(g.rules.mask.as_deref(), Some(dir.path().join("maps/m.png").as_path()));
    assert_eq!((g.rules.max_density, g.rules.placement, g.rules.min_spacing_m), (2.0, Placement::Poisson, 0.25));
    assert_eq!(
        (g.rules.slope_deg, g.rules.altitude_m, g.rules.water_level_m),
        ([5.0, 40.5], [-10.0, 300.0], Some(1.5))
    );
    assert_eq!((g.rules.scale, g.rules.random_yaw, g.rules.align_to_normal), ([0.5, 2.0], false, 0.25));
    assert_eq!(
        g.rules.exclusions,
        vec![
            Exclusion { species: "oak".into(), radius_m: 1.5 },
            Exclusion { species: "Grass_2".into(), radius_m: 0.1 }
        ]
    );
    assert_eq!((g.rules.seed, g.rules.max_instances), (9, 1234));
    // a single exclusion table; a single number for scale; an inline array of species tables
    let p = parse_preset(
        &with_species(&format!(
            "{TREE}\n[[species]]\nname = \"g\"\nkind = \"grass\"\nmax_density = 1\nscale = 1.5\n\
             exclusion = {{ species = \"oak\", radius = 2 }}"
        )),
        Path::new("p.toml"),
    )
    .unwrap();
    assert_eq!(p.species[1].rules.scale, [1.5, 1.5]);
    assert_eq!(p.species[1].rules.exclusions, vec![Exclusion { species: "oak".into(), radius_m: 2.0 }]);
    let p = parse_preset(
        &with_species("species = [{ name = \"a\", kind = \"mesh\", max_density = 0.1, min_spacing = 2.0, placement = \"poisson\" }]"),
        Path::new("p.toml"),
    );
    // (an inline `species = [...]` at the root would sit inside [terrain]; TOML puts it there)
    assert!(p.is_err());
}

#[test]
fn species_defaults_follow_the_kind() {
    let text = with_species(
        "[[species]]\nname = \"t\"\nkind = \"tree\"\nmax_density = 0.01\n\
         [[species]]\nname = \"g\"\nkind = \"grass\"\nmax_density = 1\n\
         [[species]]\nname = \"f\"\nkind = \"flower\"\nmax_density = 1\n\
         [[species]]\nname = \"m\"\nkind = \"mesh\"\nmax_density = 1",
    );
    let p = parse_preset(&text, Path::new("p.toml")).unwrap();
    assert_eq!(p.scatter.tile_m, 256.0);
    let [t, g, f, m] = &p.species[..] else { panic!("{:?}", p.species) };
    assert_eq!(
        (t.kind, t.rules.placement, t.rules.min_spacing_m, t.rules.align_to_normal),
        (SpeciesKind::Tree, Placement::Poisson, 4.0, 0.0)
    );
    assert_eq!(
        (g.kind, g.rules.placement, g.rules.min_spacing_m, g.rules.align_to_normal),
        (SpeciesKind::Grass, Placement::Jittered, 0.0, 1.0)
    );
    assert_eq!(
        (f.kind, f.rules.placement, f.rules.min_spacing_m, f.rules.align_to_normal),
        (SpeciesKind::Flower, Placement::Jittered, 0.0, 1.0)
    );
    assert_eq!(
        (m.kind, m.rules.placement, m.rules.min_spacing_m, m.rules.align_to_normal),
        (SpeciesKind::Mesh, Placement::Jittered, 0.0, 0.0)
    );
    for s in &p.species {
        assert_eq!((s.rules.density_map.as_ref(), s.rules.mask.as_ref(), s.rules.water_level_m), (None, None, None));
        assert_eq!(
            (s.rules.slope_deg, s.rules.altitude_m, s.rules.scale),
            ([0.0, 90.0], UNBOUNDED_ALTITUDE_M, [1.0, 1.0])
        );
        assert!(s.rules.random_yaw && s.rules.exclusions.is_empty());
        assert_eq!((s.rules.seed, s.rules.max_instances), (0, DEFAULT_MAX_INSTANCES));
    }
    // trees may be jittered; then the spacing defaults to 0
    let p = parse_preset(&with_species(&format!("{TREE}\nplacement = \"jittered\"")), Path::new("p.toml")).unwrap();
    assert_eq!((p.species[0].rules.placement, p.species[0].rules.min_spacing_m), (Placement::Jittered, 0.0));
    // no species: empty list, default tile
    let p = parse_preset(&with_terrain(PROC), Path::new("p.toml")).unwrap();
    assert!(p.species.is_empty());
    assert_eq!(p.scatter.tile_m, 256.0);
}

#[test]
fn species_settings_serialise_to_clean_json() {
    // the manifest is JSON: the unbounded altitude must stay a number (±∞ would become null)
    let p = parse_preset(&with_species(TREE), Path::new("p.toml")).unwrap();
    let json = serde_json::to_value(&p).unwrap();
    let s = &json["species"][0];
    assert_eq!(s["altitude_m"], serde_json::json!([-1e9, 1e9]));
    assert_eq!((s["kind"].as_str(), s["placement"].as_str()), (Some("tree"), Some("poisson")));
    assert_eq!(json["scatter"]["tile_m"], 256.0);
    // absent water level: null (an Option), never NaN
    assert!(s["water_level_m"].is_null());
}

#[test]
fn species_invalid_values_are_refused_where_they_are() {
    // (line, its position written as line 9, expected text)
    let cases: &[(&str, &str, &str)] = &[
        ("max_density = 0", "p.toml:9:15:", "`max_density` must be greater than 0, got 0"),
        ("max_density = -1", "p.toml:9:15:", "`max_density` must be greater than 0"),
        ("max_density = nan", "p.toml:9:15:", "`max_density` must be a finite number"),
        ("max_density = inf", "p.toml:9:15:", "`max_density` must be a finite number"),
        (
            "kind = \"bush\"",
            "p.toml:9:8:",
            "unknown `kind` value \"bush\"; allowed values are grass, flower, tree, mesh",
        ),
        (
            "placement = \"random\"",
            "p.toml:9:13:",
            "unknown `placement` value \"random\"; allowed values are poisson, jittered",
        ),
        ("placement = \"poison\"", "p.toml:9:13:", "did you mean \"poisson\"?"),
        ("min_spacing = -1", "p.toml:9:15:", "`min_spacing` must be 0 or more"),
        ("min_spacing = 0", "p.toml:9:15:", "`min_spacing` must be greater than 0 for placement = \"poisson\""),
        ("slope = [0, 95]", "p.toml:9:13:", "`slope` must be between 0 and 90 degrees, got 95"),
        ("slope = [-5, 30]", "p.toml:9:10:", "`slope` must be between 0 and 90 degrees, got -5"),
        ("slope = [40, 10]", "p.toml:9:9:", "`slope` is [min, max], but 40 > 10; put the smaller value first"),
        ("slope = [10]", "p.toml:9:9:", "`slope` must have two numbers [min, max], found 1"),
        ("slope = 30", "p.toml:9:9:", "`slope` must be an array [min, max] in degrees, found an integer"),
        ("slope = [0, \"30\"]", "p.toml:9:13:", "`slope` must be a number, found a string"),
        ("altitude = [100, 50]", "p.toml:9:12:", "`altitude` is [min, max], but 100 > 50"),
        ("altitude = [0, inf]", "p.toml:9:16:", "`altitude` must be a finite number"),
        ("altitude = \"high\"", "p.toml:9:12:", "`altitude` must be an array [min, max] in metres, found a string"),
        ("water_level = \"2\"", "p.toml:9:15:", "`water_level` must be a number, found a string"),
        ("water_level = nan", "p.toml:9:15:", "`water_level` must be a finite number"),
        ("scale = [0, 1]", "p.toml:9:10:", "`scale` must be greater than 0, got 0"),
        ("scale = [2, 1]", "p.toml:9:9:", "`scale` is [min, max], but 2 > 1"),
        ("scale = -1", "p.toml:9:9:", "`scale` must be greater than 0"),
        ("scale = \"big\"", "p.toml:9:9:", "`scale` must be an array [min, max], found a string"),
        (
            "random_yaw = 1",
            "p.toml:9:14:",
            "`random_yaw` must be a boolean, found an integer; write it like `random_yaw = false`",
        ),
        (
            "align_to_normal = 1.5",
            "p.toml:9:19:",
            "`align_to_normal` must be between 0 (upright) and 1 (along the terrain normal), got 1.5",
        ),
        ("align_to_normal = -0.1", "p.toml:9:19:", "`align_to_normal` must be between 0"),
        ("seed = -1", "p.toml:9:8:", "`seed` must be between 0 and"),
        ("seed = 1.5", "p.toml:9:8:", "`seed` must be an integer, found a float"),
        ("max_instances = 0", "p.toml:9:17:", "`max_instances` must be between 1 and 4294967295, got 0"),
        ("max_instances = 5e6", "p.toml:9:17:", "`max_instances` must be an integer, found a float"),
        ("density_map = 3", "p.toml:9:15:", "`density_map` must be a path (a string), found an integer"),
        ("density_map = \"\"", "p.toml:9:15:", "`density_map` is empty"),
        ("mask = true", "p.toml:9:8:", "`mask` must be a path (a string), found a boolean"),
        ("exclusion = { species = \"oak\", radius = 0 }", "p.toml:9:41:", "`radius` must be greater than 0, got 0"),
        ("exclusion = { species = \"oak\" }", "p.toml:9:13:", "`exclusion` has no `radius`; add `radius = 1.5`"),
        ("exclusion = { radius = 1 }", "p.toml:9:13:", "`exclusion` has no `species`; add `species = \"oak\"`"),
        ("exclusion = \"oak\"", "p.toml:9:13:", "`exclusion` must be a table or an array of tables, found a string"),
        ("exclusion = [1]", "p.toml:9:14:", "`exclusion` must be a table, found an integer"),
        (
            "exclusion = { species = \"oak\", radius = 1, radias = 2 }",
            "p.toml:9:44:",
            "unknown key `radias` in `exclusion`; did you mean `radius`?",
        ),
        (
            "exclusion = [{ species = \"oak\", radius = 1 }, { species = \"oak\", radius = 2 }]",
            "p.toml:9:59:",
            "species `oak` is excluded twice in `oak`",
        ),
    ];
    for (line, position, expected) in cases {
        // the line under test comes right after the name (line 7); `kind` and `max_density` follow unless tested
        let key = line.split(" = ").next().unwrap();
        let mut body = format!("[[species]]\nname = \"oak\"\n{line}\n");
        if key != "kind" {
            body.push_str("kind = \"tree\"\n");
        }
        if key != "max_density" {
            body.push_str("max_density = 0.01\n");
        }
        let e = species_error(&body);
        let position = position.replace("p.toml:9:", "p.toml:7:");
        assert!(e.starts_with(&position), "{line}: expected {position} in {e}");
        assert!(e.contains(expected), "{line}: expected {expected:?} in {e}");
        assert!(e.contains("; "), "{line}: no remedy in {e}");
    }
    // a duplicate key is a TOML error at the repeated key
    let e = species_error(&format!("{TREE}\nmax_density = 0.5"));
    assert!(e.starts_with("p.toml:9:") && e.contains("duplicate"), "{e}");
}

/// Jittered placement keeps no spacing, so a spacing it could not keep is refused while parsing,
/// at the `min_spacing` value (before, the build refused it, without a position).
#[test]
fn species_jittered_with_a_spacing_is_refused_at_the_value() {
    let grass = "[[species]]\nname = \"grass\"\nkind = \"grass\"\nmax_density = 4";
    // explicit placement: line 9, the value starts at column 15
    let e = species_error(&format!("{grass}\nplacement = \"jittered\"\nmin_spacing = 2.5"));
    assert!(e.starts_with("p.toml:10:15: `min_spacing` = 2.5 is kept only by placement = \"poisson\""), "{e}");
    assert!(e.contains("`grass` is placed \"jittered\""), "{e}");
    assert!(e.contains("; remove `min_spacing` (or set it to 0), or set `placement = \"poisson\"`"), "{e}");
    // jittered by default (grass), and a tree switched to jittered
    let e = species_error(&format!("{grass}\nmin_spacing = 1"));
    assert!(e.starts_with("p.toml:9:15: `min_spacing` = 1 is kept only by placement = \"poisson\""), "{e}");
    let e = species_error(&format!("{TREE}\nmin_spacing = 6\nplacement = \"jittered\""));
    assert!(e.starts_with("p.toml:9:15:") && e.contains("`oak` is placed \"jittered\""), "{e}");
    // 0 stays the jittered default
    let p = parse_preset(
        &with_species(&format!("{grass}\nplacement = \"jittered\"\nmin_spacing = 0")),
        Path::new("p.toml"),
    )
    .unwrap();
    assert_eq!((p.species[0].rules.placement, p.species[0].rules.min_spacing_m), (Placement::Jittered, 0.0));
}

#[test]
fn species_required_keys_and_names() {
    let e = species_error("[[species]]\nkind = \"tree\"\nmax_density = 1");
    assert_eq!(e, "p.toml:5:1: [[species]] has no `name`; add `name = \"oak\"`");
    let e = species_error("[[species]]\nname = \"oak\"\nmax_density = 1");
    assert_eq!(
        e,
        "p.toml:5:1: [[species]] `oak` has no `kind`; add `kind = \"grass\"` (or \"flower\", \"tree\", \"mesh\")"
    );
    let e = species_error("[[species]]\nname = \"oak\"\nkind = \"tree\"");
    assert_eq!(
        e,
        "p.toml:5:1: [[species]] `oak` has no `max_density`; add `max_density = 0.5` (instances per square metre)"
    );
    let e = species_error("[[species]]\nname = \"rock\"\nkind = \"mesh\"\nmax_density = 1\nplacement = \"poisson\"");
    assert!(
        e.starts_with("p.toml:5:1: [[species]] `rock` has no `min_spacing`, which placement = \"poisson\" needs"),
        "{e}"
    );
    assert!(e.contains("add `min_spacing = 1.0`"), "{e}");
    for (name, expected) in [
        ("\"\"", "the species name is empty"),
        ("\"red oak\"", "species name `red oak` contains ' ', which is not safe in a file name"),
        ("\"../oak\"", "species name `../oak` contains '.'"),
        ("\"ök\"", "contains 'ö'"),
        (&format!("\"{}\"", "x".repeat(65)), "longer than 64 characters"),
    ] {
        let e = species_error(&format!("[[species]]\nname = {name}\nkind = \"tree\"\nmax_density = 1"));
        assert!(e.starts_with("p.toml:6:8: "), "{name}: {e}");
        assert!(e.contains(expected), "{name}: {e}");
        assert!(e.contains("use only letters, digits, `-` and `_`"), "{e}");
    }
    let e = species_error("[[species]]\nname = 3\nkind = \"tree\"\nmax_density = 1");
    assert!(e.starts_with("p.toml:6:8: `name` must be a string, found an integer"), "{e}");
}

#[test]
fn duplicate_species_names_are_refused() {
    let e = species_error(&format!("{TREE}\n[[species]]\nname = \"oak\"\nkind = \"grass\"\nmax_density = 1"));
    assert_eq!(
        e,
        "p.toml:10:8: species `oak` is declared twice; the first is at line 6; give each [[species]] its own name"
    );
    // names differing only in case would be one file on case-insensitive file systems
    let e = species_error(&format!("{TREE}\n[[species]]\nname = \"Oak\"\nkind = \"grass\"\nmax_density = 1"));
    assert!(e.starts_with("p.toml:10:8: species `Oak` is declared twice; the first is at line 6 as `oak`"), "{e}");
}

/// A species named another's name followed by what that species' file names add (grass `g`
/// writes `atlases/g_blade.png`, as a species `g_blade` would) is refused at its name, either way
/// round and ignoring case; names that only look alike are not.
#[test]
fn species_whose_files_would_share_names_are_refused() {
    let species = |a: &str, ka: &str, b: &str, kb: &str| {
        format!(
            "[[species]]\nname = \"{a}\"\nkind = \"{ka}\"\nmax_density = 0.1\n\
             [[species]]\nname = \"{b}\"\nkind = \"{kb}\"\nmax_density = 0.1"
        )
    };
    let e = species_error(&species("g", "grass", "g_blade", "tree"));
    assert_eq!(
        e,
        "p.toml:10:8: species `g_blade` and species `g` (line 6) can write the same file: both can name one \
         `g_blade` (a species' files add `_LOD<n>`, `_v<n>`, `_far`, `_blade`, `_density`, `_normal` or \
         `_mip<n>` to its name), so one would overwrite the other's; rename `g_blade` so that it is not `g` \
         followed by such an ending, e.g. `g-blade`"
    );
    // the longer name first, other endings, other case
    for (a, b, file) in [
        ("Oak_LOD0", "oak", "Oak_LOD0"),
        ("oak", "oak_v2", "oak_v2"),
        ("oak", "OAK_V12_lod1", "OAK_V12_lod1"),
        ("oak", "oak_far", "oak_far"),
        ("oak", "oak_density", "oak_density"),
        ("oak", "oak_normal", "oak_normal"),
        ("oak", "oak_mip3", "oak_mip3"),
        ("oak", "oak_blade_mip2", "oak_blade_mip2"),
        ("red_oak", "red_oak_lod2", "red_oak_lod2"),
        // variant 1 of a tree `g`
        ("g", "g_v1", "g_v1"),
    ] {
        let e = species_error(&species(a, "tree", b, "grass"));
        assert!(e.starts_with("p.toml:10:8: species `"), "{e}");
        assert!(e.contains(&format!("both can name one `{file}`")), "{a} / {b}: {e}");
    }
    // alike, but no file of either can be named as one of the other's
    for (a, b) in [
        ("oak", "oak_old"),
        ("oak", "oak_lodge"),
        ("oak", "oak_v"),
        ("oak", "oak-far"),
        ("oak", "oakv2"),
        ("oak_far", "oak_fa"),
        ("oak", "oak_far_side"),
        ("pine", "pine_normal_slope"),
        ("pine", "pine_v2b"),
    ] {
        let text = with_species(&species(a, "tree", b, "grass"));
        assert!(parse_preset(&text, Path::new("p.toml")).is_ok(), "{a} / {b}");
    }
}

#[test]
fn exclusions_name_earlier_species_or_themselves() {
    let grass = |exclusion: &str| {
        format!("[[species]]\nname = \"grass\"\nkind = \"grass\"\nmax_density = 1\nexclusion = {exclusion}")
    };
    // declared later: the remedy says to move it up
    let e = species_error(&format!("{}\n{TREE}", grass("{ species = \"oak\", radius = 1 }")));
    assert_eq!(
        e,
        "p.toml:9:25: exclusion names species `oak`, which is not declared before `grass`; declare `oak` in a [[species]] \
         before `grass` (it is placed first), or name `grass` itself to keep its instances apart"
    );
    // not declared at all, with a near miss
    let e = species_error(&format!("{TREE}\n{}", grass("{ species = \"oaks\", radius = 1 }")));
    assert!(
        e.starts_with(
            "p.toml:13:25: exclusion names species `oaks`, which is not declared before `grass`; did you mean `oak`?"
        ),
        "{e}"
    );
    // not declared at all, nothing close: the declared ones are listed
    let e = species_error(&format!(
        "{TREE}\n{}",
        grass("[{ species = \"oak\", radius = 1 }, { species = \"birch\", radius = 1 }]")
    ));
    assert!(e.starts_with("p.toml:13:59: exclusion names species `birch`"), "{e}");
    assert!(e.contains("species declared so far: `oak`, `grass`"), "{e}");
    // earlier and itself are fine
    let p = parse_preset(
        &with_species(&format!(
            "{TREE}\nexclusion = {{ species = \"oak\", radius = 8 }}\n{}",
            grass("[{ species = \"oak\", radius = 1 }, { species = \"grass\", radius = 0.2 }]")
        )),
        Path::new("p.toml"),
    )
    .unwrap();
    assert_eq!(p.species[0].rules.exclusions, vec![Exclusion { species: "oak".into(), radius_m: 8.0 }]);
    assert_eq!(p.species[1].rules.exclusions.len(), 2);
}

#[test]
fn species_unknown_keys_have_positions_and_did_you_mean() {
    let e = species_error(&format!("{TREE}\ndensty_map = \"d.png\""));
    assert_eq!(e, "p.toml:9:1: unknown key `densty_map` in [[species]] `oak`; did you mean `density_map`?");
    let e = species_error(&format!("{TREE}\nmin-spacing = 3"));
    assert_eq!(e, "p.toml:9:1: unknown key `min-spacing` in [[species]] `oak`; did you mean `min_spacing`?");
    let e = species_error(&format!("{TREE}\nformats = [\"glb\"]"));
    assert!(
        e.starts_with("p.toml:9:1: unknown key `formats` in [[species]] `oak`; `formats` belongs in [scene]"),
        "{e}"
    );
    let e = species_error(&format!("{TREE}\ntile = 64"));
    assert!(e.starts_with("p.toml:9:1: unknown key `tile` in [[species]] `oak`; `tile` belongs in [scatter]"), "{e}");
    let e = species_error(&format!("{TREE}\nzzz = 1"));
    assert!(
        e.starts_with(
            "p.toml:9:1: unknown key `zzz` in [[species]] `oak`; the keys of [[species]] `oak` are `name`, `kind`"
        ),
        "{e}"
    );
    // [scatter]
    let e = species_error("[scatter]\ntiles = 64");
    assert_eq!(e, "p.toml:6:1: unknown key `tiles` in [scatter]; did you mean `tile`?");
    let e = species_error("[scatter]\nmax_density = 1");
    assert!(
        e.starts_with("p.toml:6:1: unknown key `max_density` in [scatter]; `max_density` belongs in [[species]]"),
        "{e}"
    );
    for (line, expected) in [
        ("tile = 0", "p.toml:6:8: `tile` must be greater than 0, got 0"),
        ("tile = -5", "p.toml:6:8: `tile` must be greater than 0"),
        ("tile = \"big\"", "p.toml:6:8: `tile` must be a number, found a string"),
        ("tile = nan", "p.toml:6:8: `tile` must be a finite number"),
    ] {
        let e = species_error(&format!("[scatter]\n{line}"));
        assert!(e.starts_with(expected), "{line}: {e}");
    }
    // a species key at the top level
    let e = error_of("max_density = 1\n[scene]\nname = \"x\"\n");
    assert_eq!(e, "p.toml:1:1: key `max_density` is outside any section; move it under [[species]]");
}

#[test]
fn species_section_shapes() {
    // single brackets
    let e = species_error("[species]\nname = \"oak\"");
    assert!(e.starts_with("p.toml:5:2: `[species]` must be an array of tables, one per species; write the header with double brackets"), "{e}");
    assert!(e.contains("`[scene]`, `[terrain]`, `[[species]]`, `[scatter]`"), "{e}");
    // not a table at all
    let e = error_of(&format!("species = 3\n{MINIMAL}"));
    assert!(e.starts_with("p.toml:1:1: `species` must be an array of tables `[[species]]`, found an integer"), "{e}");
    let e = error_of(&format!("species = [1]\n{MINIMAL}"));
    assert!(e.starts_with("p.toml:1:1: `species` must be an array of tables `[[species]]`, found an array"), "{e}");
    let e = error_of(&format!("scatter = 3\n{MINIMAL}"));
    assert!(e.starts_with("p.toml:1:1: `scatter` must be a section `[scatter]`, found an integer"), "{e}");
    // an inline array of tables at the top level is the same as [[species]] to TOML
    let text =
        format!("species = [{{ name = \"a\", kind = \"grass\", max_density = 1 }}]\n{MINIMAL}[terrain]\n{PROC}\n");
    let p = parse_preset(&text, Path::new("p.toml")).unwrap();
    assert_eq!(p.species[0].rules.name, "a");
}

#[test]
fn species_need_a_terrain() {
    let e = error_of(&format!("{MINIMAL}{TREE}\n"));
    assert_eq!(
        e,
        "p.toml:3:3: [[species]] needs a terrain: instances are placed on the terrain surface; add a `[terrain]` section \
         (e.g. `procedural = { kind = \"fbm\", size = 513, relief = 200.0 }`)"
    );
    // [scatter] alone is fine
    assert!(parse_preset(&format!("{MINIMAL}[scatter]\ntile = 32\n"), Path::new("p.toml")).is_ok());
    // [terrain] after the species is fine too (sections are not ordered)
    let text = format!("{MINIMAL}{TREE}\n[terrain]\n{PROC}\n");
    assert_eq!(parse_preset(&text, Path::new("p.toml")).unwrap().species.len(), 1);
}

#[test]
fn missing_density_map_and_mask_are_named_with_their_lines() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("forest.toml");
    std::fs::write(&file, with_species(&format!("{TREE}\ndensity_map = \"maps/none.png\""))).unwrap();
    let e = load_preset(&file).unwrap_err();
    let resolved = dir.path().join("maps/none.png");
    assert!(matches!(&e, PresetError::MissingInput { input, what: "density_map", .. } if input == &resolved), "{e:?}");
    assert_eq!(e.position(), Some((9, 15)));
    let s = e.to_string();
    assert!(
        s.starts_with(&format!(
            "{}:9:15: density_map `{}` not found; paths are relative",
            file.display(),
            resolved.display()
        )),
        "{s}"
    );
    // parse_preset does not look at the disk, and resolves against the preset's folder
    let p = parse_preset(&std::fs::read_to_string(&file).unwrap(), &file).unwrap();
    assert_eq!(p.species[0].rules.density_map.as_deref(), Some(resolved.as_path()));

    std::fs::write(&file, with_species(&format!("{TREE}\nmask = \"m.png\""))).unwrap();
    let e = load_preset(&file).unwrap_err();
    assert!(
        e.to_string().starts_with(&format!(
            "{}:9:8: mask `{}` not found",
            file.display(),
            dir.path().join("m.png").display()
        )),
        "{e}"
    );
    // a folder is not an image
    std::fs::create_dir_all(dir.path().join("m.png")).unwrap();
    let e = load_preset(&file).unwrap_err();
    assert!(e.to_string().contains("mask `") && e.to_string().contains("is not a file"), "{e}");
}

#[test]
fn shipped_presets_have_the_species_they_promise() {
    let p = load_preset(&manifest_dir().join("presets/meadow.toml")).unwrap();
    let names: Vec<&str> = p.species.iter().map(|s| s.rules.name.as_str()).collect();
    assert_eq!(names, ["oak", "grass", "flowers"]);
    let [oak, grass, flowers] = &p.species[..] else { panic!() };
    assert_eq!((oak.kind, oak.rules.placement), (SpeciesKind::Tree, Placement::Poisson));
    assert!(oak.rules.min_spacing_m > 0.0);
    assert_eq!((grass.kind, grass.rules.placement), (SpeciesKind::Grass, Placement::Jittered));
    assert_eq!(grass.rules.exclusions[0].species, "oak");
    assert_eq!(flowers.kind, SpeciesKind::Flower);
    assert!(
        p.species.iter().all(|s| s.rules.density_map.is_none() && s.rules.mask.is_none()),
        "no image files are shipped"
    );

    let p = load_preset(&manifest_dir().join("presets/alpine.toml")).unwrap();
    let [conifer, grass, boulder] = &p.species[..] else { panic!("{:?}", p.species) };
    assert_eq!(
        (conifer.kind, conifer.rules.placement, conifer.rules.min_spacing_m),
        (SpeciesKind::Tree, Placement::Poisson, 6.0)
    );
    assert!(
        conifer.rules.slope_deg[1] <= 35.0 && conifer.rules.altitude_m[1] < 1500.0 && conifer.rules.altitude_m[0] > 0.0
    );
    assert_eq!(grass.kind, SpeciesKind::Grass);
    assert_eq!(grass.rules.exclusions[0].species, "conifer");
    assert_eq!((boulder.kind, boulder.rules.placement), (SpeciesKind::Mesh, Placement::Poisson));
    let verdant::scene::PlantLook::Mesh(model) = &boulder.look else { panic!("boulder: {:?}", boulder.look) };
    assert!(model.obj.ends_with("models/boulder.obj") && model.obj.is_file(), "{}", model.obj.display());
    let verdant::scene::PlantLook::Tree(oak_look) =
        &load_preset(&manifest_dir().join("presets/meadow.toml")).unwrap().species[0].look
    else {
        panic!("the meadow's oaks grow from an L-system")
    };
    assert!(oak_look.lsystem.ends_with("lsystems/broadleaf.ls") && oak_look.lsystem.is_file());
}

#[test]
fn demo_species_stay_small() {
    let d = demo_preset();
    assert!(d.species.len() >= 2);
    assert!(
        d.species.iter().any(|s| s.kind == SpeciesKind::Tree) && d.species.iter().any(|s| s.kind == SpeciesKind::Grass)
    );
    // an upper bound of the instance count: max_density over the whole 2048 m × 2048 m map
    let area = 2048.0 * 2048.0;
    let bound: f64 = d.species.iter().map(|s| s.rules.max_density * area).sum();
    assert!(bound <= 200_000.0, "{bound}");
    // the same invariants the parser enforces
    for (i, s) in d.species.iter().enumerate() {
        assert!(s.rules.placement != Placement::Poisson || s.rules.min_spacing_m > 0.0);
        for e in &s.rules.exclusions {
            assert!(d.species[..=i].iter().any(|o| o.rules.name == e.species));
        }
    }
    // it serialises without nulls in the ranges
    let json = serde_json::to_value(&d).unwrap();
    assert!(json["species"].as_array().unwrap().iter().all(|s| s["altitude_m"][0].is_number()));
}

#[test]
fn template_species_example_parses_when_uncommented() {
    let text = template("t");
    let mut out = String::new();
    let mut after_scatter = false;
    for line in text.lines() {
        after_scatter |= line.starts_with("# [scatter]");
        let uncommented = match line.strip_prefix("# ") {
            Some(rest) if after_scatter => {
                let rest = rest.strip_prefix("# ").unwrap_or(rest);
                let is_toml = rest.starts_with('[') || rest.split_once(" = ").is_some_and(|(k, _)| !k.contains(' '));
                if is_toml {
                    rest
                } else {
                    line
                }
            }
            _ => line,
        };
        out.push_str(uncommented);
        out.push('\n');
    }
    assert!(out.contains("\n[[species]]\n") && out.contains("\n[scatter]\n"), "{out}");
    let p = parse_preset(&out, Path::new("presets/t.toml")).unwrap_or_else(|e| panic!("{e}\n{out}"));
    let names: Vec<&str> = p.species.iter().map(|s| s.rules.name.as_str()).collect();
    assert_eq!(names, ["pine", "grass"]);
    assert_eq!(p.species[0].rules.density_map.as_deref(), Some(Path::new("presets/maps/forest.png")));
    assert_eq!(p.species[1].rules.exclusions[0].species, "pine");
    // and as shipped (all commented out) it has none
    assert!(parse_preset(&text, Path::new("t.toml")).unwrap().species.is_empty());
}
