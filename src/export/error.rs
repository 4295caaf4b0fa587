//! What writing can fail with: the export error and a scene a writer cannot write.

use std::io;
use std::path::{Path, PathBuf};

use thiserror::Error;

/// Extensions [`write_scene`] understands, for messages.
pub const SUPPORTED_EXTENSIONS: &str = ".glb, .gltf (+ .bin), .obj (+ .mtl, .png)";

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

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SceneProblem(pub String);

impl std::fmt::Display for SceneProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for SceneProblem {}

impl SceneProblem {
    pub(crate) fn at(path: &Path) -> impl FnOnce(SceneProblem) -> ExportError + '_ {
        move |p| ExportError::InvalidScene { path: path.to_path_buf(), problem: p.0 }
    }
}
