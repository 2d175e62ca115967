//! The offline aggregate rebuild (Azim et al. 2014, sections 5 to 7; `DESIGN.md`, "Data
//! flow"): every BVH node gets one aggregate, an instanced mesh of everything below it,
//! deduplicated, simplified by IAS to a budget from its on-screen size, and atlased to one
//! material and one texture.
//!
//! # Layout
//! - `build.rs`: [`build_aggregates`], the bottom-up, level-parallel rebuild with keys and
//!   dirty tracking; [`BuildOptions`], [`BuildReport`].
//! - `generate.rs`: [`generate`], one node's pipeline: gather, cull, dedup, merge, IAS, atlas,
//!   encode; [`Handoff`], what a node hands its parent.
//! - `detail.rs`: detail culling, smallest instances first, where IAS cannot reach the
//!   budget.
//! - `dedup.rs`: Table 1 dedup with PCA alignment (section 5.1).
//! - `pca.rs`: principal frames and sign-flip alignment.
//! - `budget.rs`: the display model behind every budget (triangles, texels, culling).
//! - `store.rs`: [`AggregateStore`], content-addressed files, journal and manifest, atomic
//!   writes.
//! - `source.rs`: [`ModelSource`], where models come from.
//! - `options.rs`: [`AggregateOptions`], [`AtlasPolicy`], [`Method`].

pub mod budget;
mod build;
pub mod dedup;
pub mod detail;
mod error;
mod generate;
pub mod options;
pub mod pca;
mod source;
pub mod store;

pub use build::{
    build_aggregates, levels, node_keys, resolve_atlas, BuildOptions, BuildReport, LevelTime,
    Progress, AUTO_ATLAS_BYTES, AUTO_ATLAS_TEXTURES,
};
pub use error::AggregateError;
pub use generate::{
    generate, generate_with, ExpandedPart, Handoff, NodeInput, NodeOutput, NodeStats, Placement,
    StageSeconds, POSITION_PIXELS,
};
pub use options::{AggregateOptions, AtlasPolicy, Method};
pub use source::{InMemoryModels, ModelSource, SourceModel};
pub use store::{AggregateEntry, AggregateManifest, AggregateStore, Garbage};

/// Version of the aggregate format written by this build; part of every key. 2: shared buffer
/// views, shortest float text, co-placed parts merged, cheap placements baked, 16-bit
/// instance rotations. 3: baked mirrored placements keep outward normals. 4: an aggregate
/// built in the same run as its children keeps their parts' materials (before, a part handed
/// over in memory could lose its texture or take another part's). 5: a part without a version
/// from the children comes from its source model instead of being left out, and Table 1 is
/// part of every key. 6: the simplifier sweeps separate pieces (the same collapses, but equal
/// costs may now fall in another order). 7: where IAS stops over the budget, the smallest
/// instances are dropped until it fits (`detail.rs`). 8: submeshes of one layout share their
/// vertex accessors (`ExportOptions::share_vertices`), the same geometry in less JSON. 9:
/// normals as 8-bit and UVs as 16-bit normalized integers (`ExportOptions::short_attributes`,
/// KHR_mesh_quantization), 20 bytes a vertex instead of 32. 10: shrunk charts are baked
/// trilinearly from the source's mip chain instead of by a box of at most 3 x 3 bilinear
/// samples (`horizon_atlas`'s `bake.rs`). 11: positions as 16-bit integers over each vertex
/// run's box wherever that moves no vertex by more than an eighth of a pixel
/// ([`POSITION_PIXELS`]), 16 bytes a vertex instead of 20.
pub const FORMAT: u32 = 11;
