//! Terrain benchmark: greedy-insertion TIN (`verdant::terrain::tin`), the same algorithm on spade
//! (`tin_spade`, the reference for the choice of triangulation) and the `delatin` crate as an outside
//! peer, on Mt Fuji, the Puget Sound heightmap and a 2049² fractal, with the error of every output measured by
//! `verdant::terrain::error::measure`.
//!
//! Every case runs in a child process of this binary (`--case <input> <max_error_m> <impl>`) so the
//! peak memory of one build can be read from that process's VmHWM (reset after loading the input via
//! /proc/self/clear_refs). Plain `main`, no harness: `cargo bench --bench terrain` or
//! `scripts/bench_terrain.sh`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use verdant::heightfield::Heightfield;
use verdant::terrain::error::{measure, measure_exact};
use verdant::terrain::tin::{tin, tin_spade, TinOptions};
use verdant::terrain::SampleMesh;

const PUGET: &str = "heightmaps/diligent_ps_height_1k.png";
const FUJI: &str = "heightmaps/martini_fuji.png";
const FRACTAL_SEED: u64 = 0x7665_7264;
/// Reference triangle counts (reference C++ greedy-insertion mesher, PROVENANCE.md of the data set).
const PUGET_REFERENCE: &[(f64, usize)] = &[(10.0, 833_139), (50.0, 156_425), (1.0, 1_696_371)];
/// The benchmark asks for large meshes (the fractal at 1 m has 2.1 M vertices, over the default
/// work budget of 2^21): its budget is 2^26.
const BENCH_MAX_VERTICES: usize = 1 << 26;
/// Runs per case (best time kept); `VERDANT_BENCH_RUNS` overrides.
fn runs() -> usize {
    std::env::var("VERDANT_BENCH_RUNS").ok().and_then(|v| v.parse().ok()).unwrap_or(3)
}

fn data_dir() -> PathBuf {
    std::env::var_os("VERDANT_DATA").map(PathBuf::from).unwrap_or_else(|| PathBuf::from("../shared/data"))
}

/// Loads the 16-bit Puget Sound map: value · 0.1 m, 160 m between samples. Decimetres are not f32
/// values: the heights are kept exactly (f64) beside their f32 rounding, as the decoder does, so
/// the error is measured as written against the map's own heights.
fn load_puget(dir: &Path) -> Result<Heightfield, String> {
    let path = dir.join(PUGET);
    let img = image::open(&path).map_err(|e| format!("{}: {e}", path.display()))?.into_luma16();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let heights: Vec<f64> = img.into_raw().iter().map(|&v| v as f64 * 0.1).collect();
    Ok(Heightfield::from_f64(w, h, &heights, 160.0))
}

/// Mt Fuji, Terrain-RGB (0.1 m steps, exact heights kept as the decoder keeps them), 512², cells
/// of 30 m (the tile's ground resolution at zoom 10 @2x, rounded).
fn load_fuji(dir: &Path) -> Result<Heightfield, String> {
    let opts = verdant::heightfield::DecodeOptions {
        encoding: verdant::heightfield::Encoding::TerrainRgb,
        cell_size_m: 30.0,
        ..Default::default()
    };
    verdant::heightfield::load(&dir.join(FUJI), &opts).map(|d| d.heightfield).map_err(|e| e.to_string())
}

fn load(input: &str) -> Result<Heightfield, String> {
    match input {
        "puget" => load_puget(&data_dir()),
        "fuji" => load_fuji(&data_dir()),
        "fractal2049" => Ok(verdant::synth::fractal(2049, 2049, 1.0, 1000.0, 0.55, FRACTAL_SEED)),
        other => Err(format!("unknown input {other}")),
    }
}

/// (VmRSS, VmHWM) of this process in bytes.
fn memory() -> (u64, u64) {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let field = |name: &str| {
        status
            .lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse::<u64>().ok())
            .map_or(0, |kb| kb * 1024)
    };
    (field("VmRSS:"), field("VmHWM:"))
}

fn delatin_mesh(hf: &Heightfield, heights: &[f64], max_error_m: f64) -> SampleMesh {
    let (points, triangles) =
        delatin::triangulate(heights, (hf.width, hf.height), delatin::Error(max_error_m)).expect("delatin");
    SampleMesh {
        vertices: points.iter().map(|&(i, j)| [i as u32, j as u32]).collect(),
        triangles: triangles.iter().map(|&(a, b, c)| [a as u32, b as u32, c as u32]).collect(),
    }
}

/// CPU time (user + system) of this process so far, all its threads, in seconds, from /proc (10 ms
/// resolution): on a shared machine wall time includes waiting for a core, CPU time does not; a
/// mesher on two cores spends up to twice its wall time.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = stat.rsplit_once(')').map_or("", |r| r.1);
    let f: Vec<&str> = rest.split_whitespace().collect();
    match (f.get(11).and_then(|v| v.parse::<u64>().ok()), f.get(12).and_then(|v| v.parse::<u64>().ok())) {
        (Some(u), Some(s)) => (u + s) as f64 / 100.0,
        _ => f64::NAN,
    }
}

/// Child: builds one case several times, prints `triangles measured_max_error best_seconds
/// best_cpu_seconds peak_bytes build_bytes measured_f64` on one line.
fn run_case(input: &str, max_error_m: f64, which: &str) -> Result<(), String> {
    let hf = load(input)?;
    // delatin takes f64 heights (the map's own, exact ones): input preparation, not part of its build.
    let heights64: Vec<f64> =
        if which == "delatin" { (0..hf.heights.len()).map(|k| hf.reference(k)).collect() } else { Vec::new() };
    // Reset the high-water mark so it covers the builds only (plus what is already resident).
    let _ = std::fs::write("/proc/self/clear_refs", "5");
    let (rss_before, _) = memory();
    let mut best = f64::INFINITY;
    let mut best_cpu = f64::INFINITY;
    let mut peak = 0;
    let mut mesh = SampleMesh::default();
    for _ in 0..runs() {
        drop(std::mem::take(&mut mesh));
        let t = Instant::now();
        let c = cpu_seconds();
        mesh = match which {
            "verdant" => {
                tin(&hf, &TinOptions { max_error_m, max_vertices: BENCH_MAX_VERTICES, ..TinOptions::default() })
                    .map_err(|e| e.to_string())?
                    .mesh
            }
            "spade" => {
                tin_spade(&hf, &TinOptions { max_error_m, max_vertices: BENCH_MAX_VERTICES, ..TinOptions::default() })
                    .map_err(|e| e.to_string())?
                    .mesh
            }
            "delatin" => delatin_mesh(&hf, &heights64, max_error_m),
            other => return Err(format!("unknown implementation {other}")),
        };
        best = best.min(t.elapsed().as_secs_f64());
        best_cpu = best_cpu.min(cpu_seconds() - c);
        // Peak of the first build only: later runs can only add allocator fragmentation.
        if peak == 0 {
            peak = memory().1;
        }
    }
    let stats = measure(&hf, &mesh);
    if stats.samples_covered != hf.width * hf.height {
        eprintln!("warning: {which} covers {} of {} samples", stats.samples_covered, hf.width * hf.height);
    }
    let f64_error = measure_exact(&hf, &mesh).max_error_m;
    println!(
        "{} {} {} {} {} {} {}",
        mesh.triangles.len(),
        stats.max_error_m,
        best,
        best_cpu,
        peak,
        peak.saturating_sub(rss_before),
        f64_error
    );
    Ok(())
}

struct Row {
    triangles: usize,
    measured: f64,
    measured_f64: f64,
    seconds: f64,
    cpu: f64,
    peak: u64,
    build: u64,
}

fn spawn_case(input: &str, max_error_m: f64, which: &str) -> Result<Row, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let out = Command::new(exe)
        .args(["--case", input, &max_error_m.to_string(), which])
        .output()
        .map_err(|e| e.to_string())?;
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).into_owned());
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let f: Vec<&str> = text.split_whitespace().collect();
    let parse =
        |k: usize| f.get(k).and_then(|s| s.parse::<f64>().ok()).ok_or_else(|| format!("bad child output: {text}"));
    Ok(Row {
        triangles: parse(0)? as usize,
        measured: parse(1)?,
        measured_f64: parse(6)?,
        seconds: parse(2)?,
        cpu: parse(3)?,
        peak: parse(4)? as u64,
        build: parse(5)? as u64,
    })
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).filter(|a| a != "--bench").collect();
    if args.first().map(String::as_str) == Some("--case") {
        let (input, err, which) = (&args[1], &args[2], &args[3]);
        let max_error_m: f64 = err.parse().unwrap_or(1.0);
        if let Err(e) = run_case(input, max_error_m, which) {
            eprintln!("{e}");
            std::process::exit(1);
        }
        return;
    }
    // Optional filter: only cases whose input name contains the first argument; `--no-delatin` skips
    // the peer.
    let filter = args.iter().find(|a| !a.starts_with("--")).cloned().unwrap_or_default();
    let with_peer = !args.iter().any(|a| a == "--no-delatin");

    let mut cases: Vec<(&str, f64, usize)> = Vec::new();
    if data_dir().join(FUJI).exists() {
        cases.push(("fuji", 10.0, 512 * 512));
    } else {
        println!("skipping Mt Fuji: {} not found (set VERDANT_DATA)", data_dir().join(FUJI).display());
    }
    if data_dir().join(PUGET).exists() {
        cases.push(("puget", 10.0, 1025 * 1025));
        cases.push(("puget", 50.0, 1025 * 1025));
    } else {
        println!("skipping Puget Sound: {} not found (set VERDANT_DATA)", data_dir().join(PUGET).display());
    }
    cases.push(("fractal2049", 1.0, 2049 * 2049));
    cases.push(("fractal2049", 5.0, 2049 * 2049));
    cases.push(("fractal2049", 20.0, 2049 * 2049));
    cases.retain(|c| c.0.contains(&filter));

    println!(
        "peer: the delatin crate (Rust port of mapbox/delatin, greedy insertion like hmm; hmm's C++ source is on \
         no registry this machine reaches), built in this run; verdant uses both cores (regions of the map in \
         parallel, the same mesh at any thread count)"
    );
    println!(
        "best of {} runs per case, one process per case; as written = max error of the mesh with f32 vertices \
         against the map's exact heights, f64 = with exact vertices (same analyzer for every impl); seconds = \
         wall, cpu = CPU seconds of the build (10 ms resolution); peak = VmHWM during the first build (input \
         included), build = peak − RSS before",
        runs()
    );
    println!(
        "{:<12} {:>7} {:<8} {:>10} {:>12} {:>12} {:>8} {:>6} {:>8} {:>9} {:>9}",
        "input",
        "max_err",
        "impl",
        "triangles",
        "as written",
        "f64",
        "seconds",
        "cpu",
        "peak MB",
        "build MB",
        "B/sample"
    );
    for (input, err, samples) in cases {
        let mut rows: Vec<Row> = Vec::new();
        let impls: &[&str] = if with_peer { &["verdant", "spade", "delatin"] } else { &["verdant"] };
        for &which in impls {
            match spawn_case(input, err, which) {
                Ok(r) => {
                    println!(
                        "{:<12} {:>7} {:<8} {:>10} {:>12.7} {:>12.7} {:>8.3} {:>6.2} {:>8.1} {:>9.1} {:>9.1}{}",
                        input,
                        err,
                        which,
                        r.triangles,
                        r.measured,
                        r.measured_f64,
                        r.seconds,
                        r.cpu,
                        r.peak as f64 / 1048576.0,
                        r.build as f64 / 1048576.0,
                        r.build as f64 / samples as f64,
                        if r.measured > err { "  OVER the bound as written" } else { "" }
                    );
                    rows.push(r);
                }
                Err(e) => println!("{input:<12} {err:>7} {which:<8} failed: {}", e.trim()),
            }
        }
        if let (Some(ours), Some(peer)) = (rows.first(), rows.last().filter(|_| rows.len() == 3)) {
            println!(
                "{:<12} {:>7} {:<8} verdant/delatin: time {:.2} (cpu {:.2}), triangles {:.4}",
                "",
                "",
                "ratio",
                ours.seconds / peer.seconds,
                ours.cpu / peer.cpu,
                ours.triangles as f64 / peer.triangles as f64
            );
        }
        if input == "puget" {
            if let (Some(ours), Some(&(_, reference))) = (rows.first(), PUGET_REFERENCE.iter().find(|r| r.0 == err)) {
                println!(
                    "{:<12} {:>7} {:<8} reference {} triangles; verdant {:+.2} %",
                    "",
                    "",
                    "ref",
                    reference,
                    (ours.triangles as f64 / reference as f64 - 1.0) * 100.0
                );
            }
        }
    }
}
