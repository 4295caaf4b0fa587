//! The chain's analyzer: every level's size, its sampled Hausdorff distance to the reference and
//! its image error, from which the switch distance under the LoD policy's pixel budget follows.

use std::time::Instant;

use super::cards::ModelFrame;
use super::types::{
    AtlasCell, Progress, SpeedErrorRow, TreeLod, TreeLodError, TreeLodFigures, TreeLodOptions, SEARCH_FAR_RADII,
    SEARCH_NEAR_RADII,
};
use crate::bake::views::{switch_search_chain, Candidate, Renderable, SwitchSearch};
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
    let mut lods = Vec::with_capacity(levels.len());
    for lod in levels {
        let mesh = &lod.scene.meshes[0];
        let store = options.compact.write_options();
        let bytes = crate::export::gltf::to_glb_with(&lod.scene, &store).map_err(|e| TreeLodError::Texture(e.0))?.len();
        let quantization_m = crate::export::quantize::position_error(&lod.scene, &store.quantization);
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
        lods.push(f);
    }
    let seconds_hausdorff = started.elapsed().as_secs_f64();
    if options.analyze {
        image_errors(&mut lods, levels, reference, frame, impostor_cells, options, progress);
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
    Ok(Measured { lods, table, seconds, seconds_hausdorff, seconds_image: seconds - seconds_hausdorff })
}

/// The image figures of every level after LoD0: the error at each measured distance and the
/// switch distance from which it stays within the policy's pixel budget. All levels are searched
/// together ([`switch_search_chain`]): a distance several levels test renders LoD0 once.
fn image_errors(
    figures: &mut [TreeLodFigures],
    levels: &[TreeLod],
    reference: &Renderable,
    frame: &ModelFrame,
    impostor_cells: &[AtlasCell],
    options: &TreeLodOptions,
    progress: Progress,
) {
    let measured: Vec<usize> = (0..levels.len()).filter(|&n| levels[n].level > 0).collect();
    if measured.is_empty() {
        return;
    }
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
    let results = switch_search_chain(reference, &candidates, &view, &options.image, &range);
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
}
