//! The routes, one file per resource, and the extractors that turn malformed requests into
//! the contract's errors.

pub mod assets;
pub mod cut;
pub mod meta;
pub mod models;
pub mod objects;
pub mod web;
pub mod world;

use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::header::{CONTENT_LENGTH, CONTENT_TYPE};
use axum::http::request::Parts;
use horizon_protocol::{ErrorCode, DEFAULT_PAGE, MAX_PAGE};
use serde::de::DeserializeOwned;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::{stream, AppError, AppState};

/// Every route of the API, with its OpenAPI description.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(meta::health))
        .routes(routes!(meta::metrics_text))
        .routes(routes!(meta::openapi))
        .routes(routes!(web::index))
        .routes(routes!(world::info))
        .routes(routes!(models::upload, models::list))
        .routes(routes!(models::get))
        .routes(routes!(objects::create, objects::list))
        .routes(routes!(objects::get, objects::patch, objects::delete))
        .routes(routes!(objects::batch))
        .routes(routes!(cut::get))
        .routes(routes!(stream::stream))
        .routes(routes!(assets::get))
}

/// A JSON body: `Content-Type: application/json`, at most the body limit, parsed into `T`.
/// Anything else is the contract's 415, 413 or 400.
#[derive(Debug)]
pub struct JsonBody<T>(pub T);

impl<T: DeserializeOwned> FromRequest<AppState> for JsonBody<T> {
    type Rejection = AppError;

    async fn from_request(request: Request, state: &AppState) -> Result<Self, AppError> {
        let json = request
            .headers()
            .get(CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.split(';').next())
            .is_some_and(|v| v.trim().eq_ignore_ascii_case("application/json"));
        if !json {
            return Err(AppError::new(
                ErrorCode::UnsupportedMediaType,
                "this route takes Content-Type: application/json",
            ));
        }
        let bytes = body_bytes(request, state.config().body_limit).await?;
        serde_json::from_slice(&bytes).map(JsonBody).map_err(|e| {
            // The only numbers these bodies carry besides ids are placements; a number past
            // f64's range is an infinite coordinate.
            let code = if e.to_string().starts_with("number out of range") {
                ErrorCode::InvalidTransform
            } else {
                ErrorCode::MalformedJson
            };
            AppError::new(
                code,
                format!("the body is not the JSON this route takes: {e}"),
            )
        })
    }
}

/// The body of `request`, refused with 413 as soon as its declared or streamed size passes
/// `limit`.
pub async fn body_bytes(request: Request, limit: usize) -> Result<axum::body::Bytes, AppError> {
    let too_large = || {
        AppError::new(
            ErrorCode::TooLarge,
            format!("the body is over the limit of {limit} bytes"),
        )
    };
    let declared = request
        .headers()
        .get(CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > limit as u64) {
        return Err(too_large());
    }
    axum::body::to_bytes(request.into_body(), limit)
        .await
        .map_err(|_| too_large())
}

/// Query parameters parsed into `T`; a bad one is the contract's 400 `bad_query`.
#[derive(Debug)]
pub struct QueryParams<T>(pub T);

impl<T: DeserializeOwned, S: Send + Sync> FromRequestParts<S> for QueryParams<T> {
    type Rejection = AppError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, AppError> {
        axum::extract::Query::<T>::from_request_parts(parts, state)
            .await
            .map(|q| QueryParams(q.0))
            .map_err(|e| AppError::new(ErrorCode::BadQuery, e.body_text()))
    }
}

/// A page size from an optional `limit`: the default when absent, refused past the largest.
pub fn page_size(limit: Option<usize>) -> Result<usize, AppError> {
    match limit {
        None => Ok(DEFAULT_PAGE),
        Some(n) if (1..=MAX_PAGE).contains(&n) => Ok(n),
        Some(n) => Err(AppError::new(
            ErrorCode::BadQuery,
            format!("limit {n} is not between 1 and {MAX_PAGE}"),
        )),
    }
}
