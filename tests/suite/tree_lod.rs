//! Tree LoD chains: triangles strictly decrease LoD0 → LoD4, every level and the MSFT_lod chain is
//! a valid glb for real L-system files, no NaN, byte-identical outputs at 1 and 2 threads, switch
//! distances that never decrease (and coverages to match), atlas mips that keep coverage, and the
//! `verdant tree --lods` command's files and errors; point leaves (glTF POINTS with `_LEAF_SIZE`).

use std::path::{Path, PathBuf};
use std::process::Command;

use verdant::bake::atlas::coverage;
use verdant::lsystem::parse::parse_bytes;
use verdant::mesh::PrimitiveMode;
use verdant::plants::tree::{build_tree, TreeOptions, LEAF_SIZE_ATTRIBUTE};
use verdant::plants::tree_lod::{
    build_tree_lods, run_lods, TreeLodJob, TreeLodOptions, TreeLods, ATLAS_ALPHA_CUTOFF, IMPOSTOR_EXTRAS_KEY, TREE_LODS,
};
use verdant::validate::{read_scene, validate_file};

use crate::common::lod::{bytes_of, in_pool, small_atlas};

/// The stochastic bush of the thesis' format (as ../shared/data/lsystems/stochastic/bush.ls).
const BUSH: &str = "3-2-2\n28\n18\nX(100)=FFA\nA(40)=F[&B]>(137)A\nA(75)=F[^B]>(120)A\nA(100)=F[&B]\"[^C]>(137)A\nB(50)=F[-C]CL\nB(100)=F[+C]'C\nC(100)=F[+B]B\n@\n";

fn data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("VERDANT_LSYSTEMS_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/lsystems"));
    dir.is_dir().then_some(dir)
}

fn bush(seed: u64, options: &TreeLodOptions) -> TreeLods {
    let system = parse_bytes(BUSH.as_bytes(), Path::new("bush.ls"), None).unwrap().system;
    build_tree_lods(&system, &TreeOptions { seed, name: "bush".into(), ..TreeOptions::default() }, options).unwrap()
}

#[test]
fn tree_lods_are_byte_identical_at_one_and_two_threads() {
    let opts = small_atlas();
    let one = in_pool(1, || bush(3, &opts));
    let two = in_pool(2, || bush(3, &opts));
    assert_eq!(bytes_of(&one), bytes_of(&two));
    assert_eq!(one.report.lods, two.report.lods, "the analyzer's figures too");
    let other = bush(4, &opts);
    assert_ne!(bytes_of(&one)[0], bytes_of(&other)[0], "another seed, another bush");
}

#[test]
fn the_fast_analyzer_measures_fewer_azimuths_over_its_budget_and_says_so() {
    // the small bush draws a few thousand triangles a view: all 24 views within the default budget
    let all = bush(3, &small_atlas());
    assert_eq!(all.report.analysis_views, 24);
    assert_eq!(all.report.analysis_reduced, None);
    // a budget it is over: 4 azimuths instead of 8 (never fewer), the elevations kept
    let tight = bush(3, &TreeLodOptions { image_budget_triangles: Some(1), ..small_atlas() });
    assert_eq!(tight.report.analysis_views, 4 * 3);
    let why = tight.report.analysis_reduced.as_deref().expect("the report says why");
    assert!(
        why.contains("4 azimuths × 3 elevations instead of 8 × 3") && why.contains("--analysis exhaustive"),
        "{why}"
    );
    // the views measured are the fewer ones (the worst over 12 views is not the worst over 24 at
    // every distance), and still a whole measure: every level after LoD0, switches in order
    let rows = |t: &TreeLods| t.report.lods.iter().map(|l| l.measured.clone()).collect::<Vec<_>>();
    assert_ne!(rows(&tight), rows(&all), "the analyzer measured other views than the report says");
    for w in tight.report.lods.windows(2) {
        assert!(!w[1].measured.is_empty() && w[1].switch_distance_m >= w[0].switch_distance_m);
    }
    // the budget counts LoD0 and every measured level: exactly 24 views of them fit, one less does not
    let per_view: u64 = all.report.lods.iter().map(|l| l.triangles as u64).sum();
    let at = |budget| bush(3, &TreeLodOptions { image_budget_triangles: Some(budget), ..small_atlas() });
    assert_eq!(at(per_view * 24).report.analysis_views, 24);
    assert_eq!(at(per_view * 24 - 1).report.analysis_views, 12);
    let none = bush(3, &TreeLodOptions { image_budget_triangles: None, ..small_atlas() });
    assert_eq!((none.report.analysis_views, none.report.analysis_reduced.as_deref()), (24, None));
    assert_eq!(bytes_of(&none), bytes_of(&all), "within the budget nothing changes");
}

#[test]
fn switch_distances_never_decrease_and_errors_grow_with_the_level() {
    let t = bush(3, &small_atlas());
    let lods = &t.report.lods;
    assert_eq!(lods.len(), TREE_LODS);
    for w in lods.windows(2) {
        assert!(
            w[1].switch_distance_m >= w[0].switch_distance_m,
            "{} then {}",
            w[0].switch_distance_m,
            w[1].switch_distance_m
        );
        assert!(w[1].screen_coverage <= w[0].screen_coverage);
    }
    let radius = t.report.bounding_radius_m;
    for l in &lods[1..] {
        // measured: at least the farthest distance, and the switch is past the bounding sphere
        assert!(!l.measured.is_empty(), "LoD{} not measured", l.level);
        assert!(l.switch_distance_m > radius, "LoD{} switches at {} m inside the tree", l.level, l.switch_distance_m);
        assert!(l.geometric_error.samples > 0 && l.geometric_error.max_m.is_finite());
        assert!(l.near_iou < 1.0, "LoD{} draws exactly LoD0 at {} m", l.level, l.near_distance_m);
    }
    // the simplified mesh stays close to LoD0; the flat billboards do not
    assert!(
        lods[1].geometric_error.max_m < 0.05 * radius,
        "LoD1 moved {} m (radius {radius})",
        lods[1].geometric_error.max_m
    );
    assert!(lods[3].geometric_error.max_m > lods[1].geometric_error.max_m);
    assert_eq!(t.report.table.len(), TREE_LODS);
    // the chain carries the coverages: LoD0's node with MSFT_lod to the four others
    let root = &t.chain.nodes[t.chain.roots[0]];
    assert_eq!(root.lods.len(), TREE_LODS - 1);
    let expected: Vec<f32> = lods[1..].iter().map(|l| l.screen_coverage as f32).chain([0.0]).collect();
    assert_eq!(root.lod_screen_coverage, expected);
}

#[test]
fn atlas_mips_keep_coverage_within_two_percent() {
    // the default atlas size (at 256 px the bush's twigs are under a texel wide by the 64-px mip,
    // and no alpha scale brings that level within 2 %)
    let t = bush(3, &TreeLodOptions { analyze: false, ..TreeLodOptions::default() });
    let c0 = t.atlas[0].coverage;
    assert!(c0 > 0.01, "the atlas shows the tree ({c0})");
    assert_eq!(t.atlas[0].image.width, 1024);
    for (k, m) in t.atlas.iter().enumerate().filter(|(_, m)| m.image.width.min(m.image.height) >= 32) {
        assert!((m.coverage / c0 - 1.0).abs() <= 0.02, "atlas mip {k}: coverage {} vs {c0}", m.coverage);
        assert_eq!(coverage(&m.image, ATLAS_ALPHA_CUTOFF), m.coverage);
    }
    // every impostor view shows something, inside its own cell
    for cell in &t.impostor_cells {
        let img = &t.atlas[0].image;
        let opaque = (cell.y..cell.y + cell.size)
            .flat_map(|y| (cell.x..cell.x + cell.size).map(move |x| (x, y)))
            .filter(|&(x, y)| img.pixel(x, y).unwrap()[3] >= ATLAS_ALPHA_CUTOFF)
            .count();
        assert!(opaque > 20, "impostor cell {cell:?} is empty");
    }
}

#[test]
fn real_files_give_valid_chains_with_strictly_fewer_triangles() {
    let Some(dir) = data_dir() else {
        eprintln!("skipped: ../shared/data/lsystems not found (set VERDANT_LSYSTEMS_DIR)");
        return;
    };
    let out = tempfile::tempdir().unwrap();
    // small and varied: thesis format, lparser 5, lparser 4 polygons only (Koch), a stochastic bush
    for file in ["stochastic/design-example.ls", "stochastic/bush.ls", "lparser-v5/tree1.ls", "lparser-v4/cees-koch.ls"]
    {
        let input = dir.join(file);
        let stem = input.file_stem().unwrap().to_str().unwrap().to_string();
        let job = TreeLodJob {
            input: input.clone(),
            output: out.path().join(format!("{stem}.glb")),
            dialect: None,
            options: TreeOptions { name: stem.clone(), ..TreeOptions::default() },
            lod: TreeLodOptions { analyze: false, ..small_atlas() },
            variants: 1,
        };
        let report = run_lods(&job).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert_eq!(report.tree.validation_errors, 0);
        let mut last = usize::MAX;
        for n in 0..TREE_LODS {
            let path = out.path().join(format!("{stem}_LOD{n}.glb"));
            let v = validate_file(&path, &Default::default()).unwrap();
            assert_eq!(v.errors(), 0, "{file} LoD{n}: {v}");
            let scene = read_scene(&path).unwrap();
            let tris: usize = scene.meshes.iter().map(|m| m.triangle_count()).sum();
            assert!(tris < last, "{file} LoD{n}: {tris} triangles, not fewer than {last}");
            last = tris;
            for p in scene.meshes.iter().flat_map(|m| &m.primitives) {
                let finite = p
                    .positions
                    .iter()
                    .flatten()
                    .chain(p.normals.iter().flatten())
                    .chain(p.uvs.iter().flatten())
                    .all(|x| x.is_finite());
                assert!(finite, "{file} LoD{n}: NaN or infinity");
            }
        }
        let chain = out.path().join(format!("{stem}.glb"));
        assert_eq!(validate_file(&chain, &Default::default()).unwrap().errors(), 0);
        let scene = read_scene(&chain).unwrap();
        assert_eq!(scene.nodes[scene.roots[0]].lods.len(), TREE_LODS - 1, "{file}: MSFT_lod chain");
        assert!(
            out.path().join(format!("{stem}_atlas.png")).is_file()
                && out.path().join(format!("{stem}_atlas_mip1.png")).is_file()
        );
        // the impostor says how to pick its view
        let impostor = read_scene(&out.path().join(format!("{stem}_LOD4.glb"))).unwrap();
        let extras = impostor.meshes[0]
            .extras
            .as_ref()
            .and_then(|e| e.get(IMPOSTOR_EXTRAS_KEY))
            .unwrap_or_else(|| panic!("{file}: no impostor extras"));
        assert_eq!(extras["cells_uv"].as_array().map(Vec::len), Some(8));
    }
}

fn verdant(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_verdant")).args(args).output().expect("run verdant")
}

#[test]
fn cli_tree_and_mesh_say_each_chain_step_as_it_starts_and_quiet_silences_them() {
    // not a terminal here: plain `[name] step` lines on stderr (a spinner on a terminal)
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bush.ls");
    std::fs::write(&input, BUSH).unwrap();
    let glb = dir.path().join("out/bush.glb");
    let (i, g) = (input.to_str().unwrap(), glb.to_str().unwrap());
    let args = ["tree", i, "-o", g, "--atlas-size", "256"];
    let o = verdant(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    let steps: Vec<&str> = err.lines().filter(|l| l.starts_with("[bush] ")).collect();
    let want = [
        "[bush] LoD0: growing the tree",
        "[bush] LoD1: half the radial segments",
        "[bush] cards, billboards and the impostor",
    ];
    for w in want {
        assert!(steps.contains(&w), "missing `{w}` in:\n{err}");
    }
    assert!(steps.iter().any(|l| l.starts_with("[bush] baking the atlas: ")), "{err}");
    // in the order they run: LoD0 first, the measurements last
    assert_eq!(steps.first(), Some(&"[bush] LoD0: growing the tree"), "{err}");
    // every level after LoD0 is measured in one joint search, named in chain order
    assert!(
        steps.last().is_some_and(
            |l| l.starts_with("[bush] measuring LoD1 (simplified), LoD2 (") && l.ends_with(" against LoD0")
        ),
        "{err}"
    );
    let quiet = verdant(&[&["--quiet"], &args[..]].concat());
    assert!(quiet.status.success() && quiet.stderr.is_empty(), "{}", String::from_utf8_lossy(&quiet.stderr));

    // a model's chain the same way
    let obj = dir.path().join("box.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
                          f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n",
    )
    .unwrap();
    let out = dir.path().join("out/box.glb");
    let o = verdant(&["mesh", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--atlas-size", "256"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.lines().any(|l| l == "[box] LoD1: simplified"), "{err}");
    assert!(err.lines().any(|l| l.starts_with("[box] measuring LoD")), "{err}");
}

#[test]
fn cli_tree_writes_variants_lod_files_atlases_and_a_speed_error_table() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bush.ls");
    std::fs::write(&input, BUSH).unwrap();
    let glb = dir.path().join("out/bush.glb");
    let report = dir.path().join("out/bush.json");
    let (i, g, r) = (input.to_str().unwrap(), glb.to_str().unwrap(), report.to_str().unwrap());
    let o = verdant(&[
        "--quiet",
        "tree",
        i,
        "-o",
        g,
        "--variants",
        "2",
        "--lods",
        "4",
        "--atlas-size",
        "256",
        "--no-analysis",
        "--report",
        r,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for k in 0..2 {
        for name in [format!("bush_v{k}.glb"), format!("bush_v{k}_LOD3.glb"), format!("bush_v{k}_atlas.png")] {
            assert!(dir.path().join("out").join(&name).is_file(), "{name} missing");
        }
        assert!(!dir.path().join(format!("out/bush_v{k}_LOD4.glb")).exists(), "--lods 4 writes LoD0..3");
    }
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["variants"].as_array().unwrap().len(), 2);
    let table = r["variants"][0]["table"].as_array().unwrap();
    assert_eq!(table.len(), 4);
    assert!(table
        .iter()
        .all(|row| row["triangles"].as_u64().is_some() && row["bytes"].as_u64().is_some_and(|b| b > 0)));
    assert_ne!(r["variants"][0]["lods"][0]["triangles"], serde_json::Value::Null);
    // bad options: exit 2, naming the option and the remedy, nothing written
    let bad = dir.path().join("bad.glb");
    let o = verdant(&["tree", i, "-o", bad.to_str().unwrap(), "--lods", "9"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--lods 9 is out of range"));
    let o = verdant(&["tree", i, "-o", dir.path().join("t.obj").to_str().unwrap(), "--lods", "3"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--lods 1"));
    let o = verdant(&["tree", i, "-o", bad.to_str().unwrap(), "--atlas-size", "100"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(!bad.exists());
}

/// The POINTS primitives of a glb's JSON chunk: (mode, has indices) of every primitive.
fn primitive_modes(glb: &[u8]) -> Vec<(u64, bool)> {
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let json: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    json["meshes"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|m| m["primitives"].as_array().unwrap().iter())
        .map(|p| (p["mode"].as_u64().unwrap_or(4), p.get("indices").is_some()))
        .collect()
}

#[test]
fn point_leaves_are_one_point_per_quad_leaf_with_normal_colour_and_size() {
    let system = parse_bytes(BUSH.as_bytes(), Path::new("bush.ls"), None).unwrap().system;
    let quads = build_tree(&system, &TreeOptions { seed: 3, ..TreeOptions::default() }).unwrap();
    let points = build_tree(&system, &TreeOptions { seed: 3, leaf_points: true, ..TreeOptions::default() }).unwrap();
    // the quad leaves: two triangles each, in the textured leaf primitives
    let leaf_texture = |m: Option<usize>| {
        m.and_then(|m| quads.scene.materials[m].base_color_texture)
            .is_some_and(|t| quads.scene.textures[t].name == "leaf")
    };
    let quad_leaves: usize =
        quads.mesh().primitives.iter().filter(|p| leaf_texture(p.material)).map(|p| p.triangle_count() / 2).sum();
    assert!(quad_leaves > 10, "the bush has leaves ({quad_leaves})");
    assert_eq!(points.mesh().point_count(), quad_leaves, "one point per quad leaf");
    assert_eq!(
        points.mesh().triangle_count() + 2 * quad_leaves,
        quads.mesh().triangle_count(),
        "only the leaves changed"
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("points.glb");
    verdant::export::write_scene(&points.scene, &path).unwrap();
    let v = validate_file(&path, &Default::default()).unwrap();
    assert_eq!((v.errors(), v.warnings()), (0, 0), "{v}");
    let modes = primitive_modes(&std::fs::read(&path).unwrap());
    assert!(modes.contains(&(0, false)), "a POINTS primitive without indices: {modes:?}");
    let scene = read_scene(&path).unwrap();
    assert_eq!(scene.meshes[0].primitives, points.mesh().primitives, "re-imports as built");
    let leaves: Vec<_> = scene.meshes[0].primitives.iter().filter(|p| p.mode == PrimitiveMode::Points).collect();
    assert!(!leaves.is_empty());
    for p in leaves {
        assert_eq!(p.normals.len(), p.positions.len());
        assert_eq!(p.colors.len(), p.positions.len());
        assert!(p.colors.iter().all(|c| c[1] > c[0] && c[3] == 1.0), "leaf green");
        let size = p.custom.iter().find(|c| c.name == LEAF_SIZE_ATTRIBUTE).expect("_LEAF_SIZE");
        assert_eq!(size.values.len(), p.positions.len());
        assert!(
            size.values.iter().all(|s| s[0] > 0.0 && s[1] > 0.0 && (s[1] - s[0] / 2.0).abs() < 1e-6),
            "length, width = length / 2"
        );
        assert!(p.uvs.is_empty() && p.indices.is_empty());
        // no texture on points (they have no texture coordinates)
        assert_eq!(scene.materials[p.material.unwrap()].base_color_texture, None);
    }
    // each point sits at its quad leaf's centre: the quads' centres, in the same order
    let quad_prim = quads.mesh().primitives.iter().find(|p| leaf_texture(p.material)).unwrap();
    let centres: Vec<[f32; 3]> = quad_prim
        .indices
        .chunks_exact(6)
        .map(|q| {
            let (a, c) = (quad_prim.positions[q[0] as usize], quad_prim.positions[q[2] as usize]);
            [(a[0] + c[0]) / 2.0, (a[1] + c[1]) / 2.0, (a[2] + c[2]) / 2.0]
        })
        .collect();
    let point_prim = points.mesh().primitives.iter().find(|p| p.mode == PrimitiveMode::Points).unwrap();
    let close = centres
        .iter()
        .filter(|c| point_prim.positions.iter().any(|p| (0..3).all(|k| (p[k] - c[k]).abs() < 1e-4)))
        .count();
    assert_eq!(close, centres.len(), "every quad's centre has its point");
}

#[test]
fn point_leaf_chains_keep_points_at_lod0_and_stay_valid() {
    let system = parse_bytes(BUSH.as_bytes(), Path::new("bush.ls"), None).unwrap().system;
    let options = TreeLodOptions { analyze: false, ..small_atlas() };
    let t = build_tree_lods(
        &system,
        &TreeOptions { seed: 3, name: "bush".into(), leaf_points: true, ..TreeOptions::default() },
        &options,
    )
    .unwrap();
    let quads =
        build_tree_lods(&system, &TreeOptions { seed: 3, name: "bush".into(), ..TreeOptions::default() }, &options)
            .unwrap();
    assert!(
        t.levels[0].scene.meshes[0].point_count() > 0 && t.levels[1].scene.meshes[0].point_count() > 0,
        "LoD0 and LoD1 draw points"
    );
    let tris: Vec<usize> = t.levels.iter().map(|l| l.triangles()).collect();
    assert!(tris.windows(2).all(|w| w[1] < w[0]), "{tris:?}");
    // the atlas is baked from the quad-leaf tree
    assert_eq!(t.atlas[0].image, quads.atlas[0].image);
    // and the command writes it (OBJ refused with a remedy)
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bush.ls");
    std::fs::write(&input, BUSH).unwrap();
    let glb = dir.path().join("bush.glb");
    let o = verdant(&[
        "--quiet",
        "tree",
        input.to_str().unwrap(),
        "-o",
        glb.to_str().unwrap(),
        "--point-leaves",
        "--atlas-size",
        "256",
        "--no-analysis",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(primitive_modes(&std::fs::read(dir.path().join("bush_LOD0.glb")).unwrap()).iter().any(|m| m.0 == 0));
    let o = verdant(&[
        "tree",
        input.to_str().unwrap(),
        "-o",
        dir.path().join("bush.obj").to_str().unwrap(),
        "--point-leaves",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("point leaves"));
}

#[test]
fn a_tree_too_small_for_a_level_still_yields_a_valid_chain() {
    // one trunk segment of 4 sides, no leaves (written here by hand): its cards level has as many
    // triangles as the billboards would (8), so the billboards save nothing and are left out (this
    // used to be an error asking for --lods 3)
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("stick.ls");
    std::fs::write(&input, "1\n28\n18\nX(100)=F\n@\n").unwrap();
    let job = TreeLodJob {
        input: input.clone(),
        output: dir.path().join("out/stick.glb"),
        dialect: None,
        options: TreeOptions { name: "stick".into(), radial_segments: 4, ..TreeOptions::default() },
        lod: small_atlas(),
        variants: 1,
    };
    let report = run_lods(&job).unwrap_or_else(|e| panic!("{e}"));
    let chain = &report.variants[0];
    assert_eq!(chain.left_out.len(), 1, "{:?}", chain.left_out);
    assert_eq!(chain.left_out[0].kind, "billboards");
    assert!(chain.left_out[0].triangles >= chain.left_out[0].previous_triangles);
    let levels = chain.lods.len();
    assert_eq!(levels, TREE_LODS - 1);
    // contiguous, strictly decreasing, every file and the chain valid
    let mut last = usize::MAX;
    for (n, l) in chain.lods.iter().enumerate() {
        assert_eq!(l.level, n);
        assert!(l.triangles < last, "LoD{n}: {} triangles, not fewer than {last}", l.triangles);
        last = l.triangles;
        let file = dir.path().join(format!("out/stick_LOD{n}.glb"));
        assert!(validate_file(&file, &Default::default()).unwrap().ok(), "{}", file.display());
        let scene = read_scene(&file).unwrap();
        assert_eq!(scene.nodes[scene.roots[0]].name, format!("stick_LOD{n}"));
    }
    assert_eq!(chain.lods.last().unwrap().kind, "impostor");
    assert!(!dir.path().join(format!("out/stick_LOD{levels}.glb")).exists(), "no file past the last level");
    let scene = read_scene(&dir.path().join("out/stick.glb")).unwrap();
    assert_eq!(scene.nodes[scene.roots[0]].lods.len(), levels - 1, "MSFT_lod names every coarser level");
    let names: Vec<&str> = scene.nodes[scene.roots[0]].lods.iter().map(|&i| scene.nodes[i].name.as_str()).collect();
    assert_eq!(names, (1..levels).map(|n| format!("stick_LOD{n}")).collect::<Vec<_>>());
}
