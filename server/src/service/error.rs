//! [`AppError`]: every failure of a route as the contract's JSON error, `{"error": {"code",
//! "message"}}`, with its status. Internals are logged, never sent.

use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use horizon_protocol::{ErrorBody, ErrorCode};
use horizon_world::{BadModel, WorldError};

/// A route's failure: a code from the contract and a one-line message for the client.
#[derive(Debug)]
pub struct AppError {
    /// The contract's code (and so the status).
    pub code: ErrorCode,
    /// What the client reads.
    pub message: String,
}

impl AppError {
    /// An error with `code` and `message`.
    pub fn new(code: ErrorCode, message: impl Into<String>) -> Self {
        Self {
            code,
            message: message.into(),
        }
    }

    /// A failure of the server itself: logged in full, sent as a bare `internal`.
    pub fn internal(detail: impl std::fmt::Display) -> Self {
        tracing::error!(%detail, "internal error");
        Self::new(ErrorCode::Internal, "internal error; see the server's log")
    }
}

impl IntoResponse for AppError {
    fn into_response(self) -> Response {
        let status =
            StatusCode::from_u16(self.code.status()).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
        (status, Json(ErrorBody::new(self.code, self.message))).into_response()
    }
}

impl From<WorldError> for AppError {
    fn from(e: WorldError) -> Self {
        let message = e.to_string();
        match e {
            WorldError::BadModel { kind, .. } => Self::new(
                match kind {
                    BadModel::Malformed => ErrorCode::BadGltf,
                    BadModel::TooManyTriangles => ErrorCode::TooManyTriangles,
                    BadModel::TextureTooLarge => ErrorCode::TextureTooLarge,
                    BadModel::TooManyInstances => ErrorCode::TooManyInstances,
                    BadModel::TooLarge => ErrorCode::TooLarge,
                },
                message,
            ),
            WorldError::Model { .. } => Self::new(ErrorCode::BadGltf, message),
            WorldError::InvalidTransform(_) => Self::new(ErrorCode::InvalidTransform, message),
            WorldError::UnknownModel(_) => Self::new(ErrorCode::UnknownModel, message),
            WorldError::NotFound(_) => Self::new(ErrorCode::NotFound, message),
            WorldError::Forbidden(_) => Self::new(ErrorCode::Forbidden, message),
            WorldError::QuotaExceeded(_) => Self::new(ErrorCode::QuotaExceeded, message),
            other => Self::internal(other),
        }
    }
}

impl From<tokio::task::JoinError> for AppError {
    fn from(e: tokio::task::JoinError) -> Self {
        Self::internal(e)
    }
}

/// What a route returns.
pub type AppResult<T> = Result<T, AppError>;
