//! What a preset may say: its sections and keys, the limits on its values, and the names that
//! become folder and file names.

/// The sections a preset may have, in the order the docs list them (`species` is an array of
/// tables, `[[species]]`).
pub const SECTIONS: &[&str] =
    &["scene", "terrain", "species", "scatter", "grass", "flower", "tree", "mesh", "snow", "lod", "view"];
/// Keys of `[scene]`.
pub const SCENE_KEYS: &[&str] = &["name", "seed", "formats", "compact", "tile", "lod_scene"];
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

/// What the plants stage adds to a species' name in its files' names (before the extension;
/// `#` is a number): its chain and levels (`species/<name>.glb`, `<name>_LOD<n>.glb`), a tree's
/// variants (`<name>_v<k>…`), a grass' far card (`_far`), its atlases and their mip levels
/// (`atlases/<name>.png`, `_mip<k>`, `_blade`, `_blade_mip<k>`, `_density`, `_normal`).
const FILE_ENDINGS: [&str; 12] = [
    "",
    "_LOD#",
    "_v#",
    "_v#_LOD#",
    "_v#_mip#",
    "_v#_normal",
    "_far",
    "_blade",
    "_blade_mip#",
    "_density",
    "_normal",
    "_mip#",
];

/// Whether `text` is `pattern` (`#`: one or more digits), ignoring ASCII case.
fn fits(text: &[u8], pattern: &[u8]) -> bool {
    match pattern.split_first() {
        None => text.is_empty(),
        Some((b'#', rest)) => {
            let digits = text.iter().take_while(|c| c.is_ascii_digit()).count();
            (1..=digits).any(|n| fits(&text[n..], rest))
        }
        Some((p, rest)) => text.first().is_some_and(|c| c.eq_ignore_ascii_case(p)) && fits(&text[1..], rest),
    }
}

/// When species `shorter` and `longer` can write a file of the same name (compared ignoring case,
/// as file systems may), the name shared, without its extension: `longer` is `shorter`, `_` and
/// more, and some file of `longer`'s is named as one of `shorter`'s (a grass `g` writes
/// `atlases/g_blade.png`, and so does a species named `g_blade`; a tree `x` writes
/// `species/x_LOD0.glb`, as a species `x_LOD0` does). Kinds aside: a name that clashes with a
/// file some kind writes is refused.
pub fn file_name_clash(shorter: &str, longer: &str) -> Option<String> {
    if !longer.get(..shorter.len())?.eq_ignore_ascii_case(shorter) {
        return None;
    }
    let rest = &longer[shorter.len()..];
    if !rest.starts_with('_') {
        return None;
    }
    for theirs in FILE_ENDINGS {
        // one file of `longer`'s (any number will do: both sides take any)
        let file = format!("{rest}{}", theirs.replace('#', "1"));
        if FILE_ENDINGS[1..].iter().any(|ours| fits(file.as_bytes(), ours.as_bytes())) {
            return Some(format!("{longer}{}", theirs.replace('#', "1")));
        }
    }
    None
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
