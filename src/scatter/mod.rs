//! Scatter: density maps and terrain rules → instances sitting exactly on the exported terrain mesh.
//!
//! Plain data in, plain data out: a [`SurfaceIndex`] over the terrain's triangles, the resolved
//! [`SpeciesRules`], optional density/mask maps and the instances of species placed earlier go
//! in; a `Vec<Instance>` comes out, sorted by tile and then by generation order. Two placements:
//!
//! - [`Placement::Jittered`] (`jitter.rs`): one candidate per cell of a global grid of side
//!   1/√max_density, kept with probability density(x, z). Expected count = ∫ density · max_density.
//! - [`Placement::Poisson`] (`poisson.rs`): a maximal Poisson-disk set of radius `min_spacing`
//!   built tile by tile in four phases, then each point kept with probability
//!   density(x, z) · min(1, max_density / ρ_pack), where ρ_pack = [`POISSON_PACKING`] / r² is the
//!   density of the unthinned set. So for Poisson `max_density` is a cap: spacing sets the densest
//!   packing, and a lower `max_density` thins it further. Expected count =
//!   ∫ density · min(max_density, ρ_pack).
//!
//! Then the rules (`rules.rs`) drop candidates outside the mask, the slope/altitude ranges, below
//! water or within an exclusion radius of an earlier species. Every random number is a hash
//! (`random::mix64`) of the seed, species, tile/cell and a counter, so the output does not depend on
//! thread count or tile order. `stats.rs` is the paired analyzer.

pub mod common;
pub mod density;
pub mod jitter;
pub mod poisson;
pub mod rules;
pub mod species;
pub mod stats;
pub mod storage;
pub mod surface;

pub use common::{
    assign_variants, species_key, variant_of, Instance, RuleCounts, Scatter, ScatterError, Tiling, HEIGHT_STEPS_PER_M,
    MAX_CANDIDATES, MAX_TILES, POISSON_PACKING, POSITION_STEPS_PER_M, ROTATION_STEPS, SCALE_STEPS, YAW_STEPS_PER_DEG,
};
pub use density::DensityMap;
pub use rules::expected_count;
pub use species::{Exclusion, Placement, SpeciesRules, UNBOUNDED_ALTITUDE_M};
pub use stats::{analyze, RegionStat, SpeciesStats, TileStat};
pub use surface::SurfaceIndex;

/// Places one species; see the module docs. `earlier` holds the species placed before this one
/// (by name), for exclusions. Fails before generating when the estimate is above
/// `max_instances`, and after generating when the count is.
#[allow(clippy::too_many_arguments)]
pub fn scatter_species(
    surface: &SurfaceIndex,
    extent: [f64; 4],
    species: &SpeciesRules,
    density: Option<&DensityMap>,
    mask: Option<&DensityMap>,
    earlier: &[(&str, &[Instance])],
    tile_m: f64,
    scene_seed: u64,
) -> Result<Vec<Instance>, ScatterError> {
    scatter_species_detailed(surface, extent, species, density, mask, earlier, tile_m, scene_seed).map(|s| s.instances)
}

/// [`scatter_species`] with the rule counts and the estimate.
#[allow(clippy::too_many_arguments)]
pub fn scatter_species_detailed(
    surface: &SurfaceIndex,
    extent: [f64; 4],
    species: &SpeciesRules,
    density: Option<&DensityMap>,
    mask: Option<&DensityMap>,
    earlier: &[(&str, &[Instance])],
    tile_m: f64,
    scene_seed: u64,
) -> Result<Scatter, ScatterError> {
    scatter_species_snow(surface, extent, species, density, mask, earlier, tile_m, scene_seed, None)
}

/// [`scatter_species_detailed`] with snow thinning (`None`: none; see [`rules::SnowThinning`]).
#[allow(clippy::too_many_arguments)]
pub fn scatter_species_snow(
    surface: &SurfaceIndex,
    extent: [f64; 4],
    species: &SpeciesRules,
    density: Option<&DensityMap>,
    mask: Option<&DensityMap>,
    earlier: &[(&str, &[Instance])],
    tile_m: f64,
    scene_seed: u64,
    snow: Option<rules::SnowThinning<'_>>,
) -> Result<Scatter, ScatterError> {
    scatter_species_in_rows(surface, extent, species, density, mask, earlier, tile_m, scene_seed, snow, None)
}

/// [`scatter_species_snow`] for the tile rows `rows = [first, end)` alone (`None`: all of them):
/// the whole run's instances in those rows, in the whole run's order, and its rule counts of the
/// candidates there — so runs over rows that partition the tiling give, joined in row order, the
/// whole run's instances, and summed, its counts. Poisson blocks of the block rows beside those
/// placed are filled again by each run that needs them (the colour phases' reach; see
/// `poisson.rs`). Exclusions see only the `earlier` instances given: pass every earlier instance
/// within the exclusion radius of the rows (those of their rows widened by the radius). The
/// surface is read only at z within [`rows_reach`] of the rows, so it may hold the triangles there
/// alone. A run of rows fails fast on the whole estimate's part in its rows (never more than the
/// whole; `estimate` is NaN: the whole one would read the whole surface); the join makes the whole
/// one ([`estimate_species`]) and checks `max_instances` on the sum (a run checks its own count,
/// which is never more).
#[allow(clippy::too_many_arguments)]
pub fn scatter_species_in_rows(
    surface: &SurfaceIndex,
    extent: [f64; 4],
    species: &SpeciesRules,
    density: Option<&DensityMap>,
    mask: Option<&DensityMap>,
    earlier: &[(&str, &[Instance])],
    tile_m: f64,
    scene_seed: u64,
    snow: Option<rules::SnowThinning<'_>>,
    rows: Option<[u32; 2]>,
) -> Result<Scatter, ScatterError> {
    let tiling = Tiling::new(extent, tile_m)?;
    if let Some([first, end]) = rows {
        if first >= end || end > tiling.tiles_z {
            return Err(ScatterError::Rows { rows: [first, end], tiles_z: tiling.tiles_z });
        }
    }
    let mut ctx = rules::Rules::new(surface, tiling, species, density, mask, earlier, scene_seed)?;
    ctx.snow = snow;
    ctx.rows = rows;
    // fail fast: estimate from the density/mask/rules integral before allocating anything (a run
    // of rows: the whole estimate's part in its rows, never more than the whole)
    let estimate = match rows {
        None => checked_estimate(&ctx, species, extent)?,
        Some(rows) => {
            let area = (extent[2] - extent[0]) * (extent[3] - extent[1]);
            let part = rules::estimate_in_rows(&ctx, 128, rows) * ctx.effective_max_density * area;
            if part > species.max_instances as f64 * 1.02 + 8.0 {
                return Err(ScatterError::TooManyEstimated {
                    species: species.name.clone(),
                    estimate: part,
                    limit: species.max_instances,
                });
            }
            f64::NAN
        }
    };
    let (instances, counts) = match species.placement {
        Placement::Jittered => jitter::scatter(&ctx)?,
        Placement::Poisson => poisson::scatter(&ctx)?,
    };
    if instances.len() > species.max_instances {
        return Err(ScatterError::TooMany {
            species: species.name.clone(),
            count: instances.len(),
            limit: species.max_instances,
        });
    }
    Ok(Scatter { instances, counts, estimate })
}

/// The estimated count of a species over the whole extent (what [`scatter_species_snow`] fails
/// fast on: an error when it is over `max_instances`), for a join of runs over rows.
#[allow(clippy::too_many_arguments)]
pub fn estimate_species(
    surface: &SurfaceIndex,
    extent: [f64; 4],
    species: &SpeciesRules,
    density: Option<&DensityMap>,
    mask: Option<&DensityMap>,
    tile_m: f64,
    scene_seed: u64,
    snow: Option<rules::SnowThinning<'_>>,
) -> Result<f64, ScatterError> {
    let tiling = Tiling::new(extent, tile_m)?;
    let mut ctx = rules::Rules::without_exclusions(surface, tiling, species, density, mask, scene_seed)?;
    ctx.snow = snow;
    checked_estimate(&ctx, species, extent)
}

fn checked_estimate(ctx: &rules::Rules<'_>, species: &SpeciesRules, extent: [f64; 4]) -> Result<f64, ScatterError> {
    let area = (extent[2] - extent[0]) * (extent[3] - extent[1]);
    let estimate = rules::estimate(ctx, 128) * ctx.effective_max_density * area;
    if estimate > species.max_instances as f64 * 1.02 + 8.0 {
        return Err(ScatterError::TooManyEstimated {
            species: species.name.clone(),
            estimate,
            limit: species.max_instances,
        });
    }
    Ok(estimate)
}

/// The z range `[z0, z1]` of the surface a run over tile rows `rows = [first, end)` reads
/// ([`scatter_species_in_rows`]): the rows' span, a hair wider for points that round across a
/// tile border.
pub fn rows_reach(extent: [f64; 4], tile_m: f64, rows: [u32; 2]) -> Result<[f64; 2], ScatterError> {
    let tiling = Tiling::new(extent, tile_m)?;
    let [first, end] = rows;
    if first >= end || end > tiling.tiles_z {
        return Err(ScatterError::Rows { rows, tiles_z: tiling.tiles_z });
    }
    let lo = tiling.rect(0, first)[1];
    let hi = tiling.rect(0, end - 1)[3];
    let hair = 1e-9 * (extent[3] - extent[1] + extent[1].abs().max(extent[3].abs()));
    Ok([if first == 0 { extent[1] } else { lo - hair }, if end == tiling.tiles_z { extent[3] } else { hi + hair }])
}
