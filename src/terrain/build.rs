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

use serde_json::json;

use crate::heightfield::{Heightfield, MapRows};
use crate::mesh::{AlphaMode, Material, Mesh, Node, Primitive, Scene};

use super::chunks::{boundary_edges, ChunkGrid};
use super::sample_mesh::SampleMesh;
use super::solid::{add_skirt, base_primitive, lowered};

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
    /// Where the material layers put snow (the base colour and `_LAYER_WEIGHTS`).
    pub snow: crate::terrain::layers::SnowRule,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            chunk_samples: None,
            skirt_depth_m: None,
            base_depth_m: None,
            name: "terrain".to_string(),
            snow: Default::default(),
        }
    }
}

/// Why a scene could not be built: bad options, or a heightfield/triangulation that breaks the
/// contract of [`SampleMesh`] (the latter points at a mesher bug rather than a user mistake).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BuildError {
    #[error(transparent)]
    Meshopt(#[from] crate::meshopt_guard::FfiError),
    #[error("the terrain name is empty: give the output a name (it names the scene, nodes and meshes)")]
    EmptyName,
    #[error("chunk size {0} is too small: a chunk must span at least 2 samples; pass --chunk 2 or more (`chunk` in a preset; 64–256 is typical), or leave it out for one mesh")]
    ChunkTooSmall(usize),
    #[error("{option} is {depth_m} m: it must be a positive, finite number of metres (e.g. 10); leave the option out to disable it")]
    InvalidDepth { option: &'static str, depth_m: f64 },
    #[error("{option} of {depth_m} m cannot be represented below a height of {height_m} m in 32-bit floats; use a depth of at least a few centimetres and below 1e6 m")]
    DepthNotRepresentable { option: &'static str, depth_m: f64, height_m: f32 },
    #[error("a skirt and a base were both asked for: the base already closes the sides, and skirts would add open flaps inside the solid; use --base for a solid or --skirt for engine chunks (`base`, `skirt` in a preset), not both")]
    SkirtWithBase,
    #[error(
        "the heightfield is {width}×{height} samples: a terrain needs at least 2×2 samples; use a larger heightmap"
    )]
    HeightfieldTooSmall { width: usize, height: usize },
    #[error(
        "the heightfield holds {len} heights but is {width}×{height} samples; this is a decoder bug, please report it"
    )]
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
    #[error("a mesh would need {0} vertices, more than 32-bit indices hold; pass --chunk (`chunk` in a preset) to split the terrain")]
    TooManyVertices(usize),
    #[error(
        "a band's mesh does not fit its rows: {0}; the band piece is damaged or of another map, rebuild it (`--force`)"
    )]
    BandMismatch(String),
    #[error("cannot encode a band's rows of the normal map as PNG: {0}")]
    NormalRows(String),
}

/// Builds the scene for `mesh`, a triangulation of `hf`'s samples (see the module docs for layout).
/// Deterministic: the same inputs give the same scene. Errors on invalid options or a triangulation
/// that breaks the [`SampleMesh`] contract; never panics on them.
pub fn build_scene(hf: &Heightfield, mesh: &SampleMesh, opts: &BuildOptions) -> Result<Scene, BuildError> {
    check_options(opts)?;
    check_heightfield(hf)?;
    let (triangles, edges) = check_mesh(hf, mesh)?;

    let mut scene = Scene { name: opts.name.clone(), materials: vec![terrain_material()], ..Scene::default() };
    // reusable map from vertex id to index in the primitive being built (u32::MAX: not yet in it)
    let mut slots = vec![u32::MAX; mesh.vertices.len()];
    let all: Vec<usize> = (0..triangles.len()).collect();
    let base = match opts.base_depth_m {
        Some(depth) => Some(base(hf, mesh, &triangles, &edges, depth)?),
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
            let parent = chunk_root(&mut scene, &opts.name);
            // the chunks' surfaces in parallel (each task its own vertex slots), then put in
            // chunk order; the first failing chunk in that order is the error, as one by one
            use rayon::prelude::*;
            let order: Vec<(usize, usize)> = (0..grid.ny)
                .flat_map(|cj| (0..grid.nx).map(move |ci| (ci, cj)))
                .filter(|&(ci, cj)| !parts[cj * grid.nx + ci].is_empty())
                .collect();
            let n = mesh.vertices.len();
            let prims: Vec<Result<Primitive, BuildError>> = order
                .par_iter()
                .map_init(
                    || vec![u32::MAX; n],
                    |slots, &(ci, cj)| {
                        surface(hf, mesh, &triangles, &parts[cj * grid.nx + ci], opts.skirt_depth_m, slots)
                    },
                )
                .collect();
            for (&(ci, cj), prim) in order.iter().zip(prims) {
                let mesh = finish(String::new(), vec![prim?])?;
                add_chunk(&mut scene, parent, &grid, &opts.name, [ci, cj], mesh.primitives);
            }
            if let Some(base) = base {
                add_child(&mut scene, parent, finish(format!("{}_base", opts.name), vec![base])?, None);
            }
        }
    }
    Ok(scene)
}

/// The root node `name` of a chunked terrain scene (no mesh; the chunks are its children).
fn chunk_root(scene: &mut Scene, name: &str) -> usize {
    scene.nodes.push(Node { name: name.to_string(), ..Node::default() });
    let parent = scene.nodes.len() - 1;
    scene.roots.push(parent);
    parent
}

/// Adds `mesh` to `scene` as a child node of `parent`, of the mesh's name.
fn add_child(scene: &mut Scene, parent: usize, mesh: Mesh, extras: Option<serde_json::Value>) {
    let name = mesh.name.clone();
    scene.meshes.push(mesh);
    scene.nodes.push(Node { name, mesh: Some(scene.meshes.len() - 1), extras, ..Node::default() });
    let node = scene.nodes.len() - 1;
    scene.nodes[parent].children.push(node);
}

/// Adds chunk `[ci, cj]` of `grid` (its primitives built and ordered already) as a child of
/// `parent`: its mesh and node `{name}_chunk_<ci>_<cj>`, the node's extras its sample rectangle.
fn add_chunk(
    scene: &mut Scene,
    parent: usize,
    grid: &ChunkGrid,
    name: &str,
    [ci, cj]: [usize; 2],
    prims: Vec<Primitive>,
) {
    let (lo, hi) = grid.sample_rect(ci, cj);
    let extras = json!({ "chunk": [ci, cj], "sample_min": lo, "sample_max": hi });
    let mesh = Mesh { name: format!("{name}_chunk_{ci}_{cj}"), primitives: prims, extras: None };
    add_child(scene, parent, mesh, Some(extras));
}

/// A chunked terrain scene named `name` (no base) of a `width` × `height` map in chunks of
/// `pitch` samples, from its chunks' surface primitives as [`band_chunks`] builds them (in chunk
/// order, row-major: every band's in band order), with whatever attributes they were given: the
/// scene [`build_scene`] builds of the whole map, node for node. Errors on chunks out of order
/// or outside the grid.
pub fn assemble_chunks(
    name: &str,
    width: usize,
    height: usize,
    pitch: usize,
    chunks: impl IntoIterator<Item = ([usize; 2], Primitive)>,
) -> Result<Scene, BuildError> {
    check_options(&BuildOptions { chunk_samples: Some(pitch), name: name.to_string(), ..BuildOptions::default() })?;
    let grid = ChunkGrid::new(width, height, pitch);
    let mut scene = Scene { name: name.to_string(), materials: vec![terrain_material()], ..Scene::default() };
    let parent = chunk_root(&mut scene, name);
    let mut last: Option<usize> = None;
    for ([ci, cj], prim) in chunks {
        let at = cj * grid.nx + ci;
        if ci >= grid.nx || cj >= grid.ny || last.is_some_and(|l| l >= at) {
            return Err(BuildError::BandMismatch(format!("chunk ({ci}, {cj}) out of order or outside the grid")));
        }
        last = Some(at);
        add_chunk(&mut scene, parent, &grid, name, [ci, cj], vec![prim]);
    }
    Ok(scene)
}

/// Vertex normal of sample (i, j): the heightfield's normal, unit length in f32 (renormalised
/// after narrowing, which can leave it a few ulps off).
pub fn vertex_normal(hf: &Heightfield, i: usize, j: usize) -> [f32; 3] {
    unit_f32(hf.normal_at(i, j))
}

/// A unit normal narrowed to f32 and renormalised.
fn unit_f32(n: [f64; 3]) -> [f32; 3] {
    let n = n.map(|c| c as f32);
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    n.map(|c| c / len)
}

/// The one terrain material: a neutral grey-green to tint or replace in the engine.
pub fn terrain_material() -> Material {
    Material {
        name: "terrain".to_string(),
        base_color: [0.30, 0.36, 0.26, 1.0],
        base_color_texture: None,
        normal_texture: None,
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

/// Directed edges of a triangulation bucketed by start vertex (compressed rows, as meshoptimizer
/// builds its adjacency: fill counts, fill offset table, fill targets), targets sorted per bucket.
struct EdgeIndex {
    offsets: Vec<usize>,
    targets: Vec<u32>,
}

impl EdgeIndex {
    fn new(vertex_count: usize, triangles: &[[u32; 3]]) -> EdgeIndex {
        let mut offsets = vec![0usize; vertex_count + 1];
        for tri in triangles {
            for &v in tri {
                offsets[v as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            offsets[v + 1] += offsets[v];
        }
        let mut fill = offsets.clone();
        let mut targets = vec![0u32; triangles.len() * 3];
        for tri in triangles {
            for k in 0..3 {
                let a = tri[k] as usize;
                targets[fill[a]] = tri[(k + 1) % 3];
                fill[a] += 1;
            }
        }
        for v in 0..vertex_count {
            targets[offsets[v]..offsets[v + 1]].sort_unstable();
        }
        EdgeIndex { offsets, targets }
    }

    fn targets(&self, a: u32) -> &[u32] {
        &self.targets[self.offsets[a as usize]..self.offsets[a as usize + 1]]
    }

    fn has(&self, a: u32, b: u32) -> bool {
        self.targets(a).binary_search(&b).is_ok()
    }

    /// First edge (a, b) present twice, if any.
    fn repeated(&self) -> Option<(u32, u32)> {
        (0..self.offsets.len() - 1).find_map(|a| {
            let t = self.targets(a as u32);
            t.windows(2).find(|w| w[0] == w[1]).map(|w| (a as u32, w[0]))
        })
    }
}

/// Checks the [`SampleMesh`] contract and returns its triangles with duplicate vertices (two ids at
/// the same sample) folded onto the first id, so edges can be matched by vertex id, and the index
/// of their directed edges.
fn check_mesh(hf: &Heightfield, mesh: &SampleMesh) -> Result<(Vec<[u32; 3]>, EdgeIndex), BuildError> {
    if mesh.triangles.is_empty() {
        return Err(BuildError::EmptyMesh);
    }
    let (w, h) = (hf.width, hf.height);
    // fold duplicates: sort ids by sample, the first (smallest) id of each run stands for the run
    let mut by_sample = Vec::with_capacity(mesh.vertices.len());
    for (vertex, &sample) in mesh.vertices.iter().enumerate() {
        if sample[0] as usize >= w || sample[1] as usize >= h {
            return Err(BuildError::VertexOutOfRange { vertex, sample, width: w, height: h });
        }
        by_sample.push((sample[1] as u64 * w as u64 + sample[0] as u64, vertex as u32));
    }
    by_sample.sort_unstable();
    let mut canonical = vec![0u32; mesh.vertices.len()];
    let mut run = (u64::MAX, 0u32);
    for &(key, vertex) in &by_sample {
        if key != run.0 {
            run = (key, vertex);
        }
        canonical[vertex as usize] = run.1;
    }
    let mut triangles = Vec::with_capacity(mesh.triangles.len());
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
        triangles.push(tri);
    }
    // edge-manifold and consistently oriented: no directed edge twice
    let edges = EdgeIndex::new(mesh.vertices.len(), &triangles);
    if let Some((a, b)) = edges.repeated() {
        return Err(BuildError::NonManifoldEdge { from: mesh.vertices[a as usize], to: mesh.vertices[b as usize] });
    }
    let expected2 = 2 * (w as u128 - 1) * (h as u128 - 1);
    if covered2 != expected2 {
        return Err(BuildError::DoesNotCover { covered_cells2: covered2, expected_cells2: expected2 });
    }
    Ok((triangles, edges))
}

/// The chunks' surface primitives of a band of a chunked terrain, built from the band's rows alone:
/// `window` holds rows `row0 ..` of a map of `map_height` rows, `band` is the band's mesh (its
/// samples in the map's coordinates, as [`crate::terrain::bands::BandPiece`] keeps them), `pitch`
/// and `skirt_depth_m` the scene's chunk size and skirt. Each is the chunk's primitive of
/// [`build_scene`] of the whole map and its joined mesh — the same positions, skirt and triangle
/// order, bit for bit — without the attributes that read rows beyond the band (normals, UVs): what
/// locating points on the terrain reads ([`crate::scatter::SurfaceIndex`]), for a shard holding
/// some bands. Chunks in `(ci, cj)` order, as the scene's meshes.
pub fn band_chunk_surfaces(
    window: &Heightfield,
    row0: usize,
    map_height: usize,
    band: &SampleMesh,
    pitch: usize,
    skirt_depth_m: Option<f64>,
) -> Result<Vec<([usize; 2], Primitive)>, BuildError> {
    let rows = MapRows::new(window, row0, map_height).ok_or_else(|| {
        BuildError::BandMismatch(format!(
            "a band of rows {row0}..{} of a map of {map_height} rows",
            row0 + window.height
        ))
    })?;
    band_chunks(&rows, band, pitch, skirt_depth_m, false)
}

/// A band's chunks as [`build_scene`] makes them, from the map's rows `rows` ([`MapRows`]) and the
/// band's mesh: [`band_chunk_surfaces`], and with `shaded` also each vertex's normal and UV (the
/// whole scene's bit for bit; `rows` must then hold the row beyond each edge of the band that is
/// not the map's border, which the normals read).
pub fn band_chunks(
    rows: &MapRows,
    band: &SampleMesh,
    pitch: usize,
    skirt_depth_m: Option<f64>,
    shaded: bool,
) -> Result<Vec<([usize; 2], Primitive)>, BuildError> {
    check_options(&BuildOptions { chunk_samples: Some(pitch), skirt_depth_m, ..BuildOptions::default() })?;
    check_heightfield(rows.hf)?;
    let held = rows.held();
    let reads = |j: usize| {
        let r = if shaded { rows.normal_reach(j) } else { j..=j };
        held.contains(r.start()) && held.contains(r.end())
    };
    for (k, v) in band.vertices.iter().enumerate() {
        if v[0] as usize >= rows.hf.width || !reads(v[1] as usize) {
            return Err(BuildError::BandMismatch(format!(
                "vertex {k} at sample ({}, {}) needs rows the band's {} × rows {}..={} do not hold",
                v[0],
                v[1],
                rows.hf.width,
                held.start(),
                held.end()
            )));
        }
    }
    if let Some(t) = band.triangles.iter().position(|t| t.iter().any(|&v| v as usize >= band.vertices.len())) {
        return Err(BuildError::BandMismatch(format!("triangle {t} names a vertex the band does not have")));
    }
    let source = Window { rows, shaded };
    let grid = ChunkGrid::new(rows.hf.width, rows.map_height, pitch);
    let parts = grid.partition(&band.vertices, &band.triangles);
    let mut slots = vec![u32::MAX; band.vertices.len()];
    let mut out = Vec::new();
    for cj in 0..grid.ny {
        for ci in 0..grid.nx {
            let part = &parts[cj * grid.nx + ci];
            if part.is_empty() {
                continue;
            }
            let prim = surface(&source, band, &band.triangles, part, skirt_depth_m, &mut slots)?;
            let mut mesh = finish(String::new(), vec![prim])?;
            out.push(([ci, cj], mesh.primitives.remove(0)));
        }
    }
    Ok(out)
}

/// Where a surface primitive takes its samples' attributes from.
trait Samples {
    fn position(&self, i: usize, j: usize) -> [f32; 3];
    /// The vertex normal and UV, when the source has them.
    fn normal_uv(&self, i: usize, j: usize) -> Option<([f32; 3], [f32; 2])>;
}

impl Samples for Heightfield {
    fn position(&self, i: usize, j: usize) -> [f32; 3] {
        Heightfield::position(self, i, j)
    }

    fn normal_uv(&self, i: usize, j: usize) -> Option<([f32; 3], [f32; 2])> {
        Some((vertex_normal(self, i, j), self.planar_uv(i, j)))
    }
}

/// Some rows of a map: positions, and when `shaded` normals and UVs, the same as the map's.
struct Window<'a> {
    rows: &'a MapRows<'a>,
    shaded: bool,
}

impl Samples for Window<'_> {
    fn position(&self, i: usize, j: usize) -> [f32; 3] {
        self.rows.position(i, j)
    }

    fn normal_uv(&self, i: usize, j: usize) -> Option<([f32; 3], [f32; 2])> {
        self.shaded.then(|| (unit_f32(self.rows.normal_at(i, j)), self.rows.planar_uv(i, j)))
    }
}

/// The surface primitive of the triangles `subset`: each used sample once (in order of first use,
/// so the output is deterministic) with its exact position, heightfield normal and planar UV (when
/// `hf` has them), plus a skirt under the subset's boundary when asked for. `slots` must be all
/// `u32::MAX` on entry and is left that way.
fn surface(
    hf: &impl Samples,
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
                if let Some((normal, uv)) = hf.normal_uv(i, j) {
                    prim.normals.push(normal);
                    prim.uvs.push(uv);
                }
            }
            prim.indices.push(*slot);
        }
    }
    let skirt = match skirt_depth_m {
        Some(depth_m) => {
            let edges: Vec<[u32; 2]> =
                boundary_edges(triangles, subset).iter().map(|e| e.map(|v| slots[v as usize])).collect();
            add_skirt(&mut prim, &edges, depth_m).map_err(|height_m| BuildError::DepthNotRepresentable {
                option: "skirt depth",
                depth_m,
                height_m,
            })
        }
        None => Ok(()),
    };
    for v in used {
        slots[v as usize] = u32::MAX;
    }
    skirt.map(|()| prim)
}

/// Walls and bottom under the whole triangulation, `depth_m` below its lowest sample.
fn base(
    hf: &Heightfield,
    mesh: &SampleMesh,
    triangles: &[[u32; 3]],
    edges: &EdgeIndex,
    depth_m: f64,
) -> Result<Primitive, BuildError> {
    // the lowest sample of the map, not just of the mesh: a TIN's surface never dips below it
    let lowest = hf.heights.iter().copied().fold(f32::INFINITY, f32::min);
    let base_y = lowered(lowest, depth_m).ok_or(BuildError::DepthNotRepresentable {
        option: "base depth",
        depth_m,
        height_m: lowest,
    })?;
    // the outer border: edges whose reverse no triangle has, in triangle order
    let mut border = Vec::new();
    for tri in triangles {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            if !edges.has(b, a) {
                border.push([mesh.vertices[a as usize], mesh.vertices[b as usize]]);
            }
        }
    }
    base_primitive(hf, &border, base_y).map_err(|[from, to]| BuildError::BorderNotOnRectangle { from, to })
}

/// A named mesh of `primitives`, each reordered for the GPU (vertex cache, then vertex fetch).
fn finish(name: String, mut primitives: Vec<Primitive>) -> Result<Mesh, BuildError> {
    for prim in &mut primitives {
        if prim.positions.len() >= u32::MAX as usize {
            return Err(BuildError::TooManyVertices(prim.positions.len()));
        }
        prim.optimize_for_gpu()?;
    }
    Ok(Mesh { name, primitives, extras: None })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::fractal;
    use std::collections::{HashMap, HashSet};

    // ---- fixtures -------------------------------------------------------------------------------

    /// A regular grid triangulation with vertices every `step` samples (and on the last row/column),
    /// two CCW triangles per cell.
    fn grid_mesh(w: usize, h: usize, step: usize) -> SampleMesh {
        let ticks = |n: usize| {
            let mut t: Vec<u32> = (0..n - 1).step_by(step).map(|x| x as u32).collect();
            t.push((n - 1) as u32);
            t
        };
        let (xs, zs) = (ticks(w), ticks(h));
        let mut m = SampleMesh::default();
        for &j in &zs {
            for &i in &xs {
                m.vertices.push([i, j]);
            }
        }
        let nx = xs.len() as u32;
        for jj in 0..zs.len() as u32 - 1 {
            for ii in 0..nx - 1 {
                let (a, b, c, d) = (jj * nx + ii, jj * nx + ii + 1, (jj + 1) * nx + ii, (jj + 1) * nx + ii + 1);
                m.triangles.push([a, c, b]);
                m.triangles.push([b, c, d]);
            }
        }
        m
    }

    fn cross_y(m: &SampleMesh, t: [u32; 3]) -> i64 {
        let s = t.map(|v| m.vertices[v as usize].map(|c| c as i64));
        (s[1][1] - s[0][1]) * (s[2][0] - s[0][0]) - (s[1][0] - s[0][0]) * (s[2][1] - s[0][1])
    }

    /// Turns each triangle counter-clockwise seen from +Y.
    fn orient(mut m: SampleMesh) -> SampleMesh {
        for k in 0..m.triangles.len() {
            if cross_y(&m, m.triangles[k]) < 0 {
                m.triangles[k].swap(1, 2);
            }
        }
        m
    }

    /// A real greedy TIN (Delaunay refinement, `delatin`), as the TIN mesher will produce.
    fn tin_mesh(hf: &Heightfield, max_error: f64) -> SampleMesh {
        let heights: Vec<f64> = hf.heights.iter().map(|&h| h as f64).collect();
        let (points, tris) = delatin::triangulate(&heights, (hf.width, hf.height), delatin::Error(max_error)).unwrap();
        let m = SampleMesh {
            vertices: points.iter().map(|&(x, y)| [x as u32, y as u32]).collect(),
            triangles: tris.iter().map(|&(a, b, c)| [a as u32, b as u32, c as u32]).collect(),
        };
        orient(m)
    }

    /// A hand-made TIN on 9×9 samples: a fan of 8 big triangles around the centre, crossing chunk
    /// lines, with one of them split at an interior sample.
    fn hand_tin() -> SampleMesh {
        let mut m = SampleMesh { vertices: vec![[4, 4]], triangles: Vec::new() };
        let ring = [[0, 0], [4, 0], [8, 0], [8, 4], [8, 8], [4, 8], [0, 8], [0, 4]];
        m.vertices.extend_from_slice(&ring);
        for k in 0..8u32 {
            let (a, b) = (1 + k, 1 + (k + 1) % 8);
            if (ring[k as usize], ring[((k + 1) % 8) as usize]) == ([0, 8], [0, 4]) {
                m.vertices.push([1, 6]);
                let p = m.vertices.len() as u32 - 1;
                m.triangles.extend_from_slice(&[[0, a, p], [a, b, p], [b, 0, p]]);
            } else {
                m.triangles.push([0, a, b]);
            }
        }
        orient(m)
    }

    fn bumpy(w: usize, h: usize) -> Heightfield {
        fractal(w, h, 2.5, 80.0, 0.55, 42)
    }

    fn opts(chunk: Option<usize>, skirt: Option<f64>, base: Option<f64>) -> BuildOptions {
        BuildOptions {
            chunk_samples: chunk,
            skirt_depth_m: skirt,
            base_depth_m: base,
            name: "t".into(),
            ..Default::default()
        }
    }

    // ---- scene inspection -----------------------------------------------------------------------

    type Key = [u32; 3];
    fn key(p: [f32; 3]) -> Key {
        p.map(f32::to_bits)
    }

    fn corner(p: &Primitive, t: usize, k: usize) -> usize {
        p.indices[3 * t + k] as usize
    }

    /// (x, z) bits of every sample → (i, j).
    fn sample_lookup(hf: &Heightfield) -> HashMap<[u32; 2], (usize, usize)> {
        let mut map = HashMap::new();
        for j in 0..hf.height {
            for i in 0..hf.width {
                let p = hf.position(i, j);
                map.insert([p[0].to_bits(), p[2].to_bits()], (i, j));
            }
        }
        map
    }

    /// The normal by the formula, written out independently of `Heightfield::normal_at`.
    fn expected_normal(hf: &Heightfield, i: usize, j: usize) -> [f64; 3] {
        let h = |i: usize, j: usize| hf.at(i, j) as f64;
        let c = hf.cell_size_m;
        let (w, ht) = (hf.width, hf.height);
        let dx = if i == 0 {
            (h(1, j) - h(0, j)) / c
        } else if i == w - 1 {
            (h(w - 1, j) - h(w - 2, j)) / c
        } else {
            (h(i + 1, j) - h(i - 1, j)) / (2.0 * c)
        };
        let dz = if j == 0 {
            (h(i, 1) - h(i, 0)) / c
        } else if j == ht - 1 {
            (h(i, ht - 1) - h(i, ht - 2)) / c
        } else {
            (h(i, j + 1) - h(i, j - 1)) / (2.0 * c)
        };
        let len = (dx * dx + 1.0 + dz * dz).sqrt();
        [-dx / len, 1.0 / len, -dz / len]
    }

    fn unit(n: [f32; 3]) -> bool {
        let len = n.iter().map(|&c| c as f64 * c as f64).sum::<f64>().sqrt();
        (len - 1.0).abs() < 1e-6
    }

    /// Surface primitives (terrain and skirts) and base primitives of a scene.
    fn split_prims(scene: &Scene) -> (Vec<&Primitive>, Vec<&Primitive>) {
        let (mut surface, mut base) = (Vec::new(), Vec::new());
        for m in &scene.meshes {
            for (k, p) in m.primitives.iter().enumerate() {
                if m.name.ends_with("_base") || k == 1 {
                    base.push(p);
                } else {
                    surface.push(p);
                }
            }
        }
        (surface, base)
    }

    /// Per-vertex contract of surface primitives: every vertex sits over a sample, exactly at its
    /// position (or exactly `skirt` below it), with the heightfield normal and the planar UV.
    fn check_surface_vertices(hf: &Heightfield, scene: &Scene, skirt: Option<f64>) {
        let samples = sample_lookup(hf);
        for p in split_prims(scene).0 {
            assert_eq!(p.normals.len(), p.positions.len());
            assert_eq!(p.uvs.len(), p.positions.len());
            assert!(p.colors.is_empty());
            assert_eq!(p.material, Some(0));
            for (v, &pos) in p.positions.iter().enumerate() {
                let (i, j) = *samples.get(&[pos[0].to_bits(), pos[2].to_bits()]).expect("vertex over a sample");
                let top = hf.position(i, j);
                let skirt_y = skirt.and_then(|d| lowered(top[1], d));
                assert!(key(pos) == key(top) || Some(pos[1]) == skirt_y, "vertex {pos:?} vs sample {top:?}");
                let n = p.normals[v];
                assert!(unit(n), "normal {n:?} not unit");
                let e = expected_normal(hf, i, j);
                for k in 0..3 {
                    assert!((n[k] as f64 - e[k]).abs() < 1e-6, "normal {n:?} vs {e:?} at ({i}, {j})");
                }
                let uv = p.uvs[v];
                assert_eq!(uv, [(i as f64 / (hf.width - 1) as f64) as f32, (j as f64 / (hf.height - 1) as f64) as f32]);
                if (i == 0 || i == hf.width - 1) && (j == 0 || j == hf.height - 1) {
                    let expect = [if i == 0 { 0.0 } else { 1.0 }, if j == 0 { 0.0 } else { 1.0 }];
                    assert_eq!(uv, expect, "corner UV");
                }
            }
        }
    }

    /// Terrain-surface triangles (facing up) of a primitive as position triples.
    fn up_triangles(p: &Primitive) -> Vec<[[f32; 3]; 3]> {
        (0..p.triangle_count())
            .filter(|&t| p.triangle_cross(t)[1] > 0.0)
            .map(|t| [0, 1, 2].map(|k| p.positions[corner(p, t, k)]))
            .collect()
    }

    /// Chunks are crack-free: over the whole scene, every surface edge off the outer border is
    /// used by exactly two surface triangles, in opposite directions (compared by world position).
    /// Returns the number of surface triangles.
    fn check_crack_free(hf: &Heightfield, scene: &Scene) -> usize {
        let far = hf.position(hf.width - 1, hf.height - 1);
        let mut directed: HashMap<(Key, Key), usize> = HashMap::new();
        let mut count = 0;
        for p in split_prims(scene).0 {
            for tri in up_triangles(p) {
                count += 1;
                for k in 0..3 {
                    *directed.entry((key(tri[k]), key(tri[(k + 1) % 3]))).or_insert(0) += 1;
                }
            }
        }
        let on_border = |a: Key, b: Key| {
            let x = |k: Key| f32::from_bits(k[0]);
            let z = |k: Key| f32::from_bits(k[2]);
            (x(a) == 0.0 && x(b) == 0.0)
                || (z(a) == 0.0 && z(b) == 0.0)
                || (x(a) == far[0] && x(b) == far[0])
                || (z(a) == far[2] && z(b) == far[2])
        };
        for (&(a, b), &n) in &directed {
            assert_eq!(n, 1, "edge used twice in the same direction");
            if !directed.contains_key(&(b, a)) {
                assert!(on_border(a, b), "crack: inner edge {a:?}-{b:?} used once");
            }
        }
        count
    }

    /// Every boundary edge of every surface primitive has its skirt quad, facing outward.
    fn check_skirts(scene: &Scene, depth: f64) {
        let rot = |t: [Key; 3]| {
            let m = (0..3).min_by_key(|&k| t[k]).unwrap();
            [t[m], t[(m + 1) % 3], t[(m + 2) % 3]]
        };
        for p in split_prims(scene).0 {
            let ups = up_triangles(p);
            let mut vertical = HashSet::new();
            let mut vertical_count = 0;
            for t in 0..p.triangle_count() {
                let n = p.triangle_cross(t);
                if n[1] == 0.0 {
                    vertical_count += 1;
                    vertical.insert(rot([0, 1, 2].map(|k| key(p.positions[corner(p, t, k)]))));
                    assert!(n[0] != 0.0 || n[2] != 0.0, "degenerate skirt triangle");
                } else {
                    assert!(n[1] > 0.0, "a surface primitive has only up-facing and vertical triangles");
                }
            }
            let edges: HashSet<(Key, Key)> =
                ups.iter().flat_map(|t| (0..3).map(move |k| (key(t[k]), key(t[(k + 1) % 3])))).collect();
            let mut boundary = 0;
            for t in &ups {
                for k in 0..3 {
                    let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                    if edges.contains(&(key(b), key(a))) {
                        continue;
                    }
                    boundary += 1;
                    let low = |q: [f32; 3]| [q[0], lowered(q[1], depth).unwrap(), q[2]];
                    let (al, bl) = (low(a), low(b));
                    assert!(vertical.contains(&rot([key(b), key(a), key(al)])), "skirt triangle 1 missing");
                    assert!(vertical.contains(&rot([key(b), key(al), key(bl)])), "skirt triangle 2 missing");
                    // the quad's front faces away from the triangle that owns the edge
                    let f = |q: [f32; 3]| q.map(|c| c as f64);
                    let n = crate::math::cross3(crate::math::sub3(f(a), f(b)), crate::math::sub3(f(al), f(b)));
                    let inward = crate::math::sub3(f(c), f(a));
                    assert!(n[0] * inward[0] + n[2] * inward[2] < 0.0, "skirt faces inward");
                }
            }
            assert!(boundary > 0);
            assert_eq!(vertical_count, 2 * boundary, "exactly one quad per boundary edge");
        }
    }

    /// Merges all vertices of the scene by exact position and checks a closed, consistently
    /// oriented 2-manifold of genus 0; returns its signed volume.
    fn check_watertight(scene: &Scene) -> f64 {
        let mut ids: HashMap<Key, usize> = HashMap::new();
        let mut directed: HashMap<(usize, usize), usize> = HashMap::new();
        let mut faces = 0i64;
        let mut volume = 0.0;
        for m in &scene.meshes {
            for p in &m.primitives {
                for t in 0..p.triangle_count() {
                    let n = p.triangle_cross(t);
                    assert!(n.iter().any(|&c| c != 0.0), "degenerate triangle");
                    let pos = [0, 1, 2].map(|k| p.positions[corner(p, t, k)]);
                    let v = pos.map(|q| {
                        let next = ids.len();
                        *ids.entry(key(q)).or_insert(next)
                    });
                    for k in 0..3 {
                        *directed.entry((v[k], v[(k + 1) % 3])).or_insert(0) += 1;
                    }
                    let f = |q: [f32; 3]| q.map(|c| c as f64);
                    let (a, b, c) = (f(pos[0]), f(pos[1]), f(pos[2]));
                    volume += crate::math::cross3(b, c).iter().zip(a).map(|(x, y)| x * y).sum::<f64>() / 6.0;
                    faces += 1;
                }
            }
        }
        for (&(a, b), &n) in &directed {
            assert_eq!(n, 1, "edge used twice in one direction");
            assert_eq!(directed.get(&(b, a)), Some(&1), "open edge: not watertight");
        }
        let (v, e) = (ids.len() as i64, directed.len() as i64 / 2);
        assert_eq!(v - e + faces, 2, "Euler characteristic of a sphere-like solid");
        volume
    }

    /// Base primitives shade flat: every vertex normal is its face's normal (±x/±z walls, −y bottom).
    fn check_base_normals(scene: &Scene) {
        for p in split_prims(scene).1 {
            assert_eq!(p.normals.len(), p.positions.len());
            assert_eq!(p.uvs.len(), p.positions.len());
            for t in 0..p.triangle_count() {
                let n = p.triangle_cross(t);
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                for k in 0..3 {
                    let vn = p.normals[corner(p, t, k)];
                    assert!(unit(vn));
                    for c in 0..3 {
                        assert!((vn[c] as f64 - n[c] / len).abs() < 1e-9, "base normal {vn:?} vs face {n:?}");
                    }
                }
            }
        }
    }

    /// Volume under the triangulated surface down to `base_y`, from the sample mesh directly.
    fn volume_under(hf: &Heightfield, m: &SampleMesh, base_y: f32) -> f64 {
        let cell2 = hf.cell_size_m * hf.cell_size_m;
        m.triangles
            .iter()
            .map(|&t| {
                let mean = t
                    .iter()
                    .map(|&v| hf.at(m.vertices[v as usize][0] as usize, m.vertices[v as usize][1] as usize) as f64)
                    .sum::<f64>()
                    / 3.0;
                cross_y(m, t) as f64 / 2.0 * cell2 * (mean - base_y as f64)
            })
            .sum()
    }

    // ---- tests ----------------------------------------------------------------------------------

    #[test]
    fn single_mesh_has_exact_vertices_normals_uvs_and_ccw_triangles() {
        let hf = bumpy(33, 21);
        for m in [grid_mesh(33, 21, 1), grid_mesh(33, 21, 4), tin_mesh(&hf, 1.0)] {
            let scene = build_scene(&hf, &m, &opts(None, None, None)).unwrap();
            assert_eq!(scene.name, "t");
            assert_eq!((scene.nodes.len(), scene.meshes.len(), scene.roots.clone()), (1, 1, vec![0]));
            assert_eq!(scene.nodes[0].name, "t");
            assert_eq!(scene.meshes[0].name, "t");
            assert_eq!(scene.meshes[0].primitives.len(), 1);
            let p = &scene.meshes[0].primitives[0];
            // every triangle is terrain surface, CCW from +Y
            assert_eq!(up_triangles(p).len(), m.triangles.len());
            assert_eq!(p.triangle_count(), m.triangles.len());
            // only the samples the mesh uses
            assert_eq!(p.positions.len(), m.vertices.len());
            check_surface_vertices(&hf, &scene, None);
            assert_eq!(check_crack_free(&hf, &scene), m.triangles.len());
        }
    }

    #[test]
    fn material_is_one_opaque_single_sided_grey_green() {
        let hf = bumpy(5, 5);
        let scene = build_scene(&hf, &grid_mesh(5, 5, 1), &opts(Some(2), None, None)).unwrap();
        assert_eq!(scene.materials.len(), 1);
        let mat = &scene.materials[0];
        assert_eq!(mat.name, "terrain");
        assert_eq!(
            (mat.metallic, mat.roughness, mat.alpha_mode, mat.double_sided),
            (0.0, 1.0, AlphaMode::Opaque, false)
        );
        let [r, g, b, a] = mat.base_color;
        assert!(g > r && g > b && r > 0.1 && a == 1.0, "grey-green, opaque");
        assert!(scene.meshes.iter().flat_map(|m| &m.primitives).all(|p| p.material == Some(0)));
    }

    #[test]
    fn chunks_preserve_triangles_leave_no_cracks_and_hold_their_centroids() {
        let hf = bumpy(41, 27);
        let hand_hf = bumpy(9, 9);
        let cases = [
            (&hf, grid_mesh(41, 27, 1), 8),
            (&hf, grid_mesh(41, 27, 3), 7),
            (&hf, tin_mesh(&hf, 0.5), 16),
            (&hf, tin_mesh(&hf, 4.0), 10),
            (&hand_hf, hand_tin(), 4),
            (&hand_hf, hand_tin(), 3),
            (&hand_hf, hand_tin(), 2),
        ];
        for (hf, m, pitch) in cases {
            let scene = build_scene(hf, &m, &opts(Some(pitch), None, None)).unwrap();
            let grid = ChunkGrid::new(hf.width, hf.height, pitch);
            // a parent named after the terrain, with one child per non-empty chunk
            assert_eq!(scene.roots, vec![0]);
            let parent = &scene.nodes[0];
            assert_eq!((parent.name.as_str(), parent.mesh), ("t", None));
            assert!(!parent.children.is_empty() && parent.children.len() <= grid.len());
            assert_eq!(scene.meshes.len(), parent.children.len());
            let samples = sample_lookup(hf);
            let mut total = 0;
            for &c in &parent.children {
                let node = &scene.nodes[c];
                let extras = node.extras.as_ref().unwrap();
                let (ci, cj) = (extras["chunk"][0].as_u64().unwrap(), extras["chunk"][1].as_u64().unwrap());
                assert_eq!(node.name, format!("t_chunk_{ci}_{cj}"));
                assert_eq!((node.translation, node.rotation, node.scale), ([0.0; 3], [0.0, 0.0, 0.0, 1.0], [1.0; 3]));
                let mesh = &scene.meshes[node.mesh.unwrap()];
                assert_eq!(mesh.name, node.name);
                let p = &mesh.primitives[0];
                assert!(p.triangle_count() > 0, "empty chunks are skipped");
                let lo = [0, 1].map(|k| extras["sample_min"][k].as_u64().unwrap() as f64);
                let hi = [0, 1].map(|k| extras["sample_max"][k].as_u64().unwrap() as f64);
                assert_eq!((lo, hi), {
                    let (l, h) = grid.sample_rect(ci as usize, cj as usize);
                    (l.map(|x| x as f64), h.map(|x| x as f64))
                });
                // only the vertices its triangles use
                let mut used = vec![false; p.positions.len()];
                p.indices.iter().for_each(|&v| used[v as usize] = true);
                assert!(used.iter().all(|&u| u));
                for tri in up_triangles(p) {
                    let s = tri.map(|q| samples[&[q[0].to_bits(), q[2].to_bits()]]);
                    let centroid = [(s[0].0 + s[1].0 + s[2].0) as f64 / 3.0, (s[0].1 + s[1].1 + s[2].1) as f64 / 3.0];
                    for k in 0..2 {
                        assert!(
                            lo[k] <= centroid[k] && centroid[k] <= hi[k],
                            "centroid {centroid:?} outside {lo:?}..{hi:?}"
                        );
                    }
                }
                total += p.triangle_count();
            }
            assert_eq!(total, m.triangles.len(), "triangle count preserved");
            assert_eq!(check_crack_free(hf, &scene), m.triangles.len());
            check_surface_vertices(hf, &scene, None);
        }
    }

    #[test]
    fn skirts_hang_from_every_boundary_edge_facing_out() {
        let hf = bumpy(29, 19);
        for (m, chunk) in
            [(grid_mesh(29, 19, 2), None), (grid_mesh(29, 19, 1), Some(8)), (tin_mesh(&hf, 1.0), Some(10))]
        {
            let scene = build_scene(&hf, &m, &opts(chunk, Some(7.5), None)).unwrap();
            check_skirts(&scene, 7.5);
            check_surface_vertices(&hf, &scene, Some(7.5));
            assert_eq!(check_crack_free(&hf, &scene), m.triangles.len());
        }
    }

    #[test]
    fn base_of_a_flat_map_is_a_box_of_the_right_volume() {
        // 7×4 samples, 2 m cells, all at 10 m, base 5 m deep → a 12 m × 6 m × 5 m box
        let hf = Heightfield { width: 7, height: 4, heights: vec![10.0; 28], cell_size_m: 2.0, exact: None };
        for (m, chunk) in [(grid_mesh(7, 4, 1), None), (grid_mesh(7, 4, 2), Some(2)), (grid_mesh(7, 4, 6), None)] {
            let scene = build_scene(&hf, &m, &opts(chunk, None, Some(5.0))).unwrap();
            let volume = check_watertight(&scene);
            assert!((volume - 12.0 * 6.0 * 5.0).abs() < 1e-9, "{volume}");
            check_base_normals(&scene);
            check_surface_vertices(&hf, &scene, None);
            let bottom = scene.meshes.iter().flat_map(|m| &m.primitives).filter_map(|p| p.bounds()).map(|b| b.min[1]);
            assert_eq!(bottom.fold(f32::INFINITY, f32::min), 5.0);
        }
    }

    #[test]
    fn base_of_a_bumpy_map_is_watertight_with_the_volume_under_its_surface() {
        let (hf, small) = (bumpy(37, 23), bumpy(9, 9));
        let cases = [
            (&hf, grid_mesh(37, 23, 1), None),
            (&hf, tin_mesh(&hf, 2.0), None),
            (&hf, tin_mesh(&hf, 2.0), Some(8)),
            (&small, hand_tin(), None),
            (&small, hand_tin(), Some(3)),
        ];
        for (hf, m, chunk) in cases {
            let lowest = hf.heights.iter().copied().fold(f32::INFINITY, f32::min);
            let base_y = lowered(lowest, 12.0).unwrap();
            let scene = build_scene(hf, &m, &opts(chunk, None, Some(12.0))).unwrap();
            let volume = check_watertight(&scene);
            let expected = volume_under(hf, &m, base_y);
            assert!(volume > 0.0);
            assert!((volume - expected).abs() <= 1e-9 * expected, "{volume} vs {expected}");
            check_base_normals(&scene);
            check_surface_vertices(hf, &scene, None);
            if chunk.is_some() {
                let parent = &scene.nodes[0];
                let last = &scene.nodes[*parent.children.last().unwrap()];
                assert_eq!(last.name, "t_base");
                assert_eq!(check_crack_free(hf, &scene), m.triangles.len());
            } else {
                assert_eq!(scene.meshes[0].primitives.len(), 2);
            }
        }
    }

    #[test]
    fn invalid_options_are_errors_with_remedies() {
        let hf = bumpy(5, 5);
        let m = grid_mesh(5, 5, 1);
        let err = |o: BuildOptions| build_scene(&hf, &m, &o).unwrap_err();
        assert_eq!(err(opts(Some(0), None, None)), BuildError::ChunkTooSmall(0));
        assert_eq!(err(opts(Some(1), None, None)), BuildError::ChunkTooSmall(1));
        assert!(err(opts(Some(1), None, None)).to_string().contains("--chunk 2 or more"));
        for bad in [-1.0, 0.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(err(opts(None, Some(bad), None)), BuildError::InvalidDepth { option: "skirt depth", .. }));
            assert!(matches!(err(opts(None, None, Some(bad))), BuildError::InvalidDepth { option: "base depth", .. }));
        }
        assert!(err(opts(None, Some(-2.0), None)).to_string().contains("positive"));
        assert_eq!(err(opts(None, Some(1.0), Some(1.0))), BuildError::SkirtWithBase);
        assert_eq!(err(BuildOptions { name: " ".into(), ..BuildOptions::default() }), BuildError::EmptyName);
        // depths f32 cannot represent at this height
        let high = Heightfield { width: 2, height: 2, heights: vec![5000.0; 4], cell_size_m: 1.0, exact: None };
        let m2 = grid_mesh(2, 2, 1);
        for o in [opts(None, Some(1e-6), None), opts(None, None, Some(1e-6)), opts(None, None, Some(1e300))] {
            assert!(matches!(build_scene(&high, &m2, &o), Err(BuildError::DepthNotRepresentable { .. })));
        }
    }

    #[test]
    fn invalid_inputs_are_errors_not_panics() {
        let hf = bumpy(5, 5);
        let good = grid_mesh(5, 5, 1);
        let o = BuildOptions::default();
        let run = |hf: &Heightfield, m: &SampleMesh| build_scene(hf, m, &o).unwrap_err();

        assert_eq!(run(&hf, &SampleMesh::default()), BuildError::EmptyMesh);
        let mut m = good.clone();
        m.vertices[3] = [5, 0];
        assert!(matches!(run(&hf, &m), BuildError::VertexOutOfRange { vertex: 3, .. }));
        let mut m = good.clone();
        m.triangles[2][1] = 99;
        assert!(matches!(run(&hf, &m), BuildError::IndexOutOfRange { triangle: 2, index: 99, .. }));
        let mut m = good.clone();
        m.triangles[4].swap(0, 1);
        assert!(matches!(run(&hf, &m), BuildError::NotCounterClockwise { triangle: 4, .. }));
        let mut m = good.clone();
        m.triangles.pop();
        assert!(matches!(run(&hf, &m), BuildError::DoesNotCover { .. }));
        let mut m = good.clone();
        let dup = m.triangles[0];
        m.triangles.push(dup);
        assert!(matches!(run(&hf, &m), BuildError::NonManifoldEdge { .. }));
        // a duplicate vertex at the same sample is folded, not an error
        let mut m = good.clone();
        m.vertices.push(m.vertices[6]);
        let last = m.vertices.len() as u32 - 1;
        // half of the triangles around sample 6 use the copy: their shared edges must still match
        let mut uses = 0;
        for t in m.triangles.iter_mut() {
            if let Some(v) = t.iter_mut().find(|v| **v == 6) {
                if uses % 2 == 1 {
                    *v = last;
                }
                uses += 1;
            }
        }
        assert!(uses >= 4);
        let scene = build_scene(&hf, &m, &o).unwrap();
        assert_eq!(check_crack_free(&hf, &scene), m.triangles.len());

        let tiny = Heightfield { width: 1, height: 3, heights: vec![0.0; 3], cell_size_m: 1.0, exact: None };
        assert!(matches!(run(&tiny, &good), BuildError::HeightfieldTooSmall { .. }));
        let short = Heightfield { heights: vec![0.0; 7], ..hf.clone() };
        assert!(matches!(run(&short, &good), BuildError::HeightfieldShape { len: 7, .. }));
        let flat_cell = Heightfield { cell_size_m: 0.0, ..hf.clone() };
        assert!(matches!(run(&flat_cell, &good), BuildError::InvalidCellSize(_)));
        let mut holes = hf.clone();
        holes.heights[5 * 2 + 3] = f32::NAN;
        assert!(matches!(run(&holes, &good), BuildError::NonFiniteHeight { i: 3, j: 2, .. }));
    }

    #[test]
    fn a_2x2_map_works_with_every_option() {
        let hf = Heightfield { width: 2, height: 2, heights: vec![1.0, 2.0, 3.0, 5.0], cell_size_m: 0.5, exact: None };
        let m = grid_mesh(2, 2, 1);
        for o in [
            opts(None, None, None),
            opts(Some(2), None, None),
            opts(Some(64), Some(1.0), None),
            opts(None, Some(0.25), None),
            opts(None, None, Some(1.0)),
            opts(Some(2), None, Some(3.0)),
        ] {
            let scene = build_scene(&hf, &m, &o).unwrap();
            assert_eq!(check_crack_free(&hf, &scene), 2);
            check_surface_vertices(&hf, &scene, o.skirt_depth_m);
            if let Some(d) = o.skirt_depth_m {
                check_skirts(&scene, d);
            }
            if let Some(depth) = o.base_depth_m {
                let v = check_watertight(&scene);
                let base_y = 1.0 - depth as f32;
                assert!((v - volume_under(&hf, &m, base_y)).abs() < 1e-12);
                check_base_normals(&scene);
            }
        }
    }

    #[test]
    fn a_301x17_map_in_chunks_of_64_works() {
        let hf = bumpy(301, 17);
        for m in [grid_mesh(301, 17, 1), tin_mesh(&hf, 1.0)] {
            let scene = build_scene(&hf, &m, &opts(Some(64), Some(5.0), None)).unwrap();
            let names: Vec<&str> = scene.nodes[0].children.iter().map(|&c| scene.nodes[c].name.as_str()).collect();
            assert_eq!(names, ["t_chunk_0_0", "t_chunk_1_0", "t_chunk_2_0", "t_chunk_3_0", "t_chunk_4_0"]);
            assert_eq!(check_crack_free(&hf, &scene), m.triangles.len());
            check_skirts(&scene, 5.0);
            check_surface_vertices(&hf, &scene, Some(5.0));
            let solid = build_scene(&hf, &m, &opts(Some(64), None, Some(5.0))).unwrap();
            assert!(check_watertight(&solid) > 0.0);
        }
    }

    #[test]
    fn output_is_deterministic() {
        let hf = bumpy(45, 30);
        let m = tin_mesh(&hf, 1.0);
        let o = opts(Some(16), Some(3.0), None);
        assert_eq!(build_scene(&hf, &m, &o).unwrap(), build_scene(&hf, &m, &o).unwrap());
        let o = opts(None, None, Some(3.0));
        assert_eq!(build_scene(&hf, &m, &o).unwrap(), build_scene(&hf, &m, &o).unwrap());
    }

    #[test]
    fn heightfield_normal_matches_the_formula() {
        let hf = bumpy(6, 4);
        for j in 0..4 {
            for i in 0..6 {
                let (n, e) = (hf.normal_at(i, j), expected_normal(&hf, i, j));
                for k in 0..3 {
                    assert!((n[k] - e[k]).abs() < 1e-12);
                }
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]

        /// Any map size, mesh (grid of any step, or a TIN of any tolerance) and chunk size: chunks keep
        /// every triangle without cracks, skirts cover every chunk boundary, the base is watertight.
        #[test]
        fn invariants_hold_for_any_size_and_chunking(
            w in 2usize..24, h in 2usize..24, step in 1usize..6, tin_error in proptest::option::of(0.2f64..8.0),
            pitch in 2usize..10, seed in 0u64..1000,
        ) {
            let hf = fractal(w, h, 1.5, 30.0, 0.5, seed);
            let m = match tin_error {
                Some(e) => tin_mesh(&hf, e),
                None => grid_mesh(w, h, step),
            };
            let chunked = build_scene(&hf, &m, &opts(Some(pitch), Some(2.0), None)).unwrap();
            proptest::prop_assert_eq!(check_crack_free(&hf, &chunked), m.triangles.len());
            check_skirts(&chunked, 2.0);
            check_surface_vertices(&hf, &chunked, Some(2.0));
            let solid = build_scene(&hf, &m, &opts(Some(pitch), None, Some(2.0))).unwrap();
            let lowest = hf.heights.iter().copied().fold(f32::INFINITY, f32::min);
            let expected = volume_under(&hf, &m, lowered(lowest, 2.0).unwrap());
            let volume = check_watertight(&solid);
            proptest::prop_assert!((volume - expected).abs() <= 1e-9 * expected);
        }
    }
}
