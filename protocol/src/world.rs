//! `GET /v1/world`.

use serde::{Deserialize, Serialize};

/// The state of a world: its generations, sizes and the rebuild's progress.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct WorldInfo {
    /// The number of the last committed mutation.
    pub generation: u64,
    /// The generation whose aggregates are being served.
    pub published: u64,
    /// Objects in the world at `generation`.
    pub objects: u64,
    /// Models stored.
    pub models: u64,
    /// BVH nodes whose aggregates wait for the next rebuild.
    pub dirty_nodes: u64,
    /// Wall time of the last completed rebuild, milliseconds (none before the first).
    pub last_rebuild_ms: Option<u64>,
    /// The box holding every object, none for an empty world.
    pub bounds: Option<Bounds>,
}

/// An axis-aligned box in world space.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Bounds {
    /// The lowest corner.
    pub min: [f32; 3],
    /// The highest corner.
    pub max: [f32; 3],
}
