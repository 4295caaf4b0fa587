//! The terrain as the written file holds it: every vertex at its sample's position rounded to
//! 32-bit floats (x = i·cell, y = the height, z = j·cell), or on a 16-bit grid (`--quantize`,
//! KHR_mesh_quantization), and the vertical error of that surface measured against the map's
//! reference heights (the values its encoding defines, in f64).
//!
//! The mesher's own measure works on the f32 heights in the (i, j) plane; the stored measure can
//! exceed it by the rounding of the heights (half an ulp: 3·10⁻⁵ m at 1 km, 5·10⁻⁴ m at 8 km) and, on
//! cells that are not exact in f32, by the slope times the rounding of x and z. [`Storage`] bounds
//! that difference per face, so only faces within it of the bound are measured again as stored
//! ([`Storage::scan`]); the mesher refines until the stored measure is within the bound.

use crate::export::grid::PositionGrid;
use crate::heightfield::Heightfield;
use crate::terrain::plane::plane_height;

/// The terrain's [`PositionGrid`]: built here, where the heightfield is known (the grid itself is the
/// writer's, `export::grid`).
impl PositionGrid {
    /// The grid of a terrain over `hf` whose lowest stored point is `lowest_m` (the lowest sample,
    /// or a skirt's or base's bottom below it); `None` when the map is too wide for 16 bits.
    pub fn terrain(hf: &Heightfield, lowest_m: f32) -> Option<PositionGrid> {
        if hf.width > 65536 || hf.height > 65536 {
            return None;
        }
        let highest = hf.height_range()?.1.max(lowest_m);
        let cell = hf.cell_size_m as f32;
        // the step rounds up, so the highest point's integer stays within 65,535
        let range = highest as f64 - lowest_m as f64;
        // a flat map still needs a scale an engine can invert
        let step_y = if range > 0.0 { ((range / 65535.0) as f32).next_up() } else { 1.0 };
        Some(PositionGrid { origin: [0.0, lowest_m, 0.0], step: [cell, step_y, cell] })
    }
}

/// Where the file puts the samples, and how far that can move the surface from the mesher's.
#[derive(Debug, Clone)]
pub struct Storage {
    /// Stored x of column i and z of row j (exact values of what the file holds).
    xs: Vec<f64>,
    zs: Vec<f64>,
    /// Nominal x of column i (i·cell), the place each sample is measured at.
    cell_size_m: f64,
    /// Every stored x and z equals i·cell and j·cell exactly: the plane can be evaluated with the
    /// canonical integer weights.
    xz_exact: bool,
    /// Heights on a 16-bit grid, or as f32 (`None`).
    grid: Option<PositionGrid>,
    /// Largest horizontal distance between a stored vertex and its sample, metres.
    pub xz_shift_m: f64,
    /// Largest |reference − f32| height over all samples, metres.
    pub height_shift_m: f64,
    /// Largest |stored − f32| vertex height over all samples (the quantization), metres.
    pub vertex_shift_m: f64,
}

impl Storage {
    /// Positions as 32-bit floats, as every writer stores them by default.
    pub fn f32(hf: &Heightfield) -> Storage {
        let cell = hf.cell_size_m;
        let axis = |n: usize| -> Vec<f64> { (0..n).map(|i| (i as f64 * cell) as f32 as f64).collect() };
        Storage::new(hf, axis(hf.width), axis(hf.height), None)
    }

    /// Positions on a 16-bit grid (`--quantize`): x, z and heights as the grid stores them.
    pub fn quantized(hf: &Heightfield, grid: PositionGrid) -> Storage {
        let axis = |n: usize, a: usize| -> Vec<f64> { (0..n).map(|i| grid.dequantize(a, i as i64)).collect() };
        Storage::new(hf, axis(hf.width, 0), axis(hf.height, 2), Some(grid))
    }

    fn new(hf: &Heightfield, xs: Vec<f64>, zs: Vec<f64>, grid: Option<PositionGrid>) -> Storage {
        let cell = hf.cell_size_m;
        let shift = |v: &[f64]| v.iter().enumerate().fold(0.0f64, |m, (i, &x)| m.max((x - i as f64 * cell).abs()));
        let xz_shift_m = shift(&xs).max(shift(&zs));
        let mut s = Storage {
            xs,
            zs,
            cell_size_m: cell,
            xz_exact: xz_shift_m == 0.0,
            grid,
            xz_shift_m,
            height_shift_m: hf.rounding_m(),
            vertex_shift_m: 0.0,
        };
        if grid.is_some() {
            s.vertex_shift_m = hf.heights.iter().fold(0.0f64, |m, &h| m.max((s.stored_y(h) - h as f64).abs()));
        }
        s
    }

    /// The height the file stores for a vertex whose f32 height is `h`.
    #[inline]
    pub fn stored_y(&self, h: f32) -> f64 {
        match &self.grid {
            None => h as f64,
            Some(g) => g.dequantize(1, g.quantize(1, h)),
        }
    }

    /// Distance between neighbouring stored heights near `h`, and what sets it.
    pub fn height_step(&self, h: f64) -> (f64, &'static str) {
        match &self.grid {
            None => {
                let f = (h as f32).abs();
                ((f.next_up() - f) as f64, "32-bit floats")
            }
            Some(g) => (g.step[1] as f64, "16-bit quantized positions (--quantize)"),
        }
    }

    /// True when the stored measure is the mesher's own (exact heights, exact x and z): nothing to
    /// check again.
    pub fn is_exact(&self) -> bool {
        self.xz_exact && self.height_shift_m == 0.0 && self.vertex_shift_m == 0.0
    }

    /// Every stored x and z is exactly i·cell and j·cell.
    pub fn xz_exact(&self) -> bool {
        self.xz_exact
    }

    /// [`Storage::xz_exact`] of [`Storage::f32`] for a `width` × `height` map of `cell_size_m`
    /// cells, from its size alone.
    pub fn f32_xz_exact(width: usize, height: usize, cell_size_m: f64) -> bool {
        (0..width.max(height)).all(|i| (i as f64 * cell_size_m) as f32 as f64 == i as f64 * cell_size_m)
    }

    /// Stored height of the triangle `c` (corners as (i, j) in ascending sample index order, `hc`
    /// their stored heights) at sample `p`'s nominal place: the one formula the mesher's re-check
    /// and the analyzer share. With exact x and z it is [`plane_height`] itself.
    #[inline]
    pub(crate) fn height_at(&self, c: [[i64; 2]; 3], hc: [f64; 3], p: [i64; 2]) -> f64 {
        if self.xz_exact {
            let sign = orient(c[0], c[1], c[2]).signum();
            let w = [orient(c[1], c[2], p) * sign, orient(c[2], c[0], p) * sign, orient(c[0], c[1], p) * sign];
            return plane_height(w, hc, w[0] + w[1] + w[2]);
        }
        let x = |k: usize| self.xs[c[k][0] as usize];
        let z = |k: usize| self.zs[c[k][1] as usize];
        let (px, pz) = (p[0] as f64 * self.cell_size_m, p[1] as f64 * self.cell_size_m);
        let (x1, z1, x2, z2) = (x(1) - x(0), z(1) - z(0), x(2) - x(0), z(2) - z(0));
        let (dx, dz) = (px - x(0), pz - z(0));
        let d = x1 * z2 - x2 * z1;
        let l1 = (dx * z2 - x2 * dz) / d;
        let l2 = (x1 * dz - dx * z1) / d;
        hc[0] + l1 * (hc[1] - hc[0]) + l2 * (hc[2] - hc[0])
    }

    /// How much the stored error of a face can exceed the mesher's (f32 heights at the nominal
    /// places, in the (i, j) plane) at any of its samples, `hc` being the corners' f32 heights.
    /// With P′ the plane through the stored vertices (X′ₖ = xₖ + δₖ, Y′ₖ) and P″ the one through the
    /// stored heights at the nominal places, P′(x) − P″(x) = −Σ λₖ g′·δₖ exactly (λ the barycentric
    /// weights of x, in [0, 1] inside, g′ the stored triangle's gradient), and |P″ − P| ≤ the largest
    /// |Y′ − h| of a vertex; the sample's own reference is within the heights' rounding of h. So: the
    /// heights' rounding + the vertices' + (|g′x| + |g′z|) · the largest horizontal shift, plus f64
    /// rounding.
    pub(crate) fn margin(&self, c: [[i64; 2]; 3], hc: [f64; 3]) -> f64 {
        let magnitude = hc.iter().fold(0.0f64, |m, h| m.max(h.abs()));
        let mut m = self.height_shift_m + self.vertex_shift_m + 1e-9 * (1.0 + magnitude);
        if !self.xz_exact {
            let x = |k: usize| self.xs[c[k][0] as usize];
            let z = |k: usize| self.zs[c[k][1] as usize];
            let y = |k: usize| self.stored_y(hc[k] as f32);
            let (x1, z1, y1) = (x(1) - x(0), z(1) - z(0), y(1) - y(0));
            let (x2, z2, y2) = (x(2) - x(0), z(2) - z(0), y(2) - y(0));
            let d = x1 * z2 - x2 * z1;
            // gradient of the stored plane: y = y0 + gx·(x − x0) + gz·(z − z0)
            let gx = (y1 * z2 - y2 * z1) / d;
            let gz = (x1 * y2 - x2 * y1) / d;
            // twice the first-order bound: the products and the division round too
            m += 2.0 * (gx.abs() + gz.abs()) * self.xz_shift_m;
            if !m.is_finite() {
                return f64::INFINITY;
            }
        }
        m
    }

    /// Scans a face as stored: the worst sample that is not a corner (error, i, j) if above `floor`,
    /// and the largest error of all its samples, corners included. Rows are walked over the span
    /// the three edge functions allow (exact integer bounds), in sample order.
    pub(crate) fn scan(&self, hf: &Heightfield, mut c: [[i64; 2]; 3], floor: f64) -> (Option<(f64, u32, u32)>, f64) {
        c.sort_unstable_by_key(|p| (p[1], p[0]));
        let w = hf.width;
        let hc = c.map(|p| self.stored_y(hf.at(p[0] as usize, p[1] as usize)));
        let sign = orient(c[0], c[1], c[2]).signum();
        if sign == 0 {
            return (None, 0.0);
        }
        let area = orient(c[0], c[1], c[2]) * sign;
        // edge k's function at (i, j) is a[k]·i + b[k]·j + k0[k], ≥ 0 inside (times `sign`)
        let edges = [(c[1], c[2]), (c[2], c[0]), (c[0], c[1])];
        let coef = edges.map(|(p, q)| {
            let a = -(q[1] - p[1]) * sign;
            let b = (q[0] - p[0]) * sign;
            (a, b, -(a * p[0] + b * p[1]))
        });
        let (xmin, xmax) = (c.iter().map(|p| p[0]).min().unwrap_or(0), c.iter().map(|p| p[0]).max().unwrap_or(0));
        let (mut best, mut found, mut all) = (floor, None, 0.0f64);
        for j in c[0][1]..=c[2][1] {
            let (mut lo, mut hi) = (xmin, xmax);
            for &(a, b, k0) in &coef {
                let r = b * j + k0; // a·i + r ≥ 0
                if a > 0 {
                    lo = lo.max((-r).div_euclid(a) + ((-r).rem_euclid(a) != 0) as i64);
                } else if a < 0 {
                    hi = hi.min(r.div_euclid(-a));
                } else if r < 0 {
                    hi = lo - 1;
                }
            }
            for i in lo..=hi {
                let p = [i, j];
                let surface = if self.xz_exact {
                    let wt = coef.map(|(a, b, k0)| a * i + b * j + k0);
                    plane_height(wt, hc, area)
                } else {
                    self.height_at(c, hc, p)
                };
                let err = (surface - hf.reference(j as usize * w + i as usize)).abs();
                all = all.max(err);
                if err > best && !c.contains(&p) {
                    best = err;
                    found = Some((err, i as u32, j as u32));
                }
            }
        }
        (found, all)
    }
}

/// Twice the signed area of (a, b, p) in the (i, j) plane.
#[inline]
fn orient(a: [i64; 2], b: [i64; 2], p: [i64; 2]) -> i64 {
    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(cell: f64, heights: Vec<f64>, w: usize) -> Heightfield {
        let h = heights.len() / w;
        Heightfield::from_f64(w, h, &heights, cell)
    }

    #[test]
    fn exact_heights_and_cells_need_no_second_measure() {
        let hf = field(10.0, vec![0.0, 1.0, 2.0, 3.0], 2);
        let s = Storage::f32(&hf);
        assert!(s.is_exact(), "{s:?}");
        assert_eq!(s.xz_shift_m, 0.0);
    }

    #[test]
    fn decimetre_heights_and_inexact_cells_are_measured_as_stored() {
        // 1023.7 m is no f32; 0.1 m cells are not exact in f32 either.
        let hf = field(0.1, vec![1023.7, 1023.8, 1023.9, 1024.1], 2);
        let s = Storage::f32(&hf);
        assert!(!s.is_exact());
        assert!(s.height_shift_m > 0.0 && s.height_shift_m < 3.1e-5, "{}", s.height_shift_m);
        assert!(s.xz_shift_m > 0.0 && s.xz_shift_m < 1e-8, "{}", s.xz_shift_m);
        // a corner's stored error is its height's rounding
        let (_, all) = s.scan(&hf, [[0, 0], [1, 0], [1, 1]], 0.0);
        assert!(all > 0.0 && all <= s.margin([[0, 0], [1, 0], [1, 1]], [1023.7, 1023.8, 1024.1]), "{all}");
    }

    #[test]
    fn the_stored_plane_with_exact_cells_is_the_canonical_one() {
        let hf = field(2.0, vec![1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0, 256.0], 3);
        let s = Storage::f32(&hf);
        let c = [[0, 0], [2, 0], [0, 2]];
        let hc = [1.0, 4.0, 64.0];
        // weights at (1, 0): 1 of corner 0, 1 of corner 1 over an area of 4, i.e. (2·1 + 2·4)/4
        assert_eq!(s.height_at(c, hc, [1, 0]), 2.5);
        assert_eq!(s.height_at(c, hc, [0, 0]), 1.0);
    }
}
