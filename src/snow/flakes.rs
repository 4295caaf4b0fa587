//! Procedural snow crystals: six-fold geometry (one arm or sector built, then turned six times by
//! 60°) of the habits Nakaya's diagram gives by temperature — needles, hexagonal plates, stellar and
//! spatial dendrites, columns — plus aggregates near 0 °C, baked into an alpha atlas by the baker.

use rayon::prelude::*;
use serde::Serialize;

use crate::bake::atlas::{dilate, resolve_supersampled};
use crate::bake::image::Image;
use crate::bake::raster::{Camera, OrthoView};
use crate::bake::render::{render_mesh, RenderOptions, Shading};
use crate::mesh::{Material, Mesh, Primitive};
use crate::plants::grass_asset::BAKE_SUPERSAMPLE;
use crate::random::Stream;
use crate::snow::error::{bad, within, SnowError};

/// Stream tag of flake generation ("flak").
const FLAKE_TAG: u64 = 0x666c_616b;
/// Radius of every flake model: each sprite fills its cell the same way, the size is per particle.
pub const MODEL_RADIUS: f32 = 0.95;

/// Crystal habit (Nakaya's diagram; the snowfall thesis' six types with aggregates near 0 °C).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FlakeKind {
    /// Clusters of crystals stuck together, the large flakes of wet snow near 0 °C (above −4 °C).
    Aggregate,
    /// −4 to −8 °C: long thin prisms (180° symmetric in the sprite).
    Needle,
    /// −8 to −12 °C: flat hexagons.
    Plate,
    /// −12 to −18 °C: six branched arms in one plane.
    StellarDendrite,
    /// −18 to −25 °C: arms in several planes (3-D), seen projected.
    SpatialDendrite,
    /// −25 to −40 °C: short hexagonal prisms seen side-on (180° symmetric in the sprite).
    Column,
}

impl FlakeKind {
    pub fn name(self) -> &'static str {
        match self {
            FlakeKind::Aggregate => "aggregate",
            FlakeKind::Needle => "needle",
            FlakeKind::Plate => "plate",
            FlakeKind::StellarDendrite => "stellar_dendrite",
            FlakeKind::SpatialDendrite => "spatial_dendrite",
            FlakeKind::Column => "column",
        }
    }

    /// Rotation (degrees) that maps the sprite onto itself: 60 for the six-fold habits, 180 for
    /// needles and columns (a prism seen side-on), None for aggregates (random clusters).
    pub fn symmetry_deg(self) -> Option<f32> {
        match self {
            FlakeKind::Aggregate => None,
            FlakeKind::Needle | FlakeKind::Column => Some(180.0),
            _ => Some(60.0),
        }
    }

    /// Typical diameter range in millimetres at humidity 0.5.
    fn size_mm(self) -> [f32; 2] {
        match self {
            FlakeKind::Aggregate => [6.0, 15.0],
            FlakeKind::Needle => [1.0, 2.5],
            FlakeKind::Plate => [1.0, 3.0],
            FlakeKind::StellarDendrite => [2.0, 5.0],
            FlakeKind::SpatialDendrite => [2.0, 4.0],
            FlakeKind::Column => [0.3, 0.8],
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FlakeSettings {
    /// Air temperature where the crystals grow, °C (−40 to +2).
    pub temperature_c: f32,
    /// Relative supersaturation proxy 0..1: drier air grows plates instead of dendrites and smaller
    /// crystals; wetter air larger, more branched ones.
    pub humidity: f32,
    pub columns: u32,
    pub rows: u32,
    /// Side of one square atlas cell in pixels.
    pub cell_px: u32,
    pub alpha_cutoff: f32,
    pub seed: u64,
}

impl Default for FlakeSettings {
    fn default() -> Self {
        FlakeSettings {
            temperature_c: -15.0,
            humidity: 0.6,
            columns: 4,
            rows: 4,
            cell_px: 64,
            alpha_cutoff: 0.5,
            seed: 0,
        }
    }
}

impl FlakeSettings {
    pub fn check(&self) -> Result<(), SnowError> {
        if !within(self.temperature_c, -40.0, 2.0) {
            return bad("temperature_c", format!("is {} °C", self.temperature_c), "snow forms between −40 and +2 °C");
        }
        if !within(self.humidity, 0.0, 1.0) {
            return bad("humidity", format!("is {}", self.humidity), "use 0 (dry) to 1 (saturated)");
        }
        if !(1..=32).contains(&self.columns) || !(1..=32).contains(&self.rows) {
            return bad("columns/rows", format!("are {}×{}", self.columns, self.rows), "use 1 to 32 cells a side");
        }
        if !(16..=1024).contains(&self.cell_px) {
            return bad("cell_px", format!("is {}", self.cell_px), "use 16 to 1024 pixels");
        }
        if !within(self.alpha_cutoff, 0.05, 0.95) {
            return bad("alpha_cutoff", format!("is {}", self.alpha_cutoff), "use 0.05 to 0.95");
        }
        Ok(())
    }
}

/// The habit of a crystal grown at `temperature_c` and `humidity`; `u` in [0, 1) spreads the growth
/// temperature ±2 °C (a cloud layer is not one temperature), so the mix blends near the borders.
pub fn flake_kind(temperature_c: f32, humidity: f32, u: f32) -> FlakeKind {
    let t = temperature_c + (u - 0.5) * 4.0;
    match t {
        t if t > -4.0 => FlakeKind::Aggregate,
        t if t > -8.0 => FlakeKind::Needle,
        t if t > -12.0 => FlakeKind::Plate,
        // dendrites need supersaturated air; in dry air the plate habit continues
        t if t > -18.0 => {
            if humidity < 0.25 {
                FlakeKind::Plate
            } else {
                FlakeKind::StellarDendrite
            }
        }
        t if t > -25.0 => FlakeKind::SpatialDendrite,
        _ => FlakeKind::Column,
    }
}

/// One atlas cell: its habit and the physical diameter its sprite stands for.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FlakeCell {
    pub index: usize,
    pub kind: FlakeKind,
    pub size_mm: f32,
}

#[derive(Debug, Clone)]
pub struct FlakeAtlas {
    /// Resolved (anti-aliased) and dilated atlas, `columns × rows` cells, row-major from the top-left.
    pub image: Image,
    pub png: Vec<u8>,
    pub columns: u32,
    pub rows: u32,
    pub cell_px: u32,
    pub cells: Vec<FlakeCell>,
}

impl FlakeAtlas {
    /// UV rectangle [u0, v0, u1, v1] of cell `index` (v down).
    pub fn cell_uv(&self, index: usize) -> [f32; 4] {
        let (c, r) = ((index as u32 % self.columns) as f32, (index as u32 / self.columns) as f32);
        let (w, h) = (self.columns as f32, self.rows as f32);
        [c / w, r / h, (c + 1.0) / w, (r + 1.0) / h]
    }

    /// The cell's pixels as their own image.
    pub fn cell_image(&self, index: usize) -> Image {
        let n = self.cell_px;
        let (x0, y0) = ((index as u32 % self.columns) * n, (index as u32 / self.columns) * n);
        let mut pixels = Vec::with_capacity((n * n) as usize);
        for y in 0..n {
            for x in 0..n {
                pixels.push(self.image.pixel(x0 + x, y0 + y).unwrap_or([0.0; 4]));
            }
        }
        Image { width: n, height: n, pixels }
    }
}

const ICE: [f32; 3] = [0.93, 0.96, 1.0];
const ICE_CORE: [f32; 3] = [0.80, 0.87, 0.97];
const ICE_EDGE: [f32; 3] = [0.86, 0.91, 0.99];

fn push_tri(p: &mut Primitive, a: [f32; 3], b: [f32; 3], c: [f32; 3], color: [f32; 3]) {
    let base = p.positions.len() as u32;
    for v in [a, b, c] {
        p.positions.push(v);
        p.normals.push([0.0, 0.0, 1.0]);
        p.colors.push([color[0], color[1], color[2], 1.0]);
    }
    p.indices.extend_from_slice(&[base, base + 1, base + 2]);
}

/// A bar of `width` from `a` to `b` (its width across in the view plane).
fn push_bar(p: &mut Primitive, a: [f32; 3], b: [f32; 3], width: f32, color: [f32; 3]) {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = (dx * dx + dy * dy).sqrt().max(1e-6);
    let (nx, ny) = (-dy / len * width / 2.0, dx / len * width / 2.0);
    let a0 = [a[0] - nx, a[1] - ny, a[2]];
    let a1 = [a[0] + nx, a[1] + ny, a[2]];
    let b0 = [b[0] - nx, b[1] - ny, b[2]];
    let b1 = [b[0] + nx, b[1] + ny, b[2]];
    push_tri(p, a0, b0, b1, color);
    push_tri(p, a0, b1, a1, color);
}

fn push_hexagon(p: &mut Primitive, center: [f32; 3], radius: f32, phase: f32, color: [f32; 3]) {
    for k in 0..6 {
        let a0 = phase + k as f32 * std::f32::consts::FRAC_PI_3;
        let a1 = a0 + std::f32::consts::FRAC_PI_3;
        push_tri(
            p,
            center,
            [center[0] + radius * a0.cos(), center[1] + radius * a0.sin(), center[2]],
            [center[0] + radius * a1.cos(), center[1] + radius * a1.sin(), center[2]],
            color,
        );
    }
}

/// Appends `arm` (built along +x) turned by k·60° for k = 0..6, about the z axis.
fn sixfold(p: &mut Primitive, arm: &Primitive) {
    for k in 0..6 {
        let (s, c) = (k as f32 * std::f32::consts::FRAC_PI_3).sin_cos();
        let base = p.positions.len() as u32;
        for q in &arm.positions {
            p.positions.push([c * q[0] - s * q[1], s * q[0] + c * q[1], q[2]]);
        }
        p.normals.extend_from_slice(&arm.normals);
        p.colors.extend_from_slice(&arm.colors);
        p.indices.extend(arm.indices.iter().map(|i| i + base));
    }
}

/// An arm along +x of length `len` with `branches` pairs of side branches at ±60°, mirror-symmetric
/// about the arm (as real dendrites grow: both sides see the same vapour).
fn dendrite_arm(r: &mut Stream, len: f32, width: f32, branches: usize, z_lift: f32) -> Primitive {
    let mut arm = Primitive::default();
    push_bar(&mut arm, [0.0, 0.0, 0.0], [len, 0.0, z_lift], width, ICE);
    let (s60, c60) = std::f32::consts::FRAC_PI_3.sin_cos();
    for _ in 0..branches {
        let t = r.range([0.3, 0.85]);
        let room = (1.0 - t) * len;
        let blen = room * r.range([0.35, 0.75]);
        let at = [t * len, 0.0, t * z_lift];
        for side in [-1.0f32, 1.0] {
            push_bar(&mut arm, at, [at[0] + c60 * blen, side * s60 * blen, at[2]], width * 0.7, ICE_EDGE);
        }
    }
    arm
}

/// The flake model of `kind` in the x–y plane facing +z, centred on the origin, scaled so its
/// farthest vertex (projected on x–y) is at [`MODEL_RADIUS`]; vertex-coloured, alpha 1.
pub fn flake_model(kind: FlakeKind, r: &mut Stream) -> Primitive {
    let mut p = Primitive { material: Some(0), ..Primitive::default() };
    match kind {
        FlakeKind::Plate => {
            // the hexagon, and on some plates short broad branches growing from its corners
            // (the silhouette varies, not only the shading)
            let body = r.range([0.7, 1.0]);
            push_hexagon(&mut p, [0.0; 3], body, 0.0, ICE_EDGE);
            if body < 0.95 {
                let mut tip = Primitive::default();
                push_bar(&mut tip, [body * 0.8, 0.0, 0.0], [1.0, 0.0, 0.0], body * r.range([0.25, 0.45]), ICE_EDGE);
                sixfold(&mut p, &tip);
            }
            push_hexagon(&mut p, [0.0, 0.0, 0.001], body * r.range([0.45, 0.8]), 0.0, ICE);
            if r.unit() < 0.6 {
                // ridges along the six corners (sectored plate)
                let mut ridge = Primitive::default();
                push_bar(&mut ridge, [0.0, 0.0, 0.002], [0.98 * body, 0.0, 0.002], 0.06, ICE_CORE);
                sixfold(&mut p, &ridge);
            }
            push_hexagon(&mut p, [0.0, 0.0, 0.003], r.range([0.08, 0.2]), 0.0, ICE_CORE);
        }
        FlakeKind::StellarDendrite => {
            let (width, branches) = (r.range([0.07, 0.11]), 2 + r.below(3));
            let arm = dendrite_arm(r, 1.0, width, branches, 0.0);
            sixfold(&mut p, &arm);
            push_hexagon(&mut p, [0.0, 0.0, 0.001], r.range([0.12, 0.25]), 0.0, ICE_CORE);
        }
        FlakeKind::SpatialDendrite => {
            let width = r.range([0.07, 0.1]);
            let branches = 1 + r.below(2);
            let flat = dendrite_arm(r, 1.0, width, branches, 0.0);
            sixfold(&mut p, &flat);
            // a second set of arms between the first, rising out of the plane: seen from above
            // they are shortened by the cosine of their elevation
            let elevation = r.range([0.5, 1.0]);
            let rise = dendrite_arm(r, elevation.cos(), width * 0.9, 1, elevation.sin());
            let mut turned = rise.clone();
            let (s, c) = (std::f32::consts::FRAC_PI_6).sin_cos();
            for q in &mut turned.positions {
                *q = [c * q[0] - s * q[1], s * q[0] + c * q[1], q[2]];
            }
            sixfold(&mut p, &turned);
            push_hexagon(&mut p, [0.0, 0.0, 0.001], 0.15, 0.0, ICE_CORE);
        }
        FlakeKind::Needle => {
            // a main needle and optionally a pair placed point-symmetrically about the centre
            let half_w = r.range([0.06, 0.1]);
            push_needle(&mut p, [0.0, 0.0], 1.0, half_w);
            if r.unit() < 0.6 {
                let dx = r.range([0.2, 0.35]);
                let dy = r.range([-0.2, 0.2]);
                let len = r.range([0.5, 0.75]);
                push_needle(&mut p, [dx, dy], len, half_w * 0.8);
                push_needle(&mut p, [-dx, -dy], len, half_w * 0.8);
            }
        }
        FlakeKind::Column => {
            // a hexagonal prism side-on: a lit middle face between two darker ones, maybe capped
            let half_h = r.range([0.55, 0.8]);
            let half_w = r.range([0.3, 0.45]);
            let f = half_w / 2.0;
            push_rect(&mut p, [-f, -half_h], [f, half_h], 0.001, ICE);
            push_rect(&mut p, [-half_w, -half_h], [-f, half_h], 0.0, ICE_EDGE);
            push_rect(&mut p, [f, -half_h], [half_w, half_h], 0.0, ICE_EDGE);
            if r.unit() < 0.4 {
                let cap_w = half_w * r.range([1.5, 2.0]);
                push_rect(&mut p, [-cap_w, half_h], [cap_w, half_h + 0.08], 0.0, ICE_CORE);
                push_rect(&mut p, [-cap_w, -half_h - 0.08], [cap_w, -half_h], 0.0, ICE_CORE);
            }
        }
        FlakeKind::Aggregate => {
            // several small crystals stuck together at random places and angles
            let parts = 3 + r.below(4);
            for k in 0..parts {
                let kind = if r.unit() < 0.7 { FlakeKind::StellarDendrite } else { FlakeKind::Plate };
                let mut child = r.child(k as u64);
                let part = flake_model(kind, &mut child);
                let scale = r.range([0.35, 0.55]);
                let (s, c) = r.range([0.0, std::f32::consts::TAU]).sin_cos();
                let at = if k == 0 {
                    [0.0, 0.0]
                } else {
                    let (sa, ca) = r.range([0.0, std::f32::consts::TAU]).sin_cos();
                    let d = r.range([0.3, 0.55]);
                    [d * ca, d * sa]
                };
                let base = p.positions.len() as u32;
                for q in &part.positions {
                    let (x, y) = (q[0] * scale, q[1] * scale);
                    p.positions.push([at[0] + c * x - s * y, at[1] + s * x + c * y, q[2] * scale + 0.01 * k as f32]);
                }
                p.normals.extend_from_slice(&part.normals);
                p.colors.extend_from_slice(&part.colors);
                p.indices.extend(part.indices.iter().map(|i| i + base));
            }
        }
    }
    normalise(&mut p);
    p
}

fn push_rect(p: &mut Primitive, min: [f32; 2], max: [f32; 2], z: f32, color: [f32; 3]) {
    push_tri(p, [min[0], min[1], z], [max[0], min[1], z], [max[0], max[1], z], color);
    push_tri(p, [min[0], min[1], z], [max[0], max[1], z], [min[0], max[1], z], color);
}

/// A vertical needle centred at `c`, `len` long from tip to tip, pointed ends.
fn push_needle(p: &mut Primitive, c: [f32; 2], len: f32, half_w: f32) {
    let body = len - 2.0 * half_w;
    push_rect(p, [c[0] - half_w, c[1] - body], [c[0] + half_w, c[1] + body], 0.0, ICE);
    push_tri(
        p,
        [c[0] - half_w, c[1] + body, 0.0],
        [c[0] + half_w, c[1] + body, 0.0],
        [c[0], c[1] + len, 0.0],
        ICE_EDGE,
    );
    push_tri(
        p,
        [c[0] + half_w, c[1] - body, 0.0],
        [c[0] - half_w, c[1] - body, 0.0],
        [c[0], c[1] - len, 0.0],
        ICE_EDGE,
    );
}

/// Centres nothing (every habit is built about the origin) but scales the x–y extent to MODEL_RADIUS.
fn normalise(p: &mut Primitive) {
    let far = p.positions.iter().map(|q| (q[0] * q[0] + q[1] * q[1]).sqrt()).fold(0.0f32, f32::max);
    if far > 0.0 {
        let k = MODEL_RADIUS / far;
        for q in &mut p.positions {
            *q = [q[0] * k, q[1] * k, q[2] * k];
        }
    }
}

/// Bakes `columns × rows` flakes, each cell drawn at [`BAKE_SUPERSAMPLE`]× and resolved (anti-aliased
/// alpha), then the atlas dilated so bilinear filtering and mips do not bleed the background in.
/// Cell k's habit and size come from a stream keyed by (seed, k): any cell is reproducible alone.
pub fn build_atlas(s: &FlakeSettings) -> Result<FlakeAtlas, SnowError> {
    s.check()?;
    let n = s.cell_px;
    let count = (s.columns * s.rows) as usize;
    let materials = [Material { name: "ice".into(), double_sided: true, ..Material::default() }];
    // cells are rendered in parallel, so each render is sequential inside
    let opts = RenderOptions { use_vertex_colors: true, shading: Shading::Unlit, parallel: false };
    let ss = BAKE_SUPERSAMPLE;
    let view = OrthoView {
        origin: [-1.0, 1.0, 1.0],
        right: [1.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        forward: [0.0, 0.0, -1.0],
        pixels_per_metre: (n * ss) as f64 / 2.0,
        width: n * ss,
        height: n * ss,
    };
    let cam = Camera::Ortho(view);
    let rendered: Vec<Result<(Image, FlakeCell), SnowError>> = (0..count)
        .into_par_iter()
        .map(|k| {
            let mut r = Stream::new(&[s.seed, FLAKE_TAG, k as u64]);
            let kind = flake_kind(s.temperature_c, s.humidity, r.unit());
            let [lo, hi] = kind.size_mm();
            let size_mm = r.range([lo, hi]) * (0.6 + 0.8 * s.humidity);
            let model = flake_model(kind, &mut r);
            let mut canvas = cam.canvas([ICE[0], ICE[1], ICE[2], 0.0]).map_err(|e| SnowError::Bake(e.to_string()))?;
            const IDENTITY: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
            let mesh = Mesh { name: String::new(), primitives: vec![model], extras: None };
            render_mesh(&mut canvas, &cam, &IDENTITY, &mesh, &materials, &[], &opts);
            Ok((resolve_supersampled(&Image::from_canvas_owned(canvas), ss), FlakeCell { index: k, kind, size_mm }))
        })
        .collect();
    let mut image = Image::new(n * s.columns, n * s.rows, [ICE[0], ICE[1], ICE[2], 0.0])
        .map_err(|e| SnowError::Bake(e.to_string()))?;
    let mut cells = Vec::with_capacity(count);
    for (k, cell) in rendered.into_iter().enumerate() {
        let (img, info) = cell?;
        image.blit(&img, (k as u32 % s.columns) * n, (k as u32 / s.columns) * n);
        cells.push(info);
    }
    dilate(&mut image, s.alpha_cutoff);
    let png = image.encode_png().map_err(|e| SnowError::Bake(e.to_string()))?;
    Ok(FlakeAtlas { image, png, columns: s.columns, rows: s.rows, cell_px: n, cells })
}
