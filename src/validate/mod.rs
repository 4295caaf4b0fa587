//! `verdant validate`: re-imports written files (glTF with the `gltf` crate, OBJ with `tobj`) and
//! checks the invariants every output promises: indices in range, finite attributes, no degenerate
//! triangles, unit normals, exact POSITION min/max, and (for terrain) triangles facing +Y.
//!
//! Also checks what the Khronos validator cannot: EXT_mesh_gpu_instancing arrays (equal counts,
//! finite values, unit rotations) and MSFT_lod ids. Accessors are decoded by our own bounds-checked
//! reader, so no file, however damaged, makes this panic.
//!
//! Parts: `load_gltf` (glTF/GLB into a [`Scene`]), `accessor` (bounds-checked accessor reads),
//! `meshopt` (EXT_meshopt_compression buffers), `load_obj` (OBJ into a [`Scene`]), `checks` (the
//! invariants on the re-imported scene), `report` (what a validation found).

mod accessor;
mod checks;
mod load_gltf;
mod load_obj;
mod meshopt;
mod options;
mod report;

use options::Loaded;
pub use options::{ValidateError, ValidateOptions, NORMAL_TOLERANCE};
pub use report::{Issue, MeshReport, PrimitiveReport, Severity, ValidationReport};

use std::path::Path;

use crate::mesh::{Bounds, Mesh, Scene};
use checks::check_scene_data;
use load_gltf::load_gltf;
use load_obj::load_obj;

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
    check_scene_data(&loaded.scene, &loaded.declared_bounds, &loaded.quantized, opts, &mut issues);
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
    Ok(load_without_errors(path)?.scene)
}

/// The file loaded, or its first error as a parse error.
fn load_without_errors(path: &Path) -> Result<Loaded, ValidateError> {
    let loaded = load(path)?;
    if let Some(i) = loaded.issues.iter().find(|i| i.severity == Severity::Error) {
        return Err(ValidateError::Parse {
            path: path.to_path_buf(),
            problem: format!("{}: {}", i.location, i.message),
        });
    }
    Ok(loaded)
}

/// [`read_scene`], with every quantized mesh (KHR_mesh_quantization: integers placed by their
/// node) put into its node's frame as floats, the node's translation and scale then identity:
/// what a stage that takes meshes out of a file to place them itself needs (a mesh shown by nodes
/// of different transforms or by instances stays as stored). Positions are rounded to f32 once
/// more: measure a file's exact error with [`read_scene`].
pub fn read_scene_dequantized(path: &Path) -> Result<Scene, ValidateError> {
    let loaded = load_without_errors(path)?;
    let mut scene = loaded.scene;
    load_gltf::bake_quantized(&mut scene, &loaded.quantized, &loaded.grids);
    Ok(scene)
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
