//! Atlas post-processing: colour dilation into transparent texels by the exact Euclidean nearest
//! opaque texel (the separable distance transform with feature tracking of Felzenszwalb &
//! Huttenlocher, "Distance transforms of sampled functions", 2012), and mip chains that keep the
//! alpha-tested coverage of level 0 (Castaño, "Computing alpha mipmaps", 2010).
//!
//! Why both: bilinear filtering and mip-mapping average colour across the alpha edge, so texels
//! that are transparent must carry their visible neighbour's colour or a dark or light halo
//! appears; and averaging alpha thins alpha-tested foliage with distance (a 1-texel blade averages
//! to ½, below a ¾ cutoff, and vanishes) unless each level's alpha is rescaled to the coverage the
//! full-resolution texture has.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::bake::error::BakeError;
use crate::bake::image::Image;

/// Alpha below which a mip texel counts as empty when re-dilating: it encodes as 0 in 8 bits.
pub const MIP_DILATE_ALPHA_MIN: f32 = 0.5 / 255.0;

/// A normal-map texel of a surface facing the viewer: (0, 0, 1) encoded, alpha 0 (nothing drawn).
pub const FLAT_NORMAL: [f32; 4] = [0.5, 0.5, 1.0, 0.0];

/// The blitted normal views made a normal map: each drawn texel's (supersample-averaged) normal
/// renormalised, the gutters and empty texels given their nearest drawn texel's normal (as the
/// colour atlas is dilated, so filtering at a card's edge reads no foreign normal), alpha 1 (a
/// normal map's alpha means nothing in glTF; the colour atlas' alpha cuts the card out).
pub fn finish_normal_atlas(mut img: Image) -> Image {
    let mut drawn = false;
    for p in &mut img.pixels {
        if p[3] >= 0.5 {
            // the resolve averaged the supersamples' normals (weighted by coverage): unit length again
            let n = [0, 1, 2].map(|k| p[k].clamp(0.0, 1.0) * 2.0 - 1.0);
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            let n = if len > 1e-6 { n.map(|v| v / len) } else { [0.0, 0.0, 1.0] };
            *p = [n[0] * 0.5 + 0.5, n[1] * 0.5 + 0.5, n[2] * 0.5 + 0.5, p[3]];
            drawn = true;
        }
    }
    // every other texel takes its nearest drawn texel's normal (alpha is left as it was)
    dilate(&mut img, 0.5);
    for p in &mut img.pixels {
        if !drawn {
            *p = FLAT_NORMAL;
        }
        p[3] = 1.0;
    }
    img
}

/// Rows of no seed in [`dilate`]'s column pass.
const NO_SEED: u32 = u32::MAX;

/// Gives every texel with alpha < `alpha_min` the colour of the nearest texel (Euclidean distance
/// between texel centres, no wrapping) with alpha ≥ `alpha_min`; alpha is left unchanged. Ties go
/// the same way every run. An image without such a texel (or malformed) is left untouched.
/// Linear time: a column pass then a row pass (parallel over rows).
pub fn dilate(img: &mut Image, alpha_min: f32) {
    if !img.is_well_formed() {
        return;
    }
    let (w, h) = (img.width as usize, img.height as usize);
    let is_seed = |p: &[f32; 4]| p[3] >= alpha_min;
    if !img.pixels.iter().any(is_seed) {
        return;
    }
    // Column pass: for each texel, the row of the nearest seed in its column (down, then up).
    let mut near_row = vec![NO_SEED; w * h];
    let mut last = vec![NO_SEED; w];
    for y in 0..h {
        let row = &img.pixels[y * w..(y + 1) * w];
        for ((p, l), n) in row.iter().zip(last.iter_mut()).zip(&mut near_row[y * w..(y + 1) * w]) {
            if is_seed(p) {
                *l = y as u32;
            }
            *n = *l;
        }
    }
    last.fill(NO_SEED);
    let dist = |r: u32, y: usize| if r == NO_SEED { u64::MAX } else { (r as i64 - y as i64).unsigned_abs() };
    for y in (0..h).rev() {
        let row = &img.pixels[y * w..(y + 1) * w];
        for ((p, l), n) in row.iter().zip(last.iter_mut()).zip(&mut near_row[y * w..(y + 1) * w]) {
            if is_seed(p) {
                *l = y as u32;
            }
            // `n` holds the nearest seed at or above; take the one at or below when nearer.
            if dist(*l, y) < dist(*n, y) {
                *n = *l;
            }
        }
    }
    // Row pass: lower envelope of the parabolas (x − q)² + dy(q)² along each row; the parabola
    // that is lowest at x names the nearest seed's column q, whose nearest row we know.
    let mut nearest = vec![u32::MAX; w * h];
    nearest.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        let rows = &near_row[y * w..(y + 1) * w];
        let f = |q: usize| -> f64 {
            let dy = rows[q] as f64 - y as f64;
            dy * dy
        };
        let mut v: Vec<usize> = Vec::with_capacity(w); // columns of the envelope's parabolas
        let mut z: Vec<f64> = Vec::with_capacity(w + 1); // where each starts being lowest
        for (q, &row) in rows.iter().enumerate() {
            if row == NO_SEED {
                continue;
            }
            let fq = f(q) + (q * q) as f64;
            loop {
                let Some(&p) = v.last() else {
                    v.push(q);
                    z.push(f64::NEG_INFINITY);
                    break;
                };
                // Where parabola q becomes lower than parabola p.
                let s = (fq - (f(p) + (p * p) as f64)) / (2.0 * (q as f64 - p as f64));
                if s <= *z.last().unwrap_or(&f64::NEG_INFINITY) {
                    v.pop();
                    z.pop();
                } else {
                    v.push(q);
                    z.push(s);
                    break;
                }
            }
        }
        let mut k = 0;
        for (x, o) in out.iter_mut().enumerate() {
            while k + 1 < v.len() && z[k + 1] <= x as f64 {
                k += 1;
            }
            if let Some(&q) = v.get(k) {
                *o = rows[q] * w as u32 + q as u32;
            }
        }
    });
    for (k, &src) in nearest.iter().enumerate() {
        if src != u32::MAX && !is_seed(&img.pixels[k]) {
            let c = img.pixels[src as usize];
            let p = &mut img.pixels[k];
            *p = [c[0], c[1], c[2], p[3]];
        }
    }
}

/// Fraction of texels with alpha ≥ `cutoff` (0 for a malformed image).
pub fn coverage(img: &Image, cutoff: f32) -> f64 {
    if !img.is_well_formed() {
        return 0.0;
    }
    img.pixels.iter().filter(|p| p[3] >= cutoff).count() as f64 / img.pixels.len() as f64
}

/// One level of a mip chain.
#[derive(Debug, Clone, PartialEq)]
pub struct MipLevel {
    pub image: Image,
    /// Factor the box-filtered alpha was multiplied by (then clamped to 1); 1 for level 0.
    pub alpha_scale: f32,
    /// [`coverage`] of this level at the chain's cutoff.
    pub coverage: f64,
}

/// The next mip level by an area-weighted box filter: each side halves (rounded down, at least 1),
/// each new texel averaging the source area it covers (2 texels per axis, or 3 with weights for odd
/// sides), so mean alpha is preserved exactly. Colour is alpha-weighted (averaged as premultiplied,
/// then divided by alpha) so transparent texels do not darken the edge; where all weights have
/// alpha 0 the plain average is kept.
pub fn downsample_box(img: &Image) -> Image {
    if !img.is_well_formed() {
        return img.clone();
    }
    let (w, h) = (img.width as usize, img.height as usize);
    let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
    let wx = box_weights(w, nw);
    let wy = box_weights(h, nh);
    // Seven channels: premultiplied rgb, alpha, plain rgb.
    let expand = |p: &[f32; 4]| [p[0] * p[3], p[1] * p[3], p[2] * p[3], p[3], p[0], p[1], p[2]];
    // Horizontal pass into w' × h, then vertical into w' × h'.
    let mut tmp = vec![[0f32; 7]; nw * h];
    tmp.par_chunks_mut(nw).enumerate().for_each(|(y, row)| {
        for (x, out) in row.iter_mut().enumerate() {
            for &(sx, wt) in &wx[x] {
                let e = expand(&img.pixels[y * w + sx]);
                for c in 0..7 {
                    out[c] += wt * e[c];
                }
            }
        }
    });
    let mut pixels = vec![[0f32; 4]; nw * nh];
    pixels.par_chunks_mut(nw).enumerate().for_each(|(y, row)| {
        for (x, out) in row.iter_mut().enumerate() {
            let mut acc = [0f32; 7];
            for &(sy, wt) in &wy[y] {
                let e = &tmp[sy * nw + x];
                for c in 0..7 {
                    acc[c] += wt * e[c];
                }
            }
            let a = acc[3];
            *out =
                if a > 0.0 { [acc[0] / a, acc[1] / a, acc[2] / a, a.min(1.0)] } else { [acc[4], acc[5], acc[6], 0.0] };
        }
    });
    Image { width: nw as u32, height: nh as u32, pixels }
}

/// For each of `n_out` output texels, the source texels it overlaps and the share of its area
/// each covers (summing to 1).
fn box_weights(n_in: usize, n_out: usize) -> Vec<Vec<(usize, f32)>> {
    let scale = n_in as f64 / n_out as f64;
    (0..n_out)
        .map(|i| {
            let (lo, hi) = (i as f64 * scale, (i + 1) as f64 * scale);
            let mut taps = Vec::with_capacity(3);
            let mut s = lo.floor() as usize;
            while (s as f64) < hi && s < n_in {
                let overlap = (hi.min(s as f64 + 1.0) - lo.max(s as f64)).max(0.0);
                if overlap > 0.0 {
                    taps.push((s, (overlap / scale) as f32));
                }
                s += 1;
            }
            taps
        })
        .collect()
}

/// A mip level's size, alpha scale and coverage, as reports list them.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MipFigures {
    pub width: u32,
    pub height: u32,
    pub alpha_scale: f32,
    pub coverage: f64,
}

/// The figures of every level of a chain.
pub fn mip_figures(chain: &[MipLevel]) -> Vec<MipFigures> {
    chain
        .iter()
        .map(|m| MipFigures {
            width: m.image.width,
            height: m.image.height,
            alpha_scale: m.alpha_scale,
            coverage: m.coverage,
        })
        .collect()
}

/// The mip chain of `level0` down to 1×1. Level 0 is the input (dilate it first) with alpha
/// rounded to 8-bit steps (q/255), as the PNG will store it and as every level is. Each further
/// level is the area-weighted box filter of the previous (unscaled) one; then its alpha is
/// multiplied by the scale whose alpha-tested coverage at `cutoff` comes closest to level 0's
/// (Castaño 2010, found by bisection; see [`coverage_scale`]), clamped to 1 and rounded to 8-bit
/// steps, so the coverage reported is the coverage the file has; then transparent texels are
/// re-dilated ([`MIP_DILATE_ALPHA_MIN`]). A malformed input gives an empty chain.
pub fn mip_chain(level0: &Image, cutoff: f32) -> Vec<MipLevel> {
    if !level0.is_well_formed() {
        return Vec::new();
    }
    // Level 0 as its PNG will hold it: the coverage to keep is the file's.
    let mut base = level0.clone();
    for p in &mut base.pixels {
        p[3] = quantized_alpha(p[3], 1.0);
    }
    let target = coverage(&base, cutoff);
    let mut filtered = base.clone();
    let mut levels = vec![MipLevel { image: base, alpha_scale: 1.0, coverage: target }];
    while filtered.width > 1 || filtered.height > 1 {
        filtered = downsample_box(&filtered);
        let scale = coverage_scale(&filtered, cutoff, target);
        let mut image = filtered.clone();
        for p in &mut image.pixels {
            p[3] = quantized_alpha(p[3], scale);
        }
        dilate(&mut image, MIP_DILATE_ALPHA_MIN);
        let level_coverage = coverage(&image, cutoff);
        levels.push(MipLevel { image, alpha_scale: scale, coverage: level_coverage });
    }
    levels
}

/// min(1, alpha · scale) rounded to the nearest of the 256 values 8 bits store.
#[inline]
fn quantized_alpha(alpha: f32, scale: f32) -> f32 {
    crate::bake::raster::png::to_u8(alpha * scale) as f32 / 255.0
}

/// Plain box-filtered mips (no coverage preservation), for comparison: level 0 first.
pub fn box_mip_chain(level0: &Image) -> Vec<Image> {
    if !level0.is_well_formed() {
        return Vec::new();
    }
    let mut chain = vec![level0.clone()];
    while let Some(last) = chain.last().filter(|l| l.width > 1 || l.height > 1) {
        let next = downsample_box(last);
        chain.push(next);
    }
    chain
}

/// Averages `factor`×`factor` blocks (alpha-weighted colour, as [`downsample_box`]): turns a render
/// made at `factor` times the resolution into an image with anti-aliased (fractional) alpha, which
/// is what lets [`mip_chain`] match level 0's coverage closely (a hard 0/1 alpha gives 2×2 averages
/// in steps of ¼, and one scale cannot split texels of equal alpha). Sides not divisible by
/// `factor` are rounded up, the missing samples counting as transparent.
pub fn resolve_supersampled(img: &Image, factor: u32) -> Image {
    let f = factor.max(1) as usize;
    if !img.is_well_formed() || f == 1 {
        return img.clone();
    }
    let (w, h) = (img.width as usize, img.height as usize);
    let (nw, nh) = (w.div_ceil(f), h.div_ceil(f));
    let n = (f * f) as f32;
    let mut pixels = vec![[0f32; 4]; nw * nh];
    pixels.par_chunks_mut(nw).enumerate().for_each(|(oy, row)| {
        for (ox, out) in row.iter_mut().enumerate() {
            let (mut pre, mut plain, mut alpha) = ([0f32; 3], [0f32; 3], 0f32);
            for y in oy * f..((oy + 1) * f).min(h) {
                for x in ox * f..((ox + 1) * f).min(w) {
                    let p = img.pixels[y * w + x];
                    for c in 0..3 {
                        pre[c] += p[c] * p[3];
                        plain[c] += p[c];
                    }
                    alpha += p[3];
                }
            }
            *out = if alpha > 0.0 {
                [pre[0] / alpha, pre[1] / alpha, pre[2] / alpha, (alpha / n).min(1.0)]
            } else {
                [plain[0] / n, plain[1] / n, plain[2] / n, 0.0]
            };
        }
    });
    Image { width: nw as u32, height: nh as u32, pixels }
}

/// The alpha scale s for which the fraction of texels whose stored alpha (min(1, s·alpha) in 8
/// bits) is ≥ `cutoff` comes closest to `target`. The passing count is a step function of s:
/// bisection on log2 s finds the steps on either side of the target, the closer count wins, and s
/// is then taken from the middle (geometrically) of the range of scales giving that count, so the
/// texels nearest the cutoff stay as far from it as they can on both sides; 1 when 1 gives it.
pub fn coverage_scale(img: &Image, cutoff: f32, target: f64) -> f32 {
    if cutoff.is_nan() || cutoff <= 0.0 || !img.is_well_formed() {
        // Every texel passes whatever the scale (or there is nothing to scale).
        return 1.0;
    }
    let mut alphas: Vec<f32> = img.pixels.iter().map(|p| if p[3].is_nan() { 0.0 } else { p[3] }).collect();
    alphas.sort_by(f32::total_cmp);
    // Texels passing at scale s: a suffix of the ascending alphas (quantising is monotone).
    let passing = |s: f32| alphas.len() - alphas.partition_point(|&a| quantized_alpha(a, s) < cutoff);
    let s_of = |e: f64| e.exp2() as f32;
    const LOG2_RANGE: f64 = 24.0;
    // Bisection on log2 s: (largest found passing fewer than `count`, smallest found passing at
    // least `count`); None for a side the range [2^-24, 2^24] does not reach.
    let bracket = |count: f64| -> (Option<f64>, Option<f64>) {
        let (mut lo, mut hi) = (-LOG2_RANGE, LOG2_RANGE);
        if passing(s_of(lo)) as f64 >= count {
            return (None, Some(lo));
        }
        if (passing(s_of(hi)) as f64) < count {
            return (Some(hi), None);
        }
        while hi - lo > 1e-7 {
            let mid = 0.5 * (lo + hi);
            if passing(s_of(mid)) as f64 >= count {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        (Some(lo), Some(hi))
    };
    let wanted = target * alphas.len() as f64;
    let (lo, hi) = bracket(wanted);
    let best = match (lo.map(|e| passing(s_of(e))), hi.map(|e| passing(s_of(e)))) {
        (Some(below), Some(above)) => {
            if above as f64 - wanted <= wanted - below as f64 {
                above
            } else {
                below
            }
        }
        (Some(below), None) => below,
        (None, Some(above)) => above,
        (None, None) => return 1.0,
    };
    if passing(1.0) == best {
        return 1.0;
    }
    // The range of log2 s giving `best`: from where it is reached to where more pass (at most a
    // factor 4 wide, so a scale with nothing above it does not saturate everything).
    let start = bracket(best as f64).1.unwrap_or(-LOG2_RANGE);
    let end = bracket(best as f64 + 1.0).0.unwrap_or(LOG2_RANGE).min(start + 2.0);
    s_of(0.5 * (start + end))
}

/// Writes the chain as `<stem>.png` (level 0) and `<stem>_mip<k>.png` (level k ≥ 1) into `dir`,
/// each atomically; returns the paths in level order.
pub fn write_mip_pngs(dir: &Path, stem: &str, levels: &[MipLevel]) -> Result<Vec<PathBuf>, BakeError> {
    let plain = !stem.is_empty()
        && stem != "."
        && stem != ".."
        && !stem.contains(['/', '\\'])
        && Path::new(stem).components().count() == 1;
    if !plain {
        return Err(BakeError::BadStem { stem: stem.to_string() });
    }
    // encoded and written in parallel (the first level is most of the work)
    levels
        .par_iter()
        .enumerate()
        .map(|(k, level)| {
            let name = if k == 0 { format!("{stem}.png") } else { format!("{stem}_mip{k}.png") };
            let path = dir.join(name);
            level.image.write_png(&path)?;
            Ok(path)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_weights_cover_the_source_once() {
        for (n_in, n_out) in [(8, 4), (7, 3), (5, 2), (3, 1), (1, 1), (2, 1)] {
            let w = box_weights(n_in, n_out);
            let mut per_source = vec![0.0f64; n_in];
            for taps in &w {
                let sum: f32 = taps.iter().map(|t| t.1).sum();
                assert!((sum - 1.0).abs() < 1e-6, "{n_in}→{n_out}");
                for &(s, wt) in taps {
                    per_source[s] += wt as f64 * n_in as f64 / n_out as f64;
                }
            }
            assert!(per_source.iter().all(|&v| (v - 1.0).abs() < 1e-5), "{n_in}→{n_out}: {per_source:?}");
        }
    }

    #[test]
    fn odd_and_non_square_chains_end_at_one_texel_and_keep_mean_alpha() {
        let mut img = Image::new(13, 6, [0.0; 4]).unwrap();
        for (k, p) in img.pixels.iter_mut().enumerate() {
            *p = [0.2, 0.4, 0.6, ((k * 7) % 11) as f32 / 10.0];
        }
        let chain = box_mip_chain(&img);
        let sizes: Vec<(u32, u32)> = chain.iter().map(|l| (l.width, l.height)).collect();
        assert_eq!(sizes, vec![(13, 6), (6, 3), (3, 1), (1, 1)]);
        let mean = |i: &Image| i.pixels.iter().map(|p| p[3] as f64).sum::<f64>() / i.pixels.len() as f64;
        for l in &chain {
            assert!((mean(l) - mean(&img)).abs() < 1e-5);
            // a uniform colour stays that colour under alpha weighting
            assert!(l.pixels.iter().all(|p| (p[0] - 0.2).abs() < 1e-6 && (p[2] - 0.6).abs() < 1e-6));
        }
        assert_eq!(mip_chain(&img, 0.5).len(), 4);
    }

    #[test]
    fn alpha_weighted_filtering_ignores_transparent_colour() {
        // Opaque green next to transparent black: the average is green, not dark green.
        let img = Image { width: 2, height: 1, pixels: vec![[0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0]] };
        let m = downsample_box(&img);
        assert_eq!(m.pixels, vec![[0.0, 1.0, 0.0, 0.5]]);
    }

    #[test]
    fn resolving_a_supersampled_render_averages_blocks_by_alpha() {
        // 5×2 at factor 2: blocks of 2×2, the last column a partial block (missing = transparent).
        let red = [1.0, 0.0, 0.0, 1.0];
        let clear = [0.0, 0.0, 1.0, 0.0];
        let img = Image { width: 5, height: 2, pixels: vec![red, clear, red, red, red, clear, clear, red, red, red] };
        let r = resolve_supersampled(&img, 2);
        assert_eq!((r.width, r.height), (3, 1));
        // colour from the covered samples only; alpha the covered share of the 4 samples
        assert_eq!(r.pixels[0], [1.0, 0.0, 0.0, 0.25]);
        assert_eq!(r.pixels[1], [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(r.pixels[2], [1.0, 0.0, 0.0, 0.5]);
        assert_eq!(resolve_supersampled(&img, 1), img);
    }

    #[test]
    fn coverage_scale_hits_the_target_count_and_stays_clear_of_the_cutoff() {
        // Alphas 0.01, 0.02, …, 1.00: a target of 30 % means the 30 largest pass at 0.5 cutoff.
        let img =
            Image { width: 100, height: 1, pixels: (1..=100).map(|k| [0.0, 0.0, 0.0, k as f32 / 100.0]).collect() };
        let s = coverage_scale(&img, 0.5, 0.3);
        let passing = img.pixels.iter().filter(|p| quantized_alpha(p[3], s) >= 0.5).count();
        assert_eq!(passing, 30);
        // mid-range: scales from 0.5/0.71 to 0.5/0.70 give 30; the one chosen keeps the 30th alpha
        // (0.71) and the 31st (0.70) about 0.7 % either side of the cutoff, not on it
        assert!(0.71 * s > 0.5 * 1.005 && 0.70 * s < 0.5 * 0.995, "{s}");
        // already right at scale 1: kept
        assert_eq!(coverage_scale(&img, 0.5, 0.51), 1.0);
    }

    #[test]
    fn stems_with_folders_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        for bad in ["", "..", "a/b", "a\\b"] {
            assert!(matches!(write_mip_pngs(dir.path(), bad, &[]), Err(BakeError::BadStem { .. })), "{bad:?}");
        }
    }
}
