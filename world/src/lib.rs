//! The one API the product calls: a world and everything done to it (`DESIGN.md`, "Workspace
//! layout"). Synchronous and thread-safe; no HTTP.
//!
//! A world is a directory holding a metadata store and a blob store (`store/`). [`World`]
//! opens one and runs the pipeline over it as functions: ingest -> describe -> BVH ->
//! rebuild -> cut. The algorithms live in their own crates (`horizon-bvh`,
//! `horizon-aggregate`, ...), which are pure; this crate does the storage for them.
//!
//! # Layout
//! - `world.rs`: [`World`]: create, open (upgrading format-1 directories), upload models,
//!   apply changes, the tree, the rebuild and its publication, cuts, status.
//! - `store/`: the [`MetaStore`] and [`BlobStore`] traits and their embedded defaults,
//!   [`SqliteMeta`] and [`BlobDir`].
//! - `tree.rs`: [`Tree`], the BVH with its id maps, snapshots and replay.
//! - `models.rs`: [`Models`], the models by number, loaded on first use.
//! - `aggregates.rs`: [`AggregateSink`], the aggregate store the rebuild writes through.
//! - `ingest.rs`: how a model enters a world: import (uploads under [`UploadLimits`]),
//!   validate, normalise, describe.
//! - `legacy.rs`: reading format-1 directories for the upgrade.
//! - `durable.rs`: atomic, durable writes. `hash.rs`: content addresses (BLAKE3).
//! - `error.rs`: [`WorldError`].

mod aggregates;
mod durable;
mod error;
mod hash;
pub mod ingest;
mod legacy;
mod models;
pub mod store;
mod tree;
mod world;

pub use aggregates::AggregateSink;
pub use durable::write_atomically;
pub use error::{BadModel, WorldError};
pub use hash::{content_hash, is_content_hash};
pub use ingest::UploadLimits;
pub use models::Models;
pub use store::{
    Applied, BlobDir, BlobStore, MetaStore, ModelDescriptors, ModelLevel, ModelRow, ObjectRow,
    Published, SqliteMeta, User,
};
pub use tree::{new_object, sphere_of, Describe, Tree};
pub use world::{
    Change, RebuildOverhead, RebuildReport, Served, World, WorldStatus, SNAPSHOT_EVERY,
};
