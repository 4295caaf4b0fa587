//! Image error between two renders of the same view: alpha-coverage IoU, colour RMSE and the
//! silhouette's mean displacement in pixels. The silhouette's length is measured with the
//! Cauchy–Crofton formula over four directions (the perimeter estimator of digital geometry, e.g.
//! Lehmann & Legland, "Efficient N-dimensional surface estimation using Crofton formula", 2012),
//! exact on average over orientations where counting pixel edges overestimates diagonals by √2.

use crate::bake::image::Image;

/// How two images differ, measured on output pixels (each the average of `downsample`² samples).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ImageError {
    /// Σ min(cov_a, cov_b) / Σ max(cov_a, cov_b) over output pixels, cov the fraction of a
    /// pixel's samples with alpha ≥ cutoff (1 when neither image covers anything).
    pub iou: f64,
    /// Root mean square over output pixels covered in either image and the three channels of the
    /// difference of their colours, linear 0..1 units. A pixel's colour is the sum of its covered
    /// samples' colours / downsample² (premultiplied by coverage, i.e. over black), so a pixel
    /// covered in one image only counts its whole colour.
    pub color_rmse: f64,
    /// Σ |cov_a − cov_b| / max(1, L), L the silhouette length of `a` in output pixels, at most the
    /// perimeter of the box around both silhouettes: the area between the two silhouettes per unit
    /// of outline, i.e. the mean displacement of the silhouette along its normal. The cap keeps
    /// thin structures honest: a grass clump's blades have an outline many times its envelope's,
    /// and a billboard that loses every blade must not pass for a small displacement. A shape moved by d pixels scores d·|cos θ| on average over its outline; for a disc
    /// that is 2d/π ≈ 0.64·d.
    pub edge_error_px: f64,
}

/// Compares `a` and `b`, both rendered `downsample`× supersampled per axis (0 counts as 1).
/// Images of different sizes are compared over the larger extent, the missing part of either
/// counting as transparent; a malformed image counts as empty.
pub fn compare(a: &Image, b: &Image, cutoff: f32, downsample: u32) -> ImageError {
    let ds = downsample.max(1) as usize;
    let width = a.width.max(b.width) as usize;
    let height = a.height.max(b.height) as usize;
    let (ow, oh) = (width.div_ceil(ds), height.div_ceil(ds));
    let (mask_a, mask_b) = (Mask::of(a, cutoff, width, height), Mask::of(b, cutoff, width, height));
    let samples = (ds * ds) as f64;
    let (mut inter, mut union, mut diff) = (0.0f64, 0.0f64, 0.0f64);
    let (mut sq_err, mut colour_pixels) = (0.0f64, 0usize);
    for oy in 0..oh {
        for ox in 0..ow {
            let (mut na, mut nb) = (0usize, 0usize);
            let (mut ca, mut cb) = ([0.0f64; 3], [0.0f64; 3]);
            for y in oy * ds..((oy + 1) * ds).min(height) {
                for x in ox * ds..((ox + 1) * ds).min(width) {
                    if mask_a.get(x, y) {
                        na += 1;
                        let p = a.pixels[y * a.width as usize + x];
                        (0..3).for_each(|k| ca[k] += p[k] as f64);
                    }
                    if mask_b.get(x, y) {
                        nb += 1;
                        let p = b.pixels[y * b.width as usize + x];
                        (0..3).for_each(|k| cb[k] += p[k] as f64);
                    }
                }
            }
            let (cov_a, cov_b) = (na as f64 / samples, nb as f64 / samples);
            inter += cov_a.min(cov_b);
            union += cov_a.max(cov_b);
            diff += (cov_a - cov_b).abs();
            if na + nb > 0 {
                colour_pixels += 1;
                sq_err += (0..3).map(|k| ((ca[k] - cb[k]) / samples).powi(2)).sum::<f64>();
            }
        }
    }
    let iou = if union > 0.0 { inter / union } else { 1.0 };
    let color_rmse = if colour_pixels > 0 { (sq_err / (3 * colour_pixels) as f64).sqrt() } else { 0.0 };
    // thin structures (grass blades, twigs) have an outline far longer than the object's envelope:
    // dividing by it would credit them for detail nobody can see, so the outline counted is at most
    // the perimeter of the box around both silhouettes
    let perimeter_px = (mask_a.crofton_length() / ds as f64).min(envelope_perimeter(&mask_a, &mask_b) / ds as f64);
    ImageError { iou, color_rmse, edge_error_px: diff / perimeter_px.max(1.0) }
}

/// Perimeter (in samples) of the axis-aligned box around the covered samples of `a` and `b`; 0
/// when neither covers anything.
fn envelope_perimeter(a: &Mask, b: &Mask) -> f64 {
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0usize, 0usize);
    for y in 0..a.height {
        for x in 0..a.width {
            if a.get(x, y) || b.get(x, y) {
                x0 = x0.min(x);
                x1 = x1.max(x + 1);
                y0 = y0.min(y);
                y1 = y1.max(y + 1);
            }
        }
    }
    if x0 == usize::MAX {
        0.0
    } else {
        2.0 * ((x1 - x0) + (y1 - y0)) as f64
    }
}

/// Which samples of an image are covered (alpha ≥ cutoff), over a `width`×`height` extent with a
/// one-sample uncovered border all round (so neighbours never need a bounds check).
struct Mask {
    width: usize,
    height: usize,
    /// (width + 2) × (height + 2), row-major, sample (x, y) at (x + 1, y + 1).
    covered: Vec<bool>,
}

impl Mask {
    fn of(img: &Image, cutoff: f32, width: usize, height: usize) -> Mask {
        let stride = width + 2;
        let mut covered = vec![false; stride * (height + 2)];
        if img.is_well_formed() {
            let w = img.width as usize;
            for (y, row) in img.pixels.chunks_exact(w).enumerate().take(height) {
                let out = &mut covered[(y + 1) * stride + 1..(y + 1) * stride + 1 + w.min(width)];
                for (o, p) in out.iter_mut().zip(row) {
                    *o = p[3] >= cutoff;
                }
            }
        }
        Mask { width, height, covered }
    }

    #[inline]
    fn get(&self, x: usize, y: usize) -> bool {
        self.covered[(y + 1) * (self.width + 2) + x + 1]
    }

    /// Cauchy–Crofton length of the outline with the 4 directions 0°, 45°, 90°, 135°: the number of
    /// covered/uncovered changes along each family of lines times the lines' spacing (1, 1/√2),
    /// summed, times π/8 (½ · π/4 per direction).
    fn crofton_length(&self) -> f64 {
        let stride = self.width + 2;
        let c = &self.covered;
        let (mut axis, mut diagonal) = (0u64, 0u64);
        // Every pair of neighbours that touches the extent, from the border row/column on.
        for y in 0..=self.height {
            let (row, next) = (y * stride, (y + 1) * stride);
            for x in 0..=self.width {
                let here = c[row + x];
                axis += (here != c[row + x + 1]) as u64 + (here != c[next + x]) as u64;
                diagonal += (here != c[next + x + 1]) as u64 + (c[row + x + 1] != c[next + x]) as u64;
            }
        }
        std::f64::consts::PI / 8.0 * (axis as f64 + diagonal as f64 * std::f64::consts::FRAC_1_SQRT_2)
    }
}

/// Length of the outline of the texels with alpha ≥ `cutoff`, in texels (outside the image counts
/// as uncovered), by the Cauchy–Crofton formula over four directions.
pub fn silhouette_length(img: &Image, cutoff: f32) -> f64 {
    if !img.is_well_formed() {
        return 0.0;
    }
    Mask::of(img, cutoff, img.width as usize, img.height as usize).crofton_length()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn disc(size: u32, cx: f64, cy: f64, r: f64) -> Image {
        let mut img = Image::new(size, size, [0.0; 4]).unwrap();
        for y in 0..size {
            for x in 0..size {
                let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
                if dx * dx + dy * dy <= r * r {
                    img.pixels[(y * size + x) as usize] = [0.2, 0.7, 0.1, 1.0];
                }
            }
        }
        img
    }

    #[test]
    fn crofton_length_of_a_disc_and_a_square() {
        let r = 60.0;
        let len = silhouette_length(&disc(160, 80.0, 80.0, r), 0.5);
        let true_len = 2.0 * std::f64::consts::PI * r;
        assert!((len / true_len - 1.0).abs() < 0.02, "{len} vs {true_len}");
        // An axis-aligned square is the estimator's worst case: 0.948 of its length.
        let mut sq = Image::new(50, 50, [0.0; 4]).unwrap();
        for y in 10..40 {
            for x in 10..40 {
                sq.pixels[y * 50 + x][3] = 1.0;
            }
        }
        let len = silhouette_length(&sq, 0.5);
        assert!((len / 120.0 - 0.948).abs() < 0.01, "{len}");
    }

    #[test]
    fn losing_thin_blades_is_not_a_small_displacement() {
        // 20 one-pixel-wide vertical blades 60 px tall in a 100 × 100 image, against nothing: the
        // blades' outline is ~2,400 px, their area 1,200 px; divided by the outline that would be
        // a 0.5 px "displacement". The envelope (77 + 60)·2 = 274 px caps the outline: 4.4 px.
        let mut blades = Image::new(100, 100, [0.0; 4]).unwrap();
        for k in 0..20 {
            for y in 20..80 {
                blades.pixels[y * 100 + 5 + 4 * k][3] = 1.0;
            }
        }
        let empty = Image::new(100, 100, [0.0; 4]).unwrap();
        let e = compare(&blades, &empty, 0.5, 1);
        assert!(e.iou == 0.0);
        let envelope = 2.0 * ((82.0 - 5.0) + 60.0);
        assert!((e.edge_error_px - 1200.0 / envelope).abs() < 1e-9, "{e:?}");
        // a solid disc keeps its own (shorter) outline: shifted by 2 px it scores 2·2/π
        let a = {
            let mut img = Image::new(120, 120, [0.0; 4]).unwrap();
            for y in 0..120 {
                for x in 0..120 {
                    let (dx, dy) = (x as f64 + 0.5 - 60.0, y as f64 + 0.5 - 60.0);
                    if dx * dx + dy * dy <= 40.0 * 40.0 {
                        img.pixels[y * 120 + x][3] = 1.0;
                    }
                }
            }
            img
        };
        let mut b = Image::new(120, 120, [0.0; 4]).unwrap();
        b.blit(&a, 2, 0);
        let e = compare(&a, &b, 0.5, 1);
        assert!((e.edge_error_px - 4.0 / std::f64::consts::PI).abs() < 0.1, "{e:?}");
    }
}
