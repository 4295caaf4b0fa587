//! Plants: the meshes instanced species show. Until the grass and tree stages land, markers.

pub mod marker;
pub mod tree;
