//! Liveness, readiness, metrics and server information.

use super::AppState;
use crate::service::video::STREAM_CODECS;
use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use lightcast_protocol::ServerInfo;
use serde_json::json;
use std::sync::Arc;

/// Liveness: the process answers.
#[utoipa::path(get, path = "/healthz", tag = "meta",
    responses((status = 200, description = "The process is alive")))]
pub async fn healthz() -> Json<serde_json::Value> {
    Json(json!({"status": "ok"}))
}

/// Readiness: a usable GPU adapter is open (a CPU adapter counts only with
/// `--allow-cpu-adapter`) and the server is not shutting down.
#[utoipa::path(get, path = "/readyz", tag = "meta",
    responses(
        (status = 200, description = "Ready to render"),
        (status = 503, description = "Not ready; `reason` says why", body = lightcast_protocol::ErrorBody)))]
pub async fn readyz(State(state): State<Arc<AppState>>) -> Response {
    let reason = if *state.shutdown.borrow() {
        Some("shutting down".to_string())
    } else if !state.render_loop_alive() {
        Some("the render loop has stopped; see the server log".to_string())
    } else if state.adapter_is_cpu && !state.allow_cpu_adapter {
        Some(format!(
            "adapter {} is a CPU (software) adapter; start with --allow-cpu-adapter to serve \
             with it anyway",
            state.adapter
        ))
    } else {
        None
    };
    match reason {
        None => Json(json!({"status": "ready", "adapter": state.adapter})).into_response(),
        Some(reason) => (
            StatusCode::SERVICE_UNAVAILABLE,
            Json(lightcast_protocol::ErrorBody {
                error: "not_ready".into(),
                field: None,
                message: reason,
            }),
        )
            .into_response(),
    }
}

/// Prometheus metrics: sessions, frames, drops, per-stage GPU time histograms, encode time,
/// bytes and errors by kind.
#[utoipa::path(get, path = "/metrics", tag = "meta",
    responses((status = 200, description = "Prometheus text format", content_type = "text/plain")))]
pub async fn metrics(State(state): State<Arc<AppState>>) -> Response {
    crate::service::metrics::record_gpu_resources(&state.gpu_instance);
    (
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        crate::service::metrics::handle().render(),
    )
        .into_response()
}

/// The build, the GPU adapter and the limits requests must stay within.
#[utoipa::path(get, path = "/v1/server", tag = "meta",
    responses((status = 200, body = ServerInfo)))]
pub async fn server_info(State(state): State<Arc<AppState>>) -> Json<ServerInfo> {
    Json(ServerInfo {
        build: state.build.clone(),
        adapter: state.adapter.clone(),
        timing_source: state.timing_source.clone(),
        auth: state.auth_enabled(),
        limits: state.limits.clone(),
        stages: crate::gi::stages::names()
            .iter()
            .map(|s| s.to_string())
            .collect(),
        gi_methods: state.gi_methods(),
        defaults: state.defaults.info.clone(),
        replica: state.sessions.replica().map(str::to_string),
        video: Some(lightcast_protocol::VideoInfo {
            codecs: STREAM_CODECS.to_vec(),
            encoder: state.video_encoder.name().to_string(),
            hardware: state.video_encoder.hardware(),
            auto_bits_per_pixel: lightcast_protocol::AUTO_BITS_PER_PIXEL,
            threads_1080p: crate::service::video::encoder_threads(1920, 1080),
        }),
    })
}
