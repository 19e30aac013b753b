//! The AsyncAPI 3.0 document of a session's WebSocket (`GET /asyncapi.json`, committed as
//! `protocol/asyncapi.json`): what OpenAPI cannot say about `/v1/sessions/{id}/stream`.
//!
//! The message schemas are the OpenAPI document's own (`ClientMessage`, `ServerEvent` and what
//! they reference), copied under the same `#/components/schemas/` path so that their
//! references resolve unchanged, and marked as OpenAPI 3.1 schemas. Built by hand because no
//! maintained Rust crate generates AsyncAPI 3 from serde/utoipa types.

use super::ApiError;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use lightcast_protocol::frame::FRAME_VERSION;
use lightcast_protocol::API_VERSION;
use serde_json::{json, Value};

/// How the message schemas are written (AsyncAPI's `schemaFormat`).
const SCHEMA_FORMAT: &str = "application/vnd.oai.openapi+json;version=3.1.0";

/// The AsyncAPI document of a session's WebSocket.
pub fn asyncapi_value() -> Result<Value, serde_json::Error> {
    let openapi = super::openapi_value()?;
    let schemas = openapi
        .pointer("/components/schemas")
        .cloned()
        .unwrap_or_else(|| json!({}));
    let stages: Vec<String> = crate::gi::stages::all()
        .iter()
        .map(|s| format!("{} {}", s.index(), s.name()))
        .collect();
    let payload = |name: &str| {
        json!({
            "schemaFormat": SCHEMA_FORMAT,
            "schema": { "$ref": format!("#/components/schemas/{name}") },
        })
    };
    Ok(json!({
        "asyncapi": "3.0.0",
        "info": {
            "title": "lightcast session stream",
            "version": format!("{API_VERSION}"),
            "description": "The WebSocket of a streaming session (open it with \
                GET /v1/sessions/{id}/stream, see openapi.json): JSON control messages in, \
                JSON events and binary frames out. Messages are refused with an `error` event \
                (unknown types or fields, bad values, over the rate limit), never by closing \
                the stream.",
        },
        "defaultContentType": "application/json",
        "channels": {
            "stream": {
                "address": "/v1/sessions/{id}/stream",
                "title": "A session's stream",
                "description": "One per session; a second connection is refused with 409. \
                    Authenticate with 'Authorization: Bearer TOKEN' or a single-use `ticket` \
                    query parameter from POST /v1/sessions/{id}/ticket.",
                "parameters": { "id": { "description": "The session id." } },
                "messages": {
                    "control": {
                        "name": "ClientMessage",
                        "title": "Control message",
                        "summary": "Camera, light or parameter changes, pause, resume, still, ack, ping; a JSON text message tagged by `type`.",
                        "contentType": "application/json",
                        "payload": payload("ClientMessage"),
                    },
                    "event": {
                        "name": "ServerEvent",
                        "title": "Event",
                        "summary": "hello (first), updated, error, render_error, caches_pending, caches_ready, pong, closing; a JSON text message tagged by `type`.",
                        "contentType": "application/json",
                        "payload": payload("ServerEvent"),
                    },
                    "frame": {
                        "name": "Frame",
                        "title": "Frame",
                        "summary": "A binary message: a little-endian frame header, then the JPEG or PNG image.",
                        "description": format!(
                            "Header format version {FRAME_VERSION}: magic `LCFR`, version, header \
                             length (the image starts there), sequence number, input id, \
                             timestamps, size, codec, flags, per-stage GPU times as (stage index, \
                             ms) pairs, then the samples and relative error of progressive \
                             methods. The byte layout is in protocol/README.md ('Frame \
                             messages'); `FrameHeader::decode` (Rust) and \
                             client/web/js/frame.js decode it. Stage indices: {}.",
                            stages.join(", ")
                        ),
                        "contentType": "application/octet-stream",
                        "payload": { "type": "string", "format": "binary" },
                    },
                },
            },
        },
        "operations": {
            "receiveControl": {
                "action": "receive",
                "title": "The server receives control messages",
                "channel": { "$ref": "#/channels/stream" },
                "messages": [ { "$ref": "#/channels/stream/messages/control" } ],
            },
            "sendEvents": {
                "action": "send",
                "title": "The server sends events",
                "channel": { "$ref": "#/channels/stream" },
                "messages": [ { "$ref": "#/channels/stream/messages/event" } ],
            },
            "sendFrames": {
                "action": "send",
                "title": "The server sends frames",
                "channel": { "$ref": "#/channels/stream" },
                "messages": [ { "$ref": "#/channels/stream/messages/frame" } ],
            },
        },
        "components": { "schemas": schemas },
    }))
}

/// The AsyncAPI document, pretty-printed.
pub fn asyncapi_document() -> Result<String, serde_json::Error> {
    serde_json::to_string_pretty(&asyncapi_value()?)
}

/// The AsyncAPI 3.0 document of the session WebSocket.
#[utoipa::path(get, path = "/asyncapi.json", tag = "meta",
    responses((status = 200, description = "AsyncAPI 3.0 document of /v1/sessions/{id}/stream", content_type = "application/json")))]
pub async fn asyncapi_json() -> Response {
    match asyncapi_document() {
        Ok(json) => ([(header::CONTENT_TYPE, "application/json")], json).into_response(),
        Err(e) => ApiError::internal(e.to_string()).into_response(),
    }
}

#[cfg(test)]
mod tests {
    use serde_json::Value;

    /// Every `$ref` under `value`, as JSON pointers into the document.
    fn refs<'a>(value: &'a Value, out: &mut Vec<&'a str>) {
        match value {
            Value::Object(map) => {
                if let Some(Value::String(r)) = map.get("$ref") {
                    out.push(r);
                }
                map.values().for_each(|v| refs(v, out));
            }
            Value::Array(items) => items.iter().for_each(|v| refs(v, out)),
            _ => {}
        }
    }

    /// `protocol/asyncapi.json` is the published copy for client authors; it must match what
    /// the server serves (regenerate with `lightcast-server asyncapi > protocol/asyncapi.json`).
    #[test]
    fn committed_asyncapi_document_is_current() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../protocol/asyncapi.json");
        let committed = std::fs::read_to_string(path).unwrap_or_default();
        let current = super::asyncapi_document().expect("document serialises");
        assert!(
            committed.trim_end() == current.trim_end(),
            "protocol/asyncapi.json is stale: run `cargo run -p lightcast-server -- asyncapi > protocol/asyncapi.json`"
        );
    }

    /// Every reference resolves inside the document, and the messages the server actually
    /// parses and sends have schemas (the same types the WebSocket handler uses).
    #[test]
    fn every_reference_resolves_and_both_directions_are_described() {
        let doc = super::asyncapi_value().expect("document");
        let mut all = Vec::new();
        refs(&doc, &mut all);
        assert!(all.len() > 10, "{all:?}");
        for r in &all {
            let pointer = r.strip_prefix('#').expect("local reference");
            assert!(doc.pointer(pointer).is_some(), "{r} does not resolve");
        }
        for name in [
            "ClientMessage",
            "ServerEvent",
            "Camera",
            "Light",
            "ErrorBody",
        ] {
            assert!(
                doc.pointer(&format!("/components/schemas/{name}"))
                    .is_some(),
                "{name} missing"
            );
        }
        // The control schema lists every message type the server accepts.
        let control = doc
            .pointer("/components/schemas/ClientMessage")
            .expect("ClientMessage")
            .to_string();
        for kind in [
            "camera", "light", "update", "pause", "resume", "still", "ack", "ping",
        ] {
            assert!(control.contains(&format!("\"{kind}\"")), "{kind} missing");
        }
    }
}
