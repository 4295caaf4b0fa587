//! An L-system as the parser resolves it: dialect, axiom, rules, recursion, and the errors.

use std::path::PathBuf;

use thiserror::Error;

/// Largest rewriting depth accepted (per file, all levels together). The expansion keeps one frame
/// per level, so this also bounds the expander's memory.
pub const MAX_RECURSION: u32 = 4096;

/// The three file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Dialect {
    /// The point-sprite thesis' stochastic format: `a-b-c` recursion levels, `X(100)=axiom`,
    /// `C(P)=R` rules with cumulative probabilities, `@`. Named `ls` on the command line.
    #[serde(rename = "ls")]
    Stochastic,
    /// lparser 4: positional lines (recursion, angle, thickness, axiom), `X=…` rules, `@`.
    #[serde(rename = "v4")]
    LparserV4,
    /// lparser 5: keyword lines (`recursion 12`, `rule X = …`, `color i r g b`, …).
    #[serde(rename = "v5")]
    LparserV5,
}

impl Dialect {
    /// The command-line name (`ls`, `v4`, `v5`).
    pub fn name(self) -> &'static str {
        match self {
            Dialect::Stochastic => "ls",
            Dialect::LparserV4 => "v4",
            Dialect::LparserV5 => "v5",
        }
    }
}

impl std::fmt::Display for Dialect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How many rewriting steps the axiom goes through.
#[derive(Debug, Clone, PartialEq)]
pub enum Recursion {
    /// lparser: every symbol is rewritten this many times; a fractional part (lparser 4) makes the
    /// last step grow partially (see [`expand`]).
    Steps(f64),
    /// The thesis' `a-b-c`: `a` steps for the whole string, then `b` more for the symbols inside at
    /// least one bracket (branch-tree level 2 and finer), then `c` more for those inside two, …
    PerLevel(Vec<u32>),
}

impl Recursion {
    /// Rewriting steps of each stage: `[ceil(n)]` for [`Recursion::Steps`], the levels otherwise.
    pub fn stage_steps(&self) -> Vec<u32> {
        match self {
            Recursion::Steps(n) => vec![n.max(0.0).ceil() as u32],
            Recursion::PerLevel(levels) => levels.clone(),
        }
    }

    /// The fraction of the last step that grows (0 when the depth is whole or per level).
    pub fn fraction(&self) -> f64 {
        match self {
            Recursion::Steps(n) if n.fract() > 0.0 => n.fract(),
            _ => 0.0,
        }
    }
}

/// One element of an axiom or successor: a symbol byte, or a numeric argument `(x)` that belongs to
/// whatever symbol ends up before it after rewriting (so `e=(19.47)` makes `^e` a 19.47° pitch).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Item {
    Symbol(u8),
    /// Index into [`LSystem::args`].
    Arg(u32),
}

/// A numeric argument as written (`(.77)` keeps `.77`, so printing gives back the file's text).
#[derive(Debug, Clone, PartialEq)]
pub struct ArgText {
    pub value: f64,
    /// The text between the parentheses.
    pub text: Vec<u8>,
}

/// One right-hand side of a rule and the cumulative probability (1..=100) up to which it is chosen.
#[derive(Debug, Clone, PartialEq)]
pub struct Variant {
    /// Cumulative distribution in percent: the variant is chosen for a uniform draw u in [0, 100)
    /// when u < `cumulative` and u ≥ the previous variant's. 100 for deterministic rules.
    pub cumulative: u8,
    pub successor: Vec<Item>,
}

/// All variants of one predecessor (one variant unless the dialect is stochastic).
#[derive(Debug, Clone, PartialEq)]
pub struct Rule {
    pub predecessor: u8,
    pub variants: Vec<Variant>,
}

/// A colour table entry from a v5 `color i r g b` line (0..255 per channel).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ColorLine {
    pub index: u16,
    pub rgb: [u8; 3],
}

/// A parsed L-system. Equal systems print to identical text ([`LSystem::print`]).
#[derive(Debug, Clone, PartialEq)]
pub struct LSystem {
    pub dialect: Dialect,
    pub recursion: Recursion,
    /// Default turning angle in degrees.
    pub angle_deg: f64,
    /// Default segment diameter in percent of its length.
    pub thickness_pct: f64,
    /// v5 `min_thickness`: smallest diameter, in percent of the default step length.
    pub min_thickness_pct: Option<f64>,
    /// v5 `shape` (1: attached cylinders, else blocks). Kept for printing; verdant always draws
    /// connected cylinders.
    pub shape: Option<f64>,
    /// v5 `switch_yz`. Kept for printing; verdant always turns the turtle's sky to +Y by a rotation
    /// (lparser swapped two axes, a mirror image).
    pub switch_yz: Option<i64>,
    pub colors: Vec<ColorLine>,
    pub axiom: Vec<Item>,
    /// At most one rule per predecessor, in file order.
    pub rules: Vec<Rule>,
    /// The arguments the axiom and rules refer to, numbered in print order (axiom, then rules).
    pub args: Vec<ArgText>,
}

impl LSystem {
    /// The rule rewriting `symbol`, if any.
    pub fn rule(&self, symbol: u8) -> Option<&Rule> {
        self.rules.iter().find(|r| r.predecessor == symbol)
    }

    /// Whether some rule has more than one variant.
    pub fn is_stochastic(&self) -> bool {
        self.rules.iter().any(|r| r.variants.len() > 1)
    }

    /// Whether the seed changes the tree: a stochastic rule or a random turn `~` somewhere.
    /// (Trees grown from a system without either are identical whatever the seed.)
    pub fn uses_seed(&self) -> bool {
        let random_turn = |items: &[Item]| items.contains(&Item::Symbol(b'~'));
        self.is_stochastic()
            || random_turn(&self.axiom)
            || self.rules.iter().flat_map(|r| &r.variants).any(|v| random_turn(&v.successor))
    }
}

/// Everything that can go wrong reading or expanding an L-system.
#[derive(Debug, Error)]
pub enum LsystemError {
    #[error("cannot read {path}: {source}; check that the file exists and is readable")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A positioned problem in the file: `file:line:column: message`, the line, a caret, the remedy.
    #[error("{0}")]
    Syntax(Box<SyntaxError>),
    #[error(
        "the expansion {} the budget of {limit} symbols; lower the recursion depth, or raise the budget \
         (`--max-symbols N` for `verdant tree`, `max_symbols = N` in a preset's `[tree]` or a species' `tree = {{ … }}`)",
        match at_least { Some(n) => format!("has at least {n} symbols, over"), None => "exceeds".to_string() }
    )]
    TooManySymbols { limit: u64, at_least: Option<u64> },
    #[error("invalid expansion settings: {0}")]
    Settings(String),
}

/// Always the input's: a file that does not read or parse, settings or a budget it exceeds.
impl crate::failure::Failure for LsystemError {
    fn blame(&self) -> crate::failure::Blame {
        crate::failure::Blame::Input
    }
}

/// Where and what is wrong in an `.ls` file.
#[derive(Debug, Error)]
#[error("{}:{line}:{column}: {message}\n  {text}\n  {caret}\n{remedy}", path.display())]
pub struct SyntaxError {
    pub path: PathBuf,
    /// 1-based.
    pub line: usize,
    /// 1-based, in characters of the line as shown (undecodable bytes count one each).
    pub column: usize,
    pub message: String,
    /// The line, lossily decoded (a window around the column when it is long).
    pub text: String,
    /// Blanks (tabs where the line has tabs) and a `^` under the column.
    pub caret: String,
    pub remedy: String,
}
