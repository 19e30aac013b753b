//! Latency histograms and summaries for `stream` and `loadtest`.

use hdrhistogram::Histogram;
use serde::Serialize;
use std::time::Duration;

/// Percentiles of a set of durations, in milliseconds.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Percentiles {
    pub samples: u64,
    pub p50: f64,
    pub p95: f64,
    pub p99: f64,
    pub max: f64,
}

/// Durations recorded at microsecond resolution (1 µs … 1 h, 3 significant digits).
pub struct Latencies(Histogram<u64>);

impl Default for Latencies {
    fn default() -> Self {
        Self(Histogram::new_with_bounds(1, 3_600_000_000, 3).expect("valid histogram bounds"))
    }
}

impl Latencies {
    pub fn record(&mut self, d: Duration) {
        let us = (d.as_micros() as u64).clamp(1, 3_600_000_000);
        // Within the bounds by the clamp, so recording cannot fail.
        let _ = self.0.record(us);
    }

    pub fn merge(&mut self, other: &Latencies) {
        let _ = self.0.add(&other.0);
    }

    pub fn summary(&self) -> Percentiles {
        let ms = |us: u64| us as f64 / 1e3;
        if self.0.is_empty() {
            return Percentiles::default();
        }
        Percentiles {
            samples: self.0.len(),
            p50: ms(self.0.value_at_quantile(0.50)),
            p95: ms(self.0.value_at_quantile(0.95)),
            p99: ms(self.0.value_at_quantile(0.99)),
            max: ms(self.0.max()),
        }
    }
}

/// Running means of the per-frame time split reported in frame headers.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FrameSplit {
    /// GPU time of all stages.
    pub gpu_ms: f64,
    /// Waiting for the frame to be mapped after its GPU work.
    pub readback_ms: f64,
    pub encode_ms: f64,
    /// Render start to send, on the server (GPU, readback, encode and queueing).
    pub server_ms: f64,
    /// Server send to client receipt (same clock on loopback).
    pub network_ms: f64,
    #[serde(skip)]
    frames: u64,
}

impl FrameSplit {
    pub fn add(&mut self, h: &lightcast_protocol::FrameHeader, received_us: u64) {
        let n = self.frames as f64;
        let mean = |old: f64, new: f64| (old * n + new) / (n + 1.0);
        self.gpu_ms = mean(self.gpu_ms, f64::from(h.gpu_ms));
        self.readback_ms = mean(self.readback_ms, f64::from(h.readback_ms));
        self.encode_ms = mean(self.encode_ms, f64::from(h.encode_ms));
        self.server_ms = mean(
            self.server_ms,
            h.send_us.saturating_sub(h.render_start_us) as f64 / 1e3,
        );
        self.network_ms = mean(
            self.network_ms,
            received_us.saturating_sub(h.send_us) as f64 / 1e3,
        );
        self.frames += 1;
    }

    pub fn merge(&mut self, other: &FrameSplit) {
        let total = (self.frames + other.frames) as f64;
        if total == 0.0 {
            return;
        }
        let (a, b) = (self.frames as f64 / total, other.frames as f64 / total);
        self.gpu_ms = self.gpu_ms * a + other.gpu_ms * b;
        self.readback_ms = self.readback_ms * a + other.readback_ms * b;
        self.encode_ms = self.encode_ms * a + other.encode_ms * b;
        self.server_ms = self.server_ms * a + other.server_ms * b;
        self.network_ms = self.network_ms * a + other.network_ms * b;
        self.frames += other.frames;
    }
}

pub fn unix_us() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

/// Median of a list (0 when empty).
pub fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f64::total_cmp);
    let mid = values.len() / 2;
    if values.len().is_multiple_of(2) {
        (values[mid - 1] + values[mid]) / 2.0
    } else {
        values[mid]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_of_known_values() {
        let mut l = Latencies::default();
        for ms in 1..=100 {
            l.record(Duration::from_millis(ms));
        }
        let s = l.summary();
        assert_eq!(s.samples, 100);
        assert!((s.p50 - 50.0).abs() < 0.1, "{s:?}");
        assert!((s.p95 - 95.0).abs() < 0.1, "{s:?}");
        assert!((s.p99 - 99.0).abs() < 0.1, "{s:?}");
        assert!((s.max - 100.0).abs() < 0.1, "{s:?}");
    }

    #[test]
    fn median_of_even_and_odd_lists() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
        assert_eq!(median(&mut []), 0.0);
    }
}
