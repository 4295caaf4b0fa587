//! Scenes: a preset (plain data, parsed from TOML by `preset`) is built stage by stage into an
//! engine-ready folder `out/<scene>/` with a manifest, a report and a preview.
//!
//! The types here are the resolved settings every stage reads; they are written into the manifest
//! as they are, so a build can be reproduced from its manifest alone.

pub mod preview;
pub mod build;
pub mod cache;
pub mod manifest;
pub mod stages;

use std::path::PathBuf;

use serde::Serialize;

use crate::heightfield::DecodeOptions;
use crate::synth::NoiseKind;
use crate::terrain::job::MeshMode;

pub mod preset;

/// Output formats of a scene's meshes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    Glb,
    Gltf,
    Obj,
}

impl Format {
    pub fn extension(self) -> &'static str {
        match self {
            Format::Glb => "glb",
            Format::Gltf => "gltf",
            Format::Obj => "obj",
        }
    }
}

/// `[scene]`
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneSettings {
    /// Folder name under the output directory; letters, digits, `-` and `_` only.
    pub name: String,
    /// Global seed every random choice is derived from.
    pub seed: u64,
    /// At least one; the first is the primary format.
    pub formats: Vec<Format>,
}

/// Where the terrain's heights come from.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum TerrainSource {
    /// A heightmap file (path resolved relative to the preset file) and how to decode it.
    Heightmap { path: PathBuf, decode: DecodeOptions },
    /// `procedural = { kind = "fbm", size, seed, relief }`: a generated square map. `noise` is
    /// the TOML `kind` (`fbm` or `ridged`); generate it with [`preset::procedural_heightfield`].
    Fbm { size: usize, seed: u64, relief_m: f64, cell_size_m: f64, noise: NoiseKind },
}

/// `[terrain]`
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TerrainSettings {
    pub source: TerrainSource,
    pub mode: MeshMode,
    pub max_error_m: f64,
    pub max_triangles: Option<usize>,
    pub grid_step: usize,
    pub chunk: Option<usize>,
    pub skirt_m: Option<f64>,
    pub base_m: Option<f64>,
    /// Max errors (metres) of a LoD chain, finest first; empty for none.
    pub lods: Vec<f64>,
}

/// A whole preset, resolved: every path absolute or relative to the working directory, every
/// default filled in.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Preset {
    /// The file it came from; `None` for the embedded demo.
    pub path: Option<PathBuf>,
    pub scene: SceneSettings,
    pub terrain: Option<TerrainSettings>,
}
