//! A client of Horizon's world service (`DESIGN.md`, "Service contract (v1)"): one-shot cuts
//! over HTTP, the standing cut over WebSocket applied delta by delta into a [`LocalCut`] that
//! is checked at every step, an on-disk [`AssetCache`] of `/assets/{hash}`, and [`walk`], a
//! viewer moving along a path that measures how long each view takes to load and how often a
//! drawn entry is missing. The `horizon-client` binary (`src/main.rs`) puts these on the
//! command line.
//!
//! # Layout
//! - `http.rs`: [`Client`] (`GET /v1/cut`) and [`ClientError`], which carries the server's
//!   [`horizon_protocol::ErrorBody`].
//! - `local.rs`: [`LocalCut`], a cut kept by applying the stream's messages, with
//!   [`ApplyError`], [`Incomplete`] and [`Mismatch`].
//! - `stream.rs`: [`Stream`], the `/v1/stream` WebSocket, and [`StreamError`].
//! - `assets.rs`: [`AssetCache`] and [`TokenBucket`], the bandwidth throttle.
//! - `walk.rs`: [`walk`], [`WalkOptions`], [`WalkReport`] and [`Polyline`].

mod assets;
mod http;
mod local;
mod stream;
mod walk;

pub use assets::{AssetCache, AssetError, Fetched, TokenBucket};
pub use http::{code_name, Client, ClientError};
pub use local::{check_cut, ApplyError, Incomplete, LocalCut, Mismatch};
pub use stream::{Stream, StreamError};
pub use walk::{walk, Latencies, Polyline, WalkError, WalkOptions, WalkReport};
