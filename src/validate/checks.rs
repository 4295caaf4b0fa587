//! The invariants every output promises, checked on the re-imported scene: indices in range, finite
//! attributes, unit normals and rotations, no degenerate triangles, exact POSITION min/max, LoD
//! coverages, and (for terrain) triangles facing +Y after their node's world transform.

use glam::{DMat4, DQuat, DVec3};

use super::options::{ValidateOptions, MAX_LISTED, NORMAL_TOLERANCE};
use super::report::{issue, Issue, Severity};
use crate::mesh::{Bounds, Primitive, PrimitiveMode, Scene};

/// Collects one kind of problem for one primitive, listing the first few.
struct Finder<'a> {
    issues: &'a mut Vec<Issue>,
    loc: String,
    what: &'static str,
    count: usize,
}

impl Finder<'_> {
    fn found(&mut self, at: String, message: String) {
        if self.count < MAX_LISTED {
            self.issues.push(issue(Severity::Error, format!("{} {at}", self.loc), message));
        }
        self.count += 1;
    }
}

impl Drop for Finder<'_> {
    fn drop(&mut self) {
        if self.count > MAX_LISTED {
            let more = self.count - MAX_LISTED;
            self.issues.push(issue(Severity::Error, self.loc.clone(), format!("… and {more} more {}", self.what)));
        }
    }
}

pub(super) fn check_scene_data(
    scene: &Scene,
    declared: &[Vec<Option<Bounds>>],
    quantized: &[bool],
    opts: &ValidateOptions,
    issues: &mut Vec<Issue>,
) {
    for (mi, mesh) in scene.meshes.iter().enumerate() {
        for (pi, p) in mesh.primitives.iter().enumerate() {
            let loc = format!("mesh {mi} {:?} primitive {pi}", mesh.name);
            check_primitive(p, &loc, quantized.get(mi).copied().unwrap_or(false), issues);
            if let Some(Some(d)) = declared.get(mi).and_then(|m| m.get(pi)) {
                if let Some(b) = p.bounds() {
                    if b.min != d.min || b.max != d.max {
                        issues.push(issue(
                            Severity::Error,
                            &loc,
                            format!(
                                "POSITION min/max {:?}..{:?} differ from the data's {:?}..{:?}",
                                d.min, d.max, b.min, b.max
                            ),
                        ));
                    }
                }
            }
        }
    }
    for (ni, node) in scene.nodes.iter().enumerate() {
        let loc = format!("node {ni} {:?}", node.name);
        if let Some(inst) = &node.instances {
            let lens = [inst.translations.len(), inst.rotations.len(), inst.scales.len()];
            if lens.iter().any(|&l| l != 0 && l != inst.len()) {
                issues.push(issue(Severity::Error, &loc, format!("instance arrays have different lengths {lens:?}")));
            }
            let finite = inst
                .translations
                .iter()
                .flatten()
                .chain(inst.rotations.iter().flatten())
                .chain(inst.scales.iter().flatten());
            if !finite.into_iter().all(|x| x.is_finite()) {
                issues.push(issue(Severity::Error, &loc, "instance transform is not finite"));
            }
            if let Some(k) = inst.rotations.iter().position(|r| (length(r) - 1.0).abs() > NORMAL_TOLERANCE) {
                issues.push(issue(
                    Severity::Error,
                    &loc,
                    format!("instance {k} rotation {:?} is not a unit quaternion", inst.rotations[k]),
                ));
            }
        }
        if !node.lod_screen_coverage.is_empty() {
            let c = &node.lod_screen_coverage;
            if c.len() != node.lods.len() && c.len() != node.lods.len() + 1 {
                issues.push(issue(
                    Severity::Warning,
                    &loc,
                    format!("{} screen coverages for {} LoD levels", c.len(), node.lods.len()),
                ));
            }
            if c.windows(2).any(|w| w[1] > w[0]) {
                issues.push(issue(Severity::Warning, &loc, "screen coverages should decrease level by level"));
            }
        }
    }
    if opts.up_facing {
        check_up_facing(scene, issues);
    }
}

fn length(v: &[f32]) -> f64 {
    v.iter().map(|&x| x as f64 * x as f64).sum::<f64>().sqrt()
}

/// `quantized`: positions stored as integers (KHR_mesh_quantization), where a sliver thinner than
/// a grid step collapses to zero area: it draws nothing, and is reported as a warning.
fn check_primitive(p: &Primitive, loc: &str, quantized: bool, issues: &mut Vec<Issue>) {
    let n = p.positions.len();
    let points = p.mode == PrimitiveMode::Points;
    if !points && !p.indices.len().is_multiple_of(3) {
        issues.push(issue(
            Severity::Error,
            loc,
            format!("{} indices is not a whole number of triangles", p.indices.len()),
        ));
    }
    {
        let mut f = Finder { issues, loc: loc.into(), what: "indices out of range", count: 0 };
        for (k, &i) in p.indices.iter().enumerate() {
            if i as usize >= n {
                f.found(format!("index {k}"), format!("is {i}, but there are {n} vertices"));
            }
        }
    }
    for (name, values) in [
        ("POSITION", p.positions.iter().flat_map(|v| v.to_vec()).collect::<Vec<f32>>()),
        ("NORMAL", p.normals.iter().flat_map(|v| v.to_vec()).collect()),
        ("TEXCOORD_0", p.uvs.iter().flat_map(|v| v.to_vec()).collect()),
        ("COLOR_0", p.colors.iter().flat_map(|v| v.to_vec()).collect()),
    ] {
        let dims = match name {
            "TEXCOORD_0" => 2,
            "COLOR_0" => 4,
            _ => 3,
        };
        let mut f = Finder { issues, loc: loc.into(), what: "non-finite values", count: 0 };
        for (k, c) in values.chunks(dims).enumerate() {
            if !c.iter().all(|x| x.is_finite()) {
                f.found(format!("vertex {k}"), format!("{name} {c:?} is not finite"));
            }
        }
    }
    {
        let mut f = Finder { issues, loc: loc.into(), what: "non-unit normals", count: 0 };
        for (k, nrm) in p.normals.iter().enumerate() {
            let len = length(nrm);
            if len.is_finite() && (len - 1.0).abs() > NORMAL_TOLERANCE {
                f.found(format!("vertex {k}"), format!("normal {nrm:?} has length {len:.6}"));
            }
        }
    }
    if points {
        return;
    }
    let mut collapsed = 0usize;
    let mut f = Finder { issues, loc: loc.into(), what: "degenerate triangles", count: 0 };
    for t in 0..p.indices.len() / 3 {
        let [a, b, c] = [p.indices[3 * t], p.indices[3 * t + 1], p.indices[3 * t + 2]];
        if [a, b, c].iter().any(|&i| i as usize >= n) {
            continue;
        }
        if a == b || b == c || a == c {
            f.found(format!("triangle {t}"), format!("repeats a vertex ({a}, {b}, {c})"));
            continue;
        }
        if triangle_is_flat(p, t) {
            if quantized {
                collapsed += 1;
            } else {
                f.found(format!("triangle {t}"), "has zero area".into());
            }
        }
    }
    drop(f);
    if collapsed > 0 {
        issues.push(issue(
            Severity::Warning,
            loc,
            format!("{collapsed} triangles have zero area on the 16-bit position grid (slivers thinner than a grid step; they draw nothing)"),
        ));
    }
}

/// Zero area: the cross product is negligible against the squared edge lengths (f64, so an exact
/// zero for collinear f32 points stays zero and a sliver of real area is not flagged).
fn triangle_is_flat(p: &Primitive, t: usize) -> bool {
    let c = p.triangle_cross(t);
    let corner = |k: usize| {
        let v = p.positions[p.indices[3 * t + k] as usize];
        DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64)
    };
    let (a, b, cc) = (corner(0), corner(1), corner(2));
    let scale = (b - a).length_squared().max((cc - a).length_squared()).max((cc - b).length_squared());
    let area2 = DVec3::from(c).length();
    area2.is_finite() && area2 <= 1e-12 * scale
}

/// World matrix of every node reachable from the roots (None for the others).
fn world_matrices(scene: &Scene) -> Vec<Option<DMat4>> {
    let mut world = vec![None; scene.nodes.len()];
    let mut stack: Vec<(usize, DMat4)> = scene.roots.iter().rev().map(|&r| (r, DMat4::IDENTITY)).collect();
    while let Some((n, parent)) = stack.pop() {
        let Some(node) = scene.nodes.get(n) else { continue };
        if world[n].is_some() {
            continue; // a cycle or a node with two parents: the file checks report those
        }
        let d = |v: [f32; 3]| DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
        let r = node.rotation;
        let local = DMat4::from_scale_rotation_translation(
            d(node.scale),
            DQuat::from_xyzw(r[0] as f64, r[1] as f64, r[2] as f64, r[3] as f64),
            d(node.translation),
        );
        let m = parent * local;
        world[n] = Some(m);
        for &c in node.children.iter().rev() {
            stack.push((c, m));
        }
    }
    world
}

fn check_up_facing(scene: &Scene, issues: &mut Vec<Issue>) {
    let world = world_matrices(scene);
    for (ni, node) in scene.nodes.iter().enumerate() {
        let (Some(mi), Some(m)) = (node.mesh, world[ni]) else { continue };
        let Some(mesh) = scene.meshes.get(mi) else { continue };
        for (pi, p) in mesh.primitives.iter().enumerate() {
            let loc = format!("node {ni} {:?} mesh {:?} primitive {pi}", node.name, mesh.name);
            let mut f = Finder { issues, loc, what: "triangles not facing up", count: 0 };
            let n = p.positions.len();
            for t in 0..p.indices.len() / 3 {
                let idx = [p.indices[3 * t], p.indices[3 * t + 1], p.indices[3 * t + 2]];
                if idx.iter().any(|&i| i as usize >= n) || triangle_is_flat(p, t) {
                    continue; // reported by the primitive checks
                }
                let w = |i: u32| {
                    let v = p.positions[i as usize];
                    m.transform_point3(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
                };
                let (a, b, c) = (w(idx[0]), w(idx[1]), w(idx[2]));
                let normal = (b - a).cross(c - a);
                if normal.y.is_nan() || normal.y <= 0.0 {
                    f.found(
                        format!("triangle {t}"),
                        format!("faces {:?}, not up (+Y)", normal.normalize_or_zero().to_array()),
                    );
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Mesh;

    #[test]
    fn flat_and_repeated_triangles_are_degenerate() {
        let p = Primitive {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            indices: vec![0, 1, 2, 0, 0, 3, 0, 3, 1],
            ..Primitive::default()
        };
        let mut issues = Vec::new();
        check_primitive(&p, "p", false, &mut issues);
        assert_eq!(issues.len(), 2, "{issues:?}");
        assert!(issues[0].message.contains("zero area"));
        assert!(issues[1].message.contains("repeats"));
    }

    #[test]
    fn up_facing_uses_world_transform() {
        // counter-clockwise seen from +Y: faces up
        let p = Primitive {
            positions: vec![[0.0; 3], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]],
            indices: vec![0, 1, 2],
            ..Primitive::default()
        };
        let mut scene = Scene::default();
        let n = scene.add_mesh_node(Mesh { name: "t".into(), primitives: vec![p], extras: None });
        let mut issues = Vec::new();
        check_up_facing(&scene, &mut issues);
        assert!(issues.is_empty(), "{issues:?}");
        // turned upside down by its node: 180° about X
        scene.nodes[n].rotation = [1.0, 0.0, 0.0, 0.0];
        check_up_facing(&scene, &mut issues);
        assert_eq!(issues.len(), 1, "{issues:?}");
    }
}
