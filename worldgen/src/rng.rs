//! The generators draw from the workspace's seeded SplitMix64 ([`horizon_mesh::rng`]).

pub use horizon_mesh::rng::{mix, Rng};
