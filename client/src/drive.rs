//! Drives one session: create it, open its stream, move the camera at a steady rate, receive
//! frames and measure input→frame latency. Shared by `stream` and `loadtest`.

use crate::api::{Client, ClientError, Incoming};
use crate::stats::{unix_us, FrameSplit, Latencies};
use lightcast_protocol::frame::FLAG_KEYFRAME;
use lightcast_protocol::{Camera, ClientMessage, FrameHeader, SessionStats};
use serde::Deserialize;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// One keyframe of a camera path file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Keyframe {
    /// Seconds from the start.
    pub t: f64,
    pub camera: Camera,
}

/// A camera path: `{"keyframes": [{"t": 0, "camera": {...}}, ...]}`, interpolated linearly.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraPath {
    pub keyframes: Vec<Keyframe>,
}

impl CameraPath {
    pub fn load(path: &std::path::Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let parsed: Self =
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        if parsed.keyframes.is_empty() {
            return Err(format!("{}: no keyframes", path.display()));
        }
        let finite = parsed.keyframes.iter().all(|k| k.t.is_finite());
        if !finite || parsed.keyframes.windows(2).any(|w| w[1].t <= w[0].t) {
            return Err(format!("{}: keyframe times must rise", path.display()));
        }
        Ok(parsed)
    }

    /// The camera at `t` seconds (held at the ends).
    pub fn at(&self, t: f64) -> Camera {
        let k = &self.keyframes;
        let i = k.partition_point(|f| f.t <= t);
        if i == 0 {
            return k[0].camera.clone();
        }
        if i == k.len() {
            return k[i - 1].camera.clone();
        }
        let (a, b) = (&k[i - 1], &k[i]);
        let s = ((t - a.t) / (b.t - a.t)) as f32;
        let lerp3 = |p: [f32; 3], q: [f32; 3]| {
            [
                p[0] + (q[0] - p[0]) * s,
                p[1] + (q[1] - p[1]) * s,
                p[2] + (q[2] - p[2]) * s,
            ]
        };
        Camera {
            position: lerp3(a.camera.position, b.camera.position),
            target: lerp3(a.camera.target, b.camera.target),
            fov_y_degrees: a.camera.fov_y_degrees
                + (b.camera.fov_y_degrees - a.camera.fov_y_degrees) * s,
        }
    }
}

/// How the camera moves while driving.
#[derive(Clone, Debug)]
pub enum Motion {
    Still,
    /// Orbit `base` around its target at `degrees_per_second`.
    Orbit {
        base: Camera,
        degrees_per_second: f64,
    },
    Path(CameraPath),
}

impl Motion {
    /// The camera at `t` seconds; `None` when it does not move.
    pub fn camera(&self, t: f64) -> Option<Camera> {
        match self {
            Self::Still => None,
            Self::Orbit {
                base,
                degrees_per_second,
            } => {
                let angle = (t * degrees_per_second).to_radians() as f32;
                let (s, c) = angle.sin_cos();
                let [px, py, pz] = base.position;
                let [tx, _, tz] = base.target;
                let (dx, dz) = (px - tx, pz - tz);
                Some(Camera {
                    position: [tx + dx * c - dz * s, py, tz + dx * s + dz * c],
                    ..base.clone()
                })
            }
            Self::Path(p) => Some(p.at(t)),
        }
    }
}

pub struct DriveOptions {
    /// `SessionParams` as JSON.
    pub params: serde_json::Value,
    pub motion: Motion,
    /// Camera messages per second (0: none).
    pub input_hz: f64,
    /// Stop after this many frames inside the measuring window.
    pub max_frames: Option<u64>,
    /// Write every frame's image here.
    pub save_dir: Option<PathBuf>,
    /// Append an `h264` stream's access units to this file, from the first keyframe on.
    pub video_out: Option<PathBuf>,
    /// Frames and bytes count from this instant (after a load test's ramp-up).
    pub measure_from: Instant,
    pub deadline: Instant,
}

/// What one driven session measured.
#[derive(Default)]
pub struct DriveResult {
    pub connect: Duration,
    pub first_frame: Option<Duration>,
    /// Frames and bytes received inside the measuring window.
    pub frames: u64,
    pub bytes: u64,
    pub window: Duration,
    pub latencies: Latencies,
    pub split: FrameSplit,
    /// The server's counters for the session at the end.
    pub server_stats: Option<SessionStats>,
    pub errors: Vec<String>,
    pub last_header: Option<FrameHeader>,
    /// Video frames written to [`DriveOptions::video_out`], and keyframes among all received.
    pub video_frames: u64,
    pub keyframes: u64,
    /// The longest wait between two frames inside the measuring window (from its start for
    /// the first): how long the stream stalled, e.g. behind another client's work.
    pub longest_gap: Duration,
}

impl DriveResult {
    /// Why a run received no frame, from what the server reported for its session; `None`
    /// when frames arrived. A summary of zeros alone reads as a broken client.
    pub fn no_frames_reason(&self) -> Option<String> {
        if self.frames > 0 {
            return None;
        }
        let mut reason = format!("no frame arrived within {:.1} s", self.window.as_secs_f64());
        match &self.server_stats {
            None => reason.push_str("; the session's counters could not be read"),
            Some(s) if s.frames_rendered == 0 => reason.push_str(
                "; the server has not finished a frame for the session yet (a CPU adapter \
                 builds a GI method's pipelines on its first frame: try --gi none, a smaller \
                 --width/--height, or a longer --duration)",
            ),
            Some(s) => {
                reason.push_str(&format!(
                    "; the server rendered {} and sent {} frames for the session",
                    s.frames_rendered, s.frames_sent
                ));
                if !s.last_stages.is_empty() {
                    let gpu: f64 = s.last_stages.iter().map(|st| st.ms).sum();
                    reason.push_str(&format!(", its last one in {gpu:.1} GPU ms"));
                }
            }
        }
        if let Some(e) = self
            .server_stats
            .as_ref()
            .and_then(|s| s.last_error.as_ref())
        {
            reason.push_str(&format!("; its last error: {}: {}", e.error, e.message));
        }
        if let Some(e) = self.errors.first() {
            reason.push_str(&format!("; {e}"));
        }
        Some(reason)
    }
}

fn extension(h: &FrameHeader) -> &'static str {
    match h.codec {
        lightcast_protocol::Codec::Jpeg => "jpg",
        lightcast_protocol::Codec::Png => "png",
        lightcast_protocol::Codec::H264 => "h264",
    }
}

/// Runs one session to `opts.deadline` (or `max_frames`), then deletes it. `on_frame` is called
/// for every frame (progress).
pub async fn drive(
    client: &Client,
    opts: &DriveOptions,
    on_frame: &(dyn Fn() + Sync),
) -> Result<DriveResult, ClientError> {
    let started = Instant::now();
    let created = client.create_session(&opts.params).await?;
    let mut stream = client.connect(&created).await?;
    let mut result = DriveResult {
        connect: started.elapsed(),
        ..DriveResult::default()
    };
    if let Some(dir) = &opts.save_dir {
        std::fs::create_dir_all(dir)
            .map_err(|e| ClientError::Invalid(format!("creating {}: {e}", dir.display())))?;
    }
    let mut video = match &opts.video_out {
        Some(path) => Some(
            std::fs::File::create(path)
                .map_err(|e| ClientError::Invalid(format!("creating {}: {e}", path.display())))?,
        ),
        None => None,
    };
    let period = if opts.input_hz > 0.0 {
        Duration::from_secs_f64(1.0 / opts.input_hz)
    } else {
        Duration::from_secs(3600)
    };
    let mut ticker = tokio::time::interval(period);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let deadline = tokio::time::Instant::from_std(opts.deadline);
    let mut next_input: u64 = 1;
    // (input id, when it was sent), oldest first.
    let mut pending: VecDeque<(u64, Instant)> = VecDeque::new();
    let mut last_frame = opts.measure_from.max(Instant::now());
    loop {
        tokio::select! {
            _ = tokio::time::sleep_until(deadline) => break,
            // Ctrl-C (SIGINT) ends the run early with its summary, as the deadline would.
            _ = tokio::signal::ctrl_c() => break,
            _ = ticker.tick(), if opts.input_hz > 0.0 => {
                if let Some(camera) = opts.motion.camera(started.elapsed().as_secs_f64()) {
                    stream.send(&ClientMessage::Camera { camera, input_id: next_input }).await?;
                    pending.push_back((next_input, Instant::now()));
                    next_input += 1;
                    // A client that outpaces the server must not grow this without bound.
                    if pending.len() > 10_000 {
                        pending.pop_front();
                    }
                }
            }
            incoming = stream.next() => match incoming? {
                Incoming::Closed => {
                    result.errors.push("the server closed the stream".into());
                    break;
                }
                Incoming::Event(lightcast_protocol::ServerEvent::Error { error })
                | Incoming::Event(lightcast_protocol::ServerEvent::RenderError { error }) => {
                    result.errors.push(format!("{}: {}", error.error, error.message));
                }
                Incoming::Event(_) => {}
                Incoming::Frame { header, payload, wire_bytes } => {
                    let now = Instant::now();
                    result.first_frame.get_or_insert(started.elapsed());
                    while let Some(&(id, sent)) = pending.front() {
                        if id > header.input_id {
                            break;
                        }
                        pending.pop_front();
                        if id == header.input_id {
                            result.latencies.record(now - sent);
                        }
                    }
                    if now >= opts.measure_from {
                        result.frames += 1;
                        result.bytes += wire_bytes as u64;
                        result.longest_gap = result.longest_gap.max(now - last_frame);
                        last_frame = now;
                    }
                    result.split.add(&header, unix_us());
                    stream.send(&ClientMessage::Ack { seq: header.seq }).await?;
                    if let Some(dir) = &opts.save_dir {
                        let path = dir.join(format!("{:06}.{}", header.seq, extension(&header)));
                        std::fs::write(&path, &payload).map_err(|e| {
                            ClientError::Invalid(format!("writing {}: {e}", path.display()))
                        })?;
                    }
                    if header.flags & FLAG_KEYFRAME != 0 {
                        result.keyframes += 1;
                    }
                    // A decoder starts at a keyframe: earlier frames (sent before the stream's
                    // first keyframe reached us) cannot be decoded and are left out.
                    let video_started = result.video_frames > 0 || header.flags & FLAG_KEYFRAME != 0;
                    if let Some(file) = video.as_mut().filter(|_| header.codec.is_video() && video_started) {
                        use std::io::Write;
                        file.write_all(&payload).map_err(|e| {
                            ClientError::Invalid(format!("writing the video: {e}"))
                        })?;
                        result.video_frames += 1;
                    }
                    result.last_header = Some(header);
                    on_frame();
                    if opts.max_frames.is_some_and(|max| result.frames >= max) {
                        break;
                    }
                }
            }
        }
    }
    result.window = Instant::now().saturating_duration_since(opts.measure_from);
    result.server_stats = client
        .session(&created.session.id)
        .await
        .ok()
        .map(|s| s.stats);
    stream.close().await;
    client.delete_session(&created.session.id).await.ok();
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(x: f32, fov: f32) -> Camera {
        Camera {
            position: [x, 1.0, 3.0],
            target: [0.0, 1.0, 0.0],
            fov_y_degrees: fov,
        }
    }

    #[test]
    fn path_interpolates_and_holds_at_the_ends() {
        let path = CameraPath {
            keyframes: vec![
                Keyframe {
                    t: 0.0,
                    camera: cam(0.0, 40.0),
                },
                Keyframe {
                    t: 2.0,
                    camera: cam(2.0, 60.0),
                },
            ],
        };
        assert_eq!(path.at(-1.0), cam(0.0, 40.0));
        assert_eq!(path.at(1.0), cam(1.0, 50.0));
        assert_eq!(path.at(5.0), cam(2.0, 60.0));
    }

    #[test]
    fn orbit_keeps_distance_and_height() {
        let motion = Motion::Orbit {
            base: cam(0.0, 45.0),
            degrees_per_second: 90.0,
        };
        let c = motion.camera(1.0).expect("a camera");
        assert!(
            (c.position[0] + 3.0).abs() < 1e-5 && c.position[2].abs() < 1e-5,
            "{c:?}"
        );
        assert_eq!(c.position[1], 1.0);
    }
}
