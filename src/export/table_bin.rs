//! Binary placement tables (`[scatter] table = "binary"`): the rows of a CSV table as
//! little-endian arrays, for engines that load millions of instances (a grass CSV of 10⁷ rows is
//! ~1.4 GB of text to parse; this is 64 bytes a row to copy). Layout (`placements/<species>.bin`):
//!
//! | bytes | what |
//! |---|---|
//! | 0..4 | magic `VPLT` |
//! | 4..8 | version, u32 (1) |
//! | 8..16 | rows n, u64 |
//! | 16.. | `position` f64 × 3 × n, `rotation` f32 × 4 × n (x, y, z, w), `scale` f32 × 3 × n, `yaw_deg` f32 × n, `tile` u32 × n, `variant` u32 × n |
//!
//! Arrays follow each other without padding (every offset is a multiple of 4, positions of 8);
//! [`layout`] gives them as the JSON header written in `placements/<species>.json`. The values are
//! those of the CSV exactly (positions stay f64), so a scene builds the same from either.

use std::io::Write;
use std::path::Path;

use serde::Serialize;

use crate::export::atomic::write_atomic_with;
use crate::export::error::ExportError;
use crate::export::table::{PlacementRow, ToPlacementRow};

pub const MAGIC: &[u8; 4] = b"VPLT";
pub const VERSION: u32 = 1;
/// Bytes before the first array.
pub const HEADER_BYTES: u64 = 16;
/// Bytes of one row over all arrays.
pub const ROW_BYTES: u64 = 24 + 16 + 12 + 4 + 4 + 4;

/// One array of the file, as the JSON header lists it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BinArray {
    pub name: &'static str,
    /// `f64`, `f32` or `u32`, little-endian.
    pub component_type: &'static str,
    pub components: u32,
    /// Byte offset of the array in the file.
    pub offset: u64,
}

/// The JSON header of a binary table of `rows` rows.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BinLayout {
    pub format: &'static str,
    pub version: u32,
    pub rows: u64,
    pub bytes: u64,
    pub arrays: Vec<BinArray>,
}

const ARRAYS: [(&str, &str, u32, u64); 6] = [
    ("position", "f64", 3, 8),
    ("rotation", "f32", 4, 4),
    ("scale", "f32", 3, 4),
    ("yaw_deg", "f32", 1, 4),
    ("tile", "u32", 1, 4),
    ("variant", "u32", 1, 4),
];

/// Where each array of a table of `rows` rows lies.
pub fn layout(rows: u64) -> BinLayout {
    let mut offset = HEADER_BYTES;
    let arrays = ARRAYS
        .iter()
        .map(|&(name, component_type, components, size)| {
            let a = BinArray { name, component_type, components, offset };
            offset += rows * components as u64 * size;
            a
        })
        .collect();
    BinLayout { format: "verdant placement table", version: VERSION, rows, bytes: offset, arrays }
}

/// The table's bytes; non-finite numbers are refused (naming the row), as for CSV.
pub fn placements_bin<R: ToPlacementRow>(rows: &[R]) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity((HEADER_BYTES + ROW_BYTES * rows.len() as u64) as usize);
    write_bin(&mut out, rows).map_err(|e| e.to_string())?;
    Ok(out)
}

/// Writes the binary table to `path` atomically.
pub fn write_placements_bin<R: ToPlacementRow>(path: &Path, rows: &[R]) -> Result<(), ExportError> {
    write_atomic_with(path, |w| {
        let mut w = std::io::BufWriter::with_capacity(1 << 20, w);
        write_bin(&mut w, rows)?;
        w.flush()
    })
}

fn write_bin<R: ToPlacementRow>(w: &mut dyn Write, rows: &[R]) -> std::io::Result<()> {
    if let Some(bad) = rows.iter().position(|r| !finite(&r.placement_row())) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("row {bad} holds a value that is not a finite number"),
        ));
    }
    w.write_all(MAGIC)?;
    w.write_all(&VERSION.to_le_bytes())?;
    w.write_all(&(rows.len() as u64).to_le_bytes())?;
    // one pass per array (each a contiguous run of the file)
    for r in rows {
        for v in r.placement_row().position {
            w.write_all(&v.to_le_bytes())?;
        }
    }
    for r in rows {
        for v in r.placement_row().rotation {
            w.write_all(&v.to_le_bytes())?;
        }
    }
    for r in rows {
        for v in r.placement_row().scale {
            w.write_all(&v.to_le_bytes())?;
        }
    }
    for r in rows {
        w.write_all(&r.placement_row().yaw_deg.to_le_bytes())?;
    }
    for r in rows {
        w.write_all(&r.placement_row().tile.to_le_bytes())?;
    }
    for r in rows {
        w.write_all(&r.placement_row().variant.to_le_bytes())?;
    }
    Ok(())
}

fn finite(r: &PlacementRow) -> bool {
    r.position.iter().all(|v| v.is_finite())
        && r.rotation.iter().chain(&r.scale).all(|v| v.is_finite())
        && r.yaw_deg.is_finite()
}

/// Reads a binary table back; errors name the byte offset or row at fault.
pub fn read_placements_bin(path: &Path) -> Result<Vec<PlacementRow>, String> {
    let bytes = crate::input::read_limited(path, crate::input::MAX_TABLE_BYTES, "a placement table")
        .map_err(|e| e.to_string())?;
    parse_placements_bin(&bytes)
}

/// [`read_placements_bin`] on the bytes of a table.
pub fn parse_placements_bin(bytes: &[u8]) -> Result<Vec<PlacementRow>, String> {
    if bytes.len() < HEADER_BYTES as usize || &bytes[0..4] != MAGIC {
        return Err("bytes 0..4: not a verdant binary placement table (no `VPLT` magic)".into());
    }
    let version = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]);
    if version != VERSION {
        return Err(format!("bytes 4..8: version {version}, this verdant reads version {VERSION}"));
    }
    let n = u64::from_le_bytes(bytes[8..16].try_into().unwrap_or_default());
    let want = n.checked_mul(ROW_BYTES).and_then(|b| b.checked_add(HEADER_BYTES));
    if want != Some(bytes.len() as u64) {
        return Err(format!(
            "bytes 8..16: {n} rows need {} bytes, the file has {}",
            want.map_or_else(|| "more than 2^64".to_string(), |b| b.to_string()),
            bytes.len()
        ));
    }
    let n = n as usize;
    let l = layout(n as u64);
    let at = |k: usize| l.arrays[k].offset as usize;
    let f64_at = |o: usize| f64::from_le_bytes(bytes[o..o + 8].try_into().unwrap_or_default());
    let f32_at = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap_or_default());
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap_or_default());
    let mut rows = Vec::with_capacity(n);
    for i in 0..n {
        let row = PlacementRow {
            position: [0, 1, 2].map(|c| f64_at(at(0) + 8 * (3 * i + c))),
            rotation: [0, 1, 2, 3].map(|c| f32_at(at(1) + 4 * (4 * i + c))),
            scale: [0, 1, 2].map(|c| f32_at(at(2) + 4 * (3 * i + c))),
            yaw_deg: f32_at(at(3) + 4 * i),
            tile: u32_at(at(4) + 4 * i),
            variant: u32_at(at(5) + 4 * i),
        };
        if !finite(&row) {
            return Err(format!("row {i}: a value is not a finite number"));
        }
        rows.push(row);
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows() -> Vec<PlacementRow> {
        (0..1000u32)
            .map(|k| PlacementRow {
                position: [k as f64 * 0.1234, -(k as f64) / 3.0, 1e6 + k as f64],
                rotation: [0.0, (k as f32).sin(), 0.0, (k as f32).cos()],
                scale: [1.0 + k as f32 * 1e-3; 3],
                yaw_deg: (k % 360) as f32,
                tile: k / 100,
                variant: k % 3,
            })
            .collect()
    }

    #[test]
    fn rows_round_trip_exactly_at_the_documented_offsets() {
        let rows = rows();
        let bytes = placements_bin(&rows).unwrap();
        let l = layout(rows.len() as u64);
        assert_eq!(bytes.len() as u64, l.bytes);
        assert_eq!(l.bytes, HEADER_BYTES + ROW_BYTES * rows.len() as u64);
        assert_eq!(parse_placements_bin(&bytes).unwrap(), rows);
        // row 7's fields where the header says they are
        let f = |name: &str| l.arrays.iter().find(|a| a.name == name).unwrap().offset as usize;
        let o = f("position") + 8 * 3 * 7 + 8;
        assert_eq!(f64::from_le_bytes(bytes[o..o + 8].try_into().unwrap()), rows[7].position[1]);
        let o = f("variant") + 4 * 7;
        assert_eq!(u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()), rows[7].variant);
        assert!(l.arrays.iter().all(|a| a.offset % 4 == 0));
        assert_eq!(placements_bin::<PlacementRow>(&[]).unwrap().len(), HEADER_BYTES as usize);
    }

    #[test]
    fn damaged_tables_are_errors_naming_where() {
        let bytes = placements_bin(&rows()).unwrap();
        assert!(parse_placements_bin(&bytes[..bytes.len() - 1]).unwrap_err().contains("bytes 8..16"));
        assert!(parse_placements_bin(b"VPL").unwrap_err().contains("magic"));
        let mut v = bytes.clone();
        v[4] = 9;
        assert!(parse_placements_bin(&v).unwrap_err().contains("version 9"));
        let mut huge = bytes[..16].to_vec();
        huge[8..16].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(parse_placements_bin(&huge).unwrap_err().contains("rows need"));
        let mut nan = bytes.clone();
        let o = layout(1000).arrays[3].offset as usize + 4 * 5;
        nan[o..o + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(parse_placements_bin(&nan).unwrap_err().contains("row 5"));
        let mut bad = rows();
        bad[3].scale[0] = f32::INFINITY;
        assert!(placements_bin(&bad).unwrap_err().contains("row 3"));
    }
}
