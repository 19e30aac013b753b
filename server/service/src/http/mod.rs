//! The HTTP API: routes, shared state, auth and the OpenAPI document.
//!
//! Paths are stable (clients and tests depend on them): `/v1/scenes`, `/v1/scenes/{id}`,
//! `/v1/sessions`, `/v1/sessions/{id}`, `/v1/sessions/{id}/stream` (WebSocket),
//! `/v1/render`, `/healthz`, `/readyz`, `/metrics`, `/openapi.json`; the browser viewer at `/`
//! (its files under `/viewer/`).

pub mod asyncapi;
pub mod health;
pub mod render;
pub mod scenes;
pub mod sessions;
pub mod stream;
pub mod viewer;

use super::error::ApiError;
use super::ids;
use super::render_loop::Command;
use super::scenes::SceneRegistry;
use super::sessions::SessionRegistry;
use super::sync::lock;
use axum::extract::{Request, State};
use axum::http::{header, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::Router;
use lightcast_protocol::Limits;
use std::collections::HashMap;
use std::sync::{mpsc, Arc, Mutex};
use std::time::{Duration, Instant};
use utoipa::OpenApi;

/// How long a WebSocket ticket stays valid.
pub const TICKET_TTL: Duration = Duration::from_secs(60);

/// Longest request URI (path and query); beyond, 414. Every path and query of the API is far
/// shorter; a long one only costs parsing and echoing.
pub const MAX_URI_BYTES: usize = 8 << 10;
/// Most request headers; beyond, 431.
pub const MAX_HEADERS: usize = 100;
/// Longest name or procedural spec a scene keeps (every `GET /v1/scenes` returns them all).
pub const MAX_NAME_BYTES: u32 = 256;

/// A WebSocket ticket: opens one session's stream once, for the token that asked for it.
struct Ticket {
    session: String,
    owner: Option<String>,
    expires: Instant,
}

/// Everything the handlers share.
pub struct AppState {
    pub scenes: Arc<SceneRegistry>,
    /// Scenes shared with the other replicas (`--scene-store`), if any.
    pub scene_store: Option<crate::service::scene_store::SceneStore>,
    pub sessions: Arc<SessionRegistry>,
    pub render_tx: mpsc::Sender<Command>,
    pub limits: Limits,
    /// Bearer tokens; empty means auth is off.
    pub tokens: Vec<String>,
    pub adapter: String,
    pub adapter_is_cpu: bool,
    pub allow_cpu_adapter: bool,
    /// What requests get for the render fields they leave out.
    pub defaults: crate::service::defaults::Defaults,
    pub timing_source: String,
    /// The encoder of `h264` streams.
    pub video_encoder: crate::service::video::EncoderKind,
    pub max_texture: u32,
    /// The GPU's wgpu instance, for the live-object gauges of `/metrics`.
    pub gpu_instance: wgpu::Instance,
    pub build: String,
    pub shutdown: tokio::sync::watch::Receiver<bool>,
    /// Permits for glTF loads running at once; see [`scenes::load_upload`].
    pub loads: Arc<tokio::sync::Semaphore>,
    /// Places for uploads in flight and queued one-shot renders, globally and per token.
    pub admission: crate::service::budget::Admission,
    tickets: Mutex<HashMap<String, Ticket>>,
}

/// glTF uploads decoded at once; more wait. Each may take up to its limits in memory.
const CONCURRENT_LOADS: usize = 2;

impl AppState {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        scenes: Arc<SceneRegistry>,
        scene_store: Option<crate::service::scene_store::SceneStore>,
        sessions: Arc<SessionRegistry>,
        render_tx: mpsc::Sender<Command>,
        limits: Limits,
        tokens: Vec<String>,
        gpu: &crate::gpu::GpuContext,
        allow_cpu_adapter: bool,
        defaults: crate::service::defaults::Defaults,
        timing_source: String,
        video_encoder: crate::service::video::EncoderKind,
        shutdown: tokio::sync::watch::Receiver<bool>,
    ) -> Self {
        let admission = crate::service::budget::Admission::new(&limits);
        Self {
            scenes,
            scene_store,
            sessions,
            render_tx,
            limits,
            tokens,
            adapter: crate::gpu::context::AdapterSummary(&gpu.info).to_string(),
            adapter_is_cpu: gpu.info.device_type == wgpu::DeviceType::Cpu,
            allow_cpu_adapter,
            defaults,
            timing_source,
            video_encoder,
            max_texture: gpu.device.limits().max_texture_dimension_2d,
            gpu_instance: gpu.instance.clone(),
            build: build_id(),
            shutdown,
            loads: Arc::new(tokio::sync::Semaphore::new(CONCURRENT_LOADS)),
            admission,
            tickets: Mutex::new(HashMap::new()),
        }
    }

    /// The GI methods' descriptions with this server's limits, and its defaults as their
    /// parameters' defaults.
    pub fn gi_methods(&self) -> Vec<lightcast_protocol::GiMethodInfo> {
        let defaults = serde_json::to_value(&self.defaults.info.render.gi).unwrap_or_default();
        let mut methods = crate::gi::describe_all(&self.limits);
        for p in methods.iter_mut().flat_map(|m| &mut m.parameters) {
            if let Some(v) = defaults.get(&p.name) {
                p.default = v.clone();
            }
        }
        methods
    }

    pub fn auth_enabled(&self) -> bool {
        !self.tokens.is_empty()
    }

    /// Wakes the render loop (after a session was created or changed).
    pub fn wake(&self) {
        let _ = self.render_tx.send(Command::Wake);
    }

    /// Whether the render loop thread still runs (its end drops the receiving side, so a wake
    /// cannot be sent), for `/readyz`.
    pub fn render_loop_alive(&self) -> bool {
        self.render_tx.send(Command::Wake).is_ok()
    }

    /// Issues a single-use ticket for `session`'s WebSocket.
    pub fn issue_ticket(&self, session: &str, owner: Option<String>) -> String {
        let ticket = ids::random_hex(16);
        let now = Instant::now();
        let mut tickets = lock(&self.tickets);
        tickets.retain(|_, t| t.expires > now);
        tickets.insert(
            ticket.clone(),
            Ticket {
                session: session.to_string(),
                owner,
                expires: now + TICKET_TTL,
            },
        );
        ticket
    }

    /// Consumes a ticket for `session`; returns the token it stands for.
    fn redeem_ticket(&self, ticket: &str, session: &str) -> Result<Option<String>, ApiError> {
        let mut tickets = lock(&self.tickets);
        match tickets.remove(ticket) {
            Some(t) if t.session == session && t.expires > Instant::now() => Ok(t.owner),
            _ => Err(ApiError::unauthorized(
                "the stream ticket is unknown, used or expired; ask for a new one with \
                 POST /v1/sessions/{id}/ticket",
            )),
        }
    }
}

/// `lightcast-server <version> (<git revision>)`.
pub fn build_id() -> String {
    format!(
        "lightcast-server {} ({})",
        env!("CARGO_PKG_VERSION"),
        option_env!("LIGHTCAST_GIT_REV").unwrap_or("unknown revision")
    )
}

/// The bearer token a request was made with (`None` when auth is off).
#[derive(Clone, Debug)]
pub struct Caller(pub Option<String>);

/// Ends a request that outlasts `--request-timeout-ms`, whether the client is slow to send its
/// body or the server to answer, with the JSON error every other refusal has.
async fn time_limit(State(state): State<Arc<AppState>>, request: Request, next: Next) -> Response {
    let limit_ms = state.limits.request_timeout_ms;
    match tokio::time::timeout(Duration::from_millis(limit_ms), next.run(request)).await {
        Ok(response) => response,
        Err(_) => ApiError::new(
            StatusCode::REQUEST_TIMEOUT,
            "request_timeout",
            format!("the request took longer than this server's limit of {limit_ms} ms"),
        )
        .into_response(),
    }
}

/// Checks the bearer token (or a stream ticket) when auth is on and records the caller.
async fn authenticate(
    State(state): State<Arc<AppState>>,
    mut request: Request,
    next: Next,
) -> Response {
    match caller(&state, &request) {
        Ok(c) => {
            request.extensions_mut().insert(c);
            next.run(request).await
        }
        Err(e) => e.into_response(),
    }
}

fn caller(state: &AppState, request: &Request) -> Result<Caller, ApiError> {
    if !state.auth_enabled() {
        return Ok(Caller(None));
    }
    if let Some(value) = request.headers().get(header::AUTHORIZATION) {
        let token = value
            .to_str()
            .ok()
            .and_then(|v| v.strip_prefix("Bearer "))
            .map(str::trim)
            .ok_or_else(|| {
                ApiError::unauthorized("the Authorization header must be 'Bearer TOKEN'")
            })?;
        return if state.tokens.iter().any(|t| ids::constant_time_eq(t, token)) {
            Ok(Caller(Some(token.to_string())))
        } else {
            Err(ApiError::unauthorized("unknown bearer token"))
        };
    }
    // Browsers cannot set headers on a WebSocket: its stream takes a ticket instead.
    let path = request.uri().path();
    let ticket = request
        .uri()
        .query()
        .and_then(|q| q.split('&').find_map(|kv| kv.strip_prefix("ticket=")));
    if let (Some(session), Some(ticket)) = (
        path.strip_prefix("/v1/sessions/")
            .and_then(|rest| rest.strip_suffix("/stream")),
        ticket,
    ) {
        // Another replica's session: say where it lives rather than that the ticket is unknown.
        state.sessions.check_here(session)?;
        return state.redeem_ticket(ticket, session).map(Caller);
    }
    Err(ApiError::unauthorized(
        "this server needs a bearer token: send 'Authorization: Bearer TOKEN'",
    ))
}

/// The header every response of a replica carries its name in (`--replica`).
pub const REPLICA_HEADER: &str = "lightcast-replica";

/// Names this replica on every response, so a client or an operator behind a proxy sees which
/// replica answered.
pub async fn name_replica(
    State(state): State<Arc<AppState>>,
    request: Request,
    next: Next,
) -> Response {
    let mut response = next.run(request).await;
    if let Some(value) = state
        .sessions
        .replica()
        .and_then(|r| axum::http::HeaderValue::from_str(r).ok())
    {
        response.headers_mut().insert(REPLICA_HEADER, value);
    }
    response
}

/// Refuses a request head over this server's limits with 414/431 and the JSON error body (hyper
/// itself answers only heads over twice as large, bare, as it cannot parse them; see
/// [`crate::service::listen::ConnectionLimits::max_header_bytes`]).
pub async fn check_head(
    State(state): State<Arc<AppState>>,
    request: Request,
    next: Next,
) -> Response {
    let uri = request.uri().to_string().len();
    if uri > MAX_URI_BYTES {
        return ApiError::new(
            StatusCode::URI_TOO_LONG,
            "uri_too_long",
            format!("the URI has {uri} bytes; this server's limit is {MAX_URI_BYTES}"),
        )
        .into_response();
    }
    let headers = request.headers();
    // As sent: "name: value\r\n" per header, after the request line.
    let head = uri
        + request.method().as_str().len()
        + headers
            .iter()
            .map(|(name, value)| name.as_str().len() + value.len() + 4)
            .sum::<usize>();
    let limit = state.limits.max_header_bytes;
    if headers.len() > MAX_HEADERS || head as u64 > limit {
        return ApiError::new(
            StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
            "headers_too_large",
            format!(
                "the request head has {} headers, {head} bytes; this server's limits are \
                 {MAX_HEADERS} headers, {limit} bytes",
                headers.len()
            ),
        )
        .into_response();
    }
    next.run(request).await
}

/// The most bytes a request's body may have, and the option that sets it: scene uploads (a
/// `.glb` or multipart body to `POST /v1/scenes`, a multipart one-shot render) take
/// `--max-upload-bytes`, every other body (JSON) `--max-message-bytes`.
pub fn body_limit(limits: &Limits, request: &Request) -> (u64, &'static str) {
    let path = request.uri().path();
    let upload = request.method() == axum::http::Method::POST
        && ((path == "/v1/scenes" && !scenes::is_json(request))
            || (path == "/v1/render" && scenes::is_multipart(request)));
    if upload {
        (limits.max_upload_bytes, "--max-upload-bytes")
    } else {
        (limits.max_message_bytes, "--max-message-bytes")
    }
}

/// 413 for a body over `limit` bytes.
pub fn too_large(limit: u64, flag: &str) -> ApiError {
    ApiError::new(
        StatusCode::PAYLOAD_TOO_LARGE,
        "too_large",
        format!("the body exceeds this server's limit of {limit} bytes ({flag})"),
    )
}

/// The body length a request's `Content-Length` declares, if it is a number.
fn declared_length(headers: &header::HeaderMap) -> Option<u64> {
    headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse().ok())
}

/// Refuses a body whose declared length is over its limit before reading any of it, so an
/// `Expect: 100-continue` client gets 413 at once instead of `100 Continue` (hyper sends that
/// only when a handler starts reading the body).
async fn check_declared_length(
    State(state): State<Arc<AppState>>,
    request: Request,
    next: Next,
) -> Response {
    let declared = declared_length(request.headers());
    let (limit, flag) = body_limit(&state.limits, &request);
    match declared {
        Some(length) if length > limit => too_large(limit, flag).into_response(),
        _ => next.run(request).await,
    }
}

/// Gives every error the JSON body `{"error", "field", "message"}`, also those axum and its
/// extractors answer with plain text (a path that is not UTF-8, a rejected extractor), and
/// closes the connection after an error to a request that carries a body.
async fn json_errors(request: Request, next: Next) -> Response {
    let headers = request.headers();
    let has_body = headers.contains_key(header::TRANSFER_ENCODING)
        || declared_length(headers).is_some_and(|length| length > 0);
    let mut response = as_json_error(next.run(request).await).await;
    let status = response.status();
    if has_body && (status.is_client_error() || status.is_server_error()) {
        // An error may be decided before the body is read (a 413 over the limit, a 400 from
        // the query of an upload). hyper then closes the connection after answering without
        // saying so, and a client that sends its next request on the kept-alive connection in
        // that moment loses it (CI saw `IncompleteMessage`). Saying so makes the client open
        // a new one.
        response.headers_mut().insert(
            header::CONNECTION,
            header::HeaderValue::from_static("close"),
        );
    }
    response
}

async fn as_json_error(response: Response) -> Response {
    let status = response.status();
    let is_json = response
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"application/json"));
    if !(status.is_client_error() || status.is_server_error()) || is_json {
        return response;
    }
    // What axum says is one short line; more than a few KiB is not one of its rejections.
    let text = axum::body::to_bytes(response.into_body(), 4096)
        .await
        .map(|b| String::from_utf8_lossy(&b).trim().to_string())
        .unwrap_or_default();
    let reason = status.canonical_reason().unwrap_or("error");
    let kind = match status {
        StatusCode::PAYLOAD_TOO_LARGE => "too_large".to_string(),
        StatusCode::INTERNAL_SERVER_ERROR => "internal".to_string(),
        _ => reason.to_ascii_lowercase().replace([' ', '-'], "_"),
    };
    let message = if text.is_empty() {
        reason.to_string()
    } else {
        text
    };
    ApiError::new(status, &kind, message).into_response()
}

async fn not_found() -> ApiError {
    ApiError::new(
        StatusCode::NOT_FOUND,
        "not_found",
        "no such endpoint; see /openapi.json",
    )
}

async fn method_not_allowed() -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        "method_not_allowed",
        "this endpoint does not take that method; see /openapi.json",
    )
}

#[derive(OpenApi)]
#[openapi(
    info(
        title = "lightcast",
        description = "Remote rendering with real-time global illumination: scenes, streaming \
                       sessions (WebSocket frames with per-stage GPU timings) and one-shot \
                       renders. When the server runs with tokens, every endpoint but /healthz, \
                       /readyz and the viewer (/ and /viewer/) needs 'Authorization: Bearer TOKEN'."
    ),
    paths(
        health::healthz,
        health::readyz,
        health::metrics,
        health::server_info,
        openapi_json,
        scenes::list,
        scenes::create,
        scenes::show,
        scenes::delete,
        sessions::list,
        sessions::create,
        sessions::show,
        sessions::update,
        sessions::delete,
        sessions::ticket,
        stream::stream,
        render::render,
        asyncapi::asyncapi_json,
        viewer::index,
        viewer::api_page,
        viewer::file,
    ),
    // RenderReport travels in a header, so no path names it: listed so its schema (with the
    // comparison's metrics) is documented.
    components(schemas(
        lightcast_protocol::ClientMessage,
        lightcast_protocol::ServerEvent,
        lightcast_protocol::RenderReport,
    ))
)]
pub struct ApiDoc;

/// The OpenAPI document of every endpoint.
#[utoipa::path(get, path = "/openapi.json", tag = "meta",
    responses((status = 200, description = "OpenAPI 3.1 document", content_type = "application/json")))]
pub async fn openapi_json() -> Response {
    match openapi_document() {
        Ok(json) => ([(header::CONTENT_TYPE, "application/json")], json).into_response(),
        Err(e) => ApiError::internal(e.to_string()).into_response(),
    }
}

/// The OpenAPI document: the protocol's types, with `render.gi`'s parameters, the method
/// names, the view names and the methods' server limits from the GI registry (the protocol
/// names none of them).
pub fn openapi_value() -> Result<serde_json::Value, serde_json::Error> {
    let mut doc = serde_json::to_value(ApiDoc::openapi())?;
    if let Some(serde_json::Value::Object(schema)) = doc.pointer_mut("/components/schemas/GiParams")
    {
        if let Some(serde_json::Value::Object(props)) = schema.get_mut("properties") {
            props.extend(crate::gi::params::openapi_properties());
        }
        // Every parameter is listed now; the server refuses any other field.
        schema.insert("additionalProperties".into(), false.into());
    }
    if let Some(serde_json::Value::Object(schema)) = doc.pointer_mut("/components/schemas/GiMethod")
    {
        let methods: Vec<String> = crate::gi::methods().map(|m| m.to_string()).collect();
        schema.insert("enum".into(), methods.into());
    }
    if let Some(serde_json::Value::Object(schema)) = doc.pointer_mut("/components/schemas/Limits") {
        // The flattened map of the methods' limits, field by field.
        schema.remove("additionalProperties");
        let limits = crate::gi::limits::all();
        if let Some(serde_json::Value::Object(props)) = schema.get_mut("properties") {
            for l in &limits {
                props.insert(
                    l.name.into(),
                    serde_json::json!({
                        "type": "integer",
                        "format": "int64",
                        "minimum": l.min,
                        "description": format!("{} (`{}`)", l.doc, l.flag),
                    }),
                );
            }
        }
        if let Some(serde_json::Value::Array(required)) = schema.get_mut("required") {
            required.extend(limits.iter().map(|l| l.name.into()));
        }
    }
    if let Some(serde_json::Value::Object(schema)) = doc.pointer_mut("/components/schemas/View") {
        let views: Vec<String> = crate::gi::views::names()
            .iter()
            .map(ToString::to_string)
            .collect();
        schema.insert("enum".into(), views.into());
    }
    Ok(doc)
}

/// The OpenAPI document, pretty-printed.
pub fn openapi_document() -> Result<String, serde_json::Error> {
    serde_json::to_string_pretty(&openapi_value()?)
}

/// The service's router.
pub fn router(state: Arc<AppState>) -> Router {
    let json_limit = state.limits.max_message_bytes as usize;
    let upload_limit = state.limits.max_upload_bytes as usize;
    let uploads = Router::new()
        .route("/v1/scenes", get(scenes::list).post(scenes::create))
        .route("/v1/render", post(render::render))
        .layer(axum::extract::DefaultBodyLimit::max(upload_limit));
    let api = Router::new()
        .route("/v1/server", get(health::server_info))
        .route("/v1/scenes/{id}", get(scenes::show).delete(scenes::delete))
        .route("/v1/sessions", get(sessions::list).post(sessions::create))
        .route(
            "/v1/sessions/{id}",
            get(sessions::show)
                .patch(sessions::update)
                .delete(sessions::delete),
        )
        .route("/v1/sessions/{id}/ticket", post(sessions::ticket))
        .route("/metrics", get(health::metrics))
        .route("/openapi.json", get(openapi_json))
        .route("/asyncapi.json", get(asyncapi::asyncapi_json))
        .layer(axum::extract::DefaultBodyLimit::max(json_limit))
        .merge(uploads)
        .layer(axum::middleware::from_fn_with_state(
            Arc::clone(&state),
            time_limit,
        ))
        // The WebSocket lives beyond any request timeout.
        .route("/v1/sessions/{id}/stream", get(stream::stream))
        .layer(axum::middleware::from_fn_with_state(
            Arc::clone(&state),
            authenticate,
        ));
    Router::new()
        .route("/healthz", get(health::healthz))
        .route("/readyz", get(health::readyz))
        .route("/", get(viewer::index))
        .route("/api", get(viewer::api_page))
        .route("/viewer/{*path}", get(viewer::file))
        .merge(api)
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(axum::middleware::from_fn_with_state(
            Arc::clone(&state),
            check_declared_length,
        ))
        .layer(axum::middleware::from_fn_with_state(
            Arc::clone(&state),
            check_head,
        ))
        .layer(axum::middleware::from_fn(json_errors))
        .layer(axum::middleware::from_fn_with_state(
            Arc::clone(&state),
            name_replica,
        ))
        .layer(tower_http::trace::TraceLayer::new_for_http())
        .with_state(state)
}

#[cfg(test)]
mod tests {
    /// `protocol/openapi.json` is the published copy of the API for client authors; it must
    /// match what the code serves.
    #[test]
    fn committed_openapi_document_is_current() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../protocol/openapi.json");
        let committed = std::fs::read_to_string(path).unwrap_or_default();
        let current = super::openapi_document().expect("document serialises");
        assert!(
            committed.trim_end() == current.trim_end(),
            "protocol/openapi.json is stale; regenerate it with \
             `cargo run -p lightcast-server -- openapi > protocol/openapi.json`"
        );
    }
}
