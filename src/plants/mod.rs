//! Plants: the meshes instanced species show — grass clumps with their levels of detail and baked
//! atlases, flowers as crossed billboards, and small marker meshes for kinds without a generator.

pub mod flower;
pub mod grass;
pub mod grass_asset;
pub mod marker;
pub mod random;
pub mod texture;
