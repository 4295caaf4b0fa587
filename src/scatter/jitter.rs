//! Jittered grid placement (stratified sampling, Cook 1986 "Stochastic sampling in computer
//! graphics"): one candidate per cell of side 1/√max_density at a hashed offset, kept with
//! probability density(x, z), so the expected count is exactly ∫ density · max_density.

use rayon::prelude::*;

use crate::synth::mix64;

use super::rules::Rules;
use super::{Instance, RuleCounts, ScatterError, MAX_CANDIDATES};

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
    let per_tile: Vec<(Vec<Instance>, RuleCounts)> = (0..tiling.count() as u32)
        .into_par_iter()
        .map(|t| {
            let (tx, tz) = (t % tiling.tiles_x, t / tiling.tiles_x);
            let rect = tiling.rect(tx, tz);
            let mut counts = RuleCounts::default();
            let mut out = Vec::new();
            if rules.max_keep_over(rect) <= 0.0 {
                return (out, counts);
            }
            // cells overlapping the tile; each candidate is kept by the one tile containing it
            let range = |a: f64, b: f64, o: f64, n: i64| (((a - o) / cell).floor() as i64).clamp(0, n - 1)..=(((b - o) / cell).floor() as i64).clamp(0, n - 1);
            for cj in range(rect[1], rect[3], z0, ncz) {
                for ci in range(rect[0], rect[2], x0, ncx) {
                    let h1 = mix64(key ^ (cj as u64 * ncx as u64 + ci as u64));
                    let x = x0 + (ci as f64 + (h1 >> 32) as f64 * (1.0 / 4_294_967_296.0)) * cell;
                    let z = z0 + (cj as f64 + (h1 & 0xFFFF_FFFF) as f64 * (1.0 / 4_294_967_296.0)) * cell;
                    if x > x1 || z > z1 || tiling.tile_xz(x, z) != (tx, tz) {
                        continue;
                    }
                    let h2 = mix64(h1);
                    if let Some(inst) = rules.place(x, z, super::unit(h2), h2 ^ key, t, &mut counts) {
                        out.push(inst);
                    }
                }
            }
            (out, counts)
        })
        .collect();
    let mut counts = RuleCounts::default();
    let total = per_tile.iter().map(|(v, _)| v.len()).sum();
    let mut instances = Vec::with_capacity(total);
    for (v, c) in per_tile {
        counts.add(&c);
        instances.extend_from_slice(&v);
    }
    Ok((instances, counts))
}
