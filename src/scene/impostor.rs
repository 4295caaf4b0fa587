//! Impostors as a view sees them. A tree's impostor level is one quad facing +Z (view 0 of the
//! atlas) with the other baked views' cells in its mesh extras (`verdant_impostor`: the views,
//! their azimuth step, the centre, the cells' uv rectangles). An engine's impostor shader turns the
//! quad to the eye and shows the cell baked from the direction it is seen from; a static file does
//! neither, so an instance seen from the side showed a quad edge-on (a sliver or nothing) and every
//! instance the same baked view whatever its yaw. `scene.glb` is the scene as drawn from one view,
//! so the view stage does what the shader would: each impostor instance shows view k's quad (the
//! quad turned to azimuth k about the vertical through the centre, textured with cell k), k the
//! baked view nearest the direction from the instance's centre to the eye in the instance's own
//! frame. The quad then faces the eye within half a step (22.5° for 8 views; at worst cos 22.5° =
//! 92 % of its width), with the picture baked from that side. The tree analyzer measures view k's
//! card turned the rest of the way to the eye; turning each instance that remainder too would move
//! its transform off the table's row, which engines replay, so scene.glb keeps the rows'.

use serde_json::Value;

use crate::export::table::PlacementRow;
use crate::mesh::Mesh;
use crate::plants::tree_lod::IMPOSTOR_EXTRAS_KEY;
use crate::scene::view_stage::rotate;

/// Key in a derived mesh's extras naming the baked view it shows.
pub const IMPOSTOR_VIEW_EXTRAS_KEY: &str = "verdant_impostor_view";

/// The baked views of one impostor mesh, from its extras.
#[derive(Debug, Clone, PartialEq)]
pub struct ImpostorViews {
    step_deg: f64,
    /// In the mesh's frame (m).
    centre: [f64; 3],
    /// (u0, v0, u1, v1) of each view's cell; the mesh shows cell 0.
    cells: Vec<[f64; 4]>,
}

impl ImpostorViews {
    /// The views `mesh`'s extras describe; None for a mesh that is no impostor (or whose extras
    /// are incomplete: it is then drawn as written).
    pub fn of(mesh: &Mesh) -> Option<ImpostorViews> {
        let e = mesh.extras.as_ref()?.get(IMPOSTOR_EXTRAS_KEY)?;
        let num = |v: &Value| v.as_f64().filter(|x| x.is_finite());
        let views = e.get("views")?.as_u64()? as usize;
        let step_deg = num(e.get("azimuth_step_deg")?)?;
        let c = e.get("centre")?.as_array()?;
        let centre = [num(c.first()?)?, num(c.get(1)?)?, num(c.get(2)?)?];
        let cells: Vec<[f64; 4]> = e
            .get("cells_uv")?
            .as_array()?
            .iter()
            .map(|r| {
                let r = r.as_array()?;
                Some([num(r.first()?)?, num(r.get(1)?)?, num(r.get(2)?)?, num(r.get(3)?)?])
            })
            .collect::<Option<_>>()?;
        let usable = views > 1
            && cells.len() == views
            && step_deg > 0.0
            && cells.iter().all(|r| r[2] > r[0] && r[3] > r[1])
            && mesh.primitives.iter().all(|p| p.uvs.len() == p.positions.len());
        usable.then_some(ImpostorViews { step_deg, centre, cells })
    }

    pub fn views(&self) -> usize {
        self.cells.len()
    }

    /// The baked view instance `row` shows to an eye at `eye` (world, m): the one nearest the
    /// direction from its centre to the eye, in its own frame (rotation and scale undone).
    pub fn view_for(&self, row: &PlacementRow, eye: [f64; 3]) -> usize {
        let s = row.scale.map(|c| c as f64);
        let q = row.rotation;
        let scaled = [self.centre[0] * s[0], self.centre[1] * s[1], self.centre[2] * s[2]];
        let c = rotate(q, scaled);
        let p = row.position.map(|x| x as f32 as f64);
        let to_eye = [eye[0] - (p[0] + c[0]), eye[1] - (p[1] + c[1]), eye[2] - (p[2] + c[2])];
        let local = rotate([-q[0], -q[1], -q[2], q[3]], to_eye);
        let (dx, dz) = (local[0] / s[0].max(f64::MIN_POSITIVE), local[2] / s[2].max(f64::MIN_POSITIVE));
        if !(dx.is_finite() && dz.is_finite()) || (dx == 0.0 && dz == 0.0) {
            return 0;
        }
        let k = (dx.atan2(dz).to_degrees() / self.step_deg).round() as i64;
        k.rem_euclid(self.views() as i64) as usize
    }

    /// `base` (the impostor's quad, showing view 0) as view `k`: turned to azimuth k·step about the
    /// vertical through the centre (positions, normals, tangents), textured with cell k. Named
    /// `<base>_view<k>`; its extras name the view only (the base's `verdant_impostor` recipe, which
    /// says the quad faces +Z and shows cell 0, no longer holds for it).
    pub fn mesh(&self, base: &Mesh, k: usize) -> Mesh {
        let a = (k as f64 * self.step_deg).to_radians();
        let (sin, cos) = a.sin_cos();
        // about +Y: +Z (view 0's normal) goes to (sin a, 0, cos a), +X to (cos a, 0, −sin a)
        let turn = |x: f64, z: f64| (x * cos + z * sin, -x * sin + z * cos);
        let [c0, ck] = [self.cells[0], self.cells[k.min(self.views() - 1)]];
        let remap = |t: f32, axis: usize| {
            let f = (t as f64 - c0[axis]) / (c0[axis + 2] - c0[axis]);
            (ck[axis] + f * (ck[axis + 2] - ck[axis])) as f32
        };
        let mut out = base.clone();
        out.name = format!("{}_view{k}", base.name);
        for p in &mut out.primitives {
            for v in &mut p.positions {
                let (x, z) = turn(v[0] as f64 - self.centre[0], v[2] as f64 - self.centre[2]);
                *v = [(x + self.centre[0]) as f32, v[1], (z + self.centre[2]) as f32];
            }
            for n in &mut p.normals {
                let (x, z) = turn(n[0] as f64, n[2] as f64);
                *n = [x as f32, n[1], z as f32];
            }
            for t in &mut p.tangents {
                let (x, z) = turn(t[0] as f64, t[2] as f64);
                *t = [x as f32, t[1], z as f32, t[3]];
            }
            for uv in &mut p.uvs {
                *uv = [remap(uv[0], 0), remap(uv[1], 1)];
            }
        }
        let mut extras = match base.extras.clone() {
            Some(Value::Object(m)) => m,
            _ => serde_json::Map::new(),
        };
        extras.remove(IMPOSTOR_EXTRAS_KEY);
        extras.insert(IMPOSTOR_VIEW_EXTRAS_KEY.into(), Value::from(k));
        out.extras = Some(Value::Object(extras));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Primitive;

    /// A 2 m quad at z = 0 facing +Z around (0, 1, 0), showing the first of 8 cells of a 4 × 2 grid.
    fn impostor() -> Mesh {
        let cells: Vec<[f64; 4]> = (0..8)
            .map(|k| [(k % 4) as f64 * 0.25, (k / 4) as f64 * 0.5, (k % 4 + 1) as f64 * 0.25, (k / 4 + 1) as f64 * 0.5])
            .collect();
        Mesh {
            name: "t_LOD4".into(),
            primitives: vec![Primitive {
                positions: vec![[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 2.0, 0.0], [-1.0, 2.0, 0.0]],
                normals: vec![[0.0, 0.0, 1.0]; 4],
                tangents: vec![[1.0, 0.0, 0.0, 1.0]; 4],
                uvs: vec![[0.0, 0.5], [0.25, 0.5], [0.25, 0.0], [0.0, 0.0]],
                indices: vec![0, 1, 2, 0, 2, 3],
                ..Primitive::default()
            }],
            extras: Some(serde_json::json!({ IMPOSTOR_EXTRAS_KEY: {
                "views": 8, "azimuth_step_deg": 45.0, "centre": [0.0, 1.0, 0.0], "size_m": 2.0, "cells_uv": cells,
            }})),
        }
    }

    fn row(position: [f64; 3], yaw_deg: f64, scale: f32) -> PlacementRow {
        let h = (yaw_deg.to_radians() * 0.5) as f32;
        PlacementRow {
            position,
            rotation: [0.0, h.sin(), 0.0, h.cos()],
            scale: [scale; 3],
            yaw_deg: yaw_deg as f32,
            tile: 0,
            variant: 0,
        }
    }

    #[test]
    fn the_view_is_the_baked_direction_nearest_the_eye_in_the_instance_frame() {
        let v = ImpostorViews::of(&impostor()).expect("an impostor");
        assert_eq!(v.views(), 8);
        // eye on +Z of an unturned instance: view 0; on +X: view 2 (90°); on −Z: view 4
        assert_eq!(v.view_for(&row([0.0; 3], 0.0, 1.0), [0.0, 1.0, 50.0]), 0);
        assert_eq!(v.view_for(&row([0.0; 3], 0.0, 1.0), [50.0, 1.0, 0.0]), 2);
        assert_eq!(v.view_for(&row([0.0; 3], 0.0, 1.0), [0.0, 1.0, -50.0]), 4);
        assert_eq!(v.view_for(&row([0.0; 3], 0.0, 1.0), [-50.0, 30.0, 1.0]), 6);
        // the instance turned 90° about +Y: the eye on +X is on its own +Z
        assert_eq!(v.view_for(&row([0.0; 3], 90.0, 1.0), [50.0, 1.0, 0.0]), 0);
        // from its centre, not its origin: an eye straight above the origin but off the centre
        assert_eq!(v.view_for(&row([10.0, 0.0, 10.0], 0.0, 2.0), [10.0, 100.0, 12.0]), 0);
        // rounding to the nearest step: 20° → 0, 25° → 1
        let at = |deg: f64| [100.0 * deg.to_radians().sin(), 1.0, 100.0 * deg.to_radians().cos()];
        assert_eq!(v.view_for(&row([0.0; 3], 0.0, 1.0), at(20.0)), 0);
        assert_eq!(v.view_for(&row([0.0; 3], 0.0, 1.0), at(25.0)), 1);
        assert_eq!(v.view_for(&row([0.0; 3], 0.0, 1.0), at(-25.0)), 7);
    }

    #[test]
    fn view_k_faces_azimuth_k_and_shows_cell_k() {
        let base = impostor();
        let v = ImpostorViews::of(&base).unwrap();
        let m = v.mesh(&base, 2);
        assert_eq!(m.name, "t_LOD4_view2");
        assert_eq!(m.extras.as_ref().unwrap()[IMPOSTOR_VIEW_EXTRAS_KEY], 2);
        assert!(m.extras.as_ref().unwrap().get(IMPOSTOR_EXTRAS_KEY).is_none(), "the recipe for the +Z quad dropped");
        assert!(ImpostorViews::of(&m).is_none(), "a turned view is not turned again");
        let p = &m.primitives[0];
        // view 2 faces +X: the quad lies in x = 0, spanning z from +1 (its left) to −1
        for n in &p.normals {
            assert!((n[0] - 1.0).abs() < 1e-6 && n[2].abs() < 1e-6, "{n:?}");
        }
        assert!(p.positions.iter().all(|q| q[0].abs() < 1e-6), "{:?}", p.positions);
        assert!((p.positions[0][2] - 1.0).abs() < 1e-6 && (p.positions[1][2] + 1.0).abs() < 1e-6);
        assert_eq!(p.tangents[0][3], 1.0);
        assert!((p.tangents[0][2] + 1.0).abs() < 1e-6, "the tangent turns with the quad");
        // cell 2 of the grid: u in [0.5, 0.75], v in [0, 0.5]
        assert_eq!(p.uvs, vec![[0.5, 0.5], [0.75, 0.5], [0.75, 0.0], [0.5, 0.0]]);
        assert_eq!(v.mesh(&base, 0).primitives, base.primitives, "view 0 is the quad as written");
    }

    #[test]
    fn a_mesh_without_complete_impostor_extras_is_drawn_as_written() {
        let mut m = impostor();
        m.extras.as_mut().unwrap()[IMPOSTOR_EXTRAS_KEY]["views"] = 7.into();
        assert!(ImpostorViews::of(&m).is_none(), "7 views for 8 cells");
        m.extras = None;
        assert!(ImpostorViews::of(&m).is_none());
        m.extras = Some(serde_json::json!({ IMPOSTOR_EXTRAS_KEY: { "views": 8 } }));
        assert!(ImpostorViews::of(&m).is_none());
    }
}
