//! Writers: glTF 2.0 (.glb, .gltf + .bin), OBJ + MTL. All writes are atomic.
//!
//! Every writer first checks the whole [`Scene`] (indices in range, finite values, unit normals and
//! quaternions, a tree-shaped node graph), then builds every output file in memory, and only then
//! writes them, each through [`write_atomic`]: a scene that cannot be written leaves the previous
//! outputs untouched.

pub mod compact;
pub mod gltf;
pub mod grid;
pub mod obj;
pub mod streaming;
pub mod table;

use std::ffi::OsStr;
use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use thiserror::Error;

use crate::mesh::{AlphaMode, Scene};

/// Extensions [`write_scene`] understands, for messages.
pub const SUPPORTED_EXTENSIONS: &str = ".glb, .gltf (+ .bin), .obj (+ .mtl, .png)";

/// A normal or quaternion counts as unit length when its length is within this of 1. Stricter
/// than the Khronos validator (2.0.0-dev.3.10 accepts normals of length 1.006, rejects 1.01);
/// stages renormalise in f32 and stay far inside it.
pub const UNIT_LENGTH_TOLERANCE: f32 = 5e-4;

#[derive(Debug, Error)]
pub enum ExportError {
    #[error("could not write {path}: {source}; check that the folder is writable, the disk is not full and no folder has that name")]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("cannot export {path}: unknown extension {ext:?}; use one of {SUPPORTED_EXTENSIONS}")]
    UnsupportedExtension { path: PathBuf, ext: String },
    #[error(
        "cannot export {path}: the path has no file name (or it is not UTF-8); name a file such as out/terrain.glb"
    )]
    NoFileName { path: PathBuf },
    #[error("cannot export {path}: {problem}; this is a bug in the stage that built the scene, please report it with the command line used")]
    InvalidScene { path: PathBuf, problem: String },
}

/// The input's for an output path that names no file this module writes; the build's for a
/// failed write or a scene the writers refuse.
impl crate::failure::Failure for ExportError {
    fn blame(&self) -> crate::failure::Blame {
        match self {
            ExportError::UnsupportedExtension { .. } | ExportError::NoFileName { .. } => crate::failure::Blame::Input,
            ExportError::Io { .. } | ExportError::InvalidScene { .. } => crate::failure::Blame::Build,
        }
    }
}

/// Whether `path` names a file [`write_scene`] can write: a UTF-8 file name with a known extension
/// (`.glb`, `.gltf`, `.obj`, any case). Commands check it before any work, so a wrong `-o` fails at
/// once as bad input rather than after meshing.
pub fn check_output_path(path: &Path) -> Result<(), ExportError> {
    match path.file_stem().and_then(OsStr::to_str) {
        Some(s) if !s.is_empty() => {}
        _ => return Err(ExportError::NoFileName { path: path.to_path_buf() }),
    }
    let ext = path.extension().and_then(OsStr::to_str).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "glb" | "gltf" | "obj" => Ok(()),
        _ => Err(ExportError::UnsupportedExtension { path: path.to_path_buf(), ext }),
    }
}

/// Why a scene cannot be written (the writers know no file name; [`write_scene`] adds it).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SceneProblem(pub String);

impl std::fmt::Display for SceneProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for SceneProblem {}

impl SceneProblem {
    fn at(path: &Path) -> impl FnOnce(SceneProblem) -> ExportError + '_ {
        move |p| ExportError::InvalidScene { path: path.to_path_buf(), problem: p.0 }
    }
}

/// Writes `scene` to `path`, choosing the format by extension (`.glb`, `.gltf`, `.obj`, any case).
/// Returns every file written, the main file last.
///
/// * `.glb` — one self-contained binary glTF file.
/// * `.gltf` — JSON plus a sibling `<stem>.bin` holding vertex data and the PNG images.
/// * `.obj` — OBJ plus `<stem>.mtl` (when the scene has materials) and `<stem>_<n>[_<name>].png`
///   for each texture. Node transforms are applied and instances expanded; see [`obj`].
pub fn write_scene(scene: &Scene, path: &Path) -> Result<Vec<PathBuf>, ExportError> {
    write_scene_with(scene, path, &gltf::WriteOptions::default())
}

/// [`write_scene`] with storage options for glTF (`.glb`, `.gltf`); an `.obj` cannot take a
/// position grid (its numbers are text), which is refused.
pub fn write_scene_with(scene: &Scene, path: &Path, opts: &gltf::WriteOptions) -> Result<Vec<PathBuf>, ExportError> {
    let ext = path.extension().and_then(OsStr::to_str).unwrap_or("").to_ascii_lowercase();
    let stem = match path.file_stem().and_then(OsStr::to_str) {
        Some(s) if !s.is_empty() => s.to_string(),
        _ => return Err(ExportError::NoFileName { path: path.to_path_buf() }),
    };
    let sibling = |name: &str| path.with_file_name(name);
    // Build everything first, write afterwards: a scene error never touches the disk.
    let files: Vec<(PathBuf, Vec<u8>)> = match ext.as_str() {
        "glb" => {
            let bytes = gltf::to_glb_with(scene, opts).map_err(SceneProblem::at(path))?;
            vec![(path.to_path_buf(), bytes)]
        }
        "gltf" => {
            let bin_name = format!("{stem}.bin");
            let (json, bin) = gltf::to_gltf_with(scene, &bin_name, opts).map_err(SceneProblem::at(path))?;
            let mut files = Vec::new();
            if !bin.is_empty() {
                files.push((sibling(&bin_name), bin));
            }
            files.push((path.to_path_buf(), json));
            files
        }
        "obj" if opts.position_grid.is_some() => {
            return Err(ExportError::InvalidScene {
                path: path.to_path_buf(),
                problem: "quantized positions (--quantize) are a glTF feature (KHR_mesh_quantization); write .glb or .gltf, or leave --quantize out".into(),
            })
        }
        "obj" => {
            let out = obj::to_obj(scene, &stem).map_err(SceneProblem::at(path))?;
            let mut files: Vec<(PathBuf, Vec<u8>)> =
                out.textures.into_iter().map(|(name, png)| (sibling(&name), png)).collect();
            if let Some(mtl) = out.mtl {
                files.push((sibling(&format!("{stem}.mtl")), mtl));
            }
            files.push((path.to_path_buf(), out.obj));
            files
        }
        _ => return Err(ExportError::UnsupportedExtension { path: path.to_path_buf(), ext }),
    };
    let mut written = Vec::with_capacity(files.len());
    for (file, bytes) in files {
        write_atomic(&file, &bytes)?;
        written.push(file);
    }
    Ok(written)
}

/// Writes `bytes` to `path` atomically: a temporary file in the same folder, then renamed over
/// `path`, so a reader sees the old file or the new one, never a part. Creates missing parent
/// folders. On failure the temporary file is removed and whatever was at `path` before is left as
/// it was. No fsync: like other build tools we guard against failed and interrupted runs, not power
/// loss, and on ext4 an fsync also flushes every other file written before it (a cached scene
/// build spent most of its time there).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Like [`write_atomic`], streaming the contents from `fill` (for outputs too big to hold twice).
/// An error from `fill` aborts the write the same way an I/O error does.
pub fn write_atomic_with<F>(path: &Path, fill: F) -> Result<(), ExportError>
where
    F: FnOnce(&mut dyn Write) -> io::Result<()>,
{
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let io_err = |source: io::Error| ExportError::Io { path: path.to_path_buf(), source };
    let file_name = path
        .file_name()
        .ok_or_else(|| io_err(io::Error::new(io::ErrorKind::InvalidInput, "the path has no file name")))?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    fs::create_dir_all(&dir).map_err(io_err)?;
    if path.is_dir() {
        return Err(io_err(io::Error::new(io::ErrorKind::AlreadyExists, "a folder has this name")));
    }
    let tmp = dir.join(format!(
        ".{}.{}-{}.tmp",
        file_name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let file = fs::OpenOptions::new().write(true).create_new(true).open(&tmp)?;
        let mut w = io::BufWriter::new(file);
        fill(&mut w)?;
        drop(w.into_inner().map_err(|e| e.into_error())?);
        fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        return Err(io_err(e));
    }
    Ok(())
}

/// Checks everything a writer relies on, so writers can index without panicking and the output is
/// valid glTF: indices in range, attribute arrays as long as `positions`, finite numbers, unit
/// normals and rotations, factors in 0..1, PNG textures, and a node graph that is a forest.
pub fn check_scene(scene: &Scene) -> Result<(), SceneProblem> {
    let bad = |s: String| Err(SceneProblem(s));
    let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
    let unit = |v: &[f32]| {
        let len = v.iter().map(|&x| (x as f64) * (x as f64)).sum::<f64>().sqrt();
        (len - 1.0).abs() <= UNIT_LENGTH_TOLERANCE as f64
    };
    // glTF also bounds every rotation component to -1..1 (VALUE_NOT_IN_RANGE otherwise)
    let unit_quat = |q: &[f32; 4]| unit(q) && q.iter().all(|c| c.abs() <= 1.0);
    for (ti, t) in scene.textures.iter().enumerate() {
        if !t.png.starts_with(b"\x89PNG\r\n\x1a\n") {
            return bad(format!("texture {ti} ({:?}) is not PNG data", t.name));
        }
    }
    for (mi, m) in scene.materials.iter().enumerate() {
        let what = format!("material {mi} ({:?})", m.name);
        for t in m.textures() {
            if t >= scene.textures.len() {
                return bad(format!("{what} uses texture {t}, but the scene has {}", scene.textures.len()));
            }
        }
        let in01 = |x: f32| (0.0..=1.0).contains(&x);
        if !m.base_color.iter().all(|&x| in01(x)) || !in01(m.metallic) || !in01(m.roughness) {
            return bad(format!("{what} has a colour, metallic or roughness factor outside 0..1"));
        }
        if let AlphaMode::Mask { cutoff } = m.alpha_mode {
            if !(cutoff.is_finite() && cutoff >= 0.0) {
                return bad(format!("{what} has alpha cutoff {cutoff}; it must be a number ≥ 0"));
            }
        }
    }
    for (mi, mesh) in scene.meshes.iter().enumerate() {
        if mesh.primitives.is_empty() {
            return bad(format!("mesh {mi} ({:?}) has no primitives", mesh.name));
        }
        for (pi, p) in mesh.primitives.iter().enumerate() {
            let what = format!("mesh {mi} ({:?}) primitive {pi}", mesh.name);
            let n = p.positions.len();
            let points = p.mode == crate::mesh::PrimitiveMode::Points;
            if n == 0 || (p.indices.is_empty() && !points) {
                return bad(format!("{what} is empty (no vertices or no triangles); drop it before export"));
            }
            if !points && !p.indices.len().is_multiple_of(3) {
                return bad(format!("{what} has {} indices, not a multiple of 3", p.indices.len()));
            }
            if n > u32::MAX as usize - 1 {
                return bad(format!("{what} has {n} vertices, more than 32-bit indices can address"));
            }
            if let Some(i) = p.indices.iter().position(|&i| i as usize >= n) {
                return bad(format!("{what}: index {i} is {} but there are {n} vertices", p.indices[i]));
            }
            for (name, len) in [("normals", p.normals.len()), ("uvs", p.uvs.len()), ("colors", p.colors.len())] {
                if len != 0 && len != n {
                    return bad(format!("{what} has {len} {name} for {n} positions"));
                }
            }
            for (ci, c) in p.custom.iter().enumerate() {
                let valid_name = c.name.len() > 1
                    && c.name.starts_with('_')
                    && c.name[1..].bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_');
                if !valid_name {
                    return bad(format!(
                        "{what}: custom attribute {ci} is named {:?}; names are `_` then letters, digits or `_`",
                        c.name
                    ));
                }
                if p.custom[..ci].iter().any(|o| o.name == c.name) {
                    return bad(format!("{what}: custom attribute {:?} appears twice", c.name));
                }
                if c.values.len() != n {
                    return bad(format!("{what} has {} values of {} for {n} positions", c.values.len(), c.name));
                }
                if let Some(v) = c.values.iter().position(|v| !finite(v)) {
                    return bad(format!("{what}: {} value {v} is not finite ({:?})", c.name, c.values[v]));
                }
            }
            if let Some(v) = p.positions.iter().position(|v| !finite(v)) {
                return bad(format!("{what}: position {v} is not finite ({:?})", p.positions[v]));
            }
            if let Some(v) = p.normals.iter().position(|v| !(finite(v) && unit(v))) {
                return bad(format!("{what}: normal {v} {:?} is not unit length", p.normals[v]));
            }
            if let Some(v) = p.uvs.iter().position(|v| !finite(v)) {
                return bad(format!("{what}: uv {v} is not finite ({:?})", p.uvs[v]));
            }
            if let Some(v) = p.colors.iter().position(|v| !finite(v)) {
                return bad(format!("{what}: colour {v} is not finite ({:?})", p.colors[v]));
            }
            if let Some(m) = p.material {
                if m >= scene.materials.len() {
                    return bad(format!("{what} uses material {m}, but the scene has {}", scene.materials.len()));
                }
            }
        }
    }
    let node_count = scene.nodes.len();
    let mut parent: Vec<Option<usize>> = vec![None; node_count];
    for (ni, node) in scene.nodes.iter().enumerate() {
        let what = format!("node {ni} ({:?})", node.name);
        if let Some(m) = node.mesh {
            if m >= scene.meshes.len() {
                return bad(format!("{what} shows mesh {m}, but the scene has {}", scene.meshes.len()));
            }
        }
        if !finite(&node.translation) || !finite(&node.rotation) || !finite(&node.scale) {
            return bad(format!("{what} has a non-finite translation, rotation or scale"));
        }
        if !unit_quat(&node.rotation) {
            return bad(format!("{what} has rotation {:?}, not a unit quaternion", node.rotation));
        }
        for &c in &node.children {
            if c >= node_count {
                return bad(format!("{what} has child {c}, but the scene has {node_count} nodes"));
            }
            if let Some(p) = parent[c] {
                return bad(format!("node {c} is a child of both node {p} and node {ni}"));
            }
            parent[c] = Some(ni);
        }
        if let Some(inst) = &node.instances {
            let lens = [inst.translations.len(), inst.rotations.len(), inst.scales.len()];
            let count = inst.len();
            if lens.iter().any(|&l| l != 0 && l != count) {
                return bad(format!("{what} has instance arrays of different lengths {lens:?}"));
            }
            if count > 0 && node.mesh.is_none() {
                return bad(format!("{what} has instances but no mesh to instance"));
            }
            let all_finite = inst.translations.iter().all(|v| finite(v))
                && inst.rotations.iter().all(|v| finite(v))
                && inst.scales.iter().all(|v| finite(v));
            if !all_finite {
                return bad(format!("{what} has a non-finite instance transform"));
            }
            if let Some(k) = inst.rotations.iter().position(|r| !unit_quat(r)) {
                return bad(format!("{what}: instance {k} rotation {:?} is not a unit quaternion", inst.rotations[k]));
            }
        }
        for &l in &node.lods {
            if l >= node_count || l == ni {
                return bad(format!("{what} has level of detail node {l}, which is itself or missing"));
            }
        }
        if !finite(&node.lod_screen_coverage) {
            return bad(format!("{what} has a non-finite screen coverage"));
        }
        if !node.lod_screen_coverage.is_empty() && node.lods.is_empty() {
            return bad(format!("{what} has screen coverages but no levels of detail"));
        }
        if let Some(extras) = &node.extras {
            if !node.lod_screen_coverage.is_empty() && !extras.is_object() {
                return bad(format!("{what} has LoD screen coverage, so its extras must be a JSON object"));
            }
        }
    }
    for &r in &scene.roots {
        if r >= node_count {
            return bad(format!("root {r} is not a node (the scene has {node_count})"));
        }
        if let Some(p) = parent[r] {
            return bad(format!("root node {r} is also a child of node {p}"));
        }
    }
    let mut sorted_roots = scene.roots.clone();
    sorted_roots.sort_unstable();
    if sorted_roots.windows(2).any(|w| w[0] == w[1]) {
        return bad("a node is listed twice among the roots".into());
    }
    // A cycle shows as a walk up the parents that is longer than the node count.
    for start in 0..node_count {
        let (mut at, mut steps) = (start, 0);
        while let Some(p) = parent[at] {
            at = p;
            steps += 1;
            if steps > node_count {
                return bad(format!("node {start} is its own ancestor (the node graph has a cycle)"));
            }
        }
    }
    Ok(())
}

/// A name safe for one OBJ/MTL token and a file name: ASCII letters, digits, `-`, `_` and `.`;
/// anything else becomes `_`.
pub(crate) fn sanitize_name(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') { c } else { '_' }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_replaces_and_cleans_up() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/deeper/out.bin");
        write_atomic(&path, b"first").unwrap();
        write_atomic(&path, b"second").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"second");
        let names: Vec<_> = fs::read_dir(path.parent().unwrap()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("out.bin")]);
    }

    #[test]
    fn failed_fill_keeps_old_file_and_removes_temp() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.txt");
        write_atomic(&path, b"old").unwrap();
        let err = write_atomic_with(&path, |w| {
            w.write_all(b"half of the new")?;
            Err(io::Error::other("simulated disk full"))
        })
        .unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("out.txt") && msg.contains("simulated disk full"), "{msg}");
        assert_eq!(fs::read(&path).unwrap(), b"old");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1, "temporary file left behind");
    }

    #[test]
    fn unknown_extension_lists_supported() {
        let err = write_scene(&Scene::default(), Path::new("x/out.fbx")).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("out.fbx") && msg.contains(".glb") && msg.contains(".obj"), "{msg}");
    }

    #[test]
    fn check_scene_rejects_bad_data() {
        use crate::mesh::{Mesh, Node, Primitive};
        let tri = Primitive {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            indices: vec![0, 2, 1],
            ..Primitive::default()
        };
        let mut scene = Scene::default();
        scene.add_mesh_node(Mesh { name: "m".into(), primitives: vec![tri.clone()], extras: None });
        assert_eq!(check_scene(&scene), Ok(()));

        let mut s = scene.clone();
        s.meshes[0].primitives[0].indices[1] = 7;
        assert!(check_scene(&s).unwrap_err().0.contains("index 1 is 7"));
        let mut s = scene.clone();
        s.meshes[0].primitives[0].positions[2][1] = f32::NAN;
        assert!(check_scene(&s).is_err());
        let mut s = scene.clone();
        s.meshes[0].primitives[0].normals = vec![[0.0, 2.0, 0.0]; 3];
        assert!(check_scene(&s).unwrap_err().0.contains("unit"));
        let mut s = scene.clone();
        s.nodes[0].rotation = [0.0, 0.0, 0.0, 1.0003]; // unit within tolerance, but w > 1
        assert!(check_scene(&s).unwrap_err().0.contains("rotation"));
        let mut s = scene.clone();
        s.nodes[0].children = vec![0];
        assert!(check_scene(&s).is_err(), "self-parent");
        let mut s = scene.clone();
        s.nodes.push(Node { children: vec![0], ..Node::default() });
        s.nodes[0].children = vec![1];
        assert!(check_scene(&s).unwrap_err().0.contains("root node 0 is also a child"));
        let mut s = scene.clone();
        s.nodes.push(Node { children: vec![2], ..Node::default() });
        s.nodes.push(Node { children: vec![1], ..Node::default() });
        assert!(check_scene(&s).unwrap_err().0.contains("cycle"));
    }
}
