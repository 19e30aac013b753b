//! `/v1/sessions`: create, read, steer and delete streaming sessions.

use super::{AppState, Caller, TICKET_TTL};
use crate::service::error::{from_value, parse_json, ApiError};
use crate::service::params::resolve_session;
use crate::service::sessions::Session;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use lightcast_protocol::{SessionCreated, SessionInfo, SessionParams, StreamTicket};
use serde_json::Value;
use std::sync::Arc;

/// RFC 7396 JSON merge patch: objects merge, `null` removes, anything else replaces.
pub fn merge_patch(target: &mut Value, patch: &Value) {
    let Value::Object(patch) = patch else {
        *target = patch.clone();
        return;
    };
    if !target.is_object() {
        *target = Value::Object(serde_json::Map::new());
    }
    if let Value::Object(map) = target {
        for (key, value) in patch {
            if value.is_null() {
                map.remove(key);
            } else {
                merge_patch(map.entry(key.clone()).or_insert(Value::Null), value);
            }
        }
    }
}

/// Applies a merge patch of [`SessionParams`] to a session, all or nothing.
pub async fn apply_patch(
    state: &AppState,
    session: &Session,
    patch: &Value,
    input_id: u64,
) -> Result<(), ApiError> {
    if !patch.is_object() {
        return Err(ApiError::bad_request(
            "malformed_json",
            "the patch must be a JSON object",
        ));
    }
    let mut merged =
        serde_json::to_value(session.params()).map_err(|e| ApiError::internal(e.to_string()))?;
    merge_patch(&mut merged, patch);
    // `light` and `lights` are two spellings of one state: the one a patch sets replaces the
    // other.
    for (set, other) in [("light", "lights"), ("lights", "light")] {
        if !patch["render"][set].is_null() {
            if let Some(render) = merged.get_mut("render").and_then(Value::as_object_mut) {
                render.remove(other);
            }
        }
    }
    // A `null` removed a field: it gets the server's default back.
    if let Value::Object(map) = &mut merged {
        let render = map
            .entry("render")
            .or_insert(Value::Object(Default::default()));
        state.defaults.fill_render(render)?;
    }
    let mut params: SessionParams = from_value(merged)?;
    // A patch that changes the playing animation (stops it, changes its speed) without
    // giving its time carries on from the time it reached.
    if let (Some(old), Some(new)) = (
        &session.params().render.animation,
        &mut params.render.animation,
    ) {
        if old.playing && old != new && old.name == new.name && old.time == new.time {
            if let Some(t) = session.animation_time(std::time::Instant::now()) {
                new.time = t;
            }
        }
    }
    // Camera and light messages keep the scene: only a change of scene looks it up (in the
    // scene store too, a file read per message otherwise).
    let current = session.scene();
    let entry = if current.id == params.render.scene {
        current
    } else {
        super::scenes::scene(state, &params.render.scene).await?
    };
    let resolved = resolve_session(&params, &entry, &state.limits, state.max_texture)?;
    session.apply(params, resolved, entry.lease(), input_id);
    state.wake();
    Ok(())
}

/// Lists the caller's sessions.
#[utoipa::path(get, path = "/v1/sessions", tag = "sessions",
    responses((status = 200, body = Vec<SessionInfo>)))]
pub async fn list(
    State(state): State<Arc<AppState>>,
    Extension(caller): Extension<Caller>,
) -> Json<Vec<SessionInfo>> {
    Json(
        state
            .sessions
            .list(caller.0.as_deref())
            .iter()
            .map(|s| s.info())
            .collect(),
    )
}

/// Creates a session (every field optional: `{}` streams the default scene). Frames flow once
/// its WebSocket (`stream`) is open; the returned ticket opens it without a bearer header.
#[utoipa::path(post, path = "/v1/sessions", tag = "sessions",
    request_body = SessionParams,
    responses(
        (status = 201, body = SessionCreated),
        (status = 400, description = "A parameter is invalid; `field` names it", body = lightcast_protocol::ErrorBody),
        (status = 429, description = "Too many sessions, for the server or the token", body = lightcast_protocol::ErrorBody)))]
pub async fn create(
    State(state): State<Arc<AppState>>,
    Extension(caller): Extension<Caller>,
    body: Result<Bytes, BytesRejection>,
) -> Result<(StatusCode, Json<SessionCreated>), ApiError> {
    let body = crate::service::error::body(body)?;
    let params: SessionParams = state.defaults.parse(&body)?;
    let entry = super::scenes::scene(&state, &params.render.scene).await?;
    let resolved = resolve_session(&params, &entry, &state.limits, state.max_texture)?;
    let session = Session::new(
        state.sessions.new_id(),
        caller.0.clone(),
        params,
        resolved,
        entry.lease(),
    );
    state.sessions.insert(Arc::clone(&session))?;
    tracing::info!(session = %session.id, scene = %entry.id, "session created");
    let ticket = state.issue_ticket(&session.id, caller.0);
    Ok((
        StatusCode::CREATED,
        Json(SessionCreated {
            session: session.info(),
            ticket: StreamTicket {
                ticket,
                expires_in_ms: TICKET_TTL.as_millis() as u64,
            },
        }),
    ))
}

/// Shows a session: parameters, counters and the last frame's stage times.
#[utoipa::path(get, path = "/v1/sessions/{id}", tag = "sessions",
    params(("id" = String, Path, description = "Session id")),
    responses((status = 200, body = SessionInfo), (status = 404, body = lightcast_protocol::ErrorBody), (status = 421, description = "The session lives on another replica (named in the Lightcast-Owner header)", body = lightcast_protocol::ErrorBody)))]
pub async fn show(
    State(state): State<Arc<AppState>>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<Json<SessionInfo>, ApiError> {
    Ok(Json(state.sessions.get(&id, caller.0.as_deref())?.info()))
}

/// Changes a session with a JSON merge patch of its parameters (RFC 7396): fields present
/// replace, `null` restores the default. All or nothing.
#[utoipa::path(patch, path = "/v1/sessions/{id}", tag = "sessions",
    params(("id" = String, Path, description = "Session id")),
    request_body(content = Object, description = "Merge patch of SessionParams", content_type = "application/merge-patch+json"),
    responses(
        (status = 200, body = SessionInfo),
        (status = 400, body = lightcast_protocol::ErrorBody),
        (status = 404, body = lightcast_protocol::ErrorBody), (status = 421, description = "The session lives on another replica (named in the Lightcast-Owner header)", body = lightcast_protocol::ErrorBody)))]
pub async fn update(
    State(state): State<Arc<AppState>>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
    body: Result<Bytes, BytesRejection>,
) -> Result<Json<SessionInfo>, ApiError> {
    let body = crate::service::error::body(body)?;
    let session = state.sessions.get(&id, caller.0.as_deref())?;
    let patch: Value = parse_json(&body)?;
    apply_patch(&state, &session, &patch, 0).await?;
    Ok(Json(session.info()))
}

/// Ends a session; its WebSocket gets a `closing` event and closes.
#[utoipa::path(delete, path = "/v1/sessions/{id}", tag = "sessions",
    params(("id" = String, Path, description = "Session id")),
    responses((status = 204, description = "Deleted"), (status = 404, body = lightcast_protocol::ErrorBody), (status = 421, description = "The session lives on another replica (named in the Lightcast-Owner header)", body = lightcast_protocol::ErrorBody)))]
pub async fn delete(
    State(state): State<Arc<AppState>>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    let session = state.sessions.get(&id, caller.0.as_deref())?;
    state.sessions.remove(&session.id);
    session.close("session deleted");
    Ok(StatusCode::NO_CONTENT)
}

/// A new single-use ticket (valid 60 s) that opens the session's WebSocket without a bearer
/// header: `GET /v1/sessions/{id}/stream?ticket=…`.
#[utoipa::path(post, path = "/v1/sessions/{id}/ticket", tag = "sessions",
    params(("id" = String, Path, description = "Session id")),
    responses((status = 200, body = StreamTicket), (status = 404, body = lightcast_protocol::ErrorBody), (status = 421, description = "The session lives on another replica (named in the Lightcast-Owner header)", body = lightcast_protocol::ErrorBody)))]
pub async fn ticket(
    State(state): State<Arc<AppState>>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<Json<StreamTicket>, ApiError> {
    let session = state.sessions.get(&id, caller.0.as_deref())?;
    Ok(Json(StreamTicket {
        ticket: state.issue_ticket(&session.id, caller.0),
        expires_in_ms: TICKET_TTL.as_millis() as u64,
    }))
}

#[cfg(test)]
mod tests {
    use super::merge_patch;
    use serde_json::json;

    #[test]
    fn merge_patch_follows_rfc_7396() {
        let mut doc = json!({"a": 1, "b": {"c": 2, "d": 3}, "e": [1, 2]});
        merge_patch(
            &mut doc,
            &json!({"a": null, "b": {"c": 5}, "e": [3], "f": {"g": 1}}),
        );
        assert_eq!(doc, json!({"b": {"c": 5, "d": 3}, "e": [3], "f": {"g": 1}}));
    }
}
