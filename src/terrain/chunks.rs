//! Chunk partition of a sample triangulation: square tiles on the sample grid, each triangle given
//! to the tile that holds its centroid, and the boundary edges of a set of triangles (where skirts
//! hang and the solid base's walls start).

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// A hash map keyed by integers, hashed with a SplitMix64 finaliser instead of SipHash: keys are
/// our own vertex and edge ids (nothing untrusted to defend against) and SipHash was the larger part
/// of building a 1025² grid. Used for look-ups only, never iterated, so output order does not
/// depend on it.
pub type IdMap<K, V> = HashMap<K, V, BuildHasherDefault<IdHasher>>;

/// Hasher for [`IdMap`]: mixes each integer written into the state with `random::mix64`.
#[derive(Debug, Default, Clone, Copy)]
pub struct IdHasher(u64);

impl Hasher for IdHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u32(&mut self, n: u32) {
        self.write_u64(n as u64);
    }
    fn write_u64(&mut self, n: u64) {
        self.0 = crate::random::mix64(self.0.rotate_left(32) ^ n);
    }
    fn write_usize(&mut self, n: usize) {
        self.write_u64(n as u64);
    }
}

/// Square chunks of `pitch` cells over a `width` × `height` sample map.
///
/// Chunk (ci, cj) spans samples [ci·pitch, min((ci+1)·pitch, width−1)] along i (and likewise along
/// j): neighbouring chunks *share* their border column/row of samples. A chunk is the set of
/// triangles whose centroid lies in its rectangle. A TIN meshed with the terrain's chunks
/// ([`crate::terrain::tin::TinOptions::chunk_cells`]) follows every chunk line, so each chunk
/// fills its rectangle exactly at every level; other meshes (a triangle limit, a mesh made
/// elsewhere) may reach past it, and both sides of a shared triangle edge reference the same
/// samples, so the chunks of one mesh meet without cracks either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChunkGrid {
    pub pitch: usize,
    pub width: usize,
    pub height: usize,
    /// Chunks along i (columns) and along j (rows).
    pub nx: usize,
    pub ny: usize,
}

impl ChunkGrid {
    /// `pitch` ≥ 1 cells; `width`, `height` ≥ 1 samples (callers validate).
    pub fn new(width: usize, height: usize, pitch: usize) -> ChunkGrid {
        let pitch = pitch.max(1);
        let count = |n: usize| n.saturating_sub(1).div_ceil(pitch).max(1);
        ChunkGrid { pitch, width, height, nx: count(width), ny: count(height) }
    }

    /// Number of chunks; chunk (ci, cj) has index cj·nx + ci (row-major, like the heightmap).
    pub fn len(&self) -> usize {
        self.nx * self.ny
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Inclusive sample rectangle of chunk (ci, cj): (min [i, j], max [i, j]).
    pub fn sample_rect(&self, ci: usize, cj: usize) -> ([usize; 2], [usize; 2]) {
        let lo = [ci * self.pitch, cj * self.pitch];
        let hi = [
            ((ci + 1) * self.pitch).min(self.width.saturating_sub(1)),
            ((cj + 1) * self.pitch).min(self.height.saturating_sub(1)),
        ];
        (lo, hi)
    }

    /// Chunk holding the centroid of a triangle given by its three samples. Integer arithmetic
    /// (sum of coordinates against 3·pitch), so the choice is exact; a centroid on a chunk line goes
    /// to the higher chunk, except on the map's far border, which belongs to the last chunk.
    pub fn chunk_of(&self, corners: [[u32; 2]; 3]) -> (usize, usize) {
        let step = 3 * self.pitch as u64;
        let axis = |k: usize, n: usize| {
            let sum: u64 = corners.iter().map(|c| c[k] as u64).sum();
            ((sum / step) as usize).min(n - 1)
        };
        (axis(0, self.nx), axis(1, self.ny))
    }

    /// Triangle ids of each chunk (index cj·nx + ci), each list in input order.
    pub fn partition(&self, vertices: &[[u32; 2]], triangles: &[[u32; 3]]) -> Vec<Vec<usize>> {
        let mut chunks = vec![Vec::new(); self.len()];
        for (t, tri) in triangles.iter().enumerate() {
            let corners = tri.map(|v| vertices[v as usize]);
            let (ci, cj) = self.chunk_of(corners);
            chunks[cj * self.nx + ci].push(t);
        }
        chunks
    }
}

/// Boundary edges of the triangles `subset` (ids into `triangles`): the edges no other triangle of
/// the subset shares, each directed (a, b) the way it runs in its own triangle, so the triangle's
/// interior lies to its left seen from +Y. Ordered by triangle, then corner: deterministic.
/// Assumes a consistently oriented, edge-manifold triangulation (validated by the caller).
pub fn boundary_edges(triangles: &[[u32; 3]], subset: &[usize]) -> Vec<[u32; 2]> {
    if subset.is_empty() {
        return Vec::new();
    }
    // count each undirected edge (a map used for counting only, never iterated)
    let mut uses: IdMap<(u32, u32), u32> = IdMap::default();
    uses.reserve(subset.len() * 2);
    let key = |a: u32, b: u32| (a.min(b), a.max(b));
    for &t in subset {
        let [a, b, c] = triangles[t];
        for (p, q) in [(a, b), (b, c), (c, a)] {
            *uses.entry(key(p, q)).or_insert(0) += 1;
        }
    }
    let mut edges = Vec::new();
    for &t in subset {
        let [a, b, c] = triangles[t];
        for (p, q) in [(a, b), (b, c), (c, a)] {
            if uses[&key(p, q)] == 1 {
                edges.push([p, q]);
            }
        }
    }
    edges
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_counts_and_rectangles() {
        let g = ChunkGrid::new(301, 17, 64);
        assert_eq!((g.nx, g.ny), (5, 1));
        assert_eq!(g.sample_rect(0, 0), ([0, 0], [64, 16]));
        assert_eq!(g.sample_rect(4, 0), ([256, 0], [300, 16]));
        // an exact fit: 129 samples = 2 chunks of 64 cells
        assert_eq!(ChunkGrid::new(129, 129, 64).len(), 4);
        assert_eq!(ChunkGrid::new(2, 2, 64).len(), 1);
    }

    #[test]
    fn centroid_on_a_chunk_line_goes_up_except_at_the_far_border() {
        let g = ChunkGrid::new(9, 9, 4);
        // centroid (4, 1): on the line between chunk 0 and 1 → chunk 1
        assert_eq!(g.chunk_of([[3, 0], [6, 0], [3, 3]]), (1, 0));
        // centroid just left of the line
        assert_eq!(g.chunk_of([[3, 0], [5, 0], [3, 3]]), (0, 0));
        // centroid (8, 8) would be chunk 2, which does not exist
        assert_eq!(g.chunk_of([[8, 8], [8, 8], [8, 8]]), (1, 1));
    }

    #[test]
    fn boundary_of_two_triangles_is_their_outline() {
        // square (0,0)-(1,1) split along the diagonal, CCW from +Y
        let tris = [[0, 2, 1], [1, 2, 3]];
        let e = boundary_edges(&tris, &[0, 1]);
        assert_eq!(e, vec![[0, 2], [1, 0], [2, 3], [3, 1]]);
        assert_eq!(boundary_edges(&tris, &[1]), vec![[1, 2], [2, 3], [3, 1]]);
        assert!(boundary_edges(&tris, &[]).is_empty());
    }
}
