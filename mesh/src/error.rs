//! Typed errors for import and export. Every variant prints as one line that names the part of
//! the file at fault, so the upload service can hand it to the user as it is.

use crate::model::InvalidMesh;

/// Why an import was refused.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The file could not be read.
    #[error("cannot read {path}: {reason}")]
    Io {
        /// The path that failed.
        path: String,
        /// The OS error (a field, not a `source`, so a printed chain does not repeat it).
        reason: std::io::Error,
    },
    /// The file's format could not be told from its name or its first bytes.
    #[error("unknown model format: {0}")]
    UnknownFormat(String),
    /// The file ends before a structure it declares.
    #[error("truncated file: {0}")]
    Truncated(String),
    /// The file does not start with the signature of its format.
    #[error("bad magic: {0}")]
    BadMagic(String),
    /// The glTF JSON is not well-formed or does not follow the schema.
    #[error("invalid glTF JSON: {0}")]
    Json(String),
    /// A PLY, OBJ or STL file could not be parsed.
    #[error("cannot parse {format}: {reason}")]
    Parse {
        /// Which format.
        format: &'static str,
        /// What the parser said.
        reason: String,
    },
    /// A reference (to an accessor, a node, a buffer...) points past the end of its array.
    #[error("{what} refers to missing {target} {index}")]
    MissingReference {
        /// The referring item, e.g. `mesh 0 primitive 1`.
        what: String,
        /// What kind of item is missing.
        target: &'static str,
        /// The index that does not exist.
        index: usize,
    },
    /// A byte range reaches past the end of the data it reads.
    #[error("{what} is out of bounds: {reason}")]
    OutOfBounds {
        /// The accessor, buffer view or buffer.
        what: String,
        /// The offending range.
        reason: String,
    },
    /// A vertex index is not below the vertex count.
    #[error("{what}: index {index} is past the {vertices} vertices")]
    IndexOutOfRange {
        /// The primitive.
        what: String,
        /// The offending index value.
        index: u64,
        /// The vertex count.
        vertices: usize,
    },
    /// A position, attribute or transform is NaN or infinite.
    #[error("{0} is NaN or infinite")]
    NonFinite(String),
    /// The node graph has a cycle, so the scene is infinite.
    #[error("node graph has a cycle through node {node}")]
    NodeCycle {
        /// A node on the cycle.
        node: usize,
    },
    /// A URI that we refuse to follow: remote, or escaping the file's folder.
    #[error("refused URI {uri:?}: {reason}")]
    ForbiddenUri {
        /// The URI as written.
        uri: String,
        /// Why it is refused.
        reason: &'static str,
    },
    /// An image could not be decoded.
    #[error("image {image} cannot be decoded: {reason}")]
    ImageDecode {
        /// The glTF image index (or texture file name).
        image: String,
        /// What the decoder said.
        reason: String,
    },
    /// A size limit from [`crate::Limits`] was exceeded.
    #[error("{what} is {value}, over the limit of {limit}")]
    LimitExceeded {
        /// Which limit.
        what: &'static str,
        /// The value found (or a lower bound of it).
        value: u64,
        /// The limit.
        limit: u64,
    },
    /// A feature the file requires that Horizon does not read.
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// The imported model broke an invariant of the mesh model.
    #[error("invalid mesh: {0}")]
    Invalid(#[from] InvalidMesh),
}

impl ImportError {
    /// A short machine-readable name of the kind of error, for JSON output and tests.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Io { .. } => "io",
            Self::UnknownFormat(_) => "unknown_format",
            Self::Truncated(_) => "truncated",
            Self::BadMagic(_) => "bad_magic",
            Self::Json(_) => "json",
            Self::Parse { .. } => "parse",
            Self::MissingReference { .. } => "missing_reference",
            Self::OutOfBounds { .. } => "out_of_bounds",
            Self::IndexOutOfRange { .. } => "index_out_of_range",
            Self::NonFinite(_) => "non_finite",
            Self::NodeCycle { .. } => "node_cycle",
            Self::ForbiddenUri { .. } => "forbidden_uri",
            Self::ImageDecode { .. } => "image_decode",
            Self::LimitExceeded { .. } => "limit_exceeded",
            Self::Unsupported(_) => "unsupported",
            Self::Invalid(_) => "invalid_mesh",
        }
    }

    /// Which limit was exceeded, for a [`ImportError::LimitExceeded`].
    pub fn limit(&self) -> Option<crate::import::Limit> {
        match self {
            Self::LimitExceeded { what, .. } => Some(crate::import::Limit::of(what)),
            _ => None,
        }
    }
}

/// Why an export failed.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The mesh breaks an invariant, so it cannot be written as valid glTF.
    #[error("invalid mesh: {0}")]
    Invalid(#[from] InvalidMesh),
    /// The output would exceed what GLB can address (4 GiB).
    #[error("output too large for GLB: {0} bytes")]
    TooLarge(u64),
    /// The meshopt encoder refused the data.
    #[error("meshopt encoding failed: {0}")]
    Encode(String),
    /// The file could not be written.
    #[error("cannot write {path}: {reason}")]
    Io {
        /// The path that failed.
        path: String,
        /// The OS error.
        reason: std::io::Error,
    },
}
