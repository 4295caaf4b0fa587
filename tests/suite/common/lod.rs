//! Helpers of the LoD-chain tests (L-system trees and OBJ models).

use verdant::export::gltf::to_glb;
use verdant::plants::tree_lod::{TreeLodOptions, TreeLods};

/// The default chain with a 256-px atlas (fast).
pub fn small_atlas() -> TreeLodOptions {
    TreeLodOptions { atlas_px: 256, ..TreeLodOptions::default() }
}

/// Runs `f` in a rayon pool of `threads` threads.
pub fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(f)
}

/// Every file a chain writes, as bytes: each level's glb, the MSFT_lod glb, the atlas mips.
pub fn bytes_of(t: &TreeLods) -> Vec<Vec<u8>> {
    let mut out: Vec<Vec<u8>> = t.levels.iter().map(|l| to_glb(&l.scene).unwrap()).collect();
    out.push(to_glb(&t.chain).unwrap());
    out.extend(t.atlas.iter().map(|m| m.image.encode_png().unwrap()));
    out
}
