//! The snow analyzer: what the flake atlas, the emitter, the particle frame and the cover hold,
//! measured from the data itself (counts by habit and field, terminal velocity, cover by slope band
//! and by altitude band) for the scene report.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::mesh::Scene;
use crate::snow::cover::SNOW_ATTRIBUTE;
use crate::snow::emitter::Emitter;
use crate::snow::flakes::FlakeAtlas;
use crate::snow::particles::{Field, Particle};

/// Cover in one band of slope (degrees) or altitude (metres): terrain vertices in [from, to), their
/// mean weight, and the fraction with weight ≥ ½ ("covered").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Band {
    pub from: f32,
    pub to: f32,
    pub vertices: usize,
    pub mean_weight: f64,
    pub covered_fraction: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SnowReport {
    pub atlas_cells_by_kind: BTreeMap<String, usize>,
    pub particles_by_kind: BTreeMap<String, usize>,
    pub near_particles: usize,
    pub far_particles: usize,
    pub terminal_velocity_m_s: f32,
    pub time_constant_s: f32,
    /// Seconds a flake at terminal speed takes from the top of the volume to the ground.
    pub fall_time_s: f32,
    pub cover_by_slope: Vec<Band>,
    pub cover_by_altitude: Vec<Band>,
    /// Fraction of the top-down mask with weight ≥ ½ (when a mask was made).
    pub mask_coverage: Option<f64>,
}

/// Slope band edges in degrees.
pub const SLOPE_BANDS_DEG: [f32; 6] = [0.0, 10.0, 20.0, 30.0, 45.0, 90.01];
/// Altitude bands: this many equal bands between the lowest and highest vertex.
pub const ALTITUDE_BANDS: usize = 5;

pub fn analyze(
    atlas: &FlakeAtlas,
    emitter: &Emitter,
    particles: &[Particle],
    terrain: Option<&Scene>,
    mask: Option<&crate::snow::cover::CoverMask>,
) -> SnowReport {
    let mut atlas_cells_by_kind = BTreeMap::new();
    for c in &atlas.cells {
        *atlas_cells_by_kind.entry(c.kind.name().to_string()).or_insert(0) += 1;
    }
    let mut particles_by_kind = BTreeMap::new();
    for p in particles {
        if let Some(c) = atlas.cells.get(p.cell) {
            *particles_by_kind.entry(c.kind.name().to_string()).or_insert(0) += 1;
        }
    }
    let v = emitter.terminal_velocity_m_s();
    // (slope deg, altitude, weight) of every terrain vertex carrying the attribute
    let mut samples = Vec::new();
    for mesh in terrain.map(|t| t.meshes.as_slice()).unwrap_or(&[]) {
        for p in &mesh.primitives {
            let Some(snow) = p.custom.iter().find(|c| c.name == SNOW_ATTRIBUTE) else { continue };
            if p.normals.len() != p.positions.len() || snow.values.len() != p.positions.len() {
                continue;
            }
            for ((q, n), w) in p.positions.iter().zip(&p.normals).zip(&snow.values) {
                let slope = n[1].clamp(-1.0, 1.0).acos().to_degrees();
                samples.push((slope, q[1], w[0]));
            }
        }
    }
    let bands = |edges: &[f32], key: &dyn Fn(&(f32, f32, f32)) -> f32| -> Vec<Band> {
        edges
            .windows(2)
            .map(|e| {
                let inside: Vec<f32> = samples.iter().filter(|s| (e[0]..e[1]).contains(&key(s))).map(|s| s.2).collect();
                let n = inside.len();
                let mean = if n > 0 { inside.iter().map(|&w| w as f64).sum::<f64>() / n as f64 } else { 0.0 };
                let covered = if n > 0 { inside.iter().filter(|&&w| w >= 0.5).count() as f64 / n as f64 } else { 0.0 };
                Band { from: e[0], to: e[1], vertices: n, mean_weight: mean, covered_fraction: covered }
            })
            .collect()
    };
    let cover_by_slope = bands(&SLOPE_BANDS_DEG, &|s| s.0);
    let (lo, hi) = samples.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), s| (lo.min(s.1), hi.max(s.1)));
    let cover_by_altitude = if lo <= hi {
        let step = ((hi - lo) / ALTITUDE_BANDS as f32).max(1e-3);
        let mut edges: Vec<f32> = (0..=ALTITUDE_BANDS).map(|k| lo + step * k as f32).collect();
        // the top edge is open so the highest vertex lands in the last band
        if let Some(last) = edges.last_mut() {
            *last = f32::INFINITY;
        }
        let mut b = bands(&edges, &|s| s.1);
        if let Some(last) = b.last_mut() {
            last.to = hi;
        }
        b
    } else {
        Vec::new()
    };
    SnowReport {
        atlas_cells_by_kind,
        particles_by_kind,
        near_particles: particles.iter().filter(|p| p.field == Field::Near).count(),
        far_particles: particles.iter().filter(|p| p.field == Field::Far).count(),
        terminal_velocity_m_s: v,
        time_constant_s: emitter.time_constant_s(),
        fall_time_s: if v > 0.0 { emitter.fall_height_m / v } else { f32::INFINITY },
        cover_by_slope,
        cover_by_altitude,
        mask_coverage: mask.map(|m| m.coverage(0.5)),
    }
}
