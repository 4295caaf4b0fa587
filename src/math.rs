//! Small fixed-size vector maths on plain arrays (f64 for geometry, f32 where meshes store it), with
//! the exact arithmetic outputs were made with (divisions, not multiplications by a reciprocal).

/// a − b.
#[inline]
pub fn sub3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// a · b.
#[inline]
pub fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// a × b (right-handed).
#[inline]
pub fn cross3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// `a` scaled to unit length; `None` when its length is 0 or not finite.
#[inline]
pub fn normalize3(a: [f64; 3]) -> Option<[f64; 3]> {
    let len = dot3(a, a).sqrt();
    (len > 0.0 && len.is_finite()).then(|| a.map(|v| v / len))
}

/// a × b in f32.
#[inline]
pub fn cross3_f32(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// `v` scaled to unit length in f32; +Y when its length is 0 or not finite.
#[inline]
pub fn normalize3_f32_or_up(v: [f32; 3]) -> [f32; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if l > 0.0 && l.is_finite() {
        [v[0] / l, v[1] / l, v[2] / l]
    } else {
        [0.0, 1.0, 0.0]
    }
}
