//! Sharded builds (issue 18): `verdant build --shard i/N` in N processes at once, `verdant merge`
//! in any shard order, against one `verdant build` of the same preset, byte for byte; and the
//! merge's refusals (a shard missing, given twice, of another split, built from other inputs).

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::common::*;

/// A unit cube resting on the ground (a rock for a mesh species).
const ROCK_OBJ: &str = "v -0.5 0 -0.5\nv 0.5 0 -0.5\nv 0.5 0 0.5\nv -0.5 0 0.5\n\
                        v -0.5 1 -0.5\nv 0.5 1 -0.5\nv 0.5 1 0.5\nv -0.5 1 0.5\n\
                        f 1 2 3 4\nf 8 7 6 5\nf 1 5 6 2\nf 2 6 7 3\nf 3 7 8 4\nf 4 8 5 1\n";

/// fbm 129², LoDs, a view, and three units besides the terrain: grass, rocks (an OBJ) and flowers.
fn preset(grass_density: f64) -> String {
    format!(
        "[scene]\nname = \"world\"\nseed = 5\nformats = [\"glb\"]\n\n[terrain]\n\
         procedural = {{ kind = \"fbm\", size = 129, seed = 3, relief = 40.0 }}\n\
         cell_size = 2.0\nmax_error = 0.5\nchunk = 64\nskirt = 2.0\nlods = [0.5, 2.0]\n\n\
         [scatter]\ntile = 64.0\n\n\
         [[species]]\nname = \"rock\"\nkind = \"mesh\"\nplacement = \"poisson\"\nmax_density = 0.01\nmin_spacing = 4.0\n\
         obj = \"rock.obj\"\n\n\
         [[species]]\nname = \"grass\"\nkind = \"grass\"\nplacement = \"jittered\"\nmax_density = {grass_density}\n\
         exclusion = {{ species = \"rock\", radius = 1.0 }}\n\n\
         [[species]]\nname = \"flower\"\nkind = \"flower\"\nplacement = \"jittered\"\nmax_density = 0.05\n"
    )
}

fn setup() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "rock.obj", ROCK_OBJ);
    write(dir.path(), "world.toml", &preset(0.4));
    dir
}

/// Runs `verdant` once per argument list, all at once (in `cwd`); each must succeed.
fn run_at_once(cwd: &Path, runs: &[Vec<String>]) {
    let children: Vec<_> = runs
        .iter()
        .map(|args| {
            Command::new(env!("CARGO_BIN_EXE_verdant"))
                .current_dir(cwd)
                .args(args)
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .expect("run verdant")
        })
        .collect();
    for c in children {
        ok(&c.wait_with_output().unwrap());
    }
}

/// Runs the N shards of `world.toml` as N processes at once, into `<base>/<i>`.
fn run_shards(cwd: &Path, base: &str, n: usize) -> Vec<PathBuf> {
    let args = |i: usize| -> Vec<String> {
        let shard = format!("{i}/{n}");
        ["-q", "build", "world.toml", "--shard", &shard, "--out", &format!("{base}/{i}")].map(String::from).to_vec()
    };
    run_at_once(cwd, &(0..n).map(args).collect::<Vec<_>>());
    (0..n).map(|i| PathBuf::from(format!("{base}/{i}"))).collect()
}

/// Runs `world.toml`'s N shards into the folders `dirs` (N = their count) one after another; their
/// output, for messages.
fn run_shards_into(cwd: &Path, dirs: &[PathBuf]) -> String {
    let n = dirs.len();
    let mut said = String::new();
    for (i, d) in dirs.iter().enumerate() {
        let o = verdant_in(
            cwd,
            &["-q", "build", "world.toml", "--shard", &format!("{i}/{n}"), "--out", &d.display().to_string()],
        );
        ok(&o);
        said.push_str(&text(&o));
    }
    said
}

/// Runs the second round (`--tiles`) of the N shards `shards` of `world.toml` as N processes at once.
fn run_tile_round(cwd: &Path, shards: &[PathBuf]) {
    let n = shards.len();
    let args = |i: usize| -> Vec<String> {
        let mut args: Vec<String> = ["-q", "build", "world.toml", "--shard"].map(String::from).to_vec();
        args.push(format!("{i}/{n}"));
        args.extend(["--tiles".into(), "--out".into(), shards[i].display().to_string(), "--shards".into()]);
        args.extend(shards.iter().map(|p| p.display().to_string()));
        args
    };
    run_at_once(cwd, &(0..n).map(args).collect::<Vec<_>>());
}

fn merge(cwd: &Path, shards: &[PathBuf], out: &str) -> std::process::Output {
    let mut args: Vec<String> = vec!["-q".into(), "merge".into(), "world.toml".into(), "--shards".into()];
    args.extend(shards.iter().map(|p| p.display().to_string()));
    args.extend(["--out".into(), out.into()]);
    verdant_in(cwd, &args.iter().map(String::as_str).collect::<Vec<_>>())
}

#[test]
fn a_merged_sharded_build_is_byte_identical_to_one_build_for_any_n_and_shard_order() {
    let dir = setup();
    let cwd = dir.path();
    ok(&verdant_in(cwd, &["-q", "build", "world.toml", "--out", "single"]));
    // 4 units (terrain, rock, grass, flower): one shard of everything, two, and five (one idle)
    for n in [1usize, 2, 5] {
        let mut shards = run_shards(cwd, &format!("shards{n}"), n);
        for s in &shards {
            let record = read_json(&cwd.join(s).join("world.shard.json"));
            assert_eq!(record["of"], n);
            assert!(!cwd.join(s).join("world").exists(), "a shard writes no scene folder");
        }
        // the order the merge is given them in does not matter
        shards.reverse();
        let out = format!("merged{n}");
        ok(&merge(cwd, &shards, &out));
        assert_same_tree(&cwd.join("single/world"), &cwd.join(&out).join("world"));
        // the terrain the shards built was served, not built again in the merge (the plants stage
        // runs, each species restored from its shard's entry: the same bytes, tested above)
        assert!(timing_cached(&cwd.join(&out).join("world"), "terrain"), "{n} shards: the merge meshed again");
    }
}

#[test]
fn a_preset_whose_first_format_is_obj_merges_to_the_same_bytes() {
    // later stages read the terrain back from its first file: OBJ here, glTF + .bin second
    let dir = setup();
    let cwd = dir.path();
    write(cwd, "world.toml", &preset(0.4).replace("formats = [\"glb\"]", "formats = [\"obj\", \"gltf\"]"));
    ok(&verdant_in(cwd, &["-q", "build", "world.toml", "--out", "single"]));
    let shards = run_shards(cwd, "shards", 2);
    ok(&merge(cwd, &shards, "merged"));
    assert!(cwd.join("merged/world/terrain/terrain.obj").is_file());
    assert_same_tree(&cwd.join("single/world"), &cwd.join("merged/world"));
}

#[test]
fn a_merge_refuses_missing_duplicate_foreign_and_stale_shards() {
    let dir = setup();
    let cwd = dir.path();
    let two = run_shards(cwd, "two", 2);
    let three = run_shards(cwd, "three", 3);
    let refused = |shards: &[PathBuf], words: &[&str]| {
        let o = merge(cwd, shards, "merged");
        assert_eq!(o.status.code(), Some(2), "{}", text(&o));
        for w in words {
            assert!(text(&o).contains(w), "no `{w}` in:\n{}", text(&o));
        }
        assert!(!cwd.join("merged/world").exists(), "a refused merge builds nothing");
    };
    refused(&two[..1], &["shard 1/2 is missing", "--shard 1/2"]);
    // the second round refuses the same way, and wants the shard's own folder of the first
    let second = |out: &str, shards: &[PathBuf]| {
        let mut args = vec!["-q", "build", "world.toml", "--shard", "0/2", "--tiles", "--out", out, "--shards"];
        let given: Vec<String> = shards.iter().map(|p| p.display().to_string()).collect();
        args.extend(given.iter().map(String::as_str));
        let o = verdant_in(cwd, &args);
        assert_eq!(o.status.code(), Some(2), "{}", text(&o));
        text(&o)
    };
    assert!(second("two/0", &two[..1]).contains("shard 1/2 is missing"));
    assert!(second("two/1", &two).contains("give the second round (--tiles) the --out of the shard's first round"));
    assert!(second("elsewhere", &two).contains("not the folder of shard 0/2"));
    refused(&[two[0].clone(), two[0].clone(), two[1].clone()], &["given twice"]);
    refused(&[two[0].clone(), three[1].clone()], &["another split", "same N"]);
    refused(&[PathBuf::from("nowhere")], &["nowhere", "not a shard folder"]);
    // a shard of another binary (its bytes need not be this one's)
    let record = cwd.join("two/1/world.shard.json");
    let original = fs::read_to_string(&record).unwrap();
    let mut other: serde_json::Value = serde_json::from_str(&original).unwrap();
    other["built_by"] = "verdant 0.0.1 riscv64-linux".into();
    fs::write(&record, serde_json::to_string(&other).unwrap()).unwrap();
    refused(&two, &["built by verdant 0.0.1 riscv64-linux", "one binary"]);
    // a record without the digests of its entries (an older binary's)
    let mut bare: serde_json::Value = serde_json::from_str(&original).unwrap();
    bare.as_object_mut().unwrap().remove("digests");
    fs::write(&record, serde_json::to_string(&bare).unwrap()).unwrap();
    refused(&two, &["has no digest of", "build the shard again"]);
    fs::write(&record, original).unwrap();
    // a shard folder damaged on its way to the merge: one byte of an entry's file changed, a file
    // lost; the merge names the file, the shard and the unit, and how to mend it
    let digests: serde_json::Value = read_json(&record)["digests"].clone();
    let (entry, files) = digests.as_object().unwrap().iter().next().unwrap();
    assert!(!files.as_object().unwrap().is_empty());
    let (file, want) = files
        .as_object()
        .unwrap()
        .iter()
        .max_by_key(|(f, _)| fs::metadata(cwd.join("two/1/.cache").join(entry).join(f)).map(|m| m.len()).unwrap_or(0))
        .unwrap();
    let path = cwd.join("two/1/.cache").join(entry).join(file);
    let digest = verdant::scene::cache::sha256_hex(&fs::read(&path).unwrap());
    assert_eq!(want.as_str().unwrap(), digest, "the recorded digest is the file's");
    let bytes = fs::read(&path).unwrap();
    let mut flipped = bytes.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x10;
    fs::remove_file(&path).unwrap(); // (a hard link: never written through)
    fs::write(&path, &flipped).unwrap();
    refused(
        &two,
        &[file.as_str(), "differs from what the shard wrote", "--shard 1/2", "copy the shard's folder again"],
    );
    fs::remove_file(&path).unwrap();
    refused(&two, &[file.as_str(), "is missing", "--shard 1/2"]);
    fs::write(&path, &bytes).unwrap();
    ok(&merge(cwd, &two, "merged_ok"));
    // the preset edited after the shards were built: the grass unit no longer matches, nor the
    // terrain (its soil layer reads the species' densities), which shard 0 is named for first
    write(cwd, "world.toml", &preset(0.3));
    refused(&two, &["shard 0/2 did not build terrain from these inputs", "build the shard again"]);
}

#[test]
fn editing_one_species_rebuilds_that_species_alone() {
    // species are cached one by one (what the shards build): a new flower look misses the flower's
    // entry only; the grass and the rocks come back from theirs, and the scene equals a fresh build
    let dir = setup();
    let cwd = dir.path();
    ok(&verdant_in(cwd, &["-q", "build", "world.toml", "--out", "out"]));
    let entries = |out: &str| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(cwd.join(out).join(".cache"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("plants-species-"))
            .collect();
        v.sort();
        v
    };
    let before = entries("out");
    assert_eq!(before.len(), 3, "one entry per species: {before:?}");
    let edited = preset(0.4).replace("max_density = 0.05\n", "max_density = 0.05\nflower = { petals = 5 }\n");
    write(cwd, "world.toml", &edited);
    ok(&verdant_in(cwd, &["-q", "build", "world.toml", "--out", "out"]));
    let after = entries("out");
    let new: Vec<&String> = after.iter().filter(|e| !before.contains(e)).collect();
    assert_eq!(new.len(), 1, "only the flower was built again: {new:?}");
    ok(&verdant_in(cwd, &["-q", "build", "world.toml", "--out", "fresh"]));
    assert_same_tree(&cwd.join("fresh/world"), &cwd.join("out/world"));
}

/// The Slurm and Kubernetes recipes cannot meet their schedulers here: each is run the way its
/// scheduler would run it (the array task's or the indexed pod's variables set, `verdant` on PATH),
/// shard by shard, then its merge; the scene must equal one build.
#[test]
fn the_slurm_and_kubernetes_recipes_build_the_shards_and_merge_as_their_schedulers_would_run_them() {
    let dir = setup();
    let cwd = dir.path();
    // (a map of two bands, in scene tiles of 512 m: the second round makes them)
    let source = "procedural = { kind = \"ridged\", size = 641, seed = 4, relief = 120.0 }";
    write(cwd, "world.toml", &banded_preset(source, 0.5));
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let bin_dir = Path::new(env!("CARGO_BIN_EXE_verdant")).parent().unwrap().to_path_buf();
    // a stand-in `sbatch` that logs what it is asked to submit and answers a job id
    let fake = cwd.join("fake-bin");
    fs::create_dir_all(&fake).unwrap();
    write(&fake, "sbatch", "#!/bin/sh\necho \"$@\" >> \"$SBATCH_LOG\"\necho 1234\n");
    Command::new("chmod").arg("+x").arg(fake.join("sbatch")).status().unwrap();
    let path = format!("{}:{}:{}", bin_dir.display(), fake.display(), std::env::var("PATH").unwrap_or_default());
    ok(&verdant_in(cwd, &["-q", "build", "world.toml", "--out", "single"]));
    let run = |script: &str, env: &[(&str, String)]| {
        let o = Command::new("bash")
            .arg(root.join("scripts/shard").join(script))
            .current_dir(cwd)
            .env("PATH", &path)
            .envs(env.iter().map(|(k, v)| (*k, v.as_str())))
            .output()
            .unwrap();
        ok(&o);
    };
    // Slurm: `sbatch --array=3-5` (a 3-task array not starting at 0): the first task submits the
    // second round and the merge (logged by the stand-in); then the second round's tasks and the
    // merge job as Slurm would run them
    let out = cwd.join("slurm").display().to_string();
    let log = cwd.join("sbatch.log");
    for task in 3..=5 {
        run(
            "slurm.sbatch",
            &[
                ("SLURM_ARRAY_TASK_ID", task.to_string()),
                ("SLURM_ARRAY_TASK_MIN", "3".into()),
                ("SLURM_ARRAY_TASK_COUNT", "3".into()),
                ("SLURM_ARRAY_JOB_ID", "77".into()),
                ("SLURM_SUBMIT_DIR", root.display().to_string()),
                ("SBATCH_LOG", log.display().to_string()),
                ("PRESET", "world.toml".into()),
                ("OUT", out.clone()),
            ],
        );
    }
    let submitted = fs::read_to_string(&log).unwrap();
    let lines: Vec<&str> = submitted.lines().collect();
    assert_eq!(lines.len(), 2, "the second round and the merge, submitted once: {submitted}");
    assert!(lines[0].contains("--array=0-2") && lines[0].contains("--dependency=afterok:77"), "{submitted}");
    assert!(lines[0].contains("ROUND=tiles") && lines[0].ends_with("scripts/shard/slurm.sbatch"), "{submitted}");
    assert!(lines[1].contains("--dependency=afterany:1234") && lines[1].ends_with("slurm_merge.sbatch"), "{submitted}");
    for task in 0..3 {
        run(
            "slurm.sbatch",
            &[
                ("SLURM_ARRAY_TASK_ID", task.to_string()),
                ("SLURM_ARRAY_TASK_COUNT", "3".into()),
                ("SLURM_ARRAY_JOB_ID", "1234".into()),
                ("SHARDS", "3".into()),
                ("ROUND", "tiles".into()),
                ("NO_MERGE", "1".into()),
                ("PRESET", "world.toml".into()),
                ("OUT", out.clone()),
            ],
        );
    }
    let made: usize = (0..3)
        .map(|i| read_json(&cwd.join(format!("slurm/.shards/{i}/world.tiles.json")))["tiles"].as_array().unwrap().len())
        .sum();
    assert_eq!(made, 4, "the second round made the 2 × 2 scene tiles");
    run("slurm_merge.sbatch", &[("PRESET", "world.toml".into()), ("OUT", out.clone()), ("SHARDS", "3".into())]);
    assert_same_tree(&cwd.join("single/world"), &cwd.join("slurm/world"));
    // Kubernetes: each pod's and the merge's container command from k8s-indexed-job.yaml, with the
    // Job's env (SHARDS, PRESET) and the pod's JOB_COMPLETION_INDEX, in the shared volume's folder
    let yaml = fs::read_to_string(root.join("scripts/shard/k8s-indexed-job.yaml")).unwrap();
    let lines: Vec<String> =
        yaml.lines().filter(|l| l.trim().starts_with("- exec verdant")).map(|l| l.trim()[2..].to_string()).collect();
    assert_eq!(lines.len(), 3, "the YAML holds a shard, a second round's and a merge command");
    let shards = yaml.lines().find_map(|l| l.trim().strip_prefix("completions: ")).unwrap().parse::<usize>().unwrap();
    let sh = |command: &str, index: Option<usize>| {
        let mut c = Command::new("sh");
        c.args(["-c", command]).current_dir(cwd.join("k8s")).env("PATH", &path);
        c.env("SHARDS", shards.to_string()).env("PRESET", "world.toml");
        if let Some(i) = index {
            c.env("JOB_COMPLETION_INDEX", i.to_string());
        }
        ok(&c.output().unwrap());
    };
    fs::create_dir_all(cwd.join("k8s")).unwrap();
    fs::copy(cwd.join("world.toml"), cwd.join("k8s/world.toml")).unwrap();
    fs::copy(cwd.join("rock.obj"), cwd.join("k8s/rock.obj")).unwrap();
    for i in (0..shards).rev() {
        sh(&lines[0], Some(i));
    }
    for i in 0..shards {
        sh(&lines[1], Some(i));
    }
    sh(&lines[2], None);
    let made: usize = (0..shards)
        .map(|i| {
            read_json(&cwd.join(format!("k8s/out/.shards/{i}/world.tiles.json")))["tiles"].as_array().unwrap().len()
        })
        .sum();
    assert_eq!(made, 4, "the second round made the 2 × 2 scene tiles");
    assert_same_tree(&cwd.join("single/world"), &cwd.join("k8s/out/world"));
}

/// A chunked map of three bands (1025 rows in bands of 384: 0-384, 384-768, 768-1024) and two
/// species, grass kept 3 m from rocks: eight units, the terrain's bands, the placements of the
/// tile rows starting in each (rows of 128 m: 0-3, 3-6, 6-8), then the species. `source` is the
/// map's line of `[terrain]`.
fn banded_preset(source: &str, max_error: f64) -> String {
    format!(
        "[scene]\nname = \"world\"\nseed = 9\nformats = [\"glb\"]\ntile = 512.0\n\n[terrain]\n{source}\n\
         cell_size = 1.0\nmax_error = {max_error}\nchunk = 128\nskirt = 2.0\nlods = [0.5, 2.0]\n\n\
         [scatter]\ntile = 128.0\n\n\
         [[species]]\nname = \"rock\"\nkind = \"mesh\"\nplacement = \"poisson\"\nmax_density = 0.002\nmin_spacing = 6.0\n\
         obj = \"rock.obj\"\n\n\
         [[species]]\nname = \"grass\"\nkind = \"grass\"\nplacement = \"jittered\"\nmax_density = 0.04\n\
         exclusion = {{ species = \"rock\", radius = 3.0 }}\n"
    )
}

#[test]
fn a_chunked_terrain_is_sharded_band_by_band_and_merges_to_one_builds_bytes() {
    // a procedural map, its main mesh one of the LoD levels (0.5 m); a 16-bit PNG heightmap (each
    // shard reads its bands' rows alone), the main mesh a bound of its own (1 m) that every band
    // meshes besides the levels
    let procedural = "procedural = { kind = \"ridged\", size = 1025, seed = 4, relief = 120.0 }";
    // (a float TIFF read strip by strip, a raw 16-bit file by byte ranges: split in 2 only)
    let png = "heightmap = \"map.png\"\nheight_scale = 300.0";
    let tiff = "heightmap = \"map.tif\"";
    let raw = "heightmap = \"map.r16\"\nsize = [301, 1025]\nheight_scale = 300.0";
    for (source, max_error, splits) in
        [(procedural, 0.5, &[2usize, 4][..]), (png, 1.0, &[2, 4]), (tiff, 1.0, &[2]), (raw, 1.0, &[2])]
    {
        let dir = tempfile::tempdir().unwrap();
        let cwd = dir.path();
        write(cwd, "rock.obj", ROCK_OBJ);
        let value = |i: u32, j: u32| {
            let (x, z) = (i as f64 / 40.0, j as f64 / 55.0);
            (32768.0 + 12000.0 * (x.sin() * z.cos()) + 9000.0 * ((x * 2.7 + z * 1.3).sin())) as u16
        };
        image::ImageBuffer::from_fn(301, 1025, |i, j| image::Luma([value(i, j)])).save(cwd.join("map.png")).unwrap();
        let metres: Vec<f32> = (0..1025).flat_map(|j| (0..301).map(move |i| value(i, j) as f32 / 218.45)).collect();
        let mut tif = std::io::Cursor::new(Vec::new());
        tiff::encoder::TiffEncoder::new(&mut tif)
            .unwrap()
            .write_image::<tiff::encoder::colortype::Gray32Float>(301, 1025, &metres)
            .unwrap();
        fs::write(cwd.join("map.tif"), tif.into_inner()).unwrap();
        let raw_bytes: Vec<u8> =
            (0..1025).flat_map(|j| (0..301).flat_map(move |i| value(i, j).to_le_bytes())).collect();
        fs::write(cwd.join("map.r16"), raw_bytes).unwrap();
        write(cwd, "world.toml", &banded_preset(source, max_error));
        ok(&verdant_in(cwd, &["-q", "build", "world.toml", "--out", "single"]));
        let entries_in = |out: &Path, prefix: &str| {
            fs::read_dir(out.join(".cache"))
                .map(|d| d.filter(|e| e.as_ref().unwrap().file_name().to_string_lossy().starts_with(prefix)).count())
                .unwrap_or(0)
        };
        let single = cwd.join("single");
        let layers = entries_in(&single, "terrain-band-layers-");
        assert_eq!(entries_in(&single, "terrain-band-") - layers, 3, "a single build keeps its three bands as pieces");
        assert_eq!(layers, 3, "and each band's rows of the layers");
        assert_eq!(entries_in(&single, "terrain-band-chunks-"), 0, "its chunks are built from the map");
        for &n in splits {
            let mut shards = run_shards(cwd, &format!("shards{n}"), n);
            let mut built = Vec::new();
            for s in &shards {
                let record = read_json(&cwd.join(s).join("world.shard.json"));
                let names: Vec<String> = record["units"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|u| u["name"].as_str().unwrap().to_string())
                    .collect();
                assert_eq!(
                    names,
                    [
                        "terrain band 0 (rows 0-384)",
                        "terrain band 1 (rows 384-768)",
                        "terrain band 2 (rows 768-1024)",
                        "placements of tile rows 0-3 (band 0)",
                        "placements of tile rows 3-6 (band 1)",
                        "placements of tile rows 6-8 (band 2)",
                        "species rock",
                        "species grass"
                    ],
                    "the units: the terrain's bands, their placements, then the species"
                );
                for k in record["built"].as_array().unwrap() {
                    built.push(names[k.as_u64().unwrap() as usize].clone());
                }
                // a shard holds the pieces of its own bands, no other terrain entry
                let terrain_entries = fs::read_dir(cwd.join(s).join(".cache"))
                    .unwrap()
                    .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                    .filter(|e| e.starts_with("terrain"))
                    .collect::<Vec<_>>();
                assert!(terrain_entries.iter().all(|e| e.starts_with("terrain-band-")), "{terrain_entries:?}");
                // (each of its bands: the meshes, the layers' rows and the chunks)
                let chunks = terrain_entries.iter().filter(|e| e.starts_with("terrain-band-chunks-")).count();
                assert_eq!(3 * chunks, terrain_entries.len(), "{terrain_entries:?}");
            }
            built.sort();
            assert_eq!(built.len(), 8, "every unit built once: {built:?}");
            shards.reverse();
            let out = format!("merged{n}");
            ok(&merge(cwd, &shards, &out));
            assert_same_tree(&cwd.join("single/world"), &cwd.join(&out).join("world"));
            // the second round: the shards make the scene tiles (tiles of 512 m), the merge puts
            // them in place: the same bytes again
            shards.sort();
            run_tile_round(cwd, &shards);
            let grid = read_json(&cwd.join("single/world/scene_tiles.json"))["grid"].clone();
            let count = grid[0].as_u64().unwrap() * grid[1].as_u64().unwrap();
            assert!(count >= 2, "{grid}");
            let mut made = Vec::new();
            for s in &shards {
                let record = read_json(&cwd.join(s).join("world.tiles.json"));
                assert_eq!(record["grid"], grid, "{record}");
                assert_eq!(record["left"], serde_json::json!([]), "{record}");
                made.extend(record["tiles"].as_array().unwrap().iter().map(|t| t[0].as_u64().unwrap()));
            }
            made.sort();
            assert_eq!(made, (0..count).collect::<Vec<_>>(), "every tile made once");
            let tiled = format!("tiled{n}");
            let merged = merge(cwd, &shards, &tiled);
            ok(&merged);
            assert_same_tree(&cwd.join("single/world"), &cwd.join(&tiled).join("world"));
            if n == 2 {
                // the merge takes the tiles from the units: a tile entry's record changed (in a copy
                // of the shards, its digest recorded) is what the merged index says
                let copies: Vec<PathBuf> = (0..n).map(|k| PathBuf::from(format!("retiled/{k}"))).collect();
                for (s, c) in shards.iter().zip(&copies) {
                    copy_dir(&cwd.join(s), &cwd.join(c));
                }
                let record_file = cwd.join(&copies[0]).join("world.tiles.json");
                let mut record: serde_json::Value =
                    serde_json::from_str(&fs::read_to_string(&record_file).unwrap()).unwrap();
                let entry = record["tiles"][0][1].as_str().unwrap().to_string();
                let stage = cwd.join(&copies[0]).join(".cache").join(&entry).join("stage.json");
                let changed = fs::read_to_string(&stage).unwrap().replacen("\"bytes\": ", "\"bytes\": 7", 1);
                fs::remove_file(&stage).unwrap(); // (a hard link)
                fs::write(&stage, &changed).unwrap();
                // (not as the shard wrote it: passed over, said, and the tile written by the merge)
                let mut args: Vec<String> = vec!["merge".into(), "world.toml".into(), "--shards".into()];
                args.extend(copies.iter().map(|p| p.display().to_string()));
                args.extend(["--out".into(), "retiled_merge".into()]);
                let passed = verdant_in(cwd, &args.iter().map(String::as_str).collect::<Vec<_>>());
                ok(&passed);
                assert!(
                    text(&passed).contains("differs from what the shard wrote: the merge writes it"),
                    "{}",
                    text(&passed)
                );
                assert_same_tree(&cwd.join("single/world"), &cwd.join("retiled_merge/world"));
                record["digests"][&entry]["stage.json"] = verdant::scene::cache::sha256_hex(changed.as_bytes()).into();
                fs::write(&record_file, serde_json::to_string(&record).unwrap()).unwrap();
                ok(&merge(cwd, &copies, "retiled_merge2"));
                let index = fs::read_to_string(cwd.join("retiled_merge2/world/scene_tiles.json")).unwrap();
                assert!(index.contains("\"bytes\": 7"), "{index}");
                // a stale second round (of a first round split 2 ways, the first round then cut
                // 3 ways into the same folders) does not stop a merge: its record is gone
                let three: Vec<PathBuf> = (0..3).map(|k| PathBuf::from(format!("retiled/{k}"))).collect();
                let again = run_shards_into(cwd, &three);
                assert!(!cwd.join(&three[0]).join("world.tiles.json").exists(), "{again}");
                ok(&merge(cwd, &three, "retiled_merge3"));
                assert_same_tree(&cwd.join("single/world"), &cwd.join("retiled_merge3/world"));
            }
            if n == 2 && source == procedural {
                // the merge takes the placements and the terrain's chunks from the units: one
                // unit's first rock turned and a band's first chunk vertex moved (in copies of
                // the shards) turn them in the merged table and terrain, once their shards'
                // records say they wrote those bytes (until then the merge refuses the entries)
                let mut tampered = Vec::new();
                for (k, s) in shards.iter().enumerate() {
                    let copy = cwd.join(format!("tampered/{k}"));
                    copy_dir(&cwd.join(s), &copy);
                    for e in fs::read_dir(copy.join(".cache")).unwrap() {
                        let e = e.unwrap().path();
                        let name = e.file_name().unwrap().to_string_lossy().to_string();
                        // (a placement's x; a chunk's first position's y: magic, levels, the
                        // level's length, its chunk count, ci, cj, material, mode, positions' count)
                        let at = match name {
                            _ if name.starts_with("placements-rows-") => 52,
                            _ if name.starts_with("terrain-band-chunks-") => 76,
                            _ => continue,
                        };
                        if tampered.iter().any(|(_, n, _): &(PathBuf, String, Vec<u8>)| n[..8] == name[..8]) {
                            continue;
                        }
                        let mut blob = fs::read(e.join("blob.bin")).unwrap();
                        blob[at..at + 4].copy_from_slice(&123.0f32.to_le_bytes());
                        fs::remove_file(e.join("blob.bin")).unwrap(); // (a hard link)
                        fs::write(e.join("blob.bin"), &blob).unwrap();
                        tampered.push((copy.join("world.shard.json"), name, blob));
                    }
                }
                assert_eq!(tampered.len(), 2);
                let copies: Vec<PathBuf> = (0..n).map(|k| PathBuf::from(format!("tampered/{k}"))).collect();
                let refused = merge(cwd, &copies, "tampered_merge");
                assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
                assert!(text(&refused).contains("blob.bin"), "{}", text(&refused));
                assert!(text(&refused).contains("differs from what the shard wrote"), "{}", text(&refused));
                for (record, entry, blob) in &tampered {
                    let mut r: serde_json::Value = serde_json::from_str(&fs::read_to_string(record).unwrap()).unwrap();
                    r["digests"][entry]["blob.bin"] = verdant::scene::cache::sha256_hex(blob).into();
                    fs::write(record, serde_json::to_string(&r).unwrap()).unwrap();
                }
                ok(&merge(cwd, &copies, "tampered_merge"));
                let terrain = |out: &str| fs::read(cwd.join(out).join("world/terrain/terrain.glb")).unwrap();
                assert_ne!(terrain("tampered_merge"), terrain("single"), "the merge built the chunks itself");
                let height = 123.0f32.to_le_bytes();
                assert!(terrain("tampered_merge").windows(4).any(|w| w == height), "the moved vertex is not there");
                let table = |out: &str| fs::read_to_string(cwd.join(out).join("world/placements/rock.csv")).unwrap();
                assert_ne!(table("tampered_merge"), table("single"), "the merge placed the rows itself");
                let turned =
                    table("tampered_merge").lines().filter(|l| l.contains(",123,") || l.contains(",123.")).count();
                assert!(turned >= 1, "{}", table("tampered_merge"));
            }
        }
    }
}

/// `max_instances` is the whole species' limit: rows placed in shards under it each, whose sum is
/// over it, fail the merge with the message one build gives (the shards themselves pass).
#[test]
fn a_species_over_its_limit_only_when_its_rows_are_joined_fails_the_merge_as_one_build_fails() {
    let dir = tempfile::tempdir().unwrap();
    let cwd = dir.path();
    write(cwd, "rock.obj", ROCK_OBJ);
    let procedural = "procedural = { kind = \"ridged\", size = 1025, seed = 4, relief = 120.0 }";
    // about 40,000 grass clumps over the map, some 15,000 in each band's rows
    let preset = banded_preset(procedural, 0.5).replace("radius = 3.0 }", "radius = 3.0 }\nmax_instances = 20000");
    assert!(preset.contains("max_instances = 20000"));
    write(cwd, "world.toml", &preset);
    let single = verdant_in(cwd, &["-q", "build", "world.toml", "--out", "single"]);
    assert!(!single.status.success());
    let shards = run_shards(cwd, "limit", 3);
    let merged = merge(cwd, &shards, "merged");
    assert!(!merged.status.success());
    let error = |o: &std::process::Output| {
        String::from_utf8_lossy(&o.stderr).lines().find(|l| l.contains("grass")).unwrap_or_default().to_string()
    };
    assert!(error(&single).contains("max_instances"), "{}", text(&single));
    assert_eq!(error(&merged), error(&single), "{}", text(&merged));
}

/// Grass thinned by a snow cover is placed in the merge (the cover reads the whole terrain), and so
/// is a species kept clear of it; the rocks before them are placed by rows in the shards. The
/// merged scene is one build's.
#[test]
fn species_under_a_snow_cover_are_placed_in_the_merge_and_the_rest_by_rows() {
    let dir = tempfile::tempdir().unwrap();
    let cwd = dir.path();
    write(cwd, "rock.obj", ROCK_OBJ);
    let procedural = "procedural = { kind = \"ridged\", size = 1025, seed = 4, relief = 120.0 }";
    let preset = format!(
        "{}\n[[species]]\nname = \"pebble\"\nkind = \"mesh\"\nplacement = \"poisson\"\nmax_density = 0.002\n\
         min_spacing = 6.0\nobj = \"rock.obj\"\nexclusion = {{ species = \"grass\", radius = 1.0 }}\n\n\
         [snow]\natlas_cells = [2, 2]\ncell_px = 32\nnear_count = 50\nfar_count = 0\nsnow_line = 40.0\n\
         snow_line_noise = 5.0\nnoise_scale = 80.0\ntransition = 10.0\nmask_px = 128\nthin_plants = 0.8\n",
        banded_preset(procedural, 0.5)
    );
    write(cwd, "world.toml", &preset);
    ok(&verdant_in(cwd, &["-q", "build", "world.toml", "--out", "single"]));
    let mut shards = run_shards(cwd, "shards", 2);
    for s in &shards {
        let record = read_json(&cwd.join(s).join("world.shard.json"));
        let names: Vec<&str> =
            record["units"].as_array().unwrap().iter().map(|u| u["name"].as_str().unwrap()).collect();
        assert_eq!(names.len(), 9, "3 bands, their 3 placements, 3 species: {names:?}");
        // the placement units hold the rocks alone
        for e in fs::read_dir(cwd.join(s).join(".cache")).unwrap() {
            let e = e.unwrap().path();
            if e.file_name().unwrap().to_string_lossy().starts_with("placements-rows-") {
                let held = read_json(&e.join("stage.json"));
                let species: Vec<&str> =
                    held["species"].as_array().unwrap().iter().map(|s| s["name"].as_str().unwrap()).collect();
                assert_eq!(species, ["rock"]);
            }
        }
    }
    shards.reverse();
    ok(&merge(cwd, &shards, "merged"));
    assert_same_tree(&cwd.join("single/world"), &cwd.join("merged/world"));
    let snow = read_json(&cwd.join("single/world/placements/grass.json"));
    assert!(snow["rules"]["snow"].as_u64().unwrap() > 0, "the snow thins the grass: {snow}");
    // the grass's rows are not units, so no tile is: the second round says why, the merge writes them
    shards.sort();
    run_tile_round(cwd, &shards);
    for s in &shards {
        let record = read_json(&cwd.join(s).join("world.tiles.json"));
        assert!(record["no_units"].as_str().unwrap().contains("`grass` is placed in the merge"), "{record}");
        assert_eq!(record["tiles"], serde_json::json!([]), "{record}");
    }
    ok(&merge(cwd, &shards, "tiled"));
    assert_same_tree(&cwd.join("single/world"), &cwd.join("tiled/world"));
}

/// On a flat map every level's normal map is the same texture, which the units' stand-ins cannot
/// show: each tile is left to the merge, saying why, and the merge writes it (the same bytes). With
/// `[scene] compact` (quantized, and compressed) the tiles store the terrain on one grid over every
/// band's chunks at every level, which the second round finds from the bands' entries: the shards
/// make every tile and the merge puts them in place (linked), the same bytes as one build.
#[test]
fn a_flat_maps_tiles_are_left_to_the_merge_and_compact_scenes_tiles_are_made_by_the_shards() {
    use std::os::unix::fs::MetadataExt;
    for case in ["flat", "quantize", "compress"] {
        let dir = tempfile::tempdir().unwrap();
        let cwd = dir.path();
        write(cwd, "rock.obj", ROCK_OBJ);
        let source = match case {
            "flat" => {
                image::ImageBuffer::from_fn(641, 641, |_, _| image::Luma([30000u16]))
                    .save(cwd.join("map.png"))
                    .unwrap();
                "heightmap = \"map.png\"\nheight_scale = 300.0".to_string()
            }
            _ => "procedural = { kind = \"ridged\", size = 641, seed = 4, relief = 120.0 }".to_string(),
        };
        let mut preset = banded_preset(&source, 0.5);
        if case != "flat" {
            preset = preset.replace("tile = 512.0\n", &format!("tile = 512.0\ncompact = \"{case}\"\n"));
        }
        write(cwd, "world.toml", &preset);
        ok(&verdant_in(cwd, &["-q", "build", "world.toml", "--out", "single"]));
        let shards = run_shards(cwd, "shards", 2);
        run_tile_round(cwd, &shards);
        let (mut made, mut left) = (Vec::new(), 0);
        for s in &shards {
            let record = read_json(&cwd.join(s).join("world.tiles.json"));
            assert_eq!(record["no_units"], serde_json::Value::Null, "{case}: {record}");
            for t in record["tiles"].as_array().unwrap() {
                made.push(cwd.join(s).join(".cache").join(t[1].as_str().unwrap()));
            }
            for l in record["left"].as_array().unwrap() {
                assert!(l[1].as_str().unwrap().contains("alike"), "{case}: {record}");
                left += 1;
            }
        }
        assert_eq!((made.len(), left), if case == "flat" { (0, 4) } else { (4, 0) }, "{case}: the 2 × 2 tiles");
        ok(&merge(cwd, &shards, "merged"));
        assert_same_tree(&cwd.join("single/world"), &cwd.join("merged/world"));
        // (each merged tile is the file a shard made, linked: the same inode)
        let index = read_json(&cwd.join("merged/world/scene_tiles.json"));
        let inode = |p: &Path| fs::metadata(p).unwrap().ino();
        for t in index["tiles"].as_array().unwrap() {
            let file = t["file"].as_str().unwrap();
            let merged = inode(&cwd.join("merged/world").join(file));
            let from_shard = made.iter().any(|entry| entry.join(file).is_file() && inode(&entry.join(file)) == merged);
            assert_eq!(from_shard, case != "flat", "{case}: {file}");
        }
    }
}

/// A skirt too shallow for the map's heights in f32 is the preset's fault in a band's unit (which
/// builds the band's chunks for its normal maps) as in the terrain stage: exit code 2, the skirt
/// named, in a whole build and in a shard alike. (Without a chain: a chain's levels hang their
/// skirts at least their bounds deep.)
#[test]
fn a_band_unit_refuses_a_skirt_the_map_cannot_hold_as_one_build_does() {
    let dir = tempfile::tempdir().unwrap();
    let cwd = dir.path();
    write(cwd, "rock.obj", ROCK_OBJ);
    let source = "procedural = { kind = \"ridged\", size = 1025, seed = 4, relief = 600.0 }";
    let preset = banded_preset(source, 1.0).replace("skirt = 2.0", "skirt = 0.000001");
    write(cwd, "world.toml", &preset.replace("lods = [0.5, 2.0]\n", ""));
    for args in
        [&["build", "world.toml", "--out", "single"][..], &["build", "world.toml", "--shard", "0/2", "--out", "s0"]]
    {
        let o = verdant_in(cwd, args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("skirt depth of 0.000001 m cannot be represented"), "{args:?}: {err}");
    }
}
