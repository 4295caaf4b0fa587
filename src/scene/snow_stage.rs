//! The snow stage: from the preset's `[snow]` and the built terrain, writes `snow/` — the flake
//! atlas, `emitter.json`, the particle frame (CSV and instanced `snowfall.glb`), the cover mask,
//! `snow_layer.glb` when asked, and `terrain_snow.glb` (the terrain with the `_SNOW` attribute).
//!
//! The terrain with the weight goes to `snow/terrain_snow.glb` rather than over `terrain/terrain.glb`:
//! the terrain stage's files are cached under the terrain's key alone, and scene.glb and the LoD
//! files are built from them, so rewriting them here would make one file depend on two stages.
//! Later stages (scatter thinning, preview) read the mask back from `cover_mask.png`, so a build
//! that restores this stage from the cache thins and draws exactly like the one that computed it.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::export;
use crate::mesh::Scene;
use crate::scene::cache::KeyBuilder;
use crate::scene::error::{SceneBuildError, StageError};
use crate::scene::pipeline::{read_back, Stage, StageJob, TerrainHandoff};
use crate::scene::Preset;
use crate::snow::{self, CoverMask, SnowReport, SnowSettings};

/// Folder of the stage's files in the scene folder.
pub const SNOW_DIR: &str = "snow";
/// The mask's file name in `snow/`.
pub const MASK_FILE: &str = "cover_mask.png";
/// The terrain with the `_SNOW` attribute, in `snow/`.
pub const TERRAIN_FILE: &str = "terrain_snow.glb";

fn fail(message: String) -> StageError {
    StageError::Failed { stage: "snow", message }
}

/// Where the mask lies over the terrain (pixel (i, j) centre at min + (i + ½, j + ½)·metres_per_pixel).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct MaskInfo {
    pub file: PathBuf,
    pub width: u32,
    pub height: u32,
    pub min_x: f32,
    pub min_z: f32,
    pub metres_per_pixel: f32,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
pub struct SnowSeconds {
    pub atlas: f64,
    pub particles: f64,
    pub cover: f64,
    pub write: f64,
    pub analyze: f64,
    pub total: f64,
}

/// How closely the terrain's snow layer (the snow channel of `_LAYER_WEIGHTS`, which its base
/// colour blends by) follows the cover (`_SNOW`) on the terrain's vertices: the terrain stage bakes
/// the layer from the heightfield with the same cover settings, so only byte rounding and the
/// skirts (which take their border's layers) part them.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
pub struct LayerAgreement {
    /// Vertices compared (skirt and base vertices, below the surface, left out).
    pub vertices: usize,
    pub mean_abs_difference: f64,
    pub max_abs_difference: f64,
    /// Share of the compared vertices covered (weight ≥ ½) by the cover and by the layer.
    pub covered_fraction_cover: f64,
    pub covered_fraction_layer: f64,
}

/// Compares the snow channel of `_LAYER_WEIGHTS` with `_SNOW` on every surface vertex of `terrain`:
/// the highest vertex of its primitive at its (x, z) (a skirt or base vertex hangs below a
/// surface vertex and takes its layers).
pub fn layer_agreement(terrain: &Scene) -> LayerAgreement {
    use crate::terrain::layers::LAYER_WEIGHTS_ATTRIBUTE;
    let (mut n, mut sum, mut max, mut cov, mut lay) = (0usize, 0.0f64, 0.0f64, 0usize, 0usize);
    for p in terrain.meshes.iter().flat_map(|m| &m.primitives) {
        let find = |name: &str| p.custom.iter().find(|c| c.name == name && c.values.len() == p.positions.len());
        let (Some(snow), Some(layers)) = (find(snow::SNOW_ATTRIBUTE), find(LAYER_WEIGHTS_ATTRIBUTE)) else {
            continue;
        };
        let mut top = std::collections::HashMap::new();
        for q in &p.positions {
            let y = top.entry((q[0].to_bits(), q[2].to_bits())).or_insert(q[1]);
            *y = y.max(q[1]);
        }
        for (q, (s, l)) in p.positions.iter().zip(snow.values.iter().zip(&layers.values)) {
            if top.get(&(q[0].to_bits(), q[2].to_bits())).is_some_and(|&y| q[1] < y) {
                continue;
            }
            let d = (s[0] as f64 - l[3] as f64).abs();
            n += 1;
            sum += d;
            max = max.max(d);
            cov += usize::from(s[0] >= 0.5);
            lay += usize::from(l[3] >= 0.5);
        }
    }
    let share = |k: usize| if n == 0 { 0.0 } else { k as f64 / n as f64 };
    LayerAgreement {
        vertices: n,
        mean_abs_difference: if n == 0 { 0.0 } else { sum / n as f64 },
        max_abs_difference: max,
        covered_fraction_cover: share(cov),
        covered_fraction_layer: share(lay),
    }
}

/// What the snow stage wrote and measured.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SnowStageReport {
    /// Every file written, scene-relative (`snow/…`).
    pub files: Vec<PathBuf>,
    pub mask: MaskInfo,
    pub terrain_file: PathBuf,
    pub layer_file: Option<PathBuf>,
    pub particles: usize,
    pub layer_triangles: usize,
    pub analysis: SnowReport,
    /// The terrain's snow layer against the cover (see [`LayerAgreement`]).
    #[serde(default)]
    pub layer_agreement: LayerAgreement,
    pub seconds: SnowSeconds,
}

impl SnowStageReport {
    pub fn files(&self) -> Vec<PathBuf> {
        self.files.clone()
    }
}

/// Version of what the snow stage writes for given inputs: part of its cache key (see
/// [`crate::scene::terrain_stage::TERRAIN_ALGORITHM_VERSION`]). 2: terrain_snow.glb carries the textured terrain. 3: and its
/// `_LAYER_WEIGHTS` (terrain 5). 4: and its normal map and tangents (terrain 6). 5: its snow layer
/// follows the cover (terrain 7); the report's layer_agreement. 6: its soil layer and `_SURFACE`
/// (terrain 8).
pub const SNOW_ALGORITHM_VERSION: u32 = 6;

/// Cache key: the terrain's key and the snow settings.
pub fn snow_key(snow: &SnowSettings, terrain_key: &str) -> String {
    let mut k = KeyBuilder::new("snow", SNOW_ALGORITHM_VERSION);
    k.add(terrain_key.as_bytes());
    k.add(serde_json::to_string(snow).unwrap_or_default().as_bytes());
    k.finish()
}

fn rel(scene_dir: &Path, files: Vec<PathBuf>) -> Vec<PathBuf> {
    files.into_iter().map(|w| w.strip_prefix(scene_dir).map(Path::to_path_buf).unwrap_or(w)).collect()
}

/// Runs the snow stage into `scene_dir/snow/` on `terrain` (the terrain stage's main scene).
pub fn run_snow(
    _preset: &Preset,
    s: &SnowSettings,
    terrain: &Scene,
    scene_dir: &Path,
) -> Result<SnowStageReport, StageError> {
    let t0 = Instant::now();
    let dir = scene_dir.join(SNOW_DIR);
    let err = |e: snow::SnowError| StageError::of("snow", &e, e.to_string());

    let t1 = Instant::now();
    let atlas = snow::build_atlas(&s.flakes).map_err(err)?;
    let atlas_s = t1.elapsed().as_secs_f64();

    let t1 = Instant::now();
    let particles = snow::particles(&s.emitter, &atlas).map_err(err)?;
    let particles_s = t1.elapsed().as_secs_f64();

    let t1 = Instant::now();
    let mut covered = terrain.clone();
    covered.name = "terrain_snow".into();
    snow::apply_cover(&mut covered, &s.cover).map_err(err)?;
    let mask = snow::cover_mask(&covered, s.mask_px).map_err(err)?;
    let layer = if s.layer { Some(snow::snow_layer(&covered, s.layer_min_weight).map_err(err)?) } else { None };
    let cover_s = t1.elapsed().as_secs_f64();

    let t1 = Instant::now();
    let mut files =
        rel(scene_dir, snow::write_snowfall(&dir, &atlas, &s.emitter, &particles, s.flakes.alpha_cutoff).map_err(err)?);
    files.extend(rel(scene_dir, snow::write_cover(&dir, &mask, layer.as_ref()).map_err(err)?));
    let terrain_file = PathBuf::from(SNOW_DIR).join(TERRAIN_FILE);
    let written = export::write_scene(&covered, &scene_dir.join(&terrain_file)).map_err(|e| fail(e.to_string()))?;
    files.extend(rel(scene_dir, written));
    let write_s = t1.elapsed().as_secs_f64();

    let t1 = Instant::now();
    // the report's mask coverage is that of the mask as stored (what later stages read)
    let mask_file = PathBuf::from(SNOW_DIR).join(MASK_FILE);
    let mut info = MaskInfo {
        file: mask_file,
        width: mask.width,
        height: mask.height,
        min_x: mask.min_x,
        min_z: mask.min_z,
        metres_per_pixel: mask.metres_per_pixel,
    };
    let stored = load_mask(scene_dir, &info)?;
    info.width = stored.width;
    info.height = stored.height;
    let analysis = snow::analyze(&atlas, &s.emitter, &particles, Some(&covered), Some(&stored));
    let layer_agreement = layer_agreement(&covered);
    let analyze_s = t1.elapsed().as_secs_f64();

    let layer_file = layer.as_ref().map(|_| PathBuf::from(SNOW_DIR).join("snow_layer.glb"));
    let layer_triangles = layer.as_ref().map_or(0, |l| l.meshes.iter().map(|m| m.triangle_count()).sum());
    Ok(SnowStageReport {
        files,
        mask: info,
        terrain_file,
        layer_file,
        particles: particles.len(),
        layer_triangles,
        analysis,
        layer_agreement,
        seconds: SnowSeconds {
            atlas: atlas_s,
            particles: particles_s,
            cover: cover_s,
            write: write_s,
            analyze: analyze_s,
            total: t0.elapsed().as_secs_f64(),
        },
    })
}

/// The cover mask as stored in `snow/cover_mask.png`, placed over the terrain as the report says.
pub fn load_mask(scene_dir: &Path, info: &MaskInfo) -> Result<CoverMask, StageError> {
    let path = scene_dir.join(&info.file);
    let bytes =
        std::fs::read(&path).map_err(|e| fail(format!("{}: cannot read the cover mask: {e}", path.display())))?;
    CoverMask::from_png(&bytes, info.min_x, info.min_z, info.metres_per_pixel)
        .map_err(|e| fail(format!("{}: {e}", path.display())))
}

/// The stage in a scene build.
pub struct SnowJob<'a> {
    pub preset: &'a Preset,
    pub snow: &'a SnowSettings,
    pub terrain: &'a TerrainHandoff,
}

impl StageJob for SnowJob<'_> {
    type Report = SnowStageReport;
    type Artifact = ();
    const STAGE: Stage = Stage::Snow;

    fn key(&self) -> Result<String, SceneBuildError> {
        Ok(snow_key(self.snow, &self.terrain.key))
    }

    fn files(report: &SnowStageReport) -> Vec<PathBuf> {
        report.files()
    }

    fn run(&self, dir: &Path) -> Result<(SnowStageReport, ()), SceneBuildError> {
        // always from the terrain as written (not the in-memory scene), so a snow stage run after
        // a cached terrain gives the same bytes as one after a fresh terrain
        let written = read_back(dir, &self.terrain.main)?;
        Ok((run_snow(self.preset, self.snow, &written, dir)?, ()))
    }
}
