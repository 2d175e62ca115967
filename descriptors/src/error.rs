//! Why a descriptor could not be computed.

use horizon_mesh::InvalidMesh;

/// Why a descriptor was refused. Every variant prints as one line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DescriptorError {
    /// The input breaks the mesh model's invariants.
    #[error("invalid mesh: {0}")]
    InvalidMesh(#[from] InvalidMesh),
    /// The model has no triangles with finite, non-zero area.
    #[error("the model has no triangle with non-zero area to describe")]
    Empty,
    /// A texture the model samples could not be decoded.
    #[error("texture {texture} could not be decoded: {message}")]
    Texture {
        /// Index into the mesh's textures.
        texture: usize,
        /// The decoder's message.
        message: String,
    },
}
