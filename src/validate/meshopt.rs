//! EXT_meshopt_compression on re-import: each fallback buffer rebuilt by decoding its compressed
//! bufferViews with meshoptimizer's decoders.

use std::path::Path;

use serde_json::Value;

use crate::export::gltf::EXT_MESHOPT;
use crate::meshopt_guard::{self, FfiError};

/// The buffers of a file using EXT_meshopt_compression: the GLB chunk or `.bin` files as stored,
/// each fallback buffer (no data of its own) filled by decoding every compressed bufferView into
/// its range with meshoptimizer's decoders, so accessors then read the views as if uncompressed.
pub(super) fn meshopt_buffers(
    doc: &gltf::Document,
    base: &Path,
    blob: Option<Vec<u8>>,
) -> Result<Vec<Vec<u8>>, String> {
    let mut blob = blob;
    let mut buffers = Vec::new();
    // a fallback buffer is allocated only as far as its views reach (its byteLength is the file's word)
    let mut reach = vec![0usize; doc.buffers().len()];
    for view in doc.views() {
        let end =
            view.offset().checked_add(view.length()).ok_or(format!("bufferView {} range overflows", view.index()))?;
        if let Some(r) = reach.get_mut(view.buffer().index()) {
            *r = (*r).max(end);
        }
    }
    for buffer in doc.buffers() {
        let at = format!("buffer {}", buffer.index());
        let fallback =
            buffer.extension_value(EXT_MESHOPT).and_then(|e| e.get("fallback")).and_then(Value::as_bool) == Some(true);
        let data = match buffer.source() {
            _ if fallback => {
                let len = buffer.length().min(reach[buffer.index()]);
                if len as u64 > crate::input::MAX_GLTF_BYTES {
                    return Err(format!(
                        "{at}: a fallback buffer of {len} bytes, over the {}-byte limit",
                        crate::input::MAX_GLTF_BYTES
                    ));
                }
                vec![0; len]
            }
            gltf::buffer::Source::Bin => {
                blob.take().ok_or(format!("{at}: refers to the GLB binary chunk, which is missing or taken"))?
            }
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                return Err(format!("{at}: data: URIs beside {EXT_MESHOPT} are not read by verdant"))
            }
            gltf::buffer::Source::Uri(uri) => crate::input::resolve_inside(base, uri)
                .and_then(|f| {
                    crate::input::read_limited(&f, crate::input::MAX_GLTF_BYTES, "a glTF buffer")
                        .map_err(|e| e.to_string())
                })
                .map_err(|e| format!("{at}: {e}"))?,
        };
        if data.len() < buffer.length() && !fallback {
            return Err(format!("{at}: {} bytes, the buffer declares byteLength {}", data.len(), buffer.length()));
        }
        buffers.push(data);
    }
    for view in doc.views() {
        let Some(ext) = view.extension_value(EXT_MESHOPT) else { continue };
        let at = format!("bufferView {} {EXT_MESHOPT}", view.index());
        let field = |k: &str| ext.get(k).and_then(Value::as_u64).map(|v| v as usize).ok_or(format!("{at}: no {k}"));
        let (source, offset, length, stride, count) = (
            field("buffer")?,
            field("byteOffset").unwrap_or(0),
            field("byteLength")?,
            field("byteStride")?,
            field("count")?,
        );
        // what the decoders would write must be the view, exactly: meshoptimizer's C code asserts
        // on some of these (a triangle list whose count is not a multiple of 3) and allocates count
        // elements
        let mode = ext.get("mode").and_then(Value::as_str);
        let shape_ok = match mode {
            Some("ATTRIBUTES") => stride.is_multiple_of(4) && (4..=16).contains(&stride),
            Some("TRIANGLES") => (stride == 2 || stride == 4) && count.is_multiple_of(3),
            _ => false,
        };
        if !shape_ok {
            return Err(format!("{at}: mode {mode:?} with byteStride {stride} and count {count} is not one verdant reads (ATTRIBUTES of 4–16-byte elements, or TRIANGLES of 2- or 4-byte indices, a multiple of 3)"));
        }
        if count.checked_mul(stride) != Some(view.length()) {
            return Err(format!(
                "{at}: count {count} × byteStride {stride} is not the view's byteLength {}",
                view.length()
            ));
        }
        if ext.get("filter").and_then(Value::as_str).is_some_and(|f| f != "NONE") {
            return Err(format!("{at}: filters are not read by verdant (it writes none)"));
        }
        let encoded = buffers
            .get(source)
            .and_then(|b| b.get(offset..offset.checked_add(length)?))
            .ok_or(format!("{at}: bytes {offset}..+{length} are not in buffer {source}"))?
            .to_vec();
        let fail = |e: FfiError| format!("{at}: cannot decode: {e}");
        let decoded: Vec<u8> = match (mode, stride) {
            (Some("ATTRIBUTES"), 4) => decode_elements::<4>(&encoded, count).map_err(fail)?,
            (Some("ATTRIBUTES"), 8) => decode_elements::<8>(&encoded, count).map_err(fail)?,
            (Some("ATTRIBUTES"), 12) => decode_elements::<12>(&encoded, count).map_err(fail)?,
            (Some("ATTRIBUTES"), 16) => decode_elements::<16>(&encoded, count).map_err(fail)?,
            (Some("TRIANGLES"), 2) => meshopt_guard::decode_index_buffer::<u16>(&encoded, count)
                .map_err(fail)?
                .iter()
                .flat_map(|i| i.to_le_bytes())
                .collect(),
            (Some("TRIANGLES"), 4) => meshopt_guard::decode_index_buffer::<u32>(&encoded, count)
                .map_err(fail)?
                .iter()
                .flat_map(|i| i.to_le_bytes())
                .collect(),
            (mode, _) => return Err(format!("{at}: mode {mode:?} with byteStride {stride} is not read by verdant")),
        };
        let target = view.buffer().index();
        let range = view.offset()..view.offset() + view.length();
        let dest = buffers
            .get_mut(target)
            .and_then(|b| b.get_mut(range))
            .ok_or(format!("{at}: the view lies outside buffer {target}"))?;
        if decoded.len() != dest.len() {
            return Err(format!("{at}: decoded {} bytes for a {}-byte view", decoded.len(), dest.len()));
        }
        dest.copy_from_slice(&decoded);
    }
    Ok(buffers)
}

/// Decodes `count` elements of N = 4·K bytes (as K native words, so the bytes come back as they
/// were encoded).
fn decode_elements<const N: usize>(encoded: &[u8], count: usize) -> Result<Vec<u8>, FfiError> {
    fn words<const K: usize>(encoded: &[u8], count: usize) -> Result<Vec<u8>, FfiError>
    where
        [u32; K]: Default,
    {
        Ok(meshopt_guard::decode_vertex_buffer::<[u32; K]>(encoded, count)?
            .into_iter()
            .flatten()
            .flat_map(u32::to_ne_bytes)
            .collect())
    }
    match N {
        4 => words::<1>(encoded, count),
        8 => words::<2>(encoded, count),
        12 => words::<3>(encoded, count),
        _ => words::<4>(encoded, count),
    }
}
