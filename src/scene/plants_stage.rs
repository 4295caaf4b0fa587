//! The plants stage: for every grass, flower and L-system tree species, its meshes at every level
//! of detail (`species/`), the baked atlases with their mip chains (`atlases/`) and the analyzer's
//! figures. Independent of the terrain; the scatter stage instances what this makes.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::bake::atlas::write_mip_pngs;
use crate::bake::image::Image;
use crate::export;
use crate::export::gltf::WriteOptions;
use crate::export::quantize::Compact;
use crate::failure::Failure;
use crate::lod::LodView;
use crate::lsystem::parse;
use crate::lsystem::LSystem;
use crate::mesh::Mesh;
use crate::plants::flower::{build_flower, FlowerReport};
use crate::plants::grass::GrassSettings;
use crate::plants::grass_asset::{build_grass_with, GrassAsset, GrassReport};
use crate::plants::mesh_asset::{load_obj, MeshAssetStats, SourceMesh};
use crate::plants::tree::{TreeOptions, TreeStats};
use crate::plants::tree_lod::{
    build_mesh_lods, build_tree_lods, variant_seed, TreeLodOptions, TreeLodReport, TreeLods,
};
use crate::scene::cache::{sha256_hex, Cache, KeyBuilder};
use crate::scene::error::{SceneBuildError, StageError};
use crate::scene::pipeline::{Stage, StageJob};
use crate::scene::{MeshLook, PlantLook, Preset, SpeciesSettings, TreeLook};

fn fail(message: String) -> StageError {
    StageError::Failed { stage: "plants", message }
}

/// A species' input at fault (exit code 2): a file that does not read, an image it cannot use.
fn bad_input(message: String) -> StageError {
    StageError::Input { stage: "plants", message }
}

/// `message` with the blame of `e` (an L-system, a model or a chain that could not be built).
fn failure(e: &dyn Failure, message: String) -> StageError {
    StageError::of("plants", e, message)
}

/// What the plants stage made for one species.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct PlantReport {
    pub name: String,
    pub files: Vec<PathBuf>,
    /// What made the files: exactly one of these is set for a species with a model (none for a
    /// marker-drawn mesh species).
    #[serde(default)]
    pub grass: Option<GrassReport>,
    #[serde(default)]
    pub flower: Option<FlowerReport>,
    #[serde(default)]
    pub tree: Option<TreeSpeciesReport>,
    #[serde(default)]
    pub mesh: Option<MeshSpeciesReport>,
    /// What the view stage draws the species' instances with (typed: the view stage reads it).
    pub chain: SpeciesChain,
    /// The farthest any vertex of the species' files lies from the mesh built (`[scene] compact`:
    /// 16-bit positions; 0 for f32). Tree and mesh chains also fold it into each level's error.
    #[serde(default)]
    pub quantization_m: f64,
    pub seconds: f64,
}

/// What every species file of a build is made with: the `[lod]` policy its switch distances are
/// measured for, and how its glb files store vertex data (`[scene] compact`).
#[derive(Debug, Clone, Copy)]
pub struct SpeciesOutput<'a> {
    pub policy: &'a LodView,
    pub compact: Compact,
}

impl SpeciesOutput<'_> {
    pub fn of(preset: &Preset) -> SpeciesOutput<'_> {
        SpeciesOutput { policy: &preset.lod, compact: preset.scene.compact }
    }
}

/// A species' meshes as the plants stage wrote them, for the view stage: per variant, each level's
/// file and mesh, and the switch distance the analyzer measured for the `[lod]` policy.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
pub struct SpeciesChain {
    /// The distinct variants built: per variant, its levels (LoD0 first).
    pub variants: Vec<Vec<ChainLevel>>,
    /// The placement table's `variant` column → index in `variants` (one entry per variant the
    /// preset asks for; several map to one when an L-system ignores the seed). Empty: the identity.
    #[serde(default)]
    pub pick: Vec<usize>,
    /// Height of the LoD0 meshes above their origin (largest over the variants, m).
    pub height_m: f64,
    /// Height of the LoD0 bounding-box centre above the origin (m): distances are measured to it.
    pub centre_y_m: f64,
}

/// One level of one variant.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ChainLevel {
    /// Scene-relative file holding the mesh.
    pub file: PathBuf,
    /// Name of the mesh in that file.
    pub mesh: String,
    pub triangles: usize,
    /// Used from this distance on (eye to the bounding-sphere centre, unit instance scale,
    /// reference screen of `[lod]`); 0 for LoD0.
    pub switch_distance_m: f64,
}

impl SpeciesChain {
    fn with_bounds(variants: Vec<Vec<ChainLevel>>, lod0: &[&Mesh]) -> SpeciesChain {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for m in lod0 {
            for p in &m.primitives {
                for v in &p.positions {
                    lo = lo.min(v[1] as f64);
                    hi = hi.max(v[1] as f64);
                }
            }
        }
        if !(lo <= hi) {
            (lo, hi) = (0.0, 0.0);
        }
        let pick = (0..variants.len()).collect();
        SpeciesChain { variants, pick, height_m: hi.max(0.0), centre_y_m: 0.5 * (lo + hi) }
    }

    /// The built variant that table variant `variant` shows; None beyond the table's variants.
    pub fn shown(&self, variant: u32) -> Option<usize> {
        let v = variant as usize;
        if self.pick.is_empty() {
            return (v < self.variants.len()).then_some(v);
        }
        self.pick.get(v).copied().filter(|&k| k < self.variants.len())
    }
}

/// A chain's levels for the view stage; only LoD0 when the analyzer did not run (`analyze =
/// false`: no switch distance was measured, so no coarser level may stand in for it).
fn tree_levels(chain: &TreeLods, stem: &str, analyzed: bool) -> Vec<ChainLevel> {
    chain
        .levels
        .iter()
        .zip(&chain.report.lods)
        .take(if analyzed { usize::MAX } else { 1 })
        .map(|(level, f)| ChainLevel {
            file: PathBuf::from("species").join(format!("{stem}_LOD{}.glb", level.level)),
            mesh: level.scene.meshes.first().map(|m| m.name.clone()).unwrap_or_default(),
            triangles: f.triangles,
            switch_distance_m: f.switch_distance_m,
        })
        .collect()
}

/// One variant of a tree species: its seed, what the L-system grew and its chain's figures.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TreeVariantReport {
    pub file: PathBuf,
    pub seed: u64,
    pub stats: TreeStats,
    pub chain: TreeLodReport,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TreeSpeciesReport {
    pub lsystem: PathBuf,
    pub dialect: crate::lsystem::Dialect,
    /// `variants` of the preset; fewer are built when the L-system ignores the seed.
    pub variants_asked: usize,
    pub variants: Vec<TreeVariantReport>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct PlantsStageReport {
    pub species: Vec<PlantReport>,
    pub seconds: f64,
}

impl PlantsStageReport {
    pub fn files(&self) -> Vec<PathBuf> {
        self.species.iter().flat_map(|s| s.files.iter().cloned()).collect()
    }
}

/// Does the preset have a species this stage makes?
pub fn has_plants(preset: &Preset) -> bool {
    preset.species.iter().any(|s| !matches!(s.look, PlantLook::Marker))
}

/// Version of what the plants stage writes for given inputs: part of its cache key (see
/// [`crate::scene::terrain_stage::TERRAIN_ALGORITHM_VERSION`]). 2: chain files keep their coarser levels
/// in a second glTF scene with shared materials; flower cards inside their atlas cells. 3: bark
/// and polygon leaves textured (procedural, tinted by their colour). 4: wind data in `_WIND` /
/// `_WIND_BRANCH` on every plant, none in COLOR_0. 5: a tree species without an L-system grows a
/// built-in tree (crate::lsystem::library), not a marker. 6: chain files keep each finer level's
/// data in a buffer of its own (export::streaming), so Babylon streams them in order. 7: tree card
/// levels lit through a baked normal atlas (atlases/<stem>_normal.png, normalTexture). 8: grass and
/// flower cards too; every card with a normal map carries TANGENT. 9: switch distances for the
/// `[lod]` policy (2 px on 1080 px, 60° vertical by default); the report carries the typed chain.
/// 10: normal atlases written as linear data (glTF normalTexture), not sRGB-encoded.
/// 11: the tree analyzer searches all levels at once (the framing sphere encloses LoD0 and the
/// geometric levels, not the cards; the impostor seen through the card facing each azimuth). 12:
/// small analyzer views get up to 4×4 samples per pixel (64 across at least). 13: leaf-cluster
/// cards frame like billboards (they no longer widen every level's views). 14: the switch search
/// starts at 128 radii and narrows brackets by interpolation (same switches on ../shared/data,
/// fewer distances measured in the report). 15: the chain maps the table's `variant` column to
/// its meshes (`pick`; the files are unchanged). 16: a tree's LoD1 is its rebuild with half the
/// radial segments, simplified only when that saves nothing (edge collapse flattened the twigs).
/// 17: reports carry `stored_error_m` (compact outputs). 18: the fast analyzer's budget of 6 M triangles per measured
/// distance (a chain over it is measured from fewer azimuths; trees within it, the presets' among
/// them, are unchanged); reports carry `analysis_views`. 19: a level walking inwards is measured at
/// its own predicted crossings only (the same switches and files on ../shared/data and the
/// presets; fewer rows in the reports). 20: compact species files store `_WIND` / `_WIND_BRANCH` as
/// normalized bytes of their ranges (f32 files unchanged).
pub const PLANTS_ALGORITHM_VERSION: u32 = 20;

/// Cache key: every generated look (settings, seeds) and the bytes of its input files (a user
/// blade texture, an L-system).
pub fn plants_key(preset: &Preset) -> Result<String, StageError> {
    let mut k = KeyBuilder::new("plants", PLANTS_ALGORITHM_VERSION);
    k.add(serde_json::to_string(&preset.lod).unwrap_or_default().as_bytes());
    add_compact(&mut k, preset);
    for s in &preset.species {
        k.add(s.rules.name.as_bytes());
        k.add(serde_json::to_string(&s.look).unwrap_or_default().as_bytes());
        add_look_inputs(&mut k, &s.rules.name, &s.look)?;
    }
    Ok(k.finish())
}

/// How the species and scene files store vertex data, in a stage's key (nothing for f32 files, so
/// the keys of builds without `compact` are as they were).
pub fn add_compact(k: &mut KeyBuilder, preset: &Preset) {
    if preset.scene.compact != Compact::None {
        k.add(b"compact=").add(format!("{:?}", preset.scene.compact).as_bytes());
    }
}

/// Adds the bytes of the files a look reads to a cache key (the scatter stage's key too: its
/// scene.glb holds the instanced meshes).
pub fn add_look_inputs(k: &mut KeyBuilder, name: &str, look: &PlantLook) -> Result<(), StageError> {
    let input = match look {
        PlantLook::Grass(GrassSettings { blade_texture: Some(p), .. }) => p,
        PlantLook::Tree(t) => &t.lsystem,
        PlantLook::Mesh(m) => {
            // the model as loaded (OBJ, its MTL and textures), as glb bytes
            let source = load_model(name, m)?;
            let glb = export::gltf::to_glb(&source.scene).map_err(|e| fail(format!("{}: {e}", m.obj.display())))?;
            k.add(sha256_hex(&glb).as_bytes());
            return Ok(());
        }
        _ => return Ok(()),
    };
    // an L-system may be a built-in one (`builtin:<name>`): its source is in the crate
    let bytes = crate::lsystem::library::read_bytes(input)
        .map_err(|e| bad_input(format!("{}: cannot read: {e}", input.display())))?;
    k.add(sha256_hex(&bytes).as_bytes());
    Ok(())
}

/// Variants asked for, or 1 when the seed cannot change the tree (no stochastic rule, no `~`):
/// identical copies would only cost build time and file size.
fn distinct_variants(system: &LSystem, look: &TreeLook) -> usize {
    if system.uses_seed() {
        look.variants
    } else {
        1
    }
}

pub fn read_lsystem(name: &str, look: &TreeLook) -> Result<LSystem, StageError> {
    parse::read_file(&look.lsystem, look.dialect)
        .map(|p| p.system)
        .map_err(|e| failure(&e, format!("species `{name}`: {e}")))
}

/// How variant `k` of a tree species grows (the chain's LoD0 and the instanced mesh are the same).
fn tree_options(name: &str, look: &TreeLook, k: usize) -> TreeOptions {
    TreeOptions {
        seed: variant_seed(look.seed, k),
        radial_segments: look.radial_segments,
        max_segments: look.max_segments,
        max_triangles: look.max_triangles,
        max_symbols: look.max_symbols,
        height_m: look.height_m,
        name: format!("{name}_v{k}"),
        ..TreeOptions::default()
    }
}

/// Writes a chain: `species/<stem>.glb` (MSFT_lod; returned), `species/<stem>_LOD<n>.glb` and
/// `atlases/<stem>*.png`.
fn write_chain(chain: &TreeLods, dir: &Path, stem: &str, store: &mut Store<'_>) -> Result<PathBuf, StageError> {
    for level in &chain.levels {
        store.write(&level.scene, dir, PathBuf::from("species").join(format!("{stem}_LOD{}.glb", level.level)))?;
    }
    let file = PathBuf::from("species").join(format!("{stem}.glb"));
    store.write(&chain.chain, dir, file.clone())?;
    let files = &mut store.files;
    if !chain.atlas.is_empty() {
        write_mips(dir, stem, &chain.atlas, files)?;
    }
    if let Some(normals) = &chain.normal_atlas {
        write_normal_atlas(dir, stem, normals, files)?;
    }
    Ok(file)
}

/// `atlases/<stem>_normal.png`: a card atlas' normal map (level 0; engines make its mips).
fn write_normal_atlas(
    dir: &Path,
    stem: &str,
    normals: &crate::bake::image::Image,
    files: &mut Vec<PathBuf>,
) -> Result<(), StageError> {
    let png = normals.encode_png_data().map_err(|e| fail(format!("{stem}: {e}")))?;
    let rel = PathBuf::from("atlases").join(format!("{stem}_normal.png"));
    export::write_atomic(&dir.join(&rel), &png).map_err(|e| fail(e.to_string()))?;
    files.push(rel);
    Ok(())
}

/// What the plants stage made of a mesh species: the model as loaded and its chain's figures.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct MeshSpeciesReport {
    pub obj: PathBuf,
    pub file: PathBuf,
    pub stats: MeshAssetStats,
    pub chain: TreeLodReport,
}

fn load_model(name: &str, look: &MeshLook) -> Result<SourceMesh, StageError> {
    load_obj(&look.obj, &look.obj_options()).map_err(|e| failure(&e, format!("species `{name}`: {e}")))
}

/// Builds and writes a mesh species' chain: `species/<name>.glb`, `species/<name>_LOD<n>.glb`,
/// `atlases/<name>*.png`.
fn run_mesh(
    name: &str,
    look: &MeshLook,
    out: SpeciesOutput<'_>,
    dir: &Path,
    store: &mut Store<'_>,
) -> Result<(MeshSpeciesReport, SpeciesChain), StageError> {
    let (source, chain) = mesh_chain(name, look, out)?;
    let file = write_chain(&chain, dir, name, store)?;
    let lod0: Vec<&Mesh> = chain.levels.first().and_then(|l| l.scene.meshes.first()).into_iter().collect();
    let draw = SpeciesChain::with_bounds(vec![tree_levels(&chain, name, look.analyze)], &lod0);
    Ok((MeshSpeciesReport { obj: look.obj.clone(), file, stats: source.stats, chain: chain.report }, draw))
}

/// A mesh species' model as loaded and the LoD chain the plants stage writes for it.
pub fn mesh_chain(name: &str, look: &MeshLook, out: SpeciesOutput<'_>) -> Result<(SourceMesh, TreeLods), StageError> {
    let source = load_model(name, look)?;
    let lod = TreeLodOptions {
        lods: look.lods,
        atlas_px: look.atlas_px,
        analyze: look.analyze,
        policy: *out.policy,
        compact: out.compact,
        ..TreeLodOptions::default()
    };
    let chain = build_mesh_lods(&source, name, &lod)
        .map_err(|e| failure(&e, format!("species `{name}`: {}: {e}", look.obj.display())))?;
    Ok((source, chain))
}

/// Variant `k`'s LoD chain of a tree species, as the plants stage writes it.
pub fn tree_chain(
    name: &str,
    look: &TreeLook,
    system: &LSystem,
    k: usize,
    out: SpeciesOutput<'_>,
) -> Result<TreeLods, StageError> {
    let lod = TreeLodOptions {
        lods: look.lods,
        atlas_px: look.atlas_px,
        analyze: look.analyze,
        policy: *out.policy,
        compact: out.compact,
        ..TreeLodOptions::default()
    };
    build_tree_lods(system, &tree_options(name, look, k), &lod)
        .map_err(|e| failure(&e, format!("species `{name}`: {}: {e}", look.lsystem.display())))
}

/// Builds and writes every variant's chain: `species/<name>_v<k>.glb` (MSFT_lod),
/// `species/<name>_v<k>_LOD<n>.glb` and `atlases/<name>_v<k>*.png`.
fn run_tree(
    name: &str,
    look: &TreeLook,
    out: SpeciesOutput<'_>,
    dir: &Path,
    store: &mut Store<'_>,
) -> Result<(TreeSpeciesReport, SpeciesChain), StageError> {
    let system = read_lsystem(name, look)?;
    let count = distinct_variants(&system, look);
    let mut variants = Vec::with_capacity(count);
    let (mut levels, mut lod0) = (Vec::with_capacity(count), Vec::with_capacity(count));
    for k in 0..count {
        let chain = tree_chain(name, look, &system, k, out)?;
        let stem = format!("{name}_v{k}");
        let file = write_chain(&chain, dir, &stem, store)?;
        levels.push(tree_levels(&chain, &stem, look.analyze));
        lod0.extend(chain.levels.first().and_then(|l| l.scene.meshes.first()).cloned());
        variants.push(TreeVariantReport {
            file,
            seed: variant_seed(look.seed, k),
            stats: chain.lod0.as_ref().map(|t| t.stats.clone()).unwrap_or_default(),
            chain: chain.report,
        });
    }
    let mut draw = SpeciesChain::with_bounds(levels, &lod0.iter().collect::<Vec<_>>());
    // every variant the table may name: those of a seed-independent L-system show its one tree
    draw.pick = (0..look.variants.max(1)).map(|k| k % count.max(1)).collect();
    Ok((
        TreeSpeciesReport {
            lsystem: look.lsystem.clone(),
            dialect: system.dialect,
            variants_asked: look.variants,
            variants,
        },
        draw,
    ))
}

/// The user's blade image, if the settings name one.
pub fn user_blade(settings: &GrassSettings) -> Result<Option<Image>, StageError> {
    match &settings.blade_texture {
        None => Ok(None),
        Some(p) => Image::read_png(p)
            .map(Some)
            .map_err(|e| bad_input(format!("{}: {e}; give an RGBA PNG whose alpha is the blade's shape", p.display()))),
    }
}

/// The files a species writes, how its glb files store vertex data, and the farthest any vertex
/// of them moved in storage.
pub(crate) struct Store<'a> {
    files: &'a mut Vec<PathBuf>,
    options: WriteOptions,
    quantization_m: f64,
}

impl Store<'_> {
    fn write(&mut self, scene: &crate::mesh::Scene, dir: &Path, rel: PathBuf) -> Result<(), StageError> {
        export::write_scene_with(scene, &dir.join(&rel), &self.options).map_err(|e| fail(e.to_string()))?;
        let moved = crate::export::quantize::position_error(scene, &self.options.quantization);
        self.quantization_m = self.quantization_m.max(moved);
        self.files.push(rel);
        Ok(())
    }
}

fn write_mips(
    dir: &Path,
    stem: &str,
    chain: &[crate::bake::atlas::MipLevel],
    files: &mut Vec<PathBuf>,
) -> Result<(), StageError> {
    let written = write_mip_pngs(&dir.join("atlases"), stem, chain).map_err(|e| fail(e.to_string()))?;
    files.extend(written.into_iter().map(|p| PathBuf::from("atlases").join(p.file_name().unwrap_or_default())));
    Ok(())
}

pub fn run_plants(preset: &Preset, scene_dir: &Path) -> Result<PlantsStageReport, StageError> {
    run_plants_memo(preset, scene_dir, None)
}

/// [`run_plants`], each species served from its own cache entry when `memo` has it (and stored
/// there when built): a species edit rebuilds that species alone, and the shards of a sharded build
/// make species apart ([`crate::scene::shard`]).
pub fn run_plants_memo(
    preset: &Preset,
    scene_dir: &Path,
    memo: Option<SpeciesMemo>,
) -> Result<PlantsStageReport, StageError> {
    let t0 = Instant::now();
    let mut species = Vec::new();
    for s in &preset.species {
        if let Some(report) = species_unit(preset, s, scene_dir, memo)? {
            species.push(report);
        }
    }
    Ok(PlantsStageReport { species, seconds: t0.elapsed().as_secs_f64() })
}

/// The cache entries of single species: `plants-species-<key>`.
pub const SPECIES_MEMO_STAGE: &str = "plants-species";

/// Where species are kept apart in the cache, and whether to ignore what is there (`--force`).
#[derive(Clone, Copy)]
pub struct SpeciesMemo<'a> {
    pub cache: &'a Cache,
    pub force: bool,
}

/// Key of one species' unit: the plants stage's version, the `[lod]` policy, the species' name,
/// look and input files.
pub fn species_key(preset: &Preset, s: &SpeciesSettings) -> Result<String, StageError> {
    let mut k = KeyBuilder::new(SPECIES_MEMO_STAGE, PLANTS_ALGORITHM_VERSION);
    k.add(serde_json::to_string(&preset.lod).unwrap_or_default().as_bytes());
    add_compact(&mut k, preset);
    k.add(s.rules.name.as_bytes());
    k.add(serde_json::to_string(&s.look).unwrap_or_default().as_bytes());
    add_look_inputs(&mut k, &s.rules.name, &s.look)?;
    Ok(k.finish())
}

/// Does the plants stage make something for this species (not a marker-drawn one)?
pub fn makes(s: &SpeciesSettings) -> bool {
    !matches!(s.look, PlantLook::Marker)
}

/// One species of the plants stage: restored from `memo` when its entry is there and whole, else
/// built into `scene_dir` (and stored in `memo`). `None` for a species this stage makes nothing of.
pub fn species_unit(
    preset: &Preset,
    s: &SpeciesSettings,
    scene_dir: &Path,
    memo: Option<SpeciesMemo>,
) -> Result<Option<PlantReport>, StageError> {
    if !makes(s) {
        return Ok(None);
    }
    let Some(memo) = memo else { return run_species(preset, s, scene_dir) };
    let key = species_key(preset, s)?;
    let cached = if memo.force { None } else { memo.cache.lookup(SPECIES_MEMO_STAGE, &key) };
    if let Some((json, entry)) = cached {
        if let Ok(report) = serde_json::from_str::<PlantReport>(&json) {
            if Cache::restore(&entry, scene_dir, &report.files).is_ok() {
                return Ok(Some(report));
            }
        }
    }
    let report = run_species(preset, s, scene_dir)?;
    if let Some(r) = &report {
        let json = serde_json::to_string_pretty(r).unwrap_or_default();
        // a species that cannot be stored is only rebuilt next time
        let _ = memo.cache.store(SPECIES_MEMO_STAGE, &key, scene_dir, &r.files, &json);
    }
    Ok(report)
}

/// Builds one species' files into `scene_dir`.
fn run_species(preset: &Preset, s: &SpeciesSettings, scene_dir: &Path) -> Result<Option<PlantReport>, StageError> {
    let t1 = Instant::now();
    let mut files = Vec::new();
    let out = SpeciesOutput::of(preset);
    let mut store = Store { files: &mut files, options: out.compact.write_options(), quantization_m: 0.0 };
    let name = &s.rules.name;
    let (mut tree_report, mut mesh_report) = (None, None);
    let draw;
    let (grass_report, flower_report) = match &s.look {
        PlantLook::Marker => return Ok(None),
        PlantLook::Tree(t) => {
            let (report, chain) = run_tree(name, t, out, scene_dir, &mut store)?;
            (tree_report, draw) = (Some(report), chain);
            (None, None)
        }
        PlantLook::Mesh(m) => {
            let (report, chain) = run_mesh(name, m, out, scene_dir, &mut store)?;
            (mesh_report, draw) = (Some(report), chain);
            (None, None)
        }
        PlantLook::Grass(g) => {
            let blade = user_blade(g)?;
            let asset = build_grass_with(name, g, blade.as_ref(), true, &preset.lod)
                .map_err(|e| fail(format!("species `{name}`: {e}")))?;
            draw = grass_chain(name, g, &asset);
            for (n, scene) in asset.lod_scenes.iter().enumerate() {
                store.write(scene, scene_dir, PathBuf::from("species").join(format!("{name}_LOD{n}.glb")))?;
            }
            store.write(&asset.chain, scene_dir, PathBuf::from("species").join(format!("{name}.glb")))?;
            store.write(&asset.far, scene_dir, PathBuf::from("species").join(format!("{name}_far.glb")))?;
            let files = &mut store.files;
            write_mips(scene_dir, name, &asset.atlas, files)?;
            write_mips(scene_dir, &format!("{name}_blade"), &asset.blade, files)?;
            let density = PathBuf::from("atlases").join(format!("{name}_density.png"));
            let png = asset.density_atlas.encode_png().map_err(|e| fail(e.to_string()))?;
            export::write_atomic(&scene_dir.join(&density), &png).map_err(|e| fail(e.to_string()))?;
            files.push(density);
            write_normal_atlas(scene_dir, name, &asset.normal_atlas, files)?;
            (Some(asset.report), None)
        }
        PlantLook::Flower(f) => {
            let asset = build_flower(name, f).map_err(|e| fail(format!("species `{name}`: {e}")))?;
            let file = PathBuf::from("species").join(format!("{name}.glb"));
            let levels = asset
                .scene
                .meshes
                .iter()
                .map(|m| {
                    vec![ChainLevel {
                        file: file.clone(),
                        mesh: m.name.clone(),
                        triangles: m.triangle_count(),
                        switch_distance_m: 0.0,
                    }]
                })
                .collect();
            draw = SpeciesChain::with_bounds(levels, &asset.scene.meshes.iter().collect::<Vec<_>>());
            store.write(&asset.scene, scene_dir, file)?;
            write_mips(scene_dir, name, &asset.atlas, store.files)?;
            write_normal_atlas(scene_dir, name, &asset.normal_atlas, store.files)?;
            (None, Some(asset.report))
        }
    };
    let quantization_m = store.quantization_m;
    Ok(Some(PlantReport {
        name: name.clone(),
        quantization_m,
        files,
        grass: grass_report,
        flower: flower_report,
        tree: tree_report,
        mesh: mesh_report,
        chain: draw,
        seconds: t1.elapsed().as_secs_f64(),
    }))
}

/// A grass species' chain: the densest clumps (density is applied once, by the scatter's
/// thinning; the clump's density level is not chosen by the map again), one variant each, with
/// the levels of `species/<name>_LOD<n>.glb`.
fn grass_chain(name: &str, g: &GrassSettings, asset: &GrassAsset) -> SpeciesChain {
    let densest = g.density_levels.saturating_sub(1);
    let clumps: Vec<usize> = (0..g.variants).map(|v| densest * g.variants + v).collect();
    let variants = clumps
        .iter()
        .map(|&c| {
            asset
                .lod_scenes
                .iter()
                .zip(&asset.report.lods)
                .enumerate()
                .filter_map(|(n, (scene, f))| {
                    let mesh = scene.meshes.get(c)?;
                    Some(ChainLevel {
                        file: PathBuf::from("species").join(format!("{name}_LOD{n}.glb")),
                        mesh: mesh.name.clone(),
                        triangles: mesh.triangle_count(),
                        switch_distance_m: f.switch_distance_m,
                    })
                })
                .collect()
        })
        .collect();
    let lod0: Vec<&Mesh> = clumps.iter().filter_map(|&c| asset.lod_scenes.first()?.meshes.get(c)).collect();
    SpeciesChain::with_bounds(variants, &lod0)
}

/// The stage in a scene build.
pub struct PlantsJob<'a> {
    pub preset: &'a Preset,
    /// Species kept apart in the cache (None: each built here).
    pub memo: Option<SpeciesMemo<'a>>,
}

impl PlantsJob<'_> {
    /// The species' entry names (what `verdant cache prune` keeps for this scene).
    pub fn memo_entries(&self) -> Vec<String> {
        if self.memo.is_none() {
            return Vec::new();
        }
        let species = self.preset.species.iter().filter(|s| makes(s));
        species
            .filter_map(|s| species_key(self.preset, s).ok())
            .map(|k| Cache::entry_name(SPECIES_MEMO_STAGE, &k))
            .collect()
    }
}

impl StageJob for PlantsJob<'_> {
    type Report = PlantsStageReport;
    type Artifact = ();
    const STAGE: Stage = Stage::Plants;

    fn key(&self) -> Result<String, SceneBuildError> {
        Ok(plants_key(self.preset)?)
    }

    fn files(report: &PlantsStageReport) -> Vec<PathBuf> {
        report.files()
    }

    fn run(&self, dir: &Path) -> Result<(PlantsStageReport, ()), SceneBuildError> {
        Ok((run_plants_memo(self.preset, dir, self.memo)?, ()))
    }
}
