//! The plain data between the meshers, the analyzer and mesh building.

/// A triangulation whose vertices are heightmap samples: the plain data between the meshers
/// (`grid`, `tin`), the error analyzer (`error`) and mesh building.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SampleMesh {
    /// Sample coordinates (column i, row j) of each vertex.
    pub vertices: Vec<[u32; 2]>,
    /// Vertex indices; each triangle is counter-clockwise seen from +Y, i.e. with x = i and z = j the
    /// cross product (b − a) × (c − a) has a positive y component.
    pub triangles: Vec<[u32; 3]>,
}
