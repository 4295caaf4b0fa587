//! What a failure means to the person who ran verdant: their input is at fault (a file, a preset,
//! an option, an exceeded limit: fix it and run again) or the build itself failed (a write, a
//! broken bound, an output that does not validate). Every error the command line can end with says
//! which through [`Failure`]; `main` maps that to the exit code in one place (2 and 1).

/// Who has to act.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Blame {
    /// Bad input or usage: exit code 2.
    Input,
    /// A failure of the build, the writing or the validation of its outputs: exit code 1.
    Build,
}

impl Blame {
    /// The process exit code: 2 for [`Blame::Input`], 1 for [`Blame::Build`].
    pub const fn exit_code(self) -> i32 {
        match self {
            Blame::Input => 2,
            Blame::Build => 1,
        }
    }
}

/// An error that knows whose it is.
pub trait Failure: std::fmt::Display {
    fn blame(&self) -> Blame;

    /// [`Blame::exit_code`] of [`Failure::blame`].
    fn exit_code(&self) -> i32 {
        self.blame().exit_code()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn input_is_two_and_build_is_one() {
        assert_eq!(Blame::Input.exit_code(), 2);
        assert_eq!(Blame::Build.exit_code(), 1);
    }
}
