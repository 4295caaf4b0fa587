//! What grows on the terrain, for the terrain stage: every species' density at each texel of the
//! terrain's layer map, from its placement rules on the terrain surface (density map, mask,
//! vegetation type, slope, altitude, water; exclusions and snow thinning aside). These are the
//! values the scatter stage writes as `placements/density_<k>.png` for every species snow does not
//! thin. The terrain's soil layer and its `_SURFACE` attribute are baked from them
//! ([`crate::terrain::vegetation::VegetationCover`]).

use std::path::PathBuf;

use crate::mesh::Scene;
use crate::plants::SpeciesKind;
use crate::scatter::density::DensityMap;
use crate::scatter::SurfaceIndex;
use crate::scene::cache::{sha256_hex, KeyBuilder};
use crate::scene::error::StageError;
use crate::scene::{PlantLook, Preset, SpeciesSettings, TreeLook};
use crate::terrain::vegetation::{Ground, SpeciesCover, VegetationCover};

/// The terrain surface of a terrain scene, where the rules are read and instances stand: every
/// primitive of every mesh (skirts and base are vertical or face down; the surface index skips
/// those triangles).
pub fn surface_of(terrain: &Scene) -> SurfaceIndex {
    surface_of_parts(terrain.meshes.iter().flat_map(|m| m.primitives.iter()))
}

/// The terrain surface of some of a terrain's primitives (e.g. a band's chunks): [`surface_of`].
pub fn surface_of_parts<'a>(primitives: impl Iterator<Item = &'a crate::mesh::Primitive>) -> SurfaceIndex {
    let parts: Vec<(&[[f32; 3]], &[u32])> = primitives.map(|p| (&p.positions[..], &p.indices[..])).collect();
    SurfaceIndex::from_parts(&parts)
}

/// A map the rules read, decoded; errors name the file and are the input's fault.
fn load(path: &Option<PathBuf>, stage: &'static str) -> Result<Option<DensityMap>, StageError> {
    path.as_ref()
        .map(|p| DensityMap::load(p).map_err(|e| StageError::Input { stage, message: e.to_string() }))
        .transpose()
}

/// `[scatter] vegetation_map`, decoded when a species names a `vegetation_type`.
pub fn vegetation_map(preset: &Preset, stage: &'static str) -> Result<Option<DensityMap>, StageError> {
    if preset.species.iter().any(|s| s.vegetation_type.is_some()) {
        load(&preset.scatter.vegetation_map, stage)
    } else {
        Ok(None)
    }
}

/// A species' density map and mask as its rules read them: the mask narrowed to where the map of
/// vegetation types holds its shade when it has a `vegetation_type`.
pub fn rule_maps(
    species: &SpeciesSettings,
    vegetation: Option<&DensityMap>,
    stage: &'static str,
) -> Result<(Option<DensityMap>, Option<DensityMap>), StageError> {
    let density = load(&species.rules.density_map, stage)?;
    let mask = load(&species.rules.mask, stage)?;
    let mask = match (species.vegetation_type, vegetation) {
        (Some(shade), Some(types)) => Some(types.where_shade(shade, mask.as_ref())),
        _ => mask,
    };
    Ok((density, mask))
}

/// Adds what the cover reads to a stage's cache key: the seed, the scatter settings and every
/// species' rules, kind and look (its height and footprint), and the bytes of the maps they name
/// (a map that does not read adds a marker: the scatter stage reports it).
pub fn add_key(k: &mut KeyBuilder, preset: &Preset) {
    k.add(b"ground cover 1");
    k.add(&preset.scene.seed.to_le_bytes());
    k.add(serde_json::to_string(&preset.scatter).unwrap_or_default().as_bytes());
    let mut maps = vec![&preset.scatter.vegetation_map];
    for s in &preset.species {
        k.add(serde_json::to_string(s).unwrap_or_default().as_bytes());
        maps.extend([&s.rules.density_map, &s.rules.mask]);
    }
    for map in maps.into_iter().flatten() {
        match crate::input::read_limited(map, crate::input::MAX_IMAGE_BYTES, "a map") {
            Ok(bytes) => k.add(sha256_hex(&bytes).as_bytes()),
            Err(_) => k.add(b"unreadable"),
        };
    }
}

/// Height in metres of one of the species' plants at the middle of its scale range: a tree's
/// `height`, the middle of a grass or flower height range, else the kind's nominal height.
pub fn plant_height_m(species: &SpeciesSettings) -> f64 {
    let mid_scale = 0.5 * (species.rules.scale[0] + species.rules.scale[1]);
    let height = match &species.look {
        PlantLook::Tree(TreeLook { height_m: Some(h), .. }) => *h,
        PlantLook::Grass(g) => 0.5 * (g.height_m[0] + g.height_m[1]) as f64,
        PlantLook::Flower(f) => 0.5 * (f.height_m[0] + f.height_m[1]) as f64,
        _ => crate::plants::palette::nominal_height_m(species.kind) as f64,
    };
    height * mid_scale
}

/// Every species' density on a `size` texel grid over the terrain surface of `terrain` (the
/// terrain's layer map); `None` without species, or when a species' maps or rules are at fault
/// (the scatter stage, which reads the same, names the error).
pub fn cover(preset: &Preset, terrain: &Scene, size: [u32; 2]) -> Option<VegetationCover> {
    let surface = surface_of(terrain);
    let extent = surface.bounds();
    cover_rows(preset, &surface, extent, size, 0..size[1] as usize)
}

/// [`cover`]'s texel rows `rows` alone (`first_row` their first), from `surface`: the terrain's
/// surface, or the part of it that alone covers those texel centres (a band's chunks, whose faces
/// end on its lines), over the terrain's `extent` (its surface's bounds, [`terrain_extent`]). The
/// same weights as those rows of the whole cover, bit for bit.
pub fn cover_rows(
    preset: &Preset,
    surface: &SurfaceIndex,
    extent: [f64; 4],
    size: [u32; 2],
    rows: std::ops::Range<usize>,
) -> Option<VegetationCover> {
    if preset.species.is_empty() {
        return None;
    }
    let tiling = crate::scatter::Tiling::new(extent, preset.scatter.tile_m).ok()?;
    // which triangle holds each texel centre: one location for every species
    let texels = surface.locate_texel_rows(extent, size[0], size[1], rows.clone());
    let vegetation = vegetation_map(preset, "terrain").ok()?;
    let mut species = Vec::with_capacity(preset.species.len());
    for s in &preset.species {
        let (density, mask) = rule_maps(s, vegetation.as_ref(), "terrain").ok()?;
        let rules = crate::scatter::rules::Rules::without_exclusions(
            surface,
            tiling,
            &s.rules,
            density.as_ref(),
            mask.as_ref(),
            preset.scene.seed,
        )
        .ok()?;
        let footprint = crate::scene::preview::footprint_m(s);
        species.push(SpeciesCover {
            ground: match s.kind {
                SpeciesKind::Grass | SpeciesKind::Flower => Ground::Grass,
                SpeciesKind::Tree | SpeciesKind::Mesh => Ground::Canopy,
            },
            max_density: rules.effective_max_density,
            height_m: plant_height_m(s),
            footprint_m2: std::f64::consts::FRAC_PI_4 * footprint * footprint,
            weights: crate::scatter::rules::weight_map_located(&rules, &texels),
        });
    }
    Some(VegetationCover { extent, size, species, first_row: texels.first })
}

/// The extent a terrain's surface index has ([`crate::scatter::SurfaceIndex::bounds`]) for a map
/// of `width` × `height` samples `cell_m` apart: x from 0 to (width − 1)·cell, z likewise, as the
/// vertices store them (f32).
pub fn terrain_extent(width: usize, height: usize, cell_m: f64) -> [f64; 4] {
    let at = |i: usize| (i.saturating_sub(1) as f64 * cell_m) as f32 as f64;
    [0.0, 0.0, at(width), at(height)]
}
