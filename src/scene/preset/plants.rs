//! The plant-look tables of a preset: `[grass]` / `[flower]` (defaults for every species of that
//! kind) and a species' own `grass = { … }` / `flower = { … }` (overriding them key by key).

use toml::de::DeValue;
use toml::Spanned;

use super::error::PresetError;
use super::reader::{input_path, number_value, pair, Table};
use crate::color::srgb_to_linear_f64;
use crate::plants::flower::FlowerSettings;
use crate::plants::grass::GrassSettings;
use crate::scene::{MeshLook, TreeLook};

/// Keys of `[grass]` and `grass = { … }`.
pub const GRASS_KEYS: &[&str] = &[
    "blades",
    "clump_size",
    "segments",
    "height",
    "width",
    "bend",
    "density_levels",
    "variants",
    "wind_frequency",
    "stiffness",
    "root_color",
    "tip_color",
    "hue_jitter",
    "value_jitter",
    "alpha_cutoff",
    "atlas_px",
    "far_cells",
    "blade_texture",
];
/// Keys of `[tree]` and `tree = { … }` (the L-system file itself is the species' `lsystem`).
pub const TREE_KEYS: &[&str] = &[
    "variants",
    "height",
    "radial_segments",
    "lods",
    "atlas_size",
    "max_segments",
    "max_triangles",
    "max_symbols",
    "dialect",
    "analysis",
];
/// Keys of `[mesh]` and `mesh = { … }` (the model itself is the species' `obj`).
pub const MESH_KEYS: &[&str] = &["scale", "up_axis", "lods", "atlas_size", "analysis", "max_vertices", "max_triangles"];
/// Keys of `[flower]` and `flower = { … }`.
pub const FLOWER_KEYS: &[&str] =
    &["petals", "petal_color", "center_color", "stem_color", "height", "head", "variants", "alpha_cutoff", "atlas_px"];

/// A colour as `"#rrggbb"` or `[r, g, b]` in 0..1, both sRGB (as colour pickers show them);
/// returned linear.
fn colour(t: &Table<'_, '_>, key: &str) -> Result<Option<[f32; 3]>, PresetError> {
    let example = format!("{key} = \"#6a9a2c\"");
    let Some((_, v)) = t.get(key) else { return Ok(None) };
    match v.get_ref() {
        DeValue::String(s) => {
            let hex = s.strip_prefix('#').unwrap_or(s);
            let parsed = (hex.len() == 6 && hex.bytes().all(|b| b.is_ascii_hexdigit())).then(|| {
                std::array::from_fn(|k| {
                    u8::from_str_radix(&hex[2 * k..2 * k + 2], 16).map(|x| srgb_to_linear_f64(x as f64 / 255.0))
                })
            });
            match parsed {
                Some([Ok(r), Ok(g), Ok(b)]) => Ok(Some([r, g, b])),
                _ => Err(t.ctx.at(
                    &v.span(),
                    format!("`{key}` = {s:?} is not a colour"),
                    format!("write it as six hex digits, like `{example}`, or as `[0.4, 0.6, 0.17]`"),
                )),
            }
        }
        DeValue::Array(items) if items.len() == 3 => {
            let in01 =
                |x: f64| if (0.0..=1.0).contains(&x) { Ok(()) } else { Err("must be between 0 and 1".to_string()) };
            let mut c = [0.0f32; 3];
            for (k, item) in items.iter().enumerate() {
                c[k] = srgb_to_linear_f64(number_value(t, key, item, &example, &in01)?);
            }
            Ok(Some(c))
        }
        _ => Err(t.wrong_type(key, v, "a colour (\"#rrggbb\" or [r, g, b] in 0..1)", &example)),
    }
}

fn count(
    t: &Table<'_, '_>,
    key: &str,
    range: std::ops::RangeInclusive<u64>,
    example: &str,
) -> Result<Option<usize>, PresetError> {
    Ok(t.integer(key, range, example)?.map(|(n, _)| n as usize))
}

fn unit_interval(x: f64) -> Result<(), String> {
    if (0.0..=1.0).contains(&x) {
        Ok(())
    } else {
        Err("must be between 0 and 1".into())
    }
}

fn positive(x: f64) -> Result<(), String> {
    if x > 0.0 {
        Ok(())
    } else {
        Err("must be greater than 0".into())
    }
}

fn range_f32(r: [f64; 2]) -> [f32; 2] {
    [r[0] as f32, r[1] as f32]
}

/// Applies the keys of a grass table to `base`. Ranges are checked again as a whole by
/// [`GrassSettings::check`], whose message is reported at the table.
pub(super) fn apply_grass(
    t: &Table<'_, '_>,
    mut g: GrassSettings,
    inputs: super::error::Inputs,
) -> Result<GrassSettings, PresetError> {
    t.check_keys(GRASS_KEYS, &[("[flower]", FLOWER_KEYS), ("[tree]", TREE_KEYS)])?;
    if let Some(n) = count(t, "blades", 1..=crate::plants::grass::MAX_BLADES_PER_CLUMP as u64, "blades = 48")? {
        g.blades_per_clump = n;
    }
    if let Some((x, _)) = t.number("clump_size", "clump_size = 0.5", positive)? {
        g.clump_size_m = x as f32;
    }
    if let Some(n) = count(t, "segments", 2..=crate::plants::grass::MAX_SEGMENTS as u64, "segments = 5")? {
        g.segments = n;
    }
    if let Some(r) = pair(t, "height", "height = [0.25, 0.5]", "metres", positive)? {
        g.height_m = range_f32(r);
    }
    if let Some(r) = pair(t, "width", "width = [0.008, 0.016]", "metres", positive)? {
        g.width_m = range_f32(r);
    }
    let degrees =
        |x: f64| if (0.0..=85.0).contains(&x) { Ok(()) } else { Err("must be between 0 and 85 degrees".to_string()) };
    if let Some(r) = pair(t, "bend", "bend = [10.0, 50.0]", "degrees", degrees)? {
        g.bend_rad = [r[0].to_radians() as f32, r[1].to_radians() as f32];
    }
    if let Some(n) =
        count(t, "density_levels", 1..=crate::plants::grass::MAX_DENSITY_LEVELS as u64, "density_levels = 3")?
    {
        g.density_levels = n;
    }
    if let Some(n) = count(t, "variants", 1..=crate::plants::grass::MAX_VARIANTS as u64, "variants = 2")? {
        g.variants = n;
    }
    if let Some(r) = pair(t, "wind_frequency", "wind_frequency = [0.8, 1.8]", "Hz", |x| {
        if (0.0..=crate::plants::grass::WIND_MAX_FREQUENCY_HZ as f64).contains(&x) {
            Ok(())
        } else {
            Err(format!("must be between 0 and {} Hz", crate::plants::grass::WIND_MAX_FREQUENCY_HZ))
        }
    })? {
        g.wind_frequency_hz = range_f32(r);
    }
    if let Some(r) = pair(t, "stiffness", "stiffness = [0.3, 0.8]", "", unit_interval)? {
        g.stiffness = range_f32(r);
    }
    if let Some(c) = colour(t, "root_color")? {
        g.root_color = c;
    }
    if let Some(c) = colour(t, "tip_color")? {
        g.tip_color = c;
    }
    if let Some((x, _)) = t.number("hue_jitter", "hue_jitter = 0.25", unit_interval)? {
        g.hue_jitter = x as f32;
    }
    if let Some((x, _)) = t.number("value_jitter", "value_jitter = 0.15", |x| {
        if (0.0..=0.5).contains(&x) {
            Ok(())
        } else {
            Err("must be between 0 and 0.5".into())
        }
    })? {
        g.value_jitter = x as f32;
    }
    if let Some((x, _)) = t.number("alpha_cutoff", "alpha_cutoff = 0.75", |x| {
        if (0.05..=0.95).contains(&x) {
            Ok(())
        } else {
            Err("must be between 0.05 and 0.95 (0.7–0.78 ≈ 180–200/255 avoids halos)".into())
        }
    })? {
        g.alpha_cutoff = x as f32;
    }
    if let Some(n) = count(t, "atlas_px", 16..=4096, "atlas_px = 256")? {
        g.atlas_px = n as u32;
    }
    if let Some(n) = count(t, "far_cells", 1..=8, "far_cells = 3")? {
        g.far_cells = n;
    }
    if let Some(p) = input_path(t, "blade_texture", "blade_texture = \"textures/blade.png\"", inputs)? {
        g.blade_texture = Some(p);
    }
    g.check().map_err(|e| t.ctx.at(&t.span, format!("{}: {e}", t.label), "see docs/presets.md, section [grass]"))?;
    Ok(g)
}

pub(super) fn apply_flower(t: &Table<'_, '_>, mut f: FlowerSettings) -> Result<FlowerSettings, PresetError> {
    t.check_keys(FLOWER_KEYS, &[("[grass]", GRASS_KEYS), ("[tree]", TREE_KEYS)])?;
    if let Some(n) = count(t, "petals", 3..=32, "petals = 7")? {
        f.petals = n;
    }
    for (key, slot) in
        [("petal_color", &mut f.petal_color), ("center_color", &mut f.center_color), ("stem_color", &mut f.stem_color)]
    {
        if let Some(c) = colour(t, key)? {
            *slot = c;
        }
    }
    if let Some(r) = pair(t, "height", "height = [0.2, 0.35]", "metres", positive)? {
        f.height_m = range_f32(r);
    }
    if let Some((x, _)) = t.number("head", "head = 0.06", positive)? {
        f.head_m = x as f32;
    }
    if let Some(n) = count(t, "variants", 1..=16, "variants = 4")? {
        f.variants = n;
    }
    if let Some((x, _)) = t.number("alpha_cutoff", "alpha_cutoff = 0.75", |x| {
        if (0.05..=0.95).contains(&x) {
            Ok(())
        } else {
            Err("must be between 0.05 and 0.95".into())
        }
    })? {
        f.alpha_cutoff = x as f32;
    }
    if let Some(n) = count(t, "atlas_px", 16..=2048, "atlas_px = 128")? {
        f.atlas_px = n as u32;
    }
    f.check().map_err(|e| t.ctx.at(&t.span, format!("{}: {e}", t.label), "see docs/presets.md, section [flower]"))?;
    Ok(f)
}

/// Applies the keys of a tree table to `base`.
pub(super) fn apply_tree(t: &Table<'_, '_>, mut tree: TreeLook) -> Result<TreeLook, PresetError> {
    use crate::plants::tree::MAX_RADIAL_SEGMENTS;
    t.check_keys(TREE_KEYS, &[("[mesh]", MESH_KEYS), ("[grass]", GRASS_KEYS), ("[flower]", FLOWER_KEYS)])?;
    if let Some(n) = count(t, "variants", 1..=16, "variants = 3")? {
        tree.variants = n;
    }
    match t.get("height") {
        Some((_, v)) if matches!(v.get_ref(), DeValue::String(s) if s == "file") => tree.height_m = None,
        _ => {
            if let Some((x, _)) = t.number("height", "height = 12.0", |x| {
                if x > 0.0 && x <= 500.0 {
                    Ok(())
                } else {
                    Err("must be between 0 and 500 metres (or \"file\" to keep the file's step length)".into())
                }
            })? {
                tree.height_m = Some(x);
            }
        }
    }
    if let Some(n) = count(t, "radial_segments", 3..=MAX_RADIAL_SEGMENTS as u64, "radial_segments = 8")? {
        tree.radial_segments = n as u32;
    }
    chain_keys(t, &mut tree.lods, &mut tree.atlas_px, &mut tree.analyze)?;
    if let Some((n, _)) = t.integer("max_symbols", 1..=10_000_000_000, "max_symbols = 50000000")? {
        tree.max_symbols = n;
    }
    if let Some((n, _)) = t.integer("max_segments", 1..=100_000_000, "max_segments = 200000")? {
        tree.max_segments = n;
    }
    if let Some((n, _)) = t.integer("max_triangles", 1..=u32::MAX as u64, "max_triangles = 8000000")? {
        tree.max_triangles = n;
    }
    if let Some((name, span)) = t.string("dialect", "dialect = \"v5\"")? {
        tree.dialect = match name {
            "auto" => None,
            "ls" => Some(crate::lsystem::Dialect::Stochastic),
            "v4" => Some(crate::lsystem::Dialect::LparserV4),
            "v5" => Some(crate::lsystem::Dialect::LparserV5),
            other => return Err(super::reader::unknown_value(t, "dialect", other, &["auto", "ls", "v4", "v5"], &span)),
        };
    }
    Ok(tree)
}

/// `lods`, `atlas_size` and `analysis` of a tree or mesh table.
fn chain_keys(t: &Table<'_, '_>, lods: &mut usize, atlas_px: &mut u32, analyze: &mut bool) -> Result<(), PresetError> {
    use crate::plants::tree_lod::{MAX_ATLAS_PX, MIN_ATLAS_PX, TREE_LODS};
    if let Some(n) = count(t, "lods", 1..=TREE_LODS as u64, "lods = 5")? {
        *lods = n;
    }
    if let Some((n, span)) = t.integer("atlas_size", MIN_ATLAS_PX as u64..=MAX_ATLAS_PX as u64, "atlas_size = 1024")? {
        if n % 16 != 0 {
            return Err(t.ctx.at(
                &span,
                format!("`atlas_size` = {n} is not a multiple of 16"),
                "use e.g. `atlas_size = 1024` or 2048",
            ));
        }
        *atlas_px = n as u32;
    }
    if let Some((_, v)) = t.get("analysis") {
        match v.get_ref() {
            DeValue::Boolean(b) => *analyze = *b,
            _ => return Err(t.wrong_type("analysis", v, "a boolean", "analysis = false")),
        }
    }
    Ok(())
}

/// Applies the keys of a mesh table to `base`.
pub(super) fn apply_mesh(t: &Table<'_, '_>, mut mesh: MeshLook) -> Result<MeshLook, PresetError> {
    use crate::plants::mesh_asset::UpAxis;
    t.check_keys(MESH_KEYS, &[("[tree]", TREE_KEYS), ("[grass]", GRASS_KEYS), ("[flower]", FLOWER_KEYS)])?;
    if let Some((x, _)) = t.number("scale", "scale = 0.01", |x| {
        if x > 0.0 && x <= 1e6 {
            Ok(())
        } else {
            Err("must be greater than 0 (metres per file unit: 0.01 for centimetres)".into())
        }
    })? {
        mesh.scale = x;
    }
    if let Some((axis, span)) = t.string("up_axis", "up_axis = \"z\"")? {
        mesh.up_axis = match axis {
            "y" | "Y" => UpAxis::Y,
            "z" | "Z" => UpAxis::Z,
            other => return Err(super::reader::unknown_value(t, "up_axis", other, &["y", "z"], &span)),
        };
    }
    chain_keys(t, &mut mesh.lods, &mut mesh.atlas_px, &mut mesh.analyze)?;
    if let Some((n, _)) = t.integer("max_vertices", 3..=u32::MAX as u64, "max_vertices = 4000000")? {
        mesh.max_vertices = n as usize;
    }
    if let Some((n, _)) = t.integer("max_triangles", 1..=u32::MAX as u64, "max_triangles = 1000000")? {
        mesh.max_triangles = n as usize;
    }
    Ok(mesh)
}

/// A species' `grass = { … }` or `flower = { … }` value as a table to read.
pub(super) fn sub_table<'a, 'i>(
    t: &Table<'a, 'i>,
    key: &str,
    v: &'a Spanned<DeValue<'i>>,
) -> Result<Table<'a, 'i>, PresetError> {
    match v.get_ref() {
        DeValue::Table(table) => {
            Ok(Table { ctx: t.ctx, label: format!("`{key}` of {}", t.label), span: v.span(), table })
        }
        _ => Err(t.wrong_type(key, v, "a table", &format!("{key} = {{ height = [0.2, 0.4] }}"))),
    }
}
