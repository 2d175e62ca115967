//! Health, metrics, the OpenAPI document, the index page and the 404 of unknown routes.

use axum::extract::State;
use axum::http::header::CONTENT_TYPE;
use axum::response::{Html, IntoResponse};
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

/// What the service is, with links to the API.
#[utoipa::path(get, path = "/", tag = "service",
    responses((status = 200, description = "The index page", content_type = "text/html")))]
pub async fn index() -> Html<&'static str> {
    Html(INDEX)
}

const INDEX: &str = r#"<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>Horizon</title></head>
<body style="font-family: sans-serif; max-width: 40em; margin: 3em auto">
<h1>Horizon</h1>
<p>A world server for large user-generated 3D worlds. Upload models, place them as objects,
ask for everything that subtends a solid angle from where you are, and fetch immutable,
content-addressed assets.</p>
<ul>
<li><a href="/v1/world">/v1/world</a>: the world's generation, size and rebuild state</li>
<li><a href="/v1/models">/v1/models</a> and <a href="/v1/objects">/v1/objects</a>: its contents, a page at a time</li>
<li><a href="/v1/cut?eye=0,2,0">/v1/cut?eye=x,y,z</a>: the cut from a point (<code>min_solid_angle</code>, <code>max_entries</code>, <code>max_bytes</code>, ...)</li>
<li><code>/v1/stream</code>: the same cut kept up to date over WebSocket</li>
<li><a href="/v1/openapi.json">/v1/openapi.json</a>: every route</li>
<li><a href="/metrics">/metrics</a>, <a href="/healthz">/healthz</a></li>
</ul>
</body></html>
"#;

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
