//! A band's chunks of the terrain scene at every LoD level, as the scene's files hold them: each
//! chunk's surface with its skirt, vertex normals, UVs and the material layers' vertex attributes
//! (`_LAYER_WEIGHTS`, and with a ground cover `_LAYER_WEIGHTS_1` and `_SURFACE`), built from the
//! band's rows of the map and its meshes (docs/sharding.md). A shard keeps them in an entry of
//! their own; the merge assembles each level's terrain scene from every band's chunks
//! ([`crate::terrain::build::assemble_chunks`]) instead of building them from the whole map: the
//! same scene, node for node and bit for bit.
//!
//! What a band's chunks read beyond its own rows: the normals on its lines read the row beyond
//! each inner edge, and a vertex on its last row weighs its layers by the bilinear normal there,
//! which reads one row further ([`BandPlan::chunk_rows`]); a vertex on or near a band line reads
//! the ground cover bilinearly between the texel rows on both sides of the line, so a band needs
//! the first cover row beyond each inner edge, which lies on the neighbouring band's surface: its
//! layers entry holds it, or it is located on that band's chunks ([`EdgeCover`]).

use std::ops::Range;

use crate::heightfield::MapRows;
use crate::mesh::{CustomAttribute, Primitive, PrimitiveMode};
use crate::scene::cache::{Cache, KeyBuilder};
use crate::scene::error::StageError;
use crate::scene::terrain_stage::BandPlan;
use crate::scene::TerrainSettings;
use crate::terrain::bands::{BandPiece, Reader, Writer};
use crate::terrain::layers::{weigh_vertices, weighing_reach, SnowRule};
use crate::terrain::vegetation::VegetationCover;

/// The cache stage name of a band's chunks.
pub const BAND_CHUNKS_STAGE: &str = "terrain-band-chunks";

/// One level's chunks of a band: each chunk's (ci, cj) and its surface primitive, in chunk order.
pub type LevelChunks = Vec<([usize; 2], Primitive)>;

/// Cache key of a band's chunks: its own layers entry's key (its meshes, the snow rule and what
/// grows), then the keys of the bands whose cover rows its vertices read ([`cover_bands`]: its
/// neighbours and itself). The own key comes first on its own: of a map of two bands, each reads
/// both bands' covers, so the list of those alone would name both bands' chunks alike.
pub fn chunks_key(own_layers_key: &str, cover_layers_keys: &[String]) -> String {
    let mut k = KeyBuilder::new(BAND_CHUNKS_STAGE, crate::scene::terrain_stage::TERRAIN_ALGORITHM_VERSION);
    k.add(b"own=").add(own_layers_key.as_bytes()).add(b"|cover=");
    for key in cover_layers_keys {
        k.add(key.as_bytes()).add(b"|");
    }
    k.finish()
}

/// The texel rows of the ground cover band `k`'s chunks read: its own texel rows (`texel_rows`,
/// those of its layers) and the row beyond each inner edge.
pub fn cover_reach(plan: &BandPlan, k: usize, texel_rows: &Range<usize>) -> Range<usize> {
    let [below, above] = plan.fixed(k);
    texel_rows.start - usize::from(below && texel_rows.start > 0)
        ..texel_rows.end + usize::from(above && texel_rows.end < plan.map_px()[1] as usize)
}

/// Builds a band's chunks at every bound of `bounds` (its piece's levels, in order): each
/// level's chunks as the scene builds them ([`crate::terrain::build::band_chunks`], shaded) from
/// `field` (the rows [`BandPlan::chunk_rows`] gives), then [`weigh`]ed.
pub fn build(
    field: &MapRows,
    piece: &BandPiece,
    bounds: &[f64],
    t: &TerrainSettings,
    snow: &SnowRule,
    cover: Option<&VegetationCover>,
) -> Result<Vec<LevelChunks>, String> {
    let pitch = t.chunk.ok_or("a band's chunks need a chunked terrain")?;
    if piece.levels.len() != bounds.len() {
        return Err(format!("a band of {} levels for {} bounds", piece.levels.len(), bounds.len()));
    }
    let mut levels = Vec::with_capacity(bounds.len());
    for (level, &bound) in piece.levels.iter().zip(bounds) {
        levels.push(
            crate::terrain::build::band_chunks(field, &level.mesh, pitch, t.skirt_at(bound), true)
                .map_err(|e| e.to_string())?,
        );
    }
    weigh(levels, field, snow, cover)
}

/// A band's shaded chunks at every level with their vertices weighed ([`weigh_vertices`]) by
/// `snow` and `cover` (the rows [`cover_reach`] gives) on `field` (the rows
/// [`BandPlan::chunk_rows`] gives). Errors when a vertex would read a row of the map or of the
/// cover that is not held.
pub fn weigh(
    mut levels: Vec<LevelChunks>,
    field: &MapRows,
    snow: &SnowRule,
    cover: Option<&VegetationCover>,
) -> Result<Vec<LevelChunks>, String> {
    let held = field.held();
    let cell = field.hf.cell_size_m;
    for chunks in &mut levels {
        for (at, p) in chunks.iter_mut() {
            for q in &p.positions {
                let reach = weighing_reach(field, q[2] as f64 / cell);
                let covered = cover.is_none_or(|c| c.holds_point(q[0] as f64, q[2] as f64));
                if !held.contains(reach.start()) || !held.contains(reach.end()) || !covered {
                    return Err(format!(
                        "a vertex of chunk {at:?} at z = {} m reads rows the band's unit does not hold",
                        q[2]
                    ));
                }
            }
            weigh_vertices(p, field, snow, cover);
        }
    }
    Ok(levels)
}

const MAGIC: u64 = u64::from_le_bytes(*b"vchunk01");

/// How a custom attribute's values are kept: as f32 bits, or (for unit bytes that are exactly
/// k / 255) as the bytes k.
const AS_F32: u64 = 0;
const AS_BYTES: u64 = 1;

fn f32_bits<const N: usize>(w: &mut Writer, v: &[[f32; N]]) {
    w.u32s(v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>().into_iter());
}

fn read_f32s<const N: usize>(r: &mut Reader, vertices: Option<usize>) -> Option<Vec<[f32; N]>> {
    let bits = r.u32s()?;
    if bits.len() % N != 0 || vertices.is_some_and(|n| !bits.is_empty() && bits.len() != n * N) {
        return None;
    }
    Some(bits.chunks_exact(N).map(|c| std::array::from_fn(|k| f32::from_bits(c[k]))).collect())
}

/// One level's chunks as bytes (every number exactly).
fn level_bytes(chunks: &LevelChunks) -> Vec<u8> {
    let mut w = Writer(Vec::new());
    w.u64(chunks.len() as u64);
    for ([ci, cj], p) in chunks {
        w.u64(*ci as u64);
        w.u64(*cj as u64);
        w.u64(p.material.map_or(0, |m| m as u64 + 1));
        w.u64(match p.mode {
            PrimitiveMode::Triangles => 0,
            PrimitiveMode::Points => 1,
        });
        f32_bits(&mut w, &p.positions);
        f32_bits(&mut w, &p.normals);
        f32_bits(&mut w, &p.uvs);
        f32_bits(&mut w, &p.tangents);
        f32_bits(&mut w, &p.colors);
        w.u32s(p.indices.iter().copied());
        w.u64(p.custom.len() as u64);
        for c in &p.custom {
            w.bytes(c.name.as_bytes());
            w.u64(u64::from(c.unit_bytes));
            match c.range {
                None => w.u64(0),
                Some(r) => {
                    w.u64(1);
                    f32_bits(&mut w, &[r]);
                }
            }
            let bytes: Option<Vec<u8>> = c.unit_bytes.then_some(()).and_then(|()| {
                c.values
                    .iter()
                    .flatten()
                    .map(|&v| {
                        let b = (v * 255.0).round().clamp(0.0, 255.0) as u8;
                        ((b as f32 / 255.0).to_bits() == v.to_bits()).then_some(b)
                    })
                    .collect()
            });
            match bytes {
                Some(b) => {
                    w.u64(AS_BYTES);
                    w.bytes(&b);
                }
                None => {
                    w.u64(AS_F32);
                    f32_bits(&mut w, &c.values);
                }
            }
        }
    }
    w.0
}

fn level_from_bytes(bytes: &[u8]) -> Option<LevelChunks> {
    let mut r = Reader(bytes);
    let n = r.len(8)?;
    let mut chunks = Vec::with_capacity(n);
    for _ in 0..n {
        let at = [usize::try_from(r.u64()?).ok()?, usize::try_from(r.u64()?).ok()?];
        let material = match r.u64()? {
            0 => None,
            m => Some(usize::try_from(m - 1).ok()?),
        };
        let mode = match r.u64()? {
            0 => PrimitiveMode::Triangles,
            1 => PrimitiveMode::Points,
            _ => return None,
        };
        let positions: Vec<[f32; 3]> = read_f32s(&mut r, None)?;
        let count = Some(positions.len());
        let normals = read_f32s(&mut r, count)?;
        let uvs = read_f32s(&mut r, count)?;
        let tangents = read_f32s(&mut r, count)?;
        let colors = read_f32s(&mut r, count)?;
        let indices = r.u32s()?;
        if indices.iter().any(|&i| i as usize >= positions.len()) {
            return None;
        }
        let attributes = r.len(8)?;
        let mut custom = Vec::with_capacity(attributes);
        for _ in 0..attributes {
            let name = String::from_utf8(r.bytes()?).ok()?;
            let unit_bytes = match r.u64()? {
                0 => false,
                1 => true,
                _ => return None,
            };
            let range = match r.u64()? {
                0 => None,
                1 => Some(read_f32s::<4>(&mut r, None)?.first().copied()?),
                _ => return None,
            };
            let values: Vec<[f32; 4]> = match r.u64()? {
                AS_F32 => read_f32s(&mut r, count)?,
                AS_BYTES => {
                    let b = r.bytes()?;
                    if b.len() != 4 * positions.len() {
                        return None;
                    }
                    b.chunks_exact(4).map(|c| std::array::from_fn(|k| c[k] as f32 / 255.0)).collect()
                }
                _ => return None,
            };
            if values.len() != positions.len() {
                return None;
            }
            custom.push(CustomAttribute { name, values, unit_bytes, range });
        }
        let prim = Primitive { positions, normals, uvs, tangents, colors, custom, indices, material, mode };
        chunks.push((at, prim));
    }
    r.0.is_empty().then_some(chunks)
}

/// A band's chunks at every level as an entry's blob: each level's bytes apart (read one level at
/// a time: [`level_of`]).
pub fn to_bytes(levels: &[LevelChunks]) -> Vec<u8> {
    let mut w = Writer(Vec::new());
    w.u64(MAGIC);
    w.u64(levels.len() as u64);
    for l in levels {
        w.bytes(&level_bytes(l));
    }
    w.0
}

/// Level `level` of [`to_bytes`]'s blob (`None` when the bytes are not such a blob or lack it).
pub fn level_of(bytes: &[u8], level: usize) -> Option<LevelChunks> {
    let mut r = Reader(bytes);
    if r.u64()? != MAGIC {
        return None;
    }
    let count = r.len(8)?;
    if level >= count {
        return None;
    }
    for _ in 0..level {
        let n = r.len(1)?;
        r.take(n)?;
    }
    level_from_bytes(&r.bytes()?)
}

/// Every level of [`to_bytes`]'s blob, or `None`.
pub fn from_bytes(bytes: &[u8]) -> Option<Vec<LevelChunks>> {
    let mut r = Reader(bytes);
    if r.u64()? != MAGIC {
        return None;
    }
    let count = r.len(8)?;
    let levels = (0..count).map(|_| level_from_bytes(&r.bytes()?)).collect::<Option<Vec<_>>>()?;
    r.0.is_empty().then_some(levels)
}

/// Whether `cache` holds band chunks under `key` that read back (every level of `levels`).
pub fn holds(cache: &Cache, key: &str, levels: usize) -> bool {
    kept_blob(cache, key).is_some_and(|b| from_bytes(&b).is_some_and(|l| l.len() == levels))
}

/// Whether the band whose chunks `cache` holds under `key` has heights exactly their f32 values
/// (`false` when it does not hold them, or does not say).
pub fn heights_exact(cache: &Cache, key: &str) -> bool {
    let Some((json, _)) = cache.lookup(BAND_CHUNKS_STAGE, key) else { return false };
    serde_json::from_str::<serde_json::Value>(&json).ok().and_then(|v| v["heights_exact"].as_bool()) == Some(true)
}

/// The blob `cache` holds under `key`, if any.
pub fn kept_blob(cache: &Cache, key: &str) -> Option<Vec<u8>> {
    let (_, entry) = cache.lookup(BAND_CHUNKS_STAGE, key)?;
    Cache::read_blob(&entry).ok()
}

/// Stores a band's chunks under `key`, with whether the map's heights in the band's rows are
/// exactly their f32 values (`heights_exact`: [`crate::heightfield::Heightfield::rounding_m`] 0,
/// so the terrain's error as stored is its f64 error there: [`heights_exact`]).
pub fn store(
    cache: &Cache,
    key: &str,
    rows: [u32; 2],
    heights_exact: bool,
    levels: &[LevelChunks],
) -> Result<(), StageError> {
    let json = format!("{{\"rows\":[{},{}],\"heights_exact\":{heights_exact}}}", rows[0], rows[1]);
    cache
        .store_blob(BAND_CHUNKS_STAGE, key, &json, &to_bytes(levels))
        .map(|_| ())
        .map_err(|e| StageError::Failed { stage: "terrain", message: format!("cannot keep a band's chunks: {e}") })
}

/// Where a band's chunks take the ground cover's first texel row beyond an inner edge from when
/// the cache holds no layers of the band beyond: band `n`'s rows `rows` located on its surface
/// (its chunks at the main level). `Ok(None)` when nothing grows.
pub type EdgeCover<'a> = dyn FnMut(usize, Range<usize>) -> Result<Option<VegetationCover>, StageError> + 'a;

/// Band `k`'s chunks ([`build`]) in `cache`: kept there (unless `force`), else built from the map's
/// rows (`rows_of`, asked for [`BandPlan::chunk_rows`]), the band's piece and layers as `cache`
/// holds them (its unit stored them), and the cover's edge rows of its neighbours (their layers in
/// `cache`, else `edge`), and stored. `built`: the band's shaded chunks at every level when its
/// unit has them at hand ([`crate::scene::terrain_stage::band_piece`]), weighed instead of
/// built again. `mesh_key` is the terrain's.
#[allow(clippy::too_many_arguments)]
pub fn make(
    grows: &crate::scene::band_layers::Grows,
    t: &TerrainSettings,
    mesh_key: &str,
    plan: &BandPlan,
    k: usize,
    (cache, force): (&Cache, bool),
    built: Option<Vec<LevelChunks>>,
    rows_of: &mut dyn FnMut([u32; 2]) -> Result<crate::heightfield::Heightfield, StageError>,
    edge: &mut EdgeCover,
) -> Result<(), StageError> {
    use crate::scene::band_layers;
    use crate::scene::terrain_stage::{band_layers_key, kept_band};
    let fail = |message: String| StageError::Failed { stage: "terrain", message };
    let [a, b] = plan.rows(k);
    let Some(texel_rows) = plan.normal_rows() else {
        return Err(fail("a band's chunks need the layers baked by band".into()));
    };
    let key = chunks_key_of(grows, mesh_key, plan, k);
    if !force && holds(cache, &key, plan.bounds.len()) {
        return Ok(());
    }
    let extent = crate::scene::ground_cover::terrain_extent(plan.width, plan.height(), plan.cell_m);
    let fits = (extent, grows.preset.species.len());
    let layers_of = |n: usize| {
        band_layers::kept(cache, &band_layers_key(grows, mesh_key, plan, n), plan.map_px(), &texel_rows[n], fits)
    };
    let own = layers_of(k).ok_or_else(|| fail(format!("band {k} (rows {a}-{b}): its layers are not in the cache")))?;
    let cover = match own.cover {
        None => None,
        Some(own) => {
            let reach = cover_reach(plan, k, &texel_rows[k]);
            let mut parts = Vec::with_capacity(3);
            let mut beyond = |n: usize, rows: Range<usize>| -> Result<VegetationCover, StageError> {
                let kept = layers_of(n).and_then(|l| l.cover).and_then(|c| c.take_rows(rows.clone()));
                match kept {
                    Some(c) => Ok(c),
                    None => edge(n, rows.clone())?.and_then(|c| c.take_rows(rows.clone())).ok_or_else(|| {
                        fail(format!("band {n}'s cover rows {}-{} could not be located", rows.start, rows.end))
                    }),
                }
            };
            let bands = cover_bands(plan, k);
            if reach.start < texel_rows[k].start {
                parts.push(beyond(bands[0], reach.start..texel_rows[k].start)?);
            }
            parts.push(own);
            if reach.end > texel_rows[k].end {
                parts.push(beyond(bands[bands.len() - 1], texel_rows[k].end..reach.end)?);
            }
            Some(VegetationCover::stack(&parts).ok_or_else(|| fail(format!("band {k}'s cover rows do not join")))?)
        }
    };
    let read = plan.chunk_rows(k);
    let margin = rows_of(read)?;
    let margin_exact = margin.rounding_m() == 0.0;
    let field = MapRows::new(&margin, read[0] as usize, plan.height())
        .ok_or_else(|| fail(format!("rows {}-{} are not within the map", read[0], read[1])))?;
    let snow = crate::scene::terrain_stage::snow_rule(grows.preset);
    let levels = match built {
        Some(levels) if levels.len() == plan.bounds.len() => weigh(levels, &field, &snow, cover.as_ref()),
        _ => {
            let piece = kept_band(mesh_key, plan, k, cache)
                .ok_or_else(|| fail(format!("band {k} (rows {a}-{b}): its meshes are not in the cache")))?;
            build(&field, &piece, &plan.bounds, t, &snow, cover.as_ref())
        }
    }
    .map_err(|e| fail(format!("band {k} (rows {a}-{b}): {e}")))?;
    store(cache, &key, [a, b], margin_exact, &levels)
}

/// The bands whose layers hold the cover rows band `k`'s chunks read, in order: the band holding
/// the row before its texel rows (its neighbour, or past a band holding none), `k`, and the band
/// holding the row after them.
pub fn cover_bands(plan: &BandPlan, k: usize) -> Vec<usize> {
    let Some(texel_rows) = plan.normal_rows() else { return vec![k] };
    let reach = cover_reach(plan, k, &texel_rows[k]);
    let owner = |row: usize| texel_rows.iter().position(|r| r.contains(&row)).unwrap_or(k);
    let mut bands = Vec::with_capacity(3);
    if reach.start < texel_rows[k].start {
        bands.push(owner(reach.start));
    }
    bands.push(k);
    if reach.end > texel_rows[k].end {
        bands.push(owner(texel_rows[k].end));
    }
    bands
}

/// [`chunks_key`] of band `k` of `plan`.
pub fn chunks_key_of(grows: &crate::scene::band_layers::Grows, mesh_key: &str, plan: &BandPlan, k: usize) -> String {
    let key_of = |b: usize| crate::scene::terrain_stage::band_layers_key(grows, mesh_key, plan, b);
    let keys: Vec<String> = cover_bands(plan, k).into_iter().map(key_of).collect();
    chunks_key(&key_of(k), &keys)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::band_layers::tests::{preset, PINES_AND_GRASS_UNDER_SNOW};
    use crate::scene::band_layers::Grows;
    use crate::scene::terrain_stage::{band_layers, band_piece, band_plan, mesh_key, snow_rule, terrain_heights};
    use crate::scene::Preset;

    /// Each band's chunks made in a cache of its own (its piece and layers alone there, so every
    /// cover row beyond its lines is located on the neighbour's surface; built from its kept
    /// piece) or in one cache holding every band's layers (read from them; the chunks its normal
    /// maps were baked from weighed), assembled level by level: the scene built from the
    /// whole map and the level's joined mesh, textured by the joined layers, bit for bit.
    fn bands_assemble_to_the_whole_scene(preset: &Preset) {
        let t = preset.terrain.as_ref().unwrap();
        let (hf, _, _) = terrain_heights(t).unwrap();
        let plan = band_plan(t, hf.width, hf.height).unwrap();
        assert_eq!(plan.band_count(), 3);
        assert!(crate::scene::terrain_stage::chunks_by_band(t, &plan));
        let key = mesh_key(preset, t).unwrap();
        let grows = Grows::of(preset);
        let mut rows_of = |r: [u32; 2]| Ok(hf.rows(r[0] as usize, r[1] as usize).unwrap());
        let shared = tempfile::tempdir().unwrap();
        let shared = Cache::new(shared.path());
        let mut pieces = Vec::new();
        let mut parts = Vec::new();
        let mut built = Vec::new();
        for k in 0..3 {
            let c = Some((&shared, false));
            let made = band_piece(&key, t, &mut rows_of, &plan, k, c, true).unwrap();
            let (piece, chunks) = (made.piece, made.chunks);
            parts.push(band_layers(&grows, t, &key, &plan, k, &piece, &mut rows_of, None, c).unwrap().unwrap());
            pieces.push(piece);
            built.push(chunks.expect("the chunks its normal maps were baked from"));
        }
        let mut built = built.into_iter();
        let layers = crate::scene::band_layers::join(preset, parts, plan.map_px()).unwrap();
        let extent = crate::scene::ground_cover::terrain_extent(hf.width, hf.height, hf.cell_size_m);
        let grows_anything = !preset.species.is_empty();

        // every band's chunks, each in a cache of its own and in the shared one
        let mut alone = Vec::new();
        let mut located = 0;
        for k in 0..3 {
            let dir = tempfile::tempdir().unwrap();
            let own = Cache::new(dir.path());
            band_piece(&key, t, &mut rows_of, &plan, k, Some((&own, false)), false).unwrap();
            band_layers(&grows, t, &key, &plan, k, &pieces[k], &mut rows_of, None, Some((&own, false))).unwrap();
            let mut edge = |n: usize, rows: Range<usize>| {
                located += 1;
                let window = hf.rows(plan.rows(n)[0] as usize, plan.rows(n)[1] as usize).unwrap();
                let surface = crate::scene::placement_rows::band_surfaces(t, &key, &plan, n, &window, None)?;
                Ok(crate::scene::band_layers::locate_cover(preset, &surface, extent, plan.map_px(), rows))
            };
            make(&grows, t, &key, &plan, k, (&own, false), None, &mut rows_of, &mut edge).unwrap();
            let mut never = |_: usize, _: Range<usize>| -> Result<Option<VegetationCover>, StageError> {
                panic!("the shared cache holds every band's layers")
            };
            make(&grows, t, &key, &plan, k, (&shared, false), built.next(), &mut rows_of, &mut never).unwrap();
            let chunk_key = chunks_key_of(&grows, &key, &plan, k);
            let blob = kept_blob(&own, &chunk_key).unwrap();
            assert_eq!(Some(&blob), kept_blob(&shared, &chunk_key).as_ref(), "band {k}: located = read");
            alone.push(blob);
        }
        // the middle band locates a row on each side, the others one
        assert_eq!(located, if grows_anything { 4 } else { 0 });

        let storage = crate::terrain::stored::Storage::f32(&hf);
        for (level, &bound) in plan.bounds.iter().enumerate() {
            let opts = crate::terrain::tin::TinOptions {
                max_error_m: bound,
                max_triangles: None,
                max_vertices: t.max_vertices,
                chunk_cells: 0,
            };
            let (joined, _) = crate::terrain::bands::assemble(&hf, &storage, &pieces, level, &opts).unwrap();
            let build = crate::terrain::build::BuildOptions {
                chunk_samples: t.chunk,
                skirt_depth_m: t.skirt_at(bound),
                base_depth_m: None,
                name: "terrain".into(),
                snow: snow_rule(preset),
            };
            let mut whole = crate::terrain::build::build_scene(&hf, &joined.mesh, &build).unwrap();
            layers.texture(&mut whole, &hf, "terrain").unwrap();
            let chunks = alone.iter().flat_map(|b| level_of(b, level).unwrap());
            let mut banded =
                crate::terrain::build::assemble_chunks("terrain", hf.width, hf.height, 128, chunks).unwrap();
            layers.put_base_color(&mut banded, "terrain").unwrap();
            assert_eq!(banded.meshes.len(), whole.meshes.len());
            for (a, b) in banded.meshes.iter().zip(&whole.meshes) {
                assert!(a == b, "level {level}: chunk {} differs", b.name);
            }
            assert!(banded == whole, "level {level}: the scenes differ");
            let surface = whole.meshes[0].primitives[0].custom.iter().map(|c| c.name.as_str()).collect::<Vec<_>>();
            assert_eq!(surface.len(), if grows_anything { 3 } else { 1 }, "{surface:?}");
        }
    }

    #[test]
    fn band_chunks_assemble_to_the_whole_scene_bit_for_bit() {
        bands_assemble_to_the_whole_scene(&preset(""));
        bands_assemble_to_the_whole_scene(&preset(PINES_AND_GRASS_UNDER_SNOW));
    }

    /// A shard's cache holds what the terrain stage joins without reading the map when every
    /// band's entries say the main mesh's f64 error: its heights are their f32 values (a
    /// procedural map's), or its unit measured it (a 16-bit PNG's metres, which f32 rounds); then
    /// the terrain stage's figures and files are a whole build's from the decoded map (which takes
    /// the f64 error from its bands' figures too: the analyzer's over the whole map), also where
    /// some bands are exact and some rounded (one flat at 0 m). Not when a band's chunks are
    /// missing, nor from an earlier unit's entries (which do not say the error) on a rounded map.
    #[test]
    fn a_merge_joins_the_terrain_without_the_map_where_every_band_says_its_f64_error() {
        use crate::scene::terrain_stage::{joined_without_map, run_terrain_covered, MeshMemo};
        let dir = tempfile::tempdir().unwrap();
        let procedural = preset("");
        let png_preset = |name: &str, flat_rows: u32| {
            let map = dir.path().join(format!("{name}.png"));
            image::ImageBuffer::from_fn(301, 1025, |i, j| {
                image::Luma([if j < flat_rows { 0 } else { (i * 97 + j * 31) as u16 % 4000 + 20000 }])
            })
            .save(&map)
            .unwrap();
            let text = format!(
                "[scene]\nname = \"bands\"\nseed = 5\n\n[terrain]\nheightmap = \"{}\"\nheight_scale = 300.0\n\
                 cell_size = 2.0\nmax_error = 0.5\nchunk = 128\nskirt = 1.0\nlods = [0.5, 2.0]\n",
                map.display()
            );
            crate::scene::preset::parse_preset(&text, std::path::Path::new("png.toml")).unwrap()
        };
        let (rounded, mixed) = (png_preset("rounded", 0), png_preset("mixed", 390));
        for (name, p, rounds) in
            [("procedural", &procedural, false), ("rounded", &rounded, true), ("mixed", &mixed, true)]
        {
            let out = dir.path().join(name);
            let shard = crate::scene::shard::Shard { index: 0, count: 1 };
            crate::scene::shard::build_shard(p, &out, shard, false, &|_| {}).unwrap();
            let cache = Cache::new(&out);
            let t = p.terrain.as_ref().unwrap();
            let got = joined_without_map(p, t, &mut || mesh_key(p, t), &cache).unwrap();
            let Some((plan, f64_m, got_rounds)) = got else { panic!("{name}: not joined without the map") };
            assert!(f64_m.is_some(), "{name}: every band says its f64 error");
            assert_eq!(got_rounds, rounds, "{name}");
            // joined without the map: the whole build's figures and files
            let key = mesh_key(p, t).unwrap();
            let memo = MeshMemo { cache: &cache, force: false };
            let b = crate::scene::terrain_stage::banded_meshes(p, t, &key, None, &plan, Some(memo), rounds);
            assert!(b.is_ok(), "{name}: the bands' entries join without the map");
            let (joined_dir, whole_dir) = (out.join("joined"), out.join("whole"));
            let (from_bands, ..) = run_terrain_covered(p, t, &joined_dir, Some(memo)).unwrap();
            let (whole, ..) = run_terrain_covered(p, t, &whole_dir, None).unwrap();
            assert_eq!(from_bands.figures.max_error_f64, whole.figures.max_error_f64, "{name}");
            if name == "rounded" {
                assert!(whole.figures.max_error_f64 != whole.figures.max_error, "{name}: the map rounds");
            }
            assert_eq!(from_bands.figures, whole.figures, "{name}");
            // (every build takes it from its bands' figures: the analyzer's of the main mesh over
            // the whole decoded map, the same map meshed whole)
            let hf = crate::scene::terrain_stage::terrain_heights(t).unwrap().0;
            let opts = crate::terrain::tin::TinOptions {
                max_error_m: t.max_error_m,
                chunk_cells: 128,
                max_vertices: usize::MAX,
                ..Default::default()
            };
            let main = crate::terrain::tin::tin(&hf, &opts).unwrap().mesh;
            let analyzer = crate::terrain::error::measure_exact(&hf, &main).max_error_m;
            assert_eq!(whole.figures.max_error_f64.to_bits(), analyzer.to_bits(), "{name}");
            assert_eq!(whole.figures.vertices, main.vertices.len(), "{name}: the same mesh");
            // and with a cache
            let fresh = Cache::new(&out.join("fresh"));
            let memo = Some(MeshMemo { cache: &fresh, force: false });
            let (cached, ..) = run_terrain_covered(p, t, &out.join("cached"), memo).unwrap();
            assert_eq!(cached.figures, whole.figures, "{name}");
            for f in &whole.files {
                let same = std::fs::read(joined_dir.join(f)).unwrap() == std::fs::read(whole_dir.join(f)).unwrap();
                assert!(same, "{name}: {} differs", f.display());
            }
            // entries of an earlier unit, which do not say the error: joined where every band's
            // heights are exact (the error as stored), else decoded
            for e in std::fs::read_dir(&cache.root).unwrap().map(|e| e.unwrap().path()) {
                let stage = e.join("stage.json");
                let text = std::fs::read_to_string(&stage).unwrap_or_default();
                if let Some(at) = text.find(",\"max_error_f64_m\"") {
                    std::fs::write(&stage, format!("{}}}", &text[..at])).unwrap();
                }
            }
            let earlier = joined_without_map(p, t, &mut || mesh_key(p, t), &cache).unwrap();
            assert_eq!(earlier.map(|(_, f64_m, _)| f64_m), if rounds { None } else { Some(None) }, "{name}");
            if name == "procedural" {
                // a band's chunks gone: the map is read
                let gone = std::fs::read_dir(&cache.root)
                    .unwrap()
                    .map(|e| e.unwrap().path())
                    .find(|e| e.file_name().unwrap().to_string_lossy().starts_with("terrain-band-chunks-"))
                    .unwrap();
                std::fs::remove_dir_all(gone).unwrap();
                assert!(joined_without_map(p, t, &mut || mesh_key(p, t), &cache).unwrap().is_none());
            }
        }
    }

    /// Each band's chunks entry holds that band's chunks, on maps of two bands (where each band
    /// reads both bands' covers, so the cover keys alone named both entries alike and the second
    /// band's chunks were the first's: the merge then fell back to the map) and of three.
    #[test]
    fn every_band_keeps_its_own_chunks_under_a_name_of_its_own() {
        use crate::scene::terrain_stage::{band_plan, mesh_key};
        let dir = tempfile::tempdir().unwrap();
        let two = crate::scene::band_layers::tests::preset_of_size(641, "");
        for (name, p, bands) in [("two bands", &two, 2), ("three bands", &preset(""), 3)] {
            let t = p.terrain.as_ref().unwrap();
            let (hf, _, _) = crate::scene::terrain_stage::terrain_heights(t).unwrap();
            let plan = band_plan(t, hf.width, hf.height).unwrap();
            assert_eq!(plan.band_count(), bands, "{name}");
            let out = dir.path().join(name);
            let shard = crate::scene::shard::Shard { index: 0, count: 1 };
            crate::scene::shard::build_shard(p, &out, shard, false, &|_| {}).unwrap();
            let (cache, key, grows) = (Cache::new(&out), mesh_key(p, t).unwrap(), Grows::of(p));
            let keys: Vec<String> = (0..bands).map(|k| chunks_key_of(&grows, &key, &plan, k)).collect();
            for k in 0..bands {
                assert!(!keys[..k].contains(&keys[k]), "{name}: band {k}'s chunks named as an earlier band's");
                let blob = kept_blob(&cache, &keys[k]).unwrap_or_else(|| panic!("{name}: band {k} kept no chunks"));
                let [a, b] = plan.rows(k);
                for level in 0..t.lods.len() {
                    let chunks = level_of(&blob, level).unwrap();
                    assert!(!chunks.is_empty(), "{name}: band {k} level {level}");
                    for ([_, cj], _) in &chunks {
                        let row = (*cj * 128) as u32;
                        assert!(row >= a && row < b, "{name}: band {k} (rows {a}-{b}) holds chunk row {cj}");
                    }
                }
            }
        }
    }

    #[test]
    fn a_damaged_entry_does_not_read_back() {
        let prim = Primitive {
            positions: vec![[0.0, 1.0, 2.0], [1.0, 1.5, 2.0], [0.0, 1.0, 3.0]],
            normals: vec![[0.0, 1.0, 0.0]; 3],
            uvs: vec![[0.0, 0.5]; 3],
            indices: vec![0, 2, 1],
            material: Some(0),
            custom: vec![
                CustomAttribute {
                    name: "_W".into(),
                    values: vec![[1.0, 0.0, 17.0 / 255.0, 238.0 / 255.0]; 3],
                    unit_bytes: true,
                    range: None,
                },
                CustomAttribute {
                    name: "_S".into(),
                    values: vec![[0.3, 2.0, 1e-7, 9.5]; 3],
                    unit_bytes: false,
                    range: None,
                },
            ],
            ..Primitive::default()
        };
        let levels = vec![vec![([1, 2], prim.clone())], vec![([0, 0], prim.clone()), ([3, 0], prim)]];
        let bytes = to_bytes(&levels);
        assert_eq!(from_bytes(&bytes).as_ref(), Some(&levels));
        assert_eq!(level_of(&bytes, 1).as_ref(), Some(&levels[1]));
        assert_eq!(level_of(&bytes, 2), None);
        for cut in 0..bytes.len() {
            assert_eq!(from_bytes(&bytes[..cut]), None, "cut at {cut}");
        }
        for at in (0..bytes.len()).step_by(7) {
            let mut flipped = bytes.clone();
            flipped[at] ^= 0x5a;
            let _ = from_bytes(&flipped);
        }
    }
}
