//! One-sided sampled Hausdorff distance between two meshes, as Metro measures it (Cignoni, Rocchini
//! & Scopigno, "Metro: measuring error on simplified surfaces", CGF 1998): points sampled on the
//! candidate's triangles (area-weighted, seeded), each one's distance to the reference surface found
//! through a bounding-volume hierarchy of the reference's triangles (Rubin & Whitted 1980); closest point on a triangle after Ericson,
//! "Real-Time Collision Detection" §5.1.5.

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::bake::image::Image;
use crate::mesh::{AlphaMode, Material, Mesh};
use crate::random::mix64;

/// Most triangles in a leaf of the [`TriangleBvh`].
const LEAF_TRIANGLES: usize = 4;

/// A box is skipped when its squared distance exceeds the best one by more than this factor.
const PRUNE_SLACK: f64 = 1.0 + 1e-9;

/// Points measured per parallel batch (bounds the memory of a huge candidate's sample list).
const BATCH_POINTS: usize = 1 << 16;
/// Points measured one after another, each from its predecessor's nearest triangle.
const HINT_RUN: usize = 512;

/// What [`hausdorff`] measured, in metres.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct HausdorffError {
    /// Largest distance of a sample to the reference surface.
    pub max_m: f64,
    pub mean_m: f64,
    /// Samples measured (alpha-masked texels that are cut away are not samples).
    pub samples: usize,
}

/// The reference surface as a bounding-volume hierarchy of its triangles (median split on the
/// longest axis of the triangles' centroids, boxes around each node's triangles): a nearest-surface
/// query visits the nearer child first and skips every box farther than the best distance found,
/// so it costs about log n box tests and a few triangle tests wherever the point is (a uniform grid
/// fails on a tree: most of its box is empty air, its few filled cells hold hundreds of triangles).
pub struct TriangleBvh {
    /// In leaf order: leaf k's triangles are `triangles[start..start + count]`.
    triangles: Vec<[DVec3; 3]>,
    nodes: Vec<BvhNode>,
}

#[derive(Clone, Copy)]
struct BvhNode {
    lo: DVec3,
    hi: DVec3,
    /// Leaf: first triangle. Interior: index of the second child (the first is the next node).
    start: u32,
    /// Triangles in a leaf; 0 for an interior node.
    count: u32,
}

impl TriangleBvh {
    /// Files every finite triangle of `mesh`; None when it has none.
    pub fn new(mesh: &Mesh) -> Option<TriangleBvh> {
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
        let centroids: Vec<DVec3> = triangles.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect();
        let mut order: Vec<u32> = (0..triangles.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * triangles.len() / LEAF_TRIANGLES + 1);
        build(&triangles, &centroids, &mut order, 0, &mut nodes);
        let triangles = order.iter().map(|&i| triangles[i as usize]).collect();
        Some(TriangleBvh { triangles, nodes })
    }

    /// Distance from `p` to the nearest filed triangle: the smallest distance to any of them.
    pub fn distance(&self, p: DVec3) -> f64 {
        self.nearest(p, None).0
    }

    /// [`TriangleBvh::distance`] and the nearest triangle (its place in the hierarchy's order),
    /// starting from the distance to triangle `hint` (a neighbouring point's nearest): a close
    /// first bound prunes most boxes at once. The result does not depend on the hint: the minimum
    /// is over every triangle not provably farther, and the hint is one of them.
    pub fn nearest(&self, p: DVec3, hint: Option<u32>) -> (f64, Option<u32>) {
        // squared distances decide (sqrt is monotone, so the minimum is the same triangle's)
        let mut best = f64::INFINITY;
        let mut best_t = None;
        if let Some(t) = hint.and_then(|h| self.triangles.get(h as usize)) {
            best = (closest_on_triangle(p, t[0], t[1], t[2]) - p).length_squared();
            best_t = hint;
        }
        // depth ≤ log2(triangles) + 1 with median splits, and each step pushes at most one more
        let mut stack = [0u32; 72];
        let mut top = 1;
        // a point on a filed triangle (a level that keeps LoD0's branches) is done: nothing is nearer
        while top > 0 && best > 0.0 {
            top -= 1;
            let node = self.nodes[stack[top] as usize];
            // skipped only when clearly farther: a triangle's computed distance may round a few
            // ulps below its box's, and a near-tie must still be measured for the exact minimum
            if box_distance2(&node, p) > best * PRUNE_SLACK {
                continue;
            }
            if node.count > 0 {
                let (s, n) = (node.start as usize, node.count as usize);
                for (k, t) in self.triangles[s..s + n].iter().enumerate() {
                    let d2 = (closest_on_triangle(p, t[0], t[1], t[2]) - p).length_squared();
                    if d2 < best {
                        best = d2;
                        best_t = Some((s + k) as u32);
                    }
                }
                continue;
            }
            let (near, far) = (stack[top] + 1, node.start);
            let (dn, df) = (box_distance2(&self.nodes[near as usize], p), box_distance2(&self.nodes[far as usize], p));
            let (first, second) = if dn <= df { (near, far) } else { (far, near) };
            if top + 2 > stack.len() {
                // cannot happen for the depths above; stay exact rather than overflow
                let d = self
                    .triangles
                    .iter()
                    .map(|t| (closest_on_triangle(p, t[0], t[1], t[2]) - p).length())
                    .fold(f64::INFINITY, f64::min);
                return (d, None);
            }
            stack[top] = second;
            stack[top + 1] = first;
            top += 2;
        }
        (best.sqrt(), best_t)
    }
}

/// Appends the subtree over `order`'s triangles (indices into `triangles`, `offset` their place in
/// the final leaf order) to `nodes`; reorders `order` into leaf order.
fn build(triangles: &[[DVec3; 3]], centroids: &[DVec3], order: &mut [u32], offset: usize, nodes: &mut Vec<BvhNode>) {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    let (mut clo, mut chi) = (lo, hi);
    for &i in order.iter() {
        for v in &triangles[i as usize] {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
        clo = clo.min(centroids[i as usize]);
        chi = chi.max(centroids[i as usize]);
    }
    let here = nodes.len();
    nodes.push(BvhNode { lo, hi, start: offset as u32, count: order.len() as u32 });
    if order.len() <= LEAF_TRIANGLES {
        return;
    }
    let extent = chi - clo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let mid = order.len() / 2;
    // ties broken by triangle number: the tree does not depend on the sort's internals
    order.select_nth_unstable_by(mid, |&a, &b| {
        centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis]).then(a.cmp(&b))
    });
    let (left, right) = order.split_at_mut(mid);
    build(triangles, centroids, left, offset, nodes);
    let second = nodes.len() as u32;
    build(triangles, centroids, right, offset + mid, nodes);
    nodes[here].start = second;
    nodes[here].count = 0;
}

/// Squared distance from `p` to the node's box (0 inside).
#[inline]
fn box_distance2(node: &BvhNode, p: DVec3) -> f64 {
    let d = (node.lo - p).max(p - node.hi).max(DVec3::ZERO);
    d.length_squared()
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
    reference: &TriangleBvh,
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
    // points are gathered in order, measured in parallel batches and summed in that order: the
    // figures do not depend on the thread count
    let mut batch: Vec<DVec3> = Vec::with_capacity(BATCH_POINTS.min(samples + 64));
    let mut measure = |batch: &mut Vec<DVec3>| {
        // consecutive points lie on the same or neighbouring triangles: each starts from the
        // previous one's nearest reference triangle (the distances do not depend on it)
        let distances: Vec<f64> = batch
            .par_chunks(HINT_RUN)
            .flat_map_iter(|run| {
                run.iter().scan(None, |hint, q| {
                    let (d, t) = reference.nearest(*q, *hint);
                    *hint = t;
                    Some(d)
                })
            })
            .collect();
        for d in distances {
            if d.is_finite() {
                out.max_m = out.max_m.max(d);
                sum += d;
                out.samples += 1;
            }
        }
        batch.clear();
    };
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
                batch.push(corner[0] + (corner[1] - corner[0]) * u + (corner[2] - corner[0]) * v);
                if batch.len() == BATCH_POINTS {
                    measure(&mut batch);
                }
            }
        }
    }
    measure(&mut batch);
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
        let grid = TriangleBvh::new(&quad(0.0)).unwrap();
        let e = hausdorff(&quad(0.25), &[], &[], &grid, 500, 1);
        assert!((e.max_m - 0.25).abs() < 1e-6 && (e.mean_m - 0.25).abs() < 1e-6, "{e:?}");
        assert!(e.samples >= 500);
        let same = hausdorff(&quad(0.0), &[], &[], &grid, 200, 1);
        assert!(same.max_m < 1e-6);
        // a point far outside the grid still finds the surface
        assert!((grid.distance(DVec3::new(5.0, 0.0, 0.5)) - 4.0).abs() < 1e-9);
    }

    fn soup(coords: &[f32]) -> Mesh {
        let positions: Vec<[f32; 3]> = coords.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let indices = (0..(positions.len() / 3 * 3) as u32).collect();
        Mesh {
            name: "soup".into(),
            primitives: vec![Primitive { positions, indices, ..Primitive::default() }],
            extras: None,
        }
    }

    proptest::proptest! {
        /// The hierarchy's nearest distance is exactly the smallest distance to any triangle, for
        /// points inside and far outside the soup (clustered, overlapping and degenerate triangles).
        #[test]
        fn nearest_distance_equals_the_brute_force_minimum(
            coords in proptest::collection::vec(-4.0f32..4.0, 9..600),
            points in proptest::collection::vec((-40.0f64..40.0, -40.0f64..40.0, -40.0f64..40.0), 1..40),
            hint in 0u32..220,
        ) {
            let mesh = soup(&coords);
            let bvh = TriangleBvh::new(&mesh).unwrap();
            let tris: Vec<[DVec3; 3]> = coords
                .chunks_exact(9)
                .map(|c| [0, 1, 2].map(|k| DVec3::new(c[3 * k] as f64, c[3 * k + 1] as f64, c[3 * k + 2] as f64)))
                .collect();
            for (x, y, z) in points {
                let p = DVec3::new(x, y, z);
                let brute = tris
                    .iter()
                    .map(|t| (closest_on_triangle(p, t[0], t[1], t[2]) - p).length())
                    .fold(f64::INFINITY, f64::min);
                proptest::prop_assert_eq!(bvh.distance(p).to_bits(), brute.to_bits());
                // any starting triangle (one out of range is ignored): the same minimum, and the
                // triangle named is one at that distance
                let (d, t) = bvh.nearest(p, Some(hint));
                proptest::prop_assert_eq!(d.to_bits(), brute.to_bits());
                let t = bvh.triangles[t.unwrap() as usize];
                proptest::prop_assert_eq!((closest_on_triangle(p, t[0], t[1], t[2]) - p).length().to_bits(), brute.to_bits());
            }
        }
    }
}
