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
pub mod error;
pub mod flakes;
pub mod particles;
pub mod settings;
pub mod write;

pub use analyze::{analyze, Band, SnowReport};
pub use cover::{apply_cover, cover_mask, snow_layer, snow_weight, CoverMask, CoverSettings, SNOW_ATTRIBUTE};
pub use emitter::{emitter_json, Emitter, FarField};
pub use error::SnowError;
pub use flakes::{build_atlas, flake_kind, flake_model, FlakeAtlas, FlakeCell, FlakeKind, FlakeSettings};
pub use particles::{particles, particles_csv, snowfall_scene, Field, Particle};
pub use settings::SnowSettings;
pub use write::{write_cover, write_snowfall, ATLAS_FILE};
