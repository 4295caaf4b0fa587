//! One-sided sampled Hausdorff distance between two meshes, as Metro measures it (Cignoni, Rocchini
//! & Scopigno, "Metro: measuring error on simplified surfaces", CGF 1998): points sampled on the
//! candidate's triangles (area-weighted, seeded), each one's distance to the reference surface found
//! through a uniform grid of the reference's triangles; closest point on a triangle after Ericson,
//! "Real-Time Collision Detection" §5.1.5.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::bake::image::Image;
use crate::mesh::{AlphaMode, Material, Mesh};
use crate::random::mix64;

/// Largest grid side in cells (the grid holds at most this cubed cell lists).
const MAX_GRID_SIDE: usize = 96;

/// What [`hausdorff`] measured, in metres.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct HausdorffError {
    /// Largest distance of a sample to the reference surface.
    pub max_m: f64,
    pub mean_m: f64,
    /// Samples measured (alpha-masked texels that are cut away are not samples).
    pub samples: usize,
}

/// The reference surface, triangles filed in a uniform grid by their bounding boxes.
pub struct TriangleGrid {
    triangles: Vec<[DVec3; 3]>,
    origin: DVec3,
    cell_m: f64,
    dims: [usize; 3],
    /// Cell k's triangles are `items[starts[k]..starts[k + 1]]`.
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl TriangleGrid {
    /// Files every finite triangle of `mesh`; None when it has none.
    pub fn new(mesh: &Mesh) -> Option<TriangleGrid> {
        let triangles: Vec<[DVec3; 3]> = mesh
            .primitives
            .iter()
            .flat_map(|p| {
                p.indices.chunks_exact(3).map(move |t| {
                    [t[0], t[1], t[2]].map(|i| p.positions.get(i as usize).map(|v| DVec3::from(v.map(f64::from))))
                })
            })
            .filter_map(|t| match t {
                [Some(a), Some(b), Some(c)] if a.is_finite() && b.is_finite() && c.is_finite() => Some([a, b, c]),
                _ => None,
            })
            .collect();
        if triangles.is_empty() {
            return None;
        }
        let (lo, hi) = triangles
            .iter()
            .flatten()
            .fold((DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)), |(lo, hi), &p| (lo.min(p), hi.max(p)));
        let extent = (hi - lo).max(DVec3::splat(1e-6));
        // about two triangles per cell, no side over MAX_GRID_SIDE
        let cell_for_count = (extent.x * extent.y * extent.z / (triangles.len() as f64 / 2.0)).cbrt();
        let cell_m = cell_for_count.max(extent.max_element() / MAX_GRID_SIDE as f64).max(1e-6);
        let dims = [extent.x, extent.y, extent.z].map(|e| ((e / cell_m).ceil() as usize).clamp(1, MAX_GRID_SIDE));
        let mut grid = TriangleGrid { triangles, origin: lo, cell_m, dims, starts: Vec::new(), items: Vec::new() };
        // count per cell, prefix sums, then fill
        let n_cells = dims[0] * dims[1] * dims[2];
        let mut counts = vec![0u32; n_cells + 1];
        for t in &grid.triangles {
            grid.for_cells(t, |k| counts[k] += 1);
        }
        let mut starts = vec![0u32; n_cells + 1];
        for k in 0..n_cells {
            starts[k + 1] = starts[k] + counts[k];
        }
        let mut fill = starts.clone();
        let mut items = vec![0u32; starts[n_cells] as usize];
        for (i, t) in grid.triangles.iter().enumerate() {
            grid.for_cells(t, |k| {
                items[fill[k] as usize] = i as u32;
                fill[k] += 1;
            });
        }
        grid.starts = starts;
        grid.items = items;
        Some(grid)
    }

    fn cell_of(&self, p: DVec3) -> [usize; 3] {
        let c = (p - self.origin) / self.cell_m;
        let clamp = |v: f64, d: usize| (v.floor().max(0.0) as usize).min(d - 1);
        [clamp(c.x, self.dims[0]), clamp(c.y, self.dims[1]), clamp(c.z, self.dims[2])]
    }

    fn index(&self, c: [usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    fn for_cells(&self, t: &[DVec3; 3], mut f: impl FnMut(usize)) {
        let lo = self.cell_of(t[0].min(t[1]).min(t[2]));
        let hi = self.cell_of(t[0].max(t[1]).max(t[2]));
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    f(self.index([x, y, z]));
                }
            }
        }
    }

    /// Distance from `p` to the nearest filed triangle. Rings of cells around p's (clamped) cell are
    /// searched until the ring is farther than the best distance found: projection onto the grid's
    /// box shortens no distance to a point inside it, so the bound holds for points outside too.
    pub fn distance(&self, p: DVec3) -> f64 {
        let c = self.cell_of(p);
        let mut best = f64::INFINITY;
        let max_ring = self.dims.iter().copied().max().unwrap_or(1);
        for ring in 0..=max_ring {
            let lo = c.map(|v| v.saturating_sub(ring));
            let hi = [0, 1, 2].map(|k| (c[k] + ring).min(self.dims[k] - 1));
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        let on_ring = [x, y, z].iter().zip(c).any(|(&v, cv)| v.abs_diff(cv) == ring);
                        if !on_ring {
                            continue;
                        }
                        let k = self.index([x, y, z]);
                        for &i in &self.items[self.starts[k] as usize..self.starts[k + 1] as usize] {
                            let t = &self.triangles[i as usize];
                            best = best.min((closest_on_triangle(p, t[0], t[1], t[2]) - p).length());
                        }
                    }
                }
            }
            if best <= ring as f64 * self.cell_m {
                break;
            }
        }
        best
    }
}

/// The point of triangle abc nearest to p (Ericson's Voronoi-region walk).
pub fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom.abs() < 1e-300 {
        return a; // degenerate triangle: any corner is on it
    }
    a + ab * (vb / denom) + ac * (vc / denom)
}

/// Unit-interval number from a hash.
fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Distances of about `samples` points on `candidate`'s triangles (area-weighted, each triangle at
/// least one; positions from a hash of `seed` and the triangle's number, so the result does not
/// depend on evaluation order) to `reference`'s surface. Where a primitive's material is
/// alpha-masked with a texture, samples on texels below the cutoff are skipped: they are not drawn.
pub fn hausdorff(
    candidate: &Mesh,
    materials: &[Material],
    textures: &[Image],
    reference: &TriangleGrid,
    samples: usize,
    seed: u64,
) -> HausdorffError {
    let area = |p: &crate::mesh::Primitive, t: usize| {
        let c = p.triangle_cross(t);
        0.5 * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
    };
    let total: f64 = candidate
        .primitives
        .iter()
        .map(|p| (0..p.triangle_count()).map(|t| area(p, t)).filter(|a| a.is_finite()).sum::<f64>())
        .sum();
    let mut out = HausdorffError::default();
    let mut sum = 0.0;
    let mut serial = 0u64;
    for p in &candidate.primitives {
        let mask = p.material.and_then(|m| materials.get(m)).and_then(|m| match (m.alpha_mode, m.base_color_texture) {
            (AlphaMode::Mask { cutoff }, Some(t)) => textures.get(t).map(|img| (img, cutoff, m.base_color[3])),
            _ => None,
        });
        for t in 0..p.triangle_count() {
            serial += 1;
            let a = area(p, t);
            if !a.is_finite() {
                continue;
            }
            let n = if total > 0.0 { ((a / total * samples as f64).round() as usize).max(1) } else { 1 };
            let ids = [0, 1, 2].map(|k| p.indices[3 * t + k] as usize);
            let corner = ids.map(|i| DVec3::from(p.positions[i].map(f64::from)));
            for j in 0..n {
                let h = mix64(seed ^ mix64(serial.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ j as u64));
                let (mut u, mut v) = (unit(h), unit(mix64(h)));
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                if let (Some((img, cutoff, alpha)), false) = (mask, p.uvs.is_empty()) {
                    let uv = [0, 1].map(|k| {
                        ((1.0 - u - v) * p.uvs[ids[0]][k] as f64
                            + u * p.uvs[ids[1]][k] as f64
                            + v * p.uvs[ids[2]][k] as f64) as f32
                    });
                    if img.sample_bilinear(uv)[3] * alpha < cutoff {
                        continue;
                    }
                }
                let q = corner[0] + (corner[1] - corner[0]) * u + (corner[2] - corner[0]) * v;
                let d = reference.distance(q);
                if d.is_finite() {
                    out.max_m = out.max_m.max(d);
                    sum += d;
                    out.samples += 1;
                }
            }
        }
    }
    out.mean_m = if out.samples > 0 { sum / out.samples as f64 } else { 0.0 };
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Primitive;

    fn quad(y: f32) -> Mesh {
        let p = Primitive {
            positions: vec![[0.0, y, 0.0], [1.0, y, 0.0], [1.0, y, 1.0], [0.0, y, 1.0]],
            indices: vec![0, 2, 1, 0, 3, 2],
            ..Primitive::default()
        };
        Mesh { name: "q".into(), primitives: vec![p], extras: None }
    }

    #[test]
    fn closest_point_regions() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        assert_eq!(closest_on_triangle(DVec3::new(-1.0, -1.0, 0.0), a, b, c), a);
        assert_eq!(closest_on_triangle(DVec3::new(0.25, 0.25, 3.0), a, b, c), DVec3::new(0.25, 0.25, 0.0));
        assert!((closest_on_triangle(DVec3::new(1.0, 1.0, 0.0), a, b, c) - DVec3::new(0.5, 0.5, 0.0)).length() < 1e-12);
    }

    #[test]
    fn parallel_planes_are_their_distance_apart() {
        let grid = TriangleGrid::new(&quad(0.0)).unwrap();
        let e = hausdorff(&quad(0.25), &[], &[], &grid, 500, 1);
        assert!((e.max_m - 0.25).abs() < 1e-6 && (e.mean_m - 0.25).abs() < 1e-6, "{e:?}");
        assert!(e.samples >= 500);
        let same = hausdorff(&quad(0.0), &[], &[], &grid, 200, 1);
        assert!(same.max_m < 1e-6);
        // a point far outside the grid still finds the surface
        assert!((grid.distance(DVec3::new(5.0, 0.0, 0.5)) - 4.0).abs() < 1e-9);
    }
}
