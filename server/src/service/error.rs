//! The API's error type: an HTTP status plus the JSON body clients see.

use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use lightcast_protocol::ErrorBody;

/// An error answered to a client. `field` names the request field at fault.
#[derive(Clone, Debug)]
pub struct ApiError {
    pub status: StatusCode,
    pub body: ErrorBody,
}

impl ApiError {
    pub fn new(status: StatusCode, kind: &str, message: impl Into<String>) -> Self {
        Self {
            status,
            body: ErrorBody {
                error: kind.to_string(),
                field: None,
                message: message.into(),
            },
        }
    }

    /// 400 `invalid_field`: the value of `field` is unusable.
    pub fn field(field: impl Into<String>, message: impl Into<String>) -> Self {
        let field = field.into();
        let message = format!("{field}: {}", message.into());
        let mut e = Self::new(StatusCode::BAD_REQUEST, "invalid_field", message);
        e.body.field = Some(field);
        e
    }

    pub fn bad_request(kind: &str, message: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, kind, message)
    }

    pub fn not_found(what: &str, id: &str) -> Self {
        Self::new(
            StatusCode::NOT_FOUND,
            "not_found",
            format!("no {what} with id '{id}'"),
        )
    }

    pub fn conflict(message: impl Into<String>) -> Self {
        Self::new(StatusCode::CONFLICT, "conflict", message)
    }

    pub fn unauthorized(message: impl Into<String>) -> Self {
        Self::new(StatusCode::UNAUTHORIZED, "unauthorized", message)
    }

    pub fn forbidden(message: impl Into<String>) -> Self {
        Self::new(StatusCode::FORBIDDEN, "forbidden", message)
    }

    pub fn too_many(kind: &str, message: impl Into<String>) -> Self {
        Self::new(StatusCode::TOO_MANY_REQUESTS, kind, message)
    }

    pub fn unavailable(message: impl Into<String>) -> Self {
        Self::new(StatusCode::SERVICE_UNAVAILABLE, "unavailable", message)
    }

    pub fn internal(message: impl Into<String>) -> Self {
        Self::new(StatusCode::INTERNAL_SERVER_ERROR, "internal", message)
    }

    /// Prefixes the field path (`gi.rsm_size` inside `render` becomes `render.gi.rsm_size`).
    pub fn within(mut self, parent: &str) -> Self {
        if let Some(field) = &self.body.field {
            let full = format!("{parent}.{field}");
            self.body.message = self.body.message.replacen(field.as_str(), &full, 1);
            self.body.field = Some(full);
        }
        self
    }

    /// The error kind, for the `lightcast_errors_total` metric.
    pub fn kind(&self) -> &str {
        &self.body.error
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        metrics::counter!(crate::service::metrics::ERRORS, "kind" => self.body.error.clone())
            .increment(1);
        (self.status, axum::Json(self.body)).into_response()
    }
}

/// Parses JSON into `T`, naming the field at fault (`render.gi.rsm_size`) in the error.
/// Unknown fields are refused (the protocol types themselves tolerate them, for clients).
pub fn parse_json<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let value = strict(&mut de)?;
    de.end()
        .map_err(|e| ApiError::bad_request("malformed_json", e.to_string()))?;
    Ok(value)
}

/// Converts an already-parsed JSON value into `T`, as strictly as [`parse_json`].
pub fn from_value<T: serde::de::DeserializeOwned>(value: serde_json::Value) -> Result<T, ApiError> {
    strict(value)
}

fn strict<'de, D, T>(de: D) -> Result<T, ApiError>
where
    D: serde::Deserializer<'de>,
    D::Error: std::fmt::Display,
    T: serde::Deserialize<'de>,
{
    let mut unknown: Option<String> = None;
    let mut track = serde_path_to_error::Track::new();
    let parsed = serde_ignored::deserialize(
        serde_path_to_error::Deserializer::new(de, &mut track),
        |path| {
            unknown.get_or_insert_with(|| {
                // serde_ignored marks `Option` levels with `?`; the request has no such level.
                path.to_string().replace(".?", "").replace("?.", "")
            });
        },
    );
    match (parsed, unknown) {
        (Err(e), _) => Err(json_error(serde_path_to_error::Error::new(track.path(), e))),
        (Ok(_), Some(field)) => Err(ApiError::field(field, "unknown field")),
        (Ok(v), None) => Ok(v),
    }
}

fn json_error<E: std::fmt::Display>(e: serde_path_to_error::Error<E>) -> ApiError {
    let mut path = e.path().to_string();
    let inner = e.inner().to_string();
    // Tagged enums report an unknown field without a path; the message names it.
    if path == "." {
        if let Some(name) = inner
            .strip_prefix("unknown field `")
            .and_then(|rest| rest.split('`').next())
        {
            path = name.to_string();
        }
    }
    // "." is the document itself; "?" a place the parser never reached (a syntax error).
    if path == "." || path.contains('?') {
        ApiError::bad_request("malformed_json", inner)
    } else {
        ApiError::field(path, inner)
    }
}

/// A request body, or 413/400 with a JSON error when it is too large or unreadable.
pub fn body(
    read: Result<axum::body::Bytes, axum::extract::rejection::BytesRejection>,
) -> Result<axum::body::Bytes, ApiError> {
    read.map_err(|e| {
        let status = e.status();
        if status == StatusCode::PAYLOAD_TOO_LARGE {
            ApiError::new(status, "too_large", e.body_text())
        } else {
            ApiError::bad_request("unreadable_body", e.body_text())
        }
    })
}
