//! The crate's failures: refused input ([`BvhError`]) and broken invariants ([`InvalidTree`]).

use crate::ObjectId;

/// Why an operation on the tree was refused. The tree is unchanged when one is returned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BvhError {
    /// A descriptor has the wrong number of values.
    #[error("{which} descriptor has {got} values, expected {expected}")]
    DescriptorLength {
        /// "shape" or "texture".
        which: &'static str,
        /// The length the tree stores ([`crate::SHAPE_LEN`] or [`crate::TEXTURE_LEN`]).
        expected: usize,
        /// The length given.
        got: usize,
    },
    /// A number that must be finite is not (NaN or infinite), or a radius is negative.
    #[error("{0} is not finite (or a radius is negative)")]
    NonFinite(&'static str),
    /// The object id does not name a live object.
    #[error("no object with id {0:?}")]
    UnknownObject(ObjectId),
    /// The options break a documented constraint.
    #[error("invalid options: {0}")]
    BadOptions(String),
    /// More objects or nodes than 32-bit ids can name.
    #[error("the tree is full: ids are 32-bit")]
    Full,
}

/// A broken invariant found by [`crate::Bvh::validate`], with a one-line description.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("invalid tree: {0}")]
pub struct InvalidTree(pub String);
