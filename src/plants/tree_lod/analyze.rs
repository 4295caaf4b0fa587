//! The chain's analyzer: every level's size, its sampled Hausdorff distance to the reference and
//! its image error, from which the switch distance under the LoD policy's pixel budget follows.

use std::time::Instant;

use glam::DVec3;

use super::cards::ModelFrame;
use super::types::{
    AtlasCell, Progress, SpeedErrorRow, TreeLod, TreeLodError, TreeLodFigures, TreeLodOptions, IMPOSTOR_VIEWS,
};
use crate::bake::views::{
    lod_image_error_with, switch_search, switch_search_by, DistanceError, LodImageOptions, Renderable, SwitchSearch,
};
use crate::mesh::{Mesh, Primitive};
use crate::plants::hausdorff::{hausdorff, HausdorffError, TriangleBvh};
use crate::random::mix64;

/// What the analyzer found.
pub(super) struct Measured {
    pub lods: Vec<TreeLodFigures>,
    pub table: Vec<SpeedErrorRow>,
    pub seconds: f64,
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
        let bytes = crate::export::gltf::to_glb(&lod.scene).map_err(|e| TreeLodError::Texture(e.0))?.len();
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
        let mut f = TreeLodFigures {
            level: lod.level,
            kind: lod.kind.to_string(),
            triangles: lod.triangles(),
            vertices: mesh.vertex_count(),
            bytes,
            geometric_error,
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
        if lod.level > 0 && options.analyze {
            progress(&format!("measuring LoD{} ({}) against LoD0", lod.level, lod.kind));
            image_error(&mut f, lod, reference, frame, impostor_cells, options);
        }
        lods.push(f);
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
            worst_iou_at_switch: l.switch_iou,
            switch_distance_m: l.switch_distance_m,
            triangle_ratio: l.triangles as f64 / lod0_triangles,
        })
        .collect();
    Ok(Measured { lods, table, seconds })
}

/// `f`'s image figures: the error at each measured distance and the switch distance from which
/// it stays within the policy's pixel budget.
fn image_error(
    f: &mut TreeLodFigures,
    lod: &TreeLod,
    reference: &Renderable,
    frame: &ModelFrame,
    impostor_cells: &[AtlasCell],
    options: &TreeLodOptions,
) {
    let view = options.policy.screen_view();
    let range = SwitchSearch { far_m: frame.radius * 1024.0, near_m: frame.radius * 2.0, bisections: 3 };
    let mesh = &lod.scene.meshes[0];
    let candidate = Renderable { mesh, materials: &lod.scene.materials, textures: &lod.images };
    let (rows, switch_m, never) = if lod.kind == "impostor" {
        // the engine shows view k from azimuth k·45°: turn the reference instead, and look from
        // azimuth 0 at each view's quad
        let turned: Vec<(Mesh, Mesh)> = impostor_cells
            .iter()
            .enumerate()
            .map(|(k, cell)| {
                let azimuth = k as f64 * 360.0 / IMPOSTOR_VIEWS as f64;
                let quad = Primitive { material: Some(0), ..frame.view(0).quad(cell.uv) };
                (
                    rotated(reference.mesh, frame.centre, -azimuth),
                    Mesh { name: String::new(), primitives: vec![quad], extras: None },
                )
            })
            .collect();
        let one_azimuth = LodImageOptions { azimuths: 1, ..options.image.clone() };
        switch_search_by(&range, |d| {
            let rows = turned
                .iter()
                .filter_map(|(r, c)| {
                    let r = Renderable { mesh: r, ..*reference };
                    let c = Renderable { mesh: c, ..candidate };
                    lod_image_error_with(&r, &c, &view, &[d], &one_azimuth).distances.into_iter().next()
                })
                .collect();
            merged(rows)
        })
    } else {
        switch_search(reference, &candidate, &view, &options.image, &range)
    };
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

/// `mesh` turned by `angle_deg` about the vertical axis through `axis` (positions and normals).
fn rotated(mesh: &Mesh, axis: DVec3, angle_deg: f64) -> Mesh {
    let q = glam::DQuat::from_rotation_y(angle_deg.to_radians());
    let mut out = mesh.clone();
    for p in &mut out.primitives {
        for v in &mut p.positions {
            *v = (axis + q * (DVec3::from(v.map(f64::from)) - axis)).as_vec3().to_array();
        }
        for n in &mut p.normals {
            *n = (q * DVec3::from(n.map(f64::from))).as_vec3().to_array();
        }
    }
    out
}

/// Worst (and mean) over several measurements at one distance.
fn merged(rows: Vec<DistanceError>) -> Option<DistanceError> {
    let n = rows.len() as f64;
    let first = rows.first()?.clone();
    Some(DistanceError {
        distance_m: first.distance_m,
        worst_iou: rows.iter().map(|r| r.worst_iou).fold(f64::INFINITY, f64::min),
        mean_iou: rows.iter().map(|r| r.mean_iou).sum::<f64>() / n,
        worst_color_rmse: rows.iter().map(|r| r.worst_color_rmse).fold(0.0, f64::max),
        mean_color_rmse: rows.iter().map(|r| r.mean_color_rmse).sum::<f64>() / n,
        worst_edge_error_px: rows.iter().map(|r| r.worst_edge_error_px).fold(0.0, f64::max),
        mean_edge_error_px: rows.iter().map(|r| r.mean_edge_error_px).sum::<f64>() / n,
        passes: rows.iter().all(|r| r.passes),
        canvas_px: rows.iter().map(|r| r.canvas_px).max().unwrap_or([0, 0]),
        screen_px_per_rendered_px: rows.iter().map(|r| r.screen_px_per_rendered_px).fold(1.0, f64::max),
    })
}
