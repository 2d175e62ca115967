//! The typed errors of the aggregate rebuild.

use std::path::PathBuf;

/// Why an aggregate, or the rebuild, failed. Every message is one line.
#[derive(Debug, thiserror::Error)]
pub enum AggregateError {
    /// A model the tree names could not be loaded or is invalid.
    #[error("model {model}: {reason}")]
    Model {
        /// The BVH's model number.
        model: u64,
        /// What went wrong.
        reason: String,
    },
    /// The tree refers to a node or object it does not hold.
    #[error("tree: {0}")]
    Tree(String),
    /// Simplification refused the merged mesh.
    #[error("simplify node {node}: {source}")]
    Simplify {
        /// The node whose aggregate was being built.
        node: u32,
        /// The simplifier's error.
        source: horizon_simplify::SimplifyError,
    },
    /// The atlas could not be baked.
    #[error("atlas of node {node}: {source}")]
    Atlas {
        /// The node whose aggregate was being built.
        node: u32,
        /// The atlas error.
        source: horizon_atlas::AtlasError,
    },
    /// The GLB could not be written or read back.
    #[error("glb of node {node}: {reason}")]
    Glb {
        /// The node whose aggregate was being built.
        node: u32,
        /// What went wrong.
        reason: String,
    },
    /// A file of the store could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A file of the store is not what this build wrote.
    #[error("{path}: {reason}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// The build was asked to stop; the levels it finished are in the store.
    #[error("the build was stopped")]
    Stopped,
}

impl AggregateError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }
}
