//! What can be wrong with a preset, and how far parsing checks the input files it names.

use std::path::PathBuf;

/// Everything that can be wrong with a preset. Exit code 2 (bad input) for all of them.
#[derive(Debug, thiserror::Error)]
pub enum PresetError {
    /// The preset file itself could not be read.
    #[error("{}: cannot read the preset: {source}; check the path", file.display())]
    Read { file: PathBuf, source: std::io::Error },
    /// A problem at a place in the preset (syntax, unknown key, wrong type or value).
    #[error("{}:{line}:{column}: {problem}; {remedy}", file.display())]
    At { file: PathBuf, line: usize, column: usize, problem: String, remedy: String },
    /// An input file the preset names does not exist (`input` is the resolved path).
    #[error(
        "{}:{line}:{column}: {what} `{}` not found; paths are relative to the preset's folder — fix the path or create the file",
        file.display(),
        input.display()
    )]
    MissingInput { file: PathBuf, line: usize, column: usize, what: &'static str, input: PathBuf },
}

/// Always the input's.
impl crate::failure::Failure for PresetError {
    fn blame(&self) -> crate::failure::Blame {
        crate::failure::Blame::Input
    }
}

impl PresetError {
    /// Line and column (1-based, columns in characters) of the problem, where known.
    pub fn position(&self) -> Option<(usize, usize)> {
        match self {
            PresetError::Read { .. } => None,
            PresetError::At { line, column, .. } | PresetError::MissingInput { line, column, .. } => {
                Some((*line, *column))
            }
        }
    }
}

/// How far parsing checks the input files a preset names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Inputs {
    /// Not at all ([`parse_preset`]: no disk access).
    Unchecked,
    /// Each exists and is a file; `.ls` files parse ([`load_preset`], what a build needs first).
    Exist,
    /// Each also decodes as the preset reads it: the heightmap with its encoding, size and scale,
    /// density maps, masks and blade textures as images, OBJ models with their MTL and textures
    /// ([`check_preset`]: everything that does not need the build itself).
    Decode,
}

impl Inputs {
    pub(crate) fn exist(self) -> bool {
        self >= Inputs::Exist
    }
    pub(crate) fn decode(self) -> bool {
        self >= Inputs::Decode
    }
}
