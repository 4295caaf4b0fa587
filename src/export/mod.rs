//! Writers: glTF 2.0 (.glb, .gltf + .bin), OBJ + MTL. All writes are atomic.
//!
//! Every writer first checks the whole [`Scene`] (indices in range, finite values, unit normals and
//! quaternions, a tree-shaped node graph), then builds every output file in memory, and only then
//! writes them as one [`FileSet`] (each file staged whole beside its final path, then all renamed
//! into place): a scene that cannot be written leaves the previous outputs untouched, and a .gltf
//! is never left beside a .bin it was not written with.

pub mod atomic;
pub mod check;
pub mod compact;
pub mod error;
pub mod gltf;
pub mod grid;
pub mod obj;
pub mod quantize;
pub mod streaming;
pub mod table;
pub mod table_bin;

use std::ffi::OsStr;
use std::path::{Path, PathBuf};

pub use atomic::{write_atomic, write_atomic_with, FileSet};
pub use check::{check_scene, UNIT_LENGTH_TOLERANCE};
pub use error::{ExportError, SceneProblem, SUPPORTED_EXTENSIONS};

use crate::mesh::Scene;

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
    // replaced as a set: a .gltf never meets a .bin it was not written with
    let mut set = FileSet::new();
    stage_scene_with(&mut set, scene, path, opts)?;
    set.commit()
}

/// [`write_scene_with`] into `set` (to be committed with other files, e.g. a report); returns the
/// paths staged, in order.
pub fn stage_scene_with(
    set: &mut FileSet,
    scene: &Scene,
    path: &Path,
    opts: &gltf::WriteOptions,
) -> Result<Vec<PathBuf>, ExportError> {
    let ext = path.extension().and_then(OsStr::to_str).unwrap_or("").to_ascii_lowercase();
    let stem = match path.file_stem().and_then(OsStr::to_str) {
        Some(s) if !s.is_empty() => s.to_string(),
        _ => return Err(ExportError::NoFileName { path: path.to_path_buf() }),
    };
    let sibling = |name: &str| path.with_file_name(name);
    // Build everything first, write afterwards: a scene error never touches the disk.
    let files: Vec<(PathBuf, Vec<u8>)> = match ext.as_str() {
        "glb" => {
            // streamed from its chunks: a large scene's container is never a third copy in memory
            let glb = gltf::to_glb_parts(scene, opts).map_err(SceneProblem::at(path))?;
            set.write_with(path, |w| glb.write(w))?;
            return Ok(vec![path.to_path_buf()]);
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
        "obj" if opts.quantization.is_on() => {
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
    let mut staged = Vec::with_capacity(files.len());
    for (file, bytes) in files {
        set.write(&file, &bytes)?;
        staged.push(file);
    }
    Ok(staged)
}

#[cfg(test)]
mod tests {
    use std::{fs, io};

    use super::*;

    #[test]
    fn a_file_set_replaces_nothing_until_it_commits_and_leaves_nothing_when_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("x.gltf"), dir.path().join("x.bin"));
        write_atomic(&a, b"old json").unwrap();
        write_atomic(&b, b"old bin").unwrap();
        let names = || {
            let mut n: Vec<String> =
                fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into()).collect();
            n.sort();
            n
        };
        // staged: the old pair is untouched, the new bytes wait in hidden files ending in the
        // real extension
        let mut set = FileSet::new();
        set.write(&b, b"new bin").unwrap();
        set.write(&a, b"new json").unwrap();
        let staged = set.staged(&a).unwrap().to_path_buf();
        assert_eq!(fs::read(&staged).unwrap(), b"new json");
        assert!(staged.file_name().unwrap().to_string_lossy().starts_with(".x.gltf."));
        assert_eq!(staged.extension().unwrap(), "gltf");
        assert_eq!((fs::read(&a).unwrap(), fs::read(&b).unwrap()), (b"old json".to_vec(), b"old bin".to_vec()));
        // dropped without a commit (an error on the way): the old pair, nothing else
        drop(set);
        assert_eq!(names(), ["x.bin", "x.gltf"]);
        assert_eq!(fs::read(&a).unwrap(), b"old json");
        // committed: both new, in the order written; nothing else
        let mut set = FileSet::new();
        set.write(&b, b"new bin").unwrap();
        set.write(&a, b"first try").unwrap();
        set.write(&a, b"new json").unwrap();
        assert_eq!(set.commit().unwrap(), vec![b.clone(), a.clone()]);
        assert_eq!((fs::read(&a).unwrap(), fs::read(&b).unwrap()), (b"new json".to_vec(), b"new bin".to_vec()));
        assert_eq!(names(), ["x.bin", "x.gltf"]);
        // a path that is a folder is refused while staging: the set writes nothing
        fs::create_dir(dir.path().join("y.bin")).unwrap();
        let mut set = FileSet::new();
        set.write(&a, b"newer json").unwrap();
        assert!(set.write(&dir.path().join("y.bin"), b"bin").is_err());
        drop(set);
        assert_eq!(fs::read(&a).unwrap(), b"new json");
        assert_eq!(names(), ["x.bin", "x.gltf", "y.bin"]);
    }

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
