//! Bring your own mesh: OBJ (+ MTL + PNG) models written here procedurally — a noisy rock, the same
//! rock exported Z-up, a small tree with alpha-tested leaf cards — go through `load_obj` and
//! `build_mesh_lods` / `verdant mesh`: every level a valid glb that re-imports as built, triangles
//! strictly decreasing, LoD1 close to LoD0, the base on y = 0, Z-up equal to Y-up, byte-identical at
//! 1 and 2 threads, and bad inputs rejected with errors naming the file.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use verdant::mesh::AlphaMode;
use verdant::plants::mesh_asset::{load_obj, MeshAssetError, ObjOptions, UpAxis};
use verdant::plants::tree_lod::{build_mesh_lods, run_mesh_lods, MeshLodJob, TreeLodOptions, TREE_LODS};
use verdant::validate::{read_scene, validate_file};

use crate::common::lod::{bytes_of, in_pool, small_atlas};

/// A rock: an icosahedron subdivided 3 times (1280 triangles), pushed in and out by smooth
/// bumps, flattened underneath, 2 m across and centred away from the origin (at (5, 3, −2)).
fn rock_vertices_and_faces() -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<[f64; 3]> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut f: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let unit = |p: [f64; 3]| {
        let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        [p[0] / l, p[1] / l, p[2] / l]
    };
    for p in &mut v {
        *p = unit(*p);
    }
    for _ in 0..3 {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::new();
        for tri in &f {
            let mut m = [0usize; 3];
            for k in 0..3 {
                let (a, b) = (tri[k].min(tri[(k + 1) % 3]), tri[k].max(tri[(k + 1) % 3]));
                m[k] = *mid.entry((a, b)).or_insert_with(|| {
                    let (pa, pb) = (v[a], v[b]);
                    v.push(unit([(pa[0] + pb[0]) / 2.0, (pa[1] + pb[1]) / 2.0, (pa[2] + pb[2]) / 2.0]));
                    v.len() - 1
                });
            }
            next.extend([[tri[0], m[0], m[2]], [tri[1], m[1], m[0]], [tri[2], m[2], m[1]], [m[0], m[1], m[2]]]);
        }
        f = next;
    }
    for p in &mut v {
        let bump = 1.0 + 0.12 * (3.0 * p[0]).sin() * (2.0 * p[2]).cos() + 0.06 * (5.0 * p[1] + 1.0).sin();
        let y = (p[1] * bump * 0.7).max(-0.45);
        *p = [5.0 + p[0] * bump, 3.0 + y, -2.0 + p[2] * bump * 0.9];
    }
    (v, f)
}

fn write_rock(dir: &Path, name: &str, z_up: bool) -> PathBuf {
    let (v, f) = rock_vertices_and_faces();
    let mut obj = format!("# a rock\nmtllib {name}.mtl\no rock\n");
    for p in &v {
        // a Z-up export of the same rock: file (x, y, z) = (x, −z, y), which turns back exactly
        let q = if z_up { [p[0], -p[2], p[1]] } else { *p };
        writeln!(obj, "v {} {} {}", q[0] as f32, q[1] as f32, q[2] as f32).unwrap();
    }
    obj.push_str("usemtl stone\n");
    for t in &f {
        writeln!(obj, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1).unwrap();
    }
    std::fs::write(dir.join(format!("{name}.obj")), obj).unwrap();
    std::fs::write(dir.join(format!("{name}.mtl")), "newmtl stone\nKd 0.40 0.36 0.30\nd 1\n").unwrap();
    dir.join(format!("{name}.obj"))
}

/// A 64² leaf: an opaque green ellipse, transparent around it.
fn write_leaf_png(path: &Path) {
    let img = image::RgbaImage::from_fn(64, 64, |x, y| {
        let (u, v) = ((x as f32 + 0.5) / 32.0 - 1.0, (y as f32 + 0.5) / 32.0 - 1.0);
        if u * u / 0.4 + v * v < 0.9 {
            image::Rgba([40, 120 + (y % 16) as u8, 30, 255])
        } else {
            image::Rgba([0, 0, 0, 0])
        }
    });
    img.save(path).unwrap();
}

/// A small tree: a 10-sided tapered trunk (with normals and UVs) and 24 leaf cards (alpha-textured
/// quads with UVs, no normals) in a crown, in centimetres.
fn write_tree(dir: &Path) -> PathBuf {
    let mut obj = String::from("mtllib tree.mtl\no trunk\n");
    let sides = 10;
    let rings = 6;
    for r in 0..rings {
        let y = r as f64 * 60.0;
        let radius = 12.0 - r as f64 * 1.5;
        for s in 0..sides {
            let a = std::f64::consts::TAU * s as f64 / sides as f64;
            writeln!(obj, "v {} {} {}", radius * a.cos(), y, radius * a.sin()).unwrap();
            writeln!(obj, "vn {} 0 {}", a.cos(), a.sin()).unwrap();
            writeln!(obj, "vt {} {}", s as f64 / sides as f64, r as f64 / rings as f64).unwrap();
        }
    }
    obj.push_str("usemtl bark\n");
    for r in 0..rings - 1 {
        for s in 0..sides {
            let a = r * sides + s + 1;
            let b = r * sides + (s + 1) % sides + 1;
            let (c, d) = (a + sides, b + sides);
            // counter-clockwise seen from outside
            writeln!(obj, "f {d}/{d}/{d} {b}/{b}/{b} {a}/{a}/{a} {c}/{c}/{c}").unwrap();
        }
    }
    let base_v = rings * sides;
    let base_vt = rings * sides;
    obj.push_str("o leaves\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl leaf\n");
    for k in 0..24 {
        let a = k as f64 * 2.39996;
        let (r, y) = (30.0 + 25.0 * ((k * 7) % 5) as f64 / 4.0, 200.0 + 12.0 * (k % 8) as f64);
        let (cx, cz) = (r * a.cos(), r * a.sin());
        let (ux, uz) = (-a.sin() * 15.0, a.cos() * 15.0);
        for (du, dv) in [(-1.0, 0.0), (1.0, 0.0), (1.0, 30.0), (-1.0, 30.0)] {
            writeln!(obj, "v {} {} {}", cx + ux * du, y + dv, cz + uz * du).unwrap();
        }
        let v0 = base_v + 4 * k + 1;
        let t0 = base_vt + 1;
        writeln!(obj, "f {}/{} {}/{} {}/{} {}/{}", v0, t0, v0 + 1, t0 + 1, v0 + 2, t0 + 2, v0 + 3, t0 + 3).unwrap();
    }
    std::fs::write(dir.join("tree.obj"), obj).unwrap();
    std::fs::write(
        dir.join("tree.mtl"),
        "newmtl bark\nKd 0.35 0.22 0.12\n\nnewmtl leaf\nKd 1 1 1\nmap_Kd textures/leaf.png\n",
    )
    .unwrap();
    std::fs::create_dir_all(dir.join("textures")).unwrap();
    write_leaf_png(&dir.join("textures/leaf.png"));
    dir.join("tree.obj")
}

#[test]
fn rock_stands_on_the_origin_and_z_up_equals_y_up() {
    let dir = tempfile::tempdir().unwrap();
    let y_up = load_obj(&write_rock(dir.path(), "rock", false), &ObjOptions::default()).unwrap();
    let b = y_up.stats.bounds.unwrap();
    assert_eq!(b.min[1], 0.0, "base at y = 0");
    assert!((b.min[0] + b.max[0]).abs() < 1e-5 && (b.min[2] + b.max[2]).abs() < 1e-5, "footprint centred: {b:?}");
    assert_eq!(y_up.stats.triangles, 1280);
    assert_eq!(y_up.stats.normals_generated, 1, "the OBJ has no normals");
    assert_eq!(y_up.scene.materials[0].name, "stone");
    // normals point away from the rock's middle
    let p = &y_up.mesh().primitives[0];
    let mid = [(b.min[0] + b.max[0]) / 2.0, (b.min[1] + b.max[1]) / 2.0, (b.min[2] + b.max[2]) / 2.0];
    let outward = p
        .positions
        .iter()
        .zip(&p.normals)
        .filter(|(v, n)| (0..3).map(|k| (v[k] - mid[k]) * n[k]).sum::<f32>() > 0.0)
        .count();
    assert!(outward as f64 > 0.95 * p.positions.len() as f64, "{outward} of {} normals point out", p.positions.len());

    let z_up =
        load_obj(&write_rock(dir.path(), "rock_z", true), &ObjOptions { up_axis: UpAxis::Z, ..ObjOptions::default() })
            .unwrap();
    assert_eq!(z_up.mesh().primitives, y_up.mesh().primitives, "the Z-up export turns back into the Y-up rock");
    // read as Y-up, the same file lies on its side
    let wrong = load_obj(&dir.path().join("rock_z.obj"), &ObjOptions::default()).unwrap();
    assert_ne!(wrong.mesh().primitives, y_up.mesh().primitives);

    // scale: centimetres to metres
    let cm = load_obj(&dir.path().join("rock.obj"), &ObjOptions { scale: 0.01, ..ObjOptions::default() }).unwrap();
    let bc = cm.stats.bounds.unwrap();
    assert!(((bc.max[1] - bc.min[1]) - 0.01 * (b.max[1] - b.min[1])).abs() < 1e-5);
}

#[test]
fn rock_chain_is_valid_reimports_as_built_and_decreases() {
    let dir = tempfile::tempdir().unwrap();
    let input = write_rock(dir.path(), "rock", false);
    let out = dir.path().join("out/boulder.glb");
    let job = MeshLodJob { input: input.clone(), output: out.clone(), obj: ObjOptions::default(), lod: small_atlas() };
    let report = run_mesh_lods(&job).unwrap();
    assert_eq!((report.validation_errors, report.validation_warnings), (0, 0));
    let source = load_obj(&input, &ObjOptions::default()).unwrap();
    let built = build_mesh_lods(&source, "rock", &small_atlas()).unwrap();
    assert_eq!(built.levels.len(), TREE_LODS);
    let mut last = usize::MAX;
    for lod in &built.levels {
        let path = dir.path().join(format!("out/boulder_LOD{}.glb", lod.level));
        let v = validate_file(&path, &Default::default()).unwrap();
        assert_eq!((v.errors(), v.warnings()), (0, 0), "LoD{}: {v}", lod.level);
        let scene = read_scene(&path).unwrap();
        assert_eq!(scene.meshes[0].primitives, lod.scene.meshes[0].primitives, "LoD{} re-imports as built", lod.level);
        assert_eq!(scene.materials, lod.scene.materials);
        let tris = lod.triangles();
        assert!(tris < last, "LoD{}: {tris} triangles, not fewer than {last}", lod.level);
        last = tris;
    }
    assert_eq!(
        bytes_of(&built)[..TREE_LODS],
        built
            .levels
            .iter()
            .map(|l| std::fs::read(dir.path().join(format!("out/boulder_LOD{}.glb", l.level))).unwrap())
            .collect::<Vec<_>>()[..]
    );
    let chain = read_scene(&out).unwrap();
    assert_eq!(chain.nodes[chain.roots[0]].lods.len(), TREE_LODS - 1, "MSFT_lod chain");
    assert!(
        dir.path().join("out/boulder_atlas.png").is_file() && dir.path().join("out/boulder_atlas_mip1.png").is_file()
    );
    assert_eq!(built.levels[2].kind, "decimated");
    assert!(built.levels[2].triangles() <= built.levels[0].triangles() / 5, "LoD2 is a strong simplification");

    // LoD1 stays within a few percent of the rock's size; the billboards do not
    let lods = &report.chain.lods;
    let radius = report.chain.bounding_radius_m;
    assert!(lods[1].geometric_error.samples > 0);
    assert!(
        lods[1].geometric_error.max_m < 0.03 * radius,
        "LoD1 moved {} m (radius {radius})",
        lods[1].geometric_error.max_m
    );
    assert!(lods[3].geometric_error.max_m > lods[1].geometric_error.max_m);
    for w in lods.windows(2) {
        assert!(w[1].switch_distance_m >= w[0].switch_distance_m);
    }
    // the image analyzer measured LoD1: every measured distance from its switch on is within the budget
    assert!(!lods[1].measured.is_empty(), "the image analyzer measured LoD1");
    assert!(lods[1].measured.iter().filter(|r| r.distance_m >= lods[1].switch_distance_m).all(|r| r.passes));
    assert!(lods[4].switch_distance_m > radius, "the impostor switches in beyond the rock's size");
}

#[test]
fn mesh_lods_are_byte_identical_at_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let source = load_obj(&write_tree(dir.path()), &ObjOptions { scale: 0.01, ..ObjOptions::default() }).unwrap();
    let opts = small_atlas();
    let one = in_pool(1, || build_mesh_lods(&source, "tree", &opts).unwrap());
    let two = in_pool(2, || build_mesh_lods(&source, "tree", &opts).unwrap());
    assert_eq!(bytes_of(&one), bytes_of(&two));
    assert_eq!(one.report.lods, two.report.lods, "the analyzer's figures too");
}

#[test]
fn tree_obj_with_alpha_leaf_cards_gets_a_masked_double_sided_material_and_a_valid_chain() {
    let dir = tempfile::tempdir().unwrap();
    let input = write_tree(dir.path());
    let source = load_obj(&input, &ObjOptions { scale: 0.01, ..ObjOptions::default() }).unwrap();
    assert_eq!(source.scene.textures.len(), 1);
    let leaf = source.scene.materials.iter().find(|m| m.name == "leaf").unwrap();
    assert_eq!(leaf.alpha_mode, AlphaMode::Mask { cutoff: 0.5 });
    assert!(leaf.double_sided && leaf.base_color_texture == Some(0));
    let bark = source.scene.materials.iter().find(|m| m.name == "bark").unwrap();
    assert_eq!(bark.alpha_mode, AlphaMode::Opaque);
    assert!((bark.base_color[0] - 0.35).abs() < 1e-6);
    assert_eq!(source.stats.normals_generated, 1, "the trunk's normals are the file's, the cards' generated");
    let b = source.stats.bounds.unwrap();
    assert_eq!(b.min[1], 0.0);
    assert!((b.max[1] - 314.0 * 0.01).abs() < 1e-5, "314 cm scaled to metres: {b:?}");
    let out = dir.path().join("tree.glb");
    let report = run_mesh_lods(&MeshLodJob {
        input,
        output: out,
        obj: ObjOptions { scale: 0.01, ..ObjOptions::default() },
        lod: TreeLodOptions { analyze: false, ..small_atlas() },
    })
    .unwrap();
    assert_eq!((report.validation_errors, report.validation_warnings), (0, 0));
    let tris: Vec<usize> = report.chain.lods.iter().map(|l| l.triangles).collect();
    assert!(tris.windows(2).all(|w| w[1] < w[0]), "{tris:?}");
    // the leaves show in the impostor atlas (green, opaque texels)
    let atlas = image::open(dir.path().join("tree_atlas.png")).unwrap().to_rgba8();
    let green = atlas.pixels().filter(|p| p.0[3] > 128 && p.0[1] > p.0[0] + 40).count();
    assert!(green > 100, "{green} leaf texels in the atlas");
}

#[test]
fn bad_models_give_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let opts = ObjOptions::default();
    // missing file
    let e = load_obj(&dir.path().join("nope.obj"), &opts).unwrap_err();
    assert!(matches!(e, MeshAssetError::Read { .. }) && e.to_string().contains("nope.obj"), "{e}");
    // a garbage line: file, line and column
    std::fs::write(dir.path().join("bad.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nthis is not obj\nf 1 2 3\n").unwrap();
    let e = load_obj(&dir.path().join("bad.obj"), &opts).unwrap_err().to_string();
    assert!(e.contains("bad.obj:4:1") && e.contains("\"this\""), "{e}");
    std::fs::write(dir.path().join("nan.obj"), "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let e = load_obj(&dir.path().join("nan.obj"), &opts).unwrap_err().to_string();
    assert!(e.contains("nan.obj:2:5"), "{e}");
    std::fs::write(dir.path().join("range.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n").unwrap();
    let e = load_obj(&dir.path().join("range.obj"), &opts).unwrap_err().to_string();
    assert!(e.contains("range.obj:4:7") && e.contains("index 4"), "{e}");
    // missing MTL and missing texture name the file that is missing and the remedy
    std::fs::write(dir.path().join("nomtl.obj"), "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let e = load_obj(&dir.path().join("nomtl.obj"), &opts).unwrap_err().to_string();
    assert!(e.contains("gone.mtl") && e.contains("nomtl.obj") && e.contains("mtllib"), "{e}");
    let tree = write_tree(dir.path());
    std::fs::remove_file(dir.path().join("textures/leaf.png")).unwrap();
    let e = load_obj(&tree, &opts).unwrap_err().to_string();
    assert!(e.contains("leaf.png") && e.contains("tree.mtl") && e.contains("map_Kd"), "{e}");
    // limits
    let rock = write_rock(dir.path(), "rock", false);
    let e = load_obj(&rock, &ObjOptions { max_triangles: 1000, ..opts.clone() }).unwrap_err().to_string();
    assert!(e.contains("rock.obj") && e.contains("limit of 1000"), "{e}");
    // no MTL at all: the documented grey
    std::fs::write(dir.path().join("plain.obj"), "v 0 0 0\nv 1 0 0\nv 0 0 -1\nf 1 2 3\n").unwrap();
    let plain = load_obj(&dir.path().join("plain.obj"), &opts).unwrap();
    assert_eq!(plain.scene.materials[0].base_color, verdant::plants::mesh_asset::FALLBACK_GREY);
    // too small to simplify (one triangle): not an error; every level that would draw as many
    // triangles or more is left out and said so, the chain is LoD0 alone
    let built = build_mesh_lods(&plain, "plain", &small_atlas()).unwrap();
    assert_eq!(built.levels.len(), 1, "{:?}", built.report.left_out);
    assert_eq!(built.report.lods.len(), 1);
    assert_eq!(built.report.left_out.len(), 4, "{:?}", built.report.left_out);
    assert!(built.report.left_out.iter().all(|l| l.triangles >= l.previous_triangles && l.previous_triangles == 1));
}

fn verdant(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_verdant")).args(args).output().expect("run verdant")
}

#[test]
fn cli_mesh_writes_the_chain_like_tree_and_reports() {
    let dir = tempfile::tempdir().unwrap();
    let input = write_rock(dir.path(), "rock_z", true);
    let glb = dir.path().join("out/rock.glb");
    let report = dir.path().join("out/rock.json");
    let (i, g, r) = (input.to_str().unwrap(), glb.to_str().unwrap(), report.to_str().unwrap());
    let o = verdant(&[
        "--quiet",
        "mesh",
        i,
        "-o",
        g,
        "--up-axis",
        "z",
        "--scale",
        "0.5",
        "--lods",
        "4",
        "--atlas-size",
        "256",
        "--no-analysis",
        "--report",
        r,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for name in ["rock.glb", "rock_LOD0.glb", "rock_LOD3.glb", "rock_atlas.png", "rock_atlas_mip1.png"] {
        assert!(dir.path().join("out").join(name).is_file(), "{name} missing");
    }
    assert!(!dir.path().join("out/rock_LOD4.glb").exists(), "--lods 4 writes LoD0..3");
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["chain"]["table"].as_array().unwrap().len(), 4);
    assert_eq!(r["source"]["triangles"], 1280);
    assert_eq!(r["validation_errors"], 0);
    let height = r["source"]["bounds"]["max"][1].as_f64().unwrap();
    assert!(height > 0.3 && height < 0.8, "half of the rock's 1.1 m: {height}");
    // bad input: exit 2 naming the file; bad options: exit 2 naming the option
    let o = verdant(&["mesh", dir.path().join("missing.obj").to_str().unwrap(), "-o", g]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("missing.obj"));
    let o = verdant(&["mesh", i, "-o", dir.path().join("x.obj").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains(".glb"));
    let o = verdant(&["mesh", i, "-o", g, "--scale", "0"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--scale"));
}

#[test]
fn jpeg_textures_load_and_stay_opaque() {
    let dir = tempfile::tempdir().unwrap();
    let obj = "mtllib bark.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl bark\nf 1/1 2/2 3/3 4/4\n";
    std::fs::write(dir.path().join("wall.obj"), obj).unwrap();
    std::fs::write(dir.path().join("bark.mtl"), "newmtl bark\nKd 0.8 0.8 0.8\nmap_Kd bark.jpg\n").unwrap();
    let img = image::RgbImage::from_fn(32, 32, |x, y| image::Rgb([(x * 8) as u8, (y * 8) as u8, 90]));
    img.save(dir.path().join("bark.jpg")).unwrap();
    let source = load_obj(&dir.path().join("wall.obj"), &ObjOptions::default()).unwrap();
    assert_eq!(source.scene.textures.len(), 1);
    assert!(source.scene.textures[0].png.starts_with(b"\x89PNG"), "stored as PNG");
    let m = &source.scene.materials[0];
    assert_eq!((m.alpha_mode, m.double_sided, m.base_color_texture), (AlphaMode::Opaque, false, Some(0)));
    assert_eq!(source.mesh().primitives[0].uvs.len(), 4);
    // v flipped to glTF's convention: the OBJ's bottom edge (vt v = 0) is the image's bottom (v = 1)
    let p = &source.mesh().primitives[0];
    for (pos, uv) in p.positions.iter().zip(&p.uvs) {
        assert_eq!(uv[1], 1.0 - pos[1]);
    }
}
