//! Preset parsing: the shipped presets and the template parse; every kind of mistake is an error
//! naming file, line and column with a remedy; no text makes the parser panic.

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use verdant::heightfield::{Encoding, DEFAULT_MAX_SAMPLES};
use verdant::scene::preset::{
    demo_preset, load_preset, parse_preset, procedural_heightfield, template, PresetError,
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
    let dir = manifest_dir().join("presets");
    let mut names = Vec::new();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let preset = load_preset(&path).unwrap_or_else(|e| panic!("{e}"));
            assert!(preset.terrain.is_some(), "{}", path.display());
            names.push(preset.scene.name);
        }
    }
    names.sort();
    assert!(names.len() >= 2, "{names:?}");
    assert!(names.contains(&"alpine".to_string()) && names.contains(&"meadow".to_string()));
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
    assert!(e.starts_with("p.toml:3:1: unknown key `zzz` in [scene]; the keys of [scene] are `name`, `seed`, `formats`"), "{e}");

    // inside the procedural table
    let e = error_of(&with_terrain("procedural = { kind = \"fbm\", size = 65, releif = 10.0 }"));
    assert_eq!(e, "p.toml:4:41: unknown key `releif` in `procedural`; did you mean `relief`?");
}

#[test]
fn unknown_section_lists_the_known_ones() {
    let e = error_of(&format!("{MINIMAL}\n[species]\noak = 1\n"));
    assert!(e.starts_with("p.toml:4:2: unknown section `[species]`; known sections are `[scene]`, `[terrain]`"), "{e}");
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
        ("kind = \"perlin\", size = 65, relief = 1.0", "unknown `kind` value \"perlin\"; allowed values are fbm, ridged"),
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
        ("name = \"x\"\nformats = [\"fbx\"]", "p.toml:3:12: unknown `formats` value \"fbx\"; allowed values are glb, gltf, obj"),
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
    let p = parse_preset("[scene]\nname = \"x\"\nformats = [\"obj\", \"gltf\", \"glb\"]\n", Path::new("p.toml")).unwrap();
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
        let text = if block.contains("[scene]") { block.to_string() } else { format!("{MINIMAL}{block}") };
        parse_preset(&text, Path::new("docs/example.toml")).unwrap_or_else(|e| panic!("{e}\n{text}"));
        parsed += 1;
    }
    assert!(parsed >= 2);
}
