//! [`Client`]: the service's HTTP routes a viewer calls (`GET /v1/cut`), with every non-2xx
//! answer turned into a [`ClientError`] that carries the server's error body.

use horizon_protocol::{CutResponse, ErrorBody, ErrorCode, View};
use reqwest::header::ACCEPT_ENCODING;

/// A client of one server, at `base_url` (`http://host:port`).
#[derive(Clone, Debug)]
pub struct Client {
    base: String,
    http: reqwest::Client,
}

impl Client {
    /// A client of the server at `base_url` (`http://host:port`, a trailing slash or not).
    ///
    /// # Errors
    /// [`ClientError::Http`] if the HTTP client cannot be built, [`ClientError::BadUrl`] if
    /// `base_url` is not `http://...`.
    pub fn new(base_url: &str) -> Result<Self, ClientError> {
        let base = base_url.trim_end_matches('/').to_owned();
        if !base.starts_with("http://") && !base.starts_with("https://") {
            return Err(ClientError::BadUrl(base_url.to_owned()));
        }
        let http = reqwest::Client::builder().no_proxy().build()?;
        Ok(Self { base, http })
    }

    /// The server's base URL, without a trailing slash.
    pub fn base_url(&self) -> &str {
        &self.base
    }

    /// The HTTP client the routes are called with (shared by the asset cache).
    pub fn http(&self) -> &reqwest::Client {
        &self.http
    }

    /// `GET /v1/cut` at `view`.
    ///
    /// # Errors
    /// [`ClientError::Server`] for a non-2xx answer, [`ClientError::Http`] when the request
    /// fails, [`ClientError::Json`] when the body is not a cut.
    pub async fn cut(&self, view: &View) -> Result<CutResponse, ClientError> {
        let body = self.cut_body(view).await?;
        serde_json::from_str(&body).map_err(|e| ClientError::Json {
            what: "a cut",
            error: e,
        })
    }

    /// `GET /v1/cut` at `view`: the body exactly as the server sent it (`cut --json`).
    ///
    /// # Errors
    /// As [`Client::cut`], except that the body is not parsed.
    pub async fn cut_body(&self, view: &View) -> Result<String, ClientError> {
        let response = self
            .http
            .get(format!("{}/v1/cut", self.base))
            .query(&cut_query(view))
            .header(ACCEPT_ENCODING, "identity")
            .send()
            .await?;
        Ok(checked(response).await?.text().await?)
    }
}

/// The query of `GET /v1/cut` for `view`: every number as Rust prints it (the shortest
/// string that parses back to the same `f64`), absent budgets left out.
pub(crate) fn cut_query(view: &View) -> Vec<(&'static str, String)> {
    let [x, y, z] = view.eye;
    let mut query = vec![
        ("eye", format!("{x},{y},{z}")),
        ("min_solid_angle", view.min_solid_angle.to_string()),
        ("pixel_solid_angle", view.pixel_solid_angle.to_string()),
        ("max_pixel_error", view.max_pixel_error.to_string()),
        ("impostors", view.impostors.to_string()),
        ("instances", view.instances.to_string()),
    ];
    let b = &view.budgets;
    for (name, value) in [
        ("max_entries", b.max_entries),
        ("max_bytes", b.max_bytes),
        ("max_draw_calls", b.max_draw_calls),
        ("max_triangles", b.max_triangles),
    ] {
        if let Some(v) = value {
            query.push((name, v.to_string()));
        }
    }
    query
}

/// `response` if it is 2xx, otherwise its error as a [`ClientError`].
pub(crate) async fn checked(response: reqwest::Response) -> Result<reqwest::Response, ClientError> {
    let status = response.status();
    if status.is_success() {
        return Ok(response);
    }
    let text = response.text().await.unwrap_or_default();
    Err(match serde_json::from_str::<ErrorBody>(&text) {
        Ok(body) => ClientError::Server {
            status: status.as_u16(),
            body,
        },
        Err(_) => ClientError::Status {
            status: status.as_u16(),
            text: one_line(&text, 200),
        },
    })
}

/// `text` on one line, cut at about `max` characters.
pub(crate) fn one_line(text: &str, max: usize) -> String {
    let mut line: String = text
        .chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .take(max)
        .collect();
    if text.chars().count() > max {
        line.push_str("...");
    }
    line
}

/// An error code as the wire spells it (`bad_query`).
pub fn code_name(code: ErrorCode) -> String {
    serde_json::to_value(code)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_else(|| format!("{code:?}"))
}

/// Why a request to the service failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The server answered with the contract's error.
    #[error("the server answered {status} {}: {}", code_name(body.error.code), body.error.message)]
    Server {
        /// The HTTP status.
        status: u16,
        /// The server's error body: code and message.
        body: ErrorBody,
    },
    /// The server answered a non-2xx status without the contract's error body.
    #[error("the server answered {status}: {text}")]
    Status {
        /// The HTTP status.
        status: u16,
        /// The start of the body, on one line.
        text: String,
    },
    /// The request could not be made or its body not read.
    #[error("the request failed: {0}")]
    Http(#[from] reqwest::Error),
    /// The body is not what the route answers.
    #[error("the answer is not {what}: {error}")]
    Json {
        /// What was expected.
        what: &'static str,
        /// Why it did not parse.
        error: serde_json::Error,
    },
    /// The base URL is not an `http://` URL.
    #[error("{0:?} is not an http:// URL")]
    BadUrl(String),
}

impl ClientError {
    /// The server's error code, if the server sent one.
    pub fn code(&self) -> Option<ErrorCode> {
        match self {
            Self::Server { body, .. } => Some(body.error.code),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use horizon_protocol::Budgets;

    #[test]
    fn the_cut_query_round_trips_its_numbers_and_leaves_out_absent_budgets() {
        let view = View {
            eye: [1.5, -0.1, 1e20],
            min_solid_angle: 1e-3,
            pixel_solid_angle: 3.0e-7,
            max_pixel_error: 0.5,
            impostors: false,
            instances: false,
            budgets: Budgets {
                max_entries: Some(10),
                max_triangles: Some(7),
                ..Budgets::default()
            },
        };
        let query = cut_query(&view);
        let names: Vec<_> = query.iter().map(|(n, _)| *n).collect();
        assert_eq!(
            names,
            [
                "eye",
                "min_solid_angle",
                "pixel_solid_angle",
                "max_pixel_error",
                "impostors",
                "instances",
                "max_entries",
                "max_triangles"
            ]
        );
        let eye: Vec<f64> = query[0]
            .1
            .split(',')
            .map(|v| v.parse().expect("a number"))
            .collect();
        assert_eq!(eye, view.eye);
        assert_eq!(query[1].1.parse::<f64>().ok(), Some(1e-3));
        assert_eq!(query[2].1.parse::<f64>().ok(), Some(3.0e-7));
        assert_eq!(query[3].1.parse::<f64>().ok(), Some(0.5));
        assert_eq!(query[4].1, "false");
        assert_eq!(query[5].1, "false");
        assert_eq!(query[6].1, "10");
    }

    #[test]
    fn error_codes_print_as_the_wire_spells_them() {
        assert_eq!(code_name(ErrorCode::BadQuery), "bad_query");
        let e = ClientError::Server {
            status: 400,
            body: ErrorBody::new(ErrorCode::BadQuery, "eye is missing"),
        };
        assert_eq!(e.code(), Some(ErrorCode::BadQuery));
        assert_eq!(
            e.to_string(),
            "the server answered 400 bad_query: eye is missing"
        );
        assert!(Client::new("ws://x").is_err());
        assert_eq!(
            Client::new("http://127.0.0.1:1/")
                .expect("a client")
                .base_url(),
            "http://127.0.0.1:1"
        );
    }
}
