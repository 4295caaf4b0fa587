//! Draw calls: a primitive's triangles in index order, serially or in parallel over bands of rows
//! (each band drawing its triangles in that same order, so both give identical images).

use rayon::prelude::*;

use super::camera::{Camera, Projection};
use super::canvas::{Canvas, DrawOptions, DrawStats, Fragment};
use super::limits::BAND_ROWS;
use super::perspective::{draw_persp, raster_rows_persp, PerspSetup};
use super::scan::{pixel_rows, raster_rows, Setup};
use crate::mesh::Primitive;

impl Canvas {
    /// Draws `prim`'s triangles in index order with `shader` (None discards the fragment, e.g. for
    /// an alpha test). Serial, so the shader may keep state (`FnMut`).
    pub fn draw<F>(&mut self, proj: &Projection, prim: &Primitive, opts: &DrawOptions, mut shader: F) -> DrawStats
    where
        F: FnMut(&Fragment) -> Option<[f32; 4]>,
    {
        let setup = Setup::new(proj, prim, opts.cull);
        let mut stats = setup.stats;
        let tris: Vec<u32> = (0..setup.tris.len() as u32).collect();
        let (w, h) = (self.width, self.height);
        stats.fragments =
            raster_rows(&mut self.color, &mut self.depth, w, 0, h, &setup, prim, &tris, opts, &mut shader);
        stats
    }

    /// Like [`Canvas::draw`], in parallel over bands of rows with a stateless shader. The result is
    /// identical to [`Canvas::draw`]'s: each pixel sees its triangles in the same order.
    pub fn draw_par<F>(&mut self, proj: &Projection, prim: &Primitive, opts: &DrawOptions, shader: F) -> DrawStats
    where
        F: Fn(&Fragment) -> Option<[f32; 4]> + Sync,
    {
        let setup = Setup::new(proj, prim, opts.cull);
        let (w, h) = (self.width, self.height);
        let bins = Bins::new(setup.tris.iter().map(|t| pixel_rows(t.min[1], t.max[1], h)), h);
        let fragments = self.par_bands(&bins, |color, depth, y0, y1, tris| {
            let mut s = &shader;
            raster_rows(color, depth, w, y0, y1, &setup, prim, tris, opts, &mut s)
        });
        let mut stats = setup.stats;
        stats.fragments = fragments;
        stats
    }

    /// Draws `prim` (object coordinates, placed in the world by `object_to_world`: a 3×4 affine
    /// matrix, columns x, y, z axes and translation) as `cam` sees it. Orthographic: exactly
    /// [`Canvas::draw`] with the view's projection. Perspective: clipped at the near plane,
    /// attributes perspective-correct, depth the distance along the view axis. Serial (`FnMut`).
    /// A perspective camera that fails [`PerspectiveView::check`] draws nothing (all skipped).
    pub fn draw_camera<F>(
        &mut self,
        cam: &Camera,
        object_to_world: &[[f64; 4]; 3],
        prim: &Primitive,
        opts: &DrawOptions,
        mut shader: F,
    ) -> DrawStats
    where
        F: FnMut(&Fragment) -> Option<[f32; 4]>,
    {
        match cam {
            Camera::Ortho(v) => self.draw(&v.projection().then_from(object_to_world), prim, opts, shader),
            Camera::Perspective(v) => {
                let (w, h) = (self.width, self.height);
                draw_persp(&mut self.color, &mut self.depth, w, h, v, object_to_world, prim, opts, &mut shader)
            }
        }
    }

    /// Like [`Canvas::draw_camera`], in parallel over bands of rows; identical output.
    pub fn draw_camera_par<F>(
        &mut self,
        cam: &Camera,
        object_to_world: &[[f64; 4]; 3],
        prim: &Primitive,
        opts: &DrawOptions,
        shader: F,
    ) -> DrawStats
    where
        F: Fn(&Fragment) -> Option<[f32; 4]> + Sync,
    {
        match cam {
            Camera::Ortho(v) => self.draw_par(&v.projection().then_from(object_to_world), prim, opts, shader),
            Camera::Perspective(v) => {
                let setup = PerspSetup::new(v, object_to_world, prim, opts.cull);
                let (w, h) = (self.width, self.height);
                let bins = Bins::new(setup.tris.iter().map(|t| pixel_rows(t.min[1], t.max[1], h)), h);
                let fragments = self.par_bands(&bins, |color, depth, y0, y1, tris| {
                    let mut s = &shader;
                    raster_rows_persp(color, depth, w, y0, y1, &setup, prim, tris, opts, &mut s)
                });
                let mut stats = setup.stats;
                stats.fragments = fragments;
                stats
            }
        }
    }

    /// Runs `band` on every band of [`BAND_ROWS`] rows in parallel with that band's triangles (in
    /// draw order) and sums what it returns.
    fn par_bands<B>(&mut self, bins: &Bins, band: B) -> u64
    where
        B: Fn(&mut [[f32; 4]], &mut [f32], u32, u32, &[u32]) -> u64 + Sync,
    {
        let (w, h) = (self.width, self.height);
        let band_px = (BAND_ROWS * w) as usize;
        self.color
            .par_chunks_mut(band_px)
            .zip(self.depth.par_chunks_mut(band_px))
            .enumerate()
            .map(|(b, (color, depth))| {
                let y0 = b as u32 * BAND_ROWS;
                let y1 = (y0 + BAND_ROWS).min(h);
                band(color, depth, y0, y1, bins.band(b))
            })
            .sum()
    }
}

/// Triangles binned by the bands of [`BAND_ROWS`] rows their pixel rows touch; a counting sort, so
/// each band lists its triangles in draw order.
struct Bins {
    offsets: Vec<usize>,
    binned: Vec<u32>,
}

impl Bins {
    fn new<I>(rows: I, height: u32) -> Bins
    where
        I: Iterator<Item = Option<(u32, u32)>> + Clone,
    {
        let bands = height.div_ceil(BAND_ROWS) as usize;
        let band_range =
            |r: Option<(u32, u32)>| r.map(|(y0, y1)| ((y0 / BAND_ROWS) as usize, ((y1 - 1) / BAND_ROWS) as usize));
        let mut counts = vec![0usize; bands + 1];
        for (b0, b1) in rows.clone().filter_map(band_range) {
            for c in &mut counts[b0..=b1] {
                *c += 1;
            }
        }
        let mut offsets = vec![0usize; bands + 1];
        for b in 0..bands {
            offsets[b + 1] = offsets[b] + counts[b];
        }
        let mut binned = vec![0u32; offsets[bands]];
        let mut fill = offsets.clone();
        for (k, r) in rows.enumerate() {
            if let Some((b0, b1)) = band_range(r) {
                for f in &mut fill[b0..=b1] {
                    binned[*f] = k as u32;
                    *f += 1;
                }
            }
        }
        Bins { offsets, binned }
    }

    fn band(&self, b: usize) -> &[u32] {
        &self.binned[self.offsets[b]..self.offsets[b + 1]]
    }
}

/// Draws a whole `draw_par`-style batch and sums the stats; a small helper for callers drawing
/// several primitives with one shader.
pub fn draw_all<'a, F>(
    canvas: &mut Canvas,
    proj: &Projection,
    prims: impl IntoIterator<Item = &'a Primitive>,
    opts: &DrawOptions,
    shader: F,
) -> DrawStats
where
    F: Fn(&Fragment) -> Option<[f32; 4]> + Sync,
{
    let mut total = DrawStats::default();
    for p in prims {
        total.add(&canvas.draw_par(proj, p, opts, &shader));
    }
    total
}
