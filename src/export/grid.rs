//! The 16-bit position grid of KHR_mesh_quantization: which integer a stored coordinate becomes and
//! where the file's node transform puts it back.

/// A 16-bit position grid (KHR_mesh_quantization): a vertex is stored as integers q, and the file's
/// node transform puts it at `origin + step·q` (per axis). For a terrain, x and z step by the cell
/// (q = i, j: exact) and y by the height range over 65,535.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionGrid {
    pub origin: [f32; 3],
    pub step: [f32; 3],
}

impl PositionGrid {
    /// The integer a coordinate is stored as on `axis`.
    #[inline]
    pub fn quantize(&self, axis: usize, v: f32) -> i64 {
        ((v as f64 - self.origin[axis] as f64) / self.step[axis] as f64).round() as i64
    }

    /// What the file holds for integer `q` on `axis`: origin + step·q, exactly (f64).
    #[inline]
    pub fn dequantize(&self, axis: usize, q: i64) -> f64 {
        self.origin[axis] as f64 + self.step[axis] as f64 * q as f64
    }
}
