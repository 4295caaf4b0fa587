//! Density and mask maps: a grayscale image stretched over the terrain extent, sampled bilinearly
//! (pixel centres at (k + 0.5)/n, clamped at the borders), values 0..1.

use std::path::Path;

use super::common::ScatterError;

/// A grayscale map in 0..1, row-major, row 0 at the extent's minimum z (like heightmap rows).
#[derive(Debug, Clone, PartialEq)]
pub struct DensityMap {
    pub width: usize,
    pub height: usize,
    pub values: Vec<f32>,
}

/// Largest map accepted (pixels), checked before decoding.
pub const MAX_DENSITY_PIXELS: u64 = 16384 * 16384;

impl DensityMap {
    /// A 1×1 map: the same value everywhere.
    pub fn constant(value: f32) -> DensityMap {
        DensityMap { width: 1, height: 1, values: vec![value.clamp(0.0, 1.0)] }
    }

    /// Where this map, read as 8-bit shades (a vegetation-type map: shade N marks type N), holds
    /// `shade`: 1 there, 0 elsewhere, times `within` (a species' own mask, sampled at this map's
    /// pixel centres) when given. Sampled bilinearly like any mask, a type's border softens over
    /// one pixel.
    pub fn where_shade(&self, shade: u8, within: Option<&DensityMap>) -> DensityMap {
        let (w, h) = (self.width, self.height);
        DensityMap::from_fn(w, h, |i, j| {
            let here = self.values.get(j * w + i).map_or(-1.0, |v| (v * 255.0).round());
            if here != shade as f32 {
                return 0.0;
            }
            within.map_or(1.0, |m| m.sample((i as f64 + 0.5) / w as f64, (j as f64 + 0.5) / h as f64))
        })
    }

    /// A map from a function of (column, row); values are clamped to 0..1 (NaN becomes 0).
    pub fn from_fn(width: usize, height: usize, f: impl Fn(usize, usize) -> f32) -> DensityMap {
        let mut values = Vec::with_capacity(width * height);
        for j in 0..height {
            for i in 0..width {
                let v = f(i, j);
                values.push(if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) });
            }
        }
        DensityMap { width, height, values }
    }

    /// Decodes an 8- or 16-bit grayscale PNG/TIFF (RGB with R = G = B is accepted, alpha is
    /// ignored); errors name the file and what to do.
    pub fn load(path: &Path) -> Result<DensityMap, ScatterError> {
        let err = |reason: String| ScatterError::Map { path: path.to_path_buf(), reason };
        let reader = image::ImageReader::open(path)
            .map_err(|e| err(format!("cannot open: {e}")))?
            .with_guessed_format()
            .map_err(|e| err(format!("cannot read: {e}")))?;
        let (w, h) = reader.into_dimensions().map_err(|e| err(format!("not a readable PNG/TIFF image: {e}")))?;
        if w == 0 || h == 0 {
            return Err(err("the image is empty (0 pixels); use a map of at least 1×1".into()));
        }
        if w as u64 * h as u64 > MAX_DENSITY_PIXELS {
            return Err(err(format!("{w}×{h} pixels is above the limit of {MAX_DENSITY_PIXELS}; downscale the map")));
        }
        let img = image::ImageReader::open(path)
            .map_err(|e| err(format!("cannot open: {e}")))?
            .with_guessed_format()
            .map_err(|e| err(format!("cannot read: {e}")))?
            .decode()
            .map_err(|e| err(format!("cannot decode: {e}")))?;
        use image::DynamicImage as D;
        let (width, height) = (img.width() as usize, img.height() as usize);
        let values: Vec<f32> = match img {
            D::ImageLuma8(b) => b.into_raw().iter().map(|&v| v as f32 / 255.0).collect(),
            D::ImageLumaA8(b) => b.into_raw().chunks_exact(2).map(|p| p[0] as f32 / 255.0).collect(),
            D::ImageLuma16(b) => b.into_raw().iter().map(|&v| v as f32 / 65535.0).collect(),
            D::ImageLumaA16(b) => b.into_raw().chunks_exact(2).map(|p| p[0] as f32 / 65535.0).collect(),
            D::ImageRgb8(b) => gray_of_rgb(b.into_raw(), 3, 255.0, path)?,
            D::ImageRgba8(b) => gray_of_rgb(b.into_raw(), 4, 255.0, path)?,
            D::ImageRgb16(b) => gray_of_rgb(b.into_raw(), 3, 65535.0, path)?,
            D::ImageRgba16(b) => gray_of_rgb(b.into_raw(), 4, 65535.0, path)?,
            other => {
                return Err(err(format!(
                    "unsupported pixel format {:?}; save the map as 8- or 16-bit grayscale",
                    other.color()
                )))
            }
        };
        Ok(DensityMap { width, height, values })
    }

    /// Bilinear value at (u, v) in 0..1 over the extent (u along x, v along z); pixel centres at
    /// (k + 0.5)/n, clamped at the borders, so a 1×1 map is a constant. An empty map (or one whose
    /// `values` do not hold width × height entries) reads 0.
    #[inline]
    pub fn sample(&self, u: f64, v: f64) -> f32 {
        // a hand-built map whose size does not match its values reads 0 instead of panicking
        if self.values.len() != self.width * self.height || self.values.is_empty() {
            return 0.0;
        }
        let (fx, i0, i1) = axis(u, self.width);
        let (fz, j0, j1) = axis(v, self.height);
        let w = self.width;
        let a = self.values[j0 * w + i0];
        let b = self.values[j0 * w + i1];
        let c = self.values[j1 * w + i0];
        let d = self.values[j1 * w + i1];
        let top = a + (b - a) * fx;
        let bottom = c + (d - c) * fx;
        top + (bottom - top) * fz
    }

    /// Largest value over the pixels that can influence samples in [u0, u1] × [v0, v1] (one pixel of
    /// margin for the bilinear footprint): an upper bound used to skip empty tiles.
    pub fn max_over(&self, u0: f64, v0: f64, u1: f64, v1: f64) -> f32 {
        if self.values.len() != self.width * self.height || self.values.is_empty() {
            return 0.0;
        }
        let range = |a: f64, b: f64, n: usize| {
            let lo = ((a * n as f64 - 0.5).floor() as i64).clamp(0, n as i64 - 1) as usize;
            let hi = ((b * n as f64 - 0.5).ceil() as i64 + 1).clamp(0, n as i64 - 1) as usize;
            (lo, hi)
        };
        let (i0, i1) = range(u0, u1, self.width);
        let (j0, j1) = range(v0, v1, self.height);
        let mut m = 0.0f32;
        for j in j0..=j1 {
            for &v in &self.values[j * self.width + i0..=j * self.width + i1] {
                m = m.max(v);
            }
        }
        m
    }
}

/// Bilinear weights along one axis: (fraction, lower index, upper index), clamped to the border.
#[inline]
fn axis(u: f64, n: usize) -> (f32, usize, usize) {
    // conversions through i64 (exact for any map size): one instruction each, where usize ↔ f64
    // takes several on x86-64
    let p = u * n as i64 as f64 - 0.5;
    let last = (n - 1) as i64 as f64;
    if p.is_nan() || p <= 0.0 {
        return (0.0, 0, 0);
    }
    if p >= last {
        return (0.0, n - 1, n - 1);
    }
    // 0 < p < n − 1 here, so truncation is the floor (and no libm call)
    let i = p as i64;
    ((p - i as f64) as f32, i as usize, (i as usize + 1).min(n - 1))
}

/// Gray values of an RGB(A) image whose channels agree; anything else is an error naming the pixel.
fn gray_of_rgb<T: Copy + Into<f32> + PartialEq>(
    raw: Vec<T>,
    channels: usize,
    max: f32,
    path: &Path,
) -> Result<Vec<f32>, ScatterError> {
    let mut out = Vec::with_capacity(raw.len() / channels);
    for (k, p) in raw.chunks_exact(channels).enumerate() {
        if p[0] != p[1] || p[0] != p[2] {
            return Err(ScatterError::Map {
                path: path.to_path_buf(),
                reason: format!("pixel {k} has different red, green and blue values; density and mask maps must be grayscale (save as gray, or R = G = B)"),
            });
        }
        out.push(p[0].into() / max);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_and_bilinear() {
        let c = DensityMap::constant(0.3);
        assert_eq!(c.sample(0.0, 0.0), 0.3);
        assert_eq!(c.sample(0.99, 0.5), 0.3);
        let m = DensityMap::from_fn(2, 1, |i, _| i as f32);
        // pixel centres at u = 0.25 and 0.75, clamped outside
        assert_eq!(m.sample(0.1, 0.5), 0.0);
        assert_eq!(m.sample(0.25, 0.5), 0.0);
        assert!((m.sample(0.5, 0.5) - 0.5).abs() < 1e-6);
        assert_eq!(m.sample(0.9, 0.5), 1.0);
        assert_eq!(m.sample(f64::NAN, 0.5), 0.0);
        assert_eq!(m.max_over(0.0, 0.0, 0.1, 1.0), 1.0); // margin reaches pixel 1
    }

    #[test]
    fn load_png_gray_16_and_rgb() {
        let dir = tempfile::tempdir().unwrap();
        let p8 = dir.path().join("g8.png");
        image::GrayImage::from_raw(2, 1, vec![0, 255]).unwrap().save(&p8).unwrap();
        let m = DensityMap::load(&p8).unwrap();
        assert_eq!((m.width, m.height, m.values.clone()), (2, 1, vec![0.0, 1.0]));
        let p16 = dir.path().join("g16.png");
        image::ImageBuffer::<image::Luma<u16>, _>::from_raw(1, 1, vec![65535u16]).unwrap().save(&p16).unwrap();
        assert_eq!(DensityMap::load(&p16).unwrap().values, vec![1.0]);
        let prgb = dir.path().join("rgb.png");
        image::RgbImage::from_raw(1, 1, vec![51, 51, 51]).unwrap().save(&prgb).unwrap();
        assert!((DensityMap::load(&prgb).unwrap().values[0] - 0.2).abs() < 1e-6);
        let bad = dir.path().join("color.png");
        image::RgbImage::from_raw(1, 1, vec![1, 2, 3]).unwrap().save(&bad).unwrap();
        let e = DensityMap::load(&bad).unwrap_err().to_string();
        assert!(e.contains("color.png") && e.contains("grayscale"), "{e}");
        let missing = DensityMap::load(&dir.path().join("nope.png")).unwrap_err().to_string();
        assert!(missing.contains("nope.png"), "{missing}");
    }
}
