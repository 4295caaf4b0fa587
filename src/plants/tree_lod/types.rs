//! The chain's vocabulary: limits and defaults, options, errors, the atlas' cell layout, the levels
//! and the figures the analyzer reports.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::bake::atlas::{MipFigures, MipLevel};
use crate::bake::image::Image;
use crate::bake::raster::RasterError;
use crate::bake::views::{DistanceError, LodImageOptions};
use crate::export::ExportError;
use crate::failure::{Blame, Failure};
use crate::lod::LodView;
use crate::mesh::{Mesh, Scene};
use crate::plants::hausdorff::HausdorffError;
use crate::plants::mesh_asset::MeshAssetError;
use crate::plants::tree::{TreeError, TreeMesh};

/// LoD0 full … LoD4 impostor.
pub const TREE_LODS: usize = 5;
pub const IMPOSTOR_VIEWS: usize = 8;
/// LoD3's vertical planes (azimuths 0°, 45°, 90°, 135°: the first four impostor views).
pub const BILLBOARD_PLANES: usize = 4;
/// LoD2's leaf-cluster cards at most (two crossed quads each).
pub const MAX_CLUSTERS: usize = 64;
pub const DEFAULT_ATLAS_PX: u32 = 1024;
pub const MIN_ATLAS_PX: u32 = 256;
/// A 4096² atlas is 256 MiB as floats while baking.
pub const MAX_ATLAS_PX: u32 = 4096;
pub const ATLAS_ALPHA_CUTOFF: f32 = 0.5;
/// Transparent (then dilated) texels around every atlas cell, so filtering and mips do not bleed.
pub const ATLAS_GUTTER_PX: u32 = 4;
/// Samples per texel along each axis when baking (the resolved alpha is fractional at edges, which
/// lets the coverage-preserving mips keep level 0's coverage).
pub const BAKE_SUPERSAMPLE: u32 = 2;
pub const DEFAULT_HAUSDORFF_SAMPLES: usize = 20_000;

/// Extras key of the impostor's mesh.
pub const IMPOSTOR_EXTRAS_KEY: &str = "verdant_impostor";

/// Told each step of a chain as it starts (a progress display; `&|_| {}` for none).
pub type Progress<'a> = &'a dyn Fn(&str);

#[derive(Debug, thiserror::Error)]
pub enum TreeLodError {
    #[error(transparent)]
    Tree(#[from] TreeError),
    #[error("invalid LoD options: {0}")]
    Options(String),
    #[error("baking the tree atlas: {0}")]
    Raster(#[from] RasterError),
    #[error("tree texture: {0}")]
    Texture(String),
    #[error(transparent)]
    Export(#[from] ExportError),
    #[error(transparent)]
    MeshAsset(#[from] MeshAssetError),
    #[error(transparent)]
    Meshopt(#[from] crate::meshopt_guard::FfiError),
    #[error("{path} does not pass validation (this is a bug, please report it with the input file):\n{report}")]
    Invalid { path: PathBuf, report: String },
}

/// The input's for bad input, options or exceeded limits; the build's otherwise.
impl Failure for TreeLodError {
    fn blame(&self) -> Blame {
        match self {
            TreeLodError::Tree(e) => e.blame(),
            TreeLodError::Options(_) => Blame::Input,
            TreeLodError::MeshAsset(e) => e.blame(),
            _ => Blame::Build,
        }
    }
}

/// How the chain is built and measured.
#[derive(Debug, Clone, PartialEq)]
pub struct TreeLodOptions {
    /// Levels written (1..=5, finest first).
    pub lods: usize,
    /// Side of the square atlas (a multiple of 16 in MIN_ATLAS_PX..=MAX_ATLAS_PX).
    pub atlas_px: u32,
    /// Measure image errors and switch distances (off: coverages are 0, for timing the build).
    pub analyze: bool,
    pub hausdorff_samples: usize,
    /// How the image analyzer renders and how finely it searches ([`AnalysisDetail`]).
    pub image: LodImageOptions,
    /// How finely each switch is found: within one step of a lattice with 2^bisections points per
    /// octave (3 → 2^(1/8), 9 %); when not guided, by that many log-space bisections.
    pub bisections: usize,
    /// Where each switch search starts, in bounding radii (it halves from there to 2 radii while
    /// a level passes and doubles up to 1024 radii while one fails; 1024: every halving from the
    /// far end is measured).
    pub search_start_radii: f64,
    /// Narrow each switch's bracket by interpolation rather than bisection
    /// ([`crate::bake::views::SwitchSearch::guided`]).
    pub guided_search: bool,
    /// The most triangles the image analyzer draws at one measured distance (LoD0 and every
    /// level measured there, over all views): above it the azimuths are halved until it fits,
    /// never below 4 (8 × 3 views → 4 × 3), so the analyzer's time at the triangle cap stays a
    /// few seconds. None: every view whatever the size. See
    /// [`AnalysisDetail::image_budget_triangles`].
    pub image_budget_triangles: Option<u64>,
    /// The LoD policy switch distances are found for (`[lod]`: pixel budget and screen).
    pub policy: LodView,
    /// How the chain's glb files store vertex data; the quantization is folded into each level's
    /// reported geometric error.
    pub compact: crate::export::quantize::Compact,
}

/// How thoroughly the chain's image analyzer measures (`verdant tree|mesh --analysis`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AnalysisDetail {
    /// The default: 8 azimuths (every 45°, the impostor's views) × 3 elevations (10°, 40°, 75°),
    /// views at most 96 px across with 2×2 samples per pixel (small views up to 4×4); the search
    /// starts at 128 radii and narrows each bracket by interpolation to 2^(1/8) (switches within
    /// 9 %).
    #[default]
    Fast,
    /// What the fast measure is checked against (`scripts/bench_trees.sh`): 16 azimuths × 5
    /// elevations (10° to 80°), views up to 256 px with 4×4 samples; the search halves from 1024
    /// radii (every halving measured) and bisects each bracket 5 times (2 %). Tens of times the
    /// work.
    Exhaustive,
}

impl AnalysisDetail {
    pub fn image(self) -> LodImageOptions {
        match self {
            AnalysisDetail::Fast => LodImageOptions {
                max_side_px: 96,
                supersample: 2,
                azimuths: 8,
                elevations_deg: vec![10.0, 40.0, 75.0],
                ..LodImageOptions::default()
            },
            AnalysisDetail::Exhaustive => LodImageOptions {
                max_side_px: 256,
                supersample: 4,
                azimuths: 16,
                elevations_deg: vec![10.0, 27.5, 45.0, 62.5, 80.0],
                ..LodImageOptions::default()
            },
        }
    }

    pub fn bisections(self) -> usize {
        match self {
            AnalysisDetail::Fast => 3,
            AnalysisDetail::Exhaustive => 5,
        }
    }

    /// Fast: 128 radii, where a tree is 26 px tall on the default screen (every level of the
    /// files in ../shared/data switches nearer, at 2-76 radii; one that fails there is followed
    /// outwards). Exhaustive: from the far end, every halving measured.
    pub fn search_start_radii(self) -> f64 {
        match self {
            AnalysisDetail::Fast => 128.0,
            AnalysisDetail::Exhaustive => SEARCH_FAR_RADII,
        }
    }

    /// Fast: brackets narrowed by interpolation; exhaustive: bisected.
    pub fn guided_search(self) -> bool {
        self == AnalysisDetail::Fast
    }

    /// Fast: [`FAST_IMAGE_BUDGET_TRIANGLES`]; exhaustive: no budget (every view).
    pub fn image_budget_triangles(self) -> Option<u64> {
        match self {
            AnalysisDetail::Fast => Some(FAST_IMAGE_BUDGET_TRIANGLES),
            AnalysisDetail::Exhaustive => None,
        }
    }
}

/// The fast analyzer's triangles per measured distance: 6 M keeps all 24 views for every tree of
/// ../shared/data (the largest, abop-bush, draws 4.7 M: 120k + 62k + 12k over 24 views); a chain
/// drawing more than 250k triangles a view (LoD0 and its levels: from about 120k–150k LoD0
/// triangles, by how much LoD1 and the cards keep) is measured from 4 azimuths × 3 elevations. The
/// 262k-triangle bush at the 300k default cap (452k a view): image analysis 4.5 → 2.0 s
/// (scripts/bench_trees.sh compares it with the exhaustive measure).
pub const FAST_IMAGE_BUDGET_TRIANGLES: u64 = 6_000_000;

/// The farthest distance a switch search measures, in bounding radii (a tree ~3 px tall).
pub const SEARCH_FAR_RADII: f64 = 1024.0;
/// The nearest distance a switch search measures, in bounding radii.
pub const SEARCH_NEAR_RADII: f64 = 2.0;

impl Default for TreeLodOptions {
    fn default() -> Self {
        TreeLodOptions {
            lods: TREE_LODS,
            atlas_px: DEFAULT_ATLAS_PX,
            analyze: true,
            hausdorff_samples: DEFAULT_HAUSDORFF_SAMPLES,
            image: AnalysisDetail::Fast.image(),
            bisections: AnalysisDetail::Fast.bisections(),
            search_start_radii: AnalysisDetail::Fast.search_start_radii(),
            guided_search: AnalysisDetail::Fast.guided_search(),
            image_budget_triangles: AnalysisDetail::Fast.image_budget_triangles(),
            policy: LodView::default(),
            compact: crate::export::quantize::Compact::None,
        }
    }
}

impl TreeLodOptions {
    /// These options measured as `detail` says (views, samples and the switch search).
    pub fn with_analysis(self, detail: AnalysisDetail) -> TreeLodOptions {
        TreeLodOptions {
            image: detail.image(),
            bisections: detail.bisections(),
            search_start_radii: detail.search_start_radii(),
            guided_search: detail.guided_search(),
            image_budget_triangles: detail.image_budget_triangles(),
            ..self
        }
    }

    pub fn check(&self) -> Result<(), TreeLodError> {
        if !(1..=TREE_LODS).contains(&self.lods) {
            return Err(TreeLodError::Options(format!("--lods {} is out of range; use 1 to {TREE_LODS}", self.lods)));
        }
        if !(MIN_ATLAS_PX..=MAX_ATLAS_PX).contains(&self.atlas_px) || !self.atlas_px.is_multiple_of(16) {
            return Err(TreeLodError::Options(format!(
                "--atlas-size {} must be a multiple of 16 from {MIN_ATLAS_PX} to {MAX_ATLAS_PX} (e.g. 1024 or 2048)",
                self.atlas_px
            )));
        }
        Ok(())
    }
}

/// Every cell of an `atlas_px` tree atlas as its inside's (u0, v0, u1, v1): the impostor views
/// (large cells 0..8), then the small cells cards and billboards use.
pub fn atlas_cell_rects(atlas_px: u32) -> Vec<[f32; 4]> {
    let large = (0..IMPOSTOR_VIEWS).map(|k| AtlasCell::large(atlas_px, k).uv);
    large.chain((0..128).map(|j| AtlasCell::small(atlas_px, j).uv)).collect()
}

/// A square atlas cell; `uv` is its inside (within the gutter) as (u0, v0, u1, v1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AtlasCell {
    pub x: u32,
    pub y: u32,
    pub size: u32,
    pub uv: [f32; 4],
}

impl AtlasCell {
    fn new(atlas_px: u32, x: u32, y: u32, size: u32) -> AtlasCell {
        let (a, g) = (atlas_px as f32, ATLAS_GUTTER_PX);
        AtlasCell {
            x,
            y,
            size,
            uv: [(x + g) as f32 / a, (y + g) as f32 / a, (x + size - g) as f32 / a, (y + size - g) as f32 / a],
        }
    }

    /// Pixels inside the gutter.
    pub(super) fn inner_px(&self) -> u32 {
        self.size - 2 * ATLAS_GUTTER_PX
    }

    /// Large cell `i` of the 4 × 4 grid: 0..8 are the impostor views, 8..16 hold the small cells.
    pub(super) fn large(atlas_px: u32, i: usize) -> AtlasCell {
        let s = atlas_px / 4;
        AtlasCell::new(atlas_px, (i as u32 % 4) * s, (i as u32 / 4) * s, s)
    }

    /// Small cell `j` (0..128): large cells 8..16, each split 4 × 4; a card uses two.
    pub(super) fn small(atlas_px: u32, j: usize) -> AtlasCell {
        let big = AtlasCell::large(atlas_px, 8 + j / 16);
        let s = atlas_px / 16;
        let k = j as u32 % 16;
        AtlasCell::new(atlas_px, big.x + (k % 4) * s, big.y + (k / 4) * s, s)
    }
}

/// One level of the chain as its own file holds it.
#[derive(Debug, Clone)]
pub struct TreeLod {
    pub level: usize,
    /// What it is: "full", "simplified", "cards", "billboards", "impostor".
    pub kind: &'static str,
    pub scene: Scene,
    /// `scene.textures` decoded, same order (what the analyzer draws with).
    pub images: Vec<Image>,
}

impl TreeLod {
    pub fn triangles(&self) -> usize {
        self.scene.meshes.iter().map(Mesh::triangle_count).sum()
    }
}

/// Figures of one level.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TreeLodFigures {
    pub level: usize,
    /// The level's [`TreeLod::kind`].
    pub kind: String,
    pub triangles: usize,
    pub vertices: usize,
    /// Size of `<name>_LOD<n>.glb`.
    pub bytes: usize,
    /// One-sided Hausdorff distance LoD_k → LoD0 (sampled; masked texels excluded), of the
    /// meshes as built.
    pub geometric_error: HausdorffError,
    /// The farthest any vertex of this level moves in its files (16-bit positions: `--quantize`,
    /// `--compress`; 0 for f32), in the level's file and in the chain's, whichever is more.
    #[serde(default)]
    pub quantization_m: f64,
    /// Per attribute stored as bytes of its range (the wind in `--quantize`/`--compress` files,
    /// docs/wind.md): the largest difference per component between the values built and those a
    /// reader gets from the level's file (at most half a step). Empty for f32 files.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub attribute_error: std::collections::BTreeMap<String, [f32; 4]>,
    /// The geometric error of the level as stored: `geometric_error.max_m` plus this level's and
    /// LoD0's quantization (a surface point moves at most as far as its triangle's corners).
    #[serde(default)]
    pub stored_error_m: f64,
    /// Worst over the analyzer's views ([`TreeLodReport::analysis_views`]) at the nearest measured
    /// distance and at the switch.
    pub near_distance_m: f64,
    pub near_iou: f64,
    pub near_color_rmse: f64,
    pub switch_iou: f64,
    pub switch_color_rmse: f64,
    /// Distance (eye to the bounding-sphere centre) from which the silhouette error stays ≤ 1 px
    /// (1920 px wide, 60°); raised to the previous level's where it was nearer.
    pub switch_distance_m: f64,
    pub never_passes: bool,
    /// MSFT_lod screen coverage at the switch distance.
    pub screen_coverage: f64,
    pub measured: Vec<DistanceError>,
}

/// One row of the speed/error table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpeedErrorRow {
    pub level: usize,
    pub triangles: usize,
    pub bytes: usize,
    pub hausdorff_max_m: f64,
    /// `hausdorff_max_m` with the quantization of the files folded in ([`TreeLodFigures::stored_error_m`]).
    #[serde(default)]
    pub stored_error_m: f64,
    pub worst_iou_at_switch: f64,
    pub switch_distance_m: f64,
    /// Triangles relative to LoD0 (what the level saves the GPU).
    pub triangle_ratio: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TreeLodReport {
    pub name: String,
    pub seed: u64,
    pub atlas_px: u32,
    pub bounding_radius_m: f64,
    pub clusters: usize,
    /// Branch levels LoD2 drops (finest first); empty when the tree has one level.
    pub dropped_levels: Vec<u32>,
    /// Levels built but left out because they saved nothing over the level before (the written
    /// chain is renumbered, so `lods` and the files stay contiguous).
    pub left_out: Vec<LeftOutLevel>,
    pub lods: Vec<TreeLodFigures>,
    pub table: Vec<SpeedErrorRow>,
    pub atlas_mips: Vec<MipFigures>,
    /// LoD0 and LoD1 (`seconds_lod0` + `seconds_lod1`).
    pub seconds_meshes: f64,
    /// Growing the tree (0 for a loaded model).
    #[serde(default)]
    pub seconds_lod0: f64,
    /// LoD1: the thinner tree simplified, or the model simplified.
    #[serde(default)]
    pub seconds_lod1: f64,
    /// The atlas (impostor views, leaf-cluster cards, normals).
    pub seconds_bake: f64,
    /// The cards, billboard and impostor levels from the atlas.
    #[serde(default)]
    pub seconds_cards: f64,
    /// The analyzer (`seconds_hausdorff` + `seconds_image`).
    pub seconds_analyze: f64,
    /// Sizes and sampled Hausdorff distances of every level.
    #[serde(default)]
    pub seconds_hausdorff: f64,
    /// The image errors and switch distances of every level.
    #[serde(default)]
    pub seconds_image: f64,
    pub raster_fragments: u64,
    /// Views the image analyzer measured each distance from: azimuths × elevations, fewer than
    /// its options ask when the chain is over [`TreeLodOptions::image_budget_triangles`] (0
    /// without analysis, and in reports from before this field).
    #[serde(default)]
    pub analysis_views: usize,
    /// Why fewer views were measured than the options ask, when they were.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub analysis_reduced: Option<String>,
}

/// Everything one tree's chain writes.
#[derive(Debug, Clone)]
pub struct TreeLods {
    pub name: String,
    pub levels: Vec<TreeLod>,
    /// `<name>.glb`: LoD0 with MSFT_lod to the coarser levels.
    pub chain: Scene,
    pub atlas: Vec<MipLevel>,
    /// The atlas' normals (glTF tangent-space normal map, level 0: engines make its mips), which
    /// the card levels' material samples as normalTexture.
    pub normal_atlas: Option<Image>,
    pub impostor_cells: Vec<AtlasCell>,
    pub report: TreeLodReport,
    /// The L-system tree LoD0 shows (None for a mesh asset).
    pub lod0: Option<TreeMesh>,
}

/// A level built but not written: it would have drawn no fewer triangles than the level before it
/// (a small tree's cards can outnumber its simplified branches), so an engine would gain nothing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LeftOutLevel {
    /// What it would have been ("cards", "billboards", …) and its number in the full chain.
    pub kind: String,
    pub planned_level: usize,
    pub triangles: usize,
    /// The triangles of the level before it in the written chain.
    pub previous_triangles: usize,
}
