//! The scatter stage inside `verdant build` (issue 4), driven through the binary: placement tables and
//! the instanced scene.glb are byte-identical across runs, `--threads` and `--jobs`; scene.glb's
//! EXT_mesh_gpu_instancing nodes equal the CSV rows the first view draws, at their levels (replayed
//! here from the tables and the manifest); the JSON summaries and report.json agree with
//! the tables; spacing and exclusions hold; stage selection; the scatter cache (settings, density
//! maps); `max_instances` fails the scene alone; a species no rule allows writes empty, valid files.
//!
//! Every test writes small procedural presets (129² samples, 2 m cells: 256 m across) into a
//! temporary folder and runs the binary there with relative paths.

use std::collections::BTreeMap;
use std::fs;
use std::path::Path;

use image::{ImageBuffer, Luma};

use crate::common::*;

// ------------------------------------------------------------------------------------------ helpers

/// The scatter outputs of a scene folder: placements/* and scene.glb.
fn scatter_files(scene_dir: &Path) -> BTreeMap<String, Vec<u8>> {
    tree(scene_dir).into_iter().filter(|(k, _)| k.starts_with("placements/") || k == "scene.glb").collect()
}

const TREE: &str = "[[species]]\nname = \"tree\"\nkind = \"tree\"\nplacement = \"poisson\"\nmax_density = 0.01\n\
                    min_spacing = 5.0\nscale = [0.8, 1.2]\n";
const GRASS: &str = "[[species]]\nname = \"grass\"\nkind = \"grass\"\nplacement = \"jittered\"\nmax_density = 0.5\n\
                     scale = [0.7, 1.1]\nexclusion = { species = \"tree\", radius = 1.5 }\n";

/// A unit cube resting on the ground (a rock for a mesh species).
const ROCK_OBJ: &str = "v -0.5 0 -0.5\nv 0.5 0 -0.5\nv 0.5 0 0.5\nv -0.5 0 0.5\n\
                        v -0.5 1 -0.5\nv 0.5 1 -0.5\nv 0.5 1 0.5\nv -0.5 1 0.5\n\
                        f 1 2 3 4\nf 8 7 6 5\nf 1 5 6 2\nf 2 6 7 3\nf 3 7 8 4\nf 4 8 5 1\n";

/// fbm 129² with 2 m cells, 64² chunks with skirts, 64 m scatter tiles, and the given species tables.
fn preset(name: &str, seed: u64, species: &str) -> String {
    format!(
        "[scene]\nname = \"{name}\"\nseed = {seed}\nformats = [\"glb\"]\n\n[terrain]\n\
         procedural = {{ kind = \"fbm\", size = 129, seed = 3, relief = 50.0 }}\n\
         cell_size = 2.0\nmax_error = 0.5\nchunk = 64\nskirt = 2.0\n\n[scatter]\ntile = 64.0\n\n{species}"
    )
}

fn forest(name: &str, seed: u64) -> String {
    preset(name, seed, &format!("{TREE}\n{GRASS}"))
}

/// One parsed placement table row.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Row {
    pos: [f64; 3],
    rot: [f32; 4],
    scale: [f32; 3],
    yaw: f32,
    tile: u32,
    variant: u32,
}

const HEADER: &str = "x,y,z,qx,qy,qz,qw,sx,sy,sz,yaw_deg,tile,variant";

fn read_csv(path: &Path) -> Vec<Row> {
    let t = fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = t.lines();
    assert_eq!(lines.next(), Some(HEADER), "{}: header", path.display());
    assert!(t.ends_with('\n'), "{}: no final line end", path.display());
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 13, "{}: row {l}", path.display());
            let d = |k: usize| f[k].parse::<f64>().unwrap_or_else(|e| panic!("{l}: {e}"));
            let s = |k: usize| f[k].parse::<f32>().unwrap_or_else(|e| panic!("{l}: {e}"));
            Row {
                pos: [d(0), d(1), d(2)],
                rot: [s(3), s(4), s(5), s(6)],
                scale: [s(7), s(8), s(9)],
                yaw: s(10),
                tile: f[11].parse().unwrap(),
                variant: f[12].parse().unwrap(),
            }
        })
        .collect()
}

/// `v` rotated by the unit quaternion `q` (x, y, z, w): v + 2w (q × v) + 2 q × (q × v).
fn rotate(q: [f32; 4], v: [f64; 3]) -> [f64; 3] {
    let [x, y, z, w] = q.map(|c| c as f64);
    let cross =
        |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let t = cross([x, y, z], v).map(|c| 2.0 * c);
    let u = cross([x, y, z], t);
    [v[0] + w * t[0] + u[0], v[1] + w * t[1] + u[1], v[2] + w * t[2] + u[2]]
}

fn dist_xz(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Smallest x/z distance from each of `a` to any of `b` (skipping identical indices when `same`),
/// through a uniform grid of cell `cell` (only pairs closer than `cell` are looked at).
fn min_distance(a: &[Row], b: &[Row], same: bool, cell: f64) -> f64 {
    let mut grid: BTreeMap<(i64, i64), Vec<usize>> = BTreeMap::new();
    let key = |p: [f64; 3]| ((p[0] / cell).floor() as i64, (p[2] / cell).floor() as i64);
    for (i, r) in b.iter().enumerate() {
        grid.entry(key(r.pos)).or_default().push(i);
    }
    let mut best = f64::INFINITY;
    for (i, r) in a.iter().enumerate() {
        let (cx, cz) = key(r.pos);
        for dx in -1..=1 {
            for dz in -1..=1 {
                for &j in grid.get(&(cx + dx, cz + dz)).map(Vec::as_slice).unwrap_or(&[]) {
                    if !(same && i == j) {
                        best = best.min(dist_xz(r.pos, b[j].pos));
                    }
                }
            }
        }
    }
    best
}

/// A 16-bit gray PNG: left half `left`, right half `right` (0..1).
fn write_density(path: &Path, left: f32, right: f32) {
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    let img = ImageBuffer::from_fn(32, 16, |i, _| Luma([((if i < 16 { left } else { right }) * 65535.0) as u16]));
    img.save(path).unwrap();
}

// ------------------------------------------------------------------------------------- determinism

#[test]
fn placements_and_scene_glb_are_byte_identical_across_runs_threads_and_jobs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &forest("a", 3));
    write(d, "p/b.toml", &forest("b", 4));
    let runs: [(&str, &str, &str); 4] = [("o1", "1", "1"), ("o2", "2", "2"), ("o3", "2", "1"), ("o4", "1", "2")];
    for (k, (out, jobs, threads)) in runs.into_iter().enumerate() {
        if k >= 2 {
            // o1 (1 job, 1 thread) and o2 (2 jobs, 2 threads) build every stage; o3 and o4 reuse
            // o2's plants (the slow stage, whose thread independence the tree and grass tests check)
            // and build terrain, scatter and view at their own job and thread counts
            share_plants_cache(&d.join("o2"), &d.join(out));
        }
        ok(&verdant_in(d, &["--threads", threads, "build", "p/a.toml", "p/b.toml", "--jobs", jobs, "--out", out]));
    }
    for out in ["o3", "o4"] {
        let timing = |scene: &str| read_json(&d.join(out).join(scene).join("report.json"))["timing"].clone();
        let (a, b) = (timing("a"), timing("b"));
        for (stage, cached) in [("plants", true), ("scatter", false), ("view", false), ("preview", false)] {
            assert_eq!((&a[stage]["cached"], &b[stage]["cached"]), (&cached.into(), &cached.into()), "{out}: {stage}");
        }
        // the two scenes share their terrain: one builds it, the other may find it cached
        assert!(a["terrain"]["cached"] == false || b["terrain"]["cached"] == false, "{out}: terrain built");
    }
    // and once more like the first, with every stage recomputed
    ok(&verdant_in(d, &["--threads", "1", "build", "p/a.toml", "p/b.toml", "--jobs", "1", "--out", "o1", "--force"]));
    for scene in ["a", "b"] {
        let first = scatter_files(&d.join("o1").join(scene));
        assert_eq!(
            first.keys().collect::<Vec<_>>(),
            [
                "placements/density_0.png",
                "placements/grass.csv",
                "placements/grass.json",
                "placements/tree.csv",
                "placements/tree.json",
                "scene.glb"
            ],
            "{scene}: scatter files"
        );
        for (out, ..) in &runs[1..] {
            let other = scatter_files(&d.join(out).join(scene));
            for (rel, bytes) in &first {
                assert!(*bytes == other[rel], "{scene}/{rel} differs between o1 and {out}");
            }
        }
    }
    // a different scene seed gives different placements on the same terrain
    assert_ne!(
        fs::read(d.join("o1/a/placements/tree.csv")).unwrap(),
        fs::read(d.join("o1/b/placements/tree.csv")).unwrap()
    );
    assert_eq!(
        fs::read(d.join("o1/a/terrain/terrain.glb")).unwrap(),
        fs::read(d.join("o1/b/terrain/terrain.glb")).unwrap()
    );
}

// ---------------------------------------------------------------------- scene.glb = tables = report

#[test]
fn scene_glb_instances_equal_the_csv_rows_and_json_and_report_agree() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &forest("a", 3));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let s = d.join("o/a");
    let s_dir = s.clone();
    let scene = verdant::validate::read_scene(&s.join("scene.glb")).expect("scene.glb re-imports");
    let report = read_json(&s.join("report.json"));
    let manifest = read_json(&s.join("manifest.json"));
    assert_eq!(manifest["scatter"]["scene"], "scene.glb");
    // every analyzed level's Unreal/Unity screen size: the sphere diameter over the screen height
    // its MSFT coverage implies (16:9 reference screen), 1 for LoD0
    let mut sized = 0;
    for plant in manifest["plants"].as_array().unwrap() {
        for l in plant["lods"].as_array().unwrap() {
            let (c, size) = (l["screen_coverage"].as_f64().unwrap(), l["screen_size"].as_f64().unwrap());
            if c >= 1.0 {
                assert_eq!(size, 1.0, "{l}");
            } else {
                assert!((size - 2.0 * (c * (16.0 / 9.0) / std::f64::consts::PI).sqrt()).abs() < 1e-9, "{l}");
                sized += 1;
            }
        }
    }
    assert!(sized > 3, "{sized} levels with a screen size below 1");
    let mut counts = BTreeMap::new();
    for (k, species) in ["tree", "grass"].into_iter().enumerate() {
        let rows = read_csv(&s.join(format!("placements/{species}.csv")));
        assert!(rows.len() > if species == "tree" { 200 } else { 10_000 }, "{species}: only {} rows", rows.len());
        counts.insert(species, rows.len());

        // the first view, replayed here from the table and manifest.json's view section: each
        // row's variant (its column, through the chain's pick), distance to its centre, cull and
        // level; scene.glb's node per (variant, level) holds exactly those rows, in CSV order
        let root = scene
            .roots
            .iter()
            .map(|&r| &scene.nodes[r])
            .find(|n| n.name == species)
            .unwrap_or_else(|| panic!("no root node {species}"));
        let view = &manifest["view"]["views"][0];
        let chain = &manifest["view"]["chains"][species];
        let cull = &view["species"][k]["cull"];
        let eye: Vec<f64> = view["camera"]["eye"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let factor = view["distance_factor"].as_f64().unwrap();
        let centre_y = chain["centre_y_m"].as_f64().unwrap();
        let variants = chain["variants"].as_array().unwrap();
        let pick: Vec<usize> = chain["pick"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
        assert!(!pick.is_empty(), "{species}: the manifest's chain has no pick");
        let key = |t: [f32; 3], q: [f32; 4], s: [f32; 3]| format!("{t:?}{q:?}{s:?}");
        // an impostor level's baked views (its mesh extras in the species file), per (variant, level)
        let mut impostor_of: BTreeMap<(usize, usize), Option<serde_json::Value>> = BTreeMap::new();
        let mut want: BTreeMap<(u64, u64, Option<u64>), Vec<String>> = BTreeMap::new();
        let mut culled = 0;
        for r in &rows {
            // the column is the documented hash of x and z over the species' variants
            assert_eq!(r.variant, verdant::scatter::variant_of(r.pos, pick.len()), "{species}: variant column");
            let v = pick[r.variant as usize];
            let s = r.scale[1] as f64;
            let [x, y, z, w] = r.rot.map(|c| c as f64);
            let up = centre_y * s;
            let c = [
                r.pos[0] as f32 as f64 + 2.0 * (x * y - w * z) * up,
                r.pos[1] as f32 as f64 + (1.0 - 2.0 * (x * x + z * z)) * up,
                r.pos[2] as f32 as f64 + 2.0 * (y * z + w * x) * up,
            ];
            let d = ((c[0] - eye[0]).powi(2) + (c[1] - eye[1]).powi(2) + (c[2] - eye[2]).powi(2)).sqrt();
            let limit = cull["distance_m"].as_f64().unwrap()
                * if cull["scales_with_view"].as_bool().unwrap() { factor * s } else { 1.0 };
            if d > limit {
                culled += 1;
                continue;
            }
            let level = variants[v]
                .as_array()
                .unwrap()
                .iter()
                .enumerate()
                .filter(|(_, l)| l["switch_distance_m"].as_f64().unwrap() * factor * s <= d)
                .map(|(n, _)| n)
                .max()
                .unwrap();
            let impostor = impostor_of
                .entry((v, level))
                .or_insert_with(|| {
                    let l = &variants[v][level];
                    let file = verdant::validate::read_scene(&s_dir.join(l["file"].as_str().unwrap())).unwrap();
                    let mesh = file.meshes.iter().find(|m| m.name == l["mesh"].as_str().unwrap()).unwrap();
                    mesh.extras.as_ref().and_then(|e| e.get("verdant_impostor")).cloned()
                })
                .clone();
            // the documented view: k = round(atan2(dx, dz) / step) mod views, (dx, dz) from the
            // instance's centre to the eye in its own frame
            let view = impostor.map(|e| {
                let c: Vec<f64> = e["centre"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
                let sc = r.scale.map(|v| v as f64);
                let local_c = [c[0] * sc[0], c[1] * sc[1], c[2] * sc[2]];
                let world_c = rotate(r.rot, local_c);
                let p = r.pos.map(|v| v as f32 as f64);
                let d = [eye[0] - p[0] - world_c[0], eye[1] - p[1] - world_c[1], eye[2] - p[2] - world_c[2]];
                let l = rotate([-r.rot[0], -r.rot[1], -r.rot[2], r.rot[3]], d);
                let step = e["azimuth_step_deg"].as_f64().unwrap();
                let views = e["views"].as_i64().unwrap();
                ((((l[0] / sc[0]).atan2(l[2] / sc[2]).to_degrees() / step).round() as i64).rem_euclid(views)) as u64
            });
            want.entry((v as u64, level as u64, view)).or_default().push(key(
                [r.pos[0] as f32, r.pos[1] as f32, r.pos[2] as f32],
                r.rot,
                r.scale,
            ));
        }
        assert_eq!(view["species"][k]["culled"].as_u64(), Some(culled), "{species}: culled rows");
        let mut got: BTreeMap<(u64, u64, Option<u64>), Vec<String>> = BTreeMap::new();
        for &c in &root.children {
            let node = &scene.nodes[c];
            let e = node.extras.as_ref().unwrap_or_else(|| panic!("{}: no extras", node.name));
            let (v, level) = (e["variant"].as_u64().unwrap(), e["level"].as_u64().unwrap());
            let view = e.get("verdant_impostor_view").map(|k| k.as_u64().unwrap());
            let mesh = &scene.meshes[node.mesh.unwrap_or_else(|| panic!("{}: no mesh", node.name))];
            let chain_mesh = variants[v as usize][level as usize]["mesh"].as_str().unwrap();
            let want_name = match view {
                Some(k) => format!("{chain_mesh}_view{k}"),
                None => chain_mesh.to_string(),
            };
            assert_eq!(mesh.name, want_name, "{}: the chain's mesh (its baked view for an impostor)", node.name);
            assert_eq!(node.name, format!("{species}_{}", mesh.name));
            let inst = node.instances.as_ref().unwrap_or_else(|| panic!("{} is not instanced", node.name));
            assert_eq!(inst.translations.len(), inst.rotations.len());
            assert_eq!(inst.translations.len(), inst.scales.len());
            let keys: Vec<String> = (0..inst.translations.len())
                .map(|i| key(inst.translations[i], inst.rotations[i], inst.scales[i]))
                .collect();
            if let Some(k) = view {
                // the turned quad shows cell k of the atlas, not mirrored: its corner farthest to the
                // quad's right (azimuth k·step: right = (cos, 0, −sin)) has the cell's largest u
                let e = impostor_of[&(v as usize, level as usize)].as_ref().expect("an impostor level");
                let cell: Vec<f64> =
                    e["cells_uv"][k as usize].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
                let p = &mesh.primitives[0];
                let (lo_u, hi_u) =
                    p.uvs.iter().fold((f64::MAX, f64::MIN), |(a, b), t| (a.min(t[0] as f64), b.max(t[0] as f64)));
                let (lo_v, hi_v) =
                    p.uvs.iter().fold((f64::MAX, f64::MIN), |(a, b), t| (a.min(t[1] as f64), b.max(t[1] as f64)));
                for (got, want) in [lo_u, lo_v, hi_u, hi_v].iter().zip(&cell) {
                    assert!((got - want).abs() < 1e-6, "{}: uvs {lo_u} {lo_v} {hi_u} {hi_v}, cell {cell:?}", node.name);
                }
                let a = (k as f64 * e["azimuth_step_deg"].as_f64().unwrap()).to_radians();
                let right = |q: &[f32; 3]| q[0] as f64 * a.cos() - q[2] as f64 * a.sin();
                let far_right = (0..p.positions.len())
                    .max_by(|&i, &j| right(&p.positions[i]).total_cmp(&right(&p.positions[j])))
                    .unwrap();
                assert!((p.uvs[far_right][0] as f64 - cell[2]).abs() < 1e-6, "{}: the picture is mirrored", node.name);
            }
            if view.is_some() {
                // what a person sees: every impostor quad faces the eye within half a step (22.5°)
                let n = mesh.primitives[0].normals[0].map(|c| c as f64);
                let p0 = mesh.primitives[0].positions.iter().fold([0.0f64; 3], |a, p| {
                    [a[0] + p[0] as f64 / 4.0, a[1] + p[1] as f64 / 4.0, a[2] + p[2] as f64 / 4.0]
                });
                for i in 0..inst.translations.len() {
                    let q = inst.rotations[i];
                    let wn = rotate(q, n);
                    let sc = inst.scales[i].map(|c| c as f64);
                    let c = rotate(q, [p0[0] * sc[0], p0[1] * sc[1], p0[2] * sc[2]]);
                    let t = inst.translations[i].map(|c| c as f64);
                    let to_eye = [eye[0] - t[0] - c[0], eye[2] - t[2] - c[2]];
                    let cos = (wn[0] * to_eye[0] + wn[2] * to_eye[1])
                        / ((wn[0] * wn[0] + wn[2] * wn[2]).sqrt()
                            * (to_eye[0] * to_eye[0] + to_eye[1] * to_eye[1]).sqrt());
                    assert!(
                        cos >= (22.5f64 + 0.01).to_radians().cos(),
                        "{}: instance {i} faces {:.1}° off the eye",
                        node.name,
                        cos.acos().to_degrees()
                    );
                }
            }
            assert!(
                got.insert((v, level, view), keys).is_none(),
                "{species}: two nodes for variant {v} LOD{level} {view:?}"
            );
        }
        if species == "tree" {
            // the trees' impostors show more than one baked view (random yaws, one eye)
            let views: std::collections::BTreeSet<u64> = got.keys().filter_map(|k| k.2).collect();
            assert!(views.len() > 2, "impostor views drawn: {views:?}");
        }
        assert_eq!(got, want, "{species}: scene.glb = the table replayed for the first view (CSV order within a node)");
        assert!(got.len() > 1, "{species}: more than one mesh and level drawn: {:?}", got.keys().collect::<Vec<_>>());
        let mut by_tile: BTreeMap<u32, Vec<Row>> = BTreeMap::new();
        for r in &rows {
            by_tile.entry(r.tile).or_default().push(*r);
        }
        assert!(by_tile.len() > 4, "{species}: instances in only {} tiles", by_tile.len());
        for r in &rows {
            let n = r.rot.iter().map(|v| (*v as f64).powi(2)).sum::<f64>().sqrt();
            assert!((n - 1.0).abs() < 1e-5, "{species}: rotation {:?} not unit", r.rot);
            assert!(r.yaw.is_finite() && r.scale[0] == r.scale[1] && r.scale[1] == r.scale[2]);
        }

        // the JSON summary: count and per-tile counts
        let json = read_json(&s.join(format!("placements/{species}.json")));
        assert_eq!(json["count"].as_u64(), Some(rows.len() as u64), "{species}.json count");
        let per_tile: BTreeMap<u64, u64> = json["stats"]["per_tile"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|t| t["count"].as_u64().unwrap() > 0)
            .map(|t| (t["tile"].as_u64().unwrap(), t["count"].as_u64().unwrap()))
            .collect();
        let want: BTreeMap<u64, u64> = by_tile.iter().map(|(&t, r)| (t as u64, r.len() as u64)).collect();
        assert_eq!(per_tile, want, "{species}.json per-tile counts");

        // report.json: count, expected, min pair distance, max height error per species
        let rs = &report["stages"]["scatter"]["species"][k];
        assert_eq!(rs["name"], species);
        assert_eq!(rs["count"].as_u64(), Some(rows.len() as u64));
        let st = &rs["stats"];
        assert_eq!(st["count"].as_u64(), Some(rows.len() as u64));
        let expected = st["expected"].as_f64().unwrap_or_else(|| panic!("{species}: no expected count: {st}"));
        assert!(
            (rows.len() as f64 - expected).abs() < 0.1 * expected,
            "{species}: {} placed, {expected} expected",
            rows.len()
        );
        let max_err =
            st["max_height_error_m"].as_f64().unwrap_or_else(|| panic!("{species}: no max_height_error_m: {st}"));
        assert!((0.0..=1e-4).contains(&max_err), "{species}: max height error {max_err}");
        // measured on every instance (below the sampling limit): the CSV's heights are the mesh's
        // on their 1 µm grid (half a step, 5e-7 m, at most)
        assert_eq!(st["height_checked"].as_u64(), Some(rows.len() as u64), "{species}: {st}");
        let csv_err = st["max_height_error_csv_m"]
            .as_f64()
            .unwrap_or_else(|| panic!("{species}: no max_height_error_csv_m: {st}"));
        assert!((0.0..=5e-7 + 1e-12).contains(&csv_err), "{species}: CSV height error {csv_err}");
        let min_pair =
            st["min_pair_distance_m"].as_f64().unwrap_or_else(|| panic!("{species}: no min_pair_distance_m: {st}"));
        let ours = min_distance(&rows, &rows, true, 6.0);
        if ours.is_finite() {
            assert!(
                (ours - min_pair).abs() <= 1e-9 * ours.max(1.0),
                "{species}: report min pair {min_pair}, CSV {ours}"
            );
        }
        assert_eq!(manifest["scatter"]["species"][k]["count"].as_u64(), Some(rows.len() as u64));
    }

    // spacing: trees >= min_spacing apart over the whole scene (tile borders included); no grass
    // within the 1.5 m exclusion radius of a tree (x/z)
    let trees = read_csv(&s.join("placements/tree.csv"));
    let grass = read_csv(&s.join("placements/grass.csv"));
    let tree_pair = min_distance(&trees, &trees, true, 6.0);
    assert!(tree_pair >= 5.0 * (1.0 - 1e-9), "two trees {tree_pair} m apart, min_spacing 5");
    let clear = min_distance(&grass, &trees, false, 2.0);
    assert!(clear >= 1.5 * (1.0 - 1e-9), "grass {clear} m from a tree, exclusion radius 1.5");
    // instances lie inside the terrain (256 m) and carry the tile of their x/z (64 m tiles, 4 a row)
    for r in trees.iter().chain(&grass) {
        assert!((0.0..=256.0).contains(&r.pos[0]) && (0.0..=256.0).contains(&r.pos[2]), "{r:?}");
        let tile = ((r.pos[2] / 64.0).floor().min(3.0) as u32) * 4 + (r.pos[0] / 64.0).floor().min(3.0) as u32;
        assert_eq!(r.tile, tile, "{r:?}");
    }
    let v = verdant_in(d, &["validate", "o/a/scene.glb"]);
    ok(&v);
    let _ = counts;
}

// ---------------------------------------------------------------------------------- stage selection

#[test]
fn only_terrain_scatter_writes_placements_without_preview_and_scatter_alone_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &forest("a", 3));
    ok(&verdant_in(d, &["build", "p/a.toml", "--only", "terrain,scatter", "--out", "o"]));
    let s = d.join("o/a");
    for f in ["placements/tree.csv", "placements/grass.json", "terrain/terrain.glb"] {
        assert!(s.join(f).is_file(), "{f} missing");
    }
    // scene.glb is the view stage's
    assert!(!s.join("preview.png").exists() && !s.join("scene.glb").exists());
    let m = read_json(&s.join("manifest.json"));
    assert!(m["preview"].is_null());
    assert!(m["files"].as_array().unwrap().iter().any(|f| f["path"] == "placements/tree.csv"));

    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "full"]));
    for (rel, bytes) in scatter_files(&s) {
        assert!(bytes == fs::read(d.join("full/a").join(&rel)).unwrap(), "{rel} differs with and without the preview");
    }

    let o = verdant_in(d, &["build", "p/a.toml", "--only", "scatter", "--out", "sc"]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(2), "{t}");
    assert!(t.contains("terrain"), "the error does not name the terrain: {t}");
    assert!(!t.contains("panicked"), "{t}");
    assert!(!d.join("sc/a").exists());
}

// --------------------------------------------------------------------------------------------- cache

#[test]
fn scatter_cache_hits_on_rebuild_and_misses_on_species_or_density_map_changes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mapped =
        GRASS.replace("placement = \"jittered\"\n", "placement = \"jittered\"\ndensity_map = \"maps/grass.png\"\n");
    write_density(&d.join("p/maps/grass.png"), 0.2, 0.8);
    // every look the plants stage makes, so each of its typed reports goes through the cache
    let others = "[[species]]\nname = \"flower\"\nkind = \"flower\"\nmax_density = 0.01\n\n\
                  [[species]]\nname = \"rock\"\nkind = \"mesh\"\nmax_density = 0.002\nobj = \"models/rock.obj\"\n";
    write(d, "p/models/rock.obj", ROCK_OBJ);
    write(d, "p/a.toml", &preset("a", 3, &format!("{TREE}\n{mapped}\n{others}")));
    let build = || {
        let o = verdant_in(d, &["build", "p/a.toml", "--out", "o"]);
        ok(&o);
        o
    };
    let s = d.join("o/a");
    let o = build();
    assert_eq!(summary_row(&o, "a")[1], "built", "{}", text(&o));
    assert!(!timing_cached(&s, "scatter"));
    let first = scatter_files(&s);
    // the density map shapes the grass: the right half (0.8) holds about 4× the left (0.2)
    let grass = read_csv(&s.join("placements/grass.csv"));
    let right = grass.iter().filter(|r| r.pos[0] >= 128.0).count() as f64;
    let left = grass.len() as f64 - right;
    assert!(right > 2.5 * left && right < 6.0 * left, "left {left}, right {right}");

    // every chain level in the manifest is named and written
    let manifest = fs::read(s.join("manifest.json")).unwrap();
    let m: serde_json::Value = serde_json::from_slice(&manifest).unwrap();
    let plants = m["plants"].as_array().expect("manifest.json lists the plants");
    assert_eq!(plants.len(), 4, "{plants:?}");
    for p in plants {
        let lods = p["lods"].as_array().unwrap();
        // flowers are one level (crossed billboards); grass, trees and models are chains
        let levels = if p["look"] == "flower" { 0..=0 } else { 2..=usize::MAX };
        assert!(levels.contains(&lods.len()), "{} ({}): {lods:?}", p["name"], p["look"]);
        for l in lods {
            assert!(l["kind"].as_str().is_some_and(|k| !k.is_empty()), "{}: a level without a kind: {l}", p["name"]);
            assert!(s.join(l["file"].as_str().unwrap()).is_file(), "{}: {l}", p["name"]);
            assert!(l["triangles"].as_u64().is_some_and(|t| t > 0), "{l}");
        }
    }

    // unchanged: built*, every stage cached (the plants' reports read back), identical bytes
    let o = build();
    assert_eq!(summary_row(&o, "a")[1], "built*", "{}", text(&o));
    assert!(timing_cached(&s, "terrain") && timing_cached(&s, "scatter") && timing_cached(&s, "preview"));
    assert!(timing_cached(&s, "plants"), "the plants stage's report did not read back from the cache");
    assert_eq!(scatter_files(&s), first, "a cached scatter stage restored different bytes");
    assert_eq!(fs::read(s.join("manifest.json")).unwrap(), manifest, "a cached build wrote another manifest");

    // a species setting changes: the scatter misses, and so does the terrain, whose `_SURFACE`
    // carries the species' densities (its mesh stays the same)
    let terrain_before = read_json(&s.join("report.json"))["stages"]["terrain"]["triangles"].clone();
    let glb_before = fs::read(s.join("terrain/terrain.glb")).unwrap();
    write(
        d,
        "p/a.toml",
        &preset("a", 3, &format!("{}\n{mapped}", TREE.replace("max_density = 0.01", "max_density = 0.005"))),
    );
    build();
    assert!(!timing_cached(&s, "terrain"), "the terrain's surface attributes follow the species");
    assert!(!timing_cached(&s, "scatter"), "a changed max_density must recompute the scatter");
    assert_eq!(read_json(&s.join("report.json"))["stages"]["terrain"]["triangles"], terrain_before);
    assert!(terrain_before.as_u64().is_some_and(|t| t > 0));
    assert_ne!(fs::read(s.join("terrain/terrain.glb")).unwrap(), glb_before);
    // ... re-textured, not re-meshed: the meshes come from the cache's terrain-mesh entry, and the
    // terrain is byte for byte what a build without any cache writes
    let timing = read_json(&s.join("report.json"))["timing"]["terrain"]["computed_in"].clone();
    assert_eq!(timing["mesh"], 0.0, "the terrain was meshed again: {timing}");
    let memo = fs::read_dir(d.join("o/.cache"))
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with("terrain-mesh-"));
    assert_eq!(memo.count(), 1);
    // `cache prune` keeps it with the scene built from it
    ok(&verdant_in(d, &["cache", "prune", "--out", "o"]));
    let kept = fs::read_dir(d.join("o/.cache")).unwrap().flatten();
    assert_eq!(kept.filter(|e| e.file_name().to_string_lossy().starts_with("terrain-mesh-")).count(), 1);
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "fresh"]));
    let terrain_files = |root: &Path| {
        let mut t = tree(&root.join("a"));
        t.retain(|k, _| k.starts_with("terrain/"));
        t
    };
    assert_eq!(terrain_files(&d.join("o")), terrain_files(&d.join("fresh")), "the memo changed the terrain");
    let fewer = read_csv(&s.join("placements/tree.csv")).len();
    assert!(fewer < read_csv_bytes(&first["placements/tree.csv"]) * 3 / 4, "{fewer} trees after halving max_density");

    // the density map's bytes change (same path, same preset): scatter misses, and the terrain
    // (its soil layer follows the grass)
    let before = scatter_files(&s);
    let soil_before = fs::read(s.join("terrain/terrain_layers_1.png")).unwrap();
    write_density(&d.join("p/maps/grass.png"), 0.8, 0.2);
    build();
    assert!(!timing_cached(&s, "terrain"));
    assert_ne!(fs::read(s.join("terrain/terrain_layers_1.png")).unwrap(), soil_before, "the soil follows the grass");
    assert!(!timing_cached(&s, "scatter"), "a changed density map must recompute the scatter");
    assert_ne!(scatter_files(&s)["placements/grass.csv"], before["placements/grass.csv"]);
    assert_eq!(scatter_files(&s)["placements/tree.csv"], before["placements/tree.csv"], "the trees do not use the map");
}

fn read_csv_bytes(bytes: &[u8]) -> usize {
    bytes.iter().filter(|&&b| b == b'\n').count() - 1
}

// --------------------------------------------------------------------------------------- hard cases

#[test]
fn max_instances_exceeded_fails_the_scene_naming_the_species_and_keeps_the_old_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &forest("a", 3));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let before = tree(&d.join("o/a"));
    write(d, "p/a.toml", &preset("a", 3, &format!("{TREE}\n{GRASS}max_instances = 1000\n")));
    let o = verdant_in(d, &["build", "p/a.toml", "--out", "o"]);
    let t = text(&o);
    // a limit the preset sets is the input's fault: exit 2
    assert_eq!(o.status.code(), Some(2), "{t}");
    assert!(t.contains("grass") && t.contains("max_instances"), "the error does not name the species and limit: {t}");
    assert!(!t.contains("panicked"), "{t}");
    assert_eq!(tree(&d.join("o/a")), before, "the failed build changed the previous output");
    let left: Vec<String> = fs::read_dir(d.join("o"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".building-") || n.contains(".old-"))
        .collect();
    assert!(left.is_empty(), "temporary folders left: {left:?}");
}

#[test]
fn a_slope_range_that_excludes_everything_writes_empty_valid_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 50 m of relief over 256 m: no slope reaches 89.5°
    let steep = GRASS.replace("placement = \"jittered\"\n", "placement = \"jittered\"\nslope = [89.5, 90.0]\n");
    write(d, "p/a.toml", &preset("a", 3, &format!("{TREE}\n{steep}")));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let s = d.join("o/a");
    assert_eq!(fs::read_to_string(s.join("placements/grass.csv")).unwrap(), format!("{HEADER}\n"));
    let json = read_json(&s.join("placements/grass.json"));
    assert_eq!(json["count"].as_u64(), Some(0));
    assert!(json["rules"]["slope"].as_u64().unwrap() > 0, "{json}");
    let scene = verdant::validate::read_scene(&s.join("scene.glb")).unwrap();
    let root = scene
        .roots
        .iter()
        .map(|&r| &scene.nodes[r])
        .find(|n| n.name == "grass")
        .expect("a grass node, even when empty");
    assert!(root.children.is_empty());
    assert!(!read_csv(&s.join("placements/tree.csv")).is_empty());
    ok(&verdant_in(d, &["validate", "o/a/scene.glb"]));
}

#[test]
fn binary_tables_hold_the_csv_rows_and_build_the_same_scene() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &forest("a", 3));
    write(
        d,
        "p/b.toml",
        &forest("a", 3).replace("[scatter]\ntile = 64.0\n", "[scatter]\ntile = 64.0\ntable = \"binary\"\n"),
    );
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "csv"]));
    ok(&verdant_in(d, &["build", "p/b.toml", "--out", "bin"]));
    let (c, b) = (d.join("csv/a"), d.join("bin/a"));
    for species in ["tree", "grass"] {
        assert!(!b.join(format!("placements/{species}.csv")).exists(), "{species}: no CSV beside the binary table");
        let csv = verdant::export::table::read_placements(&c.join(format!("placements/{species}.csv"))).unwrap();
        let bin = verdant::export::table::read_placements(&b.join(format!("placements/{species}.bin"))).unwrap();
        assert!(csv.len() > 100, "{species}: {} rows", csv.len());
        assert_eq!(bin, csv, "{species}: the binary table's rows are the CSV's, exactly");
        // the JSON header says where each array lies, and the bytes are there
        let json = read_json(&b.join(format!("placements/{species}.json")));
        let header = &json["binary"];
        assert_eq!(header["rows"].as_u64(), Some(csv.len() as u64));
        let bytes = fs::read(b.join(format!("placements/{species}.bin"))).unwrap();
        assert_eq!(header["bytes"].as_u64(), Some(bytes.len() as u64));
        let arrays = header["arrays"].as_array().unwrap();
        let offset = |name: &str| {
            arrays.iter().find(|a| a["name"] == name).unwrap_or_else(|| panic!("no array {name}"))["offset"]
                .as_u64()
                .unwrap() as usize
        };
        let last = csv.len() - 1;
        let o = offset("position") + 24 * last + 16;
        assert_eq!(f64::from_le_bytes(bytes[o..o + 8].try_into().unwrap()), csv[last].position[2]);
        let o = offset("variant") + 4 * last;
        assert_eq!(u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()), csv[last].variant);
        assert_eq!(read_json(&c.join(format!("placements/{species}.json"))).get("binary"), None);
    }
    // the scene drawn from either table is the same file
    assert_eq!(fs::read(c.join("scene.glb")).unwrap(), fs::read(b.join("scene.glb")).unwrap());
    let manifest = read_json(&b.join("manifest.json"));
    let tables: Vec<&str> =
        manifest["scatter"]["species"].as_array().unwrap().iter().map(|s| s["table"].as_str().unwrap()).collect();
    assert_eq!(tables, ["placements/tree.bin", "placements/grass.bin"]);
}

#[test]
fn a_vegetation_type_grows_only_where_the_map_holds_its_shade() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // shade 1 on the left half of the terrain (x < 128 m), shade 2 on the right
    write_density(&d.join("p/types.png"), 1.0 / 255.0, 2.0 / 255.0);
    let species = "[[species]]\nname = \"heath\"\nkind = \"mesh\"\nplacement = \"jittered\"\nmax_density = 0.05\n\
                   vegetation_type = 1\n\n\
                   [[species]]\nname = \"fern\"\nkind = \"mesh\"\nplacement = \"jittered\"\nmax_density = 0.05\n\
                   vegetation_type = 2\n";
    let text = preset("a", 3, species).replace("[scatter]\n", "[scatter]\nvegetation_map = \"types.png\"\n");
    write(d, "p/a.toml", &text);
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let s = d.join("o/a");
    // 32 pixels across 256 m: a pixel is 8 m, and a type's border softens over one
    let (heath, fern) = (read_csv(&s.join("placements/heath.csv")), read_csv(&s.join("placements/fern.csv")));
    assert!(heath.len() > 400 && fern.len() > 400, "{} heath, {} fern", heath.len(), fern.len());
    assert!(heath.iter().all(|r| r.pos[0] < 128.0 + 8.0), "heath beyond its half");
    assert!(fern.iter().all(|r| r.pos[0] > 128.0 - 8.0), "fern beyond its half");
    let mid = |rows: &[Row]| rows.iter().map(|r| r.pos[0]).sum::<f64>() / rows.len() as f64;
    assert!(mid(&heath) < 70.0 && mid(&fern) > 186.0, "{} {}", mid(&heath), mid(&fern));

    // a type without a map is refused at its key, naming the [scatter] key to add
    write(d, "p/b.toml", &preset("b", 3, species));
    let out = verdant_in(d, &["build", "p/b.toml", "--out", "o"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("vegetation_type") && err.contains("vegetation_map") && err.contains("b.toml:"), "{err}");
    // an edited map is a new scatter input
    write_density(&d.join("p/types.png"), 2.0 / 255.0, 1.0 / 255.0);
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let heath = read_csv(&s.join("placements/heath.csv"));
    assert!(heath.iter().all(|r| r.pos[0] > 128.0 - 8.0), "heath follows the edited map");
}

#[test]
fn scene_lod_glb_holds_every_row_in_tile_chains_that_switch_no_earlier_than_the_view_stage() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/a.toml", &forest("a", 3).replace("skirt = 2.0\n", "skirt = 2.0\nlods = [0.5, 2.0, 8.0]\n"));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o"]));
    let s = d.join("o/a");
    let scene = verdant::validate::read_scene(&s.join("scene_lod.glb")).expect("scene_lod.glb re-imports");
    verdant::export::check_scene(&scene).expect("scene_lod.glb is a valid scene");
    let manifest = read_json(&s.join("manifest.json"));
    assert_eq!(manifest["view"]["lod_scene"], "scene_lod.glb");
    let lod = verdant::lod::LodView::default();
    let root = |name: &str| {
        scene
            .roots
            .iter()
            .map(|&r| &scene.nodes[r])
            .find(|n| n.name == name)
            .unwrap_or_else(|| panic!("no root {name}"))
    };
    // terrain: every chunk a chain of the terrain's levels, never culled
    let terrain = root("terrain");
    assert!(terrain.children.len() > 1);
    let terrain_levels = manifest["terrain"]["lods"].as_array().unwrap().len().max(1);
    assert_eq!(terrain_levels, 3, "the preset's three terrain levels");
    for &c in &terrain.children {
        let n = &scene.nodes[c];
        assert_eq!(n.lods.len() + 1, terrain_levels, "{}", n.name);
        if terrain_levels > 1 {
            assert_eq!(n.lod_screen_coverage.last(), Some(&0.0), "{}: the terrain is never culled", n.name);
        }
    }
    for species in ["tree", "grass"] {
        let rows = read_csv(&s.join(format!("placements/{species}.csv")));
        let chain = &manifest["view"]["chains"][species];
        let pick: Vec<usize> = chain["pick"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
        let mut placed = Vec::new();
        for &c in &root(species).children {
            let base = &scene.nodes[c];
            let e = base.extras.as_ref().unwrap();
            let (tile, v) = (e["tile"].as_u64().unwrap() as u32, e["variant"].as_u64().unwrap() as usize);
            let levels = chain["variants"][v].as_array().unwrap();
            assert_eq!(base.lods.len() + 1, levels.len(), "{}", base.name);
            let inst = base.instances.as_ref().unwrap();
            // the tile's rows of this variant, in table order
            let mine: Vec<&Row> = rows.iter().filter(|r| r.tile == tile && pick[r.variant as usize] == v).collect();
            assert_eq!(inst.translations.len(), mine.len(), "{}", base.name);
            for (t, r) in inst.translations.iter().zip(&mine) {
                assert_eq!(*t, r.pos.map(|x| x as f32));
            }
            placed.extend(inst.translations.iter().copied());
            // each level: the chain's mesh, the same instances
            for (k, &l) in std::iter::once(&c).chain(&base.lods).enumerate() {
                let n = &scene.nodes[l];
                assert_eq!(scene.meshes[n.mesh.unwrap()].name, levels[k]["mesh"].as_str().unwrap(), "{}", n.name);
                assert_eq!(n.instances.as_ref(), Some(inst), "{}", n.name);
            }
            // coverage k is the tile sphere's (around the instances' centres, each within its
            // height × scale) when its nearest point is at level k+1's switch × the largest scale,
            // so no instance switches nearer than the view stage switches it; the last ends at the
            // cull distance
            let cov = &base.lod_screen_coverage;
            assert!(cov.windows(2).all(|w| w[1] <= w[0]), "{}: {cov:?}", base.name);
            let (height, centre_y) = (chain["height_m"].as_f64().unwrap(), chain["centre_y_m"].as_f64().unwrap());
            let centres: Vec<[f64; 3]> = mine
                .iter()
                .map(|r| {
                    let row = verdant::export::table::PlacementRow {
                        position: r.pos,
                        rotation: r.rot,
                        scale: r.scale,
                        yaw_deg: r.yaw,
                        tile: r.tile,
                        variant: r.variant,
                    };
                    verdant::scene::view_stage::instance_centre(&row, centre_y)
                })
                .collect();
            let mid: [f64; 3] = [0, 1, 2].map(|a| {
                let (lo, hi) =
                    centres.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), c| (l.min(c[a]), h.max(c[a])));
                0.5 * (lo + hi)
            });
            let radius = mine
                .iter()
                .zip(&centres)
                .map(|(r, c)| {
                    let d = ((c[0] - mid[0]).powi(2) + (c[1] - mid[1]).powi(2) + (c[2] - mid[2]).powi(2)).sqrt();
                    d + height * r.scale[1].max(r.scale[0]).max(r.scale[2]) as f64
                })
                .fold(0.0, f64::max);
            let scale = mine.iter().map(|r| r.scale[1] as f64).fold(0.0, f64::max);
            for k in 0..levels.len() - 1 {
                let d = levels[k + 1]["switch_distance_m"].as_f64().unwrap() * scale;
                let want = verdant::lod::lod_screen_coverage(radius, d, &lod) as f32;
                assert!(
                    (cov[k] - want).abs() <= 1e-6 * want.max(1e-6),
                    "{} level {k}: {} vs {want}",
                    base.name,
                    cov[k]
                );
            }
            assert!(*cov.last().unwrap() > 0.0, "{}: culled beyond its cull distance", base.name);
        }
        assert_eq!(placed.len(), rows.len(), "{species}: every table row is in scene_lod.glb once");
    }
}

// ------------------------------------------------------------------------------ density weight maps

#[test]
fn density_weight_maps_hold_each_species_density_on_the_terrain_layer_texels() {
    // issue 15 item 2: the species' densities as weight maps (RGBA, four species an image), on the
    // texel grid of terrain_layers.png; each channel is the density the rules leave (map, slope,
    // altitude), and the count it predicts is the analyzer's expected count
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_density(&d.join("p/maps/grass.png"), 0.0, 1.0);
    let mapped = GRASS
        .replace("placement = \"jittered\"\n", "placement = \"jittered\"\ndensity_map = \"maps/grass.png\"\n")
        .replace("exclusion = { species = \"tree\", radius = 1.5 }\n", "");
    let low = "[[species]]\nname = \"low\"\nkind = \"flower\"\nmax_density = 0.05\naltitude = [-1000.0, 20.0]\n";
    let five = (0..3)
        .map(|k| format!("[[species]]\nname = \"f{k}\"\nkind = \"flower\"\nmax_density = 0.01\nslope = [0.0, 10.0]\n"))
        .collect::<String>();
    write(d, "p/a.toml", &preset("a", 3, &format!("{TREE}\n{mapped}\n{low}\n{five}")));
    let o = verdant_in(d, &["build", "p/a.toml", "--out", "o", "--skip", "view,preview"]);
    ok(&o);
    let s = d.join("o/a");
    let r = read_json(&s.join("report.json"));
    let scatter = &r["stages"]["scatter"];
    // six species: two maps, the second with two channels in use
    let maps = scatter["density_maps"].as_array().unwrap();
    assert_eq!(maps.len(), 2, "{maps:?}");
    assert_eq!(maps[0]["species"], serde_json::json!(["tree", "grass", "low", "f0"]));
    assert_eq!(maps[1]["species"], serde_json::json!(["f1", "f2"]));
    let layers = image::open(s.join("terrain/terrain_layers.png")).unwrap();
    let img = image::open(s.join("placements/density_0.png")).unwrap().to_rgba8();
    assert_eq!((img.width(), img.height()), (layers.width(), layers.height()), "the terrain layers' texels");
    let second = image::open(s.join("placements/density_1.png")).unwrap().to_rgba8();
    assert!(second.pixels().all(|p| p.0[2] == 0 && p.0[3] == 0), "unused channels are 0");
    let listed: Vec<String> = read_json(&s.join("manifest.json"))["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["path"].as_str().unwrap().to_string())
        .collect();
    assert!(listed.iter().any(|f| f == "placements/density_1.png"), "{listed:?}");

    // grass: 0 over the map's left half, 255 over its right half (no slope or altitude limits)
    let w = img.width();
    for (x, _, p) in img.enumerate_pixels() {
        let u = (x as f64 + 0.5) / w as f64;
        if u < 0.45 {
            assert_eq!(p.0[1], 0, "grass at u = {u}");
        } else if u > 0.55 {
            assert_eq!(p.0[1], 255, "grass at u = {u}");
        }
    }
    // low: only below 20 m. The terrain's height at a texel, from its placed instances' heights:
    // every placed `low` instance lies on a texel the map says it may grow on
    let low_rows = read_csv(&s.join("placements/low.csv"));
    assert!(!low_rows.is_empty());
    let extent = 128.0 * 2.0;
    let texel = |p: [f64; 3]| {
        let x = ((p[0] / extent) * w as f64).floor().clamp(0.0, w as f64 - 1.0) as u32;
        let y = ((p[2] / extent) * img.height() as f64).floor().clamp(0.0, img.height() as f64 - 1.0) as u32;
        img.get_pixel(x, y).0
    };
    let on = low_rows.iter().filter(|r| texel(r.pos)[2] > 0).count();
    assert!(
        on as f64 >= 0.98 * low_rows.len() as f64,
        "{on} of {} low instances on texels it grows on",
        low_rows.len()
    );
    let high = img.pixels().filter(|p| p.0[2] == 0).count();
    assert!(high > 1000, "the altitude limit leaves {high} texels without `low`");

    // the count each map predicts is the analyzer's expected count (same integrand, other samples)
    for sp in scatter["species"].as_array().unwrap() {
        let dw = &sp["density_weight"];
        let (from_map, expected) =
            (dw["expected_from_map"].as_f64().unwrap(), sp["stats"]["expected"].as_f64().unwrap());
        assert!(
            (from_map - expected).abs() <= 0.03 * expected + 2.0,
            "{}: map predicts {from_map:.1}, the analyzer expects {expected:.1}",
            sp["name"]
        );
    }
}

#[test]
fn the_terrain_shows_what_grows_on_it_soil_layer_and_surface_attributes() {
    // issue 15 item 2: the species' densities drive the terrain's material layers (soil where the
    // grass leaves the gentle ground bare) and the terrain walk-through thesis' surface attributes
    // (TEXTURE, TYPE, DENSITY, SIZE) travel with the mesh as `_SURFACE`
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // grass on the map's right half; trees only on its first rows (a mask 1 where row < 8 of 16)
    write_density(&d.join("p/maps/grass.png"), 0.0, 1.0);
    let mask = ImageBuffer::from_fn(32, 16, |_, j| Luma([if j < 8 { 65535u16 } else { 0 }]));
    mask.save(d.join("p/maps/trees.png")).unwrap();
    let tree = TREE.replace("max_density = 0.01\n", "max_density = 0.01\nmask = \"maps/trees.png\"\n");
    let grass = GRASS
        .replace("placement = \"jittered\"\n", "placement = \"jittered\"\ndensity_map = \"maps/grass.png\"\n")
        .replace("exclusion = { species = \"tree\", radius = 1.5 }\n", "");
    write(d, "p/a.toml", &preset("a", 3, &format!("{tree}\n{grass}")));
    ok(&verdant_in(d, &["build", "p/a.toml", "--out", "o", "--skip", "view,preview"]));
    let s = d.join("o/a");
    let r = read_json(&s.join("report.json"));
    let layers = &r["stages"]["terrain"]["layers"];
    assert_eq!(layers["layers"], serde_json::json!(["grass", "scree", "rock", "snow", "soil"]));
    let listed = read_json(&s.join("manifest.json"))["files"].to_string();
    assert!(listed.contains("terrain/terrain_layers_1.png"), "{listed}");

    // the soil takes the gentle ground the grass leaves bare, texel for texel with the grass
    // density map the scatter stage wrote
    let first = image::open(s.join("terrain/terrain_layers.png")).unwrap().to_rgba8();
    let second = image::open(s.join("terrain/terrain_layers_1.png")).unwrap().to_rgba8();
    let density = image::open(s.join("placements/density_0.png")).unwrap().to_rgba8();
    assert_eq!(first.dimensions(), second.dimensions());
    assert_eq!(first.dimensions(), density.dimensions());
    let (mut bare, mut grown) = (0, 0);
    for ((a, b), dn) in first.pixels().zip(second.pixels()).zip(density.pixels()) {
        assert!(b.0[1] == 0 && b.0[2] == 0 && b.0[3] == 0, "only R holds a layer: {b:?}");
        let gentle = a.0[0] as f64 + b.0[0] as f64;
        let want = gentle * (1.0 - dn.0[1] as f64 / 255.0);
        assert!((b.0[0] as f64 - want).abs() <= 2.0, "soil {} for gentle {gentle}, grass density {}", b.0[0], dn.0[1]);
        if gentle > 200.0 && dn.0[1] == 0 {
            bare += 1;
        } else if gentle > 200.0 && dn.0[1] == 255 {
            grown += 1;
            assert_eq!(b.0[0], 0, "no soil under full grass");
        }
    }
    assert!(bare > 1000 && grown > 1000, "{bare} bare and {grown} grass texels of gentle ground");

    // every vertex of terrain.glb as re-read: five weights summing to 255/255 over the two
    // attributes, TEXTURE the largest, TYPE/DENSITY/SIZE those of the species covering the most
    // ground under it (trees wherever they grow; grass where alone; nothing: 0)
    let back = verdant::validate::read_scene(&s.join("terrain/terrain.glb")).unwrap();
    for p in back.meshes.iter().flat_map(|m| &m.primitives) {
        let get = |name: &str| &p.custom.iter().find(|c| c.name == name).expect(name).values;
        let (w0, w1) = (get("_LAYER_WEIGHTS"), get("_LAYER_WEIGHTS_1"));
        for ((a, b), surface) in w0.iter().zip(w1).zip(get("_SURFACE")) {
            let bytes: Vec<u32> = a.iter().chain(&b[..1]).map(|v| (v * 255.0).round() as u32).collect();
            assert_eq!(bytes.iter().sum::<u32>(), 255, "{a:?} {b:?}");
            assert_eq!(&b[1..], &[0.0; 3]);
            let top = *bytes.iter().max().unwrap();
            assert!(bytes[surface[0] as usize] + 1 >= top, "TEXTURE {} of {bytes:?}", surface[0]);
        }
    }
    let species = r["stages"]["scatter"]["species"].as_array().unwrap();
    let max_density = |k: usize| species[k]["density_weight"]["max_density"].as_f64().unwrap();
    let (w, h) = density.dimensions();
    let extent = 256.0;
    let mut seen = [0usize; 3];
    for (q, v) in surface_attribute(&back, "_SURFACE") {
        // the density map's texels whose centres surround the vertex (bilinear support)
        let fx = (q[0] as f64 / extent * w as f64 - 0.5).clamp(0.0, w as f64 - 1.0);
        let fz = (q[2] as f64 / extent * h as f64 - 0.5).clamp(0.0, h as f64 - 1.0);
        let texels: Vec<[u8; 4]> = [(0, 0), (1, 0), (0, 1), (1, 1)]
            .iter()
            .map(|(di, dj)| {
                let (i, j) = ((fx.floor() as u32 + di).min(w - 1), (fz.floor() as u32 + dj).min(h - 1));
                density.get_pixel(i, j).0
            })
            .collect();
        let pure = |c: usize, b: u8| texels.iter().all(|t| t[c] == b);
        let [texture, kind, dens, size] = v;
        assert!((0.0..5.0).contains(&texture) && texture.fract() == 0.0, "{v:?}");
        if pure(0, 255) {
            assert_eq!(kind, 1.0, "trees grow at {q:?}: {v:?}");
            assert!((dens as f64 - max_density(0)).abs() < 1e-6, "{v:?} vs {}", max_density(0));
            assert!(size > 2.0, "a tree's height {size}");
            seen[0] += 1;
        } else if pure(0, 0) && pure(1, 255) {
            assert_eq!(kind, 2.0, "grass alone at {q:?}: {v:?}");
            assert!((dens as f64 - max_density(1)).abs() < 1e-6, "{v:?} vs {}", max_density(1));
            assert!(size > 0.1 && size < 1.0, "a grass clump's height {size}");
            seen[1] += 1;
        } else if pure(0, 0) && pure(1, 0) {
            assert_eq!([kind, dens, size], [0.0; 3], "nothing grows at {q:?}");
            seen[2] += 1;
        }
    }
    assert!(seen.iter().all(|&n| n > 30), "vertices under trees, grass alone, nothing: {seen:?}");
    // the report says what covers the terrain
    let md = std::fs::read_to_string(s.join("report.md")).unwrap();
    assert!(md.contains("Material layers (") && md.contains("soil "), "{md}");
}
