//! Objects: `POST /v1/objects`, `GET /v1/objects`, `GET`, `PATCH` and `DELETE
//! /v1/objects/{id}`, `POST /v1/objects/batch`.

use std::collections::HashMap;

use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::Json;
use glam::{Affine3A, Quat, Vec3};
use horizon_protocol::{
    BatchOp, BatchRequest, BatchResponse, Created, Deleted, ErrorBody, ErrorCode, NewObject,
    ObjectInfo, ObjectPage, ObjectPatch, Scale,
};
use horizon_world::{Change, ObjectRow, World, WorldError};
use serde::Deserialize;
use utoipa::IntoParams;

use super::{page_size, JsonBody, QueryParams};
use crate::service::auth::Writer;
use crate::service::{AppError, AppResult, AppState};

/// The most operations one batch may hold.
pub const MAX_BATCH: usize = 10_000;

/// How far a rotation's length may be from 1 and still count as a unit quaternion.
const UNIT_TOLERANCE: f32 = 1e-3;

/// Places a model in the world.
#[utoipa::path(post, path = "/v1/objects", tag = "objects",
    request_body = NewObject,
    responses(
        (status = 201, description = "Placed", body = Created),
        (status = 400, description = "Malformed JSON", body = ErrorBody),
        (status = 401, description = "No or bad token", body = ErrorBody),
        (status = 403, description = "Over the object quota", body = ErrorBody),
        (status = 415, description = "Not application/json", body = ErrorBody),
        (status = 422, description = "An invalid transform or an unknown model", body = ErrorBody),
    ),
    security(("bearer" = [])))]
pub async fn create(
    State(state): State<AppState>,
    Writer(user): Writer,
    JsonBody(object): JsonBody<NewObject>,
) -> AppResult<(StatusCode, Json<Created>)> {
    let transform = placement(object.translation, object.rotation, object.scale)?;
    let applied = state
        .blocking(move |world| {
            world.apply(
                Some(&user.name),
                &[Change::Create {
                    model: object.model,
                    transform,
                }],
            )
        })
        .await?;
    let a = applied
        .first()
        .ok_or_else(|| AppError::internal("a placement applied nothing"))?;
    metrics::counter!("horizon_mutations_total", "op" => "create").increment(1);
    Ok((
        StatusCode::CREATED,
        Json(Created {
            id: a.object,
            generation: a.generation,
        }),
    ))
}

/// Query of `GET /v1/objects`.
#[derive(Debug, Deserialize, IntoParams)]
pub struct ObjectsQuery {
    /// The id after which the page starts.
    pub after: Option<u64>,
    /// Objects per page (default 1,000, at most 10,000).
    pub limit: Option<usize>,
    /// Only this user's objects.
    pub owner: Option<String>,
}

/// The objects in id order, a page at a time.
#[utoipa::path(get, path = "/v1/objects", tag = "objects",
    params(ObjectsQuery),
    responses(
        (status = 200, description = "A page", body = ObjectPage),
        (status = 400, description = "A bad query", body = ErrorBody),
    ))]
pub async fn list(
    State(state): State<AppState>,
    QueryParams(query): QueryParams<ObjectsQuery>,
) -> AppResult<Json<ObjectPage>> {
    let limit = page_size(query.limit)?;
    let (rows, ids) = state
        .blocking(move |world| {
            let rows = world.objects_page(query.after, limit + 1, query.owner.as_deref())?;
            let ids = model_ids(world, &rows)?;
            Ok((rows, ids))
        })
        .await?;
    let next = (rows.len() > limit).then(|| rows[limit - 1].id);
    Ok(Json(ObjectPage {
        objects: rows.iter().take(limit).map(|r| info(r, &ids)).collect(),
        next,
    }))
}

/// One object.
#[utoipa::path(get, path = "/v1/objects/{id}", tag = "objects",
    params(("id" = u64, Path, description = "The object's id")),
    responses(
        (status = 200, description = "The object", body = ObjectInfo),
        (status = 404, description = "No such object", body = ErrorBody),
    ))]
pub async fn get(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> AppResult<Json<ObjectInfo>> {
    let id = object_id(&id)?;
    let (row, ids) = state
        .blocking(move |world| {
            let row = world
                .object(id)?
                .ok_or_else(|| WorldError::NotFound(format!("no object {id}")))?;
            let ids = model_ids(world, std::slice::from_ref(&row))?;
            Ok((row, ids))
        })
        .await?;
    Ok(Json(info(&row, &ids)))
}

/// Moves one of the caller's objects: the parts of its placement the body names change.
#[utoipa::path(patch, path = "/v1/objects/{id}", tag = "objects",
    params(("id" = u64, Path, description = "The object's id")),
    request_body = ObjectPatch,
    responses(
        (status = 200, description = "Moved", body = Created),
        (status = 401, description = "No or bad token", body = ErrorBody),
        (status = 403, description = "Another user's object", body = ErrorBody),
        (status = 404, description = "No such object", body = ErrorBody),
        (status = 422, description = "An invalid transform", body = ErrorBody),
    ),
    security(("bearer" = [])))]
pub async fn patch(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Writer(user): Writer,
    JsonBody(patch): JsonBody<ObjectPatch>,
) -> AppResult<Json<Created>> {
    let id = object_id(&id)?;
    let applied = state
        .blocking(move |world| {
            let row = world
                .object(id)?
                .ok_or_else(|| WorldError::NotFound(format!("no object {id}")))?;
            let transform =
                patched(&row, &patch).map_err(|e| WorldError::InvalidTransform(e.message))?;
            world.apply(Some(&user.name), &[Change::Move { id, transform }])
        })
        .await?;
    let a = applied
        .first()
        .ok_or_else(|| AppError::internal("a move applied nothing"))?;
    metrics::counter!("horizon_mutations_total", "op" => "move").increment(1);
    Ok(Json(Created {
        id: a.object,
        generation: a.generation,
    }))
}

/// Deletes one of the caller's objects.
#[utoipa::path(delete, path = "/v1/objects/{id}", tag = "objects",
    params(("id" = u64, Path, description = "The object's id")),
    responses(
        (status = 200, description = "Deleted", body = Deleted),
        (status = 401, description = "No or bad token", body = ErrorBody),
        (status = 403, description = "Another user's object", body = ErrorBody),
        (status = 404, description = "No such object", body = ErrorBody),
    ),
    security(("bearer" = [])))]
pub async fn delete(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Writer(user): Writer,
) -> AppResult<Json<Deleted>> {
    let id = object_id(&id)?;
    let applied = state
        .blocking(move |world| world.apply(Some(&user.name), &[Change::Delete { id }]))
        .await?;
    let a = applied
        .first()
        .ok_or_else(|| AppError::internal("a delete applied nothing"))?;
    metrics::counter!("horizon_mutations_total", "op" => "delete").increment(1);
    Ok(Json(Deleted {
        id: a.object,
        generation: a.generation,
    }))
}

/// Applies operations all or nothing, in order: if any is refused, none is applied.
#[utoipa::path(post, path = "/v1/objects/batch", tag = "objects",
    request_body = BatchRequest,
    responses(
        (status = 200, description = "Applied", body = BatchResponse),
        (status = 401, description = "No or bad token", body = ErrorBody),
        (status = 403, description = "Another user's object, or over quota", body = ErrorBody),
        (status = 404, description = "No such object", body = ErrorBody),
        (status = 413, description = "More than 10,000 operations", body = ErrorBody),
        (status = 422, description = "An invalid transform or an unknown model", body = ErrorBody),
    ),
    security(("bearer" = [])))]
pub async fn batch(
    State(state): State<AppState>,
    Writer(user): Writer,
    JsonBody(request): JsonBody<BatchRequest>,
) -> AppResult<Json<BatchResponse>> {
    if request.ops.len() > MAX_BATCH {
        return Err(AppError::new(
            ErrorCode::TooLarge,
            format!(
                "{} operations, over the limit of {MAX_BATCH}",
                request.ops.len()
            ),
        ));
    }
    // Placements are checked before anything is read or written.
    for op in &request.ops {
        if let BatchOp::Create(o) = op {
            placement(o.translation, o.rotation, o.scale)?;
        }
    }
    let count = request.ops.len() as u64;
    let applied = state
        .blocking(move |world| {
            // A move patches the object's placement as the batch has left it so far.
            let mut placed: HashMap<u64, ObjectRow> = HashMap::new();
            let mut changes = Vec::with_capacity(request.ops.len());
            for op in request.ops {
                changes.push(match op {
                    BatchOp::Create(o) => Change::Create {
                        model: o.model,
                        transform: placement(o.translation, o.rotation, o.scale)
                            .map_err(|e| WorldError::InvalidTransform(e.message))?,
                    },
                    BatchOp::Move {
                        id,
                        translation,
                        rotation,
                        scale,
                    } => {
                        let patch = ObjectPatch {
                            translation,
                            rotation,
                            scale,
                        };
                        let row = match placed.get(&id) {
                            Some(r) => r.clone(),
                            None => world
                                .object(id)?
                                .ok_or_else(|| WorldError::NotFound(format!("no object {id}")))?,
                        };
                        let transform = patched(&row, &patch)
                            .map_err(|e| WorldError::InvalidTransform(e.message))?;
                        placed.insert(id, ObjectRow { transform, ..row });
                        Change::Move { id, transform }
                    }
                    BatchOp::Delete { id } => Change::Delete { id },
                });
            }
            if changes.is_empty() {
                return Ok((world.status()?.generation, Vec::new()));
            }
            let applied = world.apply(Some(&user.name), &changes)?;
            let generation = applied.last().map_or(0, |a| a.generation);
            Ok((generation, applied.into_iter().map(|a| a.object).collect()))
        })
        .await?;
    metrics::counter!("horizon_mutations_total", "op" => "batch").increment(count);
    Ok(Json(BatchResponse {
        generation: applied.0,
        ids: applied.1,
    }))
}

/// An object id from a path, or the 404 of a path that names none.
fn object_id(text: &str) -> AppResult<u64> {
    text.parse()
        .map_err(|_| AppError::new(ErrorCode::NotFound, format!("no object {text:?}")))
}

/// A model-to-world transform from the wire's parts, checked: every number finite, the
/// rotation a unit quaternion, every scale factor positive.
pub fn placement(translation: [f32; 3], rotation: [f32; 4], scale: Scale) -> AppResult<Affine3A> {
    let invalid = |why: String| AppError::new(ErrorCode::InvalidTransform, why);
    let scale = scale.per_axis();
    if !translation
        .iter()
        .chain(&rotation)
        .chain(&scale)
        .all(|v| v.is_finite())
    {
        return Err(invalid(
            "a translation, rotation or scale is not a finite number".into(),
        ));
    }
    if scale.iter().any(|&s| s <= 0.0) {
        return Err(invalid(format!(
            "scale {scale:?} is not positive on every axis"
        )));
    }
    let q = Quat::from_array(rotation);
    let length = q.length();
    if (length - 1.0).abs() > UNIT_TOLERANCE {
        return Err(invalid(format!(
            "rotation {rotation:?} is not a unit quaternion (length {length})"
        )));
    }
    Ok(Affine3A::from_scale_rotation_translation(
        Vec3::from_array(scale),
        q.normalize(),
        Vec3::from_array(translation),
    ))
}

/// `row`'s placement with the parts `patch` names replaced.
fn patched(row: &ObjectRow, patch: &ObjectPatch) -> AppResult<Affine3A> {
    let (scale, rotation, translation) = row.transform.to_scale_rotation_translation();
    placement(
        patch.translation.unwrap_or(translation.to_array()),
        patch.rotation.unwrap_or(rotation.to_array()),
        patch.scale.unwrap_or(Scale::PerAxis(scale.to_array())),
    )
}

/// The ids of the models the rows place, by model number.
fn model_ids(world: &World, rows: &[ObjectRow]) -> Result<HashMap<u64, String>, WorldError> {
    let mut ids = HashMap::new();
    for row in rows {
        if let std::collections::hash_map::Entry::Vacant(e) = ids.entry(row.model) {
            e.insert(world.models().row(row.model)?.id);
        }
    }
    Ok(ids)
}

/// An object row as the API shows it.
fn info(row: &ObjectRow, ids: &HashMap<u64, String>) -> ObjectInfo {
    let (scale, rotation, translation) = row.transform.to_scale_rotation_translation();
    ObjectInfo {
        id: row.id,
        model: ids.get(&row.model).cloned().unwrap_or_default(),
        owner: row.owner.clone(),
        translation: translation.to_array(),
        rotation: rotation.to_array(),
        scale: scale.to_array(),
        generation: row.generation,
    }
}
