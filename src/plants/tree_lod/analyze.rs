//! The chain's analyzer: every level's size, its sampled Hausdorff distance to the reference and
//! its image error, from which the switch distance under the LoD policy's pixel budget follows.

use std::time::Instant;

use rayon::prelude::*;

use super::cards::ModelFrame;
use super::types::{
    AtlasCell, Progress, SpeedErrorRow, TreeLod, TreeLodError, TreeLodFigures, TreeLodOptions, SEARCH_FAR_RADII,
    SEARCH_NEAR_RADII,
};
use crate::bake::views::{switch_search_chain, Candidate, LodImageOptions, Renderable, SwitchSearch};
use crate::mesh::{Mesh, Primitive};
use crate::plants::hausdorff::{hausdorff, HausdorffError, TriangleBvh};
use crate::random::mix64;

/// What the analyzer found.
pub(super) struct Measured {
    pub lods: Vec<TreeLodFigures>,
    pub table: Vec<SpeedErrorRow>,
    pub seconds: f64,
    pub seconds_hausdorff: f64,
    pub seconds_image: f64,
    /// Views per measured distance, and why fewer than the options ask ([`views_within_budget`]).
    pub views: usize,
    pub reduced: Option<String>,
}

/// Measures every level of `levels` against `reference`; switch distances never decrease along
/// the chain (a coarser level never switches in before a finer one).
pub(super) fn measure_levels(
    levels: &[TreeLod],
    reference: &Renderable,
    frame: &ModelFrame,
    impostor_cells: &[AtlasCell],
    seed: u64,
    options: &TreeLodOptions,
    progress: Progress,
) -> Result<Measured, TreeLodError> {
    let started = Instant::now();
    let grid = TriangleBvh::new(reference.mesh);
    // every level at once (each measure is its own; nested parallelism inside the Hausdorff
    // batches): the levels' figures do not depend on the order
    let lods = levels.par_iter().map(|lod| {
        let mesh = &lod.scene.meshes[0];
        let store = options.compact.write_options();
        let bytes = crate::export::gltf::to_glb_with(&lod.scene, &store).map_err(|e| TreeLodError::Texture(e.0))?.len();
        let quantization_m = crate::export::quantize::position_error(&lod.scene, &store.quantization);
        let attribute_error = crate::export::quantize::attribute_error(&lod.scene, &store.quantization);
        let geometric_error = match (&grid, lod.level) {
            (Some(grid), n) if n > 0 => hausdorff(
                mesh,
                &lod.scene.materials,
                &lod.images,
                grid,
                options.hausdorff_samples,
                mix64(seed ^ n as u64),
            ),
            _ => HausdorffError::default(),
        };
        let f = TreeLodFigures {
            level: lod.level,
            kind: lod.kind.to_string(),
            triangles: lod.triangles(),
            vertices: mesh.vertex_count(),
            bytes,
            stored_error_m: geometric_error.max_m,
            geometric_error,
            quantization_m,
            attribute_error,
            near_distance_m: 0.0,
            near_iou: 1.0,
            near_color_rmse: 0.0,
            switch_iou: 1.0,
            switch_color_rmse: 0.0,
            switch_distance_m: 0.0,
            never_passes: false,
            screen_coverage: 1.0,
            measured: Vec::new(),
        };
        Ok(f)
    });
    let mut lods = lods.collect::<Result<Vec<TreeLodFigures>, TreeLodError>>()?;
    let seconds_hausdorff = started.elapsed().as_secs_f64();
    let (mut views, mut reduced) = (0, None);
    if options.analyze {
        (views, reduced) = image_errors(&mut lods, levels, reference, frame, impostor_cells, options, progress);
    }
    for n in 1..lods.len() {
        if lods[n].switch_distance_m < lods[n - 1].switch_distance_m {
            lods[n].switch_distance_m = lods[n - 1].switch_distance_m;
            lods[n].screen_coverage =
                options.policy.coverage_at_centre_distance(frame.radius, lods[n].switch_distance_m);
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    let lod0_triangles = lods[0].triangles.max(1) as f64;
    let table = lods
        .iter()
        .map(|l| SpeedErrorRow {
            level: l.level,
            triangles: l.triangles,
            bytes: l.bytes,
            hausdorff_max_m: l.geometric_error.max_m,
            stored_error_m: l.stored_error_m,
            worst_iou_at_switch: l.switch_iou,
            switch_distance_m: l.switch_distance_m,
            triangle_ratio: l.triangles as f64 / lod0_triangles,
        })
        .collect();
    Ok(Measured { lods, table, seconds, seconds_hausdorff, seconds_image: seconds - seconds_hausdorff, views, reduced })
}

/// The fewest azimuths a budget leaves: 4 × 3 views is the coarsest measure compared with the
/// exhaustive one (docs/lsystems.md); below it the budget no longer bounds the time, the triangle
/// cap does (a chain at the cap draws at most ~2.1 × 300k triangles a view: 7.6 M a distance).
pub(super) const MIN_BUDGET_AZIMUTHS: u32 = 4;

/// The azimuths of `image` halved (while even, never below [`MIN_BUDGET_AZIMUTHS`]) until a
/// measured distance draws at most `budget` triangles, `per_view` being what one view draws (LoD0
/// and every level); with why, when they were. The elevations stay: they see what azimuths cannot
/// (from above, the crown).
pub(super) fn views_within_budget(
    image: &LodImageOptions,
    per_view: u64,
    budget: Option<u64>,
) -> (LodImageOptions, Option<String>) {
    let elevations = image.elevations_deg.len().max(1) as u64;
    let Some(budget) = budget else {
        return (image.clone(), None);
    };
    let drawn = |azimuths: u32| per_view.saturating_mul(azimuths.max(1) as u64 * elevations);
    let mut azimuths = image.azimuths;
    while azimuths / 2 >= MIN_BUDGET_AZIMUTHS && azimuths % 2 == 0 && drawn(azimuths) > budget {
        azimuths /= 2;
    }
    if azimuths == image.azimuths {
        return (image.clone(), None);
    }
    let why = format!(
        "{} azimuths × {elevations} elevations instead of {} × {elevations}: LoD0 and the levels draw {per_view} \
         triangles a view, over the fast analyzer's budget of {budget} a distance (`--analysis exhaustive` \
         measures every view)",
        azimuths, image.azimuths
    );
    (LodImageOptions { azimuths, ..image.clone() }, Some(why))
}

/// The image figures of every level after LoD0: the error at each measured distance and the
/// switch distance from which it stays within the policy's pixel budget. All levels are searched
/// together ([`switch_search_chain`]): a distance several levels test renders LoD0 once. Returns
/// the views per distance and why fewer than the options ask, when they were.
fn image_errors(
    figures: &mut [TreeLodFigures],
    levels: &[TreeLod],
    reference: &Renderable,
    frame: &ModelFrame,
    impostor_cells: &[AtlasCell],
    options: &TreeLodOptions,
    progress: Progress,
) -> (usize, Option<String>) {
    let measured: Vec<usize> = (0..levels.len()).filter(|&n| levels[n].level > 0).collect();
    if measured.is_empty() {
        return (0, None);
    }
    let per_view =
        reference.mesh.triangle_count() as u64 + measured.iter().map(|&n| levels[n].triangles() as u64).sum::<u64>();
    let (image, reduced) = views_within_budget(&options.image, per_view, options.image_budget_triangles);
    if let Some(why) = &reduced {
        progress(&format!("image analysis from {why}"));
    }
    let views = image.views();
    let names: Vec<String> = measured.iter().map(|&n| format!("LoD{} ({})", levels[n].level, levels[n].kind)).collect();
    progress(&format!("measuring {} against LoD0", names.join(", ")));
    // the impostor's cards, each facing the azimuth it is baked from (engines show view k around
    // azimuth k · 360°/views)
    let cards: Vec<Mesh> = impostor_cells
        .iter()
        .enumerate()
        .map(|(k, cell)| {
            let quad = Primitive { material: Some(0), ..frame.view(k).quad(cell.uv) };
            Mesh { name: String::new(), primitives: vec![quad], extras: None }
        })
        .collect();
    let candidates: Vec<Candidate> = measured
        .iter()
        .map(|&n| {
            let lod = &levels[n];
            let r = |mesh| Renderable { mesh, materials: &lod.scene.materials, textures: &lod.images };
            if lod.kind == "impostor" {
                Candidate::PerAzimuth(cards.iter().map(r).collect())
            } else if lod.kind == "billboards" || lod.kind == "cards" {
                Candidate::Card(r(&lod.scene.meshes[0]))
            } else {
                Candidate::Mesh(r(&lod.scene.meshes[0]))
            }
        })
        .collect();
    let view = options.policy.screen_view();
    let range = SwitchSearch {
        start_m: frame.radius * options.search_start_radii,
        far_m: frame.radius * SEARCH_FAR_RADII,
        near_m: frame.radius * SEARCH_NEAR_RADII,
        bisections: options.bisections,
        guided: options.guided_search,
    };
    let results = switch_search_chain(reference, &candidates, &view, &image, &range);
    for (&n, (rows, switch_m, never)) in measured.iter().zip(results) {
        let f = &mut figures[n];
        if let Some(near) = rows.first() {
            f.near_distance_m = near.distance_m;
            f.near_iou = near.worst_iou;
            f.near_color_rmse = near.worst_color_rmse;
        }
        if let Some(at) = rows.iter().find(|d| d.distance_m >= switch_m) {
            f.switch_iou = at.worst_iou;
            f.switch_color_rmse = at.worst_color_rmse;
        }
        f.measured = rows;
        f.switch_distance_m = switch_m;
        f.never_passes = never;
        f.screen_coverage = options.policy.coverage_at_centre_distance(frame.radius, switch_m);
    }
    (views, reduced)
}

#[cfg(test)]
mod tests {
    use super::views_within_budget;
    use crate::bake::views::LodImageOptions;

    fn fast() -> LodImageOptions {
        crate::plants::tree_lod::AnalysisDetail::Fast.image()
    }

    #[test]
    fn azimuths_halve_until_a_distance_fits_the_budget_never_below_two() {
        // 24 views of 100 triangles: 2,400 a distance; never fewer than 4 azimuths
        for (budget, azimuths) in [(2_400, 8), (2_399, 4), (1_200, 4), (1_199, 4), (1, 4)] {
            let (image, why) = views_within_budget(&fast(), 100, Some(budget));
            assert_eq!(image.azimuths, azimuths, "budget {budget}");
            assert_eq!(image.elevations_deg, fast().elevations_deg);
            assert_eq!(why.is_some(), azimuths != 8, "budget {budget}");
        }
        let (image, why) = views_within_budget(&fast(), u64::MAX, None);
        assert_eq!((image, why), (fast(), None));
        // an odd count is not halved (views stay evenly spaced from 0°); 16 halves twice
        let odd = LodImageOptions { azimuths: 5, ..fast() };
        assert_eq!(views_within_budget(&odd, 100, Some(1)).0.azimuths, 5);
        let sixteen = LodImageOptions { azimuths: 16, ..fast() };
        assert_eq!(views_within_budget(&sixteen, 100, Some(1)).0.azimuths, 4);
        // no overflow at absurd sizes
        assert_eq!(views_within_budget(&fast(), u64::MAX, Some(1)).0.azimuths, 4);
        // the exhaustive measure has no budget; fast has it back
        let exhaustive = crate::plants::tree_lod::TreeLodOptions::default()
            .with_analysis(crate::plants::tree_lod::AnalysisDetail::Exhaustive);
        assert_eq!(exhaustive.image_budget_triangles, None);
        let fast_again = exhaustive.with_analysis(crate::plants::tree_lod::AnalysisDetail::Fast);
        assert_eq!(fast_again.image_budget_triangles, Some(super::super::FAST_IMAGE_BUDGET_TRIANGLES));
    }
}
