//! Every call into meshoptimizer (C++, through the meshopt crate) goes through here, so that a
//! failure on its side of the boundary becomes an error instead of ending the process.
//!
//! meshoptimizer allocates its working memory with C++ `operator new`, whose failure throws an
//! exception Rust cannot catch ("Rust cannot catch foreign exceptions": the process aborts), and
//! it trusts its inputs (with `NDEBUG`, an index past the vertex count is read out of bounds).
//! So each call here first checks what meshoptimizer assumes (whole triangles, indices within the
//! vertices, counts that fit its 32-bit indices) and then reserves, through Rust's fallible
//! allocation, the memory the call will take on both sides (the result the crate allocates and
//! meshoptimizer's scratch, bounded from its sources and checked by the tests below with an
//! allocator that counts what it really takes): when that cannot be had, the call is refused
//! with an error naming it and the size, before C++ is entered.
//!
//! meshoptimizer's allocations are routed through [`counting`] (installed once, before the first
//! call), which keeps per-thread figures the tests compare with the estimates.

use std::collections::TryReserveError;

/// What a guarded call refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("meshoptimizer's {call}: {problem}")]
pub struct FfiError {
    pub call: &'static str,
    pub problem: String,
}

fn refuse(call: &'static str, problem: String) -> FfiError {
    FfiError { call, problem }
}

/// meshoptimizer works in 32-bit indices.
const MAX_COUNT: usize = u32::MAX as usize;

/// Whole triangles over at most `MAX_COUNT` vertices, every index within `vertex_count`.
fn check_triangles(call: &'static str, indices: &[u32], vertex_count: usize) -> Result<(), FfiError> {
    if !indices.len().is_multiple_of(3) {
        return Err(refuse(call, format!("{} indices are not whole triangles", indices.len())));
    }
    if vertex_count > MAX_COUNT || indices.len() > MAX_COUNT {
        return Err(refuse(call, format!("{vertex_count} vertices / {} indices exceed 2³²−1", indices.len())));
    }
    if let Some((k, &i)) = indices.iter().enumerate().find(|(_, &i)| i as usize >= vertex_count) {
        return Err(refuse(call, format!("index {k} is {i}, past the {vertex_count} vertices")));
    }
    Ok(())
}

/// Reserves `bytes` (then gives them back) so that a call which needs them is refused here when
/// this process cannot have them (an address-space limit, a container's memory cap), instead of
/// failing inside C++.
fn preflight(call: &'static str, bytes: u128) -> Result<(), FfiError> {
    counting::install();
    let too_much = |why: String| {
        refuse(
            call,
            format!(
                "needs about {} MB of working memory, which this process cannot have ({why}); make the mesh smaller \
                 or run where more memory is available",
                bytes.div_ceil(1 << 20)
            ),
        )
    };
    let n = usize::try_from(bytes).map_err(|_| too_much("beyond the address space".into()))?;
    let mut probe: Vec<u8> = Vec::new();
    probe.try_reserve_exact(n).map_err(|e: TryReserveError| too_much(e.to_string()))?;
    Ok(())
}

/// Working memory (bytes) of each call, as functions of its counts: meshoptimizer's allocations
/// (from its sources, each rounded up) plus the result the crate allocates, with room for the
/// allocator's headers. The tests measure every call against these.
mod cost {
    pub fn vertex_cache(vertices: usize, indices: usize) -> u128 {
        // adjacency (counts, offsets, data), live triangles, timestamps, dead-end stack, emitted
        // flags; the result
        // (measured: 16 per vertex and 5 per index; 1.49 MB for 32,761 vertices, 194,400 indices)
        16 * vertices as u128 + 10 * indices as u128 + 4096
    }
    pub fn simplify(vertices: usize, indices: usize) -> u128 {
        // remap, wedge, kinds, loops, positions, quadrics, adjacency, collapse lists, the result
        // (measured: about 131 per vertex and 8 per index; 5.8 MB for the mesh above)
        160 * vertices as u128 + 16 * indices as u128 + 4096
    }
    pub fn sloppy(vertices: usize, indices: usize) -> u128 {
        // positions, cell ids, remap, quadrics per cell, tables; the result
        // (measured: about 34 per vertex; 1.1 MB for the mesh above)
        48 * vertices as u128 + 8 * indices as u128 + 65536
    }
    pub fn encode(bound: usize) -> u128 {
        2 * bound as u128 + 4096
    }
}

/// Triangles reordered for the GPU's post-transform cache (`meshopt_optimizeVertexCache`).
pub fn optimize_vertex_cache(indices: &[u32], vertex_count: usize) -> Result<Vec<u32>, FfiError> {
    const CALL: &str = "vertex cache optimizer";
    check_triangles(CALL, indices, vertex_count)?;
    preflight(CALL, cost::vertex_cache(vertex_count, indices.len()))?;
    Ok(meshopt::optimize_vertex_cache(indices, vertex_count))
}

/// Edge-collapse simplification towards `target` indices within `max_error` of the extent
/// (`meshopt_simplify`, no options).
pub fn simplify(indices: &[u32], positions: &[[f32; 3]], target: usize, max_error: f32) -> Result<Vec<u32>, FfiError> {
    const CALL: &str = "simplifier";
    check_triangles(CALL, indices, positions.len())?;
    preflight(CALL, cost::simplify(positions.len(), indices.len()))?;
    let adapter = meshopt::VertexDataAdapter::new(meshopt::typed_to_bytes(positions), 12, 0)
        .map_err(|e| refuse(CALL, e.to_string()))?;
    Ok(meshopt::simplify(indices, &adapter, target, max_error, meshopt::SimplifyOptions::None, None))
}

/// Vertex-clustering decimation towards `target` indices (`meshopt_simplifySloppy`).
pub fn simplify_sloppy(indices: &[u32], positions: &[[f32; 3]], target: usize) -> Result<Vec<u32>, FfiError> {
    const CALL: &str = "sloppy simplifier";
    check_triangles(CALL, indices, positions.len())?;
    preflight(CALL, cost::sloppy(positions.len(), indices.len()))?;
    let adapter = meshopt::VertexDataAdapter::new(meshopt::typed_to_bytes(positions), 12, 0)
        .map_err(|e| refuse(CALL, e.to_string()))?;
    Ok(meshopt::simplify_sloppy(indices, &adapter, target, 1.0, None))
}

/// The index codec (EXT_meshopt_compression's TRIANGLES mode).
pub fn encode_index_buffer(indices: &[u32], vertex_count: usize) -> Result<Vec<u8>, FfiError> {
    const CALL: &str = "index encoder";
    check_triangles(CALL, indices, vertex_count)?;
    // SAFETY: a pure function of two counts.
    let bound = unsafe { meshopt::ffi::meshopt_encodeIndexBufferBound(indices.len(), vertex_count) };
    preflight(CALL, cost::encode(bound))?;
    meshopt::encode_index_buffer(indices, vertex_count).map_err(|e| refuse(CALL, e.to_string()))
}

/// The vertex codec (version 0: what EXT_meshopt_compression reads) over elements of N bytes.
pub fn encode_vertex_buffer<const N: usize>(elements: &[[u8; N]]) -> Result<Vec<u8>, FfiError> {
    const CALL: &str = "vertex encoder";
    if elements.len() > MAX_COUNT {
        return Err(refuse(CALL, format!("{} vertices exceed 2³²−1", elements.len())));
    }
    // SAFETY: a pure function of two counts.
    let bound = unsafe { meshopt::ffi::meshopt_encodeVertexBufferBound(elements.len(), N) };
    preflight(CALL, cost::encode(bound))?;
    meshopt::encode_vertex_buffer_level(elements, 2, Some(0)).map_err(|e| refuse(CALL, e.to_string()))
}

/// `count` indices decoded from the index codec.
pub fn decode_index_buffer<T: Clone + Default>(encoded: &[u8], count: usize) -> Result<Vec<T>, FfiError> {
    const CALL: &str = "index decoder";
    if !count.is_multiple_of(3) || count > MAX_COUNT {
        return Err(refuse(CALL, format!("{count} indices are not whole triangles within 2³²−1")));
    }
    preflight(CALL, (count * std::mem::size_of::<T>()) as u128 + 4096)?;
    meshopt::decode_index_buffer::<T>(encoded, count).map_err(|e| refuse(CALL, e.to_string()))
}

/// `count` elements decoded from the vertex codec.
pub fn decode_vertex_buffer<T: Clone + Default>(encoded: &[u8], count: usize) -> Result<Vec<T>, FfiError> {
    const CALL: &str = "vertex decoder";
    if count > MAX_COUNT {
        return Err(refuse(CALL, format!("{count} vertices exceed 2³²−1")));
    }
    preflight(CALL, (count * std::mem::size_of::<T>()) as u128 + 4096)?;
    meshopt::decode_vertex_buffer::<T>(encoded, count).map_err(|e| refuse(CALL, e.to_string()))
}

/// meshoptimizer's allocation callbacks (`meshopt_setAllocator`), routed to Rust's allocator
/// with a size header, counting what each thread holds and the most it held.
pub(crate) mod counting {
    use std::alloc::{alloc, dealloc, handle_alloc_error, Layout};
    use std::cell::Cell;
    use std::ffi::c_void;
    use std::sync::Once;

    const HEADER: usize = 16;

    extern "C" {
        fn meshopt_setAllocator(allocate: extern "C" fn(usize) -> *mut c_void, deallocate: extern "C" fn(*mut c_void));
    }

    thread_local! {
        static HELD: Cell<usize> = const { Cell::new(0) };
        static PEAK: Cell<usize> = const { Cell::new(0) };
    }

    extern "C" fn allocate(size: usize) -> *mut c_void {
        let Some(layout) = size.checked_add(HEADER).and_then(|n| Layout::from_size_align(n, HEADER).ok()) else {
            handle_alloc_error(Layout::new::<[u8; HEADER]>())
        };
        // SAFETY: the layout has a non-zero size (at least the header).
        let base = unsafe { alloc(layout) };
        if base.is_null() {
            // only when the guard's estimate was short or memory went elsewhere meanwhile
            handle_alloc_error(layout);
        }
        // SAFETY: `base` holds at least HEADER bytes, aligned to 16 (so for a usize).
        unsafe { (base as *mut usize).write(size) };
        HELD.with(|h| {
            let now = h.get() + size;
            h.set(now);
            PEAK.with(|p| p.set(p.get().max(now)));
        });
        // SAFETY: within the block allocated above.
        unsafe { base.add(HEADER) as *mut c_void }
    }

    extern "C" fn deallocate(ptr: *mut c_void) {
        if ptr.is_null() {
            return;
        }
        // SAFETY: `ptr` came from `allocate`, HEADER bytes past a block that starts with its size.
        unsafe {
            let base = (ptr as *mut u8).sub(HEADER);
            let size = (base as *const usize).read();
            HELD.with(|h| h.set(h.get().saturating_sub(size)));
            dealloc(base, Layout::from_size_align_unchecked(size + HEADER, HEADER));
        }
    }

    static INSTALL: Once = Once::new();

    /// Installs the callbacks once, before this process's first meshoptimizer call (every call
    /// goes through the guard, which installs first; `Once` makes other threads wait for it).
    pub(crate) fn install() {
        // SAFETY: the callbacks match meshoptimizer's signatures; no meshoptimizer call can be in
        // flight yet, as every one goes through the guard, which waits here first.
        INSTALL.call_once(|| unsafe { meshopt_setAllocator(allocate, deallocate) });
    }

    /// The most this thread's meshoptimizer calls held at once since the last call (then reset).
    #[cfg(test)]
    pub(crate) fn take_peak() -> usize {
        PEAK.with(|p| p.replace(HELD.with(Cell::get)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of n×n vertices, two triangles per cell, heights wavy so simplification has work.
    fn grid(n: usize) -> (Vec<[f32; 3]>, Vec<u32>) {
        let positions = (0..n * n)
            .map(|k| {
                let (i, j) = ((k % n) as f32, (k / n) as f32);
                [i, (i * 0.37).sin() * (j * 0.23).cos() * 3.0, j]
            })
            .collect();
        let mut indices = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let a = (j * n + i) as u32;
                let (b, c, d) = (a + 1, a + n as u32, a + n as u32 + 1);
                indices.extend_from_slice(&[a, c, b, b, c, d]);
            }
        }
        (positions, indices)
    }

    /// meshoptimizer's own allocations stay within each call's estimate (the estimate also covers
    /// the result on the Rust side, so the C++ share must leave that room).
    #[test]
    fn the_estimates_cover_what_meshoptimizer_allocates() {
        // shared vertices (a terrain, a trunk) and a soup of separate triangles (leaf cards)
        let soup = |(p, idx): (Vec<[f32; 3]>, Vec<u32>)| -> (Vec<[f32; 3]>, Vec<u32>) {
            (idx.iter().map(|&k| p[k as usize]).collect(), (0..idx.len() as u32).collect())
        };
        for (n, separate) in [(2, false), (3, false), (17, false), (64, false), (181, false), (17, true), (120, true)] {
            let (p, idx) = if separate { soup(grid(n)) } else { grid(n) };
            let (v, i) = (p.len(), idx.len());
            counting::install();
            counting::take_peak();
            let cache = optimize_vertex_cache(&idx, v).unwrap();
            let peak = counting::take_peak() as u128;
            assert!(peak > 0, "meshoptimizer allocates through the counting callbacks");
            assert!(peak + 4 * i as u128 <= cost::vertex_cache(v, i), "cache n={n}: {peak}");
            assert_eq!(cache.len(), i);
            simplify(&idx, &p, i / 4 / 3 * 3, 0.05).unwrap();
            let peak = counting::take_peak() as u128;
            assert!(peak + 4 * i as u128 <= cost::simplify(v, i), "simplify n={n}: {peak} vs {}", cost::simplify(v, i));
            simplify_sloppy(&idx, &p, (i / 10 / 3).max(1) * 3).unwrap();
            let peak = counting::take_peak() as u128;
            assert!(peak + 4 * i as u128 <= cost::sloppy(v, i), "sloppy n={n}: {peak} vs {}", cost::sloppy(v, i));
            let encoded = encode_index_buffer(&idx, v).unwrap();
            // the codec may rotate a triangle's corners (winding kept)
            let turned = |t: &[u32]| (0..3).map(|r| [t[r], t[(r + 1) % 3], t[(r + 2) % 3]]).min().unwrap();
            let decoded = decode_index_buffer::<u32>(&encoded, i).unwrap();
            assert!(decoded.chunks(3).map(turned).eq(idx.chunks(3).map(turned)), "n={n}");
            let elements: Vec<[u8; 12]> = p.iter().map(|q| bytemuck_free(q)).collect();
            let encoded = encode_vertex_buffer(&elements).unwrap();
            let back: Vec<[u32; 3]> = decode_vertex_buffer(&encoded, v).unwrap();
            assert_eq!(back.iter().map(|w| w.map(f32::from_bits)).collect::<Vec<_>>(), p);
        }
    }

    fn bytemuck_free(q: &[f32; 3]) -> [u8; 12] {
        let mut out = [0u8; 12];
        for (k, x) in q.iter().enumerate() {
            out[4 * k..4 * k + 4].copy_from_slice(&x.to_ne_bytes());
        }
        out
    }

    #[test]
    fn what_meshoptimizer_would_trust_is_checked_first() {
        let (p, mut idx) = grid(4);
        idx[7] = 16;
        let e = optimize_vertex_cache(&idx, 16).unwrap_err();
        assert_eq!(e.to_string(), "meshoptimizer's vertex cache optimizer: index 7 is 16, past the 16 vertices");
        assert!(simplify(&idx, &p, 9, 0.1).is_err() && simplify_sloppy(&idx, &p, 9).is_err());
        assert!(encode_index_buffer(&idx, 16).is_err());
        let e = simplify(&idx[..4], &p, 3, 0.1).unwrap_err();
        assert!(e.to_string().contains("4 indices are not whole triangles"), "{e}");
        assert!(decode_index_buffer::<u32>(&[], 4).is_err());
    }

    #[test]
    fn memory_that_cannot_be_had_is_refused_before_entering_cpp() {
        let e = preflight("test", 1 << 62).unwrap_err();
        assert!(e.to_string().contains("needs about 4398046511104 MB of working memory"), "{e}");
        assert!(preflight("test", u128::MAX).is_err());
        assert!(preflight("test", 1 << 20).is_ok());
    }
}
