//! Scatter benchmark: jittered grass and Poisson trees on the TIN of a 2049² fBm terrain with a
//! varied density map, in instances per second including the height lookup on the mesh and writing
//! the placement table as CSV, plus bytes of memory per instance; scipy's `qmc.PoissonDisk` on the
//! same area and radius as an outside peer (run through `.venv/bin/python` when it exists).
//!
//! Plain `main`, no harness: `cargo bench --bench scatter` or `scripts/bench_scatter.sh`.
//! `VERDANT_BENCH_RUNS` sets the runs per case (best kept, default 3); `--no-scipy` skips the peer.

use std::io::Write;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

use rayon::prelude::*;
use verdant::scatter::{scatter_species_detailed, DensityMap, Instance, SurfaceIndex, POISSON_PACKING};
use verdant::scene::{Placement, SpeciesKind, SpeciesSettings};
use verdant::terrain::tin::{tin, TinOptions};

const SIZE: usize = 2049;
const TERRAIN_SEED: u64 = 0x7665_7264;
const MAX_ERROR_M: f64 = 2.0;
const TILE_M: f64 = 256.0;

fn runs() -> usize {
    std::env::var("VERDANT_BENCH_RUNS").ok().and_then(|v| v.parse().ok()).unwrap_or(3)
}

/// (VmRSS, VmHWM) in bytes.
fn memory() -> (u64, u64) {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let field = |name: &str| {
        status.lines().find(|l| l.starts_with(name)).and_then(|l| l.split_whitespace().nth(1)).and_then(|v| v.parse::<u64>().ok()).map_or(0, |kb| kb * 1024)
    };
    (field("VmRSS:"), field("VmHWM:"))
}

/// Resets VmHWM to the current RSS (Linux ≥ 4.0), so the next peak is this case's.
fn reset_peak() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

fn species(name: &str, placement: Placement, max_density: f64, min_spacing_m: f64) -> SpeciesSettings {
    SpeciesSettings {
        name: name.into(),
        kind: SpeciesKind::Grass,
        density_map: None,
        mask: None,
        max_density,
        placement,
        min_spacing_m,
        slope_deg: [0.0, 60.0],
        altitude_m: [-1e9, 1e9],
        water_level_m: None,
        scale: [0.8, 1.2],
        random_yaw: true,
        align_to_normal: if placement == Placement::Jittered { 1.0 } else { 0.0 },
        exclusions: vec![],
        seed: 0,
        max_instances: 100_000_000,
    }
}

/// "00" … "99": two digits per division.
const PAIRS: &[u8; 200] = b"00010203040506070809101112131415161718192021222324252627282930313233343536373839404142434445464748495051525354555657585960616263646566676869707172737475767778798081828384858687888990919293949596979899";

/// Appends `v` with `decimals` fixed decimals (rounded half away from zero) by integer formatting
/// (two digits at a time), several times faster than `{:.3}`, so writing keeps up with generating.
#[inline]
fn push_fixed(out: &mut Vec<u8>, v: f64, decimals: u32) {
    let scale = 10u64.pow(decimals);
    let m = (v.abs() * scale as f64 + 0.5) as u64; // truncation of a positive value: round half up
    if !v.is_finite() || m > 1 << 62 {
        let _ = write!(out, "{v}");
        return;
    }
    if v < 0.0 && m != 0 {
        out.push(b'-');
    }
    let mut buf = [0u8; 24];
    let mut k = buf.len();
    let mut frac = m % scale;
    let mut d = decimals;
    while d >= 2 {
        let p = (frac % 100) as usize * 2;
        k -= 2;
        buf[k..k + 2].copy_from_slice(&PAIRS[p..p + 2]);
        frac /= 100;
        d -= 2;
    }
    if d == 1 {
        k -= 1;
        buf[k] = b'0' + (frac % 10) as u8;
    }
    if decimals > 0 {
        k -= 1;
        buf[k] = b'.';
    }
    let mut int = m / scale;
    while int >= 100 {
        let p = (int % 100) as usize * 2;
        k -= 2;
        buf[k..k + 2].copy_from_slice(&PAIRS[p..p + 2]);
        int /= 100;
    }
    if int >= 10 {
        let p = int as usize * 2;
        k -= 2;
        buf[k..k + 2].copy_from_slice(&PAIRS[p..p + 2]);
    } else {
        k -= 1;
        buf[k] = b'0' + int as u8;
    }
    out.extend_from_slice(&buf[k..]);
}

/// The placement table: x, y, z, qx, qy, qz, qw, sx, sy, sz, yaw_deg, tile — formatted in parallel
/// chunks (returned, in order).
fn format_csv(instances: &[Instance]) -> Vec<Vec<u8>> {
    instances
        .par_chunks(1 << 16)
        .map(|chunk| {
            let mut out = Vec::with_capacity(chunk.len() * 96);
            for i in chunk {
                for v in &i.position {
                    push_fixed(&mut out, *v, 3);
                    out.push(b',');
                }
                for v in i.rotation {
                    push_fixed(&mut out, v as f64, 6);
                    out.push(b',');
                }
                for v in i.scale {
                    push_fixed(&mut out, v as f64, 4);
                    out.push(b',');
                }
                push_fixed(&mut out, i.yaw_deg as f64, 2);
                out.push(b',');
                push_fixed(&mut out, i.tile as f64, 0);
                out.push(b'\n');
            }
            out
        })
        .collect()
}

/// Writes the formatted chunks after the header.
fn write_csv(path: &Path, chunks: &[Vec<u8>]) -> std::io::Result<u64> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    f.write_all(b"x,y,z,qx,qy,qz,qw,sx,sy,sz,yaw_deg,tile\n")?;
    let mut bytes = 0;
    for c in chunks {
        f.write_all(c)?;
        bytes += c.len() as u64;
    }
    f.flush()?;
    Ok(bytes)
}

struct Row {
    case: String,
    instances: usize,
    candidates: u64,
    generate_s: f64,
    format_s: f64,
    write_s: f64,
    csv_bytes: u64,
    peak_bytes: u64,
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let no_scipy = args.iter().any(|a| a == "--no-scipy");
    let threads = rayon::current_num_threads();
    println!("scatter benchmark: {SIZE}² fBm terrain (1 m cells), TIN at {MAX_ERROR_M} m, tiles of {TILE_M} m, {threads} threads");

    let t = Instant::now();
    let hf = verdant::synth::fbm(SIZE, 1.0, 400.0, TERRAIN_SEED);
    let mesh = tin(&hf, &TinOptions { max_error_m: MAX_ERROR_M, max_triangles: None }).expect("tin").mesh;
    let positions: Vec<[f32; 3]> = mesh.vertices.iter().map(|&[i, j]| hf.position(i as usize, j as usize)).collect();
    let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    drop(hf);
    let ts = Instant::now();
    let surface = SurfaceIndex::new(&positions, &indices);
    let index_s = ts.elapsed().as_secs_f64();
    println!(
        "terrain + TIN: {:.2} s, {} triangles; surface index: {:.3} s, bucket {:.2} m",
        t.elapsed().as_secs_f64() - index_s,
        surface.triangle_count(),
        index_s,
        surface.bucket_size()
    );
    let side = (SIZE - 1) as f64;
    let extent = [0.0, 0.0, side, side];
    // a varied density map: its own fBm, 512², contrast-stretched so large areas are near 0 and near 1
    let dm = verdant::synth::fbm(512, 1.0, 1.0, 0xde75);
    let density = DensityMap::from_fn(512, 512, |i, j| ((dm.at(i, j) - 0.25) * 2.0).clamp(0.0, 1.0));
    let mean = density.values.iter().map(|&v| v as f64).sum::<f64>() / density.values.len() as f64;
    println!("density map: 512², mean {mean:.3}");

    let tmp = std::env::temp_dir().join(format!("verdant_bench_scatter_{}.csv", std::process::id()));
    let cases = [
        ("jittered grass, 4/m²", species("grass", Placement::Jittered, 4.0, 0.0)),
        ("poisson trees, r = 4 m", species("trees", Placement::Poisson, 1.0, 4.0)),
        ("poisson trees, r = 3 m", species("trees", Placement::Poisson, 1.0, 3.0)),
    ];
    // `--case k`: run case k only and print its row as numbers (the parent's child process), so
    // VmHWM is this case's own peak and not memory the allocator kept from an earlier case
    if let Some(k) = args.iter().position(|a| a == "--case").and_then(|p| args.get(p + 1)).and_then(|v| v.parse::<usize>().ok()) {
        let (name, sp) = &cases[k];
        let mut best: Option<Row> = None;
        for _ in 0..runs() {
            reset_peak();
            let (rss0, _) = memory();
            let t = Instant::now();
            let out = scatter_species_detailed(&surface, extent, sp, Some(&density), None, &[], TILE_M, 1).expect("scatter");
            let generate_s = t.elapsed().as_secs_f64();
            let t = Instant::now();
            let chunks = format_csv(&out.instances);
            let format_s = t.elapsed().as_secs_f64();
            let t = Instant::now();
            let csv_bytes = write_csv(&tmp, &chunks).expect("csv");
            let write_s = t.elapsed().as_secs_f64();
            drop(chunks);
            let (_, hwm) = memory();
            let row = Row {
                case: name.to_string(),
                instances: out.instances.len(),
                candidates: out.counts.candidates,
                generate_s,
                format_s,
                write_s,
                csv_bytes,
                peak_bytes: hwm.saturating_sub(rss0),
            };
            drop(out);
            if best.as_ref().is_none_or(|b| row.generate_s + row.format_s < b.generate_s + b.format_s) {
                best = Some(row);
            }
        }
        let r = best.expect("at least one run");
        let _ = std::fs::remove_file(&tmp);
        println!("ROW {} {} {} {} {} {} {} {}", r.instances, r.candidates, r.generate_s, r.format_s, r.write_s, r.csv_bytes, r.peak_bytes, name);
        return;
    }
    let mut rows = Vec::new();
    for k in 0..cases.len() {
        let out = Command::new(std::env::current_exe().expect("own path")).args(["--case", &k.to_string()]).output().expect("child");
        let text = String::from_utf8_lossy(&out.stdout);
        let Some(line) = text.lines().find(|l| l.starts_with("ROW ")) else {
            println!("case {k} failed: {}", String::from_utf8_lossy(&out.stderr));
            continue;
        };
        let f: Vec<&str> = line.splitn(9, ' ').collect();
        let num = |i: usize| f[i].parse::<f64>().unwrap_or(f64::NAN);
        rows.push(Row {
            case: f[8].to_string(),
            instances: num(1) as usize,
            candidates: num(2) as u64,
            generate_s: num(3),
            format_s: num(4),
            write_s: num(5),
            csv_bytes: num(6) as u64,
            peak_bytes: num(7) as u64,
        });
    }

    println!();
    println!("| case | instances | candidates | generate s | CSV format s | file write s | M inst/s gen | M inst/s gen + format | M inst/s gen + format + write | CSV MB | peak B/inst |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in &rows {
        let rate = |s: f64| r.instances as f64 / s / 1e6;
        println!(
            "| {} | {} | {} | {:.3} | {:.3} | {:.3} | {:.2} | {:.2} | {:.2} | {:.1} | {:.0} |",
            r.case,
            r.instances,
            r.candidates,
            r.generate_s,
            r.format_s,
            r.write_s,
            rate(r.generate_s),
            rate(r.generate_s + r.format_s),
            rate(r.generate_s + r.format_s + r.write_s),
            r.csv_bytes as f64 / 1e6,
            r.peak_bytes as f64 / r.instances.max(1) as f64
        );
    }
    println!(
        "(Instance = {} bytes in memory; peak B/inst = growth of the peak RSS during generate + format + write, each case in its own process, over instances; the formatted CSV is held in memory before writing)",
        std::mem::size_of::<Instance>()
    );

    // the outside peer: scipy's Bridson on the same area and radius, unthinned (density 1)
    if no_scipy {
        return;
    }
    let python = Path::new(".venv/bin/python");
    if !python.exists() {
        println!("\nscipy peer skipped: .venv/bin/python not found (python3 -m venv .venv && .venv/bin/pip install scipy numpy)");
        return;
    }
    let r = 4.0;
    let ours = {
        let sp = species("trees", Placement::Poisson, 1.0, r);
        let mut best = f64::INFINITY;
        let mut n = 0;
        for _ in 0..runs() {
            let t = Instant::now();
            n = scatter_species_detailed(&surface, extent, &sp, None, None, &[], TILE_M, 1).expect("scatter").instances.len();
            best = best.min(t.elapsed().as_secs_f64());
        }
        (n, best)
    };
    let script = format!(
        "import time\nfrom scipy.stats import qmc\neng = qmc.PoissonDisk(d=2, radius={}, seed=1)\nt = time.perf_counter()\np = eng.fill_space()\nprint(len(p), time.perf_counter() - t)\n",
        r / side
    );
    println!("\nscipy peer: qmc.PoissonDisk(radius = {r} m over {side} m × {side} m).fill_space() (≈ a minute) …");
    match Command::new(python).arg("-c").arg(&script).output() {
        Ok(o) if o.status.success() => {
            let text = String::from_utf8_lossy(&o.stdout);
            let mut it = text.split_whitespace();
            let n: f64 = it.next().and_then(|v| v.parse().ok()).unwrap_or(0.0);
            let s: f64 = it.next().and_then(|v| v.parse().ok()).unwrap_or(f64::NAN);
            println!("| sampler | points | seconds | points/s | points per r² |");
            println!("|---|---:|---:|---:|---:|");
            let area = side * side / (r * r);
            println!("| verdant poisson (uniform density, on the TIN, slope ≤ 60°) | {} | {:.3} | {:.0} | {:.3} |", ours.0, ours.1, ours.0 as f64 / ours.1, ours.0 as f64 / area);
            println!("| scipy qmc.PoissonDisk (unit square, 1 thread) | {n} | {s:.3} | {:.0} | {:.3} |", n / s, n / area);
            println!("speed ratio verdant / scipy: {:.0}× (verdant packing constant {POISSON_PACKING}/r²)", (ours.0 as f64 / ours.1) / (n / s));
        }
        Ok(o) => println!("scipy peer failed: {}", String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("")),
        Err(e) => println!("scipy peer skipped: {e}"),
    }
}
