//! Reading a glTF 2.0 file (`.glb` or `.gltf` + buffers) back into a [`Scene`] exactly, with the
//! structural problems the glTF crates would trip on checked first.

use std::fs;
use std::path::Path;

use serde_json::Value;

use super::accessor::{read_floats, read_indices, view_bytes};
use super::meshopt::meshopt_buffers;
use super::options::{Loaded, ValidateError};
use super::report::{issue, Issue, Severity};
use crate::export::gltf::{
    ATTRIBUTE_RANGES_KEY, EXT_INSTANCING, EXT_LOD, EXT_MESHOPT, GRID_EXTRAS_KEY, KHR_QUANTIZATION,
    KHR_TEXTURE_TRANSFORM, LOD_COVERAGE_KEY,
};
use crate::export::grid::PositionGrid;
use crate::mesh::{AlphaMode, Bounds, Instances, Material, Mesh, Node, Primitive, PrimitiveMode, Scene, Texture};

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
    // arrays and counts the schema requires to be non-empty (the Khronos validator's EMPTY_ENTITY
    // and VALUE_NOT_IN_RANGE)
    for (mi, mesh) in root.meshes.iter().enumerate() {
        if mesh.primitives.is_empty() {
            problems.push(format!("meshes[{mi}]: no primitives; a mesh has at least one"));
        }
        for (pi, prim) in mesh.primitives.iter().enumerate() {
            if prim.attributes.is_empty() {
                problems.push(format!("meshes[{mi}].primitives[{pi}]: no attributes; a primitive has at least one"));
            }
        }
    }
    for (ai, accessor) in root.accessors.iter().enumerate() {
        if accessor.count.0 == 0 {
            problems.push(format!("accessors[{ai}]: count 0; an accessor has at least one element"));
        }
    }
    for (bi, buffer) in root.buffers.iter().enumerate() {
        if buffer.byte_length.0 == 0 {
            problems.push(format!("buffers[{bi}]: byteLength 0; a buffer has at least one byte"));
        }
    }
    for (vi, view) in root.buffer_views.iter().enumerate() {
        if view.byte_length.0 == 0 {
            problems.push(format!("bufferViews[{vi}]: byteLength 0; a view has at least one byte"));
        }
    }
    // image types: glTF's two, and those of the texture extensions the file declares
    let used = |name: &str| root.extensions_used.iter().any(|e| e == name);
    let image_types: Vec<&str> = [
        ("image/png", true),
        ("image/jpeg", true),
        ("image/ktx2", used("KHR_texture_basisu")),
        ("image/webp", used("EXT_texture_webp")),
        ("image/avif", used("EXT_texture_avif")),
    ]
    .into_iter()
    .filter_map(|(t, ok)| ok.then_some(t))
    .collect();
    for (ii, image) in root.images.iter().enumerate() {
        if let Some(t) = image.mime_type.as_ref().map(|m| m.0.as_str()).filter(|t| !image_types.contains(t)) {
            problems.push(format!("images[{ii}]: mimeType {t:?} is not one of {}", image_types.join(", ")));
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

pub(super) fn load_gltf(path: &Path) -> Result<Loaded, ValidateError> {
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
                && [EXT_INSTANCING, KHR_QUANTIZATION, EXT_MESHOPT, KHR_TEXTURE_TRANSFORM]
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
    let mut quantized = Vec::new();
    let mut grids = Vec::new();

    // KHR_mesh_quantization must be required where positions are not float (a reader without it
    // would misread them)
    let quantization_used = doc.extensions_required().any(|e| e == KHR_QUANTIZATION);
    for mesh in doc.meshes() {
        let mesh_name = mesh.name().unwrap_or("").to_string();
        let mut extras = parse_extras(mesh.extras());
        // the writer's note of the grid (taken out, so extras read back as the scene had them)
        let grid = match &mut extras {
            Some(Value::Object(map)) => {
                let g = map.remove(GRID_EXTRAS_KEY).and_then(|g| grid_of(&g));
                if map.is_empty() {
                    extras = None;
                }
                g
            }
            _ => None,
        };
        grids.push(grid);
        let mut out = Mesh { name: mesh_name.clone(), primitives: Vec::new(), extras };
        let mut declared = Vec::new();
        quantized.push(mesh.primitives().any(|p| {
            p.get(&gltf::Semantic::Positions).is_some_and(|a| a.data_type() != gltf::accessor::DataType::F32)
        }));
        for (pi, prim) in mesh.primitives().enumerate() {
            let loc = format!("mesh {} {:?} primitive {pi}", mesh.index(), mesh_name);
            let (p, bounds) = read_primitive(&prim, &buffers, &loc, quantization_used, &mut issues);
            out.primitives.push(p);
            declared.push(bounds);
        }
        scene.meshes.push(out);
        declared_bounds.push(declared);
    }

    // KHR_texture_transform: the coordinates as the material's textures sample them (verdant's
    // materials hold none, so the transform is applied to the coordinates read)
    let mut uv_transforms: Vec<Option<UvTransform>> = Vec::new();
    for m in doc.materials() {
        let loc = format!("material {} {:?}", m.index().unwrap_or(0), m.name().unwrap_or(""));
        let pbr = m.pbr_metallic_roughness();
        let base = pbr.base_color_texture().map(|i| uv_transform(i.extension_value(KHR_TEXTURE_TRANSFORM)));
        let normal = m.normal_texture().map(|n| uv_transform(n.extension_value(KHR_TEXTURE_TRANSFORM)));
        let t = match (base, normal) {
            (Some(Err(e)), _) | (_, Some(Err(e))) => {
                issues.push(issue(Severity::Error, &loc, e));
                None
            }
            (Some(Ok(a)), Some(Ok(b))) if a != b => {
                issues.push(issue(
                    Severity::Error,
                    &loc,
                    format!("{KHR_TEXTURE_TRANSFORM} differs between baseColorTexture and normalTexture (verdant reads one set of coordinates per material)"),
                ));
                None
            }
            (Some(Ok(a)), _) => a,
            (None, Some(Ok(b))) => b,
            (None, None) => None,
        };
        uv_transforms.push(t);
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

    for mesh in &mut scene.meshes {
        for p in &mut mesh.primitives {
            if let Some(Some(t)) = p.material.and_then(|k| uv_transforms.get(k)) {
                for uv in &mut p.uvs {
                    *uv = [0, 1].map(|a| t.offset[a] + t.scale[a] * uv[a]);
                }
            }
        }
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
            out.instances = Some(read_instances(ext, &doc, &buffers, &loc, &mut issues).into());
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
    Ok(Loaded { scene, issues, declared_bounds, quantized, grids })
}

/// The ranges a compact file notes for attributes stored as normalized integers of value / range
/// ([`ATTRIBUTE_RANGES_KEY`] in the primitive's extras): each four positive finite numbers.
fn attribute_ranges(prim: &gltf::Primitive, loc: &str, issues: &mut Vec<Issue>) -> Vec<(String, [f32; 4])> {
    let Some(raw) = prim.extras() else { return Vec::new() };
    let Ok(Value::Object(extras)) = serde_json::from_str::<Value>(raw.get()) else { return Vec::new() };
    let Some(ranges) = extras.get(ATTRIBUTE_RANGES_KEY) else { return Vec::new() };
    let Value::Object(ranges) = ranges else {
        issues.push(issue(Severity::Error, loc, format!("extras {ATTRIBUTE_RANGES_KEY} is not an object")));
        return Vec::new();
    };
    let mut out = Vec::new();
    for (name, r) in ranges {
        let four = r
            .as_array()
            .filter(|a| a.len() == 4)
            .and_then(|a| a.iter().map(|x| x.as_f64().map(|x| x as f32)).collect::<Option<Vec<f32>>>())
            .filter(|a| a.iter().all(|x| x.is_finite() && *x > 0.0));
        match four {
            Some(a) => out.push((name.clone(), [a[0], a[1], a[2], a[3]])),
            None => issues.push(issue(
                Severity::Error,
                loc,
                format!("extras {ATTRIBUTE_RANGES_KEY}.{name} is not four positive finite numbers: {r}"),
            )),
        }
    }
    out
}

/// A grid noted in a mesh's extras ([`GRID_EXTRAS_KEY`]): finite origin, positive finite steps.
fn grid_of(v: &Value) -> Option<PositionGrid> {
    let three = |key: &str| -> Option<[f32; 3]> {
        let a = v.get(key)?.as_array()?;
        let t: [f32; 3] = [a.first()?.as_f64()? as f32, a.get(1)?.as_f64()? as f32, a.get(2)?.as_f64()? as f32];
        (a.len() == 3 && t.iter().all(|x| x.is_finite())).then_some(t)
    };
    let (origin, step) = (three("origin")?, three("step")?);
    step.iter().all(|&s| s > 0.0).then_some(PositionGrid { origin, step })
}

/// How far from unit length a normalized integer direction may be, as rounding to its type allows
/// (half a step on each component, with a margin); None for floats, which must be unit length.
fn integer_unit_tolerance(acc: &gltf::Accessor) -> Option<f32> {
    use gltf::accessor::DataType;
    match acc.data_type() {
        DataType::I8 => Some(0.012),
        DataType::I16 => Some(1e-4),
        _ => None,
    }
}

/// Directions stored as normalized integers (KHR_mesh_quantization) as the unit vectors they stand
/// for, as shaders normalise them; one stored further from unit length than its rounding allows
/// is an error.
fn renormalize(dirs: &mut [[f32; 3]], tol: f32, what: &str, loc: &str, issues: &mut Vec<Issue>) {
    let mut bad = 0usize;
    for d in dirs.iter_mut() {
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if (l - 1.0).abs() > tol || !l.is_finite() {
            bad += 1;
            continue;
        }
        *d = d.map(|c| c / l);
    }
    if bad > 0 {
        issues.push(issue(
            Severity::Error,
            loc,
            format!("{bad} {what} values are further from unit length than their integer type's rounding ({tol})"),
        ));
    }
}

/// A KHR_texture_transform's offset and scale (uv' = offset + scale·uv).
#[derive(Debug, Clone, Copy, PartialEq)]
struct UvTransform {
    offset: [f32; 2],
    scale: [f32; 2],
}

/// The transform a texture reference's extension states, if any; rotation and texCoord overrides
/// are refused (verdant writes neither).
fn uv_transform(ext: Option<&Value>) -> Result<Option<UvTransform>, String> {
    let Some(ext) = ext else { return Ok(None) };
    if ext.get("rotation").and_then(Value::as_f64).is_some_and(|r| r != 0.0) || ext.get("texCoord").is_some() {
        return Err(format!("{KHR_TEXTURE_TRANSFORM} with rotation or texCoord is not supported by verdant"));
    }
    let pair = |key: &str, default: f32| -> Result<[f32; 2], String> {
        match ext.get(key) {
            None => Ok([default; 2]),
            Some(v) => v
                .as_array()
                .filter(|a| a.len() == 2)
                .and_then(|a| Some([a[0].as_f64()? as f32, a[1].as_f64()? as f32]))
                .filter(|p| p.iter().all(|x| x.is_finite()))
                .ok_or_else(|| format!("{KHR_TEXTURE_TRANSFORM} {key} is not two finite numbers")),
        }
    };
    Ok(Some(UvTransform { offset: pair("offset", 0.0)?, scale: pair("scale", 1.0)? }))
}

/// Puts each quantized mesh (integer positions placed by its node, KHR_mesh_quantization) into
/// its own frame: exactly, by the grid its extras note (verdant's files; every node and instance
/// showing it gets its own transform back); else into its node's frame: positions, normals and tangents take the node's translation and scale, which
/// become identity. Done where every node showing the mesh has the same transform and no instances
/// (a verdant file's quantized mesh nodes; an instanced mesh keeps its grid in its instances and
/// stays as stored). The world-space geometry is unchanged.
pub(super) fn bake_quantized(scene: &mut Scene, quantized: &[bool], grids: &[Option<PositionGrid>]) {
    for (m, &q) in quantized.iter().enumerate() {
        if !q {
            continue;
        }
        if let Some(Some(grid)) = grids.get(m) {
            bake_on_grid(scene, m, grid);
            continue;
        }
        let showing: Vec<usize> = (0..scene.nodes.len()).filter(|&n| scene.nodes[n].mesh == Some(m)).collect();
        let Some(&first) = showing.first() else { continue };
        let (t, r, s) = (scene.nodes[first].translation, scene.nodes[first].rotation, scene.nodes[first].scale);
        let same = showing.iter().all(|&n| {
            let node = &scene.nodes[n];
            node.instances.is_none()
                && node.children.is_empty() // (its children would move with the baked transform)
                && node.translation == t
                && node.rotation == r
                && node.scale == s
        });
        if !same || s.iter().any(|&x| x == 0.0 || !x.is_finite()) {
            continue;
        }
        // world = T + R(S∘q) = R(R⁻¹T + S∘q)
        let rot = glam::DQuat::from_array(r.map(f64::from));
        let back = rot.inverse() * glam::DVec3::from_array(t.map(f64::from));
        let unit = |v: [f64; 3]| {
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if l > 0.0 {
                v.map(|c| (c / l) as f32)
            } else {
                v.map(|c| c as f32)
            }
        };
        for p in &mut scene.meshes[m].primitives {
            for v in &mut p.positions {
                *v = [0, 1, 2].map(|a| (back[a] + s[a] as f64 * v[a] as f64) as f32);
            }
            for n in &mut p.normals {
                *n = unit([0, 1, 2].map(|a| n[a] as f64 / s[a] as f64));
            }
            for tg in &mut p.tangents {
                let d = unit([0, 1, 2].map(|a| tg[a] as f64 * s[a] as f64));
                *tg = [d[0], d[1], d[2], tg[3]];
            }
        }
        for &n in &showing {
            scene.nodes[n].translation = [0.0; 3];
            scene.nodes[n].scale = [1.0; 3];
        }
    }
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
        let tol = prim.get(&Semantic::Normals).and_then(|a| integer_unit_tolerance(&a));
        if let Some(tol) = tol {
            renormalize(&mut p.normals, tol, "NORMAL", loc, issues);
        }
    }
    if let Some((_, v)) = read(issues, "TEXCOORD_0", prim.get(&Semantic::TexCoords(0)), &[2]) {
        p.uvs = v.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
    }
    if let Some((_, v)) = read(issues, "TANGENT", prim.get(&Semantic::Tangents), &[4]) {
        p.tangents = v.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
        let tol = prim.get(&Semantic::Tangents).and_then(|a| integer_unit_tolerance(&a));
        if let Some(tol) = tol {
            let mut xyz: Vec<[f32; 3]> = p.tangents.iter().map(|t| [t[0], t[1], t[2]]).collect();
            renormalize(&mut xyz, tol, "TANGENT", loc, issues);
            for (t, d) in p.tangents.iter_mut().zip(xyz) {
                *t = [d[0], d[1], d[2], t[3]];
            }
        }
    }
    if let Some((d, v)) = read(issues, "COLOR_0", prim.get(&Semantic::Colors(0)), &[3, 4]) {
        p.colors = v.chunks_exact(d).map(|c| [c[0], c[1], c[2], if d == 4 { c[3] } else { 1.0 }]).collect();
    }
    let ranges = attribute_ranges(prim, loc, issues);
    for (sem, acc) in prim.attributes() {
        if let Semantic::Extras(name) = sem {
            let name = format!("_{name}");
            let noted = ranges.iter().find(|(n, _)| *n == name).map(|(_, r)| *r);
            use gltf::accessor::DataType;
            // ranges start at 0: unsigned normalized integers only
            let unsigned = acc.normalized() && matches!(acc.data_type(), DataType::U8 | DataType::U16);
            let documented = crate::plants::wind::documented_range(&name);
            if noted.is_some() && !unsigned {
                issues.push(issue(
                    Severity::Error,
                    loc,
                    format!(
                        "{name} has a range in the primitive's extras ({ATTRIBUTE_RANGES_KEY}) but is not a normalized \
                         unsigned byte or short attribute"
                    ),
                ));
            } else if noted.is_none() && acc.normalized() && documented.is_some() {
                issues.push(issue(
                    Severity::Warning,
                    loc,
                    format!(
                        "{name} is stored as normalized integers but the primitive's extras note no range \
                         ({ATTRIBUTE_RANGES_KEY}): read as 0..1, not in its units (docs/wind.md); was the file \
                         re-exported by a tool that drops extras?"
                    ),
                ));
            }
            let unit_bytes = noted.is_none() && acc.normalized() && acc.data_type() == DataType::U8;
            // floats are the values; a file that notes no range has the attribute's documented one
            let range = if unit_bytes { None } else { noted.or(documented) };
            if let Some((_, v)) = read(issues, &name, Some(acc), &[4]) {
                let r = noted.filter(|_| unsigned).unwrap_or([1.0; 4]);
                let values = v.chunks_exact(4).map(|c| std::array::from_fn(|k| c[k] * r[k])).collect();
                p.custom.push(crate::mesh::CustomAttribute { name, values, unit_bytes, range });
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

/// Mesh `m` off its grid: positions origin + step·q (normals of a non-uniform grid, stored scaled
/// by the steps, turned back), and every node or instance showing it without the grid's part of
/// its transform (scale S·step and translation T + R(S∘origin) back to S and T).
fn bake_on_grid(scene: &mut Scene, m: usize, grid: &PositionGrid) {
    let (o, st) = (grid.origin.map(f64::from), grid.step.map(f64::from));
    let uniform = st[0] == st[1] && st[1] == st[2];
    for p in &mut scene.meshes[m].primitives {
        for v in &mut p.positions {
            *v = [0, 1, 2].map(|a| (o[a] + st[a] * v[a] as f64) as f32);
        }
        if !uniform {
            for n in &mut p.normals {
                let d = [0, 1, 2].map(|a| n[a] as f64 / st[a]);
                let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(f64::MIN_POSITIVE);
                *n = d.map(|c| (c / l) as f32);
            }
        }
    }
    let unplace = |r: [f32; 4], t: [f32; 3], s: [f32; 3]| -> ([f32; 3], [f32; 3]) {
        let s0 = [0, 1, 2].map(|a| s[a] as f64 / st[a]);
        let off = glam::DQuat::from_array(r.map(f64::from)) * glam::DVec3::from_array([0, 1, 2].map(|a| s0[a] * o[a]));
        ([0, 1, 2].map(|a| (t[a] as f64 - off[a]) as f32), s0.map(|x| x as f32))
    };
    for node in scene.nodes.iter_mut().filter(|n| n.mesh == Some(m)) {
        match &mut node.instances {
            Some(inst) if !inst.is_empty() => {
                let n = inst.len();
                let (mut ts, mut ss) = (Vec::with_capacity(n), Vec::with_capacity(n));
                for k in 0..n {
                    let r = inst.rotations.get(k).copied().unwrap_or([0.0, 0.0, 0.0, 1.0]);
                    let t = inst.translations.get(k).copied().unwrap_or([0.0; 3]);
                    let s = inst.scales.get(k).copied().unwrap_or([1.0; 3]);
                    let (t0, s0) = unplace(r, t, s);
                    ts.push(t0);
                    ss.push(s0);
                }
                let inst = std::sync::Arc::make_mut(inst);
                (inst.translations, inst.scales) = (ts, ss);
            }
            _ => (node.translation, node.scale) = unplace(node.rotation, node.translation, node.scale),
        }
    }
}
