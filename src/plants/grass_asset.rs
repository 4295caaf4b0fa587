//! One grass species made ready for export: its clumps at every level of detail, the atlas baked
//! from LoD0 by the software rasteriser (4 vertical slices + top view per clump, the far-field
//! block, shelf-packed), the blade texture, coverage-preserving mip chains, a density-in-alpha
//! atlas, and the analyzer's figures (triangles, bytes, image error and switch distance per LoD).

use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::bake::atlas::{
    dilate, finish_normal_atlas, mip_chain, mip_figures, resolve_supersampled, MipFigures, MipLevel, FLAT_NORMAL,
};
use crate::bake::image::Image;
use crate::bake::raster::{Camera, OrthoView, RasterError};
use crate::bake::render::{render_mesh, RenderOptions, Shading};
use crate::bake::views::{self, DistanceError, LodImageOptions, Renderable, ScreenView, SwitchSearch};
use crate::lod::LodView;
use crate::mesh::{AlphaMode, Material, Mesh, Node, Primitive, Scene, Texture};
use crate::plants::grass::{self, clump, far_block, Clump, GrassSettings, Slice, UvRect};
use crate::plants::texture;

/// Levels of detail of a clump (LoD0 blades … LoD3 top card).
pub const GRASS_LODS: usize = 4;
/// What each level draws, as manifest.json names it (see [`crate::plants::grass`]).
pub const GRASS_LOD_KINDS: [&str; GRASS_LODS] = ["blades", "blade quads", "slices", "top card"];
/// The rings the real-time grass thesis used (near blades up to 32 m, billboards to 80 m).
pub const THESIS_RINGS_M: [f64; 2] = [32.0, 80.0];
/// The grass switch search's range: farthest and nearest distance (eye to the clump's
/// bounding-sphere centre) and bisection steps (see [`SwitchSearch`]).
pub const SEARCH_FAR_M: f64 = 256.0;
pub const SEARCH_NEAR_M: f64 = 0.5;
pub const SEARCH_BISECTIONS: usize = 3;

/// Where a level's image error stays within the view's bound (the shared 1-px search,
/// [`crate::bake::views::switch_search`], over the grass range at 128 px, 4×4 samples).
pub fn switch_search(
    reference: &Renderable,
    candidate: &Renderable,
    view: &ScreenView,
) -> (Vec<DistanceError>, f64, bool) {
    let opts = LodImageOptions { max_side_px: 128, supersample: 4, ..LodImageOptions::default() };
    let range = SwitchSearch::from_far(SEARCH_FAR_M, SEARCH_NEAR_M, SEARCH_BISECTIONS);
    views::switch_search(reference, candidate, view, &opts, &range)
}

const IDENTITY: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];

#[derive(Debug, thiserror::Error)]
pub enum GrassAssetError {
    #[error(transparent)]
    Settings(#[from] grass::GrassError),
    #[error("baking the grass atlas: {0}")]
    Raster(#[from] RasterError),
    #[error("blade texture: {0}")]
    Texture(String),
}

/// Where each view sits in the atlas, in pixels and as a uv rectangle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AtlasCell {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
    pub uv: UvRect,
}

/// Figures of one level of detail (all clumps together, and the densest clump alone).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LodFigures {
    pub level: usize,
    pub triangles: usize,
    pub vertices: usize,
    /// Size of `<name>_LOD<n>.glb`.
    pub bytes: usize,
    pub densest_clump_triangles: usize,
    /// Worst over 8 azimuths × 3 elevations of the densest clump vs its LoD0, at the nearest
    /// measured distance and at the switch distance (distances from the clump's centre).
    pub near_distance_m: f64,
    pub near_iou: f64,
    pub near_color_rmse: f64,
    pub switch_iou: f64,
    pub switch_color_rmse: f64,
    pub switch_edge_error_px: f64,
    /// Every distance measured (the switch search), nearest first.
    pub measured: Vec<DistanceError>,
    /// Distance (eye to clump centre) from which this level's silhouette error stays ≤ 1 px
    /// (1920 px wide, 60° view).
    pub switch_distance_m: f64,
    /// True when the error never fell under the bound at the measured distances.
    pub never_passes: bool,
    /// MSFT_lod screen coverage at the switch distance.
    pub screen_coverage: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GrassReport {
    pub name: String,
    pub clumps: usize,
    pub blades_total: usize,
    pub lods: Vec<LodFigures>,
    pub atlas_mips: Vec<MipFigures>,
    pub blade_texture_mips: Vec<MipFigures>,
    pub far_field_triangles: usize,
    pub far_field_cells: usize,
    pub thesis_rings_m: [f64; 2],
    pub seconds_generate: f64,
    /// Of `seconds_bake`: rendering the views (at 2×, resolved), and dilating the atlases.
    pub seconds_bake: f64,
    pub seconds_render: f64,
    pub seconds_dilate: f64,
    pub seconds_analyze: f64,
    pub raster_fragments: u64,
}

/// Everything `build` writes for one grass species.
#[derive(Debug, Clone)]
pub struct GrassAsset {
    pub name: String,
    pub settings: GrassSettings,
    pub clumps: Vec<Clump>,
    /// `<name>_LOD<n>.glb`: one node per clump.
    pub lod_scenes: Vec<Scene>,
    /// `<name>.glb`: each clump's LoD0 node with MSFT_lod to its coarser levels.
    pub chain: Scene,
    /// `<name>_far.glb`.
    pub far: Scene,
    pub atlas: Vec<MipLevel>,
    pub density_atlas: Image,
    /// The atlas' normals (glTF tangent-space normal map), the card levels' normalTexture.
    pub normal_atlas: Image,
    pub blade: Vec<MipLevel>,
    pub cells: Vec<AtlasCell>,
    pub report: GrassReport,
}

/// Shelf packing of `sizes` (in order) into rows `row_width` wide; returns cells and atlas size.
fn pack(sizes: &[(u32, u32)], row_width: u32) -> (Vec<(u32, u32)>, u32, u32) {
    let (mut x, mut y, mut row_h) = (0u32, 0u32, 0u32);
    let mut out = Vec::with_capacity(sizes.len());
    for &(w, h) in sizes {
        if x + w > row_width && x > 0 {
            y += row_h;
            x = 0;
            row_h = 0;
        }
        out.push((x, y));
        x += w;
        row_h = row_h.max(h);
    }
    (out, row_width, (y + row_h).max(1))
}

fn blade_material(settings: &GrassSettings, texture: usize) -> Material {
    Material {
        name: "grass_blade".into(),
        base_color_texture: Some(texture),
        roughness: 0.9,
        alpha_mode: AlphaMode::Mask { cutoff: settings.alpha_cutoff },
        double_sided: true,
        ..Material::default()
    }
}

/// The card levels' material: the atlas, lit through its normal atlas (`texture + 1`).
fn atlas_material(settings: &GrassSettings, texture: usize) -> Material {
    Material { name: "grass_atlas".into(), normal_texture: Some(texture + 1), ..blade_material(settings, texture) }
}

/// Object → world matrix of a clump turned by `quarter` quarter turns about +Y and moved to (x, z).
fn placed(quarter: u32, x: f32, z: f32) -> [[f64; 4]; 3] {
    let (s, c) = match quarter % 4 {
        0 => (0.0, 1.0),
        1 => (1.0, 0.0),
        2 => (0.0, -1.0),
        _ => (-1.0, 0.0),
    };
    [[c, 0.0, s, x as f64], [0.0, 1.0, 0.0, 0.0], [-s, 0.0, c, z as f64]]
}

fn unlit() -> RenderOptions {
    RenderOptions { use_vertex_colors: false, shading: Shading::Unlit, ..RenderOptions::default() }
}

/// Renders `mesh` (with the blade material) through an orthographic view.
/// Transparent texels around every atlas cell.
pub const ATLAS_GUTTER_PX: u32 = 4;
/// Samples per texel along each axis when baking views: the resolved alpha is fractional at blade
/// edges (anti-aliased), which is what lets the mip chain keep level 0's coverage closely.
pub const BAKE_SUPERSAMPLE: u32 = 2;

/// Renders the meshes through an orthographic view at BAKE_SUPERSAMPLE× and resolves to the view's
/// size. Returns the image and the fragments written.
fn render(
    view: OrthoView,
    items: &[([[f64; 4]; 3], &Mesh)],
    materials: &[Material],
    textures: &[Image],
    opts: &RenderOptions,
) -> Result<(Image, u64), RasterError> {
    let ss = BAKE_SUPERSAMPLE;
    let fine = OrthoView {
        pixels_per_metre: view.pixels_per_metre * ss as f64,
        width: view.width * ss,
        height: view.height * ss,
        ..view
    };
    let cam = Camera::Ortho(fine);
    let mut canvas = cam.canvas([0.0; 4])?;
    let mut fragments = 0;
    for (m, mesh) in items {
        fragments += render_mesh(&mut canvas, &cam, m, mesh, materials, textures, opts).fragments;
    }
    Ok((resolve_supersampled(&Image::from_canvas(&canvas), ss), fragments))
}

/// The view of a slice: looking along −normal at the plane, the slab of blades in front.
fn slice_view(settings: &GrassSettings, slice: &Slice, width_px: u32, height_px: u32) -> OrthoView {
    let s = settings.clump_size_m as f64;
    let n = slice.normal.map(|x| x as f64);
    let right = slice.right().map(|x| x as f64);
    let ppm = width_px as f64 / s;
    let c = [n[0] * slice.offset_m as f64, 0.0, n[2] * slice.offset_m as f64];
    let top = settings.max_height_m() as f64;
    OrthoView {
        origin: [c[0] - right[0] * s / 2.0 + n[0] * s, top, c[2] - right[2] * s / 2.0 + n[2] * s],
        right,
        up: [0.0, 1.0, 0.0],
        forward: [-n[0], -n[1], -n[2]],
        pixels_per_metre: ppm,
        width: width_px,
        height: height_px,
    }
}

fn top_view(settings: &GrassSettings, px: u32) -> OrthoView {
    let h = settings.clump_size_m as f64 / 2.0;
    OrthoView::top_down(-h, h, -h, h, settings.max_height_m() as f64 + 0.01, px)
}

fn far_view(settings: &GrassSettings, width_px: u32, height_px: u32) -> OrthoView {
    let w = settings.far_cells as f64 * settings.clump_size_m as f64;
    OrthoView {
        origin: [-w / 2.0, settings.max_height_m() as f64, w],
        right: [1.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        forward: [0.0, 0.0, -1.0],
        pixels_per_metre: width_px as f64 / w,
        width: width_px,
        height: height_px,
    }
}

fn lod_mesh(name: String, prim: Primitive) -> Mesh {
    Mesh { name, primitives: vec![prim], extras: None }
}

fn clump_name(name: &str, c: &Clump) -> String {
    format!("{name}_d{}v{}", c.level, c.variant)
}

/// A scene holding one node per clump (laid out on a grid 1.5 clump sizes apart, so a viewer shows
/// them side by side; each mesh has its origin at the clump centre), one material, one texture.
fn clump_scene(
    name: &str,
    clumps: &[Clump],
    meshes: Vec<Mesh>,
    material: Material,
    textures: Vec<Texture>,
    spacing: f32,
) -> Scene {
    let mut scene = Scene { name: name.into(), materials: vec![material], textures, ..Scene::default() };
    for (c, mesh) in clumps.iter().zip(meshes) {
        let node = scene.add_mesh_node(mesh);
        let n = &mut scene.nodes[node];
        n.translation = [c.variant as f32 * spacing, 0.0, c.level as f32 * spacing];
        n.extras = Some(serde_json::json!({ "density_level": c.level, "variant": c.variant }));
    }
    scene
}

fn png(image: &Image) -> Result<Vec<u8>, GrassAssetError> {
    image.encode_png().map_err(|e| GrassAssetError::Texture(e.to_string()))
}

/// The viewer LoD switch distances are computed for by default (the default `[lod]` policy,
/// shared with trees and terrain).
pub fn screen_view() -> LodView {
    LodView::default()
}

/// Builds, bakes and measures one grass species. `user_blade` replaces the procedural blade
/// texture (its alpha is kept).
pub fn build_grass(
    name: &str,
    settings: &GrassSettings,
    user_blade: Option<&Image>,
) -> Result<GrassAsset, GrassAssetError> {
    build_grass_with(name, settings, user_blade, true, &screen_view())
}

/// [`build_grass`], with the image analyzer optional (`analyze = false`: no switch distances, the
/// MSFT_lod coverages are then all 0 — for benchmarking generation and baking alone).
pub fn build_grass_with(
    name: &str,
    settings: &GrassSettings,
    user_blade: Option<&Image>,
    analyze: bool,
    policy: &LodView,
) -> Result<GrassAsset, GrassAssetError> {
    settings.check()?;
    let started = Instant::now();
    let s = settings;
    let clumps: Vec<Clump> =
        (0..s.density_levels).flat_map(|l| (0..s.variants).map(move |v| (l, v))).map(|(l, v)| clump(s, l, v)).collect();
    let blade_image = match user_blade {
        Some(u) => texture::blade_texture_from(s, u),
        None => texture::blade_texture(s),
    };
    let lod0: Vec<Primitive> = clumps.iter().map(|c| grass::lod0(s, c, 0)).collect();
    let lod1: Vec<Primitive> = clumps.iter().map(|c| grass::lod1(s, c, 0)).collect();
    let seconds_generate = started.elapsed().as_secs_f64();

    // bake: views of each clump's LoD0 (slices then top), then the far-field block
    let bake_started = Instant::now();
    let px = s.atlas_px;
    let slice_h = ((s.max_height_m() / s.clump_size_m) * px as f32).ceil().max(1.0) as u32;
    let far_w = px * s.far_cells as u32;
    let mut sizes = Vec::new();
    for _ in &clumps {
        sizes.extend([(px, slice_h); 4]);
        sizes.push((px, px));
    }
    sizes.push((far_w, slice_h));
    // every cell gets a gutter of ATLAS_GUTTER_PX transparent (then dilated) texels on each side, so
    // filtering and the smaller mips do not bleed one view into its neighbour
    let g = ATLAS_GUTTER_PX;
    let padded: Vec<(u32, u32)> = sizes.iter().map(|&(w, h)| (w + 2 * g, h + 2 * g)).collect();
    let (origins, atlas_w, atlas_h) = pack(&padded, (4 * px).max(far_w) + 2 * g * 4);
    let cells: Vec<AtlasCell> = sizes
        .iter()
        .zip(&origins)
        .enumerate()
        .map(|(i, (&(w, h), &(x, y)))| {
            let (x, y) = (x + g, y + g);
            // slices and the far block show exactly the tallest blade (their images round it up);
            // the top view shows its whole square
            let top = i % 5 == 4 && i < 5 * clumps.len();
            let shown_h = if top { h as f32 } else { s.max_height_m() / s.clump_size_m * px as f32 };
            AtlasCell {
                x,
                y,
                width: w,
                height: h,
                uv: [
                    x as f32 / atlas_w as f32,
                    y as f32 / atlas_h as f32,
                    (x + w) as f32 / atlas_w as f32,
                    (y as f32 + shown_h) / atlas_h as f32,
                ],
            }
        })
        .collect();

    let blade_materials = [blade_material(s, 0)];
    let textures = [blade_image.clone()];
    let opts = unlit();
    let lod0_meshes: Vec<Mesh> =
        clumps.iter().zip(&lod0).map(|(c, p)| lod_mesh(clump_name(name, c), p.clone())).collect();
    let mut atlas = Image { width: atlas_w, height: atlas_h, pixels: vec![[0.0; 4]; (atlas_w * atlas_h) as usize] };
    let mut density = atlas.clone();
    let mut fragments = 0u64;
    // density in alpha: the same views with each blade's (1 − rank) as an opaque vertex colour
    let rank_material = [Material { name: "rank".into(), ..Material::default() }];
    let rank_opts = RenderOptions { use_vertex_colors: true, ..unlit() };
    // every clump view (4 slices + top), drawn in parallel and blitted in order: the same bytes at
    // any thread count
    let views: Vec<(usize, usize)> = (0..clumps.len()).flat_map(|ci| (0..5).map(move |k| (ci, k))).collect();
    let rendered: Vec<Result<(Image, Image, Image, u64), RasterError>> = views
        .par_iter()
        .map(|&(ci, k)| {
            let c = &clumps[ci];
            let cell = cells[ci * 5 + k];
            let (view, prim, ranked) = if k < 4 {
                let slice = grass::slices(s.clump_size_m)[k];
                let slab = grass::lod0_filtered(s, c, 0, |b| slice.holds(b));
                let ranked = rank_colored(&slab, c, |b| slice.holds(b));
                (slice_view(s, &slice, cell.width, cell.height), slab, ranked)
            } else {
                (top_view(s, cell.width), lod0[ci].clone(), rank_colored(&lod0[ci], c, |_| true))
            };
            let (colour, f) = render(
                view,
                &[(IDENTITY, &lod_mesh(String::new(), prim.clone()))],
                &blade_materials,
                &textures,
                &opts,
            )?;
            let (rank, _) =
                render(view, &[(IDENTITY, &lod_mesh(String::new(), ranked))], &rank_material, &[], &rank_opts)?;
            let normal_opts = RenderOptions { shading: Shading::card_normals(&view), ..unlit() };
            let (normals, _) =
                render(view, &[(IDENTITY, &lod_mesh(String::new(), prim))], &blade_materials, &textures, &normal_opts)?;
            Ok((colour, rank, normals, f))
        })
        .collect();
    let mut normal_atlas =
        Image { width: atlas_w, height: atlas_h, pixels: vec![FLAT_NORMAL; (atlas_w * atlas_h) as usize] };
    for (&(ci, k), r) in views.iter().zip(rendered) {
        let (colour, rank, normals, f) = r?;
        let cell = cells[ci * 5 + k];
        fragments += f;
        atlas.blit(&colour, cell.x, cell.y);
        density.blit(&rank, cell.x, cell.y);
        normal_atlas.blit(&normals, cell.x, cell.y);
    }
    let far_cell = *cells.last().expect("the far-field cell is always packed");
    let densest = s.density_levels - 1;
    let block: Vec<([[f64; 4]; 3], &Mesh)> = far_block(s)
        .into_iter()
        .map(|(variant, quarter, [x, z])| (placed(quarter, x, z), &lod0_meshes[densest * s.variants + variant]))
        .collect();
    let far_v = far_view(s, far_cell.width, far_cell.height);
    let (img, f) = render(far_v, &block, &blade_materials, &textures, &opts)?;
    fragments += f;
    atlas.blit(&img, far_cell.x, far_cell.y);
    let (img, _) = render(
        far_v,
        &block,
        &blade_materials,
        &textures,
        &RenderOptions { shading: Shading::card_normals(&far_v), ..unlit() },
    )?;
    normal_atlas.blit(&img, far_cell.x, far_cell.y);
    let normal_atlas = finish_normal_atlas(normal_atlas);

    // density atlas: colour of the atlas, alpha = 1 − rank where the atlas is opaque, else 0
    let seconds_render = bake_started.elapsed().as_secs_f64();
    // dilation keeps alpha, and the density atlas' opaque texels are the atlas' (alpha ≥ cutoff): its
    // colour is the dilated atlas' colour
    dilate(&mut atlas, s.alpha_cutoff);
    for (d, a) in density.pixels.iter_mut().zip(&atlas.pixels) {
        let rank_alpha = if a[3] >= s.alpha_cutoff && d[3] > 0.0 { d[0].max(1.0 / 255.0) } else { 0.0 };
        *d = [a[0], a[1], a[2], rank_alpha];
    }
    let seconds_dilate = bake_started.elapsed().as_secs_f64() - seconds_render;
    let atlas_chain = mip_chain(&atlas, s.alpha_cutoff);
    let mut blade_level0 = blade_image.clone();
    dilate(&mut blade_level0, s.alpha_cutoff);
    let blade_chain = mip_chain(&blade_level0, s.alpha_cutoff);
    let seconds_bake = bake_started.elapsed().as_secs_f64();

    // meshes of every level, and the scenes
    let spacing = 1.5 * s.clump_size_m;
    let blade_tex = Texture { name: format!("{name}_blade"), png: png(&blade_chain[0].image)? };
    let atlas_tex = Texture { name: format!("{name}_atlas"), png: png(&atlas_chain[0].image)? };
    let normal_tex = Texture {
        name: format!("{name}_atlas_normal"),
        png: normal_atlas.encode_png_data().map_err(|e| GrassAssetError::Texture(e.to_string()))?,
    };
    let slice_rects = |ci: usize| -> [UvRect; 4] { std::array::from_fn(|k| cells[ci * 5 + k].uv) };
    let lod2: Vec<Primitive> =
        clumps.iter().enumerate().map(|(ci, c)| grass::lod2(s, c, &slice_rects(ci), cells[ci * 5 + 4].uv, 0)).collect();
    let lod3: Vec<Primitive> =
        clumps.iter().enumerate().map(|(ci, c)| grass::lod3(s, c, cells[ci * 5 + 4].uv, 0)).collect();
    let levels: [Vec<Primitive>; GRASS_LODS] = [lod0, lod1, lod2, lod3];
    let mut lod_scenes = Vec::with_capacity(GRASS_LODS);
    for (n, prims) in levels.iter().enumerate() {
        let meshes = clumps
            .iter()
            .zip(prims)
            .map(|(c, p)| lod_mesh(format!("{}_LOD{n}", clump_name(name, c)), p.clone()))
            .collect();
        let (material, textures) = if n < 2 {
            (blade_material(s, 0), vec![blade_tex.clone()])
        } else {
            (atlas_material(s, 0), vec![atlas_tex.clone(), normal_tex.clone()])
        };
        lod_scenes.push(clump_scene(&format!("{name}_LOD{n}"), &clumps, meshes, material, textures, spacing));
    }
    let far_prim = grass::far_field(s, far_cell.uv, 0);
    let far_triangles = far_prim.triangle_count();
    let far = clump_scene(
        &format!("{name}_far"),
        &clumps[..1],
        vec![lod_mesh(format!("{name}_far"), far_prim)],
        atlas_material(s, 0),
        vec![atlas_tex.clone(), normal_tex.clone()],
        0.0,
    );

    // analyzer: the densest first variant against its LoD0, from 8 azimuths × 3 elevations
    let analyze_started = Instant::now();
    let atlas_level0 = atlas_chain[0].image.clone();
    let probe = densest * s.variants;
    let reference_mesh = lod_mesh(String::new(), levels[0][probe].clone());
    let reference = Renderable { mesh: &reference_mesh, materials: &blade_materials, textures: &textures };
    let atlas_materials = [atlas_material(s, 0)];
    let atlas_textures = [atlas_level0, normal_atlas.clone()];
    let view = policy.screen_view();
    let radius = bounding_radius(&levels[0][probe]);
    let mut lods = Vec::with_capacity(GRASS_LODS);
    for (n, prims) in levels.iter().enumerate() {
        let scene_bytes = crate::export::gltf::to_glb(&lod_scenes[n]).map_err(|e| GrassAssetError::Texture(e.0))?.len();
        let (triangles, vertices) =
            prims.iter().fold((0, 0), |(t, v), p| (t + p.triangle_count(), v + p.positions.len()));
        let mut f = LodFigures {
            level: n,
            triangles,
            vertices,
            bytes: scene_bytes,
            densest_clump_triangles: prims[probe].triangle_count(),
            near_distance_m: 0.0,
            near_iou: 1.0,
            near_color_rmse: 0.0,
            measured: Vec::new(),
            switch_iou: 1.0,
            switch_color_rmse: 0.0,
            switch_edge_error_px: 0.0,
            switch_distance_m: 0.0,
            never_passes: false,
            screen_coverage: 1.0,
        };
        if n > 0 && analyze {
            let cand_mesh = lod_mesh(String::new(), prims[probe].clone());
            let candidate = if n < 2 {
                Renderable { mesh: &cand_mesh, materials: &blade_materials, textures: &textures }
            } else {
                Renderable { mesh: &cand_mesh, materials: &atlas_materials, textures: &atlas_textures }
            };
            let (rows, switch_m, never) = switch_search(&reference, &candidate, &view);
            if let Some(near) = rows.first() {
                f.near_distance_m = near.distance_m;
                f.near_iou = near.worst_iou;
                f.near_color_rmse = near.worst_color_rmse;
            }
            if let Some(at) = rows.iter().find(|d| d.distance_m >= switch_m) {
                f.switch_iou = at.worst_iou;
                f.switch_color_rmse = at.worst_color_rmse;
                f.switch_edge_error_px = at.worst_edge_error_px;
            }
            f.measured = rows;
            f.switch_distance_m = switch_m;
            f.never_passes = never;
            f.screen_coverage = policy.coverage_at_centre_distance(radius, switch_m);
        }
        lods.push(f);
    }
    // a coarser level never switches in before a finer one
    for n in 1..lods.len() {
        if lods[n].switch_distance_m < lods[n - 1].switch_distance_m {
            lods[n].switch_distance_m = lods[n - 1].switch_distance_m;
            lods[n].screen_coverage = policy.coverage_at_centre_distance(radius, lods[n].switch_distance_m);
        }
    }
    let seconds_analyze = analyze_started.elapsed().as_secs_f64();

    let chain = lod_chain_scene(name, &clumps, &lod_scenes, &lods, spacing);
    let report = GrassReport {
        name: name.into(),
        clumps: clumps.len(),
        blades_total: clumps.iter().map(|c| c.blades.len()).sum(),
        lods,
        atlas_mips: mip_figures(&atlas_chain),
        blade_texture_mips: mip_figures(&blade_chain),
        far_field_triangles: far_triangles,
        far_field_cells: s.far_cells * s.far_cells,
        thesis_rings_m: THESIS_RINGS_M,
        seconds_generate,
        seconds_bake,
        seconds_render,
        seconds_dilate,
        seconds_analyze,
        raster_fragments: fragments,
    };
    Ok(GrassAsset {
        name: name.into(),
        settings: s.clone(),
        clumps,
        lod_scenes,
        chain,
        far,
        atlas: atlas_chain,
        density_atlas: density,
        normal_atlas,
        blade: blade_chain,
        cells,
        report,
    })
}

/// LoD0 primitive of the blades `keep` accepts, coloured (1 − rank) for the density atlas.
fn rank_colored(lod0: &Primitive, c: &Clump, keep: impl Fn(&grass::Blade) -> bool) -> Primitive {
    let per_blade = lod0.positions.len() / c.blades.iter().filter(|b| keep(b)).count().max(1);
    let ranks: Vec<f32> = c.blades.iter().filter(|b| keep(b)).map(|b| 1.0 - b.rank).collect();
    let colors = (0..lod0.positions.len()).map(|v| {
        let r = ranks.get(v / per_blade.max(1)).copied().unwrap_or(1.0);
        [r, r, r, 1.0]
    });
    Primitive { colors: colors.collect(), custom: Vec::new(), material: Some(0), ..lod0.clone() }
}

fn bounding_radius(p: &Primitive) -> f64 {
    let Some(b) = p.bounds() else { return 0.0 };
    let c: [f64; 3] = std::array::from_fn(|k| 0.5 * (b.min[k] as f64 + b.max[k] as f64));
    p.positions.iter().map(|v| (0..3).map(|k| (v[k] as f64 - c[k]).powi(2)).sum::<f64>().sqrt()).fold(0.0, f64::max)
}

/// `<name>.glb`: a node per clump showing LoD0, with MSFT_lod to LoD1…3 (nodes that are not roots)
/// and `extras.MSFT_screencoverage` from the measured switch distances.
fn lod_chain_scene(name: &str, clumps: &[Clump], lod_scenes: &[Scene], lods: &[LodFigures], spacing: f32) -> Scene {
    let mut scene = Scene { name: name.into(), ..Scene::default() };
    // materials and textures: the blade ones (LoD0/1) then the atlas ones (LoD2/3)
    scene.textures =
        vec![lod_scenes[0].textures[0].clone(), lod_scenes[2].textures[0].clone(), lod_scenes[2].textures[1].clone()];
    let mut blade = lod_scenes[0].materials[0].clone();
    blade.base_color_texture = Some(0);
    let mut atlas = lod_scenes[2].materials[0].clone();
    atlas.base_color_texture = Some(1);
    atlas.normal_texture = Some(2);
    scene.materials = vec![blade, atlas];
    let mut coverage: Vec<f32> = lods.iter().skip(1).map(|l| l.screen_coverage as f32).collect();
    coverage.push(0.0);
    for (ci, c) in clumps.iter().enumerate() {
        let translation = [c.variant as f32 * spacing, 0.0, c.level as f32 * spacing];
        let mut ids = Vec::new();
        let mut first = None;
        for (n, lod) in lod_scenes.iter().enumerate() {
            let mut mesh = lod.meshes[ci].clone();
            for p in &mut mesh.primitives {
                p.material = Some(if n < 2 { 0 } else { 1 });
            }
            scene.meshes.push(mesh);
            scene.nodes.push(Node {
                name: format!("{}_LOD{n}", clump_name(name, c)),
                mesh: Some(scene.meshes.len() - 1),
                translation,
                ..Node::default()
            });
            let id = scene.nodes.len() - 1;
            if n == 0 {
                first = Some(id);
            } else {
                ids.push(id);
            }
        }
        let first = first.expect("a chain has LoD0");
        scene.nodes[first].lods = ids;
        scene.nodes[first].lod_screen_coverage = coverage.clone();
        scene.nodes[first].extras = Some(serde_json::json!({ "density_level": c.level, "variant": c.variant }));
        scene.roots.push(first);
    }
    scene
}
