//! The 3-D turtle that interprets an expanded L-system (ABOP §1.5, "turtle interpretation"), with
//! lparser's command table (Lapré; the same rotations as the point-sprite thesis' table 1, §3.3).
//!
//! The turtle's frame (heading H, left L, up U) is kept orthonormal: every turn is an exact plane
//! rotation of two of the vectors followed by Gram–Schmidt, and turns by multiples of 90° use exact
//! sines and cosines (so `+(90)` four times gives back the same bits). `$` and tropism stay defined
//! when the heading is vertical. Lengths and thicknesses are clamped, so no NaN or infinity ever
//! leaves the turtle.
//!
//! Coordinates: lparser's turtle starts heading up its +Z "sky"; verdant turns that world to glTF's
//! +Y up by a rotation (not lparser's y/z swap, which mirrors), so the start frame is H = +Y,
//! L = −Z, U = +X and the sky is +Y. The frame keeps lparser's orientation, U = L × H.

use glam::DVec3;

use super::expand::Token;
use super::system::{Dialect, LSystem};
use crate::random::mix64;

/// The turtle's "up in the world": `$` levels the left vector against it, tropism pulls away from it.
pub const SKY: DVec3 = DVec3::Y;

/// Largest |step length| in turtle units (lengths are clamped to it, so positions stay finite).
pub const MAX_STEP: f64 = 1e6;
/// Largest thickness (diameter as a multiple of the segment length).
pub const MAX_THICKNESS: f64 = 1e3;
/// Most vertices one polygon `{ … }` records; later ones are counted in
/// [`TurtleCounts::polygon_vertices_dropped`].
pub const MAX_POLYGON_VERTICES: usize = 1 << 16;
/// Most vertices all open polygons hold together (braces need not balance within a rule, so
/// without this a file could open polygons in proportion to its expanded length).
pub const MAX_OPEN_POLYGON_VERTICES: usize = 1 << 20;
/// Most polygons open at once; a `{` beyond it, and its `}`, are ignored and counted in
/// [`TurtleCounts::polygons_skipped`].
pub const MAX_OPEN_POLYGONS: usize = 1 << 12;
/// lparser's default tropism amount (`t` without an argument).
pub const DEFAULT_TROPISM: f64 = 0.2;
/// The largest random turn of `~` without an argument, in degrees.
pub const DEFAULT_RANDOM_TURN_DEG: f64 = 6.0;

const RANDOM_SALT: u64 = 0x7475_7274_6c65_0002;

/// Sine and cosine of an angle in degrees; exact for multiples of 90°.
pub fn sin_cos_deg(deg: f64) -> (f64, f64) {
    let r = deg.rem_euclid(360.0);
    if r == 0.0 {
        (0.0, 1.0)
    } else if r == 90.0 {
        (1.0, 0.0)
    } else if r == 180.0 {
        (0.0, -1.0)
    } else if r == 270.0 {
        (-1.0, 0.0)
    } else {
        r.to_radians().sin_cos()
    }
}

/// Whether a turn by `deg` only permutes and negates vectors (no rounding, no renormalising).
fn is_quarter_turn(deg: f64) -> bool {
    deg.rem_euclid(90.0) == 0.0
}

/// The turtle's orientation: heading, left and up, orthonormal, with U = L × H.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    pub heading: DVec3,
    pub left: DVec3,
    pub up: DVec3,
}

impl Frame {
    /// lparser's start frame turned to +Y up: heading +Y, left −Z, up +X.
    pub const START: Frame = Frame { heading: DVec3::Y, left: DVec3::NEG_Z, up: DVec3::X };

    /// `+`: turn about up, the heading toward left (lparser: rotation by −a about U).
    pub fn turn(&mut self, deg: f64) {
        let (s, c) = sin_cos_deg(deg);
        let (h, l) = (self.heading, self.left);
        self.heading = h * c + l * s;
        self.left = l * c - h * s;
        self.settle(deg);
    }

    /// `&`: pitch about left, the heading toward up (lparser: rotation by +a about L).
    pub fn pitch(&mut self, deg: f64) {
        let (s, c) = sin_cos_deg(deg);
        let (h, u) = (self.heading, self.up);
        self.heading = h * c + u * s;
        self.up = u * c - h * s;
        self.settle(deg);
    }

    /// `>`: roll about the heading, left toward −up (lparser: rotation by +a about H).
    pub fn roll(&mut self, deg: f64) {
        let (s, c) = sin_cos_deg(deg);
        let (l, u) = (self.left, self.up);
        self.left = l * c - u * s;
        self.up = u * c + l * s;
        self.settle(deg);
    }

    /// `$`: roll about the heading until left is horizontal and up points skyward. With a vertical
    /// heading every left vector is already horizontal: the frame is kept.
    pub fn roll_to_horizontal(&mut self) {
        let left = self.heading.cross(SKY);
        let len = left.length();
        if len < 1e-9 {
            return;
        }
        self.left = left / len;
        // U = L × H = S − (S·H)H: the sky's part across the heading, never below the horizon
        self.up = self.left.cross(self.heading);
        self.reorthonormalize();
    }

    /// Tropism (ABOP §2.3): rotates the frame about H × T by `amount`·|H × T| radians, bending the
    /// heading toward `toward`. Continuous and a no-op when the heading is parallel to `toward`.
    pub fn bend(&mut self, toward: DVec3, amount: f64) {
        let axis = self.heading.cross(toward);
        let len = axis.length();
        if len < 1e-12 || !amount.is_finite() {
            return;
        }
        let k = axis / len;
        let (s, c) = (amount * len).sin_cos();
        let rotate = |v: DVec3| v * c + k.cross(v) * s + k * k.dot(v) * (1.0 - c);
        self.heading = rotate(self.heading);
        self.left = rotate(self.left);
        self.up = rotate(self.up);
        self.reorthonormalize();
    }

    /// Gram–Schmidt after a rotation that is not a quarter turn.
    fn settle(&mut self, deg: f64) {
        if !is_quarter_turn(deg) {
            self.reorthonormalize();
        }
    }

    /// Makes the frame exactly orthonormal again (up to rounding), keeping the heading's direction.
    pub fn reorthonormalize(&mut self) {
        let h = self.heading.normalize_or_zero();
        if h == DVec3::ZERO {
            *self = Frame::START;
            return;
        }
        let mut l = self.left - h * self.left.dot(h);
        let len = l.length();
        l = if len > 1e-6 { l / len } else { h.any_orthonormal_vector() };
        self.heading = h;
        self.left = l;
        self.up = l.cross(h);
    }

    /// Largest deviation from an orthonormal frame with U = L × H: unit lengths, zero dot products.
    pub fn orthonormality_error(&self) -> f64 {
        let (h, l, u) = (self.heading, self.left, self.up);
        [
            (h.length() - 1.0).abs(),
            (l.length() - 1.0).abs(),
            (u.length() - 1.0).abs(),
            h.dot(l).abs(),
            h.dot(u).abs(),
            l.dot(u).abs(),
            (l.cross(h) - u).length(),
        ]
        .into_iter()
        .fold(0.0, f64::max)
    }
}

/// The per-dialect meaning of the commands (docs/lsystems.md has them as a table).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Conventions {
    /// Length of `F` in turtle units (lparser 4: 100, lparser 5 and the thesis: 1).
    pub step: f64,
    /// Factors of `"`, `'`, `;`, `:`, `?`, `!` without an argument.
    pub length_up: f64,
    pub length_down: f64,
    pub angle_up: f64,
    pub angle_down: f64,
    pub thickness_up: f64,
    pub thickness_down: f64,
    /// `L` draws a leaf (the thesis); in lparser files `L` is an ordinary (rule) symbol.
    pub leaf_command: bool,
    /// The thesis turns 180° about its heading with `|` and about its up with `%` (its table 1:
    /// "180° about Y" — the heading — and "about Z by 180°"); lparser the other way round.
    pub bar_rolls: bool,
    /// `{` records the turtle's position as the polygon's first vertex (lparser 4) or not (lparser 5).
    pub polygon_starts_at_turtle: bool,
    /// Colour index at the start (lparser: 2) and of thesis leaves.
    pub start_color: u16,
    pub leaf_color: u16,
    /// The diameter is the thickness times the current segment length, so `"` thickens too
    /// (lparser); or times the dialect's step, independent of the length (the thesis keeps length
    /// and thickness as separate turtle attributes, its §3.3).
    pub thickness_follows_length: bool,
}

impl Conventions {
    pub fn of(dialect: Dialect) -> Conventions {
        let lparser = Conventions {
            step: 1.0,
            length_up: 1.0 / 0.9,
            length_down: 0.9,
            angle_up: 1.0 / 0.9,
            angle_down: 0.9,
            thickness_up: 1.0 / 0.7,
            thickness_down: 0.7,
            leaf_command: false,
            bar_rolls: false,
            polygon_starts_at_turtle: false,
            start_color: 2,
            leaf_color: 8,
            thickness_follows_length: true,
        };
        match dialect {
            Dialect::LparserV4 => Conventions { step: 100.0, polygon_starts_at_turtle: true, ..lparser },
            Dialect::LparserV5 => lparser,
            Dialect::Stochastic => Conventions {
                length_up: 1.1,
                angle_up: 1.1,
                thickness_up: 1.3,
                leaf_command: true,
                bar_rolls: true,
                polygon_starts_at_turtle: true,
                start_color: 12,
                thickness_follows_length: false,
                ..lparser
            },
        }
    }
}

/// A drawn segment (`F` or `Z`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// The run of segments this one belongs to: a branch drawn without moving, popping or changing
    /// colour in between. Runs end with [`Sink::chain_end`].
    pub chain: u32,
    /// It starts where the previous segment of its chain ended.
    pub continues: bool,
    pub start: DVec3,
    pub end: DVec3,
    /// The turtle's frame while drawing it (the heading points from start to end for positive lengths).
    pub frame: Frame,
    /// Diameter in turtle units: |length| × thickness (lparser) or step × thickness (the thesis),
    /// at least the minimum thickness.
    pub diameter: f64,
    pub color: u16,
    /// Branch level: the `[` nesting depth it was drawn at (0 for the trunk).
    pub level: u32,
    /// Where it lies along its limb: see [`Limb`] (`arc` at the segment's start).
    pub limb: Limb,
}

/// Where a drawn piece lies on the tree: which limb (everything grown from one branch off the
/// trunk, twigs included) and how far along it the turtle has travelled from the trunk, in turtle
/// units. On the trunk (level 0) both are 0; limbs are numbered from 1 in the order they start.
/// Wind data uses it: branch bending grows with the arc, and one limb sways with one phase.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Limb {
    pub id: u32,
    pub arc: f64,
}

/// A closed polygon `{ … }`: its recorded vertices and where it was closed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Polygon<'a> {
    pub vertices: &'a [DVec3],
    pub color: u16,
    pub level: u32,
    pub limb: Limb,
}

/// A leaf (`L` in the thesis' dialect).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Leaf {
    pub position: DVec3,
    pub frame: Frame,
    /// The current step length in turtle units (leaves scale with it).
    pub length: f64,
    pub color: u16,
    pub level: u32,
    pub limb: Limb,
}

/// Receives what the turtle draws.
pub trait Sink {
    type Error;
    fn segment(&mut self, segment: &Segment) -> Result<(), Self::Error>;
    /// No further segment will continue `chain`.
    fn chain_end(&mut self, chain: u32) -> Result<(), Self::Error>;
    fn leaf(&mut self, leaf: &Leaf) -> Result<(), Self::Error>;
    /// A closed polygon `{ … }` with at least three recorded vertices.
    fn polygon(&mut self, polygon: &Polygon) -> Result<(), Self::Error>;
}

/// What the turtle did, counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct TurtleCounts {
    pub segments: u64,
    pub leaves: u64,
    pub polygons: u64,
    /// Polygons closed with fewer than three vertices (nothing to draw).
    pub polygons_skipped: u64,
    pub polygon_vertices_dropped: u64,
}

#[derive(Debug, Clone)]
struct State {
    pos: DVec3,
    frame: Frame,
    step: f64,
    half_step: f64,
    angle_deg: f64,
    /// Diameter as a fraction of the segment length (lparser) or of the step (the thesis).
    thickness: f64,
    tropism: f64,
    color: u16,
    /// A `c` has set the colour on this path (thesis leaves then take it).
    color_set: bool,
    chain: Option<u32>,
    limb: Limb,
}

/// Interprets a token stream; feed it tokens in order, then call [`Turtle::finish`].
pub struct Turtle {
    conventions: Conventions,
    seed: u64,
    fraction: f64,
    min_diameter: f64,
    state: State,
    stack: Vec<State>,
    polygons: Vec<Vec<DVec3>>,
    /// Vertices held by `polygons`.
    open_polygon_vertices: usize,
    /// `{` ignored beyond [`MAX_OPEN_POLYGONS`], still waiting for their `}`.
    polygons_overflow: u64,
    /// A command that may still receive an argument from the next token, with the growth factor in
    /// force where it stood (a partial-growth marker may come between it and its argument).
    pending: Option<(u8, u64, f64)>,
    partial_depth: u32,
    next_chain: u32,
    next_limb: u32,
    counts: TurtleCounts,
}

fn clamp_step(x: f64) -> f64 {
    if x.is_finite() {
        x.clamp(-MAX_STEP, MAX_STEP)
    } else if x > 0.0 {
        MAX_STEP
    } else if x < 0.0 {
        -MAX_STEP
    } else {
        0.0
    }
}

fn clamp_finite(x: f64, lo: f64, hi: f64) -> f64 {
    if x.is_nan() {
        lo.max(0.0).min(hi)
    } else {
        x.clamp(lo, hi)
    }
}

/// Commands that read an argument `(x)` right after them.
fn takes_argument(c: u8) -> bool {
    matches!(
        c,
        b'F' | b'Z'
            | b'f'
            | b'z'
            | b'g'
            | b'+'
            | b'-'
            | b'&'
            | b'^'
            | b'<'
            | b'>'
            | b'~'
            | b't'
            | b'"'
            | b'\''
            | b';'
            | b':'
            | b'?'
            | b'!'
            | b'c'
    )
}

impl Turtle {
    pub fn new(system: &LSystem, seed: u64) -> Turtle {
        let conventions = Conventions::of(system.dialect);
        let step = conventions.step;
        Turtle {
            seed: mix64(seed ^ RANDOM_SALT),
            fraction: system.recursion.fraction(),
            min_diameter: clamp_finite(system.min_thickness_pct.unwrap_or(0.0) / 100.0 * step, 0.0, MAX_STEP),
            state: State {
                pos: DVec3::ZERO,
                frame: Frame::START,
                step,
                half_step: step / 2.0,
                angle_deg: clamp_finite(system.angle_deg, -MAX_STEP, MAX_STEP),
                thickness: clamp_finite(system.thickness_pct / 100.0, 0.0, MAX_THICKNESS),
                tropism: DEFAULT_TROPISM,
                color: conventions.start_color,
                color_set: false,
                chain: None,
                limb: Limb::default(),
            },
            conventions,
            stack: Vec::new(),
            polygons: Vec::new(),
            open_polygon_vertices: 0,
            polygons_overflow: 0,
            pending: None,
            partial_depth: 0,
            next_chain: 0,
            next_limb: 1,
            counts: TurtleCounts::default(),
        }
    }

    pub fn counts(&self) -> TurtleCounts {
        self.counts
    }

    pub fn position(&self) -> DVec3 {
        self.state.pos
    }

    pub fn frame(&self) -> Frame {
        self.state.frame
    }

    /// Current `[` nesting depth.
    pub fn level(&self) -> u32 {
        self.stack.len() as u32
    }

    /// Interprets one token.
    pub fn feed<S: Sink>(&mut self, token: Token, sink: &mut S) -> Result<(), S::Error> {
        match token {
            Token::Symbol { byte, id } => {
                if let Some((c, pid, g)) = self.pending.take() {
                    self.execute(c, pid, None, g, sink)?;
                }
                let g = self.growth();
                if takes_argument(byte) {
                    self.pending = Some((byte, id, g));
                    Ok(())
                } else {
                    self.execute(byte, id, None, g, sink)
                }
            }
            Token::Arg { value, .. } => match self.pending.take() {
                Some((c, id, g)) => self.execute(c, id, Some(value), g, sink),
                // an argument after anything else has no command to go to (lparser skips it too)
                None => Ok(()),
            },
            // the markers do not flush a pending command: `^e` with `e=(19.47)` still pitches
            Token::PartialBegin => {
                self.partial_depth += 1;
                Ok(())
            }
            Token::PartialEnd => {
                self.partial_depth = self.partial_depth.saturating_sub(1);
                Ok(())
            }
        }
    }

    /// Runs the last pending command and ends every open chain (unclosed polygons are dropped).
    pub fn finish<S: Sink>(&mut self, sink: &mut S) -> Result<(), S::Error> {
        if let Some((c, id, g)) = self.pending.take() {
            self.execute(c, id, None, g, sink)?;
        }
        self.end_chain(sink)?;
        while let Some(state) = self.stack.pop() {
            self.state = state;
            self.end_chain(sink)?;
        }
        self.polygons.clear();
        self.open_polygon_vertices = 0;
        Ok(())
    }

    fn end_chain<S: Sink>(&mut self, sink: &mut S) -> Result<(), S::Error> {
        match self.state.chain.take() {
            Some(c) => sink.chain_end(c),
            None => Ok(()),
        }
    }

    /// The growth fraction in force (1 outside partial spans).
    fn growth(&self) -> f64 {
        if self.partial_depth > 0 {
            self.fraction
        } else {
            1.0
        }
    }

    /// Uniform in [−1, 1) from the seed, the symbol's position id and which draw it is.
    fn random(&self, id: u64, k: u64) -> f64 {
        let h = mix64(id ^ self.seed ^ k.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        (h >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    fn record(&mut self) {
        if let Some(poly) = self.polygons.last_mut() {
            if poly.len() < MAX_POLYGON_VERTICES && self.open_polygon_vertices < MAX_OPEN_POLYGON_VERTICES {
                poly.push(self.state.pos);
                self.open_polygon_vertices += 1;
            } else {
                self.counts.polygon_vertices_dropped += 1;
            }
        }
    }

    fn draw<S: Sink>(&mut self, length: f64, sink: &mut S) -> Result<(), S::Error> {
        let length = clamp_step(length);
        if length == 0.0 {
            return Ok(());
        }
        let start = self.state.pos;
        let end = start + self.state.frame.heading * length;
        let (chain, continues) = match self.state.chain {
            Some(c) => (c, true),
            None => {
                let c = self.next_chain;
                self.next_chain = self.next_chain.wrapping_add(1);
                self.state.chain = Some(c);
                (c, false)
            }
        };
        let scale = if self.conventions.thickness_follows_length { length.abs() } else { self.conventions.step };
        let diameter = (scale * self.state.thickness).max(self.min_diameter);
        let segment = Segment {
            chain,
            continues,
            start,
            end,
            frame: self.state.frame,
            diameter: clamp_finite(diameter, 0.0, MAX_STEP),
            color: self.state.color,
            level: self.level(),
            limb: self.state.limb,
        };
        self.counts.segments += 1;
        self.state.pos = end;
        self.travel(length);
        sink.segment(&segment)
    }

    /// Moving `length` along a limb lengthens its arc; the trunk's stays 0.
    fn travel(&mut self, length: f64) {
        if self.level() > 0 {
            self.state.limb.arc = clamp_finite(self.state.limb.arc + length.abs(), 0.0, f64::MAX);
        }
    }

    fn advance<S: Sink>(&mut self, length: f64, record: bool, sink: &mut S) -> Result<(), S::Error> {
        let length = clamp_step(length);
        if length != 0.0 {
            self.end_chain(sink)?;
            self.state.pos += self.state.frame.heading * length;
            self.travel(length);
        }
        if record {
            self.record();
        }
        Ok(())
    }

    /// Runs command `c` (position id `id`) under growth factor `g`: lengths and angles are scaled
    /// by it, multiplicative factors x become 1 + g·(x − 1).
    fn execute<S: Sink>(&mut self, c: u8, id: u64, arg: Option<f64>, g: f64, sink: &mut S) -> Result<(), S::Error> {
        let factor = |x: f64| 1.0 + g * (x - 1.0);
        let angle = |t: &Turtle| arg.unwrap_or(t.state.angle_deg) * g;
        match c {
            b'F' => self.draw(arg.unwrap_or(self.state.step) * g, sink)?,
            b'Z' => self.draw(arg.unwrap_or(self.state.half_step) * g, sink)?,
            b'f' => self.advance(arg.unwrap_or(self.state.step) * g, true, sink)?,
            b'z' => self.advance(arg.unwrap_or(self.state.half_step) * g, true, sink)?,
            b'g' => self.advance(arg.unwrap_or(self.state.step) * g, false, sink)?,
            b'.' => self.record(),
            b'+' => self.state.frame.turn(angle(self)),
            b'-' => self.state.frame.turn(-angle(self)),
            b'&' => self.state.frame.pitch(angle(self)),
            b'^' => self.state.frame.pitch(-angle(self)),
            b'>' => self.state.frame.roll(angle(self)),
            b'<' => self.state.frame.roll(-angle(self)),
            b'|' if self.conventions.bar_rolls => self.state.frame.roll(180.0),
            b'|' => self.state.frame.turn(180.0),
            b'%' if self.conventions.bar_rolls => self.state.frame.turn(180.0),
            b'%' => self.state.frame.roll(180.0),
            b'$' => self.state.frame.roll_to_horizontal(),
            b'~' => {
                let max = clamp_finite(arg.unwrap_or(DEFAULT_RANDOM_TURN_DEG) * g, -360.0, 360.0);
                let (a, b, r) = (self.random(id, 1) * max, self.random(id, 2) * max, self.random(id, 3) * max);
                self.state.frame.turn(a);
                self.state.frame.pitch(b);
                self.state.frame.roll(r);
            }
            b't' => {
                let e = clamp_finite(arg.unwrap_or(self.state.tropism) * g, -MAX_THICKNESS, MAX_THICKNESS);
                self.state.frame.bend(-SKY, e);
            }
            b'"' | b'\'' => {
                let default = if c == b'"' { self.conventions.length_up } else { self.conventions.length_down };
                let k = factor(arg.unwrap_or(default));
                self.state.step = clamp_step(self.state.step * k);
                self.state.half_step = clamp_step(self.state.half_step * k);
            }
            b';' | b':' => {
                let default = if c == b';' { self.conventions.angle_up } else { self.conventions.angle_down };
                let k = factor(arg.unwrap_or(default));
                self.state.angle_deg = clamp_finite(self.state.angle_deg * k, -MAX_STEP, MAX_STEP);
            }
            b'?' | b'!' => {
                let default = if c == b'?' { self.conventions.thickness_up } else { self.conventions.thickness_down };
                let k = factor(arg.unwrap_or(default));
                self.state.thickness = clamp_finite(self.state.thickness * k, 0.0, MAX_THICKNESS);
            }
            b'c' => {
                let color = match arg {
                    Some(x) => clamp_finite(x, 0.0, u16::MAX as f64) as u16,
                    None => self.state.color.saturating_add(1),
                };
                if color != self.state.color {
                    // a new colour is a new material: the branch's run of shared rings ends here
                    self.end_chain(sink)?;
                    self.state.color = color;
                }
                self.state.color_set = true;
            }
            b'[' => {
                let saved = self.state.clone();
                self.stack.push(saved);
                if self.stack.len() == 1 {
                    // a branch off the trunk starts a limb; deeper branches stay on theirs
                    self.state.limb = Limb { id: self.next_limb, arc: 0.0 };
                    self.next_limb = self.next_limb.wrapping_add(1).max(1);
                }
                // a branch starts its own run; the parent's run continues after `]`
                self.state.chain = None;
            }
            b']' => {
                if let Some(parent) = self.stack.pop() {
                    self.end_chain(sink)?;
                    self.state = parent;
                }
            }
            b'{' => {
                if self.polygons.len() >= MAX_OPEN_POLYGONS {
                    self.polygons_overflow += 1;
                    self.counts.polygons_skipped += 1;
                } else {
                    self.polygons.push(Vec::new());
                    if self.conventions.polygon_starts_at_turtle {
                        self.record();
                    }
                }
            }
            b'}' if self.polygons_overflow > 0 => self.polygons_overflow -= 1,
            b'}' => {
                if let Some(poly) = self.polygons.pop() {
                    self.open_polygon_vertices -= poly.len();
                    if poly.len() >= 3 {
                        self.counts.polygons += 1;
                        sink.polygon(&Polygon {
                            vertices: &poly,
                            color: self.state.color,
                            level: self.level(),
                            limb: self.state.limb,
                        })?;
                    } else {
                        self.counts.polygons_skipped += 1;
                    }
                }
            }
            b'L' if self.conventions.leaf_command => {
                self.counts.leaves += 1;
                let leaf = Leaf {
                    position: self.state.pos,
                    frame: self.state.frame,
                    length: self.state.step.abs() * g,
                    // the turtle's colour index once a `c` has set one, else leaf green
                    color: if self.state.color_set { self.state.color } else { self.conventions.leaf_color },
                    level: self.level(),
                    limb: self.state.limb,
                };
                sink.leaf(&leaf)?;
            }
            _ => {}
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quarter_turns_are_exact() {
        let mut f = Frame::START;
        for _ in 0..4 {
            f.turn(90.0);
        }
        assert_eq!(f, Frame::START);
        f.pitch(90.0);
        assert_eq!(f.heading, DVec3::X, "& pitches the heading toward up");
        f.pitch(-90.0);
        f.turn(90.0);
        assert_eq!(f.heading, DVec3::NEG_Z, "+ turns the heading toward left");
        let mut g = Frame::START;
        g.roll(180.0);
        assert_eq!((g.heading, g.left, g.up), (DVec3::Y, DVec3::Z, DVec3::NEG_X));
    }

    #[test]
    fn roll_to_horizontal_levels_left_and_keeps_vertical_frames() {
        let mut f = Frame::START;
        f.roll(37.0);
        let before = f;
        f.roll_to_horizontal();
        assert_eq!(f, before, "vertical heading: left is already horizontal");
        f.pitch(30.0);
        f.roll(50.0);
        f.roll_to_horizontal();
        assert!(f.left.dot(SKY).abs() < 1e-12);
        assert!(f.up.dot(SKY) > 0.0);
        assert!(f.orthonormality_error() < 1e-12);
    }

    #[test]
    fn tropism_bends_toward_gravity_and_is_quiet_when_vertical() {
        let mut f = Frame::START;
        f.bend(-SKY, 0.5);
        assert_eq!(f, Frame::START);
        f.pitch(90.0);
        let before = f.heading.dot(SKY);
        f.bend(-SKY, 0.2);
        assert!(f.heading.dot(SKY) < before);
        assert!((f.heading.dot(SKY) + 0.2f64.sin()).abs() < 1e-12);
    }
}
