//! Accessor data read through bounds-checked views, so no file, however damaged, makes a read panic:
//! float and (normalized) integer attributes as f32, indices as u32.

/// The bytes of a bufferView, bounds-checked.
pub(super) fn view_bytes<'b>(view: &gltf::buffer::View, buffers: &[&'b [u8]]) -> Result<&'b [u8], String> {
    let buffer = buffers.get(view.buffer().index()).ok_or("bufferView names a missing buffer")?;
    let end = view.offset().checked_add(view.length()).ok_or("bufferView range overflows")?;
    buffer.get(view.offset()..end).ok_or_else(|| {
        format!("bufferView {} ends at byte {end}, past its buffer's {} bytes", view.index(), buffer.len())
    })
}

/// Elements of an accessor as byte slices (each `size` bytes long).
fn accessor_elements<'b>(acc: &gltf::Accessor, buffers: &[&'b [u8]]) -> Result<Vec<&'b [u8]>, String> {
    if acc.sparse().is_some() {
        return Err("sparse accessors are not supported by verdant".into());
    }
    let size = acc.size();
    let count = acc.count();
    let Some(view) = acc.view() else {
        return Err("accessor has no bufferView (all zeros); verdant does not write such files".into());
    };
    let data = view_bytes(&view, buffers)?;
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!("byteStride {stride} is smaller than an element ({size} bytes)"));
    }
    if count == 0 {
        return Ok(Vec::new());
    }
    let end = (count - 1)
        .checked_mul(stride)
        .and_then(|x| x.checked_add(size))
        .and_then(|x| x.checked_add(acc.offset()))
        .ok_or("accessor range overflows")?;
    if end > data.len() {
        return Err(format!("accessor {} needs {end} bytes of a {}-byte bufferView", acc.index(), data.len()));
    }
    Ok((0..count).map(|i| &data[acc.offset() + i * stride..acc.offset() + i * stride + size]).collect())
}

/// Decodes a float or (normalized) integer accessor into f32 values; returns components per element.
pub(super) fn read_floats(acc: &gltf::Accessor, buffers: &[&[u8]]) -> Result<(usize, Vec<f32>), String> {
    use gltf::accessor::DataType;
    let dims = acc.dimensions().multiplicity();
    let comp = acc.data_type().size();
    let norm = acc.normalized();
    let ty = acc.data_type();
    let mut out = Vec::with_capacity(acc.count().saturating_mul(dims).min(1 << 24));
    for e in accessor_elements(acc, buffers)? {
        for c in e.chunks_exact(comp).take(dims) {
            let v = match ty {
                DataType::F32 => f32::from_le_bytes([c[0], c[1], c[2], c[3]]),
                DataType::U32 => u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f32,
                DataType::U8 if norm => c[0] as f32 / 255.0,
                DataType::U8 => c[0] as f32,
                DataType::I8 if norm => (c[0] as i8 as f32 / 127.0).max(-1.0),
                DataType::I8 => c[0] as i8 as f32,
                DataType::U16 if norm => u16::from_le_bytes([c[0], c[1]]) as f32 / 65535.0,
                DataType::U16 => u16::from_le_bytes([c[0], c[1]]) as f32,
                DataType::I16 if norm => (i16::from_le_bytes([c[0], c[1]]) as f32 / 32767.0).max(-1.0),
                DataType::I16 => i16::from_le_bytes([c[0], c[1]]) as f32,
            };
            out.push(v);
        }
    }
    Ok((dims, out))
}

pub(super) fn read_indices(acc: &gltf::Accessor, buffers: &[&[u8]]) -> Result<Vec<u32>, String> {
    use gltf::accessor::{DataType, Dimensions};
    if acc.dimensions() != Dimensions::Scalar {
        return Err("index accessor is not SCALAR".into());
    }
    let elements = accessor_elements(acc, buffers)?;
    match acc.data_type() {
        DataType::U8 => Ok(elements.iter().map(|e| e[0] as u32).collect()),
        DataType::U16 => Ok(elements.iter().map(|e| u16::from_le_bytes([e[0], e[1]]) as u32).collect()),
        DataType::U32 => Ok(elements.iter().map(|e| u32::from_le_bytes([e[0], e[1], e[2], e[3]])).collect()),
        t => Err(format!("index component type {t:?} is not an unsigned integer")),
    }
}
