//! `verdant validate`: re-imports written files (glTF with the `gltf` crate, OBJ with `tobj`) and
//! checks the invariants every output promises: indices in range, finite attributes, no degenerate
//! triangles, unit normals, exact POSITION min/max, and (for terrain) triangles facing +Y.
//!
//! Also checks what the Khronos validator cannot: EXT_mesh_gpu_instancing arrays (equal counts,
//! finite values, unit rotations) and MSFT_lod ids. Accessors are decoded by our own bounds-checked
//! reader, so no file, however damaged, makes this panic.

use std::fmt;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use glam::{DMat4, DQuat, DVec3};
use serde_json::Value;
use thiserror::Error;

use crate::export::gltf::{EXT_INSTANCING, EXT_LOD, EXT_MESHOPT, KHR_QUANTIZATION, LOD_COVERAGE_KEY};
use crate::mesh::{AlphaMode, Bounds, Instances, Material, Mesh, Node, Primitive, PrimitiveMode, Scene, Texture};

/// |length − 1| above which a normal is reported.
pub const NORMAL_TOLERANCE: f64 = 1e-3;
/// How many occurrences of one problem in one primitive are listed before a summary line.
const MAX_LISTED: usize = 5;

#[derive(Debug, Clone, Default)]
pub struct ValidateOptions {
    /// Terrain: every triangle must face up (+Y) after its node's world transform.
    pub up_facing: bool,
}

/// The file could not be read or parsed at all (its content problems go in the report instead).
#[derive(Debug, Error)]
pub enum ValidateError {
    #[error("cannot read {path}: {source}; check that the file exists and is readable")]
    Read {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("cannot parse {path}: {problem}; the file is damaged or truncated, export it again")]
    Parse { path: PathBuf, problem: String },
    #[error("cannot validate {path}: unknown extension {ext:?}; verdant reads .glb, .gltf and .obj")]
    Unsupported { path: PathBuf, ext: String },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    Warning,
    Error,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Issue {
    pub severity: Severity,
    /// Where: "mesh 'tree' primitive 1 triangle 17", "node 3 'scatter'", "line 12", …
    pub location: String,
    pub message: String,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PrimitiveReport {
    pub vertices: usize,
    pub triangles: usize,
    /// Points drawn (POINTS primitives, e.g. point leaves).
    pub points: usize,
    pub bounds: Option<Bounds>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct MeshReport {
    pub name: String,
    pub primitives: Vec<PrimitiveReport>,
    /// Bounds in metres as the first (unrotated) node holding the mesh places it, where that node
    /// scales or moves it: a quantized mesh's positions are integers (KHR_mesh_quantization).
    pub placed: Option<Bounds>,
}

impl MeshReport {
    pub fn vertices(&self) -> usize {
        self.primitives.iter().map(|p| p.vertices).sum()
    }
    pub fn triangles(&self) -> usize {
        self.primitives.iter().map(|p| p.triangles).sum()
    }
    pub fn points(&self) -> usize {
        self.primitives.iter().map(|p| p.points).sum()
    }
    pub fn bounds(&self) -> Option<Bounds> {
        let corners: Vec<[f32; 3]> =
            self.primitives.iter().filter_map(|p| p.bounds).flat_map(|b| [b.min, b.max]).collect();
        Bounds::of(&corners)
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct ValidationReport {
    pub path: PathBuf,
    pub meshes: Vec<MeshReport>,
    pub issues: Vec<Issue>,
}

impl ValidationReport {
    /// No error-level issue.
    pub fn ok(&self) -> bool {
        self.errors() == 0
    }
    pub fn errors(&self) -> usize {
        self.issues.iter().filter(|i| i.severity == Severity::Error).count()
    }
    pub fn warnings(&self) -> usize {
        self.issues.iter().filter(|i| i.severity == Severity::Warning).count()
    }
}

impl fmt::Display for ValidationReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v: usize = self.meshes.iter().map(MeshReport::vertices).sum();
        let t: usize = self.meshes.iter().map(MeshReport::triangles).sum();
        writeln!(f, "{}: {} meshes, {v} vertices, {t} triangles", self.path.display(), self.meshes.len())?;
        for m in &self.meshes {
            write!(f, "  mesh {:?}: {} vertices, {} triangles", m.name, m.vertices(), m.triangles())?;
            if m.points() > 0 {
                write!(f, ", {} points", m.points())?;
            }
            match (m.bounds(), m.placed) {
                (Some(b), Some(p)) => writeln!(
                    f,
                    ", bounds {:?} .. {:?} as stored, {:?} .. {:?} as placed by its node",
                    b.min, b.max, p.min, p.max
                )?,
                (Some(b), None) => writeln!(f, ", bounds {:?} .. {:?}", b.min, b.max)?,
                _ => writeln!(f)?,
            }
        }
        for i in &self.issues {
            let sev = match i.severity {
                Severity::Error => "error",
                Severity::Warning => "warning",
            };
            writeln!(f, "  {sev}: {}: {}", i.location, i.message)?;
        }
        if self.ok() {
            write!(f, "ok ({} warnings)", self.warnings())
        } else {
            write!(f, "FAILED: {} errors, {} warnings", self.errors(), self.warnings())
        }
    }
}

/// The mesh's bounds as the first node holding it places them, when that node scales or moves it
/// without rotating.
fn placed_bounds(scene: &Scene, mesh: usize, m: &Mesh) -> Option<Bounds> {
    let node = scene.nodes.iter().find(|n| n.mesh == Some(mesh))?;
    if node.rotation != [0.0, 0.0, 0.0, 1.0] || (node.scale == [1.0; 3] && node.translation == [0.0; 3]) {
        return None;
    }
    let points: Vec<[f32; 3]> = m.primitives.iter().filter_map(|p| p.bounds()).flat_map(|b| [b.min, b.max]).collect();
    let b = Bounds::of(&points)?;
    let place =
        |p: [f32; 3]| [0, 1, 2].map(|a| (node.translation[a] as f64 + node.scale[a] as f64 * p[a] as f64) as f32);
    Bounds::of(&[place(b.min), place(b.max)])
}

/// Validates one `.glb`, `.gltf` or `.obj` file.
pub fn validate_file(path: &Path, opts: &ValidateOptions) -> Result<ValidationReport, ValidateError> {
    let loaded = load(path)?;
    let mut issues = loaded.issues;
    check_scene_data(&loaded.scene, &loaded.declared_bounds, opts, &mut issues);
    let meshes = loaded
        .scene
        .meshes
        .iter()
        .enumerate()
        .map(|(mi, m)| MeshReport {
            placed: placed_bounds(&loaded.scene, mi, m),
            name: m.name.clone(),
            primitives: m
                .primitives
                .iter()
                .map(|p| PrimitiveReport {
                    vertices: p.positions.len(),
                    triangles: p.triangle_count(),
                    points: p.point_count(),
                    bounds: p.bounds(),
                })
                .collect(),
        })
        .collect();
    Ok(ValidationReport { path: path.to_path_buf(), meshes, issues })
}

/// Re-imports a `.glb`/`.gltf` (exactly) or `.obj` (best effort: one root node per object, no
/// hierarchy, welded vertices, materials from the MTL) into the in-memory [`Scene`].
/// A file whose content cannot be represented (a missing POSITION, a damaged accessor) is an error.
pub fn read_scene(path: &Path) -> Result<Scene, ValidateError> {
    let loaded = load(path)?;
    if let Some(i) = loaded.issues.iter().find(|i| i.severity == Severity::Error) {
        return Err(ValidateError::Parse {
            path: path.to_path_buf(),
            problem: format!("{}: {}", i.location, i.message),
        });
    }
    Ok(loaded.scene)
}

/// A file turned into a [`Scene`], with the problems met on the way and, for glTF, the declared
/// POSITION min/max of every primitive (`declared_bounds[mesh][primitive]`).
struct Loaded {
    scene: Scene,
    issues: Vec<Issue>,
    declared_bounds: Vec<Vec<Option<Bounds>>>,
}

fn load(path: &Path) -> Result<Loaded, ValidateError> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    // the glTF crates index arrays a damaged file may not have (gltf-json's mesh hook, the image
    // source): the checks in `gltf_json_problems` come first; a panic that still escapes them is
    // the last resort, turned into a parse error naming the file instead of ending the process
    let guarded = |f: fn(&Path) -> Result<Loaded, ValidateError>| {
        std::panic::catch_unwind(|| f(path)).unwrap_or_else(|panic| {
            let what =
                panic.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| panic.downcast_ref::<String>().cloned());
            Err(ValidateError::Parse {
                path: path.to_path_buf(),
                problem: format!("a glTF/OBJ library failed on it ({})", what.unwrap_or_else(|| "no message".into())),
            })
        })
    };
    match ext.as_str() {
        "glb" | "gltf" => guarded(load_gltf),
        "obj" => guarded(load_obj),
        _ => Err(ValidateError::Unsupported { path: path.to_path_buf(), ext }),
    }
}

/// References gltf-json's validation or the gltf crate follow without a bounds check: every
/// primitive's attribute and morph-target accessors (gltf-json 1.4.1 mesh.rs:151 indexes the
/// POSITION accessor before validating it) and each image's source (gltf 1.4.1 image.rs:125–128
/// unwraps `mimeType` for a bufferView image and `uri` when there is no bufferView). Checked on
/// the JSON before either crate looks at them; each problem is "json path: what is wrong".
fn gltf_json_problems(root: &gltf::json::Root) -> Vec<String> {
    let mut problems = Vec::new();
    let accessors = root.accessors.len();
    for (mi, mesh) in root.meshes.iter().enumerate() {
        for (pi, prim) in mesh.primitives.iter().enumerate() {
            let at = format!("meshes[{mi}].primitives[{pi}]");
            for (semantic, index) in &prim.attributes {
                if index.value() >= accessors {
                    let name = match semantic {
                        gltf::json::validation::Checked::Valid(s) => s.to_string(),
                        gltf::json::validation::Checked::Invalid => "?".into(),
                    };
                    problems.push(format!(
                        "{at}.attributes.{name}: accessor {} does not exist ({accessors} accessors)",
                        index.value()
                    ));
                }
            }
            for (ti, target) in prim.targets.iter().flatten().enumerate() {
                for (name, index) in
                    [("POSITION", &target.positions), ("NORMAL", &target.normals), ("TANGENT", &target.tangents)]
                {
                    if let Some(index) = (*index).filter(|i| i.value() >= accessors) {
                        problems.push(format!(
                            "{at}.targets[{ti}].{name}: accessor {} does not exist ({accessors} accessors)",
                            index.value()
                        ));
                    }
                }
            }
        }
    }
    for (ii, image) in root.images.iter().enumerate() {
        match (&image.buffer_view, &image.uri) {
            (Some(_), Some(_)) => {
                problems.push(format!("images[{ii}]: both a uri and a bufferView; an image has exactly one"))
            }
            (Some(_), None) if image.mime_type.is_none() => problems
                .push(format!("images[{ii}]: an image in a bufferView needs a mimeType (image/png or image/jpeg)")),
            (None, None) => problems.push(format!("images[{ii}]: neither a uri nor a bufferView")),
            _ => {}
        }
    }
    problems
}

fn issue(severity: Severity, location: impl Into<String>, message: impl Into<String>) -> Issue {
    Issue { severity, location: location.into(), message: message.into() }
}

// ---------------------------------------------------------------------------------------------
// glTF

fn load_gltf(path: &Path) -> Result<Loaded, ValidateError> {
    let parse = |problem: String| ValidateError::Parse { path: path.to_path_buf(), problem };
    let bytes = crate::input::read_limited(path, crate::input::MAX_GLTF_BYTES, "a glTF file")
        .map_err(|e| ValidateError::Read { path: path.to_path_buf(), source: e.into_io() })?;
    // a GLB's header states the file's length (the Khronos validator's GLB_LENGTH_MISMATCH)
    if bytes.starts_with(b"glTF") && bytes.len() >= 12 {
        let declared = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize;
        if declared != bytes.len() {
            return Err(parse(format!(
                "the GLB header says the file is {declared} bytes, it is {} (truncated or padded?)",
                bytes.len()
            )));
        }
    }
    // the gltf crate refuses required extensions it does not implement; the ones verdant writes
    // (EXT_mesh_gpu_instancing) are checked here instead, so validate with that one exception
    let gltf = gltf::Gltf::from_slice_without_validation(&bytes).map_err(|e| parse(format!("not valid glTF: {e}")))?;
    {
        use gltf::json::validation::{Error as JsonError, Validate};
        let root = gltf.document.as_json();
        let problems = gltf_json_problems(root);
        if !problems.is_empty() {
            return Err(parse(format!("not valid glTF: {}", problems.join("; "))));
        }
        let mut problems = Vec::new();
        root.validate(root, gltf::json::Path::new, &mut |path, error| {
            let at = path().to_string();
            let ours = matches!(error, JsonError::Unsupported)
                && at.starts_with("extensionsRequired")
                && [EXT_INSTANCING, KHR_QUANTIZATION, EXT_MESHOPT]
                    .iter()
                    .any(|ext| root.extensions_required.iter().any(|e| e == ext) && at.contains(ext));
            if !ours {
                problems.push(format!("{at}: {error}"));
            }
        });
        if !problems.is_empty() {
            return Err(parse(format!("not valid glTF: {}", problems.join("; "))));
        }
    }
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let doc = gltf.document;
    // buffer files: inside the file's folder, regular files within the size limit, named when
    // missing (checked before the gltf crate reads them)
    for buffer in doc.buffers() {
        if let gltf::buffer::Source::Uri(uri) = buffer.source() {
            if uri.starts_with("data:") {
                continue;
            }
            let checked = crate::input::resolve_inside(base, uri).and_then(|file| {
                let meta = fs::metadata(&file).map_err(|e| format!("{}: {e}", file.display()))?;
                if !meta.is_file() {
                    return Err(format!("{} is not a regular file", file.display()));
                }
                if meta.len() > crate::input::MAX_GLTF_BYTES {
                    return Err(format!(
                        "{}: {} bytes, more than the {}-byte limit for a glTF buffer",
                        file.display(),
                        meta.len(),
                        crate::input::MAX_GLTF_BYTES
                    ));
                }
                if (meta.len() as usize) < buffer.length() {
                    return Err(format!(
                        "{}: {} bytes, the buffer declares byteLength {}",
                        file.display(),
                        meta.len(),
                        buffer.length()
                    ));
                }
                Ok(())
            });
            if let Err(e) = checked {
                return Err(parse(format!("buffer {} (uri `{}`): {e}", buffer.index(), crate::input::escape(uri))));
            }
        }
    }
    let buffers: Vec<Vec<u8>> = if doc.extensions_used().any(|e| e == EXT_MESHOPT) {
        meshopt_buffers(&doc, base, gltf.blob).map_err(parse)?
    } else {
        gltf::import_buffers(&doc, Some(base), gltf.blob)
            .map_err(|e| parse(format!("cannot load its buffers: {e}")))?
            .into_iter()
            .map(|b| b.0)
            .collect()
    };
    let buffers: Vec<&[u8]> = buffers.iter().map(|b| &b[..]).collect();
    let mut issues = node_graph_issues(&doc);
    let mut scene = Scene::default();
    let mut declared_bounds = Vec::new();

    // KHR_mesh_quantization must be required where positions are not float (a reader without it
    // would misread them)
    let quantization_used = doc.extensions_required().any(|e| e == KHR_QUANTIZATION);
    for mesh in doc.meshes() {
        let mesh_name = mesh.name().unwrap_or("").to_string();
        let mut out = Mesh { name: mesh_name.clone(), primitives: Vec::new(), extras: parse_extras(mesh.extras()) };
        let mut declared = Vec::new();
        for (pi, prim) in mesh.primitives().enumerate() {
            let loc = format!("mesh {} {:?} primitive {pi}", mesh.index(), mesh_name);
            let (p, bounds) = read_primitive(&prim, &buffers, &loc, quantization_used, &mut issues);
            out.primitives.push(p);
            declared.push(bounds);
        }
        scene.meshes.push(out);
        declared_bounds.push(declared);
    }

    for m in doc.materials() {
        let pbr = m.pbr_metallic_roughness();
        let alpha_mode = match m.alpha_mode() {
            gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
            gltf::material::AlphaMode::Mask => AlphaMode::Mask { cutoff: m.alpha_cutoff().unwrap_or(0.5) },
            gltf::material::AlphaMode::Blend => AlphaMode::Blend,
        };
        scene.materials.push(Material {
            name: m.name().unwrap_or("").to_string(),
            base_color: pbr.base_color_factor(),
            base_color_texture: pbr.base_color_texture().map(|i| i.texture().index()),
            normal_texture: m.normal_texture().map(|n| n.texture().index()),
            metallic: pbr.metallic_factor(),
            roughness: pbr.roughness_factor(),
            alpha_mode,
            double_sided: m.double_sided(),
        });
    }

    for t in doc.textures() {
        let image = t.source();
        let loc = format!("texture {} image {}", t.index(), image.index());
        let png = match image.source() {
            gltf::image::Source::View { view, .. } => match view_bytes(&view, &buffers) {
                Ok(b) => b.to_vec(),
                Err(e) => {
                    issues.push(issue(Severity::Error, &loc, e));
                    Vec::new()
                }
            },
            gltf::image::Source::Uri { uri, .. } => {
                if uri.starts_with("data:") {
                    issues.push(issue(Severity::Warning, &loc, "data: URI images are not checked"));
                    Vec::new()
                } else {
                    match crate::input::resolve_inside(base, uri).and_then(|file| {
                        crate::input::read_limited(&file, crate::input::MAX_TEXTURE_BYTES, "an image")
                            .map_err(|e| e.to_string())
                    }) {
                        Ok(bytes) => bytes,
                        Err(e) => {
                            issues.push(issue(Severity::Error, &loc, format!("image URI: {e}")));
                            Vec::new()
                        }
                    }
                }
            }
        };
        if !png.is_empty() && !png.starts_with(b"\x89PNG\r\n\x1a\n") && !png.starts_with(&[0xff, 0xd8, 0xff]) {
            issues.push(issue(Severity::Error, &loc, "image data is neither PNG nor JPEG"));
        }
        let name = t.name().or(image.name()).unwrap_or("").to_string();
        scene.textures.push(Texture { name, png });
    }

    for node in doc.nodes() {
        let loc = format!("node {} {:?}", node.index(), node.name().unwrap_or(""));
        let (translation, rotation, scale) = node.transform().decomposed();
        let mut out = Node {
            name: node.name().unwrap_or("").to_string(),
            mesh: node.mesh().map(|m| m.index()),
            translation,
            rotation,
            scale,
            children: node.children().map(|c| c.index()).collect(),
            extras: parse_extras(node.extras()),
            ..Node::default()
        };
        if let Some(ext) = node.extension_value(EXT_INSTANCING) {
            out.instances = Some(read_instances(ext, &doc, &buffers, &loc, &mut issues));
            if node.mesh().is_none() {
                issues.push(issue(Severity::Error, &loc, format!("{EXT_INSTANCING} on a node without a mesh")));
            }
        }
        if let Some(ext) = node.extension_value(EXT_LOD) {
            match ext.get("ids").and_then(Value::as_array) {
                Some(ids) => {
                    for id in ids {
                        match id.as_u64().map(|i| i as usize).filter(|&i| i < doc.nodes().len() && i != node.index()) {
                            Some(i) => out.lods.push(i),
                            None => issues.push(issue(
                                Severity::Error,
                                &loc,
                                format!("{EXT_LOD} id {id} is not another node"),
                            )),
                        }
                    }
                }
                None => issues.push(issue(Severity::Error, &loc, format!("{EXT_LOD} without an \"ids\" array"))),
            }
            // the coverage lives in extras; take it out so extras round-trip as written
            if let Some(Value::Object(map)) = &mut out.extras {
                if let Some(cov) = map.remove(LOD_COVERAGE_KEY) {
                    match cov
                        .as_array()
                        .map(|a| a.iter().map(|c| c.as_f64().map(|c| c as f32)).collect::<Option<Vec<_>>>())
                    {
                        Some(Some(c)) => out.lod_screen_coverage = c,
                        _ => issues.push(issue(
                            Severity::Error,
                            &loc,
                            format!("{LOD_COVERAGE_KEY} is not an array of numbers"),
                        )),
                    }
                    if map.is_empty() {
                        out.extras = None;
                    }
                }
            }
        }
        scene.nodes.push(out);
    }

    if let Some(s) = doc.default_scene().or_else(|| doc.scenes().next()) {
        scene.name = s.name().unwrap_or("").to_string();
        scene.roots = s.nodes().map(|n| n.index()).collect();
        scene.extras = parse_extras(s.extras());
    }
    Ok(Loaded { scene, issues, declared_bounds })
}

fn parse_extras(raw: &gltf::json::Extras) -> Option<Value> {
    raw.as_ref().and_then(|r| serde_json::from_str(r.get()).ok())
}

/// Reads one triangle primitive; problems that stop an attribute from being read become issues.
fn read_primitive(
    prim: &gltf::Primitive,
    buffers: &[&[u8]],
    loc: &str,
    quantization_used: bool,
    issues: &mut Vec<Issue>,
) -> (Primitive, Option<Bounds>) {
    use gltf::Semantic;
    let mut p = Primitive { material: prim.material().index(), ..Primitive::default() };
    match prim.mode() {
        gltf::mesh::Mode::Triangles => {}
        gltf::mesh::Mode::Points => p.mode = PrimitiveMode::Points,
        mode => {
            issues.push(issue(
                Severity::Warning,
                loc,
                format!("mode {mode:?} is not checked (only triangle lists and points are)"),
            ));
            return (p, None);
        }
    }
    let mut declared = None;
    let read = |issues: &mut Vec<Issue>,
                sem: &str,
                acc: Option<gltf::Accessor>,
                dims: &[usize]|
     -> Option<(usize, Vec<f32>)> {
        let acc = acc?;
        match read_floats(&acc, buffers) {
            Ok((d, v)) if dims.contains(&d) => Some((d, v)),
            Ok((d, _)) => {
                issues.push(issue(Severity::Error, loc, format!("{sem} has {d} components per element")));
                None
            }
            Err(e) => {
                issues.push(issue(Severity::Error, loc, format!("{sem}: {e}")));
                None
            }
        }
    };
    match prim.get(&Semantic::Positions) {
        None => issues.push(issue(Severity::Error, loc, "no POSITION attribute")),
        Some(acc) => {
            // KHR_mesh_quantization allows (normalized) byte and short positions too
            use gltf::accessor::DataType;
            let quantized = matches!(acc.data_type(), DataType::U8 | DataType::I8 | DataType::U16 | DataType::I16);
            if acc.data_type() != DataType::F32 && !(quantized && quantization_used) {
                issues.push(issue(
                    Severity::Error,
                    loc,
                    if quantized {
                        "POSITION is not FLOAT and the file does not use KHR_mesh_quantization"
                    } else {
                        "POSITION is not FLOAT"
                    },
                ));
            }
            let bound = |v: Option<Value>| -> Option<[f32; 3]> {
                let a = v?.as_array()?.iter().map(|x| x.as_f64().map(|x| x as f32)).collect::<Option<Vec<f32>>>()?;
                a.try_into().ok()
            };
            match (bound(acc.min()), bound(acc.max())) {
                (Some(min), Some(max)) => declared = Some(Bounds { min, max }),
                _ => issues.push(issue(
                    Severity::Error,
                    loc,
                    "POSITION accessor lacks a 3-number min/max (glTF requires it)",
                )),
            }
            if let Some((_, v)) = read(issues, "POSITION", Some(acc), &[3]) {
                p.positions = v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
            }
        }
    }
    if let Some((_, v)) = read(issues, "NORMAL", prim.get(&Semantic::Normals), &[3]) {
        p.normals = v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    }
    if let Some((_, v)) = read(issues, "TEXCOORD_0", prim.get(&Semantic::TexCoords(0)), &[2]) {
        p.uvs = v.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
    }
    if let Some((_, v)) = read(issues, "TANGENT", prim.get(&Semantic::Tangents), &[4]) {
        p.tangents = v.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
    }
    if let Some((d, v)) = read(issues, "COLOR_0", prim.get(&Semantic::Colors(0)), &[3, 4]) {
        p.colors = v.chunks_exact(d).map(|c| [c[0], c[1], c[2], if d == 4 { c[3] } else { 1.0 }]).collect();
    }
    for (sem, acc) in prim.attributes() {
        if let Semantic::Extras(name) = sem {
            let name = format!("_{name}");
            if let Some((_, v)) = read(issues, &name, Some(acc), &[4]) {
                let values = v.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
                p.custom.push(crate::mesh::CustomAttribute { name, values });
            }
        }
    }
    match prim.indices() {
        Some(acc) => match read_indices(&acc, buffers) {
            Ok(i) => p.indices = i,
            Err(e) => issues.push(issue(Severity::Error, loc, format!("indices: {e}"))),
        },
        // non-indexed points: every vertex is one (kept without indices, as written)
        None if p.mode == PrimitiveMode::Points => {}
        // non-indexed triangles: every three vertices are a triangle
        None => p.indices = (0..p.positions.len() as u32).collect(),
    }
    let custom = p.custom.iter().map(|c| (c.name.as_str(), c.values.len()));
    for (name, len) in [
        ("NORMAL", p.normals.len()),
        ("TEXCOORD_0", p.uvs.len()),
        ("TANGENT", p.tangents.len()),
        ("COLOR_0", p.colors.len()),
    ]
    .into_iter()
    .chain(custom)
    {
        if len != 0 && len != p.positions.len() {
            issues.push(issue(
                Severity::Error,
                loc,
                format!("{name} has {len} elements for {} positions", p.positions.len()),
            ));
        }
    }
    (p, declared)
}

fn read_instances(
    ext: &Value,
    doc: &gltf::Document,
    buffers: &[&[u8]],
    loc: &str,
    issues: &mut Vec<Issue>,
) -> Instances {
    let mut inst = Instances::default();
    let attrs = ext.get("attributes").and_then(Value::as_object);
    let mut get = |name: &str, dims: usize| -> Vec<f32> {
        let Some(index) = attrs.and_then(|a| a.get(name)) else { return Vec::new() };
        let acc = index.as_u64().and_then(|i| doc.accessors().nth(i as usize));
        match acc.map(|a| read_floats(&a, buffers)) {
            Some(Ok((d, v))) if d == dims => v,
            Some(Ok((d, _))) => {
                issues.push(issue(
                    Severity::Error,
                    loc,
                    format!("instance {name} has {d} components, expected {dims}"),
                ));
                Vec::new()
            }
            Some(Err(e)) => {
                issues.push(issue(Severity::Error, loc, format!("instance {name}: {e}")));
                Vec::new()
            }
            None => {
                issues.push(issue(Severity::Error, loc, format!("instance {name} accessor {index} does not exist")));
                Vec::new()
            }
        }
    };
    inst.translations = get("TRANSLATION", 3).chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    inst.rotations = get("ROTATION", 4).chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
    inst.scales = get("SCALE", 3).chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    inst
}

/// The bytes of a bufferView, bounds-checked.
fn view_bytes<'b>(view: &gltf::buffer::View, buffers: &[&'b [u8]]) -> Result<&'b [u8], String> {
    let buffer = buffers.get(view.buffer().index()).ok_or("bufferView names a missing buffer")?;
    let end = view.offset().checked_add(view.length()).ok_or("bufferView range overflows")?;
    buffer.get(view.offset()..end).ok_or_else(|| {
        format!("bufferView {} ends at byte {end}, past its buffer's {} bytes", view.index(), buffer.len())
    })
}

/// The buffers of a file using EXT_meshopt_compression: the GLB chunk or `.bin` files as stored,
/// each fallback buffer (no data of its own) filled by decoding every compressed bufferView into
/// its range with meshoptimizer's decoders, so accessors then read the views as if uncompressed.
fn meshopt_buffers(doc: &gltf::Document, base: &Path, blob: Option<Vec<u8>>) -> Result<Vec<Vec<u8>>, String> {
    let mut blob = blob;
    let mut buffers = Vec::new();
    // a fallback buffer is allocated only as far as its views reach (its byteLength is the file's word)
    let mut reach = vec![0usize; doc.buffers().len()];
    for view in doc.views() {
        let end =
            view.offset().checked_add(view.length()).ok_or(format!("bufferView {} range overflows", view.index()))?;
        if let Some(r) = reach.get_mut(view.buffer().index()) {
            *r = (*r).max(end);
        }
    }
    for buffer in doc.buffers() {
        let at = format!("buffer {}", buffer.index());
        let fallback =
            buffer.extension_value(EXT_MESHOPT).and_then(|e| e.get("fallback")).and_then(Value::as_bool) == Some(true);
        let data = match buffer.source() {
            _ if fallback => {
                let len = buffer.length().min(reach[buffer.index()]);
                if len as u64 > crate::input::MAX_GLTF_BYTES {
                    return Err(format!(
                        "{at}: a fallback buffer of {len} bytes, over the {}-byte limit",
                        crate::input::MAX_GLTF_BYTES
                    ));
                }
                vec![0; len]
            }
            gltf::buffer::Source::Bin => {
                blob.take().ok_or(format!("{at}: refers to the GLB binary chunk, which is missing or taken"))?
            }
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                return Err(format!("{at}: data: URIs beside {EXT_MESHOPT} are not read by verdant"))
            }
            gltf::buffer::Source::Uri(uri) => crate::input::resolve_inside(base, uri)
                .and_then(|f| {
                    crate::input::read_limited(&f, crate::input::MAX_GLTF_BYTES, "a glTF buffer")
                        .map_err(|e| e.to_string())
                })
                .map_err(|e| format!("{at}: {e}"))?,
        };
        if data.len() < buffer.length() && !fallback {
            return Err(format!("{at}: {} bytes, the buffer declares byteLength {}", data.len(), buffer.length()));
        }
        buffers.push(data);
    }
    for view in doc.views() {
        let Some(ext) = view.extension_value(EXT_MESHOPT) else { continue };
        let at = format!("bufferView {} {EXT_MESHOPT}", view.index());
        let field = |k: &str| ext.get(k).and_then(Value::as_u64).map(|v| v as usize).ok_or(format!("{at}: no {k}"));
        let (source, offset, length, stride, count) = (
            field("buffer")?,
            field("byteOffset").unwrap_or(0),
            field("byteLength")?,
            field("byteStride")?,
            field("count")?,
        );
        // what the decoders would write must be the view, exactly: meshoptimizer's C code asserts
        // on some of these (a triangle list whose count is not a multiple of 3) and allocates count
        // elements
        let mode = ext.get("mode").and_then(Value::as_str);
        let shape_ok = match mode {
            Some("ATTRIBUTES") => stride.is_multiple_of(4) && (4..=16).contains(&stride),
            Some("TRIANGLES") => (stride == 2 || stride == 4) && count.is_multiple_of(3),
            _ => false,
        };
        if !shape_ok {
            return Err(format!("{at}: mode {mode:?} with byteStride {stride} and count {count} is not one verdant reads (ATTRIBUTES of 4–16-byte elements, or TRIANGLES of 2- or 4-byte indices, a multiple of 3)"));
        }
        if count.checked_mul(stride) != Some(view.length()) {
            return Err(format!(
                "{at}: count {count} × byteStride {stride} is not the view's byteLength {}",
                view.length()
            ));
        }
        if ext.get("filter").and_then(Value::as_str).is_some_and(|f| f != "NONE") {
            return Err(format!("{at}: filters are not read by verdant (it writes none)"));
        }
        let encoded = buffers
            .get(source)
            .and_then(|b| b.get(offset..offset.checked_add(length)?))
            .ok_or(format!("{at}: bytes {offset}..+{length} are not in buffer {source}"))?
            .to_vec();
        let fail = |e: meshopt::Error| format!("{at}: cannot decode: {e}");
        let decoded: Vec<u8> = match (mode, stride) {
            (Some("ATTRIBUTES"), 4) => decode_elements::<4>(&encoded, count).map_err(fail)?,
            (Some("ATTRIBUTES"), 8) => decode_elements::<8>(&encoded, count).map_err(fail)?,
            (Some("ATTRIBUTES"), 12) => decode_elements::<12>(&encoded, count).map_err(fail)?,
            (Some("ATTRIBUTES"), 16) => decode_elements::<16>(&encoded, count).map_err(fail)?,
            (Some("TRIANGLES"), 2) => meshopt::decode_index_buffer::<u16>(&encoded, count)
                .map_err(fail)?
                .iter()
                .flat_map(|i| i.to_le_bytes())
                .collect(),
            (Some("TRIANGLES"), 4) => meshopt::decode_index_buffer::<u32>(&encoded, count)
                .map_err(fail)?
                .iter()
                .flat_map(|i| i.to_le_bytes())
                .collect(),
            (mode, _) => return Err(format!("{at}: mode {mode:?} with byteStride {stride} is not read by verdant")),
        };
        let target = view.buffer().index();
        let range = view.offset()..view.offset() + view.length();
        let dest = buffers
            .get_mut(target)
            .and_then(|b| b.get_mut(range))
            .ok_or(format!("{at}: the view lies outside buffer {target}"))?;
        if decoded.len() != dest.len() {
            return Err(format!("{at}: decoded {} bytes for a {}-byte view", decoded.len(), dest.len()));
        }
        dest.copy_from_slice(&decoded);
    }
    Ok(buffers)
}

/// Decodes `count` elements of N = 4·K bytes (as K native words, so the bytes come back as they
/// were encoded).
fn decode_elements<const N: usize>(encoded: &[u8], count: usize) -> Result<Vec<u8>, meshopt::Error> {
    fn words<const K: usize>(encoded: &[u8], count: usize) -> Result<Vec<u8>, meshopt::Error>
    where
        [u32; K]: Default,
    {
        Ok(meshopt::decode_vertex_buffer::<[u32; K]>(encoded, count)?
            .into_iter()
            .flatten()
            .flat_map(u32::to_ne_bytes)
            .collect())
    }
    match N {
        4 => words::<1>(encoded, count),
        8 => words::<2>(encoded, count),
        12 => words::<3>(encoded, count),
        _ => words::<4>(encoded, count),
    }
}

/// Elements of an accessor as byte slices (each `size` bytes long).
fn accessor_elements<'b>(acc: &gltf::Accessor, buffers: &[&'b [u8]]) -> Result<Vec<&'b [u8]>, String> {
    if acc.sparse().is_some() {
        return Err("sparse accessors are not supported by verdant".into());
    }
    let size = acc.size();
    let count = acc.count();
    let Some(view) = acc.view() else {
        return Err("accessor has no bufferView (all zeros); verdant does not write such files".into());
    };
    let data = view_bytes(&view, buffers)?;
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!("byteStride {stride} is smaller than an element ({size} bytes)"));
    }
    if count == 0 {
        return Ok(Vec::new());
    }
    let end = (count - 1)
        .checked_mul(stride)
        .and_then(|x| x.checked_add(size))
        .and_then(|x| x.checked_add(acc.offset()))
        .ok_or("accessor range overflows")?;
    if end > data.len() {
        return Err(format!("accessor {} needs {end} bytes of a {}-byte bufferView", acc.index(), data.len()));
    }
    Ok((0..count).map(|i| &data[acc.offset() + i * stride..acc.offset() + i * stride + size]).collect())
}

/// Decodes a float or (normalized) integer accessor into f32 values; returns components per element.
fn read_floats(acc: &gltf::Accessor, buffers: &[&[u8]]) -> Result<(usize, Vec<f32>), String> {
    use gltf::accessor::DataType;
    let dims = acc.dimensions().multiplicity();
    let comp = acc.data_type().size();
    let norm = acc.normalized();
    let ty = acc.data_type();
    let mut out = Vec::with_capacity(acc.count().saturating_mul(dims).min(1 << 24));
    for e in accessor_elements(acc, buffers)? {
        for c in e.chunks_exact(comp).take(dims) {
            let v = match ty {
                DataType::F32 => f32::from_le_bytes([c[0], c[1], c[2], c[3]]),
                DataType::U32 => u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f32,
                DataType::U8 if norm => c[0] as f32 / 255.0,
                DataType::U8 => c[0] as f32,
                DataType::I8 if norm => (c[0] as i8 as f32 / 127.0).max(-1.0),
                DataType::I8 => c[0] as i8 as f32,
                DataType::U16 if norm => u16::from_le_bytes([c[0], c[1]]) as f32 / 65535.0,
                DataType::U16 => u16::from_le_bytes([c[0], c[1]]) as f32,
                DataType::I16 if norm => (i16::from_le_bytes([c[0], c[1]]) as f32 / 32767.0).max(-1.0),
                DataType::I16 => i16::from_le_bytes([c[0], c[1]]) as f32,
            };
            out.push(v);
        }
    }
    Ok((dims, out))
}

fn read_indices(acc: &gltf::Accessor, buffers: &[&[u8]]) -> Result<Vec<u32>, String> {
    use gltf::accessor::{DataType, Dimensions};
    if acc.dimensions() != Dimensions::Scalar {
        return Err("index accessor is not SCALAR".into());
    }
    let elements = accessor_elements(acc, buffers)?;
    match acc.data_type() {
        DataType::U8 => Ok(elements.iter().map(|e| e[0] as u32).collect()),
        DataType::U16 => Ok(elements.iter().map(|e| u16::from_le_bytes([e[0], e[1]]) as u32).collect()),
        DataType::U32 => Ok(elements.iter().map(|e| u32::from_le_bytes([e[0], e[1], e[2], e[3]])).collect()),
        t => Err(format!("index component type {t:?} is not an unsigned integer")),
    }
}

/// The node hierarchy must be a forest (glTF 2.0 §3.5.3): no node is its own ancestor and no
/// node has two parents; otherwise a viewer walking it loops or draws a node twice.
fn node_graph_issues(doc: &gltf::Document) -> Vec<Issue> {
    let n = doc.nodes().len();
    let mut parent: Vec<Option<usize>> = vec![None; n];
    let mut issues = Vec::new();
    for node in doc.nodes() {
        for child in node.children() {
            let c = child.index();
            if let Some(p) = parent[c] {
                issues.push(issue(
                    Severity::Error,
                    format!("node {c}"),
                    format!("has two parents, nodes {p} and {}", node.index()),
                ));
            } else {
                parent[c] = Some(node.index());
            }
        }
    }
    for start in 0..n {
        // walk up from every node: more than n steps means a cycle
        let (mut at, mut steps) = (start, 0);
        while let Some(p) = parent[at] {
            at = p;
            steps += 1;
            if steps > n {
                issues.push(issue(
                    Severity::Error,
                    format!("node {start}"),
                    "is its own ancestor: the node hierarchy has a cycle",
                ));
                return issues;
            }
        }
    }
    issues
}

// ---------------------------------------------------------------------------------------------
// OBJ

fn load_obj(path: &Path) -> Result<Loaded, ValidateError> {
    let text = crate::input::read_limited(path, crate::input::MAX_OBJ_BYTES, "an OBJ model")
        .map_err(|e| ValidateError::Read { path: path.to_path_buf(), source: e.into_io() })?;
    // tobj rejects out-of-range faces without saying where; find them ourselves, with line numbers
    let issues = scan_obj_faces(&String::from_utf8_lossy(&text));
    if !issues.is_empty() {
        return Ok(Loaded { scene: Scene::default(), issues, declared_bounds: Vec::new() });
    }
    let opts = tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() };
    let (models, materials) = crate::input::load_obj_bounded(path, &text, &opts)
        .0
        .map_err(|e| ValidateError::Parse { path: path.to_path_buf(), problem: format!("not valid OBJ: {e}") })?;
    let mut issues = Vec::new();
    let mut scene = Scene::default();
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    match materials {
        Ok(mats) => {
            for m in mats {
                let [r, g, b] = m.diffuse.unwrap_or([1.0; 3]);
                let param = |k: &str| m.unknown_param.get(k).and_then(|v| v.trim().parse::<f32>().ok());
                let mut mat = Material {
                    name: m.name.clone(),
                    base_color: [r, g, b, m.dissolve.unwrap_or(1.0)],
                    metallic: param("Pm").unwrap_or(0.0),
                    roughness: param("Pr").unwrap_or(1.0),
                    ..Material::default()
                };
                if let Some(tex) = &m.diffuse_texture {
                    let read = crate::input::resolve_inside(base, tex).and_then(|file| {
                        crate::input::read_limited(&file, crate::input::MAX_TEXTURE_BYTES, "a texture")
                            .map_err(|e| e.to_string())
                    });
                    match read {
                        Ok(png) => {
                            let name = Path::new(tex).file_stem().and_then(|s| s.to_str()).unwrap_or("").to_string();
                            scene.textures.push(Texture { name, png });
                            mat.base_color_texture = Some(scene.textures.len() - 1);
                        }
                        Err(e) => issues.push(issue(
                            Severity::Warning,
                            format!("material {:?}", m.name),
                            format!("cannot read texture: {e}"),
                        )),
                    }
                }
                scene.materials.push(mat);
            }
        }
        Err(e) => issues.push(issue(Severity::Warning, "mtllib", format!("materials not loaded: {e}"))),
    }
    for model in models {
        let m = &model.mesh;
        if m.positions.is_empty() && m.indices.is_empty() {
            continue; // tobj's placeholder for a file without faces
        }
        let n = m.positions.len() / 3;
        let prim = Primitive {
            positions: m.positions.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
            normals: m.normals.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
            // OBJ's v runs up from the image's bottom, glTF's down from its top
            uvs: m.texcoords.chunks_exact(2).map(|c| [c[0], 1.0 - c[1]]).collect(),
            colors: if m.vertex_color.len() == 3 * n {
                m.vertex_color.chunks_exact(3).map(|c| [c[0], c[1], c[2], 1.0]).collect()
            } else {
                Vec::new()
            },
            indices: m.indices.clone(),
            material: m.material_id.filter(|&i| i < scene.materials.len()),
            ..Primitive::default()
        };
        // consecutive models with one name are one object split by `usemtl`
        let same = scene.meshes.last().is_some_and(|last| last.name == model.name);
        if same {
            if let Some(last) = scene.meshes.last_mut() {
                last.primitives.push(prim);
            }
        } else {
            scene.add_mesh_node(Mesh { name: model.name.clone(), primitives: vec![prim], extras: None });
        }
    }
    let declared_bounds = Vec::new();
    Ok(Loaded { scene, issues, declared_bounds })
}

/// Finds face corners that name a vertex, uv or normal not defined before them.
fn scan_obj_faces(text: &str) -> Vec<Issue> {
    let mut issues = Vec::new();
    let (mut v, mut vt, mut vn) = (0i64, 0i64, 0i64);
    for (ln, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => v += 1,
            Some("vt") => vt += 1,
            Some("vn") => vn += 1,
            Some("f") => {
                for corner in words {
                    for (k, part) in corner.split('/').enumerate().take(3) {
                        if part.is_empty() {
                            continue;
                        }
                        let count = [v, vt, vn][k];
                        let ok = match part.parse::<i64>() {
                            Ok(i) if i > 0 => i <= count,
                            Ok(i) if i < 0 => -i <= count,
                            _ => false,
                        };
                        if ok {
                            continue;
                        }
                        let what = ["vertex", "texture coordinate", "normal"][k];
                        if issues.len() < MAX_LISTED {
                            issues.push(issue(
                                Severity::Error,
                                format!("line {}", ln + 1),
                                format!(
                                    "face corner {corner:?} names {what} {part}, but {count} are defined before it"
                                ),
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    issues
}

// ---------------------------------------------------------------------------------------------
// checks on the re-imported scene

/// Collects one kind of problem for one primitive, listing the first few.
struct Finder<'a> {
    issues: &'a mut Vec<Issue>,
    loc: String,
    what: &'static str,
    count: usize,
}

impl Finder<'_> {
    fn found(&mut self, at: String, message: String) {
        if self.count < MAX_LISTED {
            self.issues.push(issue(Severity::Error, format!("{} {at}", self.loc), message));
        }
        self.count += 1;
    }
}

impl Drop for Finder<'_> {
    fn drop(&mut self) {
        if self.count > MAX_LISTED {
            let more = self.count - MAX_LISTED;
            self.issues.push(issue(Severity::Error, self.loc.clone(), format!("… and {more} more {}", self.what)));
        }
    }
}

fn check_scene_data(scene: &Scene, declared: &[Vec<Option<Bounds>>], opts: &ValidateOptions, issues: &mut Vec<Issue>) {
    for (mi, mesh) in scene.meshes.iter().enumerate() {
        for (pi, p) in mesh.primitives.iter().enumerate() {
            let loc = format!("mesh {mi} {:?} primitive {pi}", mesh.name);
            check_primitive(p, &loc, issues);
            if let Some(Some(d)) = declared.get(mi).and_then(|m| m.get(pi)) {
                if let Some(b) = p.bounds() {
                    if b.min != d.min || b.max != d.max {
                        issues.push(issue(
                            Severity::Error,
                            &loc,
                            format!(
                                "POSITION min/max {:?}..{:?} differ from the data's {:?}..{:?}",
                                d.min, d.max, b.min, b.max
                            ),
                        ));
                    }
                }
            }
        }
    }
    for (ni, node) in scene.nodes.iter().enumerate() {
        let loc = format!("node {ni} {:?}", node.name);
        if let Some(inst) = &node.instances {
            let lens = [inst.translations.len(), inst.rotations.len(), inst.scales.len()];
            if lens.iter().any(|&l| l != 0 && l != inst.len()) {
                issues.push(issue(Severity::Error, &loc, format!("instance arrays have different lengths {lens:?}")));
            }
            let finite = inst
                .translations
                .iter()
                .flatten()
                .chain(inst.rotations.iter().flatten())
                .chain(inst.scales.iter().flatten());
            if !finite.into_iter().all(|x| x.is_finite()) {
                issues.push(issue(Severity::Error, &loc, "instance transform is not finite"));
            }
            if let Some(k) = inst.rotations.iter().position(|r| (length(r) - 1.0).abs() > NORMAL_TOLERANCE) {
                issues.push(issue(
                    Severity::Error,
                    &loc,
                    format!("instance {k} rotation {:?} is not a unit quaternion", inst.rotations[k]),
                ));
            }
        }
        if !node.lod_screen_coverage.is_empty() {
            let c = &node.lod_screen_coverage;
            if c.len() != node.lods.len() && c.len() != node.lods.len() + 1 {
                issues.push(issue(
                    Severity::Warning,
                    &loc,
                    format!("{} screen coverages for {} LoD levels", c.len(), node.lods.len()),
                ));
            }
            if c.windows(2).any(|w| w[1] > w[0]) {
                issues.push(issue(Severity::Warning, &loc, "screen coverages should decrease level by level"));
            }
        }
    }
    if opts.up_facing {
        check_up_facing(scene, issues);
    }
}

fn length(v: &[f32]) -> f64 {
    v.iter().map(|&x| x as f64 * x as f64).sum::<f64>().sqrt()
}

fn check_primitive(p: &Primitive, loc: &str, issues: &mut Vec<Issue>) {
    let n = p.positions.len();
    let points = p.mode == PrimitiveMode::Points;
    if !points && !p.indices.len().is_multiple_of(3) {
        issues.push(issue(
            Severity::Error,
            loc,
            format!("{} indices is not a whole number of triangles", p.indices.len()),
        ));
    }
    {
        let mut f = Finder { issues, loc: loc.into(), what: "indices out of range", count: 0 };
        for (k, &i) in p.indices.iter().enumerate() {
            if i as usize >= n {
                f.found(format!("index {k}"), format!("is {i}, but there are {n} vertices"));
            }
        }
    }
    for (name, values) in [
        ("POSITION", p.positions.iter().flat_map(|v| v.to_vec()).collect::<Vec<f32>>()),
        ("NORMAL", p.normals.iter().flat_map(|v| v.to_vec()).collect()),
        ("TEXCOORD_0", p.uvs.iter().flat_map(|v| v.to_vec()).collect()),
        ("COLOR_0", p.colors.iter().flat_map(|v| v.to_vec()).collect()),
    ] {
        let dims = match name {
            "TEXCOORD_0" => 2,
            "COLOR_0" => 4,
            _ => 3,
        };
        let mut f = Finder { issues, loc: loc.into(), what: "non-finite values", count: 0 };
        for (k, c) in values.chunks(dims).enumerate() {
            if !c.iter().all(|x| x.is_finite()) {
                f.found(format!("vertex {k}"), format!("{name} {c:?} is not finite"));
            }
        }
    }
    {
        let mut f = Finder { issues, loc: loc.into(), what: "non-unit normals", count: 0 };
        for (k, nrm) in p.normals.iter().enumerate() {
            let len = length(nrm);
            if len.is_finite() && (len - 1.0).abs() > NORMAL_TOLERANCE {
                f.found(format!("vertex {k}"), format!("normal {nrm:?} has length {len:.6}"));
            }
        }
    }
    if points {
        return;
    }
    let mut f = Finder { issues, loc: loc.into(), what: "degenerate triangles", count: 0 };
    for t in 0..p.indices.len() / 3 {
        let [a, b, c] = [p.indices[3 * t], p.indices[3 * t + 1], p.indices[3 * t + 2]];
        if [a, b, c].iter().any(|&i| i as usize >= n) {
            continue;
        }
        if a == b || b == c || a == c {
            f.found(format!("triangle {t}"), format!("repeats a vertex ({a}, {b}, {c})"));
            continue;
        }
        if triangle_is_flat(p, t) {
            f.found(format!("triangle {t}"), "has zero area".into());
        }
    }
}

/// Zero area: the cross product is negligible against the squared edge lengths (f64, so an exact
/// zero for collinear f32 points stays zero and a sliver of real area is not flagged).
fn triangle_is_flat(p: &Primitive, t: usize) -> bool {
    let c = p.triangle_cross(t);
    let corner = |k: usize| {
        let v = p.positions[p.indices[3 * t + k] as usize];
        DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64)
    };
    let (a, b, cc) = (corner(0), corner(1), corner(2));
    let scale = (b - a).length_squared().max((cc - a).length_squared()).max((cc - b).length_squared());
    let area2 = DVec3::from(c).length();
    area2.is_finite() && area2 <= 1e-12 * scale
}

/// World matrix of every node reachable from the roots (None for the others).
fn world_matrices(scene: &Scene) -> Vec<Option<DMat4>> {
    let mut world = vec![None; scene.nodes.len()];
    let mut stack: Vec<(usize, DMat4)> = scene.roots.iter().rev().map(|&r| (r, DMat4::IDENTITY)).collect();
    while let Some((n, parent)) = stack.pop() {
        let Some(node) = scene.nodes.get(n) else { continue };
        if world[n].is_some() {
            continue; // a cycle or a node with two parents: the file checks report those
        }
        let d = |v: [f32; 3]| DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
        let r = node.rotation;
        let local = DMat4::from_scale_rotation_translation(
            d(node.scale),
            DQuat::from_xyzw(r[0] as f64, r[1] as f64, r[2] as f64, r[3] as f64),
            d(node.translation),
        );
        let m = parent * local;
        world[n] = Some(m);
        for &c in node.children.iter().rev() {
            stack.push((c, m));
        }
    }
    world
}

fn check_up_facing(scene: &Scene, issues: &mut Vec<Issue>) {
    let world = world_matrices(scene);
    for (ni, node) in scene.nodes.iter().enumerate() {
        let (Some(mi), Some(m)) = (node.mesh, world[ni]) else { continue };
        let Some(mesh) = scene.meshes.get(mi) else { continue };
        for (pi, p) in mesh.primitives.iter().enumerate() {
            let loc = format!("node {ni} {:?} mesh {:?} primitive {pi}", node.name, mesh.name);
            let mut f = Finder { issues, loc, what: "triangles not facing up", count: 0 };
            let n = p.positions.len();
            for t in 0..p.indices.len() / 3 {
                let idx = [p.indices[3 * t], p.indices[3 * t + 1], p.indices[3 * t + 2]];
                if idx.iter().any(|&i| i as usize >= n) || triangle_is_flat(p, t) {
                    continue; // reported by the primitive checks
                }
                let w = |i: u32| {
                    let v = p.positions[i as usize];
                    m.transform_point3(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
                };
                let (a, b, c) = (w(idx[0]), w(idx[1]), w(idx[2]));
                let normal = (b - a).cross(c - a);
                if normal.y.is_nan() || normal.y <= 0.0 {
                    f.found(
                        format!("triangle {t}"),
                        format!("faces {:?}, not up (+Y)", normal.normalize_or_zero().to_array()),
                    );
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obj_face_scan_finds_bad_corners_with_lines() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 0 1\nvn 0 1 0\nf 1//1 2//1 3//1\nf 1 2 4\nf 1/1 2 -4\n";
        let issues = scan_obj_faces(text);
        assert_eq!(issues.len(), 3, "{issues:?}");
        assert_eq!(issues[0].location, "line 6");
        assert!(issues[0].message.contains("vertex 4"));
        assert!(issues[1].message.contains("texture coordinate 1"));
    }

    #[test]
    fn flat_and_repeated_triangles_are_degenerate() {
        let p = Primitive {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            indices: vec![0, 1, 2, 0, 0, 3, 0, 3, 1],
            ..Primitive::default()
        };
        let mut issues = Vec::new();
        check_primitive(&p, "p", &mut issues);
        assert_eq!(issues.len(), 2, "{issues:?}");
        assert!(issues[0].message.contains("zero area"));
        assert!(issues[1].message.contains("repeats"));
    }

    #[test]
    fn up_facing_uses_world_transform() {
        // counter-clockwise seen from +Y: faces up
        let p = Primitive {
            positions: vec![[0.0; 3], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]],
            indices: vec![0, 1, 2],
            ..Primitive::default()
        };
        let mut scene = Scene::default();
        let n = scene.add_mesh_node(Mesh { name: "t".into(), primitives: vec![p], extras: None });
        let mut issues = Vec::new();
        check_up_facing(&scene, &mut issues);
        assert!(issues.is_empty(), "{issues:?}");
        // turned upside down by its node: 180° about X
        scene.nodes[n].rotation = [1.0, 0.0, 0.0, 0.0];
        check_up_facing(&scene, &mut issues);
        assert_eq!(issues.len(), 1, "{issues:?}");
    }
}
