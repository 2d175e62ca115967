//! `POST /v1/models`, `GET /v1/models/{id}`, `GET /v1/models`.

use axum::extract::{Path, Request, State};
use axum::http::header::CONTENT_TYPE;
use axum::http::StatusCode;
use axum::Json;
use horizon_protocol::{ErrorBody, ErrorCode, ModelInfo, ModelLevelInfo, ModelPage};
use horizon_world::{ModelLevel, ModelRow};
use serde::Deserialize;
use utoipa::IntoParams;

use super::{body_bytes, page_size, QueryParams};
use crate::service::auth::Writer;
use crate::service::{AppError, AppResult, AppState};

/// The media types a model upload may have.
const MODEL_TYPES: &[&str] = &["model/gltf-binary", "model/gltf+json"];

/// Query of `POST /v1/models`.
#[derive(Debug, Deserialize, IntoParams)]
pub struct UploadQuery {
    /// A name for people (default: the first digits of the model's id).
    pub name: Option<String>,
}

/// Uploads a model: a GLB, or glTF JSON with its buffers embedded as data URIs. It is
/// validated, normalised, stored and described before the answer; the same bytes uploaded
/// again give the same model.
#[utoipa::path(post, path = "/v1/models", tag = "models",
    params(UploadQuery),
    request_body(content_type = "model/gltf-binary", description = "GLB bytes (or model/gltf+json)"),
    responses(
        (status = 201, description = "Stored", body = ModelInfo),
        (status = 200, description = "Those bytes were already stored", body = ModelInfo),
        (status = 400, description = "Not glTF, truncated, out-of-range buffers, an external URI", body = ErrorBody),
        (status = 401, description = "No or bad token", body = ErrorBody),
        (status = 403, description = "Over the byte quota", body = ErrorBody),
        (status = 413, description = "Over the body, triangle, texture or instance limit", body = ErrorBody),
        (status = 415, description = "Not model/gltf-binary or model/gltf+json", body = ErrorBody),
    ),
    security(("bearer" = [])))]
pub async fn upload(
    State(state): State<AppState>,
    Writer(user): Writer,
    QueryParams(query): QueryParams<UploadQuery>,
    request: Request,
) -> AppResult<(StatusCode, Json<ModelInfo>)> {
    let media = request
        .headers()
        .get(CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.split(';').next())
        .map(|v| v.trim().to_ascii_lowercase());
    if !media.as_deref().is_some_and(|m| MODEL_TYPES.contains(&m)) {
        return Err(AppError::new(
            ErrorCode::UnsupportedMediaType,
            "a model is uploaded as model/gltf-binary or model/gltf+json",
        ));
    }
    let name = query.name.unwrap_or_default();
    if name.len() > 256 || name.chars().any(char::is_control) {
        return Err(AppError::new(
            ErrorCode::BadQuery,
            "name must be at most 256 printable characters",
        ));
    }
    let bytes = body_bytes(request, state.config().body_limit).await?;
    let (row, created, levels) = state
        .blocking(move |world| {
            let name = if name.is_empty() {
                format!("model-{}", &horizon_world::content_hash(&bytes)[..12])
            } else {
                name
            };
            let (row, created) = world.upload_model(&bytes, &name, &user.name)?;
            let levels = world.levels_of(&row.asset)?;
            Ok::<_, horizon_world::WorldError>((row, created, levels))
        })
        .await?;
    if created {
        metrics::counter!("horizon_uploads_total").increment(1);
        metrics::counter!("horizon_upload_bytes_total").increment(row.bytes);
    }
    let status = if created {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    Ok((status, Json(info(&row, &levels))))
}

/// A model's metadata.
#[utoipa::path(get, path = "/v1/models/{id}", tag = "models",
    params(("id" = String, Path, description = "The model's id")),
    responses(
        (status = 200, description = "The model", body = ModelInfo),
        (status = 404, description = "No such model", body = ErrorBody),
    ))]
pub async fn get(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> AppResult<Json<ModelInfo>> {
    let (row, levels) = state
        .blocking(move |world| {
            let Some(row) = world.model(&id)? else {
                return Ok(Err(id));
            };
            let levels = world.levels_of(&row.asset)?;
            Ok::<_, horizon_world::WorldError>(Ok((row, levels)))
        })
        .await?
        .map_err(|id| AppError::new(ErrorCode::NotFound, format!("no model {id}")))?;
    Ok(Json(info(&row, &levels)))
}

/// Query of `GET /v1/models`.
#[derive(Debug, Deserialize, IntoParams)]
pub struct ModelsQuery {
    /// The id after which the page starts.
    pub after: Option<String>,
    /// Models per page (default 1,000, at most 10,000).
    pub limit: Option<usize>,
}

/// The models in id order, a page at a time.
#[utoipa::path(get, path = "/v1/models", tag = "models",
    params(ModelsQuery),
    responses(
        (status = 200, description = "A page", body = ModelPage),
        (status = 400, description = "A bad limit", body = ErrorBody),
    ))]
pub async fn list(
    State(state): State<AppState>,
    QueryParams(query): QueryParams<ModelsQuery>,
) -> AppResult<Json<ModelPage>> {
    let limit = page_size(query.limit)?;
    let rows = state
        .blocking(move |world| {
            let mut rows = world.models_page(query.after.as_deref(), limit + 1)?;
            let next = (rows.len() > limit).then(|| rows[limit - 1].id.clone());
            rows.truncate(limit);
            let mut out = Vec::with_capacity(rows.len());
            for row in rows {
                let levels = world.levels_of(&row.asset)?;
                out.push((row, levels));
            }
            Ok::<_, horizon_world::WorldError>((out, next))
        })
        .await?;
    let (rows, next) = rows;
    Ok(Json(ModelPage {
        models: rows.iter().map(|(row, levels)| info(row, levels)).collect(),
        next,
    }))
}

/// A model row and its levels of detail as the API shows them.
pub fn info(row: &ModelRow, levels: &[ModelLevel]) -> ModelInfo {
    let count = |key: &str| row.stats.get(key).and_then(|v| v.as_u64()).unwrap_or(0);
    ModelInfo {
        id: row.id.clone(),
        asset: row.asset.clone(),
        name: row.name.clone(),
        owner: row.owner.clone(),
        bytes: row.bytes,
        submeshes: count("submeshes"),
        instances: count("instances"),
        triangles_unique: count("triangles_unique"),
        triangles_expanded: count("triangles_expanded"),
        materials: count("materials"),
        textures: count("textures"),
        levels: levels
            .iter()
            .enumerate()
            .map(|(k, l)| ModelLevelInfo {
                level: k as u32,
                asset: l.asset.clone(),
                bytes: l.info.bytes,
                triangles: l.info.triangles,
                draw_calls: l.info.submeshes.max(1),
                error: l.info.error,
                texel_density: l.info.texel_density,
            })
            .collect(),
    }
}
