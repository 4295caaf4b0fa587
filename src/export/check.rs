//! The checks every writer relies on before it writes a byte, and the names OBJ/MTL can carry.

use crate::export::error::SceneProblem;
use crate::mesh::{AlphaMode, Scene};

/// A normal or quaternion counts as unit length when its length is within this of 1. Stricter
/// than the Khronos validator (2.0.0-dev.3.10 accepts normals of length 1.006, rejects 1.01);
/// stages renormalise in f32 and stay far inside it.
pub const UNIT_LENGTH_TOLERANCE: f32 = 5e-4;

/// Checks everything a writer relies on, so writers can index without panicking and the output is
/// valid glTF: indices in range, attribute arrays as long as `positions`, finite numbers, unit
/// normals and rotations, factors in 0..1, PNG textures, and a node graph that is a forest.
pub fn check_scene(scene: &Scene) -> Result<(), SceneProblem> {
    let bad = |s: String| Err(SceneProblem(s));
    let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
    let unit = |v: &[f32]| {
        let len = v.iter().map(|&x| (x as f64) * (x as f64)).sum::<f64>().sqrt();
        (len - 1.0).abs() <= UNIT_LENGTH_TOLERANCE as f64
    };
    // glTF also bounds every rotation component to -1..1 (VALUE_NOT_IN_RANGE otherwise)
    let unit_quat = |q: &[f32; 4]| unit(q) && q.iter().all(|c| c.abs() <= 1.0);
    for (ti, t) in scene.textures.iter().enumerate() {
        if !t.png.starts_with(b"\x89PNG\r\n\x1a\n") {
            return bad(format!("texture {ti} ({:?}) is not PNG data", t.name));
        }
    }
    for (mi, m) in scene.materials.iter().enumerate() {
        let what = format!("material {mi} ({:?})", m.name);
        for t in m.textures() {
            if t >= scene.textures.len() {
                return bad(format!("{what} uses texture {t}, but the scene has {}", scene.textures.len()));
            }
        }
        let in01 = |x: f32| (0.0..=1.0).contains(&x);
        if !m.base_color.iter().all(|&x| in01(x)) || !in01(m.metallic) || !in01(m.roughness) {
            return bad(format!("{what} has a colour, metallic or roughness factor outside 0..1"));
        }
        if let AlphaMode::Mask { cutoff } = m.alpha_mode {
            if !(cutoff.is_finite() && cutoff >= 0.0) {
                return bad(format!("{what} has alpha cutoff {cutoff}; it must be a number ≥ 0"));
            }
        }
    }
    for (mi, mesh) in scene.meshes.iter().enumerate() {
        if mesh.primitives.is_empty() {
            return bad(format!("mesh {mi} ({:?}) has no primitives", mesh.name));
        }
        for (pi, p) in mesh.primitives.iter().enumerate() {
            let what = format!("mesh {mi} ({:?}) primitive {pi}", mesh.name);
            let n = p.positions.len();
            let points = p.mode == crate::mesh::PrimitiveMode::Points;
            if n == 0 || (p.indices.is_empty() && !points) {
                return bad(format!("{what} is empty (no vertices or no triangles); drop it before export"));
            }
            if !points && !p.indices.len().is_multiple_of(3) {
                return bad(format!("{what} has {} indices, not a multiple of 3", p.indices.len()));
            }
            if n > u32::MAX as usize - 1 {
                return bad(format!("{what} has {n} vertices, more than 32-bit indices can address"));
            }
            if let Some(i) = p.indices.iter().position(|&i| i as usize >= n) {
                return bad(format!("{what}: index {i} is {} but there are {n} vertices", p.indices[i]));
            }
            for (name, len) in [("normals", p.normals.len()), ("uvs", p.uvs.len()), ("colors", p.colors.len())] {
                if len != 0 && len != n {
                    return bad(format!("{what} has {len} {name} for {n} positions"));
                }
            }
            for (ci, c) in p.custom.iter().enumerate() {
                let valid_name = c.name.len() > 1
                    && c.name.starts_with('_')
                    && c.name[1..].bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_');
                if !valid_name {
                    return bad(format!(
                        "{what}: custom attribute {ci} is named {:?}; names are `_` then letters, digits or `_`",
                        c.name
                    ));
                }
                if p.custom[..ci].iter().any(|o| o.name == c.name) {
                    return bad(format!("{what}: custom attribute {:?} appears twice", c.name));
                }
                if c.values.len() != n {
                    return bad(format!("{what} has {} values of {} for {n} positions", c.values.len(), c.name));
                }
                if let Some(v) = c.values.iter().position(|v| !finite(v)) {
                    return bad(format!("{what}: {} value {v} is not finite ({:?})", c.name, c.values[v]));
                }
            }
            if let Some(v) = p.positions.iter().position(|v| !finite(v)) {
                return bad(format!("{what}: position {v} is not finite ({:?})", p.positions[v]));
            }
            if let Some(v) = p.normals.iter().position(|v| !(finite(v) && unit(v))) {
                return bad(format!("{what}: normal {v} {:?} is not unit length", p.normals[v]));
            }
            if let Some(v) = p.uvs.iter().position(|v| !finite(v)) {
                return bad(format!("{what}: uv {v} is not finite ({:?})", p.uvs[v]));
            }
            if let Some(v) = p.colors.iter().position(|v| !finite(v)) {
                return bad(format!("{what}: colour {v} is not finite ({:?})", p.colors[v]));
            }
            if let Some(m) = p.material {
                if m >= scene.materials.len() {
                    return bad(format!("{what} uses material {m}, but the scene has {}", scene.materials.len()));
                }
            }
        }
    }
    let node_count = scene.nodes.len();
    let mut parent: Vec<Option<usize>> = vec![None; node_count];
    for (ni, node) in scene.nodes.iter().enumerate() {
        let what = format!("node {ni} ({:?})", node.name);
        if let Some(m) = node.mesh {
            if m >= scene.meshes.len() {
                return bad(format!("{what} shows mesh {m}, but the scene has {}", scene.meshes.len()));
            }
        }
        if !finite(&node.translation) || !finite(&node.rotation) || !finite(&node.scale) {
            return bad(format!("{what} has a non-finite translation, rotation or scale"));
        }
        if !unit_quat(&node.rotation) {
            return bad(format!("{what} has rotation {:?}, not a unit quaternion", node.rotation));
        }
        for &c in &node.children {
            if c >= node_count {
                return bad(format!("{what} has child {c}, but the scene has {node_count} nodes"));
            }
            if let Some(p) = parent[c] {
                return bad(format!("node {c} is a child of both node {p} and node {ni}"));
            }
            parent[c] = Some(ni);
        }
        if let Some(inst) = &node.instances {
            let lens = [inst.translations.len(), inst.rotations.len(), inst.scales.len()];
            let count = inst.len();
            if lens.iter().any(|&l| l != 0 && l != count) {
                return bad(format!("{what} has instance arrays of different lengths {lens:?}"));
            }
            if count > 0 && node.mesh.is_none() {
                return bad(format!("{what} has instances but no mesh to instance"));
            }
            let all_finite = inst.translations.iter().all(|v| finite(v))
                && inst.rotations.iter().all(|v| finite(v))
                && inst.scales.iter().all(|v| finite(v));
            if !all_finite {
                return bad(format!("{what} has a non-finite instance transform"));
            }
            if let Some(k) = inst.rotations.iter().position(|r| !unit_quat(r)) {
                return bad(format!("{what}: instance {k} rotation {:?} is not a unit quaternion", inst.rotations[k]));
            }
        }
        for &l in &node.lods {
            if l >= node_count || l == ni {
                return bad(format!("{what} has level of detail node {l}, which is itself or missing"));
            }
        }
        if !finite(&node.lod_screen_coverage) {
            return bad(format!("{what} has a non-finite screen coverage"));
        }
        if !node.lod_screen_coverage.is_empty() && node.lods.is_empty() {
            return bad(format!("{what} has screen coverages but no levels of detail"));
        }
        if let Some(extras) = &node.extras {
            if !node.lod_screen_coverage.is_empty() && !extras.is_object() {
                return bad(format!("{what} has LoD screen coverage, so its extras must be a JSON object"));
            }
        }
    }
    for &r in &scene.roots {
        if r >= node_count {
            return bad(format!("root {r} is not a node (the scene has {node_count})"));
        }
        if let Some(p) = parent[r] {
            return bad(format!("root node {r} is also a child of node {p}"));
        }
    }
    let mut sorted_roots = scene.roots.clone();
    sorted_roots.sort_unstable();
    if sorted_roots.windows(2).any(|w| w[0] == w[1]) {
        return bad("a node is listed twice among the roots".into());
    }
    // A cycle shows as a walk up the parents that is longer than the node count.
    for start in 0..node_count {
        let (mut at, mut steps) = (start, 0);
        while let Some(p) = parent[at] {
            at = p;
            steps += 1;
            if steps > node_count {
                return bad(format!("node {start} is its own ancestor (the node graph has a cycle)"));
            }
        }
    }
    Ok(())
}

/// A name safe for one OBJ/MTL token and a file name: ASCII letters, digits, `-`, `_` and `.`;
/// anything else becomes `_`.
pub(crate) fn sanitize_name(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') { c } else { '_' }).collect()
}
