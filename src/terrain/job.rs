//! One terrain job end to end: decode → mesh (grid or TIN) → measure → build scene → write,
//! with the timings and the analyzer's figures collected into a report.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::export::gltf::WriteOptions;
use crate::export::grid::PositionGrid;
use crate::export::quantize::Quantization;
use crate::export::{self, ExportError};
use crate::heightfield::{self, DecodeOptions, Decoded, Encoding, Heightfield, HeightfieldError};
use crate::mesh::{Bounds, Scene};
use crate::terrain::build::{build_scene, BuildError, BuildOptions};
use crate::terrain::error::{exact_max_error, measure_stored, ErrorStats, TerrainError};
use crate::terrain::grid::grid;
use crate::terrain::layers::{bake_layers_with, LayerReport, TerrainLayers};
use crate::terrain::normal_map::{bake_normal_map, put_normal_map, NormalMapReport};
use crate::terrain::sample_mesh::SampleMesh;
use crate::terrain::stored::Storage;
use crate::terrain::tin::{tin_stored, TinOptions};
use crate::terrain::vegetation::VegetationCover;

/// Where the heights come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    File(PathBuf),
    /// The embedded procedural map ([`crate::synth::demo`]).
    Demo,
}

impl Source {
    pub fn label(&self) -> String {
        match self {
            Source::File(p) => p.display().to_string(),
            Source::Demo => "demo (embedded procedural map)".into(),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum MeshMode {
    /// Greedy-insertion Delaunay TIN, bounded by --max-error.
    Tin,
    /// Regular grid of every --grid-step samples.
    Grid,
}

#[derive(Debug, Clone)]
pub struct TerrainJob {
    pub source: Source,
    pub decode: DecodeOptions,
    pub mode: MeshMode,
    pub grid_step: usize,
    pub max_error_m: f64,
    pub max_triangles: Option<usize>,
    /// The meshing work budget in vertices ([`crate::terrain::budget`]).
    pub max_vertices: usize,
    pub build: BuildOptions,
    /// Store positions as 16-bit integers (KHR_mesh_quantization); the bound holds as quantized.
    pub quantize: bool,
    /// Also compress vertex and index data (EXT_meshopt_compression; lossless); needs `quantize`.
    pub meshopt: bool,
}

#[derive(Debug, thiserror::Error)]
pub enum JobError {
    #[error(transparent)]
    Input(#[from] HeightfieldError),
    #[error("{source_label}: {error}")]
    Terrain { source_label: String, error: TerrainError },
    #[error(transparent)]
    Build(#[from] BuildError),
    #[error(transparent)]
    Export(#[from] ExportError),
    #[error("invalid option: {0}")]
    Options(String),
    #[error("cannot encode the terrain's base-colour texture: {0}")]
    Texture(String),
    #[error(
        "{source_label}: internal error: as written the terrain is {measured_m} m off the map at sample (column {i}, \
         row {j}), over --max-error {bound_m} m; nothing was written; please report this with the heightmap"
    )]
    BoundBroken { source_label: String, measured_m: f64, bound_m: f64, i: u32, j: u32 },
}

/// The build's for a failure while building or writing; the input's otherwise (bad input or usage).
impl crate::failure::Failure for JobError {
    fn blame(&self) -> crate::failure::Blame {
        match self {
            JobError::Export(e) => crate::failure::Failure::blame(e),
            JobError::Texture(_) | JobError::BoundBroken { .. } => crate::failure::Blame::Build,
            _ => crate::failure::Blame::Input,
        }
    }
}

#[derive(Debug, Clone, Serialize, Default)]
pub struct Seconds {
    pub decode: f64,
    pub mesh: f64,
    pub analyze: f64,
    pub build: f64,
    pub export: f64,
    pub total: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct OutputSummary {
    pub files: Vec<String>,
    pub meshes: usize,
    pub vertices: usize,
    pub triangles: usize,
    pub bounds: Option<Bounds>,
}

/// What the terrain stage measured of its main mesh: one schema, flattened into both
/// `verdant terrain --report` and the scene's `stages.terrain` (report.json, the cache).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TerrainFigures {
    pub width: usize,
    pub height: usize,
    /// Metres between samples.
    pub cell_size_m: f64,
    pub voids_filled: usize,
    pub mode: MeshMode,
    /// Requested bound in metres (TIN mode).
    pub max_error_requested: Option<f64>,
    pub max_triangles: Option<usize>,
    pub hit_triangle_limit: bool,
    /// Largest vertical error over every sample, measured by the analyzer on the vertices as the
    /// file stores them (f32, or the 16-bit grid) against the map's heights as its encoding
    /// defines them (metres): the figure the bound applies to.
    pub max_error: f64,
    /// The same with the vertices exactly at their samples (f64), before the file's rounding.
    pub max_error_f64: f64,
    pub worst_sample: [u32; 2],
    pub rms_error: f64,
    /// Terrain surface triangulation (before skirts and base).
    pub vertices: usize,
    pub triangles: usize,
    /// Triangles of the full grid (2·(w−1)·(h−1)), for the reduction ratio.
    pub full_grid_triangles: usize,
    /// The material layers baked into the terrain's base-colour texture (terrain/layers.rs).
    pub layers: LayerReport,
    /// The normal map baked against this mesh and the shading error it removes
    /// (terrain/normal_map.rs).
    pub normal_map: NormalMapReport,
}

/// What `--report` writes: the analyzer's figures, the input and the files, and the time each
/// step took.
#[derive(Debug, Clone, Serialize)]
pub struct TerrainReport {
    pub input: String,
    pub encoding: Encoding,
    pub grid_step: Option<usize>,
    #[serde(flatten)]
    pub figures: TerrainFigures,
    pub output: Option<OutputSummary>,
    pub seconds: Seconds,
}

/// The heights of a job's source, decoded.
pub fn load_source(job: &TerrainJob) -> Result<Decoded, JobError> {
    Ok(match &job.source {
        Source::File(path) => heightfield::load(path, &job.decode)?,
        Source::Demo => {
            let mut hf = crate::synth::demo();
            if job.decode.cell_size_m != DecodeOptions::default().cell_size_m {
                hf.cell_size_m = job.decode.cell_size_m;
            }
            Decoded { heightfield: hf, encoding: Encoding::Float, voids_filled: 0 }
        }
    })
}

/// Meshes `hf` as `settings` ask, at `max_error_m` (a grid of every `grid_step` samples, or a TIN
/// within the bound, stopping at `max_triangles`), within the vertex budget. Returns the mesh and
/// whether the triangle limit stopped it.
pub fn mesh_samples(
    hf: &Heightfield,
    settings: &MeshSettings,
    max_error_m: f64,
    storage: &Storage,
) -> Result<(SampleMesh, bool), TerrainError> {
    match settings.mode {
        MeshMode::Grid => {
            crate::terrain::budget::check_grid(hf.width, hf.height, settings.grid_step, settings.max_vertices)
                .map_err(|over| TerrainError::OverBudget {
                    limit: settings.max_vertices,
                    over,
                    max_error_m,
                    grid: true,
                })?;
            Ok((grid(hf, settings.grid_step)?, false))
        }
        MeshMode::Tin => {
            let opts = TinOptions {
                max_error_m,
                max_triangles: settings.max_triangles,
                max_vertices: settings.max_vertices,
                chunk_cells: settings.chunk_cells,
            };
            let r = tin_stored(hf, &opts, storage)?;
            Ok((r.mesh, r.hit_triangle_limit))
        }
    }
}

/// Meshes `hf` as the job asks, at `max_error_m`.
pub fn mesh_heightfield(
    job: &TerrainJob,
    hf: &Heightfield,
    max_error_m: f64,
    storage: &Storage,
) -> Result<(SampleMesh, bool), JobError> {
    mesh_samples(hf, &job.mesh_settings(), max_error_m, storage)
        .map_err(|error| JobError::Terrain { source_label: job.source.label(), error })
}

fn check_options(job: &TerrainJob) -> Result<(), JobError> {
    if job.mode == MeshMode::Tin && !(job.max_error_m.is_finite() && job.max_error_m >= 0.0) {
        return Err(JobError::Options(format!(
            "--max-error must be a finite number of metres ≥ 0, got {}",
            job.max_error_m
        )));
    }
    if job.mode == MeshMode::Grid && job.grid_step == 0 {
        return Err(JobError::Options("--grid-step must be at least 1 sample".into()));
    }
    if job.max_triangles == Some(0) {
        return Err(JobError::Options("--max-triangles must be at least 2 (the two corner triangles)".into()));
    }
    Ok(())
}

/// The 16-bit grid of a quantized terrain: x and z by the cell, y from the lowest point written
/// (the base's bottom or the skirts' below the lowest sample) to the highest sample.
fn position_grid(job: &TerrainJob, hf: &Heightfield) -> Result<PositionGrid, JobError> {
    let lowest = hf.height_range().map_or(0.0, |r| r.0);
    let depth = job.build.base_depth_m.or(job.build.skirt_depth_m);
    let bottom = match depth {
        Some(d) => crate::terrain::solid::lowered(lowest, d).unwrap_or(lowest),
        None => lowest,
    };
    PositionGrid::terrain(hf, bottom).ok_or_else(|| {
        JobError::Options(format!(
            "--quantize stores x and z as 16-bit sample numbers, but the map is {}×{} samples (at most 65536 a side); leave --quantize out",
            hf.width, hf.height
        ))
    })
}

/// How the job's file stores the vertices (f32, or the 16-bit grid with `quantize`): the bound
/// holds for that.
fn storage_for(job: &TerrainJob, hf: &Heightfield) -> Result<(Option<PositionGrid>, Storage), JobError> {
    let grid = if job.quantize { Some(position_grid(job, hf)?) } else { None };
    Ok((grid, grid.map_or_else(|| Storage::f32(hf), |g| Storage::quantized(hf, g))))
}

/// How a heightfield is meshed: what the CLI job and the scene's terrain stage both ask for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshSettings {
    pub mode: MeshMode,
    pub grid_step: usize,
    pub max_error_m: f64,
    pub max_triangles: Option<usize>,
    pub max_vertices: usize,
    /// Cells a side of the terrain's chunks the map is cut along ([`TinOptions::chunk_cells`]; 0:
    /// not chunked).
    pub chunk_cells: u32,
}

/// A terrain meshed, measured as stored and built into its textured scene.
pub struct Meshed {
    pub mesh: SampleMesh,
    pub hit_triangle_limit: bool,
    /// Measured on the vertices as stored against the map's heights (what the bound applies to).
    pub stats: ErrorStats,
    /// The same with the vertices exactly at their samples (f64).
    pub max_error_f64_m: f64,
    pub scene: Scene,
    /// The material layers (the scene's base colour; LoD levels are textured with the same).
    pub layers: TerrainLayers,
    /// What the normal map baked against this mesh corrects.
    pub normal_map: NormalMapReport,
    /// Seconds meshing, measuring, building (0 for a mesh given ready).
    pub seconds: [f64; 3],
}

/// What grows on a built terrain scene, when anything does (the soil layer and `_SURFACE`).
pub type CoverOf<'a> = dyn Fn(&Scene) -> Option<VegetationCover> + 'a;

/// Where [`mesh_and_build`] takes the terrain's material layers from.
pub enum LayersFrom<'a> {
    /// Baked over the whole map, with what the function gives grows on the built scene
    /// ([`bake_layers_with`]).
    Bake(Option<&'a CoverOf<'a>>),
    /// Baked already (a terrain meshed in bands: each band baked its rows).
    Baked(Box<TerrainLayers>),
    /// Baked already, and the scene built with their vertex attributes (a terrain meshed in bands
    /// whose chunks the bands built: [`crate::terrain::build::assemble_chunks`]); only the base
    /// colour and normal map are put on it.
    Assembled(Box<TerrainLayers>, Box<Scene>),
}

/// The one path from samples to a textured terrain scene: meshes `hf` as `settings` ask (or takes
/// `ready`, a mesh already made at the same settings with its stats, e.g. a LoD level, and its f64
/// error when that is known, e.g. from a banded terrain's units), measures it
/// as `storage` stores it, refuses a TIN over its bound as written (the analyzer has the last
/// word), builds the scene (`build`: chunks, skirts, base, name), textures it with the layers and bakes
/// its normal map against it. `layers` says where the material layers come from.
pub fn mesh_and_build(
    hf: &Heightfield,
    settings: &MeshSettings,
    storage: &Storage,
    build: &BuildOptions,
    label: &str,
    ready: Option<(SampleMesh, bool, ErrorStats, Option<f64>)>,
    layers: LayersFrom<'_>,
    normal_rows: Option<crate::terrain::normal_map::TexelRows>,
) -> Result<Meshed, JobError> {
    let (mut t_mesh, mut t_analyze) = (0.0, 0.0);
    let (mesh, hit_limit, stats, known_f64_m) = match ready {
        Some(ready) => ready,
        None => {
            let t = Instant::now();
            let (mesh, hit) = mesh_samples(hf, settings, settings.max_error_m, storage)
                .map_err(|error| JobError::Terrain { source_label: label.to_string(), error })?;
            t_mesh = t.elapsed().as_secs_f64();
            let t = Instant::now();
            let stats = measure_stored(hf, &mesh, storage);
            t_analyze = t.elapsed().as_secs_f64();
            (mesh, hit, stats, None)
        }
    };
    check_bound(settings, label, hit_limit, &stats)?;
    let t = Instant::now();
    let (mut scene, layers) = match layers {
        LayersFrom::Assembled(layers, scene) => {
            let mut scene = *scene;
            layers.put_base_color(&mut scene, &build.name).map_err(JobError::Texture)?;
            (scene, *layers)
        }
        LayersFrom::Baked(layers) => {
            let mut scene = build_scene(hf, &mesh, build)?;
            layers.texture(&mut scene, hf, &build.name).map_err(JobError::Texture)?;
            (scene, *layers)
        }
        LayersFrom::Bake(cover) => {
            let mut scene = build_scene(hf, &mesh, build)?;
            let layers = bake_layers_with(hf, &build.snow, cover.and_then(|f| f(&scene)).map(std::sync::Arc::new));
            layers.texture(&mut scene, hf, &build.name).map_err(JobError::Texture)?;
            (scene, layers)
        }
    };
    // (the normal map's rows baked already when the terrain's bands baked them)
    let normal_map = match normal_rows {
        Some(rows) => put_normal_map(&mut scene, &build.name, layers.report.map_px, rows),
        None => bake_normal_map(hf, &mut scene, &build.name, layers.report.map_px),
    }
    .map_err(JobError::Texture)?;
    let t_build = t.elapsed().as_secs_f64();
    let max_error_f64_m = known_f64_m.unwrap_or_else(|| exact_max_error(hf, &mesh, &stats, storage));
    Ok(Meshed {
        mesh,
        hit_triangle_limit: hit_limit,
        stats,
        max_error_f64_m,
        scene,
        layers,
        normal_map,
        seconds: [t_mesh, t_analyze, t_build],
    })
}

/// A TIN over its bound as written (and not held back by a triangle limit) is refused.
fn check_bound(settings: &MeshSettings, label: &str, hit_limit: bool, stats: &ErrorStats) -> Result<(), JobError> {
    if settings.mode == MeshMode::Tin && !hit_limit && stats.max_error_m > settings.max_error_m {
        let [i, j] = stats.worst_sample;
        return Err(JobError::BoundBroken {
            source_label: label.to_string(),
            measured_m: stats.max_error_m,
            bound_m: settings.max_error_m,
            i,
            j,
        });
    }
    Ok(())
}

/// [`mesh_and_build`] of a mesh made already (`ready`) whose scene was assembled with its vertex
/// attributes (a terrain meshed in bands whose chunks the bands built), its f64 error known (the
/// error as stored on a map whose storage is exact, [`Storage::is_exact`]; else the bands'
/// units measured it): the base colour and the normal map (its rows joined from the bands') put
/// on it, the map never read.
pub fn finish_assembled(
    settings: &MeshSettings,
    label: &str,
    name: &str,
    (mesh, hit_limit, stats): (SampleMesh, bool, ErrorStats),
    max_error_f64_m: f64,
    layers: TerrainLayers,
    mut scene: Scene,
    normal_rows: crate::terrain::normal_map::TexelRows,
) -> Result<Meshed, JobError> {
    check_bound(settings, label, hit_limit, &stats)?;
    let t = Instant::now();
    layers.put_base_color(&mut scene, name).map_err(JobError::Texture)?;
    let normal_map = put_normal_map(&mut scene, name, layers.report.map_px, normal_rows).map_err(JobError::Texture)?;
    Ok(Meshed {
        mesh,
        hit_triangle_limit: hit_limit,
        stats,
        max_error_f64_m,
        scene,
        layers,
        normal_map,
        seconds: [0.0, 0.0, t.elapsed().as_secs_f64()],
    })
}

impl Meshed {
    /// The figures of this mesh of `hf` (`voids_filled` from the decoding).
    pub fn figures(&self, hf: &Heightfield, settings: &MeshSettings, voids_filled: usize) -> TerrainFigures {
        self.figures_of([hf.width, hf.height], hf.cell_size_m, settings, voids_filled)
    }

    /// [`Meshed::figures`] of a map of `size` samples `cell_size_m` apart.
    pub fn figures_of(
        &self,
        [width, height]: [usize; 2],
        cell_size_m: f64,
        settings: &MeshSettings,
        voids_filled: usize,
    ) -> TerrainFigures {
        TerrainFigures {
            width,
            height,
            cell_size_m,
            voids_filled,
            mode: settings.mode,
            max_error_requested: (settings.mode == MeshMode::Tin).then_some(settings.max_error_m),
            max_triangles: settings.max_triangles,
            hit_triangle_limit: self.hit_triangle_limit,
            max_error: self.stats.max_error_m,
            max_error_f64: self.max_error_f64_m,
            worst_sample: self.stats.worst_sample,
            rms_error: self.stats.rms_error_m,
            vertices: self.mesh.vertices.len(),
            triangles: self.mesh.triangles.len(),
            full_grid_triangles: 2 * width.saturating_sub(1) * height.saturating_sub(1),
            layers: self.layers.report.clone(),
            normal_map: self.normal_map.clone(),
        }
    }
}

impl TerrainJob {
    pub fn mesh_settings(&self) -> MeshSettings {
        MeshSettings {
            mode: self.mode,
            grid_step: self.grid_step,
            max_error_m: self.max_error_m,
            max_triangles: self.max_triangles,
            max_vertices: self.max_vertices,
            chunk_cells: crate::terrain::regions::chunk_cells(self.build.chunk_samples),
        }
    }
}

/// Runs the job; writes the scene to `output` when given.
pub fn run(job: &TerrainJob, output: Option<&Path>) -> Result<(TerrainReport, Scene), JobError> {
    run_reporting(job, output, None)
}

/// [`run`], and the report as JSON to `report` when given: the scene's files and the report are
/// replaced as one set ([`export::FileSet`]), so a report never describes a mesh that was not
/// written, nor a mesh lacks the report asked for.
pub fn run_reporting(
    job: &TerrainJob,
    output: Option<&Path>,
    report_path: Option<&Path>,
) -> Result<(TerrainReport, Scene), JobError> {
    check_options(job)?;
    let t0 = Instant::now();
    let decoded = load_source(job)?;
    let hf = &decoded.heightfield;
    let t_decode = t0.elapsed().as_secs_f64();

    let (grid, storage) = storage_for(job, hf)?;
    let settings = job.mesh_settings();
    let meshed =
        mesh_and_build(hf, &settings, &storage, &job.build, &job.source.label(), None, LayersFrom::Bake(None), None)?;
    let figures = meshed.figures(hf, &settings, decoded.voids_filled);
    let ([t_mesh, t_analyze, t_build], scene) = (meshed.seconds, meshed.scene);

    let t = Instant::now();
    let mut set = export::FileSet::new();
    let output_summary = match output {
        Some(path) => {
            let files = export::stage_scene_with(
                &mut set,
                &scene,
                path,
                &WriteOptions {
                    quantization: grid.map_or(Quantization::Off, Quantization::Grid),
                    meshopt: job.meshopt && grid.is_some(),
                    ..WriteOptions::default()
                },
            )?;
            Some(summarize(&scene, files.iter().map(|f| f.display().to_string()).collect()))
        }
        None => None,
    };
    let t_export = t.elapsed().as_secs_f64();

    let report = TerrainReport {
        input: job.source.label(),
        encoding: decoded.encoding,
        grid_step: (job.mode == MeshMode::Grid).then_some(job.grid_step),
        figures,
        output: output_summary,
        seconds: Seconds {
            decode: t_decode,
            mesh: t_mesh,
            analyze: t_analyze,
            build: t_build,
            export: t_export,
            total: t0.elapsed().as_secs_f64(),
        },
    };
    if let Some(path) = report_path {
        set.write(path, &json_bytes(&report)?)?;
    }
    set.commit()?;
    Ok((report, scene))
}

/// Counts and bounds of everything in `scene` (all primitives, in world space for terrain, whose
/// nodes carry no transform).
pub fn summarize(scene: &Scene, files: Vec<String>) -> OutputSummary {
    let mut bounds: Option<Bounds> = None;
    let (mut vertices, mut triangles) = (0, 0);
    for m in &scene.meshes {
        for p in &m.primitives {
            vertices += p.positions.len();
            triangles += p.triangle_count();
            if let Some(b) = p.bounds() {
                bounds = Some(match bounds {
                    None => b,
                    Some(a) => Bounds::of(&[a.min, a.max, b.min, b.max]).unwrap_or(a),
                });
            }
        }
    }
    OutputSummary { files, meshes: scene.meshes.len(), vertices, triangles, bounds }
}

/// One row of the speed/error curve.
#[derive(Debug, Clone, Serialize)]
pub struct SweepRow {
    pub max_error_requested: f64,
    pub triangles: usize,
    pub vertices: usize,
    pub max_error: f64,
    pub rms_error: f64,
    pub hit_triangle_limit: bool,
    pub seconds: f64,
}

/// Meshes the job's source at each threshold: the speed/error curve of that input.
pub fn sweep(job: &TerrainJob, thresholds_m: &[f64]) -> Result<(Decoded, Vec<SweepRow>), JobError> {
    check_options(job)?;
    if let Some(bad) = thresholds_m.iter().find(|t| !(t.is_finite() && **t >= 0.0)) {
        return Err(JobError::Options(format!("--sweep thresholds must be finite metres ≥ 0, got {bad}")));
    }
    let decoded = load_source(job)?;
    let hf = &decoded.heightfield;
    let (_, storage) = storage_for(job, hf)?;
    let mut rows = Vec::with_capacity(thresholds_m.len());
    for &max_error_m in thresholds_m {
        let t = Instant::now();
        let (mesh, hit_triangle_limit) = mesh_heightfield(job, hf, max_error_m, &storage)?;
        let seconds = t.elapsed().as_secs_f64();
        let stats = measure_stored(hf, &mesh, &storage);
        rows.push(SweepRow {
            max_error_requested: max_error_m,
            triangles: mesh.triangles.len(),
            vertices: mesh.vertices.len(),
            max_error: stats.max_error_m,
            rms_error: stats.rms_error_m,
            hit_triangle_limit,
            seconds,
        });
    }
    Ok((decoded, rows))
}

/// The sweep as a fixed-width table.
pub fn sweep_table(rows: &[SweepRow]) -> String {
    let mut s = format!(
        "{:>12} {:>12} {:>12} {:>14} {:>12} {:>10}\n",
        "max_error_m", "triangles", "vertices", "measured_max_m", "rms_m", "seconds"
    );
    for r in rows {
        s += &format!(
            "{:>12} {:>12} {:>12} {:>14.4} {:>12.4} {:>10.3}{}\n",
            r.max_error_requested,
            r.triangles,
            r.vertices,
            r.max_error,
            r.rms_error,
            r.seconds,
            if r.hit_triangle_limit { "  (triangle limit reached)" } else { "" }
        );
    }
    s
}

/// Writes `value` as pretty JSON, atomically.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), JobError> {
    export::write_atomic(path, &json_bytes(value)?)?;
    Ok(())
}

/// `value` as pretty JSON with a final newline.
fn json_bytes<T: Serialize>(value: &T) -> Result<Vec<u8>, JobError> {
    let mut text = serde_json::to_string_pretty(value).map_err(|e| JobError::Options(e.to_string()))?;
    text.push('\n');
    Ok(text.into_bytes())
}
