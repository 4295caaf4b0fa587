//! The one error type of the baking module.

use std::path::PathBuf;

use crate::bake::raster::{RasterError, MAX_CANVAS_SIDE};
use crate::export::ExportError;

#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    #[error("could not read {source_name} as a PNG image: {reason} (save it as an 8- or 16-bit PNG)")]
    Png { source_name: String, reason: String },
    // images share the rasteriser's canvas limit (`image::MAX_IMAGE_SIDE` is `MAX_CANVAS_SIDE`)
    #[error(
        "{source_name} is {width}×{height} pixels; images must be 1 to {MAX_CANVAS_SIDE} pixels a side (resize it)"
    )]
    ImageSize { source_name: String, width: u64, height: u64 },
    #[error("could not read {}: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("image of {width}×{height} pixels holds {pixels} pixels instead of {expected}: a caller built it wrong")]
    Malformed { width: u32, height: u32, pixels: usize, expected: u64 },
    #[error("could not encode the image as PNG: {0}")]
    Encode(String),
    #[error("file stem {stem:?} for the mip images must be a plain, non-empty file name without folders")]
    BadStem { stem: String },
    #[error(transparent)]
    Raster(#[from] RasterError),
    #[error(transparent)]
    Write(#[from] ExportError),
}
