//! The in-memory scene every stage produces and every writer consumes.
//!
//! Plain data: flat arrays of vertex attributes, `u32` indices (writers narrow to `u16` where they
//! fit), materials and textures referenced by index. Units are metres, +Y up, right-handed, front
//! faces counter-clockwise. Writers (`export`) and the re-import checks (`validate`) meet here.

use serde_json::Value;

use crate::math::{cross3, sub3};

/// One drawable piece with a single material: the unit of a glTF primitive or an OBJ group.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Primitive {
    pub positions: Vec<[f32; 3]>,
    /// Unit normals, one per position, or empty.
    pub normals: Vec<[f32; 3]>,
    /// Texture coordinates (glTF convention: v down from the image's top), one per position, or empty.
    pub uvs: Vec<[f32; 2]>,
    /// glTF TANGENT (unit xyz along +u, w = ±1 the bitangent's sign), one per position, or empty:
    /// written where a material has a normal map, so no engine has to guess the tangent space.
    pub tangents: Vec<[f32; 4]>,
    /// Linear RGBA vertex colours in 0..1, one per position, or empty.
    pub colors: Vec<[f32; 4]>,
    /// Application-specific per-vertex data written as glTF custom attributes (names start with `_`,
    /// e.g. `_WIND`), four floats per vertex, one entry per position.
    pub custom: Vec<CustomAttribute>,
    /// Triangle list; every three indices are one triangle, counter-clockwise seen from its front.
    pub indices: Vec<u32>,
    /// Index into [`Scene::materials`].
    pub material: Option<usize>,
    /// How the vertices are drawn: triangles (`indices`, three per triangle) or points (one per
    /// vertex; `indices` empty).
    pub mode: PrimitiveMode,
}

/// The glTF primitive topology the writers and the re-import support.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub enum PrimitiveMode {
    /// A triangle list (glTF mode 4).
    #[default]
    Triangles,
    /// One point per vertex, no indices (glTF mode 0): point sprites an engine sizes and shades.
    Points,
}

/// A per-vertex VEC4 float attribute an engine shader reads by name (glTF: an application-specific
/// semantic, which must start with an underscore).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CustomAttribute {
    pub name: String,
    pub values: Vec<[f32; 4]>,
    /// Written as normalized unsigned bytes (a quarter of the floats' size): for values in 0..1 that
    /// are already multiples of 1/255, so the file holds exactly these values (the glTF reader gives
    /// shaders the same floats).
    pub unit_bytes: bool,
    /// The upper ends of the components' documented ranges (the lower ends are 0), for data whose
    /// precision an engine does not need in full (wind, docs/wind.md): a compact file (`--quantize`, `--compress`) stores
    /// such an attribute as normalized unsigned bytes of `value / range` and the range in the
    /// primitive's extras ([`crate::export::gltf::ATTRIBUTE_RANGES_KEY`]); an f32 file as floats.
    pub range: Option<[f32; 4]>,
}

/// A named mesh made of one or more primitives.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    pub name: String,
    pub primitives: Vec<Primitive>,
    pub extras: Option<Value>,
}

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum AlphaMode {
    #[default]
    Opaque,
    /// Alpha test: fragments with alpha below `cutoff` are discarded (no sorting needed).
    Mask {
        cutoff: f32,
    },
    Blend,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    pub name: String,
    /// Linear RGBA multiplier.
    pub base_color: [f32; 4],
    /// Index into [`Scene::textures`].
    pub base_color_texture: Option<usize>,
    /// A tangent-space normal map (glTF normalTexture, TEXCOORD_0), index into [`Scene::textures`].
    pub normal_texture: Option<usize>,
    pub metallic: f32,
    pub roughness: f32,
    pub alpha_mode: AlphaMode,
    pub double_sided: bool,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: String::new(),
            base_color: [1.0, 1.0, 1.0, 1.0],
            base_color_texture: None,
            normal_texture: None,
            metallic: 0.0,
            roughness: 1.0,
            alpha_mode: AlphaMode::Opaque,
            double_sided: false,
        }
    }
}

/// The glTF tangent of a flat textured quad (corners 0, 1, 3 span it): xyz along +u, w the sign
/// that makes cross(normal, tangent)·w point up the image (towards smaller v), as glTF's normal-map
/// convention (+Y up) needs.
pub fn quad_tangent(corners: [[f32; 3]; 4], uvs: [[f32; 2]; 4], normal: [f32; 3]) -> [f32; 4] {
    let sub = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let (e1, e2) = (sub(corners[1], corners[0]), sub(corners[3], corners[0]));
    let (du1, dv1, du2, dv2) =
        (uvs[1][0] - uvs[0][0], uvs[1][1] - uvs[0][1], uvs[3][0] - uvs[0][0], uvs[3][1] - uvs[0][1]);
    let det = du1 * dv2 - du2 * dv1;
    if det == 0.0 || !det.is_finite() {
        return [1.0, 0.0, 0.0, 1.0];
    }
    let dpdu = [0, 1, 2].map(|k| (e1[k] * dv2 - e2[k] * dv1) / det);
    let dpdv = [0, 1, 2].map(|k| (e2[k] * du1 - e1[k] * du2) / det);
    // Gram-Schmidt against the normal, unit length
    let d = dpdu[0] * normal[0] + dpdu[1] * normal[1] + dpdu[2] * normal[2];
    let t = [0, 1, 2].map(|k| dpdu[k] - normal[k] * d);
    let len = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
    if len == 0.0 || !len.is_finite() {
        return [1.0, 0.0, 0.0, 1.0];
    }
    let t = t.map(|x| x / len);
    let b =
        [normal[1] * t[2] - normal[2] * t[1], normal[2] * t[0] - normal[0] * t[2], normal[0] * t[1] - normal[1] * t[0]];
    let up_the_image = -(b[0] * dpdv[0] + b[1] * dpdv[1] + b[2] * dpdv[2]);
    [t[0], t[1], t[2], if up_the_image >= 0.0 { 1.0 } else { -1.0 }]
}

impl Material {
    /// The texture indices it samples: base colour, then the normal map.
    pub fn textures(&self) -> impl Iterator<Item = usize> {
        self.base_color_texture.into_iter().chain(self.normal_texture)
    }

    /// The material with every texture index mapped by `f` (None: that texture is dropped).
    pub fn with_textures(&self, f: impl Fn(usize) -> Option<usize>) -> Material {
        Material {
            base_color_texture: self.base_color_texture.and_then(&f),
            normal_texture: self.normal_texture.and_then(&f),
            ..self.clone()
        }
    }
}

/// An image stored inside the output (PNG bytes), sampled with repeat wrapping and linear filtering.
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    pub name: String,
    pub png: Vec<u8>,
}

/// Per-instance transforms for EXT_mesh_gpu_instancing (all three arrays have the same length,
/// or are empty to mean identity).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Instances {
    pub translations: Vec<[f32; 3]>,
    /// Unit quaternions (x, y, z, w).
    pub rotations: Vec<[f32; 4]>,
    pub scales: Vec<[f32; 3]>,
}

impl Instances {
    pub fn len(&self) -> usize {
        self.translations.len().max(self.rotations.len()).max(self.scales.len())
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A node of the scene graph.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    pub name: String,
    /// Index into [`Scene::meshes`].
    pub mesh: Option<usize>,
    pub translation: [f32; 3],
    /// Unit quaternion (x, y, z, w).
    pub rotation: [f32; 4],
    pub scale: [f32; 3],
    /// Indices into [`Scene::nodes`].
    pub children: Vec<usize>,
    pub extras: Option<Value>,
    /// GPU instancing of `mesh` (EXT_mesh_gpu_instancing). Shared: the levels of an instanced LoD
    /// chain (scene_lod.glb) place the same rows, held once (on a world of 1.3 M instances a copy
    /// per level was ~160 MB at the view stage's peak).
    pub instances: Option<std::sync::Arc<Instances>>,
    /// Coarser levels of detail of this node (MSFT_lod): indices into [`Scene::nodes`], finest first,
    /// with the screen coverage at which each level switches.
    pub lods: Vec<usize>,
    pub lod_screen_coverage: Vec<f32>,
}

impl Default for Node {
    fn default() -> Self {
        Node {
            name: String::new(),
            mesh: None,
            translation: [0.0; 3],
            rotation: [0.0, 0.0, 0.0, 1.0],
            scale: [1.0; 3],
            children: Vec::new(),
            extras: None,
            instances: None,
            lods: Vec::new(),
            lod_screen_coverage: Vec::new(),
        }
    }
}

/// Everything one output file holds.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scene {
    pub name: String,
    pub nodes: Vec<Node>,
    /// Indices into `nodes` of the scene's root nodes.
    pub roots: Vec<usize>,
    pub meshes: Vec<Mesh>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub extras: Option<Value>,
}

/// Axis-aligned bounds of a set of points (serialised as `{"min": [x, y, z], "max": [x, y, z]}`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Bounds {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl Bounds {
    /// Bounds of `points`, or `None` for an empty set.
    pub fn of(points: &[[f32; 3]]) -> Option<Bounds> {
        let first = *points.first()?;
        let mut b = Bounds { min: first, max: first };
        for p in &points[1..] {
            for (k, &v) in p.iter().enumerate() {
                b.min[k] = b.min[k].min(v);
                b.max[k] = b.max[k].max(v);
            }
        }
        Some(b)
    }
}

impl Primitive {
    /// Triangles drawn (0 for a points primitive).
    pub fn triangle_count(&self) -> usize {
        match self.mode {
            PrimitiveMode::Triangles => self.indices.len() / 3,
            PrimitiveMode::Points => 0,
        }
    }

    /// Points drawn (0 for a triangle primitive).
    pub fn point_count(&self) -> usize {
        match self.mode {
            PrimitiveMode::Triangles => 0,
            PrimitiveMode::Points => self.positions.len(),
        }
    }

    pub fn is_points(&self) -> bool {
        self.mode == PrimitiveMode::Points
    }

    pub fn bounds(&self) -> Option<Bounds> {
        Bounds::of(&self.positions)
    }

    /// Twice the area vector of triangle `t`: (b − a) × (c − a), in f64.
    pub fn triangle_cross(&self, t: usize) -> [f64; 3] {
        let p = |k: usize| {
            let v = self.positions[self.indices[3 * t + k] as usize];
            [v[0] as f64, v[1] as f64, v[2] as f64]
        };
        cross3(sub3(p(1), p(0)), sub3(p(2), p(0)))
    }

    /// Reorders triangles and vertices for the GPU's post-transform cache and then for vertex fetch
    /// (meshoptimizer). Triangles keep their winding; the set of triangles is unchanged.
    /// Refused (the primitive unchanged) when meshoptimizer could not take it
    /// ([`crate::meshopt_guard`]).
    pub fn optimize_for_gpu(&mut self) -> Result<(), crate::meshopt_guard::FfiError> {
        // points have no triangles to reorder (and every vertex is drawn)
        if self.is_points() || self.indices.is_empty() || self.positions.is_empty() {
            return Ok(());
        }
        let vertex_count = self.positions.len();
        let cache = crate::meshopt_guard::optimize_vertex_cache(&self.indices, vertex_count)?;
        let mut indices = cache;
        // fetch order: vertices renumbered in the order the triangles first use them (what
        // meshopt's vertex-fetch remap does), vertices no triangle uses dropped
        let mut remap = vec![u32::MAX; vertex_count];
        let mut new_count = 0usize;
        for i in indices.iter_mut() {
            let r = &mut remap[*i as usize];
            if *r == u32::MAX {
                *r = new_count as u32;
                new_count += 1;
            }
            *i = *r;
        }
        fn apply<T: Copy + Default>(v: &mut Vec<T>, remap: &[u32], n: usize) {
            if v.is_empty() {
                return;
            }
            let mut out = vec![T::default(); n];
            for (old, &new) in remap.iter().enumerate() {
                if new != u32::MAX {
                    out[new as usize] = v[old];
                }
            }
            *v = out;
        }
        apply(&mut self.positions, &remap, new_count);
        apply(&mut self.normals, &remap, new_count);
        apply(&mut self.uvs, &remap, new_count);
        apply(&mut self.tangents, &remap, new_count);
        apply(&mut self.colors, &remap, new_count);
        for c in &mut self.custom {
            apply(&mut c.values, &remap, new_count);
        }
        self.indices = indices;
        Ok(())
    }
}

impl Mesh {
    pub fn triangle_count(&self) -> usize {
        self.primitives.iter().map(Primitive::triangle_count).sum()
    }
    pub fn point_count(&self) -> usize {
        self.primitives.iter().map(Primitive::point_count).sum()
    }
    pub fn vertex_count(&self) -> usize {
        self.primitives.iter().map(|p| p.positions.len()).sum()
    }
}

impl Scene {
    /// Adds a mesh and a root node showing it; returns the node index.
    pub fn add_mesh_node(&mut self, mesh: Mesh) -> usize {
        let name = mesh.name.clone();
        self.meshes.push(mesh);
        self.nodes.push(Node { name, mesh: Some(self.meshes.len() - 1), ..Node::default() });
        let n = self.nodes.len() - 1;
        self.roots.push(n);
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_of_points() {
        assert_eq!(Bounds::of(&[]), None);
        let b = Bounds::of(&[[1.0, -2.0, 3.0], [-1.0, 5.0, 0.5]]).unwrap();
        assert_eq!(b.min, [-1.0, -2.0, 0.5]);
        assert_eq!(b.max, [1.0, 5.0, 3.0]);
    }

    #[test]
    fn gpu_optimisation_keeps_triangles_and_winding() {
        // A 3x3 grid of vertices, 8 triangles, with an unused vertex at the end.
        let mut p = Primitive::default();
        for j in 0..3 {
            for i in 0..3 {
                p.positions.push([i as f32, 0.0, j as f32]);
                p.uvs.push([i as f32 / 2.0, j as f32 / 2.0]);
            }
        }
        p.positions.push([9.0, 9.0, 9.0]);
        p.uvs.push([0.0, 0.0]);
        for j in 0..2u32 {
            for i in 0..2u32 {
                let a = j * 3 + i;
                p.indices.extend_from_slice(&[a, a + 3, a + 1, a + 1, a + 3, a + 4]);
            }
        }
        let tri_set = |p: &Primitive| {
            let mut v: Vec<[[i32; 3]; 3]> = (0..p.triangle_count())
                .map(|t| {
                    let c = |k: usize| {
                        let q = p.positions[p.indices[3 * t + k] as usize];
                        [q[0] as i32, q[1] as i32, q[2] as i32]
                    };
                    // rotate so the smallest corner is first; keeps winding
                    let tri = [c(0), c(1), c(2)];
                    let m = (0..3).min_by_key(|&k| tri[k]).unwrap();
                    [tri[m], tri[(m + 1) % 3], tri[(m + 2) % 3]]
                })
                .collect();
            v.sort();
            v
        };
        let before = tri_set(&p);
        p.optimize_for_gpu().unwrap();
        assert_eq!(p.positions.len(), 9, "unused vertex dropped");
        assert_eq!(p.uvs.len(), 9);
        assert_eq!(tri_set(&p), before);
        for (q, uv) in p.positions.iter().zip(&p.uvs) {
            assert_eq!([q[0] / 2.0, q[2] / 2.0], *uv, "attributes moved together");
        }
    }

    #[test]
    fn quad_tangents_point_along_u_with_the_bitangent_up_the_image() {
        // a card facing +Z, u to the right (+X), v down the image (−Y): tangent +X, w = +1
        let corners = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let uvs = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];
        assert_eq!(quad_tangent(corners, uvs, [0.0, 0.0, 1.0]), [1.0, 0.0, 0.0, 1.0]);
        // the image mirrored left-right: tangent −X; cross(N, −X) = −Y points down the image, so w = −1
        let mirrored = [[1.0, 1.0], [0.0, 1.0], [0.0, 0.0], [1.0, 0.0]];
        assert_eq!(quad_tangent(corners, mirrored, [0.0, 0.0, 1.0]), [-1.0, 0.0, 0.0, -1.0]);
        // no uv area: a unit default, never NaN
        assert_eq!(quad_tangent(corners, [[0.5, 0.5]; 4], [0.0, 0.0, 1.0]), [1.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn optimize_drops_an_unused_vertex_in_the_middle_and_keeps_custom_attributes_aligned() {
        // vertex 1 is used by no triangle; the custom attribute carries each vertex's own position
        let positions: Vec<[f32; 3]> =
            vec![[0.0, 0.0, 0.0], [9.0, 9.0, 9.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 1.0]];
        let custom = vec![CustomAttribute {
            name: "_ID".into(),
            values: positions.iter().map(|p| [p[0], p[1], p[2], 1.0]).collect(),
            unit_bytes: false,
            range: None,
        }];
        let mut p = Primitive { positions, custom, indices: vec![0, 3, 2, 2, 3, 4], ..Primitive::default() };
        p.optimize_for_gpu().unwrap();
        assert_eq!(p.positions.len(), 4);
        assert!(!p.positions.contains(&[9.0, 9.0, 9.0]));
        assert_eq!(p.custom[0].values.len(), 4);
        for (q, c) in p.positions.iter().zip(&p.custom[0].values) {
            assert_eq!([q[0], q[1], q[2], 1.0], *c);
        }
    }
}
