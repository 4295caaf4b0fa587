//! Every card of every shipped species reads only its own atlas cell: each triangle drawn with an
//! atlas material has all three texture coordinates inside one cell's inside (within the gutter of
//! transparent, dilated texels that keeps filtering and mips from reading a neighbour). A card whose
//! V ran past its cell (the old flowers: 0..1.458 with repeat wrapping) showed a second flower head
//! on the ground. Flowers also must meet the ground: the card's bottom edge samples the cell's
//! bottom row, where the stem was drawn.

use std::path::{Path, PathBuf};

use verdant::mesh::Scene;
use verdant::plants::flower::build_flower;
use verdant::plants::grass_asset::build_grass;
use verdant::plants::tree_lod::{atlas_cell_rects, TreeLods};
use verdant::scene::plants_stage::{mesh_chain, read_lsystem, tree_chain, user_blade, SpeciesOutput};
use verdant::scene::preset::{demo_preset, load_preset};
use verdant::scene::{PlantLook, Preset};

use crate::wind::{check_plant_scene, Expect};

const EPS: f32 = 1e-6;

fn shipped_presets() -> Vec<(String, Preset)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("presets");
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.sort();
    assert!(paths.len() >= 3, "shipped presets in {}", dir.display());
    let mut out = vec![("demo".to_string(), demo_preset())];
    out.extend(paths.iter().map(|p| (p.display().to_string(), load_preset(p).unwrap_or_else(|e| panic!("{e}")))));
    out
}

fn inside(uv: [f32; 2], r: &[f32; 4]) -> bool {
    uv[0] >= r[0] - EPS && uv[0] <= r[2] + EPS && uv[1] >= r[1] - EPS && uv[1] <= r[3] + EPS
}

/// Every primitive with texture coordinates has a textured material (no UV a viewer ignores: the
/// Khronos validator reports those as unused).
fn uvs_are_used(what: &str, scene: &Scene) {
    for mesh in &scene.meshes {
        for (k, p) in mesh.primitives.iter().enumerate() {
            if p.uvs.is_empty() {
                continue;
            }
            let textured = p.material.is_some_and(|m| scene.materials[m].base_color_texture.is_some());
            assert!(textured, "{what}: mesh {} primitive {k} has UVs but its material has no texture", mesh.name);
        }
    }
}

/// Checks every triangle drawn with a texture whose name ends in `_atlas`; returns how many.
fn check_cards(what: &str, scene: &Scene, cells: &[[f32; 4]]) -> usize {
    uvs_are_used(what, scene);
    let mut checked = 0;
    for mesh in &scene.meshes {
        for p in &mesh.primitives {
            let Some(m) = p.material else { continue };
            let Some(t) = scene.materials[m].base_color_texture else { continue };
            if !scene.textures[t].name.ends_with("_atlas") {
                continue;
            }
            assert_eq!(p.uvs.len(), p.positions.len(), "{what}: mesh {} has no uv per vertex", mesh.name);
            for (k, tri) in p.indices.chunks_exact(3).enumerate() {
                let uv = [tri[0], tri[1], tri[2]].map(|i| p.uvs[i as usize]);
                assert!(
                    cells.iter().any(|c| uv.iter().all(|&q| inside(q, c))),
                    "{what}: mesh {} triangle {k} reads outside every atlas cell: uvs {uv:?}",
                    mesh.name
                );
                checked += 1;
            }
        }
    }
    checked
}

/// Lit cards: every material drawing a tree atlas also has the atlas' normal map as its
/// normalTexture, and that map holds unit normals facing the viewer (tangent space, +Z towards it).
fn check_normal_maps(what: &str, scene: &Scene) -> usize {
    let mut checked = 0;
    for m in &scene.materials {
        let Some(t) = m.base_color_texture else { continue };
        if !scene.textures[t].name.ends_with("_atlas") {
            continue;
        }
        let n = m
            .normal_texture
            .unwrap_or_else(|| panic!("{what}: material {} draws an atlas without a normal map", m.name));
        assert!(scene.textures[n].name.ends_with("_atlas_normal"), "{what}: normal map {}", scene.textures[n].name);
        // glTF reads a normalTexture as linear data: the bytes as stored, not sRGB-decoded
        let img = verdant::bake::image::Image::from_png_data(&scene.textures[n].png).unwrap();
        for p in &img.pixels {
            let v = [p[0] * 2.0 - 1.0, p[1] * 2.0 - 1.0, p[2] * 2.0 - 1.0];
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            // 8-bit texels: each component within 1/255
            assert!((len - 1.0).abs() < 0.02 && v[2] >= -0.01, "{what}: normal texel {p:?} (length {len})");
        }
        checked += 1;
    }
    checked
}

/// A tree or mesh chain: the MSFT_lod file and every level against the tree atlas' cells.
fn check_chain(what: &str, chain: &TreeLods, atlas_px: u32, sways: bool) {
    let cells = atlas_cell_rects(atlas_px);
    let mut n = check_cards(&format!("{what} chain"), &chain.chain, &cells);
    for level in &chain.levels {
        n += check_cards(&format!("{what} LOD{}", level.level), &level.scene, &cells);
        // wind: the full tree and its simplified level bend branches; the card levels sway
        let expect = match (sways, level.kind) {
            (false, _) => Expect::Nothing,
            (true, "full" | "simplified") => Expect::SwayAndBranch,
            (true, _) => Expect::Sway,
        };
        check_plant_scene(&format!("{what} LOD{}", level.level), &level.scene, expect);
        if matches!(level.kind, "cards" | "billboards" | "impostor") {
            assert!(
                check_normal_maps(&format!("{what} LOD{}", level.level), &level.scene) > 0,
                "{what} LOD{}: no lit card material",
                level.level
            );
        }
    }
    assert!(n > 0, "{what}: no atlas cards checked");
}

#[test]
fn every_shipped_card_stays_inside_its_atlas_cell() {
    let mut kinds = std::collections::BTreeSet::new();
    for (preset_name, preset) in shipped_presets() {
        for s in &preset.species {
            let what = format!("{preset_name}: species `{}`", s.rules.name);
            match &s.look {
                PlantLook::Marker => continue,
                PlantLook::Grass(g) => {
                    let blade = user_blade(g).unwrap();
                    let asset = build_grass(&s.rules.name, g, blade.as_ref()).unwrap();
                    let cells: Vec<[f32; 4]> = asset.cells.iter().map(|c| c.uv).collect();
                    let mut n = check_cards(&format!("{what} chain"), &asset.chain, &cells);
                    for (k, scene) in asset.lod_scenes.iter().enumerate() {
                        n += check_cards(&format!("{what} LOD{k}"), scene, &cells);
                    }
                    n += check_cards(&format!("{what} far field"), &asset.far, &cells);
                    assert!(n > 0, "{what}: no atlas cards checked");
                    for (k, scene) in asset.lod_scenes.iter().enumerate() {
                        assert!(check_plant_scene(&format!("{what} LOD{k}"), scene, Expect::Sway) > 0);
                    }
                    check_plant_scene(&format!("{what} chain"), &asset.chain, Expect::Sway);
                    check_plant_scene(&format!("{what} far field"), &asset.far, Expect::Sway);
                    // lit cards: LoD2, LoD3, the far field and the chain's atlas material
                    let lit: usize = [&asset.lod_scenes[2], &asset.lod_scenes[3], &asset.far, &asset.chain]
                        .iter()
                        .map(|sc| check_normal_maps(&what, sc))
                        .sum();
                    assert!(lit >= 4, "{what}: {lit} lit card materials");
                    kinds.insert("grass");
                }
                PlantLook::Flower(f) => {
                    let asset = build_flower(&s.rules.name, f).unwrap();
                    let cells: Vec<[f32; 4]> = asset.cells.iter().map(|c| c.uv).collect();
                    assert!(check_cards(&what, &asset.scene, &cells) > 0, "{what}: no atlas cards checked");
                    assert!(check_plant_scene(&what, &asset.scene, Expect::Sway) > 0);
                    assert_eq!(check_normal_maps(&what, &asset.scene), 1, "{what}: the flower cards are lit");
                    for (v, c) in asset.cells.iter().enumerate() {
                        // the card's bottom (y = 0) samples the cell's bottom row: the stem meets the ground
                        assert!(
                            (c.card_uv[3] - c.uv[3]).abs() < EPS,
                            "{what} v{v}: card bottom {} vs cell bottom {}",
                            c.card_uv[3],
                            c.uv[3]
                        );
                        let prim = &asset.scene.meshes[v].primitives[0];
                        for (pos, uv) in prim.positions.iter().zip(&prim.uvs) {
                            if pos[1] == 0.0 {
                                assert!(
                                    (uv[1] - c.uv[3]).abs() < EPS,
                                    "{what} v{v}: a ground vertex samples v = {}",
                                    uv[1]
                                );
                            }
                        }
                    }
                    kinds.insert("flower");
                }
                PlantLook::Tree(t) => {
                    let system = read_lsystem(&s.rules.name, t).unwrap();
                    check_chain(
                        &what,
                        &tree_chain(&s.rules.name, t, &system, 0, SpeciesOutput::of(&preset)).unwrap(),
                        t.atlas_px,
                        true,
                    );
                    kinds.insert("tree");
                }
                PlantLook::Mesh(m) => {
                    check_chain(
                        &what,
                        &mesh_chain(&s.rules.name, m, SpeciesOutput::of(&preset)).unwrap().1,
                        m.atlas_px,
                        false,
                    );
                    kinds.insert("mesh");
                }
            }
        }
    }
    // the shipped presets exercise every generated look
    assert_eq!(kinds.into_iter().collect::<Vec<_>>(), ["flower", "grass", "mesh", "tree"]);
}

#[test]
fn a_tall_flower_card_fits_its_cell() {
    // taller than twice its width: the old atlas clipped the card's bottom and stretched V past 1
    let s = verdant::plants::flower::FlowerSettings { height_m: [0.6, 0.9], ..Default::default() };
    s.check().unwrap();
    let asset = build_flower("tall", &s).unwrap();
    for c in &asset.cells {
        assert!(c.card_uv.iter().all(|v| (0.0..=1.0).contains(v)), "{c:?}");
        assert!(
            c.card_uv[0] >= c.uv[0] - EPS
                && c.card_uv[2] <= c.uv[2] + EPS
                && c.card_uv[1] >= c.uv[1] - EPS
                && c.card_uv[3] <= c.uv[3] + EPS,
            "{c:?}"
        );
    }
    let cells: Vec<[f32; 4]> = asset.cells.iter().map(|c| c.uv).collect();
    assert!(check_cards("tall flower", &asset.scene, &cells) > 0);
}
