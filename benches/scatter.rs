//! Scatter benchmark: jittered grass and Poisson trees on the TIN of a 2049² fBm terrain with a
//! varied density map, in instances per second including the height lookup on the mesh and writing
//! the placement table, plus bytes of memory per instance; scipy's `qmc.PoissonDisk` on the same
//! area and radius as an outside peer (run through `.venv/bin/python` when it exists).
//!
//! It measures the product's path: `scatter::scatter_species_detailed`, then the instances
//! written as the scene build writes them, `export::table::placements_csv` (in memory) or
//! `write_placements_csv` (the file), and the analyzer (`scatter::analyze`) once per case. Each stage is reported as its best
//! wall time over the runs with the CPU time (all threads) of that run: the machine is shared and
//! noisy, so CPU ≈ 2 × wall means both cores were ours, CPU ≈ wall means we got about one.
//! Each case runs in its own process (its own peak RSS) and prints a digest of its placements and
//! rule counts, which must not change unless a commit says why.
//!
//! Then each case placed by tile rows alone (`scatter_species_in_rows`, a shard's rows) in 2, 4
//! and 8 runs: the work a split adds and the slowest run, and whether the joined runs are the
//! whole run.
//!
//! Plain `main`, no harness: `cargo bench --bench scatter` or `scripts/bench_scatter.sh`.
//! `VERDANT_BENCH_RUNS` sets the runs per case (best kept, default 3); `--no-scipy` skips the peer.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use verdant::export::table::{placements_csv, write_placements_csv};
use verdant::scatter::{
    analyze, scatter_species_detailed, scatter_species_in_rows, DensityMap, Instance, SurfaceIndex, POISSON_PACKING,
};
use verdant::scatter::{Placement, SpeciesRules};
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
        status
            .lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse::<u64>().ok())
            .map_or(0, |kb| kb * 1024)
    };
    (field("VmRSS:"), field("VmHWM:"))
}

/// Resets VmHWM to the current RSS (Linux ≥ 4.0), so the next peak is this case's.
fn reset_peak() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

fn species(name: &str, placement: Placement, max_density: f64, min_spacing_m: f64) -> SpeciesRules {
    SpeciesRules {
        name: name.into(),
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

/// CPU seconds of this process (all threads, user + system) from /proc/self/stat, in clock ticks
/// (10 ms); the machine is shared, so CPU time next to wall time shows how much we were stolen.
fn cpu_s() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // fields after the parenthesised command: state is field 3, utime 14, stime 15
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<u64> = rest.split_whitespace().map(|v| v.parse().unwrap_or(0)).collect();
    f.get(11).zip(f.get(12)).map_or(f64::NAN, |(u, s)| (u + s) as f64 / 100.0)
}

/// Wall and CPU seconds of `f`.
fn timed<T>(f: impl FnOnce() -> T) -> (T, f64, f64) {
    let (t, c) = (Instant::now(), cpu_s());
    let v = f();
    (v, t.elapsed().as_secs_f64(), cpu_s() - c)
}

/// FNV-1a over every instance's bits and the rule counts: the placements must not change unless a
/// commit says why.
fn instances_digest(s: &verdant::scatter::Scatter) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |v: u64| h = (h ^ v).wrapping_mul(0x0100_0000_01b3);
    for i in &s.instances {
        i.position.iter().for_each(|v| eat(v.to_bits()));
        i.rotation.iter().chain(&i.scale).chain([&i.yaw_deg]).for_each(|v| eat(v.to_bits() as u64));
        eat(i.tile as u64);
    }
    let c = &s.counts;
    [c.candidates, c.density, c.mask, c.off_surface, c.water, c.altitude, c.slope, c.exclusion, c.placed]
        .iter()
        .for_each(|&v| eat(v));
    h
}

/// One case: best wall time of each stage over the runs (stages independently), with the CPU
/// time of that same run.
struct Row {
    case: String,
    instances: usize,
    candidates: u64,
    generate_s: f64,
    generate_cpu: f64,
    /// rows + `placements_csv` (in memory)
    format_s: f64,
    format_cpu: f64,
    /// rows + `write_placements_csv` (format and write the file, atomically, as the product does)
    write_s: f64,
    write_cpu: f64,
    csv_bytes: u64,
    peak_bytes: u64,
    /// generate + write of one and the same run (the target's figure): best and median over the runs
    total_best_s: f64,
    total_median_s: f64,
}

const ROW_FIELDS: usize = 13;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let no_scipy = args.iter().any(|a| a == "--no-scipy");
    let threads = rayon::current_num_threads();
    let load = std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next().map(str::to_string))
        .unwrap_or_default();
    println!("scatter benchmark: {SIZE}² fBm terrain (1 m cells), TIN at {MAX_ERROR_M} m, tiles of {TILE_M} m, {threads} threads");

    let t = Instant::now();
    let hf = verdant::synth::fbm(SIZE, 1.0, 400.0, TERRAIN_SEED);
    let mesh = tin(&hf, &TinOptions { max_error_m: MAX_ERROR_M, max_triangles: None, ..TinOptions::default() })
        .expect("tin")
        .mesh;
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
    let zero = density.values.iter().filter(|&&v| v <= 0.0).count() as f64 / density.values.len() as f64;
    println!("density map: 512², mean {mean:.3}, {:.1} % of pixels 0", zero * 100.0);

    let tmp = std::env::temp_dir().join(format!("verdant_bench_scatter_{}.csv", std::process::id()));
    let cases = [
        ("jittered grass, 4/m²", species("grass", Placement::Jittered, 4.0, 0.0)),
        ("poisson trees, r = 4 m", species("trees", Placement::Poisson, 1.0, 4.0)),
        ("poisson trees, r = 3 m", species("trees", Placement::Poisson, 1.0, 3.0)),
    ];
    // `--case k`: run case k only and print its row as numbers (the parent's child process), so
    // VmHWM is this case's own peak and not memory the allocator kept from an earlier case
    if let Some(k) =
        args.iter().position(|a| a == "--case").and_then(|p| args.get(p + 1)).and_then(|v| v.parse::<usize>().ok())
    {
        let (name, sp) = &cases[k];
        let mut best: Option<Row> = None;
        let mut totals = Vec::new();
        let mut digest = None;
        for _ in 0..runs() {
            reset_peak();
            let (rss0, _) = memory();
            let (out, generate_s, generate_cpu) = timed(|| {
                scatter_species_detailed(&surface, extent, sp, Some(&density), None, &[], TILE_M, 1).expect("scatter")
            });
            // the product's path first (its peak is the case's memory), then the in-memory table;
            // the previous run's file is removed first: the product writes into a fresh build folder,
            // and replacing a 0.9 GB file would time the kernel freeing its pages
            let _ = std::fs::remove_file(&tmp);
            let ((), write_s, write_cpu) = timed(|| write_placements_csv(&tmp, &out.instances).expect("write"));
            let (_, hwm) = memory();
            let (csv_bytes, format_s, format_cpu) = timed(|| placements_csv(&out.instances).expect("csv").len() as u64);
            if digest.is_none() {
                digest = Some(instances_digest(&out));
            }
            let row = Row {
                case: name.to_string(),
                instances: out.instances.len(),
                candidates: out.counts.candidates,
                generate_s,
                generate_cpu,
                format_s,
                format_cpu,
                write_s,
                write_cpu,
                csv_bytes,
                peak_bytes: hwm.saturating_sub(rss0),
                total_best_s: generate_s + write_s,
                total_median_s: f64::NAN,
            };
            totals.push(generate_s + write_s);
            println!("RUN {name}: generate {generate_s:.3} ({generate_cpu:.2}) + format and write {write_s:.3} ({write_cpu:.2}) = {:.3} s, {:.2} M inst/s; in-memory table {format_s:.3} ({format_cpu:.2})", generate_s + write_s, out.instances.len() as f64 / (generate_s + write_s) / 1e6);
            drop(out);
            best = Some(match best {
                None => row,
                Some(b) => {
                    let pick = |x: (f64, f64), y: (f64, f64)| if x.0 <= y.0 { x } else { y };
                    let g = pick((b.generate_s, b.generate_cpu), (row.generate_s, row.generate_cpu));
                    let f = pick((b.format_s, b.format_cpu), (row.format_s, row.format_cpu));
                    let w = pick((b.write_s, b.write_cpu), (row.write_s, row.write_cpu));
                    Row {
                        generate_s: g.0,
                        generate_cpu: g.1,
                        format_s: f.0,
                        format_cpu: f.1,
                        write_s: w.0,
                        write_cpu: w.1,
                        peak_bytes: b.peak_bytes.min(row.peak_bytes),
                        ..row
                    }
                }
            });
        }
        let mut r = best.expect("at least one run");
        totals.sort_by(f64::total_cmp);
        r.total_best_s = totals[0];
        r.total_median_s = if totals.len() % 2 == 1 {
            totals[totals.len() / 2]
        } else {
            0.5 * (totals[totals.len() / 2 - 1] + totals[totals.len() / 2])
        };
        let _ = std::fs::remove_file(&tmp);
        println!("DIGEST {:016x} {name}", digest.unwrap_or(0));
        // the analyzer, as every build runs it (its height check samples at most 2^19 instances)
        let out =
            scatter_species_detailed(&surface, extent, sp, Some(&density), None, &[], TILE_M, 1).expect("scatter");
        let t = Instant::now();
        let stats =
            analyze(&surface, extent, sp, Some(&density), None, None, &out.instances, TILE_M, 0.0).expect("analyze");
        println!(
            "ANALYZE {name}: {:.3} s for {} instances; height checked on {} ({} off the mesh): max |y − terrain| {:.2e} m as scene.glb stores it (f32), {:.2e} m in the CSV (f64)",
            t.elapsed().as_secs_f64(),
            out.instances.len(),
            stats.height_checked,
            stats.off_surface,
            stats.max_height_error_m,
            stats.max_height_error_csv_m
        );
        println!(
            "ROW {} {} {} {} {} {} {} {} {} {} {} {} {}",
            r.instances,
            r.candidates,
            r.generate_s,
            r.generate_cpu,
            r.format_s,
            r.format_cpu,
            r.write_s,
            r.write_cpu,
            r.csv_bytes,
            r.peak_bytes,
            r.total_best_s,
            r.total_median_s,
            name
        );
        return;
    }
    let mut rows = Vec::new();
    let mut analyzer_lines = Vec::new();
    let mut run_lines = Vec::new();
    for k in 0..cases.len() {
        let out = Command::new(std::env::current_exe().expect("own path"))
            .args(["--case", &k.to_string()])
            .output()
            .expect("child");
        let text = String::from_utf8_lossy(&out.stdout);
        analyzer_lines.extend(text.lines().filter_map(|l| l.strip_prefix("ANALYZE ")).map(str::to_string));
        run_lines.extend(text.lines().filter_map(|l| l.strip_prefix("RUN ")).map(str::to_string));
        let Some(line) = text.lines().find(|l| l.starts_with("ROW ")) else {
            println!("case {k} failed: {}", String::from_utf8_lossy(&out.stderr));
            continue;
        };
        let f: Vec<&str> = line.splitn(ROW_FIELDS + 1, ' ').collect();
        let num = |i: usize| f[i].parse::<f64>().unwrap_or(f64::NAN);
        rows.push(Row {
            case: f[ROW_FIELDS].to_string(),
            instances: num(1) as usize,
            candidates: num(2) as u64,
            generate_s: num(3),
            generate_cpu: num(4),
            format_s: num(5),
            format_cpu: num(6),
            write_s: num(7),
            write_cpu: num(8),
            csv_bytes: num(9) as u64,
            peak_bytes: num(10) as u64,
            total_best_s: num(11),
            total_median_s: num(12),
        });
    }

    println!();
    println!("best of {} runs per stage (wall s; CPU s of all threads in parentheses; shared machine, load average at start {load})", runs());
    println!("| case | instances | candidates | generate s | + CSV format s | format + write file s | M inst/s gen | M inst/s gen + format | M inst/s gen + format + write | CSV MB | CSV B/inst | peak B/inst |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in &rows {
        let rate = |s: f64| r.instances as f64 / s / 1e6;
        println!(
            "| {} | {} | {} | {:.3} ({:.2}) | {:.3} ({:.2}) | {:.3} ({:.2}) | {:.2} | {:.2} | {:.2} | {:.1} | {:.1} | {:.0} |",
            r.case,
            r.instances,
            r.candidates,
            r.generate_s,
            r.generate_cpu,
            r.format_s,
            r.format_cpu,
            r.write_s,
            r.write_cpu,
            rate(r.generate_s),
            rate(r.generate_s + r.format_s),
            rate(r.generate_s + r.write_s),
            r.csv_bytes as f64 / 1e6,
            r.csv_bytes as f64 / r.instances.max(1) as f64,
            r.peak_bytes as f64 / r.instances.max(1) as f64
        );
    }
    // issue 4's targets, on the gen + format + write rate (wall; and per CPU-second × 2 cores,
    // what the same work gives when both cores are ours)
    for r in &rows {
        let target = if r.case.starts_with("jittered") { 5.0 } else { 0.5 };
        let wall = r.instances as f64 / (r.generate_s + r.write_s) / 1e6;
        let cpu2 = r.instances as f64 / ((r.generate_cpu + r.write_cpu) / 2.0) / 1e6;
        let (best, median) = (r.instances as f64 / r.total_best_s / 1e6, r.instances as f64 / r.total_median_s / 1e6);
        println!(
            "target {}: ≥ {target} M inst/s incl. writing — {wall:.2} M/s wall from the best stages ({}); one run's generate + write: best {best:.2}, median {median:.2} M/s over {} runs; {cpu2:.2} M/s from CPU time on 2 cores",
            r.case,
            if wall >= target { "met" } else { "not met" },
            runs()
        );
    }
    println!(
        "(the product path: scatter_species_detailed, then the instances → export::table::placements_csv (shortest round-trip floats, no copy of the instances), and + write_placements_csv (format + atomic write to {}, page cache, no fsync); Instance = {} bytes in memory; peak B/inst = lowest growth of the peak RSS during one run's generate + write (the product path; the in-memory table is measured after), each case in its own process, over instances)",
        std::env::temp_dir().display(),
        std::mem::size_of::<Instance>()
    );

    println!();
    println!("every run, in order (wall s, CPU s in parentheses; the first run of a process also pays for memory the machine has not handed out before):");
    for l in &run_lines {
        println!("run, {l}");
    }
    println!();
    for l in &analyzer_lines {
        println!("analyzer, {l}");
    }

    rows_table(&surface, extent, &density, &cases);

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
            n = scatter_species_detailed(&surface, extent, &sp, None, None, &[], TILE_M, 1)
                .expect("scatter")
                .instances
                .len();
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
            println!(
                "| verdant poisson (uniform density, on the TIN, slope ≤ 60°) | {} | {:.3} | {:.0} | {:.3} |",
                ours.0,
                ours.1,
                ours.0 as f64 / ours.1,
                ours.0 as f64 / area
            );
            println!(
                "| scipy qmc.PoissonDisk (unit square, 1 thread) | {n} | {s:.3} | {:.0} | {:.3} |",
                n / s,
                n / area
            );
            println!(
                "speed ratio verdant / scipy: {:.0}× (verdant packing constant {POISSON_PACKING}/r²)",
                (ours.0 as f64 / ours.1) / (n / s)
            );
        }
        Ok(o) => println!("scipy peer failed: {}", String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("")),
        Err(e) => println!("scipy peer skipped: {e}"),
    }
}

/// Placing tile rows alone (a shard's rows, `scatter_species_in_rows`): each case split into N
/// runs over consecutive tile rows, run one after another; the sum of their best wall times
/// against the whole run's (the work a split adds: Poisson runs fill the block rows beside
/// theirs again and thin one more each side) and the slowest run's (the wall time of N machines),
/// and whether the joined runs are the whole run's instances and counts.
fn rows_table(surface: &SurfaceIndex, extent: [f64; 4], density: &DensityMap, cases: &[(&str, SpeciesRules)]) {
    let rows = ((extent[3] - extent[1]) / TILE_M).ceil() as u32;
    let best = |f: &dyn Fn() -> verdant::scatter::Scatter| {
        let mut out = None;
        let mut best = f64::INFINITY;
        for _ in 0..runs() {
            let t = Instant::now();
            let s = f();
            best = best.min(t.elapsed().as_secs_f64());
            out = Some(s);
        }
        (out.expect("a run"), best)
    };
    println!();
    println!("tile rows placed alone ({rows} rows of {TILE_M} m): N runs over consecutive rows, one after another, best of {} runs each", runs());
    println!("| case | N | whole s | sum of runs s | sum / whole | slowest run s | whole / slowest | identical |");
    println!("|---|---:|---:|---:|---:|---:|---:|---|");
    for (name, sp) in cases {
        let (whole, whole_s) = best(&|| {
            scatter_species_detailed(surface, extent, sp, Some(density), None, &[], TILE_M, 1).expect("scatter")
        });
        for n in [2u32, 4, 8] {
            let (mut joined, mut counts) = (Vec::new(), verdant::scatter::RuleCounts::default());
            let (mut sum, mut slowest) = (0.0f64, 0.0f64);
            for k in 0..n {
                let range = [k * rows / n, (k + 1) * rows / n];
                let (run, s) = best(&|| {
                    scatter_species_in_rows(surface, extent, sp, Some(density), None, &[], TILE_M, 1, None, Some(range))
                        .expect("scatter rows")
                });
                sum += s;
                slowest = slowest.max(s);
                joined.extend(run.instances);
                counts.add(&run.counts);
            }
            let same = joined == whole.instances && counts == whole.counts;
            println!(
                "| {name} | {n} | {whole_s:.3} | {sum:.3} | {:.2} | {slowest:.3} | {:.2} | {} |",
                sum / whole_s,
                whole_s / slowest,
                if same { "yes" } else { "NO" }
            );
        }
    }
}
