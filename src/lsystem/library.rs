//! Built-in L-systems: a small species library in the crate, so a tree species needs no file of
//! its own (`kind = "tree"` without `lsystem`, the demo, `verdant tree builtin:conifer`).
//!
//! A library tree is named by a path `builtin:<name>` wherever an `.ls` path is taken:
//! [`crate::lsystem::parse::read_file`] reads it from the crate instead of the disk, and messages
//! name it so. Each source is an lparser 5 file written for verdant (`library/<name>.ls`), grown
//! at one unit per `F` and meant to be scaled to its species' height.

use std::path::{Path, PathBuf};

/// What names a built-in L-system in place of a path.
pub const PREFIX: &str = "builtin:";

/// One built-in species.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Species {
    pub name: &'static str,
    pub about: &'static str,
    /// The height its trees are scaled to unless the preset (or `--height`) says otherwise.
    pub height_m: f64,
    pub source: &'static [u8],
}

/// The library, in the order `verdant` lists it.
pub const SPECIES: &[Species] = &[
    Species {
        name: "conifer",
        about: "a spruce-like cone of drooping whorls with needle plates",
        height_m: 18.0,
        source: include_bytes!("library/conifer.ls"),
    },
    Species {
        name: "broadleaf",
        about: "a round-crowned deciduous tree",
        height_m: 12.0,
        source: include_bytes!("library/broadleaf.ls"),
    },
    Species {
        name: "birch",
        about: "a slender white-barked tree with drooping twigs",
        height_m: 14.0,
        source: include_bytes!("library/birch.ls"),
    },
    Species { name: "bush", about: "a five-stemmed shrub", height_m: 2.5, source: include_bytes!("library/bush.ls") },
];

/// Words in a species name that pick a library tree when a preset names no L-system (checked in
/// this order; anything else is a broadleaf).
const NAME_HINTS: &[(&str, &str)] = &[
    ("birch", "birch"),
    ("pine", "conifer"),
    ("spruce", "conifer"),
    ("fir", "conifer"),
    ("larch", "conifer"),
    ("cedar", "conifer"),
    ("conifer", "conifer"),
    ("bush", "bush"),
    ("shrub", "bush"),
    ("hedge", "bush"),
];

/// The species a `builtin:<name>` path names: `None` for an ordinary path, `Some(Err(names))` for
/// an unknown name (with the names there are).
pub fn named(path: &Path) -> Option<Result<&'static Species, String>> {
    let name = path.to_str()?.strip_prefix(PREFIX)?;
    Some(find(name).ok_or_else(names))
}

/// The species called `name`.
pub fn find(name: &str) -> Option<&'static Species> {
    SPECIES.iter().find(|s| s.name == name)
}

/// `conifer, broadleaf, birch, bush`.
pub fn names() -> String {
    SPECIES.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
}

/// The path naming a species: `builtin:<name>`.
pub fn path_of(species: &Species) -> PathBuf {
    PathBuf::from(format!("{PREFIX}{}", species.name))
}

/// The library tree for a species called `species_name` when it names no L-system: the library's
/// own name or a hint word in it (`scots-pine` → conifer, `shrubs` → bush), else a broadleaf.
pub fn for_species_name(species_name: &str) -> &'static Species {
    let lower = species_name.to_ascii_lowercase();
    if let Some(s) = find(&lower) {
        return s;
    }
    let pick = NAME_HINTS.iter().find(|(word, _)| lower.contains(word)).map_or("broadleaf", |&(_, s)| s);
    find(pick).expect("hints name library species")
}

/// The bytes an `.ls` path stands for: a library source or the file's contents.
pub fn read_bytes(path: &Path) -> std::io::Result<std::borrow::Cow<'static, [u8]>> {
    match named(path) {
        Some(Ok(s)) => Ok(std::borrow::Cow::Borrowed(s.source)),
        Some(Err(names)) => Err(std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!("no built-in L-system of that name (built-in: {names})"),
        )),
        None => crate::input::read_limited(path, crate::input::MAX_LSYSTEM_BYTES, "an L-system")
            .map(std::borrow::Cow::Owned)
            .map_err(crate::input::ReadError::into_io),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_resolve_and_hints_pick_a_species() {
        assert_eq!(named(Path::new("builtin:conifer")).unwrap().unwrap().name, "conifer");
        assert!(named(Path::new("builtin:palm")).unwrap().unwrap_err().contains("conifer, broadleaf, birch, bush"));
        assert!(named(Path::new("trees/conifer.ls")).is_none());
        assert_eq!(for_species_name("scots-pine").name, "conifer");
        assert_eq!(for_species_name("Birch_2").name, "birch");
        assert_eq!(for_species_name("shrubs").name, "bush");
        assert_eq!(for_species_name("oak").name, "broadleaf");
        assert_eq!(for_species_name("bush").name, "bush");
        assert_eq!(path_of(find("birch").unwrap()), PathBuf::from("builtin:birch"));
        assert_eq!(&*read_bytes(Path::new("builtin:bush")).unwrap(), find("bush").unwrap().source);
    }

    #[test]
    fn every_library_source_parses_as_lparser_5_without_warnings() {
        for s in SPECIES {
            let p = crate::lsystem::parse::parse_bytes(s.source, &path_of(s), None)
                .unwrap_or_else(|e| panic!("{}: {e}", s.name));
            assert_eq!(p.system.dialect, crate::lsystem::Dialect::LparserV5, "{}", s.name);
            assert!(p.warnings.is_empty(), "{}: {:?}", s.name, p.warnings);
            // the seed changes the tree (variants differ)
            assert!(p.system.uses_seed(), "{}", s.name);
        }
    }
}
