//! Placement tables: one CSV row per instance, for engines that do not read EXT_mesh_gpu_instancing
//! (Godot, Unreal) and for tools. Numbers are written in their shortest round-trip form (ryu), so
//! a reader gets back exactly the values in memory; rows are formatted in parallel chunks and
//! joined in order, so the bytes do not depend on the thread count.

use std::path::Path;

use rayon::prelude::*;

use crate::export::{write_atomic, ExportError};

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

const ROWS_PER_CHUNK: usize = 16_384;

fn push_row(out: &mut Vec<u8>, r: &PlacementRow, fmt: &mut ryu::Buffer) {
    let field = |out: &mut Vec<u8>, s: &str| {
        out.extend_from_slice(s.as_bytes());
        out.push(b',');
    };
    for v in r.position {
        field(out, fmt.format_finite(v));
    }
    for v in r.rotation {
        field(out, fmt.format_finite(v));
    }
    for v in r.scale {
        field(out, fmt.format_finite(v));
    }
    field(out, fmt.format_finite(r.yaw_deg));
    // integers: write! into a Vec cannot fail
    let _ = std::io::Write::write_fmt(out, format_args!("{}\n", r.tile));
}

/// The table as CSV bytes: a header line, then one line per row. Non-finite numbers are refused
/// (a placement bug, not something to write).
pub fn placements_csv(rows: &[PlacementRow]) -> Result<Vec<u8>, String> {
    if let Some(k) = rows.iter().position(|r| {
        !(r.position.iter().all(|v| v.is_finite())
            && r.rotation.iter().all(|v| v.is_finite())
            && r.scale.iter().all(|v| v.is_finite())
            && r.yaw_deg.is_finite())
    }) {
        return Err(format!("row {k} holds a value that is not a finite number"));
    }
    let mut out = PLACEMENT_COLUMNS.join(",").into_bytes();
    out.push(b'\n');
    let chunks: Vec<Vec<u8>> = rows
        .par_chunks(ROWS_PER_CHUNK)
        .map(|chunk| {
            let mut buf = Vec::with_capacity(chunk.len() * 120);
            let mut fmt = ryu::Buffer::new();
            for r in chunk {
                push_row(&mut buf, r, &mut fmt);
            }
            buf
        })
        .collect();
    out.reserve(chunks.iter().map(Vec::len).sum());
    for c in chunks {
        out.extend_from_slice(&c);
    }
    Ok(out)
}

/// Writes the placement table to `path` atomically.
pub fn write_placements_csv(path: &Path, rows: &[PlacementRow]) -> Result<(), ExportError> {
    let bytes = placements_csv(rows).map_err(|problem| ExportError::InvalidScene {
        path: path.to_path_buf(),
        problem,
    })?;
    write_atomic(path, &bytes)
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
    }

    #[test]
    fn empty_table_has_a_header_and_nan_is_refused() {
        assert_eq!(placements_csv(&[]).unwrap(), b"x,y,z,qx,qy,qz,qw,sx,sy,sz,yaw_deg,tile\n");
        let bad = PlacementRow { position: [f64::NAN, 0.0, 0.0], rotation: [0.0, 0.0, 0.0, 1.0], scale: [1.0; 3], yaw_deg: 0.0, tile: 0 };
        assert!(placements_csv(&[bad]).unwrap_err().contains("row 0"));
    }
}
