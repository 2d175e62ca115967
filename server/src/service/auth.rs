//! Bearer tokens: writes need one, reads are public. A token is looked up by its hash, the only
//! form the world stores (`horizon token create` prints the token itself once).

use axum::extract::FromRequestParts;
use axum::http::header::AUTHORIZATION;
use axum::http::request::Parts;
use horizon_protocol::ErrorCode;
use horizon_world::User;

use super::{AppError, AppState};

/// The user a request's bearer token belongs to.
#[derive(Clone, Debug)]
pub struct Writer(pub User);

impl FromRequestParts<AppState> for Writer {
    type Rejection = AppError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, AppError> {
        let unauthorized = |why: &str| AppError::new(ErrorCode::Unauthorized, why);
        let header = parts
            .headers
            .get(AUTHORIZATION)
            .ok_or_else(|| unauthorized("this route needs 'Authorization: Bearer TOKEN'"))?;
        let token = header
            .to_str()
            .ok()
            .and_then(|h| h.strip_prefix("Bearer "))
            .map(str::trim)
            .filter(|t| !t.is_empty() && t.len() <= 256)
            .ok_or_else(|| unauthorized("the Authorization header is not 'Bearer TOKEN'"))?
            .to_owned();
        let user = state
            .blocking(move |world| world.user_of_token(&token))
            .await?
            .ok_or_else(|| unauthorized("the token is not one this world issued"))?;
        Ok(Writer(user))
    }
}
