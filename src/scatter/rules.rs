//! Placement rules shared by both placements: density thinning, mask, height on the mesh, water,
//! altitude and slope (degrees from the containing triangle's normal), and exclusion radii around
//! the instances of earlier species (a uniform-grid spatial hash of those instances).

use crate::random::mix64;
use crate::scatter::species::{Placement, SpeciesRules};

use super::common::{
    on_grid, sin_cos_0_pi, species_key, unit, Instance, RuleCounts, ScatterError, Tiling, POISSON_PACKING, SCALE_STEPS,
    YAW_STEPS_PER_DEG,
};
use super::density::DensityMap;
use super::surface::{texel_centre, SurfaceIndex, TexelTriangles};

/// Everything one species' candidates are judged by, resolved once.
pub struct Rules<'a> {
    pub surface: &'a SurfaceIndex,
    pub tiling: Tiling,
    pub species: &'a SpeciesRules,
    pub density: Option<&'a DensityMap>,
    pub mask: Option<&'a DensityMap>,
    /// Root of every random number of this species.
    pub key: u64,
    /// Instances per m² where the density map is 1, after the Poisson cap.
    pub effective_max_density: f64,
    /// Poisson: fraction of the unthinned set kept where density is 1 (≤ 1); jittered: 1.
    pub keep_scale: f64,
    /// Poisson radius: max(min_spacing, a self-exclusion radius).
    pub radius: f64,
    exclusions: Vec<ExclusionGrid>,
    inv_w: f64,
    inv_h: f64,
    align: f64,
    /// cos of the slope range's ends: slope ∈ [a, b] ⇔ n.y ∈ [cos b, cos a] (no acos per candidate)
    cos_slope: [f64; 2],
    /// Snow thinning (grass and flowers under a `[snow]` cover); `None` places as without snow.
    pub snow: Option<SnowThinning<'a>>,
    /// The tile rows `[first, end)` this run places (`None`: every row): the whole run's instances
    /// in those rows, in its order, and its rule counts of the candidates there (see
    /// [`crate::scatter::scatter_species_in_rows`]).
    pub rows: Option<[u32; 2]>,
}

/// Drops a candidate that passed the terrain rules with probability `strength × weight_at(x, z)`
/// of the snow cover mask, decided by a hash of the candidate's own seed (order-independent).
#[derive(Debug, Clone, Copy)]
pub struct SnowThinning<'a> {
    pub mask: &'a crate::snow::CoverMask,
    /// `[snow] thin_plants`, 0..1.
    pub strength: f64,
}

impl SnowThinning<'_> {
    /// Probability that a candidate at (x, z) is dropped: strength × the cover weight there.
    #[inline]
    pub fn drop_share(&self, x: f64, z: f64) -> f64 {
        self.strength * self.mask.weight_at(x as f32, z as f32) as f64
    }
}

/// Tag mixed into a candidate's seed for its snow decision ("snow"), independent of yaw and scale.
const SNOW_TAG: u64 = 0x736e_6f77;

impl<'a> Rules<'a> {
    pub fn new(
        surface: &'a SurfaceIndex,
        tiling: Tiling,
        species: &'a SpeciesRules,
        density: Option<&'a DensityMap>,
        mask: Option<&'a DensityMap>,
        earlier: &[(&str, &[Instance])],
        scene_seed: u64,
    ) -> Result<Rules<'a>, ScatterError> {
        let mut rules = Rules::without_exclusions(surface, tiling, species, density, mask, scene_seed)?;
        for ex in &species.exclusions {
            if ex.species == species.name {
                continue; // handled as the Poisson radius
            }
            let Some((_, instances)) = earlier.iter().find(|(name, _)| *name == ex.species) else {
                return Err(ScatterError::UnknownExclusion {
                    species: species.name.clone(),
                    other: ex.species.clone(),
                });
            };
            if ex.radius_m > 0.0 && !instances.is_empty() {
                rules.exclusions.push(ExclusionGrid::new(instances, ex.radius_m, tiling.extent));
            }
        }
        Ok(rules)
    }

    /// The rules without exclusions (the analyzer's expected counts ignore them).
    pub fn without_exclusions(
        surface: &'a SurfaceIndex,
        tiling: Tiling,
        species: &'a SpeciesRules,
        density: Option<&'a DensityMap>,
        mask: Option<&'a DensityMap>,
        scene_seed: u64,
    ) -> Result<Rules<'a>, ScatterError> {
        let bad = |reason: String| ScatterError::Settings { species: species.name.clone(), reason };
        if !(species.max_density >= 0.0 && species.max_density.is_finite()) {
            return Err(bad(format!(
                "max_density = {} must be a finite number ≥ 0 (instances per m²)",
                species.max_density
            )));
        }
        for ex in &species.exclusions {
            if !(ex.radius_m >= 0.0 && ex.radius_m.is_finite()) {
                return Err(bad(format!(
                    "exclusion radius {} around `{}` must be finite and ≥ 0",
                    ex.radius_m, ex.species
                )));
            }
        }
        if !species.scale.iter().all(|s| s.is_finite()) {
            return Err(bad(format!("scale {:?} must be finite", species.scale)));
        }
        let self_radius =
            species.exclusions.iter().filter(|e| e.species == species.name).map(|e| e.radius_m).fold(0.0, f64::max);
        let (radius, effective, keep_scale) = match species.placement {
            Placement::Jittered => {
                if self_radius > 0.0 {
                    return Err(bad(format!(
                        "an exclusion radius around its own instances needs placement = \"poisson\" (set min_spacing = {self_radius}); jittered placement keeps no spacing"
                    )));
                }
                // a spacing the placement cannot keep must not be accepted silently
                if species.min_spacing_m > 0.0 {
                    return Err(bad(format!(
                        "min_spacing = {} is kept only by placement = \"poisson\"; jittered placement keeps no spacing: remove min_spacing or use poisson",
                        species.min_spacing_m
                    )));
                }
                (0.0, species.max_density, 1.0)
            }
            Placement::Poisson => {
                let r = species.min_spacing_m.max(self_radius);
                if !(r > 0.0 && r.is_finite()) {
                    return Err(bad(format!(
                        "min_spacing = {} must be a finite number > 0 for placement = \"poisson\"",
                        species.min_spacing_m
                    )));
                }
                let packing = POISSON_PACKING / (r * r);
                let keep = (species.max_density / packing).min(1.0);
                (r, species.max_density.min(packing), keep)
            }
        };
        let [x0, z0, x1, z1] = tiling.extent;
        Ok(Rules {
            surface,
            tiling,
            species,
            density,
            mask,
            key: species_key(scene_seed, species),
            effective_max_density: effective,
            keep_scale,
            radius,
            exclusions: Vec::new(),
            inv_w: 1.0 / (x1 - x0),
            inv_h: 1.0 / (z1 - z0),
            align: if species.align_to_normal.is_finite() { species.align_to_normal.clamp(0.0, 1.0) } else { 0.0 },
            cos_slope: cos_range(species.slope_deg),
            snow: None,
            rows: None,
        })
    }

    /// Whether tile row `tz` is one this run places ([`Rules::rows`]).
    #[inline]
    pub fn places_row(&self, tz: u32) -> bool {
        self.rows.is_none_or(|[first, end]| tz >= first && tz < end)
    }

    /// Map coordinates (u, v) of a point.
    #[inline]
    pub fn uv(&self, x: f64, z: f64) -> (f64, f64) {
        ((x - self.tiling.extent[0]) * self.inv_w, (z - self.tiling.extent[1]) * self.inv_h)
    }

    /// Density in 0..1 at (x, z) (1 without a map).
    #[inline]
    pub fn density_at(&self, x: f64, z: f64) -> f64 {
        match self.density {
            Some(m) => {
                let (u, v) = self.uv(x, z);
                m.sample(u, v).clamp(0.0, 1.0) as f64
            }
            None => 1.0,
        }
    }

    /// Upper bound of the keep probability over a rectangle (0 lets a tile be skipped).
    pub fn max_keep_over(&self, rect: [f64; 4]) -> f64 {
        let (u0, v0) = self.uv(rect[0], rect[1]);
        let (u1, v1) = self.uv(rect[2], rect[3]);
        let d = self.density.map_or(1.0, |m| m.max_over(u0, v0, u1, v1) as f64);
        let m = self.mask.map_or(1.0, |m| if m.max_over(u0, v0, u1, v1) >= 0.5 { 1.0 } else { 0.0 });
        d * m * self.keep_scale
    }

    /// Upper bound of the density map alone over a rectangle (1 without a map): where it is 0, every
    /// candidate is a density reject.
    pub fn max_density_over(&self, rect: [f64; 4]) -> f64 {
        let (u0, v0) = self.uv(rect[0], rect[1]);
        let (u1, v1) = self.uv(rect[2], rect[3]);
        self.density.map_or(1.0, |m| m.max_over(u0, v0, u1, v1) as f64)
    }

    /// Judges the candidate at (x, z): kept when `keep_u` (uniform in [0, 1)) is below
    /// density · keep_scale and every rule passes; `attr` seeds its yaw and scale.
    /// `hint` is the surface's point-location hint for a run of nearby candidates
    /// ([`SurfaceIndex::height_at_near`]).
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn place(
        &self,
        x: f64,
        z: f64,
        keep_u: f64,
        attr: u64,
        tile: u32,
        counts: &mut RuleCounts,
        hint: &mut u32,
    ) -> Option<Instance> {
        counts.candidates += 1;
        if keep_u >= self.density_at(x, z) * self.keep_scale {
            counts.density += 1;
            return None;
        }
        if let Some(m) = self.mask {
            let (u, v) = self.uv(x, z);
            if m.sample(u, v) < 0.5 {
                counts.mask += 1;
                return None;
            }
        }
        let Some((y, n)) = self.surface.height_at_near(x, z, hint) else {
            counts.off_surface += 1;
            return None;
        };
        match self.terrain_rule(y, n) {
            Some(Reject::Water) => counts.water += 1,
            Some(Reject::Altitude) => counts.altitude += 1,
            Some(Reject::Slope) => counts.slope += 1,
            None => {
                if let Some(snow) = &self.snow {
                    if unit(mix64(attr ^ SNOW_TAG)) < snow.drop_share(x, z) {
                        counts.snow += 1;
                        return None;
                    }
                }
                if self.exclusions.iter().any(|g| g.excludes(x, z)) {
                    counts.exclusion += 1;
                    return None;
                }
                counts.placed += 1;
                return Some(self.instance([x, y, z], n, attr, tile));
            }
        }
        None
    }

    /// Which terrain rule (if any) rejects a point at height `y` on a triangle with normal `n`.
    #[inline]
    fn terrain_rule(&self, y: f64, n: [f64; 3]) -> Option<Reject> {
        let s = self.species;
        if let Some(w) = s.water_level_m {
            if y < w {
                return Some(Reject::Water);
            }
        }
        if !(y >= s.altitude_m[0] && y <= s.altitude_m[1]) {
            return Some(Reject::Altitude);
        }
        if !(n[1] >= self.cos_slope[0] && n[1] <= self.cos_slope[1]) {
            return Some(Reject::Slope);
        }
        None
    }

    /// Weight of a sample point in the estimate: density · mask · terrain rules · the share snow
    /// leaves (1 − strength · cover weight; no randomness). The surface is asked without a hint:
    /// a hint answers as `height_at` only where no upward triangles overlap.
    #[inline]
    fn weight(&self, x: f64, z: f64) -> f64 {
        self.weight_on(x, z, || self.surface.height_at(x, z))
    }

    /// [`Self::weight`] given how to ask the surface at (x, z) (height and normal; `None` off
    /// the mesh), asked only where density and mask leave a weight.
    #[inline]
    fn weight_on(&self, x: f64, z: f64, surface: impl FnOnce() -> Option<(f64, [f64; 3])>) -> f64 {
        let d = self.density_at(x, z);
        if d <= 0.0 {
            return 0.0;
        }
        if let Some(m) = self.mask {
            let (u, v) = self.uv(x, z);
            if m.sample(u, v) < 0.5 {
                return 0.0;
            }
        }
        match surface() {
            Some((y, n)) if self.terrain_rule(y, n).is_none() => match &self.snow {
                Some(snow) => d * (1.0 - snow.drop_share(x, z)).clamp(0.0, 1.0),
                None => d,
            },
            _ => 0.0,
        }
    }

    fn instance(&self, position: [f64; 3], n: [f64; 3], attr: u64, tile: u32) -> Instance {
        let s = self.species;
        let h1 = mix64(attr);
        // yaw in whole 0.01° in [0, 360), scale in whole 10⁻⁴ within its range (short table entries)
        let yaw_deg = if s.random_yaw {
            super::common::floor_i64(unit(h1) * 360.0 * YAW_STEPS_PER_DEG) as f64 / YAW_STEPS_PER_DEG
        } else {
            0.0
        };
        let scale = on_grid(s.scale[0] + (s.scale[1] - s.scale[0]) * unit(mix64(h1)), SCALE_STEPS)
            .clamp(s.scale[0], s.scale[1]) as f32;
        // the half angle π·yaw/360 in [0, π): a polynomial sincos
        let half = sin_cos_0_pi(yaw_deg * (std::f64::consts::PI / 360.0));
        Instance {
            position,
            rotation: orientation_half(half, n, self.align),
            scale: [scale; 3],
            yaw_deg: yaw_deg as f32,
            tile,
            variant: 0,
        }
    }
}

/// [cos max, cos min] of a slope range in degrees, clamped to [0°, 180°]; NaN ends reject all.
fn cos_range(deg: [f64; 2]) -> [f64; 2] {
    let c = |d: f64| d.clamp(0.0, 180.0).to_radians().cos();
    if deg[0].is_nan() || deg[1].is_nan() || deg[0] > deg[1] {
        return [f64::INFINITY, f64::NEG_INFINITY];
    }
    // exact ends: 0° is n.y ≤ 1 (cos 0 = 1), 90° is n.y ≥ 0 even if cos(π/2) rounds to 6e-17
    let lo = if deg[1] >= 90.0 && deg[1] < 90.0 + 1e-9 { 0.0 } else { c(deg[1]) };
    [lo, c(deg[0])]
}

enum Reject {
    Water,
    Altitude,
    Slope,
}

/// Unit quaternion (x, y, z, w): yaw about +Y, then a tilt by `align` × the slope angle about the
/// horizontal axis that turns +Y toward `n` (q = q_tilt ⊗ q_yaw, written out since q_yaw has only y).
pub fn orientation(yaw_rad: f64, n: [f64; 3], align: f64) -> [f32; 4] {
    orientation_half((0.5 * yaw_rad).sin_cos(), n, align)
}

/// [`orientation`] from (sin, cos) of half the yaw.
#[inline]
fn orientation_half((ys, yw): (f64, f64), n: [f64; 3], align: f64) -> [f32; 4] {
    let (ax, az) = (n[2], -n[0]); // up × n
    let len2 = ax * ax + az * az;
    if align <= 0.0 || len2 < 1e-24 {
        return [0.0, ys as f32, 0.0, yw as f32];
    }
    let (tx, tz, tw) = if align >= 1.0 {
        // the shortest arc from +Y to n: (up × n, 1 + up·n), normalised — no trigonometry
        let w = 1.0 + n[1];
        let inv = 1.0 / (len2 + w * w).sqrt();
        (ax * inv, az * inv, w * inv)
    } else {
        let phi = align * n[1].clamp(-1.0, 1.0).acos();
        let (s, c) = (0.5 * phi).sin_cos();
        let inv = s / len2.sqrt();
        (ax * inv, az * inv, c)
    };
    [(tx * yw - tz * ys) as f32, (tw * ys) as f32, (tz * yw + tx * ys) as f32, (tw * yw) as f32]
}

/// The species' density at every texel centre of a `w` × `h` map over the extent, as a fraction
/// of its effective max density ([`Rules::effective_max_density`]): density map · mask · terrain
/// rules (slope, altitude, water) · the share snow thinning leaves; exclusions not counted. Texel
/// (x, y) lies at ((x + ½)/w, (y + ½)/h) of the extent, row 0 at its minimum z (the layout of the
/// terrain's weight map). Row-major; the same values at any thread count.
pub fn weight_map(rules: &Rules, w: u32, h: u32) -> Vec<f32> {
    weight_map_located(rules, &rules.surface.locate_texels(rules.tiling.extent, w, h))
}

/// [`weight_map`] at the texels `texels` located on the rules' surface (one location for every
/// species of a terrain, [`SurfaceIndex::locate_texels`]; of its texel rows `texels.first ..` when
/// located by rows); located again if they were located over another extent.
pub fn weight_map_located(rules: &Rules, texels: &TexelTriangles) -> Vec<f32> {
    use rayon::prelude::*;
    let [x0, z0, x1, z1] = rules.tiling.extent;
    let [w, h] = texels.size;
    let rows = texels.tri.len() / (w.max(1) as usize);
    if texels.extent != rules.tiling.extent || texels.tri.len() != w as usize * rows || texels.first + rows > h as usize
    {
        let again = rules.surface.locate_texel_rows(rules.tiling.extent, w, h, texels.first..texels.first + rows);
        return weight_map_located(rules, &again);
    }
    let first = texels.first;
    texels
        .tri
        .par_chunks(w.max(1) as usize)
        .enumerate()
        .flat_map_iter(|(j, row)| {
            let z = texel_centre(z0, z1, (first + j) as u32, h);
            row.iter().enumerate().map(move |(i, &t)| {
                let x = texel_centre(x0, x1, i as u32, w);
                rules.weight_on(x, z, || rules.surface.height_on(t, x, z)).clamp(0.0, 1.0) as f32
            })
        })
        .collect()
}

/// Fraction-weighted mean of [`Rules::weight`] over the whole extent on `samples`² points.
pub fn estimate(rules: &Rules, samples: usize) -> f64 {
    estimate_region(rules, rules.tiling.extent, samples)
}

/// The part of [`estimate`] (the whole extent's `samples`² points) from the points in tile rows
/// `[first, end)`: never more than the whole, so a run of rows refusing on it refuses only what
/// the whole run refuses too; it reads the surface within those rows alone.
pub fn estimate_in_rows(rules: &Rules, samples: usize, [first, end]: [u32; 2]) -> f64 {
    let x0 = rules.tiling.extent[0];
    mean_weight(rules, rules.tiling.extent, samples, |z| (first..end).contains(&rules.tiling.tile_xz(x0, z).1))
}

/// Mean of density · mask · rules over a region by the midpoint rule on `samples`² points.
pub fn estimate_region(rules: &Rules, region: [f64; 4], samples: usize) -> f64 {
    mean_weight(rules, region, samples, |_| true)
}

/// Σ [`Rules::weight`] over the midpoints of a `samples`² grid on `region` whose z `row` keeps,
/// over all `samples`² points: rows in parallel, summed in row order (the same float result at
/// any thread count).
fn mean_weight(rules: &Rules, region: [f64; 4], samples: usize, row: impl Fn(f64) -> bool + Sync) -> f64 {
    use rayon::prelude::*;
    let n = samples.max(1);
    let (w, h) = (region[2] - region[0], region[3] - region[1]);
    if !(w > 0.0 && h > 0.0) {
        return 0.0;
    }
    let sum: f64 = (0..n)
        .into_par_iter()
        .map(|j| {
            let z = region[1] + (j as f64 + 0.5) / n as f64 * h;
            if !row(z) {
                return 0.0;
            }
            (0..n).map(|i| rules.weight(region[0] + (i as f64 + 0.5) / n as f64 * w, z)).sum::<f64>()
        })
        .collect::<Vec<f64>>()
        .iter()
        .sum();
    sum / (n * n) as f64
}

/// Instances of an earlier species in a uniform grid (cell ≥ radius, so a query reads 3×3 cells).
struct ExclusionGrid {
    origin: [f64; 2],
    inv_cell: f64,
    dims: [usize; 2],
    start: Vec<u32>,
    points: Vec<[f64; 2]>,
    r2: f64,
}

impl ExclusionGrid {
    fn new(instances: &[Instance], radius: f64, extent: [f64; 4]) -> ExclusionGrid {
        let (w, h) = (extent[2] - extent[0] + 2.0 * radius, extent[3] - extent[1] + 2.0 * radius);
        // about one instance per cell, never smaller than the radius
        let mut cell = radius.max((w * h / instances.len() as f64).sqrt());
        let cap = (4 * instances.len() + 1024) as f64;
        while (w / cell).ceil() * (h / cell).ceil() > cap {
            cell *= 1.5;
        }
        let origin = [extent[0] - radius, extent[1] - radius];
        let dims = [((w / cell).ceil() as usize).max(1), ((h / cell).ceil() as usize).max(1)];
        let inv_cell = 1.0 / cell;
        let cell_of = |p: &[f64; 3]| {
            let i = (((p[0] - origin[0]) * inv_cell).floor().max(0.0) as usize).min(dims[0] - 1);
            let j = (((p[2] - origin[1]) * inv_cell).floor().max(0.0) as usize).min(dims[1] - 1);
            j * dims[0] + i
        };
        let mut start = vec![0u32; dims[0] * dims[1] + 1];
        for inst in instances {
            start[cell_of(&inst.position) + 1] += 1;
        }
        for k in 1..start.len() {
            start[k] += start[k - 1];
        }
        let mut fill = start.clone();
        let mut points = vec![[0.0; 2]; instances.len()];
        for inst in instances {
            let c = cell_of(&inst.position);
            points[fill[c] as usize] = [inst.position[0], inst.position[2]];
            fill[c] += 1;
        }
        ExclusionGrid { origin, inv_cell, dims, start, points, r2: radius * radius }
    }

    /// True if an instance lies closer than the radius to (x, z).
    #[inline]
    fn excludes(&self, x: f64, z: f64) -> bool {
        let fi = super::common::floor_i64((x - self.origin[0]) * self.inv_cell);
        let fj = super::common::floor_i64((z - self.origin[1]) * self.inv_cell);
        for j in (fj - 1).max(0)..=(fj + 1).min(self.dims[1] as i64 - 1) {
            let row = j as usize * self.dims[0];
            let (i0, i1) = ((fi - 1).max(0), (fi + 1).min(self.dims[0] as i64 - 1));
            if i0 > i1 {
                continue;
            }
            let (s, e) = (self.start[row + i0 as usize] as usize, self.start[row + i1 as usize + 1] as usize);
            for p in &self.points[s..e] {
                let (dx, dz) = (p[0] - x, p[1] - z);
                if dx * dx + dz * dz < self.r2 {
                    return true;
                }
            }
        }
        false
    }
}

/// Expected count of a species over `[x0, z0, x1, z1]` (a region of the extent): the integral of
/// density · mask · terrain rules (slope, altitude, water) · the share snow thinning leaves, times
/// the effective max density, by the midpoint rule on `samples`² points. Exclusions are not
/// counted. Used by the analyzer.
#[allow(clippy::too_many_arguments)]
pub fn expected_count(
    surface: &SurfaceIndex,
    extent: [f64; 4],
    species: &SpeciesRules,
    density: Option<&DensityMap>,
    mask: Option<&DensityMap>,
    snow: Option<SnowThinning<'_>>,
    region: [f64; 4],
    samples: usize,
) -> Result<f64, ScatterError> {
    let tiling = Tiling::new(extent, (extent[2] - extent[0]).max(extent[3] - extent[1]))?;
    let mut ctx = Rules::new(surface, tiling, species, density, mask, &[], 0).or_else(|e| match e {
        // exclusions are ignored here, so unknown names do not matter
        ScatterError::UnknownExclusion { .. } => Rules::without_exclusions(surface, tiling, species, density, mask, 0),
        e => Err(e),
    })?;
    ctx.snow = snow;
    let area = (region[2] - region[0]).max(0.0) * (region[3] - region[1]).max(0.0);
    Ok(estimate_region(&ctx, region, samples) * ctx.effective_max_density * area)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rotate(q: [f32; 4], v: [f64; 3]) -> [f64; 3] {
        let (x, y, z, w) = (q[0] as f64, q[1] as f64, q[2] as f64, q[3] as f64);
        // v' = v + 2w (q × v) + 2 q × (q × v)
        let c = |a: [f64; 3], b: [f64; 3]| {
            [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
        };
        let qv = [x, y, z];
        let t = c(qv, v);
        let t = [2.0 * t[0], 2.0 * t[1], 2.0 * t[2]];
        let u = c(qv, t);
        [v[0] + w * t[0] + u[0], v[1] + w * t[1] + u[1], v[2] + w * t[2] + u[2]]
    }

    #[test]
    fn orientation_turns_up_to_normal_and_keeps_yaw() {
        let l = (0.3f64 * 0.3 + 0.9 * 0.9 + 0.2 * 0.2).sqrt();
        let n = [0.3 / l, 0.9 / l, -0.2 / l];
        for yaw in [0.0, 1.0, 4.0] {
            let q = orientation(yaw, n, 1.0);
            let norm: f32 = q.iter().map(|v| v * v).sum();
            assert!((norm - 1.0).abs() < 1e-6);
            let up = rotate(q, [0.0, 1.0, 0.0]);
            for k in 0..3 {
                assert!((up[k] - n[k]).abs() < 1e-6, "{up:?} vs {n:?}");
            }
        }
        // upright: up stays up, +X turns by the yaw about +Y
        let q = orientation(std::f64::consts::FRAC_PI_2, n, 0.0);
        let x = rotate(q, [1.0, 0.0, 0.0]);
        assert!((x[0]).abs() < 1e-6 && (x[2] + 1.0).abs() < 1e-6, "{x:?}");
        // half-aligned: the angle to +Y is half the slope
        let q = orientation(0.3, n, 0.5);
        let up = rotate(q, [0.0, 1.0, 0.0]);
        assert!((up[1].acos() - 0.5 * n[1].acos()).abs() < 1e-6);
    }
}
