//! `manifest.json` (every file with size and sha256, counts, bounds, chunks, LoD switch distances,
//! the resolved preset and the verdant version — byte-identical for the same preset and seed) and
//! `report.json` / `report.md` (the figures each stage measured, then a separate timing section).

use std::fs;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::export::write_atomic;
use crate::plants::grass_asset::GRASS_LOD_KINDS;
use crate::plants::tree_lod::TreeLodReport;
use crate::scene::cache::{sha256_hex, FileHashes};
use crate::scene::error::SceneBuildError;
use crate::scene::pipeline::Cost;
use crate::scene::pipeline::Stage;
use crate::scene::plants_stage::{PlantReport, PlantsStageReport};
use crate::scene::preview_stage::PreviewStageReport;
use crate::scene::scatter_stage::ScatterStageReport;
use crate::scene::snow_stage::SnowStageReport;
use crate::scene::terrain_stage::TerrainStageReport;
use crate::scene::Preset;

/// One stage's result in this build.
#[derive(Debug, Clone)]
pub enum StageRun {
    Terrain { report: TerrainStageReport, cached: bool, cost: Cost },
    Plants { report: PlantsStageReport, cached: bool, cost: Cost },
    Scatter { report: ScatterStageReport, cached: bool, cost: Cost },
    Preview { report: PreviewStageReport, cached: bool, cost: Cost },
    Snow { report: SnowStageReport, cached: bool, cost: Cost },
    View { report: crate::scene::view_stage::ViewStageReport, cached: bool, cost: Cost },
}

impl StageRun {
    pub fn stage(&self) -> Stage {
        match self {
            StageRun::Terrain { .. } => Stage::Terrain,
            StageRun::Plants { .. } => Stage::Plants,
            StageRun::Scatter { .. } => Stage::Scatter,
            StageRun::Preview { .. } => Stage::Preview,
            StageRun::Snow { .. } => Stage::Snow,
            StageRun::View { .. } => Stage::View,
        }
    }
    pub fn cached(&self) -> bool {
        match self {
            StageRun::Terrain { cached, .. }
            | StageRun::Plants { cached, .. }
            | StageRun::Scatter { cached, .. }
            | StageRun::Preview { cached, .. }
            | StageRun::Snow { cached, .. }
            | StageRun::View { cached, .. } => *cached,
        }
    }
    pub fn cost(&self) -> Cost {
        match self {
            StageRun::Terrain { cost, .. }
            | StageRun::Plants { cost, .. }
            | StageRun::Scatter { cost, .. }
            | StageRun::Preview { cost, .. }
            | StageRun::Snow { cost, .. }
            | StageRun::View { cost, .. } => *cost,
        }
    }
    pub fn seconds(&self) -> f64 {
        self.cost().seconds
    }
}

#[derive(Serialize)]
struct FileEntry {
    path: String,
    bytes: u64,
    sha256: String,
}

#[derive(Serialize)]
struct Manifest<'a> {
    verdant_version: &'static str,
    scene: &'a str,
    files: Vec<FileEntry>,
    terrain: Option<TerrainManifest<'a>>,
    plants: Option<Vec<PlantManifest>>,
    scatter: Option<ScatterManifest>,
    snow: Option<SnowManifest<'a>>,
    /// The view stage: scene.glb, what each view draws, and the chains it drew with (so a
    /// checker or an engine can replay the selection from the placement tables).
    view: Option<ViewManifest<'a>>,
    preview: Option<String>,
    /// Bytes written, in all and per top-level folder or file (manifest and reports not counted).
    bytes: Sizes,
    settings: &'a Preset,
}

/// What a scene folder weighs.
#[derive(Serialize, Clone)]
pub struct Sizes {
    pub total: u64,
    pub files: usize,
    /// `terrain`, `species`, `atlases`, `placements`, `snow`, `scene.glb`, `preview.png`.
    pub by_part: std::collections::BTreeMap<String, u64>,
}

fn sizes(files: &[FileEntry]) -> Sizes {
    let mut by_part = std::collections::BTreeMap::new();
    for f in files {
        let part = f.path.split('/').next().unwrap_or(&f.path).to_string();
        *by_part.entry(part).or_insert(0) += f.bytes;
    }
    Sizes { total: files.iter().map(|f| f.bytes).sum(), files: files.len(), by_part }
}

#[derive(Serialize)]
struct ViewManifest<'a> {
    scene: String,
    bytes: u64,
    /// scene_lod.glb: every terrain chunk and placement tile as an MSFT_lod chain (none with
    /// `lod_scene = false`).
    #[serde(skip_serializing_if = "Option::is_none")]
    lod_scene: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    lod_scene_bytes: Option<u64>,
    /// `[scene] tile`: the scene in tiles ([`crate::scene::view_tiles`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    tiles: Option<TilesManifest>,
    views: &'a [crate::scene::view_stage::ViewReport],
    chains: std::collections::BTreeMap<&'a str, &'a crate::scene::plants_stage::SpeciesChain>,
}

#[derive(Serialize)]
struct TilesManifest {
    /// The index (scene_tiles.json), which lists every tile's file, square, box and contents.
    index: String,
    tile_m: f64,
    tiles: usize,
    bytes: u64,
}

#[derive(Serialize)]
struct TerrainManifest<'a> {
    files: Vec<String>,
    width: usize,
    height: usize,
    cell_size_m: f64,
    vertices: usize,
    triangles: usize,
    output_triangles: usize,
    max_error_m: f64,
    bounds: &'a Option<crate::mesh::Bounds>,
    chunks: &'a [crate::scene::terrain_stage::ChunkInfo],
    lods: &'a [crate::scene::terrain_stage::LodInfo],
}

/// A generated species: its files, and per level of detail the measured switch distance and the
/// MSFT_lod screen coverage written into its glb.
#[derive(Serialize)]
struct PlantManifest {
    name: String,
    /// "grass", "flower", "tree" or "mesh": what made the files.
    look: &'static str,
    files: Vec<String>,
    lods: Vec<PlantLodManifest>,
}

/// One level of a species' chain (of one variant, for trees).
#[derive(Serialize)]
struct PlantLodManifest {
    #[serde(skip_serializing_if = "Option::is_none")]
    variant: Option<usize>,
    level: usize,
    /// What the level draws: "blades", "blade quads", "slices", "top card" (grass); "full",
    /// "simplified", "decimated", "cards", "billboards", "impostor" (trees and models).
    kind: String,
    file: String,
    triangles: usize,
    switch_distance_m: f64,
    screen_coverage: f64,
    /// Unreal's LoD `ScreenSize` and Unity's LODGroup relative height where the level starts
    /// (sphere diameter over screen height; see [`crate::lod::screen_size_from_coverage`]).
    screen_size: f64,
}

#[derive(Serialize)]
struct ScatterManifest {
    scene: String,
    tile_m: f64,
    species: Vec<SpeciesManifest>,
}

#[derive(Serialize)]
struct SpeciesManifest {
    name: String,
    count: usize,
    table: String,
    summary: String,
    tiles: usize,
}

/// The snow stage's files and the analyzer's figures (deterministic: no timings).
#[derive(Serialize)]
struct SnowManifest<'a> {
    files: Vec<String>,
    mask: &'a crate::scene::snow_stage::MaskInfo,
    terrain: String,
    particles: usize,
    layer_triangles: usize,
    analysis: &'a crate::snow::SnowReport,
}

/// Scene-relative paths of every file under `dir`, sorted, with `/` separators.
fn list_files(dir: &Path) -> std::io::Result<Vec<String>> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) -> std::io::Result<()> {
        for entry in fs::read_dir(dir)? {
            let path = entry?.path();
            if path.is_dir() {
                walk(root, &path, out)?;
            } else if let Ok(rel) = path.strip_prefix(root) {
                out.push(rel.components().map(|c| c.as_os_str().to_string_lossy()).collect::<Vec<_>>().join("/"));
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out)?;
    out.sort();
    Ok(out)
}

fn rel_strings(files: &[PathBuf]) -> Vec<String> {
    files.iter().map(|p| p.to_string_lossy().replace('\\', "/")).collect()
}

/// Writes manifest.json, report.json and report.md into `dir`; returns the number of files in
/// the scene folder (these three included).
/// `known` holds sizes and hashes already computed (by the cache) for some of the files; the
/// others are read and hashed here. `warnings` (what the input readers repaired) are listed in
/// both reports.
pub fn write_manifest_and_report(
    preset: &Preset,
    dir: &Path,
    runs: &[StageRun],
    known: &FileHashes,
    warnings: &[String],
) -> Result<usize, SceneBuildError> {
    let io = |path: &Path, e: String| SceneBuildError::Io { path: path.to_owned(), message: e };
    let mut files = Vec::new();
    for rel in list_files(dir).map_err(|e| io(dir, e.to_string()))? {
        let (bytes, sha256) = match known.get(&rel) {
            Some((size, sha)) => (*size, sha.clone()),
            None => {
                let data = fs::read(dir.join(&rel)).map_err(|e| io(&dir.join(&rel), e.to_string()))?;
                (data.len() as u64, sha256_hex(&data))
            }
        };
        files.push(FileEntry { path: rel, bytes, sha256 });
    }
    let bytes = sizes(&files);
    let terrain = runs.iter().find_map(|r| match r {
        StageRun::Terrain { report, .. } => Some(report),
        _ => None,
    });
    let scatter = runs.iter().find_map(|r| match r {
        StageRun::Scatter { report, .. } => Some(report),
        _ => None,
    });
    let plants = runs.iter().find_map(|r| match r {
        StageRun::Plants { report, .. } => Some(report),
        _ => None,
    });
    let view = runs.iter().find_map(|r| match r {
        StageRun::View { report, .. } => Some(report),
        _ => None,
    });
    let preview = runs.iter().find_map(|r| match r {
        StageRun::Preview { report, .. } => Some(report),
        _ => None,
    });
    let snow = runs.iter().find_map(|r| match r {
        StageRun::Snow { report, .. } => Some(report),
        _ => None,
    });
    let manifest = Manifest {
        verdant_version: env!("CARGO_PKG_VERSION"),
        scene: &preset.scene.name,
        files,
        terrain: terrain.map(|t| TerrainManifest {
            files: rel_strings(&t.files),
            width: t.figures.width,
            height: t.figures.height,
            cell_size_m: t.figures.cell_size_m,
            vertices: t.figures.vertices,
            triangles: t.figures.triangles,
            output_triangles: t.output_triangles,
            max_error_m: t.figures.max_error,
            bounds: &t.bounds,
            chunks: &t.chunks,
            lods: &t.lods,
        }),
        plants: plants.map(|p| {
            p.species
                .iter()
                .map(|sp| PlantManifest {
                    name: sp.name.clone(),
                    files: rel_strings(&sp.files),
                    look: if sp.grass.is_some() {
                        "grass"
                    } else if sp.flower.is_some() {
                        "flower"
                    } else if sp.tree.is_some() {
                        "tree"
                    } else {
                        "mesh"
                    },
                    lods: plant_lods(sp, &preset.lod),
                })
                .collect()
        }),
        scatter: scatter.map(|s| ScatterManifest {
            scene: "scene.glb".into(),
            tile_m: s.tile_m,
            species: s
                .species
                .iter()
                .map(|sp| SpeciesManifest {
                    name: sp.name.clone(),
                    count: sp.count,
                    table: sp.csv.to_string_lossy().replace('\\', "/"),
                    summary: sp.csv.with_extension("json").to_string_lossy().replace('\\', "/"),
                    tiles: sp.stats.per_tile.len(),
                })
                .collect(),
        }),
        snow: snow.map(|s| SnowManifest {
            files: rel_strings(&s.files),
            mask: &s.mask,
            terrain: s.terrain_file.to_string_lossy().replace('\\', "/"),
            particles: s.particles,
            layer_triangles: s.layer_triangles,
            analysis: &s.analysis,
        }),
        view: view.map(|v| ViewManifest {
            scene: v.scene_file.to_string_lossy().replace('\\', "/"),
            bytes: v.scene_bytes,
            lod_scene: v.lod_scene_file.as_ref().map(|f| f.to_string_lossy().replace('\\', "/")),
            lod_scene_bytes: v.lod_scene_file.as_ref().map(|_| v.lod_scene_bytes),
            tiles: v.tiles.as_ref().map(|t| TilesManifest {
                index: t.index_file.to_string_lossy().replace('\\', "/"),
                tile_m: t.tile_m,
                tiles: t.tile_files.len(),
                bytes: t.bytes,
            }),
            views: &v.views,
            chains: plants.map(|p| p.species.iter().map(|s| (s.name.as_str(), &s.chain)).collect()).unwrap_or_default(),
        }),
        preview: preview.map(|p| p.file.to_string_lossy().replace('\\', "/")),
        bytes,
        settings: preset,
    };
    let n_files = manifest.files.len() + 3;
    write_atomic(&dir.join("manifest.json"), pretty(&manifest).as_bytes()).map_err(|e| io(dir, e.to_string()))?;
    let report = report_json(preset, runs, &manifest.bytes, warnings);
    write_atomic(&dir.join("report.json"), report.as_bytes()).map_err(|e| io(dir, e.to_string()))?;
    write_atomic(&dir.join("report.md"), report_md(preset, runs, &manifest.bytes, warnings).as_bytes())
        .map_err(|e| io(dir, e.to_string()))?;
    Ok(n_files)
}

fn pretty<T: Serialize>(v: &T) -> String {
    let mut s = serde_json::to_string_pretty(v).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"));
    s.push('\n');
    s
}

/// report.json: measured figures per stage, then `timing` (the only part that varies run to run).
fn report_json(preset: &Preset, runs: &[StageRun], bytes: &Sizes, warnings: &[String]) -> String {
    use serde_json::{json, Map, Value};
    let mut stages = Map::new();
    let mut timing = Map::new();
    for r in runs {
        let (name, mut value, cached, cost) = match r {
            StageRun::Terrain { report, cached, cost } => {
                ("terrain", serde_json::to_value(report).unwrap_or(Value::Null), *cached, *cost)
            }
            StageRun::Scatter { report, cached, cost } => {
                let mut v = serde_json::to_value(report).unwrap_or(Value::Null);
                // per-species seconds are timing too
                if let Some(list) = v.get_mut("species").and_then(Value::as_array_mut) {
                    for sp in list {
                        if let Some(o) = sp.as_object_mut() {
                            o.remove("seconds");
                            if let Some(st) = o.get_mut("stats").and_then(Value::as_object_mut) {
                                st.remove("seconds");
                                st.remove("analyze_seconds");
                            }
                        }
                    }
                }
                ("scatter", v, *cached, *cost)
            }
            StageRun::Preview { report, cached, cost } => {
                ("preview", serde_json::to_value(report).unwrap_or(Value::Null), *cached, *cost)
            }
            StageRun::Snow { report, cached, cost } => {
                ("snow", serde_json::to_value(report).unwrap_or(Value::Null), *cached, *cost)
            }
            StageRun::View { report, cached, cost } => {
                let mut v = serde_json::to_value(report).unwrap_or(Value::Null);
                if let Some(o) = v.as_object_mut() {
                    o.remove("seconds");
                    if let Some(t) = o.get_mut("tiles").and_then(Value::as_object_mut) {
                        t.remove("seconds");
                    }
                }
                ("view", v, *cached, *cost)
            }
            StageRun::Plants { report, cached, cost } => {
                let mut v = serde_json::to_value(report).unwrap_or(Value::Null);
                if let Some(list) = v.get_mut("species").and_then(Value::as_array_mut) {
                    for sp in list {
                        if let Some(o) = sp.as_object_mut() {
                            o.remove("seconds");
                            for look in ["grass", "flower"] {
                                if let Some(g) = o.get_mut(look).and_then(Value::as_object_mut) {
                                    g.retain(|k, _| !k.starts_with("seconds"));
                                }
                            }
                            // a tree's timing is per variant, in its chain's report; a mesh's in its chain's
                            let (mut tree, mut mesh) = (None, None);
                            for (k, v) in o.iter_mut() {
                                match k.as_str() {
                                    "tree" => tree = v.get_mut("variants").and_then(Value::as_array_mut),
                                    "mesh" => mesh = Some(v),
                                    _ => {}
                                }
                            }
                            for v in tree.into_iter().flatten().chain(mesh) {
                                if let Some(c) = v.get_mut("chain").and_then(Value::as_object_mut) {
                                    c.retain(|k, _| !k.starts_with("seconds"));
                                }
                            }
                        }
                    }
                }
                ("plants", v, *cached, *cost)
            }
        };
        // the stage's own seconds are from the run that computed it: timing, not results
        let computed = value.as_object_mut().and_then(|o| o.remove("seconds")).unwrap_or(Value::Null);
        stages.insert(name.into(), value);
        let mut t = json!({ "cached": cached, "seconds": cost.seconds, "computed_in": computed });
        if let Some(peak) = cost.peak_bytes {
            t["peak_memory_mib"] = json!(crate::memory::mib(peak));
        }
        timing.insert(name.into(), t);
    }
    let total: f64 = runs.iter().map(StageRun::seconds).sum();
    timing.insert("total_seconds".into(), json!(total));
    // the process's own mark (it sees spikes between samples) or the largest sample (the kernel
    // updates its mark lazily), whichever is larger
    let sampled = runs.iter().filter_map(|r| r.cost().peak_bytes).max();
    if let Some(peak) = crate::memory::peak_rss_bytes().max(sampled) {
        timing.insert("process_peak_memory_mib".into(), json!(crate::memory::mib(peak)));
    }
    let v = json!({
        "scene": preset.scene.name,
        "verdant_version": env!("CARGO_PKG_VERSION"),
        "stages": stages,
        "warnings": warnings,
        "bytes": bytes,
        "timing": timing,
    });
    pretty(&v)
}

/// report.md: the same figures for people.
fn report_md(preset: &Preset, runs: &[StageRun], bytes: &Sizes, warnings: &[String]) -> String {
    let mut s = format!("# {} — build report\n\nverdant {}\n\n", preset.scene.name, env!("CARGO_PKG_VERSION"));
    if !warnings.is_empty() {
        s += "## Warnings\n\nWhat the input readers repaired (the build used the repaired input):\n\n";
        for w in warnings {
            s += &format!("- {w}\n");
        }
        s += "\n";
    }
    for r in runs {
        match r {
            StageRun::Terrain { report: t, .. } => {
                s += "## Terrain\n\n";
                s += &format!("{}×{} samples, {} m apart", t.figures.width, t.figures.height, t.figures.cell_size_m);
                if t.figures.voids_filled > 0 {
                    s += &format!(", {} voids filled", t.figures.voids_filled);
                }
                s += "\n\nShading error: the angle between the map's normal and the one an engine lights with, \
                      mean / largest over the normal map's texels, with the level's own normal map and with its \
                      vertex normals only. Skirts: how deep each level's chunk skirts hang (at least the preset's \
                      `skirt`; with a chain, the level's error plus the coarsest level's, the largest step to \
                      a neighbouring chunk at any level).\n\n| level | max error requested (m) | measured max (m) | RMS (m) | triangles | switch distance (m) | skirts (m) | shading error with normal map (°) | without (°) |\n|---|---|---|---|---|---|---|---|---|\n";
                let shading = |n: &crate::terrain::normal_map::NormalMapReport| {
                    format!(
                        "{:.2} / {:.2} | {:.1} / {:.1}",
                        n.mean_error_deg, n.max_error_deg, n.mean_error_without_deg, n.max_error_without_deg
                    )
                };
                let skirt = |d: Option<f64>| d.map_or("—".into(), |d| format!("{d:.2}"));
                s += &format!(
                    "| main | {} | {:.4} | {:.4} | {} | — | {} | {} |\n",
                    t.figures.max_error_requested.map_or("grid".into(), |e| e.to_string()),
                    t.figures.max_error,
                    t.figures.rms_error,
                    t.figures.triangles,
                    skirt(t.skirt_m),
                    shading(&t.figures.normal_map)
                );
                for l in &t.lods {
                    s += &format!(
                        "| LOD{} | {} | {:.4} | {:.4} | {} | {:.1} | {} | {} |\n",
                        l.level,
                        l.max_error_requested_m,
                        l.max_error_m,
                        l.rms_error_m,
                        l.triangles,
                        l.switch_distance_m,
                        skirt(l.skirt_m),
                        shading(&l.normal_map)
                    );
                }
                let layers = &t.figures.layers;
                let shares: Vec<String> = layers
                    .layers
                    .iter()
                    .zip(&layers.coverage)
                    .map(|(name, c)| format!("{name} {:.1} %", 100.0 * c))
                    .collect();
                s += &format!(
                    "\nMaterial layers ({}×{} texels, `terrain_layers*.png`; snow from the {}{}): {}\n",
                    layers.map_px[0],
                    layers.map_px[1],
                    layers.snow,
                    if layers.layers.len() > 4 {
                        ", soil where the species' rules leave the gentle ground bare"
                    } else {
                        ""
                    },
                    shares.join(", ")
                );
                if !t.chunks.is_empty() {
                    s += &format!(
                        "\n{} chunks; {} triangles written in all (skirts and base included)\n",
                        t.chunks.len(),
                        t.output_triangles
                    );
                }
                s += "\n";
            }
            StageRun::Scatter { report: sc, .. } => {
                s += &format!("## Scatter\n\nPlacement tables (`placements/`), tiles of {} m; `scene.glb` (the view stage) draws them\n\n", sc.tile_m);
                s += "| species | kind | instances | expected | ratio | min pair distance (m) | min_spacing (m) | max \\|y − terrain\\| scene.glb, f32 (m) | max \\|y − terrain\\| CSV (m) | snow-thinned | tiles |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
                for sp in &sc.species {
                    let spacing =
                        preset.species.iter().find(|x| x.rules.name == sp.name).map_or(0.0, |x| x.rules.min_spacing_m);
                    s += &format!(
                        "| {} | {:?} | {} | {:.0} | {:.3} | {} | {} | {:.2e} | {:.2e} | {} | {} |\n",
                        sp.name,
                        sp.kind,
                        sp.count,
                        sp.stats.expected,
                        sp.stats.count_ratio.unwrap_or(f64::NAN),
                        sp.stats.min_pair_distance_m.map_or("—".to_string(), |d| format!("{d:.3}")),
                        spacing,
                        sp.stats.max_height_error_m,
                        sp.stats.max_height_error_csv_m,
                        sp.rules.snow,
                        sp.stats.per_tile.len()
                    );
                }
                s += "\n";
            }
            StageRun::Plants { report: pl, .. } => s += &plants_md(pl),
            StageRun::Snow { report: sn, .. } => s += &snow_md(sn),
            StageRun::View { report: v, .. } => s += &view_section(v),
            StageRun::Preview { report: p, .. } => {
                s += &match (&p.map, &p.view) {
                    (Some(map), Some(v)) => format!(
                        "## Preview\n\n`{}`, {}×{} px: scene.glb rendered from view `{}` ({} instances); `{}`: the shaded relief from above with the placements\n\n",
                        p.file.display(), p.width_px, p.height_px, v.camera, v.instances, map.display()
                    ),
                    _ => format!("## Preview\n\n`{}`, {}×{} px, shaded relief drawn from the terrain mesh\n\n", p.file.display(), p.width_px, p.height_px),
                };
            }
        }
    }
    s += &format!(
        "## Output\n\n{} files, {:.1} MB in all (manifest and reports aside)\n\n| part | MB |\n|---|---|\n",
        bytes.files,
        bytes.total as f64 / 1e6
    );
    for (part, b) in &bytes.by_part {
        s += &format!("| {part} | {:.2} |\n", *b as f64 / 1e6);
    }
    s += "\n## Timing\n\nPeak memory: the process's resident set at its largest during the stage, sampled every \
          2 ms (what it still holds of earlier stages included, and with `--jobs` above 1 the other scenes \
          built at the same time).\n\n| stage | cached | seconds | peak memory (MiB) |\n|---|---|---|---|\n";
    for r in runs {
        let cost = r.cost();
        let peak = cost.peak_bytes.map_or("—".to_string(), |b| format!("{:.0}", crate::memory::mib(b)));
        s += &format!(
            "| {} | {} | {:.3} | {peak} |\n",
            r.stage().name(),
            if r.cached() { "yes" } else { "no" },
            cost.seconds
        );
    }
    s
}

/// Per level of a species' chain (per variant for trees): its file, triangles, switch distance
/// and MSFT_lod screen coverage.
fn plant_lods(sp: &PlantReport, view: &crate::lod::LodView) -> Vec<PlantLodManifest> {
    let size = |coverage: f64| crate::lod::screen_size_from_coverage(coverage, view);
    if let Some(g) = &sp.grass {
        return g
            .lods
            .iter()
            .map(|l| PlantLodManifest {
                variant: None,
                level: l.level,
                kind: GRASS_LOD_KINDS.get(l.level).copied().unwrap_or("").to_string(),
                file: format!("species/{}_LOD{}.glb", sp.name, l.level),
                triangles: l.triangles,
                switch_distance_m: l.switch_distance_m,
                screen_coverage: l.screen_coverage,
                screen_size: size(l.screen_coverage),
            })
            .collect();
    }
    let chain_rows = |stem: &str, chain: &TreeLodReport, variant: Option<usize>| -> Vec<PlantLodManifest> {
        chain
            .lods
            .iter()
            .map(|l| PlantLodManifest {
                variant,
                level: l.level,
                kind: l.kind.clone(),
                file: format!("species/{stem}_LOD{}.glb", l.level),
                triangles: l.triangles,
                switch_distance_m: l.switch_distance_m,
                screen_coverage: l.screen_coverage,
                screen_size: size(l.screen_coverage),
            })
            .collect()
    };
    if let Some(t) = &sp.tree {
        return t
            .variants
            .iter()
            .enumerate()
            .flat_map(|(k, v)| chain_rows(&format!("{}_v{k}", sp.name), &v.chain, Some(k)))
            .collect();
    }
    if let Some(m) = &sp.mesh {
        return chain_rows(&sp.name, &m.chain, None);
    }
    Vec::new()
}

const CHAIN_NOTE: &str = "The chain's speed/error table: geometric error = one-sided Hausdorff distance LoD_k → LoD0 (sampled); \
     image error from 8 azimuths × 3 elevations (4 × 3 for a chain over the analyzer's budget: its report's `analysis_views`); switch distance = where the silhouette error stays within the `[lod]` pixel budget (see the view section).";
const CHAIN_HEADER: &str = "| model | level | kind | triangles | bytes | Hausdorff max (m) | IoU at switch | switch distance (m) | screen coverage |\n\
                            |---|---|---|---|---|---|---|---|---|\n";

fn file_name(path: &Path) -> String {
    path.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default()
}

/// The rows of one chain's table, the first cell naming the model.
fn chain_rows(model: &str, chain: &TreeLodReport) -> String {
    let mut s = String::new();
    for l in &chain.lods {
        let never = if l.never_passes { " (never ≤ 1 px in range)" } else { "" };
        s += &format!(
            "| {model} | LOD{} | {} | {} | {} | {:.3} | {:.3} | {:.1}{never} | {:.2e} |\n",
            l.level,
            l.kind,
            l.triangles,
            l.bytes,
            l.geometric_error.max_m,
            l.switch_iou,
            l.switch_distance_m,
            l.screen_coverage
        );
    }
    for o in &chain.left_out {
        s += &format!(
            "| {model} | — | {} (left out) | {} | — | — | — | not fewer triangles than the {} before it | — |\n",
            o.kind, o.triangles, o.previous_triangles
        );
    }
    s
}

/// The snow section of report.md: counts, the fall, and the cover by slope and altitude band.
fn snow_md(r: &SnowStageReport) -> String {
    let a = &r.analysis;
    let mut s = String::from(
        "## Snow

",
    );
    let kinds = |m: &std::collections::BTreeMap<String, usize>| {
        m.iter().map(|(k, n)| format!("{k} {n}")).collect::<Vec<_>>().join(", ")
    };
    s += &format!(
        "Atlas cells by habit: {}. Particles: {} near + {} far ({}).

",
        kinds(&a.atlas_cells_by_kind),
        a.near_particles,
        a.far_particles,
        kinds(&a.particles_by_kind)
    );
    s += &format!(
        "Terminal velocity v = m·g/k = {:.3} m/s, time constant {:.3} s, fall from the top in {:.1} s.

",
        a.terminal_velocity_m_s, a.time_constant_s, a.fall_time_s
    );
    s += &format!(
        "Cover mask `{}` {}×{} px ({:.3} m/px): {:.1} % of it at weight ≥ ½. Terrain with the weight: `{}`{}.

",
        r.mask.file.display(),
        r.mask.width,
        r.mask.height,
        r.mask.metres_per_pixel,
        100.0 * a.mask_coverage.unwrap_or(0.0),
        r.terrain_file.display(),
        r.layer_file.as_ref().map_or(String::new(), |f| format!(
            "; snow layer `{}` ({} triangles)",
            f.display(),
            r.layer_triangles
        )),
    );
    let g = &r.layer_agreement;
    s += &format!(
        "The terrain's snow layer (its base colour and `_LAYER_WEIGHTS`) follows this cover: on {} surface vertices, \
         mean |layer − cover| {:.4}, max {:.4}; covered (≥ ½) {:.1} % by the cover, {:.1} % by the layer.

",
        g.vertices,
        g.mean_abs_difference,
        g.max_abs_difference,
        100.0 * g.covered_fraction_cover,
        100.0 * g.covered_fraction_layer,
    );
    for (title, unit, bands) in [("slope", "°", &a.cover_by_slope), ("altitude", " m", &a.cover_by_altitude)] {
        s += &format!("| {title} band | vertices | mean weight | covered (≥ ½) |\n|---|---|---|---|\n");
        for b in bands {
            s += &format!(
                "| {:.1}{unit} – {:.1}{unit} | {} | {:.3} | {:.3} |\n",
                b.from, b.to, b.vertices, b.mean_weight, b.covered_fraction
            );
        }
        s += "\n";
    }
    s
}

/// The plants section of report.md: per grass species a LoD table (with the thesis' rings for
/// comparison) and the atlas coverage per mip level; per flower species its counts.
fn plants_md(report: &PlantsStageReport) -> String {
    let mut s = String::from("## Plants\n\n");
    for sp in &report.species {
        if let Some(g) = &sp.grass {
            s += &format!(
                "### {} (grass: {} clumps, {} blades)\n\nImage error of the densest clump against its LoD0, rendered by the baker from 8 azimuths × 3 elevations; \
                 switch distance = where the silhouette error stays within the `[lod]` pixel budget.\n\n",
                sp.name, g.clumps, g.blades_total
            );
            s += "| level | triangles | vertices | bytes | IoU near | RMSE near | IoU at switch | edge error at switch (px) | switch distance (m) | screen coverage |\n|---|---|---|---|---|---|---|---|---|---|\n";
            for l in &g.lods {
                let never = if l.never_passes { " (never ≤ 1 px in range)" } else { "" };
                s += &format!(
                    "| LOD{} | {} | {} | {} | {:.3} | {:.3} | {:.3} | {:.2} | {:.1}{never} | {:.2e} |\n",
                    l.level,
                    l.triangles,
                    l.vertices,
                    l.bytes,
                    l.near_iou,
                    l.near_color_rmse,
                    l.switch_iou,
                    l.switch_edge_error_px,
                    l.switch_distance_m,
                    l.screen_coverage
                );
            }
            let switch = |k: usize| g.lods.get(k).map_or(f64::NAN, |l| l.switch_distance_m);
            s += &format!(
                "\nThe real-time grass thesis switched blades → billboards at {} m and billboards → nothing at {} m; measured here: \
                 LoD1 from {:.1} m, LoD2 from {:.1} m, LoD3 from {:.1} m.\n\n",
                g.thesis_rings_m[0], g.thesis_rings_m[1], switch(1), switch(2), switch(3)
            );
            s += "| atlas mip | size | alpha scale | coverage |\n|---|---|---|---|\n";
            for (k, m) in g.atlas_mips.iter().enumerate() {
                s += &format!("| {k} | {}×{} | {:.3} | {:.4} |\n", m.width, m.height, m.alpha_scale, m.coverage);
            }
            s += "\n";
        }
        if let Some(t) = &sp.tree {
            s += &format!(
                "### {} (L-system tree: {}, dialect {})\n\n{CHAIN_NOTE}\n\n",
                sp.name,
                file_name(&t.lsystem),
                t.dialect.name()
            );
            s += CHAIN_HEADER;
            for (k, v) in t.variants.iter().enumerate() {
                let parts = v.stats.leaves + v.stats.polygons;
                s += &chain_rows(&format!("{k} ({} segments, {parts} leaves + polygons)", v.stats.segments), &v.chain);
            }
            s += "\n";
        }
        if let Some(m) = &sp.mesh {
            s += &format!("### {} (mesh: {})\n\n{CHAIN_NOTE}\n\n", sp.name, file_name(&m.obj));
            s += CHAIN_HEADER;
            s += &chain_rows(&format!("{} vertices, {} triangles", m.stats.vertices, m.stats.triangles), &m.chain);
            s += "\n";
        }
        if let Some(f) = &sp.flower {
            s += &format!(
                "### {} (flower)\n\n{} variants, {} triangles per flower (crossed billboards) baked from models of {} triangles in all\n\n",
                sp.name, f.variants, f.triangles_per_flower, f.model_triangles
            );
        }
    }
    s
}

/// report.md's view section: per view, what is drawn against full detail, then per species and
/// level the switch distances and what each level draws.
fn view_section(v: &crate::scene::view_stage::ViewStageReport) -> String {
    let mut s = format!(
        "## Scene view\n\n`{}` ({:.1} MB) is the scene as drawn from the first view: terrain chunks and instances at the level their distance selects, instances beyond their species' cull distance left out.\n\n",
        v.scene_file.display(),
        v.scene_bytes as f64 / 1e6
    );
    if let Some(t) = &v.tiles {
        let largest = t.largest_bytes;
        s += &format!(
            "`{}` indexes the scene in {} tiles of {} m (`{}/`, {:.1} MB, the largest {:.1} MB): each a GLB of its own holding the terrain chunks centred in its square and the instances of the placement tiles in it, chained as in scene_lod.glb{}, with the species' levels it uses and its part of the terrain's textures.\n\n",
            t.index_file.display(),
            t.tile_files.len(),
            t.tile_m,
            crate::scene::view_tiles::TILES_DIR,
            t.bytes as f64 / 1e6,
            largest as f64 / 1e6,
            if v.lod_scene_file.is_some() { "" } else { " (which `lod_scene = false` leaves out)" }
        );
    }
    s += "| view | eye (m) | looking along | fov | image | triangles | draw calls | full-detail triangles | full-detail draw calls | triangle ratio |\n|---|---|---|---|---|---|---|---|---|---|\n";
    for r in &v.views {
        let c = &r.camera;
        s += &format!(
            "| {} | ({:.1}, {:.1}, {:.1}) | ({:.3}, {:.3}, {:.3}) | {:.0}° | {}×{} | {} | {} | {} | {} | {:.2e} |\n",
            c.name,
            c.eye[0],
            c.eye[1],
            c.eye[2],
            c.forward[0],
            c.forward[1],
            c.forward[2],
            c.fov_y_deg,
            c.size_px[0],
            c.size_px[1],
            r.triangles,
            r.draw_calls,
            r.full_detail_triangles,
            r.full_detail_draw_calls,
            r.triangles as f64 / (r.full_detail_triangles.max(1)) as f64
        );
    }
    for r in &v.views {
        s += &format!(
            "\n### {}\n\nterrain chunks per level: {:?} ({} triangles, {} at full detail)\n\n",
            r.camera.name, r.terrain.chunks_per_level, r.terrain.triangles, r.terrain.full_detail_triangles
        );
        if let Some(c) = &r.image {
            s += &match &c.skipped {
                Some(why) => format!("Image against full detail: not rendered ({why}).\n\n"),
                None => format!(
                    "Image against full detail ({}×{} px, {} samples per pixel, the project's rasterizer): {:.2} % of pixels differ by more than {} (linear), colour RMSE {:.4}; {:.2} % of single samples (no anti-aliasing); {:.1} s.\n\n",
                    c.size_px[0], c.size_px[1], c.samples_per_pixel, 100.0 * c.differing, c.threshold,
                    c.color_rmse, 100.0 * c.differing_samples, c.seconds
                ),
            };
        }
        s += "| species | level | switch distance (m, per variant) | instances | triangles |\n|---|---|---|---|---|\n";
        for sp in &r.species {
            for l in &sp.levels {
                let d: Vec<String> =
                    l.switch_distance_m.iter().map(|d| format!("{:.1}", d * r.distance_factor)).collect();
                s += &format!(
                    "| {} | LOD{} | {} | {} | {} |\n",
                    sp.name,
                    l.level,
                    d.join(", "),
                    l.instances,
                    l.triangles
                );
            }
            match &sp.cull {
                Some(c) => {
                    let how =
                        if c.scales_with_view { "from the budget, × instance scale" } else { "set by the preset" };
                    s += &format!(
                        "| {} | culled | beyond {:.1} m ({how}) | {} of {} | — |\n",
                        sp.name,
                        if c.scales_with_view { c.distance_m * r.distance_factor } else { c.distance_m },
                        sp.culled,
                        sp.placed
                    );
                }
                None => s += &format!("| {} | — | no mesh: placement table only | {} | — |\n", sp.name, sp.placed),
            }
        }
    }
    s + "\n"
}
