//! Renders a scene (as scene.glb holds it) from a view with the project's rasterizer: every node's
//! mesh at its transform, every EXT_mesh_gpu_instancing instance at its own, base colour ×
//! texture with the alpha tests, Lambert-lit under a fixed sun, over a sky colour. What
//! `preview.png` shows, and what a view's image comparison (LoD against full detail) measures.

use crate::bake::image::Image;
use crate::bake::raster::{Camera as RasterCamera, Canvas, PerspectiveView};
use crate::bake::render::{render_mesh, RenderOptions, Shading};
use crate::mesh::{Node, Scene};
use crate::scene::view::Camera;

/// Sky colour (linear RGBA) behind the scene.
pub const SKY: [f32; 4] = [0.55, 0.7, 0.9, 1.0];
/// Towards the sun (world space, normalised by the shader) and the ambient share of the light.
const SUN: [f32; 3] = [0.3, 1.0, 0.2];
const AMBIENT: f32 = 0.35;
/// Nearest distance drawn (m).
const NEAR_M: f64 = 0.1;
/// Meshes with more triangles are drawn in parallel bands; smaller ones (most instances) serially.
const PARALLEL_TRIANGLES: usize = 4096;

/// The rasterizer's camera for `camera` at `width` × `height` pixels (the view's aspect kept by
/// the caller).
pub fn raster_camera(camera: &Camera, width: u32, height: u32) -> RasterCamera {
    let aspect = width as f64 / height.max(1) as f64;
    let fov_x = 2.0 * ((camera.fov_y_deg.to_radians() * 0.5).tan() * aspect).atan();
    let f = camera.forward;
    // an up that is not parallel to the view axis
    let up = if f[1].abs() > 0.999 { [0.0, 0.0, -1.0] } else { [0.0, 1.0, 0.0] };
    RasterCamera::Perspective(PerspectiveView {
        eye: camera.eye,
        target: [camera.eye[0] + f[0], camera.eye[1] + f[1], camera.eye[2] + f[2]],
        up,
        fov_x_deg: fov_x.to_degrees().min(179.0),
        width,
        height,
        near: NEAR_M,
    })
}

/// 3×4 object-to-world matrix (rows; 4th column the translation) of a translation, unit
/// quaternion (x, y, z, w) and scale.
pub fn trs_matrix(t: [f32; 3], q: [f32; 4], s: [f32; 3]) -> [[f64; 4]; 3] {
    let [x, y, z, w] = q.map(|c| c as f64);
    let r = [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
        [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
        [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
    ];
    let s = s.map(|c| c as f64);
    std::array::from_fn(|row| [r[row][0] * s[0], r[row][1] * s[1], r[row][2] * s[2], t[row] as f64])
}

fn mul(a: &[[f64; 4]; 3], b: &[[f64; 4]; 3]) -> [[f64; 4]; 3] {
    std::array::from_fn(|r| {
        let mut row = [0.0; 4];
        for (c, out) in row.iter_mut().enumerate() {
            *out = (0..3).map(|k| a[r][k] * b[k][c]).sum::<f64>() + if c == 3 { a[r][3] } else { 0.0 };
        }
        row
    })
}

/// What a render drew.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RenderFigures {
    pub triangles: u64,
    pub instances: u64,
}

/// Renders `scene` from `camera` at `width` × `height`.
pub fn render_view(scene: &Scene, camera: &Camera, width: u32, height: u32) -> Result<(Canvas, RenderFigures), String> {
    let mut canvas = Canvas::new(width, height, SKY).map_err(|e| e.to_string())?;
    // normal maps hold data (glTF reads them as linear values), colour textures sRGB
    let is_data: Vec<bool> =
        (0..scene.textures.len()).map(|t| scene.materials.iter().any(|m| m.normal_texture == Some(t))).collect();
    // decoded in parallel (a world's terrain maps are 2048² each); the first bad one named
    let textures: Vec<Result<Image, String>> = {
        use rayon::prelude::*;
        scene
            .textures
            .par_iter()
            .zip(&is_data)
            .map(|(t, &data)| {
                if data { Image::from_png_data(&t.png) } else { Image::from_png(&t.png) }
                    .map_err(|e| format!("texture `{}`: {e}", t.name))
            })
            .collect()
    };
    let textures: Vec<Image> = textures.into_iter().collect::<Result<_, _>>()?;
    let cam = raster_camera(camera, width, height);
    let RasterCamera::Perspective(view) = &cam else { unreachable!("raster_camera is a perspective") };
    let may_see = view.sphere_test().map_err(|e| e.to_string())?;
    // per mesh, a sphere around its vertices (object space): an instance whose sphere lies outside
    // the view is skipped, not drawn triangle by triangle (exact: it covers no pixel)
    let spheres: Vec<Option<([f64; 3], f64)>> = scene.meshes.iter().map(bounding_sphere).collect();
    let mut figures = RenderFigures::default();
    let identity = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
    let mut stack: Vec<(usize, [[f64; 4]; 3])> = scene.roots.iter().rev().map(|&r| (r, identity)).collect();
    let mut visited = vec![false; scene.nodes.len()];
    while let Some((index, parent)) = stack.pop() {
        let Some(node) = scene.nodes.get(index) else { continue };
        if std::mem::replace(&mut visited[index], true) {
            continue;
        }
        let world = mul(&parent, &node_matrix(node));
        if let Some(mesh) = node.mesh.and_then(|m| scene.meshes.get(m)) {
            let opts = RenderOptions {
                shading: Shading::Lambert { light_dir: SUN, ambient: AMBIENT },
                parallel: mesh.triangle_count() > PARALLEL_TRIANGLES,
                ..RenderOptions::default()
            };
            match &node.instances {
                Some(inst) => {
                    for k in 0..inst.translations.len() {
                        let m = mul(&world, &trs_matrix(inst.translations[k], inst.rotations[k], inst.scales[k]));
                        figures.instances += 1;
                        if spheres[node.mesh.unwrap_or(0)]
                            .is_some_and(|(c, r)| !may_see(transform(&m, c), r * max_scale(&m)))
                        {
                            continue;
                        }
                        figures.triangles +=
                            render_mesh(&mut canvas, &cam, &m, mesh, &scene.materials, &textures, &opts).triangles
                                as u64;
                    }
                }
                None => {
                    figures.triangles +=
                        render_mesh(&mut canvas, &cam, &world, mesh, &scene.materials, &textures, &opts).triangles
                            as u64
                }
            }
        }
        stack.extend(node.children.iter().rev().map(|&c| (c, world)));
    }
    Ok((canvas, figures))
}

/// The centre of `mesh`'s bounding box and the distance from it to its farthest vertex; None
/// without vertices.
fn bounding_sphere(mesh: &crate::mesh::Mesh) -> Option<([f64; 3], f64)> {
    let (lo, hi) = crate::scene::view_stage::mesh_bounds(mesh)?;
    let c = [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a]));
    let r2 = mesh
        .primitives
        .iter()
        .flat_map(|p| &p.positions)
        .map(|p| (0..3).map(|a| (p[a] as f64 - c[a]).powi(2)).sum::<f64>())
        .fold(0.0, f64::max);
    // a little slack for f32 rounding of the transformed vertices
    Some((c, r2.sqrt() * (1.0 + 1e-6) + 1e-6))
}

fn transform(m: &[[f64; 4]; 3], p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3])
}

/// The largest factor by which `m` stretches a length (bounded by its columns' lengths).
fn max_scale(m: &[[f64; 4]; 3]) -> f64 {
    (0..3).map(|c| (0..3).map(|r| m[r][c] * m[r][c]).sum::<f64>()).sum::<f64>().sqrt()
}

fn node_matrix(n: &Node) -> [[f64; 4]; 3] {
    trs_matrix(n.translation, n.rotation, n.scale)
}

/// How two renders of one view differ ([`image_difference`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Difference {
    /// Share of pixels (each the box-filtered mean of its samples, linear colour) whose colour
    /// differs by more than the threshold in some channel.
    pub differing: f64,
    /// Colour RMSE of those pixels over every channel.
    pub color_rmse: f64,
    /// The same share over single samples (the image without anti-aliasing).
    pub differing_samples: f64,
}

/// How two renders of one view, each `samples` × `samples` samples per pixel (the canvases are
/// that many times the image's size), differ once resolved as an engine's anti-aliasing resolves
/// them: every pixel the mean of its samples in linear colour. A share of the pixels that differ
/// by more than `threshold` in any channel, the colour RMSE, and the share of single samples that
/// differ (what an aliased render would count: a sub-pixel leaf or a culled flower there is a whole
/// pixel or none).
pub fn image_difference(a: &Canvas, b: &Canvas, samples: u32, threshold: f32) -> Difference {
    let k = samples.max(1) as usize;
    let (w, h) = (a.width.min(b.width) as usize, a.height.min(b.height) as usize);
    let (pw, ph) = (w / k, h / k);
    let (mut differing, mut differing_samples, mut sq) = (0usize, 0usize, 0.0f64);
    let over = |p: &[f32; 4], q: &[f32; 4]| (0..3).any(|c| (p[c] - q[c]).abs() > threshold);
    let at = |c: &Canvas, x: usize, y: usize| c.color[y * c.width as usize + x];
    for py in 0..ph {
        for px in 0..pw {
            let (mut ma, mut mb) = ([0.0f32; 4], [0.0f32; 4]);
            for y in py * k..(py + 1) * k {
                for x in px * k..(px + 1) * k {
                    let (p, q) = (at(a, x, y), at(b, x, y));
                    differing_samples += over(&p, &q) as usize;
                    for c in 0..3 {
                        ma[c] += p[c];
                        mb[c] += q[c];
                    }
                }
            }
            let n = (k * k) as f32;
            let (ma, mb) = (ma.map(|v| v / n), mb.map(|v| v / n));
            differing += over(&ma, &mb) as usize;
            sq += (0..3).map(|c| ((ma[c] - mb[c]) as f64).powi(2)).sum::<f64>();
        }
    }
    let pixels = (pw * ph).max(1);
    Difference {
        differing: differing as f64 / pixels as f64,
        color_rmse: (sq / (3 * pixels) as f64).sqrt(),
        differing_samples: differing_samples as f64 / (pixels * k * k) as f64,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trs_matches_the_rotation_and_scale() {
        let h = std::f32::consts::FRAC_1_SQRT_2;
        // 90° about +Y: +X goes to −Z
        let m = trs_matrix([1.0, 2.0, 3.0], [0.0, h, 0.0, h], [2.0; 3]);
        let x = [m[0][0], m[1][0], m[2][0]];
        assert!((x[0]).abs() < 1e-6 && (x[2] + 2.0).abs() < 1e-6, "{x:?}");
        assert_eq!([m[0][3], m[1][3], m[2][3]], [1.0, 2.0, 3.0]);
        let id = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
        assert_eq!(mul(&id, &m), m);
    }

    #[test]
    fn identical_renders_do_not_differ() {
        let c = Canvas::new(4, 4, SKY).unwrap();
        assert_eq!(image_difference(&c, &c, 1, 0.05), Difference::default());
        let mut d = c.clone();
        d.color[0] = [0.0, 0.0, 0.0, 1.0];
        let one = image_difference(&c, &d, 1, 0.05);
        assert_eq!((one.differing, one.differing_samples), (1.0 / 16.0, 1.0 / 16.0));
        assert!(one.color_rmse > 0.0);
    }

    #[test]
    fn pixels_are_compared_as_the_mean_of_their_samples() {
        // 2 × 2 pixels of 2 × 2 samples: one black sample in pixel 0 moves its mean by a quarter
        // of the sky's colour (over the threshold); a sample a little off in pixel 3 does not count
        let c = Canvas::new(4, 4, SKY).unwrap();
        let mut d = c.clone();
        d.color[0] = [0.0, 0.0, 0.0, 1.0];
        d.color[3 * 4 + 3] = [SKY[0] + 0.08, SKY[1], SKY[2], 1.0];
        let r = image_difference(&c, &d, 2, 0.05);
        assert_eq!(r.differing, 0.25, "pixel 0 only: 0.08 / 4 = 0.02 in pixel 3");
        assert_eq!(r.differing_samples, 2.0 / 16.0);
        let quarter = [SKY[0] / 4.0, SKY[1] / 4.0, SKY[2] / 4.0];
        let want = ((quarter.iter().map(|v| (*v as f64).powi(2)).sum::<f64>() + 0.02f64.powi(2)) / 12.0).sqrt();
        assert!((r.color_rmse - want).abs() < 1e-6, "{} vs {want}", r.color_rmse);
    }
}
