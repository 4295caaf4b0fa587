//! Levels of detail with switch distances from *measured* geometric error: each level is an
//! error-bounded TIN (greedy insertion, `terrain::tin`), measured by the analyzer (`terrain::error`),
//! and switched where its error projects below a pixel tolerance (the screen-space error metric of
//! Lindstrom & Pascucci and of chunked LOD, Ulrich 2002: ρ = ε · H / (2 d tan(fov/2))).
//!
//! Convention for a chain of levels 0..n (0 the finest): level k is used from distance `d_k` on, up
//! to (not including) `d_{k+1}`; the last level is used from its distance to infinity. `d_0 = 0`
//! always (the finest level is what there is close up), and for k ≥ 1
//! `d_k = ε_k · screen_height_px / (2 · tan(fov_y/2) · max_screen_error_px)` with ε_k the level's
//! measured max error: from `d_k` on, level k's error covers at most `max_screen_error_px` pixels.
//! Distances are to the nearest point of the geometry (the error can be anywhere on it).

use std::time::Instant;

use rayon::prelude::*;

use crate::heightfield::Heightfield;
#[cfg(test)]
use crate::terrain::budget::DEFAULT_MAX_VERTICES;
use crate::terrain::error::{measure, ErrorStats};
use crate::terrain::tin::{tin, TinOptions};
use crate::terrain::{SampleMesh, TerrainError};

/// Screen-space error budget of the default policy (`[lod] max_pixel_error`): 2 px on a
/// 1080-px-high screen with a 60° vertical field of view. Chosen so levels switch where engines
/// switch them: a 12–15 m tree reaches its impostor at roughly 250–330 m, grass clumps their cards
/// at 10–20 m, and the coarsest level of a species is culled where its height spans 2 px.
pub const DEFAULT_MAX_PIXEL_ERROR: f64 = 2.0;

/// The viewer the switch distances are computed for: the scene's LoD policy (`[lod]`), shared by
/// the terrain chain, every plant chain and the cull distances.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LodView {
    /// Height of the screen (or render target) in pixels.
    pub screen_height_px: f64,
    /// Vertical field of view in degrees (0 < fov < 180).
    pub fov_y_deg: f64,
    /// Largest geometric error allowed on screen, in pixels (> 0).
    pub max_screen_error_px: f64,
    /// Screen width / height; only the screen-coverage form ([`lod_screen_coverage`]) needs it.
    pub aspect: f64,
}

impl Default for LodView {
    fn default() -> Self {
        LodView {
            screen_height_px: 1080.0,
            fov_y_deg: 60.0,
            max_screen_error_px: DEFAULT_MAX_PIXEL_ERROR,
            aspect: 16.0 / 9.0,
        }
    }
}

impl LodView {
    /// Pixels per metre at distance 1 m: H / (2 tan(fov/2)).
    fn pixels_per_metre_at_1m(&self) -> f64 {
        self.screen_height_px / (2.0 * (self.fov_y_deg.to_radians() * 0.5).tan())
    }

    /// Distance (metres) beyond which an error of `error_m` projects to less than
    /// `max_screen_error_px` pixels: d = ε · H / (2 tan(fov/2) · τ).
    pub fn switch_distance(&self, error_m: f64) -> f64 {
        error_m * self.pixels_per_metre_at_1m() / self.max_screen_error_px
    }

    /// Pixels an error of `error_m` covers at `distance_m` (the inverse of [`LodView::switch_distance`]).
    pub fn projected_error_px(&self, error_m: f64, distance_m: f64) -> f64 {
        error_m * self.pixels_per_metre_at_1m() / distance_m
    }

    /// The same viewer as the image analyzer's [`ScreenView`] (screen width and horizontal field of
    /// view, the same pixel budget).
    pub fn screen_view(&self) -> crate::bake::ScreenView {
        let fov_x = 2.0 * ((self.fov_y_deg.to_radians() * 0.5).tan() * self.aspect).atan();
        crate::bake::ScreenView {
            width_px: self.screen_height_px * self.aspect,
            fov_x_deg: fov_x.to_degrees().min(179.0),
            max_error_px: self.max_screen_error_px,
        }
    }

    /// Distance at which something `size_m` tall spans `max_screen_error_px` pixels: the default
    /// cull distance of a species (its coarsest level is then within the error budget of nothing).
    pub fn cull_distance(&self, size_m: f64) -> f64 {
        self.switch_distance(size_m.max(0.0))
    }

    /// MSFT_lod screen coverage ([`lod_screen_coverage`]) when the eye is `centre_distance_m` from
    /// the bounding-sphere centre (the plant analyzers measure distances to the centre).
    pub fn coverage_at_centre_distance(&self, radius_m: f64, centre_distance_m: f64) -> f64 {
        lod_screen_coverage(radius_m, (centre_distance_m - radius_m).max(0.0), self)
    }

    /// Checks the view (every field finite and in range); the message names the bad field.
    pub fn validate(&self) -> Result<(), String> {
        self.check().map_err(|e| e.to_string())
    }

    fn check(&self) -> Result<(), LodError> {
        let ok = self.screen_height_px.is_finite()
            && self.screen_height_px > 0.0
            && self.fov_y_deg.is_finite()
            && self.fov_y_deg > 0.0
            && self.fov_y_deg < 180.0
            && self.max_screen_error_px.is_finite()
            && self.max_screen_error_px > 0.0
            && self.aspect.is_finite()
            && self.aspect > 0.0;
        if ok {
            Ok(())
        } else {
            Err(LodError::InvalidView { view: *self })
        }
    }
}

/// One level of a terrain LoD chain.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LodLevel {
    /// 0 is the finest.
    pub level: usize,
    pub max_error_requested_m: f64,
    pub mesh: SampleMesh,
    /// What the analyzer measured for `mesh` (over every sample).
    pub stats: ErrorStats,
    /// Use this level from this distance on (see the module docs); 0 for level 0.
    pub switch_distance_m: f64,
    /// True if the triangle limit stopped refinement before the requested error was reached (the
    /// measured error in `stats` is then above `max_error_requested_m`).
    pub hit_triangle_limit: bool,
    /// Time to mesh and measure this level.
    pub seconds: f64,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LodError {
    #[error("a LoD chain needs at least one max error (e.g. lods = [1, 4, 16])")]
    NoLevels,
    #[error("LoD max error #{index} is {value}: each must be a finite number of metres ≥ 0")]
    InvalidError { index: usize, value: f64 },
    #[error(
        "LoD max errors must be strictly increasing, finest first: #{index} is {value} m after {previous} m \
         (e.g. lods = [1, 4, 16])"
    )]
    NotIncreasing { index: usize, previous: f64, value: f64 },
    #[error(
        "invalid LoD view {view:?}: screen height, pixel tolerance and aspect must be > 0 and the field of \
         view between 0 and 180 degrees"
    )]
    InvalidView { view: LodView },
    #[error("LoD level {level}: {error}")]
    Terrain { level: usize, error: TerrainError },
}

/// Checks that `max_errors_m` is a usable chain: not empty, finite, ≥ 0, strictly increasing.
pub fn check_max_errors(max_errors_m: &[f64]) -> Result<(), LodError> {
    if max_errors_m.is_empty() {
        return Err(LodError::NoLevels);
    }
    for (index, &value) in max_errors_m.iter().enumerate() {
        if !value.is_finite() || value < 0.0 {
            return Err(LodError::InvalidError { index, value });
        }
        if index > 0 && value <= max_errors_m[index - 1] {
            return Err(LodError::NotIncreasing { index, previous: max_errors_m[index - 1], value });
        }
    }
    Ok(())
}

/// Builds one TIN per requested max error (finest first), measures each with the analyzer and
/// assigns switch distances from the measured errors (module docs give the convention).
///
/// Greedy insertion inserts samples in an order that does not depend on the bound, so each coarser
/// level is a prefix of the finer one's insertions: triangle counts never increase along the chain
/// and measured errors never decrease. Distances are made non-decreasing regardless (each is at
/// least the previous one), which only matters when a triangle limit cuts levels short.
/// Levels are meshed in parallel; the result is the same at any thread count.
pub fn terrain_lod_chain(
    hf: &Heightfield,
    max_errors_m: &[f64],
    max_triangles: Option<usize>,
    max_vertices: usize,
    view: &LodView,
) -> Result<Vec<LodLevel>, LodError> {
    terrain_lod_chain_in_bands(hf, max_errors_m, max_triangles, max_vertices, 0, view)
}

/// [`terrain_lod_chain`] with every level cut along the lines of chunks of `chunk_cells` cells and
/// meshed in bands of whole chunks ([`TinOptions::chunk_cells`]; 0: not chunked).
pub fn terrain_lod_chain_in_bands(
    hf: &Heightfield,
    max_errors_m: &[f64],
    max_triangles: Option<usize>,
    max_vertices: usize,
    chunk_cells: u32,
    view: &LodView,
) -> Result<Vec<LodLevel>, LodError> {
    check_chain(max_errors_m, view)?;
    let built: Vec<Result<LodLevel, LodError>> = max_errors_m
        .par_iter()
        .enumerate()
        .map(|(level, &max_error_m)| {
            let start = Instant::now();
            let r = tin(hf, &TinOptions { max_error_m, max_triangles, max_vertices, chunk_cells })
                .map_err(|error| LodError::Terrain { level, error })?;
            let stats = measure(hf, &r.mesh);
            Ok(LodLevel {
                level,
                max_error_requested_m: max_error_m,
                mesh: r.mesh,
                stats,
                switch_distance_m: 0.0,
                hit_triangle_limit: r.hit_triangle_limit,
                seconds: start.elapsed().as_secs_f64(),
            })
        })
        .collect();
    let mut levels = built.into_iter().collect::<Result<Vec<_>, _>>()?;
    assign_switch_distances(&mut levels, view);
    Ok(levels)
}

/// What a chain of `max_errors_m` (finest first) under `view` must be, checked before meshing it.
pub fn check_chain(max_errors_m: &[f64], view: &LodView) -> Result<(), LodError> {
    check_max_errors(max_errors_m)?;
    view.check()
}

/// Each level's switch distance from its measured error (level 0 from 0 m), never nearer than the
/// previous level's (the module docs give the convention).
pub fn assign_switch_distances(levels: &mut [LodLevel], view: &LodView) {
    let mut previous = 0.0f64;
    for l in levels.iter_mut().skip(1) {
        l.switch_distance_m = view.switch_distance(l.stats.max_error_m).max(previous);
        previous = l.switch_distance_m;
    }
}

/// Screen coverage as Babylon.js computes it for MSFT_lod (`Mesh.getLOD` with screen coverage):
/// the area of the bounding sphere's projected disc over the screen's area,
/// π r² / (aspect · (2 D tan(fov/2))²), D the distance from the camera to the sphere's *centre*.
///
/// `nearest_distance_m` is a switch distance in this module's sense (to the nearest point of the
/// object), so D = nearest_distance_m + radius_m: when the viewer is D from the centre it is at least
/// `nearest_distance_m` from every point of the object, so the switch keeps the pixel-error bound.
/// Capped at 1 (the object fills the screen).
pub fn lod_screen_coverage(radius_m: f64, nearest_distance_m: f64, view: &LodView) -> f64 {
    let centre = nearest_distance_m.max(0.0) + radius_m.max(0.0);
    if centre <= 0.0 {
        return 1.0;
    }
    let screen_h = 2.0 * centre * (view.fov_y_deg.to_radians() * 0.5).tan();
    let c = std::f64::consts::PI * radius_m * radius_m / (view.aspect * screen_h * screen_h);
    if c.is_finite() {
        c.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Screen size as Unreal measures a LoD's `ScreenSize` and Unity a LODGroup's relative height (with
/// the LODGroup's `size` set to the bounding sphere's diameter): the sphere's diameter over the
/// screen's height at the sphere's centre distance D, r / (D · tan(fov/2)). From the MSFT_lod
/// coverage c of the same view ([`lod_screen_coverage`]): 2 √(c · aspect / π). A coverage of 1 (the
/// object fills the screen, as LoD0 always does) gives 1, the engines' LoD0 convention.
pub fn screen_size_from_coverage(coverage: f64, view: &LodView) -> f64 {
    if !(coverage < 1.0) {
        return 1.0;
    }
    2.0 * (coverage.max(0.0) * view.aspect / std::f64::consts::PI).sqrt()
}

/// The node `extras.MSFT_screencoverage` array for a chain: one value per level, finest first;
/// value k is the smallest coverage at which level k is shown (the coverage at `d_{k+1}`, where
/// level k+1 takes over), and the last is 0 so the coarsest level is never culled.
/// `radius_m` is the bounding-sphere radius of the object (e.g. of one terrain chunk).
pub fn msft_screen_coverage(levels: &[LodLevel], radius_m: f64, view: &LodView) -> Vec<f32> {
    let mut out: Vec<f32> =
        levels.iter().skip(1).map(|next| lod_screen_coverage(radius_m, next.switch_distance_m, view) as f32).collect();
    if !levels.is_empty() {
        out.push(0.0);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn screen_size_is_the_sphere_diameter_over_the_screen_height() {
        let view = LodView::default();
        for (r, d) in [(1.0, 50.0), (7.5, 300.0), (0.2, 3.0)] {
            let c = lod_screen_coverage(r, d - r, &view);
            let want = r / (d * (view.fov_y_deg.to_radians() * 0.5).tan());
            let got = screen_size_from_coverage(c, &view);
            assert!((got - want).abs() < 1e-12 * want.max(1.0), "r {r} at {d} m: {got} vs {want}");
        }
        assert_eq!(screen_size_from_coverage(1.0, &view), 1.0);
    }

    #[test]
    fn formula_matches_the_definition() {
        let v = LodView { max_screen_error_px: 1.0, ..LodView::default() };
        // 1080 px, 60°: H / (2 tan 30°) = 1080 / 1.1547 = 935.3 px per metre at 1 m.
        let d = v.switch_distance(1.0);
        assert!((d - 1080.0 / (2.0 * (30.0f64).to_radians().tan())).abs() < 1e-9);
        assert!((d - 935.307).abs() < 1e-3, "{d}");
        assert!((v.projected_error_px(1.0, d) - 1.0).abs() < 1e-12);
        let v2 = LodView { max_screen_error_px: 2.0, ..v };
        assert!((v2.switch_distance(1.0) - d / 2.0).abs() < 1e-9);
    }

    #[test]
    fn switch_distances_rise_with_level_and_fall_as_the_budget_grows() {
        let hf = crate::synth::fractal(65, 65, 2.0, 40.0, 0.5, 3);
        let errors = [0.1, 0.5, 2.0, 8.0];
        let mut previous: Option<Vec<f64>> = None;
        for budget in [0.5, 1.0, 2.0, 4.0, 8.0] {
            let view = LodView { max_screen_error_px: budget, ..LodView::default() };
            let chain = terrain_lod_chain(&hf, &errors, None, DEFAULT_MAX_VERTICES, &view).unwrap();
            let d: Vec<f64> = chain.iter().map(|l| l.switch_distance_m).collect();
            assert_eq!(d[0], 0.0);
            assert!(d.windows(2).all(|w| w[1] > w[0]), "budget {budget}: {d:?}");
            // at its switch distance each level's measured error projects to the budget
            for l in chain.iter().skip(1) {
                let px = view.projected_error_px(l.stats.max_error_m, l.switch_distance_m);
                assert!(px <= budget * (1.0 + 1e-9), "{px} px > {budget}");
            }
            if let Some(p) = &previous {
                assert!(d.iter().zip(p).skip(1).all(|(now, before)| now < before), "{d:?} vs {p:?}");
            }
            previous = Some(d);
        }
    }

    #[test]
    fn bad_errors_are_refused() {
        assert_eq!(check_max_errors(&[]), Err(LodError::NoLevels));
        assert!(matches!(check_max_errors(&[1.0, 1.0]), Err(LodError::NotIncreasing { index: 1, .. })));
        assert!(matches!(check_max_errors(&[2.0, 1.0]), Err(LodError::NotIncreasing { .. })));
        assert!(matches!(check_max_errors(&[f64::NAN]), Err(LodError::InvalidError { index: 0, .. })));
        assert!(matches!(check_max_errors(&[-1.0]), Err(LodError::InvalidError { .. })));
        assert_eq!(check_max_errors(&[0.0, 0.5, 4.0]), Ok(()));
        let hf = crate::synth::fractal(9, 9, 1.0, 10.0, 0.5, 1);
        let bad_view = LodView { fov_y_deg: 180.0, ..LodView::default() };
        assert!(matches!(
            terrain_lod_chain(&hf, &[1.0], None, DEFAULT_MAX_VERTICES, &bad_view),
            Err(LodError::InvalidView { .. })
        ));
        let tiny = Heightfield { width: 1, height: 1, heights: vec![0.0], cell_size_m: 1.0, exact: None };
        assert!(matches!(
            terrain_lod_chain(&tiny, &[1.0], None, DEFAULT_MAX_VERTICES, &LodView::default()),
            Err(LodError::Terrain { level: 0, .. })
        ));
    }

    #[test]
    fn coverage_is_babylons_disc_over_screen() {
        let v = LodView { aspect: 1.0, fov_y_deg: 90.0, ..LodView::default() };
        // r = 1 at centre distance 1 with tan(45°) = 1: π / 4.
        let c = lod_screen_coverage(1.0, 0.0, &v);
        assert!((c - std::f64::consts::PI / 4.0).abs() < 1e-12);
        // farther: falls with the square of the centre distance
        let c3 = lod_screen_coverage(1.0, 2.0, &v);
        assert!((c3 - c / 9.0).abs() < 1e-12);
        assert_eq!(lod_screen_coverage(0.0, 0.0, &v), 1.0);
    }
}
