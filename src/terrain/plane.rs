//! The height of the plane through a triangle's three samples at a sample inside it: the one
//! interpolation formula the mesher (`tin`), the analyzer (`error`) and the stored surface (`stored`)
//! share, so the errors they report agree to the last bit.

/// The plane through three samples evaluated at a fourth, the one formula the mesher and the
/// analyzer use. `w` are the integer barycentric weights (twice the signed sub-triangle areas, all ≥ 0
/// inside), `h` the corner heights and `area` = w[0] + w[1] + w[2] > 0. The corners must be given in
/// ascending sample index order so that the floating-point sum is evaluated in one canonical order
/// whichever way a triangle is stored; weights are exact integers, so the result is bit-identical
/// between callers.
#[inline(always)]
pub(crate) fn plane_height(w: [i64; 3], h: [f64; 3], area: i64) -> f64 {
    (w[0] as f64 * h[0] + w[1] as f64 * h[1] + w[2] as f64 * h[2]) / area as f64
}
