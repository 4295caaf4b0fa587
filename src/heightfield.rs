//! Heightmaps decoded into metres, and sampling of them.

/// A regular grid of heights in metres. Sample (i, j) — column i, row j — lies at
/// x = i·cell_size_m, z = j·cell_size_m, y = `heights[j * width + i]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Heightfield {
    pub width: usize,
    pub height: usize,
    /// Row-major heights in metres, `width * height` finite values.
    pub heights: Vec<f32>,
    pub cell_size_m: f64,
}

impl Heightfield {
    /// Height in metres at sample (i, j). Panics if out of range (callers index within bounds).
    #[inline]
    pub fn at(&self, i: usize, j: usize) -> f32 {
        self.heights[j * self.width + i]
    }

    /// World position of sample (i, j), the one place the axis contract is written down.
    #[inline]
    pub fn position(&self, i: usize, j: usize) -> [f32; 3] {
        [
            (i as f64 * self.cell_size_m) as f32,
            self.at(i, j),
            (j as f64 * self.cell_size_m) as f32,
        ]
    }

    /// Unit surface normal at sample (i, j) from the heights alone, in f64: n ∝ (−∂h/∂x, 1, −∂h/∂z)
    /// with central differences inside and one-sided differences on the border (a map one sample
    /// wide has zero slope along that axis). Taken from the samples, not from any triangulation, so
    /// shading does not show the mesh. Panics if (i, j) is out of range, like [`Heightfield::at`].
    pub fn normal_at(&self, i: usize, j: usize) -> [f64; 3] {
        // (lo, hi) neighbours along one axis, clamped to the map: central inside, one-sided at edges
        let span = |k: usize, n: usize| (k.saturating_sub(1), (k + 1).min(n.saturating_sub(1)));
        let (i0, i1) = span(i, self.width);
        let (j0, j1) = span(j, self.height);
        let slope = |a: f32, b: f32, steps: usize| {
            if steps == 0 {
                0.0
            } else {
                (b as f64 - a as f64) / (steps as f64 * self.cell_size_m)
            }
        };
        let dhdx = slope(self.at(i0, j), self.at(i1, j), i1 - i0);
        let dhdz = slope(self.at(i, j0), self.at(i, j1), j1 - j0);
        let len = (dhdx * dhdx + 1.0 + dhdz * dhdz).sqrt();
        [-dhdx / len, 1.0 / len, -dhdz / len]
    }
}
