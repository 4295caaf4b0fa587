//! A chunked terrain's bands as pieces built apart (a shard's terrain unit, docs/sharding.md):
//! each band of whole chunks ([`crate::terrain::regions::band_lines`]) meshed at every bound of
//! the terrain (its LoD levels and its main mesh) from its own rows, and measured there. The
//! pieces of all bands, put together ([`assemble`]), are the meshes and figures meshing the whole
//! map gives, bit for bit: the same meshes as [`crate::terrain::tin::tin`] (which meshes a banded
//! map band by band as well) and the figures [`crate::terrain::error::measure`] finds on them.

use rayon::prelude::*;

use crate::heightfield::Heightfield;
use crate::heightfield::MapRows;
use crate::terrain::build::{band_chunks, BuildError};
use crate::terrain::error::{combine_rows, measure_rows, ErrorStats, RowsMeasure, TerrainError};
use crate::terrain::normal_map::{bake_rows, RowFigures, TexelRows};
use crate::terrain::regions::{join_bands, mesh_band};
use crate::terrain::sample_mesh::SampleMesh;
use crate::terrain::stored::Storage;
use crate::terrain::tin::{finish_tin_stored, TinOptions, TinResult};

/// One bound's mesh of a band (samples in the map's coordinates), the largest error its mesher
/// found, and what the analyzer measured in the band's rows.
#[derive(Debug, Clone, PartialEq)]
pub struct BandLevel {
    pub mesh: SampleMesh,
    pub mesher_error_m: f64,
    pub measure: RowsMeasure,
    /// The normal map's texel rows this band bakes at this level ([`bake_band_normals`]), when
    /// the terrain's normal maps are baked by band ([`band_texel_rows`]).
    pub normals: Option<BandNormals>,
}

/// A band's rows of a level's normal map: texel rows `first .. first + figures.len()`, as PNG
/// (the texels, `width` wide) and each row's figures.
#[derive(Debug, Clone, PartialEq)]
pub struct BandNormals {
    pub first: usize,
    pub width: usize,
    pub png: Vec<u8>,
    pub figures: Vec<RowFigures>,
}

/// A band's meshes at every bound, in the order the bounds were given.
#[derive(Debug, Clone, PartialEq)]
pub struct BandPiece {
    pub rows: [u32; 2],
    pub levels: Vec<BandLevel>,
}

/// Meshes rows `rows` of `hf` (a band; `fixed` as [`mesh_band`] takes it, cut along the lines of
/// chunks of `chunk_cells` cells) at every bound of `bounds` and measures each mesh there.
/// `storage` is `Storage::f32(hf)`.
pub fn build_band(
    hf: &Heightfield,
    storage: &Storage,
    bounds: &[f64],
    max_vertices: usize,
    chunk_cells: u32,
    rows: [u32; 2],
    fixed: [bool; 2],
) -> Result<BandPiece, TerrainError> {
    let levels: Vec<Result<BandLevel, TerrainError>> = bounds
        .par_iter()
        .map(|&max_error_m| {
            let opts = TinOptions { max_error_m, max_triangles: None, max_vertices, chunk_cells };
            let (mesh, mesher_error_m) = mesh_band(hf, &opts, storage, rows, fixed)?;
            let measure = measure_rows(hf, &mesh, rows);
            Ok(BandLevel { mesh, mesher_error_m, measure, normals: None })
        })
        .collect();
    Ok(BandPiece { rows, levels: levels.into_iter().collect::<Result<_, _>>()? })
}

/// [`build_band`] from the band's rows alone: `window` is rows `row0 ..= row0 + window.height − 1`
/// of the map (the band; `row0` a chunk line); the piece is in the map's coordinates, the same as
/// built from the whole map.
pub fn build_band_window(
    window: &Heightfield,
    row0: u32,
    bounds: &[f64],
    max_vertices: usize,
    chunk_cells: u32,
    fixed: [bool; 2],
) -> Result<BandPiece, TerrainError> {
    let storage = Storage::f32(window);
    let last = (window.height - 1) as u32;
    let mut piece = build_band(window, &storage, bounds, max_vertices, chunk_cells, [0, last], fixed)?;
    let w = window.width;
    piece.rows = [row0, row0 + last];
    for l in &mut piece.levels {
        for v in &mut l.mesh.vertices {
            v[1] += row0;
        }
        l.measure.rows = piece.rows;
        for r in &mut l.measure.inner {
            r.3 += row0 as usize * w;
        }
    }
    Ok(piece)
}

/// The whole map's mesh and figures at bound `k` of the pieces (every band's, in order), with the
/// checks [`crate::terrain::tin::tin_stored`] makes of a joined mesh.
pub fn assemble(
    hf: &Heightfield,
    storage: &Storage,
    pieces: &[BandPiece],
    k: usize,
    opts: &TinOptions,
) -> Result<(TinResult, ErrorStats), TerrainError> {
    assemble_stored(hf.width, Some((hf, storage)), pieces, k, opts)
}

/// [`assemble`] of a map `width` samples wide, `stored` the map and its storage, or `None` to join
/// without the map: exact for a map whose storage is exact ([`Storage::is_exact`]); on a map f32
/// rounds, a joined mesh over its bound as stored is then not refused here (the caller checks
/// the result's `max_error_m` and reads the map to name the worst sample).
pub fn assemble_stored(
    width: usize,
    stored: Option<(&Heightfield, &Storage)>,
    pieces: &[BandPiece],
    k: usize,
    opts: &TinOptions,
) -> Result<(TinResult, ErrorStats), TerrainError> {
    let mut lines: Vec<u32> = pieces.iter().map(|p| p.rows[0]).collect();
    lines.extend(pieces.last().map(|p| p.rows[1]));
    let bands = pieces.iter().map(|p| (p.levels[k].mesh.clone(), p.levels[k].mesher_error_m)).collect();
    let (mesh, max_error_m) = join_bands(bands, &lines);
    let measures: Vec<RowsMeasure> = pieces.iter().map(|p| p.levels[k].measure.clone()).collect();
    let stats = combine_rows(&measures, width);
    Ok((finish_tin_stored(stored, opts, mesh, max_error_m, false)?, stats))
}

/// How far (in v, the map's UV) a texel centre must lie from a band line to be a band's own.
const LINE_CLEARANCE_V: f64 = 1e-6;

/// The texel rows of each band of `lines` (a map of `map_height` sample rows) in a map
/// `texels_high` texels high: those whose centres lie inside the band's rows, where only the
/// band's faces can cover them (the faces of a band end on its lines). `None` when a texel
/// centre lies on or within [`LINE_CLEARANCE_V`] of an inner line (either band's faces could
/// cover it): such a terrain's normal maps are baked whole.
pub fn band_texel_rows(lines: &[u32], map_height: usize, texels_high: u32) -> Option<Vec<std::ops::Range<usize>>> {
    let h = texels_high as usize;
    let span = (map_height.max(2) - 1) as f64;
    let mut out = Vec::with_capacity(lines.len().saturating_sub(1));
    let mut y = 0;
    for (k, w) in lines.windows(2).enumerate() {
        let start = y;
        let inner = k + 2 < lines.len();
        let line_v = w[1] as f64 / span;
        while y < h {
            let tv = (y as f64 + 0.5) / h as f64;
            if inner {
                if (tv - line_v).abs() <= LINE_CLEARANCE_V {
                    return None;
                }
                if tv > line_v {
                    break;
                }
            }
            y += 1;
        }
        out.push(start..y);
    }
    Some(out)
}

/// The band's texel rows `texel_rows` of the normal map (`map_px`) of its chunks at one level:
/// `mesh` (the band's mesh at that level) built into chunks as the scene builds them (`pitch`,
/// `skirt_depth_m`; [`band_chunks`]) from `rows`, the band's rows and the row beyond each inner
/// edge, and baked ([`bake_rows`]). The same texels and row figures as the whole map's bake, bit
/// for bit, for the rows [`band_texel_rows`] gives the band.
pub fn bake_band_normals(
    rows: &MapRows,
    mesh: &SampleMesh,
    pitch: usize,
    skirt_depth_m: Option<f64>,
    map_px: [u32; 2],
    texel_rows: std::ops::Range<usize>,
) -> Result<BandNormals, BuildError> {
    let chunks = band_chunks(rows, mesh, pitch, skirt_depth_m, true)?;
    bake_band_normals_of(&chunks, rows, map_px, texel_rows)
}

/// [`bake_band_normals`] of the band's chunks built already (shaded, from `rows`).
pub fn bake_band_normals_of(
    chunks: &[([usize; 2], crate::mesh::Primitive)],
    rows: &MapRows,
    map_px: [u32; 2],
    texel_rows: std::ops::Range<usize>,
) -> Result<BandNormals, BuildError> {
    // (a band's texels are read by the rows beyond its edges at most: the chunks' check)
    let baked = bake_rows(chunks.iter().map(|(_, p)| p), rows, map_px, texel_rows);
    // (a band may hold no texel centre: a short last band under a map's coarse texels)
    let png = if baked.figures.is_empty() {
        Vec::new()
    } else {
        crate::bake::raster::png::encode_rgba8_png(baked.texels.as_flattened(), map_px[0], baked.figures.len() as u32)
            .map_err(BuildError::NormalRows)?
    };
    Ok(BandNormals { first: baked.first, width: baked.width, png, figures: baked.figures })
}

/// A level's whole normal map from its bands' rows (every band's, in order).
pub fn join_normals(parts: &[&BandNormals], map_px: [u32; 2]) -> Result<TexelRows, String> {
    let [w, h] = map_px.map(|c| c as usize);
    let mut out = TexelRows { first: 0, width: w, texels: Vec::with_capacity(w * h), figures: Vec::with_capacity(h) };
    for part in parts {
        if part.first != out.figures.len() || part.width != w {
            return Err(format!(
                "a band's normal map rows start at {} ({} wide) where row {} ({w} wide) was due",
                part.first,
                part.width,
                out.figures.len()
            ));
        }
        if !part.figures.is_empty() {
            let img = image::load_from_memory_with_format(&part.png, image::ImageFormat::Png)
                .map_err(|e| format!("a band's normal map rows do not decode: {e}"))?
                .into_rgba8();
            if img.width() as usize != w || img.height() as usize != part.figures.len() {
                return Err(format!("a band's normal map rows are {}×{} texels", img.width(), img.height()));
            }
            out.texels.extend(img.into_raw().chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]));
        }
        out.figures.extend_from_slice(&part.figures);
    }
    if out.figures.len() != h {
        return Err(format!("the bands' normal map rows end at {} of {h}", out.figures.len()));
    }
    Ok(out)
}

/// Little-endian words, as a piece is kept in the cache.
pub(crate) struct Writer(pub Vec<u8>);

impl Writer {
    pub fn u64(&mut self, v: u64) {
        self.0.extend(v.to_le_bytes());
    }
    pub fn f64(&mut self, v: f64) {
        self.u64(v.to_bits());
    }
    pub fn u32s(&mut self, v: impl ExactSizeIterator<Item = u32>) {
        self.u64(v.len() as u64);
        for x in v {
            self.0.extend(x.to_le_bytes());
        }
    }
    pub fn u64s(&mut self, v: &[u64]) {
        self.u64(v.len() as u64);
        for &x in v {
            self.u64(x);
        }
    }
    pub fn bytes(&mut self, v: &[u8]) {
        self.u64(v.len() as u64);
        self.0.extend_from_slice(v);
    }
}

pub(crate) struct Reader<'a>(pub &'a [u8]);

impl Reader<'_> {
    pub fn take(&mut self, n: usize) -> Option<&[u8]> {
        if self.0.len() < n {
            return None;
        }
        let (head, rest) = self.0.split_at(n);
        self.0 = rest;
        Some(head)
    }
    pub fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    pub fn f64(&mut self) -> Option<f64> {
        self.u64().map(f64::from_bits)
    }
    pub fn len(&mut self, unit: usize) -> Option<usize> {
        let n = usize::try_from(self.u64()?).ok()?;
        // never more than the bytes left can hold
        (n.checked_mul(unit)? <= self.0.len()).then_some(n)
    }
    pub fn u32s(&mut self) -> Option<Vec<u32>> {
        let n = self.len(4)?;
        Some(self.take(4 * n)?.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
    }
    pub fn u64s(&mut self) -> Option<Vec<u64>> {
        let n = self.len(8)?;
        (0..n).map(|_| self.u64()).collect()
    }
    pub fn bytes(&mut self) -> Option<Vec<u8>> {
        let n = self.len(1)?;
        Some(self.take(n)?.to_vec())
    }
}

const MAGIC: u64 = u64::from_le_bytes(*b"vbandv02");

impl BandPiece {
    /// The piece as bytes (every number exactly: f64 by its bits).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer(Vec::new());
        w.u64(MAGIC);
        w.u64(self.rows[0] as u64);
        w.u64(self.rows[1] as u64);
        w.u64(self.levels.len() as u64);
        for l in &self.levels {
            w.u32s(l.mesh.vertices.iter().flatten().copied().collect::<Vec<_>>().into_iter());
            w.u32s(l.mesh.triangles.iter().flatten().copied().collect::<Vec<_>>().into_iter());
            w.f64(l.mesher_error_m);
            let m = &l.measure;
            w.u64(m.rows[0] as u64);
            w.u64(m.rows[1] as u64);
            w.u64(m.inner.len() as u64);
            for &(sum_sq, covered, max, worst) in &m.inner {
                w.f64(sum_sq);
                w.u64(covered as u64);
                w.f64(max);
                w.u64(worst as u64);
            }
            w.u64s(&m.edges[0]);
            w.u64s(&m.edges[1]);
            match &l.normals {
                None => w.u64(0),
                Some(n) => {
                    w.u64(1);
                    w.u64(n.first as u64);
                    w.u64(n.width as u64);
                    w.u64(n.figures.len() as u64);
                    for f in &n.figures {
                        w.f64(f.sum_without);
                        w.f64(f.max_without);
                        w.f64(f.sum_with);
                        w.f64(f.max_with);
                        w.u64(f.texels);
                    }
                    w.bytes(&n.png);
                }
            }
        }
        w.0
    }

    /// A piece back from [`BandPiece::to_bytes`]; `None` for bytes that are not one (a damaged
    /// cache entry is built again).
    pub fn from_bytes(bytes: &[u8]) -> Option<BandPiece> {
        let mut r = Reader(bytes);
        if r.u64()? != MAGIC {
            return None;
        }
        let row = |r: &mut Reader| u32::try_from(r.u64()?).ok();
        let rows = [row(&mut r)?, row(&mut r)?];
        let count = r.len(1)?;
        let mut levels = Vec::with_capacity(count);
        for _ in 0..count {
            let v = r.u32s()?;
            let t = r.u32s()?;
            if v.len() % 2 != 0 || t.len() % 3 != 0 {
                return None;
            }
            let mesh = SampleMesh {
                vertices: v.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
                triangles: t.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
            };
            let mesher_error_m = r.f64()?;
            let measure_rows = [row(&mut r)?, row(&mut r)?];
            let n = r.len(32)?;
            let mut inner = Vec::with_capacity(n);
            for _ in 0..n {
                inner.push((r.f64()?, r.u64()? as usize, r.f64()?, r.u64()? as usize));
            }
            let edges = [r.u64s()?, r.u64s()?];
            let normals = match r.u64()? {
                0 => None,
                1 => {
                    let first = usize::try_from(r.u64()?).ok()?;
                    let width = usize::try_from(r.u64()?).ok()?;
                    let n = r.len(40)?;
                    let mut figures = Vec::with_capacity(n);
                    for _ in 0..n {
                        figures.push(RowFigures {
                            sum_without: r.f64()?,
                            max_without: r.f64()?,
                            sum_with: r.f64()?,
                            max_with: r.f64()?,
                            texels: r.u64()?,
                        });
                    }
                    Some(BandNormals { first, width, png: r.bytes()?, figures })
                }
                _ => return None,
            };
            let measure = RowsMeasure { rows: measure_rows, inner, edges };
            levels.push(BandLevel { mesh, mesher_error_m, measure, normals });
        }
        r.0.is_empty().then_some(BandPiece { rows, levels })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::error::measure;
    use crate::terrain::regions::band_lines;
    use crate::terrain::tin::tin;

    #[test]
    fn pieces_built_apart_put_together_are_the_whole_maps_meshes_and_figures_bit_for_bit() {
        // 3 bands of 384 rows (the last shorter), three bounds; f32 and decimetre heights
        let rough = crate::synth::fractal(600, 1100, 1.0, 300.0, 0.6, 41);
        let tenths: Vec<f64> = rough.heights.iter().map(|&z| (z as f64 * 10.0).round() / 10.0).collect();
        for hf in [rough.clone(), Heightfield::from_f64(600, 1100, &tenths, 1.0)] {
            let storage = Storage::f32(&hf);
            let lines = band_lines(hf.height, 384, storage.xz_exact());
            assert_eq!(lines, vec![0, 384, 768, 1099]);
            let bounds = [0.5, 2.0, 8.0];
            let last = lines[lines.len() - 1];
            let pieces: Vec<BandPiece> = lines
                .windows(2)
                .map(|w| {
                    let piece =
                        build_band(&hf, &storage, &bounds, usize::MAX, 128, [w[0], w[1]], [w[0] > 0, w[1] < last])
                            .unwrap();
                    // kept as bytes and read back, as a shard hands it over
                    let back = BandPiece::from_bytes(&piece.to_bytes()).unwrap();
                    assert_eq!(back, piece);
                    back
                })
                .collect();
            for (k, &bound) in bounds.iter().enumerate() {
                let opts =
                    TinOptions { max_error_m: bound, chunk_cells: 128, max_vertices: usize::MAX, ..Default::default() };
                let (result, stats) = assemble(&hf, &storage, &pieces, k, &opts).unwrap();
                let whole = tin(&hf, &opts).unwrap();
                assert_eq!(result, whole, "bound {bound}: the pieces' mesh is not the map's");
                let measured = measure(&hf, &whole.mesh);
                assert_eq!(stats, measured, "bound {bound}: the pieces' figures are not the analyzer's");
                assert_eq!(stats.rms_error_m.to_bits(), measured.rms_error_m.to_bits());
                assert_eq!(stats.samples_covered, hf.width * hf.height);
            }
        }
    }

    /// Each band's f64 error in its rows from its window alone ([`exact_max_in_rows`]), the
    /// largest of them, is the f64 error of the joined mesh over the whole map, bit for bit: on
    /// decimetre heights (which f32 rounds), and with the worst sample on a band line (a ridge of
    /// 0.3 m bumps along row 384, which the seam keeps within the bound without a vertex there).
    #[test]
    fn the_bands_f64_errors_from_their_rows_give_the_whole_maps() {
        use crate::terrain::error::{exact_max_in_rows, measure_exact};
        let rough = crate::synth::fractal(500, 1000, 1.0, 200.0, 0.6, 8);
        let tenths: Vec<f64> = rough.heights.iter().map(|&z| (z as f64 * 10.0).round() / 10.0).collect();
        let ridge: Vec<f64> = (0..500 * 1000)
            .map(|k| {
                let (i, j) = (k % 500, k / 500);
                ((i as f64 * 0.01 + j as f64 * 0.02) * 10.0).round() / 10.0
                    + if j == 384 && i % 2 == 1 { 0.3 } else { 0.0 }
            })
            .collect();
        for (name, heights) in [("tenths", &tenths), ("ridge on a band line", &ridge)] {
            let hf = Heightfield::from_f64(500, 1000, heights, 1.0);
            let storage = Storage::f32(&hf);
            assert!(!storage.is_exact(), "{name}: f32 rounds the heights");
            let bounds = [0.5, 3.0];
            let bands = [([0, 384], [false, true]), ([384, 768], [true, true]), ([768, 999], [true, false])];
            let pieces: Vec<(BandPiece, f64)> = bands
                .iter()
                .map(|&(rows, fixed)| {
                    let window = hf.rows(rows[0] as usize, rows[1] as usize).unwrap();
                    let piece = build_band_window(&window, rows[0], &bounds, usize::MAX, 128, fixed).unwrap();
                    let mut local = piece.levels[0].mesh.clone();
                    for v in &mut local.vertices {
                        v[1] -= rows[0];
                    }
                    let e = exact_max_in_rows(&window, &local, [0, rows[1] - rows[0]]);
                    (piece, e)
                })
                .collect();
            let opts =
                TinOptions { max_error_m: 0.5, chunk_cells: 128, max_vertices: usize::MAX, ..Default::default() };
            let just: Vec<BandPiece> = pieces.iter().map(|(p, _)| p.clone()).collect();
            let (joined, _) = assemble(&hf, &storage, &just, 0, &opts).unwrap();
            let whole = measure_exact(&hf, &joined.mesh);
            let largest = pieces.iter().map(|(_, e)| *e).fold(0.0, f64::max);
            assert_eq!(largest.to_bits(), whole.max_error_m.to_bits(), "{name}");
            if name.starts_with("ridge") {
                assert_eq!(whole.worst_sample[1], 384, "{name}: the worst sample is on the band line");
            }
        }
    }

    #[test]
    fn a_band_built_from_its_rows_alone_is_the_band_built_from_the_whole_map() {
        let rough = crate::synth::fractal(500, 1000, 1.0, 200.0, 0.6, 8);
        let tenths: Vec<f64> = rough.heights.iter().map(|&z| (z as f64 * 10.0).round() / 10.0).collect();
        for hf in [rough.clone(), Heightfield::from_f64(500, 1000, &tenths, 1.0)] {
            let storage = Storage::f32(&hf);
            for (rows, fixed) in [([0, 384], [false, true]), ([384, 768], [true, true]), ([768, 999], [true, false])] {
                let whole = build_band(&hf, &storage, &[0.5, 3.0], usize::MAX, 128, rows, fixed).unwrap();
                let window = hf.rows(rows[0] as usize, rows[1] as usize).unwrap();
                let alone = build_band_window(&window, rows[0], &[0.5, 3.0], usize::MAX, 128, fixed).unwrap();
                assert_eq!(alone, whole, "rows {rows:?}");
            }
        }
    }

    /// A band's chunks built from its rows and its piece alone are the chunks of the scene built
    /// from the whole map and the joined mesh: positions, skirts and triangle order bit for bit
    /// (what places instances on a shard's bands), and with the rows beyond its edges their normals
    /// and UVs too; a piece of other rows is refused.
    #[test]
    fn a_bands_chunk_surfaces_from_its_rows_are_the_whole_scenes_chunks() {
        use crate::heightfield::MapRows;
        use crate::terrain::build::{band_chunk_surfaces, band_chunks, build_scene, BuildError, BuildOptions};
        let hf = crate::synth::fractal(300, 1000, 1.5, 200.0, 0.6, 12);
        let storage = Storage::f32(&hf);
        let lines = band_lines(hf.height, 384, storage.xz_exact());
        let last = lines[lines.len() - 1];
        for (pitch, skirt) in [(128usize, Some(3.0)), (128, None), (192, Some(1.0))] {
            let band_cells = crate::terrain::regions::band_cells_for_chunk(Some(pitch));
            let lines = band_lines(hf.height, band_cells, true);
            let mut from_bands = Vec::new();
            let mut shaded_bands = Vec::new();
            let pieces: Vec<BandPiece> = lines
                .windows(2)
                .map(|w| {
                    let window = hf.rows(w[0] as usize, w[1] as usize).unwrap();
                    let piece =
                        build_band_window(&window, w[0], &[0.8], usize::MAX, pitch as u32, [w[0] > 0, w[1] < last])
                            .unwrap();
                    let chunks =
                        band_chunk_surfaces(&window, w[0] as usize, hf.height, &piece.levels[0].mesh, pitch, skirt)
                            .unwrap();
                    // shaded: from the band's rows and the row beyond each inner edge
                    let (r0, r1) = ((w[0] as usize).saturating_sub(1), (w[1] as usize + 1).min(hf.height - 1));
                    let margin = hf.rows(r0, r1).unwrap();
                    let rows = MapRows::new(&margin, r0, hf.height).unwrap();
                    let shaded = band_chunks(&rows, &piece.levels[0].mesh, pitch, skirt, true).unwrap();
                    assert_eq!(shaded.len(), chunks.len());
                    for ((at, plain), (at_shaded, lit)) in chunks.iter().zip(&shaded) {
                        assert_eq!((at, &plain.indices, &plain.positions), (at_shaded, &lit.indices, &lit.positions));
                    }
                    // without the rows beyond its edges, a band cannot be shaded
                    if w[0] > 0 {
                        let tight = MapRows::new(&window, w[0] as usize, hf.height).unwrap();
                        let e = band_chunks(&tight, &piece.levels[0].mesh, pitch, skirt, true);
                        assert!(matches!(e, Err(BuildError::BandMismatch(_))), "{e:?}");
                    }
                    from_bands.extend(chunks);
                    shaded_bands.extend(shaded);
                    piece
                })
                .collect();
            let chunk_cells = pitch as u32;
            let opts = TinOptions { max_error_m: 0.8, chunk_cells, max_vertices: usize::MAX, ..Default::default() };
            let (joined, _) = assemble(&hf, &storage, &pieces, 0, &opts).unwrap();
            let scene = build_scene(
                &hf,
                &joined.mesh,
                &BuildOptions { chunk_samples: Some(pitch), skirt_depth_m: skirt, ..BuildOptions::default() },
            )
            .unwrap();
            let chunks: Vec<_> = scene.meshes.iter().filter(|m| m.name.contains("_chunk_")).collect();
            assert_eq!(chunks.len(), from_bands.len(), "pitch {pitch}");
            assert!(lines.len() > 2, "several bands");
            for (whole, ([ci, cj], band)) in chunks.iter().zip(&from_bands) {
                assert_eq!(whole.name, format!("terrain_chunk_{ci}_{cj}"));
                let p = &whole.primitives[0];
                assert_eq!(p.indices, band.indices, "{}", whole.name);
                let bits = |v: &[[f32; 3]]| v.iter().map(|p| p.map(f32::to_bits)).collect::<Vec<_>>();
                assert_eq!(bits(&p.positions), bits(&band.positions), "{}", whole.name);
                assert!(band.normals.is_empty() && band.uvs.is_empty());
            }
            for (whole, (_, band)) in chunks.iter().zip(&shaded_bands) {
                let p = &whole.primitives[0];
                let bits3 = |v: &[[f32; 3]]| v.iter().map(|p| p.map(f32::to_bits)).collect::<Vec<_>>();
                let bits2 = |v: &[[f32; 2]]| v.iter().map(|p| p.map(f32::to_bits)).collect::<Vec<_>>();
                assert_eq!(p.indices, band.indices, "{}", whole.name);
                assert_eq!(bits3(&p.positions), bits3(&band.positions), "{}", whole.name);
                assert_eq!(bits3(&p.normals), bits3(&band.normals), "{}", whole.name);
                assert_eq!(bits2(&p.uvs), bits2(&band.uvs), "{}", whole.name);
            }
        }
        // a band's mesh handed rows it was not built from
        let window = hf.rows(0, 384).unwrap();
        let piece = build_band_window(&window, 0, &[0.8], usize::MAX, 128, [false, true]).unwrap();
        let e = band_chunk_surfaces(&hf.rows(384, 600).unwrap(), 384, hf.height, &piece.levels[0].mesh, 128, None);
        assert!(matches!(e, Err(BuildError::BandMismatch(_))), "{e:?}");
    }

    /// A level's normal map baked band by band — each band's chunks from its rows and the row
    /// beyond each inner edge, its own texel rows — and joined is the whole scene's map: the same
    /// PNG and the same figures, bit for bit; the rows survive the piece's bytes.
    #[test]
    fn normal_maps_baked_by_band_are_the_whole_scenes() {
        use crate::terrain::build::{build_scene, BuildOptions};
        use crate::terrain::normal_map::{bake_normal_map, put_normal_map};
        let tall = crate::synth::fractal(300, 1000, 2.0, 180.0, 0.6, 5);
        let storage = Storage::f32(&tall);
        for (pitch, skirt, px) in [(128usize, Some(2.0), [256u32, 1024u32]), (192, None, [512, 512])] {
            let band_cells = crate::terrain::regions::band_cells_for_chunk(Some(pitch));
            let lines = band_lines(tall.height, band_cells, true);
            assert!(lines.len() > 3, "several bands: {lines:?}");
            let last = lines[lines.len() - 1];
            let texel_rows = band_texel_rows(&lines, tall.height, px[1]).unwrap();
            let pieces: Vec<BandPiece> = lines
                .windows(2)
                .zip(&texel_rows)
                .map(|(w, texels)| {
                    let (r0, r1) = ((w[0] as usize).saturating_sub(1), (w[1] as usize + 1).min(tall.height - 1));
                    let margin = tall.rows(r0, r1).unwrap();
                    let window = tall.rows(w[0] as usize, w[1] as usize).unwrap();
                    let mut piece =
                        build_band_window(&window, w[0], &[1.5], usize::MAX, pitch as u32, [w[0] > 0, w[1] < last])
                            .unwrap();
                    let rows = MapRows::new(&margin, r0, tall.height).unwrap();
                    let normals =
                        bake_band_normals(&rows, &piece.levels[0].mesh, pitch, skirt, px, texels.clone()).unwrap();
                    piece.levels[0].normals = Some(normals);
                    BandPiece::from_bytes(&piece.to_bytes()).unwrap()
                })
                .collect();
            let opts = TinOptions {
                max_error_m: 1.5,
                chunk_cells: pitch as u32,
                max_vertices: usize::MAX,
                ..Default::default()
            };
            let (joined, _) = assemble(&tall, &storage, &pieces, 0, &opts).unwrap();
            let build = BuildOptions { chunk_samples: Some(pitch), skirt_depth_m: skirt, ..BuildOptions::default() };
            let mut whole = build_scene(&tall, &joined.mesh, &build).unwrap();
            let expected = bake_normal_map(&tall, &mut whole, "terrain", px).unwrap();
            let parts: Vec<&BandNormals> = pieces.iter().map(|p| p.levels[0].normals.as_ref().unwrap()).collect();
            let rows = join_normals(&parts, px).unwrap();
            let mut banded = build_scene(&tall, &joined.mesh, &build).unwrap();
            let got = put_normal_map(&mut banded, "terrain", px, rows).unwrap();
            assert_eq!(got, expected, "pitch {pitch}");
            assert_eq!(got.mean_error_deg.to_bits(), expected.mean_error_deg.to_bits());
            assert!(expected.texels == (px[0] * px[1]) as usize && expected.max_error_without_deg > 1.0);
            assert_eq!(banded, whole, "pitch {pitch}: the same scene, normal map and tangents included");
            // a band missing is refused, not joined into a short map
            assert!(join_normals(&parts[1..], px).is_err());
            // a band of no texel rows bakes and joins as nothing (no PNG of zero rows)
            let last_band = lines.len() - 2;
            let (r0, r1) = (lines[last_band] as usize - 1, tall.height - 1);
            let margin = tall.rows(r0, r1).unwrap();
            let rows = MapRows::new(&margin, r0, tall.height).unwrap();
            let end = px[1] as usize;
            let mesh = &pieces[last_band].levels[0].mesh;
            let empty = bake_band_normals(&rows, mesh, pitch, skirt, px, end..end).unwrap();
            assert!(empty.png.is_empty() && empty.figures.is_empty() && empty.first == end);
            let mut with_empty = parts.clone();
            with_empty.push(&empty);
            assert_eq!(join_normals(&with_empty, px).unwrap().figures.len(), end);
        }
    }

    /// Texel rows go to the band their centres lie in; a centre on an inner line (or too near
    /// it to tell whose face covers it) leaves the map to be baked whole.
    #[test]
    fn texel_rows_go_to_the_band_their_centres_lie_in() {
        // 9 sample rows (v = j / 8), lines at rows 0, 4, 8: v = 0.5 between the two bands
        assert_eq!(band_texel_rows(&[0, 4, 8], 9, 4), Some(vec![0..2, 2..4]));
        assert_eq!(band_texel_rows(&[0, 4, 8], 9, 8), Some(vec![0..4, 4..8]));
        assert_eq!(band_texel_rows(&[0, 4, 8], 9, 3), None, "texel 1's centre is at v = 0.5");
        assert_eq!(band_texel_rows(&[0, 8], 9, 3), Some(vec![0..3]), "one band: every row");
        // a short last band under coarse texels holds no texel centre (v = 0.875 < 8/9)
        assert_eq!(band_texel_rows(&[0, 4, 8, 9], 10, 4), Some(vec![0..2, 2..4, 4..4]));
        // the world preset's map: 8193 rows in bands of 512, 8192 texels
        let lines: Vec<u32> = (0..=16).map(|k| k * 512).collect();
        let rows = band_texel_rows(&lines, 8193, 8192).unwrap();
        assert_eq!(rows.len(), 16);
        assert!(rows.iter().all(|r| r.len() == 512) && rows[15].end == 8192);
    }

    #[test]
    fn bytes_that_are_not_a_piece_are_refused_not_misread() {
        let hf = crate::synth::fractal(300, 700, 1.0, 100.0, 0.5, 3);
        let storage = Storage::f32(&hf);
        let piece = build_band(&hf, &storage, &[1.0], usize::MAX, 128, [0, 384], [false, true]).unwrap();
        let bytes = piece.to_bytes();
        assert!(BandPiece::from_bytes(&bytes[..bytes.len() - 1]).is_none(), "a cut piece");
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(BandPiece::from_bytes(&longer).is_none(), "trailing bytes");
        let mut wrong = bytes.clone();
        wrong[0] ^= 1;
        assert!(BandPiece::from_bytes(&wrong).is_none(), "another format");
        let mut huge = bytes;
        huge[32..40].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(BandPiece::from_bytes(&huge).is_none(), "a length past the end");
    }
}
