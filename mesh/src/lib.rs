//! The instanced mesh model at the bottom of Horizon, with its import and export.
//!
//! # Layout
//! - [`model`]: [`InstancedMesh`] and its parts (submeshes, instances, materials, textures),
//!   counts, bounds, expansion and `validate()`.
//! - [`import`]: glTF/GLB, PLY, OBJ and STL readers behind [`import_file`] and
//!   [`import_bytes`], with [`Limits`] for untrusted uploads.
//! - [`bake`]: instances cheaper written out than instanced, merged into shared geometry.
//! - [`export`]: the GLB writer, with EXT_mesh_gpu_instancing and optional meshopt compression.
//! - [`transform`]: decomposition of affine transforms into translation, rotation and scale.
//! - [`stats`]: the summary printed by `horizon mesh stats`.
//! - [`rng`]: the seeded SplitMix64 generator every crate and test draws from.
//! - [`error`]: the typed errors of import and export.

pub mod bake;
pub mod error;
pub mod export;
pub mod import;
mod meshopt_stream;
pub mod model;
pub mod rng;
pub mod stats;
pub mod transform;

pub use error::{ExportError, ImportError};
pub use export::{export_glb, ExportOptions};
pub use import::{
    import_bytes, import_file, Format, ImageCheck, ImportOptions, Imported, Limit, Limits,
};
pub use model::{
    Aabb, AlphaMode, ExpandedMesh, Instance, InstancedMesh, InvalidMesh, Material, Submesh,
    Texture, TextureRef, UvTransform, Wrap,
};
pub use stats::MeshStats;
