//! The `verdant tree --lods N` and `verdant mesh` jobs: read the input, build each chain in memory,
//! write and validate every file, report.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use super::chain::{build_mesh_lods_with, build_tree_lods_with};
use super::types::{Progress, TreeLodError, TreeLodOptions, TreeLodReport, TreeLods};
use crate::bake::image::Image;
use crate::export::{self, FileSet, SceneProblem};
use crate::lsystem::{parse, Dialect};
use crate::mesh::Scene;
use crate::plants::mesh_asset::{load_obj, MeshAssetStats, ObjOptions};
use crate::plants::tree::{TreeError, TreeOptions, TreeReport, TreeSeconds};
use crate::random::mix64;
use crate::validate::{validate_file, ValidateOptions};

/// One `verdant tree` run with a LoD chain: read, build each variant's chain, write, validate.
#[derive(Debug, Clone)]
pub struct TreeLodJob {
    pub input: PathBuf,
    /// `<dir>/<stem>.glb`: the chain; `<stem>_LOD<n>.glb` and `<stem>_atlas*.png` beside it
    /// (`<stem>_v<k>…` for variant k when there are several).
    pub output: PathBuf,
    pub dialect: Option<Dialect>,
    pub options: TreeOptions,
    pub lod: TreeLodOptions,
    /// Trees from seeds derived from `options.seed` (variant 0 uses the seed itself).
    pub variants: usize,
}

/// What `verdant tree --report` writes with a LoD chain: the LoD0 figures of variant 0 as
/// without one, then every variant's chain.
#[derive(Debug, Clone, Serialize)]
pub struct TreeLodRunReport {
    #[serde(flatten)]
    pub tree: TreeReport,
    pub variants: Vec<TreeLodReport>,
}

/// The seed of variant `k` (0: the seed itself).
pub fn variant_seed(seed: u64, k: usize) -> u64 {
    if k == 0 {
        seed
    } else {
        mix64(seed ^ mix64(k as u64))
    }
}

/// Validates the staged glb meant for `path`: (errors, warnings) found, or why it is invalid.
fn validate_staged(staged: &Path, path: &Path) -> Result<(usize, usize), TreeLodError> {
    let v = validate_file(staged, &ValidateOptions::default())
        .map_err(|e| TreeLodError::Invalid { path: path.to_path_buf(), report: e.to_string() })?;
    if !v.ok() {
        return Err(TreeLodError::Invalid { path: path.to_path_buf(), report: v.to_string() });
    }
    Ok((v.errors(), v.warnings()))
}

/// The files one run wrote and what validating them found.
#[derive(Debug, Default)]
struct Written {
    files: Vec<PathBuf>,
    errors: usize,
    warnings: usize,
}

impl Written {
    /// A glb written and what validating it found.
    fn add(&mut self, path: &Path, (errors, warnings): (usize, usize)) {
        self.files.push(path.to_path_buf());
        self.errors += errors;
        self.warnings += warnings;
    }
}

/// Writes `chain` as `<dir>/<file_stem>_LOD<n>.glb`, `<file_stem>_atlas*.png` and the MSFT_lod
/// `<file_stem>.glb` into `set`, validating every glb before anything is replaced. The files are
/// encoded and validated in parallel; they are listed (and the first failure reported) in that
/// order.
fn write_chain(
    chain: &TreeLods,
    dir: &Path,
    file_stem: &str,
    set: &mut FileSet,
    written: &mut Written,
    store: &export::gltf::WriteOptions,
) -> Result<(), TreeLodError> {
    let texture = |e: &dyn std::fmt::Display| TreeLodError::Texture(e.to_string());
    let mut scenes: Vec<(&Scene, PathBuf)> =
        chain.levels.iter().map(|lod| (&lod.scene, dir.join(format!("{file_stem}_LOD{}.glb", lod.level)))).collect();
    scenes.push((&chain.chain, dir.join(format!("{file_stem}.glb"))));
    let glbs: Vec<Result<Vec<u8>, TreeLodError>> = scenes
        .par_iter()
        .map(|(scene, path)| Ok(export::gltf::to_glb_with(scene, store).map_err(SceneProblem::at(path))?))
        .collect();
    let mut images: Vec<(PathBuf, &Image, bool)> = chain
        .atlas
        .iter()
        .enumerate()
        .map(|(k, level)| {
            let name = if k == 0 { format!("{file_stem}_atlas.png") } else { format!("{file_stem}_atlas_mip{k}.png") };
            (dir.join(name), &level.image, false)
        })
        .collect();
    if let Some(normals) = &chain.normal_atlas {
        images.push((dir.join(format!("{file_stem}_atlas_normal.png")), normals, true));
    }
    // colour as sRGB, the normal atlas as data (glTF reads a normalTexture as linear values)
    let pngs: Vec<Result<Vec<u8>, TreeLodError>> = images
        .par_iter()
        .map(|(_, image, data)| {
            if *data { image.encode_png_data() } else { image.encode_png() }.map_err(|e| texture(&e))
        })
        .collect();
    // staged in the order listed: the levels, the atlas images, the chain
    let levels = chain.levels.len();
    let mut glbs = scenes.iter().zip(glbs);
    for ((_, path), bytes) in glbs.by_ref().take(levels) {
        set.write(path, &bytes?)?;
    }
    for ((path, _, _), bytes) in images.iter().zip(pngs) {
        set.write(path, &bytes?)?;
    }
    for ((_, path), bytes) in glbs {
        set.write(path, &bytes?)?;
    }
    let checked: Vec<Result<(usize, usize), TreeLodError>> =
        scenes.par_iter().map(|(_, path)| validate_staged(set.staged(path).unwrap_or(path), path)).collect();
    let mut checked = scenes.iter().zip(checked);
    for ((_, path), found) in checked.by_ref().take(levels) {
        written.add(path, found?);
    }
    written.files.extend(images.into_iter().map(|(p, _, _)| p));
    for ((_, path), found) in checked {
        written.add(path, found?);
    }
    Ok(())
}

/// A chain's output must be a .glb (it holds MSFT_lod).
fn check_glb_output(output: &Path) -> Result<(), TreeLodError> {
    let ext = output.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext != "glb" {
        return Err(TreeLodError::Options(format!(
            "{}: a LoD chain is written as .glb (MSFT_lod); use a .glb output or --lods 1",
            output.display()
        )));
    }
    Ok(())
}

/// Runs `job`: every file is built in memory before the first is written.
pub fn run_lods(job: &TreeLodJob) -> Result<TreeLodRunReport, TreeLodError> {
    run_lods_with(job, &|_| {})
}

/// [`run_lods`], saying each step to `progress` as it starts (with the variant when several).
pub fn run_lods_with(job: &TreeLodJob, progress: Progress) -> Result<TreeLodRunReport, TreeLodError> {
    run_lods_reporting(job, None, progress)
}

/// [`run_lods_with`], and the report as JSON to `report` when given, replaced with the chain's
/// files as one set: a report never lists files that were not written.
pub fn run_lods_reporting(
    job: &TreeLodJob,
    report: Option<&Path>,
    progress: Progress,
) -> Result<TreeLodRunReport, TreeLodError> {
    let t0 = Instant::now();
    check_glb_output(&job.output)?;
    if !(1..=64).contains(&job.variants) {
        return Err(TreeLodError::Options(format!("--variants {} is out of range; use 1 to 64", job.variants)));
    }
    job.lod.check()?;
    let parsed = parse::read_file(&job.input, job.dialect).map_err(|e| TreeLodError::Tree(TreeError::Parse(e)))?;
    let t_parse = t0.elapsed().as_secs_f64();
    let stem = job.output.file_stem().and_then(|s| s.to_str()).unwrap_or("tree").to_string();
    let dir = job.output.parent().map(Path::to_path_buf).unwrap_or_default();
    // names inside the files come from the tree's name, file names from the output's stem, so the
    // same tree written under two names has the same bytes
    let suffix = |k: usize| if job.variants == 1 { String::new() } else { format!("_v{k}") };
    let mut chains = Vec::with_capacity(job.variants);
    for k in 0..job.variants {
        let options = TreeOptions {
            seed: variant_seed(job.options.seed, k),
            name: format!("{}{}", job.options.name, suffix(k)),
            ..job.options.clone()
        };
        let say = |step: &str| match job.variants {
            1 => progress(step),
            n => progress(&format!("variant {}/{n}: {step}", k + 1)),
        };
        let chain = build_tree_lods_with(&parsed.system, &options, &job.lod, &say).map_err(|e| match e {
            TreeLodError::Tree(t) => {
                TreeLodError::Tree(TreeError::InFile { path: job.input.clone(), source: Box::new(t) })
            }
            e => e,
        })?;
        chains.push(chain);
    }
    let t_build = t0.elapsed().as_secs_f64();
    // every variant's files replaced as one set, after all of them are written and validated
    let (mut written, mut set) = (Written::default(), FileSet::new());
    for (k, c) in chains.iter().enumerate() {
        write_chain(
            c,
            &dir,
            &format!("{stem}{}", suffix(k)),
            &mut set,
            &mut written,
            &job.lod.compact.write_options(),
        )?;
    }
    let Written { files, errors, warnings } = written;
    let t_total = t0.elapsed().as_secs_f64();
    let first = &chains[0];
    let tree = TreeReport {
        input: job.input.display().to_string(),
        output: job.output.display().to_string(),
        files: files.iter().map(|f| f.display().to_string()).collect(),
        dialect: parsed.system.dialect,
        dialect_detected: parsed.detected,
        seed: job.options.seed,
        radial_segments: job.options.radial_segments,
        stats: first.lod0.as_ref().map(|t| t.stats.clone()).unwrap_or_default(),
        warnings: parsed
            .warnings
            .into_iter()
            .chain(first.lod0.as_ref().and_then(|t| crate::plants::tree::size_warning(&t.stats, &job.options)))
            .collect(),
        validation_errors: errors,
        validation_warnings: warnings,
        seconds: TreeSeconds {
            parse: t_parse,
            build: first.report.seconds_meshes,
            export: t_total - t_build,
            to_lod0: t_parse + first.report.seconds_meshes,
            validate: 0.0,
            total: t_total,
        },
    };
    let run = TreeLodRunReport { tree, variants: chains.into_iter().map(|c| c.report).collect() };
    if let Some(path) = report {
        set.write(path, &json_bytes(&run)?)?;
    }
    set.commit()?;
    Ok(run)
}

// ---------------------------------------------------------------------------------------------
// the `verdant mesh` job

/// One `verdant mesh` run: load an OBJ, build its chain, write and validate as `verdant tree` does.
#[derive(Debug, Clone)]
pub struct MeshLodJob {
    pub input: PathBuf,
    /// `<dir>/<stem>.glb`: the chain; `<stem>_LOD<n>.glb` and `<stem>_atlas*.png` beside it.
    pub output: PathBuf,
    pub obj: ObjOptions,
    pub lod: TreeLodOptions,
}

/// What `verdant mesh --report` writes.
#[derive(Debug, Clone, Serialize)]
pub struct MeshLodRunReport {
    pub input: String,
    pub output: String,
    pub files: Vec<String>,
    pub source: MeshAssetStats,
    pub validation_errors: usize,
    pub validation_warnings: usize,
    pub seconds_load: f64,
    pub seconds_total: f64,
    pub chain: TreeLodReport,
}

/// Runs `job`: every file is built in memory before the first is written. The names inside the
/// files come from the input's stem, the file names from the output's.
pub fn run_mesh_lods(job: &MeshLodJob) -> Result<MeshLodRunReport, TreeLodError> {
    run_mesh_lods_with(job, &|_| {})
}

/// [`run_mesh_lods`], saying each step to `progress` as it starts.
pub fn run_mesh_lods_with(job: &MeshLodJob, progress: Progress) -> Result<MeshLodRunReport, TreeLodError> {
    run_mesh_lods_reporting(job, None, progress)
}

/// [`run_mesh_lods_with`], and the report as JSON to `report` when given, replaced with the
/// chain's files as one set.
pub fn run_mesh_lods_reporting(
    job: &MeshLodJob,
    report: Option<&Path>,
    progress: Progress,
) -> Result<MeshLodRunReport, TreeLodError> {
    let t0 = Instant::now();
    check_glb_output(&job.output)?;
    job.lod.check()?;
    let source = load_obj(&job.input, &job.obj)?;
    let seconds_load = t0.elapsed().as_secs_f64();
    let name = job.input.file_stem().and_then(|s| s.to_str()).unwrap_or("mesh").to_string();
    let chain = build_mesh_lods_with(&source, &name, &job.lod, progress)?;
    let stem = job.output.file_stem().and_then(|s| s.to_str()).unwrap_or("mesh").to_string();
    let dir = job.output.parent().map(Path::to_path_buf).unwrap_or_default();
    let (mut written, mut set) = (Written::default(), FileSet::new());
    write_chain(&chain, &dir, &stem, &mut set, &mut written, &job.lod.compact.write_options())?;
    let run = MeshLodRunReport {
        input: job.input.display().to_string(),
        output: job.output.display().to_string(),
        files: written.files.iter().map(|f| f.display().to_string()).collect(),
        source: source.stats,
        validation_errors: written.errors,
        validation_warnings: written.warnings,
        seconds_load,
        seconds_total: t0.elapsed().as_secs_f64(),
        chain: chain.report,
    };
    if let Some(path) = report {
        set.write(path, &json_bytes(&run)?)?;
    }
    set.commit()?;
    Ok(run)
}

/// `report` as pretty JSON with a final newline.
fn json_bytes<T: Serialize>(report: &T) -> Result<Vec<u8>, TreeLodError> {
    let mut text = serde_json::to_string_pretty(report)
        .map_err(|e| TreeLodError::Options(format!("cannot serialise the report: {e}")))?;
    text.push('\n');
    Ok(text.into_bytes())
}
