//! The rasterizer's limits, fixed-point resolution and error type.

use crate::export::ExportError;

/// Largest canvas side in pixels: keeps canvases within a few GB and the fixed-point arithmetic far
/// inside `i64` (see [`MAX_VERTEX_SUBPIXELS`]).
pub const MAX_CANVAS_SIDE: u32 = 16384;

/// Sub-pixel bits of the snapped vertex positions (1/256 pixel, as GPUs do).
const SUBPIXEL_BITS: u32 = 8;
pub(super) const SUBPIXEL: i64 = 1 << SUBPIXEL_BITS;

/// Vertices farther than this from the canvas origin (in sub-pixels, = 2^20 pixels) are not drawn:
/// it keeps every edge-function product below 2^60. Such triangles are counted in
/// [`DrawStats::skipped`] (an orthographic view that far off is a caller bug, not a silent loss).
pub const MAX_VERTEX_SUBPIXELS: i64 = 1 << 28;

/// Rows per parallel band: small enough to balance two to many cores, large enough that few
/// triangles straddle bands (each straddling triangle is set up once per band).
pub(super) const BAND_ROWS: u32 = 16;

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
