//! Marker meshes: small stand-ins that instanced species reference until the grass and tree
//! stages make real plants. Each is built at its nominal size in metres, base at the origin,
//! +Y up, so an instance's scale multiplies a plausible size.

use crate::mesh::{Material, Mesh, Primitive};
use crate::plants::SpeciesKind;

/// Nominal height in metres of a kind's marker.
pub fn nominal_height_m(kind: SpeciesKind) -> f32 {
    match kind {
        SpeciesKind::Tree => 8.0,
        SpeciesKind::Grass => 0.4,
        SpeciesKind::Flower => 0.3,
        SpeciesKind::Mesh => 1.0,
    }
}

/// A distinct, stable colour per species (linear RGB), also used for its preview dots.
pub fn species_color(kind: SpeciesKind, index: usize) -> [f32; 4] {
    let base: [[f32; 3]; 4] = match kind {
        SpeciesKind::Tree => [[0.05, 0.25, 0.06], [0.10, 0.32, 0.05], [0.03, 0.18, 0.10], [0.15, 0.28, 0.03]],
        SpeciesKind::Grass => [[0.35, 0.60, 0.12], [0.45, 0.65, 0.15], [0.30, 0.52, 0.20], [0.55, 0.62, 0.18]],
        SpeciesKind::Flower => [[0.90, 0.75, 0.10], [0.85, 0.25, 0.45], [0.55, 0.35, 0.85], [0.95, 0.95, 0.95]],
        SpeciesKind::Mesh => [[0.55, 0.50, 0.45], [0.45, 0.45, 0.50], [0.60, 0.40, 0.30], [0.40, 0.40, 0.40]],
    };
    let c = base[index % base.len()];
    [c[0], c[1], c[2], 1.0]
}

fn push_quad(p: &mut Primitive, corners: [[f32; 3]; 4], normal: [f32; 3]) {
    let base = p.positions.len() as u32;
    for (k, c) in corners.iter().enumerate() {
        p.positions.push(*c);
        p.normals.push(normal);
        p.uvs.push([if k == 1 || k == 2 { 1.0 } else { 0.0 }, if k >= 2 { 0.0 } else { 1.0 }]);
    }
    p.indices.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
}

/// Two crossed vertical cards (double-sided material): the classic billboard clump.
fn crossed_cards(height: f32, width: f32) -> Primitive {
    let mut p = Primitive::default();
    let w = width / 2.0;
    // corners counter-clockwise seen from the normal's side: bottom-left, bottom-right, top-right, top-left
    push_quad(&mut p, [[-w, 0.0, 0.0], [w, 0.0, 0.0], [w, height, 0.0], [-w, height, 0.0]], [0.0, 0.0, 1.0]);
    push_quad(&mut p, [[0.0, 0.0, w], [0.0, 0.0, -w], [0.0, height, -w], [0.0, height, w]], [1.0, 0.0, 0.0]);
    p
}

/// A closed cone or prism around +Y from `y0` to `y1` with `sides` faces; radius r0 at the bottom,
/// r1 at the top (0 for a cone). Flat-shaded faces with their own vertices.
fn frustum(sides: usize, y0: f32, y1: f32, r0: f32, r1: f32) -> Primitive {
    let mut p = Primitive::default();
    let ring = |k: usize, r: f32, y: f32| {
        let a = std::f32::consts::TAU * k as f32 / sides as f32;
        [r * a.cos(), y, -r * a.sin()]
    };
    for k in 0..sides {
        let (a0, a1) = (ring(k, r0, y0), ring(k + 1, r0, y0));
        let (b0, b1) = (ring(k, r1, y1), ring(k + 1, r1, y1));
        // outward face normal from the face's plane
        let e1 = [a1[0] - a0[0], a1[1] - a0[1], a1[2] - a0[2]];
        let top = if r1 > 0.0 { b0 } else { b1 };
        let e2 = [top[0] - a0[0], top[1] - a0[1], top[2] - a0[2]];
        let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let n = [n[0] / len, n[1] / len, n[2] / len];
        let base = p.positions.len() as u32;
        if r1 > 0.0 {
            for v in [a0, a1, b1, b0] {
                p.positions.push(v);
                p.normals.push(n);
            }
            p.indices.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
        } else {
            for v in [a0, a1, b1] {
                p.positions.push(v);
                p.normals.push(n);
            }
            p.indices.extend_from_slice(&[base, base + 1, base + 2]);
        }
    }
    // bottom cap, facing −Y
    let base = p.positions.len() as u32;
    for k in 0..sides {
        p.positions.push(ring(k, r0, y0));
        p.normals.push([0.0, -1.0, 0.0]);
    }
    for k in 1..sides as u32 - 1 {
        p.indices.extend_from_slice(&[base, base + k + 1, base + k]);
    }
    p
}

/// The marker of a species and its material (index 0 of the returned list is used by the first
/// primitive, and so on).
pub fn marker(kind: SpeciesKind, name: &str, color: [f32; 4]) -> (Mesh, Vec<Material>) {
    let h = nominal_height_m(kind);
    let plain = |suffix: &str, c: [f32; 4], double_sided: bool| Material {
        name: format!("{name}_{suffix}"),
        base_color: c,
        roughness: 0.9,
        double_sided,
        ..Material::default()
    };
    let (primitives, materials) = match kind {
        SpeciesKind::Tree => {
            let trunk = frustum(6, 0.0, 0.3 * h, 0.04 * h, 0.03 * h);
            let crown = frustum(8, 0.2 * h, h, 0.25 * h, 0.0);
            (vec![trunk, crown], vec![plain("trunk", [0.25, 0.15, 0.07, 1.0], false), plain("crown", color, false)])
        }
        SpeciesKind::Grass | SpeciesKind::Flower => {
            (vec![crossed_cards(h, 0.6 * h)], vec![plain("cards", color, true)])
        }
        SpeciesKind::Mesh => (vec![frustum(4, 0.0, h, 0.5 * h, 0.5 * h)], vec![plain("box", color, false)]),
    };
    let primitives = primitives
        .into_iter()
        .enumerate()
        .map(|(k, mut p)| {
            p.material = Some(k);
            p.optimize_for_gpu().expect("a marker's 30 triangles fit meshoptimizer");
            p
        })
        .collect();
    (Mesh { name: format!("{name}_marker"), primitives, extras: None }, materials)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markers_are_valid_meshes_of_their_nominal_height() {
        for kind in [SpeciesKind::Tree, SpeciesKind::Grass, SpeciesKind::Flower, SpeciesKind::Mesh] {
            let (mesh, materials) = marker(kind, "s", species_color(kind, 0));
            assert_eq!(mesh.primitives.len(), materials.len());
            let mut top = 0.0f32;
            for p in &mesh.primitives {
                assert_eq!(p.normals.len(), p.positions.len());
                for n in &p.normals {
                    assert!(((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt() - 1.0).abs() < 1e-5);
                }
                for t in 0..p.triangle_count() {
                    let c = p.triangle_cross(t);
                    assert!(c.iter().map(|v| v * v).sum::<f64>() > 1e-12, "{kind:?}: degenerate triangle");
                    // winding agrees with the stored normal
                    let n = p.normals[p.indices[3 * t] as usize];
                    assert!(c[0] * n[0] as f64 + c[1] * n[1] as f64 + c[2] * n[2] as f64 > 0.0, "{kind:?}: winding");
                }
                top = p.positions.iter().fold(top, |m, q| m.max(q[1]));
                assert!(p.positions.iter().all(|q| q[1] >= 0.0));
            }
            assert!((top - nominal_height_m(kind)).abs() < 1e-5);
        }
    }
}
