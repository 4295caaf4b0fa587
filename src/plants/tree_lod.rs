//! Level-of-detail chain of an L-system tree with baked atlases, after the point-sprite thesis'
//! BranchTree (finest branches become sprites first) and Maciel & Shirley's textured-cluster
//! impostors ("Visual navigation of large environments using textured clusters", I3D 1995).
//! LoD0 full; LoD1 half the radial segments + meshoptimizer simplification (Garland & Heckbert
//! quadrics); LoD2 the finest branch level replaced by leaf-cluster cards baked from it; LoD3 four
//! crossed billboards; LoD4 one impostor quad with 8 baked views. Each level is measured: triangles,
//! bytes, sampled one-sided Hausdorff distance to LoD0 ([`crate::plants::hausdorff`]) and image error
//! with the 1-px switch distance ([`crate::bake::views::switch_search`]).
//!
//! Impostor view selection (LoD4): the quad in the file faces +Z; an engine turns it to face the
//! camera about the vertical axis through `centre` and picks the atlas cell from the direction
//! (dx, dz) from the tree to the eye: `k = round(atan2(dx, dz) / 45°) mod 8`, cell k having been
//! baked looking from azimuth k · 45° (0° = from +Z, 90° = from +X). The mesh extras
//! (`verdant_impostor`) carry the cells' uv rectangles, the centre and the quad size.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::bake::atlas::{
    dilate, finish_normal_atlas, mip_chain, mip_figures, resolve_supersampled, write_mip_pngs, MipFigures, MipLevel,
    FLAT_NORMAL,
};
use crate::bake::image::Image;
use crate::bake::raster::{Camera, OrthoView, RasterError};
use crate::bake::render::{render_mesh, RenderOptions, Shading};
use crate::bake::views::{
    lod_image_error_with, switch_search, switch_search_by, DistanceError, LodImageOptions, Renderable, SwitchSearch,
};
use crate::export::{self, ExportError};
use crate::failure::{Blame, Failure};
use crate::lod::LodView;
use crate::lsystem::{parse, Dialect, LSystem};
use crate::mesh::{AlphaMode, Bounds, CustomAttribute, Material, Mesh, Node, Primitive, Scene, Texture};
use crate::plants::hausdorff::{hausdorff, HausdorffError, TriangleGrid};
use crate::plants::mesh_asset::{load_obj, MeshAssetError, MeshAssetStats, ObjOptions, SourceMesh};
use crate::plants::tree::{build_tree, is_flat, TreeError, TreeMesh, TreeOptions, TreeReport, TreeSeconds};
use crate::plants::wind::{self, WIND_ATTRIBUTE, WIND_BRANCH_ATTRIBUTE};
use crate::random::mix64;
use crate::validate::{validate_file, ValidateOptions};

/// LoD0 full … LoD4 impostor.
pub const TREE_LODS: usize = 5;
pub const IMPOSTOR_VIEWS: usize = 8;
/// LoD3's vertical planes (azimuths 0°, 45°, 90°, 135°: the first four impostor views).
pub const BILLBOARD_PLANES: usize = 4;
/// LoD2's leaf-cluster cards at most (two crossed quads each).
pub const MAX_CLUSTERS: usize = 64;
pub const DEFAULT_ATLAS_PX: u32 = 1024;
pub const MIN_ATLAS_PX: u32 = 256;
/// A 4096² atlas is 256 MiB as floats while baking.
pub const MAX_ATLAS_PX: u32 = 4096;
pub const ATLAS_ALPHA_CUTOFF: f32 = 0.5;
/// Transparent (then dilated) texels around every atlas cell, so filtering and mips do not bleed.
pub const ATLAS_GUTTER_PX: u32 = 4;
/// Samples per texel along each axis when baking (the resolved alpha is fractional at edges, which
/// lets the coverage-preserving mips keep level 0's coverage).
pub const BAKE_SUPERSAMPLE: u32 = 2;
pub const DEFAULT_HAUSDORFF_SAMPLES: usize = 20_000;
/// LoD1 and LoD2 keep about this fraction of their input's triangles...
const SIMPLIFY_RATIO: f64 = 0.5;
/// ...unless that would move the surface more than the first of these fractions of the mesh's
/// extent; the next ones are tried only when a level would not have fewer triangles than the one
/// before (small polygon-only plants).
const SIMPLIFY_MAX_ERRORS: [f32; 4] = [0.01, 0.05, 0.25, 1.0];
/// Extras key of the impostor's mesh.
pub const IMPOSTOR_EXTRAS_KEY: &str = "verdant_impostor";

const IDENTITY: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];

#[derive(Debug, thiserror::Error)]
pub enum TreeLodError {
    #[error(transparent)]
    Tree(#[from] TreeError),
    #[error("invalid LoD options: {0}")]
    Options(String),
    #[error("baking the tree atlas: {0}")]
    Raster(#[from] RasterError),
    #[error("tree texture: {0}")]
    Texture(String),
    #[error(transparent)]
    Export(#[from] ExportError),
    #[error(transparent)]
    MeshAsset(#[from] MeshAssetError),
    #[error("{path} does not pass validation (this is a bug, please report it with the input file):\n{report}")]
    Invalid { path: PathBuf, report: String },
}

/// The input's for bad input, options or exceeded limits; the build's otherwise.
impl Failure for TreeLodError {
    fn blame(&self) -> Blame {
        match self {
            TreeLodError::Tree(e) => e.blame(),
            TreeLodError::Options(_) => Blame::Input,
            TreeLodError::MeshAsset(e) => e.blame(),
            _ => Blame::Build,
        }
    }
}

/// How the chain is built and measured.
#[derive(Debug, Clone, PartialEq)]
pub struct TreeLodOptions {
    /// Levels written (1..=5, finest first).
    pub lods: usize,
    /// Side of the square atlas (a multiple of 16 in MIN_ATLAS_PX..=MAX_ATLAS_PX).
    pub atlas_px: u32,
    /// Measure image errors and switch distances (off: coverages are 0, for timing the build).
    pub analyze: bool,
    pub hausdorff_samples: usize,
    /// How the image analyzer renders (8 azimuths × 3 elevations).
    pub image: LodImageOptions,
    /// The LoD policy switch distances are found for (`[lod]`: pixel budget and screen).
    pub policy: LodView,
}

impl Default for TreeLodOptions {
    fn default() -> Self {
        TreeLodOptions {
            lods: TREE_LODS,
            atlas_px: DEFAULT_ATLAS_PX,
            analyze: true,
            hausdorff_samples: DEFAULT_HAUSDORFF_SAMPLES,
            image: LodImageOptions { max_side_px: 96, supersample: 2, ..LodImageOptions::default() },
            policy: LodView::default(),
        }
    }
}

impl TreeLodOptions {
    pub fn check(&self) -> Result<(), TreeLodError> {
        if !(1..=TREE_LODS).contains(&self.lods) {
            return Err(TreeLodError::Options(format!("--lods {} is out of range; use 1 to {TREE_LODS}", self.lods)));
        }
        if !(MIN_ATLAS_PX..=MAX_ATLAS_PX).contains(&self.atlas_px) || !self.atlas_px.is_multiple_of(16) {
            return Err(TreeLodError::Options(format!(
                "--atlas-size {} must be a multiple of 16 from {MIN_ATLAS_PX} to {MAX_ATLAS_PX} (e.g. 1024 or 2048)",
                self.atlas_px
            )));
        }
        Ok(())
    }
}

/// Every cell of an `atlas_px` tree atlas as its inside's (u0, v0, u1, v1): the impostor views
/// (large cells 0..8), then the small cells cards and billboards use.
pub fn atlas_cell_rects(atlas_px: u32) -> Vec<[f32; 4]> {
    let large = (0..IMPOSTOR_VIEWS).map(|k| AtlasCell::large(atlas_px, k).uv);
    large.chain((0..128).map(|j| AtlasCell::small(atlas_px, j).uv)).collect()
}

/// A square atlas cell; `uv` is its inside (within the gutter) as (u0, v0, u1, v1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AtlasCell {
    pub x: u32,
    pub y: u32,
    pub size: u32,
    pub uv: [f32; 4],
}

impl AtlasCell {
    fn new(atlas_px: u32, x: u32, y: u32, size: u32) -> AtlasCell {
        let (a, g) = (atlas_px as f32, ATLAS_GUTTER_PX);
        AtlasCell {
            x,
            y,
            size,
            uv: [(x + g) as f32 / a, (y + g) as f32 / a, (x + size - g) as f32 / a, (y + size - g) as f32 / a],
        }
    }

    /// Pixels inside the gutter.
    fn inner_px(&self) -> u32 {
        self.size - 2 * ATLAS_GUTTER_PX
    }

    /// Large cell `i` of the 4 × 4 grid: 0..8 are the impostor views, 8..16 hold the small cells.
    fn large(atlas_px: u32, i: usize) -> AtlasCell {
        let s = atlas_px / 4;
        AtlasCell::new(atlas_px, (i as u32 % 4) * s, (i as u32 / 4) * s, s)
    }

    /// Small cell `j` (0..128): large cells 8..16, each split 4 × 4; a card uses two.
    fn small(atlas_px: u32, j: usize) -> AtlasCell {
        let big = AtlasCell::large(atlas_px, 8 + j / 16);
        let s = atlas_px / 16;
        let k = j as u32 % 16;
        AtlasCell::new(atlas_px, big.x + (k % 4) * s, big.y + (k / 4) * s, s)
    }
}

/// A square picture plane: vertical, facing azimuth `azimuth_deg` (0° = +Z, 90° = +X), `side_m`
/// wide and tall around `centre`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct CardFrame {
    centre: DVec3,
    azimuth_deg: f64,
    side_m: f64,
}

impl CardFrame {
    /// Towards the viewer, and to the viewer's right.
    fn axes(&self) -> (DVec3, DVec3) {
        let a = self.azimuth_deg.to_radians();
        (DVec3::new(a.sin(), 0.0, a.cos()), DVec3::new(a.cos(), 0.0, -a.sin()))
    }

    fn ortho(&self, px: u32) -> OrthoView {
        let (toward, right) = self.axes();
        let h = self.side_m / 2.0;
        // the depth starts a side ahead of the centre: everything framed is behind it
        let origin = self.centre - right * h + DVec3::Y * h + toward * self.side_m;
        OrthoView {
            origin: origin.to_array(),
            right: right.to_array(),
            up: [0.0, 1.0, 0.0],
            forward: (-toward).to_array(),
            pixels_per_metre: px as f64 / self.side_m,
            width: px,
            height: px,
        }
    }

    /// The quad showing `uv` (counter-clockwise seen from the viewer side).
    fn quad(&self, uv: [f32; 4]) -> Primitive {
        let (toward, right) = self.axes();
        let h = self.side_m / 2.0;
        let corner = |r: f64, u: f64| (self.centre + right * (r * h) + DVec3::Y * (u * h)).as_vec3().to_array();
        let n = toward.as_vec3().to_array();
        let positions = [corner(-1.0, -1.0), corner(1.0, -1.0), corner(1.0, 1.0), corner(-1.0, 1.0)];
        let uvs = [[uv[0], uv[3]], [uv[2], uv[3]], [uv[2], uv[1]], [uv[0], uv[1]]];
        Primitive {
            positions: positions.to_vec(),
            normals: vec![n; 4],
            uvs: uvs.to_vec(),
            tangents: vec![crate::mesh::quad_tangent(positions, uvs, n); 4],
            indices: vec![0, 1, 2, 0, 2, 3],
            ..Primitive::default()
        }
    }
}

/// Renders `mesh` into a `px` square through `frame` at BAKE_SUPERSAMPLE×, resolved.
fn bake(
    frame: &CardFrame,
    px: u32,
    mesh: &Mesh,
    materials: &[Material],
    textures: &[Image],
    shading: Shading,
) -> Result<(Image, u64), RasterError> {
    let cam = Camera::Ortho(frame.ortho(px * BAKE_SUPERSAMPLE));
    let mut canvas = cam.canvas([0.0; 4])?;
    let opts = RenderOptions { use_vertex_colors: false, shading, parallel: false };
    let fragments = render_mesh(&mut canvas, &cam, &IDENTITY, mesh, materials, textures, &opts).fragments;
    Ok((resolve_supersampled(&Image::from_canvas_owned(canvas), BAKE_SUPERSAMPLE), fragments))
}

/// `a` with `b`'s vertices and triangles after its own (positions, normals, uvs and the custom
/// attributes both have, or all of `b`'s when `a` is empty; `a`'s material).
fn appended(mut a: Primitive, b: &Primitive) -> Primitive {
    let base = a.positions.len() as u32;
    if a.positions.is_empty() {
        a.custom = b.custom.iter().map(|c| CustomAttribute { name: c.name.clone(), values: Vec::new() }).collect();
    }
    a.custom.retain(|c| b.custom.iter().any(|d| d.name == c.name));
    for c in &mut a.custom {
        if let Some(d) = wind::find(&b.custom, &c.name) {
            c.values.extend_from_slice(&d.values);
        }
    }
    a.positions.extend_from_slice(&b.positions);
    a.normals.extend_from_slice(&b.normals);
    a.uvs.extend_from_slice(&b.uvs);
    a.tangents.extend_from_slice(&b.tangents);
    a.indices.extend(b.indices.iter().map(|i| i + base));
    a
}

/// How a tree's card levels sway: the model's ground and top and its sway frequency, from LoD0's
/// `_WIND` (None when LoD0 has none: an OBJ rock does not sway).
#[derive(Debug, Clone, Copy)]
struct CardWind {
    ground_y: f32,
    top_y: f32,
    sway_hz: f32,
}

impl CardWind {
    fn of(lod0: &Mesh) -> Option<CardWind> {
        let sway_hz = lod0
            .primitives
            .iter()
            .find_map(|p| wind::find(&p.custom, WIND_ATTRIBUTE))
            .and_then(|w| w.values.first())?[2];
        let positions: Vec<[f32; 3]> = lod0.primitives.iter().flat_map(|p| p.positions.iter().copied()).collect();
        let b = Bounds::of(&positions)?;
        let ground_y = if (b.min[1]..=b.max[1]).contains(&0.0) { 0.0 } else { b.min[1] };
        Some(CardWind { ground_y, top_y: b.max[1], sway_hz })
    }

    /// `card` with `_WIND` from each vertex's height and, when `branch` is given (a card standing
    /// for part of the crown: its mean branch weight and its limb's phase), `_WIND_BRANCH`.
    fn on(&self, mut card: Primitive, branch: Option<[f32; 2]>) -> Primitive {
        card.custom = vec![wind::height_wind(&card.positions, self.ground_y, self.top_y, 0.0, self.sway_hz, 0.0)];
        if let Some([weight, phase]) = branch {
            card.custom.push(CustomAttribute {
                name: WIND_BRANCH_ATTRIBUTE.into(),
                values: vec![[weight, phase, 0.0, 0.0]; card.positions.len()],
            });
        }
        card
    }
}

/// The mean branch weight of `mesh`'s vertices and the limb phase most of them have.
fn branch_of(mesh: &Mesh) -> [f32; 2] {
    let values: Vec<[f32; 4]> = mesh
        .primitives
        .iter()
        .filter_map(|p| wind::find(&p.custom, WIND_BRANCH_ATTRIBUTE))
        .flat_map(|c| c.values.iter().copied())
        .collect();
    if values.is_empty() {
        return [0.0, 0.0];
    }
    let weight = values.iter().map(|v| v[0] as f64).sum::<f64>() / values.len() as f64;
    let mut phases: Vec<u32> = values.iter().map(|v| v[1].to_bits()).collect();
    phases.sort_unstable();
    let (mut best, mut best_run, mut run) = (phases[0], 0, 0);
    for (k, &ph) in phases.iter().enumerate() {
        run = if k > 0 && phases[k - 1] == ph { run + 1 } else { 1 };
        if run > best_run {
            (best, best_run) = (ph, run);
        }
    }
    [weight as f32, f32::from_bits(best)]
}

/// The triangles `keep` picks from `p`, with only the vertices they use (in first-use order).
fn subset(p: &Primitive, keep: impl Fn(usize) -> bool) -> Primitive {
    let mut remap = vec![u32::MAX; p.positions.len()];
    let mut out = Primitive { material: p.material, ..Primitive::default() };
    for t in (0..p.triangle_count()).filter(|&t| keep(t)) {
        for k in 0..3 {
            let i = p.indices[3 * t + k] as usize;
            if remap[i] == u32::MAX {
                remap[i] = out.positions.len() as u32;
                out.positions.push(p.positions[i]);
                if let Some(n) = p.normals.get(i) {
                    out.normals.push(*n);
                }
                if let Some(uv) = p.uvs.get(i) {
                    out.uvs.push(*uv);
                }
                if let Some(t) = p.tangents.get(i) {
                    out.tangents.push(*t);
                }
                if let Some(c) = p.colors.get(i) {
                    out.colors.push(*c);
                }
                for (k, c) in p.custom.iter().enumerate() {
                    if out.custom.len() <= k {
                        out.custom.push(CustomAttribute { name: c.name.clone(), values: Vec::new() });
                    }
                    if let Some(v) = c.values.get(i) {
                        out.custom[k].values.push(*v);
                    }
                }
            }
            out.indices.push(remap[i]);
        }
    }
    out
}

/// meshoptimizer's edge-collapse simplification of every primitive to about `ratio` of its
/// triangles (never past `max_error` of the extent), zero-area results dropped, then reordered for
/// the vertex cache and fetch.
fn simplify(mesh: &Mesh, ratio: f64, max_error: f32) -> Mesh {
    let mut out = Mesh { name: mesh.name.clone(), primitives: Vec::new(), extras: None };
    for p in &mesh.primitives {
        // point leaves stay as they are (a point is already as cheap as it gets)
        if p.is_points() {
            out.primitives.push(p.clone());
            continue;
        }
        let bytes = meshopt::typed_to_bytes(&p.positions);
        let Ok(adapter) = meshopt::VertexDataAdapter::new(bytes, 12, 0) else {
            out.primitives.push(p.clone());
            continue;
        };
        let target = ((p.indices.len() as f64 * ratio) as usize / 3) * 3;
        let indices = meshopt::simplify(&p.indices, &adapter, target, max_error, meshopt::SimplifyOptions::None, None);
        if let Some(q) = simplified(p, &indices) {
            out.primitives.push(q);
        }
    }
    out
}

/// `p` with the triangles `indices` (those of zero area dropped), its unused vertices removed and
/// reordered for the vertex cache and fetch; `None` when no triangle is left.
fn simplified(p: &Primitive, indices: &[u32]) -> Option<Primitive> {
    let kept: Vec<u32> =
        indices.chunks_exact(3).filter(|t| !is_flat(&p.positions, [t[0], t[1], t[2]])).flatten().copied().collect();
    if kept.is_empty() {
        return None;
    }
    // compact first: Primitive::optimize_for_gpu assumes every vertex is used (meshopt's fetch
    // remap is as long as the used vertices, not all of them)
    let mut q = subset(&Primitive { indices: kept, ..p.clone() }, |_| true);
    q.optimize_for_gpu();
    Some(q)
}

/// The triangles of branch levels above `max_kept` (what LoD2 drops), per primitive.
fn finer_than(tree: &TreeMesh, max_kept: u32) -> Mesh {
    let mesh = tree.mesh();
    let mut out = Mesh { name: String::new(), primitives: Vec::new(), extras: None };
    for (p, ranges) in mesh.primitives.iter().zip(&tree.levels) {
        let Some(k) = ranges.levels.iter().position(|&l| l > max_kept) else { continue };
        let first = ranges.index_starts[k] as usize / 3;
        let q = subset(p, |t| t >= first);
        if !q.indices.is_empty() {
            out.primitives.push(q);
        }
    }
    out
}

/// A cluster of dropped geometry and where its card stands.
struct Cluster {
    mesh: Mesh,
    centre: DVec3,
    side_m: f64,
}

/// [`simplify`] with the smallest error bound of SIMPLIFY_MAX_ERRORS that leaves fewer than
/// `below` triangles (the largest bound's result when none does).
fn simplify_below(mesh: &Mesh, ratio: f64, below: usize) -> Mesh {
    let mut out = Mesh::default();
    for max_error in SIMPLIFY_MAX_ERRORS {
        out = simplify(mesh, ratio, max_error);
        if out.triangle_count() < below {
            break;
        }
    }
    out
}

/// meshoptimizer's sloppy (vertex-clustering) decimation of every triangle primitive to about
/// `ratio` of its triangles (more when that would erase the primitive): no topology kept, so it
/// reaches targets edge collapse cannot; zero-area results dropped, then reordered for the vertex
/// cache and fetch.
fn simplify_sloppy(mesh: &Mesh, ratio: f64) -> Mesh {
    let mut out = Mesh { name: mesh.name.clone(), primitives: Vec::new(), extras: None };
    for p in mesh.primitives.iter().filter(|p| !p.is_points()) {
        let bytes = meshopt::typed_to_bytes(&p.positions);
        let Ok(adapter) = meshopt::VertexDataAdapter::new(bytes, 12, 0) else { continue };
        // vertex clustering can erase a thin part (a trunk, a card) entirely: then ask for more
        let mut r = ratio;
        while r < 1.0 {
            let target = ((p.indices.len() as f64 * r) as usize / 3).max(1) * 3;
            if let Some(q) = simplified(p, &meshopt::simplify_sloppy(&p.indices, &adapter, target, 1.0, None)) {
                out.primitives.push(q);
                break;
            }
            r *= 2.0;
        }
    }
    out
}

/// Groups `dropped` by a uniform n³ grid over its triangles' centroids, n the largest of 8…1 that
/// leaves at most `max_clusters` occupied cells (none when 0); clusters in cell order (deterministic).
fn clusters(dropped: &Mesh, max_clusters: usize) -> Vec<Cluster> {
    let centroid = |p: &Primitive, t: usize| {
        (0..3).map(|k| DVec3::from(p.positions[p.indices[3 * t + k] as usize].map(f64::from))).sum::<DVec3>() / 3.0
    };
    let all: Vec<DVec3> =
        dropped.primitives.iter().flat_map(|p| (0..p.triangle_count()).map(move |t| centroid(p, t))).collect();
    if all.is_empty() || max_clusters == 0 {
        return Vec::new();
    }
    let (lo, hi) =
        all.iter().fold((DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)), |(lo, hi), &c| (lo.min(c), hi.max(c)));
    let extent = (hi - lo).max(DVec3::splat(1e-9));
    let cell_of = |c: DVec3, n: usize| {
        let r = (c - lo) / extent * n as f64;
        let f = |v: f64| (v.floor().max(0.0) as usize).min(n - 1);
        (f(r.z) * n + f(r.y)) * n + f(r.x)
    };
    let mut n = 8;
    let mut cells: Vec<usize>;
    loop {
        cells = all.iter().map(|&c| cell_of(c, n)).collect();
        let mut occupied = cells.clone();
        occupied.sort_unstable();
        occupied.dedup();
        if occupied.len() <= max_clusters || n == 1 {
            break;
        }
        n -= 1;
    }
    let mut ids: Vec<usize> = cells.clone();
    ids.sort_unstable();
    ids.dedup();
    let mut out = Vec::with_capacity(ids.len());
    for id in ids {
        let mut mesh = Mesh::default();
        let mut serial = 0;
        for p in &dropped.primitives {
            let start = serial;
            let q = subset(p, |t| cells[start + t] == id);
            serial += p.triangle_count();
            if !q.indices.is_empty() {
                mesh.primitives.push(q);
            }
        }
        let (lo, hi) = mesh.primitives.iter().flat_map(|p| &p.positions).fold(
            (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
            |(lo, hi), v| {
                let v = DVec3::from(v.map(f64::from));
                (lo.min(v), hi.max(v))
            },
        );
        let side_m = (hi - lo).max_element().max(1e-3) * 1.02;
        out.push(Cluster { mesh, centre: (lo + hi) / 2.0, side_m });
    }
    out
}

/// One level of the chain as its own file holds it.
#[derive(Debug, Clone)]
pub struct TreeLod {
    pub level: usize,
    /// What it is: "full", "simplified", "cards", "billboards", "impostor".
    pub kind: &'static str,
    pub scene: Scene,
    /// `scene.textures` decoded, same order (what the analyzer draws with).
    pub images: Vec<Image>,
}

impl TreeLod {
    pub fn triangles(&self) -> usize {
        self.scene.meshes.iter().map(Mesh::triangle_count).sum()
    }
}

/// Figures of one level.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TreeLodFigures {
    pub level: usize,
    /// The level's [`TreeLod::kind`].
    pub kind: String,
    pub triangles: usize,
    pub vertices: usize,
    /// Size of `<name>_LOD<n>.glb`.
    pub bytes: usize,
    /// One-sided Hausdorff distance LoD_k → LoD0 (sampled; masked texels excluded).
    pub geometric_error: HausdorffError,
    /// Worst over 8 azimuths × 3 elevations at the nearest measured distance and at the switch.
    pub near_distance_m: f64,
    pub near_iou: f64,
    pub near_color_rmse: f64,
    pub switch_iou: f64,
    pub switch_color_rmse: f64,
    /// Distance (eye to the bounding-sphere centre) from which the silhouette error stays ≤ 1 px
    /// (1920 px wide, 60°); raised to the previous level's where it was nearer.
    pub switch_distance_m: f64,
    pub never_passes: bool,
    /// MSFT_lod screen coverage at the switch distance.
    pub screen_coverage: f64,
    pub measured: Vec<DistanceError>,
}

/// One row of the speed/error table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpeedErrorRow {
    pub level: usize,
    pub triangles: usize,
    pub bytes: usize,
    pub hausdorff_max_m: f64,
    pub worst_iou_at_switch: f64,
    pub switch_distance_m: f64,
    /// Triangles relative to LoD0 (what the level saves the GPU).
    pub triangle_ratio: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TreeLodReport {
    pub name: String,
    pub seed: u64,
    pub atlas_px: u32,
    pub bounding_radius_m: f64,
    pub clusters: usize,
    /// Branch levels LoD2 drops (finest first); empty when the tree has one level.
    pub dropped_levels: Vec<u32>,
    /// Levels built but left out because they saved nothing over the level before (the written
    /// chain is renumbered, so `lods` and the files stay contiguous).
    pub left_out: Vec<LeftOutLevel>,
    pub lods: Vec<TreeLodFigures>,
    pub table: Vec<SpeedErrorRow>,
    pub atlas_mips: Vec<MipFigures>,
    pub seconds_meshes: f64,
    pub seconds_bake: f64,
    pub seconds_analyze: f64,
    pub raster_fragments: u64,
}

/// Everything one tree's chain writes.
#[derive(Debug, Clone)]
pub struct TreeLods {
    pub name: String,
    pub levels: Vec<TreeLod>,
    /// `<name>.glb`: LoD0 with MSFT_lod to the coarser levels.
    pub chain: Scene,
    pub atlas: Vec<MipLevel>,
    /// The atlas' normals (glTF tangent-space normal map, level 0: engines make its mips), which
    /// the card levels' material samples as normalTexture.
    pub normal_atlas: Option<Image>,
    pub impostor_cells: Vec<AtlasCell>,
    pub report: TreeLodReport,
    /// The L-system tree LoD0 shows (None for a mesh asset).
    pub lod0: Option<TreeMesh>,
}

fn decode(textures: &[Texture]) -> Result<Vec<Image>, TreeLodError> {
    textures
        .iter()
        .map(|t| Image::from_png(&t.png).map_err(|e| TreeLodError::Texture(format!("{}: {e}", t.name))))
        .collect()
}

fn single_mesh_scene(name: &str, mesh: Mesh, materials: Vec<Material>, textures: Vec<Texture>) -> Scene {
    let mut scene = Scene { name: name.into(), materials, textures, ..Scene::default() };
    scene.add_mesh_node(Mesh { name: name.into(), ..mesh });
    scene
}

/// The cards' material: the colour atlas, lit through the normal atlas (`texture + 1`).
fn atlas_material(texture: usize) -> Material {
    Material {
        name: "tree_atlas".into(),
        base_color_texture: Some(texture),
        normal_texture: Some(texture + 1),
        roughness: 0.8,
        alpha_mode: AlphaMode::Mask { cutoff: ATLAS_ALPHA_CUTOFF },
        double_sided: true,
        ..Material::default()
    }
}

/// `mesh` turned by `angle_deg` about the vertical axis through `axis` (positions and normals).
fn rotated(mesh: &Mesh, axis: DVec3, angle_deg: f64) -> Mesh {
    let q = glam::DQuat::from_rotation_y(angle_deg.to_radians());
    let mut out = mesh.clone();
    for p in &mut out.primitives {
        for v in &mut p.positions {
            *v = (axis + q * (DVec3::from(v.map(f64::from)) - axis)).as_vec3().to_array();
        }
        for n in &mut p.normals {
            *n = (q * DVec3::from(n.map(f64::from))).as_vec3().to_array();
        }
    }
    out
}

/// Worst (and mean) over several measurements at one distance.
fn merged(rows: Vec<DistanceError>) -> Option<DistanceError> {
    let n = rows.len() as f64;
    let first = rows.first()?.clone();
    Some(DistanceError {
        distance_m: first.distance_m,
        worst_iou: rows.iter().map(|r| r.worst_iou).fold(f64::INFINITY, f64::min),
        mean_iou: rows.iter().map(|r| r.mean_iou).sum::<f64>() / n,
        worst_color_rmse: rows.iter().map(|r| r.worst_color_rmse).fold(0.0, f64::max),
        mean_color_rmse: rows.iter().map(|r| r.mean_color_rmse).sum::<f64>() / n,
        worst_edge_error_px: rows.iter().map(|r| r.worst_edge_error_px).fold(0.0, f64::max),
        mean_edge_error_px: rows.iter().map(|r| r.mean_edge_error_px).sum::<f64>() / n,
        passes: rows.iter().all(|r| r.passes),
        canvas_px: rows.iter().map(|r| r.canvas_px).max().unwrap_or([0, 0]),
        screen_px_per_rendered_px: rows.iter().map(|r| r.screen_px_per_rendered_px).fold(1.0, f64::max),
    })
}

/// A level's mesh with the materials and textures it refers to.
struct LevelParts {
    mesh: Mesh,
    materials: Vec<Material>,
    textures: Vec<Texture>,
}

/// How LoD2 is made from its source.
// one value per chain build: boxing the larger variant would buy nothing
#[allow(clippy::large_enum_variant)]
enum CoarseLevel {
    /// Trees: `kept` (the coarser branch levels of the LoD1 build) simplified below LoD1, plus
    /// crossed cards baked from the clusters of `dropped` (the finest level of the reference).
    Cards { kept: LevelParts, dropped: Mesh, dropped_levels: Vec<u32> },
    /// Meshes: LoD0 decimated much harder than LoD1 (meshoptimizer's sloppy simplifier, about
    /// SLOPPY_RATIO of the triangles, halved until below LoD1).
    Sloppy,
}

/// Everything the generic chain builder needs from a tree or a mesh asset.
struct ChainInput<'a> {
    name: String,
    /// Seeds the Hausdorff sampling.
    seed: u64,
    lod0: LevelParts,
    /// What the atlas is baked from and every level measured against: LoD0 itself, or for a tree
    /// with point leaves the same tree with quad leaves (points are not rasterised).
    reference: &'a Mesh,
    reference_materials: &'a [Material],
    reference_textures: &'a [Texture],
    lod1: Option<LevelParts>,
    coarse: CoarseLevel,
    started: Instant,
}

/// LoD2 of a mesh asset keeps about this fraction of LoD0's triangles.
pub const SLOPPY_RATIO: f64 = 0.1;

/// Builds the LoD chain of `system`'s tree, bakes its atlas and measures every level.
///
/// With `tree_options.leaf_points`, LoD0 and LoD1 draw leaves as points; the atlases, LoD2's cards
/// and the analyzer's reference use the same tree with quad leaves (a rasteriser does not draw
/// sprites), so the coarser levels look like those of the quad-leaf tree.
pub fn build_tree_lods(
    system: &LSystem,
    tree_options: &TreeOptions,
    options: &TreeLodOptions,
) -> Result<TreeLods, TreeLodError> {
    options.check()?;
    let started = Instant::now();
    let lod0 = build_tree(system, tree_options)?;
    let quads = if tree_options.leaf_points {
        Some(build_tree(system, &TreeOptions { leaf_points: false, ..tree_options.clone() })?)
    } else {
        None
    };
    let reference = quads.as_ref().unwrap_or(&lod0);
    let wanted = options.lods;
    let lod0_triangles = lod0.mesh().triangle_count();
    let half = if wanted > 1 {
        Some(build_tree(
            system,
            &TreeOptions { radial_segments: (tree_options.radial_segments / 2).max(3), ..tree_options.clone() },
        )?)
    } else {
        None
    };
    let lod1 = half.as_ref().map(|half| LevelParts {
        mesh: simplify_below(half.mesh(), SIMPLIFY_RATIO, lod0_triangles),
        materials: half.scene.materials.clone(),
        textures: half.scene.textures.clone(),
    });
    let max_level = lod0.stats.max_branch_level;
    let coarse = match &half {
        Some(half) if max_level > 0 && wanted > 2 => CoarseLevel::Cards {
            kept: LevelParts {
                mesh: half.up_to_level(max_level - 1),
                materials: half.scene.materials.clone(),
                textures: half.scene.textures.clone(),
            },
            dropped: finer_than(reference, max_level - 1),
            dropped_levels: vec![max_level],
        },
        Some(half) => CoarseLevel::Cards {
            kept: LevelParts {
                mesh: half.mesh().clone(),
                materials: half.scene.materials.clone(),
                textures: half.scene.textures.clone(),
            },
            dropped: Mesh::default(),
            dropped_levels: Vec::new(),
        },
        None => CoarseLevel::Sloppy,
    };
    let input = ChainInput {
        name: tree_options.name.clone(),
        seed: tree_options.seed,
        lod0: LevelParts {
            mesh: lod0.mesh().clone(),
            materials: lod0.scene.materials.clone(),
            textures: lod0.scene.textures.clone(),
        },
        reference: reference.mesh(),
        reference_materials: &reference.scene.materials,
        reference_textures: &reference.scene.textures,
        lod1,
        coarse,
        started,
    };
    let (name, levels, chain, atlas, normal_atlas, impostor_cells, report) = build_chain(input, options)?;
    Ok(TreeLods { name, levels, chain, atlas, normal_atlas, impostor_cells, report, lod0: Some(lod0) })
}

/// Builds the LoD chain of a loaded mesh (an OBJ tree or rock): LoD0 the mesh, LoD1 meshoptimizer
/// simplification to about half, LoD2 sloppy decimation to about a tenth (strictly fewer triangles
/// than LoD1), LoD3 crossed billboards and LoD4 the impostor from the atlas baked from LoD0; every
/// level measured as a tree's. `name` names the meshes, nodes and atlas inside the files.
pub fn build_mesh_lods(source: &SourceMesh, name: &str, options: &TreeLodOptions) -> Result<TreeLods, TreeLodError> {
    options.check()?;
    let started = Instant::now();
    let mesh = source.mesh();
    if mesh.triangle_count() == 0 {
        return Err(TreeLodError::Options(format!("{name}: the mesh has no triangles")));
    }
    let lod1 = (options.lods > 1).then(|| LevelParts {
        mesh: simplify_below(mesh, SIMPLIFY_RATIO, mesh.triangle_count()),
        materials: source.scene.materials.clone(),
        textures: source.scene.textures.clone(),
    });
    let input = ChainInput {
        name: name.to_string(),
        seed: mix64(source.stats.triangles as u64),
        lod0: LevelParts {
            mesh: mesh.clone(),
            materials: source.scene.materials.clone(),
            textures: source.scene.textures.clone(),
        },
        reference: mesh,
        reference_materials: &source.scene.materials,
        reference_textures: &source.scene.textures,
        lod1,
        coarse: CoarseLevel::Sloppy,
        started,
    };
    let (name, levels, chain, atlas, normal_atlas, impostor_cells, report) = build_chain(input, options)?;
    Ok(TreeLods { name, levels, chain, atlas, normal_atlas, impostor_cells, report, lod0: None })
}

type Chain = (String, Vec<TreeLod>, Scene, Vec<MipLevel>, Option<Image>, Vec<AtlasCell>, TreeLodReport);

/// The levels after LoD1, the atlas, the analyzer and the MSFT_lod scene, for any source.
fn build_chain(input: ChainInput, options: &TreeLodOptions) -> Result<Chain, TreeLodError> {
    let ChainInput { name, seed, lod0, reference, reference_materials, reference_textures, lod1, coarse, started } =
        input;
    let images0 = decode(&lod0.textures)?;
    let reference_images = decode(reference_textures)?;
    let materials0 = reference_materials.to_vec();
    let wanted = options.lods;
    let card_wind = CardWind::of(&lod0.mesh);
    let mut levels = vec![TreeLod {
        level: 0,
        kind: "full",
        scene: single_mesh_scene(&format!("{name}_LOD0"), lod0.mesh, lod0.materials, lod0.textures),
        images: images0,
    }];
    let lod1_source = lod1.as_ref().map(|l| (l.materials.clone(), l.textures.clone()));
    if let Some(lod1) = lod1 {
        // a model too small to simplify (a 12-triangle box) keeps LoD0's mesh here: the level then
        // saves nothing and is left out of the written chain, which goes on to the card levels
        let (mesh, materials, textures) = if lod1.mesh.primitives.is_empty() {
            let lod0 = &levels[0].scene;
            (lod0.meshes[0].clone(), lod0.materials.clone(), lod0.textures.clone())
        } else {
            (lod1.mesh, lod1.materials, lod1.textures)
        };
        let images = decode(&textures)?;
        levels.push(TreeLod {
            level: 1,
            kind: "simplified",
            scene: single_mesh_scene(&format!("{name}_LOD1"), mesh, materials, textures),
            images,
        });
    }
    let seconds_meshes = started.elapsed().as_secs_f64();

    // the frame every model-wide view uses: a square around the vertical axis through the
    // footprint centre, the whole model inside
    let all_positions: Vec<[f32; 3]> = reference.primitives.iter().flat_map(|p| p.positions.iter().copied()).collect();
    let bounds = Bounds::of(&all_positions).ok_or(TreeError::Empty)?;
    let axis =
        DVec3::new((bounds.min[0] + bounds.max[0]) as f64 / 2.0, 0.0, (bounds.min[2] + bounds.max[2]) as f64 / 2.0);
    let reach = all_positions
        .iter()
        .map(|v| ((v[0] as f64 - axis.x).powi(2) + (v[2] as f64 - axis.z).powi(2)).sqrt())
        .fold(0.0, f64::max);
    let height = (bounds.max[1] - bounds.min[1]) as f64;
    let centre = DVec3::new(axis.x, (bounds.min[1] + bounds.max[1]) as f64 / 2.0, axis.z);
    let tree_side = (2.0 * reach).max(height).max(1e-3) * 1.02;
    let tree_frame =
        |k: usize| CardFrame { centre, azimuth_deg: k as f64 * 360.0 / IMPOSTOR_VIEWS as f64, side_m: tree_side };
    let radius = all_positions.iter().map(|v| (DVec3::from(v.map(f64::from)) - centre).length()).fold(0.0, f64::max);
    drop(all_positions);

    // bake: the impostor views (LoD3 reuses the first four), then two views per leaf cluster
    let bake_started = Instant::now();
    let px = options.atlas_px;
    let (dropped_levels, groups) = match &coarse {
        CoarseLevel::Cards { dropped, dropped_levels, .. } if !dropped_levels.is_empty() => {
            // cards take at most half of LoD1's triangle count (4 triangles a card)
            let max_clusters = levels.get(1).map_or(0, |l| (l.triangles() / 8).min(MAX_CLUSTERS));
            (dropped_levels.clone(), clusters(dropped, max_clusters))
        }
        _ => (Vec::new(), Vec::new()),
    };
    let impostor_cells: Vec<AtlasCell> = (0..IMPOSTOR_VIEWS).map(|k| AtlasCell::large(px, k)).collect();
    let mut jobs: Vec<(AtlasCell, CardFrame, &Mesh)> = Vec::new();
    if wanted > 2 {
        for (k, cell) in impostor_cells.iter().enumerate() {
            jobs.push((*cell, tree_frame(k), reference));
        }
        for (c, g) in groups.iter().enumerate() {
            for side in 0..2 {
                let frame = CardFrame { centre: g.centre, azimuth_deg: 90.0 * side as f64, side_m: g.side_m };
                jobs.push((AtlasCell::small(px, 2 * c + side), frame, &g.mesh));
            }
        }
    }
    let rendered: Vec<Result<(Image, u64), RasterError>> = jobs
        .par_iter()
        .map(|(cell, frame, mesh)| bake(frame, cell.inner_px(), mesh, &materials0, &reference_images, Shading::Unlit))
        .collect();
    // the same views as normals in each card's frame: the normal atlas lit cards sample
    let normals: Vec<Result<(Image, u64), RasterError>> = jobs
        .par_iter()
        .map(|(cell, frame, mesh)| {
            bake(frame, cell.inner_px(), mesh, &materials0, &reference_images, Shading::card_normals(&frame.ortho(1)))
        })
        .collect();
    let mut normal_atlas = Image { width: px, height: px, pixels: vec![FLAT_NORMAL; (px as usize) * (px as usize)] };
    for ((cell, _, _), r) in jobs.iter().zip(normals) {
        normal_atlas.blit(&r?.0, cell.x + ATLAS_GUTTER_PX, cell.y + ATLAS_GUTTER_PX);
    }
    let mut atlas = Image { width: px, height: px, pixels: vec![[0.0; 4]; (px as usize) * (px as usize)] };
    let mut fragments = 0;
    for ((cell, _, _), r) in jobs.iter().zip(rendered) {
        let (img, f) = r?;
        fragments += f;
        atlas.blit(&img, cell.x + ATLAS_GUTTER_PX, cell.y + ATLAS_GUTTER_PX);
    }
    let atlas_chain = if wanted > 2 {
        dilate(&mut atlas, ATLAS_ALPHA_CUTOFF);
        mip_chain(&atlas, ATLAS_ALPHA_CUTOFF)
    } else {
        Vec::new()
    };
    let normal_atlas = (wanted > 2).then(|| finish_normal_atlas(normal_atlas));
    let seconds_bake = bake_started.elapsed().as_secs_f64();

    // the textured levels
    let atlas_texture = match atlas_chain.first() {
        Some(level0) => Some(Texture {
            name: format!("{name}_atlas"),
            png: level0.image.encode_png().map_err(|e| TreeLodError::Texture(e.to_string()))?,
        }),
        None => None,
    };
    let normal_texture = match &normal_atlas {
        Some(img) => Some(Texture {
            name: format!("{name}_atlas_normal"),
            png: img.encode_png_data().map_err(|e| TreeLodError::Texture(e.to_string()))?,
        }),
        None => None,
    };
    if let (Some((lod1_materials, lod1_textures)), Some(atlas_tex), Some(atlas0), Some(normal_tex), Some(normal_img)) =
        (&lod1_source, &atlas_texture, atlas_chain.first(), &normal_texture, &normal_atlas)
    {
        let lod1_triangles = levels[1].triangles();
        let (mesh, materials, textures, images) = match &coarse {
            CoarseLevel::Cards { kept, .. } => {
                // LoD2: the coarser branch levels simplified, plus the cards; simplified harder
                // until it has fewer triangles than LoD1
                let mut cards = Primitive::default();
                for (c, g) in groups.iter().enumerate() {
                    let branch = branch_of(&g.mesh);
                    for side in 0..2 {
                        let frame = CardFrame { centre: g.centre, azimuth_deg: 90.0 * side as f64, side_m: g.side_m };
                        let quad = frame.quad(AtlasCell::small(px, 2 * c + side).uv);
                        cards = appended(cards, &card_wind.map_or(quad.clone(), |w| w.on(quad, Some(branch))));
                    }
                }
                let below = lod1_triangles.saturating_sub(cards.triangle_count());
                let mut ratio = SIMPLIFY_RATIO;
                let mut mesh = simplify_below(&kept.mesh, ratio, below);
                while mesh.triangle_count() >= below && ratio > 0.01 {
                    ratio /= 2.0;
                    mesh = simplify_below(&kept.mesh, ratio, below);
                }
                let mut materials = kept.materials.clone();
                let mut textures = kept.textures.clone();
                let mut images = decode(&textures)?;
                if !cards.indices.is_empty() {
                    textures.push(atlas_tex.clone());
                    images.push(atlas0.image.clone());
                    materials.push(atlas_material(textures.len() - 1));
                    textures.push(normal_tex.clone());
                    images.push(normal_img.clone());
                    cards.material = Some(materials.len() - 1);
                    mesh.primitives.push(cards);
                }
                (mesh, materials, textures, images)
            }
            CoarseLevel::Sloppy => {
                let lod0_mesh = &levels[0].scene.meshes[0];
                let mut ratio = SLOPPY_RATIO;
                let mut mesh = simplify_sloppy(lod0_mesh, ratio);
                while mesh.triangle_count() >= lod1_triangles && ratio > 1e-4 {
                    ratio /= 2.0;
                    mesh = simplify_sloppy(lod0_mesh, ratio);
                }
                if mesh.primitives.is_empty() {
                    // nothing left to decimate: LoD1's mesh, left out below as saving nothing
                    let lod1 = &levels[1].scene;
                    (lod1.meshes[0].clone(), lod1.materials.clone(), lod1.textures.clone(), levels[1].images.clone())
                } else {
                    (mesh, lod1_materials.clone(), lod1_textures.clone(), levels[1].images.clone())
                }
            }
        };
        levels.push(TreeLod {
            level: 2,
            kind: if matches!(coarse, CoarseLevel::Sloppy) { "decimated" } else { "cards" },
            scene: single_mesh_scene(&format!("{name}_LOD2"), mesh, materials, textures),
            images,
        });
        // LoD3: crossed billboards
        let mut planes = Primitive { material: Some(0), ..Primitive::default() };
        for (k, cell) in impostor_cells.iter().take(BILLBOARD_PLANES).enumerate() {
            let quad = tree_frame(k).quad(cell.uv);
            planes = appended(planes, &card_wind.map_or(quad.clone(), |w| w.on(quad, None)));
        }
        let mesh = Mesh { name: String::new(), primitives: vec![planes], extras: None };
        levels.push(TreeLod {
            level: 3,
            kind: "billboards",
            scene: single_mesh_scene(
                &format!("{name}_LOD3"),
                mesh,
                vec![atlas_material(0)],
                vec![atlas_tex.clone(), normal_tex.clone()],
            ),
            images: vec![atlas0.image.clone(), normal_img.clone()],
        });
        // LoD4: the impostor quad facing +Z (view 0), the others' cells in the extras
        let quad = tree_frame(0).quad(impostor_cells[0].uv);
        let quad = Primitive { material: Some(0), ..card_wind.map_or(quad.clone(), |w| w.on(quad, None)) };
        let extras = json!({ IMPOSTOR_EXTRAS_KEY: {
            "views": IMPOSTOR_VIEWS,
            "azimuth_step_deg": 360.0 / IMPOSTOR_VIEWS as f64,
            "view_from_direction": "k = round(atan2(dx, dz) / azimuth_step_deg) mod views, (dx, dz) from the centre to the eye",
            "face_camera_about": "y axis through centre",
            "centre": centre.to_array(),
            "size_m": tree_side,
            "cells_uv": impostor_cells.iter().map(|c| c.uv).collect::<Vec<_>>(),
        }});
        let mesh = Mesh { name: String::new(), primitives: vec![quad], extras: Some(extras) };
        let scene = single_mesh_scene(
            &format!("{name}_LOD4"),
            mesh,
            vec![atlas_material(0)],
            vec![atlas_tex.clone(), normal_tex.clone()],
        );
        levels.push(TreeLod {
            level: 4,
            kind: "impostor",
            scene,
            images: vec![atlas0.image.clone(), normal_img.clone()],
        });
    }
    levels.truncate(wanted);
    let (levels, left_out) = without_levels_that_save_nothing(&name, levels);

    // analyzer
    let analyze_started = Instant::now();
    let grid = TriangleGrid::new(reference);
    let view = options.policy.screen_view();
    let range = SwitchSearch { far_m: radius * 1024.0, near_m: radius * 2.0, bisections: 3 };
    let reference_view = Renderable { mesh: reference, materials: &materials0, textures: &reference_images };
    let mut lods = Vec::with_capacity(levels.len());
    for lod in &levels {
        let mesh = &lod.scene.meshes[0];
        let bytes = crate::export::gltf::to_glb(&lod.scene).map_err(|e| TreeLodError::Texture(e.0))?.len();
        let geometric_error = match (&grid, lod.level) {
            (Some(grid), n) if n > 0 => hausdorff(
                mesh,
                &lod.scene.materials,
                &lod.images,
                grid,
                options.hausdorff_samples,
                mix64(seed ^ n as u64),
            ),
            _ => HausdorffError::default(),
        };
        let mut f = TreeLodFigures {
            level: lod.level,
            kind: lod.kind.to_string(),
            triangles: lod.triangles(),
            vertices: mesh.vertex_count(),
            bytes,
            geometric_error,
            near_distance_m: 0.0,
            near_iou: 1.0,
            near_color_rmse: 0.0,
            switch_iou: 1.0,
            switch_color_rmse: 0.0,
            switch_distance_m: 0.0,
            never_passes: false,
            screen_coverage: 1.0,
            measured: Vec::new(),
        };
        if lod.level > 0 && options.analyze {
            let candidate = Renderable { mesh, materials: &lod.scene.materials, textures: &lod.images };
            let (rows, switch_m, never) = if lod.kind == "impostor" {
                // the engine shows view k from azimuth k·45°: turn the reference instead, and look
                // from azimuth 0 at each view's quad
                let turned: Vec<(Mesh, Mesh)> = impostor_cells
                    .iter()
                    .enumerate()
                    .map(|(k, cell)| {
                        let azimuth = k as f64 * 360.0 / IMPOSTOR_VIEWS as f64;
                        let quad = Primitive { material: Some(0), ..tree_frame(0).quad(cell.uv) };
                        (
                            rotated(reference, centre, -azimuth),
                            Mesh { name: String::new(), primitives: vec![quad], extras: None },
                        )
                    })
                    .collect();
                let one_azimuth = LodImageOptions { azimuths: 1, ..options.image.clone() };
                switch_search_by(&range, |d| {
                    let rows = turned
                        .iter()
                        .filter_map(|(r, c)| {
                            let r = Renderable { mesh: r, materials: &materials0, textures: &reference_images };
                            let c = Renderable { mesh: c, ..candidate };
                            lod_image_error_with(&r, &c, &view, &[d], &one_azimuth).distances.into_iter().next()
                        })
                        .collect();
                    merged(rows)
                })
            } else {
                switch_search(&reference_view, &candidate, &view, &options.image, &range)
            };
            if let Some(near) = rows.first() {
                f.near_distance_m = near.distance_m;
                f.near_iou = near.worst_iou;
                f.near_color_rmse = near.worst_color_rmse;
            }
            if let Some(at) = rows.iter().find(|d| d.distance_m >= switch_m) {
                f.switch_iou = at.worst_iou;
                f.switch_color_rmse = at.worst_color_rmse;
            }
            f.measured = rows;
            f.switch_distance_m = switch_m;
            f.never_passes = never;
            f.screen_coverage = options.policy.coverage_at_centre_distance(radius, switch_m);
        }
        lods.push(f);
    }
    // a coarser level never switches in before a finer one
    for n in 1..lods.len() {
        if lods[n].switch_distance_m < lods[n - 1].switch_distance_m {
            lods[n].switch_distance_m = lods[n - 1].switch_distance_m;
            lods[n].screen_coverage = options.policy.coverage_at_centre_distance(radius, lods[n].switch_distance_m);
        }
    }
    let seconds_analyze = analyze_started.elapsed().as_secs_f64();
    let lod0_triangles = lods[0].triangles.max(1) as f64;
    let table = lods
        .iter()
        .map(|l| SpeedErrorRow {
            level: l.level,
            triangles: l.triangles,
            bytes: l.bytes,
            hausdorff_max_m: l.geometric_error.max_m,
            worst_iou_at_switch: l.switch_iou,
            switch_distance_m: l.switch_distance_m,
            triangle_ratio: l.triangles as f64 / lod0_triangles,
        })
        .collect();
    let chain = chain_scene(&name, &levels, &lods);
    let report = TreeLodReport {
        name: name.clone(),
        seed,
        atlas_px: px,
        bounding_radius_m: radius,
        clusters: groups.len(),
        dropped_levels,
        left_out,
        lods,
        table,
        atlas_mips: mip_figures(&atlas_chain),
        seconds_meshes,
        seconds_bake,
        seconds_analyze,
        raster_fragments: fragments,
    };
    Ok((name, levels, chain, atlas_chain, normal_atlas, impostor_cells, report))
}

/// A level built but not written: it would have drawn no fewer triangles than the level before it
/// (a small tree's cards can outnumber its simplified branches), so an engine would gain nothing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LeftOutLevel {
    /// What it would have been ("cards", "billboards", …) and its number in the full chain.
    pub kind: String,
    pub planned_level: usize,
    pub triangles: usize,
    /// The triangles of the level before it in the written chain.
    pub previous_triangles: usize,
}

/// `levels` without those that are empty or draw no fewer triangles than the level kept before
/// them; the rest renumbered 0, 1, 2, … (files and names `_LOD<n>` stay contiguous).
fn without_levels_that_save_nothing(name: &str, levels: Vec<TreeLod>) -> (Vec<TreeLod>, Vec<LeftOutLevel>) {
    let mut kept: Vec<TreeLod> = Vec::with_capacity(levels.len());
    let mut left_out = Vec::new();
    for lod in levels {
        let empty = lod.scene.meshes.first().is_none_or(|m| m.primitives.is_empty());
        match kept.last().map(TreeLod::triangles) {
            Some(previous) if empty || lod.triangles() >= previous => {
                left_out.push(LeftOutLevel {
                    kind: lod.kind.to_string(),
                    planned_level: lod.level,
                    triangles: lod.triangles(),
                    previous_triangles: previous,
                });
            }
            _ => kept.push(lod),
        }
    }
    for (n, lod) in kept.iter_mut().enumerate() {
        if lod.level != n {
            let renamed = format!("{name}_LOD{n}");
            lod.level = n;
            lod.scene.name = renamed.clone();
            for mesh in &mut lod.scene.meshes {
                mesh.name = renamed.clone();
            }
            for node in &mut lod.scene.nodes {
                node.name = renamed.clone();
            }
        }
    }
    (kept, left_out)
}

/// `<name>.glb`: LoD0's node with MSFT_lod to the coarser levels' nodes (not roots) and
/// `MSFT_screencoverage` from the measured switch distances; equal textures stored once.
fn chain_scene(name: &str, levels: &[TreeLod], lods: &[TreeLodFigures]) -> Scene {
    let mut scene = Scene { name: name.into(), ..Scene::default() };
    let mut ids = Vec::new();
    for lod in levels {
        let src = &lod.scene;
        let texture_map: Vec<usize> = src
            .textures
            .iter()
            .map(|t| match scene.textures.iter().position(|u| u == t) {
                Some(i) => i,
                None => {
                    scene.textures.push(t.clone());
                    scene.textures.len() - 1
                }
            })
            .collect();
        let material_base = scene.materials.len();
        scene.materials.extend(src.materials.iter().map(|m| m.with_textures(|t| texture_map.get(t).copied())));
        let mut mesh = src.meshes[0].clone();
        for p in &mut mesh.primitives {
            p.material = p.material.map(|m| m + material_base);
        }
        scene.meshes.push(mesh);
        scene.nodes.push(Node { name: src.name.clone(), mesh: Some(scene.meshes.len() - 1), ..Node::default() });
        ids.push(scene.nodes.len() - 1);
    }
    let root = ids[0];
    scene.nodes[root].lods = ids[1..].to_vec();
    let mut coverage: Vec<f32> = lods.iter().skip(1).map(|l| l.screen_coverage as f32).collect();
    if !coverage.is_empty() {
        coverage.push(0.0);
    }
    scene.nodes[root].lod_screen_coverage = coverage;
    scene.roots.push(root);
    scene
}

// ---------------------------------------------------------------------------------------------
// the `verdant tree --lods N` job

/// One `verdant tree` run with a LoD chain: read, build each variant's chain, write, validate.
#[derive(Debug, Clone)]
pub struct TreeLodJob {
    pub input: PathBuf,
    /// `<dir>/<stem>.glb`: the chain; `<stem>_LOD<n>.glb` and `<stem>_atlas*.png` beside it
    /// (`<stem>_v<k>…` for variant k when there are several).
    pub output: PathBuf,
    pub dialect: Option<Dialect>,
    pub options: TreeOptions,
    pub lod: TreeLodOptions,
    /// Trees from seeds derived from `options.seed` (variant 0 uses the seed itself).
    pub variants: usize,
}

/// What `verdant tree --report` writes with a LoD chain: the LoD0 figures of variant 0 as
/// without one, then every variant's chain.
#[derive(Debug, Clone, Serialize)]
pub struct TreeLodRunReport {
    #[serde(flatten)]
    pub tree: TreeReport,
    pub variants: Vec<TreeLodReport>,
}

/// The seed of variant `k` (0: the seed itself).
pub fn variant_seed(seed: u64, k: usize) -> u64 {
    if k == 0 {
        seed
    } else {
        mix64(seed ^ mix64(k as u64))
    }
}

fn write_glb(scene: &Scene, path: &Path, files: &mut Vec<PathBuf>) -> Result<(usize, usize), TreeLodError> {
    export::write_scene(scene, path)?;
    let v = validate_file(path, &ValidateOptions::default())
        .map_err(|e| TreeLodError::Invalid { path: path.to_path_buf(), report: e.to_string() })?;
    if !v.ok() {
        return Err(TreeLodError::Invalid { path: path.to_path_buf(), report: v.to_string() });
    }
    files.push(path.to_path_buf());
    Ok((v.errors(), v.warnings()))
}

/// The files one run wrote and what validating them found.
#[derive(Debug, Default)]
struct Written {
    files: Vec<PathBuf>,
    errors: usize,
    warnings: usize,
}

/// Writes `chain` as `<dir>/<file_stem>_LOD<n>.glb`, `<file_stem>_atlas*.png` and the MSFT_lod
/// `<file_stem>.glb`, validating every glb.
fn write_chain(chain: &TreeLods, dir: &Path, file_stem: &str, written: &mut Written) -> Result<(), TreeLodError> {
    for lod in &chain.levels {
        let (e, w) = write_glb(&lod.scene, &dir.join(format!("{file_stem}_LOD{}.glb", lod.level)), &mut written.files)?;
        written.errors += e;
        written.warnings += w;
    }
    if !chain.atlas.is_empty() {
        let pngs = write_mip_pngs(dir, &format!("{file_stem}_atlas"), &chain.atlas)
            .map_err(|e| TreeLodError::Texture(e.to_string()))?;
        written.files.extend(pngs);
    }
    if let Some(normals) = &chain.normal_atlas {
        let path = dir.join(format!("{file_stem}_atlas_normal.png"));
        let png = normals.encode_png_data().map_err(|e| TreeLodError::Texture(e.to_string()))?;
        export::write_atomic(&path, &png).map_err(|e| TreeLodError::Texture(e.to_string()))?;
        written.files.push(path);
    }
    let (e, w) = write_glb(&chain.chain, &dir.join(format!("{file_stem}.glb")), &mut written.files)?;
    written.errors += e;
    written.warnings += w;
    Ok(())
}

/// A chain's output must be a .glb (it holds MSFT_lod).
fn check_glb_output(output: &Path) -> Result<(), TreeLodError> {
    let ext = output.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext != "glb" {
        return Err(TreeLodError::Options(format!(
            "{}: a LoD chain is written as .glb (MSFT_lod); use a .glb output or --lods 1",
            output.display()
        )));
    }
    Ok(())
}

/// Runs `job`: every file is built in memory before the first is written.
pub fn run_lods(job: &TreeLodJob) -> Result<TreeLodRunReport, TreeLodError> {
    let t0 = Instant::now();
    check_glb_output(&job.output)?;
    if !(1..=64).contains(&job.variants) {
        return Err(TreeLodError::Options(format!("--variants {} is out of range; use 1 to 64", job.variants)));
    }
    job.lod.check()?;
    let parsed = parse::read_file(&job.input, job.dialect).map_err(|e| TreeLodError::Tree(TreeError::Parse(e)))?;
    let t_parse = t0.elapsed().as_secs_f64();
    let stem = job.output.file_stem().and_then(|s| s.to_str()).unwrap_or("tree").to_string();
    let dir = job.output.parent().map(Path::to_path_buf).unwrap_or_default();
    // names inside the files come from the tree's name, file names from the output's stem, so the
    // same tree written under two names has the same bytes
    let suffix = |k: usize| if job.variants == 1 { String::new() } else { format!("_v{k}") };
    let mut chains = Vec::with_capacity(job.variants);
    for k in 0..job.variants {
        let options = TreeOptions {
            seed: variant_seed(job.options.seed, k),
            name: format!("{}{}", job.options.name, suffix(k)),
            ..job.options.clone()
        };
        let chain = build_tree_lods(&parsed.system, &options, &job.lod).map_err(|e| match e {
            TreeLodError::Tree(t) => {
                TreeLodError::Tree(TreeError::InFile { path: job.input.clone(), source: Box::new(t) })
            }
            e => e,
        })?;
        chains.push(chain);
    }
    let t_build = t0.elapsed().as_secs_f64();
    let mut written = Written::default();
    for (k, c) in chains.iter().enumerate() {
        write_chain(c, &dir, &format!("{stem}{}", suffix(k)), &mut written)?;
    }
    let Written { files, errors, warnings } = written;
    let t_total = t0.elapsed().as_secs_f64();
    let first = &chains[0];
    let tree = TreeReport {
        input: job.input.display().to_string(),
        output: job.output.display().to_string(),
        files: files.iter().map(|f| f.display().to_string()).collect(),
        dialect: parsed.system.dialect,
        dialect_detected: parsed.detected,
        seed: job.options.seed,
        radial_segments: job.options.radial_segments,
        stats: first.lod0.as_ref().map(|t| t.stats.clone()).unwrap_or_default(),
        warnings: parsed
            .warnings
            .into_iter()
            .chain(first.lod0.as_ref().and_then(|t| crate::plants::tree::size_warning(&t.stats, &job.options)))
            .collect(),
        validation_errors: errors,
        validation_warnings: warnings,
        seconds: TreeSeconds {
            parse: t_parse,
            build: first.report.seconds_meshes,
            export: t_total - t_build,
            to_lod0: t_parse + first.report.seconds_meshes,
            validate: 0.0,
            total: t_total,
        },
    };
    Ok(TreeLodRunReport { tree, variants: chains.into_iter().map(|c| c.report).collect() })
}

// ---------------------------------------------------------------------------------------------
// the `verdant mesh` job

/// One `verdant mesh` run: load an OBJ, build its chain, write and validate as `verdant tree` does.
#[derive(Debug, Clone)]
pub struct MeshLodJob {
    pub input: PathBuf,
    /// `<dir>/<stem>.glb`: the chain; `<stem>_LOD<n>.glb` and `<stem>_atlas*.png` beside it.
    pub output: PathBuf,
    pub obj: ObjOptions,
    pub lod: TreeLodOptions,
}

/// What `verdant mesh --report` writes.
#[derive(Debug, Clone, Serialize)]
pub struct MeshLodRunReport {
    pub input: String,
    pub output: String,
    pub files: Vec<String>,
    pub source: MeshAssetStats,
    pub validation_errors: usize,
    pub validation_warnings: usize,
    pub seconds_load: f64,
    pub seconds_total: f64,
    pub chain: TreeLodReport,
}

/// Runs `job`: every file is built in memory before the first is written. The names inside the
/// files come from the input's stem, the file names from the output's.
pub fn run_mesh_lods(job: &MeshLodJob) -> Result<MeshLodRunReport, TreeLodError> {
    let t0 = Instant::now();
    check_glb_output(&job.output)?;
    job.lod.check()?;
    let source = load_obj(&job.input, &job.obj)?;
    let seconds_load = t0.elapsed().as_secs_f64();
    let name = job.input.file_stem().and_then(|s| s.to_str()).unwrap_or("mesh").to_string();
    let chain = build_mesh_lods(&source, &name, &job.lod)?;
    let stem = job.output.file_stem().and_then(|s| s.to_str()).unwrap_or("mesh").to_string();
    let dir = job.output.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut written = Written::default();
    write_chain(&chain, &dir, &stem, &mut written)?;
    Ok(MeshLodRunReport {
        input: job.input.display().to_string(),
        output: job.output.display().to_string(),
        files: written.files.iter().map(|f| f.display().to_string()).collect(),
        source: source.stats,
        validation_errors: written.errors,
        validation_warnings: written.warnings,
        seconds_load,
        seconds_total: t0.elapsed().as_secs_f64(),
        chain: chain.report,
    })
}

/// Writes any serialisable report as pretty JSON (atomically).
pub fn write_json_report<T: Serialize>(path: &Path, report: &T) -> Result<(), TreeLodError> {
    let mut text = serde_json::to_string_pretty(report)
        .map_err(|e| TreeLodError::Options(format!("cannot serialise the report: {e}")))?;
    text.push('\n');
    export::write_atomic(path, text.as_bytes())?;
    Ok(())
}

/// Writes a report as pretty JSON (atomically).
pub fn write_lod_report(path: &Path, report: &TreeLodRunReport) -> Result<(), TreeLodError> {
    write_json_report(path, report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atlas_cells_do_not_overlap_and_stay_inside() {
        let px = 512;
        let mut cells: Vec<AtlasCell> = (0..8).map(|i| AtlasCell::large(px, i)).collect();
        cells.extend((0..2 * MAX_CLUSTERS).map(|j| AtlasCell::small(px, j)));
        for (i, a) in cells.iter().enumerate() {
            assert!(a.x + a.size <= px && a.y + a.size <= px);
            assert!(a.uv.iter().all(|u| (0.0..=1.0).contains(u)));
            for b in &cells[i + 1..] {
                let apart = a.x + a.size <= b.x || b.x + b.size <= a.x || a.y + a.size <= b.y || b.y + b.size <= a.y;
                assert!(apart, "{a:?} overlaps {b:?}");
            }
        }
    }

    #[test]
    fn card_quad_faces_its_viewer_and_maps_the_cell() {
        for az in [0.0, 45.0, 90.0, 200.0] {
            let f = CardFrame { centre: DVec3::new(1.0, 2.0, 3.0), azimuth_deg: az, side_m: 2.0 };
            let q = f.quad([0.25, 0.5, 0.5, 0.75]);
            let c = q.triangle_cross(0);
            let (toward, _) = f.axes();
            assert!(DVec3::from(c).dot(toward) > 0.0, "counter-clockwise seen from the viewer at {az}°");
            // the quad's corners land on the view's corners
            let v = f.ortho(100);
            let tl = v.to_pixel(q.positions[3].map(f64::from));
            let br = v.to_pixel(q.positions[1].map(f64::from));
            assert!(
                tl[0].abs() < 1e-3
                    && tl[1].abs() < 1e-3
                    && (br[0] - 100.0).abs() < 1e-3
                    && (br[1] - 100.0).abs() < 1e-3
            );
            assert!(tl[2] > 0.0 && br[2] > 0.0, "in front of the camera");
        }
    }
}
