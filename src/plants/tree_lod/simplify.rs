//! meshoptimizer's simplifiers on our meshes: edge collapse under an error bound (LoD1, the branches
//! LoD2 keeps), sloppy vertex clustering (a mesh asset's LoD2), and the triangles of a tree's finest
//! branch level (what LoD2's cards stand for).

use crate::mesh::{CustomAttribute, Mesh, Primitive};
use crate::meshopt_guard::{self, FfiError};
use crate::plants::tree::{is_flat, TreeMesh};

/// LoD1 and LoD2 keep about this fraction of their input's triangles...
pub(super) const SIMPLIFY_RATIO: f64 = 0.5;
/// ...unless that would move the surface more than the first of these fractions of the mesh's
/// extent; the next ones are tried only when a level would not have fewer triangles than the one
/// before (small polygon-only plants).
const SIMPLIFY_MAX_ERRORS: [f32; 4] = [0.01, 0.05, 0.25, 1.0];

/// LoD2 of a mesh asset keeps about this fraction of LoD0's triangles.
pub const SLOPPY_RATIO: f64 = 0.1;

/// The triangles `keep` picks from `p`, with only the vertices they use (in first-use order).
pub(super) fn subset(p: &Primitive, keep: impl Fn(usize) -> bool) -> Primitive {
    let mut remap = vec![u32::MAX; p.positions.len()];
    let mut out = Primitive { material: p.material, ..Primitive::default() };
    for t in (0..p.triangle_count()).filter(|&t| keep(t)) {
        for k in 0..3 {
            let i = p.indices[3 * t + k] as usize;
            if remap[i] == u32::MAX {
                remap[i] = out.positions.len() as u32;
                out.positions.push(p.positions[i]);
                if let Some(n) = p.normals.get(i) {
                    out.normals.push(*n);
                }
                if let Some(uv) = p.uvs.get(i) {
                    out.uvs.push(*uv);
                }
                if let Some(t) = p.tangents.get(i) {
                    out.tangents.push(*t);
                }
                if let Some(c) = p.colors.get(i) {
                    out.colors.push(*c);
                }
                for (k, c) in p.custom.iter().enumerate() {
                    if out.custom.len() <= k {
                        out.custom.push(CustomAttribute {
                            name: c.name.clone(),
                            values: Vec::new(),
                            unit_bytes: c.unit_bytes,
                            range: c.range,
                        });
                    }
                    if let Some(v) = c.values.get(i) {
                        out.custom[k].values.push(*v);
                    }
                }
            }
            out.indices.push(remap[i]);
        }
    }
    out
}

/// meshoptimizer's edge-collapse simplification of every primitive to about `ratio` of its
/// triangles (never past `max_error` of the extent), zero-area results dropped, then reordered for
/// the vertex cache and fetch.
fn simplify(mesh: &Mesh, ratio: f64, max_error: f32) -> Result<Mesh, FfiError> {
    let mut out = Mesh { name: mesh.name.clone(), primitives: Vec::new(), extras: None };
    for p in &mesh.primitives {
        // point leaves stay as they are (a point is already as cheap as it gets)
        if p.is_points() {
            out.primitives.push(p.clone());
            continue;
        }
        let target = ((p.indices.len() as f64 * ratio) as usize / 3) * 3;
        let indices = meshopt_guard::simplify(&p.indices, &p.positions, target, max_error)?;
        if let Some(q) = simplified(p, &indices)? {
            out.primitives.push(q);
        }
    }
    Ok(out)
}

/// `p` with the triangles `indices` (those of zero area dropped), its unused vertices removed and
/// reordered for the vertex cache and fetch; `None` when no triangle is left.
fn simplified(p: &Primitive, indices: &[u32]) -> Result<Option<Primitive>, FfiError> {
    let kept: Vec<u32> =
        indices.chunks_exact(3).filter(|t| !is_flat(&p.positions, [t[0], t[1], t[2]])).flatten().copied().collect();
    if kept.is_empty() {
        return Ok(None);
    }
    // compact first: Primitive::optimize_for_gpu assumes every vertex is used (meshopt's fetch
    // remap is as long as the used vertices, not all of them)
    let mut q = subset(&Primitive { indices: kept, ..p.clone() }, |_| true);
    q.optimize_for_gpu()?;
    Ok(Some(q))
}

/// The triangles of branch levels above `max_kept` (what LoD2 drops), per primitive.
pub(super) fn finer_than(tree: &TreeMesh, max_kept: u32) -> Mesh {
    let mesh = tree.mesh();
    let mut out = Mesh { name: String::new(), primitives: Vec::new(), extras: None };
    for (p, ranges) in mesh.primitives.iter().zip(&tree.levels) {
        let Some(k) = ranges.levels.iter().position(|&l| l > max_kept) else { continue };
        let first = ranges.index_starts[k] as usize / 3;
        let q = subset(p, |t| t >= first);
        if !q.indices.is_empty() {
            out.primitives.push(q);
        }
    }
    out
}

/// [`simplify`] with the smallest error bound of SIMPLIFY_MAX_ERRORS that leaves fewer than
/// `below` triangles (the largest bound's result when none does).
pub(super) fn simplify_below(mesh: &Mesh, ratio: f64, below: usize) -> Result<Mesh, FfiError> {
    let mut out = Mesh::default();
    for max_error in SIMPLIFY_MAX_ERRORS {
        out = simplify(mesh, ratio, max_error)?;
        if out.triangle_count() < below {
            break;
        }
    }
    Ok(out)
}

/// meshoptimizer's sloppy (vertex-clustering) decimation of every triangle primitive to about
/// `ratio` of its triangles (more when that would erase the primitive): no topology kept, so it
/// reaches targets edge collapse cannot; zero-area results dropped, then reordered for the vertex
/// cache and fetch.
pub(super) fn simplify_sloppy(mesh: &Mesh, ratio: f64) -> Result<Mesh, FfiError> {
    let mut out = Mesh { name: mesh.name.clone(), primitives: Vec::new(), extras: None };
    for p in mesh.primitives.iter().filter(|p| !p.is_points()) {
        // vertex clustering can erase a thin part (a trunk, a card) entirely: then ask for more
        let mut r = ratio;
        while r < 1.0 {
            let target = ((p.indices.len() as f64 * r) as usize / 3).max(1) * 3;
            if let Some(q) = simplified(p, &meshopt_guard::simplify_sloppy(&p.indices, &p.positions, target)?)? {
                out.primitives.push(q);
                break;
            }
            r *= 2.0;
        }
    }
    Ok(out)
}
