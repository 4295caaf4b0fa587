//! The errors of a scene build: a stage's, and the build's as a whole. Each says whose it is
//! ([`Failure`]): a bad input (a heightmap that does not decode, an L-system that does not parse, a
//! species above its limits) exits 2, a failure of the build itself (a write, an invalid output) 1.

use std::path::PathBuf;

use crate::failure::{Blame, Failure};
use crate::scene::preset::PresetError;

/// A stage that could not finish: which stage, whose fault, what happened.
#[derive(Debug, thiserror::Error)]
pub enum StageError {
    /// Its input is at fault: a file that does not read or decode, settings the stage refuses, an
    /// exceeded limit.
    #[error("{stage} stage: {message}")]
    Input { stage: &'static str, message: String },
    /// The stage itself failed: a write, an encoding, an output that does not read back.
    #[error("{stage} stage: {message}")]
    Failed { stage: &'static str, message: String },
}

impl StageError {
    /// `message` with the blame `e` carries (a typed error of a lower module).
    pub fn of(stage: &'static str, e: &dyn Failure, message: String) -> StageError {
        match e.blame() {
            Blame::Input => StageError::Input { stage, message },
            Blame::Build => StageError::Failed { stage, message },
        }
    }
}

impl Failure for StageError {
    fn blame(&self) -> Blame {
        match self {
            StageError::Input { .. } => Blame::Input,
            StageError::Failed { .. } => Blame::Build,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum SceneBuildError {
    #[error(transparent)]
    Preset(#[from] PresetError),
    #[error(transparent)]
    Stage(#[from] StageError),
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("{0}")]
    Usage(String),
}

/// The input's for a preset that does not parse or names what is not there, stages that cannot run
/// alone and a stage's bad input; the build's for a stage that failed and a file it could not write.
impl Failure for SceneBuildError {
    fn blame(&self) -> Blame {
        match self {
            SceneBuildError::Preset(e) => e.blame(),
            SceneBuildError::Usage(_) => Blame::Input,
            SceneBuildError::Stage(e) => e.blame(),
            SceneBuildError::Io { .. } => Blame::Build,
        }
    }
}
