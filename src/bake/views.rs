//! LoD image analyzer: renders a reference and a candidate level of detail with the baker from 8
//! azimuths × 3 elevations at each test distance, at the size the object has on a given screen,
//! and measures the image error ([`compare`]); the switch distance is where the silhouette error
//! falls under a pixel tolerance for good. This is the image-space LoD metric of Lindstrom & Turk,
//! "Image-driven simplification" (ACM TOG 2000), used here to place the switch instead of to guide
//! the simplification.

use rayon::prelude::*;

use crate::bake::compare::{compare, ImageError};
use crate::bake::image::Image;
use crate::bake::raster::{Camera, Canvas, PerspectiveView};
use crate::bake::render::{render_mesh, RenderOptions, Shading};
use crate::mesh::{Material, Mesh};

/// The screen the errors are measured for. Height is `width_px` · 9/16 (a 16:9 screen).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ScreenView {
    pub width_px: f64,
    /// Horizontal field of view.
    pub fov_x_deg: f64,
    /// Largest silhouette error (mean displacement, [`ImageError::edge_error_px`]) accepted, in
    /// screen pixels.
    pub max_error_px: f64,
}

impl Default for ScreenView {
    fn default() -> Self {
        ScreenView { width_px: 1920.0, fov_x_deg: 60.0, max_error_px: 1.0 }
    }
}

/// Screen height / width.
const ASPECT_HEIGHT: f64 = 9.0 / 16.0;

/// Largest side of a rendered (supersampled) view: two 4096² canvases are 0.7 GB, per thread.
/// `max_side_px` is lowered to fit (the errors then scaled up to screen pixels, as for any cap).
pub const MAX_RENDER_SIDE_PX: u32 = 4096;

impl ScreenView {
    /// A finite screen width over 0, a field of view in (0°, 179°] and a tolerance over 0.
    pub fn check(&self) -> Result<(), String> {
        if !(self.width_px.is_finite() && self.width_px >= 1.0) {
            return Err(format!("screen width_px = {} must be at least 1 pixel", self.width_px));
        }
        if !(self.fov_x_deg > 0.0 && self.fov_x_deg <= 179.0) {
            return Err(format!("fov_x_deg = {} must be in (0, 179] degrees", self.fov_x_deg));
        }
        if !(self.max_error_px.is_finite() && self.max_error_px > 0.0) {
            return Err(format!("max_error_px = {} must be a positive number of pixels", self.max_error_px));
        }
        Ok(())
    }

    pub fn height_px(&self) -> f64 {
        self.width_px * ASPECT_HEIGHT
    }

    /// Focal length in pixels: (width/2) / tan(fov_x/2) (1662.8 px for 1920 px and 60°).
    pub fn focal_px(&self) -> f64 {
        self.width_px * 0.5 / (self.fov_x_deg.to_radians() * 0.5).tan()
    }

    /// Diameter in pixels of a sphere of `radius_m` whose centre is `distance_m` from the eye, seen
    /// at the centre of the screen: 2·f·tan(asin(r/d)). Infinite when the eye is inside it.
    pub fn projected_diameter_px(&self, radius_m: f64, distance_m: f64) -> f64 {
        if distance_m.is_nan() || radius_m.is_nan() || distance_m <= radius_m {
            return f64::INFINITY;
        }
        let s = radius_m / distance_m;
        2.0 * self.focal_px() * s / (1.0 - s * s).sqrt()
    }

    /// Screen coverage as MSFT_lod and our manifests use it: the projected bounding-sphere diameter
    /// ([`ScreenView::projected_diameter_px`]) divided by the screen *height* (width · 9/16). It
    /// exceeds 1 when the object is taller than the screen; infinite with the eye inside the sphere.
    pub fn screen_coverage(&self, radius_m: f64, distance_m: f64) -> f64 {
        self.projected_diameter_px(radius_m, distance_m) / self.height_px()
    }

    /// The distance at which a sphere of `radius_m` has screen coverage `coverage` (the inverse of
    /// [`ScreenView::screen_coverage`]).
    pub fn distance_for_coverage(&self, radius_m: f64, coverage: f64) -> f64 {
        // D = coverage·H = 2 f r / sqrt(d² − r²)  ⇒  d = r · sqrt(1 + (2f/D)²).
        let d_px = coverage * self.height_px();
        radius_m * (1.0 + (2.0 * self.focal_px() / d_px).powi(2)).sqrt()
    }
}

/// Samples across a view's canvas at least (see [`SMALL_VIEW_MAX_SUPERSAMPLE`]).
const MIN_SAMPLES_ACROSS: u32 = 64;
/// Samples per pixel along each axis a small view is raised to at most.
const SMALL_VIEW_MAX_SUPERSAMPLE: u32 = 4;

/// A mesh with what it needs to be drawn.
#[derive(Debug, Clone, Copy)]
pub struct Renderable<'a> {
    pub mesh: &'a Mesh,
    pub materials: &'a [Material],
    pub textures: &'a [Image],
}

/// How [`lod_image_error_with`] renders.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LodImageOptions {
    /// Samples per output pixel along each axis (a view under 64 samples across gets more, up to
    /// 4×4, so far-away silhouettes are not measured at the noise of the sample grid).
    pub supersample: u32,
    /// Smallest canvas side in output pixels (the object centred, at its on-screen size).
    pub min_side_px: u32,
    /// Largest canvas side in output pixels: a view that would be larger is rendered at reduced
    /// resolution and its pixel errors scaled back up to screen pixels (an estimate, flagged by
    /// [`DistanceError::screen_px_per_rendered_px`] > 1).
    pub max_side_px: u32,
    /// Azimuths, evenly spaced from 0° (looking towards −Z from +Z).
    pub azimuths: u32,
    /// Elevations of the eye above the horizon of the object's centre.
    pub elevations_deg: Vec<f64>,
    /// Alpha at which a rendered sample counts as covered (renders are alpha 0 or 1).
    pub cutoff: f32,
}

impl LodImageOptions {
    /// Views per distance: azimuths × elevations.
    pub fn views(&self) -> usize {
        self.azimuths.max(1) as usize * self.elevations_deg.len().max(1)
    }
}

impl Default for LodImageOptions {
    fn default() -> Self {
        LodImageOptions {
            supersample: 4,
            min_side_px: 16,
            max_side_px: 256,
            azimuths: 8,
            elevations_deg: vec![10.0, 40.0, 75.0],
            cutoff: 0.5,
        }
    }
}

/// The errors over all views at one distance.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DistanceError {
    /// From the eye to the reference's bounding-sphere centre.
    pub distance_m: f64,
    pub worst_iou: f64,
    pub mean_iou: f64,
    pub worst_color_rmse: f64,
    pub mean_color_rmse: f64,
    /// In screen pixels.
    pub worst_edge_error_px: f64,
    pub mean_edge_error_px: f64,
    /// `worst_edge_error_px` ≤ the view's `max_error_px`.
    pub passes: bool,
    /// Canvas size in output pixels (before supersampling).
    pub canvas_px: [u32; 2],
    /// 1 when rendered at screen resolution; above 1 when capped by `max_side_px`.
    pub screen_px_per_rendered_px: f64,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LodImageReport {
    pub view: ScreenView,
    /// Reference bounding sphere (centre of its bounding box, radius enclosing both meshes).
    pub centre: [f64; 3],
    pub radius_m: f64,
    /// Views per distance (azimuths × elevations).
    pub views: usize,
    /// Tested distances in increasing order (non-finite or non-positive ones are left out).
    pub distances: Vec<DistanceError>,
    /// The smallest distance from which on every tested distance passes, log-interpolated between
    /// the last failing and the first passing one (error against distance on log-log axes); 0 when
    /// all pass or none was tested; the largest tested distance when the last one fails.
    pub switch_distance_m: f64,
    /// The largest tested distance still fails: `switch_distance_m` is a lower bound only.
    pub never_passes: bool,
    /// Why nothing was measured (an invalid [`ScreenView`]); then `distances` is empty and
    /// `never_passes` true, so a caller that ignores this cannot mistake it for a pass.
    pub problem: Option<String>,
}

/// [`lod_image_error_with`] with the default options (4× supersampling, 8 × 3 views).
pub fn lod_image_error(
    reference: &Renderable,
    candidate: &Renderable,
    view: &ScreenView,
    distances_m: &[f64],
) -> LodImageReport {
    lod_image_error_with(reference, candidate, view, distances_m, &LodImageOptions::default())
}

/// Renders `reference` and `candidate` (both in the same object space, unlit, alpha-tested as
/// their materials say) with perspective cameras looking at the reference's bounding-sphere
/// centre from every azimuth × elevation at each distance, the focal length that of `view`, and
/// compares them ([`compare`]). The canvas is the object's on-screen extent (the sphere's projected
/// diameter plus a margin, no larger than the screen, at least `min_side_px`), so pixel errors are
/// screen pixels. Parallel over views; the result does not depend on the thread count.
pub fn lod_image_error_with(
    reference: &Renderable,
    candidate: &Renderable,
    view: &ScreenView,
    distances_m: &[f64],
    opts: &LodImageOptions,
) -> LodImageReport {
    let Sphere { centre, radius_m } = bounding_sphere(reference.mesh, &[candidate.mesh]);
    if let Err(problem) = view.check() {
        return LodImageReport {
            view: *view,
            centre,
            radius_m,
            views: 0,
            distances: Vec::new(),
            switch_distance_m: 0.0,
            never_passes: true,
            problem: Some(problem),
        };
    }
    let mut distances: Vec<f64> = distances_m.iter().copied().filter(|d| d.is_finite() && *d > 0.0).collect();
    distances.sort_by(f64::total_cmp);
    let views = opts.views();
    let sphere = Sphere { centre, radius_m };
    let only = [Candidate::Mesh(*candidate)];
    // distances in parallel too (each measures its views in parallel), rows kept in order
    let per_distance: Vec<Vec<DistanceError>> =
        distances.par_iter().map(|&d| measure_distance(reference, &[&only[0]], view, opts, sphere, d)).collect();
    let rows: Vec<DistanceError> = per_distance.into_iter().flatten().collect();
    let (switch_distance_m, never_passes) = switch_distance(&rows, view.max_error_px);
    LodImageReport {
        view: *view,
        centre,
        radius_m,
        views,
        distances: rows,
        switch_distance_m,
        never_passes,
        problem: None,
    }
}

/// The distances the 1-px switch search walks: from `start_m` halving down to `near_m` while a
/// level passes, doubling up to `far_m` while it fails, then narrowing each level's bracket (its
/// failing and passing distance) down to one step of the lattice `start_m` · 2^(j / 2^bisections):
/// switches are found within a factor 2^(1/2^bisections). `start_m` = `far_m` checks every halving
/// from the far end ([`SwitchSearch::from_far`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SwitchSearch {
    pub start_m: f64,
    pub far_m: f64,
    pub near_m: f64,
    pub bisections: usize,
    /// How a bracket is narrowed: false, bisected in log space (`bisections` rounds); true, probed
    /// where the error, linear in log-log between the bracket's ends, meets the bound, then at that
    /// probe's neighbour across it (error against distance is close to 1/d near a switch: two
    /// probes usually close a bracket that bisection needs three for), bisecting when a pair of
    /// probes did not halve the bracket; and the levels halving inwards (doubling outwards) go
    /// together straight to the point where the first of them is predicted to meet the bound,
    /// instead of halving towards it.
    pub guided: bool,
}

impl SwitchSearch {
    /// Halving from the far end, bracket bisected: every distance on the far side of a switch is
    /// measured.
    pub fn from_far(far_m: f64, near_m: f64, bisections: usize) -> SwitchSearch {
        SwitchSearch { start_m: far_m, far_m, near_m, bisections, guided: false }
    }
}

/// Where a level's image error stays within the view's bound: measured at `start_m`, then
/// `start_m`/2, … until a distance fails, or (when `start_m` fails) `start_m`·2, … until one passes
/// or `far_m` is passed (error ≤ 1 px is monotone in distance but for noise: from `far_m` every
/// halving on the far side is checked), then bisected in log space between the failing and the
/// passing distance. Returns the measured rows (sorted by distance), the switch distance (the
/// nearest distance known to pass: conservative) and whether even the farthest failed. A chain of
/// one level ([`switch_search_chain`]).
pub fn switch_search(
    reference: &Renderable,
    candidate: &Renderable,
    view: &ScreenView,
    opts: &LodImageOptions,
    range: &SwitchSearch,
) -> (Vec<DistanceError>, f64, bool) {
    let mut found = switch_search_chain(reference, &[Candidate::Mesh(*candidate)], view, opts, range);
    found.pop().unwrap_or((Vec::new(), 0.0, false))
}

/// A level measured against the reference: geometry seen from every view; textured cards showing
/// parts of the reference projected onto them (leaf-cluster cards, billboards); or a
/// view-dependent impostor whose cards are evenly spaced in azimuth from 0° (card k faces azimuth
/// k · 360°/n): a view at azimuth α sees the card nearest to it turned about the vertical axis
/// through the framing sphere's centre to face α, as an impostor shader shows it. Cards do not
/// widen the framing sphere: what they show is the reference projected onto them, and only their
/// cut-away corners reach past it (a 2-px margin takes what little a projection onto an off-centre
/// plane may add). Geometry does: the sphere encloses it, so nothing of it is cropped.
#[derive(Debug, Clone)]
pub enum Candidate<'a> {
    Mesh(Renderable<'a>),
    Card(Renderable<'a>),
    PerAzimuth(Vec<Renderable<'a>>),
}

impl<'a> Candidate<'a> {
    /// What a view from `azimuth_deg` draws and the angle (degrees) to turn it by about the vertical
    /// axis first (None for an impostor without cards).
    fn seen_from(&self, azimuth_deg: f64) -> Option<(&Renderable<'a>, f64)> {
        match self {
            Candidate::Mesh(r) | Candidate::Card(r) => Some((r, 0.0)),
            Candidate::PerAzimuth(cards) if cards.is_empty() => None,
            Candidate::PerAzimuth(cards) => {
                let n = cards.len();
                let step = 360.0 / n as f64;
                let k = (azimuth_deg.rem_euclid(360.0) / step).round() as usize % n;
                // within (−180°, 180°]; views at the cards' own azimuths (the default 8) see them
                // untouched
                let turn = (azimuth_deg - k as f64 * step).rem_euclid(360.0);
                let turn = if turn > 180.0 { turn - 360.0 } else { turn };
                cards.get(k).map(|c| (c, if turn.abs() < 1e-9 { 0.0 } else { turn }))
            }
        }
    }

    /// The geometry the framing sphere must enclose (cards: none, see above).
    fn framed(&self) -> Option<&'a Mesh> {
        match self {
            Candidate::Mesh(r) => Some(r.mesh),
            Candidate::Card(_) | Candidate::PerAzimuth(_) => None,
        }
    }
}

/// `mesh` turned by `angle_deg` about the vertical axis through `centre` (positions and normals):
/// a turn by +angle moves what faces azimuth θ to face θ + angle (0° = +Z, 90° = +X).
fn turned(mesh: &Mesh, centre: [f64; 3], angle_deg: f64) -> Mesh {
    let (s, c) = angle_deg.to_radians().sin_cos();
    let turn = |x: f64, z: f64| (c * x + s * z, -s * x + c * z);
    let mut out = mesh.clone();
    for p in &mut out.primitives {
        for v in &mut p.positions {
            let (x, z) = turn(v[0] as f64 - centre[0], v[2] as f64 - centre[2]);
            *v = [(x + centre[0]) as f32, v[1], (z + centre[2]) as f32];
        }
        for n in &mut p.normals {
            let (x, z) = turn(n[0] as f64, n[2] as f64);
            *n = [x as f32, n[1], z as f32];
        }
    }
    out
}

/// [`switch_search`] for every level of a chain at once, each against the same reference and in
/// the same framing: the sphere encloses the reference and every geometric candidate (not the cards,
/// see [`Candidate`]), and a distance two
/// levels both test renders the reference once for both. Every distance the search visits lies
/// on the lattice `start_m` · 2^(j / 2^bisections) (j any integer), so levels whose switches are near one another
/// share most of them. Per level: its rows (sorted by distance), switch distance and whether even
/// the farthest failed, exactly as [`switch_search`] of that level alone decides them when the
/// framing is the same.
pub fn switch_search_chain(
    reference: &Renderable,
    candidates: &[Candidate],
    view: &ScreenView,
    opts: &LodImageOptions,
    range: &SwitchSearch,
) -> Vec<(Vec<DistanceError>, f64, bool)> {
    let meshes: Vec<&Mesh> = candidates.iter().filter_map(Candidate::framed).collect();
    let sphere = bounding_sphere(reference.mesh, &meshes);
    let mut searches: Vec<LevelSearch> = candidates.iter().map(|_| LevelSearch::default()).collect();
    if !(range.near_m > 0.0 && range.far_m.is_finite() && range.far_m >= range.near_m) {
        // nothing to walk: an empty range, or halving would never reach a positive nearest distance
        return searches.into_iter().map(|_| (Vec::new(), 0.0, false)).collect();
    }
    let measure = |levels: &[usize], d: f64| -> Vec<DistanceError> {
        // a distance of 0 (or not finite) puts the eye on the target: nothing to measure
        if view.check().is_err() || !(d.is_finite() && d > 0.0) {
            return Vec::new();
        }
        let picked: Vec<&Candidate> = levels.iter().map(|&i| &candidates[i]).collect();
        measure_distance(reference, &picked, view, opts, sphere, d)
    };
    // distances as lattice points: d(j) = start · 2^(j / steps), so two levels asking for the same
    // point ask for the same bits and share its renders
    let steps = 1i64 << range.bisections.min(20);
    let start = if range.start_m.is_finite() { range.start_m.clamp(range.near_m, range.far_m) } else { range.far_m };
    let at =
        |j: i64| start * 2f64.powi(j.div_euclid(steps) as i32) * 2f64.powf(j.rem_euclid(steps) as f64 / steps as f64);
    // the points of one step, each with the levels it is measured for: measured at once (in
    // parallel over points as over views, so a step waits for its slowest view once, not once per
    // point), then recorded in order; whether any was measured
    let measure_points = |searches: &mut [LevelSearch], points: Vec<(i64, Vec<usize>)>| -> bool {
        let measured: Vec<(i64, Vec<usize>, Vec<DistanceError>)> = points
            .into_par_iter()
            .map(|(j, levels)| {
                let rows = measure(&levels, at(j));
                (j, levels, rows)
            })
            .collect();
        let mut any = false;
        for (j, levels, rows) in measured {
            if rows.len() == levels.len() {
                for (&i, r) in levels.iter().zip(rows) {
                    searches[i].record(j, r);
                }
                any = true;
            }
        }
        any
    };
    // every level at the start; then halving towards `near_m` while a level passes (it leaves at
    // its first failure) and doubling towards `far_m` while one fails (it leaves at its first pass)
    let all: Vec<usize> = (0..searches.len()).collect();
    if measure_points(&mut searches, vec![(0, all)]) {
        let (mut inward, mut outward) = (-steps, steps);
        // the lattice's nearest and farthest points inside the range
        let index = |d: f64| (steps as f64 * (d / start).log2()).round() as i64;
        let (mut j_near, mut j_far) = (index(range.near_m), index(range.far_m));
        while at(j_near) < range.near_m {
            j_near += 1;
        }
        while at(j_far) > range.far_m {
            j_far -= 1;
        }
        loop {
            let mut passing: Vec<usize> = (0..searches.len()).filter(|&i| searches[i].fail.is_none()).collect();
            let failing: Vec<usize> = (0..searches.len()).filter(|&i| searches[i].pass.is_none()).collect();
            if range.guided {
                // the walking levels go straight to where they are predicted to cross the bound
                // (the error close to 1/d: the first point predicted to pass), rather than halving
                // towards it; levels whose predictions meet share the point
                let predicted = |(j, e): (i64, f64)| {
                    let k = j as f64 + steps as f64 * (e / view.max_error_px).log2();
                    k.is_finite().then(|| k.ceil() as i64)
                };
                // inwards: each walking level's next point is its predicted crossing, nearer than
                // its nearest pass; the farthest of them is measured, by the levels whose next point
                // it is. A level predicted to cross nearer waits for its own point: measured here it
                // would draw itself where its error is a fraction of the bound (a LoD1 at 0.05 px
                // followed the impostor's walk out at 100 radii), which tells nothing the prediction
                // from its last pass does not. A level without a prediction (no error at all) walks
                // with every point.
                let next = |i: usize| {
                    let (jp, e) = searches[i].pass?;
                    predicted((jp, e)).map(|k| k.clamp(j_near.min(jp - 1), jp - 1))
                };
                if let Some(k) = passing.iter().filter_map(|&i| next(i)).max() {
                    inward = k;
                    passing.retain(|&i| next(i).is_none_or(|n| n >= k));
                }
                // outwards: all failed at the same point; the nearest predicted crossing first
                let jf = failing.first().and_then(|&i| searches[i].fail).map(|f| f.0);
                if let (Some(jf), Some(k)) =
                    (jf, failing.iter().filter_map(|&i| searches[i].fail.and_then(predicted)).min())
                {
                    outward = k.clamp(jf + 1, j_far.max(jf + 1));
                }
            }
            let points: Vec<(i64, Vec<usize>)> =
                [(inward, passing, at(inward) >= range.near_m), (outward, failing, at(outward) <= range.far_m)]
                    .into_iter()
                    .filter(|(_, levels, ok)| *ok && !levels.is_empty())
                    .map(|(j, levels, _)| (j, levels))
                    .collect();
            if points.is_empty() || !measure_points(&mut searches, points) {
                break;
            }
            inward -= steps;
            outward += steps;
        }
    }
    // each level's bracket narrowed to one lattice step, one round at a time; levels asking for
    // the same point share its renders
    let bound = view.max_error_px;
    // guided: a pair of probes, then a bisection when the pair did not halve the bracket
    let rounds = if range.guided { 3 * range.bisections + 2 } else { range.bisections };
    for _ in 0..rounds {
        let mut wanted: std::collections::BTreeMap<i64, Vec<usize>> = std::collections::BTreeMap::new();
        for (i, s) in searches.iter_mut().enumerate() {
            if let Some(j) = s.next_probe(range.guided, bound) {
                wanted.entry(j).or_default().push(i);
            }
        }
        if wanted.is_empty() {
            break;
        }
        measure_points(&mut searches, wanted.into_iter().collect());
    }
    searches
        .into_iter()
        .map(|mut s| {
            s.rows.sort_by(|a, b| a.distance_m.total_cmp(&b.distance_m));
            match (s.fail, s.pass) {
                (None, _) => (s.rows, 0.0, false),
                (Some((f, _)), None) => (s.rows, at(f), true),
                (Some(_), Some((p, _))) => (s.rows, at(p), false),
            }
        })
        .collect()
}

/// One level's switch search: what it measured, its nearest passing and failing lattice point
/// (with the worst edge error there), and where a guided narrowing stands.
#[derive(Default)]
struct LevelSearch {
    rows: Vec<DistanceError>,
    pass: Option<(i64, f64)>,
    fail: Option<(i64, f64)>,
    /// A guided pair of probes under way: the bracket's width before it and whether the second
    /// probe (the neighbour) was made.
    pair: Option<(i64, bool)>,
}

impl LevelSearch {
    fn record(&mut self, j: i64, row: DistanceError) {
        let e = row.worst_edge_error_px;
        if row.passes {
            self.pass = Some((j, e));
        } else {
            self.fail = Some((j, e));
        }
        self.rows.push(row);
    }

    /// The lattice point to measure next inside the bracket; None once it is one step wide (or
    /// there is no bracket). See [`SwitchSearch::guided`].
    fn next_probe(&mut self, guided: bool, bound: f64) -> Option<i64> {
        let ((lo, e_lo), (hi, e_hi)) = (self.fail?, self.pass?);
        let width = hi - lo;
        if width <= 1 {
            return None;
        }
        let middle = lo + width / 2;
        if !guided {
            return Some(middle);
        }
        match self.pair {
            Some((before, false)) => {
                // the interpolated probe is now an end: its neighbour across the switch (strictly
                // inside, as the bracket is wider than one step)
                self.pair = Some((before, true));
                let passed = self.rows.last().is_some_and(|r| r.passes);
                return Some(if passed { hi - 1 } else { lo + 1 });
            }
            Some((before, true)) => {
                self.pair = None;
                if 2 * width > before {
                    return Some(middle);
                }
            }
            None => {}
        }
        // where log(error) meets log(bound), linear in log(distance) between the ends
        let t = (e_lo / bound).ln() / (e_lo / e_hi).ln();
        if !(t.is_finite() && t > 0.0 && t < 1.0) {
            return Some(middle);
        }
        self.pair = Some((width, false));
        Some((lo + (t * width as f64).ceil() as i64).clamp(lo + 1, hi - 1))
    }
}

/// The sphere every view of one measurement is framed by.
#[derive(Debug, Clone, Copy)]
struct Sphere {
    centre: [f64; 3],
    radius_m: f64,
}

/// Centre of the reference's bounding box and the radius around it that encloses the reference
/// and every candidate (a candidate may be wider, e.g. billboards); at least 1 mm.
fn bounding_sphere(reference: &Mesh, candidates: &[&Mesh]) -> Sphere {
    let points = |m: &Mesh| {
        m.primitives
            .iter()
            .flat_map(|p| p.positions.iter())
            .filter(|q| q.iter().all(|v| v.is_finite()))
            .map(|q| q.map(|v| v as f64))
            .collect::<Vec<_>>()
    };
    let r = points(reference);
    let c: Vec<[f64; 3]> = candidates.iter().flat_map(|m| points(m)).collect();
    // An empty reference (nothing to see) still gets a view of the candidates.
    let framed = if r.is_empty() { &c } else { &r };
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for q in framed {
        for k in 0..3 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    let centre = if lo[0].is_finite() { [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k])) } else { [0.0; 3] };
    let radius_m = r
        .iter()
        .chain(&c)
        .map(|q| ((q[0] - centre[0]).powi(2) + (q[1] - centre[1]).powi(2) + (q[2] - centre[2]).powi(2)).sqrt())
        .fold(1e-3, f64::max);
    Sphere { centre, radius_m }
}

/// The errors of each of `candidates` at one distance over every view (in parallel over views;
/// the reference is rendered once per view for all of them). One row per candidate, in order.
fn measure_distance(
    reference: &Renderable,
    candidates: &[&Candidate],
    view: &ScreenView,
    opts: &LodImageOptions,
    sphere: Sphere,
    distance_m: f64,
) -> Vec<DistanceError> {
    let azimuths = opts.azimuths.max(1) as usize;
    let elevations = if opts.elevations_deg.is_empty() { vec![0.0] } else { opts.elevations_deg.clone() };
    let views = opts.views();
    let per_view: Vec<Vec<(ImageError, [u32; 2], f64)>> = (0..views)
        .into_par_iter()
        .map(|v| {
            let azimuth = (v % azimuths) as f64 * 360.0 / azimuths as f64;
            let elevation = elevations[v / azimuths];
            let shot = ViewShot::new(view, opts, sphere, distance_m, azimuth, elevation);
            let reference_image = shot.render(reference);
            candidates
                .iter()
                .map(|c| {
                    let empty = Mesh::default();
                    let nothing = Renderable { mesh: &empty, materials: &[], textures: &[] };
                    let image = match c.seen_from(azimuth) {
                        Some((seen, turn)) if turn != 0.0 => {
                            let mesh = turned(seen.mesh, sphere.centre, turn);
                            shot.render(&Renderable { mesh: &mesh, ..*seen })
                        }
                        Some((seen, _)) => shot.render(seen),
                        None => shot.render(&nothing),
                    };
                    shot.compare(&reference_image, &image, opts.cutoff)
                })
                .collect()
        })
        .collect();
    (0..candidates.len())
        .map(|c| {
            let per: Vec<&(ImageError, [u32; 2], f64)> = per_view.iter().map(|v| &v[c]).collect();
            let n = per.len() as f64;
            let worst = |f: fn(&ImageError) -> f64| per.iter().map(|r| f(&r.0)).fold(f64::NEG_INFINITY, f64::max);
            let mean = |f: fn(&ImageError) -> f64| per.iter().map(|r| f(&r.0)).sum::<f64>() / n;
            let worst_edge = worst(|e| e.edge_error_px);
            DistanceError {
                distance_m,
                worst_iou: per.iter().map(|r| r.0.iou).fold(f64::INFINITY, f64::min),
                mean_iou: mean(|e| e.iou),
                worst_color_rmse: worst(|e| e.color_rmse),
                mean_color_rmse: mean(|e| e.color_rmse),
                worst_edge_error_px: worst_edge,
                mean_edge_error_px: mean(|e| e.edge_error_px),
                passes: worst_edge <= view.max_error_px,
                canvas_px: per.iter().map(|r| r.1).max().unwrap_or([0, 0]),
                screen_px_per_rendered_px: per.iter().map(|r| r.2).fold(1.0, f64::max),
            }
        })
        .collect()
}

/// One view of a measurement: the camera at `distance_m` from the sphere's centre looking at it
/// from `azimuth_deg`, `elevation_deg`, its canvas the object's on-screen extent.
struct ViewShot {
    cam: Camera,
    canvas_px: [u32; 2],
    /// Rendered pixels per screen pixel (≤ 1 when capped by `max_side_px`).
    shrink: f64,
    supersample: u32,
}

impl ViewShot {
    fn new(
        view: &ScreenView,
        opts: &LodImageOptions,
        sphere: Sphere,
        distance_m: f64,
        azimuth_deg: f64,
        elevation_deg: f64,
    ) -> ViewShot {
        let Sphere { centre, radius_m } = sphere;
        let ss = opts.supersample.clamp(1, MAX_RENDER_SIDE_PX);
        let margin_px = 2.0;
        let diameter = view.projected_diameter_px(radius_m, distance_m) + 2.0 * margin_px;
        // The object's extent, but never more than the screen shows.
        let want = [diameter.min(view.width_px), diameter.min(view.height_px())];
        let max_side = opts.max_side_px.clamp(1, MAX_RENDER_SIDE_PX / ss);
        let min_side = opts.min_side_px.clamp(1, max_side);
        let shrink = (max_side as f64 / want[0].max(want[1])).min(1.0);
        let side = |px: f64| ((px * shrink).ceil() as u32).clamp(min_side, max_side);
        let canvas_px = [side(want[0]), side(want[1])];
        // a small view gets more samples per pixel (up to 4×4): its silhouette error is then not
        // at the mercy of the sample grid, and its cost is the triangles, not the samples
        let across = canvas_px[0].max(canvas_px[1]);
        let ss = ss.max(MIN_SAMPLES_ACROSS.div_ceil(across).min(SMALL_VIEW_MAX_SUPERSAMPLE));
        let focal_rendered = view.focal_px() * shrink * ss as f64;
        let width = (canvas_px[0] * ss).min(crate::bake::raster::MAX_CANVAS_SIDE);
        let height = (canvas_px[1] * ss).min(crate::bake::raster::MAX_CANVAS_SIDE);
        let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
        let dir = [el.cos() * az.sin(), el.sin(), el.cos() * az.cos()];
        let cam = Camera::Perspective(PerspectiveView {
            eye: [0, 1, 2].map(|k| centre[k] + distance_m * dir[k]),
            target: centre,
            up: [0.0, 1.0, 0.0],
            fov_x_deg: (2.0 * (width as f64 * 0.5 / focal_rendered).atan()).to_degrees(),
            width,
            height,
            // Close enough to keep what is in front of the eye, far enough for depth precision.
            near: (distance_m * 1e-3).max(1e-4),
        });
        ViewShot { cam, canvas_px, shrink, supersample: ss }
    }

    fn render(&self, r: &Renderable) -> Image {
        match self.cam.canvas([0.0; 4]) {
            Ok(mut canvas) => {
                draw(&mut canvas, &self.cam, r);
                Image::from_canvas_owned(canvas)
            }
            // Cannot happen for the sizes above; an empty image keeps the analyzer total.
            Err(_) => Image { width: 0, height: 0, pixels: Vec::new() },
        }
    }

    /// (error in screen pixels, canvas size in output pixels, screen pixels per rendered pixel).
    fn compare(&self, reference: &Image, candidate: &Image, cutoff: f32) -> (ImageError, [u32; 2], f64) {
        let mut error = compare(reference, candidate, cutoff, self.supersample);
        error.edge_error_px /= self.shrink;
        (error, self.canvas_px, 1.0 / self.shrink)
    }
}

fn draw(canvas: &mut Canvas, cam: &Camera, r: &Renderable) {
    const IDENTITY: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
    // Serial inside a view: the views themselves run in parallel.
    let opts = RenderOptions { use_vertex_colors: false, shading: Shading::Unlit, parallel: false };
    render_mesh(canvas, cam, &IDENTITY, r.mesh, r.materials, r.textures, &opts);
}

/// (switch distance, never passes) from the rows in increasing distance.
fn switch_distance(rows: &[DistanceError], max_error_px: f64) -> (f64, bool) {
    let Some(last_fail) = rows.iter().rposition(|r| !r.passes) else {
        return (0.0, false);
    };
    let Some(pass) = rows.get(last_fail + 1) else {
        return (rows[last_fail].distance_m, true);
    };
    let fail = &rows[last_fail];
    let (e_f, e_p, tau) = (fail.worst_edge_error_px, pass.worst_edge_error_px, max_error_px);
    let (l_f, l_p) = (fail.distance_m.ln(), pass.distance_m.ln());
    // Where the error crosses the tolerance: linear in log-log when both errors are positive
    // (error ∝ 1/distance is a straight line there), else linear in error against log distance.
    let t = if e_p > 0.0 && tau > 0.0 && e_f.is_finite() {
        (e_f.ln() - tau.ln()) / (e_f.ln() - e_p.ln())
    } else if e_f.is_finite() && e_f > e_p {
        (e_f - tau) / (e_f - e_p)
    } else {
        1.0
    };
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 1.0 };
    ((l_f + t * (l_p - l_f)).exp(), false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Primitive;

    fn row(distance_m: f64, worst: f64) -> DistanceError {
        DistanceError {
            distance_m,
            worst_iou: 1.0,
            mean_iou: 1.0,
            worst_color_rmse: 0.0,
            mean_color_rmse: 0.0,
            worst_edge_error_px: worst,
            mean_edge_error_px: worst,
            passes: worst <= 1.0,
            canvas_px: [16, 16],
            screen_px_per_rendered_px: 1.0,
        }
    }

    /// Narrows the bracket (fail at lattice point 0, pass at `steps`) of an error curve `e(j)` as
    /// the chain search does: the final bracket and the probes made.
    fn narrow(guided: bool, bisections: usize, e: &dyn Fn(i64) -> f64) -> ((i64, i64), usize) {
        let steps = 1i64 << bisections;
        let mut s = LevelSearch::default();
        s.record(0, row(0.0, e(0)));
        s.record(steps, row(0.0, e(steps)));
        let rounds = if guided { 3 * bisections + 2 } else { bisections };
        let mut probes = 0;
        for _ in 0..rounds {
            let Some(j) = s.next_probe(guided, 1.0) else { break };
            assert!(j > s.fail.unwrap().0 && j < s.pass.unwrap().0, "probe {j} outside the bracket");
            s.record(j, row(0.0, e(j)));
            probes += 1;
        }
        ((s.fail.unwrap().0, s.pass.unwrap().0), probes)
    }

    proptest::proptest! {
        #[test]
        fn a_guided_narrowing_ends_where_bisection_does_on_a_monotone_error(
            crossing in 0.01f64..0.99,
            slope in 0.3f64..3.0,
            bisections in 1usize..6,
        ) {
            // error = (distance / crossing distance)^(-slope): 1 px at `crossing` of the octave
            let steps = (1i64 << bisections) as f64;
            let e = |j: i64| 2f64.powf(-slope * (j as f64 / steps - crossing));
            let (guided, probes) = narrow(true, bisections, &e);
            let (bisected, _) = narrow(false, bisections, &e);
            proptest::prop_assert_eq!(guided, bisected);
            proptest::prop_assert_eq!(guided.1 - guided.0, 1);
            proptest::prop_assert!(probes <= 3 * bisections + 2);
        }
    }

    #[test]
    fn a_guided_narrowing_closes_a_1_over_d_bracket_in_two_probes() {
        // error ∝ 1/d crossing 1 px at 2^(2.6/8) of the octave: probe 3 passes, 2 fails
        let e = |j: i64| 2f64.powf(-(j as f64 - 2.6) / 8.0);
        assert_eq!(narrow(true, 3, &e), ((2, 3), 2));
        assert_eq!(narrow(false, 3, &e), ((2, 3), 3));
        // a curve that is not a power law still ends at the crossing, bisecting when a pair of
        // probes does not halve the bracket: flat until 6.5, then a cliff
        let cliff = |j: i64| if (j as f64) < 6.5 { 1.5 } else { 0.2 };
        assert_eq!(narrow(true, 3, &cliff).0, (6, 7));
    }

    #[test]
    fn switch_distance_interpolates_in_log_log() {
        // error = 40 / d: crosses 1 px at 40 m exactly
        let rows: Vec<DistanceError> = [10.0, 20.0, 80.0, 160.0].iter().map(|&d| row(d, 40.0 / d)).collect();
        let (d, never) = switch_distance(&rows, 1.0);
        assert!((d - 40.0).abs() < 1e-9 && !never, "{d}");
        // a later failure moves the switch past it
        let mut bumpy = rows.clone();
        bumpy[3] = row(160.0, 1.5);
        let (d, never) = switch_distance(&bumpy, 1.0);
        assert!((d - 160.0).abs() < 1e-9 && never);
        let all_pass: Vec<DistanceError> = [10.0, 20.0].iter().map(|&d| row(d, 0.0)).collect();
        assert_eq!(switch_distance(&all_pass, 1.0), (0.0, false));
        // a perfect pass after a failure: linear in error
        let (d, _) = switch_distance(&[row(10.0, 3.0), row(20.0, 0.0)], 1.0);
        assert!(d > 10.0 && d < 20.0);
        assert_eq!(switch_distance(&[], 1.0), (0.0, false));
    }

    #[test]
    fn an_impostor_view_sees_the_nearest_card_turned_to_face_it() {
        let empty = Mesh::default();
        let r = Renderable { mesh: &empty, materials: &[], textures: &[] };
        let cards = Candidate::PerAzimuth(vec![r; 8]);
        let pick = |az: f64| cards.seen_from(az).map(|(c, turn)| (c.mesh as *const Mesh, turn));
        assert_eq!(pick(45.0).map(|p| p.1), Some(0.0));
        let (_, t) = pick(30.0).unwrap();
        assert!((t + 15.0).abs() < 1e-12, "{t}");
        let (_, t) = pick(350.0).unwrap();
        assert!((t + 10.0).abs() < 1e-12, "{t}");
        assert!(Candidate::PerAzimuth(Vec::new()).seen_from(0.0).is_none());
        // a card facing +Z (azimuth 0°) turned by 90° faces +X (azimuth 90°), about the centre
        let quad = Primitive {
            positions: vec![[1.0, 0.0, 2.0], [3.0, 0.0, 2.0], [3.0, 1.0, 2.0]],
            normals: vec![[0.0, 0.0, 1.0]; 3],
            indices: vec![0, 1, 2],
            ..Primitive::default()
        };
        let m = Mesh { name: String::new(), primitives: vec![quad], extras: None };
        let t = turned(&m, [2.0, 0.0, 2.0], 90.0);
        let p = &t.primitives[0];
        for (got, want) in p.positions.iter().zip([[2.0, 0.0, 3.0], [2.0, 0.0, 1.0], [2.0, 1.0, 1.0]]) {
            assert!(got.iter().zip(want).all(|(g, w)| (g - w).abs() < 1e-6), "{got:?} {want:?}");
        }
        assert!((p.normals[0][0] - 1.0).abs() < 1e-6 && p.normals[0][2].abs() < 1e-6);
    }

    #[test]
    fn screen_coverage_and_its_inverse() {
        let v = ScreenView::default();
        assert!((v.focal_px() - 1662.768).abs() < 1e-3);
        let c = v.screen_coverage(0.5, 20.0);
        // small-angle: 2 r f / d / 1080
        assert!((c - 2.0 * 0.5 * v.focal_px() / 20.0 / 1080.0).abs() < 1e-4);
        assert!((v.distance_for_coverage(0.5, c) - 20.0).abs() < 1e-9);
        assert_eq!(v.screen_coverage(1.0, 0.5), f64::INFINITY);
        assert!(v.check().is_ok());
        for bad in [
            ScreenView { width_px: f64::NAN, ..v },
            ScreenView { fov_x_deg: 0.0, ..v },
            ScreenView { max_error_px: -1.0, ..v },
        ] {
            assert!(bad.check().is_err());
            let empty = Mesh::default();
            let r = Renderable { mesh: &empty, materials: &[], textures: &[] };
            let report = lod_image_error(&r, &r, &bad, &[10.0]);
            assert!(report.problem.is_some() && report.never_passes && report.distances.is_empty());
        }
    }
}
