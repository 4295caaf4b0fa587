//! The terrain stage: the heightmap (a file or procedural) meshed to its error bound, chunked,
//! textured with its material layers, with its LoD chain, written in the preset's formats.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::export;
use crate::heightfield::{self, Heightfield};
use crate::lod::terrain_lod_chain_in_bands;
use crate::mesh::{Bounds, Scene};
use crate::scene::band_layers::Grows;
use crate::scene::cache::{sha256_hex, KeyBuilder};
use crate::scene::error::{SceneBuildError, StageError};
use crate::scene::pipeline::{Stage, StageJob};
use crate::scene::preset::procedural_heightfield;
use crate::scene::{Preset, TerrainSettings, TerrainSource};
use crate::terrain::build::{build_scene, BuildOptions};
use crate::terrain::job::{mesh_and_build, LayersFrom, MeshMode, MeshSettings, Meshed, TerrainFigures};
use crate::terrain::layers::SnowRule;
use crate::terrain::normal_map::{bake_normal_map, put_normal_map, NormalMapReport};
use crate::terrain::regions::chunk_cells;
use crate::terrain::stored::Storage;

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ChunkInfo {
    pub name: String,
    pub triangles: usize,
    pub bounds: Bounds,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct LodInfo {
    pub level: usize,
    pub files: Vec<PathBuf>,
    pub max_error_requested_m: f64,
    pub max_error_m: f64,
    pub rms_error_m: f64,
    pub triangles: usize,
    /// Use this level from this camera distance on (metres), until the next level's distance.
    pub switch_distance_m: f64,
    /// The level's own normal map (baked against its mesh) and the shading error it removes.
    pub normal_map: crate::terrain::normal_map::NormalMapReport,
    /// How deep its chunks' skirts hang ([`crate::scene::TerrainSettings::skirt_at`]); none
    /// without skirts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skirt_m: Option<f64>,
}

/// What the terrain stage measured. Deterministic fields only; timings live in `seconds`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TerrainStageReport {
    /// What the analyzer measured of the main mesh: the schema `verdant terrain --report` writes
    /// (`max_error` on the vertices as written, the figure the bound applies to; `max_error_f64`).
    #[serde(flatten)]
    pub figures: TerrainFigures,
    pub input_sha256: Option<String>,
    /// Triangles written, skirts and base included.
    pub output_triangles: usize,
    pub bounds: Option<Bounds>,
    pub files: Vec<PathBuf>,
    pub chunks: Vec<ChunkInfo>,
    /// How deep the main mesh's skirts hang; none without skirts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skirt_m: Option<f64>,
    pub lods: Vec<LodInfo>,
    /// Seconds of the run that computed these results (a cached build reports the original run).
    pub seconds: StageSeconds,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
pub struct StageSeconds {
    pub decode: f64,
    pub mesh: f64,
    pub analyze: f64,
    pub build: f64,
    pub export: f64,
    pub lods: f64,
    pub total: f64,
}

fn fail(stage: Stage) -> impl Fn(String) -> StageError {
    move |message| StageError::Failed { stage: stage.name(), message }
}

/// A stage's input at fault (exit code 2).
fn bad_input(stage: Stage) -> impl Fn(String) -> StageError {
    move |message| StageError::Input { stage: stage.name(), message }
}

/// The terrain's heights, from a file or generated; with the file's hash when it came from one.
pub fn terrain_heights(t: &TerrainSettings) -> Result<(Heightfield, usize, Option<String>), StageError> {
    let f = bad_input(Stage::Terrain);
    match &t.source {
        TerrainSource::Heightmap { path, decode } => {
            let bytes = crate::input::read_limited(path, crate::input::MAX_HEIGHTMAP_BYTES, "a heightmap")
                .map_err(|e| f(e.to_string()))?;
            let d = heightfield::decode(path, &bytes, decode).map_err(|e| f(e.to_string()))?;
            Ok((d.heightfield, d.voids_filled, Some(sha256_hex(&bytes))))
        }
        source => {
            let hf = procedural_heightfield(source)
                .ok_or_else(|| f("the procedural terrain could not be generated".into()))?;
            Ok((hf, 0, None))
        }
    }
}

/// Version of what the terrain stage writes for given inputs: part of its cache key. Bump it in
/// the commit that changes the stage's output bytes (tests/suite/scene_build.rs pins a digest of a
/// reference build per version and fails until it is bumped). 2: base-colour texture from the
/// material layers, terrain_layers.png. 3: LoD switch distances for the `[lod]` policy (2 px by
/// default, was 1 px). 4: the error is measured on the vertices as written (f32) against the map's
/// exact heights, and the TIN refines until that is within the bound; `max_error_f64_m` beside it.
/// 5: every vertex carries its layer weights (`_LAYER_WEIGHTS`). 6: every file a normal map baked
/// against its own mesh, TANGENT on every vertex (terrain/normal_map.rs). 7: the snow layer follows
/// the preset's `[snow]` cover when it has one; slopes from the normalised bilinear normal. 8: in a
/// scene with species, the soil layer (terrain_layers_1.png, `_LAYER_WEIGHTS_1`) and `_SURFACE`
/// from what grows (scene/ground_cover.rs). 9: maps over 480 samples a side are meshed as
/// regions of about 320 cells in parallel, joined along seams fixed first (terrain/regions.rs).
/// 10: a chunked map is meshed in bands of whole chunks (at least 320 rows), each from its own rows
/// alone (terrain/regions.rs `mesh_band`): the unit a shard will build. 11: the normal maps baked
/// by bands of texel rows in parallel (the same texels; their mean errors summed band by band).
/// 12: a banded terrain's bands bake their rows of its normal maps (the same texels); the maps'
/// figures summed per texel row, rows in order. 13: a chunked map is cut along every chunk line,
/// so each level's chunks fill their squares exactly (no hole between chunks of different levels);
/// with a LoD chain, each level's skirts hang at least its bound plus the coarsest level's
/// ([`crate::scene::TerrainSettings::skirt_at`]: deep enough to close the step to any level).
/// 14: a banded terrain's bands bake their rows of its layers (cover, weight maps, base colour:
/// scene/band_layers.rs); a layer texel reads its own texel of the cover (was: the cover
/// interpolated at its centre, which rounding could pull 10⁻¹⁶ towards a neighbour); the coverage
/// summed per texel row, rows in order (the same maps, the coverage's last digits).
pub const TERRAIN_ALGORITHM_VERSION: u32 = 14;

/// The stage in a scene build.
pub struct TerrainJob<'a> {
    pub preset: &'a Preset,
    pub terrain: &'a TerrainSettings,
    /// Where the meshes are kept apart from the stage's files (see [`MeshMemo`]); `None`: always
    /// mesh.
    pub memo: Option<MeshMemo<'a>>,
}

/// The terrain's meshes (the main TIN and its LoD chain) kept in the cache under a key of what
/// they depend on alone (the terrain settings, the `[lod]` policy, the heightmap's bytes), so a
/// build whose terrain stage misses for another reason (a species edit changes the soil layer and
/// `_SURFACE`; a `[snow]` cover, the snow layer; the formats) re-textures and re-writes the
/// terrain without meshing it again. The entry is `terrain-mesh-<key>` beside the stage entries.
#[derive(Clone, Copy)]
pub struct MeshMemo<'a> {
    pub cache: &'a crate::scene::cache::Cache,
    /// `--force`: mesh again and replace the entry.
    pub force: bool,
}

/// The cache stage name of the terrain's meshes.
pub const MESH_MEMO_STAGE: &str = "terrain-mesh";

/// What the memo keeps: the LoD chain as meshed and measured, and the main mesh with its figures.
/// In the entry, `stage.json` holds them with the meshes' arrays left empty and their lengths in
/// `sizes`; `blob.bin` holds the arrays (little-endian u32: each mesh's vertices then triangles,
/// chain levels first, then the main mesh).
#[derive(Serialize, Deserialize)]
struct Meshes {
    chain: Vec<crate::lod::LodLevel>,
    main: (crate::terrain::sample_mesh::SampleMesh, bool, crate::terrain::error::ErrorStats),
    #[serde(default)]
    sizes: Vec<[usize; 2]>,
}

impl Meshes {
    fn meshes_mut(&mut self) -> impl Iterator<Item = &mut crate::terrain::sample_mesh::SampleMesh> {
        self.chain.iter_mut().map(|l| &mut l.mesh).chain(std::iter::once(&mut self.main.0))
    }

    /// Moves the arrays out into a blob (and their lengths into `sizes`).
    fn to_blob(&mut self) -> Vec<u8> {
        let mut blob = Vec::new();
        let mut sizes = Vec::new();
        for m in self.meshes_mut() {
            sizes.push([m.vertices.len(), m.triangles.len()]);
            blob.extend(m.vertices.iter().flatten().flat_map(|v| v.to_le_bytes()));
            blob.extend(m.triangles.iter().flatten().flat_map(|v| v.to_le_bytes()));
            *m = Default::default();
        }
        self.sizes = sizes;
        blob
    }

    /// Puts the arrays back from a blob; `None` when it does not match `sizes`.
    fn from_blob(mut self, blob: &[u8]) -> Option<Meshes> {
        let mut words = blob.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]));
        let expected: usize = self.sizes.iter().map(|[v, t]| 2 * v + 3 * t).sum();
        if blob.len() != 4 * expected {
            return None;
        }
        let sizes = std::mem::take(&mut self.sizes);
        if self.chain.len() + 1 != sizes.len() {
            return None;
        }
        for (m, [v, t]) in self.meshes_mut().zip(sizes) {
            m.vertices = (0..v).map(|_| [words.next().unwrap_or(0), words.next().unwrap_or(0)]).collect();
            m.triangles = (0..t)
                .map(|_| [words.next().unwrap_or(0), words.next().unwrap_or(0), words.next().unwrap_or(0)])
                .collect();
        }
        Some(self)
    }
}

/// The cache stage name of a band's meshes (terrain/bands.rs): a shard's terrain unit.
pub const BAND_STAGE: &str = "terrain-band";

/// A terrain meshed in bands built apart ([`crate::terrain::bands`]): the band lines, and the
/// bounds every band is meshed at (the LoD levels', then the main mesh's when it is none of them).
#[derive(Debug, Clone, PartialEq)]
pub struct BandPlan {
    pub lines: Vec<u32>,
    pub bounds: Vec<f64>,
    /// The map's width in samples and its cell size in metres.
    pub width: usize,
    pub cell_m: f64,
}

impl BandPlan {
    pub fn band_count(&self) -> usize {
        self.lines.len() - 1
    }

    /// The map's height in samples.
    pub fn height(&self) -> usize {
        self.lines[self.lines.len() - 1] as usize + 1
    }

    /// Band `k`'s rows.
    pub fn rows(&self, k: usize) -> [u32; 2] {
        [self.lines[k], self.lines[k + 1]]
    }

    /// Whether band `k` has a band below and above it.
    pub fn fixed(&self, k: usize) -> [bool; 2] {
        [k > 0, k + 2 < self.lines.len()]
    }

    /// Band `k`'s rows and the row beyond each of its inner edges: what its unit reads (the
    /// chunks' vertex normals on a band line read the rows on both sides).
    pub fn read_rows(&self, k: usize) -> [u32; 2] {
        let [a, b] = self.rows(k);
        [a.saturating_sub(1), (b + 1).min(self.height() as u32 - 1)]
    }

    /// The rows band `k`'s chunks with their vertex attributes read ([`crate::scene::band_chunks`]):
    /// [`BandPlan::read_rows`] and one more below (a vertex on the band's last row weighs its layers
    /// by the bilinear normal there, which reads the normals of the row below it).
    pub fn chunk_rows(&self, k: usize) -> [u32; 2] {
        let [a, b] = self.rows(k);
        [a.saturating_sub(1), (b + 2).min(self.height() as u32 - 1)]
    }

    /// The size of the terrain's texture maps (base colour, layer weights, normal maps).
    pub fn map_px(&self) -> [u32; 2] {
        [crate::terrain::layers::map_px(self.width), crate::terrain::layers::map_px(self.height())]
    }

    /// Each band's rows of the normal maps, which its unit bakes; `None` when a texel centre
    /// lies on a band line and the maps are baked whole ([`crate::terrain::bands::band_texel_rows`]).
    pub fn normal_rows(&self) -> Option<Vec<std::ops::Range<usize>>> {
        crate::terrain::bands::band_texel_rows(&self.lines, self.height(), self.map_px()[1])
    }
}

/// How a `width` × `height` terrain with settings `t` is meshed in bands: `None` when it is meshed
/// whole (no chunks, a grid, a triangle limit, one band's rows, or x and z not exact in f32: see
/// [`crate::terrain::regions::band_lines`]).
pub fn band_plan(t: &TerrainSettings, width: usize, height: usize) -> Option<BandPlan> {
    if t.mode != MeshMode::Tin || t.max_triangles.is_some() {
        return None;
    }
    let cell = t.cell_size_m();
    let exact = Storage::f32_xz_exact(width, height, cell);
    let lines =
        crate::terrain::regions::band_lines(height, crate::terrain::regions::band_cells_for_chunk(t.chunk), exact);
    if lines.len() <= 2 {
        return None;
    }
    let mut bounds = t.lods.clone();
    if !bounds.contains(&t.max_error_m) {
        bounds.push(t.max_error_m);
    }
    Some(BandPlan { lines, bounds, width, cell_m: cell })
}

/// [`band_plan`] from the settings alone: a procedural map's size, a heightmap's from its header
/// (a heightmap that cannot tell is decoded; one that does not decode fails the terrain stage).
pub fn planned_bands(t: &TerrainSettings) -> Result<Option<BandPlan>, StageError> {
    let (w, h) = match &t.source {
        TerrainSource::Heightmap { path, decode } => match heightfield::dimensions_of_file(path, decode) {
            Some(size) => size,
            None => {
                let (hf, _, _) = terrain_heights(t)?;
                (hf.width, hf.height)
            }
        },
        TerrainSource::Fbm { size, .. } => (*size, *size),
    };
    Ok(band_plan(t, w, h))
}

/// Cache key of band `rows` of a terrain whose meshes' key is `mesh_key` ([`mesh_key`]: what
/// meshing reads, the heightmap's bytes among it, hashed once for all the bands).
pub fn band_key(mesh_key: &str, rows: [u32; 2]) -> String {
    let mut k = KeyBuilder::new(BAND_STAGE, TERRAIN_ALGORITHM_VERSION);
    k.add(mesh_key.as_bytes());
    k.add(&rows[0].to_le_bytes());
    k.add(&rows[1].to_le_bytes());
    k.finish()
}

/// The rows of a terrain's map the bands a shard builds need, made one band at a time: a
/// procedural map's rows alone (its range found once, by a pass that keeps nothing); a TIFF, raw
/// or `.hgt` heightmap's band rows read alone as each band asks ([`heightfield::read_kept_rows`]:
/// strips or tiles, byte ranges); a PNG's rows of all those bands read in one pass over the file
/// and held; the map decoded whole once where the reader cannot window it.
pub struct BandRows<'a> {
    t: &'a TerrainSettings,
    /// The rows of every band wanted.
    wanted: Vec<[u32; 2]>,
    range: Option<(f64, f64)>,
    /// The map's rows held, and which file row each is (every row when decoded whole).
    held: Option<(Heightfield, Vec<usize>)>,
}

impl<'a> BandRows<'a> {
    /// For the bands of rows `wanted`.
    pub fn new(t: &'a TerrainSettings, wanted: Vec<[u32; 2]>) -> BandRows<'a> {
        BandRows { t, wanted, range: None, held: None }
    }

    fn hold(&mut self) -> Result<(), StageError> {
        let TerrainSource::Heightmap { path, decode } = &self.t.source else { return Ok(()) };
        if self.held.is_some() {
            return Ok(());
        }
        let input = bad_input(Stage::Terrain);
        let wanted = &self.wanted;
        let keep = |j: usize| wanted.iter().any(|r| (r[0] as usize..=r[1] as usize).contains(&j));
        self.held = Some(match heightfield::read_kept_rows(path, decode, &keep).map_err(|e| input(e.to_string()))? {
            Some((d, rows)) => (d.heightfield, rows),
            None => {
                let hf = heightfield::load(path, decode).map_err(|e| input(e.to_string()))?.heightfield;
                let rows = (0..hf.height).collect();
                (hf, rows)
            }
        });
        Ok(())
    }

    /// Rows `rows[0]..=rows[1]` of the map.
    pub fn rows(&mut self, rows: [u32; 2]) -> Result<Heightfield, StageError> {
        let f = fail(Stage::Terrain);
        let outside = || f(format!("rows {}-{} are not within the terrain's map", rows[0], rows[1]));
        let span = [rows[0] as usize, rows[1] as usize];
        match self.t.source {
            TerrainSource::Fbm { size, seed, relief_m, cell_size_m, noise } => {
                let range = *self.range.get_or_insert_with(|| crate::synth::noise_range(noise, size, seed));
                crate::synth::noise_rows(noise, size, cell_size_m, relief_m, seed, range, span).ok_or_else(outside)
            }
            TerrainSource::Heightmap { ref path, ref decode } => {
                // a file read by ranges: this band's rows alone, so a shard holds one band's rows
                // at a time (a PNG's wanted rows are read in one pass and held; a map a window
                // cannot give is decoded whole once)
                if self.held.is_none() && heightfield::reads_by_range(path) {
                    let keep = |j: usize| (span[0]..=span[1]).contains(&j);
                    let window = heightfield::read_kept_rows(path, decode, &keep)
                        .map_err(|e| bad_input(Stage::Terrain)(e.to_string()))?;
                    if let Some((d, kept)) = window {
                        if kept.first() != Some(&span[0]) || kept.len() != span[1] - span[0] + 1 {
                            return Err(outside());
                        }
                        return Ok(d.heightfield);
                    }
                }
                self.hold()?;
                let (hf, held) = self.held.as_ref().ok_or_else(outside)?;
                // the band's rows are consecutive among those held (every row of a wanted band is)
                let first = held.binary_search(&span[0]).map_err(|_| outside())?;
                let last = first + (span[1] - span[0]);
                if held.get(last) != Some(&span[1]) {
                    return Err(outside());
                }
                hf.rows(first, last).ok_or_else(outside)
            }
        }
    }
}

/// Band `k` of `plan`: from `cache` when it holds it (unless `force`), else meshed and measured
/// from its rows, its chunks' rows of every level's normal map baked (when the plan bakes them
/// by band), and stored there. `rows` gives the map's rows ([`BandRows`], or the rows of a map at
/// hand); it is asked for [`BandPlan::read_rows`]. `mesh_key` is the terrain's [`mesh_key`]. With
/// `keep`, also the band's chunks at every level it built for its normal maps (shaded, without the
/// layers' attributes: what [`crate::scene::band_chunks::make`] weighs; `None` when the piece came
/// from the cache or the plan bakes no normal maps by band).
pub fn band_piece(
    mesh_key: &str,
    t: &TerrainSettings,
    rows_of: &mut dyn FnMut([u32; 2]) -> Result<Heightfield, StageError>,
    plan: &BandPlan,
    k: usize,
    cache: Option<(&crate::scene::cache::Cache, bool)>,
    keep: bool,
) -> Result<MadeBand, StageError> {
    use crate::terrain::bands::{bake_band_normals_of, build_band_window};
    let f = fail(Stage::Terrain);
    let rows = plan.rows(k);
    let key = cache.map(|_| band_key(mesh_key, rows));
    if let Some((c, false)) = cache {
        if let Some(piece) = kept_band(mesh_key, plan, k, c) {
            let exact_max_m = band_exact_max(c, mesh_key, plan, k);
            return Ok(MadeBand { piece, chunks: None, exact_max_m });
        }
    }
    let read = plan.read_rows(k);
    let margin = rows_of(read)?;
    let outside = || f(format!("rows {}-{} are not within the map's rows read", rows[0], rows[1]));
    let window = margin.rows((rows[0] - read[0]) as usize, (rows[1] - read[0]) as usize).ok_or_else(outside)?;
    let terrain_error = |error| {
        let e = crate::terrain::job::JobError::Terrain { source_label: source_label(t), error };
        StageError::of(Stage::Terrain.name(), &e, e.to_string())
    };
    let mut piece =
        build_band_window(&window, rows[0], &plan.bounds, t.max_vertices, chunk_cells(t.chunk), plan.fixed(k))
            .map_err(terrain_error)?;
    // the main mesh's f64 error in the band's rows (the largest of the bands' is the whole
    // mesh's, which the join takes without the map: `joined_without_map`): measured against the
    // exact heights where f32 rounds them, else the error as stored its analyzer found
    let exact_max_m = main_level(t, plan).map(|m| {
        if window.rounding_m() == 0.0 {
            return crate::terrain::error::largest_in_rows(&piece.levels[m].measure);
        }
        let mut local = piece.levels[m].mesh.clone();
        for v in &mut local.vertices {
            v[1] -= rows[0];
        }
        crate::terrain::error::exact_max_in_rows(&window, &local, [0, rows[1] - rows[0]])
    });
    drop(window);
    let mut kept = None;
    if let (Some(texel_rows), Some(pitch)) = (plan.normal_rows(), t.chunk) {
        let map = crate::heightfield::MapRows::new(&margin, read[0] as usize, plan.height()).ok_or_else(outside)?;
        let mut levels = Vec::new();
        for (level, &bound) in piece.levels.iter_mut().zip(&plan.bounds) {
            // (the scene's chunks: options the map cannot take are the input's fault, as there)
            let in_band = |e: crate::terrain::build::BuildError| {
                let e = crate::terrain::job::JobError::from(e);
                StageError::of(Stage::Terrain.name(), &e, format!("band {k} (rows {}-{}): {e}", rows[0], rows[1]))
            };
            let chunks = crate::terrain::build::band_chunks(&map, &level.mesh, pitch, t.skirt_at(bound), true)
                .map_err(in_band)?;
            let normals = bake_band_normals_of(&chunks, &map, plan.map_px(), texel_rows[k].clone()).map_err(in_band)?;
            level.normals = Some(normals);
            if keep {
                levels.push(chunks);
            }
        }
        kept = keep.then_some(levels);
    }
    if let (Some((c, _)), Some(key)) = (cache, &key) {
        // (a store that fails only costs meshing the band again, or a shard that says so)
        let json = match exact_max_m {
            // (the bits, which JSON's decimal need not give back exactly)
            Some(e) => format!(
                "{{\"rows\":[{},{}],\"max_error_f64_m\":{e},\"max_error_f64_bits\":{}}}",
                rows[0],
                rows[1],
                e.to_bits()
            ),
            None => format!("{{\"rows\":[{},{}]}}", rows[0], rows[1]),
        };
        let _ = c.store_blob(BAND_STAGE, key, &json, &piece.to_bytes());
    }
    Ok(MadeBand { piece, chunks: kept, exact_max_m })
}

/// What [`band_piece`] gives of a band.
pub struct MadeBand {
    pub piece: crate::terrain::bands::BandPiece,
    /// With `keep`, the band's chunks at every level built for its normal maps.
    pub chunks: Option<Vec<crate::scene::band_chunks::LevelChunks>>,
    /// The main mesh's f64 error in the band's rows (measured against the exact heights where f32
    /// rounds them, else its error as stored; as its entry says when it came from the cache, `None`
    /// when an earlier unit's entry does not say).
    pub exact_max_m: Option<f64>,
}

/// Band `k` of `plan` as `cache` holds it (`None` when it does not, or not whole).
pub fn kept_band(
    mesh_key: &str,
    plan: &BandPlan,
    k: usize,
    cache: &crate::scene::cache::Cache,
) -> Option<crate::terrain::bands::BandPiece> {
    let rows = plan.rows(k);
    let (_, entry) = cache.lookup(BAND_STAGE, &band_key(mesh_key, rows))?;
    let piece = crate::terrain::bands::BandPiece::from_bytes(&crate::scene::cache::Cache::read_blob(&entry).ok()?)?;
    // (normal map rows where the plan bakes them by band, of the band's texel rows)
    let texel_rows = plan.normal_rows().map(|r| r[k].clone());
    let width = plan.map_px()[0] as usize;
    let normals_fit = piece.levels.iter().all(|l| match (&l.normals, &texel_rows) {
        (Some(n), Some(r)) => {
            n.first == r.start && n.figures.len() == r.len() && n.width == width && n.png.is_empty() == r.is_empty()
        }
        (None, None) => true,
        _ => false,
    });
    (piece.rows == rows && piece.levels.len() == plan.bounds.len() && normals_fit).then_some(piece)
}

/// Whether a terrain planned in bands bakes its layers by band (as its normal maps: a chunked map
/// whose texel centres all lie off the band lines, [`BandPlan::normal_rows`]).
pub fn layers_by_band(t: &TerrainSettings, plan: &BandPlan) -> bool {
    t.chunk.is_some() && plan.normal_rows().is_some()
}

/// Whether a terrain planned in bands has its chunks built by band (with their vertex
/// attributes, [`crate::scene::band_chunks`]; a shard's band unit keeps them): when it bakes its
/// layers by band and has no base (the base closes the whole map).
pub fn chunks_by_band(t: &TerrainSettings, plan: &BandPlan) -> bool {
    layers_by_band(t, plan) && t.base_m.is_none()
}

/// Cache key of band `k`'s layer rows ([`crate::scene::band_layers::layers_key`]).
pub fn band_layers_key(grows: &Grows, mesh_key: &str, plan: &BandPlan, k: usize) -> String {
    crate::scene::band_layers::layers_key(grows, &band_key(mesh_key, plan.rows(k)))
}

/// The cache entries band `k`'s unit makes: its meshes', and its layer rows' when the plan bakes
/// them by band.
pub fn band_entries(grows: &Grows, t: &TerrainSettings, mesh_key: &str, plan: &BandPlan, k: usize) -> Vec<String> {
    use crate::scene::cache::Cache;
    let mut entries = vec![Cache::entry_name(BAND_STAGE, &band_key(mesh_key, plan.rows(k)))];
    if layers_by_band(t, plan) {
        let key = band_layers_key(grows, mesh_key, plan, k);
        entries.push(Cache::entry_name(crate::scene::band_layers::BAND_LAYERS_STAGE, &key));
    }
    if chunks_by_band(t, plan) {
        let key = crate::scene::band_chunks::chunks_key_of(grows, mesh_key, plan, k);
        entries.push(Cache::entry_name(crate::scene::band_chunks::BAND_CHUNKS_STAGE, &key));
    }
    entries
}

/// Band `k`'s rows of the terrain's layers (`None` when the plan does not bake them by band):
/// from `cache` when it holds them (unless `force`), else baked from `piece` (the band's meshes)
/// and the map's rows (`rows_of`, asked for [`BandPlan::read_rows`]) and stored there. `surface`
/// is the band's chunk surfaces at the main level when the caller has them.
#[allow(clippy::too_many_arguments)]
pub fn band_layers(
    grows: &Grows,
    t: &TerrainSettings,
    mesh_key: &str,
    plan: &BandPlan,
    k: usize,
    piece: &crate::terrain::bands::BandPiece,
    rows_of: &mut dyn FnMut([u32; 2]) -> Result<Heightfield, StageError>,
    surface: Option<&[crate::mesh::Primitive]>,
    cache: Option<(&crate::scene::cache::Cache, bool)>,
) -> Result<Option<crate::scene::band_layers::BandLayers>, StageError> {
    use crate::scene::band_layers;
    let (Some(texel_rows), Some(pitch), true) = (plan.normal_rows(), t.chunk, layers_by_band(t, plan)) else {
        return Ok(None);
    };
    let f = fail(Stage::Terrain);
    let texel_rows = texel_rows[k].clone();
    let key = band_layers_key(grows, mesh_key, plan, k);
    if let Some((c, false)) = cache {
        let extent = crate::scene::ground_cover::terrain_extent(plan.width, plan.height(), plan.cell_m);
        let fits = (extent, grows.preset.species.len());
        if let Some(kept) = band_layers::kept(c, &key, plan.map_px(), &texel_rows, fits) {
            return Ok(Some(kept));
        }
    }
    let read = plan.read_rows(k);
    let margin = rows_of(read)?;
    let rows = plan.rows(k);
    let field = crate::heightfield::MapRows::new(&margin, read[0] as usize, plan.height())
        .ok_or_else(|| f(format!("rows {}-{} are not within the map", read[0], read[1])))?;
    let built;
    let surface = match surface {
        Some(s) => s,
        None => {
            let main = plan.bounds.iter().position(|&b| b == t.max_error_m).unwrap_or(0);
            let chunks = crate::terrain::build::band_chunk_surfaces(
                &margin,
                read[0] as usize,
                plan.height(),
                &piece.levels[main].mesh,
                pitch,
                t.skirt_at(t.max_error_m),
            )
            .map_err(|e| f(format!("the terrain's chunks of rows {}-{}: {e}", rows[0], rows[1])))?;
            built = chunks.into_iter().map(|(_, p)| p).collect::<Vec<_>>();
            &built[..]
        }
    };
    let baked = band_layers::bake(grows.preset, &field, plan.cell_m, surface, plan.map_px(), texel_rows);
    if let Some((c, _)) = cache {
        band_layers::store(c, &key, &baked)?;
    }
    Ok(Some(baked))
}

/// Each bound's normal map rows, every band's in order (when the bands baked them).
type BandedNormals = Option<Vec<Vec<crate::terrain::bands::BandNormals>>>;

/// The terrain's LoD chain (switch distances assigned) and main mesh from its bands' pieces, and
/// their normal map rows.
/// What a terrain meshed in bands is made of, from its bands' pieces.
pub(crate) struct Banded {
    /// The LoD chain (switch distances assigned).
    chain: Vec<crate::lod::LodLevel>,
    /// The main mesh, whether it hit a triangle limit (never: bands have none), its figures.
    main: (crate::terrain::sample_mesh::SampleMesh, bool, crate::terrain::error::ErrorStats),
    /// The main mesh's f64 error from the bands' units, when each says it.
    main_f64_m: Option<f64>,
    normals: BandedNormals,
    /// The material layers joined from the bands' rows (when the plan bakes them by band).
    layers: Option<crate::terrain::layers::TerrainLayers>,
    /// Every band's chunks in the cache (a sharded build's: their entries' keys, in band order),
    /// when it holds them all.
    chunks: Option<Vec<String>>,
}

/// `hf`: the map, or `None` when every band's entries are in `memo`'s cache and say the main
/// mesh's f64 error ([`joined_without_map`]; an entry that does not read back then fails, and so
/// does a level over its bound as stored on a map f32 `rounds`).
pub(crate) fn banded_meshes(
    preset: &Preset,
    t: &TerrainSettings,
    key: &str,
    hf: Option<&Heightfield>,
    plan: &BandPlan,
    memo: Option<MeshMemo<'_>>,
    rounds: bool,
) -> Result<Banded, StageError> {
    use crate::terrain::tin::{check_tin_input, TinOptions};
    let input = bad_input(Stage::Terrain);
    if !t.lods.is_empty() {
        crate::lod::check_chain(&t.lods, &preset.lod).map_err(|e| input(e.to_string()))?;
    }
    let storage = hf.map(|hf| (hf, Storage::f32(hf)));
    let opts = |max_error_m: f64| TinOptions {
        max_error_m,
        max_triangles: None,
        max_vertices: t.max_vertices,
        chunk_cells: 0,
    };
    // a level's error as the chain names it, the main mesh's as `verdant terrain` does
    let level_error = |k: usize, error: crate::terrain::TerrainError| -> StageError {
        if k < t.lods.len() {
            input(crate::lod::LodError::Terrain { level: k, error }.to_string())
        } else {
            let e = crate::terrain::job::JobError::Terrain { source_label: source_label(t), error };
            StageError::of(Stage::Terrain.name(), &e, e.to_string())
        }
    };
    // (a map not read was checked by the bands' units, each on its rows)
    for (k, &bound) in plan.bounds.iter().enumerate() {
        if let Some(hf) = hf {
            check_tin_input(hf, &opts(bound)).map_err(|e| level_error(k, e))?;
        }
    }
    let start = Instant::now();
    let cache = memo.map(|m| (m.cache, m.force));
    let mut rows_of = |rows: [u32; 2]| {
        hf.and_then(|hf| hf.rows(rows[0] as usize, rows[1] as usize))
            .ok_or_else(|| fail(Stage::Terrain)(format!("rows {}-{} are not within the map", rows[0], rows[1])))
    };
    let made = (0..plan.band_count())
        .map(|k| band_piece(key, t, &mut rows_of, plan, k, cache, false))
        .collect::<Result<Vec<_>, _>>()?;
    // the main mesh's f64 error when every band says it
    let main_f64_m = made.iter().try_fold(0.0, |a: f64, b| Some(b.exact_max_m?.max(a)));
    let mut pieces: Vec<_> = made.into_iter().map(|b| b.piece).collect();
    // each band's rows of the layers, joined (when the plan bakes them by band)
    let grows = Grows::of(preset);
    let chunks = match cache {
        Some((c, false)) if chunks_by_band(t, plan) => {
            let keys: Vec<String> = (0..plan.band_count())
                .map(|k| crate::scene::band_chunks::chunks_key_of(&grows, key, plan, k))
                .collect();
            let stage = crate::scene::band_chunks::BAND_CHUNKS_STAGE;
            keys.iter().all(|k| c.lookup(stage, k).is_some()).then_some(keys)
        }
        _ => None,
    };
    let layers = if layers_by_band(t, plan) {
        let mut parts = Vec::with_capacity(pieces.len());
        for (k, piece) in pieces.iter().enumerate() {
            parts.extend(band_layers(&grows, t, key, plan, k, piece, &mut rows_of, None, cache)?);
        }
        let joined = crate::scene::band_layers::join(preset, parts, plan.map_px())
            .map_err(|e| fail(Stage::Terrain)(format!("the bands' layer rows do not join: {e}")))?;
        Some(joined)
    } else {
        None
    };
    // each bound's normal map rows, taken from the pieces (every band's, or none)
    let normals: BandedNormals = plan.normal_rows().map(|_| {
        (0..plan.bounds.len()).map(|k| pieces.iter_mut().filter_map(|p| p.levels[k].normals.take()).collect()).collect()
    });
    let share = start.elapsed().as_secs_f64() / plan.bounds.len() as f64;
    let mut levels = Vec::with_capacity(plan.bounds.len());
    for (k, &bound) in plan.bounds.iter().enumerate() {
        let start = Instant::now();
        let stored = storage.as_ref().map(|(hf, s)| (*hf, s));
        let (r, stats) = crate::terrain::bands::assemble_stored(plan.width, stored, &pieces, k, &opts(bound))
            .map_err(|e| level_error(k, e))?;
        // (over its bound as stored, a level of a map f32 rounds is refused naming its worst
        // sample, which the map is read for)
        if rounds && hf.is_none() && r.max_error_m > bound {
            return Err(fail(Stage::Terrain)(format!("level {k} is over its bound as stored")));
        }
        levels.push(crate::lod::LodLevel {
            level: k,
            max_error_requested_m: bound,
            mesh: r.mesh,
            stats,
            switch_distance_m: 0.0,
            hit_triangle_limit: false,
            seconds: share + start.elapsed().as_secs_f64(),
        });
    }
    let main_level = plan.bounds.iter().position(|&b| b == t.max_error_m).unwrap_or(0);
    let main = (levels[main_level].mesh.clone(), false, levels[main_level].stats);
    levels.truncate(t.lods.len());
    crate::lod::assign_switch_distances(&mut levels, &preset.lod);
    Ok(Banded { chain: levels, main, main_f64_m, normals, layers, chunks })
}

/// The main mesh's level among `plan`'s bounds.
fn main_level(t: &TerrainSettings, plan: &BandPlan) -> Option<usize> {
    plan.bounds.iter().position(|&b| b == t.max_error_m)
}

/// The main mesh's f64 error in band `k`'s rows as its unit measured it (`None` when the entry
/// does not say: one stored before units said it).
fn band_exact_max(cache: &crate::scene::cache::Cache, key: &str, plan: &BandPlan, k: usize) -> Option<f64> {
    let (json, _) = cache.lookup(BAND_STAGE, &band_key(key, plan.rows(k)))?;
    let v: serde_json::Value = serde_json::from_str(&json).ok()?;
    v["max_error_f64_bits"].as_u64().map(f64::from_bits)
}

/// A terrain the cache holds every band's entries of (pieces, layers, chunks), each saying the
/// main mesh's f64 error in its rows (measured by its unit against the map's exact heights, or the
/// error as stored where those are their f32 values), so the terrain stage joins it without
/// reading the map (a merge's): its band plan, the main mesh's f64 error (the largest of the
/// bands'), and whether f32 rounds the map's heights in any band. `None` when it does not (the
/// map is then decoded), or for an `.hgt` (voids). (Entries of an earlier unit that do not say
/// the error join when every band's heights are exact: the error as stored is the f64 error.)
/// `key` is the terrain's [`mesh_key`], asked for only when the terrain could be joined so.
pub(crate) fn joined_without_map(
    preset: &Preset,
    t: &TerrainSettings,
    key: &mut dyn FnMut() -> Result<String, StageError>,
    cache: &crate::scene::cache::Cache,
) -> Result<Option<(BandPlan, Option<f64>, bool)>, StageError> {
    use crate::scene::band_chunks;
    if let TerrainSource::Heightmap { path, decode } = &t.source {
        let hgt = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("hgt"));
        if hgt || decode.encoding == heightfield::Encoding::Hgt {
            return Ok(None);
        }
    }
    let Some(plan) = planned_bands(t)? else { return Ok(None) };
    if !chunks_by_band(t, &plan) {
        return Ok(None);
    }
    let key = key()?;
    let grows = Grows::of(preset);
    let (mut largest, mut said, mut rounds) = (0.0f64, 0, false);
    for k in 0..plan.band_count() {
        let chunks = band_chunks::chunks_key_of(&grows, &key, &plan, k);
        let all = cache.lookup(BAND_STAGE, &band_key(&key, plan.rows(k))).is_some()
            && cache
                .lookup(crate::scene::band_layers::BAND_LAYERS_STAGE, &band_layers_key(&grows, &key, &plan, k))
                .is_some()
            && cache.lookup(band_chunks::BAND_CHUNKS_STAGE, &chunks).is_some();
        if !all {
            return Ok(None);
        }
        let exact = band_chunks::heights_exact(cache, &chunks);
        rounds |= !exact;
        match band_exact_max(cache, &key, &plan, k) {
            Some(e) => {
                largest = largest.max(e);
                said += 1;
            }
            // (an earlier unit's entry: only exact heights say the error as stored)
            None if exact => {}
            None => return Ok(None),
        }
    }
    match said {
        0 => Ok(Some((plan, None, false))),
        n if n == plan.band_count() => Ok(Some((plan, Some(largest), rounds))),
        _ => Ok(None),
    }
}

/// The heightmap's sha256 (hashed in pieces, not held), `None` for a procedural terrain.
fn heightmap_sha256(t: &TerrainSettings) -> Result<Option<String>, StageError> {
    match &t.source {
        TerrainSource::Heightmap { path, .. } => {
            crate::scene::cache::sha256_hex_of_input(path, crate::input::MAX_HEIGHTMAP_BYTES, "a heightmap")
                .map(Some)
                .map_err(|e| bad_input(Stage::Terrain)(e.to_string()))
        }
        _ => Ok(None),
    }
}

/// Key of the terrain's meshes: what meshing reads (not the formats, snow or species).
pub fn mesh_key(preset: &Preset, t: &TerrainSettings) -> Result<String, StageError> {
    Ok(mesh_key_hashed(preset, t, heightmap_sha256(t)?.as_deref()))
}

/// [`mesh_key`] of a terrain whose heightmap's sha256 is `heightmap_sha256` (`None`: procedural).
fn mesh_key_hashed(preset: &Preset, t: &TerrainSettings, heightmap_sha256: Option<&str>) -> String {
    let mut k = KeyBuilder::new(MESH_MEMO_STAGE, TERRAIN_ALGORITHM_VERSION);
    k.add(serde_json::to_string(t).unwrap_or_default().as_bytes());
    if !t.lods.is_empty() {
        k.add(serde_json::to_string(&preset.lod).unwrap_or_default().as_bytes());
    }
    if let Some(hash) = heightmap_sha256 {
        k.add(hash.as_bytes());
    }
    k.finish()
}

impl TerrainJob<'_> {
    /// The entries the terrain's meshes are kept in apart from its files (what `verdant cache
    /// prune` keeps for this scene): its bands' pieces when it is meshed in bands, else the memo.
    pub fn memo_entries(&self) -> Vec<String> {
        use crate::scene::cache::Cache;
        if self.memo.is_none() {
            return Vec::new();
        }
        let (t, preset) = (self.terrain, self.preset);
        match planned_bands(t) {
            Ok(Some(plan)) => match mesh_key(preset, t) {
                Ok(key) => {
                    let grows = Grows::of(preset);
                    (0..plan.band_count()).flat_map(|k| band_entries(&grows, t, &key, &plan, k)).collect()
                }
                Err(_) => Vec::new(),
            },
            Ok(None) => {
                mesh_key(preset, t).ok().map(|key| Cache::entry_name(MESH_MEMO_STAGE, &key)).into_iter().collect()
            }
            Err(_) => Vec::new(),
        }
    }
}

impl StageJob for TerrainJob<'_> {
    type Report = TerrainStageReport;
    /// The main scene (what the snow, scatter and preview stages read).
    type Artifact = Terrained;
    const STAGE: Stage = Stage::Terrain;

    fn key(&self) -> Result<String, SceneBuildError> {
        Ok(terrain_key(self.preset, self.terrain)?)
    }

    fn files(report: &TerrainStageReport) -> Vec<PathBuf> {
        terrain_files(report)
    }

    fn run(&self, dir: &Path) -> Result<(TerrainStageReport, Terrained), SceneBuildError> {
        let (report, scene, cover) = run_terrain_covered(self.preset, self.terrain, dir, self.memo)?;
        Ok((report, Terrained { scene, cover }))
    }
}

/// Cache key of the terrain stage: its settings, the formats, the input's content.
pub fn terrain_key(preset: &Preset, t: &TerrainSettings) -> Result<String, StageError> {
    let mut k = KeyBuilder::new("terrain", TERRAIN_ALGORITHM_VERSION);
    k.add(serde_json::to_string(t).unwrap_or_default().as_bytes());
    k.add(serde_json::to_string(&preset.scene.formats).unwrap_or_default().as_bytes());
    if !t.lods.is_empty() {
        k.add(serde_json::to_string(&preset.lod).unwrap_or_default().as_bytes());
    }
    if let Some(snow) = &preset.snow {
        // the snow layer follows the scene's cover (see [`snow_rule`])
        k.add(serde_json::to_string(&snow.cover).unwrap_or_default().as_bytes());
    }
    if !preset.species.is_empty() {
        // the soil layer and `_SURFACE` follow what grows (scene/ground_cover.rs)
        crate::scene::ground_cover::add_key(&mut k, preset);
    }
    if let Some(hash) = heightmap_sha256(t)? {
        k.add(hash.as_bytes());
    }
    Ok(k.finish())
}

/// Where the terrain's snow layer lies: the preset's `[snow]` cover when it has one (the base
/// colour then shows the snow the snow stage's mask and the thinned plants follow), else the
/// fixed snowline.
pub fn snow_rule(preset: &Preset) -> SnowRule {
    preset.snow.as_ref().map_or(SnowRule::Snowline, |s| SnowRule::Cover(s.cover.clone()))
}

/// How errors name the terrain's heights: the heightmap's path, or the procedural kind.
pub(crate) fn source_label(t: &TerrainSettings) -> String {
    match &t.source {
        TerrainSource::Heightmap { path, .. } => path.display().to_string(),
        _ => "the procedural terrain".into(),
    }
}

fn write_formats(preset: &Preset, scene: &Scene, scene_dir: &Path, stem: &str) -> Result<Vec<PathBuf>, StageError> {
    let mut files = Vec::new();
    for fmt in &preset.scene.formats {
        let rel = PathBuf::from("terrain").join(format!("{stem}.{}", fmt.extension()));
        let written =
            export::write_scene(scene, &scene_dir.join(&rel)).map_err(|e| fail(Stage::Terrain)(e.to_string()))?;
        for w in written {
            let rel = w.strip_prefix(scene_dir).map(Path::to_path_buf).unwrap_or(w);
            files.push(rel);
        }
    }
    Ok(files)
}

/// Runs the terrain stage into `scene_dir`; returns its report and the main scene (for the preview).
pub fn run_terrain(
    preset: &Preset,
    t: &TerrainSettings,
    scene_dir: &Path,
) -> Result<(TerrainStageReport, Scene), StageError> {
    run_terrain_covered(preset, t, scene_dir, None).map(|(report, scene, _)| (report, scene))
}

/// What a terrain stage that ran hands on: the main scene, and what grows on it (the ground cover
/// its layers were baked with: every species' density on the layer map's texels, which the scatter
/// stage's density maps hold for the species snow does not thin).
pub struct Terrained {
    pub scene: Scene,
    pub cover: Option<std::sync::Arc<crate::terrain::vegetation::VegetationCover>>,
}

/// [`run_terrain`], taking the meshes from `memo` when it holds them (and storing them when not),
/// also handing on the ground cover its layers were baked with.
pub fn run_terrain_covered(
    preset: &Preset,
    t: &TerrainSettings,
    scene_dir: &Path,
    memo: Option<MeshMemo<'_>>,
) -> Result<(TerrainStageReport, Scene, Option<std::sync::Arc<crate::terrain::vegetation::VegetationCover>>), StageError>
{
    let f = fail(Stage::Terrain);
    // the settings or the map at fault: a chain the map cannot have, chunks or skirts it cannot take
    let input = bad_input(Stage::Terrain);
    let t0 = Instant::now();
    // The map, decoded when something reads it: a terrain sharded by bands whose every unit is in
    // the cache (a merge's), each saying the main mesh's f64 error in its rows (heights exact in
    // f32, or measured by the unit), is joined from the bands' pieces, layers and chunks without it.
    let held: std::cell::OnceCell<Heightfield> = std::cell::OnceCell::new();
    let map = || -> Result<&Heightfield, StageError> {
        if let Some(hf) = held.get() {
            return Ok(hf);
        }
        let (hf, _, _) = terrain_heights(t)?;
        Ok(held.get_or_init(|| hf))
    };
    // the heightmap hashed in pieces when the cache may make decoding it needless (and hashed
    // again as decoded when it does not), else only as decoded
    let mut hashed: Option<Option<String>> = None;
    let kept_plan = match memo {
        Some(m) if !m.force => {
            let mut key = || -> Result<String, StageError> {
                let sha = heightmap_sha256(t)?;
                let key = mesh_key_hashed(preset, t, sha.as_deref());
                hashed = Some(sha);
                Ok(key)
            };
            joined_without_map(preset, t, &mut key, m.cache)?
        }
        _ => None,
    };
    let (voids_filled, input_sha256) = match (&kept_plan, hashed.take()) {
        // (a map of such bands fills no voids: an `.hgt` is always decoded)
        (Some(_), Some(sha)) => (0, sha),
        (Some(_), None) => (0, heightmap_sha256(t)?),
        (None, _) => {
            let (hf, voids_filled, input_sha256) = terrain_heights(t)?;
            let _ = held.set(hf);
            (voids_filled, input_sha256)
        }
    };
    let key = mesh_key_hashed(preset, t, input_sha256.as_deref());
    let decode_s = t0.elapsed().as_secs_f64();

    // whether f32 rounds the heights of some band joined without the map (a level over its bound
    // as stored then needs the map, for the whole build's message)
    let kept_rounds = kept_plan.as_ref().is_some_and(|(_, _, rounds)| *rounds);
    // a chunked map's bands, each kept in the cache as a piece of its own (a shard's unit)
    let plan = match kept_plan {
        Some((plan, ..)) => Some(plan),
        None => {
            let hf = map()?;
            band_plan(t, hf.width, hf.height)
        }
    };
    let size = match &plan {
        Some(plan) => [plan.width, plan.height()],
        None => [map()?.width, map()?.height],
    };
    // the meshes as an earlier build of the same terrain made them (an entry that does not read
    // back is meshed again and replaced)
    let (band_memo, memo) = if plan.is_some() { (memo, None) } else { (None, memo) };
    let memo_key = memo.map(|_| key.clone());
    let remembered: Option<Meshes> = match (memo, &memo_key) {
        (Some(m), Some(key)) if !m.force => m.cache.lookup(MESH_MEMO_STAGE, key).and_then(|(json, entry)| {
            let meshes: Meshes = serde_json::from_str(&json).ok()?;
            meshes.from_blob(&crate::scene::cache::Cache::read_blob(&entry).ok()?)
        }),
        _ => None,
    };
    let from_memo = remembered.is_some();

    let chunk_cells = chunk_cells(t.chunk);
    // The LoD chain meshes its levels in parallel; when one of them is the main mesh's bound,
    // the main mesh is taken from the chain instead of being computed twice.
    let t1 = Instant::now();
    // the main mesh's f64 error from a banded terrain's units, when each measured it
    let mut bands_f64_m = None;
    let (mut chain, remembered_main, band_normals, band_layers, band_chunks) = match (remembered, &plan) {
        (_, Some(plan)) => {
            // (without the map while every entry reads back; with it where one does not)
            let b = match held.get() {
                Some(hf) => banded_meshes(preset, t, &key, Some(hf), plan, band_memo, false)?,
                None => match banded_meshes(preset, t, &key, None, plan, band_memo, kept_rounds) {
                    Ok(b) => b,
                    Err(_) => banded_meshes(preset, t, &key, Some(map()?), plan, band_memo, false)?,
                },
            };
            bands_f64_m = b.main_f64_m;
            (b.chain, Some(b.main), b.normals, b.layers, b.chunks)
        }
        (Some(m), None) => (m.chain, Some(m.main), None, None, None),
        (None, None) if t.lods.is_empty() => (Vec::new(), None, None, None, None),
        (None, None) => (
            terrain_lod_chain_in_bands(map()?, &t.lods, t.max_triangles, t.max_vertices, chunk_cells, &preset.lod)
                .map_err(|e| input(e.to_string()))?,
            None,
            None,
            None,
            None,
        ),
    };
    // bound k's scene named `name` from the bands' chunks when the cache holds them (`None` when
    // one does not read back: the scene is then built from the map)
    let assembled = |bound: f64, name: &str| -> Option<Scene> {
        let (Some(plan), Some(keys), Some(cache), Some(pitch)) = (&plan, &band_chunks, band_memo, t.chunk) else {
            return None;
        };
        let level = plan.bounds.iter().position(|&b| b == bound)?;
        let mut chunks = Vec::new();
        for key in keys {
            let blob = crate::scene::band_chunks::kept_blob(cache.cache, key)?;
            chunks.extend(crate::scene::band_chunks::level_of(&blob, level)?);
        }
        crate::terrain::build::assemble_chunks(name, plan.width, plan.height(), pitch, chunks).ok()
    };
    // bound k's normal map, put together from the bands' rows
    let normal_rows = |bound: f64| -> Result<Option<crate::terrain::normal_map::TexelRows>, StageError> {
        let (Some(plan), Some(normals)) = (&plan, &band_normals) else { return Ok(None) };
        let Some(k) = plan.bounds.iter().position(|&b| b == bound) else { return Ok(None) };
        let refs: Vec<&crate::terrain::bands::BandNormals> = normals[k].iter().collect();
        crate::terrain::bands::join_normals(&refs, plan.map_px()).map(Some).map_err(&f)
    };
    let chain_s = t1.elapsed().as_secs_f64();
    let ready = remembered_main.or_else(|| {
        chain
            .iter()
            .find(|l| t.mode == MeshMode::Tin && l.max_error_requested_m == t.max_error_m)
            .map(|l| (l.mesh.clone(), l.hit_triangle_limit, l.stats))
    });
    let snow = snow_rule(preset);
    let build_opts = |name: String, max_error_m: f64| BuildOptions {
        chunk_samples: t.chunk,
        skirt_depth_m: t.skirt_at(max_error_m),
        base_depth_m: t.base_m,
        name,
        snow: snow.clone(),
    };
    let settings = MeshSettings {
        mode: t.mode,
        grid_step: t.grid_step,
        max_error_m: t.max_error_m,
        max_triangles: t.max_triangles,
        max_vertices: t.max_vertices,
        chunk_cells,
    };
    // the same path as `verdant terrain`: mesh (or the shared level), measure as stored, build
    // what grows on it: the soil layer and every vertex's `_SURFACE`, from the species' rules on
    // this surface (the densities the scatter stage's density maps hold)
    let map_px = size.map(crate::terrain::layers::map_px);
    let cover = |scene: &Scene| crate::scene::ground_cover::cover(preset, scene, map_px);
    let job_error = |e: crate::terrain::job::JobError| StageError::of(Stage::Terrain.name(), &e, e.to_string());
    let meshed = match (band_layers, assembled(t.max_error_m, "terrain"), normal_rows(t.max_error_m)?, ready) {
        // (the map not read: heights exact in f32, so the error as stored is the f64 error, or
        // the bands measured it)
        (Some(layers), Some(scene), Some(rows), Some(ready)) if held.get().is_none() => {
            let label = source_label(t);
            // (bands of an earlier unit that do not say it join only where the heights are exact)
            let f64_m = bands_f64_m.unwrap_or(ready.2.max_error_m);
            crate::terrain::job::finish_assembled(&settings, &label, "terrain", ready, f64_m, layers, scene, rows)
                .map_err(job_error)?
        }
        (layers, scene, rows, ready) => {
            let hf = map()?;
            // (a banded terrain's f64 error from its units' figures when they measured it)
            let ready = ready.map(|(mesh, hit, stats)| (mesh, hit, stats, bands_f64_m));
            mesh_and_build(
                hf,
                &settings,
                &Storage::f32(hf),
                &build_opts("terrain".into(), t.max_error_m),
                &source_label(t),
                ready,
                match (layers, scene) {
                    (Some(layers), Some(scene)) => LayersFrom::Assembled(Box::new(layers), Box::new(scene)),
                    (Some(layers), None) => LayersFrom::Baked(Box::new(layers)),
                    (None, _) => LayersFrom::Bake(Some(&cover)),
                },
                rows,
            )
            .map_err(job_error)?
        }
    };
    if let (Some(m), Some(key), false) = (memo, &memo_key, from_memo) {
        // kept for the next build of this terrain (a store that fails only costs a re-mesh then)
        let mut meshes =
            Meshes { chain, main: (meshed.mesh.clone(), meshed.hit_triangle_limit, meshed.stats), sizes: Vec::new() };
        let blob = meshes.to_blob();
        if let Ok(json) = serde_json::to_string(&meshes) {
            let _ = m.cache.store_blob(MESH_MEMO_STAGE, key, &json, &blob);
        }
        chain = meshes
            .from_blob(&blob)
            .ok_or_else(|| f("the terrain's meshes did not read back from their own arrays".into()))?
            .chain;
    }
    let figures = meshed.figures_of(size, t.cell_size_m(), &settings, voids_filled);
    // The chain level the main mesh is (the same mesh, built with the same options but its name):
    // its files are the main scene's under the level's names, written from the main scene itself
    // rather than built, textured and baked a second time beside it.
    let main_level = chain
        .iter()
        .find(|l| t.mode == MeshMode::Tin && l.max_error_requested_m == t.max_error_m && l.mesh == meshed.mesh)
        .map(|l| l.level);
    // (a shared level's meshing and measuring time is counted under `lods`)
    let [mesh_s, analyze_s, build_s] = meshed.seconds;
    let Meshed { mut scene, layers, .. } = meshed;
    // a level's scene: from the bands' chunks (weighed already), else built from the map
    let textured = |bound: f64,
                    name: &str,
                    mesh: &crate::terrain::sample_mesh::SampleMesh|
     -> Result<(Scene, NormalMapReport), StageError> {
        let rows = normal_rows(bound)?;
        let colour = |e| f(format!("cannot encode the terrain's base colour: {e}"));
        let mut scene = match assembled(bound, name) {
            Some(mut scene) => {
                layers.put_base_color(&mut scene, "terrain").map_err(colour)?;
                scene
            }
            None => {
                let hf = map()?;
                let mut scene =
                    build_scene(hf, mesh, &build_opts(name.to_string(), bound)).map_err(|e| input(e.to_string()))?;
                layers.texture(&mut scene, hf, "terrain").map_err(colour)?;
                scene
            }
        };
        let normal = match rows {
            Some(rows) => put_normal_map(&mut scene, name, layers.report.map_px, rows),
            None => bake_normal_map(map()?, &mut scene, name, layers.report.map_px),
        }
        .map_err(|e| f(format!("cannot bake the normal map of {name}: {e}")))?;
        Ok((scene, normal))
    };

    let t1 = Instant::now();
    let mut files = write_formats(preset, &scene, scene_dir, "terrain")?;
    let pngs = layers.weight_pngs().map_err(|e| f(format!("cannot encode the layer weight map: {e}")))?;
    for (k, png) in pngs.iter().enumerate() {
        let weights = PathBuf::from("terrain").join(layer_map_name(k));
        export::write_atomic(&scene_dir.join(&weights), png).map_err(|e| f(e.to_string()))?;
        files.push(weights);
    }
    let export_s = t1.elapsed().as_secs_f64();

    let t1 = Instant::now();
    let mut lods = Vec::new();
    for level in chain {
        let stem = format!("terrain_LOD{}", level.level);
        let (files, normal_map) = if main_level == Some(level.level) {
            rename_terrain(&mut scene, "terrain", &stem);
            let files = write_formats(preset, &scene, scene_dir, &stem);
            rename_terrain(&mut scene, &stem, "terrain");
            (files?, figures.normal_map.clone())
        } else {
            let (lod_scene, normal_map) = textured(level.max_error_requested_m, &stem, &level.mesh)?;
            (write_formats(preset, &lod_scene, scene_dir, &stem)?, normal_map)
        };
        lods.push(LodInfo {
            level: level.level,
            files,
            max_error_requested_m: level.max_error_requested_m,
            max_error_m: level.stats.max_error_m,
            rms_error_m: level.stats.rms_error_m,
            triangles: level.mesh.triangles.len(),
            switch_distance_m: level.switch_distance_m,
            normal_map,
            skirt_m: t.skirt_at(level.max_error_requested_m),
        });
    }
    let lods_s = chain_s + t1.elapsed().as_secs_f64();

    let summary = crate::terrain::job::summarize(&scene, Vec::new());
    let chunks = if t.chunk.is_some() {
        scene
            .meshes
            .iter()
            .filter_map(|m| {
                let b = Bounds::of(&m.primitives.iter().flat_map(|p| p.positions.iter().copied()).collect::<Vec<_>>())?;
                Some(ChunkInfo { name: m.name.clone(), triangles: m.triangle_count(), bounds: b })
            })
            .collect()
    } else {
        Vec::new()
    };
    let report = TerrainStageReport {
        figures,
        input_sha256,
        output_triangles: summary.triangles,
        bounds: summary.bounds,
        files,
        chunks,
        skirt_m: t.skirt_at(t.max_error_m),
        lods,
        seconds: StageSeconds {
            decode: decode_s,
            mesh: mesh_s,
            analyze: analyze_s,
            build: build_s,
            export: export_s,
            lods: lods_s,
            total: t0.elapsed().as_secs_f64(),
        },
    };
    Ok((report, scene, layers.cover.clone()))
}

/// Renames a terrain scene built under the name `from` as building it under `to` names it: the
/// scene, its nodes and meshes (`{from}`, `{from}_chunk_<ci>_<cj>`, `{from}_base`) and its normal
/// map (`{from}_normal`; the base colour is `terrain_base_color` in every terrain scene).
fn rename_terrain(scene: &mut Scene, from: &str, to: &str) {
    let rename = |name: &mut String| {
        if let Some(rest) = name.strip_prefix(from).filter(|r| r.is_empty() || r.starts_with('_')) {
            *name = format!("{to}{rest}");
        }
    };
    rename(&mut scene.name);
    scene.nodes.iter_mut().for_each(|n| rename(&mut n.name));
    scene.meshes.iter_mut().for_each(|m| rename(&mut m.name));
    let normal = format!("{from}_normal");
    for texture in scene.textures.iter_mut().filter(|t| t.name == normal) {
        texture.name = format!("{to}_normal");
    }
}

/// File name of the k-th layer weight map (layers 4k … 4k + 3): `terrain_layers.png`, then
/// `terrain_layers_1.png` (soil).
pub fn layer_map_name(k: usize) -> String {
    if k == 0 {
        "terrain_layers.png".into()
    } else {
        format!("terrain_layers_{k}.png")
    }
}

/// Every file the terrain stage wrote, LoD levels included (scene-relative).
pub fn terrain_files(r: &TerrainStageReport) -> Vec<PathBuf> {
    let mut files = r.files.clone();
    for l in &r.lods {
        files.extend(l.files.iter().cloned());
    }
    files
}
