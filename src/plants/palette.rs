//! The species palette of the preview and the map: a distinct, stable colour per species and a
//! nominal size per kind (what the top-down map draws instances with; the plants themselves come
//! from the grass, flower, tree and mesh generators).

use crate::plants::SpeciesKind;

/// A plausible height in metres of a kind's plant at scale 1, for the preview's footprints when no
/// mesh is built (an L-system tree with a set height uses that instead).
pub fn nominal_height_m(kind: SpeciesKind) -> f32 {
    match kind {
        SpeciesKind::Tree => 8.0,
        SpeciesKind::Grass => 0.4,
        SpeciesKind::Flower => 0.3,
        SpeciesKind::Mesh => 1.0,
    }
}

/// A distinct, stable colour per species (linear RGB), also used for its preview dots.
pub fn species_color(kind: SpeciesKind, index: usize) -> [f32; 4] {
    let base: [[f32; 3]; 4] = match kind {
        SpeciesKind::Tree => [[0.05, 0.25, 0.06], [0.10, 0.32, 0.05], [0.03, 0.18, 0.10], [0.15, 0.28, 0.03]],
        SpeciesKind::Grass => [[0.35, 0.60, 0.12], [0.45, 0.65, 0.15], [0.30, 0.52, 0.20], [0.55, 0.62, 0.18]],
        SpeciesKind::Flower => [[0.90, 0.75, 0.10], [0.85, 0.25, 0.45], [0.55, 0.35, 0.85], [0.95, 0.95, 0.95]],
        SpeciesKind::Mesh => [[0.55, 0.50, 0.45], [0.45, 0.45, 0.50], [0.60, 0.40, 0.30], [0.40, 0.40, 0.40]],
    };
    let c = base[index % base.len()];
    [c[0], c[1], c[2], 1.0]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_are_stable_per_species_and_distinct_within_a_kind() {
        for kind in [SpeciesKind::Tree, SpeciesKind::Grass, SpeciesKind::Flower, SpeciesKind::Mesh] {
            assert_eq!(species_color(kind, 1), species_color(kind, 5), "{kind:?}: the palette repeats every 4");
            assert_ne!(species_color(kind, 0), species_color(kind, 1));
            assert!(nominal_height_m(kind) > 0.0);
        }
    }
}
