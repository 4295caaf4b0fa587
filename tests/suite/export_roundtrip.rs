//! Writes scenes as .glb, .gltf and .obj, reads them back and validates them (public API only).
//!
//! Set VERDANT_GLTF_VALIDATOR to a node script wrapping the Khronos `gltf-validator` npm package
//! (usage: `node SCRIPT FILE...`, exit 0 only without errors and warnings) to also run it.

use std::fs;
use std::path::{Path, PathBuf};

use proptest::prelude::*;
use serde_json::json;
use verdant::export::{write_atomic, write_scene, ExportError};
use verdant::mesh::{AlphaMode, CustomAttribute, Instances, Material, Mesh, Node, Primitive, Scene, Texture};
use verdant::validate::{read_scene, validate_file, Severity, ValidateError, ValidateOptions};

fn tiny_png() -> Vec<u8> {
    let img = image::RgbaImage::from_fn(4, 4, |x, y| {
        image::Rgba([x as u8 * 60, y as u8 * 60, 128, if (x + y) % 2 == 0 { 255 } else { 0 }])
    });
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).unwrap();
    png
}

/// Two meshes (one with two primitives), a textured MASK material, a hierarchy with TRS and
/// extras, an instanced node and a LoD node.
fn sample_scene() -> Scene {
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let leaves = Primitive {
        positions: vec![[0.1, 1.0, -0.3], [1.7, 1.2, -0.3], [1.7, 2.9, 0.3], [0.1, 2.7, 0.3]],
        normals: vec![[0.0, s, -s], [0.0, s, -s], [0.0, 0.0, 1.0], [0.6, 0.0, 0.8]],
        uvs: vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.1], [0.0, 0.0]],
        colors: vec![[0.2, 0.5, 0.1, 1.0], [0.3, 0.6, 0.1, 0.5], [0.2, 0.7, 0.2, 1.0], [0.1, 0.5, 0.1, 0.0]],
        // in name order, as glTF's attribute map reads them back
        custom: vec![
            CustomAttribute {
                // stored as normalized bytes (the terrain's layer weights): k/255 comes back exactly
                name: "_LAYER_WEIGHTS".into(),
                values: vec![
                    [1.0, 0.0, 0.0, 0.0],
                    [51.0 / 255.0, 204.0 / 255.0, 0.0, 0.0],
                    [0.0, 0.0, 1.0, 0.0],
                    [0.2, 0.2, 0.2, 0.4],
                ],
                unit_bytes: true,
                range: None,
            },
            CustomAttribute {
                name: "_WIND".into(),
                values: vec![
                    [0.0, 0.25, 1.5, 0.8],
                    [0.0, 0.25, 1.5, 0.8],
                    [1.0, 0.25, 1.5, 0.8],
                    [1.0, 0.75, 2.0, 0.3],
                ],
                unit_bytes: false,
                // (what a reader gives `_WIND`: its documented ranges, docs/wind.md)
                range: Some(verdant::plants::wind::WIND_RANGE),
            },
        ],
        indices: vec![0, 1, 2, 0, 2, 3],
        material: Some(0),
        ..Primitive::default()
    };
    let trunk = Primitive {
        positions: vec![[-0.1, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 1.3, 0.0]],
        normals: vec![[0.0, 0.0, 1.0]; 3],
        indices: vec![0, 1, 2],
        material: Some(1),
        ..Primitive::default()
    };
    let ground = Primitive {
        positions: vec![[-5.0, 0.0, -5.0], [-5.0, 0.0, 5.0], [5.0, 0.25, 5.0], [5.0, 0.0, -5.0]],
        normals: vec![[0.0, 1.0, 0.0]; 4],
        uvs: vec![[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]],
        indices: vec![0, 1, 2, 0, 2, 3],
        ..Primitive::default()
    };
    let mut scene = Scene {
        name: "sample".into(),
        meshes: vec![
            Mesh { name: "tree".into(), primitives: vec![leaves, trunk], extras: Some(json!({"species": "oak"})) },
            Mesh { name: "ground".into(), primitives: vec![ground], extras: None },
        ],
        materials: vec![
            Material {
                name: "leaf".into(),
                base_color: [0.5, 0.8, 0.3, 1.0],
                base_color_texture: Some(0),
                // the same image as its normal map: the round trip keeps normalTexture
                normal_texture: Some(0),
                metallic: 0.0,
                roughness: 0.75,
                alpha_mode: AlphaMode::Mask { cutoff: 0.7 },
                double_sided: true,
            },
            Material { name: "bark".into(), base_color: [0.4, 0.3, 0.2, 1.0], metallic: 0.25, ..Material::default() },
        ],
        textures: vec![Texture { name: "leaf_albedo".into(), png: tiny_png() }],
        extras: Some(json!({"seed": 42, "preset": "test"})),
        ..Scene::default()
    };
    let h = 0.5f32.sqrt();
    scene.nodes = vec![
        Node { name: "root".into(), children: vec![1], extras: Some(json!({"tile": [0, 1]})), ..Node::default() },
        Node {
            name: "child".into(),
            mesh: Some(0),
            translation: [1.5, 0.25, -3.0],
            rotation: [0.0, h, 0.0, h],
            scale: [2.0, 2.0, 2.0],
            extras: Some(json!({"age": 12.5})),
            ..Node::default()
        },
        Node { name: "ground".into(), mesh: Some(1), ..Node::default() },
        Node {
            name: "forest".into(),
            mesh: Some(0),
            instances: Some(std::sync::Arc::new(Instances {
                translations: vec![[0.0, 0.0, 0.0], [3.0, 0.0, 1.0], [-2.5, 0.1, 4.0]],
                rotations: vec![[0.0, 0.0, 0.0, 1.0], [0.0, h, 0.0, h], [0.0, 1.0, 0.0, 0.0]],
                scales: vec![[1.0; 3], [0.8; 3], [1.2, 1.1, 1.2]],
            })),
            ..Node::default()
        },
        Node {
            name: "tree_LOD0".into(),
            mesh: Some(0),
            translation: [4.0, 0.0, 4.0],
            lods: vec![5],
            lod_screen_coverage: vec![0.5, 0.1],
            extras: Some(json!({"kind": "lod"})),
            ..Node::default()
        },
        Node { name: "tree_LOD1".into(), mesh: Some(1), translation: [4.0, 0.0, 4.0], ..Node::default() },
    ];
    scene.roots = vec![0, 2, 3, 4];
    scene
}

fn no_temp_files(dir: &Path) {
    for e in fs::read_dir(dir).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().to_string();
        // `.<name>.<pid>-<n>.tmp[.<ext>]`
        assert!(!(name.starts_with('.') && name.contains(".tmp")), "temporary file left behind: {name}");
    }
}

fn run_khronos_validator(files: &[PathBuf]) {
    let Ok(script) = std::env::var("VERDANT_GLTF_VALIDATOR") else { return };
    let out = std::process::Command::new("node").arg(script).args(files).output().expect("run node");
    let text = String::from_utf8_lossy(&out.stdout);
    println!("{text}");
    assert!(out.status.success(), "Khronos validator reported errors or warnings:\n{text}");
}

#[test]
fn gltf_and_glb_round_trip_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let scene = sample_scene();
    let glb = dir.path().join("out/sample.glb");
    let gltf = dir.path().join("out/sample.gltf");
    assert_eq!(write_scene(&scene, &glb).unwrap(), vec![glb.clone()]);
    let written = write_scene(&scene, &gltf).unwrap();
    assert_eq!(written, vec![dir.path().join("out/sample.bin"), gltf.clone()]);
    for path in [&glb, &gltf] {
        let back = read_scene(path).unwrap();
        // everything, bit for bit: attributes, indices, materials, textures, hierarchy, extras,
        // instancing and LoD
        assert_eq!(back, scene, "{}", path.display());
        let report = validate_file(path, &ValidateOptions::default()).unwrap();
        assert!(report.ok() && report.issues.is_empty(), "{report}");
        assert_eq!(report.meshes.len(), 2);
        assert_eq!((report.meshes[0].vertices(), report.meshes[0].triangles()), (7, 3));
    }
    // the JSON says what the extensions need
    let json: serde_json::Value = serde_json::from_slice(&fs::read(&gltf).unwrap()).unwrap();
    assert_eq!(json["extensionsUsed"], json!(["EXT_mesh_gpu_instancing", "MSFT_lod"]));
    // instancing is required (one copy at the node would be wrong); MSFT_lod degrades gracefully
    assert_eq!(json["extensionsRequired"], json!(["EXT_mesh_gpu_instancing"]));
    assert_eq!(json["nodes"][4]["extensions"]["MSFT_lod"]["ids"], json!([5]));
    // the level shown only through MSFT_lod is in a second scene: used, but not the default one
    assert_eq!(json["scene"], json!(0));
    assert_eq!(json["scenes"][0]["nodes"], json!([0, 2, 3, 4]));
    assert_eq!(json["scenes"][1]["nodes"], json!([5]));
    assert_eq!(json["nodes"][4]["extras"]["MSFT_screencoverage"], json!([0.5, 0.10000000149011612]));
    assert!(json["nodes"][2].get("translation").is_none(), "identity TRS omitted");
    assert_eq!(json["materials"][0]["alphaMode"], "MASK");
    assert_eq!(json["images"][0]["mimeType"], "image/png");
    assert_eq!(json["asset"]["generator"], format!("verdant {}", env!("CARGO_PKG_VERSION")));
    for view in json["bufferViews"].as_array().unwrap() {
        assert_eq!(view["byteOffset"].as_u64().unwrap_or(0) % 4, 0);
    }
    no_temp_files(&dir.path().join("out"));
    run_khronos_validator(&[glb, gltf]);
}

#[test]
fn written_files_hold_only_what_the_scene_shows() {
    // the sample scene plus a mesh no node shows, a node under no root, a material no primitive uses
    // and a second copy of the bark material that the trunk uses (as a chain assembled from level files has)
    let mut scene = sample_scene();
    let orphan_mesh = scene.meshes[0].clone();
    scene.meshes.push(Mesh { name: "unused".into(), ..orphan_mesh });
    scene.nodes.push(Node { name: "orphan".into(), mesh: Some(0), ..Node::default() });
    scene.materials.push(Material { name: "never used".into(), ..Material::default() });
    let copy = scene.materials[1].clone();
    scene.materials.push(copy);
    scene.meshes[0].primitives[1].material = Some(scene.materials.len() - 1);
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("compact.glb");
    write_scene(&scene, &glb).unwrap();
    let back = read_scene(&glb).unwrap();
    // what the sample shows, exactly: the extra mesh, node and materials are gone, the copy merged
    let sample = sample_scene();
    assert_eq!(back.nodes, sample.nodes);
    assert_eq!(back.meshes, sample.meshes);
    assert_eq!(back.materials, sample.materials);
    assert_eq!(back.textures, sample.textures);
    // and the same bytes as the sample itself
    let plain = dir.path().join("sample.glb");
    write_scene(&sample, &plain).unwrap();
    assert_eq!(fs::read(&glb).unwrap(), fs::read(&plain).unwrap());
    run_khronos_validator(&[glb]);
}

/// One triangle corner: position, normal, uv.
type Corner = ([f32; 3], Option<[f32; 3]>, Option<[f32; 2]>);

/// Each triangle's three corners, in order.
fn corners(p: &Primitive) -> Vec<Corner> {
    p.indices
        .iter()
        .map(|&i| {
            let i = i as usize;
            (p.positions[i], p.normals.get(i).copied(), p.uvs.get(i).copied())
        })
        .collect()
}

#[test]
fn obj_round_trips_values() {
    let dir = tempfile::tempdir().unwrap();
    let scene = sample_scene();
    let path = dir.path().join("sample.obj");
    let written = write_scene(&scene, &path).unwrap();
    let names: Vec<String> = written.iter().map(|p| p.file_name().unwrap().to_string_lossy().into()).collect();
    assert_eq!(names, ["sample_0_leaf_albedo.png", "sample.mtl", "sample.obj"]);
    let report = validate_file(&path, &ValidateOptions::default()).unwrap();
    assert!(report.ok(), "{report}");

    let back = read_scene(&path).unwrap();
    let mesh_names: Vec<&str> = back.meshes.iter().map(|m| m.name.as_str()).collect();
    // depth-first from the roots; instances expanded; the LoD level outside the hierarchy skipped
    assert_eq!(mesh_names, ["child", "ground", "forest_0", "forest_1", "forest_2", "tree_LOD0"]);

    // the ground has an identity transform: every corner comes back exactly (after un-welding)
    let ground = &back.meshes[1];
    assert_eq!(corners(&ground.primitives[0]), corners(&scene.meshes[1].primitives[0]));
    // forest_0 is the tree mesh untransformed: both primitives, one per material
    let tree = &back.meshes[2];
    assert_eq!(tree.primitives.len(), 2);
    for (a, b) in tree.primitives.iter().zip(&scene.meshes[0].primitives) {
        let (ca, cb) = (corners(a), corners(b));
        for (x, y) in ca.iter().zip(&cb) {
            assert_eq!(x.0, y.0);
            assert_eq!(x.1, y.1);
            // v comes back as 1 − (1 − v): exact for these except within an ulp of 1.0
            if let (Some(u), Some(w)) = (x.2, y.2) {
                assert_eq!(u[0], w[0]);
                assert!((u[1] - w[1]).abs() <= f32::EPSILON, "{u:?} {w:?}");
            }
        }
        assert_eq!(a.material, b.material);
    }
    // the child is scaled by 2, turned 90° about Y and moved
    let child = &back.meshes[0].primitives[1];
    assert!(child
        .positions
        .iter()
        .any(|p| (p[0] - 1.5).abs() < 1e-5 && (p[1] - 2.85).abs() < 1e-5 && (p[2] + 3.0).abs() < 1e-5));

    // materials
    assert_eq!(back.materials.len(), 2);
    for (a, b) in back.materials.iter().zip(&scene.materials) {
        assert_eq!(a.name, b.name);
        assert_eq!(a.base_color, b.base_color);
        assert_eq!((a.metallic, a.roughness), (b.metallic, b.roughness));
        assert_eq!(a.base_color_texture, b.base_color_texture);
    }
    assert_eq!(back.textures[0].png, scene.textures[0].png);
}

#[test]
fn large_meshes_use_32_bit_indices() {
    let dir = tempfile::tempdir().unwrap();
    let grid = |side: u32| {
        let mut p = Primitive::default();
        for j in 0..side {
            for i in 0..side {
                p.positions.push([i as f32 * 0.5, ((i * 7 + j * 3) % 11) as f32 * 0.1, j as f32 * 0.5]);
                p.normals.push([0.0, 1.0, 0.0]);
            }
        }
        for j in 0..side - 1 {
            for i in 0..side - 1 {
                let a = j * side + i;
                p.indices.extend_from_slice(&[a, a + side, a + 1, a + 1, a + side, a + side + 1]);
            }
        }
        let mut scene = Scene::default();
        scene.add_mesh_node(Mesh { name: "grid".into(), primitives: vec![p], extras: None });
        scene
    };
    let mut files = Vec::new();
    // 65,536 vertices: the largest index, 65535, is the primitive restart value, so u32
    for (side, component) in [(256u32, 5125u64), (265, 5125)] {
        let scene = grid(side); // 65,536 and 70,225 vertices
        let path = dir.path().join(format!("grid{side}.gltf"));
        write_scene(&scene, &path).unwrap();
        let json: serde_json::Value = serde_json::from_slice(&fs::read(&path).unwrap()).unwrap();
        let indices = json["meshes"][0]["primitives"][0]["indices"].as_u64().unwrap() as usize;
        assert_eq!(json["accessors"][indices]["componentType"].as_u64().unwrap(), component, "side {side}");
        assert_eq!(read_scene(&path).unwrap(), scene);
        let report = validate_file(&path, &ValidateOptions { up_facing: false }).unwrap();
        assert!(report.ok(), "{report}");
        files.push(path);
    }
    // 65,535 vertices (max index 65534) still fit in u16
    let mut scene = grid(256);
    let p = &mut scene.meshes[0].primitives[0];
    p.positions.truncate(65535);
    p.normals.truncate(65535);
    let keep: Vec<u32> = p.indices.chunks(3).filter(|t| t.iter().all(|&i| i < 65535)).flatten().copied().collect();
    p.indices = keep;
    let path = dir.path().join("u16.gltf");
    write_scene(&scene, &path).unwrap();
    let json: serde_json::Value = serde_json::from_slice(&fs::read(&path).unwrap()).unwrap();
    let indices = json["meshes"][0]["primitives"][0]["indices"].as_u64().unwrap() as usize;
    assert_eq!(json["accessors"][indices]["componentType"], 5123);
    files.push(path);
    run_khronos_validator(&files);
}

#[test]
fn outputs_are_byte_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    for ext in ["glb", "gltf", "obj"] {
        let a = write_scene(&sample_scene(), &dir.path().join(format!("a/s.{ext}"))).unwrap();
        let b = write_scene(&sample_scene(), &dir.path().join(format!("b/s.{ext}"))).unwrap();
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(fs::read(x).unwrap(), fs::read(y).unwrap(), "{}", x.display());
        }
    }
}

#[test]
fn failed_writes_leave_previous_output_intact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("keep.glb");
    write_scene(&sample_scene(), &path).unwrap();
    let before = fs::read(&path).unwrap();

    // a broken scene never reaches the disk
    let mut broken = sample_scene();
    broken.meshes[1].primitives[0].indices[4] = 99;
    let err = write_scene(&broken, &path).unwrap_err();
    assert!(matches!(err, ExportError::InvalidScene { .. }));
    let msg = err.to_string();
    assert!(msg.contains("keep.glb") && msg.contains("99"), "{msg}");
    assert_eq!(fs::read(&path).unwrap(), before);

    // a folder where the file should go: the write fails, the folder and its content stay
    let blocked = dir.path().join("blocked.glb");
    fs::create_dir(&blocked).unwrap();
    fs::write(blocked.join("inside.txt"), b"x").unwrap();
    let err = write_scene(&sample_scene(), &blocked).unwrap_err();
    assert!(err.to_string().contains("blocked.glb"), "{err}");
    assert_eq!(fs::read(blocked.join("inside.txt")).unwrap(), b"x");
    let err = write_atomic(&blocked, b"bytes").unwrap_err();
    assert!(matches!(err, ExportError::Io { .. }));

    // a file where a parent folder should be
    let err = write_atomic(&path.join("sub.glb"), b"bytes").unwrap_err();
    assert!(err.to_string().contains("sub.glb"), "{err}");
    assert_eq!(fs::read(&path).unwrap(), before);
    no_temp_files(dir.path());
}

#[test]
fn validate_finds_broken_obj_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.obj");
    write_scene(&sample_scene(), &path).unwrap();
    let good = fs::read_to_string(&path).unwrap();

    // a NaN position
    let nan = good.replacen("v -5 0 -5", "v NaN 0 -5", 1);
    assert_ne!(nan, good);
    fs::write(&path, &nan).unwrap();
    let report = validate_file(&path, &ValidateOptions::default()).unwrap();
    assert!(!report.ok(), "{report}");
    assert!(report.issues.iter().any(|i| i.message.contains("not finite")), "{report}");

    // a face corner naming a vertex that does not exist
    let lines: Vec<&str> = good.lines().collect();
    let f = lines.iter().position(|l| l.starts_with("f ")).unwrap();
    let mut bad_lines: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    bad_lines[f] = "f 9999/1/1 2/2/2 3/3/3".into();
    fs::write(&path, bad_lines.join("\n")).unwrap();
    let report = validate_file(&path, &ValidateOptions::default()).unwrap();
    assert!(!report.ok());
    let issue = &report.issues[0];
    assert_eq!(issue.severity, Severity::Error);
    assert_eq!(issue.location, format!("line {}", f + 1));
    assert!(issue.message.contains("9999"), "{report}");
    assert!(report.to_string().contains("FAILED"), "{report}");
}

#[test]
fn validate_finds_broken_gltf_files() {
    let dir = tempfile::tempdir().unwrap();
    let scene = sample_scene();

    // truncated GLB: an error naming the file
    let glb = dir.path().join("cut.glb");
    write_scene(&scene, &glb).unwrap();
    let bytes = fs::read(&glb).unwrap();
    fs::write(&glb, &bytes[..bytes.len() / 2]).unwrap();
    let err = validate_file(&glb, &ValidateOptions::default()).unwrap_err();
    assert!(matches!(err, ValidateError::Parse { .. }));
    assert!(err.to_string().contains("cut.glb"), "{err}");
    assert!(read_scene(&glb).is_err());

    // a missing file
    let err = validate_file(&dir.path().join("missing.glb"), &ValidateOptions::default()).unwrap_err();
    assert!(matches!(err, ValidateError::Read { .. }) && err.to_string().contains("missing.glb"));

    // POSITION max that does not match the data
    let gltf = dir.path().join("bounds.gltf");
    write_scene(&scene, &gltf).unwrap();
    let mut json: serde_json::Value = serde_json::from_slice(&fs::read(&gltf).unwrap()).unwrap();
    json["accessors"][0]["max"][0] = json!(100.0);
    fs::write(&gltf, serde_json::to_vec(&json).unwrap()).unwrap();
    let report = validate_file(&gltf, &ValidateOptions::default()).unwrap();
    assert!(!report.ok());
    assert!(report.issues.iter().any(|i| i.message.contains("min/max")), "{report}");

    // an index out of range, patched into the binary buffer (u16 indices of the ground)
    let gltf = dir.path().join("index.gltf");
    write_scene(&scene, &gltf).unwrap();
    let json: serde_json::Value = serde_json::from_slice(&fs::read(&gltf).unwrap()).unwrap();
    let acc = json["meshes"][1]["primitives"][0]["indices"].as_u64().unwrap() as usize;
    let view = json["accessors"][acc]["bufferView"].as_u64().unwrap() as usize;
    let offset = json["bufferViews"][view]["byteOffset"].as_u64().unwrap() as usize;
    let bin_path = dir.path().join("index.bin");
    let mut bin = fs::read(&bin_path).unwrap();
    bin[offset + 2..offset + 4].copy_from_slice(&500u16.to_le_bytes());
    fs::write(&bin_path, &bin).unwrap();
    let report = validate_file(&gltf, &ValidateOptions::default()).unwrap();
    assert!(!report.ok());
    assert!(report.issues.iter().any(|i| i.message.contains("is 500")), "{report}");
}

#[test]
fn up_facing_check_for_terrain() {
    let dir = tempfile::tempdir().unwrap();
    let mut scene = sample_scene();
    scene.roots = vec![2]; // only the ground
    let path = dir.path().join("terrain.glb");
    write_scene(&scene, &path).unwrap();
    let up = ValidateOptions { up_facing: true };
    assert!(validate_file(&path, &up).unwrap().ok());
    // wound clockwise: both triangles face down
    for t in scene.meshes[1].primitives[0].indices.chunks_mut(3) {
        t.swap(1, 2);
    }
    write_scene(&scene, &path).unwrap();
    let report = validate_file(&path, &up).unwrap();
    assert_eq!(report.errors(), 2, "{report}");
    assert!(validate_file(&path, &ValidateOptions::default()).unwrap().ok());
}

fn unit_vector() -> impl Strategy<Value = [f32; 3]> {
    (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0)
        .prop_filter("not too short", |(x, y, z)| x * x + y * y + z * z > 0.01)
        .prop_map(|(x, y, z)| {
            let l = (x * x + y * y + z * z).sqrt();
            [x / l, y / l, z / l]
        })
}

fn small_mesh() -> impl Strategy<Value = Primitive> {
    (3usize..40).prop_flat_map(|n| {
        (
            prop::collection::vec(prop::array::uniform3(-1.0e4f32..1.0e4), n),
            prop::collection::vec(unit_vector(), n),
            prop::collection::vec(prop::array::uniform2(-2.0f32..2.0), n),
            prop::collection::vec(0..n as u32, 3..90),
            any::<bool>(),
        )
            .prop_map(|(positions, normals, uvs, mut indices, with_uvs)| {
                indices.truncate(indices.len() / 3 * 3);
                Primitive {
                    positions,
                    normals,
                    uvs: if with_uvs { uvs } else { Vec::new() },
                    indices,
                    ..Primitive::default()
                }
            })
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn random_meshes_round_trip_through_glb(prims in prop::collection::vec(small_mesh(), 1..3)) {
        let dir = tempfile::tempdir().unwrap();
        let mut scene = Scene::default();
        scene.add_mesh_node(Mesh { name: "random".into(), primitives: prims, extras: None });
        let path = dir.path().join("r.glb");
        write_scene(&scene, &path).unwrap();
        prop_assert_eq!(read_scene(&path).unwrap(), scene);
    }

    #[test]
    fn damaged_glb_never_panics(cut in 0usize..2000, flips in prop::collection::vec((0usize..2000, any::<u8>()), 0..8)) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.glb");
        write_scene(&sample_scene(), &path).unwrap();
        let mut bytes = fs::read(&path).unwrap();
        for (at, value) in flips {
            let n = bytes.len();
            bytes[at % n] = value;
        }
        bytes.truncate(bytes.len().saturating_sub(cut));
        fs::write(&path, &bytes).unwrap();
        // any outcome but a panic is fine
        let _ = validate_file(&path, &ValidateOptions { up_facing: true });
        let _ = read_scene(&path);
    }
}

#[test]
fn empty_scene_writes_valid_files_without_buffers() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene { name: "empty".into(), ..Scene::default() };
    let mut files = Vec::new();
    for ext in ["glb", "gltf", "obj"] {
        let path = dir.path().join(format!("e.{ext}"));
        assert_eq!(write_scene(&scene, &path).unwrap(), vec![path.clone()], "no .bin/.mtl for nothing");
        let report = validate_file(&path, &ValidateOptions::default()).unwrap();
        assert!(report.ok() && report.meshes.is_empty(), "{report}");
        if ext != "obj" {
            // no roots: the glTF has no scene object, so name and extras are not kept
            assert_eq!(read_scene(&path).unwrap(), Scene::default());
            files.push(path);
        }
    }
    run_khronos_validator(&files);
}

#[test]
fn a_lod_chain_glb_streams_each_finer_level_from_its_own_buffer() {
    // a three-level chain, finest first: node 0 (mesh 0) with MSFT_lod levels node 1 (mesh 1) and
    // node 2 (mesh 2). Babylon.js streams the coarsest first and, with its default options, defers a
    // level only when its data comes through a URI: so the coarsest level's data is in the GLB
    // chunk, each finer level's in a data: URI buffer of its own (the old single-chunk files made
    // 5 of 10 chains fail to load there)
    let tri = |y: f32| Primitive {
        positions: vec![[0.0, y, 0.0], [1.0, y, 0.0], [0.0, y, 1.0]],
        indices: vec![0, 2, 1],
        material: Some(0),
        ..Primitive::default()
    };
    let mesh = |name: &str, y: f32| Mesh { name: name.into(), primitives: vec![tri(y)], extras: None };
    let scene = Scene {
        meshes: vec![mesh("lod0", 0.0), mesh("lod1", 1.0), mesh("lod2", 2.0)],
        materials: vec![Material::default()],
        nodes: vec![
            Node {
                name: "t_LOD0".into(),
                mesh: Some(0),
                lods: vec![1, 2],
                lod_screen_coverage: vec![0.5, 0.2, 0.05],
                ..Node::default()
            },
            Node { name: "t_LOD1".into(), mesh: Some(1), ..Node::default() },
            Node { name: "t_LOD2".into(), mesh: Some(2), ..Node::default() },
        ],
        roots: vec![0],
        ..Scene::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("chain.glb");
    write_scene(&scene, &path).unwrap();
    let bytes = fs::read(&path).unwrap();
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let doc: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let buffers = doc["buffers"].as_array().unwrap();
    assert_eq!(buffers.len(), 3, "{buffers:?}");
    assert!(buffers[0].get("uri").is_none(), "the coarsest level is in the GLB chunk");
    for b in &buffers[1..] {
        assert!(b["uri"].as_str().unwrap().starts_with("data:application/octet-stream;base64,"));
    }
    // each mesh's POSITION lives in its level's buffer: LoD2 (coarsest) 0, LoD1 1, LoD0 2
    let buffer_of_mesh = |m: usize| {
        let a = doc["meshes"][m]["primitives"][0]["attributes"]["POSITION"].as_u64().unwrap() as usize;
        let v = doc["accessors"][a]["bufferView"].as_u64().unwrap() as usize;
        doc["bufferViews"][v]["buffer"].as_u64().unwrap()
    };
    let by_name: Vec<(String, u64)> =
        (0..3).map(|m| (doc["meshes"][m]["name"].as_str().unwrap().to_string(), buffer_of_mesh(m))).collect();
    for (name, buffer) in by_name {
        let want = match name.as_str() {
            "lod2" => 0,
            "lod1" => 1,
            "lod0" => 2,
            other => panic!("{other}"),
        };
        assert_eq!(buffer, want, "{name}");
    }
    // every reader gets the same scene back, and the file is valid glTF
    let back = read_scene(&path).unwrap();
    assert_eq!(back.meshes.len(), 3);
    let mut names: Vec<&str> = back.meshes.iter().map(|m| m.name.as_str()).collect();
    names.sort();
    assert_eq!(names, ["lod0", "lod1", "lod2"]);
    for m in &back.meshes {
        let orig = scene.meshes.iter().find(|o| o.name == m.name).unwrap();
        assert_eq!(m.primitives, orig.primitives);
    }
    run_khronos_validator(&[path]);
}
