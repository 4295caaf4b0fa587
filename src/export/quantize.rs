//! Which grid each mesh's positions are stored on (KHR_mesh_quantization), and what that costs.
//!
//! Two plans: one grid for every mesh ([`Quantization::Grid`], a terrain: x and z by the cell, y by
//! the height range), or a grid per mesh family ([`Quantization::PerMesh`], species and scenes).
//! A family is the meshes of one MSFT_lod chain (a node's mesh and its levels' meshes): they share
//! one grid, over their joint bounding box, so an instanced chain keeps one set of instance
//! transforms. A per-mesh grid is uniform (one step on all three axes, the box's largest extent over
//! 65,535, as gltfpack does), so normals and tangents need no correction and fit in 8 bits.
//!
//! The grid is put back by the node: a mesh node's translation and scale take the grid's origin
//! and step; an instanced node's instance transforms take them instead (EXT_mesh_gpu_instancing
//! applies the node's transform after the instance's, so the node cannot carry a per-vertex grid).
//! A mesh shown by a node that also has children keeps f32 positions (its children would move).
//!
//! Texture coordinates in 0..1 become 16-bit normalized integers; outside 0..1 (bark repeating
//! along a branch) they are stored relative to the range of every primitive sharing the material,
//! which the material's textures put back through KHR_texture_transform (offset and scale).

use super::grid::PositionGrid;
use crate::mesh::{CustomAttribute, Instances, Scene};

/// How positions are stored.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub enum Quantization {
    /// 32-bit floats.
    #[default]
    Off,
    /// Every mesh on this grid (a terrain's: exact x and z, normals pre-scaled to 16 bits).
    Grid(PositionGrid),
    /// Each mesh family on a uniform 16-bit grid over its own bounding box.
    PerMesh,
}

impl Quantization {
    pub fn is_on(&self) -> bool {
        !matches!(self, Quantization::Off)
    }
}

/// What a species or scene file is stored as (`--quantize`, `--compress`; a preset's `compact`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Compact {
    /// f32 vertex data.
    #[default]
    None,
    /// KHR_mesh_quantization, a grid per mesh family ([`Quantization::PerMesh`]).
    Quantize,
    /// `Quantize`, then EXT_meshopt_compression (lossless).
    Compress,
}

impl Compact {
    /// The glTF writer's options for species and scene files.
    pub fn write_options(self) -> super::gltf::WriteOptions {
        super::gltf::WriteOptions {
            quantization: if self == Compact::None { Quantization::Off } else { Quantization::PerMesh },
            meshopt: self == Compact::Compress,
            mesh_grids: Vec::new(),
        }
    }

    /// From the `--quantize` and `--compress` flags.
    pub fn from_flags(quantize: bool, compress: bool) -> Compact {
        match (quantize, compress) {
            (_, true) => Compact::Compress,
            (true, false) => Compact::Quantize,
            _ => Compact::None,
        }
    }
}

/// The grid a mesh is stored on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshGrid {
    pub grid: PositionGrid,
    /// One step on every axis: normals and tangents stored as they are, in 8 bits.
    pub uniform: bool,
}

/// A material's texture-coordinate range (KHR_texture_transform puts `offset + scale·uv` back).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UvRange {
    pub offset: [f32; 2],
    pub scale: [f32; 2],
}

impl UvRange {
    /// The normalized 16-bit integer a coordinate is stored as.
    pub fn quantize(&self, axis: usize, u: f32) -> u16 {
        let n = (u as f64 - self.offset[axis] as f64) / self.scale[axis] as f64;
        (n.clamp(0.0, 1.0) * 65535.0).round() as u16
    }
}

/// What each mesh and material of a (compacted) scene is stored with.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Plan {
    /// Per mesh: its grid, or None for f32 positions.
    pub mesh: Vec<Option<MeshGrid>>,
    /// Per material: the range its quantized texture coordinates outside 0..1 are stored in.
    pub uv: Vec<Option<UvRange>>,
}

/// Positions per axis on the 16-bit grid.
const STEPS: f64 = 65535.0;

/// A uniform 16-bit grid whose integers 0..=65535 cover `min..=max` on every axis.
pub fn uniform_grid(min: [f32; 3], max: [f32; 3]) -> PositionGrid {
    let extent = (0..3).map(|a| max[a] as f64 - min[a] as f64).fold(0.0, f64::max);
    let mut step = (extent / STEPS) as f32;
    if step.is_nan() || step <= 0.0 || !step.is_finite() {
        step = 1.0; // a point (or an empty mesh): every vertex is integer 0
    }
    // rounding the step down could put the far corner at 65,536
    while (step as f64) * STEPS < extent {
        step = f32::from_bits(step.to_bits() + 1);
    }
    PositionGrid { origin: min, step: [step; 3] }
}

/// The plan for `scene` (compacted, checked): which grid each mesh and which range each material
/// takes under `q`; with [`Quantization::PerMesh`], the meshes named in `named` take the grid given,
/// their families too.
#[allow(clippy::needless_range_loop)] // per-axis min/max over three and two components
pub fn plan(scene: &Scene, q: &Quantization, named: &[(String, MeshGrid)]) -> Plan {
    let meshes = scene.meshes.len();
    let mut plan = Plan { mesh: vec![None; meshes], uv: vec![None; scene.materials.len()] };
    match q {
        Quantization::Off => return plan,
        Quantization::Grid(grid) => plan.mesh = vec![Some(MeshGrid { grid: *grid, uniform: false }); meshes],
        Quantization::PerMesh => {
            let family = families(scene);
            let mut boxes: Vec<Option<([f32; 3], [f32; 3])>> = vec![None; meshes];
            for (m, mesh) in scene.meshes.iter().enumerate() {
                for p in mesh.primitives.iter().flat_map(|p| &p.positions) {
                    let b = boxes[family[m]].get_or_insert((*p, *p));
                    for a in 0..3 {
                        b.0[a] = b.0[a].min(p[a]);
                        b.1[a] = b.1[a].max(p[a]);
                    }
                }
            }
            // a node with children cannot carry its mesh's grid, and a mesh whose extras are not a
            // JSON object cannot note it for readers: that family stays f32
            let mut blocked = vec![false; meshes];
            for (m, mesh) in scene.meshes.iter().enumerate() {
                if mesh.extras.as_ref().is_some_and(|e| !e.is_object()) {
                    blocked[family[m]] = true;
                }
            }
            for node in &scene.nodes {
                if let (Some(m), false) = (node.mesh, node.children.is_empty()) {
                    blocked[family[m]] = true;
                }
            }
            // a named grid is its family's
            let mut given: Vec<Option<MeshGrid>> = vec![None; meshes];
            for (m, mesh) in scene.meshes.iter().enumerate() {
                if let Some((_, g)) = named.iter().find(|(n, _)| *n == mesh.name) {
                    given[family[m]] = Some(*g);
                }
            }
            for m in 0..meshes {
                let f = family[m];
                plan.mesh[m] = match (given[f], boxes[f], blocked[f]) {
                    (_, _, true) | (None, None, _) => None,
                    (Some(grid), _, false) => Some(grid),
                    (None, Some((lo, hi)), false) => Some(MeshGrid { grid: uniform_grid(lo, hi), uniform: true }),
                };
            }
        }
    }
    // texture coordinates outside 0..1: a range per textured material whose every primitive is
    // quantized (a material also drawn with f32 positions keeps float coordinates)
    let mut range: Vec<Option<([f32; 2], [f32; 2])>> = vec![None; scene.materials.len()];
    let mut usable: Vec<bool> = scene.materials.iter().map(|m| m.textures().next().is_some()).collect();
    for (m, mesh) in scene.meshes.iter().enumerate() {
        for p in &mesh.primitives {
            let Some(k) = p.material else { continue };
            if plan.mesh[m].is_none() {
                usable[k] = false;
                continue;
            }
            for uv in &p.uvs {
                let r = range[k].get_or_insert((*uv, *uv));
                for a in 0..2 {
                    r.0[a] = r.0[a].min(uv[a]);
                    r.1[a] = r.1[a].max(uv[a]);
                }
            }
        }
    }
    for k in 0..scene.materials.len() {
        if let (Some((lo, hi)), true) = (range[k], usable[k]) {
            let unit = (0..2).all(|a| lo[a] >= 0.0 && hi[a] <= 1.0);
            if !unit {
                let scale = [0, 1].map(|a| {
                    let s = hi[a] - lo[a];
                    if s > 0.0 && s.is_finite() {
                        s
                    } else {
                        1.0
                    }
                });
                plan.uv[k] = Some(UvRange { offset: lo, scale });
            }
        }
    }
    plan
}

/// Each mesh's family: meshes linked through MSFT_lod (a node's mesh with its levels' meshes) share
/// the lowest index among them.
fn families(scene: &Scene) -> Vec<usize> {
    let mut parent: Vec<usize> = (0..scene.meshes.len()).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for node in &scene.nodes {
        let Some(a) = node.mesh else { continue };
        for &l in &node.lods {
            if let Some(b) = scene.nodes.get(l).and_then(|n| n.mesh) {
                let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
                parent[ra.max(rb)] = ra.min(rb);
            }
        }
    }
    (0..parent.len()).map(|i| find(&mut parent, i)).collect()
}

/// Instance transforms that also put `grid` back: each instance's translation T and scale S become
/// T + R(S∘origin) and S∘step (rotation unchanged).
pub fn place_instances(inst: &Instances, grid: &PositionGrid) -> Instances {
    let n = inst.len();
    let mut out = Instances {
        translations: Vec::with_capacity(n),
        rotations: inst.rotations.clone(),
        scales: Vec::with_capacity(n),
    };
    for k in 0..n {
        let r = inst.rotations.get(k).copied().unwrap_or([0.0, 0.0, 0.0, 1.0]);
        let t = inst.translations.get(k).copied().unwrap_or([0.0; 3]);
        let s = inst.scales.get(k).copied().unwrap_or([1.0; 3]);
        let (t, s) = place(r, t, s, grid);
        out.translations.push(t);
        out.scales.push(s);
    }
    out
}

/// The node transform T·R·S followed by the grid's Tr(origin)·Sc(step), as one TRS:
/// translation T + R(S∘origin), scale S∘step (rotation unchanged).
pub fn place(rotation: [f32; 4], translation: [f32; 3], scale: [f32; 3], grid: &PositionGrid) -> ([f32; 3], [f32; 3]) {
    let so = [0, 1, 2].map(|a| scale[a] * grid.origin[a]);
    let r = glam::Quat::from_array(rotation).mul_vec3(glam::Vec3::from_array(so));
    let t = [translation[0] + r.x, translation[1] + r.y, translation[2] + r.z];
    (t, [0, 1, 2].map(|a| scale[a] * grid.step[a]))
}

/// The range a custom attribute is stored over as normalized unsigned bytes of value / range: in
/// a compact file (`q` on), when it has one (`CustomAttribute::range`, wind) and every value lies
/// within it; None (floats as they are) otherwise.
pub fn attribute_range(c: &CustomAttribute, q: &Quantization) -> Option<[f32; 4]> {
    let range = c.range.filter(|_| q.is_on() && !c.unit_bytes)?;
    let fits = range.iter().all(|r| r.is_finite() && *r > 0.0)
        && c.values.iter().all(|v| v.iter().zip(&range).all(|(x, r)| (0.0..=r * (1.0 + 1e-6)).contains(x)));
    fits.then_some(range)
}

/// The byte `x` is stored as over `0..=range` (the nearest of 256 steps).
pub fn range_byte(x: f32, range: f32) -> u8 {
    ((x / range).clamp(0.0, 1.0) * 255.0).round() as u8
}

/// What a reader gets back for `x` stored over `range`: the byte, normalized, times the range.
pub fn range_value(x: f32, range: f32) -> f32 {
    range_byte(x, range) as f32 / 255.0 * range
}

/// Per custom attribute stored as bytes of its range under `q` (the wind of a compact file): the
/// largest difference per component between the values as built and as a reader gets them (at most
/// half a step, range / 510). Empty for f32 files.
pub fn attribute_error(scene: &Scene, q: &Quantization) -> std::collections::BTreeMap<String, [f32; 4]> {
    let mut worst = std::collections::BTreeMap::new();
    for c in scene.meshes.iter().flat_map(|m| &m.primitives).flat_map(|p| &p.custom) {
        let Some(range) = attribute_range(c, q) else { continue };
        let e: &mut [f32; 4] = worst.entry(c.name.clone()).or_default();
        for v in &c.values {
            for k in 0..4 {
                e[k] = e[k].max((range_value(v[k], range[k]) - v[k]).abs());
            }
        }
    }
    worst
}

/// The largest distance (metres, in the mesh's own frame) any vertex of `scene` moves when stored
/// under `q`: what quantization adds to a mesh's error (a surface point moves at most as far as
/// its triangle's corners). 0 without quantization.
pub fn position_error(scene: &Scene, q: &Quantization) -> f64 {
    position_error_with(scene, q, &[])
}

/// [`position_error`] with named grids (see [`plan`]).
pub fn position_error_with(scene: &Scene, q: &Quantization, named: &[(String, MeshGrid)]) -> f64 {
    if !q.is_on() {
        return 0.0;
    }
    let (compacted, _) = super::compact::compact(scene);
    let scene: &Scene = &compacted.scene;
    let plan = plan(scene, q, named);
    let mut worst = 0.0f64;
    for (mesh, grid) in scene.meshes.iter().zip(&plan.mesh) {
        let Some(g) = grid else { continue };
        for p in mesh.primitives.iter().flat_map(|p| &p.positions) {
            let d2: f64 = (0..3)
                .map(|a| {
                    let stored = g.grid.dequantize(a, g.grid.quantize(a, p[a]));
                    (stored - p[a] as f64).powi(2)
                })
                .sum();
            worst = worst.max(d2.sqrt());
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Mesh, Node, Primitive};

    fn tri(scale: f32) -> Mesh {
        let positions = vec![[0.0, 0.0, 0.0], [scale, 0.0, 0.0], [0.0, scale * 0.5, 0.3]];
        Mesh {
            name: "t".into(),
            primitives: vec![Primitive { positions, indices: vec![0, 1, 2], ..Primitive::default() }],
            extras: None,
        }
    }

    #[test]
    fn the_far_corner_is_on_the_grid() {
        for extent in [1e-3f32, 0.3, 1.0, 7.77, 1234.5, 3.0e5] {
            let far = -1.0 + extent;
            let g = uniform_grid([-1.0, 2.0, 0.5], [far, 2.0, 0.5 + extent / 3.0]);
            let extent = far as f64 + 1.0;
            assert!(g.quantize(0, far) <= 65535, "{extent}");
            assert!(g.step[0] as f64 * STEPS >= extent);
            assert!((g.step[0] as f64 * STEPS) < extent * (1.0 + 1e-6));
        }
        // a point: one integer
        let g = uniform_grid([3.0; 3], [3.0; 3]);
        assert_eq!(g.quantize(1, 3.0), 0);
    }

    #[test]
    fn a_lod_chain_shares_one_grid_and_other_meshes_have_their_own() {
        let mut scene = Scene::default();
        let a = scene.add_mesh_node(tri(1.0));
        let b = scene.add_mesh_node(tri(4.0));
        let c = scene.add_mesh_node(tri(9.0));
        scene.nodes[a].lods = vec![b];
        scene.nodes[a].lod_screen_coverage = vec![0.5];
        scene.roots.retain(|&r| r != b);
        let p = plan(&scene, &Quantization::PerMesh, &[]);
        let grid = |n: usize| p.mesh[scene.nodes[n].mesh.unwrap()].unwrap().grid;
        assert_eq!(grid(a), grid(b));
        assert_ne!(grid(a), grid(c));
        // the chain's box: the larger level's 4 m
        assert!(grid(a).step[0] as f64 * STEPS >= 4.0 && grid(a).step[0] as f64 * STEPS < 4.0001);
        // the error: at most half a step on each axis
        let e = position_error(&scene, &Quantization::PerMesh);
        assert!(e > 0.0 && e <= 0.5 * 3f64.sqrt() * grid(c).step[0] as f64, "{e}");
    }

    #[test]
    fn a_mesh_node_with_children_keeps_floats() {
        let mut scene = Scene::default();
        let a = scene.add_mesh_node(tri(1.0));
        let child = scene.nodes.len();
        scene.nodes.push(Node { name: "c".into(), ..Node::default() });
        scene.nodes[a].children.push(child);
        let p = plan(&scene, &Quantization::PerMesh, &[]);
        assert_eq!(p.mesh, vec![None]);
        assert_eq!(position_error(&scene, &Quantization::PerMesh), 0.0);
    }

    #[test]
    fn instances_take_the_grid() {
        let grid = PositionGrid { origin: [1.0, 2.0, 3.0], step: [0.5; 3] };
        let inst = Instances {
            translations: vec![[10.0, 0.0, 0.0]],
            rotations: vec![[0.0, std::f32::consts::FRAC_1_SQRT_2, 0.0, std::f32::consts::FRAC_1_SQRT_2]],
            scales: vec![[2.0; 3]],
        };
        let placed = place_instances(&inst, &grid);
        // a stored integer q lands where the original position would: T + R(S∘(origin + step·q))
        let q = glam::Vec3::new(4.0, 6.0, 8.0);
        let original = glam::Vec3::from(grid.origin) + q * 0.5;
        let r = glam::Quat::from_array(inst.rotations[0]);
        let want = glam::Vec3::from(inst.translations[0]) + r * (original * 2.0);
        let got = glam::Vec3::from(placed.translations[0]) + r * (q * glam::Vec3::from(placed.scales[0]));
        assert!((want - got).length() < 1e-5, "{want} {got}");
    }
}
