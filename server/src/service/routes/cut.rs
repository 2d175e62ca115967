//! `GET /v1/cut`: one cut at a view (`service::cut` plans it).

use axum::extract::State;
use axum::Json;
use horizon_protocol::{Budgets, CutResponse, ErrorBody, ErrorCode, View};
use horizon_protocol::{
    DEFAULT_MAX_PIXEL_ERROR, DEFAULT_MIN_SOLID_ANGLE, DEFAULT_PIXEL_SOLID_ANGLE,
};
use serde::Deserialize;
use utoipa::IntoParams;

use super::QueryParams;
use crate::service::{AppError, AppResult, AppState};

/// The query of `GET /v1/cut`.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
pub struct CutParams {
    /// The viewer's position: `x,y,z`.
    pub eye: String,
    /// The smallest solid angle shown as itself, steradians, in (0, 4 pi). Default 0.001.
    pub min_solid_angle: Option<f64>,
    /// The solid angle of one screen pixel. Default 3.0e-7.
    pub pixel_solid_angle: Option<f64>,
    /// The most geometric error an object's level of detail may show, pixels. Default 1; 0
    /// sends every object at full detail.
    pub max_pixel_error: Option<f64>,
    /// Whether the client draws impostors. Default true.
    pub impostors: Option<bool>,
    /// Whether a node of reused models may be sent as its objects' shared models, placed
    /// (an `instances` entry), where that costs less than its aggregate. Default true.
    pub instances: Option<bool>,
    /// The most entries (default 4,000).
    pub max_entries: Option<u64>,
    /// The most asset bytes.
    pub max_bytes: Option<u64>,
    /// The most draw calls.
    pub max_draw_calls: Option<u64>,
    /// The most triangles.
    pub max_triangles: Option<u64>,
}

impl CutParams {
    /// The view these parameters state, checked.
    pub fn view(&self) -> Result<View, AppError> {
        let bad = |m: String| AppError::new(ErrorCode::BadQuery, m);
        let eye: Vec<f64> = self
            .eye
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| bad(format!("eye {:?} is not x,y,z: {e}", self.eye)))?;
        let [x, y, z] = eye[..] else {
            return Err(bad(format!("eye {:?} is not x,y,z", self.eye)));
        };
        let view = View {
            eye: [x, y, z],
            min_solid_angle: self.min_solid_angle.unwrap_or(DEFAULT_MIN_SOLID_ANGLE),
            pixel_solid_angle: self.pixel_solid_angle.unwrap_or(DEFAULT_PIXEL_SOLID_ANGLE),
            max_pixel_error: self.max_pixel_error.unwrap_or(DEFAULT_MAX_PIXEL_ERROR),
            impostors: self.impostors.unwrap_or(true),
            instances: self.instances.unwrap_or(true),
            budgets: Budgets {
                max_entries: self.max_entries,
                max_bytes: self.max_bytes,
                max_draw_calls: self.max_draw_calls,
                max_triangles: self.max_triangles,
            },
        };
        view.check().map_err(bad)?;
        Ok(view)
    }
}

/// One cut: every object of the generation it names, counted exactly once, as itself where
/// it subtends at least `min_solid_angle` and through one aggregate elsewhere, largest solid
/// angle first under the budgets.
#[utoipa::path(get, path = "/v1/cut", tag = "cuts",
    params(CutParams),
    responses(
        (status = 200, description = "The cut", body = CutResponse),
        (status = 400, description = "A parameter missing, not finite or out of range", body = ErrorBody),
    ))]
pub async fn get(
    State(state): State<AppState>,
    QueryParams(params): QueryParams<CutParams>,
) -> AppResult<Json<CutResponse>> {
    let view = params.view()?;
    let cut = state.cut(view).await?;
    metrics::counter!("horizon_cuts_total").increment(1);
    Ok(Json(cut))
}
