//! The API's error type: an HTTP status plus the JSON body clients see.

use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use lightcast_protocol::ErrorBody;

/// An error answered to a client. `field` names the request field at fault.
#[derive(Clone, Debug)]
pub struct ApiError {
    pub status: StatusCode,
    pub body: ErrorBody,
    /// The replica that holds what was asked for (421), sent as `Lightcast-Owner`.
    pub owner: Option<String>,
    /// Seconds after which the request may succeed, sent as `Retry-After`: set by
    /// [`ApiError::new`] on every 429, so none goes without it.
    pub retry_after: Option<u32>,
}

/// `Retry-After` of a 429: a hint, as nobody knows when a session ends or an upload finishes;
/// short enough that a client (or the proxy, trying another replica first) retries soon.
pub const RETRY_AFTER_SECS: u32 = 2;

/// The header of a 421 naming the replica that holds the session.
pub const OWNER_HEADER: &str = "lightcast-owner";

/// Most characters of a client's own value (an id, a name) repeated in an error message:
/// enough to recognise it, while a 100 KB id cannot make its error 100 KB.
pub const ECHO_CHARS: usize = 64;

/// Most characters of an error message or field path. Messages repeat parts of the request
/// (serde names an unknown variant or field verbatim); this bounds what any of them costs.
const MESSAGE_CHARS: usize = 1024;

/// `value` shortened to `max` characters, saying how long it was when it was cut.
fn shorten(value: String, max: usize) -> String {
    match value.char_indices().nth(max) {
        Some((cut, _)) => format!("{}… ({} bytes)", &value[..cut], value.len()),
        None => value,
    }
}

/// A client's value as an error message repeats it: at most [`ECHO_CHARS`] characters.
pub fn echo(value: &str) -> String {
    shorten(value.to_string(), ECHO_CHARS)
}

impl ApiError {
    pub fn new(status: StatusCode, kind: &str, message: impl Into<String>) -> Self {
        Self {
            status,
            body: ErrorBody {
                error: kind.to_string(),
                field: None,
                message: shorten(message.into(), MESSAGE_CHARS),
            },
            owner: None,
            retry_after: (status == StatusCode::TOO_MANY_REQUESTS).then_some(RETRY_AFTER_SECS),
        }
    }

    /// 421 `misdirected`: session `id` is genuine but lives on replica `owner`.
    pub fn misdirected(id: &str, owner: &str) -> Self {
        let mut e = Self::new(
            StatusCode::MISDIRECTED_REQUEST,
            "misdirected",
            format!(
                "session '{}' lives on replica '{owner}'; send its requests there (a proxy \
                 routes on the part of the id before the first '.')",
                echo(id)
            ),
        );
        e.owner = Some(owner.to_string());
        e
    }

    /// 400 `invalid_field`: the value of `field` is unusable.
    pub fn field(field: impl Into<String>, message: impl Into<String>) -> Self {
        let field = shorten(field.into(), ECHO_CHARS * 4);
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
            format!("no {what} with id '{}'", echo(id)),
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

    /// 429: a limit of the server or of the token is reached for now (with `Retry-After`).
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
        let mut response = (self.status, axum::Json(self.body)).into_response();
        if let Some(value) = self
            .owner
            .and_then(|o| axum::http::HeaderValue::from_str(&o).ok())
        {
            response.headers_mut().insert(OWNER_HEADER, value);
        }
        if let Some(seconds) = self.retry_after {
            response
                .headers_mut()
                .insert(axum::http::header::RETRY_AFTER, seconds.into());
        }
        response
    }
}

/// Parses a request body: a JSON object, into `T`, naming the field at fault
/// (`render.gi.rsm_size`) in the error. Unknown fields are refused (the protocol types
/// themselves tolerate them, for clients).
pub fn parse_json<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    parse_object(bytes, "the request body")
}

/// As [`parse_json`] for a document `what` names in its error ("a control message").
/// Anything but an object is refused: serde would otherwise fill a struct from an array by
/// position, and `[]` would pass as every field's default.
pub fn parse_object<T: serde::de::DeserializeOwned>(
    bytes: &[u8],
    what: &str,
) -> Result<T, ApiError> {
    if bytes.iter().find(|b| !b.is_ascii_whitespace()) != Some(&b'{') {
        let found = match serde_json::from_slice::<serde_json::Value>(bytes) {
            Err(e) => return Err(ApiError::bad_request("malformed_json", e.to_string())),
            Ok(serde_json::Value::Array(_)) => "an array",
            Ok(serde_json::Value::String(_)) => "a string",
            Ok(serde_json::Value::Number(_)) => "a number",
            Ok(serde_json::Value::Bool(_)) => "a boolean",
            Ok(_) => "null",
        };
        return Err(ApiError::bad_request(
            "malformed_json",
            format!("{what} must be a JSON object, not {found}"),
        ));
    }
    let mut de = serde_json::Deserializer::from_slice(bytes);
    serde_path_to_error::deserialize::<_, UniqueKeys>(&mut de).map_err(json_error)?;
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let value = strict(&mut de)?;
    de.end()
        .map_err(|e| ApiError::bad_request("malformed_json", e.to_string()))?;
    Ok(value)
}

/// A JSON document in which no object repeats a key. serde_json keeps the last of repeated
/// keys where a document is parsed into a `Value` first (merge patches, WebSocket messages),
/// and a struct refuses them at its parent's path; checking before either names the key and
/// treats every endpoint alike.
struct UniqueKeys;

impl<'de> serde::Deserialize<'de> for UniqueKeys {
    fn deserialize<D: serde::Deserializer<'de>>(de: D) -> Result<Self, D::Error> {
        de.deserialize_any(UniqueKeys)
    }
}

impl<'de> serde::de::Visitor<'de> for UniqueKeys {
    type Value = UniqueKeys;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("JSON")
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<Self, A::Error> {
        let mut seen = std::collections::HashSet::new();
        while let Some(key) = map.next_key::<String>()? {
            if seen.contains(&key) {
                return Err(serde::de::Error::custom(format!("duplicate field `{key}`")));
            }
            map.next_value::<UniqueKeys>()?;
            seen.insert(key);
        }
        Ok(self)
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Self, A::Error> {
        while seq.next_element::<UniqueKeys>()?.is_some() {}
        Ok(self)
    }

    fn visit_bool<E>(self, _: bool) -> Result<Self, E> {
        Ok(self)
    }

    fn visit_i64<E>(self, _: i64) -> Result<Self, E> {
        Ok(self)
    }

    fn visit_u64<E>(self, _: u64) -> Result<Self, E> {
        Ok(self)
    }

    fn visit_f64<E>(self, _: f64) -> Result<Self, E> {
        Ok(self)
    }

    fn visit_str<E>(self, _: &str) -> Result<Self, E> {
        Ok(self)
    }

    fn visit_unit<E>(self) -> Result<Self, E> {
        Ok(self)
    }
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
    // Tagged enums report an unknown field without a path, and a repeated key is found before
    // its value is entered, at its parent's path; the message names the key.
    let named = ["unknown field `", "duplicate field `"]
        .iter()
        .find_map(|prefix| {
            inner
                .strip_prefix(prefix)
                .and_then(|rest| rest.split('`').next())
        });
    match named {
        Some(name) if path == "." => path = name.to_string(),
        Some(name) if inner.starts_with("duplicate") => path = format!("{path}.{name}"),
        _ => {}
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

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::Value;

    #[test]
    fn only_objects_are_bodies() {
        for (body, found) in [
            ("[]", "an array"),
            (" [1, 2]", "an array"),
            ("null", "null"),
            ("\"{}\"", "a string"),
            ("7", "a number"),
        ] {
            let e = parse_json::<Value>(body.as_bytes()).expect_err(body);
            assert_eq!(e.body.error, "malformed_json", "{body}");
            assert_eq!(e.body.field, None, "{body}");
            assert!(e.body.message.contains(found), "{body}: {}", e.body.message);
        }
        let e = parse_json::<Value>(b"[oops").expect_err("not JSON");
        assert_eq!(e.body.error, "malformed_json");
        assert!(parse_json::<Value>(b" {\"a\": [1, {\"b\": 2}]} ").is_ok());
    }

    #[test]
    fn repeated_keys_are_named_by_their_full_path() {
        for (body, path) in [
            (r#"{"a": 1, "a": 2}"#, "a"),
            (r#"{"a": {"b": 1, "c": 2, "b": 3}}"#, "a.b"),
            (r#"{"a": [{"x": 1}, {"y": 1, "y": 2}]}"#, "a[1].y"),
        ] {
            let e = parse_json::<Value>(body.as_bytes()).expect_err(body);
            assert_eq!(e.body.field.as_deref(), Some(path), "{body}: {e:?}");
        }
    }

    #[test]
    fn what_a_client_sent_is_echoed_shortened() {
        let long = "é".repeat(10_000);
        let shown = echo(&long);
        assert!(shown.chars().count() < ECHO_CHARS + 20, "{shown}");
        assert!(shown.ends_with("(20000 bytes)"), "{shown}");
        assert_eq!(echo("short"), "short");
        let e = ApiError::field(long.clone(), long);
        assert!(e.body.message.len() < 4 * MESSAGE_CHARS);
        assert!(e
            .body
            .field
            .is_some_and(|f| f.chars().count() < 4 * ECHO_CHARS + 20));
    }

    #[test]
    fn every_429_carries_retry_after() {
        for e in [
            ApiError::too_many("too_many_sessions", "full"),
            ApiError::new(StatusCode::TOO_MANY_REQUESTS, "upload_quota", "quota"),
        ] {
            let response = e.into_response();
            assert_eq!(response.status(), StatusCode::TOO_MANY_REQUESTS);
            assert_eq!(
                response.headers()[axum::http::header::RETRY_AFTER],
                RETRY_AFTER_SECS.to_string()
            );
        }
        let other = ApiError::unavailable("stopping").into_response();
        assert!(other
            .headers()
            .get(axum::http::header::RETRY_AFTER)
            .is_none());
    }
}
