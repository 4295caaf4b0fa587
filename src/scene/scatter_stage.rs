//! The scatter stage: places every `[[species]]` on the exported terrain surface (in preset order,
//! so exclusions see the species before them) and writes `placements/<species>.csv` and `.json`.
//! The view stage draws them (scene.glb).

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::export::{self, table};
use crate::mesh::Scene;
use crate::plants::palette;
use crate::scatter::density::DensityMap;
use crate::scatter::rules::SnowThinning;
use crate::scatter::stats::{analyze, SpeciesStats};
use crate::scatter::surface::SurfaceIndex;
use crate::scatter::{scatter_species_snow, Instance, RuleCounts};
use crate::scene::cache::{sha256_hex, KeyBuilder};
use crate::scene::error::{SceneBuildError, StageError};
use crate::scene::pipeline::{Stage, StageJob, TerrainHandoff};
use crate::scene::{Preset, SpeciesSettings};

fn fail(message: String) -> StageError {
    StageError::Failed { stage: "scatter", message }
}

/// A species' input at fault (exit code 2): a map that does not read, settings or limits it exceeds.
fn bad_input(message: String) -> StageError {
    StageError::Input { stage: "scatter", message }
}

/// What the scatter stage measured for one species (also written as placements/<species>.json).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SpeciesReport {
    pub name: String,
    pub kind: crate::plants::SpeciesKind,
    pub count: usize,
    /// The placement table (`placements/<species>.csv`, or `.bin` with `[scatter] table = "binary"`).
    pub csv: PathBuf,
    pub rules: RuleCounts,
    pub stats: SpeciesStats,
    pub seconds: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ScatterStageReport {
    pub tile_m: f64,
    pub species: Vec<SpeciesReport>,
    pub seconds: f64,
}

impl ScatterStageReport {
    pub fn files(&self) -> Vec<PathBuf> {
        let mut files = Vec::new();
        for s in &self.species {
            files.push(s.csv.clone());
            files.push(s.csv.with_extension("json"));
        }
        files
    }
}

/// Version of what the scatter stage writes for given inputs: part of its cache key (see
/// [`crate::scene::terrain_stage::TERRAIN_ALGORITHM_VERSION`]). 2: scene.glb holds no unused mesh; 3: its terrain is textured; 4:
/// its plants carry wind in `_WIND`, not COLOR_0; 5: a tree without an L-system instances a
/// built-in tree; 6: flower cards lit by a normal atlas (with TANGENT); 7: scene.glb moved to the
/// view stage (tables only); 8: a `variant` column.
pub const SCATTER_ALGORITHM_VERSION: u32 = 8;

/// Cache key: the terrain's key, the species and scatter settings, the scene seed, the maps' bytes.
pub fn scatter_key(preset: &Preset, terrain_key: &str) -> Result<String, StageError> {
    let mut k = KeyBuilder::new("scatter", SCATTER_ALGORITHM_VERSION);
    k.add(terrain_key.as_bytes());
    k.add(&preset.scene.seed.to_le_bytes());
    k.add(serde_json::to_string(&preset.scatter).unwrap_or_default().as_bytes());
    if let Some(map) = &preset.scatter.vegetation_map {
        let bytes = crate::input::read_limited(map, crate::input::MAX_IMAGE_BYTES, "a vegetation map")
            .map_err(|e| bad_input(e.to_string()))?;
        k.add(sha256_hex(&bytes).as_bytes());
    }
    for s in &preset.species {
        k.add(serde_json::to_string(s).unwrap_or_default().as_bytes());
        crate::scene::plants_stage::add_look_inputs(&mut k, &s.rules.name, &s.look)?;
        for map in [&s.rules.density_map, &s.rules.mask].into_iter().flatten() {
            let bytes = crate::input::read_limited(map, crate::input::MAX_IMAGE_BYTES, "a density map or mask")
                .map_err(|e| bad_input(e.to_string()))?;
            k.add(sha256_hex(&bytes).as_bytes());
        }
    }
    Ok(k.finish())
}

/// The terrain surface of a terrain scene: every primitive of every mesh (skirts and base are
/// vertical or face down; the surface index skips those triangles).
pub fn surface_of(terrain: &Scene) -> SurfaceIndex {
    let parts: Vec<(&[[f32; 3]], &[u32])> =
        terrain.meshes.iter().flat_map(|m| m.primitives.iter().map(|p| (&p.positions[..], &p.indices[..]))).collect();
    SurfaceIndex::from_parts(&parts)
}

fn load_map(path: &Option<PathBuf>) -> Result<Option<DensityMap>, StageError> {
    path.as_ref().map(|p| DensityMap::load(p).map_err(|e| bad_input(e.to_string()))).transpose()
}

/// The placed instances of one species, for the preview.
pub struct Placed {
    pub species: SpeciesSettings,
    pub color: [f32; 4],
    pub instances: Vec<Instance>,
}

/// Runs the scatter stage into `scene_dir`.
pub fn run_scatter(
    preset: &Preset,
    terrain: &Scene,
    scene_dir: &Path,
) -> Result<(ScatterStageReport, Vec<Placed>), StageError> {
    run_scatter_with_snow(preset, terrain, scene_dir, None)
}

/// [`run_scatter`] with the snow stage's cover mask: grass and flowers are thinned by
/// `[snow] thin_plants` × the mask's weight (counted as the `snow` rule); trees and meshes are not.
pub fn run_scatter_with_snow(
    preset: &Preset,
    terrain: &Scene,
    scene_dir: &Path,
    snow_mask: Option<&crate::snow::CoverMask>,
) -> Result<(ScatterStageReport, Vec<Placed>), StageError> {
    let t0 = Instant::now();
    let surface = surface_of(terrain);
    let extent = surface.bounds();
    let mut placed: Vec<Placed> = Vec::new();
    let mut reports = Vec::new();
    let vegetation = if preset.species.iter().any(|s| s.vegetation_type.is_some()) {
        load_map(&preset.scatter.vegetation_map)?
    } else {
        None
    };
    for (index, species) in preset.species.iter().enumerate() {
        let t1 = Instant::now();
        let density = load_map(&species.rules.density_map)?;
        let mask = load_map(&species.rules.mask)?;
        // a vegetation type grows only where the map of types holds its shade (within its own mask)
        let mask = match (species.vegetation_type, &vegetation) {
            (Some(shade), Some(types)) => Some(types.where_shade(shade, mask.as_ref())),
            _ => mask,
        };
        let earlier: Vec<(&str, &[Instance])> =
            placed.iter().map(|p| (p.species.rules.name.as_str(), &p.instances[..])).collect();
        let thinning = match (snow_mask, &preset.snow, species.kind) {
            (Some(mask), Some(snow), crate::plants::SpeciesKind::Grass | crate::plants::SpeciesKind::Flower)
                if snow.thin_plants > 0.0 =>
            {
                Some(SnowThinning { mask, strength: snow.thin_plants })
            }
            _ => None,
        };
        let mut result = scatter_species_snow(
            &surface,
            extent,
            &species.rules,
            density.as_ref(),
            mask.as_ref(),
            &earlier,
            preset.scatter.tile_m,
            preset.scene.seed,
            thinning,
        )
        .map_err(|e| bad_input(e.to_string()))?;
        // each row names the variant it shows: the manifest's chain maps it to its meshes
        crate::scatter::assign_variants(&mut result.instances, species.look.table_variants());
        let generate_s = t1.elapsed().as_secs_f64();
        let stats = analyze(
            &surface,
            extent,
            &species.rules,
            density.as_ref(),
            mask.as_ref(),
            thinning,
            &result.instances,
            preset.scatter.tile_m,
            generate_s,
        )
        .map_err(|e| bad_input(e.to_string()))?;
        let format = preset.scatter.table;
        let csv = PathBuf::from("placements").join(format!("{}.{}", species.rules.name, format.extension()));
        match format {
            table::TableFormat::Csv => table::write_placements_csv(&scene_dir.join(&csv), &result.instances),
            table::TableFormat::Binary => {
                crate::export::table_bin::write_placements_bin(&scene_dir.join(&csv), &result.instances)
            }
        }
        .map_err(|e| fail(e.to_string()))?;
        let report = SpeciesReport {
            name: species.rules.name.clone(),
            kind: species.kind,
            count: result.instances.len(),
            csv: csv.clone(),
            rules: result.counts,
            stats,
            seconds: t1.elapsed().as_secs_f64(),
        };
        // timing stays out of the summary, so the file is byte-identical from run to run
        let mut summary = serde_json::to_value(SpeciesSummary::from(&report)).map_err(|e| fail(e.to_string()))?;
        if format == table::TableFormat::Binary {
            // the binary table's header: where each array lies
            let layout = crate::export::table_bin::layout(report.count as u64);
            if let Some(o) = summary.as_object_mut() {
                o.insert("binary".into(), serde_json::to_value(layout).map_err(|e| fail(e.to_string()))?);
            }
        }
        if let Some(st) = summary.get_mut("stats").and_then(serde_json::Value::as_object_mut) {
            st.remove("seconds");
            st.remove("analyze_seconds");
        }
        let mut json = serde_json::to_string_pretty(&summary).map_err(|e| fail(e.to_string()))?;
        json.push('\n');
        export::write_atomic(&scene_dir.join(csv.with_extension("json")), json.as_bytes())
            .map_err(|e| fail(e.to_string()))?;
        reports.push(report);
        placed.push(Placed {
            species: species.clone(),
            color: palette::species_color(species.kind, index),
            instances: result.instances,
        });
    }
    let report =
        ScatterStageReport { tile_m: preset.scatter.tile_m, species: reports, seconds: t0.elapsed().as_secs_f64() };
    Ok((report, placed))
}

/// placements/<species>.json: count, per-tile counts and AABBs (in `stats.per_tile`), and the
/// analyzer's figures.
#[derive(Serialize)]
struct SpeciesSummary<'a> {
    species: &'a str,
    kind: crate::plants::SpeciesKind,
    count: usize,
    table: &'a Path,
    rules: &'a RuleCounts,
    stats: &'a SpeciesStats,
}

impl<'a> From<&'a SpeciesReport> for SpeciesSummary<'a> {
    fn from(r: &'a SpeciesReport) -> Self {
        SpeciesSummary {
            species: &r.name,
            kind: r.kind,
            count: r.count,
            table: &r.csv,
            rules: &r.rules,
            stats: &r.stats,
        }
    }
}

/// The stage in a scene build.
pub struct ScatterJob<'a> {
    pub preset: &'a Preset,
    pub terrain: &'a TerrainHandoff,
    /// The snow cover that thins the placements, and the snow stage's key.
    pub cover: Option<(&'a crate::snow::CoverMask, &'a str)>,
}

impl StageJob for ScatterJob<'_> {
    type Report = ScatterStageReport;
    /// Every species' placements (what the preview draws after a fresh run).
    type Artifact = Vec<Placed>;
    const STAGE: Stage = Stage::Scatter;

    fn key(&self) -> Result<String, SceneBuildError> {
        // thinning by the snow cover makes the placements depend on the snow stage too
        let upstream = match self.cover {
            Some((_, snow_key)) => format!("{}+snow:{snow_key}", self.terrain.key),
            None => self.terrain.key.clone(),
        };
        Ok(scatter_key(self.preset, &upstream)?)
    }

    fn files(report: &ScatterStageReport) -> Vec<PathBuf> {
        report.files()
    }

    fn run(&self, dir: &Path) -> Result<(ScatterStageReport, Vec<Placed>), SceneBuildError> {
        let cover = self.cover.map(|(m, _)| m);
        Ok(run_scatter_with_snow(self.preset, self.terrain.scene()?, dir, cover)?)
    }
}
