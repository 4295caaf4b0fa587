//! Engine-ready terrain from a sample triangulation: vertices exactly at their samples, normals from
//! the heightfield (central differences, so shading does not show the triangulation), planar UVs,
//! optional chunks (`chunks`), skirts and a watertight base (`solid`), then meshoptimizer's vertex
//! cache and fetch ordering (Forsyth-style cache optimisation, as in meshoptimizer's vcacheoptimizer).
//!
//! Scene layout:
//! - no chunks: one root node and one mesh named `name`; primitive 0 is the surface (with its skirt),
//!   primitive 1 the base's walls and bottom when a base is asked for.
//! - chunks: a root node `name` (no mesh) whose children are `name_chunk_<ci>_<cj>` (row-major, empty
//!   chunks skipped), each with a mesh of the same name holding only the vertices its triangles use,
//!   in world space (translation zero, so each mesh's bounds are its exact extent), plus a child
//!   `name_base` holding the walls and bottom when a base is asked for. Each chunk node's extras hold
//!   `{"chunk": [ci, cj], "sample_min": [i, j], "sample_max": [i, j]}` (its inclusive sample
//!   rectangle; neighbouring chunks share their border samples).
//!
//! The base closes the whole terrain, not each chunk: walls along the map's rectangle border and one
//! flat bottom, so the union of all primitives is one solid, watertight by vertex position.

use std::collections::{HashMap, HashSet};

use serde_json::json;

use crate::heightfield::Heightfield;
use crate::mesh::{AlphaMode, Material, Mesh, Node, Primitive, Scene};

use super::chunks::{boundary_edges, ChunkGrid};
use super::solid::{add_skirt, base_primitive, lowered};
use super::SampleMesh;

/// How to turn a triangulation into meshes.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildOptions {
    /// Split into square chunks this many samples apart (≥ 2; see [`ChunkGrid`]); `None`: one mesh.
    pub chunk_samples: Option<usize>,
    /// Hang a skirt this many metres deep from every chunk's boundary (hides LoD cracks in engines).
    pub skirt_depth_m: Option<f64>,
    /// Close the terrain into a solid whose flat bottom lies this many metres below the lowest sample.
    pub base_depth_m: Option<f64>,
    /// Name of the scene, its root node and (without chunks) its mesh.
    pub name: String,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions { chunk_samples: None, skirt_depth_m: None, base_depth_m: None, name: "terrain".to_string() }
    }
}

/// Why a scene could not be built: bad options, or a heightfield/triangulation that breaks the
/// contract of [`SampleMesh`] (the latter points at a mesher bug rather than a user mistake).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BuildError {
    #[error("the terrain name is empty: give the output a name (it names the scene, nodes and meshes)")]
    EmptyName,
    #[error("chunk size {0} is too small: a chunk must span at least 2 samples; pass --chunk 2 or more (64–256 is typical), or leave it out for one mesh")]
    ChunkTooSmall(usize),
    #[error("{option} is {depth_m} m: it must be a positive, finite number of metres (e.g. 10); leave the option out to disable it")]
    InvalidDepth { option: &'static str, depth_m: f64 },
    #[error("{option} of {depth_m} m cannot be represented below a height of {height_m} m in 32-bit floats; use a depth of at least a few centimetres and below 1e6 m")]
    DepthNotRepresentable { option: &'static str, depth_m: f64, height_m: f32 },
    #[error("a skirt and a base were both asked for: the base already closes the sides, and skirts would add open flaps inside the solid; use --base for a solid or --skirt for engine chunks, not both")]
    SkirtWithBase,
    #[error("the heightfield is {width}×{height} samples: a terrain needs at least 2×2 samples; use a larger heightmap")]
    HeightfieldTooSmall { width: usize, height: usize },
    #[error("the heightfield holds {len} heights but is {width}×{height} samples; this is a decoder bug, please report it")]
    HeightfieldShape { width: usize, height: usize, len: usize },
    #[error("the cell size is {0} m: it must be a positive, finite number of metres; pass a cell size like 1.0")]
    InvalidCellSize(f64),
    #[error("the height at sample ({i}, {j}) is {value}: every height must be finite; fix or fill that pixel (no-data values must be replaced before meshing)")]
    NonFiniteHeight { i: usize, j: usize, value: f32 },
    #[error("the triangulation has no triangles; mesh the heightfield first (the grid mesher always gives some for a 2×2 or larger map)")]
    EmptyMesh,
    #[error("triangulation vertex {vertex} is at sample {sample:?}, outside the {width}×{height} heightfield; the mesher and the heightfield do not match")]
    VertexOutOfRange { vertex: usize, sample: [u32; 2], width: usize, height: usize },
    #[error("triangle {triangle} refers to vertex {index}, but there are only {vertex_count}; the triangulation is corrupt (mesher bug)")]
    IndexOutOfRange { triangle: usize, index: u32, vertex_count: usize },
    #[error("triangle {triangle} with samples {samples:?} is clockwise or degenerate seen from +Y; triangles must be counter-clockwise with positive area (mesher bug)")]
    NotCounterClockwise { triangle: usize, samples: [[u32; 2]; 3] },
    #[error("the edge from sample {from:?} to {to:?} runs the same way in two triangles: they overlap or fold over (mesher bug)")]
    NonManifoldEdge { from: [u32; 2], to: [u32; 2] },
    #[error("the triangles cover {covered_cells2}/2 cells but the map has {expected_cells2}/2: the triangulation must cover the map's rectangle exactly, without holes or overlaps (mesher bug)")]
    DoesNotCover { covered_cells2: u128, expected_cells2: u128 },
    #[error("the edge from sample {from:?} to {to:?} is on the outside of the triangulation but not on the map's border: a base needs the mesh to cover the whole rectangle (mesher bug)")]
    BorderNotOnRectangle { from: [u32; 2], to: [u32; 2] },
    #[error("a mesh would need {0} vertices, more than 32-bit indices hold; pass --chunk to split the terrain")]
    TooManyVertices(usize),
}

/// Builds the scene for `mesh`, a triangulation of `hf`'s samples (see the module docs for layout).
/// Deterministic: the same inputs give the same scene. Errors on invalid options or a triangulation
/// that breaks the [`SampleMesh`] contract; never panics on them.
pub fn build_scene(hf: &Heightfield, mesh: &SampleMesh, opts: &BuildOptions) -> Result<Scene, BuildError> {
    check_options(opts)?;
    check_heightfield(hf)?;
    let triangles = check_mesh(hf, mesh)?;

    let mut scene = Scene { name: opts.name.clone(), materials: vec![terrain_material()], ..Scene::default() };
    // reusable map from vertex id to index in the primitive being built (u32::MAX: not yet in it)
    let mut slots = vec![u32::MAX; mesh.vertices.len()];
    let all: Vec<usize> = (0..triangles.len()).collect();
    let base = match opts.base_depth_m {
        Some(depth) => Some(base(hf, mesh, &triangles, &all, depth)?),
        None => None,
    };

    match opts.chunk_samples {
        None => {
            let mut primitives = vec![surface(hf, mesh, &triangles, &all, opts.skirt_depth_m, &mut slots)?];
            primitives.extend(base);
            scene.add_mesh_node(finish(opts.name.clone(), primitives)?);
        }
        Some(pitch) => {
            let grid = ChunkGrid::new(hf.width, hf.height, pitch);
            let parts = grid.partition(&mesh.vertices, &triangles);
            scene.nodes.push(Node { name: opts.name.clone(), ..Node::default() });
            let parent = scene.nodes.len() - 1;
            scene.roots.push(parent);
            let child = |scene: &mut Scene, mesh: Mesh, extras| {
                let name = mesh.name.clone();
                scene.meshes.push(mesh);
                scene.nodes.push(Node { name, mesh: Some(scene.meshes.len() - 1), extras, ..Node::default() });
                let node = scene.nodes.len() - 1;
                scene.nodes[parent].children.push(node);
            };
            for cj in 0..grid.ny {
                for ci in 0..grid.nx {
                    let part = &parts[cj * grid.nx + ci];
                    if part.is_empty() {
                        continue;
                    }
                    let prim = surface(hf, mesh, &triangles, part, opts.skirt_depth_m, &mut slots)?;
                    let (lo, hi) = grid.sample_rect(ci, cj);
                    let extras = json!({ "chunk": [ci, cj], "sample_min": lo, "sample_max": hi });
                    child(&mut scene, finish(format!("{}_chunk_{ci}_{cj}", opts.name), vec![prim])?, Some(extras));
                }
            }
            if let Some(base) = base {
                child(&mut scene, finish(format!("{}_base", opts.name), vec![base])?, None);
            }
        }
    }
    Ok(scene)
}

/// UV0 of sample (i, j): planar over the map, u = i/(w−1), v = j/(h−1). Row 0 is the heightmap
/// image's top row and glTF's v runs down from the image top, so a texture made from the heightmap's
/// pixels lands on its samples. Exactly 0 and 1 at the corners. Needs a map of at least 2×2.
pub fn planar_uv(hf: &Heightfield, i: usize, j: usize) -> [f32; 2] {
    [(i as f64 / (hf.width - 1) as f64) as f32, (j as f64 / (hf.height - 1) as f64) as f32]
}

/// Vertex normal of sample (i, j): the heightfield's normal, unit length in f32 (renormalised
/// after narrowing, which can leave it a few ulps off).
pub fn vertex_normal(hf: &Heightfield, i: usize, j: usize) -> [f32; 3] {
    let n = hf.normal_at(i, j).map(|c| c as f32);
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    n.map(|c| c / len)
}

/// The one terrain material: a neutral grey-green to tint or replace in the engine.
pub fn terrain_material() -> Material {
    Material {
        name: "terrain".to_string(),
        base_color: [0.30, 0.36, 0.26, 1.0],
        base_color_texture: None,
        metallic: 0.0,
        roughness: 1.0,
        alpha_mode: AlphaMode::Opaque,
        double_sided: false,
    }
}

fn check_options(opts: &BuildOptions) -> Result<(), BuildError> {
    if opts.name.trim().is_empty() {
        return Err(BuildError::EmptyName);
    }
    if let Some(n) = opts.chunk_samples {
        if n < 2 {
            return Err(BuildError::ChunkTooSmall(n));
        }
    }
    for (option, depth) in [("skirt depth", opts.skirt_depth_m), ("base depth", opts.base_depth_m)] {
        if let Some(depth_m) = depth {
            if !(depth_m.is_finite() && depth_m > 0.0) {
                return Err(BuildError::InvalidDepth { option, depth_m });
            }
        }
    }
    if opts.skirt_depth_m.is_some() && opts.base_depth_m.is_some() {
        return Err(BuildError::SkirtWithBase);
    }
    Ok(())
}

fn check_heightfield(hf: &Heightfield) -> Result<(), BuildError> {
    let (width, height) = (hf.width, hf.height);
    if width < 2 || height < 2 {
        return Err(BuildError::HeightfieldTooSmall { width, height });
    }
    if width.checked_mul(height) != Some(hf.heights.len()) {
        return Err(BuildError::HeightfieldShape { width, height, len: hf.heights.len() });
    }
    if !(hf.cell_size_m.is_finite() && hf.cell_size_m > 0.0) {
        return Err(BuildError::InvalidCellSize(hf.cell_size_m));
    }
    if let Some(k) = hf.heights.iter().position(|h| !h.is_finite()) {
        return Err(BuildError::NonFiniteHeight { i: k % width, j: k / width, value: hf.heights[k] });
    }
    Ok(())
}

/// Checks the [`SampleMesh`] contract and returns its triangles with duplicate vertices (two ids at
/// the same sample) folded onto the first id, so edges can be matched by vertex id.
fn check_mesh(hf: &Heightfield, mesh: &SampleMesh) -> Result<Vec<[u32; 3]>, BuildError> {
    if mesh.triangles.is_empty() {
        return Err(BuildError::EmptyMesh);
    }
    let (w, h) = (hf.width, hf.height);
    // fold duplicates: first vertex id at each sample
    let mut first_at: HashMap<u64, u32> = HashMap::with_capacity(mesh.vertices.len());
    let mut canonical = Vec::with_capacity(mesh.vertices.len());
    for (vertex, &sample) in mesh.vertices.iter().enumerate() {
        if sample[0] as usize >= w || sample[1] as usize >= h {
            return Err(BuildError::VertexOutOfRange { vertex, sample, width: w, height: h });
        }
        let key = sample[1] as u64 * w as u64 + sample[0] as u64;
        canonical.push(*first_at.entry(key).or_insert(vertex as u32));
    }
    let mut triangles = Vec::with_capacity(mesh.triangles.len());
    let mut directed: HashSet<(u32, u32)> = HashSet::with_capacity(mesh.triangles.len() * 3);
    let mut covered2: u128 = 0;
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for &index in tri {
            if index as usize >= mesh.vertices.len() {
                return Err(BuildError::IndexOutOfRange { triangle: t, index, vertex_count: mesh.vertices.len() });
            }
        }
        let tri = tri.map(|v| canonical[v as usize]);
        let samples = tri.map(|v| mesh.vertices[v as usize]);
        // y of (b − a) × (c − a) with x = i, z = j: e.z·f.x − e.x·f.z
        let d = |k: usize, axis: usize| samples[k][axis] as i64 - samples[0][axis] as i64;
        let cross_y = d(1, 1) * d(2, 0) - d(1, 0) * d(2, 1);
        if cross_y <= 0 {
            return Err(BuildError::NotCounterClockwise { triangle: t, samples });
        }
        covered2 += cross_y as u128;
        for (a, b) in [(tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])] {
            if !directed.insert((a, b)) {
                let (from, to) = (mesh.vertices[a as usize], mesh.vertices[b as usize]);
                return Err(BuildError::NonManifoldEdge { from, to });
            }
        }
        triangles.push(tri);
    }
    let expected2 = 2 * (w as u128 - 1) * (h as u128 - 1);
    if covered2 != expected2 {
        return Err(BuildError::DoesNotCover { covered_cells2: covered2, expected_cells2: expected2 });
    }
    Ok(triangles)
}

/// The surface primitive of the triangles `subset`: each used sample once (in order of first use,
/// so the output is deterministic) with its exact position, heightfield normal and planar UV, plus
/// a skirt under the subset's boundary when asked for. `slots` must be all `u32::MAX` on entry and
/// is left that way.
fn surface(
    hf: &Heightfield,
    mesh: &SampleMesh,
    triangles: &[[u32; 3]],
    subset: &[usize],
    skirt_depth_m: Option<f64>,
    slots: &mut [u32],
) -> Result<Primitive, BuildError> {
    let mut prim = Primitive { material: Some(0), ..Primitive::default() };
    let mut used: Vec<u32> = Vec::new();
    prim.indices.reserve(subset.len() * 3);
    for &t in subset {
        for v in triangles[t] {
            let slot = &mut slots[v as usize];
            if *slot == u32::MAX {
                *slot = used.len() as u32;
                used.push(v);
                let [i, j] = mesh.vertices[v as usize].map(|c| c as usize);
                prim.positions.push(hf.position(i, j));
                prim.normals.push(vertex_normal(hf, i, j));
                prim.uvs.push(planar_uv(hf, i, j));
            }
            prim.indices.push(*slot);
        }
    }
    let skirt = match skirt_depth_m {
        Some(depth_m) => {
            let edges: Vec<[u32; 2]> =
                boundary_edges(triangles, subset).iter().map(|e| e.map(|v| slots[v as usize])).collect();
            add_skirt(&mut prim, &edges, depth_m)
                .map_err(|height_m| BuildError::DepthNotRepresentable { option: "skirt depth", depth_m, height_m })
        }
        None => Ok(()),
    };
    for v in used {
        slots[v as usize] = u32::MAX;
    }
    skirt.map(|()| prim)
}

/// Walls and bottom under the whole triangulation, `depth_m` below its lowest sample.
fn base(hf: &Heightfield, mesh: &SampleMesh, triangles: &[[u32; 3]], all: &[usize], depth_m: f64) -> Result<Primitive, BuildError> {
    // the lowest sample of the map, not just of the mesh: a TIN's surface never dips below it
    let lowest = hf.heights.iter().copied().fold(f32::INFINITY, f32::min);
    let base_y = lowered(lowest, depth_m)
        .ok_or(BuildError::DepthNotRepresentable { option: "base depth", depth_m, height_m: lowest })?;
    let border: Vec<[[u32; 2]; 2]> =
        boundary_edges(triangles, all).iter().map(|e| e.map(|v| mesh.vertices[v as usize])).collect();
    base_primitive(hf, &border, base_y).map_err(|[from, to]| BuildError::BorderNotOnRectangle { from, to })
}

/// A named mesh of `primitives`, each reordered for the GPU (vertex cache, then vertex fetch).
fn finish(name: String, mut primitives: Vec<Primitive>) -> Result<Mesh, BuildError> {
    for prim in &mut primitives {
        if prim.positions.len() >= u32::MAX as usize {
            return Err(BuildError::TooManyVertices(prim.positions.len()));
        }
        prim.optimize_for_gpu();
    }
    Ok(Mesh { name, primitives, extras: None })
}
