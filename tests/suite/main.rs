//! Every integration test in one binary: the library and its dependencies are linked once instead
//! of once per test file, which was most of the check's compile time (19 test binaries). Each
//! module is one former `tests/<name>.rs`; run one with `cargo test --release --test suite <name>::`.

mod atlas_cells;
mod bake;
mod cli;
mod common;
mod compact_species;
mod export_roundtrip;
mod fuzz_regressions;
mod grass;
mod heightfield_decode;
mod limits;
mod lsystem;
mod mesh_lod;
mod preset_parse;
mod preview_lod;
mod scatter_build;
mod scatter_cases;
mod scene_build;
mod scene_tiles;
mod scene_view;
mod sharding;
mod snow;
mod snow_build;
mod terrain_band_layers;
mod terrain_cases;
mod terrain_chunks;
mod tree_lod;
mod tree_species;
mod validator_parity;
mod wind;
