//! Reading the TOML document: positions, the typed getters of a table, checked numbers and
//! choices, and the messages they give (`file:line:column: problem; remedy`).

use std::ops::Range;
use std::path::{Path, PathBuf};

use clap::ValueEnum;
use toml::de::{DeTable, DeValue};
use toml::Spanned;

use super::error::{Inputs, PresetError};

/// Type of a value as a message says it ("a string", "an integer", …).
pub(super) fn type_name(value: &DeValue<'_>) -> &'static str {
    match value {
        DeValue::String(_) => "a string",
        DeValue::Integer(_) => "an integer",
        DeValue::Float(_) => "a float",
        DeValue::Boolean(_) => "a boolean",
        DeValue::Datetime(_) => "a date-time",
        DeValue::Array(_) => "an array",
        DeValue::Table(_) => "a table",
    }
}

/// 1-based line and column (in characters) of byte `offset` in `text`.
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

/// The closest of `candidates` to `word`, if it is close enough to be a likely misspelling.
pub fn did_you_mean<'a>(word: &str, candidates: &[&'a str]) -> Option<&'a str> {
    let w = word.to_lowercase().replace('-', "_");
    let (distance, best) =
        candidates.iter().map(|c| (strsim::damerau_levenshtein(&w, c), *c)).min_by_key(|(d, _)| *d)?;
    if distance <= (best.chars().count() / 3).max(1) {
        return Some(best);
    }
    // a fragment of a longer key (`error` → `max_error`)
    candidates.iter().find(|c| w.chars().count() >= 4 && c.contains(w.as_str())).copied()
}

pub(super) fn backticked(items: &[&str]) -> String {
    items.iter().map(|k| format!("`{k}`")).collect::<Vec<_>>().join(", ")
}

/// The text being parsed and where it came from.
pub(super) struct Ctx<'a> {
    pub(super) file: &'a Path,
    pub(super) text: &'a str,
}

impl Ctx<'_> {
    pub(super) fn at(&self, span: &Range<usize>, problem: impl Into<String>, remedy: impl Into<String>) -> PresetError {
        let (line, column) = line_column(self.text, span.start);
        PresetError::At { file: self.file.to_path_buf(), line, column, problem: problem.into(), remedy: remedy.into() }
    }
}

pub(super) type Entry<'a, 'i> = (&'a Spanned<std::borrow::Cow<'i, str>>, &'a Spanned<DeValue<'i>>);

/// A table of the document being read: `[scene]`, `[terrain]` or the procedural inline table.
pub(super) struct Table<'a, 'i> {
    pub(super) ctx: &'a Ctx<'a>,
    /// How messages name it: "[terrain]", "`procedural`".
    pub(super) label: String,
    /// Where "missing key" problems point: the table's name.
    pub(super) span: Range<usize>,
    pub(super) table: &'a DeTable<'i>,
}

impl<'a, 'i> Table<'a, 'i> {
    /// Entries in the order they appear in the file.
    pub(super) fn entries(&self) -> Vec<Entry<'a, 'i>> {
        let mut entries: Vec<Entry<'a, 'i>> = self.table.iter().collect();
        entries.sort_by_key(|(k, _)| k.span().start);
        entries
    }

    /// Every key must be one of `known`; `elsewhere` lists other tables' keys for "belongs in".
    pub(super) fn check_keys(&self, known: &[&str], elsewhere: &[(&str, &[&str])]) -> Result<(), PresetError> {
        for (key, _) in self.entries() {
            let name: &str = key.get_ref();
            if known.contains(&name) {
                continue;
            }
            let problem = format!("unknown key `{name}` in {}", self.label);
            let homes: Vec<&str> = elsewhere.iter().filter(|(_, keys)| keys.contains(&name)).map(|(t, _)| *t).collect();
            let remedy = if let Some(suggestion) = did_you_mean(name, known) {
                format!("did you mean `{suggestion}`?")
            } else if !homes.is_empty() {
                format!("`{name}` belongs in {}", homes.join(" or "))
            } else {
                format!("the keys of {} are {}", self.label, backticked(known))
            };
            return Err(self.ctx.at(&key.span(), problem, remedy));
        }
        Ok(())
    }

    pub(super) fn get(&self, key: &str) -> Option<Entry<'a, 'i>> {
        self.table.iter().find(|(k, _)| k.get_ref() == key)
    }

    pub(super) fn wrong_type(
        &self,
        key: &str,
        value: &Spanned<DeValue<'_>>,
        expected: &str,
        example: &str,
    ) -> PresetError {
        self.ctx.at(
            &value.span(),
            format!("`{key}` must be {expected}, found {}", type_name(value.get_ref())),
            format!("write it like `{example}`"),
        )
    }

    pub(super) fn missing(&self, key: &str, example: &str) -> PresetError {
        self.ctx.at(&self.span, format!("{} has no `{key}`", self.label), format!("add `{example}`"))
    }

    pub(super) fn string(&self, key: &str, example: &str) -> Result<Option<(&'a str, Range<usize>)>, PresetError> {
        match self.get(key) {
            None => Ok(None),
            Some((_, v)) => match v.get_ref() {
                DeValue::String(s) => Ok(Some((s.as_ref(), v.span()))),
                _ => Err(self.wrong_type(key, v, "a string", example)),
            },
        }
    }

    pub(super) fn boolean(&self, key: &str, example: &str) -> Result<Option<bool>, PresetError> {
        match self.get(key) {
            None => Ok(None),
            Some((_, v)) => match v.get_ref() {
                DeValue::Boolean(b) => Ok(Some(*b)),
                _ => Err(self.wrong_type(key, v, "a boolean", example)),
            },
        }
    }

    /// An integer in `range` (inclusive), as u64.
    pub(super) fn integer(
        &self,
        key: &str,
        range: std::ops::RangeInclusive<u64>,
        example: &str,
    ) -> Result<Option<(u64, Range<usize>)>, PresetError> {
        match self.get(key) {
            None => Ok(None),
            Some((_, v)) => integer_value(self, key, v, range, example).map(|n| Some((n, v.span()))),
        }
    }

    /// A number (integer or float), finite, checked by `valid` (which says what is wrong).
    pub(super) fn number(
        &self,
        key: &str,
        example: &str,
        valid: impl Fn(f64) -> Result<(), String>,
    ) -> Result<Option<(f64, Range<usize>)>, PresetError> {
        match self.get(key) {
            None => Ok(None),
            Some((_, v)) => number_value(self, key, v, example, &valid).map(|x| Some((x, v.span()))),
        }
    }
}

pub(super) fn integer_value(
    t: &Table<'_, '_>,
    key: &str,
    v: &Spanned<DeValue<'_>>,
    range: std::ops::RangeInclusive<u64>,
    example: &str,
) -> Result<u64, PresetError> {
    let DeValue::Integer(i) = v.get_ref() else {
        return Err(t.wrong_type(key, v, "an integer", example));
    };
    let n = i64::from_str_radix(i.as_str(), i.radix()).map_err(|_| {
        t.ctx.at(&v.span(), format!("`{key}` = {i} is out of range"), format!("use a value in {range:?}"))
    })?;
    match u64::try_from(n) {
        Ok(n) if range.contains(&n) => Ok(n),
        _ => Err(t.ctx.at(
            &v.span(),
            format!("`{key}` must be between {} and {}, got {n}", range.start(), range.end()),
            format!("write it like `{example}`"),
        )),
    }
}

pub(super) fn number_value(
    t: &Table<'_, '_>,
    key: &str,
    v: &Spanned<DeValue<'_>>,
    example: &str,
    valid: &dyn Fn(f64) -> Result<(), String>,
) -> Result<f64, PresetError> {
    let x = match v.get_ref() {
        DeValue::Integer(i) => i64::from_str_radix(i.as_str(), i.radix()).ok().map(|n| n as f64),
        DeValue::Float(f) => f.as_str().parse::<f64>().ok(),
        _ => return Err(t.wrong_type(key, v, "a number", example)),
    };
    let x = x.ok_or_else(|| {
        t.ctx.at(&v.span(), format!("`{key}` is not a number TOML can hold"), format!("write it like `{example}`"))
    })?;
    if !x.is_finite() {
        return Err(t.ctx.at(
            &v.span(),
            format!("`{key}` must be a finite number, got {x}"),
            format!("write it like `{example}`"),
        ));
    }
    valid(x).map_err(|why| {
        // as written in the file, not 300 digits of 1e300
        let got = if x != 0.0 && !(1e-3..1e9).contains(&x.abs()) { format!("{x:e}") } else { format!("{x}") };
        t.ctx.at(&v.span(), format!("`{key}` {why}, got {got}"), format!("write it like `{example}`"))
    })?;
    Ok(x)
}

pub(super) fn positive(x: f64) -> Result<(), String> {
    if x > 0.0 {
        Ok(())
    } else {
        Err("must be greater than 0".into())
    }
}

pub(super) fn non_negative(x: f64) -> Result<(), String> {
    if x >= 0.0 {
        Ok(())
    } else {
        Err("must be 0 or more".into())
    }
}

pub(super) fn any_finite(_: f64) -> Result<(), String> {
    Ok(())
}

/// The CLI's name of a clap value (`terrain-rgb`, `tin`).
pub(super) fn value_name<T: ValueEnum>(v: &T) -> String {
    v.to_possible_value().map(|p| p.get_name().to_string()).unwrap_or_default()
}

/// Picks the variant of `T` named `s` (the CLI's spelling), or explains the allowed ones.
pub(super) fn choice<T: ValueEnum + Copy>(
    t: &Table<'_, '_>,
    key: &str,
    s: &str,
    span: &Range<usize>,
) -> Result<T, PresetError> {
    if let Some(v) = T::value_variants().iter().find(|v| value_name(*v) == s) {
        return Ok(*v);
    }
    let names: Vec<String> = T::value_variants().iter().map(value_name).collect();
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    Err(unknown_value(t, key, s, &names, span))
}

pub(super) fn unknown_value(
    t: &Table<'_, '_>,
    key: &str,
    s: &str,
    allowed: &[&str],
    span: &Range<usize>,
) -> PresetError {
    let remedy = match did_you_mean(s, allowed) {
        Some(m) => format!("did you mean \"{m}\"? (allowed: {})", allowed.join(", ")),
        None => format!("allowed values are {}", allowed.join(", ")),
    };
    t.ctx.at(span, format!("unknown `{key}` value \"{s}\""), remedy)
}

/// `key = [min, max]`: two numbers, each checked by `valid`, min ≤ max.
pub(super) fn pair(
    t: &Table<'_, '_>,
    key: &str,
    example: &str,
    unit: &str,
    valid: impl Fn(f64) -> Result<(), String>,
) -> Result<Option<[f64; 2]>, PresetError> {
    let Some((_, v)) = t.get(key) else { return Ok(None) };
    let expected =
        if unit.is_empty() { "an array [min, max]".to_string() } else { format!("an array [min, max] in {unit}") };
    let DeValue::Array(items) = v.get_ref() else {
        return Err(t.wrong_type(key, v, &expected, example));
    };
    if items.len() != 2 {
        return Err(t.ctx.at(
            &v.span(),
            format!("`{key}` must have two numbers [min, max], found {}", items.len()),
            format!("write it like `{example}`"),
        ));
    }
    let min = number_value(t, key, &items[0], example, &valid)?;
    let max = number_value(t, key, &items[1], example, &valid)?;
    if min > max {
        return Err(t.ctx.at(
            &v.span(),
            format!("`{key}` is [min, max], but {min} > {max}"),
            format!("put the smaller value first, e.g. `{example}`"),
        ));
    }
    Ok(Some([min, max]))
}

/// An input file named at `value` must exist and be a file.
pub(super) fn check_input_file(
    t: &Table<'_, '_>,
    value: &Spanned<DeValue<'_>>,
    what: &'static str,
    path: &Path,
) -> Result<(), PresetError> {
    if !path.exists() {
        let (line, column) = line_column(t.ctx.text, value.span().start);
        return Err(PresetError::MissingInput {
            file: t.ctx.file.to_path_buf(),
            line,
            column,
            what,
            input: path.to_path_buf(),
        });
    }
    if !path.is_file() {
        return Err(t.ctx.at(
            &value.span(),
            format!("{what} `{}` is not a file", path.display()),
            format!("name the {what} file itself, not its folder"),
        ));
    }
    Ok(())
}

/// `relative` as seen from the folder of the preset file `preset` (absolute paths stay as they are).
pub fn resolve(preset: &Path, relative: &Path) -> PathBuf {
    match preset.parent() {
        Some(dir) if relative.is_relative() && !dir.as_os_str().is_empty() => dir.join(relative),
        _ => relative.to_path_buf(),
    }
}

/// An optional input file (`density_map`, `mask`): resolved against the preset's folder; when
/// `inputs` asks, it must exist and be a file, and decode.
pub(super) fn input_path(
    t: &Table<'_, '_>,
    key: &'static str,
    example: &str,
    inputs: Inputs,
) -> Result<Option<PathBuf>, PresetError> {
    let Some((_, value)) = t.get(key) else { return Ok(None) };
    let DeValue::String(relative) = value.get_ref() else {
        return Err(t.wrong_type(key, value, "a path (a string)", example));
    };
    if relative.is_empty() {
        return Err(t.ctx.at(
            &value.span(),
            format!("`{key}` is empty"),
            format!("name a grayscale image, relative to this preset, or remove `{key}`"),
        ));
    }
    let path = resolve(t.ctx.file, Path::new(relative.as_ref()));
    if inputs.exist() {
        check_input_file(t, value, key, &path)?;
    }
    if inputs.decode() {
        let problem = match key {
            "density_map" | "mask" | "vegetation_map" => {
                crate::scatter::DensityMap::load(&path).err().map(|e| e.to_string())
            }
            "blade_texture" => crate::bake::image::Image::read_png(&path).err().map(|e| e.to_string()),
            _ => None,
        };
        if let Some(e) = problem {
            return Err(t.ctx.at(
                &value.span(),
                format!("`{key}` does not decode: {e}"),
                "give a PNG (8 or 16 bit; density maps and masks are read as grayscale)",
            ));
        }
    }
    Ok(Some(path))
}
