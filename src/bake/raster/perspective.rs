//! Perspective triangles: clipped in view space against the near plane and the guard band
//! (Sutherland & Hodgman 1974), projected and snapped, then scanned with perspective-correct
//! attributes (Heckbert & Moreton 1991).

use rayon::prelude::*;

use super::camera::{PerspFrame, PerspectiveView};
use super::canvas::{Cull, DrawOptions, DrawStats, Fragment};
use super::limits::{MAX_VERTEX_SUBPIXELS, SUBPIXEL};
use super::scan::{orient, pixel_columns, pixel_rows, scan_triangle, weigh, Attributes};
use crate::math::{cross3, dot3, sub3};
use crate::mesh::Primitive;

/// A vertex of a triangle being clipped: its view-space position and its weights of the source
/// triangle's three vertices (index order). Both are linear along an edge in view space.
#[derive(Debug, Clone, Copy, Default)]
struct ClipVertex {
    view: [f64; 3],
    bary: [f64; 3],
}

/// Most vertices a triangle can have after clipping by the five planes (one more per plane).
const MAX_CLIP_VERTICES: usize = 3 + 5;

/// A convex polygon in a fixed buffer (clipping allocates nothing).
#[derive(Clone, Copy)]
struct ClipPolygon {
    v: [ClipVertex; MAX_CLIP_VERTICES],
    len: usize,
}

impl ClipPolygon {
    /// Sutherland–Hodgman against one plane. A crossing edge's new vertex is computed from its
    /// inside end, so the two triangles sharing that edge get the same point (no crack).
    fn clip(&self, plane: [f64; 4]) -> ClipPolygon {
        let dist = |c: &ClipVertex| plane[0] * c.view[0] + plane[1] * c.view[1] + plane[2] * c.view[2] + plane[3];
        let mut out = ClipPolygon { v: [ClipVertex::default(); MAX_CLIP_VERTICES], len: 0 };
        let mut push = |c: ClipVertex| {
            if out.len < MAX_CLIP_VERTICES {
                out.v[out.len] = c;
                out.len += 1;
            }
        };
        for k in 0..self.len {
            let (a, b) = (self.v[k], self.v[(k + 1) % self.len]);
            let (da, db) = (dist(&a), dist(&b));
            if da >= 0.0 {
                push(a);
            }
            if (da >= 0.0) != (db >= 0.0) {
                let (inside, outside, di, doo) = if da >= 0.0 { (a, b, da, db) } else { (b, a, db, da) };
                let t = di / (di - doo);
                let lerp = |p: [f64; 3], q: [f64; 3]| [0, 1, 2].map(|d| p[d] + t * (q[d] - p[d]));
                push(ClipVertex { view: lerp(inside.view, outside.view), bary: lerp(inside.bary, outside.bary) });
            }
        }
        out
    }
}

/// A perspective triangle (a source triangle or a piece of its clipped polygon) ready to scan.
#[derive(Debug, Clone, Copy)]
pub(super) struct PerspTri {
    /// Index of the source triangle in the primitive.
    index: u32,
    /// The source triangle's vertex indices, in index order.
    source: [u32; 3],
    /// Snapped positions, ordered so the edge functions are ≥ 0 inside.
    pts: [[i64; 2]; 3],
    /// 1 / depth at each of `pts`.
    inv_depth: [f64; 3],
    /// Weights of the source vertices at each of `pts`.
    bary: [[f64; 3]; 3],
    pub(super) min: [i64; 2],
    pub(super) max: [i64; 2],
    /// The source triangle is counter-clockwise seen from the eye.
    front: bool,
}

impl PerspTri {
    /// Screen triangle `pts` (edge functions ≥ 0 inside) of source triangle `t` (`idx` its vertex
    /// indices), with its bounding box.
    #[inline]
    fn new(t: usize, idx: &[u32], pts: [[i64; 2]; 3], inv_depth: [f64; 3], bary: [[f64; 3]; 3], front: bool) -> Self {
        PerspTri {
            index: t as u32,
            source: [idx[0], idx[1], idx[2]],
            pts,
            inv_depth,
            bary,
            min: [pts[0][0].min(pts[1][0]).min(pts[2][0]), pts[0][1].min(pts[1][1]).min(pts[2][1])],
            max: [pts[0][0].max(pts[1][0]).max(pts[2][0]), pts[0][1].max(pts[1][1]).max(pts[2][1])],
            front,
        }
    }
}

pub(super) struct PerspSetup {
    pub(super) tris: Vec<PerspTri>,
    pub(super) stats: DrawStats,
}

/// A vertex in view space, with its screen position when it needs no clipping.
#[derive(Clone, Copy)]
struct ViewVertex {
    view: [f64; 3],
    finite: bool,
    /// Inside every clip plane (then a triangle of three such vertices is not clipped).
    inside: bool,
    /// When `inside`: snapped position and 1/depth, None where off the subpixel grid's range.
    screen: Option<([i64; 2], f64)>,
}

/// What every triangle of one primitive's perspective draw shares: the camera frame, its clip
/// planes and the vertices in view space.
struct PerspContext {
    frame: PerspFrame,
    planes: [[f64; 4]; 5],
    verts: Vec<ViewVertex>,
}

impl PerspContext {
    /// None when the view is invalid. `parallel`: move the vertices to view space in parallel;
    /// otherwise into `verts` (cleared first: a buffer kept from an earlier draw).
    fn new(
        view: &PerspectiveView,
        object_to_world: &[[f64; 4]; 3],
        prim: &Primitive,
        parallel: bool,
        mut verts: Vec<ViewVertex>,
    ) -> Option<PerspContext> {
        let frame = view.frame().ok()?;
        let to_view = frame.view.then_from(object_to_world);
        let planes = frame.clip_planes();
        let one = |p: &[f32; 3]| {
            let v = to_view.apply([p[0] as f64, p[1] as f64, p[2] as f64]);
            let finite = v.iter().all(|c| c.is_finite());
            let inside = finite && planes.iter().all(|plane| inside(&v, plane));
            let screen = inside.then(|| frame.snapped(v)).flatten();
            ViewVertex { view: v, finite, inside, screen }
        };
        if parallel {
            verts = prim.positions.par_iter().map(one).collect();
        } else {
            verts.clear();
            verts.extend(prim.positions.iter().map(one));
        }
        Some(PerspContext { frame, planes, verts })
    }

    /// Sets up source triangle `t` (vertex indices `idx`): culled, clipped, projected and snapped
    /// into up to six screen triangles handed to `emit` in fan order; counted in `stats`.
    #[inline]
    fn triangle(&self, t: usize, idx: &[u32], cull: Cull, stats: &mut DrawStats, mut emit: impl FnMut(PerspTri)) {
        let get = |k: usize| self.verts.get(idx[k] as usize).filter(|v| v.finite);
        let (Some(va), Some(vb), Some(vc)) = (get(0), get(1), get(2)) else {
            stats.skipped += 1;
            return;
        };
        let (a, b, c) = (va.view, vb.view, vc.view);
        // Facing from the eye (the origin of view space). View space (right, up, forward) is
        // left-handed, so counter-clockwise seen from the eye is a positive triple product.
        let facing = dot3(cross3(sub3(b, a), sub3(c, a)), a);
        let front = facing > 0.0;
        let culled = facing == 0.0
            || !facing.is_finite()
            || match cull {
                Cull::None => false,
                Cull::Back => !front,
                Cull::Front => front,
            };
        if culled {
            stats.culled += 1;
            return;
        }
        if va.inside && vb.inside && vc.inside {
            // Nothing to clip (most triangles): the polygon path below with its three vertices,
            // projected once per vertex.
            let (Some(sa), Some(sb), Some(sc)) = (va.screen, vb.screen, vc.screen) else {
                stats.skipped += 1;
                return;
            };
            let screen = [sa, sb, sc];
            let area = orient(screen[0].0, screen[1].0, screen[2].0);
            if area == 0 {
                stats.culled += 1;
                return;
            }
            const UNIT: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
            let order = if area < 0 { [0, 2, 1] } else { [0, 1, 2] };
            let pts = order.map(|i| screen[i].0);
            emit(PerspTri::new(t, idx, pts, order.map(|i| screen[i].1), order.map(|i| UNIT[i]), front));
            stats.triangles += 1;
            return;
        }
        let mut poly = ClipPolygon { v: [ClipVertex::default(); MAX_CLIP_VERTICES], len: 3 };
        poly.v[..3].copy_from_slice(&[
            ClipVertex { view: a, bary: [1.0, 0.0, 0.0] },
            ClipVertex { view: b, bary: [0.0, 1.0, 0.0] },
            ClipVertex { view: c, bary: [0.0, 0.0, 1.0] },
        ]);
        for plane in &self.planes {
            if [a, b, c].iter().all(|v| inside(v, plane)) {
                continue;
            }
            poly = poly.clip(*plane);
            if poly.len < 3 {
                break;
            }
        }
        if poly.len < 3 {
            stats.clipped += 1;
            return;
        }
        // Project and snap the polygon; then a fan of triangles around its first vertex.
        let mut screen = [([0i64; 2], 0.0f64); MAX_CLIP_VERTICES];
        for (k, cv) in poly.v[..poly.len].iter().enumerate() {
            match self.frame.snapped(cv.view) {
                Some(p) => screen[k] = p,
                None => {
                    stats.skipped += 1;
                    return;
                }
            }
        }
        let mut any = false;
        for k in 1..poly.len - 1 {
            let fan = [0, k, k + 1];
            let area = orient(screen[0].0, screen[k].0, screen[k + 1].0);
            if area == 0 {
                continue;
            }
            let order = if area < 0 { [fan[0], fan[2], fan[1]] } else { fan };
            let pts = order.map(|i| screen[i].0);
            any = true;
            emit(PerspTri::new(t, idx, pts, order.map(|i| screen[i].1), order.map(|i| poly.v[i].bary), front));
        }
        if any {
            stats.triangles += 1;
        } else {
            // Zero area on the image once snapped, as in the orthographic path.
            stats.culled += 1;
        }
    }
}

/// Whether view-space `v` is on the kept side of `plane`.
#[inline]
fn inside(v: &[f64; 3], plane: &[f64; 4]) -> bool {
    plane[0] * v[0] + plane[1] * v[1] + plane[2] * v[2] + plane[3] >= 0.0
}

impl PerspFrame {
    /// View-space `v` projected and snapped to the subpixel grid, with 1/depth; None off the
    /// grid's range or not in front of the eye.
    #[inline]
    fn snapped(&self, v: [f64; 3]) -> Option<([i64; 2], f64)> {
        let s = self.project(v);
        match (snap(s[0]), snap(s[1])) {
            (Some(x), Some(y)) if s[2] > 0.0 => Some(([x, y], 1.0 / s[2])),
            _ => None,
        }
    }
}

/// A pixel coordinate on the subpixel grid, rounded half away from zero (as `f64::round`); None
/// beyond [`MAX_VERTEX_SUBPIXELS`] or NaN. Without a rounding instruction in the baseline target,
/// `f64::round` is a library call; this is the same number from a truncation.
#[inline]
fn snap(pixel: f64) -> Option<i64> {
    let v = pixel * SUBPIXEL as f64;
    // |round(v)| ≤ lim  ⇔  |v| < lim + ½ (exact: lim is a small power of two)
    if !(v.abs() < MAX_VERTEX_SUBPIXELS as f64 + 0.5) {
        return None;
    }
    let t = v as i64;
    // exact for |v| < 2^52
    let f = v - t as f64;
    Some(t + (f >= 0.5) as i64 - (f <= -0.5) as i64)
}

impl PerspSetup {
    /// Every triangle of `prim` set up for scanning (what a draw in parallel bands bins).
    pub(super) fn new(
        view: &PerspectiveView,
        object_to_world: &[[f64; 4]; 3],
        prim: &Primitive,
        cull: Cull,
    ) -> PerspSetup {
        let mut stats = DrawStats::default();
        let Some(ctx) = PerspContext::new(view, object_to_world, prim, true, Vec::new()) else {
            stats.skipped = prim.indices.len() / 3;
            return PerspSetup { tris: Vec::new(), stats };
        };
        let mut tris = Vec::with_capacity(prim.indices.len() / 3);
        for (t, idx) in prim.indices.chunks_exact(3).enumerate() {
            ctx.triangle(t, idx, cull, &mut stats, |tri| tris.push(tri));
        }
        PerspSetup { tris, stats }
    }
}

/// A serial perspective draw of `prim` into a whole canvas (`color`/`depth`, `width` × `height`):
/// each triangle is set up and scanned at once, in index order, so nothing is stored per triangle.
/// The same pixels and stats as [`PerspSetup::new`] followed by [`raster_rows_persp`] over all rows.
#[allow(clippy::too_many_arguments)]
pub(super) fn draw_persp<F>(
    color: &mut [[f32; 4]],
    depth: &mut [f32],
    width: u32,
    height: u32,
    view: &PerspectiveView,
    object_to_world: &[[f64; 4]; 3],
    prim: &Primitive,
    opts: &DrawOptions,
    shader: &mut F,
) -> DrawStats
where
    F: FnMut(&Fragment) -> Option<[f32; 4]>,
{
    let mut stats = DrawStats::default();
    let Some(ctx) = PerspContext::new(view, object_to_world, prim, false, VERTEX_CACHE.take()) else {
        stats.skipped = prim.indices.len() / 3;
        return stats;
    };
    let attributes = Attributes::of(prim);
    let mut fragments = 0u64;
    for (t, idx) in prim.indices.chunks_exact(3).enumerate() {
        ctx.triangle(t, idx, opts.cull, &mut stats, |tri| {
            fragments += raster_persp_triangle(color, depth, width, 0, height, &tri, prim, &attributes, opts, shader);
        });
    }
    if ctx.verts.capacity() <= MAX_KEPT_VERTICES {
        VERTEX_CACHE.set(ctx.verts);
    }
    stats.fragments = fragments;
    stats
}

thread_local! {
    /// Each thread's vertex cache, kept from one serial draw to the next: the LoD analyzer draws
    /// the same 100k-vertex tree hundreds of times, and a fresh 6 MB buffer each time cost its
    /// allocation and page faults.
    static VERTEX_CACHE: std::cell::Cell<Vec<ViewVertex>> = const { std::cell::Cell::new(Vec::new()) };
}

/// The largest vertex cache a thread keeps between draws (64 MB).
const MAX_KEPT_VERTICES: usize = 1 << 20;

/// [`raster_rows`](super::scan::raster_rows) for perspective triangles: per pixel, the screen-linear weights l give
/// 1/z = Σ lᵢ/zᵢ and the perspective-correct weights (lᵢ/zᵢ)·z of the (clipped) vertices, whose
/// own weights of the source triangle then give the attributes.
#[allow(clippy::too_many_arguments)]
pub(super) fn raster_rows_persp<F>(
    color: &mut [[f32; 4]],
    depth: &mut [f32],
    width: u32,
    y0: u32,
    y1: u32,
    setup: &PerspSetup,
    prim: &Primitive,
    tris: &[u32],
    opts: &DrawOptions,
    shader: &mut F,
) -> u64
where
    F: FnMut(&Fragment) -> Option<[f32; 4]>,
{
    let attributes = Attributes::of(prim);
    let mut written = 0u64;
    for &t in tris {
        if let Some(tri) = setup.tris.get(t as usize) {
            written += raster_persp_triangle(color, depth, width, y0, y1, tri, prim, &attributes, opts, shader);
        }
    }
    written
}

/// Scans one set-up triangle into the rows [y0, y1) held by `color`/`depth`; returns the fragments
/// written.
#[allow(clippy::too_many_arguments)]
#[inline]
fn raster_persp_triangle<F>(
    color: &mut [[f32; 4]],
    depth: &mut [f32],
    width: u32,
    y0: u32,
    y1: u32,
    tri: &PerspTri,
    prim: &Primitive,
    attributes: &Attributes,
    opts: &DrawOptions,
    shader: &mut F,
) -> u64
where
    F: FnMut(&Fragment) -> Option<[f32; 4]>,
{
    let Attributes { normals, uvs, colors } = *attributes;
    let n = prim.positions.len();
    let mut written = 0u64;
    let Some((ry0, ry1)) = pixel_rows(tri.min[1], tri.max[1], y1) else {
        return 0;
    };
    let ry0 = ry0.max(y0);
    if ry0 >= ry1 {
        return 0;
    }
    let Some((x0, x1)) = pixel_columns(tri.min[0], tri.max[0], width) else {
        return 0;
    };
    let vi = tri.source.map(|i| i as usize);
    if vi.iter().any(|&i| i >= n) {
        return 0;
    }
    let inv_area = 1.0 / orient(tri.pts[0], tri.pts[1], tri.pts[2]) as f64;
    let [w0, w1, w2] = tri.inv_depth;
    let [b0, b1, b2] = tri.bary;
    scan_triangle(tri.pts, x0, x1, ry0, ry1, |x, y, e| {
        let q = [e[0] as f64 * inv_area * w0, e[1] as f64 * inv_area * w1, e[2] as f64 * inv_area * w2];
        let inv_z = q[0] + q[1] + q[2];
        let z_view = 1.0 / inv_z;
        let z = z_view as f32;
        let k = (y - y0) as usize * width as usize + x as usize;
        if !opts.depth_test || z < depth[k] {
            let lam = [q[0] * z_view, q[1] * z_view, q[2] * z_view];
            let bary = weigh(lam, &b0, &b1, &b2);
            let bf = [bary[0] as f32, bary[1] as f32, bary[2] as f32];
            let p = &prim.positions;
            let frag = Fragment {
                x,
                y,
                depth: z,
                position: weigh(bf, &p[vi[0]], &p[vi[1]], &p[vi[2]]),
                normal: normals.map_or([0.0; 3], |nm| weigh(bf, &nm[vi[0]], &nm[vi[1]], &nm[vi[2]])),
                uv: uvs.map_or([0.0; 2], |u| weigh(bf, &u[vi[0]], &u[vi[1]], &u[vi[2]])),
                color: colors.map_or([1.0; 4], |cl| weigh(bf, &cl[vi[0]], &cl[vi[1]], &cl[vi[2]])),
                bary: bf,
                triangle: tri.index,
                front_facing: tri.front,
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
    written
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::strategy::Strategy;

    proptest::proptest! {
        /// `snap` is `f64::round` of the subpixel coordinate, and refuses what `round` puts out of range.
        #[test]
        fn snap_rounds_as_the_library_does(
            pixel in proptest::prop_oneof![
                -1.1e6f64..1.1e6,
                (-4096i64..4096).prop_map(|k| k as f64 / SUBPIXEL as f64 + 0.5 / SUBPIXEL as f64),
                proptest::num::f64::ANY,
            ],
        ) {
            let v = pixel * SUBPIXEL as f64;
            let r = v.round();
            let want = (r.abs() <= MAX_VERTEX_SUBPIXELS as f64).then_some(r as i64);
            proptest::prop_assert_eq!(snap(pixel), want);
        }
    }

    #[test]
    fn snap_at_the_edges_of_its_range() {
        let lim = MAX_VERTEX_SUBPIXELS as f64 / SUBPIXEL as f64;
        let sub = 1.0 / SUBPIXEL as f64;
        assert_eq!(snap(lim), Some(MAX_VERTEX_SUBPIXELS));
        assert_eq!(snap(lim + 0.49 * sub), Some(MAX_VERTEX_SUBPIXELS));
        assert_eq!(snap(lim + 0.5 * sub), None);
        assert_eq!(snap(-lim - 0.5 * sub), None);
        assert_eq!(snap(2.5 * sub), Some(3));
        assert_eq!(snap(-2.5 * sub), Some(-3));
        assert_eq!(snap(-0.4 * sub), Some(0));
        assert_eq!(snap(f64::NAN), None);
        assert_eq!(snap(f64::INFINITY), None);
    }
}
