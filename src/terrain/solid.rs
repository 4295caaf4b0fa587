//! Closing a terrain surface downward. Skirts: vertical strips hanging from a chunk's boundary, the
//! usual filler for cracks between chunks drawn at different levels of detail (as in chunked LoD
//! terrain, Ulrich 2002). Base: walls from the map's outer border down to a flat bottom, making the
//! terrain a watertight solid (for printing, dioramas, volume queries).

use crate::heightfield::Heightfield;
use crate::mesh::Primitive;

use super::chunks::IdMap;

/// `y` lowered by `depth_m`, or `None` when f32 cannot hold a finite value strictly below `y`
/// (a depth far too small for the height's precision, or absurdly large).
pub fn lowered(y: f32, depth_m: f64) -> Option<f32> {
    let low = (y as f64 - depth_m) as f32;
    (low.is_finite() && low < y).then_some(low)
}

/// Adds a skirt to `prim` under `edges`: directed boundary edges (a, b) of its surface triangles,
/// in local vertex indices, each running the way it does in its triangle (interior on the left).
///
/// Each edge gets a quad down to the lowered copies a′, b′, wound (b, a, a′), (b, a′, b′): with
/// e = b − a its normal is depth·(e × ŷ), which points away from the triangle's interior, so the
/// skirt's front faces outward from the chunk. A lowered vertex copies its top vertex's normal and
/// UV so the skirt shades like the edge it hangs from; it is shared by the quads on either side.
/// On a depth f32 cannot represent, returns the offending top height and leaves `prim` unchanged.
pub fn add_skirt(prim: &mut Primitive, edges: &[[u32; 2]], depth_m: f64) -> Result<(), f32> {
    if edges.is_empty() {
        return Ok(());
    }
    let top_count = prim.positions.len();
    // lowered copy of each top vertex, created on first use
    let mut below = vec![u32::MAX; top_count];
    let mut positions = Vec::new();
    let mut source = Vec::new();
    let mut indices = Vec::with_capacity(edges.len() * 6);
    for &[a, b] in edges {
        let mut low = |v: u32| -> Result<u32, f32> {
            let slot = &mut below[v as usize];
            if *slot == u32::MAX {
                let [x, y, z] = prim.positions[v as usize];
                let y_low = lowered(y, depth_m).ok_or(y)?;
                *slot = (top_count + positions.len()) as u32;
                positions.push([x, y_low, z]);
                source.push(v as usize);
            }
            Ok(*slot)
        };
        let (a_low, b_low) = (low(a)?, low(b)?);
        indices.extend_from_slice(&[b, a, a_low, b, a_low, b_low]);
    }
    // copy attributes from the top vertices
    for &v in &source {
        if !prim.normals.is_empty() {
            prim.normals.push(prim.normals[v]);
        }
        if !prim.uvs.is_empty() {
            prim.uvs.push(prim.uvs[v]);
        }
        if !prim.colors.is_empty() {
            prim.colors.push(prim.colors[v]);
        }
    }
    prim.positions.extend(positions);
    prim.indices.extend(indices);
    Ok(())
}

/// Side of the map's rectangle an edge between two border samples lies on: 0 = row 0 (faces −z),
/// 1 = last column (+x), 2 = last row (+z), 3 = column 0 (−x). `None` if the edge is not on one side.
fn border_side(a: [u32; 2], b: [u32; 2], width: usize, height: usize) -> Option<usize> {
    let (last_i, last_j) = ((width - 1) as u32, (height - 1) as u32);
    if a[1] == 0 && b[1] == 0 {
        Some(0)
    } else if a[0] == last_i && b[0] == last_i {
        Some(1)
    } else if a[1] == last_j && b[1] == last_j {
        Some(2)
    } else if a[0] == 0 && b[0] == 0 {
        Some(3)
    } else {
        None
    }
}

const SIDE_NORMALS: [[f32; 3]; 4] = [[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]];

/// Walls and bottom that close a surface whose outer border is `border`: its directed boundary
/// edges (a, b) in sample coordinates, as they run in their triangles, all on the map's rectangle.
///
/// Walls hang from each border edge to `base_y` with the same (b, a, a′), (b, a′, b′) winding as a
/// skirt; the bottom is a fan from the rectangle's centre over every bottom edge, so each wall's
/// bottom edge meets exactly one bottom triangle (running the other way) and no fan triangle is
/// degenerate (the centre is strictly inside a convex outline). Walls and bottom have their own
/// vertices (side normals ±x/±z, bottom −y) so shading is flat there; positions still coincide with
/// the surface's border samples exactly, which makes the whole watertight by position.
/// `base_y` must lie strictly below every height. Returns the first edge not on the border as `Err`.
pub fn base_primitive(hf: &Heightfield, border: &[[[u32; 2]; 2]], base_y: f32) -> Result<Primitive, [[u32; 2]; 2]> {
    let mut prim = Primitive { material: Some(0), ..Primitive::default() };
    if border.is_empty() {
        return Ok(prim);
    }
    let (w, h) = (hf.width, hf.height);
    let sample_key = |s: [u32; 2]| s[1] as u64 * w as u64 + s[0] as u64;
    // vertices are created on first use and found again through these keys (never iterated)
    let mut walls: IdMap<(u64, usize, bool), u32> = IdMap::default();
    let mut floor: IdMap<u64, u32> = IdMap::default();
    let push = |prim: &mut Primitive, p: [f32; 3], n: [f32; 3], uv: [f32; 2]| {
        prim.positions.push(p);
        prim.normals.push(n);
        prim.uvs.push(uv);
        (prim.positions.len() - 1) as u32
    };
    let centre =
        [((w - 1) as f64 * hf.cell_size_m / 2.0) as f32, base_y, ((h - 1) as f64 * hf.cell_size_m / 2.0) as f32];
    let centre_index = push(&mut prim, centre, [0.0, -1.0, 0.0], [0.5, 0.5]);
    for &[a, b] in border {
        let side = border_side(a, b, w, h).ok_or([a, b])?;
        let mut wall = |prim: &mut Primitive, s: [u32; 2], low: bool| -> u32 {
            *walls.entry((sample_key(s), side, low)).or_insert_with(|| {
                let mut p = hf.position(s[0] as usize, s[1] as usize);
                if low {
                    p[1] = base_y;
                }
                push(prim, p, SIDE_NORMALS[side], hf.planar_uv(s[0] as usize, s[1] as usize))
            })
        };
        let (ta, tb, la, lb) =
            (wall(&mut prim, a, false), wall(&mut prim, b, false), wall(&mut prim, a, true), wall(&mut prim, b, true));
        prim.indices.extend_from_slice(&[tb, ta, la, tb, la, lb]);
        let mut bottom = |prim: &mut Primitive, s: [u32; 2]| -> u32 {
            *floor.entry(sample_key(s)).or_insert_with(|| {
                let p = hf.position(s[0] as usize, s[1] as usize);
                push(prim, [p[0], base_y, p[2]], [0.0, -1.0, 0.0], hf.planar_uv(s[0] as usize, s[1] as usize))
            })
        };
        let (fa, fb) = (bottom(&mut prim, a), bottom(&mut prim, b));
        // the wall's bottom edge runs a′→b′; the fan triangle takes it back b′→a′, facing −y
        prim.indices.extend_from_slice(&[centre_index, fb, fa]);
    }
    Ok(prim)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lowering_rejects_unrepresentable_depths() {
        assert_eq!(lowered(10.0, 2.5), Some(7.5));
        assert_eq!(lowered(1000.0, 1e-9), None, "lost in f32 rounding");
        assert_eq!(lowered(0.0, 1e300), None, "not finite in f32");
    }

    #[test]
    fn skirt_quad_faces_away_from_its_triangle() {
        // one CCW triangle (0,0), (0,1), (1,0) at y = 0
        let mut p = Primitive {
            positions: vec![[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]],
            normals: vec![[0.0, 1.0, 0.0]; 3],
            indices: vec![0, 1, 2],
            ..Primitive::default()
        };
        add_skirt(&mut p, &[[0, 1]], 2.0).unwrap();
        assert_eq!(p.positions.len(), 5);
        assert_eq!(p.normals.len(), 5);
        assert_eq!(p.positions[3], [0.0, -2.0, 0.0]);
        // the edge x = 0 has the triangle on +x: both skirt triangles must face −x
        for t in 1..3 {
            let n = p.triangle_cross(t);
            assert!(n[0] < 0.0 && n[1] == 0.0 && n[2] == 0.0, "{n:?}");
        }
        // an unrepresentable depth leaves the primitive as it was
        let before = p.clone();
        assert_eq!(add_skirt(&mut p, &[[1, 2]], 1e300), Err(0.0));
        assert_eq!(p, before);
    }
}
