//! A large map meshed as a grid of regions in parallel, joined without a crack.
//!
//! The map is cut into about [`REGION_CELLS`]-cell rectangles along fixed sample lines (the cut
//! depends only on the map's size, never on the thread count). Each seam between two neighbouring
//! regions is simplified first, in one dimension, to the bound (the samples on a seam are then within
//! it along the hull edges every region starts from); both regions start from the same seam samples,
//! mesh their own samples by greedy insertion ([`mesh_region`]) and are joined by merging the seam
//! vertices. Should a region still insert a sample on a seam (a sample whose error the plane of its
//! triangle rounds over the bound), the sample joins the seam and both regions are meshed again,
//! until no region adds one: the result is watertight by construction, not by luck.
//!
//! A chunked map is cut along every chunk line (and each chunk further, as a map of its size), so
//! at any bound each chunk's triangles lie in its square: chunks of different levels side by side
//! meet along one straight line, never leaving a hole ([`cuts_between`]). It is first cut into
//! bands of whole chunks ([`band_cells_for_chunk`]): each band is
//! meshed from its own rows alone ([`mesh_band`]), its edges inside the map fixed as seams that
//! never take a sample, so a band can be built apart (by a shard, from a window of the map) and
//! the bands joined into the same mesh.
//!
//! The cost against one greedy pass over the whole map: the seam vertices the 1-D pass adds (a few
//! hundred per seam where the map is rough; `benches/terrain.rs` prints the triangle counts against
//! the peer's).

use std::collections::HashMap;
use std::sync::atomic::AtomicUsize;

use rayon::prelude::*;

use crate::heightfield::Heightfield;
use crate::terrain::error::TerrainError;
use crate::terrain::sample_mesh::SampleMesh;
use crate::terrain::stored::Storage;
use crate::terrain::tin::{mesh_region, Rect, RegionMesh, SharedBudget, TinOptions};

/// About this many cells along a region's side; a map of fewer than 1.5 times this many cells a
/// side is one region along it (no seam). Small enough that a 512² map is cut in four (both cores
/// of this machine busy) and that a region's heights and queue stay in cache: measured in
/// `benches/terrain.rs`, CPU time itself drops to 0.3–0.5 of one pass over the whole map. The
/// triangle count moves by ±0.4 % with the cut (greedy insertion is not optimal either way).
pub const REGION_CELLS: u32 = 320;

/// The sample lines a map of `samples` along one axis is cut at: first 0, last `samples − 1`.
fn cuts(samples: usize) -> Vec<u32> {
    let cells = samples.saturating_sub(1) as u64;
    let n = ((cells as f64 / REGION_CELLS as f64).round() as u64).clamp(1, cells.max(1));
    (0..=n).map(|k| (k * cells / n) as u32).collect()
}

/// The sample lines between `a` and `b` (both included, `a < b`) a map is cut at along one axis
/// with chunks of `chunk` cells (0: not chunked): every chunk line between them (the multiples of
/// `chunk`), and each stretch between two of those cut further as [`cuts`] cuts a map of its size.
/// By the map's size and chunks alone, never by the thread count. (Moving each cut to the nearby
/// line whose seam keeps the fewest samples was tried: the triangle count moved by ±0.4 % either
/// way, as it does for any other placement.)
fn cuts_between(a: u32, b: u32, chunk: u32) -> Vec<u32> {
    let mut ends = vec![a];
    if chunk > 0 {
        let mut line = (a / chunk).saturating_add(1).saturating_mul(chunk);
        while line < b {
            ends.push(line);
            line = line.saturating_add(chunk);
        }
    }
    ends.push(b);
    let mut out = vec![a];
    for w in ends.windows(2) {
        out.extend(cuts((w[1] - w[0]) as usize + 1).into_iter().skip(1).map(|t| t + w[0]));
    }
    out
}

/// The cut lines of a map along x and along y ([`cuts_between`]).
fn layout(hf: &Heightfield, chunk: u32) -> (Vec<u32>, Vec<u32>) {
    let last = |n: usize| n.saturating_sub(1) as u32;
    (cuts_between(0, last(hf.width), chunk), cuts_between(0, last(hf.height), chunk))
}

/// Where a seam lies: along column `at` (rows `from..=to`) or along row `at` (columns `from..=to`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct Seam {
    vertical: bool,
    at: u32,
    from: u32,
    to: u32,
}

impl Seam {
    fn sample(&self, t: u32) -> [u32; 2] {
        if self.vertical {
            [self.at, t]
        } else {
            [t, self.at]
        }
    }
}

/// The seam samples between the ends of `seam` (ends excluded) that keep every sample of the line
/// within the bound along it: the worst sample of each stretch over the bound is kept, and its two
/// halves treated alike (in one dimension, greedy insertion and this recursion keep the same
/// samples). A sample's error is the mesher's (f32 heights) or the stored one (stored heights against
/// the reference), whichever is larger, with a margin for the rounding of the plane evaluation.
fn simplify_seam(hf: &Heightfield, storage: &Storage, seam: Seam, max_error_m: f64) -> Vec<u32> {
    let height = |t: u32| {
        let [i, j] = seam.sample(t);
        let k = j as usize * hf.width + i as usize;
        (hf.heights[k], hf.reference(k))
    };
    let error = |a: u32, b: u32, t: u32| {
        let ((ha, _), (hb, _), (h, reference)) = (height(a), height(b), height(t));
        let (wa, wb, span) = ((b - t) as f64, (t - a) as f64, (b - a) as f64);
        let mesher = ((wa * ha as f64 + wb * hb as f64) / span - h as f64).abs();
        let stored = ((wa * storage.stored_y(ha) + wb * storage.stored_y(hb)) / span - reference).abs();
        let magnitude = (ha.abs()).max(hb.abs()).max(h.abs()) as f64;
        mesher.max(stored) + 1e-9 * (1.0 + magnitude)
    };
    let mut kept = Vec::new();
    let mut stack = vec![(seam.from, seam.to)];
    while let Some((a, b)) = stack.pop() {
        let worst = (a + 1..b).map(|t| (error(a, b, t), t)).fold(None, |m: Option<(f64, u32)>, (e, t)| match m {
            Some((me, _)) if me >= e => m,
            _ => Some((e, t)),
        });
        if let Some((e, t)) = worst {
            if e > max_error_m {
                kept.push(t);
                stack.push((a, t));
                stack.push((t, b));
            }
        }
    }
    kept.sort_unstable();
    kept
}

/// Meshes `hf` region by region in parallel (one region when the map is small) and joins the
/// regions; returns the mesh and its largest error (as [`mesh_region`] measures it). With
/// `opts.chunk_cells` the map is cut along its chunk lines and meshed band by band
/// ([`band_lines`], [`mesh_band`]).
pub(crate) fn mesh_by_regions(
    hf: &Heightfield,
    opts: &TinOptions,
    storage: &Storage,
) -> Result<(SampleMesh, f64), TerrainError> {
    let band_cells = band_cells_for_chunk(Some(opts.chunk_cells as usize).filter(|&c| c > 0));
    let lines = band_lines(hf.height, band_cells, storage.xz_exact());
    if lines.len() > 2 {
        let bands: Vec<Result<(SampleMesh, f64), TerrainError>> = lines
            .par_windows(2)
            .map(|w| mesh_band(hf, opts, storage, [w[0], w[1]], [w[0] > 0, w[1] < lines[lines.len() - 1]]))
            .collect();
        let bands = bands.into_iter().collect::<Result<Vec<_>, _>>()?;
        return Ok(join_bands(bands, &lines));
    }
    let (xs, ys) = layout(hf, opts.chunk_cells);
    mesh_rects(hf, opts, storage, &xs, &ys, [false, false], true).map(|(mesh, error, _)| (mesh, error))
}

/// The whole map meshed as [`mesh_by_regions`] does, also returning how many rounds of meshing the
/// seams took; without `simplify_seams` the seams start empty (a test of the rounds).
#[cfg(test)]
fn mesh_by_regions_with(
    hf: &Heightfield,
    opts: &TinOptions,
    storage: &Storage,
    simplify_seams: bool,
) -> Result<(SampleMesh, f64, usize), TerrainError> {
    let (xs, ys) = layout(hf, opts.chunk_cells);
    mesh_rects(hf, opts, storage, &xs, &ys, [false, false], simplify_seams)
}

/// A terrain's chunk size in cells as [`TinOptions::chunk_cells`] takes it (0: not chunked; a
/// chunk wider than any map u32 can index cuts nothing).
pub fn chunk_cells(chunk: Option<usize>) -> u32 {
    chunk.map_or(0, |c| c.min(u32::MAX as usize) as u32)
}

/// Rows of cells in a band of a map cut into chunks of `chunk` cells: the fewest whole chunks
/// reaching [`REGION_CELLS`] (a band's edges are chunk lines, so each chunk's triangles come from
/// one band), 0 (one band) without chunks.
pub fn band_cells_for_chunk(chunk: Option<usize>) -> u32 {
    match chunk {
        Some(c) if c > 0 => (c as u64 * (REGION_CELLS as u64).div_ceil(c as u64)).min(u32::MAX as u64) as u32,
        _ => 0,
    }
}

/// The rows a map of `height` samples is cut into bands at, for bands of `band_cells` cells
/// (first 0, last `height − 1`; the last band may be shorter): `[0, height − 1]` (one band) when
/// `band_cells` is 0 or not less than the map's cells, or when the file's x and z are not exactly
/// i·cell and j·cell (see [`mesh_band`] for why a band's edges then cannot be fixed).
pub fn band_lines(height: usize, band_cells: u32, xz_exact: bool) -> Vec<u32> {
    let cells = height.saturating_sub(1) as u32;
    if band_cells == 0 || band_cells >= cells || !xz_exact {
        return vec![0, cells];
    }
    let mut lines: Vec<u32> = (0..cells).step_by(band_cells as usize).collect();
    lines.push(cells);
    lines
}

/// The rows `rows[0]..=rows[1]` of `hf` meshed on their own, as a band of the map: cut into
/// regions as the whole map is ([`cuts_between`]: the chunk lines of `opts.chunk_cells` counted
/// from row 0 of `hf`, so a window's first row must be a chunk line of the map), the band's bottom and
/// top edges, where `fixed` says a neighbouring band lies beyond them, fixed as seams simplified
/// in one dimension from their own samples alone, which the neighbouring band computes alike.
/// `hf` may be the band's rows alone (a window of the map: `rows` is then `[0, hf.height − 1]`).
/// Returns the band's mesh (samples in `hf`'s coordinates) and its largest error.
///
/// The band depends on its rows alone: no sample is ever inserted on a fixed edge. With x and z
/// stored exactly ([`band_lines`] asks for it), a sample on a hull edge is measured by the
/// triangle's plane at an exact integer weight of 0 for the far corner, which is the 1-D
/// interpolation along the edge up to rounding (the seam's margin covers it), both for the f32
/// heights and as stored; the 1-D pass kept every sample over the bound there. (Should a region
/// still insert one, the band fails with an internal error rather than leave a crack.)
pub fn mesh_band(
    hf: &Heightfield,
    opts: &TinOptions,
    storage: &Storage,
    rows: [u32; 2],
    fixed: [bool; 2],
) -> Result<(SampleMesh, f64), TerrainError> {
    let (xs, _) = layout(hf, opts.chunk_cells);
    let ys = cuts_between(rows[0], rows[1], opts.chunk_cells);
    mesh_rects(hf, opts, storage, &xs, &ys, fixed, true).map(|(mesh, error, _)| (mesh, error))
}

/// Joins band meshes (in band order, cut at `lines`): each vertex on a band line once.
pub fn join_bands(bands: Vec<(SampleMesh, f64)>, lines: &[u32]) -> (SampleMesh, f64) {
    let meshes = bands
        .into_iter()
        .map(|(m, e)| RegionMesh {
            vertices: m.vertices,
            triangles: m.triangles,
            max_error_m: e,
            hit_triangle_limit: false,
            inserted_inside: 0,
        })
        .collect();
    join(meshes, &[0, u32::MAX], lines)
}

/// Meshes the rectangles between the cut lines `xs` × `ys` of `hf` in parallel and joins them; also
/// returns how many rounds of meshing the seams took. `fixed` says whether the bottom (`ys[0]`) and
/// top (`ys[last]`) edges are seams with rectangles outside (a band's edges inside the map): they
/// are simplified like any seam but never take a sample. Without `simplify_seams` the seams start
/// empty (a test of the rounds that reconcile them).
fn mesh_rects(
    hf: &Heightfield,
    opts: &TinOptions,
    storage: &Storage,
    xs: &[u32],
    ys: &[u32],
    fixed: [bool; 2],
    simplify_seams: bool,
) -> Result<(SampleMesh, f64, usize), TerrainError> {
    let (nx, ny) = (xs.len() - 1, ys.len() - 1);
    let rect = |rx: usize, ry: usize| Rect { i0: xs[rx], j0: ys[ry], i1: xs[rx + 1], j1: ys[ry + 1] };
    if nx * ny == 1 && fixed == [false, false] {
        let r = mesh_region(hf, opts, storage, rect(0, 0), &[], None)?;
        return Ok((SampleMesh { vertices: r.vertices, triangles: r.triangles }, r.max_error_m, 1));
    }
    // A region's seams: left, right (vertical), bottom, top (horizontal), where it has a neighbour.
    let seams_of = |rx: usize, ry: usize| -> Vec<Seam> {
        let r = rect(rx, ry);
        let mut s = Vec::new();
        if rx > 0 {
            s.push(Seam { vertical: true, at: r.i0, from: r.j0, to: r.j1 });
        }
        if rx + 1 < nx {
            s.push(Seam { vertical: true, at: r.i1, from: r.j0, to: r.j1 });
        }
        if ry > 0 || fixed[0] {
            s.push(Seam { vertical: false, at: r.j0, from: r.i0, to: r.i1 });
        }
        if ry + 1 < ny || fixed[1] {
            s.push(Seam { vertical: false, at: r.j1, from: r.i0, to: r.i1 });
        }
        s
    };
    let is_fixed = |s: &Seam| !s.vertical && ((fixed[0] && s.at == ys[0]) || (fixed[1] && s.at == ys[ny]));
    let regions: Vec<(usize, usize)> = (0..ny).flat_map(|ry| (0..nx).map(move |rx| (rx, ry))).collect();
    let all_seams: Vec<Seam> = {
        let mut v: Vec<Seam> = regions.iter().flat_map(|&(rx, ry)| seams_of(rx, ry)).collect();
        v.sort_unstable_by_key(|s| (s.vertical, s.at, s.from));
        v.dedup();
        v
    };
    let mut seam_samples: HashMap<Seam, Vec<u32>> = all_seams
        .par_iter()
        .map(|&s| (s, if simplify_seams { simplify_seam(hf, storage, s, opts.max_error_m) } else { Vec::new() }))
        .collect::<Vec<_>>()
        .into_iter()
        .collect();

    let mut meshes: Vec<Option<RegionMesh>> = (0..regions.len()).map(|_| None).collect();
    let mut dirty: Vec<bool> = vec![true; regions.len()];
    let mut rounds = 0;
    let (inner_x, inner_y) = (&xs[1..nx], &ys[1..ny]);
    loop {
        let todo: Vec<usize> = (0..regions.len()).filter(|&k| dirty[k]).collect();
        if todo.is_empty() {
            break;
        }
        rounds += 1;
        // the vertices the joined mesh will hold for sure: every region corner and seam sample once,
        // and what the regions not meshed again inserted off the cut lines
        let certain = (nx + 1) * (ny + 1)
            + seam_samples.values().map(Vec::len).sum::<usize>()
            + (0..regions.len())
                .filter(|&k| !dirty[k])
                .filter_map(|k| meshes[k].as_ref())
                .map(|m| m.inserted_inside)
                .sum::<usize>();
        let count = AtomicUsize::new(certain);
        let shared = SharedBudget { count: &count, limit: opts.max_vertices, cuts: (inner_x, inner_y) };
        let built: Vec<(usize, Result<RegionMesh, TerrainError>)> = todo
            .par_iter()
            .map(|&k| {
                let (rx, ry) = regions[k];
                let border: Vec<[u32; 2]> =
                    seams_of(rx, ry).iter().flat_map(|s| seam_samples[s].iter().map(move |&t| s.sample(t))).collect();
                (k, mesh_region(hf, opts, storage, rect(rx, ry), &border, Some(&shared)))
            })
            .collect();
        dirty.fill(false);
        for (k, r) in built {
            meshes[k] = Some(r?);
        }
        // A sample a region inserted on one of its seams joins the seam; both sides mesh again.
        for &k in &todo {
            let (rx, ry) = regions[k];
            let Some(mesh) = &meshes[k] else { continue };
            for s in seams_of(rx, ry) {
                let on_seam = mesh.vertices.iter().filter_map(|v| {
                    let (along, across) = if s.vertical { (v[1], v[0]) } else { (v[0], v[1]) };
                    (across == s.at && along > s.from && along < s.to).then_some(along)
                });
                let added: Vec<u32> = on_seam.filter(|t| seam_samples[&s].binary_search(t).is_err()).collect();
                if added.is_empty() {
                    continue;
                }
                if is_fixed(&s) {
                    let [i, j] = s.sample(added[0]);
                    return Err(TerrainError::Internal { i: i as usize, j: j as usize });
                }
                let list = seam_samples.get_mut(&s).expect("every seam has its samples");
                list.extend(added);
                list.sort_unstable();
                list.dedup();
                for (m, &(qx, qy)) in regions.iter().enumerate() {
                    if seams_of(qx, qy).contains(&s) {
                        dirty[m] = true;
                    }
                }
            }
        }
    }
    let (mesh, max_error_m) = join(meshes.into_iter().flatten().collect(), &xs, &ys);
    Ok((mesh, max_error_m, rounds))
}

/// Joins region meshes into one: vertices in region order, each seam vertex once (where it first
/// appears), triangles in region order.
fn join(meshes: Vec<RegionMesh>, xs: &[u32], ys: &[u32]) -> (SampleMesh, f64) {
    let inner_x = &xs[1..xs.len() - 1];
    let inner_y = &ys[1..ys.len() - 1];
    let on_seam = |v: [u32; 2]| inner_x.binary_search(&v[0]).is_ok() || inner_y.binary_search(&v[1]).is_ok();
    let mut shared: HashMap<[u32; 2], u32> = HashMap::new();
    let mut out = SampleMesh { vertices: Vec::new(), triangles: Vec::new() };
    let mut max_error_m = 0.0f64;
    for m in meshes {
        max_error_m = max_error_m.max(m.max_error_m);
        let ids: Vec<u32> = m
            .vertices
            .iter()
            .map(|&v| {
                let fresh = out.vertices.len() as u32;
                let id = if on_seam(v) { *shared.entry(v).or_insert(fresh) } else { fresh };
                if id == fresh {
                    out.vertices.push(v);
                }
                id
            })
            .collect();
        out.triangles.extend(m.triangles.iter().map(|t| t.map(|k| ids[k as usize])));
    }
    (out, max_error_m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::error::measure;
    use crate::terrain::tin::tests::check_mesh;
    use crate::terrain::tin::tin;

    #[test]
    fn maps_are_cut_into_regions_of_about_320_cells_by_their_size_alone() {
        assert_eq!(cuts(2), vec![0, 1]);
        assert_eq!(cuts(321), vec![0, 320]);
        assert_eq!(cuts(480), vec![0, 479], "under 1.5 regions' cells: one region");
        assert_eq!(cuts(512), vec![0, 255, 511]);
        assert_eq!(cuts(1025), vec![0, 341, 682, 1024]);
        assert_eq!(cuts(2049), vec![0, 341, 682, 1024, 1365, 1706, 2048]);
        // a chunked map: every chunk line, each chunk cut as a map of its size
        assert_eq!(cuts_between(0, 1024, 0), cuts(1025));
        assert_eq!(cuts_between(0, 1024, 512), vec![0, 256, 512, 768, 1024]);
        assert_eq!(cuts_between(0, 300, 128), vec![0, 128, 256, 300], "the last chunk is shorter");
        assert_eq!(cuts_between(0, 1024, 256), vec![0, 256, 512, 768, 1024]);
        assert_eq!(cuts_between(384, 768, 128), vec![384, 512, 640, 768], "a band's rows");
        assert_eq!(cuts_between(0, 129, 128), vec![0, 128, 129], "a chunk one cell wide");
    }

    /// With chunks, every chunk line is a seam at every bound: each chunk's triangles (the
    /// triangles whose centroid lies in its square) lie in its square and fill it, so neighbours
    /// shown at different levels meet along one straight line (a crack the skirts hide, never a
    /// hole seen from above). Chunks of every width, the last ones shorter; a map whose positions
    /// f32 cannot hold exactly (meshed as one band) as well.
    #[test]
    fn a_chunked_maps_chunks_fill_their_squares_exactly_at_every_bound() {
        use crate::terrain::chunks::ChunkGrid;
        let rough = crate::synth::fractal(301, 700, 1.0, 200.0, 0.6, 3);
        let inexact = crate::synth::fractal(260, 230, 0.3, 40.0, 0.6, 5);
        assert!(!Storage::f32(&inexact).xz_exact());
        for (hf, pitch) in [(&rough, 128u32), (&rough, 192), (&rough, 64), (&rough, 512), (&inexact, 100)] {
            for bound in [0.2, 1.5, 12.0] {
                let opts = TinOptions {
                    max_error_m: bound,
                    chunk_cells: pitch,
                    max_vertices: usize::MAX,
                    ..Default::default()
                };
                let r = tin(hf, &opts).unwrap();
                check_mesh(hf, &r.mesh);
                let grid = ChunkGrid::new(hf.width, hf.height, pitch as usize);
                let parts = grid.partition(&r.mesh.vertices, &r.mesh.triangles);
                for (k, triangles) in parts.iter().enumerate() {
                    let (lo, hi) = grid.sample_rect(k % grid.nx, k / grid.nx);
                    let mut twice_area = 0i64;
                    for &t in triangles {
                        let c = r.mesh.triangles[t].map(|v| r.mesh.vertices[v as usize].map(|x| x as i64));
                        for p in c {
                            let inside = (0..2).all(|a| lo[a] as i64 <= p[a] && p[a] <= hi[a] as i64);
                            assert!(
                                inside,
                                "pitch {pitch} at {bound}: chunk {k}'s corner {p:?} outside {lo:?}..{hi:?}"
                            );
                        }
                        let cross =
                            (c[1][0] - c[0][0]) * (c[2][1] - c[0][1]) - (c[1][1] - c[0][1]) * (c[2][0] - c[0][0]);
                        twice_area += cross.abs();
                    }
                    let square = 2 * ((hi[0] - lo[0]) * (hi[1] - lo[1])) as i64;
                    assert_eq!(twice_area, square, "pitch {pitch} at {bound}: chunk {k} does not fill its square");
                }
            }
        }
    }

    #[test]
    fn a_seam_keeps_every_sample_on_it_within_the_bound() {
        let hf = crate::synth::fractal(300, 3, 1.0, 200.0, 0.6, 9);
        let storage = Storage::f32(&hf);
        let seam = Seam { vertical: false, at: 1, from: 0, to: 299 };
        for bound in [0.0, 0.5, 3.0, 50.0] {
            let kept = simplify_seam(&hf, &storage, seam, bound);
            let mut ends = vec![0];
            ends.extend(&kept);
            ends.push(299);
            for pair in ends.windows(2) {
                let (a, b) = (pair[0], pair[1]);
                let (ha, hb) = (hf.at(a as usize, 1) as f64, hf.at(b as usize, 1) as f64);
                for t in a + 1..b {
                    let lerp = ha + (hb - ha) * (t - a) as f64 / (b - a) as f64;
                    assert!((lerp - hf.at(t as usize, 1) as f64).abs() <= bound + 1e-6, "sample {t} at bound {bound}");
                }
            }
            if bound == 0.0 {
                assert_eq!(kept.len(), 298, "a rough line at bound 0 keeps every sample");
            }
        }
    }

    #[test]
    fn regions_join_without_a_crack_within_the_bound_and_the_same_at_any_thread_count() {
        // 2 × 1, 3 × 3 and 2 × 2 regions
        for (w, h, bound) in [(1100, 700, 2.0), (1300, 1400, 0.5), (1025, 1025, 8.0)] {
            let hf = crate::synth::fractal(w, h, 1.0, 300.0, 0.55, 77);
            let opts = TinOptions { max_error_m: bound, ..TinOptions::default() };
            let one =
                rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| tin(&hf, &opts)).unwrap();
            let two =
                rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap().install(|| tin(&hf, &opts)).unwrap();
            assert_eq!(one, two, "{w}×{h}: the mesh depends on the thread count");
            assert!(layout(&hf, 0).0.len() > 2, "{w}×{h} is cut into regions");
            check_mesh(&hf, &one.mesh);
            let stats = measure(&hf, &one.mesh);
            assert_eq!(stats.max_error_m, one.max_error_m, "{w}×{h}: the reported error is the analyzer's");
            assert!(one.max_error_m <= bound, "{w}×{h}: {} over {bound}", one.max_error_m);
        }
    }

    #[test]
    fn regions_going_over_the_vertex_budget_together_stop_with_the_same_error_at_any_thread_count() {
        // 1300² samples (16 regions, each far below the budget alone): a budget of half the mesh's
        // vertices stops the regions together, with the same error at 1 and 2 threads; a budget the
        // mesh fits exactly changes nothing
        let hf = crate::synth::fractal(1300, 1300, 1.0, 300.0, 0.6, 21);
        let full = tin(&hf, &TinOptions { max_error_m: 2.0, ..TinOptions::default() }).unwrap();
        let needed = full.mesh.vertices.len();
        let over = TinOptions { max_error_m: 2.0, max_vertices: needed / 2, ..TinOptions::default() };
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            match pool.install(|| tin(&hf, &over)) {
                Err(TerrainError::OverBudget { over: crate::terrain::budget::OverBudget::Exceeded, limit, .. }) => {
                    assert_eq!(limit, needed / 2)
                }
                other => panic!("{threads} threads: expected the budget to stop the regions, got {other:?}"),
            }
        }
        let exact = TinOptions { max_error_m: 2.0, max_vertices: needed, ..TinOptions::default() };
        assert_eq!(tin(&hf, &exact).unwrap(), full, "a budget the mesh fits exactly changes nothing");
    }

    #[test]
    fn seams_a_region_inserts_samples_on_are_shared_and_both_sides_meshed_again() {
        // Without the 1-D pass every seam starts empty: the regions insert seam samples of their
        // own, different on each side; the rounds share them until both sides agree.
        let hf = crate::synth::fractal(1100, 600, 1.0, 200.0, 0.6, 5);
        let opts = TinOptions { max_error_m: 1.0, ..TinOptions::default() };
        let storage = Storage::f32(&hf);
        let (mesh, max_error_m, rounds) = mesh_by_regions_with(&hf, &opts, &storage, false).unwrap();
        assert!(rounds >= 2, "the seams needed no second round ({rounds})");
        check_mesh(&hf, &mesh);
        assert_eq!(measure(&hf, &mesh).max_error_m, max_error_m);
        assert!(max_error_m <= 1.0);
        // with the 1-D pass one round is the rule
        let (_, _, rounds) = mesh_by_regions_with(&hf, &opts, &storage, true).unwrap();
        assert_eq!(rounds, 1);
    }

    /// Every band of `hf` meshed from a window of its rows alone, shifted into the map and joined.
    fn from_windows(hf: &Heightfield, opts: &TinOptions) -> (SampleMesh, f64) {
        let band_cells = band_cells_for_chunk(Some(opts.chunk_cells as usize));
        let lines = band_lines(hf.height, band_cells, Storage::f32(hf).xz_exact());
        let last = lines[lines.len() - 1];
        let bands = lines
            .windows(2)
            .map(|w| {
                let window = hf.rows(w[0] as usize, w[1] as usize).unwrap();
                let rows = [0, w[1] - w[0]];
                let (mut mesh, error) =
                    mesh_band(&window, opts, &Storage::f32(&window), rows, [w[0] > 0, w[1] < last]).unwrap();
                for v in &mut mesh.vertices {
                    v[1] += w[0];
                }
                (mesh, error)
            })
            .collect();
        join_bands(bands, &lines)
    }

    #[test]
    fn chunked_maps_are_cut_into_bands_of_whole_chunks_reaching_320_rows() {
        assert_eq!(band_cells_for_chunk(None), 0);
        assert_eq!(band_cells_for_chunk(Some(512)), 512);
        assert_eq!(band_cells_for_chunk(Some(128)), 384);
        assert_eq!(band_cells_for_chunk(Some(64)), 320);
        assert_eq!(band_lines(8193, 512, true), (0..=16).map(|k| k * 512).collect::<Vec<_>>());
        assert_eq!(band_lines(1100, 384, true), vec![0, 384, 768, 1099], "the last band is shorter");
        assert_eq!(band_lines(385, 384, true), vec![0, 384], "a map of one band's rows is one band");
        assert_eq!(band_lines(1100, 0, true), vec![0, 1099]);
        // x and z not exactly i·cell, j·cell (0.3 m cells): the bands' edges could take a sample
        let inexact = Storage::f32(&crate::synth::fractal(1100, 4, 0.3, 1.0, 0.5, 1));
        assert!(!inexact.xz_exact());
        assert_eq!(band_lines(1100, 384, inexact.xz_exact()), vec![0, 1099], "inexact positions: one band");
    }

    #[test]
    fn a_band_meshed_from_its_own_rows_is_the_maps_band_and_the_bands_join_without_a_crack() {
        // bands of 384, 320 and 512 rows (chunks of 128, 64 and 512), rough and smooth maps, f32
        // heights and decimetre heights (Terrain-RGB-like, measured against their exact values as
        // stored)
        for (w, h, chunk, bound, relief) in
            [(700, 1300, 128u32, 0.5f64, 300.0), (900, 1100, 64, 2.0, 600.0), (500, 1025, 512, 0.0, 40.0)]
        {
            let band = band_cells_for_chunk(Some(chunk as usize));
            let rough = crate::synth::fractal(w, h, 1.0, relief, 0.6, 7 + w as u64);
            let tenths: Vec<f64> = rough.heights.iter().map(|&z| (z as f64 * 10.0).round() / 10.0 + 0.05).collect();
            // (a bound of 0 is finer than f32 holds decimetres: the tenths map is meshed within 0.1 m)
            for (hf, bound) in [(rough.clone(), bound), (Heightfield::from_f64(w, h, &tenths, 1.0), bound.max(0.1))] {
                let opts = TinOptions { max_error_m: bound, chunk_cells: chunk, ..TinOptions::default() };
                let whole = tin(&hf, &opts).unwrap();
                assert!(band_lines(h, band, Storage::f32(&hf).xz_exact()).len() > 2, "{w}×{h} is cut into bands");
                check_mesh(&hf, &whole.mesh);
                let stats = measure(&hf, &whole.mesh);
                assert!(stats.max_error_m <= bound, "{w}×{h} at {bound}: {} over the bound", stats.max_error_m);
                let (windows, error) = from_windows(&hf, &opts);
                assert_eq!(windows, whole.mesh, "{w}×{h}, bands of {band}: a band's rows alone mesh it otherwise");
                assert_eq!(error, whole.max_error_m);
                let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| tin(&hf, &opts));
                assert_eq!(one.unwrap(), whole, "{w}×{h}: the bands depend on the thread count");
            }
        }
    }
}
