//! Placement tables: one CSV row per instance, for engines that do not read EXT_mesh_gpu_instancing
//! (Godot, Unreal) and for tools. Numbers are written in their shortest round-trip form (ryu's bytes), so
//! a reader gets back exactly the values in memory; rows are formatted in parallel chunks and
//! joined in order, so the bytes do not depend on the thread count.

use std::path::Path;

use rayon::prelude::*;
use serde_json::ser::{CompactFormatter, Formatter};

use crate::export::{write_atomic_with, ExportError};

/// The columns of a placement table, in order.
pub const PLACEMENT_COLUMNS: [&str; 12] = ["x", "y", "z", "qx", "qy", "qz", "qw", "sx", "sy", "sz", "yaw_deg", "tile"];

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
}

/// Rows formatted by one task; a task's buffer is reserved once for its rows at the longest.
const ROWS_PER_CHUNK: usize = 16_384;
/// Chunks formatted while the previous batch is written (bounds the streaming writer's memory to
/// two batches: 2 × 32 × 16384 rows ≈ 150 MB at 143 B/row).
const CHUNKS_PER_BATCH: usize = 32;
/// Longest row: a shortest round-trip f64 is at most 24 bytes and an f32 16, a u32 has 10 digits,
/// and 11 commas + a newline.
const ROW_MAX: usize = 3 * 24 + 8 * 16 + 10 + 12;

/// Appends one row: each number's shortest round-trip digits, a field equal to the previous one
/// (the uniform scale) copied instead of formatted again, the tile by pairs of digits. Returns
/// false (writing nothing) if a number is not finite. The caller reserves [`ROW_MAX`] per row, so
/// nothing reallocates here.
///
/// The digits come from serde_json's `CompactFormatter` (already a dependency), which writes
/// floats with Żmij (Schubfach-based, shortest round-trip): the same bytes as
/// `ryu::Buffer::format_finite` (tested below), 20–35 % less CPU per number.
#[inline]
fn push_row(out: &mut Vec<u8>, r: &PlacementRow) -> bool {
    let finite = r.position.iter().all(|v| v.is_finite()) && r.rotation.iter().chain(&r.scale).all(|v| v.is_finite()) && r.yaw_deg.is_finite();
    if !finite {
        return false;
    }
    for v in r.position {
        push_f64(out, v);
        out.push(b',');
    }
    let mut prev: (u32, usize, usize) = (u32::MAX, 0, 0); // bits, start, end of the last f32 field
    for v in r.rotation.into_iter().chain(r.scale).chain([r.yaw_deg]) {
        let bits = v.to_bits();
        if bits == prev.0 {
            out.extend_from_within(prev.1..prev.2);
        } else {
            let start = out.len();
            push_f32(out, v);
            prev = (bits, start, out.len());
        }
        out.push(b',');
    }
    push_u32(out, r.tile);
    out.push(b'\n');
    true
}

/// Below these magnitudes Żmij and ryu write the same bytes (above, Żmij writes "1e+16" where ryu
/// writes "1e16"; such values are ryu's, so the bytes never depend on the formatter).
const ZMIJ_F64_BELOW: f64 = 1e15;
const ZMIJ_F32_BELOW: f32 = 1e7;

#[inline]
fn push_f64(out: &mut Vec<u8>, v: f64) {
    if v.abs() < ZMIJ_F64_BELOW {
        let _ = CompactFormatter.write_f64(out, v); // into a Vec: cannot fail
    } else {
        out.extend_from_slice(ryu::Buffer::new().format_finite(v).as_bytes());
    }
}

#[inline]
fn push_f32(out: &mut Vec<u8>, v: f32) {
    if v.abs() < ZMIJ_F32_BELOW {
        let _ = CompactFormatter.write_f32(out, v);
    } else {
        out.extend_from_slice(ryu::Buffer::new().format_finite(v).as_bytes());
    }
}

/// "00" … "99".
const PAIRS: &[u8; 200] = b"00010203040506070809101112131415161718192021222324252627282930313233343536373839404142434445464748495051525354555657585960616263646566676869707172737475767778798081828384858687888990919293949596979899";

/// Appends `v` in decimal, two digits at a time.
#[inline]
fn push_u32(out: &mut Vec<u8>, mut v: u32) {
    let mut buf = [0u8; 10];
    let mut k = buf.len();
    while v >= 100 {
        let p = (v % 100) as usize * 2;
        v /= 100;
        k -= 2;
        buf[k..k + 2].copy_from_slice(&PAIRS[p..p + 2]);
    }
    if v >= 10 {
        let p = v as usize * 2;
        k -= 2;
        buf[k..k + 2].copy_from_slice(&PAIRS[p..p + 2]);
    } else {
        k -= 1;
        buf[k] = b'0' + v as u8;
    }
    out.extend_from_slice(&buf[k..]);
}

/// Formats `chunk` (whose first row is row `first` of the table) into `buf` (cleared first);
/// `Err(row)` names the first row holding a non-finite number.
fn format_chunk(chunk: &[PlacementRow], first: usize, buf: &mut Vec<u8>) -> Result<(), usize> {
    buf.clear();
    buf.reserve(chunk.len() * ROW_MAX);
    for (k, r) in chunk.iter().enumerate() {
        if !push_row(buf, r) {
            return Err(first + k);
        }
    }
    Ok(())
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
fn format_batch(rows: &[PlacementRow], first: usize, bufs: &mut Vec<Vec<u8>>) -> Result<(), usize> {
    let chunks = rows.len().div_ceil(ROWS_PER_CHUNK);
    bufs.resize_with(bufs.len().max(chunks), Vec::new);
    let results: Vec<Result<(), usize>> = bufs[..chunks]
        .par_iter_mut()
        .zip(rows.par_chunks(ROWS_PER_CHUNK))
        .enumerate()
        .map(|(c, (buf, chunk))| format_chunk(chunk, first + c * ROWS_PER_CHUNK, buf))
        .collect();
    for b in &mut bufs[chunks..] {
        b.clear();
    }
    results.into_iter().collect()
}

/// The table as CSV bytes: a header line, then one line per row. Non-finite numbers are refused
/// (a placement bug, not something to write). Built by the streaming writer into one growing
/// buffer, so only two batches of chunk buffers exist besides it (fresh pages are costly).
pub fn placements_csv(rows: &[PlacementRow]) -> Result<Vec<u8>, String> {
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
pub fn write_placements_csv(path: &Path, rows: &[PlacementRow]) -> Result<(), ExportError> {
    let mut bad: Option<usize> = None;
    let result = write_atomic_with(path, |w| stream_csv(w, rows, ROWS_PER_CHUNK * CHUNKS_PER_BATCH, &mut bad));
    match (result, bad) {
        (Err(_), Some(row)) => Err(ExportError::InvalidScene { path: path.to_path_buf(), problem: not_finite(row) }),
        (r, _) => r,
    }
}

/// The CSV into `w` in batches of `batch` rows (the next batch formatted while this thread writes
/// the current one); a non-finite number stops it with an error and its row in `bad`.
fn stream_csv(w: &mut dyn std::io::Write, rows: &[PlacementRow], batch: usize, bad: &mut Option<usize>) -> std::io::Result<()> {
    let mut refuse = |row: usize| {
        *bad = Some(row);
        std::io::Error::new(std::io::ErrorKind::InvalidData, not_finite(row))
    };
    w.write_all(&header())?;
    let mut cur: Vec<Vec<u8>> = Vec::new();
    let mut next: Vec<Vec<u8>> = Vec::new();
    let mut batches = rows.chunks(batch.max(1)).enumerate();
    let Some((_, first)) = batches.next() else { return Ok(()) };
    format_batch(first, 0, &mut cur).map_err(&mut refuse)?;
    for (k, rows) in batches {
        let mut formatted = Ok(());
        let written = rayon::in_place_scope(|s| {
            s.spawn(|_| formatted = format_batch(rows, k * batch, &mut next));
            cur.iter().try_for_each(|b| w.write_all(b))
        });
        written?;
        formatted.map_err(&mut refuse)?;
        std::mem::swap(&mut cur, &mut next);
    }
    cur.iter().try_for_each(|b| w.write_all(b))
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
                assert_eq!(f.len(), 12);
                let d = |k: usize| f[k].parse::<f64>().unwrap();
                let s = |k: usize| f[k].parse::<f32>().unwrap();
                PlacementRow {
                    position: [d(0), d(1), d(2)],
                    rotation: [s(3), s(4), s(5), s(6)],
                    scale: [s(7), s(8), s(9)],
                    yaw_deg: s(10),
                    tile: f[11].parse().unwrap(),
                }
            })
            .collect()
    }

    #[test]
    fn rows_round_trip_exactly_and_bytes_do_not_depend_on_threads() {
        let rows: Vec<PlacementRow> = (0..40_000u32)
            .map(|k| {
                let t = k as f64 * 0.123_456_789;
                PlacementRow {
                    position: [t, -t / 7.0, 1e6 + t],
                    rotation: [0.0, (t as f32).sin(), 0.0, (t as f32).cos()],
                    scale: [1.0 + k as f32 * 1e-5; 3],
                    yaw_deg: (k % 360) as f32 + 0.25,
                    tile: k / 1000,
                }
            })
            .collect();
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
                f.extend(r.rotation.iter().chain(&r.scale).chain([&r.yaw_deg]).map(|&v| fmt.format_finite(v).to_string()));
                f.push(r.tile.to_string());
                f.join(",") + "\n"
            })
            .collect();
        assert_eq!(&a[PLACEMENT_COLUMNS.join(",").len() + 1..], expect.as_bytes());
    }

    /// The formatter's bytes are ryu's, over random bit patterns of every exponent.
    #[test]
    fn digits_are_ryus() {
        let mut fmt = ryu::Buffer::new();
        let mut h: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut out = Vec::new();
        let near: Vec<f64> = (0..40).flat_map(|e| [10f64.powi(e - 20), 10f64.powi(e - 20) * (1.0 - f64::EPSILON), 9.999_999e14, 9_999_999.0, 1e7 - 0.5]).collect();
        for &v in &near {
            for v in [v, -v] {
                out.clear();
                push_f64(&mut out, v);
                assert_eq!(out, fmt.format_finite(v).as_bytes());
                out.clear();
                push_f32(&mut out, v as f32);
                assert_eq!(out, fmt.format_finite(v as f32).as_bytes());
            }
        }
        for _ in 0..200_000 {
            h = crate::synth::mix64(h);
            let (d, s) = (f64::from_bits(h), f32::from_bits((h >> 32) as u32));
            for (a, b) in [(d, s as f64), (h as f64 * 1e-12, (h >> 40) as f64 / 16.0)] {
                if a.is_finite() {
                    out.clear();
                    push_f64(&mut out, a);
                    assert_eq!(out, fmt.format_finite(a).as_bytes());
                }
                let b = b as f32;
                if b.is_finite() {
                    out.clear();
                    push_f32(&mut out, b);
                    assert_eq!(out, fmt.format_finite(b).as_bytes());
                }
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
            })
            .collect();
        assert_eq!(parse(&placements_csv(&rows).unwrap()), rows);
    }

    #[test]
    fn empty_table_has_a_header_and_nan_is_refused() {
        assert_eq!(placements_csv(&[]).unwrap(), b"x,y,z,qx,qy,qz,qw,sx,sy,sz,yaw_deg,tile\n");
        let bad = PlacementRow { position: [f64::NAN, 0.0, 0.0], rotation: [0.0, 0.0, 0.0, 1.0], scale: [1.0; 3], yaw_deg: 0.0, tile: 0 };
        assert!(placements_csv(&[bad]).unwrap_err().contains("row 0"));
        let mut rows = vec![PlacementRow { position: [1.0; 3], rotation: [0.0, 0.0, 0.0, 1.0], scale: [1.0; 3], yaw_deg: 0.0, tile: 0 }; 70_000];
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
