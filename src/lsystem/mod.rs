//! L-systems: the three `.ls` dialects verdant reads ([`parse`]), their depth-first streaming
//! rewriting ([`expand`]) and the turtle that turns the symbols into segments and polygons ([`turtle`]).
//!
//! Sources: Lindenmayer (1968) and Prusinkiewicz & Lindenmayer, "The Algorithmic Beauty of Plants"
//! (1990, ch. 1); Laurens Lapré's lparser 4 (positional files) and 5 (keyword files); the point-sprite
//! L-system thesis, §1.2 (rewriting), §3.2 (its stochastic `.ls` format) and §3.3 (turtle table).
//! docs/lsystems.md has the one table of how the dialects differ.
//!
//! Data flow: file bytes → [`LSystem`] (rules as [`Item`] strings) → [`expand::Expander`] (a stream
//! of [`expand::Token`]s, never the whole string) → [`turtle::Turtle`] (events for a geometry sink).

pub mod expand;
pub mod library;
pub mod parse;
pub mod system;
pub mod turtle;

pub use system::{
    ArgText, ColorLine, Dialect, Item, LSystem, LsystemError, Recursion, Rule, SyntaxError, Variant, MAX_RECURSION,
};
