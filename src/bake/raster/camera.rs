//! Cameras: the orthographic view (an affine [`Projection`] to pixels) and the pinhole perspective
//! view with its checked frame and clip planes (near plane and guard band).

use super::canvas::Canvas;
use super::limits::{RasterError, MAX_CANVAS_SIDE};
use crate::math::{cross3, dot3, normalize3, sub3};

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
pub(super) struct PerspFrame {
    /// World → view space (x right, y up, z forward): rows right, up, forward.
    pub(super) view: Projection,
    pub(super) focal_px: f64,
    pub(super) centre: [f64; 2],
    pub(super) size: [f64; 2],
    pub(super) near: f64,
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

    pub(super) fn frame(&self) -> Result<PerspFrame, RasterError> {
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

    /// A test of spheres (world centre, radius) against the view's frustum: false only for a
    /// sphere wholly nearer than the near plane or wholly outside one of the image's four sides, so
    /// a mesh inside such a sphere covers no pixel and may be skipped (a true may still draw
    /// nothing).
    pub fn sphere_test(&self) -> Result<impl Fn([f64; 3], f64) -> bool, RasterError> {
        let f = self.frame()?;
        let (hw, hh) = (f.size[0] * 0.5, f.size[1] * 0.5);
        let (nx, ny) = ((f.focal_px * f.focal_px + hw * hw).sqrt(), (f.focal_px * f.focal_px + hh * hh).sqrt());
        Ok(move |c: [f64; 3], r: f64| {
            let v = f.view.apply(c);
            let fx = f.focal_px;
            !(v[2] + r < f.near
                || (fx * v[0] - hw * v[2]) / nx > r
                || (-fx * v[0] - hw * v[2]) / nx > r
                || (fx * v[1] - hh * v[2]) / ny > r
                || (-fx * v[1] - hh * v[2]) / ny > r)
        })
    }
}

impl PerspFrame {
    /// View space → (pixel x, pixel y, depth); z must be > 0.
    #[inline]
    pub(super) fn project(&self, v: [f64; 3]) -> [f64; 3] {
        let s = self.focal_px / v[2];
        [self.centre[0] + v[0] * s, self.centre[1] - v[1] * s, v[2]]
    }

    /// The clip planes as (a, b, c, d): a point of view space is kept where a·x + b·y + c·z + d ≥ 0.
    /// The near plane first, then the guard band's four sides (pixel x ≥ −G, x ≤ width + G, and y
    /// alike), written without dividing by z, which is positive once the near plane has been applied.
    pub(super) fn clip_planes(&self) -> [[f64; 4]; 5] {
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
