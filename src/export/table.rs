//! Placement tables: one CSV row per instance, for engines that do not read EXT_mesh_gpu_instancing
//! (Godot, Unreal) and for tools. Numbers are written in their shortest round-trip form (ryu's bytes), so
//! a reader gets back exactly the values in memory; rows are formatted in parallel chunks and
//! joined in order, so the bytes do not depend on the thread count.

use std::path::Path;

use rayon::prelude::*;
use serde_json::ser::{CompactFormatter, Formatter};

use crate::export::atomic::write_atomic_with;
use crate::export::error::ExportError;

/// The columns of a placement table, in order.
pub const PLACEMENT_COLUMNS: [&str; 13] =
    ["x", "y", "z", "qx", "qy", "qz", "qw", "sx", "sy", "sz", "yaw_deg", "tile", "variant"];

/// One placed instance as the table writes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacementRow {
    /// Metres (f64: the table keeps the placement's full precision; glTF stores f32).
    pub position: [f64; 3],
    /// Unit quaternion x, y, z, w.
    pub rotation: [f32; 4],
    pub scale: [f32; 3],
    pub yaw_deg: f32,
    pub tile: u32,
    /// Which of its species' meshes the instance shows (the scene's manifest.json maps it to the
    /// chain and its LoD0 file: `view.chains.<species>.pick[variant]`).
    pub variant: u32,
}

/// Anything that is one row of a placement table: the writer reads rows through this, so a
/// caller's own instances are written without first being copied into a `Vec<PlacementRow>`.
pub trait ToPlacementRow {
    fn placement_row(&self) -> PlacementRow;
}

impl ToPlacementRow for PlacementRow {
    #[inline]
    fn placement_row(&self) -> PlacementRow {
        *self
    }
}

/// Rows formatted by one task; a task's buffer is reserved once for its rows at the longest.
const ROWS_PER_CHUNK: usize = 4096;
/// Chunks formatted while the previous batch is written. The streaming writer's buffers (two
/// batches: 2 × 8 × 4096 rows at most ≈ 15 MB) are reused from batch to batch: their pages are
/// touched once and stay warm in the caches, where fresh pages for a whole table would cost a
/// page fault per 4 KiB.
const CHUNKS_PER_BATCH: usize = 8;
/// Longest row: a shortest round-trip f64 is at most 24 bytes and an f32 16, a u32 has 10 digits,
/// and 12 commas + a newline.
const ROW_MAX: usize = 3 * 24 + 8 * 16 + 2 * 10 + 13;

/// A chunk's bytes under construction: `buf[..len]` is written. Fields are stored with fixed-size
/// 8-byte copies (the buffer holds [`ROW_MAX`] per row plus [`SLACK`], which absorbs the
/// over-write): no per-field call to `memcpy` for a variable length.
struct Line<'a> {
    buf: &'a mut [u8],
    len: usize,
}

/// Bytes past the last row that an 8-byte store may touch.
const SLACK: usize = 16;

impl Line<'_> {
    /// Room for one more row: at least [`ROW_MAX`] + [`SLACK`] bytes past `len`. [`push_row`]
    /// checks it once per row; the single-byte and 8-byte stores of the row (at most `ROW_MAX`
    /// bytes, and an 8-byte store reaches at most 6 past the row's end, as every one keeps at
    /// least one byte and a newline follows) are then unchecked: the bounds checks were ~15 % of
    /// the formatting's instructions. `push` and `put8` are private and have this precondition.
    #[inline]
    fn has_room_for_a_row(&self) -> bool {
        self.buf.len() >= self.len + ROW_MAX + SLACK
    }

    #[inline]
    fn push(&mut self, b: u8) {
        fast_path_check!(self.len < self.buf.len(), "placement row store at {} of {}", self.len, self.buf.len());
        // SAFETY: within a row (see `has_room_for_a_row`), len < buf.len()
        unsafe { *self.buf.get_unchecked_mut(self.len) = b };
        self.len += 1;
    }

    /// Stores the 8 bytes of `word` (little-endian) and keeps the first `n` (≤ 8).
    #[inline]
    fn put8(&mut self, word: u64, n: usize) {
        fast_path_check!(
            self.len + 8 <= self.buf.len() && n <= 8,
            "8-byte store at {} of {}",
            self.len,
            self.buf.len()
        );
        // SAFETY: within a row (see `has_room_for_a_row`), len + 8 ≤ buf.len(); the store is
        // unaligned-safe
        unsafe { self.buf.as_mut_ptr().add(self.len).cast::<[u8; 8]>().write_unaligned(word.to_le_bytes()) };
        self.len += n;
    }

    /// Appends what `write` writes (at most 24 bytes: a float's shortest digits) in place.
    #[inline]
    fn put_with(&mut self, write: impl FnOnce(&mut &mut [u8]) -> std::io::Result<()>) {
        let mut rest = &mut self.buf[self.len..];
        let before = rest.len();
        // the buffer holds ROW_MAX per row, so a number always fits
        let _ = write(&mut rest);
        self.len += before - rest.len();
    }

    #[inline]
    fn extend(&mut self, s: &[u8]) {
        self.buf[self.len..self.len + s.len()].copy_from_slice(s);
        self.len += s.len();
    }

    /// Appends `v` in decimal.
    #[inline]
    fn put_u64(&mut self, v: u64) {
        if v < 100_000_000 {
            self.put_below_1e8(v as u32);
        } else {
            self.put_large(v);
        }
    }

    /// Appends `v` < 10⁸ in decimal.
    #[inline]
    fn put_below_1e8(&mut self, v: u32) {
        let d = eight_digits(v);
        // leading zero digits are the low zero bytes; one digit stays
        let skip = ((d.trailing_zeros() / 8) as usize).min(7);
        self.put8((d | ASCII_ZEROS) >> (8 * skip), 8 - skip);
    }

    /// Appends `v` ≥ 10⁸ in decimal: groups of eight digits.
    #[cold]
    fn put_large(&mut self, v: u64) {
        let (high, low) = (v / 100_000_000, (v % 100_000_000) as u32);
        if high < 100_000_000 {
            self.put_below_1e8(high as u32);
        } else {
            self.put_below_1e8((high / 100_000_000) as u32);
            self.put8(eight_digits((high % 100_000_000) as u32) | ASCII_ZEROS, 8);
        }
        self.put8(eight_digits(low) | ASCII_ZEROS, 8);
    }

    /// Appends ±m·10^-D as ryu writes it: the integer part, a point, the fraction without trailing
    /// zeros (at least one digit). 1 ≤ D ≤ 7.
    #[inline(always)]
    fn put_fixed<const D: u32>(&mut self, negative: bool, m: u64) {
        if negative {
            self.push(b'-');
        }
        let unit = 10u64.pow(D);
        if m < 100_000_000 {
            // all digits from one conversion: 8 − D integer digits (leading zeros skipped, one
            // stays), the point, D fraction digits (trailing zeros cut, one stays)
            let int_len = 8 - D as usize;
            let d = eight_digits(m as u32);
            let skip = ((d.trailing_zeros() / 8) as usize).min(int_len - 1);
            let cut = ((d.leading_zeros() / 8) as usize).min(D as usize - 1);
            let ascii = d | ASCII_ZEROS;
            self.put8(ascii >> (8 * skip), int_len - skip);
            self.push(b'.');
            self.put8(ascii >> (8 * int_len), D as usize - cut);
            return;
        }
        let (int, frac) = (m / unit, m % unit);
        self.put_u64(int);
        self.push(b'.');
        // the fraction's D digits, then zeros: trailing zero digits are the high zero bytes
        let d = eight_digits((frac * 10u64.pow(8 - D)) as u32);
        let keep = 8 - ((d.leading_zeros() / 8) as usize).min(7);
        self.put8(d | ASCII_ZEROS, keep);
    }
}

/// The eight decimal digits of `n` < 10⁸ as byte values 0–9, most significant in the lowest byte
/// (the order they are written in): 4 + 4 digits in two 32-bit lanes, each lane split into pairs
/// (x/100 = x·10486 >> 20 for x < 10⁴), each pair into digits (x/10 = x·103 >> 10 for x < 100),
/// all lanes at once, so a number costs a few multiplications instead of a division per digit.
#[inline]
fn eight_digits(n: u32) -> u64 {
    debug_assert!(n < 100_000_000);
    let n = n as u64;
    let halves = (n / 10_000) | ((n % 10_000) << 32);
    let hundreds = ((halves * 10_486) >> 20) & 0x0000_007F_0000_007F;
    let pairs = hundreds | ((halves - hundreds * 100) << 16);
    let tens = ((pairs * 103) >> 10) & 0x000F_000F_000F_000F;
    tens | ((pairs - tens * 10) << 8)
}

const ASCII_ZEROS: u64 = 0x3030_3030_3030_3030;

/// Appends one row: each number's shortest round-trip digits, a field equal to the previous one
/// (the uniform scale) copied instead of formatted again. Returns false if a number is not finite.
///
/// Numbers that are short decimals (see [`short_f64`], [`short_f32`]: a scatter's positions,
/// heights, quaternions, scales and yaws on their grids) are written from their integer by
/// [`Line::put_fixed`]; others get their digits from serde_json's `CompactFormatter` (already a
/// dependency), which writes floats with Żmij (Schubfach-based, shortest round-trip): the same
/// bytes as `ryu::Buffer::format_finite` (tested below), 20–35 % less CPU per number.
#[inline]
fn push_row(line: &mut Line<'_>, r: &PlacementRow) -> bool {
    let finite = r.position.iter().all(|v| v.is_finite())
        && r.rotation.iter().chain(&r.scale).all(|v| v.is_finite())
        && r.yaw_deg.is_finite();
    if !finite {
        return false;
    }
    // the stores below are unchecked: this is the check (every buffer is sized for it)
    assert!(line.has_room_for_a_row(), "placement table buffer too small for a row");
    for v in r.position {
        push_f64(line, v);
        line.push(b',');
    }
    for v in r.rotation {
        match short_f32(v, &UNIT_GRID) {
            Some(m) => line.put_fixed::<UNIT_DIGITS>(v < 0.0, m),
            None => push_f32(line, v),
        }
        line.push(b',');
    }
    let mut prev: (u32, usize, usize) = (u32::MAX, 0, 0); // bits, start, end of the last field
    for v in r.scale.into_iter().chain([r.yaw_deg]) {
        let bits = v.to_bits();
        if bits == prev.0 {
            let n = prev.2 - prev.1;
            if n <= 8 {
                // one 8-byte load and store (a short scale like "1.0123"), no memmove call
                let mut word = [0u8; 8];
                word.copy_from_slice(&line.buf[prev.1..prev.1 + 8]);
                line.put8(u64::from_le_bytes(word), n);
            } else {
                line.buf.copy_within(prev.1..prev.2, line.len);
                line.len += n;
            }
        } else {
            let start = line.len;
            push_f32(line, v);
            prev = (bits, start, line.len);
        }
        line.push(b',');
    }
    line.put_u64(r.tile as u64);
    line.push(b',');
    line.put_u64(r.variant as u64);
    line.push(b'\n');
    true
}

/// Below these magnitudes Żmij and ryu write the same bytes (above, Żmij writes "1e+16" where ryu
/// writes "1e16"; such values are ryu's, so the bytes never depend on the formatter).
const ZMIJ_F64_BELOW: f64 = 1e15;
const ZMIJ_F32_BELOW: f32 = 1e7;

/// Short decimals: an f64 that is the nearest double to a whole number of 10^-6 (a scatter's
/// jittered x/z on their 0.1 mm grid, its heights on their 1 µm grid), or an f32 that reads back
/// from a whole number of 10^-4 (a scale, a yaw in 0.01°) or, below 1, of 10^-7 (a quaternion
/// component on its grid), is written straight from that integer, without the general
/// shortest-digits search. Within these ranges a float's spacing is below the grid step, so no
/// other decimal with as few digits rounds to the same value: the integer's digits are the
/// shortest round-trip digits, ryu's bytes (tested against ryu below).
const SHORT_F64_SCALE: f64 = 1e6;
const SHORT_F64_DIGITS: u32 = 6;
const SHORT_F64_RANGE: std::ops::Range<f64> = 1e-4..1e9;

/// Whole numbers of 1/`scale` for f32 magnitudes in `range`.
struct F32Grid {
    scale: f64,
    range: std::ops::Range<f32>,
}
const SHORT_F32_DIGITS: u32 = 4;
/// Up to 1024 an f32's spacing (≤ 6.1·10⁻⁵) is below the grid step, so a rounding interval holds at
/// most one grid value (yaws reach 359.99°).
const SHORT_GRID: F32Grid = F32Grid { scale: 1e4, range: 1e-4..1024.0 };
/// Quaternion components: ryu writes plain decimals from 10⁻⁵ on, and up to 1 an f32's spacing
/// (≤ 6·10⁻⁸) is below the grid step.
const UNIT_DIGITS: u32 = 7;
const UNIT_GRID: F32Grid = F32Grid { scale: 1e7, range: 1e-5..1.000_000_1 };

/// |v|·10⁶ when |v| is the nearest double to that whole number of 10⁻⁶ (in range).
#[inline]
fn short_f64(v: f64) -> Option<u64> {
    let a = v.abs();
    if !SHORT_F64_RANGE.contains(&a) {
        return None;
    }
    // signed conversions (one instruction each, unlike u64's); a·10⁶ + 0.5 is positive, so
    // truncation is the rounding
    let scaled = a * SHORT_F64_SCALE;
    let m = (scaled + 0.5) as i64;
    // most values are far from the grid: the product tells, before the exact test divides (a value
    // on the grid is within a·2.3e-10 of it: the rounding of a and of the product)
    if (scaled - m as f64).abs() > 1e-3 + a * 3e-10 {
        return None;
    }
    (m as f64 / SHORT_F64_SCALE == a).then_some(m as u64)
}

/// |v|·scale when that whole number of grid steps, read as an f32, gives |v| back (in range).
#[inline]
fn short_f32(v: f32, grid: &F32Grid) -> Option<u64> {
    let a = v.abs();
    if !grid.range.contains(&a) {
        return None;
    }
    // a·scale is exact in f64 (24 + at most 17 significant bits), and so is its distance to m: the
    // decimal m/scale reads back as v when it is closer to v than half the spacing of floats around
    // v (a quarter below a power of two, where the spacing halves); ties are not taken
    let scaled = a as f64 * grid.scale;
    let m = (scaled + 0.5) as i64;
    let spacing = f32::from_bits(a.to_bits() & 0x7F80_0000) as f64 * (1.0 / 8_388_608.0);
    let half = if a.to_bits() & 0x7F_FFFF == 0 { 0.25 * spacing } else { 0.5 * spacing };
    ((scaled - m as f64).abs() < half * grid.scale).then_some(m as u64)
}

#[inline]
fn push_f64(line: &mut Line<'_>, v: f64) {
    if let Some(m) = short_f64(v) {
        // on the 10⁻⁴ grid (jittered x and z): four fraction digits, more often one conversion
        if m % 100 == 0 {
            line.put_fixed::<4>(v < 0.0, m / 100);
        } else {
            line.put_fixed::<SHORT_F64_DIGITS>(v < 0.0, m);
        }
    } else if v == 0.0 {
        line.extend(if v.is_sign_negative() { b"-0.0" } else { b"0.0" });
    } else if v.abs() < ZMIJ_F64_BELOW {
        line.put_with(|w| CompactFormatter.write_f64(w, v));
    } else {
        line.extend(ryu::Buffer::new().format_finite(v).as_bytes());
    }
}

#[inline]
fn push_f32(line: &mut Line<'_>, v: f32) {
    if let Some(m) = short_f32(v, &SHORT_GRID) {
        line.put_fixed::<SHORT_F32_DIGITS>(v < 0.0, m);
    } else if v == 0.0 {
        line.extend(if v.is_sign_negative() { b"-0.0" } else { b"0.0" });
    } else if v.abs() < ZMIJ_F32_BELOW {
        line.put_with(|w| CompactFormatter.write_f32(w, v));
    } else {
        line.extend(ryu::Buffer::new().format_finite(v).as_bytes());
    }
}

/// Formats `chunk` (whose first row is row `first` of the table) into `buf` (cleared first);
/// `Err(row)` names the first row holding a non-finite number.
fn format_chunk<R: ToPlacementRow>(chunk: &[R], first: usize, buf: &mut Chunk) -> Result<(), usize> {
    // grown (and zeroed) once, then reused batch after batch: rows are stored straight into it
    let need = chunk.len() * ROW_MAX + SLACK;
    if buf.bytes.len() < need {
        buf.bytes.resize(need, 0);
    }
    let mut line = Line { buf: &mut buf.bytes, len: 0 };
    for (k, r) in chunk.iter().enumerate() {
        if !push_row(&mut line, &r.placement_row()) {
            buf.len = 0;
            return Err(first + k);
        }
    }
    buf.len = line.len;
    Ok(())
}

/// One task's formatted rows: `bytes[..len]`.
#[derive(Default)]
struct Chunk {
    bytes: Vec<u8>,
    len: usize,
}

impl Chunk {
    fn written(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

fn header() -> Vec<u8> {
    let mut h = PLACEMENT_COLUMNS.join(",").into_bytes();
    h.push(b'\n');
    h
}

fn not_finite(row: usize) -> String {
    format!("row {row} holds a value that is not a finite number")
}

/// Formats `rows` (row `first` of the table first) in parallel chunks into `bufs` (one per chunk,
/// reused across calls so their pages are touched once).
fn format_batch<R: ToPlacementRow + Sync>(rows: &[R], first: usize, bufs: &mut Vec<Chunk>) -> Result<(), usize> {
    let chunks = rows.len().div_ceil(ROWS_PER_CHUNK);
    bufs.resize_with(bufs.len().max(chunks), Chunk::default);
    let results: Vec<Result<(), usize>> = bufs[..chunks]
        .par_iter_mut()
        .zip(rows.par_chunks(ROWS_PER_CHUNK))
        .enumerate()
        .map(|(c, (buf, chunk))| format_chunk(chunk, first + c * ROWS_PER_CHUNK, buf))
        .collect();
    for b in &mut bufs[chunks..] {
        b.len = 0;
    }
    results.into_iter().collect()
}

/// How the scatter stage writes placement tables (`[scatter] table`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TableFormat {
    /// `placements/<species>.csv`, one text row per instance.
    #[default]
    Csv,
    /// `placements/<species>.bin`, little-endian arrays ([`crate::export::table_bin`]).
    Binary,
}

impl TableFormat {
    pub fn extension(self) -> &'static str {
        match self {
            TableFormat::Csv => "csv",
            TableFormat::Binary => "bin",
        }
    }
}

/// Reads a placement table in either format, by its extension (`.bin`: binary, else CSV).
pub fn read_placements(path: &Path) -> Result<Vec<PlacementRow>, String> {
    if path.extension().is_some_and(|e| e == "bin") {
        crate::export::table_bin::read_placements_bin(path)
    } else {
        read_placements_csv(path)
    }
}

/// Reads a placement table back (the CSV [`write_placements_csv`] writes): the header must name
/// [`PLACEMENT_COLUMNS`]; every number is parsed exactly (the writer's shortest round-trip form),
/// so the rows equal those written. Errors name the line.
pub fn read_placements_csv(path: &Path) -> Result<Vec<PlacementRow>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("cannot read: {e}"))?;
    parse_placements_csv(&text)
}

/// [`read_placements_csv`] on the text of a table. Pieces of about [`PARSE_PIECE_BYTES`], cut
/// after a line's end, are parsed in parallel and joined in order; an error is the first bad
/// line's, as a parse from the top would name it.
pub fn parse_placements_csv(text: &str) -> Result<Vec<PlacementRow>, String> {
    use rayon::prelude::*;
    let header = text.lines().next().unwrap_or("");
    let body = text.split_once('\n').map_or("", |(_, body)| body);
    if header.split(',').collect::<Vec<_>>() != PLACEMENT_COLUMNS {
        return Err(format!("line 1: the header is `{header}`, expected `{}`", PLACEMENT_COLUMNS.join(",")));
    }
    // pieces of whole lines: each ends after a '\n' (or at the end of the text)
    let mut pieces = Vec::new();
    let mut at = 0;
    while at < body.len() {
        let mut end = (at + PARSE_PIECE_BYTES).min(body.len());
        end = body.as_bytes()[end..].iter().position(|&b| b == b'\n').map_or(body.len(), |k| end + k + 1);
        pieces.push(&body[at..end]);
        at = end;
    }
    // every line's row in one array (no second copy of a world's rows): each piece fills its
    // lines' part, then the rows of blank lines, if any, are closed up
    let lines: Vec<usize> = pieces.par_iter().map(|p| p.lines().count()).collect();
    let blank =
        PlacementRow { position: [0.0; 3], rotation: [0.0; 4], scale: [0.0; 3], yaw_deg: 0.0, tile: 0, variant: 0 };
    let mut rows = vec![blank; lines.iter().sum()];
    let mut parts = Vec::with_capacity(pieces.len());
    let mut rest = &mut rows[..];
    for &n in &lines {
        let (part, tail) = rest.split_at_mut(n);
        parts.push(part);
        rest = tail;
    }
    let filled: Vec<Result<usize, (usize, String)>> = pieces
        .par_iter()
        .zip(parts.into_par_iter())
        .map(|(piece, part)| {
            let mut k = 0;
            for (n, line) in piece.lines().enumerate() {
                if !line.is_empty() {
                    part[k] = parse_placement_line(line).map_err(|e| (n, e))?;
                    k += 1;
                }
            }
            Ok(k)
        })
        .collect();
    let (mut read, mut write) = (0, 0);
    for (&n, result) in lines.iter().zip(filled) {
        match result {
            Ok(k) => {
                if read != write {
                    rows.copy_within(read..read + k, write);
                }
                write += k;
            }
            // line numbers count the header and every line before (blank ones too)
            Err((at, e)) => return Err(format!("line {}{e}", read + at + 2)),
        }
        read += n;
    }
    rows.truncate(write);
    Ok(rows)
}

/// Bytes of table text one parallel task parses ([`parse_placements_csv`]).
const PARSE_PIECE_BYTES: usize = 1 << 20;

/// One row of a placement table; an error is what follows the line number ("line N" + it).
fn parse_placement_line(line: &str) -> Result<PlacementRow, String> {
    let f: Vec<&str> = line.split(',').collect();
    if f.len() != PLACEMENT_COLUMNS.len() {
        return Err(format!(": {} fields, expected {}", f.len(), PLACEMENT_COLUMNS.len()));
    }
    let bad = |k: usize| format!(", column `{}`: `{}` is not a finite number", PLACEMENT_COLUMNS[k], f[k]);
    let num64 = |k: usize| f[k].parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| bad(k));
    // f32 columns parsed as f32: their shortest form rounds to the same f32 (via f64 it might not)
    let num32 = |k: usize| f[k].parse::<f32>().ok().filter(|x| x.is_finite()).ok_or_else(|| bad(k));
    Ok(PlacementRow {
        position: [num64(0)?, num64(1)?, num64(2)?],
        rotation: [num32(3)?, num32(4)?, num32(5)?, num32(6)?],
        scale: [num32(7)?, num32(8)?, num32(9)?],
        yaw_deg: num32(10)?,
        tile: f[11].parse::<u32>().map_err(|_| format!(", column `tile`: `{}` is not a tile number", f[11]))?,
        variant: f[12]
            .parse::<u32>()
            .map_err(|_| format!(", column `variant`: `{}` is not a variant number", f[12]))?,
    })
}

/// The table as CSV bytes: a header line, then one line per row. Non-finite numbers are refused
/// (a placement bug, not something to write). Built by the streaming writer into one growing
/// buffer, so only two batches of chunk buffers exist besides it (fresh pages are costly).
pub fn placements_csv<R: ToPlacementRow + Sync>(rows: &[R]) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(64 + rows.len() * 144);
    let mut bad = None;
    match stream_csv(&mut out, rows, ROWS_PER_CHUNK * CHUNKS_PER_BATCH, &mut bad) {
        Ok(()) => Ok(out),
        Err(e) => Err(bad.map_or_else(|| e.to_string(), not_finite)),
    }
}

/// Writes the placement table to `path` atomically, streaming: batches of rows are formatted in
/// parallel while the previous batch is written, so memory stays bounded by two batches and the
/// bytes are those of [`placements_csv`].
pub fn write_placements_csv<R: ToPlacementRow + Sync>(path: &Path, rows: &[R]) -> Result<(), ExportError> {
    let mut bad: Option<usize> = None;
    let result = write_atomic_with(path, |w| stream_csv(w, rows, ROWS_PER_CHUNK * CHUNKS_PER_BATCH, &mut bad));
    match (result, bad) {
        (Err(_), Some(row)) => Err(ExportError::InvalidScene { path: path.to_path_buf(), problem: not_finite(row) }),
        (r, _) => r,
    }
}

/// The CSV into `w` in batches of `batch` rows (the next batch formatted while this thread writes
/// the current one); a non-finite number stops it with an error and its row in `bad`.
fn stream_csv<R: ToPlacementRow + Sync>(
    w: &mut dyn std::io::Write,
    rows: &[R],
    batch: usize,
    bad: &mut Option<usize>,
) -> std::io::Result<()> {
    let mut refuse = |row: usize| {
        *bad = Some(row);
        std::io::Error::new(std::io::ErrorKind::InvalidData, not_finite(row))
    };
    w.write_all(&header())?;
    let mut cur: Vec<Chunk> = Vec::new();
    let mut next: Vec<Chunk> = Vec::new();
    let mut batches = rows.chunks(batch.max(1)).enumerate();
    let Some((_, first)) = batches.next() else { return Ok(()) };
    format_batch(first, 0, &mut cur).map_err(&mut refuse)?;
    for (k, rows) in batches {
        let mut formatted = Ok(());
        let written = rayon::in_place_scope(|s| {
            s.spawn(|_| formatted = format_batch(rows, k * batch, &mut next));
            cur.iter().try_for_each(|b| w.write_all(b.written()))
        });
        written?;
        formatted.map_err(&mut refuse)?;
        std::mem::swap(&mut cur, &mut next);
    }
    cur.iter().try_for_each(|b| w.write_all(b.written()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(csv: &[u8]) -> Vec<PlacementRow> {
        let text = std::str::from_utf8(csv).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next().unwrap(), PLACEMENT_COLUMNS.join(","));
        lines
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                assert_eq!(f.len(), 13);
                let d = |k: usize| f[k].parse::<f64>().unwrap();
                let s = |k: usize| f[k].parse::<f32>().unwrap();
                PlacementRow {
                    position: [d(0), d(1), d(2)],
                    rotation: [s(3), s(4), s(5), s(6)],
                    scale: [s(7), s(8), s(9)],
                    yaw_deg: s(10),
                    tile: f[11].parse().unwrap(),
                    variant: f[12].parse().unwrap(),
                }
            })
            .collect()
    }

    /// 40 000 rows of varied numbers (about 4 MB of CSV).
    fn sample_rows() -> Vec<PlacementRow> {
        (0..40_000u32)
            .map(|k| {
                let t = k as f64 * 0.123_456_789;
                PlacementRow {
                    position: [t, -t / 7.0, 1e6 + t],
                    rotation: [0.0, (t as f32).sin(), 0.0, (t as f32).cos()],
                    scale: [1.0 + k as f32 * 1e-5; 3],
                    yaw_deg: (k % 360) as f32 + 0.25,
                    tile: k / 1000,
                    variant: k % 3,
                }
            })
            .collect()
    }

    #[test]
    fn rows_round_trip_exactly_and_bytes_do_not_depend_on_threads() {
        let rows = sample_rows();
        let a = placements_csv(&rows).unwrap();
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let b = one.install(|| placements_csv(&rows).unwrap());
        assert_eq!(a, b);
        assert_eq!(parse(&a), rows);
        // the streaming writer, in several batches, writes the same bytes
        for batch in [ROWS_PER_CHUNK, 3 * ROWS_PER_CHUNK + 5, 1 << 20] {
            let mut out = Vec::new();
            let mut bad = None;
            stream_csv(&mut out, &rows, batch, &mut bad).unwrap();
            assert_eq!(out, a);
            assert_eq!(bad, None);
        }
        // the same bytes as ryu's safe API, field by field
        let mut fmt = ryu::Buffer::new();
        let expect: String = rows
            .iter()
            .map(|r| {
                let mut f: Vec<String> = r.position.iter().map(|&v| fmt.format_finite(v).to_string()).collect();
                f.extend(
                    r.rotation.iter().chain(&r.scale).chain([&r.yaw_deg]).map(|&v| fmt.format_finite(v).to_string()),
                );
                f.push(r.tile.to_string());
                f.push(r.variant.to_string());
                f.join(",") + "\n"
            })
            .collect();
        assert_eq!(&a[PLACEMENT_COLUMNS.join(",").len() + 1..], expect.as_bytes());
    }

    /// The formatter's bytes are ryu's, over random bit patterns of every exponent.
    fn text(put: impl FnOnce(&mut Line<'_>)) -> Vec<u8> {
        let mut buf = [0u8; ROW_MAX + SLACK];
        let mut line = Line { buf: &mut buf, len: 0 };
        put(&mut line);
        let len = line.len;
        buf[..len].to_vec()
    }

    fn f64_text(v: f64) -> Vec<u8> {
        text(|line| push_f64(line, v))
    }

    fn f32_text(v: f32) -> Vec<u8> {
        text(|line| push_f32(line, v))
    }

    /// A quaternion component as `push_row` writes it.
    fn unit_text(v: f32) -> Vec<u8> {
        text(|line| match short_f32(v, &UNIT_GRID) {
            Some(m) => line.put_fixed::<UNIT_DIGITS>(v < 0.0, m),
            None => push_f32(line, v),
        })
    }

    /// A table of several parse pieces reads back as written, with CRLF ends and blank lines too;
    /// an error names the first bad line (counting blank ones), wherever the pieces were cut.
    #[test]
    fn a_table_of_many_pieces_reads_back_in_order_and_names_the_first_bad_line() {
        let rows = sample_rows();
        let csv = String::from_utf8(placements_csv(&rows).unwrap()).unwrap();
        assert!(csv.len() > 2 * PARSE_PIECE_BYTES, "{} bytes: more than one piece", csv.len());
        assert_eq!(parse_placements_csv(&csv).unwrap(), rows);
        assert_eq!(parse_placements_csv(&csv.replace('\n', "\r\n")).unwrap(), rows);
        let lines: Vec<&str> = csv.lines().collect();
        let mut blank = lines.clone();
        blank.insert(5, "");
        blank.insert(20_000, "");
        assert_eq!(parse_placements_csv(&blank.join("\n")).unwrap(), rows);
        for bad in [[29_000usize, 29_500], [4, 28_000], [12_345, 12_346]] {
            let mut l = blank.clone();
            l[bad[0]] = "1,2,3";
            l[bad[1]] = "x";
            let e = parse_placements_csv(&l.join("\r\n")).unwrap_err();
            assert_eq!(e, format!("line {}: 3 fields, expected 13", bad[0] + 1));
        }
        let mut l = lines.clone();
        l[17_000] = "1,2,3,0,0,0,1,1,1,1,0,oops,0";
        let e = parse_placements_csv(&l.join("\n")).unwrap_err();
        assert_eq!(e, "line 17001, column `tile`: `oops` is not a tile number");
    }

    #[test]
    fn integers_are_decimal() {
        let mut h: u64 = 3;
        let mut values: Vec<u64> = (0..20).flat_map(|e| [10u64.pow(e), 10u64.pow(e) - 1, 10u64.pow(e) + 1]).collect();
        values.extend([0, u32::MAX as u64, u64::MAX, 99_999_999, 100_000_000]);
        for _ in 0..100_000 {
            h = crate::random::mix64(h);
            values.push(h >> (h % 64));
        }
        for v in values {
            assert_eq!(text(|line| line.put_u64(v)), v.to_string().as_bytes());
        }
    }

    #[test]
    fn digits_are_ryus() {
        let mut fmt = ryu::Buffer::new();
        let mut h: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut out;
        let near: Vec<f64> = (0..40)
            .flat_map(|e| {
                [10f64.powi(e - 20), 10f64.powi(e - 20) * (1.0 - f64::EPSILON), 9.999_999e14, 9_999_999.0, 1e7 - 0.5]
            })
            .collect();
        for &v in &near {
            for v in [v, -v] {
                out = f64_text(v);
                assert_eq!(out, fmt.format_finite(v).as_bytes());
                out = f32_text(v as f32);
                assert_eq!(out, fmt.format_finite(v as f32).as_bytes());
            }
        }
        for _ in 0..200_000 {
            h = crate::random::mix64(h);
            let (d, s) = (f64::from_bits(h), f32::from_bits((h >> 32) as u32));
            for (a, b) in [(d, s as f64), (h as f64 * 1e-12, (h >> 40) as f64 / 16.0)] {
                if a.is_finite() {
                    out = f64_text(a);
                    assert_eq!(out, fmt.format_finite(a).as_bytes());
                }
                let b = b as f32;
                if b.is_finite() {
                    out = f32_text(b);
                    assert_eq!(out, fmt.format_finite(b).as_bytes());
                }
            }
        }
    }

    /// Short decimals (the fast path) are ryu's bytes too: every f32 that is the nearest float to
    /// k·10⁻⁴ below 1024 (every scale, yaw in 0.01°), and f64 on 10⁻⁴ and 10⁻⁶ grids up to the
    /// range's ends, both signs; and values just off a grid, which take the general path.
    #[test]
    fn short_decimals_are_ryus() {
        let mut fmt = ryu::Buffer::new();
        let mut out = Vec::new();
        let mut check32 = |v: f32, out: &mut Vec<u8>| {
            *out = f32_text(v);
            assert_eq!(&out[..], fmt.format_finite(v).as_bytes(), "{v:e}");
        };
        for k in 0..10_240_000u32 {
            let v = (k as f64 / 1e4) as f32;
            // the short path takes every one of them (from 10⁻⁴ on)
            assert_eq!(short_f32(v, &SHORT_GRID), (k > 0).then_some(k as u64), "{v:e}");
            for v in [v, -v, f32::from_bits(v.to_bits() + 1), f32::from_bits(v.to_bits().saturating_sub(1))] {
                check32(v, &mut out);
            }
        }
        for k in 0..36_000u32 {
            check32((k as f64 / 100.0) as f32, &mut out);
            check32(k as f32 / 100.0, &mut out);
        }
        let mut fmt = ryu::Buffer::new();
        let mut h: u64 = 7;
        for _ in 0..1_000_000 {
            h = crate::random::mix64(h);
            let m = (h >> 20) % 1_000_000_000_000_000; // below 10^15: values below 10^9 at 10⁻⁶
            let short = m % 1_000_000_000_000_000 / 1000; // below 10^12: values below 10^6 at 10⁻⁶
            if short >= 100 {
                assert_eq!(short_f64(short as f64 / 1e6), Some(short));
                assert_eq!(short_f64(-((short / 100) as f64) / 1e4), Some(short / 100 * 100));
            }
            for v in [
                m as f64 / 1e4,
                m as f64 / 1e6,
                (m % 100_000) as f64 / 1e6,
                (h >> 11) as f64 / (1u64 << 53) as f64 * 4096.0,
            ] {
                for v in [v, -v, f64::from_bits(v.to_bits() + 1), f64::from_bits(v.to_bits().saturating_sub(1))] {
                    out = f64_text(v);
                    assert_eq!(&out[..], fmt.format_finite(v).as_bytes(), "{v:e}");
                }
            }
        }
        for v in [1e-4, 1e-4 - 1e-20, 1e9, 1e9 - 1e-6, 999_999_999.999_999, 0.000_100_000_1, 0.5, 1.0, 10.0] {
            out = f64_text(v);
            assert_eq!(&out[..], fmt.format_finite(v).as_bytes(), "{v:e}");
        }
        for v in [
            1e-4f32, 255.9999, 256.0, 255.99998, 0.00010001, 1023.9999, 1024.0, 1023.99994, 1024.0001, 359.99, 512.0001,
        ] {
            check32(v, &mut out);
        }
    }

    /// Quaternion components on their 10⁻⁷ grid (every one of them, as the scatter rounds them),
    /// their neighbouring floats and the ends of the range are written as ryu writes them, and the
    /// grid's values take the short path from 10⁻⁵ on.
    #[test]
    fn unit_grid_decimals_are_ryus() {
        let mut fmt = ryu::Buffer::new();
        for k in 0..=10_000_000u32 {
            // as the scatter rounds a component: the nearest f32 to the nearest f64 to k·10⁻⁷
            let v = (k as f64 / 1e7) as f32;
            assert_eq!(short_f32(v, &UNIT_GRID), (k >= 100).then_some(k as u64), "{v:e}");
            let near = [f32::from_bits(v.to_bits() + 1), f32::from_bits(v.to_bits().saturating_sub(1))];
            for v in [v, -v].into_iter().chain(if k % 5 == 0 { near.to_vec() } else { vec![] }) {
                assert_eq!(unit_text(v), fmt.format_finite(v).as_bytes(), "{v:e}");
            }
        }
        for v in [1e-5f32, 0.99999994, 1.0, 1.000_000_1, 9.99e-6, 1.0e-5 * (1.0 + f32::EPSILON), 0.1, 0.5] {
            for v in [v, -v] {
                assert_eq!(unit_text(v), fmt.format_finite(v).as_bytes(), "{v:e}");
            }
        }
    }

    #[test]
    fn extremes_round_trip() {
        let rows: Vec<PlacementRow> = [f64::MAX, f64::MIN_POSITIVE, -1e-300, 5e-324, 0.0, -0.0, 123_456_789.123_456_79]
            .iter()
            .enumerate()
            .map(|(k, &v)| PlacementRow {
                position: [v, -v, v * 0.5],
                rotation: [f32::MAX, f32::MIN_POSITIVE, -1e-45, -0.0],
                scale: [v.clamp(-1e38, 1e38) as f32, 1e-40, 1.0],
                yaw_deg: 359.99997,
                tile: [u32::MAX, 0, 9, 10, 99, 100, 1_000_000_007][k],
                variant: [0, u32::MAX, 1, 15, 7, 100_000_000, 99_999_999][k],
            })
            .collect();
        assert_eq!(parse(&placements_csv(&rows).unwrap()), rows);
    }

    /// The unchecked stores with their checks on (`fast_path_check!` asserts in unit tests): rows of
    /// the longest fields, one buffer sized for exactly one row, so a store past the row's budget
    /// (ROW_MAX + SLACK) fails here instead of writing past the buffer in release.
    #[test]
    fn the_longest_rows_stay_within_their_budget() {
        let longest_f64 = [-1.234_567_890_123_456_7e-300, -2.225_073_858_507_201_4e-308, -f64::MAX, -5e-324];
        let longest_f32 = [-1.175_494_4e-38f32, -3.402_823_5e38, -1.401_298_5e-45, -1.234_567_9e-37];
        for (k, (&d, &f)) in longest_f64.iter().zip(&longest_f32).enumerate() {
            let row = PlacementRow {
                position: [d, d, d],
                rotation: [f; 4],
                scale: [f, -f, f],
                yaw_deg: -f,
                tile: u32::MAX - k as u32,
                variant: u32::MAX - k as u32,
            };
            let mut buf = vec![0u8; ROW_MAX + SLACK];
            let mut line = Line { buf: &mut buf, len: 0 };
            assert!(push_row(&mut line, &row));
            let len = line.len;
            assert!(len <= ROW_MAX, "a row of {len} bytes is longer than ROW_MAX = {ROW_MAX}");
            assert_eq!(buf[len - 1], b'\n');
            let header = format!("{}\n", PLACEMENT_COLUMNS.join(","));
            assert_eq!(parse(&[header.as_bytes(), &buf[..len]].concat()), vec![row]);
        }
    }

    #[test]
    fn empty_table_has_a_header_and_nan_is_refused() {
        assert_eq!(placements_csv::<PlacementRow>(&[]).unwrap(), b"x,y,z,qx,qy,qz,qw,sx,sy,sz,yaw_deg,tile,variant\n");
        let bad = PlacementRow {
            position: [f64::NAN, 0.0, 0.0],
            rotation: [0.0, 0.0, 0.0, 1.0],
            scale: [1.0; 3],
            yaw_deg: 0.0,
            tile: 0,
            variant: 0,
        };
        assert!(placements_csv(&[bad]).unwrap_err().contains("row 0"));
        let mut rows = vec![
            PlacementRow {
                position: [1.0; 3],
                rotation: [0.0, 0.0, 0.0, 1.0],
                scale: [1.0; 3],
                yaw_deg: 0.0,
                tile: 0,
                variant: 0,
            };
            70_000
        ];
        rows[50_001].scale[2] = f32::INFINITY;
        assert!(placements_csv(&rows).unwrap_err().contains("row 50001"));
        let mut bad = None;
        assert!(stream_csv(&mut Vec::new(), &rows, ROWS_PER_CHUNK, &mut bad).is_err());
        assert_eq!(bad, Some(50_001));
        let dir = tempfile::tempdir().unwrap();
        let e = write_placements_csv(&dir.path().join("p.csv"), &rows).unwrap_err();
        assert!(e.to_string().contains("row 50001"), "{e}");
        assert!(!dir.path().join("p.csv").exists());
    }
}
