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
//!
//! Parts: `canvas` (the image and a draw call's options, statistics, fragments), `camera` (views and
//! projections), `scan` (the fixed-point scan and the orthographic path), `perspective` (clipping and
//! perspective-correct scan), `draw` (serial and banded parallel draw calls), `png` (8-bit sRGB out).

mod camera;
mod canvas;
mod draw;
mod limits;
mod perspective;
pub mod png;
mod scan;
#[cfg(test)]
mod tests;

pub use camera::{Camera, OrthoView, PerspectiveView, Projection};
pub use canvas::{Canvas, Cull, DrawOptions, DrawStats, Fragment};
pub use draw::draw_all;
pub use limits::{RasterError, MAX_CANVAS_SIDE, MAX_VERTEX_SUBPIXELS};
