//! The `[snow]` section of a preset: crystal atlas, emitter, cover and plant thinning in one flat
//! table (documented key by key in docs/presets.md). Each key is checked where it stands; the
//! settings are then checked as a whole by [`SnowSettings::check`], reported at the section.

use toml::de::DeValue;

use super::error::PresetError;
use super::reader::{number_value, Table};
use crate::snow::emitter::Respawn;
use crate::snow::{FarField, SnowSettings};

/// Keys of `[snow]`.
pub const SNOW_KEYS: &[&str] = &[
    "seed",
    "temperature_c",
    "humidity",
    "atlas_cells",
    "cell_px",
    "alpha_cutoff",
    "near_radius",
    "near_count",
    "far_radius",
    "far_count",
    "view_angle",
    "fall_height",
    "wind_direction",
    "wind_speed",
    "flake_mass",
    "drag",
    "ground_slowdown",
    "ground_speed_factor",
    "respawn",
    "max_spin",
    "snow_line",
    "snow_line_noise",
    "noise_scale",
    "transition",
    "full_slope",
    "max_slope",
    "wind_scour",
    "depth",
    "mask_px",
    "layer",
    "layer_min_weight",
    "thin_plants",
];

/// Seed of the snow when `[snow] seed` is absent: the scene seed mixed with a tag, so the snow
/// changes with the scene seed but not with anything else.
pub fn default_snow_seed(scene_seed: u64) -> u64 {
    crate::random::mix64(scene_seed ^ 0x0073_6e6f_7773_6565) // "snowsee"
}

fn in_range(lo: f64, hi: f64, unit: &'static str) -> impl Fn(f64) -> Result<(), String> {
    move |x| if (lo..=hi).contains(&x) { Ok(()) } else { Err(format!("must be between {lo} and {hi}{unit}")) }
}

fn positive_up_to(hi: f64, unit: &'static str) -> impl Fn(f64) -> Result<(), String> {
    move |x| if x > 0.0 && x <= hi { Ok(()) } else { Err(format!("must be greater than 0 and at most {hi}{unit}")) }
}

/// A float key in `valid`, stored with `set` when present.
fn num(
    t: &Table<'_, '_>,
    key: &str,
    example: &str,
    valid: impl Fn(f64) -> Result<(), String>,
    set: impl FnOnce(f64),
) -> Result<(), PresetError> {
    if let Some((x, _)) = t.number(key, example, valid)? {
        set(x);
    }
    Ok(())
}

/// `key = [a, b]`: two numbers, each checked by `valid` (no order between them).
fn two(
    t: &Table<'_, '_>,
    key: &str,
    example: &str,
    valid: impl Fn(f64) -> Result<(), String>,
) -> Result<Option<[f64; 2]>, PresetError> {
    let Some((_, v)) = t.get(key) else { return Ok(None) };
    let DeValue::Array(items) = v.get_ref() else {
        return Err(t.wrong_type(key, v, "an array of two numbers", example));
    };
    if items.len() != 2 {
        return Err(t.ctx.at(
            &v.span(),
            format!("`{key}` must have two numbers, found {}", items.len()),
            format!("write it like `{example}`"),
        ));
    }
    Ok(Some([number_value(t, key, &items[0], example, &valid)?, number_value(t, key, &items[1], example, &valid)?]))
}

/// Reads `[snow]` over the defaults; `scene_seed` seeds it when it has no `seed`.
pub(super) fn parse_snow(t: &Table<'_, '_>, scene_seed: u64) -> Result<SnowSettings, PresetError> {
    t.check_keys(
        SNOW_KEYS,
        &[
            ("[scene]", super::keys::SCENE_KEYS),
            ("[terrain]", super::keys::TERRAIN_KEYS),
            ("[grass]", super::plants::GRASS_KEYS),
        ],
    )?;
    let mut s = SnowSettings::default();
    let seed = t.integer("seed", 0..=i64::MAX as u64, "seed = 3")?.map_or(default_snow_seed(scene_seed), |(n, _)| n);
    s.flakes.seed = seed;
    s.emitter.seed = seed;
    s.cover.seed = seed;

    // crystals
    num(
        t,
        "temperature_c",
        "temperature_c = -15.0",
        in_range(-40.0, 2.0, " °C (snow forms between −40 and +2 °C)"),
        |x| s.flakes.temperature_c = x as f32,
    )?;
    num(t, "humidity", "humidity = 0.6", in_range(0.0, 1.0, ""), |x| s.flakes.humidity = x as f32)?;
    if let Some((_, v)) = t.get("atlas_cells") {
        let example = "atlas_cells = [4, 4]";
        match v.get_ref() {
            DeValue::Array(items) if items.len() == 2 => {
                s.flakes.columns = super::reader::integer_value(t, "atlas_cells", &items[0], 1..=32, example)? as u32;
                s.flakes.rows = super::reader::integer_value(t, "atlas_cells", &items[1], 1..=32, example)? as u32;
            }
            _ => return Err(t.wrong_type("atlas_cells", v, "an array of two integers [columns, rows]", example)),
        }
    }
    if let Some((n, _)) = t.integer("cell_px", 16..=1024, "cell_px = 64")? {
        s.flakes.cell_px = n as u32;
    }
    num(t, "alpha_cutoff", "alpha_cutoff = 0.5", in_range(0.05, 0.95, ""), |x| s.flakes.alpha_cutoff = x as f32)?;

    // emitter
    let e = &mut s.emitter;
    num(t, "near_radius", "near_radius = 15.0", in_range(0.1, 10_000.0, " m"), |x| e.near_radius_m = x as f32)?;
    if let Some((n, _)) = t.integer("near_count", 0..=crate::snow::emitter::MAX_FLAKES as u64, "near_count = 4000")? {
        e.near_count = n as u32;
    }
    let far_count = t.integer("far_count", 0..=crate::snow::emitter::MAX_FLAKES as u64, "far_count = 6000")?;
    let far_radius = t.number("far_radius", "far_radius = 60.0", positive_up_to(100_000.0, " m"))?;
    let view_angle = t.number("view_angle", "view_angle = 90.0", in_range(1.0, 360.0, " degrees"))?;
    match far_count {
        // far_count = 0: no far field; its other keys would be silently unused
        Some((0, _)) => {
            if let Some((k, _)) = t.get("far_radius").or(t.get("view_angle")) {
                return Err(t.ctx.at(
                    &k.span(),
                    format!("`{}` describes the far field, but far_count = 0 turns it off", k.get_ref()),
                    "remove it, or give far_count > 0",
                ));
            }
            e.far = None;
        }
        _ => {
            let mut far = e.far.clone().unwrap_or(FarField { outer_radius_m: 60.0, count: 6000, view_angle_deg: 90.0 });
            if let Some((n, _)) = far_count {
                far.count = n as u32;
            }
            if let Some((x, span)) = far_radius {
                if x as f32 <= e.near_radius_m {
                    return Err(t.ctx.at(
                        &span,
                        format!("`far_radius` = {x} must be larger than near_radius = {}", e.near_radius_m),
                        "the far field is the ring between near_radius and far_radius: make far_radius larger, or set far_count = 0",
                    ));
                }
                far.outer_radius_m = x as f32;
            }
            if let Some((x, _)) = view_angle {
                far.view_angle_deg = x as f32;
            }
            e.far = Some(far);
        }
    }
    num(t, "fall_height", "fall_height = 20.0", in_range(0.1, 10_000.0, " m"), |x| e.fall_height_m = x as f32)?;
    if let Some(d) = two(t, "wind_direction", "wind_direction = [1.0, 0.0]", |x| {
        if x.abs() <= 1e6 {
            Ok(())
        } else {
            Err("must be at most 1e6 in size".into())
        }
    })? {
        if d[0] * d[0] + d[1] * d[1] <= 1e-12 {
            let span = t.get("wind_direction").map(|(_, v)| v.span()).unwrap_or(t.span.clone());
            return Err(t.ctx.at(&span, "`wind_direction` is [0, 0], which has no direction", "give the [x, z] the wind blows towards, e.g. `wind_direction = [1.0, 0.0]`; use wind_speed = 0 for calm air"));
        }
        e.wind_direction = [d[0] as f32, d[1] as f32];
        s.cover.wind_direction = e.wind_direction;
    }
    num(t, "wind_speed", "wind_speed = 1.5", in_range(0.0, 100.0, " m/s"), |x| e.wind_speed_m_s = x as f32)?;
    num(t, "flake_mass", "flake_mass = 3e-6", positive_up_to(1e-3, " kg (flakes weigh about 1e-6 kg)"), |x| {
        e.flake_mass_kg = x as f32
    })?;
    num(t, "drag", "drag = 3e-5", positive_up_to(1.0, " kg/s"), |x| e.drag_kg_s = x as f32)?;
    num(t, "ground_slowdown", "ground_slowdown = 0.5", in_range(0.0, 10_000.0, " m"), |x| {
        e.ground_slowdown_m = x as f32
    })?;
    num(t, "ground_speed_factor", "ground_speed_factor = 0.3", in_range(0.0, 1.0, ""), |x| {
        e.ground_speed_factor = x as f32
    })?;
    match t.string("respawn", "respawn = \"top\"")? {
        None => {}
        Some(("top", _)) => e.respawn = Respawn::Top,
        Some(("wrap_vertical", _)) => e.respawn = Respawn::WrapVertical,
        Some((other, span)) => {
            return Err(super::reader::unknown_value(t, "respawn", other, &["top", "wrap_vertical"], &span))
        }
    }
    num(t, "max_spin", "max_spin = 1.0", in_range(0.0, 100.0, " rad/s"), |x| e.max_spin_rad_s = x as f32)?;

    // cover
    let c = &mut s.cover;
    num(t, "snow_line", "snow_line = 120.0", in_range(-20_000.0, 20_000.0, " m"), |x| c.snow_line_m = x as f32)?;
    num(t, "snow_line_noise", "snow_line_noise = 15.0", in_range(0.0, 10_000.0, " m"), |x| {
        c.snow_line_noise_m = x as f32
    })?;
    num(t, "noise_scale", "noise_scale = 200.0", in_range(0.01, 1e6, " m"), |x| c.noise_scale_m = x as f32)?;
    num(t, "transition", "transition = 10.0", in_range(0.0, 10_000.0, " m"), |x| c.transition_m = x as f32)?;
    num(t, "full_slope", "full_slope = 25.0", in_range(0.0, 90.0, " degrees"), |x| c.full_slope_deg = x as f32)?;
    num(t, "max_slope", "max_slope = 50.0", in_range(0.0, 90.0, " degrees"), |x| c.max_slope_deg = x as f32)?;
    if c.full_slope_deg >= c.max_slope_deg {
        let span = t.get("max_slope").or(t.get("full_slope")).map(|(_, v)| v.span()).unwrap_or(t.span.clone());
        return Err(t.ctx.at(
            &span,
            format!("full_slope = {}° must be below max_slope = {}°", c.full_slope_deg, c.max_slope_deg),
            "snow lies fully up to full_slope and none from max_slope on: e.g. `full_slope = 25.0`, `max_slope = 50.0`",
        ));
    }
    num(t, "wind_scour", "wind_scour = 0.5", in_range(0.0, 1.0, ""), |x| c.wind_scour = x as f32)?;
    num(t, "depth", "depth = 0.3", in_range(0.0, 100.0, " m"), |x| c.max_depth_m = x as f32)?;
    if let Some((n, _)) = t.integer("mask_px", 16..=8192, "mask_px = 512")? {
        s.mask_px = n as u32;
    }
    if let Some(b) = t.boolean("layer", "layer = true")? {
        s.layer = b;
    }
    num(t, "layer_min_weight", "layer_min_weight = 0.5", in_range(0.0, 1.0, ""), |x| s.layer_min_weight = x as f32)?;
    num(t, "thin_plants", "thin_plants = 0.8", in_range(0.0, 1.0, ""), |x| s.thin_plants = x)?;

    s.check().map_err(|e| t.ctx.at(&t.span, format!("{}: {e}", t.label), "see docs/presets.md, section [snow]"))?;
    Ok(s)
}
