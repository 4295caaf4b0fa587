//! The plants stage: for every grass and flower species, its meshes at every level of detail
//! (`species/`), the baked atlases with their mip chains (`atlases/`) and the analyzer's figures.
//! Independent of the terrain; the scatter stage instances what this makes.

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
use crate::scene::{PlantLook, Preset};

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
    pub seconds: f64,
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

/// Cache key: every generated look (settings, seeds) and the bytes of any user blade texture.
pub fn plants_key(preset: &Preset) -> Result<String, StageError> {
    let mut k = KeyBuilder::new("plants");
    for s in &preset.species {
        k.add(s.name.as_bytes());
        k.add(serde_json::to_string(&s.look).unwrap_or_default().as_bytes());
        if let PlantLook::Grass(GrassSettings { blade_texture: Some(p), .. }) = &s.look {
            let bytes = std::fs::read(p).map_err(|e| fail(format!("{}: cannot read: {e}", p.display())))?;
            k.add(sha256_hex(&bytes).as_bytes());
        }
    }
    Ok(k.finish())
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
        let (grass_report, flower_report) = match &s.look {
            PlantLook::Marker => continue,
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
                (Some(asset.report), None)
            }
            PlantLook::Flower(f) => {
                let asset = build_flower(name, f).map_err(|e| fail(format!("species `{name}`: {e}")))?;
                write(&asset.scene, scene_dir, PathBuf::from("species").join(format!("{name}.glb")), &mut files)?;
                write_mips(scene_dir, name, &asset.atlas, &mut files)?;
                (None, Some(asset.report))
            }
        };
        species.push(PlantReport {
            name: name.clone(),
            files,
            grass: grass_report.map(|r: GrassReport| serde_json::to_value(r).unwrap_or_default()),
            flower: flower_report.map(|r: FlowerReport| serde_json::to_value(r).unwrap_or_default()),
            seconds: t1.elapsed().as_secs_f64(),
        });
    }
    Ok(PlantsStageReport { species, seconds: t0.elapsed().as_secs_f64() })
}

/// The meshes scene.glb instances for a species with a generated look: grass LoD0 clumps (index
/// level · variants + variant) with the blade material, or the flower variants' crossed cards.
pub struct InstanceMeshes {
    pub meshes: Vec<Mesh>,
    pub material: Material,
    pub texture: Texture,
    /// Grass: density levels (clumps are chosen by local density); flowers: 1.
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
                    let prim = grass::lod0(g, &c, 0);
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
            Ok(Some(InstanceMeshes { meshes, material, texture: Texture { name: format!("{name}_blade"), png }, levels: g.density_levels, variants: g.variants }))
        }
        PlantLook::Flower(f) => {
            let f: &FlowerSettings = f;
            let asset = build_flower(name, f).map_err(|e| fail(format!("species `{name}`: {e}")))?;
            let scene = asset.scene;
            let meshes = scene.meshes.clone();
            let material = scene.materials[0].clone();
            let texture = scene.textures[0].clone();
            Ok(Some(InstanceMeshes { meshes, material, texture, levels: 1, variants: f.variants }))
        }
    }
}
