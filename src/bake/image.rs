//! Float RGBA images for textures and atlases: linear colour with straight alpha in memory, sRGB
//! 8-bit PNG on disk (the IEC 61966-2-1 transfer function, as glTF base-colour textures are), and
//! bilinear sampling with repeat wrapping as a glTF sampler with LINEAR filtering and REPEAT does.

use std::io::Cursor;
use std::path::Path;

use image::ImageDecoder;

use crate::bake::error::BakeError;
use crate::bake::raster::{Canvas, MAX_CANVAS_SIDE};
use crate::color::srgb_to_linear;
use crate::export::write_atomic;

/// Largest image side accepted (the rasteriser's canvas limit): 16384² RGBA f32 is 4 GB.
pub const MAX_IMAGE_SIDE: u32 = MAX_CANVAS_SIDE;

/// An image: linear RGB, straight (not premultiplied) alpha, row-major from the top-left.
/// `pixels.len()` must be `width · height`; functions given an image that breaks this treat it as
/// empty rather than panic.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[f32; 4]>,
}

impl Image {
    /// A `width`×`height` image filled with `fill`.
    pub fn new(width: u32, height: u32, fill: [f32; 4]) -> Result<Image, BakeError> {
        check_size("the requested image", width as u64, height as u64)?;
        Ok(Image { width, height, pixels: vec![fill; width as usize * height as usize] })
    }

    /// The canvas' colours (the depth is dropped).
    pub fn from_canvas(canvas: &Canvas) -> Image {
        Image { width: canvas.width, height: canvas.height, pixels: canvas.color.clone() }
    }

    /// The canvas' colours, without copying them (the depth is dropped).
    pub fn from_canvas_owned(canvas: Canvas) -> Image {
        Image { width: canvas.width, height: canvas.height, pixels: canvas.color }
    }

    /// `pixels` has exactly `width · height` entries and neither side is 0.
    pub fn is_well_formed(&self) -> bool {
        self.width > 0 && self.height > 0 && self.pixels.len() as u64 == self.width as u64 * self.height as u64
    }

    /// Decodes PNG bytes: colour from sRGB to linear, alpha as stored; grey, palette and 16-bit
    /// images are expanded. Colour-space chunks (gAMA, iCCP) are ignored: PNG colour is taken as
    /// sRGB, as glTF does for base-colour textures.
    pub fn from_png(bytes: &[u8]) -> Result<Image, BakeError> {
        Image::decode_png(bytes, "the PNG data")
    }

    /// Reads and decodes a PNG file (see [`Image::from_png`]); errors name the file.
    pub fn read_png(path: &Path) -> Result<Image, BakeError> {
        let bytes = crate::input::read_limited(path, crate::input::MAX_IMAGE_BYTES, "an image")
            .map_err(|e| BakeError::Read { path: path.to_path_buf(), source: e.into_io() })?;
        Image::decode_png(&bytes, &path.display().to_string())
    }

    /// Decodes PNG bytes that hold data, not colour (a glTF normalTexture): values as stored,
    /// 0..1, no sRGB decoding (the inverse of [`Image::encode_png_data`]).
    pub fn from_png_data(bytes: &[u8]) -> Result<Image, BakeError> {
        // an 8-bit channel k reads as what the colour decode and its undoing below give k: one
        // table, the same values (a world's 2048² normal maps took a powf per channel)
        let (mut img, sixteen) = Image::decode_png_as(bytes, "the PNG data", |k| {
            let v = crate::color::linear_to_srgb(srgb_to_linear(k as f32 / 255.0));
            (v * 255.0).round() / 255.0
        })?;
        if !sixteen {
            return Ok(img);
        }
        for p in &mut img.pixels {
            for c in p.iter_mut().take(3) {
                *c = crate::color::linear_to_srgb(*c);
            }
        }
        // 8-bit values exactly: the sRGB round trip may be off by a rounding step
        for p in &mut img.pixels {
            for c in p.iter_mut().take(3) {
                *c = (*c * 255.0).round() / 255.0;
            }
        }
        Ok(img)
    }

    /// PNG bytes of an image that holds data, not colour (a glTF normalTexture, which glTF reads as
    /// linear values): each channel written as stored, no sRGB encoding. Deterministic.
    pub fn encode_png_data(&self) -> Result<Vec<u8>, BakeError> {
        if !self.is_well_formed() {
            return Err(self.malformed());
        }
        let to_u8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        let raw: Vec<u8> =
            self.pixels.iter().flat_map(|c| [to_u8(c[0]), to_u8(c[1]), to_u8(c[2]), to_u8(c[3])]).collect();
        crate::bake::raster::png::encode_rgba8_png(&raw, self.width, self.height).map_err(BakeError::Encode)
    }

    fn decode_png(bytes: &[u8], source_name: &str) -> Result<Image, BakeError> {
        Image::decode_png_as(bytes, source_name, |k| srgb_to_linear(k as f32 / 255.0)).map(|(img, _)| img)
    }

    /// [`Image::decode_png`] with 8-bit colour channel k read as `eight(k)` (alpha as stored);
    /// whether the image was 16-bit (its colour then decoded from sRGB, as `decode_png` does).
    fn decode_png_as(bytes: &[u8], source_name: &str, eight: impl Fn(u8) -> f32) -> Result<(Image, bool), BakeError> {
        let png_err =
            |e: image::ImageError| BakeError::Png { source_name: source_name.to_string(), reason: e.to_string() };
        let decoder = image::codecs::png::PngDecoder::new(Cursor::new(bytes)).map_err(png_err)?;
        // Refuse oversized images from the header, before any pixel memory is allocated.
        let (width, height) = decoder.dimensions();
        check_size(source_name, width as u64, height as u64)?;
        let colour = decoder.color_type();
        let sixteen = colour.bytes_per_pixel() / colour.channel_count() == 2;
        let dynamic = image::DynamicImage::from_decoder(decoder).map_err(png_err)?;
        let pixels: Vec<[f32; 4]> = if sixteen {
            let raw = dynamic.into_rgba16();
            raw.pixels()
                .map(|p| {
                    let c = |v: u16| v as f32 / 65535.0;
                    [srgb_to_linear(c(p[0])), srgb_to_linear(c(p[1])), srgb_to_linear(c(p[2])), c(p[3])]
                })
                .collect()
        } else {
            // 256 entries instead of a powf per channel.
            let table: Vec<f32> = (0..=255u8).map(eight).collect();
            let raw = dynamic.into_rgba8();
            raw.pixels()
                .map(|p| [table[p[0] as usize], table[p[1] as usize], table[p[2] as usize], p[3] as f32 / 255.0])
                .collect()
        };
        Ok((Image { width, height, pixels }, sixteen))
    }

    /// sRGB-encoded 8-bit RGBA, row-major from the top-left (alpha stays linear), rounded to nearest.
    pub fn to_rgba8(&self) -> Vec<u8> {
        crate::bake::raster::png::rgba8(&self.pixels)
    }

    /// PNG bytes (RGBA8, sRGB colour). Deterministic: the same image gives the same bytes.
    pub fn encode_png(&self) -> Result<Vec<u8>, BakeError> {
        if !self.is_well_formed() {
            return Err(self.malformed());
        }
        crate::bake::raster::png::encode_rgba8_png(&self.to_rgba8(), self.width, self.height).map_err(BakeError::Encode)
    }

    /// Writes the image as a PNG, atomically (temporary file, then rename).
    pub fn write_png(&self, path: &Path) -> Result<(), BakeError> {
        let bytes = self.encode_png()?;
        write_atomic(path, &bytes)?;
        Ok(())
    }

    fn malformed(&self) -> BakeError {
        BakeError::Malformed {
            width: self.width,
            height: self.height,
            pixels: self.pixels.len(),
            expected: self.width as u64 * self.height as u64,
        }
    }

    #[inline]
    pub fn pixel(&self, x: u32, y: u32) -> Option<[f32; 4]> {
        if x < self.width && y < self.height {
            self.pixels.get(y as usize * self.width as usize + x as usize).copied()
        } else {
            None
        }
    }

    /// Bilinear sample at texture coordinates `uv` (glTF convention: u right, v *down* from the
    /// image's top edge; texel (i, j) has its centre at ((i + ½)/width, (j + ½)/height)), wrapping
    /// around in both directions (REPEAT). Straight colour and alpha are filtered independently,
    /// as a GPU does. A non-finite coordinate reads as 0; a malformed image as transparent black.
    pub fn sample_bilinear(&self, uv: [f32; 2]) -> [f32; 4] {
        if !self.is_well_formed() {
            return [0.0; 4];
        }
        let (w, h) = (self.width as i64, self.height as i64);
        let axis = |t: f32, n: i64| -> (usize, usize, f32) {
            let t = if t.is_finite() { t as f64 } else { 0.0 };
            // Position in texel units relative to texel centres; wrap the integer part.
            let x = t * n as f64 - 0.5;
            let x0 = x.floor();
            let frac = (x - x0) as f32;
            let i = x0 as i64;
            if i >= 0 && i + 1 < n {
                // inside: no wrapping (the common case; spares two integer divisions)
                return (i as usize, i as usize + 1, frac);
            }
            let i0 = i.rem_euclid(n);
            (i0 as usize, ((i0 + 1) % n) as usize, frac)
        };
        let (x0, x1, fx) = axis(uv[0], w);
        let (y0, y1, fy) = axis(uv[1], h);
        let w = w as usize;
        let p = |x: usize, y: usize| self.pixels[y * w + x];
        let (a, b, c, d) = (p(x0, y0), p(x1, y0), p(x0, y1), p(x1, y1));
        [0, 1, 2, 3].map(|k| {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bottom = c[k] + (d[k] - c[k]) * fx;
            top + (bottom - top) * fy
        })
    }

    /// Copies `src` into this image with its top-left corner at (x, y); whatever falls outside
    /// this image is left out. For packing atlases.
    pub fn blit(&mut self, src: &Image, x: u32, y: u32) {
        if !self.is_well_formed() || !src.is_well_formed() || x >= self.width || y >= self.height {
            return;
        }
        let cols = src.width.min(self.width - x) as usize;
        let rows = src.height.min(self.height - y);
        for r in 0..rows {
            let from = r as usize * src.width as usize;
            let to = (y + r) as usize * self.width as usize + x as usize;
            self.pixels[to..to + cols].copy_from_slice(&src.pixels[from..from + cols]);
        }
    }
}

fn check_size(source_name: &str, width: u64, height: u64) -> Result<(), BakeError> {
    let max = MAX_IMAGE_SIDE as u64;
    if width == 0 || height == 0 || width > max || height > max {
        return Err(BakeError::ImageSize { source_name: source_name.to_string(), width, height });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn data_pngs_keep_their_values() {
        // a flat normal is (128, 128, 255) in the file, not its sRGB encoding (188, 188, 255)
        let img = Image::new(1, 1, [0.5, 0.5, 1.0, 1.0]).unwrap();
        let png = img.encode_png_data().unwrap();
        let decoded = image::load_from_memory(&png).unwrap().to_rgba8();
        assert_eq!(decoded.get_pixel(0, 0).0, [128, 128, 255, 255]);
        let back = Image::from_png_data(&png).unwrap();
        assert!((back.pixels[0][0] - 128.0 / 255.0).abs() < 1e-6 && back.pixels[0][2] == 1.0);
    }

    use super::*;
    use crate::color::linear_to_srgb;

    /// An 8-bit data PNG reads through its table as the colour decode and its undoing give every
    /// value 0..=255, bit for bit; a 16-bit one as before.
    #[test]
    fn data_pngs_read_as_the_colour_decode_undone() {
        let raw: Vec<u8> = (0..=255u8).flat_map(|k| [k, 255 - k, k.wrapping_mul(7), k]).collect();
        let png = crate::bake::raster::png::encode_rgba8_png(&raw, 16, 16).unwrap();
        let undone = |img: Image| -> Vec<[u32; 4]> {
            img.pixels
                .iter()
                .map(|p| {
                    let c = |v: f32| ((linear_to_srgb(v) * 255.0).round() / 255.0).to_bits();
                    [c(p[0]), c(p[1]), c(p[2]), p[3].to_bits()]
                })
                .collect()
        };
        let bits = |img: Image| -> Vec<[u32; 4]> { img.pixels.iter().map(|p| p.map(f32::to_bits)).collect() };
        assert_eq!(bits(Image::from_png_data(&png).unwrap()), undone(Image::from_png(&png).unwrap()));
        let mut wide = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut wide, 4, 1);
            enc.set_color(png::ColorType::Rgba);
            enc.set_depth(png::BitDepth::Sixteen);
            let samples: Vec<u8> = (0..16u16).flat_map(|k| (k * 4099).to_be_bytes()).collect();
            enc.write_header().unwrap().write_image_data(&samples).unwrap();
        }
        assert_eq!(bits(Image::from_png_data(&wide).unwrap()), undone(Image::from_png(&wide).unwrap()));
    }

    fn checker() -> Image {
        // 2×2: red, green / blue, white at half alpha.
        Image {
            width: 2,
            height: 2,
            pixels: vec![[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0], [1.0, 1.0, 1.0, 0.5]],
        }
    }

    #[test]
    fn texel_centres_sample_exactly_and_edges_wrap() {
        let img = checker();
        assert_eq!(img.sample_bilinear([0.25, 0.25]), [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(img.sample_bilinear([0.75, 0.25]), [0.0, 1.0, 0.0, 1.0]);
        // v runs down: the bottom row is v = 0.75
        assert_eq!(img.sample_bilinear([0.25, 0.75]), [0.0, 0.0, 1.0, 1.0]);
        // repeat: u + 1 and u − 3 read the same
        assert_eq!(img.sample_bilinear([1.25, -2.75]), img.sample_bilinear([0.25, 0.25]));
        // halfway between red and green
        let mid = img.sample_bilinear([0.5, 0.25]);
        assert!((mid[0] - 0.5).abs() < 1e-6 && (mid[1] - 0.5).abs() < 1e-6);
        // u = 0 is halfway between the last and first column (wrapping)
        let seam = img.sample_bilinear([0.0, 0.25]);
        assert!((seam[0] - 0.5).abs() < 1e-6 && (seam[1] - 0.5).abs() < 1e-6);
        assert_eq!(img.sample_bilinear([f32::NAN, 0.25]), img.sample_bilinear([0.0, 0.25]));
        let broken = Image { width: 3, height: 3, pixels: vec![] };
        assert_eq!(broken.sample_bilinear([0.5, 0.5]), [0.0; 4]);
    }

    #[test]
    fn png_roundtrip_is_within_one_code_value() {
        let mut img = Image::new(5, 3, [0.0; 4]).unwrap();
        for (k, p) in img.pixels.iter_mut().enumerate() {
            let t = k as f32 / 14.0;
            *p = [t, t * t, 1.0 - t, (k % 4) as f32 / 3.0];
        }
        let png = img.encode_png().unwrap();
        let back = Image::from_png(&png).unwrap();
        assert_eq!((back.width, back.height), (5, 3));
        for (a, b) in img.pixels.iter().zip(&back.pixels) {
            for k in 0..3 {
                assert!((linear_to_srgb(a[k]) - linear_to_srgb(b[k])).abs() <= 0.5 / 255.0 + 1e-6);
            }
            assert!((a[3] - b[3]).abs() <= 0.5 / 255.0 + 1e-6);
        }
        // encoding again gives the same bytes
        assert_eq!(back.encode_png().unwrap(), png);
    }

    #[test]
    fn bad_png_and_sizes_are_errors() {
        assert!(matches!(Image::from_png(b"not a png"), Err(BakeError::Png { .. })));
        assert!(matches!(Image::new(0, 4, [0.0; 4]), Err(BakeError::ImageSize { .. })));
        let broken = Image { width: 2, height: 2, pixels: vec![[0.0; 4]] };
        assert!(matches!(broken.encode_png(), Err(BakeError::Malformed { .. })));
        let missing = Image::read_png(Path::new("/nonexistent/verdant.png")).unwrap_err();
        assert!(missing.to_string().contains("/nonexistent/verdant.png"));
    }

    #[test]
    fn blit_copies_and_clips() {
        let mut dst = Image::new(4, 3, [0.0; 4]).unwrap();
        let src = checker();
        dst.blit(&src, 3, 2);
        assert_eq!(dst.pixel(3, 2), Some([1.0, 0.0, 0.0, 1.0]));
        assert_eq!(dst.pixels.iter().filter(|p| p[3] > 0.0).count(), 1);
        dst.blit(&src, 1, 0);
        assert_eq!(dst.pixel(2, 0), Some([0.0, 1.0, 0.0, 1.0]));
        assert_eq!(dst.pixel(2, 1), Some([1.0, 1.0, 1.0, 0.5]));
        dst.blit(&src, 9, 9); // entirely outside: nothing
    }
}
