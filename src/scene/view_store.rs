//! How scene.glb and scene_lod.glb store vertex data (`[scene] compact`): every species mesh on a
//! 16-bit grid of its own family (as in its species file), and every terrain mesh — the main
//! mesh's chunks and every level's — on one uniform grid over the whole terrain, so the chunks'
//! seams stay closed (a seam vertex is the same integers in both chunks) and normals need no
//! correction for the grid's scale (Babylon.js lights a non-uniformly scaled quantized terrain
//! darker than three.js: it does not apply the scale's inverse transpose to pre-scaled normals).

use crate::export::gltf::WriteOptions;
use crate::export::quantize::{position_error_with, uniform_grid, Compact, MeshGrid, Quantization};
use crate::mesh::{Mesh, Node, Scene};
use crate::scene::Preset;

/// The writer's options for the scene files, and the farthest a terrain vertex moves on the
/// terrain's grid (0 for f32 files).
pub(super) fn scene_store(preset: &Preset, terrain: &[&Mesh]) -> (WriteOptions, f64) {
    let mut options = preset.scene.compact.write_options();
    if preset.scene.compact == Compact::None {
        return (options, 0.0);
    }
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for p in terrain.iter().flat_map(|m| &m.primitives).flat_map(|p| &p.positions) {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    if !lo[0].is_finite() {
        return (options, 0.0);
    }
    let grid = MeshGrid { grid: uniform_grid(lo, hi), uniform: true };
    let mut names: Vec<String> = terrain.iter().map(|m| m.name.clone()).filter(|n| !n.is_empty()).collect();
    names.sort();
    names.dedup();
    options.mesh_grids = names.into_iter().map(|n| (n, grid)).collect();
    // the terrain meshes alone, on that grid
    let mut alone = Scene::default();
    for m in terrain {
        let mut m = (*m).clone();
        m.primitives.iter_mut().for_each(|p| p.material = None); // (their materials are not here)
        alone.meshes.push(m);
        alone.nodes.push(Node { mesh: Some(alone.meshes.len() - 1), ..Node::default() });
        alone.roots.push(alone.nodes.len() - 1);
    }
    let moved = position_error_with(&alone, &Quantization::PerMesh, &options.mesh_grids);
    (options, moved)
}
