//! Vertical error of a terrain triangulation against its heightfield: the analyzer paired with the
//! meshers (`grid`, `tin`). Every sample is located in the triangles covering it (closed triangles,
//! so samples on edges count) and compared with the plane through the triangle's three samples.
//!
//! Deliberately independent of `tin`'s rasteriser: triangles are scanned over their bounding box with
//! a direct integer inside test per sample, so a bug in the mesher's span arithmetic shows up here.
//! Only the interpolation formula is shared by definition (see [`plane_height`]), so that the error
//! the mesher reports and the error measured here agree to the last bit.
//!
//! Also home of [`TerrainError`], the one error type of the terrain module.

use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

use crate::heightfield::Heightfield;
use crate::terrain::plane::plane_height;
use crate::terrain::sample_mesh::SampleMesh;
use crate::terrain::stored::Storage;

/// Largest width or height the meshers accept: keeps every edge function (products of two sample
/// coordinates) exact in `i64` and every coordinate exact in `f64`.
pub const MAX_SIDE_SAMPLES: usize = 1 << 24;

/// Everything that can go wrong when meshing a heightfield.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TerrainError {
    #[error(
        "heightfield of {width}×{height} samples has no area: a terrain needs at least 2×2 samples \
         (check the heightmap's size or crop)"
    )]
    ZeroArea { width: usize, height: usize },
    #[error(
        "heightfield of {width}×{height} samples is too large: at most {max} samples per side are \
         supported, and 2^32 in all; split the map into tiles"
    )]
    TooLarge { width: usize, height: usize, max: usize },
    #[error("heightfield claims {width}×{height} samples but holds {len} heights")]
    SizeMismatch { width: usize, height: usize, len: usize },
    #[error("height at sample (column {i}, row {j}) is not a finite number; fix or mask the heightmap")]
    NonFiniteHeight { i: usize, j: usize },
    #[error("grid step must be at least 1 sample, got {step}")]
    ZeroStep { step: usize },
    #[error("maximum error must be a finite number of metres ≥ 0, got {value}")]
    InvalidMaxError { value: f64 },
    #[error("triangle limit {limit} is below 2: the two triangles of the corner rectangle are the coarsest terrain")]
    TriangleLimitTooSmall { limit: usize },
    #[error(
        "--max-error {max_error_m} m (`max_error` in a preset) is finer than the file can store the terrain's heights: at sample (column {i}, \
         row {j}), {height_m} m, {storage} are {step_m:e} m apart, so the written surface is {achieved_m:e} m \
         off there, at a vertex no further refinement moves; use a bound of at least {achieved_m:e} m"
    )]
    BelowStoragePrecision {
        max_error_m: f64,
        achieved_m: f64,
        i: usize,
        j: usize,
        height_m: f64,
        step_m: f64,
        storage: &'static str,
    },
    #[error("{}", budget_message(*.limit, *.over, *.max_error_m, *.grid))]
    OverBudget { limit: usize, over: crate::terrain::budget::OverBudget, max_error_m: f64, grid: bool },
    #[error("internal error: the triangulation could not take sample (column {i}, row {j}); please report this with the heightmap")]
    Internal { i: usize, j: usize },
}

/// The words of [`TerrainError::OverBudget`]: what was over, the options that change it (by both
/// names: the flag of `verdant terrain` and the key of a preset's `[terrain]`).
fn budget_message(limit: usize, over: crate::terrain::budget::OverBudget, max_error_m: f64, grid: bool) -> String {
    use crate::terrain::budget::OverBudget;
    let raise = "or raise the budget (`--max-vertices N` for `verdant terrain`, `max_vertices = N` in a preset's \
                 [terrain]) if this machine has the time and memory: about 5 s and 250 MB per million vertices";
    match over {
        OverBudget::Predicted { vertices } if grid => format!(
            "the grid has {vertices} vertices, over the meshing budget of {limit}; take a larger grid step \
             (`--grid-step` / `grid_step`), use a TIN, {raise}"
        ),
        OverBudget::Predicted { vertices } => format!(
            "a mesh within {max_error_m} m needs at least about {vertices} vertices ({vertices} samples stand more \
             than the bound above or below their neighbours' mean: noise, or a map whose heights are scaled too \
             high), over the meshing budget of {limit}; check the heightmap's encoding and height scale, raise the \
             bound (`--max-error` / `max_error`), {raise}"
        ),
        OverBudget::Exceeded => format!(
            "a mesh within {max_error_m} m needs more than the meshing budget of {limit} vertices (its regions \
             went over it together while meshing); raise the bound (`--max-error` / `max_error`), cap the \
             triangles for a best-effort mesh (`--max-triangles` / `max_triangles`), {raise}"
        ),
        OverBudget::Reached { error_m } => format!(
            "the mesh reached the meshing budget of {limit} vertices with its error still {error_m} m, over the \
             bound of {max_error_m} m; raise the bound (`--max-error` / `max_error`), cap the triangles for a \
             best-effort mesh (`--max-triangles` / `max_triangles`), {raise}"
        ),
    }
}

/// Checks what every mesher relies on: at least 2×2 samples, a supported size, one finite height per
/// sample.
pub(crate) fn check_heightfield(hf: &Heightfield) -> Result<(), TerrainError> {
    let (width, height) = (hf.width, hf.height);
    if width < 2 || height < 2 {
        return Err(TerrainError::ZeroArea { width, height });
    }
    // Sample indices are stored as u32 by the TIN mesher.
    if width > MAX_SIDE_SAMPLES || height > MAX_SIDE_SAMPLES || width.saturating_mul(height) > u32::MAX as usize {
        return Err(TerrainError::TooLarge { width, height, max: MAX_SIDE_SAMPLES });
    }
    if width.checked_mul(height) != Some(hf.heights.len()) {
        return Err(TerrainError::SizeMismatch { width, height, len: hf.heights.len() });
    }
    if let Some(k) = hf.heights.iter().position(|h| !h.is_finite()) {
        return Err(TerrainError::NonFiniteHeight { i: k % width, j: k / width });
    }
    Ok(())
}

/// What [`measure`] found.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ErrorStats {
    /// Largest |mesh height − sample height| over all covered samples, in metres.
    pub max_error_m: f64,
    /// Root mean square of the per-sample error over covered samples (each sample counted once).
    pub rms_error_m: f64,
    /// Sample (column, row) where `max_error_m` occurs (the lowest row-major index on ties).
    pub worst_sample: [u32; 2],
    /// Number of samples inside at least one triangle; `width·height` for a complete triangulation.
    pub samples_covered: usize,
}

/// Triangles measured per parallel task: large enough to amortise scheduling, small enough to balance.
const TRIANGLES_PER_TASK: usize = 4096;

/// Samples measured at a time (a band of whole rows; 16 MiB of slots).
const BAND_SAMPLES: usize = 1 << 21;

/// Which surface is measured against the map's reference heights ([`Heightfield::reference`]).
#[derive(Clone, Copy)]
enum Surface<'a> {
    /// The vertices as the file stores them.
    Stored(&'a Storage),
    /// The vertices exactly at their samples (reference heights, x = i·cell, z = j·cell): the f64
    /// figure, what the triangulation achieves before any rounding.
    Exact,
}

/// Measures the vertical error of `mesh` as written (vertices at f32 positions, see
/// [`Storage::f32`]) against `hf`'s reference heights at every sample: the figure a bound is
/// promised on.
///
/// A sample on an edge or vertex shared by several triangles takes the largest error among them.
/// Triangles with vertex indices out of range, vertices outside the heightfield or zero area cover
/// nothing (so they show as missing coverage rather than a panic). Deterministic at any thread count.
pub fn measure(hf: &Heightfield, mesh: &SampleMesh) -> ErrorStats {
    measure_surface(hf, mesh, Surface::Stored(&Storage::f32(hf)))
}

/// The same measure for vertices stored as `storage` says (e.g. quantized).
pub fn measure_stored(hf: &Heightfield, mesh: &SampleMesh, storage: &Storage) -> ErrorStats {
    measure_surface(hf, mesh, Surface::Stored(storage))
}

/// The same measure with the vertices exactly at their samples, in f64 (equal to [`measure`] when
/// the heights and cell positions are exact in f32).
pub fn measure_exact(hf: &Heightfield, mesh: &SampleMesh) -> ErrorStats {
    measure_surface(hf, mesh, Surface::Exact)
}

/// The f64 figure beside `stored` (what [`measure_stored`] found for `mesh` as `storage` holds
/// it): measured again only when the storage rounds anything, else it is the same number.
pub fn exact_max_error(hf: &Heightfield, mesh: &SampleMesh, stored: &ErrorStats, storage: &Storage) -> f64 {
    if storage.is_exact() {
        stored.max_error_m
    } else {
        measure_exact(hf, mesh).max_error_m
    }
}

fn measure_surface(hf: &Heightfield, mesh: &SampleMesh, surface: Surface) -> ErrorStats {
    let band = (BAND_SAMPLES / hf.width.max(1)).clamp(1, hf.height.max(1));
    measure_surface_in_bands(hf, mesh, surface, band)
}

/// [`measure_surface`] a band of `band` rows at a time: the same figures for any band height.
fn measure_surface_in_bands(hf: &Heightfield, mesh: &SampleMesh, surface: Surface, band: usize) -> ErrorStats {
    let empty = ErrorStats { max_error_m: 0.0, rms_error_m: 0.0, worst_sample: [0, 0], samples_covered: 0 };
    let (w, h) = (hf.width, hf.height);
    if w == 0 || h == 0 || w.checked_mul(h) != Some(hf.heights.len()) || w > MAX_SIDE_SAMPLES || h > MAX_SIDE_SAMPLES {
        return empty;
    }
    // The map is measured a band of rows at a time, so the per-sample slots cover one band, not
    // the whole map (8 bytes a sample: 537 MB at 8193², once per LoD level measured at the same
    // time). Each triangle is scanned in every band its rows reach, clipped to the band's rows.
    let band = band.clamp(1, h);
    let bands = h.div_ceil(band);
    let band_span =
        |tri: &[u32; 3]| triangle_corners(mesh, tri, w, h).map(|c| (c[0][1] as usize / band, c[2][1] as usize / band));
    // the triangles of each band, in mesh order, in one list of exactly the size needed (a
    // counting sort: per-band lists would each keep growth slack)
    let mut start = vec![0usize; bands + 1];
    for (b0, b1) in mesh.triangles.iter().filter_map(band_span) {
        for b in b0..=b1 {
            start[b + 1] += 1;
        }
    }
    for b in 0..bands {
        start[b + 1] += start[b];
    }
    let mut by_band = vec![0u32; start[bands]];
    let mut next = start.clone();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let Some((b0, b1)) = band_span(tri) else { continue };
        for b in b0..=b1 {
            by_band[next[b]] = t as u32;
            next[b] += 1;
        }
    }
    // Per sample of the band: 0 = not covered, else (bits of the error as f64) + 1. Non-negative
    // f64 bit patterns order like the values, so an atomic max keeps the largest error whatever
    // the thread order.
    let mut slots: Vec<AtomicU64> = (0..band * w).map(|_| AtomicU64::new(0)).collect();
    let mut rows: Vec<(f64, usize, f64, usize)> = Vec::with_capacity(h);
    for b in 0..bands {
        let list = &by_band[start[b]..start[b + 1]];
        let (j_lo, j_hi) = (b * band, ((b + 1) * band).min(h) - 1);
        if b > 0 {
            slots.iter_mut().for_each(|s| *s.get_mut() = 0);
        }
        list.par_chunks(TRIANGLES_PER_TASK).for_each(|chunk| {
            for &t in chunk {
                let Some(corners) = triangle_corners(mesh, &mesh.triangles[t as usize], w, h) else { continue };
                scan_triangle(hf, corners, surface, &slots, j_lo as i64, j_hi as i64);
            }
        });
        // Reduce per row in parallel, then rows in order, so the RMS sum is the same at any thread
        // count.
        rows.par_extend((j_lo..=j_hi).into_par_iter().map(|j| {
            row_figures(slots[(j - j_lo) * w..(j - j_lo + 1) * w].iter().map(|s| s.load(Ordering::Relaxed)), j, w)
        }));
    }
    reduce_rows(rows, w)
}

/// One row's figures from its samples' slots (0: not covered, else the error's bits + 1): the sum
/// of squared errors, the samples covered, the largest error and its sample index (first on ties).
type RowFigures = (f64, usize, f64, usize);

fn row_figures(slots: impl Iterator<Item = u64>, j: usize, w: usize) -> RowFigures {
    let (mut sum_sq, mut covered, mut max, mut worst) = (0.0f64, 0usize, -1.0f64, 0usize);
    for (i, v) in slots.enumerate() {
        if v == 0 {
            continue;
        }
        let err = f64::from_bits(v - 1);
        covered += 1;
        sum_sq += err * err;
        if err > max {
            max = err;
            worst = j * w + i;
        }
    }
    (sum_sq, covered, max, worst)
}

/// The map's figures from every row's, rows in order.
fn reduce_rows(rows: impl IntoIterator<Item = RowFigures>, w: usize) -> ErrorStats {
    let (mut sum_sq, mut covered, mut max, mut worst) = (0.0f64, 0usize, -1.0f64, 0usize);
    for (s, c, m, k) in rows {
        sum_sq += s;
        covered += c;
        if m > max {
            max = m;
            worst = k;
        }
    }
    if covered == 0 {
        return ErrorStats { max_error_m: 0.0, rms_error_m: 0.0, worst_sample: [0, 0], samples_covered: 0 };
    }
    ErrorStats {
        max_error_m: max,
        rms_error_m: (sum_sq / covered as f64).sqrt(),
        worst_sample: [(worst % w) as u32, (worst / w) as u32],
        samples_covered: covered,
    }
}

/// What [`measure`] finds in rows `rows[0]..=rows[1]` of a map from the triangles of those rows
/// alone (a band's mesh, [`crate::terrain::regions::mesh_band`]): the figures of every row
/// strictly inside, and the slots of the two edge rows, which the neighbouring bands' triangles
/// also reach (the samples there take the largest error of either side: [`combine_rows`]).
#[derive(Debug, Clone, PartialEq)]
pub struct RowsMeasure {
    pub rows: [u32; 2],
    /// Rows `rows[0] + 1 .. rows[1]`: (sum of squares, samples covered, largest error, its sample).
    pub inner: Vec<(f64, usize, f64, usize)>,
    /// The slots of rows `rows[0]` and `rows[1]` (0: not covered, else the error's bits + 1).
    pub edges: [Vec<u64>; 2],
}

/// Measures `mesh` (as written: f32 positions) in rows `rows` of `hf` ([`RowsMeasure`]).
pub fn measure_rows(hf: &Heightfield, mesh: &SampleMesh, rows: [u32; 2]) -> RowsMeasure {
    measure_rows_on(hf, mesh, rows, Surface::Stored(&Storage::f32(hf)))
}

/// The largest error in rows `rows` of `hf` (edge rows included) of `mesh` with its vertices
/// exactly at their samples ([`measure_exact`]'s figure there, from the triangles of those rows
/// alone): over a map's bands in turn, each band's mesh in its rows, the largest of them is
/// [`measure_exact`]'s `max_error_m` of the joined mesh, bit for bit (each sample takes the
/// largest error among the triangles covering it, whichever band they belong to).
pub fn exact_max_in_rows(hf: &Heightfield, mesh: &SampleMesh, rows: [u32; 2]) -> f64 {
    largest_in_rows(&measure_rows_on(hf, mesh, rows, Surface::Exact))
}

/// The largest error a [`RowsMeasure`] holds, edge rows included (0 when it covers nothing): of a
/// band whose heights are exactly their f32 values, its f64 error in its rows, as
/// [`exact_max_in_rows`] would measure it (the same planes through the same heights).
pub fn largest_in_rows(m: &RowsMeasure) -> f64 {
    let edges = m.edges.iter().flatten().filter(|&&s| s > 0).map(|&s| f64::from_bits(s - 1));
    m.inner.iter().map(|r| r.2).chain(edges).fold(0.0, f64::max)
}

fn measure_rows_on(hf: &Heightfield, mesh: &SampleMesh, rows: [u32; 2], surface: Surface<'_>) -> RowsMeasure {
    let (w, h) = (hf.width, hf.height);
    let (j_lo, j_hi) = (rows[0] as usize, (rows[1] as usize).min(h.saturating_sub(1)));
    let slots: Vec<AtomicU64> = (0..(j_hi + 1 - j_lo) * w).map(|_| AtomicU64::new(0)).collect();
    mesh.triangles.par_chunks(TRIANGLES_PER_TASK).for_each(|chunk| {
        for tri in chunk {
            let Some(corners) = triangle_corners(mesh, tri, w, h) else { continue };
            if corners[2][1] < j_lo as i64 || corners[0][1] > j_hi as i64 {
                continue;
            }
            scan_triangle(hf, corners, surface, &slots, j_lo as i64, j_hi as i64);
        }
    });
    let row = |j: usize| -> Vec<u64> {
        slots[(j - j_lo) * w..(j - j_lo + 1) * w].iter().map(|s| s.load(Ordering::Relaxed)).collect()
    };
    let inner = (j_lo + 1..j_hi)
        .into_par_iter()
        .map(|j| row_figures(slots[(j - j_lo) * w..(j - j_lo + 1) * w].iter().map(|s| s.load(Ordering::Relaxed)), j, w))
        .collect();
    RowsMeasure { rows: [j_lo as u32, j_hi as u32], inner, edges: [row(j_lo), row(j_hi)] }
}

/// The figures of a whole map of width `w` from its bands' [`RowsMeasure`]s (in row order, each
/// band's first row the previous band's last): equal to [`measure`] of the joined mesh, bit for
/// bit (every row reduced alike, rows in order).
pub fn combine_rows(bands: &[RowsMeasure], w: usize) -> ErrorStats {
    let mut rows: Vec<RowFigures> = Vec::new();
    let mut carried: Option<Vec<u64>> = None;
    for b in bands {
        let bottom: Vec<u64> = match carried.take() {
            Some(top) => top.iter().zip(&b.edges[0]).map(|(&x, &y)| x.max(y)).collect(),
            None => b.edges[0].clone(),
        };
        rows.push(row_figures(bottom.into_iter(), b.rows[0] as usize, w));
        rows.extend(b.inner.iter().copied());
        if b.rows[1] > b.rows[0] {
            carried = Some(b.edges[1].clone());
        }
    }
    if let (Some(top), Some(last)) = (carried, bands.last()) {
        rows.push(row_figures(top.into_iter(), last.rows[1] as usize, w));
    }
    reduce_rows(rows, w)
}

/// The triangle's corners as (i, j) in ascending sample index order, or `None` if it cannot cover
/// anything (bad index, outside the map, zero area).
fn triangle_corners(mesh: &SampleMesh, tri: &[u32; 3], w: usize, h: usize) -> Option<[[i64; 2]; 3]> {
    let mut c = [[0i64; 2]; 3];
    for k in 0..3 {
        let v = mesh.vertices.get(tri[k] as usize)?;
        if v[0] as usize >= w || v[1] as usize >= h {
            return None;
        }
        c[k] = [v[0] as i64, v[1] as i64];
    }
    c.sort_by_key(|p| (p[1], p[0]));
    if orient(c[0], c[1], c[2]) == 0 {
        return None;
    }
    Some(c)
}

/// Twice the signed area of (a, b, p) in the (i, j) plane.
#[inline]
fn orient(a: [i64; 2], b: [i64; 2], p: [i64; 2]) -> i64 {
    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
}

/// Visits every sample of the triangle's bounding box in rows `j_lo..=j_hi`, keeps those inside the
/// closed triangle and records their error (`slots` holds those rows, from row `j_lo` on).
fn scan_triangle(hf: &Heightfield, c: [[i64; 2]; 3], surface: Surface, slots: &[AtomicU64], j_lo: i64, j_hi: i64) {
    let w = hf.width;
    let sign = orient(c[0], c[1], c[2]).signum();
    let area = orient(c[0], c[1], c[2]) * sign;
    let hc = match surface {
        Surface::Stored(storage) => c.map(|p| storage.stored_y(hf.at(p[0] as usize, p[1] as usize))),
        Surface::Exact => c.map(|p| hf.reference(p[1] as usize * w + p[0] as usize)),
    };
    let (i0, i1) = (c.iter().map(|p| p[0]).min().unwrap_or(0), c.iter().map(|p| p[0]).max().unwrap_or(0));
    let (j0, j1) = (c[0][1].max(j_lo), c[2][1].min(j_hi));
    for j in j0..=j1 {
        for i in i0..=i1 {
            let p = [i, j];
            let wts = [orient(c[1], c[2], p) * sign, orient(c[2], c[0], p) * sign, orient(c[0], c[1], p) * sign];
            if wts.iter().any(|&x| x < 0) {
                continue;
            }
            let k = j as usize * w + i as usize;
            let surface_m = match surface {
                Surface::Stored(storage) if storage.xz_exact() => plane_height(wts, hc, area),
                Surface::Stored(storage) => storage.height_at(c, hc, p),
                Surface::Exact => plane_height(wts, hc, area),
            };
            let err = (surface_m - hf.reference(k)).abs();
            slots[(j - j_lo) as usize * w + i as usize].fetch_max(err.to_bits() + 1, Ordering::Relaxed);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hf(width: usize, height: usize, heights: Vec<f32>) -> Heightfield {
        Heightfield { width, height, heights, cell_size_m: 1.0, exact: None }
    }

    #[test]
    fn two_triangles_over_a_bump() {
        // 3×3, centre raised by 2: the two corner triangles miss it by 2 (centre lies on the diagonal).
        let mut heights = vec![0.0; 9];
        heights[4] = 2.0;
        let map = hf(3, 3, heights);
        let mesh = SampleMesh { vertices: vec![[0, 0], [2, 0], [0, 2], [2, 2]], triangles: vec![[0, 2, 1], [1, 2, 3]] };
        let s = measure(&map, &mesh);
        assert_eq!(s.samples_covered, 9);
        assert_eq!(s.max_error_m, 2.0);
        assert_eq!(s.worst_sample, [1, 1]);
        assert!((s.rms_error_m - (4.0f64 / 9.0).sqrt()).abs() < 1e-12);
    }

    /// The banded measure gives the whole-map pass's figures bit for bit, at any band height and
    /// thread count: a TIN and a grid over a random map, bands of 1, 2, 3, 5 and all rows.
    #[test]
    fn every_band_height_gives_the_same_figures() {
        let (w, h) = (37usize, 23usize);
        let heights: Vec<f32> =
            (0..w * h).map(|k| (crate::random::mix64(k as u64 ^ 0x5eed) % 1000) as f32 * 0.01).collect();
        let map = hf(w, h, heights);
        let tin =
            crate::terrain::tin::tin(&map, &crate::terrain::tin::TinOptions { max_error_m: 0.5, ..Default::default() })
                .unwrap()
                .mesh;
        let grid = crate::terrain::grid::grid(&map, 2).unwrap();
        let storage = Storage::f32(&map);
        for mesh in [&tin, &grid] {
            let whole = measure_surface_in_bands(&map, mesh, Surface::Stored(&storage), h);
            assert!(whole.samples_covered == w * h && whole.max_error_m > 0.0, "{whole:?}");
            for band in [1, 2, 3, 5, h, 10 * h] {
                for threads in [1, 3] {
                    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                    let got = pool.install(|| measure_surface_in_bands(&map, mesh, Surface::Stored(&storage), band));
                    assert_eq!(got, whole, "band {band}, {threads} threads");
                    assert_eq!(got.rms_error_m.to_bits(), whole.rms_error_m.to_bits());
                }
            }
        }
    }

    #[test]
    fn bad_triangles_cover_nothing() {
        let map = hf(2, 2, vec![0.0; 4]);
        let mesh = SampleMesh {
            vertices: vec![[0, 0], [1, 0], [0, 1], [5, 5]],
            triangles: vec![[0, 1, 3], [0, 1, 9], [0, 0, 1]],
        };
        let s = measure(&map, &mesh);
        assert_eq!(s.samples_covered, 0);
        let s = measure(&hf(2, 2, vec![0.0; 3]), &mesh);
        assert_eq!(s.samples_covered, 0);
    }

    #[test]
    fn heightfield_checks() {
        assert_eq!(check_heightfield(&hf(1, 5, vec![0.0; 5])), Err(TerrainError::ZeroArea { width: 1, height: 5 }));
        assert_eq!(
            check_heightfield(&hf(2, 2, vec![0.0; 3])),
            Err(TerrainError::SizeMismatch { width: 2, height: 2, len: 3 })
        );
        assert_eq!(
            check_heightfield(&hf(2, 2, vec![0.0, 0.0, f32::NAN, 0.0])),
            Err(TerrainError::NonFiniteHeight { i: 0, j: 1 })
        );
        let msg = TerrainError::ZeroArea { width: 1, height: 1 }.to_string();
        assert!(msg.contains("at least 2×2"), "{msg}");
    }
}
