//! Where a world keeps what it is made of, behind two traits whose signatures name neither SQL
//! nor files, so that another database or an object store can take the embedded defaults'
//! place:
//! - [`MetaStore`]: models, descriptors, objects with their owners, users with their tokens
//!   and quotas, the generation counter and its log of mutations, the aggregate entries, and
//!   what is published. Every mutation is one transaction: committed whole or not at all,
//!   durable when the call returns. [`SqliteMeta`] (`sqlite.rs`) is the default.
//! - [`BlobStore`]: immutable bytes named by their content hash (models, aggregates, parts
//!   files, manifests, tree snapshots). [`BlobDir`] (`blobs.rs`) is the default.

mod blobs;
mod sqlite;

use glam::Affine3A;
use serde::{Deserialize, Serialize};

pub use blobs::BlobDir;
pub use sqlite::SqliteMeta;

use crate::error::WorldError;

/// Immutable, content-addressed bytes.
pub trait BlobStore: Send + Sync + std::fmt::Debug {
    /// Stores `bytes`, durably before returning; returns their content hash. Storing bytes
    /// already stored does nothing.
    fn put(&self, bytes: &[u8]) -> Result<String, WorldError>;
    /// Takes `bytes` to be stored at the next [`BlobStore::commit_staged`] (a batch is made
    /// durable in one flush); returns their content hash.
    fn stage(&self, bytes: &[u8]) -> Result<String, WorldError>;
    /// Stores everything staged, durably.
    fn commit_staged(&self) -> Result<(), WorldError>;
    /// The bytes named `hash`, if stored.
    fn get(&self, hash: &str) -> Result<Option<Vec<u8>>, WorldError>;
    /// The size of the blob named `hash`, if stored.
    fn size(&self, hash: &str) -> Result<Option<u64>, WorldError>;
    /// Forgets the blob named `hash` (nothing if it is not stored).
    fn delete(&self, hash: &str) -> Result<(), WorldError>;
    /// Every stored hash, sorted.
    fn list(&self) -> Result<Vec<String>, WorldError>;
    /// Removes what interrupted writes left; call before any staging. Returns how many.
    fn sweep(&self) -> Result<usize, WorldError>;
}

/// A model's descriptors and local bounding sphere.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelDescriptors {
    /// 3D Zernike descriptor (121 values).
    pub zernike: Vec<f32>,
    /// Color Structure Descriptor (32 bins).
    pub csd: Vec<f32>,
    /// Centre of the model's bounding sphere, in model space.
    pub centre: [f32; 3],
    /// Radius of the model's bounding sphere, in model space.
    pub radius: f32,
}

/// A model as the metadata store holds it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelRow {
    /// The BVH's model number: dense, from 0, in the order models were added.
    pub number: u64,
    /// The model's id: the content hash of the bytes it came as.
    pub id: String,
    /// The content hash of its stored GLB.
    pub asset: String,
    /// A name for people.
    pub name: String,
    /// Who uploaded it, if a user did.
    pub owner: Option<String>,
    /// Bytes of the stored GLB.
    pub bytes: u64,
    /// What the model holds (`horizon_mesh::MeshStats` as JSON).
    pub stats: serde_json::Value,
}

/// An object as the metadata store holds it.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectRow {
    /// The object's id.
    pub id: u64,
    /// Its model's number.
    pub model: u64,
    /// Model-to-world transform.
    pub transform: Affine3A,
    /// Who placed it, if a user did.
    pub owner: Option<String>,
    /// The generation that last placed or moved it.
    pub generation: u64,
}

/// One change to the objects, as asked.
#[derive(Clone, Debug, PartialEq)]
pub enum Mutation {
    /// Place a new object of a model (by number) with a transform.
    Create {
        /// The model's number.
        model: u64,
        /// Model-to-world transform.
        transform: Affine3A,
    },
    /// Give an object a new transform.
    Move {
        /// The object.
        id: u64,
        /// Its new transform.
        transform: Affine3A,
    },
    /// Remove an object.
    Delete {
        /// The object.
        id: u64,
    },
}

/// One committed change, in generation order: what the BVH replays.
#[derive(Clone, Debug, PartialEq)]
pub struct Applied {
    /// The generation this change made.
    pub generation: u64,
    /// The object it touched.
    pub object: u64,
    /// The change: `Some((model, transform))` for a placement or a move (the object's whole
    /// new state), `None` for a delete.
    pub state: Option<(u64, Affine3A)>,
}

/// Who a token belongs to, and their limits.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct User {
    /// The user's name.
    pub name: String,
    /// Most objects the user may own at once, if limited.
    pub max_objects: Option<u64>,
    /// Most bytes of stored models the user may upload, if limited.
    pub max_bytes: Option<u64>,
}

/// What is being served: the generation whose aggregates are built, and the blobs that hold
/// them.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Published {
    /// The generation.
    pub generation: u64,
    /// The blob holding its aggregate manifest, if any build ever completed.
    pub manifest: Option<String>,
    /// The manifest published before it, whose blobs are kept while clients may still fetch
    /// them.
    pub previous_manifest: Option<String>,
    /// Wall time of the rebuild that published it, milliseconds.
    pub rebuild_ms: Option<u64>,
}

/// A tree snapshot: the BVH at a generation, from which the log is replayed.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Snapshot {
    /// The generation the tree holds every change up to.
    pub generation: u64,
    /// The blob holding it.
    pub blob: String,
}

/// Models, objects, users and generations (see the module docs).
pub trait MetaStore: Send + Sync + std::fmt::Debug {
    /// The world's name and seed (what created it).
    fn identity(&self) -> Result<(String, u64), WorldError>;
    /// The number of the last committed mutation.
    fn generation(&self) -> Result<u64, WorldError>;

    /// Adds a model, or finds the one with the same id: `(row, true)` if it was added. A
    /// user's `max_bytes` is checked in the same transaction.
    fn add_model(&self, model: NewModel<'_>) -> Result<(ModelRow, bool), WorldError>;
    /// Refuses, as [`MetaStore::add_model`] would, a model of `bytes` for `owner` past their
    /// `max_bytes` (a cheap check before the work of ingest; `add_model` checks again).
    fn check_model_quota(&self, owner: &str, bytes: u64) -> Result<(), WorldError>;
    /// The model with this id.
    fn model(&self, id: &str) -> Result<Option<ModelRow>, WorldError>;
    /// Every model, by number.
    fn models(&self) -> Result<Vec<ModelRow>, WorldError>;
    /// Up to `limit` models with ids after `after`, in id order.
    fn models_page(&self, after: Option<&str>, limit: usize) -> Result<Vec<ModelRow>, WorldError>;
    /// Number of models.
    fn model_count(&self) -> Result<u64, WorldError>;

    /// The descriptors of a stored GLB, by its content hash.
    fn descriptors(&self, asset: &str) -> Result<Option<ModelDescriptors>, WorldError>;
    /// Records the descriptors of a stored GLB.
    fn put_descriptors(&self, asset: &str, d: &ModelDescriptors) -> Result<(), WorldError>;
    /// The levels of detail of a stored GLB, by its content hash (level 0 first).
    fn levels(&self, asset: &str) -> Result<Option<Vec<ModelLevel>>, WorldError>;
    /// Every stored GLB's levels of detail, by its content hash.
    fn all_levels(&self) -> Result<std::collections::HashMap<String, Vec<ModelLevel>>, WorldError>;
    /// Records the levels of detail of a stored GLB (their blobs are durable before).
    fn put_levels(&self, asset: &str, levels: &[ModelLevel]) -> Result<(), WorldError>;
    /// Records the levels of detail of many stored GLBs in one transaction.
    fn put_levels_batch(&self, rows: &[(String, Vec<ModelLevel>)]) -> Result<(), WorldError>;

    /// Applies `mutations` in order as one transaction, each making the next generation, for
    /// `user` (`None`: the world itself, which owns every object and has no quota). A user
    /// may move and delete only their own objects, and stays within `max_objects`. Fails
    /// whole: nothing is applied if any mutation is refused.
    fn apply(&self, user: Option<&str>, mutations: &[Mutation])
        -> Result<Vec<Applied>, WorldError>;
    /// The object with this id.
    fn object(&self, id: u64) -> Result<Option<ObjectRow>, WorldError>;
    /// Up to `limit` objects with ids after `after` (of `owner`, if given), in id order.
    fn objects_page(
        &self,
        after: Option<u64>,
        limit: usize,
        owner: Option<&str>,
    ) -> Result<Vec<ObjectRow>, WorldError>;
    /// Number of objects.
    fn object_count(&self) -> Result<u64, WorldError>;
    /// Every committed change after `generation`, in order.
    fn log_after(&self, generation: u64) -> Result<Vec<Applied>, WorldError>;

    /// Adds a user (or updates their limits) and a token for them, stored by its hash.
    fn add_token(&self, user: &User, token_hash: &str) -> Result<(), WorldError>;
    /// The user a token hash belongs to.
    fn user_of_token(&self, token_hash: &str) -> Result<Option<User>, WorldError>;

    /// Every aggregate entry recorded, as JSON text by key.
    fn aggregate_entries(&self) -> Result<Vec<(String, String)>, WorldError>;
    /// Records aggregate entries (key, JSON text) in one transaction.
    fn put_aggregate_entries(&self, entries: &[(String, String)]) -> Result<(), WorldError>;
    /// Keeps only the entries whose keys are listed.
    fn retain_aggregate_entries(&self, keys: &[String]) -> Result<(), WorldError>;
    /// Removes the entries with these keys, in one transaction.
    fn remove_aggregate_entries(&self, keys: &[String]) -> Result<(), WorldError>;

    /// What is published.
    fn published(&self) -> Result<Published, WorldError>;
    /// Publishes `published` as one step (readers see the old or the new, never a mix).
    fn publish(&self, published: &Published) -> Result<(), WorldError>;
    /// The latest tree snapshot.
    fn snapshot(&self) -> Result<Option<Snapshot>, WorldError>;
    /// Records a tree snapshot, and forgets the log up to its generation.
    fn put_snapshot(&self, snapshot: &Snapshot) -> Result<(), WorldError>;
}

/// A model to add.
#[derive(Clone, Copy, Debug)]
pub struct NewModel<'a> {
    /// Its id: the content hash of the bytes it came as.
    pub id: &'a str,
    /// The content hash of its stored GLB.
    pub asset: &'a str,
    /// A name for people.
    pub name: &'a str,
    /// Who uploads it.
    pub owner: Option<&'a str>,
    /// Bytes of the stored GLB.
    pub bytes: u64,
    /// What it holds.
    pub stats: &'a serde_json::Value,
    /// Its descriptors, recorded in the same transaction if given.
    pub descriptors: Option<&'a ModelDescriptors>,
    /// Its levels of detail, recorded in the same transaction if given (their blobs are
    /// durable before).
    pub levels: Option<&'a [ModelLevel]>,
}

/// One level of detail of a stored model: level 0 is the stored GLB itself.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelLevel {
    /// The content hash of the level's GLB.
    pub asset: String,
    /// Its error, triangles, draw calls, bytes and texel density.
    #[serde(flatten)]
    pub info: horizon_levels::LevelInfo,
}
