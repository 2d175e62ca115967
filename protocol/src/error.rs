//! The one error shape of every route: `{"error": {"code": "snake_case_code", "message":
//! "one line"}}`, with the status each code is sent with.

use serde::{Deserialize, Serialize};

/// An error response's body.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ErrorBody {
    /// What went wrong.
    pub error: ErrorDetail,
}

/// A machine-readable code and a one-line message for people.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ErrorDetail {
    /// The stable code clients branch on.
    pub code: ErrorCode,
    /// One line for people; it never carries internals.
    pub message: String,
}

impl ErrorBody {
    /// The body of an error with `code` and `message` (newlines become spaces).
    pub fn new(code: ErrorCode, message: impl Into<String>) -> Self {
        let message: String = message.into();
        Self {
            error: ErrorDetail {
                code,
                message: message.replace(['\n', '\r'], " "),
            },
        }
    }
}

/// Every error code of the service.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum ErrorCode {
    /// 400: the body is not the JSON the route takes.
    MalformedJson,
    /// 400: a query parameter is missing, not finite, or out of range.
    BadQuery,
    /// 400: not glTF, truncated, buffers out of range, or an external URI.
    BadGltf,
    /// 401: no token, or not a token this world issued.
    Unauthorized,
    /// 403: the object belongs to someone else.
    Forbidden,
    /// 403: the change would exceed the owner's quota.
    QuotaExceeded,
    /// 404: no such model, object, asset or route.
    NotFound,
    /// 405: the route exists, but not with this method.
    MethodNotAllowed,
    /// 409: the request conflicts with the world's state.
    Conflict,
    /// 413: the body is over the limit.
    TooLarge,
    /// 413: the model has more expanded triangles than the limit.
    TooManyTriangles,
    /// 413: a texture is over the side or pixel limit.
    TextureTooLarge,
    /// 413: the model has more instances than the limit.
    TooManyInstances,
    /// 415: the body's media type is not one the route takes.
    UnsupportedMediaType,
    /// 422: NaN or infinite numbers, a zero or negative scale, a non-unit rotation.
    InvalidTransform,
    /// 422: the object names a model the world does not have.
    UnknownModel,
    /// 429: too many requests.
    RateLimited,
    /// 503: the service cannot take more work now.
    Overloaded,
    /// 500: the server failed; the details are in its log.
    Internal,
}

impl ErrorCode {
    /// The HTTP status this code is sent with.
    pub fn status(self) -> u16 {
        match self {
            Self::MalformedJson | Self::BadQuery | Self::BadGltf => 400,
            Self::Unauthorized => 401,
            Self::Forbidden | Self::QuotaExceeded => 403,
            Self::NotFound => 404,
            Self::MethodNotAllowed => 405,
            Self::Conflict => 409,
            Self::TooLarge
            | Self::TooManyTriangles
            | Self::TextureTooLarge
            | Self::TooManyInstances => 413,
            Self::UnsupportedMediaType => 415,
            Self::InvalidTransform | Self::UnknownModel => 422,
            Self::RateLimited => 429,
            Self::Overloaded => 503,
            Self::Internal => 500,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_serialise_to_the_contract_shape() {
        let body = ErrorBody::new(ErrorCode::QuotaExceeded, "over\nquota");
        let json = serde_json::to_value(&body).expect("serialise");
        assert_eq!(
            json,
            serde_json::json!({"error": {"code": "quota_exceeded", "message": "over quota"}})
        );
        assert_eq!(ErrorCode::QuotaExceeded.status(), 403);
        let back: ErrorBody = serde_json::from_value(json).expect("parse");
        assert_eq!(back, body);
    }
}
