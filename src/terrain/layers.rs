//! Terrain material layers from rules, and the base-colour texture baked from them.
//!
//! Each texel of a map covering the terrain gets four layer weights from the surface there (the
//! terrain walk-through thesis' surface attributes): grass on gentle ground, scree on moderate
//! slopes, rock on steep ones, snow where the [`SnowRule`] puts it: above a fixed snowline unless
//! too steep to hold it, or, in a scene with `[snow]`, exactly the snow stage's cover (the weight
//! [`crate::snow::snow_weight`] gives the surface: snow line with its noise, slope, wind). In a
//! scene with species, a fifth layer, soil, takes the gentle ground the vegetation leaves bare (or,
//! without grass species, the forest floor under trees: [`VegetationCover::soil_share`]). The
//! weights are written as RGBA weight maps, four layers an image (R grass, G scree, B rock, A snow;
//! then R soil; the splat/alpha-map layout Unity terrain and Unreal landscape layers import), and
//! blended with each layer's albedo into a base-colour texture (no lighting baked in) that
//! terrain.glb's material samples through its planar UVs, so every viewer shows the terrain
//! coloured. With a vegetation cover every vertex also carries `_SURFACE`: the thesis' TEXTURE,
//! TYPE, DENSITY and SIZE. The analyzer is the coverage: the share of the map each layer covers.

use serde::{Deserialize, Serialize};

use crate::bake::raster::png::{encode_rgba8_png, rgba8};
use crate::heightfield::{Heightfield, MapRows};
use crate::mesh::{Primitive, Scene, Texture};
use crate::snow::CoverSettings;
use crate::terrain::vegetation::VegetationCover;

/// The layers, in weight-map channel order (terrain_layers.png's R, G, B, A, then
/// terrain_layers_1.png's R). Soil is baked only with a vegetation cover.
pub const LAYER_NAMES: [&str; 5] = ["grass", "scree", "rock", "snow", "soil"];

/// Each layer's albedo, linear RGB (sRGB (84, 112, 46), (128, 112, 88), (112, 108, 102), (236, 240, 246),
/// (96, 74, 50)).
pub const LAYER_ALBEDO: [[f32; 3]; 5] = [
    [0.0887, 0.162, 0.0273],
    [0.216, 0.162, 0.0976],
    [0.162, 0.150, 0.133],
    [0.838, 0.871, 0.922],
    [0.117, 0.0685, 0.0319],
];

/// Layers per weight map (RGBA).
pub const LAYERS_PER_MAP: usize = 4;

/// Slopes (degrees) where scree starts and is full, then rock starts and is full.
pub const SCREE_SLOPE_DEG: [f64; 2] = [18.0, 30.0];
pub const ROCK_SLOPE_DEG: [f64; 2] = [32.0, 45.0];
/// Snow lies above this height (metres), fading in over [`SNOW_FADE_M`] above it, on slopes below
/// 40° (gone at 55°).
pub const SNOWLINE_M: f64 = 2500.0;
pub const SNOW_FADE_M: f64 = 300.0;
pub const SNOW_SLOPE_DEG: [f64; 2] = [40.0, 55.0];

/// The per-vertex layer weights on every terrain primitive (VEC4 normalized unsigned bytes: grass,
/// scree, rock, snow, the weight map's channels, summing to 255/255), for engines that blend
/// layers by vertex.
pub const LAYER_WEIGHTS_ATTRIBUTE: &str = "_LAYER_WEIGHTS";

/// The fifth layer's per-vertex weight (VEC4 normalized unsigned bytes: soil, 0, 0, 0; the bytes of
/// both attributes sum to 255/255), written with a vegetation cover.
pub const LAYER_WEIGHTS_1_ATTRIBUTE: &str = "_LAYER_WEIGHTS_1";

/// The terrain walk-through thesis' surface attributes per vertex (VEC4 float), written with a
/// vegetation cover: TEXTURE (index in [`LAYER_NAMES`] of the layer with the largest weight), TYPE
/// (1-based preset index of the species covering the most ground, 0 where nothing grows), DENSITY
/// (that species' instances per m²), SIZE (its plant height in metres).
pub const SURFACE_ATTRIBUTE: &str = "_SURFACE";

/// Texels weighed at a time while baking (whole rows; 5 MiB of f64 weights).
const BAKE_BAND_TEXELS: u32 = 1 << 17;

/// Longest side of the baked maps, in texels.
pub const MAX_LAYER_MAP_PX: u32 = 2048;

fn smoothstep(edge: [f64; 2], x: f64) -> f64 {
    let t = ((x - edge[0]) / (edge[1] - edge[0])).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Where the snow layer lies.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum SnowRule {
    /// Above [`SNOWLINE_M`], fading in over [`SNOW_FADE_M`], on slopes under [`SNOW_SLOPE_DEG`]
    /// (a terrain built alone, or a scene without `[snow]`).
    #[default]
    Snowline,
    /// The scene's snow cover (its preset's `[snow]`): the weight the snow stage puts on each vertex
    /// as `_SNOW`, from the same settings, so the base colour shows the snow the mask and the
    /// thinned plants follow.
    Cover(CoverSettings),
}

impl SnowRule {
    /// The snow weight (0–1) of the surface at world `position` with unit `normal`.
    pub fn weight(&self, position: [f64; 3], normal: [f64; 3]) -> f64 {
        match self {
            SnowRule::Snowline => {
                let slope_deg = normal[1].clamp(-1.0, 1.0).acos().to_degrees();
                smoothstep([SNOWLINE_M, SNOWLINE_M + SNOW_FADE_M], position[1])
                    * (1.0 - smoothstep(SNOW_SLOPE_DEG, slope_deg))
            }
            SnowRule::Cover(c) => {
                let w = crate::snow::snow_weight(c, position.map(|v| v as f32), normal.map(|v| v as f32))[0];
                (w as f64).clamp(0.0, 1.0)
            }
        }
    }

    /// How the report names the rule.
    pub fn label(&self) -> &'static str {
        match self {
            SnowRule::Snowline => "snowline",
            SnowRule::Cover(_) => "snow cover",
        }
    }
}

/// The four layer weights (summing to 1) of ground with this slope and height under the fixed
/// snowline ([`SnowRule::Snowline`]).
pub fn layer_weights(slope_deg: f64, height_m: f64) -> [f64; 4] {
    let snow_cover =
        smoothstep([SNOWLINE_M, SNOWLINE_M + SNOW_FADE_M], height_m) * (1.0 - smoothstep(SNOW_SLOPE_DEG, slope_deg));
    weights_with_snow(slope_deg, snow_cover)
}

/// The four layer weights (summing to 1) of ground with this slope under this much snow (0–1):
/// the snow takes its share, the rest is grass, scree and rock by slope.
pub fn weights_with_snow(slope_deg: f64, snow_cover: f64) -> [f64; 4] {
    let snow_cover = snow_cover.clamp(0.0, 1.0);
    let rock = smoothstep(ROCK_SLOPE_DEG, slope_deg);
    let scree = smoothstep(SCREE_SLOPE_DEG, slope_deg) * (1.0 - rock);
    let rest = 1.0 - snow_cover;
    let (rock, scree) = (rock * rest, scree * rest);
    let grass = (1.0 - rock - scree - snow_cover).max(0.0);
    [grass, scree, rock, snow_cover]
}

/// Texels along an axis of `samples` heightmap samples: the power of two nearest the number of
/// sample spacings (about a texel per cell; the larger when within 3/4 of it), from 2 to
/// [`MAX_LAYER_MAP_PX`].
pub fn map_px(samples: usize) -> u32 {
    let spans = samples.saturating_sub(1).clamp(2, 1 << 20) as u32;
    let above = spans.next_power_of_two();
    let nearest = if 4 * spans >= 3 * above { above } else { above / 2 };
    nearest.clamp(2, MAX_LAYER_MAP_PX)
}

/// What the layers cover, for the report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LayerReport {
    /// Weight map and base-colour texture size (width, height) in texels.
    pub map_px: [u32; 2],
    /// Layer names in weight-map channel order.
    pub layers: Vec<String>,
    /// Mean weight of each layer over the map (sums to 1).
    pub coverage: Vec<f64>,
    /// The fixed snowline (used when `snow` is "snowline").
    pub snowline_m: f64,
    /// Where the snow layer comes from: "snowline" or "snow cover" (the scene's `[snow]`).
    #[serde(default = "default_snow_source")]
    pub snow: String,
}

fn default_snow_source() -> String {
    SnowRule::Snowline.label().into()
}

/// The baked layers of one heightfield.
#[derive(Debug, Clone)]
pub struct TerrainLayers {
    /// RGBA8 weights per texel of each weight map (layers `4k … 4k + 3` in map k; one map without
    /// a vegetation cover, two with its soil layer), row 0 at the map's top (v = 0), as written.
    pub weights: Vec<Vec<[u8; 4]>>,
    /// The base colour the weights blend to, as sRGB-encoded 8-bit RGBA (what its PNG holds;
    /// [`crate::bake::raster::png::rgba8`] of the linear colour), `report.map_px` in size.
    pub albedo_rgba8: Vec<u8>,
    pub report: LayerReport,
    /// Where the snow layer lies (the per-vertex weights follow the same rule).
    pub snow: SnowRule,
    /// What grows where (the soil layer and `_SURFACE`); `None` for a terrain built alone.
    pub cover: Option<std::sync::Arc<VegetationCover>>,
    /// `albedo_rgba8` as PNG, encoded on first use (every LoD scene shares it).
    albedo_png: std::sync::OnceLock<Result<Vec<u8>, String>>,
}

/// The layer weights of the surface at continuous sample coordinates (s, t) of the map `field`:
/// bilinear height and normal (see [`Heightfield::normal_bilinear`]), the slope from that normal,
/// the snow from `snow`, the soil share of the gentle ground from `soil` (given the position).
fn weights_at(field: &MapRows, snow: &SnowRule, s: f64, t: f64, soil: impl Fn([f64; 3]) -> f64) -> [f64; 5] {
    let height = field.height_bilinear(s, t);
    let normal = field.normal_bilinear(s, t);
    let slope_deg = normal[1].clamp(-1.0, 1.0).acos().to_degrees();
    let cell = field.hf.cell_size_m;
    let position = [s * cell, height, t * cell];
    let [grass, scree, rock, snow] = weights_with_snow(slope_deg, snow.weight(position, normal));
    let soil = grass * soil(position).clamp(0.0, 1.0);
    [grass - soil, scree, rock, snow, soil]
}

/// Sets [`LAYER_WEIGHTS_ATTRIBUTE`] on every primitive of `scene` and, with a vegetation cover,
/// [`LAYER_WEIGHTS_1_ATTRIBUTE`] and [`SURFACE_ATTRIBUTE`] (see [`TerrainLayers::texture`]).
fn vertex_weights(scene: &mut Scene, hf: &Heightfield, snow: &SnowRule, cover: Option<&VegetationCover>) {
    let field = MapRows::whole(hf);
    for p in scene.meshes.iter_mut().flat_map(|m| m.primitives.iter_mut()) {
        weigh_vertices(p, &field, snow, cover);
    }
}

/// The sample rows [`weigh_vertices`] reads for a vertex at row coordinate `t` (z / cell) of
/// `field`'s map: those its bilinear normal reads (the rows around `t`, each with its neighbours).
pub fn weighing_reach(field: &MapRows, t: f64) -> std::ops::RangeInclusive<usize> {
    let ((_, j0), (_, j1), _) = field.bilinear_cell(0.0, t);
    *field.normal_reach(j0).start()..=*field.normal_reach(j1).end()
}

/// Sets [`LAYER_WEIGHTS_ATTRIBUTE`] on primitive `p` of a terrain on `field`'s map and, with a
/// vegetation cover, [`LAYER_WEIGHTS_1_ATTRIBUTE`] and [`SURFACE_ATTRIBUTE`]: each vertex weighed
/// from the surface under it (x, z → sample x / cell, z / cell). `field` must hold the rows
/// [`weighing_reach`] gives for the vertices' rows, and `cover` the texel rows around them (a
/// cover of some rows weighs 0 where it holds none: see [`VegetationCover::holds_point`]).
pub fn weigh_vertices(p: &mut Primitive, field: &MapRows, snow: &SnowRule, cover: Option<&VegetationCover>) {
    use crate::mesh::CustomAttribute;
    use rayon::prelude::*;
    let cell = field.hf.cell_size_m;
    let per_vertex: Vec<([f32; 4], [f32; 4], [f32; 4])> = p
        .positions
        .par_iter()
        .map(|q| {
            let soil = |p: [f64; 3]| cover.map_or(0.0, |c| c.soil_share(p[0], p[2]));
            let w = weights_at(field, snow, q[0] as f64 / cell, q[2] as f64 / cell, soil);
            let bytes = unit_byte_weights(w).map(|k| k as f32 / 255.0);
            let texture = (0..w.len()).fold(0, |best, k| if w[k] > w[best] { k } else { best });
            let surface = cover.map_or([0.0; 4], |c| {
                let at = c.at(q[0] as f64, q[2] as f64);
                [texture as f32, at.dominant as f32, at.density as f32, at.height_m as f32]
            });
            ([bytes[0], bytes[1], bytes[2], bytes[3]], [bytes[4], 0.0, 0.0, 0.0], surface)
        })
        .collect();
    let names = [LAYER_WEIGHTS_ATTRIBUTE, LAYER_WEIGHTS_1_ATTRIBUTE, SURFACE_ATTRIBUTE];
    p.custom.retain(|c| !names.contains(&c.name.as_str()));
    let values = per_vertex.iter().map(|v| v.0).collect();
    p.custom.push(CustomAttribute { name: LAYER_WEIGHTS_ATTRIBUTE.into(), values, unit_bytes: true, range: None });
    if cover.is_some() {
        let values = per_vertex.iter().map(|v| v.1).collect();
        p.custom.push(CustomAttribute {
            name: LAYER_WEIGHTS_1_ATTRIBUTE.into(),
            values,
            unit_bytes: true,
            range: None,
        });
        let values = per_vertex.iter().map(|v| v.2).collect();
        p.custom.push(CustomAttribute { name: SURFACE_ATTRIBUTE.into(), values, unit_bytes: false, range: None });
    }
}

/// Weights summing to 1 as bytes summing to exactly 255: each rounded down, the bytes left over
/// given to the largest remainders (ties to the earlier layer).
fn unit_byte_weights<const N: usize>(w: [f64; N]) -> [u8; N] {
    let scaled = w.map(|v| v.clamp(0.0, 1.0) * 255.0);
    let mut k = scaled.map(|v| v.floor() as u32);
    let mut order: [usize; N] = std::array::from_fn(|i| i);
    order.sort_by(|&a, &b| (scaled[b] - scaled[b].floor()).total_cmp(&(scaled[a] - scaled[a].floor())).then(a.cmp(&b)));
    let left = 255u32.saturating_sub(k.iter().sum());
    for &i in order.iter().take(left as usize) {
        k[i] += 1;
    }
    k.map(|v| v.min(255) as u8)
}

/// Bakes the weight map and the base colour over the whole heightfield (at least 2 × 2 samples).
/// Texel (x, y) is sampled at its centre, uv ((x + ½)/W, (y + ½)/H), which the planar terrain UVs
/// map to sample coordinates (u·(w − 1), v·(h − 1)). `snow` says where the snow layer lies.
pub fn bake_layers(hf: &Heightfield, snow: &SnowRule) -> TerrainLayers {
    bake_layers_with(hf, snow, None)
}

/// [`bake_layers`] with what grows on the terrain: the soil layer (a second weight map) and
/// `_SURFACE` on every vertex the layers texture. The cover's texels should be the map's (same
/// size over the terrain's extent) so the soil follows the density maps texel for texel: a texel
/// then reads the cover's texel alone ([`VegetationCover::soil_share_texel`]).
pub fn bake_layers_with(
    hf: &Heightfield,
    snow: &SnowRule,
    cover: Option<std::sync::Arc<VegetationCover>>,
) -> TerrainLayers {
    let map = [map_px(hf.width), map_px(hf.height)];
    let rows = bake_layer_rows(&MapRows::whole(hf), map, snow, cover.as_deref(), 0..map[1] as usize);
    TerrainLayers::from_rows(vec![rows], map, snow, cover).expect("the whole map's rows join")
}

/// Texel rows `first .. first + sums.len()` of the layer maps, `width` texels wide, as
/// [`bake_layer_rows`] bakes them: what a band of a terrain meshed in bands bakes of them.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerRows {
    pub first: usize,
    pub width: usize,
    /// RGBA8 weights per texel of each weight map (one, or two with a vegetation cover).
    pub weights: Vec<Vec<[u8; 4]>>,
    /// The base colour as sRGB-encoded 8-bit RGBA.
    pub albedo_rgba8: Vec<u8>,
    /// Each texel row's sum of every layer's weights (texels in order): the coverage's terms.
    pub sums: Vec<[f64; 5]>,
}

/// Texel rows `rows` of the layer maps (`map_px` over the whole map) of the map `field` (which
/// must hold every sample row those texels read: the rows around each texel centre and their
/// neighbours). With a `cover` of the map's texel grid each texel reads the cover's texel, which
/// must then be among its rows. The same bytes and row sums as those rows of a whole bake, bit for
/// bit, whatever rows `field` holds.
pub fn bake_layer_rows(
    field: &MapRows,
    map_px: [u32; 2],
    snow: &SnowRule,
    cover: Option<&VegetationCover>,
    rows: std::ops::Range<usize>,
) -> LayerRows {
    use rayon::prelude::*;
    let [w, h] = map_px;
    let layers = if cover.is_some() { LAYER_NAMES.len() } else { LAYERS_PER_MAP };
    let texels = w as usize * rows.len();
    let mut weights = vec![Vec::with_capacity(texels); layers.div_ceil(LAYERS_PER_MAP)];
    let mut albedo = Vec::with_capacity(4 * texels);
    let mut sums = Vec::with_capacity(rows.len());
    // (texel grids alike: a texel reads its own texel of the cover)
    let same_grid = cover.is_some_and(|c| c.size == map_px);
    let (width, height) = (field.hf.width, field.map_height);
    // A band of rows at a time (weighed in parallel, then folded in texel order): the f64 weights
    // of every texel are never all held (40 bytes a texel, 168 MB at 2048², and as much again
    // while collected).
    let step = (BAKE_BAND_TEXELS / w.max(1)).max(1) as usize;
    let mut band: Vec<[f64; 5]> = Vec::new();
    let mut pixels: Vec<[f32; 4]> = Vec::new();
    for y0 in rows.clone().step_by(step) {
        band.clear();
        band.par_extend((y0..(y0 + step).min(rows.end)).into_par_iter().flat_map_iter(|y| {
            let t = (y as f64 + 0.5) / h as f64 * (height - 1) as f64;
            (0..w).map(move |x| {
                let s = (x as f64 + 0.5) / w as f64 * (width - 1) as f64;
                let soil = |p: [f64; 3]| match cover {
                    Some(c) if same_grid => c.soil_share_texel(x as usize, y),
                    Some(c) => c.soil_share(p[0], p[2]),
                    None => 0.0,
                };
                weights_at(field, snow, s, t, soil)
            })
        }));
        pixels.clear();
        for row in band.chunks(w as usize) {
            let mut sum = [0.0f64; 5];
            for wts in row {
                let mut colour = [0.0f32, 0.0, 0.0, 1.0];
                for (k, &wk) in wts.iter().enumerate() {
                    sum[k] += wk;
                    for c in 0..3 {
                        colour[c] += wk as f32 * LAYER_ALBEDO[k][c];
                    }
                }
                let bytes = wts.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8);
                for (m, map) in weights.iter_mut().enumerate() {
                    map.push(std::array::from_fn(|c| bytes.get(LAYERS_PER_MAP * m + c).copied().unwrap_or(0)));
                }
                pixels.push(colour);
            }
            sums.push(sum);
        }
        // the base colour as the PNG holds it (sRGB 8-bit), not as linear f32 (4 times the bytes)
        albedo.extend(rgba8(&pixels));
    }
    LayerRows { first: rows.start, width: w as usize, weights, albedo_rgba8: albedo, sums }
}

impl TerrainLayers {
    /// The layers of a map from its texel rows (every row of `map_px`, in order: a whole bake's,
    /// or each band's). The coverage is each row's sums added in row order, over the texel count:
    /// the same figures whichever pieces the rows came in.
    pub fn from_rows(
        parts: Vec<LayerRows>,
        map_px: [u32; 2],
        snow: &SnowRule,
        cover: Option<std::sync::Arc<VegetationCover>>,
    ) -> Result<TerrainLayers, String> {
        let [w, h] = map_px.map(|v| v as usize);
        let layers = if cover.is_some() { LAYER_NAMES.len() } else { LAYERS_PER_MAP };
        let maps = layers.div_ceil(LAYERS_PER_MAP);
        let mut weights: Vec<Vec<[u8; 4]>> = vec![Vec::with_capacity(w * h); maps];
        let mut albedo = Vec::with_capacity(4 * w * h);
        let mut sums = [0.0f64; 5];
        let mut next = 0;
        for part in parts {
            let n = part.sums.len();
            if part.first != next || part.width != w || part.weights.len() != maps {
                return Err(format!(
                    "layer rows from {} ({} wide, {} maps) where row {next} ({w} wide, {maps} maps) was due",
                    part.first,
                    part.width,
                    part.weights.len()
                ));
            }
            if part.albedo_rgba8.len() != 4 * w * n || part.weights.iter().any(|m| m.len() != w * n) {
                return Err(format!("layer rows from {} do not hold {n} rows of {w} texels", part.first));
            }
            for (map, rows) in weights.iter_mut().zip(part.weights) {
                map.extend(rows);
            }
            albedo.extend(part.albedo_rgba8);
            for row in &part.sums {
                for k in 0..5 {
                    sums[k] += row[k];
                }
            }
            next += n;
        }
        if next != h {
            return Err(format!("layer rows end at row {next} of {h}"));
        }
        let n = (w * h).max(1) as f64;
        Ok(TerrainLayers {
            weights,
            albedo_rgba8: albedo,
            report: LayerReport {
                map_px,
                layers: LAYER_NAMES[..layers].iter().map(|s| s.to_string()).collect(),
                coverage: sums[..layers].iter().map(|s| s / n).collect(),
                snowline_m: SNOWLINE_M,
                snow: snow.label().into(),
            },
            snow: snow.clone(),
            cover,
            albedo_png: std::sync::OnceLock::new(),
        })
    }

    /// The first weight map as PNG bytes (RGBA8, stored as is: weights, not colours).
    pub fn weights_png(&self) -> Result<Vec<u8>, String> {
        self.weight_pngs().map(|mut v| v.swap_remove(0))
    }

    /// Every weight map as PNG bytes (map k holds layers 4k … 4k + 3).
    pub fn weight_pngs(&self) -> Result<Vec<Vec<u8>>, String> {
        let [w, h] = self.report.map_px;
        self.weights.iter().map(|m| encode_rgba8_png(&m.concat(), w, h)).collect()
    }

    /// Puts the layers on a terrain `scene` built from `hf`: the base colour on every terrain
    /// material (materials named `terrain`: the texture, replacing one of the same name, and a
    /// white factor so the texture's colour is what shows), and [`LAYER_WEIGHTS_ATTRIBUTE`] (with
    /// a cover also [`LAYER_WEIGHTS_1_ATTRIBUTE`] and [`SURFACE_ATTRIBUTE`]) on every primitive,
    /// from the surface under each vertex (x, z → sample x / cell, z / cell; skirt and base
    /// vertices take their border's).
    pub fn texture(&self, scene: &mut Scene, hf: &Heightfield, name: &str) -> Result<(), String> {
        vertex_weights(scene, hf, &self.snow, self.cover.as_deref());
        self.put_base_color(scene, name)
    }

    /// The base colour on every terrain material of `scene` ([`TerrainLayers::texture`] without
    /// the vertex attributes: for a scene whose chunks were weighed already).
    pub fn put_base_color(&self, scene: &mut Scene, name: &str) -> Result<(), String> {
        let [w, h] = self.report.map_px;
        let png = self.albedo_png.get_or_init(|| encode_rgba8_png(&self.albedo_rgba8, w, h)).clone()?;
        put_base_color_png(scene, name, png);
        Ok(())
    }
}

/// `png` as the base colour of every terrain material of `scene` (materials named `terrain`):
/// the texture `{name}_base_color`, replacing one of that name, and a white factor so the
/// texture's colour is what shows ([`TerrainLayers::put_base_color`] of a map encoded already).
pub fn put_base_color_png(scene: &mut Scene, name: &str, png: Vec<u8>) {
    {
        let texture = Texture { name: format!("{name}_base_color"), png };
        let t = match scene.textures.iter().position(|t| t.name == texture.name) {
            Some(t) => {
                scene.textures[t] = texture;
                t
            }
            None => {
                scene.textures.push(texture);
                scene.textures.len() - 1
            }
        };
        for m in scene.materials.iter_mut().filter(|m| m.name == "terrain") {
            m.base_color_texture = Some(t);
            m.base_color = [1.0, 1.0, 1.0, 1.0];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_follow_slope_and_height_and_sum_to_one() {
        let flat_low = layer_weights(2.0, 100.0);
        assert!(flat_low[0] > 0.99, "{flat_low:?}");
        let steep = layer_weights(60.0, 100.0);
        assert!(steep[2] > 0.99, "{steep:?}");
        let moderate = layer_weights(25.0, 100.0);
        assert!(moderate[1] > 0.3 && moderate[0] > 0.1, "{moderate:?}");
        let high_flat = layer_weights(5.0, SNOWLINE_M + 2.0 * SNOW_FADE_M);
        assert!(high_flat[3] > 0.99, "{high_flat:?}");
        let high_cliff = layer_weights(70.0, SNOWLINE_M + 2.0 * SNOW_FADE_M);
        assert!(high_cliff[3] < 0.01 && high_cliff[2] > 0.99, "{high_cliff:?}");
        for slope in (0..90).step_by(3) {
            for height in [0.0, 2400.0, 2600.0, 2700.0, 9000.0] {
                let w = layer_weights(slope as f64, height);
                assert!(
                    (w.iter().sum::<f64>() - 1.0).abs() < 1e-12 && w.iter().all(|&v| v >= 0.0),
                    "{slope} {height} {w:?}"
                );
            }
        }
    }

    #[test]
    fn a_snow_cover_rule_puts_snow_where_the_cover_does() {
        // a gentle ramp (about 6°) rising 0.1 m a cell along x: the cover's line at 3 m, a sharp
        // transition, no noise or wind, so snow exactly where the ramp is above 3 m
        let (w, h) = (65, 17);
        let heights: Vec<f32> = (0..w * h).map(|k| (k % w) as f32 * 0.1).collect();
        let hf = Heightfield { width: w, height: h, cell_size_m: 1.0, heights, exact: None };
        let cover = CoverSettings { snow_line_m: 3.0, transition_m: 0.0, wind_scour: 0.0, ..CoverSettings::default() };
        let layers = bake_layers(&hf, &SnowRule::Cover(cover.clone()));
        assert_eq!(layers.report.snow, "snow cover");
        let [mw, mh] = layers.report.map_px;
        for y in 0..mh {
            for x in 0..mw {
                let s = (x as f64 + 0.5) / mw as f64 * (w - 1) as f64;
                let want = if s * 0.1 >= 3.0 { 255 } else { 0 };
                assert_eq!(layers.weights[0][(y * mw + x) as usize][3], want, "texel ({x}, {y}) at height {}", s * 0.1);
            }
        }
        // the same weight the snow stage gives a vertex with this position and normal
        let rule = SnowRule::Cover(CoverSettings { transition_m: 4.0, snow_line_noise_m: 2.0, ..cover });
        let n = hf.normal_bilinear(40.0, 8.0);
        let q = [40.0, hf.height_bilinear(40.0, 8.0), 8.0];
        let direct = crate::snow::snow_weight(
            match &rule {
                SnowRule::Cover(c) => c,
                _ => unreachable!(),
            },
            q.map(|v| v as f32),
            n.map(|v| v as f32),
        )[0];
        assert!(direct > 0.05 && direct < 0.95, "{direct}");
        assert_eq!(rule.weight(q, n), direct as f64);
        // the fixed snowline puts none on this low ramp
        assert!(bake_layers(&hf, &SnowRule::Snowline).weights[0].iter().all(|t| t[3] == 0));
    }

    #[test]
    fn a_vegetation_cover_turns_bare_gentle_ground_to_soil_and_puts_surface_on_every_vertex() {
        use crate::terrain::vegetation::{Ground, SpeciesCover, VegetationCover};
        // a flat plain 64 m square: grass grows on its right half only
        let (w, h) = (65, 65);
        let hf = Heightfield { width: w, height: h, cell_size_m: 1.0, heights: vec![0.0; w * h], exact: None };
        let size = [map_px(w), map_px(h)];
        let weights = (0..size[0] * size[1]).map(|k| if k % size[0] >= size[0] / 2 { 1.0 } else { 0.0 }).collect();
        let grass =
            SpeciesCover { ground: Ground::Grass, max_density: 4.0, height_m: 0.3, footprint_m2: 0.05, weights };
        let cover = VegetationCover {
            extent: [0.0, 0.0, (w - 1) as f64, (h - 1) as f64],
            size,
            species: vec![grass],
            first_row: 0,
        };
        let layers = bake_layers_with(&hf, &SnowRule::Snowline, Some(std::sync::Arc::new(cover)));
        assert_eq!(layers.report.layers, LAYER_NAMES);
        assert_eq!(layers.weights.len(), 2, "two weight maps");
        let c = &layers.report.coverage;
        assert!((c[0] - 0.5).abs() < 1e-9 && (c[4] - 0.5).abs() < 1e-9, "{c:?}");
        assert_eq!(layers.weight_pngs().unwrap().len(), 2);
        let texel = |x: u32| (layers.weights[0][x as usize], layers.weights[1][x as usize]);
        assert_eq!(texel(0), ([0, 0, 0, 0], [255, 0, 0, 0]), "bare: soil");
        assert_eq!(texel(size[0] - 1), ([255, 0, 0, 0], [0, 0, 0, 0]), "grass where it grows");
        // every vertex: five bytes summing to 255, TEXTURE the larger layer, the grass's TYPE,
        // DENSITY and SIZE where it grows, nothing where it does not
        let mut scene = crate::terrain::build::build_scene(
            &hf,
            &crate::terrain::grid::grid(&hf, 8).unwrap(),
            &crate::terrain::build::BuildOptions::default(),
        )
        .unwrap();
        layers.texture(&mut scene, &hf, "terrain").unwrap();
        let p = &scene.meshes[0].primitives[0];
        let get = |name: &str| &p.custom.iter().find(|c| c.name == name).unwrap().values;
        for (((q, a), b), surface) in p
            .positions
            .iter()
            .zip(get(LAYER_WEIGHTS_ATTRIBUTE))
            .zip(get(LAYER_WEIGHTS_1_ATTRIBUTE))
            .zip(get(SURFACE_ATTRIBUTE))
        {
            let total: f32 = a.iter().sum::<f32>() + b[0];
            assert!((total - 1.0).abs() < 1e-5, "{a:?} {b:?}");
            if q[0] < 28.0 {
                assert_eq!((a[0], b[0]), (0.0, 1.0), "soil at {q:?}");
                assert_eq!(*surface, [4.0, 0.0, 0.0, 0.0], "at {q:?}");
            } else if q[0] > 36.0 {
                assert_eq!((a[0], b[0]), (1.0, 0.0), "grass at {q:?}");
                assert_eq!(*surface, [0.0, 1.0, 4.0, 0.3], "at {q:?}");
            }
        }
    }

    #[test]
    fn map_sizes_are_powers_of_two_near_the_sample_spacing() {
        assert_eq!(map_px(513), 512);
        assert_eq!(map_px(512), 512);
        assert_eq!(map_px(257), 256);
        assert_eq!(map_px(300), 256);
        assert_eq!(map_px(400), 512);
        assert_eq!(map_px(2), 2);
        assert_eq!(map_px(20001), MAX_LAYER_MAP_PX);
    }

    #[test]
    fn a_cliff_bakes_rock_and_a_plain_grass() {
        // left half flat, right half a 60° ramp
        let (w, h) = (65, 33);
        let cell = 1.0;
        let heights: Vec<f32> = (0..w * h)
            .map(|k| {
                let i = k % w;
                if i < 32 {
                    0.0
                } else {
                    (i - 32) as f32 * 1.732
                }
            })
            .collect();
        let hf = Heightfield { width: w, height: h, cell_size_m: cell, heights, exact: None };
        let layers = bake_layers(&hf, &SnowRule::Snowline);
        assert_eq!(layers.report.map_px, [64, 32]);
        let at = |x: usize, y: usize| layers.weights[0][y * 64 + x];
        assert!(at(4, 16)[0] == 255, "{:?}", at(4, 16));
        assert!(at(60, 16)[2] == 255, "{:?}", at(60, 16));
        let c = &layers.report.coverage;
        assert!((c.iter().sum::<f64>() - 1.0).abs() < 1e-9);
        assert!(c[0] > 0.4 && c[2] > 0.4, "{c:?}");
        let png = layers.weights_png().unwrap();
        assert!(png.starts_with(b"\x89PNG"));
        // the texture goes on the terrain material
        let mut scene = Scene { materials: vec![crate::terrain::build::terrain_material()], ..Scene::default() };
        layers.texture(&mut scene, &hf, "terrain").unwrap();
        assert_eq!(scene.materials[0].base_color_texture, Some(0));
        assert_eq!(scene.textures[0].name, "terrain_base_color");
        // and the weights go on every vertex of the built terrain, skirts included: grass on the
        // plain, rock on the ramp, each the weights of the surface under it
        let mesh = crate::terrain::grid::grid(&hf, 1).unwrap();
        let opts = crate::terrain::build::BuildOptions {
            chunk_samples: Some(16),
            skirt_depth_m: Some(2.0),
            base_depth_m: None,
            name: "t".into(),
            ..Default::default()
        };
        let mut built = crate::terrain::build::build_scene(&hf, &mesh, &opts).unwrap();
        layers.texture(&mut built, &hf, "t").unwrap();
        let mut seen = [0usize; 2];
        for p in built.meshes.iter().flat_map(|m| &m.primitives) {
            let c = p.custom.iter().find(|c| c.name == LAYER_WEIGHTS_ATTRIBUTE).expect("weights on every primitive");
            assert_eq!(c.values.len(), p.positions.len());
            for (q, v) in p.positions.iter().zip(&c.values) {
                let bytes = v.map(|x| (x * 255.0).round() as u32);
                assert_eq!(bytes.iter().sum::<u32>(), 255, "{v:?}");
                assert_eq!(bytes.map(|b| b as f32 / 255.0), *v, "exact multiples of 1/255");
                let i = (q[0] as f64 / cell).round() as usize;
                if i < 31 {
                    assert!(v[0] > 0.99, "grass at x = {}: {v:?}", q[0]);
                    seen[0] += 1;
                } else if i > 33 {
                    assert!(v[2] > 0.99, "rock at x = {}: {v:?}", q[0]);
                    seen[1] += 1;
                }
            }
        }
        assert!(seen[0] > 100 && seen[1] > 100, "{seen:?}");
    }
}
