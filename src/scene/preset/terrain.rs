//! `[terrain]`: a heightmap file (decoded as the build will, when asked) or a procedural map.

use std::path::Path;

use toml::de::DeValue;
use toml::Spanned;

use super::error::{Inputs, PresetError};
use super::keys::{HEIGHTMAP_ONLY_KEYS, PROCEDURAL_KEYS, PROCEDURAL_SIZES, SCENE_KEYS, TERRAIN_KEYS};
use super::reader::{
    any_finite, check_input_file, choice, integer_value, non_negative, number_value, positive, resolve, unknown_value,
    Table,
};
use crate::heightfield::{DecodeOptions, Encoding, DEFAULT_MAX_SAMPLES};
use crate::scene::{TerrainSettings, TerrainSource};
use crate::synth::NoiseKind;
use crate::terrain::job::MeshMode;

pub(super) fn parse_terrain(
    t: &Table<'_, '_>,
    scene_seed: u64,
    inputs: Inputs,
) -> Result<TerrainSettings, PresetError> {
    t.check_keys(TERRAIN_KEYS, &[("[scene]", SCENE_KEYS), ("`procedural = { … }`", PROCEDURAL_KEYS)])?;
    let cell_size = t.number("cell_size", "cell_size = 10.0", |x| {
        positive(x)?;
        // one cell alone cannot pass the extent limit; a whole map is checked with its size
        crate::heightfield::check_extent(2, 2, x).map_err(|_| {
            format!(
                "must be at most {:e} m (Earth's circumference): it is the distance between neighbouring samples",
                crate::heightfield::MAX_EXTENT_M
            )
        })
    })?;
    let cell_size_m = cell_size.as_ref().map_or(1.0, |(x, _)| *x);

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
            let source = parse_procedural(t, v, cell_size_m, scene_seed)?;
            if let (TerrainSource::Fbm { size, .. }, Some((_, span))) = (&source, &cell_size) {
                crate::heightfield::check_extent(*size, *size, cell_size_m)
                    .map_err(|problem| t.ctx.at(span, problem, "lower `cell_size` or `size`"))?;
            }
            source
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
    let max_vertices = t
        .integer("max_vertices", 4..=u32::MAX as u64, "max_vertices = 4000000")?
        .map_or(crate::terrain::budget::DEFAULT_MAX_VERTICES, |(n, _)| n as usize);
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

    Ok(TerrainSettings {
        source,
        mode,
        max_error_m,
        max_triangles,
        max_vertices,
        grid_step,
        chunk,
        skirt_m,
        base_m,
        lods,
    })
}

pub(super) fn parse_procedural(
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

pub(super) fn parse_heightmap(
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
