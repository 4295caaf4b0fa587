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

pub(crate) fn bad<T>(key: &'static str, problem: String, remedy: &str) -> Result<T, SnowError> {
    Err(SnowError::Setting { key, problem, remedy: remedy.into() })
}

/// `v` is finite and inside `[lo, hi]`.
pub(crate) fn within(v: f32, lo: f32, hi: f32) -> bool {
    v.is_finite() && lo <= v && v <= hi
}
