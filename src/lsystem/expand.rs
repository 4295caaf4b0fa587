//! Depth-first streaming rewriting: the derivation of an L-system (Lindenmayer 1968; ABOP §1.2) is
//! walked as a tree, one stack frame per rewriting step, and its leaves come out left to right as
//! [`Token`]s. The expanded string (lparser caps it at 2–4 MiB) never exists: memory grows with the
//! recursion depth, not with the expanded length, so 10⁸ symbols and more stream in constant space.
//!
//! Stochastic choices (the thesis' `C(P)=R`) hash the seed with the symbol's *position in the
//! derivation* — the path of successor indices from the axiom — so a tree is reproducible and
//! independent of evaluation order: any other traversal that numbers positions the same way makes
//! the same choices.
//!
//! Recursion: lparser 4's fractional depth `n + f` rewrites ⌈n + f⌉ times and wraps the last step's
//! successors (of every symbol but the drawing ones `F f Z z`, as lparser does) in
//! [`Token::PartialBegin`]/[`Token::PartialEnd`]: the turtle grows them by the fraction f. The
//! thesis' per-level `a-b-c` rewrites everything `a` times, then the symbols inside at least one
//! bracket `b` more times, then those inside two `c` more times (see [`Expander`]).

use super::system::{Item, LSystem, LsystemError, Recursion};
use crate::random::mix64;

/// Default budget of expanded symbols: 5·10⁷, about 12 times what lparser itself can hold (it caps
/// the string at 2–4 MiB), and about 3 s of expansion on this project's reference machine (10⁹
/// took a minute).
pub const DEFAULT_MAX_SYMBOLS: u64 = 50_000_000;

/// The fewest symbols any derivation of a single-stage system can have (each step's shortest
/// successor taken everywhere), saturating; `None` for per-level recursion. Lets a budget refuse
/// `A=AA` at depth 60 at once instead of after expanding 10⁹ symbols.
pub fn fewest_symbols(system: &LSystem) -> Option<u128> {
    let steps = system.recursion.stage_steps();
    if steps.len() != 1 {
        return None;
    }
    let mut rule_of = [usize::MAX; 256];
    for (k, rule) in system.rules.iter().enumerate() {
        if rule_of[rule.predecessor as usize] == usize::MAX && !rule.variants.is_empty() {
            rule_of[rule.predecessor as usize] = k;
        }
    }
    let cap = u128::MAX / 4;
    let length = |items: &[Item], len: &[u128; 256]| -> u128 {
        items.iter().fold(0u128, |acc, it| match it {
            Item::Symbol(b) => acc.saturating_add(len[*b as usize]).min(cap),
            Item::Arg(_) => acc,
        })
    };
    // len[b]: the shortest expansion of symbol b after t more steps
    let mut len = [1u128; 256];
    for _ in 0..steps[0] {
        let mut next = len;
        for (b, &k) in rule_of.iter().enumerate() {
            if k != usize::MAX {
                next[b] = system.rules[k].variants.iter().map(|v| length(&v.successor, &len)).min().unwrap_or(1);
            }
        }
        len = next;
    }
    Some(length(&system.axiom, &len))
}

/// The position id of the axiom's (virtual) parent.
const ROOT_ID: u64 = 0x243F_6A88_85A3_08D3;
/// Salt of the rule-choice hash (the turtle's random turns use another).
const CHOICE_SALT: u64 = 0x6368_6f69_6365_0001;

/// One element of the expanded string.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Token {
    /// A symbol and its position id in the derivation (see [`child_id`]).
    Symbol {
        byte: u8,
        id: u64,
    },
    /// A numeric argument: it belongs to the symbol before it. `index` points into
    /// [`LSystem::args`] (for the text as written).
    Arg {
        value: f64,
        index: u32,
    },
    /// Start and end of a successor produced by the partial last step of a fractional recursion.
    PartialBegin,
    PartialEnd,
}

/// What an expansion produced, counted while streaming.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct Counts {
    /// Symbols (modules) of the expanded string; arguments are not counted.
    pub symbols: u64,
    /// Length of the expanded string as lparser would build it: symbols plus argument text with
    /// its parentheses.
    pub string_bytes: u64,
    /// Most frames the expansion held at once (the memory it used is proportional).
    pub peak_frames: usize,
    /// Deepest `[` nesting of the expanded string.
    pub max_bracket_depth: u64,
}

/// Position id of item `index` of the successor that replaced the symbol with id `parent`.
#[inline]
pub fn child_id(parent: u64, index: usize) -> u64 {
    mix64(parent.rotate_left(23) ^ (index as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

/// Position id of axiom item `index`.
#[inline]
pub fn axiom_id(index: usize) -> u64 {
    child_id(ROOT_ID, index)
}

/// Which variant of a rule with these cumulative distributions a symbol with position id `id`
/// takes: a uniform draw u in [0, 100) from hash(seed, id), the first variant with u < its value.
pub fn choose_variant(cumulative: &[u8], seed: u64, id: u64) -> usize {
    if cumulative.len() <= 1 {
        return 0;
    }
    let h = mix64(id ^ mix64(seed ^ CHOICE_SALT));
    let u = (h >> 11) as f64 / (1u64 << 53) as f64 * 100.0;
    cumulative.iter().position(|&c| u < c as f64).unwrap_or(cumulative.len() - 1)
}

const fn single_symbols() -> [Item; 256] {
    let mut items = [Item::Symbol(0); 256];
    let mut i = 0;
    while i < 256 {
        items[i] = Item::Symbol(i as u8);
        i += 1;
    }
    items
}

/// One-symbol strings, for symbols that enter a later stage of a per-level recursion.
static SINGLE_SYMBOLS: [Item; 256] = single_symbols();

/// Lparser's drawing symbols, whose successors are never marked partial.
fn grows_fully(symbol: u8) -> bool {
    matches!(symbol, b'F' | b'f' | b'Z' | b'z')
}

struct Frame<'a> {
    items: &'a [Item],
    pos: u32,
    /// Rewriting steps still to apply to the items of this frame (within its stage).
    remaining: u32,
    stage: u8,
    /// Emit [`Token::PartialEnd`] when exhausted.
    partial: bool,
    id: u64,
}

/// The streaming expansion of one system: call [`Expander::next_token`] until it returns `None`.
///
/// Per-level recursion, stage by stage: stage 0 rewrites the axiom `levels[0]` times, giving the
/// string S₀; stage k ≥ 1 rewrites the symbols of S_{k−1} that lie inside at least k brackets
/// `levels[k]` more times (the rest pass unchanged), giving S_k. The stages run interleaved
/// depth-first, each keeping the bracket depth of its own string.
pub struct Expander<'a> {
    system: &'a LSystem,
    /// `rule_of[b]` = index + 1 into `system.rules`, or 0.
    rule_of: [u16; 256],
    cumulative: Vec<Vec<u8>>,
    stage_steps: Vec<u32>,
    fraction: f64,
    seed: u64,
    frames: Vec<Frame<'a>>,
    /// Bracket depth of each stage's string so far.
    stage_depth: Vec<u64>,
    counts: Counts,
    max_symbols: u64,
}

impl<'a> Expander<'a> {
    pub fn new(system: &'a LSystem, seed: u64, max_symbols: u64) -> Result<Self, LsystemError> {
        let stage_steps = system.recursion.stage_steps();
        if stage_steps.is_empty() {
            return Err(LsystemError::Settings("the recursion has no levels".into()));
        }
        let total: u64 = stage_steps.iter().map(|&s| s as u64).sum();
        if total > super::MAX_RECURSION as u64 {
            return Err(LsystemError::Settings(format!(
                "{total} rewriting steps is over the limit of {}",
                super::MAX_RECURSION
            )));
        }
        if let Recursion::Steps(n) = system.recursion {
            if !(n.is_finite() && n >= 0.0) {
                return Err(LsystemError::Settings(format!("recursion depth {n} is not a number ≥ 0")));
            }
        }
        if let Some(fewest) = fewest_symbols(system) {
            if fewest > max_symbols as u128 {
                return Err(LsystemError::TooManySymbols {
                    limit: max_symbols,
                    at_least: Some(fewest.min(u64::MAX as u128) as u64),
                });
            }
        }
        let mut rule_of = [0u16; 256];
        for (k, rule) in system.rules.iter().enumerate().take(u16::MAX as usize - 1) {
            if rule_of[rule.predecessor as usize] == 0 && !rule.variants.is_empty() {
                rule_of[rule.predecessor as usize] = k as u16 + 1;
            }
        }
        let cumulative = system.rules.iter().map(|r| r.variants.iter().map(|v| v.cumulative).collect()).collect();
        let mut expander = Expander {
            system,
            rule_of,
            cumulative,
            fraction: system.recursion.fraction(),
            seed,
            frames: Vec::with_capacity(total as usize + stage_steps.len() + 1),
            stage_depth: vec![0; stage_steps.len()],
            stage_steps,
            counts: Counts::default(),
            max_symbols,
        };
        let axiom_steps = expander.stage_steps[0];
        expander.frames.push(Frame {
            items: &system.axiom,
            pos: 0,
            remaining: axiom_steps,
            stage: 0,
            partial: false,
            id: ROOT_ID,
        });
        expander.counts.peak_frames = 1;
        Ok(expander)
    }

    /// What has been produced so far (all of it once [`Expander::next_token`] returned `None`).
    pub fn counts(&self) -> Counts {
        self.counts
    }

    fn push(&mut self, frame: Frame<'a>) {
        self.frames.push(frame);
        self.counts.peak_frames = self.counts.peak_frames.max(self.frames.len());
    }

    /// The next token of the expanded string, or `None` at its end.
    pub fn next_token(&mut self) -> Result<Option<Token>, LsystemError> {
        loop {
            let Some(top) = self.frames.last_mut() else { return Ok(None) };
            if top.pos as usize == top.items.len() {
                let partial = top.partial;
                self.frames.pop();
                if partial {
                    return Ok(Some(Token::PartialEnd));
                }
                continue;
            }
            let index = top.pos as usize;
            let item = top.items[index];
            top.pos += 1;
            let (remaining, stage, parent) = (top.remaining, top.stage as usize, top.id);
            let symbol = match item {
                Item::Arg(a) => {
                    // arguments are never rewritten: they pass every stage unchanged
                    let arg = &self.system.args[a as usize];
                    self.counts.string_bytes += arg.text.len() as u64 + 2;
                    return Ok(Some(Token::Arg { value: arg.value, index: a }));
                }
                Item::Symbol(b) => b,
            };
            let id = child_id(parent, index);
            let rule = self.rule_of[symbol as usize];
            if remaining > 0 && rule != 0 {
                let k = rule as usize - 1;
                let v = choose_variant(&self.cumulative[k], self.seed, id);
                let successor = &self.system.rules[k].variants[v].successor;
                let partial = remaining == 1 && self.fraction > 0.0 && !grows_fully(symbol);
                self.push(Frame {
                    items: successor,
                    pos: 0,
                    remaining: remaining - 1,
                    stage: stage as u8,
                    partial,
                    id,
                });
                if partial {
                    return Ok(Some(Token::PartialBegin));
                }
                continue;
            }
            // final in `stage`: it is part of that stage's string; later stages may rewrite it
            let mut s = stage;
            let mut enters_stage = None;
            loop {
                let depth = self.stage_depth[s];
                match symbol {
                    b'[' => self.stage_depth[s] += 1,
                    b']' => self.stage_depth[s] = depth.saturating_sub(1),
                    _ => {}
                }
                if s + 1 == self.stage_steps.len() {
                    break;
                }
                s += 1;
                if rule != 0 && self.stage_steps[s] > 0 && depth >= s as u64 {
                    enters_stage = Some(s);
                    break;
                }
            }
            if let Some(s) = enters_stage {
                let single = &SINGLE_SYMBOLS[symbol as usize..symbol as usize + 1];
                self.push(Frame {
                    items: single,
                    pos: 0,
                    remaining: self.stage_steps[s],
                    stage: s as u8,
                    partial: false,
                    id,
                });
                continue;
            }
            if self.counts.symbols >= self.max_symbols {
                return Err(LsystemError::TooManySymbols { limit: self.max_symbols, at_least: None });
            }
            self.counts.symbols += 1;
            self.counts.string_bytes += 1;
            let last = self.stage_steps.len() - 1;
            self.counts.max_bracket_depth = self.counts.max_bracket_depth.max(self.stage_depth[last]);
            return Ok(Some(Token::Symbol { byte: symbol, id }));
        }
    }
}

/// Counts the expansion of `system` without keeping it.
pub fn count(system: &LSystem, seed: u64, max_symbols: u64) -> Result<Counts, LsystemError> {
    let mut e = Expander::new(system, seed, max_symbols)?;
    while e.next_token()?.is_some() {}
    Ok(e.counts())
}

/// The expanded string as lparser would print it (arguments as written). Materialises it: for
/// small systems, tests and debugging; partial-growth markers are left out.
pub fn expand_to_bytes(system: &LSystem, seed: u64, max_symbols: u64) -> Result<Vec<u8>, LsystemError> {
    let mut e = Expander::new(system, seed, max_symbols)?;
    let mut out = Vec::new();
    while let Some(t) = e.next_token()? {
        match t {
            Token::Symbol { byte, .. } => out.push(byte),
            Token::Arg { index, .. } => system.items_text(&[Item::Arg(index)]).iter().for_each(|&b| out.push(b)),
            Token::PartialBegin | Token::PartialEnd => {}
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lsystem::parse::parse_bytes;
    use crate::lsystem::Dialect;
    use std::path::Path;

    fn sys(text: &str) -> LSystem {
        parse_bytes(text.as_bytes(), Path::new("t.ls"), None).unwrap().system
    }

    #[test]
    fn streams_like_parallel_rewriting() {
        let s = sys("3\n10\n10\nF+A(3)\nA=F[-A](2)B\nB=AB\n@\n");
        for steps in 0..5 {
            let mut s = s.clone();
            s.recursion = Recursion::Steps(steps as f64);
            assert_eq!(expand_to_bytes(&s, 0, 10_000).unwrap(), reference(&s, steps), "{steps} steps");
        }
        assert_eq!(expand_to_bytes(&s, 0, 100).unwrap()[..16].to_vec(), b"F+F[-F[-F[-A](2)".to_vec());
    }

    /// Parallel rewriting on a materialised string, arguments kept atomic.
    fn reference(s: &LSystem, steps: u32) -> Vec<u8> {
        let mut cur = s.axiom.clone();
        for _ in 0..steps {
            let mut next = Vec::new();
            for item in &cur {
                match item {
                    Item::Symbol(b) => match s.rule(*b) {
                        Some(r) => next.extend_from_slice(&r.variants[0].successor),
                        None => next.push(*item),
                    },
                    Item::Arg(_) => next.push(*item),
                }
            }
            cur = next;
        }
        s.items_text(&cur)
    }

    #[test]
    fn symbol_budget_is_an_error() {
        let s = sys("10\n10\n10\nF\nF=FF\n@\n");
        assert_eq!(count(&s, 0, u64::MAX).unwrap().symbols, 1024);
        let e = count(&s, 0, 1000).unwrap_err();
        assert!(matches!(e, LsystemError::TooManySymbols { limit: 1000, .. }), "{e}");
    }

    #[test]
    fn fractional_recursion_marks_the_last_step() {
        let s = sys("1.5\n10\n10\nAF\nA=+B\nB=-F\nF=FF\n@\n");
        assert_eq!(s.recursion.stage_steps(), vec![2]);
        let mut e = Expander::new(&s, 0, 100).unwrap();
        let mut text = String::new();
        while let Some(t) = e.next_token().unwrap() {
            text.push(match t {
                Token::Symbol { byte, .. } => byte as char,
                Token::PartialBegin => '<',
                Token::PartialEnd => '>',
                Token::Arg { .. } => '(',
            });
        }
        // the second step is partial: B's successor is marked, F's (a drawing symbol) is not
        assert_eq!(text, "+<-F>FFFF");
    }

    #[test]
    fn per_level_recursion_rewrites_inner_branches_more() {
        // stage 0 once: FA → F[B]A ; stage 1 (depth ≥ 1) once more: B → BB inside the bracket only
        let s = parse_bytes(b"1-1\n30\n20\nX(100)=A\nA(100)=F[B]A\nB(100)=BB\n@\n", Path::new("t.ls"), None)
            .unwrap()
            .system;
        assert_eq!(s.dialect, Dialect::Stochastic);
        assert_eq!(expand_to_bytes(&s, 0, 100).unwrap(), b"F[BB]A");
        // 2-1: S0 = F[BB]F[B]A; stage 1 rewrites the Bs (inside brackets), not the outer A
        let s = parse_bytes(b"2-1\n30\n20\nX(100)=A\nA(100)=F[B]A\nB(100)=BB\n@\n", Path::new("t.ls"), None)
            .unwrap()
            .system;
        assert_eq!(expand_to_bytes(&s, 0, 100).unwrap(), b"F[BBBB]F[BB]A");
    }

    #[test]
    fn choices_follow_the_distribution_and_the_seed() {
        let cumulative = [30u8, 75, 100];
        let mut hits = [0usize; 3];
        for i in 0..30_000 {
            hits[choose_variant(&cumulative, 7, axiom_id(i))] += 1;
        }
        let p: [f64; 3] = [0.30, 0.45, 0.25];
        for k in 0..3 {
            let (n, expected) = (30_000.0f64, 30_000.0 * p[k]);
            let sigma = (n * p[k] * (1.0 - p[k])).sqrt();
            assert!((hits[k] as f64 - expected).abs() < 3.0 * sigma, "{hits:?}");
        }
        assert_eq!(choose_variant(&[100], 1, 2), 0);
    }
}
