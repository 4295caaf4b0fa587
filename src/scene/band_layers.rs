//! A band's rows of the terrain's material layers (terrain/layers.rs), part of a band's unit
//! (docs/sharding.md): the ground cover's texel rows of the band, each species' density on the
//! band's own surface, and the weight maps', base colour's and coverage's rows baked from them and
//! from the band's rows of the map. The texel rows are those of the band's normal maps
//! ([`crate::terrain::bands::band_texel_rows`]): their centres lie inside the band's rows, where
//! only the band's faces cover them, so a band's surface locates them as the whole terrain's does,
//! and each layer texel reads its own texel of the cover. The terrain stage joins every band's
//! rows: the same maps, cover and figures as baking them over the whole map, bit for bit.
//!
//! Kept apart from the band's meshes (its own cache entry, keyed on them and on what the layers
//! read besides: the `[snow]` cover and what grows), so a species edit re-bakes a band's layers
//! without meshing it again.

use std::ops::Range;

use crate::heightfield::MapRows;
use crate::mesh::Primitive;
use crate::scene::cache::{Cache, KeyBuilder};
use crate::scene::error::StageError;
use crate::scene::Preset;
use crate::terrain::layers::{bake_layer_rows, LayerRows, TerrainLayers};
use crate::terrain::vegetation::{SpeciesCover, VegetationCover};

/// The cache stage name of a band's layer rows.
pub const BAND_LAYERS_STAGE: &str = "terrain-band-layers";

/// A band's texel rows of the cover (when anything grows) and of the layer maps.
#[derive(Debug, Clone, PartialEq)]
pub struct BandLayers {
    pub cover: Option<VegetationCover>,
    pub rows: LayerRows,
}

/// What a terrain's layers read besides its meshes and map (the snow rule, what grows and the maps
/// its rules read), with its digest: hashed once for all the bands (the maps may be large).
pub struct Grows<'a> {
    pub preset: &'a Preset,
    pub key: String,
}

impl<'a> Grows<'a> {
    pub fn of(preset: &'a Preset) -> Grows<'a> {
        let mut k = KeyBuilder::new(BAND_LAYERS_STAGE, crate::scene::terrain_stage::TERRAIN_ALGORITHM_VERSION);
        k.add(format!("{:?}", crate::scene::terrain_stage::snow_rule(preset)).as_bytes());
        if !preset.species.is_empty() {
            crate::scene::ground_cover::add_key(&mut k, preset);
        }
        Grows { preset, key: k.finish() }
    }
}

/// Cache key of a band's layer rows: its meshes' entry (`band_key`: the band's rows and what
/// meshing reads) and what the layers read besides ([`Grows`]).
pub fn layers_key(grows: &Grows, band_key: &str) -> String {
    let mut k = KeyBuilder::new(BAND_LAYERS_STAGE, crate::scene::terrain_stage::TERRAIN_ALGORITHM_VERSION);
    k.add(band_key.as_bytes());
    k.add(grows.key.as_bytes());
    k.finish()
}

/// Bakes texel rows `texel_rows` of a terrain's layers (maps of `map_px` over a map of
/// `width` × `map_height` samples `cell_m` apart): the cover located on `surface` (the band's
/// chunks at the main level: [`crate::terrain::build::band_chunk_surfaces`]), the layers from
/// `field` (the band's rows and the row beyond each inner edge, as its normal maps read them).
pub fn bake(
    preset: &Preset,
    field: &MapRows,
    cell_m: f64,
    surface: &[Primitive],
    map_px: [u32; 2],
    texel_rows: Range<usize>,
) -> BandLayers {
    let extent = crate::scene::ground_cover::terrain_extent(field.hf.width, field.map_height, cell_m);
    let cover = locate_cover(preset, surface, extent, map_px, texel_rows.clone());
    let snow = crate::scene::terrain_stage::snow_rule(preset);
    let rows = bake_layer_rows(field, map_px, &snow, cover.as_ref(), texel_rows);
    BandLayers { cover, rows }
}

/// The ground cover's texel rows `texel_rows` (of a `map_px` grid over `extent`, the terrain's)
/// located on `surface`: chunks whose faces alone cover those texel centres (a band's, at the
/// main level). `None` when nothing grows.
pub fn locate_cover(
    preset: &Preset,
    surface: &[Primitive],
    extent: [f64; 4],
    map_px: [u32; 2],
    texel_rows: Range<usize>,
) -> Option<VegetationCover> {
    let index = crate::scene::ground_cover::surface_of_parts(surface.iter());
    crate::scene::ground_cover::cover_rows(preset, &index, extent, map_px, texel_rows)
}

/// The terrain's layers from every band's rows (in order): the whole cover (every species' rows
/// joined) and the layer maps and coverage ([`TerrainLayers::from_rows`]).
pub fn join(preset: &Preset, parts: Vec<BandLayers>, map_px: [u32; 2]) -> Result<TerrainLayers, String> {
    let covered = parts.iter().filter(|p| p.cover.is_some()).count();
    if covered != 0 && covered != parts.len() {
        return Err(format!("{covered} of {} bands have a ground cover", parts.len()));
    }
    let mut cover: Option<VegetationCover> = None;
    let mut rows = Vec::with_capacity(parts.len());
    for part in parts {
        if let Some(c) = part.cover {
            let whole = cover.get_or_insert_with(|| VegetationCover {
                extent: c.extent,
                size: c.size,
                species: c.species.iter().map(|s| SpeciesCover { weights: Vec::new(), ..s.clone() }).collect(),
                first_row: 0,
            });
            let due = whole.species.first().map_or(0, |s| s.weights.len()) / (map_px[0].max(1) as usize);
            if c.first_row != due || c.size != whole.size || c.species.len() != whole.species.len() {
                return Err(format!("a band's cover rows start at {} where row {due} was due", c.first_row));
            }
            for (w, s) in whole.species.iter_mut().zip(c.species) {
                w.weights.extend(s.weights);
            }
        }
        rows.push(part.rows);
    }
    if let Some(c) = &cover {
        let texels = map_px[0] as usize * map_px[1] as usize;
        if let Some(s) = c.species.iter().find(|s| s.weights.len() != texels) {
            return Err(format!("the bands' cover holds {} texels of {texels}", s.weights.len()));
        }
    }
    let snow = crate::scene::terrain_stage::snow_rule(preset);
    TerrainLayers::from_rows(rows, map_px, &snow, cover.map(std::sync::Arc::new))
}

/// The layer rows as an entry's blob: a header of little-endian u32 (first row, width, rows, weight
/// maps, species: 0 without a cover), each species' figures (ground 0 grass / 1 canopy, then
/// max density, height and footprint as f64) and the extent (4 × f64), each row's sums (5 × f64),
/// then PNGs (each a u32 length, then its bytes): each weight map's rows, the base colour's, and
/// each species' weights as RGBA (each f32's little-endian bytes a texel: lossless, and deflated).
pub fn to_bytes(b: &BandLayers) -> Result<Vec<u8>, String> {
    let r = &b.rows;
    let (w, n) = (r.width as u32, r.sums.len() as u32);
    let mut out = Vec::new();
    let species = b.cover.as_ref().map_or(0, |c| c.species.len());
    for v in [r.first as u32, w, n, r.weights.len() as u32, species as u32] {
        out.extend(v.to_le_bytes());
    }
    if let Some(c) = &b.cover {
        for s in &c.species {
            out.extend(u32::from(s.ground == crate::terrain::vegetation::Ground::Canopy).to_le_bytes());
            for v in [s.max_density, s.height_m, s.footprint_m2] {
                out.extend(v.to_le_bytes());
            }
        }
        for v in c.extent {
            out.extend(v.to_le_bytes());
        }
    }
    for row in &r.sums {
        for v in row {
            out.extend(v.to_le_bytes());
        }
    }
    let mut png = |rgba: &[u8]| -> Result<(), String> {
        let bytes = if n == 0 { Vec::new() } else { crate::bake::raster::png::encode_rgba8_png(rgba, w, n)? };
        out.extend((bytes.len() as u32).to_le_bytes());
        out.extend(bytes);
        Ok(())
    };
    for map in &r.weights {
        png(map.as_flattened())?;
    }
    png(&r.albedo_rgba8)?;
    if let Some(c) = &b.cover {
        for s in &c.species {
            png(&s.weights.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>())?;
        }
    }
    Ok(out)
}

/// [`to_bytes`] read back (`None` when the bytes are not such rows of a `map_px` map).
pub fn from_bytes(bytes: &[u8], map_px: [u32; 2]) -> Option<BandLayers> {
    let mut at = 0usize;
    let mut take = |len: usize| -> Option<&[u8]> {
        let s = bytes.get(at..at.checked_add(len)?)?;
        at += len;
        Some(s)
    };
    let mut u32_ = || take(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let [first, w, n, maps, species] = [u32_()?, u32_()?, u32_()?, u32_()?, u32_()?].map(|v| v as usize);
    // (a species' figures take 28 bytes: a count past what the bytes hold is damage, not memory
    // to reserve)
    if w != map_px[0] as usize || first + n > map_px[1] as usize || maps == 0 || maps > 2 || species > bytes.len() / 28
    {
        return None;
    }
    let mut take = |len: usize| -> Option<&[u8]> {
        let s = bytes.get(at..at.checked_add(len)?)?;
        at += len;
        Some(s)
    };
    let f64_ = |b: &[u8]| f64::from_le_bytes(b.try_into().unwrap_or([0; 8]));
    let mut figures = Vec::with_capacity(species);
    for _ in 0..species {
        let ground = u32::from_le_bytes(take(4)?.try_into().ok()?);
        if ground > 1 {
            return None;
        }
        let [d, h, f] = [f64_(take(8)?), f64_(take(8)?), f64_(take(8)?)];
        figures.push((ground, d, h, f));
    }
    let mut extent = [0.0; 4];
    if species > 0 {
        for v in extent.iter_mut() {
            *v = f64_(take(8)?);
        }
    }
    let mut sums = Vec::with_capacity(n);
    for _ in 0..n {
        let mut row = [0.0; 5];
        for v in row.iter_mut() {
            *v = f64_(take(8)?);
        }
        sums.push(row);
    }
    let mut png = || -> Option<Vec<u8>> {
        let len = u32::from_le_bytes(take(4)?.try_into().ok()?) as usize;
        let data = take(len)?;
        if n == 0 {
            return data.is_empty().then(Vec::new);
        }
        // (the size from the header first: a damaged one reserves nothing)
        let size = image::ImageReader::with_format(std::io::Cursor::new(data), image::ImageFormat::Png)
            .into_dimensions()
            .ok()?;
        if size != (w as u32, n as u32) {
            return None;
        }
        let img = image::load_from_memory_with_format(data, image::ImageFormat::Png).ok()?.into_rgba8();
        (img.width() as usize == w && img.height() as usize == n).then(|| img.into_raw())
    };
    let mut weights = Vec::with_capacity(maps);
    for _ in 0..maps {
        weights.push(png()?.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect());
    }
    let albedo_rgba8 = png()?;
    let mut cover_species = Vec::with_capacity(species);
    for (ground, max_density, height_m, footprint_m2) in figures {
        let raw = png()?;
        cover_species.push(SpeciesCover {
            ground: if ground == 1 {
                crate::terrain::vegetation::Ground::Canopy
            } else {
                crate::terrain::vegetation::Ground::Grass
            },
            max_density,
            height_m,
            footprint_m2,
            weights: raw.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect(),
        });
    }
    // (one weight map, two with a cover's soil layer)
    if at != bytes.len() || maps != 1 + usize::from(species > 0) {
        return None;
    }
    let cover =
        (species > 0).then_some(VegetationCover { extent, size: map_px, species: cover_species, first_row: first });
    Some(BandLayers { cover, rows: LayerRows { first, width: w, weights, albedo_rgba8, sums } })
}

/// Band `k`'s layer rows as `cache` holds them under `key` ([`layers_key`]), for texel rows
/// `texel_rows` of a `map_px` map over `extent`, with a cover of `species` species or none
/// (`None` when it does not hold them, or not whole: then they are baked again).
pub fn kept(
    cache: &Cache,
    key: &str,
    map_px: [u32; 2],
    texel_rows: &Range<usize>,
    (extent, species): ([f64; 4], usize),
) -> Option<BandLayers> {
    let (_, entry) = cache.lookup(BAND_LAYERS_STAGE, key)?;
    let b = from_bytes(&Cache::read_blob(&entry).ok()?, map_px)?;
    let cover_fits = b.cover.as_ref().is_none_or(|c| c.extent == extent && c.species.len() == species);
    (b.rows.first == texel_rows.start && b.rows.sums.len() == texel_rows.len() && cover_fits).then_some(b)
}

/// Stores band layer rows under `key` (a store that fails only costs baking them again).
pub fn store(cache: &Cache, key: &str, b: &BandLayers) -> Result<(), StageError> {
    let blob = to_bytes(b).map_err(|e| StageError::Failed { stage: "terrain", message: e })?;
    let json = format!("{{\"texel_rows\":[{},{}]}}", b.rows.first, b.rows.first + b.rows.sums.len());
    let _ = cache.store_blob(BAND_LAYERS_STAGE, key, &json, &blob);
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::scene::terrain_stage::{band_piece, band_plan, layers_by_band, mesh_key, snow_rule, terrain_heights};
    use crate::terrain::layers::bake_layers_with;

    /// Pines and grass on their slopes (soil between), under a `[snow]` cover.
    pub(crate) const PINES_AND_GRASS_UNDER_SNOW: &str =
        "[[species]]\nname = \"pine\"\nkind = \"tree\"\nlsystem = \"builtin:conifer\"\n\
         placement = \"poisson\"\nmax_density = 0.002\nmin_spacing = 10.0\nslope = [0.0, 30.0]\n\n\
         [[species]]\nname = \"grass\"\nkind = \"grass\"\nplacement = \"jittered\"\n\
         max_density = 0.02\nslope = [0.0, 25.0]\naltitude = [0.0, 120.0]\n\n\
         [snow]\nsnow_line = 110.0\nsnow_line_noise = 10.0\nnoise_scale = 80.0\ntransition = 10.0\n";

    /// A map of three bands (rows 0-384, 384-768, 768-1024; chunks of 128, skirts, two levels),
    /// and `extra` added.
    pub(crate) fn preset(extra: &str) -> Preset {
        preset_of_size(1025, extra)
    }

    /// [`preset`] on a map of `size` × `size` samples (641: two bands, rows 0-384 and 384-640).
    pub(crate) fn preset_of_size(size: usize, extra: &str) -> Preset {
        let text = format!(
            "[scene]\nname = \"bands\"\nseed = 5\n\n[terrain]\n\
             procedural = {{ kind = \"ridged\", size = {size}, seed = 3, relief = 160.0 }}\n\
             cell_size = 2.0\nmax_error = 0.5\nchunk = 128\nskirt = 1.0\nlods = [0.5, 2.0]\n\n\
             [scatter]\ntile = 128.0\n\n{extra}"
        );
        crate::scene::preset::parse_preset(&text, std::path::Path::new("bands.toml")).unwrap()
    }

    /// Every band's layer rows (baked from its own rows and its own chunks' surface) joined, and
    /// the layers baked over the whole map from the whole main scene's cover: bit for bit alike.
    fn bands_join_to_the_whole_bake(preset: &Preset) {
        let t = preset.terrain.as_ref().unwrap();
        let (hf, _, _) = terrain_heights(t).unwrap();
        let plan = band_plan(t, hf.width, hf.height).unwrap();
        assert_eq!(plan.band_count(), 3);
        assert!(layers_by_band(t, &plan));
        let key = mesh_key(preset, t).unwrap();
        let mut rows_of = |r: [u32; 2]| Ok(hf.rows(r[0] as usize, r[1] as usize).unwrap());
        let pieces: Vec<_> =
            (0..3).map(|k| band_piece(&key, t, &mut rows_of, &plan, k, None, false).unwrap().piece).collect();
        let mut parts = Vec::new();
        let grows = Grows::of(preset);
        for (k, piece) in pieces.iter().enumerate() {
            let part =
                crate::scene::terrain_stage::band_layers(&grows, t, &key, &plan, k, piece, &mut rows_of, None, None)
                    .unwrap()
                    .unwrap();
            // (each band's entry reads back as written)
            assert_eq!(from_bytes(&to_bytes(&part).unwrap(), plan.map_px()).as_ref(), Some(&part));
            parts.push(part);
        }
        let banded = join(preset, parts, plan.map_px()).unwrap();

        // the whole bake: the main scene built from the joined main mesh, its cover, the layers
        let storage = crate::terrain::stored::Storage::f32(&hf);
        let opts = crate::terrain::tin::TinOptions {
            max_error_m: 0.5,
            max_triangles: None,
            max_vertices: t.max_vertices,
            chunk_cells: 0,
        };
        let (main, _) = crate::terrain::bands::assemble(&hf, &storage, &pieces, 0, &opts).unwrap();
        let build = crate::terrain::build::BuildOptions {
            chunk_samples: t.chunk,
            skirt_depth_m: t.skirt_at(0.5),
            base_depth_m: None,
            name: "terrain".into(),
            snow: snow_rule(preset),
        };
        let scene = crate::terrain::build::build_scene(&hf, &main.mesh, &build).unwrap();
        let map_px = plan.map_px();
        let cover = crate::scene::ground_cover::cover(preset, &scene, map_px);
        assert_eq!(cover.is_some(), !preset.species.is_empty());
        if let Some(c) = &cover {
            let extent = crate::scene::ground_cover::terrain_extent(hf.width, hf.height, hf.cell_size_m);
            assert_eq!(c.extent, extent, "the extent a band assumes is the whole surface's");
            let joined = banded.cover.as_deref().unwrap();
            for (a, b) in c.species.iter().zip(&joined.species) {
                assert_eq!(a.weights.len(), b.weights.len());
                let differ = a.weights.iter().zip(&b.weights).filter(|(x, y)| x.to_bits() != y.to_bits()).count();
                assert_eq!(differ, 0, "{differ} cover texels differ");
                assert!(a.weights.iter().any(|&w| w > 0.0) && a.weights.iter().any(|&w| w < 1.0));
            }
        }
        let whole = bake_layers_with(&hf, &snow_rule(preset), cover.map(std::sync::Arc::new));
        assert_eq!(whole.weights, banded.weights);
        assert_eq!(whole.albedo_rgba8, banded.albedo_rgba8);
        assert_eq!(whole.report, banded.report);
        assert_eq!(
            whole.report.coverage.iter().map(|c| c.to_bits()).collect::<Vec<_>>(),
            banded.report.coverage.iter().map(|c| c.to_bits()).collect::<Vec<_>>()
        );
        // and what the layers put on a scene (vertex weights, `_SURFACE`, base colour) alike
        let (mut a, mut b) = (scene.clone(), scene);
        whole.texture(&mut a, &hf, "terrain").unwrap();
        banded.texture(&mut b, &hf, "terrain").unwrap();
        assert!(a == b, "the layers put on the scene differ");
    }

    #[test]
    fn band_layer_rows_join_to_the_whole_maps_bake_bit_for_bit() {
        // bare ground: the four layers by slope and the snowline
        bands_join_to_the_whole_bake(&preset(""));
        // grass and trees on their slopes (soil between), under a `[snow]` cover
        bands_join_to_the_whole_bake(&preset(PINES_AND_GRASS_UNDER_SNOW));
    }

    #[test]
    fn a_damaged_entry_does_not_read_back() {
        let b = BandLayers {
            cover: None,
            rows: LayerRows {
                first: 2,
                width: 4,
                weights: vec![vec![[1, 2, 3, 4]; 8]],
                albedo_rgba8: vec![9; 32],
                sums: vec![[0.5; 5]; 2],
            },
        };
        let bytes = to_bytes(&b).unwrap();
        assert_eq!(from_bytes(&bytes, [4, 8]), Some(b.clone()));
        assert_eq!(from_bytes(&bytes[..bytes.len() - 1], [4, 8]), None, "cut short");
        assert_eq!(from_bytes(&[bytes.clone(), vec![0]].concat(), [4, 8]), None, "a byte too many");
        assert_eq!(from_bytes(&bytes, [8, 8]), None, "another map's width");
        assert_eq!(from_bytes(&bytes, [4, 3]), None, "rows past the map");
        // a cover's entry: a ground other than grass (0) or canopy (1) is damage
        let covered = BandLayers {
            cover: Some(VegetationCover {
                extent: [0.0, 0.0, 6.0, 14.0],
                size: [4, 8],
                species: vec![SpeciesCover {
                    ground: crate::terrain::vegetation::Ground::Canopy,
                    max_density: 0.1,
                    height_m: 9.0,
                    footprint_m2: 3.0,
                    weights: vec![0.25; 8],
                }],
                first_row: 2,
            }),
            rows: LayerRows { weights: vec![vec![[1, 2, 3, 4]; 8]; 2], ..b.rows.clone() },
        };
        let bytes_c = to_bytes(&covered).unwrap();
        assert_eq!(from_bytes(&bytes_c, [4, 8]), Some(covered.clone()));
        let mut bad = bytes_c.clone();
        bad[20] = 2;
        assert_eq!(from_bytes(&bad, [4, 8]), None, "ground 2");
        // one weight map with a cover (its soil map lost) is damage too
        let one_map = BandLayers { rows: b.rows.clone(), ..covered };
        assert_eq!(from_bytes(&to_bytes(&one_map).unwrap(), [4, 8]), None);
        // a species count no entry could hold is refused before anything is reserved for it
        let mut huge = bytes.clone();
        huge[16..20].copy_from_slice(&u32::MAX.to_le_bytes());
        assert_eq!(from_bytes(&huge, [4, 8]), None);
        // every cut and every flipped byte of the header reads back as nothing or as rows, never
        // a panic
        for cut in 0..bytes.len() {
            assert_eq!(from_bytes(&bytes[..cut], [4, 8]), None, "cut at {cut}");
        }
        for k in 0..20 {
            let mut b = bytes.clone();
            b[k] ^= 0x5a;
            let _ = from_bytes(&b, [4, 8]);
        }
    }
}
