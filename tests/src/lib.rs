//! Helpers for the end-to-end tests: start a real server on a loopback port (in this process,
//! on lavapipe in CI), talk to it over HTTP and WebSocket, and decode what comes back.

use clap::Parser;
use futures_util::{SinkExt, StreamExt};
use lightcast_protocol::{ErrorBody, FrameHeader, ServerEvent, SessionCreated};
use lightcast_server::service::{ServeArgs, Service};
use serde_json::{json, Value};
use std::time::Duration;
use tokio_tungstenite::tungstenite::Message;

/// A reqwest client builder for the tests. The workspace builds reqwest with rustls and no
/// built-in crypto provider (the `lightcast` client brings its own, ring); tests install ring
/// as the process's default once, so plain clients work too.
pub fn http_builder() -> reqwest::ClientBuilder {
    // Err: already installed by an earlier call.
    let _ = rustls::crypto::ring::default_provider().install_default();
    reqwest::Client::builder()
}

/// How long a test waits for any one thing from the server before failing.
pub const PATIENCE: Duration = Duration::from_secs(120);

#[derive(Parser)]
struct Wrapper {
    #[command(flatten)]
    serve: ServeArgs,
}

/// A server running in this process on an ephemeral loopback port.
pub struct TestServer {
    pub base: String,
    pub http: reqwest::Client,
    service: Option<Service>,
    _cache: tempfile::TempDir,
}

impl TestServer {
    /// Starts with the built-in default scene, a fresh light-cache directory and `extra`
    /// command-line options of `serve`.
    pub async fn start(extra: &[&str]) -> Self {
        Self::start_with(extra, true).await
    }

    /// As [`Self::start`]; `allow_cpu_adapter` says whether a software adapter counts as ready.
    pub async fn start_with(extra: &[&str], allow_cpu_adapter: bool) -> Self {
        let cache = tempfile::tempdir().expect("temporary cache directory");
        let cache_dir = cache.path().to_string_lossy().into_owned();
        let mut argv = vec![
            "lightcast-server",
            "--listen",
            "127.0.0.1:0",
            "--cache-dir",
            &cache_dir,
            "--encode-threads",
            "2",
        ];
        if allow_cpu_adapter {
            argv.push("--allow-cpu-adapter");
        }
        argv.extend_from_slice(extra);
        let args = Wrapper::try_parse_from(argv)
            .expect("valid serve options")
            .serve;
        let service = Service::start(&args, &|line: &str| eprintln!("server: {line}"))
            .await
            .expect("the server starts");
        Self {
            base: format!("http://{}", service.addr),
            http: http_builder().build().expect("HTTP client"),
            service: Some(service),
            _cache: cache,
        }
    }

    /// A client of whatever serves at `base` (a proxy in front of servers started here):
    /// the same helpers, and [`Self::stop`] stops nothing.
    pub fn remote(base: String) -> Self {
        Self {
            base,
            http: http_builder().build().expect("HTTP client"),
            service: None,
            _cache: tempfile::tempdir().expect("temporary directory"),
        }
    }

    /// The port this server listens on.
    pub fn port(&self) -> u16 {
        self.service.as_ref().map_or(0, |s| s.addr.port())
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    pub fn ws_url(&self, path: &str) -> String {
        format!("{}{path}", self.base.replacen("http://", "ws://", 1))
    }

    /// Stops the server as SIGTERM would.
    pub async fn stop(mut self) {
        if let Some(s) = self.service.take() {
            s.shutdown().await.expect("clean shutdown");
        }
    }

    /// POST /v1/scenes of a `.glb` named `name`; panics unless 201. The scene's info.
    pub async fn upload_glb(&self, name: &str, glb: Vec<u8>) -> Value {
        let resp = self
            .http
            .post(self.url(&format!("/v1/scenes?name={name}")))
            .header("content-type", "model/gltf-binary")
            .body(glb)
            .send()
            .await
            .expect("upload");
        assert_eq!(resp.status(), 201, "uploading {name}");
        resp.json().await.expect("SceneInfo")
    }

    /// POST /v1/sessions with `params`; panics unless 201.
    pub async fn create_session(&self, params: Value, token: Option<&str>) -> SessionCreated {
        let mut req = self.http.post(self.url("/v1/sessions")).json(&params);
        if let Some(t) = token {
            req = req.bearer_auth(t);
        }
        let resp = req.send().await.expect("request");
        let status = resp.status();
        let body = resp.text().await.expect("body");
        assert_eq!(status, 201, "creating a session: {body}");
        serde_json::from_str(&body).expect("SessionCreated")
    }

    /// Opens a session's stream with its ticket.
    pub async fn connect(&self, created: &SessionCreated) -> Stream {
        let url = self.ws_url(&format!(
            "{}?ticket={}",
            created.session.stream, created.ticket.ticket
        ));
        let (ws, _) = tokio_tungstenite::connect_async(url)
            .await
            .expect("WebSocket opens");
        Stream { ws, video: None }
    }

    /// GET without a token; panics only when the request cannot be made.
    pub async fn get(&self, path: &str) -> reqwest::Response {
        self.http.get(self.url(path)).send().await.expect("request")
    }

    /// DELETE without a token; panics only when the request cannot be made.
    pub async fn delete(&self, path: &str) -> reqwest::Response {
        self.http
            .delete(self.url(path))
            .send()
            .await
            .expect("request")
    }

    /// GET a JSON document; panics unless 200.
    pub async fn get_json(&self, path: &str) -> Value {
        let resp = self.get(path).await;
        assert_eq!(resp.status(), 200, "GET {path}");
        resp.json().await.expect("JSON")
    }

    /// Waits until the default scene's light caches are ready.
    pub async fn wait_caches_ready(&self, scene: &str) {
        tokio::time::timeout(PATIENCE, async {
            loop {
                let info = self.get_json(&format!("/v1/scenes/{scene}")).await;
                if info["caches"][0]["state"] == "ready" {
                    return;
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        })
        .await
        .expect("light caches become ready");
    }
}

/// A decoded binary frame.
pub struct ReceivedFrame {
    pub header: FrameHeader,
    /// The image (an H.264 frame as the stream's decoder shows it).
    pub rgba: image::RgbaImage,
    /// The encoded payload as it came.
    pub payload: Vec<u8>,
    /// An H.264 frame's decoded luma plane, rows packed.
    pub luma: Option<Vec<u8>>,
}

impl ReceivedFrame {
    pub fn stage(&self, name: &str) -> Option<f32> {
        let index = lightcast_server::gi::stages::index_of(name)?;
        self.header
            .stages
            .iter()
            .find(|(i, _)| *i == index)
            .map(|(_, ms)| *ms)
    }
}

/// One side of a session's WebSocket.
pub struct Stream {
    pub ws: tokio_tungstenite::WebSocketStream<
        tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>,
    >,
    /// The decoder of an `h264` stream (OpenH264's, independent of the server's encoder
    /// state), made at the first video frame.
    video: Option<openh264::decoder::Decoder>,
}

/// Decodes one H.264 access unit: RGBA (the decoder's own conversion) and the luma plane.
fn decode_h264(
    decoder: &mut openh264::decoder::Decoder,
    unit: &[u8],
) -> (image::RgbaImage, Vec<u8>) {
    use openh264::formats::YUVSource;
    let picture = decoder
        .decode(unit)
        .expect("a decodable access unit")
        .expect("one picture per access unit");
    let (w, h) = picture.dimensions();
    let mut rgba = vec![0; w * h * 4];
    picture.write_rgba8(&mut rgba);
    let stride = picture.strides().0;
    let luma = (0..h)
        .flat_map(|y| picture.y()[y * stride..y * stride + w].to_vec())
        .collect();
    let image = image::RgbaImage::from_raw(w as u32, h as u32, rgba).expect("sized buffer");
    (image, luma)
}

/// What the server sent next.
pub enum Incoming {
    Frame(Box<ReceivedFrame>),
    Event(ServerEvent),
    Closed,
}

impl Stream {
    /// Reads until the server closes the stream; the reason of its `closing` event, if any.
    pub async fn closing_reason(&mut self) -> Option<String> {
        let mut reason = None;
        loop {
            match self.next().await {
                Incoming::Event(ServerEvent::Closing { reason: r }) => reason = Some(r),
                Incoming::Closed => return reason,
                _ => {}
            }
        }
    }

    /// Reads until the server ends the stream: the code of its close frame, `None` where the
    /// connection ended without one.
    pub async fn close_code(&mut self) -> Option<u16> {
        loop {
            let msg = tokio::time::timeout(PATIENCE, self.ws.next())
                .await
                .expect("the server ends the stream in time");
            match msg {
                Some(Ok(Message::Close(frame))) => return frame.map(|f| u16::from(f.code)),
                None | Some(Err(_)) => return None,
                Some(Ok(_)) => {}
            }
        }
    }

    pub async fn send(&mut self, message: Value) {
        self.ws
            .send(Message::Text(message.to_string().into()))
            .await
            .expect("send");
    }

    pub async fn send_raw(&mut self, message: Message) {
        self.ws.send(message).await.expect("send");
    }

    /// The next frame or event.
    pub async fn next(&mut self) -> Incoming {
        loop {
            let msg = tokio::time::timeout(PATIENCE, self.ws.next())
                .await
                .expect("the server sends something in time");
            match msg {
                None | Some(Err(_)) | Some(Ok(Message::Close(_))) => return Incoming::Closed,
                Some(Ok(Message::Binary(bytes))) => {
                    let (header, payload) =
                        FrameHeader::decode(&bytes).expect("valid frame header");
                    let (rgba, luma) = if header.codec.is_video() {
                        let decoder = self.video.get_or_insert_with(|| {
                            openh264::decoder::Decoder::new().expect("an H.264 decoder")
                        });
                        let (rgba, luma) = decode_h264(decoder, payload);
                        (rgba, Some(luma))
                    } else {
                        let rgba = image::load_from_memory(payload)
                            .expect("decodable image")
                            .to_rgba8();
                        (rgba, None)
                    };
                    return Incoming::Frame(Box::new(ReceivedFrame {
                        header,
                        rgba,
                        payload: payload.to_vec(),
                        luma,
                    }));
                }
                Some(Ok(Message::Text(text))) => {
                    return Incoming::Event(serde_json::from_str(&text).expect("ServerEvent JSON"))
                }
                Some(Ok(_)) => {}
            }
        }
    }

    /// The next frame, skipping events (events are returned in `seen`).
    pub async fn next_frame(&mut self, seen: &mut Vec<ServerEvent>) -> ReceivedFrame {
        loop {
            match self.next().await {
                Incoming::Frame(f) => {
                    self.send(json!({"type": "ack", "seq": f.header.seq})).await;
                    return *f;
                }
                Incoming::Event(e) => seen.push(e),
                Incoming::Closed => {
                    panic!("stream closed while waiting for a frame; events: {seen:?}")
                }
            }
        }
    }

    /// The next event, skipping frames.
    pub async fn next_event(&mut self) -> ServerEvent {
        loop {
            match self.next().await {
                Incoming::Frame(_) => {}
                Incoming::Event(e) => return e,
                Incoming::Closed => panic!("stream closed while waiting for an event"),
            }
        }
    }

    /// The next `error` event, skipping frames, `hello` and `updated`; panics on any other.
    pub async fn next_error(&mut self) -> ErrorBody {
        loop {
            match self.next_event().await {
                ServerEvent::Error { error } => return error,
                ServerEvent::Hello { .. } | ServerEvent::Updated { .. } => {}
                other => panic!("unexpected event {other:?}"),
            }
        }
    }
}

/// Mean absolute difference of two RGBA images in 0–255 levels.
pub fn mean_abs_diff(a: &image::RgbaImage, b: &image::RgbaImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    a.as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| f64::from(x.abs_diff(*y)))
        .sum::<f64>()
        / a.as_raw().len() as f64
}

/// Session parameters small enough for lavapipe: `width`×`height`, a small RSM and few VALs.
/// [`small_session`] with direct light only: the fastest frames, for tests about the stream
/// rather than GI.
pub fn direct_session(width: u32, height: u32) -> Value {
    let mut params = small_session(width, height);
    params["render"]["gi"]["method"] = json!("none");
    params
}

pub fn small_session(width: u32, height: u32) -> Value {
    json!({
        "render": {
            "width": width,
            "height": height,
            "shadow_map_size": 256,
            "gi": {"rsm_size": 32, "val_count": 256, "view_samples": 64}
        },
        "fps_cap": 60,
        "encoding": {"still_after_ms": 0}
    })
}

/// The real-world glTF scene of `shared/scenes/`, copied into `tests/data/` (not written by
/// this project).
pub fn cornell_glb() -> Vec<u8> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data/cornell-box/cornell-box.glb"
    );
    std::fs::read(path).expect("tests/data/cornell-box/cornell-box.glb")
}

/// Splits a `.glb` into a `.gltf` JSON that references `bin_name` and the binary chunk.
pub fn glb_to_gltf(glb: &[u8], bin_name: &str) -> (Vec<u8>, Vec<u8>) {
    let u32_at = |o: usize| u32::from_le_bytes(glb[o..o + 4].try_into().expect("4 bytes")) as usize;
    let json_len = u32_at(12);
    let json = &glb[20..20 + json_len];
    let bin_start = 20 + json_len;
    let bin_len = u32_at(bin_start);
    let bin = glb[bin_start + 8..bin_start + 8 + bin_len].to_vec();
    let mut doc: Value = serde_json::from_slice(json).expect("glTF JSON");
    doc["buffers"][0]["uri"] = Value::String(bin_name.to_string());
    (serde_json::to_vec(&doc).expect("JSON"), bin)
}

/// A `.glb` of the glTF JSON `doc` and the binary chunk `bin` (both padded to 4 bytes).
pub fn glb(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut json = serde_json::to_vec(doc).expect("serialise");
    json.resize(json.len().next_multiple_of(4), b' ');
    let mut bin = bin.to_vec();
    bin.resize(bin.len().next_multiple_of(4), 0);
    let chunk =
        |kind: &[u8; 4], data: &[u8]| [&(data.len() as u32).to_le_bytes()[..], kind, data].concat();
    let body = [chunk(b"JSON", &json), chunk(b"BIN\0", &bin)].concat();
    let length = 12 + body.len() as u32;
    [
        &b"glTF"[..],
        &2u32.to_le_bytes(),
        &length.to_le_bytes(),
        &body,
    ]
    .concat()
}

/// A `.glb` of one triangle: a scene that is not the Cornell box, at a few hundred bytes.
pub fn triangle_glb() -> Vec<u8> {
    let bin: Vec<u8> = [0f32, 0., 0., 1., 0., 0., 0., 1., 0.]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .collect();
    let doc = json!({
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": bin.len()}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": 3,
                       "min": [0, 0, 0], "max": [1, 1, 0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "nodes": [{"mesh": 0}],
    });
    glb(&doc, &bin)
}

/// A `.glb` of one triangle (`corners`: x, y, z of each corner) on the root node "ground",
/// the node `child` under it (as written) and the animation `animation` translating that
/// child from `from` to `to` over 2 s; `extra` adds top-level fields (extensions).
fn one_slide_glb(
    corners: [f32; 9],
    child: Value,
    animation: &str,
    (from, to): ([f32; 3], [f32; 3]),
    extra: Value,
) -> Vec<u8> {
    let floats = |v: &[f32]| v.iter().flat_map(|f| f.to_le_bytes()).collect::<Vec<u8>>();
    let bin = [
        floats(&corners),
        floats(&[0., 2.]),
        floats(&[from, to].concat()),
    ]
    .concat();
    let view = |offset: usize, length: usize| json!({"buffer": 0, "byteOffset": offset, "byteLength": length});
    let corner = |i: usize| [corners[i], corners[3 + i], corners[6 + i]];
    let (min, max): (Vec<f32>, Vec<f32>) = (0..3)
        .map(|i| {
            let c = corner(i);
            (
                c.iter().copied().fold(f32::MAX, f32::min),
                c.iter().copied().fold(f32::MIN, f32::max),
            )
        })
        .unzip();
    let mut doc = json!({
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [view(0, 36), view(36, 8), view(44, 24)],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": 3,
             "min": min, "max": max},
            {"bufferView": 1, "componentType": 5126, "type": "SCALAR", "count": 2,
             "min": [0], "max": [2]},
            {"bufferView": 2, "componentType": 5126, "type": "VEC3", "count": 2},
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "nodes": [{"name": "ground", "mesh": 0, "children": [1]}, child],
        "scenes": [{"nodes": [0]}],
        "animations": [{
            "name": animation,
            "channels": [{"sampler": 0, "target": {"node": 1, "path": "translation"}}],
            "samplers": [{"input": 1, "output": 2}],
        }],
    });
    if let (Some(doc), Value::Object(extra)) = (doc.as_object_mut(), extra) {
        doc.extend(extra);
    }
    glb(&doc, &bin)
}

/// A `.glb` of two triangles: a static root "ground" and its child "mover", which the
/// animation "slide" translates 1 m along x over 2 s (issue 35's moving objects).
pub fn animated_glb() -> Vec<u8> {
    one_slide_glb(
        [0., 0., 0., 0., 0., 1., 1., 0., 0.],
        json!({"name": "mover", "mesh": 0, "translation": [0, 0.5, 0]}),
        "slide",
        ([0., 0., 0.], [1., 0., 0.]),
        json!({}),
    )
}

/// A `.glb` of a ground triangle (4 m legs, facing up) lit by a spot light on the node "lamp",
/// 1 m above it and aiming down, which the animation "swing" carries from (0.5, 1, 0.5) to
/// (2.5, 1, 2.5) over 2 s (issue 35: lights move with the nodes carrying them).
pub fn lamp_glb() -> Vec<u8> {
    let down = -std::f32::consts::FRAC_1_SQRT_2;
    one_slide_glb(
        [0., 0., 0., 0., 0., 4., 4., 0., 0.],
        // −90° about x turns the light's −z axis down.
        json!({"name": "lamp", "translation": [0.5, 1, 0.5], "rotation": [down, 0, 0, -down],
               "extensions": {"KHR_lights_punctual": {"light": 0}}}),
        "swing",
        ([0.5, 1., 0.5], [2.5, 1., 2.5]),
        json!({
            "extensionsUsed": ["KHR_lights_punctual"],
            "extensions": {"KHR_lights_punctual": {"lights": [
                {"type": "spot", "intensity": 20,
                 "spot": {"innerConeAngle": 0.3, "outerConeAngle": 0.6}}
            ]}},
        }),
    )
}
