//! Snow: a crystal sprite atlas, an emitter description and a frozen particle frame for engine
//! particle systems, and snow cover on the terrain. Crystal habits by temperature follow Nakaya's
//! diagram as the snowfall thesis summarises it; the fall is gravity with linear drag (v = m·g/k).
//!
//! `flakes` draws six-fold crystals as geometry and bakes them into an atlas; `emitter` is the
//! `emitter.json` data; `particles` places the initial flakes (CSV and an instanced glb); `cover`
//! weights terrain vertices by slope, altitude and exposure; `analyze` measures all of it; `write`
//! writes the `snow/` folder.

pub mod analyze;
pub mod cover;
pub mod emitter;
pub mod flakes;
pub mod particles;
pub mod write;

pub use analyze::{analyze, Band, SnowReport};
pub use cover::{apply_cover, cover_mask, snow_layer, snow_weight, CoverMask, CoverSettings, SNOW_ATTRIBUTE};
pub use emitter::{emitter_json, Emitter, FarField};
pub use flakes::{build_atlas, flake_kind, flake_model, FlakeAtlas, FlakeCell, FlakeKind, FlakeSettings};
pub use particles::{particles, particles_csv, snowfall_scene, Field, Particle};
pub use write::{write_cover, write_snowfall, ATLAS_FILE};

/// The one error type of the snow module: a setting out of range (named, with its remedy), a JSON
/// document that does not parse (with line and column), or a bake / input-scene failure.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SnowError {
    #[error("snow setting `{key}` {problem}; {remedy}")]
    Setting { key: &'static str, problem: String, remedy: String },
    #[error("{source_name}: line {line}, column {column}: {message}; fix the emitter JSON (see docs/snow.md)")]
    Json { source_name: String, line: usize, column: usize, message: String },
    #[error("baking the snow flake atlas failed: {0}")]
    Bake(String),
    #[error("terrain scene for snow cover: {0}")]
    Terrain(String),
    /// A file could not be written (the export error's message names the file and the remedy).
    #[error("{0}")]
    Write(String),
}

/// The input's for settings and JSON; the build's for a bake, the terrain it was given or a write.
impl crate::failure::Failure for SnowError {
    fn blame(&self) -> crate::failure::Blame {
        match self {
            SnowError::Setting { .. } | SnowError::Json { .. } => crate::failure::Blame::Input,
            SnowError::Bake(_) | SnowError::Terrain(_) | SnowError::Write(_) => crate::failure::Blame::Build,
        }
    }
}

pub(crate) fn bad<T>(key: &'static str, problem: String, remedy: &str) -> Result<T, SnowError> {
    Err(SnowError::Setting { key, problem, remedy: remedy.into() })
}

/// `v` is finite and inside `[lo, hi]`.
pub(crate) fn within(v: f32, lo: f32, hi: f32) -> bool {
    v.is_finite() && lo <= v && v <= hi
}

/// The resolved `[snow]` section of a preset: everything the scene's snow stage needs (written
/// into the manifest as it is). See docs/presets.md, section `[snow]`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SnowSettings {
    pub flakes: FlakeSettings,
    pub emitter: Emitter,
    pub cover: CoverSettings,
    /// Pixels along the longer side of the cover mask (`cover_mask.png`).
    pub mask_px: u32,
    /// Write `snow_layer.glb` (the snow surface lifted by its depth).
    pub layer: bool,
    /// Triangles of the layer have all three vertices at this weight or more.
    pub layer_min_weight: f32,
    /// 0..1: a grass or flower instance is dropped with probability `thin_plants × weight`.
    pub thin_plants: f64,
}

impl Default for SnowSettings {
    fn default() -> Self {
        SnowSettings {
            flakes: FlakeSettings::default(),
            emitter: Emitter::default(),
            cover: CoverSettings::default(),
            mask_px: 512,
            layer: true,
            layer_min_weight: 0.5,
            thin_plants: 0.8,
        }
    }
}

impl SnowSettings {
    /// Every part checked as a whole (the preset parser checks single keys first).
    pub fn check(&self) -> Result<(), SnowError> {
        self.flakes.check()?;
        self.emitter.check()?;
        self.cover.check()?;
        if !(16..=8192).contains(&self.mask_px) {
            return bad("mask_px", format!("is {}", self.mask_px), "use 16 to 8192 pixels");
        }
        if !within(self.layer_min_weight, 0.0, 1.0) {
            return bad("layer_min_weight", format!("is {}", self.layer_min_weight), "use 0 to 1");
        }
        if !(self.thin_plants.is_finite() && (0.0..=1.0).contains(&self.thin_plants)) {
            return bad(
                "thin_plants",
                format!("is {}", self.thin_plants),
                "use 0 (no thinning) to 1 (no plant where the cover is full)",
            );
        }
        Ok(())
    }
}
