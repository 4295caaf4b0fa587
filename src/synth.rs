//! Procedural heightmaps: the project's own sample inputs (the `--demo` terrain, benchmark maps,
//! test fixtures), so nothing third-party has to ship with it.
//!
//! Fractal terrain by the diamond-square midpoint displacement of Fournier, Fussell & Carpenter
//! (1982), and fractional Brownian motion of gradient noise (Perlin 1985/2002) with Musgrave's
//! ridged multifractal variant ("Texturing & Modeling", ch. 16). Each random value is a hash of
//! (seed, lattice point), so a map does not depend on evaluation order or thread count.

use rayon::prelude::*;
use serde::Serialize;

use crate::heightfield::Heightfield;
use crate::random::mix64;

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
            let x0 = if (y / half).is_multiple_of(2) { half } else { 0 };
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
    // Synthetic heights are defined as their f32 values: no exact copy.
    Heightfield {
        width,
        height,
        heights: out.iter().map(|&v| ((v - lo) * scale) as f32).collect(),
        cell_size_m,
        exact: None,
    }
}

/// Which fractal sum of gradient noise [`noise_map`] builds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum NoiseKind {
    /// Fractional Brownian motion: rolling hills, rounded ridges and valleys alike.
    #[default]
    Fbm,
    /// Ridged multifractal: sharp crests, smoother valley floors (each octave weighted by the
    /// previous one, so detail gathers on the ridges) — alpine terrain.
    Ridged,
}

/// Octaves summed at most; finer ones than 2 samples per wavelength are skipped (they would only alias).
pub const NOISE_OCTAVES: u32 = 8;
/// The widest noise map (presets offer up to 8193 samples).
pub const MAX_NOISE_SIDE: usize = i32::MAX as usize;
const LACUNARITY: f64 = 2.0;
const GAIN: f64 = 0.5;

/// Eight unit gradient directions, 45° apart.
const GRADIENTS: [(f64, f64); 8] = [
    (1.0, 0.0),
    (std::f64::consts::FRAC_1_SQRT_2, std::f64::consts::FRAC_1_SQRT_2),
    (0.0, 1.0),
    (-std::f64::consts::FRAC_1_SQRT_2, std::f64::consts::FRAC_1_SQRT_2),
    (-1.0, 0.0),
    (-std::f64::consts::FRAC_1_SQRT_2, -std::f64::consts::FRAC_1_SQRT_2),
    (0.0, -1.0),
    (std::f64::consts::FRAC_1_SQRT_2, -std::f64::consts::FRAC_1_SQRT_2),
];

/// Quintic fade 6t⁵ − 15t⁴ + 10t³ (Perlin 2002): C² continuous across lattice cells.
#[inline]
fn fade(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// Gradient noise at (x, y) in lattice units, roughly in [−1, 1]; zero at lattice points. Maps
/// evaluate it a row at a time ([`octave_row`], the same arithmetic); this per-sample form is the
/// reference the tests hold that to.
#[cfg(test)]
fn gradient_noise(octave_seed: u64, x: f64, y: f64) -> f64 {
    let (xf, yf) = (x.floor(), y.floor());
    let (ix, iy) = (xf as i64, yf as i64);
    let (fx, fy) = (x - xf, y - yf);
    let corner = |cx: i64, cy: i64, dx: f64, dy: f64| {
        let h = mix64(octave_seed ^ mix64((cx as u64) << 32 ^ (cy as u64 & 0xFFFF_FFFF)));
        let (gx, gy) = GRADIENTS[(h >> 61) as usize];
        gx * dx + gy * dy
    };
    let n00 = corner(ix, iy, fx, fy);
    let n10 = corner(ix + 1, iy, fx - 1.0, fy);
    let n01 = corner(ix, iy + 1, fx, fy - 1.0);
    let n11 = corner(ix + 1, iy + 1, fx - 1.0, fy - 1.0);
    let (u, v) = (fade(fx), fade(fy));
    let a = n00 + u * (n10 - n00);
    let b = n01 + u * (n11 - n01);
    // 2-D gradient noise peaks at ±√2/2; scale to about ±1
    (a + v * (b - a)) * std::f64::consts::SQRT_2
}

/// One octave's seed and lattice offset (so octaves do not share their zero at the origin).
fn octave_params(seed: u64, octave: u32) -> (u64, f64, f64) {
    let s = mix64(seed ^ mix64(0x6f63_7461_7665 ^ octave as u64));
    let ox = (mix64(s ^ 1) >> 11) as f64 / (1u64 << 53) as f64 * 1024.0;
    let oy = (mix64(s ^ 2) >> 11) as f64 / (1u64 << 53) as f64 * 1024.0;
    (s, ox, oy)
}

/// One octave of a noise map: (seed, offset x, offset y, frequency, amplitude).
type Octave = (u64, f64, f64, f64, f64);

/// `x.floor()` for the lattice coordinates of a map (finite, within ±2⁶³): the same value, bit for
/// bit, without the library call (a baseline x86-64 build has no floor instruction; the noise
/// takes two per sample and octave otherwise).
#[inline]
fn floor_exact(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        // (the truncation's sign: −0.0 stays −0.0)
        t.copysign(x)
    }
}

/// One octave's [`gradient_noise`] along row `j` of a map, into `out` (one value per sample). What
/// depends on the row alone (its lattice row, the fade across it) is worked out once, and a
/// lattice cell's four corner gradients (four hashes) once per cell: the samples of a cell are a
/// run found from the cell's right edge, evaluated in a loop without branches. The arithmetic per
/// sample is [`gradient_noise`]'s, operation for operation, so the values are the same bits (a
/// test compares them).
fn octave_row(&(s, ox, oy, f, _): &Octave, j: usize, out: &mut [f64]) {
    let y = j as f64 * f + oy;
    let yf = floor_exact(y);
    let (fy, iy) = (y - yf, yf as i64);
    let v = fade(fy);
    let gradient =
        |cx: i64, cy: i64| GRADIENTS[(mix64(s ^ mix64((cx as u64) << 32 ^ (cy as u64 & 0xFFFF_FFFF))) >> 61) as usize];
    let x_of = |i: usize| i as f64 * f + ox;
    let n = out.len();
    let mut i = 0;
    while i < n {
        let xf = floor_exact(x_of(i));
        let ix = xf as i64;
        // the run: samples from i whose x is below the cell's right edge (x grows with i)
        let next = xf + 1.0;
        let mut end = ((next - ox) / f).max(0.0).min(n as f64) as usize;
        while end < n && x_of(end) < next {
            end += 1;
        }
        while end > i + 1 && x_of(end - 1) >= next {
            end -= 1;
        }
        let end = end.max(i + 1);
        let [(g00x, g00y), (g10x, g10y), (g01x, g01y), (g11x, g11y)] =
            [gradient(ix, iy), gradient(ix + 1, iy), gradient(ix, iy + 1), gradient(ix + 1, iy + 1)];
        // (the sample index through i32, which converts to f64 in one instruction: the same value,
        // [`MAX_NOISE_SIDE`] keeps it in range)
        let base = i as i32;
        for (k, o) in out[i..end].iter_mut().enumerate() {
            let fx = ((base + k as i32) as f64 * f + ox) - xf;
            let n00 = g00x * fx + g00y * fy;
            let n10 = g10x * (fx - 1.0) + g10y * fy;
            let n01 = g01x * fx + g01y * (fy - 1.0);
            let n11 = g11x * (fx - 1.0) + g11y * (fy - 1.0);
            let u = fade(fx);
            let a = n00 + u * (n10 - n00);
            let b = n01 + u * (n11 - n01);
            *o = (a + v * (b - a)) * std::f64::consts::SQRT_2;
        }
        i = end;
    }
}

/// Samples a parallel task of [`noise_map`]'s range and scaling takes.
const NORMALISE_BLOCK: usize = 1 << 16;

/// A `size` × `size` fractal map, heights in metres normalised to [0, `relief_m`]. The widest
/// octave spans half the map; each next one has twice the frequency (lacunarity 2) and half the
/// amplitude (gain 0.5), up to [`NOISE_OCTAVES`]. Rows are computed in parallel, each sample from
/// its own coordinates only, so the map is byte-identical for a seed at any thread count.
pub fn noise_map(kind: NoiseKind, size: usize, cell_size_m: f64, relief_m: f64, seed: u64) -> Heightfield {
    let side = size.max(1);
    let octaves = octave_table(side, seed);
    // The raw f64 samples are kept as pairs of 32-bit words in the buffer that then becomes the
    // f32 heights, in place: 8 bytes a sample at most, instead of the raw map (8) beside the
    // heights (4).
    let n = side * side;
    let mut words = vec![0u32; 2 * n];
    words.par_chunks_mut(2 * side).enumerate().for_each_init(
        || (vec![0.0f64; side], Vec::new()),
        |(raw, scratch), (j, row)| {
            raw_row(kind, &octaves, j, raw, scratch);
            for (pair, v) in row.chunks_exact_mut(2).zip(raw.iter()) {
                let bits = v.to_bits();
                pair[0] = bits as u32;
                pair[1] = (bits >> 32) as u32;
            }
        },
    );
    let pair = |p: &[u32]| f64::from_bits(p[0] as u64 | (p[1] as u64) << 32);
    // the range in parallel (min and max: the same at any split; a zero taken as +0)
    let none = (f64::INFINITY, f64::NEG_INFINITY);
    let (lo, hi) = words
        .par_chunks(2 * NORMALISE_BLOCK)
        .map(|c| c.chunks_exact(2).map(pair).fold(none, |(lo, hi), v| (lo.min(v), hi.max(v))))
        .reduce(|| none, |a, b| (a.0.min(b.0), a.1.max(b.1)));
    let (lo, hi) = (lo + 0.0, hi + 0.0);
    let scale = if hi > lo { relief_m / (hi - lo) } else { 0.0 };
    let height = |v: f64| ((((v - lo) * scale) as f32).clamp(0.0, relief_m as f32)).to_bits();
    // Height k goes to word k, which is read (as part of sample k / 2) before it is written: sample
    // k lies in words 2k and 2k + 1, never before word k. The first block in order; then samples
    // [a, 2a) in parallel, written to words [a, 2a) (samples before a, done) from words [2a, 4a)
    // (not written until the samples from 2a on are).
    let first = NORMALISE_BLOCK.min(n);
    for k in 0..first {
        words[k] = height(pair(&words[2 * k..2 * k + 2]));
    }
    let mut a = first;
    while a < n {
        let b = (2 * a).min(n);
        let (written, read) = words.split_at_mut(2 * a);
        written[a..b]
            .par_chunks_mut(NORMALISE_BLOCK)
            .zip(read[..2 * (b - a)].par_chunks(2 * NORMALISE_BLOCK))
            .for_each(|(out, raw)| out.iter_mut().zip(raw.chunks_exact(2)).for_each(|(w, p)| *w = height(pair(p))));
        a = b;
    }
    words.truncate(n);
    words.shrink_to_fit();
    // (u32 → f32 of the same size: the standard library collects this in the same allocation)
    let heights: Vec<f32> = words.into_iter().map(f32::from_bits).collect();
    Heightfield { width: side, height: side, heights, cell_size_m, exact: None }
}

/// The octaves of a `side`-sample map: (seed, offset x, offset y, frequency, amplitude).
fn octave_table(side: usize, seed: u64) -> Vec<Octave> {
    let base_wavelength = ((side - 1) as f64 / 2.0).max(1.0);
    let mut octaves = Vec::new();
    let (mut frequency, mut amplitude) = (1.0 / base_wavelength, 1.0);
    for o in 0..NOISE_OCTAVES {
        if o > 0 && frequency > 0.5 {
            break;
        }
        let (s, ox, oy) = octave_params(seed, o);
        octaves.push((s, ox, oy, frequency, amplitude));
        frequency *= LACUNARITY;
        amplitude *= GAIN;
    }
    octaves
}

/// Row `j`'s raw values (before the map is scaled to its relief) into `out` (one per sample): each
/// octave's row ([`octave_row`], into `scratch`) added into every sample's sum in turn: per
/// sample, the sum over its octaves in order that the kind makes (a test holds it to the
/// per-sample sums).
fn raw_row(kind: NoiseKind, octaves: &[Octave], j: usize, out: &mut [f64], scratch: &mut Vec<f64>) {
    let side = out.len();
    assert!(side <= MAX_NOISE_SIDE, "a noise map is at most {MAX_NOISE_SIDE} samples wide");
    // per sample: [sum, weight] (the ridged kind's weight from the previous octave)
    scratch.resize(2 * side, 0.0);
    let (noise, weights) = scratch.split_at_mut(side);
    match kind {
        NoiseKind::Fbm => {
            // (what `Iterator::sum` starts from)
            out.fill([0.0f64; 0].iter().sum());
            for octave in octaves {
                octave_row(octave, j, noise);
                let a = octave.4;
                for (sum, &n) in out.iter_mut().zip(noise.iter()) {
                    *sum += a * n;
                }
            }
        }
        NoiseKind::Ridged => {
            out.fill(0.0);
            weights.fill(1.0);
            for octave in octaves {
                octave_row(octave, j, noise);
                let a = octave.4;
                for ((sum, weight), &n) in out.iter_mut().zip(weights.iter_mut()).zip(noise.iter()) {
                    let r = 1.0 - n.abs();
                    let signal = r * r * *weight;
                    *weight = (signal * 2.0).clamp(0.0, 1.0);
                    *sum += signal * a;
                }
            }
        }
    }
}

/// Rows `rows[0]..=rows[1]` of [`noise_map`]'s map, the same heights bit for bit, holding only
/// those rows: the map's range, which scales every height, is found by a pass over every row that
/// keeps nothing (so this takes about as long as the whole map, in the memory of its rows).
/// `None` when the rows are not within the map.
pub fn noise_map_rows(
    kind: NoiseKind,
    size: usize,
    cell_size_m: f64,
    relief_m: f64,
    seed: u64,
    rows: [usize; 2],
) -> Option<Heightfield> {
    noise_rows(kind, size, cell_size_m, relief_m, seed, noise_range(kind, size, seed), rows)
}

/// The smallest and largest raw value of [`noise_map`]'s map (what scales it to its relief), by a
/// pass over every row that keeps nothing.
pub fn noise_range(kind: NoiseKind, size: usize, seed: u64) -> (f64, f64) {
    let side = size.max(1);
    let octaves = octave_table(side, seed);
    let (lo, hi) = (0..side)
        .into_par_iter()
        .map_init(
            || (vec![0.0f64; side], Vec::new()),
            |(row, scratch), j| {
                raw_row(kind, &octaves, j, row, scratch);
                row.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)))
            },
        )
        .reduce(|| (f64::INFINITY, f64::NEG_INFINITY), |a, b| (a.0.min(b.0), a.1.max(b.1)));
    // (a zero taken as +0, whichever sign the split met first, as [`noise_map`] takes it)
    (lo + 0.0, hi + 0.0)
}

/// Rows `rows[0]..=rows[1]` of [`noise_map`]'s map given its raw `range` ([`noise_range`]).
pub fn noise_rows(
    kind: NoiseKind,
    size: usize,
    cell_size_m: f64,
    relief_m: f64,
    seed: u64,
    (lo, hi): (f64, f64),
    rows: [usize; 2],
) -> Option<Heightfield> {
    let side = size.max(1);
    if rows[0] > rows[1] || rows[1] >= side {
        return None;
    }
    let octaves = octave_table(side, seed);
    let scale = if hi > lo { relief_m / (hi - lo) } else { 0.0 };
    let mut heights = vec![0.0f32; (rows[1] - rows[0] + 1) * side];
    heights.par_chunks_mut(side).enumerate().for_each_init(
        || (vec![0.0f64; side], Vec::new()),
        |(row, scratch), (k, out)| {
            raw_row(kind, &octaves, rows[0] + k, row, scratch);
            for (h, &v) in out.iter_mut().zip(row.iter()) {
                *h = (((v - lo) * scale) as f32).clamp(0.0, relief_m as f32);
            }
        },
    );
    Some(Heightfield { width: side, height: rows[1] - rows[0] + 1, heights, cell_size_m, exact: None })
}

/// Fractional Brownian motion of gradient noise: a `size` × `size` map in [0, `relief_m`] metres.
pub fn fbm(size: usize, cell_size_m: f64, relief_m: f64, seed: u64) -> Heightfield {
    noise_map(NoiseKind::Fbm, size, cell_size_m, relief_m, seed)
}

/// Ridged multifractal gradient noise: a `size` × `size` map in [0, `relief_m`] metres.
pub fn ridged(size: usize, cell_size_m: f64, relief_m: f64, seed: u64) -> Heightfield {
    noise_map(NoiseKind::Ridged, size, cell_size_m, relief_m, seed)
}

/// The embedded default terrain of `verdant terrain --demo`: 257 × 257 samples, 4 m apart, up to 300 m.
pub fn demo() -> Heightfield {
    fractal(257, 257, 4.0, 300.0, 0.45, 0x0076_6572_6461_6e74)
}

#[cfg(test)]
mod tests {

    #[test]
    fn rows_of_a_noise_map_made_alone_are_the_maps_rows_bit_for_bit() {
        for kind in [NoiseKind::Fbm, NoiseKind::Ridged] {
            let whole = noise_map(kind, 301, 2.0, 250.0, 17);
            for rows in [[0, 0], [0, 40], [120, 255], [299, 300], [300, 300]] {
                let part = noise_map_rows(kind, 301, 2.0, 250.0, 17, rows).unwrap();
                let expected = whole.rows(rows[0], rows[1]).unwrap();
                assert_eq!(part.heights.len(), expected.heights.len());
                assert!(
                    part.heights.iter().zip(&expected.heights).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{kind:?} rows {rows:?}"
                );
                assert_eq!(part, expected);
            }
            // a map scaled in several parallel waves (over 2 × 65536 samples)
            let big = noise_map(kind, 401, 1.5, 90.0, 5);
            for rows in [[0, 3], [163, 164], [326, 400]] {
                assert_eq!(noise_map_rows(kind, 401, 1.5, 90.0, 5, rows).unwrap(), big.rows(rows[0], rows[1]).unwrap());
            }
            assert!(noise_map_rows(kind, 301, 2.0, 250.0, 17, [10, 301]).is_none());
            assert!(noise_map_rows(kind, 301, 2.0, 250.0, 17, [11, 10]).is_none());
        }
    }
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

    #[test]
    fn fbm_is_deterministic_in_range_and_seeded() {
        for kind in [NoiseKind::Fbm, NoiseKind::Ridged] {
            let a = noise_map(kind, 129, 2.0, 400.0, 7);
            let b = noise_map(kind, 129, 2.0, 400.0, 7);
            let c = noise_map(kind, 129, 2.0, 400.0, 8);
            assert_eq!(a, b);
            assert_ne!(a, c);
            assert_eq!((a.width, a.height, a.heights.len()), (129, 129, 129 * 129));
            assert_eq!(a.cell_size_m, 2.0);
            let lo = a.heights.iter().cloned().fold(f32::INFINITY, f32::min);
            let hi = a.heights.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
            assert!(a.heights.iter().all(|h| h.is_finite()));
            assert!(lo == 0.0 && (hi - 400.0).abs() < 1e-3, "{kind:?}: {lo}..{hi}");
        }
    }

    /// The row-wise evaluation ([`octave_row`], [`raw_row`]) gives the bits the per-sample noise
    /// gives ([`gradient_noise`] at every octave, summed as the kinds sum), at every sample of rows
    /// far apart, across every lattice cell of every octave, and on maps of odd sizes whose cells
    /// end between samples.
    #[test]
    fn row_noise_is_the_per_sample_noise_bit_for_bit() {
        for (side, seed, rows) in [
            (8193usize, 77u64, vec![0usize, 1, 4095, 8191, 8192]),
            (1001, 5, vec![0, 333, 1000]),
            (37, 9, vec![0, 17, 36]),
            (2, 1, vec![0, 1]),
        ] {
            let octaves = octave_table(side, seed);
            if side == 8193 {
                assert_eq!(octaves.len(), NOISE_OCTAVES as usize, "every octave fits an 8193² map");
            }
            let mut scratch = Vec::new();
            for j in rows {
                let mut fbm_row = vec![0.0f64; side];
                let mut ridged_row = vec![0.0f64; side];
                raw_row(NoiseKind::Fbm, &octaves, j, &mut fbm_row, &mut scratch);
                raw_row(NoiseKind::Ridged, &octaves, j, &mut ridged_row, &mut scratch);
                let mut by_octave = vec![vec![0.0f64; side]; octaves.len()];
                for (octave, row) in octaves.iter().zip(&mut by_octave) {
                    octave_row(octave, j, row);
                }
                for i in 0..side {
                    let (x, y) = (i as f64, j as f64);
                    let reference: Vec<f64> =
                        octaves.iter().map(|&(s, ox, oy, f, _)| gradient_noise(s, x * f + ox, y * f + oy)).collect();
                    let values: Vec<f64> = by_octave.iter().map(|row| row[i]).collect();
                    assert_eq!(
                        values.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                        reference.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                        "side {side}: ({i}, {j})"
                    );
                    let fbm: f64 = octaves.iter().zip(&reference).map(|(&(.., a), &n)| a * n).sum();
                    assert_eq!(fbm_row[i].to_bits(), fbm.to_bits(), "side {side}: ({i}, {j})");
                    let (mut ridged, mut weight) = (0.0f64, 1.0f64);
                    for (&(.., a), &n) in octaves.iter().zip(&reference) {
                        let r = 1.0 - n.abs();
                        let signal = r * r * weight;
                        weight = (signal * 2.0).clamp(0.0, 1.0);
                        ridged += signal * a;
                    }
                    assert_eq!(ridged_row[i].to_bits(), ridged.to_bits(), "side {side}: ({i}, {j})");
                }
            }
        }
    }

    /// [`floor_exact`] is `floor` on the coordinates the noise takes, and on the awkward values
    /// around them (integers, just below and above, negative zero, halves).
    #[test]
    fn floor_exact_is_floor() {
        let mut xs = vec![0.0f64, -0.0, 0.5, -0.5, 1.0, -1.0, 1.0 - f64::EPSILON, 4096.0, 1e15 + 0.5, -1e15 - 0.5];
        let mut state = 3u64;
        for _ in 0..100_000 {
            state = mix64(state);
            let x = (state >> 11) as f64 / (1u64 << 53) as f64 * 20_000.0 - 10_000.0;
            xs.extend([x, x.floor(), x.floor() - f64::EPSILON * x.abs(), x.next_up(), x.next_down()]);
        }
        for x in xs {
            assert_eq!(floor_exact(x).to_bits(), x.floor().to_bits(), "{x:e}");
        }
    }

    #[test]
    fn fbm_is_independent_of_thread_count() {
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let a = one.install(|| fbm(257, 1.0, 100.0, 42));
        let b = fbm(257, 1.0, 100.0, 42);
        assert_eq!(a, b);
    }

    #[test]
    fn fbm_tiny_sizes_do_not_panic() {
        for size in [0, 1, 2, 3] {
            let hf = ridged(size, 1.0, 10.0, 1);
            assert!(hf.heights.iter().all(|h| h.is_finite() && (0.0..=10.0).contains(h)));
        }
    }
}
