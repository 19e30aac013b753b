//! Drives one session: create it, open its stream, move the camera at a steady rate, receive
//! frames and measure input→frame latency. Shared by `stream` and `loadtest`.

use crate::api::{Client, ClientError, Incoming};
use crate::node_path::NodePath;
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
        let parsed: Self = read_json(path)?;
        let times: Vec<f64> = parsed.keyframes.iter().map(|k| k.t).collect();
        check_times(&times).map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(parsed)
    }

    /// The camera at `t` seconds (held at the ends).
    pub fn at(&self, t: f64) -> Camera {
        sample(
            &self.keyframes,
            t,
            |k| k.t,
            |k| k.camera.clone(),
            |a, b, s| Camera {
                position: lerp3(a.camera.position, b.camera.position, s),
                target: lerp3(a.camera.target, b.camera.target, s),
                fov_y_degrees: a.camera.fov_y_degrees
                    + (b.camera.fov_y_degrees - a.camera.fov_y_degrees) * s,
            },
        )
    }
}

/// A path file (`--camera-path`, `--node-path`) as `T`; errors start with the file's name.
pub fn read_json<T: serde::de::DeserializeOwned>(path: &std::path::Path) -> Result<T, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))
}

/// A path's keyframe times: at least one, each a finite number after the one before.
pub fn check_times(times: &[f64]) -> Result<(), String> {
    if times.is_empty() {
        return Err("no keyframes".into());
    }
    if let Some(i) = times.iter().position(|t| !t.is_finite()) {
        return Err(format!("keyframes[{i}].t is not a finite number"));
    }
    match times.windows(2).position(|w| w[1] <= w[0]) {
        Some(i) => Err(format!(
            "keyframe times must rise: keyframes[{}].t = {} is not after keyframes[{i}].t = {}",
            i + 1,
            times[i + 1],
            times[i]
        )),
        None => Ok(()),
    }
}

/// A keyframed value at `t` seconds: `mix(a, b, s)` between the keyframes `a` and `b` around
/// `t`, `s` in [0, 1) the fraction of the way from `a` to `b`; the first or last keyframe's
/// own value before the first and after the last. `keys` is not empty and its `time`s rise
/// ([`check_times`]).
pub fn sample<K, T>(
    keys: &[K],
    t: f64,
    time: impl Fn(&K) -> f64,
    value: impl Fn(&K) -> T,
    mix: impl Fn(&K, &K, f32) -> T,
) -> T {
    let i = keys.partition_point(|k| time(k) <= t);
    if i == 0 {
        return value(&keys[0]);
    }
    if i == keys.len() {
        return value(&keys[i - 1]);
    }
    let (a, b) = (&keys[i - 1], &keys[i]);
    mix(a, b, ((t - time(a)) / (time(b) - time(a))) as f32)
}

/// `p + (q − p)·s` per component.
pub fn lerp3(p: [f32; 3], q: [f32; 3], s: f32) -> [f32; 3] {
    [
        p[0] + (q[0] - p[0]) * s,
        p[1] + (q[1] - p[1]) * s,
        p[2] + (q[2] - p[2]) * s,
    ]
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
    /// Movable nodes' poses to replay (`nodes` messages), on the camera's ticks.
    pub node_path: Option<NodePath>,
    /// Input ticks per second (0: none): each sends the camera (unless [`Motion::Still`]) and
    /// the nodes of [`DriveOptions::node_path`] as they are at that time.
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

impl DriveOptions {
    /// The messages of one input tick at `t` seconds, each with its own input id from
    /// `next_id` on (a frame's header echoes the last one it shows): the camera, unless it is
    /// still, then the node path's poses.
    fn inputs(&self, t: f64, next_id: &mut u64) -> Vec<(u64, ClientMessage)> {
        let mut take_id = || {
            *next_id += 1;
            *next_id - 1
        };
        let mut messages = Vec::new();
        if let Some(camera) = self.motion.camera(t) {
            let input_id = take_id();
            messages.push((input_id, ClientMessage::Camera { camera, input_id }));
        }
        if let Some(path) = &self.node_path {
            let input_id = take_id();
            let nodes = path.at(t);
            messages.push((input_id, ClientMessage::Nodes { nodes, input_id }));
        }
        messages
    }
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
                for (input_id, message) in opts.inputs(started.elapsed().as_secs_f64(), &mut next_input) {
                    stream.send(&message).await?;
                    pending.push_back((input_id, Instant::now()));
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
    fn a_tick_sends_the_camera_and_the_node_path_with_their_own_input_ids() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join("nodes.json");
        std::fs::write(
            &file,
            r#"{"keyframes": [{"t": 0, "nodes": [{"node": 1, "translation": [0, 0, 0]}]},
                              {"t": 2, "nodes": [{"node": 1, "translation": [0.2, 0, 0]}]}]}"#,
        )
        .expect("write");
        let path = CameraPath {
            keyframes: vec![Keyframe {
                t: 0.0,
                camera: cam(0.0, 40.0),
            }],
        };
        let mut opts = DriveOptions {
            params: serde_json::json!({}),
            motion: Motion::Path(path),
            node_path: Some(NodePath::load(&file).expect("loads")),
            input_hz: 10.0,
            max_frames: None,
            save_dir: None,
            video_out: None,
            measure_from: Instant::now(),
            deadline: Instant::now(),
        };
        let mut next = 7;
        let sent = opts.inputs(1.0, &mut next);
        assert_eq!(next, 9);
        assert_eq!(sent.len(), 2);
        assert_eq!(
            sent[0],
            (
                7,
                ClientMessage::Camera {
                    camera: cam(0.0, 40.0),
                    input_id: 7
                }
            )
        );
        let ClientMessage::Nodes { nodes, input_id: 8 } = &sent[1].1 else {
            panic!("{:?}", sent[1]);
        };
        assert_eq!(sent[1].0, 8);
        assert_eq!(nodes.len(), 1);
        assert_eq!(nodes[0].translation, Some([0.1, 0.0, 0.0]));
        // A still camera sends nothing of its own; the nodes go on.
        opts.motion = Motion::Still;
        let sent = opts.inputs(3.0, &mut next);
        assert_eq!(sent.len(), 1);
        assert!(
            matches!(&sent[0], (9, ClientMessage::Nodes { nodes, input_id: 9 }) if nodes[0].translation == Some([0.2, 0.0, 0.0])),
            "{sent:?}"
        );
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
