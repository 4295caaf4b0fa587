//! Wavefront OBJ + MTL writer (the de-facto format as Blender, tobj and most DCC tools read it).
//!
//! What is written: one `o` per node with a mesh, visiting roots depth-first, children in order;
//! node transforms (parents included) are applied to positions and normals. A node with
//! EXT_mesh_gpu_instancing-style instances is expanded into one `o <name>_<k>` copy per instance.
//! MSFT_lod levels that are not in the hierarchy are not written (they have their own
//! `_LOD<n>` files). Each primitive gets a `usemtl`; primitives of one node that share a material
//! merge on re-import, as OBJ has no primitive boundary. Vertex colours go on `v` lines as
//! `v x y z r g b` (alpha is dropped); readers index colours like positions, so when any primitive
//! has colours every `v` line gets one (white for primitives without). `vt` is (u, 1 − v): OBJ's v runs up from the bottom.
//!
//! Numbers use Rust's shortest round-trip formatting, so every f32 (positions of identity-
//! transformed nodes, normals, u) reads back bit-exact; v reads back as 1 − (1 − v), exact for
//! multiples of 2⁻²⁴ in 0..1 and within one ulp of 1.0 otherwise. MTL has Kd, d, map_Kd and the
//! PBR extension's Pm/Pr; alpha mode and double-sidedness have no OBJ equivalent and are dropped.
//! Scenes with points primitives (point leaves) are refused with a message: OBJ has no point sprites.

use std::fmt::Write;

use glam::{DMat3, DMat4, DQuat, DVec3};

use super::check::{check_scene, sanitize_name};
use super::error::SceneProblem;
use crate::mesh::{Node, PrimitiveMode, Scene};

/// The files of one OBJ export: `<stem>.obj`, `<stem>.mtl` (None without materials) and the
/// textures as `(file name, PNG bytes)`.
pub struct ObjOutput {
    pub obj: Vec<u8>,
    pub mtl: Option<Vec<u8>>,
    pub textures: Vec<(String, Vec<u8>)>,
}

/// File name of texture `index` in an OBJ export named `stem`.
pub fn texture_file_name(stem: &str, index: usize, name: &str) -> String {
    if name.is_empty() {
        format!("{stem}_{index}.png")
    } else {
        format!("{stem}_{index}_{}.png", sanitize_name(name))
    }
}

/// Unique one-token names: the sanitized name, `<fallback><i>` when empty, `_<i>` on collision.
fn unique_names<'a>(names: impl Iterator<Item = &'a str>, fallback: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for (i, n) in names.enumerate() {
        let mut s = if n.is_empty() { format!("{fallback}{i}") } else { sanitize_name(n) };
        if out.contains(&s) {
            s = format!("{s}_{i}");
        }
        out.push(s);
    }
    out
}

fn trs(t: [f32; 3], r: [f32; 4], s: [f32; 3]) -> DMat4 {
    let d = |v: [f32; 3]| DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
    DMat4::from_scale_rotation_translation(
        d(s),
        DQuat::from_xyzw(r[0] as f64, r[1] as f64, r[2] as f64, r[3] as f64),
        d(t),
    )
}

fn local(node: &Node) -> DMat4 {
    trs(node.translation, node.rotation, node.scale)
}

pub fn to_obj(scene: &Scene, stem: &str) -> Result<ObjOutput, SceneProblem> {
    check_scene(scene)?;
    // OBJ's `p` elements carry no size or normal and few readers draw them: refuse, do not drop
    for (mi, mesh) in scene.meshes.iter().enumerate() {
        if let Some(pi) = mesh.primitives.iter().position(|p| p.mode == PrimitiveMode::Points) {
            return Err(SceneProblem(format!(
                "mesh {mi} ({:?}) primitive {pi} is drawn as points (point leaves); OBJ cannot carry point sprites: \
                 write .glb or .gltf, or build without --point-leaves",
                mesh.name
            )));
        }
    }
    let textures: Vec<(String, Vec<u8>)> =
        scene.textures.iter().enumerate().map(|(i, t)| (texture_file_name(stem, i, &t.name), t.png.clone())).collect();
    let material_names = unique_names(scene.materials.iter().map(|m| m.name.as_str()), "material");
    let node_names = unique_names(scene.nodes.iter().map(|n| n.name.as_str()), "node");

    // MTL
    let mtl = (!scene.materials.is_empty()).then(|| {
        let mut s = format!("# {}\n", super::gltf::GENERATOR);
        for (m, name) in scene.materials.iter().zip(&material_names) {
            let [r, g, b, a] = m.base_color;
            let _ = writeln!(s, "\nnewmtl {name}\nKd {r} {g} {b}\nd {a}\nPm {}\nPr {}", m.metallic, m.roughness);
            if let Some(t) = m.base_color_texture {
                let _ = writeln!(s, "map_Kd {}", textures[t].0);
            }
        }
        s.into_bytes()
    });

    // OBJ: nodes depth-first from the roots, with world transforms
    let mut s = format!("# {}\n", super::gltf::GENERATOR);
    if mtl.is_some() {
        let _ = writeln!(s, "mtllib {stem}.mtl");
    }
    let mut base = [1usize; 3]; // next v, vt, vn number (OBJ counts from 1)
    let with_colors = scene.meshes.iter().flat_map(|m| &m.primitives).any(|p| !p.colors.is_empty());
    let names = Names { materials: &material_names, with_colors };
    let mut stack: Vec<(usize, DMat4)> = scene.roots.iter().rev().map(|&r| (r, DMat4::IDENTITY)).collect();
    while let Some((ni, parent)) = stack.pop() {
        let node = &scene.nodes[ni];
        let world = parent * local(node);
        if let Some(mi) = node.mesh {
            match node.instances.as_ref().filter(|i| !i.is_empty()) {
                None => write_object(&mut s, scene, mi, &node_names[ni], world, &names, &mut base),
                Some(inst) => {
                    for k in 0..inst.len() {
                        let t = inst.translations.get(k).copied().unwrap_or([0.0; 3]);
                        let r = inst.rotations.get(k).copied().unwrap_or([0.0, 0.0, 0.0, 1.0]);
                        let sc = inst.scales.get(k).copied().unwrap_or([1.0; 3]);
                        let name = format!("{}_{k}", node_names[ni]);
                        write_object(&mut s, scene, mi, &name, world * trs(t, r, sc), &names, &mut base);
                    }
                }
            }
        }
        for &c in node.children.iter().rev() {
            stack.push((c, world));
        }
    }
    Ok(ObjOutput { obj: s.into_bytes(), mtl, textures })
}

/// What every object of one export shares.
struct Names<'a> {
    materials: &'a [String],
    /// Some primitive has vertex colours, so every `v` line carries one.
    with_colors: bool,
}

/// Writes mesh `mi` as object `name`, transformed by `world`.
fn write_object(
    s: &mut String,
    scene: &Scene,
    mi: usize,
    name: &str,
    world: DMat4,
    names: &Names,
    base: &mut [usize; 3],
) {
    let identity = world == DMat4::IDENTITY;
    let normal_matrix = DMat3::from_mat4(world).inverse().transpose();
    let _ = writeln!(s, "o {name}");
    for p in &scene.meshes[mi].primitives {
        // vertices
        for (k, v) in p.positions.iter().enumerate() {
            let v = if identity {
                *v
            } else {
                world.transform_point3(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64)).as_vec3().to_array()
            };
            match (p.colors.get(k), names.with_colors) {
                (Some(c), _) => _ = writeln!(s, "v {} {} {} {} {} {}", v[0], v[1], v[2], c[0], c[1], c[2]),
                (None, true) => _ = writeln!(s, "v {} {} {} 1 1 1", v[0], v[1], v[2]),
                (None, false) => _ = writeln!(s, "v {} {} {}", v[0], v[1], v[2]),
            }
        }
        for uv in &p.uvs {
            let _ = writeln!(s, "vt {} {}", uv[0], 1.0 - uv[1]);
        }
        for n in &p.normals {
            let n = if identity {
                *n
            } else {
                let w = (normal_matrix * DVec3::new(n[0] as f64, n[1] as f64, n[2] as f64)).normalize_or_zero();
                w.as_vec3().to_array()
            };
            let _ = writeln!(s, "vn {} {} {}", n[0], n[1], n[2]);
        }
        // faces
        if let Some(m) = p.material {
            let _ = writeln!(s, "usemtl {}", names.materials[m]);
        }
        // a mirroring transform flips winding; swap two corners to keep the front face
        let flip = world.determinant() < 0.0;
        for tri in p.indices.chunks_exact(3) {
            let order = if flip { [tri[0], tri[2], tri[1]] } else { [tri[0], tri[1], tri[2]] };
            s.push('f');
            for i in order {
                let i = i as usize;
                let v = base[0] + i;
                match (p.uvs.is_empty(), p.normals.is_empty()) {
                    (true, true) => _ = write!(s, " {v}"),
                    (false, true) => _ = write!(s, " {v}/{}", base[1] + i),
                    (true, false) => _ = write!(s, " {v}//{}", base[2] + i),
                    (false, false) => _ = write!(s, " {v}/{}/{}", base[1] + i, base[2] + i),
                }
            }
            s.push('\n');
        }
        base[0] += p.positions.len();
        base[1] += p.uvs.len();
        base[2] += p.normals.len();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Mesh, Primitive};

    #[test]
    fn obj_text_for_one_triangle() {
        let mut scene = Scene::default();
        let p = Primitive {
            positions: vec![[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, -0.3]],
            normals: vec![[0.0, 1.0, 0.0]; 3],
            uvs: vec![[0.0, 0.0], [1.0, 0.0], [0.0, 0.25]],
            indices: vec![0, 2, 1],
            ..Primitive::default()
        };
        let n = scene.add_mesh_node(Mesh { name: "tri angle".into(), primitives: vec![p], extras: None });
        scene.nodes[n].translation = [10.0, 0.0, 0.0];
        let out = to_obj(&scene, "t").unwrap();
        let text = String::from_utf8(out.obj).unwrap();
        assert!(out.mtl.is_none());
        assert!(text.contains("o tri_angle\n"), "{text}");
        assert!(text.contains("v 10.1 0 0\n"), "{text}");
        assert!(text.contains("vt 0 0.75\n"), "{text}");
        assert!(text.contains("f 1/1/1 3/3/3 2/2/2\n"), "{text}");
    }

    #[test]
    fn points_are_refused_with_a_remedy() {
        let mut scene = Scene::default();
        let p = Primitive {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0]],
            mode: PrimitiveMode::Points,
            ..Primitive::default()
        };
        scene.add_mesh_node(Mesh { name: "leaves".into(), primitives: vec![p], extras: None });
        let e = to_obj(&scene, "t").err().expect("points refused");
        assert!(e.0.contains("points") && e.0.contains(".glb"), "{}", e.0);
    }
}
