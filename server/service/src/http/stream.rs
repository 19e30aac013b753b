//! `/v1/sessions/{id}/stream`: the session's WebSocket. Binary frames out (see
//! `lightcast_protocol::frame`), JSON control messages in, JSON events out.

use super::sessions::apply_patch;
use super::{AppState, Caller};
use crate::service::error::{from_value, parse_object, ApiError};
use crate::service::sessions::{unix_us, Session};
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{CloseFrame, Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::response::Response;
use axum::Extension;
use lightcast_protocol::{ClientMessage, ErrorBody, FrameHeader, ServerEvent};
use serde_json::json;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A client that takes longer than this to accept one message is disconnected.
const SEND_TIMEOUT: Duration = Duration::from_secs(10);

/// Token bucket for control messages: `rate` per second, bursts of twice that.
struct RateLimit {
    rate: f64,
    tokens: f64,
    last: Instant,
}

impl RateLimit {
    fn new(rate: u32) -> Self {
        Self {
            rate: f64::from(rate),
            tokens: 2.0 * f64::from(rate),
            last: Instant::now(),
        }
    }

    fn allow(&mut self) -> bool {
        let now = Instant::now();
        let refill = now.duration_since(self.last).as_secs_f64() * self.rate;
        self.tokens = (self.tokens + refill).min(2.0 * self.rate);
        self.last = now;
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

/// Opens the session's WebSocket (one per session at a time). Authenticate with the bearer
/// header or `?ticket=` from `POST /v1/sessions` or `/v1/sessions/{id}/ticket`.
#[utoipa::path(get, path = "/v1/sessions/{id}/stream", tag = "sessions",
    params(
        ("id" = String, Path, description = "Session id"),
        ("ticket" = Option<String>, Query, description = "Single-use ticket, for clients that cannot set headers")),
    responses(
        (status = 101, description = "WebSocket: binary frames (FrameHeader + image) and JSON ServerEvent text out; JSON ClientMessage text in"),
        (status = 404, body = ErrorBody),
        (status = 421, description = "The session lives on another replica (named in the Lightcast-Owner header)", body = ErrorBody),
        (status = 409, description = "A stream is already attached", body = ErrorBody),
        (status = 426, description = "Not a WebSocket request", body = ErrorBody)))]
pub async fn stream(
    State(state): State<Arc<AppState>>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
    upgrade: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    let session = state.sessions.get(&id, caller.0.as_deref())?;
    let upgrade = upgrade.map_err(|e| {
        ApiError::new(
            StatusCode::UPGRADE_REQUIRED,
            "websocket_required",
            format!("{}: open this path as a WebSocket", e.body_text()),
        )
    })?;
    if !session.attach() {
        return Err(ApiError::conflict(
            "this session already has a stream attached",
        ));
    }
    let failed = Arc::clone(&session);
    let max = state.limits.max_message_bytes as usize;
    Ok(upgrade
        .max_message_size(max)
        .max_frame_size(max)
        .on_failed_upgrade(move |_| failed.detach())
        .on_upgrade(move |socket| async move {
            state.wake();
            run(socket, &state, &session).await;
            session.detach();
        }))
}

async fn send(socket: &mut WebSocket, message: Message) -> bool {
    matches!(
        tokio::time::timeout(SEND_TIMEOUT, socket.send(message)).await,
        Ok(Ok(()))
    )
}

async fn send_event(socket: &mut WebSocket, event: &ServerEvent) -> bool {
    match serde_json::to_string(event) {
        Ok(text) => send(socket, Message::Text(text.into())).await,
        Err(_) => false,
    }
}

fn error_event(e: ApiError) -> ServerEvent {
    metrics::counter!(crate::service::metrics::ERRORS, "kind" => e.body.error.clone()).increment(1);
    ServerEvent::Error { error: e.body }
}

async fn run(mut socket: WebSocket, state: &AppState, session: &Arc<Session>) {
    let mut events = session.events.subscribe();
    let mut closed = session.closed();
    let mut shutdown = state.shutdown.clone();
    // A session ended (DELETE) or a shutdown begun between the lookup and the attach has set
    // its value already, which `changed()` would not report.
    if closed.borrow().is_some() {
        closed.mark_changed();
    }
    if *shutdown.borrow() {
        shutdown.mark_changed();
    }
    let mut limit = RateLimit::new(state.limits.max_messages_per_second);
    // Frames sent and not yet acknowledged: an `ack` for one of them is flow control the server
    // asked for, so it spends no token (at 240 fps the acks alone would exceed the default
    // 120 messages per second); acks beyond the frames sent are ordinary messages.
    let mut unacked: u64 = 0;
    // Browsers and WebSocket libraries answer pings by themselves, so a client that is still
    // there is heard from at least every `silence / 3` even when it sends nothing of its own.
    let silence = Duration::from_secs(state.limits.stream_silence_secs);
    let mut pings = tokio::time::interval_at((Instant::now() + silence / 3).into(), silence / 3);
    pings.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut last_heard = Instant::now();
    let hello = ServerEvent::Hello {
        session: Box::new(session.info()),
        codecs: crate::service::video::STREAM_CODECS.to_vec(),
        video_encoder: Some(state.video_encoder.name().to_string()),
    };
    if !send_event(&mut socket, &hello).await {
        return;
    }
    let reason = loop {
        tokio::select! {
            mut frame = session.slot.take() => {
                FrameHeader::patch_send_time(&mut frame, unix_us());
                let len = frame.len();
                if !send(&mut socket, Message::Binary(frame.into())).await {
                    session.in_flight.fetch_sub(1, Ordering::Relaxed);
                    return;
                }
                session.record_sent(len);
                unacked += 1;
            }
            incoming = socket.recv() => {
                last_heard = Instant::now();
                let rate_limited = || error_event(ApiError::too_many(
                    "rate_limited",
                    format!(
                        "more than {} messages per second; message ignored",
                        state.limits.max_messages_per_second
                    ),
                ));
                let reply = match incoming {
                    None | Some(Ok(Message::Close(_))) => return,
                    Some(Err(e)) => {
                        if let Some(frame) = refusal_close(e, state.limits.max_message_bytes) {
                            let _ = send(&mut socket, Message::Close(Some(frame))).await;
                        }
                        return;
                    }
                    Some(Ok(Message::Text(text))) => {
                        let owed_ack = unacked > 0 && is_ack(text.as_bytes());
                        if owed_ack {
                            unacked -= 1;
                        }
                        if owed_ack || limit.allow() {
                            handle(state, session, text.as_bytes()).await
                        } else {
                            Some(rate_limited())
                        }
                    }
                    // Refused, but each costs its reply: held to the same rate as text.
                    Some(Ok(Message::Binary(_))) if !limit.allow() => Some(rate_limited()),
                    Some(Ok(Message::Binary(_))) => Some(error_event(ApiError::bad_request(
                        "binary_not_accepted",
                        "control messages are JSON text; binary messages are ignored",
                    ))),
                    Some(Ok(_)) => None,
                };
                if let Some(event) = reply {
                    if !send_event(&mut socket, &event).await {
                        return;
                    }
                }
            }
            event = events.recv() => {
                match event {
                    Ok(event) => {
                        if !send_event(&mut socket, &event).await {
                            return;
                        }
                    }
                    Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => {}
                    Err(tokio::sync::broadcast::error::RecvError::Closed) => return,
                }
            }
            _ = pings.tick() => {
                if last_heard.elapsed() >= silence {
                    break format!(
                        "nothing heard from the client for {} s, not even a pong",
                        silence.as_secs()
                    );
                }
                if !send(&mut socket, Message::Ping(Default::default())).await {
                    return;
                }
            }
            _ = closed.changed() => {
                break closed.borrow().clone().unwrap_or_else(|| "closed".into());
            }
            _ = shutdown.changed() => {
                break "server shutting down".to_string();
            }
        }
    };
    let _ = send_event(
        &mut socket,
        &ServerEvent::Closing {
            reason: reason.clone(),
        },
    )
    .await;
    let _ = send(
        &mut socket,
        Message::Close(Some(CloseFrame {
            code: axum::extract::ws::close_code::AWAY,
            reason: reason.into(),
        })),
    )
    .await;
}

/// The close frame that tells a client why its message ended the stream (RFC 6455 §7.4.1):
/// 1009 for a message over `max_bytes`, 1007 for text that is not UTF-8, 1002 for another
/// protocol violation; `None` where the connection itself failed and nothing can be sent.
fn refusal_close(error: axum::Error, max_bytes: u64) -> Option<CloseFrame> {
    use axum::extract::ws::close_code;
    use tungstenite::error::{CapacityError, Error};
    let (code, reason) = match error.into_inner().downcast::<Error>().ok().map(|e| *e)? {
        Error::Capacity(CapacityError::MessageTooLong { size, .. }) => (
            close_code::SIZE,
            format!("a message of {size} bytes is over this server's limit of {max_bytes} (--max-message-bytes)"),
        ),
        Error::Capacity(e) => (close_code::SIZE, e.to_string()),
        Error::Utf8(e) => (close_code::INVALID, format!("a text message is not UTF-8: {e}")),
        Error::Protocol(e) => (close_code::PROTOCOL, e.to_string()),
        _ => return None,
    };
    // A close frame's reason has at most 123 bytes.
    let mut cut = reason.len().min(123);
    while !reason.is_char_boundary(cut) {
        cut -= 1;
    }
    Some(CloseFrame {
        code,
        reason: reason[..cut].to_string().into(),
    })
}

/// Whether a control message is an `ack` (a cheap look at its `type` only; `handle` still
/// validates the whole message).
fn is_ack(text: &[u8]) -> bool {
    #[derive(serde::Deserialize)]
    struct Tag<'a> {
        #[serde(borrow, rename = "type")]
        kind: Option<&'a str>,
    }
    serde_json::from_slice::<Tag>(text).is_ok_and(|t| t.kind == Some("ack"))
}

/// A field of a control message named as the HTTP API names it: a camera or light message's
/// `camera`/`light`/`lights` sets the session's `render.camera`/`render.light`/`render.lights`.
fn session_path(path: &str) -> String {
    let top = path.split(['.', '[']).next().unwrap_or_default();
    if top == "camera" || top == "light" || top == "lights" {
        format!("render.{path}")
    } else {
        path.to_string()
    }
}

/// `e`, a refusal of control message `raw`, naming the field at fault. serde reports a value
/// refused inside an internally tagged enum (every [`ClientMessage`]) without its path, so the
/// key at fault is the one whose absence makes the message parse or go missing; inside a
/// camera or light, the path is that of the value's own type.
fn message_error(raw: &serde_json::Value, e: ApiError) -> ApiError {
    if let Some(field) = &e.body.field {
        return ApiError::field(session_path(field), strip_field(&e));
    }
    let Some(object) = raw.as_object() else {
        return e;
    };
    let culprit = object.keys().filter(|k| *k != "type").find(|key| {
        let mut without = object.clone();
        without.remove(*key);
        match from_value::<ClientMessage>(serde_json::Value::Object(without)) {
            Ok(_) => true,
            Err(other) => other
                .body
                .message
                .contains(&format!("missing field `{key}`")),
        }
    });
    let Some(key) = culprit else {
        return e;
    };
    let inner = match key.as_str() {
        "camera" => from_value::<lightcast_protocol::Camera>(object[key].clone()).err(),
        "light" => from_value::<lightcast_protocol::Light>(object[key].clone()).err(),
        "lights" => from_value::<Vec<lightcast_protocol::Light>>(object[key].clone()).err(),
        _ => None,
    };
    match inner
        .as_ref()
        .and_then(|i| Some((i.body.field.as_ref()?, strip_field(i))))
    {
        Some((field, message)) => ApiError::field(session_path(&format!("{key}.{field}")), message),
        None => ApiError::field(session_path(key), e.body.message),
    }
}

/// An error's message without the `field: ` in front of it.
fn strip_field(e: &ApiError) -> String {
    let message = &e.body.message;
    e.body
        .field
        .as_ref()
        .and_then(|f| message.strip_prefix(&format!("{f}: ")))
        .unwrap_or(message)
        .to_string()
}

/// Handles one control message; returns the event to answer with, if any.
async fn handle(state: &AppState, session: &Session, text: &[u8]) -> Option<ServerEvent> {
    let raw: serde_json::Value = match parse_object(text, "a control message") {
        Ok(v) => v,
        Err(e) => return Some(error_event(message_error(&serde_json::Value::Null, e))),
    };
    let message: ClientMessage = match from_value(raw.clone()) {
        Ok(m) => m,
        Err(e) => return Some(error_event(message_error(&raw, e))),
    };
    // serde lets a message without fields of its own (`pause`) carry any others; refuse those
    // as every other message's are, so `{"type": "pause", "session": …}` cannot look as if it
    // acted on another session.
    if let (Some(sent), Ok(serde_json::Value::Object(known))) =
        (raw.as_object(), serde_json::to_value(&message))
    {
        if let Some(extra) = sent.keys().find(|k| !known.contains_key(*k)) {
            return Some(error_event(ApiError::field(extra.clone(), "unknown field")));
        }
    }
    // Camera and light go through the session's strict parameter path as they were sent, so
    // a misspelt field inside them is named (`render.camera.zoom`) rather than dropped.
    let result = match message {
        ClientMessage::Camera { input_id, .. } => {
            apply_patch(
                state,
                session,
                &json!({"render": {"camera": raw["camera"]}}),
                input_id,
            )
            .await
        }
        ClientMessage::Light {
            index: None,
            input_id,
            ..
        } => {
            apply_patch(
                state,
                session,
                &json!({"render": {"light": raw["light"]}}),
                input_id,
            )
            .await
        }
        ClientMessage::Light {
            light,
            index: Some(index),
            input_id,
        } => {
            // The lights the session renders now (its own, or its scene's), one replaced.
            let params = session.params();
            let lights =
                crate::service::params::lights(&params.render, &session.scene(), &state.limits);
            match lights {
                Ok(mut lights) if (index as usize) < lights.len() => {
                    lights[index as usize] = light;
                    apply_patch(
                        state,
                        session,
                        &json!({"render": {"lights": lights}}),
                        input_id,
                    )
                    .await
                }
                Ok(lights) => Err(ApiError::field(
                    "index",
                    format!(
                        "{index} is not a light of this session (it has {})",
                        lights.len()
                    ),
                )),
                Err(e) => Err(e),
            }
        }
        ClientMessage::Lights { input_id, .. } => {
            apply_patch(
                state,
                session,
                &json!({"render": {"lights": raw["lights"]}}),
                input_id,
            )
            .await
        }
        ClientMessage::Nodes { nodes, input_id } => {
            let entry = session.scene();
            // The message's own entries first, so an error names them (`nodes[2].scale`).
            match crate::service::params::poses(&nodes, &entry) {
                Err(e) => Err(e),
                Ok(_) => {
                    let mut merged = session.params().render.nodes;
                    merged.retain(|kept| nodes.iter().all(|n| n.node != kept.node));
                    // An entry without fields puts its node back: nothing left to keep.
                    merged.extend(nodes.into_iter().filter(|n| {
                        n.translation.is_some() || n.rotation.is_some() || n.scale.is_some()
                    }));
                    apply_patch(
                        state,
                        session,
                        &json!({"render": {"nodes": merged}}),
                        input_id,
                    )
                    .await
                }
            }
        }
        ClientMessage::Animation {
            name,
            time,
            playing,
            speed,
            input_id,
        } => {
            // Another animation (or the first) starts from its beginning, playing, unless the
            // message says otherwise; the one playing keeps what the message leaves out.
            let same = session
                .params()
                .render
                .animation
                .is_some_and(|a| a.name == name);
            let mut patch = serde_json::Map::new();
            patch.insert("name".into(), json!(name));
            for (field, given, fresh) in [
                ("time", time.map(|t| json!(t)), json!(0.0)),
                ("playing", playing.map(|p| json!(p)), json!(true)),
                ("speed", speed.map(|s| json!(s)), json!(1.0)),
            ] {
                match (given, same) {
                    (Some(v), _) => {
                        patch.insert(field.into(), v);
                    }
                    (None, false) => {
                        patch.insert(field.into(), fresh);
                    }
                    (None, true) => {}
                }
            }
            apply_patch(
                state,
                session,
                &json!({"render": {"animation": patch}}),
                input_id,
            )
            .await
        }
        ClientMessage::Update { patch, input_id } => {
            apply_patch(state, session, &patch, input_id).await
        }
        ClientMessage::Pause => {
            session.set_paused(true);
            Ok(())
        }
        ClientMessage::Resume => {
            session.set_paused(false);
            state.wake();
            Ok(())
        }
        ClientMessage::Still => {
            session.request_still();
            state.wake();
            Ok(())
        }
        ClientMessage::Pick { x, y, nonce } => session
            .request_pick(crate::service::sessions::PickRequest { x, y, nonce })
            .map(|()| state.wake()),
        ClientMessage::Keyframe => {
            session.request_keyframe();
            Ok(())
        }
        ClientMessage::Ack { .. } => {
            session.record_ack();
            Ok(())
        }
        ClientMessage::Ping { nonce } => return Some(ServerEvent::Pong { nonce }),
    };
    result.err().map(error_event)
}
