//! glTF binary data: buffers, buffer views (including EXT_meshopt_compression) and accessors
//! (glTF 2.0 spec, section 3.6; KHR_mesh_quantization; EXT_meshopt_compression).
//!
//! Every byte range is checked before it is sliced, with checked arithmetic, so a file that
//! lies about its sizes gets [`ImportError::OutOfBounds`] instead of a panic.

use std::borrow::Cow;
use std::path::Path;

use gltf::json::accessor::{ComponentType, Type};
use gltf::json::validation::Checked;
use gltf::json::Root;
use serde::Deserialize;

use super::uri;
use crate::error::ImportError;

/// The loaded bytes of every buffer and every decompressed buffer view.
#[derive(Debug)]
pub(crate) struct BinaryData<'a> {
    /// One entry per glTF buffer; `None` for an EXT_meshopt_compression fallback buffer, which
    /// has no bytes of its own.
    buffers: Vec<Option<Cow<'a, [u8]>>>,
    /// One entry per buffer view; `Some` when the view was decompressed.
    decoded_views: Vec<Option<Vec<u8>>>,
}

/// The EXT_meshopt_compression object on a buffer view.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct MeshoptView {
    buffer: usize,
    #[serde(default)]
    byte_offset: u64,
    byte_length: u64,
    byte_stride: u64,
    count: u64,
    mode: String,
    #[serde(default)]
    filter: Option<String>,
}

impl<'a> BinaryData<'a> {
    /// Loads every buffer and decodes every compressed view, within the byte budget.
    pub fn load(
        doc: &Root,
        glb_bin: Option<&'a [u8]>,
        base_dir: Option<&Path>,
        budget: &mut u64,
    ) -> Result<Self, ImportError> {
        // Stage 1: buffers, from the GLB chunk, a data: URI or a file beside the asset.
        let mut buffers = Vec::with_capacity(doc.buffers.len());
        for (b, buffer) in doc.buffers.iter().enumerate() {
            let declared = buffer.byte_length.0;
            let is_fallback = buffer
                .extensions
                .as_ref()
                .and_then(|e| e.others.get("EXT_meshopt_compression"))
                .is_some();
            let data: Option<Cow<'a, [u8]>> = match &buffer.uri {
                Some(u) => Some(uri::resolve(u, base_dir, budget)?.bytes.into()),
                None if is_fallback => None,
                None if b == 0 => Some(
                    glb_bin
                        .ok_or_else(|| ImportError::OutOfBounds {
                            what: "buffer 0".into(),
                            reason: "it has no URI and the file has no GLB binary chunk".into(),
                        })?
                        .into(),
                ),
                None => {
                    return Err(ImportError::OutOfBounds {
                        what: format!("buffer {b}"),
                        reason: "only buffer 0 may use the GLB binary chunk".into(),
                    })
                }
            };
            if let Some(d) = &data {
                if (d.len() as u64) < declared {
                    return Err(ImportError::Truncated(format!(
                        "buffer {b} declares {declared} bytes but has {}",
                        d.len()
                    )));
                }
            }
            buffers.push(data);
        }
        let mut out = Self {
            buffers,
            decoded_views: vec![None; doc.buffer_views.len()],
        };
        // Stage 2: decompress EXT_meshopt_compression views.
        for (v, view) in doc.buffer_views.iter().enumerate() {
            let ext = view
                .extensions
                .as_ref()
                .and_then(|e| e.others.get("EXT_meshopt_compression"));
            if let Some(ext) = ext {
                let ext: MeshoptView = serde_json::from_value(ext.clone()).map_err(|e| {
                    ImportError::Json(format!("buffer view {v}: bad EXT_meshopt_compression: {e}"))
                })?;
                let decoded = out.decode_meshopt_view(v, view.byte_length.0, &ext, budget)?;
                out.decoded_views[v] = Some(decoded);
            }
        }
        Ok(out)
    }

    /// The bytes of a buffer view: its slice of its buffer, or its decompressed bytes.
    pub fn view(&self, doc: &Root, v: usize) -> Result<(&[u8], Option<usize>), ImportError> {
        let view = doc
            .buffer_views
            .get(v)
            .ok_or_else(|| missing("accessor", "buffer view", v))?;
        let stride = view.byte_stride.map(|s| s.0);
        if let Some(decoded) = &self.decoded_views[v] {
            return Ok((decoded, stride));
        }
        let b = view.buffer.value();
        let buffer = self
            .buffers
            .get(b)
            .ok_or_else(|| missing(&format!("buffer view {v}"), "buffer", b))?
            .as_deref()
            .ok_or_else(|| ImportError::OutOfBounds {
                what: format!("buffer view {v}"),
                reason: format!("buffer {b} is a compression fallback with no data"),
            })?;
        let offset = view.byte_offset.map_or(0, |o| o.0);
        let bytes = slice(buffer, offset, view.byte_length.0, || {
            format!("buffer view {v}")
        })?;
        Ok((bytes, stride))
    }

    fn decode_meshopt_view(
        &self,
        v: usize,
        declared_len: u64,
        ext: &MeshoptView,
        budget: &mut u64,
    ) -> Result<Vec<u8>, ImportError> {
        let what = || format!("buffer view {v} (EXT_meshopt_compression)");
        let source = self
            .buffers
            .get(ext.buffer)
            .ok_or_else(|| missing(&what(), "buffer", ext.buffer))?
            .as_deref()
            .ok_or_else(|| ImportError::OutOfBounds {
                what: what(),
                reason: "its source is a fallback buffer with no data".into(),
            })?;
        let encoded = slice(source, ext.byte_offset, ext.byte_length, what)?;
        let size = ext
            .count
            .checked_mul(ext.byte_stride)
            .filter(|&s| s == declared_len)
            .ok_or_else(|| ImportError::OutOfBounds {
                what: what(),
                reason: format!(
                    "count {} x stride {} does not match its byteLength {declared_len}",
                    ext.count, ext.byte_stride
                ),
            })?;
        uri::take_budget(budget, size)?;
        let count = ext.count as usize;
        let stride = ext.byte_stride as usize;
        let fail = |e: meshopt::Error| ImportError::OutOfBounds {
            what: what(),
            reason: format!("meshopt decoding failed: {e:?}"),
        };
        let mut bytes = match (ext.mode.as_str(), stride) {
            ("ATTRIBUTES", s) if s % 4 == 0 && (4..=256).contains(&s) => {
                crate::meshopt_stream::decode_vertex_stream(encoded, count, stride).map_err(fail)?
            }
            ("TRIANGLES", 2) if count.is_multiple_of(3) => {
                let ix: Vec<u16> = meshopt::decode_index_buffer(encoded, count).map_err(fail)?;
                ix.iter().flat_map(|i| i.to_le_bytes()).collect()
            }
            ("TRIANGLES", 4) if count.is_multiple_of(3) => {
                let ix: Vec<u32> = meshopt::decode_index_buffer(encoded, count).map_err(fail)?;
                ix.iter().flat_map(|i| i.to_le_bytes()).collect()
            }
            ("INDICES", 2) => {
                let ix: Vec<u16> = meshopt::decode_index_sequence(encoded, count).map_err(fail)?;
                ix.iter().flat_map(|i| i.to_le_bytes()).collect()
            }
            ("INDICES", 4) => {
                let ix: Vec<u32> = meshopt::decode_index_sequence(encoded, count).map_err(fail)?;
                ix.iter().flat_map(|i| i.to_le_bytes()).collect()
            }
            (mode, s) => {
                return Err(ImportError::Unsupported(format!(
                    "{}: mode {mode} with stride {s} and count {count}",
                    what()
                )))
            }
        };
        match ext.filter.as_deref().unwrap_or("NONE") {
            "NONE" => {}
            "OCTAHEDRAL" if stride == 4 => filter_in_place::<i8>(&mut bytes, Filter::Oct),
            "OCTAHEDRAL" if stride == 8 => filter_in_place::<i16>(&mut bytes, Filter::Oct),
            "QUATERNION" if stride == 8 => filter_in_place::<i16>(&mut bytes, Filter::Quat),
            "COLOR" if stride == 4 => filter_in_place::<u8>(&mut bytes, Filter::Color),
            "COLOR" if stride == 8 => filter_in_place::<u16>(&mut bytes, Filter::Color),
            "EXPONENTIAL" => {
                let mut words: Vec<[u32; 1]> = bytes
                    .chunks_exact(4)
                    .map(|c| [u32::from_le_bytes([c[0], c[1], c[2], c[3]])])
                    .collect();
                meshopt::decode_filter_exp(&mut words);
                bytes = words.iter().flat_map(|w| w[0].to_le_bytes()).collect();
            }
            other => {
                return Err(ImportError::Unsupported(format!(
                    "{}: filter {other} with stride {stride}",
                    what()
                )))
            }
        }
        Ok(bytes)
    }
}

/// Reads one accessor as numbers: normalized integers map to [0, 1] or [-1, 1], other
/// integers keep their value (KHR_mesh_quantization), and sparse substitutions are applied.
#[derive(Debug)]
pub(crate) struct AccessorValues {
    /// Components per element (1 for SCALAR, 3 for VEC3...).
    pub components: usize,
    /// `count * components` values, element-major.
    pub values: Vec<f32>,
}

/// Reads accessor `a` as floats.
pub(crate) fn read_floats(
    doc: &Root,
    data: &BinaryData<'_>,
    a: usize,
    max_elements: u64,
) -> Result<AccessorValues, ImportError> {
    let acc = doc
        .accessors
        .get(a)
        .ok_or_else(|| missing("primitive", "accessor", a))?;
    let what = || format!("accessor {a}");
    let component = match acc.component_type {
        Checked::Valid(c) => c.0,
        Checked::Invalid => {
            return Err(ImportError::Json(format!("{}: bad componentType", what())))
        }
    };
    let components = match acc.type_ {
        Checked::Valid(Type::Scalar) => 1,
        Checked::Valid(Type::Vec2) => 2,
        Checked::Valid(Type::Vec3) => 3,
        Checked::Valid(Type::Vec4) => 4,
        Checked::Valid(_) => {
            return Err(ImportError::Unsupported(format!(
                "{}: matrix accessors are not read",
                what()
            )))
        }
        Checked::Invalid => return Err(ImportError::Json(format!("{}: bad type", what()))),
    };
    let count = acc.count.0;
    // An accessor backed by a buffer view is bounded by the view's bytes; one without a view
    // (zeros plus sparse entries) is bounded only by its declared count, so cap that.
    if acc.buffer_view.is_none() && count > max_elements {
        return Err(ImportError::LimitExceeded {
            what: "element count of an accessor without a buffer view",
            value: count,
            limit: max_elements,
        });
    }
    let count = count as usize;
    let offset = acc.byte_offset.map_or(0, |o| o.0);
    let dense = match acc.buffer_view {
        Some(view) => Some(data.view(doc, view.value())?),
        None => None,
    };
    // Check the byte range before allocating for it.
    if let Some((bytes, stride)) = dense {
        let size = component_size(component) * components;
        strided_region(bytes, offset, stride.unwrap_or(size), count, size, &what)?;
    }
    let mut values = vec![0.0f32; count * components];
    // Stage 1: the dense part, or zeros when there is no buffer view.
    if let Some((bytes, stride)) = dense {
        read_strided(
            bytes,
            offset,
            stride,
            count,
            components,
            component,
            acc.normalized,
            &mut values,
            &what,
        )?;
    }
    // Stage 2: sparse substitutions.
    if let Some(sparse) = &acc.sparse {
        let n = sparse.count.0 as usize;
        if n as u64 > count as u64 {
            return Err(ImportError::OutOfBounds {
                what: what(),
                reason: format!("{n} sparse entries for {count} elements"),
            });
        }
        let index_type = match sparse.indices.component_type {
            Checked::Valid(c) => c.0,
            Checked::Invalid => {
                return Err(ImportError::Json(format!(
                    "{}: bad sparse index type",
                    what()
                )))
            }
        };
        let (ibytes, _) = data.view(doc, sparse.indices.buffer_view.value())?;
        let mut targets = vec![0.0f32; n];
        read_strided(
            ibytes,
            sparse.indices.byte_offset.0,
            None,
            n,
            1,
            index_type,
            false,
            &mut targets,
            &|| format!("{} sparse indices", what()),
        )?;
        let (vbytes, _) = data.view(doc, sparse.values.buffer_view.value())?;
        let mut replacement = vec![0.0f32; n * components];
        read_strided(
            vbytes,
            sparse.values.byte_offset.0,
            None,
            n,
            components,
            component,
            acc.normalized,
            &mut replacement,
            &|| format!("{} sparse values", what()),
        )?;
        for (k, &t) in targets.iter().enumerate() {
            let t = t as usize;
            if t >= count {
                return Err(ImportError::OutOfBounds {
                    what: what(),
                    reason: format!("sparse index {t} past {count} elements"),
                });
            }
            values[t * components..(t + 1) * components]
                .copy_from_slice(&replacement[k * components..(k + 1) * components]);
        }
    }
    Ok(AccessorValues { components, values })
}

/// Reads accessor `a` as vertex indices (unsigned integer scalars).
pub(crate) fn read_indices(
    doc: &Root,
    data: &BinaryData<'_>,
    a: usize,
    max_elements: u64,
) -> Result<Vec<u32>, ImportError> {
    let acc = doc
        .accessors
        .get(a)
        .ok_or_else(|| missing("primitive", "indices accessor", a))?;
    let integer = matches!(
        acc.component_type,
        Checked::Valid(gltf::json::accessor::GenericComponentType(
            ComponentType::U8 | ComponentType::U16 | ComponentType::U32
        ))
    );
    if !integer || !matches!(acc.type_, Checked::Valid(Type::Scalar)) {
        return Err(ImportError::Json(format!(
            "accessor {a}: indices must be unsigned integer scalars"
        )));
    }
    // u32 indices are exact in f64 but not in f32, so read them directly when dense.
    if acc.sparse.is_none() {
        if let (Some(view), Checked::Valid(ct)) = (acc.buffer_view, acc.component_type) {
            let (bytes, stride) = data.view(doc, view.value())?;
            let count = acc.count.0;
            let size = component_size(ct.0);
            let stride = stride.unwrap_or(size);
            let offset = acc.byte_offset.map_or(0, |o| o.0);
            let region = strided_region(bytes, offset, stride, count as usize, size, &|| {
                format!("accessor {a}")
            })?;
            return Ok((0..count as usize)
                .map(|k| {
                    let e = &region[k * stride..k * stride + size];
                    match size {
                        1 => u32::from(e[0]),
                        2 => u32::from(u16::from_le_bytes([e[0], e[1]])),
                        _ => u32::from_le_bytes([e[0], e[1], e[2], e[3]]),
                    }
                })
                .collect());
        }
    }
    // Sparse or view-less index accessors are rare; f32 is exact below 2^24.
    let v = read_floats(doc, data, a, max_elements)?;
    Ok(v.values.iter().map(|&x| x as u32).collect())
}

pub(crate) fn missing(what: &str, target: &'static str, index: usize) -> ImportError {
    ImportError::MissingReference {
        what: what.into(),
        target,
        index,
    }
}

fn component_size(c: ComponentType) -> usize {
    match c {
        ComponentType::I8 | ComponentType::U8 => 1,
        ComponentType::I16 | ComponentType::U16 => 2,
        ComponentType::U32 | ComponentType::F32 => 4,
    }
}

/// `bytes[offset .. offset + len]`, or an error naming `what`.
fn slice(
    bytes: &[u8],
    offset: u64,
    len: u64,
    what: impl Fn() -> String,
) -> Result<&[u8], ImportError> {
    offset
        .checked_add(len)
        .filter(|&end| end <= bytes.len() as u64)
        .map(|end| &bytes[offset as usize..end as usize])
        .ok_or_else(|| ImportError::OutOfBounds {
            what: what(),
            reason: format!(
                "bytes {offset}..{} of {}",
                offset.saturating_add(len),
                bytes.len()
            ),
        })
}

/// The bytes from `offset` that hold `count` elements of `size` bytes every `stride` bytes.
fn strided_region<'b>(
    bytes: &'b [u8],
    offset: u64,
    stride: usize,
    count: usize,
    size: usize,
    what: &dyn Fn() -> String,
) -> Result<&'b [u8], ImportError> {
    if stride < size {
        return Err(ImportError::OutOfBounds {
            what: what(),
            reason: format!("byteStride {stride} is smaller than an element ({size} bytes)"),
        });
    }
    if count == 0 {
        return Ok(&[]);
    }
    let len = (count as u64 - 1)
        .checked_mul(stride as u64)
        .and_then(|l| l.checked_add(size as u64))
        .ok_or_else(|| ImportError::OutOfBounds {
            what: what(),
            reason: "its size overflows".into(),
        })?;
    slice(bytes, offset, len, what)
}

#[allow(clippy::too_many_arguments)]
fn read_strided(
    bytes: &[u8],
    offset: u64,
    stride: Option<usize>,
    count: usize,
    components: usize,
    component: ComponentType,
    normalized: bool,
    out: &mut [f32],
    what: &dyn Fn() -> String,
) -> Result<(), ImportError> {
    let csize = component_size(component);
    let size = csize * components;
    let stride = stride.unwrap_or(size);
    let region = strided_region(bytes, offset, stride, count, size, what)?;
    for k in 0..count {
        let element = &region[k * stride..k * stride + size];
        for (c, raw) in element.chunks_exact(csize).enumerate() {
            out[k * components + c] = decode_component(raw, component, normalized);
        }
    }
    Ok(())
}

/// One component as a float (glTF 2.0 spec 3.11, "normalized integers").
fn decode_component(raw: &[u8], component: ComponentType, normalized: bool) -> f32 {
    let (value, scale) = match component {
        ComponentType::I8 => (f32::from(raw[0] as i8), 127.0),
        ComponentType::U8 => (f32::from(raw[0]), 255.0),
        ComponentType::I16 => (f32::from(i16::from_le_bytes([raw[0], raw[1]])), 32767.0),
        ComponentType::U16 => (f32::from(u16::from_le_bytes([raw[0], raw[1]])), 65535.0),
        ComponentType::U32 => (
            u32::from_le_bytes([raw[0], raw[1], raw[2], raw[3]]) as f32,
            4294967295.0,
        ),
        ComponentType::F32 => return f32::from_le_bytes([raw[0], raw[1], raw[2], raw[3]]),
    };
    if normalized {
        // Signed normalized values clamp so that both -128 and -127 map to -1.
        (value / scale).max(-1.0)
    } else {
        value
    }
}

#[derive(Clone, Copy)]
enum Filter {
    Oct,
    Quat,
    Color,
}

/// Applies a meshopt filter to 4-component elements of type `C`, in place.
fn filter_in_place<C: meshopt::FilterComponent + Component>(bytes: &mut Vec<u8>, filter: Filter) {
    let size = std::mem::size_of::<C>();
    let mut items: Vec<[C; 4]> = bytes
        .chunks_exact(size * 4)
        .map(|e| std::array::from_fn(|c| C::read(&e[c * size..(c + 1) * size])))
        .collect();
    match filter {
        Filter::Oct => meshopt::decode_filter_oct(&mut items),
        Filter::Quat => C::decode_quat(&mut items),
        Filter::Color => meshopt::decode_filter_color(&mut items),
    }
    bytes.clear();
    for item in &items {
        for c in item {
            c.write(bytes);
        }
    }
}

/// Little-endian component reading and writing for the filter element types.
trait Component: Sized + Copy {
    fn read(raw: &[u8]) -> Self;
    fn write(self, out: &mut Vec<u8>);
    /// The quaternion filter exists only for 16-bit components; other widths never reach it.
    fn decode_quat(_items: &mut [[Self; 4]]) {}
}

impl Component for i8 {
    fn read(raw: &[u8]) -> Self {
        raw[0] as i8
    }
    fn write(self, out: &mut Vec<u8>) {
        out.push(self as u8);
    }
}

impl Component for u8 {
    fn read(raw: &[u8]) -> Self {
        raw[0]
    }
    fn write(self, out: &mut Vec<u8>) {
        out.push(self);
    }
}

impl Component for i16 {
    fn read(raw: &[u8]) -> Self {
        i16::from_le_bytes([raw[0], raw[1]])
    }
    fn write(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn decode_quat(items: &mut [[Self; 4]]) {
        meshopt::decode_filter_quat(items);
    }
}

impl Component for u16 {
    fn read(raw: &[u8]) -> Self {
        u16::from_le_bytes([raw[0], raw[1]])
    }
    fn write(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}
