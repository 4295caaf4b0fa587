//! Plants: the meshes instanced species show — grass clumps with their levels of detail, and small
//! marker meshes for kinds that have no generator yet.

pub mod grass;
pub mod marker;
pub mod random;
