//! The chain builder every source shares: LoD0 and LoD1 as given, the atlas baked from the
//! reference, the card, billboard and impostor levels, the levels that save nothing left out, the
//! analyzer, and the MSFT_lod scene.

use std::time::Instant;

use serde_json::json;

use super::analyze::{measure_levels, Measured};
use super::cards::{
    appended, atlas_material, bake_atlas, branch_of, clusters, BakedAtlas, CardFrame, CardWind, Cluster, ModelFrame,
};
use super::simplify::{finer_than, simplify_below, simplify_sloppy, SIMPLIFY_RATIO, SLOPPY_RATIO};
use super::types::{
    AtlasCell, LeftOutLevel, Progress, TreeLod, TreeLodError, TreeLodFigures, TreeLodOptions, TreeLodReport, TreeLods,
    BILLBOARD_PLANES, IMPOSTOR_EXTRAS_KEY, IMPOSTOR_VIEWS, MAX_CLUSTERS,
};
use crate::bake::atlas::mip_figures;
use crate::bake::image::Image;
use crate::bake::views::Renderable;
use crate::lsystem::LSystem;
use crate::mesh::{Material, Mesh, Node, Primitive, Scene, Texture};
use crate::plants::mesh_asset::SourceMesh;
use crate::plants::tree::{build_tree, TreeOptions};
use crate::random::mix64;

pub(super) fn decode(textures: &[Texture]) -> Result<Vec<Image>, TreeLodError> {
    textures
        .iter()
        .map(|t| Image::from_png(&t.png).map_err(|e| TreeLodError::Texture(format!("{}: {e}", t.name))))
        .collect()
}

fn single_mesh_scene(name: &str, mesh: Mesh, materials: Vec<Material>, textures: Vec<Texture>) -> Scene {
    let mut scene = Scene { name: name.into(), materials, textures, ..Scene::default() };
    scene.add_mesh_node(Mesh { name: name.into(), ..mesh });
    scene
}

/// A tree's LoD1: the tree rebuilt with half the radial segments, as it is when that saves at least
/// a quarter of LoD0's triangles; simplified (meshoptimizer) when it does not (3-sided branches, a
/// plant of leaves and polygons, whose count halving the rings hardly changes). Edge collapse on top
/// of the rebuild halved the triangles again but flattened the thin twigs, which then vanish or
/// reappear pixel by pixel where LoD1 is shown: on the demo's first view the LoD scene differed from
/// full detail on 2.67 % of the pixels with a simplified LoD1 (4,352 triangles), 1.70 % with the
/// rebuild (8,280), whose measured silhouette error is within the budget at every distance.
fn lod1_mesh(half: &Mesh, lod0_triangles: usize) -> Result<Mesh, TreeLodError> {
    if half.triangle_count() * 4 <= lod0_triangles * 3 {
        return Ok(half.clone());
    }
    Ok(simplify_below(half, SIMPLIFY_RATIO, lod0_triangles)?)
}

/// A level's mesh with the materials and textures it refers to.
struct LevelParts {
    mesh: Mesh,
    materials: Vec<Material>,
    textures: Vec<Texture>,
}

/// How LoD2 is made from its source.
// one value per chain build: boxing the larger variant would buy nothing
#[allow(clippy::large_enum_variant)]
enum CoarseLevel {
    /// Trees: `kept` (the coarser branch levels of the LoD1 build) simplified below LoD1, plus
    /// crossed cards baked from the clusters of `dropped` (the finest level of the reference).
    Cards { kept: LevelParts, dropped: Mesh, dropped_levels: Vec<u32> },
    /// Meshes: LoD0 decimated much harder than LoD1 (meshoptimizer's sloppy simplifier, about
    /// SLOPPY_RATIO of the triangles, halved until below LoD1).
    Sloppy,
}

/// Everything the generic chain builder needs from a tree or a mesh asset.
struct ChainInput<'a> {
    name: String,
    /// Seeds the Hausdorff sampling.
    seed: u64,
    lod0: LevelParts,
    /// What the atlas is baked from and every level measured against: LoD0 itself, or for a tree
    /// with point leaves the same tree with quad leaves (points are not rasterised).
    reference: &'a Mesh,
    reference_materials: &'a [Material],
    reference_textures: &'a [Texture],
    lod1: Option<LevelParts>,
    coarse: CoarseLevel,
    started: Instant,
    /// Seconds growing LoD0 (0 for a loaded model).
    seconds_lod0: f64,
    /// Told each step as it starts.
    progress: Progress<'a>,
}

/// Builds the LoD chain of `system`'s tree, bakes its atlas and measures every level.
///
/// With `tree_options.leaf_points`, LoD0 and LoD1 draw leaves as points; the atlases, LoD2's cards
/// and the analyzer's reference use the same tree with quad leaves (a rasteriser does not draw
/// sprites), so the coarser levels look like those of the quad-leaf tree.
pub fn build_tree_lods(
    system: &LSystem,
    tree_options: &TreeOptions,
    options: &TreeLodOptions,
) -> Result<TreeLods, TreeLodError> {
    build_tree_lods_with(system, tree_options, options, &|_| {})
}

/// [`build_tree_lods`], saying each step to `progress` as it starts (LoD0, LoD1, the bake, the
/// textured levels, each level's measurement).
pub fn build_tree_lods_with(
    system: &LSystem,
    tree_options: &TreeOptions,
    options: &TreeLodOptions,
    progress: Progress,
) -> Result<TreeLods, TreeLodError> {
    options.check()?;
    let started = Instant::now();
    progress("LoD0: growing the tree");
    let lod0 = build_tree(system, tree_options)?;
    let quads = if tree_options.leaf_points {
        Some(build_tree(system, &TreeOptions { leaf_points: false, ..tree_options.clone() })?)
    } else {
        None
    };
    let seconds_lod0 = started.elapsed().as_secs_f64();
    let reference = quads.as_ref().unwrap_or(&lod0);
    let wanted = options.lods;
    let lod0_triangles = lod0.mesh().triangle_count();
    if wanted > 1 {
        progress("LoD1: half the radial segments");
    }
    let half = if wanted > 1 {
        Some(build_tree(
            system,
            &TreeOptions { radial_segments: (tree_options.radial_segments / 2).max(3), ..tree_options.clone() },
        )?)
    } else {
        None
    };
    let lod1 = half
        .as_ref()
        .map(|half| -> Result<LevelParts, TreeLodError> {
            Ok(LevelParts {
                mesh: lod1_mesh(half.mesh(), lod0_triangles)?,
                materials: half.scene.materials.clone(),
                textures: half.scene.textures.clone(),
            })
        })
        .transpose()?;
    let max_level = lod0.stats.max_branch_level;
    let coarse = match &half {
        Some(half) if max_level > 0 && wanted > 2 => CoarseLevel::Cards {
            kept: LevelParts {
                mesh: half.up_to_level(max_level - 1),
                materials: half.scene.materials.clone(),
                textures: half.scene.textures.clone(),
            },
            dropped: finer_than(reference, max_level - 1),
            dropped_levels: vec![max_level],
        },
        Some(half) => CoarseLevel::Cards {
            kept: LevelParts {
                mesh: half.mesh().clone(),
                materials: half.scene.materials.clone(),
                textures: half.scene.textures.clone(),
            },
            dropped: Mesh::default(),
            dropped_levels: Vec::new(),
        },
        None => CoarseLevel::Sloppy,
    };
    let input = ChainInput {
        name: tree_options.name.clone(),
        seed: tree_options.seed,
        lod0: LevelParts {
            mesh: lod0.mesh().clone(),
            materials: lod0.scene.materials.clone(),
            textures: lod0.scene.textures.clone(),
        },
        reference: reference.mesh(),
        reference_materials: &reference.scene.materials,
        reference_textures: &reference.scene.textures,
        lod1,
        coarse,
        started,
        seconds_lod0,
        progress,
    };
    let chain = build_chain(input, options)?;
    Ok(TreeLods { lod0: Some(lod0), ..chain })
}

/// Builds the LoD chain of a loaded mesh (an OBJ tree or rock): LoD0 the mesh, LoD1 meshoptimizer
/// simplification to about half, LoD2 sloppy decimation to about a tenth (strictly fewer triangles
/// than LoD1), LoD3 crossed billboards and LoD4 the impostor from the atlas baked from LoD0; every
/// level measured as a tree's. `name` names the meshes, nodes and atlas inside the files.
pub fn build_mesh_lods(source: &SourceMesh, name: &str, options: &TreeLodOptions) -> Result<TreeLods, TreeLodError> {
    build_mesh_lods_with(source, name, options, &|_| {})
}

/// [`build_mesh_lods`], saying each step to `progress` as it starts.
pub fn build_mesh_lods_with(
    source: &SourceMesh,
    name: &str,
    options: &TreeLodOptions,
    progress: Progress,
) -> Result<TreeLods, TreeLodError> {
    options.check()?;
    if options.lods > 1 {
        progress("LoD1: simplified");
    }
    let started = Instant::now();
    let mesh = source.mesh();
    if mesh.triangle_count() == 0 {
        return Err(TreeLodError::Options(format!("{name}: the mesh has no triangles")));
    }
    let lod1 = if options.lods > 1 {
        Some(LevelParts {
            mesh: simplify_below(mesh, SIMPLIFY_RATIO, mesh.triangle_count())?,
            materials: source.scene.materials.clone(),
            textures: source.scene.textures.clone(),
        })
    } else {
        None
    };
    let input = ChainInput {
        name: name.to_string(),
        seed: mix64(source.stats.triangles as u64),
        lod0: LevelParts {
            mesh: mesh.clone(),
            materials: source.scene.materials.clone(),
            textures: source.scene.textures.clone(),
        },
        reference: mesh,
        reference_materials: &source.scene.materials,
        reference_textures: &source.scene.textures,
        lod1,
        coarse: CoarseLevel::Sloppy,
        started,
        seconds_lod0: 0.0,
        progress,
    };
    build_chain(input, options)
}

/// The levels after LoD1, the atlas, the analyzer and the MSFT_lod scene, for any source.
fn build_chain(input: ChainInput, options: &TreeLodOptions) -> Result<TreeLods, TreeLodError> {
    let ChainInput {
        name,
        seed,
        lod0,
        reference,
        reference_materials,
        reference_textures,
        lod1,
        coarse,
        started,
        seconds_lod0,
        progress,
    } = input;
    let reference_images = decode(reference_textures)?;
    let reference = Renderable { mesh: reference, materials: reference_materials, textures: &reference_images };
    let card_wind = CardWind::of(&lod0.mesh);
    let (mut levels, lod1_source) = first_levels(&name, lod0, lod1)?;
    let seconds_meshes = started.elapsed().as_secs_f64();

    let frame = ModelFrame::of(reference.mesh)?;
    let bake_started = Instant::now();
    let (dropped_levels, groups) = match &coarse {
        CoarseLevel::Cards { dropped, dropped_levels, .. } if !dropped_levels.is_empty() => {
            // cards take at most half of LoD1's triangle count (4 triangles a card)
            let max_clusters = levels.get(1).map_or(0, |l| (l.triangles() / 8).min(MAX_CLUSTERS));
            (dropped_levels.clone(), clusters(dropped, max_clusters))
        }
        _ => (Vec::new(), Vec::new()),
    };
    if options.lods > 2 {
        progress(&format!("baking the atlas: {} views", 2 * (IMPOSTOR_VIEWS + 2 * groups.len())));
    }
    let atlas = bake_atlas(&reference, &frame, &groups, options)?;
    let seconds_bake = bake_started.elapsed().as_secs_f64();
    let cards_started = Instant::now();
    if let Some(lod1_source) = &lod1_source {
        let sources = CoarseSources { name: &name, lod1: lod1_source, coarse: &coarse, groups: &groups, card_wind };
        if options.lods > 2 {
            progress("cards, billboards and the impostor");
        }
        textured_levels(&sources, &mut levels, &atlas, &frame, options.atlas_px)?;
    }
    levels.truncate(options.lods);
    let (levels, left_out) = without_levels_that_save_nothing(&name, levels);
    let seconds_cards = cards_started.elapsed().as_secs_f64();

    let mut measured = measure_levels(&levels, &reference, &frame, &atlas.impostor_cells, seed, options, progress)?;
    let chain = chain_scene(&name, &levels, &measured.lods);
    fold_quantization(&mut measured, &chain, options);
    let report = TreeLodReport {
        name: name.clone(),
        seed,
        atlas_px: options.atlas_px,
        bounding_radius_m: frame.radius,
        clusters: groups.len(),
        dropped_levels,
        left_out,
        lods: measured.lods,
        table: measured.table,
        atlas_mips: mip_figures(&atlas.mips),
        seconds_meshes,
        seconds_lod0,
        seconds_lod1: seconds_meshes - seconds_lod0,
        seconds_bake,
        seconds_cards,
        seconds_analyze: measured.seconds,
        seconds_hausdorff: measured.seconds_hausdorff,
        seconds_image: measured.seconds_image,
        raster_fragments: atlas.fragments,
        analysis_views: measured.views,
        analysis_reduced: measured.reduced.clone(),
    };
    Ok(TreeLods {
        name,
        levels,
        chain,
        atlas: atlas.mips,
        normal_atlas: atlas.normal,
        impostor_cells: atlas.impostor_cells,
        report,
        lod0: None,
    })
}

/// LoD0 and LoD1 as levels, and LoD1's materials and textures (what a decimated LoD2 uses).
#[allow(clippy::type_complexity)]
fn first_levels(
    name: &str,
    lod0: LevelParts,
    lod1: Option<LevelParts>,
) -> Result<(Vec<TreeLod>, Option<(Vec<Material>, Vec<Texture>)>), TreeLodError> {
    let images0 = decode(&lod0.textures)?;
    let mut levels = vec![TreeLod {
        level: 0,
        kind: "full",
        scene: single_mesh_scene(&format!("{name}_LOD0"), lod0.mesh, lod0.materials, lod0.textures),
        images: images0,
    }];
    let lod1_source = lod1.as_ref().map(|l| (l.materials.clone(), l.textures.clone()));
    if let Some(lod1) = lod1 {
        // a model too small to simplify (a 12-triangle box) keeps LoD0's mesh here: the level then
        // saves nothing and is left out of the written chain, which goes on to the card levels
        let (mesh, materials, textures) = if lod1.mesh.primitives.is_empty() {
            let lod0 = &levels[0].scene;
            (lod0.meshes[0].clone(), lod0.materials.clone(), lod0.textures.clone())
        } else {
            (lod1.mesh, lod1.materials, lod1.textures)
        };
        let images = decode(&textures)?;
        levels.push(TreeLod {
            level: 1,
            kind: "simplified",
            scene: single_mesh_scene(&format!("{name}_LOD1"), mesh, materials, textures),
            images,
        });
    }
    Ok((levels, lod1_source))
}

/// What the levels after LoD1 are made from.
struct CoarseSources<'a> {
    name: &'a str,
    /// LoD1's materials and textures.
    lod1: &'a (Vec<Material>, Vec<Texture>),
    coarse: &'a CoarseLevel,
    /// The leaf clusters LoD2's cards stand for.
    groups: &'a [Cluster],
    card_wind: Option<CardWind>,
}

/// LoD2 (cards or decimated), LoD3 (crossed billboards) and LoD4 (the impostor) after `levels`'
/// LoD0 and LoD1; nothing when no atlas was baked (a chain of two levels or fewer).
fn textured_levels(
    sources: &CoarseSources,
    levels: &mut Vec<TreeLod>,
    atlas: &BakedAtlas,
    frame: &ModelFrame,
    px: u32,
) -> Result<(), TreeLodError> {
    let (Some(atlas0), Some(normal_img)) = (atlas.mips.first(), &atlas.normal) else { return Ok(()) };
    let CoarseSources { name, lod1: (lod1_materials, lod1_textures), coarse, groups, card_wind } = *sources;
    let (atlas_png, normal_png) = rayon::join(|| atlas0.image.encode_png(), || normal_img.encode_png_data());
    let atlas_tex =
        Texture { name: format!("{name}_atlas"), png: atlas_png.map_err(|e| TreeLodError::Texture(e.to_string()))? };
    let normal_tex = Texture {
        name: format!("{name}_atlas_normal"),
        png: normal_png.map_err(|e| TreeLodError::Texture(e.to_string()))?,
    };
    let impostor_cells = &atlas.impostor_cells;
    let lod1_triangles = levels[1].triangles();
    let (mesh, materials, textures, images) = match coarse {
        CoarseLevel::Cards { kept, .. } => {
            // LoD2: the coarser branch levels simplified, plus the cards; simplified harder
            // until it has fewer triangles than LoD1
            let mut cards = Primitive::default();
            for (c, g) in groups.iter().enumerate() {
                let branch = branch_of(&g.mesh);
                for side in 0..2 {
                    let card = CardFrame { centre: g.centre, azimuth_deg: 90.0 * side as f64, side_m: g.side_m };
                    let quad = card.quad(AtlasCell::small(px, 2 * c + side).uv);
                    cards = appended(cards, &card_wind.map_or(quad.clone(), |w| w.on(quad, Some(branch))));
                }
            }
            let below = lod1_triangles.saturating_sub(cards.triangle_count());
            let mut ratio = SIMPLIFY_RATIO;
            let mut mesh = simplify_below(&kept.mesh, ratio, below)?;
            while mesh.triangle_count() >= below && ratio > 0.01 {
                ratio /= 2.0;
                mesh = simplify_below(&kept.mesh, ratio, below)?;
            }
            let mut materials = kept.materials.clone();
            let mut textures = kept.textures.clone();
            let mut images = decode(&textures)?;
            if !cards.indices.is_empty() {
                textures.push(atlas_tex.clone());
                images.push(atlas0.image.clone());
                materials.push(atlas_material(textures.len() - 1));
                textures.push(normal_tex.clone());
                images.push(normal_img.clone());
                cards.material = Some(materials.len() - 1);
                mesh.primitives.push(cards);
            }
            (mesh, materials, textures, images)
        }
        CoarseLevel::Sloppy => {
            let lod0_mesh = &levels[0].scene.meshes[0];
            let mut ratio = SLOPPY_RATIO;
            let mut mesh = simplify_sloppy(lod0_mesh, ratio)?;
            while mesh.triangle_count() >= lod1_triangles && ratio > 1e-4 {
                ratio /= 2.0;
                mesh = simplify_sloppy(lod0_mesh, ratio)?;
            }
            if mesh.primitives.is_empty() {
                // nothing left to decimate: LoD1's mesh, left out below as saving nothing
                let lod1 = &levels[1].scene;
                (lod1.meshes[0].clone(), lod1.materials.clone(), lod1.textures.clone(), levels[1].images.clone())
            } else {
                (mesh, lod1_materials.clone(), lod1_textures.clone(), levels[1].images.clone())
            }
        }
    };
    levels.push(TreeLod {
        level: 2,
        kind: if matches!(coarse, CoarseLevel::Sloppy) { "decimated" } else { "cards" },
        scene: single_mesh_scene(&format!("{name}_LOD2"), mesh, materials, textures),
        images,
    });
    // LoD3: crossed billboards
    let mut planes = Primitive { material: Some(0), ..Primitive::default() };
    for (k, cell) in impostor_cells.iter().take(BILLBOARD_PLANES).enumerate() {
        let quad = frame.view(k).quad(cell.uv);
        planes = appended(planes, &card_wind.map_or(quad.clone(), |w| w.on(quad, None)));
    }
    let mesh = Mesh { name: String::new(), primitives: vec![planes], extras: None };
    levels.push(TreeLod {
        level: 3,
        kind: "billboards",
        scene: single_mesh_scene(
            &format!("{name}_LOD3"),
            mesh,
            vec![atlas_material(0)],
            vec![atlas_tex.clone(), normal_tex.clone()],
        ),
        images: vec![atlas0.image.clone(), normal_img.clone()],
    });
    // LoD4: the impostor quad facing +Z (view 0), the others' cells in the extras
    let quad = frame.view(0).quad(impostor_cells[0].uv);
    let quad = Primitive { material: Some(0), ..card_wind.map_or(quad.clone(), |w| w.on(quad, None)) };
    let extras = json!({ IMPOSTOR_EXTRAS_KEY: {
        "views": IMPOSTOR_VIEWS,
        "azimuth_step_deg": 360.0 / IMPOSTOR_VIEWS as f64,
        "view_from_direction": "k = round(atan2(dx, dz) / azimuth_step_deg) mod views, (dx, dz) from the centre to the eye",
        "face_camera_about": "y axis through centre",
        "centre": frame.centre.to_array(),
        "size_m": frame.side_m,
        "cells_uv": impostor_cells.iter().map(|c| c.uv).collect::<Vec<_>>(),
    }});
    let mesh = Mesh { name: String::new(), primitives: vec![quad], extras: Some(extras) };
    let scene = single_mesh_scene(
        &format!("{name}_LOD4"),
        mesh,
        vec![atlas_material(0)],
        vec![atlas_tex.clone(), normal_tex.clone()],
    );
    levels.push(TreeLod { level: 4, kind: "impostor", scene, images: vec![atlas0.image.clone(), normal_img.clone()] });
    Ok(())
}

/// `levels` without those that are empty or draw no fewer triangles than the level kept before
/// them; the rest renumbered 0, 1, 2, … (files and names `_LOD<n>` stay contiguous).
fn without_levels_that_save_nothing(name: &str, levels: Vec<TreeLod>) -> (Vec<TreeLod>, Vec<LeftOutLevel>) {
    let mut kept: Vec<TreeLod> = Vec::with_capacity(levels.len());
    let mut left_out = Vec::new();
    for lod in levels {
        let empty = lod.scene.meshes.first().is_none_or(|m| m.primitives.is_empty());
        match kept.last().map(TreeLod::triangles) {
            Some(previous) if empty || lod.triangles() >= previous => {
                left_out.push(LeftOutLevel {
                    kind: lod.kind.to_string(),
                    planned_level: lod.level,
                    triangles: lod.triangles(),
                    previous_triangles: previous,
                });
            }
            _ => kept.push(lod),
        }
    }
    for (n, lod) in kept.iter_mut().enumerate() {
        if lod.level != n {
            let renamed = format!("{name}_LOD{n}");
            lod.level = n;
            lod.scene.name = renamed.clone();
            for mesh in &mut lod.scene.meshes {
                mesh.name = renamed.clone();
            }
            for node in &mut lod.scene.nodes {
                node.name = renamed.clone();
            }
        }
    }
    (kept, left_out)
}

/// Each level's error as stored: the chain file's levels share one grid (over all of them), which
/// may be coarser than a level file's own, so a level's quantization is the larger of the two;
/// LoD0's is added to every level's, as the reference itself moved.
pub(super) fn fold_quantization(measured: &mut Measured, chain: &Scene, options: &TreeLodOptions) {
    let in_chain = crate::export::quantize::position_error(chain, &options.compact.write_options().quantization);
    for l in &mut measured.lods {
        l.quantization_m = l.quantization_m.max(in_chain);
    }
    let lod0 = measured.lods.first().map_or(0.0, |l| l.quantization_m);
    for (l, row) in measured.lods.iter_mut().zip(&mut measured.table) {
        l.stored_error_m = l.geometric_error.max_m + l.quantization_m + if l.level > 0 { lod0 } else { 0.0 };
        row.stored_error_m = l.stored_error_m;
    }
}

/// `<name>.glb`: LoD0's node with MSFT_lod to the coarser levels' nodes (not roots) and
/// `MSFT_screencoverage` from the measured switch distances; equal textures stored once.
fn chain_scene(name: &str, levels: &[TreeLod], lods: &[TreeLodFigures]) -> Scene {
    let mut scene = Scene { name: name.into(), ..Scene::default() };
    let mut ids = Vec::new();
    for lod in levels {
        let src = &lod.scene;
        let texture_map: Vec<usize> = src
            .textures
            .iter()
            .map(|t| match scene.textures.iter().position(|u| u == t) {
                Some(i) => i,
                None => {
                    scene.textures.push(t.clone());
                    scene.textures.len() - 1
                }
            })
            .collect();
        let material_base = scene.materials.len();
        scene.materials.extend(src.materials.iter().map(|m| m.with_textures(|t| texture_map.get(t).copied())));
        let mut mesh = src.meshes[0].clone();
        for p in &mut mesh.primitives {
            p.material = p.material.map(|m| m + material_base);
        }
        scene.meshes.push(mesh);
        scene.nodes.push(Node { name: src.name.clone(), mesh: Some(scene.meshes.len() - 1), ..Node::default() });
        ids.push(scene.nodes.len() - 1);
    }
    let root = ids[0];
    scene.nodes[root].lods = ids[1..].to_vec();
    let mut coverage: Vec<f32> = lods.iter().skip(1).map(|l| l.screen_coverage as f32).collect();
    if !coverage.is_empty() {
        coverage.push(0.0);
    }
    scene.nodes[root].lod_screen_coverage = coverage;
    scene.roots.push(root);
    scene
}
