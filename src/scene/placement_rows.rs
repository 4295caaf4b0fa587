//! Placements by rows: a shard's unit of the scatter stage (docs/sharding.md). The tile rows
//! starting in each band of a terrain meshed in bands are placed alone, on the surface of the bands
//! they reach (each band's chunks rebuilt from its rows and band piece,
//! [`crate::terrain::build::band_chunk_surfaces`], in the whole mesh's order, which the surface
//! index answers as the whole mesh: [`crate::scatter::surface`]), for every species that can be:
//! not thinned by snow (the snow stage's cover mask is the whole terrain's) and excluded by no
//! species that cannot. A species excluded by an earlier one is given that one's instances of its
//! rows widened by the radius, placed in the same unit. The merge's scatter stage joins the units'
//! instances in row order and sums their rule counts: the whole run's, bit for bit
//! ([`crate::scatter::scatter_species_in_rows`]); it makes the estimate and checks
//! `max_instances` on the join, and runs the analyzer, density maps and tables as a build does.

use crate::heightfield::Heightfield;
use crate::mesh::Primitive;
use crate::plants::SpeciesKind;
use crate::scatter::{Instance, RuleCounts, SurfaceIndex, Tiling};
use crate::scene::cache::{Cache, KeyBuilder};
use crate::scene::error::StageError;
use crate::scene::scatter_stage::Joined;
use crate::scene::terrain_stage::{kept_band, BandPlan};
use crate::scene::{Format, Preset, TerrainSettings};
use crate::terrain::bands::build_band_window;

/// Cache entries of placement units: `placements-rows-<key>`.
pub const ROWS_STAGE: &str = "placements-rows";

/// Version of a unit's bytes for given inputs (with the scatter stage's).
const ROWS_VERSION: u32 = 1;

fn fail(message: String) -> StageError {
    StageError::Failed { stage: "scatter", message }
}

fn bad_input(message: String) -> StageError {
    StageError::Input { stage: "scatter", message }
}

/// How a preset's placements are cut into units.
#[derive(Debug, Clone, PartialEq)]
pub struct RowsPlan {
    /// Tile rows `[first, end)` of each unit (the rows starting in a band; bands no row starts in
    /// have none).
    pub groups: Vec<[u32; 2]>,
    /// Per species (preset order): placed in the units.
    pub placed: Vec<bool>,
    /// The scatter extent: the terrain surface's bounds, as the whole mesh's f32 positions give.
    pub extent: [f64; 4],
    /// What every unit's key holds but its rows ([`rows_key`]): hashed once, since it reads
    /// every map and look input.
    key: String,
}

/// The extent of a `width` × `height` map of `cell` m as the terrain's f32 positions span it.
fn extent_of(width: usize, height: usize, cell: f64) -> [f64; 4] {
    let far = |n: usize| ((n - 1) as f64 * cell) as f32 as f64;
    [0.0, 0.0, far(width), far(height)]
}

/// The units of `preset`'s placements on a terrain meshed in bands by `bands` (`mesh_key`: the
/// terrain's [`crate::scene::terrain_stage::mesh_key`]); `None` when no species can be placed in
/// units, or the terrain writes no glTF file (the scatter stage then reads it back from its OBJ,
/// which does not read back as written: [`crate::scene::pipeline::TerrainHandoff`]).
pub fn rows_plan(
    preset: &Preset,
    t: &TerrainSettings,
    bands: &BandPlan,
    mesh_key: &str,
) -> Result<Option<RowsPlan>, StageError> {
    if t.chunk.is_none() || !preset.scene.formats.iter().any(|f| matches!(f, Format::Glb | Format::Gltf)) {
        return Ok(None);
    }
    let snow_thins = preset.snow.as_ref().is_some_and(|s| s.thin_plants > 0.0);
    let mut placed: Vec<bool> = Vec::with_capacity(preset.species.len());
    for s in &preset.species {
        let thinned = snow_thins && matches!(s.kind, SpeciesKind::Grass | SpeciesKind::Flower);
        let needs_outside = s.rules.exclusions.iter().any(|ex| {
            ex.species != s.rules.name
                && preset.species.iter().zip(&placed).any(|(e, &p)| e.rules.name == ex.species && !p)
        });
        placed.push(!thinned && !needs_outside);
    }
    if !placed.iter().any(|&p| p) {
        return Ok(None);
    }
    let extent = extent_of(bands.width, bands.height(), bands.cell_m);
    let Ok(tiling) = Tiling::new(extent, preset.scatter.tile_m) else { return Ok(None) };
    // the first tile row starting at or after each band's first row
    let starts: Vec<u32> = (0..bands.band_count())
        .map(|k| {
            let z = (bands.lines[k] as f64 * bands.cell_m) as f32 as f64;
            (0..tiling.tiles_z).find(|&r| tiling.rect(0, r)[1] >= z).unwrap_or(tiling.tiles_z)
        })
        .collect();
    let mut groups = Vec::new();
    for k in 0..starts.len() {
        let end = starts.get(k + 1).copied().unwrap_or(tiling.tiles_z);
        groups.push([starts[k], end]);
    }
    // the terrain's meshes, what the chunks' surfaces are built with, the scatter settings, seed,
    // every species and the maps they read, which species the units place
    let mut k = KeyBuilder::new(ROWS_STAGE, ROWS_VERSION);
    k.add(crate::scene::scatter_stage::scatter_key(preset, mesh_key)?.as_bytes());
    k.add(&placed.iter().map(|&p| p as u8).collect::<Vec<u8>>());
    k.add(&t.chunk.unwrap_or(0).to_le_bytes());
    k.add(&t.skirt_at(t.max_error_m).unwrap_or(-1.0).to_le_bytes());
    k.add(&t.max_error_m.to_le_bytes());
    Ok(Some(RowsPlan { groups, placed, extent, key: k.finish() }))
}

/// Key of the unit of tile rows `rows` of `plan`.
pub fn rows_key(plan: &RowsPlan, rows: [u32; 2]) -> String {
    let mut k = KeyBuilder::new(ROWS_STAGE, ROWS_VERSION);
    k.add(plan.key.as_bytes());
    k.add(&rows[0].to_le_bytes());
    k.add(&rows[1].to_le_bytes());
    k.finish()
}

/// One species' placements in a unit's rows.
#[derive(Debug, Clone, PartialEq)]
pub struct RowsPlacement {
    pub instances: Vec<Instance>,
    pub counts: RuleCounts,
}

/// The tile rows covering z in `[z0, z1]`.
fn rows_over(tiling: &Tiling, z0: f64, z1: f64) -> [u32; 2] {
    let (_, first) = tiling.tile_xz(tiling.extent[0], z0);
    let (_, last) = tiling.tile_xz(tiling.extent[0], z1);
    [first, last + 1]
}

/// The rows each species is placed over in unit `rows` (preset order; empty `[0, 0]` where
/// none): the unit's own for a species it places, widened for an earlier species by the radius of
/// every exclusion a later one has around it.
fn needed_rows(preset: &Preset, plan: &RowsPlan, tiling: &Tiling, rows: [u32; 2]) -> Result<Vec<[u32; 2]>, StageError> {
    let n = preset.species.len();
    let mut need = vec![[0u32, 0u32]; n];
    for i in (0..n).rev() {
        if plan.placed[i] {
            need[i] = union(need[i], rows);
        }
        if need[i][0] >= need[i][1] {
            continue;
        }
        let reach = crate::scatter::rows_reach(plan.extent, tiling.tile_m, need[i]).map_err(|e| fail(e.to_string()))?;
        let s = &preset.species[i];
        for ex in s.rules.exclusions.iter().filter(|ex| ex.species != s.rules.name) {
            let Some(e) = preset.species[..i].iter().position(|e| e.rules.name == ex.species) else { continue };
            let r = ex.radius_m;
            need[e] = union(need[e], rows_over(tiling, reach[0] - r, reach[1] + r));
        }
    }
    Ok(need)
}

fn union(a: [u32; 2], b: [u32; 2]) -> [u32; 2] {
    if a[0] >= a[1] {
        b
    } else if b[0] >= b[1] {
        a
    } else {
        [a[0].min(b[0]), a[1].max(b[1])]
    }
}

/// What unit `g` reads: the rows each species is placed over, the z range of the surface they
/// read, and the bands within a sample of it (whose chunks it is given).
#[allow(clippy::type_complexity)]
pub fn reach(
    preset: &Preset,
    bands: &BandPlan,
    plan: &RowsPlan,
    g: usize,
) -> Result<(Vec<[u32; 2]>, [f64; 2], Vec<usize>), StageError> {
    let tiling = Tiling::new(plan.extent, preset.scatter.tile_m).map_err(|e| bad_input(e.to_string()))?;
    let need = needed_rows(preset, plan, &tiling, plan.groups[g])?;
    let (mut z0, mut z1) = (f64::INFINITY, f64::NEG_INFINITY);
    for r in need.iter().filter(|r| r[0] < r[1]) {
        let reach = crate::scatter::rows_reach(plan.extent, tiling.tile_m, *r).map_err(|e| fail(e.to_string()))?;
        z0 = z0.min(reach[0]);
        z1 = z1.max(reach[1]);
    }
    let reached = (0..bands.band_count())
        .filter(|&k| {
            let [a, b] = bands.rows(k);
            let (za, zb) = (a as f64 * bands.cell_m, b as f64 * bands.cell_m);
            zb >= z0 - bands.cell_m && za <= z1 + bands.cell_m
        })
        .collect();
    Ok((need, [z0, z1], reached))
}

/// The chunks' surfaces of band `k` of `bands` (positions and triangles: what a surface index
/// reads), built from `window` (the band's rows) and the band's main mesh: its piece's when
/// `cache` holds it, else that level meshed alone (the same mesh: a band meshes each bound on its
/// own; not kept).
pub fn band_surfaces(
    t: &TerrainSettings,
    mesh_key: &str,
    bands: &BandPlan,
    k: usize,
    window: &Heightfield,
    cache: Option<&Cache>,
) -> Result<Vec<Primitive>, StageError> {
    let [a, b] = bands.rows(k);
    let main = bands.bounds.iter().position(|&b| b == t.max_error_m).unwrap_or(0);
    let pitch = t.chunk.ok_or_else(|| fail("placements by rows need a chunked terrain".into()))?;
    let mesh = match cache.and_then(|c| kept_band(mesh_key, bands, k, c)) {
        Some(mut piece) => piece.levels.swap_remove(main).mesh,
        None => {
            let bound = [bands.bounds[main]];
            let chunk_cells = crate::terrain::regions::chunk_cells(Some(pitch));
            let mut piece =
                build_band_window(window, a, &bound, t.max_vertices, chunk_cells, bands.fixed(k)).map_err(|error| {
                    let e = crate::terrain::job::JobError::Terrain {
                        source_label: crate::scene::terrain_stage::source_label(t),
                        error,
                    };
                    StageError::of(crate::scene::pipeline::Stage::Terrain.name(), &e, e.to_string())
                })?;
            piece.levels.swap_remove(0).mesh
        }
    };
    let chunks = crate::terrain::build::band_chunk_surfaces(
        window,
        a as usize,
        bands.height(),
        &mesh,
        pitch,
        t.skirt_at(t.max_error_m),
    )
    .map_err(|e| fail(format!("the terrain's chunks of rows {a}-{b}: {e}")))?;
    Ok(chunks.into_iter().map(|(_, p)| p).collect())
}

/// A band's chunk surfaces, by band ([`band_surfaces`]; kept by the caller between units).
pub type SurfacesOf<'a> = dyn FnMut(usize) -> Result<std::rc::Rc<Vec<Primitive>>, StageError> + 'a;

/// Places unit `g` of `plan`: every species it places, in its rows (`None` for the others), on
/// the chunks `surfaces` gives of the bands its rows reach ([`reach`]).
pub fn place_rows(
    preset: &Preset,
    bands: &BandPlan,
    plan: &RowsPlan,
    g: usize,
    surfaces: &mut SurfacesOf<'_>,
) -> Result<Vec<Option<RowsPlacement>>, StageError> {
    let rows = plan.groups[g];
    let (need, [z0, z1], reached) = reach(preset, bands, plan, g)?;
    let mut held = Vec::with_capacity(reached.len());
    for k in reached {
        held.push(surfaces(k)?);
    }
    let prims: Vec<&Primitive> = held.iter().flat_map(|h| h.iter()).collect();
    let parts: Vec<(&[[f32; 3]], &[u32])> = prims.iter().map(|p| (&p.positions[..], &p.indices[..])).collect();
    let surface = SurfaceIndex::covering(&parts, [z0, z1]);
    let vegetation = crate::scene::ground_cover::vegetation_map(preset, "scatter")?;
    // each species over its rows, as runs of the rows before, of, and after the unit's
    let mut placed: Vec<(String, Vec<Instance>)> = Vec::new();
    let mut out = Vec::with_capacity(preset.species.len());
    for (i, s) in preset.species.iter().enumerate() {
        let [first, end] = need[i];
        if first >= end {
            out.push(None);
            continue;
        }
        let (density, mask) = crate::scene::ground_cover::rule_maps(s, vegetation.as_ref(), "scatter")?;
        let earlier: Vec<(&str, &[Instance])> = placed.iter().map(|(n, v)| (n.as_str(), &v[..])).collect();
        let mut all = Vec::new();
        let mut own = None;
        for part in [[first, rows[0].max(first)], [rows[0].max(first), rows[1].min(end)], [rows[1].min(end), end]] {
            if part[0] >= part[1] {
                continue;
            }
            let run = crate::scatter::scatter_species_in_rows(
                &surface,
                plan.extent,
                &s.rules,
                density.as_ref(),
                mask.as_ref(),
                &earlier,
                preset.scatter.tile_m,
                preset.scene.seed,
                None,
                Some(part),
            )
            .map_err(|e| bad_input(format!("tile rows {}-{}: {e}", part[0], part[1])))?;
            if part == [rows[0].max(first), rows[1].min(end)] && plan.placed[i] {
                own = Some(RowsPlacement { instances: run.instances.clone(), counts: run.counts });
            }
            all.extend(run.instances);
        }
        out.push(own);
        placed.push((s.rules.name.clone(), all));
    }
    if surface.strayed() {
        return Err(fail(format!(
            "placing tile rows {}-{} read the terrain outside the bands they were given (z {z0}-{z1}); \
             this is a bug, please report it (a build without --shard is not affected)",
            rows[0], rows[1]
        )));
    }
    Ok(out)
}

/// A unit's placements as kept in the cache: per species placed, `name count` words, then its
/// instances, 64 bytes each (little-endian; every bit of every field).
pub fn to_bytes(preset: &Preset, placements: &[Option<RowsPlacement>]) -> (String, Vec<u8>) {
    let mut blob = Vec::new();
    let mut species = Vec::new();
    for (s, p) in preset.species.iter().zip(placements) {
        let Some(p) = p else { continue };
        species.push(serde_json::json!({ "name": s.rules.name, "count": p.instances.len(), "rules": p.counts }));
        for i in &p.instances {
            i.position.iter().for_each(|v| blob.extend_from_slice(&v.to_le_bytes()));
            i.rotation.iter().for_each(|v| blob.extend_from_slice(&v.to_le_bytes()));
            i.scale.iter().for_each(|v| blob.extend_from_slice(&v.to_le_bytes()));
            blob.extend_from_slice(&i.yaw_deg.to_le_bytes());
            blob.extend_from_slice(&i.tile.to_le_bytes());
            blob.extend_from_slice(&i.variant.to_le_bytes());
        }
    }
    (serde_json::json!({ "species": species }).to_string(), blob)
}

/// [`to_bytes`] read back for `preset` (`None` when they do not read as its species' placements).
pub fn from_bytes(preset: &Preset, plan: &RowsPlan, json: &str, blob: &[u8]) -> Option<Vec<Option<RowsPlacement>>> {
    let v: serde_json::Value = serde_json::from_str(json).ok()?;
    let listed = v.get("species")?.as_array()?;
    let mut listed = listed.iter();
    let mut at = 0usize;
    let mut out = Vec::with_capacity(preset.species.len());
    let word4 = |b: &[u8], k: usize| -> [u8; 4] { b[k..k + 4].try_into().unwrap_or_default() };
    for (s, &placed) in preset.species.iter().zip(&plan.placed) {
        if !placed {
            out.push(None);
            continue;
        }
        let e = listed.next()?;
        if e.get("name")?.as_str()? != s.rules.name {
            return None;
        }
        let count = e.get("count")?.as_u64()? as usize;
        let counts: RuleCounts = serde_json::from_value(e.get("rules")?.clone()).ok()?;
        let bytes = blob.get(at..at.checked_add(count.checked_mul(INSTANCE_BYTES)?)?)?;
        at += bytes.len();
        let instances = bytes
            .chunks_exact(INSTANCE_BYTES)
            .map(|b| {
                let f64_at = |k: usize| f64::from_le_bytes(b[k..k + 8].try_into().unwrap_or_default());
                let f32_at = |k: usize| f32::from_le_bytes(word4(b, k));
                Instance {
                    position: [f64_at(0), f64_at(8), f64_at(16)],
                    rotation: [f32_at(24), f32_at(28), f32_at(32), f32_at(36)],
                    scale: [f32_at(40), f32_at(44), f32_at(48)],
                    yaw_deg: f32_at(52),
                    tile: u32::from_le_bytes(word4(b, 56)),
                    variant: u32::from_le_bytes(word4(b, 60)),
                }
            })
            .collect();
        out.push(Some(RowsPlacement { instances, counts }));
    }
    (listed.next().is_none() && at == blob.len()).then_some(out)
}

const INSTANCE_BYTES: usize = 64;

/// Unit `g` from `cache` when it holds it (unless `force`), else placed ([`place_rows`]) and
/// stored there.
#[allow(clippy::too_many_arguments)]
pub fn rows_unit(
    preset: &Preset,
    bands: &BandPlan,
    plan: &RowsPlan,
    g: usize,
    surfaces: &mut SurfacesOf<'_>,
    cache: &Cache,
    force: bool,
) -> Result<Vec<Option<RowsPlacement>>, StageError> {
    let key = rows_key(plan, plan.groups[g]);
    if !force {
        if let Some(kept) = kept_unit(preset, plan, cache, &key) {
            return Ok(kept);
        }
    }
    let placements = place_rows(preset, bands, plan, g, surfaces)?;
    let (json, blob) = to_bytes(preset, &placements);
    // (a store that fails only costs placing the rows again, or a shard that says so)
    let _ = cache.store_blob(ROWS_STAGE, &key, &json, &blob);
    Ok(placements)
}

/// Unit `key`'s placements as `cache` holds them (`None` when it does not, or not whole).
pub fn kept_unit(preset: &Preset, plan: &RowsPlan, cache: &Cache, key: &str) -> Option<Vec<Option<RowsPlacement>>> {
    let (json, entry) = cache.lookup(ROWS_STAGE, key)?;
    from_bytes(preset, plan, &json, &Cache::read_blob(&entry).ok()?)
}

/// Every unit's placements joined (rows in order, counts summed) when `cache` holds every unit
/// of `plan` (a merge's cache); `None` otherwise (the scatter stage then places every species
/// whole).
pub fn joined(
    preset: &Preset,
    plan: &RowsPlan,
    cache: &Cache,
) -> Result<Option<Vec<Option<RowsPlacement>>>, StageError> {
    let mut out: Vec<Option<RowsPlacement>> = plan
        .placed
        .iter()
        .map(|&p| p.then(|| RowsPlacement { instances: Vec::new(), counts: RuleCounts::default() }))
        .collect();
    for &rows in plan.groups.iter().filter(|r| r[0] < r[1]) {
        let key = rows_key(plan, rows);
        let Some(unit) = kept_unit(preset, plan, cache, &key) else { return Ok(None) };
        for (o, u) in out.iter_mut().zip(unit) {
            if let (Some(o), Some(u)) = (o.as_mut(), u) {
                o.instances.extend(u.instances);
                o.counts.add(&u.counts);
            }
        }
    }
    Ok(Some(out))
}

/// [`joined`] for a preset's terrain: its band plan and rows plan worked out, `None` where it has
/// none.
pub fn joined_for(preset: &Preset, cache: &Cache) -> Result<Option<Joined>, StageError> {
    let Some(t) = &preset.terrain else { return Ok(None) };
    let Some(bands) = crate::scene::terrain_stage::planned_bands(t)? else { return Ok(None) };
    let key = crate::scene::terrain_stage::mesh_key(preset, t)?;
    let Some(plan) = rows_plan(preset, t, &bands, &key)? else { return Ok(None) };
    Ok(joined(preset, &plan, cache)?.map(|all| all.into_iter().map(|p| p.map(|p| (p.instances, p.counts))).collect()))
}
