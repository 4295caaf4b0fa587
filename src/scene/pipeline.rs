//! The stage contract and the cached runner every stage goes through.
//!
//! A stage is a [`StageJob`]: its inputs (settings from the preset, upstream keys and artifacts),
//! a content key (the stage's algorithm version, its settings, the bytes of its input files, the
//! keys of the stages it reads), the files its report names, and the computation. The
//! [`StageRunner`] serves a job from the cache when its key is there and whole, and otherwise
//! runs it and stores the files and the typed report. What later stages need is the job's
//! in-memory artifact on a fresh run, or read back from the files on a cache hit.

use std::cell::OnceCell;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::mesh::Scene;
use crate::scene::cache::{Cache, FileHashes};
use crate::scene::error::SceneBuildError;
use crate::validate::read_scene_dequantized;

/// One stage of a scene build.
pub trait StageJob {
    /// What the stage measured: written to the cache and read back on a hit, so the manifest and
    /// report are the same either way.
    type Report: Serialize + DeserializeOwned;
    /// What a fresh run hands to later stages in memory (a cache hit has none: they read the files).
    type Artifact;
    /// Which stage (its name prefixes the cache entries).
    const STAGE: Stage;
    /// The cache key: the stage's algorithm version, its settings, its input files' contents and
    /// the keys of the stages whose outputs it reads.
    fn key(&self) -> Result<String, SceneBuildError>;
    /// The files `report` names, relative to the scene folder (what the cache stores and restores).
    fn files(report: &Self::Report) -> Vec<PathBuf>;
    /// Computes the stage into the scene folder `dir`.
    fn run(&self, dir: &Path) -> Result<(Self::Report, Self::Artifact), SceneBuildError>;
}

/// One stage as the runner ran it.
pub struct Ran<R, X> {
    pub report: R,
    /// `None` when the cache served the stage.
    pub artifact: Option<X>,
    pub cached: bool,
    pub key: String,
    /// Wall time and peak memory of this run (the cache lookup and restore, or the computation
    /// and store).
    pub cost: Cost,
}

/// What running a stage cost (timing: it varies run to run).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cost {
    pub seconds: f64,
    /// The process's resident memory at its largest during the run, bytes, sampled
    /// ([`crate::memory::measure`]; `None` where the platform does not tell).
    pub peak_bytes: Option<u64>,
}

/// The cache as one build used it.
#[derive(Debug, Default)]
pub struct CacheUse {
    /// Sizes and hashes of the files restored or stored (the manifest need not re-read them).
    pub hashes: FileHashes,
    /// Entry folder names looked up, served or stored (what `verdant cache prune` keeps).
    pub entries: Vec<String>,
}

/// Runs stages into one scene folder through one cache.
pub struct StageRunner<'a> {
    pub cache: &'a Cache,
    /// Ignore the cache (recompute, and replace the entries).
    pub force: bool,
    pub dir: &'a Path,
    pub used: CacheUse,
    pub progress: &'a dyn Fn(&str),
}

impl StageRunner<'_> {
    /// Restores `job`'s files and report from the cache when its key is there and the entry is
    /// whole (an entry that does not read back is recomputed and replaced); otherwise runs it and
    /// stores what it wrote.
    pub fn run<J: StageJob>(&mut self, job: &J) -> Result<Ran<J::Report, J::Artifact>, SceneBuildError> {
        let (ran, peak) = crate::memory::measure(|| self.run_unmeasured(job));
        // what the stage freed goes back to the system before the next one starts
        crate::memory::release_freed();
        ran.map(|ran| Ran { cost: Cost { peak_bytes: peak, ..ran.cost }, ..ran })
    }

    fn run_unmeasured<J: StageJob>(&mut self, job: &J) -> Result<Ran<J::Report, J::Artifact>, SceneBuildError> {
        let t0 = Instant::now();
        let stage = J::STAGE.name();
        let key = job.key()?;
        let cached = if self.force { None } else { self.cache.lookup(stage, &key) };
        let restored = cached.and_then(|(json, entry)| {
            let report: J::Report = serde_json::from_str(&json).ok()?;
            let hashes = Cache::restore(&entry, self.dir, &J::files(&report)).ok()?;
            Some((report, hashes))
        });
        self.used.entries.push(Cache::entry_name(stage, &key));
        if let Some((report, hashes)) = restored {
            self.used.hashes.extend(hashes);
            (self.progress)(&format!("{stage}: cached"));
            return Ok(Ran {
                report,
                artifact: None,
                cached: true,
                key,
                cost: Cost { seconds: t0.elapsed().as_secs_f64(), peak_bytes: None },
            });
        }
        (self.progress)(&format!("{stage}: running"));
        let (report, artifact) = job.run(self.dir)?;
        let json = serde_json::to_string_pretty(&report).unwrap_or_default();
        match self.cache.store(stage, &key, self.dir, &J::files(&report), &json) {
            Ok(hashes) => self.used.hashes.extend(hashes),
            Err(e) => (self.progress)(&format!("{stage}: could not store the cache entry ({e}); continuing")),
        }
        Ok(Ran {
            report,
            artifact: Some(artifact),
            cached: false,
            key,
            cost: Cost { seconds: t0.elapsed().as_secs_f64(), peak_bytes: None },
        })
    }
}

/// A scene file read back as later stages see it (what a cache hit hands on).
pub fn read_back(dir: &Path, rel: &Path) -> Result<Scene, SceneBuildError> {
    let path = dir.join(rel);
    read_scene_dequantized(&path).map_err(|e| SceneBuildError::Io { path: path.clone(), message: e.to_string() })
}

/// The terrain as later stages take it: in memory when the terrain stage ran, else read back from
/// its first mesh file on first use (also a check that what was cached reads back).
pub struct TerrainHandoff {
    cell: OnceCell<Scene>,
    /// What grows on the in-memory scene (when the stage ran, and its scene is the one handed on),
    /// until the scatter stage has read it ([`TerrainHandoff::release_cover`]).
    cover: std::cell::RefCell<Option<std::sync::Arc<crate::terrain::vegetation::VegetationCover>>>,
    dir: PathBuf,
    /// The terrain's first mesh file, relative to `dir`.
    pub main: PathBuf,
    /// The terrain stage's cache key (what depends on the terrain keys on it).
    pub key: String,
}

impl TerrainHandoff {
    /// `files` are the terrain stage's files; the main one is its first glTF (`.glb`/`.gltf`), else
    /// its first OBJ. An OBJ does not read back as the scene that was written (its reader rebuilds
    /// the vertices), so with an OBJ main file the in-memory `scene` is not used: later stages read
    /// the file whether the terrain stage ran or was served from the cache, and make the same bytes.
    pub fn new(
        dir: &Path,
        files: &[PathBuf],
        key: String,
        ran: Option<crate::scene::terrain_stage::Terrained>,
    ) -> TerrainHandoff {
        let ext = |p: &&PathBuf| p.extension().and_then(|e| e.to_str()).map(str::to_owned);
        let gltf = files.iter().find(|p| matches!(ext(p).as_deref(), Some("glb" | "gltf")));
        let main =
            gltf.or_else(|| files.iter().find(|p| ext(p).as_deref() == Some("obj"))).cloned().unwrap_or_default();
        let cell = OnceCell::new();
        let mut cover = None;
        if let (Some(ran), true) = (ran, gltf.is_some()) {
            let _ = cell.set(ran.scene);
            cover = ran.cover;
        }
        TerrainHandoff { cell, cover: std::cell::RefCell::new(cover), dir: dir.to_path_buf(), main, key }
    }

    /// The ground cover the terrain's layers were baked with, on the texels of its layer map over
    /// the scene's surface; `None` when the terrain stage was served from the cache (or nothing
    /// grows), or once released: the scatter stage then computes the same weights itself.
    pub fn cover(&self) -> Option<std::sync::Arc<crate::terrain::vegetation::VegetationCover>> {
        self.cover.borrow().clone()
    }

    /// Lets the cover go (every species' weights over the layer map: 33 MB on the world preset),
    /// so the stages after the scatter stage do not hold it.
    pub fn release_cover(&self) {
        self.cover.borrow_mut().take();
    }

    pub fn scene(&self) -> Result<&Scene, SceneBuildError> {
        if let Some(scene) = self.cell.get() {
            return Ok(scene);
        }
        if self.main.as_os_str().is_empty() {
            return Err(SceneBuildError::Usage("the terrain stage wrote no mesh".into()));
        }
        let scene = read_back(&self.dir, &self.main)?;
        Ok(self.cell.get_or_init(|| scene))
    }
}

/// The stages in build order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Stage {
    /// Heightmap → terrain meshes (+ LoD chain).
    Terrain,
    /// `[snow]` → snow/: flake atlas, emitter.json, particle frame, cover mask, snow layer, and the
    /// terrain with the `_SNOW` weight (skipped without `[snow]`).
    Snow,
    /// Grass, flower, tree and mesh species → their meshes with LoDs (species/) and baked atlases (atlases/).
    Plants,
    /// [[species]] → placements on the terrain: tables (placements/).
    Scatter,
    /// The first `[[view]]` → scene.glb: terrain chunks and instances at the levels their
    /// distances select, culled beyond each species' cull distance; per view, what is drawn.
    View,
    /// preview.png: a shaded relief drawn from the terrain mesh.
    Preview,
}

impl Stage {
    pub const ALL: [Stage; 6] =
        [Stage::Terrain, Stage::Snow, Stage::Plants, Stage::Scatter, Stage::View, Stage::Preview];
    pub fn name(self) -> &'static str {
        match self {
            Stage::Terrain => "terrain",
            Stage::Snow => "snow",
            Stage::Plants => "plants",
            Stage::Scatter => "scatter",
            Stage::View => "view",
            Stage::Preview => "preview",
        }
    }
}
