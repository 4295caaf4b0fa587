//! The canvas as an image file: linear colour to sRGB 8-bit RGBA, PNG encoding, atomic writes.

use std::path::Path;

use super::canvas::Canvas;
use super::limits::RasterError;
use crate::color::linear_to_srgb;
use crate::export::write_atomic;

impl Canvas {
    /// sRGB-encoded 8-bit RGBA, row-major from the top-left (alpha stays linear, as PNG wants).
    pub fn to_rgba8(&self) -> Vec<u8> {
        rgba8(&self.color)
    }

    /// The canvas as PNG bytes (sRGB, 8-bit RGBA). Deterministic.
    pub fn encode_png(&self) -> Result<Vec<u8>, RasterError> {
        encode_rgba8_png(&self.to_rgba8(), self.width, self.height).map_err(RasterError::Encode)
    }

    /// Writes the canvas as a PNG, atomically (temporary file, then rename).
    pub fn write_png(&self, path: &Path) -> Result<(), RasterError> {
        let bytes = self.encode_png()?;
        write_atomic(path, &bytes)?;
        Ok(())
    }
}

/// Linear straight-alpha RGBA → sRGB-encoded 8-bit RGBA (alpha stays linear), rounded to nearest:
/// what every PNG the baker writes holds.
/// In parallel over pixels (an atlas has a million).
pub fn rgba8(pixels: &[[f32; 4]]) -> Vec<u8> {
    use rayon::prelude::*;
    let one = |c: &[f32; 4]| {
        [to_u8(linear_to_srgb(c[0])), to_u8(linear_to_srgb(c[1])), to_u8(linear_to_srgb(c[2])), to_u8(c[3])]
    };
    pixels.par_iter().with_min_len(1 << 14).map(one).collect::<Vec<[u8; 4]>>().into_flattened()
}

/// PNG bytes of `width` × `height` RGBA8 pixels (deterministic: same pixels, same bytes).
pub fn encode_rgba8_png(rgba: &[u8], width: u32, height: u32) -> Result<Vec<u8>, String> {
    use image::ImageEncoder;
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(rgba, width, height, image::ExtendedColorType::Rgba8)
        .map_err(|e| e.to_string())?;
    Ok(bytes)
}

#[inline]
pub(crate) fn to_u8(v: f32) -> u8 {
    // NaN → 0; round half up.
    if v.is_nan() {
        0
    } else {
        (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
    }
}
