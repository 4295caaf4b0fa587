//! `scene_lod.glb`: the scene for viewers and engines that switch levels themselves (Babylon.js,
//! three.js with `scripts/engines/three_msft_lod.js`), where scene.glb is the selection one view
//! makes. Every terrain chunk and every placement tile × species × variant is an MSFT_lod chain:
//! one node per level (a chunk of `terrain_LOD<k>.glb`; the tile's instances of the level's mesh),
//! with `MSFT_screencoverage` worked out for the chunk's or the tile's bounding sphere on the `[lod]`
//! reference screen, so that no part of it switches before verdant's switch distance would switch
//! it: level k is shown while the sphere covers at least coverage k, which is the coverage when the
//! sphere's nearest point is at level k+1's switch distance (for a tile, times its largest instance
//! scale). A species' coarsest level ends at its cull distance; the terrain's never does.

use std::path::{Path, PathBuf};

use crate::export::table::PlacementRow;
use crate::lod::{lod_screen_coverage, LodView};
use crate::mesh::{Instances, Node, Scene};
use crate::scene::error::StageError;
use crate::scene::plants_stage::SpeciesChain;
use crate::scene::view::CullDistance;
use crate::scene::view_stage::{instance_centre, mesh_bounds, shown, Assembler};

/// One species as the LoD scene instances it.
#[derive(Clone, Copy)]
pub(super) struct LodSpecies<'a> {
    pub name: &'a str,
    pub chain: &'a SpeciesChain,
    pub rows: &'a [PlacementRow],
    /// The rows this scene instances (indices into `rows`, ascending); `None`: every row.
    pub picked: Option<&'a [u32]>,
    pub cull: CullDistance,
}

/// The terrain's chunks and level files (level 0 first, with their switch distances).
#[derive(Clone, Copy)]
pub(super) struct LodTerrain<'a> {
    pub main: &'a Scene,
    pub levels: &'a [(PathBuf, f64)],
    /// The level files hold the main mesh's chunks (same count, same order).
    pub chunked: bool,
    pub main_file: &'a Path,
    /// The chunks this scene holds (indices into `main`'s meshes, ascending); `None`: every chunk.
    pub picked: Option<&'a [usize]>,
    /// Move the level files' chunks out of the files read instead of copying them (the last scene
    /// assembled from them).
    pub take: bool,
}

/// Builds `scene_lod.glb`'s scene in `asm` (which must start empty), or a part of it (the picked
/// chunks and rows: a scene tile, [`crate::scene::view_tiles`]); returns the terrain's meshes in
/// it (every level of every chunk).
pub(super) fn lod_scene(
    asm: &mut Assembler<'_>,
    terrain: &LodTerrain<'_>,
    species: &[LodSpecies<'_>],
    view: &LodView,
) -> Result<Vec<usize>, StageError> {
    // terrain: per chunk, its levels
    let mut chunks = Vec::new();
    let mut terrain_meshes = Vec::new();
    let all: Vec<usize>;
    let picked = match terrain.picked {
        Some(p) => p,
        None => {
            all = (0..terrain.main.meshes.len()).collect();
            &all
        }
    };
    for &c in picked {
        let m = &terrain.main.meshes[c];
        let files: Vec<(&Path, f64)> = if terrain.chunked && !terrain.levels.is_empty() {
            terrain.levels.iter().map(|(f, d)| (f.as_path(), *d)).collect()
        } else {
            vec![(terrain.main_file, 0.0)]
        };
        let radius = mesh_bounds(m).map_or(0.0, |(lo, hi)| 0.5 * distance(lo, hi));
        let mut nodes = Vec::with_capacity(files.len());
        for (k, (file, _)) in files.iter().enumerate() {
            // (each chunk of a level file is appended here once, and the file not read again)
            let mi = if terrain.take && terrain.chunked && !terrain.levels.is_empty() {
                asm.mesh_moved(file, c)?
            } else {
                asm.mesh(file, c)?
            };
            asm.scene.nodes.push(Node { name: format!("{}_LOD{k}", m.name), mesh: Some(mi), ..Node::default() });
            nodes.push(asm.scene.nodes.len() - 1);
            terrain_meshes.push(mi);
        }
        let switches: Vec<f64> = files.iter().map(|(_, d)| *d).collect();
        chunks.push(chain_node(&mut asm.scene, &nodes, &coverages(radius, &switches, None, view)));
    }
    // (a part leaves out what it has none of)
    if terrain.picked.is_none() || !chunks.is_empty() {
        asm.scene.nodes.push(Node { name: "terrain".into(), children: chunks, ..Node::default() });
        asm.scene.roots.push(asm.scene.nodes.len() - 1);
    }

    // plants: per tile and variant, its levels, each instancing the tile's rows
    for s in species {
        let mut groups: std::collections::BTreeMap<(u32, usize), Vec<&PlacementRow>> = Default::default();
        let rows: Box<dyn Iterator<Item = (usize, &PlacementRow)>> = match s.picked {
            Some(p) => Box::new(p.iter().map(|&n| (n as usize, &s.rows[n as usize]))),
            None => Box::new(s.rows.iter().enumerate()),
        };
        for (n, row) in rows {
            groups.entry((row.tile, shown(s.name, s.chain, n, row)?)).or_default().push(row);
        }
        if s.picked.is_some() && groups.is_empty() {
            continue;
        }
        let mut children = Vec::with_capacity(groups.len());
        for ((tile, variant), rows) in groups {
            let levels = &s.chain.variants[variant];
            let instances = std::sync::Arc::new(Instances {
                translations: rows.iter().map(|r| r.position.map(|x| x as f32)).collect(),
                rotations: rows.iter().map(|r| r.rotation).collect(),
                scales: rows.iter().map(|r| r.scale).collect(),
            });
            // the tile's sphere: around its instances' centres, each instance within its height
            let centres: Vec<[f64; 3]> = rows.iter().map(|r| instance_centre(r, s.chain.centre_y_m)).collect();
            let (lo, hi) = bounds(&centres);
            let centre = [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a]));
            let radius = rows
                .iter()
                .zip(&centres)
                .map(|(r, c)| {
                    distance(*c, centre) + s.chain.height_m * r.scale[1].max(r.scale[0]).max(r.scale[2]) as f64
                })
                .fold(0.0, f64::max);
            let max_scale = rows.iter().map(|r| r.scale[1] as f64).fold(0.0, f64::max);
            let mut nodes = Vec::with_capacity(levels.len());
            for (k, level) in levels.iter().enumerate() {
                let mi = asm.mesh_named(&level.file, &level.mesh)?;
                asm.scene.nodes.push(Node {
                    name: format!("{}_t{tile}_v{variant}_LOD{k}", s.name),
                    mesh: Some(mi),
                    instances: Some(instances.clone()),
                    extras: Some(serde_json::json!({
                        "species": s.name, "tile": tile, "variant": variant, "level": k, "mesh": level.mesh,
                        "file": level.file,
                    })),
                    ..Node::default()
                });
                nodes.push(asm.scene.nodes.len() - 1);
            }
            let switches: Vec<f64> = levels.iter().map(|l| l.switch_distance_m * max_scale).collect();
            let cull = if s.cull.scales_with_view { s.cull.distance_m * max_scale } else { s.cull.distance_m };
            children.push(chain_node(&mut asm.scene, &nodes, &coverages(radius, &switches, Some(cull), view)));
        }
        asm.scene.nodes.push(Node { name: s.name.to_string(), children, ..Node::default() });
        asm.scene.roots.push(asm.scene.nodes.len() - 1);
    }
    Ok(terrain_meshes)
}

/// MSFT_screencoverage of a chain whose level k switches in at `switches[k]` (nearest distance, m)
/// for a sphere of `radius`: coverage k is the sphere's when its nearest point is at level k+1's
/// switch (the last: at the cull distance, or 0 when never culled). Never increasing: a level
/// whose switch equals the next one's gets an empty range.
fn coverages(radius: f64, switches: &[f64], cull: Option<f64>, view: &LodView) -> Vec<f32> {
    let mut out: Vec<f32> = switches
        .iter()
        .skip(1)
        .map(|&d| lod_screen_coverage(radius, d, view) as f32)
        .chain(std::iter::once(cull.map_or(0.0, |d| lod_screen_coverage(radius, d, view) as f32)))
        .collect();
    for k in 1..out.len() {
        out[k] = out[k].min(out[k - 1]);
    }
    out
}

/// Makes `levels[0]` the chain's node (MSFT_lod naming the others, with `coverage`) and returns it;
/// a chain of one level is a plain node.
fn chain_node(scene: &mut Scene, levels: &[usize], coverage: &[f32]) -> usize {
    let base = levels[0];
    if levels.len() > 1 {
        scene.nodes[base].lods = levels[1..].to_vec();
        scene.nodes[base].lod_screen_coverage = coverage.to_vec();
    }
    base
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn bounds(points: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coverages_fall_with_the_switch_distances_and_end_at_the_cull() {
        let view = LodView::default();
        let c = coverages(5.0, &[0.0, 20.0, 80.0, 80.0], Some(300.0), &view);
        assert_eq!(c.len(), 4);
        assert!(c.windows(2).all(|w| w[1] <= w[0]), "{c:?}");
        assert_eq!(c[1], c[2], "equal switches: an empty range for the level between");
        assert!(c[3] > 0.0 && (c[3] as f64 - lod_screen_coverage(5.0, 300.0, &view)).abs() < 1e-9);
        assert_eq!(coverages(5.0, &[0.0, 20.0], None, &view)[1], 0.0, "never culled");
    }
}
