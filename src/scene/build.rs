//! Building scenes from presets: each scene is built stage by stage into a temporary folder beside
//! its destination and renamed into place only when every stage succeeded, so a failed build
//! leaves the previous `out/<scene>/` untouched. Several presets build in parallel (`--jobs`);
//! one failing does not stop the others.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use crate::failure::{Blame, Failure};
pub use crate::progress::ProgressView;
use crate::scene::cache::{process_alive, temp_owner, Cache};
use crate::scene::error::SceneBuildError;
use crate::scene::manifest::{write_manifest_and_report, StageRun};
use crate::scene::pipeline::{CacheUse, Stage, StageRunner, TerrainHandoff};
use crate::scene::plants_stage::{self, PlantsJob, PlantsStageReport};
use crate::scene::preset::load_preset;
use crate::scene::preview::{footprint_m, PreviewLayer};
use crate::scene::preview_stage::{PreviewJob, PreviewPlacements};
use crate::scene::scatter_stage::{Placed, ScatterJob};
use crate::scene::shard::{self, Shard};
use crate::scene::snow_stage::{self, SnowJob};
use crate::scene::terrain_stage::{LodInfo, TerrainJob};
use crate::scene::view_stage::{TerrainInput, ViewJob, ViewStageReport};
use crate::scene::Preset;
use crate::snow::CoverMask;

/// How to build: where, which stages, whether to ignore the cache.
#[derive(Debug, Clone)]
pub struct BuildSettings {
    pub out_dir: PathBuf,
    pub stages: Vec<Stage>,
    pub force: bool,
    /// Render each scene's first view with LoD and at full detail and report how the images differ
    /// (`--compare-full-detail`; full detail can be billions of triangles, so it is asked for).
    pub compare_full_detail: bool,
    /// Build only this shard's units into `out_dir`'s cache (`--shard i/N`; [`crate::scene::shard`]).
    pub shard: Option<Shard>,
    /// A merge's build: the scatter stage takes the placements the shards made by rows from the
    /// cache ([`crate::scene::placement_rows`]; set by [`merge_batch`]).
    pub merging: bool,
    /// A shard's second round (`--tiles --shards DIR...`): every first-round shard folder; the shard
    /// then makes the scene tiles of its share ([`crate::scene::tile_units`]). Empty: the first.
    pub tiles_from: Vec<PathBuf>,
    /// A merge's scenes whose shards made scene tiles (their view stage puts them in place).
    pub tile_scenes: Vec<String>,
}

impl Default for BuildSettings {
    fn default() -> Self {
        BuildSettings {
            out_dir: PathBuf::from("out"),
            stages: Stage::ALL.to_vec(),
            force: false,
            compare_full_detail: false,
            shard: None,
            merging: false,
            tiles_from: Vec::new(),
            tile_scenes: Vec::new(),
        }
    }
}

/// Whose fault a batch's failure is: the build's when one build failed, else the input's when an
/// input was bad, else `None` (every scene built).
pub fn batch_blame(outcomes: &[SceneOutcome]) -> Option<Blame> {
    let blames = || outcomes.iter().filter_map(|o| o.blame);
    if blames().any(|b| b == Blame::Build) {
        Some(Blame::Build)
    } else {
        blames().next()
    }
}

fn io_err(path: &Path) -> impl Fn(std::io::Error) -> SceneBuildError + '_ {
    move |e| SceneBuildError::Io { path: path.to_owned(), message: e.to_string() }
}

/// The outcome of one scene, a row of the summary table.
#[derive(Debug, Clone, Serialize)]
pub struct SceneOutcome {
    /// The preset file, or "(embedded demo)".
    pub preset: String,
    pub scene: String,
    /// `None` when the scene was built; the error message otherwise.
    pub error: Option<String>,
    /// `None` when built; else whose fault the failure is (bad input or usage, or the build itself).
    #[serde(skip)]
    pub blame: Option<Blame>,
    pub dir: Option<PathBuf>,
    pub files: usize,
    pub triangles: usize,
    pub cached_stages: Vec<Stage>,
    pub seconds: f64,
    /// What the inputs' readers repaired (L-system files: [`crate::scene::preset::lsystem_warnings`]),
    /// for the caller to show; report.md lists them too.
    pub warnings: Vec<String>,
}

impl SceneOutcome {
    /// A scene that failed with `e` after `seconds`.
    fn failed(preset: String, scene: String, e: &SceneBuildError, seconds: f64) -> SceneOutcome {
        SceneOutcome {
            preset,
            scene,
            error: Some(e.to_string()),
            blame: Some(e.blame()),
            dir: None,
            files: 0,
            triangles: 0,
            cached_stages: Vec::new(),
            seconds,
            warnings: Vec::new(),
        }
    }
}

/// Reports progress lines: (scene, message).
pub type Progress<'a> = &'a (dyn Fn(&str, &str) + Sync);

/// Builds one preset into `settings.out_dir/<scene>/`.
pub fn build_preset(
    preset: &Preset,
    settings: &BuildSettings,
    progress: Progress,
) -> Result<SceneOutcome, SceneBuildError> {
    let t0 = Instant::now();
    let name = &preset.scene.name;
    let out = &settings.out_dir;
    // a shard's round: its cache entries and record are its output, not a scene folder
    let shard_outcome = |files: usize| SceneOutcome {
        preset: preset_label(preset),
        scene: name.clone(),
        error: None,
        blame: None,
        dir: Some(out.clone()),
        files,
        triangles: 0,
        cached_stages: Vec::new(),
        seconds: t0.elapsed().as_secs_f64(),
        warnings: crate::scene::preset::lsystem_warnings(preset),
    };
    let say = |m: &str| progress(name, m);
    match (settings.shard, settings.tiles_from.is_empty()) {
        (Some(part), false) => {
            let record = shard::build_tile_shard(preset, out, part, &settings.tiles_from, settings.force, &say)?;
            return Ok(shard_outcome(record.tiles.len()));
        }
        (Some(part), true) => {
            let record = shard::build_shard(preset, out, part, settings.force, &say)?;
            return Ok(shard_outcome(record.built.len()));
        }
        (None, _) => {}
    }
    for stage in [Stage::Snow, Stage::Scatter, Stage::Preview] {
        let applies = stage != Stage::Snow || preset.snow.is_some();
        if applies
            && settings.stages.contains(&stage)
            && !settings.stages.contains(&Stage::Terrain)
            && preset.terrain.is_some()
        {
            return Err(SceneBuildError::Usage(format!(
                "the {} stage needs the terrain: select it too (--only terrain,{})",
                stage.name(),
                stage.name()
            )));
        }
    }
    // scene.glb draws the placements: the view stage runs with the scatter stage
    if settings.stages.contains(&Stage::View)
        && !settings.stages.contains(&Stage::Scatter)
        && !preset.species.is_empty()
    {
        return Err(SceneBuildError::Usage(
            "the view stage draws the placements: select the scatter stage too (--only terrain,scatter,view)".into(),
        ));
    }
    fs::create_dir_all(out).map_err(io_err(out))?;
    let final_dir = out.join(name);
    remove_stale_folders(out, name);
    let tmp_dir = out.join(format!(".{name}.building-{}", std::process::id()));
    let _ = fs::remove_dir_all(&tmp_dir);
    fs::create_dir_all(&tmp_dir).map_err(io_err(&tmp_dir))?;
    let result = build_into(preset, settings, &tmp_dir, progress);
    match result {
        Ok(mut outcome) => {
            swap_into_place(&tmp_dir, &final_dir)?;
            outcome.dir = Some(final_dir);
            outcome.seconds = t0.elapsed().as_secs_f64();
            Ok(outcome)
        }
        Err(e) => {
            let _ = fs::remove_dir_all(&tmp_dir);
            Err(e)
        }
    }
}

/// Cleans up after builds of scene `name` that were killed: their `.NAME.building-PID` folders are
/// removed, and a `.NAME.old-PID` folder (the previous scene, moved aside just before the new one
/// was to take its place) is put back when no scene folder exists, else removed. Folders of
/// processes still running are left alone.
pub fn remove_stale_folders(out: &Path, name: &str) {
    let Ok(items) = fs::read_dir(out) else { return };
    let final_dir = out.join(name);
    let (building, old) = (format!(".{name}.building-"), format!(".{name}.old-"));
    for item in items.flatten() {
        let file = item.file_name().to_string_lossy().to_string();
        let owner = if file.starts_with(&building) {
            temp_owner(&file, ".building-")
        } else if file.starts_with(&old) {
            temp_owner(&file, ".old-")
        } else {
            continue;
        };
        let Some(pid) = owner else { continue };
        if pid == std::process::id() || process_alive(pid) {
            continue;
        }
        let path = item.path();
        if file.starts_with(&old) && !final_dir.exists() && fs::rename(&path, &final_dir).is_ok() {
            continue;
        }
        let _ = fs::remove_dir_all(&path);
    }
}

/// Replaces `final_dir` by `tmp_dir`. On Linux the two folders are exchanged in one rename
/// (renameat2 RENAME_EXCHANGE): a reader sees the old scene or the new one, never no scene; the
/// old one, now at `tmp_dir`, is removed after. Elsewhere (or on a filesystem without the
/// exchange) the old folder is moved aside first and removed only after the new one is in place;
/// a kill between those two renames leaves `.NAME.old-PID`, which the next build of the scene
/// moves back ([`remove_stale_folders`]).
fn swap_into_place(tmp_dir: &Path, final_dir: &Path) -> Result<(), SceneBuildError> {
    #[cfg(target_os = "linux")]
    if final_dir.is_dir() {
        use rustix::fs::{renameat_with, RenameFlags, CWD};
        if renameat_with(CWD, tmp_dir, CWD, final_dir, RenameFlags::EXCHANGE).is_ok() {
            let _ = fs::remove_dir_all(tmp_dir);
            return Ok(());
        }
    }
    let old = final_dir.with_file_name(format!(
        ".{}.old-{}",
        final_dir.file_name().and_then(|n| n.to_str()).unwrap_or("scene"),
        std::process::id()
    ));
    let had_old = final_dir.exists();
    if had_old {
        let _ = fs::remove_dir_all(&old);
        fs::rename(final_dir, &old).map_err(io_err(final_dir))?;
    }
    if let Err(e) = fs::rename(tmp_dir, final_dir) {
        if had_old {
            let _ = fs::rename(&old, final_dir);
        }
        let _ = fs::remove_dir_all(tmp_dir);
        return Err(io_err(final_dir)(e));
    }
    if had_old {
        let _ = fs::remove_dir_all(&old);
    }
    Ok(())
}

/// Runs the selected stages in order into `dir`, each through the cache; later stages take what
/// earlier ones made (the terrain scene, the snow cover, the plants' chains, the placements).
fn build_into(
    preset: &Preset,
    settings: &BuildSettings,
    dir: &Path,
    progress: Progress,
) -> Result<SceneOutcome, SceneBuildError> {
    let name = &preset.scene.name;
    let say = |m: &str| progress(name, m);
    let cache = Cache::new(&settings.out_dir);
    let wants = |s: Stage| settings.stages.contains(&s);
    let mut runner =
        StageRunner { cache: &cache, force: settings.force, dir, used: CacheUse::default(), progress: &say };
    let mut runs: Vec<StageRun> = Vec::new();

    // the terrain scene for later stages (in memory when built, else read back on first use)
    let mut terrain: Option<TerrainHandoff> = None;
    let mut terrain_lods: Vec<LodInfo> = Vec::new();
    if let (true, Some(t)) = (wants(Stage::Terrain), &preset.terrain) {
        let memo = crate::scene::terrain_stage::MeshMemo { cache: &cache, force: settings.force };
        let job = TerrainJob { preset, terrain: t, memo: Some(memo) };
        let ran = runner.run(&job)?;
        // the terrain's meshes, kept apart from its files: `cache prune` keeps them with the scene
        runner.used.entries.extend(job.memo_entries());
        terrain = Some(TerrainHandoff::new(dir, &ran.report.files, ran.key, ran.artifact));
        terrain_lods = ran.report.lods.clone();
        runs.push(StageRun::Terrain { cost: ran.cost, report: ran.report, cached: ran.cached });
    }

    // the snow cover as stored in snow/cover_mask.png (cached or not, the same values), and its key
    let mut cover: Option<(CoverMask, String)> = None;
    if let (true, Some(snow), Some(terrain)) = (wants(Stage::Snow), &preset.snow, &terrain) {
        let ran = runner.run(&SnowJob { preset, snow, terrain })?;
        cover = Some((snow_stage::load_mask(dir, &ran.report.mask)?, ran.key));
        runs.push(StageRun::Snow { cost: ran.cost, report: ran.report, cached: ran.cached });
    }
    let cover_ref = cover.as_ref().map(|(m, k)| (m, k.as_str()));

    let mut plants: Option<(PlantsStageReport, String)> = None;
    if wants(Stage::Plants) && plants_stage::has_plants(preset) {
        let memo = plants_stage::SpeciesMemo { cache: &cache, force: settings.force };
        let job = PlantsJob { preset, memo: Some(memo) };
        let ran = runner.run(&job)?;
        // each species' entry, kept apart: `cache prune` keeps them with the scene
        runner.used.entries.extend(job.memo_entries());
        plants = Some((ran.report.clone(), ran.key));
        runs.push(StageRun::Plants { cost: ran.cost, report: ran.report, cached: ran.cached });
    }

    // what the preview draws of the placements, and the scatter stage's key; the view stage's
    // report and key (the preview renders scene.glb from the first view)
    let mut placed: (Option<Vec<PreviewLayer>>, Vec<(String, PathBuf)>, Option<String>) = (None, Vec::new(), None);
    let mut drawn: Option<(ViewStageReport, String)> = None;
    // a merge's scene tiles, made by the shards' second round (`--tiles`): put in place by the view
    // stage where the cache holds them, the others written there
    let tile_plan = match settings.merging && !settings.force && settings.tile_scenes.contains(name) {
        true => crate::scene::tile_units::plan(preset).ok().and_then(Result::ok),
        false => None,
    };
    let kept_tile = |ij: [u32; 2], grid: [u32; 2]| tile_plan.as_ref().and_then(|p| p.kept(&cache, dir, ij, grid));
    if let (true, Some(terrain), false) = (wants(Stage::Scatter), &terrain, preset.species.is_empty()) {
        // a merge's placements, made by rows in the shards
        let joined = || crate::scene::placement_rows::joined_for(preset, &cache);
        let ran = runner.run(&ScatterJob {
            preset,
            terrain,
            cover: cover_ref,
            joined: (settings.merging && !settings.force).then_some(&joined as &dyn Fn() -> _),
        })?;
        let tables: Vec<(String, PathBuf)> =
            ran.report.species.iter().map(|s| (s.name.clone(), s.csv.clone())).collect();
        runs.push(StageRun::Scatter { cost: ran.cost, report: ran.report, cached: ran.cached });
        // positions as stored (f32), so a preview drawn after a cached scatter is the same; taken
        // before the view stage, which then does not hold the instances beside its own (76 MB of
        // 1.2 M grass instances on presets/worlds/highlands.toml)
        // (the terrain's cover is read: not held through the view and preview stages)
        terrain.release_cover();
        let layers = ran.artifact.map(|placed| placed.iter().map(preview_layer).collect());
        if wants(Stage::View) {
            let plants_key = plants.as_ref().map_or("", |(_, k)| k.as_str());
            let job = ViewJob {
                preset,
                terrain: TerrainInput { main: &terrain.main, lods: &terrain_lods },
                plants: plants.as_ref().map(|(r, _)| r),
                tables: &tables,
                compare_full_detail: settings.compare_full_detail,
                upstream: [&terrain.key, plants_key, &ran.key],
                kept_tiles: tile_plan.as_ref().map(|_| &kept_tile as crate::scene::view_tiles::KeptTile),
            };
            let view = runner.run(&job)?;
            drawn = Some((view.report.clone(), view.key));
            runs.push(StageRun::View { cost: view.cost, report: view.report, cached: view.cached });
        }
        placed = (layers, tables, Some(ran.key));
    }

    if let (true, Some(terrain)) = (wants(Stage::Preview), &terrain) {
        let placements = match &placed {
            (Some(layers), _, _) => PreviewPlacements::Fresh(layers),
            (None, tables, Some(_)) => PreviewPlacements::Tables(tables),
            (None, _, None) => PreviewPlacements::None,
        };
        let job = PreviewJob {
            preset,
            terrain,
            placements: (placements, placed.2.as_deref()),
            cover: cover_ref,
            view: drawn.as_ref().map(|(r, k)| (r, k.as_str())),
        };
        let ran = runner.run(&job)?;
        runs.push(StageRun::Preview { cost: ran.cost, report: ran.report, cached: ran.cached });
    }

    progress(name, "manifest and report");
    let known = runner.used;
    let warnings = crate::scene::preset::lsystem_warnings(preset);
    let files = write_manifest_and_report(preset, dir, &runs, &known.hashes, &warnings)?;
    if let Err(e) = cache.record_scene(name, &known.entries) {
        progress(
            name,
            &format!("could not record the cache entries used ({e}); `verdant cache prune` may remove them"),
        );
    }
    let triangles = runs
        .iter()
        .map(|r| match r {
            StageRun::Terrain { report, .. } => report.output_triangles,
            _ => 0,
        })
        .sum();
    Ok(SceneOutcome {
        preset: preset_label(preset),
        scene: name.clone(),
        error: None,
        blame: None,
        dir: None,
        files,
        triangles,
        cached_stages: runs.iter().filter(|r| r.cached()).map(StageRun::stage).collect(),
        seconds: 0.0,
        warnings,
    })
}

/// One species' fresh placements as the preview draws them: positions as stored (f32).
fn preview_layer(p: &Placed) -> PreviewLayer {
    PreviewLayer {
        color: p.color,
        kind: p.species.kind,
        footprint_m: footprint_m(&p.species),
        positions: p.instances.iter().map(|i| i.position.map(|v| v as f32 as f64)).collect(),
    }
}

pub fn preset_label(preset: &Preset) -> String {
    preset.path.as_ref().map_or("(embedded demo)".to_string(), |p| p.display().to_string())
}

/// What to build in a batch: a preset file, or an already resolved preset (the embedded demo).
#[derive(Debug, Clone)]
pub enum PresetSource {
    File(PathBuf),
    Resolved(Box<Preset>),
}

/// Builds every preset, `jobs` at a time; returns one outcome per preset, in the given order.
pub fn build_batch(
    sources: &[PresetSource],
    settings: &BuildSettings,
    jobs: usize,
    progress: Progress,
) -> Vec<SceneOutcome> {
    // load first, so two presets naming the same scene are caught before anything is built
    let loaded: Vec<(String, Result<Preset, SceneBuildError>)> = sources
        .iter()
        .map(|s| match s {
            PresetSource::File(p) => (p.display().to_string(), load_preset(p).map_err(SceneBuildError::from)),
            PresetSource::Resolved(p) => (preset_label(p), Ok((**p).clone())),
        })
        .collect();
    let mut seen: Vec<(String, String)> = Vec::new();
    let loaded: Vec<(String, Result<Preset, SceneBuildError>)> = loaded
        .into_iter()
        .map(|(label, r)| match r {
            Ok(p) => {
                if let Some((_, first)) = seen.iter().find(|(n, _)| *n == p.scene.name) {
                    let msg = format!("{label}: scene name `{}` is already built by {first} in this batch; give one of them another [scene] name", p.scene.name);
                    (label, Err(SceneBuildError::Usage(msg)))
                } else {
                    seen.push((p.scene.name.clone(), label.clone()));
                    (label, Ok(p))
                }
            }
            Err(e) => (label, Err(e)),
        })
        .collect();

    let run_one = |(label, r): &(String, Result<Preset, SceneBuildError>)| -> SceneOutcome {
        let t0 = Instant::now();
        let failed = |scene: String, e: &SceneBuildError| {
            SceneOutcome::failed(label.clone(), scene, e, t0.elapsed().as_secs_f64())
        };
        match r {
            Err(e) => failed("—".into(), e),
            Ok(p) => build_preset(p, settings, progress).unwrap_or_else(|e| SceneOutcome {
                // a repair may be why it failed
                warnings: crate::scene::preset::lsystem_warnings(p),
                ..failed(p.scene.name.clone(), &e)
            }),
        }
    };
    let jobs = jobs.clamp(1, loaded.len().max(1));
    if jobs == 1 {
        return loaded.iter().map(run_one).collect();
    }
    // `jobs` workers take presets w, w + jobs, …; the pool keeps at least the --threads workers
    // for the stages inside, so both settings mean what they say
    let threads = jobs.max(rayon::current_num_threads());
    let Ok(pool) = rayon::ThreadPoolBuilder::new().num_threads(threads).build() else {
        return loaded.iter().map(run_one).collect();
    };
    let mut per_worker: Vec<Vec<(usize, SceneOutcome)>> = pool.install(|| {
        (0..jobs)
            .into_par_iter()
            .map(|w| (w..loaded.len()).step_by(jobs).map(|k| (k, run_one(&loaded[k]))).collect())
            .collect()
    });
    let mut outcomes: Vec<(usize, SceneOutcome)> = per_worker.drain(..).flatten().collect();
    outcomes.sort_by_key(|(k, _)| *k);
    outcomes.into_iter().map(|(_, o)| o).collect()
}

/// Merges sharded builds: for every preset, checks that `shard_dirs` hold all its shards and brings
/// their cache entries into `settings.out_dir` ([`shard::gather`]), then builds it there (every
/// unit a shard made is served from the cache). A preset whose shards do not check out fails alone.
pub fn merge_batch(
    sources: &[PresetSource],
    shard_dirs: &[PathBuf],
    settings: &BuildSettings,
    jobs: usize,
    progress: Progress,
) -> Vec<SceneOutcome> {
    let mut ready: Vec<(usize, PresetSource)> = Vec::new();
    let mut failed: Vec<(usize, SceneOutcome)> = Vec::new();
    let mut tile_scenes: Vec<String> = Vec::new();
    for (k, source) in sources.iter().enumerate() {
        let loaded = match source {
            PresetSource::File(p) => load_preset(p).map_err(SceneBuildError::from),
            PresetSource::Resolved(p) => Ok((**p).clone()),
        };
        let mut scene = "—".to_string();
        let gathered = loaded.and_then(|p| {
            scene = p.scene.name.clone();
            let brought = shard::gather(&p, shard_dirs, &settings.out_dir)?;
            let say = |m: &str| progress(&p.scene.name, m);
            let tiles = shard::gather_tiles(&p, shard_dirs, &settings.out_dir, shard_dirs.len(), &say)?;
            if tiles > 0 {
                tile_scenes.push(p.scene.name.clone());
            }
            progress(
                &p.scene.name,
                &format!(
                    "merge: {brought} cache entries brought from {} shards, {tiles} scene tiles made by them",
                    shard_dirs.len()
                ),
            );
            Ok(p)
        });
        match gathered {
            Ok(p) => ready.push((k, PresetSource::Resolved(Box::new(p)))),
            Err(e) => {
                let label = match source {
                    PresetSource::File(p) => p.display().to_string(),
                    PresetSource::Resolved(p) => preset_label(p),
                };
                failed.push((k, SceneOutcome::failed(label, scene, &e, 0.0)));
            }
        }
    }
    let settings = BuildSettings { shard: None, force: false, merging: true, tile_scenes, ..settings.clone() };
    let sources: Vec<PresetSource> = ready.iter().map(|(_, s)| s.clone()).collect();
    let built = build_batch(&sources, &settings, jobs, progress);
    let mut all: Vec<(usize, SceneOutcome)> = ready.into_iter().map(|(k, _)| k).zip(built).collect();
    all.extend(failed);
    all.sort_by_key(|(k, _)| *k);
    all.into_iter().map(|(_, o)| o).collect()
}

/// The end-of-batch table: scene, status, files, triangles, seconds.
pub fn summary_table(outcomes: &[SceneOutcome]) -> String {
    let mut s =
        format!("{:<16} {:<8} {:>6} {:>11} {:>8}  {}\n", "scene", "status", "files", "triangles", "seconds", "preset");
    for o in outcomes {
        let status = match (&o.error, o.cached_stages.is_empty()) {
            (Some(_), _) => "FAILED",
            (None, true) => "built",
            (None, false) => "built*",
        };
        s += &format!(
            "{:<16} {:<8} {:>6} {:>11} {:>8.2}  {}\n",
            o.scene, status, o.files, o.triangles, o.seconds, o.preset
        );
    }
    if outcomes.iter().any(|o| o.error.is_none() && !o.cached_stages.is_empty()) {
        s += "built* = some stages reused from the cache (--force rebuilds them)\n";
    }
    for o in outcomes {
        if let Some(e) = &o.error {
            s += &format!("error: {e}\n");
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::error::StageError;

    #[test]
    fn a_scene_folder_is_swapped_with_no_moment_without_one() {
        // a reader polling the scene folder while it is replaced 300 times: on Linux (exchange) it
        // never finds it missing; everywhere the new contents are in place and nothing is left
        let dir = tempfile::tempdir().unwrap();
        let final_dir = dir.path().join("scene");
        fs::create_dir_all(&final_dir).unwrap();
        fs::write(final_dir.join("v"), "0").unwrap();
        let done = std::sync::atomic::AtomicBool::new(false);
        let missing = std::thread::scope(|s| {
            let reader = s.spawn(|| {
                let mut missing = 0usize;
                while !done.load(std::sync::atomic::Ordering::Relaxed) {
                    missing += usize::from(!final_dir.is_dir());
                }
                missing
            });
            for k in 1..=300 {
                let tmp = dir.path().join(format!(".scene.building-{k}"));
                fs::create_dir_all(&tmp).unwrap();
                fs::write(tmp.join("v"), k.to_string()).unwrap();
                swap_into_place(&tmp, &final_dir).unwrap();
                assert!(!tmp.exists(), "the old scene is removed");
            }
            done.store(true, std::sync::atomic::Ordering::Relaxed);
            reader.join().unwrap()
        });
        assert_eq!(fs::read_to_string(final_dir.join("v")).unwrap(), "300");
        let left: Vec<_> = fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(left, vec![std::ffi::OsString::from("scene")]);
        if cfg!(target_os = "linux") {
            assert_eq!(missing, 0, "the scene folder was missing {missing} times while it was swapped");
        }
    }

    #[test]
    fn a_batch_is_the_builds_fault_when_one_build_failed_else_the_inputs() {
        let outcome = |blame: Option<Blame>| SceneOutcome {
            preset: String::new(),
            scene: String::new(),
            error: blame.map(|_| "x".into()),
            blame,
            dir: None,
            files: 0,
            triangles: 0,
            cached_stages: Vec::new(),
            seconds: 0.0,
            warnings: Vec::new(),
        };
        let (ok, input, build) = (outcome(None), outcome(Some(Blame::Input)), outcome(Some(Blame::Build)));
        assert_eq!(batch_blame(&[ok.clone(), ok.clone()]), None);
        assert_eq!(batch_blame(&[ok.clone(), input.clone()]), Some(Blame::Input));
        assert_eq!(batch_blame(&[input.clone(), build.clone(), ok]), Some(Blame::Build));
        assert_eq!(batch_blame(&[build, input]), Some(Blame::Build));
        // a stage's error keeps the blame of what failed in it
        let bad_map =
            SceneBuildError::Stage(StageError::Input { stage: "terrain", message: "x.png: not a PNG".into() });
        let write = SceneBuildError::Stage(StageError::Failed { stage: "terrain", message: "disk full".into() });
        assert_eq!((bad_map.exit_code(), write.exit_code()), (2, 1));
    }

    #[test]
    fn folders_of_killed_builds_are_cleaned_up() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        // a build of pid 4294967295 (never a running process) was killed while building `a`, and one
        // between the two renames of `b`'s swap: `b` exists only as the folder moved aside
        let stale = out.join(".a.building-4294967295");
        let moved = out.join(".b.old-4294967295");
        let running = out.join(format!(".a.building-{}", std::process::id()));
        for d in [&stale, &moved, &running] {
            fs::create_dir_all(d).unwrap();
        }
        fs::write(moved.join("manifest.json"), b"{}").unwrap();
        fs::create_dir_all(out.join(".ab.building-4294967295")).unwrap();
        remove_stale_folders(out, "a");
        assert!(!stale.exists(), "a killed build's folder is removed");
        assert!(running.exists(), "this process's own folder is left (it may be in use)");
        assert!(out.join(".ab.building-4294967295").exists(), "another scene's folder is not touched");
        remove_stale_folders(out, "b");
        assert!(!moved.exists() && out.join("b/manifest.json").is_file(), "the previous scene is put back");
        // with a scene folder in place, a leftover old folder is removed
        fs::create_dir_all(out.join(".b.old-4294967295")).unwrap();
        remove_stale_folders(out, "b");
        assert!(!out.join(".b.old-4294967295").exists() && out.join("b").is_dir());
    }
}
