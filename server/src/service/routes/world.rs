//! `GET /v1/world`.

use axum::extract::State;
use axum::Json;
use horizon_protocol::{Bounds, ErrorBody, WorldInfo};

use crate::service::{AppResult, AppState};

/// The world's generations, sizes and rebuild state.
#[utoipa::path(get, path = "/v1/world", tag = "world",
    responses(
        (status = 200, description = "The world", body = WorldInfo),
        (status = 500, description = "The server failed", body = ErrorBody),
    ))]
pub async fn info(State(state): State<AppState>) -> AppResult<Json<WorldInfo>> {
    let s = state.blocking(|world| world.status()).await?;
    Ok(Json(WorldInfo {
        generation: s.generation,
        published: s.published,
        objects: s.objects,
        models: s.models,
        dirty_nodes: s.dirty_nodes,
        last_rebuild_ms: s.last_rebuild_ms,
        bounds: s.bounds.map(|b| Bounds {
            min: b.min.to_array(),
            max: b.max.to_array(),
        }),
    }))
}
