//! The snowfall emitter an engine particle system reads (`emitter.json`): the snowfall thesis'
//! near cylinder around the camera plus a far sector inside the view angle, gravity with linear
//! drag (dv/dt = g − (k/m)·v, so the terminal velocity is v = m·g/k), wind, and a respawn rule.

use serde::{Deserialize, Serialize};

use crate::snow::error::{bad, within, SnowError};
use crate::snow::flakes::FlakeAtlas;

/// Standard gravity, m/s².
pub const GRAVITY_M_S2: f32 = 9.806_65;
/// Flakes per field at most (an engine draws them every frame).
pub const MAX_FLAKES: u32 = 1_000_000;

/// The far field: flakes between `near_radius_m` and `outer_radius_m`, only inside the horizontal
/// view angle (centred on the camera's −Z, the glTF camera's view direction).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FarField {
    pub outer_radius_m: f32,
    pub count: u32,
    pub view_angle_deg: f32,
}

/// Everything the engine's particle system needs; documented field by field in docs/snow.md.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Emitter {
    /// Radius of the cylinder around the camera holding `near_count` flakes (r1).
    pub near_radius_m: f32,
    pub near_count: u32,
    pub far: Option<FarField>,
    /// Flakes spawn between the camera's ground level (y = 0) and this height.
    pub fall_height_m: f32,
    /// Horizontal wind direction (x, z); normalised when read.
    pub wind_direction: [f32; 2],
    pub wind_speed_m_s: f32,
    /// Mass of one flake (kg) and its linear drag coefficient k (kg/s): terminal velocity m·g/k.
    pub flake_mass_kg: f32,
    pub drag_kg_s: f32,
    /// Below this height flakes slow down linearly to `ground_speed_factor` of their speed at y = 0.
    pub ground_slowdown_m: f32,
    pub ground_speed_factor: f32,
    /// Flakes reaching y ≤ 0 or leaving their field respawn at the top, at a new random x, z inside
    /// their field (relative to the camera's current position).
    pub respawn: Respawn,
    /// Sprite spin, radians per second, uniform in ±this.
    pub max_spin_rad_s: f32,
    pub seed: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Respawn {
    /// At y = fall_height_m, new random x, z in the field.
    Top,
    /// At y = fall_height_m, same x, z relative to the camera (cheaper; the pattern repeats).
    WrapVertical,
}

impl Default for Emitter {
    fn default() -> Self {
        Emitter {
            near_radius_m: 15.0,
            near_count: 4000,
            far: Some(FarField { outer_radius_m: 60.0, count: 6000, view_angle_deg: 90.0 }),
            fall_height_m: 20.0,
            wind_direction: [1.0, 0.0],
            wind_speed_m_s: 1.5,
            // a 3 mg flake with k = 3·10⁻⁵ kg/s falls at about 1 m/s, typical of dendrites
            flake_mass_kg: 3.0e-6,
            drag_kg_s: 3.0e-5,
            ground_slowdown_m: 0.5,
            ground_speed_factor: 0.3,
            respawn: Respawn::Top,
            max_spin_rad_s: 1.0,
            seed: 0,
        }
    }
}

impl Emitter {
    /// Parses emitter JSON; errors give `source_name`, line and column.
    pub fn from_json(text: &str, source_name: &str) -> Result<Emitter, SnowError> {
        let e: Emitter = serde_json::from_str(text).map_err(|err| SnowError::Json {
            source_name: source_name.into(),
            line: err.line(),
            column: err.column(),
            message: err.to_string(),
        })?;
        e.check()?;
        Ok(e)
    }

    pub fn check(&self) -> Result<(), SnowError> {
        if !within(self.near_radius_m, 0.1, 10_000.0) {
            return bad("near_radius_m", format!("is {} m", self.near_radius_m), "use 0.1 to 10000 m");
        }
        if self.near_count > MAX_FLAKES {
            return bad("near_count", format!("is {}", self.near_count), "use at most 1000000 flakes");
        }
        if let Some(far) = &self.far {
            if !(far.outer_radius_m.is_finite()
                && far.outer_radius_m > self.near_radius_m
                && far.outer_radius_m <= 100_000.0)
            {
                return bad(
                    "far.outer_radius_m",
                    format!("is {} m with near_radius_m {} m", far.outer_radius_m, self.near_radius_m),
                    "make it larger than near_radius_m (and at most 100000 m), or remove `far`",
                );
            }
            if far.count > MAX_FLAKES {
                return bad("far.count", format!("is {}", far.count), "use at most 1000000 flakes");
            }
            if !within(far.view_angle_deg, 1.0, 360.0) {
                return bad("far.view_angle_deg", format!("is {}°", far.view_angle_deg), "use 1 to 360 degrees");
            }
        }
        if !within(self.fall_height_m, 0.1, 10_000.0) {
            return bad("fall_height_m", format!("is {} m", self.fall_height_m), "use 0.1 to 10000 m");
        }
        let [wx, wz] = self.wind_direction;
        if !(wx.is_finite() && wz.is_finite() && wx * wx + wz * wz > 1e-12) {
            return bad("wind_direction", format!("is {:?}", self.wind_direction), "give a non-zero [x, z] direction");
        }
        if !within(self.wind_speed_m_s, 0.0, 100.0) {
            return bad("wind_speed_m_s", format!("is {} m/s", self.wind_speed_m_s), "use 0 to 100 m/s");
        }
        if !(self.flake_mass_kg.is_finite() && self.flake_mass_kg > 0.0 && self.flake_mass_kg <= 1e-3) {
            return bad(
                "flake_mass_kg",
                format!("is {} kg", self.flake_mass_kg),
                "use a positive mass up to 0.001 kg (flakes weigh ~1e-6 kg)",
            );
        }
        if !(self.drag_kg_s.is_finite() && self.drag_kg_s > 0.0 && self.drag_kg_s <= 1.0) {
            return bad(
                "drag_kg_s",
                format!("is {} kg/s", self.drag_kg_s),
                "use a positive drag coefficient up to 1 kg/s",
            );
        }
        if !within(self.ground_slowdown_m, 0.0, self.fall_height_m) {
            return bad("ground_slowdown_m", format!("is {} m", self.ground_slowdown_m), "use 0 up to fall_height_m");
        }
        if !within(self.ground_speed_factor, 0.0, 1.0) {
            return bad("ground_speed_factor", format!("is {}", self.ground_speed_factor), "use 0 to 1");
        }
        if !within(self.max_spin_rad_s, 0.0, 100.0) {
            return bad("max_spin_rad_s", format!("is {} rad/s", self.max_spin_rad_s), "use 0 to 100 rad/s");
        }
        Ok(())
    }

    /// Terminal fall speed v = m·g/k (m/s), where gravity and linear drag balance.
    pub fn terminal_velocity_m_s(&self) -> f32 {
        self.flake_mass_kg * GRAVITY_M_S2 / self.drag_kg_s
    }

    /// Time constant m/k (s): the fall speed reaches 1 − 1/e of terminal after this long from rest.
    pub fn time_constant_s(&self) -> f32 {
        self.flake_mass_kg / self.drag_kg_s
    }

    /// One explicit step of the fall speed (downwards positive): dv/dt = g − (k/m)·v. Stable for
    /// dt < 2·m/k; the engine does the same per frame.
    pub fn step_fall_speed(&self, v: f32, dt: f32) -> f32 {
        v + dt * (GRAVITY_M_S2 - self.drag_kg_s / self.flake_mass_kg * v)
    }

    /// Factor on the fall speed at height `y` above the ground: 1 above `ground_slowdown_m`, then
    /// linear down to `ground_speed_factor` at y = 0 (flakes settle rather than hit the ground).
    pub fn ground_factor(&self, y: f32) -> f32 {
        if self.ground_slowdown_m <= 0.0 || y >= self.ground_slowdown_m {
            return 1.0;
        }
        let t = (y / self.ground_slowdown_m).clamp(0.0, 1.0);
        self.ground_speed_factor + (1.0 - self.ground_speed_factor) * t
    }

    /// Unit wind direction (x, z).
    pub fn wind_unit(&self) -> [f32; 2] {
        let [x, z] = self.wind_direction;
        let l = (x * x + z * z).sqrt();
        if l > 0.0 {
            [x / l, z / l]
        } else {
            [1.0, 0.0]
        }
    }
}

/// `emitter.json` as written: the emitter, the derived figures an engine would otherwise have to
/// recompute, and the atlas the sprites come from (cell k at column k % columns, row k / columns).
#[derive(Debug, Clone, Serialize)]
pub struct EmitterFile<'a> {
    #[serde(flatten)]
    pub emitter: &'a Emitter,
    pub terminal_velocity_m_s: f32,
    pub time_constant_s: f32,
    pub wind_unit: [f32; 2],
    pub atlas: AtlasInfo<'a>,
}

#[derive(Debug, Clone, Serialize)]
pub struct AtlasInfo<'a> {
    pub image: &'a str,
    pub columns: u32,
    pub rows: u32,
    pub cell_px: u32,
    pub cells: &'a [crate::snow::flakes::FlakeCell],
}

/// The text of `emitter.json` (pretty, stable field order) for `emitter` and `atlas`, whose PNG is
/// written next to it as `atlas_file`.
pub fn emitter_json(emitter: &Emitter, atlas: &FlakeAtlas, atlas_file: &str) -> Result<String, SnowError> {
    emitter.check()?;
    let file = EmitterFile {
        emitter,
        terminal_velocity_m_s: emitter.terminal_velocity_m_s(),
        time_constant_s: emitter.time_constant_s(),
        wind_unit: emitter.wind_unit(),
        atlas: AtlasInfo {
            image: atlas_file,
            columns: atlas.columns,
            rows: atlas.rows,
            cell_px: atlas.cell_px,
            cells: &atlas.cells,
        },
    };
    serde_json::to_string_pretty(&file).map_err(|e| SnowError::Bake(e.to_string()))
}
