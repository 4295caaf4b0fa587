//! Heightmaps decoded into metres, and sampling of them.
//!
//! Encodings: 8/16-bit gray PNG/TIFF (also gray stored as RGB with R = G = B), 32-bit float TIFF
//! (metres), Mapbox Terrain-RGB, Mapzen Terrarium, SRTM `.hgt` (big-endian int16 with voids) and raw
//! little-endian 16-bit `.r16`/`.raw`. Every decoder checks the sample count against an explicit
//! limit before it allocates, and every error names the file and what to do.

use std::fmt;
use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::sync::Arc;

mod rows;
mod window;
pub use rows::MapRows;
pub use window::{dimensions_of_file, kept_rows_from, read_kept_rows, reads_by_range, KeptRows};

/// A regular grid of heights in metres. Sample (i, j) — column i, row j — lies at
/// x = i·cell_size_m, z = j·cell_size_m, y = `heights[j * width + i]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Heightfield {
    pub width: usize,
    pub height: usize,
    /// Row-major heights in metres, `width * height` finite values: the heights the terrain's
    /// vertices store (glTF and OBJ hold 32-bit floats).
    pub heights: Vec<f32>,
    pub cell_size_m: f64,
    /// The heights as the map's encoding defines them, where 32-bit floats cannot hold them exactly
    /// (Terrain-RGB's decimetres, a gray map's scale): `None` when `heights` are the exact values.
    /// Terrain error is measured against these, so a bound holds for the map, not for its rounding.
    pub exact: Option<ExactHeights>,
}

/// A map's exact heights ([`Heightfield::exact`]).
#[derive(Debug, Clone, PartialEq)]
pub enum ExactHeights {
    /// One f64 per sample.
    Values(Arc<[f64]>),
    /// One integer code per sample (a pixel's value) and the encoding's map from codes to metres,
    /// applied on every read: 4 bytes a sample instead of 8 (an 8193² gray map keeps 268 MB, not
    /// 537 MB, beside its f32 heights).
    Codes { codes: Arc<[u32]>, map: CodeMap },
    /// Codes of a small range (gray: at most 3 × 65535 + 1) and every code's height, computed once
    /// by its [`CodeMap`]: a read is a look-up, not the map's two divisions.
    Table { codes: Arc<[u32]>, heights: Arc<[f64]> },
}

impl ExactHeights {
    /// The heights of `codes` by `map`: a table when the codes' range is small.
    pub fn coded(codes: Vec<u32>, map: CodeMap) -> ExactHeights {
        let top = codes.iter().copied().max().unwrap_or(0);
        if matches!(map, CodeMap::Gray { .. }) && top < 1 << 18 {
            let heights = (0..=top).map(|c| map.metres(c)).collect();
            ExactHeights::Table { codes: codes.into(), heights }
        } else {
            ExactHeights::Codes { codes: codes.into(), map }
        }
    }

    #[inline]
    pub fn at(&self, k: usize) -> f64 {
        match self {
            ExactHeights::Values(v) => v[k],
            ExactHeights::Codes { codes, map } => map.metres(codes[k]),
            ExactHeights::Table { codes, heights } => heights[codes[k] as usize],
        }
    }
}

/// How an integer-coded encoding turns a pixel's code into metres: the f64 operations its decoder
/// defines, in their order, so a height computed again is bit-identical to the decoded one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CodeMap {
    /// `offset + (code / divisor) / vmax · scale`: gray (divisor 1: the pixel's value; 3: the sum
    /// of R, G and B of gray stored as RGB), and raw 16-bit maps.
    Gray { offset: f64, scale: f64, vmax: f64, divisor: f64 },
    /// Mapbox Terrain-RGB, code = R·65536 + G·256 + B: `code · 0.1 − 10000`.
    TerrainRgb,
    /// Mapzen Terrarium, code = R·65536 + G·256 + B: `R·256 + G + B/256 − 32768`, which is
    /// `code / 256 − 32768` exactly (every partial sum is an exact dyadic number).
    Terrarium,
}

impl CodeMap {
    #[inline]
    pub fn metres(&self, code: u32) -> f64 {
        match *self {
            CodeMap::Gray { offset, scale, vmax, divisor } => offset + code as f64 / divisor / vmax * scale,
            CodeMap::TerrainRgb => code as f64 * 0.1 - 10000.0,
            CodeMap::Terrarium => code as f64 / 256.0 - 32768.0,
        }
    }
}

impl Heightfield {
    /// Height in metres at sample (i, j). Panics if out of range (callers index within bounds).
    #[inline]
    pub fn at(&self, i: usize, j: usize) -> f32 {
        self.heights[j * self.width + i]
    }

    /// Builds a heightfield from heights in f64, keeping them as [`Heightfield::exact`] when any
    /// of them is not exactly a 32-bit float.
    pub fn from_f64(width: usize, height: usize, heights: &[f64], cell_size_m: f64) -> Heightfield {
        let narrow: Vec<f32> = heights.iter().map(|&h| h as f32).collect();
        let exact =
            narrow.iter().zip(heights).any(|(&n, &h)| n as f64 != h).then(|| ExactHeights::Values(heights.into()));
        Heightfield { width, height, heights: narrow, cell_size_m, exact }
    }

    /// Builds a heightfield from integer codes and their map to metres, keeping the codes as
    /// [`Heightfield::exact`] when any height is not exactly a 32-bit float.
    pub fn from_codes(width: usize, height: usize, codes: Vec<u32>, map: CodeMap, cell_size_m: f64) -> Heightfield {
        // each code's height computed once: narrowed, and compared with its narrowing
        let mut inexact = false;
        let narrow: Vec<f32> = codes
            .iter()
            .map(|&c| {
                let exact = map.metres(c);
                inexact |= exact as f32 as f64 != exact;
                exact as f32
            })
            .collect();
        let exact = inexact.then(|| ExactHeights::coded(codes, map));
        Heightfield { width, height, heights: narrow, cell_size_m, exact }
    }

    /// The reference height of sample k (row-major): exact where the encoding's values are not
    /// 32-bit floats, else the stored height.
    #[inline]
    pub fn reference(&self, k: usize) -> f64 {
        match &self.exact {
            Some(e) => e.at(k),
            None => self.heights[k] as f64,
        }
    }

    /// Rows `j0..=j1` of the map as a map of their own (heights and reference heights alike):
    /// a band's window, sample (i, j) of which is the map's (i, j0 + j). `None` when the rows are
    /// not within the map.
    pub fn rows(&self, j0: usize, j1: usize) -> Option<Heightfield> {
        if j0 > j1 || j1 >= self.height {
            return None;
        }
        let range = j0 * self.width..(j1 + 1) * self.width;
        let slice = |codes: &Arc<[u32]>| -> Arc<[u32]> { codes[range.clone()].into() };
        let exact = self.exact.as_ref().map(|e| match e {
            ExactHeights::Values(v) => ExactHeights::Values(v[range.clone()].into()),
            ExactHeights::Codes { codes, map } => ExactHeights::Codes { codes: slice(codes), map: *map },
            ExactHeights::Table { codes, heights } => {
                ExactHeights::Table { codes: slice(codes), heights: heights.clone() }
            }
        });
        Some(Heightfield {
            width: self.width,
            height: j1 - j0 + 1,
            heights: self.heights[range.clone()].to_vec(),
            cell_size_m: self.cell_size_m,
            exact,
        })
    }

    /// Largest |stored − reference| height over all samples (0 when the heights are exact).
    pub fn rounding_m(&self) -> f64 {
        match &self.exact {
            Some(e) => self.heights.iter().enumerate().fold(0.0f64, |m, (k, &h)| m.max((e.at(k) - h as f64).abs())),
            None => 0.0,
        }
    }

    /// World position of sample (i, j), the one place the axis contract is written down.
    #[inline]
    pub fn position(&self, i: usize, j: usize) -> [f32; 3] {
        [(i as f64 * self.cell_size_m) as f32, self.at(i, j), (j as f64 * self.cell_size_m) as f32]
    }

    /// UV0 of sample (i, j): planar over the map, u = i/(w−1), v = j/(h−1). Row 0 is the heightmap
    /// image's top row and glTF's v runs down from the image top, so a texture made from the heightmap's
    /// pixels lands on its samples. Exactly 0 and 1 at the corners. Needs a map of at least 2×2.
    #[inline]
    pub fn planar_uv(&self, i: usize, j: usize) -> [f32; 2] {
        [(i as f64 / (self.width - 1) as f64) as f32, (j as f64 / (self.height - 1) as f64) as f32]
    }

    /// Lowest and highest height, or `None` when empty.
    pub fn height_range(&self) -> Option<(f32, f32)> {
        let first = *self.heights.first()?;
        Some(self.heights.iter().fold((first, first), |(lo, hi), &h| (lo.min(h), hi.max(h))))
    }

    /// Unit surface normal at sample (i, j) from the heights alone, in f64: n ∝ (−∂h/∂x, 1, −∂h/∂z)
    /// with central differences inside and one-sided differences on the border (a map one sample
    /// wide has zero slope along that axis). Taken from the samples, not from any triangulation, so
    /// shading does not show the mesh. Panics if (i, j) is out of range, like [`Heightfield::at`].
    pub fn normal_at(&self, i: usize, j: usize) -> [f64; 3] {
        MapRows::whole(self).normal_at(i, j)
    }

    /// The height bilinearly interpolated at continuous sample coordinates (s, t) (x = s·cell,
    /// z = t·cell), clamped to the map.
    pub fn height_bilinear(&self, s: f64, t: f64) -> f64 {
        MapRows::whole(self).height_bilinear(s, t)
    }

    /// The unit normal at continuous sample coordinates (s, t): the four surrounding samples'
    /// [`Heightfield::normal_at`] bilinearly interpolated and normalised (straight up if they cancel).
    pub fn normal_bilinear(&self, s: f64, t: f64) -> [f64; 3] {
        MapRows::whole(self).normal_bilinear(s, t)
    }
}

/// How the pixel values of a heightmap file map to metres.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Encoding {
    /// Decide by file extension and channels.
    Auto,
    /// 8/16-bit gray (or RGB with R = G = B): y = offset + v / vmax · scale.
    Gray,
    /// Mapbox Terrain-RGB: y = (R·65536 + G·256 + B) · 0.1 − 10000 m.
    TerrainRgb,
    /// Mapzen/AWS Terrarium: y = R·256 + G + B/256 − 32768 m.
    Terrarium,
    /// SRTM .hgt: big-endian int16 metres, square, −32768 = void.
    Hgt,
    /// Raw little-endian unsigned 16-bit (.r16/.raw), needs --size: scaled like 16-bit gray.
    R16,
    /// 32-bit float TIFF, metres.
    Float,
}

impl fmt::Display for Encoding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Encoding::Auto => "auto",
            Encoding::Gray => "gray",
            Encoding::TerrainRgb => "terrain-rgb",
            Encoding::Terrarium => "terrarium",
            Encoding::Hgt => "hgt",
            Encoding::R16 => "r16",
            Encoding::Float => "float",
        })
    }
}

/// Default limit on width × height: 8193 × 8193 samples (about 6 GiB of peak working memory
/// for a fine TIN). Raise it with `--max-samples` on a machine that has the memory.
pub const DEFAULT_MAX_SAMPLES: usize = 8193 * 8193;

/// Heights beyond ±1,000 km are refused at decoding: no terrain reaches them (Earth spans −11 km
/// to 9 km, Olympus Mons 22 km), and near f32's range (±3.4·10³⁸) differences of heights overflow
/// and every error figure loses its meaning (a float TIFF of 10³⁰ m "met" a 1 m bound by 10²⁴ m).
pub const MAX_ABS_HEIGHT_M: f32 = 1.0e6;

/// A terrain spans at most 40,000 km (Earth's circumference) along either side: a larger sample
/// spacing is a unit mistake, and near f32's range positions become infinite (a cell size of
/// 10³⁰⁰ m wrote infinite vertices).
pub const MAX_EXTENT_M: f64 = 4.0e7;

/// Refuses a cell size that puts a `width` × `height` map beyond [`MAX_EXTENT_M`]: the problem
/// (without the file, which the caller names).
pub fn check_extent(width: usize, height: usize, cell_size_m: f64) -> Result<(), String> {
    let extent = (width.max(height).saturating_sub(1)) as f64 * cell_size_m;
    if extent <= MAX_EXTENT_M {
        return Ok(());
    }
    Err(format!(
        "a cell size of {cell_size_m:e} m (--cell-size, or `cell_size` in a preset) makes the {width}×{height} map {extent:e} m across, \
         beyond the {MAX_EXTENT_M:e} m (Earth's circumference) a terrain may span; give the distance between neighbouring samples in metres"
    ))
}

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DecodeOptions {
    pub encoding: Encoding,
    /// Width × height for raw files (`.r16`/`.raw`).
    pub size: Option<(usize, usize)>,
    pub cell_size_m: f64,
    /// Gray and r16: metres spanned by the full value range (0..vmax).
    pub height_scale_m: f64,
    /// Gray and r16: metres added to every height.
    pub height_offset_m: f64,
    pub max_samples: usize,
}

impl Default for DecodeOptions {
    fn default() -> Self {
        DecodeOptions {
            encoding: Encoding::Auto,
            size: None,
            cell_size_m: 1.0,
            height_scale_m: 100.0,
            height_offset_m: 0.0,
            max_samples: DEFAULT_MAX_SAMPLES,
        }
    }
}

/// A decoded heightmap and what the decoder found out about it.
#[derive(Debug, Clone)]
pub struct Decoded {
    pub heightfield: Heightfield,
    /// The encoding actually used (never `Auto`).
    pub encoding: Encoding,
    /// Void samples (SRTM −32768) filled from their valid neighbours.
    pub voids_filled: usize,
}

#[derive(Debug, thiserror::Error)]
pub enum HeightfieldError {
    #[error("{path}: cannot read the file: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: the file is empty; expected a heightmap (PNG, TIFF, .hgt, .r16/.raw)")]
    Empty { path: PathBuf },
    #[error("{path}: cannot decode the image: {message}. Is the file complete and really a PNG/TIFF? Re-export it, or pick --encoding hgt/r16 (`encoding` in a preset) for raw data")]
    Image { path: PathBuf, message: String },
    #[error("{path}: {width}×{height} = {samples} samples exceeds the limit of {limit}; downsample the map, split it into tiles, or raise --max-samples (`max_samples` in a preset's [terrain]) if this machine has the memory")]
    TooLarge { path: PathBuf, width: usize, height: usize, samples: u128, limit: usize },
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    #[error("{path}: invalid option: {message}")]
    Options { path: PathBuf, message: String },
}

impl HeightfieldError {
    fn format(path: &Path, message: impl Into<String>) -> Self {
        HeightfieldError::Format { path: path.to_owned(), message: message.into() }
    }
}

/// Reads and decodes the heightmap at `path` into metres.
pub fn load(path: &Path, opts: &DecodeOptions) -> Result<Decoded, HeightfieldError> {
    if !(opts.cell_size_m.is_finite() && opts.cell_size_m > 0.0) {
        return Err(HeightfieldError::Options {
            path: path.to_owned(),
            message: format!(
                "--cell-size (`cell_size` in a preset) must be a positive number of metres, got {}",
                opts.cell_size_m
            ),
        });
    }
    if !(opts.height_scale_m.is_finite() && opts.height_offset_m.is_finite()) {
        return Err(HeightfieldError::Options {
            path: path.to_owned(),
            message: "--height-scale and --height-offset (`height_scale`, `height_offset` in a preset) must be finite"
                .into(),
        });
    }
    let bytes = crate::input::read_limited(path, crate::input::MAX_HEIGHTMAP_BYTES, "a heightmap")
        .map_err(|e| HeightfieldError::Io { path: path.to_owned(), source: e.into_io() })?;
    decode(path, &bytes, opts)
}

/// Decodes heightmap `bytes`; `path` names the source in messages and decides `auto` by extension.
pub fn decode(path: &Path, bytes: &[u8], opts: &DecodeOptions) -> Result<Decoded, HeightfieldError> {
    if bytes.is_empty() {
        return Err(HeightfieldError::Empty { path: path.to_owned() });
    }
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let encoding = match opts.encoding {
        Encoding::Auto => match ext.as_str() {
            "hgt" => Encoding::Hgt,
            "r16" | "raw" => Encoding::R16,
            _ => Encoding::Auto, // decided from the image's channels below
        },
        e => e,
    };
    let decoded = match encoding {
        Encoding::Hgt => decode_hgt(path, bytes, opts)?,
        Encoding::R16 => decode_r16(path, bytes, opts)?,
        _ => decode_image(path, bytes, encoding, opts)?,
    };
    finish_decoded(path, decoded, opts, &|j| j)
}

/// What [`decode`] checks and sets on every decoded map (`row_of` names a row of the map as the
/// file's, for the errors).
fn finish_decoded(
    path: &Path,
    mut decoded: Decoded,
    opts: &DecodeOptions,
    row_of: &dyn Fn(usize) -> usize,
) -> Result<Decoded, HeightfieldError> {
    decoded.heightfield.cell_size_m = opts.cell_size_m;
    let (w, h) = (decoded.heightfield.width, decoded.heightfield.height);
    check_extent(w, h, opts.cell_size_m)
        .map_err(|message| HeightfieldError::Options { path: path.to_owned(), message })?;
    if let Some(k) = decoded.heightfield.heights.iter().position(|h| !(h.is_finite() && h.abs() <= MAX_ABS_HEIGHT_M)) {
        let w = decoded.heightfield.width;
        let h = decoded.heightfield.heights[k];
        let what = if h.is_finite() {
            format!("is {h:e} m, beyond the ±{MAX_ABS_HEIGHT_M:e} m terrain heights are limited to")
        } else {
            "is not a finite height".into()
        };
        // gray and r16 heights are the scale and offset applied to the samples: those are to blame
        let remedy = match decoded.encoding {
            Encoding::Gray | Encoding::R16 => {
                let metres = |m: f64| {
                    if m != 0.0 && !(1e-3..1e9).contains(&m.abs()) {
                        format!("{m:e}")
                    } else {
                        format!("{m}")
                    }
                };
                format!(
                    "--height-scale {} and --height-offset {} (`height_scale`, `height_offset` in a preset) take heights there; use metres that fit",
                    metres(opts.height_scale_m),
                    metres(opts.height_offset_m)
                )
            }
            _ => "fix or fill the map before meshing (or check --encoding, `encoding` in a preset)".into(),
        };
        return Err(HeightfieldError::format(
            path,
            format!("sample (column {}, row {}) {what}; {remedy}", k % w, row_of(k / w)),
        ));
    }
    Ok(decoded)
}

fn check_size(path: &Path, width: usize, height: usize, opts: &DecodeOptions) -> Result<(), HeightfieldError> {
    let samples = width as u128 * height as u128;
    if samples > opts.max_samples as u128 {
        return Err(HeightfieldError::TooLarge {
            path: path.to_owned(),
            width,
            height,
            samples,
            limit: opts.max_samples,
        });
    }
    if width == 0 || height == 0 {
        return Err(HeightfieldError::format(path, format!("the map has no samples ({width}×{height})")));
    }
    Ok(())
}

fn heightfield(width: usize, height: usize, heights: Vec<f32>) -> Heightfield {
    Heightfield { width, height, heights, cell_size_m: 1.0, exact: None }
}

/// SRTM .hgt: a square of big-endian int16 metres; −32768 marks a void.
fn decode_hgt(path: &Path, bytes: &[u8], opts: &DecodeOptions) -> Result<Decoded, HeightfieldError> {
    if !bytes.len().is_multiple_of(2) {
        return Err(HeightfieldError::format(
            path,
            format!(
                "a .hgt file holds 16-bit samples, but its size ({} bytes) is odd; the file is truncated or not SRTM",
                bytes.len()
            ),
        ));
    }
    let n = bytes.len() / 2;
    let side = (n as f64).sqrt().round() as usize;
    if side * side != n {
        return Err(HeightfieldError::format(
            path,
            format!("a .hgt file is a square of 16-bit samples (1201² for SRTM3, 3601² for SRTM1), but {} samples is not a square; the file is truncated or not SRTM", n),
        ));
    }
    check_size(path, side, side, opts)?;
    const VOID: i16 = -32768;
    let raw: Vec<i16> = bytes.chunks_exact(2).map(|c| i16::from_be_bytes([c[0], c[1]])).collect();
    let valid: Vec<bool> = raw.iter().map(|&v| v != VOID).collect();
    let mut heights: Vec<f32> = raw.iter().map(|&v| v as f32).collect();
    let voids_filled = fill_voids(side, side, &mut heights, valid).map_err(|_| {
        HeightfieldError::format(path, "every sample is a void (−32768); there is no height data to mesh")
    })?;
    Ok(Decoded { heightfield: heightfield(side, side, heights), encoding: Encoding::Hgt, voids_filled })
}

/// [`fill_voids`] found no valid sample to fill from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NothingValid;

/// Fills samples with `valid == false` from their valid neighbours: breadth-first from the valid
/// region, each void takes the mean of its already-known 4-neighbours (deterministic, one pass per
/// ring). Returns the number filled, or [`NothingValid`] if no sample is valid.
pub fn fill_voids(
    width: usize,
    height: usize,
    heights: &mut [f32],
    mut known: Vec<bool>,
) -> Result<usize, NothingValid> {
    let total_void = known.iter().filter(|&&k| !k).count();
    if total_void == 0 {
        return Ok(0);
    }
    if total_void == known.len() {
        return Err(NothingValid);
    }
    let neighbours = |k: usize| {
        let (i, j) = (k % width, k / width);
        let mut out = [usize::MAX; 4];
        if i > 0 {
            out[0] = k - 1;
        }
        if i + 1 < width {
            out[1] = k + 1;
        }
        if j > 0 {
            out[2] = k - width;
        }
        if j + 1 < height {
            out[3] = k + width;
        }
        out
    };
    // first ring: voids touching a valid sample
    let mut ring: Vec<usize> =
        (0..known.len()).filter(|&k| !known[k] && neighbours(k).iter().any(|&n| n != usize::MAX && known[n])).collect();
    let mut in_ring = vec![false; known.len()];
    for &k in &ring {
        in_ring[k] = true;
    }
    while !ring.is_empty() {
        // values of this ring from previously known samples only, so the order within a ring is irrelevant
        let values: Vec<f32> = ring
            .iter()
            .map(|&k| {
                let (sum, count) = neighbours(k)
                    .iter()
                    .filter(|&&n| n != usize::MAX && known[n])
                    .fold((0.0f64, 0u32), |(s, c), &n| (s + heights[n] as f64, c + 1));
                (sum / count as f64) as f32
            })
            .collect();
        for (&k, v) in ring.iter().zip(values) {
            heights[k] = v;
            known[k] = true;
        }
        let mut next = Vec::new();
        for &k in &ring {
            for n in neighbours(k) {
                if n != usize::MAX && !known[n] && !in_ring[n] {
                    in_ring[n] = true;
                    next.push(n);
                }
            }
        }
        next.sort_unstable();
        ring = next;
    }
    Ok(total_void)
}

/// Raw little-endian unsigned 16-bit samples, row-major, size given by `--size WxH` (a square is
/// inferred when the size is omitted and the sample count is a perfect square).
fn decode_r16(path: &Path, bytes: &[u8], opts: &DecodeOptions) -> Result<Decoded, HeightfieldError> {
    let n = bytes.len() / 2;
    let (width, height) = match opts.size {
        Some(s) => s,
        None => {
            let side = (n as f64).sqrt().round() as usize;
            if side * side != n || !bytes.len().is_multiple_of(2) {
                return Err(HeightfieldError::format(
                    path,
                    format!("a raw 16-bit heightmap needs its size: pass --size WIDTHxHEIGHT, or `size = [WIDTH, HEIGHT]` in a preset ({} bytes is not a square of 16-bit samples)", bytes.len()),
                ));
            }
            (side, side)
        }
    };
    check_size(path, width, height, opts)?;
    let expected = width as u128 * height as u128 * 2;
    if bytes.len() as u128 != expected {
        return Err(HeightfieldError::format(
            path,
            format!("--size {width}x{height} needs {expected} bytes of little-endian 16-bit samples, but the file has {}; check --size (`size` in a preset) and the byte order", bytes.len()),
        ));
    }
    let map = CodeMap::Gray { offset: opts.height_offset_m, scale: opts.height_scale_m, vmax: 65535.0, divisor: 1.0 };
    let codes: Vec<u32> = bytes.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]]) as u32).collect();
    Ok(Decoded {
        heightfield: Heightfield::from_codes(width, height, codes, map, 1.0),
        encoding: Encoding::R16,
        voids_filled: 0,
    })
}

fn image_error(path: &Path, e: impl fmt::Display) -> HeightfieldError {
    HeightfieldError::Image { path: path.to_owned(), message: e.to_string() }
}

/// PNG / TIFF (and anything else the `image` crate reads) by encoding.
fn decode_image(
    path: &Path,
    bytes: &[u8],
    encoding: Encoding,
    opts: &DecodeOptions,
) -> Result<Decoded, HeightfieldError> {
    let is_tiff = is_tiff(bytes);
    if is_tiff {
        if let Some(decoded) = decode_float_tiff(path, bytes, encoding, opts)? {
            return Ok(decoded);
        }
    }
    if encoding == Encoding::Float {
        return Err(HeightfieldError::format(path, "--encoding float needs a 32-bit float TIFF; this file is not one (for 8/16-bit images use gray, terrain-rgb or terrarium: --encoding, or `encoding` in a preset)"));
    }
    if bytes.starts_with(PNG_SIGNATURE) {
        if let Some(decoded) = decode_png_rows(path, Cursor::new(bytes), encoding, opts, None)? {
            return Ok(decoded);
        }
    }
    decode_whole_image(path, bytes, encoding, opts)
}

/// Any 8/16-bit image the `image` crate reads, decoded whole, then turned into height codes.
fn decode_whole_image(
    path: &Path,
    bytes: &[u8],
    encoding: Encoding,
    opts: &DecodeOptions,
) -> Result<Decoded, HeightfieldError> {
    // (the `image` crate's guess knows TIFF's signatures but not BigTIFF's, which its TIFF decoder reads)
    let reader = || -> Result<image::ImageReader<Cursor<&[u8]>>, HeightfieldError> {
        let mut reader =
            image::ImageReader::new(Cursor::new(bytes)).with_guessed_format().map_err(|e| image_error(path, e))?;
        if reader.format().is_none() && is_tiff(bytes) {
            reader.set_format(image::ImageFormat::Tiff);
        }
        Ok(reader)
    };
    let header = reader()?;
    if header.format().is_none() {
        return Err(HeightfieldError::Image {
            path: path.to_owned(),
            message: "the content is not a recognised image format (PNG or TIFF expected)".into(),
        });
    }
    let (width, height) = header.into_dimensions().map_err(|e| image_error(path, e))?;
    check_size(path, width as usize, height as usize, opts)?;
    let mut reader = reader()?;
    reader.no_limits(); // the size was checked against our own limit above
    let img = reader.decode().map_err(|e| image_error(path, e))?;
    let (w, h) = (width as usize, height as usize);
    use image::DynamicImage as D;
    let gray = |vmax: f64, divisor: f64| CodeMap::Gray {
        offset: opts.height_offset_m,
        scale: opts.height_scale_m,
        vmax,
        divisor,
    };
    // the samples (one a pixel for gray, three for RGB), moved out of the image where it holds
    // them so (a converted copy only for images with alpha), dropped before the heights are made
    enum Samples {
        Eight(Vec<u8>),
        Sixteen(Vec<u16>),
    }
    let color = img.color();
    let gray_image = matches!(img, D::ImageLuma8(_) | D::ImageLumaA8(_) | D::ImageLuma16(_) | D::ImageLumaA16(_));
    let samples = match img {
        D::ImageLuma8(b) => Some(Samples::Eight(b.into_raw())),
        D::ImageLuma16(b) => Some(Samples::Sixteen(b.into_raw())),
        D::ImageRgb8(b) => Some(Samples::Eight(b.into_raw())),
        D::ImageRgb16(b) => Some(Samples::Sixteen(b.into_raw())),
        i @ D::ImageLumaA8(_) => Some(Samples::Eight(i.into_luma8().into_raw())),
        i @ D::ImageLumaA16(_) => Some(Samples::Sixteen(i.into_luma16().into_raw())),
        i @ D::ImageRgba8(_) => Some(Samples::Eight(i.into_rgb8().into_raw())),
        i @ D::ImageRgba16(_) => Some(Samples::Sixteen(i.into_rgb16().into_raw())),
        _ => None,
    };
    if gray_image && !matches!(encoding, Encoding::Auto | Encoding::Gray) {
        return Err(HeightfieldError::format(
            path,
            format!("--encoding {encoding} needs an RGB image, but this one is grayscale; use --encoding gray (or auto; `encoding = \"gray\"` in a preset)"),
        ));
    }
    let eight_bit_rgb = matches!(samples, Some(Samples::Eight(_))) && !gray_image;
    let (encoding, codes, map): (Encoding, Vec<u32>, CodeMap) = match (samples, encoding) {
        (Some(samples), Encoding::Auto | Encoding::Gray) => {
            let (vmax, value): (f64, Box<dyn Fn(usize) -> u32>) = match &samples {
                Samples::Eight(v) => (255.0, Box::new(|k| v[k] as u32)),
                Samples::Sixteen(v) => (65535.0, Box::new(|k| v[k] as u32)),
            };
            if gray_image {
                (Encoding::Gray, (0..w * h).map(value).collect(), gray(vmax, 1.0))
            } else {
                let px = |k: usize| [value(3 * k), value(3 * k + 1), value(3 * k + 2)];
                if encoding == Encoding::Auto {
                    if let Some(k) = (0..w * h).position(|k| {
                        let p = px(k);
                        p[0] != p[1] || p[1] != p[2]
                    }) {
                        let p = px(k);
                        return Err(HeightfieldError::format(
                            path,
                            format!(
                                "an RGB image whose channels differ (pixel column {}, row {} is R={} G={} B={}) is not a gray heightmap; choose how to read it: --encoding terrain-rgb (Mapbox), --encoding terrarium (Mapzen), or --encoding gray (uses the mean of R, G, B); `encoding` in a preset",
                                k % w, k / w, p[0], p[1], p[2]
                            ),
                        ));
                    }
                }
                // gray stored as RGB: the mean of the channels (equal to each channel when R = G = B)
                let codes = (0..w * h)
                    .map(|k| {
                        let p = px(k);
                        p[0] + p[1] + p[2]
                    })
                    .collect();
                (Encoding::Gray, codes, gray(vmax, 3.0))
            }
        }
        (Some(Samples::Eight(raw)), Encoding::TerrainRgb | Encoding::Terrarium) if eight_bit_rgb => {
            let map = if encoding == Encoding::TerrainRgb { CodeMap::TerrainRgb } else { CodeMap::Terrarium };
            let codes = raw.chunks_exact(3).map(|c| (c[0] as u32) << 16 | (c[1] as u32) << 8 | c[2] as u32).collect();
            (encoding, codes, map)
        }
        (_, Encoding::TerrainRgb | Encoding::Terrarium) => {
            return Err(HeightfieldError::format(
                path,
                format!("--encoding {encoding} (`encoding` in a preset) needs an 8-bit RGB or RGBA image"),
            ));
        }
        (_, e) => {
            return Err(HeightfieldError::format(
                path,
                format!("unsupported pixel format {color:?} for --encoding {e} (`encoding` in a preset); use an 8/16-bit gray or RGB PNG/TIFF, or a 32-bit float TIFF"),
            ));
        }
    };
    Ok(Decoded { heightfield: Heightfield::from_codes(w, h, codes, map, 1.0), encoding, voids_filled: 0 })
}

const PNG_SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";

/// Whether `bytes` begin as a TIFF or a BigTIFF (either byte order) does.
fn is_tiff(bytes: &[u8]) -> bool {
    [b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"].iter().any(|m| bytes.starts_with(*m))
}

/// A PNG decoded a row at a time straight into height codes: no image buffer and no converted copy
/// beside the codes (for an 8193² map 0.13–0.2 GB each that `decode_image` holds at once). The
/// same `png` decoder and transformations as the `image` crate's (EXPAND: palettes to RGB(A),
/// gray under 8 bits to 8), so the same codes, the same errors (tested against it). Ok(None) for
/// an interlaced PNG, whose rows arrive in passes: `decode_image` reads it whole.
/// Kept rows: which rows to keep, and the list of those kept (file rows, in order).
type KeepRows<'a> = (&'a dyn Fn(usize) -> bool, &'a mut Vec<usize>);

fn decode_png_rows<R: std::io::BufRead + std::io::Seek>(
    path: &Path,
    source: R,
    encoding: Encoding,
    opts: &DecodeOptions,
    mut keep: Option<KeepRows<'_>>,
) -> Result<Option<Decoded>, HeightfieldError> {
    let mut decoder = png::Decoder::new_with_limits(source, png::Limits { bytes: usize::MAX });
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder.read_info().map_err(|e| image_error(path, e))?;
    if reader.info().interlaced {
        return Ok(None);
    }
    let (w, h) = (reader.info().width as usize, reader.info().height as usize);
    check_size(path, w, h, opts)?;
    let (color, depth) = reader.output_color_type();
    let sixteen = depth == png::BitDepth::Sixteen;
    if !matches!(depth, png::BitDepth::Eight | png::BitDepth::Sixteen) {
        return Ok(None); // (EXPAND leaves none: the image crate's refusal, whatever it says)
    }
    let (channels, gray_image) = match color {
        png::ColorType::Grayscale => (1, true),
        png::ColorType::GrayscaleAlpha => (2, true),
        png::ColorType::Rgb => (3, false),
        png::ColorType::Rgba => (4, false),
        png::ColorType::Indexed => return Ok(None),
    };
    let vmax = if sixteen { 65535.0 } else { 255.0 };
    let asked = encoding;
    let gray = |divisor: f64| CodeMap::Gray { offset: opts.height_offset_m, scale: opts.height_scale_m, vmax, divisor };
    let (encoding, map) = match (gray_image, encoding) {
        (true, Encoding::Auto | Encoding::Gray) => (Encoding::Gray, gray(1.0)),
        (true, e) => {
            return Err(HeightfieldError::format(
                path,
                format!("--encoding {e} needs an RGB image, but this one is grayscale; use --encoding gray (or auto; `encoding = \"gray\"` in a preset)"),
            ));
        }
        (false, Encoding::Auto | Encoding::Gray) => (Encoding::Gray, gray(3.0)),
        (false, Encoding::TerrainRgb | Encoding::Terrarium) if !sixteen => {
            (encoding, if encoding == Encoding::TerrainRgb { CodeMap::TerrainRgb } else { CodeMap::Terrarium })
        }
        (false, Encoding::TerrainRgb | Encoding::Terrarium) => {
            return Err(HeightfieldError::format(
                path,
                format!("--encoding {encoding} (`encoding` in a preset) needs an 8-bit RGB or RGBA image"),
            ));
        }
        _ => return Ok(None),
    };
    let kept_rows = keep.as_ref().map_or(h, |(k, _)| (0..h).filter(|&j| k(j)).count());
    let mut codes = Vec::with_capacity(w * kept_rows);
    let mut row_index = 0;
    while let Some(row) = reader.next_row().map_err(|e| image_error(path, e))? {
        let data = row.data();
        let kept = match keep.as_mut() {
            Some((k, list)) if k(row_index) => {
                list.push(row_index);
                true
            }
            Some(_) => false,
            None => true,
        };
        let value = |k: usize| -> u32 {
            if sixteen {
                u16::from_be_bytes([data[2 * k], data[2 * k + 1]]) as u32
            } else {
                data[k] as u32
            }
        };
        for i in 0..w {
            let at = i * channels;
            let code = if gray_image {
                value(at)
            } else {
                let p = [value(at), value(at + 1), value(at + 2)];
                match map {
                    CodeMap::TerrainRgb | CodeMap::Terrarium => p[0] << 16 | p[1] << 8 | p[2],
                    _ => {
                        if asked == Encoding::Auto && (p[0] != p[1] || p[1] != p[2]) {
                            return Err(HeightfieldError::format(
                                path,
                                format!(
                                    "an RGB image whose channels differ (pixel column {i}, row {row_index} is R={} G={} B={}) is not a gray heightmap; choose how to read it: --encoding terrain-rgb (Mapbox), --encoding terrarium (Mapzen), or --encoding gray (uses the mean of R, G, B); `encoding` in a preset",
                                    p[0], p[1], p[2]
                                ),
                            ));
                        }
                        p[0] + p[1] + p[2]
                    }
                }
            };
            if kept {
                codes.push(code);
            }
        }
        row_index += 1;
    }
    if row_index != h || codes.len() != w * kept_rows {
        return Err(image_error(path, format!("the image data end after {row_index} of {h} rows")));
    }
    let heightfield = Heightfield::from_codes(w, kept_rows, codes, map, 1.0);
    Ok(Some(Decoded { heightfield, encoding, voids_filled: 0 }))
}

/// 32-bit float single-channel TIFF in metres. Returns Ok(None) for TIFFs of other sample types,
/// which the `image` crate then decodes.
fn decode_float_tiff(
    path: &Path,
    bytes: &[u8],
    encoding: Encoding,
    opts: &DecodeOptions,
) -> Result<Option<Decoded>, HeightfieldError> {
    use tiff::decoder::{Decoder, DecodingResult, Limits};
    let tiff_err = |e: tiff::TiffError| image_error(path, e);
    let mut dec = Decoder::new(Cursor::new(bytes)).map_err(tiff_err)?;
    let color = dec.colortype().map_err(tiff_err)?;
    let is_float_gray = matches!(color, tiff::ColorType::Gray(32)) && {
        let fmt = dec.find_tag(tiff::tags::Tag::SampleFormat).ok().flatten();
        matches!(fmt.and_then(|v| v.into_u16().ok()), Some(3))
    };
    if !is_float_gray {
        return Ok(None);
    }
    if !matches!(encoding, Encoding::Auto | Encoding::Float) {
        return Err(HeightfieldError::format(
            path,
            format!("this is a 32-bit float TIFF (metres); use --encoding float or auto (`encoding` in a preset), not {encoding}"),
        ));
    }
    let (w, h) = dec.dimensions().map_err(tiff_err)?;
    check_size(path, w as usize, h as usize, opts)?;
    dec = dec.with_limits(Limits::unlimited());
    let heights = match dec.read_image().map_err(tiff_err)? {
        DecodingResult::F32(v) => v,
        _ => return Ok(None),
    };
    if heights.len() != w as usize * h as usize {
        return Err(HeightfieldError::format(
            path,
            "the TIFF's pixel data does not match its size; the file is damaged",
        ));
    }
    Ok(Some(Decoded {
        heightfield: heightfield(w as usize, h as usize, heights),
        encoding: Encoding::Float,
        voids_filled: 0,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The coded heights are the decoders' former f64 formulas, bit for bit, for every code of
    /// 8/16-bit gray (and gray stored as RGB), and for Terrain-RGB and Terrarium over their range.
    #[test]
    fn coded_heights_equal_the_encodings_formulas_bit_for_bit() {
        let (offset, scale) = (-12.5, 6553.5);
        let gray = |v: f64, vmax: f64| offset + v / vmax * scale;
        for (vmax, divisor, top) in
            [(255.0, 1.0, 255u32), (65535.0, 1.0, 65535), (65535.0, 3.0, 3 * 65535), (255.0, 3.0, 765)]
        {
            let map = CodeMap::Gray { offset, scale, vmax, divisor };
            let codes: Vec<u32> = (0..=top).collect();
            let exact = ExactHeights::coded(codes.clone(), map);
            assert!(matches!(exact, ExactHeights::Table { .. }));
            for &c in &codes {
                let v = if divisor == 1.0 { c as f64 } else { c as f64 / 3.0 };
                assert_eq!(
                    exact.at(c as usize).to_bits(),
                    gray(v, vmax).to_bits(),
                    "gray code {c} of {vmax}/{divisor}"
                );
                assert_eq!(map.metres(c).to_bits(), gray(v, vmax).to_bits());
            }
        }
        for k in 0..200_000u64 {
            let code = (crate::random::mix64(k) & 0xff_ffff) as u32;
            let (r, g, b) = ((code >> 16) as f64, ((code >> 8) & 255) as f64, (code & 255) as f64);
            let mapbox = (r * 65536.0 + g * 256.0 + b) * 0.1 - 10000.0;
            let mapzen = r * 256.0 + g + b / 256.0 - 32768.0;
            assert_eq!(CodeMap::TerrainRgb.metres(code).to_bits(), mapbox.to_bits(), "Terrain-RGB {code:#x}");
            assert_eq!(CodeMap::Terrarium.metres(code).to_bits(), mapzen.to_bits(), "Terrarium {code:#x}");
        }
    }

    #[test]
    fn a_coded_map_keeps_codes_only_when_f32_cannot_hold_its_heights() {
        let whole = CodeMap::Gray { offset: 0.0, scale: 255.0, vmax: 255.0, divisor: 1.0 };
        assert!(Heightfield::from_codes(2, 2, vec![0, 1, 2, 255], whole, 1.0).exact.is_none());
        let tenths = Heightfield::from_codes(2, 1, vec![1, 3], CodeMap::TerrainRgb, 1.0);
        assert_eq!(tenths.reference(1), 3.0 * 0.1 - 10000.0);
        assert!(matches!(tenths.exact, Some(ExactHeights::Codes { .. })));
        assert!(tenths.rounding_m() > 0.0);
    }

    /// A PNG of `w`×`h` with `color`/`depth` from the byte stream `bytes` (palette and tRNS given).
    pub(super) fn png_file(
        w: u32,
        h: u32,
        color: png::ColorType,
        depth: png::BitDepth,
        data: &[u8],
        palette: Option<Vec<u8>>,
        trns: Option<Vec<u8>>,
    ) -> Vec<u8> {
        let mut out = Vec::new();
        {
            let mut e = png::Encoder::new(&mut out, w, h);
            e.set_color(color);
            e.set_depth(depth);
            if let Some(p) = palette {
                e.set_palette(p);
            }
            if let Some(t) = trns {
                e.set_trns(t);
            }
            let mut writer = e.write_header().unwrap();
            writer.write_image_data(data).unwrap();
        }
        out
    }

    /// Row-wise PNG decoding gives what decoding the whole image with the `image` crate gives, for
    /// every PNG colour type and bit depth, every encoding, gray stored as RGB (equal channels)
    /// and not: the same heights, exact references and encoding, or the same error.
    #[test]
    fn png_rows_decode_as_the_whole_image_does() {
        use png::{BitDepth as B, ColorType as C};
        let (w, h) = (13u32, 7u32);
        let mut state = 0x1234_5678_u64;
        let mut next = move || {
            state = crate::random::mix64(state);
            state
        };
        let mut cases = 0;
        for (color, depth) in [
            (C::Grayscale, B::One),
            (C::Grayscale, B::Two),
            (C::Grayscale, B::Four),
            (C::Grayscale, B::Eight),
            (C::Grayscale, B::Sixteen),
            (C::GrayscaleAlpha, B::Eight),
            (C::GrayscaleAlpha, B::Sixteen),
            (C::Rgb, B::Eight),
            (C::Rgb, B::Sixteen),
            (C::Rgba, B::Eight),
            (C::Rgba, B::Sixteen),
            (C::Indexed, B::Eight),
            (C::Indexed, B::Four),
        ] {
            let channels = match color {
                C::Grayscale | C::Indexed => 1,
                C::GrayscaleAlpha => 2,
                C::Rgb => 3,
                C::Rgba => 4,
            };
            let bits = depth as usize;
            let row_bytes = (w as usize * channels * bits).div_ceil(8);
            for equal_channels in [true, false] {
                for trns in [false, true] {
                    if trns && !matches!(color, C::Grayscale | C::Rgb | C::Indexed) {
                        continue;
                    }
                    let mut data = vec![0u8; row_bytes * h as usize];
                    for b in &mut data {
                        *b = next() as u8;
                    }
                    if equal_channels && matches!(color, C::Rgb | C::Rgba) {
                        let px = channels * bits / 8;
                        let comp = bits / 8;
                        for pixel in data.chunks_exact_mut(px) {
                            let (r, rest) = pixel.split_at_mut(comp);
                            rest[..comp].copy_from_slice(r);
                            rest[comp..2 * comp].copy_from_slice(r);
                        }
                    }
                    let palette = (color == C::Indexed).then(|| (0..256 * 3).map(|k| (k * 7 % 251) as u8).collect());
                    let trns_chunk = trns.then(|| match color {
                        C::Indexed => vec![0, 128, 255],
                        C::Grayscale => vec![0, 1],
                        _ => vec![0, 1, 0, 2, 0, 3],
                    });
                    let file = png_file(w, h, color, depth, &data, palette, trns_chunk);
                    for encoding in [Encoding::Auto, Encoding::Gray, Encoding::TerrainRgb, Encoding::Terrarium] {
                        let opts = DecodeOptions {
                            encoding,
                            height_scale_m: 812.5,
                            height_offset_m: -3.25,
                            ..Default::default()
                        };
                        let path = Path::new("map.png");
                        let rows = decode_png_rows(path, Cursor::new(&file), encoding, &opts, None);
                        let whole = decode_whole_image(path, &file, encoding, &opts);
                        let what = format!("{color:?} {depth:?} {encoding:?} equal={equal_channels} trns={trns}");
                        match (rows, whole) {
                            (Ok(Some(a)), Ok(b)) => {
                                let (x, y) = (&a.heightfield, &b.heightfield);
                                assert_eq!((x.width, x.height, a.encoding), (y.width, y.height, b.encoding), "{what}");
                                assert_eq!(x.heights, y.heights, "{what}");
                                for k in 0..x.heights.len() {
                                    assert_eq!(
                                        x.reference(k).to_bits(),
                                        y.reference(k).to_bits(),
                                        "{what}: sample {k}"
                                    );
                                }
                                cases += 1;
                            }
                            (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string(), "{what}"),
                            (Ok(None), _) => panic!("{what}: a non-interlaced PNG left to the whole-image path"),
                            (a, b) => {
                                panic!("{what}: rows {:?}, whole {:?}", a.map(|d| d.is_some()), b.map(|d| d.encoding))
                            }
                        }
                    }
                }
            }
        }
        assert!(cases > 40, "{cases} cases decoded");
        // (the png encoder writes no interlaced files: those take the whole-image path untested here)
        // a truncated file is an error naming it
        let data: Vec<u8> = (0..w * h).map(|k| (k * 5) as u8).collect();
        let opts = DecodeOptions::default();
        let file = png_file(w, h, C::Grayscale, B::Eight, &data, None, None);
        let cut = &file[..file.len() - 20];
        let e = decode_image(Path::new("cut.png"), cut, Encoding::Auto, &opts).unwrap_err().to_string();
        assert!(e.contains("cut.png"), "{e}");
    }
}
