//! The fixed-point triangle scan both cameras share: vertices snapped to sub-pixels, edge functions in
//! `i64` with the top-left fill rule, and the orthographic path's setup and row rasteriser.

use rayon::prelude::*;

use super::camera::Projection;
use super::canvas::{Cull, DrawOptions, DrawStats, Fragment};
use super::limits::{MAX_VERTEX_SUBPIXELS, SUBPIXEL};
use crate::mesh::Primitive;

/// A vertex on the image: snapped position in sub-pixels and depth; `None` if unusable.
type ScreenVertex = Option<([i64; 2], f64)>;

/// A triangle ready to rasterise: its vertices ordered so the edge functions are ≥ 0 inside.
#[derive(Debug, Clone, Copy)]
pub(super) struct TriSetup {
    index: u32,
    /// Vertex indices (into the primitive) in edge-function order.
    v: [u32; 3],
    /// Sub-pixel bounding box, inclusive.
    pub(super) min: [i64; 2],
    pub(super) max: [i64; 2],
    /// The edge order swapped vertices 1 and 2 (the triangle was clockwise in sub-pixel math).
    swapped: bool,
}

impl TriSetup {
    fn pixel_rows(&self, height: u32) -> Option<(u32, u32)> {
        pixel_rows(self.min[1], self.max[1], height)
    }
}

/// Pixel rows [y0, y1) whose centres may lie in the sub-pixel span [min_y, max_y], clipped to
/// `height`; None if none.
#[inline]
pub(super) fn pixel_rows(min_y: i64, max_y: i64, height: u32) -> Option<(u32, u32)> {
    // Row y's centre is y·S + S/2; first row with centre ≥ min, last with centre ≤ max.
    let y0 = first_centre(min_y).max(0);
    let y1 = (last_centre(max_y) + 1).min(height as i64);
    (y0 < y1).then_some((y0 as u32, y1 as u32))
}

/// Smallest pixel index whose centre (k·S + S/2) is ≥ `v` (sub-pixels).
#[inline]
fn first_centre(v: i64) -> i64 {
    (v - SUBPIXEL / 2 + SUBPIXEL - 1).div_euclid(SUBPIXEL)
}

/// Largest pixel index whose centre is ≤ `v`.
#[inline]
fn last_centre(v: i64) -> i64 {
    (v - SUBPIXEL / 2).div_euclid(SUBPIXEL)
}

/// Every vertex projected once, and every triangle classified (drawn, culled, skipped).
pub(super) struct Setup {
    verts: Vec<ScreenVertex>,
    pub(super) tris: Vec<TriSetup>,
    pub(super) stats: DrawStats,
}

impl Setup {
    pub(super) fn new(proj: &Projection, prim: &Primitive, cull: Cull) -> Setup {
        let verts: Vec<ScreenVertex> = prim
            .positions
            .par_iter()
            .map(|p| {
                let s = proj.apply([p[0] as f64, p[1] as f64, p[2] as f64]);
                if !s.iter().all(|v| v.is_finite()) {
                    return None;
                }
                let snap = |v: f64| (v * SUBPIXEL as f64).round();
                let (x, y) = (snap(s[0]), snap(s[1]));
                let lim = MAX_VERTEX_SUBPIXELS as f64;
                if x.abs() > lim || y.abs() > lim {
                    return None;
                }
                Some(([x as i64, y as i64], s[2]))
            })
            .collect();
        let mut stats = DrawStats::default();
        let mut tris = Vec::with_capacity(prim.indices.len() / 3);
        for (t, idx) in prim.indices.chunks_exact(3).enumerate() {
            let get = |k: usize| verts.get(idx[k] as usize).copied().flatten();
            let (Some(a), Some(b), Some(c)) = (get(0), get(1), get(2)) else {
                stats.skipped += 1;
                continue;
            };
            let area = orient(a.0, b.0, c.0);
            // Pixel y runs down, so a positive sub-pixel area is clockwise on the image.
            let front = area < 0;
            let culled = area == 0
                || match cull {
                    Cull::None => false,
                    Cull::Back => !front,
                    Cull::Front => front,
                };
            if culled {
                stats.culled += 1;
                continue;
            }
            let swapped = area < 0;
            let v = if swapped { [idx[0], idx[2], idx[1]] } else { [idx[0], idx[1], idx[2]] };
            let ps = [a.0, b.0, c.0];
            let min = [ps.iter().map(|p| p[0]).min().unwrap_or(0), ps.iter().map(|p| p[1]).min().unwrap_or(0)];
            let max = [ps.iter().map(|p| p[0]).max().unwrap_or(0), ps.iter().map(|p| p[1]).max().unwrap_or(0)];
            stats.triangles += 1;
            tris.push(TriSetup { index: t as u32, v, min, max, swapped });
        }
        Setup { verts, tris, stats }
    }
}

/// Twice the signed area of (a, b, p), sub-pixel units: the edge function of edge a→b at p.
#[inline(always)]
pub(super) fn orient(a: [i64; 2], b: [i64; 2], p: [i64; 2]) -> i64 {
    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
}

/// Top-left rule for an edge a→b of a triangle whose inside has positive edge functions, with y
/// down: a top edge is horizontal with the inside below it (b to the right of a); a left edge has
/// the inside to its right (it runs up the image). Pixels exactly on other edges belong to the
/// neighbour, so on those edges the test is `> 0`, i.e. `≥ 1` for integers.
#[inline]
fn edge_bias(a: [i64; 2], b: [i64; 2]) -> i64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let top_left = (dy == 0 && dx > 0) || dy < 0;
    if top_left {
        0
    } else {
        -1
    }
}

/// The triangle's pixel columns [x0, x1) whose centres may be inside, clipped to `width`.
#[inline]
pub(super) fn pixel_columns(min_x: i64, max_x: i64, width: u32) -> Option<(i64, i64)> {
    let x0 = first_centre(min_x).max(0);
    let x1 = (last_centre(max_x) + 1).min(width as i64);
    (x0 < x1).then_some((x0, x1))
}

/// The scan shared by both cameras: calls `covered(x, y, e)` for every pixel of rows [ry0, ry1) and
/// columns [x0, x1) whose centre the triangle (a, b, c) owns under the top-left rule, in row-major
/// order. The vertices are ordered so the edge functions are ≥ 0 inside; `e` holds the edge
/// functions opposite a, b and c (edges b→c, c→a, a→b) at the pixel centre.
///
/// Each edge function is linear along a row, so a wide row is not tested pixel by pixel: the
/// columns where all three are inside are solved for in integers (the same pixels and values as
/// testing each one; a long thin branch seen at an angle has a wide box and a narrow span).
#[inline(always)]
pub(super) fn scan_triangle<C>(pts: [[i64; 2]; 3], x0: i64, x1: i64, ry0: u32, ry1: u32, mut covered: C)
where
    C: FnMut(u32, u32, [i64; 3]),
{
    let [a, b, c] = pts;
    let bias = [edge_bias(b, c), edge_bias(c, a), edge_bias(a, b)];
    let step_x = [-(c[1] - b[1]) * SUBPIXEL, -(a[1] - c[1]) * SUBPIXEL, -(b[1] - a[1]) * SUBPIXEL];
    let width = x1 - x0;
    for y in ry0..ry1 {
        let py = y as i64 * SUBPIXEL + SUBPIXEL / 2;
        let px = x0 * SUBPIXEL + SUBPIXEL / 2;
        let mut e = [orient(b, c, [px, py]), orient(c, a, [px, py]), orient(a, b, [px, py])];
        if width <= SPAN_MIN_WIDTH {
            for x in x0..x1 {
                if e[0] + bias[0] >= 0 && e[1] + bias[1] >= 0 && e[2] + bias[2] >= 0 {
                    covered(x as u32, y, e);
                }
                for d in 0..3 {
                    e[d] += step_x[d];
                }
            }
            continue;
        }
        let (mut lo, mut hi) = (0i64, width);
        for d in 0..3 {
            let (k0, k1) = inside_steps(e[d] + bias[d], step_x[d]);
            lo = lo.max(k0);
            hi = hi.min(k1);
        }
        if lo >= hi {
            continue;
        }
        for d in 0..3 {
            e[d] += lo * step_x[d];
        }
        for x in x0 + lo..x0 + hi {
            covered(x as u32, y, e);
            for d in 0..3 {
                e[d] += step_x[d];
            }
        }
    }
}

/// Rows at most this wide are tested pixel by pixel (three divisions cost more than a few tests).
const SPAN_MIN_WIDTH: i64 = 6;

/// The steps k ≥ 0 (as a range [k0, k1), k1 possibly unbounded) at which `start + k·step ≥ 0`.
#[inline(always)]
fn inside_steps(start: i64, step: i64) -> (i64, i64) {
    match step.signum() {
        0 if start >= 0 => (0, i64::MAX),
        0 => (0, 0),
        // increasing: from the first k with k·step ≥ −start
        1 if start >= 0 => (0, i64::MAX),
        1 => ((-start + step - 1) / step, i64::MAX),
        // decreasing: up to the last k with k·(−step) ≤ start
        _ if start < 0 => (0, 0),
        _ => (0, start / -step + 1),
    }
}

/// w₀·a + w₁·b + w₂·c per component, summed in that order (results depend on it). A plain loop
/// rather than `array::map`, which the compiler does not always inline in the pixel loop.
#[inline(always)]
pub(super) fn weigh<T, const N: usize>(w: [T; 3], a: &[T; N], b: &[T; N], c: &[T; N]) -> [T; N]
where
    T: Copy + Default + std::ops::Mul<Output = T> + std::ops::Add<Output = T>,
{
    let mut out = [T::default(); N];
    for d in 0..N {
        out[d] = w[0] * a[d] + w[1] * b[d] + w[2] * c[d];
    }
    out
}

/// The optional per-vertex attributes of a primitive: each counts only when there is one per
/// position (else it reads as its default).
#[derive(Clone, Copy)]
pub(super) struct Attributes<'a> {
    pub(super) normals: Option<&'a [[f32; 3]]>,
    pub(super) uvs: Option<&'a [[f32; 2]]>,
    pub(super) colors: Option<&'a [[f32; 4]]>,
}

impl<'a> Attributes<'a> {
    pub(super) fn of(prim: &'a Primitive) -> Self {
        let n = prim.positions.len();
        Attributes {
            normals: (prim.normals.len() == n).then_some(&prim.normals[..]),
            uvs: (prim.uvs.len() == n).then_some(&prim.uvs[..]),
            colors: (prim.colors.len() == n).then_some(&prim.colors[..]),
        }
    }
}

/// Rasterises the triangles `tris` (positions in `setup.tris`, in draw order) into the rows
/// [y0, y1) of the canvas; `color`/`depth` hold exactly those rows. Returns the fragments written.
#[allow(clippy::too_many_arguments)]
pub(super) fn raster_rows<F>(
    color: &mut [[f32; 4]],
    depth: &mut [f32],
    width: u32,
    y0: u32,
    y1: u32,
    setup: &Setup,
    prim: &Primitive,
    tris: &[u32],
    opts: &DrawOptions,
    shader: &mut F,
) -> u64
where
    F: FnMut(&Fragment) -> Option<[f32; 4]>,
{
    let Attributes { normals, uvs, colors } = Attributes::of(prim);
    let mut written = 0u64;
    for &t in tris {
        let Some(tri) = setup.tris.get(t as usize) else {
            continue;
        };
        let Some((ry0, ry1)) = tri.pixel_rows(y1) else {
            continue;
        };
        let (ry0, ry1) = (ry0.max(y0), ry1);
        if ry0 >= ry1 {
            continue;
        }
        let Some((x0, x1)) = pixel_columns(tri.min[0], tri.max[0], width) else {
            continue;
        };
        let sv = tri.v.map(|i| setup.verts[i as usize].unwrap_or(([0, 0], 0.0)));
        let pts = [sv[0].0, sv[1].0, sv[2].0];
        let inv_area = 1.0 / orient(pts[0], pts[1], pts[2]) as f64;
        let depths = [sv[0].1, sv[1].1, sv[2].1];
        let vi = tri.v.map(|i| i as usize);
        scan_triangle(pts, x0, x1, ry0, ry1, |x, y, e| {
            let l = [e[0] as f64 * inv_area, e[1] as f64 * inv_area, e[2] as f64 * inv_area];
            let z = (l[0] * depths[0] + l[1] * depths[1] + l[2] * depths[2]) as f32;
            let k = (y - y0) as usize * width as usize + x as usize;
            if !opts.depth_test || z < depth[k] {
                let lf = [l[0] as f32, l[1] as f32, l[2] as f32];
                let p = &prim.positions;
                let frag = Fragment {
                    x,
                    y,
                    depth: z,
                    position: weigh(lf, &p[vi[0]], &p[vi[1]], &p[vi[2]]),
                    normal: normals.map_or([0.0; 3], |nm| weigh(lf, &nm[vi[0]], &nm[vi[1]], &nm[vi[2]])),
                    uv: uvs.map_or([0.0; 2], |u| weigh(lf, &u[vi[0]], &u[vi[1]], &u[vi[2]])),
                    color: colors.map_or([1.0; 4], |cl| weigh(lf, &cl[vi[0]], &cl[vi[1]], &cl[vi[2]])),
                    // Report weights in the triangle's index order.
                    bary: if tri.swapped { [lf[0], lf[2], lf[1]] } else { lf },
                    triangle: tri.index,
                    front_facing: tri.swapped,
                };
                if let Some(rgba) = shader(&frag) {
                    color[k] = rgba;
                    if opts.depth_write {
                        depth[k] = z;
                    }
                    written += 1;
                }
            }
        });
    }
    written
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pixel of the box tested one by one: what [`scan_triangle`] must reproduce.
    fn scan_each_pixel(pts: [[i64; 2]; 3], x0: i64, x1: i64, ry0: u32, ry1: u32) -> Vec<(u32, u32, [i64; 3])> {
        let [a, b, c] = pts;
        let bias = [edge_bias(b, c), edge_bias(c, a), edge_bias(a, b)];
        let mut out = Vec::new();
        for y in ry0..ry1 {
            for x in x0..x1 {
                let p = [x * SUBPIXEL + SUBPIXEL / 2, y as i64 * SUBPIXEL + SUBPIXEL / 2];
                let e = [orient(b, c, p), orient(c, a, p), orient(a, b, p)];
                if (0..3).all(|d| e[d] + bias[d] >= 0) {
                    out.push((x as u32, y, e));
                }
            }
        }
        out
    }

    proptest::proptest! {
        /// Solving each row's span gives the same pixels, in the same order, with the same edge
        /// values as testing every pixel of the box: thin slivers, wide and narrow boxes, edges
        /// through pixel centres (coordinates on the pixel grid), horizontal and vertical edges.
        #[test]
        fn row_spans_are_the_pixels_tested_one_by_one(
            coords in proptest::collection::vec(-40i64 * SUBPIXEL..80 * SUBPIXEL, 6),
            on_grid in proptest::bool::ANY,
            width in 1u32..70,
            height in 1u32..50,
        ) {
            let snap = |v: i64| if on_grid { v / (SUBPIXEL / 2) * (SUBPIXEL / 2) } else { v };
            let mut pts = [[snap(coords[0]), snap(coords[1])], [snap(coords[2]), snap(coords[3])], [snap(coords[4]), snap(coords[5])]];
            let area = orient(pts[0], pts[1], pts[2]);
            proptest::prop_assume!(area != 0);
            if area < 0 {
                pts.swap(1, 2);
            }
            let min = [0, 1].map(|k| pts.iter().map(|p| p[k]).min().unwrap());
            let max = [0, 1].map(|k| pts.iter().map(|p| p[k]).max().unwrap());
            let (Some((x0, x1)), Some((ry0, ry1))) = (pixel_columns(min[0], max[0], width), pixel_rows(min[1], max[1], height)) else {
                return Ok(());
            };
            let mut spans = Vec::new();
            scan_triangle(pts, x0, x1, ry0, ry1, |x, y, e| spans.push((x, y, e)));
            proptest::prop_assert_eq!(spans, scan_each_pixel(pts, x0, x1, ry0, ry1));
        }
    }

    #[test]
    fn inside_steps_bounds() {
        // start + k·step ≥ 0
        assert_eq!(inside_steps(-10, 3), (4, i64::MAX)); // k = 4: 2 ≥ 0, k = 3: −1
        assert_eq!(inside_steps(-9, 3), (3, i64::MAX));
        assert_eq!(inside_steps(5, 3), (0, i64::MAX));
        assert_eq!(inside_steps(10, -3), (0, 4)); // k = 3: 1 ≥ 0, k = 4: −2
        assert_eq!(inside_steps(9, -3), (0, 4)); // k = 3: 0
        assert_eq!(inside_steps(-1, -3), (0, 0));
        assert_eq!(inside_steps(0, 0), (0, i64::MAX));
        assert_eq!(inside_steps(-1, 0), (0, 0));
    }
}
