//! Compaction before writing glTF: a file holds what its scene shows, each thing once.
//!
//! Nodes reachable from the roots (through children, or as MSFT_lod levels) are kept, then the
//! meshes kept nodes show, the materials their primitives use and the textures those sample;
//! everything else is dropped. Equal textures, then equal materials, are stored once: importers copy
//! a repeated material per use (Blender's `bark.001`, `.002`, … on a LoD chain). Kept objects keep
//! their order of first appearance, so one scene always gives the same bytes, and a scene with
//! nothing to drop or merge is passed through untouched.
//!
//! Nodes reached only as MSFT_lod levels (not under the roots) are reported as `lod_roots`: the
//! glTF writer puts them in a second, non-default glTF scene, where they count as used (the Khronos
//! validator) and importers that ignore MSFT_lod do not instantiate them: Blender (4.5, 5.x) links
//! nodes of no scene into a visible "Orphan Nodes" collection, but a non-default scene's nodes into
//! another Blender scene or an excluded collection; three.js and Babylon.js show the default scene.

use std::borrow::Cow;

use crate::mesh::Scene;

/// A scene ready to write and the nodes that form its second glTF scene.
#[derive(Debug)]
pub struct Compacted<'a> {
    pub scene: Cow<'a, Scene>,
    /// Roots of the nodes shown only as coarser levels of detail (indices into `scene.nodes`).
    pub lod_roots: Vec<usize>,
}

/// Figures of what [`compact`] dropped and merged (for tests and reports).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CompactFigures {
    pub nodes_dropped: usize,
    pub meshes_dropped: usize,
    pub materials_dropped: usize,
    pub textures_dropped: usize,
}

/// `scene` without unreachable or unused objects and with equal materials and textures merged.
/// Expects a scene that passed `check_scene` (indices in range, tree-shaped node graph).
pub fn compact(scene: &Scene) -> (Compacted<'_>, CompactFigures) {
    let n = scene.nodes.len();
    // nodes under the roots, then those reached only as levels of detail (and their children)
    let mut in_tree = vec![false; n];
    let mut stack: Vec<usize> = scene.roots.clone();
    while let Some(i) = stack.pop() {
        if !std::mem::replace(&mut in_tree[i], true) {
            stack.extend(&scene.nodes[i].children);
        }
    }
    let mut in_lods = vec![false; n];
    let mut stack: Vec<usize> =
        (0..n).filter(|&i| in_tree[i]).flat_map(|i| scene.nodes[i].lods.iter().copied()).collect();
    while let Some(i) = stack.pop() {
        if in_tree[i] || std::mem::replace(&mut in_lods[i], true) {
            continue;
        }
        stack.extend(&scene.nodes[i].children);
        stack.extend(&scene.nodes[i].lods);
    }
    let keep_node: Vec<bool> = (0..n).map(|i| in_tree[i] || in_lods[i]).collect();
    let mut is_child = vec![false; n];
    for (i, node) in scene.nodes.iter().enumerate() {
        if keep_node[i] {
            for &c in &node.children {
                is_child[c] = true;
            }
        }
    }

    // equal textures and materials: each maps to its first equal one
    let texture_canon: Vec<usize> = (0..scene.textures.len())
        .map(|t| (0..t).find(|&u| scene.textures[u] == scene.textures[t]).unwrap_or(t))
        .collect();
    let remapped_materials: Vec<_> =
        scene.materials.iter().map(|m| m.with_textures(|t| Some(texture_canon[t]))).collect();
    let material_canon: Vec<usize> = (0..remapped_materials.len())
        .map(|m| (0..m).find(|&k| remapped_materials[k] == remapped_materials[m]).unwrap_or(m))
        .collect();

    // what the kept nodes use
    let mut mesh_used = vec![false; scene.meshes.len()];
    for (i, node) in scene.nodes.iter().enumerate() {
        if let (true, Some(m)) = (keep_node[i], node.mesh) {
            mesh_used[m] = true;
        }
    }
    let mut material_used = vec![false; scene.materials.len()];
    for (m, mesh) in scene.meshes.iter().enumerate() {
        if mesh_used[m] {
            for p in &mesh.primitives {
                if let Some(k) = p.material {
                    material_used[material_canon[k]] = true;
                }
            }
        }
    }
    let mut texture_used = vec![false; scene.textures.len()];
    for (k, m) in remapped_materials.iter().enumerate() {
        if material_used[k] {
            for t in m.textures() {
                texture_used[t] = true;
            }
        }
    }

    let count_false = |v: &[bool]| v.iter().filter(|&&b| !b).count();
    let figures = CompactFigures {
        nodes_dropped: count_false(&keep_node),
        meshes_dropped: count_false(&mesh_used),
        materials_dropped: count_false(&material_used),
        textures_dropped: count_false(&texture_used),
    };
    let lod_roots_of = |map: &dyn Fn(usize) -> usize| -> Vec<usize> {
        (0..n).filter(|&i| in_lods[i] && !is_child[i]).map(map).collect()
    };
    if figures == CompactFigures::default() {
        return (Compacted { scene: Cow::Borrowed(scene), lod_roots: lod_roots_of(&|i| i) }, figures);
    }

    // new indices: kept objects in their original order
    let renumber = |keep: &[bool]| -> Vec<Option<usize>> {
        let mut next = 0;
        keep.iter()
            .map(|&k| {
                k.then(|| {
                    next += 1;
                    next - 1
                })
            })
            .collect()
    };
    let node_at = renumber(&keep_node);
    let mesh_at = renumber(&mesh_used);
    let material_at = renumber(&material_used);
    let texture_at = renumber(&texture_used);
    let node_index = |i: usize| node_at[i].expect("kept nodes reach only kept nodes");

    let mut out = Scene { name: scene.name.clone(), extras: scene.extras.clone(), ..Scene::default() };
    out.textures = scene.textures.iter().zip(&texture_used).filter(|(_, &u)| u).map(|(t, _)| t.clone()).collect();
    out.materials = remapped_materials
        .iter()
        .zip(&material_used)
        .filter(|(_, &u)| u)
        .map(|(m, _)| m.with_textures(|t| Some(texture_at[t].expect("a used material's texture is kept"))))
        .collect();
    out.meshes = scene
        .meshes
        .iter()
        .zip(&mesh_used)
        .filter(|(_, &u)| u)
        .map(|(mesh, _)| {
            let mut mesh = mesh.clone();
            for p in &mut mesh.primitives {
                p.material =
                    p.material.map(|k| material_at[material_canon[k]].expect("a used primitive's material is kept"));
            }
            mesh
        })
        .collect();
    out.nodes = scene
        .nodes
        .iter()
        .zip(&keep_node)
        .filter(|(_, &k)| k)
        .map(|(node, _)| {
            let mut node = node.clone();
            node.mesh = node.mesh.map(|m| mesh_at[m].expect("a kept node's mesh is kept"));
            node.children = node.children.iter().map(|&c| node_index(c)).collect();
            node.lods = node.lods.iter().map(|&l| node_index(l)).collect();
            node
        })
        .collect();
    out.roots = scene.roots.iter().map(|&r| node_index(r)).collect();
    let lod_roots = lod_roots_of(&node_index);
    (Compacted { scene: Cow::Owned(out), lod_roots }, figures)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Material, Mesh, Node, Primitive, Texture};

    fn quad_mesh(name: &str, material: usize) -> Mesh {
        Mesh {
            name: name.into(),
            primitives: vec![Primitive {
                positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                indices: vec![0, 1, 2],
                material: Some(material),
                ..Primitive::default()
            }],
            extras: None,
        }
    }

    fn chain() -> Scene {
        let tex = |b: u8| Texture { name: "atlas".into(), png: [b"\x89PNG\r\n\x1a\n".as_slice(), &[b; 4]].concat() };
        let mat = |t: usize| Material { name: "bark".into(), base_color_texture: Some(t), ..Material::default() };
        let mut s = Scene {
            name: "chain".into(),
            textures: vec![tex(1), tex(1), tex(2)],
            materials: vec![mat(0), mat(1), mat(2), Material::default()],
            meshes: vec![quad_mesh("lod0", 0), quad_mesh("lod1", 1), quad_mesh("unused", 2), quad_mesh("lod2", 3)],
            ..Scene::default()
        };
        s.nodes = vec![
            Node { name: "lod0".into(), mesh: Some(0), lods: vec![1, 3], ..Node::default() },
            Node { name: "lod1".into(), mesh: Some(1), ..Node::default() },
            Node { name: "orphan".into(), mesh: Some(2), ..Node::default() },
            Node { name: "lod2".into(), mesh: Some(3), ..Node::default() },
        ];
        s.roots = vec![0];
        s
    }

    #[test]
    fn drops_what_nothing_shows_and_merges_equal_materials() {
        let s = chain();
        let (c, f) = compact(&s);
        assert_eq!(
            f,
            CompactFigures { nodes_dropped: 1, meshes_dropped: 1, materials_dropped: 2, textures_dropped: 2 }
        );
        let out = c.scene.as_ref();
        assert_eq!(out.nodes.iter().map(|n| n.name.as_str()).collect::<Vec<_>>(), ["lod0", "lod1", "lod2"]);
        assert_eq!(out.nodes[0].lods, vec![1, 2]);
        assert_eq!(out.meshes.iter().map(|m| m.name.as_str()).collect::<Vec<_>>(), ["lod0", "lod1", "lod2"]);
        // lod0 and lod1 used equal materials over equal textures: one material, one texture
        assert_eq!(out.textures.len(), 1);
        assert_eq!(out.materials.len(), 2);
        assert_eq!(out.meshes[0].primitives[0].material, Some(0));
        assert_eq!(out.meshes[1].primitives[0].material, Some(0));
        assert_eq!(out.meshes[2].primitives[0].material, Some(1));
        assert_eq!(c.lod_roots, vec![1, 2]);
        crate::export::check_scene(out).unwrap();
    }

    #[test]
    fn a_scene_with_nothing_to_drop_passes_through() {
        let mut s = chain();
        s.nodes.remove(2);
        s.nodes[0].lods = vec![1, 2];
        s.meshes.remove(2);
        s.nodes[2].mesh = Some(2);
        s.textures.truncate(1);
        s.materials = vec![
            Material { name: "bark".into(), base_color_texture: Some(0), ..Material::default() },
            Material::default(),
        ];
        for (m, k) in s.meshes.iter_mut().zip([0, 0, 1]) {
            m.primitives[0].material = Some(k);
        }
        let (c, f) = compact(&s);
        assert_eq!(f, CompactFigures::default());
        assert!(matches!(c.scene, Cow::Borrowed(_)));
        assert_eq!(c.lod_roots, vec![1, 2]);
    }

    #[test]
    fn children_of_a_lod_node_are_not_lod_roots() {
        let mut s = chain();
        s.nodes[1].children = vec![2];
        let (c, f) = compact(&s);
        assert_eq!(f.nodes_dropped, 0);
        assert_eq!(c.lod_roots, vec![1, 3]);
    }
}
