//! The terrain's normal map: the height field's normals at texel resolution, in the tangent space
//! of the mesh that carries them, so a coarse TIN is lit as the full map would be.
//!
//! A TIN triangle spans many samples; its vertex normals (the map's normals at its corners)
//! interpolate to a smooth normal that misses every ridge and gully inside it. Each texel of the
//! map stores the height field's normal there (bilinear between the samples' central-difference
//! normals) relative to the frame an engine builds at that point of this mesh: the interpolated
//! vertex normal N, the TANGENT written with it (along +u = +x, orthogonal to the vertex normal,
//! w = +1) and B = N × T, which points up the image (towards smaller v, −z) as glTF's normal
//! textures expect. Every LoD level bakes its own map against its own mesh.
//!
//! The analyzer is the shading error: at every texel centre the angle between the height field's
//! normal and the normal an engine shades with, without the map (the interpolated vertex normal)
//! and with it (the texel as written, 8 bits a channel, through the same frame).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::heightfield::{Heightfield, MapRows};
use crate::mesh::{Primitive, Scene, Texture};

/// What the normal map corrects, measured at every texel centre the terrain's surface covers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NormalMapReport {
    /// Map size (width, height) in texels: the layers' size.
    pub map_px: [u32; 2],
    /// Texels the surface covers (every texel of a whole map).
    pub texels: usize,
    /// Angle (degrees) between the height field's normal and the interpolated vertex normal: the
    /// shading error without the map, mean and largest.
    pub mean_error_without_deg: f64,
    pub max_error_without_deg: f64,
    /// The same with the map as written (8-bit texels decoded through the tangent frame).
    pub mean_error_deg: f64,
    pub max_error_deg: f64,
}

/// The tangent glTF wants beside a normal map at a vertex with this unit normal: +x with its
/// component along the normal removed (+z where the normal is nearly ±x, as on a skirt's end
/// wall), unit length, w = +1 (the bitangent N × T then points towards −z, up the image).
pub fn terrain_tangent(n: [f32; 3]) -> [f32; 4] {
    let n = n.map(|c| c as f64);
    let along = |a: [f64; 3]| {
        let d = a[0] * n[0] + a[1] * n[1] + a[2] * n[2];
        let t = [a[0] - d * n[0], a[1] - d * n[1], a[2] - d * n[2]];
        let len = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
        (len > 1e-3).then(|| t.map(|c| c / len))
    };
    let t = along([1.0, 0.0, 0.0]).or_else(|| along([0.0, 0.0, 1.0])).unwrap_or([1.0, 0.0, 0.0]);
    [t[0] as f32, t[1] as f32, t[2] as f32, 1.0]
}

type V3 = [f64; 3];

use crate::math::{cross3 as cross, dot3 as dot};

/// `a` at unit length; straight up when it has none.
fn unit(a: V3) -> V3 {
    crate::math::normalize3(a).unwrap_or([0.0, 1.0, 0.0])
}

fn angle_deg(a: V3, b: V3) -> f64 {
    dot(unit(a), unit(b)).clamp(-1.0, 1.0).acos().to_degrees()
}

/// The orthonormal frame (T, B, N) an engine shades with at barycentric `bary` of a triangle with
/// these vertex normals and tangents (interpolated, N normalised, T orthogonalised to it).
fn frame(normals: [[f32; 3]; 3], tangents: [[f32; 4]; 3], bary: [f64; 3]) -> (V3, V3, V3) {
    let lerp = |v: [[f32; 3]; 3]| -> V3 { std::array::from_fn(|k| (0..3).map(|c| bary[c] * v[c][k] as f64).sum()) };
    let n = unit(lerp(normals));
    let t0 = lerp(tangents.map(|t| [t[0], t[1], t[2]]));
    let t = unit([0, 1, 2].map(|k| t0[k] - dot(t0, n) * n[k]));
    (t, cross(n, t), n)
}

fn to_byte(v: f64) -> u8 {
    ((v * 0.5 + 0.5).clamp(0.0, 1.0) * 255.0).round() as u8
}

fn from_byte(b: u8) -> f64 {
    b as f64 / 255.0 * 2.0 - 1.0
}

/// Texel rows baked together (a band of the map; the bands run in parallel).
const TEXEL_ROWS_PER_BAND: usize = 64;

/// First texel index along axis `c` (of `n` texels) whose centre can lie in the triangle `uv`.
fn texel_lo(uv: &[[f64; 2]; 3], c: usize, n: u32) -> usize {
    let m = uv.iter().map(|q| q[c]).fold(f64::INFINITY, f64::min);
    ((m * n as f64 - 0.5).floor().max(0.0) as usize).min(n as usize)
}

/// One past the last texel index along axis `c` whose centre can lie in the triangle `uv`.
fn texel_hi(uv: &[[f64; 2]; 3], c: usize, n: u32) -> usize {
    let m = uv.iter().map(|q| q[c]).fold(f64::NEG_INFINITY, f64::max);
    ((m * n as f64 - 0.5).ceil().max(0.0) as usize + 1).min(n as usize)
}

/// One texel row's share of the figures: the angles summed in the order the row's texels were
/// baked (faces in scene order), the largest, and the texels covered. A map's figures are its
/// rows', summed row by row from the top, so rows baked apart (a band's unit) give the same.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RowFigures {
    pub sum_without: f64,
    pub max_without: f64,
    pub sum_with: f64,
    pub max_with: f64,
    pub texels: u64,
}

/// Texel rows `first .. first + figures.len()` of a normal map `width` texels wide, baked: their
/// texels (row-major) and each row's figures.
#[derive(Debug, Clone, PartialEq)]
pub struct TexelRows {
    pub first: usize,
    pub width: usize,
    pub texels: Vec<[u8; 4]>,
    pub figures: Vec<RowFigures>,
}

/// A top face of the surface with its uv rows.
struct Face {
    uv: [[f64; 2]; 3],
    area: f64,
    normals: [[f32; 3]; 3],
    tangents: [[f32; 4]; 3],
    rows: (usize, usize),
}

/// The surface's top faces of `primitives` (in order; skirt walls have no extent in uv, the base
/// faces down), with their uv rows in a map `h` texels high. Tangents are [`terrain_tangent`] of
/// the vertex normals, as [`add_tangents`] writes them.
fn surface_faces<'p>(primitives: impl Iterator<Item = &'p Primitive>, h: u32) -> Vec<Face> {
    let mut faces: Vec<Face> = Vec::new();
    for p in primitives {
        for tri in p.indices.chunks_exact(3) {
            let v = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
            if v.iter().any(|&k| k >= p.positions.len() || k >= p.normals.len() || k >= p.uvs.len()) {
                continue;
            }
            let pos = v.map(|k| p.positions[k].map(|c| c as f64));
            let e1 = [0, 1, 2].map(|k| pos[1][k] - pos[0][k]);
            let e2 = [0, 1, 2].map(|k| pos[2][k] - pos[0][k]);
            if cross(e1, e2)[1] <= 0.0 {
                continue;
            }
            let uv = v.map(|k| p.uvs[k].map(|c| c as f64));
            let area = (uv[1][0] - uv[0][0]) * (uv[2][1] - uv[0][1]) - (uv[2][0] - uv[0][0]) * (uv[1][1] - uv[0][1]);
            if area.abs() < 1e-18 {
                continue;
            }
            let rows = (texel_lo(&uv, 1, h), texel_hi(&uv, 1, h));
            let normals = v.map(|k| p.normals[k]);
            faces.push(Face { uv, area, normals, tangents: normals.map(terrain_tangent), rows });
        }
    }
    faces
}

/// Texel rows `rows` of the normal map (`map_px` texels) of the surface `primitives` (the top
/// faces of a terrain's chunks, in scene order, with normals and UVs), shading the height field's
/// normals `field` ([`MapRows`]: every sample row those texels read must be held). Texel (x, y) is
/// the point at uv ((x + ½)/W, (y + ½)/H) of the surface; it takes the first face covering its
/// centre, and stays (0, 0, 1) where none does.
pub fn bake_rows<'p>(
    primitives: impl Iterator<Item = &'p Primitive>,
    field: &MapRows,
    map_px: [u32; 2],
    rows: std::ops::Range<usize>,
) -> TexelRows {
    let [w, h] = map_px;
    let (wu, hu) = (w as usize, h as usize);
    let rows = rows.start.min(hu)..rows.end.min(hu);
    let faces = surface_faces(primitives, h);
    let span = |n: usize| (n.max(2) - 1) as f64;
    let (sx, sy) = (span(field.hf.width), span(field.map_height));
    // Bands of texel rows baked in parallel, each by every face reaching it in scene order: a
    // texel takes the first face covering its centre, as one pass over the faces would give it;
    // the figures are summed per row (the same at any thread count).
    let band = TEXEL_ROWS_PER_BAND;
    let bands = rows.len().div_ceil(band);
    // each band's faces, in scene order (a face is listed in every band its rows reach)
    let mut reaching: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (k, f) in faces.iter().enumerate() {
        let (lo, hi) = (f.rows.0.max(rows.start), f.rows.1.min(rows.end));
        if lo < hi {
            for list in &mut reaching[(lo - rows.start) / band..=(hi - 1 - rows.start) / band] {
                list.push(k as u32);
            }
        }
    }
    let baked: Vec<(Vec<[u8; 4]>, Vec<RowFigures>)> = reaching
        .into_par_iter()
        .enumerate()
        .map(|(b, reaching)| {
            let y0 = rows.start + b * band;
            let y1 = (y0 + band).min(rows.end);
            // (0, 0, 1) until a surface triangle covers the texel
            let mut texels = vec![[128u8, 128, 255, 255]; (y1 - y0) * wu];
            let mut covered = vec![false; (y1 - y0) * wu];
            let mut figures = vec![RowFigures::default(); y1 - y0];
            for f in reaching.into_iter().map(|k| &faces[k as usize]) {
                let uv = &f.uv;
                for y in f.rows.0.max(y0)..f.rows.1.min(y1) {
                    let tv = (y as f64 + 0.5) / h as f64;
                    let row = &mut figures[y - y0];
                    for x in texel_lo(uv, 0, w)..texel_hi(uv, 0, w) {
                        let tu = (x as f64 + 0.5) / w as f64;
                        let b1 = ((tu - uv[0][0]) * (uv[2][1] - uv[0][1]) - (uv[2][0] - uv[0][0]) * (tv - uv[0][1]))
                            / f.area;
                        let b2 = ((uv[1][0] - uv[0][0]) * (tv - uv[0][1]) - (tu - uv[0][0]) * (uv[1][1] - uv[0][1]))
                            / f.area;
                        let bary = [1.0 - b1 - b2, b1, b2];
                        if bary.iter().any(|&b| b < -1e-9) {
                            continue;
                        }
                        let k = (y - y0) * wu + x;
                        if covered[k] {
                            continue;
                        }
                        covered[k] = true;
                        let (t, b, n) = frame(f.normals, f.tangents, bary);
                        let field = field.normal_bilinear(tu * sx, tv * sy);
                        let local = [dot(field, t), dot(field, b), dot(field, n)];
                        let bytes = [to_byte(local[0]), to_byte(local[1]), to_byte(local[2]), 255];
                        texels[k] = bytes;
                        let decoded = [0, 1, 2].map(|c| {
                            from_byte(bytes[0]) * t[c] + from_byte(bytes[1]) * b[c] + from_byte(bytes[2]) * n[c]
                        });
                        let (without, with) = (angle_deg(n, field), angle_deg(decoded, field));
                        row.sum_without += without;
                        row.max_without = row.max_without.max(without);
                        row.sum_with += with;
                        row.max_with = row.max_with.max(with);
                        row.texels += 1;
                    }
                }
            }
            (texels, figures)
        })
        .collect();
    let mut out = TexelRows {
        first: rows.start,
        width: wu,
        texels: Vec::with_capacity(rows.len() * wu),
        figures: Vec::with_capacity(rows.len()),
    };
    for (texels, figures) in baked {
        out.texels.extend(texels);
        out.figures.extend(figures);
    }
    out
}

/// TANGENT ([`terrain_tangent`] of the normal) on every primitive of a material named `terrain`;
/// which materials those are.
fn add_tangents(scene: &mut Scene, name: &str) -> Result<Vec<bool>, String> {
    let terrain: Vec<bool> = scene.materials.iter().map(|m| m.name == "terrain").collect();
    let uses_map = |p: &Primitive| p.material.is_some_and(|m| terrain.get(m).copied().unwrap_or(false));
    for p in scene.meshes.iter_mut().flat_map(|m| m.primitives.iter_mut()).filter(|p| uses_map(p)) {
        if p.normals.len() != p.positions.len() || p.uvs.len() != p.positions.len() {
            return Err(format!("terrain mesh `{name}` has a primitive without normals or UVs"));
        }
        p.tangents = p.normals.iter().map(|&n| terrain_tangent(n)).collect();
    }
    Ok(terrain)
}

/// Bakes the normal map of the terrain `scene` (built from `hf`) at `map_px` texels and puts it
/// on the scene: TANGENT on every primitive of a material named `terrain`, the map (PNG, data not
/// colour) as those materials' normal texture, named `{name}_normal`. Texel (x, y) is the point at
/// uv ((x + ½)/W, (y + ½)/H) of the surface (the top faces; skirts and the base, which the planar
/// UVs map onto the border or the whole map again, do not write it). Returns what the map corrects.
pub fn bake_normal_map(
    hf: &Heightfield,
    scene: &mut Scene,
    name: &str,
    map_px: [u32; 2],
) -> Result<NormalMapReport, String> {
    let terrain = add_tangents(scene, name)?;
    let uses_map = |p: &&Primitive| p.material.is_some_and(|m| terrain.get(m).copied().unwrap_or(false));
    let primitives = scene.meshes.iter().flat_map(|m| &m.primitives).filter(uses_map);
    let rows = bake_rows(primitives, &MapRows::whole(hf), map_px, 0..map_px[1] as usize);
    attach(scene, name, map_px, &terrain, rows)
}

/// [`bake_normal_map`] with the map's texel rows baked already (every row, in order: bands' units
/// put together).
pub fn put_normal_map(
    scene: &mut Scene,
    name: &str,
    map_px: [u32; 2],
    rows: TexelRows,
) -> Result<NormalMapReport, String> {
    let terrain = add_tangents(scene, name)?;
    attach(scene, name, map_px, &terrain, rows)
}

/// `png` as the normal texture (named `{name}_normal`) of every `terrain` material of `scene`,
/// with TANGENT on their primitives: what [`put_normal_map`] puts, of a map encoded already (a
/// scene tile unit's stand-in for the whole map, [`crate::scene::tile_units`]).
pub fn put_normal_texture(scene: &mut Scene, name: &str, png: Vec<u8>) -> Result<(), String> {
    let terrain = add_tangents(scene, name)?;
    attach_png(scene, name, &terrain, png);
    Ok(())
}

fn attach_png(scene: &mut Scene, name: &str, terrain: &[bool], png: Vec<u8>) {
    scene.textures.push(Texture { name: format!("{name}_normal"), png });
    let index = scene.textures.len() - 1;
    for (m, _) in scene.materials.iter_mut().zip(terrain).filter(|(_, &t)| t) {
        m.normal_texture = Some(index);
    }
}

/// The map of `rows` as the normal texture of the `terrain` materials, and its figures.
fn attach(
    scene: &mut Scene,
    name: &str,
    map_px: [u32; 2],
    terrain: &[bool],
    rows: TexelRows,
) -> Result<NormalMapReport, String> {
    let [w, h] = map_px;
    if rows.first != 0
        || rows.width != w as usize
        || rows.figures.len() != h as usize
        || rows.texels.len() != (w * h) as usize
    {
        return Err(format!(
            "the normal map of `{name}` has rows {}..{} of {} texels; {w} × {h} were wanted",
            rows.first,
            rows.first + rows.figures.len(),
            rows.width
        ));
    }
    let (mut sum_without, mut max_without) = (0.0f64, 0.0f64);
    let (mut sum_with, mut max_with) = (0.0f64, 0.0f64);
    let mut count = 0u64;
    for r in &rows.figures {
        sum_without += r.sum_without;
        max_without = max_without.max(r.max_without);
        sum_with += r.sum_with;
        max_with = max_with.max(r.max_with);
        count += r.texels;
    }
    let png = crate::bake::raster::png::encode_rgba8_png(rows.texels.as_flattened(), w, h)?;
    attach_png(scene, name, terrain, png);
    let mean = |s: f64| if count > 0 { s / count as f64 } else { 0.0 };
    Ok(NormalMapReport {
        map_px,
        texels: count as usize,
        mean_error_without_deg: mean(sum_without),
        max_error_without_deg: max_without,
        mean_error_deg: mean(sum_with),
        max_error_deg: max_with,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tangents_run_along_x_orthogonal_to_the_normal_with_the_bitangent_up_the_image() {
        // flat ground: T = +x, and N × T = −z, towards smaller v (up the image), as glTF wants
        let t = terrain_tangent([0.0, 1.0, 0.0]);
        assert_eq!(t, [1.0, 0.0, 0.0, 1.0]);
        let b = cross([0.0, 1.0, 0.0], [1.0, 0.0, 0.0]);
        assert_eq!(b, [0.0, 0.0, -1.0]);
        for n in [[0.6, 0.8, 0.0], [0.0, 0.6, -0.8], [-0.48, 0.6, 0.64], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]] {
            let t = terrain_tangent(n);
            let d = n[0] * t[0] + n[1] * t[1] + n[2] * t[2];
            let len = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
            assert!(d.abs() < 1e-6 && (len - 1.0).abs() < 1e-6 && t[3] == 1.0, "{n:?} -> {t:?}");
        }
        // a skirt's end wall facing ±x takes +z
        assert_eq!(terrain_tangent([1.0, 0.0, 0.0]), [0.0, 0.0, 1.0, 1.0]);
    }

    #[test]
    fn a_tilted_plane_needs_no_correction_and_a_bump_under_a_big_triangle_does() {
        let (w, h) = (33, 17);
        let plane: Vec<f32> = (0..w * h).map(|k| 0.5 * (k % w) as f32 + 0.25 * (k / w) as f32).collect();
        let hf = Heightfield { width: w, height: h, cell_size_m: 1.0, heights: plane, exact: None };
        let coarse = crate::terrain::grid::grid(&hf, 16).unwrap();
        let opts = crate::terrain::build::BuildOptions {
            chunk_samples: None,
            skirt_depth_m: None,
            base_depth_m: None,
            name: "t".into(),
            ..Default::default()
        };
        let mut scene = crate::terrain::build::build_scene(&hf, &coarse, &opts).unwrap();
        let r = bake_normal_map(&hf, &mut scene, "t", [32, 16]).unwrap();
        assert_eq!(r.texels, 32 * 16);
        assert!(r.max_error_without_deg < 1e-6 && r.max_error_deg < 0.5, "{r:?}");
        let img = image::load_from_memory(&scene.textures[0].png).unwrap().to_rgba8();
        assert!(img.pixels().all(|p| p.0 == [128, 128, 255, 255]), "a plane's map is (0, 0, 1) everywhere");
        assert_eq!(scene.materials[0].normal_texture, Some(0));
        assert!(scene.meshes.iter().flat_map(|m| &m.primitives).all(|p| p.tangents.len() == p.positions.len()));

        // a bump in the middle of one 16 × 16-cell quad: its vertex normals see none of it
        let bump: Vec<f32> = (0..w * h)
            .map(|k| {
                let (x, z) = ((k % w) as f32 - 8.0, (k / w) as f32 - 8.0);
                4.0 * (-(x * x + z * z) / 8.0).exp()
            })
            .collect();
        let hf = Heightfield { width: w, height: h, cell_size_m: 1.0, heights: bump, exact: None };
        let mut scene = crate::terrain::build::build_scene(&hf, &coarse, &opts).unwrap();
        let r = bake_normal_map(&hf, &mut scene, "t", [32, 16]).unwrap();
        assert!(r.max_error_without_deg > 30.0 && r.max_error_deg < 0.6, "{r:?}");
    }
}
