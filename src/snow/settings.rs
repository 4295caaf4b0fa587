//! The resolved `[snow]` section: flakes, emitter, cover, mask and layer, checked as a whole.

use crate::snow::cover::CoverSettings;
use crate::snow::emitter::Emitter;
use crate::snow::error::{bad, within, SnowError};
use crate::snow::flakes::FlakeSettings;

/// The resolved `[snow]` section of a preset: everything the scene's snow stage needs (written
/// into the manifest as it is). See docs/presets.md, section `[snow]`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SnowSettings {
    pub flakes: FlakeSettings,
    pub emitter: Emitter,
    pub cover: CoverSettings,
    /// Pixels along the longer side of the cover mask (`cover_mask.png`).
    pub mask_px: u32,
    /// Write `snow_layer.glb` (the snow surface lifted by its depth).
    pub layer: bool,
    /// Triangles of the layer have all three vertices at this weight or more.
    pub layer_min_weight: f32,
    /// 0..1: a grass or flower instance is dropped with probability `thin_plants × weight`.
    pub thin_plants: f64,
}

impl Default for SnowSettings {
    fn default() -> Self {
        SnowSettings {
            flakes: FlakeSettings::default(),
            emitter: Emitter::default(),
            cover: CoverSettings::default(),
            mask_px: 512,
            layer: true,
            layer_min_weight: 0.5,
            thin_plants: 0.8,
        }
    }
}

impl SnowSettings {
    /// Every part checked as a whole (the preset parser checks single keys first).
    pub fn check(&self) -> Result<(), SnowError> {
        self.flakes.check()?;
        self.emitter.check()?;
        self.cover.check()?;
        if !(16..=8192).contains(&self.mask_px) {
            return bad("mask_px", format!("is {}", self.mask_px), "use 16 to 8192 pixels");
        }
        if !within(self.layer_min_weight, 0.0, 1.0) {
            return bad("layer_min_weight", format!("is {}", self.layer_min_weight), "use 0 to 1");
        }
        if !(self.thin_plants.is_finite() && (0.0..=1.0).contains(&self.thin_plants)) {
            return bad(
                "thin_plants",
                format!("is {}", self.thin_plants),
                "use 0 (no thinning) to 1 (no plant where the cover is full)",
            );
        }
        Ok(())
    }
}
