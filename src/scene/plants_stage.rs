//! The plants stage: for every grass, flower and L-system tree species, its meshes at every level
//! of detail (`species/`), the baked atlases with their mip chains (`atlases/`) and the analyzer's
//! figures. Independent of the terrain; the scatter stage instances what this makes.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::bake::atlas::write_mip_pngs;
use crate::bake::image::Image;
use crate::export;
use crate::mesh::{Material, Mesh, Texture};
use crate::plants::flower::{build_flower, FlowerReport, FlowerSettings};
use crate::plants::grass::{self, GrassSettings};
use crate::plants::grass_asset::{build_grass, GrassReport};
use crate::plants::texture;
use crate::scene::cache::{sha256_hex, KeyBuilder};
use crate::scene::stages::StageError;
use crate::lsystem::parse;
use crate::lsystem::LSystem;
use crate::plants::tree::{build_tree, TreeOptions, TreeStats};
use crate::plants::mesh_asset::{load_obj, MeshAssetStats, ObjOptions, SourceMesh};
use crate::plants::tree_lod::{build_mesh_lods, build_tree_lods, variant_seed, TreeLodOptions, TreeLodReport, TreeLods};
use crate::scene::{MeshLook, PlantLook, Preset, TreeLook};

fn fail(message: String) -> StageError {
    StageError::Failed { stage: "plants", message }
}

/// What the plants stage made for one species.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct PlantReport {
    pub name: String,
    pub files: Vec<PathBuf>,
    /// The figures of a grass species (serialised as JSON values so the report stays one type).
    pub grass: Option<serde_json::Value>,
    pub flower: Option<serde_json::Value>,
    /// A tree species: [`TreeSpeciesReport`].
    #[serde(default)]
    pub tree: Option<serde_json::Value>,
    /// A mesh species: [`MeshSpeciesReport`].
    #[serde(default)]
    pub mesh: Option<serde_json::Value>,
    pub seconds: f64,
}

/// One variant of a tree species: its seed, what the L-system grew and its chain's figures.
#[derive(Debug, Clone, Serialize)]
pub struct TreeVariantReport {
    pub file: PathBuf,
    pub seed: u64,
    pub stats: TreeStats,
    pub chain: TreeLodReport,
}

#[derive(Debug, Clone, Serialize)]
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
/// [`crate::scene::stages::TERRAIN_ALGORITHM_VERSION`]). 2: chain files keep their coarser levels
/// in a second glTF scene with shared materials; flower cards inside their atlas cells. 3: bark
/// and polygon leaves textured (procedural, tinted by their colour). 4: wind data in `_WIND` /
/// `_WIND_BRANCH` on every plant, none in COLOR_0. 5: a tree species without an L-system grows a
/// built-in tree (crate::lsystem::library), not a marker. 6: chain files keep each finer level's
/// data in a buffer of its own (export::streaming), so Babylon streams them in order. 7: tree card
/// levels lit through a baked normal atlas (atlases/<stem>_normal.png, normalTexture). 8: grass and
/// flower cards too; every card with a normal map carries TANGENT.
pub const PLANTS_ALGORITHM_VERSION: u32 = 8;

/// Cache key: every generated look (settings, seeds) and the bytes of its input files (a user
/// blade texture, an L-system).
pub fn plants_key(preset: &Preset) -> Result<String, StageError> {
    let mut k = KeyBuilder::new("plants", PLANTS_ALGORITHM_VERSION);
    for s in &preset.species {
        k.add(s.name.as_bytes());
        k.add(serde_json::to_string(&s.look).unwrap_or_default().as_bytes());
        add_look_inputs(&mut k, &s.name, &s.look)?;
    }
    Ok(k.finish())
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
    let bytes = crate::lsystem::library::read_bytes(input).map_err(|e| fail(format!("{}: cannot read: {e}", input.display())))?;
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
    parse::read_file(&look.lsystem, look.dialect).map(|p| p.system).map_err(|e| fail(format!("species `{name}`: {e}")))
}

/// How variant `k` of a tree species grows (the chain's LoD0 and the instanced mesh are the same).
fn tree_options(name: &str, look: &TreeLook, k: usize) -> TreeOptions {
    TreeOptions {
        seed: variant_seed(look.seed, k),
        radial_segments: look.radial_segments,
        max_segments: look.max_segments,
        height_m: look.height_m,
        name: format!("{name}_v{k}"),
        ..TreeOptions::default()
    }
}

/// Writes a chain: `species/<stem>.glb` (MSFT_lod; returned), `species/<stem>_LOD<n>.glb` and
/// `atlases/<stem>*.png`.
fn write_chain(chain: &TreeLods, dir: &Path, stem: &str, files: &mut Vec<PathBuf>) -> Result<PathBuf, StageError> {
    for level in &chain.levels {
        write(&level.scene, dir, PathBuf::from("species").join(format!("{stem}_LOD{}.glb", level.level)), files)?;
    }
    let file = PathBuf::from("species").join(format!("{stem}.glb"));
    write(&chain.chain, dir, file.clone(), files)?;
    if !chain.atlas.is_empty() {
        write_mips(dir, stem, &chain.atlas, files)?;
    }
    if let Some(normals) = &chain.normal_atlas {
        write_normal_atlas(dir, stem, normals, files)?;
    }
    Ok(file)
}

/// `atlases/<stem>_normal.png`: a card atlas' normal map (level 0; engines make its mips).
fn write_normal_atlas(dir: &Path, stem: &str, normals: &crate::bake::image::Image, files: &mut Vec<PathBuf>) -> Result<(), StageError> {
    let png = normals.encode_png().map_err(|e| fail(format!("{stem}: {e}")))?;
    let rel = PathBuf::from("atlases").join(format!("{stem}_normal.png"));
    export::write_atomic(&dir.join(&rel), &png).map_err(|e| fail(e.to_string()))?;
    files.push(rel);
    Ok(())
}

/// What the plants stage made of a mesh species: the model as loaded and its chain's figures.
#[derive(Debug, Clone, Serialize)]
pub struct MeshSpeciesReport {
    pub obj: PathBuf,
    pub file: PathBuf,
    pub stats: MeshAssetStats,
    pub chain: TreeLodReport,
}

fn load_model(name: &str, look: &MeshLook) -> Result<SourceMesh, StageError> {
    let options = ObjOptions { scale: look.scale, up_axis: look.up_axis, ..ObjOptions::default() };
    load_obj(&look.obj, &options).map_err(|e| fail(format!("species `{name}`: {e}")))
}

/// Builds and writes a mesh species' chain: `species/<name>.glb`, `species/<name>_LOD<n>.glb`,
/// `atlases/<name>*.png`.
fn run_mesh(name: &str, look: &MeshLook, dir: &Path, files: &mut Vec<PathBuf>) -> Result<MeshSpeciesReport, StageError> {
    let (source, chain) = mesh_chain(name, look)?;
    let file = write_chain(&chain, dir, name, files)?;
    Ok(MeshSpeciesReport { obj: look.obj.clone(), file, stats: source.stats, chain: chain.report })
}

/// A mesh species' model as loaded and the LoD chain the plants stage writes for it.
pub fn mesh_chain(name: &str, look: &MeshLook) -> Result<(SourceMesh, TreeLods), StageError> {
    let source = load_model(name, look)?;
    let lod = TreeLodOptions { lods: look.lods, atlas_px: look.atlas_px, analyze: look.analyze, ..TreeLodOptions::default() };
    let chain = build_mesh_lods(&source, name, &lod).map_err(|e| fail(format!("species `{name}`: {}: {e}", look.obj.display())))?;
    Ok((source, chain))
}

/// Variant `k`'s LoD chain of a tree species, as the plants stage writes it.
pub fn tree_chain(name: &str, look: &TreeLook, system: &LSystem, k: usize) -> Result<TreeLods, StageError> {
    let lod = TreeLodOptions { lods: look.lods, atlas_px: look.atlas_px, analyze: look.analyze, ..TreeLodOptions::default() };
    build_tree_lods(system, &tree_options(name, look, k), &lod).map_err(|e| fail(format!("species `{name}`: {}: {e}", look.lsystem.display())))
}

/// Builds and writes every variant's chain: `species/<name>_v<k>.glb` (MSFT_lod),
/// `species/<name>_v<k>_LOD<n>.glb` and `atlases/<name>_v<k>*.png`.
fn run_tree(name: &str, look: &TreeLook, dir: &Path, files: &mut Vec<PathBuf>) -> Result<TreeSpeciesReport, StageError> {
    let system = read_lsystem(name, look)?;
    let count = distinct_variants(&system, look);
    let mut variants = Vec::with_capacity(count);
    for k in 0..count {
        let chain = tree_chain(name, look, &system, k)?;
        let file = write_chain(&chain, dir, &format!("{name}_v{k}"), files)?;
        variants.push(TreeVariantReport { file, seed: variant_seed(look.seed, k), stats: chain.lod0.as_ref().map(|t| t.stats.clone()).unwrap_or_default(), chain: chain.report });
    }
    Ok(TreeSpeciesReport { lsystem: look.lsystem.clone(), dialect: system.dialect, variants_asked: look.variants, variants })
}

/// The user's blade image, if the settings name one.
pub fn user_blade(settings: &GrassSettings) -> Result<Option<Image>, StageError> {
    match &settings.blade_texture {
        None => Ok(None),
        Some(p) => Image::read_png(p)
            .map(Some)
            .map_err(|e| fail(format!("{}: {e}; give an RGBA PNG whose alpha is the blade's shape", p.display()))),
    }
}

fn write(scene: &crate::mesh::Scene, dir: &Path, rel: PathBuf, files: &mut Vec<PathBuf>) -> Result<(), StageError> {
    export::write_scene(scene, &dir.join(&rel)).map_err(|e| fail(e.to_string()))?;
    files.push(rel);
    Ok(())
}

fn write_mips(dir: &Path, stem: &str, chain: &[crate::bake::atlas::MipLevel], files: &mut Vec<PathBuf>) -> Result<(), StageError> {
    let written = write_mip_pngs(&dir.join("atlases"), stem, chain).map_err(|e| fail(e.to_string()))?;
    files.extend(written.into_iter().map(|p| PathBuf::from("atlases").join(p.file_name().unwrap_or_default())));
    Ok(())
}

pub fn run_plants(preset: &Preset, scene_dir: &Path) -> Result<PlantsStageReport, StageError> {
    let t0 = Instant::now();
    let mut species = Vec::new();
    for s in &preset.species {
        let t1 = Instant::now();
        let mut files = Vec::new();
        let name = &s.name;
        let (mut tree_report, mut mesh_report) = (None, None);
        let (grass_report, flower_report) = match &s.look {
            PlantLook::Marker => continue,
            PlantLook::Tree(t) => {
                tree_report = Some(run_tree(name, t, scene_dir, &mut files)?);
                (None, None)
            }
            PlantLook::Mesh(m) => {
                mesh_report = Some(run_mesh(name, m, scene_dir, &mut files)?);
                (None, None)
            }
            PlantLook::Grass(g) => {
                let blade = user_blade(g)?;
                let asset = build_grass(name, g, blade.as_ref()).map_err(|e| fail(format!("species `{name}`: {e}")))?;
                for (n, scene) in asset.lod_scenes.iter().enumerate() {
                    write(scene, scene_dir, PathBuf::from("species").join(format!("{name}_LOD{n}.glb")), &mut files)?;
                }
                write(&asset.chain, scene_dir, PathBuf::from("species").join(format!("{name}.glb")), &mut files)?;
                write(&asset.far, scene_dir, PathBuf::from("species").join(format!("{name}_far.glb")), &mut files)?;
                write_mips(scene_dir, name, &asset.atlas, &mut files)?;
                write_mips(scene_dir, &format!("{name}_blade"), &asset.blade, &mut files)?;
                let density = PathBuf::from("atlases").join(format!("{name}_density.png"));
                let png = asset.density_atlas.encode_png().map_err(|e| fail(e.to_string()))?;
                export::write_atomic(&scene_dir.join(&density), &png).map_err(|e| fail(e.to_string()))?;
                files.push(density);
                write_normal_atlas(scene_dir, name, &asset.normal_atlas, &mut files)?;
                (Some(asset.report), None)
            }
            PlantLook::Flower(f) => {
                let asset = build_flower(name, f).map_err(|e| fail(format!("species `{name}`: {e}")))?;
                write(&asset.scene, scene_dir, PathBuf::from("species").join(format!("{name}.glb")), &mut files)?;
                write_mips(scene_dir, name, &asset.atlas, &mut files)?;
                write_normal_atlas(scene_dir, name, &asset.normal_atlas, &mut files)?;
                (None, Some(asset.report))
            }
        };
        species.push(PlantReport {
            name: name.clone(),
            files,
            grass: grass_report.map(|r: GrassReport| serde_json::to_value(r).unwrap_or_default()),
            flower: flower_report.map(|r: FlowerReport| serde_json::to_value(r).unwrap_or_default()),
            tree: tree_report.map(|r| serde_json::to_value(r).unwrap_or_default()),
            mesh: mesh_report.map(|r| serde_json::to_value(r).unwrap_or_default()),
            seconds: t1.elapsed().as_secs_f64(),
        });
    }
    Ok(PlantsStageReport { species, seconds: t0.elapsed().as_secs_f64() })
}

/// The meshes scene.glb instances for a species with a generated look: grass LoD0 clumps (index
/// level · variants + variant) with the blade material, the flower variants' crossed cards, or
/// the tree variants' LoD0 meshes. Primitives index `materials`, materials index `textures`.
pub struct InstanceMeshes {
    pub meshes: Vec<Mesh>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    /// Grass: density levels (clumps are chosen by local density); flowers and trees: 1.
    pub levels: usize,
    pub variants: usize,
}

pub fn instance_meshes(name: &str, look: &PlantLook) -> Result<Option<InstanceMeshes>, StageError> {
    match look {
        PlantLook::Marker => Ok(None),
        PlantLook::Grass(g) => {
            g.check().map_err(|e| fail(format!("species `{name}`: {e}")))?;
            let blade = match user_blade(g)? {
                Some(u) => texture::blade_texture_from(g, &u),
                None => texture::blade_texture(g),
            };
            let mut level0 = blade;
            crate::bake::atlas::dilate(&mut level0, g.alpha_cutoff);
            let png = level0.encode_png().map_err(|e| fail(e.to_string()))?;
            let mut meshes = Vec::new();
            for level in 0..g.density_levels {
                for variant in 0..g.variants {
                    let c = grass::clump(g, level, variant);
                    let mut prim = grass::lod0(g, &c, 0);
                    prim.material = Some(0);
                    meshes.push(Mesh { name: format!("{name}_d{level}v{variant}"), primitives: vec![prim], extras: None });
                }
            }
            let material = Material {
                name: format!("{name}_blade"),
                base_color_texture: Some(0),
                roughness: 0.9,
                alpha_mode: crate::mesh::AlphaMode::Mask { cutoff: g.alpha_cutoff },
                double_sided: true,
                ..Material::default()
            };
            Ok(Some(InstanceMeshes {
                meshes,
                materials: vec![material],
                textures: vec![Texture { name: format!("{name}_blade"), png }],
                levels: g.density_levels,
                variants: g.variants,
            }))
        }
        PlantLook::Flower(f) => {
            let f: &FlowerSettings = f;
            let asset = build_flower(name, f).map_err(|e| fail(format!("species `{name}`: {e}")))?;
            let scene = asset.scene;
            Ok(Some(InstanceMeshes { meshes: scene.meshes, materials: scene.materials, textures: scene.textures, levels: 1, variants: f.variants }))
        }
        PlantLook::Tree(t) => {
            let system = read_lsystem(name, t)?;
            let variants = distinct_variants(&system, t);
            let mut out = InstanceMeshes { meshes: Vec::new(), materials: Vec::new(), textures: Vec::new(), levels: 1, variants };
            for k in 0..variants {
                let tree = build_tree(&system, &tree_options(name, t, k))
                    .map_err(|e| fail(format!("species `{name}`: {}: {e}", t.lsystem.display())))?;
                append_scene(&mut out, tree.scene);
            }
            Ok(Some(out))
        }
        PlantLook::Mesh(m) => {
            let source = load_model(name, m)?;
            let mut out = InstanceMeshes { meshes: Vec::new(), materials: Vec::new(), textures: Vec::new(), levels: 1, variants: 1 };
            append_scene(&mut out, source.scene);
            Ok(Some(out))
        }
    }
}

/// Appends a scene's meshes, renumbering its materials and textures; a texture or material equal
/// to one already held is shared (the variants of a tree use the same leaf texture and bark).
fn append_scene(out: &mut InstanceMeshes, scene: crate::mesh::Scene) {
    let textures: Vec<usize> = scene
        .textures
        .into_iter()
        .map(|t| match out.textures.iter().position(|o| o.png == t.png) {
            Some(i) => i,
            None => {
                out.textures.push(t);
                out.textures.len() - 1
            }
        })
        .collect();
    let materials: Vec<usize> = scene
        .materials
        .into_iter()
        .map(|m| {
            let m = m.with_textures(|i| Some(textures[i]));
            match out.materials.iter().position(|o| *o == m) {
                Some(i) => i,
                None => {
                    out.materials.push(m);
                    out.materials.len() - 1
                }
            }
        })
        .collect();
    for mut mesh in scene.meshes {
        for p in &mut mesh.primitives {
            p.material = p.material.map(|i| materials[i]);
        }
        out.meshes.push(mesh);
    }
}
