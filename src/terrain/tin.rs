//! Error-bounded triangulated irregular network (TIN) by greedy insertion: Garland & Heckbert, "Fast
//! polygonal approximation of terrains and height fields" (CMU-CS-95-181, 1995), algorithm III —
//! Delaunay insertion of the worst-approximated sample, with per-triangle candidates in a heap.
//!
//! Start from the four corners (two triangles). Every triangle knows its candidate: the sample inside
//! it (closed, so edges count) with the largest vertical distance to the triangle's plane. A max-heap
//! keeps the triangles above the bound ordered by candidate error; the worst candidate is inserted and
//! the Delaunay property restored by flips, until the worst error is within the bound or the triangle
//! limit is reached. An insertion only re-triangulates a star-shaped cavity around the new vertex, so
//! only the triangles incident to it are rescanned; older queue entries of reused triangle slots are
//! recognised as stale because they no longer match the slot's current candidate.
//!
//! [`tin`] runs on a small flat-array triangulation specialised for this (the point's triangle is
//! always known, predicates are exact integer arithmetic); [`tin_spade`] is the same algorithm on the
//! spade crate, kept as the measured reference for that choice (about 1.7× slower on Puget Sound at
//! 10 m, most of it spade's point location and DCEL cache misses; see `benches/terrain.rs`).

use spade::handles::FixedVertexHandle;
use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation};

use crate::heightfield::Heightfield;
use crate::terrain::budget::{self, OverBudget, DEFAULT_MAX_VERTICES};
use crate::terrain::error::{check_heightfield, measure_stored, TerrainError};
use crate::terrain::plane::plane_height;
use crate::terrain::sample_mesh::SampleMesh;
use crate::terrain::stored::Storage;

/// What to build.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TinOptions {
    /// Largest allowed vertical distance between the mesh and any sample, in metres (≥ 0).
    pub max_error_m: f64,
    /// Stop refining before the triangle count would exceed this (≥ 2); the error then reached is
    /// reported in [`TinResult::max_error_m`].
    pub max_triangles: Option<usize>,
    /// The work budget: refuse a map predicted to need more vertices than this before meshing, and
    /// stop with an error when the mesh reaches it with the error still over the bound
    /// ([`crate::terrain::budget`]).
    pub max_vertices: usize,
    /// Cells a side of the terrain's chunks (0: not chunked). The map is then cut along every
    /// chunk line, so that at any bound each chunk's triangles lie in its square and neighbouring
    /// chunks meet along straight lines (shown at different levels, they leave cracks the skirts
    /// hide, never holes), and meshed in bands of whole chunks, each from its own rows alone
    /// ([`super::regions::band_cells_for_chunk`], [`super::regions::mesh_band`]). Ignored with a
    /// triangle limit.
    pub chunk_cells: u32,
}

impl Default for TinOptions {
    fn default() -> Self {
        TinOptions { max_error_m: 1.0, max_triangles: None, max_vertices: DEFAULT_MAX_VERTICES, chunk_cells: 0 }
    }
}

/// A TIN and the error it achieves.
#[derive(Debug, Clone, PartialEq)]
pub struct TinResult {
    pub mesh: SampleMesh,
    /// Largest vertical error over all samples, measured while building (equal to what
    /// [`crate::terrain::error::measure`] reports for `mesh`).
    pub max_error_m: f64,
    /// True if refinement stopped at `max_triangles` with the error still above `max_error_m`.
    pub hit_triangle_limit: bool,
}

/// A face whose candidate is worse than the bound, as queued.
#[derive(Debug, Clone, Copy)]
struct Entry {
    /// Vertical error at the candidate sample, metres.
    err: f64,
    /// Candidate sample, row-major index.
    sample: u32,
    face: u32,
}

/// Heap order: larger error first; ties go to the lower sample index, then the lower face index, so
/// the output depends on nothing but the input.
#[inline]
fn before(a: &Entry, b: &Entry) -> bool {
    if a.err != b.err {
        return a.err > b.err;
    }
    (a.sample, a.face) < (b.sample, b.face)
}

/// What the mesher keeps per face slot (slots are reused when edges flip).
#[derive(Debug, Clone, Copy)]
struct FaceSlot {
    /// The face's queued candidate (error, sample), or sample NONE. A queue entry that does not
    /// match it is stale: the face was rescanned since.
    err: f64,
    sample: u32,
    /// Upper bound on the face's vertical error (all samples, rounded up): lets the final error be
    /// found without rescanning every face.
    upper: f32,
}

/// No queued candidate.
const NONE: u32 = u32::MAX;

impl Default for FaceSlot {
    fn default() -> Self {
        FaceSlot { err: 0.0, sample: NONE, upper: 0.0 }
    }
}

/// Records a face's fresh scan and queues its candidate if it is above the bound.
fn record_scan(faces: &mut Vec<FaceSlot>, queue: &mut FaceQueue, face: u32, scan: &Scan, width: u32) {
    let f = face as usize;
    if faces.len() <= f {
        faces.resize(f + 1, FaceSlot::default());
    }
    let slot = &mut faces[f];
    // Rounded up so it stays an upper bound in f32.
    slot.upper = (scan.upper as f32).next_up();
    match scan.candidate {
        Some((err, i, j)) => {
            let sample = j * width + i;
            (slot.err, slot.sample) = (err, sample);
            queue.push(Entry { err, sample, face });
        }
        None => (slot.err, slot.sample) = (0.0, NONE),
    }
}

/// Max-heap (4-ary) of faces above the bound, keys inline, with lazy deletion: a rescanned face just
/// pushes a new entry and stale ones (not matching the face's current candidate) are dropped when
/// they surface. Nothing is written per face while
/// sifting, which matters because every such write would be a cache miss on a large map.
#[derive(Default)]
struct FaceQueue {
    heap: Vec<Entry>,
}

const ARITY: usize = 4;

impl FaceQueue {
    /// The worst valid entry, after dropping stale ones from the top.
    fn peek(&mut self, faces: &[FaceSlot]) -> Option<Entry> {
        while let Some(&top) = self.heap.first() {
            let current = faces.get(top.face as usize);
            if current.is_some_and(|f| f.sample == top.sample && f.err.to_bits() == top.err.to_bits()) {
                return Some(top);
            }
            self.pop();
        }
        None
    }

    fn push(&mut self, e: Entry) {
        self.heap.push(e);
        let mut p = self.heap.len() - 1;
        while p > 0 {
            let parent = (p - 1) / ARITY;
            if !before(&e, &self.heap[parent]) {
                break;
            }
            self.heap[p] = self.heap[parent];
            p = parent;
        }
        self.heap[p] = e;
    }

    fn pop(&mut self) {
        let Some(last) = self.heap.pop() else { return };
        let n = self.heap.len();
        if n == 0 {
            return;
        }
        let mut p = 0;
        loop {
            let first = ARITY * p + 1;
            if first >= n {
                break;
            }
            let mut m = first;
            for c in first + 1..(first + ARITY).min(n) {
                if before(&self.heap[c], &self.heap[m]) {
                    m = c;
                }
            }
            if !before(&self.heap[m], &last) {
                break;
            }
            self.heap[p] = self.heap[m];
            p = m;
        }
        self.heap[p] = last;
    }
}

/// Twice the signed area of (a, b, p) in the (i, j) plane, positive when counter-clockwise there;
/// exact for sides below 2^24.
#[inline]
fn orient(a: [i64; 2], b: [i64; 2], p: [i64; 2]) -> i64 {
    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
}

/// One edge's bound on the row spans of a triangle, stepped exactly from row to row (integer DDA, no
/// division per row). With the edge function e(x, y) = ax·x + r(y), r(y + 1) = r(y) + by, the samples
/// of row y on the triangle's side of the edge are x ≥ `x` (a lower bound, ax > 0) or x ≤ `x` (an upper
/// bound, ax < 0); `v` ∈ [0, `a`) is the edge function there and `a` = |ax|.
#[derive(Clone, Copy)]
struct EdgeStep {
    x: i64,
    v: i64,
    a: i64,
    /// Per row: x += dx, v += dv, and once more x += s, v −= a if v reached a.
    dx: i64,
    dv: i64,
    s: i64,
}

impl EdgeStep {
    /// The bound of edge ax·x + by·y + k0 ≥ 0 (ax ≠ 0) at row y.
    #[inline]
    fn new(ax: i64, by: i64, k0: i64, y: i64) -> EdgeStep {
        let r = by * y + k0;
        let a = ax.abs();
        let (dq, dr) = (by.div_euclid(a), by.rem_euclid(a));
        if ax > 0 {
            // Smallest x with a·x + r ≥ 0.
            EdgeStep { x: -r.div_euclid(a), v: r.rem_euclid(a), a, dx: -dq, dv: dr, s: -1 }
        } else {
            // Largest x with r − a·x ≥ 0.
            EdgeStep { x: r.div_euclid(a), v: r.rem_euclid(a), a, dx: dq, dv: dr, s: 1 }
        }
    }

    #[inline(always)]
    fn step(&mut self) {
        self.v += self.dv;
        // Branch-free: whether v wraps is data-dependent, so a branch would mispredict often.
        let wrap = -((self.v >= self.a) as i64);
        self.v -= self.a & wrap;
        self.x += self.dx + (self.s & wrap);
    }
}

/// Finds the sample of the closed triangle `c` farthest from the triangle's plane, if its error
/// exceeds `floor`, as (error, i, j); the corners themselves are never candidates. Also bounds the
/// error of every sample from above.
///
/// The triangle is scanned row by row; each row's span comes from the edge functions, stepped from
/// row to row in exact integers ([`EdgeStep`], so samples on edges are always included). Along a row
/// the plane is stepped in f64 ([`row_fast_max`]), which is fast but not bit-exact; only rows that can
/// hold the worst sample are walked again, and there any sample whose fast error comes within `slack`
/// of the best so far is re-evaluated with the canonical formula ([`plane_height`], exact integer
/// weights), so the returned error is exactly what the analyzer computes and the bound it certifies
/// is real.
fn find_candidate(hf: &Heightfield, mut corners: [Corner; 3], floor: f64) -> Scan {
    // Canonical corner order (ascending sample index) so `plane_height` sums in the same order as the
    // analyzer does; also puts the rows in c[0].j ..= c[2].j.
    corners.sort_unstable_by_key(|k| (k.y, k.x));
    let c = corners.map(|k| [k.x, k.y]);
    // Heights come with the corners (stored in the triangulation's vertices): no random reads here.
    let hc = corners.map(|k| k.h as f64);
    let signed = orient(c[0], c[1], c[2]);
    if signed == 0 {
        return Scan { candidate: None, upper: 0.0 };
    }
    let sign = signed.signum();
    let area = signed * sign;
    // Weight k at (x, y) = ax[k]·x + by[k]·y + k0[k]; weight 0 belongs to the edge opposite corner 0.
    let edges = [(c[1], c[2]), (c[2], c[0]), (c[0], c[1])];
    let mut ax = [0i64; 3];
    let mut by = [0i64; 3];
    let mut k0 = [0i64; 3];
    for (k, &(a, b)) in edges.iter().enumerate() {
        ax[k] = -(b[1] - a[1]) * sign;
        by[k] = (b[0] - a[0]) * sign;
        k0[k] = orient(a, b, [0, 0]) * sign;
    }
    // Rows c[0].y ..= c[2].y. The long edge c2–c0 (edge 1) bounds one side of every row; the other
    // side is c0–c1 (edge 2) down to row c[1].y and c1–c2 (edge 0) from there (both pass through c1,
    // so either gives that row's bound). A horizontal edge bounds no row and is never used.
    let (ya, yb, yc) = (c[0][1], c[1][1], c[2][1]);
    let edge = |k: usize, y: i64| EdgeStep::new(ax[k], by[k], k0[k], y);
    let mut long = edge(1, ya);
    let long_is_lower = ax[1] > 0;
    let mut short = if yb > ya { edge(2, ya) } else { edge(0, ya) };
    let switch_at = if yb > ya && yc > yb { yb } else { i64::MIN };
    // Plane gradient relative to corner 0, for the fast path.
    let inv_area = 1.0 / area as f64;
    let gx = (ax[0] as f64 * hc[0] + ax[1] as f64 * hc[1] + ax[2] as f64 * hc[2]) * inv_area;
    let gy = (by[0] as f64 * hc[0] + by[1] as f64 * hc[1] + by[2] as f64 * hc[2]) * inv_area;
    let xmin = c.iter().map(|p| p[0]).min().unwrap_or(0);
    let xmax = c.iter().map(|p| p[0]).max().unwrap_or(0);
    let (x0, y0) = (c[0][0], c[0][1]);
    // Bound on |z| anywhere in the triangle (and on every term of the fast evaluation); the fast
    // path's rounding error is a few ulps of it, so 1e-6 of it is ample slack.
    let magnitude = hc[0].abs().max(hc[1].abs()).max(hc[2].abs())
        + gx.abs() * (xmax - xmin) as f64
        + gy.abs() * (c[2][1] - c[0][1]) as f64;
    let slack = 1e-6 * (1.0 + magnitude);

    let w = hf.width;
    let mut best = floor;
    let mut found: Option<(u32, u32)> = None;
    // Exact re-walk of one row, in order: only samples whose fast error comes within `slack` of the
    // best (or of the row's fast maximum, since only the row's exact maximum can become the best and
    // the first sample reaching it wins) get the canonical evaluation.
    let mut rewalk = |&RowMax { y, lo, hi, max }: &RowMax, best: &mut f64| {
        let (y, lo) = (y as i64, lo as i64);
        let row = &hf.heights[y as usize * w + lo as usize..=y as usize * w + hi];
        let z0 = hc[0] + gx * (lo - x0) as f64 + gy * (y - y0) as f64;
        let t = max - 2.0 * slack;
        for (k, &h) in row.iter().enumerate() {
            if (z0 + gx * k as f64 - h as f64).abs() > t.max(*best - slack) {
                let x = lo + k as i64;
                let wt = [0, 1, 2].map(|e| ax[e] * x + by[e] * y + k0[e]);
                let err = (plane_height(wt, hc, area) - h as f64).abs();
                if err > *best && !c.contains(&[x, y]) {
                    *best = err;
                    found = Some((x as u32, y as u32));
                }
            }
        }
    };
    // Pass 1 takes every row's largest fast error (the innermost loop of the run, no per-sample
    // branch). Rows that may hold the worst sample are kept to be re-walked exactly, in order, once
    // the fast maximum R of the whole face is known: a row whose fast maximum is below R − 3·slack has
    // every exact error below that of the sample giving R, so it cannot hold the (first) worst
    // sample; nor can a row whose fast maximum is at most floor − slack. If the buffer fills, the
    // rows kept so far are re-walked at once (still in order, so the result is the same).
    let mut kept = [RowMax { y: 0, lo: 0, hi: 0, max: 0.0 }; KEPT_ROWS];
    let mut n_kept = 0;
    let floor_cut = floor - slack;
    let mut fast_max = 0.0f64;
    for y in ya..=yc {
        if y == switch_at {
            short = edge(0, yb);
        }
        let (lo, hi) = if long_is_lower { (long.x, short.x) } else { (short.x, long.x) };
        long.step();
        short.step();
        if lo > hi {
            continue;
        }
        debug_assert!(xmin <= lo && hi <= xmax);
        let z0 = hc[0] + gx * (lo - x0) as f64 + gy * (y - y0) as f64;
        let row_max = row_fast_max(&hf.heights, y as usize * w + lo as usize, (hi - lo + 1) as usize, z0, gx);
        fast_max = fast_max.max(row_max);
        if row_max > floor_cut && row_max >= fast_max - 3.0 * slack {
            if n_kept == KEPT_ROWS {
                let cut = fast_max - 3.0 * slack;
                let mut m = 0;
                for k in 0..n_kept {
                    if kept[k].max >= cut {
                        kept[m] = kept[k];
                        m += 1;
                    }
                }
                n_kept = m;
                if n_kept == KEPT_ROWS {
                    for r in &kept {
                        rewalk(r, &mut best);
                    }
                    n_kept = 0;
                }
            }
            kept[n_kept] = RowMax { y: y as u32, lo: lo as u32, hi: hi as usize, max: row_max };
            n_kept += 1;
        }
    }
    let cut = fast_max - 3.0 * slack;
    for r in &kept[..n_kept] {
        if r.max >= cut {
            rewalk(r, &mut best);
        }
    }
    Scan { candidate: found.map(|(i, j)| (best, i, j)), upper: fast_max + slack }
}

/// A row kept for the exact re-walk: its span and its largest fast error.
#[derive(Clone, Copy)]
struct RowMax {
    y: u32,
    lo: u32,
    hi: usize,
    max: f64,
}

/// Rows kept for the exact re-walk before it is forced (a small stack buffer).
const KEPT_ROWS: usize = 8;

/// The largest fast error |z0 + gx·k − h[k]| over the row h = heights[start..start + n] (n ≥ 1). The
/// plane is stepped along the row (two f64 lanes per SSE2 register, four samples per step); the
/// accumulated rounding is at most one ulp of the plane's magnitude per step, far inside the caller's
/// slack (1e-6 of it) for any row below 2^24 samples. A last partial group reads past the row's end
/// (when the heights go on) and masks those lanes out.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn row_fast_max(heights: &[f32], start: usize, n: usize, z0: f64, gx: f64) -> f64 {
    use std::arch::x86_64::*;
    let row = &heights[start..start + n];
    // from `heights`, not `row`: the last group may read (and mask out) samples past the row
    let p = heights[start..].as_ptr();
    // SAFETY: SSE2 is part of x86_64; every load reads heights[start + k..start + k + 4], checked to
    // be in bounds (k + 4 ≤ n, or start + k + 4 ≤ heights.len() for the last group).
    unsafe {
        let abs = _mm_castsi128_pd(_mm_set1_epi64x(i64::MAX));
        let step = _mm_set1_pd(4.0 * gx);
        let mut za = _mm_set_pd(z0 + gx, z0);
        let mut zb = _mm_set_pd(z0 + 3.0 * gx, z0 + 2.0 * gx);
        let (mut ma, mut mb) = (_mm_setzero_pd(), _mm_setzero_pd());
        let mut k = 0;
        while k + 4 <= n {
            fast_path_check!(start + k + 4 <= heights.len());
            let h = _mm_loadu_ps(p.add(k));
            ma = _mm_max_pd(ma, _mm_and_pd(_mm_sub_pd(za, _mm_cvtps_pd(h)), abs));
            mb = _mm_max_pd(mb, _mm_and_pd(_mm_sub_pd(zb, _mm_cvtps_pd(_mm_movehl_ps(h, h))), abs));
            za = _mm_add_pd(za, step);
            zb = _mm_add_pd(zb, step);
            k += 4;
        }
        let rest = n - k;
        if rest > 0 {
            if start + k + 4 <= heights.len() {
                // Lanes k .. k + rest are the row's; the others are zeroed (errors are ≥ 0).
                let keep_a = _mm_castsi128_pd(_mm_set_epi64x(-((rest >= 2) as i64), -1));
                let keep_b = _mm_castsi128_pd(_mm_set_epi64x(0, -((rest >= 3) as i64)));
                let h = _mm_loadu_ps(p.add(k));
                let ea = _mm_and_pd(_mm_sub_pd(za, _mm_cvtps_pd(h)), abs);
                let eb = _mm_and_pd(_mm_sub_pd(zb, _mm_cvtps_pd(_mm_movehl_ps(h, h))), abs);
                ma = _mm_max_pd(ma, _mm_and_pd(ea, keep_a));
                mb = _mm_max_pd(mb, _mm_and_pd(eb, keep_b));
            } else {
                // The very end of the heights: one sample at a time.
                for (d, &h) in row[k..].iter().enumerate() {
                    let e = (z0 + gx * (k + d) as f64 - h as f64).abs();
                    ma = _mm_max_sd(ma, _mm_set_sd(e));
                }
            }
        }
        let m = _mm_max_pd(ma, mb);
        _mm_cvtsd_f64(_mm_max_sd(m, _mm_unpackhi_pd(m, m)))
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn row_fast_max(heights: &[f32], start: usize, n: usize, z0: f64, gx: f64) -> f64 {
    heights[start..start + n].iter().enumerate().fold(0.0f64, |m, (k, &h)| m.max((z0 + gx * k as f64 - h as f64).abs()))
}

/// Result of scanning one face.
struct Scan {
    /// (error, i, j) of the worst sample, if worse than the floor asked for.
    candidate: Option<(f64, u32, u32)>,
    /// Upper bound on the exact error of every sample of the face (corners included).
    upper: f64,
}

/// A triangle corner: sample (x = i, y = j) and its height.
#[derive(Debug, Clone, Copy)]
struct Corner {
    x: i64,
    y: i64,
    h: f32,
}

/// A triangulation vertex: its sample and the sample's height, kept together so a face's corners
/// and heights come from one read. Coordinates are below 2^24, so exact in f32.
#[derive(Debug, Clone, Copy)]
struct Vertex {
    x: f32,
    y: f32,
    h: f32,
}

impl HasPosition for Vertex {
    type Scalar = f32;
    fn position(&self) -> Point2<f32> {
        Point2::new(self.x, self.y)
    }
}

impl Vertex {
    fn corner(&self) -> Corner {
        Corner { x: self.x as i64, y: self.y as i64, h: self.h }
    }
}

type Dt = DelaunayTriangulation<Vertex>;

/// One face of a star: (face index, corners as (i, j), one corner's vertex index).
type StarFace = (u32, [Corner; 3], u32);

/// Greedy-insertion state on spade: the triangulation, per-face bookkeeping and the queue of faces still
/// above the bound.
struct Mesher<'a> {
    hf: &'a Heightfield,
    max_error_m: f64,
    dt: Dt,
    faces: Vec<FaceSlot>,
    /// Per face: one of its vertices, where locating its candidate starts.
    hints: Vec<u32>,
    queue: FaceQueue,
    /// Scratch lists for a star (faces, neighbours), reused so an insertion allocates nothing.
    star: Vec<StarFace>,
    ring: Vec<(Corner, Option<u32>)>,
}

impl Mesher<'_> {
    /// Rescans the faces around vertex `v` (all of them new or changed by its insertion).
    fn rescan_star(&mut self, v: FixedVertexHandle) {
        let vh = self.dt.vertex(v);
        let pv = vh.data().corner();
        let hint = v.index() as u32;
        // Out-edges come counter-clockwise, so the face left of v → n[k] is (v, n[k], n[k + 1]):
        // one read per neighbour instead of walking each face.
        self.ring.clear();
        for e in vh.out_edges() {
            let face = e.face().as_inner().map(|f| f.fix().index() as u32);
            self.ring.push((e.to().data().corner(), face));
        }
        self.star.clear();
        let n = self.ring.len();
        for k in 0..n {
            if let (a, Some(face)) = self.ring[k] {
                self.star.push((face, [pv, a, self.ring[(k + 1) % n].0], hint));
            }
        }
        self.rescan();
    }

    /// Recomputes the candidates of the faces in `self.star` and queues those above the bound.
    fn rescan(&mut self) {
        let w = self.hf.width as u32;
        for &(face, corners, hint) in &self.star {
            let scan = find_candidate(self.hf, corners, self.max_error_m);
            record_scan(&mut self.faces, &mut self.queue, face, &scan, w);
            if self.hints.len() <= face as usize {
                self.hints.resize(face as usize + 1, 0);
            }
            self.hints[face as usize] = hint;
        }
    }
}

/// The triangulation as a [`SampleMesh`]. Built from one sequential pass over spade's half-edges
/// (each knows its origin, face, next and previous edge) instead of walking every face, which on a
/// large map would be several cache misses per triangle.
fn output(dt: &Dt) -> SampleMesh {
    let vertices: Vec<[u32; 2]> = dt.vertices().map(|v| [v.data().x as u32, v.data().y as u32]).collect();
    // Face slot 0 is spade's outer face; all others are inner faces (nothing is ever removed).
    let mut corners = vec![[0u32; 3]; dt.num_all_faces()];
    for e in dt.directed_edges() {
        let face = e.face();
        if face.is_outer() {
            continue;
        }
        // Place the origin by the edge's position in its face's cycle, counted from the cycle's
        // lowest-numbered edge, so the three corners land in counter-clockwise order.
        let (k, next, prev) = (e.fix().index(), e.next().fix().index(), e.prev().fix().index());
        let pos = if k < next && k < prev {
            0
        } else if prev < k && prev < next {
            1
        } else {
            2
        };
        corners[face.fix().index()][pos] = e.from().fix().index() as u32;
    }
    // spade's faces are counter-clockwise in (x = i, y = j), which is clockwise seen from +Y.
    let triangles = corners.iter().skip(1).map(|&[a, b, c]| [a, c, b]).collect();
    SampleMesh { vertices, triangles }
}

/// The largest vertical error of the final triangulation, exactly as the analyzer computes it. Every
/// face holds an upper bound of its error from its last scan; only faces whose bound reaches the best
/// exact error found so far are rescanned, most likely first.
///
/// With a `storage` that rounds, the faces' bounds cover the stored error (see [`recheck_stored`])
/// and the exact figure is the stored one, corners included.
fn achieved_error(
    hf: &Heightfield,
    faces: &[FaceSlot],
    first_face: usize,
    mesh: &SampleMesh,
    storage: Option<&Storage>,
) -> f64 {
    // Face slot f holds output triangle f − first_face.
    let faces = &faces[..faces.len().min(mesh.triangles.len() + first_face)];
    let exact = |f: usize, floor: f64| {
        let corners = mesh.triangles[f - first_face].map(|v| {
            let [i, j] = mesh.vertices[v as usize];
            Corner { x: i as i64, y: j as i64, h: hf.at(i as usize, j as usize) }
        });
        match storage {
            Some(s) => s.scan(hf, corners.map(|k| [k.x, k.y]), floor).1.max(floor),
            None => find_candidate(hf, corners, floor).candidate.map_or(floor, |c| c.0),
        }
    };
    // The face with the largest bound first: its exact error rules out almost every other face.
    let Some(first) =
        (first_face..faces.len()).max_by(|&a, &b| faces[a].upper.total_cmp(&faces[b].upper).then(b.cmp(&a)))
    else {
        return 0.0;
    };
    let mut best = exact(first, 0.0);
    let mut rest: Vec<(f32, usize)> = (first_face..faces.len())
        .filter(|&f| f != first && faces[f].upper as f64 > best)
        .map(|f| (faces[f].upper, f))
        .collect();
    rest.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    for (upper, f) in rest {
        if upper as f64 <= best {
            break;
        }
        best = exact(f, best);
    }
    best
}

/// Asks the CPU to start loading the heights around a sample that is about to be inserted: the
/// faces rescanned after the insertion lie around it, and greedy insertion jumps across the map, so
/// without this every row of every rescan waits on a cache miss. Overlaps with the spade insertion.
#[inline]
fn prefetch_around(hf: &Heightfield, i: usize, j: usize) {
    const ROWS: usize = 3;
    const COLUMNS: usize = 6;
    let w = hf.width;
    let (i0, i1) = (i.saturating_sub(COLUMNS), (i + COLUMNS).min(w - 1));
    for y in j.saturating_sub(ROWS)..=(j + ROWS).min(hf.height - 1) {
        for x in [i0, i1] {
            if let Some(p) = hf.heights.get(y * w + x) {
                prefetch(p);
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn prefetch<T>(p: &T) {
    // SAFETY: a prefetch is only a hint; it never faults and has no visible effect, and `p` is a
    // valid reference anyway.
    unsafe { std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p as *const T as *const i8) }
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn prefetch<T>(_: &T) {}

/// Checks the input and options every variant relies on.
fn check_input(hf: &Heightfield, opts: &TinOptions) -> Result<(), TerrainError> {
    check_heightfield(hf)?;
    if !opts.max_error_m.is_finite() || opts.max_error_m < 0.0 {
        return Err(TerrainError::InvalidMaxError { value: opts.max_error_m });
    }
    if let Some(limit) = opts.max_triangles {
        if limit < 2 {
            return Err(TerrainError::TriangleLimitTooSmall { limit });
        }
    }
    Ok(())
}

/// The same greedy insertion with spade's Delaunay triangulation underneath: the design's first
/// choice, kept as the reference [`tin`] is measured against (same contract, same candidates and
/// queue; see `benches/terrain.rs`). spade has to locate every insertion by walking from a hint
/// vertex and keeps a general DCEL, so on large maps it spends about half the run in cache misses
/// that the specialised triangulation of [`tin`] avoids.
pub fn tin_spade(hf: &Heightfield, opts: &TinOptions) -> Result<TinResult, TerrainError> {
    check_input(hf, opts)?;
    let (w, h) = (hf.width, hf.height);
    let internal = |i: u32, j: u32| TerrainError::Internal { i: i as usize, j: j as usize };

    let mut m = Mesher {
        hf,
        max_error_m: opts.max_error_m,
        dt: Dt::new(),
        faces: Vec::new(),
        hints: Vec::new(),
        queue: FaceQueue::default(),
        star: Vec::new(),
        ring: Vec::new(),
    };
    let vertex = |i: u32, j: u32| Vertex { x: i as f32, y: j as f32, h: hf.at(i as usize, j as usize) };
    let (xm, ym) = ((w - 1) as u32, (h - 1) as u32);
    for (i, j) in [(0, 0), (xm, 0), (xm, ym), (0, ym)] {
        m.dt.insert(vertex(i, j)).map_err(|_| internal(i, j))?;
    }
    // The two corner triangles (the last corner is not necessarily in both).
    m.star =
        m.dt.inner_faces()
            .map(|f| {
                let [a, b, c] = f.vertices();
                (f.fix().index() as u32, [a.data().corner(), b.data().corner(), c.data().corner()], 0)
            })
            .collect();
    m.rescan();

    let mut triangles = 2usize;
    let mut hit_triangle_limit = false;
    while let Some(top) = m.queue.peek(&m.faces) {
        let (ci, cj) = (top.sample % w as u32, top.sample / w as u32);
        // Inserting on the rectangle's border splits one triangle, inside it splits (flips aside) two.
        let on_border = ci == 0 || cj == 0 || ci as usize == w - 1 || cj as usize == h - 1;
        let added = if on_border { 1 } else { 2 };
        if let Some(limit) = opts.max_triangles {
            if triangles + added > limit {
                hit_triangle_limit = true;
                break;
            }
        }
        prefetch_around(hf, ci as usize, cj as usize);
        let before = m.dt.num_vertices();
        let v =
            m.dt.insert_with_hint(vertex(ci, cj), FixedVertexHandle::from_index(m.hints[top.face as usize] as usize))
                .map_err(|_| internal(ci, cj))?;
        if m.dt.num_vertices() != before + 1 {
            // The candidate was already a vertex: impossible for a valid triangulation (a closed face
            // holds no vertex but its corners); stop rather than loop forever.
            return Err(internal(ci, cj));
        }
        triangles += added;
        m.rescan_star(v);
    }
    let mesh = output(&m.dt);
    let max_error_m = achieved_error(hf, &m.faces, 1, &mesh, None);
    Ok(TinResult { mesh, max_error_m, hit_triangle_limit })
}

/// Half-edge "none": a border edge has no twin.
const NO_EDGE: u32 = u32::MAX;

#[inline]
fn next_edge(e: u32) -> u32 {
    if e % 3 == 2 {
        e - 2
    } else {
        e + 1
    }
}

#[inline]
fn prev_edge(e: u32) -> u32 {
    if e.is_multiple_of(3) {
        e + 2
    } else {
        e - 1
    }
}

/// Is `d` strictly inside the circumcircle of the counter-clockwise triangle (a, b, c)? Exact: with
/// coordinates below 2^24 every product fits in i128.
fn in_circle(a: [i64; 2], b: [i64; 2], c: [i64; 2], d: [i64; 2]) -> bool {
    // Offsets below 2^14 (any map up to 16384 samples a side): every term stays below 2^60, so i64
    // is exact and much cheaper than i128.
    let spread = [a, b, c].iter().fold(0, |m, p| m | (p[0] - d[0]).abs() | (p[1] - d[1]).abs());
    if spread < 1 << 14 {
        let row = |p: [i64; 2]| {
            let (x, y) = (p[0] - d[0], p[1] - d[1]);
            (x, y, x * x + y * y)
        };
        let (ax, ay, a2) = row(a);
        let (bx, by, b2) = row(b);
        let (cx, cy, c2) = row(c);
        return ax * (by * c2 - b2 * cy) - ay * (bx * c2 - b2 * cx) + a2 * (bx * cy - by * cx) > 0;
    }
    let row = |p: [i64; 2]| {
        let (x, y) = ((p[0] - d[0]) as i128, (p[1] - d[1]) as i128);
        (x, y, x * x + y * y)
    };
    let (ax, ay, a2) = row(a);
    let (bx, by, b2) = row(b);
    let (cx, cy, c2) = row(c);
    ax * (by * c2 - b2 * cy) - ay * (bx * c2 - b2 * cx) + a2 * (bx * cy - by * cx) > 0
}

/// A Delaunay triangulation of sample points specialised for greedy insertion, in flat arrays like
/// Garland & Heckbert's and mapbox/delatin's: triangle t has corners `tri[3t..3t + 3]`
/// (counter-clockwise in the (i, j) plane) and half-edge 3t + k runs from corner k to corner k + 1,
/// with `twin[e]` its opposite half-edge or NO_EDGE on the border. The mesher always knows which
/// triangle a new point falls in (the one whose candidate it is), so there is no point location,
/// and the exact integer predicates need no adaptive arithmetic.
#[derive(Default)]
struct GreedyDelaunay {
    coords: Vec<[u32; 2]>,
    tri: Vec<u32>,
    twin: Vec<u32>,
    /// Triangles created or changed by the last insertion (all incident to the new point).
    touched: Vec<u32>,
    /// Legalisation work list (half-edges opposite the new point).
    pending: Vec<u32>,
}

impl GreedyDelaunay {
    #[inline]
    fn point(&self, v: u32) -> [i64; 2] {
        let c = self.coords[v as usize];
        [c[0] as i64, c[1] as i64]
    }

    fn triangle_count(&self) -> usize {
        self.tri.len() / 3
    }

    /// Writes triangle `t` (a new slot if `t` is the count) and links its half-edges' twins both ways.
    fn set_triangle(&mut self, t: u32, corners: [u32; 3], twins: [u32; 3]) {
        let e0 = 3 * t as usize;
        if e0 == self.tri.len() {
            self.tri.extend_from_slice(&corners);
            self.twin.extend_from_slice(&twins);
        } else {
            self.tri[e0..e0 + 3].copy_from_slice(&corners);
            self.twin[e0..e0 + 3].copy_from_slice(&twins);
        }
        for (k, &o) in twins.iter().enumerate() {
            if o != NO_EDGE {
                self.twin[o as usize] = (e0 + k) as u32;
            }
        }
        self.touched.push(t);
    }

    /// Inserts point `p` (a new vertex) into triangle `t`, which contains it (edges included), and
    /// restores the Delaunay property by flips. Afterwards `touched` lists every triangle whose
    /// corners changed.
    fn insert(&mut self, t: u32, p: [u32; 2]) -> u32 {
        let pv = self.coords.len() as u32;
        self.coords.push(p);
        self.touched.clear();
        let pp = [p[0] as i64, p[1] as i64];
        let e0 = 3 * t;
        // Which edge (if any) the point lies on.
        let on_edge = (0..3)
            .map(|k| e0 + k)
            .find(|&e| orient(self.point(self.tri[e as usize]), self.point(self.tri[next_edge(e) as usize]), pp) == 0);
        // The new triangles form a fan around p: ring vertices counter-clockwise, the outer twin of
        // each ring edge, and the slots to reuse. Fan triangle k = (p, r[k], r[k + 1]), so its
        // half-edge 1 is the one opposite p.
        let mut ring = [0u32; 4];
        let mut outer = [NO_EDGE; 4];
        let mut slots = [0u32; 4];
        let (m, closed) = match on_edge {
            None => {
                for k in 0..3 {
                    ring[k] = self.tri[(e0 + k as u32) as usize];
                    outer[k] = self.twin[(e0 + k as u32) as usize];
                }
                let n = self.triangle_count() as u32;
                slots[..3].copy_from_slice(&[t, n, n + 1]);
                (3, true)
            }
            Some(e) => {
                // Edge u → v of t = (u, v, w).
                let (u, v, w) =
                    (self.tri[e as usize], self.tri[next_edge(e) as usize], self.tri[prev_edge(e) as usize]);
                let f = self.twin[e as usize];
                let n = self.triangle_count() as u32;
                if f == NO_EDGE {
                    // On the border: (p, v, w), (p, w, u); the fan stays open at p → v and u → p.
                    ring[..3].copy_from_slice(&[v, w, u]);
                    outer[0] = self.twin[next_edge(e) as usize];
                    outer[1] = self.twin[prev_edge(e) as usize];
                    slots[..2].copy_from_slice(&[t, n]);
                    (2, false)
                } else {
                    // Shared with t' = (v, u, x): four triangles around p.
                    let x = self.tri[prev_edge(f) as usize];
                    ring = [v, w, u, x];
                    outer = [
                        self.twin[next_edge(e) as usize],
                        self.twin[prev_edge(e) as usize],
                        self.twin[next_edge(f) as usize],
                        self.twin[prev_edge(f) as usize],
                    ];
                    slots = [t, n, f / 3, n + 1];
                    (4, true)
                }
            }
        };
        // Write the fan. Spokes: triangle k's half-edge 0 (p → r[k]) twins triangle k − 1's half-edge
        // 2 (r[k] → p). New slots are appended in increasing order, so create them in that order.
        let mut order = [0usize, 1, 2, 3];
        let order = &mut order[..m];
        order.sort_unstable_by_key(|&k| slots[k]);
        for &k in order.iter() {
            let r1 = if k + 1 < m || !closed { ring[k + 1] } else { ring[0] };
            self.set_triangle(slots[k], [pv, ring[k], r1], [NO_EDGE, outer[k], NO_EDGE]);
        }
        // Now that every fan slot exists, link the spokes.
        for k in 0..m {
            let e = 3 * slots[k];
            let prev_spoke = if k > 0 {
                3 * slots[k - 1] + 2
            } else if closed {
                3 * slots[m - 1] + 2
            } else {
                NO_EDGE
            };
            self.twin[e as usize] = prev_spoke;
            if prev_spoke != NO_EDGE {
                self.twin[prev_spoke as usize] = e;
            }
        }
        // Legalise the edges opposite p.
        self.pending.clear();
        for &s in &slots[..m] {
            self.pending.push(3 * s + 1);
        }
        while let Some(a) = self.pending.pop() {
            self.legalize(a);
        }
        self.touched.sort_unstable();
        self.touched.dedup();
        pv
    }

    /// Edge `a` (half-edge 1 of triangle (p, r0, r1), opposite p): if the point q across it lies
    /// inside the circumcircle, flip to (p, r0, q) + (p, q, r1) and queue their far edges.
    fn legalize(&mut self, a: u32) {
        let b = self.twin[a as usize];
        if b == NO_EDGE {
            return;
        }
        let t = a / 3;
        let t2 = b / 3;
        let (p, r0, r1) = (self.tri[3 * t as usize], self.tri[a as usize], self.tri[next_edge(a) as usize]);
        let q = self.tri[prev_edge(b) as usize];
        if !in_circle(self.point(p), self.point(r0), self.point(r1), self.point(q)) {
            return;
        }
        let spoke_in = self.twin[3 * t as usize]; // twin of p → r0
        let spoke_out = self.twin[3 * t as usize + 2]; // twin of r1 → p
        let h_r0q = self.twin[next_edge(b) as usize]; // twin of r0 → q
        let h_qr1 = self.twin[prev_edge(b) as usize]; // twin of q → r1
        self.set_triangle(t, [p, r0, q], [spoke_in, h_r0q, NO_EDGE]);
        self.set_triangle(t2, [p, q, r1], [3 * t + 2, h_qr1, spoke_out]);
        self.pending.push(3 * t + 1);
        self.pending.push(3 * t2 + 1);
    }
}

/// Builds a TIN of `hf` whose vertical error at every sample is at most `opts.max_error_m` (unless
/// `opts.max_triangles` stops it first). Deterministic; heights are only read.
pub fn tin(hf: &Heightfield, opts: &TinOptions) -> Result<TinResult, TerrainError> {
    tin_stored(hf, opts, &Storage::f32(hf))
}

/// [`tin`] for a file that stores the vertices as `storage` says (f32, or a 16-bit grid): the
/// bound holds for the surface as stored.
///
/// Without a triangle limit, a map of more than [`REGION_CELLS`](super::regions::REGION_CELLS)
/// cells a side is meshed as a grid of regions in parallel, joined along seams fixed before
/// meshing ([`super::regions`]); the regions depend only on the map's size, so the mesh is the same
/// at any thread count. With a triangle limit the whole map is one region (the limit picks the
/// worst samples of the whole map).
pub fn tin_stored(hf: &Heightfield, opts: &TinOptions, storage: &Storage) -> Result<TinResult, TerrainError> {
    check_tin_input(hf, opts)?;
    let (mesh, max_error_m, hit_triangle_limit) = if opts.max_triangles.is_some() {
        let whole = Rect { i0: 0, j0: 0, i1: (hf.width - 1) as u32, j1: (hf.height - 1) as u32 };
        let r = mesh_region(hf, opts, storage, whole, &[], None)?;
        (SampleMesh { vertices: r.vertices, triangles: r.triangles }, r.max_error_m, r.hit_triangle_limit)
    } else {
        let (mesh, max_error_m) = super::regions::mesh_by_regions(hf, opts, storage)?;
        (mesh, max_error_m, false)
    };
    finish_tin(hf, opts, storage, mesh, max_error_m, hit_triangle_limit)
}

/// Checks before meshing `hf` as [`tin_stored`] does: the map and options, and the vertex budget
/// the map is predicted to need.
pub(crate) fn check_tin_input(hf: &Heightfield, opts: &TinOptions) -> Result<(), TerrainError> {
    check_input(hf, opts)?;
    budget::check_tin(hf, opts.max_error_m, opts.max_vertices).map_err(|over| TerrainError::OverBudget {
        limit: opts.max_vertices,
        over,
        max_error_m: opts.max_error_m,
        grid: false,
    })
}

/// The checks after meshing that [`tin_stored`] makes of the joined mesh (`max_error_m` as the
/// mesher found it): the vertex budget, and a bound finer than the storage holds.
pub(crate) fn finish_tin(
    hf: &Heightfield,
    opts: &TinOptions,
    storage: &Storage,
    mesh: SampleMesh,
    max_error_m: f64,
    hit_triangle_limit: bool,
) -> Result<TinResult, TerrainError> {
    finish_tin_stored(Some((hf, storage)), opts, mesh, max_error_m, hit_triangle_limit)
}

/// [`finish_tin`] where `stored` is the map and its storage, or `None` for a map whose storage is
/// exact ([`Storage::is_exact`]: then the map is not read).
pub(crate) fn finish_tin_stored(
    stored: Option<(&Heightfield, &Storage)>,
    opts: &TinOptions,
    mesh: SampleMesh,
    max_error_m: f64,
    hit_triangle_limit: bool,
) -> Result<TinResult, TerrainError> {
    let over_budget =
        |over| TerrainError::OverBudget { limit: opts.max_vertices, over, max_error_m: opts.max_error_m, grid: false };
    if mesh.vertices.len() > opts.max_vertices {
        return Err(over_budget(OverBudget::Exceeded));
    }
    let Some((hf, storage)) = stored.filter(|(_, s)| !s.is_exact()) else {
        return Ok(TinResult { mesh, max_error_m, hit_triangle_limit });
    };
    if max_error_m <= opts.max_error_m || hit_triangle_limit {
        return Ok(TinResult { mesh, max_error_m, hit_triangle_limit });
    }
    // Every face's samples other than its corners are within the bound as stored; what is left
    // over is at vertices, whose stored heights the bound is finer than.
    let stats = measure_stored(hf, &mesh, storage);
    let [i, j] = stats.worst_sample;
    let height_m = hf.reference(j as usize * hf.width + i as usize);
    let (step_m, storage_kind) = storage.height_step(height_m);
    Err(TerrainError::BelowStoragePrecision {
        max_error_m: opts.max_error_m,
        achieved_m: stats.max_error_m,
        i: i as usize,
        j: j as usize,
        height_m,
        step_m,
        storage: storage_kind,
    })
}

/// A rectangle of samples, corners included: columns `i0..=i1`, rows `j0..=j1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Rect {
    pub i0: u32,
    pub j0: u32,
    pub i1: u32,
    pub j1: u32,
}

/// The vertex budget shared by the regions of one map while they mesh in parallel: every vertex a
/// region inserts off the cut lines is in the joined mesh exactly once, so once their count (with
/// the vertices every region starts from) passes the budget, the joined mesh would too, whatever
/// the thread count: meshing stops there instead of after the whole map.
pub(crate) struct SharedBudget<'a> {
    pub count: &'a std::sync::atomic::AtomicUsize,
    pub limit: usize,
    /// The cut lines (columns, rows) between regions.
    pub cuts: (&'a [u32], &'a [u32]),
}

/// One rectangle of the map meshed by greedy insertion.
pub(crate) struct RegionMesh {
    /// Samples (i, j), the rectangle's corners first, then `border`, then as inserted.
    pub vertices: Vec<[u32; 2]>,
    /// Clockwise seen from +Y, as [`SampleMesh`] holds them.
    pub triangles: Vec<[u32; 3]>,
    /// Largest error over the rectangle's samples (as stored, when the storage rounds).
    pub max_error_m: f64,
    pub hit_triangle_limit: bool,
    /// Vertices inserted off the cut lines (counted in the [`SharedBudget`]).
    pub inserted_inside: usize,
}

/// Greedy insertion over the samples of `rect` alone, starting from its corners and the `border`
/// samples (on its sides, none a corner; a seam shared with a neighbouring rectangle), which stay
/// vertices: the sides between them are hull edges, never flipped, so two rectangles that start
/// from the same seam samples meet without a crack as long as neither inserts another sample on it.
pub(crate) fn mesh_region(
    hf: &Heightfield,
    opts: &TinOptions,
    storage: &Storage,
    rect: Rect,
    border: &[[u32; 2]],
    shared: Option<&SharedBudget>,
) -> Result<RegionMesh, TerrainError> {
    let over_budget =
        |over| TerrainError::OverBudget { limit: opts.max_vertices, over, max_error_m: opts.max_error_m, grid: false };
    let w = hf.width;
    let Rect { i0, j0, i1, j1 } = rect;
    let corner = |v: u32, dt: &GreedyDelaunay| {
        let [i, j] = dt.coords[v as usize];
        Corner { x: i as i64, y: j as i64, h: hf.at(i as usize, j as usize) }
    };
    let mut dt = GreedyDelaunay::default();
    // Corners 0 = (i0, j0), 1 = (i1, j0), 2 = (i1, j1), 3 = (i0, j1); triangles (0, 1, 2) and
    // (0, 2, 3), counter-clockwise in (i, j), sharing the diagonal 2 → 0 / 0 → 2.
    dt.coords.extend_from_slice(&[[i0, j0], [i1, j0], [i1, j1], [i0, j1]]);
    dt.set_triangle(0, [0, 1, 2], [NO_EDGE, NO_EDGE, NO_EDGE]);
    dt.set_triangle(1, [0, 2, 3], [2, NO_EDGE, NO_EDGE]);
    // The seam samples: each splits the hull edge it lies on (found among the border half-edges).
    for &p in border {
        let pp = [p[0] as i64, p[1] as i64];
        let holder = (0..dt.tri.len() as u32).find(|&e| {
            if dt.twin[e as usize] != NO_EDGE {
                return false;
            }
            let (a, b) = (dt.point(dt.tri[e as usize]), dt.point(dt.tri[next_edge(e) as usize]));
            orient(a, b, pp) == 0 && (pp[0] - a[0]) * (pp[0] - b[0]) + (pp[1] - a[1]) * (pp[1] - b[1]) < 0
        });
        let Some(e) = holder else {
            debug_assert!(false, "seam sample {p:?} is not inside a side of {rect:?}");
            continue;
        };
        dt.insert(e / 3, p);
    }
    let mut faces: Vec<FaceSlot> = Vec::new();
    let mut queue = FaceQueue::default();
    // The file stores f32 positions: where they can differ from the samples, faces near the bound
    // are measured again as stored.
    let as_stored = !storage.is_exact();
    let rescan = |dt: &GreedyDelaunay, faces: &mut Vec<FaceSlot>, queue: &mut FaceQueue, t: u32| {
        let e = 3 * t as usize;
        let corners = [corner(dt.tri[e], dt), corner(dt.tri[e + 1], dt), corner(dt.tri[e + 2], dt)];
        let mut scan = find_candidate(hf, corners, opts.max_error_m);
        if as_stored {
            scan = recheck_stored(storage, hf, corners, scan, opts.max_error_m);
        }
        record_scan(faces, queue, t, &scan, w as u32);
    };
    for t in 0..dt.triangle_count() as u32 {
        rescan(&dt, &mut faces, &mut queue, t);
    }

    let mut hit_triangle_limit = false;
    let mut inserted_inside = 0;
    while let Some(top) = queue.peek(&faces) {
        let (ci, cj) = (top.sample % w as u32, top.sample / w as u32);
        // Inserting on the rectangle's border splits one triangle, anywhere else two (net).
        let on_border = ci == i0 || cj == j0 || ci == i1 || cj == j1;
        if let Some(b) = shared {
            let on_cut = b.cuts.0.binary_search(&ci).is_ok() || b.cuts.1.binary_search(&cj).is_ok();
            if !on_cut {
                inserted_inside += 1;
                if b.count.fetch_add(1, std::sync::atomic::Ordering::Relaxed) >= b.limit {
                    return Err(over_budget(OverBudget::Exceeded));
                }
            }
        }
        let added = if on_border { 1 } else { 2 };
        if let Some(limit) = opts.max_triangles {
            if dt.triangle_count() + added > limit {
                hit_triangle_limit = true;
                break;
            }
        }
        // one region alone (the whole map): its own count is the mesh's; regions share theirs above
        if shared.is_none() && dt.coords.len() >= opts.max_vertices {
            return Err(over_budget(OverBudget::Reached { error_m: top.err }));
        }
        prefetch_around(hf, ci as usize, cj as usize);
        dt.insert(top.face, [ci, cj]);
        let touched = std::mem::take(&mut dt.touched);
        for &t in &touched {
            rescan(&dt, &mut faces, &mut queue, t);
        }
        dt.touched = touched;
    }

    let mesh = SampleMesh {
        vertices: std::mem::take(&mut dt.coords),
        // Counter-clockwise in (i, j) is clockwise seen from +Y: swap two corners.
        triangles: dt.tri.chunks_exact(3).map(|c| [c[0], c[2], c[1]]).collect(),
    };
    let max_error_m = achieved_error(hf, &faces, 0, &mesh, as_stored.then_some(storage));
    Ok(RegionMesh {
        vertices: mesh.vertices,
        triangles: mesh.triangles,
        max_error_m,
        hit_triangle_limit,
        inserted_inside,
    })
}

/// A face's scan as stored (see [`Storage`]): a face the mesher found above the bound stays
/// queued; one within it whose stored error may still exceed the bound (within the margin of the
/// storage's rounding) is scanned again as stored, and queued if a sample other than a corner is
/// over the bound there.
fn recheck_stored(storage: &Storage, hf: &Heightfield, corners: [Corner; 3], scan: Scan, floor: f64) -> Scan {
    let c = corners.map(|k| [k.x, k.y]);
    let margin = storage.margin(c, corners.map(|k| k.h as f64));
    if scan.candidate.is_some() {
        // queued as it is; its bound covers the stored error (the final figure relies on it when
        // the triangle limit stops refinement)
        return Scan { candidate: scan.candidate, upper: scan.upper + margin };
    }
    if scan.upper + margin <= floor {
        return Scan { candidate: None, upper: scan.upper + margin };
    }
    let (candidate, all) = storage.scan(hf, c, floor);
    Scan { candidate, upper: all }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::terrain::error::measure;
    use proptest::prelude::*;
    use std::collections::{HashMap, HashSet};

    /// The SSE2 row scan (its loads checked by `fast_path_check!` here) against the plain one, at
    /// every row length and position: rows ending inside the heights (the masked last group reads
    /// past the row) and at their very end (the scalar tail).
    #[test]
    fn the_fast_row_scan_equals_the_plain_one_at_every_length_and_end() {
        let heights: Vec<f32> = (0..37).map(|k| ((k * 7919) % 113) as f32 * 0.37 - 20.0).collect();
        let (z0, gx) = (-3.25, 0.618);
        for start in 0..heights.len() {
            for n in 1..=heights.len() - start {
                let plain = heights[start..start + n]
                    .iter()
                    .enumerate()
                    .fold(0.0f64, |m, (k, &h)| m.max((z0 + gx * k as f64 - h as f64).abs()));
                let fast = row_fast_max(&heights, start, n, z0, gx);
                assert!((fast - plain).abs() <= 1e-12 * plain.max(1.0), "start {start}, n {n}: {fast} vs {plain}");
            }
        }
    }

    /// Asserts that `mesh` is a valid triangulation of the whole sample rectangle of `hf`: vertices
    /// in range and distinct, corners present, every triangle non-degenerate and counter-clockwise
    /// seen from +Y, every interior edge shared by exactly two triangles in opposite directions and
    /// every other edge on the border, areas summing to the rectangle's, every sample covered.
    pub(crate) fn check_mesh(hf: &Heightfield, mesh: &SampleMesh) {
        let (w, h) = (hf.width as i64, hf.height as i64);
        let mut seen = HashSet::new();
        for v in &mesh.vertices {
            assert!((v[0] as i64) < w && (v[1] as i64) < h, "vertex {v:?} outside {w}×{h}");
            assert!(seen.insert(*v), "duplicate vertex {v:?}");
        }
        for corner in [[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]] {
            assert!(seen.contains(&[corner[0] as u32, corner[1] as u32]), "corner {corner:?} missing");
        }
        let mut twice_area = 0i64;
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &mesh.triangles {
            let p = t.map(|k| {
                let v = mesh.vertices[k as usize];
                [v[0] as i64, v[1] as i64]
            });
            // With x = i, z = j the +Y component of (b − a) × (c − a) is −orient(a, b, c).
            let up = -orient(p[0], p[1], p[2]);
            assert!(up > 0, "triangle {t:?} = {p:?} is degenerate or clockwise from +Y");
            twice_area += up;
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        assert_eq!(twice_area, 2 * (w - 1) * (h - 1), "triangle areas do not sum to the rectangle");
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1, "directed edge {a}->{b} used {n} times");
            if !edges.contains_key(&(b, a)) {
                let (p, q) = (mesh.vertices[a as usize], mesh.vertices[b as usize]);
                let on_border = (p[0] == q[0] && (p[0] == 0 || p[0] as i64 == w - 1))
                    || (p[1] == q[1] && (p[1] == 0 || p[1] as i64 == h - 1));
                assert!(on_border, "unmatched edge {p:?}->{q:?} is not on the border");
            }
        }
        assert_eq!(measure(hf, mesh).samples_covered, hf.width * hf.height, "not every sample covered");
    }

    fn map(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> Heightfield {
        let mut heights = Vec::with_capacity(w * h);
        for j in 0..h {
            for i in 0..w {
                heights.push(f(i, j));
            }
        }
        Heightfield { width: w, height: h, heights, cell_size_m: 1.0, exact: None }
    }

    fn noise(w: usize, h: usize, seed: u64, range: u64, scale: f32) -> Heightfield {
        map(w, h, |i, j| (crate::random::mix64(seed ^ ((j * w + i) as u64)) % range) as f32 * scale)
    }

    /// Builds a TIN and checks everything the contract promises.
    fn checked(hf: &Heightfield, max_error_m: f64, max_triangles: Option<usize>) -> TinResult {
        let before = hf.clone();
        let r = tin(hf, &TinOptions { max_error_m, max_triangles, ..TinOptions::default() }).expect("tin");
        assert_eq!(*hf, before, "heights modified");
        check_mesh(hf, &r.mesh);
        let s = measure(hf, &r.mesh);
        assert_eq!(s.max_error_m, r.max_error_m, "reported and measured max error differ");
        if !r.hit_triangle_limit {
            assert!(s.max_error_m <= max_error_m, "error {} above bound {max_error_m}", s.max_error_m);
        }
        if let Some(limit) = max_triangles {
            assert!(r.mesh.triangles.len() <= limit);
        }
        r
    }

    #[test]
    fn constant_map_is_two_triangles() {
        let r = checked(&map(50, 30, |_, _| 123.4), 0.0, None);
        assert_eq!(r.mesh.triangles.len(), 2);
        assert_eq!(r.max_error_m, 0.0);
    }

    #[test]
    fn planar_map_is_two_triangles() {
        let r = checked(&map(65, 40, |i, j| 0.5 * i as f32 - 0.25 * j as f32 + 10.0), 0.0, None);
        assert_eq!(r.mesh.triangles.len(), 2);
        let r = checked(&map(37, 23, |i, j| 0.3 * i as f32 + 0.7 * j as f32), 1e-3, None);
        assert_eq!(r.mesh.triangles.len(), 2);
    }

    #[test]
    fn single_spike_in_the_middle() {
        let r = checked(&map(33, 33, |i, j| if (i, j) == (16, 16) { 100.0 } else { 0.0 }), 0.5, None);
        assert!(r.mesh.vertices.contains(&[16, 16]));
    }

    #[test]
    fn single_spike_on_the_border() {
        for spike in [(0, 10), (20, 32), (32, 5), (7, 0)] {
            let r = checked(&map(33, 33, |i, j| if (i, j) == spike { -50.0 } else { 5.0 }), 0.5, None);
            assert!(r.mesh.vertices.contains(&[spike.0 as u32, spike.1 as u32]), "{spike:?}");
        }
    }

    #[test]
    fn vertical_cliff() {
        let r = checked(&map(40, 30, |i, _| if i < 17 { 0.0 } else { 500.0 }), 0.5, None);
        assert!(r.mesh.triangles.len() < 2 * 39 * 29);
        checked(&map(40, 30, |i, j| if i + j < 35 { 0.0 } else { 500.0 }), 1.0, None);
    }

    #[test]
    fn white_noise() {
        let hf = noise(40, 35, 1, 1000, 0.1);
        let r = checked(&hf, 0.0, None);
        // Every sample off the plane of its neighbours: the full grid's triangle count.
        assert_eq!(r.mesh.vertices.len(), 40 * 35);
        assert_eq!(r.mesh.triangles.len(), 2 * 39 * 34);
        let r = checked(&hf, 5.0, None);
        assert!(r.mesh.triangles.len() > 2 * 39 * 34 / 2, "{}", r.mesh.triangles.len());
    }

    #[test]
    fn checkerboard() {
        let r = checked(&map(25, 25, |i, j| if (i + j) % 2 == 0 { 0.0 } else { 10.0 }), 1.0, None);
        assert_eq!(r.mesh.vertices.len(), 25 * 25);
    }

    #[test]
    fn non_square_301_by_17() {
        let hf = crate::synth::fractal(301, 17, 1.0, 200.0, 0.6, 3);
        for e in [0.0, 0.5, 5.0, 50.0] {
            checked(&hf, e, None);
        }
        let tall = crate::synth::fractal(9, 120, 1.0, 200.0, 0.6, 4);
        checked(&tall, 2.0, None);
    }

    #[test]
    fn two_by_two() {
        let r = checked(&map(2, 2, |i, j| (i * 7 + j * 3) as f32), 0.0, None);
        assert_eq!(r.mesh.triangles.len(), 2);
        assert_eq!(r.mesh.vertices.len(), 4);
    }

    #[test]
    fn degenerate_sizes_are_clear_errors() {
        for (w, h) in [(1, 10), (10, 1), (1, 1), (0, 0)] {
            let e = tin(&map(w, h, |_, _| 0.0), &TinOptions::default()).unwrap_err();
            assert_eq!(e, TerrainError::ZeroArea { width: w, height: h });
            assert!(e.to_string().contains("at least 2×2"));
        }
    }

    #[test]
    fn bad_options_are_errors() {
        let hf = map(4, 4, |_, _| 0.0);
        for bad in [-1.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                tin(&hf, &TinOptions { max_error_m: bad, max_triangles: None, ..TinOptions::default() }),
                Err(TerrainError::InvalidMaxError { .. })
            ));
        }
        assert_eq!(
            tin(&hf, &TinOptions { max_error_m: 1.0, max_triangles: Some(1), ..TinOptions::default() }),
            Err(TerrainError::TriangleLimitTooSmall { limit: 1 })
        );
        let mut nan = hf.clone();
        nan.heights[6] = f32::NAN;
        assert_eq!(tin(&nan, &TinOptions::default()), Err(TerrainError::NonFiniteHeight { i: 2, j: 1 }));
    }

    /// The work budget: a map whose estimate is within it but whose mesh is not stops at the budget
    /// with the error it had reached (over the bound); the same map within a budget it fits meshes as
    /// before; a triangle cap below the budget stops first (best effort, not an error).
    #[test]
    fn the_vertex_budget_stops_the_mesher_when_the_estimate_passed() {
        let hf = crate::synth::fractal(129, 129, 1.0, 200.0, 0.6, 7);
        let full = tin(&hf, &TinOptions { max_error_m: 4.0, ..TinOptions::default() }).unwrap();
        let needed = full.mesh.vertices.len();
        let estimate = budget::sharp_samples(&hf, 4.0);
        assert!(estimate < needed * 3 / 4, "the test needs a map the estimate underrates: {estimate} vs {needed}");
        let limit = (estimate + needed) / 2;
        let opts = TinOptions { max_error_m: 4.0, max_vertices: limit, ..TinOptions::default() };
        match tin(&hf, &opts) {
            Err(TerrainError::OverBudget { limit: l, over: OverBudget::Reached { error_m }, .. }) => {
                assert_eq!(l, limit);
                assert!(error_m > 4.0, "stopped over the bound: {error_m}");
            }
            other => panic!("expected the budget to stop the mesher, got {other:?}"),
        }
        let roomy = TinOptions { max_error_m: 4.0, max_vertices: needed, ..TinOptions::default() };
        assert_eq!(tin(&hf, &roomy).unwrap(), full, "a budget the mesh fits changes nothing");
        let capped = TinOptions { max_triangles: Some(limit), ..opts };
        let best_effort = tin(&hf, &capped).unwrap();
        assert!(best_effort.hit_triangle_limit && best_effort.mesh.vertices.len() < limit);
    }

    #[test]
    fn sixteen_bit_full_range() {
        // Raw 16-bit values 0..=65535 at 0.1 m, plus the extremes side by side.
        let hf = map(64, 48, |i, j| {
            let v = match (i, j) {
                (10, 10) => 65535,
                (11, 10) => 0,
                _ => crate::random::mix64((j * 64 + i) as u64 / 7) % 65536,
            };
            v as f32 * 0.1
        });
        for e in [0.0, 10.0, 1000.0] {
            checked(&hf, e, None);
        }
    }

    #[test]
    fn triangle_limit_is_honoured() {
        let hf = crate::synth::fractal(65, 65, 1.0, 300.0, 0.55, 9);
        let free = checked(&hf, 0.5, None);
        for limit in [2, 3, 10, 101, 500] {
            let r = checked(&hf, 0.5, Some(limit));
            assert!(r.hit_triangle_limit);
            assert!(r.mesh.triangles.len() <= limit && r.mesh.triangles.len() + 2 > limit);
            assert!(r.max_error_m > 0.5);
        }
        let r = checked(&hf, 0.5, Some(free.mesh.triangles.len()));
        assert!(!r.hit_triangle_limit);
        assert_eq!(r, free);
    }

    /// Every interior edge is locally Delaunay: the far corner of the neighbour is not strictly
    /// inside the circumcircle.
    fn assert_delaunay(mesh: &SampleMesh) {
        let p = |v: u32| {
            let c = mesh.vertices[v as usize];
            [c[0] as i64, c[1] as i64]
        };
        // Triangles are clockwise in (i, j); reverse them to the counter-clockwise order in_circle wants.
        let ccw: Vec<[u32; 3]> = mesh.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect();
        let mut by_edge: HashMap<(u32, u32), u32> = HashMap::new();
        for (k, t) in ccw.iter().enumerate() {
            for e in 0..3 {
                by_edge.insert((t[e], t[(e + 1) % 3]), ((k as u32) << 2) | e as u32);
            }
        }
        for t in &ccw {
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                if let Some(&code) = by_edge.get(&(b, a)) {
                    let u = ccw[(code >> 2) as usize];
                    let far = u[((code & 3) as usize + 2) % 3];
                    assert!(!in_circle(p(t[0]), p(t[1]), p(t[2]), p(far)), "edge {a}-{b} not Delaunay");
                }
            }
        }
    }

    #[test]
    fn triangulation_is_delaunay() {
        for (hf, e) in [
            (crate::synth::fractal(97, 61, 1.0, 300.0, 0.55, 11), 2.0),
            (noise(30, 30, 7, 100, 1.0), 0.0),
            (map(40, 30, |i, _| if i < 17 { 0.0 } else { 500.0 }), 0.5),
        ] {
            assert_delaunay(&checked(&hf, e, None).mesh);
        }
    }

    #[test]
    fn spade_reference_agrees() {
        // Same contract from the spade variant, and (Delaunay ties aside) nearly the same mesh.
        for (hf, e) in [
            (crate::synth::fractal(129, 97, 1.0, 300.0, 0.55, 5), 1.0),
            (noise(25, 19, 3, 50, 0.5), 3.0),
            (map(33, 33, |i, j| if (i, j) == (0, 10) { -50.0 } else { 5.0 }), 0.5),
        ] {
            let ours = checked(&hf, e, None);
            let theirs =
                tin_spade(&hf, &TinOptions { max_error_m: e, max_triangles: None, ..TinOptions::default() }).unwrap();
            check_mesh(&hf, &theirs.mesh);
            let s = measure(&hf, &theirs.mesh);
            assert_eq!(s.max_error_m, theirs.max_error_m);
            assert!(s.max_error_m <= e);
            let (a, b) = (ours.mesh.triangles.len() as f64, theirs.mesh.triangles.len() as f64);
            assert!((a - b).abs() <= 0.05 * b + 4.0, "{a} vs {b}");
        }
        let limited = tin_spade(
            &noise(20, 20, 1, 100, 1.0),
            &TinOptions { max_error_m: 0.0, max_triangles: Some(50), ..TinOptions::default() },
        )
        .unwrap();
        assert!(limited.hit_triangle_limit && limited.mesh.triangles.len() <= 50);
    }

    #[test]
    fn proptest_regression_tiny_noise() {
        // Found by the proptest below while the heap's removal was broken.
        checked(&noise(3, 6, 1896575047789721511, 24, 0.5), 0.0, None);
    }

    #[test]
    fn deterministic() {
        let hf = crate::synth::fractal(129, 97, 1.0, 300.0, 0.55, 5);
        let a = checked(&hf, 1.0, None);
        let b = tin(&hf, &TinOptions { max_error_m: 1.0, max_triangles: None, ..TinOptions::default() }).unwrap();
        assert_eq!(a, b);
        // Looser bounds give fewer triangles.
        let c = checked(&hf, 10.0, None);
        assert!(c.mesh.triangles.len() < a.mesh.triangles.len());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        #[test]
        fn bound_holds_on_random_maps(
            w in 2usize..20,
            h in 2usize..20,
            seed in any::<u64>(),
            levels in 1u64..50,
            max_error_m in 0.0f64..20.0,
        ) {
            // Few distinct levels make ties and exactly planar patches likely.
            let hf = noise(w, h, seed, levels, 0.5);
            checked(&hf, max_error_m, None);
        }

        /// High-altitude decimetre heights (no f32 holds them) on cells that are not exact in f32:
        /// whenever the mesher accepts a bound, the surface as stored keeps it at every sample; when
        /// it refuses one, the storage really cannot meet it at a vertex.
        #[test]
        fn bound_holds_as_stored_on_high_altitude_maps(
            w in 2usize..24,
            h in 2usize..24,
            seed in any::<u64>(),
            base_dm in 80_000u64..90_000,
            relief_dm in 1u64..400,
            cell in prop_oneof![Just(1.0f64), Just(0.3), Just(30.87), Just(92.6), Just(3087.3), Just(927.7)],
            steps in prop_oneof![Just(1.5f64), Just(3.0), Just(10.0), Just(200.0), Just(2000.0)],
        ) {
            let heights: Vec<f64> = (0..w * h)
                .map(|k| (base_dm + crate::random::mix64(seed ^ k as u64) % relief_dm) as f64 * 0.1)
                .collect();
            let hf = Heightfield::from_f64(w, h, &heights, cell);
            // a bound of some f32 steps at these heights (~9.8e-4 m)
            let bound = steps * 0.5 * 9.765625e-4;
            match tin(&hf, &TinOptions { max_error_m: bound, max_triangles: None, ..TinOptions::default() }) {
                Ok(r) => {
                    check_mesh(&hf, &r.mesh);
                    let s = measure(&hf, &r.mesh);
                    prop_assert!(s.max_error_m <= bound, "{} > {bound}", s.max_error_m);
                    prop_assert_eq!(s.max_error_m, r.max_error_m);
                }
                Err(TerrainError::BelowStoragePrecision { achieved_m, .. }) => {
                    prop_assert!(achieved_m > bound);
                    // with cells exact in f32 a vertex is off by its height's rounding alone, in any
                    // triangulation: the full grid cannot meet it either
                    if cell == 1.0 {
                        let full = crate::terrain::grid::grid(&hf, 1).unwrap();
                        prop_assert!(measure(&hf, &full).max_error_m > bound);
                    }
                }
                Err(e) => prop_assert!(false, "{e}"),
            }
        }

        /// The same on a 16-bit position grid (`--quantize`): heights rounded to the grid's step,
        /// x and z by the cell in f32; accepted bounds hold for the quantized surface.
        #[test]
        fn bound_holds_on_the_quantized_grid(
            w in 2usize..24,
            h in 2usize..24,
            seed in any::<u64>(),
            relief_dm in 1u64..40_000,
            cell in prop_oneof![Just(1.0f64), Just(0.3), Just(30.87), Just(92.6), Just(3087.3), Just(927.7)],
            steps in prop_oneof![Just(0.6f64), Just(1.5), Just(4.0), Just(40.0)],
        ) {
            let heights: Vec<f64> = (0..w * h)
                .map(|k| (20_000 + crate::random::mix64(seed ^ k as u64) % relief_dm) as f64 * 0.1)
                .collect();
            let hf = Heightfield::from_f64(w, h, &heights, cell);
            let grid = crate::export::grid::PositionGrid::terrain(&hf, hf.height_range().unwrap().0).unwrap();
            let storage = Storage::quantized(&hf, grid);
            let bound = steps * grid.step[1] as f64;
            match tin_stored(&hf, &TinOptions { max_error_m: bound, max_triangles: None, ..TinOptions::default() }, &storage) {
                Ok(r) => {
                    check_mesh(&hf, &r.mesh);
                    let s = measure_stored(&hf, &r.mesh, &storage);
                    prop_assert!(s.max_error_m <= bound, "{} > {bound}", s.max_error_m);
                    prop_assert_eq!(s.max_error_m, r.max_error_m);
                }
                Err(TerrainError::BelowStoragePrecision { achieved_m, .. }) => prop_assert!(achieved_m > bound),
                Err(e) => prop_assert!(false, "{e}"),
            }
        }
    }
}
