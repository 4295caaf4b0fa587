//! Scenes: a preset (plain data, parsed from TOML by `preset`) is built stage by stage into an
//! engine-ready folder `out/<scene>/` with a manifest, a report and a preview.
//!
//! The types here are the resolved settings every stage reads; they are written into the manifest
//! as they are, so a build can be reproduced from its manifest alone.

pub mod band_chunks;
pub mod band_layers;
pub mod build;
pub mod cache;
pub mod error;
pub mod ground_cover;
pub mod impostor;
pub mod manifest;
pub mod pipeline;
pub mod placement_rows;
pub mod plants_stage;
pub mod preview;
pub mod preview_stage;
pub mod scatter_stage;
pub mod shard;
pub mod snow_stage;
pub mod terrain_stage;
pub mod tile_units;
mod view_lod;
pub mod view_render;
pub mod view_stage;
mod view_store;
pub mod view_tiles;

use std::path::PathBuf;

use serde::Serialize;

use crate::heightfield::DecodeOptions;
use crate::plants::SpeciesKind;
use crate::scatter::SpeciesRules;
use crate::synth::NoiseKind;
use crate::terrain::job::MeshMode;

pub mod preset;
pub mod view;

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
    /// How the species files, scene.glb and scene_lod.glb store vertex data (`compact`).
    pub compact: crate::export::quantize::Compact,
    /// `tile`: the side (m) of the square scene tiles the view stage also writes the scene as
    /// (`tiles/`, indexed by `scene_tiles.json`; [`view_tiles`]); `None`: no tiles.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tile_m: Option<f64>,
    /// `lod_scene`: write scene_lod.glb (every chunk and instance in one file); `false` leaves it
    /// out (a scene over the GLB's 4 GiB, written as tiles).
    #[serde(skip_serializing_if = "is_true")]
    pub lod_scene: bool,
}

fn is_true(b: &bool) -> bool {
    *b
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
    /// The meshing work budget in vertices (`max_vertices`; [`crate::terrain::budget`]).
    pub max_vertices: usize,
    pub grid_step: usize,
    pub chunk: Option<usize>,
    pub skirt_m: Option<f64>,
    pub base_m: Option<f64>,
    /// Max errors (metres) of a LoD chain, finest first; empty for none.
    pub lods: Vec<f64>,
}

impl TerrainSettings {
    /// The distance between the map's samples in metres (the heightmap's `cell_size`, or the
    /// procedural terrain's).
    pub fn cell_size_m(&self) -> f64 {
        match &self.source {
            TerrainSource::Heightmap { decode, .. } => decode.cell_size_m,
            TerrainSource::Fbm { cell_size_m, .. } => *cell_size_m,
        }
    }

    /// How deep the skirts hang on the chunks of a mesh of bound `max_error_m`: the preset's
    /// `skirt`, or deeper when a neighbouring chunk may be shown at another level of the chain
    /// and lie further below. Both chunks' edges along their shared line are within their bounds
    /// of the samples on it (the line is a seam of every level, its vertices samples), and two
    /// polylines through the same sample positions differ most at a vertex of one of them, so the
    /// step is at most the sum of the two bounds: each skirt reaches its own bound plus the
    /// chain's coarsest. Unchanged without a chain or chunks (no neighbour at another level);
    /// `None` without `skirt`.
    pub fn skirt_at(&self, max_error_m: f64) -> Option<f64> {
        if self.lods.is_empty() || self.chunk.is_none() {
            return self.skirt_m;
        }
        let coarsest = self.lods.iter().copied().fold(self.max_error_m, f64::max);
        self.skirt_m.map(|depth| depth.max(max_error_m + coarsest))
    }
}

/// A whole preset, resolved: every path absolute or relative to the working directory, every
/// default filled in.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Preset {
    /// The file it came from; `None` for the embedded demo.
    pub path: Option<PathBuf>,
    pub scene: SceneSettings,
    pub terrain: Option<TerrainSettings>,
    /// `[[species]]`, in file order (exclusions refer to species placed earlier).
    pub species: Vec<SpeciesSettings>,
    /// `[scatter]`
    pub scatter: ScatterSettings,
    /// `[snow]`: flakes, emitter, cover and plant thinning; `None` without the section.
    pub snow: Option<crate::snow::SnowSettings>,
    /// `[lod]`: the pixel budget and reference screen every switch and cull distance is chosen for.
    pub lod: crate::lod::LodView,
    /// `[[view]]`, in file order (at least one: the default view when the preset has none);
    /// `scene.glb` is the scene as drawn from the first.
    pub views: Vec<view::ViewSettings>,
}

/// `[scatter]`: how placement is split into tiles.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScatterSettings {
    /// Side of a placement tile in metres (instances are grouped per tile in tables and scene.glb).
    pub tile_m: f64,
    /// `table`: how the placement tables are written (CSV, or little-endian binary arrays).
    pub table: crate::export::table::TableFormat,
    /// `vegetation_map`: one grey image over the terrain whose 8-bit shades name vegetation types;
    /// a species with `vegetation_type = N` is placed only where the shade is N.
    pub vegetation_map: Option<PathBuf>,
}

impl Default for ScatterSettings {
    fn default() -> Self {
        ScatterSettings { tile_m: 256.0, table: crate::export::table::TableFormat::Csv, vegetation_map: None }
    }
}

/// `[[species]]`, resolved: how its instances are placed (the scatter stage's half, flattened
/// into the manifest as one object) and what they show (the plants stage's half).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpeciesSettings {
    #[serde(flatten)]
    pub rules: SpeciesRules,
    pub kind: SpeciesKind,
    /// `cull_distance` (m): instances farther from the eye are not drawn; `None`: from the LoD
    /// budget (where the coarsest level spans the pixel budget, [`view::cull_distance`]).
    pub cull_distance_m: Option<f64>,
    /// `vegetation_type`: the shade (0–255) of `[scatter] vegetation_map` where it grows.
    pub vegetation_type: Option<u8>,
    /// What its instances show: a generated grass clump or flower, or a marker mesh.
    pub look: PlantLook,
}

/// The mesh a species' instances reference.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "generator", rename_all = "lowercase")]
pub enum PlantLook {
    /// A small stand-in (trees and meshes until their generators land).
    Marker,
    /// `grass = { … }` / `[grass]`: generated clumps with LoDs and a baked atlas.
    Grass(crate::plants::grass::GrassSettings),
    /// `flower = { … }` / `[flower]`: crossed billboards of a baked procedural flower.
    Flower(crate::plants::flower::FlowerSettings),
    /// `lsystem = "…"` (+ `tree = { … }` / `[tree]`): L-system trees with their LoD chains.
    Tree(TreeLook),
    /// `obj = "…"` (+ `mesh = { … }` / `[mesh]`): your own OBJ model with the same LoD chain.
    Mesh(MeshLook),
}

impl PlantLook {
    /// How many variants the placement table's `variant` column picks from (the preset's
    /// `variants`; one for a mesh or a marker). A tree whose L-system ignores the seed builds fewer
    /// distinct meshes; the chain's `pick` then maps several variants to one.
    pub fn table_variants(&self) -> usize {
        match self {
            PlantLook::Marker | PlantLook::Mesh(_) => 1,
            PlantLook::Grass(g) => g.variants,
            PlantLook::Flower(f) => f.variants,
            PlantLook::Tree(t) => t.variants,
        }
        .max(1)
    }
}

/// A mesh species' look: the OBJ file, how it is read and how its chain is built.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshLook {
    /// The `.obj` file (resolved against the preset's folder); its MTL and textures beside it.
    pub obj: PathBuf,
    /// Metres per file unit.
    pub scale: f64,
    pub up_axis: crate::plants::mesh_asset::UpAxis,
    pub lods: usize,
    pub atlas_px: u32,
    pub analyze: bool,
    /// Budgets of the model as read (`max_vertices`, `max_triangles`).
    pub max_vertices: usize,
    pub max_triangles: usize,
}

impl MeshLook {
    /// How the plants stage (and `preset check`) reads the model: scale, up axis, budgets.
    pub fn obj_options(&self) -> crate::plants::mesh_asset::ObjOptions {
        crate::plants::mesh_asset::ObjOptions {
            scale: self.scale,
            up_axis: self.up_axis,
            max_vertices: self.max_vertices,
            max_triangles: self.max_triangles,
            ..Default::default()
        }
    }
}

impl Default for MeshLook {
    fn default() -> Self {
        MeshLook {
            obj: PathBuf::new(),
            scale: 1.0,
            up_axis: crate::plants::mesh_asset::UpAxis::Y,
            lods: crate::plants::tree_lod::TREE_LODS,
            atlas_px: 1024,
            analyze: true,
            max_vertices: crate::plants::mesh_asset::DEFAULT_MAX_VERTICES,
            max_triangles: crate::plants::mesh_asset::DEFAULT_MAX_TRIANGLES,
        }
    }
}

/// A tree species' look: which L-system, how many variants and how their chains are built.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TreeLook {
    /// The `.ls` file (resolved against the preset's folder).
    pub lsystem: PathBuf,
    /// `None`: detected from the file.
    pub dialect: Option<crate::lsystem::Dialect>,
    /// Trees grown from different seeds; instances pick one by a hash of their position.
    pub variants: usize,
    /// Every variant scaled to this height (m) before the instance's `scale`; `None`: the file's
    /// own step length (1 m per `F` in lparser 5 and the thesis, 1 cm in lparser 4).
    pub height_m: Option<f64>,
    pub radial_segments: u32,
    /// Levels of the chain written (1..=5).
    pub lods: usize,
    pub atlas_px: u32,
    pub max_segments: u64,
    /// Refuse a variant needing more triangles than this (`max_triangles`).
    pub max_triangles: u64,
    /// Budget of expanded L-system symbols (see [`crate::lsystem::expand::DEFAULT_MAX_SYMBOLS`]).
    pub max_symbols: u64,
    /// Measure image errors and switch distances (the MSFT_lod coverages need them).
    pub analyze: bool,
    /// Seed of variant 0 (see [`preset::species_look_seed`]).
    pub seed: u64,
}

impl Default for TreeLook {
    fn default() -> Self {
        TreeLook {
            lsystem: PathBuf::new(),
            dialect: None,
            variants: 3,
            height_m: Some(10.0),
            radial_segments: crate::plants::tree::DEFAULT_RADIAL_SEGMENTS,
            lods: crate::plants::tree_lod::TREE_LODS,
            atlas_px: 1024,
            max_segments: 200_000,
            max_triangles: crate::plants::tree::DEFAULT_MAX_TRIANGLES,
            max_symbols: crate::lsystem::expand::DEFAULT_MAX_SYMBOLS,
            analyze: true,
            seed: 0,
        }
    }
}
