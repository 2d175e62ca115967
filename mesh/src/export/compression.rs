//! Compression (EXT_meshopt_compression), the approach of meshoptimizer's gltfpack: each
//! submesh's indices are optimised for the vertex cache and its vertices for fetch order, and
//! every vertex, index and instance stream is meshopt-encoded into a buffer view of its own,
//! which decodes into a fallback buffer that holds no bytes in the file.
//!
//! Compression quantizes too (`quantize.rs`, KHR_mesh_quantization): positions become 16-bit
//! integers over each submesh's box whatever the tolerance, with the whole dequantisation
//! folded into every instance transform (`instancing.rs`), normals 8-bit, and UVs in [0, 1] and
//! colours 16-bit.

use crate::error::ExportError;
use crate::model::Submesh;

/// How a buffer view's bytes are stored.
pub(super) enum Encoding<'a> {
    /// meshopt vertex codec, for vertex and instance attributes.
    Attributes { stride: usize },
    /// meshopt index codec, for triangle lists.
    Triangles {
        indices: &'a [u32],
        vertex_count: usize,
    },
}

/// A buffer view's bytes meshopt-encoded, with the fields of its EXT_meshopt_compression
/// object.
pub(super) struct Encoded {
    /// The encoded bytes, stored in the binary chunk.
    pub(super) data: Vec<u8>,
    /// `ATTRIBUTES` or `TRIANGLES`.
    pub(super) mode: &'static str,
    /// Bytes per element once decoded.
    pub(super) stride: usize,
    /// Elements once decoded.
    pub(super) count: usize,
}

/// Encodes `bytes` with the meshopt codec `encoding` names.
pub(super) fn encode(bytes: &[u8], encoding: Encoding<'_>) -> Result<Encoded, ExportError> {
    Ok(match encoding {
        Encoding::Attributes { stride } => Encoded {
            data: crate::meshopt_stream::encode_vertex_stream(bytes, stride)
                .map_err(|e| ExportError::Encode(format!("{e:?}")))?,
            mode: "ATTRIBUTES",
            stride,
            count: bytes.len() / stride,
        },
        Encoding::Triangles {
            indices,
            vertex_count,
        } => Encoded {
            data: meshopt::encode_index_buffer(indices, vertex_count)
                .map_err(|e| ExportError::Encode(format!("{e:?}")))?,
            mode: "TRIANGLES",
            stride: bytes.len() / indices.len().max(1),
            count: indices.len(),
        },
    })
}

/// Indices optimised for the vertex cache, and the vertex order optimised for fetch: returns
/// the new indices and, for each new vertex, its old index. Unused vertices are dropped.
///
/// The fetch order is first use in the optimised index stream, which is what
/// `meshopt_optimizeVertexFetchRemap` computes; it is done here because the `meshopt` crate's
/// wrapper (0.7) truncates the remap table to the used-vertex count, losing the entries of
/// higher-numbered vertices whenever some vertex is unused.
pub(super) fn optimise_order(s: &Submesh) -> (Vec<u32>, Vec<u32>) {
    let n = s.positions.len();
    let mut indices = meshopt::optimize_vertex_cache(&s.indices, n);
    let mut remap = vec![u32::MAX; n];
    let mut order = Vec::new();
    for i in indices.iter_mut() {
        let slot = &mut remap[*i as usize];
        if *slot == u32::MAX {
            *slot = order.len() as u32;
            order.push(*i);
        }
        *i = *slot;
    }
    (indices, order)
}
