//! The `[lod]` section (the scene's LoD policy: pixel budget and reference screen) and the
//! `[[view]]` cameras of a preset, documented key by key in docs/presets.md.

use toml::de::DeValue;

use super::error::PresetError;
use super::reader::{number_value, Table};
use crate::lod::LodView;
use crate::scene::view::{ViewSettings, DEFAULT_VIEW_FOV_DEG, DEFAULT_VIEW_SIZE_PX, MAX_VIEW_SIDE_PX};

/// Keys of `[lod]`.
pub const LOD_KEYS: &[&str] = &["max_pixel_error", "screen_height", "fov"];
/// Keys of `[[view]]`.
pub const VIEW_KEYS: &[&str] = &["name", "position", "target", "yaw", "pitch", "fov", "size"];

fn in_range(lo: f64, hi: f64, unit: &'static str) -> impl Fn(f64) -> Result<(), String> {
    move |x| if x > lo && x <= hi { Ok(()) } else { Err(format!("must be greater than {lo} and at most {hi}{unit}")) }
}

/// `[lod]` over the default policy ([`LodView::default`]).
pub(super) fn parse_lod(t: &Table<'_, '_>) -> Result<LodView, PresetError> {
    t.check_keys(LOD_KEYS, &[("[[view]]", VIEW_KEYS)])?;
    let mut v = LodView::default();
    if let Some((x, _)) = t.number("max_pixel_error", "max_pixel_error = 2.0", in_range(0.0, 1000.0, " px"))? {
        v.max_screen_error_px = x;
    }
    if let Some((x, _)) = t.number("screen_height", "screen_height = 1080", in_range(0.0, 65_536.0, " px"))? {
        v.screen_height_px = x;
    }
    if let Some((x, _)) = t.number("fov", "fov = 60.0", in_range(0.0, 179.0, " degrees (vertical field of view)"))? {
        v.fov_y_deg = x;
    }
    Ok(v)
}

fn three(t: &Table<'_, '_>, key: &str, example: &str) -> Result<Option<[f64; 3]>, PresetError> {
    let Some((_, v)) = t.get(key) else { return Ok(None) };
    let DeValue::Array(items) = v.get_ref() else {
        return Err(t.wrong_type(key, v, "an array [x, y, z] in metres", example));
    };
    if items.len() != 3 {
        return Err(t.ctx.at(
            &v.span(),
            format!("`{key}` must have three numbers [x, y, z], found {}", items.len()),
            format!("write it like `{example}`"),
        ));
    }
    let finite = |x: f64| if x.abs() <= 1e7 { Ok(()) } else { Err("must be within ±10 000 km".to_string()) };
    let mut out = [0.0; 3];
    for (o, item) in out.iter_mut().zip(items.iter()) {
        *o = number_value(t, key, item, example, &finite)?;
    }
    Ok(Some(out))
}

/// One `[[view]]` table (`index` names it when it has no `name`).
pub(super) fn parse_view(t: &Table<'_, '_>, index: usize) -> Result<ViewSettings, PresetError> {
    t.check_keys(VIEW_KEYS, &[("[lod]", LOD_KEYS)])?;
    let name = match t.string("name", "name = \"overlook\"")? {
        Some((s, span)) => {
            super::keys::check_safe_name("view", "file", s)
                .map_err(|e| t.ctx.at(&span, e, "use letters, digits, `-` and `_`"))?;
            s.to_string()
        }
        None => format!("view{index}"),
    };
    let position = three(t, "position", "position = [500.0, 120.0, 900.0]")?;
    let target = three(t, "target", "target = [500.0, 40.0, 500.0]")?;
    let yaw = t.number("yaw", "yaw = 180.0", |x| {
        if x.abs() <= 360.0 {
            Ok(())
        } else {
            Err("must be within ±360 degrees".into())
        }
    })?;
    let pitch = t.number("pitch", "pitch = -10.0", |x| {
        if x.abs() < 90.0 {
            Ok(())
        } else {
            Err("must be between −90 and 90 degrees (exclusive)".into())
        }
    })?;
    if let (Some(_), Some((_, span))) = (&target, yaw.as_ref().or(pitch.as_ref())) {
        return Err(t.ctx.at(span, "a view has either `target` or `yaw`/`pitch`, not both", "remove one of them"));
    }
    let fov = t
        .number("fov", "fov = 60.0", in_range(0.0, 179.0, " degrees (vertical field of view)"))?
        .map_or(DEFAULT_VIEW_FOV_DEG, |(x, _)| x);
    let size = match t.get("size") {
        None => DEFAULT_VIEW_SIZE_PX,
        Some((_, v)) => {
            let example = "size = [1920, 1080]";
            match v.get_ref() {
                DeValue::Array(items) if items.len() == 2 => [
                    super::reader::integer_value(t, "size", &items[0], 16..=MAX_VIEW_SIDE_PX as u64, example)? as u32,
                    super::reader::integer_value(t, "size", &items[1], 16..=MAX_VIEW_SIDE_PX as u64, example)? as u32,
                ],
                _ => {
                    return Err(t.wrong_type("size", v, "an array of two integers [width, height] in pixels", example))
                }
            }
        }
    };
    Ok(ViewSettings {
        name,
        position,
        target,
        yaw_pitch_deg: match (yaw, pitch) {
            (None, None) => None,
            (y, p) => Some([y.map_or(0.0, |(x, _)| x), p.map_or(0.0, |(x, _)| x)]),
        },
        fov_y_deg: fov,
        size_px: size,
    })
}
