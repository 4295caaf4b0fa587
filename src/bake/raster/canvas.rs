//! The canvas a rasteriser draws into (linear RGBA colour and depth per pixel) and the vocabulary of
//! a draw call: culling, options, statistics and the fragment a shader is given.

use super::limits::{RasterError, MAX_CANVAS_SIDE};

/// An image being drawn: linear RGBA colour and depth per pixel, row-major from the top-left.
#[derive(Debug, Clone, PartialEq)]
pub struct Canvas {
    pub width: u32,
    pub height: u32,
    pub color: Vec<[f32; 4]>,
    pub depth: Vec<f32>,
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
    /// Adds another draw's counts (a mesh's primitives, a canvas' bands).
    pub(crate) fn add(&mut self, o: &DrawStats) {
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
}
