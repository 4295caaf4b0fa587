//! Sharded builds: a scene's independent units of work built by N processes (on one machine or
//! many), then merged into the scene a single build makes, byte for byte.
//!
//! A unit is work whose result is a cache entry: each band of a chunked terrain (its meshes at every
//! level and their figures, `terrain/bands.rs`; the terrain stage then runs in the merge), or the
//! terrain stage of one meshed whole (its files and its meshes), the placements of the tile rows
//! starting in each band (`placement_rows.rs`), and each species the plants stage makes. Unit k of
//! a preset (in the order [`units`] lists them) is built by shard k mod N, but bands and their
//! placements go in runs of neighbours (band k of B to shard ⌊k·N/B⌋): `verdant build PRESET --shard i/N --out DIR` builds shard i's units into
//! `DIR/.cache/` and writes `DIR/<scene>.shard.json` (which units, which entries). `verdant merge
//! PRESET --shards DIR... --out OUT` checks that the N shards of the same preset are all there,
//! brings their entries into `OUT/.cache/` and builds the scene there: every unit is served from
//! the cache exactly as a rebuild of an unchanged scene is, so the scene is the one a single build
//! makes, whatever N and whichever shard finished first. The stages that read every unit (snow,
//! scatter, view, preview) and the manifest run in the merge.
//!
//! Not split yet (issue 18): the terrain's chunks, textures and files by band, the placements of
//! species under a snow cover, the scene files by tile (docs/sharding.md, "Limits").

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::scene::cache::{entry_digests, process_alive, temp_owner, Cache};
use crate::scene::error::SceneBuildError;
use crate::scene::pipeline::{CacheUse, StageJob, StageRunner};
use crate::scene::placement_rows;
use crate::scene::plants_stage::{self, SpeciesMemo, SPECIES_MEMO_STAGE};
use crate::scene::terrain_stage::{
    band_layers, band_piece, mesh_key, planned_bands, BandPlan, BandRows, MadeBand, MeshMemo, TerrainJob,
};
use crate::scene::Preset;

/// Shard `index` of `count` (`--shard i/N`, 0 ≤ i < N).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

/// Most shards a build may be cut into.
pub const MAX_SHARDS: usize = 65_536;

impl FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> Result<Shard, String> {
        let usage = || format!("`{s}`: a shard is INDEX/COUNT, 0 ≤ INDEX < COUNT ≤ {MAX_SHARDS} (e.g. 0/4)");
        let (i, n) = s.split_once('/').ok_or_else(usage)?;
        let (index, count): (usize, usize) =
            (i.trim().parse().map_err(|_| usage())?, n.trim().parse().map_err(|_| usage())?);
        if count == 0 || index >= count || count > MAX_SHARDS {
            return Err(usage());
        }
        Ok(Shard { index, count })
    }
}

/// One unit of a preset's build and the cache entries it leaves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Unit {
    /// `terrain`, or `species <name>`.
    pub name: String,
    pub entries: Vec<String>,
}

/// What a shard built (`<scene>.shard.json` in its folder).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardRecord {
    /// The binary that built the shard (`verdant <version> <arch>-<os>`): the merge refuses shards of
    /// another, whose bytes need not be the same.
    pub built_by: String,
    pub scene: String,
    pub shard: usize,
    pub of: usize,
    /// Every unit of the preset, in order (the merge checks its own preset lists the same).
    pub units: Vec<Unit>,
    /// Indices into `units` this shard built.
    pub built: Vec<usize>,
    /// The sha256 of every file of every cache entry this shard built, by entry name, then path
    /// inside the entry ([`crate::scene::cache::entry_digests`]): the merge checks each entry it
    /// is given against them.
    #[serde(default)]
    pub digests: BTreeMap<String, BTreeMap<String, String>>,
    /// The shard process's peak resident memory, MiB (timing, not results: it varies run to run;
    /// absent where the platform does not tell).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_memory_mib: Option<f64>,
}

/// The units of `preset`, in order: the terrain (the stage, or each of its bands when it is meshed
/// in bands: the terrain stage then runs in the merge), then every species the plants stage makes,
/// in preset order.
pub fn units(preset: &Preset, out: &Path) -> Result<Vec<Unit>, SceneBuildError> {
    Ok(planned(preset, out)?.into_iter().map(|(unit, _, _)| unit).collect())
}

/// What a unit is to build.
enum Work<'a> {
    Terrain(&'a crate::scene::TerrainSettings),
    /// The terrain, the band, the plan, the terrain's mesh key, what its layers read besides.
    Band(
        &'a crate::scene::TerrainSettings,
        usize,
        std::rc::Rc<BandPlan>,
        std::rc::Rc<String>,
        std::rc::Rc<crate::scene::band_layers::Grows<'a>>,
    ),
    Species(&'a crate::scene::SpeciesSettings),
    /// The terrain, the placement unit, the band plan, the rows plan, the terrain's mesh key.
    Placements(
        &'a crate::scene::TerrainSettings,
        usize,
        std::rc::Rc<BandPlan>,
        std::rc::Rc<crate::scene::placement_rows::RowsPlan>,
        std::rc::Rc<String>,
    ),
}

/// Which shard of N builds a unit: a terrain band and the placements of its rows go by band, the
/// bands in N runs of neighbours (band k of B to shard ⌊k·N/B⌋: placements stand on their own band
/// and its neighbours, mostly the same shard's), every other unit by its position k to k mod N.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Slot {
    Band { k: usize, of: usize },
    At(usize),
}

impl Slot {
    fn shard(self, count: usize) -> usize {
        match self {
            Slot::Band { k, of } => k * count / of.max(1),
            Slot::At(k) => k % count,
        }
    }
}

/// The units of `preset` in order, what each builds, and which shard builds it.
fn planned<'a>(preset: &'a Preset, out: &Path) -> Result<Vec<(Unit, Work<'a>, Slot)>, SceneBuildError> {
    let cache = Cache::new(out);
    let mut units = Vec::new();
    if let Some(t) = &preset.terrain {
        match planned_bands(t)? {
            Some(plan) => {
                let plan = std::rc::Rc::new(plan);
                let key = std::rc::Rc::new(mesh_key(preset, t)?);
                let grows = std::rc::Rc::new(crate::scene::band_layers::Grows::of(preset));
                for k in 0..plan.band_count() {
                    let rows = plan.rows(k);
                    let entries = crate::scene::terrain_stage::band_entries(&grows, t, &key, &plan, k);
                    let name = format!("terrain band {k} (rows {}-{})", rows[0], rows[1]);
                    let slot = Slot::Band { k, of: plan.band_count() };
                    units.push((
                        Unit { name, entries },
                        Work::Band(t, k, plan.clone(), key.clone(), grows.clone()),
                        slot,
                    ));
                }
                // the placements of the tile rows starting in each band, in that band's shard
                if let Some(rows) = placement_rows::rows_plan(preset, t, &plan, &key)? {
                    let rows = std::rc::Rc::new(rows);
                    for (g, r) in rows.groups.iter().enumerate().filter(|(_, r)| r[0] < r[1]) {
                        let entries =
                            vec![Cache::entry_name(placement_rows::ROWS_STAGE, &placement_rows::rows_key(&rows, *r))];
                        let name = format!("placements of tile rows {}-{} (band {g})", r[0], r[1]);
                        let work = Work::Placements(t, g, plan.clone(), rows.clone(), key.clone());
                        units.push((Unit { name, entries }, work, Slot::Band { k: g, of: plan.band_count() }));
                    }
                }
            }
            None => {
                let job = TerrainJob { preset, terrain: t, memo: Some(MeshMemo { cache: &cache, force: false }) };
                let mut entries = vec![Cache::entry_name("terrain", &job.key()?)];
                entries.extend(job.memo_entries());
                units.push((Unit { name: "terrain".into(), entries }, Work::Terrain(t), Slot::At(0)));
            }
        }
    }
    for s in preset.species.iter().filter(|s| plants_stage::makes(s)) {
        let key = plants_stage::species_key(preset, s)?;
        let entries = vec![Cache::entry_name(SPECIES_MEMO_STAGE, &key)];
        let slot = Slot::At(units.len());
        units.push((Unit { name: format!("species {}", s.rules.name), entries }, Work::Species(s), slot));
    }
    Ok(units)
}

/// The rows of the map the units `mine` of `planned` read: their bands', and the bands their
/// placements stand on.
fn wanted_rows(preset: &Preset, planned: &[(Unit, Work<'_>, Slot)], mine: &[usize]) -> Vec<[u32; 2]> {
    let mut bands: Vec<[u32; 2]> = Vec::new();
    for &k in mine {
        match &planned[k].1 {
            Work::Band(t, b, plan, _, _) => {
                if crate::scene::terrain_stage::chunks_by_band(t, plan) {
                    bands.push(plan.chunk_rows(*b));
                    // (the cover's rows beyond its lines may lie on bands of other shards)
                    if !preset.species.is_empty() {
                        let neighbours = crate::scene::band_chunks::cover_bands(plan, *b);
                        bands.extend(neighbours.into_iter().filter(|n| n != b).map(|n| plan.rows(n)));
                    }
                } else {
                    bands.push(plan.read_rows(*b));
                }
            }
            Work::Placements(_, g, plan, rows, _) => {
                if let Ok((_, _, reached)) = placement_rows::reach(preset, plan, rows, *g) {
                    bands.extend(reached.into_iter().map(|b| plan.rows(b)));
                }
            }
            _ => {}
        }
    }
    bands.sort_unstable();
    bands.dedup();
    bands
}

/// A band of this shard whose chunks with their vertex attributes are still to be made: they read
/// the ground cover's row beyond each of its lines, which the next band's layers hold.
struct Pending<'a> {
    t: &'a crate::scene::TerrainSettings,
    b: usize,
    plan: &'a BandPlan,
    key: &'a str,
    grows: &'a crate::scene::band_layers::Grows<'a>,
    /// Its chunks at every level as its unit built them for the normal maps (`None` when its
    /// meshes came from the cache: they are built again).
    chunks: Option<Vec<crate::scene::band_chunks::LevelChunks>>,
    /// Its rows ([`BandPlan::chunk_rows`]) when its unit read them.
    margin: Option<crate::heightfield::Heightfield>,
}

impl Pending<'_> {
    /// Makes the band's chunks entry ([`crate::scene::band_chunks::make`]): the cover's rows
    /// beyond its lines from its neighbours' layers in `cache`, or located on the surfaces of
    /// bands another shard builds (kept in `surfaces`).
    fn finish(
        self,
        preset: &Preset,
        cache: &Cache,
        force: bool,
        source: &mut BandRows,
        surfaces: &mut std::collections::HashMap<usize, std::rc::Rc<Vec<crate::mesh::Primitive>>>,
    ) -> Result<(), crate::scene::error::StageError> {
        let Pending { t, b, plan, key, grows, chunks, mut margin } = self;
        let extent = crate::scene::ground_cover::terrain_extent(plan.width, plan.height(), plan.cell_m);
        let source = std::cell::RefCell::new(source);
        // (the rows held handed over, not copied: they are read once)
        let mut rows_of = |rows: [u32; 2]| match margin.take() {
            Some(hf) if rows == plan.chunk_rows(b) => Ok(hf),
            _ => source.borrow_mut().rows(rows),
        };
        let mut edge = |n: usize, rows: std::ops::Range<usize>| {
            let made = surfaces_for(n, surfaces, &mut source.borrow_mut(), t, key, plan)?;
            Ok(crate::scene::band_layers::locate_cover(preset, &made, extent, plan.map_px(), rows))
        };
        crate::scene::band_chunks::make(grows, t, key, plan, b, (cache, force), chunks, &mut rows_of, &mut edge)
    }
}

/// Band `k`'s chunk surfaces at the main level ([`placement_rows::band_surfaces`]) from
/// `surfaces` when made already, else made from `source`'s rows and kept there.
fn surfaces_for(
    k: usize,
    surfaces: &mut std::collections::HashMap<usize, std::rc::Rc<Vec<crate::mesh::Primitive>>>,
    source: &mut BandRows,
    t: &crate::scene::TerrainSettings,
    key: &str,
    bands: &BandPlan,
) -> Result<std::rc::Rc<Vec<crate::mesh::Primitive>>, crate::scene::error::StageError> {
    if let Some(made) = surfaces.get(&k) {
        return Ok(made.clone());
    }
    let window = source.rows(bands.rows(k))?;
    let made = std::rc::Rc::new(placement_rows::band_surfaces(t, key, bands, k, &window, None)?);
    surfaces.insert(k, made.clone());
    Ok(made)
}

/// What [`ShardRecord::built_by`] says of this binary.
pub fn this_binary() -> String {
    format!("verdant {} {}-{}", env!("CARGO_PKG_VERSION"), std::env::consts::ARCH, std::env::consts::OS)
}

/// The record's file in a shard folder.
pub fn record_path(shard_dir: &Path, scene: &str) -> PathBuf {
    shard_dir.join(format!("{scene}.shard.json"))
}

/// Builds shard `shard`'s units of `preset` into `out/.cache/` and records them in
/// `out/<scene>.shard.json`. Scene files are made in a temporary folder and removed: the cache
/// entries are the shard's output.
pub fn build_shard(
    preset: &Preset,
    out: &Path,
    shard: Shard,
    force: bool,
    say: &dyn Fn(&str),
) -> Result<ShardRecord, SceneBuildError> {
    let name = &preset.scene.name;
    let io = |path: &Path| {
        let path = path.to_owned();
        move |e: std::io::Error| SceneBuildError::Io { path: path.clone(), message: e.to_string() }
    };
    fs::create_dir_all(out).map_err(io(out))?;
    let cache = Cache::new(out);
    let planned = planned(preset, out)?;
    let mine: Vec<usize> = (0..planned.len()).filter(|&k| planned[k].2.shard(shard.count) == shard.index).collect();
    remove_stale_shard_folders(out, name);
    // (a second round's record of an earlier first round no longer belongs to this folder)
    let _ = fs::remove_file(tile_record_path(out, name));
    let tmp = out.join(format!(".{name}.shard-{}", std::process::id()));
    let _ = fs::remove_dir_all(&tmp);
    fs::create_dir_all(&tmp).map_err(io(&tmp))?;
    let all: Vec<Unit> = planned.iter().map(|(u, _, _)| u.clone()).collect();
    let result = (|| -> Result<(), SceneBuildError> {
        let mut runner = StageRunner { cache: &cache, force, dir: &tmp, used: CacheUse::default(), progress: say };
        // each band's rows of the map, made as it is built
        let mut band_rows: Option<BandRows> = None;
        // the chunk surfaces of the bands placements stand on, made once: from the rows in hand
        // when this shard builds the band, else when a placement unit first reaches it
        let mut surfaces: std::collections::HashMap<usize, std::rc::Rc<Vec<crate::mesh::Primitive>>> =
            std::collections::HashMap::new();
        let places = mine.iter().any(|&k| matches!(planned[k].1, Work::Placements(..)));
        // a band whose chunks wait for the next band's layers (the cover's rows beyond its line)
        let mut pending: Option<Pending> = None;
        for &k in &mine {
            let (unit, work, _) = &planned[k];
            if !matches!(work, Work::Band(..)) {
                if let (Some(p), Some(source)) = (pending.take(), band_rows.as_mut()) {
                    p.finish(preset, &cache, force, source, &mut surfaces)?;
                }
            }
            say(&format!("shard {}/{}: {}", shard.index, shard.count, unit.name));
            match work {
                Work::Terrain(t) => {
                    let memo = Some(MeshMemo { cache: &cache, force });
                    runner.run(&TerrainJob { preset, terrain: t, memo })?;
                }
                Work::Band(t, b, plan, key, grows) => {
                    let source = band_rows.get_or_insert_with(|| {
                        // the rows of every band of this shard, read together
                        BandRows::new(t, wanted_rows(preset, &planned, &mine))
                    });
                    // (with its chunks kept, the rows they read: one more below)
                    let chunked = crate::scene::terrain_stage::chunks_by_band(t, plan);
                    let read = if chunked { plan.chunk_rows(*b) } else { plan.read_rows(*b) };
                    let c = Some((&cache, force));
                    let (chunks, margin) = if places {
                        // the band's rows read once for its meshes and its chunks' surfaces
                        let margin = source.rows(read)?;
                        let MadeBand { piece, chunks, .. } =
                            band_piece(key, t, &mut |_| Ok(margin.clone()), plan, *b, c, chunked)?;
                        let [a, z] = plan.rows(*b);
                        let window = margin.rows((a - read[0]) as usize, (z - read[0]) as usize).ok_or_else(|| {
                            crate::scene::error::StageError::Failed {
                                stage: "terrain",
                                message: format!("rows {a}-{z} are not within those read"),
                            }
                        })?;
                        let made = placement_rows::band_surfaces(t, key, plan, *b, &window, Some(&cache))?;
                        // its rows of the layers, from the same surfaces
                        let mut rows_of = |_| Ok(margin.clone());
                        band_layers(grows, t, key, plan, *b, &piece, &mut rows_of, Some(&made), c)?;
                        surfaces.insert(*b, std::rc::Rc::new(made));
                        (chunks, Some(margin))
                    } else {
                        // the band's rows read once, if at all, for its meshes and its layers
                        let mut held: Option<crate::heightfield::Heightfield> = None;
                        let mut rows_of = |_: [u32; 2]| match &held {
                            Some(hf) => Ok(hf.clone()),
                            None => {
                                let hf = source.rows(read)?;
                                held = Some(hf.clone());
                                Ok(hf)
                            }
                        };
                        let MadeBand { piece, chunks, .. } = band_piece(key, t, &mut rows_of, plan, *b, c, chunked)?;
                        band_layers(grows, t, key, plan, *b, &piece, &mut rows_of, None, c)?;
                        (chunks, held)
                    };
                    // the band before's chunks, now that this band's layers hold the cover rows
                    // beyond its line; this band's when the next band is built (or none is)
                    if let Some(p) = pending.take() {
                        p.finish(preset, &cache, force, source, &mut surfaces)?;
                    }
                    if chunked {
                        pending = Some(Pending { t, b: *b, plan, key, grows, chunks, margin });
                    }
                }
                Work::Placements(t, g, bands, rows, key) => {
                    let source =
                        band_rows.get_or_insert_with(|| BandRows::new(t, wanted_rows(preset, &planned, &mine)));
                    let mut surfaces_of = |k: usize| surfaces_for(k, &mut surfaces, source, t, key, bands);
                    placement_rows::rows_unit(preset, bands, rows, *g, &mut surfaces_of, &cache, force)?;
                }
                Work::Species(s) => {
                    plants_stage::species_unit(preset, s, &tmp, Some(SpeciesMemo { cache: &cache, force }))?;
                }
            }
        }
        if let (Some(p), Some(source)) = (pending.take(), band_rows.as_mut()) {
            p.finish(preset, &cache, force, source, &mut surfaces)?;
        }
        Ok(())
    })();
    let _ = fs::remove_dir_all(&tmp);
    result?;
    // every entry the record names must be there (a store that failed, e.g. on a full disk, is
    // only a miss for a single build, but a merge would find nothing)
    for &k in &mine {
        for entry in &all[k].entries {
            if !cache.root.join(entry).join("stage.json").is_file() {
                return Err(SceneBuildError::Io {
                    path: cache.root.join(entry),
                    message: format!(
                        "{}'s cache entry could not be stored (is the disk full?); build the shard again",
                        all[k].name
                    ),
                });
            }
        }
    }
    let digests = digests_of(&cache, mine.iter().flat_map(|&k| &all[k].entries))?;
    let record = ShardRecord {
        built_by: this_binary(),
        scene: name.clone(),
        shard: shard.index,
        of: shard.count,
        units: all,
        built: mine,
        digests,
        peak_memory_mib: crate::memory::peak_rss_bytes().map(crate::memory::mib),
    };
    if let Some(mib) = record.peak_memory_mib {
        say(&format!(
            "shard {}/{}: {} of {} units, peak memory {mib:.0} MiB",
            shard.index,
            shard.count,
            record.built.len(),
            record.units.len()
        ));
    }
    write_record(&record_path(out, name), &record)?;
    Ok(record)
}

/// The digests of `entries` of `cache` ([`entry_digests`]), by entry name.
fn digests_of<'e>(
    cache: &Cache,
    entries: impl IntoIterator<Item = &'e String>,
) -> Result<BTreeMap<String, BTreeMap<String, String>>, SceneBuildError> {
    let mut digests = BTreeMap::new();
    for entry in entries {
        let dir = cache.root.join(entry);
        let files = entry_digests(&dir).map_err(|e| SceneBuildError::Io { path: dir, message: e.to_string() })?;
        digests.insert(entry.clone(), files);
    }
    Ok(digests)
}

/// Writes a shard's record (atomically: a merge never reads half of one).
fn write_record(path: &Path, record: &impl Serialize) -> Result<(), SceneBuildError> {
    let text = serde_json::to_string_pretty(record).unwrap_or_default();
    crate::export::write_atomic(path, text.as_bytes())
        .map_err(|e| SceneBuildError::Io { path: path.to_path_buf(), message: e.to_string() })
}

/// What a shard's second round built (`<scene>.tiles.json` in its folder): the scene tiles of its
/// share ([`crate::scene::tile_units`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TileRecord {
    pub built_by: String,
    pub scene: String,
    pub shard: usize,
    pub of: usize,
    /// The tiles' grid ([0, 0] when the preset's tiles are not units: `no_units` says why).
    pub grid: [u32; 2],
    /// Each tile this shard made (its index in the grid, row-major) and its entry.
    pub tiles: Vec<(usize, String)>,
    /// Tiles of this shard's share left to the merge, and why.
    pub left: Vec<(usize, String)>,
    /// Why no tile is a unit (the merge writes every tile), when none is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub no_units: Option<String>,
    /// The sha256 of every file of every entry made, as in [`ShardRecord::digests`].
    pub digests: BTreeMap<String, BTreeMap<String, String>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_memory_mib: Option<f64>,
}

/// The second round's record in a shard folder.
pub fn tile_record_path(shard_dir: &Path, scene: &str) -> PathBuf {
    shard_dir.join(format!("{scene}.tiles.json"))
}

/// The second round of shard `shard` (`--tiles`, after every shard of the first): brings the
/// first round's entries of `shard_dirs` (all N folders, checked as the merge checks them) into
/// `out`'s cache, then makes the scene tiles of its share (tile t to shard t mod N) as cache
/// entries, and records them in `out/<scene>.tiles.json`.
pub fn build_tile_shard(
    preset: &Preset,
    out: &Path,
    shard: Shard,
    shard_dirs: &[PathBuf],
    force: bool,
    say: &dyn Fn(&str),
) -> Result<TileRecord, SceneBuildError> {
    let name = &preset.scene.name;
    let io = |path: &Path| {
        let path = path.to_owned();
        move |e: std::io::Error| SceneBuildError::Io { path: path.clone(), message: e.to_string() }
    };
    // (in the shard's own folder of the first round, where the merge looks for its record)
    let own =
        fs::read_to_string(record_path(out, name)).ok().and_then(|t| serde_json::from_str::<ShardRecord>(&t).ok());
    if own.as_ref().map(|r| (r.shard, r.of)) != Some((shard.index, shard.count)) {
        return Err(SceneBuildError::Usage(format!(
            "{}: not the folder of shard {}/{} of scene `{name}`: give the second round (--tiles) the --out of the shard's first round",
            out.display(),
            shard.index,
            shard.count
        )));
    }
    // (its record of an earlier run is replaced at the end, or gone if this round fails)
    let _ = fs::remove_file(tile_record_path(out, name));
    gather(preset, shard_dirs, out)?;
    let cache = Cache::new(out);
    let mut record = TileRecord {
        built_by: this_binary(),
        scene: name.clone(),
        shard: shard.index,
        of: shard.count,
        grid: [0, 0],
        tiles: Vec::new(),
        left: Vec::new(),
        no_units: None,
        digests: BTreeMap::new(),
        peak_memory_mib: None,
    };
    match crate::scene::tile_units::plan(preset)? {
        Err(why) => {
            say(&format!("shard {}/{}: no tile units ({why}); the merge writes the tiles", shard.index, shard.count));
            record.no_units = Some(why);
        }
        Ok(plan) => {
            record.grid = plan.grid;
            remove_stale_shard_folders(out, name);
            let tmp = out.join(format!(".{name}.shard-{}", std::process::id()));
            let _ = fs::remove_dir_all(&tmp);
            fs::create_dir_all(&tmp).map_err(io(&tmp))?;
            let result = (|| -> Result<(), SceneBuildError> {
                // (runs of neighbouring tiles, row-major: a shard's tiles share rows, and what a row's
                // tiles read alike is made once)
                let mine: Vec<usize> =
                    (0..plan.count()).filter(|t| t * shard.count / plan.count() == shard.index).collect();
                let todo: Vec<usize> = mine
                    .iter()
                    .copied()
                    .filter(|&t| force || !cache.root.join(plan.entry_of(t)).join("stage.json").is_file())
                    .collect();
                record.tiles.extend(mine.iter().filter(|t| !todo.contains(t)).map(|&t| (t, plan.entry_of(t))));
                if todo.is_empty() {
                    return Ok(());
                }
                let inputs = crate::scene::tile_units::TileInputs::new(&plan, &cache, &tmp)?;
                let [nx, _] = plan.grid;
                let mut row: Option<crate::scene::tile_units::TileRow> = None;
                for t in todo {
                    let entry = plan.entry_of(t);
                    let j = (t / nx as usize) as u32;
                    say(&format!("shard {}/{}: scene tile {} {j}", shard.index, shard.count, t % nx as usize));
                    if row.as_ref().is_none_or(|r| r.j() != j) {
                        drop(row.take()); // (the row before freed first)
                        row = Some(crate::scene::tile_units::tile_row(&plan, &inputs, j, &cache)?);
                    }
                    let row = row.as_ref().expect("made above");
                    match crate::scene::tile_units::build_tile(&plan, &inputs, row, t, &tmp)? {
                        Err(why) => {
                            say(&format!("  left to the merge: {why}"));
                            record.left.push((t, why));
                        }
                        Ok(made) => {
                            let files: Vec<PathBuf> = made.iter().map(|(tile, _)| PathBuf::from(&tile.file)).collect();
                            let kept = crate::scene::tile_units::KeptTileEntry {
                                quantization_m: made.as_ref().map_or(0.0, |(_, q)| *q),
                                tile: made.map(|(tile, _)| tile),
                            };
                            let json = serde_json::to_string_pretty(&kept).unwrap_or_default();
                            cache
                                .store(crate::scene::tile_units::TILE_STAGE, &plan.key_of(t), &tmp, &files, &json)
                                .map_err(io(&cache.root.join(&entry)))?;
                            for f in &files {
                                let _ = fs::remove_file(tmp.join(f));
                            }
                            record.tiles.push((t, entry));
                        }
                    }
                }
                Ok(())
            })();
            let _ = fs::remove_dir_all(&tmp);
            result?;
        }
    }
    record.tiles.sort();
    record.digests = digests_of(&cache, record.tiles.iter().map(|(_, e)| e))?;
    record.peak_memory_mib = crate::memory::peak_rss_bytes().map(crate::memory::mib);
    if let Some(mib) = record.peak_memory_mib {
        say(&format!(
            "shard {}/{}: {} scene tiles ({} left to the merge), peak memory {mib:.0} MiB",
            shard.index,
            shard.count,
            record.tiles.len(),
            record.left.len()
        ));
    }
    write_record(&tile_record_path(out, name), &record)?;
    Ok(record)
}

/// Brings the scene tiles the shards' second round made (`<scene>.tiles.json` in their folders,
/// where present) into `out`'s cache, each entry checked against its record's digests; the merge's
/// view stage then puts them in place ([`crate::scene::tile_units`]). Returns the tiles brought.
/// The second round is optional, so what does not check out is passed over, said through `say`,
/// and its tiles are written by the merge: a record of another binary or split (a stale one), an
/// entry missing or not as the shard wrote it.
pub fn gather_tiles(
    preset: &Preset,
    shard_dirs: &[PathBuf],
    out: &Path,
    count: usize,
    say: &dyn Fn(&str),
) -> Result<usize, SceneBuildError> {
    let name = &preset.scene.name;
    let cache = Cache::new(out);
    let mut brought = 0;
    for dir in shard_dirs {
        let path = tile_record_path(dir, name);
        let Ok(text) = fs::read_to_string(&path) else { continue };
        let r: TileRecord = match serde_json::from_str(&text) {
            Ok(r) => r,
            Err(e) => {
                say(&format!("{}: not a tile record ({e}): its tiles are written by the merge", path.display()));
                continue;
            }
        };
        if r.built_by != this_binary() || r.of != count {
            say(&format!(
                "{}: a second round of shard {}/{} by {}, not of these {count} shards by {}: its tiles are written by the merge",
                path.display(),
                r.shard,
                r.of,
                r.built_by,
                this_binary()
            ));
            continue;
        }
        let root = Cache::new(dir).root;
        for (t, entry) in &r.tiles {
            let src = root.join(entry);
            let got = entry_digests(&src).ok();
            if got.is_none() || r.digests.get(entry) != got.as_ref() {
                say(&format!(
                    "{}: scene tile {t} of shard {}/{count} is missing or differs from what the shard wrote: the merge writes it",
                    src.display(),
                    r.shard
                ));
                continue;
            }
            let fresh =
                cache.import(&src).map_err(|e| SceneBuildError::Io { path: src.clone(), message: e.to_string() })?;
            brought += usize::from(fresh || cache.root.join(entry).join("stage.json").is_file());
        }
    }
    Ok(brought)
}

/// Removes the `.NAME.shard-PID` folders of shards of scene `name` that were killed (their process
/// is gone); folders of running processes are left alone.
fn remove_stale_shard_folders(out: &Path, name: &str) {
    let Ok(items) = fs::read_dir(out) else { return };
    let prefix = format!(".{name}.shard-");
    for item in items.flatten() {
        let file = item.file_name().to_string_lossy().to_string();
        if !file.starts_with(&prefix) {
            continue;
        }
        let Some(pid) = temp_owner(&file, ".shard-") else { continue };
        if pid != std::process::id() && !process_alive(pid) {
            let _ = fs::remove_dir_all(item.path());
        }
    }
}

/// Checks that `shard_dirs` hold all N shards of `preset` (each once, all of the same N, every unit
/// built by one of them, from the same inputs) and brings their entries into `out/.cache/`. Then a
/// build of `preset` into `out` serves every unit from the cache.
pub fn gather(preset: &Preset, shard_dirs: &[PathBuf], out: &Path) -> Result<usize, SceneBuildError> {
    let name = &preset.scene.name;
    let usage = |m: String| SceneBuildError::Usage(m);
    let mut records: Vec<(PathBuf, ShardRecord)> = Vec::new();
    for dir in shard_dirs {
        let path = record_path(dir, name);
        let text = fs::read_to_string(&path).map_err(|e| {
            usage(format!("{}: {e}: not a shard folder of scene `{name}` (build it with --shard i/N)", path.display()))
        })?;
        let record: ShardRecord =
            serde_json::from_str(&text).map_err(|e| usage(format!("{}: not a shard record: {e}", path.display())))?;
        records.push((path, record));
    }
    let Some(count) = records.first().map(|(_, r)| r.of) else {
        return Err(usage(format!("scene `{name}`: no shard folder given (--shards DIR...)")));
    };
    if count == 0 || count > MAX_SHARDS {
        return Err(usage(format!("{}: a split into {count} shards (1 … {MAX_SHARDS})", records[0].0.display())));
    }
    for (path, r) in &records {
        if r.built_by != this_binary() {
            return Err(usage(format!(
                "{}: built by {}, this is {}: build every shard and the merge with one binary (their bytes may differ)",
                path.display(),
                r.built_by,
                this_binary()
            )));
        }
    }
    let mut seen: Vec<Option<&PathBuf>> = vec![None; count];
    for (path, r) in &records {
        if r.of != count {
            return Err(usage(format!(
                "{}: shard {}/{} of another split than {}/{count} (every shard must be built with the same N)",
                path.display(),
                r.shard,
                r.of,
                records[0].1.shard
            )));
        }
        match seen.get_mut(r.shard) {
            Some(Some(first)) => {
                return Err(usage(format!(
                    "shard {}/{count} given twice: {} and {}",
                    r.shard,
                    first.display(),
                    path.display()
                )))
            }
            Some(slot) => *slot = Some(path),
            None => return Err(usage(format!("{}: shard {} is not below {count}", path.display(), r.shard))),
        }
    }
    if let Some(missing) = seen.iter().position(Option::is_none) {
        return Err(usage(format!(
            "scene `{name}`: shard {missing}/{count} is missing; build it (verdant build … --shard {missing}/{count}) and give its folder"
        )));
    }
    // the units of this preset, as this merge sees it: each must be in its shard's record
    let expected: Vec<(Unit, usize)> =
        planned(preset, out)?.into_iter().map(|(unit, _, slot)| (unit, slot.shard(count))).collect();
    for (unit, shard) in &expected {
        let shard = *shard;
        let (path, record) = records.iter().find(|(_, r)| r.shard == shard).expect("every shard is present");
        let built = record.built.iter().any(|&b| record.units.get(b) == Some(unit));
        if !built {
            return Err(usage(format!(
                "{}: shard {shard}/{count} did not build {} from these inputs (was it built from another version of the preset or its files, or from the preset given by another path?); build the shard again",
                path.display(),
                unit.name
            )));
        }
    }
    // every entry as its shard wrote it: the same files, the same bytes (a folder copied between
    // machines may lose or damage one)
    // (each entry of each unit: the unit, its shard's place among the folders given, the entry's
    // name and folder there) checked first, all of them, then brought in
    let given: Vec<(&Unit, usize, &String, PathBuf)> = expected
        .iter()
        .flat_map(|(unit, shard)| {
            let at = records.iter().position(|(_, r)| r.shard == *shard).expect("every shard is present");
            let root = Cache::new(&shard_dirs[at]).root;
            unit.entries.iter().map(move |e| (unit, at, e, root.join(e)))
        })
        .collect();
    for (unit, at, entry, src) in &given {
        let (path, record) = &records[*at];
        let shard = record.shard;
        let again = format!(
            "copy the shard's folder again, or build it again (verdant build … --shard {shard}/{count} --force)"
        );
        let Some(want) = record.digests.get(*entry) else {
            return Err(usage(format!(
                "{}: the record of shard {shard}/{count} has no digest of {entry} ({}): build the shard again with this binary",
                path.display(),
                unit.name
            )));
        };
        let got = entry_digests(src).map_err(|e| {
            usage(format!("{}: shard {shard}/{count}'s entry of {}: {e}; {again}", src.display(), unit.name))
        })?;
        if let Some(file) = want.keys().chain(got.keys()).find(|f| want.get(*f) != got.get(*f)) {
            let what = match (want.get(file), got.get(file)) {
                (Some(_), None) => "is missing".to_string(),
                (None, Some(_)) => "was not written by the shard".to_string(),
                _ => "differs from what the shard wrote".to_string(),
            };
            return Err(usage(format!(
                "{}: {file} of shard {shard}/{count}'s {} {what}; {again}",
                src.display(),
                unit.name
            )));
        }
    }
    let cache = Cache::new(out);
    let mut brought = 0;
    for (_, _, _, src) in &given {
        let fresh = cache.import(src).map_err(|e| SceneBuildError::Io { path: src.clone(), message: e.to_string() })?;
        brought += usize::from(fresh);
    }
    Ok(brought)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folders_of_killed_shards_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let (dead, mine, other) =
            (".w.shard-4294967295", format!(".w.shard-{}", std::process::id()), ".v.shard-4294967295");
        for f in [dead, mine.as_str(), other] {
            fs::create_dir_all(dir.path().join(f)).unwrap();
        }
        remove_stale_shard_folders(dir.path(), "w");
        assert!(!dir.path().join(dead).exists(), "a killed shard's folder is removed");
        assert!(dir.path().join(&mine).exists() && dir.path().join(other).exists(), "others are left");
    }

    /// Records written before shards reported their peak memory still read (the field is
    /// optional), and a record with it round-trips.
    #[test]
    fn a_record_reads_with_and_without_its_peak_memory() {
        let old = r#"{"built_by": "verdant 0.1.0 x86_64-linux", "scene": "w", "shard": 1, "of": 2,
            "units": [{"name": "terrain", "entries": ["terrain-ab"]}], "built": []}"#;
        let record: ShardRecord = serde_json::from_str(old).unwrap();
        assert_eq!(record.peak_memory_mib, None);
        assert!(!serde_json::to_string(&record).unwrap().contains("peak_memory_mib"));
        let with = ShardRecord { peak_memory_mib: Some(723.5), ..record };
        let back: ShardRecord = serde_json::from_str(&serde_json::to_string(&with).unwrap()).unwrap();
        assert_eq!(back, with);
    }

    #[test]
    fn a_shard_is_index_over_count() {
        assert_eq!("0/1".parse::<Shard>(), Ok(Shard { index: 0, count: 1 }));
        assert_eq!(" 3 / 4 ".parse::<Shard>(), Ok(Shard { index: 3, count: 4 }));
        for bad in ["4/4", "1/0", "x/2", "2", "-1/3", "0/65537", ""] {
            let e = bad.parse::<Shard>().unwrap_err();
            assert!(e.contains("INDEX/COUNT"), "{bad}: {e}");
        }
    }
}
