//! Tree meshes from L-systems: branches as generalized cylinders (Bloomenthal, "Modeling the Mighty
//! Maple", SIGGRAPH 1985) whose consecutive segments share one ring in the bisector plane of the
//! joint, rings carried along a branch by projection (a discrete rotation-minimising frame), leaves
//! as textured quads and `{ }` polygons triangulated by ear clipping (Meisters 1975).
//!
//! The expansion streams straight into the turtle and the turtle into this builder, so memory holds
//! the mesh and the open branches (one per `[` level), never the expanded string. Every piece is
//! filed under its branch level (the `[` nesting it was drawn at): inside each primitive the
//! vertices and triangles are ordered by level, so dropping the finest levels is taking a prefix
//! ([`TreeMesh::up_to_level`]); the ranges are also written to the mesh's extras.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DVec2, DVec3};
use serde::{Deserialize, Serialize};
use serde_json::json;
use thiserror::Error;

use crate::color::srgb_to_linear;
use crate::export::{self, ExportError};
use crate::failure::{Blame, Failure};
use crate::lsystem::expand::{Expander, DEFAULT_MAX_SYMBOLS};
use crate::lsystem::turtle::{Conventions, Frame, Leaf, Limb, Polygon, Segment, Sink, Turtle, TurtleCounts};
use crate::lsystem::{parse, Dialect, LSystem, LsystemError};
use crate::mesh::{AlphaMode, Bounds, CustomAttribute, Material, Mesh, Primitive, PrimitiveMode, Scene, Texture};
use crate::plants::wind::{self, WIND_ATTRIBUTE, WIND_BRANCH_ATTRIBUTE};
use crate::random::mix64;
use crate::validate::{validate_file, ValidateOptions};

pub const DEFAULT_RADIAL_SEGMENTS: u32 = 8;
pub const MAX_RADIAL_SEGMENTS: u32 = 64;
pub const DEFAULT_MAX_SEGMENTS: u64 = 1_000_000;
/// A tree's default triangle budget: its LoD chain costs about its LoD0 triangles (a 262k-triangle
/// bush takes 4.9–6.6 s for the default chain with analysis; one of 2.36 M took 53 s and 3 GB under
/// the former 4 M default), so the default keeps any tree a user did not ask to be large to a few
/// seconds. 2.5× the largest tree of ../shared/data (abop-bush, 119,856); `--max-triangles` /
/// `max_triangles` raise it.
pub const DEFAULT_MAX_TRIANGLES: u64 = 300_000;
/// Key of the branch-level table in the tree mesh's extras.
pub const EXTRAS_KEY: &str = "verdant_tree";
/// Polygons with more vertices than this are fanned instead of ear-clipped (ear clipping is quadratic).
const MAX_EAR_CLIP_VERTICES: usize = 256;
/// Consecutive segments meeting at a sharper angle than this (cosine) do not share a ring.
const MIN_JOINT_COS: f64 = -0.2;

/// How a tree is built.
#[derive(Debug, Clone, PartialEq)]
pub struct TreeOptions {
    /// Seeds stochastic rules and the turtle's random turns (`~`).
    pub seed: u64,
    /// Vertices around each branch ring (3..=64).
    pub radial_segments: u32,
    pub max_symbols: u64,
    pub max_segments: u64,
    pub max_triangles: u64,
    /// Metres of one default step `F` (lparser 4: 100 turtle units; lparser 5 and the thesis: 1).
    pub metres_per_step: f64,
    /// Scale the finished tree to this height in metres (None: keep the step scale).
    pub height_m: Option<f64>,
    /// Thinner branches are drawn with this radius (thinner than a few mm only makes slivers).
    pub min_radius_m: f64,
    /// Radius of a branch tip as a fraction of its last segment's radius.
    pub tip_radius_ratio: f64,
    /// Leaf quads (`L`): length as a fraction of the current step; the width is half the length.
    pub leaf_length_ratio: f64,
    /// Leaves (`L`) as one glTF point each (the point-sprite thesis) instead of textured quads: at
    /// the quad's centre, NORMAL the leaf's normal, COLOR_0 its colour, `_LEAF_SIZE` = (length,
    /// width, 0, 0) in metres for the engine to size the sprite. Polygons stay triangles.
    pub leaf_points: bool,
    /// Name of the mesh and its node.
    pub name: String,
}

impl Default for TreeOptions {
    fn default() -> Self {
        TreeOptions {
            seed: 0,
            radial_segments: DEFAULT_RADIAL_SEGMENTS,
            max_symbols: DEFAULT_MAX_SYMBOLS,
            max_segments: DEFAULT_MAX_SEGMENTS,
            max_triangles: DEFAULT_MAX_TRIANGLES,
            metres_per_step: 1.0,
            height_m: None,
            min_radius_m: 0.002,
            tip_radius_ratio: 0.5,
            leaf_length_ratio: 0.4,
            leaf_points: false,
            name: "tree".into(),
        }
    }
}

#[derive(Debug, Error)]
pub enum TreeError {
    /// Reading or parsing the file (the message carries file:line:column).
    #[error(transparent)]
    Parse(LsystemError),
    #[error("{0}")]
    Expand(LsystemError),
    #[error(
        "the tree draws more than {limit} segments (--max-segments; `max_segments` in a preset's tree); lower the recursion depth or raise the limit"
    )]
    TooManySegments { limit: u64 },
    #[error("the tree needs more than {limit} triangles (--max-triangles; `max_triangles` in a preset's tree); lower the recursion depth or --radial-segments (`radial_segments`), or raise the limit")]
    TooManyTriangles { limit: u64 },
    #[error("the L-system draws nothing (no segment, leaf or polygon with area); check its axiom and rules")]
    Empty,
    #[error("invalid tree options: {0}")]
    Options(String),
    #[error("{path}: {source}")]
    InFile {
        path: PathBuf,
        #[source]
        source: Box<TreeError>,
    },
    #[error(transparent)]
    Export(#[from] ExportError),
    #[error("{path} does not pass validation (this is a bug, please report it with the input file):\n{report}")]
    Invalid { path: PathBuf, report: String },
}

/// The build's for a failed write or an invalid output; the input's otherwise (bad input,
/// options or exceeded limits).
impl Failure for TreeError {
    fn blame(&self) -> Blame {
        match self {
            TreeError::Export(e) => e.blame(),
            TreeError::Invalid { .. } => Blame::Build,
            TreeError::InFile { source, .. } => source.blame(),
            _ => Blame::Input,
        }
    }
}

impl TreeError {
    fn in_file(self, path: &Path) -> TreeError {
        match self {
            TreeError::Parse(_) | TreeError::InFile { .. } | TreeError::Export(_) | TreeError::Invalid { .. } => self,
            e => TreeError::InFile { path: path.to_path_buf(), source: Box::new(e) },
        }
    }
}

/// Where one branch level starts inside a primitive (levels ascending; a level runs to the next
/// level's start or the end of the primitive).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct LevelRanges {
    pub levels: Vec<u32>,
    pub vertex_starts: Vec<u32>,
    pub index_starts: Vec<u32>,
}

/// One drawn segment of the branch skeleton, in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkeletonSegment {
    pub start: [f32; 3],
    pub end: [f32; 3],
    pub radius_m: f32,
    pub level: u32,
    pub color: u16,
}

/// What a build produced, counted.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TreeStats {
    pub symbols: u64,
    pub string_bytes: u64,
    pub segments: u64,
    pub leaves: u64,
    pub polygons: u64,
    /// Polygons with fewer than three distinct vertices or no area (nothing to draw).
    pub polygons_skipped: u64,
    pub triangles: u64,
    pub vertices: u64,
    pub primitives: usize,
    pub max_branch_level: u32,
    /// Triangles that collapsed to zero area in f32 (very thin or short pieces), left out.
    pub degenerate_triangles_dropped: u64,
    pub bounds: Option<Bounds>,
    pub height_m: f64,
}

/// A built tree: a one-mesh scene plus what later stages (LoD) need.
#[derive(Debug, Clone)]
pub struct TreeMesh {
    /// One mesh (index 0) shown by one root node, its materials and the leaf texture.
    pub scene: Scene,
    /// Per primitive of the mesh: where each branch level starts.
    pub levels: Vec<LevelRanges>,
    pub skeleton: Vec<SkeletonSegment>,
    pub stats: TreeStats,
}

impl TreeMesh {
    pub fn mesh(&self) -> &Mesh {
        &self.scene.meshes[0]
    }

    /// The mesh without branch levels finer than `max_level` (a prefix of every primitive's
    /// vertices and triangles; primitives left empty are dropped).
    pub fn up_to_level(&self, max_level: u32) -> Mesh {
        let mesh = self.mesh();
        let mut out = Mesh { name: mesh.name.clone(), primitives: Vec::new(), extras: None };
        for (p, ranges) in mesh.primitives.iter().zip(&self.levels) {
            let keep = ranges.levels.iter().position(|&l| l > max_level).unwrap_or(ranges.levels.len());
            let (v_end, i_end) = match keep {
                k if k == ranges.levels.len() => (p.positions.len(), p.indices.len()),
                k => (ranges.vertex_starts[k] as usize, ranges.index_starts[k] as usize),
            };
            if i_end == 0 && !(p.is_points() && v_end > 0) {
                continue;
            }
            let cut = |n: usize| n.min(v_end);
            let custom = p
                .custom
                .iter()
                .map(|c| CustomAttribute {
                    name: c.name.clone(),
                    values: c.values[..cut(c.values.len())].to_vec(),
                    unit_bytes: c.unit_bytes,
                    range: c.range,
                })
                .collect();
            // every field is set, but Primitive literals end in `..Primitive::default()` (fields get added)
            #[allow(clippy::needless_update)]
            out.primitives.push(Primitive {
                positions: p.positions[..v_end].to_vec(),
                normals: p.normals[..cut(p.normals.len())].to_vec(),
                uvs: p.uvs[..cut(p.uvs.len())].to_vec(),
                tangents: p.tangents[..cut(p.tangents.len())].to_vec(),
                colors: p.colors[..cut(p.colors.len())].to_vec(),
                indices: p.indices[..i_end].to_vec(),
                material: p.material,
                custom,
                mode: p.mode,
                ..Primitive::default()
            });
        }
        out
    }
}

// ---------------------------------------------------------------------------------------------
// colours and the leaf texture

/// lparser's colour table (sRGB 0..1): index 8 is its leaf green, 12 its bark; unset entries grey.
pub fn lparser_color(index: u16) -> [f32; 3] {
    match index {
        2 => [0.8, 0.4, 0.4],
        3 => [0.8, 0.8, 0.4],
        4 => [0.4, 0.8, 0.4],
        5 => [0.4, 0.8, 0.8],
        6 => [0.4, 0.4, 0.8],
        7 => [0.8, 0.4, 0.8],
        8 => [0.2, 0.5, 0.2],
        9 => [0.2, 0.5, 0.5],
        10 => [0.2, 0.2, 0.5],
        11 => [0.5, 0.2, 0.5],
        12 => [0.6, 0.2, 0.2],
        13 => [0.5, 0.5, 0.5],
        14 => [0.75, 0.75, 0.75],
        15 => [1.0, 1.0, 1.0],
        _ => [0.5, 0.5, 0.5],
    }
}

/// A colour index of `system` as a linear RGBA material factor (v5 `color` lines override lparser's table).
pub fn material_color(system: &LSystem, index: u16) -> [f32; 4] {
    let srgb = match system.colors.iter().find(|c| c.index == index) {
        Some(c) => c.rgb.map(|v| v as f32 / 255.0),
        None => lparser_color(index),
    };
    let [r, g, b] = srgb.map(srgb_to_linear);
    [r, g, b, 1.0]
}

/// Width and height of the procedural leaf texture.
pub const LEAF_TEXTURE_SIZE: (u32, u32) = (64, 128);

/// The procedural leaf: a pointed blade with a midrib, side veins and a short stalk, stem at the
/// bottom of the image (v = 1), tip at the top; pale, so the material colour tints it; alpha is the
/// outline (anti-aliased). Deterministic PNG bytes.
pub fn leaf_texture_png() -> Vec<u8> {
    let (w, h) = LEAF_TEXTURE_SIZE;
    let image = image::RgbaImage::from_fn(w, h, |x, y| {
        // t along the leaf: 0 at the stem (bottom), 1 at the tip (top); s across: −1..1
        let t = 1.0 - (y as f64 + 0.5) / h as f64;
        let s = ((x as f64 + 0.5) / w as f64) * 2.0 - 1.0;
        let stalk = 0.12;
        let half_width = if t < stalk {
            0.05
        } else {
            // the tip ends a little below the top edge, so it is pointed even at this resolution
            let u = ((t - stalk) / (0.97 - stalk)).min(1.0);
            0.92 * (std::f64::consts::PI * u.powf(0.75)).sin().max(0.0)
        };
        let pixel = 2.0 / w as f64;
        let coverage = ((half_width - s.abs()) / pixel + 0.5).clamp(0.0, 1.0);
        let midrib = (1.0 - s.abs() / 0.06).max(0.0);
        // side veins: lines rising from the midrib toward the tip
        let vein_phase = (t * 9.0 - s.abs() * 2.5).rem_euclid(1.0);
        let vein = (1.0 - (vein_phase - 0.5).abs() / 0.08).max(0.0) * (s.abs() < half_width * 0.85) as u8 as f64;
        let edge = (1.0 - (half_width - s.abs()) / (4.0 * pixel)).clamp(0.0, 1.0);
        let shade = 0.93 - 0.20 * midrib - 0.12 * vein - 0.10 * edge;
        let v = (shade.clamp(0.0, 1.0) * 255.0).round() as u8;
        image::Rgba([v, v, (v as f64 * 0.92) as u8, (coverage * 255.0).round() as u8])
    });
    let mut png = Vec::new();
    // an in-memory PNG encode of a valid RGBA buffer cannot fail
    image.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).expect("PNG encoding in memory");
    png
}

// ---------------------------------------------------------------------------------------------
// the builder

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    Bark,
    Polygon,
    Leaf,
    /// A leaf as one point (`TreeOptions::leaf_points`).
    LeafPoint,
}

/// Custom attribute of point leaves: (length, width, 0, 0) of the leaf in metres.
pub const LEAF_SIZE_ATTRIBUTE: &str = "_LEAF_SIZE";

/// Vertices and triangles of one (kind, colour, level).
#[derive(Default)]
struct Part {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    uvs: Vec<[f32; 2]>,
    indices: Vec<u32>,
    /// Point leaves only: (length, width, 0, 0) per vertex.
    sizes: Vec<[f32; 4]>,
    /// Per vertex, before the tree's size is known: (arc along its limb in metres, flutter
    /// weight, flutter phase, limb phase); `assemble` turns it into `_WIND` and `_WIND_BRANCH`.
    wind: Vec<[f32; 4]>,
}

impl Part {
    fn vertex(&mut self, p: DVec3, n: DVec3, uv: [f64; 2], wind: [f32; 4]) -> u32 {
        self.wind.push(wind);
        self.positions.push(p.as_vec3().to_array());
        self.normals.push(n.normalize_or(DVec3::Y).as_vec3().normalize_or(glam::Vec3::Y).to_array());
        self.uvs.push([uv[0] as f32, uv[1] as f32]);
        self.positions.len() as u32 - 1
    }
}

/// A branch run whose last segment has no end ring yet.
struct OpenChain {
    kind_color: (Kind, u16),
    level: u32,
    /// First vertex of the last ring emitted (R + 1 vertices).
    ring: u32,
    side: DVec3,
    /// End point, unit direction and radius of the last segment.
    end: DVec3,
    dir: DVec3,
    radius: f64,
    /// Length along the branch at `end`, in units of the first ring's circumference (texture v).
    v_at_end: f64,
    circumference: f64,
    /// The limb and the arc along it at `end`.
    limb: Limb,
}

struct Builder<'a> {
    system: &'a LSystem,
    options: &'a TreeOptions,
    metres_per_unit: f64,
    radial: usize,
    /// `cos`, `sin` of the ring angles (R + 1 entries, the last equal to the first).
    ring_dirs: Vec<(f64, f64)>,
    parts: BTreeMap<(Kind, u16), BTreeMap<u32, Part>>,
    chains: HashMap<u32, OpenChain>,
    skeleton: Vec<SkeletonSegment>,
    triangles: u64,
    segments: u64,
    polygons_skipped: u64,
    /// Leaves and polygons so far: each gets its own flutter phase.
    leaves: u64,
}

impl<'a> Builder<'a> {
    fn new(system: &'a LSystem, options: &'a TreeOptions) -> Self {
        let radial = options.radial_segments as usize;
        let ring_dirs = (0..=radial)
            .map(|j| {
                let a = std::f64::consts::TAU * (j % radial) as f64 / radial as f64;
                (a.cos(), a.sin())
            })
            .collect();
        Builder {
            system,
            options,
            metres_per_unit: options.metres_per_step / Conventions::of(system.dialect).step,
            radial,
            ring_dirs,
            parts: BTreeMap::new(),
            chains: HashMap::new(),
            skeleton: Vec::new(),
            triangles: 0,
            segments: 0,
            polygons_skipped: 0,
            leaves: 0,
        }
    }

    /// Raw wind data of a vertex on `limb` (see [`Part::wind`]): wood does not flutter.
    fn wood(&self, limb: Limb) -> [f32; 4] {
        [(limb.arc * self.metres_per_unit) as f32, 0.0, 0.0, self.limb_phase(limb.id)]
    }

    /// One phase per limb, 0 on the trunk.
    fn limb_phase(&self, id: u32) -> f32 {
        if id == 0 {
            0.0
        } else {
            wind::phase_of(mix64(self.options.seed ^ 0x6c69_6d62) ^ id as u64)
        }
    }

    /// The next leaf's flutter phase.
    fn flutter_phase(&mut self) -> f32 {
        self.leaves += 1;
        wind::phase_of(mix64(self.options.seed ^ 0x666c_7574) ^ self.leaves)
    }

    fn part(&mut self, kind: Kind, color: u16, level: u32) -> &mut Part {
        self.parts.entry((kind, color)).or_default().entry(level).or_default()
    }

    fn add_triangles(&mut self, n: usize) -> Result<(), TreeError> {
        self.triangles += n as u64;
        if self.triangles > self.options.max_triangles {
            return Err(TreeError::TooManyTriangles { limit: self.options.max_triangles });
        }
        Ok(())
    }

    /// Emits a ring of R + 1 vertices (the seam twice, for the texture) around `centre` in the plane
    /// with normal `normal`; `stretch` widens it along `bend` (the elliptical cut of a mitred joint).
    #[allow(clippy::too_many_arguments)]
    fn ring(
        &mut self,
        key: (Kind, u16),
        level: u32,
        limb: Limb,
        centre: DVec3,
        normal: DVec3,
        side: DVec3,
        radius: f64,
        stretch: Option<(DVec3, f64)>,
        v: f64,
    ) -> u32 {
        let t = normal.cross(side);
        let wind = self.wood(limb);
        let dirs = std::mem::take(&mut self.ring_dirs);
        let radial = self.radial as f64;
        let part = self.part(key.0, key.1, level);
        let first = part.positions.len() as u32;
        for (j, &(c, s)) in dirs.iter().enumerate() {
            let mut offset = side * c + t * s;
            if let Some((bend, k)) = stretch {
                offset += bend * (offset.dot(bend) * (k - 1.0));
            }
            part.vertex(centre + offset * radius, offset, [j as f64 / radial, v], wind);
        }
        self.ring_dirs = dirs;
        first
    }

    /// Triangles of the tube between two rings of one part.
    fn tube(&mut self, key: (Kind, u16), level: u32, a: u32, b: u32) -> Result<(), TreeError> {
        let radial = self.radial as u32;
        let part = self.part(key.0, key.1, level);
        for j in 0..radial {
            let (a0, a1, b0, b1) = (a + j, a + j + 1, b + j, b + j + 1);
            part.indices.extend_from_slice(&[a0, a1, b0, a1, b1, b0]);
        }
        self.add_triangles(2 * self.radial)
    }

    /// A flat cap over a ring's circle: `facing` is the cap's outward normal; `centre` its middle.
    #[allow(clippy::too_many_arguments)]
    fn cap(
        &mut self,
        key: (Kind, u16),
        level: u32,
        limb: Limb,
        centre: DVec3,
        facing: DVec3,
        side: DVec3,
        radius: f64,
    ) -> Result<(), TreeError> {
        let t = facing.cross(side);
        let wind = self.wood(limb);
        let dirs = std::mem::take(&mut self.ring_dirs);
        let radial = self.radial;
        let part = self.part(key.0, key.1, level);
        let middle = part.vertex(centre, facing, [0.5, 0.5], wind);
        for &(c, s) in &dirs[..radial] {
            part.vertex(centre + (side * c + t * s) * radius, facing, [0.5 + 0.5 * c, 0.5 - 0.5 * s], wind);
        }
        for j in 0..radial as u32 {
            let (p, q) = (middle + 1 + j, middle + 1 + (j + 1) % radial as u32);
            part.indices.extend_from_slice(&[middle, p, q]);
        }
        self.ring_dirs = dirs;
        self.add_triangles(radial)
    }

    /// Closes an open chain: its last segment ends in a tapered tip ring and a cap.
    fn close_chain(&mut self, chain: OpenChain) -> Result<(), TreeError> {
        let radius = (chain.radius * self.options.tip_radius_ratio).max(self.options.min_radius_m);
        let side = transport(chain.side, chain.dir);
        let tip = self.ring(
            chain.kind_color,
            chain.level,
            chain.limb,
            chain.end,
            chain.dir,
            side,
            radius,
            None,
            chain.v_at_end,
        );
        self.tube(chain.kind_color, chain.level, chain.ring, tip)?;
        self.cap(chain.kind_color, chain.level, chain.limb, chain.end, chain.dir, side, radius)
    }

    fn radius_of(&self, segment: &Segment) -> f64 {
        (segment.diameter * 0.5 * self.metres_per_unit).max(self.options.min_radius_m)
    }
}

/// `side` made perpendicular to the unit `normal` (parallel transport by projection); any
/// perpendicular when it is (nearly) parallel.
fn transport(side: DVec3, normal: DVec3) -> DVec3 {
    let projected = side - normal * side.dot(normal);
    let len = projected.length();
    if len > 1e-6 {
        projected / len
    } else {
        normal.any_orthonormal_vector()
    }
}

impl Sink for Builder<'_> {
    type Error = TreeError;

    fn segment(&mut self, s: &Segment) -> Result<(), TreeError> {
        self.segments += 1;
        if self.segments > self.options.max_segments {
            return Err(TreeError::TooManySegments { limit: self.options.max_segments });
        }
        let (p0, p1) = (s.start * self.metres_per_unit, s.end * self.metres_per_unit);
        let length = p0.distance(p1);
        if length.is_nan() || length <= 1e-9 {
            return Ok(());
        }
        let dir = (p1 - p0) / length;
        let radius = self.radius_of(s);
        // the arc along the limb at the segment's end (the trunk's stays 0, as the turtle's)
        let end_limb = Limb { arc: if s.level > 0 { s.limb.arc + (s.end - s.start).length() } else { 0.0 }, ..s.limb };
        let key = (Kind::Bark, s.color);
        self.skeleton.push(SkeletonSegment {
            start: p0.as_vec3().to_array(),
            end: p1.as_vec3().to_array(),
            radius_m: radius as f32,
            level: s.level,
            color: s.color,
        });
        // continue the chain through a shared ring when it ends here and the bend is not too sharp
        if let Some(mut chain) = self.chains.remove(&s.chain) {
            let joins = s.continues
                && chain.kind_color == key
                && chain.dir.dot(dir) > MIN_JOINT_COS
                && chain.end.distance(p0) <= 1e-9 * (1.0 + p0.length());
            if joins {
                let bisector = (chain.dir + dir).normalize();
                let side = transport(chain.side, bisector);
                // the cut of a cylinder by the bisector plane is an ellipse 1/cos(θ/2) wide along the bend
                let cos_half = bisector.dot(dir).clamp(0.1, 1.0);
                let bend = chain.dir.cross(dir);
                let stretch =
                    (bend.length() > 1e-9).then(|| (bisector.cross(bend.normalize()).normalize(), 1.0 / cos_half));
                let ring = self.ring(key, chain.level, chain.limb, p0, bisector, side, radius, stretch, chain.v_at_end);
                self.tube(key, chain.level, chain.ring, ring)?;
                chain.ring = ring;
                chain.limb = end_limb;
                chain.side = side;
                chain.end = p1;
                chain.dir = dir;
                chain.radius = radius;
                chain.v_at_end += length / chain.circumference;
                self.chains.insert(s.chain, chain);
                return Ok(());
            }
            self.close_chain(chain)?;
        }
        // a new run: base ring (capped underneath) at the start
        let side = transport(s.frame.up, dir);
        let circumference = std::f64::consts::TAU * radius;
        let ring = self.ring(key, s.level, s.limb, p0, dir, side, radius, None, 0.0);
        self.cap(key, s.level, s.limb, p0, -dir, side, radius)?;
        self.chains.insert(
            s.chain,
            OpenChain {
                kind_color: key,
                level: s.level,
                ring,
                side,
                end: p1,
                dir,
                radius,
                v_at_end: length / circumference,
                circumference,
                limb: end_limb,
            },
        );
        Ok(())
    }

    fn chain_end(&mut self, chain: u32) -> Result<(), TreeError> {
        match self.chains.remove(&chain) {
            Some(open) => self.close_chain(open),
            None => Ok(()),
        }
    }

    fn leaf(&mut self, leaf: &Leaf) -> Result<(), TreeError> {
        let length = leaf.length * self.options.leaf_length_ratio * self.metres_per_unit;
        if length.is_nan() || length <= 1e-6 {
            return Ok(());
        }
        let width = length * 0.5;
        let Frame { heading, left, up } = leaf.frame;
        let p = leaf.position * self.metres_per_unit;
        let [arc, _, _, limb_phase] = self.wood(leaf.limb);
        let flutter_phase = self.flutter_phase();
        if self.options.leaf_points {
            // the quad's centre, facing where the quad faces
            let part = self.part(Kind::LeafPoint, leaf.color, leaf.level);
            part.vertex(p + heading * (length / 2.0), up, [0.5, 0.5], [arc, 1.0, flutter_phase, limb_phase]);
            part.sizes.push([length as f32, width as f32, 0.0, 0.0]);
            return Ok(());
        }
        let corners = [
            p - left * (width / 2.0),
            p + left * (width / 2.0),
            p + left * (width / 2.0) + heading * length,
            p - left * (width / 2.0) + heading * length,
        ];
        let uvs = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];
        let part = self.part(Kind::Leaf, leaf.color, leaf.level);
        let first = part.positions.len() as u32;
        for (k, (c, uv)) in corners.iter().zip(uvs).enumerate() {
            // (b − a) × (c − a) = w·ℓ·(L × H) = U: counter-clockwise seen from the up side;
            // the stalk end (corners 0, 1) holds still, the tip (2, 3) flutters
            let flutter = if k >= 2 { 1.0 } else { 0.0 };
            part.vertex(*c, up, uv, [arc, flutter, flutter_phase, limb_phase]);
        }
        part.indices.extend_from_slice(&[first, first + 1, first + 2, first, first + 2, first + 3]);
        self.add_triangles(2)
    }

    fn polygon(&mut self, polygon: &Polygon) -> Result<(), TreeError> {
        let Polygon { vertices, color, level, limb } = *polygon;
        let scale = self.metres_per_unit;
        let mut points: Vec<DVec3> = Vec::with_capacity(vertices.len());
        let extent = vertices.iter().fold(0.0f64, |m, v| m.max(v.abs().max_element())) * scale;
        let eps = 1e-9 * (1.0 + extent);
        for v in vertices {
            let p = *v * scale;
            if points.last().is_none_or(|q| q.distance(p) > eps) {
                points.push(p);
            }
        }
        while points.len() > 1 && points[0].distance(points[points.len() - 1]) <= eps {
            points.pop();
        }
        // Newell's normal: the polygon winds counter-clockwise around it
        let mut normal = DVec3::ZERO;
        for (i, a) in points.iter().enumerate() {
            let b = points[(i + 1) % points.len()];
            normal += DVec3::new((a.y - b.y) * (a.z + b.z), (a.z - b.z) * (a.x + b.x), (a.x - b.x) * (a.y + b.y));
        }
        let area2 = normal.length();
        if points.len() < 3 || area2.is_nan() || area2 <= eps * eps {
            self.polygons_skipped += 1;
            return Ok(());
        }
        let n = normal / area2;
        let u_axis = transport(points[1] - points[0], n);
        let v_axis = n.cross(u_axis);
        let flat: Vec<DVec2> =
            points.iter().map(|p| DVec2::new((*p - points[0]).dot(u_axis), (*p - points[0]).dot(v_axis))).collect();
        let triangles = triangulate(&flat);
        if triangles.is_empty() {
            self.polygons_skipped += 1;
            return Ok(());
        }
        let (lo, hi) =
            flat.iter().fold((DVec2::splat(f64::MAX), DVec2::splat(f64::MIN)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let size = (hi - lo).max(DVec2::splat(1e-12));
        // a polygon leaf is held where it starts (its first vertex, the stalk): flutter grows away from it
        let reach = points.iter().map(|p| p.distance(points[0])).fold(0.0, f64::max).max(1e-12);
        let [arc, _, _, limb_phase] = self.wood(limb);
        let flutter_phase = self.flutter_phase();
        let part = self.part(Kind::Polygon, color, level);
        let first = part.positions.len() as u32;
        for (p, f) in points.iter().zip(&flat) {
            let uv = (*f - lo) / size;
            let flutter = (p.distance(points[0]) / reach) as f32;
            part.vertex(*p, n, [uv.x, 1.0 - uv.y], [arc, flutter, flutter_phase, limb_phase]);
        }
        for t in &triangles {
            part.indices.extend(t.iter().map(|&k| first + k as u32));
        }
        self.add_triangles(triangles.len())
    }
}

/// Twice the signed area of triangle (a, b, c): positive when counter-clockwise.
fn orient(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}

/// Triangulates a simple polygon given counter-clockwise (ear clipping); clockwise input is
/// reversed. Self-intersecting or very large polygons fall back to a fan for what remains.
/// Returns triangles of input indices, counter-clockwise, without zero-area ones.
pub fn triangulate(points: &[DVec2]) -> Vec<[usize; 3]> {
    let n = points.len();
    if n < 3 {
        return Vec::new();
    }
    let area: f64 = (0..n).map(|i| points[i].perp_dot(points[(i + 1) % n])).sum();
    let mut ring: Vec<usize> = if area >= 0.0 { (0..n).collect() } else { (0..n).rev().collect() };
    let scale = points.iter().fold(0.0f64, |m, p| m.max(p.abs().max_element())).max(1e-300);
    let eps = 1e-12 * scale * scale;
    let mut out = Vec::with_capacity(n - 2);
    while ring.len() > 3 && ring.len() <= MAX_EAR_CLIP_VERTICES {
        let m = ring.len();
        let mut clipped = false;
        for i in 0..m {
            let (ia, ib, ic) = (ring[(i + m - 1) % m], ring[i], ring[(i + 1) % m]);
            let (a, b, c) = (points[ia], points[ib], points[ic]);
            let o = orient(a, b, c);
            if o.abs() <= eps {
                // a collinear (or doubled) vertex adds nothing: drop it
                ring.remove(i);
                clipped = true;
                break;
            }
            if o < 0.0 {
                continue; // reflex
            }
            let blocked = ring.iter().any(|&k| {
                if k == ia || k == ib || k == ic {
                    return false;
                }
                let p = points[k];
                orient(a, b, p) >= -eps && orient(b, c, p) >= -eps && orient(c, a, p) >= -eps
            });
            if !blocked {
                out.push([ia, ib, ic]);
                ring.remove(i);
                clipped = true;
                break;
            }
        }
        if !clipped {
            break; // no ear: not a simple polygon; fan the rest
        }
    }
    for k in 1..ring.len().saturating_sub(1) {
        let t = [ring[0], ring[k], ring[k + 1]];
        if orient(points[t[0]], points[t[1]], points[t[2]]) > eps {
            out.push(t);
        }
    }
    out
}

/// Zero area as the validator judges it: the cross product is negligible against the squared
/// longest edge, computed in f64 from the f32 positions as written.
pub(crate) fn is_flat(p: &[[f32; 3]], t: [u32; 3]) -> bool {
    let [a, b, c] = t.map(|i| DVec3::from(p[i as usize].map(f64::from)));
    let scale = (b - a).length_squared().max((c - a).length_squared()).max((c - b).length_squared());
    let cross = (b - a).cross(c - a).length();
    cross.is_nan() || cross <= 1e-12 * scale || t[0] == t[1] || t[1] == t[2] || t[0] == t[2]
}

/// Builds the tree of `system`.
pub fn build_tree(system: &LSystem, options: &TreeOptions) -> Result<TreeMesh, TreeError> {
    check_options(options)?;
    let mut expander = Expander::new(system, options.seed, options.max_symbols).map_err(TreeError::Expand)?;
    let mut turtle = Turtle::new(system, options.seed);
    let mut builder = Builder::new(system, options);
    while let Some(token) = expander.next_token().map_err(TreeError::Expand)? {
        turtle.feed(token, &mut builder)?;
    }
    turtle.finish(&mut builder)?;
    let counts = expander.counts();
    assemble(builder, turtle.counts(), counts.symbols, counts.string_bytes)
}

fn check_options(o: &TreeOptions) -> Result<(), TreeError> {
    let bad = |m: String| Err(TreeError::Options(m));
    if !(3..=MAX_RADIAL_SEGMENTS).contains(&o.radial_segments) {
        return bad(format!("--radial-segments {} is out of range; use 3 to {MAX_RADIAL_SEGMENTS}", o.radial_segments));
    }
    if !(o.metres_per_step.is_finite() && o.metres_per_step > 0.0) {
        return bad(format!("the step length {} m must be a positive number", o.metres_per_step));
    }
    if let Some(h) = o.height_m {
        if !(h.is_finite() && h > 0.0) {
            return bad(format!("--height {h} must be a positive number of metres"));
        }
    }
    for (name, v) in [
        ("minimum radius", o.min_radius_m),
        ("tip radius ratio", o.tip_radius_ratio),
        ("leaf length ratio", o.leaf_length_ratio),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return bad(format!("the {name} {v} must be a positive number"));
        }
    }
    Ok(())
}

/// Orders every primitive's pieces by branch level, drops f32-degenerate triangles, makes the
/// materials and the scene.
fn assemble(
    mut builder: Builder,
    turtle: TurtleCounts,
    symbols: u64,
    string_bytes: u64,
) -> Result<TreeMesh, TreeError> {
    let mut chains: Vec<(u32, OpenChain)> = builder.chains.drain().collect();
    chains.sort_by_key(|(id, _)| *id);
    for (_, chain) in chains {
        builder.close_chain(chain)?;
    }
    // a uniform scale to the requested height (radii, lengths and positions alike)
    let (lo, hi) = builder
        .parts
        .values()
        .flat_map(|levels| levels.values())
        .flat_map(|p| &p.positions)
        .fold((f64::MAX, f64::MIN), |(lo, hi), p| (lo.min(p[1] as f64), hi.max(p[1] as f64)));
    let scale = match builder.options.height_m {
        Some(h) if hi > lo => h / (hi - lo),
        _ => 1.0,
    };
    let system = builder.system;
    let options = builder.options;
    // wind: the bend runs from the ground (the root, or the lowest point when all is above it) to
    // the top; branch weights from the trunk to the farthest tip along any limb
    let ground = ((if (lo..=hi).contains(&0.0) { 0.0 } else { lo }) * scale) as f32;
    let top = (hi * scale) as f32;
    let longest_arc = builder
        .parts
        .values()
        .flat_map(|levels| levels.values())
        .flat_map(|p| &p.wind)
        .fold(0.0f64, |m, w| m.max(w[0] as f64))
        * scale;
    let sway_hz = wind::tree_sway_frequency_hz(((hi - lo) * scale).max(0.0));
    let mut scene = Scene { name: options.name.clone(), ..Scene::default() };
    let mut mesh = Mesh { name: options.name.clone(), primitives: Vec::new(), extras: None };
    let mut all_levels = Vec::new();
    let mut dropped = 0u64;
    let mut leaf_texture = None;
    let (mut bark_texture, mut polygon_texture) = (None, None);
    for ((kind, color), levels) in std::mem::take(&mut builder.parts) {
        let points = kind == Kind::LeafPoint;
        let mut prim = Primitive {
            mode: if points { PrimitiveMode::Points } else { PrimitiveMode::Triangles },
            ..Primitive::default()
        };
        let mut sizes = Vec::new();
        let mut raw_wind: Vec<[f32; 4]> = Vec::new();
        let mut ranges = LevelRanges::default();
        for (level, mut part) in levels {
            if scale != 1.0 {
                for p in &mut part.positions {
                    *p = p.map(|x| (x as f64 * scale) as f32);
                }
                for s in &mut part.sizes {
                    *s = s.map(|x| (x as f64 * scale) as f32);
                }
            }
            let base = prim.positions.len() as u32;
            let index_start = prim.indices.len() as u32;
            if points {
                if part.positions.is_empty() {
                    continue;
                }
                ranges.levels.push(level);
                ranges.vertex_starts.push(base);
                ranges.index_starts.push(index_start);
                prim.positions.extend(part.positions);
                prim.normals.extend(part.normals);
                sizes.extend(part.sizes);
                raw_wind.extend(part.wind);
                continue;
            }
            for t in part.indices.chunks_exact(3) {
                let t = [t[0], t[1], t[2]];
                if is_flat(&part.positions, t) {
                    dropped += 1;
                } else {
                    prim.indices.extend(t.iter().map(|i| base + i));
                }
            }
            if prim.indices.len() as u32 == index_start {
                continue;
            }
            ranges.levels.push(level);
            ranges.vertex_starts.push(base);
            ranges.index_starts.push(index_start);
            prim.positions.extend(part.positions);
            prim.normals.extend(part.normals);
            prim.uvs.extend(part.uvs);
            raw_wind.extend(part.wind);
        }
        if prim.indices.is_empty() && (!points || prim.positions.is_empty()) {
            continue;
        }
        let base_color = material_color(system, color);
        if points {
            prim.colors = vec![base_color; prim.positions.len()];
            prim.custom = vec![CustomAttribute {
                name: LEAF_SIZE_ATTRIBUTE.into(),
                values: sizes,
                unit_bytes: false,
                range: None,
            }];
        }
        let span = top - ground;
        let sway = prim
            .positions
            .iter()
            .map(|p| [if span > 0.0 { wind::bend_weight((p[1] - ground) / span) } else { 0.0 }, 0.0, sway_hz, 0.0])
            .collect();
        let branch = raw_wind
            .iter()
            .map(|&[arc, flutter, flutter_phase, limb_phase]| {
                let w =
                    if longest_arc > 0.0 { wind::bend_weight((arc as f64 * scale / longest_arc) as f32) } else { 0.0 };
                [w, limb_phase, flutter, flutter_phase]
            })
            .collect();
        prim.custom.push(CustomAttribute {
            name: WIND_ATTRIBUTE.into(),
            values: sway,
            unit_bytes: false,
            range: Some(wind::WIND_RANGE),
        });
        prim.custom.push(CustomAttribute {
            name: WIND_BRANCH_ATTRIBUTE.into(),
            values: branch,
            unit_bytes: false,
            range: Some(wind::WIND_BRANCH_RANGE),
        });
        let (name, material) = match kind {
            Kind::Bark => {
                let texture = *bark_texture.get_or_insert_with(|| {
                    scene
                        .textures
                        .push(Texture { name: "bark".into(), png: crate::plants::texture::bark_texture_png() });
                    scene.textures.len() - 1
                });
                (
                    format!("bark_c{color}"),
                    Material { base_color, base_color_texture: Some(texture), roughness: 0.9, ..Material::default() },
                )
            }
            Kind::Polygon => {
                let texture = *polygon_texture.get_or_insert_with(|| {
                    scene.textures.push(Texture {
                        name: "leaf_surface".into(),
                        png: crate::plants::texture::polygon_leaf_texture_png(),
                    });
                    scene.textures.len() - 1
                });
                let m = Material {
                    base_color,
                    base_color_texture: Some(texture),
                    roughness: 0.7,
                    double_sided: true,
                    ..Material::default()
                };
                (format!("leaf_polygon_c{color}"), m)
            }
            Kind::Leaf => {
                let texture = *leaf_texture.get_or_insert_with(|| {
                    scene.textures.push(Texture { name: "leaf".into(), png: leaf_texture_png() });
                    scene.textures.len() - 1
                });
                let m = Material {
                    base_color,
                    base_color_texture: Some(texture),
                    roughness: 0.7,
                    alpha_mode: AlphaMode::Mask { cutoff: 0.5 },
                    double_sided: true,
                    ..Material::default()
                };
                (format!("leaf_c{color}"), m)
            }
            // the colour rides on COLOR_0 (per point, as the sprite shader reads it); no texture:
            // points have no texture coordinates
            Kind::LeafPoint => (
                format!("leaf_points_c{color}"),
                Material { roughness: 0.7, double_sided: true, ..Material::default() },
            ),
        };
        scene.materials.push(Material { name, ..material });
        prim.material = Some(scene.materials.len() - 1);
        mesh.primitives.push(prim);
        all_levels.push(ranges);
    }
    let triangles: u64 = mesh.primitives.iter().map(|p| p.triangle_count() as u64).sum();
    if triangles == 0 && mesh.point_count() == 0 {
        return Err(TreeError::Empty);
    }
    let mut skeleton = std::mem::take(&mut builder.skeleton);
    if scale != 1.0 {
        for s in &mut skeleton {
            s.start = s.start.map(|x| (x as f64 * scale) as f32);
            s.end = s.end.map(|x| (x as f64 * scale) as f32);
            s.radius_m = (s.radius_m as f64 * scale) as f32;
        }
    }
    let corners: Vec<[f32; 3]> =
        mesh.primitives.iter().filter_map(|p| p.bounds()).flat_map(|b| [b.min, b.max]).collect();
    let bounds = Bounds::of(&corners);
    let max_branch_level = all_levels.iter().flat_map(|r| r.levels.iter().copied()).max().unwrap_or(0);
    mesh.extras = Some(json!({ EXTRAS_KEY: { "max_branch_level": max_branch_level, "branch_levels": all_levels } }));
    let stats = TreeStats {
        symbols,
        string_bytes,
        segments: turtle.segments,
        leaves: turtle.leaves,
        polygons: turtle.polygons,
        polygons_skipped: turtle.polygons_skipped + builder.polygons_skipped,
        triangles,
        vertices: mesh.vertex_count() as u64,
        primitives: mesh.primitives.len(),
        max_branch_level,
        degenerate_triangles_dropped: dropped,
        bounds,
        height_m: bounds.map_or(0.0, |b| (b.max[1] - b.min[1]) as f64),
    };
    scene.add_mesh_node(mesh);
    Ok(TreeMesh { scene, levels: all_levels, skeleton, stats })
}

// ---------------------------------------------------------------------------------------------
// the `verdant tree` job

/// One `verdant tree` run: read, build, write, validate.
#[derive(Debug, Clone)]
pub struct TreeJob {
    pub input: PathBuf,
    pub output: PathBuf,
    /// None: detect the dialect.
    pub dialect: Option<Dialect>,
    pub options: TreeOptions,
    /// How a glTF output stores vertex data (16-bit grid per mesh, meshopt compression).
    pub compact: crate::export::quantize::Compact,
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct TreeSeconds {
    pub parse: f64,
    /// Expansion, turtle and mesh (the expansion streams through both).
    pub build: f64,
    pub export: f64,
    /// Parse + build + export: the time to the LoD0 file.
    pub to_lod0: f64,
    pub validate: f64,
    pub total: f64,
}

/// What `verdant tree --report` writes.
#[derive(Debug, Clone, Serialize)]
pub struct TreeReport {
    pub input: String,
    pub output: String,
    pub files: Vec<String>,
    pub dialect: Dialect,
    pub dialect_detected: bool,
    pub seed: u64,
    pub radial_segments: u32,
    #[serde(flatten)]
    pub stats: TreeStats,
    pub warnings: Vec<String>,
    pub validation_errors: usize,
    pub validation_warnings: usize,
    pub seconds: TreeSeconds,
}

/// Heights outside this range (m) at the L-system's own scale are reported: no real plant is
/// taller than 120 m, and a tree under 5 cm is a scale mistake (lparser 4 files at 1 cm per step).
pub const PLAUSIBLE_HEIGHT_M: [f64; 2] = [0.05, 120.0];

/// A warning when a tree left at its L-system's own scale (no `--height`) came out at an
/// implausible size: fern-plant.ls grows 732 m tall at 1 m per step.
pub fn size_warning(stats: &TreeStats, options: &TreeOptions) -> Option<String> {
    let h = stats.height_m;
    if options.height_m.is_some() || (PLAUSIBLE_HEIGHT_M[0]..=PLAUSIBLE_HEIGHT_M[1]).contains(&h) {
        return None;
    }
    Some(format!(
        "the tree is {h:.3} m tall at the L-system's own scale ({} m per step), outside {}–{} m: pass --height METRES (e.g. --height 12; `height` in a preset's tree) to scale it, or --step",
        options.metres_per_step, PLAUSIBLE_HEIGHT_M[0], PLAUSIBLE_HEIGHT_M[1]
    ))
}

/// Parses, builds and writes the tree of `job`, then re-reads and validates the file.
pub fn run(job: &TreeJob) -> Result<TreeReport, TreeError> {
    run_reporting(job, None)
}

/// [`run`], and the report as JSON to `report_path` when given: the tree's files are written and
/// validated in a hidden folder beside the output (a .gltf or .obj is checked with the .bin or .mtl
/// it names), then moved in together with the report, so a failure leaves the previous files and
/// report as they were.
pub fn run_reporting(job: &TreeJob, report_path: Option<&Path>) -> Result<TreeReport, TreeError> {
    let t0 = Instant::now();
    let obj = job.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    if obj && job.options.leaf_points {
        return Err(TreeError::Options(format!(
            "{}: OBJ cannot carry point leaves (glTF POINTS); write .glb or .gltf, or drop --point-leaves",
            job.output.display()
        )));
    }
    let parsed = parse::read_file(&job.input, job.dialect).map_err(TreeError::Parse)?;
    let t_parse = t0.elapsed().as_secs_f64();
    let tree = build_tree(&parsed.system, &job.options).map_err(|e| e.in_file(&job.input))?;
    let t_build = t0.elapsed().as_secs_f64();
    export::check_output_path(&job.output)?;
    let mut set = export::FileSet::new();
    let folder = set.folder_beside(&job.output)?;
    let file_name = job.output.file_name().unwrap_or_default();
    if job.compact != crate::export::quantize::Compact::None && obj {
        return Err(TreeError::Options(format!(
            "{}: --quantize and --compress store glTF integer positions (KHR_mesh_quantization), which an .obj cannot hold; write .glb or .gltf, or leave them out",
            job.output.display()
        )));
    }
    let staged = export::write_scene_with(&tree.scene, &folder.join(file_name), &job.compact.write_options())?;
    let t_export = t0.elapsed().as_secs_f64();
    let validation = validate_file(&folder.join(file_name), &ValidateOptions::default())
        .map_err(|e| TreeError::Invalid { path: job.output.clone(), report: e.to_string() })?;
    if !validation.ok() {
        return Err(TreeError::Invalid { path: job.output.clone(), report: validation.to_string() });
    }
    let mut files = Vec::with_capacity(staged.len());
    for file in staged {
        let target = job.output.with_file_name(file.file_name().unwrap_or_default());
        files.push(target.clone());
        set.adopt(file, target);
    }
    let t_total = t0.elapsed().as_secs_f64();
    let report = TreeReport {
        input: job.input.display().to_string(),
        output: job.output.display().to_string(),
        files: files.iter().map(|f| f.display().to_string()).collect(),
        dialect: parsed.system.dialect,
        dialect_detected: parsed.detected,
        seed: job.options.seed,
        radial_segments: job.options.radial_segments,
        warnings: parsed.warnings.into_iter().chain(size_warning(&tree.stats, &job.options)).collect(),
        stats: tree.stats,
        validation_errors: validation.errors(),
        validation_warnings: validation.warnings(),
        seconds: TreeSeconds {
            parse: t_parse,
            build: t_build - t_parse,
            export: t_export - t_build,
            to_lod0: t_export,
            validate: t_total - t_export,
            total: t_total,
        },
    };
    if let Some(path) = report_path {
        set.write(path, &report_json(&report)?)?;
    }
    set.commit()?;
    Ok(report)
}

/// A report as pretty JSON.
fn report_json(report: &TreeReport) -> Result<Vec<u8>, TreeError> {
    let mut text = serde_json::to_string_pretty(report)
        .map_err(|e| TreeError::Options(format!("cannot serialise the report: {e}")))?;
    text.push('\n');
    Ok(text.into_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lsystem::parse::parse_bytes;

    fn system(text: &str) -> LSystem {
        parse_bytes(text.as_bytes(), Path::new("t.ls"), None).unwrap().system
    }

    #[test]
    fn straight_branch_shares_rings_and_is_closed() {
        // three segments in one run: 4 rings (base, 2 joints, tip) and 2 caps, no duplicated ring
        let s = system("recursion 0\nangle 30\nthickness 10\naxiom FFF\n");
        let o = TreeOptions { radial_segments: 6, ..TreeOptions::default() };
        let tree = build_tree(&s, &o).unwrap();
        let p = &tree.mesh().primitives[0];
        assert_eq!(p.positions.len(), 4 * 7 + 2 * 7);
        assert_eq!(p.triangle_count(), 3 * 12 + 2 * 6);
        // closed surface: every edge is used by exactly two triangles, once in each direction
        let key = |v: [f32; 3]| v.map(|x| (x * 1e4).round() as i64);
        let mut edges: BTreeMap<([i64; 3], [i64; 3]), i32> = BTreeMap::new();
        for t in p.indices.chunks_exact(3) {
            for k in 0..3 {
                let (a, b) = (key(p.positions[t[k] as usize]), key(p.positions[t[(k + 1) % 3] as usize]));
                *edges.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { -1 };
            }
        }
        assert!(edges.values().all(|&d| d == 0), "open or inconsistently wound surface");
        assert_eq!(tree.stats.height_m, 3.0);
    }

    #[test]
    fn ear_clipping_handles_concave_polygons() {
        // an L shape (concave at (1, 1)): 4 triangles, total area 3, all counter-clockwise
        let pts =
            [(0.0, 0.0), (2.0, 0.0), (2.0, 1.0), (1.0, 1.0), (1.0, 2.0), (0.0, 2.0)].map(|(x, y)| DVec2::new(x, y));
        let tris = triangulate(&pts);
        assert_eq!(tris.len(), 4);
        let area: f64 = tris.iter().map(|t| orient(pts[t[0]], pts[t[1]], pts[t[2]]) / 2.0).sum();
        assert!((area - 3.0).abs() < 1e-12);
        assert!(tris.iter().all(|t| orient(pts[t[0]], pts[t[1]], pts[t[2]]) > 0.0));
        let mut cw = pts;
        cw.reverse();
        assert_eq!(triangulate(&cw).len(), 4);
    }

    #[test]
    fn leaf_texture_is_a_leaf_shape() {
        let png = leaf_texture_png();
        let img = image::load_from_memory(&png).unwrap().to_rgba8();
        assert_eq!(img.dimensions(), LEAF_TEXTURE_SIZE);
        let (w, h) = LEAF_TEXTURE_SIZE;
        assert_eq!(img.get_pixel(w / 2, h / 2)[3], 255, "opaque in the middle");
        assert_eq!(img.get_pixel(0, h / 2)[3], 0, "transparent at the side");
        assert_eq!(img.get_pixel(w / 2, 0)[3], 0, "pointed tip");
        assert_eq!(png, leaf_texture_png(), "deterministic");
    }
}
