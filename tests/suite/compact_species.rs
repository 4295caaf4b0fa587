//! Compact species files (`verdant tree|mesh --quantize|--compress`, issue 17 item 3): 16-bit
//! positions on a grid per mesh family, 8-bit normals, texture coordinates outside 0..1 through
//! KHR_texture_transform, meshopt compression. What a user relies on: every file validates; it
//! reads back as the f32 file within the quantization the report states (per vertex, in the file's
//! world space); --compress reads back exactly as --quantize (lossless); the report's error as
//! stored folds the quantization in; instanced meshes are placed right; bytes are deterministic.

use std::path::Path;

use verdant::export::gltf::{to_glb_with, WriteOptions};
use verdant::export::quantize::{position_error, uniform_grid, Compact, Quantization};
use verdant::mesh::{Instances, Material, Mesh, Node, Primitive, Scene, Texture};
use verdant::plants::tree::TreeOptions;
use verdant::plants::tree_lod::{run_lods, TreeLodJob, TreeLodOptions, TreeLodRunReport};
use verdant::validate::{read_scene, validate_file};

use crate::common::lod::small_atlas;

const BUSH: &str = "3-2-2\n28\n18\nX(100)=FFA\nA(40)=F[&B]>(137)A\nA(75)=F[^B]>(120)A\nA(100)=F[&B]\"[^C]>(137)A\nB(50)=F[-C]CL\nB(100)=F[+C]'C\nC(100)=F[+B]B\n@\n";

fn chain(dir: &Path, stem: &str, compact: Compact) -> TreeLodRunReport {
    let input = dir.join("bush.ls");
    std::fs::write(&input, BUSH).unwrap();
    let job = TreeLodJob {
        input,
        output: dir.join(format!("{stem}.glb")),
        dialect: None,
        options: TreeOptions { name: "bush".into(), seed: 5, height_m: Some(6.0), ..TreeOptions::default() },
        lod: TreeLodOptions { compact, ..small_atlas() },
        variants: 1,
    };
    run_lods(&job).unwrap_or_else(|e| panic!("{stem}: {e}"))
}

/// Every vertex of every mesh node of `scene` in world space (node transforms only: the species
/// files have no instances), in file order.
fn world(scene: &Scene) -> Vec<Vec<[f64; 3]>> {
    scene
        .nodes
        .iter()
        .filter_map(|n| {
            let m = n.mesh?;
            let q = glam::DQuat::from_array(n.rotation.map(f64::from));
            Some(
                scene.meshes[m]
                    .primitives
                    .iter()
                    .flat_map(|p| &p.positions)
                    .map(|p| {
                        let s = glam::DVec3::new(
                            p[0] as f64 * n.scale[0] as f64,
                            p[1] as f64 * n.scale[1] as f64,
                            p[2] as f64 * n.scale[2] as f64,
                        );
                        (q * s + glam::DVec3::from_array(n.translation.map(f64::from))).to_array()
                    })
                    .collect(),
            )
        })
        .collect()
}

fn max_distance(a: &[Vec<[f64; 3]>], b: &[Vec<[f64; 3]>]) -> f64 {
    assert_eq!(a.len(), b.len());
    let mut worst = 0.0f64;
    for (x, y) in a.iter().zip(b) {
        assert_eq!(x.len(), y.len());
        for (p, q) in x.iter().zip(y) {
            let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
            worst = worst.max(d);
        }
    }
    worst
}

#[test]
fn compact_tree_chains_validate_read_back_within_the_reported_quantization_and_compress_losslessly() {
    let dir = tempfile::tempdir().unwrap();
    let f = chain(dir.path(), "f", Compact::None);
    let q = chain(dir.path(), "q", Compact::Quantize);
    let c = chain(dir.path(), "c", Compact::Compress);
    assert_eq!(q.tree.validation_errors, 0);
    assert_eq!(c.tree.validation_errors, 0);
    let (fv, qv, cv) = (&f.variants[0], &q.variants[0], &c.variants[0]);
    let mut wind_values = 0;
    assert_eq!(fv.lods.len(), qv.lods.len());
    let mut files: Vec<String> = (0..fv.lods.len()).map(|n| format!("_LOD{n}")).collect();
    files.push(String::new());
    for (n, suffix) in files.iter().enumerate() {
        let path = |stem: &str| dir.path().join(format!("{stem}{suffix}.glb"));
        for stem in ["q", "c"] {
            let v = validate_file(&path(stem), &Default::default()).unwrap();
            assert_eq!(v.errors(), 0, "{stem}{suffix}: {v}");
        }
        let (fs, qs, cs) =
            (read_scene(&path("f")).unwrap(), read_scene(&path("q")).unwrap(), read_scene(&path("c")).unwrap());
        // lossless compression: the same scene as the quantized file (meshopt's index codec may
        // start a triangle at another corner: same triangle, same winding)
        assert_eq!(canonical(qs.clone()), canonical(cs), "{suffix}");
        // each vertex where the f32 file has it, within the level's reported quantization
        let moved = max_distance(&world(&fs), &world(&qs));
        let reported = if n < fv.lods.len() {
            qv.lods[n].quantization_m
        } else {
            qv.lods.iter().map(|l| l.quantization_m).fold(0.0, f64::max)
        };
        // (a quad's corners are its box's: on the grid exactly)
        assert!(moved > 0.0 || n > 0, "{suffix}: nothing quantized");
        assert!(moved <= reported * (1.0 + 1e-6) + 1e-7, "{suffix}: vertices moved {moved} m, report says {reported}");
        // 16 bits over a 6 m tree: well under a millimetre
        assert!(reported < 1e-3 && reported > 1e-6, "{reported}");
        // texture coordinates (bark repeats along branches: KHR_texture_transform) as drawn
        for (a, b) in fs.meshes.iter().zip(&qs.meshes) {
            for (p, r) in a.primitives.iter().zip(&b.primitives) {
                for (u, w) in p.uvs.iter().zip(&r.uvs) {
                    let range = p.uvs.iter().flatten().fold(1.0f32, |m, &x| m.max(x.abs()));
                    assert!((u[0] - w[0]).abs() <= range * 2e-5 && (u[1] - w[1]).abs() <= range * 2e-5, "{u:?} {w:?}");
                }
                for (nf, nq) in p.normals.iter().zip(&r.normals) {
                    let dot = nf[0] * nq[0] + nf[1] * nq[1] + nf[2] * nq[2];
                    assert!(dot > 0.9998, "normal {nf:?} read back as {nq:?}"); // 8 bits: ≤ 1.2°
                }
                // wind data: bytes of value / range, each within half a step of the f32 file's
                assert_eq!(p.custom.len(), r.custom.len(), "{suffix}");
                for (cf, cq) in p.custom.iter().zip(&r.custom) {
                    assert_eq!(cf.name, cq.name);
                    // (an f32 file notes no range: it stores the floats, read with their documented range)
                    assert_eq!(cf.range, cq.range);
                    let range = cq.range.unwrap_or_else(|| panic!("{suffix}: {} has no range", cq.name));
                    let expected = if cq.name == "_WIND" {
                        verdant::plants::wind::WIND_RANGE
                    } else {
                        verdant::plants::wind::WIND_BRANCH_RANGE
                    };
                    assert_eq!(range, expected, "{suffix}: {}", cq.name);
                    for (a, b) in cf.values.iter().zip(&cq.values) {
                        for k in 0..4 {
                            let step = range[k] / 255.0;
                            assert!(
                                (a[k] - b[k]).abs() <= 0.5 * step * (1.0 + 1e-4),
                                "{}: {a:?} read back as {b:?}",
                                cf.name
                            );
                            // on a step, exactly as an engine reads it (k / 255 × range)
                            assert_eq!(b[k], (b[k] / step).round() / 255.0 * range[k], "{}", cf.name);
                        }
                    }
                    wind_values += cf.values.len();
                }
            }
        }
    }
    assert!(wind_values > 1000, "{wind_values}");
    // the report states what storing the wind as bytes cost each level: within half a step, and
    // none for f32 files
    for l in &qv.lods {
        let wind = &l.attribute_error["_WIND"];
        for k in 0..4 {
            assert!(wind[k] <= verdant::plants::wind::WIND_RANGE[k] / 510.0 * (1.0 + 1e-4), "LOD{}: {wind:?}", l.level);
        }
        // (a billboard's corners weigh 0 and 1: on steps)
        assert!(wind[0] > 0.0 || l.level > 0, "LOD0: its bend weights cannot all be on steps");
    }
    assert!(fv.lods.iter().all(|l| l.attribute_error.is_empty()));
    // the error as stored: the sampled Hausdorff distance plus the level's and LoD0's quantization
    let q0 = qv.lods[0].quantization_m;
    for (l, row) in qv.lods.iter().zip(&qv.table) {
        let extra = if l.level > 0 { q0 } else { 0.0 };
        assert_eq!(l.stored_error_m, l.geometric_error.max_m + l.quantization_m + extra);
        assert_eq!(row.stored_error_m, l.stored_error_m);
    }
    for l in &fv.lods {
        assert_eq!(l.quantization_m, 0.0);
        assert_eq!(l.stored_error_m, l.geometric_error.max_m);
    }
    // smaller, and compression smaller still
    let size = |v: &verdant::plants::tree_lod::TreeLodReport| v.lods.iter().map(|l| l.bytes).sum::<usize>();
    assert!(size(qv) < size(fv) && size(cv) < size(qv), "{} {} {}", size(fv), size(qv), size(cv));
    // the same build, the same bytes
    let again = chain(dir.path(), "c2", Compact::Compress);
    for suffix in &files {
        let read = |stem: &str| std::fs::read(dir.path().join(format!("{stem}{suffix}.glb"))).unwrap();
        assert_eq!(read("c"), read("c2"), "{suffix}");
    }
    assert_eq!(again.variants[0].lods.len(), cv.lods.len());
}

/// A LoD chain shown by an instanced node (as scene_lod.glb holds): the levels share one grid, so
/// one set of instance transforms, which carries the grid; each instance's vertices land where the
/// f32 file puts them.
#[test]
fn instanced_chains_share_their_grid_and_place_every_instance() {
    let quad = |s: f32| Primitive {
        positions: vec![[-s, 0.0, 0.0], [s, 0.0, 0.0], [s, 2.0 * s, 0.0], [-s, 2.0 * s, 0.0]],
        normals: vec![[0.0, 0.0, 1.0]; 4],
        uvs: vec![[0.0, 0.0], [3.0, 0.0], [3.0, 2.5], [0.0, 2.5]],
        indices: vec![0, 1, 2, 0, 2, 3],
        material: Some(0),
        ..Primitive::default()
    };
    let mut scene = Scene::default();
    scene.textures.push(Texture { name: "t".into(), png: tiny_png() });
    scene.materials.push(Material { base_color_texture: Some(0), ..Material::default() });
    scene.meshes.push(Mesh { name: "fine".into(), primitives: vec![quad(1.0)], extras: None });
    scene.meshes.push(Mesh { name: "coarse".into(), primitives: vec![quad(1.3)], extras: None });
    let instances = Instances {
        translations: vec![[10.0, 0.0, 5.0], [-40.0, 3.0, 7.5], [0.25, -1.0, 300.0]],
        rotations: vec![[0.0, 0.0, 0.0, 1.0], [0.0, 0.38268343, 0.0, 0.9238795], [0.0, 1.0, 0.0, 0.0]],
        scales: vec![[1.0; 3], [2.0, 1.5, 2.0], [0.5; 3]],
    };
    scene.nodes.push(Node {
        name: "chain".into(),
        mesh: Some(0),
        instances: Some(instances.clone().into()),
        lods: vec![1],
        lod_screen_coverage: vec![0.2, 0.0],
        ..Node::default()
    });
    scene.nodes.push(Node {
        name: "coarse".into(),
        mesh: Some(1),
        instances: Some(instances.clone().into()),
        ..Node::default()
    });
    scene.roots.push(0);
    let dir = tempfile::tempdir().unwrap();
    let opts = WriteOptions { quantization: Quantization::PerMesh, meshopt: true, ..WriteOptions::default() };
    let path = dir.path().join("chain.glb");
    std::fs::write(&path, to_glb_with(&scene, &opts).unwrap()).unwrap();
    let v = validate_file(&path, &Default::default()).unwrap();
    assert_eq!(v.errors(), 0, "{v}");
    let back = read_scene(&path).unwrap();
    // one grid over both levels: their instance transforms are one accessor set
    let doc: serde_json::Value = {
        let bytes = std::fs::read(&path).unwrap();
        let n = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        serde_json::from_slice(&bytes[20..20 + n]).unwrap()
    };
    let ext = |n: usize| doc["nodes"][n]["extensions"]["EXT_mesh_gpu_instancing"]["attributes"].clone();
    assert_eq!(ext(0), ext(1));
    assert!(doc["extensionsRequired"].as_array().unwrap().iter().any(|e| e == "KHR_texture_transform"));
    let grid = uniform_grid([-1.3, 0.0, 0.0], [1.3, 2.6, 0.0]);
    let bound = 0.5 * 3f64.sqrt() * grid.step[0] as f64;
    let err = position_error(&scene, &Quantization::PerMesh);
    assert!(err > 0.0 && err <= bound, "{err} {bound}");
    let place = |inst: &Instances, k: usize, p: [f32; 3]| -> glam::DVec3 {
        let r = glam::DQuat::from_array(inst.rotations[k].map(f64::from));
        let s = glam::DVec3::from_array(inst.scales[k].map(f64::from));
        glam::DVec3::from_array(inst.translations[k].map(f64::from))
            + r * (s * glam::DVec3::from_array(p.map(f64::from)))
    };
    for n in 0..2 {
        let (orig, read) = (&scene.nodes[n], &back.nodes[n]);
        let (om, rm) = (&scene.meshes[orig.mesh.unwrap()], &back.meshes[read.mesh.unwrap()]);
        let (oi, ri) = (orig.instances.as_ref().unwrap(), read.instances.as_ref().unwrap());
        for k in 0..3 {
            let scale = oi.scales[k].iter().fold(0.0f32, |m, &s| m.max(s)) as f64;
            for (p, q) in om.primitives[0].positions.iter().zip(&rm.primitives[0].positions) {
                let d = (place(oi, k, *p) - place(ri, k, *q)).length();
                assert!(d <= err * scale * (1.0 + 1e-5) + 1e-5, "node {n} instance {k}: {d} > {}", err * scale);
            }
        }
        // texture coordinates outside 0..1 come back through the transform
        for (u, w) in om.primitives[0].uvs.iter().zip(&rm.primitives[0].uvs) {
            assert!((u[0] - w[0]).abs() < 1e-4 && (u[1] - w[1]).abs() < 1e-4, "{u:?} {w:?}");
        }
    }
}

#[test]
fn compact_outputs_refuse_obj() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bush.ls");
    std::fs::write(&input, BUSH).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_verdant"))
        .arg("tree")
        .arg(&input)
        .arg("-o")
        .arg(dir.path().join("bush.obj"))
        .arg("--compress")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let msg = String::from_utf8_lossy(&out.stderr);
    assert!(msg.contains("bush.obj") && msg.contains("write .glb or .gltf"), "{msg}");
    assert!(!dir.path().join("bush.obj").exists());
}

/// Each triangle starting at its smallest index (rotation keeps the winding).
fn canonical(mut scene: Scene) -> Scene {
    for m in &mut scene.meshes {
        for p in &mut m.primitives {
            for t in p.indices.chunks_exact_mut(3) {
                let k = (0..3).min_by_key(|&k| t[k]).unwrap();
                t.rotate_left(k);
            }
        }
    }
    scene
}

fn tiny_png() -> Vec<u8> {
    let img = verdant::bake::image::Image::new(2, 2, [1.0; 4]).unwrap();
    img.encode_png().unwrap()
}

/// A preset with a tree and a grass species on a chunked terrain, `compact` as given.
fn scene_preset(name: &str, compact: &str) -> String {
    format!(
        "[scene]\nname = \"{name}\"\nseed = 5\ncompact = \"{compact}\"\n\n[terrain]\n\
         procedural = {{ kind = \"fbm\", size = 129, seed = 3, relief = 30.0 }}\n\
         cell_size = 2.0\nmax_error = 0.3\nchunk = 64\nskirt = 1.0\nlods = [0.3, 1.2]\n\n[scatter]\ntile = 64.0\n\n\
         [[species]]\nname = \"bush\"\nkind = \"tree\"\nlsystem = \"builtin:bush\"\n\
         tree = {{ variants = 1, height = 4.0, atlas_size = 256, analysis = false }}\n\
         max_density = 0.004\nmin_spacing = 8.0\nscale = [0.8, 1.2]\n\n\
         [[species]]\nname = \"grass\"\nkind = \"grass\"\nmax_density = 0.2\nscale = [0.8, 1.2]\n"
    )
}

/// `[scene] compact`: every species file and both scene files quantized (or compressed), valid,
/// each species file where the f32 build's is within the quantization the report states; the scene
/// drawn with the same triangles; the terrain's chunks on one grid (seams closed); `compact`
/// changes the plants and view stages' keys, not the terrain's.
#[test]
fn compact_scenes_store_species_and_scene_files_within_the_reported_quantization() {
    use crate::common::{ok, read_json, verdant_in, write};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (name, compact) in [("f", "none"), ("q", "quantize"), ("c", "compress")] {
        write(d, &format!("p/{name}.toml"), &scene_preset(name, compact));
        ok(&verdant_in(d, &["build", &format!("p/{name}.toml"), "--out", "o"]));
    }
    let report = |n: &str| read_json(&d.join(format!("o/{n}/report.json")));
    let (rf, rq, rc) = (report("f"), report("q"), report("c"));
    // the terrain stage is the same (its files stay f32): the same bytes
    for f in ["terrain/terrain.glb", "terrain/terrain_LOD1.glb"] {
        let read = |n: &str| std::fs::read(d.join(format!("o/{n}/{f}"))).unwrap();
        assert_eq!(read("f"), read("q"), "{f}");
    }
    let view = |r: &serde_json::Value, k: &str| r["stages"]["view"][k].as_f64().unwrap();
    assert_eq!(view(&rf, "quantization_m"), 0.0);
    // a 256 m terrain on one 16-bit grid: under 4 mm; the species' grids are finer
    for r in [&rq, &rc] {
        let t = view(r, "terrain_quantization_m");
        assert!(t > 0.0 && t < 256.0 / 65535.0, "{t}");
        assert!(view(r, "quantization_m") >= t);
        assert!(view(r, "scene_bytes") < view(&rf, "scene_bytes"));
    }
    assert!(view(&rc, "lod_scene_bytes") < view(&rq, "lod_scene_bytes"));
    let species = |r: &serde_json::Value| r["stages"]["plants"]["species"].as_array().unwrap().clone();
    for (sq, sf) in species(&rq).iter().zip(species(&rf)) {
        let q = sq["quantization_m"].as_f64().unwrap();
        assert!(q > 0.0 && q < 1e-3, "{}: {q}", sq["name"]);
        assert_eq!(sf["quantization_m"].as_f64().unwrap(), 0.0);
        // every species file: valid, each vertex within the species' figure of the f32 file's
        for file in sq["files"].as_array().unwrap().iter().filter_map(|f| f.as_str()).filter(|f| f.ends_with(".glb")) {
            let (pq, pf) = (d.join("o/q").join(file), d.join("o/f").join(file));
            let v = validate_file(&pq, &Default::default()).unwrap();
            assert_eq!(v.errors(), 0, "{file}: {v}");
            let (fq, ff) = (world(&read_scene(&pq).unwrap()), world(&read_scene(&pf).unwrap()));
            let moved = max_distance(&ff, &fq);
            assert!(moved <= q * (1.0 + 1e-6) + 1e-7, "{file}: {moved} > {q}");
            assert_wind_stored(&pq, true);
            assert_wind_stored(&pf, false);
        }
    }
    // the tree chain's levels fold it in
    let lods = &species(&rq)[0]["tree"]["variants"][0]["chain"]["lods"];
    for l in lods.as_array().unwrap() {
        let (g, qm, s) = (
            l["geometric_error"]["max_m"].as_f64().unwrap(),
            l["quantization_m"].as_f64().unwrap(),
            l["stored_error_m"].as_f64().unwrap(),
        );
        assert!(qm > 0.0 && s >= g + qm, "{l}");
    }
    // the scene files: valid, the wind as bytes, the same triangles drawn
    for n in ["q", "c"] {
        for f in ["scene.glb", "scene_lod.glb"] {
            let v = validate_file(&d.join(format!("o/{n}/{f}")), &Default::default()).unwrap();
            assert_eq!(v.errors(), 0, "{n}/{f}: {v}");
            assert_wind_stored(&d.join(format!("o/{n}/{f}")), true);
            assert_wind_stored(&d.join(format!("o/f/{f}")), false);
        }
        let (a, b) = (&rf["stages"]["view"]["views"][0], &report(n)["stages"]["view"]["views"][0]);
        assert_eq!(a["triangles"], b["triangles"]);
        assert_eq!(a["draw_calls"], b["draw_calls"]);
    }
    // every instance where the f32 scene puts it (the species meshes as the view stage read them
    // back from their compact files, the grid in the instance transforms): each node's first and
    // last instance, vertex by vertex, within the view stage's figure (which counts what the
    // species files had moved the meshes it read back from them)
    let species_q = species(&rq).iter().map(|s| s["quantization_m"].as_f64().unwrap()).fold(0.0, f64::max);
    let bound = view(&rq, "quantization_m");
    assert!(bound >= species_q);
    let instanced = |s: &Scene, n: &Node, k: usize| -> Vec<glam::DVec3> {
        let inst = n.instances.as_ref().unwrap();
        let k = k.min(inst.len() - 1);
        let r = glam::DQuat::from_array(inst.rotations[k].map(f64::from));
        let sc = glam::DVec3::from_array(inst.scales[k].map(f64::from));
        let t = glam::DVec3::from_array(inst.translations[k].map(f64::from));
        s.meshes[n.mesh.unwrap()]
            .primitives
            .iter()
            .flat_map(|p| &p.positions)
            .map(|p| t + r * (sc * glam::DVec3::from_array(p.map(f64::from))))
            .collect()
    };
    let (sf, sq) = (read_scene(&d.join("o/f/scene.glb")).unwrap(), read_scene(&d.join("o/q/scene.glb")).unwrap());
    let mut checked = 0;
    for nf in sf.nodes.iter().filter(|n| n.instances.as_ref().is_some_and(|i| !i.is_empty())) {
        let nq = sq.nodes.iter().find(|n| n.name == nf.name).unwrap_or_else(|| panic!("{} missing", nf.name));
        for k in [0, usize::MAX] {
            let scale = nf.instances.as_ref().unwrap().scales.iter().flatten().fold(1.0f32, |m, &x| m.max(x)) as f64;
            for (a, b) in instanced(&sf, nf, k).iter().zip(instanced(&sq, nq, k)) {
                assert!((*a - b).length() <= bound * scale * (1.0 + 1e-4) + 1e-4, "{}: {a} vs {b}", nf.name);
                checked += 1;
            }
        }
    }
    assert!(checked > 0);
    // one grid for the terrain's chunks: a seam vertex has the same integers in both chunks, so
    // the chunks meet exactly (world positions of the quantized scene.glb's terrain vertices that
    // coincide in the f32 file coincide here too)
    let terrain = |s: &Scene| -> Vec<Vec<[f64; 3]>> {
        let mut t = s.clone();
        t.nodes.retain(|n| n.mesh.is_some_and(|m| s.meshes[m].name.starts_with("terrain")) && n.instances.is_none());
        world(&t)
    };
    let (tf, tq) = (terrain(&sf), terrain(&sq));
    assert!(tf.len() > 1, "a chunked terrain");
    // every f32 point, wherever it occurs (chunk seams), is stored at one place
    let mut stored: std::collections::HashMap<[u64; 3], [f64; 3]> = Default::default();
    let mut shared = 0usize;
    for (cf, cq) in tf.iter().zip(&tq) {
        for (pf, pq) in cf.iter().zip(cq) {
            match stored.entry(pf.map(f64::to_bits)) {
                std::collections::hash_map::Entry::Occupied(e) => {
                    shared += 1;
                    let first = e.get();
                    let d = (0..3).map(|a| (first[a] - pq[a]).abs()).fold(0.0, f64::max);
                    assert!(d < 1e-9, "a seam point stored at {first:?} and {pq:?}");
                }
                std::collections::hash_map::Entry::Vacant(e) => {
                    e.insert(*pq);
                }
            }
        }
    }
    assert!(shared > 100, "{shared} seam points");
}

/// What the view stage reads back from a compact species file: each mesh in its own frame and each
/// node (a clump laid out beside the others) and instance with its own transform, within the
/// quantization (the grid noted in the mesh's extras, which read back without it).
#[test]
fn dequantized_reads_give_meshes_nodes_and_instances_back() {
    let quad = |z: f32| Primitive {
        positions: vec![[-0.25, 0.2, z], [0.25, 0.2, z], [0.25, 0.7, z + 0.5], [-0.25, 0.7, z]],
        normals: vec![[0.0, 0.0, 1.0]; 4],
        indices: vec![0, 1, 2, 0, 2, 3],
        ..Primitive::default()
    };
    let mut scene = Scene::default();
    scene.meshes.push(Mesh {
        name: "clump0".into(),
        primitives: vec![quad(0.0)],
        extras: Some(serde_json::json!({"k": 1})),
    });
    scene.meshes.push(Mesh { name: "clump1".into(), primitives: vec![quad(-0.3)], extras: None });
    scene.nodes.push(Node {
        name: "a".into(),
        mesh: Some(0),
        translation: [0.0, 0.0, 1.5],
        scale: [2.0; 3],
        ..Node::default()
    });
    scene.nodes.push(Node {
        name: "b".into(),
        mesh: Some(1),
        translation: [3.0, 1.0, -2.0],
        rotation: [0.0, 0.38268343, 0.0, 0.9238795],
        instances: Some(std::sync::Arc::new(Instances {
            translations: vec![[10.0, 0.0, 5.0], [-4.0, 2.0, 1.0]],
            rotations: vec![[0.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 0.0]],
            scales: vec![[1.0; 3], [0.5, 2.0, 0.5]],
        })),
        ..Node::default()
    });
    scene.roots = vec![0, 1];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("clumps.glb");
    let opts = Compact::Compress.write_options();
    std::fs::write(&path, to_glb_with(&scene, &opts).unwrap()).unwrap();
    let err = position_error(&scene, &opts.quantization);
    let back = verdant::validate::read_scene_dequantized(&path).unwrap();
    assert_eq!(back.meshes[0].extras, scene.meshes[0].extras, "the grid note is taken out of the extras");
    assert_eq!(back.meshes[1].extras, None);
    for (a, b) in scene.meshes.iter().zip(&back.meshes) {
        for (p, q) in a.primitives[0].positions.iter().zip(&b.primitives[0].positions) {
            let d = (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f32>().sqrt() as f64;
            assert!(d <= err * (1.0 + 1e-5) + 1e-6, "{}: {p:?} read back as {q:?}", a.name);
        }
    }
    let close = |a: [f32; 3], b: [f32; 3]| (0..3).all(|k| (a[k] - b[k]).abs() <= 1e-4 * (1.0 + a[k].abs()));
    for (a, b) in scene.nodes.iter().zip(&back.nodes) {
        assert!(close(a.translation, b.translation) && close(a.scale, b.scale), "{a:?}\n{b:?}");
        if let (Some(x), Some(y)) = (&a.instances, &b.instances) {
            for k in 0..2 {
                assert!(close(x.translations[k], y.translations[k]) && close(x.scales[k], y.scales[k]), "{x:?}\n{y:?}");
            }
        }
    }
}

/// Wind data in a compact file: normalized bytes of value / range with the range in the
/// primitive's extras, what an engine reads; floats where a value lies outside its range or the
/// file is f32; reading a compact file back and writing it again gives the same bytes.
#[test]
fn compact_files_store_wind_as_bytes_of_its_range() {
    use verdant::export::gltf::ATTRIBUTE_RANGES_KEY;
    use verdant::mesh::CustomAttribute;
    use verdant::plants::wind::{WIND_ATTRIBUTE, WIND_BRANCH_ATTRIBUTE, WIND_BRANCH_RANGE, WIND_RANGE};
    let tri = |wind: Vec<[f32; 4]>, branch: Vec<[f32; 4]>| Primitive {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]],
        indices: vec![0, 1, 2],
        custom: vec![
            CustomAttribute { name: WIND_ATTRIBUTE.into(), values: wind, unit_bytes: false, range: Some(WIND_RANGE) },
            CustomAttribute {
                name: WIND_BRANCH_ATTRIBUTE.into(),
                values: branch,
                unit_bytes: false,
                range: Some(WIND_BRANCH_RANGE),
            },
        ],
        ..Primitive::default()
    };
    let tau = std::f32::consts::TAU;
    let wind = vec![[0.0, 0.1, 0.4, 0.0], [0.25, 3.0, 1.6, 0.5], [1.0, tau, 4.0, 1.0]];
    // a branch phase past its range (not a verdant value, but any data): kept as floats
    let branch = vec![[0.0, 0.0, 0.0, 1.0], [0.5, 7.0, 0.2, 2.0], [1.0, 1.0, 1.0, tau]];
    let mut scene = Scene::default();
    scene.meshes.push(Mesh { name: "plant".into(), primitives: vec![tri(wind.clone(), branch.clone())], extras: None });
    scene.nodes.push(Node { name: "plant".into(), mesh: Some(0), ..Node::default() });
    scene.roots.push(0);
    let dir = tempfile::tempdir().unwrap();
    let doc_of = |path: &Path| -> serde_json::Value {
        let bytes = std::fs::read(path).unwrap();
        let n = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        serde_json::from_slice(&bytes[20..20 + n]).unwrap()
    };
    for compact in [Compact::None, Compact::Quantize, Compact::Compress] {
        let path = dir.path().join(format!("{compact:?}.glb"));
        let bytes = to_glb_with(&scene, &compact.write_options()).unwrap();
        std::fs::write(&path, &bytes).unwrap();
        let v = validate_file(&path, &Default::default()).unwrap();
        assert_eq!(v.errors(), 0, "{compact:?}: {v}");
        let doc = doc_of(&path);
        let prim = &doc["meshes"][0]["primitives"][0];
        let acc = |name: &str| doc["accessors"][prim["attributes"][name].as_u64().unwrap() as usize].clone();
        let back = read_scene(&path).unwrap();
        let custom = &back.meshes[0].primitives[0].custom;
        let (w, b) = (&custom[0], &custom[1]);
        assert_eq!((w.name.as_str(), b.name.as_str()), (WIND_ATTRIBUTE, WIND_BRANCH_ATTRIBUTE));
        // the branch data lie outside their range: floats, as written
        assert_eq!(acc("_WIND_BRANCH")["componentType"], 5126, "{compact:?}");
        assert_eq!(b.values, branch);
        if compact == Compact::None {
            assert_eq!(acc("_WIND")["componentType"], 5126);
            assert!(prim.get("extras").is_none());
            assert_eq!(w.values, wind);
            continue;
        }
        assert_eq!(acc("_WIND")["componentType"], 5121, "{compact:?}: unsigned bytes");
        assert_eq!(acc("_WIND")["normalized"], true);
        let noted: Vec<f32> = prim["extras"][ATTRIBUTE_RANGES_KEY]["_WIND"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap() as f32)
            .collect();
        assert_eq!(noted, WIND_RANGE.to_vec());
        assert!(prim["extras"][ATTRIBUTE_RANGES_KEY].get("_WIND_BRANCH").is_none());
        assert_eq!(w.range, Some(WIND_RANGE));
        for (a, r) in wind.iter().zip(&w.values) {
            for k in 0..4 {
                assert!((a[k] - r[k]).abs() <= WIND_RANGE[k] / 510.0 * (1.0 + 1e-4), "{a:?} read back as {r:?}");
            }
        }
        // the ends of each range are exact
        assert_eq!(w.values[2], wind[2]);
        assert_eq!(w.values[0][0], 0.0);
        // a range that is not four positive numbers is an error naming it, not values scaled by 0
        let noted = format!("\"{ATTRIBUTE_RANGES_KEY}\":{{\"_WIND\":[1.0,");
        let json_end = 20 + u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        let at = bytes[..json_end].windows(noted.len()).position(|w| w == noted.as_bytes()).expect("the range noted");
        let mut bad = bytes.clone();
        bad[at + noted.len() - 4] = b'0';
        let bad_path = dir.path().join("bad.glb");
        std::fs::write(&bad_path, &bad).unwrap();
        let v = validate_file(&bad_path, &Default::default()).unwrap();
        assert!(v.errors() > 0 && format!("{v}").contains("not four positive finite numbers"), "{v}");
        // ranges lost (a tool that drops extras, here a renamed key): a warning, not silent 0..1 phases
        let mut lost = bytes.clone();
        lost[at + ATTRIBUTE_RANGES_KEY.len()] = b'z';
        std::fs::write(&bad_path, &lost).unwrap();
        let v = validate_file(&bad_path, &Default::default()).unwrap();
        assert!(v.warnings() > 0 && format!("{v}").contains("note no range"), "{v}");
        // read back, written again and read: the same values (the same bytes)
        let again = dir.path().join("again.glb");
        std::fs::write(&again, to_glb_with(&back, &compact.write_options()).unwrap()).unwrap();
        assert_eq!(read_scene(&again).unwrap().meshes[0].primitives[0].custom, *custom, "{compact:?}");
    }
}

/// Every `_WIND*` accessor of the GLB at `path` is normalized unsigned bytes with its ranges noted
/// in the primitive's extras (`compact`), or floats with none; and there is wind in the file.
fn assert_wind_stored(path: &Path, compact: bool) {
    let bytes = std::fs::read(path).unwrap();
    let n = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let doc: serde_json::Value = serde_json::from_slice(&bytes[20..20 + n]).unwrap();
    let mut wind = 0;
    for prim in doc["meshes"].as_array().into_iter().flatten().flat_map(|m| m["primitives"].as_array().unwrap()) {
        for (name, a) in prim["attributes"].as_object().unwrap().iter().filter(|(k, _)| k.starts_with("_WIND")) {
            let acc = &doc["accessors"][a.as_u64().unwrap() as usize];
            let noted = &prim["extras"][verdant::export::gltf::ATTRIBUTE_RANGES_KEY][name];
            if compact {
                assert_eq!((acc["componentType"].as_u64(), &acc["normalized"]), (Some(5121), &serde_json::json!(true)));
                assert_eq!(noted.as_array().map(|a| a.len()), Some(4), "{}: {name}", path.display());
            } else {
                assert_eq!(acc["componentType"].as_u64(), Some(5126), "{}: {name}", path.display());
                assert!(noted.is_null());
            }
            wind += 1;
        }
    }
    // (a model that does not sway has none: the boulder's files)
    let model = path.file_name().unwrap().to_string_lossy().contains("boulder");
    assert!(wind > 0 || model, "{}: no wind", path.display());
}
