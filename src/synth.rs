//! Procedural heightmaps: the project's own sample inputs (the `--demo` terrain, benchmark maps,
//! test fixtures), so nothing third-party has to ship with it.
//!
//! Fractal terrain by the diamond-square midpoint displacement of Fournier, Fussell & Carpenter
//! (1982). Each random offset is a hash of (seed, x, y), so the map does not depend on evaluation
//! order or thread count.

use crate::heightfield::Heightfield;

/// SplitMix64 finaliser: a well-mixed 64-bit hash.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Uniform value in [−1, 1) from a hash of `seed` and a lattice point.
#[inline]
fn signed_unit(seed: u64, x: usize, y: usize) -> f64 {
    let h = mix64(seed ^ mix64((x as u64) << 32 ^ y as u64));
    (h >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// A fractal heightfield of `width` × `height` samples, heights in metres in [0, `relief_m`].
/// `roughness` in (0, 1): how much each octave keeps of the previous one's amplitude (0.5 ≈ natural).
pub fn fractal(width: usize, height: usize, cell_size_m: f64, relief_m: f64, roughness: f64, seed: u64) -> Heightfield {
    let n = width.max(height).max(2);
    let mut size = 1usize;
    while size + 1 < n {
        size *= 2;
    }
    let side = size + 1;
    let mut h = vec![0.0f64; side * side];
    let idx = |x: usize, y: usize| y * side + x;
    // corners
    for &(x, y) in &[(0, 0), (size, 0), (0, size), (size, size)] {
        h[idx(x, y)] = signed_unit(seed, x, y);
    }
    let mut step = size;
    let mut amp = 1.0f64;
    while step > 1 {
        let half = step / 2;
        // diamond step: centres of squares
        for y in (half..side).step_by(step) {
            for x in (half..side).step_by(step) {
                let avg = (h[idx(x - half, y - half)]
                    + h[idx(x + half, y - half)]
                    + h[idx(x - half, y + half)]
                    + h[idx(x + half, y + half)])
                    / 4.0;
                h[idx(x, y)] = avg + amp * signed_unit(seed, x, y);
            }
        }
        // square step: edge midpoints, averaging the neighbours that exist
        for y in (0..side).step_by(half) {
            let x0 = if (y / half) % 2 == 0 { half } else { 0 };
            for x in (x0..side).step_by(step) {
                let mut sum = 0.0;
                let mut count = 0.0;
                if x >= half {
                    sum += h[idx(x - half, y)];
                    count += 1.0;
                }
                if x + half < side {
                    sum += h[idx(x + half, y)];
                    count += 1.0;
                }
                if y >= half {
                    sum += h[idx(x, y - half)];
                    count += 1.0;
                }
                if y + half < side {
                    sum += h[idx(x, y + half)];
                    count += 1.0;
                }
                h[idx(x, y)] = sum / count + amp * signed_unit(seed, x, y);
            }
        }
        amp *= roughness;
        step = half;
    }
    // crop and normalise to [0, relief_m]
    let mut out = Vec::with_capacity(width * height);
    for y in 0..height {
        out.extend_from_slice(&h[idx(0, y)..idx(0, y) + width]);
    }
    let lo = out.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = out.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let scale = if hi > lo { relief_m / (hi - lo) } else { 0.0 };
    Heightfield {
        width,
        height,
        heights: out.iter().map(|&v| ((v - lo) * scale) as f32).collect(),
        cell_size_m,
    }
}

/// The embedded default terrain of `verdant terrain --demo`: 257 × 257 samples, 4 m apart, up to 300 m.
pub fn demo() -> Heightfield {
    fractal(257, 257, 4.0, 300.0, 0.45, 0x7665_7264_616e_74)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fractal_is_deterministic_and_in_range() {
        let a = fractal(65, 33, 1.0, 100.0, 0.5, 7);
        let b = fractal(65, 33, 1.0, 100.0, 0.5, 7);
        let c = fractal(65, 33, 1.0, 100.0, 0.5, 8);
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert_eq!(a.heights.len(), 65 * 33);
        let lo = a.heights.iter().cloned().fold(f32::INFINITY, f32::min);
        let hi = a.heights.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
        assert!(lo >= 0.0 && hi <= 100.0 + 1e-3 && hi - lo > 50.0, "{lo}..{hi}");
    }

    #[test]
    fn demo_has_relief() {
        let d = demo();
        assert_eq!((d.width, d.height), (257, 257));
        assert!(d.heights.iter().all(|h| h.is_finite()));
    }
}
