//! sRGB transfer functions (IEC 61966-2-1): colours as authored (sRGB) to the linear values that
//! materials and shading use, and back.

/// The sRGB transfer function (IEC 61966-2-1) of a linear value in 0..1, in f32 (clamped; NaN → 0).
pub fn linear_to_srgb(v: f32) -> f32 {
    if v.is_nan() || v <= 0.0 {
        0.0
    } else if v >= 1.0 {
        1.0
    } else if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Inverse of [`linear_to_srgb`].
pub fn srgb_to_linear(v: f32) -> f32 {
    if v.is_nan() || v <= 0.0 {
        0.0
    } else if v >= 1.0 {
        1.0
    } else if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// [`srgb_to_linear`] of an f64 (a preset's number or `#rrggbb` digit pair), clamped to [0, 1] and
/// evaluated in f64, rounded to f32 only at the end: its last bit can differ from the f32 version's.
pub fn srgb_to_linear_f64(c: f64) -> f32 {
    let c = c.clamp(0.0, 1.0);
    (if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trips() {
        assert!((srgb_to_linear(linear_to_srgb(0.3)) - 0.3).abs() < 1e-6);
    }
}
