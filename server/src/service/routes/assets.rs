//! `GET /assets/{hash}`: immutable, content-addressed blobs (models, aggregates, manifests).
//! The hash is the ETag and the name never changes meaning, so responses are cacheable for a
//! year; `If-None-Match` gives 304; `Range` gives 206 on the stored bytes (never compressed);
//! whole responses are compressed per `Accept-Encoding` by the service's middleware.

use axum::body::Body;
use axum::extract::{Path, State};
use axum::http::header::{
    ACCEPT_RANGES, CACHE_CONTROL, CONTENT_LENGTH, CONTENT_RANGE, CONTENT_TYPE, ETAG, IF_NONE_MATCH,
    RANGE,
};
use axum::http::{HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use horizon_protocol::{ErrorBody, ErrorCode};

use crate::service::{AppError, AppResult, AppState};

/// How long clients and caches may keep an asset: it never changes.
const IMMUTABLE: &str = "public, max-age=31536000, immutable";

/// An asset's bytes.
#[utoipa::path(get, path = "/assets/{hash}", tag = "assets",
    params(("hash" = String, Path, description = "The asset's content hash (BLAKE3, 64 hex digits)")),
    responses(
        (status = 200, description = "The asset", content_type = "application/octet-stream"),
        (status = 206, description = "The requested range of it"),
        (status = 304, description = "The client's copy is current"),
        (status = 404, description = "No such asset", body = ErrorBody),
        (status = 416, description = "The range is outside the asset"),
    ))]
pub async fn get(
    State(state): State<AppState>,
    Path(hash): Path<String>,
    headers: HeaderMap,
) -> AppResult<Response> {
    let not_found = || AppError::new(ErrorCode::NotFound, format!("no asset {hash}"));
    if !horizon_world::is_content_hash(&hash) {
        return Err(not_found());
    }
    let etag = format!("\"{hash}\"");
    let etag_value = HeaderValue::from_str(&etag).map_err(AppError::internal)?;
    let cached = headers
        .get(IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| t.trim() == etag || t.trim() == "*"));
    let bytes = {
        let hash = hash.clone();
        state.blocking(move |world| world.blob(&hash)).await?
    }
    .ok_or_else(not_found)?;
    let mut response = if cached {
        StatusCode::NOT_MODIFIED.into_response()
    } else {
        match headers.get(RANGE).and_then(|v| v.to_str().ok()) {
            Some(range) => partial(bytes, range),
            None => whole(bytes),
        }
    };
    let h = response.headers_mut();
    h.insert(ETAG, etag_value);
    h.insert(CACHE_CONTROL, HeaderValue::from_static(IMMUTABLE));
    h.insert(ACCEPT_RANGES, HeaderValue::from_static("bytes"));
    if response.status() == StatusCode::OK {
        metrics::counter!("horizon_asset_bytes_total").increment(
            response
                .headers()
                .get(CONTENT_LENGTH)
                .and_then(|v| v.to_str().ok())
                .and_then(|v| v.parse().ok())
                .unwrap_or(0),
        );
    }
    Ok(response)
}

/// The whole asset, typed by its first bytes.
fn whole(bytes: Vec<u8>) -> Response {
    let kind = media_type(&bytes);
    let len = bytes.len();
    (
        [
            (CONTENT_TYPE, HeaderValue::from_static(kind)),
            (CONTENT_LENGTH, HeaderValue::from(len)),
        ],
        Body::from(bytes),
    )
        .into_response()
}

/// One byte range of the asset (RFC 9110 section 14), or 416 if it lies outside.
fn partial(bytes: Vec<u8>, range: &str) -> Response {
    let len = bytes.len() as u64;
    let unsatisfiable = || {
        (
            StatusCode::RANGE_NOT_SATISFIABLE,
            [(CONTENT_RANGE, format!("bytes */{len}"))],
        )
            .into_response()
    };
    let ranges = match http_range_header::parse_range_header(range).and_then(|r| r.validate(len)) {
        Ok(r) => r,
        Err(_) => return unsatisfiable(),
    };
    // One range is served; a request for several gets the first (as a whole 206).
    let Some(r) = ranges.first() else {
        return unsatisfiable();
    };
    let (start, end) = (*r.start(), *r.end());
    let kind = media_type(&bytes);
    let body = bytes[start as usize..=end as usize].to_vec();
    (
        StatusCode::PARTIAL_CONTENT,
        [
            (CONTENT_TYPE, kind.to_owned()),
            (CONTENT_RANGE, format!("bytes {start}-{end}/{len}")),
            (CONTENT_LENGTH, body.len().to_string()),
        ],
        Body::from(body),
    )
        .into_response()
}

/// What a blob is, from its first bytes.
fn media_type(bytes: &[u8]) -> &'static str {
    if bytes.starts_with(b"glTF") {
        "model/gltf-binary"
    } else if bytes.first() == Some(&b'{') {
        "application/json"
    } else {
        "application/octet-stream"
    }
}
