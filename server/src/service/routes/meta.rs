//! Health, metrics, the OpenAPI document and the 404 of unknown routes.

use axum::extract::State;
use axum::http::header::CONTENT_TYPE;
use axum::response::IntoResponse;
use axum::Json;
use horizon_protocol::ErrorCode;
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;

use crate::service::{ApiDoc, AppError, AppState};

/// The OpenAPI document of every route.
pub fn document() -> utoipa::openapi::OpenApi {
    OpenApiRouter::<AppState>::with_openapi(ApiDoc::openapi())
        .merge(super::router())
        .into_openapi()
}

/// 200 while the process serves.
#[utoipa::path(get, path = "/healthz", tag = "service",
    responses((status = 200, description = "The process serves", body = String)))]
pub async fn health() -> &'static str {
    "ok"
}

/// Prometheus text: request counts and latencies by route, rebuilds, generations, dirty nodes.
#[utoipa::path(get, path = "/metrics", tag = "service",
    responses((status = 200, description = "Prometheus text exposition", body = String)))]
pub async fn metrics_text(State(state): State<AppState>) -> impl IntoResponse {
    if let Ok(Ok(s)) = tokio::task::spawn_blocking({
        let world = state.world().clone();
        move || world.status()
    })
    .await
    {
        metrics::gauge!("horizon_generation").set(s.generation as f64);
        metrics::gauge!("horizon_published_generation").set(s.published as f64);
        metrics::gauge!("horizon_generation_lag")
            .set(s.generation.saturating_sub(s.published) as f64);
        metrics::gauge!("horizon_dirty_nodes").set(s.dirty_nodes as f64);
        metrics::gauge!("horizon_objects").set(s.objects as f64);
        metrics::gauge!("horizon_models").set(s.models as f64);
    }
    (
        [(CONTENT_TYPE, "text/plain; version=0.0.4")],
        state.inner.metrics.render(),
    )
}

/// This document.
#[utoipa::path(get, path = "/v1/openapi.json", tag = "service",
    responses((status = 200, description = "OpenAPI 3.1 of every route", content_type = "application/json")))]
pub async fn openapi() -> Json<utoipa::openapi::OpenApi> {
    Json(document())
}

/// Any route the service does not have.
pub async fn not_found() -> AppError {
    AppError::new(ErrorCode::NotFound, "no such route")
}

/// A route asked with a method it does not take.
pub async fn method_not_allowed() -> AppError {
    AppError::new(
        ErrorCode::MethodNotAllowed,
        "this route does not take that method",
    )
}
