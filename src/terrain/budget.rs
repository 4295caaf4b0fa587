//! The meshing work budget: how many vertices a terrain mesher may make, an estimate of what a
//! map needs checked before any meshing, and the count the TIN mesher checks as it inserts.
//!
//! Work and memory grow with the vertices a mesh needs, which the file size does not show: an
//! 11 KB 16-bit checkerboard PNG of 2049² samples needs every one of its 4.2 M samples as a vertex
//! at any bound under its step (16.9 s, 982 MB here; 8193² would be ~16× that). The budget turns
//! such inputs into a clear error in well under a second instead.

use rayon::prelude::*;

use crate::heightfield::Heightfield;

/// The default vertex budget of one terrain mesh (2²¹): about 4 M triangles, some 9 s and 500 MB
/// of meshing on a 2-core machine. Real maps within the default `--max-samples` rarely need more at
/// a metre's bound (a 1024² 16-bit mountain map at 0.5 m: 0.91 M). Raise it with
/// `--max-vertices` / `max_vertices` where the time and memory are available.
pub const DEFAULT_MAX_VERTICES: usize = 1 << 21;

/// Samples that stand more than `max_error_m` above or below the mean of their four neighbours
/// (interior samples; the borders are not counted).
///
/// An estimate of the vertices a mesh within `max_error_m` needs, and below it on every map we
/// measured (estimate ÷ the greedy TIN's vertex count: 0.86–0.92 on Mt Fuji at 0.5–1 m, 0.49 at
/// 5 m; 0.96 on a 1024² mountain map at 1 m, 0.57 at 20 m; 0.11–0.86 on an SRTM tile; 1.00 on a
/// checkerboard): a sharp sample is one no plane through its neighbours comes near, and a mesh
/// without a vertex there has to reach it with a plane through vertices further away. So a map
/// whose estimate is over the budget is refused before meshing, and the mesher's own count stops
/// the rest. Rows are counted in parallel; the sum does not depend on the thread count.
pub fn sharp_samples(hf: &Heightfield, max_error_m: f64) -> usize {
    let (w, h) = (hf.width, hf.height);
    if w < 3 || h < 3 {
        return 0;
    }
    let bound = 4.0 * max_error_m;
    (1..h - 1)
        .into_par_iter()
        .map(|j| {
            let row = |r: usize| &hf.heights[r * w..(r + 1) * w];
            let (up, mid, down) = (row(j - 1), row(j), row(j + 1));
            (1..w - 1)
                .filter(|&i| {
                    let around = mid[i - 1] as f64 + mid[i + 1] as f64 + up[i] as f64 + down[i] as f64;
                    (4.0 * mid[i] as f64 - around).abs() > bound
                })
                .count()
        })
        .sum()
}

/// Why a mesh would go over its vertex budget.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OverBudget {
    /// Known before meshing: a grid's vertex count, or a TIN's estimate ([`sharp_samples`]).
    Predicted { vertices: usize },
    /// The TIN mesher reached the budget with the error still at `error_m`.
    Reached { error_m: f64 },
    /// The regions of a large map, meshed in parallel, needed more vertices together than the
    /// budget (found while meshing, or when they were joined; `terrain/regions.rs`).
    Exceeded,
}

/// Refuses a TIN over the budget before meshing when the map's sharp samples alone exceed it
/// (only counted when the map has more samples than the budget: otherwise it cannot be exceeded).
pub(crate) fn check_tin(hf: &Heightfield, max_error_m: f64, max_vertices: usize) -> Result<(), OverBudget> {
    if hf.width.saturating_mul(hf.height) <= max_vertices {
        return Ok(());
    }
    let vertices = sharp_samples(hf, max_error_m);
    if vertices > max_vertices {
        return Err(OverBudget::Predicted { vertices });
    }
    Ok(())
}

/// Refuses a grid over the budget: its vertex count is known exactly.
pub(crate) fn check_grid(width: usize, height: usize, step: usize, max_vertices: usize) -> Result<(), OverBudget> {
    let along = |n: usize| (n - 1).div_ceil(step.max(1)) + 1;
    let vertices = along(width).saturating_mul(along(height));
    if vertices > max_vertices {
        return Err(OverBudget::Predicted { vertices });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> Heightfield {
        let heights = (0..w * h).map(|k| f(k % w, k / w)).collect();
        Heightfield { width: w, height: h, heights, cell_size_m: 1.0, exact: None }
    }

    #[test]
    fn a_checkerboard_is_all_sharp_and_a_plane_or_a_straight_ridge_is_not() {
        let board = field(33, 17, |i, j| if (i + j) % 2 == 0 { 0.0 } else { 10.0 });
        assert_eq!(sharp_samples(&board, 1.0), 31 * 15);
        assert_eq!(sharp_samples(&board, 10.0), 0, "deviation 10 is not over a bound of 10");
        let plane = field(40, 40, |i, j| 3.0 * i as f32 - 2.0 * j as f32 + 7.0);
        assert_eq!(sharp_samples(&plane, 0.0), 0);
        // a ridge along i: each ridge sample is 20 m over its two neighbours across, level along
        let ridge = field(40, 40, |_, j| if j == 20 { 20.0 } else { 0.0 });
        assert_eq!(sharp_samples(&ridge, 9.0), 38, "|4·20 − 2·20| = 40 > 36");
        assert_eq!(sharp_samples(&ridge, 10.0), 0);
    }

    #[test]
    fn the_budget_is_refused_before_meshing_when_the_estimate_or_the_grid_exceeds_it() {
        let board = field(65, 65, |i, j| if (i + j) % 2 == 0 { 0.0 } else { 10.0 });
        assert_eq!(check_tin(&board, 1.0, 1000), Err(OverBudget::Predicted { vertices: 63 * 63 }));
        assert_eq!(check_tin(&board, 1.0, 65 * 65), Ok(()), "a map within the budget in samples is not scanned");
        assert_eq!(check_tin(&board, 20.0, 1000), Ok(()));
        assert_eq!(check_grid(65, 65, 1, 4224), Err(OverBudget::Predicted { vertices: 4225 }));
        assert_eq!(check_grid(65, 65, 1, 4225), Ok(()));
        assert_eq!(check_grid(65, 65, 3, 23 * 23), Ok(()), "every 3rd sample and the last: 23 per side");
        assert_eq!(check_grid(65, 65, 3, 23 * 23 - 1), Err(OverBudget::Predicted { vertices: 23 * 23 }));
    }
}
