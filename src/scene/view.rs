//! Cameras (`[[view]]`) and what a view selects: the level of detail an instance or a terrain
//! chunk is drawn at, and what is culled. Plain data and arithmetic; the view stage
//! (`view_stage`) applies it to the files the other stages wrote.
//!
//! Switch distances are measured for the scene's reference screen (`[lod]`, [`LodView`]): level k
//! of a chain is within the pixel budget from `d_k` on. A view with another image height or field
//! of view sees an error of ε metres at distance d as ε · H / (2 d tan(fov/2)) pixels, so its
//! distances are the reference's times [`view_distance_factor`]; an instance scaled by s has s
//! times the error of the unit chain, so its distances are s times longer too.

use serde::{Deserialize, Serialize};

use crate::lod::LodView;

/// Vertical field of view of a `[[view]]` without `fov` (degrees).
pub const DEFAULT_VIEW_FOV_DEG: f64 = 60.0;
/// Image size of a `[[view]]` without `size` (pixels, width × height).
pub const DEFAULT_VIEW_SIZE_PX: [u32; 2] = [1920, 1080];
/// Largest side of a view's image (pixels).
pub const MAX_VIEW_SIDE_PX: u32 = 16_384;

/// `[[view]]` as written: any of position, target or yaw/pitch may be left out and is then
/// derived from the terrain ([`ViewSettings::resolve`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewSettings {
    pub name: String,
    /// Eye position (m).
    pub position: Option<[f64; 3]>,
    /// Point looked at (m); excludes `yaw_pitch_deg`.
    pub target: Option<[f64; 3]>,
    /// Heading and elevation of the view direction in degrees: yaw 0 looks along −Z, 90 along +X;
    /// pitch > 0 looks up.
    pub yaw_pitch_deg: Option<[f64; 2]>,
    /// Vertical field of view (degrees).
    pub fov_y_deg: f64,
    /// Image width × height (pixels).
    pub size_px: [u32; 2],
}

impl ViewSettings {
    /// The view of a preset without `[[view]]`: every field derived from the terrain.
    pub fn default_view() -> ViewSettings {
        ViewSettings {
            name: "view0".into(),
            position: None,
            target: None,
            yaw_pitch_deg: None,
            fov_y_deg: DEFAULT_VIEW_FOV_DEG,
            size_px: DEFAULT_VIEW_SIZE_PX,
        }
    }

    /// The camera, filling what the view leaves out from the terrain: `extent` = (min x, min z,
    /// max x, max z) of the surface and `height_at(x, z)` its height. The default eye stands 5 %
    /// in from the +Z edge, on the centre line, 2 m + 2 % of the larger side above the ground; the
    /// default target is the ground at the centre of the extent.
    pub fn resolve(&self, extent: [f64; 4], height_at: impl Fn(f64, f64) -> Option<f64>) -> Result<Camera, String> {
        let (w, d) = (extent[2] - extent[0], extent[3] - extent[1]);
        let cx = 0.5 * (extent[0] + extent[2]);
        let cz = 0.5 * (extent[1] + extent[3]);
        let ground = |x: f64, z: f64| height_at(x, z).unwrap_or(0.0);
        let eye = self.position.unwrap_or_else(|| {
            let z = extent[3] - 0.05 * d;
            [cx, ground(cx, z) + 2.0 + 0.02 * w.max(d), z]
        });
        let forward = match (self.target, self.yaw_pitch_deg) {
            (_, Some([yaw, pitch])) => {
                let (y, p) = (yaw.to_radians(), pitch.to_radians());
                [y.sin() * p.cos(), p.sin(), -y.cos() * p.cos()]
            }
            (target, None) => {
                let t = target.unwrap_or_else(|| [cx, ground(cx, cz), cz]);
                let v = [t[0] - eye[0], t[1] - eye[1], t[2] - eye[2]];
                let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                if !(n > 1e-6) {
                    return Err(format!(
                        "view `{}`: the target is where the eye is ({:?}); move the target or set yaw/pitch",
                        self.name, eye
                    ));
                }
                [v[0] / n, v[1] / n, v[2] / n]
            }
        };
        Ok(Camera { name: self.name.clone(), eye, forward, fov_y_deg: self.fov_y_deg, size_px: self.size_px })
    }
}

/// A resolved view: where the eye is and where it looks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub name: String,
    pub eye: [f64; 3],
    /// Unit view direction.
    pub forward: [f64; 3],
    pub fov_y_deg: f64,
    pub size_px: [u32; 2],
}

impl Camera {
    /// Pixels per metre at 1 m of this view's image: H / (2 tan(fov/2)).
    pub fn pixels_per_metre_at_1m(&self) -> f64 {
        self.size_px[1] as f64 / (2.0 * (self.fov_y_deg.to_radians() * 0.5).tan())
    }

    pub fn distance_to(&self, p: [f64; 3]) -> f64 {
        let v = [p[0] - self.eye[0], p[1] - self.eye[1], p[2] - self.eye[2]];
        (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
    }

    /// Distance from the eye to the nearest point of an axis-aligned box.
    pub fn distance_to_box(&self, min: [f64; 3], max: [f64; 3]) -> f64 {
        let mut s = 0.0;
        for a in 0..3 {
            let e = self.eye[a];
            let g = if e < min[a] {
                min[a] - e
            } else if e > max[a] {
                e - max[a]
            } else {
                0.0
            };
            s += g * g;
        }
        s.sqrt()
    }
}

/// How much farther than on the reference screen a level may switch in `camera`: the ratio of
/// their pixels per metre at 1 m (1 for the same image height and field of view).
pub fn view_distance_factor(camera: &Camera, policy: &LodView) -> f64 {
    camera.pixels_per_metre_at_1m() / (policy.screen_height_px / (2.0 * (policy.fov_y_deg.to_radians() * 0.5).tan()))
}

/// The level shown at `distance_m` for a chain switching at `switch_m` (reference-screen
/// distances, finest first, `switch_m[0]` = 0), scaled by `factor` (view and instance scale): the
/// last level whose scaled switch distance is ≤ the distance.
pub fn level_at(distance_m: f64, switch_m: &[f64], factor: f64) -> usize {
    let mut level = 0;
    for (k, &d) in switch_m.iter().enumerate().skip(1) {
        if d * factor <= distance_m {
            level = k;
        }
    }
    level
}

/// The cull distance of a species on the reference screen: the preset's `cull_distance` when
/// set, else where its height spans the pixel budget ([`LodView::cull_distance`]), and never
/// before its coarsest level switches in (so every level is seen somewhere).
pub fn cull_distance(set_m: Option<f64>, height_m: f64, last_switch_m: f64, policy: &LodView) -> CullDistance {
    match set_m {
        Some(m) => CullDistance { distance_m: m, scales_with_view: false },
        None => CullDistance { distance_m: policy.cull_distance(height_m).max(last_switch_m), scales_with_view: true },
    }
}

/// Where a species stops being drawn.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CullDistance {
    /// Metres (from the eye to the instance's bounding-sphere centre).
    pub distance_m: f64,
    /// Derived from the pixel budget: scaled like switch distances (by the view and the
    /// instance's scale). A `cull_distance` the preset sets is used as written.
    pub scales_with_view: bool,
}

impl CullDistance {
    /// Whether an instance at `distance_m` (scale `scale`, in a view with `factor`) is culled.
    pub fn culls(&self, distance_m: f64, factor: f64, scale: f64) -> bool {
        let limit = if self.scales_with_view { self.distance_m * factor * scale } else { self.distance_m };
        distance_m > limit
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(_: f64, _: f64) -> Option<f64> {
        Some(10.0)
    }

    #[test]
    fn default_view_looks_at_the_centre_from_the_edge() {
        let c = ViewSettings::default_view().resolve([0.0, 0.0, 1000.0, 2000.0], flat).unwrap();
        assert_eq!(c.eye[0], 500.0);
        assert!((c.eye[2] - 1900.0).abs() < 1e-9);
        assert!((c.eye[1] - (10.0 + 2.0 + 40.0)).abs() < 1e-9);
        // towards −Z and down
        assert!(c.forward[2] < -0.9 && c.forward[1] < 0.0, "{:?}", c.forward);
        let yaw = ViewSettings { yaw_pitch_deg: Some([90.0, 0.0]), ..ViewSettings::default_view() };
        let c = yaw.resolve([0.0, 0.0, 10.0, 10.0], flat).unwrap();
        assert!((c.forward[0] - 1.0).abs() < 1e-12);
        let same = ViewSettings {
            position: Some([1.0, 2.0, 3.0]),
            target: Some([1.0, 2.0, 3.0]),
            ..ViewSettings::default_view()
        };
        assert!(same.resolve([0.0, 0.0, 10.0, 10.0], flat).unwrap_err().contains("target"));
    }

    #[test]
    fn levels_switch_in_order_and_scale_with_the_factor() {
        let switch = [0.0, 30.0, 200.0, 250.0];
        assert_eq!(level_at(0.0, &switch, 1.0), 0);
        assert_eq!(level_at(29.9, &switch, 1.0), 0);
        assert_eq!(level_at(30.0, &switch, 1.0), 1);
        assert_eq!(level_at(220.0, &switch, 1.0), 2);
        assert_eq!(level_at(1e9, &switch, 1.0), 3);
        // a twice-as-large instance (or a twice-as-sharp view) keeps each level twice as far
        assert_eq!(level_at(59.0, &switch, 2.0), 0);
        assert_eq!(level_at(60.0, &switch, 2.0), 1);
    }

    #[test]
    fn the_reference_view_has_factor_one_and_sharper_views_more() {
        let policy = LodView::default();
        let c = Camera {
            name: "v".into(),
            eye: [0.0; 3],
            forward: [0.0, 0.0, -1.0],
            fov_y_deg: policy.fov_y_deg,
            size_px: [1920, 1080],
        };
        assert!((view_distance_factor(&c, &policy) - 1.0).abs() < 1e-12);
        let tall = Camera { size_px: [3840, 2160], ..c.clone() };
        assert!((view_distance_factor(&tall, &policy) - 2.0).abs() < 1e-12);
        assert_eq!(c.distance_to_box([1.0, -1.0, -1.0], [2.0, 1.0, 1.0]), 1.0);
        assert_eq!(c.distance_to_box([-1.0; 3], [1.0; 3]), 0.0);
    }

    #[test]
    fn default_cull_follows_the_budget_and_never_hides_the_last_level() {
        let policy = LodView::default();
        let c = cull_distance(None, 0.5, 10.0, &policy);
        assert!((c.distance_m - policy.switch_distance(0.5)).abs() < 1e-9);
        let looser = LodView { max_screen_error_px: 4.0, ..policy };
        assert!(cull_distance(None, 0.5, 10.0, &looser).distance_m < c.distance_m);
        assert_eq!(cull_distance(None, 0.01, 300.0, &policy).distance_m, 300.0);
        let set = cull_distance(Some(80.0), 0.5, 10.0, &policy);
        assert!(!set.culls(80.0, 3.0, 2.0) && set.culls(80.1, 3.0, 2.0));
        assert!(!c.culls(c.distance_m * 1.9, 1.0, 2.0));
    }
}
