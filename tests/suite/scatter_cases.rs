//! The hard cases of the scatter issue (#4), one test each: instances on the real TIN surface,
//! spacing across tile borders, density fidelity in constant-density regions, determinism across
//! runs and thread counts, degenerate density maps, spacing larger than the terrain, rules that
//! exclude everything, exclusions, limits, water/altitude and masks.

use proptest::prelude::*;
use verdant::scatter::{
    analyze, expected_count, scatter_species, scatter_species_detailed, stats::min_pair_distance, DensityMap, Instance,
    ScatterError, SurfaceIndex, POISSON_PACKING,
};
use verdant::scatter::{Exclusion, Placement, SpeciesRules};
use verdant::terrain::tin::{tin, TinOptions};

struct Terrain {
    positions: Vec<[f32; 3]>,
    indices: Vec<u32>,
    surface: SurfaceIndex,
    extent: [f64; 4],
}

/// An fBm heightfield (`size`² samples, 1 m apart), its greedy TIN at `max_error_m`, and the index.
fn terrain(size: usize, relief_m: f64, max_error_m: f64) -> Terrain {
    let hf = verdant::synth::fbm(size, 1.0, relief_m, 0x5ca7);
    let mesh = tin(&hf, &TinOptions { max_error_m, max_triangles: None, ..TinOptions::default() }).unwrap().mesh;
    let positions: Vec<[f32; 3]> = mesh.vertices.iter().map(|&[i, j]| hf.position(i as usize, j as usize)).collect();
    let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let surface = SurfaceIndex::new(&positions, &indices);
    let side = (size - 1) as f64;
    Terrain { positions, indices, surface, extent: [0.0, 0.0, side, side] }
}

fn species(name: &str, placement: Placement) -> SpeciesRules {
    SpeciesRules {
        name: name.into(),
        density_map: None,
        mask: None,
        max_density: 1.0,
        placement,
        // jittered placement keeps no spacing and refuses one
        min_spacing_m: if placement == Placement::Poisson { 1.0 } else { 0.0 },
        slope_deg: [0.0, 90.0],
        altitude_m: [-1e9, 1e9],
        water_level_m: None,
        scale: [0.8, 1.2],
        random_yaw: true,
        align_to_normal: 1.0,
        exclusions: vec![],
        seed: 0,
        max_instances: 10_000_000,
    }
}

fn xz(v: &[Instance]) -> Vec<[f64; 2]> {
    v.iter().map(|i| [i.position[0], i.position[2]]).collect()
}

/// Height by brute force: scan every triangle, barycentric weights written out independently.
fn brute_height(t: &Terrain, x: f64, z: f64) -> Option<f64> {
    for tri in t.indices.chunks_exact(3) {
        let p = |k: usize| {
            let v = t.positions[tri[k] as usize];
            (v[0] as f64, v[1] as f64, v[2] as f64)
        };
        let ((ax, ay, az), (bx, by, bz), (cx, cy, cz)) = (p(0), p(1), p(2));
        let det = (bz - cz) * (ax - cx) + (cx - bx) * (az - cz);
        let l1 = ((bz - cz) * (x - cx) + (cx - bx) * (z - cz)) / det;
        let l2 = ((cz - az) * (x - cx) + (ax - cx) * (z - cz)) / det;
        let l3 = 1.0 - l1 - l2;
        if l1 >= -1e-12 && l2 >= -1e-12 && l3 >= -1e-12 {
            return Some(l1 * ay + l2 * by + l3 * cy);
        }
    }
    None
}

#[test]
fn instances_sit_on_the_tin_surface() {
    let t = terrain(257, 120.0, 1.0);
    for placement in [Placement::Jittered, Placement::Poisson] {
        let sp = species("grass", placement);
        let v = scatter_species(&t.surface, t.extent, &sp, None, None, &[], 32.0, 1).unwrap();
        assert!(v.len() > 10_000, "{}", v.len());
        let stats = analyze(&t.surface, t.extent, &sp, None, None, None, &v, 32.0, 0.0).unwrap();
        assert_eq!((stats.off_surface, stats.height_checked), (0, v.len()));
        // the CSV's f64 heights sit on the mesh up to their 1 µm grid (half a step); scene.glb's
        // f32 values up to f32's rounding too
        assert!(stats.max_height_error_csv_m <= 5e-7 + 1e-12, "{}", stats.max_height_error_csv_m);
        assert!(stats.max_height_error_m <= 1e-4, "{}", stats.max_height_error_m);
        // independent of the index: brute force over every triangle for a sample of instances
        let mut worst = 0.0f64;
        for inst in v.iter().step_by(v.len() / 300) {
            let y = brute_height(&t, inst.position[0], inst.position[2]).expect("instance off the mesh");
            worst = worst.max((y - inst.position[1]).abs());
        }
        assert!(worst <= 1e-4, "{placement:?}: {worst}");
        // rotations are unit quaternions, tilted toward the (upward) normal
        assert!(v.iter().all(|i| (i.rotation.iter().map(|q| q * q).sum::<f32>() - 1.0).abs() < 1e-5));
        assert!(v.iter().all(|i| (0.8..=1.2).contains(&i.scale[0]) && (0.0..360.0).contains(&i.yaw_deg)));
        // yaw in whole 0.01°, scale in whole 10⁻⁴, jittered x/z on the 0.1 mm grid (short CSV entries)
        let on = |v: f64, steps: f64| ((v * steps).round() / steps - v).abs() <= v.abs() * 1e-7;
        assert!(v.iter().all(|i| on(i.yaw_deg as f64, 100.0) && on(i.scale[0] as f64, 1e4)));
        if placement == Placement::Jittered {
            assert!(v.iter().all(|i| (i.position[0] * 1e4).round() / 1e4 == i.position[0]
                && (i.position[2] * 1e4).round() / 1e4 == i.position[2]));
        }
        // heights on the 1 µm grid, quaternion components on the 10⁻⁷ grid (both placements)
        assert!(v.iter().all(|i| (i.position[1] * 1e6).round() / 1e6 == i.position[1]));
        assert!(v.iter().all(|i| i.rotation.iter().all(|&q| ((q as f64 * 1e7).round() / 1e7) as f32 == q)));
    }
}

/// Corners (x, y, z) of triangle `k` of the terrain's index list, in f64.
fn corners(t: &Terrain, k: usize) -> [[f64; 3]; 3] {
    [0, 1, 2].map(|c| t.positions[t.indices[3 * k + c] as usize].map(|v| v as f64))
}

/// Edge-vector coordinates (s, u) of (x, z) in a triangle: p − a = s·(b − a) + u·(c − a) in x/z.
fn edge_coordinates(p: [[f64; 3]; 3], x: f64, z: f64) -> (f64, f64) {
    let [a, b, c] = p;
    let det = (b[0] - a[0]) * (c[2] - a[2]) - (b[2] - a[2]) * (c[0] - a[0]);
    let s = ((x - a[0]) * (c[2] - a[2]) - (z - a[2]) * (c[0] - a[0])) / det;
    let u = ((b[0] - a[0]) * (z - a[2]) - (b[2] - a[2]) * (x - a[0])) / det;
    (s, u)
}

/// Height at (x, z) of the plane through a triangle's corners (also outside the triangle).
fn plane_height(p: [[f64; 3]; 3], x: f64, z: f64) -> f64 {
    let (s, u) = edge_coordinates(p, x, z);
    p[0][1] + s * (p[1][1] - p[0][1]) + u * (p[2][1] - p[0][1])
}

/// The analyzer's height check locates instances without the placement's index: an instance given
/// the height of a neighbouring triangle's plane (what picking the wrong triangle would give) is
/// measured at that distance, sampled or not, and positions off the mesh are counted.
#[test]
fn analyzer_height_error_catches_a_wrong_triangle() {
    use verdant::scatter::stats::height_check;
    let t = terrain(129, 80.0, 1.0);
    let sp = species("grass", Placement::Jittered);
    let placed = scatter_species(&t.surface, t.extent, &sp, None, None, &[], 32.0, 5).unwrap();
    let clean = height_check(&t.surface, &placed, usize::MAX);
    assert_eq!((clean.checked, clean.unlocated), (placed.len(), 0));
    assert!(clean.max_error_f64_m <= 5e-7 + 1e-12, "heights on their 1 µm grid: {clean:?}");
    // for some instances (every 50th): the triangle containing it, by brute force, and the plane of
    // a triangle sharing an edge with it; keep the instance where the two differ most
    let tri_count = t.indices.len() / 3;
    let (mut worst_k, mut worst_y, mut worst_d) = (0, 0.0, 0.0f64);
    for k in (0..placed.len()).step_by(50) {
        let [x, y, z] = placed[k].position;
        let inside = (0..tri_count).find(|&n| {
            let (s, u) = edge_coordinates(corners(&t, n), x, z);
            s >= -1e-12 && u >= -1e-12 && s + u <= 1.0 + 1e-12
        });
        let Some(inside) = inside else { continue };
        let own: Vec<u32> = t.indices[3 * inside..3 * inside + 3].to_vec();
        for n in (0..tri_count).filter(|&n| n != inside) {
            let shared = t.indices[3 * n..3 * n + 3].iter().filter(|v| own.contains(v)).count();
            if shared == 2 {
                let wrong = plane_height(corners(&t, n), x, z);
                if (wrong - y).abs() > worst_d {
                    (worst_k, worst_y, worst_d) = (k, wrong, (wrong - y).abs());
                }
            }
        }
    }
    assert!(worst_d > 1e-3, "the terrain is too flat for this test: {worst_d}");
    // worst_d is measured from the placed height, which is the mesh's on the 1 µm grid
    const GRID_ERROR: f64 = 5e-7 + 1e-9;
    let mut bad = placed.clone();
    bad[worst_k].position[1] = worst_y;
    let check = height_check(&t.surface, &bad, usize::MAX);
    assert!((check.max_error_f64_m - worst_d).abs() <= GRID_ERROR, "{check:?} vs {worst_d}");
    assert!(check.max_error_f32_m >= worst_d - 1e-4, "{check:?} vs {worst_d}");
    // sampled: every k-th instance from the first, so an instance at a multiple of the stride is seen
    let limit = bad.len() / 10;
    let stride = bad.len().div_ceil(limit);
    let mut sampled = placed.clone();
    sampled[3 * stride].position[1] = worst_y;
    sampled[3 * stride].position[0] = placed[worst_k].position[0];
    sampled[3 * stride].position[2] = placed[worst_k].position[2];
    let check = height_check(&t.surface, &sampled, limit);
    assert_eq!(check.checked, sampled.len().div_ceil(stride), "{check:?}");
    assert!(check.checked <= limit);
    assert!((check.max_error_f64_m - worst_d).abs() <= GRID_ERROR, "{check:?} vs {worst_d}");
    // and through analyze(), as the report gets it
    let stats = analyze(&t.surface, t.extent, &sp, None, None, None, &bad, 32.0, 0.0).unwrap();
    assert!(
        (stats.max_height_error_csv_m - worst_d).abs() <= GRID_ERROR && stats.max_height_error_m >= worst_d - 1e-4,
        "{stats:?}"
    );
    // off the mesh: counted, not measured
    let mut off = placed[..10].to_vec();
    off[4].position[0] = t.extent[2] + 5.0;
    let check = height_check(&t.surface, &off, usize::MAX);
    assert_eq!((check.checked, check.unlocated), (10, 1));
}

#[test]
fn poisson_spacing_holds_across_tile_borders() {
    let t = terrain(201, 60.0, 0.5);
    for (r, tile_m, self_radius) in [(2.0, 5.0, 0.0), (1.0, 3.0, 0.0), (1.5, 1.0, 0.0), (1.0, 7.0, 2.5)] {
        let mut sp = species("trees", Placement::Poisson);
        sp.min_spacing_m = r;
        sp.max_density = 100.0; // at full packing: the tightest case
        if self_radius > 0.0 {
            sp.exclusions.push(Exclusion { species: "trees".into(), radius_m: self_radius });
        }
        let v = scatter_species(&t.surface, t.extent, &sp, None, None, &[], tile_m, 3).unwrap();
        let tiles: std::collections::BTreeSet<u32> = v.iter().map(|i| i.tile).collect();
        assert!(tiles.len() > 100, "{} tiles", tiles.len());
        let d = min_pair_distance(xz(&v)).unwrap();
        let spacing = r.max(self_radius);
        assert!(d >= spacing * (1.0 - 1e-9), "r {r} tile {tile_m}: {d}");
        // sorted by tile
        assert!(v.windows(2).all(|w| w[0].tile <= w[1].tile));
        // and still densely packed (no empty bands along the borders)
        let density = v.len() as f64 / (200.0 * 200.0) * spacing * spacing;
        assert!(density > 0.95 * POISSON_PACKING, "{density}");
    }
}

/// A 64 × 1 map: the left half 0.2, the right half 0.8.
fn two_regions() -> DensityMap {
    DensityMap::from_fn(64, 1, |i, _| if i < 32 { 0.2 } else { 0.8 })
}

#[test]
fn density_fidelity_in_two_constant_regions() {
    let t = terrain(201, 40.0, 0.5);
    let map = two_regions();
    let halves = [[0.0, 0.0, 100.0, 200.0], [100.0, 0.0, 200.0, 200.0]];
    for placement in [Placement::Jittered, Placement::Poisson] {
        for seed in 0..3 {
            let mut sp = species("cover", placement);
            sp.seed = seed;
            // jittered: 1/m² → 4,000 expected at 0.2; Poisson r = 1 (0.613/m² at full packing) → 2,450
            let v = scatter_species(&t.surface, t.extent, &sp, Some(&map), None, &[], 16.0, 11).unwrap();
            for (k, half) in halves.iter().enumerate() {
                let expected = expected_count(&t.surface, t.extent, &sp, Some(&map), None, None, *half, 400).unwrap();
                let effective = match placement {
                    Placement::Jittered => sp.max_density,
                    Placement::Poisson => sp.max_density.min(POISSON_PACKING / (sp.min_spacing_m * sp.min_spacing_m)),
                };
                let nominal = [0.2, 0.8][k] * effective * 20_000.0;
                // the bilinear ramp between the halves moves ≈ 1 % from one side to the other
                assert!((expected / nominal - 1.0).abs() < 0.015, "{expected} vs {nominal}");
                assert!(expected >= 2000.0);
                let measured = v.iter().filter(|i| i.position[0] >= half[0] && i.position[0] < half[2]).count() as f64;
                let ratio = measured / expected;
                eprintln!("{placement:?} seed {seed} half {k}: {measured} / {expected:.0} = {ratio:.4}");
                assert!(
                    (ratio - 1.0).abs() < 0.05,
                    "{placement:?} seed {seed} half {k}: {measured} / {expected:.0} = {ratio:.3}"
                );
            }
            // the analyzer says the same
            let stats = analyze(&t.surface, t.extent, &sp, Some(&map), None, None, &v, 16.0, 0.0).unwrap();
            assert!((stats.count_ratio.unwrap() - 1.0).abs() < 0.03, "{:?}", stats.count_ratio);
            assert_eq!(stats.regions.len(), 64);
        }
    }
}

#[test]
fn deterministic_across_runs_and_thread_counts() {
    let t = terrain(129, 50.0, 0.5);
    let map = DensityMap::from_fn(17, 9, |i, j| ((i * 7 + j * 3) % 11) as f32 / 10.0);
    for placement in [Placement::Jittered, Placement::Poisson] {
        let mut sp = species("d", placement);
        sp.max_density = 2.0;
        if placement == Placement::Poisson {
            sp.min_spacing_m = 0.7;
        }
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| scatter_species(&t.surface, t.extent, &sp, Some(&map), None, &[], 10.0, 99).unwrap())
        };
        let a = run(1);
        let b = run(2);
        let c = scatter_species(&t.surface, t.extent, &sp, Some(&map), None, &[], 10.0, 99).unwrap();
        assert!(!a.is_empty());
        assert_eq!(a, b, "{placement:?}: 1 vs 2 threads");
        assert_eq!(a, c, "{placement:?}: repeated run");
        // and the seed matters
        let d = scatter_species(&t.surface, t.extent, &sp, Some(&map), None, &[], 10.0, 100).unwrap();
        assert_ne!(a, d);
    }
}

#[test]
fn density_all_zero_all_one_and_one_pixel() {
    let t = terrain(129, 50.0, 0.5);
    for placement in [Placement::Jittered, Placement::Poisson] {
        let sp = species("g", placement);
        let zero = DensityMap::from_fn(32, 32, |_, _| 0.0);
        let none = scatter_species(&t.surface, t.extent, &sp, Some(&zero), None, &[], 16.0, 5).unwrap();
        assert!(none.is_empty());
        // all 1 is the same as no map; a 1×1 map of 1 too
        let ones = DensityMap::from_fn(5, 3, |_, _| 1.0);
        let uniform = scatter_species(&t.surface, t.extent, &sp, None, None, &[], 16.0, 5).unwrap();
        assert_eq!(scatter_species(&t.surface, t.extent, &sp, Some(&ones), None, &[], 16.0, 5).unwrap(), uniform);
        assert_eq!(
            scatter_species(&t.surface, t.extent, &sp, Some(&DensityMap::constant(1.0)), None, &[], 16.0, 5).unwrap(),
            uniform
        );
        let expected = expected_count(&t.surface, t.extent, &sp, None, None, None, t.extent, 200).unwrap();
        assert!((uniform.len() as f64 / expected - 1.0).abs() < 0.03, "{} vs {expected}", uniform.len());
        // a 1×1 map of 0.5: half
        let half =
            scatter_species(&t.surface, t.extent, &sp, Some(&DensityMap::constant(0.5)), None, &[], 16.0, 5).unwrap();
        assert!((half.len() as f64 / (0.5 * expected) - 1.0).abs() < 0.04, "{} vs {}", half.len(), 0.5 * expected);
    }
}

#[test]
fn density_map_of_another_resolution_and_aspect() {
    // a 37 × 91 map (aspect 0.4) over a square 200 m terrain: a gradient along x, stripes along z
    let t = terrain(201, 40.0, 0.5);
    let map = DensityMap::from_fn(37, 91, |i, j| (i as f32 / 36.0) * if (j / 13) % 2 == 0 { 1.0 } else { 0.5 });
    for placement in [Placement::Jittered, Placement::Poisson] {
        let mut sp = species("g", placement);
        sp.max_density = 1.5;
        let v = scatter_species(&t.surface, t.extent, &sp, Some(&map), None, &[], 25.0, 8).unwrap();
        let stats = analyze(&t.surface, t.extent, &sp, Some(&map), None, None, &v, 25.0, 0.0).unwrap();
        assert!((stats.count_ratio.unwrap() - 1.0).abs() < 0.03, "{placement:?} {:?}", stats.count_ratio);
        // every region with a good number expected is within 15 % (a few hundred each)
        for r in stats.regions.iter().filter(|r| r.expected > 400.0) {
            assert!((r.ratio.unwrap() - 1.0).abs() < 0.15, "{placement:?} {r:?}");
        }
        // the gradient shows: the right column of regions holds far more than the left
        let col = |c: usize| stats.regions.iter().skip(c).step_by(8).map(|r| r.measured).sum::<usize>();
        assert!(col(7) > 5 * col(0).max(1), "{} vs {}", col(7), col(0));
    }
}

#[test]
fn spacing_larger_than_the_terrain() {
    let t = terrain(65, 20.0, 0.5);
    let mut sp = species("giant", Placement::Poisson);
    sp.min_spacing_m = 500.0;
    for tile_m in [8.0, 64.0, 1000.0] {
        let v = scatter_species(&t.surface, t.extent, &sp, None, None, &[], tile_m, 1).unwrap();
        assert!(v.len() <= 1, "{}", v.len());
    }
}

#[test]
fn slope_range_that_excludes_everything() {
    let t = terrain(129, 30.0, 0.5);
    for placement in [Placement::Jittered, Placement::Poisson] {
        let mut sp = species("cliff", placement);
        sp.slope_deg = [89.0, 90.0];
        let out = scatter_species_detailed(&t.surface, t.extent, &sp, None, None, &[], 16.0, 1).unwrap();
        assert!(out.instances.is_empty());
        assert!(out.counts.slope > 1000, "{:?}", out.counts);
        assert_eq!(out.estimate, 0.0);
    }
}

#[test]
fn slope_rule_uses_the_triangle_normal() {
    let t = terrain(129, 80.0, 0.5);
    let mut sp = species("steep", Placement::Jittered);
    sp.slope_deg = [20.0, 35.0];
    let v = scatter_species(&t.surface, t.extent, &sp, None, None, &[], 16.0, 1).unwrap();
    assert!(!v.is_empty());
    for i in &v {
        let (_, n) = t.surface.height_at(i.position[0], i.position[2]).unwrap();
        let slope = n[1].acos().to_degrees();
        assert!((20.0..=35.0).contains(&slope), "{slope}");
    }
}

#[test]
fn exclusion_against_an_earlier_species() {
    let t = terrain(129, 30.0, 0.5);
    let mut trees = species("oak", Placement::Poisson);
    trees.min_spacing_m = 6.0;
    let oaks = scatter_species(&t.surface, t.extent, &trees, None, None, &[], 32.0, 2).unwrap();
    assert!(oaks.len() > 100);
    let mut grass = species("grass", Placement::Jittered);
    grass.max_density = 4.0;
    grass.exclusions.push(Exclusion { species: "oak".into(), radius_m: 1.5 });
    let earlier: [(&str, &[Instance]); 1] = [("oak", &oaks)];
    let out = scatter_species_detailed(&t.surface, t.extent, &grass, None, None, &earlier, 32.0, 2).unwrap();
    assert!(out.instances.len() > 30_000);
    assert!(out.counts.exclusion > 0);
    for g in &out.instances {
        for o in &oaks {
            let d = ((g.position[0] - o.position[0]).powi(2) + (g.position[2] - o.position[2]).powi(2)).sqrt();
            assert!(d >= 1.5, "grass {d} m from an oak");
        }
    }
    // about π·1.5² m² per oak is cleared
    let cleared = out.counts.exclusion as f64 / (grass.max_density * oaks.len() as f64 * std::f64::consts::PI * 2.25);
    assert!((cleared - 1.0).abs() < 0.1, "{cleared}");
    // a species that is not placed earlier is an error naming both
    let e = scatter_species(&t.surface, t.extent, &grass, None, None, &[], 32.0, 2).unwrap_err().to_string();
    assert!(e.contains("grass") && e.contains("oak"), "{e}");
    // jittered cannot keep its own instances apart
    let mut selfish = species("fern", Placement::Jittered);
    selfish.exclusions.push(Exclusion { species: "fern".into(), radius_m: 1.0 });
    let e = scatter_species(&t.surface, t.extent, &selfish, None, None, &[], 32.0, 2).unwrap_err().to_string();
    assert!(e.contains("fern") && e.contains("poisson"), "{e}");
}

#[test]
fn max_instances_exceeded_is_a_clear_error() {
    let t = terrain(129, 30.0, 0.5);
    let mut sp = species("lawn", Placement::Jittered);
    sp.max_instances = 1000;
    let e = scatter_species(&t.surface, t.extent, &sp, None, None, &[], 16.0, 1).unwrap_err();
    assert!(matches!(e, ScatterError::TooManyEstimated { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("lawn") && msg.contains("max_instances = 1000") && msg.contains("raise max_instances"),
        "{msg}"
    );
    // a huge request fails fast (estimated, not generated)
    sp.max_density = 1e7;
    let e = scatter_species(&t.surface, t.extent, &sp, None, None, &[], 16.0, 1).unwrap_err();
    // TooManyEstimated is raised before any point is generated (no wall-clock bound: shared machines)
    assert!(matches!(e, ScatterError::TooManyEstimated { .. }), "{e:?}");
    // huge work with little output (density ~0 almost everywhere) is refused too
    sp.max_instances = usize::MAX;
    sp.max_density = 1e9;
    let sparse = DensityMap::from_fn(64, 64, |i, j| if (i, j) == (0, 0) { 1e-6 } else { 0.0 });
    let e = scatter_species(&t.surface, t.extent, &sp, Some(&sparse), None, &[], 16.0, 1).unwrap_err();
    assert!(matches!(e, ScatterError::TooMuchWork { .. }), "{e:?}");
    // at the limit it passes
    let mut ok = species("lawn", Placement::Poisson);
    let n = scatter_species(&t.surface, t.extent, &ok, None, None, &[], 16.0, 1).unwrap().len();
    ok.max_instances = n;
    assert_eq!(scatter_species(&t.surface, t.extent, &ok, None, None, &[], 16.0, 1).unwrap().len(), n);
}

#[test]
fn water_level_and_altitude() {
    let t = terrain(129, 100.0, 0.5);
    for placement in [Placement::Jittered, Placement::Poisson] {
        let mut sp = species("reed", placement);
        sp.water_level_m = Some(30.0);
        sp.altitude_m = [-1e9, 70.0];
        let out = scatter_species_detailed(&t.surface, t.extent, &sp, None, None, &[], 16.0, 4).unwrap();
        assert!(out.counts.water > 100 && out.counts.altitude > 100 && out.instances.len() > 100, "{:?}", out.counts);
        assert!(out.instances.iter().all(|i| i.position[1] >= 30.0 && i.position[1] <= 70.0));
        let stats = analyze(&t.surface, t.extent, &sp, None, None, None, &out.instances, 16.0, 0.0).unwrap();
        assert!((stats.count_ratio.unwrap() - 1.0).abs() < 0.05, "{:?}", stats.count_ratio);
    }
}

#[test]
fn mask_keeps_only_the_marked_half() {
    let t = terrain(129, 30.0, 0.5);
    let mask = DensityMap::from_fn(16, 16, |i, _| if i >= 8 { 1.0 } else { 0.0 });
    for placement in [Placement::Jittered, Placement::Poisson] {
        let sp = species("m", placement);
        let out = scatter_species_detailed(&t.surface, t.extent, &sp, None, Some(&mask), &[], 16.0, 4).unwrap();
        assert!(out.instances.len() > 1000);
        assert!(out.counts.mask > 1000);
        assert!(out.instances.iter().all(|i| i.position[0] >= 64.0 - 1e-9), "an instance left of the mask edge");
    }
}

#[test]
fn poisson_max_density_below_packing_thins() {
    let t = terrain(201, 40.0, 0.5);
    let mut sp = species("sparse", Placement::Poisson);
    sp.min_spacing_m = 1.0;
    sp.max_density = 0.1; // a sixth of the packing at r = 1
    let v = scatter_species(&t.surface, t.extent, &sp, None, None, &[], 20.0, 6).unwrap();
    let expected = 0.1 * 200.0 * 200.0;
    assert!((v.len() as f64 / expected - 1.0).abs() < 0.05, "{} vs {expected}", v.len());
    assert!(min_pair_distance(xz(&v)).unwrap() >= 1.0);
}

#[test]
fn bad_settings_are_errors_not_panics() {
    let t = terrain(65, 20.0, 0.5);
    let sp = species("x", Placement::Poisson);
    assert!(matches!(
        scatter_species(&t.surface, [0.0, 0.0, 0.0, 10.0], &sp, None, None, &[], 16.0, 1),
        Err(ScatterError::Extent { .. })
    ));
    assert!(matches!(
        scatter_species(&t.surface, t.extent, &sp, None, None, &[], 1e-6, 1),
        Err(ScatterError::Tiles { .. })
    ));
    assert!(matches!(
        scatter_species(&t.surface, t.extent, &sp, None, None, &[], f64::NAN, 1),
        Err(ScatterError::Tiles { .. })
    ));
    let mut bad = sp.clone();
    bad.min_spacing_m = 0.0;
    assert!(matches!(
        scatter_species(&t.surface, t.extent, &bad, None, None, &[], 16.0, 1),
        Err(ScatterError::Settings { .. })
    ));
    bad.min_spacing_m = 1.0;
    bad.max_density = f64::NAN;
    assert!(matches!(
        scatter_species(&t.surface, t.extent, &bad, None, None, &[], 16.0, 1),
        Err(ScatterError::Settings { .. })
    ));
    // an empty surface: nothing is placed, no error
    let empty = SurfaceIndex::new(&[], &[]);
    assert!(scatter_species(&empty, t.extent, &sp, None, None, &[], 16.0, 1).unwrap().is_empty());
    // an empty density map reads 0
    let e = DensityMap { width: 0, height: 0, values: vec![] };
    assert!(scatter_species(&t.surface, t.extent, &sp, Some(&e), None, &[], 16.0, 1).unwrap().is_empty());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// On a planar grid mesh the height is the plane's, exactly, at any point (edges and corners included).
    #[test]
    fn height_on_a_plane_is_exact(a in -2.0f64..2.0, b in -2.0f64..2.0, c in -50.0f64..50.0, n in 1usize..12,
                                  pts in proptest::collection::vec((0.0f64..=1.0, 0.0f64..=1.0), 1..40)) {
        let side = n as f64 * 4.0;
        let mut positions = Vec::new();
        for j in 0..=n { for i in 0..=n {
            let (x, z) = (i as f64 * 4.0, j as f64 * 4.0);
            positions.push([x as f32, (a * x + b * z + c) as f32, z as f32]);
        } }
        let mut indices = Vec::new();
        for j in 0..n as u32 { for i in 0..n as u32 {
            let v = j * (n as u32 + 1) + i;
            let w = v + n as u32 + 1;
            indices.extend_from_slice(&[v, w, v + 1, v + 1, w, w + 1]);
        } }
        let s = SurfaceIndex::new(&positions, &indices);
        prop_assert_eq!(s.triangle_count(), 2 * n * n);
        for (u, v) in pts {
            // snap some points onto grid lines
            let (x, z) = ((u * side * 4.0).round() / 4.0, v * side);
            let (y, normal) = s.height_at(x, z).expect("inside");
            // the plane through the f32 vertices
            let want = |x: f64, z: f64| a * x + b * z + c;
            prop_assert!((y - want(x, z)).abs() < 1e-4 * (1.0 + want(x, z).abs()), "{} vs {}", y, want(x, z));
            prop_assert!(normal[1] > 0.0);
        }
    }

    /// Bilinear samples stay within the map's value range, for any resolution.
    #[test]
    fn density_samples_stay_in_range(w in 1usize..9, h in 1usize..9, seed in 0u64..1000, u in -0.5f64..1.5, v in -0.5f64..1.5) {
        let m = DensityMap::from_fn(w, h, |i, j| (verdant::random::mix64(seed ^ (i * 31 + j) as u64) % 1000) as f32 / 999.0);
        let lo = m.values.iter().cloned().fold(1.0f32, f32::min);
        let hi = m.values.iter().cloned().fold(0.0f32, f32::max);
        let s = m.sample(u, v);
        prop_assert!(s >= lo - 1e-6 && s <= hi + 1e-6);
    }
}

#[test]
fn jittered_refuses_a_spacing_it_cannot_keep() {
    let t = terrain(33, 10.0, 0.5);
    let mut sp = species("j", Placement::Jittered);
    sp.min_spacing_m = 2.0;
    let e = scatter_species(&t.surface, t.extent, &sp, None, None, &[], 16.0, 1).unwrap_err().to_string();
    assert!(e.contains("min_spacing") && e.contains("poisson"), "{e}");
}

/// The whole run of `sp` joined from runs over the tile rows of `cuts` (`0 = c0 < c1 < … = rows`),
/// each given the `earlier` instances of its rows widened by `margin` rows (exclusions read those
/// alone): instances in row order, counts summed.
#[allow(clippy::too_many_arguments)]
fn joined_rows(
    t: &Terrain,
    sp: &SpeciesRules,
    earlier: &[(&str, &[Instance])],
    tile_m: f64,
    tiles_x: u32,
    cuts: &[u32],
    margin: u32,
) -> (Vec<Instance>, verdant::scatter::RuleCounts) {
    let (mut all, mut counts) = (Vec::new(), verdant::scatter::RuleCounts::default());
    for w in cuts.windows(2) {
        let near = |i: &&Instance| {
            let row = i.tile / tiles_x;
            row + margin >= w[0] && row < w[1] + margin
        };
        let kept: Vec<Vec<Instance>> = earlier.iter().map(|(_, v)| v.iter().filter(near).copied().collect()).collect();
        let given: Vec<(&str, &[Instance])> = earlier.iter().zip(&kept).map(|((n, _), v)| (*n, v.as_slice())).collect();
        let run = verdant::scatter::scatter_species_in_rows(
            &t.surface,
            t.extent,
            sp,
            None,
            None,
            &given,
            tile_m,
            7,
            None,
            Some([w[0], w[1]]),
        )
        .unwrap();
        assert!(run.instances.iter().all(|i| (w[0]..w[1]).contains(&(i.tile / tiles_x))), "only its rows");
        all.extend(run.instances);
        counts.add(&run.counts);
    }
    (all, counts)
}

/// Tile rows placed alone (a shard's rows): runs over rows that partition the tiling, joined in
/// row order, are the whole run — every instance bit for bit and in order, the rule counts summed —
/// for Poisson blocks of one tile and of three (the colour phases reaching across the runs'
/// borders: the block rows beside a run's are filled again), jittered placement, and species
/// excluded by an earlier one (given only its instances of their rows widened by the radius).
#[test]
fn tile_rows_placed_alone_join_to_the_whole_run() {
    let t = terrain(257, 60.0, 0.5);
    let tile_m = 16.0; // 16 × 16 tiles
    let mut small = species("small", Placement::Poisson);
    small.min_spacing_m = 2.0;
    let mut wide = species("wide", Placement::Poisson);
    wide.min_spacing_m = 40.0; // blocks of 3 tiles
    let mut jittered = species("jittered", Placement::Jittered);
    jittered.max_density = 0.5;
    jittered.exclusions = vec![Exclusion { species: "small".into(), radius_m: 1.5 }];
    let mut near = species("near", Placement::Poisson);
    near.min_spacing_m = 1.5;
    near.max_density = 0.2;
    near.exclusions = vec![Exclusion { species: "small".into(), radius_m: 1.0 }];
    let whole = |sp: &SpeciesRules, earlier: &[(&str, &[Instance])]| {
        scatter_species_detailed(&t.surface, t.extent, sp, None, None, earlier, tile_m, 7).unwrap()
    };
    let small_all = whole(&small, &[]);
    assert!(small_all.instances.len() > 1000);
    let earlier: [(&str, &[Instance]); 1] = [("small", &small_all.instances)];
    let partitions: Vec<Vec<u32>> =
        vec![vec![0, 1, 16], vec![0, 5, 6, 11, 16], vec![0, 8, 9, 10, 16], (0..=16).collect()];
    for (sp, earlier, margin) in
        [(&small, &[][..], 0), (&wide, &[][..], 0), (&jittered, &earlier[..], 1), (&near, &earlier[..], 1)]
    {
        let all = whole(sp, earlier);
        assert!(!all.instances.is_empty(), "{}", sp.name);
        for cuts in &partitions {
            let (joined, counts) = joined_rows(&t, sp, earlier, tile_m, 16, cuts, margin);
            assert!(
                joined == all.instances,
                "{} over rows {cuts:?}: {} instances, whole {}",
                sp.name,
                joined.len(),
                all.instances.len()
            );
            assert_eq!(counts, all.counts, "{} over rows {cuts:?}", sp.name);
        }
    }
    // rows that are not the tiling's
    for rows in [[3, 3], [5, 2], [0, 17]] {
        let err = verdant::scatter::scatter_species_in_rows(
            &t.surface,
            t.extent,
            &small,
            None,
            None,
            &[],
            tile_m,
            7,
            None,
            Some(rows),
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("tile rows") && err.contains("0..16"), "{err}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]
    /// The same for random tile sizes, spacings (blocks of one to several tiles, partial last
    /// rows), extents whose tile and block borders are not exact in binary (starting at 0.61 m)
    /// and cuts.
    #[test]
    fn tile_rows_of_any_cut_join_to_the_whole_run(
        tile_m in prop::sample::select(vec![7.0, 10.5, 16.0, 23.0, 0.7 * 13.0]),
        spacing in 0.9f64..30.0,
        poisson in any::<bool>(),
        offset in any::<bool>(),
        cut_seeds in prop::collection::vec(any::<u32>(), 1..5),
    ) {
        let mut t = terrain(129, 40.0, 0.5);
        if offset {
            t.extent = [0.37, 0.61, 128.0, 128.0];
        }
        let mut sp = species("p", if poisson { Placement::Poisson } else { Placement::Jittered });
        if poisson {
            sp.min_spacing_m = spacing;
        } else {
            sp.max_density = 1.0 / spacing;
        }
        let rows = ((t.extent[3] - t.extent[1]) / tile_m).ceil() as u32;
        let mut cuts: Vec<u32> = cut_seeds.iter().map(|s| s % rows).filter(|&c| c > 0).collect();
        cuts.extend([0, rows]);
        cuts.sort_unstable();
        cuts.dedup();
        let all = scatter_species_detailed(&t.surface, t.extent, &sp, None, None, &[], tile_m, 7).unwrap();
        let tiles_x = ((t.extent[2] - t.extent[0]) / tile_m).ceil() as u32;
        let (joined, counts) = joined_rows(&t, &sp, &[], tile_m, tiles_x, &cuts, 0);
        prop_assert!(joined == all.instances, "cuts {:?}: {} vs {}", cuts, joined.len(), all.instances.len());
        prop_assert_eq!(counts, all.counts);
    }
}
