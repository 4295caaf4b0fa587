//! The view stage: `scene.glb` as drawn from the preset's first `[[view]]` — every terrain chunk
//! at the level its distance selects, every placed instance at the level of its own distance
//! (its species' chain, as the plants stage wrote it), instances beyond their species' cull
//! distance left out — and, per view, what is drawn: triangles and draw calls against the same
//! scene at full detail.
//!
//! Inputs are the files the other stages wrote (terrain levels, species level files, placement
//! tables), read back, so a build after cached stages writes the same bytes. Instances of one
//! mesh at one level share one EXT_mesh_gpu_instancing node (one draw call per primitive), in
//! table order.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::export::{self, table};
use crate::mesh::{Instances, Mesh, Node, Scene};
use crate::scatter::surface::SurfaceIndex;
use crate::scene::cache::KeyBuilder;
use crate::scene::error::{SceneBuildError, StageError};
use crate::scene::impostor::{ImpostorViews, IMPOSTOR_VIEW_EXTRAS_KEY};
use crate::scene::pipeline::{Stage, StageJob};
use crate::scene::plants_stage::{PlantsStageReport, SpeciesChain};
use crate::scene::terrain_stage::LodInfo;
use crate::scene::view::{cull_distance, level_at, view_distance_factor, Camera, CullDistance};
use crate::scene::view_lod::{lod_scene, LodSpecies, LodTerrain};
use crate::scene::Preset;
use crate::validate::read_scene_dequantized;

fn fail(message: String) -> StageError {
    StageError::Failed { stage: "view", message }
}

/// Version of what the view stage writes for given inputs (part of its cache key, see
/// [`crate::scene::terrain_stage::TERRAIN_ALGORITHM_VERSION`]).
/// 2: the species' normal atlases are linear data. 3: the trees' switch distances from the joint
/// chain search (plants 11). 4: and from small views sampled more finely (plants 12). 5: cards
/// framed as billboards (plants 13). 6: the terrain chunks carry `_LAYER_WEIGHTS` (terrain 5). 7:
/// scene_lod.glb beside scene.glb. 8: the terrain chunks' normal maps and tangents (terrain 6). 9:
/// their snow layer from the scene's snow cover (terrain 7). 10: their soil layer, `_LAYER_WEIGHTS_1`
/// and `_SURFACE` (terrain 8). 11: impostor instances show the baked view facing the eye
/// (`<mesh>_view<k>`, scene/impostor.rs); trees' LoD1 rebuilt (plants 16); the image comparison
/// resolves 4 × 4 samples per pixel. 12: the terrain meshed in regions (terrain 9). 13: compact
/// scene files store the plants' wind as normalized bytes of its ranges (plants 20). 14: the
/// chunked terrain meshed in bands (terrain 10). 15: scene tiles (`[scene] tile`, alpine writes
/// them). 16: a tile takes whole placement tiles; its box from each species' reach. 17: the
/// report (and the cache entry's) holds the tiles' summary, not their index again (the same files).
pub const VIEW_ALGORITHM_VERSION: u32 = 17;

/// What one view draws.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ViewReport {
    pub camera: Camera,
    /// Switch and budget-derived cull distances are the reference screen's times this (times the
    /// instance's scale), see [`view_distance_factor`].
    pub distance_factor: f64,
    pub terrain: TerrainDraw,
    pub species: Vec<SpeciesDraw>,
    /// Drawn: terrain chunks at their levels plus every drawn instance's level triangles.
    pub triangles: u64,
    /// One per primitive of each terrain chunk and of each instanced (mesh, level) node.
    pub draw_calls: usize,
    /// The same scene at full detail: every placed instance at LoD0, the finest terrain, nothing
    /// culled (what scene.glb was before views).
    pub full_detail_triangles: u64,
    pub full_detail_draw_calls: usize,
    /// The view rendered with LoD against full detail (`--compare-full-detail`, first view only).
    #[serde(default)]
    pub image: Option<ImageComparison>,
}

/// How the view with LoD differs from the same view at full detail, rendered by the project's
/// rasterizer at `size_px` with `samples_per_pixel` samples resolved as anti-aliasing resolves them.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ImageComparison {
    pub size_px: [u32; 2],
    /// Samples per pixel (a square grid: 16 = 4 × 4), box-filtered in linear colour.
    #[serde(default = "one")]
    pub samples_per_pixel: u32,
    /// Share of pixels where some channel differs by more than `threshold` (linear 0..1).
    pub differing: f64,
    /// The same share over single samples: the render without anti-aliasing.
    #[serde(default)]
    pub differing_samples: f64,
    pub threshold: f32,
    pub color_rmse: f64,
    /// Why it was not rendered, when it was not (too many full-detail triangles).
    pub skipped: Option<String>,
    pub seconds: f64,
}

fn one() -> u32 {
    1
}

/// Most full-detail triangles `--compare-full-detail` renders.
/// The renders skip instances outside the view, so the cost is the triangles in view: alpine's
/// 3.09 G full-detail triangles compare in about 80 s on 2 cores (1.2 GB).
pub const MAX_COMPARE_TRIANGLES: u64 = 5_000_000_000;
/// Size of the compared images (pixels).
pub const COMPARE_SIZE_PX: [u32; 2] = [960, 540];
/// Samples per pixel of the comparison renders, per axis (4 × 4 = 16, box-filtered): the image a
/// viewer sees with anti-aliasing. Rendered with one sample, a leaf, twig or flower smaller than a
/// pixel is a whole pixel or none, so the full-detail reference itself speckles where a coarser level
/// or a cull draws its mean (demo: 1.63 % of single samples differ, 1.43 % of resolved pixels;
/// meadow 2.13 % against 1.19 %); both figures are reported.
pub const COMPARE_SAMPLES: u32 = 4;
/// A pixel differs when a channel moves by more than this (linear colour: about 8/255 in sRGB
/// mid-tones).
pub const COMPARE_THRESHOLD: f32 = 0.03;

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TerrainDraw {
    /// Chunks drawn at each level (finest first).
    pub chunks_per_level: Vec<usize>,
    pub triangles: u64,
    pub full_detail_triangles: u64,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SpeciesDraw {
    pub name: String,
    /// Rows of the placement table.
    pub placed: usize,
    pub drawn: usize,
    pub culled: usize,
    /// `None` for a species without meshes (placement tables only).
    pub cull: Option<CullDistance>,
    pub levels: Vec<LevelDraw>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct LevelDraw {
    pub level: usize,
    /// Reference-screen switch distance of each variant (m).
    pub switch_distance_m: Vec<f64>,
    pub instances: usize,
    pub triangles: u64,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ViewStageReport {
    pub scene_file: PathBuf,
    /// Bytes of scene.glb.
    pub scene_bytes: u64,
    /// scene_lod.glb: every chunk and tile as an MSFT_lod chain ([`crate::scene::view_lod`]);
    /// `None` with `[scene] lod_scene = false`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lod_scene_file: Option<PathBuf>,
    pub lod_scene_bytes: u64,
    /// `[scene] tile`: the scene in tiles and their index ([`crate::scene::view_tiles`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tiles: Option<crate::scene::view_tiles::SceneTilesReport>,
    /// The farthest any vertex of scene.glb, scene_lod.glb and the scene tiles lies from the mesh built
    /// (`[scene] compact`: 16-bit positions; 0 for f32), in the mesh's own frame (an instance's
    /// scale multiplies it): what storing them here moved them plus what their species files
    /// had (the view stage reads the species meshes back from those).
    #[serde(default)]
    pub quantization_m: f64,
    /// The same for the terrain's meshes alone, all on one grid over the terrain (seams closed):
    /// its vertices move up to this far in any direction, so in these files the terrain's vertical
    /// error may grow by this much times (1 + the steepest slope).
    #[serde(default)]
    pub terrain_quantization_m: f64,
    pub views: Vec<ViewReport>,
    pub seconds: f64,
}

impl ViewStageReport {
    pub fn files(&self) -> Vec<PathBuf> {
        let mut files = vec![self.scene_file.clone()];
        files.extend(self.lod_scene_file.clone());
        files.extend(self.tiles.iter().flat_map(|t| t.files()));
        files
    }
}

/// Cache key: the upstream stages' keys (terrain, plants, scatter) and the views and policy.
pub fn view_key(preset: &Preset, upstream: &[&str]) -> String {
    let mut k = KeyBuilder::new("view", VIEW_ALGORITHM_VERSION);
    for u in upstream {
        k.add(u.as_bytes()).add(b"|");
    }
    k.add(serde_json::to_string(&preset.lod).unwrap_or_default().as_bytes());
    k.add(serde_json::to_string(&preset.views).unwrap_or_default().as_bytes());
    crate::scene::plants_stage::add_compact(&mut k, preset);
    if let Some(t) = preset.scene.tile_m {
        k.add(b"tile=").add(&t.to_le_bytes());
    }
    if !preset.scene.lod_scene {
        k.add(b"lod_scene=false");
    }
    for s in &preset.species {
        k.add(s.rules.name.as_bytes()).add(serde_json::to_string(&s.cull_distance_m).unwrap_or_default().as_bytes());
    }
    k.finish()
}

/// The chain's variant that row `n` of `species`' table shows (its `variant` column through the
/// chain's `pick`); an error naming the table's line when the column names no variant.
pub(super) fn shown(
    species: &str,
    chain: &SpeciesChain,
    n: usize,
    row: &table::PlacementRow,
) -> Result<usize, StageError> {
    chain.shown(row.variant).ok_or_else(|| {
        fail(format!(
            "the placement table of `{species}`, row {n} (line {} of a CSV): variant {} is none of the species' {} (the \
             table and the plants do not match: rebuild the scene)",
            n + 2,
            row.variant,
            chain.pick.len().max(chain.variants.len())
        ))
    })
}

/// Files read once and shared; meshes, materials and textures appended once, equal textures
/// and materials stored once (every level file of a tree carries the same atlas).
pub(super) struct Assembler<'a> {
    pub(super) dir: &'a Path,
    /// Shared, not copied: the main terrain file is also held by the stage while it assembles.
    pub(super) files: BTreeMap<PathBuf, Arc<Scene>>,
    pub(super) scene: Scene,
    /// (file, mesh index in it) → mesh index in `scene`.
    pub(super) meshes: BTreeMap<(PathBuf, usize), usize>,
    /// (file, material index in it) → material index in `scene` (a terrain's ~1000 chunks share one
    /// material whose textures need not be compared again for each).
    materials: BTreeMap<(PathBuf, usize), usize>,
    /// (file, impostor mesh name, baked view) → its view's mesh in `scene` ([`ImpostorViews::mesh`]).
    pub(super) impostor_views: BTreeMap<(PathBuf, String, usize), usize>,
}

impl<'a> Assembler<'a> {
    pub(super) fn file(&mut self, rel: &Path) -> Result<&Scene, StageError> {
        Ok(self.shared(rel)?)
    }

    /// [`Assembler::file`] as a shared handle (no copy of the scene).
    pub(super) fn shared(&mut self, rel: &Path) -> Result<&Arc<Scene>, StageError> {
        if !self.files.contains_key(rel) {
            let path = self.dir.join(rel);
            let s = read_scene_dequantized(&path).map_err(|e| fail(format!("{}: {e}", path.display())))?;
            self.files.insert(rel.to_path_buf(), Arc::new(s));
        }
        Ok(&self.files[rel])
    }

    /// Material `index` of file `rel` (already read) with its textures, appended once; `None` when
    /// the file has no such material.
    fn material_of(&mut self, rel: &Path, index: usize) -> Option<usize> {
        let key = (rel.to_path_buf(), index);
        if let Some(&i) = self.materials.get(&key) {
            return Some(i);
        }
        let src = &self.files[rel];
        let m = src.materials.get(index)?;
        let mut map = BTreeMap::new();
        for i in m.textures() {
            if let Some(t) = src.textures.get(i) {
                let at = match self.scene.textures.iter().position(|o| o.png == t.png) {
                    Some(at) => at,
                    None => {
                        self.scene.textures.push(t.clone());
                        self.scene.textures.len() - 1
                    }
                };
                map.insert(i, at);
            }
        }
        let m = m.with_textures(|i| map.get(&i).copied());
        let at = match self.scene.materials.iter().position(|o| *o == m) {
            Some(at) => at,
            None => {
                self.scene.materials.push(m);
                self.scene.materials.len() - 1
            }
        };
        self.materials.insert(key, at);
        Some(at)
    }

    /// The mesh `index` of file `rel`, appended once; its index in the assembled scene.
    pub(super) fn mesh(&mut self, rel: &Path, index: usize) -> Result<usize, StageError> {
        self.append(rel, index, false)
    }

    /// [`Assembler::mesh`], moving the mesh's data out of the file read instead of copying it when
    /// nothing else holds that file: for meshes no later step reads from the file again (the terrain
    /// level files' chunks in scene_lod.glb, each appended once; on a world, 1.9 M triangles that were
    /// held twice). What stays in the file is the mesh's name.
    pub(super) fn mesh_moved(&mut self, rel: &Path, index: usize) -> Result<usize, StageError> {
        self.append(rel, index, true)
    }

    fn append(&mut self, rel: &Path, index: usize, take: bool) -> Result<usize, StageError> {
        if let Some(&i) = self.meshes.get(&(rel.to_path_buf(), index)) {
            return Ok(i);
        }
        self.shared(rel)?;
        let file = self.files.get_mut(rel).expect("read above");
        let taken = match Arc::get_mut(file).and_then(|s| s.meshes.get_mut(index)) {
            Some(m) if take => {
                let name = m.name.clone();
                Some(std::mem::replace(m, Mesh { name, ..Mesh::default() }))
            }
            _ => None,
        };
        let Some(mut mesh) = taken.or_else(|| self.files[rel].meshes.get(index).cloned()) else {
            return Err(fail(format!("{}: has no mesh #{index}", rel.display())));
        };
        for p in &mut mesh.primitives {
            p.material = p.material.and_then(|m| self.material_of(rel, m));
        }
        self.scene.meshes.push(mesh);
        let i = self.scene.meshes.len() - 1;
        self.meshes.insert((rel.to_path_buf(), index), i);
        Ok(i)
    }

    /// The baked views of mesh `name` of file `rel` when it is an impostor.
    fn impostor(&mut self, rel: &Path, name: &str) -> Result<Option<ImpostorViews>, StageError> {
        Ok(self.file(rel)?.meshes.iter().find(|m| m.name == name).and_then(ImpostorViews::of))
    }

    /// The impostor mesh `name` of file `rel` as baked view `k` shows it, appended once.
    fn impostor_view(&mut self, rel: &Path, name: &str, views: &ImpostorViews, k: usize) -> Result<usize, StageError> {
        let key = (rel.to_path_buf(), name.to_string(), k);
        if let Some(&i) = self.impostor_views.get(&key) {
            return Ok(i);
        }
        let base = self.mesh_named(rel, name)?;
        let mesh = views.mesh(&self.scene.meshes[base], k);
        self.scene.meshes.push(mesh);
        let i = self.scene.meshes.len() - 1;
        self.impostor_views.insert(key, i);
        Ok(i)
    }

    pub(super) fn new(dir: &'a Path) -> Assembler<'a> {
        Assembler {
            dir,
            files: BTreeMap::new(),
            scene: Scene::default(),
            meshes: BTreeMap::new(),
            materials: BTreeMap::new(),
            impostor_views: BTreeMap::new(),
        }
    }

    /// An empty scene over files already read.
    pub(super) fn with_files(dir: &'a Path, files: BTreeMap<PathBuf, Arc<Scene>>) -> Assembler<'a> {
        Assembler { files, ..Assembler::new(dir) }
    }

    pub(super) fn mesh_named(&mut self, rel: &Path, name: &str) -> Result<usize, StageError> {
        let index = self
            .file(rel)?
            .meshes
            .iter()
            .position(|m| m.name == name)
            .ok_or_else(|| fail(format!("{}: has no mesh named `{name}` (rebuild with --force)", rel.display())))?;
        self.mesh(rel, index)
    }
}

/// The terrain as the view stage draws it: the main mesh file's chunks and, per LoD level, the
/// file holding the same chunks at that level.
pub struct TerrainInput<'a> {
    pub main: &'a Path,
    pub lods: &'a [LodInfo],
}

fn first_mesh_file(files: &[PathBuf]) -> Option<&PathBuf> {
    files.iter().find(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("glb" | "gltf" | "obj")))
}

pub(super) fn mesh_bounds(m: &Mesh) -> Option<([f64; 3], [f64; 3])> {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &m.primitives {
        for v in &p.positions {
            for a in 0..3 {
                lo[a] = lo[a].min(v[a] as f64);
                hi[a] = hi[a].max(v[a] as f64);
            }
        }
    }
    (lo[0] <= hi[0]).then_some((lo, hi))
}

/// Rotates `v` by the unit quaternion `q` (x, y, z, w).
pub(super) fn rotate(q: [f32; 4], v: [f64; 3]) -> [f64; 3] {
    let [x, y, z, w] = q.map(|c| c as f64);
    let t = [2.0 * (y * v[2] - z * v[1]), 2.0 * (z * v[0] - x * v[2]), 2.0 * (x * v[1] - y * v[0])];
    [
        v[0] + w * t[0] + (y * t[2] - z * t[1]),
        v[1] + w * t[1] + (z * t[0] - x * t[2]),
        v[2] + w * t[2] + (x * t[1] - y * t[0]),
    ]
}

/// Where the view measures an instance's distance from: its chain's bounding-box centre, placed,
/// rotated and scaled like the instance (as f32, as scene.glb stores it).
pub fn instance_centre(row: &table::PlacementRow, centre_y_m: f64) -> [f64; 3] {
    let p = row.position.map(|v| v as f32 as f64);
    let up = rotate(row.rotation, [0.0, centre_y_m * row.scale[1] as f64, 0.0]);
    [p[0] + up[0], p[1] + up[1], p[2] + up[2]]
}

/// Runs the view stage into `scene_dir`: writes scene.glb for the first view and measures every
/// view.
pub fn run_view(
    preset: &Preset,
    terrain: &TerrainInput<'_>,
    plants: Option<&PlantsStageReport>,
    tables: &[(String, PathBuf)],
    scene_dir: &Path,
    compare_full_detail: bool,
    kept_tiles: Option<crate::scene::view_tiles::KeptTile<'_>>,
) -> Result<ViewStageReport, StageError> {
    let t0 = Instant::now();
    let mut asm = Assembler::new(scene_dir);
    let main = Arc::clone(asm.shared(terrain.main)?);
    // the surface only places the cameras: dropped before anything is assembled (1.7 M triangles
    // index into ~230 MB)
    let (cameras, extent): (Vec<Camera>, [f64; 4]) = {
        let parts: Vec<(&[[f32; 3]], &[u32])> =
            main.meshes.iter().flat_map(|m| m.primitives.iter().map(|p| (&p.positions[..], &p.indices[..]))).collect();
        let surface = SurfaceIndex::from_parts(&parts);
        let extent = surface.bounds();
        let cameras: Vec<Camera> = preset
            .views
            .iter()
            .map(|v| v.resolve(extent, |x, z| surface.height_at(x, z).map(|(h, _)| h)))
            .collect::<Result<_, _>>()
            .map_err(fail)?;
        (cameras, extent)
    };

    // terrain levels: per level, its file (same chunk layout as the main mesh) and switch distance
    let mut levels: Vec<(PathBuf, f64)> = Vec::new();
    for l in terrain.lods {
        if let Some(f) = first_mesh_file(&l.files) {
            levels.push((f.clone(), l.switch_distance_m));
        }
    }
    let chunked = !levels.is_empty()
        && levels.iter().try_fold(true, |ok, (f, _)| {
            Ok::<bool, StageError>(ok && asm.file(f)?.meshes.len() == main.meshes.len())
        })?;

    // placements and chains
    let chains: BTreeMap<&str, &SpeciesChain> =
        plants.map(|p| p.species.iter().map(|s| (s.name.as_str(), &s.chain)).collect()).unwrap_or_default();
    let mut rows_of: Vec<Vec<table::PlacementRow>> = Vec::with_capacity(preset.species.len());
    for s in &preset.species {
        let rel = tables
            .iter()
            .find(|(n, _)| *n == s.rules.name)
            .map(|(_, p)| p.clone())
            .unwrap_or_else(|| PathBuf::from("placements").join(format!("{}.csv", s.rules.name)));
        let path = scene_dir.join(&rel);
        rows_of.push(table::read_placements(&path).map_err(|e| fail(format!("{}: {e}", path.display())))?);
    }

    // full detail (first view, when compared): the main terrain, every row at its variant's LoD0
    let mut full = Assembler::new(scene_dir);
    if compare_full_detail {
        let mut children = Vec::new();
        for c in 0..main.meshes.len() {
            let mi = full.mesh(terrain.main, c)?;
            full.scene.nodes.push(Node { mesh: Some(mi), ..Node::default() });
            children.push(full.scene.nodes.len() - 1);
        }
        for (s, rows) in preset.species.iter().zip(&rows_of) {
            let Some(chain) = chains.get(s.rules.name.as_str()).filter(|c| !c.variants.is_empty()) else { continue };
            let mut groups: BTreeMap<usize, Instances> = BTreeMap::new();
            for (n, row) in rows.iter().enumerate() {
                let g = groups.entry(shown(&s.rules.name, chain, n, row)?).or_default();
                g.translations.push(row.position.map(|x| x as f32));
                g.rotations.push(row.rotation);
                g.scales.push(row.scale);
            }
            for (v, inst) in groups {
                let l0 = &chain.variants[v][0];
                let mi = full.mesh_named(&l0.file, &l0.mesh)?;
                full.scene.nodes.push(Node { mesh: Some(mi), instances: Some(inst.into()), ..Node::default() });
                children.push(full.scene.nodes.len() - 1);
            }
        }
        full.scene.nodes.push(Node { children, ..Node::default() });
        full.scene.roots.push(full.scene.nodes.len() - 1);
    }

    let mut reports = Vec::with_capacity(cameras.len());
    for (view_index, camera) in cameras.iter().enumerate() {
        let write = view_index == 0;
        let factor = view_distance_factor(camera, &preset.lod);

        // terrain: each chunk at the level its nearest point's distance selects
        let switch: Vec<f64> = std::iter::once(0.0).chain(levels.iter().skip(1).map(|(_, d)| *d)).collect();
        let mut chunks_per_level = vec![0usize; levels.len().max(1)];
        let (mut t_tris, mut t_full, mut t_calls) = (0u64, 0u64, 0usize);
        let mut terrain_children = Vec::new();
        for (c, m) in main.meshes.iter().enumerate() {
            t_full += m.triangle_count() as u64;
            let level = match (chunked, mesh_bounds(m)) {
                (true, Some((lo, hi))) => level_at(camera.distance_to_box(lo, hi), &switch, factor),
                _ => 0,
            };
            chunks_per_level[level] += 1;
            let (file, index) = if chunked { (levels[level].0.clone(), c) } else { (terrain.main.to_path_buf(), c) };
            let mesh = &asm.file(&file)?.meshes[index];
            t_tris += mesh.triangle_count() as u64;
            t_calls += mesh.primitives.len();
            if write {
                let mi = asm.mesh(&file, index)?;
                asm.scene.nodes.push(Node {
                    name: asm.scene.meshes[mi].name.clone(),
                    mesh: Some(mi),
                    ..Node::default()
                });
                terrain_children.push(asm.scene.nodes.len() - 1);
            }
        }
        if write {
            asm.scene.nodes.push(Node { name: "terrain".into(), children: terrain_children, ..Node::default() });
            asm.scene.roots.push(asm.scene.nodes.len() - 1);
        }
        let (mut triangles, mut draw_calls) = (t_tris, t_calls);
        let (mut full_triangles, mut full_calls) =
            (t_full, main.meshes.iter().map(|m| m.primitives.len()).sum::<usize>());

        let mut species_reports = Vec::with_capacity(preset.species.len());
        for (s, rows) in preset.species.iter().zip(&rows_of) {
            let Some(chain) = chains.get(s.rules.name.as_str()).filter(|c| !c.variants.is_empty()) else {
                species_reports.push(SpeciesDraw {
                    name: s.rules.name.clone(),
                    placed: rows.len(),
                    drawn: 0,
                    culled: 0,
                    cull: None,
                    levels: Vec::new(),
                });
                continue;
            };
            let nlevels = chain.variants.iter().map(Vec::len).max().unwrap_or(0);
            let last_switch =
                chain.variants.iter().filter_map(|v| v.last()).map(|l| l.switch_distance_m).fold(0.0, f64::max);
            let cull = cull_distance(s.cull_distance_m, chain.height_m, last_switch, &preset.lod);
            // (variant, level, baked view of an impostor level) → instances
            let mut groups: BTreeMap<(usize, usize, Option<usize>), Instances> = BTreeMap::new();
            let mut impostors: BTreeMap<(usize, usize), Option<ImpostorViews>> = BTreeMap::new();
            let mut culled = 0usize;
            for (n, row) in rows.iter().enumerate() {
                let variant = shown(&s.rules.name, chain, n, row)?;
                let v = &chain.variants[variant];
                let scale = row.scale[1] as f64;
                let d = camera.distance_to(instance_centre(row, chain.centre_y_m));
                if cull.culls(d, factor, scale) {
                    culled += 1;
                    continue;
                }
                let switch: Vec<f64> = v.iter().map(|l| l.switch_distance_m).collect();
                let level = level_at(d, &switch, factor * scale);
                let impostor = match impostors.get(&(variant, level)) {
                    Some(i) => i,
                    None => {
                        let i = asm.impostor(&v[level].file, &v[level].mesh)?;
                        impostors.entry((variant, level)).or_insert(i)
                    }
                };
                let view = impostor.as_ref().map(|i| i.view_for(row, camera.eye));
                let g = groups.entry((variant, level, view)).or_default();
                g.translations.push(row.position.map(|x| x as f32));
                g.rotations.push(row.rotation);
                g.scales.push(row.scale);
            }
            let mut level_draws: Vec<LevelDraw> = (0..nlevels)
                .map(|level| LevelDraw {
                    level,
                    switch_distance_m: chain
                        .variants
                        .iter()
                        .filter_map(|v| v.get(level))
                        .map(|l| l.switch_distance_m)
                        .collect(),
                    instances: 0,
                    triangles: 0,
                })
                .collect();
            let mut children = Vec::new();
            for ((variant, level, view), inst) in groups {
                let l = &chain.variants[variant][level];
                let n = inst.translations.len();
                level_draws[level].instances += n;
                level_draws[level].triangles += (n * l.triangles) as u64;
                triangles += (n * l.triangles) as u64;
                let mi = match (view, &impostors[&(variant, level)]) {
                    (Some(k), Some(views)) => asm.impostor_view(&l.file, &l.mesh, views, k)?,
                    _ => asm.mesh_named(&l.file, &l.mesh)?,
                };
                draw_calls += asm.scene.meshes[mi].primitives.len();
                if write {
                    let mut extras = serde_json::json!({
                        "species": s.rules.name, "variant": variant, "level": level, "mesh": l.mesh, "file": l.file,
                    });
                    if let Some(k) = view {
                        extras[IMPOSTOR_VIEW_EXTRAS_KEY] = k.into();
                    }
                    asm.scene.nodes.push(Node {
                        name: format!("{}_{}", s.rules.name, asm.scene.meshes[mi].name),
                        mesh: Some(mi),
                        instances: Some(inst.into()),
                        extras: Some(extras),
                        ..Node::default()
                    });
                    children.push(asm.scene.nodes.len() - 1);
                }
            }
            // full detail: every row at its variant's LoD0, one node per variant
            let mut variants_used = vec![0usize; chain.variants.len()];
            for (n, row) in rows.iter().enumerate() {
                variants_used[shown(&s.rules.name, chain, n, row)?] += 1;
            }
            for (variant, &n) in variants_used.iter().enumerate() {
                if n == 0 {
                    continue;
                }
                let l0 = &chain.variants[variant][0];
                full_triangles += (n * l0.triangles) as u64;
                let mi = asm.mesh_named(&l0.file, &l0.mesh)?;
                full_calls += asm.scene.meshes[mi].primitives.len();
            }
            if write {
                asm.scene.nodes.push(Node { name: s.rules.name.clone(), children, ..Node::default() });
                asm.scene.roots.push(asm.scene.nodes.len() - 1);
            }
            let drawn = rows.len() - culled;
            species_reports.push(SpeciesDraw {
                name: s.rules.name.clone(),
                placed: rows.len(),
                drawn,
                culled,
                cull: Some(cull),
                levels: level_draws,
            });
        }
        reports.push(ViewReport {
            camera: camera.clone(),
            distance_factor: factor,
            terrain: TerrainDraw { chunks_per_level, triangles: t_tris, full_detail_triangles: t_full },
            species: species_reports,
            triangles,
            draw_calls,
            full_detail_triangles: full_triangles,
            full_detail_draw_calls: full_calls,
            image: None,
        });
    }
    if compare_full_detail {
        if let Some(first) = reports.first_mut() {
            let t = Instant::now();
            let [w, h] = COMPARE_SIZE_PX;
            let mut c = ImageComparison {
                size_px: [w, h],
                samples_per_pixel: COMPARE_SAMPLES * COMPARE_SAMPLES,
                differing: 0.0,
                differing_samples: 0.0,
                threshold: COMPARE_THRESHOLD,
                color_rmse: 0.0,
                skipped: None,
                seconds: 0.0,
            };
            if first.full_detail_triangles > MAX_COMPARE_TRIANGLES {
                c.skipped = Some(format!(
                    "{} full-detail triangles, over the {MAX_COMPARE_TRIANGLES} the comparison renders",
                    first.full_detail_triangles
                ));
            } else {
                let render = |s: &Scene| {
                    crate::scene::view_render::render_view(s, &first.camera, w * COMPARE_SAMPLES, h * COMPARE_SAMPLES)
                        .map(|(canvas, _)| canvas)
                        .map_err(fail)
                };
                let (lod, detail) = (render(&asm.scene)?, render(&full.scene)?);
                let d = crate::scene::view_render::image_difference(&lod, &detail, COMPARE_SAMPLES, COMPARE_THRESHOLD);
                (c.differing, c.color_rmse, c.differing_samples) = (d.differing, d.color_rmse, d.differing_samples);
            }
            c.seconds = t.elapsed().as_secs_f64();
            first.image = Some(c);
        }
    }

    drop(full);
    // `[scene] compact`: the terrain on its own grid (the main mesh's and every level's chunks)
    for (f, _) in &levels {
        asm.file(f)?;
    }
    let terrain_meshes: Vec<&Mesh> =
        main.meshes.iter().chain(levels.iter().flat_map(|(f, _)| asm.files[f].meshes.iter())).collect();
    let (store, terrain_quantization_m) = crate::scene::view_store::scene_store(preset, &terrain_meshes);
    drop(terrain_meshes);
    // meshes appended only for the full-detail count are not instanced by any node: drop them
    let mut scene = asm.scene;
    prune_unused_meshes(&mut scene);
    scene.name = preset.scene.name.clone();
    scene.extras = Some(serde_json::json!({ "verdant_view": reports.first().map(|r| &r.camera) }));
    let scene_file = PathBuf::from("scene.glb");
    export::write_scene_with(&scene, &scene_dir.join(&scene_file), &store).map_err(|e| fail(e.to_string()))?;
    // (measured once written: the writer checked the scene)
    let quantization_m = crate::export::quantize::position_error_with(&scene, &store.quantization, &store.mesh_grids);
    let scene_bytes = std::fs::metadata(scene_dir.join(&scene_file)).map(|m| m.len()).unwrap_or(0);
    drop(scene);

    // scene_lod.glb: every chunk and tile with its whole chain, for viewers that switch themselves
    let mut lod = Assembler::with_files(scene_dir, asm.files);
    let species: Vec<LodSpecies> = preset
        .species
        .iter()
        .zip(&rows_of)
        .filter_map(|(s, rows)| {
            let chain = *chains.get(s.rules.name.as_str()).filter(|c| !c.variants.is_empty())?;
            let last = chain.variants.iter().filter_map(|v| v.last()).map(|l| l.switch_distance_m).fold(0.0, f64::max);
            let cull = cull_distance(s.cull_distance_m, chain.height_m, last, &preset.lod);
            Some(LodSpecies { name: &s.rules.name, chain, rows, picked: None, cull })
        })
        .collect();
    let lod_terrain =
        LodTerrain { main: &main, levels: &levels, chunked, main_file: terrain.main, picked: None, take: true };
    // `[scene] tile`: the same scene in tiles, before scene_lod.glb takes the level files' chunks
    let tiles = match preset.scene.tile_m {
        None => None,
        Some(tile_m) => {
            let job = crate::scene::view_tiles::TileJob {
                dir: scene_dir,
                // the scatter stage's tiling (over the same surface's bounds): a placement tile's
                // rows go to the scene tile holding its centre, one chain in one tile
                placement_tiles: crate::scatter::Tiling::new(extent, preset.scatter.tile_m).ok(),
                terrain: &lod_terrain,
                species: &species,
                policy: &preset.lod,
                store: &store,
                tile_m,
                scene_name: &preset.scene.name,
                kept: kept_tiles,
            };
            Some(crate::scene::view_tiles::write_tiles(&job, &mut lod.files)?)
        }
    };
    let mut quantization_m = quantization_m.max(tiles.as_ref().map_or(0.0, |t| t.quantization_m));
    let mut lod_scene_file = None;
    let mut lod_scene_bytes = 0;
    if preset.scene.lod_scene {
        lod_scene(&mut lod, &lod_terrain, &species, &preset.lod)?;
        // what it was assembled from is not needed for the write (at a world's size, the read files,
        // the placement rows and the main terrain are as large as the scene)
        let Assembler { scene: mut lod_scene, files, .. } = lod;
        drop(species);
        drop(files);
        drop(rows_of);
        drop(main);
        lod_scene.name = format!("{} (levels of detail)", preset.scene.name);
        let file = PathBuf::from("scene_lod.glb");
        export::write_scene_with(&lod_scene, &scene_dir.join(&file), &store).map_err(|e| {
            let e = e.to_string();
            let remedy = match (e.contains("4 GiB"), preset.scene.tile_m) {
                (false, _) => "",
                (true, None) => {
                    " (a scene this large is written as tiles: set `tile` and `lod_scene = false` in \
                                [scene], docs/scene.md)"
                }
                (true, Some(_)) => " (the scene is written as tiles: set `lod_scene = false` in [scene])",
            };
            fail(format!("{}: {e}{remedy}", file.display()))
        })?;
        quantization_m = quantization_m.max(crate::export::quantize::position_error_with(
            &lod_scene,
            &store.quantization,
            &store.mesh_grids,
        ));
        lod_scene_bytes = std::fs::metadata(scene_dir.join(&file)).map(|m| m.len()).unwrap_or(0);
        lod_scene_file = Some(file);
    }
    // the species meshes were read back from their compact files: they had already moved by up to
    // their species' figure before these files stored them again
    let species_m = plants.map_or(0.0, |p| p.species.iter().map(|s| s.quantization_m).fold(0.0, f64::max));
    let quantization_m = quantization_m + species_m;
    Ok(ViewStageReport {
        scene_file,
        scene_bytes,
        lod_scene_file,
        lod_scene_bytes,
        tiles,
        quantization_m,
        terrain_quantization_m,
        views: reports,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Keeps the items `used` marks, in order; returns them and each old index's new one.
fn keep_used<T>(items: Vec<T>, used: &[bool]) -> (Vec<T>, Vec<Option<usize>>) {
    let mut remap = vec![None; items.len()];
    let mut kept = Vec::new();
    for (i, item) in items.into_iter().enumerate() {
        if used[i] {
            remap[i] = Some(kept.len());
            kept.push(item);
        }
    }
    (kept, remap)
}

/// Removes meshes no node references (and then materials and textures no mesh uses), keeping
/// the order of the rest.
fn prune_unused_meshes(scene: &mut Scene) {
    let mut used = vec![false; scene.meshes.len()];
    for m in scene.nodes.iter().filter_map(|n| n.mesh) {
        used[m] = true;
    }
    let (meshes, remap) = keep_used(std::mem::take(&mut scene.meshes), &used);
    scene.meshes = meshes;
    for n in &mut scene.nodes {
        n.mesh = n.mesh.and_then(|m| remap[m]);
    }
    let mut used = vec![false; scene.materials.len()];
    for i in scene.meshes.iter().flat_map(|m| m.primitives.iter().filter_map(|p| p.material)) {
        used[i] = true;
    }
    let (materials, remap) = keep_used(std::mem::take(&mut scene.materials), &used);
    for p in scene.meshes.iter_mut().flat_map(|m| m.primitives.iter_mut()) {
        p.material = p.material.and_then(|i| remap[i]);
    }
    let mut used = vec![false; scene.textures.len()];
    for t in materials.iter().flat_map(|m| m.textures()) {
        used[t] = true;
    }
    let (textures, remap) = keep_used(std::mem::take(&mut scene.textures), &used);
    scene.materials = materials.into_iter().map(|m| m.with_textures(|i| remap[i])).collect();
    scene.textures = textures;
}

/// The stage in a scene build.
pub struct ViewJob<'a> {
    pub preset: &'a Preset,
    pub terrain: TerrainInput<'a>,
    /// The plants stage's report (the species' chains), if it ran.
    pub plants: Option<&'a PlantsStageReport>,
    /// Each species' placement table (name, CSV).
    pub tables: &'a [(String, PathBuf)],
    pub compare_full_detail: bool,
    /// The keys of the terrain, plants and scatter stages (what scene.glb is drawn from).
    pub upstream: [&'a str; 3],
    /// Scene tiles built already (a merge's: the shards' tile units, [`crate::scene::tile_units`]).
    pub kept_tiles: Option<crate::scene::view_tiles::KeptTile<'a>>,
}

impl StageJob for ViewJob<'_> {
    type Report = ViewStageReport;
    type Artifact = ();
    const STAGE: Stage = Stage::View;

    fn key(&self) -> Result<String, SceneBuildError> {
        let compare = if self.compare_full_detail { "compare" } else { "" };
        let [terrain, plants, scatter] = self.upstream;
        Ok(view_key(self.preset, &[terrain, plants, scatter, compare]))
    }

    fn files(report: &ViewStageReport) -> Vec<PathBuf> {
        report.files()
    }

    fn run(&self, dir: &Path) -> Result<(ViewStageReport, ()), SceneBuildError> {
        let report = run_view(
            self.preset,
            &self.terrain,
            self.plants,
            self.tables,
            dir,
            self.compare_full_detail,
            self.kept_tiles,
        )?;
        Ok((report, ()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_centre_follows_rotation_and_scale() {
        let row = table::PlacementRow {
            position: [1.0, 2.0, 3.0],
            rotation: [0.0, 0.0, 0.0, 1.0],
            scale: [2.0; 3],
            yaw_deg: 0.0,
            tile: 0,
            variant: 0,
        };
        assert_eq!(instance_centre(&row, 5.0), [1.0, 12.0, 3.0]);
        // tipped 90° about +Z: up becomes −X
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let tipped = table::PlacementRow { rotation: [0.0, 0.0, h, h], scale: [1.0; 3], ..row };
        let c = instance_centre(&tipped, 5.0);
        assert!((c[0] - (1.0 - 5.0)).abs() < 1e-5 && (c[1] - 2.0).abs() < 1e-5, "{c:?}");
    }
}
