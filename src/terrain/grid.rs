//! Regular grid triangulation of a heightfield: every `step`-th sample (plus the last row and column),
//! two triangles per cell. Step 1 reproduces the heightmap exactly; it is the reference the greedy
//! TIN (`tin`) is measured against.

use crate::heightfield::Heightfield;
use crate::terrain::error::{check_heightfield, TerrainError};
use crate::terrain::sample_mesh::SampleMesh;

/// Sample positions along one axis of `n` samples: 0, step, 2·step, … and always n − 1.
fn axis(n: usize, step: usize) -> Vec<u32> {
    let mut v: Vec<u32> = (0..n).step_by(step).map(|x| x as u32).collect();
    if v.last() != Some(&((n - 1) as u32)) {
        v.push((n - 1) as u32);
    }
    v
}

/// Triangulates every `step`-th sample of `hf` (always including the last row and column), two
/// triangles per cell, counter-clockwise seen from +Y. Vertices are row-major.
pub fn grid(hf: &Heightfield, step: usize) -> Result<SampleMesh, TerrainError> {
    check_heightfield(hf)?;
    if step == 0 {
        return Err(TerrainError::ZeroStep { step });
    }
    let xs = axis(hf.width, step);
    let zs = axis(hf.height, step);
    let (nx, nz) = (xs.len(), zs.len());
    let mut mesh =
        SampleMesh { vertices: Vec::with_capacity(nx * nz), triangles: Vec::with_capacity(2 * (nx - 1) * (nz - 1)) };
    for &j in &zs {
        for &i in &xs {
            mesh.vertices.push([i, j]);
        }
    }
    // Cell corners a = (i0, j0), b = (i1, j0), c = (i0, j1), d = (i1, j1). (a, c, b) and (b, c, d) are
    // counter-clockwise seen from +Y (clockwise in the (i, j) plane, see `SampleMesh`).
    for r in 0..nz - 1 {
        for q in 0..nx - 1 {
            let a = (r * nx + q) as u32;
            let b = a + 1;
            let c = a + nx as u32;
            let d = c + 1;
            mesh.triangles.push([a, c, b]);
            mesh.triangles.push([b, c, d]);
        }
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::error::measure;
    use crate::terrain::tin::tests::check_mesh;

    fn noise(w: usize, h: usize) -> Heightfield {
        let heights = (0..w * h).map(|k| (crate::random::mix64(k as u64) % 1000) as f32 * 0.25).collect();
        Heightfield { width: w, height: h, heights, cell_size_m: 1.0, exact: None }
    }

    #[test]
    fn step_one_is_exact() {
        let map = noise(13, 7);
        let mesh = grid(&map, 1).unwrap();
        assert_eq!(mesh.vertices.len(), 13 * 7);
        assert_eq!(mesh.triangles.len(), 2 * 12 * 6);
        check_mesh(&map, &mesh);
        let s = measure(&map, &mesh);
        assert_eq!(s.max_error_m, 0.0);
        assert_eq!(s.rms_error_m, 0.0);
        assert_eq!(s.samples_covered, 13 * 7);
    }

    #[test]
    fn coarse_step_keeps_last_row_and_column() {
        let map = noise(10, 6);
        let mesh = grid(&map, 4).unwrap();
        // columns 0, 4, 8, 9; rows 0, 4, 5
        assert_eq!(mesh.vertices.len(), 4 * 3);
        assert!(mesh.vertices.contains(&[9, 5]));
        check_mesh(&map, &mesh);
        assert_eq!(measure(&map, &mesh).samples_covered, 60);
        // A step larger than the map gives the two corner triangles.
        assert_eq!(grid(&map, 100).unwrap().triangles.len(), 2);
    }

    #[test]
    fn rejects_bad_input() {
        let line = Heightfield { width: 1, height: 9, heights: vec![0.0; 9], cell_size_m: 1.0, exact: None };
        assert_eq!(grid(&line, 1), Err(TerrainError::ZeroArea { width: 1, height: 9 }));
        assert_eq!(grid(&noise(3, 3), 0), Err(TerrainError::ZeroStep { step: 0 }));
    }
}
