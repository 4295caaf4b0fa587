//! Which buffer each mesh and texture of a GLB goes to, so that loaders streaming MSFT_lod levels
//! get them coarse to fine.
//!
//! Babylon.js (9.x) loads MSFT_lod progressively: the coarsest level first, then each finer one,
//! each level replacing the one before. It defers a finer level's data until the coarser level has
//! loaded only when that data comes through a URI (or with the loader's `useRangeRequests`). With
//! everything in the GLB's one binary chunk, every level loads at once, a finer level that finishes
//! first disposes the coarser one still loading, and the import fails ("Cannot read properties of
//! undefined (reading 'setEnabled')") or hangs — 5 of 10 chain files did so with Babylon's
//! defaults. So a chain GLB keeps in its binary chunk (group 0) what the coarsest level needs and
//! everything outside the chains, and puts what each finer level needs first in a buffer of its own
//! (group g for the g-th level counted from the coarsest), written as a base64 `data:` URI inside the
//! same file: the file stays self-contained, and any glTF reader loads it as before.

use crate::mesh::Scene;

/// Buffer group of every mesh and texture (0: the binary chunk), and how many groups there are.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LoadGroups {
    pub mesh: Vec<usize>,
    pub texture: Vec<usize>,
    pub groups: usize,
}

/// The groups of a compacted scene, or `None` when it has no MSFT_lod node (one buffer then).
pub fn load_groups(scene: &Scene) -> Option<LoadGroups> {
    let mut mesh = vec![usize::MAX; scene.meshes.len()];
    let mut groups = 0;
    for (i, node) in scene.nodes.iter().enumerate() {
        if node.lods.is_empty() {
            continue;
        }
        // levels finest first (the node, then its ids); a loader streams them coarsest first
        let levels: Vec<usize> = std::iter::once(i).chain(node.lods.iter().copied()).collect();
        let coarsest = levels.len() - 1;
        groups = groups.max(levels.len());
        for (level, &root) in levels.iter().enumerate() {
            let group = coarsest - level;
            let mut stack = vec![root];
            while let Some(n) = stack.pop() {
                if let Some(m) = scene.nodes[n].mesh {
                    // a mesh two levels share is loaded with the first (coarser) of them
                    mesh[m] = mesh[m].min(group);
                }
                stack.extend(&scene.nodes[n].children);
            }
        }
    }
    if groups == 0 {
        return None;
    }
    for g in &mut mesh {
        if *g == usize::MAX {
            *g = 0;
        }
    }
    let mut texture = vec![usize::MAX; scene.textures.len()];
    for (m, g) in scene.meshes.iter().zip(&mesh) {
        for p in &m.primitives {
            for t in p.material.and_then(|k| scene.materials.get(k)).into_iter().flat_map(|mat| mat.textures()) {
                texture[t] = texture[t].min(*g);
            }
        }
    }
    for g in &mut texture {
        if *g == usize::MAX {
            *g = 0;
        }
    }
    Some(LoadGroups { mesh, texture, groups })
}

/// Standard base64 (RFC 4648 §4) with padding, for `data:` URIs.
pub fn base64(bytes: &[u8]) -> String {
    let mut out = String::new();
    push_base64(&mut out, bytes);
    out
}

/// `bytes` in base64 appended to `out` (a URI's prefix written first is not copied again: a
/// world's level buffers run to a hundred megabytes).
pub fn push_base64(out: &mut String, bytes: &[u8]) {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    out.reserve(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Material, Mesh, Node, Primitive, Texture};

    #[test]
    fn base64_matches_rfc_4648_vectors() {
        for (plain, coded) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(plain.as_bytes()), coded);
        }
        assert_eq!(base64(&[0xff, 0xfe, 0x00]), "//4A");
    }

    #[test]
    fn levels_are_grouped_coarsest_first_and_shared_data_goes_with_the_coarser() {
        // node 0 (LoD0, mesh 0) with levels node 1 (mesh 1) and node 2 (mesh 2, also used by
        // node 3 outside any chain); mesh 0 and mesh 2 share texture 0, mesh 1 has texture 1
        let prim = |m: usize| Primitive {
            positions: vec![[0.0; 3]; 3],
            indices: vec![0, 1, 2],
            material: Some(m),
            ..Primitive::default()
        };
        let mesh = |m: usize| Mesh { name: String::new(), primitives: vec![prim(m)], extras: None };
        let node = |m: usize, lods: Vec<usize>| Node { mesh: Some(m), lods, ..Node::default() };
        let scene = Scene {
            meshes: vec![mesh(0), mesh(1), mesh(0), mesh(2)],
            materials: vec![
                Material { base_color_texture: Some(0), ..Material::default() },
                Material { base_color_texture: Some(1), ..Material::default() },
                Material::default(),
            ],
            textures: vec![Texture { name: "a".into(), png: vec![1] }, Texture { name: "b".into(), png: vec![2] }],
            nodes: vec![node(0, vec![1, 2]), node(1, vec![]), node(2, vec![]), node(3, vec![])],
            roots: vec![0, 3],
            ..Scene::default()
        };
        let g = load_groups(&scene).unwrap();
        assert_eq!(g.groups, 3);
        // LoD0 (finest) loads last: group 2; LoD1 group 1; LoD2 (coarsest) and the plain mesh 3 group 0
        assert_eq!(g.mesh, vec![2, 1, 0, 0]);
        // texture 0 is first needed by the coarsest level (mesh 2 uses material 0 too)
        assert_eq!(g.texture, vec![0, 1]);
        assert!(load_groups(&Scene {
            nodes: vec![node(0, vec![])],
            roots: vec![0],
            meshes: vec![mesh(2)],
            materials: vec![Material::default(); 3],
            ..Scene::default()
        })
        .is_none());
    }
}
