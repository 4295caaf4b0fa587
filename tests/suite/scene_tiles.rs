//! Scene tiles (`[scene] tile`, issue 18): the scene of scene_lod.glb cut into square GLBs and
//! `scene_tiles.json` — every chain of scene_lod.glb in exactly one tile, the same geometry,
//! instances and coverages; each tile's box holding what it holds; the terrain's textures cropped
//! to what the tile's chunks read, sampled at the same texels; clear errors for bad `tile` values.

use std::collections::BTreeMap;

use verdant::mesh::{Node, Scene};

use crate::common::*;

/// fbm 193² with 2 m cells (384 m across), 64² chunks (128 m) with a three-level terrain chain,
/// rocks and grass, tiles of `tile` metres.
fn preset(tile: &str) -> String {
    format!(
        "[scene]\nname = \"tiled\"\nseed = 5\n{tile}\n\n[terrain]\n\
         procedural = {{ kind = \"fbm\", size = 193, seed = 3, relief = 30.0 }}\n\
         cell_size = 2.0\nmax_error = 0.1\nchunk = 64\nskirt = 1.0\nlods = [0.1, 0.4, 1.6]\n\n\
         [scatter]\ntile = 32.0\n\n\
         [[species]]\nname = \"rock\"\nkind = \"mesh\"\nplacement = \"poisson\"\nmax_density = 0.004\n\
         min_spacing = 6.0\nobj = \"rock.obj\"\n\n\
         [[species]]\nname = \"grass\"\nkind = \"grass\"\nmax_density = 0.2\nscale = [0.8, 1.2]\n"
    )
}

const ROCK_OBJ: &str = "v -0.5 0 -0.5\nv 0.5 0 -0.5\nv 0.5 0 0.5\nv -0.5 0 0.5\n\
                        v -0.5 1 -0.5\nv 0.5 1 -0.5\nv 0.5 1 0.5\nv -0.5 1 0.5\n\
                        f 1 2 3 4\nf 8 7 6 5\nf 1 5 6 2\nf 2 6 7 3\nf 3 7 8 4\nf 4 8 5 1\n";

/// A temporary folder holding the rock species' OBJ.
fn folder() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "rock.obj", ROCK_OBJ);
    dir
}

/// What a chain node of a LoD scene is, file-independently: per level, its node name, the mesh's
/// name and geometry (positions, normals, indices of each primitive), its instances, and the
/// chain's coverages.
#[derive(Debug, PartialEq)]
struct Chain {
    levels: Vec<Level>,
    coverage: Vec<f32>,
}

/// A primitive's positions, normals and indices.
type Geometry = (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<u32>);
/// A level: its node's name, its mesh's name and primitives, its instances.
type Level = (String, String, Vec<Geometry>, Option<verdant::mesh::Instances>);

fn level(scene: &Scene, n: &Node) -> Level {
    let m = &scene.meshes[n.mesh.unwrap()];
    let prims = m.primitives.iter().map(|p| (p.positions.clone(), p.normals.clone(), p.indices.clone())).collect();
    (n.name.clone(), m.name.clone(), prims, n.instances.as_deref().cloned())
}

/// Every chain under the scene's roots (a root's children), by its first level's node name.
fn chains(scene: &Scene) -> BTreeMap<String, Chain> {
    let mut out = BTreeMap::new();
    for &r in &scene.roots {
        for &c in &scene.nodes[r].children {
            let n = &scene.nodes[c];
            let levels =
                std::iter::once(n).chain(n.lods.iter().map(|&k| &scene.nodes[k])).map(|l| level(scene, l)).collect();
            let chain = Chain { levels, coverage: n.lod_screen_coverage.clone() };
            assert!(out.insert(n.name.clone(), chain).is_none(), "{} twice", n.name);
        }
    }
    out
}

/// `v` turned by the unit quaternion `q` (x, y, z, w).
fn rotate(q: [f32; 4], v: [f32; 3]) -> [f32; 3] {
    let [x, y, z, w] = q;
    let t = [2.0 * (y * v[2] - z * v[1]), 2.0 * (z * v[0] - x * v[2]), 2.0 * (x * v[1] - y * v[0])];
    [
        v[0] + w * t[0] + (y * t[2] - z * t[1]),
        v[1] + w * t[1] + (z * t[0] - x * t[2]),
        v[2] + w * t[2] + (x * t[1] - y * t[0]),
    ]
}

fn decode(png: &[u8]) -> image::RgbaImage {
    image::load_from_memory(png).unwrap().to_rgba8()
}

#[test]
fn tiles_hold_every_chain_of_the_lod_scene_once_with_the_same_texels() {
    let dir = folder();
    let d = dir.path();
    write(d, "p.toml", &preset("tile = 256.0"));
    ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "o"]));
    let s = d.join("o/tiled");
    let index = read_json(&s.join("scene_tiles.json"));
    assert_eq!(index["format"], "verdant-scene-tiles");
    assert_eq!(index["version"], 1);
    assert_eq!(index["tile_m"], 256.0);
    // 384 m across in tiles of 256 m: 2 × 2, each holding chunks and instances
    assert_eq!(index["grid"], serde_json::json!([2, 2]));
    let tiles = index["tiles"].as_array().unwrap();
    assert_eq!(tiles.len(), 4);
    // the manifest lists the index and every tile
    let manifest = std::fs::read_to_string(s.join("manifest.json")).unwrap();
    assert!(manifest.contains("\"scene_tiles.json\""));

    let whole = verdant::validate::read_scene(&s.join("scene_lod.glb")).unwrap();
    let whole_chains = chains(&whole);
    // the whole scene's terrain textures (every chunk shares them)
    let whole_png: BTreeMap<String, image::RgbaImage> = whole
        .textures
        .iter()
        .filter(|t| t.name.starts_with("terrain"))
        .map(|t| (t.name.clone(), decode(&t.png)))
        .collect();
    assert!(whole_png.len() >= 2, "base colour and normal maps: {:?}", whole_png.keys());
    let whole_uv: BTreeMap<&str, &Vec<[f32; 2]>> = whole
        .meshes
        .iter()
        .filter(|m| m.name.starts_with("terrain"))
        .map(|m| (m.name.as_str(), &m.primitives[0].uvs))
        .collect();

    let mut seen: BTreeMap<String, Chain> = BTreeMap::new();
    let mut instances: BTreeMap<String, u64> = BTreeMap::new();
    for t in tiles {
        let file = s.join(t["file"].as_str().unwrap());
        assert_eq!(std::fs::metadata(&file).unwrap().len(), t["bytes"].as_u64().unwrap(), "{file:?}");
        assert!(manifest.contains(&format!("\"{}\"", t["file"].as_str().unwrap())), "{file:?} not in the manifest");
        let tile = verdant::validate::read_scene(&file).unwrap();
        let rect: Vec<f64> = t["rect_m"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let lo: Vec<f64> = t["bounds_min"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let hi: Vec<f64> = t["bounds_max"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let inside = |p: [f32; 3]| (0..3).all(|a| p[a] as f64 >= lo[a] - 1e-4 && p[a] as f64 <= hi[a] + 1e-4);
        let mut chunks = 0;
        for (name, chain) in chains(&tile) {
            let first = &chain.levels[0];
            if name.starts_with("terrain") {
                chunks += 1;
                // the chunk's centre lies in the tile's square
                let (mut a, mut b) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
                for p in first.2.iter().flat_map(|p| &p.0) {
                    assert!(inside(*p), "{name}: a vertex outside the tile's box");
                    for k in 0..3 {
                        a[k] = a[k].min(p[k]);
                        b[k] = b[k].max(p[k]);
                    }
                }
                let (cx, cz) = (0.5 * (a[0] + b[0]) as f64, 0.5 * (a[2] + b[2]) as f64);
                assert!(
                    cx >= rect[0] && cx < rect[2] && cz >= rect[1] && cz < rect[3],
                    "{name} centred outside its tile"
                );
            } else {
                // every vertex of every level, placed by each instance, inside the tile's box; each
                // instance in the tile's square (f32 rounding on its border)
                for (level, inst) in chain.levels.iter().filter_map(|l| Some((l, l.3.as_ref()?))) {
                    let n = inst.translations.len();
                    assert!(inst.rotations.len() == n && inst.scales.len() == n, "{name}");
                    for k in 0..n {
                        let (t, q, s) = (inst.translations[k], inst.rotations[k], inst.scales[k]);
                        for p in level.2.iter().flat_map(|p| &p.0) {
                            let v = rotate(q, [p[0] * s[0], p[1] * s[1], p[2] * s[2]]);
                            let w = [t[0] + v[0], t[1] + v[1], t[2] + v[2]];
                            assert!(
                                inside(w),
                                "{name}: a vertex of an instance at {t:?} reaches {w:?}, outside {lo:?}..{hi:?}"
                            );
                        }
                        let (x, z) = (t[0] as f64, t[2] as f64);
                        let e = 1e-3;
                        assert!(
                            x >= rect[0] - e && (x < rect[2] + e || rect[2] >= 384.0),
                            "{name}: x {x} outside {rect:?}"
                        );
                        assert!(
                            z >= rect[1] - e && (z < rect[3] + e || rect[3] >= 384.0),
                            "{name}: z {z} outside {rect:?}"
                        );
                    }
                }
                let species = name.split('_').next().unwrap().to_string();
                *instances.entry(species).or_default() +=
                    chain.levels[0].3.as_ref().map_or(0, |i| i.translations.len() as u64);
            }
            assert!(seen.insert(name.clone(), chain).is_none(), "{name} in two tiles");
        }
        assert_eq!(chunks, t["terrain_chunks"].as_u64().unwrap());

        // the terrain's textures: the whole map's texels of the rectangle kept, and each chunk's
        // coordinates on the same texels
        let [x0, y0, cw, ch] = [0, 1, 2, 3].map(|k| t["texture_texels"][k].as_u64().unwrap() as u32);
        for tex in tile.textures.iter().filter(|t| t.name.starts_with("terrain")) {
            let full = &whole_png[&tex.name];
            let crop = decode(&tex.png);
            assert_eq!((crop.width(), crop.height()), (cw, ch), "{}", tex.name);
            let expected = image::imageops::crop_imm(full, x0, y0, cw, ch).to_image();
            assert!(crop == expected, "{}: the tile's texels are not the whole map's", tex.name);
        }
        let (w, h) = {
            let any = whole_png.values().next().unwrap();
            (any.width() as f64, any.height() as f64)
        };
        for m in tile.meshes.iter().filter(|m| m.name.starts_with("terrain")) {
            let whole_uvs = whole_uv[m.name.as_str()];
            for (a, b) in m.primitives[0].uvs.iter().zip(whole_uvs) {
                // in texels: the tile's coordinate is the whole map's, less the rectangle's corner
                let (tu, tv) = (a[0] as f64 * cw as f64 + x0 as f64, a[1] as f64 * ch as f64 + y0 as f64);
                assert!((tu - b[0] as f64 * w).abs() < 1e-3 && (tv - b[1] as f64 * h).abs() < 1e-3, "{}", m.name);
                assert!((0.0..=1.0).contains(&a[0]) && (0.0..=1.0).contains(&a[1]), "{}: {a:?}", m.name);
            }
        }
        for (sp, n) in t["instances"].as_object().unwrap() {
            assert!(n.as_u64().unwrap() > 0, "{sp}");
        }
    }
    // every chain once, the same levels, geometry, instances and coverages
    assert_eq!(seen.len(), whole_chains.len());
    for (name, chain) in &whole_chains {
        assert_eq!(seen.get(name), Some(chain), "{name}");
    }
    // the index counts every placed row
    let manifest = read_json(&s.join("manifest.json"));
    for sp in manifest["scatter"]["species"].as_array().unwrap() {
        let name = sp["name"].as_str().unwrap();
        let listed: u64 = tiles.iter().map(|t| t["instances"][name].as_u64().unwrap_or(0)).sum();
        assert_eq!(listed, sp["count"].as_u64().unwrap(), "{name}");
        assert_eq!(instances[name], listed, "{name}");
    }
}

#[test]
fn bad_tile_values_are_refused_with_their_line() {
    let dir = folder();
    let d = dir.path();
    for (tile, line, says) in [
        ("tile = 0.0", 4, "between 1 and 1 000 000 m"),
        ("tile = \"big\"", 4, "a number"),
        // a scene tile holds whole placement tiles (32 m)
        ("tile = 200.0", 4, "multiple of the placement tiles' 32 m"),
        ("lod_scene = false", 4, "neither scene_lod.glb nor tiles"),
    ] {
        write(d, "p.toml", &preset(tile));
        let o = verdant_in(d, &["-q", "build", "p.toml", "--out", "o"]);
        let t = text(&o);
        assert!(!o.status.success(), "{tile}: {t}");
        assert!(t.contains(&format!("p.toml:{line}")) && t.contains(says), "{tile}: {t}");
    }
    // tiles need chunks to cut the terrain by
    write(d, "p.toml", &preset("tile = 256.0").replace("chunk = 64\n", ""));
    let o = verdant_in(d, &["-q", "build", "p.toml", "--out", "o"]);
    let t = text(&o);
    assert!(
        !o.status.success() && t.contains("p.toml:4") && t.contains("chunked terrain") && t.contains("chunk ="),
        "{t}"
    );
}

#[test]
fn tiles_are_the_same_bytes_at_any_thread_count_and_stand_without_scene_lod() {
    let dir = folder();
    let d = dir.path();
    write(d, "p.toml", &preset("tile = 128.0"));
    ok(&verdant_in(d, &["-q", "--threads", "1", "build", "p.toml", "--out", "one"]));
    ok(&verdant_in(d, &["-q", "--threads", "3", "build", "p.toml", "--out", "three"]));
    assert_same_tree(&d.join("one/tiled"), &d.join("three/tiled"));
    // rebuilt unchanged: the view stage served from the cache, tiles and index restored the same
    ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "one"]));
    assert!(timing_cached(&d.join("one/tiled"), "view"));
    assert_same_tree(&d.join("one/tiled"), &d.join("three/tiled"));
    assert_eq!(read_json(&d.join("one/tiled/scene_tiles.json"))["tiles"].as_array().unwrap().len(), 9);
    // `lod_scene = false`: the tiles alone, the same bytes; no scene_lod.glb anywhere
    write(d, "p.toml", &preset("tile = 128.0\nlod_scene = false"));
    ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "alone"]));
    let (with, alone) = (tree(&d.join("one/tiled")), tree(&d.join("alone/tiled")));
    assert!(!alone.contains_key("scene_lod.glb") && with.contains_key("scene_lod.glb"));
    for (rel, bytes) in with.iter().filter(|(rel, _)| rel.starts_with("tiles/") || *rel == "scene_tiles.json") {
        assert!(alone.get(rel) == Some(bytes), "{rel} differs without scene_lod.glb");
    }
    // the flag changes what the view stage writes: turned either way in one folder, never served
    // from the other's cache entry
    ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "one"]));
    assert!(!d.join("one/tiled/scene_lod.glb").exists(), "lod_scene = false, yet scene_lod.glb");
    write(d, "p.toml", &preset("tile = 128.0"));
    ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "one"]));
    assert_same_tree(&d.join("one/tiled"), &d.join("three/tiled"));
    let manifest = read_json(&d.join("alone/tiled/manifest.json"));
    assert!(
        manifest["view"].get("lod_scene").is_none()
            && manifest["view"].get("lod_scene_bytes").is_none()
            && manifest["view"]["tiles"]["tiles"] == 9,
        "{}",
        manifest["view"]
    );
    assert!(!std::fs::read_to_string(d.join("alone/tiled/manifest.json")).unwrap().contains("scene_lod.glb"));
    // a boolean only
    write(d, "p.toml", &preset("lod_scene = \"no\""));
    let o = verdant_in(d, &["-q", "build", "p.toml", "--out", "bad"]);
    assert!(!o.status.success() && text(&o).contains("p.toml:4") && text(&o).contains("a boolean"), "{}", text(&o));
}

#[test]
fn no_tile_writes_no_tiles() {
    let dir = folder();
    let d = dir.path();
    write(d, "p.toml", &preset(""));
    ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "o"]));
    assert!(!d.join("o/tiled/scene_tiles.json").exists() && !d.join("o/tiled/tiles").exists());
    assert!(!read_json(&d.join("o/tiled/report.json"))["stages"]["view"].as_object().unwrap().contains_key("tiles"));
}
