//! What placement reads of a species: its name (seeds, exclusions, messages) and its rules. The
//! scene translates a preset's `[[species]]` into these; the plants stage reads the rest.

use std::path::PathBuf;

use serde::Serialize;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Placement {
    /// Poisson-disk sampling thinned by density: spacing ≥ `min_spacing` everywhere.
    Poisson,
    /// One jittered candidate per grid cell, thinned by density: fast, for dense ground cover.
    Jittered,
}

/// `exclusion = { species = "...", radius = m }`: keep at least `radius_m` from every instance
/// of `species` (which must be placed earlier; naming the species itself keeps its own instances
/// apart).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Exclusion {
    pub species: String,
    pub radius_m: f64,
}

/// `altitude` when absent: "unbounded", written as ±1e9 m rather than ±∞ because JSON has no
/// infinity (serde_json writes `null`), and the manifest must reproduce the build. No terrain
/// comes near 10⁶ km, so the band never excludes anything.
pub const UNBOUNDED_ALTITUDE_M: [f64; 2] = [-1e9, 1e9];

/// How one species is placed: the placement half of a `[[species]]` (the scene's
/// `SpeciesSettings` flattens it into the manifest).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpeciesRules {
    pub name: String,
    /// Grayscale image stretched over the terrain extent (bilinear); value 0..1 scales
    /// `max_density`. `None`: uniform.
    pub density_map: Option<PathBuf>,
    /// Grayscale image over the extent; nothing is placed where it is below 0.5.
    pub mask: Option<PathBuf>,
    /// Instances per square metre where the density map is 1.
    pub max_density: f64,
    pub placement: Placement,
    /// Poisson radius in metres (minimum distance between two instances of this species).
    /// The parser guarantees > 0 for `Poisson`; 0 (no minimum) is the default for `Jittered`.
    pub min_spacing_m: f64,
    /// Allowed terrain slope in degrees, [min, max].
    pub slope_deg: [f64; 2],
    /// Allowed altitude in metres, [min, max]; [`UNBOUNDED_ALTITUDE_M`] when the preset sets none.
    pub altitude_m: [f64; 2],
    /// Nothing is placed below this height (metres).
    pub water_level_m: Option<f64>,
    /// Uniform scale range [min, max].
    pub scale: [f64; 2],
    pub random_yaw: bool,
    /// 0: upright (+Y), 1: along the terrain normal; in between, a blend.
    pub align_to_normal: f64,
    pub exclusions: Vec<Exclusion>,
    /// Offset added to the scene seed for this species.
    pub seed: u64,
    /// Explicit limit; exceeding it is an error naming the species and the remedy.
    pub max_instances: usize,
}
