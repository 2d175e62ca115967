//! The typed errors of a world. Every message is one line and names the file or model it is
//! about.

use std::path::PathBuf;

/// Why an operation on a world failed.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// The directory does not hold a world.
    #[error("{} is not a world directory", .0.display())]
    NotAWorld(PathBuf),
    /// The world has not been built (no descriptors, BVH or aggregates yet).
    #[error("no built world in {} (run horizon build)", .0.display())]
    NotBuilt(PathBuf),
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A file is not what this version writes.
    #[error("corrupt {}: {reason}", path.display())]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// The world's files disagree with each other.
    #[error("{0}")]
    Inconsistent(String),
    /// A model could not be imported, is invalid, or could not be described or stored.
    #[error("model {name}: {reason}")]
    Model {
        /// The model's file, name or content hash.
        name: String,
        /// What went wrong.
        reason: String,
    },
    /// Uploaded bytes are not a model this world takes (see [`BadModel`]).
    #[error("{reason}")]
    BadModel {
        /// Which rule it broke.
        kind: BadModel,
        /// What is wrong, in one line.
        reason: String,
    },
    /// A transform is not a placement: NaN or infinite numbers, a zero or negative scale, a
    /// rotation that is not a unit quaternion.
    #[error("{0}")]
    InvalidTransform(String),
    /// An object names a model the world does not have.
    #[error("{0}")]
    UnknownModel(String),
    /// No such object, model or blob.
    #[error("{0}")]
    NotFound(String),
    /// The object belongs to someone else.
    #[error("{0}")]
    Forbidden(String),
    /// The change would take a user past their quota.
    #[error("{0}")]
    QuotaExceeded(String),
    /// The metadata database failed.
    #[error("database: {0}")]
    Database(String),
    /// The BVH refused its input.
    #[error(transparent)]
    Bvh(#[from] horizon_bvh::BvhError),
    /// A built BVH broke one of its invariants.
    #[error("invalid tree: {0}")]
    InvalidTree(#[from] horizon_bvh::InvalidTree),
    /// The aggregate rebuild failed as a whole.
    #[error(transparent)]
    Aggregate(#[from] horizon_aggregate::AggregateError),
}

/// The rules an uploaded model can break.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BadModel {
    /// Not glTF, truncated, buffers out of range, an external URI, invalid geometry.
    Malformed,
    /// More expanded triangles than the limit.
    TooManyTriangles,
    /// A texture over the side or pixel limit.
    TextureTooLarge,
    /// More instances than the limit.
    TooManyInstances,
    /// Bigger than the byte limit.
    TooLarge,
}

impl WorldError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    /// A model-level failure.
    pub fn model(name: impl Into<String>, reason: impl std::fmt::Display) -> Self {
        Self::Model {
            name: name.into(),
            reason: reason.to_string(),
        }
    }
}
