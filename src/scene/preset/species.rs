//! `[[species]]`: placement rules, the plant look and its inputs, exclusions.

use std::ops::Range;
use std::path::Path;

use toml::de::DeValue;
use toml::Spanned;

use super::error::{Inputs, PresetError};
use super::keys::{
    check_species_name, DEFAULT_MAX_INSTANCES, DEFAULT_TREE_SPACING_M, EXCLUSION_KEYS, MAX_MAX_INSTANCES, SCATTER_KEYS,
    SCENE_KEYS, SPECIES_KEYS, TERRAIN_KEYS,
};
use super::plants;
use super::reader::{
    any_finite, backticked, did_you_mean, input_path, non_negative, number_value, pair, positive, unknown_value, Table,
};
use crate::lsystem::library;
use crate::plants::flower::FlowerSettings;
use crate::plants::grass::GrassSettings;
use crate::plants::SpeciesKind;
use crate::scatter::{Exclusion, Placement, SpeciesRules, UNBOUNDED_ALTITUDE_M};
use crate::scene::{MeshLook, PlantLook, SpeciesSettings, TreeLook};

/// Defaults of the plant looks (`[grass]`, `[flower]`) and the scene seed they are keyed by.
pub(super) struct Looks<'a> {
    pub(super) grass: &'a GrassSettings,
    pub(super) flower: &'a FlowerSettings,
    pub(super) tree: &'a TreeLook,
    /// `[tree]` sets `height` (else a built-in tree grows to its species' own height).
    pub(super) tree_height_set: bool,
    pub(super) mesh: &'a MeshLook,
    pub(super) scene_seed: u64,
}

/// Seed of a species' generated look: the scene seed mixed with the species' name and its own
/// offset (two grass species of one scene differ; renaming or `seed` reshuffles one alone).
pub fn species_look_seed(scene_seed: u64, name: &str, species_seed: u64) -> u64 {
    let name_hash = name.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3));
    crate::random::mix64(
        scene_seed ^ crate::random::mix64(name_hash ^ crate::random::mix64(species_seed.wrapping_add(0x6c6f_6f6b))),
    )
}

pub(super) fn parse_look(
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
                if let Err(e) = crate::plants::mesh_asset::load_obj(&look.obj, &look.obj_options()) {
                    let (_, v) = t.get("obj").expect("obj was read above");
                    return Err(t.ctx.at(
                        &v.span(),
                        format!("the model of {} does not load:\n{e}", t.label),
                        "fix the OBJ (or its MTL and textures), or `mesh = { scale, up_axis, max_vertices, max_triangles }`",
                    ));
                }
            }
            PlantLook::Mesh(look)
        }
    })
}

pub(super) fn value_name_kind(kind: SpeciesKind) -> &'static str {
    match kind {
        SpeciesKind::Grass => "grass",
        SpeciesKind::Flower => "flower",
        SpeciesKind::Tree => "tree",
        SpeciesKind::Mesh => "mesh",
    }
}

/// One `[[species]]` table; `earlier` are the species declared before it (in file order), which
/// its exclusions may name; `vegetation_map`: whether `[scatter]` names a map of vegetation types
/// (which `vegetation_type` needs). Returns the settings and the span of the `name` value.
pub(super) fn parse_species(
    t: &Table<'_, '_>,
    earlier: &[SpeciesSettings],
    looks: &Looks<'_>,
    inputs: Inputs,
    vegetation_map: bool,
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
    let vegetation_type = match t.integer("vegetation_type", 0..=255, "vegetation_type = 3")? {
        Some((_, span)) if !vegetation_map => return Err(t.ctx.at(
            &span,
            format!("{} has a `vegetation_type`, but there is no map of types", t.label),
            "add `vegetation_map = \"maps/vegetation.png\"` to `[scatter]` (a grey image whose shade N marks where \
                 `vegetation_type = N` grows), or remove `vegetation_type`",
        )),
        other => other.map(|(n, _)| n as u8),
    };
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
        vegetation_type,
        look,
    };
    Ok((species, name_span))
}

/// `exclusion = { species, radius }` or an array of such tables. The named species must be
/// declared earlier (it is placed first) or be `this` species itself.
pub(super) fn parse_exclusions(
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
