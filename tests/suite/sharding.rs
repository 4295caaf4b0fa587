//! Sharded builds (issue 18): `verdant build --shard i/N` in N processes at once, `verdant merge`
//! in any shard order, against one `verdant build` of the same preset, byte for byte; and the
//! merge's refusals (a shard missing, given twice, of another split, built from other inputs).

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

/// Runs the N shards of `world.toml` as N processes at once, into `<base>/<i>`.
fn run_shards(cwd: &Path, base: &str, n: usize) -> Vec<PathBuf> {
    let children: Vec<_> = (0..n)
        .map(|i| {
            Command::new(env!("CARGO_BIN_EXE_verdant"))
                .current_dir(cwd)
                .args(["-q", "build", "world.toml", "--shard", &format!("{i}/{n}"), "--out", &format!("{base}/{i}")])
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .expect("run verdant")
        })
        .collect();
    for c in children {
        ok(&c.wait_with_output().unwrap());
    }
    (0..n).map(|i| PathBuf::from(format!("{base}/{i}"))).collect()
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
    refused(&[two[0].clone(), two[0].clone(), two[1].clone()], &["given twice"]);
    refused(&[two[0].clone(), three[1].clone()], &["another split", "same N"]);
    refused(&[PathBuf::from("nowhere")], &["nowhere", "not a shard folder"]);
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
