//! The atlas and what draws from it: the atlas' cells, the picture planes (cards, billboards, the
//! impostor quad) and their frames, the bake of colour and normal views into the cells, leaf
//! clusters, and the wind the card levels carry.

use glam::DVec3;
use rayon::prelude::*;

use super::simplify::subset;
use super::types::{
    AtlasCell, TreeLodError, TreeLodOptions, ATLAS_ALPHA_CUTOFF, ATLAS_GUTTER_PX, BAKE_SUPERSAMPLE, IMPOSTOR_VIEWS,
};
use crate::bake::atlas::{dilate, finish_normal_atlas, mip_chain, resolve_supersampled, MipLevel, FLAT_NORMAL};
use crate::bake::image::Image;
use crate::bake::raster::{Camera, OrthoView, RasterError};
use crate::bake::render::render_unlit_and_card_normals;
use crate::bake::views::Renderable;
use crate::mesh::{AlphaMode, Bounds, CustomAttribute, Material, Mesh, Primitive};
use crate::plants::tree::TreeError;
use crate::plants::wind::{self, WIND_ATTRIBUTE, WIND_BRANCH_ATTRIBUTE};

/// A square picture plane: vertical, facing azimuth `azimuth_deg` (0° = +Z, 90° = +X), `side_m`
/// wide and tall around `centre`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct CardFrame {
    pub centre: DVec3,
    pub azimuth_deg: f64,
    pub side_m: f64,
}

impl CardFrame {
    /// Towards the viewer, and to the viewer's right.
    pub(super) fn axes(&self) -> (DVec3, DVec3) {
        let a = self.azimuth_deg.to_radians();
        (DVec3::new(a.sin(), 0.0, a.cos()), DVec3::new(a.cos(), 0.0, -a.sin()))
    }

    pub(super) fn ortho(&self, px: u32) -> OrthoView {
        let (toward, right) = self.axes();
        let h = self.side_m / 2.0;
        // the depth starts a side ahead of the centre: everything framed is behind it
        let origin = self.centre - right * h + DVec3::Y * h + toward * self.side_m;
        OrthoView {
            origin: origin.to_array(),
            right: right.to_array(),
            up: [0.0, 1.0, 0.0],
            forward: (-toward).to_array(),
            pixels_per_metre: px as f64 / self.side_m,
            width: px,
            height: px,
        }
    }

    /// The quad showing `uv` (counter-clockwise seen from the viewer side).
    pub(super) fn quad(&self, uv: [f32; 4]) -> Primitive {
        let (toward, right) = self.axes();
        let h = self.side_m / 2.0;
        let corner = |r: f64, u: f64| (self.centre + right * (r * h) + DVec3::Y * (u * h)).as_vec3().to_array();
        let n = toward.as_vec3().to_array();
        let positions = [corner(-1.0, -1.0), corner(1.0, -1.0), corner(1.0, 1.0), corner(-1.0, 1.0)];
        let uvs = [[uv[0], uv[3]], [uv[2], uv[3]], [uv[2], uv[1]], [uv[0], uv[1]]];
        Primitive {
            positions: positions.to_vec(),
            normals: vec![n; 4],
            uvs: uvs.to_vec(),
            tangents: vec![crate::mesh::quad_tangent(positions, uvs, n); 4],
            indices: vec![0, 1, 2, 0, 2, 3],
            ..Primitive::default()
        }
    }
}

/// Renders `mesh` into a `px` square through `frame` at BAKE_SUPERSAMPLE×, resolved.
pub(super) fn bake(
    frame: &CardFrame,
    px: u32,
    mesh: &Mesh,
    materials: &[Material],
    textures: &[Image],
) -> Result<Baked, RasterError> {
    let view = frame.ortho(px * BAKE_SUPERSAMPLE);
    let cam = Camera::Ortho(view);
    let mut canvas = cam.canvas([0.0; 4])?;
    let mut normals = vec![[0.0f32; 4]; canvas.color.len()];
    let normal_view = frame.ortho(1);
    let fragments =
        render_unlit_and_card_normals(&mut canvas, &cam, &normal_view, mesh, materials, textures, &mut normals)
            .fragments;
    let normals = Image { width: canvas.width, height: canvas.height, pixels: normals };
    Ok(Baked {
        color: resolve_supersampled(&Image::from_canvas_owned(canvas), BAKE_SUPERSAMPLE),
        normals: resolve_supersampled(&normals, BAKE_SUPERSAMPLE),
        fragments,
    })
}

/// One baked cell: its colour, its card normals and the fragments drawn.
pub(super) struct Baked {
    pub color: Image,
    pub normals: Image,
    pub fragments: u64,
}

/// `a` with `b`'s vertices and triangles after its own (positions, normals, uvs and the custom
/// attributes both have, or all of `b`'s when `a` is empty; `a`'s material).
pub(super) fn appended(mut a: Primitive, b: &Primitive) -> Primitive {
    let base = a.positions.len() as u32;
    if a.positions.is_empty() {
        a.custom = b
            .custom
            .iter()
            .map(|c| CustomAttribute {
                name: c.name.clone(),
                values: Vec::new(),
                unit_bytes: c.unit_bytes,
                range: c.range,
            })
            .collect();
    }
    a.custom.retain(|c| b.custom.iter().any(|d| d.name == c.name));
    for c in &mut a.custom {
        if let Some(d) = wind::find(&b.custom, &c.name) {
            c.values.extend_from_slice(&d.values);
        }
    }
    a.positions.extend_from_slice(&b.positions);
    a.normals.extend_from_slice(&b.normals);
    a.uvs.extend_from_slice(&b.uvs);
    a.tangents.extend_from_slice(&b.tangents);
    a.indices.extend(b.indices.iter().map(|i| i + base));
    a
}

/// How a tree's card levels sway: the model's ground and top and its sway frequency, from LoD0's
/// `_WIND` (None when LoD0 has none: an OBJ rock does not sway).
#[derive(Debug, Clone, Copy)]
pub(super) struct CardWind {
    ground_y: f32,
    top_y: f32,
    sway_hz: f32,
}

impl CardWind {
    pub(super) fn of(lod0: &Mesh) -> Option<CardWind> {
        let sway_hz = lod0
            .primitives
            .iter()
            .find_map(|p| wind::find(&p.custom, WIND_ATTRIBUTE))
            .and_then(|w| w.values.first())?[2];
        let positions: Vec<[f32; 3]> = lod0.primitives.iter().flat_map(|p| p.positions.iter().copied()).collect();
        let b = Bounds::of(&positions)?;
        let ground_y = if (b.min[1]..=b.max[1]).contains(&0.0) { 0.0 } else { b.min[1] };
        Some(CardWind { ground_y, top_y: b.max[1], sway_hz })
    }

    /// `card` with `_WIND` from each vertex's height and, when `branch` is given (a card standing
    /// for part of the crown: its mean branch weight and its limb's phase), `_WIND_BRANCH`.
    pub(super) fn on(&self, mut card: Primitive, branch: Option<[f32; 2]>) -> Primitive {
        card.custom = vec![wind::height_wind(&card.positions, self.ground_y, self.top_y, 0.0, self.sway_hz, 0.0)];
        if let Some([weight, phase]) = branch {
            card.custom.push(CustomAttribute {
                name: WIND_BRANCH_ATTRIBUTE.into(),
                values: vec![[weight, phase, 0.0, 0.0]; card.positions.len()],
                unit_bytes: false,
                range: Some(wind::WIND_BRANCH_RANGE),
            });
        }
        card
    }
}

/// The mean branch weight of `mesh`'s vertices and the limb phase most of them have.
pub(super) fn branch_of(mesh: &Mesh) -> [f32; 2] {
    let values: Vec<[f32; 4]> = mesh
        .primitives
        .iter()
        .filter_map(|p| wind::find(&p.custom, WIND_BRANCH_ATTRIBUTE))
        .flat_map(|c| c.values.iter().copied())
        .collect();
    if values.is_empty() {
        return [0.0, 0.0];
    }
    let weight = values.iter().map(|v| v[0] as f64).sum::<f64>() / values.len() as f64;
    let mut phases: Vec<u32> = values.iter().map(|v| v[1].to_bits()).collect();
    phases.sort_unstable();
    let (mut best, mut best_run, mut run) = (phases[0], 0, 0);
    for (k, &ph) in phases.iter().enumerate() {
        run = if k > 0 && phases[k - 1] == ph { run + 1 } else { 1 };
        if run > best_run {
            (best, best_run) = (ph, run);
        }
    }
    [weight as f32, f32::from_bits(best)]
}

/// A cluster of dropped geometry and where its card stands.
pub(super) struct Cluster {
    pub mesh: Mesh,
    pub centre: DVec3,
    pub side_m: f64,
}

/// Groups `dropped` by a uniform n³ grid over its triangles' centroids, n the largest of 8…1 that
/// leaves at most `max_clusters` occupied cells (none when 0); clusters in cell order (deterministic).
pub(super) fn clusters(dropped: &Mesh, max_clusters: usize) -> Vec<Cluster> {
    let centroid = |p: &Primitive, t: usize| {
        (0..3).map(|k| DVec3::from(p.positions[p.indices[3 * t + k] as usize].map(f64::from))).sum::<DVec3>() / 3.0
    };
    let all: Vec<DVec3> =
        dropped.primitives.iter().flat_map(|p| (0..p.triangle_count()).map(move |t| centroid(p, t))).collect();
    if all.is_empty() || max_clusters == 0 {
        return Vec::new();
    }
    let (lo, hi) =
        all.iter().fold((DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)), |(lo, hi), &c| (lo.min(c), hi.max(c)));
    let extent = (hi - lo).max(DVec3::splat(1e-9));
    let cell_of = |c: DVec3, n: usize| {
        let r = (c - lo) / extent * n as f64;
        let f = |v: f64| (v.floor().max(0.0) as usize).min(n - 1);
        (f(r.z) * n + f(r.y)) * n + f(r.x)
    };
    let mut n = 8;
    let mut cells: Vec<usize>;
    loop {
        cells = all.iter().map(|&c| cell_of(c, n)).collect();
        let mut occupied = cells.clone();
        occupied.sort_unstable();
        occupied.dedup();
        if occupied.len() <= max_clusters || n == 1 {
            break;
        }
        n -= 1;
    }
    let mut ids: Vec<usize> = cells.clone();
    ids.sort_unstable();
    ids.dedup();
    let mut out = Vec::with_capacity(ids.len());
    for id in ids {
        let mut mesh = Mesh::default();
        let mut serial = 0;
        for p in &dropped.primitives {
            let start = serial;
            let q = subset(p, |t| cells[start + t] == id);
            serial += p.triangle_count();
            if !q.indices.is_empty() {
                mesh.primitives.push(q);
            }
        }
        let (lo, hi) = mesh.primitives.iter().flat_map(|p| &p.positions).fold(
            (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
            |(lo, hi), v| {
                let v = DVec3::from(v.map(f64::from));
                (lo.min(v), hi.max(v))
            },
        );
        let side_m = (hi - lo).max_element().max(1e-3) * 1.02;
        out.push(Cluster { mesh, centre: (lo + hi) / 2.0, side_m });
    }
    out
}

/// The cards' material: the colour atlas, lit through the normal atlas (`texture + 1`).
pub(super) fn atlas_material(texture: usize) -> Material {
    Material {
        name: "tree_atlas".into(),
        base_color_texture: Some(texture),
        normal_texture: Some(texture + 1),
        roughness: 0.8,
        alpha_mode: AlphaMode::Mask { cutoff: ATLAS_ALPHA_CUTOFF },
        double_sided: true,
        ..Material::default()
    }
}

/// The frame every model-wide view uses: a square `side_m` wide around the vertical axis through
/// the footprint's centre, the whole model inside.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ModelFrame {
    pub centre: DVec3,
    pub side_m: f64,
    /// The bounding sphere's radius about `centre`.
    pub radius: f64,
}

impl ModelFrame {
    pub fn of(mesh: &Mesh) -> Result<ModelFrame, TreeLodError> {
        let all_positions: Vec<[f32; 3]> = mesh.primitives.iter().flat_map(|p| p.positions.iter().copied()).collect();
        let bounds = Bounds::of(&all_positions).ok_or(TreeError::Empty)?;
        let axis =
            DVec3::new((bounds.min[0] + bounds.max[0]) as f64 / 2.0, 0.0, (bounds.min[2] + bounds.max[2]) as f64 / 2.0);
        let reach = all_positions
            .iter()
            .map(|v| ((v[0] as f64 - axis.x).powi(2) + (v[2] as f64 - axis.z).powi(2)).sqrt())
            .fold(0.0, f64::max);
        let height = (bounds.max[1] - bounds.min[1]) as f64;
        let centre = DVec3::new(axis.x, (bounds.min[1] + bounds.max[1]) as f64 / 2.0, axis.z);
        let side_m = (2.0 * reach).max(height).max(1e-3) * 1.02;
        let radius =
            all_positions.iter().map(|v| (DVec3::from(v.map(f64::from)) - centre).length()).fold(0.0, f64::max);
        Ok(ModelFrame { centre, side_m, radius })
    }

    /// Impostor view `k`: the model seen from azimuth k · 360° / IMPOSTOR_VIEWS.
    pub fn view(&self, k: usize) -> CardFrame {
        CardFrame { centre: self.centre, azimuth_deg: k as f64 * 360.0 / IMPOSTOR_VIEWS as f64, side_m: self.side_m }
    }
}

/// The baked colour and normal atlases (empty for a chain of two levels or fewer).
pub(super) struct BakedAtlas {
    pub impostor_cells: Vec<AtlasCell>,
    /// The colour atlas' coverage-preserving mips, level 0 first.
    pub mips: Vec<MipLevel>,
    pub normal: Option<Image>,
    pub fragments: u64,
}

/// Bakes the impostor views of `reference` (LoD3 reuses the first four), then two views per leaf
/// cluster, in colour and as normals in each card's frame (the normal atlas lit cards sample).
pub(super) fn bake_atlas(
    reference: &Renderable,
    frame: &ModelFrame,
    groups: &[Cluster],
    options: &TreeLodOptions,
) -> Result<BakedAtlas, TreeLodError> {
    let px = options.atlas_px;
    let wanted = options.lods;
    let impostor_cells: Vec<AtlasCell> = (0..IMPOSTOR_VIEWS).map(|k| AtlasCell::large(px, k)).collect();
    let mut jobs: Vec<(AtlasCell, CardFrame, &Mesh)> = Vec::new();
    if wanted > 2 {
        for (k, cell) in impostor_cells.iter().enumerate() {
            jobs.push((*cell, frame.view(k), reference.mesh));
        }
        for (c, g) in groups.iter().enumerate() {
            for side in 0..2 {
                let card = CardFrame { centre: g.centre, azimuth_deg: 90.0 * side as f64, side_m: g.side_m };
                jobs.push((AtlasCell::small(px, 2 * c + side), card, &g.mesh));
            }
        }
    }
    let (materials, images) = (reference.materials, reference.textures);
    // one task per cell: the eight impostor views draw the whole tree and come first, and rayon's
    // default split would leave them in one sequential piece for one thread (the bake then did not
    // scale with threads at all)
    let baked: Vec<Result<Baked, RasterError>> = jobs
        .par_iter()
        .with_max_len(1)
        .map(|(cell, card, mesh)| bake(card, cell.inner_px(), mesh, materials, images))
        .collect();
    let mut normal_atlas = Image { width: px, height: px, pixels: vec![FLAT_NORMAL; (px as usize) * (px as usize)] };
    let mut atlas = Image { width: px, height: px, pixels: vec![[0.0; 4]; (px as usize) * (px as usize)] };
    let mut fragments = 0;
    for ((cell, _, _), b) in jobs.iter().zip(baked) {
        let b = b?;
        fragments += b.fragments;
        atlas.blit(&b.color, cell.x + ATLAS_GUTTER_PX, cell.y + ATLAS_GUTTER_PX);
        normal_atlas.blit(&b.normals, cell.x + ATLAS_GUTTER_PX, cell.y + ATLAS_GUTTER_PX);
    }
    let mips = if wanted > 2 {
        dilate(&mut atlas, ATLAS_ALPHA_CUTOFF);
        mip_chain(&atlas, ATLAS_ALPHA_CUTOFF)
    } else {
        Vec::new()
    };
    let normal = (wanted > 2).then(|| finish_normal_atlas(normal_atlas));
    Ok(BakedAtlas { impostor_cells, mips, normal, fragments })
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::CardFrame;
    use crate::plants::tree_lod::types::{AtlasCell, MAX_CLUSTERS};

    #[test]
    fn atlas_cells_do_not_overlap_and_stay_inside() {
        let px = 512;
        let mut cells: Vec<AtlasCell> = (0..8).map(|i| AtlasCell::large(px, i)).collect();
        cells.extend((0..2 * MAX_CLUSTERS).map(|j| AtlasCell::small(px, j)));
        for (i, a) in cells.iter().enumerate() {
            assert!(a.x + a.size <= px && a.y + a.size <= px);
            assert!(a.uv.iter().all(|u| (0.0..=1.0).contains(u)));
            for b in &cells[i + 1..] {
                let apart = a.x + a.size <= b.x || b.x + b.size <= a.x || a.y + a.size <= b.y || b.y + b.size <= a.y;
                assert!(apart, "{a:?} overlaps {b:?}");
            }
        }
    }

    #[test]
    fn card_quad_faces_its_viewer_and_maps_the_cell() {
        for az in [0.0, 45.0, 90.0, 200.0] {
            let f = CardFrame { centre: DVec3::new(1.0, 2.0, 3.0), azimuth_deg: az, side_m: 2.0 };
            let q = f.quad([0.25, 0.5, 0.5, 0.75]);
            let c = q.triangle_cross(0);
            let (toward, _) = f.axes();
            assert!(DVec3::from(c).dot(toward) > 0.0, "counter-clockwise seen from the viewer at {az}°");
            // the quad's corners land on the view's corners
            let v = f.ortho(100);
            let tl = v.to_pixel(q.positions[3].map(f64::from));
            let br = v.to_pixel(q.positions[1].map(f64::from));
            assert!(
                tl[0].abs() < 1e-3
                    && tl[1].abs() < 1e-3
                    && (br[0] - 100.0).abs() < 1e-3
                    && (br[1] - 100.0).abs() < 1e-3
            );
            assert!(tl[2] > 0.0 && br[2] > 0.0, "in front of the camera");
        }
    }
}
