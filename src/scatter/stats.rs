//! The scatter analyzer, paired with the generator: count vs expected (the integral of density,
//! mask and terrain rules), density fidelity per region, the exact minimum pair distance over all
//! instances (uniform grid, widened until the answer is provably exact), the largest distance from
//! the mesh surface, and per-tile counts and bounds.
//!
//! The surface distance does not reuse the generator's point location ([`SurfaceIndex::height_at`]):
//! [`height_check`] runs the other way round, triangle by triangle over a grid of the instances'
//! positions, with its own inside test and its own interpolation (edge-vector coordinates in f64),
//! so a wrong triangle picked by the placement shows up as a height error.

use std::collections::BTreeMap;
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use crate::scatter::species::SpeciesRules;

use super::common::{Instance, ScatterError, Tiling};
use super::density::DensityMap;
use super::rules::expected_count;
use super::surface::SurfaceIndex;

/// Regions per side of the fidelity grid.
pub const REGIONS: usize = 8;
/// Midpoint samples per side of each region for its expected count.
const REGION_SAMPLES: usize = 48;

#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct RegionStat {
    /// [min_x, min_z, max_x, max_z]
    pub region: [f64; 4],
    pub expected: f64,
    pub measured: usize,
    /// measured / expected; `None` where nothing is expected.
    pub ratio: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct TileStat {
    pub tile: u32,
    pub count: usize,
    pub aabb_min: [f64; 3],
    pub aabb_max: [f64; 3],
}

#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct SpeciesStats {
    pub species: String,
    pub count: usize,
    /// ∫ density · mask · terrain rules · effective max density (exclusions not counted).
    pub expected: f64,
    pub count_ratio: Option<f64>,
    /// An 8×8 grid over the extent, row-major from (min_x, min_z).
    pub regions: Vec<RegionStat>,
    /// Exact smallest distance in x/z between two instances; `None` below two instances.
    pub min_pair_distance_m: Option<f64>,
    /// The species' `min_spacing` (what `min_pair_distance_m` is to be compared with, for Poisson).
    pub min_spacing_m: f64,
    /// Largest |y − mesh height at (x, z)| over the checked instances, with x, y, z as scene.glb
    /// stores them (f32), so it includes the f32 rounding of the position.
    pub max_height_error_m: f64,
    /// The same for the f64 values of the placement CSV.
    pub max_height_error_csv_m: f64,
    /// Instances whose height was checked: all of them up to [`MAX_HEIGHT_CHECKS`], else every
    /// k-th (k = ⌈count / MAX_HEIGHT_CHECKS⌉, starting with the first).
    pub height_checked: usize,
    /// Checked instances that no mesh triangle contains (should be 0).
    pub off_surface: usize,
    pub per_tile: Vec<TileStat>,
    /// Generation time (passed in) and the analyzer's own time.
    pub seconds: f64,
    pub analyze_seconds: f64,
}

/// Measures one species' instances; `snow` is the thinning they were placed with (the expected
/// counts leave out what it drops), `seconds` the generation time to report with them.
#[allow(clippy::too_many_arguments)]
pub fn analyze(
    surface: &SurfaceIndex,
    extent: [f64; 4],
    species: &SpeciesRules,
    density: Option<&DensityMap>,
    mask: Option<&DensityMap>,
    snow: Option<super::rules::SnowThinning<'_>>,
    instances: &[Instance],
    tile_m: f64,
    seconds: f64,
) -> Result<SpeciesStats, ScatterError> {
    let start = Instant::now();
    let tiling = Tiling::new(extent, tile_m)?;
    let [x0, z0, x1, z1] = extent;
    let (rw, rh) = ((x1 - x0) / REGIONS as f64, (z1 - z0) / REGIONS as f64);
    // fill region counts
    let mut measured = vec![0usize; REGIONS * REGIONS];
    for inst in instances {
        let i = (((inst.position[0] - x0) / rw).floor().max(0.0) as usize).min(REGIONS - 1);
        let j = (((inst.position[2] - z0) / rh).floor().max(0.0) as usize).min(REGIONS - 1);
        measured[j * REGIONS + i] += 1;
    }
    let mut regions = Vec::with_capacity(REGIONS * REGIONS);
    for (k, &m) in measured.iter().enumerate() {
        let (i, j) = ((k % REGIONS) as f64, (k / REGIONS) as f64);
        let region = [x0 + i * rw, z0 + j * rh, x0 + (i + 1.0) * rw, z0 + (j + 1.0) * rh];
        let expected = expected_count(surface, extent, species, density, mask, snow, region, REGION_SAMPLES)?;
        regions.push(RegionStat { region, expected, measured: m, ratio: ratio(m, expected) });
    }
    let expected: f64 = regions.iter().map(|r| r.expected).sum();
    let heights = height_check(surface, instances, MAX_HEIGHT_CHECKS);
    let mut tiles: BTreeMap<u32, TileStat> = BTreeMap::new();
    for inst in instances {
        let t = tiles.entry(inst.tile).or_insert(TileStat {
            tile: inst.tile,
            count: 0,
            aabb_min: inst.position,
            aabb_max: inst.position,
        });
        t.count += 1;
        for k in 0..3 {
            t.aabb_min[k] = t.aabb_min[k].min(inst.position[k]);
            t.aabb_max[k] = t.aabb_max[k].max(inst.position[k]);
        }
    }
    let _ = tiling; // the tiling is validated so tile ids here and in the generator agree
    Ok(SpeciesStats {
        species: species.name.clone(),
        count: instances.len(),
        expected,
        count_ratio: ratio(instances.len(), expected),
        regions,
        min_pair_distance_m: min_pair_distance(instances.iter().map(|i| [i.position[0], i.position[2]]).collect()),
        min_spacing_m: species.min_spacing_m,
        max_height_error_m: heights.max_error_f32_m,
        max_height_error_csv_m: heights.max_error_f64_m,
        height_checked: heights.checked,
        off_surface: heights.unlocated,
        per_tile: tiles.into_values().collect(),
        seconds,
        analyze_seconds: start.elapsed().as_secs_f64(),
    })
}

/// Most instances [`analyze`] checks against the mesh (it runs on every build): 2^19 covers every
/// instance of the bundled presets (alpine grass: 393 k); on the 8.8 M-instance benchmark the
/// check then takes about 0.15 s of the analyzer's time.
pub const MAX_HEIGHT_CHECKS: usize = 1 << 19;

/// What [`height_check`] measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeightCheck {
    /// Instances checked.
    pub checked: usize,
    /// Checked instances that no triangle contains (at their f64 or their f32 position).
    pub unlocated: usize,
    /// Largest |y − mesh height| with the f64 position (the CSV's values).
    pub max_error_f64_m: f64,
    /// Largest |y − mesh height| with the position rounded to f32 (scene.glb's values).
    pub max_error_f32_m: f64,
}

/// A point this far outside a triangle, in barycentric units, still counts as inside: shared edges
/// then belong to both triangles (their heights agree there up to rounding).
const INSIDE_TOLERANCE: f64 = 1e-9;

/// Distance of the instances from the mesh surface, located independently of the placement's
/// [`SurfaceIndex::height_at`]: the checked positions (every k-th instance, at most `max_checks`,
/// each once in f64 and once rounded to f32) are bucketed in a uniform grid, then every triangle
/// visits the buckets under its bounding box and measures the positions inside it. Where a
/// position lies on an edge shared by two triangles, the smaller error counts.
pub fn height_check(surface: &SurfaceIndex, instances: &[Instance], max_checks: usize) -> HeightCheck {
    let none = HeightCheck { checked: 0, unlocated: 0, max_error_f64_m: 0.0, max_error_f32_m: 0.0 };
    if instances.is_empty() || max_checks == 0 {
        return none;
    }
    let stride = instances.len().div_ceil(max_checks);
    // queries 2k and 2k + 1: instance k·stride at its f64 and at its f32 position, as (x, z, y)
    let mut queries: Vec<[f64; 3]> = Vec::with_capacity(2 * instances.len().div_ceil(stride));
    for inst in instances.iter().step_by(stride) {
        let p = inst.position;
        queries.push(p);
        queries.push(p.map(|v| v as f32 as f64));
    }
    let checked = queries.len() / 2;
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for q in &queries {
        for (k, v) in [q[0], q[2]].into_iter().enumerate() {
            lo[k] = lo[k].min(v);
            hi[k] = hi[k].max(v);
        }
    }
    if !(lo.iter().chain(&hi).all(|v| v.is_finite())) {
        return HeightCheck { checked, unlocated: checked, ..none };
    }
    // about two queries per bucket
    let (w, h) = ((hi[0] - lo[0]).max(1e-9), (hi[1] - lo[1]).max(1e-9));
    let cell = (2.0 * w * h / queries.len() as f64).sqrt().max(w.max(h) / 4096.0);
    let dims = [(w / cell) as usize + 1, (h / cell) as usize + 1];
    let bucket = |x: f64, z: f64| {
        let i = (((x - lo[0]) / cell).max(0.0) as usize).min(dims[0] - 1);
        let j = (((z - lo[1]) / cell).max(0.0) as usize).min(dims[1] - 1);
        (i, j)
    };
    // fill bucket counts, offsets, then the query indices by bucket
    let mut start = vec![0u32; dims[0] * dims[1] + 1];
    for q in &queries {
        let (i, j) = bucket(q[0], q[2]);
        start[j * dims[0] + i + 1] += 1;
    }
    for k in 1..start.len() {
        start[k] += start[k - 1];
    }
    // the queries in bucket order (a triangle then reads them, and its results, in sequence),
    // with the index of each in `queries`
    let mut fill = start.clone();
    let mut order = vec![0u32; queries.len()];
    let mut sorted = vec![[0.0; 3]; queries.len()];
    for (n, q) in queries.iter().enumerate() {
        let (i, j) = bucket(q[0], q[2]);
        let b = j * dims[0] + i;
        order[fill[b] as usize] = n as u32;
        sorted[fill[b] as usize] = *q;
        fill[b] += 1;
    }
    // each thread takes a contiguous share of the triangles and keeps its own smallest error per
    // query; the shares are merged by minimum, so the answer does not depend on the split
    let triangles = surface.triangle_count();
    let shares = rayon::current_num_threads().clamp(1, triangles.max(1));
    let share = triangles.div_ceil(shares);
    let best = (0..shares)
        .into_par_iter()
        .map(|k| {
            let mut best = vec![f64::INFINITY; queries.len()];
            for [a, b, c] in (k * share..((k + 1) * share).min(triangles)).map(|t| surface.triangle(t)) {
                let (e1, e2) = ([b[0] - a[0], b[2] - a[2]], [c[0] - a[0], c[2] - a[2]]);
                let det = e1[0] * e2[1] - e1[1] * e2[0];
                if det == 0.0 || !det.is_finite() {
                    continue;
                }
                let (x0, x1) = (a[0].min(b[0]).min(c[0]), a[0].max(b[0]).max(c[0]));
                let (z0, z1) = (a[2].min(b[2]).min(c[2]), a[2].max(b[2]).max(c[2]));
                if x1 < lo[0] || z1 < lo[1] || x0 > hi[0] || z0 > hi[1] {
                    continue;
                }
                let ((i0, j0), (i1, j1)) = (bucket(x0, z0), bucket(x1, z1));
                let inv_det = 1.0 / det;
                for j in j0..=j1 {
                    let slots = start[j * dims[0] + i0] as usize..start[j * dims[0] + i1 + 1] as usize;
                    for (q, slot) in sorted[slots.clone()].iter().zip(&mut best[slots]) {
                        // p − a = s·e1 + t·e2 (Cramer's rule)
                        let (px, pz) = (q[0] - a[0], q[2] - a[2]);
                        let s = (px * e2[1] - pz * e2[0]) * inv_det;
                        let t = (e1[0] * pz - e1[1] * px) * inv_det;
                        if s < -INSIDE_TOLERANCE || t < -INSIDE_TOLERANCE || s + t > 1.0 + INSIDE_TOLERANCE {
                            continue;
                        }
                        let y = a[1] + s * (b[1] - a[1]) + t * (c[1] - a[1]);
                        *slot = slot.min((q[1] - y).abs());
                    }
                }
            }
            best
        })
        .reduce_with(|mut a, b| {
            a.iter_mut().zip(b).for_each(|(x, y)| *x = x.min(y));
            a
        })
        .unwrap_or_default();
    // back from bucket order: query 2k is instance k's f64 position, 2k + 1 its f32 one
    let mut result = HeightCheck { checked, ..none };
    let mut unlocated = vec![false; checked];
    for (&n, &e) in order.iter().zip(&best) {
        let n = n as usize;
        if !e.is_finite() {
            unlocated[n / 2] = true;
        } else if n.is_multiple_of(2) {
            result.max_error_f64_m = result.max_error_f64_m.max(e);
        } else {
            result.max_error_f32_m = result.max_error_f32_m.max(e);
        }
    }
    result.unlocated = unlocated.iter().filter(|&&u| u).count();
    result
}

fn ratio(measured: usize, expected: f64) -> Option<f64> {
    (expected > 0.0).then(|| measured as f64 / expected)
}

/// Exact smallest pairwise distance of 2-D points: bucket into a grid of cell c and compare each
/// point with the 3×3 cells around it; a result ≤ c is exact (a closer pair would share or touch
/// cells), otherwise retry with a wider cell.
pub fn min_pair_distance(points: Vec<[f64; 2]>) -> Option<f64> {
    if points.len() < 2 {
        return None;
    }
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &points {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let (w, h) = ((hi[0] - lo[0]).max(1e-12), (hi[1] - lo[1]).max(1e-12));
    if !(w.is_finite() && h.is_finite()) {
        return None;
    }
    let mut cell = (w * h / points.len() as f64).sqrt().max(w.max(h) / 65536.0);
    loop {
        let dims = [((w / cell).floor() as usize + 1), ((h / cell).floor() as usize + 1)];
        let cell_of = |p: &[f64; 2]| {
            let i = (((p[0] - lo[0]) / cell) as usize).min(dims[0] - 1);
            let j = (((p[1] - lo[1]) / cell) as usize).min(dims[1] - 1);
            (i, j)
        };
        // fill cell counts, offsets, then the points sorted by cell
        let mut start = vec![0usize; dims[0] * dims[1] + 1];
        for p in &points {
            let (i, j) = cell_of(p);
            start[j * dims[0] + i + 1] += 1;
        }
        for k in 1..start.len() {
            start[k] += start[k - 1];
        }
        let mut fill = start.clone();
        let mut sorted = vec![[0.0; 2]; points.len()];
        for p in &points {
            let (i, j) = cell_of(p);
            let c = j * dims[0] + i;
            sorted[fill[c]] = *p;
            fill[c] += 1;
        }
        let best2 = (0..dims[1])
            .into_par_iter()
            .map(|j| {
                let mut best = f64::INFINITY;
                for i in 0..dims[0] {
                    let c = j * dims[0] + i;
                    for a in start[c]..start[c + 1] {
                        let p = sorted[a];
                        // pairs within the cell (later points only) and with the forward half of the neighbours
                        for q in &sorted[a + 1..start[c + 1]] {
                            best = best.min((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2));
                        }
                        for (di, dj) in [(1i64, 0i64), (-1, 1), (0, 1), (1, 1)] {
                            let (ni, nj) = (i as i64 + di, j as i64 + dj);
                            if ni < 0 || nj < 0 || ni >= dims[0] as i64 || nj >= dims[1] as i64 {
                                continue;
                            }
                            let n = nj as usize * dims[0] + ni as usize;
                            for q in &sorted[start[n]..start[n + 1]] {
                                best = best.min((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2));
                            }
                        }
                    }
                }
                best
            })
            .reduce(|| f64::INFINITY, f64::min);
        let best = best2.sqrt();
        if best <= cell || (dims[0] == 1 && dims[1] == 1) {
            return Some(best);
        }
        cell = (cell * 4.0).max(best);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_pair_distance_is_exact() {
        // brute force on a few hashed point sets, including far-apart pairs
        for seed in 0..20u64 {
            let n = 2 + (seed as usize * 7) % 60;
            let pts: Vec<[f64; 2]> = (0..n as u64)
                .map(|k| {
                    let h = crate::random::mix64(seed * 1000 + k);
                    [(h >> 40) as f64 / 1e3 * (1 + seed % 3) as f64, (h & 0xFF_FFFF) as f64 / 1e5]
                })
                .collect();
            let mut brute = f64::INFINITY;
            for a in 0..n {
                for b in a + 1..n {
                    brute = brute.min(((pts[a][0] - pts[b][0]).powi(2) + (pts[a][1] - pts[b][1]).powi(2)).sqrt());
                }
            }
            assert_eq!(min_pair_distance(pts), Some(brute), "seed {seed}");
        }
        assert_eq!(min_pair_distance(vec![[0.0, 0.0]]), None);
        assert_eq!(min_pair_distance(vec![[0.0, 0.0], [3.0, 4.0]]), Some(5.0));
        assert_eq!(min_pair_distance(vec![[1.0, 1.0], [1.0, 1.0]]), Some(0.0));
    }
}
