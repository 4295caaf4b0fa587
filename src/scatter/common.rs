//! What every placement method shares: instances and their table grids, tiles, rule counts,
//! the error type and the limits, the species key and the small exact maths of the hot loops.

use std::path::PathBuf;

use crate::random::mix64;
use crate::scatter::species::SpeciesRules;

/// Points per r² of the unthinned set this sampler produces away from the extent's edges (measured:
/// 0.616–0.617 on 300 r × 300 r with tiles of 10 r to 300 r, which includes ≈ +0.5 % from the
/// extent's edges, where points pack tighter; see `poisson`'s `packing_constant` test). Random sequential
/// adsorption saturates at ≈ 0.70/r² (jamming coverage 0.547); Bridson with k = 30 stops short of it.
pub const POISSON_PACKING: f64 = 0.613;

/// One placed instance. `rotation` is a unit quaternion (x, y, z, w): yaw about +Y, then a tilt
/// toward the terrain normal by `align_to_normal` of the slope angle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Instance {
    pub position: [f64; 3],
    pub rotation: [f32; 4],
    pub scale: [f32; 3],
    pub yaw_deg: f32,
    /// Placement tile: `tz * tiles_x + tx` over the extent, tiles of `tile_m` from (min_x, min_z).
    pub tile: u32,
    /// Which of the species' meshes it shows: [`variant_of`] its position (0 until
    /// [`assign_variants`] gives the species' count).
    pub variant: u32,
}

/// Which of `variants` meshes an instance at `position` shows: a hash of its x and z (f64 bits),
/// so neighbours differ and the choice is reproducible from the position alone. Written in the
/// placement table's `variant` column.
pub fn variant_of(position: [f64; 3], variants: usize) -> u32 {
    let h = mix64(position[0].to_bits() ^ mix64(position[2].to_bits()));
    (((h >> 32) * variants.max(1) as u64) >> 32) as u32
}

/// Sets every instance's [`Instance::variant`] for a species of `variants` meshes (in parallel:
/// each depends on its own position only).
pub fn assign_variants(instances: &mut [Instance], variants: usize) {
    use rayon::prelude::*;
    instances.par_iter_mut().for_each(|i| i.variant = variant_of(i.position, variants));
}

/// An instance is a row of its placement table (written without a copy).
impl crate::export::table::ToPlacementRow for Instance {
    #[inline]
    fn placement_row(&self) -> crate::export::table::PlacementRow {
        crate::export::table::PlacementRow {
            position: self.position,
            rotation: self.rotation,
            scale: self.scale,
            yaw_deg: self.yaw_deg,
            tile: self.tile,
            variant: self.variant,
        }
    }
}

/// Candidates examined and why they were dropped (for the report).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct RuleCounts {
    /// Candidates generated (jittered: cells inside the extent; Poisson: the unthinned set).
    pub candidates: u64,
    pub density: u64,
    pub mask: u64,
    /// No terrain triangle under the candidate (holes, outside the mesh).
    pub off_surface: u64,
    pub water: u64,
    pub altitude: u64,
    pub slope: u64,
    pub exclusion: u64,
    /// Grass and flowers dropped where snow lies (`[snow] thin_plants`; 0 without snow).
    #[serde(default)]
    pub snow: u64,
    pub placed: u64,
}

impl RuleCounts {
    pub fn add(&mut self, o: &RuleCounts) {
        self.candidates += o.candidates;
        self.density += o.density;
        self.mask += o.mask;
        self.off_surface += o.off_surface;
        self.water += o.water;
        self.altitude += o.altitude;
        self.slope += o.slope;
        self.exclusion += o.exclusion;
        self.snow += o.snow;
        self.placed += o.placed;
    }
}

/// The instances of one species and the rule counts.
#[derive(Debug, Clone, PartialEq)]
pub struct Scatter {
    pub instances: Vec<Instance>,
    pub counts: RuleCounts,
    /// Estimated count before generation (∫ density · effective max density over the extent,
    /// with mask and terrain rules sampled on a grid; exclusions not counted).
    pub estimate: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum ScatterError {
    #[error("{}: {reason}", path.display())]
    Map { path: PathBuf, reason: String },
    #[error("species `{species}`: {reason}")]
    Settings { species: String, reason: String },
    #[error("species `{species}`: about {estimate:.0} instances expected, above max_instances = {limit}; lower max_density (or the density map), raise min_spacing, or raise max_instances")]
    TooManyEstimated { species: String, estimate: f64, limit: usize },
    #[error("species `{species}`: {count} instances placed, above max_instances = {limit}; lower max_density (or the density map), raise min_spacing, or raise max_instances")]
    TooMany { species: String, count: usize, limit: usize },
    #[error("species `{species}`: {work} candidate points to examine (limit {limit}); {remedy}")]
    TooMuchWork { species: String, work: f64, limit: f64, remedy: String },
    #[error("species `{species}`: exclusion names `{other}`, which is not placed before it; list `{other}` earlier in the preset")]
    UnknownExclusion { species: String, other: String },
    #[error("scatter extent {extent:?} is empty or not finite; pass [min_x, min_z, max_x, max_z] with max > min")]
    Extent { extent: [f64; 4] },
    #[error("tile size {tile_m} m gives {tiles} tiles over the extent (limit {limit}); use a larger [scatter] tile_m")]
    Tiles { tile_m: f64, tiles: u64, limit: u64 },
    #[error("tile rows {}..{} are not rows of the tiling (0..{tiles_z}); place a non-empty range of its rows", rows[0], rows[1])]
    Rows { rows: [u32; 2], tiles_z: u32 },
}

/// Always the input's: a map that does not read, settings or limits the species exceeds.
impl crate::failure::Failure for ScatterError {
    fn blame(&self) -> crate::failure::Blame {
        crate::failure::Blame::Input
    }
}

/// Most tiles accepted over an extent.
pub const MAX_TILES: u64 = 1 << 22;
/// Most candidates a species may examine (jittered cells, Poisson points): bounds time and memory
/// even where the density map is mostly 0.
pub const MAX_CANDIDATES: f64 = 1.0e9;

/// Tiles of `tile_m` metres over the extent, starting at (min_x, min_z); the last row/column may
/// be partial. Points on the far border belong to the last tile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tiling {
    pub extent: [f64; 4],
    pub tile_m: f64,
    pub tiles_x: u32,
    pub tiles_z: u32,
}

impl Tiling {
    pub fn new(extent: [f64; 4], tile_m: f64) -> Result<Tiling, ScatterError> {
        let [x0, z0, x1, z1] = extent;
        if !(extent.iter().all(|v| v.is_finite()) && x1 > x0 && z1 > z0) {
            return Err(ScatterError::Extent { extent });
        }
        let nx = if tile_m > 0.0 && tile_m.is_finite() { ((x1 - x0) / tile_m).ceil().max(1.0) } else { f64::INFINITY };
        let nz = if tile_m > 0.0 && tile_m.is_finite() { ((z1 - z0) / tile_m).ceil().max(1.0) } else { f64::INFINITY };
        let tiles = nx * nz;
        if tiles.is_nan() || tiles > MAX_TILES as f64 {
            return Err(ScatterError::Tiles {
                tile_m,
                tiles: if tiles.is_finite() { tiles as u64 } else { u64::MAX },
                limit: MAX_TILES,
            });
        }
        Ok(Tiling { extent, tile_m, tiles_x: nx as u32, tiles_z: nz as u32 })
    }

    pub fn count(&self) -> usize {
        self.tiles_x as usize * self.tiles_z as usize
    }

    /// Tile column and row of a point (clamped, so the far border joins the last tile).
    #[inline]
    pub fn tile_xz(&self, x: f64, z: f64) -> (u32, u32) {
        // truncation is the floor here: negative values clamp to tile 0 either way
        let tx = ((x - self.extent[0]) / self.tile_m).clamp(0.0, (self.tiles_x - 1) as f64) as u32;
        let tz = ((z - self.extent[1]) / self.tile_m).clamp(0.0, (self.tiles_z - 1) as f64) as u32;
        (tx, tz)
    }

    #[inline]
    pub fn tile_of(&self, x: f64, z: f64) -> u32 {
        let (tx, tz) = self.tile_xz(x, z);
        tz * self.tiles_x + tx
    }

    /// [min_x, min_z, max_x, max_z] of tile (tx, tz), cut to the extent.
    pub fn rect(&self, tx: u32, tz: u32) -> [f64; 4] {
        let [x0, z0, x1, z1] = self.extent;
        [
            x0 + tx as f64 * self.tile_m,
            z0 + tz as f64 * self.tile_m,
            (x0 + (tx + 1) as f64 * self.tile_m).min(x1),
            (z0 + (tz + 1) as f64 * self.tile_m).min(z1),
        ]
    }
}

/// The key every random number of a species derives from: scene seed + species seed offset, mixed
/// with the species name (two species with equal settings still differ).
pub fn species_key(scene_seed: u64, species: &SpeciesRules) -> u64 {
    // FNV-1a of the name: stable across platforms and Rust versions (unlike std's hasher)
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in species.name.bytes() {
        h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
    }
    mix64(mix64(scene_seed.wrapping_add(species.seed)) ^ h)
}

/// ⌊v⌋ as an integer without a libm call (baseline x86-64 has no `roundsd`, so `f64::floor` is a
/// function call in the hot loops); saturates for huge or NaN values like `as`.
#[inline]
pub(crate) fn floor_i64(v: f64) -> i64 {
    let t = v as i64;
    if (t as f64) > v {
        t - 1
    } else {
        t
    }
}

/// (sin x, cos x) for x in [0, π] by Taylor polynomials around π/2 (error < 4e-9): the yaw half
/// angle, which only needs f32 accuracy, without libm's general `sincos`.
#[inline]
pub(crate) fn sin_cos_0_pi(x: f64) -> (f64, f64) {
    let t = x - std::f64::consts::FRAC_PI_2; // in [−π/2, π/2]: sin x = cos t, cos x = −sin t
    let t2 = t * t;
    let sin_t = t
        * (1.0
            + t2 * (-1.0 / 6.0
                + t2 * (1.0 / 120.0
                    + t2 * (-1.0 / 5040.0
                        + t2 * (1.0 / 362_880.0 + t2 * (-1.0 / 39_916_800.0 + t2 / 6_227_020_800.0))))));
    let cos_t = 1.0
        + t2 * (-0.5
            + t2 * (1.0 / 24.0
                + t2 * (-1.0 / 720.0
                    + t2 * (1.0 / 40_320.0
                        + t2 * (-1.0 / 3_628_800.0 + t2 * (1.0 / 479_001_600.0 - t2 / 87_178_291_200.0))))));
    (cos_t, -sin_t)
}

/// Jittered positions lie on a grid of this many steps per metre (0.1 mm): far finer than any
/// use of a placement, and their table entries are then short decimals (see `export::table`).
/// Poisson positions keep every bit (rounding could bring two closer than `min_spacing`).
pub const POSITION_STEPS_PER_M: f64 = 1e4;
/// Yaw in steps of 0.01°, scale in steps of 10⁻⁴, for the same reason.
pub const YAW_STEPS_PER_DEG: f64 = 100.0;
pub const SCALE_STEPS: f64 = 1e4;

/// Heights lie on a 1 µm grid (error ≤ 5·10⁻⁷ m against the mesh, far below the 10⁻⁴ m the
/// placement promises), quaternion components on a 10⁻⁷ grid (about f32's own resolution near 1):
/// their table entries are then short decimals written from integers, and the CSV and scene.glb
/// hold the same values.
pub const HEIGHT_STEPS_PER_M: f64 = 1e6;
pub const ROTATION_STEPS: f64 = 1e7;

/// The heights a placed instance may have: [max(water level, altitude min), altitude max].
pub(crate) fn height_bounds(s: &SpeciesRules) -> (f64, f64) {
    (s.altitude_m[0].max(s.water_level_m.unwrap_or(f64::NEG_INFINITY)), s.altitude_m[1])
}

/// `inst` with its height and rotation on their grids ([`HEIGHT_STEPS_PER_M`],
/// [`ROTATION_STEPS`]). A height that the rounding would carry out of `bounds` (water level,
/// altitude range) keeps its exact value, so the rules still hold for the written value.
#[inline]
pub(crate) fn on_table_grids(mut inst: Instance, bounds: (f64, f64)) -> Instance {
    let y = on_grid(inst.position[1], HEIGHT_STEPS_PER_M);
    if y >= bounds.0 && y <= bounds.1 {
        inst.position[1] = y;
    }
    for q in &mut inst.rotation {
        *q = on_grid(*q as f64, ROTATION_STEPS) as f32;
    }
    inst
}

/// `v` on a grid of `steps` per unit: the nearest f64 to ⌊v·steps + ½⌋ / steps.
#[inline]
pub(crate) fn on_grid(v: f64, steps: f64) -> f64 {
    floor_i64(v * steps + 0.5) as f64 / steps
}

/// Uniform in [0, 1) from the top 53 bits of a hash.
#[inline]
pub(crate) fn unit(h: u64) -> f64 {
    // through i64 (exact below 2^53): one conversion instruction, where u64 → f64 takes a branch
    // and several on x86-64
    ((h >> 11) as i64) as f64 * (1.0 / (1u64 << 53) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variants_mix_and_repeat() {
        let mut counts = [0usize; 3];
        for k in 0..300 {
            let p = [k as f64 * 0.37, 0.0, k as f64 * 1.91];
            let v = variant_of(p, 3);
            assert_eq!(v, variant_of(p, 3));
            counts[v as usize] += 1;
        }
        assert!(counts.iter().all(|&n| n > 60), "{counts:?}");
        assert_eq!(variant_of([1.0, 2.0, 3.0], 1), 0);
        // no variants is read as one
        assert_eq!(variant_of([1.0, 2.0, 3.0], 0), 0);
    }
}
