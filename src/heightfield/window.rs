//! A heightmap's rows alone: the rows a shard's terrain bands need, read from the file without
//! holding the rest of the map — a PNG row by row (every row inflated, the others dropped), a
//! TIFF by the strips or tiles that hold kept rows (the others never read), raw 16-bit and
//! `.hgt` files by byte range — decoded to the heights [`decode`](super::decode) gives those rows,
//! bit for bit (tested against it for every format).
//!
//! A window checks what a whole decode checks of the map (its size, its extent at the cell size)
//! and of the rows it reads (heights finite and within limits); a bad sample in rows it does not
//! read is the whole decode's to find (the merge's, in a sharded build). Where a window cannot
//! give the whole decode's heights, or the file is one the whole decoder would refuse, the readers
//! answer `None` and the caller decodes the map whole (which names what is wrong): an `.hgt` whose kept rows hold a void (a void is filled from the nearest valid
//! samples, wherever they lie), an RGB TIFF read as `auto` (every pixel must be checked for gray),
//! planar or exotic TIFF sample layouts, interlaced or palette PNGs.

use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use super::{
    check_extent, check_size, decode_png_rows, finish_decoded, heightfield, image_error, is_tiff, CodeMap,
    DecodeOptions, Decoded, Encoding, Heightfield, HeightfieldError, PNG_SIGNATURE,
};

/// Kept rows as one map (`rows[k]` is the file's row of the map's row k), or `None`: decode whole.
pub type KeptRows = Option<(Decoded, Vec<usize>)>;

/// The rows `keep` accepts of the heightmap at `path`, in order, read by window (see the module
/// docs); `None` when the file is to be decoded whole.
pub fn read_kept_rows(
    path: &Path,
    opts: &DecodeOptions,
    keep: &dyn Fn(usize) -> bool,
) -> Result<KeptRows, HeightfieldError> {
    let (file, len) = crate::input::open_limited(path, crate::input::MAX_HEIGHTMAP_BYTES, "a heightmap")
        .map_err(|e| HeightfieldError::Io { path: path.to_owned(), source: e.into_io() })?;
    kept_rows_from(path, BufReader::new(file), len, opts, keep)
}

/// Whether [`read_kept_rows`] reads the file at `path` by ranges (a TIFF's strips or tiles, raw and
/// `.hgt` byte ranges: each call costs about its rows) rather than in one pass over the whole file
/// (a PNG, whose rows are inflated in order: read every wanted row in one call).
pub fn reads_by_range(path: &Path) -> bool {
    let mut magic = [0u8; 8];
    let read = std::fs::File::open(path).and_then(|mut f| f.read_exact(&mut magic));
    read.is_ok() && magic != PNG_SIGNATURE
}

/// [`read_kept_rows`] from `source`, the `len` bytes of the file `path` names.
pub fn kept_rows_from<R: BufRead + Seek>(
    path: &Path,
    mut source: R,
    len: u64,
    opts: &DecodeOptions,
    keep: &dyn Fn(usize) -> bool,
) -> Result<KeptRows, HeightfieldError> {
    if len == 0 {
        return Ok(None);
    }
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let encoding = match (opts.encoding, ext.as_str()) {
        (Encoding::Auto, "hgt") => Encoding::Hgt,
        (Encoding::Auto, "r16" | "raw") => Encoding::R16,
        (e, _) => e,
    };
    let io = |source| HeightfieldError::Io { path: path.to_owned(), source };
    // the kept rows, and the file's height in rows (its whole extent is checked as a whole decode
    // checks it)
    let (rows, file_height) = match encoding {
        Encoding::Hgt | Encoding::R16 => {
            let rows = sixteen_bit_rows(path, &mut source, len, encoding, opts, keep).map_err(io)?;
            let height = rows.as_ref().map_or(0, |(d, _)| (len / 2) as usize / d.heightfield.width.max(1));
            (rows, height)
        }
        _ => {
            // the signature, and a PNG's height (IHDR, always the first chunk, bytes 16..24)
            let head = source.fill_buf().map_err(io)?;
            let png_height = (head.len() >= 24 && head.starts_with(PNG_SIGNATURE) && &head[12..16] == b"IHDR")
                .then(|| u32::from_be_bytes([head[20], head[21], head[22], head[23]]) as usize);
            let tiff = is_tiff(head);
            if let (Some(height), true) = (png_height, encoding != Encoding::Float) {
                let mut kept = Vec::new();
                (decode_png_rows(path, source, encoding, opts, Some((keep, &mut kept)))?.map(|d| (d, kept)), height)
            } else if tiff {
                match tiff_rows(path, source, encoding, opts, keep)? {
                    Some((decoded, rows, height)) => (Some((decoded, rows)), height),
                    None => (None, 0),
                }
            } else {
                (None, 0)
            }
        }
    };
    let Some((decoded, rows)) = rows else { return Ok(None) };
    check_extent(decoded.heightfield.width, file_height, opts.cell_size_m)
        .map_err(|message| HeightfieldError::Options { path: path.to_owned(), message })?;
    let decoded = finish_decoded(path, decoded, opts, &|j| rows.get(j).copied().unwrap_or(j))?;
    Ok(Some((decoded, rows)))
}

/// The kept rows of a raw 16-bit (`.r16`/`.raw`, little-endian) or SRTM `.hgt` (big-endian,
/// signed, voids) file, each read by its byte range. `None` where the whole decoder has a word to
/// say: a size that does not fit the file, or (`.hgt`) a void among the kept rows.
fn sixteen_bit_rows<R: Read + Seek>(
    path: &Path,
    source: &mut R,
    len: u64,
    encoding: Encoding,
    opts: &DecodeOptions,
    keep: &dyn Fn(usize) -> bool,
) -> std::io::Result<KeptRows> {
    let n = len / 2;
    let side = (n as f64).sqrt().round() as u64;
    let square = (len.is_multiple_of(2) && side * side == n).then_some((side as usize, side as usize));
    let size = if encoding == Encoding::Hgt { square } else { opts.size.or(square) };
    let Some((w, h)) = size else { return Ok(None) };
    if w as u128 * h as u128 * 2 != len as u128 || check_size(path, w, h, opts).is_err() {
        return Ok(None);
    }
    let rows: Vec<usize> = (0..h).filter(|&j| keep(j)).collect();
    let mut row = vec![0u8; 2 * w];
    let mut samples: Vec<u16> = Vec::with_capacity(w * rows.len());
    let mut at = None;
    for &j in &rows {
        let start = (j * w * 2) as u64;
        if at != Some(start) {
            source.seek(SeekFrom::Start(start))?;
        }
        source.read_exact(&mut row)?;
        at = Some(start + row.len() as u64);
        if encoding == Encoding::Hgt {
            samples.extend(row.chunks_exact(2).map(|c| u16::from_be_bytes([c[0], c[1]])));
        } else {
            samples.extend(row.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])));
        }
    }
    let decoded = if encoding == Encoding::Hgt {
        const VOID: i16 = -32768;
        if samples.iter().any(|&s| s as i16 == VOID) {
            return Ok(None);
        }
        let heights = samples.iter().map(|&s| s as i16 as f32).collect();
        Decoded { heightfield: heightfield(w, rows.len(), heights), encoding, voids_filled: 0 }
    } else {
        let map =
            CodeMap::Gray { offset: opts.height_offset_m, scale: opts.height_scale_m, vmax: 65535.0, divisor: 1.0 };
        let codes = samples.into_iter().map(u32::from).collect();
        Decoded { heightfield: Heightfield::from_codes(w, rows.len(), codes, map, 1.0), encoding, voids_filled: 0 }
    };
    Ok(Some((decoded, rows)))
}

/// The kept rows of a TIFF, from the strips or tiles holding them: 32-bit float gray (metres),
/// 8/16-bit gray (with or without alpha) and 8/16-bit RGB(A) read as gray, Terrain-RGB or
/// Terrarium — the samples the whole decoder's `tiff` decoder gives (the `image` crate reads
/// TIFFs with it), turned into heights by the same rules.
fn tiff_rows<R: Read + Seek>(
    path: &Path,
    source: R,
    encoding: Encoding,
    opts: &DecodeOptions,
    keep: &dyn Fn(usize) -> bool,
) -> Result<Option<(Decoded, Vec<usize>, usize)>, HeightfieldError> {
    use tiff::decoder::{Decoder, DecodingResult, Limits};
    use tiff::tags::Tag;
    use tiff::ColorType as C;
    let Ok(mut dec) = Decoder::new(source) else { return Ok(None) };
    let (Ok((w, h)), Ok(color)) = (dec.dimensions(), dec.colortype()) else { return Ok(None) };
    // (read as the whole decoder reads it: one value; a list, e.g. one per RGB sample, is none)
    let format = dec.find_tag(Tag::SampleFormat).ok().flatten().and_then(|v| v.into_u16().ok());
    let planar = dec.find_tag_unsigned::<u16>(Tag::PlanarConfiguration).ok().flatten().unwrap_or(1);
    if planar != 1 {
        return Ok(None);
    }
    // (channels, 16-bit, gray); float gray apart
    let layout = match (color, format.unwrap_or(1)) {
        (C::Gray(32), 3) => None,
        (C::Gray(8), 1) => Some((1, false, true)),
        (C::Gray(16), 1) => Some((1, true, true)),
        (C::GrayA(8), 1) => Some((2, false, true)),
        (C::GrayA(16), 1) => Some((2, true, true)),
        (C::RGB(8), 1) => Some((3, false, false)),
        (C::RGB(16), 1) => Some((3, true, false)),
        (C::RGBA(8), 1) => Some((4, false, false)),
        (C::RGBA(16), 1) => Some((4, true, false)),
        _ => return Ok(None),
    };
    let gray = |vmax: f64, divisor: f64| CodeMap::Gray {
        offset: opts.height_offset_m,
        scale: opts.height_scale_m,
        vmax,
        divisor,
    };
    // the heights' encoding and code map (None: float metres); where the whole decoder refuses or
    // must see every pixel (RGB as `auto`), it decodes
    let (encoding, map) = match (layout, encoding) {
        (None, Encoding::Auto | Encoding::Float) => (Encoding::Float, None),
        (Some((_, sixteen, true)), Encoding::Auto | Encoding::Gray) => {
            (Encoding::Gray, Some(gray(if sixteen { 65535.0 } else { 255.0 }, 1.0)))
        }
        (Some((_, sixteen, false)), Encoding::Gray) => {
            (Encoding::Gray, Some(gray(if sixteen { 65535.0 } else { 255.0 }, 3.0)))
        }
        (Some((_, false, false)), Encoding::TerrainRgb) => (Encoding::TerrainRgb, Some(CodeMap::TerrainRgb)),
        (Some((_, false, false)), Encoding::Terrarium) => (Encoding::Terrarium, Some(CodeMap::Terrarium)),
        _ => return Ok(None),
    };
    let (w, h) = (w as usize, h as usize);
    check_size(path, w, h, opts)?;
    let mut dec = dec.with_limits(Limits::unlimited());
    let (cw, ch) = dec.chunk_dimensions();
    let (cw, ch) = (cw as usize, ch as usize);
    if cw == 0 || ch == 0 {
        return Ok(None);
    }
    let across = w.div_ceil(cw);
    let channels = layout.map_or(1, |l| l.0);
    let rows: Vec<usize> = (0..h).filter(|&j| keep(j)).collect();
    let mut slot = vec![usize::MAX; h];
    for (k, &j) in rows.iter().enumerate() {
        slot[j] = k;
    }
    let mut heights = vec![0f32; if map.is_none() { w * rows.len() } else { 0 }];
    let mut codes = vec![0u32; if map.is_some() { w * rows.len() } else { 0 }];
    let damaged =
        || HeightfieldError::format(path, "the TIFF's pixel data does not match its size; the file is damaged");
    for down in 0..h.div_ceil(ch) {
        let (j0, j1) = (down * ch, ((down + 1) * ch).min(h));
        if !(j0..j1).any(|j| slot[j] != usize::MAX) {
            continue;
        }
        for a in 0..across {
            let (x0, dw, dh) = (a * cw, cw.min(w - a * cw), j1 - j0);
            let index = u32::try_from(down * across + a).map_err(|_| damaged())?;
            let chunk = dec.read_chunk(index).map_err(|e| image_error(path, e))?;
            let n = dw * dh * channels;
            let value: Box<dyn Fn(usize) -> u32 + '_> = match &chunk {
                DecodingResult::U8(v) if v.len() == n => Box::new(|k| v[k] as u32),
                DecodingResult::U16(v) if v.len() == n => Box::new(|k| v[k] as u32),
                DecodingResult::F32(v) if v.len() == n => {
                    for y in (0..dh).filter(|&y| slot[j0 + y] != usize::MAX) {
                        let out = slot[j0 + y] * w + x0;
                        heights[out..out + dw].copy_from_slice(&v[y * dw..(y + 1) * dw]);
                    }
                    continue;
                }
                _ => return Err(damaged()),
            };
            let Some(map) = map else { return Err(damaged()) };
            for y in (0..dh).filter(|&y| slot[j0 + y] != usize::MAX) {
                let out = slot[j0 + y] * w + x0;
                for x in 0..dw {
                    let at = (y * dw + x) * channels;
                    codes[out + x] = match (channels, map) {
                        (1 | 2, _) => value(at),
                        (_, CodeMap::Gray { .. }) => value(at) + value(at + 1) + value(at + 2),
                        _ => value(at) << 16 | value(at + 1) << 8 | value(at + 2),
                    };
                }
            }
        }
    }
    let heightfield = match map {
        Some(map) => Heightfield::from_codes(w, rows.len(), codes, map, 1.0),
        None => heightfield(w, rows.len(), heights),
    };
    Ok(Some((Decoded { heightfield, encoding, voids_filled: 0 }, rows, h)))
}

/// The map's width and height in samples as [`decode`](super::decode) would find them, from the
/// file's header (or length) alone: `None` when that cannot tell (a file that does not decode:
/// `decode` names what is wrong).
pub fn dimensions_of_file(path: &Path, opts: &DecodeOptions) -> Option<(usize, usize)> {
    let (file, len) = crate::input::open_limited(path, crate::input::MAX_HEIGHTMAP_BYTES, "a heightmap").ok()?;
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let square = || {
        let n = len / 2;
        let side = (n as f64).sqrt().round() as u64;
        (side * side == n && len.is_multiple_of(2)).then_some((side as usize, side as usize))
    };
    match (opts.encoding, ext.as_str()) {
        (Encoding::Hgt, _) | (Encoding::Auto, "hgt") => square(),
        (Encoding::R16, _) | (Encoding::Auto, "r16" | "raw") => opts.size.or_else(square),
        _ => {
            let mut file = BufReader::new(file);
            let mut magic = [0u8; 4];
            file.read_exact(&mut magic).ok()?;
            file.seek(SeekFrom::Start(0)).ok()?;
            if is_tiff(&magic) {
                // (the `image` crate does not open a float TIFF, whose size the `tiff` crate reads)
                let (w, h) = tiff::decoder::Decoder::new(file).ok()?.dimensions().ok()?;
                return Some((w as usize, h as usize));
            }
            let reader = image::ImageReader::new(file).with_guessed_format().ok()?;
            let (w, h) = reader.into_dimensions().ok()?;
            Some((w as usize, h as usize))
        }
    }
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::super::decode;
    use super::super::tests::png_file;
    use super::*;

    fn kept(path: &str, file: &[u8], opts: &DecodeOptions, keep: &dyn Fn(usize) -> bool) -> KeptRows {
        kept_rows_from(Path::new(path), Cursor::new(file), file.len() as u64, opts, keep).unwrap()
    }

    /// The kept rows of `file` are the whole decode's rows, bit for bit (heights and exact
    /// references): rows 3–17 and 17–31 (two bands sharing their edge row) and the last.
    fn assert_rows_of_whole(path: &str, file: &[u8], opts: &DecodeOptions) {
        let whole = decode(Path::new(path), file, opts).unwrap();
        let (w, h) = (whole.heightfield.width, whole.heightfield.height);
        let keep = |j: usize| (3..=17).contains(&j) || (17..=31).contains(&j) || j == h - 1;
        let (rows_map, rows) = kept(path, file, opts, &keep).unwrap_or_else(|| panic!("{path}: read whole"));
        assert_eq!(rows, (3..=31).chain([h - 1]).collect::<Vec<_>>(), "{path}");
        assert_eq!(rows_map.encoding, whole.encoding, "{path}");
        let (part, whole) = (rows_map.heightfield, whole.heightfield);
        assert_eq!((part.width, part.height, part.cell_size_m), (w, rows.len(), opts.cell_size_m), "{path}");
        for (k, &j) in rows.iter().enumerate() {
            for i in 0..w {
                let (a, b) = (k * w + i, j * w + i);
                assert_eq!(part.heights[a].to_bits(), whole.heights[b].to_bits(), "{path} ({i}, {j})");
                assert_eq!(part.reference(a).to_bits(), whole.reference(b).to_bits(), "{path} ({i}, {j})");
            }
        }
    }

    /// A little-endian uncompressed TIFF of `w`×`h` pixels of `spp` samples of `bits` bits
    /// (`format`: 1 unsigned, 3 float; `data` the samples' bytes, row-major, little-endian), in
    /// strips of `strip_rows` rows or in tiles (padded at the right and bottom edges).
    #[allow(clippy::too_many_arguments)]
    fn tiff_file(
        w: usize,
        h: usize,
        spp: u16,
        bits: u16,
        format: u16,
        photometric: u16,
        data: &[u8],
        strip_rows: usize,
        tiles: Option<(usize, usize)>,
    ) -> Vec<u8> {
        let px = bits as usize / 8 * spp as usize;
        assert_eq!(data.len(), w * h * px);
        let mut out = b"II*\0\0\0\0\0".to_vec();
        let (mut offsets, mut counts) = (Vec::new(), Vec::new());
        match tiles {
            None => {
                for j0 in (0..h).step_by(strip_rows) {
                    let bytes = &data[j0 * w * px..(j0 + strip_rows).min(h) * w * px];
                    offsets.push(out.len() as u32);
                    counts.push(bytes.len() as u32);
                    out.extend_from_slice(bytes);
                }
            }
            Some((tw, th)) => {
                for ty in (0..h).step_by(th) {
                    for tx in (0..w).step_by(tw) {
                        offsets.push(out.len() as u32);
                        counts.push((tw * th * px) as u32);
                        for (x, y) in (0..th).flat_map(|y| (0..tw).map(move |x| (x, y))) {
                            let (i, j) = (tx + x, ty + y);
                            if i < w && j < h {
                                out.extend_from_slice(&data[(j * w + i) * px..][..px]);
                            } else {
                                out.extend(std::iter::repeat_n(0, px));
                            }
                        }
                    }
                }
            }
        }
        let (short, long) = (3u16, 4u16);
        let base = if photometric == 2 { 3 } else { 1 };
        let mut tags: Vec<(u16, u16, Vec<u32>)> = vec![
            (256, long, vec![w as u32]),
            (257, long, vec![h as u32]),
            (258, short, vec![bits as u32; spp as usize]),
            (259, short, vec![1]),
            (262, short, vec![photometric as u32]),
            (277, short, vec![spp as u32]),
            (284, short, vec![1]),
            (339, short, vec![format as u32; spp as usize]),
        ];
        if spp > base {
            tags.push((338, short, vec![2]));
        }
        match tiles {
            None => tags.extend([(273, long, offsets), (278, long, vec![strip_rows as u32]), (279, long, counts)]),
            Some((tw, th)) => tags.extend([
                (322, long, vec![tw as u32]),
                (323, long, vec![th as u32]),
                (324, long, offsets),
                (325, long, counts),
            ]),
        }
        tags.sort_by_key(|t| t.0);
        let bytes_of = |kind: u16, values: &[u32]| -> Vec<u8> {
            values
                .iter()
                .flat_map(|&v| if kind == 3 { (v as u16).to_le_bytes().to_vec() } else { v.to_le_bytes().to_vec() })
                .collect()
        };
        let mut fields = Vec::new();
        for (tag, kind, values) in &tags {
            let mut bytes = bytes_of(*kind, values);
            if bytes.len() > 4 {
                out.resize(out.len() + out.len() % 2, 0);
                let at = out.len() as u32;
                out.extend_from_slice(&bytes);
                bytes = at.to_le_bytes().to_vec();
            }
            bytes.resize(4, 0);
            fields.push((*tag, *kind, values.len() as u32, bytes));
        }
        out.resize(out.len() + out.len() % 2, 0);
        let ifd = out.len() as u32;
        out[4..8].copy_from_slice(&ifd.to_le_bytes());
        out.extend_from_slice(&(fields.len() as u16).to_le_bytes());
        for (tag, kind, count, value) in fields {
            out.extend_from_slice(&tag.to_le_bytes());
            out.extend_from_slice(&kind.to_le_bytes());
            out.extend_from_slice(&count.to_le_bytes());
            out.extend_from_slice(&value);
        }
        out.extend_from_slice(&0u32.to_le_bytes());
        out
    }

    /// The rows of a PNG kept alone are the whole map's rows: 16-bit gray (scaled: exact
    /// references) and Terrain-RGB; a bad sample's row is named as the file's.
    #[test]
    fn kept_rows_of_a_png_are_the_maps_rows() {
        use png::{BitDepth as B, ColorType as C};
        let (w, h) = (37u32, 50u32);
        let gray: Vec<u8> = (0..w * h).map(|k| ((k * 2749 + 7) % 65536) as u16).flat_map(|v| v.to_be_bytes()).collect();
        let rgb: Vec<u8> = (0..w * h).flat_map(|k| [1, (k % 251) as u8, (k * 7 % 256) as u8]).collect();
        let opts = |encoding, height_scale_m| DecodeOptions {
            encoding,
            height_scale_m,
            cell_size_m: 2.0,
            ..DecodeOptions::default()
        };
        let gray_png = png_file(w, h, C::Grayscale, B::Sixteen, &gray, None, None);
        assert_rows_of_whole("map.png", &gray_png, &opts(Encoding::Gray, 6553.5));
        assert!(decode(Path::new("map.png"), &gray_png, &opts(Encoding::Gray, 6553.5))
            .unwrap()
            .heightfield
            .exact
            .is_some());
        let rgb_png = png_file(w, h, C::Rgb, B::Eight, &rgb, None, None);
        assert_rows_of_whole("map.png", &rgb_png, &opts(Encoding::TerrainRgb, 100.0));
        // heights out of range everywhere: the first kept row, the file's row 40, is named
        let bad = DecodeOptions { encoding: Encoding::Gray, height_scale_m: 1e13, ..DecodeOptions::default() };
        let err =
            kept_rows_from(Path::new("map.png"), Cursor::new(&gray_png), gray_png.len() as u64, &bad, &|j| j >= 40)
                .unwrap_err()
                .to_string();
        assert!(err.contains("row 40)"), "{err}");
        // not an image this reads by rows: decoded whole
        assert!(kept("map.tif", b"II*\0rest", &DecodeOptions::default(), &|_| true).is_none());
        assert!(kept("map.png", b"GIF89a..", &DecodeOptions::default(), &|_| true).is_none());
    }

    /// TIFF rows from their strips or tiles are the whole decode's rows, for 32-bit float gray,
    /// 8/16-bit gray, 16-bit RGB read as gray and 8-bit RGBA as
    /// Terrain-RGB, in strips of 1 and 7 rows and in 16×16 tiles over a 37×50 map (edge tiles
    /// padded), and in LZW strips with a horizontal predictor as the `tiff` crate writes them.
    #[test]
    fn kept_rows_of_a_tiff_are_the_maps_rows_in_strips_and_tiles() {
        let (w, h) = (37usize, 50usize);
        let mut state = 0x51ed_u64;
        let mut next = move || {
            state = crate::random::mix64(state);
            state
        };
        let samples = |n: usize, bytes: usize, next: &mut dyn FnMut() -> u64| -> Vec<u8> {
            (0..n).flat_map(|_| next().to_le_bytes()[..bytes].to_vec()).collect()
        };
        let floats: Vec<u8> =
            (0..w * h).flat_map(|k| (((k * 7919) % 4001) as f32 * 0.37 - 500.0).to_le_bytes()).collect();
        let rgba: Vec<u8> = (0..w * h).flat_map(|k| [1, (k % 251) as u8, (k * 7 % 256) as u8, 255]).collect();
        // (samples a pixel, bits, sample format, photometric, samples, encoding, height scale)
        type Case = (u16, u16, u16, u16, Vec<u8>, Encoding, f64);
        let cases: Vec<Case> = vec![
            (1, 32, 3, 1, floats, Encoding::Auto, 1.0),
            (1, 8, 1, 1, samples(w * h, 1, &mut next), Encoding::Auto, 100.0),
            (1, 16, 1, 1, samples(w * h, 2, &mut next), Encoding::Gray, 6553.5),
            (3, 16, 1, 2, samples(w * h * 3, 2, &mut next), Encoding::Gray, 1000.0),
            (4, 8, 1, 2, rgba, Encoding::TerrainRgb, 1.0),
            (1, 16, 1, 0, samples(w * h, 2, &mut next), Encoding::Gray, 6553.5), // white is zero
        ];
        for (spp, bits, format, photometric, data, encoding, height_scale_m) in cases {
            let opts = DecodeOptions { encoding, height_scale_m, cell_size_m: 0.5, ..DecodeOptions::default() };
            for (strip_rows, tiles) in [(1, None), (7, None), (0, Some((16, 16)))] {
                let file = tiff_file(w, h, spp, bits, format, photometric, &data, strip_rows, tiles);
                assert_rows_of_whole("map.tif", &file, &opts);
            }
        }
        // compressed by the tiff crate's own encoder (LZW, horizontal predictor)
        use tiff::encoder::{colortype, Compression, TiffEncoder};
        let values: Vec<u16> = (0..w * h).map(|k| (k * 977 % 65536) as u16).collect();
        let mut file = Cursor::new(Vec::new());
        TiffEncoder::new(&mut file)
            .unwrap()
            .with_compression(Compression::Lzw)
            .with_predictor(tiff::tags::Predictor::Horizontal)
            .write_image::<colortype::Gray16>(w as u32, h as u32, &values)
            .unwrap();
        let opts = DecodeOptions { encoding: Encoding::Gray, height_scale_m: 6553.5, ..DecodeOptions::default() };
        assert_rows_of_whole("map.tiff", file.get_ref(), &opts);
        // BigTIFFs (64-bit offsets, as GDAL writes maps past 4 GB): float metres, 16-bit gray
        let metres: Vec<f32> = values.iter().map(|&v| v as f32 * 0.25 - 900.0).collect();
        let mut file = Cursor::new(Vec::new());
        TiffEncoder::new_big(&mut file)
            .unwrap()
            .write_image::<colortype::Gray32Float>(w as u32, h as u32, &metres)
            .unwrap();
        assert!(file.get_ref().starts_with(b"II+\0"));
        assert_rows_of_whole("map.tif", file.get_ref(), &DecodeOptions::default());
        let mut file = Cursor::new(Vec::new());
        TiffEncoder::new_big(&mut file).unwrap().write_image::<colortype::Gray16>(w as u32, h as u32, &values).unwrap();
        assert_rows_of_whole("map.tif", file.get_ref(), &opts);
    }

    /// Where the whole decoder must see the file: an RGB TIFF read as `auto` (each pixel checked
    /// for gray), a float TIFF as gray, a file cut short inside a kept strip (an error naming the
    /// file, not a panic), a TIFF whose strips are never read when no row is kept from them.
    #[test]
    fn tiffs_the_window_leaves_to_the_whole_decoder() {
        let (w, h) = (20usize, 30usize);
        let rgb: Vec<u8> = (0..w * h * 3).map(|k| (k % 200) as u8).collect();
        let file = tiff_file(w, h, 3, 8, 1, 2, &rgb, 5, None);
        assert!(kept("map.tif", &file, &DecodeOptions::default(), &|_| true).is_none());
        let floats: Vec<u8> = (0..w * h).flat_map(|k| (k as f32).to_le_bytes()).collect();
        let file = tiff_file(w, h, 1, 32, 3, 1, &floats, 5, None);
        let gray = DecodeOptions { encoding: Encoding::Gray, ..DecodeOptions::default() };
        assert!(kept("map.tif", &file, &gray, &|_| true).is_none());
        assert!(decode(Path::new("map.tif"), &file, &gray).is_err());
        // strips 0-5 hold rows 0-29 (5 each); strip 4 (rows 20-24) pointed past the file's end
        let mut cut = file.clone();
        let ifd = u32::from_le_bytes(cut[4..8].try_into().unwrap()) as usize;
        let entries = u16::from_le_bytes([cut[ifd], cut[ifd + 1]]) as usize;
        let entry = (0..entries).map(|e| ifd + 2 + 12 * e).find(|&at| cut[at..at + 2] == 273u16.to_le_bytes()).unwrap();
        let offsets = u32::from_le_bytes(cut[entry + 8..entry + 12].try_into().unwrap()) as usize;
        cut[offsets + 16..offsets + 20].copy_from_slice(&0x7fff_0000u32.to_le_bytes());
        let read = |file: &[u8], j: usize| {
            kept_rows_from(
                Path::new("map.tif"),
                Cursor::new(file),
                file.len() as u64,
                &DecodeOptions::default(),
                &|r| r == j,
            )
        };
        assert!(read(&cut, 2).unwrap().is_some());
        let err = read(&cut, 22).unwrap_err().to_string();
        assert!(err.starts_with("map.tif:"), "{err}");
        assert!(decode(Path::new("map.tif"), &cut, &DecodeOptions::default()).is_err());
        // a strip never read: damage in rows 10-14 does not reach rows 0-4
        let mut damaged = file.clone();
        let strip2 = 8 + 10 * w * 4;
        damaged[strip2..strip2 + 5 * w * 4].fill(0xff); // NaN heights
        let (rows, _) = kept("map.tif", &damaged, &DecodeOptions::default(), &|j| j < 5).unwrap();
        assert_eq!(rows.heightfield.heights, (0..5 * w).map(|k| k as f32).collect::<Vec<_>>());
        let err = kept_rows_from(
            Path::new("map.tif"),
            Cursor::new(&damaged),
            damaged.len() as u64,
            &DecodeOptions::default(),
            &|j| j == 12,
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("map.tif") && err.contains("row 12)"), "{err}");
    }

    /// Raw 16-bit and `.hgt` rows by byte range are the whole decode's rows; an `.hgt` void among
    /// the kept rows leaves the map to the whole decoder (a void is filled from the whole map),
    /// one elsewhere does not change the kept rows; a size that does not fit is the whole
    /// decoder's to report.
    #[test]
    fn kept_rows_of_raw_and_hgt_files_are_the_maps_rows() {
        let (w, h) = (37usize, 40usize);
        let raw: Vec<u8> = (0..w * h).flat_map(|k| (((k * 2749 + 7) % 65536) as u16).to_le_bytes()).collect();
        let opts = DecodeOptions { size: Some((w, h)), height_scale_m: 6553.5, ..DecodeOptions::default() };
        assert_rows_of_whole("map.r16", &raw, &opts);
        let wrong = DecodeOptions { size: Some((w, h + 1)), ..opts };
        assert!(kept("map.raw", &raw, &wrong, &|_| true).is_none());
        assert!(decode(Path::new("map.raw"), &raw, &wrong).is_err());
        let side = 41usize;
        let mut hgt: Vec<u8> = (0..side * side).flat_map(|k| (((k * 31) % 3000) as i16 - 200).to_be_bytes()).collect();
        assert_rows_of_whole("N44E033.hgt", &hgt, &DecodeOptions::default());
        // a void in row 35: outside the rows kept below (3-31 and 40)
        let void = (35 * side + 5) * 2;
        hgt[void..void + 2].copy_from_slice(&(-32768i16).to_be_bytes());
        let whole = decode(Path::new("N44E033.hgt"), &hgt, &DecodeOptions::default()).unwrap();
        assert_eq!(whole.voids_filled, 1);
        assert!(kept("N44E033.hgt", &hgt, &DecodeOptions::default(), &|j| j == 35).is_none());
        assert_rows_of_whole("N44E033.hgt", &hgt, &DecodeOptions::default());
    }

    /// A map wider across than a terrain may span (its whole height at this cell size) is refused
    /// by a window of a few rows too, with the whole decoder's message: raw, PNG and TIFF.
    #[test]
    fn a_window_checks_the_whole_maps_extent() {
        let (w, h) = (4usize, 1000usize);
        let raw: Vec<u8> = (0..w * h).flat_map(|k| (k as u16).to_le_bytes()).collect();
        let png = png_file(
            w as u32,
            h as u32,
            png::ColorType::Grayscale,
            png::BitDepth::Eight,
            &vec![7u8; w * h],
            None,
            None,
        );
        let tif = tiff_file(w, h, 1, 8, 1, 1, &vec![7u8; w * h], 16, None);
        for (path, file) in [("map.r16", &raw), ("map.png", &png), ("map.tif", &tif)] {
            let opts = DecodeOptions { size: Some((w, h)), cell_size_m: 5.0e4, ..DecodeOptions::default() };
            let whole = decode(Path::new(path), file, &opts).unwrap_err().to_string();
            let window = kept_rows_from(Path::new(path), Cursor::new(file), file.len() as u64, &opts, &|j| j < 3)
                .unwrap_err()
                .to_string();
            assert_eq!(window, whole, "{path}");
            assert!(window.contains("4×1000"), "{window}");
        }
    }
}
