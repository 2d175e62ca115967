//! The offline aggregate rebuild (Azim et al. 2014, sections 5 to 7; `DESIGN.md`, "Data
//! flow"): every BVH node gets one aggregate, an instanced mesh of everything below it,
//! deduplicated, simplified by IAS to a budget from its on-screen size, and atlased to one
//! material and one texture.
//!
//! # Layout
//! - `build.rs`: [`build_aggregates`], the bottom-up, level-parallel rebuild that reuses
//!   every node whose key the store knows; [`BuildOptions`], [`BuildReport`].
//! - `keys.rs`: [`node_keys`], what each node's aggregate is made from, hashed
//!   ([`KeyHasher`]): the dirty tracking.
//! - `generate.rs`: [`generate`], one node's pipeline: gather, cull, dedup, merge, IAS, box
//!   proxies, atlas, encode; [`Handoff`], what a node hands its parent.
//! - `impostors.rs`: [`build_impostors`], the orthoview impostors of the nodes where they
//!   cost less to serve than the aggregate: ray-cast at the hierarchy's leaves, composited
//!   above, reused by key, in the manifest beside the aggregates.
//! - `proxy.rs`: box proxies for the objects whose simplified parts lost their shape, and
//!   over the budget for the smallest others: nothing that shows is dropped.
//! - `dedup.rs`: Table 1 dedup with PCA alignment (section 5.1).
//! - `pca.rs`: principal frames and sign-flip alignment.
//! - `budget.rs`: the display model behind every budget (triangles, texels, culling).
//! - `store.rs`: [`AggregateStore`], the trait through which a build keeps its GLBs, parts
//!   files, entries and manifest (`horizon-world` implements it over a world directory);
//!   [`MemoryStore`], one in memory.
//! - `source.rs`: [`ModelSource`], where models come from.
//! - `options.rs`: [`AggregateOptions`], [`AtlasPolicy`], [`Method`].
//! - `baseline.rs` (feature `baseline`, for the lab only): the unoptimised aggregates the
//!   report compares with, and [`build_subtrees`], a build of some subtrees alone.
//!
//! The crate is pure over its inputs: models come through [`ModelSource`], output goes
//! through [`AggregateStore`]; it does no file or network I/O of its own.

#[cfg(feature = "baseline")]
mod baseline;
pub mod budget;
mod build;
pub mod dedup;
mod error;
mod generate;
pub mod impostors;
mod keys;
pub mod options;
pub mod pca;
pub mod proxy;
mod source;
pub mod store;

#[cfg(feature = "baseline")]
pub use build::build_subtrees;
pub use build::{
    build_aggregates, build_aggregates_until, levels, resolve_atlas, BuildOptions, BuildOutcome,
    BuildReport, LevelTime, Progress, AUTO_ATLAS_BYTES, AUTO_ATLAS_TEXTURES,
};
pub use error::AggregateError;
pub use generate::{
    generate, generate_with, ExpandedPart, Handoff, NodeInput, NodeOutput, NodeStats, Placement,
    StageSeconds, POSITION_PIXELS,
};
pub use impostors::{build_impostors, ImpostorEntry, ImpostorPolicy, ImpostorReport, ImpostorView};
pub use keys::{node_keys, KeyHasher};
pub use options::{AggregateOptions, AtlasPolicy, Method};
pub use source::{InMemoryModels, ModelSource, SourceModel};
pub use store::{AggregateEntry, AggregateManifest, AggregateStore, MemoryStore, PartList};

/// Version of the aggregate format written by this build; part of every key, so aggregates of
/// another format are never reused. Raise it whenever the bytes an aggregate is made of
/// change for the same inputs.
pub const FORMAT: u32 = 17;
