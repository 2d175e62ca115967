//! Why no atlas could be built.

use horizon_mesh::model::InvalidMesh;

use crate::layout::LayoutError;

/// Why no atlas could be built.
#[derive(Debug, thiserror::Error)]
pub enum AtlasError {
    /// The input mesh breaks one of its invariants.
    #[error("invalid input mesh: {0}")]
    InvalidMesh(#[from] InvalidMesh),
    /// A referenced texture could not be decoded.
    #[error("texture {texture} does not decode: {source}")]
    Decode {
        /// Index of the texture in the input mesh.
        texture: usize,
        /// The decoder's complaint.
        source: image::ImageError,
    },
    /// Even one texel per chart does not pack into the allowed side.
    #[error("{charts} charts do not fit a {side}x{side} atlas even at one texel each")]
    DoesNotFit {
        /// Number of charts.
        charts: usize,
        /// The side tried.
        side: u32,
    },
    /// The packer produced an invalid layout (a bug, reported rather than drawn).
    #[error("packed layout is invalid: {0}")]
    Layout(#[from] LayoutError),
    /// No side and quality bring the encoded atlas under the budget.
    #[error("the atlas cannot be encoded in {max_bytes} bytes")]
    OverBudget {
        /// The budget.
        max_bytes: usize,
    },
    /// The image encoder failed.
    #[error("atlas encoding failed: {0}")]
    Encode(image::ImageError),
}
