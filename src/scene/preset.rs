//! Presets: a scene's settings in TOML (`presets/*.toml`, documented key by key in
//! `docs/presets.md`), resolved into the plain types of [`crate::scene`].
//!
//! The document is parsed with spans (`toml::de::DeTable`) and walked by hand rather than through
//! serde derive, so every problem — a syntax error, an unknown or misspelled key, a wrong type, a
//! value out of range, a missing input file — is reported as `file:line:column: problem; remedy`.

use std::ops::Range;
use std::path::Path;

use toml::de::{DeTable, DeValue};

mod error;
mod keys;
mod plants;
mod reader;
mod snow;
mod species;
mod template;
mod terrain;
mod view;

pub(crate) use error::Inputs;
pub use error::PresetError;
pub use keys::{
    check_scene_name, check_species_name, file_name_clash, DEFAULT_MAX_INSTANCES, DEFAULT_TILE_M,
    DEFAULT_TREE_SPACING_M, EXCLUSION_KEYS, MAX_MAX_INSTANCES, MAX_NAME_CHARS, PROCEDURAL_KEYS, PROCEDURAL_SIZES,
    SCATTER_KEYS, SCENE_KEYS, SECTIONS, SPECIES_KEYS, TERRAIN_KEYS,
};
pub use plants::{FLOWER_KEYS, GRASS_KEYS, MESH_KEYS, TREE_KEYS};
pub use snow::{default_snow_seed, SNOW_KEYS};
pub use view::{LOD_KEYS, VIEW_KEYS};

use reader::*;
pub use reader::{did_you_mean, line_column, resolve};
pub use species::species_look_seed;
use species::*;
pub use template::template;
use terrain::*;

use super::{
    Format, MeshLook, PlantLook, Preset, ScatterSettings, SceneSettings, SpeciesSettings, TerrainSettings,
    TerrainSource, TreeLook,
};
use crate::export::quantize::Compact;
use crate::heightfield::Heightfield;
use crate::lsystem::library;
use crate::plants::flower::FlowerSettings;
use crate::plants::grass::GrassSettings;
use crate::plants::SpeciesKind;
use crate::scatter::{Exclusion, Placement, SpeciesRules, UNBOUNDED_ALTITUDE_M};
use crate::synth::{self, NoiseKind};
use crate::terrain::job::MeshMode;

/// Reads, parses and resolves the preset at `path`, and checks that the input files it names exist.
pub fn load_preset(path: &Path) -> Result<Preset, PresetError> {
    load(path, Inputs::Exist)
}

/// [`load_preset`], and every input decodes as the preset reads it (`verdant preset check`): a
/// heightmap its `encoding` cannot read, an image that is no PNG, an OBJ that does not load are
/// reported at the preset key that names them, before any build.
pub fn check_preset(path: &Path) -> Result<Preset, PresetError> {
    load(path, Inputs::Decode)
}

fn load(path: &Path, inputs: Inputs) -> Result<Preset, PresetError> {
    let bytes = crate::input::read_limited(path, crate::input::MAX_PRESET_BYTES, "a preset")
        .map_err(|e| PresetError::Read { file: path.to_path_buf(), source: e.into_io() })?;
    let text = String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let text = String::from_utf8_lossy(e.as_bytes());
        let (line, column) = line_column(&text, at);
        PresetError::At {
            file: path.to_path_buf(),
            line,
            column,
            problem: format!("byte {at} is not UTF-8 text"),
            remedy: "save the preset as UTF-8 (TOML files are UTF-8)".into(),
        }
    })?;
    parse(&text, path, inputs)
}

/// Parses and resolves preset `text`. `path` is where it came from: it names the file in messages
/// and relative input paths are resolved against its folder. Input files are not checked here
/// ([`load_preset`] does).
pub fn parse_preset(text: &str, path: &Path) -> Result<Preset, PresetError> {
    parse(text, path, Inputs::Unchecked)
}

/// The embedded default of `verdant build` without a preset: a 513² fBm map generated in memory,
/// 4 m cells (2 km across), 300 m relief, TIN within 1 m in 128² chunks with skirts and a
/// three-level LoD chain; Poisson-spaced trees below 240 m and jittered grass that keeps clear of
/// their trunks — about 130 000 instances in all, so the demo builds in seconds.
pub fn demo_preset() -> Preset {
    Preset {
        path: None,
        scene: SceneSettings {
            name: "demo".into(),
            seed: 0,
            formats: vec![Format::Glb],
            compact: Compact::None,
            tile_m: None,
            lod_scene: true,
        },
        terrain: Some(TerrainSettings {
            source: TerrainSource::Fbm {
                size: 513,
                seed: 0x0076_6572_6461_6e74,
                relief_m: 300.0,
                cell_size_m: 4.0,
                noise: NoiseKind::Fbm,
            },
            mode: MeshMode::Tin,
            max_error_m: 1.0,
            max_triangles: None,
            max_vertices: crate::terrain::budget::DEFAULT_MAX_VERTICES,
            grid_step: 1,
            chunk: Some(128),
            skirt_m: Some(4.0),
            base_m: None,
            lods: vec![1.0, 4.0, 16.0],
        }),
        species: vec![
            // 58 % of the map is below 240 m with slopes under 30°: ≈ 2.4 km² × 0.002 ≈ 4 800 trees
            SpeciesSettings {
                rules: SpeciesRules {
                    name: "tree".into(),
                    density_map: None,
                    mask: None,
                    max_density: 0.002,
                    placement: Placement::Poisson,
                    min_spacing_m: 6.0,
                    slope_deg: [0.0, 30.0],
                    altitude_m: [0.0, 240.0],
                    water_level_m: None,
                    scale: [0.8, 1.25],
                    random_yaw: true,
                    align_to_normal: 0.0,
                    exclusions: Vec::new(),
                    seed: 0,
                    max_instances: DEFAULT_MAX_INSTANCES,
                },
                kind: SpeciesKind::Tree,
                cull_distance_m: None,
                vegetation_type: None,
                // the built-in broadleaf (crate::lsystem::library), 12 m before the instance scale
                look: PlantLook::Tree(TreeLook {
                    lsystem: library::path_of(library::find("broadleaf").expect("a library species")),
                    height_m: Some(12.0),
                    seed: species_look_seed(0, "tree", 0),
                    ..TreeLook::default()
                }),
            },
            // 75 % of the map has slopes under 35°: ≈ 3.1 km² × 0.04 ≈ 125 000 clumps
            SpeciesSettings {
                rules: SpeciesRules {
                    name: "grass".into(),
                    density_map: None,
                    mask: None,
                    max_density: 0.04,
                    placement: Placement::Jittered,
                    min_spacing_m: 0.0,
                    slope_deg: [0.0, 35.0],
                    altitude_m: UNBOUNDED_ALTITUDE_M,
                    water_level_m: None,
                    scale: [0.7, 1.2],
                    random_yaw: true,
                    align_to_normal: 1.0,
                    exclusions: vec![Exclusion { species: "tree".into(), radius_m: 1.5 }],
                    seed: 0,
                    max_instances: DEFAULT_MAX_INSTANCES,
                },
                kind: SpeciesKind::Grass,
                cull_distance_m: None,
                vegetation_type: None,
                look: PlantLook::Grass(GrassSettings {
                    seed: species_look_seed(0, "grass", 0),
                    ..GrassSettings::default()
                }),
            },
        ],
        scatter: ScatterSettings::default(),
        snow: None,
        lod: crate::lod::LodView::default(),
        views: vec![crate::scene::view::ViewSettings::default_view()],
    }
}

/// Side lengths (m) of the terrain a preset meshes, known without decoding the heights: from the
/// procedural size, or from a heightmap's header (`None` when the header cannot be read).
pub fn terrain_extent_m(t: &TerrainSettings) -> Option<[f64; 2]> {
    match &t.source {
        TerrainSource::Fbm { size, cell_size_m, .. } => Some([(*size as f64 - 1.0) * cell_size_m; 2]),
        TerrainSource::Heightmap { path, decode } => {
            let (w, h) = match image::image_dimensions(path) {
                Ok(d) => d,
                // raw grids (.hgt, .r16): square, two bytes a sample
                Err(_) => {
                    let side = ((std::fs::metadata(path).ok()?.len() / 2) as f64).sqrt().floor() as u32;
                    (side, side)
                }
            };
            let cell = decode.cell_size_m;
            Some([(w.max(1) as f64 - 1.0) * cell, (h.max(1) as f64 - 1.0) * cell])
        }
    }
}

/// Where in `text` the `index`-th `[[species]]` sets `key` (line and column, 1-based), or where
/// that species' table starts when it does not set it; `None` when `text` has no such species.
pub fn species_key_position(text: &str, index: usize, key: &str) -> Option<(usize, usize)> {
    let root = DeTable::parse(text).ok()?;
    let (_, species) = root.get_ref().get_key_value("species")?;
    let DeValue::Array(items) = species.get_ref() else { return None };
    let item = items.get(index)?;
    let DeValue::Table(table) = item.get_ref() else { return None };
    let span = match table.get_key_value(key) {
        Some((k, _)) => k.span(),
        None => item.span(),
    };
    Some(line_column(text, span.start))
}

/// Upper estimates of each species' count before any work: `max_density` (capped by the Poisson
/// packing for `poisson`) over the whole terrain; (name, estimate, max_instances) for the species
/// whose estimate is above its `max_instances` (the build fails if the rules allow that many).
pub fn instance_estimates_over_limit(p: &Preset) -> Vec<(String, f64, usize)> {
    let Some(area) = p.terrain.as_ref().and_then(terrain_extent_m).map(|[w, h]| w * h) else { return Vec::new() };
    p.species
        .iter()
        .filter_map(|s| {
            let density = match s.rules.placement {
                Placement::Poisson if s.rules.min_spacing_m > 0.0 => s
                    .rules
                    .max_density
                    .min(crate::scatter::POISSON_PACKING / (s.rules.min_spacing_m * s.rules.min_spacing_m)),
                _ => s.rules.max_density,
            };
            let estimate = density * area;
            (estimate > s.rules.max_instances as f64).then(|| (s.rules.name.clone(), estimate, s.rules.max_instances))
        })
        .collect()
}

/// What the L-system reader repaired in each tree species' file, as lparser would have accepted
/// it (brackets balanced across rules, a stray `)`, a blank inside a rule, ...): one line per
/// repair naming the file, its line and column, and the species. `verdant preset check` and
/// `verdant build` print them and report.md lists them, so a file that builds is not silently
/// different from what its author wrote. A file that does not parse gives none here (loading the
/// preset reports it as an error).
pub fn lsystem_warnings(p: &Preset) -> Vec<String> {
    p.species
        .iter()
        .filter_map(|s| match &s.look {
            PlantLook::Tree(t) => Some((&s.rules.name, t)),
            _ => None,
        })
        .flat_map(|(name, t)| {
            let warnings = crate::lsystem::parse::read_file(&t.lsystem, t.dialect).map(|p| p.warnings);
            warnings
                .unwrap_or_default()
                .into_iter()
                .map(move |w| format!("{}: {w} (species `{name}`)", t.lsystem.display()))
        })
        .collect()
}

/// Generates the heights of a procedural source; `None` for a heightmap file.
pub fn procedural_heightfield(source: &TerrainSource) -> Option<Heightfield> {
    match *source {
        TerrainSource::Heightmap { .. } => None,
        TerrainSource::Fbm { size, seed, relief_m, cell_size_m, noise } => {
            Some(synth::noise_map(noise, size, cell_size_m, relief_m, seed))
        }
    }
}

// ---------------------------------------------------------------------------------------------
// parsing

fn parse(text: &str, path: &Path, inputs: Inputs) -> Result<Preset, PresetError> {
    let ctx = Ctx { file: path, text };
    let root = DeTable::parse(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        let message = e.message().trim().trim_end_matches('.').to_string();
        let remedy = if message.contains("duplicate") {
            "each key and section may appear only once: remove or merge the repeated one"
        } else {
            "fix the syntax here (see docs/presets.md for an example)"
        };
        ctx.at(&span, format!("TOML syntax: {message}"), remedy)
    })?;
    let root = root.get_ref();

    // sections, in file order: known names holding tables only
    let mut entries: Vec<Entry<'_, '_>> = root.iter().collect();
    entries.sort_by_key(|(k, _)| k.span().start);
    let mut scene = None;
    let mut terrain = None;
    let mut species_tables = None;
    let mut scatter = None;
    let mut grass_section = None;
    let mut flower_section = None;
    let mut tree_section = None;
    let mut mesh_section = None;
    let mut snow_section = None;
    let mut lod_section = None;
    let mut view_tables = None;
    for (key, value) in entries {
        let name: &str = key.get_ref();
        if name == "view" {
            match value.get_ref() {
                DeValue::Array(items) if items.iter().all(|i| matches!(i.get_ref(), DeValue::Table(_))) => {
                    view_tables = Some((key.span(), items));
                    continue;
                }
                _ => {
                    return Err(ctx.at(
                        &key.span(),
                        "`view` must be an array of tables, one per camera",
                        "write the header with double brackets, `[[view]]`, once before each view",
                    ));
                }
            }
        }
        if name == "species" {
            // `[[species]]`: an array of tables (inline `species = [{ … }]` is the same to TOML)
            let species_example = "[[species]]\nname = \"oak\"\nkind = \"tree\"\nmax_density = 0.01";
            match value.get_ref() {
                DeValue::Array(items) if items.iter().all(|i| matches!(i.get_ref(), DeValue::Table(_))) => {
                    species_tables = Some((key.span(), items));
                    continue;
                }
                DeValue::Table(_) => {
                    return Err(ctx.at(
                        &key.span(),
                        "`[species]` must be an array of tables, one per species",
                        format!(
                            "write the header with double brackets, `[[species]]`, once before each species (known sections: {})",
                            sections_list()
                        ),
                    ));
                }
                other => {
                    return Err(ctx.at(
                        &key.span(),
                        format!("`species` must be an array of tables `[[species]]`, found {}", type_name(other)),
                        format!("write each species as a table, e.g. `{}`", species_example.replace('\n', "; ")),
                    ));
                }
            }
        }
        let table = match value.get_ref() {
            DeValue::Table(t) => t,
            // `[[name]]` of an unknown array of tables
            DeValue::Array(items)
                if !SECTIONS.contains(&name)
                    && !items.is_empty()
                    && items.iter().all(|i| matches!(i.get_ref(), DeValue::Table(_))) =>
            {
                return Err(unknown_section(&ctx, &key.span(), &format!("[[{name}]]"), name));
            }
            other => {
                let problem = if SECTIONS.contains(&name) {
                    format!("`{name}` must be a section `[{name}]`, found {}", type_name(other))
                } else {
                    format!("key `{name}` is outside any section")
                };
                let home = [
                    ("[scene]", SCENE_KEYS),
                    ("[terrain]", TERRAIN_KEYS),
                    ("[[species]]", SPECIES_KEYS),
                    ("[scatter]", SCATTER_KEYS),
                ]
                .iter()
                .find(|(_, keys)| keys.contains(&name))
                .map(|(s, _)| *s);
                let remedy = match home {
                    Some(s) if !SECTIONS.contains(&name) => format!("move it under {s}"),
                    _ => format!("keys go under one of the sections {}", sections_list()),
                };
                return Err(ctx.at(&key.span(), problem, remedy));
            }
        };
        match name {
            "scene" => scene = Some((key.span(), table)),
            "terrain" => terrain = Some((key.span(), table)),
            "scatter" => scatter = Some((key.span(), table)),
            "grass" => grass_section = Some((key.span(), table)),
            "flower" => flower_section = Some((key.span(), table)),
            "tree" => tree_section = Some((key.span(), table)),
            "mesh" => mesh_section = Some((key.span(), table)),
            "snow" => snow_section = Some((key.span(), table)),
            "lod" => lod_section = Some((key.span(), table)),
            _ => return Err(unknown_section(&ctx, &key.span(), &format!("[{name}]"), name)),
        }
    }

    let Some((scene_span, scene_table)) = scene else {
        return Err(ctx.at(&(0..0), "the preset has no [scene] section", "add `[scene]` with `name = \"my-scene\"`"));
    };
    let (scene, tile) =
        parse_scene(&Table { ctx: &ctx, label: "[scene]".into(), span: scene_span, table: scene_table })?;
    let terrain = match terrain {
        None => None,
        Some((span, table)) => {
            let t = Table { ctx: &ctx, label: "[terrain]".into(), span, table };
            Some(parse_terrain(&t, scene.seed, inputs)?)
        }
    };
    if let Some((_, span)) = &tile {
        if terrain.as_ref().is_none_or(|t| t.chunk.is_none()) {
            return Err(ctx.at(
                span,
                "scene tiles need a chunked terrain: a tile holds the terrain chunks whose centres lie in it",
                "set `chunk` in [terrain] (e.g. `chunk = 512`), with `tile` a multiple of the chunks' side",
            ));
        }
    }
    let scatter = match scatter {
        None => ScatterSettings::default(),
        Some((span, table)) => parse_scatter(&Table { ctx: &ctx, label: "[scatter]".into(), span, table }, inputs)?,
    };
    if let Some((tile_m, span)) = &tile {
        // a scene tile holds whole placement tiles (each one chain per variant, as in scene_lod.glb)
        let ratio = tile_m / scatter.tile_m;
        if (ratio - ratio.round()).abs() > 1e-9 * ratio.max(1.0) || ratio.round() < 1.0 {
            return Err(ctx.at(
                span,
                format!(
                    "`tile = {tile_m}` is not a whole multiple of the placement tiles' {} m ([scatter] tile): a scene \
                     tile holds whole placement tiles",
                    scatter.tile_m
                ),
                format!(
                    "set `tile` to a multiple of {} m (e.g. `tile = {}`)",
                    scatter.tile_m,
                    scatter.tile_m * ratio.round().max(1.0)
                ),
            ));
        }
    }
    let grass_defaults = match grass_section {
        None => GrassSettings::default(),
        Some((span, table)) => plants::apply_grass(
            &Table { ctx: &ctx, label: "[grass]".into(), span, table },
            GrassSettings::default(),
            inputs,
        )?,
    };
    let flower_defaults = match flower_section {
        None => FlowerSettings::default(),
        Some((span, table)) => plants::apply_flower(
            &Table { ctx: &ctx, label: "[flower]".into(), span, table },
            FlowerSettings::default(),
        )?,
    };
    let tree_height_set =
        tree_section.as_ref().is_some_and(|(_, table)| table.iter().any(|(k, _)| k.get_ref() == "height"));
    let tree_defaults = match tree_section {
        None => TreeLook::default(),
        Some((span, table)) => {
            plants::apply_tree(&Table { ctx: &ctx, label: "[tree]".into(), span, table }, TreeLook::default())?
        }
    };
    let mesh_defaults = match mesh_section {
        None => MeshLook::default(),
        Some((span, table)) => {
            plants::apply_mesh(&Table { ctx: &ctx, label: "[mesh]".into(), span, table }, MeshLook::default())?
        }
    };
    let snow = match snow_section {
        None => None,
        Some((span, _)) if terrain.is_none() => {
            return Err(ctx.at(
                &span,
                "[snow] needs a terrain: the snow cover lies on it",
                "add a `[terrain]` section (e.g. `procedural = { kind = \"fbm\", size = 513, relief = 200.0 }`)",
            ));
        }
        Some((span, table)) => {
            Some(snow::parse_snow(&Table { ctx: &ctx, label: "[snow]".into(), span, table }, scene.seed)?)
        }
    };
    let looks = Looks {
        grass: &grass_defaults,
        flower: &flower_defaults,
        tree: &tree_defaults,
        tree_height_set,
        mesh: &mesh_defaults,
        scene_seed: scene.seed,
    };
    let mut species: Vec<SpeciesSettings> = Vec::new();
    if let Some((key_span, items)) = species_tables {
        if terrain.is_none() {
            return Err(ctx.at(
                &key_span,
                "[[species]] needs a terrain: instances are placed on the terrain surface",
                "add a `[terrain]` section (e.g. `procedural = { kind = \"fbm\", size = 513, relief = 200.0 }`)",
            ));
        }
        // line of each earlier species' name, for "declared twice" messages
        let mut lines: Vec<usize> = Vec::new();
        for item in items.iter() {
            let DeValue::Table(table) = item.get_ref() else { continue };
            let t = Table { ctx: &ctx, label: "[[species]]".into(), span: item.span(), table };
            let (s, name_span) = parse_species(&t, &species, &looks, inputs, scatter.vegetation_map.is_some())?;
            // compared ignoring case: `Oak` and `oak` would be one file on some file systems
            if let Some(i) = species.iter().position(|e| e.rules.name.eq_ignore_ascii_case(&s.rules.name)) {
                let first = &species[i].rules.name;
                let case = if *first == s.rules.name {
                    String::new()
                } else {
                    format!(" as `{first}` (names that differ only in case are one file name on some systems)")
                };
                return Err(ctx.at(
                    &name_span,
                    format!("species `{}` is declared twice; the first is at line {}{case}", s.rules.name, lines[i]),
                    "give each [[species]] its own name",
                ));
            }
            // one species' name followed by what another's file names add: the two write one file
            for (e, line) in species.iter().zip(&lines) {
                let (first, then) = (&e.rules.name, &s.rules.name);
                let clash = file_name_clash(first, then)
                    .map(|f| (first, then, f))
                    .or_else(|| file_name_clash(then, first).map(|f| (then, first, f)));
                if let Some((shorter, longer, file)) = clash {
                    return Err(ctx.at(
                        &name_span,
                        format!(
                            "species `{then}` and species `{first}` (line {line}) can write the same file: \
                             both can name one `{file}` (a species' files add `_LOD<n>`, `_v<n>`, `_far`, \
                             `_blade`, `_density`, `_normal` or `_mip<n>` to its name), so one would \
                             overwrite the other's"
                        ),
                        format!(
                            "rename `{longer}` so that it is not `{shorter}` followed by such an ending, e.g. `{}`",
                            format!("{}-{}", &longer[..shorter.len()], &longer[shorter.len() + 1..])
                        ),
                    ));
                }
            }
            lines.push(line_column(text, name_span.start).0);
            species.push(s);
        }
    }
    let lod = match lod_section {
        None => crate::lod::LodView::default(),
        Some((span, table)) => view::parse_lod(&Table { ctx: &ctx, label: "[lod]".into(), span, table })?,
    };
    let mut views = Vec::new();
    if let Some((_, items)) = view_tables {
        for (index, item) in items.iter().enumerate() {
            let DeValue::Table(table) = item.get_ref() else { continue };
            let t = Table { ctx: &ctx, label: "[[view]]".into(), span: item.span(), table };
            let v = view::parse_view(&t, index)?;
            if views.iter().any(|e: &crate::scene::view::ViewSettings| e.name == v.name) {
                return Err(ctx.at(
                    &item.span(),
                    format!("view `{}` is declared twice", v.name),
                    "give each [[view]] its own name",
                ));
            }
            views.push(v);
        }
    }
    if views.is_empty() {
        views.push(crate::scene::view::ViewSettings::default_view());
    }
    Ok(Preset { path: Some(path.to_path_buf()), scene, terrain, species, scatter, snow, lod, views })
}

fn unknown_section(ctx: &Ctx<'_>, span: &Range<usize>, header: &str, name: &str) -> PresetError {
    let remedy = match did_you_mean(name, SECTIONS) {
        Some(s) => format!("did you mean `{}`? (known sections: {})", section_header(s), sections_list()),
        None => format!("known sections are {} (see docs/presets.md)", sections_list()),
    };
    ctx.at(span, format!("unknown section `{header}`"), remedy)
}

/// How a section's header is written: `[scene]`, `[[species]]`.
fn section_header(name: &str) -> String {
    if name == "species" || name == "view" {
        format!("[[{name}]]")
    } else {
        format!("[{name}]")
    }
}

fn sections_list() -> String {
    SECTIONS.iter().map(|s| format!("`{}`", section_header(s))).collect::<Vec<_>>().join(", ")
}

/// `[scene]`, and where its `tile` was set (checked against the terrain once that is read).
fn parse_scene(t: &Table<'_, '_>) -> Result<(SceneSettings, Option<(f64, std::ops::Range<usize>)>), PresetError> {
    t.check_keys(SCENE_KEYS, &[("[terrain]", TERRAIN_KEYS), ("`procedural`", PROCEDURAL_KEYS)])?;
    let (name, name_span) =
        t.string("name", "name = \"alpine-valley\"")?.ok_or_else(|| t.missing("name", "name = \"my-scene\""))?;
    check_scene_name(name).map_err(|why| {
        t.ctx.at(&name_span, why, "use only letters, digits, `-` and `_`, e.g. `name = \"alpine-valley\"`")
    })?;
    let seed = t.integer("seed", 0..=i64::MAX as u64, "seed = 42")?.map_or(0, |(s, _)| s);

    let mut formats = Vec::new();
    if let Some((_, v)) = t.get("formats") {
        let DeValue::Array(items) = v.get_ref() else {
            return Err(t.wrong_type("formats", v, "an array of strings", "formats = [\"glb\", \"obj\"]"));
        };
        if items.is_empty() {
            return Err(t.ctx.at(&v.span(), "`formats` is empty", "list at least one of \"glb\", \"gltf\", \"obj\""));
        }
        for item in items.iter() {
            let DeValue::String(s) = item.get_ref() else {
                return Err(t.wrong_type("formats", item, "an array of strings", "formats = [\"glb\", \"obj\"]"));
            };
            let format = match s.as_ref() {
                "glb" => Format::Glb,
                "gltf" => Format::Gltf,
                "obj" => Format::Obj,
                other => return Err(unknown_value(t, "formats", other, &["glb", "gltf", "obj"], &item.span())),
            };
            if formats.contains(&format) {
                return Err(t.ctx.at(&item.span(), format!("format \"{s}\" is listed twice"), "list each format once"));
            }
            formats.push(format);
        }
    } else {
        formats.push(Format::Glb);
    }
    let compact = match t.string("compact", "compact = \"compress\"")? {
        None => Compact::None,
        Some(("none", _)) => Compact::None,
        Some(("quantize", _)) => Compact::Quantize,
        Some(("compress", _)) => Compact::Compress,
        Some((other, span)) => {
            return Err(unknown_value(t, "compact", other, &["none", "quantize", "compress"], &span))
        }
    };
    let tile = t.number("tile", "tile = 2048.0", |x| {
        if (1.0..=1.0e6).contains(&x) {
            Ok(())
        } else {
            Err("must be between 1 and 1 000 000 m (the side of a scene tile)".into())
        }
    })?;
    let lod_scene = t.boolean("lod_scene", "lod_scene = false")?.unwrap_or(true);
    if let (false, None, Some((_, v))) = (lod_scene, &tile, t.get("lod_scene")) {
        return Err(t.ctx.at(
            &v.span(),
            "`lod_scene = false` without `tile` leaves the scene with neither scene_lod.glb nor tiles",
            "set `tile` in [scene] (e.g. `tile = 2048.0`), or remove `lod_scene = false`",
        ));
    }
    let tile_m = tile.as_ref().map(|(x, _)| *x);
    Ok((SceneSettings { name: name.to_string(), seed, formats, compact, tile_m, lod_scene }, tile))
}

fn parse_scatter(t: &Table<'_, '_>, inputs: Inputs) -> Result<ScatterSettings, PresetError> {
    t.check_keys(SCATTER_KEYS, &[("[[species]]", SPECIES_KEYS), ("[terrain]", TERRAIN_KEYS), ("[scene]", SCENE_KEYS)])?;
    let tile_m = t.number("tile", "tile = 256.0", positive)?.map_or(DEFAULT_TILE_M, |(x, _)| x);
    let table = match t.string("table", "table = \"binary\"")? {
        Some((s, span)) => reader::choice(t, "table", s, &span)?,
        None => crate::export::table::TableFormat::Csv,
    };
    let vegetation_map = input_path(t, "vegetation_map", "vegetation_map = \"maps/vegetation.png\"", inputs)?;
    Ok(ScatterSettings { tile_m, table, vegetation_map })
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;

    #[test]
    fn line_column_counts_characters() {
        let text = "a\nbé = 1\n";
        assert_eq!(line_column(text, 0), (1, 1));
        assert_eq!(line_column(text, 2), (2, 1));
        assert_eq!(line_column(text, 5), (2, 3)); // after 'b' and 'é' (2 bytes)
        assert_eq!(line_column(text, 4), (2, 2)); // inside 'é': backs off to its start
        assert_eq!(line_column(text, 1000), (3, 1));
    }

    #[test]
    fn did_you_mean_finds_near_misses_only() {
        assert_eq!(did_you_mean("max_eror", TERRAIN_KEYS), Some("max_error"));
        assert_eq!(did_you_mean("Max-Error", TERRAIN_KEYS), Some("max_error"));
        assert_eq!(did_you_mean("lod", TERRAIN_KEYS), Some("lods"));
        assert_eq!(did_you_mean("skirts", TERRAIN_KEYS), Some("skirt"));
        assert_eq!(did_you_mean("terain", SECTIONS), Some("terrain"));
        assert_eq!(did_you_mean("specie", SECTIONS), Some("species"));
        assert_eq!(did_you_mean("densty_map", SPECIES_KEYS), Some("density_map"));
        assert_eq!(did_you_mean("snwo", SECTIONS), Some("snow"));
        assert_eq!(did_you_mean("hail", SECTIONS), None);
        assert_eq!(did_you_mean("zzz", TERRAIN_KEYS), None);
    }

    #[test]
    fn scene_names() {
        assert!(check_scene_name("alpine-valley_2").is_ok());
        for bad in ["", "a b", "../x", "a/b", "é", "a.b", &"x".repeat(65)] {
            assert!(check_scene_name(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn demo_is_procedural_chunked_with_lods() {
        let d = demo_preset();
        assert_eq!(d.scene.name, "demo");
        assert_eq!(d.scene.formats, vec![Format::Glb]);
        let t = d.terrain.as_ref().unwrap();
        assert!(t.chunk.is_some() && t.lods.len() >= 2);
        let hf = procedural_heightfield(&t.source).unwrap();
        assert_eq!((hf.width, hf.height, hf.cell_size_m), (513, 513, 4.0));
    }

    #[test]
    fn template_escapes_the_name() {
        let t = template("a\"b");
        assert!(t.contains("name = \"a\\\"b\""));
        // parses (the name itself is then refused as unsafe, with its position)
        let e = parse_preset(&t, Path::new("x.toml")).unwrap_err();
        assert!(e.to_string().contains("x.toml:7:8:"), "{e}");
    }

    #[test]
    fn resolve_is_relative_to_the_preset_folder() {
        assert_eq!(resolve(Path::new("presets/a.toml"), Path::new("h.png")), PathBuf::from("presets/h.png"));
        assert_eq!(resolve(Path::new("a.toml"), Path::new("h.png")), PathBuf::from("h.png"));
        assert_eq!(resolve(Path::new("presets/a.toml"), Path::new("/abs/h.png")), PathBuf::from("/abs/h.png"));
    }
}
