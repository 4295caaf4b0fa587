//! What the fuzzers found, kept found (issue 19): each reproducer, written here by hand, goes through
//! the same `verdant::harness` entry its fuzz target runs, and through the CLI where a user meets
//! it. Then a small deterministic fuzzer of our own (seeded mutations of valid inputs) runs every
//! harness entry, so a change that brings back a panic fails here without a nightly toolchain.

use std::fs;
use std::path::Path;

use verdant::harness;
use verdant::validate::{validate_file, ValidateError, ValidateOptions};

use crate::common::*;

/// A one-triangle glTF whose JSON is patched by `edit` (the buffer is a data: URI).
fn triangle_gltf(edit: impl FnOnce(&mut serde_json::Value)) -> Vec<u8> {
    let mut v = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 0, 1]}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAAAAAAIA/"}]
    });
    edit(&mut v);
    serde_json::to_vec(&v).unwrap()
}

/// The four glTF files that made gltf-json 1.4.1 or gltf 1.4.1 panic (../shared/data/bad/
/// gltf_json_mesh_panic.glb, gltf_position_oob.gltf, gltf_image_no_mime.gltf,
/// gltf_image_no_source.gltf), rebuilt by hand: each must be a parse error naming the JSON path.
fn gltf_reproducers() -> Vec<(&'static str, Vec<u8>, &'static str)> {
    let image = |image: serde_json::Value| {
        triangle_gltf(|v| {
            v["images"] = serde_json::json!([image]);
            v["textures"] = serde_json::json!([{"source": 0}]);
        })
    };
    // a GLB whose fifth mesh names accessor 26 of 17 (the fuzzer's file, in small)
    let accessors: Vec<serde_json::Value> = (0..17)
        .map(|_| serde_json::json!({"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 0, 1]}))
        .collect();
    let meshes: Vec<serde_json::Value> = (0..5)
        .map(|m| serde_json::json!({"primitives": [{"attributes": {"POSITION": if m == 4 { 26 } else { m }}}]}))
        .collect();
    let json = serde_json::json!({
        "asset": {"version": "2.0"},
        "meshes": meshes,
        "accessors": accessors,
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "buffers": [{"byteLength": 36}]
    });
    let bin: Vec<u8> = [0f32, 0., 0., 1., 0., 0., 0., 0., 1.].iter().flat_map(|f| f.to_le_bytes()).collect();
    vec![
        (
            "mesh_panic.glb",
            glb(&json.to_string(), &bin),
            "meshes[4].primitives[0].attributes.POSITION: accessor 26 does not exist (17 accessors)",
        ),
        (
            "position_oob.gltf",
            triangle_gltf(|v| {
                v["accessors"] = serde_json::json!([]);
            }),
            "meshes[0].primitives[0].attributes.POSITION: accessor 0 does not exist (0 accessors)",
        ),
        (
            "image_no_mime.gltf",
            image(serde_json::json!({"bufferView": 0})),
            "images[0]: an image in a bufferView needs a mimeType",
        ),
        (
            "image_no_source.gltf",
            image(serde_json::json!({"name": "nothing"})),
            "images[0]: neither a uri nor a bufferView",
        ),
        (
            "morph_target_oob.gltf",
            triangle_gltf(|v| {
                v["meshes"][0]["primitives"][0]["targets"] = serde_json::json!([{"POSITION": 9}]);
            }),
            "meshes[0].primitives[0].targets[0].POSITION: accessor 9 does not exist",
        ),
    ]
}

#[test]
fn glb_files_that_made_the_gltf_crates_panic_are_positioned_parse_errors() {
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes, expected) in gltf_reproducers() {
        let path = dir.path().join(name);
        fs::write(&path, &bytes).unwrap();
        harness::gltf(&bytes);
        match validate_file(&path, &ValidateOptions::default()) {
            Err(ValidateError::Parse { problem, .. }) => {
                assert!(problem.contains(expected), "{name}: expected `{expected}` in `{problem}`")
            }
            other => panic!("{name}: expected a parse error, got {other:?}"),
        }
        // what a user sees: exit 2, the file and the JSON path named, no panic
        let o = verdant_in(dir.path(), &["validate", name]);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{name}: {t}");
        assert!(t.contains(name) && t.contains(expected) && !t.contains("panicked"), "{name}: {t}");
    }
}

#[test]
fn the_valid_triangle_still_validates() {
    // the reproducers above are one edit away from this file: it must stay valid
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("triangle.gltf");
    fs::write(&path, triangle_gltf(|_| {})).unwrap();
    let report = validate_file(&path, &ValidateOptions::default()).unwrap();
    assert!(report.ok(), "{report}");
    assert_eq!(report.meshes[0].primitives[0].vertices, 3);
}

/// ../shared/data/bad/lsystem_slow_v5.ls in essence: a rule that copies itself three times at
/// recursion 18 (3¹⁸ ≈ 3.9·10⁸ copies), which kept parse + expand + mesh busy past 10 s.
const SLOW_V5: &str = "recursion 18\nangle 10\nthickness 15\naxiom [|FFFFFFAFFFF]P>(80)'P\nrule P = [&(10)G[ccA][bcB][a][b]]tFtF(80)'P>(90)'P>(90)'P\nrule G = tFtFtFuFtFtFtFtF\n";

#[test]
fn a_self_copying_rule_is_refused_before_expanding() {
    let parsed = verdant::lsystem::parse::parse_bytes(SLOW_V5.as_bytes(), Path::new("slow.ls"), None).unwrap();
    let options = verdant::plants::tree::TreeOptions::default();
    let err = verdant::plants::tree::build_tree(&parsed.system, &options)
        .expect_err("3^18 copies are over every default budget");
    let message = err.to_string();
    assert!(message.contains("over the budget of 50000000 symbols") && message.contains("max_symbols"), "{message}");
    // refused from the counts alone: the lower bound is known before a symbol is expanded
    match verdant::lsystem::expand::fewest_symbols(&parsed.system) {
        Some(n) => assert!(n > options.max_symbols as u128, "{n}"),
        None => panic!("the lower bound of the expansion is unknown"),
    }
    harness::lsystem(SLOW_V5.as_bytes());
}

/// The lsystem target's timeout of session 37 (39 bytes, written here from its bytes): an lparser v4
/// file whose rule branches four times at recursion 6, with a stray 0xFF byte, draws 298,592
/// triangles, just within the trees' default budget of 300,000. `verdant tree` builds it in 1.3 s
/// (release); the fuzz build (AddressSanitizer, coverage) took 6.5 s alone and over libFuzzer's 10 s
/// while the machine also compiled. Not a hang: the triangle budget is what bounds it.
const BUSHY_V4: &[u8] = b"6\n30\n10\nX\nX=N[+X-X\\+X{.XcF[@-X\\+X{.\xff\n@\n";

#[test]
fn a_tree_just_within_the_default_triangle_budget_builds_and_a_lower_budget_refuses_it() {
    let parsed = verdant::lsystem::parse::parse_bytes(BUSHY_V4, Path::new("bushy.ls"), None).unwrap();
    let options = verdant::plants::tree::TreeOptions::default();
    let tree = verdant::plants::tree::build_tree(&parsed.system, &options).unwrap();
    let triangles = tree.mesh().triangle_count();
    assert!(triangles > 250_000 && triangles as u64 <= options.max_triangles, "{triangles}");
    let lower = verdant::plants::tree::TreeOptions { max_triangles: 250_000, ..options };
    let err = verdant::plants::tree::build_tree(&parsed.system, &lower).expect_err("over a 250k budget");
    assert!(err.to_string().contains("more than 250000 triangles"), "{err}");
    harness::lsystem(BUSHY_V4);
}

/// The files of ../shared/data/bad, when it is there, through their harness entries.
#[test]
fn the_shared_bad_inputs_pass_their_harness_entries() {
    let bad = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/bad");
    let Ok(entries) = fs::read_dir(&bad) else {
        eprintln!("skipped: {} is absent (the fuzzers' reproducers of ../shared)", bad.display());
        return;
    };
    let mut ran = 0;
    for entry in entries.flatten() {
        let path = entry.path();
        let bytes = fs::read(&path).unwrap();
        match path.extension().and_then(|e| e.to_str()) {
            Some("glb" | "gltf") => {
                harness::gltf(&bytes);
                let o = verdant_in(&bad, &["validate", path.to_str().unwrap()]);
                assert_eq!(o.status.code(), Some(2), "{}: {}", path.display(), text(&o));
                assert!(!text(&o).contains("panicked"), "{}", text(&o));
            }
            Some("ls") => harness::lsystem(&bytes),
            _ => continue,
        }
        ran += 1;
    }
    assert!(ran >= 5, "expected the five reproducers in {}, ran {ran}", bad.display());
}

// ---------------------------------------------------------------------------------------------
// a small fuzzer of our own: seeded mutations of valid inputs through every harness entry

/// A counter through the project's mix64: the mutations are the same on every run.
struct Stream(u64);

impl Stream {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(1);
        verdant::random::mix64(self.0)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Bytes that matter to parsers: digits, signs, brackets, separators, huge and tiny numbers.
const INTERESTING: &[&[u8]] = &[
    b"0",
    b"-1",
    b"9",
    b"1e39",
    b"-1e308",
    b"nan",
    b"inf",
    b"65535",
    b"4294967295",
    b"[",
    b"]",
    b"(",
    b")",
    b"{",
    b"}",
    b"=",
    b",",
    b"\n",
    b"\0",
    b"\xff",
    b"\"",
    b".",
    b"-0.0",
    b"99999999999",
];

fn mutate(seed: &[u8], s: &mut Stream) -> Vec<u8> {
    let mut d = seed.to_vec();
    for _ in 0..1 + s.below(4) {
        let at = s.below(d.len() + 1);
        match s.below(6) {
            0 if !d.is_empty() => {
                let k = s.below(d.len());
                d[k] ^= 1 << s.below(8);
            }
            1 if !d.is_empty() => {
                let end = (at + 1 + s.below(16)).min(d.len());
                d.drain(at.min(end)..end);
            }
            2 => {
                let token = INTERESTING[s.below(INTERESTING.len())];
                d.splice(at..at, token.iter().copied());
            }
            3 if !d.is_empty() => {
                // duplicate a span (repeated rules, sections, rows)
                let start = s.below(d.len());
                let end = (start + 1 + s.below(32)).min(d.len());
                let span = d[start..end].to_vec();
                d.splice(at..at, span);
            }
            4 => d.truncate(at),
            _ if !d.is_empty() => {
                let k = s.below(d.len());
                d[k] = s.next() as u8;
            }
            _ => d.push(s.next() as u8),
        }
    }
    d
}

thread_local! {
    static PANICS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Counts panics per thread (then reports them as before): the validator turns a panic inside the
/// glTF crates into a parse error, which must still fail these tests.
fn count_panics() {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            PANICS.with(|p| p.set(p.get() + 1));
            previous(info);
        }));
    });
}

fn run_mutations(name: &str, seeds: &[Vec<u8>], per_seed: usize, entry: fn(&[u8])) {
    count_panics();
    let mut s = Stream(0x5EED ^ name.len() as u64);
    for seed in seeds {
        let inputs =
            std::iter::once(seed.clone()).chain((0..per_seed).map(|_| mutate(seed, &mut s)).collect::<Vec<_>>());
        for input in inputs {
            let before = PANICS.with(|p| p.get());
            let outcome = std::panic::catch_unwind(|| entry(&input));
            // a panic names the input so it can be turned into a reproducer
            if outcome.is_err() || PANICS.with(|p| p.get()) != before {
                panic!("harness::{name} panicked on a mutation of a seed: {:?}", String::from_utf8_lossy(&input));
            }
        }
    }
}

fn png16(width: u32, height: u32, f: impl Fn(u32, u32) -> u16) -> Vec<u8> {
    let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(width, height, |i, j| image::Luma([f(i, j)]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

#[test]
fn mutated_lsystems_never_panic() {
    let seeds: Vec<Vec<u8>> = [
        "5\n22\n20\nA\nA=F[&+A]////[&+A]/////[&+A]\nF=!F\n@\n",
        "recursion 4\nangle 30\nthickness 10\naxiom F(2)A\nrule A = !(0.7)[&(20)F A][^(20)F A]\n",
        "recursion 3\nangle 45\ncolor 3 200 40 40\naxiom c(3)FX\nrule X = [+FX][-FX]L\nrule L = {.f.-f.-f.}\n",
        "3-2-2\nX(50)=F[+X]F[-X]\nX(50)=F[-X]+X\nF=FF\n",
        SLOW_V5,
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect();
    run_mutations("lsystem", &seeds, 120, harness::lsystem);
}

#[test]
fn mutated_heightmaps_never_panic() {
    let mut tiff = std::io::Cursor::new(Vec::new());
    let metres: Vec<f32> = (0..81).map(|k| 8800.0 + (k % 9 * (k / 9)) as f32 * 1e-3).collect();
    tiff::encoder::TiffEncoder::new(&mut tiff)
        .unwrap()
        .write_image::<tiff::encoder::colortype::Gray32Float>(9, 9, &metres)
        .unwrap();
    let seeds = vec![
        png16(17, 17, |i, j| ((i * 3000 + j * 700) % 65536) as u16),
        png16(4, 3, |i, _| if i < 2 { 0 } else { 65535 }),
        tiff.into_inner(),
        [10i16, 20, 30, 40, -32768, 60, 70, 80, 90].iter().flat_map(|v| v.to_be_bytes()).collect(),
    ];
    run_mutations("heightmap", &seeds, 150, harness::heightmap);
}

#[test]
fn mutated_presets_never_panic() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut seeds: Vec<Vec<u8>> = ["meadow", "winter_valley", "alpine"]
        .iter()
        .map(|n| fs::read(root.join(format!("presets/{n}.toml"))).unwrap())
        .collect();
    seeds.push(verdant::scene::preset::template("seed").into_bytes());
    run_mutations("preset", &seeds, 150, harness::preset);
}

#[test]
fn mutated_models_never_panic() {
    let obj = "mtllib model.mtl\no cube\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
                usemtl bark\nf 1/1 4/4 3/3 2/2\nf 5/1 6/2 7/3 8/4\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
    let mtl = "newmtl bark\nKd 0.5 0.35 0.2\nmap_Kd texture.png\n";
    let texture = png16(2, 2, |i, j| (i * 30000 + j * 20000) as u16);
    let mut cube = format!("{obj}\0{mtl}\0").into_bytes();
    cube.extend_from_slice(&texture);
    let seeds = vec![cube, b"v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 3 2\n".to_vec()];
    run_mutations("obj", &seeds, 150, harness::obj);
}

#[test]
fn mutated_gltf_files_never_panic() {
    let mut seeds: Vec<Vec<u8>> = gltf_reproducers().into_iter().map(|(_, bytes, _)| bytes).collect();
    seeds.push(triangle_gltf(|_| {}));
    // a file verdant writes: a small terrain
    let hf = verdant::heightfield::Heightfield {
        width: 9,
        height: 9,
        heights: (0..81).map(|k| (k % 7) as f32).collect(),
        cell_size_m: 1.0,
        exact: None,
    };
    let tin = verdant::terrain::tin::tin(&hf, &verdant::terrain::tin::TinOptions::default()).unwrap();
    let scene = verdant::terrain::build::build_scene(&hf, &tin.mesh, &Default::default()).unwrap();
    seeds.push(verdant::export::gltf::to_glb(&scene).unwrap());
    // the same quantized (KHR_mesh_quantization) and compressed (EXT_meshopt_compression): the
    // reader decodes meshoptimizer streams, whose C decoder must never see a shape it asserts on
    let grid = verdant::export::grid::PositionGrid::terrain(&hf, 0.0).unwrap();
    for meshopt in [false, true] {
        let opts = verdant::export::gltf::WriteOptions {
            quantization: verdant::export::quantize::Quantization::Grid(grid),
            meshopt,
            ..verdant::export::gltf::WriteOptions::default()
        };
        seeds.push(verdant::export::gltf::to_glb_with(&scene, &opts).unwrap());
    }
    run_mutations("gltf", &seeds, 150, harness::gltf);
}

#[test]
fn mutated_placement_tables_never_panic() {
    let table = "x,y,z,qx,qy,qz,qw,sx,sy,sz,yaw_deg,tile,variant\n\
                 0.5,12.25,3.0,0.0,0.38268343,0.0,0.9238795,1.0,1.0,1.0,45.0,0,0\n\
                 -0.0,1e-7,123456.789,0.0,-0.0,0.0,1.0,0.8,1.2,0.8,0.0,17,2\n\
                 8191.999,8800.001,0.001,0.0,1.0,0.0,0.0,2.5,2.5,2.5,180.0,4294967295,4294967295\n";
    run_mutations("placements", &[table.as_bytes().to_vec()], 400, harness::placements);
}

#[test]
fn mutated_binary_placement_tables_never_panic() {
    let rows = verdant::export::table::parse_placements_csv(
        "x,y,z,qx,qy,qz,qw,sx,sy,sz,yaw_deg,tile,variant\n\
         0.5,12.25,3.0,0.0,0.38268343,0.0,0.9238795,1.0,1.0,1.0,45.0,0,0\n\
         -0.0,1e-7,123456.789,0.0,-0.0,0.0,1.0,0.8,1.2,0.8,0.0,17,2\n",
    )
    .unwrap();
    let seed = verdant::export::table_bin::placements_bin(&rows).unwrap();
    run_mutations("placements_bin", &[seed], 400, harness::placements_bin);
}

// ---------------------------------------------------------------------------------------------
// what the mutations above found, kept as named cases

#[test]
fn a_colour_line_with_two_numbers_is_a_positioned_error_not_a_tobj_panic() {
    // tobj 4.0.5's parse_float3 unwraps: `Kd 0.5 0.35` aborted the whole load
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "model.obj", "mtllib model.mtl\nv 0 0 0\nv 1 0 0\nv 0 0 1\nusemtl bark\nf 1 3 2\n");
    write(dir.path(), "model.mtl", "newmtl bark\nd 1\nKd 0.5 0.35\n");
    let o = verdant_in(dir.path(), &["mesh", "model.obj", "--lods", "1", "-o", "m.glb"]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(2), "{t}");
    assert!(
        t.contains("model.mtl")
            && t.contains("line 3: `Kd` needs three numbers (r g b), found 2")
            && !t.contains("panicked"),
        "{t}"
    );
    let data = b"mtllib model.mtl\nv 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 3 2\n\0newmtl m\nKa 1\n\0";
    harness::obj(data);
}

#[test]
fn heights_beyond_a_thousand_kilometres_are_refused_with_the_sample_named() {
    // a float TIFF of 10^30 m: the TIN "met" its 1 m bound while the measure found 10^24 m
    let dir = tempfile::tempdir().unwrap();
    let mut metres = vec![100.0f32; 16];
    metres[6] = 1.0e30;
    let file = fs::File::create(dir.path().join("huge.tif")).unwrap();
    tiff::encoder::TiffEncoder::new(file)
        .unwrap()
        .write_image::<tiff::encoder::colortype::Gray32Float>(4, 4, &metres)
        .unwrap();
    let o = verdant_in(dir.path(), &["terrain", "huge.tif", "-o", "t.glb"]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(2), "{t}");
    assert!(t.contains("sample (column 2, row 1) is 1e30 m, beyond the ±1e6 m"), "{t}");
    // a gray map scaled out of range blames the scale, not the map
    let png = png16(4, 4, |i, j| (i * 1000 + j) as u16);
    fs::write(dir.path().join("gray.png"), png).unwrap();
    let o = verdant_in(dir.path(), &["terrain", "gray.png", "--height-scale", "1e39", "-o", "t.glb"]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(2), "{t}");
    assert!(t.contains("--height-scale 1e39") && !t.contains("fix or fill the map"), "{t}");
    // 9 km stays a map (the limit is far from real terrain)
    let o = verdant_in(dir.path(), &["terrain", "gray.png", "--height-scale", "9000", "-o", "t.glb"]);
    assert!(o.status.success(), "{}", text(&o));
}
