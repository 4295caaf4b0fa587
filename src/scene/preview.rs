//! `preview.png`: a shaded relief of what was built, drawn from the meshes (not the heightmap) with
//! the software rasteriser, seen straight from above. Deferred shading in two passes: the surface
//! pass stores height, interpolated normal and chunk per pixel (the canvas's four channels as a
//! G-buffer), then every covered pixel is shaded with Lambert from the north-west at 45° times a hypsometric
//! tint over the *visible* height range (so skirts and a base do not stretch the colour ramp), and
//! pixels on a border between two chunk nodes are darkened.
//!
//! Orientation is the heightmap image's: x to the right, z down the image (north, −z, up), the long
//! side `size_px` pixels, the aspect kept. Later stages can draw into the same picture with
//! [`preview_view`], which gives the identical view.

use std::path::Path;

use crate::bake::raster::{Canvas, Cull, DrawOptions, OrthoView, RasterError, MAX_CANVAS_SIDE};
use crate::color::srgb_to_linear;
use crate::mesh::{Primitive, Scene};

/// Uncovered pixels: transparent, so the picture composes onto any page background.
pub const BACKGROUND: [f32; 4] = [0.0, 0.0, 0.0, 0.0];

/// Direction *towards* the light: from the north-west (−x, −z) at 45° elevation.
const LIGHT: [f32; 3] = [-0.5, std::f32::consts::FRAC_1_SQRT_2, -0.5];

/// Light never fully absent, so slopes facing away from the sun keep their tint readable.
const AMBIENT: f32 = 0.25;
/// Chunk borders are drawn as the shaded colour times this.
const OUTLINE_FACTOR: f32 = 0.6;

/// Hypsometric ramp (sRGB stops, t = relative height): low greens → browns → grey rock → snow.
const RAMP: [(f32, [f32; 3]); 6] = [
    (0.00, [0.24, 0.42, 0.20]),
    (0.25, [0.45, 0.58, 0.29]),
    (0.50, [0.62, 0.55, 0.36]),
    (0.70, [0.50, 0.40, 0.30]),
    (0.85, [0.60, 0.60, 0.60]),
    (1.00, [0.97, 0.97, 0.98]),
];

/// One primitive to draw, in world space (borrowed when its node transform is the identity).
enum WorldPrim<'a> {
    Borrowed(&'a Primitive),
    Owned(Primitive),
}

impl WorldPrim<'_> {
    fn get(&self) -> &Primitive {
        match self {
            WorldPrim::Borrowed(p) => p,
            WorldPrim::Owned(p) => p,
        }
    }
}

/// A 3×4 affine matrix (columns x, y, z axes, translation) as rows.
type Affine = [[f64; 4]; 3];

const IDENTITY: Affine = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];

fn node_matrix(t: [f32; 3], q: [f32; 4], s: [f32; 3]) -> Affine {
    let [x, y, z, w] = q.map(|v| v as f64);
    // Rotation matrix of a unit quaternion, columns scaled.
    let r = [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
        [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
        [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
    ];
    let mut m = [[0.0; 4]; 3];
    for row in 0..3 {
        for col in 0..3 {
            m[row][col] = r[row][col] * s[col] as f64;
        }
        m[row][3] = t[row] as f64;
    }
    m
}

fn compose(a: &Affine, b: &Affine) -> Affine {
    let mut m = [[0.0; 4]; 3];
    for row in 0..3 {
        for col in 0..4 {
            m[row][col] = a[row][0] * b[0][col] + a[row][1] * b[1][col] + a[row][2] * b[2][col];
        }
        m[row][3] += a[row][3];
    }
    m
}

fn transformed(p: &Primitive, m: &Affine) -> Primitive {
    let apply = |v: [f32; 3], w: f64| {
        let v = [v[0] as f64, v[1] as f64, v[2] as f64];
        [0, 1, 2].map(|r| (m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2] + m[r][3] * w) as f32)
    };
    // Normals by the same linear part: exact for rotations and uniform scales, which is what the
    // stages produce; renormalised by the shader anyway.
    Primitive {
        positions: p.positions.iter().map(|&v| apply(v, 1.0)).collect(),
        normals: p.normals.iter().map(|&v| apply(v, 0.0)).collect(),
        ..p.clone()
    }
}

/// Every primitive reachable from the scene's roots, in world space, in traversal order (roots in
/// order, children depth first), each with the ordinal of its chunk node (extras with a `chunk`
/// key) or −1. Instanced nodes are left out (their stage draws its placements) and so are
/// MSFT_lod's coarser levels (only referenced, not children).
fn collect(scene: &Scene) -> Vec<(WorldPrim<'_>, f32)> {
    let mut prims = Vec::new();
    let mut chunk_count = 0u32;
    let mut stack: Vec<(usize, Affine)> = scene.roots.iter().rev().map(|&r| (r, IDENTITY)).collect();
    // A malformed graph (cycle, shared child, bad index) must not hang or panic: each node once.
    let mut seen = vec![false; scene.nodes.len()];
    while let Some((n, parent)) = stack.pop() {
        let Some(node) = scene.nodes.get(n) else { continue };
        if std::mem::replace(&mut seen[n], true) {
            continue;
        }
        let local = node_matrix(node.translation, node.rotation, node.scale);
        let m = compose(&parent, &local);
        let identity = m == IDENTITY;
        if let (Some(mi), None) = (node.mesh, &node.instances) {
            if let Some(mesh) = scene.meshes.get(mi) {
                let is_chunk = node.extras.as_ref().is_some_and(|e| e.get("chunk").is_some());
                // Ordinals stay exact in f32 up to 2^24 chunks.
                let id = if is_chunk { chunk_count as f32 } else { -1.0 };
                chunk_count += is_chunk as u32;
                for p in &mesh.primitives {
                    let wp = if identity { WorldPrim::Borrowed(p) } else { WorldPrim::Owned(transformed(p, &m)) };
                    prims.push((wp, id));
                }
            }
        }
        for &c in node.children.iter().rev() {
            stack.push((c, m));
        }
    }
    prims
}

/// World bounds of the drawable primitives: (min x, max x, min z, max z, max y), if any point.
fn extent(prims: &[(WorldPrim<'_>, f32)]) -> Option<[f64; 5]> {
    let mut e: Option<[f64; 5]> = None;
    for (p, _) in prims {
        for v in &p.get().positions {
            if !v.iter().all(|c| c.is_finite()) {
                continue;
            }
            let (x, y, z) = (v[0] as f64, v[1] as f64, v[2] as f64);
            e = Some(match e {
                None => [x, x, z, z, y],
                Some(q) => [q[0].min(x), q[1].max(x), q[2].min(z), q[3].max(z), q[4].max(y)],
            });
        }
    }
    e
}

/// The view [`terrain_preview`] draws with: top-down, fit to the scene's x/z bounds, the long side
/// `size_px` (clamped to 1..=16384). `None` for a scene with nothing to draw.
pub fn preview_view(scene: &Scene, size_px: u32) -> Option<OrthoView> {
    let prims = collect(scene);
    let e = extent(&prims)?;
    // Depth measured from just above the highest point, so every depth is positive.
    Some(OrthoView::top_down(e[0], e[1], e[2], e[3], e[4] + 1.0, size_px))
}

/// Shaded relief of every mesh in `scene` seen from above (see the module docs). Deterministic: the
/// same scene gives the same pixels at any thread count. A scene with nothing to draw gives a
/// transparent `size_px`² canvas.
pub fn terrain_preview(scene: &Scene, size_px: u32) -> Canvas {
    let size_px = size_px.clamp(1, MAX_CANVAS_SIDE);
    let prims = collect(scene);
    let blank = || blank_canvas(size_px, size_px);
    let Some(e) = extent(&prims) else { return blank() };
    let view = OrthoView::top_down(e[0], e[1], e[2], e[3], e[4] + 1.0, size_px);
    let Ok(mut canvas) = view.canvas(BACKGROUND) else { return blank() };

    // Surface pass, into a G-buffer: (height, unit normal's x and z, chunk ordinal). The normal's y
    // is recovered as ≥ 0: back faces are culled, so what is seen faces up. Vertical skirts and
    // walls have no area from above; the base's bottom faces down.
    let proj = view.projection();
    let opts = DrawOptions { cull: Cull::Back, depth_test: true, depth_write: true };
    for (p, id) in &prims {
        canvas.draw_par(&proj, p.get(), &opts, |f| {
            let [nx, ny, nz] = f.normal;
            let len = (nx * nx + ny * ny + nz * nz).sqrt();
            // A primitive without normals reads as facing straight up.
            let (nx, nz) = if len > 1e-12 && len.is_finite() { (nx / len, nz / len) } else { (0.0, 0.0) };
            Some([f.position[1], nx, nz, *id])
        });
    }

    // Visible height range for the tint.
    let covered = |k: usize| canvas.depth[k].is_finite();
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for (k, c) in canvas.color.iter().enumerate() {
        if covered(k) && c[0].is_finite() {
            lo = lo.min(c[0]);
            hi = hi.max(c[0]);
        }
    }
    let span = if hi > lo { hi - lo } else { 1.0 };

    // Chunk borders as the chunks really are (a TIN's chunks follow its triangles, not the chunk
    // grid's lines): a pixel whose right or lower neighbour belongs to another chunk.
    let (w, h) = (canvas.width as usize, canvas.height as usize);
    let chunk = |k: usize| if covered(k) { canvas.color[k][3] } else { -1.0 };
    let outline: Vec<bool> = (0..w * h)
        .map(|k| {
            let (x, y) = (k % w, k / w);
            let id = chunk(k);
            let differs = |n: usize| {
                let other = chunk(n);
                id >= 0.0 && other >= 0.0 && other != id
            };
            (x + 1 < w && differs(k + 1)) || (y + 1 < h && differs(k + w))
        })
        .collect();

    // Shading pass.
    for ((c, d), &edge) in canvas.color.iter_mut().zip(&canvas.depth).zip(&outline) {
        if !d.is_finite() {
            *c = BACKGROUND;
            continue;
        }
        let [height, nx, nz, _] = *c;
        let t = if height.is_finite() { (height - lo) / span } else { 0.0 };
        let tint = hypsometric_tint(t);
        let ny = (1.0 - nx * nx - nz * nz).max(0.0).sqrt();
        let lambert = (nx * LIGHT[0] + ny * LIGHT[1] + nz * LIGHT[2]).max(0.0);
        let mut shade = AMBIENT + (1.0 - AMBIENT) * lambert;
        if edge {
            shade *= OUTLINE_FACTOR;
        }
        *c = [tint[0] * shade, tint[1] * shade, tint[2] * shade, 1.0];
    }
    canvas
}

fn blank_canvas(width: u32, height: u32) -> Canvas {
    let n = width as usize * height as usize;
    Canvas { width, height, color: vec![BACKGROUND; n], depth: vec![f32::INFINITY; n] }
}

/// Linear RGB of the hypsometric ramp at relative height `t` (clamped to 0..1).
pub fn hypsometric_tint(t: f32) -> [f32; 3] {
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 };
    let mut c = RAMP[RAMP.len() - 1].1;
    for pair in RAMP.windows(2) {
        let ((t0, c0), (t1, c1)) = (pair[0], pair[1]);
        if t <= t1 {
            let u = if t1 > t0 { (t - t0) / (t1 - t0) } else { 0.0 };
            c = [0, 1, 2].map(|d| c0[d] + (c1[d] - c0[d]) * u);
            break;
        }
    }
    c.map(srgb_to_linear)
}

/// Colour of snow in the preview (linear), and how opaque full cover (weight 1) is drawn: the relief
/// stays readable under it.
const SNOW_COLOR: [f32; 3] = [0.92, 0.94, 0.97];
const SNOW_MAX_OPACITY: f32 = 0.85;

/// Blends the snow cover into a drawn terrain: every covered pixel towards white by the mask's
/// weight at its centre (× [`SNOW_MAX_OPACITY`]). Draw it before the placements, so they stay on top.
pub fn draw_cover(canvas: &mut Canvas, view: &OrthoView, mask: &crate::snow::CoverMask) {
    let w = canvas.width as usize;
    if w == 0
        || canvas.color.len() != w * canvas.height as usize
        || view.pixels_per_metre.is_nan()
        || view.pixels_per_metre <= 0.0
    {
        return;
    }
    // pixel (i, j) of a top-down view has its centre at x = origin.x + (i + ½)/ppm, z = origin.z + (j + ½)/ppm
    let inv = 1.0 / view.pixels_per_metre;
    for (k, (c, d)) in canvas.color.iter_mut().zip(&canvas.depth).enumerate() {
        if !d.is_finite() {
            continue;
        }
        let x = view.origin[0] + ((k % w) as f64 + 0.5) * inv;
        let z = view.origin[2] + ((k / w) as f64 + 0.5) * inv;
        let a = SNOW_MAX_OPACITY * mask.weight_at(x as f32, z as f32).clamp(0.0, 1.0);
        for ch in 0..3 {
            c[ch] = c[ch] * (1.0 - a) + SNOW_COLOR[ch] * a;
        }
    }
}

/// Writes a preview (or any canvas) as an sRGB PNG, atomically.
pub fn write_png(canvas: &Canvas, path: &Path) -> Result<(), RasterError> {
    canvas.write_png(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::heightfield::Heightfield;
    use crate::terrain::build::{build_scene, BuildOptions};
    use crate::terrain::grid::grid;

    fn hill(n: usize) -> Heightfield {
        let c = (n - 1) as f32 / 2.0;
        let heights = (0..n * n)
            .map(|k| {
                let (i, j) = ((k % n) as f32 - c, (k / n) as f32 - c);
                40.0 * (-(i * i + j * j) / (c * c * 0.3)).exp()
            })
            .collect();
        Heightfield { width: n, height: n, heights, cell_size_m: 2.0, exact: None }
    }

    fn luminance(c: [f32; 4]) -> f32 {
        0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
    }

    #[test]
    fn hill_is_white_in_the_middle_and_green_at_the_corners() {
        let hf = hill(33);
        let mesh = grid(&hf, 1).unwrap();
        let scene = build_scene(&hf, &mesh, &BuildOptions::default()).unwrap();
        let c = terrain_preview(&scene, 64);
        assert_eq!((c.width, c.height), (64, 64));
        assert!(c.color.iter().all(|p| p[3] == 1.0), "terrain fills the square picture");
        let centre = c.pixel(32, 32).unwrap();
        let corner = c.pixel(0, 0).unwrap();
        assert!(luminance(centre) > luminance(corner) * 1.5, "{centre:?} vs {corner:?}");
        assert!(corner[1] > corner[0] && corner[1] > corner[2], "corner is green: {corner:?}");
        // north-west slope faces the light, south-east slope faces away
        assert!(luminance(c.pixel(24, 24).unwrap()) > luminance(c.pixel(40, 40).unwrap()));
        assert_eq!(c, terrain_preview(&scene, 64));
    }

    #[test]
    fn chunks_skirts_and_base_draw_the_same_relief_with_outlines() {
        let hf = hill(33);
        let mesh = grid(&hf, 1).unwrap();
        let plain = terrain_preview(&build_scene(&hf, &mesh, &BuildOptions::default()).unwrap(), 64);
        let with = |skirt: Option<f64>, base: Option<f64>| BuildOptions {
            chunk_samples: Some(16),
            skirt_depth_m: skirt,
            base_depth_m: base,
            ..BuildOptions::default()
        };
        for opts in [with(Some(5.0), None), with(None, Some(10.0))] {
            let chunked = terrain_preview(&build_scene(&hf, &mesh, &opts).unwrap(), 64);
            assert_eq!((chunked.width, chunked.height), (64, 64));
            let mut differing = 0;
            for (a, b) in plain.color.iter().zip(&chunked.color) {
                // Same triangles, maybe with rotated corners after the GPU reordering: equal up to the
                // last bits of the interpolation, except on outlines (darkened by the outline factor).
                if (a[0] - b[0]).abs() > 1e-5 {
                    differing += 1;
                    assert!((b[0] - a[0] * OUTLINE_FACTOR).abs() < 1e-4, "{a:?} {b:?}");
                }
            }
            // one inner border row and column of the 64² picture (grid: chunks follow its lines)
            assert!(differing > 64 && differing < 64 * 3, "{differing}");
        }
    }

    #[test]
    fn empty_scene_gives_a_blank_canvas_and_aspect_is_kept() {
        let c = terrain_preview(&Scene::default(), 10);
        assert_eq!((c.width, c.height), (10, 10));
        assert!(c.color.iter().all(|&p| p == BACKGROUND));
        let hf = Heightfield { width: 9, height: 5, heights: vec![1.0; 45], cell_size_m: 1.0, exact: None };
        let scene = build_scene(&hf, &grid(&hf, 1).unwrap(), &BuildOptions::default()).unwrap();
        let v = preview_view(&scene, 80).unwrap();
        assert_eq!((v.width, v.height), (80, 40));
        let c = terrain_preview(&scene, 80);
        assert_eq!((c.width, c.height), (80, 40));
        assert!(c.color.iter().all(|p| p[3] == 1.0));
    }

    #[test]
    fn malformed_graphs_do_not_hang() {
        let hf = hill(5);
        let mut scene = build_scene(&hf, &grid(&hf, 1).unwrap(), &BuildOptions::default()).unwrap();
        let root = scene.roots[0];
        scene.nodes[root].children = vec![root, root, 99];
        scene.roots.push(root);
        let c = terrain_preview(&scene, 16);
        assert!(c.color.iter().all(|p| p[3] == 1.0));
    }

    #[test]
    fn tint_runs_green_to_white() {
        let low = hypsometric_tint(0.0);
        let high = hypsometric_tint(1.0);
        assert!(low[1] > low[0] && low[1] > low[2]);
        assert!(high.iter().all(|&v| v > 0.9));
        assert_eq!(hypsometric_tint(f32::NAN), low);
    }
}

/// One species' instances as the preview draws them.
#[derive(Debug, Clone, PartialEq)]
pub struct PreviewLayer {
    pub color: [f32; 4],
    /// Trees and meshes are objects, drawn as discs however small; grass and flowers are cover,
    /// drawn as discs only where each is at least [`MIN_DISC_PX`] wide, else as density shading.
    pub kind: crate::plants::SpeciesKind,
    /// Width of one instance seen from above, in metres (see [`footprint_m`]).
    pub footprint_m: f64,
    /// Instance positions (x, y, z); the preview uses x and z.
    pub positions: Vec<[f64; 3]>,
}

/// Width seen from above of one instance of a species, times the middle of its scale range: the
/// kind's nominal height (plants/palette.rs) in these proportions (a tree's crown is half its height wide, grass and
/// flower cards 0.6 of it, a mesh box its height); an L-system tree scaled to a height as wide as
/// [`TREE_CROWN_PER_HEIGHT`] of it (an estimate, so the preview needs no tree built).
pub fn footprint_m(species: &crate::scene::SpeciesSettings) -> f64 {
    use crate::plants::SpeciesKind;
    use crate::scene::PlantLook;
    let mid_scale = 0.5 * (species.rules.scale[0] + species.rules.scale[1]);
    if let PlantLook::Tree(crate::scene::TreeLook { height_m: Some(h), .. }) = &species.look {
        return h * TREE_CROWN_PER_HEIGHT * mid_scale;
    }
    let kind = species.kind;
    let width_per_height = match kind {
        SpeciesKind::Tree => 0.5,
        SpeciesKind::Grass | SpeciesKind::Flower => 0.6,
        SpeciesKind::Mesh => 1.0,
    };
    crate::plants::palette::nominal_height_m(kind) as f64 * width_per_height * mid_scale
}

/// Crown width over height assumed for L-system trees in the preview (broad-leaved trees are about
/// as wide as tall, conifers a third: the middle).
pub const TREE_CROWN_PER_HEIGHT: f64 = 0.7;

/// Smallest disc drawn, in pixels across: a tree far smaller than a pixel still shows.
pub const MIN_DISC_PX: f64 = 3.0;
/// Objects whose discs would cover more than this share of the picture (were they disjoint), a
/// dense forest, are drawn as density shading instead.
const MAX_DISC_COVER: f64 = 0.5;
/// Opacity of a disc, and of the densest shading.
const DISC_OPACITY: f32 = 0.95;
const SHADE_OPACITY: f32 = 0.85;
/// Discs at least this wide (px) get a darker rim, so neighbouring crowns stay apart.
const RIM_FROM_PX: f64 = 3.0;
const RIM_FACTOR: f32 = 0.55;
/// Density shading averages over a window expected to hold this many instances (at most
/// (2·MAX_SHADE_RADIUS + 1)² pixels), so sparse cover is a tint rather than noise.
const SHADE_WINDOW_COUNT: f64 = 8.0;
const MAX_SHADE_RADIUS: usize = 6;

/// True when `layer` is drawn as one disc per instance (see [`PreviewLayer::kind`]).
fn draws_as_discs(layer: &PreviewLayer, pixels_per_metre: f64, pixels: usize) -> bool {
    use crate::plants::SpeciesKind;
    let footprint_px = layer.footprint_m * pixels_per_metre;
    let d = footprint_px.max(MIN_DISC_PX);
    let cover = layer.positions.len() as f64 * std::f64::consts::FRAC_PI_4 * d * d / pixels as f64;
    match layer.kind {
        SpeciesKind::Tree | SpeciesKind::Mesh => true,
        SpeciesKind::Grass | SpeciesKind::Flower => footprint_px >= MIN_DISC_PX && cover <= MAX_DISC_COVER,
    }
}

/// Draws placements over a preview made with `view`: objects (trees, meshes) as one disc per
/// instance, as wide as the footprint and at least [`MIN_DISC_PX`]; cover (grass, flowers; and a
/// forest too dense for discs) as shading whose opacity follows the local instance density
/// (counts per pixel, box-filtered; the square root of the density relative to the densest shaded
/// layer's 98th percentile, so a sparse cover shows fainter than a dense one). Shaded layers go
/// first, then the discs on top, each in layer order, so trees stay visible over grass.
pub fn draw_placements(canvas: &mut Canvas, view: &OrthoView, layers: &[PreviewLayer]) {
    let (w, h) = (canvas.width as usize, canvas.height as usize);
    if w == 0 || h == 0 || canvas.color.len() != w * h {
        return;
    }
    let ppm = view.pixels_per_metre;
    let pixel = |p: [f64; 3]| {
        let q = view.to_pixel(p);
        (q[0].is_finite() && q[1].is_finite()).then_some((q[0], q[1]))
    };
    let blend = |c: &mut [f32; 4], color: [f32; 4], a: f32| {
        for k in 0..3 {
            c[k] = c[k] * (1.0 - a) + color[k] * a;
        }
        c[3] = c[3].max(a);
    };
    // density per pixel of each shaded layer, then one reference for all of them (the largest of
    // their 98th percentiles), so a sparse cover shows fainter than a dense one
    let shaded: Vec<(&PreviewLayer, Vec<f32>)> = layers
        .iter()
        .filter(|l| !draws_as_discs(l, ppm, w * h))
        .map(|layer| {
            // fill counts per pixel
            let mut counts = vec![0f32; w * h];
            for &p in &layer.positions {
                if let Some((x, y)) = pixel(p) {
                    if x >= 0.0 && y >= 0.0 && (x as usize) < w && (y as usize) < h {
                        counts[y as usize * w + x as usize] += 1.0;
                    }
                }
            }
            let mean = layer.positions.len() as f64 / (w * h) as f64;
            let radius = (0..=MAX_SHADE_RADIUS)
                .find(|r| mean * ((2 * r + 1) * (2 * r + 1)) as f64 >= SHADE_WINDOW_COUNT)
                .unwrap_or(MAX_SHADE_RADIUS);
            (layer, box_filter(&counts, w, h, radius))
        })
        .collect();
    let reference = shaded
        .iter()
        .filter_map(|(_, density)| {
            let mut present: Vec<f32> = density.iter().copied().filter(|&v| v > 0.0).collect();
            let k = present.len().checked_sub(1)? * 98 / 100;
            Some(*present.select_nth_unstable_by(k, f32::total_cmp).1)
        })
        .fold(0.0f32, f32::max);
    for (layer, density) in &shaded {
        for (c, &v) in canvas.color.iter_mut().zip(density) {
            if v > 0.0 {
                // square root: a cover a tenth as dense still shows, at a third of the opacity
                blend(c, layer.color, SHADE_OPACITY * (v / reference).min(1.0).sqrt());
            }
        }
    }
    for layer in layers.iter().filter(|l| draws_as_discs(l, ppm, w * h)) {
        let r = (layer.footprint_m * ppm).max(MIN_DISC_PX) / 2.0;
        let rim = if 2.0 * r >= RIM_FROM_PX { r - 1.0 } else { f64::INFINITY };
        let dark =
            [layer.color[0] * RIM_FACTOR, layer.color[1] * RIM_FACTOR, layer.color[2] * RIM_FACTOR, layer.color[3]];
        for &p in &layer.positions {
            let Some((cx, cy)) = pixel(p) else { continue };
            // pixels whose centre lies in the disc
            let (x0, x1) = ((cx - r).floor().max(0.0), (cx + r).ceil().min(w as f64));
            let (y0, y1) = ((cy - r).floor().max(0.0), (cy + r).ceil().min(h as f64));
            for y in y0 as usize..y1.max(0.0) as usize {
                for x in x0 as usize..x1.max(0.0) as usize {
                    let d = ((x as f64 + 0.5 - cx).powi(2) + (y as f64 + 0.5 - cy).powi(2)).sqrt();
                    if d <= r {
                        blend(&mut canvas.color[y * w + x], if d > rim { dark } else { layer.color }, DISC_OPACITY);
                    }
                }
            }
        }
    }
}

/// Mean over the (2r + 1)² window around each pixel (cut at the borders), by running sums along
/// rows, then columns.
fn box_filter(values: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let pass = |src: &[f32], len: usize, lines: usize, at: &dyn Fn(usize, usize) -> usize| {
        let mut out = vec![0f32; src.len()];
        for line in 0..lines {
            let mut sum = 0f64;
            // the window [i − r, i + r], entering on the right and leaving on the left
            for i in 0..len + r {
                if i < len {
                    sum += src[at(line, i)] as f64;
                }
                if i >= r {
                    let c = i - r;
                    if c > r {
                        sum -= src[at(line, c - r - 1)] as f64;
                    }
                    let n = (c + r).min(len - 1) + 1 - c.saturating_sub(r);
                    out[at(line, c)] = (sum / n as f64) as f32;
                }
            }
        }
        out
    };
    let rows = pass(values, w, h, &|line, i| line * w + i);
    pass(&rows, h, w, &|line, i| i * w + line)
}

#[cfg(test)]
mod placement_tests {
    use super::*;
    use crate::plants::SpeciesKind;

    const TREE: [f32; 4] = [0.05, 0.25, 0.06, 1.0];
    const GRASS: [f32; 4] = [0.35, 0.60, 0.12, 1.0];

    /// A 100 m × 100 m view at 1 px per metre over a blank canvas.
    fn blank() -> (Canvas, OrthoView) {
        let view = OrthoView::top_down(0.0, 100.0, 0.0, 100.0, 10.0, 100);
        (view.canvas(BACKGROUND).unwrap(), view)
    }

    fn layer(kind: SpeciesKind, color: [f32; 4], footprint_m: f64, positions: Vec<[f64; 3]>) -> PreviewLayer {
        PreviewLayer { color, kind, footprint_m, positions }
    }

    fn covered(c: &Canvas) -> usize {
        c.color.iter().filter(|p| p[3] > 0.0).count()
    }

    #[test]
    fn trees_are_discs_of_their_footprint_and_at_least_three_pixels() {
        // a sub-pixel crown: a 3 px disc (the 3×3 pixels whose centres are within 1.5 px)
        let (mut c, view) = blank();
        draw_placements(
            &mut c,
            &view,
            &[layer(SpeciesKind::Tree, TREE, 0.4, vec![[20.5, 0.0, 30.5], [70.5, 0.0, 60.5]])],
        );
        assert_eq!(covered(&c), 2 * 9);
        assert!(c.color[30 * 100 + 20][3] > 0.9 && c.color[31 * 100 + 21][3] > 0.9 && c.color[32 * 100 + 20][3] == 0.0);
        // a 9 m crown: about π·4.5² pixels, its own colour inside and a darker rim
        let (mut c, view) = blank();
        draw_placements(&mut c, &view, &[layer(SpeciesKind::Tree, TREE, 9.0, vec![[50.5, 0.0, 50.5]])]);
        let n = covered(&c) as f64;
        assert!((n - std::f64::consts::PI * 4.5 * 4.5).abs() < 8.0, "{n}");
        let (inside, rim) = (c.color[50 * 100 + 50], c.color[50 * 100 + 54]);
        assert!((inside[1] - TREE[1] * DISC_OPACITY).abs() < 1e-6, "{inside:?}");
        assert!(rim[3] > 0.9 && rim[1] < 0.7 * inside[1], "{rim:?}");
        // far outside the view: nothing drawn, no panic
        let (mut c, view) = blank();
        draw_placements(
            &mut c,
            &view,
            &[layer(SpeciesKind::Tree, TREE, 9.0, vec![[-1e9, 0.0, 5.0], [f64::NAN, 0.0, 1.0]])],
        );
        assert_eq!(covered(&c), 0);
    }

    #[test]
    fn dense_cover_is_shaded_by_density_and_trees_are_drawn_over_it() {
        // grass four times as dense on the left half as on the right: 8 and 2 per m², hashed spots
        let mut grass = Vec::new();
        for k in 0..50_000u64 {
            let h = crate::random::mix64(k);
            let (u, v) = ((h >> 40) as f64 / (1u64 << 24) as f64, (h & 0xFF_FFFF) as f64 / (1u64 << 24) as f64);
            let x = if k % 5 == 0 { 50.0 + 50.0 * u } else { 50.0 * u };
            grass.push([x, 0.0, 100.0 * v]);
        }
        let (mut c, view) = blank();
        // the tree comes first in the list but is drawn over the shading
        let layers = [
            layer(SpeciesKind::Tree, TREE, 6.0, vec![[25.5, 0.0, 50.5]]),
            layer(SpeciesKind::Grass, GRASS, 0.24, grass),
        ];
        draw_placements(&mut c, &view, &layers);
        let mean_alpha = |x0: usize, x1: usize| {
            let (mut sum, mut n) = (0.0, 0);
            for y in 10..90 {
                for x in x0..x1 {
                    if (x as f64 - 25.5).abs() > 5.0 || (y as f64 - 50.5).abs() > 5.0 {
                        sum += c.color[y * 100 + x][3];
                        n += 1;
                    }
                }
            }
            sum / n as f32
        };
        let (left, right) = (mean_alpha(10, 40), mean_alpha(60, 90));
        // opacity ∝ √density: 0.85 where densest, about half of it at a quarter of the density
        assert!(left > 0.75 && left <= SHADE_OPACITY, "{left}");
        assert!((right / left - 0.5).abs() < 0.1, "{left} {right}");
        let tree = c.color[50 * 100 + 25];
        assert!((tree[1] - (0.95 * TREE[1] + 0.05 * c.color[50 * 100 + 10][1])).abs() < 0.05, "{tree:?}");
        // the same cover seen close enough that a clump is 3 px wide is drawn as discs
        assert!(draws_as_discs(&layers[1], MIN_DISC_PX / 0.24, 1 << 30) && !draws_as_discs(&layers[1], 1.0, 10_000));
    }

    #[test]
    fn box_filter_is_the_window_mean() {
        let (w, h) = (7, 5);
        let v: Vec<f32> = (0..w * h).map(|k| ((k * 37) % 11) as f32).collect();
        for r in 0..4 {
            let f = box_filter(&v, w, h, r);
            for y in 0..h {
                for x in 0..w {
                    let (mut s, mut n) = (0.0, 0.0);
                    for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                        for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                            s += v[yy * w + xx];
                            n += 1.0;
                        }
                    }
                    assert!((f[y * w + x] - s / n).abs() < 1e-5, "r {r} at {x},{y}");
                }
            }
        }
    }
}
