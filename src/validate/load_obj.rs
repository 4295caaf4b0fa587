//! Reading an OBJ model (with its MTL) back into a [`Scene`], best effort, after a scan of the face
//! lines that names each corner pointing at an element not defined before it.

use std::path::Path;

use super::options::{Loaded, ValidateError, MAX_LISTED};
use super::report::{issue, Issue, Severity};
use crate::mesh::{Material, Mesh, Primitive, Scene, Texture};

pub(super) fn load_obj(path: &Path) -> Result<Loaded, ValidateError> {
    let text = crate::input::read_limited(path, crate::input::MAX_OBJ_BYTES, "an OBJ model")
        .map_err(|e| ValidateError::Read { path: path.to_path_buf(), source: e.into_io() })?;
    // tobj rejects out-of-range faces without saying where; find them ourselves, with line numbers
    let issues = scan_obj_faces(&String::from_utf8_lossy(&text));
    if !issues.is_empty() {
        return Ok(Loaded {
            scene: Scene::default(),
            issues,
            declared_bounds: Vec::new(),
            quantized: Vec::new(),
            grids: Vec::new(),
        });
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
    Ok(Loaded { scene, issues, declared_bounds, quantized: Vec::new(), grids: Vec::new() })
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
}
