//! Scene tiles (`[scene] tile = S`): the scene of scene_lod.glb cut into squares of S metres, each
//! a self-contained GLB that any glTF loader opens alone (`tiles/tile_<i>_<j>.glb`), and
//! `scene_tiles.json`, the index an engine streams them by (each tile's square, the box around
//! everything in it, its file and bytes, its chunks and instances).
//!
//! A tile holds the terrain chunks whose centres lie in its square, each with its whole MSFT_lod
//! chain, and the instances of the placement tiles whose centres lie in it (`tile` is a multiple of
//! `[scatter] tile`: the placement tiles in its square), grouped as scene_lod.glb groups them
//! (placement tile × variant, one chain each, with the same screen coverages): the same nodes,
//! meshes and instances, so a viewer showing every tile shows scene_lod.glb. The last row and
//! column of tiles also hold anything beyond the grid (the terrain's far edge, x = (n − 1)·cell).
//!
//! What a tile repeats: the species' levels it instances (glTF cannot refer to a mesh in another
//! file; this is what 3D Tiles does with EXT_mesh_gpu_instancing). What it does not: the terrain's
//! textures (base colour and each level's normal map cover the whole map). A tile keeps the texel
//! rectangle its chunks' texture coordinates reach, plus the texel each bilinear lookup reads
//! beyond it, and its chunks' coordinates are mapped onto that rectangle: a texel centre of the
//! whole map's texture is the same texel centre of the tile's, so a magnified lookup reads the same
//! texels with the same weights (at the map's outer edge, where the whole texture wraps around, the
//! tile's wraps onto its own far edge; mip levels are the engine's, made from the tile's texels).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::export::{self, gltf::WriteOptions};
use crate::lod::LodView;
use crate::mesh::Scene;
use crate::scene::error::StageError;
use crate::scene::view_lod::{lod_scene, LodSpecies, LodTerrain};
use crate::scene::view_stage::{mesh_bounds, Assembler};

/// The tiles' folder in the scene folder.
pub const TILES_DIR: &str = "tiles";
/// The index, in the scene folder.
pub const INDEX_FILE: &str = "scene_tiles.json";
/// `format` of the index.
pub const INDEX_FORMAT: &str = "verdant-scene-tiles";
/// `version` of the index (raised when a field changes meaning).
pub const INDEX_VERSION: u32 = 1;
/// At most this many tiles in the grid (256 × 256).
pub const MAX_TILES: u64 = 65_536;

/// One tile of the index.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SceneTile {
    /// The tile's GLB, relative to the scene folder (`/`-separated on every system).
    pub file: String,
    /// (i, j): the square x ∈ [i·S, (i+1)·S), z ∈ [j·S, (j+1)·S).
    pub index: [u32; 2],
    /// The square: [x0, z0, x1, z1] (m).
    pub rect_m: [f64; 4],
    /// The box around everything in the tile: every level of its chunks, and each instance's
    /// position within its species' reach (the farthest vertex of any of its levels from the
    /// mesh's origin) times its largest scale (m).
    pub bounds_min: [f64; 3],
    pub bounds_max: [f64; 3],
    pub bytes: u64,
    pub terrain_chunks: usize,
    /// Instances per species (species with none in the tile are left out).
    pub instances: BTreeMap<String, usize>,
    /// The texel rectangle of the terrain's textures the tile keeps, [x, y, width, height] in the
    /// whole map's texels; `None`: the textures are whole (or the tile has none).
    pub texture_texels: Option<[u32; 4]>,
}

/// `scene_tiles.json`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SceneTileIndex {
    pub format: String,
    pub version: u32,
    pub scene: String,
    /// The tiles' side (m).
    pub tile_m: f64,
    /// Tiles along x and z (tiles with nothing in them are not written).
    pub grid: [u32; 2],
    /// The LoD policy the tiles' MSFT_screencoverage values were worked out for.
    pub lod: LodView,
    pub tiles: Vec<SceneTile>,
}

/// What the view stage reports of the tiles.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SceneTilesReport {
    /// `scene_tiles.json`: the index of the tiles (what the report does not repeat: a world of
    /// 65,536 tiles would carry 40 MB of it twice).
    pub index_file: PathBuf,
    /// The tiles' side (m) and grid.
    pub tile_m: f64,
    pub grid: [u32; 2],
    /// Every tile's file (scene-relative), in the index's order.
    pub tile_files: Vec<PathBuf>,
    /// Bytes of every tile together, and of the largest.
    pub bytes: u64,
    pub largest_bytes: u64,
    /// The farthest any vertex of a tile lies from the mesh read (`[scene] compact`; 0 for f32).
    #[serde(default)]
    pub quantization_m: f64,
    pub seconds: f64,
}

impl SceneTilesReport {
    pub fn files(&self) -> Vec<PathBuf> {
        std::iter::once(self.index_file.clone()).chain(self.tile_files.iter().cloned()).collect()
    }
}

fn fail(message: String) -> StageError {
    StageError::Failed { stage: "view", message }
}

/// The tile (i, j) of a point: its square's, clamped to the grid.
pub fn tile_of(x: f64, z: f64, tile_m: f64, grid: [u32; 2]) -> [u32; 2] {
    let one = |v: f64, n: u32| ((v / tile_m).floor().max(0.0) as u64).min(n as u64 - 1) as u32;
    [one(x, grid[0]), one(z, grid[1])]
}

/// A decoded texture, for cropping it tile after tile: the whole texture, or a window of its rows
/// (a tile unit's, [`crate::scene::tile_units`]: the rows its tile reaches, from the bands').
pub(super) struct Decoded<'a> {
    /// The PNG as the terrain's file holds it (what a tile's copy of the texture is matched by).
    pub png: &'a [u8],
    /// Rows `first_row ..` of the texture, at its whole width (borrowed where many tiles crop it).
    pub image: std::borrow::Cow<'a, image::DynamicImage>,
    pub first_row: u32,
    /// The whole texture's width and height.
    pub size: (u32, u32),
}

/// What a build kept of a scene tile (a tile unit's entry, [`crate::scene::tile_units`]), given
/// the tile (i, j) and the grid: `Some(Some(..))` its record and how far its vertices moved, with
/// its file put in the scene folder; `Some(None)` a tile with nothing in it; `None` not kept.
pub type KeptTile<'a> = &'a dyn Fn([u32; 2], [u32; 2]) -> Option<Option<(SceneTile, f64)>>;

/// The inputs of [`write_tiles`].
pub(super) struct TileJob<'a> {
    pub dir: &'a Path,
    /// The placement tiles the rows' `tile` numbers name (None: rows go by their own positions).
    pub placement_tiles: Option<crate::scatter::Tiling>,
    pub terrain: &'a LodTerrain<'a>,
    pub species: &'a [LodSpecies<'a>],
    pub policy: &'a LodView,
    pub store: &'a WriteOptions,
    pub tile_m: f64,
    pub scene_name: &'a str,
    /// Tiles a build kept (a merge's, from the shards' tile units): put in place, not written.
    pub kept: Option<KeptTile<'a>>,
}

/// The tile grid over a terrain reaching `max_x`, `max_z` (m).
pub fn grid_of(max_x: f64, max_z: f64, s: f64) -> Result<[u32; 2], StageError> {
    let cells = |v: f64| ((v / s).ceil() as u64).max(1);
    let (nx, nz) = (cells(max_x), cells(max_z));
    if nx.saturating_mul(nz) > MAX_TILES {
        return Err(fail(format!(
            "the preset's `[scene] tile = {s}` cuts the terrain ({max_x:.0} m × {max_z:.0} m) into {nx} × {nz} \
             tiles, over the {MAX_TILES} a scene writes: set a larger `tile`"
        )));
    }
    Ok([nx as u32, nz as u32])
}

/// The tile (its index in the grid, row-major) a placement row goes to: where its placement
/// tile's centre lies, so each chain (placement tile × variant) is in one scene tile whole, with
/// scene_lod.glb's bounding sphere and coverages (rows of no placement tile: their own position).
pub fn tile_of_row(
    r: &crate::export::table::PlacementRow,
    placement_tiles: Option<crate::scatter::Tiling>,
    tile_m: f64,
    grid: [u32; 2],
) -> usize {
    let at = |x: f64, z: f64| {
        let [i, j] = tile_of(x, z, tile_m, grid);
        j as usize * grid[0] as usize + i as usize
    };
    match placement_tiles {
        Some(p) if r.tile < p.tiles_x.saturating_mul(p.tiles_z) => {
            let [x0, z0, x1, z1] = p.rect(r.tile % p.tiles_x, r.tile / p.tiles_x);
            at(0.5 * (x0 + x1), 0.5 * (z0 + z1))
        }
        _ => at(r.position[0] as f32 as f64, r.position[2] as f32 as f64),
    }
}

/// The tile a chunk goes to: where the centre of its box (`mesh_bounds`) lies.
pub fn tile_of_chunk((lo, hi): &([f64; 3], [f64; 3]), tile_m: f64, grid: [u32; 2]) -> usize {
    let [i, j] = tile_of(0.5 * (lo[0] + hi[0]), 0.5 * (lo[2] + hi[2]), tile_m, grid);
    j as usize * grid[0] as usize + i as usize
}

/// Each species' reach: the farthest vertex of any of its levels from the mesh's origin (every
/// level file read in `files`).
pub(super) fn species_reach(files: &BTreeMap<PathBuf, Arc<Scene>>, species: &[LodSpecies<'_>]) -> Vec<f64> {
    species
        .iter()
        .map(|sp| {
            let levels = sp.chain.variants.iter().flatten();
            let meshes = levels.filter_map(|l| files.get(&l.file)?.meshes.iter().find(|m| m.name == l.mesh));
            let points = meshes.flat_map(|m| m.primitives.iter().flat_map(|p| &p.positions));
            points.map(|p| p.iter().map(|&v| (v as f64) * (v as f64)).sum::<f64>().sqrt()).fold(0.0, f64::max)
        })
        .collect()
}

/// Writes every tile and the index into `job.dir`, reading the files through `files` (the view
/// stage's files read, handed back as they were).
pub(super) fn write_tiles(
    job: &TileJob<'_>,
    files: &mut BTreeMap<PathBuf, Arc<Scene>>,
) -> Result<SceneTilesReport, StageError> {
    let t0 = std::time::Instant::now();
    let s = job.tile_m;
    // the grid: over the terrain's chunks
    let chunk_box: Vec<Option<([f64; 3], [f64; 3])>> = job.terrain.main.meshes.iter().map(mesh_bounds).collect();
    let (max_x, max_z) =
        chunk_box.iter().flatten().fold((0.0f64, 0.0f64), |(x, z), (_, hi)| (x.max(hi[0]), z.max(hi[2])));
    let grid = grid_of(max_x, max_z, s)?;
    let nx = grid[0] as u64;
    let count = grid[0] as usize * grid[1] as usize;
    // chunks and rows of each tile, ascending
    let mut chunks: Vec<Vec<usize>> = vec![Vec::new(); count];
    for (c, b) in chunk_box.iter().enumerate() {
        if let Some(b) = b {
            chunks[tile_of_chunk(b, s, grid)].push(c);
        }
    }
    let by_placement_tile = |r: &crate::export::table::PlacementRow| tile_of_row(r, job.placement_tiles, s, grid);
    let rows: Vec<Vec<Vec<u32>>> = job
        .species
        .iter()
        .map(|sp| {
            let mut per = vec![Vec::new(); count];
            for (n, r) in sp.rows.iter().enumerate() {
                per[by_placement_tile(r)].push(n as u32);
            }
            per
        })
        .collect();

    std::fs::create_dir_all(job.dir.join(TILES_DIR))
        .map_err(|e| fail(format!("{}: {e}", job.dir.join(TILES_DIR).display())))?;
    // the tiles the build kept (a merge's, made by the shards), put in place; the others written,
    // and so is a kept tile whose chunks or instances are not the scene's (never expected: its key
    // holds everything it was made from; it is written anew rather than trusted)
    let occupied = |t: usize| !chunks[t].is_empty() || rows.iter().any(|per| !per[t].is_empty());
    let matches = |t: usize, tile: &Option<(SceneTile, f64)>| match tile {
        None => !occupied(t),
        Some((tile, _)) => {
            let counts: BTreeMap<String, usize> = job
                .species
                .iter()
                .zip(&rows)
                .filter(|(_, per)| !per[t].is_empty())
                .map(|(sp, per)| (sp.name.to_string(), per[t].len()))
                .collect();
            occupied(t) && tile.terrain_chunks == chunks[t].len() && tile.instances == counts
        }
    };
    let mut kept: BTreeMap<usize, Option<(SceneTile, f64)>> = BTreeMap::new();
    if let Some(k) = job.kept {
        for t in 0..count {
            if let Some(tile) = k([(t % nx as usize) as u32, (t / nx as usize) as u32], grid) {
                if matches(t, &tile) {
                    kept.insert(t, tile);
                }
            }
        }
    }
    let to_write = (0..count).filter(|&t| occupied(t) && !kept.contains_key(&t)).count();
    // every file a tile reads, read here once (when any tile is to be written)
    let mut asm = Assembler::with_files(job.dir, std::mem::take(files));
    let read: Result<(), StageError> = (|| {
        if to_write == 0 {
            return Ok(());
        }
        asm.shared(job.terrain.main_file)?;
        for (f, _) in job.terrain.levels {
            asm.shared(f)?;
        }
        for l in job.species.iter().flat_map(|sp| sp.chain.variants.iter().flatten()) {
            asm.shared(&l.file)?;
        }
        Ok(())
    })();
    *files = std::mem::take(&mut asm.files);
    read?;
    let reach = species_reach(files, job.species);
    let decoded = if to_write == 0 { Vec::new() } else { decode_terrain_textures(files, job.terrain)? };
    // one tile after another: two at once took a world's view stage from 0.85 to 1.0 GB (each
    // holds its meshes and its GLB's bytes) to save 0.7 s of 1.8; the textures are cropped and
    // encoded in parallel
    let mut tiles = Vec::new();
    let (mut total, mut quantization_m) = (0u64, 0.0f64);
    for t in 0..count {
        if let Some(k) = kept.remove(&t) {
            if let Some((tile, q)) = k {
                total += tile.bytes;
                quantization_m = quantization_m.max(q);
                tiles.push(tile);
            }
            continue;
        }
        if !occupied(t) {
            continue;
        }
        let (i, j) = ((t % nx as usize) as u32, (t / nx as usize) as u32);
        let species: Vec<LodSpecies<'_>> =
            job.species.iter().zip(&rows).map(|(sp, per)| LodSpecies { picked: Some(&per[t]), ..*sp }).collect();
        let (tile, q) = write_tile(job, files, &decoded, [i, j], &chunks[t], &species, &reach)?;
        total += tile.bytes;
        quantization_m = quantization_m.max(q);
        tiles.push(tile);
    }
    let index = SceneTileIndex {
        format: INDEX_FORMAT.into(),
        version: INDEX_VERSION,
        scene: job.scene_name.to_string(),
        tile_m: s,
        grid,
        lod: *job.policy,
        tiles,
    };
    let mut text = serde_json::to_vec_pretty(&index).map_err(|e| fail(e.to_string()))?;
    text.push(b'\n');
    let index_file = PathBuf::from(INDEX_FILE);
    export::write_atomic(&job.dir.join(&index_file), &text)
        .map_err(|e| fail(format!("{}: {e}", job.dir.join(&index_file).display())))?;
    Ok(SceneTilesReport {
        index_file,
        tile_m: s,
        grid,
        tile_files: index.tiles.iter().map(|t| PathBuf::from(&t.file)).collect(),
        bytes: total,
        largest_bytes: index.tiles.iter().map(|t| t.bytes).max().unwrap_or(0),
        quantization_m,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Writes tile `[i, j]` of `chunks` (its chunks) and `species` (each picking its rows); the tile
/// and the farthest its vertices moved in storage.
pub(super) fn write_tile(
    job: &TileJob<'_>,
    files: &BTreeMap<PathBuf, Arc<Scene>>,
    decoded: &[Decoded<'_>],
    [i, j]: [u32; 2],
    chunks: &[usize],
    species: &[LodSpecies<'_>],
    reach: &[f64],
) -> Result<(SceneTile, f64), StageError> {
    let s = job.tile_m;
    let terrain = LodTerrain { picked: Some(chunks), take: false, ..*job.terrain };
    let mut asm = Assembler::with_files(job.dir, files.clone());
    let terrain_meshes = lod_scene(&mut asm, &terrain, species, job.policy)?;
    let mut scene = asm.scene;

    // the box: the terrain's levels as stored, the instances within their height
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    let mut grow = |p: [f64; 3], r: f64| {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a] - r);
            hi[a] = hi[a].max(p[a] + r);
        }
    };
    for &m in &terrain_meshes {
        for p in scene.meshes[m].primitives.iter().flat_map(|p| &p.positions) {
            grow(p.map(|v| v as f64), 0.0);
        }
    }
    let mut instances = BTreeMap::new();
    for (sp, &reach) in species.iter().zip(reach) {
        let picked = sp.picked.unwrap_or(&[]);
        if picked.is_empty() {
            continue;
        }
        instances.insert(sp.name.to_string(), picked.len());
        for &n in picked {
            let r = &sp.rows[n as usize];
            grow(
                r.position.map(|v| v as f32 as f64),
                reach * r.scale.iter().fold(0.0f32, |m, &v| m.max(v.abs())) as f64,
            );
        }
    }

    let texture_texels = crop_terrain_textures(&mut scene, &terrain_meshes, decoded)?;
    scene.name = format!("{} tile {i} {j}", job.scene_name);
    let rect_m = [i as f64 * s, j as f64 * s, (i + 1) as f64 * s, (j + 1) as f64 * s];
    scene.extras = Some(serde_json::json!({ "verdant_tile": { "index": [i, j], "rect_m": rect_m } }));
    let file = format!("{TILES_DIR}/tile_{i}_{j}.glb");
    let path = job.dir.join(&file);
    export::write_scene_with(&scene, &path, job.store).map_err(|e| {
        let e = e.to_string();
        let remedy = if e.contains("4 GiB") { " (set a smaller `tile` in [scene])" } else { "" };
        fail(format!("{}: {e}{remedy}", path.display()))
    })?;
    let moved = crate::export::quantize::position_error_with(&scene, &job.store.quantization, &job.store.mesh_grids);
    drop(scene);
    let bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    let tile = SceneTile {
        file,
        index: [i, j],
        rect_m,
        bounds_min: lo,
        bounds_max: hi,
        bytes,
        terrain_chunks: chunks.len(),
        instances,
        texture_texels,
    };
    Ok((tile, moved))
}

/// The textures of the terrain's files, decoded once for every tile (in parallel).
fn decode_terrain_textures<'f>(
    files: &'f BTreeMap<PathBuf, Arc<Scene>>,
    terrain: &LodTerrain<'_>,
) -> Result<Vec<Decoded<'f>>, StageError> {
    use rayon::prelude::*;
    let mut pngs: Vec<(&str, &Vec<u8>)> = Vec::new();
    let sources = std::iter::once(terrain.main_file).chain(terrain.levels.iter().map(|(f, _)| f.as_path()));
    for f in sources {
        for t in files.get(f).into_iter().flat_map(|s| &s.textures) {
            if !pngs.iter().any(|(_, p)| **p == t.png) {
                pngs.push((&t.name, &t.png));
            }
        }
    }
    pngs.into_par_iter()
        .map(|(name, png)| {
            let image = image::load_from_memory_with_format(png, image::ImageFormat::Png)
                .map_err(|e| fail(format!("the terrain's texture `{name}`: {e} (rebuild with --force)")))?;
            let size = (image.width(), image.height());
            Ok(Decoded { png, image: std::borrow::Cow::Owned(image), first_row: 0, size })
        })
        .collect()
}

/// The texel rectangle [x, y, width, height] of a `w` × `h` texture that bilinear lookups at
/// texture coordinates within `[u0, u1] × [v0, v1]` read (clamped to the texture).
pub fn texel_rect(u: [f64; 2], v: [f64; 2], w: u32, h: u32) -> [u32; 4] {
    let span = |a: f64, b: f64, n: u32| {
        let first = (a * n as f64 - 0.5).floor().clamp(0.0, (n - 1) as f64) as u32;
        let last = ((b * n as f64 - 0.5).floor() + 1.0).clamp(0.0, (n - 1) as f64) as u32;
        (first, last.max(first) - first + 1)
    };
    let (x, cw) = span(u[0], u[1], w);
    let (y, ch) = span(v[0], v[1], h);
    [x, y, cw, ch]
}

/// Crops the textures of the terrain's meshes (`terrain`, indices into `scene.meshes`) to the
/// texels their coordinates reach and maps the coordinates onto the crop; the rectangle kept, or
/// `None` when the textures stay whole (no coordinates, textures of different sizes, a texture
/// another mesh also uses, or a rectangle that is the whole texture).
pub(super) fn crop_terrain_textures(
    scene: &mut Scene,
    terrain: &[usize],
    decoded: &[Decoded<'_>],
) -> Result<Option<[u32; 4]>, StageError> {
    let terrain: BTreeSet<usize> = terrain.iter().copied().collect();
    let textures_of = |scene: &Scene, m: usize| -> Vec<usize> {
        scene.meshes[m]
            .primitives
            .iter()
            .filter_map(|p| p.material)
            .filter_map(|k| scene.materials.get(k))
            .flat_map(|mat| mat.textures())
            .collect()
    };
    let used: BTreeSet<usize> = terrain.iter().flat_map(|&m| textures_of(scene, m)).collect();
    if used.is_empty() {
        return Ok(None);
    }
    let shared = (0..scene.meshes.len())
        .filter(|m| !terrain.contains(m))
        .any(|m| textures_of(scene, m).iter().any(|t| used.contains(t)));
    let (mut u, mut v) = ([f64::INFINITY, f64::NEG_INFINITY], [f64::INFINITY, f64::NEG_INFINITY]);
    for p in terrain.iter().flat_map(|&m| &scene.meshes[m].primitives) {
        for uv in &p.uvs {
            u = [u[0].min(uv[0] as f64), u[1].max(uv[0] as f64)];
            v = [v[0].min(uv[1] as f64), v[1].max(uv[1] as f64)];
        }
    }
    if shared || !u[0].is_finite() || !v[0].is_finite() {
        return Ok(None);
    }
    // each texture as decoded from the terrain's files (a texture of another file stays whole)
    let mut of = BTreeMap::new();
    for &t in &used {
        match decoded.iter().position(|d| *d.png == scene.textures[t].png[..]) {
            Some(k) => of.insert(t, k),
            None => return Ok(None),
        };
    }
    let sizes: BTreeSet<(u32, u32)> = of.values().map(|&k| decoded[k].size).collect();
    let [(w, h)] = sizes.into_iter().collect::<Vec<_>>()[..] else { return Ok(None) };
    let rect = texel_rect(u, v, w, h);
    if rect == [0, 0, w, h] {
        return Ok(None);
    }
    let [x0, y0, cw, ch] = rect;
    // (a window of rows must hold the rectangle's)
    for &k in of.values() {
        let d = &decoded[k];
        if y0 < d.first_row || y0 + ch > d.first_row + d.image.height() {
            return Err(fail(format!(
                "texel rows {y0}-{} of the terrain's textures are not among the rows read ({}-{})",
                y0 + ch,
                d.first_row,
                d.first_row + d.image.height()
            )));
        }
    }
    let crops: Vec<(usize, Result<Vec<u8>, String>)> = {
        use rayon::prelude::*;
        let work: Vec<(usize, &Decoded)> = of.iter().map(|(&t, &k)| (t, &decoded[k])).collect();
        work.into_par_iter()
            .map(|(t, d)| {
                let mut bytes = Vec::new();
                let r = d
                    .image
                    .crop_imm(x0, y0 - d.first_row, cw, ch)
                    .write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png)
                    .map(|_| bytes)
                    .map_err(|e| e.to_string());
                (t, r)
            })
            .collect()
    };
    for (t, r) in crops {
        scene.textures[t].png =
            r.map_err(|e| fail(format!("the terrain's texture `{}`: {e}", scene.textures[t].name)))?;
    }
    for &m in &terrain {
        for p in &mut scene.meshes[m].primitives {
            for uv in &mut p.uvs {
                *uv = [
                    ((uv[0] as f64 * w as f64 - x0 as f64) / cw as f64) as f32,
                    ((uv[1] as f64 * h as f64 - y0 as f64) / ch as f64) as f32,
                ];
            }
        }
    }
    Ok(Some(rect))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_fall_in_their_square_and_the_grid_holds_what_lies_beyond() {
        let g = [4, 3];
        assert_eq!(tile_of(0.0, 0.0, 100.0, g), [0, 0]);
        assert_eq!(tile_of(99.999, 100.0, 100.0, g), [0, 1]);
        assert_eq!(tile_of(400.0, 300.0, 100.0, g), [3, 2]);
        assert_eq!(tile_of(-1.0, 1e9, 100.0, g), [0, 2]);
    }

    #[test]
    fn the_texel_rectangle_holds_every_texel_a_lookup_reads() {
        // 16 texels; coordinates 0.25..0.5 → texel centres 3.5..7.5 → texels 3..8
        assert_eq!(texel_rect([0.25, 0.5], [0.0, 1.0], 16, 8), [3, 0, 6, 8]);
        // on a texel centre exactly: the next texel too (weight 0, but read)
        assert_eq!(texel_rect([4.5 / 16.0, 4.5 / 16.0], [0.5, 0.5], 16, 8), [4, 3, 2, 2]);
        // clamped to the texture
        assert_eq!(texel_rect([-0.1, 1.2], [0.99, 1.0], 16, 8), [0, 7, 16, 1]);
    }
}
