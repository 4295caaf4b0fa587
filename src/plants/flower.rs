//! Flowers as the real-time grass thesis drew them: two crossed vertical billboards, textured with
//! a flower the baker renders from a small procedural 3-D model (a curved stem with two leaves, a
//! head of N elliptical petals around a disc, tilted towards the viewer).

use serde::{Deserialize, Serialize};

use crate::bake::atlas::{dilate, finish_normal_atlas, mip_chain, resolve_supersampled, MipLevel, FLAT_NORMAL};
use crate::bake::image::Image;
use crate::bake::raster::{Camera, OrthoView, RasterError};
use crate::bake::render::{render_mesh, RenderOptions, Shading};
use crate::mesh::{AlphaMode, Material, Mesh, Primitive, Scene, Texture};
use crate::plants::wind;
use crate::random::Stream;

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FlowerSettings {
    pub petals: usize,
    /// Linear RGB.
    pub petal_color: [f32; 3],
    pub center_color: [f32; 3],
    pub stem_color: [f32; 3],
    pub height_m: [f32; 2],
    pub head_m: f32,
    /// Flower variants side by side in the atlas (each a different random flower).
    pub variants: usize,
    pub alpha_cutoff: f32,
    /// Atlas pixels per variant (width; the cell is twice as tall).
    pub atlas_px: u32,
    pub seed: u64,
}

impl Default for FlowerSettings {
    fn default() -> Self {
        FlowerSettings {
            petals: 7,
            petal_color: [0.85, 0.20, 0.35],
            center_color: [0.95, 0.70, 0.05],
            stem_color: [0.06, 0.22, 0.03],
            height_m: [0.2, 0.35],
            head_m: 0.06,
            variants: 4,
            alpha_cutoff: 0.75,
            atlas_px: 128,
            seed: 0,
        }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("flower setting `{key}` {problem}; {remedy}")]
pub struct FlowerError {
    pub key: &'static str,
    pub problem: String,
    pub remedy: String,
}

impl FlowerSettings {
    pub fn check(&self) -> Result<(), FlowerError> {
        let bad = |key, problem: String, remedy: &str| Err(FlowerError { key, problem, remedy: remedy.into() });
        if !(3..=32).contains(&self.petals) {
            return bad("petals", format!("is {}", self.petals), "use 3 to 32");
        }
        let c_ok = |c: [f32; 3]| c.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x));
        if !c_ok(self.petal_color) || !c_ok(self.center_color) || !c_ok(self.stem_color) {
            return bad("petal_color/center_color/stem_color", "has a channel outside 0..1".into(), "give RGB in 0..1");
        }
        let h = self.height_m;
        if !(h[0].is_finite() && h[1].is_finite() && 0.01 <= h[0] && h[0] <= h[1] && h[1] <= 10.0) {
            return bad("height", format!("is {h:?} m"), "give [min, max] with 0.01 ≤ min ≤ max ≤ 10 m");
        }
        if !(self.head_m.is_finite() && self.head_m >= 0.005 && self.head_m <= h[0]) {
            return bad("head", format!("is {} m", self.head_m), "use 0.005 m up to the smallest height");
        }
        if !(1..=16).contains(&self.variants) {
            return bad("variants", format!("is {}", self.variants), "use 1 to 16");
        }
        if !(self.alpha_cutoff.is_finite() && (0.05..=0.95).contains(&self.alpha_cutoff)) {
            return bad("alpha_cutoff", format!("is {}", self.alpha_cutoff), "use 0.05 to 0.95");
        }
        if !(16..=2048).contains(&self.atlas_px) {
            return bad("atlas_px", format!("is {}", self.atlas_px), "use 16 to 2048");
        }
        Ok(())
    }

    fn card_width(&self) -> f32 {
        // the head, tilted petals and leaves fit in 2.2 head diameters
        (2.2 * self.head_m).max(0.35 * self.height_m[1])
    }
}

fn push_tri(p: &mut Primitive, a: [f32; 3], b: [f32; 3], c: [f32; 3], color: [f32; 3]) {
    let base = p.positions.len() as u32;
    let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let n = if l > 0.0 { [n[0] / l, n[1] / l, n[2] / l] } else { [0.0, 0.0, 1.0] };
    for v in [a, b, c] {
        p.positions.push(v);
        p.normals.push(n);
        p.colors.push([color[0], color[1], color[2], 1.0]);
    }
    p.indices.extend_from_slice(&[base, base + 1, base + 2]);
}

/// The 3-D flower of `variant`, facing +z, base at the origin; vertex-coloured.
pub fn flower_model(s: &FlowerSettings, variant: usize) -> (Primitive, f32) {
    let mut r = Stream::new(&[s.seed, 0x0066_6c77, variant as u64]);
    let height = r.range(s.height_m);
    let lean = (r.unit() - 0.5) * 0.3; // stem curve sideways (x)
    let mut p = Primitive { material: Some(0), ..Primitive::default() };
    // stem: a ribbon facing the viewer, 8 segments
    let stem_w = (s.head_m * 0.08).max(0.002);
    let seg = 8;
    let stem_at = |t: f32| [lean * height * t * t, height * t, 0.0];
    for k in 0..seg {
        let (t0, t1) = (k as f32 / seg as f32, (k + 1) as f32 / seg as f32);
        let (a, b) = (stem_at(t0), stem_at(t1));
        let w = stem_w / 2.0;
        push_tri(&mut p, [a[0] - w, a[1], 0.0], [a[0] + w, a[1], 0.0], [b[0] + w, b[1], 0.0], s.stem_color);
        push_tri(&mut p, [a[0] - w, a[1], 0.0], [b[0] + w, b[1], 0.0], [b[0] - w, b[1], 0.0], s.stem_color);
    }
    // two leaves
    for (side, t) in [(-1.0f32, 0.25 + 0.1 * r.unit()), (1.0, 0.4 + 0.1 * r.unit())] {
        let a = stem_at(t);
        let len = height * (0.25 + 0.1 * r.unit());
        let tip = [a[0] + side * len * 0.8, a[1] + len * 0.6, 0.01];
        let mid = [a[0] + side * len * 0.4, a[1] + len * 0.3, 0.01];
        let w = len * 0.18;
        let leaf = [s.stem_color[0] * 1.3, (s.stem_color[1] * 1.4).min(1.0), s.stem_color[2] * 1.2];
        push_tri(&mut p, a, [mid[0], mid[1] - w, 0.01], tip, leaf);
        push_tri(&mut p, a, tip, [mid[0], mid[1] + w, 0.01], leaf);
    }
    // head: petals around a disc, tilted 25° towards +z, jittered colour
    let top = stem_at(1.0);
    let tilt = 25f32.to_radians();
    let head = s.head_m / 2.0;
    let jitter = 0.85 + 0.3 * r.unit();
    let petal: [f32; 3] = std::array::from_fn(|k| (s.petal_color[k] * jitter).min(1.0));
    let place = |x: f32, y: f32, z: f32| {
        // rotate (x, y-in-disc, z) about x by the tilt: the disc's plane is x–y facing +z
        let (st, ct) = tilt.sin_cos();
        [top[0] + x, top[1] + y * ct, top[2] + z + y * st]
    };
    let phase = r.unit() * std::f32::consts::TAU;
    for k in 0..s.petals {
        let a = phase + k as f32 * std::f32::consts::TAU / s.petals as f32;
        let (sa, ca) = a.sin_cos();
        let (px, py) = (-sa, ca); // perpendicular
        let len = head * (0.9 + 0.2 * r.unit());
        let w = len * std::f32::consts::PI / s.petals as f32 * 1.1;
        let base = place(ca * head * 0.25, sa * head * 0.25, 0.002);
        let mid_l = place(ca * len * 0.6 + px * w, sa * len * 0.6 + py * w, 0.002);
        let mid_r = place(ca * len * 0.6 - px * w, sa * len * 0.6 - py * w, 0.002);
        let tip = place(ca * len, sa * len, 0.002);
        push_tri(&mut p, base, mid_r, tip, petal);
        push_tri(&mut p, base, tip, mid_l, petal);
    }
    let disc = head * 0.3;
    for k in 0..12 {
        let a0 = k as f32 * std::f32::consts::TAU / 12.0;
        let a1 = (k + 1) as f32 * std::f32::consts::TAU / 12.0;
        push_tri(
            &mut p,
            place(0.0, 0.0, 0.004),
            place(a0.cos() * disc, a0.sin() * disc, 0.004),
            place(a1.cos() * disc, a1.sin() * disc, 0.004),
            s.center_color,
        );
    }
    (p, height)
}

/// Transparent (then dilated) texels around each variant's atlas cell.
pub const ATLAS_GUTTER_PX: u32 = 4;

/// One variant's place in the atlas, as (u0, v0, u1, v1) with v down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlowerCell {
    /// The cell's inside (within the gutter).
    pub uv: [f32; 4],
    /// What the cards show: the whole card, centred, its bottom on the cell's bottom (the ground).
    pub card_uv: [f32; 4],
}

/// A flower species: crossed billboards per variant, the atlas they show, its mips.
#[derive(Debug, Clone)]
pub struct FlowerAsset {
    pub scene: Scene,
    pub atlas: Vec<MipLevel>,
    /// The atlas' normals (glTF tangent-space normal map), the cards' normalTexture.
    pub normal_atlas: Image,
    /// Each variant's atlas cell and the part of it its cards show.
    pub cells: Vec<FlowerCell>,
    pub report: FlowerReport,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FlowerReport {
    pub name: String,
    pub variants: usize,
    pub triangles_per_flower: usize,
    pub model_triangles: usize,
    pub atlas_coverage: Vec<f64>,
    pub seconds: f64,
}

pub fn build_flower(name: &str, s: &FlowerSettings) -> Result<FlowerAsset, RasterError> {
    let started = std::time::Instant::now();
    let px = s.atlas_px;
    let g = ATLAS_GUTTER_PX;
    // each variant's cell is px × 2px inside a gutter of transparent (then dilated) texels, so
    // filtering and the smaller mips never read a neighbour's flower
    let (cell_w, cell_h) = (px, 2 * px);
    let (atlas_w, atlas_h) = ((cell_w + 2 * g) * s.variants as u32, cell_h + 2 * g);
    let card_w = s.card_width();
    let card_h = s.height_m[1] * 1.1;
    // square pixels; the whole card fits the cell, its bottom edge (the ground) on the cell's
    let ppm = (cell_w as f64 / card_w as f64).min(cell_h as f64 / card_h as f64);
    let (window_w, window_h) = (cell_w as f64 / ppm, cell_h as f64 / ppm);
    let mut atlas = Image { width: atlas_w, height: atlas_h, pixels: vec![[0.0; 4]; (atlas_w * atlas_h) as usize] };
    let mut normal_atlas =
        Image { width: atlas_w, height: atlas_h, pixels: vec![FLAT_NORMAL; (atlas_w * atlas_h) as usize] };
    let materials = [Material { name: "flower_model".into(), double_sided: true, ..Material::default() }];
    let opts = RenderOptions { use_vertex_colors: true, shading: Shading::Unlit, ..RenderOptions::default() };
    let mut model_triangles = 0;
    let mut cells = Vec::with_capacity(s.variants);
    for v in 0..s.variants {
        let (model, _) = flower_model(s, v);
        model_triangles += model.triangle_count();
        // front view of the cell's window, centred on the stem, its bottom row at the ground
        let ss = crate::plants::grass_asset::BAKE_SUPERSAMPLE;
        let view = OrthoView {
            origin: [-window_w / 2.0, window_h, 1.0],
            right: [1.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            forward: [0.0, 0.0, -1.0],
            pixels_per_metre: ppm * ss as f64,
            width: cell_w * ss,
            height: cell_h * ss,
        };
        let cam = Camera::Ortho(view);
        let mut canvas = cam.canvas([0.0; 4])?;
        let mesh = Mesh { name: String::new(), primitives: vec![model], extras: None };
        const IDENTITY: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
        render_mesh(&mut canvas, &cam, &IDENTITY, &mesh, &materials, &[], &opts);
        // resolved from BAKE_SUPERSAMPLE× (anti-aliased alpha, which the coverage-keeping mips need)
        let (x, y) = (v as u32 * (cell_w + 2 * g) + g, g);
        atlas.blit(&resolve_supersampled(&Image::from_canvas(&canvas), ss), x, y);
        // the same view's normals in the card's frame: the lit cards' normal atlas
        let mut canvas = cam.canvas([0.0; 4])?;
        let normal_opts = RenderOptions {
            use_vertex_colors: false,
            shading: Shading::card_normals(&view),
            ..RenderOptions::default()
        };
        render_mesh(&mut canvas, &cam, &IDENTITY, &mesh, &materials, &[], &normal_opts);
        normal_atlas.blit(&resolve_supersampled(&Image::from_canvas(&canvas), ss), x, y);
        // the card's rectangle inside the cell: centred, bottom-aligned
        let (shown_w, shown_h) = (card_w as f64 * ppm, card_h as f64 * ppm);
        let (aw, ah) = (atlas_w as f64, atlas_h as f64);
        let u0 = (x as f64 + (cell_w as f64 - shown_w) / 2.0) / aw;
        let u1 = (x as f64 + (cell_w as f64 + shown_w) / 2.0) / aw;
        let v1 = (y + cell_h) as f64 / ah;
        let v0 = v1 - shown_h / ah;
        cells.push(FlowerCell {
            uv: [
                x as f32 / aw as f32,
                y as f32 / ah as f32,
                (x + cell_w) as f32 / aw as f32,
                (y + cell_h) as f32 / ah as f32,
            ],
            card_uv: [u0 as f32, v0 as f32, u1 as f32, v1 as f32],
        });
    }
    dilate(&mut atlas, s.alpha_cutoff);
    let chain = mip_chain(&atlas, s.alpha_cutoff);
    let png = chain[0].image.encode_png().map_err(|e| RasterError::Encode(e.to_string()))?;
    let normal_atlas = finish_normal_atlas(normal_atlas);
    let normal_png = normal_atlas.encode_png_data().map_err(|e| RasterError::Encode(e.to_string()))?;
    let mut scene = Scene {
        name: name.into(),
        materials: vec![Material {
            name: "flower".into(),
            base_color_texture: Some(0),
            normal_texture: Some(1),
            roughness: 0.8,
            alpha_mode: AlphaMode::Mask { cutoff: s.alpha_cutoff },
            double_sided: true,
            ..Material::default()
        }],
        textures: vec![
            Texture { name: format!("{name}_atlas"), png },
            Texture { name: format!("{name}_atlas_normal"), png: normal_png },
        ],
        ..Scene::default()
    };
    let mut per_flower = 0;
    for (v, cell) in cells.iter().enumerate() {
        let mut prim = crossed_cards(card_w, card_h, cell.card_uv);
        // the stem sways from the ground; each variant with its own phase
        let phase = Stream::new(&[s.seed, 0x77_696e64, v as u64]).unit() * std::f32::consts::TAU;
        prim.custom =
            vec![wind::height_wind(&prim.positions, 0.0, card_h, phase, wind::FLOWER_SWAY_HZ, wind::FLOWER_STIFFNESS)];
        per_flower = prim.triangle_count();
        let node = scene.add_mesh_node(Mesh { name: format!("{name}_v{v}"), primitives: vec![prim], extras: None });
        scene.nodes[node].translation = [v as f32 * card_w * 1.5, 0.0, 0.0];
        scene.nodes[node].extras = Some(serde_json::json!({ "variant": v }));
    }
    let report = FlowerReport {
        name: name.into(),
        variants: s.variants,
        triangles_per_flower: per_flower,
        model_triangles,
        atlas_coverage: chain.iter().map(|m| m.coverage).collect(),
        seconds: started.elapsed().as_secs_f64(),
    };
    Ok(FlowerAsset { scene, atlas: chain, normal_atlas, cells, report })
}

/// Two crossed vertical cards `width` × `height` showing `rect` ([u0, v0, u1, v1], v down).
fn crossed_cards(width: f32, height: f32, rect: [f32; 4]) -> Primitive {
    let mut p = Primitive { material: Some(0), ..Primitive::default() };
    let h = width / 2.0;
    let [u0, v0, u1, v1] = rect;
    for (corners, normal) in [
        ([[-h, 0.0, 0.0], [h, 0.0, 0.0], [h, height, 0.0], [-h, height, 0.0]], [0.0, 0.0, 1.0]),
        ([[0.0, 0.0, h], [0.0, 0.0, -h], [0.0, height, -h], [0.0, height, h]], [1.0, 0.0, 0.0]),
    ] {
        let base = p.positions.len() as u32;
        let uvs: [[f32; 2]; 4] =
            std::array::from_fn(|k| [if k == 1 || k == 2 { u1 } else { u0 }, if k >= 2 { v0 } else { v1 }]);
        let tangent = crate::mesh::quad_tangent(corners, uvs, normal);
        for (c, uv) in corners.iter().zip(uvs) {
            p.positions.push(*c);
            p.normals.push(normal);
            p.uvs.push(uv);
            p.tangents.push(tangent);
        }
        p.indices.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flower_models_are_deterministic_and_fit_their_card() {
        let s = FlowerSettings::default();
        s.check().unwrap();
        let (a, h) = flower_model(&s, 1);
        assert_eq!(a, flower_model(&s, 1).0);
        assert_ne!(a, flower_model(&s, 2).0);
        assert!((s.height_m[0]..=s.height_m[1]).contains(&h));
        let b = a.bounds().unwrap();
        assert!(b.max[0] - b.min[0] <= s.card_width(), "{b:?}");
        assert!(b.max[1] <= s.height_m[1] * 1.1);
        assert_eq!(FlowerSettings { petals: 2, ..s }.check().unwrap_err().key, "petals");
    }
}
