//! Seeded procedural workloads for Horizon: instanced models shaped like the IAS benchmark models
//! of Table 2 in Azim et al. 2014 (sections 6 and 8.1).
//!
//! Every model is an [`InstancedMesh`] whose structure (submeshes, instances, expanded triangles)
//! follows the paper's table, so that instance-aware simplification can be measured on it:
//!
//! | name           | submeshes | instances | expanded triangles |
//! |----------------|-----------|-----------|--------------------|
//! | `maple-tree`   | 18        | 9,324     | ~1.82M             |
//! | `village-mesh` | 79        | 13,523    | ~1.25M             |
//! | `patio-chair`  | 6         | 68        | 2,240              |
//! | `stonehenge`   | 59        | 80        | ~10k               |
//!
//! The same name and seed always give a bit-identical mesh; another seed moves the placements.
//!
//! # Layout
//! - [`models`]: one module per model.
//! - [`shapes`]: closed primitives (box, tube, frustum, sphere, extrusion) and open sheets (leaf
//!   blade, height field), built once per submesh.
//! - [`textures`]: small procedural PNG textures (bark, leaf, stone, wood, roof tiles, ...).
//! - [`assembly`]: collects textures, materials, submeshes and instances into a model.
//! - [`worlds`]: the benchmark worlds (village, island, city, city9) built from small parametric
//!   models; [`generate_world`].
//! - [`noise`] and [`rng`]: the seeded value noise, and the workspace's SplitMix64 generator
//!   (re-exported from `horizon_mesh::rng`), that everything draws from.

pub mod assembly;
pub mod models;
pub mod noise;
pub mod rng;
pub mod shapes;
pub mod textures;
pub mod worlds;

pub use worlds::distinct::{city_distinct_layout, distinct_building, CITY_DISTINCT_OBJECTS};
pub use worlds::{generate_world, generate_world_with, World, WorldObject, WORLD_NAMES};

use horizon_mesh::InstancedMesh;

/// The names [`generate_model`] accepts, in the order of the paper's Table 2.
pub const MODEL_NAMES: [&str; 4] = ["maple-tree", "village-mesh", "patio-chair", "stonehenge"];

/// Generates the named benchmark model (see [`MODEL_NAMES`]) from `seed`.
///
/// # Errors
/// [`WorldgenError::UnknownModel`] for a name not in [`MODEL_NAMES`];
/// [`WorldgenError::Texture`] if a procedural texture cannot be encoded.
pub fn generate_model(name: &str, seed: u64) -> Result<InstancedMesh, WorldgenError> {
    Ok(generate_model_with_info(name, seed)?.mesh)
}

/// Like [`generate_model`], but also says what each submesh is and whether it is closed.
///
/// # Errors
/// As [`generate_model`].
pub fn generate_model_with_info(name: &str, seed: u64) -> Result<GeneratedModel, WorldgenError> {
    match name {
        "maple-tree" => models::maple_tree::generate(seed),
        "village-mesh" => models::village_mesh::generate(seed),
        "patio-chair" => models::patio_chair::generate(seed),
        "stonehenge" => models::stonehenge::generate(seed),
        _ => Err(WorldgenError::UnknownModel {
            name: name.to_owned(),
            valid: &MODEL_NAMES,
        }),
    }
}

/// A generated model with a description of each of its submeshes.
#[derive(Clone, Debug, Default)]
pub struct GeneratedModel {
    /// The instanced mesh.
    pub mesh: InstancedMesh,
    /// One entry per submesh of `mesh`, in the same order.
    pub submeshes: Vec<SubmeshInfo>,
}

/// What a submesh of a generated model is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SubmeshInfo {
    /// A short name such as `trunk`, `leaf-green` or `house-body-3`.
    pub name: String,
    /// Whether the submesh is a closed, consistently outward-wound surface: welded by position,
    /// every edge is shared by exactly two triangles, once in each direction.
    pub closed: bool,
}

/// Why a model could not be generated.
#[derive(Debug, thiserror::Error)]
pub enum WorldgenError {
    /// The name is not one of [`MODEL_NAMES`].
    #[error("unknown model {name:?}; valid names are: {}", valid.join(", "))]
    UnknownModel {
        /// The name asked for.
        name: String,
        /// The names that exist.
        valid: &'static [&'static str],
    },
    /// The name is not one of [`WORLD_NAMES`].
    #[error("unknown world {name:?}; valid names are: {}", valid.join(", "))]
    UnknownWorld {
        /// The name asked for.
        name: String,
        /// The names that exist.
        valid: &'static [&'static str],
    },
    /// A procedural texture could not be encoded as PNG.
    #[error("could not encode a procedural texture: {0}")]
    Texture(#[from] image::ImageError),
}
