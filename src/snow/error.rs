//! The snow module's one error type and the checks its settings share.

/// The one error type of the snow module: a setting out of range (named, with its remedy), a JSON
/// document that does not parse (with line and column), or a bake / input-scene failure.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SnowError {
    #[error("snow setting `{key}` {problem}; {remedy}")]
    Setting { key: &'static str, problem: String, remedy: String },
    #[error("{source_name}: line {line}, column {column}: {message}; fix the emitter JSON (see docs/snow.md)")]
    Json { source_name: String, line: usize, column: usize, message: String },
    #[error("baking the snow flake atlas failed: {0}")]
    Bake(String),
    #[error("terrain scene for snow cover: {0}")]
    Terrain(String),
    /// A file could not be written (the export error's message names the file and the remedy).
    #[error("{0}")]
    Write(String),
}

/// The input's for settings and JSON; the build's for a bake, the terrain it was given or a write.
impl crate::failure::Failure for SnowError {
    fn blame(&self) -> crate::failure::Blame {
        match self {
            SnowError::Setting { .. } | SnowError::Json { .. } => crate::failure::Blame::Input,
            SnowError::Bake(_) | SnowError::Terrain(_) | SnowError::Write(_) => crate::failure::Blame::Build,
        }
    }
}

pub(crate) fn bad<T>(key: &'static str, problem: String, remedy: &str) -> Result<T, SnowError> {
    Err(SnowError::Setting { key, problem, remedy: remedy.into() })
}

/// `v` is finite and inside `[lo, hi]`.
pub(crate) fn within(v: f32, lo: f32, hi: f32) -> bool {
    v.is_finite() && lo <= v && v <= hi
}
