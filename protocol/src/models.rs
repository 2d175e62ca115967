//! `POST /v1/models`, `GET /v1/models/{id}`, `GET /v1/models`.

use serde::{Deserialize, Serialize};

/// A stored model: its id, the asset it is served as, and what it holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ModelInfo {
    /// The model's id: the content hash (BLAKE3-256, 64 hex digits) of the bytes uploaded, so
    /// the same bytes uploaded twice get the same id.
    pub id: String,
    /// The content hash of its stored GLB, served at `/assets/{asset}`.
    pub asset: String,
    /// A name for people (the uploaded file's, or the generator's).
    pub name: String,
    /// Who uploaded it (none for models a generator or an import placed).
    pub owner: Option<String>,
    /// Bytes of the stored GLB.
    pub bytes: u64,
    /// Submeshes (one draw each).
    pub submeshes: u64,
    /// Placements of submeshes inside the model.
    pub instances: u64,
    /// Triangles stored.
    pub triangles_unique: u64,
    /// Triangles drawn, every instance counted.
    pub triangles_expanded: u64,
    /// Materials.
    pub materials: u64,
    /// Textures.
    pub textures: u64,
    /// Its levels of detail, level 0 (the stored GLB, `asset`) first, each coarser than the
    /// one before; empty until the model has been levelled (`horizon build`).
    #[serde(default)]
    pub levels: Vec<ModelLevelInfo>,
}

/// One level of detail of a model: a GLB of its own, served at `/assets/{asset}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ModelLevelInfo {
    /// 0 for the model as stored, then 1, 2, ... coarser.
    pub level: u32,
    /// The content hash of its GLB.
    pub asset: String,
    /// Bytes of its GLB.
    pub bytes: u64,
    /// Triangles drawn, instances expanded.
    pub triangles: u64,
    /// Draw calls: one per submesh.
    pub draw_calls: u64,
    /// Symmetric Hausdorff distance to level 0, in model units.
    pub error: f64,
    /// Texels per model unit over the textured surface (none without textures).
    pub texel_density: Option<f64>,
}

/// One page of `GET /v1/models`, in id order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ModelPage {
    /// The models of the page.
    pub models: Vec<ModelInfo>,
    /// The `after` of the next page; none on the last.
    pub next: Option<String>,
}
