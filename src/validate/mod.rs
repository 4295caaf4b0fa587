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
mod report;

pub use report::{Issue, MeshReport, PrimitiveReport, Severity, ValidationReport};

use std::io;
use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::mesh::{Bounds, Mesh, Scene};
use checks::check_scene_data;
use load_gltf::load_gltf;
use load_obj::load_obj;

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
