//! Height on the exported terrain mesh: point location in a uniform grid of buckets over x/z (each
//! bucket lists the triangles whose reach, their bounding box widened by a hair, overlaps it), then
//! exact barycentric interpolation in the containing triangle (the grass thesis, formula 3.2), all
//! in f64.
//!
//! Which triangle a point is given depends on the triangles and their order only, never on the
//! bucket grid: the candidates are exactly the triangles whose reach holds the point (every one of
//! them is in its bucket, whatever the grid), taken in the mesh's order. So an index over the
//! triangles near some rows of a map (in the whole mesh's order) answers every point of those rows
//! as the whole map's index does, bit for bit: what places a shard's rows of instances alone.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::math::{cross3, sub3};

/// One upward-facing triangle: corners as the mesh stores them (f32, widened to f64 exactly where
/// they are used: 36 bytes instead of 72, and a world's 1.6 M triangles hold 100 MB, not 150).
#[derive(Debug, Clone, Copy)]
struct Tri {
    p: [[f32; 3]; 3],
    /// Unit normal (computed once, as `height_at` did per query).
    n: [f64; 3],
}

/// Point location over the upward-facing triangles of a terrain mesh.
#[derive(Debug, Clone)]
pub struct SurfaceIndex {
    tris: Vec<Tri>,
    /// Bucket grid origin, cell size and dimensions.
    origin: [f64; 2],
    cell: f64,
    inv_cell: f64,
    dims: [usize; 2],
    /// CSR: triangles of bucket b are `items[start[b]..start[b + 1]]`.
    start: Vec<u32>,
    items: Vec<u32>,
    bounds: [f64; 4],
    /// Union of the triangles' reaches: no point outside has a candidate.
    reach: [f64; 4],
    /// For an index of some rows' triangles ([`Self::covering`]): the z range it answers as the
    /// whole map's index does, and whether a query fell outside it.
    cover: Option<([f64; 2], Arc<AtomicBool>)>,
}

/// Relative tolerance of the inside test: a point this far outside a triangle (as a fraction of
/// its doubled area) still counts, so points on shared edges never fall between two triangles.
const EDGE_TOLERANCE: f64 = 1e-12;

/// Relative margin inside a hinted triangle (see [`SurfaceIndex::height_at_near`]).
const HINT_MARGIN: f64 = 1e-9;

/// How far a triangle's reach extends its bounding box, relative to the box's size plus its
/// largest coordinate: far beyond [`EDGE_TOLERANCE`] (a point that close to a triangle's edge lies
/// within 10⁻¹² of its size of the box) and f64 rounding at such coordinates (10⁻¹⁶).
const REACH: f64 = 1e-9;

impl SurfaceIndex {
    /// Index over one primitive's triangles (world-space positions, triangle list). Triangles whose
    /// normal does not point up (skirts, the base) or that are degenerate or reference missing
    /// vertices are skipped.
    pub fn new(positions: &[[f32; 3]], indices: &[u32]) -> SurfaceIndex {
        SurfaceIndex::from_parts(&[(positions, indices)])
    }

    /// Index over several primitives (e.g. the chunks of a chunked terrain, all in world space).
    pub fn from_parts(parts: &[(&[[f32; 3]], &[u32])]) -> SurfaceIndex {
        use rayon::prelude::*;
        // reserved once (the skirts and base skipped below are few): grown by doubling, the array
        // and its copies took a third more at a world's size
        let mut tris = Vec::with_capacity(parts.iter().map(|(_, i)| i.len() / 3).sum());
        for (positions, indices) in parts {
            // triangles in parallel, kept in the mesh's order
            let part: Vec<Tri> = indices
                .par_chunks_exact(3)
                .filter_map(|t| {
                    let get = |k: usize| positions.get(t[k] as usize).copied();
                    let (fa, fb, fc) = (get(0)?, get(1)?, get(2)?);
                    let (a, b, c) = (widen(fa), widen(fb), widen(fc));
                    if !(a.iter().chain(&b).chain(&c)).all(|v| v.is_finite()) {
                        return None;
                    }
                    let n = cross3(sub3(b, a), sub3(c, a));
                    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                    // upward-facing only: skirts are vertical (n.y = 0 exactly), the base faces down
                    if n[1] <= 1e-12 * len {
                        return None;
                    }
                    Some(Tri { p: [fa, fb, fc], n: [n[0] / len, n[1] / len, n[2] / len] })
                })
                .collect();
            tris.extend(part);
        }
        SurfaceIndex::build(tris, 1.0)
    }

    /// [`Self::from_parts`] with buckets `scale` times the usual size: the same answers (tests).
    #[cfg(test)]
    fn from_parts_scaled(parts: &[(&[[f32; 3]], &[u32])], scale: f64) -> SurfaceIndex {
        let s = SurfaceIndex::from_parts(parts);
        SurfaceIndex::build(s.tris, scale)
    }

    fn build(tris: Vec<Tri>, scale: f64) -> SurfaceIndex {
        use rayon::prelude::*;
        // the corners' x/z box and the reaches' union, in parallel (min and max: the same at any
        // split)
        let unite = |a: [f64; 4], b: [f64; 4]| [a[0].min(b[0]), a[1].min(b[1]), a[2].max(b[2]), a[3].max(b[3])];
        let none = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        let (bounds, reach) = tris
            .par_iter()
            .map(|t| (t.xz_box(), t.reach()))
            .reduce(|| (none, none), |p, q| (unite(p.0, q.0), unite(p.1, q.1)));
        // (a zero taken as +0, whichever sign the split met first)
        let (bounds, reach) = (bounds.map(|v| v + 0.0), reach.map(|v| v + 0.0));
        if tris.is_empty() {
            return SurfaceIndex {
                tris,
                origin: [0.0; 2],
                cell: 1.0,
                inv_cell: 1.0,
                dims: [0, 0],
                start: vec![0],
                items: Vec::new(),
                bounds: [0.0; 4],
                reach: [0.0; 4],
                cover: None,
            };
        }
        // about one triangle per bucket on average: a query then tests a handful of triangles
        let (w, h) = ((bounds[2] - bounds[0]).max(1e-9), (bounds[3] - bounds[1]).max(1e-9));
        let mut cell = (w * h / tris.len() as f64).sqrt() * 1.5 * scale;
        if cell <= 0.0 || !cell.is_finite() {
            cell = w.max(h);
        }
        // cap the bucket count (long thin meshes) at ~4 per triangle + 1024
        let cap = (4 * tris.len() + 1024) as f64;
        while (w / cell).ceil() * (h / cell).ceil() > cap {
            cell *= 1.5;
        }
        let dims = [((w / cell).ceil() as usize).max(1), ((h / cell).ceil() as usize).max(1)];
        let origin = [bounds[0], bounds[1]];
        let inv_cell = 1.0 / cell;
        // a triangle is in every bucket its reach overlaps: `locate` maps a point to its bucket by
        // the same monotonic formula, so a point in a reach is in one of the triangle's buckets
        let cell_range = |t: &Tri| {
            let [x0, z0, x1, z1] = t.reach();
            let c = |v: f64, o: f64, n: usize| bucket_of(v, o, inv_cell, n);
            (c(x0, origin[0], dims[0]), c(z0, origin[1], dims[1]), c(x1, origin[0], dims[0]), c(z1, origin[1], dims[1]))
        };
        // each triangle's buckets, once
        // (as u32: a bucket grid is at most ~4 per triangle + 1024, and triangles are u32-indexed)
        let ranges: Vec<[u32; 4]> = tris
            .par_iter()
            .map(|t| {
                let (i0, j0, i1, j1) = cell_range(t);
                [i0, j0, i1, j1].map(|v| v as u32)
            })
            .collect();
        // fill bucket counts
        let mut start = vec![0u32; dims[0] * dims[1] + 1];
        for &[i0, j0, i1, j1] in &ranges {
            let (i0, j0, i1, j1) = (i0 as usize, j0 as usize, i1 as usize, j1 as usize);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    start[j * dims[0] + i + 1] += 1;
                }
            }
        }
        // fill offset table
        for k in 1..start.len() {
            start[k] += start[k - 1];
        }
        let mut fill = start.clone();
        let mut items = vec![0u32; *start.last().unwrap_or(&0) as usize];
        for (ti, &[i0, j0, i1, j1]) in ranges.iter().enumerate() {
            let (i0, j0, i1, j1) = (i0 as usize, j0 as usize, i1 as usize, j1 as usize);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let b = j * dims[0] + i;
                    items[fill[b] as usize] = ti as u32;
                    fill[b] += 1;
                }
            }
        }
        SurfaceIndex { tris, origin, cell, inv_cell, dims, start, items, bounds, reach, cover: None }
    }

    /// [`Self::from_parts`] of the triangles near the rows of z in `z` (every triangle within a
    /// sample spacing of them, in the whole mesh's order), which it answers as the whole mesh's
    /// index does; a query outside is answered from the triangles it has and marked
    /// ([`Self::strayed`]), so a caller can refuse what it placed then.
    pub fn covering(parts: &[(&[[f32; 3]], &[u32])], z: [f64; 2]) -> SurfaceIndex {
        let mut s = SurfaceIndex::from_parts(parts);
        s.cover = Some((z, Arc::new(AtomicBool::new(false))));
        s
    }

    /// Whether a query fell outside the z range of an index of some rows ([`Self::covering`]).
    pub fn strayed(&self) -> bool {
        self.cover.as_ref().is_some_and(|(_, flag)| flag.load(Ordering::Relaxed))
    }

    /// Number of indexed (upward-facing) triangles.
    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// [min_x, min_z, max_x, max_z] of the indexed triangles (zeros when empty).
    pub fn bounds(&self) -> [f64; 4] {
        self.bounds
    }

    /// Corners (x, y, z) of indexed triangle `k` (0 ≤ k < [`Self::triangle_count`]): for checks
    /// that locate points their own way (the analyzer).
    pub fn triangle(&self, k: usize) -> [[f64; 3]; 3] {
        self.tris[k].corners()
    }

    /// Side of a bucket in metres.
    pub fn bucket_size(&self) -> f64 {
        self.cell
    }

    /// Height of the mesh at (x, z) and the unit normal of the containing triangle, by barycentric
    /// interpolation in f64; `None` outside the mesh (or over a hole).
    #[inline]
    pub fn height_at(&self, x: f64, z: f64) -> Option<(f64, [f64; 3])> {
        // no triangle has index u32::MAX: the lookup starts from the bucket
        let mut no_hint = u32::MAX;
        self.height_at_near(x, z, &mut no_hint)
    }

    /// [`Self::height_at`] for a run of nearby queries (a row of jittered cells, a tile's Poisson
    /// points): `hint` holds the triangle the last query found (any value to start, e.g.
    /// `u32::MAX`) and is tried first; it is taken only when (x, z) lies inside it by a margin
    /// (10⁻⁹ of its doubled area) far above rounding, where no other triangle of the mesh can
    /// contain the point, so the answer is the one `height_at` gives.
    #[inline]
    pub fn height_at_near(&self, x: f64, z: f64, hint: &mut u32) -> Option<(f64, [f64; 3])> {
        if let Some(([z0, z1], flag)) = &self.cover {
            if !(z >= *z0 && z <= *z1) {
                flag.store(true, Ordering::Relaxed);
            }
        }
        if let Some(tri) = self.tris.get(*hint as usize) {
            let w = bary(tri, x, z);
            if w.0.min(w.1).min(w.2) > HINT_MARGIN * w.3 {
                return Some((interpolate(tri, w), tri.n));
            }
        }
        let t = self.locate(x, z)?;
        *hint = t as u32;
        let tri = &self.tris[t];
        Some((interpolate(tri, bary(tri, x, z)), tri.n))
    }

    /// The triangle [`Self::height_at`] answers each texel centre of a `w` × `h` grid over `extent`
    /// with ([`texel_centre`]), found by rasterizing the triangles rather than by a lookup per texel:
    /// a texel takes the first triangle in the mesh's order that contains its centre exactly (which
    /// `locate` returns: such a triangle's reach holds the point, so it is among the candidates,
    /// and they are tried in order), and a texel no triangle contains exactly is located as one
    /// query (a point on an edge within rounding, or off the mesh). The same answers, bit for bit.
    pub fn locate_texels(&self, extent: [f64; 4], w: u32, h: u32) -> TexelTriangles {
        self.locate_texel_rows(extent, w, h, 0..h as usize)
    }

    /// [`Self::locate_texels`] of texel rows `rows` of the grid alone (`first` their first row):
    /// the same answers in those rows. An index of some of a terrain's triangles (a band's chunks)
    /// answers the rows only its own triangles cover as the whole terrain's index does.
    pub fn locate_texel_rows(&self, extent: [f64; 4], w: u32, h: u32, rows: std::ops::Range<usize>) -> TexelTriangles {
        use rayon::prelude::*;
        const ROWS: usize = 64;
        let (wu, hu) = (w as usize, h as usize);
        let rows = rows.start.min(hu)..rows.end.min(hu);
        let (first, count) = (rows.start, rows.len());
        let mut tri = vec![u32::MAX; wu * count];
        let [x0, z0, x1, z1] = extent;
        let spans = [x1 - x0, z1 - z0];
        if wu > 0 && count > 0 && spans.iter().all(|s| s.is_finite() && *s > 0.0) {
            // texel index range whose centres may lie in [lo, hi]: widened by 10⁻⁶ of a texel,
            // far beyond the rounding of a centre or of this formula (10⁻¹⁵ of the extent)
            let range = |lo: f64, hi: f64, o: f64, span: f64, n: usize| -> Option<(usize, usize)> {
                let a = ((lo - o) / span * n as f64 - 0.5 - 1e-6).ceil();
                let b = ((hi - o) / span * n as f64 - 0.5 + 1e-6).floor();
                if !(b >= 0.0 && a <= (n - 1) as f64 && a <= b) {
                    return None;
                }
                Some((a.max(0.0) as usize, b.min((n - 1) as f64) as usize))
            };
            // each block of ROWS texel rows (of those located) gets the triangles that may reach
            // it, in order
            let blocks = count.div_ceil(ROWS);
            let mut lists: Vec<Vec<u32>> = vec![Vec::new(); blocks];
            // (u32: texel indices of a grid of u32 sides; 20 bytes a triangle)
            let spans_of: Vec<Option<[u32; 4]>> = self
                .tris
                .par_iter()
                .map(|t| {
                    let [xa, za, xb, zb] = t.xz_box();
                    let (i0, i1) = range(xa, xb, x0, spans[0], wu)?;
                    let (j0, j1) = range(za, zb, z0, spans[1], hu)?;
                    Some([i0, i1, j0, j1].map(|v| v as u32))
                })
                .collect();
            for (k, s) in spans_of.iter().enumerate() {
                if let Some([_, _, j0, j1]) = s.map(|s| s.map(|v| v as usize)) {
                    if j1 < first || j0 >= first + count {
                        continue;
                    }
                    let (j0, j1) = (j0.max(first) - first, j1.min(first + count - 1) - first);
                    for list in &mut lists[j0 / ROWS..=j1 / ROWS] {
                        list.push(k as u32);
                    }
                }
            }
            tri.par_chunks_mut((ROWS * wu).max(1)).zip(lists.par_iter()).enumerate().for_each(|(b, (rows, list))| {
                let first = first + b * ROWS;
                let count = rows.len() / wu;
                for &k in list {
                    let Some([i0, i1, j0, j1]) = spans_of[k as usize].map(|s| s.map(|v| v as usize)) else { continue };
                    let t = &self.tris[k as usize];
                    for j in j0.max(first)..=j1.min(first + count - 1) {
                        let z = texel_centre(z0, z1, j as u32, h);
                        let row = &mut rows[(j - first) * wu..(j - first + 1) * wu];
                        for (i, slot) in row.iter_mut().enumerate().take(i1 + 1).skip(i0) {
                            if *slot != u32::MAX {
                                continue;
                            }
                            let (w0, w1, w2, _) = bary(t, texel_centre(x0, x1, i as u32, w), z);
                            if w0.min(w1).min(w2) >= 0.0 {
                                *slot = k;
                            }
                        }
                    }
                }
            });
        }
        // what no triangle holds exactly: one query each (few: centres on edges, off the mesh)
        tri.par_chunks_mut(wu.max(1)).enumerate().for_each(|(j, row)| {
            let z = texel_centre(z0, z1, (first + j) as u32, h);
            for (i, slot) in row.iter_mut().enumerate() {
                if *slot == u32::MAX {
                    *slot = self.locate(texel_centre(x0, x1, i as u32, w), z).map_or(u32::MAX, |t| t as u32);
                }
            }
        });
        TexelTriangles { extent, size: [w, h], first, tri }
    }

    /// Height and unit normal at (x, z) on the triangle `texels` gave its texel, as
    /// [`Self::height_at`] answers it there (`None` off the mesh).
    #[inline]
    pub fn height_on(&self, tri: u32, x: f64, z: f64) -> Option<(f64, [f64; 3])> {
        let t = self.tris.get(tri as usize)?;
        Some((interpolate(t, bary(t, x, z)), t.n))
    }

    /// Index of a triangle containing (x, z): of the triangles whose reach holds it, in order, the
    /// first that contains it exactly, else the best within [`EDGE_TOLERANCE`] (a point on an
    /// edge, up to rounding). The bucket only narrows the search (module docs): every triangle
    /// whose reach holds the point is in it.
    #[inline]
    fn locate(&self, x: f64, z: f64) -> Option<usize> {
        if self.tris.is_empty() {
            return None;
        }
        let r = &self.reach;
        // (false for NaN)
        if !(x >= r[0] && z >= r[1] && x <= r[2] && z <= r[3]) {
            return None;
        }
        let i = bucket_of(x, self.origin[0], self.inv_cell, self.dims[0]);
        let j = bucket_of(z, self.origin[1], self.inv_cell, self.dims[1]);
        let b = j * self.dims[0] + i;
        let (s, e) = (self.start[b] as usize, self.start[b + 1] as usize);
        let mut best = None;
        let mut best_score = -EDGE_TOLERANCE;
        for &t in &self.items[s..e] {
            let tri = &self.tris[t as usize];
            let (w0, w1, w2, d) = bary(tri, x, z);
            // all weights share the sign of d when inside; normalised (d > 0) inside means ≥ 0
            let least = w0.min(w1).min(w2);
            if least >= 0.0 {
                return Some(t as usize);
            }
            // the relative distance (a division) only for the few within the tolerance, and only
            // of a triangle whose reach holds the point (one that contains it exactly does: its
            // weights round by 10⁻¹⁶ of its size, far inside the reach)
            if least >= -EDGE_TOLERANCE * d && tri.reaches(x, z) {
                let m = least / d;
                if m >= best_score {
                    best_score = m;
                    best = Some(t as usize);
                }
            }
        }
        best
    }
}

/// Centre of texel `i` of `n` across [lo, hi]: lo + (i + ½)/n · (hi − lo), the one formula
/// every map over a terrain's extent samples at.
#[inline]
pub fn texel_centre(lo: f64, hi: f64, i: u32, n: u32) -> f64 {
    lo + (i as f64 + 0.5) / n as f64 * (hi - lo)
}

/// Which triangle of a [`SurfaceIndex`] holds each texel centre of a grid
/// ([`SurfaceIndex::locate_texels`]): row-major, row 0 at the extent's minimum z, `u32::MAX` off
/// the mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct TexelTriangles {
    pub extent: [f64; 4],
    pub size: [u32; 2],
    /// The first texel row located (0 for the whole grid); `tri` holds rows `first ..`.
    pub first: usize,
    pub tri: Vec<u32>,
}

/// A stored corner in f64 (exact: every f32 is an f64).
#[inline]
fn widen(v: [f32; 3]) -> [f64; 3] {
    [v[0] as f64, v[1] as f64, v[2] as f64]
}

/// Bucket of coordinate `v` on an axis from `origin` in buckets of `1 / inv_cell` (n of them):
/// monotonic in `v`, clamped to the grid.
#[inline]
fn bucket_of(v: f64, origin: f64, inv_cell: f64, n: usize) -> usize {
    (((v - origin) * inv_cell).floor().max(0.0) as usize).min(n - 1)
}

impl Tri {
    #[inline]
    fn corners(&self) -> [[f64; 3]; 3] {
        self.p.map(widen)
    }

    /// The triangle's x/z bounding box [x0, z0, x1, z1].
    #[inline]
    fn xz_box(&self) -> [f64; 4] {
        let [a, b, c] = self.corners();
        [a[0].min(b[0]).min(c[0]), a[2].min(b[2]).min(c[2]), a[0].max(b[0]).max(c[0]), a[2].max(b[2]).max(c[2])]
    }

    /// The triangle's reach: its x/z bounding box [x0, z0, x1, z1] widened by [`REACH`] of its
    /// size plus its largest coordinate (a function of the corners alone).
    #[inline]
    fn reach(&self) -> [f64; 4] {
        let [x0, z0, x1, z1] = self.xz_box();
        let m = REACH * ((x1 - x0) + (z1 - z0) + x0.abs().max(x1.abs()).max(z0.abs()).max(z1.abs()));
        [x0 - m, z0 - m, x1 + m, z1 + m]
    }

    #[inline]
    fn reaches(&self, x: f64, z: f64) -> bool {
        let [x0, z0, x1, z1] = self.reach();
        x >= x0 && z >= z0 && x <= x1 && z <= z1
    }
}

/// Height at the point whose unnormalised weights [`bary`] gave.
#[inline]
fn interpolate(t: &Tri, (w0, w1, w2, d): (f64, f64, f64, f64)) -> f64 {
    let [a, b, c] = t.corners();
    (w0 * a[1] + w1 * b[1] + w2 * c[1]) / d
}

/// Unnormalised barycentric weights of (x, z) and their sum d (twice the signed area in x/z).
#[inline]
fn bary(t: &Tri, x: f64, z: f64) -> (f64, f64, f64, f64) {
    let [a, b, c] = t.corners();
    let orient = |p: [f64; 3], q: [f64; 3], rx: f64, rz: f64| (q[0] - p[0]) * (rz - p[2]) - (q[2] - p[2]) * (rx - p[0]);
    let w0 = orient(b, c, x, z);
    let w1 = orient(c, a, x, z);
    let w2 = orient(a, b, x, z);
    let d = w0 + w1 + w2;
    // d can be flipped in sign for either winding; divide by d and the sign cancels
    let d = if d == 0.0 { f64::MIN_POSITIVE } else { d };
    if d < 0.0 {
        (-w0, -w1, -w2, -d)
    } else {
        (w0, w1, w2, d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2×2 quad at heights 0, 1, 2, 3 split along its diagonal, counter-clockwise from +Y.
    fn quad() -> SurfaceIndex {
        let p = [[0.0, 0.0, 0.0], [2.0, 1.0, 0.0], [2.0, 3.0, 2.0], [0.0, 2.0, 2.0]];
        // (b − a) × (c − a) must have +y: with x right and z "down" that is [0, 2, 1], [0, 3, 2]
        SurfaceIndex::new(&p, &[0, 2, 1, 0, 3, 2])
    }

    #[test]
    fn interpolates_exactly_and_resolves_edges() {
        let s = quad();
        assert_eq!(s.triangle_count(), 2);
        // corners
        assert_eq!(s.height_at(0.0, 0.0).unwrap().0, 0.0);
        assert_eq!(s.height_at(2.0, 2.0).unwrap().0, 3.0);
        // the shared diagonal: both triangles give the same height
        let (y, _) = s.height_at(1.0, 1.0).unwrap();
        assert!((y - 1.5).abs() < 1e-12);
        // inside the triangle (0, 1, 2): plane y = x/2 + z
        let (y, n) = s.height_at(1.5, 0.5).unwrap();
        assert!((y - 1.25).abs() < 1e-12, "{y}");
        assert!(n[1] > 0.0 && ((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) - 1.0).abs() < 1e-12);
        assert!(s.height_at(-0.1, 0.5).is_none());
        assert!(s.height_at(f64::NAN, 0.5).is_none());
    }

    /// The hinted lookup gives `height_at`'s answer bit for bit, from any hint, on a mesh of many
    /// small triangles (points on edges and vertices included).
    #[test]
    fn hinted_lookup_matches_the_plain_one() {
        let n = 24usize;
        let mut p = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let (x, z) = (i as f32 * 1.5, j as f32 * 1.5);
                p.push([x, (x * 0.37).sin() * 3.0 + z * 0.2, z]);
            }
        }
        let mut idx = Vec::new();
        for j in 0..n as u32 {
            for i in 0..n as u32 {
                let (a, b, c, d) = (
                    j * (n as u32 + 1) + i,
                    j * (n as u32 + 1) + i + 1,
                    (j + 1) * (n as u32 + 1) + i,
                    (j + 1) * (n as u32 + 1) + i + 1,
                );
                idx.extend([a, c, b, b, c, d]);
            }
        }
        let s = SurfaceIndex::new(&p, &idx);
        let mut hint = u32::MAX;
        let mut h: u64 = 3;
        for k in 0..20_000 {
            h = crate::random::mix64(h);
            // a walk of small steps, every 7th query on the lattice (vertices and edges)
            let (x, z) = if k % 7 == 0 {
                ((h % 25) as f64 * 1.5, ((h >> 8) % 25) as f64 * 0.75)
            } else {
                ((h >> 11) as f64 / (1u64 << 53) as f64 * 37.0 - 0.5, (h & 0xFFFF) as f64 / 65536.0 * 36.0)
            };
            assert_eq!(
                s.height_at_near(x, z, &mut hint).map(|(y, n)| (y.to_bits(), n.map(f64::to_bits))),
                s.height_at(x, z).map(|(y, n)| (y.to_bits(), n.map(f64::to_bits))),
                "({x}, {z})"
            );
        }
    }

    use proptest::prelude::*;

    type Answer = Option<(u64, [u64; 3])>;

    fn answer(s: &SurfaceIndex, x: f64, z: f64) -> Answer {
        s.height_at(x, z).map(|(y, n)| (y.to_bits(), n.map(f64::to_bits)))
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        /// A point's triangle depends on the mesh and its order alone: indexes of a TIN with
        /// buckets of any size, and an index of only the triangles near some rows (in the mesh's
        /// order), answer every point (of those rows) bit for bit alike: random points, points on
        /// vertices, on edges (shared ones are ties) and just outside the map.
        #[test]
        fn answers_do_not_depend_on_the_buckets_or_on_triangles_far_away(
            size in proptest::sample::select(vec![9usize, 17, 33, 65]),
            cell in proptest::sample::select(vec![0.5f64, 1.0, 2.0, 30.0, 0.3]),
            relief in 1.0f64..400.0,
            error in 0.0f64..0.2,
            seed in 0u64..1000,
            rows in (0usize..64, 1usize..64),
            scale in proptest::sample::select(vec![0.05f64, 0.3, 2.0, 9.0]),
        ) {
            let hf = crate::synth::fbm(size, cell, relief, seed);
            let opts = crate::terrain::tin::TinOptions { max_error_m: error * relief, ..Default::default() };
            let mesh = crate::terrain::tin::tin(&hf, &opts).unwrap().mesh;
            let positions: Vec<[f32; 3]> =
                mesh.vertices.iter().map(|v| hf.position(v[0] as usize, v[1] as usize)).collect();
            let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
            let whole = SurfaceIndex::from_parts(&[(&positions, &indices)]);
            let other = SurfaceIndex::from_parts_scaled(&[(&positions, &indices)], scale);
            prop_assert_ne!(whole.dims, other.dims);
            // the rows [r0, r1] and the triangles within a cell of them, in order
            let r0 = rows.0 % (size - 1);
            let r1 = (r0 + rows.1).min(size - 1);
            let (z0, z1) = ((r0 as f64 * cell) as f32 as f64, (r1 as f64 * cell) as f32 as f64);
            let near: Vec<u32> = mesh
                .triangles
                .iter()
                .filter(|t| {
                    let zs = t.map(|v| positions[v as usize][2] as f64);
                    zs.iter().any(|&z| z <= z1 + cell) && zs.iter().any(|&z| z >= z0 - cell)
                })
                .flatten()
                .copied()
                .collect();
            let part = SurfaceIndex::from_parts_scaled(&[(&positions, &near)], scale.recip());
            let extent = (size - 1) as f64 * cell;
            let mut h = seed ^ 0x5eed;
            let mut next = || {
                h = crate::random::mix64(h);
                (h >> 11) as f64 / (1u64 << 53) as f64
            };
            for k in 0..600 {
                let (x, z) = match k % 4 {
                    // anywhere, a little beyond the map too
                    0 => (next() * extent * 1.02 - 0.01 * extent, next() * extent * 1.02 - 0.01 * extent),
                    // a vertex
                    1 => {
                        let p = positions[(next() * positions.len() as f64) as usize];
                        (p[0] as f64, p[2] as f64)
                    }
                    // a point of an edge (a shared one is a tie)
                    _ => {
                        let t = mesh.triangles[(next() * mesh.triangles.len() as f64) as usize];
                        let e = (next() * 3.0) as usize;
                        let (a, b) = (positions[t[e] as usize], positions[t[(e + 1) % 3] as usize]);
                        let f = if k % 4 == 2 { 0.5 } else { next() };
                        (a[0] as f64 + f * (b[0] as f64 - a[0] as f64), a[2] as f64 + f * (b[2] as f64 - a[2] as f64))
                    }
                };
                let expected = answer(&whole, x, z);
                prop_assert_eq!(answer(&other, x, z), expected, "({}, {}) with buckets {} times", x, z, scale);
                if z >= z0 && z <= z1 {
                    prop_assert_eq!(answer(&part, x, z), expected, "({}, {}) by the rows' triangles", x, z);
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(40))]
        /// Rasterized texel location answers every texel centre as `height_at` does, bit for bit:
        /// grids whose centres fall on the lattice's vertices and edges (`size − 1` texels over the
        /// map, and multiples), random grids, grids reaching beyond the mesh, and overlapping
        /// triangles (copies of some ahead of the mesh and behind it: the first in order wins).
        #[test]
        fn located_texels_are_the_lookups_answers(
            size in proptest::sample::select(vec![9usize, 17, 33]),
            cell in proptest::sample::select(vec![0.5f64, 1.0, 3.0, 0.3]),
            relief in 1.0f64..300.0,
            error in 0.0f64..0.2,
            seed in 0u64..1000,
            grid in proptest::sample::select(vec![(0u32, 0u32), (1, 1), (2, 1), (1, 2), (3, 5), (17, 4), (1, 40)]),
            beyond in proptest::sample::select(vec![0.0f64, 0.0, 0.07, -0.2]),
            overlap in proptest::bool::ANY,
        ) {
            let hf = crate::synth::fbm(size, cell, relief, seed);
            let opts = crate::terrain::tin::TinOptions { max_error_m: error * relief, ..Default::default() };
            let mesh = crate::terrain::tin::tin(&hf, &opts).unwrap().mesh;
            let positions: Vec<[f32; 3]> =
                mesh.vertices.iter().map(|v| hf.position(v[0] as usize, v[1] as usize)).collect();
            let mut indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
            if overlap {
                // a few triangles again, ahead (they win) with their corners turned (the same
                // winding, other roundings) and behind (they never win)
                let some: Vec<u32> = mesh.triangles.iter().step_by(5).flatten().copied().collect();
                let mut turned = some.clone();
                turned.chunks_exact_mut(3).for_each(|t| t.rotate_left(1));
                indices = [turned, indices, some].concat();
            }
            let s = SurfaceIndex::from_parts(&[(&positions, &indices)]);
            let side = (size - 1) as f64 * cell;
            let m = beyond * side;
            let extent = [-m, -m * 0.5, side + m, side + m * 0.5];
            // grid (0, 0): one texel per cell, centres on the cells' diagonals' midpoints
            let (w, h) = match grid {
                (0, 0) => ((size - 1) as u32, (size - 1) as u32),
                (a, b) => (a * (size as u32 - 1) / 2 + 1, b * (size as u32 - 1) / 2 + 1),
            };
            let texels = s.locate_texels(extent, w, h);
            prop_assert_eq!(texels.tri.len(), (w * h) as usize);
            for j in 0..h {
                let z = texel_centre(extent[1], extent[3], j, h);
                for i in 0..w {
                    let x = texel_centre(extent[0], extent[2], i, w);
                    let t = texels.tri[(j * w + i) as usize];
                    prop_assert_eq!(
                        s.height_on(t, x, z).map(|(y, n)| (y.to_bits(), n.map(f64::to_bits))),
                        answer(&s, x, z),
                        "texel ({}, {}) of {}x{} at ({}, {})", i, j, w, h, x, z
                    );
                    prop_assert_eq!(Some(t).filter(|&t| t != u32::MAX).map(|t| t as usize), s.locate(x, z));
                }
            }
            // any run of rows located alone: those rows of the whole grid (runs across the
            // blocks of 64 rows the rasterizer works in, and past the grid's end: clamped)
            for (a, b) in [(0, h), (1, 2), (h / 3, h - h / 4), (h - 1, h + 5), (h, h)] {
                let (a, b) = (a.min(h) as usize, b as usize);
                let rows = s.locate_texel_rows(extent, w, h, a..b);
                let end = b.min(h as usize);
                prop_assert_eq!(rows.first, a);
                prop_assert_eq!(&rows.tri[..], &texels.tri[a * w as usize..end * w as usize]);
            }
        }
    }

    #[test]
    fn located_texels_of_an_empty_grid_or_extent() {
        let s = quad();
        assert!(s.locate_texels([0.0, 0.0, 2.0, 2.0], 0, 3).tri.is_empty());
        // a degenerate extent: every texel located one by one, on the line x = 1
        let t = s.locate_texels([1.0, 0.0, 1.0, 2.0], 2, 2);
        for (k, &tri) in t.tri.iter().enumerate() {
            let z = texel_centre(0.0, 2.0, k as u32 / 2, 2);
            assert_eq!(Some(tri as usize), s.locate(1.0, z));
        }
    }

    #[test]
    fn skips_downward_vertical_and_bad_triangles() {
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -5.0, 0.0]];
        // downward (clockwise from +Y), vertical (skirt-like), out-of-range index
        let s = SurfaceIndex::new(&p, &[0, 1, 2, 0, 1, 3, 0, 1, 9]);
        assert_eq!(s.triangle_count(), 0);
        assert!(s.height_at(0.2, 0.2).is_none());
        let up = SurfaceIndex::new(&p, &[0, 2, 1]);
        assert_eq!(up.triangle_count(), 1);
    }
}
