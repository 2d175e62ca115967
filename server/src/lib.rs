//! The `horizon` product (`DESIGN.md`, "Workspace layout"): the world service and the
//! command-line tools a user runs, over `horizon-world`. The binary is `src/main.rs`; this
//! library holds the service ([`service::app`], [`service::run`]) and what the lab's
//! `horizon-lab` shares with the binary.
//!
//! # Layout
//! - `service/`: the HTTP service (axum): routes, errors, auth, metrics, the rebuild worker.
//! - `terminal.rs`: stdout lines a closed pipe ends quietly ([`outln!`]), progress bars,
//!   one-line errors and exit statuses.
//! - `generated.rs`: a `horizon-worldgen` world written as a world directory (the demo's
//!   village, the lab's benchmark worlds).

pub mod generated;
pub mod service;
pub mod terminal;
