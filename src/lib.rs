//! verdant — the asset pipeline step before an engine import.
//!
//! Heightmaps, density maps and L-system files go in; error-bounded terrain, vegetation with levels of
//! detail and placement tables come out as glTF 2.0 and OBJ. One module per pipeline stage, plain data
//! at its edges; every generator is paired with an analyzer that measures its error.
//!
//! Conventions every output relies on: metres, +Y up, right-handed; heightmap sample (column i, row j)
//! lies at x = i·cell, z = j·cell; triangles wind counter-clockwise seen from their front (+Y for
//! terrain); writes are atomic; same inputs give byte-identical outputs at any thread count.

/// `assert!` where debug assertions are on and in the library's unit tests, which CI runs in release
/// (where `debug_assert!` is compiled out): the precondition of an unsafe fast path is checked in
/// every test that drives it, and costs nothing in the shipped binary.
macro_rules! fast_path_check {
    ($($arg:tt)*) => {
        if cfg!(any(debug_assertions, test)) {
            assert!($($arg)*);
        }
    };
}

pub mod bake;
pub mod color;
pub mod export;
pub mod failure;
pub mod harness;
pub mod heightfield;
pub mod input;
pub mod lod;
pub mod lsystem;
pub mod math;
pub mod memory;
pub mod mesh;
pub mod meshopt_guard;
pub mod plants;
pub mod progress;
pub mod random;
pub mod scatter;
pub mod scene;
pub mod snow;
pub mod synth;
pub mod terrain;
pub mod validate;
