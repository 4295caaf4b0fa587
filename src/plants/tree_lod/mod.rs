//! Level-of-detail chain of an L-system tree with baked atlases, after the point-sprite thesis'
//! BranchTree (finest branches become sprites first) and Maciel & Shirley's textured-cluster
//! impostors ("Visual navigation of large environments using textured clusters", I3D 1995).
//! LoD0 full; LoD1 half the radial segments + meshoptimizer simplification (Garland & Heckbert
//! quadrics); LoD2 the finest branch level replaced by leaf-cluster cards baked from it; LoD3 four
//! crossed billboards; LoD4 one impostor quad with 8 baked views. Each level is measured: triangles,
//! bytes, sampled one-sided Hausdorff distance to LoD0 ([`crate::plants::hausdorff`]) and image error
//! with the switch distance under the pixel budget ([`crate::bake::views::switch_search_chain`]).
//!
//! Impostor view selection (LoD4): the quad in the file faces +Z; an engine turns it to face the
//! camera about the vertical axis through `centre` and picks the atlas cell from the direction
//! (dx, dz) from the tree to the eye: `k = round(atan2(dx, dz) / 45°) mod 8`, cell k having been
//! baked looking from azimuth k · 45° (0° = from +Z, 90° = from +X). The mesh extras
//! (`verdant_impostor`) carry the cells' uv rectangles, the centre and the quad size.

mod analyze;
mod cards;
mod chain;
mod job;
mod simplify;
mod types;

pub use self::chain::{build_mesh_lods, build_mesh_lods_with, build_tree_lods, build_tree_lods_with};
pub use self::job::{
    run_lods, run_lods_reporting, run_lods_with, run_mesh_lods, run_mesh_lods_reporting, run_mesh_lods_with,
    variant_seed, MeshLodJob, MeshLodRunReport, TreeLodJob, TreeLodRunReport,
};
pub use self::simplify::SLOPPY_RATIO;
pub use self::types::{
    atlas_cell_rects, AnalysisDetail, AtlasCell, LeftOutLevel, Progress, SpeedErrorRow, TreeLod, TreeLodError,
    TreeLodFigures, TreeLodOptions, TreeLodReport, TreeLods, ATLAS_ALPHA_CUTOFF, ATLAS_GUTTER_PX, BAKE_SUPERSAMPLE,
    BILLBOARD_PLANES, DEFAULT_ATLAS_PX, DEFAULT_HAUSDORFF_SAMPLES, FAST_IMAGE_BUDGET_TRIANGLES, IMPOSTOR_EXTRAS_KEY,
    IMPOSTOR_VIEWS, MAX_ATLAS_PX, MAX_CLUSTERS, MIN_ATLAS_PX, TREE_LODS,
};
