//! Prometheus metrics: names in one place, and the recorder behind `/metrics`.

use metrics_exporter_prometheus::{PrometheusBuilder, PrometheusHandle};
use std::sync::OnceLock;

pub const SESSIONS: &str = "lightcast_sessions";
pub const SCENES: &str = "lightcast_scenes";
pub const FRAMES_RENDERED: &str = "lightcast_frames_rendered_total";
pub const FRAMES_SENT: &str = "lightcast_frames_sent_total";
pub const FRAMES_DROPPED: &str = "lightcast_frames_dropped_total";
pub const FRAMES_THROTTLED: &str = "lightcast_frames_throttled_total";
pub const BYTES_SENT: &str = "lightcast_bytes_sent_total";
pub const ERRORS: &str = "lightcast_errors_total";
pub const STAGE_MS: &str = "lightcast_stage_ms";
pub const GPU_FRAME_MS: &str = "lightcast_gpu_frame_ms";
pub const READBACK_MS: &str = "lightcast_readback_ms";
pub const ENCODE_MS: &str = "lightcast_encode_ms";
pub const RENDERS: &str = "lightcast_oneshot_renders_total";

/// Histogram buckets in milliseconds, from sub-millisecond GPU stages to slow software renders.
const MS_BUCKETS: &[f64] = &[
    0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 33.0, 66.0, 125.0, 250.0, 500.0, 1000.0, 4000.0,
];

/// The process-wide recorder (installed on first use; servers started in one process, as in
/// tests, share it).
pub fn handle() -> &'static PrometheusHandle {
    static HANDLE: OnceLock<PrometheusHandle> = OnceLock::new();
    HANDLE.get_or_init(|| {
        let recorder = PrometheusBuilder::new()
            .set_buckets(MS_BUCKETS)
            .expect("bucket list is not empty")
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
    describe_gauge!(SCENES, "Scenes held");
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
    describe_histogram!(STAGE_MS, Unit::Milliseconds, "GPU time per pipeline stage");
    describe_histogram!(GPU_FRAME_MS, Unit::Milliseconds, "GPU time per frame");
    describe_histogram!(
        READBACK_MS,
        Unit::Milliseconds,
        "Wait for the frame to be mapped after its GPU work"
    );
    describe_histogram!(ENCODE_MS, Unit::Milliseconds, "Encode time per frame");
    describe_counter!(RENDERS, "One-shot renders");
}
