//! Baking: drawing meshes into images. `raster` is the exact software rasteriser (orthographic and
//! perspective) the preview and the grass and tree billboard baker draw with; `render` draws meshes
//! with their materials, `atlas` dilates atlases and builds coverage-preserving mip chains,
//! `compare` and `views` measure the image error of levels of detail.

pub mod atlas;
pub mod compare;
pub mod error;
pub mod image;
pub mod raster;
pub mod render;
pub mod views;

pub use atlas::{coverage, dilate, mip_chain, write_mip_pngs, MipLevel};
pub use compare::{compare, ImageError};
pub use error::BakeError;
pub use image::Image;
pub use raster::{
    Camera, Canvas, Cull, DrawOptions, DrawStats, Fragment, OrthoView, PerspectiveView, Projection, RasterError,
};
pub use render::{render_mesh, RenderOptions, Shading};
pub use views::{lod_image_error, LodImageReport, Renderable, ScreenView};
