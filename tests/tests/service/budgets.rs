//! Memory budgets and per-token quotas end to end: hostile uploads and parameters refused
//! before they take memory, budgets shared by every scene and given back with them, and one
//! token unable to take every slot.

use lightcast_e2e::{direct_session, glb, TestServer, PATIENCE};
use serde_json::{json, Value};
use std::time::Duration;
use tokio::io::AsyncWriteExt;

/// A solid `side`² PNG: tens of kilobytes that decode to 4·side² bytes.
fn solid_png(side: u32) -> Vec<u8> {
    let image = image::RgbaImage::from_pixel(side, side, image::Rgba([200, 120, 40, 255]));
    let mut out = std::io::Cursor::new(Vec::new());
    image
        .write_to(&mut out, image::ImageFormat::Png)
        .expect("encode PNG");
    out.into_inner()
}

/// A `.glb` of `images` quads, each textured with its own image of the same `png` bytes.
fn textured_quads(png: &[u8], images: usize) -> Vec<u8> {
    let floats = |v: &[f32]| v.iter().flat_map(|f| f.to_le_bytes()).collect::<Vec<u8>>();
    let positions = floats(&[0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.]);
    let uvs = floats(&[0., 1., 1., 1., 1., 0., 0., 0.]);
    let indices: Vec<u8> = [0u16, 1, 2, 0, 2, 3, 0, 0]
        .iter()
        .flat_map(|i| i.to_le_bytes())
        .collect();
    let bin = [positions, uvs, indices, png.to_vec()].concat();
    let primitives: Vec<Value> = (0..images)
        .map(|m| json!({"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": m}))
        .collect();
    let doc = json!({
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 32},
            {"buffer": 0, "byteOffset": 80, "byteLength": 12},
            {"buffer": 0, "byteOffset": 96, "byteLength": png.len()},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": 4,
             "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5126, "type": "VEC2", "count": 4},
            {"bufferView": 2, "componentType": 5123, "type": "SCALAR", "count": 6},
        ],
        "images": (0..images).map(|_| json!({"bufferView": 3, "mimeType": "image/png"})).collect::<Vec<_>>(),
        "textures": (0..images).map(|i| json!({"source": i})).collect::<Vec<_>>(),
        "materials": (0..images)
            .map(|i| json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": i}}}))
            .collect::<Vec<_>>(),
        "meshes": [{"primitives": primitives}],
        "nodes": [{"mesh": 0}],
    });
    glb(&doc, &bin)
}

/// A `.glb` whose only accessor is a POSITION of `count` zero-filled elements (no buffer view),
/// with a sparse substitution that makes elements 1 and 2 a real triangle with element 0.
fn zero_filled_positions(count: u64) -> Vec<u8> {
    let bin: Vec<u8> = [1f32, 0., 0., 0., 1., 0.]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .chain([1u32, 2].iter().flat_map(|i| i.to_le_bytes()))
        .collect();
    let doc = json!({
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 24},
            {"buffer": 0, "byteOffset": 24, "byteLength": 8},
        ],
        "accessors": [{
            "componentType": 5126, "type": "VEC3", "count": count,
            "sparse": {
                "count": 2,
                "indices": {"bufferView": 1, "componentType": 5125},
                "values": {"bufferView": 0},
            },
        }],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "nodes": [{"mesh": 0}],
    });
    glb(&doc, &bin)
}

/// Whether the error body's message passes `check`.
fn message_is(body: &Value, check: impl Fn(&str) -> bool) -> bool {
    check(body["message"].as_str().unwrap_or_default())
}

async fn upload(server: &TestServer, body: Vec<u8>, token: Option<&str>) -> (u16, Value) {
    let mut req = server
        .http
        .post(server.url("/v1/scenes"))
        .header("content-type", "model/gltf-binary")
        .body(body);
    if let Some(t) = token {
        req = req.bearer_auth(t);
    }
    let resp = req.send().await.expect("upload");
    let status = resp.status().as_u16();
    (status, resp.json().await.expect("JSON body"))
}

async fn post_json(server: &TestServer, path: &str, body: Value, token: &str) -> (u16, Value) {
    let resp = server
        .http
        .post(server.url(path))
        .bearer_auth(token)
        .json(&body)
        .send()
        .await
        .expect("request");
    let status = resp.status().as_u16();
    let body = resp.bytes().await.expect("body");
    (status, serde_json::from_slice(&body).unwrap_or(Value::Null))
}

fn tiny_render(method: &str, cache_distance: Option<f64>) -> Value {
    let mut gi = json!({"method": method, "rsm_size": 32, "val_count": 64, "view_samples": 16});
    if let Some(d) = cache_distance {
        gi["cache_distance"] = json!(d);
    }
    json!({"render": {"width": 16, "height": 16, "shadow_map_size": 256, "gi": gi}})
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hostile_uploads_and_cache_distances_are_refused_before_they_take_memory() {
    let server =
        TestServer::start(&["--max-scene-texture-bytes", &(20u64 << 20).to_string()]).await;

    // Two 4096² images in ~100 KB: each is kept at 2048² (16 MiB, not 64), and the second
    // crosses the scene's 20 MiB before it is decoded.
    let png = solid_png(4096);
    let one = textured_quads(&png, 1);
    assert!(one.len() < 512 << 10, "{} bytes", one.len());
    let (status, body) = upload(&server, textured_quads(&png, 2), None).await;
    assert_eq!(
        (status, body["error"].as_str()),
        (413, Some("texture_budget")),
        "{body}"
    );
    let message = body["message"].as_str().unwrap_or_default();
    assert!(
        message.contains("texture 1 (image 1)")
            && message.contains("kept at 2048×2048")
            && message.contains("--max-scene-texture-bytes"),
        "{message}"
    );
    let (status, body) = upload(&server, one, None).await;
    assert_eq!(status, 201, "one downscaled image fits: {body}");

    // Three million zero-filled positions in a few hundred bytes: refused before they are
    // allocated.
    let bomb = zero_filled_positions(3_000_000);
    assert!(bomb.len() < 1024);
    let (status, body) = upload(&server, bomb, None).await;
    assert_eq!(
        (status, body["error"].as_str()),
        (400, Some("invalid_scene")),
        "{body}"
    );
    assert!(
        message_is(&body, |m| m.contains("zero-filled")
            && m.contains("at most 1048576")),
        "{body}"
    );
    // Fewer are read, and the zero-area triangles they make are dropped with their vertices.
    let (status, body) = upload(&server, zero_filled_positions(600_000), None).await;
    assert_eq!(status, 201, "{body}");
    assert_eq!(
        (body["triangles"].as_u64(), body["vertices"].as_u64()),
        (Some(1), Some(3))
    );

    // A distance just above the smallest the format's own cap allows (what the server used
    // to suggest for a far too small one) makes ~2 million caches: refused by the per-set
    // budget before anything is queued, with a distance that fits.
    use lightcast_server::gi::common::triangles::surface_area;
    use lightcast_server::gi::lightskin::caches::{min_distance_for, MAX_CACHES};
    let area = surface_area(&lightcast_server::scene::procedural::cornell_box());
    let old_minimum = f64::from(min_distance_for(area, MAX_CACHES));
    for distance in [1e-6, old_minimum * 1.01] {
        let render = tiny_render("lightskin", Some(distance));
        let (status, body) = post_json(&server, "/v1/render", render, "").await;
        assert_eq!(status, 400, "{body}");
        assert_eq!(body["field"], "render.gi.cache_distance");
        let fits = min_distance_for(area, 250_000);
        assert!(
            message_is(&body, |m| m
                .contains("limit of 250000 per set (--max-caches-per-set)")
                && m.ends_with(&format!("use cache_distance >= {fits}"))),
            "{body}"
        );
    }
    let scene = server.get_json("/v1/scenes/default").await;
    assert_eq!(
        scene["caches"].as_array().map(Vec::len),
        Some(1),
        "only the default set was queued: {scene}"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn memory_budgets_are_shared_by_every_scene_shown_and_given_back() {
    let cornell = lightcast_server::scene::procedural::cornell_box().triangle_count() as u64;
    let server = TestServer::start(&[
        "--max-scene-texture-bytes",
        &(20u64 << 20).to_string(),
        "--max-total-texture-bytes",
        &(24u64 << 20).to_string(),
        "--max-total-triangles",
        &(cornell + 10).to_string(),
    ])
    .await;
    let limits = server.get_json("/v1/server").await["limits"].clone();
    assert_eq!(limits["max_texture_size"], 2048);
    assert_eq!(limits["max_scene_texture_bytes"], 20 << 20);
    assert_eq!(limits["max_total_texture_bytes"], 24 << 20);
    assert_eq!(limits["max_total_triangles"], cornell + 10);
    assert_eq!(limits["max_caches_per_set"], 250_000);
    assert_eq!(limits["max_total_caches"], 1_000_000);
    assert_eq!(
        limits["token_max_sessions"],
        Value::Null,
        "no quotas without auth"
    );

    let scene = textured_quads(&solid_png(4096), 1);
    let (status, first) = upload(&server, scene.clone(), None).await;
    assert_eq!(status, 201, "{first}");
    let (status, body) = upload(&server, scene.clone(), None).await;
    assert_eq!(
        (status, body["error"].as_str()),
        (413, Some("texture_budget")),
        "{body}"
    );
    assert!(
        message_is(&body, |m| m.contains("--max-total-texture-bytes")),
        "{body}"
    );
    // A one-block street has 130 triangles (68 for the block, 62 for its parked car): more
    // than the 8 left beside the default scene and the quad.
    let street = json!({"procedural": "street?blocks=1"});
    let (status, body) = post_json(&server, "/v1/scenes", street, "").await;
    assert_eq!(
        (status, body["error"].as_str()),
        (413, Some("triangle_budget")),
        "{body}"
    );
    // Six quads, 12 triangles: refused at the fifth, before it is read.
    let (status, body) = upload(&server, textured_quads(&solid_png(4), 6), None).await;
    assert_eq!(
        (status, body["error"].as_str()),
        (413, Some("triangle_budget")),
        "{body}"
    );
    assert!(
        message_is(&body, |m| m.contains("primitive 4:")
            && m.contains("--max-total-triangles")),
        "{body}"
    );

    let id = first["id"].as_str().expect("id");
    let resp = server.delete(&format!("/v1/scenes/{id}")).await;
    assert_eq!(resp.status(), 204);
    // Given back when the scene's memory is freed: at once, or when a light-cache
    // precomputation that holds it ends.
    until(
        "201",
        |status, _| status == 201,
        async || upload(&server, scene.clone(), None).await,
    )
    .await;
    server.stop().await;
}

/// Sends the headers of a POST with a `Content-Length` body and only its first bytes, and
/// keeps the connection open: the request stays in flight until the stream is dropped. The
/// body is a scene upload's (`/v1/scenes`) or JSON within the message limit (`/v1/render`).
async fn stalled_post(server: &TestServer, path: &str, token: &str) -> tokio::net::TcpStream {
    let (content_type, length) = if path == "/v1/render" {
        ("application/json", 1000)
    } else {
        ("model/gltf-binary", 100_000)
    };
    let addr = server.base.trim_start_matches("http://");
    let mut stream = tokio::net::TcpStream::connect(addr).await.expect("connect");
    let head = format!(
        "POST {path} HTTP/1.1\r\nHost: {addr}\r\nAuthorization: Bearer {token}\r\n\
         Content-Type: {content_type}\r\nContent-Length: {length}\r\n\r\n{{"
    );
    stream.write_all(head.as_bytes()).await.expect("send");
    stream
}

/// Retries `attempt` until its answer is `done` (budgets are given back when the server frees
/// a scene, not at once).
async fn until(
    what: &str,
    done: impl Fn(u16, &Value) -> bool,
    mut attempt: impl AsyncFnMut() -> (u16, Value),
) {
    tokio::time::timeout(PATIENCE, async {
        loop {
            let (status, body) = attempt().await;
            if done(status, &body) {
                return;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    })
    .await
    .unwrap_or_else(|_| panic!("no {what} answer"));
}

/// A request to `path` of `token`, stalled mid-body, that holds a place: `probe` (another
/// request of the token) is answered with the error kind `refusal`. A stalled request that
/// arrived while an earlier probe held the place was refused itself (it has an answer on
/// its socket); it is sent again.
async fn stalled_holding_a_place(
    server: &TestServer,
    path: &str,
    token: &str,
    refusal: &str,
    mut probe: impl AsyncFnMut() -> (u16, Value),
) -> tokio::net::TcpStream {
    tokio::time::timeout(PATIENCE, async {
        let mut stalled = stalled_post(server, path, token).await;
        loop {
            if probe().await.1["error"] == refusal {
                return stalled;
            }
            let mut byte = [0u8; 1];
            match stalled.try_read(&mut byte) {
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
                _ => stalled = stalled_post(server, path, token).await,
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    })
    .await
    .unwrap_or_else(|_| panic!("no '{refusal}' answer"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_token_cannot_take_every_slot() {
    let alice = "alice-token-0123456789";
    let bob = "bob-token-9876543210xx";
    let server = TestServer::start(&[
        "--token",
        &format!("{alice},{bob}"),
        "--max-sessions",
        "4",
        "--max-scenes",
        "5",
        "--token-max-uploads",
        "1",
        "--token-max-renders",
        "1",
    ])
    .await;
    let resp = server
        .http
        .get(server.url("/v1/server"))
        .bearer_auth(alice)
        .send()
        .await
        .expect("server info");
    let limits = resp.json::<Value>().await.expect("JSON")["limits"].clone();
    assert_eq!(
        limits["token_max_sessions"], 2,
        "fair share of 4 for 2 tokens"
    );
    assert_eq!(
        limits["token_max_scenes"], 2,
        "fair share of the 4 uploadable"
    );
    assert_eq!(limits["token_max_uploads"], 1);
    assert_eq!(limits["token_max_renders"], 1);

    // Uploads in flight: one of alice's, stalled mid-body, holds her only place. The probe is
    // not a scene, so once admitted it is refused as such and holds nothing.
    let junk = b"not a scene".to_vec();
    let probe = async || upload(&server, junk.clone(), Some(alice)).await;
    let stalled =
        stalled_holding_a_place(&server, "/v1/scenes", alice, "upload_quota", probe).await;
    let (status, body) = upload(&server, junk.clone(), Some(alice)).await;
    assert_eq!(
        (status, body["error"].as_str()),
        (429, Some("upload_quota")),
        "{body}"
    );
    assert!(message_is(&body, |m| m.contains("--token-max-uploads")));
    let (status, body) = upload(&server, junk.clone(), Some(bob)).await;
    assert_eq!(
        (status, body["error"].as_str()),
        (400, Some("invalid_scene")),
        "bob uploads: {body}"
    );
    drop(stalled);
    until(
        "invalid_scene",
        |_, body| body["error"] == "invalid_scene",
        async || upload(&server, junk.clone(), Some(alice)).await,
    )
    .await;

    // One-shot renders, likewise.
    let mut bad_render = tiny_render("none", None);
    bad_render["render"]["width"] = json!(0);
    let probe = async || post_json(&server, "/v1/render", bad_render.clone(), alice).await;
    let stalled =
        stalled_holding_a_place(&server, "/v1/render", alice, "render_quota", probe).await;
    let (status, _) = post_json(&server, "/v1/render", tiny_render("none", None), bob).await;
    assert_eq!(status, 200, "bob renders meanwhile");
    drop(stalled);
    until(
        "invalid_field",
        |_, body| body["error"] == "invalid_field",
        async || post_json(&server, "/v1/render", bad_render.clone(), alice).await,
    )
    .await;

    // Sessions.
    for _ in 0..2 {
        server
            .create_session(direct_session(16, 16), Some(alice))
            .await;
    }
    let (status, body) = post_json(&server, "/v1/sessions", direct_session(16, 16), alice).await;
    assert_eq!(
        (status, body["error"].as_str()),
        (429, Some("session_quota")),
        "{body}"
    );
    assert!(message_is(&body, |m| m.contains("--token-max-sessions")));
    // Quota refusals are 429s like the server's own limits, so they carry Retry-After too.
    let resp = server
        .http
        .post(server.url("/v1/sessions"))
        .bearer_auth(alice)
        .json(&direct_session(16, 16))
        .send()
        .await
        .expect("request");
    assert_eq!(resp.status(), 429);
    assert_eq!(resp.headers()["retry-after"], "2");
    server
        .create_session(direct_session(16, 16), Some(bob))
        .await;

    // Scenes.
    let street = json!({"procedural": "street?blocks=1"});
    for _ in 0..2 {
        let (status, body) = post_json(&server, "/v1/scenes", street.clone(), alice).await;
        assert_eq!(status, 201, "{body}");
    }
    let (status, body) = post_json(&server, "/v1/scenes", street.clone(), alice).await;
    assert_eq!(
        (status, body["error"].as_str()),
        (429, Some("scene_quota")),
        "{body}"
    );
    let (status, body) = post_json(&server, "/v1/scenes", street, bob).await;
    assert_eq!(status, 201, "{body}");
    server.stop().await;
}
