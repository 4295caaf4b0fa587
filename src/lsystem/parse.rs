//! Reading and printing the three `.ls` dialects: lparser 4's positional lines, lparser 5's keyword
//! lines (Laurens Lapré's lparser documentation and example files) and the stochastic format of the
//! point-sprite L-system thesis (§3.2). Files are bytes, not UTF-8: real ones carry CP437 comments.
//!
//! Every problem is reported as `file:line:column`, with the line, a caret under the column and what
//! to do. [`print`] writes a system back in its own dialect; parsing that text gives an equal system.

use std::path::Path;

use super::system::{
    ArgText, ColorLine, Dialect, Item, LSystem, LsystemError, Recursion, Rule, SyntaxError, Variant, MAX_RECURSION,
};

/// A parsed file and the remarks that did not stop it (shadowed rules, ignored keywords).
#[derive(Debug, Clone, PartialEq)]
pub struct Parsed {
    pub system: LSystem,
    /// Whether the dialect was detected (true) or forced by the caller (false).
    pub detected: bool,
    pub warnings: Vec<String>,
}

/// Reads and parses `path`; `dialect` None detects it from the content ([`detect`]).
pub fn read_file(path: &Path, dialect: Option<Dialect>) -> Result<Parsed, LsystemError> {
    // `builtin:<name>` is a library source (crate::lsystem::library), not a file
    let bytes =
        super::library::read_bytes(path).map_err(|source| LsystemError::Read { path: path.to_path_buf(), source })?;
    parse_bytes(&bytes, path, dialect)
}

/// A character of an echoed source line as shown: tabs kept (the caret line repeats them),
/// other control characters escaped.
fn shown(c: char) -> String {
    if c == '\t' {
        "\t".to_string()
    } else {
        crate::input::escape(&c.to_string())
    }
}

/// Parses the contents of a file; `path` only names it in messages.
pub fn parse_bytes(bytes: &[u8], path: &Path, dialect: Option<Dialect>) -> Result<Parsed, LsystemError> {
    let source = Source::new(bytes, path);
    let detected = dialect.is_none();
    let dialect = dialect.unwrap_or_else(|| detect(bytes));
    let mut warnings = Vec::new();
    let mut system = match dialect {
        Dialect::LparserV4 => parse_v4(&source, &mut warnings)?,
        Dialect::LparserV5 => parse_v5(&source, &mut warnings)?,
        Dialect::Stochastic => parse_stochastic(&source, &mut warnings)?,
    };
    renumber_args(&mut system);
    Ok(Parsed { system, detected, warnings })
}

/// The dialect of a file: v5 when its first line (past comments) starts with a v5 keyword; the
/// thesis' stochastic format when that line reads like `3-2-2` or some line like `A(40)=…`;
/// lparser 4 otherwise.
pub fn detect(bytes: &[u8]) -> Dialect {
    let source = Source::new(bytes, Path::new(""));
    let mut functional = source.lines.iter().filter(|l| !is_comment_or_blank(l.bytes));
    let Some(first) = functional.next() else { return Dialect::LparserV4 };
    let word = first_word(first.bytes);
    if V5_KEYWORDS.iter().any(|k| k.as_bytes() == word) {
        return Dialect::LparserV5;
    }
    let token = first_token(first.bytes).1;
    let is_levels = token.contains(&b'-') && token.iter().all(|&b| b.is_ascii_digit() || b == b'-');
    if is_levels || source.lines.iter().any(|l| looks_stochastic_rule(first_token(l.bytes).1)) {
        return Dialect::Stochastic;
    }
    Dialect::LparserV4
}

/// `C(P)=`: one byte, a parenthesised whole number, `=`.
fn looks_stochastic_rule(token: &[u8]) -> bool {
    if token.len() < 5 || token[1] != b'(' {
        return false;
    }
    match token[2..].iter().position(|&b| b == b')') {
        Some(close) => {
            let digits = &token[2..2 + close];
            !digits.is_empty() && digits.iter().all(u8::is_ascii_digit) && token.get(3 + close) == Some(&b'=')
        }
        None => false,
    }
}

const V5_KEYWORDS: [&str; 13] = [
    "recursion",
    "angle",
    "thickness",
    "min_thickness",
    "shape",
    "switch_yz",
    "color",
    "axiom",
    "rule",
    "mutation",
    "trace",
    "no_wait",
    "poly_limit",
];

// ---------------------------------------------------------------------------------------------
// lines, tokens and positioned errors

struct Line<'a> {
    /// 1-based.
    number: usize,
    /// Without the line end (LF or CRLF).
    bytes: &'a [u8],
}

struct Source<'a> {
    path: &'a Path,
    lines: Vec<Line<'a>>,
}

impl<'a> Source<'a> {
    fn new(bytes: &'a [u8], path: &'a Path) -> Self {
        let mut lines: Vec<Line> = bytes
            .split(|&b| b == b'\n')
            .enumerate()
            .map(|(i, l)| Line { number: i + 1, bytes: l.strip_suffix(b"\r").unwrap_or(l) })
            .collect();
        // a final line end does not start another line
        if bytes.ends_with(b"\n") {
            lines.pop();
        }
        Source { path, lines }
    }

    /// A positioned error at byte `col` (0-based) of line `number`.
    fn error(&self, number: usize, col: usize, message: impl Into<String>, remedy: impl Into<String>) -> LsystemError {
        let bytes = self.lines.get(number.wrapping_sub(1)).map(|l| l.bytes).unwrap_or(&[]);
        let col = col.min(bytes.len());
        let before: Vec<char> = String::from_utf8_lossy(&bytes[..col]).chars().collect();
        let all: Vec<char> = String::from_utf8_lossy(bytes).chars().collect();
        // long lines: a window around the column, so the caret stays on screen
        const CONTEXT: usize = 60;
        let at = before.len();
        let start = at.saturating_sub(CONTEXT);
        let end = (at + CONTEXT).min(all.len());
        // control bytes (an ESC from a pasted colour code) are shown escaped, never sent to the
        // terminal; the caret keeps its place under the escaped text
        let mut text: String = all[start..end].iter().map(|c| shown(*c)).collect();
        let mut caret: String = before[start..]
            .iter()
            .map(|&c| if c == '\t' { "\t".to_string() } else { " ".repeat(shown(c).chars().count()) })
            .collect();
        if start > 0 {
            text.insert(0, '…');
            caret.insert(0, ' ');
        }
        if end < all.len() {
            text.push('…');
        }
        caret.push('^');
        LsystemError::Syntax(Box::new(SyntaxError {
            path: self.path.to_path_buf(),
            line: number,
            column: at + 1,
            message: crate::input::escape(&message.into()),
            text,
            caret,
            remedy: remedy.into(),
        }))
    }

    /// A positioned warning: `line L, column C: message` (C 1-based, in characters).
    fn warning(&self, number: usize, col: usize, message: impl Into<String>) -> String {
        let bytes = self.lines.get(number.wrapping_sub(1)).map(|l| l.bytes).unwrap_or(&[]);
        let column = String::from_utf8_lossy(&bytes[..col.min(bytes.len())]).chars().count() + 1;
        format!("line {number}, column {column}: {}", crate::input::escape(&message.into()))
    }

    /// An error just past the last line (something missing at the end of the file).
    fn error_at_end(&self, message: impl Into<String>, remedy: impl Into<String>) -> LsystemError {
        let number = self.lines.len().max(1);
        let col = self.lines.last().map_or(0, |l| l.bytes.len());
        self.error(number, col, message, remedy)
    }
}

fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\x0b' | b'\x0c' | b'\r')
}

/// Blank, or a comment line (`#` as the first non-blank byte).
fn is_comment_or_blank(line: &[u8]) -> bool {
    match line.iter().position(|&b| !is_space(b)) {
        None => true,
        Some(i) => line[i] == b'#',
    }
}

/// The first run of bytes that are neither blank nor `#`, with its starting column: positional
/// lines keep everything after the first blank (or `#`) as a comment.
fn first_token(line: &[u8]) -> (usize, &[u8]) {
    let start = line.iter().position(|&b| !is_space(b)).unwrap_or(line.len());
    let len = line[start..].iter().position(|&b| is_space(b) || b == b'#').unwrap_or(line.len() - start);
    (start, &line[start..start + len])
}

/// The thesis' format has no blanks: text after one is a comment. When that text reads like more of
/// the rule (turtle commands, brackets, arguments) rather than words, the blank most likely split
/// the rule: warn with its position (the rule is read up to the blank).
fn warn_blank_inside(source: &Source, line: &Line, end: usize, what: &str, warnings: &mut Vec<String>) {
    let rest = &line.bytes[end.min(line.bytes.len())..];
    let Some(start) = rest.iter().position(|&b| !is_space(b)) else { return };
    let next = first_word(&rest[start..]);
    let rule_like = !next.starts_with(b"#")
        && next.iter().any(|b| b"[]()+-&^<>|%$\"'!?;:=".contains(b))
        && !next.iter().any(|b| b.is_ascii_lowercase() && !b"fgtzc".contains(b));
    if rule_like {
        warnings.push(source.warning(
            line.number,
            end,
            format!(
                "a blank inside {what}: `{}` after it is read as a comment (the format has no blanks; remove the blank to make it part of the rule)",
                String::from_utf8_lossy(next)
            ),
        ));
    }
}

/// The first blank-separated word.
fn first_word(line: &[u8]) -> &[u8] {
    let start = line.iter().position(|&b| !is_space(b)).unwrap_or(line.len());
    let len = line[start..].iter().position(|&b| is_space(b)).unwrap_or(line.len() - start);
    &line[start..start + len]
}

/// A finite number written in ASCII (`12`, `7.5`, `.77`, `-3`, `1e2`).
fn number(text: &[u8]) -> Option<f64> {
    let s = std::str::from_utf8(text).ok()?;
    // Rust would also read `inf`, `NaN` and `infinity`; only digits make a number here
    if !s.bytes().any(|b| b.is_ascii_digit()) || s.bytes().any(|b| b.is_ascii_alphabetic() && b != b'e' && b != b'E') {
        return None;
    }
    s.parse::<f64>().ok().filter(|v| v.is_finite())
}

fn show(b: u8) -> String {
    if b.is_ascii_graphic() {
        format!("`{}`", b as char)
    } else {
        format!("byte 0x{b:02X}")
    }
}

/// Bytes that cannot be rewritten: argument syntax, brackets (they must stay balanced), `=`, `@`
/// (it ends the rules), `#` (comments).
fn predecessor_problem(b: u8) -> Option<&'static str> {
    match b {
        b'(' | b')' => Some("parentheses hold arguments and cannot be rewritten"),
        b'[' | b']' => Some("brackets cannot be rewritten: they must stay balanced"),
        b'=' | b'@' | b'#' => Some("this character is part of the file syntax"),
        _ if is_space(b) || b == b'\n' => Some("blanks separate comments"),
        _ => None,
    }
}

/// Parses an axiom or successor given as (byte, column) pairs of line `line`: symbols and `(x)`
/// arguments. Brackets need not balance within a rule, as in lparser, which rewrites the whole
/// string: real files open a branch in one rule and close it in another (`ò=[""`, `ó=]c-(135)`),
/// and lparser 5's horn.ls does the same with polygon braces. The turtle matches brackets over the
/// derivation (branch levels are its stack depth): a `]` with no open branch is ignored and
/// branches still open at the end are closed there. Such rules, and a stray `)` (which lparser
/// ignores; it is dropped), get a positioned warning.
fn parse_items(
    source: &Source,
    line: usize,
    text: &[(u8, usize)],
    args: &mut Vec<ArgText>,
    what: &str,
    warnings: &mut Vec<String>,
) -> Result<Vec<Item>, LsystemError> {
    let mut items = Vec::with_capacity(text.len());
    let mut open_square: Vec<usize> = Vec::new();
    let mut i = 0;
    while i < text.len() {
        let (b, col) = text[i];
        match b {
            b'(' => {
                let close = text[i + 1..].iter().position(|&(c, _)| c == b')').map(|k| i + 1 + k).ok_or_else(|| {
                    source.error(
                        line,
                        col,
                        format!("`(` is never closed in {what}"),
                        "close the argument with `)`, as in `+(30)`",
                    )
                })?;
                let inner: Vec<u8> = text[i + 1..close].iter().map(|&(c, _)| c).collect();
                let value = number(&inner).ok_or_else(|| {
                    source.error(
                        line,
                        col,
                        format!("`({})` is not a number", String::from_utf8_lossy(&inner)),
                        "arguments are finite numbers, as in `+(30)` or `'(.8)`",
                    )
                })?;
                items.push(Item::Arg(args.len() as u32));
                args.push(ArgText { value, text: inner });
                i = close + 1;
                continue;
            }
            b')' => {
                warnings.push(source.warning(
                    line,
                    col,
                    format!("a `)` without `(` in {what} is ignored (as lparser does)"),
                ));
                i += 1;
                continue;
            }
            b'[' => open_square.push(col),
            b']' if open_square.pop().is_none() => {
                warnings.push(source.warning(
                    line,
                    col,
                    format!("`]` in {what} closes a branch it did not open: matched over the derivation (as lparser does); ignored where no branch is open"),
                ));
            }
            _ => {}
        }
        items.push(Item::Symbol(b));
        i += 1;
    }
    if let Some(&col) = open_square.first() {
        warnings.push(source.warning(
            line,
            col,
            format!("`[` in {what} is not closed there: matched over the derivation (as lparser does); a branch still open at the end is closed there"),
        ));
    }
    Ok(items)
}

/// Column-tagged bytes of a contiguous token starting at `start`.
fn tagged(token: &[u8], start: usize) -> Vec<(u8, usize)> {
    token.iter().enumerate().map(|(i, &b)| (b, start + i)).collect()
}

fn check_recursion(source: &Source, line: usize, col: usize, value: f64) -> Result<f64, LsystemError> {
    if !(0.0..=MAX_RECURSION as f64).contains(&value) {
        return Err(source.error(
            line,
            col,
            format!("recursion depth {value} is out of range"),
            format!("use a depth from 0 to {MAX_RECURSION}"),
        ));
    }
    Ok(value)
}

fn check_thickness(source: &Source, line: usize, col: usize, value: f64) -> Result<f64, LsystemError> {
    if value < 0.0 {
        return Err(source.error(line, col, format!("thickness {value} is negative"), "use a percentage ≥ 0"));
    }
    Ok(value)
}

/// Adds a rule unless its predecessor already has one (the first rule of a symbol wins, as in lparser).
fn add_rule(rules: &mut Vec<Rule>, lines: &mut Vec<usize>, rule: Rule, line: usize, warnings: &mut Vec<String>) {
    if let Some(k) = rules.iter().position(|r| r.predecessor == rule.predecessor) {
        warnings.push(format!(
            "line {line}: a second rule for {} is ignored (the one on line {} comes first and wins)",
            show(rule.predecessor),
            lines[k]
        ));
        return;
    }
    rules.push(rule);
    lines.push(line);
}

// ---------------------------------------------------------------------------------------------
// lparser 4: positional

fn parse_v4(source: &Source, warnings: &mut Vec<String>) -> Result<LSystem, LsystemError> {
    let mut lines = source.lines.iter().filter(|l| !is_comment_or_blank(l.bytes));
    let mut value = |what: &str, example: &str| -> Result<(usize, usize, f64), LsystemError> {
        let line = lines.next().ok_or_else(|| {
            source.error_at_end(
                format!("the file ends before the {what} line"),
                "lparser 4 files start with four lines: recursion depth, angle, thickness, axiom",
            )
        })?;
        let (col, token) = first_token(line.bytes);
        let v = number(token).ok_or_else(|| {
            source.error(
                line.number,
                col,
                format!("expected the {what} (a number), found `{}`", String::from_utf8_lossy(token)),
                format!("write the {what} as a number, e.g. {example}"),
            )
        })?;
        Ok((line.number, col, v))
    };
    let (ln, col, recursion) = value("recursion depth", "12 or 7.5")?;
    let recursion = check_recursion(source, ln, col, recursion)?;
    let (_, _, angle_deg) = value("angle", "22.5")?;
    let (ln, col, thickness) = value("thickness", "80")?;
    let thickness_pct = check_thickness(source, ln, col, thickness)?;
    let mut args = Vec::new();
    let axiom_line = lines.next().ok_or_else(|| {
        source
            .error_at_end("the file ends before the axiom line", "add the axiom (the start string) as the fourth line")
    })?;
    let (col, token) = first_token(axiom_line.bytes);
    if token.is_empty() {
        return Err(source.error(
            axiom_line.number,
            col,
            "the axiom is empty",
            "write the start string, e.g. `c(12)A`",
        ));
    }
    let axiom = parse_items(source, axiom_line.number, &tagged(token, col), &mut args, "the axiom", warnings)?;
    let mut rules = Vec::new();
    let mut rule_lines = Vec::new();
    let mut ended = false;
    for line in lines {
        let (col, token) = first_token(line.bytes);
        if token.first() == Some(&b'@') {
            ended = true;
            break;
        }
        if token.len() < 2 || token[1] != b'=' {
            return Err(source.error(
                line.number,
                col,
                format!("expected a rule `X=…`, found `{}`", String::from_utf8_lossy(token)),
                "write one rule per line as a symbol, `=` and its successor (e.g. `F=FF`), and end the rules with `@`",
            ));
        }
        let predecessor = token[0];
        if let Some(why) = predecessor_problem(predecessor) {
            return Err(source.error(
                line.number,
                col,
                format!("{} cannot be a rule's predecessor: {why}", show(predecessor)),
                "rewrite another symbol",
            ));
        }
        let what = format!("the rule for {}", show(predecessor));
        let successor = parse_items(source, line.number, &tagged(&token[2..], col + 2), &mut args, &what, warnings)?;
        let rule = Rule { predecessor, variants: vec![Variant { cumulative: 100, successor }] };
        add_rule(&mut rules, &mut rule_lines, rule, line.number, warnings);
    }
    if !ended {
        return Err(
            source.error_at_end("the rules do not end with a `@` line", "add a line holding `@` after the last rule")
        );
    }
    Ok(LSystem {
        dialect: Dialect::LparserV4,
        recursion: Recursion::Steps(recursion),
        angle_deg,
        thickness_pct,
        min_thickness_pct: None,
        shape: None,
        switch_yz: None,
        colors: Vec::new(),
        axiom,
        rules,
        args,
    })
}

// ---------------------------------------------------------------------------------------------
// lparser 5: keywords

fn parse_v5(source: &Source, warnings: &mut Vec<String>) -> Result<LSystem, LsystemError> {
    // lparser 5's defaults for the lines a file leaves out
    let mut recursion = 1.0;
    let mut angle_deg = 45.0;
    let mut thickness_pct = 100.0;
    let mut min_thickness_pct = None;
    let mut shape = None;
    let mut switch_yz = None;
    let mut colors: Vec<ColorLine> = Vec::new();
    let mut axiom = None;
    let mut args = Vec::new();
    let mut rules = Vec::new();
    let mut rule_lines = Vec::new();
    for line in source.lines.iter().filter(|l| !is_comment_or_blank(l.bytes)) {
        let bytes = line.bytes;
        let key_start = bytes.iter().position(|&b| !is_space(b)).unwrap_or(0);
        let key = first_word(bytes);
        let rest_start = key_start + key.len();
        // everything after `#` is a comment
        let rest_end = bytes[rest_start..].iter().position(|&b| b == b'#').map_or(bytes.len(), |k| rest_start + k);
        let rest: Vec<(u8, usize)> = (rest_start..rest_end).map(|c| (bytes[c], c)).collect();
        let words: Vec<(usize, Vec<u8>)> = {
            let mut words = Vec::new();
            let mut cur: Option<(usize, Vec<u8>)> = None;
            for &(b, c) in &rest {
                if is_space(b) {
                    if let Some(w) = cur.take() {
                        words.push(w);
                    }
                } else {
                    cur.get_or_insert((c, Vec::new())).1.push(b);
                }
            }
            words.extend(cur);
            words
        };
        let key_text = String::from_utf8_lossy(key).into_owned();
        let one_number = |what: &str| -> Result<(usize, f64), LsystemError> {
            match words.as_slice() {
                [(col, w)] => number(w).map(|v| (*col, v)).ok_or_else(|| {
                    source.error(
                        line.number,
                        *col,
                        format!("`{key_text}` needs {what}, found `{}`", String::from_utf8_lossy(w)),
                        format!("write e.g. `{key_text} 12`"),
                    )
                }),
                [] => Err(source.error(
                    line.number,
                    rest_start,
                    format!("`{key_text}` needs {what}"),
                    format!("write e.g. `{key_text} 12`"),
                )),
                [_, (col, _), ..] => Err(source.error(
                    line.number,
                    *col,
                    format!("unexpected text after `{key_text}`'s value"),
                    "put comments after `#`",
                )),
            }
        };
        let items_text: Vec<(u8, usize)> = rest.iter().copied().filter(|&(b, _)| !is_space(b)).collect();
        match key {
            b"recursion" => {
                let (col, v) = one_number("a depth")?;
                recursion = check_recursion(source, line.number, col, v)?;
            }
            b"angle" => angle_deg = one_number("an angle in degrees")?.1,
            b"thickness" => {
                let (col, v) = one_number("a percentage")?;
                thickness_pct = check_thickness(source, line.number, col, v)?;
            }
            b"min_thickness" => {
                let (col, v) = one_number("a percentage")?;
                min_thickness_pct = Some(check_thickness(source, line.number, col, v)?);
            }
            b"shape" => shape = Some(one_number("a shape number")?.1),
            b"switch_yz" => {
                let (col, v) = one_number("0 or 1")?;
                if v.fract() != 0.0 || v.abs() > 1e15 {
                    return Err(source.error(
                        line.number,
                        col,
                        "`switch_yz` needs a whole number",
                        "write `switch_yz 1` or `switch_yz 0`",
                    ));
                }
                switch_yz = Some(v as i64);
            }
            b"mutation" => {
                let (col, v) = one_number("a count")?;
                if v != 0.0 {
                    return Err(source.error(
                        line.number,
                        col,
                        "mutation is not supported (lparser's random edits of the rules)",
                        "set it to 0 or remove the line; use --seed (`variants` in a preset) for variants",
                    ));
                }
            }
            b"trace" | b"no_wait" | b"poly_limit" => {
                warnings.push(format!(
                    "line {}: `{key_text}` is ignored (use --max-triangles, `max_triangles` in a preset's tree, for a polygon budget)",
                    line.number
                ));
            }
            b"color" => {
                let bad = |col: usize| {
                    source.error(
                        line.number,
                        col,
                        "`color` needs an index and three channel values 0..255",
                        "write e.g. `color 8 40 120 30`",
                    )
                };
                if words.len() != 4 {
                    return Err(bad(words.first().map_or(rest_start, |w| w.0)));
                }
                let mut v = [0u16; 4];
                for (k, (col, w)) in words.iter().enumerate() {
                    match number(w) {
                        Some(x) if x.fract() == 0.0 && (0.0..=255.0).contains(&x) => v[k] = x as u16,
                        _ => return Err(bad(*col)),
                    }
                }
                let entry = ColorLine { index: v[0], rgb: [v[1] as u8, v[2] as u8, v[3] as u8] };
                // a later line for the same index replaces the earlier one, as in lparser
                colors.retain(|c| c.index != entry.index);
                colors.push(entry);
            }
            b"axiom" => {
                if items_text.is_empty() {
                    return Err(source.error(
                        line.number,
                        rest_start,
                        "the axiom is empty",
                        "write the start string, e.g. `axiom FFA`",
                    ));
                }
                if axiom.is_some() {
                    warnings.push(format!("line {}: a second `axiom` replaces the first", line.number));
                }
                axiom = Some(parse_items(source, line.number, &items_text, &mut args, "the axiom", warnings)?);
            }
            b"rule" => {
                let eq = items_text.iter().position(|&(b, _)| b == b'=');
                let (pred, col) = match (eq, items_text.first()) {
                    (Some(1), Some(&(b, col))) => (b, col),
                    _ => {
                        return Err(source.error(
                            line.number,
                            items_text.first().map_or(rest_start, |p| p.1),
                            "expected `rule X = …` with a one-symbol predecessor",
                            "write e.g. `rule F = F[+F]F`",
                        ))
                    }
                };
                if let Some(why) = predecessor_problem(pred) {
                    return Err(source.error(
                        line.number,
                        col,
                        format!("{} cannot be a rule's predecessor: {why}", show(pred)),
                        "rewrite another symbol",
                    ));
                }
                let what = format!("the rule for {}", show(pred));
                let successor = parse_items(source, line.number, &items_text[2..], &mut args, &what, warnings)?;
                let rule = Rule { predecessor: pred, variants: vec![Variant { cumulative: 100, successor }] };
                add_rule(&mut rules, &mut rule_lines, rule, line.number, warnings);
            }
            _ => {
                return Err(source.error(
                    line.number,
                    key_start,
                    format!("unknown keyword `{key_text}`"),
                    format!("lparser 5 lines start with one of: {}; comments start with `#`", V5_KEYWORDS.join(", ")),
                ))
            }
        }
    }
    let axiom = axiom.ok_or_else(|| source.error_at_end("the file has no `axiom` line", "add e.g. `axiom FFA`"))?;
    Ok(LSystem {
        dialect: Dialect::LparserV5,
        recursion: Recursion::Steps(recursion),
        angle_deg,
        thickness_pct,
        min_thickness_pct,
        shape,
        switch_yz,
        colors,
        axiom,
        rules,
        args,
    })
}

// ---------------------------------------------------------------------------------------------
// the thesis' stochastic format

/// Most recursion levels accepted in `a-b-c` (the thesis uses three).
pub const MAX_LEVELS: usize = 8;

fn parse_stochastic(source: &Source, warnings: &mut Vec<String>) -> Result<LSystem, LsystemError> {
    const FORMAT: &str = "the stochastic .ls format is: recursion levels (e.g. 3-2-2), angle, thickness, `X(100)=axiom`, rules `C(P)=R`, `@`";
    let mut lines = source.lines.iter().filter(|l| !is_comment_or_blank(l.bytes));
    let mut next = |what: &str| {
        lines
            .next()
            .map(|l| (l, first_token(l.bytes)))
            .ok_or_else(|| source.error_at_end(format!("the file ends before the {what} line"), FORMAT))
    };
    // recursion levels
    let (line, (col, token)) = next("recursion levels")?;
    let levels: Option<Vec<u32>> = token
        .split(|&b| b == b'-')
        .map(|part| {
            if part.is_empty() || !part.iter().all(u8::is_ascii_digit) {
                None
            } else {
                std::str::from_utf8(part).ok()?.parse::<u32>().ok()
            }
        })
        .collect();
    let levels = levels.filter(|l| (1..=MAX_LEVELS).contains(&l.len())).ok_or_else(|| {
        source.error(
            line.number,
            col,
            format!("expected the recursion levels `a-b-c`, found `{}`", String::from_utf8_lossy(token)),
            format!("write 1 to {MAX_LEVELS} whole numbers separated by `-`, e.g. 3-2-2"),
        )
    })?;
    if levels.iter().map(|&l| l as u64).sum::<u64>() > MAX_RECURSION as u64 {
        return Err(source.error(
            line.number,
            col,
            "the recursion levels add up to too many steps",
            format!("keep their sum at most {MAX_RECURSION}"),
        ));
    }
    let mut value = |what: &str, example: &str| -> Result<(usize, usize, f64), LsystemError> {
        let (line, (col, token)) = next(what)?;
        let v = number(token).ok_or_else(|| {
            source.error(
                line.number,
                col,
                format!("expected the {what} (a number), found `{}`", String::from_utf8_lossy(token)),
                format!("write the {what} as a number, e.g. {example}; {FORMAT}"),
            )
        })?;
        Ok((line.number, col, v))
    };
    let (_, _, angle_deg) = value("default angle", "28")?;
    let (ln, col, thickness) = value("default thickness", "18")?;
    let thickness_pct = check_thickness(source, ln, col, thickness)?;
    let mut args = Vec::new();
    // axiom X(100)=…
    let (line, (col, token)) = next("axiom")?;
    let axiom_text = token.strip_prefix(b"X(100)=").ok_or_else(|| {
        let message = if token.starts_with(b"X(") {
            "the axiom's distribution must be 100".to_string()
        } else {
            format!("expected the axiom `X(100)=…`, found `{}`", String::from_utf8_lossy(token))
        };
        source.error(
            line.number,
            col,
            message,
            "write the axiom as `X(100)=` followed by the start string, e.g. `X(100)=FFA`",
        )
    })?;
    if axiom_text.is_empty() {
        return Err(source.error(line.number, col + 7, "the axiom is empty", "write the start string after `X(100)=`"));
    }
    let axiom = parse_items(source, line.number, &tagged(axiom_text, col + 7), &mut args, "the axiom", warnings)?;
    warn_blank_inside(source, line, col + token.len(), "the axiom", warnings);
    // rules C(P)=R, variants of one symbol in ascending P, the last at 100
    let mut rules: Vec<Rule> = Vec::new();
    let mut last_variant_at: Vec<(usize, usize)> = Vec::new(); // (line, col) of each rule's latest variant
    let mut ended = false;
    for line in lines {
        let (col, token) = first_token(line.bytes);
        if token.first() == Some(&b'@') {
            ended = true;
            break;
        }
        let bad_rule = || {
            source.error(
                line.number,
                col,
                format!("expected a rule variant `C(P)=R`, found `{}`", String::from_utf8_lossy(token)),
                "write a symbol, its cumulative probability 1..100 in parentheses, `=` and the successor, e.g. `A(40)=F[&B]A`",
            )
        };
        if token.len() < 5 || token[1] != b'(' {
            return Err(bad_rule());
        }
        let close = token.iter().position(|&b| b == b')').ok_or_else(bad_rule)?;
        if token.get(close + 1) != Some(&b'=') {
            return Err(bad_rule());
        }
        let predecessor = token[0];
        if let Some(why) = predecessor_problem(predecessor) {
            return Err(source.error(
                line.number,
                col,
                format!("{} cannot be a rule's predecessor: {why}", show(predecessor)),
                "rewrite another symbol",
            ));
        }
        let p_text = &token[2..close];
        let cumulative = match std::str::from_utf8(p_text)
            .ok()
            .filter(|s| s.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|s| s.parse::<u32>().ok())
        {
            Some(p) if (1..=100).contains(&p) => p as u8,
            _ => {
                return Err(source.error(
                    line.number,
                    col + 2,
                    format!("distribution `{}` is not a whole number from 1 to 100", String::from_utf8_lossy(p_text)),
                    "write each variant's cumulative probability in percent; the last variant of a symbol has 100",
                ))
            }
        };
        let what = format!("the rule for {}", show(predecessor));
        let successor = parse_items(
            source,
            line.number,
            &tagged(&token[close + 2..], col + close + 2),
            &mut args,
            &what,
            warnings,
        )?;
        warn_blank_inside(source, line, col + token.len(), &what, warnings);
        match rules.iter().position(|r| r.predecessor == predecessor) {
            Some(k) => {
                let previous = rules[k].variants.last().map_or(0, |v| v.cumulative);
                if previous == 100 {
                    return Err(source.error(
                        line.number,
                        col,
                        format!("{} already has a variant up to 100 on line {}", show(predecessor), last_variant_at[k].0),
                        "a symbol's variants are listed in ascending cumulative probability and end at 100; remove or renumber this one",
                    ));
                }
                if cumulative <= previous {
                    return Err(source.error(
                        line.number,
                        col + 2,
                        format!("the distribution {cumulative} of {} does not increase (the previous variant has {previous})", show(predecessor)),
                        "list a symbol's variants in ascending cumulative probability: e.g. 30, 75, 100 for 30 %, 45 %, 25 %",
                    ));
                }
                rules[k].variants.push(Variant { cumulative, successor });
                last_variant_at[k] = (line.number, col + 2);
            }
            None => {
                rules.push(Rule { predecessor, variants: vec![Variant { cumulative, successor }] });
                last_variant_at.push((line.number, col + 2));
            }
        }
    }
    if !ended {
        return Err(source
            .error_at_end("the rules do not end with a `@` line", "add a line starting with `@` after the last rule"));
    }
    for (rule, &(line, col)) in rules.iter().zip(&last_variant_at) {
        let last = rule.variants.last().map_or(0, |v| v.cumulative);
        if last != 100 {
            return Err(source.error(
                line,
                col,
                format!("the variants of {} end at {last}; the last must be 100", show(rule.predecessor)),
                "distributions are cumulative: make the last variant's 100 (e.g. 30, 75, 100)",
            ));
        }
    }
    Ok(LSystem {
        dialect: Dialect::Stochastic,
        recursion: Recursion::PerLevel(levels),
        angle_deg,
        thickness_pct,
        min_thickness_pct: None,
        shape: None,
        switch_yz: None,
        colors: Vec::new(),
        axiom,
        rules,
        args,
    })
}

/// Renumbers [`LSystem::args`] in print order (axiom, then each rule's variants), so that printing
/// and parsing again gives identical indices whatever order the file had its lines in.
fn renumber_args(system: &mut LSystem) {
    let old = std::mem::take(&mut system.args);
    let renumber = |items: &mut Vec<Item>, args: &mut Vec<ArgText>| {
        for item in items.iter_mut() {
            if let Item::Arg(a) = item {
                args.push(old[*a as usize].clone());
                *a = args.len() as u32 - 1;
            }
        }
    };
    let mut args = Vec::with_capacity(old.len());
    renumber(&mut system.axiom, &mut args);
    for rule in &mut system.rules {
        for v in &mut rule.variants {
            renumber(&mut v.successor, &mut args);
        }
    }
    system.args = args;
}

// ---------------------------------------------------------------------------------------------
// printing

/// Appends the text of `items` (symbols as their bytes, arguments as written, in parentheses).
pub(crate) fn write_items(system: &LSystem, items: &[Item], out: &mut Vec<u8>) {
    for item in items {
        match *item {
            Item::Symbol(b) => out.push(b),
            Item::Arg(a) => {
                out.push(b'(');
                match system.args.get(a as usize) {
                    Some(arg) => out.extend_from_slice(&arg.text),
                    None => out.push(b'0'),
                }
                out.push(b')');
            }
        }
    }
}

/// The system as file text in its own dialect.
pub(crate) fn print(system: &LSystem) -> Vec<u8> {
    let mut out = Vec::new();
    let line = |out: &mut Vec<u8>, s: String| {
        out.extend_from_slice(s.as_bytes());
        out.push(b'\n');
    };
    let steps = match &system.recursion {
        Recursion::Steps(n) => *n,
        Recursion::PerLevel(levels) => levels.iter().map(|&l| l as f64).sum(),
    };
    match system.dialect {
        Dialect::LparserV4 => {
            line(&mut out, format!("{steps}"));
            line(&mut out, format!("{}", system.angle_deg));
            line(&mut out, format!("{}", system.thickness_pct));
            write_items(system, &system.axiom, &mut out);
            out.push(b'\n');
            for rule in &system.rules {
                out.extend_from_slice(&[rule.predecessor, b'=']);
                if let Some(v) = rule.variants.first() {
                    write_items(system, &v.successor, &mut out);
                }
                out.push(b'\n');
            }
            line(&mut out, "@".into());
        }
        Dialect::LparserV5 => {
            line(&mut out, format!("recursion {steps}"));
            line(&mut out, format!("angle {}", system.angle_deg));
            line(&mut out, format!("thickness {}", system.thickness_pct));
            if let Some(m) = system.min_thickness_pct {
                line(&mut out, format!("min_thickness {m}"));
            }
            if let Some(s) = system.shape {
                line(&mut out, format!("shape {s}"));
            }
            if let Some(s) = system.switch_yz {
                line(&mut out, format!("switch_yz {s}"));
            }
            for c in &system.colors {
                line(&mut out, format!("color {} {} {} {}", c.index, c.rgb[0], c.rgb[1], c.rgb[2]));
            }
            out.extend_from_slice(b"axiom ");
            write_items(system, &system.axiom, &mut out);
            out.push(b'\n');
            for rule in &system.rules {
                out.extend_from_slice(b"rule ");
                out.extend_from_slice(&[rule.predecessor, b' ', b'=', b' ']);
                if let Some(v) = rule.variants.first() {
                    write_items(system, &v.successor, &mut out);
                }
                out.push(b'\n');
            }
        }
        Dialect::Stochastic => {
            let levels = match &system.recursion {
                Recursion::PerLevel(levels) => levels.iter().map(|l| l.to_string()).collect::<Vec<_>>().join("-"),
                Recursion::Steps(n) => format!("{}", n.ceil() as u32),
            };
            line(&mut out, levels);
            line(&mut out, format!("{}", system.angle_deg));
            line(&mut out, format!("{}", system.thickness_pct));
            out.extend_from_slice(b"X(100)=");
            write_items(system, &system.axiom, &mut out);
            out.push(b'\n');
            for rule in &system.rules {
                for v in &rule.variants {
                    out.push(rule.predecessor);
                    out.extend_from_slice(format!("({})=", v.cumulative).as_bytes());
                    write_items(system, &v.successor, &mut out);
                    out.push(b'\n');
                }
            }
            line(&mut out, "@".into());
        }
    }
    out
}

/// Printing, beside the parser it mirrors.
impl LSystem {
    /// The file text of this system in its own dialect (bytes: symbols may be any byte).
    pub fn print(&self) -> Vec<u8> {
        print(self)
    }

    /// `items` as the text they were written as (`F[&B]>(137)A`).
    pub fn items_text(&self, items: &[Item]) -> Vec<u8> {
        let mut out = Vec::with_capacity(items.len());
        write_items(self, items, &mut out);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str, dialect: Option<Dialect>) -> Result<Parsed, LsystemError> {
        parse_bytes(text.as_bytes(), Path::new("t.ls"), dialect)
    }

    #[test]
    fn detects_each_dialect() {
        assert_eq!(detect(b"# c\n7\n22.5\n80\nA\nA=FA\n@\n"), Dialect::LparserV4);
        assert_eq!(detect(b"# c\r\n\r\nrecursion 3\r\naxiom F\r\n"), Dialect::LparserV5);
        assert_eq!(detect(b"3-2-2\n28\n18\nX(100)=FA\nA(100)=F\n@\n"), Dialect::Stochastic);
        assert_eq!(detect(b"4\n28\n18\nX(100)=FA\nA(50)=F\nA(100)=FF\n@\n"), Dialect::Stochastic);
    }

    #[test]
    fn v4_comments_and_arguments() {
        let p = parse(
            "# head\n7   # depth\n22.5\n80\n#\nc(12)A # axiom\nA=[&FL!A]>(137)A\ne=(19.47)\n@\ntrailing text\n",
            None,
        )
        .unwrap();
        let s = &p.system;
        assert_eq!(s.dialect, Dialect::LparserV4);
        assert_eq!(s.recursion, Recursion::Steps(7.0));
        assert_eq!(s.axiom.len(), 3);
        assert_eq!(s.args[0].value, 12.0);
        assert_eq!(s.rules.len(), 2);
        assert_eq!(s.items_text(&s.rules[1].variants[0].successor), b"(19.47)");
    }

    #[test]
    fn brackets_balance_over_the_derivation_with_positioned_warnings() {
        // lparser accepts rules whose brackets balance only with other rules, and stray `)`
        let p = parse("2\n10\n10\nAXB\nX=F[+F\nB=F]F)\n@\n", None).unwrap();
        assert_eq!(p.warnings.len(), 3, "{:?}", p.warnings);
        assert!(p.warnings[0].starts_with("line 5, column 4: `[`"), "{:?}", p.warnings);
        assert!(p.warnings[1].starts_with("line 6, column 4: `]`"), "{:?}", p.warnings);
        assert!(p.warnings[2].starts_with("line 6, column 6: a `)` without `(`"), "{:?}", p.warnings);
        // the `)` is dropped, the brackets kept for the turtle to match
        let b = p.system.rules.iter().find(|r| r.predecessor == b'B').unwrap();
        assert_eq!(p.system.items_text(&b.variants[0].successor), b"F]F");
    }

    #[test]
    fn a_blank_inside_a_thesis_rule_warns_with_its_position() {
        let p = parse("2\n28\n18\nX(100)=FA\nA(100)=F[&A] >(137)A\n@\n", None).unwrap();
        assert_eq!(p.warnings.len(), 1, "{:?}", p.warnings);
        assert!(p.warnings[0].starts_with("line 5, column 13: a blank inside the rule for `A`"), "{:?}", p.warnings);
        // the rule is read up to the blank; a real comment after a blank does not warn
        assert_eq!(p.system.items_text(&p.system.rules[0].variants[0].successor), b"F[&A]");
        let p = parse("2\n28\n18\nX(100)=FA # the trunk\nA(100)=F[&A]A  grows upward\n@\n", None).unwrap();
        assert!(p.warnings.is_empty(), "{:?}", p.warnings);
    }

    #[test]
    fn first_rule_wins_with_a_warning() {
        let p = parse("2\n10\n10\nA\nA=F\nA=FF\n@\n", None).unwrap();
        assert_eq!(p.system.rules.len(), 1);
        assert_eq!(p.system.items_text(&p.system.rules[0].variants[0].successor), b"F");
        assert!(p.warnings[0].contains("line 6"), "{:?}", p.warnings);
    }

    #[test]
    fn errors_are_positioned_with_a_caret() {
        let e = parse("2\n10\n10\nA\nA=F[+F+(30F\n@\n", None).unwrap_err();
        let text = e.to_string();
        assert!(text.starts_with("t.ls:5:8: `(` is never closed"), "{text}");
        assert!(text.contains("\n  A=F[+F+(30F\n         ^\n"), "{text}");
        let e = parse("2\n10\n10\nA\nA=+(x)F\n@\n", None).unwrap_err().to_string();
        assert!(e.starts_with("t.ls:5:4: `(x)` is not a number"), "{e}");
        let e = parse("2\n10\n10\nA\nA=F\n", None).unwrap_err().to_string();
        assert!(e.contains("do not end with a `@`"), "{e}");
        let e = parse("recursion 2\nangel 3\naxiom F\n", None).unwrap_err().to_string();
        assert!(e.starts_with("t.ls:2:1: unknown keyword `angel`"), "{e}");
    }

    #[test]
    fn cp437_bytes_do_not_break_positions() {
        let mut bytes = b"#\xc9\xcd\xcd comment\n2\n10\n10\nA\n".to_vec();
        bytes.extend_from_slice(b"\xcdA=F]\n@\n");
        let e = parse_bytes(&bytes, Path::new("cp.ls"), Some(Dialect::LparserV4)).unwrap_err().to_string();
        // the first token is `\xcdA=F]`: its first byte is no rule
        assert!(e.starts_with("cp.ls:6:1: expected a rule"), "{e}");
        assert!(e.contains('\u{FFFD}'), "{e}");
    }

    #[test]
    fn stochastic_distributions_are_checked() {
        let ok = "1-0-0\n30\n20\nX(100)=A\nA(30)=F\nA(75)=FF\nA(100)=FFF\n@\n";
        let p = parse(ok, None).unwrap();
        assert_eq!(p.system.rules[0].variants.iter().map(|v| v.cumulative).collect::<Vec<_>>(), vec![30, 75, 100]);
        let e =
            parse("1\n30\n20\nX(100)=A\nA(30)=F\nA(75)=FF\n@\n", Some(Dialect::Stochastic)).unwrap_err().to_string();
        assert!(e.starts_with("t.ls:6:3: the variants of `A` end at 75; the last must be 100"), "{e}");
        let e = parse("1\n30\n20\nX(100)=A\nA(30)=F\nA(20)=FF\nA(100)=F\n@\n", Some(Dialect::Stochastic))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("t.ls:6:3: the distribution 20 of `A` does not increase"), "{e}");
        let e = parse("1\n30\n20\nX(90)=A\n@\n", Some(Dialect::Stochastic)).unwrap_err().to_string();
        assert!(e.contains("must be 100"), "{e}");
    }

    #[test]
    fn v5_crlf_spaces_and_colors() {
        let text = "# x\r\nrecursion 5\r\nangle 10\t\r\nthickness 100\r\ncolor 8 10 200 30\r\naxiom c(12)F F\r\nrule F = F [ + F ] F # c\r\n";
        let p = parse(text, None).unwrap();
        let s = &p.system;
        assert_eq!(s.dialect, Dialect::LparserV5);
        assert_eq!(s.colors, vec![ColorLine { index: 8, rgb: [10, 200, 30] }]);
        assert_eq!(s.items_text(&s.axiom), b"c(12)FF");
        assert_eq!(s.items_text(&s.rules[0].variants[0].successor), b"F[+F]F");
    }

    #[test]
    fn print_then_parse_is_identity_for_each_dialect() {
        for text in [
            "7.5\n22.5\n80\nc(12)A\nA=[&FL!A]>(.5)A\nL=[c(8){-f+f}]\n@\n",
            "recursion 12\nangle 30\nthickness 100\nmin_thickness 5\ncolor 3 1 2 3\naxiom [|ffff]D\nrule D = AB!'(.9)D\nrule 1 = 2\n",
            "3-2-2\n28\n18\nX(100)=FFA\nA(40)=F[&B]>(137)A\nA(100)=F[^B]A\nB(100)=F\n@\n",
        ] {
            let a = parse(text, None).unwrap().system;
            let printed = a.print();
            let b = parse_bytes(&printed, Path::new("p.ls"), None).unwrap().system;
            assert_eq!(a, b, "{}", String::from_utf8_lossy(&printed));
        }
    }
}
