//! Procedural plant textures, so no photograph has to ship: grass blade columns (root-to-tip
//! gradient, per-column hue/value jitter, fine streak noise, alpha shaped like the blade's taper)
//! and the same columns made from a user's blade image; tileable bark and polygon-leaf surfaces.

use crate::bake::image::Image;
use crate::plants::grass::{taper, GrassSettings, BLADE_TEXTURE_COLUMNS};
use crate::random::Stream;

/// Pixels per blade column and texture height of the procedural blade texture.
pub const COLUMN_PX: u32 = 16;
pub const BLADE_TEXTURE_HEIGHT: u32 = 128;

/// Hue/value jitter of column `c`: (towards-yellow shift −1..1 scaled by hue_jitter, value factor).
fn column_jitter(settings: &GrassSettings, c: usize) -> (f32, f32) {
    let mut r = Stream::new(&[settings.seed, 0x0062_6c61_6465, c as u64]);
    let hue = (2.0 * r.unit() - 1.0) * settings.hue_jitter;
    let value = 1.0 + (2.0 * r.unit() - 1.0) * settings.value_jitter;
    (hue, value)
}

/// Shifts a green towards yellow (hue > 0: more red) or blue-green (hue < 0: more blue), keeping
/// the colour's green channel, then scales its value.
fn jitter_colour(c: [f32; 3], hue: f32, value: f32) -> [f32; 3] {
    let g = c[1];
    let r = (c[0] + hue.max(0.0) * g * 0.8).min(1.0);
    let b = (c[2] + (-hue).max(0.0) * g * 0.5).min(1.0);
    [(r * value).clamp(0.0, 1.0), (g * value).clamp(0.0, 1.0), (b * value).clamp(0.0, 1.0)]
}

/// The procedural blade texture: `BLADE_TEXTURE_COLUMNS` columns side by side, each a blade from
/// its root (bottom row) to its tip (top row), alpha 1 inside the taper (anti-aliased edge).
pub fn blade_texture(settings: &GrassSettings) -> Image {
    let (cols, w, h) = (BLADE_TEXTURE_COLUMNS as u32, COLUMN_PX, BLADE_TEXTURE_HEIGHT);
    let width = cols * w;
    let mut pixels = vec![[0.0f32; 4]; (width * h) as usize];
    for c in 0..cols {
        let (hue, value) = column_jitter(settings, c as usize);
        let root = jitter_colour(settings.root_color, hue, value);
        let tip = jitter_colour(settings.tip_color, hue, value);
        let mut streaks = Stream::new(&[settings.seed, 0x0000_7374_726b, c as u64]);
        let streak: Vec<f32> = (0..w).map(|_| 1.0 + 0.12 * (2.0 * streaks.unit() - 1.0)).collect();
        for y in 0..h {
            // row 0 is the top of the image = the tip
            let t = 1.0 - (y as f32 + 0.5) / h as f32;
            let grad = t.powf(0.8);
            let half = 0.5 * taper(t) * w as f32; // half-width in pixels
            for x in 0..w {
                let off = (x as f32 + 0.5 - w as f32 / 2.0).abs();
                let alpha = (half - off + 0.5).clamp(0.0, 1.0);
                let mut grain = Stream::new(&[settings.seed, c as u64, y as u64, x as u64]);
                let n = streak[x as usize] * (1.0 + 0.05 * (2.0 * grain.unit() - 1.0));
                // the midrib is a little lighter
                let rib = 1.0 + 0.1 * (1.0 - (off / (w as f32 / 2.0)).min(1.0)).powi(4);
                let col: [f32; 3] =
                    std::array::from_fn(|k| ((root[k] + (tip[k] - root[k]) * grad) * n * rib).clamp(0.0, 1.0));
                pixels[(y * width + c * w + x) as usize] = [col[0], col[1], col[2], alpha];
            }
        }
    }
    Image { width, height: h, pixels }
}

/// The blade texture from a user's image: the image repeated in every column (resampled to the
/// column size), each copy with its column's hue/value jitter; the image's alpha is kept.
pub fn blade_texture_from(settings: &GrassSettings, user: &Image) -> Image {
    let (cols, w, h) = (BLADE_TEXTURE_COLUMNS as u32, COLUMN_PX * 2, BLADE_TEXTURE_HEIGHT * 2);
    let width = cols * w;
    let mut pixels = vec![[0.0f32; 4]; (width * h) as usize];
    for c in 0..cols {
        let (hue, value) = column_jitter(settings, c as usize);
        for y in 0..h {
            for x in 0..w {
                let uv = [(x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32];
                let s = user.sample_bilinear(uv);
                let col = jitter_colour([s[0], s[1], s[2]], hue, value);
                pixels[(y * width + c * w + x) as usize] = [col[0], col[1], col[2], s[3]];
            }
        }
    }
    Image { width, height: h, pixels }
}

/// Side of the procedural bark and polygon-leaf textures.
pub const SURFACE_TEXTURE_PX: u32 = 128;

/// A grey tileable texture (sRGB bytes, opaque) from a luminance function of (u, v) in [0, 1)²;
/// the material's base colour factor tints it.
fn luminance_png(f: impl Fn(f64, f64) -> f64) -> Vec<u8> {
    let n = SURFACE_TEXTURE_PX;
    let image = image::RgbaImage::from_fn(n, n, |x, y| {
        let (u, v) = ((x as f64 + 0.5) / n as f64, (y as f64 + 0.5) / n as f64);
        let l = (f(u, v).clamp(0.0, 1.0) * 255.0).round() as u8;
        image::Rgba([l, l, l, 255])
    });
    let mut png = Vec::new();
    // an in-memory PNG encode of a valid RGBA buffer cannot fail
    image.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).expect("PNG encoding in memory");
    png
}

/// Bark, tileable in u (around the branch, one turn) and v (along it, one circumference a
/// repeat): twelve vertical ridges that wander along the branch, darker furrows between them and a
/// finer grain. Luminance 0.66–1 (mean ≈ 0.86), multiplied by the bark colour.
pub fn bark_texture_png() -> Vec<u8> {
    use std::f64::consts::TAU;
    luminance_png(|u, v| {
        let wander = 0.35 * (TAU * 2.0 * v).sin() + 0.15 * (TAU * (5.0 * v + 3.0 * u)).sin();
        let ridge = 0.5 + 0.5 * (TAU * (12.0 * u + wander)).sin();
        let grain = 0.5 + 0.5 * (TAU * (40.0 * u + 7.0 * v)).sin() * (TAU * (3.0 * u + 23.0 * v)).sin();
        0.66 + 0.30 * ridge.powf(0.6) + 0.04 * grain
    })
}

/// A leaf surface for polygon leaves (uv spans the polygon's extent): a soft midrib along v and
/// side veins; luminance 0.8–1, multiplied by the leaf colour.
pub fn polygon_leaf_texture_png() -> Vec<u8> {
    luminance_png(|u, v| {
        let across = (u - 0.5).abs();
        let midrib = (1.0 - across / 0.04).max(0.0);
        let phase = (v * 7.0 + across * 3.0).rem_euclid(1.0);
        let vein = (1.0 - (phase - 0.5).abs() / 0.06).max(0.0);
        0.97 - 0.12 * midrib - 0.08 * vein
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blade_columns_taper_to_the_tip_and_differ_in_colour() {
        let s = GrassSettings::default();
        let t = blade_texture(&s);
        let coverage_row = |y: u32| (0..COLUMN_PX).filter(|&x| t.pixels[(y * t.width + x) as usize][3] >= 0.5).count();
        // wide at the root (bottom), narrow at the tip (top)
        assert!(coverage_row(BLADE_TEXTURE_HEIGHT - 1) >= COLUMN_PX as usize - 1);
        assert!(coverage_row(0) <= 2);
        let mid = |c: u32| t.pixels[((BLADE_TEXTURE_HEIGHT / 2) * t.width + c * COLUMN_PX + COLUMN_PX / 2) as usize];
        let distinct = (1..BLADE_TEXTURE_COLUMNS as u32).filter(|&c| mid(c) != mid(0)).count();
        assert!(distinct >= BLADE_TEXTURE_COLUMNS - 2);
        // root darker than tip (gradient)
        let root = t.pixels[((BLADE_TEXTURE_HEIGHT - 1) * t.width + COLUMN_PX / 2) as usize];
        let tip = t.pixels[(8 * t.width + COLUMN_PX / 2) as usize];
        assert!(root[1] < tip[1]);
        assert_eq!(blade_texture(&s), t, "deterministic");
    }
}
