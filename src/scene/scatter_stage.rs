//! The scatter stage: places every `[[species]]` on the exported terrain surface (in preset order,
//! so exclusions see the species before them), writes `placements/<species>.csv` and `.json`, and
//! `scene.glb`: the terrain plus one EXT_mesh_gpu_instancing node per species per tile.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::export::{self, table};
use crate::mesh::{Instances, Mesh, Node, Scene};
use crate::plants::marker;
use crate::scatter::density::DensityMap;
use crate::scatter::stats::{analyze, SpeciesStats};
use crate::scatter::surface::SurfaceIndex;
use crate::scatter::rules::SnowThinning;
use crate::scatter::{scatter_species_snow, Instance, RuleCounts};
use crate::scene::cache::{sha256_hex, KeyBuilder};
use crate::scene::stages::StageError;
use crate::scene::{Preset, SpeciesSettings};

fn fail(message: String) -> StageError {
    StageError::Failed { stage: "scatter", message }
}

/// What the scatter stage measured for one species (also written as placements/<species>.json).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SpeciesReport {
    pub name: String,
    pub kind: crate::scene::SpeciesKind,
    pub count: usize,
    pub csv: PathBuf,
    pub rules: RuleCounts,
    pub stats: SpeciesStats,
    pub seconds: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ScatterStageReport {
    pub scene_file: PathBuf,
    pub tile_m: f64,
    pub species: Vec<SpeciesReport>,
    pub seconds: f64,
}

impl ScatterStageReport {
    pub fn files(&self) -> Vec<PathBuf> {
        let mut files = vec![self.scene_file.clone()];
        for s in &self.species {
            files.push(s.csv.clone());
            files.push(s.csv.with_extension("json"));
        }
        files
    }
}

/// Version of what the scatter stage writes for given inputs: part of its cache key (see
/// [`crate::scene::stages::TERRAIN_ALGORITHM_VERSION`]). 2: scene.glb holds no unused mesh; 3: its terrain is textured; 4:
/// its plants carry wind in `_WIND`, not COLOR_0; 5: a tree without an L-system instances a
/// built-in tree; 6: flower cards lit by a normal atlas (with TANGENT).
pub const SCATTER_ALGORITHM_VERSION: u32 = 6;

/// Cache key: the terrain's key, the species and scatter settings, the scene seed, the maps' bytes.
pub fn scatter_key(preset: &Preset, terrain_key: &str) -> Result<String, StageError> {
    let mut k = KeyBuilder::new("scatter", SCATTER_ALGORITHM_VERSION);
    k.add(terrain_key.as_bytes());
    k.add(&preset.scene.seed.to_le_bytes());
    k.add(serde_json::to_string(&preset.scatter).unwrap_or_default().as_bytes());
    for s in &preset.species {
        k.add(serde_json::to_string(s).unwrap_or_default().as_bytes());
        crate::scene::plants_stage::add_look_inputs(&mut k, &s.name, &s.look)?;
        for map in [&s.density_map, &s.mask].into_iter().flatten() {
            let bytes = std::fs::read(map).map_err(|e| fail(format!("{}: cannot read: {e}", map.display())))?;
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
    path.as_ref().map(|p| DensityMap::load(p).map_err(|e| fail(e.to_string()))).transpose()
}

/// The placed instances of one species, for the preview.
pub struct Placed {
    pub species: SpeciesSettings,
    pub color: [f32; 4],
    pub instances: Vec<Instance>,
}

/// Runs the scatter stage into `scene_dir`.
pub fn run_scatter(preset: &Preset, terrain: &Scene, scene_dir: &Path) -> Result<(ScatterStageReport, Vec<Placed>), StageError> {
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
    for (index, species) in preset.species.iter().enumerate() {
        let t1 = Instant::now();
        let density = load_map(&species.density_map)?;
        let mask = load_map(&species.mask)?;
        let earlier: Vec<(&str, &[Instance])> = placed.iter().map(|p| (p.species.name.as_str(), &p.instances[..])).collect();
        let thinning = match (snow_mask, &preset.snow, species.kind) {
            (Some(mask), Some(snow), crate::scene::SpeciesKind::Grass | crate::scene::SpeciesKind::Flower) if snow.thin_plants > 0.0 => {
                Some(SnowThinning { mask, strength: snow.thin_plants })
            }
            _ => None,
        };
        let result = scatter_species_snow(
            &surface,
            extent,
            species,
            density.as_ref(),
            mask.as_ref(),
            &earlier,
            preset.scatter.tile_m,
            preset.scene.seed,
            thinning,
        )
        .map_err(|e| fail(e.to_string()))?;
        let generate_s = t1.elapsed().as_secs_f64();
        let stats = analyze(&surface, extent, species, density.as_ref(), mask.as_ref(), thinning, &result.instances, preset.scatter.tile_m, generate_s)
            .map_err(|e| fail(e.to_string()))?;
        let csv = PathBuf::from("placements").join(format!("{}.csv", species.name));
        table::write_placements_csv(&scene_dir.join(&csv), &result.instances).map_err(|e| fail(e.to_string()))?;
        let report = SpeciesReport {
            name: species.name.clone(),
            kind: species.kind,
            count: result.instances.len(),
            csv: csv.clone(),
            rules: result.counts,
            stats,
            seconds: t1.elapsed().as_secs_f64(),
        };
        // timing stays out of the summary, so the file is byte-identical from run to run
        let mut summary = serde_json::to_value(SpeciesSummary::from(&report)).map_err(|e| fail(e.to_string()))?;
        if let Some(st) = summary.get_mut("stats").and_then(serde_json::Value::as_object_mut) {
            st.remove("seconds");
            st.remove("analyze_seconds");
        }
        let mut json = serde_json::to_string_pretty(&summary).map_err(|e| fail(e.to_string()))?;
        json.push('\n');
        export::write_atomic(&scene_dir.join(csv.with_extension("json")), json.as_bytes()).map_err(|e| fail(e.to_string()))?;
        reports.push(report);
        placed.push(Placed { species: species.clone(), color: marker::species_color(species.kind, index), instances: result.instances });
    }
    let scene = instanced_scene(terrain, &placed, extent)?;
    let scene_file = PathBuf::from("scene.glb");
    export::write_scene(&scene, &scene_dir.join(&scene_file)).map_err(|e| fail(e.to_string()))?;
    let report = ScatterStageReport { scene_file, tile_m: preset.scatter.tile_m, species: reports, seconds: t0.elapsed().as_secs_f64() };
    Ok((report, placed))
}

/// placements/<species>.json: count, per-tile counts and AABBs (in `stats.per_tile`), and the
/// analyzer's figures.
#[derive(Serialize)]
struct SpeciesSummary<'a> {
    species: &'a str,
    kind: crate::scene::SpeciesKind,
    count: usize,
    table: &'a Path,
    rules: &'a RuleCounts,
    stats: &'a SpeciesStats,
}

impl<'a> From<&'a SpeciesReport> for SpeciesSummary<'a> {
    fn from(r: &'a SpeciesReport) -> Self {
        SpeciesSummary { species: &r.name, kind: r.kind, count: r.count, table: &r.csv, rules: &r.rules, stats: &r.stats }
    }
}

/// Which generated mesh an instance shows: the clump density level from the density map at its
/// position (sparse clumps where the map is low; the densest level without a map) and a variant
/// from a hash of its position, so neighbouring clumps differ and the choice is reproducible.
fn mesh_choice(i: &Instance, levels: usize, variants: usize, density: Option<&DensityMap>, extent: [f64; 4]) -> usize {
    let level = match density {
        None => levels - 1,
        Some(m) => {
            let u = (i.position[0] - extent[0]) / (extent[2] - extent[0]);
            let v = (i.position[2] - extent[1]) / (extent[3] - extent[1]);
            let d = m.sample(u, v).clamp(0.0, 1.0) as f64;
            ((d * levels as f64) as usize).min(levels - 1)
        }
    };
    let h = crate::synth::mix64(i.position[0].to_bits() ^ crate::synth::mix64(i.position[2].to_bits()));
    level * variants + (((h >> 32) * variants as u64) >> 32) as usize
}

/// The terrain scene plus, per species, its meshes (generated grass clumps or flowers, else a
/// marker) and one instanced node per tile and mesh (grouped under a node named after the species).
pub fn instanced_scene(terrain: &Scene, placed: &[Placed], extent: [f64; 4]) -> Result<Scene, StageError> {
    let mut scene = terrain.clone();
    for p in placed {
        let generated = crate::scene::plants_stage::instance_meshes(&p.species.name, &p.species.look)?;
        let density = match &generated {
            Some(g) if g.levels > 1 => load_map(&p.species.density_map)?,
            _ => None,
        };
        let (mesh_indices, levels, variants) = match generated {
            Some(g) => {
                let texture_base = scene.textures.len();
                scene.textures.extend(g.textures);
                let material_base = scene.materials.len();
                scene.materials.extend(
                    g.materials
                        .into_iter()
                        .map(|m| m.with_textures(|t| Some(t + texture_base))),
                );
                let first = scene.meshes.len();
                for mut m in g.meshes {
                    for prim in &mut m.primitives {
                        prim.material = prim.material.map(|i| i + material_base);
                    }
                    scene.meshes.push(m);
                }
                ((first..scene.meshes.len()).collect::<Vec<_>>(), g.levels, g.variants)
            }
            None => {
                let (mesh, materials) = marker::marker(p.species.kind, &p.species.name, p.color);
                let material_base = scene.materials.len();
                scene.materials.extend(materials);
                let mesh = Mesh {
                    primitives: mesh
                        .primitives
                        .into_iter()
                        .map(|mut prim| {
                            prim.material = prim.material.map(|m| m + material_base);
                            prim
                        })
                        .collect(),
                    ..mesh
                };
                scene.meshes.push(mesh);
                (vec![scene.meshes.len() - 1], 1, 1)
            }
        };
        let mut by_tile: BTreeMap<(u32, usize), Instances> = BTreeMap::new();
        for i in &p.instances {
            let choice = if mesh_indices.len() > 1 { mesh_choice(i, levels, variants, density.as_ref(), extent) } else { 0 };
            let inst = by_tile.entry((i.tile, choice)).or_default();
            inst.translations.push([i.position[0] as f32, i.position[1] as f32, i.position[2] as f32]);
            inst.rotations.push(i.rotation);
            inst.scales.push(i.scale);
        }
        let mut children = Vec::new();
        for ((tile, choice), instances) in by_tile {
            let mesh = mesh_indices[choice];
            let name = if mesh_indices.len() > 1 {
                format!("{}_tile_{tile}_{}", p.species.name, scene.meshes[mesh].name)
            } else {
                format!("{}_tile_{tile}", p.species.name)
            };
            scene.nodes.push(Node {
                name,
                mesh: Some(mesh),
                instances: Some(instances),
                extras: Some(serde_json::json!({ "species": p.species.name, "tile": tile, "mesh": scene.meshes[mesh].name })),
                ..Node::default()
            });
            children.push(scene.nodes.len() - 1);
        }
        scene.nodes.push(Node { name: p.species.name.clone(), children, ..Node::default() });
        scene.roots.push(scene.nodes.len() - 1);
    }
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f64, z: f64) -> Instance {
        Instance { position: [x, 0.0, z], rotation: [0.0, 0.0, 0.0, 1.0], scale: [1.0; 3], yaw_deg: 0.0, tile: 0 }
    }

    #[test]
    fn clumps_follow_the_density_map_and_variants_mix() {
        // left half of the extent at density 0.2, right half at 0.9; 3 levels × 2 variants
        let map = DensityMap::from_fn(2, 1, |i, _| if i == 0 { 0.2 } else { 0.9 });
        let extent = [0.0, 0.0, 100.0, 100.0];
        let mut variants = [0usize; 2];
        for k in 0..200 {
            let z = k as f64 * 0.37;
            let left = mesh_choice(&at(10.0 + k as f64 * 0.1, z), 3, 2, Some(&map), extent);
            let right = mesh_choice(&at(90.0 - k as f64 * 0.1, z), 3, 2, Some(&map), extent);
            assert_eq!(left / 2, 0, "sparse clumps where the map is low");
            assert_eq!(right / 2, 2, "dense clumps where it is high");
            variants[left % 2] += 1;
        }
        assert!(variants.iter().all(|&n| n > 60), "both variants used: {variants:?}");
        // no map: the densest level
        assert_eq!(mesh_choice(&at(1.0, 2.0), 3, 2, None, extent) / 2, 2);
        // the same instance, the same choice
        assert_eq!(mesh_choice(&at(3.5, 7.25), 3, 2, Some(&map), extent), mesh_choice(&at(3.5, 7.25), 3, 2, Some(&map), extent));
    }
}
