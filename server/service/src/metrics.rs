//! Prometheus metrics: names in one place, and the recorder behind `/metrics`.

use metrics_exporter_prometheus::{Matcher, PrometheusBuilder, PrometheusHandle};
use std::sync::OnceLock;

pub const SESSIONS: &str = "lightcast_sessions";
/// Sessions the server accepts at once (`--max-sessions`): with [`SESSIONS`], what an
/// autoscaler needs.
pub const SESSION_CAPACITY: &str = "lightcast_session_capacity";
pub const SCENES: &str = "lightcast_scenes";
pub const FRAMES_RENDERED: &str = "lightcast_frames_rendered_total";
pub const FRAMES_SENT: &str = "lightcast_frames_sent_total";
pub const FRAMES_DROPPED: &str = "lightcast_frames_dropped_total";
pub const FRAMES_THROTTLED: &str = "lightcast_frames_throttled_total";
pub const BYTES_SENT: &str = "lightcast_bytes_sent_total";
pub const ERRORS: &str = "lightcast_errors_total";
/// Durations in seconds, as Prometheus names them; each has a deprecated `_ms` twin kept for
/// one release (same observations, milliseconds).
pub const STAGE_SECONDS: &str = "lightcast_stage_seconds";
pub const GPU_FRAME_SECONDS: &str = "lightcast_gpu_frame_seconds";
pub const READBACK_SECONDS: &str = "lightcast_readback_seconds";
pub const ENCODE_SECONDS: &str = "lightcast_encode_seconds";
/// Per frame, how long the GPU sat idle before it for want of it (`render_loop::Queued`): its
/// sum over the run's wall time is the share of time the render loop left the GPU idle
/// between session frames (at least; one-shot renders' chunks and comparisons are not seen).
pub const GPU_IDLE_SECONDS: &str = "lightcast_gpu_idle_seconds";
pub const STAGE_MS: &str = "lightcast_stage_ms";
pub const GPU_FRAME_MS: &str = "lightcast_gpu_frame_ms";
pub const READBACK_MS: &str = "lightcast_readback_ms";
pub const ENCODE_MS: &str = "lightcast_encode_ms";
pub const RENDERS: &str = "lightcast_oneshot_renders_total";
pub const RENDERS_ABANDONED: &str = "lightcast_oneshot_renders_abandoned_total";
/// Open HTTP/WebSocket connections, and those refused by `reason` (`too_many_connections`).
pub const CONNECTIONS: &str = "lightcast_connections";
pub const CONNECTIONS_REFUSED: &str = "lightcast_connections_refused_total";
/// Live GPU objects by kind (wgpu's registry, read at each scrape): a soak watches these for
/// leaks of GPU resources.
pub const GPU_BUFFERS: &str = "lightcast_gpu_buffers";
pub const GPU_TEXTURES: &str = "lightcast_gpu_textures";
pub const GPU_BIND_GROUPS: &str = "lightcast_gpu_bind_groups";

/// Sets the GPU object gauges from `instance`'s report.
pub fn record_gpu_resources(instance: &wgpu::Instance) {
    if let Some(c) = crate::gpu::context::resource_counts(instance) {
        metrics::gauge!(GPU_BUFFERS).set(c.buffers as f64);
        metrics::gauge!(GPU_TEXTURES).set(c.textures as f64);
        metrics::gauge!(GPU_BIND_GROUPS).set(c.bind_groups as f64);
    }
}

/// Histogram buckets in milliseconds, from sub-millisecond GPU stages to slow software renders.
const MS_BUCKETS: &[f64] = &[
    0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 33.0, 66.0, 125.0, 250.0, 500.0, 1000.0, 4000.0,
];

/// The same buckets in seconds.
const SECONDS_BUCKETS: &[f64] = &[
    0.000_05, 0.000_1, 0.000_25, 0.000_5, 0.001, 0.002, 0.004, 0.008, 0.016, 0.033, 0.066, 0.125,
    0.25, 0.5, 1.0, 4.0,
];

/// Records a duration of `ms` milliseconds in the `seconds` histogram and its deprecated
/// `ms` twin.
pub fn record_duration(seconds: &'static str, ms_name: &'static str, ms: f64) {
    metrics::histogram!(seconds).record(ms / 1e3);
    metrics::histogram!(ms_name).record(ms);
}

/// Records one pipeline stage's GPU time.
pub fn record_stage(stage: &'static str, ms: f64) {
    metrics::histogram!(STAGE_SECONDS, "stage" => stage).record(ms / 1e3);
    metrics::histogram!(STAGE_MS, "stage" => stage).record(ms);
}

/// The process-wide recorder (installed on first use; servers started in one process, as in
/// tests, share it).
pub fn handle() -> &'static PrometheusHandle {
    static HANDLE: OnceLock<PrometheusHandle> = OnceLock::new();
    HANDLE.get_or_init(|| {
        let recorder = PrometheusBuilder::new()
            .set_buckets_for_metric(Matcher::Suffix("_seconds".into()), SECONDS_BUCKETS)
            .and_then(|b| b.set_buckets_for_metric(Matcher::Suffix("_ms".into()), MS_BUCKETS))
            .expect("bucket lists are not empty")
            .build_recorder();
        let handle = recorder.handle();
        if metrics::set_global_recorder(recorder).is_err() {
            tracing::warn!("a metrics recorder was already installed; /metrics will be empty");
        }
        describe();
        handle
    })
}

fn describe() {
    use metrics::{describe_counter, describe_gauge, describe_histogram, Unit};
    describe_gauge!(SESSIONS, "Open sessions");
    describe_gauge!(SESSION_CAPACITY, "Sessions the server accepts at once");
    describe_gauge!(SCENES, "Scenes held");
    describe_gauge!(GPU_BUFFERS, "Live GPU buffers");
    describe_gauge!(GPU_TEXTURES, "Live GPU textures");
    describe_gauge!(GPU_BIND_GROUPS, "Live GPU bind groups");
    describe_counter!(FRAMES_RENDERED, "Frames rendered for sessions");
    describe_counter!(FRAMES_SENT, "Frames written to WebSockets");
    describe_counter!(
        FRAMES_DROPPED,
        "Encoded frames replaced before their client took them"
    );
    describe_counter!(
        FRAMES_THROTTLED,
        "Session ticks skipped because the client had frames in flight"
    );
    describe_counter!(BYTES_SENT, Unit::Bytes, "Frame bytes written to WebSockets");
    describe_counter!(ERRORS, "Errors answered to clients, by kind");
    describe_histogram!(STAGE_SECONDS, Unit::Seconds, "GPU time per pipeline stage");
    describe_histogram!(GPU_FRAME_SECONDS, Unit::Seconds, "GPU time per frame");
    describe_histogram!(
        READBACK_SECONDS,
        Unit::Seconds,
        "Wait for the frame to be mapped after its GPU work"
    );
    describe_histogram!(ENCODE_SECONDS, Unit::Seconds, "Encode time per frame");
    describe_histogram!(
        GPU_IDLE_SECONDS,
        Unit::Seconds,
        "Per frame, how long the GPU sat idle before it while the render loop prepared it (at least)"
    );
    for (name, what) in [
        (STAGE_MS, STAGE_SECONDS),
        (GPU_FRAME_MS, GPU_FRAME_SECONDS),
        (READBACK_MS, READBACK_SECONDS),
        (ENCODE_MS, ENCODE_SECONDS),
    ] {
        describe_histogram!(
            name,
            Unit::Milliseconds,
            format!("Deprecated: {what} in milliseconds")
        );
    }
    describe_counter!(RENDERS, "One-shot renders");
    describe_counter!(
        RENDERS_ABANDONED,
        "Chunked one-shot renders stopped between chunks because their client had gone"
    );
}
