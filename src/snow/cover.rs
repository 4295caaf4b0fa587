//! Snow cover on a terrain: a per-vertex weight = slope factor × altitude factor × exposure factor.
//! Slope: full cover up to `full_slope_deg`, a smoothstep to none at `max_slope_deg` (snow slides
//! off steep rock); altitude: a snow line perturbed by value noise with a smooth transition band;
//! exposure: windward faces are scoured in proportion to n·(−wind) (lee faces keep their snow).

use rayon::prelude::*;
use serde::Serialize;

use crate::bake::image::Image;
use crate::bake::raster::{Camera, OrthoView};
use crate::bake::render::{render_mesh, RenderOptions, Shading};
use crate::color::srgb_to_linear;
use crate::mesh::{CustomAttribute, Material, Mesh, Primitive, Scene};
use crate::random::mix64;
use crate::snow::error::{bad, within, SnowError};

/// Name of the glTF custom attribute: x = weight 0..1, y = snow depth in metres (weight ·
/// `max_depth_m`), z = slope factor, w = altitude factor (exposure = x / (z · w) where defined).
pub const SNOW_ATTRIBUTE: &str = "_SNOW";

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CoverSettings {
    /// Full cover on slopes up to this angle (degrees from horizontal)…
    pub full_slope_deg: f32,
    /// …and none from this angle on.
    pub max_slope_deg: f32,
    /// Mean altitude (m) of the snow line: half cover there.
    pub snow_line_m: f32,
    /// The snow line moves up and down by up to this much (m) with value noise over the terrain.
    pub snow_line_noise_m: f32,
    /// Horizontal wavelength (m) of that noise.
    pub noise_scale_m: f32,
    /// Height (m) over which cover goes from none to full across the snow line.
    pub transition_m: f32,
    /// Direction the wind blows towards (x, z); faces turned into the wind lose snow.
    pub wind_direction: [f32; 2],
    /// 0: no wind effect; 1: a vertical face into the wind is bare.
    pub wind_scour: f32,
    /// Snow depth (m) at weight 1.
    pub max_depth_m: f32,
    pub seed: u64,
}

impl Default for CoverSettings {
    fn default() -> Self {
        CoverSettings {
            full_slope_deg: 25.0,
            max_slope_deg: 50.0,
            snow_line_m: 0.0,
            snow_line_noise_m: 0.0,
            noise_scale_m: 100.0,
            transition_m: 10.0,
            wind_direction: [1.0, 0.0],
            wind_scour: 0.5,
            max_depth_m: 0.3,
            seed: 0,
        }
    }
}

impl CoverSettings {
    pub fn check(&self) -> Result<(), SnowError> {
        if !within(self.full_slope_deg, 0.0, 90.0)
            || !within(self.max_slope_deg, 0.0, 90.0)
            || self.full_slope_deg >= self.max_slope_deg
        {
            return bad(
                "full_slope_deg/max_slope_deg",
                format!("are {}° and {}°", self.full_slope_deg, self.max_slope_deg),
                "give 0 ≤ full_slope_deg < max_slope_deg ≤ 90",
            );
        }
        if !within(self.snow_line_m, -20_000.0, 20_000.0) {
            return bad("snow_line_m", format!("is {} m", self.snow_line_m), "use −20000 to 20000 m");
        }
        if !within(self.snow_line_noise_m, 0.0, 10_000.0) {
            return bad("snow_line_noise_m", format!("is {} m", self.snow_line_noise_m), "use 0 to 10000 m");
        }
        if !within(self.noise_scale_m, 0.01, 1e6) {
            return bad("noise_scale_m", format!("is {} m", self.noise_scale_m), "use 0.01 to 1000000 m");
        }
        if !within(self.transition_m, 0.0, 10_000.0) {
            return bad("transition_m", format!("is {} m", self.transition_m), "use 0 to 10000 m");
        }
        let [wx, wz] = self.wind_direction;
        if !(wx.is_finite() && wz.is_finite() && wx * wx + wz * wz > 1e-12) {
            return bad("wind_direction", format!("is {:?}", self.wind_direction), "give a non-zero [x, z] direction");
        }
        if !within(self.wind_scour, 0.0, 1.0) {
            return bad("wind_scour", format!("is {}", self.wind_scour), "use 0 to 1");
        }
        if !within(self.max_depth_m, 0.0, 100.0) {
            return bad("max_depth_m", format!("is {} m", self.max_depth_m), "use 0 to 100 m");
        }
        Ok(())
    }
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Value noise in [−1, 1] at (x, z): hashed lattice values, smoothly interpolated.
fn value_noise(seed: u64, x: f32, z: f32, scale: f32) -> f32 {
    let (fx, fz) = (x / scale, z / scale);
    let (ix, iz) = (fx.floor(), fz.floor());
    let (tx, tz) = (fx - ix, fz - iz);
    let lattice = |i: f32, j: f32| {
        let h = mix64(seed ^ mix64(((i as i64 as u64) << 32) ^ (j as i64 as u64 & 0xffff_ffff)));
        (h >> 40) as f32 / (1u64 << 23) as f32 - 1.0
    };
    let (sx, sz) = (tx * tx * (3.0 - 2.0 * tx), tz * tz * (3.0 - 2.0 * tz));
    let a = lattice(ix, iz) + sx * (lattice(ix + 1.0, iz) - lattice(ix, iz));
    let b = lattice(ix, iz + 1.0) + sx * (lattice(ix + 1.0, iz + 1.0) - lattice(ix, iz + 1.0));
    a + sz * (b - a)
}

/// (weight, slope factor, altitude factor) of a surface point at `position` with unit `normal`.
/// At a fixed position, the weight never increases with the slope (each factor is non-increasing
/// in it, for any aspect). A normal pointing down (overhang) gets no snow.
pub fn snow_weight(s: &CoverSettings, position: [f32; 3], normal: [f32; 3]) -> [f32; 3] {
    let ny = normal[1].clamp(-1.0, 1.0);
    if ny.is_nan() || ny <= 0.0 {
        return [0.0, 0.0, altitude_factor(s, position)];
    }
    let slope_deg = ny.acos().to_degrees();
    let slope = 1.0 - smoothstep(s.full_slope_deg, s.max_slope_deg, slope_deg);
    let altitude = altitude_factor(s, position);
    // the horizontal part of the normal has length sin(slope): its component into the wind grows
    // with the slope at a fixed aspect, so scouring does too
    let [wx, wz] = s.wind_direction;
    let wl = (wx * wx + wz * wz).sqrt().max(1e-12);
    let into_wind = (-(normal[0] * wx + normal[2] * wz) / wl).max(0.0);
    let exposure = 1.0 - s.wind_scour * into_wind.min(1.0);
    [slope * altitude * exposure, slope, altitude]
}

fn altitude_factor(s: &CoverSettings, p: [f32; 3]) -> f32 {
    let line = s.snow_line_m + s.snow_line_noise_m * value_noise(s.seed ^ 0x736e_6f77, p[0], p[2], s.noise_scale_m);
    if s.transition_m <= 0.0 {
        return if p[1] >= line { 1.0 } else { 0.0 };
    }
    smoothstep(line - s.transition_m / 2.0, line + s.transition_m / 2.0, p[1])
}

/// Area-weighted vertex normals (for primitives written without normals).
fn vertex_normals(p: &Primitive) -> Vec<[f32; 3]> {
    let mut n = vec![[0.0f64; 3]; p.positions.len()];
    for t in 0..p.triangle_count() {
        let c = p.triangle_cross(t);
        for k in 0..3 {
            let v = p.indices[3 * t + k] as usize;
            for a in 0..3 {
                n[v][a] += c[a];
            }
        }
    }
    n.iter()
        .map(|v| {
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if l > 0.0 {
                [(v[0] / l) as f32, (v[1] / l) as f32, (v[2] / l) as f32]
            } else {
                [0.0, 1.0, 0.0]
            }
        })
        .collect()
}

fn check_primitive(mesh: &str, k: usize, p: &Primitive) -> Result<(), SnowError> {
    let n = p.positions.len();
    if p.indices.iter().any(|&i| i as usize >= n) {
        return Err(SnowError::Terrain(format!(
            "mesh {mesh:?} primitive {k} has an index beyond its {n} vertices; re-export the terrain"
        )));
    }
    if !p.normals.is_empty() && p.normals.len() != n {
        return Err(SnowError::Terrain(format!(
            "mesh {mesh:?} primitive {k} has {} normals for {n} vertices; re-export the terrain",
            p.normals.len()
        )));
    }
    if p.positions.iter().flatten().any(|c| !c.is_finite()) {
        return Err(SnowError::Terrain(format!(
            "mesh {mesh:?} primitive {k} has a non-finite position; fix the heightmap"
        )));
    }
    Ok(())
}

/// Adds (or replaces) the [`SNOW_ATTRIBUTE`] of every primitive of `terrain`. Positions are taken as
/// world positions (the terrain stage builds its meshes in world space with identity nodes).
pub fn apply_cover(terrain: &mut Scene, s: &CoverSettings) -> Result<(), SnowError> {
    s.check()?;
    for mesh in &mut terrain.meshes {
        for (k, p) in mesh.primitives.iter_mut().enumerate() {
            check_primitive(&mesh.name, k, p)?;
            let normals = if p.normals.len() == p.positions.len() { p.normals.clone() } else { vertex_normals(p) };
            let values: Vec<[f32; 4]> = p
                .positions
                .par_iter()
                .zip(normals.par_iter())
                .map(|(&q, &n)| {
                    let [w, slope, alt] = snow_weight(s, q, n);
                    [w, w * s.max_depth_m, slope, alt]
                })
                .collect();
            p.custom.retain(|c| c.name != SNOW_ATTRIBUTE);
            p.custom.push(CustomAttribute { name: SNOW_ATTRIBUTE.into(), values, unit_bytes: false, range: None });
        }
    }
    Ok(())
}

/// The snow weight over the terrain's x–z extent, looked at from above: pixel (i, j) covers
/// x = min_x + (i + ½)·metres_per_pixel, z = min_z + (j + ½)·metres_per_pixel (north, −Z, up).
#[derive(Debug, Clone, PartialEq)]
pub struct CoverMask {
    pub width: u32,
    pub height: u32,
    pub min_x: f32,
    pub min_z: f32,
    pub metres_per_pixel: f32,
    /// Row-major weights 0..1; 0 where the terrain does not cover the pixel.
    pub weights: Vec<f32>,
}

impl CoverMask {
    /// Bilinear weight at (x, z), clamped at the edges: what the scatter stage reads to thin grass
    /// and flowers where snow lies deep (e.g. keep a plant with probability 1 − weight).
    pub fn weight_at(&self, x: f32, z: f32) -> f32 {
        if self.weights.is_empty() || !x.is_finite() || !z.is_finite() {
            return 0.0;
        }
        let fx = ((x - self.min_x) / self.metres_per_pixel - 0.5).clamp(0.0, (self.width - 1) as f32);
        let fz = ((z - self.min_z) / self.metres_per_pixel - 0.5).clamp(0.0, (self.height - 1) as f32);
        let (i0, j0) = (fx.floor() as u32, fz.floor() as u32);
        let (i1, j1) = ((i0 + 1).min(self.width - 1), (j0 + 1).min(self.height - 1));
        let (tx, tz) = (fx - i0 as f32, fz - j0 as f32);
        let at = |i: u32, j: u32| self.weights[(j * self.width + i) as usize];
        let a = at(i0, j0) + tx * (at(i1, j0) - at(i0, j0));
        let b = at(i0, j1) + tx * (at(i1, j1) - at(i0, j1));
        a + tz * (b - a)
    }

    /// Fraction of pixels with weight ≥ `threshold`.
    pub fn coverage(&self, threshold: f32) -> f64 {
        if self.weights.is_empty() {
            return 0.0;
        }
        self.weights.iter().filter(|&&w| w >= threshold).count() as f64 / self.weights.len() as f64
    }

    /// The mask as `cover_mask.png` stores it (8-bit, value/255 per pixel) read back over the given
    /// extent: what a later stage uses, so a build from cached snow files thins and draws exactly
    /// like the build that computed them.
    pub fn from_png(bytes: &[u8], min_x: f32, min_z: f32, metres_per_pixel: f32) -> Result<CoverMask, SnowError> {
        let img = image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
            .map_err(|e| SnowError::Terrain(format!("the cover mask PNG does not decode ({e}); rebuild with --force")))?
            .to_rgba8();
        if img.width() == 0 || img.height() == 0 || !(metres_per_pixel.is_finite() && metres_per_pixel > 0.0) {
            return Err(SnowError::Terrain("the cover mask is empty; rebuild with --force".into()));
        }
        Ok(CoverMask {
            width: img.width(),
            height: img.height(),
            min_x,
            min_z,
            metres_per_pixel,
            weights: img.pixels().map(|p| p.0[0] as f32 / 255.0).collect(),
        })
    }

    /// A grey image whose 8-bit PNG value is weight·255 (the colour is pre-linearised so the sRGB
    /// encoding stores the weight itself); alpha 1.
    pub fn to_image(&self) -> Image {
        Image {
            width: self.width,
            height: self.height,
            pixels: self
                .weights
                .iter()
                .map(|&w| {
                    let l = srgb_to_linear(w.clamp(0.0, 1.0));
                    [l, l, l, 1.0]
                })
                .collect(),
        }
    }
}

/// The checked primitive `k` of mesh `mesh`'s `_SNOW` attribute, one value per vertex (what
/// [`apply_cover`] wrote).
fn snow_of<'a>(mesh: &str, k: usize, p: &'a Primitive) -> Result<&'a crate::mesh::CustomAttribute, SnowError> {
    check_primitive(mesh, k, p)?;
    let Some(snow) = p.custom.iter().find(|c| c.name == SNOW_ATTRIBUTE) else {
        return Err(SnowError::Terrain(format!(
            "mesh {mesh:?} primitive {k} has no {SNOW_ATTRIBUTE} attribute; call apply_cover first"
        )));
    };
    if snow.values.len() != p.positions.len() {
        return Err(SnowError::Terrain(format!(
            "mesh {mesh:?} primitive {k} has {} {SNOW_ATTRIBUTE} values for {} vertices; call apply_cover again",
            snow.values.len(),
            p.positions.len()
        )));
    }
    Ok(snow)
}

/// Draws the terrain (after [`apply_cover`]) from above with each vertex coloured by its weight,
/// `size_px` pixels along the longer side of its x–z extent.
pub fn cover_mask(terrain: &Scene, size_px: u32) -> Result<CoverMask, SnowError> {
    if !(1..=8192).contains(&size_px) {
        return bad("mask_px", format!("is {size_px}"), "use 1 to 8192 pixels");
    }
    let mut prims = Vec::new();
    for mesh in &terrain.meshes {
        for (k, p) in mesh.primitives.iter().enumerate() {
            let snow = snow_of(&mesh.name, k, p)?;
            prims.push(Primitive {
                positions: p.positions.clone(),
                colors: snow.values.iter().map(|v| [v[0], v[0], v[0], 1.0]).collect(),
                indices: p.indices.clone(),
                material: Some(0),
                ..Primitive::default()
            });
        }
    }
    let points: Vec<[f32; 3]> = prims.iter().flat_map(|p| p.positions.iter().copied()).collect();
    let Some(b) = crate::mesh::Bounds::of(&points) else {
        return Err(SnowError::Terrain("the terrain scene has no vertices; build the terrain first".into()));
    };
    let view = OrthoView::top_down(
        b.min[0] as f64,
        b.max[0] as f64,
        b.min[2] as f64,
        b.max[2] as f64,
        b.max[1] as f64 + 1.0,
        size_px,
    );
    let cam = Camera::Ortho(view);
    let mut canvas = cam.canvas([0.0; 4]).map_err(|e| SnowError::Bake(e.to_string()))?;
    let materials = [Material { name: "snow_weight".into(), double_sided: true, ..Material::default() }];
    let opts = RenderOptions { use_vertex_colors: true, shading: Shading::Unlit, parallel: true };
    let mesh = Mesh { name: String::new(), primitives: prims, extras: None };
    const IDENTITY: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
    render_mesh(&mut canvas, &cam, &IDENTITY, &mesh, &materials, &[], &opts);
    Ok(CoverMask {
        width: canvas.width,
        height: canvas.height,
        min_x: b.min[0],
        min_z: b.min[2],
        metres_per_pixel: (1.0 / view.pixels_per_metre) as f32,
        weights: canvas.color.iter().map(|c| if c[3] > 0.0 { c[0].clamp(0.0, 1.0) } else { 0.0 }).collect(),
    })
}

/// The snow layer: the terrain's triangles whose three vertices all have weight ≥ `min_weight`,
/// each vertex lifted along its normal by its snow depth; one white, rough material.
pub fn snow_layer(terrain: &Scene, min_weight: f32) -> Result<Scene, SnowError> {
    if !within(min_weight, 0.0, 1.0) {
        return bad("layer_min_weight", format!("is {min_weight}"), "use 0 to 1");
    }
    let mut out = Scene {
        name: format!("{}_snow", terrain.name),
        materials: vec![Material {
            name: "snow".into(),
            base_color: [0.9, 0.92, 0.95, 1.0],
            roughness: 0.9,
            ..Material::default()
        }],
        ..Scene::default()
    };
    for mesh in &terrain.meshes {
        let mut prims = Vec::new();
        for (k, p) in mesh.primitives.iter().enumerate() {
            let snow = snow_of(&mesh.name, k, p)?;
            let normals = if p.normals.len() == p.positions.len() { p.normals.clone() } else { vertex_normals(p) };
            let mut q = Primitive { material: Some(0), ..Primitive::default() };
            let mut remap = vec![u32::MAX; p.positions.len()];
            for tri in p.indices.chunks_exact(3) {
                if tri.iter().any(|&i| snow.values[i as usize][0] < min_weight) {
                    continue;
                }
                for &i in tri {
                    let i = i as usize;
                    if remap[i] == u32::MAX {
                        remap[i] = q.positions.len() as u32;
                        let (v, n, d) = (p.positions[i], normals[i], snow.values[i][1]);
                        q.positions.push([v[0] + n[0] * d, v[1] + n[1] * d, v[2] + n[2] * d]);
                        q.normals.push(n);
                    }
                    q.indices.push(remap[i]);
                }
            }
            if !q.indices.is_empty() {
                prims.push(q);
            }
        }
        if !prims.is_empty() {
            out.add_mesh_node(Mesh { name: format!("{}_snow", mesh.name), primitives: prims, extras: None });
        }
    }
    Ok(out)
}
