//! Grass clumps and their levels of detail, after the grass LoD thesis (blades as strips of ~5
//! quads grouped in clumps of several density levels, wind parameters per blade in vertex colours)
//! and the real-time grass thesis (a clump as 4 vertical slices + 1 horizontal billboard, textures
//! baked from the full clump, alpha test without sorting).
//!
//! A clump is a square cell of side `clump_size_m` centred on the origin, roots on y = 0. Every
//! blade stays inside the cell (root, bend and width), so a clump rotated by 0/90/180/270° tiles
//! seamlessly with its neighbours. Randomness is keyed by (seed, density level, variant, blade).
//!
//! Levels of detail of one clump:
//! - LoD0: each blade a strip of `segments` quads bending along its facing direction, tapering to a
//!   point (the last segment is a triangle): 2·segments − 1 triangles per blade;
//! - LoD1: each blade one quad from root to tip, the taper drawn by the blade texture's alpha;
//! - LoD2: the real-time grass thesis' clump: 4 vertical slices (two facing ±z, two facing ±x, each
//!   showing the blades rooted in its half of the cell) + 1 horizontal card, textured from the atlas;
//! - LoD3: one horizontal card with the top view.
//!
//! Far field: two crossed vertical billboards `far_cells` clumps wide, covering far_cells² cells.

use serde::Serialize;

use crate::math::{cross3_f32, normalize3_f32_or_up};
use crate::mesh::{CustomAttribute, Primitive};
use crate::random::Stream;

pub use crate::plants::wind::WIND_ATTRIBUTE;
/// Largest blade sway frequency a preset may ask for (Hz).
pub const WIND_MAX_FREQUENCY_HZ: f32 = crate::plants::wind::MAX_FREQUENCY_HZ;
/// Limits that keep one clump a reasonable asset (and the generator's memory bounded).
pub const MAX_BLADES_PER_CLUMP: usize = 4096;
pub const MAX_SEGMENTS: usize = 32;
pub const MAX_DENSITY_LEVELS: usize = 8;
pub const MAX_VARIANTS: usize = 8;
/// Colour variants (columns) in the procedural blade texture.
pub const BLADE_TEXTURE_COLUMNS: usize = 8;

/// How one grass species looks. Lengths in metres, angles in radians, colours linear RGB.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GrassSettings {
    /// Blades in the densest clump; level k of `density_levels` has (k+1)/levels of them.
    pub blades_per_clump: usize,
    /// Side of the square clump cell.
    pub clump_size_m: f32,
    /// Quads per blade at LoD0.
    pub segments: usize,
    pub height_m: [f32; 2],
    pub width_m: [f32; 2],
    /// Total bend of a blade from root to tip.
    pub bend_rad: [f32; 2],
    pub density_levels: usize,
    pub variants: usize,
    /// Wind sway frequency range (Hz) and stiffness range (0 limp … 1 rigid).
    pub wind_frequency_hz: [f32; 2],
    pub stiffness: [f32; 2],
    pub root_color: [f32; 3],
    pub tip_color: [f32; 3],
    /// Per-blade colour jitter: hue shift (fraction of the green–yellow range) and value (±).
    pub hue_jitter: f32,
    pub value_jitter: f32,
    /// Alpha test threshold of every grass material (the real-time grass thesis: 180–200/255).
    pub alpha_cutoff: f32,
    /// Pixels per atlas view (a slice or the top view is this wide).
    pub atlas_px: u32,
    /// Clumps per side of a far-field billboard.
    pub far_cells: usize,
    pub seed: u64,
    /// A blade image (PNG, alpha = blade shape) used instead of the procedural blade texture.
    pub blade_texture: Option<std::path::PathBuf>,
}

impl Default for GrassSettings {
    fn default() -> Self {
        GrassSettings {
            blades_per_clump: 48,
            clump_size_m: 0.5,
            segments: 5,
            height_m: [0.25, 0.5],
            width_m: [0.008, 0.016],
            bend_rad: [0.15, 0.9],
            density_levels: 3,
            variants: 2,
            wind_frequency_hz: [0.8, 1.8],
            stiffness: [0.3, 0.8],
            root_color: [0.045, 0.12, 0.012],
            tip_color: [0.30, 0.50, 0.07],
            hue_jitter: 0.25,
            value_jitter: 0.15,
            alpha_cutoff: 0.75,
            atlas_px: 256,
            far_cells: 3,
            seed: 0,
            blade_texture: None,
        }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("grass setting `{key}` {problem}; {remedy}")]
pub struct GrassError {
    pub key: &'static str,
    pub problem: String,
    pub remedy: String,
}

fn bad(key: &'static str, problem: impl Into<String>, remedy: impl Into<String>) -> Result<(), GrassError> {
    Err(GrassError { key, problem: problem.into(), remedy: remedy.into() })
}

impl GrassSettings {
    /// Blades in a clump of density level `level` (0 = sparsest).
    pub fn blades_in_level(&self, level: usize) -> usize {
        (self.blades_per_clump * (level + 1)).div_ceil(self.density_levels.max(1))
    }

    /// Checks every setting; the generator relies on these bounds.
    pub fn check(&self) -> Result<(), GrassError> {
        let range_ok = |r: [f32; 2], lo: f32, hi: f32| {
            r[0].is_finite() && r[1].is_finite() && lo <= r[0] && r[0] <= r[1] && r[1] <= hi
        };
        if !(1..=MAX_DENSITY_LEVELS).contains(&self.density_levels) {
            return bad(
                "density_levels",
                format!("is {}", self.density_levels),
                format!("use 1 to {MAX_DENSITY_LEVELS}"),
            );
        }
        if !(1..=MAX_VARIANTS).contains(&self.variants) {
            return bad("variants", format!("is {}", self.variants), format!("use 1 to {MAX_VARIANTS}"));
        }
        if self.blades_per_clump > MAX_BLADES_PER_CLUMP {
            return bad(
                "blades_per_clump",
                format!("is {}", self.blades_per_clump),
                format!("use at most {MAX_BLADES_PER_CLUMP}"),
            );
        }
        // LoD1 (2 triangles a blade) must stay coarser than LoD0 and finer than LoD2 (10 triangles)
        if self.blades_in_level(0) < 6 {
            return bad(
                "blades_per_clump",
                format!(
                    "gives {} blades in the sparsest of {} density levels",
                    self.blades_in_level(0),
                    self.density_levels
                ),
                format!("use at least {} blades (6 per level) or fewer density_levels", 6 * self.density_levels),
            );
        }
        if !(1..=MAX_SEGMENTS).contains(&self.segments) {
            return bad(
                "segments",
                format!("is {}", self.segments),
                format!("use 1 to {MAX_SEGMENTS} (2–5 is typical)"),
            );
        }
        if self.segments < 2 {
            return bad("segments", "is 1: a blade of one segment is already LoD1", "use 2 or more (default 5)");
        }
        if !(self.clump_size_m.is_finite() && (0.01..=100.0).contains(&self.clump_size_m)) {
            return bad("clump_size", format!("is {} m", self.clump_size_m), "use 0.01 to 100 m (0.5 is typical)");
        }
        if !range_ok(self.height_m, 1e-3, 100.0) {
            return bad(
                "height",
                format!("is {:?} m", self.height_m),
                "give [min, max] with 0.001 ≤ min ≤ max ≤ 100 m",
            );
        }
        if !range_ok(self.width_m, 1e-4, self.clump_size_m / 2.0) {
            return bad(
                "width",
                format!("is {:?} m", self.width_m),
                format!(
                    "give [min, max] with 0.0001 ≤ min ≤ max ≤ half the clump size ({} m)",
                    self.clump_size_m / 2.0
                ),
            );
        }
        if !range_ok(self.bend_rad, 0.0, 1.5) {
            return bad(
                "bend",
                format!("is {:?} rad", self.bend_rad),
                "give [min, max] radians within 0 ≤ min ≤ max ≤ 1.5 (degrees ≈ rad × 57.3)",
            );
        }
        if !range_ok(self.wind_frequency_hz, 0.0, WIND_MAX_FREQUENCY_HZ) {
            return bad(
                "wind_frequency",
                format!("is {:?} Hz", self.wind_frequency_hz),
                format!("give [min, max] within 0..{WIND_MAX_FREQUENCY_HZ} Hz"),
            );
        }
        if !range_ok(self.stiffness, 0.0, 1.0) {
            return bad("stiffness", format!("is {:?}", self.stiffness), "give [min, max] within 0..1");
        }
        let colour_ok = |c: [f32; 3]| c.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x));
        if !colour_ok(self.root_color) || !colour_ok(self.tip_color) {
            return bad("root_color/tip_color", "has a channel outside 0..1", "give linear RGB in 0..1");
        }
        if !(self.hue_jitter.is_finite()
            && (0.0..=1.0).contains(&self.hue_jitter)
            && self.value_jitter.is_finite()
            && (0.0..=0.5).contains(&self.value_jitter))
        {
            return bad("hue_jitter/value_jitter", "is out of range", "use hue_jitter 0..1 and value_jitter 0..0.5");
        }
        if !(self.alpha_cutoff.is_finite() && (0.05..=0.95).contains(&self.alpha_cutoff)) {
            return bad(
                "alpha_cutoff",
                format!("is {}", self.alpha_cutoff),
                "use 0.05 to 0.95 (0.75 ≈ 190/255 is typical)",
            );
        }
        if !(16..=4096).contains(&self.atlas_px) {
            return bad("atlas_px", format!("is {}", self.atlas_px), "use 16 to 4096 pixels per view");
        }
        if !(1..=8).contains(&self.far_cells) {
            return bad("far_cells", format!("is {}", self.far_cells), "use 1 to 8 clumps per far billboard side");
        }
        Ok(())
    }

    /// Tallest a blade can reach (its length; bending only lowers it).
    pub fn max_height_m(&self) -> f32 {
        self.height_m[1]
    }
}

/// One blade: a ribbon rooted at `root` (y = 0), bending towards `facing` (a horizontal unit
/// vector, also its face normal at the root).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Blade {
    pub root: [f32; 2],
    pub facing: [f32; 2],
    pub length_m: f32,
    pub width_m: f32,
    pub bend_rad: f32,
    /// Wind: phase (0..1 of a cycle), frequency (Hz), stiffness (0..1).
    pub phase: f32,
    pub frequency_hz: f32,
    pub stiffness: f32,
    /// Colour variant: column of the blade texture.
    pub column: usize,
    /// Random rank in (0, 1): the blade is shown while 1 − rank ≥ an engine's (1 − density) cutoff.
    pub rank: f32,
}

impl Blade {
    /// Centreline points from root (k = 0) to tip (k = segments): each segment keeps length
    /// length/segments and turns by the bend so far (θ(t) = bend·t², t at the segment's middle).
    pub fn centreline(&self, segments: usize) -> Vec<[f32; 3]> {
        let step = self.length_m / segments as f32;
        let mut p = [self.root[0], 0.0, self.root[1]];
        let mut pts = Vec::with_capacity(segments + 1);
        pts.push(p);
        for k in 0..segments {
            let t = (k as f32 + 0.5) / segments as f32;
            let theta = self.bend_rad * t * t;
            let (s, c) = theta.sin_cos();
            p = [p[0] + step * s * self.facing[0], p[1] + step * c, p[2] + step * s * self.facing[1]];
            pts.push(p);
        }
        pts
    }

    /// Half-width at fraction t of the length: full at the root, tapering to 0 at the tip.
    pub fn half_width(&self, t: f32) -> f32 {
        0.5 * self.width_m * taper(t)
    }
}

/// Width profile of a blade (1 at the root, 0 at the tip); the blade texture's alpha has the same
/// shape, slightly wider, so one-quad blades (LoD1) show the same silhouette.
pub fn taper(t: f32) -> f32 {
    (1.0 - t.clamp(0.0, 1.0)).powf(0.6)
}

/// Share of a texture column's width the LoD0 strip uses at its root (the texture's alpha shape is
/// the full column width: the margin keeps filtered edges inside the opaque part).
pub const STRIP_IN_COLUMN: f32 = 0.9;

/// One clump: the blades of a (density level, variant) pair.
#[derive(Debug, Clone, PartialEq)]
pub struct Clump {
    pub level: usize,
    pub variant: usize,
    pub size_m: f32,
    pub blades: Vec<Blade>,
}

/// The blades of clump (`level`, `variant`).
pub fn clump(settings: &GrassSettings, level: usize, variant: usize) -> Clump {
    let n = settings.blades_in_level(level);
    let half = settings.clump_size_m / 2.0;
    let stream = Stream::new(&[settings.seed, 0x0067_7261_7373, level as u64, variant as u64]);
    let mut blades = Vec::with_capacity(n);
    for b in 0..n {
        let mut r = stream.child(b as u64);
        let length_m = r.range(settings.height_m);
        let width_m = r.range(settings.width_m);
        let yaw = r.unit() * std::f32::consts::TAU;
        let facing = [yaw.cos(), yaw.sin()];
        let mut bend_rad = r.range(settings.bend_rad);
        // the tip's horizontal reach; bend less if it could not fit in the cell at all
        let reach = |bend: f32| {
            let blade = Blade {
                root: [0.0; 2],
                facing,
                length_m,
                width_m,
                bend_rad: bend,
                phase: 0.0,
                frequency_hz: 0.0,
                stiffness: 0.0,
                column: 0,
                rank: 0.0,
            };
            let tip = blade.centreline(settings.segments)[settings.segments];
            (tip[0], tip[2])
        };
        let margin = width_m / 2.0;
        while bend_rad > 0.0 {
            let (dx, dz) = reach(bend_rad);
            if dx.abs() + 2.0 * margin < settings.clump_size_m * 0.8
                && dz.abs() + 2.0 * margin < settings.clump_size_m * 0.8
            {
                break;
            }
            bend_rad *= 0.8;
            if bend_rad < 1e-3 {
                bend_rad = 0.0;
            }
        }
        let (dx, dz) = reach(bend_rad);
        // root uniformly where the whole blade (root, tip, half-width either side) stays inside
        let span = |d: f32| {
            let lo = -half + margin + (-d).max(0.0);
            let hi = half - margin - d.max(0.0);
            (lo, hi.max(lo))
        };
        let (x0, x1) = span(dx);
        let (z0, z1) = span(dz);
        let root = [r.range([x0, x1]), r.range([z0, z1])];
        blades.push(Blade {
            root,
            facing,
            length_m,
            width_m,
            bend_rad,
            phase: r.unit(),
            frequency_hz: r.range(settings.wind_frequency_hz),
            stiffness: r.range(settings.stiffness),
            column: r.below(BLADE_TEXTURE_COLUMNS),
            rank: (b as f32 + 0.5) / n as f32, // shuffled below
        });
    }
    // ranks: a random permutation of (i + ½)/n, so a density cutoff keeps an even share
    let mut order: Vec<(u64, usize)> = (0..n).map(|i| (stream.child(1 << 40 | i as u64).next_u64(), i)).collect();
    order.sort_unstable();
    for (rank_index, &(_, i)) in order.iter().enumerate() {
        blades[i].rank = (rank_index as f32 + 0.5) / n as f32;
    }
    Clump { level, variant, size_m: settings.clump_size_m, blades }
}

/// Wind data of one vertex in `_WIND` (plants::wind): bend weight, phase in radians, frequency in
/// Hz, stiffness. No COLOR_0: the blade's colour is its texture's.
fn push_wind(p: &mut Primitive, blade: &Blade, height_fraction: f32) {
    let weight = crate::plants::wind::bend_weight(height_fraction);
    if let Some(w) = p.custom.first_mut() {
        w.values.push([weight, blade.phase * std::f32::consts::TAU, blade.frequency_hz, blade.stiffness]);
    }
}

fn wind_primitive(material: usize) -> Primitive {
    Primitive {
        material: Some(material),
        custom: vec![CustomAttribute {
            name: WIND_ATTRIBUTE.into(),
            values: Vec::new(),
            unit_bytes: false,
            range: Some(crate::plants::wind::WIND_RANGE),
        }],
        ..Primitive::default()
    }
}

/// u range of a blade texture column (the column's full width), for a centre offset in −1..1.
fn column_u(column: usize, across: f32) -> f32 {
    (column as f32 + 0.5 + 0.5 * across) / BLADE_TEXTURE_COLUMNS as f32
}

/// LoD0: full blades. `material` is the blade material (blade texture, MASK, double-sided).
pub fn lod0(settings: &GrassSettings, clump: &Clump, material: usize) -> Primitive {
    lod0_filtered(settings, clump, material, |_| true)
}

/// LoD0 of the blades `keep` accepts (the baker draws one slab of the clump at a time).
pub fn lod0_filtered(
    settings: &GrassSettings,
    clump: &Clump,
    material: usize,
    keep: impl Fn(&Blade) -> bool,
) -> Primitive {
    let n = settings.segments;
    let mut p = wind_primitive(material);
    for blade in clump.blades.iter().filter(|b| keep(b)) {
        let pts = blade.centreline(n);
        let side = [-blade.facing[1], 0.0, blade.facing[0]]; // horizontal, across the blade
        let base = p.positions.len() as u32;
        for (k, c) in pts.iter().enumerate() {
            let t = k as f32 / n as f32;
            // tangent by central differences along the centreline
            let (a, b) = (pts[k.saturating_sub(1)], pts[(k + 1).min(n)]);
            let tangent = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let normal = normalize3_f32_or_up(cross3_f32(side, tangent));
            let hw = blade.half_width(t);
            let v = 1.0 - t; // glTF v runs down from the image top: tip at the top
            if k < n {
                for s in [-1.0f32, 1.0] {
                    p.positions.push([c[0] + s * hw * side[0], c[1], c[2] + s * hw * side[2]]);
                    p.normals.push(normal);
                    p.uvs.push([column_u(blade.column, s * STRIP_IN_COLUMN * taper(t)), v]);
                    push_wind(&mut p, blade, c[1] / settings.max_height_m());
                }
            } else {
                p.positions.push(*c);
                p.normals.push(normal);
                p.uvs.push([column_u(blade.column, 0.0), v]);
                push_wind(&mut p, blade, c[1] / settings.max_height_m());
            }
        }
        // rows k (2 vertices: left, right); the last row is the tip vertex
        for k in 0..n as u32 {
            let (l0, r0) = (base + 2 * k, base + 2 * k + 1);
            if (k as usize) < n - 1 {
                let (l1, r1) = (l0 + 2, r0 + 2);
                p.indices.extend_from_slice(&[l0, r0, r1, l0, r1, l1]);
            } else {
                p.indices.extend_from_slice(&[l0, r0, l0 + 2]);
            }
        }
    }
    p
}

/// LoD1: one quad per blade from root to tip, full width; the texture's alpha draws the taper.
pub fn lod1(settings: &GrassSettings, clump: &Clump, material: usize) -> Primitive {
    let mut p = wind_primitive(material);
    for blade in &clump.blades {
        let pts = blade.centreline(settings.segments);
        let (root, tip) = (pts[0], pts[settings.segments]);
        let side = [-blade.facing[1], 0.0, blade.facing[0]];
        let axis = [tip[0] - root[0], tip[1] - root[1], tip[2] - root[2]];
        let normal = normalize3_f32_or_up(cross3_f32(side, axis));
        let hw = blade.width_m / 2.0;
        let base = p.positions.len() as u32;
        for (c, v, s) in [(root, 1.0, -1.0f32), (root, 1.0, 1.0), (tip, 0.0, 1.0), (tip, 0.0, -1.0)] {
            p.positions.push([c[0] + s * hw * side[0], c[1], c[2] + s * hw * side[2]]);
            p.normals.push(normal);
            p.uvs.push([column_u(blade.column, s), v]);
            push_wind(&mut p, blade, c[1] / settings.max_height_m());
        }
        p.indices.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    p
}

/// A rectangle of the atlas in glTF uv (v down from the top): `[u0, v0, u1, v1]`.
pub type UvRect = [f32; 4];

/// The four vertical slices of the LoD2 clump and the views the baker renders for them: slice i
/// shows the blades whose root lies in its half of the cell, seen along `-normal` (from the side
/// the normal points to).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slice {
    /// Unit normal of the slice plane (horizontal).
    pub normal: [f32; 3],
    /// Offset of the plane from the clump centre along the normal's axis (±size/4).
    pub offset_m: f32,
}

/// Slices in atlas order: the two planes facing +z (at z = −s/4 and +s/4), then the two facing +x.
pub fn slices(size_m: f32) -> [Slice; 4] {
    let q = size_m / 4.0;
    [
        Slice { normal: [0.0, 0.0, 1.0], offset_m: -q },
        Slice { normal: [0.0, 0.0, 1.0], offset_m: q },
        Slice { normal: [1.0, 0.0, 0.0], offset_m: -q },
        Slice { normal: [1.0, 0.0, 0.0], offset_m: q },
    ]
}

impl Slice {
    /// Does this slice's slab hold the blade (by its root)?
    pub fn holds(&self, blade: &Blade) -> bool {
        let along = if self.normal[2] != 0.0 { blade.root[1] } else { blade.root[0] };
        (along < 0.0) == (self.offset_m < 0.0)
    }

    /// The slice's image axes: `right` (u grows along it) and the plane's fixed coordinate.
    pub fn right(&self) -> [f32; 3] {
        // seen from +normal: right = up × normal … for +z: +x; for +x: −z
        if self.normal[2] != 0.0 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 0.0, -1.0]
        }
    }
}

/// Height of the LoD2/LoD3 horizontal card, as a fraction of the tallest blade: about where the
/// top view's blade mass sits.
pub const HORIZONTAL_CARD_HEIGHT: f32 = 0.45;

/// Pushes a textured quad with wind data: corners counter-clockwise seen from `normal`'s side,
/// uvs per corner, wind weight from each corner's height.
fn push_card(
    p: &mut Primitive,
    settings: &GrassSettings,
    corners: [[f32; 3]; 4],
    uvs: [[f32; 2]; 4],
    normal: [f32; 3],
    phase: f32,
) {
    let base = p.positions.len() as u32;
    let card = Blade {
        root: [0.0; 2],
        facing: [0.0, 1.0],
        length_m: 0.0,
        width_m: 0.0,
        bend_rad: 0.0,
        phase,
        frequency_hz: 0.5 * (settings.wind_frequency_hz[0] + settings.wind_frequency_hz[1]),
        stiffness: 0.5 * (settings.stiffness[0] + settings.stiffness[1]),
        column: 0,
        rank: 0.0,
    };
    let tangent = crate::mesh::quad_tangent(corners, uvs, normal);
    for k in 0..4 {
        p.positions.push(corners[k]);
        p.normals.push(normal);
        p.uvs.push(uvs[k]);
        p.tangents.push(tangent);
        push_wind(p, &card, corners[k][1] / settings.max_height_m());
    }
    p.indices.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
}

/// A vertical card through `centre` facing `normal` (horizontal), `width` wide, from y = 0 to
/// `height`, showing atlas rect `rect` (its left edge at −right).
#[allow(clippy::too_many_arguments)] // plain numbers of one card; a struct would only rename them
fn push_vertical(
    p: &mut Primitive,
    settings: &GrassSettings,
    centre: [f32; 3],
    normal: [f32; 3],
    width: f32,
    height: f32,
    rect: UvRect,
    phase: f32,
) {
    let right = [normal[2], 0.0, -normal[0]]; // up × normal
    let h = width / 2.0;
    let at = |s: f32, y: f32| [centre[0] + s * h * right[0], y, centre[2] + s * h * right[2]];
    let [u0, v0, u1, v1] = rect;
    push_card(
        p,
        settings,
        [at(-1.0, 0.0), at(1.0, 0.0), at(1.0, height), at(-1.0, height)],
        [[u0, v1], [u1, v1], [u1, v0], [u0, v0]],
        normal,
        phase,
    );
}

/// A horizontal card over the clump cell at height `y`, showing the top view `rect` (x to the
/// right, z down the image, as the baker's top-down view).
fn push_horizontal(p: &mut Primitive, settings: &GrassSettings, size: f32, y: f32, rect: UvRect) {
    let h = size / 2.0;
    let [u0, v0, u1, v1] = rect;
    // counter-clockwise seen from above: (−,+z), (+,+z), (+,−z), (−,−z)
    push_card(
        p,
        settings,
        [[-h, y, h], [h, y, h], [h, y, -h], [-h, y, -h]],
        [[u0, v1], [u1, v1], [u1, v0], [u0, v0]],
        [0.0, 1.0, 0.0],
        0.0,
    );
}

/// LoD2: 4 vertical slices + 1 horizontal card; `slice_rects` in [`slices`] order, `top_rect` the
/// top view. `material` uses the clump atlas.
pub fn lod2(
    settings: &GrassSettings,
    clump: &Clump,
    slice_rects: &[UvRect; 4],
    top_rect: UvRect,
    material: usize,
) -> Primitive {
    let mut p = wind_primitive(material);
    let s = clump.size_m;
    let height = settings.max_height_m();
    for (i, (slice, rect)) in slices(s).iter().zip(slice_rects).enumerate() {
        let n = slice.normal;
        let centre = [n[0] * slice.offset_m, 0.0, n[2] * slice.offset_m];
        push_vertical(&mut p, settings, centre, n, s, height, *rect, i as f32 / 4.0);
    }
    push_horizontal(&mut p, settings, s, HORIZONTAL_CARD_HEIGHT * height, top_rect);
    p
}

/// LoD3: the top view on one horizontal card.
pub fn lod3(settings: &GrassSettings, clump: &Clump, top_rect: UvRect, material: usize) -> Primitive {
    let mut p = wind_primitive(material);
    push_horizontal(&mut p, settings, clump.size_m, HORIZONTAL_CARD_HEIGHT * settings.max_height_m(), top_rect);
    p
}

/// Far field: two crossed vertical billboards `far_cells` clumps wide through the centre of a
/// far_cells × far_cells block of clumps, both showing `rect` (the block seen from the front).
pub fn far_field(settings: &GrassSettings, rect: UvRect, material: usize) -> Primitive {
    let mut p = wind_primitive(material);
    let w = settings.far_cells as f32 * settings.clump_size_m;
    let h = settings.max_height_m();
    push_vertical(&mut p, settings, [0.0; 3], [0.0, 0.0, 1.0], w, h, rect, 0.0);
    push_vertical(&mut p, settings, [0.0; 3], [1.0, 0.0, 0.0], w, h, rect, 0.5);
    p
}

/// The far-field block: clump (level = densest, variant and quarter-turn by hash) at each cell of
/// a far_cells² block centred on the origin, as (clump variant, quarter turns, centre x, z).
pub fn far_block(settings: &GrassSettings) -> Vec<(usize, u32, [f32; 2])> {
    let k = settings.far_cells;
    let s = settings.clump_size_m;
    let mut r = Stream::new(&[settings.seed, 0x0066_6172]);
    let mut cells = Vec::with_capacity(k * k);
    for j in 0..k {
        for i in 0..k {
            let centre = [(i as f32 + 0.5 - k as f32 / 2.0) * s, (j as f32 + 0.5 - k as f32 / 2.0) * s];
            cells.push((r.below(settings.variants), r.below(4) as u32, centre));
        }
    }
    cells
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> GrassSettings {
        GrassSettings::default()
    }

    #[test]
    fn defaults_are_valid_and_bad_settings_are_named() {
        settings().check().unwrap();
        let e = GrassSettings { segments: 0, ..settings() }.check().unwrap_err();
        assert_eq!(e.key, "segments");
        let e = GrassSettings { blades_per_clump: 8, density_levels: 3, ..settings() }.check().unwrap_err();
        assert_eq!(e.key, "blades_per_clump");
        assert!(e.to_string().contains("18"), "{e}");
        let e = GrassSettings { height_m: [0.5, 0.2], ..settings() }.check().unwrap_err();
        assert_eq!(e.key, "height");
        let e = GrassSettings { alpha_cutoff: f32::NAN, ..settings() }.check().unwrap_err();
        assert_eq!(e.key, "alpha_cutoff");
    }

    #[test]
    fn blades_stay_inside_the_cell_so_rotated_clumps_tile() {
        let s = GrassSettings { bend_rad: [1.2, 1.5], width_m: [0.02, 0.04], ..settings() };
        for level in 0..s.density_levels {
            for variant in 0..s.variants {
                let c = clump(&s, level, variant);
                assert_eq!(c.blades.len(), s.blades_in_level(level));
                let p = lod0(&s, &c, 0);
                let half = s.clump_size_m / 2.0;
                for v in &p.positions {
                    assert!(v[0].abs() <= half + 1e-6 && v[2].abs() <= half + 1e-6, "{v:?} outside ±{half}");
                    assert!(v[1] >= 0.0 && v[1] <= s.max_height_m() + 1e-6);
                }
            }
        }
    }

    #[test]
    fn lod0_blades_have_the_documented_shape_and_wind() {
        let s = settings();
        let c = clump(&s, s.density_levels - 1, 0);
        let p = lod0(&s, &c, 0);
        let n = c.blades.len();
        assert_eq!(p.triangle_count(), n * (2 * s.segments - 1));
        assert_eq!(p.positions.len(), n * (2 * s.segments + 1));
        // COLOR_0 would multiply the blade's colour and alpha: the wind data is in _WIND only
        assert!(p.colors.is_empty());
        assert_eq!(p.custom[0].name, WIND_ATTRIBUTE);
        assert_eq!(p.custom[0].values.len(), p.positions.len());
        for (i, wind) in p.custom[0].values.iter().enumerate() {
            let y = p.positions[i][1];
            // bend weight: 0 at the root, rising with height, 1 only at the tallest possible tip
            assert!((wind[0] - (y / s.max_height_m()).powi(2)).abs() < 1e-6);
            assert!((0.0..std::f32::consts::TAU).contains(&wind[1]), "phase {}", wind[1]);
            assert!((s.wind_frequency_hz[0]..=s.wind_frequency_hz[1]).contains(&wind[2]));
            assert!((s.stiffness[0]..=s.stiffness[1]).contains(&wind[3]));
        }
        for (k, v) in p.normals.iter().enumerate() {
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            assert!((l - 1.0).abs() < 1e-5, "normal {k} {v:?}");
        }
        // each blade keeps its length: the centreline's segments sum to it
        for b in &c.blades {
            let pts = b.centreline(s.segments);
            let len: f32 = pts
                .windows(2)
                .map(|w| {
                    ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2) + (w[1][2] - w[0][2]).powi(2)).sqrt()
                })
                .sum();
            assert!((len - b.length_m).abs() < 1e-5);
        }
    }

    #[test]
    fn lod_triangle_counts_strictly_decrease() {
        let s = settings();
        for level in 0..s.density_levels {
            let c = clump(&s, level, 0);
            let r = [0.0, 0.0, 0.25, 0.5];
            let counts = [
                lod0(&s, &c, 0).triangle_count(),
                lod1(&s, &c, 0).triangle_count(),
                lod2(&s, &c, &[r; 4], r, 0).triangle_count(),
                lod3(&s, &c, r, 0).triangle_count(),
            ];
            assert!(counts.windows(2).all(|w| w[0] > w[1]), "level {level}: {counts:?}");
        }
    }

    #[test]
    fn clumps_are_deterministic_and_variants_differ() {
        let s = settings();
        assert_eq!(clump(&s, 1, 0), clump(&s, 1, 0));
        assert_ne!(clump(&s, 1, 0).blades, clump(&s, 1, 1).blades);
        let other_seed = GrassSettings { seed: 9, ..settings() };
        assert_ne!(clump(&s, 1, 0).blades, clump(&other_seed, 1, 0).blades);
    }

    #[test]
    fn ranks_are_a_permutation_and_slabs_split_the_blades() {
        let s = settings();
        let c = clump(&s, 2, 1);
        let mut ranks: Vec<f32> = c.blades.iter().map(|b| b.rank).collect();
        ranks.sort_by(f32::total_cmp);
        for (i, r) in ranks.iter().enumerate() {
            assert!((r - (i as f32 + 0.5) / ranks.len() as f32).abs() < 1e-6);
        }
        let sl = slices(s.clump_size_m);
        for pair in [[0, 1], [2, 3]] {
            let a = c.blades.iter().filter(|b| sl[pair[0]].holds(b)).count();
            let b = c.blades.iter().filter(|b| sl[pair[1]].holds(b)).count();
            assert_eq!(a + b, c.blades.len());
        }
    }
}
