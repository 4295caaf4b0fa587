//! What a preset may say: its sections and keys, the limits on its values, and the names that
//! become folder and file names.

/// The sections a preset may have, in the order the docs list them (`species` is an array of
/// tables, `[[species]]`).
pub const SECTIONS: &[&str] =
    &["scene", "terrain", "species", "scatter", "grass", "flower", "tree", "mesh", "snow", "lod", "view"];
/// Keys of `[scene]`.
pub const SCENE_KEYS: &[&str] = &["name", "seed", "formats", "compact"];
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
    "max_vertices",
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
    "vegetation_type",
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
pub const SCATTER_KEYS: &[&str] = &["tile", "table", "vegetation_map"];
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
pub(super) const HEIGHTMAP_ONLY_KEYS: &[&str] = &["encoding", "size", "height_scale", "height_offset", "max_samples"];
/// Sizes a procedural map may have (samples per side).
pub const PROCEDURAL_SIZES: std::ops::RangeInclusive<u64> = 2..=8193;
/// Longest scene name (it becomes a folder name).
pub const MAX_NAME_CHARS: usize = 64;

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

/// The words a species' file names add to its name after `_` (`species/<name>_LOD<n>.glb`,
/// `<name>_v<k>…` variants, `<name>_far.glb`, `atlases/<name>_blade.png`, `_density`, `_normal`,
/// `_mip<k>` atlas levels).
const FILE_SUFFIX_WORDS: [&str; 7] = ["lod#", "v#", "far", "blade", "density", "normal", "mip#"];

/// When species `longer` is named `shorter` followed by `_` and one of the words the plants stage
/// adds to `shorter`'s file names (compared ignoring case, as file systems may), the word: the two
/// species can write the same file (a grass `g` writes `atlases/g_blade.png`, and so does a
/// species named `g_blade`), one overwriting the other's.
pub fn file_name_clash<'a>(shorter: &str, longer: &'a str) -> Option<&'a str> {
    if !longer.get(..shorter.len())?.eq_ignore_ascii_case(shorter) {
        return None;
    }
    let word = longer[shorter.len()..].strip_prefix('_')?;
    let word = word.split('_').next().unwrap_or(word);
    let lower = word.to_ascii_lowercase();
    let fits = FILE_SUFFIX_WORDS.iter().any(|w| match w.strip_suffix('#') {
        Some(prefix) => lower
            .strip_prefix(prefix)
            .is_some_and(|digits| !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit())),
        None => lower == *w,
    });
    fits.then_some(word)
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
