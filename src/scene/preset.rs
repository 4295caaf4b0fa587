//! Presets: a scene's settings in TOML (`presets/*.toml`, documented key by key in
//! `docs/presets.md`), resolved into the plain types of [`crate::scene`].
//!
//! The document is parsed with spans (`toml::de::DeTable`) and walked by hand rather than through
//! serde derive, so every problem — a syntax error, an unknown or misspelled key, a wrong type, a
//! value out of range, a missing input file — is reported as `file:line:column: problem; remedy`.

use std::ops::Range;
use std::path::{Path, PathBuf};

use clap::ValueEnum;
use toml::de::{DeTable, DeValue};
use toml::Spanned;

mod plants;
mod snow;
mod view;

pub use plants::{FLOWER_KEYS, GRASS_KEYS, MESH_KEYS, TREE_KEYS};
pub use snow::{default_snow_seed, SNOW_KEYS};
pub use view::{LOD_KEYS, VIEW_KEYS};

use super::{
    Format, MeshLook, PlantLook, Preset, ScatterSettings, SceneSettings, SpeciesSettings, TerrainSettings,
    TerrainSource, TreeLook,
};
use crate::heightfield::{DecodeOptions, Encoding, Heightfield, DEFAULT_MAX_SAMPLES};
use crate::lsystem::library;
use crate::plants::flower::FlowerSettings;
use crate::plants::grass::GrassSettings;
use crate::plants::SpeciesKind;
use crate::scatter::{Exclusion, Placement, SpeciesRules, UNBOUNDED_ALTITUDE_M};
use crate::synth::{self, NoiseKind};
use crate::terrain::job::MeshMode;

/// The sections a preset may have, in the order the docs list them (`species` is an array of
/// tables, `[[species]]`).
pub const SECTIONS: &[&str] =
    &["scene", "terrain", "species", "scatter", "grass", "flower", "tree", "mesh", "snow", "lod", "view"];
/// Keys of `[scene]`.
pub const SCENE_KEYS: &[&str] = &["name", "seed", "formats"];
/// Keys of `[terrain]`.
pub const TERRAIN_KEYS: &[&str] = &[
    "heightmap",
    "encoding",
    "size",
    "cell_size",
    "height_scale",
    "height_offset",
    "max_samples",
    "procedural",
    "mode",
    "max_error",
    "max_triangles",
    "grid_step",
    "chunk",
    "skirt",
    "base",
    "lods",
];
/// Keys of `[[species]]`.
pub const SPECIES_KEYS: &[&str] = &[
    "name",
    "kind",
    "density_map",
    "mask",
    "max_density",
    "placement",
    "min_spacing",
    "slope",
    "altitude",
    "water_level",
    "scale",
    "random_yaw",
    "align_to_normal",
    "exclusion",
    "seed",
    "max_instances",
    "cull_distance",
    "grass",
    "flower",
    "lsystem",
    "tree",
    "obj",
    "mesh",
];
/// Keys of `[[species]] exclusion = { … }`.
pub const EXCLUSION_KEYS: &[&str] = &["species", "radius"];
/// Keys of `[scatter]`.
pub const SCATTER_KEYS: &[&str] = &["tile"];
/// Default `max_instances` of a species.
pub const DEFAULT_MAX_INSTANCES: usize = 5_000_000;
/// Largest `max_instances` a preset may ask for (a glTF accessor count is a u32).
pub const MAX_MAX_INSTANCES: u64 = u32::MAX as u64;
/// Default `min_spacing` (m) of a Poisson-placed tree: crowns of ordinary trees do not touch.
pub const DEFAULT_TREE_SPACING_M: f64 = 4.0;
/// Default `[scatter] tile` (m).
pub const DEFAULT_TILE_M: f64 = 256.0;
/// Keys of `[terrain] procedural = { … }`.
pub const PROCEDURAL_KEYS: &[&str] = &["kind", "size", "seed", "relief"];
/// `[terrain]` keys that only mean something for a heightmap file.
const HEIGHTMAP_ONLY_KEYS: &[&str] = &["encoding", "size", "height_scale", "height_offset", "max_samples"];
/// Sizes a procedural map may have (samples per side).
pub const PROCEDURAL_SIZES: std::ops::RangeInclusive<u64> = 2..=8193;
/// Longest scene name (it becomes a folder name).
pub const MAX_NAME_CHARS: usize = 64;

/// Everything that can be wrong with a preset. Exit code 2 (bad input) for all of them.
#[derive(Debug, thiserror::Error)]
pub enum PresetError {
    /// The preset file itself could not be read.
    #[error("{}: cannot read the preset: {source}; check the path", file.display())]
    Read { file: PathBuf, source: std::io::Error },
    /// A problem at a place in the preset (syntax, unknown key, wrong type or value).
    #[error("{}:{line}:{column}: {problem}; {remedy}", file.display())]
    At { file: PathBuf, line: usize, column: usize, problem: String, remedy: String },
    /// An input file the preset names does not exist (`input` is the resolved path).
    #[error(
        "{}:{line}:{column}: {what} `{}` not found; paths are relative to the preset's folder — fix the path or create the file",
        file.display(),
        input.display()
    )]
    MissingInput { file: PathBuf, line: usize, column: usize, what: &'static str, input: PathBuf },
}

/// Always the input's.
impl crate::failure::Failure for PresetError {
    fn blame(&self) -> crate::failure::Blame {
        crate::failure::Blame::Input
    }
}

impl PresetError {
    /// Line and column (1-based, columns in characters) of the problem, where known.
    pub fn position(&self) -> Option<(usize, usize)> {
        match self {
            PresetError::Read { .. } => None,
            PresetError::At { line, column, .. } | PresetError::MissingInput { line, column, .. } => {
                Some((*line, *column))
            }
        }
    }
}

/// How far parsing checks the input files a preset names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Inputs {
    /// Not at all ([`parse_preset`]: no disk access).
    Unchecked,
    /// Each exists and is a file; `.ls` files parse ([`load_preset`], what a build needs first).
    Exist,
    /// Each also decodes as the preset reads it: the heightmap with its encoding, size and scale,
    /// density maps, masks and blade textures as images, OBJ models with their MTL and textures
    /// ([`check_preset`]: everything that does not need the build itself).
    Decode,
}

impl Inputs {
    pub(crate) fn exist(self) -> bool {
        self >= Inputs::Exist
    }
    pub(crate) fn decode(self) -> bool {
        self >= Inputs::Decode
    }
}

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
        scene: SceneSettings { name: "demo".into(), seed: 0, formats: vec![Format::Glb] },
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

/// Generates the heights of a procedural source; `None` for a heightmap file.
pub fn procedural_heightfield(source: &TerrainSource) -> Option<Heightfield> {
    match *source {
        TerrainSource::Heightmap { .. } => None,
        TerrainSource::Fbm { size, seed, relief_m, cell_size_m, noise } => {
            Some(synth::noise_map(noise, size, cell_size_m, relief_m, seed))
        }
    }
}

/// Whether `name` may be a scene name: 1 to 64 ASCII letters, digits, `-` and `_` (a folder name
/// on every platform). The error says what is wrong.
pub fn check_scene_name(name: &str) -> Result<(), String> {
    check_safe_name("scene", "folder", name)
}

/// Whether `name` may be a species name: the same rule as a scene name, since it names files
/// (`placements/<name>.csv`, `species/<name>_LOD0.glb`).
pub fn check_species_name(name: &str) -> Result<(), String> {
    check_safe_name("species", "file", name)
}

pub(super) fn check_safe_name(what: &str, used_as: &str, name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err(format!("the {what} name is empty"));
    }
    if name.chars().count() > MAX_NAME_CHARS {
        return Err(format!("the {what} name is longer than {MAX_NAME_CHARS} characters"));
    }
    if let Some(c) = name.chars().find(|c| !(c.is_ascii_alphanumeric() || *c == '-' || *c == '_')) {
        return Err(format!("{what} name `{name}` contains {c:?}, which is not safe in a {used_as} name"));
    }
    Ok(())
}

/// `verdant preset new NAME`: a fully commented preset that parses as it is (a procedural
/// terrain, so it builds without any input file). `name` should pass [`check_scene_name`].
pub fn template(name: &str) -> String {
    let escaped: String = name
        .chars()
        .flat_map(|c| match c {
            '"' => vec!['\\', '"'],
            '\\' => vec!['\\', '\\'],
            c if c.is_control() => vec!['_'],
            c => vec![c],
        })
        .collect();
    TEMPLATE.replace("{NAME}", &escaped)
}

const TEMPLATE: &str = r#"# verdant preset — every key is documented in docs/presets.md.
# Check it with `verdant preset check FILE`, build it with `verdant build FILE`.
# Paths are relative to this file's folder. Lengths are in metres.

[scene]
# Output folder name under out/: letters, digits, `-` and `_` only.
name = "{NAME}"
# Global seed: every random choice of the build derives from it (same seed, same files).
seed = 0
# Mesh formats written, first = primary: "glb", "gltf" (+ .bin), "obj" (+ .mtl).
formats = ["glb"]

[terrain]
# Heights come from EITHER a heightmap file OR a procedural map (exactly one of the two).
#
# A heightmap file and how to decode it (the meanings of `verdant terrain`'s options):
# heightmap = "heights/valley.png"
# encoding = "auto"          # auto, gray, terrain-rgb, terrarium, hgt, r16, float
# size = [1025, 1025]        # width, height of a raw .r16/.raw file (square if omitted)
# height_scale = 100.0       # gray / r16: metres spanned by the full value range
# height_offset = 0.0        # gray / r16: metres added to every height
# max_samples = 67125249     # refuse larger maps (8193²)
#
# A generated square map: kind "fbm" (rolling) or "ridged" (sharp crests), `size` samples a
# side (2..=8193), heights normalised to 0..`relief` metres; `seed` defaults to [scene] seed.
procedural = { kind = "fbm", size = 513, seed = 7, relief = 200.0 }
# Metres between neighbouring samples (both sources).
cell_size = 2.0

# Meshing: "tin" (adaptive, every sample within max_error) or "grid" (every grid_step-th sample).
mode = "tin"
max_error = 1.0              # tin: largest vertical error allowed at any sample, metres
# max_triangles = 200000     # tin: stop early at this many triangles (achieved error reported)
# grid_step = 1              # grid: keep every N-th sample

# Split into chunk×chunk-sample tiles (crack-free), one mesh each.
chunk = 128
# Skirts this deep along every chunk border hide cracks between neighbouring LoDs.
skirt = 2.0
# base = 20.0                # close into a watertight solid this far below the lowest sample
# A LoD chain per chunk: the max error of each level, finest first, strictly increasing.
lods = [1.0, 4.0, 16.0]

# [scatter]
# tile = 256.0               # side of a placement tile, metres

# Vegetation: one [[species]] table per species, placed in file order; a species can keep clear
# only of species declared above it (or of itself). Uncomment to scatter trees and grass.
#
# [[species]]
# name = "pine"              # letters, digits, `-` and `_`; names placements/pine.csv
# kind = "tree"              # "grass", "flower", "tree" or "mesh"
# max_density = 0.005        # instances per m² where the density map is 1 (required)
# # density_map = "maps/forest.png"  # grayscale over the terrain: 0..1 scales max_density
# # mask = "maps/no-roads.png"       # grayscale: nothing where it is below 0.5
# placement = "poisson"      # "poisson" (default for trees) or "jittered" (default otherwise)
# min_spacing = 5.0          # metres between two instances (required > 0 for poisson; trees: 4)
# slope = [0.0, 35.0]        # allowed slope, degrees (default [0, 90])
# altitude = [0.0, 150.0]    # allowed height, metres (default: unbounded)
# # water_level = 2.0        # nothing below this height, metres
# scale = [0.8, 1.2]         # uniform scale range (default [1, 1])
# random_yaw = true          # random turn about the vertical (default true)
# align_to_normal = 0.0      # 0 upright … 1 along the ground normal (default: grass/flower 1, else 0)
# seed = 0                   # offset added to the scene seed for this species
# max_instances = 5000000    # more than this is an error naming the species
# # lsystem = "trees/pine.ls"        # grow the trees from this L-system; "builtin:conifer" (or
# #                                   # broadleaf, birch, bush) or none: a built-in tree
# # tree = { variants = 3, height = 14.0 }  # see docs/presets.md, section [tree]
#
# [[species]]
# name = "grass"
# kind = "grass"
# max_density = 0.2
# slope = [0.0, 30.0]
# # keep 1.5 m clear around every pine (an array of such tables lists several species)
# exclusion = { species = "pine", radius = 1.5 }

# Snow: a flake atlas, a particle emitter for the engine, a frozen frame of the fall, and snow
# cover on the terrain that thins grass and flowers (written to snow/). Uncomment to add it.
#
# [snow]
# seed = 0                   # default: derived from the scene seed
# temperature_c = -15.0      # where crystals grow, −40..+2 °C: picks the habits (see docs/snow.md)
# humidity = 0.6             # 0 dry … 1 saturated: plates vs dendrites, flake sizes
# atlas_cells = [4, 4]       # flake atlas columns, rows (1..32 each)
# cell_px = 64               # pixels a cell side (16..1024)
# alpha_cutoff = 0.5         # alpha-test threshold of the flake material
# near_radius = 15.0         # r1: cylinder around the camera holding near_count flakes, m
# near_count = 4000          # N1
# far_radius = 60.0          # r2 > r1: far field out to here, only inside the view angle, m
# far_count = 6000           # N2 (0: no far field)
# view_angle = 90.0          # horizontal view angle of the far field, degrees
# fall_height = 20.0         # flakes live from the ground up to here, m
# wind_direction = [1.0, 0.0]  # [x, z] the wind blows towards (also scours windward snow)
# wind_speed = 1.5           # m/s
# flake_mass = 3e-6          # kg; terminal velocity v = m·g/drag
# drag = 3e-5                # linear drag coefficient k, kg/s
# ground_slowdown = 0.5      # below this height flakes slow down, m …
# ground_speed_factor = 0.3  # … to this fraction of their speed at the ground
# respawn = "top"            # "top" or "wrap_vertical"
# max_spin = 1.0             # sprite spin, rad/s
# snow_line = 100.0          # altitude of half cover, m
# snow_line_noise = 10.0     # the snow line wanders this much up and down, m …
# noise_scale = 200.0        # … over this horizontal wavelength, m
# transition = 10.0          # height over which cover goes from none to full, m
# full_slope = 25.0          # full cover up to this slope, degrees …
# max_slope = 50.0           # … and none from this slope on
# wind_scour = 0.5           # 0..1: how bare faces turned into the wind are
# depth = 0.3                # snow depth at full cover, m
# mask_px = 512              # cover_mask.png's long side, pixels
# layer = true               # write snow_layer.glb (the snow surface lifted by its depth)
# layer_min_weight = 0.5     # the layer keeps triangles at least this covered
# thin_plants = 0.8          # grass/flowers dropped with probability thin_plants × cover weight
"#;

// ---------------------------------------------------------------------------------------------
// parsing

/// Type of a value as a message says it ("a string", "an integer", …).
fn type_name(value: &DeValue<'_>) -> &'static str {
    match value {
        DeValue::String(_) => "a string",
        DeValue::Integer(_) => "an integer",
        DeValue::Float(_) => "a float",
        DeValue::Boolean(_) => "a boolean",
        DeValue::Datetime(_) => "a date-time",
        DeValue::Array(_) => "an array",
        DeValue::Table(_) => "a table",
    }
}

/// 1-based line and column (in characters) of byte `offset` in `text`.
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

/// The closest of `candidates` to `word`, if it is close enough to be a likely misspelling.
pub fn did_you_mean<'a>(word: &str, candidates: &[&'a str]) -> Option<&'a str> {
    let w = word.to_lowercase().replace('-', "_");
    let (distance, best) =
        candidates.iter().map(|c| (strsim::damerau_levenshtein(&w, c), *c)).min_by_key(|(d, _)| *d)?;
    if distance <= (best.chars().count() / 3).max(1) {
        return Some(best);
    }
    // a fragment of a longer key (`error` → `max_error`)
    candidates.iter().find(|c| w.chars().count() >= 4 && c.contains(w.as_str())).copied()
}

fn backticked(items: &[&str]) -> String {
    items.iter().map(|k| format!("`{k}`")).collect::<Vec<_>>().join(", ")
}

/// The text being parsed and where it came from.
struct Ctx<'a> {
    file: &'a Path,
    text: &'a str,
}

impl Ctx<'_> {
    fn at(&self, span: &Range<usize>, problem: impl Into<String>, remedy: impl Into<String>) -> PresetError {
        let (line, column) = line_column(self.text, span.start);
        PresetError::At { file: self.file.to_path_buf(), line, column, problem: problem.into(), remedy: remedy.into() }
    }
}

type Entry<'a, 'i> = (&'a Spanned<std::borrow::Cow<'i, str>>, &'a Spanned<DeValue<'i>>);

/// A table of the document being read: `[scene]`, `[terrain]` or the procedural inline table.
struct Table<'a, 'i> {
    ctx: &'a Ctx<'a>,
    /// How messages name it: "[terrain]", "`procedural`".
    label: String,
    /// Where "missing key" problems point: the table's name.
    span: Range<usize>,
    table: &'a DeTable<'i>,
}

impl<'a, 'i> Table<'a, 'i> {
    /// Entries in the order they appear in the file.
    fn entries(&self) -> Vec<Entry<'a, 'i>> {
        let mut entries: Vec<Entry<'a, 'i>> = self.table.iter().collect();
        entries.sort_by_key(|(k, _)| k.span().start);
        entries
    }

    /// Every key must be one of `known`; `elsewhere` lists other tables' keys for "belongs in".
    fn check_keys(&self, known: &[&str], elsewhere: &[(&str, &[&str])]) -> Result<(), PresetError> {
        for (key, _) in self.entries() {
            let name: &str = key.get_ref();
            if known.contains(&name) {
                continue;
            }
            let problem = format!("unknown key `{name}` in {}", self.label);
            let homes: Vec<&str> = elsewhere.iter().filter(|(_, keys)| keys.contains(&name)).map(|(t, _)| *t).collect();
            let remedy = if let Some(suggestion) = did_you_mean(name, known) {
                format!("did you mean `{suggestion}`?")
            } else if !homes.is_empty() {
                format!("`{name}` belongs in {}", homes.join(" or "))
            } else {
                format!("the keys of {} are {}", self.label, backticked(known))
            };
            return Err(self.ctx.at(&key.span(), problem, remedy));
        }
        Ok(())
    }

    fn get(&self, key: &str) -> Option<Entry<'a, 'i>> {
        self.table.iter().find(|(k, _)| k.get_ref() == key)
    }

    fn wrong_type(&self, key: &str, value: &Spanned<DeValue<'_>>, expected: &str, example: &str) -> PresetError {
        self.ctx.at(
            &value.span(),
            format!("`{key}` must be {expected}, found {}", type_name(value.get_ref())),
            format!("write it like `{example}`"),
        )
    }

    fn missing(&self, key: &str, example: &str) -> PresetError {
        self.ctx.at(&self.span, format!("{} has no `{key}`", self.label), format!("add `{example}`"))
    }

    fn string(&self, key: &str, example: &str) -> Result<Option<(&'a str, Range<usize>)>, PresetError> {
        match self.get(key) {
            None => Ok(None),
            Some((_, v)) => match v.get_ref() {
                DeValue::String(s) => Ok(Some((s.as_ref(), v.span()))),
                _ => Err(self.wrong_type(key, v, "a string", example)),
            },
        }
    }

    /// An integer in `range` (inclusive), as u64.
    fn integer(
        &self,
        key: &str,
        range: std::ops::RangeInclusive<u64>,
        example: &str,
    ) -> Result<Option<(u64, Range<usize>)>, PresetError> {
        match self.get(key) {
            None => Ok(None),
            Some((_, v)) => integer_value(self, key, v, range, example).map(|n| Some((n, v.span()))),
        }
    }

    /// A number (integer or float), finite, checked by `valid` (which says what is wrong).
    fn number(
        &self,
        key: &str,
        example: &str,
        valid: impl Fn(f64) -> Result<(), String>,
    ) -> Result<Option<(f64, Range<usize>)>, PresetError> {
        match self.get(key) {
            None => Ok(None),
            Some((_, v)) => number_value(self, key, v, example, &valid).map(|x| Some((x, v.span()))),
        }
    }
}

fn integer_value(
    t: &Table<'_, '_>,
    key: &str,
    v: &Spanned<DeValue<'_>>,
    range: std::ops::RangeInclusive<u64>,
    example: &str,
) -> Result<u64, PresetError> {
    let DeValue::Integer(i) = v.get_ref() else {
        return Err(t.wrong_type(key, v, "an integer", example));
    };
    let n = i64::from_str_radix(i.as_str(), i.radix()).map_err(|_| {
        t.ctx.at(&v.span(), format!("`{key}` = {i} is out of range"), format!("use a value in {range:?}"))
    })?;
    match u64::try_from(n) {
        Ok(n) if range.contains(&n) => Ok(n),
        _ => Err(t.ctx.at(
            &v.span(),
            format!("`{key}` must be between {} and {}, got {n}", range.start(), range.end()),
            format!("write it like `{example}`"),
        )),
    }
}

fn number_value(
    t: &Table<'_, '_>,
    key: &str,
    v: &Spanned<DeValue<'_>>,
    example: &str,
    valid: &dyn Fn(f64) -> Result<(), String>,
) -> Result<f64, PresetError> {
    let x = match v.get_ref() {
        DeValue::Integer(i) => i64::from_str_radix(i.as_str(), i.radix()).ok().map(|n| n as f64),
        DeValue::Float(f) => f.as_str().parse::<f64>().ok(),
        _ => return Err(t.wrong_type(key, v, "a number", example)),
    };
    let x = x.ok_or_else(|| {
        t.ctx.at(&v.span(), format!("`{key}` is not a number TOML can hold"), format!("write it like `{example}`"))
    })?;
    if !x.is_finite() {
        return Err(t.ctx.at(
            &v.span(),
            format!("`{key}` must be a finite number, got {x}"),
            format!("write it like `{example}`"),
        ));
    }
    valid(x)
        .map_err(|why| t.ctx.at(&v.span(), format!("`{key}` {why}, got {x}"), format!("write it like `{example}`")))?;
    Ok(x)
}

fn positive(x: f64) -> Result<(), String> {
    if x > 0.0 {
        Ok(())
    } else {
        Err("must be greater than 0".into())
    }
}

fn non_negative(x: f64) -> Result<(), String> {
    if x >= 0.0 {
        Ok(())
    } else {
        Err("must be 0 or more".into())
    }
}

fn any_finite(_: f64) -> Result<(), String> {
    Ok(())
}

/// The CLI's name of a clap value (`terrain-rgb`, `tin`).
fn value_name<T: ValueEnum>(v: &T) -> String {
    v.to_possible_value().map(|p| p.get_name().to_string()).unwrap_or_default()
}

/// Picks the variant of `T` named `s` (the CLI's spelling), or explains the allowed ones.
fn choice<T: ValueEnum + Copy>(t: &Table<'_, '_>, key: &str, s: &str, span: &Range<usize>) -> Result<T, PresetError> {
    if let Some(v) = T::value_variants().iter().find(|v| value_name(*v) == s) {
        return Ok(*v);
    }
    let names: Vec<String> = T::value_variants().iter().map(value_name).collect();
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    Err(unknown_value(t, key, s, &names, span))
}

fn unknown_value(t: &Table<'_, '_>, key: &str, s: &str, allowed: &[&str], span: &Range<usize>) -> PresetError {
    let remedy = match did_you_mean(s, allowed) {
        Some(m) => format!("did you mean \"{m}\"? (allowed: {})", allowed.join(", ")),
        None => format!("allowed values are {}", allowed.join(", ")),
    };
    t.ctx.at(span, format!("unknown `{key}` value \"{s}\""), remedy)
}

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
    let scene = parse_scene(&Table { ctx: &ctx, label: "[scene]".into(), span: scene_span, table: scene_table })?;
    let terrain = match terrain {
        None => None,
        Some((span, table)) => {
            let t = Table { ctx: &ctx, label: "[terrain]".into(), span, table };
            Some(parse_terrain(&t, scene.seed, inputs)?)
        }
    };
    let scatter = match scatter {
        None => ScatterSettings::default(),
        Some((span, table)) => parse_scatter(&Table { ctx: &ctx, label: "[scatter]".into(), span, table })?,
    };
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
            let (s, name_span) = parse_species(&t, &species, &looks, inputs)?;
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

fn parse_scene(t: &Table<'_, '_>) -> Result<SceneSettings, PresetError> {
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
    Ok(SceneSettings { name: name.to_string(), seed, formats })
}

fn parse_terrain(t: &Table<'_, '_>, scene_seed: u64, inputs: Inputs) -> Result<TerrainSettings, PresetError> {
    t.check_keys(TERRAIN_KEYS, &[("[scene]", SCENE_KEYS), ("`procedural = { … }`", PROCEDURAL_KEYS)])?;
    let cell_size_m = t.number("cell_size", "cell_size = 10.0", positive)?.map_or(1.0, |(x, _)| x);

    let source = match (t.get("heightmap"), t.get("procedural")) {
        (Some((hk, _)), Some((pk, _))) => {
            let later = if hk.span().start > pk.span().start { hk } else { pk };
            return Err(t.ctx.at(
                &later.span(),
                "[terrain] has both `heightmap` and `procedural`",
                "keep one of them: a heightmap file or a generated map",
            ));
        }
        (None, None) => {
            return Err(t.ctx.at(
                &t.span,
                "[terrain] has neither `heightmap` nor `procedural`",
                "add `heightmap = \"heights.png\"` or `procedural = { kind = \"fbm\", size = 513, relief = 200.0 }`",
            ));
        }
        (None, Some((_, v))) => {
            // keys that only a file has
            for key in HEIGHTMAP_ONLY_KEYS {
                if let Some((k, _)) = t.get(key) {
                    return Err(t.ctx.at(
                        &k.span(),
                        format!("`{key}` applies to a heightmap file, not to a procedural map"),
                        "remove it",
                    ));
                }
            }
            parse_procedural(t, v, cell_size_m, scene_seed)?
        }
        (Some((_, v)), None) => parse_heightmap(t, v, cell_size_m, inputs)?,
    };

    let mode = match t.string("mode", "mode = \"tin\"")? {
        None => MeshMode::Tin,
        Some((s, span)) => choice::<MeshMode>(t, "mode", s, &span)?,
    };
    let max_error_m = t.number("max_error", "max_error = 1.0", non_negative)?.map_or(1.0, |(x, _)| x);
    let max_triangles =
        t.integer("max_triangles", 2..=u32::MAX as u64, "max_triangles = 200000")?.map(|(n, _)| n as usize);
    let grid_step = t.integer("grid_step", 1..=1 << 20, "grid_step = 2")?.map_or(1, |(n, _)| n as usize);
    let chunk = t.integer("chunk", 2..=1 << 20, "chunk = 256")?.map(|(n, _)| n as usize);
    let skirt_m = t.number("skirt", "skirt = 10.0", positive)?.map(|(x, _)| x);
    let base_m = t.number("base", "base = 20.0", positive)?.map(|(x, _)| x);

    let mut lods = Vec::new();
    if let Some((key, v)) = t.get("lods") {
        let DeValue::Array(items) = v.get_ref() else {
            return Err(t.wrong_type("lods", v, "an array of numbers", "lods = [2.0, 8.0, 32.0]"));
        };
        for item in items.iter() {
            let x = number_value(t, "lods", item, "lods = [2.0, 8.0, 32.0]", &positive)?;
            if let Some(&previous) = lods.last() {
                if x <= previous {
                    return Err(t.ctx.at(
                        &item.span(),
                        format!("`lods` must increase strictly (finest level first), but {x} follows {previous}"),
                        "list each level's max error in metres, smallest first, e.g. `lods = [2.0, 8.0, 32.0]`",
                    ));
                }
            }
            lods.push(x);
        }
        if !lods.is_empty() && mode == MeshMode::Grid {
            return Err(t.ctx.at(
                &key.span(),
                "`lods` needs mode = \"tin\" (levels are max errors of TIN meshes)",
                "set `mode = \"tin\"` or remove `lods`",
            ));
        }
    }

    Ok(TerrainSettings { source, mode, max_error_m, max_triangles, grid_step, chunk, skirt_m, base_m, lods })
}

fn parse_scatter(t: &Table<'_, '_>) -> Result<ScatterSettings, PresetError> {
    t.check_keys(SCATTER_KEYS, &[("[[species]]", SPECIES_KEYS), ("[terrain]", TERRAIN_KEYS), ("[scene]", SCENE_KEYS)])?;
    let tile_m = t.number("tile", "tile = 256.0", positive)?.map_or(DEFAULT_TILE_M, |(x, _)| x);
    Ok(ScatterSettings { tile_m })
}

/// One `[[species]]` table; `earlier` are the species declared before it (in file order), which
/// its exclusions may name. Returns the settings and the span of the `name` value.
/// Defaults of the plant looks (`[grass]`, `[flower]`) and the scene seed they are keyed by.
struct Looks<'a> {
    grass: &'a GrassSettings,
    flower: &'a FlowerSettings,
    tree: &'a TreeLook,
    /// `[tree]` sets `height` (else a built-in tree grows to its species' own height).
    tree_height_set: bool,
    mesh: &'a MeshLook,
    scene_seed: u64,
}

/// Seed of a species' generated look: the scene seed mixed with the species' name and its own
/// offset (two grass species of one scene differ; renaming or `seed` reshuffles one alone).
pub fn species_look_seed(scene_seed: u64, name: &str, species_seed: u64) -> u64 {
    let name_hash = name.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3));
    crate::random::mix64(
        scene_seed ^ crate::random::mix64(name_hash ^ crate::random::mix64(species_seed.wrapping_add(0x6c6f_6f6b))),
    )
}

fn parse_look(
    t: &Table<'_, '_>,
    name: &str,
    kind: SpeciesKind,
    looks: &Looks<'_>,
    seed: u64,
    inputs: Inputs,
) -> Result<PlantLook, PresetError> {
    for (key, owner) in [
        ("grass", SpeciesKind::Grass),
        ("flower", SpeciesKind::Flower),
        ("tree", SpeciesKind::Tree),
        ("lsystem", SpeciesKind::Tree),
        ("mesh", SpeciesKind::Mesh),
        ("obj", SpeciesKind::Mesh),
    ] {
        if let Some((k, _)) = t.get(key) {
            if kind != owner {
                let owner_name = value_name_kind(owner);
                let what = if matches!(key, "lsystem" | "obj") {
                    format!("`{key} = \"…\"`")
                } else {
                    format!("`{key} = {{ … }}`")
                };
                return Err(t.ctx.at(
                    &k.span(),
                    format!(
                        "{what} describes kind = \"{owner_name}\", but {} is kind = \"{}\"",
                        t.label,
                        value_name_kind(kind)
                    ),
                    format!("remove `{key}` or set `kind = \"{owner_name}\"`"),
                ));
            }
        }
    }
    Ok(match kind {
        SpeciesKind::Grass => {
            let base = GrassSettings { seed: species_look_seed(looks.scene_seed, name, seed), ..looks.grass.clone() };
            match t.get("grass") {
                None => PlantLook::Grass(base),
                Some((_, v)) => {
                    PlantLook::Grass(plants::apply_grass(&plants::sub_table(t, "grass", v)?, base, inputs)?)
                }
            }
        }
        SpeciesKind::Flower => {
            let base = FlowerSettings { seed: species_look_seed(looks.scene_seed, name, seed), ..looks.flower.clone() };
            match t.get("flower") {
                None => PlantLook::Flower(base),
                Some((_, v)) => PlantLook::Flower(plants::apply_flower(&plants::sub_table(t, "flower", v)?, base)?),
            }
        }
        SpeciesKind::Tree => {
            // `lsystem = "builtin:<name>"` or no `lsystem`: a tree of the built-in library
            // (crate::lsystem::library), grown to its species' height unless `height` is set
            let builtin = match t.get("lsystem") {
                Some((_, v)) => match v.get_ref() {
                    DeValue::String(text) if text.starts_with(library::PREFIX) => match library::named(Path::new(text.as_ref())) {
                        Some(Ok(species)) => Some(species),
                        _ => {
                            return Err(t.ctx.at(
                                &v.span(),
                                format!("`{text}` names no built-in L-system"),
                                format!("use one of {} as `lsystem = \"builtin:conifer\"`, or a .ls file relative to this preset", library::names()),
                            ))
                        }
                    },
                    _ => None,
                },
                None => Some(library::for_species_name(name)),
            };
            let lsystem = match builtin {
                Some(species) => library::path_of(species),
                None => input_path(t, "lsystem", "lsystem = \"trees/birch.ls\"", inputs)?
                    .expect("`lsystem` was found above"),
            };
            let mut base =
                TreeLook { lsystem, seed: species_look_seed(looks.scene_seed, name, seed), ..looks.tree.clone() };
            let species_sets_height = match t.get("tree") {
                Some((_, v)) => {
                    matches!(v.get_ref(), DeValue::Table(table) if table.iter().any(|(k, _)| k.get_ref() == "height"))
                }
                None => false,
            };
            if let Some(species) = builtin {
                if !looks.tree_height_set && !species_sets_height {
                    base.height_m = Some(species.height_m);
                }
            }
            let look = match t.get("tree") {
                None => base,
                Some((_, v)) => plants::apply_tree(&plants::sub_table(t, "tree", v)?, base)?,
            };
            if inputs.exist() {
                // the .ls file is parsed now so a bad rule is reported before anything is built
                if let Err(e) = crate::lsystem::parse::read_file(&look.lsystem, look.dialect) {
                    let (k, v) = t.get("lsystem").expect("lsystem was read above");
                    let _ = k;
                    return Err(t.ctx.at(
                        &v.span(),
                        format!("the L-system of {} does not parse:\n{e}", t.label),
                        "fix the file at the position shown, or force its format with `tree = { dialect = \"v5\" }`",
                    ));
                }
            }
            PlantLook::Tree(look)
        }
        SpeciesKind::Mesh => {
            let Some(obj) = input_path(t, "obj", "obj = \"rocks/boulder.obj\"", inputs)? else {
                if let Some((k, _)) = t.get("mesh") {
                    return Err(t.ctx.at(
                        &k.span(),
                        format!("`mesh = {{ … }}` says how to read {}'s model, but it names no `obj` file", t.label),
                        "add `obj = \"rocks/boulder.obj\"` (relative to this preset), or remove `mesh`",
                    ));
                }
                // documented: a mesh species without a model is drawn as a marker
                return Ok(PlantLook::Marker);
            };
            let base = MeshLook { obj, ..looks.mesh.clone() };
            let look = match t.get("mesh") {
                None => base,
                Some((_, v)) => plants::apply_mesh(&plants::sub_table(t, "mesh", v)?, base)?,
            };
            if inputs.decode() {
                // the model as the plants stage loads it (scale, up axis, MTL, textures, limits)
                let options = crate::plants::mesh_asset::ObjOptions {
                    scale: look.scale,
                    up_axis: look.up_axis,
                    ..Default::default()
                };
                if let Err(e) = crate::plants::mesh_asset::load_obj(&look.obj, &options) {
                    let (_, v) = t.get("obj").expect("obj was read above");
                    return Err(t.ctx.at(
                        &v.span(),
                        format!("the model of {} does not load:\n{e}", t.label),
                        "fix the OBJ (or its MTL and textures), or `mesh = { scale, up_axis }`",
                    ));
                }
            }
            PlantLook::Mesh(look)
        }
    })
}

fn value_name_kind(kind: SpeciesKind) -> &'static str {
    match kind {
        SpeciesKind::Grass => "grass",
        SpeciesKind::Flower => "flower",
        SpeciesKind::Tree => "tree",
        SpeciesKind::Mesh => "mesh",
    }
}

fn parse_species(
    t: &Table<'_, '_>,
    earlier: &[SpeciesSettings],
    looks: &Looks<'_>,
    inputs: Inputs,
) -> Result<(SpeciesSettings, Range<usize>), PresetError> {
    let (name, name_span) = t.string("name", "name = \"oak\"")?.ok_or_else(|| t.missing("name", "name = \"oak\""))?;
    check_species_name(name).map_err(|why| {
        t.ctx.at(&name_span, why, "use only letters, digits, `-` and `_`, e.g. `name = \"scots-pine\"`")
    })?;
    // from here on, messages name the species
    let t = &Table { ctx: t.ctx, label: format!("[[species]] `{name}`"), span: t.span.clone(), table: t.table };
    t.check_keys(
        SPECIES_KEYS,
        &[
            ("`exclusion = { … }`", EXCLUSION_KEYS),
            ("[scatter]", SCATTER_KEYS),
            ("[terrain]", TERRAIN_KEYS),
            ("[scene]", SCENE_KEYS),
        ],
    )?;

    let kind = match t.string("kind", "kind = \"tree\"")? {
        None => {
            return Err(t.ctx.at(
                &t.span,
                format!("{} has no `kind`", t.label),
                "add `kind = \"grass\"` (or \"flower\", \"tree\", \"mesh\")",
            ))
        }
        Some(("grass", _)) => SpeciesKind::Grass,
        Some(("flower", _)) => SpeciesKind::Flower,
        Some(("tree", _)) => SpeciesKind::Tree,
        Some(("mesh", _)) => SpeciesKind::Mesh,
        Some((other, span)) => {
            return Err(unknown_value(t, "kind", other, &["grass", "flower", "tree", "mesh"], &span))
        }
    };
    let density_map = input_path(t, "density_map", "density_map = \"maps/grass.png\"", inputs)?;
    let mask = input_path(t, "mask", "mask = \"maps/meadow-mask.png\"", inputs)?;
    let max_density = t
        .number("max_density", "max_density = 0.5", positive)?
        .ok_or_else(|| {
            t.ctx.at(
                &t.span,
                format!("{} has no `max_density`", t.label),
                "add `max_density = 0.5` (instances per square metre)",
            )
        })?
        .0;

    let placement = match t.string("placement", "placement = \"poisson\"")? {
        None if kind == SpeciesKind::Tree => Placement::Poisson,
        None => Placement::Jittered,
        Some(("poisson", _)) => Placement::Poisson,
        Some(("jittered", _)) => Placement::Jittered,
        Some((other, span)) => return Err(unknown_value(t, "placement", other, &["poisson", "jittered"], &span)),
    };
    let min_spacing = t.number("min_spacing", "min_spacing = 4.0", non_negative)?;
    let min_spacing_m = match (placement, min_spacing) {
        (Placement::Poisson, Some((x, span))) if x <= 0.0 => {
            return Err(t.ctx.at(
                &span,
                "`min_spacing` must be greater than 0 for placement = \"poisson\" (it is the Poisson-disk radius)",
                "give the smallest distance in metres between two instances, e.g. `min_spacing = 4.0`, or use `placement = \"jittered\"`",
            ));
        }
        (Placement::Jittered, Some((x, span))) if x > 0.0 => {
            return Err(t.ctx.at(
                &span,
                format!("`min_spacing` = {x} is kept only by placement = \"poisson\"; {} is placed \"jittered\", which keeps no spacing", t.label),
                "remove `min_spacing` (or set it to 0), or set `placement = \"poisson\"` to keep instances that far apart",
            ));
        }
        (_, Some((x, _))) => x,
        (Placement::Poisson, None) if kind == SpeciesKind::Tree => DEFAULT_TREE_SPACING_M,
        (Placement::Poisson, None) => {
            return Err(t.ctx.at(
                &t.span,
                format!(
                    "{} has no `min_spacing`, which placement = \"poisson\" needs (only trees have a default)",
                    t.label
                ),
                "add `min_spacing = 1.0` (metres between two instances) or use `placement = \"jittered\"`",
            ));
        }
        (Placement::Jittered, None) => 0.0,
    };

    let slope_deg = pair(t, "slope", "slope = [0.0, 35.0]", "degrees", |x| {
        if (0.0..=90.0).contains(&x) {
            Ok(())
        } else {
            Err("must be between 0 and 90 degrees".into())
        }
    })?
    .unwrap_or([0.0, 90.0]);
    let altitude_m =
        pair(t, "altitude", "altitude = [200.0, 1800.0]", "metres", any_finite)?.unwrap_or(UNBOUNDED_ALTITUDE_M);
    let water_level_m = t.number("water_level", "water_level = 2.0", any_finite)?.map(|(x, _)| x);
    let scale = match t.get("scale") {
        // a single number: every instance the same size
        Some((_, v)) if matches!(v.get_ref(), DeValue::Integer(_) | DeValue::Float(_)) => {
            let x = number_value(t, "scale", v, "scale = [0.8, 1.2]", &positive)?;
            [x, x]
        }
        _ => pair(t, "scale", "scale = [0.8, 1.2]", "", positive)?.unwrap_or([1.0, 1.0]),
    };
    let random_yaw = match t.get("random_yaw") {
        None => true,
        Some((_, v)) => match v.get_ref() {
            DeValue::Boolean(b) => *b,
            _ => return Err(t.wrong_type("random_yaw", v, "a boolean", "random_yaw = false")),
        },
    };
    let align_to_normal = t
        .number("align_to_normal", "align_to_normal = 0.5", |x| {
            if (0.0..=1.0).contains(&x) {
                Ok(())
            } else {
                Err("must be between 0 (upright) and 1 (along the terrain normal)".into())
            }
        })?
        .map_or(
            match kind {
                SpeciesKind::Grass | SpeciesKind::Flower => 1.0,
                SpeciesKind::Tree | SpeciesKind::Mesh => 0.0,
            },
            |(x, _)| x,
        );
    let exclusions = match t.get("exclusion") {
        None => Vec::new(),
        Some((_, v)) => parse_exclusions(t, v, name, earlier)?,
    };
    let seed = t.integer("seed", 0..=i64::MAX as u64, "seed = 1")?.map_or(0, |(s, _)| s);
    let max_instances = t
        .integer("max_instances", 1..=MAX_MAX_INSTANCES, "max_instances = 5000000")?
        .map_or(DEFAULT_MAX_INSTANCES, |(n, _)| n as usize);
    let cull_distance_m = t.number("cull_distance", "cull_distance = 80.0", positive)?.map(|(x, _)| x);
    let look = parse_look(t, name, kind, looks, seed, inputs)?;

    let species = SpeciesSettings {
        rules: SpeciesRules {
            name: name.to_string(),
            density_map,
            mask,
            max_density,
            placement,
            min_spacing_m,
            slope_deg,
            altitude_m,
            water_level_m,
            scale,
            random_yaw,
            align_to_normal,
            exclusions,
            seed,
            max_instances,
        },
        kind,
        cull_distance_m,
        look,
    };
    Ok((species, name_span))
}

/// `exclusion = { species, radius }` or an array of such tables. The named species must be
/// declared earlier (it is placed first) or be `this` species itself.
fn parse_exclusions(
    t: &Table<'_, '_>,
    value: &Spanned<DeValue<'_>>,
    this: &str,
    earlier: &[SpeciesSettings],
) -> Result<Vec<Exclusion>, PresetError> {
    let example = "exclusion = { species = \"oak\", radius = 1.5 }";
    let items: Vec<&Spanned<DeValue<'_>>> = match value.get_ref() {
        DeValue::Table(_) => vec![value],
        DeValue::Array(items) => items.iter().collect(),
        _ => return Err(t.wrong_type("exclusion", value, "a table or an array of tables", example)),
    };
    let mut exclusions: Vec<Exclusion> = Vec::new();
    for item in items {
        let DeValue::Table(table) = item.get_ref() else {
            return Err(t.wrong_type("exclusion", item, "a table", example));
        };
        let e = Table { ctx: t.ctx, label: "`exclusion`".into(), span: item.span(), table };
        e.check_keys(EXCLUSION_KEYS, &[("[[species]]", SPECIES_KEYS)])?;
        let (other, span) =
            e.string("species", "species = \"oak\"")?.ok_or_else(|| e.missing("species", "species = \"oak\""))?;
        let radius_m =
            e.number("radius", "radius = 1.5", positive)?.ok_or_else(|| e.missing("radius", "radius = 1.5"))?.0;
        if other != this && !earlier.iter().any(|s| s.rules.name == other) {
            let names: Vec<&str> = earlier.iter().map(|s| s.rules.name.as_str()).chain([this]).collect();
            let remedy = match did_you_mean(other, &names) {
                Some(m) => format!("did you mean `{m}`?"),
                None if earlier.is_empty() => format!(
                    "declare `{other}` in a [[species]] before `{this}` (it is placed first), or name `{this}` itself to keep its instances apart"
                ),
                None => format!(
                    "declare `{other}` in a [[species]] before `{this}` (it is placed first); species declared so far: {}",
                    backticked(&names)
                ),
            };
            return Err(t.ctx.at(
                &span,
                format!("exclusion names species `{other}`, which is not declared before `{this}`"),
                remedy,
            ));
        }
        if exclusions.iter().any(|x| x.species == other) {
            return Err(t.ctx.at(
                &span,
                format!("species `{other}` is excluded twice in `{this}`"),
                "keep one exclusion per species (the larger radius)",
            ));
        }
        exclusions.push(Exclusion { species: other.to_string(), radius_m });
    }
    Ok(exclusions)
}

/// `key = [min, max]`: two numbers, each checked by `valid`, min ≤ max.
fn pair(
    t: &Table<'_, '_>,
    key: &str,
    example: &str,
    unit: &str,
    valid: impl Fn(f64) -> Result<(), String>,
) -> Result<Option<[f64; 2]>, PresetError> {
    let Some((_, v)) = t.get(key) else { return Ok(None) };
    let expected =
        if unit.is_empty() { "an array [min, max]".to_string() } else { format!("an array [min, max] in {unit}") };
    let DeValue::Array(items) = v.get_ref() else {
        return Err(t.wrong_type(key, v, &expected, example));
    };
    if items.len() != 2 {
        return Err(t.ctx.at(
            &v.span(),
            format!("`{key}` must have two numbers [min, max], found {}", items.len()),
            format!("write it like `{example}`"),
        ));
    }
    let min = number_value(t, key, &items[0], example, &valid)?;
    let max = number_value(t, key, &items[1], example, &valid)?;
    if min > max {
        return Err(t.ctx.at(
            &v.span(),
            format!("`{key}` is [min, max], but {min} > {max}"),
            format!("put the smaller value first, e.g. `{example}`"),
        ));
    }
    Ok(Some([min, max]))
}

/// An optional input file (`density_map`, `mask`): resolved against the preset's folder; when
/// `inputs` asks, it must exist and be a file, and decode.
fn input_path(
    t: &Table<'_, '_>,
    key: &'static str,
    example: &str,
    inputs: Inputs,
) -> Result<Option<PathBuf>, PresetError> {
    let Some((_, value)) = t.get(key) else { return Ok(None) };
    let DeValue::String(relative) = value.get_ref() else {
        return Err(t.wrong_type(key, value, "a path (a string)", example));
    };
    if relative.is_empty() {
        return Err(t.ctx.at(
            &value.span(),
            format!("`{key}` is empty"),
            format!("name a grayscale image, relative to this preset, or remove `{key}`"),
        ));
    }
    let path = resolve(t.ctx.file, Path::new(relative.as_ref()));
    if inputs.exist() {
        check_input_file(t, value, key, &path)?;
    }
    if inputs.decode() {
        let problem = match key {
            "density_map" | "mask" => crate::scatter::DensityMap::load(&path).err().map(|e| e.to_string()),
            "blade_texture" => crate::bake::image::Image::read_png(&path).err().map(|e| e.to_string()),
            _ => None,
        };
        if let Some(e) = problem {
            return Err(t.ctx.at(
                &value.span(),
                format!("`{key}` does not decode: {e}"),
                "give a PNG (8 or 16 bit; density maps and masks are read as grayscale)",
            ));
        }
    }
    Ok(Some(path))
}

/// An input file named at `value` must exist and be a file.
fn check_input_file(
    t: &Table<'_, '_>,
    value: &Spanned<DeValue<'_>>,
    what: &'static str,
    path: &Path,
) -> Result<(), PresetError> {
    if !path.exists() {
        let (line, column) = line_column(t.ctx.text, value.span().start);
        return Err(PresetError::MissingInput {
            file: t.ctx.file.to_path_buf(),
            line,
            column,
            what,
            input: path.to_path_buf(),
        });
    }
    if !path.is_file() {
        return Err(t.ctx.at(
            &value.span(),
            format!("{what} `{}` is not a file", path.display()),
            format!("name the {what} file itself, not its folder"),
        ));
    }
    Ok(())
}

fn parse_procedural(
    terrain: &Table<'_, '_>,
    value: &Spanned<DeValue<'_>>,
    cell_size_m: f64,
    scene_seed: u64,
) -> Result<TerrainSource, PresetError> {
    let example = "procedural = { kind = \"fbm\", size = 513, seed = 7, relief = 200.0 }";
    let DeValue::Table(table) = value.get_ref() else {
        return Err(terrain.wrong_type("procedural", value, "a table", example));
    };
    let t = Table { ctx: terrain.ctx, label: "`procedural`".into(), span: value.span(), table };
    t.check_keys(PROCEDURAL_KEYS, &[("[terrain]", TERRAIN_KEYS), ("[scene]", SCENE_KEYS)])?;
    let noise = match t.string("kind", "kind = \"fbm\"")? {
        None => NoiseKind::Fbm,
        Some(("fbm", _)) => NoiseKind::Fbm,
        Some(("ridged", _)) => NoiseKind::Ridged,
        Some((other, span)) => return Err(unknown_value(&t, "kind", other, &["fbm", "ridged"], &span)),
    };
    let size =
        t.integer("size", PROCEDURAL_SIZES, "size = 513")?.ok_or_else(|| t.missing("size", "size = 513"))?.0 as usize;
    let seed = t.integer("seed", 0..=i64::MAX as u64, "seed = 7")?.map_or(scene_seed, |(s, _)| s);
    let relief_m =
        t.number("relief", "relief = 200.0", positive)?.ok_or_else(|| t.missing("relief", "relief = 200.0"))?.0;
    Ok(TerrainSource::Fbm { size, seed, relief_m, cell_size_m, noise })
}

fn parse_heightmap(
    t: &Table<'_, '_>,
    value: &Spanned<DeValue<'_>>,
    cell_size_m: f64,
    inputs: Inputs,
) -> Result<TerrainSource, PresetError> {
    let DeValue::String(relative) = value.get_ref() else {
        return Err(t.wrong_type("heightmap", value, "a path (a string)", "heightmap = \"heights/valley.png\""));
    };
    if relative.is_empty() {
        return Err(t.ctx.at(
            &value.span(),
            "`heightmap` is empty",
            "name the heightmap file, relative to this preset",
        ));
    }
    let path = resolve(t.ctx.file, Path::new(relative.as_ref()));
    let mut decode = DecodeOptions { cell_size_m, ..DecodeOptions::default() };
    if let Some((s, span)) = t.string("encoding", "encoding = \"gray\"")? {
        decode.encoding = choice::<Encoding>(t, "encoding", s, &span)?;
    }
    if let Some((_, v)) = t.get("size") {
        let example = "size = [1025, 1025]";
        match v.get_ref() {
            DeValue::Array(items) if items.len() == 2 => {
                let w = integer_value(t, "size", &items[0], 1..=1 << 20, example)? as usize;
                let h = integer_value(t, "size", &items[1], 1..=1 << 20, example)? as usize;
                decode.size = Some((w, h));
            }
            _ => return Err(t.wrong_type("size", v, "an array of two integers [width, height]", example)),
        }
    }
    if let Some((x, _)) = t.number("height_scale", "height_scale = 100.0", any_finite)? {
        decode.height_scale_m = x;
    }
    if let Some((x, _)) = t.number("height_offset", "height_offset = 0.0", any_finite)? {
        decode.height_offset_m = x;
    }
    decode.max_samples = t
        .integer("max_samples", 1..=i64::MAX as u64, "max_samples = 67125249")?
        .map_or(DEFAULT_MAX_SAMPLES, |(n, _)| n as usize);

    if inputs.exist() {
        check_input_file(t, value, "heightmap", &path)?;
    }
    if inputs.decode() {
        let decoded = crate::input::read_limited(&path, crate::input::MAX_HEIGHTMAP_BYTES, "a heightmap")
            .map_err(|e| e.to_string())
            .and_then(|bytes| crate::heightfield::decode(&path, &bytes, &decode).map_err(|e| e.to_string()));
        if let Err(e) = decoded {
            return Err(t.ctx.at(
                &value.span(),
                format!("the heightmap does not decode as this preset reads it: {e}"),
                "fix `encoding` (and `size`, `height_scale` for raw maps) in [terrain], or the file",
            ));
        }
    }
    Ok(TerrainSource::Heightmap { path, decode })
}

/// `relative` as seen from the folder of the preset file `preset` (absolute paths stay as they are).
pub fn resolve(preset: &Path, relative: &Path) -> PathBuf {
    match preset.parent() {
        Some(dir) if relative.is_relative() && !dir.as_os_str().is_empty() => dir.join(relative),
        _ => relative.to_path_buf(),
    }
}

#[cfg(test)]
mod tests {
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
