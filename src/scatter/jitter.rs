//! Jittered grid placement (stratified sampling, Cook 1986 "Stochastic sampling in computer
//! graphics"): one candidate per cell of side 1/√max_density at a hashed offset, kept with
//! probability density(x, z), so the expected count is exactly ∫ density · max_density.
//! Positions are rounded to a 0.1 mm grid (far below the jitter's scale), heights and rotations to
//! theirs (see `on_table_grids`), which keeps the placement table's entries short.

use crate::random::mix64;

use super::common::{
    height_bounds, on_grid, on_table_grids, Instance, RuleCounts, ScatterError, MAX_CANDIDATES, POSITION_STEPS_PER_M,
};
use super::rules::Rules;
use super::storage::gather_in_order;

/// All instances of a jittered species, sorted by tile and then by cell (row-major).
pub fn scatter(rules: &Rules) -> Result<(Vec<Instance>, RuleCounts), ScatterError> {
    let s = rules.species;
    if s.max_density <= 0.0 {
        return Ok((Vec::new(), RuleCounts::default()));
    }
    let [x0, z0, x1, z1] = rules.tiling.extent;
    let cell = 1.0 / s.max_density.sqrt();
    // the grid is global (anchored at the extent's corner), so cells do not depend on the tiling;
    // a cell's candidate belongs to the tile that contains it
    let (ncx, ncz) = (((x1 - x0) / cell).ceil(), ((z1 - z0) / cell).ceil());
    if ncx * ncz > MAX_CANDIDATES || ncx >= u32::MAX as f64 || ncz >= u32::MAX as f64 {
        return Err(ScatterError::TooMuchWork {
            species: s.name.clone(),
            work: ncx * ncz,
            limit: MAX_CANDIDATES,
            remedy: "lower max_density".into(),
        });
    }
    let (ncx, ncz) = (ncx as i64, ncz as i64);
    let tiling = rules.tiling;
    let key = mix64(rules.key ^ 0x6a69_7474_6572); // "jitter"
    let bounds = height_bounds(s);
    // the density map's bound over blocks of BLOCK × BLOCK cells: a candidate whose keep_u is at or
    // above it is a density reject (counted without sampling the map or calling the rules), and
    // where the bound is 0 every candidate is (counted without hashing). The bound is the largest
    // pixel under the block's bilinear footprint (map values are 0..1, NaN-free), raised by 10⁻⁶
    // for the f32 rounding of the interpolation, so the kept instances and counts are exactly
    // those of sampling every candidate.
    const BLOCK: i64 = 32;
    // cells overlapping a tile; each candidate is kept by the one tile containing it
    let range = |a: f64, b: f64, o: f64, n: i64| {
        (((a - o) / cell).floor() as i64).clamp(0, n - 1)..=(((b - o) / cell).floor() as i64).clamp(0, n - 1)
    };
    let tile_cells = |t: usize| {
        let rect = tiling.rect(t as u32 % tiling.tiles_x, t as u32 / tiling.tiles_x);
        let (ri, rj) = (range(rect[0], rect[2], x0, ncx), range(rect[1], rect[3], z0, ncz));
        (*ri.start(), *ri.end(), *rj.start(), *rj.end())
    };
    // each tile's keep bound, and from it a bound of its instances (the result's capacity: virtual
    // until touched, so an over-estimate costs no memory)
    let tile_keep: Vec<f64> = (0..tiling.count() as u32)
        .map(|t| rules.max_keep_over(tiling.rect(t % tiling.tiles_x, t / tiling.tiles_x)))
        .collect();
    let tile_bound: Vec<usize> = (0..tiling.count())
        .map(|t| {
            if !rules.places_row(t as u32 / tiling.tiles_x) {
                return 0;
            }
            let (ci0, ci1, cj0, cj1) = tile_cells(t);
            (((ci1 - ci0 + 1) * (cj1 - cj0 + 1)) as f64 * tile_keep[t].clamp(0.0, 1.0)).ceil() as usize
        })
        .collect();
    // more than max_instances is an error after generating, so the reservation stops there
    let total_bound = tile_bound.iter().sum::<usize>().min(s.max_instances.saturating_add(1));
    let part_bound = tile_bound.iter().copied().max().unwrap_or(0);
    // tiles in parallel, each one's instances appended in tile order as it finishes
    let (instances, per_tile) =
        gather_in_order(tiling.count(), total_bound, part_bound, |t, out: &mut Vec<Instance>| {
            let mut counts = RuleCounts::default();
            // the triangle of the last candidate: the next one, a cell away, is most often in it
            let mut hint = u32::MAX;
            // (a tile outside the rows placed: another run's; every candidate is its own tile's)
            if tile_keep[t] <= 0.0 || !rules.places_row(t as u32 / tiling.tiles_x) {
                return counts;
            }
            let (ci0, ci1, cj0, cj1) = tile_cells(t);
            let t = t as u32;
            let (tx, tz) = (t % tiling.tiles_x, t / tiling.tiles_x);
            // interior cells (two cells clear of the tile's border, so far from any rounding) hold
            // candidates of this tile only: no tile test for them
            let (ii0, ii1, ij0, ij1) = (ci0 + 2, ci1 - 2, cj0 + 2, cj1 - 2);
            // no reallocation while pushing (a hint: a bound the system refuses leaves the buffer to grow)
            let _ = out.try_reserve(tile_bound[t as usize]);
            // row-major over the tile's cells (the output order), with the density bound of the
            // blocks of each band of BLOCK rows
            let mut bound = Vec::new();
            for bj in (cj0..=cj1).step_by(BLOCK as usize) {
                let bj1 = (bj + BLOCK - 1).min(cj1);
                bound.clear();
                bound.extend((ci0..=ci1).step_by(BLOCK as usize).map(|bi| {
                    let bi1 = (bi + BLOCK - 1).min(ci1);
                    let d = rules.max_density_over([
                        x0 + bi as f64 * cell,
                        z0 + bj as f64 * cell,
                        x0 + (bi1 + 1) as f64 * cell,
                        z0 + (bj1 + 1) as f64 * cell,
                    ]);
                    if d <= 0.0 {
                        0.0
                    } else {
                        d.min(1.0) * (1.0 + 1e-6) * rules.keep_scale
                    }
                }));
                for cj in bj..=bj1 {
                    let row_inside = cj >= ij0 && cj <= ij1;
                    for ci in ci0..=ci1 {
                        let h1 = mix64(key ^ (cj as u64 * ncx as u64 + ci as u64));
                        // on the 0.1 mm grid (POSITION_STEPS_PER_M): short table entries
                        let position = || {
                            let x = on_grid(
                                x0 + (ci as f64 + (h1 >> 32) as f64 * (1.0 / 4_294_967_296.0)) * cell,
                                POSITION_STEPS_PER_M,
                            );
                            let z = on_grid(
                                z0 + (cj as f64 + (h1 & 0xFFFF_FFFF) as f64 * (1.0 / 4_294_967_296.0)) * cell,
                                POSITION_STEPS_PER_M,
                            );
                            (x, z)
                        };
                        // a border cell's candidate may belong to the next tile: its position first; an
                        // interior one's only once it passed the density bound (half are rejected before)
                        let mut at = None;
                        if !(row_inside && ci >= ii0 && ci <= ii1) {
                            let (x, z) = position();
                            if x > x1 || z > z1 || tiling.tile_xz(x, z) != (tx, tz) {
                                continue;
                            }
                            at = Some((x, z));
                        }
                        let keep_bound = bound[((ci - ci0) / BLOCK) as usize];
                        if keep_bound <= 0.0 {
                            counts.candidates += 1;
                            counts.density += 1;
                            continue;
                        }
                        let h2 = mix64(h1);
                        let keep_u = super::common::unit(h2);
                        if keep_u >= keep_bound {
                            counts.candidates += 1;
                            counts.density += 1;
                            continue;
                        }
                        let (x, z) = at.unwrap_or_else(position);
                        if let Some(inst) = rules.place(x, z, keep_u, h2 ^ key, t, &mut counts, &mut hint) {
                            out.push(on_table_grids(inst, bounds));
                        }
                    }
                }
            }
            counts
        });
    let mut counts = RuleCounts::default();
    for c in &per_tile {
        counts.add(c);
    }
    Ok((instances, counts))
}
