//! What validation is asked for, what it may fail with, and what a loader hands the checks.

use std::io;
use std::path::PathBuf;

use thiserror::Error;

use crate::mesh::{Bounds, Scene};
use crate::validate::report::Issue;

/// |length − 1| above which a normal is reported.
pub const NORMAL_TOLERANCE: f64 = 1e-3;
/// How many occurrences of one problem in one primitive are listed before a summary line.
pub(super) const MAX_LISTED: usize = 5;

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

/// A file turned into a [`Scene`], with the problems met on the way and, for glTF, the declared
/// POSITION min/max of every primitive (`declared_bounds[mesh][primitive]`).
pub(super) struct Loaded {
    pub scene: Scene,
    pub issues: Vec<Issue>,
    pub declared_bounds: Vec<Vec<Option<Bounds>>>,
    /// Per mesh: positions stored as integers (KHR_mesh_quantization), placed by their node.
    pub quantized: Vec<bool>,
    /// Per mesh: the grid its extras note (verdant's quantized files).
    pub grids: Vec<Option<crate::export::grid::PositionGrid>>,
}
