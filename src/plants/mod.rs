//! Plants: the meshes instanced species show — grass clumps with their levels of detail and baked
//! atlases, flowers as crossed billboards, L-system trees, OBJ models, and the species palette the
//! preview draws them with.

pub mod flower;
pub mod grass;
pub mod grass_asset;
pub mod hausdorff;
pub mod mesh_asset;
pub mod palette;
pub mod texture;
pub mod tree;
pub mod tree_lod;
pub mod wind;

use serde::{Deserialize, Serialize};

/// What a species' instances are: the generator its meshes come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SpeciesKind {
    Grass,
    Flower,
    Tree,
    Mesh,
}
