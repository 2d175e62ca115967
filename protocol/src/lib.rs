//! Horizon's wire types (`DESIGN.md`, "Service contract (v1)"): one serde type per request,
//! response and error of the service, shared by the server, the clients and the lab. JSON
//! everywhere. This crate depends on serde alone (and utoipa behind the `openapi` feature, for
//! the server's OpenAPI document), so it also builds for wasm.
//!
//! # Layout
//! - `error.rs`: [`ErrorBody`] and [`ErrorCode`], with each code's HTTP status.
//! - `world.rs`: [`WorldInfo`], what `GET /v1/world` answers.
//! - `models.rs`: [`ModelInfo`] and its page.
//! - `cut.rs`: [`View`], [`CutResponse`] and its [`Entry`]s.
//! - `stream.rs`: the WebSocket's [`ClientMessage`] and [`ServerMessage`].
//! - `objects.rs`: [`NewObject`], [`ObjectPatch`], [`ObjectInfo`], the batch and pages.

mod cut;
mod error;
mod models;
mod objects;
mod stream;
mod world;

pub use cut::{
    Asset, AssetRole, Budgets, CutResponse, Entry, EntryKind, Impostor, ImpostorView, Placement,
    StoppedBy, View, DEFAULT_MAX_ENTRIES, DEFAULT_MAX_PIXEL_ERROR, DEFAULT_MIN_SOLID_ANGLE,
    DEFAULT_PIXEL_SOLID_ANGLE, MAX_ENTRIES_LIMIT,
};
pub use error::{ErrorBody, ErrorCode, ErrorDetail};
pub use models::{ModelInfo, ModelLevelInfo, ModelPage};
pub use objects::{
    BatchOp, BatchRequest, BatchResponse, Created, Deleted, NewObject, ObjectInfo, ObjectPage,
    ObjectPatch, Scale,
};
pub use stream::{Addition, ClientMessage, Removal, RemoveReason, Renamed, Reuse, ServerMessage};
pub use world::{Bounds, WorldInfo};

/// The default size of a page of `GET /v1/objects` and `GET /v1/models`.
pub const DEFAULT_PAGE: usize = 1_000;

/// The largest page a client may ask for.
pub const MAX_PAGE: usize = 10_000;
