//! Writes the `snow/` output folder: every file atomically (temporary name, then rename), so a
//! failed build leaves the previous outputs intact.

use std::path::{Path, PathBuf};

use crate::export::{write_atomic, write_scene};
use crate::mesh::Scene;
use crate::snow::cover::CoverMask;
use crate::snow::emitter::{emitter_json, Emitter};
use crate::snow::error::SnowError;
use crate::snow::flakes::FlakeAtlas;
use crate::snow::particles::{particles_csv, snowfall_scene, Particle};

/// File name of the flake atlas, which `emitter.json` refers to.
pub const ATLAS_FILE: &str = "flakes.png";

fn write(path: PathBuf, bytes: &[u8], written: &mut Vec<PathBuf>) -> Result<(), SnowError> {
    write_atomic(&path, bytes).map_err(|e| SnowError::Write(e.to_string()))?;
    written.push(path);
    Ok(())
}

/// Writes `flakes.png`, `emitter.json`, `particles.csv` and `snowfall.glb` into `dir` (created if
/// missing); returns the files written.
pub fn write_snowfall(
    dir: &Path,
    atlas: &FlakeAtlas,
    emitter: &Emitter,
    particles: &[Particle],
    alpha_cutoff: f32,
) -> Result<Vec<PathBuf>, SnowError> {
    let mut written = Vec::new();
    // build everything that can fail on the data before touching the disk
    let json = emitter_json(emitter, atlas, ATLAS_FILE)?;
    let scene = snowfall_scene("snowfall", particles, atlas, alpha_cutoff);
    write(dir.join(ATLAS_FILE), &atlas.png, &mut written)?;
    write(dir.join("emitter.json"), json.as_bytes(), &mut written)?;
    write(dir.join("particles.csv"), particles_csv(particles).as_bytes(), &mut written)?;
    let glb = write_scene(&scene, &dir.join("snowfall.glb")).map_err(|e| SnowError::Write(e.to_string()))?;
    written.extend(glb);
    Ok(written)
}

/// Writes `cover_mask.png` and, when given, `snow_layer.glb` into `dir`.
pub fn write_cover(dir: &Path, mask: &CoverMask, layer: Option<&Scene>) -> Result<Vec<PathBuf>, SnowError> {
    let mut written = Vec::new();
    let png = mask.to_image().encode_png().map_err(|e| SnowError::Bake(e.to_string()))?;
    write(dir.join("cover_mask.png"), &png, &mut written)?;
    if let Some(layer) = layer {
        written.extend(write_scene(layer, &dir.join("snow_layer.glb")).map_err(|e| SnowError::Write(e.to_string()))?);
    }
    Ok(written)
}
