//! Scene tiles as units of a sharded build (`[scene] tile`): the second round of shards
//! (`verdant build PRESET --shard i/N --tiles --shards DIR...`, after every shard of the first) writes
//! each tile of its share from the first round's cache entries alone, and the merge puts those
//! tiles in place instead of writing them ([`crate::scene::view_tiles::KeptTile`]): the same bytes
//! as the tiles one build writes.
//!
//! What a tile reads, and where a unit finds it:
//! - its terrain chunks at every level: the band chunks entries (each chunk's surface with its
//!   vertex attributes, [`crate::scene::band_chunks`]) of the bands its chunks lie in, assembled
//!   as the terrain stage assembles each level's scene ([`crate::terrain::build::assemble_chunks`]),
//!   with the terrain's material, tangents and textures put on them as there;
//! - the texel rows of the terrain's textures its chunks reach: the base colour from the bands'
//!   layers entries, each level's normal map from the bands' pieces. The tile keeps only that
//!   rectangle of each texture ([`crate::scene::view_tiles`]), so the whole textures are never
//!   made: each level scene carries a stand-in naming its texture, and the tile's crop reads the
//!   rows (two whole textures equal in the rows read could be one texture in the scene's files,
//!   which the stand-ins would not show: such a tile is left to the merge);
//! - each level's switch distance: from every band piece's measure of that level (the largest
//!   error over the bands is the joined mesh's, [`crate::lod::assign_switch_distances`]);
//! - its instances: the placement units' rows of the placement tiles in it, with the variant the
//!   scatter stage assigns each row ([`crate::scatter::assign_variants`]), in table order;
//! - the species' levels: the species entries, restored into the unit's folder;
//! - with `[scene] compact`, the grid the terrain is stored on: over the box of every band's chunks
//!   at every level, as [`crate::scene::view_store`] puts it over the terrain's files.
//!
//! A tile unit's key holds every entry name of the first round (each the hash of what its unit
//! read), the `[lod]` policy, the tile's side, the grid and the tile's index, the placement tiles'
//! side, the scene's name and each species' cull distance: the merge looks a tile up by the same
//! key, so a tile built from other inputs is never put in place (it writes that tile itself).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::export::table::{PlacementRow, ToPlacementRow};
use crate::mesh::{Mesh, Scene};
use crate::scatter::Tiling;
use crate::scene::band_layers::Grows;
use crate::scene::cache::{Cache, KeyBuilder};
use crate::scene::error::{SceneBuildError, StageError};
use crate::scene::placement_rows::{self, RowsPlan};
use crate::scene::plants_stage::{self, PlantReport, SpeciesMemo};
use crate::scene::terrain_stage::{self, BandPlan};
use crate::scene::view::cull_distance;
use crate::scene::view_lod::{LodSpecies, LodTerrain};
use crate::scene::view_stage::{mesh_bounds, VIEW_ALGORITHM_VERSION};
use crate::scene::view_tiles::{self, Decoded, SceneTile, TileJob};
use crate::scene::{Format, Preset, TerrainSettings};

/// The cache stage name of a scene tile's entry.
pub const TILE_STAGE: &str = "scene-tile";

/// The main terrain file and each level's, as the terrain stage names them (scene-relative).
const MAIN_FILE: &str = "terrain/terrain.glb";

fn level_file(k: usize) -> PathBuf {
    PathBuf::from(format!("terrain/terrain_LOD{k}.glb"))
}

fn fail(message: String) -> StageError {
    StageError::Failed { stage: "view", message }
}

/// What a tile unit's entry says (`stage.json`): its record (`None`: nothing lies in the tile) and
/// how far its vertices moved in storage.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct KeptTileEntry {
    pub tile: Option<SceneTile>,
    pub quantization_m: f64,
}

/// The tile units of a preset: what every unit reads, worked out once.
pub struct TilePlan<'a> {
    preset: &'a Preset,
    t: &'a TerrainSettings,
    bands: BandPlan,
    mesh_key: String,
    grows: Grows<'a>,
    rows: Option<RowsPlan>,
    /// The tiles' side (m) and grid.
    pub tile_m: f64,
    pub grid: [u32; 2],
    placement_tiles: Option<Tiling>,
    /// What every unit's key holds but its tile.
    key: String,
}

/// The tile units of `preset`, or why its tiles are written by the merge (`Ok(Err(why))`).
pub fn plan(preset: &Preset) -> Result<Result<TilePlan<'_>, String>, SceneBuildError> {
    let Some(tile_m) = preset.scene.tile_m else { return Ok(Err("the preset has no `[scene] tile`".into())) };
    let first_mesh = preset.scene.formats.iter().find(|f| matches!(f, Format::Glb | Format::Gltf | Format::Obj));
    if first_mesh != Some(&Format::Glb) {
        return Ok(Err("the terrain's first mesh format is not glb (the view stage reads that file)".into()));
    }
    let Some(t) = &preset.terrain else { return Ok(Err("the preset has no terrain".into())) };
    let Some(bands) = terrain_stage::planned_bands(t)? else {
        return Ok(Err("the terrain is meshed whole, not in bands".into()));
    };
    if !terrain_stage::chunks_by_band(t, &bands) || t.lods.is_empty() || t.chunk.is_none() {
        return Ok(Err("the terrain's bands do not keep their chunks at every level (a base, or no lods)".into()));
    }
    let mesh_key = terrain_stage::mesh_key(preset, t)?;
    let rows = placement_rows::rows_plan(preset, t, &bands, &mesh_key)?;
    for (k, s) in preset.species.iter().enumerate() {
        let by_rows = rows.as_ref().is_some_and(|r| r.placed.get(k) == Some(&true));
        if plants_stage::makes(s) && !by_rows {
            return Ok(Err(format!(
                "species `{}` is placed in the merge (under `[snow] thin_plants`, or excluded by such a species)",
                s.rules.name
            )));
        }
    }
    let far = |n: usize| ((n - 1) as f64 * bands.cell_m) as f32 as f64;
    let grid = view_tiles::grid_of(far(bands.width), far(bands.height()), tile_m)?;
    let extent = crate::scene::ground_cover::terrain_extent(bands.width, bands.height(), bands.cell_m);
    let placement_tiles = Tiling::new(extent, preset.scatter.tile_m).ok();
    let mut k = KeyBuilder::new(TILE_STAGE, VIEW_ALGORITHM_VERSION);
    for unit in crate::scene::shard::units(preset, Path::new("."))? {
        for e in &unit.entries {
            k.add(e.as_bytes()).add(b"|");
        }
    }
    k.add(serde_json::to_string(&preset.lod).unwrap_or_default().as_bytes());
    k.add(preset.scene.name.as_bytes()).add(b"|").add(&tile_m.to_le_bytes());
    k.add(&preset.scatter.tile_m.to_le_bytes());
    for s in &preset.species {
        k.add(s.rules.name.as_bytes()).add(serde_json::to_string(&s.cull_distance_m).unwrap_or_default().as_bytes());
    }
    let grows = Grows::of(preset);
    Ok(Ok(TilePlan { preset, t, bands, mesh_key, grows, rows, tile_m, grid, placement_tiles, key: k.finish() }))
}

impl TilePlan<'_> {
    /// Tiles in the grid (row-major: tile t is (t mod nx, t div nx)).
    pub fn count(&self) -> usize {
        self.grid[0] as usize * self.grid[1] as usize
    }

    /// Cache key of tile `t`'s unit.
    pub fn key_of(&self, t: usize) -> String {
        let mut k = KeyBuilder::new(TILE_STAGE, VIEW_ALGORITHM_VERSION);
        k.add(self.key.as_bytes());
        k.add(&self.grid[0].to_le_bytes()).add(&self.grid[1].to_le_bytes()).add(&(t as u64).to_le_bytes());
        k.finish()
    }

    /// The entry name of tile `t`'s unit.
    pub fn entry_of(&self, t: usize) -> String {
        Cache::entry_name(TILE_STAGE, &self.key_of(t))
    }

    /// The tile (i, j) the kept entry of which `cache` holds, put into `scene_dir`: what the
    /// merge's view stage asks ([`view_tiles::KeptTile`]); `None` when it holds none (or another
    /// grid is asked for).
    pub fn kept(
        &self,
        cache: &Cache,
        scene_dir: &Path,
        [i, j]: [u32; 2],
        grid: [u32; 2],
    ) -> Option<Option<(SceneTile, f64)>> {
        if grid != self.grid {
            return None;
        }
        let t = j as usize * grid[0] as usize + i as usize;
        let (json, entry) = cache.lookup(TILE_STAGE, &self.key_of(t))?;
        let kept: KeptTileEntry = serde_json::from_str(&json).ok()?;
        match kept.tile {
            None => Some(None),
            Some(tile) => {
                (tile.index == [i, j]).then_some(())?;
                Cache::restore(&entry, scene_dir, &[PathBuf::from(&tile.file)]).ok()?;
                Some(Some((tile, kept.quantization_m)))
            }
        }
    }

    /// The bands whose rows hold a chunk that may go to tile row `j` (with one chunk's margin on
    /// each side, the chunks then placed by their boxes as the view stage places them).
    fn bands_of_row(&self, j: u32) -> Vec<usize> {
        let pitch = self.t.chunk.unwrap_or(1) as f64 * self.bands.cell_m;
        let lo = j as f64 * self.tile_m - pitch;
        let hi = if j + 1 == self.grid[1] { f64::INFINITY } else { (j + 1) as f64 * self.tile_m + pitch };
        let lo = if j == 0 { f64::NEG_INFINITY } else { lo };
        (0..self.bands.band_count())
            .filter(|&k| {
                let [a, b] = self.bands.rows(k);
                (b as f64 * self.bands.cell_m) >= lo && (a as f64 * self.bands.cell_m) <= hi
            })
            .collect()
    }
}

/// What every tile of a shard reads alike: each level's switch distance, the species' chains and
/// level files (restored into the shard's folder), and each species' reach.
pub struct TileInputs {
    /// Each level's file and switch distance (level 0 first).
    levels: Vec<(PathBuf, f64)>,
    /// The species the tiles instance (preset order, those with meshes): index in the preset, report.
    species: Vec<(usize, PlantReport)>,
    /// The species' level files, read.
    files: BTreeMap<PathBuf, Arc<Scene>>,
    /// `[scene] compact`: the grid every terrain mesh is stored on, over every band's chunks at
    /// every level (what [`crate::scene::view_store`] puts over the terrain's files).
    terrain_grid: Option<crate::export::quantize::MeshGrid>,
}

impl TileInputs {
    /// From `cache` (every band piece and species entry of the first round), the species restored
    /// into `dir`.
    pub fn new(plan: &TilePlan<'_>, cache: &Cache, dir: &Path) -> Result<TileInputs, StageError> {
        // each level's largest error over the bands (one piece held at a time), then its switch
        let mut largest = vec![0.0f64; plan.t.lods.len()];
        for k in 0..plan.bands.band_count() {
            let piece = terrain_stage::kept_band(&plan.mesh_key, &plan.bands, k, cache)
                .ok_or_else(|| fail(format!("band {k}'s meshes are not in the cache (build every shard first)")))?;
            for (l, m) in largest.iter_mut().enumerate() {
                let level = piece.levels.get(l).ok_or_else(|| fail(format!("band {k} has no level {l}")))?;
                *m = m.max(crate::terrain::error::largest_in_rows(&level.measure));
            }
        }
        let mut levels = Vec::with_capacity(largest.len());
        let mut previous = 0.0f64;
        for (l, &e) in largest.iter().enumerate() {
            let d = if l == 0 { 0.0 } else { plan.preset.lod.switch_distance(e).max(previous) };
            previous = d;
            levels.push((level_file(l), d));
        }
        let mut species = Vec::new();
        let mut files = BTreeMap::new();
        for (k, s) in plan.preset.species.iter().enumerate().filter(|(_, s)| plants_stage::makes(s)) {
            let key = plants_stage::species_key(plan.preset, s)?;
            if cache.lookup(plants_stage::SPECIES_MEMO_STAGE, &key).is_none() {
                return Err(fail(format!("species `{}` is not in the cache (build every shard first)", s.rules.name)));
            }
            let memo = Some(SpeciesMemo { cache, force: false });
            let Some(report) = plants_stage::species_unit(plan.preset, s, dir, memo)? else { continue };
            if report.chain.variants.is_empty() {
                continue;
            }
            for l in report.chain.variants.iter().flatten() {
                if !files.contains_key(&l.file) {
                    let path = dir.join(&l.file);
                    let scene = crate::validate::read_scene_dequantized(&path)
                        .map_err(|e| fail(format!("{}: {e}", path.display())))?;
                    files.insert(l.file.clone(), Arc::new(scene));
                }
            }
            species.push((k, report));
        }
        // `[scene] compact`: the terrain's grid, over the box of every band's chunks at every level
        // (the main mesh's among them), one band's entry held at a time
        let mut terrain_grid = None;
        if plan.preset.scene.compact != crate::export::quantize::Compact::None {
            let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
            for k in 0..plan.bands.band_count() {
                let key = crate::scene::band_chunks::chunks_key_of(&plan.grows, &plan.mesh_key, &plan.bands, k);
                let blob = crate::scene::band_chunks::kept_blob(cache, &key)
                    .ok_or_else(|| fail(format!("band {k}'s chunks are not in the cache (build every shard first)")))?;
                for level in 0..plan.bands.bounds.len() {
                    let chunks = crate::scene::band_chunks::level_of(&blob, level)
                        .ok_or_else(|| fail(format!("band {k}'s chunks entry does not read back (level {level})")))?;
                    for p in chunks.iter().flat_map(|(_, prim)| &prim.positions) {
                        for a in 0..3 {
                            lo[a] = lo[a].min(p[a]);
                            hi[a] = hi[a].max(p[a]);
                        }
                    }
                }
            }
            if lo[0].is_finite() {
                let grid = crate::export::quantize::uniform_grid(lo, hi);
                terrain_grid = Some(crate::export::quantize::MeshGrid { grid, uniform: true });
            }
        }
        Ok(TileInputs { levels, species, files, terrain_grid })
    }
}

/// A texture as the tile units stand it in for (never a PNG: its bytes name it).
fn stand_in(what: &str) -> Vec<u8> {
    format!("verdant scene tile unit: {what}").into_bytes()
}

fn refs(parts: &[(usize, Vec<u8>)]) -> Vec<(usize, &[u8])> {
    parts.iter().map(|(f, b)| (*f, &b[..])).collect()
}

/// Rows `rows` of a `width`-texel RGBA8 texture from the bands' rows (`parts`: each its first
/// row and its texels, in order), as an image.
fn window(parts: &[(usize, &[u8])], width: u32, rows: [u32; 2]) -> Result<image::DynamicImage, StageError> {
    let row_bytes = width as usize * 4;
    let mut bytes = Vec::with_capacity(row_bytes * (rows[1] - rows[0]) as usize);
    for y in rows[0] as usize..rows[1] as usize {
        let (first, texels) = parts
            .iter()
            .find(|(first, texels)| y >= *first && y < first + texels.len() / row_bytes)
            .ok_or_else(|| fail(format!("texel row {y} of the terrain's textures is in no band read")))?;
        bytes.extend_from_slice(&texels[(y - first) * row_bytes..(y - first + 1) * row_bytes]);
    }
    let image = image::RgbaImage::from_raw(width, rows[1] - rows[0], bytes)
        .ok_or_else(|| fail("a window of the terrain's textures does not hold its texels".into()))?;
    Ok(image::DynamicImage::ImageRgba8(image))
}

/// What every tile of one row of the grid reads alike, made once for the row: the main level's and
/// each level's scene of the chunks around the row (each chunk at its index in the whole scene's,
/// the others empty; the textures stood in for), the texel rows of the textures the row's chunks
/// reach, and the row's placement rows of every species.
pub struct TileRow {
    j: u32,
    main: Scene,
    /// The level files' scenes, with the species' files read.
    files: BTreeMap<PathBuf, Arc<Scene>>,
    /// The stand-ins and the texel rows they stand for (`first_row ..`), when the row has chunks.
    textures: Vec<(Vec<u8>, image::DynamicImage)>,
    first_row: u32,
    /// Why the row's tiles are left to the merge, when they are.
    left: Option<String>,
    /// Per species (as [`TileInputs::species`]): the row's placement rows, in table order.
    rows: Vec<Vec<PlacementRow>>,
}

impl TileRow {
    /// The row of the grid.
    pub fn j(&self) -> u32 {
        self.j
    }
}

/// Tile row `j` of `plan` from `cache` ([`TileRow`]).
pub fn tile_row(plan: &TilePlan<'_>, inputs: &TileInputs, j: u32, cache: &Cache) -> Result<TileRow, StageError> {
    let (preset, tt, bands) = (plan.preset, plan.t, &plan.bands);
    let [nx, _] = plan.grid;
    let pitch = tt.chunk.unwrap_or(1);
    let grid = crate::terrain::chunks::ChunkGrid::new(bands.width, bands.height(), pitch);
    let main_level = bands
        .bounds
        .iter()
        .position(|&b| b == tt.max_error_m)
        .ok_or_else(|| fail("the terrain's bands have no main level".into()))?;
    // the chunks of the bands around the row, at the main level and every level
    let near = plan.bands_of_row(j);
    let mut blobs = Vec::with_capacity(near.len());
    for &k in &near {
        let key = crate::scene::band_chunks::chunks_key_of(&plan.grows, &plan.mesh_key, bands, k);
        let blob = crate::scene::band_chunks::kept_blob(cache, &key)
            .ok_or_else(|| fail(format!("band {k}'s chunks are not in the cache (build every shard first)")))?;
        blobs.push(blob);
    }
    // a level's scene of those chunks, each at its index in the whole scene's (the others empty)
    let level_scene = |level: usize, name: &str| -> Result<Scene, StageError> {
        let mut chunks = Vec::new();
        for (blob, k) in blobs.iter().zip(&near) {
            chunks.extend(
                crate::scene::band_chunks::level_of(blob, level)
                    .ok_or_else(|| fail(format!("band {k}'s chunks entry does not read back (level {level})")))?,
            );
        }
        let at: Vec<usize> = chunks.iter().map(|([ci, cj], _)| cj * grid.nx + ci).collect();
        let mut scene = crate::terrain::build::assemble_chunks(name, bands.width, bands.height(), pitch, chunks)
            .map_err(|e| fail(format!("the bands' chunks: {e}")))?;
        if scene.meshes.len() != at.len() {
            return Err(fail("the bands' chunks are not one mesh each".into()));
        }
        let mut meshes = vec![Mesh::default(); grid.len()];
        for (m, &c) in std::mem::take(&mut scene.meshes).into_iter().zip(&at) {
            meshes[c] = m;
        }
        scene.meshes = meshes;
        Ok(scene)
    };
    let main = level_scene(main_level, "terrain")?;
    // the row's chunks: those whose boxes' centres lie in it, as the view stage places them
    let in_row = |c: usize| {
        mesh_bounds(&main.meshes[c])
            .is_some_and(|b| view_tiles::tile_of_chunk(&b, plan.tile_m, plan.grid) / nx as usize == j as usize)
    };
    let row_chunks: Vec<usize> = (0..main.meshes.len()).filter(|&c| in_row(c)).collect();

    // each level's scene as its file holds it, the textures stood in for
    let mut files = inputs.files.clone();
    for (l, (file, _)) in inputs.levels.iter().enumerate() {
        let stem = format!("terrain_LOD{l}");
        let mut scene = level_scene(l, &stem)?;
        crate::terrain::layers::put_base_color_png(&mut scene, "terrain", stand_in("base colour"));
        crate::terrain::normal_map::put_normal_texture(&mut scene, &stem, stand_in(&format!("normal map {l}")))
            .map_err(fail)?;
        files.insert(file.clone(), Arc::new(scene));
    }
    drop(blobs);

    // the texel rows the row's chunks reach at any level, from the bands' rows
    let map_px = bands.map_px();
    let (mut u, mut v) = ([f64::INFINITY, f64::NEG_INFINITY], [f64::INFINITY, f64::NEG_INFINITY]);
    for (file, _) in &inputs.levels {
        for p in row_chunks.iter().flat_map(|&c| &files[file].meshes[c].primitives) {
            for uv in &p.uvs {
                u = [u[0].min(uv[0] as f64), u[1].max(uv[0] as f64)];
                v = [v[0].min(uv[1] as f64), v[1].max(uv[1] as f64)];
            }
        }
    }
    let (mut textures, mut first_row, mut left) = (Vec::new(), 0, None);
    if !row_chunks.is_empty() && !v[0].is_finite() {
        left = Some("its chunks have no texture coordinates".to_string());
    } else if !row_chunks.is_empty() {
        let [_, y0, _, ch] = view_tiles::texel_rect(u, v, map_px[0], map_px[1]);
        let texel_rows = bands.normal_rows().ok_or_else(|| fail("the terrain's bands bake no texel rows".into()))?;
        let reached = (0..bands.band_count())
            .filter(|&k| texel_rows[k].start < (y0 + ch) as usize && texel_rows[k].end > y0 as usize);
        let mut albedo = Vec::new();
        let mut normals: Vec<Vec<(usize, Vec<u8>)>> = vec![Vec::new(); inputs.levels.len()];
        for k in reached {
            let key = terrain_stage::band_layers_key(&plan.grows, &plan.mesh_key, bands, k);
            let (_, entry) = cache
                .lookup(crate::scene::band_layers::BAND_LAYERS_STAGE, &key)
                .ok_or_else(|| fail(format!("band {k}'s layers are not in the cache (build every shard first)")))?;
            let layers = Cache::read_blob(&entry)
                .ok()
                .and_then(|b| crate::scene::band_layers::from_bytes(&b, map_px))
                .ok_or_else(|| fail(format!("band {k}'s layers entry does not read back")))?;
            albedo.push((layers.rows.first, layers.rows.albedo_rgba8));
            let piece = terrain_stage::kept_band(&plan.mesh_key, bands, k, cache)
                .ok_or_else(|| fail(format!("band {k}'s meshes are not in the cache")))?;
            for (l, out) in normals.iter_mut().enumerate() {
                let n = piece
                    .levels
                    .get(l)
                    .and_then(|p| p.normals.as_ref())
                    .ok_or_else(|| fail(format!("band {k} has no normal rows at level {l}")))?;
                if n.figures.is_empty() {
                    continue;
                }
                let strip = image::load_from_memory_with_format(&n.png, image::ImageFormat::Png)
                    .map_err(|e| fail(format!("band {k}'s normal rows at level {l}: {e}")))?
                    .into_rgba8()
                    .into_raw();
                out.push((n.first, strip));
            }
        }
        let rows_read = [y0, y0 + ch];
        textures.push((stand_in("base colour"), window(&refs(&albedo), map_px[0], rows_read)?));
        for (l, n) in normals.iter().enumerate() {
            textures.push((stand_in(&format!("normal map {l}")), window(&refs(n), map_px[0], rows_read)?));
        }
        first_row = y0;
        // two whole textures that differ differ in some row; two alike in every row read may be
        // one texture in the scene's files, which the stand-ins would not show
        for a in 0..textures.len() {
            for b in a + 1..textures.len() {
                if textures[a].1 == textures[b].1 {
                    left = Some("two of the terrain's textures are alike in its rows (they may be one texture)".into());
                }
            }
        }
    }

    // the row's rows of every species: its placement tiles', in table order
    let mut rows: Vec<Vec<PlacementRow>> = vec![Vec::new(); inputs.species.len()];
    if let (Some(rp), Some(tiling)) = (&plan.rows, plan.placement_tiles) {
        for &g in rp.groups.iter().filter(|g| g[0] < g[1]) {
            // (a group of tile rows reaching the row)
            let reaches = (g[0]..g[1]).any(|r| {
                let [_, z0, _, z1] = tiling.rect(0, r);
                view_tiles::tile_of(0.0, 0.5 * (z0 + z1), plan.tile_m, plan.grid)[1] == j
            });
            if !reaches {
                continue;
            }
            let key = placement_rows::rows_key(rp, g);
            let unit = placement_rows::kept_unit(preset, rp, cache, &key).ok_or_else(|| {
                fail(format!(
                    "the placements of tile rows {}-{} are not in the cache (build every shard first)",
                    g[0], g[1]
                ))
            })?;
            for (slot, (k, _)) in inputs.species.iter().enumerate() {
                let Some(Some(p)) = unit.get(*k) else { continue };
                let in_row = |inst: &&crate::scatter::Instance| {
                    let t = view_tiles::tile_of_row(&inst.placement_row(), Some(tiling), plan.tile_m, plan.grid);
                    t / nx as usize == j as usize
                };
                let mut mine: Vec<crate::scatter::Instance> = p.instances.iter().filter(in_row).cloned().collect();
                crate::scatter::assign_variants(&mut mine, preset.species[*k].look.table_variants());
                rows[slot].extend(mine.iter().map(|inst| inst.placement_row()));
            }
        }
    }
    Ok(TileRow { j, main, files, textures, first_row, left, rows })
}

/// Tile `t` of `plan` (of row `row`), written into `dir` (`dir/tiles/tile_<i>_<j>.glb`): its record
/// and how far its vertices moved (`Ok(Ok(None))`: nothing lies in it), or why the merge is to
/// write it (`Ok(Err(why))`).
pub fn build_tile(
    plan: &TilePlan<'_>,
    inputs: &TileInputs,
    row: &TileRow,
    t: usize,
    dir: &Path,
) -> Result<Result<Option<(SceneTile, f64)>, String>, StageError> {
    let preset = plan.preset;
    let [nx, _] = plan.grid;
    let (i, j) = ((t % nx as usize) as u32, (t / nx as usize) as u32);
    if j != row.j {
        return Err(fail(format!("tile {t} is not of row {}", row.j)));
    }
    let picked: Vec<usize> = (0..row.main.meshes.len())
        .filter(|&c| {
            mesh_bounds(&row.main.meshes[c]).is_some_and(|b| view_tiles::tile_of_chunk(&b, plan.tile_m, plan.grid) == t)
        })
        .collect();
    let placement = |r: &PlacementRow| view_tiles::tile_of_row(r, plan.placement_tiles, plan.tile_m, plan.grid);
    let picked_rows: Vec<Vec<u32>> = row
        .rows
        .iter()
        .map(|rows| (0..rows.len() as u32).filter(|&n| placement(&rows[n as usize]) == t).collect())
        .collect();
    if picked.is_empty() && picked_rows.iter().all(Vec::is_empty) {
        return Ok(Ok(None));
    }
    if let (Some(why), false) = (&row.left, picked.is_empty()) {
        return Ok(Err(why.clone()));
    }
    let map_px = plan.bands.map_px();
    let decoded: Vec<Decoded<'_>> = row
        .textures
        .iter()
        .map(|(png, image)| Decoded {
            png,
            image: std::borrow::Cow::Borrowed(image),
            first_row: row.first_row,
            size: (map_px[0], map_px[1]),
        })
        .collect();
    let lod_species: Vec<LodSpecies<'_>> = inputs
        .species
        .iter()
        .zip(&row.rows)
        .map(|((k, report), rows)| {
            let chain = &report.chain;
            let last = chain.variants.iter().filter_map(|v| v.last()).map(|l| l.switch_distance_m).fold(0.0, f64::max);
            let cull = cull_distance(preset.species[*k].cull_distance_m, chain.height_m, last, &preset.lod);
            LodSpecies { name: &preset.species[*k].rules.name, chain, rows, picked: None, cull }
        })
        .collect();
    let species: Vec<LodSpecies<'_>> =
        lod_species.iter().zip(&picked_rows).map(|(sp, p)| LodSpecies { picked: Some(p), ..*sp }).collect();
    let reach = view_tiles::species_reach(&row.files, &lod_species);
    let terrain = LodTerrain {
        main: &row.main,
        levels: &inputs.levels,
        chunked: true,
        main_file: Path::new(MAIN_FILE),
        picked: None,
        take: false,
    };
    // (`[scene] compact`: the tile's terrain meshes on the terrain's grid)
    let mut store = preset.scene.compact.write_options();
    if let Some(grid) = inputs.terrain_grid {
        for (file, _) in &inputs.levels {
            let names = picked.iter().map(|&c| &row.files[file].meshes[c].name).filter(|n| !n.is_empty());
            store.mesh_grids.extend(names.map(|n| (n.clone(), grid)));
        }
    }
    let job = TileJob {
        dir,
        placement_tiles: plan.placement_tiles,
        terrain: &terrain,
        species: &lod_species,
        policy: &preset.lod,
        store: &store,
        tile_m: plan.tile_m,
        scene_name: &preset.scene.name,
        kept: None,
    };
    std::fs::create_dir_all(dir.join(view_tiles::TILES_DIR)).map_err(|e| fail(format!("{}: {e}", dir.display())))?;
    let (tile, moved) = view_tiles::write_tile(&job, &row.files, &decoded, [i, j], &picked, &species, &reach)?;
    if !picked.is_empty() && tile.texture_texels.is_none() {
        // (the stand-ins were kept whole: the tile needs the whole textures)
        let _ = std::fs::remove_file(dir.join(&tile.file));
        return Ok(Err("it keeps the terrain's textures whole".into()));
    }
    Ok(Ok(Some((tile, moved))))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_takes_each_row_from_the_band_holding_it_and_refuses_rows_of_none() {
        // a texture 2 texels wide: one band's rows 0-1, the next band's rows 2-4
        let a: Vec<u8> = (0..16).collect();
        let b: Vec<u8> = (100..124).collect();
        let parts = [(0usize, &a[..]), (2, &b[..])];
        let w = window(&parts, 2, [1, 4]).unwrap().into_rgba8();
        assert_eq!((w.width(), w.height()), (2, 3));
        assert_eq!(&w.as_raw()[..8], &a[8..16], "row 1 from the first band");
        assert_eq!(&w.as_raw()[8..], &b[..16], "rows 2-3 from the second");
        let e = window(&parts, 2, [3, 6]).unwrap_err().to_string();
        assert!(e.contains("texel row 5"), "{e}");
    }
}
