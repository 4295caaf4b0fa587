//! A chunked terrain's levels as written (`terrain/terrain_LOD<k>.glb`): at every level each chunk
//! fills its square seen from above, and where two neighbouring chunks are shown at any two levels
//! (as scene.glb, scene_lod.glb and the scene tiles mix them) the higher edge's skirt reaches the
//! lower edge at every sample along their shared line: no hole from above, no crack from the side.

use std::collections::BTreeMap;

use crate::common::*;

/// fbm 401² with 2 m cells, chunks of 64 cells (the last 16: 7 × 7), two bands (320 rows and 80),
/// a three-level chain and skirts shallower than its coarsest level's error.
const PRESET: &str = "[scene]\nname = \"chunks\"\nseed = 2\n\n[terrain]\n\
                      procedural = { kind = \"fbm\", size = 401, seed = 9, relief = 60.0 }\n\
                      cell_size = 2.0\nmax_error = 0.1\nchunk = 64\nskirt = 0.5\nlods = [0.1, 0.5, 2.5]\n";
const CELL: f32 = 2.0;
const PITCH: u32 = 64;
const LAST: u32 = 400;

/// A chunk of one level: its top faces' positions (x, z, y) by triangle, and its edge heights
/// (x or z along the line → top y, skirt bottom y) on each side of its square.
struct Chunk {
    top: Vec<[[f32; 3]; 3]>,
    /// per vertex position on the square's border: (x, z) → (highest y, lowest y)
    border: BTreeMap<(u32, u32), (f32, f32)>,
}

fn square(i: u32, j: u32) -> ([f32; 2], [f32; 2]) {
    let lo = [i * PITCH, j * PITCH].map(|s| s as f32 * CELL);
    let hi = [((i + 1) * PITCH).min(LAST), ((j + 1) * PITCH).min(LAST)].map(|s| s as f32 * CELL);
    (lo, hi)
}

fn chunks(path: &std::path::Path) -> BTreeMap<(u32, u32), Chunk> {
    let scene = verdant::validate::read_scene(path).unwrap();
    let mut out = BTreeMap::new();
    for m in &scene.meshes {
        let Some(at) = m.name.split("_chunk_").nth(1) else { continue };
        let ij: Vec<u32> = at.split('_').map(|s| s.parse().unwrap()).collect();
        let (lo, hi) = square(ij[0], ij[1]);
        let mut c = Chunk { top: Vec::new(), border: BTreeMap::new() };
        for p in &m.primitives {
            for v in &p.positions {
                assert!(
                    lo[0] <= v[0] && v[0] <= hi[0] && lo[1] <= v[2] && v[2] <= hi[1],
                    "{}: vertex {v:?} outside its square {lo:?}..{hi:?}",
                    m.name
                );
                if v[0] == lo[0] || v[0] == hi[0] || v[2] == lo[1] || v[2] == hi[1] {
                    let key = ((v[0] / CELL) as u32, (v[2] / CELL) as u32);
                    let e = c.border.entry(key).or_insert((v[1], v[1]));
                    *e = (e.0.max(v[1]), e.1.min(v[1]));
                }
            }
            for t in p.indices.chunks(3) {
                let q = [0, 1, 2].map(|k| p.positions[t[k] as usize]);
                let cross = (q[1][0] - q[0][0]) as f64 * (q[2][2] - q[0][2]) as f64
                    - (q[1][2] - q[0][2]) as f64 * (q[2][0] - q[0][0]) as f64;
                if cross.abs() > 1e-9 {
                    assert!(cross < 0.0, "{}: a face turned down {q:?}", m.name);
                    c.top.push(q);
                }
            }
        }
        out.insert((ij[0], ij[1]), c);
    }
    out
}

/// The top edge of `c` along its border line at sample positions `along` (x index when the line
/// runs along x, else z index) interpolated between the edge's vertices, and the skirt's depth
/// below each vertex (the smallest).
fn edge(c: &Chunk, vertical: bool, at: u32, from: u32, to: u32) -> (Vec<f64>, f64) {
    let pts: Vec<(u32, f32, f32)> = c
        .border
        .iter()
        .filter_map(|(&(i, j), &(hi, lo))| {
            let (across, along) = if vertical { (i, j) } else { (j, i) };
            (across == at && (from..=to).contains(&along)).then_some((along, hi, lo))
        })
        .collect();
    assert_eq!(pts.first().map(|p| p.0), Some(from), "the edge starts at the square's corner");
    assert_eq!(pts.last().map(|p| p.0), Some(to), "the edge ends at the square's corner");
    let depth = pts.iter().map(|p| (p.1 - p.2) as f64).fold(f64::INFINITY, f64::min);
    let heights = (from..=to)
        .map(|t| {
            let k = pts.partition_point(|p| p.0 < t);
            if pts[k].0 == t {
                return pts[k].1 as f64;
            }
            let (a, b) = (pts[k - 1], pts[k]);
            let w = (t - a.0) as f64 / (b.0 - a.0) as f64;
            a.1 as f64 * (1.0 - w) + b.1 as f64 * w
        })
        .collect();
    (heights, depth)
}

#[test]
fn chunks_fill_their_squares_and_their_skirts_close_the_step_to_any_level() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p.toml", PRESET);
    ok(&verdant_in(d, &["-q", "build", "p.toml", "--out", "o"]));
    let levels: Vec<BTreeMap<(u32, u32), Chunk>> =
        (0..3).map(|k| chunks(&d.join(format!("o/chunks/terrain/terrain_LOD{k}.glb")))).collect();
    let bounds = [0.1, 0.5, 2.5];
    for (k, level) in levels.iter().enumerate() {
        assert_eq!(level.len(), 49, "LOD{k}: 7 × 7 chunks");
        for (&(i, j), c) in level {
            let (lo, hi) = square(i, j);
            let area: f64 = c
                .top
                .iter()
                .map(|q| {
                    let cross = (q[1][0] - q[0][0]) as f64 * (q[2][2] - q[0][2]) as f64
                        - (q[1][2] - q[0][2]) as f64 * (q[2][0] - q[0][0]) as f64;
                    -cross / 2.0
                })
                .sum();
            let want = ((hi[0] - lo[0]) * (hi[1] - lo[1])) as f64;
            assert!((area - want).abs() < 1e-6 * want, "LOD{k} chunk {i},{j}: top faces cover {area} of {want} m²");
        }
    }
    // every neighbouring pair at every two levels: the step along their line within the higher
    // edge's skirt; the skirts hang each level's bound plus the coarsest one's (0.5 m asked)
    let mut largest_step = 0.0f64;
    for (a, la) in levels.iter().enumerate() {
        for (b, lb) in levels.iter().enumerate() {
            for (&(i, j), ca) in la {
                for (vertical, n) in [(true, (i + 1, j)), (false, (i, j + 1))] {
                    let Some(cb) = lb.get(&n) else { continue };
                    let (lo, hi) = square(i, j);
                    let (at, from, to) = if vertical {
                        ((hi[0] / CELL) as u32, (lo[1] / CELL) as u32, (hi[1] / CELL) as u32)
                    } else {
                        ((hi[1] / CELL) as u32, (lo[0] / CELL) as u32, (hi[0] / CELL) as u32)
                    };
                    let (ha, da) = edge(ca, vertical, at, from, to);
                    let (hb, db) = edge(cb, vertical, at, from, to);
                    assert!(da >= bounds[a] + 2.5 - 1e-4, "LOD{a} skirt {da} m");
                    assert!(db >= bounds[b] + 2.5 - 1e-4, "LOD{b} skirt {db} m");
                    for (t, (&ya, &yb)) in ha.iter().zip(&hb).enumerate() {
                        let step = ya - yb;
                        largest_step = largest_step.max(step.abs());
                        let reach = if step > 0.0 { da } else { db };
                        assert!(
                            step.abs() <= reach + 1e-4,
                            "LOD{a} chunk {i},{j} beside LOD{b} chunk {n:?}, sample {} along the line: a step of \
                             {step:.3} m, the skirt {reach:.3} m",
                            from + t as u32
                        );
                    }
                }
            }
        }
    }
    // the case is a real one: some step is larger than the 0.5 m the preset asks for
    assert!(largest_step > 0.5, "largest step {largest_step}");
}
