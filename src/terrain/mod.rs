//! Terrain: heightfield → triangulation of its samples (grid or greedy TIN) → measured error →
//! engine-ready meshes (normals, UVs, chunks, skirts, base), coloured by material layers and lit
//! through a normal map baked against each mesh.

pub mod bands;
pub mod budget;
pub mod build;
pub mod chunks;
pub mod error;
pub mod grid;
pub mod job;
pub mod layers;
pub mod normal_map;
pub mod plane;
pub mod regions;
pub mod sample_mesh;
pub mod solid;
pub mod stored;
pub mod tin;
pub mod vegetation;

pub use error::TerrainError;
pub use sample_mesh::SampleMesh;
