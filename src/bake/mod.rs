//! Baking: drawing meshes into images. `raster` is the exact software rasteriser the preview and
//! (later) the grass and tree billboard baker draw with; atlases and mip chains will live beside it.

pub mod raster;

pub use raster::{Canvas, Cull, DrawOptions, DrawStats, Fragment, OrthoView, Projection, RasterError};
