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
    /// Area-weighted points measured exactly, over which `mean_m` is taken (alpha-masked texels
    /// that are cut away are not samples).
    pub samples: usize,
    /// One more point on every triangle, measured for `max_m` only.
    #[serde(default)]
    pub coverage_samples: usize,
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
        self.nearest_above(p, hint, 0.0)
    }

    /// [`TriangleBvh::nearest`] where only a distance above `floor` matters: the search stops at
    /// the first triangle within `floor` and returns its distance (then an upper bound of the
    /// nearest, itself within `floor`); a distance above `floor` is exact.
    pub fn nearest_above(&self, p: DVec3, hint: Option<u32>, floor: f64) -> (f64, Option<u32>) {
        let floor2 = if floor > 0.0 { floor * floor } else { 0.0 };
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
        // a point on a filed triangle (a level that keeps LoD0's branches) is done: nothing is
        // nearer; so is one within the floor
        while top > 0 && best > floor2 {
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

/// Salt of the area-weighted samples' hashes (the coverage samples hash the triangle's number).
const AREA_SALT: u64 = 0xA5EA_5A3F_1E5D_0C17;

/// One triangle of the candidate as the sampler sees it.
struct SampledTriangle<'a> {
    corner: [DVec3; 3],
    /// Where the primitive is alpha-masked: its uvs at the corners, the texture, cutoff and alpha.
    mask: Option<([[f32; 2]; 3], &'a Image, f32, f32)>,
}

impl SampledTriangle<'_> {
    /// The point at barycentric (u, v) from hash `h`, unless it falls on a texel cut away.
    fn point(&self, h: u64) -> Option<DVec3> {
        let (mut u, mut v) = (unit(h), unit(mix64(h)));
        if u + v > 1.0 {
            (u, v) = (1.0 - u, 1.0 - v);
        }
        if let Some((uv, img, cutoff, alpha)) = self.mask {
            let at =
                [0, 1].map(|k| ((1.0 - u - v) * uv[0][k] as f64 + u * uv[1][k] as f64 + v * uv[2][k] as f64) as f32);
            if img.sample_bilinear(at)[3] * alpha < cutoff {
                return None;
            }
        }
        let [a, b, c] = self.corner;
        Some(a + (b - a) * u + (c - a) * v)
    }
}

/// Distances from points on `candidate`'s triangles to `reference`'s surface, as Metro samples
/// them, in two sets:
/// - about `samples` points spread by area (stratified: the k-th at a jittered k/samples of the
///   surface's cumulative area), each measured exactly: their mean is the mean distance over the
///   surface, and they count as `samples`;
/// - one point on every triangle, so no triangle goes unmeasured however small: these count only
///   for the maximum, and a point's search stops as soon as a reference triangle is found within
///   the largest distance measured so far (it cannot raise it). The maximum is exact over both
///   sets whatever that bound was, so it does not depend on batching or thread count; on a dense
///   tree most coverage points end at their first triangle (a 124k-triangle LoD1: 4.0 s → 0.4 s).
///
/// Positions come from hashes of `seed` and the sample's or triangle's number, so the result does
/// not depend on evaluation order. Where a primitive's material is alpha-masked with a texture,
/// points on texels below the cutoff are skipped: they are not drawn.
pub fn hausdorff(
    candidate: &Mesh,
    materials: &[Material],
    textures: &[Image],
    reference: &TriangleBvh,
    samples: usize,
    seed: u64,
) -> HausdorffError {
    let mut triangles: Vec<(SampledTriangle, f64)> = Vec::new();
    for p in &candidate.primitives {
        let mask = p.material.and_then(|m| materials.get(m)).and_then(|m| match (m.alpha_mode, m.base_color_texture) {
            (AlphaMode::Mask { cutoff }, Some(t)) if !p.uvs.is_empty() => {
                textures.get(t).map(|img| (img, cutoff, m.base_color[3]))
            }
            _ => None,
        });
        for t in 0..p.triangle_count() {
            let c = p.triangle_cross(t);
            let area = 0.5 * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
            let ids = [0, 1, 2].map(|k| p.indices[3 * t + k] as usize);
            let (Some(corner), true) = (
                ids.map(|i| p.positions.get(i).map(|v| DVec3::from(v.map(f64::from))))
                    .into_iter()
                    .collect::<Option<Vec<_>>>(),
                area.is_finite(),
            ) else {
                // the numbering stays that of the mesh: a skipped triangle keeps its number's hash unused
                triangles.push((SampledTriangle { corner: [DVec3::NAN; 3], mask: None }, f64::NAN));
                continue;
            };
            let mask = mask.and_then(|(img, cutoff, alpha)| {
                let uv = ids.map(|i| p.uvs.get(i).copied());
                (uv.iter().all(Option::is_some)).then(|| (uv.map(|u| u.unwrap_or_default()), img, cutoff, alpha))
            });
            triangles.push((SampledTriangle { corner: [corner[0], corner[1], corner[2]], mask }, area));
        }
    }
    let total: f64 = triangles.iter().map(|t| t.1).filter(|a| a.is_finite()).sum();
    let mut out = HausdorffError::default();
    let mut sum = 0.0;

    // the area-weighted points, measured exactly
    let mut exact = Batches::new(reference, samples + 64);
    if total > 0.0 && samples > 0 {
        let step = total / samples as f64;
        let target = |k: usize| (k as f64 + unit(mix64(seed ^ AREA_SALT ^ mix64(k as u64)))) * step;
        let (mut k, mut cumulative) = (0usize, 0.0);
        for (tri, area) in &triangles {
            if !area.is_finite() {
                continue;
            }
            let end = cumulative + area;
            while k < samples && target(k) < end {
                if let Some(q) = tri.point(mix64(seed ^ AREA_SALT ^ mix64(k as u64).rotate_left(17))) {
                    exact.push(q, 0.0, |d| tally(&mut out, &mut sum, d, true));
                }
                k += 1;
            }
            cumulative = end;
        }
    }
    exact.finish(0.0, |d| tally(&mut out, &mut sum, d, true));

    // one point on every triangle: for the maximum only, unless nothing was measured exactly (a
    // surface of no area, or all of it cut away), when they are the samples
    let only_max = out.samples > 0;
    let mut coverage = Batches::new(reference, triangles.len());
    for (serial, (tri, area)) in triangles.iter().enumerate() {
        if !area.is_finite() {
            continue;
        }
        let h = mix64(seed ^ mix64((serial as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15)));
        if let Some(q) = tri.point(h) {
            let floor = if only_max { out.max_m } else { 0.0 };
            coverage.push(q, floor, |d| tally(&mut out, &mut sum, d, !only_max));
        }
    }
    let floor = if only_max { out.max_m } else { 0.0 };
    coverage.finish(floor, |d| tally(&mut out, &mut sum, d, !only_max));
    out.mean_m = if out.samples > 0 { sum / out.samples as f64 } else { 0.0 };
    out
}

/// Counts a measured distance: toward the maximum always, toward the mean (`sum`, `samples`) when
/// it was measured exactly, else as a coverage sample.
fn tally(out: &mut HausdorffError, sum: &mut f64, d: f64, exact: bool) {
    out.max_m = out.max_m.max(d);
    if exact {
        *sum += d;
        out.samples += 1;
    } else {
        out.coverage_samples += 1;
    }
}

/// Points gathered in order, measured in parallel batches and handed on in that order (the
/// figures do not depend on the thread count).
struct Batches<'a> {
    reference: &'a TriangleBvh,
    points: Vec<DVec3>,
}

impl<'a> Batches<'a> {
    fn new(reference: &'a TriangleBvh, expected: usize) -> Self {
        Batches { reference, points: Vec::with_capacity(BATCH_POINTS.min(expected)) }
    }

    /// Adds `q`; a full batch is measured with distances up to `floor` not needing to be exact
    /// (each point's distance, or a value no larger than `floor`, goes to `found`).
    fn push(&mut self, q: DVec3, floor: f64, found: impl FnMut(f64)) {
        self.points.push(q);
        if self.points.len() == BATCH_POINTS {
            self.finish(floor, found);
        }
    }

    fn finish(&mut self, floor: f64, mut found: impl FnMut(f64)) {
        let reference = self.reference;
        // consecutive points lie on the same or neighbouring triangles: each starts from the
        // previous one's nearest reference triangle (the distances do not depend on it)
        let distances: Vec<f64> = self
            .points
            .par_chunks(HINT_RUN)
            .flat_map_iter(|run| {
                run.iter().scan(None, move |hint, q| {
                    let (d, t) = reference.nearest_above(*q, *hint, floor);
                    *hint = t;
                    Some(d)
                })
            })
            .collect();
        for d in distances.into_iter().filter(|d| d.is_finite()) {
            found(d);
        }
        self.points.clear();
    }
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

    #[test]
    fn a_tiny_triangle_far_off_sets_the_maximum_but_not_the_mean() {
        // the reference plane, and a candidate of the same plane plus a sliver 1 m above it: too
        // small for any of the area-weighted points, so only its coverage point finds it
        let grid = TriangleBvh::new(&quad(0.0)).unwrap();
        let mut candidate = quad(0.0);
        let p = &mut candidate.primitives[0];
        p.positions.extend([[0.5, 1.0, 0.5], [0.501, 1.0, 0.5], [0.5, 1.0, 0.501]]);
        p.indices.extend([4, 5, 6]);
        let e = hausdorff(&candidate, &[], &[], &grid, 1000, 7);
        assert!((e.max_m - 1.0).abs() < 1e-9, "{e:?}");
        assert!(e.mean_m < 1e-6 && e.samples >= 990 && e.coverage_samples == 3, "{e:?}");
        // the same points measured exactly give the same maximum: the coverage search's early stop
        // never lowers it
        let exact = hausdorff(&candidate, &[], &[], &grid, 0, 7);
        assert_eq!(exact.max_m.to_bits(), e.max_m.to_bits());
        assert_eq!((exact.samples, exact.coverage_samples), (3, 0));
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
                // with a floor: exact above it, at most the floor below it
                for floor in [brute * 0.5, brute, brute * 2.0] {
                    let (d, _) = bvh.nearest_above(p, Some(hint), floor);
                    if brute > floor {
                        proptest::prop_assert_eq!(d.to_bits(), brute.to_bits());
                    } else {
                        proptest::prop_assert!(d <= floor && d >= brute, "{} {} {}", d, floor, brute);
                    }
                }
            }
        }
    }
}
