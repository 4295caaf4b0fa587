//! glTF 2.0 writer (Khronos glTF 2.0 specification; GLB container, EXT_mesh_gpu_instancing, MSFT_lod).
//!
//! Layout of the binary buffer: one tightly packed bufferView per attribute, index list, instance
//! array and image, each starting on a 4-byte boundary, in scene order (meshes, then instanced
//! nodes, then textures). POSITION accessors carry min/max computed from the f32 values exactly as
//! written. Indices are UNSIGNED_SHORT when the largest is ≤ 65534 (65535 is the primitive restart
//! value of some APIs), else UNSIGNED_INT. Points primitives (mode POINTS) have no index list. No hash maps anywhere: the same scene gives the same bytes.
//!
//! The scene is compacted first ([`super::compact`]): objects nothing shows are left out, equal
//! materials and textures are written once, and nodes shown only as MSFT_lod levels form a second,
//! non-default glTF scene (scene 0 is the one every viewer shows). In a GLB with MSFT_lod, what each
//! finer level needs first is in a buffer of its own, a base64 `data:` URI ([`super::streaming`]):
//! Babylon.js then streams the levels coarse to fine instead of racing them.

use std::collections::BTreeSet;

use gltf_json as json;
use json::validation::Checked::Valid;
use json::validation::USize64;
use json::Index;
use serde_json::{Map, Value};

use super::check::check_scene;
use super::compact::compact;
use super::error::SceneProblem;
use super::grid::PositionGrid;
use super::quantize::{place, place_instances, plan, MeshGrid, Quantization, UvRange};
use super::streaming::{load_groups, push_base64};
use crate::mesh::{AlphaMode, PrimitiveMode, Scene};

/// `asset.generator` of every file written.
pub const GENERATOR: &str = concat!("verdant ", env!("CARGO_PKG_VERSION"));
pub const EXT_INSTANCING: &str = "EXT_mesh_gpu_instancing";
pub const EXT_LOD: &str = "MSFT_lod";
/// Key in a LoD node's extras holding the screen coverage of each level (MSFT_lod convention).
pub const LOD_COVERAGE_KEY: &str = "MSFT_screencoverage";

/// Name of the second glTF scene, which holds the nodes shown only as MSFT_lod levels.
pub const LOD_SCENE_NAME: &str = "MSFT_lod levels (not shown by default)";

/// Largest index written as UNSIGNED_SHORT.
pub const MAX_U16_INDEX: u32 = 65534;

const ARRAY_BUFFER: json::buffer::Target = json::buffer::Target::ArrayBuffer;
const ELEMENT_ARRAY_BUFFER: json::buffer::Target = json::buffer::Target::ElementArrayBuffer;

/// KHR_mesh_quantization: integer vertex attributes, dequantized by the node transform.
pub const KHR_QUANTIZATION: &str = "KHR_mesh_quantization";
/// KHR_texture_transform: puts quantized texture coordinates outside 0..1 back (offset, scale).
pub const KHR_TEXTURE_TRANSFORM: &str = "KHR_texture_transform";
/// Key in a quantized mesh's extras holding its grid (`origin`, `step`: a stored integer q is at
/// origin + step·q in the mesh's own frame): the node's transform carries the grid too, but a
/// reader that places the mesh itself needs the mesh's own coordinates.
pub const GRID_EXTRAS_KEY: &str = "verdant_quantization_grid";
/// Primitive extras of a compact file: `{ "_NAME": [r0, r1, r2, r3] }` for each custom attribute
/// stored as normalized unsigned bytes of value / range (`CustomAttribute::range`, e.g. wind); a
/// reader multiplies the normalized value by the range to get the value back.
pub const ATTRIBUTE_RANGES_KEY: &str = "verdant_attribute_ranges";

/// How vertex data is stored.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WriteOptions {
    /// Store positions as 16-bit integers (KHR_mesh_quantization, see [`super::quantize`]): on
    /// one grid for every mesh (normals 16-bit, pre-scaled so the node's scale turns them back), or
    /// on a uniform grid per mesh family (normals and tangents 8-bit); the node (or its instances)
    /// gets the grid's scale and translation; texture coordinates 16-bit normalized.
    pub quantization: Quantization,
    /// Compress vertex and index data with meshoptimizer's codecs (EXT_meshopt_compression,
    /// lossless; required by the file, so loaders need its decoder). MSFT_lod levels then stay in
    /// the one binary chunk (no streaming buffers).
    pub meshopt: bool,
    /// With [`Quantization::PerMesh`]: meshes of these names (and their families) are stored on
    /// the grid given instead of their own (a chunked terrain's chunks on one grid: the seams stay
    /// closed).
    pub mesh_grids: Vec<(String, MeshGrid)>,
}

/// EXT_meshopt_compression: bufferViews decoded by meshoptimizer's vertex and index codecs.
pub const EXT_MESHOPT: &str = "EXT_meshopt_compression";

/// How a bufferView's bytes can be compressed.
#[derive(Debug, Clone, Copy)]
enum Codec {
    /// Vertex data: `count` elements of `stride` bytes (a multiple of 4).
    Attributes { stride: usize, count: usize },
    /// A triangle list of `count` indices of `size` bytes.
    Triangles { size: usize, count: usize },
}

/// The scene as one GLB file.
pub fn to_glb(scene: &Scene) -> Result<Vec<u8>, SceneProblem> {
    to_glb_with(scene, &WriteOptions::default())
}

/// [`to_glb`] with storage options.
pub fn to_glb_with(scene: &Scene, opts: &WriteOptions) -> Result<Vec<u8>, SceneProblem> {
    let glb = to_glb_parts(scene, opts)?;
    let mut out = Vec::with_capacity(glb.byte_len());
    glb.write(&mut out).map_err(|e| SceneProblem(e.to_string()))?;
    Ok(out)
}

/// [`to_glb_with`] as its two chunks, for writing straight to a file ([`Glb::write`]) without
/// the whole container in memory beside them; the glTF tree is dropped once serialised.
pub fn to_glb_parts(scene: &Scene, opts: &WriteOptions) -> Result<Glb, SceneProblem> {
    let (root, bin, levels) = build(scene, None, opts)?;
    let json = json_bytes(&root, false, opts)?;
    drop(root);
    let uris = level_uri_offsets(&json, levels)?;
    let glb = Glb { json, uris, bin };
    u32::try_from(glb.byte_len()).map_err(|_| {
        SceneProblem(format!(
            "the GLB would be {} bytes, over the format's 4 GiB limit; split the scene",
            glb.byte_len()
        ))
    })?;
    Ok(glb)
}

/// A GLB's JSON and BIN chunks (unpadded), at most 4 GiB together ([`to_glb_parts`] checks).
///
/// The MSFT_lod level buffers' `data:` URIs are not in `json` yet: each is kept as its raw bytes
/// with the offset its base64 goes to, and encoded as the file is written. A world's level buffers
/// run to a hundred megabytes; as base64 strings in the glTF tree and again in its serialised text
/// they were the largest things a scene write held (about 300 MB on presets/worlds/highlands.toml).
pub struct Glb {
    json: Vec<u8>,
    /// (offset in `json`, raw bytes): the base64 of the bytes is the URI's payload, inserted there.
    uris: Vec<(usize, Vec<u8>)>,
    bin: Vec<u8>,
}

/// The `uri` of a level buffer until its payload is written: a `data:` URI with nothing after the
/// comma ([`Glb`]).
const LEVEL_URI: &str = "data:application/octet-stream;base64,";

/// The length of the base64 of `n` bytes (padded).
fn base64_len(n: usize) -> usize {
    n.div_ceil(3) * 4
}

/// Where each level buffer's payload goes in the serialised JSON: just after the comma of the
/// k-th `"uri":"data:application/octet-stream;base64,"` followed by its closing quote. The key
/// and its quotes appear unescaped only as the JSON's own structure (a name holding that text is
/// escaped as `\"uri\":\"…`), so the matches are the buffers' `uri` members, in buffer order.
fn level_uri_offsets(json: &[u8], levels: Vec<Vec<u8>>) -> Result<Vec<(usize, Vec<u8>)>, SceneProblem> {
    if levels.is_empty() {
        return Ok(Vec::new());
    }
    let pattern = format!("\"uri\":\"{LEVEL_URI}\"");
    let pattern = pattern.as_bytes();
    let offsets: Vec<usize> = json
        .windows(pattern.len())
        .enumerate()
        .filter(|(_, w)| *w == pattern)
        .map(|(at, _)| at + pattern.len() - 1)
        .collect();
    if offsets.len() != levels.len() {
        return Err(SceneProblem(format!(
            "internal: {} level buffers but {} empty data: URIs in the glTF JSON",
            levels.len(),
            offsets.len()
        )));
    }
    Ok(offsets.into_iter().zip(levels).collect())
}

impl Glb {
    /// The JSON chunk's length with the level buffers' base64 in it (unpadded).
    fn json_len(&self) -> usize {
        self.json.len() + self.uris.iter().map(|(_, data)| base64_len(data.len())).sum::<usize>()
    }

    /// The container's length in bytes (header, chunks and their padding).
    pub fn byte_len(&self) -> usize {
        let bin = if self.bin.is_empty() { 0 } else { 8 + self.bin.len().next_multiple_of(4) };
        12 + 8 + self.json_len().next_multiple_of(4) + bin
    }

    /// Writes the container: header, JSON chunk padded with spaces, BIN chunk (when there is data)
    /// padded with zeros (glTF 2.0 §4.4).
    pub fn write(&self, w: &mut dyn std::io::Write) -> std::io::Result<()> {
        let (json_len, bin_len) = (self.json_len().next_multiple_of(4), self.bin.len().next_multiple_of(4));
        w.write_all(b"glTF")?;
        w.write_all(&2u32.to_le_bytes())?;
        w.write_all(&(self.byte_len() as u32).to_le_bytes())?;
        w.write_all(&(json_len as u32).to_le_bytes())?;
        w.write_all(b"JSON")?;
        let mut from = 0;
        let mut text = String::new();
        for (at, data) in &self.uris {
            w.write_all(&self.json[from..*at])?;
            // in pieces of 3 × 64 KiB: whole groups of three bytes, so the pieces' base64 joins up
            for piece in data.chunks(3 << 16) {
                text.clear();
                push_base64(&mut text, piece);
                w.write_all(text.as_bytes())?;
            }
            from = *at;
        }
        w.write_all(&self.json[from..])?;
        w.write_all(&b"   "[..json_len - self.json_len()])?;
        if !self.bin.is_empty() {
            w.write_all(&(bin_len as u32).to_le_bytes())?;
            w.write_all(b"BIN\0")?;
            w.write_all(&self.bin)?;
            w.write_all(&[0u8; 3][..bin_len - self.bin.len()])?;
        }
        Ok(())
    }
}

/// The scene as `.gltf` JSON (pretty-printed) and the contents of the `.bin` file it refers to as
/// `bin_name` (a file name in the same folder). The bin is empty, and not referenced, when the
/// scene holds no data.
pub fn to_gltf(scene: &Scene, bin_name: &str) -> Result<(Vec<u8>, Vec<u8>), SceneProblem> {
    to_gltf_with(scene, bin_name, &WriteOptions::default())
}

/// [`to_gltf`] with storage options.
pub fn to_gltf_with(scene: &Scene, bin_name: &str, opts: &WriteOptions) -> Result<(Vec<u8>, Vec<u8>), SceneProblem> {
    // (a .gltf keeps one .bin: no level buffers)
    let (root, bin, _) = build(scene, Some(&uri_encode(bin_name)), opts)?;
    let mut json = json_bytes(&root, true, opts)?;
    json.push(b'\n');
    Ok((json, bin))
}

/// The JSON text. With quantized positions, every node's translation and scale (which carry the
/// dequantization) are written as the exact values of their f32s, so a reader in f64 (JavaScript)
/// and one in f32 get the same numbers: the shortest f32 decimal would differ in f64 by up to half
/// an f32 step, times 65,535 across the grid.
fn json_bytes(root: &json::Root, pretty: bool, opts: &WriteOptions) -> Result<Vec<u8>, SceneProblem> {
    let fail = |e: serde_json::Error| SceneProblem(format!("cannot serialise the glTF JSON: {e}"));
    if !opts.quantization.is_on() {
        return if pretty { root.to_vec_pretty() } else { root.to_vec() }.map_err(fail);
    }
    let mut value = serde_json::to_value(root).map_err(fail)?;
    for node in value.get_mut("nodes").and_then(Value::as_array_mut).into_iter().flatten() {
        for key in ["translation", "scale"] {
            if let Some(Value::Array(xs)) = node.get_mut(key) {
                for x in xs.iter_mut() {
                    if let Some(v) = x.as_f64() {
                        *x = exact(v as f32);
                    }
                }
            }
        }
    }
    if pretty { serde_json::to_vec_pretty(&value) } else { serde_json::to_vec(&value) }.map_err(fail)
}

/// Percent-encodes everything but RFC 3986 unreserved characters (a relative URI for a file name).
fn uri_encode(name: &str) -> String {
    let mut s = String::new();
    for b in name.bytes() {
        if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.' | b'~') {
            s.push(b as char);
        } else {
            s.push_str(&format!("%{b:02X}"));
        }
    }
    s
}

/// The binary buffers under construction (one per load group: 0 the GLB chunk or `.bin`) and
/// their views.
struct Bin {
    groups: Vec<Vec<u8>>,
    /// Which group the next views go to.
    group: usize,
    views: Vec<json::buffer::View>,
    /// Per view: how its bytes compress, if they are vertex or index data.
    codecs: Vec<Option<Codec>>,
}

impl Bin {
    fn push_view(&mut self, bytes: &[u8], target: Option<json::buffer::Target>) -> Index<json::buffer::View> {
        let data = &mut self.groups[self.group];
        data.resize(data.len().next_multiple_of(4), 0);
        let offset = data.len();
        data.extend_from_slice(bytes);
        self.views.push(json::buffer::View {
            // the group for now: `build` renumbers to the buffers written
            buffer: Index::new(self.group as u32),
            byte_length: USize64::from(bytes.len()),
            byte_offset: if offset == 0 { None } else { Some(USize64::from(offset)) },
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: None,
        });
        self.codecs.push(None);
        Index::new(self.views.len() as u32 - 1)
    }
}

/// EXT_meshopt_compression over the one group of `bin`: every vertex and index view's bytes are
/// encoded (vertex codec version 0, index codec version 1, as the extension specifies) into buffer
/// 0, which also keeps the other views (images) as they are; the views themselves move to buffer
/// 1, a fallback buffer without data that the decoder fills. Returns buffer 0's bytes and whether
/// any view was encoded (a view whose encoding is not smaller stays as it is).
fn compress_views(
    root: &mut json::Root,
    bin: &mut Bin,
    bin_uri: Option<&str>,
) -> Result<(Vec<u8>, bool), SceneProblem> {
    let data = std::mem::take(&mut bin.groups[0]);
    let (mut out, mut fallback_len) = (Vec::with_capacity(data.len() / 2), 0usize);
    let fail = |e: crate::meshopt_guard::FfiError| SceneProblem(format!("could not encode a buffer: {e}"));
    for (view, codec) in bin.views.iter_mut().zip(&bin.codecs) {
        let offset = view.byte_offset.map_or(0, |o| o.0 as usize);
        let bytes = &data[offset..offset + view.byte_length.0 as usize];
        out.resize(out.len().next_multiple_of(4), 0);
        let raw = |view: &mut json::buffer::View, out: &mut Vec<u8>| {
            view.byte_offset = (!out.is_empty()).then(|| USize64::from(out.len()));
            view.buffer = Index::new(0);
            out.extend_from_slice(bytes);
        };
        let Some(codec) = codec else {
            raw(view, &mut out);
            continue;
        };
        let (encoded, mode, stride, count) = match *codec {
            Codec::Attributes { stride, count } => {
                (encode_vertices(bytes, stride).map_err(fail)?, "ATTRIBUTES", stride, count)
            }
            Codec::Triangles { size, count } => {
                let indices: Vec<u32> = match size {
                    2 => bytes.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]]) as u32).collect(),
                    _ => bytes.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect(),
                };
                let vertex_count = indices.iter().max().map_or(0, |&m| m as usize + 1);
                (
                    crate::meshopt_guard::encode_index_buffer(&indices, vertex_count).map_err(fail)?,
                    "TRIANGLES",
                    size,
                    count,
                )
            }
        };
        // a few vertices encode larger than they are (the codec's headers): such a view stays raw
        if encoded.len() >= bytes.len() {
            raw(view, &mut out);
            continue;
        }
        let mut ext = Map::new();
        ext.insert(
            EXT_MESHOPT.into(),
            serde_json::json!({
                "buffer": 0, "byteOffset": out.len(), "byteLength": encoded.len(),
                "byteStride": stride, "count": count, "mode": mode,
            }),
        );
        view.extensions = Some(json::extensions::buffer::View { others: ext });
        out.extend_from_slice(&encoded);
        fallback_len = fallback_len.next_multiple_of(4);
        view.byte_offset = (fallback_len > 0).then(|| USize64::from(fallback_len));
        view.buffer = Index::new(1);
        fallback_len += view.byte_length.0 as usize;
    }
    out.resize(out.len().next_multiple_of(4), 0);
    root.buffers.push(json::Buffer {
        byte_length: USize64::from(out.len()),
        name: None,
        uri: bin_uri.map(str::to_string),
        extensions: None,
        extras: None,
    });
    if fallback_len == 0 {
        // nothing encoded smaller than it is: no compressed view, no fallback buffer
        return Ok((out, false));
    }
    let mut ext = Map::new();
    ext.insert(EXT_MESHOPT.into(), serde_json::json!({ "fallback": true }));
    root.buffers.push(json::Buffer {
        byte_length: USize64::from(fallback_len.next_multiple_of(4)),
        name: Some("EXT_meshopt_compression fallback (no data: decoded on load)".into()),
        uri: None,
        extensions: Some(json::extensions::buffer::Buffer { others: ext }),
        extras: None,
    });
    Ok((out, true))
}

/// meshoptimizer's vertex codec (version 0, the one EXT_meshopt_compression reads) over elements
/// of `stride` bytes.
fn encode_vertices(bytes: &[u8], stride: usize) -> Result<Vec<u8>, crate::meshopt_guard::FfiError> {
    fn typed<const N: usize>(bytes: &[u8]) -> Result<Vec<u8>, crate::meshopt_guard::FfiError> {
        let elements: Vec<[u8; N]> = bytes.chunks_exact(N).map(|c| c.try_into().unwrap_or([0; N])).collect();
        crate::meshopt_guard::encode_vertex_buffer(&elements)
    }
    match stride {
        4 => typed::<4>(bytes),
        8 => typed::<8>(bytes),
        12 => typed::<12>(bytes),
        16 => typed::<16>(bytes),
        _ => Err(crate::meshopt_guard::FfiError {
            call: "vertex encoder",
            problem: format!("no vertex codec for {stride}-byte elements"),
        }),
    }
}

/// The KHR_mesh_quantization attribute writers.
mod quantized {
    use super::*;

    /// A view of `stride`-byte elements for vertex data.
    fn strided_view(bin: &mut Bin, bytes: &[u8], stride: usize) -> Index<json::buffer::View> {
        let view = bin.push_view(bytes, Some(ARRAY_BUFFER));
        bin.views[view.value()].byte_stride = Some(json::buffer::Stride(stride));
        bin.codecs[view.value()] = Some(Codec::Attributes { stride, count: bytes.len() / stride });
        view
    }

    /// POSITION as UNSIGNED_SHORT VEC3 on `grid` (8-byte elements), min/max the integers.
    pub(super) fn positions(
        root: &mut json::Root,
        bin: &mut Bin,
        positions: &[[f32; 3]],
        grid: &PositionGrid,
    ) -> Result<Index<json::Accessor>, SceneProblem> {
        let mut bytes = Vec::with_capacity(positions.len() * 8);
        let (mut lo, mut hi) = ([u16::MAX; 3], [0u16; 3]);
        for p in positions {
            for a in 0..3 {
                let q = grid.quantize(a, p[a]);
                let q = u16::try_from(q).map_err(|_| {
                    SceneProblem(format!(
                        "position {p:?} lies outside the 16-bit grid {grid:?}: write without quantization"
                    ))
                })?;
                lo[a] = lo[a].min(q);
                hi[a] = hi[a].max(q);
                bytes.extend_from_slice(&q.to_le_bytes());
            }
            bytes.extend_from_slice(&[0, 0]);
        }
        let view = strided_view(bin, &bytes, 8);
        let mut acc = accessor(view, positions.len(), json::accessor::ComponentType::U16, json::accessor::Type::Vec3);
        acc.min = Some(Value::Array(lo.iter().map(|&q| Value::from(q)).collect()));
        acc.max = Some(Value::Array(hi.iter().map(|&q| Value::from(q)).collect()));
        Ok(root.push(acc))
    }

    /// NORMAL as normalized BYTE VEC3 (4-byte elements) on a uniform grid, whose scale leaves
    /// normals as they are; else as SHORT, see [`normals16`].
    pub(super) fn normals(
        root: &mut json::Root,
        bin: &mut Bin,
        normals: &[[f32; 3]],
        grid: &MeshGrid,
    ) -> Index<json::Accessor> {
        if !grid.uniform {
            return normals16(root, bin, normals, &grid.grid);
        }
        let bytes: Vec<u8> = normals.iter().flat_map(|n| snorm8([n[0], n[1], n[2], 0.0])).collect();
        snorm8_accessor(root, bin, &bytes, json::accessor::Type::Vec3)
    }

    /// Normalized signed bytes, 4 a vertex (`type_` VEC3 or VEC4), over their own view.
    fn snorm8_accessor(
        root: &mut json::Root,
        bin: &mut Bin,
        bytes: &[u8],
        type_: json::accessor::Type,
    ) -> Index<json::Accessor> {
        let view = strided_view(bin, bytes, 4);
        let mut acc = accessor(view, bytes.len() / 4, json::accessor::ComponentType::I8, type_);
        acc.normalized = true;
        root.push(acc)
    }

    /// Four components in -1..1 as normalized signed bytes.
    fn snorm8(v: [f32; 4]) -> [u8; 4] {
        v.map(|c| ((c.clamp(-1.0, 1.0) * 127.0).round() as i8) as u8)
    }

    /// NORMAL as normalized SHORT VEC3: each normal scaled by the grid's steps and renormalised,
    /// so that the node's (non-uniform) scale, applied to normals by its inverse transpose, gives
    /// the normal back. 16 bits, as the scale can make the stored normal nearly flat.
    fn normals16(
        root: &mut json::Root,
        bin: &mut Bin,
        normals: &[[f32; 3]],
        grid: &PositionGrid,
    ) -> Index<json::Accessor> {
        let mut bytes = Vec::with_capacity(normals.len() * 8);
        for n in normals {
            let v = [0, 1, 2].map(|a| n[a] as f64 * grid.step[a] as f64);
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(f64::MIN_POSITIVE);
            for c in v {
                bytes.extend_from_slice(&(((c / len) * 32767.0).round() as i16).to_le_bytes());
            }
            bytes.extend_from_slice(&[0, 0]);
        }
        let view = strided_view(bin, &bytes, 8);
        let mut acc = accessor(view, normals.len(), json::accessor::ComponentType::I16, json::accessor::Type::Vec3);
        acc.normalized = true;
        root.push(acc)
    }

    /// TEXCOORD_0 within 0..1, or within `range` (put back by the material's
    /// KHR_texture_transform), as normalized UNSIGNED_SHORT VEC2.
    pub(super) fn uvs(
        root: &mut json::Root,
        bin: &mut Bin,
        uvs: &[[f32; 2]],
        range: Option<&UvRange>,
    ) -> Index<json::Accessor> {
        let bytes: Vec<u8> = uvs
            .iter()
            .flat_map(|uv| {
                [0, 1].map(|a| match range {
                    Some(r) => r.quantize(a, uv[a]),
                    None => (uv[a] as f64 * 65535.0).round() as u16,
                })
            })
            .flat_map(u16::to_le_bytes)
            .collect();
        let view = strided_view(bin, &bytes, 4);
        let mut acc = accessor(view, uvs.len(), json::accessor::ComponentType::U16, json::accessor::Type::Vec2);
        acc.normalized = true;
        root.push(acc)
    }

    /// TANGENT as normalized BYTE VEC4, on a uniform grid (4 bytes a vertex instead of 16; the
    /// handedness w stays ±1 exactly).
    pub(super) fn tangents(root: &mut json::Root, bin: &mut Bin, tangents: &[[f32; 4]]) -> Index<json::Accessor> {
        let bytes: Vec<u8> =
            tangents.iter().flat_map(|t| snorm8([t[0], t[1], t[2], if t[3] < 0.0 { -1.0 } else { 1.0 }])).collect();
        snorm8_accessor(root, bin, &bytes, json::accessor::Type::Vec4)
    }
}

fn f32_bytes<const N: usize>(values: &[[f32; N]]) -> Vec<u8> {
    values.iter().flatten().flat_map(|x| x.to_le_bytes()).collect()
}

fn accessor(
    view: Index<json::buffer::View>,
    count: usize,
    component: json::accessor::ComponentType,
    type_: json::accessor::Type,
) -> json::Accessor {
    json::Accessor {
        buffer_view: Some(view),
        byte_offset: None,
        count: USize64::from(count),
        component_type: Valid(json::accessor::GenericComponentType(component)),
        extensions: None,
        extras: None,
        type_: Valid(type_),
        min: None,
        max: None,
        name: None,
        normalized: false,
        sparse: None,
    }
}

/// A VEC4 vertex attribute of values in 0..1 as normalized unsigned bytes over its own new
/// bufferView (4 bytes a vertex, aligned as glTF asks); values are rounded to the nearest k/255.
fn unit_byte_accessor(root: &mut json::Root, bin: &mut Bin, values: &[[f32; 4]]) -> Index<json::Accessor> {
    ranged_byte_accessor(root, bin, values, [1.0; 4])
}

/// Normalized unsigned bytes of value / range ([`super::quantize::range_byte`]) over their own
/// new bufferView.
fn ranged_byte_accessor(
    root: &mut json::Root,
    bin: &mut Bin,
    values: &[[f32; 4]],
    range: [f32; 4],
) -> Index<json::Accessor> {
    let bytes: Vec<u8> = values
        .iter()
        .flat_map(|v| std::array::from_fn::<u8, 4, _>(|k| super::quantize::range_byte(v[k], range[k])))
        .collect();
    let view = bin.push_view(&bytes, Some(ARRAY_BUFFER));
    bin.codecs[view.value()] = Some(Codec::Attributes { stride: 4, count: values.len() });
    let mut a = accessor(view, values.len(), json::accessor::ComponentType::U8, json::accessor::Type::Vec4);
    a.normalized = true;
    root.push(a)
}

/// A float accessor over its own new bufferView.
fn float_accessor<const N: usize>(
    root: &mut json::Root,
    bin: &mut Bin,
    values: &[[f32; N]],
    target: Option<json::buffer::Target>,
) -> Index<json::Accessor> {
    use json::accessor::Type;
    let type_ = match N {
        2 => Type::Vec2,
        3 => Type::Vec3,
        4 => Type::Vec4,
        _ => Type::Scalar,
    };
    let view = bin.push_view(&f32_bytes(values), target);
    if target == Some(ARRAY_BUFFER) {
        bin.codecs[view.value()] = Some(Codec::Attributes { stride: 4 * N, count: values.len() });
    }
    root.push(accessor(view, values.len(), json::accessor::ComponentType::F32, type_))
}

/// Instance transforms compress as vertex data do (EXT_meshopt_compression's ATTRIBUTES mode).
fn instance_codec(root: &json::Root, bin: &mut Bin, a: Index<json::Accessor>) {
    let acc = &root.accessors[a.value()];
    if let (Some(view), Valid(t)) = (acc.buffer_view, &acc.type_) {
        let stride = 4 * t.multiplicity();
        bin.codecs[view.value()] = Some(Codec::Attributes { stride, count: acc.count.0 as usize });
    }
}

/// Exact JSON for an f32: its f64 value, so readers in either precision get the same number back.
fn exact(x: f32) -> Value {
    Value::from(x as f64)
}

fn raw_json(v: &Value) -> Result<Box<json::extras::RawValue>, SceneProblem> {
    serde_json::value::to_raw_value(v).map_err(|e| SceneProblem(format!("cannot serialise extras: {e}")))
}

fn opt_name(name: &str) -> Option<String> {
    (!name.is_empty()).then(|| name.to_string())
}

/// Builds the glTF document and its binary buffer (`bin_uri`: None for GLB).
// `..Default::default()` on the node extension: gltf-json adds a field with KHR_lights_punctual.
#[allow(clippy::needless_update)]
/// The glTF tree, the data of its first buffer (the GLB chunk or the .bin) and, for a GLB that
/// streams MSFT_lod levels, each further buffer's data (its `uri` is [`LEVEL_URI`] with the payload
/// left out; [`Glb`] writes it).
#[allow(clippy::type_complexity)]
fn build(
    scene: &Scene,
    bin_uri: Option<&str>,
    opts: &WriteOptions,
) -> Result<(json::Root, Vec<u8>, Vec<Vec<u8>>), SceneProblem> {
    use json::accessor::{ComponentType, Type};
    check_scene(scene)?;
    let (compacted, _) = compact(scene);
    let lod_roots = compacted.lod_roots;
    let scene: &Scene = &compacted.scene;
    let stored = plan(scene, &opts.quantization, &opts.mesh_grids);
    let mut root = json::Root {
        asset: json::Asset { generator: Some(GENERATOR.to_string()), version: "2.0".into(), ..Default::default() },
        ..Default::default()
    };
    // a GLB streams MSFT_lod levels from buffers of their own; a .gltf keeps one .bin
    let groups = if bin_uri.is_none() && !opts.meshopt { load_groups(scene) } else { None };
    let mut bin = Bin {
        groups: vec![Vec::new(); groups.as_ref().map_or(1, |g| g.groups)],
        group: 0,
        views: Vec::new(),
        codecs: Vec::new(),
    };
    let mut extensions_used = BTreeSet::new();
    // an instanced node shown without instancing would be one wrong copy: loaders must support it
    let mut extensions_required = BTreeSet::new();

    // meshes: one view per attribute and per index list
    for (mi, mesh) in scene.meshes.iter().enumerate() {
        bin.group = groups.as_ref().map_or(0, |g| g.mesh[mi]);
        let mut primitives = Vec::with_capacity(mesh.primitives.len());
        let grid = stored.mesh[mi].as_ref();
        for p in &mesh.primitives {
            let mut attributes = std::collections::BTreeMap::new();
            let pos = match grid {
                None => {
                    let pos = float_accessor(&mut root, &mut bin, &p.positions, Some(ARRAY_BUFFER));
                    let bounds = p.bounds().ok_or_else(|| SceneProblem("a primitive has no positions".into()))?;
                    let acc = &mut root.accessors[pos.value()];
                    acc.min = Some(Value::Array(bounds.min.iter().map(|&x| exact(x)).collect()));
                    acc.max = Some(Value::Array(bounds.max.iter().map(|&x| exact(x)).collect()));
                    pos
                }
                Some(grid) => {
                    extensions_used.insert(KHR_QUANTIZATION);
                    extensions_required.insert(KHR_QUANTIZATION);
                    quantized::positions(&mut root, &mut bin, &p.positions, &grid.grid)?
                }
            };
            attributes.insert(Valid(json::mesh::Semantic::Positions), pos);
            if !p.normals.is_empty() {
                let a = match grid {
                    None => float_accessor(&mut root, &mut bin, &p.normals, Some(ARRAY_BUFFER)),
                    Some(grid) => quantized::normals(&mut root, &mut bin, &p.normals, grid),
                };
                attributes.insert(Valid(json::mesh::Semantic::Normals), a);
            }
            if !p.uvs.is_empty() {
                let unit = p.uvs.iter().flatten().all(|&u| (0.0..=1.0).contains(&u));
                let range = p.material.and_then(|k| stored.uv[k].as_ref());
                let a = if grid.is_some() && (unit || range.is_some()) {
                    quantized::uvs(&mut root, &mut bin, &p.uvs, range)
                } else {
                    float_accessor(&mut root, &mut bin, &p.uvs, Some(ARRAY_BUFFER))
                };
                attributes.insert(Valid(json::mesh::Semantic::TexCoords(0)), a);
            }
            // not on a non-uniform grid: Babylon.js builds its normal-map frame from the node's
            // matrix itself (not its inverse transpose), which the grid's scale bends flat; without
            // TANGENT, engines derive the frame from the surface (three.js and Babylon alike)
            if !p.tangents.is_empty() && grid.is_none_or(|g| g.uniform) {
                let a = match grid {
                    None => float_accessor(&mut root, &mut bin, &p.tangents, Some(ARRAY_BUFFER)),
                    Some(_) => quantized::tangents(&mut root, &mut bin, &p.tangents),
                };
                attributes.insert(Valid(json::mesh::Semantic::Tangents), a);
            }
            if !p.colors.is_empty() {
                let a = float_accessor(&mut root, &mut bin, &p.colors, Some(ARRAY_BUFFER));
                attributes.insert(Valid(json::mesh::Semantic::Colors(0)), a);
            }
            let mut ranges = Map::new();
            for c in &p.custom {
                let a = if c.unit_bytes {
                    unit_byte_accessor(&mut root, &mut bin, &c.values)
                } else if let Some(range) = super::quantize::attribute_range(c, &opts.quantization) {
                    ranges.insert(c.name.clone(), Value::Array(range.iter().map(|&r| exact(r)).collect()));
                    ranged_byte_accessor(&mut root, &mut bin, &c.values, range)
                } else {
                    float_accessor(&mut root, &mut bin, &c.values, Some(ARRAY_BUFFER))
                };
                attributes.insert(Valid(json::mesh::Semantic::Extras(c.name[1..].to_string())), a);
            }
            // points draw every vertex in order: no index list
            let indices = if p.indices.is_empty() && p.mode == PrimitiveMode::Points {
                None
            } else {
                let max_index = p.indices.iter().copied().max().unwrap_or(0);
                let (bytes, component): (Vec<u8>, _) = if max_index <= MAX_U16_INDEX {
                    (p.indices.iter().flat_map(|&i| (i as u16).to_le_bytes()).collect(), ComponentType::U16)
                } else {
                    (p.indices.iter().flat_map(|&i| i.to_le_bytes()).collect(), ComponentType::U32)
                };
                let view = bin.push_view(&bytes, Some(ELEMENT_ARRAY_BUFFER));
                if p.mode == PrimitiveMode::Triangles && !p.indices.is_empty() && p.indices.len().is_multiple_of(3) {
                    let size = bytes.len() / p.indices.len();
                    bin.codecs[view.value()] = Some(Codec::Triangles { size, count: p.indices.len() });
                }
                Some(root.push(accessor(view, p.indices.len(), component, Type::Scalar)))
            };
            let mode = match p.mode {
                PrimitiveMode::Triangles => json::mesh::Mode::Triangles,
                PrimitiveMode::Points => json::mesh::Mode::Points,
            };
            let extras = if ranges.is_empty() {
                None
            } else {
                let mut extras = Map::new();
                extras.insert(ATTRIBUTE_RANGES_KEY.into(), Value::Object(ranges));
                Some(raw_json(&Value::Object(extras))?)
            };
            primitives.push(json::mesh::Primitive {
                attributes,
                extensions: None,
                extras,
                indices,
                material: p.material.map(|m| Index::new(m as u32)),
                mode: Valid(mode),
                targets: None,
            });
        }
        // the grid, for readers that take the mesh out of its node (verdant's stages): exact f32s
        let extras = match (grid, &mesh.extras) {
            (Some(g), None | Some(Value::Object(_))) => {
                let mut map = match &mesh.extras {
                    Some(Value::Object(m)) => m.clone(),
                    _ => Map::new(),
                };
                map.insert(
                    GRID_EXTRAS_KEY.into(),
                    serde_json::json!({ "origin": g.grid.origin.map(exact), "step": g.grid.step.map(exact) }),
                );
                Some(raw_json(&Value::Object(map))?)
            }
            _ => mesh.extras.as_ref().map(raw_json).transpose()?,
        };
        root.push(json::Mesh { extensions: None, extras, name: opt_name(&mesh.name), primitives, weights: None });
    }

    // materials
    for (k, m) in scene.materials.iter().enumerate() {
        // quantized texture coordinates outside 0..1 are put back by every texture the material samples
        let uv_transform = stored.uv[k].map(|r| {
            extensions_used.insert(KHR_TEXTURE_TRANSFORM);
            extensions_required.insert(KHR_TEXTURE_TRANSFORM);
            let mut ext = Map::new();
            ext.insert(
                KHR_TEXTURE_TRANSFORM.into(),
                serde_json::json!({ "offset": r.offset.map(exact), "scale": r.scale.map(exact) }),
            );
            json::extensions::texture::Info { others: ext, ..Default::default() }
        });
        let (alpha_mode, alpha_cutoff) = match m.alpha_mode {
            AlphaMode::Opaque => (json::material::AlphaMode::Opaque, None),
            AlphaMode::Mask { cutoff } => (json::material::AlphaMode::Mask, Some(json::material::AlphaCutoff(cutoff))),
            AlphaMode::Blend => (json::material::AlphaMode::Blend, None),
        };
        let base_color_texture = m.base_color_texture.map(|t| json::texture::Info {
            index: Index::new(t as u32),
            tex_coord: 0,
            extensions: uv_transform.clone(),
            extras: None,
        });
        root.push(json::Material {
            alpha_cutoff,
            alpha_mode: Valid(alpha_mode),
            double_sided: m.double_sided,
            name: opt_name(&m.name),
            normal_texture: m.normal_texture.map(|t| json::material::NormalTexture {
                index: Index::new(t as u32),
                scale: 1.0,
                tex_coord: 0,
                extensions: uv_transform.as_ref().map(|e| json::extensions::material::NormalTexture {
                    others: e.others.clone(),
                    ..Default::default()
                }),
                extras: None,
            }),
            pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                base_color_factor: json::material::PbrBaseColorFactor(m.base_color),
                base_color_texture,
                metallic_factor: json::material::StrengthFactor(m.metallic),
                roughness_factor: json::material::StrengthFactor(m.roughness),
                metallic_roughness_texture: None,
                extensions: None,
                extras: None,
            },
            ..Default::default()
        });
    }

    // nodes, with instancing accessors appended after the mesh data; nodes with equal instances
    // (the levels of one MSFT_lod chain) share one set of accessors
    bin.group = 0;
    let mut written_instances: std::collections::HashMap<u64, Vec<(&crate::mesh::Instances, Value)>> =
        std::collections::HashMap::new();
    let grid_of = |node: &crate::mesh::Node| node.mesh.and_then(|m| stored.mesh[m].as_ref());
    // an instanced quantized mesh: its instances carry the grid (the node's transform applies after theirs)
    let placed: Vec<Option<crate::mesh::Instances>> = scene
        .nodes
        .iter()
        .map(|node| match (grid_of(node), node.instances.as_ref().filter(|i| !i.is_empty())) {
            (Some(g), Some(inst)) => Some(place_instances(inst, &g.grid)),
            _ => None,
        })
        .collect();
    for (ni, node) in scene.nodes.iter().enumerate() {
        let mut ext = Map::new();
        let instances = placed[ni].as_ref().or(node.instances.as_deref());
        if let Some(inst) = instances.filter(|i| !i.is_empty()) {
            let key = instances_hash(inst);
            if let Some((_, attributes)) = written_instances.get(&key).and_then(|v| v.iter().find(|(i, _)| *i == inst))
            {
                ext.insert(EXT_INSTANCING.into(), serde_json::json!({ "attributes": attributes }));
            } else {
                let mut attributes = Map::new();
                if !inst.translations.is_empty() {
                    let a = float_accessor(&mut root, &mut bin, &inst.translations, None);
                    instance_codec(&root, &mut bin, a);
                    attributes.insert("TRANSLATION".into(), Value::from(a.value()));
                }
                if !inst.rotations.is_empty() {
                    let a = float_accessor(&mut root, &mut bin, &inst.rotations, None);
                    instance_codec(&root, &mut bin, a);
                    attributes.insert("ROTATION".into(), Value::from(a.value()));
                }
                if !inst.scales.is_empty() {
                    let a = float_accessor(&mut root, &mut bin, &inst.scales, None);
                    instance_codec(&root, &mut bin, a);
                    attributes.insert("SCALE".into(), Value::from(a.value()));
                }
                let attributes = Value::Object(attributes);
                ext.insert(EXT_INSTANCING.into(), serde_json::json!({ "attributes": attributes }));
                written_instances.entry(key).or_default().push((inst, attributes));
            }
            extensions_used.insert(EXT_INSTANCING);
            extensions_required.insert(EXT_INSTANCING);
        }
        let mut extras = node.extras.clone();
        if !node.lods.is_empty() {
            ext.insert(EXT_LOD.into(), serde_json::json!({ "ids": node.lods }));
            extensions_used.insert(EXT_LOD);
            if !node.lod_screen_coverage.is_empty() {
                let coverage = Value::Array(node.lod_screen_coverage.iter().map(|&c| Value::from(c)).collect());
                let mut map = match extras {
                    Some(Value::Object(map)) => map,
                    _ => Map::new(), // check_scene allows only objects or nothing here
                };
                map.insert(LOD_COVERAGE_KEY.into(), coverage);
                extras = Some(Value::Object(map));
            }
        }
        // a quantized mesh is placed by its node (or its instances, above): the grid's scale and
        // origin join its transform
        let (mut translation, mut scale) = (node.translation, node.scale);
        if let (Some(grid), None) = (grid_of(node), &placed[ni]) {
            if !node.children.is_empty() {
                return Err(SceneProblem(format!(
                    "node {:?} holds a mesh and children: quantized positions on one grid need the node to itself; write without quantization",
                    node.name
                )));
            }
            (translation, scale) = place(node.rotation, translation, scale, &grid.grid);
        }
        let is = |v: &[f32], identity: &[f32]| v == identity;
        root.push(json::Node {
            children: (!node.children.is_empty())
                .then(|| node.children.iter().map(|&c| Index::new(c as u32)).collect()),
            extensions: (!ext.is_empty()).then(|| json::extensions::scene::Node { others: ext, ..Default::default() }),
            extras: extras.as_ref().map(raw_json).transpose()?,
            mesh: node.mesh.map(|m| Index::new(m as u32)),
            name: opt_name(&node.name),
            rotation: (!is(&node.rotation, &[0.0, 0.0, 0.0, 1.0]))
                .then_some(json::scene::UnitQuaternion(node.rotation)),
            scale: (!is(&scale, &[1.0; 3])).then_some(scale),
            translation: (!is(&translation, &[0.0; 3])).then_some(translation),
            ..Default::default()
        });
    }

    // textures: PNG bytes in views without target; one shared sampler
    if !scene.textures.is_empty() {
        let sampler = root.push(json::texture::Sampler {
            mag_filter: Some(Valid(json::texture::MagFilter::Linear)),
            min_filter: Some(Valid(json::texture::MinFilter::LinearMipmapLinear)),
            wrap_s: Valid(json::texture::WrappingMode::Repeat),
            wrap_t: Valid(json::texture::WrappingMode::Repeat),
            ..Default::default()
        });
        for (ti, t) in scene.textures.iter().enumerate() {
            bin.group = groups.as_ref().map_or(0, |g| g.texture[ti]);
            let view = bin.push_view(&t.png, None);
            let image = root.push(json::Image {
                buffer_view: Some(view),
                mime_type: Some(json::image::MimeType("image/png".into())),
                name: opt_name(&t.name),
                uri: None,
                extensions: None,
                extras: None,
            });
            root.push(json::Texture {
                name: opt_name(&t.name),
                sampler: Some(sampler),
                source: image,
                extensions: None,
                extras: None,
            });
        }
    }

    // scene, buffer, extension lists
    // A scene without nodes is valid glTF, but the gltf crate (and so `verdant validate`) cannot
    // read one; a scene with no roots has nothing to show, so it is left out with its name/extras.
    if !scene.roots.is_empty() {
        root.scenes.push(json::Scene {
            extensions: None,
            extras: scene.extras.as_ref().map(raw_json).transpose()?,
            name: opt_name(&scene.name),
            nodes: scene.roots.iter().map(|&r| Index::new(r as u32)).collect(),
        });
        root.scene = Some(Index::new(0));
        // levels shown only through MSFT_lod: a second scene, so they are used but not shown by
        // importers that ignore the extension (see `compact`)
        if !lod_roots.is_empty() {
            root.scenes.push(json::Scene {
                extensions: None,
                extras: None,
                name: Some(LOD_SCENE_NAME.into()),
                nodes: lod_roots.iter().map(|&r| Index::new(r as u32)).collect(),
            });
        }
    }
    // (a scene with no vertex or index data has nothing to compress)
    if opts.meshopt && bin.codecs.iter().any(Option::is_some) {
        let (chunk, compressed) = compress_views(&mut root, &mut bin, bin_uri)?;
        if compressed {
            extensions_used.insert(EXT_MESHOPT);
            extensions_required.insert(EXT_MESHOPT);
        }
        root.buffer_views = bin.views;
        root.extensions_used = extensions_used.into_iter().map(str::to_string).collect();
        root.extensions_required = extensions_required.into_iter().map(str::to_string).collect();
        return Ok((root, chunk, Vec::new()));
    }
    // buffers: group 0 is the GLB chunk (or the .bin), the other non-empty groups data: URIs
    let mut chunk = Vec::new();
    let mut levels = Vec::new();
    let mut buffer_of = vec![0u32; bin.groups.len()];
    for (g, mut data) in bin.groups.into_iter().enumerate() {
        data.resize(data.len().next_multiple_of(4), 0);
        if data.is_empty() {
            continue;
        }
        buffer_of[g] = root.buffers.len() as u32;
        // a level's payload is written with the file ([`Glb`])
        let uri = if g == 0 { bin_uri.map(str::to_string) } else { Some(LEVEL_URI.to_string()) };
        root.buffers.push(json::Buffer {
            byte_length: USize64::from(data.len()),
            name: (g > 0).then(|| format!("MSFT_lod level {g} from the coarsest")),
            uri,
            extensions: None,
            extras: None,
        });
        if g == 0 {
            chunk = data;
        } else {
            levels.push(data);
        }
    }
    for v in &mut bin.views {
        v.buffer = Index::new(buffer_of[v.buffer.value()]);
    }
    root.buffer_views = bin.views;
    root.extensions_used = extensions_used.into_iter().map(str::to_string).collect();
    root.extensions_required = extensions_required.into_iter().map(str::to_string).collect();
    Ok((root, chunk, levels))
}

/// A hash of every instance transform's bits (equal instances hash equal; candidates are then
/// compared in full).
fn instances_hash(inst: &crate::mesh::Instances) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for t in &inst.translations {
        t.map(f32::to_bits).hash(&mut h);
    }
    for r in &inst.rotations {
        r.map(f32::to_bits).hash(&mut h);
    }
    for s in &inst.scales {
        s.map(f32::to_bits).hash(&mut h);
    }
    (inst.translations.len(), inst.rotations.len(), inst.scales.len()).hash(&mut h);
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Mesh, Primitive};

    fn triangle_scene(max_index: u32) -> Scene {
        let n = max_index as usize + 1;
        let positions: Vec<[f32; 3]> = (0..n).map(|i| [i as f32, 0.0, (i % 7) as f32]).collect();
        let mut scene = Scene::default();
        let prim = Primitive { positions, indices: vec![0, max_index, 1], ..Primitive::default() };
        scene.add_mesh_node(Mesh { name: "m".into(), primitives: vec![prim], extras: None });
        scene
    }

    fn index_component(scene: &Scene) -> json::accessor::ComponentType {
        let (root, _, _) = build(scene, None, &WriteOptions::default()).unwrap();
        let acc = root.meshes[0].primitives[0].indices.unwrap();
        match root.accessors[acc.value()].component_type {
            Valid(t) => t.0,
            _ => unreachable!(),
        }
    }

    #[test]
    fn index_width_switches_above_65534() {
        assert_eq!(index_component(&triangle_scene(65534)), json::accessor::ComponentType::U16);
        assert_eq!(index_component(&triangle_scene(65535)), json::accessor::ComponentType::U32);
    }

    /// Folding the grid into a rotated, scaled, translated node places a quantized vertex where the
    /// node put the float one: T·R·S·(origin + step∘q) = T'·R·S'·q.
    #[test]
    fn the_grid_folds_into_any_node_transform() {
        let grid = PositionGrid { origin: [1.5, -20.0, 3.0], step: [0.5, 0.25, 2.0] };
        let rotation = glam::Quat::from_euler(glam::EulerRot::YXZ, 0.7, -0.3, 0.2).to_array();
        let (t, s) = ([10.0, 5.0, -2.0], [2.0, 0.5, 1.5]);
        let (t2, s2) = place(rotation, t, s, &grid);
        let r = glam::Quat::from_array(rotation);
        for q in [[0.0f32, 0.0, 0.0], [3.0, 7.0, 11.0], [65535.0, 1.0, 2.0]] {
            let local = glam::Vec3::from_array([0, 1, 2].map(|a| grid.origin[a] + grid.step[a] * q[a]));
            let want = glam::Vec3::from_array(t) + r * (glam::Vec3::from_array(s) * local);
            let got = glam::Vec3::from_array(t2) + r * (glam::Vec3::from_array(s2) * glam::Vec3::from_array(q));
            assert!((want - got).length() < 1e-3 * (1.0 + want.length()), "{want} vs {got}");
        }
    }

    #[test]
    fn positions_off_the_grid_are_refused() {
        let grid = PositionGrid { origin: [0.0; 3], step: [1.0; 3] };
        let opts = WriteOptions { quantization: Quantization::Grid(grid), ..WriteOptions::default() };
        assert!(to_glb_with(&triangle_scene(2), &opts).is_ok());
        let mut far = triangle_scene(2);
        far.meshes[0].primitives[0].positions[0] = [70000.0, 0.0, 0.0];
        let err = to_glb_with(&far, &opts).unwrap_err();
        assert!(err.0.contains("outside the 16-bit grid"), "{}", err.0);
    }

    #[test]
    fn glb_chunks_are_padded_and_aligned() {
        let glb = to_glb(&triangle_scene(2)).unwrap();
        assert_eq!(&glb[0..4], b"glTF");
        assert_eq!(u32::from_le_bytes(glb[8..12].try_into().unwrap()) as usize, glb.len());
        let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
        assert_eq!(json_len % 4, 0);
        assert_eq!(&glb[20 + json_len + 4..20 + json_len + 8], b"BIN\0");
        assert_eq!(glb.len() % 4, 0);
        let json = std::str::from_utf8(&glb[20..20 + json_len]).unwrap();
        assert!(json.contains(GENERATOR));
    }

    /// The container streamed to a file ([`Glb::write`], as `export::write_scene` does) is the one
    /// [`to_glb_with`] returns, for JSON chunks of every length mod 4 and for a scene with no
    /// binary data (no BIN chunk): the 12-byte header's length, both chunk headers and paddings.
    #[test]
    fn the_streamed_glb_is_the_in_memory_one_for_every_padding() {
        let mut lengths_mod_4 = std::collections::BTreeSet::new();
        let mut scenes: Vec<Scene> = (0..12)
            .map(|k| {
                let mut s = triangle_scene(2);
                s.name = "x".repeat(k);
                s
            })
            .collect();
        scenes.push(Scene { name: "empty".into(), ..Scene::default() });
        let dir = tempfile::tempdir().unwrap();
        for (k, scene) in scenes.iter().enumerate() {
            let in_memory = to_glb(scene).unwrap();
            let glb = to_glb_parts(scene, &WriteOptions::default()).unwrap();
            lengths_mod_4.insert(glb.json.len() % 4);
            assert_eq!(glb.byte_len(), in_memory.len());
            let path = dir.path().join(format!("s{k}.glb"));
            crate::export::write_scene_with(scene, &path, &WriteOptions::default()).unwrap();
            assert_eq!(std::fs::read(&path).unwrap(), in_memory, "scene {k}");
            assert_eq!(glb.bin.is_empty(), k == 12);
        }
        assert_eq!(lengths_mod_4.len(), 4, "JSON lengths mod 4 covered: {lengths_mod_4:?}");
        // nothing but the written files is left in the folder (no staged temporaries)
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), scenes.len());
    }

    /// The level buffers' base64, written piece by piece as the file is ([`Glb::write`]), is the
    /// payload the data: URI must hold: a chain whose levels have every length mod 3 and run over
    /// several pieces reads back as written, names holding the URI's own text included (they are
    /// escaped in the JSON and never taken for a buffer's `uri`), and the header's length is the
    /// file's.
    #[test]
    fn level_buffers_stream_their_base64_into_the_json_chunk() {
        let pattern = format!("\"uri\":\"{LEVEL_URI}\"");
        let level = |n: usize, y: f32| {
            let positions: Vec<[f32; 3]> = (0..n).map(|i| [i as f32, y, (i % 5) as f32]).collect();
            let indices: Vec<u32> = (0..n as u32 - 2).flat_map(|i| [i, i + 1, i + 2]).collect();
            Primitive { positions, indices, ..Primitive::default() }
        };
        // vertices 3 × 12 bytes apart: the buffers' lengths (positions and indices, 4-aligned)
        // differ mod 3; the finest runs over three 192 KiB pieces
        for (k, sizes) in [[3usize, 4, 5], [40_000, 17_001, 5]].iter().enumerate() {
            let meshes: Vec<Mesh> = sizes
                .iter()
                .enumerate()
                .map(|(l, &n)| Mesh {
                    name: format!("{pattern} lod{l}"),
                    primitives: vec![level(n, l as f32)],
                    extras: None,
                })
                .collect();
            let scene = Scene {
                name: pattern.clone(),
                meshes,
                nodes: vec![
                    crate::mesh::Node {
                        name: pattern.clone(),
                        mesh: Some(0),
                        lods: vec![1, 2],
                        lod_screen_coverage: vec![0.5, 0.2, 0.05],
                        ..crate::mesh::Node::default()
                    },
                    crate::mesh::Node { name: "l1".into(), mesh: Some(1), ..crate::mesh::Node::default() },
                    crate::mesh::Node { name: "l2".into(), mesh: Some(2), ..crate::mesh::Node::default() },
                ],
                roots: vec![0],
                ..Scene::default()
            };
            let glb = to_glb_parts(&scene, &WriteOptions::default()).unwrap();
            assert_eq!(glb.uris.len(), 2, "two finer levels in URIs");
            let lengths: std::collections::BTreeSet<usize> = glb.uris.iter().map(|(_, d)| d.len() % 3).collect();
            assert!(k == 0 || lengths.len() == 2, "{lengths:?}");
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("chain.glb");
            crate::export::write_scene_with(&scene, &path, &WriteOptions::default()).unwrap();
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(bytes.len(), glb.byte_len());
            assert_eq!(to_glb(&scene).unwrap(), bytes);
            let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
            let doc: Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
            for (b, (_, data)) in doc["buffers"].as_array().unwrap()[1..].iter().zip(&glb.uris) {
                let uri = b["uri"].as_str().unwrap();
                assert_eq!(uri, format!("{LEVEL_URI}{}", crate::export::streaming::base64(data)));
            }
            let back = crate::validate::read_scene(&path).unwrap();
            assert_eq!(back.name, scene.name);
            for m in &scene.meshes {
                let got = back.meshes.iter().find(|b| b.name == m.name).expect("every level reads back");
                assert_eq!(got.primitives[0].positions, m.primitives[0].positions);
                assert_eq!(got.primitives[0].indices, m.primitives[0].indices);
            }
        }
    }

    #[test]
    fn uri_encoding() {
        assert_eq!(uri_encode("my tile #1.bin"), "my%20tile%20%231.bin");
    }
}
