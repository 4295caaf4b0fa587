//! Bring your own mesh: a Wavefront OBJ (+ MTL, + PNG/JPEG `map_Kd` textures) read with tobj into
//! the in-memory [`Scene`] the LoD chain starts from ([`crate::plants::tree_lod::build_mesh_lods`]),
//! as the terrain walk-through thesis loaded 3DS models. Missing normals are generated angle-weighted
//! (Thürmer & Wüthrich, "Computing vertex normals from polygonal facets", JGT 1998).
//!
//! What the loader does, in order: a line scan that positions syntax errors (file:line:column) and
//! enforces the vertex/triangle limits before anything is allocated; tobj (triangulated, one index
//! per corner); one primitive per material (faces without a material, or an OBJ without `mtllib`,
//! get a grey default); Z-up files turned to +Y up ((x, y, z) → (x, z, −y)); the unit `scale`
//! applied; then recentring: the lowest point at y = 0 and the centre of the x/z bounding
//! rectangle (the footprint) at x = z = 0, so the model stands on the origin like a tree does.
//!
//! Materials: `Kd` is the linear base colour (multiplying `map_Kd`, as the MTL spec says), `d` its
//! alpha. A texture with any texel alpha below 1 makes the material an alpha mask (cutoff 0.5) and
//! double-sided (leaf cards); otherwise `d` < 1 makes it blended. Texture paths are relative to the
//! MTL's folder. Vertex colours, `map_d`, `map_Bump` and other maps are ignored.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::bake::raster::png::encode_rgba8_png;
use crate::mesh::{AlphaMode, Bounds, Material, Mesh, Primitive, Scene, Texture};
use crate::plants::tree::is_flat;

/// Vertex positions an OBJ may define (`--max-vertices` / `[mesh] max_vertices`), checked while
/// scanning.
pub const DEFAULT_MAX_VERTICES: usize = 2_000_000;
/// Triangles an OBJ may have (`--max-triangles` / `[mesh] max_triangles`), checked while scanning:
/// a model's default LoD chain costs about its triangles, as a tree's does, so the budget is the
/// trees' (the bush of ../shared/data exported as a 262k-triangle OBJ builds its default chain in
/// about 5.5 s here, a 1 M-triangle wavy sheet in about 5 s; a 3.9 M-triangle model ran past 5 min
/// under the former 4 M default).
pub const DEFAULT_MAX_TRIANGLES: usize = 300_000;
/// Textures larger than this on a side are refused (a 8192² RGBA texture is 256 MiB decoded).
pub const MAX_TEXTURE_SIDE_PX: u32 = 8192;
/// The colour of faces without a material.
pub const FALLBACK_GREY: [f32; 4] = [0.5, 0.5, 0.5, 1.0];

#[derive(Debug, thiserror::Error)]
pub enum MeshAssetError {
    #[error("{path}: cannot read the file ({problem}); check the path")]
    Read { path: PathBuf, problem: String },
    #[error("{path}:{line}:{column}: {message}\n  {text}\n  {caret}^", caret = " ".repeat(column.saturating_sub(1)))]
    Syntax { path: PathBuf, line: usize, column: usize, message: String, text: String },
    #[error("{path}: tobj cannot load it ({problem}); re-export it as a triangle or polygon OBJ")]
    Load { path: PathBuf, problem: String },
    #[error("{obj}: its material library {mtl} cannot be read ({problem}); put the .mtl beside the .obj or remove the `mtllib` line (faces then fall back to grey)")]
    MissingMaterialLibrary { obj: PathBuf, mtl: PathBuf, problem: String },
    #[error("{mtl}: material {material:?} uses texture {texture} which cannot be read ({problem}); put it beside the .mtl (map_Kd paths are relative to the .mtl's folder) or remove the map_Kd line")]
    MissingTexture { mtl: PathBuf, material: String, texture: PathBuf, problem: String },
    #[error("{path}: material {material:?} has the texture {texture} but its faces have no texture coordinates (vt); export UVs or remove the map_Kd line")]
    NoTexCoords { path: PathBuf, material: String, texture: String },
    #[error(
        "{path}: {count} {what}, over the limit of {limit}; simplify the model first or raise the limit \
         (--max-{what} of `verdant mesh`; `max_{what}` in a preset's [mesh])"
    )]
    TooLarge { path: PathBuf, what: &'static str, count: usize, limit: usize },
    #[error("{path}: no faces with area; export the model's faces (f lines)")]
    Empty { path: PathBuf },
    #[error("invalid OBJ options: {0}")]
    Options(String),
}

/// Every failure here is bad input or an exceeded limit.
impl crate::failure::Failure for MeshAssetError {
    fn blame(&self) -> crate::failure::Blame {
        crate::failure::Blame::Input
    }
}

/// Which axis of the file points up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub enum UpAxis {
    /// +Y up (glTF, Maya, Blender's default OBJ export).
    #[default]
    Y,
    /// +Z up (3ds Max, many CAD and photogrammetry exports): turned by (x, y, z) → (x, z, −y).
    Z,
}

/// How an OBJ is read.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjOptions {
    /// Metres per file unit (0.01 for centimetres).
    pub scale: f64,
    pub up_axis: UpAxis,
    /// Put the lowest point at y = 0 and the footprint centre at x = z = 0.
    pub recentre: bool,
    pub max_vertices: usize,
    pub max_triangles: usize,
}

impl Default for ObjOptions {
    fn default() -> Self {
        ObjOptions {
            scale: 1.0,
            up_axis: UpAxis::Y,
            recentre: true,
            max_vertices: DEFAULT_MAX_VERTICES,
            max_triangles: DEFAULT_MAX_TRIANGLES,
        }
    }
}

/// What the loader found and did.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshAssetStats {
    pub vertices: usize,
    pub triangles: usize,
    pub primitives: usize,
    pub materials: usize,
    pub textures: usize,
    /// Primitives whose normals were generated (the file had none, or unusable ones).
    pub normals_generated: usize,
    pub has_uvs: bool,
    pub degenerate_triangles_dropped: usize,
    /// Metres added to every position after turning and scaling (the recentring).
    pub offset_m: [f64; 3],
    pub bounds: Option<Bounds>,
}

/// A loaded model: one mesh (index 0) shown by one root node, its materials and textures.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceMesh {
    pub scene: Scene,
    pub stats: MeshAssetStats,
}

impl SourceMesh {
    pub fn mesh(&self) -> &Mesh {
        &self.scene.meshes[0]
    }
}

/// OBJ keywords the scan accepts (geometry it does not use, such as curves, is accepted and ignored).
const KNOWN_KEYWORDS: &[&str] = &[
    "v",
    "vt",
    "vn",
    "vp",
    "f",
    "l",
    "p",
    "o",
    "g",
    "s",
    "usemtl",
    "mtllib",
    "cstype",
    "deg",
    "bmat",
    "step",
    "curv",
    "curv2",
    "surf",
    "parm",
    "trim",
    "hole",
    "scrv",
    "sp",
    "end",
    "con",
    "mg",
    "lod",
    "shadow_obj",
    "trace_obj",
    "ctech",
    "stech",
    "maplib",
    "usemap",
    "bevel",
    "c_interp",
    "d_interp",
];

/// Checks every line of `text`: known keyword, finite numbers where numbers belong, face corners
/// that name existing vertices; counts positions and triangles against the limits. Returns the
/// material libraries named (`mtllib`).
fn scan(path: &Path, text: &[u8], options: &ObjOptions) -> Result<Vec<String>, MeshAssetError> {
    let (mut positions, mut triangles, mut texcoords, mut normals) = (0usize, 0usize, 0usize, 0usize);
    let mut mtllibs = Vec::new();
    for (n, raw) in text.split(|&b| b == b'\n').enumerate() {
        let line = String::from_utf8_lossy(raw);
        let line = line.trim_end_matches('\r');
        let syntax = |column: usize, message: String| MeshAssetError::Syntax {
            path: path.to_path_buf(),
            line: n + 1,
            column,
            message,
            text: line.to_string(),
        };
        let content = line.split('#').next().unwrap_or("");
        // (column, token) pairs, 1-based columns
        let mut tokens = Vec::new();
        let mut start = None;
        for (i, c) in content.char_indices().chain([(content.len(), ' ')]) {
            match (c.is_whitespace(), start) {
                (false, None) => start = Some(i),
                (true, Some(s)) => {
                    tokens.push((content[..s].chars().count() + 1, &content[s..i]));
                    start = None;
                }
                _ => {}
            }
        }
        let Some(&(kw_col, keyword)) = tokens.first() else { continue };
        if !KNOWN_KEYWORDS.contains(&keyword) {
            return Err(syntax(
                kw_col,
                format!("unknown statement {keyword:?} (expected v, vt, vn, f, o, g, usemtl, mtllib, …)"),
            ));
        }
        let numbers = |min: usize, max: usize| -> Result<(), MeshAssetError> {
            let args = &tokens[1..];
            if args.len() < min || args.len() > max {
                return Err(syntax(kw_col, format!("`{keyword}` takes {min} to {max} numbers, found {}", args.len())));
            }
            for &(col, t) in args {
                match t.parse::<f64>() {
                    // models are read as 32-bit floats (tobj, then glTF): a larger number would
                    // become infinity and its faces vanish as if they had no area
                    Ok(x) if x.is_finite() && x.abs() <= f32::MAX as f64 => {}
                    Ok(x) if x.is_finite() => {
                        return Err(syntax(
                            col,
                            format!(
                                "{t} is beyond the ±3.4e38 a 32-bit float holds (models are stored as 32-bit floats); rescale the model in the program that wrote it"
                            ),
                        ))
                    }
                    _ => return Err(syntax(col, format!("{t:?} is not a finite number"))),
                }
            }
            Ok(())
        };
        match keyword {
            "v" => {
                numbers(3, 7)?;
                positions += 1;
                if positions > options.max_vertices {
                    return Err(MeshAssetError::TooLarge {
                        path: path.to_path_buf(),
                        what: "vertices",
                        count: positions,
                        limit: options.max_vertices,
                    });
                }
            }
            "vt" => {
                numbers(1, 3)?;
                texcoords += 1;
            }
            "vn" => {
                numbers(3, 3)?;
                normals += 1;
            }
            "f" => {
                let corners = &tokens[1..];
                if corners.len() < 3 {
                    return Err(syntax(kw_col, format!("a face needs at least 3 corners, found {}", corners.len())));
                }
                for &(col, corner) in corners {
                    let parts: Vec<&str> = corner.split('/').collect();
                    if parts.len() > 3 || parts[0].is_empty() {
                        return Err(syntax(
                            col,
                            format!("{corner:?} is not a face corner (v, v/vt, v//vn or v/vt/vn)"),
                        ));
                    }
                    for (k, (part, count)) in parts.iter().zip([positions, texcoords, normals]).enumerate() {
                        if part.is_empty() && k > 0 {
                            continue;
                        }
                        let what = ["vertex", "texture coordinate", "normal"][k];
                        let index: i64 = part
                            .parse()
                            .map_err(|_| syntax(col, format!("{part:?} in {corner:?} is not a {what} index")))?;
                        let resolved = if index < 0 { count as i64 + index } else { index - 1 };
                        if index == 0 || resolved < 0 || resolved >= count as i64 {
                            return Err(syntax(
                                col,
                                format!("{what} index {index} refers to none of the {count} {what}s defined above"),
                            ));
                        }
                    }
                }
                triangles += corners.len() - 2;
                if triangles > options.max_triangles {
                    return Err(MeshAssetError::TooLarge {
                        path: path.to_path_buf(),
                        what: "triangles",
                        count: triangles,
                        limit: options.max_triangles,
                    });
                }
            }
            "mtllib" => mtllibs.extend(tokens[1..].iter().map(|(_, t)| t.to_string())),
            _ => {}
        }
    }
    Ok(mtllibs)
}

/// A material's texture decoded: PNG bytes to store and whether any texel is see-through.
struct LoadedTexture {
    png: Vec<u8>,
    has_alpha: bool,
}

fn load_texture(mtl: &Path, material: &str, texture: &Path) -> Result<LoadedTexture, MeshAssetError> {
    let missing = |problem: String| MeshAssetError::MissingTexture {
        mtl: mtl.to_path_buf(),
        material: material.to_string(),
        texture: texture.to_path_buf(),
        problem,
    };
    let bytes = crate::input::read_limited(texture, crate::input::MAX_TEXTURE_BYTES, "a texture")
        .map_err(|e| missing(e.into_io().to_string()))?;
    let image = image::load_from_memory(&bytes).map_err(|e| missing(format!("not a PNG or JPEG image: {e}")))?;
    if image.width().max(image.height()) > MAX_TEXTURE_SIDE_PX || image.width() == 0 || image.height() == 0 {
        return Err(missing(format!(
            "{}×{} px; textures must be 1 to {MAX_TEXTURE_SIDE_PX} px a side",
            image.width(),
            image.height()
        )));
    }
    let rgba = image.to_rgba8();
    let has_alpha = rgba.pixels().any(|p| p.0[3] < 255);
    let png = encode_rgba8_png(rgba.as_raw(), rgba.width(), rgba.height()).map_err(missing)?;
    Ok(LoadedTexture { png, has_alpha })
}

/// The texture file `name` (from a `map_Kd` line) names, relative to the MTL folders tried in
/// order; with options before the file name (`-s 1 1 1 bark.png`), the last word. Only paths inside
/// an MTL's folder are read ([`crate::input::resolve_inside`]): an absolute or escaping name is an error.
fn texture_path(name: &str, mtl_dirs: &[PathBuf]) -> Result<PathBuf, String> {
    let candidates: Vec<&str> =
        [name.trim(), name.split_whitespace().last().unwrap_or("")].into_iter().filter(|c| !c.is_empty()).collect();
    for c in &candidates {
        for dir in mtl_dirs {
            if let Ok(p) = crate::input::resolve_inside(dir, c) {
                if p.is_file() {
                    return Ok(p);
                }
            }
        }
    }
    crate::input::resolve_inside(
        &mtl_dirs.first().cloned().unwrap_or_default(),
        candidates.first().copied().unwrap_or(name),
    )
}

/// Angle-weighted vertex normals, accumulated over vertices at the same position so UV seams do
/// not show as shading seams.
fn angle_weighted_normals(p: &Primitive) -> Vec<[f32; 3]> {
    let mut group_of: BTreeMap<[u32; 3], usize> = BTreeMap::new();
    let groups: Vec<usize> = p
        .positions
        .iter()
        .map(|v| {
            let n = group_of.len();
            *group_of.entry(v.map(f32::to_bits)).or_insert(n)
        })
        .collect();
    let mut sums = vec![DVec3::ZERO; group_of.len()];
    let at = |i: u32| DVec3::from(p.positions[i as usize].map(f64::from));
    for t in p.indices.chunks_exact(3) {
        let c = [at(t[0]), at(t[1]), at(t[2])];
        let face = (c[1] - c[0]).cross(c[2] - c[0]).normalize_or_zero();
        for k in 0..3 {
            let (a, b) = ((c[(k + 1) % 3] - c[k]).normalize_or_zero(), (c[(k + 2) % 3] - c[k]).normalize_or_zero());
            let angle = a.dot(b).clamp(-1.0, 1.0).acos();
            sums[groups[t[k] as usize]] += face * angle;
        }
    }
    groups.iter().map(|&g| sums[g].normalize_or(DVec3::Y).as_vec3().normalize_or(glam::Vec3::Y).to_array()).collect()
}

/// Reads `path` (and its MTL and textures) into a [`SourceMesh`].
pub fn load_obj(path: &Path, options: &ObjOptions) -> Result<SourceMesh, MeshAssetError> {
    if !(options.scale.is_finite() && options.scale > 0.0) {
        return Err(MeshAssetError::Options(format!(
            "--scale {} (`scale` in a preset's mesh) must be a positive number (metres per file unit)",
            options.scale
        )));
    }
    let text = crate::input::read_limited(path, crate::input::MAX_OBJ_BYTES, "an OBJ model")
        .map_err(|e| MeshAssetError::Read { path: path.to_path_buf(), problem: e.into_io().to_string() })?;
    let mtllibs = scan(path, &text, options)?;
    let obj_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let load_options = tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() };
    let (loaded, mtl_failed) = crate::input::load_obj_bounded(path, &text, &load_options);
    let (models, materials) =
        loaded.map_err(|e| MeshAssetError::Load { path: path.to_path_buf(), problem: e.to_string() })?;
    let mtl_paths: Vec<PathBuf> = mtllibs.iter().map(|m| obj_dir.join(m)).collect();
    let materials = match materials {
        Ok(m) => m,
        Err(e) if !mtl_paths.is_empty() => {
            let (mtl, problem) = mtl_failed.unwrap_or_else(|| (mtl_paths[0].clone(), e.to_string()));
            return Err(MeshAssetError::MissingMaterialLibrary { obj: path.to_path_buf(), mtl, problem });
        }
        Err(_) => Vec::new(),
    };
    let mtl_dirs: Vec<PathBuf> =
        mtl_paths.iter().map(|m| m.parent().map(Path::to_path_buf).unwrap_or_default()).collect();
    let first_mtl = mtl_paths.first().cloned().unwrap_or_else(|| path.to_path_buf());

    // materials and their textures (each file decoded once)
    let mut scene = Scene { name: file_stem(path), ..Scene::default() };
    let mut texture_ids: BTreeMap<PathBuf, (usize, bool)> = BTreeMap::new();
    for m in &materials {
        let kd = m.diffuse.unwrap_or([1.0, 1.0, 1.0]);
        let d = m.dissolve.unwrap_or(1.0);
        let clamp = |x: f32| if x.is_finite() { x.clamp(0.0, 1.0) } else { 1.0 };
        let mut material = Material {
            name: m.name.clone(),
            base_color: [clamp(kd[0]), clamp(kd[1]), clamp(kd[2]), clamp(d)],
            roughness: 0.9,
            ..Material::default()
        };
        let mut textured_alpha = false;
        if let Some(name) = m.diffuse_texture.as_deref().filter(|n| !n.trim().is_empty()) {
            let file = texture_path(name, &mtl_dirs).map_err(|problem| MeshAssetError::MissingTexture {
                mtl: first_mtl.clone(),
                material: m.name.clone(),
                texture: PathBuf::from(name),
                problem,
            })?;
            let (id, has_alpha) = match texture_ids.get(&file) {
                Some(&v) => v,
                None => {
                    let t = load_texture(&first_mtl, &m.name, &file)?;
                    scene.textures.push(Texture { name: file_stem(&file), png: t.png });
                    let v = (scene.textures.len() - 1, t.has_alpha);
                    texture_ids.insert(file.clone(), v);
                    v
                }
            };
            material.base_color_texture = Some(id);
            textured_alpha = has_alpha;
        }
        if textured_alpha {
            material.alpha_mode = AlphaMode::Mask { cutoff: 0.5 };
            material.double_sided = true;
        } else if material.base_color[3] < 1.0 {
            material.alpha_mode = AlphaMode::Blend;
        }
        scene.materials.push(material);
    }

    // one primitive per material, models in file order
    let mut by_material: BTreeMap<Option<usize>, (Primitive, bool)> = BTreeMap::new();
    for model in &models {
        let m = &model.mesh;
        let n = m.positions.len() / 3;
        if n == 0 || m.indices.is_empty() {
            continue;
        }
        let material = m.material_id.filter(|&i| i < scene.materials.len());
        let (prim, normals_ok) =
            by_material.entry(material).or_insert_with(|| (Primitive { material, ..Primitive::default() }, true));
        let base = prim.positions.len() as u32;
        prim.positions.extend(m.positions.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        let has_normals = m.normals.len() == 3 * n;
        *normals_ok &= has_normals && (base == 0 || !prim.normals.is_empty());
        if has_normals && *normals_ok {
            prim.normals.extend(m.normals.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        }
        let has_uvs = m.texcoords.len() == 2 * n;
        if has_uvs && (base == 0 || !prim.uvs.is_empty()) {
            prim.uvs.extend(m.texcoords.chunks_exact(2).map(|c| [c[0], 1.0 - c[1]]));
        } else {
            prim.uvs.clear();
        }
        prim.indices.extend(m.indices.iter().map(|&i| i + base));
    }
    let total_vertices: usize = by_material.values().map(|(p, _)| p.positions.len()).sum();
    if total_vertices > options.max_vertices {
        return Err(MeshAssetError::TooLarge {
            path: path.to_path_buf(),
            what: "vertices",
            count: total_vertices,
            limit: options.max_vertices,
        });
    }

    // turn, scale, then recentre
    let turn = |v: [f32; 3]| -> DVec3 {
        let v = DVec3::from(v.map(f64::from));
        match options.up_axis {
            UpAxis::Y => v,
            UpAxis::Z => DVec3::new(v.x, v.z, -v.y),
        }
    };
    let mut lo = DVec3::splat(f64::MAX);
    let mut hi = DVec3::splat(f64::MIN);
    for (p, _) in by_material.values() {
        for v in &p.positions {
            let w = turn(*v) * options.scale;
            lo = lo.min(w);
            hi = hi.max(w);
        }
    }
    let offset = if options.recentre && total_vertices > 0 {
        DVec3::new(-(lo.x + hi.x) / 2.0, -lo.y, -(lo.z + hi.z) / 2.0)
    } else {
        DVec3::ZERO
    };
    let mut stats = MeshAssetStats { offset_m: offset.to_array(), ..MeshAssetStats::default() };
    let mut mesh = Mesh { name: scene.name.clone(), primitives: Vec::new(), extras: None };
    for (_, (mut p, normals_ok)) in by_material {
        for v in &mut p.positions {
            *v = (turn(*v) * options.scale + offset).as_vec3().to_array();
        }
        let mut usable = normals_ok && p.normals.len() == p.positions.len();
        if usable {
            for nrm in &mut p.normals {
                let t = turn(*nrm);
                let len = t.length();
                if !(len.is_finite() && len > 1e-6) {
                    usable = false;
                    break;
                }
                *nrm = (t / len).as_vec3().normalize_or(glam::Vec3::Y).to_array();
            }
        }
        // degenerate triangles (zero area after rounding to f32) would fail validation
        let before = p.indices.len() / 3;
        let kept: Vec<u32> = p
            .indices
            .chunks_exact(3)
            .filter(|t| !is_flat(&p.positions, [t[0], t[1], t[2]]))
            .flatten()
            .copied()
            .collect();
        stats.degenerate_triangles_dropped += before - kept.len() / 3;
        p.indices = kept;
        if p.indices.is_empty() {
            continue;
        }
        if !usable {
            p.normals = angle_weighted_normals(&p);
            stats.normals_generated += 1;
        }
        if let Some(material) = p.material.map(|m| &scene.materials[m]) {
            if material.base_color_texture.is_some() && p.uvs.is_empty() {
                let texture = materials
                    .iter()
                    .find(|m| m.name == material.name)
                    .and_then(|m| m.diffuse_texture.clone())
                    .unwrap_or_default();
                return Err(MeshAssetError::NoTexCoords {
                    path: path.to_path_buf(),
                    material: material.name.clone(),
                    texture,
                });
            }
        }
        p.optimize_for_gpu().map_err(|e| MeshAssetError::Read { path: path.to_path_buf(), problem: e.to_string() })?;
        mesh.primitives.push(p);
    }
    if mesh.primitives.is_empty() {
        return Err(MeshAssetError::Empty { path: path.to_path_buf() });
    }
    // faces without a material: the documented grey
    if mesh.primitives.iter().any(|p| p.material.is_none()) {
        scene.materials.push(Material {
            name: "default_grey".into(),
            base_color: FALLBACK_GREY,
            roughness: 0.9,
            ..Material::default()
        });
        let grey = scene.materials.len() - 1;
        for p in mesh.primitives.iter_mut().filter(|p| p.material.is_none()) {
            p.material = Some(grey);
        }
    }
    stats.vertices = mesh.vertex_count();
    stats.triangles = mesh.triangle_count();
    stats.primitives = mesh.primitives.len();
    stats.materials = scene.materials.len();
    stats.textures = scene.textures.len();
    stats.has_uvs = mesh.primitives.iter().all(|p| !p.uvs.is_empty());
    let corners: Vec<[f32; 3]> =
        mesh.primitives.iter().filter_map(|p| p.bounds()).flat_map(|b| [b.min, b.max]).collect();
    stats.bounds = Bounds::of(&corners);
    scene.add_mesh_node(mesh);
    Ok(SourceMesh { scene, stats })
}

fn file_stem(path: &Path) -> String {
    path.file_stem().and_then(|s| s.to_str()).unwrap_or("mesh").to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_normals_of_a_tetrahedron_point_outwards() {
        let p = Primitive {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            indices: vec![0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3],
            ..Primitive::default()
        };
        let n = angle_weighted_normals(&p);
        let centre = DVec3::splat(0.25);
        for (v, nrm) in p.positions.iter().zip(&n) {
            let out = DVec3::from(v.map(f64::from)) - centre;
            assert!(out.dot(DVec3::from(nrm.map(f64::from))) > 0.0, "{v:?} {nrm:?}");
            assert!((DVec3::from(nrm.map(f64::from)).length() - 1.0).abs() < 1e-6);
        }
        // the corner at the origin sees three right angles: its normal is the diagonal's opposite
        let d = DVec3::from(n[0].map(f64::from));
        assert!((d - DVec3::splat(-1.0).normalize()).length() < 1e-6, "{d:?}");
    }
}
