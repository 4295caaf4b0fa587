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
}
