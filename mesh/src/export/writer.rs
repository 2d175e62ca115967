//! The GLB writer: the glTF JSON arrays and binary chunk being filled, buffer views and
//! accessors, and the final assembly of the JSON document and the GLB container.
//!
//! Uncompressed accessors share one buffer view per kind of data, each at its own byte offset;
//! compressed ones get a meshopt-encoded view each (`compression.rs`). The other files add
//! their parts through `impl GlbWriter` blocks of their own: meshes (`geometry.rs`), textures
//! and materials (`textures.rs`), nodes (`instancing.rs`).

use std::collections::BTreeSet;

use serde_json::{json, Map, Value};

use super::attributes::Attribute;
use super::compression::{self, Encoding};
use super::json::{contains_null, numbers};
use super::options::ExportOptions;
use crate::error::ExportError;

/// Where the bytes of uncompressed accessors go: one buffer view per kind of data, shared by
/// every accessor of that kind (each at its own `byteOffset`), rather than one view per
/// accessor, whose JSON would cost as much again as the accessors' on an aggregate of many
/// small submeshes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct PoolKey {
    stride: Option<usize>,
    target: Option<u32>,
}

/// One shared buffer view being filled; laid out in the binary chunk by `finish`.
struct Pool {
    key: PoolKey,
    view: usize,
    bytes: Vec<u8>,
}

/// Accumulates the glTF JSON arrays and the binary chunk.
pub(super) struct GlbWriter {
    pub(super) compress: bool,
    pub(super) short_rotations: bool,
    /// Normals, UVs and colours as normalized integers (`short_attributes`, or compressing).
    pub(super) short_attributes: bool,
    /// Whether an attribute was written as integers (KHR_mesh_quantization).
    pub(super) quantized: bool,
    /// The largest distance a quantized position may move (`ExportOptions::position_tolerance`;
    /// unbounded when compressing, `None` for float positions).
    pub(super) position_tolerance: Option<f32>,
    pools: Vec<Pool>,
    /// The GLB binary chunk (buffer 0).
    pub(super) bin: Vec<u8>,
    /// Size of the virtual uncompressed buffer (buffer 1) that compressed views decode into.
    fallback_len: usize,
    accessors: Vec<Value>,
    pub(super) buffer_views: Vec<Value>,
    pub(super) meshes: Vec<Value>,
    pub(super) materials: Vec<Value>,
    pub(super) textures: Vec<Value>,
    pub(super) images: Vec<Value>,
    pub(super) samplers: Vec<Value>,
    pub(super) nodes: Vec<Value>,
    pub(super) roots: Vec<usize>,
    pub(super) extensions_used: BTreeSet<&'static str>,
    extensions_required: BTreeSet<&'static str>,
}

impl GlbWriter {
    pub(super) fn new(options: ExportOptions) -> Self {
        Self {
            compress: options.compress,
            short_rotations: options.short_rotations,
            short_attributes: options.compress || options.short_attributes,
            quantized: false,
            position_tolerance: if options.compress {
                Some(f32::INFINITY)
            } else {
                options.position_tolerance
            },
            pools: Vec::new(),
            bin: Vec::new(),
            fallback_len: 0,
            accessors: Vec::new(),
            buffer_views: Vec::new(),
            meshes: Vec::new(),
            materials: Vec::new(),
            textures: Vec::new(),
            images: Vec::new(),
            samplers: Vec::new(),
            nodes: Vec::new(),
            roots: Vec::new(),
            extensions_used: BTreeSet::new(),
            extensions_required: BTreeSet::new(),
        }
    }

    pub(super) fn align_bin(&mut self) {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
    }

    /// Places `bytes` in a buffer view and returns the view and the offset in it: a shared
    /// view per kind of data when not compressing, else a view of its own, meshopt-encoded.
    pub(super) fn add_view(
        &mut self,
        bytes: &[u8],
        stride: Option<usize>,
        target: Option<u32>,
        encoding: Encoding<'_>,
    ) -> Result<(usize, usize), ExportError> {
        if !self.compress {
            let key = PoolKey { stride, target };
            let k = match self.pools.iter().position(|p| p.key == key) {
                Some(k) => k,
                None => {
                    // Offset and length are filled in by `finish`.
                    let mut view = Map::new();
                    view.insert("buffer".into(), json!(0));
                    if let Some(s) = stride {
                        view.insert("byteStride".into(), json!(s));
                    }
                    if let Some(t) = target {
                        view.insert("target".into(), json!(t));
                    }
                    self.buffer_views.push(Value::Object(view));
                    self.pools.push(Pool {
                        key,
                        view: self.buffer_views.len() - 1,
                        bytes: Vec::new(),
                    });
                    self.pools.len() - 1
                }
            };
            let pool = &mut self.pools[k];
            // Every accessor starts on a 4-byte boundary (vertex attributes must).
            while !pool.bytes.len().is_multiple_of(4) {
                pool.bytes.push(0);
            }
            let offset = pool.bytes.len();
            pool.bytes.extend_from_slice(bytes);
            return Ok((pool.view, offset));
        }
        // Compressed: the encoded bytes go in the binary chunk, and the view decodes them into
        // its place in the fallback buffer.
        self.align_bin();
        let encoded = compression::encode(bytes, encoding)?;
        let mut view = Map::new();
        view.insert("buffer".into(), json!(1));
        view.insert("byteOffset".into(), json!(self.fallback_len));
        self.fallback_len += bytes.len().div_ceil(4) * 4;
        view.insert(
            "extensions".into(),
            json!({"EXT_meshopt_compression": {
                "buffer": 0,
                "byteOffset": self.bin.len(),
                "byteLength": encoded.data.len(),
                "byteStride": encoded.stride,
                "count": encoded.count,
                "mode": encoded.mode,
            }}),
        );
        self.bin.extend_from_slice(&encoded.data);
        view.insert("byteLength".into(), json!(bytes.len()));
        if let Some(s) = stride {
            view.insert("byteStride".into(), json!(s));
        }
        if let Some(t) = target {
            view.insert("target".into(), json!(t));
        }
        self.buffer_views.push(Value::Object(view));
        Ok((self.buffer_views.len() - 1, 0))
    }

    /// The accessor of `a`, whose bytes are at `offset` in buffer view `view`.
    pub(super) fn add_accessor(&mut self, (view, offset): (usize, usize), a: &Attribute) -> usize {
        let mut acc = Map::new();
        acc.insert("bufferView".into(), json!(view));
        if offset > 0 {
            acc.insert("byteOffset".into(), json!(offset));
        }
        acc.insert("componentType".into(), json!(a.component_type));
        if a.normalized {
            acc.insert("normalized".into(), json!(true));
        }
        acc.insert("count".into(), json!(a.count));
        acc.insert("type".into(), json!(a.type_name));
        if let Some((min, max)) = &a.bounds {
            acc.insert("min".into(), numbers(min));
            acc.insert("max".into(), numbers(max));
        }
        self.accessors.push(Value::Object(acc));
        self.accessors.len() - 1
    }

    /// Writes a vertex or instance attribute: its view (meshopt-encoded when compressing) and
    /// its accessor.
    pub(super) fn write_attribute(
        &mut self,
        a: &Attribute,
        target: Option<u32>,
    ) -> Result<usize, ExportError> {
        let view = self.add_view(
            &a.bytes,
            target.map(|_| a.stride),
            target,
            Encoding::Attributes { stride: a.stride },
        )?;
        Ok(self.add_accessor(view, a))
    }

    /// Lays out the shared views in the binary chunk, declares the extensions used and writes
    /// the JSON document and the GLB container.
    pub(super) fn finish(mut self) -> Result<Vec<u8>, ExportError> {
        for pool in std::mem::take(&mut self.pools) {
            self.align_bin();
            let view = &mut self.buffer_views[pool.view];
            view["byteOffset"] = json!(self.bin.len());
            view["byteLength"] = json!(pool.bytes.len());
            self.bin.extend_from_slice(&pool.bytes);
        }
        self.align_bin();
        let mut buffers = Vec::new();
        if !self.bin.is_empty() {
            buffers.push(json!({ "byteLength": self.bin.len() }));
        }
        if self.fallback_len > 0 {
            self.extensions_used.insert("EXT_meshopt_compression");
            self.extensions_required.insert("EXT_meshopt_compression");
            buffers.push(json!({
                "byteLength": self.fallback_len,
                "extensions": {"EXT_meshopt_compression": {"fallback": true}},
            }));
        }
        if (self.compress && !self.meshes.is_empty()) || self.quantized {
            self.extensions_used.insert("KHR_mesh_quantization");
            self.extensions_required.insert("KHR_mesh_quantization");
        }
        let mut doc = Map::new();
        doc.insert(
            "asset".into(),
            json!({"version": "2.0", "generator": "Horizon"}),
        );
        doc.insert("scene".into(), json!(0));
        doc.insert("scenes".into(), json!([{ "nodes": self.roots }]));
        let arrays = [
            ("nodes", self.nodes),
            ("meshes", self.meshes),
            ("materials", self.materials),
            ("textures", self.textures),
            ("images", self.images),
            ("samplers", self.samplers),
            ("accessors", self.accessors),
            ("bufferViews", self.buffer_views),
            ("buffers", buffers),
        ];
        for (name, values) in arrays {
            if !values.is_empty() {
                doc.insert(name.into(), Value::Array(values));
            }
        }
        if !self.extensions_used.is_empty() {
            doc.insert("extensionsUsed".into(), json!(self.extensions_used));
        }
        if !self.extensions_required.is_empty() {
            doc.insert("extensionsRequired".into(), json!(self.extensions_required));
        }
        let doc = Value::Object(doc);
        // serde_json writes a non-finite float as null; every number here is checked finite
        // upstream, and this keeps any miss from becoming a silently broken file.
        if contains_null(&doc) {
            return Err(ExportError::Encode(
                "a non-finite number reached the output".into(),
            ));
        }
        let json = serde_json::to_vec(&doc).map_err(|e| ExportError::Encode(e.to_string()))?;
        let total = json.len() as u64 + self.bin.len() as u64 + 28;
        if total > u64::from(u32::MAX) {
            return Err(ExportError::TooLarge(total));
        }
        let glb = gltf::Glb {
            header: gltf::binary::Header {
                magic: *b"glTF",
                version: 2,
                length: 0,
            },
            json: json.into(),
            bin: (!self.bin.is_empty()).then_some(self.bin.into()),
        };
        glb.to_vec().map_err(|e| ExportError::Encode(e.to_string()))
    }
}
