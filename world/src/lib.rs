//! The one API the product calls: a world directory and everything done to it (`DESIGN.md`,
//! "Workspace layout").
//!
//! A world is a directory of content-addressed model files, its objects, the models'
//! descriptors, the BVH snapshot and the aggregate store. [`World`] opens one and runs the
//! pipeline over it as functions: ingest -> describe -> BVH -> offline rebuild -> cut. The
//! algorithms live in their own crates (`horizon-bvh`, `horizon-aggregate`, ...), which are
//! pure; this crate does the file I/O for them. It is synchronous.
//!
//! # Layout
//! - `world.rs`: [`World`]: create, open, describe, build the tree, rebuild the aggregates,
//!   cut.
//! - `ingest.rs`: how a model enters a world: import, validate, normalise, describe.
//! - `dir.rs`: [`WorldDir`], the directory's files and their formats ([`WorldManifest`],
//!   [`ObjectList`], [`DescriptorCache`]).
//! - `aggregates.rs`: [`AggregateDir`], the aggregate store (blobs, journal, manifest, garbage
//!   collection), the [`horizon_aggregate::AggregateStore`] the rebuild writes through.
//! - `durable.rs`: atomic, durable writes.
//! - `hash.rs`: content addresses.
//! - `error.rs`: [`WorldError`].

mod aggregates;
mod dir;
mod durable;
mod error;
mod hash;
pub mod ingest;
mod world;

pub use aggregates::{AggregateDir, BlobKind, Garbage};
pub use dir::{
    DescriptorCache, ModelDescriptors, ModelRecord, ObjectList, ObjectRecord, WorldDir,
    WorldManifest, FORMAT,
};
pub use durable::write_atomically;
pub use error::WorldError;
pub use hash::content_hash;
pub use world::{RebuildReport, World};
