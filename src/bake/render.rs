//! Draws a [`Mesh`] with its glTF metallic-roughness materials reduced to what a billboard bake
//! and an image comparison need: base colour × base-colour texture (× vertex colour on request),
//! the glTF alpha modes as alpha tests, back-face culling of single-sided materials, and either no
//! lighting or a Lambert term (Lambert, "Photometria", 1760: diffuse ∝ cos of the light angle).

use crate::bake::image::Image;
use crate::bake::raster::{Camera, Canvas, Cull, DrawOptions, DrawStats, Fragment};
use crate::mesh::{AlphaMode, Material, Mesh, Primitive};

/// Alpha threshold [`AlphaMode::Blend`] is drawn with: without sorting there is no blending, so a
/// blended material is treated as a mask at ½ (the coverage a blend would show most of).
pub const BLEND_AS_MASK_CUTOFF: f32 = 0.5;

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Shading {
    /// Colour as the material gives it (what atlas baking uses: the engine lights the billboard).
    #[default]
    Unlit,
    /// Colour × (ambient + (1 − ambient) · max(0, n·l)), with `light_dir` pointing *towards* the
    /// light in world space (normalised here) and n the interpolated vertex normal (else the
    /// triangle's own) moved to world space. Double-sided materials use |n·l|: a leaf is lit on both
    /// faces. `ambient` is clamped to 0..1.
    Lambert { light_dir: [f32; 3], ambient: f32 },
    /// Instead of a colour, the surface normal in a card's frame (unit `right`, `up`, `toward` the
    /// viewer, world space) as a glTF tangent-space normal-map texel: rgb = n/2 + ½ with +X right,
    /// +Y up, +Z towards the viewer, alpha 1. What a lit billboard needs: an engine lights the card
    /// with these normals as it lights the 3-D levels. Double-sided surfaces show the side that
    /// faces the viewer; the interpolated vertex normal is used (else the triangle's own), and one
    /// leaning away from the viewer (near a silhouette) is laid into the card's plane.
    CardNormals { right: [f32; 3], up: [f32; 3], toward: [f32; 3] },
}

impl Shading {
    /// [`Shading::CardNormals`] for a card seen through `view`: its right, its up, towards the viewer.
    pub fn card_normals(view: &crate::bake::raster::OrthoView) -> Shading {
        let f = |v: [f64; 3]| v.map(|x| x as f32);
        Shading::CardNormals { right: f(view.right), up: f(view.up), toward: f(view.forward.map(|x| -x)) }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// Multiply by COLOR_0 (vertex-coloured models: flowers, snow). Off by default: textured plants
    /// have no COLOR_0, and a bake must not darken by one it does not mean.
    pub use_vertex_colors: bool,
    pub shading: Shading,
    /// Draw each primitive in parallel bands (same output either way; off when the caller already
    /// runs many renders in parallel).
    pub parallel: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions { use_vertex_colors: false, shading: Shading::Unlit, parallel: true }
    }
}

/// Draws every primitive of `mesh` in order into `canvas` as `cam` sees it, the mesh placed in the
/// world by `object_to_world` (3×4: columns x, y, z axes and translation). A primitive's material
/// is `materials[prim.material]` (the glTF default material when absent or out of range), its
/// texture `textures[material.base_color_texture]` (none when out of range), sampled bilinearly
/// with repeat wrapping. Written alpha is 1: Opaque writes every fragment, Mask discards alpha
/// below its cutoff, Blend is drawn as a mask at [`BLEND_AS_MASK_CUTOFF`]. Depth-tested.
pub fn render_mesh(
    canvas: &mut Canvas,
    cam: &Camera,
    object_to_world: &[[f64; 4]; 3],
    mesh: &Mesh,
    materials: &[Material],
    textures: &[Image],
    opts: &RenderOptions,
) -> DrawStats {
    let default_material = Material::default();
    let normal_matrix = cofactor3(object_to_world);
    let mut total = DrawStats::default();
    for prim in &mesh.primitives {
        let (material, texture, draw) = primitive_material(prim, materials, textures, &default_material);
        let lighting = match opts.shading {
            Shading::Unlit => None,
            Shading::Lambert { light_dir, ambient } => {
                // lit as an engine lights it: through the material's normal map where there is one
                let normal_map = material.normal_texture.and_then(|t| textures.get(t));
                Some(Lighting::new(prim, &normal_matrix, light_dir, ambient).with_normal_map(prim, normal_map))
            }
            Shading::CardNormals { .. } => Some(Lighting::new(prim, &normal_matrix, [0.0, 1.0, 0.0], 0.0)),
        };
        let card = match opts.shading {
            Shading::CardNormals { right, up, toward } => Some([right, up, toward]),
            _ => None,
        };
        let shader =
            |f: &Fragment| shade(f, material, texture, opts.use_vertex_colors, lighting.as_ref(), card.as_ref());
        let stats = if opts.parallel {
            canvas.draw_camera_par(cam, object_to_world, prim, &draw, shader)
        } else {
            canvas.draw_camera(cam, object_to_world, prim, &draw, shader)
        };
        total.add(&stats);
    }
    total
}

/// [`render_mesh`] unlit (no vertex colours) into `canvas` and, in the same pass, what
/// [`Shading::card_normals`] of `view` draws into `normals` (the canvas' size, row-major, as
/// cleared by the caller): a fragment the alpha test keeps writes both, so `normals` equals a
/// second, separate render with that shading (test), and each triangle is set up and scanned once
/// instead of twice. Serial (a bake runs its cells in parallel).
pub fn render_unlit_and_card_normals(
    canvas: &mut Canvas,
    cam: &Camera,
    view: &crate::bake::raster::OrthoView,
    mesh: &Mesh,
    materials: &[Material],
    textures: &[Image],
    normals: &mut [[f32; 4]],
) -> DrawStats {
    let Shading::CardNormals { right, up, toward } = Shading::card_normals(view) else {
        unreachable!("card_normals gives CardNormals")
    };
    let axes = [right, up, toward];
    let default_material = Material::default();
    let identity = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
    let normal_matrix = cofactor3(&identity);
    let width = canvas.width as usize;
    let mut total = DrawStats::default();
    for prim in &mesh.primitives {
        let (material, texture, draw) = primitive_material(prim, materials, textures, &default_material);
        let lighting = Lighting::new(prim, &normal_matrix, [0.0, 1.0, 0.0], 0.0);
        let shader = |f: &Fragment| {
            // the same alpha test decides both: the normal is written where the colour is
            let color = shade(f, material, texture, false, None, None)?;
            let normal = shade(f, material, texture, false, Some(&lighting), Some(&axes));
            if let (Some(n), Some(slot)) = (normal, normals.get_mut(f.y as usize * width + f.x as usize)) {
                *slot = n;
            }
            Some(color)
        };
        let stats = canvas.draw_camera(cam, &identity, prim, &draw, shader);
        total.add(&stats);
    }
    total
}

/// A primitive's material (`default` when absent or out of range), its base-colour texture (none
/// when out of range) and how it is drawn (single-sided materials cull back faces).
fn primitive_material<'a>(
    prim: &Primitive,
    materials: &'a [Material],
    textures: &'a [Image],
    default: &'a Material,
) -> (&'a Material, Option<&'a Image>, DrawOptions) {
    let material = prim.material.and_then(|m| materials.get(m)).unwrap_or(default);
    let texture = material.base_color_texture.and_then(|t| textures.get(t));
    let cull = if material.double_sided { Cull::None } else { Cull::Back };
    (material, texture, DrawOptions { cull, ..DrawOptions::default() })
}

/// The colour of one fragment, or None when the alpha test discards it.
#[inline]
fn shade(
    f: &Fragment,
    material: &Material,
    texture: Option<&Image>,
    use_vertex_colors: bool,
    lighting: Option<&Lighting<'_>>,
    card: Option<&[[f32; 3]; 3]>,
) -> Option<[f32; 4]> {
    let mut c = material.base_color;
    if let Some(t) = texture {
        let s = t.sample_bilinear(f.uv);
        c = [c[0] * s[0], c[1] * s[1], c[2] * s[2], c[3] * s[3]];
    }
    if use_vertex_colors {
        c = [c[0] * f.color[0], c[1] * f.color[1], c[2] * f.color[2], c[3] * f.color[3]];
    }
    let cutoff = match material.alpha_mode {
        AlphaMode::Opaque => None,
        AlphaMode::Mask { cutoff } => Some(cutoff),
        AlphaMode::Blend => Some(BLEND_AS_MASK_CUTOFF),
    };
    // A NaN alpha is discarded too.
    if cutoff.is_some_and(|cut| c[3].is_nan() || c[3] < cut) {
        return None;
    }
    if let (Some(light), Some(axes)) = (lighting, card) {
        let n = light.world_normal(f).unwrap_or([axes[2][0] as f64, axes[2][1] as f64, axes[2][2] as f64]);
        let mut t = axes.map(|a| (a[0] as f64 * n[0] + a[1] as f64 * n[1] + a[2] as f64 * n[2]) as f32);
        if t[2] < 0.0 && material.double_sided {
            t = t.map(|x| -x);
        }
        if t[2] < 0.0 {
            // a front face whose interpolated normal leans past the silhouette: seen edge-on
            t[2] = 0.0;
            let len = (t[0] * t[0] + t[1] * t[1]).sqrt();
            t = if len > 1e-6 { [t[0] / len, t[1] / len, 0.0] } else { [0.0, 0.0, 1.0] };
        }
        return Some([t[0] * 0.5 + 0.5, t[1] * 0.5 + 0.5, t[2] * 0.5 + 0.5, 1.0]);
    }
    if let Some(light) = lighting {
        let k = light.factor(f, material.double_sided);
        c = [c[0] * k, c[1] * k, c[2] * k, c[3]];
    }
    Some([c[0], c[1], c[2], 1.0])
}

/// What the Lambert term needs, prepared once per primitive.
struct Lighting<'a> {
    /// Object → world for normals: the cofactor matrix of the linear part (the inverse transpose
    /// up to a positive scale, which the normalisation removes; defined for singular matrices too).
    normal_matrix: [[f64; 3]; 3],
    light: [f64; 3],
    ambient: f32,
    /// Per-triangle object-space normals when the primitive has no vertex normals.
    face_normals: Option<Vec<[f32; 3]>>,
    /// A tangent-space normal map with the primitive's vertex normals, tangents (xyz, w the
    /// bitangent's sign) and indices (glTF normalTexture on TEXCOORD_0).
    normal_map: Option<NormalMap<'a>>,
}

struct NormalMap<'a> {
    image: &'a Image,
    normals: &'a [[f32; 3]],
    tangents: &'a [[f32; 4]],
    indices: &'a [u32],
}

impl<'a> Lighting<'a> {
    /// Lights through `image` (a glTF tangent-space normal map) when the primitive has vertex
    /// normals and tangents for every vertex; unchanged otherwise.
    fn with_normal_map(mut self, prim: &'a Primitive, image: Option<&'a Image>) -> Lighting<'a> {
        let n = prim.positions.len();
        if let Some(image) = image {
            if prim.normals.len() == n && prim.tangents.len() == n {
                self.normal_map =
                    Some(NormalMap { image, normals: &prim.normals, tangents: &prim.tangents, indices: &prim.indices });
            }
        }
        self
    }

    /// The normal-mapped object-space normal at `f`, when a normal map applies.
    fn mapped_normal(&self, f: &Fragment) -> Option<[f32; 3]> {
        let m = self.normal_map.as_ref()?;
        let t = f.triangle as usize;
        let idx = m.indices.get(3 * t..3 * t + 3)?;
        let (mut n, mut tg, mut w) = ([0.0f32; 3], [0.0f32; 3], 0.0f32);
        for (k, &i) in idx.iter().enumerate() {
            let (vn, vt) = (m.normals.get(i as usize)?, m.tangents.get(i as usize)?);
            let b = f.bary[k];
            for a in 0..3 {
                n[a] += b * vn[a];
                tg[a] += b * vt[a];
            }
            w += b * vt[3];
        }
        let s = m.image.sample_bilinear(f.uv);
        let (x, y, z) = (2.0 * s[0] - 1.0, 2.0 * s[1] - 1.0, 2.0 * s[2] - 1.0);
        let sign = if w < 0.0 { -1.0 } else { 1.0 };
        let bt = [
            sign * (n[1] * tg[2] - n[2] * tg[1]),
            sign * (n[2] * tg[0] - n[0] * tg[2]),
            sign * (n[0] * tg[1] - n[1] * tg[0]),
        ];
        Some([0, 1, 2].map(|a| x * tg[a] + y * bt[a] + z * n[a]))
    }

    fn new(prim: &Primitive, normal_matrix: &[[f64; 3]; 3], light_dir: [f32; 3], ambient: f32) -> Lighting<'a> {
        let l = light_dir.map(|v| v as f64);
        let len = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
        // A zero or broken light direction lights from straight above.
        let light = if len > 0.0 && len.is_finite() { l.map(|v| v / len) } else { [0.0, 1.0, 0.0] };
        let face_normals = (prim.normals.len() != prim.positions.len()).then(|| {
            (0..prim.triangle_count())
                .map(|t| {
                    let ok = prim.indices[3 * t..3 * t + 3].iter().all(|&i| (i as usize) < prim.positions.len());
                    if ok {
                        prim.triangle_cross(t).map(|v| v as f32)
                    } else {
                        [0.0; 3]
                    }
                })
                .collect()
        });
        let ambient = if ambient.is_nan() { 0.0 } else { ambient.clamp(0.0, 1.0) };
        Lighting { normal_matrix: *normal_matrix, light, ambient, face_normals, normal_map: None }
    }

    /// The fragment's unit world-space normal, None when it has no usable one.
    fn world_normal(&self, f: &Fragment) -> Option<[f64; 3]> {
        let n = match (&self.face_normals, self.mapped_normal(f)) {
            (_, Some(mapped)) => mapped,
            (Some(faces), None) => faces.get(f.triangle as usize).copied().unwrap_or([0.0; 3]),
            (None, None) => f.normal,
        };
        let m = &self.normal_matrix;
        let nw = [0, 1, 2].map(|r| m[r][0] * n[0] as f64 + m[r][1] * n[1] as f64 + m[r][2] * n[2] as f64);
        let len = (nw[0] * nw[0] + nw[1] * nw[1] + nw[2] * nw[2]).sqrt();
        (len > 0.0 && len.is_finite()).then(|| nw.map(|v| v / len))
    }

    fn factor(&self, f: &Fragment, double_sided: bool) -> f32 {
        let cos = match self.world_normal(f) {
            Some(nw) => nw[0] * self.light[0] + nw[1] * self.light[1] + nw[2] * self.light[2],
            // No usable normal: light it fully rather than paint it black.
            None => 1.0,
        };
        let diffuse = if double_sided { cos.abs() } else { cos.max(0.0) } as f32;
        self.ambient + (1.0 - self.ambient) * diffuse
    }
}

/// Cofactor matrix of the 3×3 linear part of a 3×4 affine matrix.
fn cofactor3(m: &[[f64; 4]; 3]) -> [[f64; 3]; 3] {
    let a = |r: usize, c: usize| m[r][c];
    let mut out = [[0.0; 3]; 3];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
            let (c1, c2) = ((c + 1) % 3, (c + 2) % 3);
            *v = a(r1, c1) * a(r2, c2) - a(r1, c2) * a(r2, c1);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::raster::OrthoView;

    const IDENTITY: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];

    /// Looking down −Z at x, y ∈ [0, 4]: one pixel per metre, x right, y up.
    fn front_view() -> Camera {
        Camera::Ortho(OrthoView {
            origin: [0.0, 4.0, 10.0],
            right: [1.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            forward: [0.0, 0.0, -1.0],
            pixels_per_metre: 1.0,
            width: 4,
            height: 4,
        })
    }

    fn quad(normal_z: f32) -> Primitive {
        Primitive {
            positions: vec![[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [4.0, 4.0, 0.0], [0.0, 4.0, 0.0]],
            normals: vec![[0.0, 0.0, normal_z]; 4],
            uvs: vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]],
            indices: vec![0, 1, 2, 0, 2, 3],
            material: Some(0),
            ..Primitive::default()
        }
    }

    #[test]
    fn one_pass_gives_the_colour_and_the_card_normals_two_renders_give() {
        // two overlapping alpha-masked quads (one tilted, one facing away and double-sided) on a
        // 32 x 32 view, a texture with holes: colour, normals and stats as the separate passes
        let view = OrthoView {
            origin: [-0.5, 4.5, 10.0],
            right: [1.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            forward: [0.0, 0.0, -1.0],
            pixels_per_metre: 6.4,
            width: 32,
            height: 32,
        };
        let cam = Camera::Ortho(view);
        let mut tilted = quad(1.0);
        tilted.normals = vec![[0.3, 0.2, 0.9], [0.0, 0.1, 1.0], [-0.4, 0.0, 0.8], [0.1, -0.3, 0.9]];
        let mut behind = quad(-1.0);
        behind.positions.iter_mut().for_each(|p| *p = [p[0] * 0.7 + 0.9, p[1] * 0.8 + 0.5, -0.5]);
        behind.material = Some(1);
        let pixels: Vec<[f32; 4]> =
            (0..64).map(|i| [(i % 8) as f32 / 8.0, 0.5, 0.2, if (i * 7) % 5 < 2 { 0.1 } else { 1.0 }]).collect();
        let texture = Image { width: 8, height: 8, pixels };
        let masked = Material {
            alpha_mode: AlphaMode::Mask { cutoff: 0.5 },
            base_color_texture: Some(0),
            ..Material::default()
        };
        let materials = [masked.clone(), Material { double_sided: true, ..masked }];
        let mesh = Mesh { primitives: vec![behind, tilted], ..Mesh::default() };
        let serial = |shading| RenderOptions { shading, parallel: false, ..RenderOptions::default() };
        let textures = [texture];
        let mut color = cam.canvas([0.0; 4]).unwrap();
        let stats = render_mesh(&mut color, &cam, &IDENTITY, &mesh, &materials, &textures, &serial(Shading::Unlit));
        let mut normal = cam.canvas([0.0; 4]).unwrap();
        let card = serial(Shading::card_normals(&view));
        render_mesh(&mut normal, &cam, &IDENTITY, &mesh, &materials, &textures, &card);
        let mut both = cam.canvas([0.0; 4]).unwrap();
        let mut normals = vec![[0.0f32; 4]; both.color.len()];
        let one = render_unlit_and_card_normals(&mut both, &cam, &view, &mesh, &materials, &textures, &mut normals);
        let bits = |c: &[[f32; 4]]| c.iter().flat_map(|p| p.map(f32::to_bits)).collect::<Vec<u32>>();
        assert_eq!(bits(&both.color), bits(&color.color));
        assert_eq!(bits(&normals), bits(&normal.color));
        assert_eq!(one, stats);
        // the mask left holes and both quads show: the test is not trivially passed
        let covered = color.color.iter().filter(|c| c[3] > 0.0).count();
        assert!(stats.fragments > 0 && covered > 100 && covered < 32 * 32, "{covered}");
    }

    #[test]
    fn cofactor_of_a_scale_is_the_inverse_transpose_up_to_scale() {
        let m = [[2.0, 0.0, 0.0, 5.0], [0.0, 3.0, 0.0, 0.0], [0.0, 0.0, 4.0, 0.0]];
        assert_eq!(cofactor3(&m), [[12.0, 0.0, 0.0], [0.0, 8.0, 0.0], [0.0, 0.0, 6.0]]);
    }

    #[test]
    fn card_normals_are_tangent_space_texels_facing_the_viewer() {
        // the card frame of front_view: right +X, up +Y, toward the viewer +Z
        let opts = RenderOptions {
            shading: Shading::CardNormals { right: [1.0, 0.0, 0.0], up: [0.0, 1.0, 0.0], toward: [0.0, 0.0, 1.0] },
            ..RenderOptions::default()
        };
        let texel = |normal: [f32; 3], double_sided: bool| {
            let mut q = quad(1.0);
            q.normals = vec![normal; 4];
            let mut c = front_view().canvas([0.0; 4]).unwrap();
            let mat = Material { base_color: [0.2, 0.9, 0.1, 1.0], double_sided, ..Material::default() };
            render_mesh(
                &mut c,
                &front_view(),
                &IDENTITY,
                &Mesh { primitives: vec![q], ..Mesh::default() },
                &[mat],
                &[],
                &opts,
            );
            c.color[5]
        };
        let close = |a: [f32; 4], b: [f32; 4]| a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-5);
        // tilted up: green (the image's up) above ½, the colour ignored
        assert!(close(texel([0.0, 0.6, 0.8], false), [0.5, 0.8, 0.9, 1.0]), "{:?}", texel([0.0, 0.6, 0.8], false));
        // tilted right: red above ½
        assert!(close(texel([0.6, 0.0, 0.8], false), [0.8, 0.5, 0.9, 1.0]));
        // a double-sided leaf turned away shows its other side, facing the viewer
        assert!(close(texel([0.0, 0.6, -0.8], true), [0.5, 0.2, 0.9, 1.0]));
        // unnormalised normals come out unit length
        assert!(close(texel([0.0, 0.0, 3.0], false), [0.5, 0.5, 1.0, 1.0]));
    }

    #[test]
    fn lambert_lights_through_the_normal_map() {
        // a quad facing +Z, tangent +X; the map turns every normal to +X; the light comes from +X
        let opts = RenderOptions {
            shading: Shading::Lambert { light_dir: [1.0, 0.0, 0.0], ambient: 0.25 },
            ..RenderOptions::default()
        };
        let mut prim = quad(1.0);
        prim.tangents = vec![[1.0, 0.0, 0.0, 1.0]; 4];
        let mesh = Mesh { primitives: vec![prim], ..Mesh::default() };
        let map = Image::new(2, 2, [1.0, 0.5, 0.5, 1.0]).unwrap();
        let with = Material { normal_texture: Some(0), ..Material::default() };
        let mut c = front_view().canvas([0.0; 4]).unwrap();
        render_mesh(&mut c, &front_view(), &IDENTITY, &mesh, &[with], &[map], &opts);
        assert!((c.color[5][0] - 1.0).abs() < 1e-5, "lit through the map: {:?}", c.color[5]);
        // without the map the same light grazes the quad: ambient only
        let mut c = front_view().canvas([0.0; 4]).unwrap();
        render_mesh(&mut c, &front_view(), &IDENTITY, &mesh, &[Material::default()], &[], &opts);
        assert!((c.color[5][0] - 0.25).abs() < 1e-5, "{:?}", c.color[5]);
    }

    #[test]
    fn lambert_lights_by_the_angle_and_both_sides_when_double_sided() {
        let light = Shading::Lambert { light_dir: [0.0, 0.6, 0.8], ambient: 0.25 };
        let opts = RenderOptions { shading: light, ..RenderOptions::default() };
        let mesh = Mesh { primitives: vec![quad(1.0)], ..Mesh::default() };
        let mat = |double_sided| Material { base_color: [0.5, 1.0, 1.0, 1.0], double_sided, ..Material::default() };
        let mut c = front_view().canvas([0.0; 4]).unwrap();
        render_mesh(&mut c, &front_view(), &IDENTITY, &mesh, &[mat(false)], &[], &opts);
        let lit = 0.25 + 0.75 * 0.8;
        assert!((c.color[5][0] - 0.5 * lit).abs() < 1e-6 && (c.color[5][1] - lit).abs() < 1e-6);
        // the normal turned away: single-sided gets only ambient, double-sided |n·l|
        let away = Mesh { primitives: vec![quad(-1.0)], ..Mesh::default() };
        let mut c = front_view().canvas([0.0; 4]).unwrap();
        render_mesh(&mut c, &front_view(), &IDENTITY, &away, &[mat(false)], &[], &opts);
        assert!((c.color[5][1] - 0.25).abs() < 1e-6);
        let mut c = front_view().canvas([0.0; 4]).unwrap();
        render_mesh(&mut c, &front_view(), &IDENTITY, &away, &[mat(true)], &[], &opts);
        assert!((c.color[5][1] - lit).abs() < 1e-6);
        // no vertex normals: the face normal (+Z for this winding) is used
        let mut flat = quad(1.0);
        flat.normals.clear();
        let mut c = front_view().canvas([0.0; 4]).unwrap();
        render_mesh(
            &mut c,
            &front_view(),
            &IDENTITY,
            &Mesh { primitives: vec![flat], ..Mesh::default() },
            &[mat(false)],
            &[],
            &opts,
        );
        assert!((c.color[5][1] - lit).abs() < 1e-6);
    }

    #[test]
    fn single_sided_back_faces_are_culled_and_vertex_colours_are_opt_in() {
        let mut back = quad(1.0);
        back.indices = vec![0, 2, 1, 0, 3, 2];
        back.colors = vec![[0.5, 0.5, 0.5, 1.0]; 4];
        let mesh = Mesh { primitives: vec![back], ..Mesh::default() };
        let one_side = Material::default();
        let mut c = front_view().canvas([0.0; 4]).unwrap();
        let s = render_mesh(
            &mut c,
            &front_view(),
            &IDENTITY,
            &mesh,
            std::slice::from_ref(&one_side),
            &[],
            &RenderOptions::default(),
        );
        assert_eq!((s.triangles, s.culled, s.fragments), (0, 2, 0));
        let two = Material { double_sided: true, ..one_side };
        let mut c = front_view().canvas([0.0; 4]).unwrap();
        render_mesh(
            &mut c,
            &front_view(),
            &IDENTITY,
            &mesh,
            std::slice::from_ref(&two),
            &[],
            &RenderOptions::default(),
        );
        assert!(c.color.iter().all(|p| *p == [1.0; 4]));
        let vc = RenderOptions { use_vertex_colors: true, ..RenderOptions::default() };
        render_mesh(
            &mut c,
            &front_view(),
            &[[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.0]],
            &mesh,
            &[two],
            &[],
            &vc,
        );
        assert!(c.color.iter().all(|p| *p == [0.5, 0.5, 0.5, 1.0]));
    }
}
