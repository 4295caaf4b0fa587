//! L-system trees as preset species (issue 6, item 8): `kind = "tree", lsystem = "…"` with
//! `tree = { … }` / `[tree]`; the plants stage writes every variant's LoD chain and atlases, the
//! scatter stage instances the variants' LoD0 meshes in scene.glb (picked by position), the
//! manifest and report carry the chains; errors in the preset or the .ls file are positioned.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use verdant::scene::preset::{load_preset, parse_preset};
use verdant::scene::PlantLook;

use crate::common::*;

/// A small stochastic tree (random turns `~`: every seed grows a different one), written here.
const BUSH_LS: &str = "# test bush\nrecursion 4\nangle 25\nthickness 15\naxiom c(12)FFFA\n\
                       rule A = !\"[~(20)&FL A]>(120)[~(20)&FL A]>(120)[~(20)&FL A]\n\
                       rule L = [c(8){.-z.+z.+z.-|-z.+z.+z.}]\n";
/// The same without random turns: the seed changes nothing.
const FIXED_LS: &str = "recursion 3\nangle 25\nthickness 15\naxiom FFA\nrule A = !\"[&FA]>(120)[&FA]>(120)[&FA]\n";

/// fbm 129² with 2 m cells (256 m across), 64 m scatter tiles, one tree species.
fn preset(name: &str, tree_table: &str, lsystem: &str) -> String {
    format!(
        "[scene]\nname = \"{name}\"\nseed = 5\nformats = [\"glb\"]\n\n[terrain]\n\
         procedural = {{ kind = \"fbm\", size = 129, seed = 3, relief = 30.0 }}\n\
         cell_size = 2.0\nmax_error = 0.5\nchunk = 64\n\n[scatter]\ntile = 64.0\n\n\
         [[species]]\nname = \"bush\"\nkind = \"tree\"\nlsystem = \"{lsystem}\"\n{tree_table}\n\
         max_density = 0.004\nmin_spacing = 8.0\nscale = [0.8, 1.2]\n"
    )
}

const QUICK: &str = "tree = { variants = 2, height = 6.0, atlas_size = 256, analysis = false }";

fn csv_rows(path: &Path) -> usize {
    fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).lines().count() - 1
}

#[test]
fn variants_are_built_as_chains_and_instanced_by_position() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/trees/bush.ls", BUSH_LS);
    write(d, "p/a.toml", &preset("a", QUICK, "trees/bush.ls"));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let s = d.join("o/a");

    // every variant's chain: the MSFT_lod glb, five levels, the atlas with its mips
    for k in 0..2 {
        let chain = verdant::validate::read_scene(&s.join(format!("species/bush_v{k}.glb"))).expect("chain re-imports");
        assert!(!chain.meshes.is_empty());
        let mut triangles = Vec::new();
        for level in 0..5 {
            let lod = verdant::validate::read_scene(&s.join(format!("species/bush_v{k}_LOD{level}.glb")))
                .expect("level re-imports");
            triangles.push(lod.meshes.iter().map(|m| m.triangle_count()).sum::<usize>());
        }
        assert!(
            triangles.windows(2).all(|w| w[1] < w[0]),
            "variant {k}: triangles must strictly decrease: {triangles:?}"
        );
        assert!(s.join(format!("atlases/bush_v{k}.png")).is_file(), "variant {k}: atlas");
        assert!(s.join(format!("atlases/bush_v{k}_mip1.png")).is_file(), "variant {k}: atlas mips");
    }
    assert!(!s.join("species/bush_v2.glb").exists(), "only the variants asked for");

    // scene.glb: the two variants' LoD0 meshes (no analysis: no coarser level may stand in), instanced; instances = CSV rows; both used
    let scene = verdant::validate::read_scene(&s.join("scene.glb")).expect("scene.glb re-imports");
    let mesh_index = |name: &str| {
        scene.meshes.iter().position(|m| m.name == name).unwrap_or_else(|| panic!("scene.glb has no mesh {name}"))
    };
    let variants = [mesh_index("bush_v0_LOD0"), mesh_index("bush_v1_LOD0")];
    assert_ne!(
        scene.meshes[variants[0]].primitives[0].positions, scene.meshes[variants[1]].primitives[0].positions,
        "two seeds, two different trees"
    );
    let lod0 = verdant::validate::read_scene(&s.join("species/bush_v1_LOD0.glb")).unwrap();
    assert_eq!(
        lod0.meshes[0].triangle_count(),
        scene.meshes[variants[1]].triangle_count(),
        "the instanced mesh is the chain's LoD0"
    );
    let root = scene.roots.iter().map(|&r| &scene.nodes[r]).find(|n| n.name == "bush").expect("species root node");
    let mut per_variant = BTreeMap::new();
    for &c in &root.children {
        let node = &scene.nodes[c];
        let mesh = node.mesh.expect("instanced node has a mesh");
        assert!(variants.contains(&mesh), "{} shows mesh {mesh}, not a variant", node.name);
        *per_variant.entry(mesh).or_insert(0) += node.instances.as_ref().expect("instanced").translations.len();
    }
    let rows = csv_rows(&s.join("placements/bush.csv"));
    assert!(rows > 60, "only {rows} trees");
    assert_eq!(per_variant.values().sum::<usize>(), rows, "instances = CSV rows");
    assert!(per_variant.values().all(|&n| n > rows / 5), "both variants used: {per_variant:?}");
    // textures and materials of the variants are shared, not copied per variant
    let leaf_textures = scene.textures.iter().filter(|t| t.name.contains("leaf")).count();
    assert!(leaf_textures <= 1, "{leaf_textures} leaf textures");

    // manifest and report
    let manifest = read_json(&s.join("manifest.json"));
    let plants = manifest["plants"].as_array().expect("manifest plants");
    let bush = plants.iter().find(|p| p["name"] == "bush").expect("bush in manifest plants");
    let lods = bush["lods"].as_array().unwrap();
    assert_eq!(lods.len(), 10, "5 levels × 2 variants: {lods:?}");
    for l in lods {
        assert!(s.join(l["file"].as_str().unwrap()).is_file(), "{l}");
        // Unreal/Unity screen size: 1 for LoD0, then the coverage's sphere diameter over the
        // screen height (16:9 reference screen), never growing along the chain
        let (c, size) = (l["screen_coverage"].as_f64().unwrap(), l["screen_size"].as_f64().unwrap());
        if l["level"] == 0 || c >= 1.0 {
            // LoD0, or a chain built without analysis (every switch at 0: the object fills the screen)
            assert_eq!(size, 1.0, "{l}");
        } else {
            let want = 2.0 * (c * (16.0 / 9.0) / std::f64::consts::PI).sqrt();
            assert!((size - want).abs() < 1e-9 && size < 1.0, "{l}");
        }
    }
    for pair in lods.windows(2).filter(|p| p[0]["variant"] == p[1]["variant"]) {
        assert!(pair[1]["screen_size"].as_f64() <= pair[0]["screen_size"].as_f64(), "{pair:?}");
    }
    let report = read_json(&s.join("report.json"));
    let tree = report["stages"]["plants"]["species"].as_array().unwrap().iter().find(|p| p["name"] == "bush").unwrap()
        ["tree"]
        .clone();
    assert_eq!(tree["variants_asked"], 2);
    assert_eq!(tree["variants"].as_array().unwrap().len(), 2);
    assert!(tree["variants"][0]["stats"]["segments"].as_u64().unwrap() > 20);
    assert!(tree["variants"][0]["chain"].get("seconds_bake").is_none(), "timing stays out of report.json's results");
    let md = fs::read_to_string(s.join("report.md")).unwrap();
    assert!(md.contains("### bush (L-system tree: bush.ls, dialect v5)"), "{md}");
}

#[test]
fn a_system_that_ignores_the_seed_builds_one_variant() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/fixed.ls", FIXED_LS);
    write(d, "p/a.toml", &preset("a", "tree = { variants = 3, atlas_size = 256, analysis = false }", "fixed.ls"));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let s = d.join("o/a");
    assert!(s.join("species/bush_v0.glb").is_file());
    assert!(!s.join("species/bush_v1.glb").exists(), "identical copies are not written");
    let report = read_json(&s.join("report.json"));
    let tree = &report["stages"]["plants"]["species"][0]["tree"];
    assert_eq!(tree["variants_asked"], 3);
    assert_eq!(tree["variants"].as_array().unwrap().len(), 1);
    let scene = verdant::validate::read_scene(&s.join("scene.glb")).unwrap();
    assert_eq!(scene.meshes.iter().filter(|m| m.name.starts_with("bush_v")).count(), 1);
    // the table still names the three variants asked (the hash over 3), and the chain shows the
    // one tree for each
    let rows = verdant::export::table::read_placements_csv(&s.join("placements/bush.csv")).unwrap();
    assert!(rows.len() > 30, "{} rows", rows.len());
    let mut seen = [0usize; 3];
    for r in &rows {
        assert_eq!(r.variant, verdant::scatter::variant_of(r.position, 3));
        seen[r.variant as usize] += 1;
    }
    assert!(seen.iter().all(|&n| n > 0), "every variant named: {seen:?}");
    let manifest = read_json(&s.join("manifest.json"));
    let chain = &manifest["view"]["chains"]["bush"];
    assert_eq!(chain["pick"], serde_json::json!([0, 0, 0]));
    assert_eq!(chain["variants"].as_array().unwrap().len(), 1);
    let instanced = scene.nodes.iter().filter(|n| n.instances.is_some()).count();
    assert!(instanced >= 1);
    for n in scene.nodes.iter().filter(|n| n.instances.is_some() && n.name.starts_with("bush")) {
        assert_eq!(n.extras.as_ref().unwrap()["variant"], 0, "{}", n.name);
    }
}

#[test]
fn builds_are_byte_identical_and_the_lsystem_bytes_key_the_cache() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/bush.ls", BUSH_LS);
    write(d, "p/a.toml", &preset("a", QUICK, "bush.ls"));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o1", "--threads", "1"]));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o2", "--threads", "2"]));
    let outputs = |root: &str| -> BTreeMap<String, Vec<u8>> {
        tree(&d.join(root).join("a"))
            .into_iter()
            .filter(|(k, _)| k.starts_with("species/") || k.starts_with("atlases/") || k == "scene.glb")
            .collect()
    };
    let (a, b) = (outputs("o1"), outputs("o2"));
    assert!(a.len() > 12, "{:?}", a.keys().collect::<Vec<_>>());
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (k, v) in &a {
        assert!(b[k] == *v, "{k} differs between --threads 1 and 2");
    }
    // unchanged: cached; the .ls file edited: the plants and the scatter stage run again
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o1"]));
    assert!(timing_cached(&d.join("o1/a"), "plants") && timing_cached(&d.join("o1/a"), "scatter"));
    write(d, "p/bush.ls", &BUSH_LS.replace("angle 25", "angle 30"));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o1"]));
    assert!(!timing_cached(&d.join("o1/a"), "plants") && !timing_cached(&d.join("o1/a"), "scatter"));
    assert_ne!(
        fs::read(d.join("o1/a/species/bush_v0_LOD0.glb")).unwrap(),
        a["species/bush_v0_LOD0.glb"],
        "the new angle is built"
    );
}

// ----------------------------------------------------------------------------------- preset errors

const HEAD: &str = "[scene]\nname = \"x\"\n[terrain]\nprocedural = { kind = \"fbm\", size = 65, relief = 10.0 }\n";

fn error_of(text: &str) -> String {
    match parse_preset(text, Path::new("p.toml")) {
        Ok(p) => panic!("expected an error, parsed {p:?}"),
        Err(e) => e.to_string(),
    }
}

fn species(body: &str) -> String {
    format!("{HEAD}[[species]]\nname = \"t\"\nmax_density = 0.01\n{body}\n")
}

#[test]
fn tree_tables_are_read_with_defaults_and_overrides() {
    let text = format!("{HEAD}[tree]\nvariants = 4\nheight = 15.0\n[[species]]\nname = \"a\"\nkind = \"tree\"\nmax_density = 0.01\nlsystem = \"a.ls\"\n\
                        [[species]]\nname = \"b\"\nkind = \"tree\"\nmax_density = 0.01\nlsystem = \"b.ls\"\ntree = {{ variants = 2, height = \"file\", radial_segments = 5, lods = 3, atlas_size = 512, dialect = \"v4\" }}\n\
                        [[species]]\nname = \"c\"\nkind = \"tree\"\nmax_density = 0.01\n");
    let p = parse_preset(&text, Path::new("dir/p.toml")).unwrap_or_else(|e| panic!("{e}"));
    let PlantLook::Tree(a) = &p.species[0].look else { panic!("a: {:?}", p.species[0].look) };
    assert_eq!((a.variants, a.height_m, a.lods), (4, Some(15.0), 5), "[tree] defaults");
    assert_eq!(a.lsystem, Path::new("dir/a.ls"), "resolved against the preset's folder");
    let PlantLook::Tree(b) = &p.species[1].look else { panic!() };
    assert_eq!((b.variants, b.height_m, b.radial_segments, b.lods, b.atlas_px), (2, None, 5, 3, 512));
    assert_eq!(b.dialect, Some(verdant::lsystem::Dialect::LparserV4));
    assert_ne!(a.seed, b.seed, "each species its own seed");
    // no `lsystem`: a built-in tree picked by the name ("c" hints at nothing: a broadleaf), grown
    // to [tree]'s height since [tree] sets one
    let PlantLook::Tree(c) = &p.species[2].look else { panic!("c: {:?}", p.species[2].look) };
    assert_eq!((c.lsystem.as_path(), c.height_m), (Path::new("builtin:broadleaf"), Some(15.0)));
}

#[test]
fn a_tree_without_a_file_grows_from_the_built_in_library() {
    // the name picks the species, at its own height unless the preset sets one
    let text = format!("{HEAD}[[species]]\nname = \"scots-pine\"\nkind = \"tree\"\nmax_density = 0.01\n\
                        [[species]]\nname = \"b\"\nkind = \"tree\"\nmax_density = 0.01\nlsystem = \"builtin:birch\"\ntree = {{ height = 9.0, variants = 2 }}\n\
                        [[species]]\nname = \"hedge\"\nkind = \"tree\"\nmax_density = 0.01\ntree = {{ variants = 1 }}\n");
    let p = parse_preset(&text, Path::new("dir/p.toml")).unwrap_or_else(|e| panic!("{e}"));
    let looks: Vec<(PathBuf, Option<f64>, usize)> = p
        .species
        .iter()
        .map(|s| match &s.look {
            PlantLook::Tree(t) => (t.lsystem.clone(), t.height_m, t.variants),
            other => panic!("{}: {other:?}", s.rules.name),
        })
        .collect();
    assert_eq!(
        looks,
        vec![
            (PathBuf::from("builtin:conifer"), Some(18.0), 3),
            (PathBuf::from("builtin:birch"), Some(9.0), 2),
            (PathBuf::from("builtin:bush"), Some(2.5), 1),
        ]
    );
    // an unknown built-in name is a positioned error listing the library
    let e = error_of(&species("kind = \"tree\"\nlsystem = \"builtin:palm\""));
    assert!(
        e.contains("p.toml:") && e.contains("builtin:palm") && e.contains("conifer, broadleaf, birch, bush"),
        "{e}"
    );
}

#[test]
fn tree_preset_mistakes_are_positioned_errors_with_a_remedy() {
    let cases: &[(&str, &str, &str)] = &[
        ("kind = \"grass\"\nlsystem = \"a.ls\"", "p.toml:9:1", "set `kind = \"tree\"`"),
        (
            "kind = \"tree\"\nlsystem = \"a.ls\"\ntree = { atlas_size = 1000 }",
            "not a multiple of 16",
            "atlas_size = 1024",
        ),
        ("kind = \"tree\"\nlsystem = \"a.ls\"\ntree = { dialect = \"v6\" }", "dialect", "allowed: auto, ls, v4, v5"),
        ("kind = \"tree\"\nlsystem = \"a.ls\"\ntree = { varients = 2 }", "varients", "variants"),
        ("kind = \"tree\"\nlsystem = \"a.ls\"\ntree = { variants = 0 }", "variants", "1"),
        ("kind = \"tree\"\nlsystem = \"a.ls\"\ntree = { height = -3.0 }", "height", "500"),
        ("kind = \"tree\"\nlsystem = \"\"", "`lsystem` is empty", "relative to this preset"),
    ];
    for (body, problem, remedy) in cases {
        let e = error_of(&species(body));
        assert!(e.contains("p.toml:"), "{body}: no position in\n{e}");
        assert!(e.contains(problem), "{body}: expected {problem:?} in\n{e}");
        assert!(e.contains(remedy), "{body}: expected remedy {remedy:?} in\n{e}");
    }
}

#[test]
fn a_broken_lsystem_file_is_reported_with_both_positions() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "bad.ls", "recursion 2\nangle 20\nthickness 10\naxiom F+(2x)A\nrule A = F\n");
    let p = write(d, "p.toml", &species("kind = \"tree\"\nlsystem = \"bad.ls\""));
    let e = load_preset(&p).expect_err("the bad argument is found while loading").to_string();
    assert!(e.contains("p.toml:9:11"), "the preset's `lsystem` value:\n{e}");
    assert!(e.contains("bad.ls:4:"), "the position in the .ls file:\n{e}");
    let missing = write(d, "q.toml", &species("kind = \"tree\"\nlsystem = \"nowhere.ls\""));
    let e = load_preset(&missing).expect_err("missing file").to_string();
    assert!(e.contains("nowhere.ls") && e.contains("q.toml:9:"), "{e}");
}

#[test]
fn a_repaired_lsystem_is_a_positioned_warning_in_check_build_and_report() {
    // lparser 4 text with a stray `)` (lparser ignores it; so does the reader, with a warning):
    // `preset check` and `build` print it with the file, line and column, report.md and
    // report.json list it, and a build served from the cache still says it
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/trees/stray.ls", "4\n25\n10\nA\nA=F[&FA]^^f)[+FA]\n@\n");
    let tree = "tree = { variants = 1, height = 6.0, atlas_size = 256, analysis = false, lods = 2 }";
    write(d, "p/a.toml", &preset("a", tree, "trees/stray.ls"));
    let expect = |out: &std::process::Output, what: &str| {
        let err = String::from_utf8_lossy(&out.stderr);
        let line = err.lines().find(|l| l.starts_with("warning:") && l.contains("stray.ls")).unwrap_or_else(|| {
            panic!("{what}: no warning naming stray.ls in\n{}", text(out));
        });
        assert!(line.contains("line 5, column 12") && line.contains("species `bush`"), "{what}: {line}");
    };
    let check = verdant_in(d, &["preset", "check", "p/a.toml"]);
    ok(&check);
    expect(&check, "preset check");
    for pass in ["fresh", "cached"] {
        let build = verdant_in(d, &["build", "p/a.toml", "--out", "o", "--only", "plants"]);
        ok(&build);
        expect(&build, pass);
        let md = fs::read_to_string(d.join("o/a/report.md")).unwrap();
        assert!(md.contains("## Warnings") && md.contains("stray.ls: line 5, column 12"), "{pass}:\n{md}");
        let json = read_json(&d.join("o/a/report.json"));
        let listed = json["warnings"].as_array().expect("report.json lists the warnings");
        assert_eq!(listed.len(), 1, "{pass}: {listed:?}");
    }
    // a file without repairs warns nothing
    write(d, "p/trees/bush.ls", BUSH_LS);
    write(d, "p/b.toml", &preset("b", tree, "trees/bush.ls"));
    let check = verdant_in(d, &["preset", "check", "p/b.toml"]);
    ok(&check);
    assert!(!String::from_utf8_lossy(&check.stderr).contains("warning"), "{}", text(&check));
}

// ------------------------------------------------------------------------------------ mesh species

/// A lumpy rock as OBJ text: a UV sphere of `rings` × `sectors` quads, displaced by sines, with
/// a material library `rock.mtl`.
fn rock_obj(rings: usize, sectors: usize) -> String {
    let mut s = String::from("mtllib rock.mtl\no rock\n");
    for r in 0..=rings {
        let theta = std::f64::consts::PI * r as f64 / rings as f64;
        for k in 0..sectors {
            let phi = 2.0 * std::f64::consts::PI * k as f64 / sectors as f64;
            let bump = 1.0 + 0.15 * (3.0 * phi).sin() * (2.0 * theta).sin();
            s += &format!(
                "v {:.5} {:.5} {:.5}\n",
                bump * theta.sin() * phi.cos(),
                0.7 * bump * theta.cos(),
                bump * theta.sin() * phi.sin()
            );
        }
    }
    s += "usemtl stone\n";
    let at = |r: usize, k: usize| r * sectors + (k % sectors) + 1;
    for r in 0..rings {
        for k in 0..sectors {
            s += &format!("f {} {} {} {}\n", at(r, k), at(r, k + 1), at(r + 1, k + 1), at(r + 1, k));
        }
    }
    s
}

fn mesh_preset(name: &str, mesh_table: &str) -> String {
    format!(
        "[scene]\nname = \"{name}\"\nseed = 5\nformats = [\"glb\"]\n\n[terrain]\n\
         procedural = {{ kind = \"fbm\", size = 129, seed = 3, relief = 30.0 }}\n\
         cell_size = 2.0\nmax_error = 0.5\nchunk = 64\n\n[scatter]\ntile = 64.0\n\n\
         [[species]]\nname = \"rock\"\nkind = \"mesh\"\nobj = \"models/rock.obj\"\n{mesh_table}\n\
         max_density = 0.003\nplacement = \"poisson\"\nmin_spacing = 8.0\nscale = [0.5, 2.0]\n"
    )
}

#[test]
fn an_obj_model_gets_the_chain_and_is_instanced() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/models/rock.obj", &rock_obj(16, 24));
    write(d, "p/models/rock.mtl", "newmtl stone\nKd 0.4 0.38 0.35\n");
    write(d, "p/a.toml", &mesh_preset("a", "mesh = { atlas_size = 256, analysis = false }"));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let s = d.join("o/a");
    let mut triangles = Vec::new();
    for level in 0..5 {
        let lod =
            verdant::validate::read_scene(&s.join(format!("species/rock_LOD{level}.glb"))).expect("level re-imports");
        triangles.push(lod.meshes.iter().map(|m| m.triangle_count()).sum::<usize>());
    }
    assert_eq!(
        triangles[0],
        16 * 24 * 2 - 2 * 24,
        "LoD0 is the model (poles' degenerate halves dropped): {triangles:?}"
    );
    assert!(triangles.windows(2).all(|w| w[1] < w[0]), "{triangles:?}");
    assert!(s.join("species/rock.glb").is_file() && s.join("atlases/rock.png").is_file());

    let scene = verdant::validate::read_scene(&s.join("scene.glb")).unwrap();
    let root = scene.roots.iter().map(|&r| &scene.nodes[r]).find(|n| n.name == "rock").expect("species root node");
    let instanced: usize =
        root.children.iter().map(|&c| scene.nodes[c].instances.as_ref().unwrap().translations.len()).sum();
    assert_eq!(instanced, csv_rows(&s.join("placements/rock.csv")));
    let mesh = scene.nodes[root.children[0]].mesh.unwrap();
    assert_eq!(scene.meshes[mesh].triangle_count(), triangles[0], "scene.glb instances the model itself");
    // the model stands on y = 0 (recentred), so instances sit on the ground
    let min_y = scene.meshes[mesh]
        .primitives
        .iter()
        .flat_map(|p| p.positions.iter().map(|v| v[1]))
        .fold(f32::INFINITY, f32::min);
    assert!(min_y.abs() < 1e-5, "model base at y = {min_y}");
    let manifest = read_json(&s.join("manifest.json"));
    let rock = manifest["plants"].as_array().unwrap().iter().find(|p| p["name"] == "rock").unwrap().clone();
    assert_eq!(rock["look"], "mesh");
    assert_eq!(rock["lods"].as_array().unwrap().len(), 5);
    assert!(fs::read_to_string(s.join("report.md")).unwrap().contains("### rock (mesh: rock.obj)"));

    // the material library keys the cache too: a new colour rebuilds the plants and the scene
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    assert!(timing_cached(&s, "plants") && timing_cached(&s, "scatter"));
    write(d, "p/models/rock.mtl", "newmtl stone\nKd 0.6 0.3 0.2\n");
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    assert!(!timing_cached(&s, "plants") && !timing_cached(&s, "scatter"));
}

#[test]
fn mesh_preset_mistakes_are_positioned_errors() {
    let cases: &[(&str, &str, &str)] = &[
        ("kind = \"tree\"\nobj = \"a.obj\"", "describes kind = \"mesh\"", "set `kind = \"mesh\"`"),
        ("kind = \"mesh\"\nmesh = { scale = 0.01 }", "names no `obj` file", "add `obj ="),
        ("kind = \"mesh\"\nobj = \"a.obj\"\nmesh = { up_axis = \"x\" }", "up_axis", "allowed: y, z"),
        ("kind = \"mesh\"\nobj = \"a.obj\"\nmesh = { scale = 0.0 }", "scale", "centimetres"),
        ("kind = \"mesh\"\nobj = \"a.obj\"\nmesh = { variants = 2 }", "variants", "[tree]"),
    ];
    for (body, problem, remedy) in cases {
        let e = error_of(&species(body));
        assert!(e.contains("p.toml:"), "{body}: no position in\n{e}");
        assert!(e.contains(problem), "{body}: expected {problem:?} in\n{e}");
        assert!(e.contains(remedy), "{body}: expected remedy {remedy:?} in\n{e}");
    }
    // a broken model fails the build naming the file and line
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/models/rock.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
    write(d, "p/a.toml", &mesh_preset("a", ""));
    let o = verdant_in(d, &["build", "p/a.toml", "--out", "o"]);
    assert_ne!(o.status.code(), Some(0));
    let t = text(&o);
    assert!(t.contains("rock.obj") && t.contains("species `rock`"), "{t}");
}
