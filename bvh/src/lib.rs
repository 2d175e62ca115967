//! Similarity-aware bounding volume hierarchy (Azim et al. 2014, section 4) with Sirikata's
//! max-sphere bound and the solid-angle cut query (core paper eq. 3; Cheslack-Postava et al.
//! 2012).
//!
//! A world's objects live in an R-tree-like hierarchy whose every leaf is at the same depth.
//! Objects are grouped by proximity *and* by the similarity of their shape (3D Zernike, L2)
//! and texture (Color Structure Descriptor, L1) descriptors, so that an aggregate of a node's
//! objects holds many near-duplicates to instance. A client asks for a *cut*: every object
//! subtending at least `Omega_min` as itself, everything else through exactly one ancestor
//! aggregate.
//!
//! # Layout
//! - [`Bvh`] (`tree.rs`): the arena of nodes and the struct-of-arrays object store; ids,
//!   accessors ([`NodeRef`], [`ObjectRef`]), memory accounting.
//! - `insert.rs`: [`Bvh::insert`], descent by eq. 1 and the bookkeeping of an insert.
//! - `split.rs`: the similarity-aware split of an overflowing node (section 4.2).
//! - `remove.rs`: [`Bvh::remove`] (condense, reinsert orphans) and [`Bvh::move_object`].
//! - `bulk.rs`: [`Bvh::bulk_build`] and [`Bvh::rebuild`], the top-down build by descriptor
//!   dispersion (section 4.3), parallel with rayon.
//! - `cut.rs`: [`Bvh::cut`], best-first refinement by worst-case solid angle.
//! - `standing.rs`: [`StandingQuery`], a per-client cut kept up to date with ordered
//!   [`CutDelta`]s and hysteresis (Sirikata's `RTreeCutQueryHandler`).
//! - `spatial.rs` (feature `baseline`, for the lab only): `SpatialBaseline`, the same objects
//!   in an `obvhs` SAH BVH with the same cut, the query-cost baseline.
//! - `validate.rs`: [`Bvh::validate`], every structural invariant.
//! - [`solid_angle`](mod@solid_angle): eq. 3 and the max-sphere worst case.
//! - [`bounds`]: spheres, boxes and the sphere fit.
//! - [`options`]: [`BvhOptions`] with the documented defaults.

pub mod bounds;
mod bulk;
mod cut;
mod error;
mod insert;
pub mod options;
mod remove;
pub mod solid_angle;
#[cfg(feature = "baseline")]
pub mod spatial;
mod split;
mod standing;
mod tree;
mod validate;

pub use bounds::{Aabb, Sphere};
pub use cut::{
    Cut, CutEntry, CutItem, CutQuery, CutWorkspace, EntryKind, DEFAULT_MAX_RESULTS,
    DEFAULT_MIN_SOLID_ANGLE,
};
pub use error::{BvhError, InvalidTree};
pub use options::{BvhOptions, DEFAULT_MU, DEFAULT_W, MAX_BRANCHING};
pub use solid_angle::{solid_angle, worst_case_solid_angle};
#[cfg(feature = "baseline")]
pub use spatial::{SpatialBaseline, SpatialCut, SpatialEntry, SpatialItem, SpatialWorkspace};
pub use standing::{apply_deltas, CutDelta, StandingOptions, StandingQuery, UpdateStats};
pub use tree::{Bvh, NewObject, NodeId, NodeRef, ObjectId, ObjectRef};

/// Length of a shape descriptor: the 121 rotation-invariant norms of a 3D Zernike descriptor
/// of order 20 (core paper section 4.1), compared by L2 distance.
pub const SHAPE_LEN: usize = 121;

/// Length of a texture descriptor: the 32-bin MPEG-7 Color Structure Descriptor on the 0..=255
/// amplitude scale (core paper section 4.1), compared by L1 distance.
pub const TEXTURE_LEN: usize = 32;
