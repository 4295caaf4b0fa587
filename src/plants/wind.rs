//! Wind data on plant vertices, in glTF application-specific attributes (never COLOR_0: glTF
//! multiplies COLOR_0 into the base colour and alpha, so data there darkens and cuts out plants).
//!
//! Every plant mesh (grass, flowers, L-system trees and their card levels) carries `_WIND`, one
//! VEC4 of floats per vertex, the same layout everywhere so one vertex shader sways them all:
//! - x: bend weight, 0 at the ground, rising as the square of the height fraction to 1 at the
//!   tallest tip (a cantilever bends about quadratically near its root);
//! - y: phase in radians, 0..2π: per blade for grass, per plant for flowers, 0 for trees (the
//!   whole tree sways as one; an instance phase comes from its position);
//! - z: sway frequency in Hz: per blade for grass, the species' for flowers, and for trees
//!   [`tree_sway_frequency_hz`] of its height;
//! - w: stiffness 0 (limp) … 1 (rigid): per blade for grass, the species' for flowers, 0 for trees
//!   (their bend weight already says how far a vertex moves).
//!
//! L-system trees also carry `_WIND_BRANCH` (VEC4) for branch bending and leaf flutter, after
//! the Crysis vegetation shading (Sousa, GPU Gems 3, ch. 16):
//! - x: branch weight, 0 on the trunk and where a limb leaves it, rising as the square of the arc
//!   length along the limb (twigs inherit their limb's) to 1 at the tip farthest along any limb;
//! - y: branch phase in radians, one per limb (everything grown from one trunk branch), 0 on the
//!   trunk; it cannot tear the mesh because the branch weight is 0 where a limb joins the trunk;
//! - z: flutter weight, 0 on wood, leaves 0 at the stalk to 1 at the tip;
//! - w: flutter phase in radians, one per leaf.
//!
//! docs/wind.md has a GLSL vertex shader and notes for Godot, Unity and Unreal.

use crate::mesh::CustomAttribute;
use crate::random::mix64;

/// The sway attribute every plant mesh carries.
pub const WIND_ATTRIBUTE: &str = "_WIND";
/// Branch bending and leaf flutter on L-system trees.
pub const WIND_BRANCH_ATTRIBUTE: &str = "_WIND_BRANCH";
/// Largest sway frequency any plant carries (Hz): grass blades up to a preset's
/// `wind_frequency`, trees up to 3 Hz, flowers 1.4 Hz.
pub const MAX_FREQUENCY_HZ: f32 = 4.0;
/// What each `_WIND` component ranges over (from 0): weight, phase (radians), frequency (Hz),
/// stiffness. Compact files store `_WIND` as normalized bytes of value / range (`CustomAttribute::range`).
pub const WIND_RANGE: [f32; 4] = [1.0, std::f32::consts::TAU, MAX_FREQUENCY_HZ, 1.0];
/// What each `_WIND_BRANCH` component ranges over (from 0): weight, phase, weight, phase.
pub const WIND_BRANCH_RANGE: [f32; 4] = [1.0, std::f32::consts::TAU, 1.0, std::f32::consts::TAU];
/// The documented ranges of a wind attribute by its name (None for any other attribute): what a
/// reader of an f32 file, which notes no range, gives `CustomAttribute::range`.
pub fn documented_range(name: &str) -> Option<[f32; 4]> {
    match name {
        WIND_ATTRIBUTE => Some(WIND_RANGE),
        WIND_BRANCH_ATTRIBUTE => Some(WIND_BRANCH_RANGE),
        _ => None,
    }
}
/// Flowers: the sway frequency (Hz) and stiffness of a flower stem.
pub const FLOWER_SWAY_HZ: f32 = 1.4;
pub const FLOWER_STIFFNESS: f32 = 0.3;

/// The bend weight at `fraction` of the plant's height (clamped to 0..1): its square.
pub fn bend_weight(fraction: f32) -> f32 {
    if fraction.is_nan() {
        return 0.0;
    }
    fraction.clamp(0.0, 1.0).powi(2)
}

/// A tree's first sway frequency from its height: 1.6 / √height Hz, within 0.1–3 Hz (about
/// 0.3–0.5 Hz for trees of 10–25 m, as field measurements of conifers and broadleaves report; a
/// 1 m shrub sways near 1.6 Hz).
pub fn tree_sway_frequency_hz(height_m: f64) -> f32 {
    if height_m.is_nan() || height_m <= 0.0 {
        return 3.0;
    }
    (1.6 / height_m.sqrt()).clamp(0.1, 3.0) as f32
}

/// A phase in radians (0..2π) from a key: the same key gives the same phase on any machine.
pub fn phase_of(key: u64) -> f32 {
    ((mix64(key ^ 0x7769_6e64_7068_6173) >> 40) as f32 / (1u64 << 24) as f32) * std::f32::consts::TAU
}

/// `_WIND` for vertices swaying by height alone (cards, billboards, flowers): bend from
/// `ground_y` to `top_y`, one phase, frequency and stiffness for all.
pub fn height_wind(
    positions: &[[f32; 3]],
    ground_y: f32,
    top_y: f32,
    phase: f32,
    frequency_hz: f32,
    stiffness: f32,
) -> CustomAttribute {
    let span = top_y - ground_y;
    let values = positions
        .iter()
        .map(|p| {
            let w = if span > 0.0 { bend_weight((p[1] - ground_y) / span) } else { 0.0 };
            [w, phase, frequency_hz, stiffness]
        })
        .collect();
    CustomAttribute { name: WIND_ATTRIBUTE.into(), values, unit_bytes: false, range: Some(WIND_RANGE) }
}

/// The attribute named `name` among `custom`, if any.
pub fn find<'a>(custom: &'a [CustomAttribute], name: &str) -> Option<&'a CustomAttribute> {
    custom.iter().find(|c| c.name == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bend_weight_is_zero_at_the_ground_one_at_the_top_and_monotone() {
        assert_eq!(bend_weight(0.0), 0.0);
        assert_eq!(bend_weight(1.0), 1.0);
        assert_eq!(bend_weight(-0.5), 0.0);
        assert_eq!(bend_weight(2.0), 1.0);
        assert_eq!(bend_weight(f32::NAN), 0.0);
        let w: Vec<f32> = (0..=10).map(|k| bend_weight(k as f32 / 10.0)).collect();
        assert!(w.windows(2).all(|p| p[1] > p[0]));
    }

    #[test]
    fn taller_trees_sway_slower_within_limits() {
        let f: Vec<f32> = [0.5, 2.0, 10.0, 25.0, 100.0].iter().map(|&h| tree_sway_frequency_hz(h)).collect();
        assert!(f.windows(2).all(|p| p[1] < p[0]), "{f:?}");
        assert!(
            (0.3..0.55).contains(&tree_sway_frequency_hz(10.0)) && (0.3..0.55).contains(&tree_sway_frequency_hz(15.0))
        );
        assert_eq!(tree_sway_frequency_hz(0.0), 3.0);
        assert_eq!(tree_sway_frequency_hz(f64::NAN), 3.0);
        assert_eq!(tree_sway_frequency_hz(1e9), 0.1);
    }

    #[test]
    fn phases_are_in_range_reproducible_and_spread() {
        let p: Vec<f32> = (0..1000).map(phase_of).collect();
        assert!(p.iter().all(|x| (0.0..std::f32::consts::TAU).contains(x)));
        assert_eq!(phase_of(7), phase_of(7));
        let mean = p.iter().sum::<f32>() / p.len() as f32;
        assert!((mean - std::f32::consts::PI).abs() < 0.3, "{mean}");
    }

    #[test]
    fn height_wind_follows_the_height() {
        let a = height_wind(&[[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 2.0, 0.0]], 0.0, 2.0, 1.0, 1.5, 0.25);
        assert_eq!(a.name, WIND_ATTRIBUTE);
        assert_eq!(a.values, vec![[0.0, 1.0, 1.5, 0.25], [0.25, 1.0, 1.5, 0.25], [1.0, 1.0, 1.5, 0.25]]);
        // a flat card (no height) does not bend
        assert!(height_wind(&[[0.0, 1.0, 0.0]], 1.0, 1.0, 0.0, 1.0, 0.0).values[0][0] == 0.0);
    }
}
