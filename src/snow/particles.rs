//! The frozen first frame of the snowfall: deterministic initial flakes in the emitter's volume
//! (area-uniform in the near disc and in the far sector, uniform in height), as a CSV table and as a
//! glTF scene of flake quads instanced with EXT_mesh_gpu_instancing (one instanced node per atlas cell).

use std::fmt::Write as _;

use rayon::prelude::*;
use serde::Serialize;

use crate::mesh::{AlphaMode, Instances, Material, Mesh, Node, Primitive, Scene, Texture};
use crate::random::Stream;
use crate::snow::emitter::Emitter;
use crate::snow::error::SnowError;
use crate::snow::flakes::FlakeAtlas;

/// Stream tag of particle placement ("part").
const PARTICLE_TAG: u64 = 0x7061_7274;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Field {
    Near,
    Far,
}

/// One flake: position relative to the camera's ground point, diameter, atlas cell, initial sprite
/// angle and spin rate about the view axis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Particle {
    pub field: Field,
    pub position: [f32; 3],
    pub size_m: f32,
    pub cell: usize,
    pub angle_rad: f32,
    pub spin_rad_s: f32,
}

/// The initial flakes: `near_count` in the near cylinder, then `far.count` in the far sector. Flake
/// i of a field depends only on (seed, field, i), so the result is the same at any thread count.
pub fn particles(e: &Emitter, atlas: &FlakeAtlas) -> Result<Vec<Particle>, SnowError> {
    e.check()?;
    if atlas.cells.is_empty() {
        return crate::snow::error::bad("atlas", "has no cells".into(), "bake an atlas with at least one cell");
    }
    let make = |field: Field, i: u32| {
        let mut r = Stream::new(&[e.seed, PARTICLE_TAG, field as u64, i as u64]);
        let (radius, angle) = match (field, &e.far) {
            (Field::Far, Some(far)) => {
                let (r1, r2) = (e.near_radius_m, far.outer_radius_m);
                let rad = (r1 * r1 + r.unit() * (r2 * r2 - r1 * r1)).sqrt().clamp(r1, r2);
                let half = far.view_angle_deg.to_radians() / 2.0;
                (rad, r.range([-half, half]))
            }
            _ => (e.near_radius_m * r.unit().sqrt(), r.range([0.0, std::f32::consts::TAU])),
        };
        // angle 0 is straight ahead: the camera looks along −Z
        let position = [radius * angle.sin(), r.unit() * e.fall_height_m, -radius * angle.cos()];
        let cell = r.below(atlas.cells.len());
        let size_m = atlas.cells[cell].size_mm * 1e-3 * r.range([0.85, 1.15]);
        let angle_rad = r.range([0.0, std::f32::consts::TAU]);
        let spin_rad_s = r.range([-e.max_spin_rad_s, e.max_spin_rad_s]);
        Particle { field, position, size_m, cell, angle_rad, spin_rad_s }
    };
    let mut out: Vec<Particle> = (0..e.near_count).into_par_iter().map(|i| make(Field::Near, i)).collect();
    if let Some(far) = &e.far {
        out.par_extend((0..far.count).into_par_iter().map(|i| make(Field::Far, i)));
    }
    Ok(out)
}

/// `field,x,y,z,size_m,cell,angle_rad,spin_rad_s` with a header, one flake per line.
pub fn particles_csv(ps: &[Particle]) -> String {
    let mut s = String::with_capacity(64 * ps.len() + 64);
    s.push_str("field,x,y,z,size_m,cell,angle_rad,spin_rad_s\n");
    for p in ps {
        let field = match p.field {
            Field::Near => "near",
            Field::Far => "far",
        };
        let [x, y, z] = p.position;
        let _ = writeln!(s, "{field},{x},{y},{z},{},{},{},{}", p.size_m, p.cell, p.angle_rad, p.spin_rad_s);
    }
    s
}

/// The snowfall frame as a scene: per atlas cell one unit quad (x–y plane, facing +Z towards the
/// camera at the origin, UVs of that cell) instanced at its flakes, scaled by the flake size and
/// turned by its angle about Z; a double-sided MASK material with the atlas. Cells no flake uses get
/// no node.
pub fn snowfall_scene(name: &str, ps: &[Particle], atlas: &FlakeAtlas, alpha_cutoff: f32) -> Scene {
    let mut scene = Scene {
        name: name.into(),
        materials: vec![Material {
            name: "snowflake".into(),
            base_color_texture: Some(0),
            roughness: 0.6,
            alpha_mode: AlphaMode::Mask { cutoff: alpha_cutoff },
            double_sided: true,
            ..Material::default()
        }],
        textures: vec![Texture { name: format!("{name}_flakes"), png: atlas.png.clone() }],
        ..Scene::default()
    };
    for cell in 0..atlas.cells.len() {
        let mine: Vec<&Particle> = ps.iter().filter(|p| p.cell == cell).collect();
        if mine.is_empty() {
            continue;
        }
        let prim = flake_quad(atlas.cell_uv(cell));
        scene.meshes.push(Mesh { name: format!("flake_cell{cell}"), primitives: vec![prim], extras: None });
        let instances = Instances {
            translations: mine.iter().map(|p| p.position).collect(),
            rotations: mine
                .iter()
                .map(|p| {
                    let (s, c) = (p.angle_rad / 2.0).sin_cos();
                    [0.0, 0.0, s, c]
                })
                .collect(),
            scales: mine.iter().map(|p| [p.size_m, p.size_m, p.size_m]).collect(),
        };
        scene.nodes.push(Node {
            name: format!("snowfall_cell{cell}"),
            mesh: Some(scene.meshes.len() - 1),
            instances: Some(instances.into()),
            extras: Some(serde_json::json!({ "cell": cell, "kind": atlas.cells[cell].kind.name() })),
            ..Node::default()
        });
        scene.roots.push(scene.nodes.len() - 1);
    }
    scene
}

/// A 1 × 1 quad centred on the origin in the x–y plane, front face +Z, showing `rect` (v down).
fn flake_quad(rect: [f32; 4]) -> Primitive {
    let [u0, v0, u1, v1] = rect;
    Primitive {
        positions: vec![[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]],
        normals: vec![[0.0, 0.0, 1.0]; 4],
        uvs: vec![[u0, v1], [u1, v1], [u1, v0], [u0, v0]],
        indices: vec![0, 1, 2, 0, 2, 3],
        material: Some(0),
        ..Primitive::default()
    }
}
