//! Exact software triangle rasteriser: edge functions over the bounding box in fixed point with the
//! top-left fill rule (Pineda, "A parallel algorithm for polygon rasterization", SIGGRAPH 1988; the
//! rule and 8-bit sub-pixel snapping as in Direct3D 10+ rasterisation rules), z-buffer, attributes
//! interpolated at pixel centres with the barycentric weights the edge functions give.
//!
//! Conventions:
//! - Pixel (x, y) covers [x, x+1) × [y, y+1) in pixel coordinates, x right, y *down* the image; it
//!   is sampled at its centre (x + ½, y + ½). A pixel belongs to a triangle when its centre is
//!   inside, or on a top or left edge. Two triangles sharing an edge therefore write every pixel
//!   along it exactly once: no cracks, no double blends.
//! - Vertices are snapped to 1/256 pixel and the edge functions evaluated in `i64`, so the test is
//!   exact and the same for both triangles of a shared edge (floating-point edge functions are not
//!   antisymmetric, which is exactly what makes cracks).
//! - Depth: distance along the view's forward axis; smaller is nearer; the buffer starts at +∞ and a
//!   fragment passes when strictly nearer (so on ties the first triangle drawn wins, deterministically).
//! - Front faces are counter-clockwise *as seen on the image* (terrain seen from +Y is front facing).
//! - Colours are linear RGBA with straight (not premultiplied) alpha; PNG output is sRGB 8-bit.
//!
//! Two cameras. Orthographic ([`OrthoView`], any affine [`Projection`]): screen-space barycentrics are
//! the object-space ones. Perspective ([`PerspectiveView`]): triangles are clipped in view space
//! against the near plane and a guard band (Sutherland & Hodgman, "Reentrant polygon clipping",
//! CACM 1974) and attributes interpolated perspective-correctly, a/w and 1/w linear on the image
//! (Heckbert & Moreton, "Interpolation for polygon texture mapping and shading", 1991). Both share
//! the fixed-point scan and its fill rule. Triangles are drawn in index order; the parallel variants
//! split the canvas into bands of rows, each drawing its triangles in that same order, so the output
//! is identical to the serial one.

use std::path::Path;

use rayon::prelude::*;

use crate::color::linear_to_srgb;
use crate::export::{write_atomic, ExportError};
use crate::math::{cross3, dot3, normalize3, sub3};
use crate::mesh::Primitive;

/// Largest canvas side in pixels: keeps canvases within a few GB and the fixed-point arithmetic far
/// inside `i64` (see [`MAX_VERTEX_SUBPIXELS`]).
pub const MAX_CANVAS_SIDE: u32 = 16384;

/// Sub-pixel bits of the snapped vertex positions (1/256 pixel, as GPUs do).
const SUBPIXEL_BITS: u32 = 8;
const SUBPIXEL: i64 = 1 << SUBPIXEL_BITS;

/// Vertices farther than this from the canvas origin (in sub-pixels, = 2^20 pixels) are not drawn:
/// it keeps every edge-function product below 2^60. Such triangles are counted in
/// [`DrawStats::skipped`] (an orthographic view that far off is a caller bug, not a silent loss).
pub const MAX_VERTEX_SUBPIXELS: i64 = 1 << 28;

/// Rows per parallel band: small enough to balance two to many cores, large enough that few
/// triangles straddle bands (each straddling triangle is set up once per band).
const BAND_ROWS: u32 = 16;

#[derive(Debug, thiserror::Error)]
pub enum RasterError {
    #[error("canvas of {width}×{height} pixels is not supported: each side must be 1 to {MAX_CANVAS_SIDE} pixels")]
    CanvasSize { width: u32, height: u32 },
    #[error("perspective camera: {0}")]
    Camera(String),
    #[error("could not encode the image as PNG: {0}")]
    Encode(String),
    #[error(transparent)]
    Write(#[from] ExportError),
}

/// An image being drawn: linear RGBA colour and depth per pixel, row-major from the top-left.
#[derive(Debug, Clone, PartialEq)]
pub struct Canvas {
    pub width: u32,
    pub height: u32,
    pub color: Vec<[f32; 4]>,
    pub depth: Vec<f32>,
}

/// An orthographic camera: world point `p` lands at pixel coordinates
/// x = (p − origin)·right · ppm, y = −(p − origin)·up · ppm, depth = (p − origin)·forward.
/// `origin` is the world point at the image's top-left *corner*; `right`, `up`, `forward` should be
/// orthonormal (they are used as given, so a scaled axis scales the image). Forward points away from
/// the viewer; for a right-handed camera forward = up × right (then front faces, counter-clockwise
/// seen from the viewer, stay counter-clockwise on the image).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrthoView {
    pub origin: [f64; 3],
    pub right: [f64; 3],
    pub up: [f64; 3],
    pub forward: [f64; 3],
    pub pixels_per_metre: f64,
    pub width: u32,
    pub height: u32,
}

/// World → (pixel x, pixel y, depth) as a 3×4 affine matrix: row k · (p, 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    pub rows: [[f64; 4]; 3],
}

impl Projection {
    #[inline]
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        self.rows.map(|r| r[0] * p[0] + r[1] * p[1] + r[2] * p[2] + r[3])
    }

    /// This projection after an object → world affine transform given as a 3×4 matrix (columns
    /// x, y, z axes and translation): the result maps object space straight to pixels.
    pub fn then_from(&self, object_to_world: &[[f64; 4]; 3]) -> Projection {
        let m = object_to_world;
        let mut rows = [[0.0; 4]; 3];
        for (k, r) in self.rows.iter().enumerate() {
            for c in 0..4 {
                rows[k][c] = r[0] * m[0][c] + r[1] * m[1][c] + r[2] * m[2][c];
            }
            rows[k][3] += r[3];
        }
        Projection { rows }
    }
}

impl OrthoView {
    /// Looking straight down −Y at the rectangle x ∈ [min_x, max_x], z ∈ [min_z, max_z]: x to the
    /// right, z down the image (north, −z, is up: the heightmap image's orientation), the long side
    /// `size_px` pixels and the aspect kept (the short side at least 1 pixel). Depth is measured
    /// down from `top_y` (the highest point drawn), so higher points are nearer.
    pub fn top_down(min_x: f64, max_x: f64, min_z: f64, max_z: f64, top_y: f64, size_px: u32) -> OrthoView {
        let size_px = size_px.clamp(1, MAX_CANVAS_SIDE);
        let ext_x = (max_x - min_x).max(0.0);
        let ext_z = (max_z - min_z).max(0.0);
        let longest = ext_x.max(ext_z);
        // A degenerate extent (a point or a line) still gets a finite scale and a 1-pixel side.
        let ppm = if longest > 0.0 && longest.is_finite() { size_px as f64 / longest } else { 1.0 };
        let side = |ext: f64| ((ext * ppm).round() as u32).clamp(1, MAX_CANVAS_SIDE);
        OrthoView {
            origin: [min_x, top_y, min_z],
            right: [1.0, 0.0, 0.0],
            up: [0.0, 0.0, -1.0],
            forward: [0.0, -1.0, 0.0],
            pixels_per_metre: ppm,
            width: side(ext_x),
            height: side(ext_z),
        }
    }

    pub fn projection(&self) -> Projection {
        let o = self.origin;
        let s = self.pixels_per_metre;
        let row = |a: [f64; 3], scale: f64| {
            [a[0] * scale, a[1] * scale, a[2] * scale, -(a[0] * o[0] + a[1] * o[1] + a[2] * o[2]) * scale]
        };
        Projection { rows: [row(self.right, s), row(self.up, -s), row(self.forward, 1.0)] }
    }

    /// Pixel coordinates (not rounded) and depth of a world point.
    pub fn to_pixel(&self, p: [f64; 3]) -> [f64; 3] {
        self.projection().apply(p)
    }

    /// An empty canvas of this view's size.
    pub fn canvas(&self, clear: [f32; 4]) -> Result<Canvas, RasterError> {
        Canvas::new(self.width, self.height, clear)
    }
}

/// A pinhole camera at `eye` looking at `target`, `up` giving the image's up direction (it need
/// not be perpendicular to the view axis, only not parallel to it). The horizontal field of view
/// `fov_x_deg` spans the image width; pixels are square, the optical axis passes through the
/// image centre. A view-space point (x right, y up, z = distance along the view axis) lands at
/// pixel x = width/2 + f·x/z, y = height/2 − f·y/z with f = (width/2) / tan(fov_x/2), depth z.
/// Nothing nearer than `near` metres (along the view axis) is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PerspectiveView {
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub up: [f64; 3],
    pub fov_x_deg: f64,
    pub width: u32,
    pub height: u32,
    pub near: f64,
}

/// A perspective view's orthonormal frame and image constants, checked.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PerspFrame {
    /// World → view space (x right, y up, z forward): rows right, up, forward.
    view: Projection,
    focal_px: f64,
    centre: [f64; 2],
    size: [f64; 2],
    near: f64,
}

/// Widest field of view accepted: beyond it the focal length collapses towards zero.
const MAX_FOV_DEG: f64 = 179.0;

/// Pixels of guard band around the image that perspective triangles are clipped to (besides the
/// near plane), so projected vertices stay inside [`MAX_VERTEX_SUBPIXELS`] however close to the
/// eye's plane they come: 2^18 + [`MAX_CANVAS_SIDE`] < 2^20 pixels.
const GUARD_BAND_PX: f64 = (1u32 << 18) as f64;

impl PerspectiveView {
    /// Focal length in pixels: (width/2) / tan(fov_x/2).
    pub fn focal_px(&self) -> f64 {
        self.width as f64 * 0.5 / (self.fov_x_deg.to_radians() * 0.5).tan()
    }

    /// Checks the view: finite eye and target apart, `up` not parallel to the view axis, field of
    /// view in (0°, 179°], `near` > 0 and both sides 1 to [`MAX_CANVAS_SIDE`] pixels.
    pub fn check(&self) -> Result<(), RasterError> {
        self.frame().map(|_| ())
    }

    fn frame(&self) -> Result<PerspFrame, RasterError> {
        let bad = |why: &str| Err(RasterError::Camera(why.to_string()));
        if self.width == 0 || self.height == 0 || self.width > MAX_CANVAS_SIDE || self.height > MAX_CANVAS_SIDE {
            return Err(RasterError::CanvasSize { width: self.width, height: self.height });
        }
        if !(self.fov_x_deg > 0.0 && self.fov_x_deg <= MAX_FOV_DEG) {
            return bad(&format!("fov_x_deg = {} is outside (0, {MAX_FOV_DEG}]", self.fov_x_deg));
        }
        if !(self.near > 0.0 && self.near.is_finite()) {
            return bad(&format!("near = {} must be a positive distance in metres", self.near));
        }
        if !self.eye.iter().chain(&self.target).chain(&self.up).all(|v| v.is_finite()) {
            return bad("eye, target and up must be finite");
        }
        let Some(forward) = normalize3(sub3(self.target, self.eye)) else {
            return bad("eye and target coincide; move the target away from the eye");
        };
        // Right-handed: right = forward × up, up' = right × forward (see `OrthoView`).
        let Some(right) = normalize3(cross3(forward, self.up)) else {
            return bad("up is parallel to the view direction; pick another up vector");
        };
        let up = cross3(right, forward);
        let row = |a: [f64; 3]| [a[0], a[1], a[2], -dot3(a, self.eye)];
        let (w, h) = (self.width as f64, self.height as f64);
        Ok(PerspFrame {
            view: Projection { rows: [row(right), row(up), row(forward)] },
            focal_px: self.focal_px(),
            centre: [w * 0.5, h * 0.5],
            size: [w, h],
            near: self.near,
        })
    }

    /// Pixel coordinates (not rounded) and depth along the view axis of a world point; `None` when
    /// the view is invalid or the point is not in front of the near plane.
    pub fn to_pixel(&self, p: [f64; 3]) -> Option<[f64; 3]> {
        let f = self.frame().ok()?;
        let v = f.view.apply(p);
        (v[2] >= f.near).then(|| f.project(v))
    }

    /// An empty canvas of this view's size (the view is checked first).
    pub fn canvas(&self, clear: [f32; 4]) -> Result<Canvas, RasterError> {
        self.check()?;
        Canvas::new(self.width, self.height, clear)
    }
}

impl PerspFrame {
    /// View space → (pixel x, pixel y, depth); z must be > 0.
    #[inline]
    fn project(&self, v: [f64; 3]) -> [f64; 3] {
        let s = self.focal_px / v[2];
        [self.centre[0] + v[0] * s, self.centre[1] - v[1] * s, v[2]]
    }

    /// The clip planes as (a, b, c, d): a point of view space is kept where a·x + b·y + c·z + d ≥ 0.
    /// The near plane first, then the guard band's four sides (pixel x ≥ −G, x ≤ width + G, and y
    /// alike), written without dividing by z, which is positive once the near plane has been applied.
    fn clip_planes(&self) -> [[f64; 4]; 5] {
        let (f, g) = (self.focal_px, GUARD_BAND_PX);
        let [cx, cy] = self.centre;
        let [w, h] = self.size;
        [
            [0.0, 0.0, 1.0, -self.near],
            [f, 0.0, cx + g, 0.0],
            [-f, 0.0, w + g - cx, 0.0],
            [0.0, -f, cy + g, 0.0],
            [0.0, f, h + g - cy, 0.0],
        ]
    }
}

/// The camera a canvas is drawn with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Camera {
    Ortho(OrthoView),
    Perspective(PerspectiveView),
}

impl Camera {
    pub fn width(&self) -> u32 {
        match self {
            Camera::Ortho(v) => v.width,
            Camera::Perspective(v) => v.width,
        }
    }

    pub fn height(&self) -> u32 {
        match self {
            Camera::Ortho(v) => v.height,
            Camera::Perspective(v) => v.height,
        }
    }

    /// An empty canvas of the camera's size (a perspective view is checked first).
    pub fn canvas(&self, clear: [f32; 4]) -> Result<Canvas, RasterError> {
        match self {
            Camera::Ortho(v) => v.canvas(clear),
            Camera::Perspective(v) => v.canvas(clear),
        }
    }
}

/// Which triangles to skip by their facing on the image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Cull {
    #[default]
    None,
    /// Skip triangles clockwise on the image (back faces).
    Back,
    /// Skip triangles counter-clockwise on the image.
    Front,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DrawOptions {
    pub cull: Cull,
    /// Discard fragments not strictly nearer than the depth buffer.
    pub depth_test: bool,
    /// Store the depth of written fragments.
    pub depth_write: bool,
}

impl Default for DrawOptions {
    fn default() -> Self {
        DrawOptions { cull: Cull::None, depth_test: true, depth_write: true }
    }
}

/// What one draw call did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DrawStats {
    /// Triangles rasterised (some may have covered no pixel centre).
    pub triangles: usize,
    /// Triangles skipped by the cull mode, or with zero area on the image.
    pub culled: usize,
    /// Triangles skipped as unusable: an index out of range, a non-finite position, or a vertex
    /// beyond [`MAX_VERTEX_SUBPIXELS`].
    pub skipped: usize,
    /// Perspective only: triangles wholly behind the near plane (or beyond the guard band around
    /// the image), so nothing of them is visible. Triangles crossing it are clipped and drawn.
    pub clipped: usize,
    /// Fragments the shader returned a colour for and that were written.
    pub fragments: u64,
}

impl DrawStats {
    fn add(&mut self, o: &DrawStats) {
        self.triangles += o.triangles;
        self.culled += o.culled;
        self.skipped += o.skipped;
        self.clipped += o.clipped;
        self.fragments += o.fragments;
    }
}

/// One covered pixel, given to the shader. Attributes are interpolated at the pixel centre from the
/// primitive's own (object-space) values, perspective-correctly under a perspective camera; a
/// missing attribute reads as zero (colour: opaque white).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fragment {
    pub x: u32,
    pub y: u32,
    pub depth: f32,
    pub position: [f32; 3],
    /// Interpolated, not renormalised (the shader decides whether it needs unit length).
    pub normal: [f32; 3],
    pub uv: [f32; 2],
    pub color: [f32; 4],
    /// Weights of the triangle's three vertices in index order; they sum to 1.
    pub bary: [f32; 3],
    /// Index of the triangle in the primitive.
    pub triangle: u32,
    /// Counter-clockwise on the image.
    pub front_facing: bool,
}

impl Canvas {
    /// A canvas filled with `clear` and depth +∞.
    pub fn new(width: u32, height: u32, clear: [f32; 4]) -> Result<Canvas, RasterError> {
        if width == 0 || height == 0 || width > MAX_CANVAS_SIDE || height > MAX_CANVAS_SIDE {
            return Err(RasterError::CanvasSize { width, height });
        }
        let n = width as usize * height as usize;
        Ok(Canvas { width, height, color: vec![clear; n], depth: vec![f32::INFINITY; n] })
    }

    #[inline]
    pub fn pixel(&self, x: u32, y: u32) -> Option<[f32; 4]> {
        (x < self.width && y < self.height).then(|| self.color[y as usize * self.width as usize + x as usize])
    }

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
                let setup = PerspSetup::new(v, object_to_world, prim, opts.cull);
                let mut stats = setup.stats;
                let tris: Vec<u32> = (0..setup.tris.len() as u32).collect();
                let (w, h) = (self.width, self.height);
                stats.fragments = raster_rows_persp(
                    &mut self.color,
                    &mut self.depth,
                    w,
                    0,
                    h,
                    &setup,
                    prim,
                    &tris,
                    opts,
                    &mut shader,
                );
                stats
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

    /// sRGB-encoded 8-bit RGBA, row-major from the top-left (alpha stays linear, as PNG wants).
    pub fn to_rgba8(&self) -> Vec<u8> {
        rgba8(&self.color)
    }

    /// The canvas as PNG bytes (sRGB, 8-bit RGBA). Deterministic.
    pub fn encode_png(&self) -> Result<Vec<u8>, RasterError> {
        encode_rgba8_png(&self.to_rgba8(), self.width, self.height).map_err(RasterError::Encode)
    }

    /// Writes the canvas as a PNG, atomically (temporary file, then rename).
    pub fn write_png(&self, path: &Path) -> Result<(), RasterError> {
        let bytes = self.encode_png()?;
        write_atomic(path, &bytes)?;
        Ok(())
    }
}

/// The sRGB transfer function (IEC 61966-2-1) of a linear value in 0..1.
/// Linear straight-alpha RGBA → sRGB-encoded 8-bit RGBA (alpha stays linear), rounded to nearest:
/// what every PNG the baker writes holds.
pub fn rgba8(pixels: &[[f32; 4]]) -> Vec<u8> {
    let mut out = Vec::with_capacity(pixels.len() * 4);
    for c in pixels {
        out.extend_from_slice(&[
            to_u8(linear_to_srgb(c[0])),
            to_u8(linear_to_srgb(c[1])),
            to_u8(linear_to_srgb(c[2])),
            to_u8(c[3]),
        ]);
    }
    out
}

/// PNG bytes of `width` × `height` RGBA8 pixels (deterministic: same pixels, same bytes).
pub fn encode_rgba8_png(rgba: &[u8], width: u32, height: u32) -> Result<Vec<u8>, String> {
    use image::ImageEncoder;
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(rgba, width, height, image::ExtendedColorType::Rgba8)
        .map_err(|e| e.to_string())?;
    Ok(bytes)
}

#[inline]
pub(crate) fn to_u8(v: f32) -> u8 {
    // NaN → 0; round half up.
    if v.is_nan() {
        0
    } else {
        (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
    }
}

/// A vertex on the image: snapped position in sub-pixels and depth; `None` if unusable.
type ScreenVertex = Option<([i64; 2], f64)>;

/// A triangle ready to rasterise: its vertices ordered so the edge functions are ≥ 0 inside.
#[derive(Debug, Clone, Copy)]
struct TriSetup {
    index: u32,
    /// Vertex indices (into the primitive) in edge-function order.
    v: [u32; 3],
    /// Sub-pixel bounding box, inclusive.
    min: [i64; 2],
    max: [i64; 2],
    /// The edge order swapped vertices 1 and 2 (the triangle was clockwise in sub-pixel math).
    swapped: bool,
}

impl TriSetup {
    fn pixel_rows(&self, height: u32) -> Option<(u32, u32)> {
        pixel_rows(self.min[1], self.max[1], height)
    }
}

/// Pixel rows [y0, y1) whose centres may lie in the sub-pixel span [min_y, max_y], clipped to
/// `height`; None if none.
#[inline]
fn pixel_rows(min_y: i64, max_y: i64, height: u32) -> Option<(u32, u32)> {
    // Row y's centre is y·S + S/2; first row with centre ≥ min, last with centre ≤ max.
    let y0 = first_centre(min_y).max(0);
    let y1 = (last_centre(max_y) + 1).min(height as i64);
    (y0 < y1).then_some((y0 as u32, y1 as u32))
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

/// Smallest pixel index whose centre (k·S + S/2) is ≥ `v` (sub-pixels).
#[inline]
fn first_centre(v: i64) -> i64 {
    (v - SUBPIXEL / 2 + SUBPIXEL - 1).div_euclid(SUBPIXEL)
}

/// Largest pixel index whose centre is ≤ `v`.
#[inline]
fn last_centre(v: i64) -> i64 {
    (v - SUBPIXEL / 2).div_euclid(SUBPIXEL)
}

/// Every vertex projected once, and every triangle classified (drawn, culled, skipped).
struct Setup {
    verts: Vec<ScreenVertex>,
    tris: Vec<TriSetup>,
    stats: DrawStats,
}

impl Setup {
    fn new(proj: &Projection, prim: &Primitive, cull: Cull) -> Setup {
        let verts: Vec<ScreenVertex> = prim
            .positions
            .par_iter()
            .map(|p| {
                let s = proj.apply([p[0] as f64, p[1] as f64, p[2] as f64]);
                if !s.iter().all(|v| v.is_finite()) {
                    return None;
                }
                let snap = |v: f64| (v * SUBPIXEL as f64).round();
                let (x, y) = (snap(s[0]), snap(s[1]));
                let lim = MAX_VERTEX_SUBPIXELS as f64;
                if x.abs() > lim || y.abs() > lim {
                    return None;
                }
                Some(([x as i64, y as i64], s[2]))
            })
            .collect();
        let mut stats = DrawStats::default();
        let mut tris = Vec::with_capacity(prim.indices.len() / 3);
        for (t, idx) in prim.indices.chunks_exact(3).enumerate() {
            let get = |k: usize| verts.get(idx[k] as usize).copied().flatten();
            let (Some(a), Some(b), Some(c)) = (get(0), get(1), get(2)) else {
                stats.skipped += 1;
                continue;
            };
            let area = orient(a.0, b.0, c.0);
            // Pixel y runs down, so a positive sub-pixel area is clockwise on the image.
            let front = area < 0;
            let culled = area == 0
                || match cull {
                    Cull::None => false,
                    Cull::Back => !front,
                    Cull::Front => front,
                };
            if culled {
                stats.culled += 1;
                continue;
            }
            let swapped = area < 0;
            let v = if swapped { [idx[0], idx[2], idx[1]] } else { [idx[0], idx[1], idx[2]] };
            let ps = [a.0, b.0, c.0];
            let min = [ps.iter().map(|p| p[0]).min().unwrap_or(0), ps.iter().map(|p| p[1]).min().unwrap_or(0)];
            let max = [ps.iter().map(|p| p[0]).max().unwrap_or(0), ps.iter().map(|p| p[1]).max().unwrap_or(0)];
            stats.triangles += 1;
            tris.push(TriSetup { index: t as u32, v, min, max, swapped });
        }
        Setup { verts, tris, stats }
    }
}

/// A vertex of a triangle being clipped: its view-space position and its weights of the source
/// triangle's three vertices (index order). Both are linear along an edge in view space.
#[derive(Debug, Clone, Copy, Default)]
struct ClipVertex {
    view: [f64; 3],
    bary: [f64; 3],
}

/// Most vertices a triangle can have after clipping by the five planes (one more per plane).
const MAX_CLIP_VERTICES: usize = 3 + 5;

/// A convex polygon in a fixed buffer (clipping allocates nothing).
#[derive(Clone, Copy)]
struct ClipPolygon {
    v: [ClipVertex; MAX_CLIP_VERTICES],
    len: usize,
}

impl ClipPolygon {
    /// Sutherland–Hodgman against one plane. A crossing edge's new vertex is computed from its
    /// inside end, so the two triangles sharing that edge get the same point (no crack).
    fn clip(&self, plane: [f64; 4]) -> ClipPolygon {
        let dist = |c: &ClipVertex| plane[0] * c.view[0] + plane[1] * c.view[1] + plane[2] * c.view[2] + plane[3];
        let mut out = ClipPolygon { v: [ClipVertex::default(); MAX_CLIP_VERTICES], len: 0 };
        let mut push = |c: ClipVertex| {
            if out.len < MAX_CLIP_VERTICES {
                out.v[out.len] = c;
                out.len += 1;
            }
        };
        for k in 0..self.len {
            let (a, b) = (self.v[k], self.v[(k + 1) % self.len]);
            let (da, db) = (dist(&a), dist(&b));
            if da >= 0.0 {
                push(a);
            }
            if (da >= 0.0) != (db >= 0.0) {
                let (inside, outside, di, doo) = if da >= 0.0 { (a, b, da, db) } else { (b, a, db, da) };
                let t = di / (di - doo);
                let lerp = |p: [f64; 3], q: [f64; 3]| [0, 1, 2].map(|d| p[d] + t * (q[d] - p[d]));
                push(ClipVertex { view: lerp(inside.view, outside.view), bary: lerp(inside.bary, outside.bary) });
            }
        }
        out
    }
}

/// A perspective triangle (a source triangle or a piece of its clipped polygon) ready to scan.
#[derive(Debug, Clone, Copy)]
struct PerspTri {
    /// Index of the source triangle in the primitive.
    index: u32,
    /// The source triangle's vertex indices, in index order.
    source: [u32; 3],
    /// Snapped positions, ordered so the edge functions are ≥ 0 inside.
    pts: [[i64; 2]; 3],
    /// 1 / depth at each of `pts`.
    inv_depth: [f64; 3],
    /// Weights of the source vertices at each of `pts`.
    bary: [[f64; 3]; 3],
    min: [i64; 2],
    max: [i64; 2],
    /// The source triangle is counter-clockwise seen from the eye.
    front: bool,
}

struct PerspSetup {
    tris: Vec<PerspTri>,
    stats: DrawStats,
}

impl PerspSetup {
    fn new(view: &PerspectiveView, object_to_world: &[[f64; 4]; 3], prim: &Primitive, cull: Cull) -> PerspSetup {
        let mut stats = DrawStats::default();
        let Ok(frame) = view.frame() else {
            stats.skipped = prim.indices.len() / 3;
            return PerspSetup { tris: Vec::new(), stats };
        };
        let to_view = frame.view.then_from(object_to_world);
        let verts: Vec<Option<[f64; 3]>> = prim
            .positions
            .par_iter()
            .map(|p| {
                let v = to_view.apply([p[0] as f64, p[1] as f64, p[2] as f64]);
                v.iter().all(|c| c.is_finite()).then_some(v)
            })
            .collect();
        let planes = frame.clip_planes();
        let mut tris = Vec::with_capacity(prim.indices.len() / 3);
        for (t, idx) in prim.indices.chunks_exact(3).enumerate() {
            let get = |k: usize| verts.get(idx[k] as usize).copied().flatten();
            let (Some(a), Some(b), Some(c)) = (get(0), get(1), get(2)) else {
                stats.skipped += 1;
                continue;
            };
            // Facing from the eye (the origin of view space). View space (right, up, forward) is
            // left-handed, so counter-clockwise seen from the eye is a positive triple product.
            let facing = dot3(cross3(sub3(b, a), sub3(c, a)), a);
            let front = facing > 0.0;
            let culled = facing == 0.0
                || !facing.is_finite()
                || match cull {
                    Cull::None => false,
                    Cull::Back => !front,
                    Cull::Front => front,
                };
            if culled {
                stats.culled += 1;
                continue;
            }
            let mut poly = ClipPolygon { v: [ClipVertex::default(); MAX_CLIP_VERTICES], len: 3 };
            poly.v[..3].copy_from_slice(&[
                ClipVertex { view: a, bary: [1.0, 0.0, 0.0] },
                ClipVertex { view: b, bary: [0.0, 1.0, 0.0] },
                ClipVertex { view: c, bary: [0.0, 0.0, 1.0] },
            ]);
            let inside = |v: &[f64; 3], p: &[f64; 4]| p[0] * v[0] + p[1] * v[1] + p[2] * v[2] + p[3] >= 0.0;
            for plane in &planes {
                if [a, b, c].iter().all(|v| inside(v, plane)) {
                    continue;
                }
                poly = poly.clip(*plane);
                if poly.len < 3 {
                    break;
                }
            }
            if poly.len < 3 {
                stats.clipped += 1;
                continue;
            }
            // Project and snap the polygon; then a fan of triangles around its first vertex.
            let mut screen = [([0i64; 2], 0.0f64); MAX_CLIP_VERTICES];
            let mut usable = true;
            for (k, cv) in poly.v[..poly.len].iter().enumerate() {
                let s = frame.project(cv.view);
                let snap = |v: f64| (v * SUBPIXEL as f64).round();
                let (x, y) = (snap(s[0]), snap(s[1]));
                let lim = MAX_VERTEX_SUBPIXELS as f64;
                if !(x.abs() <= lim && y.abs() <= lim && s[2] > 0.0) {
                    usable = false;
                    break;
                }
                screen[k] = ([x as i64, y as i64], 1.0 / s[2]);
            }
            if !usable {
                stats.skipped += 1;
                continue;
            }
            let before = tris.len();
            for k in 1..poly.len - 1 {
                let fan = [0, k, k + 1];
                let area = orient(screen[0].0, screen[k].0, screen[k + 1].0);
                if area == 0 {
                    continue;
                }
                let order = if area < 0 { [fan[0], fan[2], fan[1]] } else { fan };
                let pts = order.map(|i| screen[i].0);
                tris.push(PerspTri {
                    index: t as u32,
                    source: [idx[0], idx[1], idx[2]],
                    pts,
                    inv_depth: order.map(|i| screen[i].1),
                    bary: order.map(|i| poly.v[i].bary),
                    min: [pts.iter().map(|p| p[0]).min().unwrap_or(0), pts.iter().map(|p| p[1]).min().unwrap_or(0)],
                    max: [pts.iter().map(|p| p[0]).max().unwrap_or(0), pts.iter().map(|p| p[1]).max().unwrap_or(0)],
                    front,
                });
            }
            if tris.len() == before {
                // Zero area on the image once snapped, as in the orthographic path.
                stats.culled += 1;
            } else {
                stats.triangles += 1;
            }
        }
        PerspSetup { tris, stats }
    }
}

/// Twice the signed area of (a, b, p), sub-pixel units: the edge function of edge a→b at p.
#[inline(always)]
fn orient(a: [i64; 2], b: [i64; 2], p: [i64; 2]) -> i64 {
    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
}

/// Top-left rule for an edge a→b of a triangle whose inside has positive edge functions, with y
/// down: a top edge is horizontal with the inside below it (b to the right of a); a left edge has
/// the inside to its right (it runs up the image). Pixels exactly on other edges belong to the
/// neighbour, so on those edges the test is `> 0`, i.e. `≥ 1` for integers.
#[inline]
fn edge_bias(a: [i64; 2], b: [i64; 2]) -> i64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let top_left = (dy == 0 && dx > 0) || dy < 0;
    if top_left {
        0
    } else {
        -1
    }
}

/// The triangle's pixel columns [x0, x1) whose centres may be inside, clipped to `width`.
#[inline]
fn pixel_columns(min_x: i64, max_x: i64, width: u32) -> Option<(i64, i64)> {
    let x0 = first_centre(min_x).max(0);
    let x1 = (last_centre(max_x) + 1).min(width as i64);
    (x0 < x1).then_some((x0, x1))
}

/// The scan shared by both cameras: calls `covered(x, y, e)` for every pixel of rows [ry0, ry1) and
/// columns [x0, x1) whose centre the triangle (a, b, c) owns under the top-left rule, in row-major
/// order. The vertices are ordered so the edge functions are ≥ 0 inside; `e` holds the edge
/// functions opposite a, b and c (edges b→c, c→a, a→b) at the pixel centre.
#[inline(always)]
fn scan_triangle<C>(pts: [[i64; 2]; 3], x0: i64, x1: i64, ry0: u32, ry1: u32, mut covered: C)
where
    C: FnMut(u32, u32, [i64; 3]),
{
    let [a, b, c] = pts;
    let bias = [edge_bias(b, c), edge_bias(c, a), edge_bias(a, b)];
    let step_x = [-(c[1] - b[1]) * SUBPIXEL, -(a[1] - c[1]) * SUBPIXEL, -(b[1] - a[1]) * SUBPIXEL];
    for y in ry0..ry1 {
        let py = y as i64 * SUBPIXEL + SUBPIXEL / 2;
        let px = x0 * SUBPIXEL + SUBPIXEL / 2;
        let mut e = [orient(b, c, [px, py]), orient(c, a, [px, py]), orient(a, b, [px, py])];
        for x in x0..x1 {
            if e[0] + bias[0] >= 0 && e[1] + bias[1] >= 0 && e[2] + bias[2] >= 0 {
                covered(x as u32, y, e);
            }
            for d in 0..3 {
                e[d] += step_x[d];
            }
        }
    }
}

/// w₀·a + w₁·b + w₂·c per component, summed in that order (results depend on it). A plain loop
/// rather than `array::map`, which the compiler does not always inline in the pixel loop.
#[inline(always)]
fn weigh<T, const N: usize>(w: [T; 3], a: &[T; N], b: &[T; N], c: &[T; N]) -> [T; N]
where
    T: Copy + Default + std::ops::Mul<Output = T> + std::ops::Add<Output = T>,
{
    let mut out = [T::default(); N];
    for d in 0..N {
        out[d] = w[0] * a[d] + w[1] * b[d] + w[2] * c[d];
    }
    out
}

/// The optional per-vertex attributes of a primitive: each counts only when there is one per
/// position (else it reads as its default).
struct Attributes<'a> {
    normals: Option<&'a [[f32; 3]]>,
    uvs: Option<&'a [[f32; 2]]>,
    colors: Option<&'a [[f32; 4]]>,
}

impl<'a> Attributes<'a> {
    fn of(prim: &'a Primitive) -> Self {
        let n = prim.positions.len();
        Attributes {
            normals: (prim.normals.len() == n).then_some(&prim.normals[..]),
            uvs: (prim.uvs.len() == n).then_some(&prim.uvs[..]),
            colors: (prim.colors.len() == n).then_some(&prim.colors[..]),
        }
    }
}

/// Rasterises the triangles `tris` (positions in `setup.tris`, in draw order) into the rows
/// [y0, y1) of the canvas; `color`/`depth` hold exactly those rows. Returns the fragments written.
#[allow(clippy::too_many_arguments)]
fn raster_rows<F>(
    color: &mut [[f32; 4]],
    depth: &mut [f32],
    width: u32,
    y0: u32,
    y1: u32,
    setup: &Setup,
    prim: &Primitive,
    tris: &[u32],
    opts: &DrawOptions,
    shader: &mut F,
) -> u64
where
    F: FnMut(&Fragment) -> Option<[f32; 4]>,
{
    let Attributes { normals, uvs, colors } = Attributes::of(prim);
    let mut written = 0u64;
    for &t in tris {
        let Some(tri) = setup.tris.get(t as usize) else {
            continue;
        };
        let Some((ry0, ry1)) = tri.pixel_rows(y1) else {
            continue;
        };
        let (ry0, ry1) = (ry0.max(y0), ry1);
        if ry0 >= ry1 {
            continue;
        }
        let Some((x0, x1)) = pixel_columns(tri.min[0], tri.max[0], width) else {
            continue;
        };
        let sv = tri.v.map(|i| setup.verts[i as usize].unwrap_or(([0, 0], 0.0)));
        let pts = [sv[0].0, sv[1].0, sv[2].0];
        let inv_area = 1.0 / orient(pts[0], pts[1], pts[2]) as f64;
        let depths = [sv[0].1, sv[1].1, sv[2].1];
        let vi = tri.v.map(|i| i as usize);
        scan_triangle(pts, x0, x1, ry0, ry1, |x, y, e| {
            let l = [e[0] as f64 * inv_area, e[1] as f64 * inv_area, e[2] as f64 * inv_area];
            let z = (l[0] * depths[0] + l[1] * depths[1] + l[2] * depths[2]) as f32;
            let k = (y - y0) as usize * width as usize + x as usize;
            if !opts.depth_test || z < depth[k] {
                let lf = [l[0] as f32, l[1] as f32, l[2] as f32];
                let p = &prim.positions;
                let frag = Fragment {
                    x,
                    y,
                    depth: z,
                    position: weigh(lf, &p[vi[0]], &p[vi[1]], &p[vi[2]]),
                    normal: normals.map_or([0.0; 3], |nm| weigh(lf, &nm[vi[0]], &nm[vi[1]], &nm[vi[2]])),
                    uv: uvs.map_or([0.0; 2], |u| weigh(lf, &u[vi[0]], &u[vi[1]], &u[vi[2]])),
                    color: colors.map_or([1.0; 4], |cl| weigh(lf, &cl[vi[0]], &cl[vi[1]], &cl[vi[2]])),
                    // Report weights in the triangle's index order.
                    bary: if tri.swapped { [lf[0], lf[2], lf[1]] } else { lf },
                    triangle: tri.index,
                    front_facing: tri.swapped,
                };
                if let Some(rgba) = shader(&frag) {
                    color[k] = rgba;
                    if opts.depth_write {
                        depth[k] = z;
                    }
                    written += 1;
                }
            }
        });
    }
    written
}

/// [`raster_rows`] for perspective triangles: per pixel, the screen-linear weights l give
/// 1/z = Σ lᵢ/zᵢ and the perspective-correct weights (lᵢ/zᵢ)·z of the (clipped) vertices, whose
/// own weights of the source triangle then give the attributes.
#[allow(clippy::too_many_arguments)]
fn raster_rows_persp<F>(
    color: &mut [[f32; 4]],
    depth: &mut [f32],
    width: u32,
    y0: u32,
    y1: u32,
    setup: &PerspSetup,
    prim: &Primitive,
    tris: &[u32],
    opts: &DrawOptions,
    shader: &mut F,
) -> u64
where
    F: FnMut(&Fragment) -> Option<[f32; 4]>,
{
    let Attributes { normals, uvs, colors } = Attributes::of(prim);
    let n = prim.positions.len();
    let mut written = 0u64;
    for &t in tris {
        let Some(tri) = setup.tris.get(t as usize) else {
            continue;
        };
        let Some((ry0, ry1)) = pixel_rows(tri.min[1], tri.max[1], y1) else {
            continue;
        };
        let ry0 = ry0.max(y0);
        if ry0 >= ry1 {
            continue;
        }
        let Some((x0, x1)) = pixel_columns(tri.min[0], tri.max[0], width) else {
            continue;
        };
        let vi = tri.source.map(|i| i as usize);
        if vi.iter().any(|&i| i >= n) {
            continue;
        }
        let inv_area = 1.0 / orient(tri.pts[0], tri.pts[1], tri.pts[2]) as f64;
        let [w0, w1, w2] = tri.inv_depth;
        let [b0, b1, b2] = tri.bary;
        scan_triangle(tri.pts, x0, x1, ry0, ry1, |x, y, e| {
            let q = [e[0] as f64 * inv_area * w0, e[1] as f64 * inv_area * w1, e[2] as f64 * inv_area * w2];
            let inv_z = q[0] + q[1] + q[2];
            let z_view = 1.0 / inv_z;
            let z = z_view as f32;
            let k = (y - y0) as usize * width as usize + x as usize;
            if !opts.depth_test || z < depth[k] {
                let lam = [q[0] * z_view, q[1] * z_view, q[2] * z_view];
                let bary = weigh(lam, &b0, &b1, &b2);
                let bf = [bary[0] as f32, bary[1] as f32, bary[2] as f32];
                let p = &prim.positions;
                let frag = Fragment {
                    x,
                    y,
                    depth: z,
                    position: weigh(bf, &p[vi[0]], &p[vi[1]], &p[vi[2]]),
                    normal: normals.map_or([0.0; 3], |nm| weigh(bf, &nm[vi[0]], &nm[vi[1]], &nm[vi[2]])),
                    uv: uvs.map_or([0.0; 2], |u| weigh(bf, &u[vi[0]], &u[vi[1]], &u[vi[2]])),
                    color: colors.map_or([1.0; 4], |cl| weigh(bf, &cl[vi[0]], &cl[vi[1]], &cl[vi[2]])),
                    bary: bf,
                    triangle: tri.index,
                    front_facing: tri.front,
                };
                if let Some(rgba) = shader(&frag) {
                    color[k] = rgba;
                    if opts.depth_write {
                        depth[k] = z;
                    }
                    written += 1;
                }
            }
        });
    }
    written
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A view where world x, y map to pixel x, y one to one (y down), depth = world z.
    fn identity() -> Projection {
        Projection { rows: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]] }
    }

    fn prim(positions: Vec<[f32; 3]>, indices: Vec<u32>) -> Primitive {
        Primitive { positions, indices, ..Primitive::default() }
    }

    /// Counts how often each pixel is written.
    fn coverage(c: &mut Canvas, p: &Primitive, opts: &DrawOptions) -> Vec<u32> {
        let mut counts = vec![0u32; c.color.len()];
        let w = c.width as usize;
        c.draw(&identity(), p, opts, |f| {
            counts[f.y as usize * w + f.x as usize] += 1;
            Some([1.0; 4])
        });
        counts
    }

    const NO_DEPTH: DrawOptions = DrawOptions { cull: Cull::None, depth_test: false, depth_write: false };

    #[test]
    fn quad_covers_exactly_its_pixels_once() {
        // Pixel-aligned quad [2, 6) × [1, 4): pixel centres 2.5..5.5 × 1.5..3.5 → 4×3 pixels.
        let p = prim(vec![[2.0, 1.0, 0.0], [6.0, 1.0, 0.0], [6.0, 4.0, 0.0], [2.0, 4.0, 0.0]], vec![0, 1, 2, 0, 2, 3]);
        let mut c = Canvas::new(8, 6, [0.0; 4]).unwrap();
        let counts = coverage(&mut c, &p, &NO_DEPTH);
        for y in 0..6 {
            for x in 0..8 {
                let inside = (2..6).contains(&x) && (1..4).contains(&y);
                assert_eq!(counts[y * 8 + x], inside as u32, "pixel ({x}, {y})");
            }
        }
    }

    #[test]
    fn shared_edges_through_pixel_centres_are_drawn_once() {
        // A jittered grid whose vertices sit on pixel centres and edges pass through many centres:
        // the worst case for the fill rule. Every pixel centre inside the hull is written once.
        let n = 6usize;
        let s = 7.0f32;
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let inner = i > 0 && i < n && j > 0 && j < n;
                let jit = if inner { ((i * 3 + j * 5) % 5) as f32 - 2.0 } else { 0.0 };
                pos.push([0.5 + i as f32 * s + jit, 0.5 + j as f32 * s - jit, 0.0]);
            }
        }
        let mut idx = Vec::new();
        for j in 0..n as u32 {
            for i in 0..n as u32 {
                let a = j * (n as u32 + 1) + i;
                let (b, c, d) = (a + 1, a + n as u32 + 1, a + n as u32 + 2);
                // alternate the diagonal, and the winding, to exercise both orientations
                if (i + j) % 2 == 0 {
                    idx.extend_from_slice(&[a, b, d, a, d, c]);
                } else {
                    idx.extend_from_slice(&[a, c, b, b, c, d]);
                }
            }
        }
        let p = prim(pos, idx);
        let side = (n as f32 * s + 1.0) as u32;
        let mut c = Canvas::new(side, side, [0.0; 4]).unwrap();
        let counts = coverage(&mut c, &p, &NO_DEPTH);
        // Hull is [0.5, 0.5 + n·s]²: pixel centres x + 0.5 with 0 ≤ x ≤ n·s; the right and bottom
        // borders are not top-left edges, so x = n·s is outside.
        let last = (n as f32 * s) as usize;
        for y in 0..side as usize {
            for x in 0..side as usize {
                let expect = (x < last && y < last) as u32;
                assert_eq!(counts[y * side as usize + x], expect, "pixel ({x}, {y})");
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        /// Random jittered triangulations of a rectangle (sub-pixel vertices, random diagonals and
        /// windings): every pixel centre of the rectangle is written exactly once, nothing else.
        #[test]
        fn random_triangulations_cover_each_pixel_once(
            jitter in proptest::collection::vec((-300i32..=300, -300i32..=300), 64),
            flips in proptest::collection::vec(0u8..4, 49),
        ) {
            let (n, s) = (7usize, 5.0f32);
            let mut pos = Vec::new();
            for j in 0..=n {
                for i in 0..=n {
                    let inner = i > 0 && i < n && j > 0 && j < n;
                    let (dx, dy) = if inner { jitter[j * 8 + i] } else { (0, 0) };
                    // jitter up to ±1.17 px in 1/256 steps (cells stay convex, so either diagonal is a valid
                    // split): vertices land on centres, on edges, anywhere
                    pos.push([0.5 + i as f32 * s + dx as f32 / 256.0, 0.5 + j as f32 * s + dy as f32 / 256.0, 0.0]);
                }
            }
            let mut idx = Vec::new();
            for j in 0..n as u32 {
                for i in 0..n as u32 {
                    let a = j * (n as u32 + 1) + i;
                    let (b, c, d) = (a + 1, a + n as u32 + 1, a + n as u32 + 2);
                    let f = flips[j as usize * n + i as usize];
                    let mut two = if f & 1 == 0 { [a, b, d, a, d, c] } else { [a, b, c, b, d, c] };
                    if f & 2 != 0 {
                        two.swap(1, 2);
                    }
                    idx.extend_from_slice(&two);
                }
            }
            let p = prim(pos, idx);
            let side = (n as f32 * s + 2.0) as u32;
            let mut c = Canvas::new(side, side, [0.0; 4]).unwrap();
            let counts = coverage(&mut c, &p, &NO_DEPTH);
            let last = (n as f32 * s) as usize;
            for y in 0..side as usize {
                for x in 0..side as usize {
                    proptest::prop_assert_eq!(counts[y * side as usize + x], (x < last && y < last) as u32, "pixel ({}, {})", x, y);
                }
            }
        }
    }

    #[test]
    fn fan_around_a_pixel_centre_owns_it_once() {
        // Eight triangles around the centre of pixel (8, 8), with diagonal and axis edges.
        let c0 = [8.5f32, 8.5];
        let ring: Vec<[f32; 2]> = (0..8)
            .map(|k| {
                let d = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)][k];
                [c0[0] + 6.0 * d.0 as f32, c0[1] + 6.0 * d.1 as f32]
            })
            .collect();
        let mut pos = vec![[c0[0], c0[1], 0.0]];
        pos.extend(ring.iter().map(|r| [r[0], r[1], 0.0]));
        let mut idx = Vec::new();
        for k in 0..8u32 {
            idx.extend_from_slice(&[0, 1 + k, 1 + (k + 1) % 8]);
        }
        let p = prim(pos, idx);
        let mut c = Canvas::new(17, 17, [0.0; 4]).unwrap();
        let counts = coverage(&mut c, &p, &NO_DEPTH);
        assert_eq!(counts[8 * 17 + 8], 1);
        assert!(counts.iter().all(|&n| n <= 1));
    }

    #[test]
    fn depth_test_keeps_the_nearest() {
        let quad = |z: f32| vec![[0.0, 0.0, z], [4.0, 0.0, z], [4.0, 4.0, z], [0.0, 4.0, z]];
        let idx = vec![0, 1, 2, 0, 2, 3];
        let mut c = Canvas::new(4, 4, [0.0; 4]).unwrap();
        let opts = DrawOptions::default();
        c.draw(&identity(), &prim(quad(5.0), idx.clone()), &opts, |_| Some([1.0, 0.0, 0.0, 1.0]));
        let s = c.draw(&identity(), &prim(quad(9.0), idx.clone()), &opts, |_| Some([0.0, 1.0, 0.0, 1.0]));
        assert_eq!(s.fragments, 0, "farther quad hidden");
        c.draw(&identity(), &prim(quad(2.0), idx), &opts, |_| Some([0.0, 0.0, 1.0, 1.0]));
        assert!(c.color.iter().all(|&p| p == [0.0, 0.0, 1.0, 1.0]));
        assert!(c.depth.iter().all(|&d| d == 2.0));
    }

    #[test]
    fn interpolation_is_exact_at_vertices_and_linear_between() {
        // Vertices on pixel centres; attribute = a linear function of position.
        let pos = vec![[0.5, 0.5, 1.0], [8.5, 0.5, 2.0], [0.5, 8.5, 3.0]];
        let f = |p: [f32; 3]| [p[0] * 0.25 + 1.0, p[1] * -0.5 + 3.0];
        let mut p = prim(pos.clone(), vec![0, 1, 2]);
        p.uvs = pos.iter().map(|&q| f(q)).collect();
        p.colors = vec![[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0]];
        let mut c = Canvas::new(10, 10, [0.0; 4]).unwrap();
        let mut frags = Vec::new();
        c.draw(&identity(), &p, &DrawOptions::default(), |fr| {
            frags.push(*fr);
            Some([1.0; 4])
        });
        let at = |x: u32, y: u32| frags.iter().find(|fr| fr.x == x && fr.y == y).copied();
        // Vertex 0 and the top-left-owned vertices are exact; vertex 1 and 2 lie on the non-top-left
        // hypotenuse, which the fill rule hands to the neighbour.
        let v0 = at(0, 0).expect("vertex 0 covered");
        assert_eq!(v0.uv, p.uvs[0]);
        assert_eq!(v0.color, p.colors[0]);
        assert_eq!(v0.bary, [1.0, 0.0, 0.0]);
        assert_eq!(v0.depth, 1.0);
        for fr in &frags {
            let want = f([fr.x as f32 + 0.5, fr.y as f32 + 0.5, 0.0]);
            assert!((fr.uv[0] - want[0]).abs() < 1e-5 && (fr.uv[1] - want[1]).abs() < 1e-5);
            assert!((fr.bary.iter().sum::<f32>() - 1.0).abs() < 1e-6);
            assert!((fr.position[0] - (fr.x as f32 + 0.5)).abs() < 1e-5);
        }
        // Reversed winding: vertex 0 still exact, bary still in index order.
        let mut q = p.clone();
        q.indices = vec![0, 2, 1];
        let mut c2 = Canvas::new(10, 10, [0.0; 4]).unwrap();
        let mut first = None;
        c2.draw(&identity(), &q, &DrawOptions::default(), |fr| {
            if fr.x == 0 && fr.y == 0 {
                first = Some(*fr);
            }
            Some([1.0; 4])
        });
        let f0 = first.expect("covered");
        assert_eq!(f0.bary, [1.0, 0.0, 0.0]);
        assert_eq!(f0.uv, p.uvs[0]);
    }

    #[test]
    fn culling_by_facing_on_the_image() {
        // Counter-clockwise on the image (y down): (0,0) → (0,4) → (4,0).
        let ccw = prim(vec![[0.0, 0.0, 0.0], [0.0, 4.0, 0.0], [4.0, 0.0, 0.0]], vec![0, 1, 2]);
        let mut cw = ccw.clone();
        cw.indices = vec![0, 2, 1];
        let mut c = Canvas::new(4, 4, [0.0; 4]).unwrap();
        let back = DrawOptions { cull: Cull::Back, ..DrawOptions::default() };
        let s = c.draw(&identity(), &ccw, &back, |f| {
            assert!(f.front_facing);
            Some([1.0; 4])
        });
        assert_eq!((s.triangles, s.culled), (1, 0));
        let s = c.draw(&identity(), &cw, &back, |_| Some([1.0; 4]));
        assert_eq!((s.triangles, s.culled), (0, 1));
    }

    #[test]
    fn bad_input_is_skipped_not_panicked() {
        let p = prim(
            vec![[0.0, 0.0, 0.0], [f32::NAN, 1.0, 0.0], [3.0, 3.0, 0.0], [1e30, 0.0, 0.0]],
            vec![0, 1, 2, 0, 2, 9, 0, 2, 3, 0, 0, 2, 7],
        );
        let mut c = Canvas::new(4, 4, [0.0; 4]).unwrap();
        let s = c.draw(&identity(), &p, &DrawOptions::default(), |_| Some([1.0; 4]));
        assert_eq!((s.triangles, s.culled, s.skipped, s.fragments), (0, 1, 3, 0));
        assert!(Canvas::new(0, 5, [0.0; 4]).is_err());
        assert!(Canvas::new(MAX_CANVAS_SIDE + 1, 5, [0.0; 4]).is_err());
    }

    fn test_mesh() -> Primitive {
        // A 40×40 grid of wavy quads spanning the canvas and beyond, overlapping itself twice.
        let n = 40u32;
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (i as f32 * 2.7 - 4.0, j as f32 * 2.3 - 3.0);
                pos.push([x + (y * 0.7).sin(), y + (x * 0.3).cos(), (x * 0.1).sin() + (y * 0.2).cos()]);
            }
        }
        let mut idx = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                idx.extend_from_slice(&[a, a + 1, a + n + 2, a, a + n + 2, a + n + 1]);
            }
        }
        let mut p = prim(pos, idx.clone());
        // a second, shifted copy so the depth test has work to do
        let off = p.positions.len() as u32;
        let shifted: Vec<[f32; 3]> = p.positions.iter().map(|q| [q[0] + 1.3, q[1] - 0.7, q[2] + 0.05]).collect();
        p.positions.extend(shifted);
        p.indices.extend(idx.iter().map(|i| i + off));
        p.colors = p.positions.iter().map(|q| [q[0] / 100.0, q[1] / 100.0, q[2], 1.0]).collect();
        p
    }

    #[test]
    fn parallel_equals_serial_and_is_deterministic() {
        let p = test_mesh();
        let shade = |f: &Fragment| Some(f.color);
        let mut a = Canvas::new(97, 83, [0.0; 4]).unwrap();
        let sa = a.draw(&identity(), &p, &DrawOptions::default(), shade);
        let mut b = Canvas::new(97, 83, [0.0; 4]).unwrap();
        let sb = b.draw_par(&identity(), &p, &DrawOptions::default(), shade);
        assert_eq!(sa, sb);
        assert_eq!(a, b);
        let mut c = Canvas::new(97, 83, [0.0; 4]).unwrap();
        c.draw_par(&identity(), &p, &DrawOptions::default(), shade);
        assert_eq!(b.encode_png().unwrap(), c.encode_png().unwrap());
        assert!(sa.fragments > 0);
    }

    #[test]
    fn discarded_fragments_leave_colour_and_depth() {
        let p = prim(vec![[0.0, 0.0, 1.0], [4.0, 0.0, 1.0], [4.0, 4.0, 1.0], [0.0, 4.0, 1.0]], vec![0, 1, 2, 0, 2, 3]);
        let mut c = Canvas::new(4, 4, [0.5; 4]).unwrap();
        let s = c.draw(&identity(), &p, &DrawOptions::default(), |f| (f.x % 2 == 0).then_some([1.0; 4]));
        assert_eq!(s.fragments, 8);
        assert_eq!(c.pixel(1, 0), Some([0.5; 4]));
        assert_eq!(c.depth[1], f32::INFINITY);
        assert_eq!(c.pixel(0, 0), Some([1.0; 4]));
    }

    /// A ground grid of `n`×`n` cells over [−half, half]² at y = 0, diagonals alternating.
    fn ground(n: u32, half: f32) -> Primitive {
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let t = |k: u32| -half + 2.0 * half * k as f32 / n as f32;
                pos.push([t(i), 0.0, t(j)]);
            }
        }
        let mut idx = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                let (b, c, d) = (a + 1, a + n + 1, a + n + 2);
                // counter-clockwise seen from +Y
                if (i + j) % 2 == 0 {
                    idx.extend_from_slice(&[a, c, d, a, d, b]);
                } else {
                    idx.extend_from_slice(&[a, c, b, b, c, d]);
                }
            }
        }
        prim(pos, idx)
    }

    const IDENTITY: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];

    fn low_camera() -> PerspectiveView {
        // 1 m above a ground that runs under and behind the eye, looking slightly down.
        PerspectiveView {
            eye: [0.3, 1.0, 0.2],
            target: [0.0, 0.2, -6.0],
            up: [0.0, 1.0, 0.0],
            fov_x_deg: 100.0,
            width: 96,
            height: 64,
            near: 0.05,
        }
    }

    #[test]
    fn perspective_ground_through_the_near_plane_is_watertight_and_exact() {
        // 2 km of ground in 40 m cells: most cells cross the near plane or the guard band, so
        // clipping makes every visible pixel; each must be written once, exactly where the ray
        // from the eye through its centre hits the ground in front of the near plane.
        let v = low_camera();
        let p = ground(50, 1000.0);
        let cam = Camera::Perspective(v);
        let mut c = cam.canvas([0.0; 4]).unwrap();
        let mut counts = vec![0u32; c.color.len()];
        let mut depths = vec![f32::NAN; c.color.len()];
        let w = v.width as usize;
        let s = c.draw_camera(&cam, &IDENTITY, &p, &NO_DEPTH, |f| {
            counts[f.y as usize * w + f.x as usize] += 1;
            depths[f.y as usize * w + f.x as usize] = f.depth;
            assert!(f.bary.iter().all(|b| b.is_finite()) && f.position.iter().all(|q| q.is_finite()));
            Some([1.0; 4])
        });
        assert_eq!(s.skipped, 0);
        assert!(s.clipped > 0, "part of the ground is behind the eye");
        let frame = v.frame().unwrap();
        let [r, u, fw] = frame.view.rows.map(|row| [row[0], row[1], row[2]]);
        let mut checked = 0;
        // The ray from the eye through pixel point (px, py) meets the ground at view depth t (the ray
        // parameter, its forward component being 1) and at (x, z).
        let ray = |px: f64, py: f64| {
            let (dx, dy) = ((px - frame.centre[0]) / frame.focal_px, -(py - frame.centre[1]) / frame.focal_px);
            let dir = [0, 1, 2].map(|k| fw[k] + dx * r[k] + dy * u[k]);
            let t = if dir[1] < 0.0 { -v.eye[1] / dir[1] } else { f64::INFINITY };
            (t, [v.eye[0] + t * dir[0], v.eye[2] + t * dir[2]], dir)
        };
        for y in 0..v.height as usize {
            for x in 0..w {
                let (t, hit, dir) = ray(x as f64 + 0.5, y as f64 + 0.5);
                let inside = t.is_finite() && hit[0].abs() < 1000.0 && hit[1].abs() < 1000.0;
                let margin = |a: f64| (a.abs() - 1000.0).abs() > 1.0 && dir[1].abs() > 1e-4;
                if !(margin(hit[0]) && margin(hit[1])) {
                    continue;
                }
                checked += 1;
                assert_eq!(counts[y * w + x], inside as u32, "pixel ({x}, {y})");
                if inside {
                    // Exact up to the 1/256-pixel vertex snapping: within the depths a pixel
                    // centre moved by 1/128 pixel would see (near the horizon that is metres).
                    let z = depths[y * w + x] as f64;
                    let e = 1.0 / 128.0;
                    let around = [(-e, -e), (e, -e), (-e, e), (e, e)]
                        .map(|(ex, ey)| ray(x as f64 + 0.5 + ex, y as f64 + 0.5 + ey).0);
                    let lo = around.iter().fold(t, |a, &b| a.min(b));
                    let hi = around.iter().fold(t, |a, &b| a.max(b));
                    assert!(
                        z >= lo * (1.0 - 1e-6) && z <= hi * (1.0 + 1e-6),
                        "pixel ({x}, {y}): depth {z} vs {t} ({lo}..{hi})"
                    );
                }
            }
        }
        assert!(checked > 5000);
        assert!(counts.contains(&0) && counts.contains(&1));
    }

    #[test]
    fn perspective_clips_what_is_behind_the_eye_and_parallel_matches_serial() {
        let v = low_camera();
        let cam = Camera::Perspective(v);
        // Entirely behind the eye (the view looks towards −Z, this is at +Z).
        let behind = prim(vec![[-1.0, 0.0, 3.0], [1.0, 0.0, 3.0], [0.0, 2.0, 3.0]], vec![0, 1, 2]);
        let mut c = cam.canvas([0.0; 4]).unwrap();
        let s = c.draw_camera(&cam, &IDENTITY, &behind, &DrawOptions::default(), |_| Some([1.0; 4]));
        assert_eq!((s.triangles, s.clipped, s.fragments), (0, 1, 0));
        // A wall through the eye's position, both windings, with colours.
        let mut wall = prim(
            vec![[-3.0, -1.0, 2.0], [3.0, -1.0, 2.0], [3.0, 3.0, -4.0], [-3.0, 3.0, -4.0]],
            vec![0, 1, 2, 0, 2, 3, 0, 2, 1],
        );
        wall.colors = vec![[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0]];
        let mut p = ground(30, 50.0);
        let off = p.positions.len() as u32;
        p.positions.extend_from_slice(&wall.positions);
        p.indices.extend(wall.indices.iter().map(|i| i + off));
        p.colors = vec![[0.5; 4]; off as usize];
        p.colors.extend_from_slice(&wall.colors);
        let shade = |f: &Fragment| Some([f.color[0], f.color[1], f.depth / 100.0, f.front_facing as u8 as f32]);
        let mut a = cam.canvas([0.0; 4]).unwrap();
        let sa = a.draw_camera(&cam, &IDENTITY, &p, &DrawOptions::default(), shade);
        let mut b = cam.canvas([0.0; 4]).unwrap();
        let sb = b.draw_camera_par(&cam, &IDENTITY, &p, &DrawOptions::default(), shade);
        assert_eq!(sa, sb);
        assert_eq!(a, b);
        assert!(a.color.iter().chain(&b.color).flatten().all(|v| v.is_finite()));
        assert!(a.depth.iter().all(|&d| d == f32::INFINITY || d >= v.near as f32 * 0.999));
        assert!(sa.fragments > 0);
    }

    #[test]
    fn facing_agrees_between_the_cameras() {
        // Counter-clockwise seen from +Z; both cameras look from +Z towards −Z.
        let tri = prim(vec![[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]], vec![0, 1, 2]);
        let ortho = Camera::Ortho(OrthoView {
            origin: [-2.0, 2.0, 5.0],
            right: [1.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            forward: [0.0, 0.0, -1.0],
            pixels_per_metre: 8.0,
            width: 32,
            height: 32,
        });
        let persp = Camera::Perspective(PerspectiveView {
            eye: [0.0, 0.0, 5.0],
            target: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            fov_x_deg: 45.0,
            width: 32,
            height: 32,
            near: 0.1,
        });
        for cam in [ortho, persp] {
            let back = DrawOptions { cull: Cull::Back, ..DrawOptions::default() };
            let mut c = cam.canvas([0.0; 4]).unwrap();
            let s = c.draw_camera(&cam, &IDENTITY, &tri, &back, |f| {
                assert!(f.front_facing);
                Some([1.0; 4])
            });
            assert_eq!((s.triangles, s.culled), (1, 0), "{cam:?}");
            assert!(s.fragments > 20);
            let mut rev = tri.clone();
            rev.indices = vec![0, 2, 1];
            let s = c.draw_camera(&cam, &IDENTITY, &rev, &back, |_| Some([1.0; 4]));
            assert_eq!((s.triangles, s.culled), (0, 1), "{cam:?}");
        }
    }

    #[test]
    fn bad_perspective_views_are_errors_and_draw_nothing() {
        let good = low_camera();
        assert!(good.check().is_ok());
        let bad = [
            PerspectiveView { target: good.eye, ..good },
            PerspectiveView { up: [0.0, 0.0, 0.0], ..good },
            PerspectiveView { fov_x_deg: 180.0, ..good },
            PerspectiveView { near: 0.0, ..good },
            PerspectiveView { eye: [f64::NAN, 0.0, 0.0], ..good },
            PerspectiveView { width: 0, ..good },
        ];
        let tri = prim(vec![[-1.0, 0.0, -3.0], [1.0, 0.0, -3.0], [0.0, 2.0, -3.0]], vec![0, 1, 2]);
        for v in bad {
            assert!(v.check().is_err(), "{v:?}");
            assert!(Camera::Perspective(v).canvas([0.0; 4]).is_err());
            let mut c = Canvas::new(8, 8, [0.0; 4]).unwrap();
            let s =
                c.draw_camera(&Camera::Perspective(v), &IDENTITY, &tri, &DrawOptions::default(), |_| Some([1.0; 4]));
            assert_eq!((s.skipped, s.fragments), (1, 0));
        }
    }

    #[test]
    fn ortho_view_maps_corners_and_png_roundtrips() {
        let v = OrthoView::top_down(10.0, 30.0, -5.0, 5.0, 100.0, 200);
        assert_eq!((v.width, v.height), (200, 100));
        let tl = v.to_pixel([10.0, 40.0, -5.0]);
        assert_eq!(tl, [0.0, 0.0, 60.0]);
        let br = v.to_pixel([30.0, 100.0, 5.0]);
        assert_eq!(br, [200.0, 100.0, 0.0]);
        let mut c = v.canvas([0.0, 0.0, 0.0, 0.0]).unwrap();
        c.color[0] = [1.0, 0.5, 0.0, 1.0];
        let png = c.encode_png().unwrap();
        let img = image::load_from_memory(&png).unwrap().to_rgba8();
        assert_eq!(img.dimensions(), (200, 100));
        assert_eq!(img.get_pixel(0, 0).0, [255, 188, 0, 255]);
        assert_eq!(img.get_pixel(1, 0).0, [0, 0, 0, 0]);
    }
}
