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
use crate::scatter::surface::{SurfaceIndex, TexelTriangles};
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
    /// Its channel of the density weight maps.
    #[serde(default)]
    pub density_weight: Option<DensityWeight>,
    pub seconds: f64,
}

/// One density weight map (`placements/density_<k>.png`): four species per RGBA image.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct DensityMapInfo {
    pub file: PathBuf,
    /// The species in channel order R, G, B, A (fewer in the last map: the rest are 0).
    pub species: Vec<String>,
    pub size_px: [u32; 2],
}

/// What a species' density weight channel holds, and the analyzer's check of it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct DensityWeight {
    pub file: PathBuf,
    /// 0 = R … 3 = A.
    pub channel: usize,
    /// Instances per m² where the channel is 255.
    pub max_density: f64,
    /// Σ (channel / 255) × texel area × max_density: the count the map predicts (exclusions and
    /// Poisson spacing aside), beside the analyzer's expected count (`stats.expected`).
    pub expected_from_map: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ScatterStageReport {
    pub tile_m: f64,
    pub species: Vec<SpeciesReport>,
    /// Each species' density over the terrain as weight maps (the layout of terrain_layers.png).
    #[serde(default)]
    pub density_maps: Vec<DensityMapInfo>,
    pub seconds: f64,
}

impl ScatterStageReport {
    pub fn files(&self) -> Vec<PathBuf> {
        let mut files = Vec::new();
        for s in &self.species {
            files.push(s.csv.clone());
            files.push(s.csv.with_extension("json"));
        }
        files.extend(self.density_maps.iter().map(|m| m.file.clone()));
        files
    }
}

/// Version of what the scatter stage writes for given inputs: part of its cache key (see
/// [`crate::scene::terrain_stage::TERRAIN_ALGORITHM_VERSION`]). 2: scene.glb holds no unused mesh; 3: its terrain is textured; 4:
/// its plants carry wind in `_WIND`, not COLOR_0; 5: a tree without an L-system instances a
/// built-in tree; 6: flower cards lit by a normal atlas (with TANGENT); 7: scene.glb moved to the
/// view stage (tables only); 8: a `variant` column; 9: density weight maps (placements/density_<k>.png). 10: placed on the terrain meshed in regions (terrain 9). 11: on the chunked terrain meshed in bands (terrain 10).
pub const SCATTER_ALGORITHM_VERSION: u32 = 11;

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

/// The size of the terrain's weight map (its base-colour texture, which has the same texels), so
/// the density maps share its texel grid; 512 on the long side when the terrain has none.
fn layer_map_size(terrain: &Scene, extent: [f64; 4]) -> [u32; 2] {
    let from_texture = terrain
        .materials
        .iter()
        .find(|m| m.name == "terrain")
        .and_then(|m| m.base_color_texture)
        .and_then(|t| terrain.textures.get(t))
        .and_then(|t| {
            image::ImageReader::new(std::io::Cursor::new(&t.png)).with_guessed_format().ok()?.into_dimensions().ok()
        });
    match from_texture {
        Some((w, h)) if w > 0 && h > 0 => [w, h],
        _ => {
            let (w, h) = (extent[2] - extent[0], extent[3] - extent[1]);
            let long = w.max(h).max(1e-9);
            [((512.0 * w / long).round() as u32).max(1), ((512.0 * h / long).round() as u32).max(1)]
        }
    }
}

/// Species per density weight map (RGBA).
const SPECIES_PER_DENSITY_MAP: usize = 4;

/// The `index`-th species' density weights as the bytes its channel holds (255 = its effective
/// max density) and what they say: its file and channel, and the count the bytes predict.
#[allow(clippy::too_many_arguments)]
fn species_density<'t>(
    surface: &SurfaceIndex,
    texels: impl FnOnce() -> &'t TexelTriangles,
    (extent, size): ([f64; 4], [u32; 2]),
    preset: &Preset,
    species: &SpeciesSettings,
    (density, mask): (Option<&DensityMap>, Option<&DensityMap>),
    (thinning, grown): (Option<SnowThinning<'_>>, Option<&[f32]>),
    index: usize,
) -> Result<(Vec<u8>, DensityWeight), StageError> {
    let tiling = crate::scatter::Tiling::new(extent, preset.scatter.tile_m).map_err(|e| bad_input(e.to_string()))?;
    let mut rules = crate::scatter::rules::Rules::without_exclusions(
        surface,
        tiling,
        &species.rules,
        density,
        mask,
        preset.scene.seed,
    )
    .map_err(|e| bad_input(e.to_string()))?;
    rules.snow = thinning;
    let to_byte = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    let bytes: Vec<u8> = match grown {
        Some(weights) => weights.iter().map(|&v| to_byte(v)).collect(),
        None => crate::scatter::rules::weight_map_located(&rules, texels()).into_iter().map(to_byte).collect(),
    };
    debug_assert_eq!(bytes.len(), size[0] as usize * size[1] as usize);
    let texel_m2 = (extent[2] - extent[0]) * (extent[3] - extent[1]) / bytes.len().max(1) as f64;
    let sum: f64 = bytes.iter().map(|&b| b as f64 / 255.0).sum();
    let weight = DensityWeight {
        file: PathBuf::from("placements").join(format!("density_{}.png", index / SPECIES_PER_DENSITY_MAP)),
        channel: index % SPECIES_PER_DENSITY_MAP,
        max_density: rules.effective_max_density,
        expected_from_map: sum * texel_m2 * rules.effective_max_density,
    };
    Ok((bytes, weight))
}

/// Writes the density weight maps: species `4k … 4k + 3` (in preset order) in the R, G, B, A of
/// `placements/density_<k>.png`, each channel its species' density over its max (255 = max).
fn write_density_maps(
    scene_dir: &Path,
    size: [u32; 2],
    weights: &[(String, Vec<u8>)],
) -> Result<Vec<DensityMapInfo>, StageError> {
    let n = (size[0] * size[1]) as usize;
    let mut maps = Vec::new();
    for (k, group) in weights.chunks(SPECIES_PER_DENSITY_MAP).enumerate() {
        let mut rgba = vec![0u8; 4 * n];
        for (c, (_, w)) in group.iter().enumerate() {
            for (i, &b) in w.iter().enumerate() {
                rgba[4 * i + c] = b;
            }
        }
        let file = PathBuf::from("placements").join(format!("density_{k}.png"));
        let png = crate::bake::raster::png::encode_rgba8_png(&rgba, size[0], size[1]).map_err(fail)?;
        export::write_atomic(&scene_dir.join(&file), &png).map_err(|e| fail(e.to_string()))?;
        maps.push(DensityMapInfo { file, species: group.iter().map(|(s, _)| s.clone()).collect(), size_px: size });
    }
    Ok(maps)
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
    run_scatter_joined(preset, terrain, scene_dir, snow_mask, None)
}

/// Placements made elsewhere, by species in preset order (`None`: placed here): each one's
/// instances and rule counts.
pub type Joined = Vec<Option<(Vec<Instance>, RuleCounts)>>;

/// [`run_scatter_with_snow`], taking the placements of the species `joined` holds from there (a
/// merge's units placed by rows, joined in row order) instead of placing them; their estimate and
/// `max_instances` are checked as a run checks them.
pub fn run_scatter_joined(
    preset: &Preset,
    terrain: &Scene,
    scene_dir: &Path,
    snow_mask: Option<&crate::snow::CoverMask>,
    joined: Option<Joined>,
) -> Result<(ScatterStageReport, Vec<Placed>), StageError> {
    run_scatter_covered(preset, terrain, scene_dir, snow_mask, joined, None)
}

/// [`run_scatter_joined`], taking the density maps of the species snow does not thin from
/// `grown`, the ground cover the terrain stage baked its layers with on this very scene (the same
/// rules on the same surface and texels: the same weights, bit for bit), when it has the density
/// maps' texels; computed here otherwise.
pub fn run_scatter_covered(
    preset: &Preset,
    terrain: &Scene,
    scene_dir: &Path,
    snow_mask: Option<&crate::snow::CoverMask>,
    mut joined: Option<Joined>,
    grown: Option<&crate::terrain::vegetation::VegetationCover>,
) -> Result<(ScatterStageReport, Vec<Placed>), StageError> {
    let t0 = Instant::now();
    let surface = crate::scene::ground_cover::surface_of(terrain);
    let extent = surface.bounds();
    let mut placed: Vec<Placed> = Vec::new();
    let mut reports = Vec::new();
    let map_size = layer_map_size(terrain, extent);
    // the terrain's cover, when it covers the density maps' texels with every species
    let texels_n = map_size[0] as usize * map_size[1] as usize;
    let grown = grown.filter(|c| {
        c.size == map_size
            && c.extent == extent
            && c.first_row == 0
            && c.species.len() == preset.species.len()
            && c.species.iter().all(|s| s.weights.len() == texels_n)
    });
    // which triangle holds each texel centre of the density maps: one location for every species
    let texels = std::cell::OnceCell::new();
    let mut weights: Vec<(String, Vec<u8>)> = Vec::new();
    let vegetation = crate::scene::ground_cover::vegetation_map(preset, "scatter")?;
    for (index, species) in preset.species.iter().enumerate() {
        let t1 = Instant::now();
        // a vegetation type grows only where the map of types holds its shade (within its own mask)
        let (density, mask) = crate::scene::ground_cover::rule_maps(species, vegetation.as_ref(), "scatter")?;
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
        let from_rows = joined.as_mut().and_then(|j| j.get_mut(index)).and_then(Option::take);
        let mut result = match from_rows {
            Some((instances, counts)) => {
                let r = &species.rules;
                let estimate = crate::scatter::estimate_species(
                    &surface,
                    extent,
                    r,
                    density.as_ref(),
                    mask.as_ref(),
                    preset.scatter.tile_m,
                    preset.scene.seed,
                    thinning,
                )
                .map_err(|e| bad_input(e.to_string()))?;
                if instances.len() > r.max_instances {
                    let e = crate::scatter::ScatterError::TooMany {
                        species: r.name.clone(),
                        count: instances.len(),
                        limit: r.max_instances,
                    };
                    return Err(bad_input(e.to_string()));
                }
                crate::scatter::Scatter { instances, counts, estimate }
            }
            None => scatter_species_snow(
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
            .map_err(|e| bad_input(e.to_string()))?,
        };
        // its density over the terrain, on the weight map's texels (exclusions aside): the
        // terrain's cover when it holds them (not thinned by snow), else weighed here
        let grown_weights = grown.filter(|_| thinning.is_none()).map(|c| &c.species[index].weights[..]);
        let (bytes, density_weight) = species_density(
            &surface,
            || texels.get_or_init(|| surface.locate_texels(extent, map_size[0], map_size[1])),
            (extent, map_size),
            preset,
            species,
            (density.as_ref(), mask.as_ref()),
            (thinning, grown_weights),
            weights.len(),
        )?;
        weights.push((species.rules.name.clone(), bytes));
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
            density_weight: Some(density_weight),
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
    let density_maps = write_density_maps(scene_dir, map_size, &weights)?;
    let report = ScatterStageReport {
        tile_m: preset.scatter.tile_m,
        species: reports,
        density_maps,
        seconds: t0.elapsed().as_secs_f64(),
    };
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
    /// The placements made elsewhere, asked for when the stage runs (a merge's, made by rows in
    /// its shards); `None`, or a call giving `None`: every species is placed here.
    pub joined: Option<&'a dyn Fn() -> Result<Option<Joined>, StageError>>,
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
        let joined = self.joined.map(|f| f()).transpose()?.flatten();
        let grown = self.terrain.cover();
        Ok(run_scatter_covered(self.preset, self.terrain.scene()?, dir, cover, joined, grown.as_deref())?)
    }
}
