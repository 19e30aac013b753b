//! Bad input over HTTP and WebSocket: each gets a precise error (status, kind and the full
//! field path) and the server keeps serving.

use super::api::render_small;
use futures_util::SinkExt;
use lightcast_e2e::{cornell_glb, small_session, TestServer};
use serde_json::{json, Value};
use tokio_tungstenite::tungstenite::Message;

/// A ~50 KB GLB whose 1,000 primitives reuse one index accessor of 10 million zero-filled
/// entries (allowed when it is sparse): billions of triangles from a small upload.
fn reused_accessor_bomb() -> Vec<u8> {
    let sparse = json!({
        "count": 1,
        "indices": {"bufferView": 0, "componentType": 5125},
        "values": {"bufferView": 0},
    });
    let primitive = json!({"attributes": {"POSITION": 0}, "indices": 1});
    let doc = json!({
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": 16}],
        "bufferViews": [{"buffer": 0, "byteLength": 16}],
        "accessors": [
            {"componentType": 5126, "type": "VEC3", "count": 3, "sparse": sparse},
            {"componentType": 5125, "type": "SCALAR", "count": 9_999_999, "sparse": sparse},
        ],
        "meshes": [{"primitives": vec![primitive; 1000]}],
        "nodes": [{"mesh": 0}],
    });
    let mut json = serde_json::to_vec(&doc).expect("serialise");
    json.resize(json.len().next_multiple_of(4), b' ');
    let chunk =
        |kind: &[u8; 4], data: &[u8]| [&(data.len() as u32).to_le_bytes()[..], kind, data].concat();
    let body = [chunk(b"JSON", &json), chunk(b"BIN\0", &[0; 16])].concat();
    let length = 12 + body.len() as u32;
    let header = [&b"glTF"[..], &2u32.to_le_bytes(), &length.to_le_bytes()].concat();
    [header, body].concat()
}

struct Case {
    method: &'static str,
    path: String,
    content_type: &'static str,
    body: Vec<u8>,
    status: u16,
    error: &'static str,
    field: Option<&'static str>,
}

fn case(
    method: &'static str,
    path: &str,
    body: impl Into<Vec<u8>>,
    status: u16,
    error: &'static str,
    field: Option<&'static str>,
) -> Case {
    Case {
        method,
        path: path.to_string(),
        content_type: "application/json",
        body: body.into(),
        status,
        error,
        field,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_inputs_get_precise_errors_and_the_server_keeps_serving() {
    let server = TestServer::start(&[
        "--max-upload-bytes",
        "200000",
        "--max-message-bytes",
        "4096",
    ])
    .await;
    let created = server.create_session(small_session(32, 32), None).await;
    let session = format!("/v1/sessions/{}", created.session.id);
    let glb = cornell_glb();
    let mut truncated_glb = case(
        "POST",
        "/v1/scenes",
        glb[..glb.len() / 2].to_vec(),
        400,
        "invalid_scene",
        None,
    );
    truncated_glb.content_type = "model/gltf-binary";
    let mut bad_magic = glb.clone();
    bad_magic[20..24].copy_from_slice(b"XXXX");
    let mut hostile_glb = case("POST", "/v1/scenes", bad_magic, 400, "invalid_scene", None);
    hostile_glb.content_type = "model/gltf-binary";
    let mut garbage_upload = case(
        "POST",
        "/v1/scenes",
        vec![0xff, 0x00, 0x13, 0x37],
        400,
        "invalid_scene",
        None,
    );
    garbage_upload.content_type = "application/octet-stream";
    let mut bomb = case(
        "POST",
        "/v1/scenes",
        reused_accessor_bomb(),
        400,
        "invalid_scene",
        None,
    );
    bomb.content_type = "model/gltf-binary";
    let mut too_big = case(
        "POST",
        "/v1/scenes",
        vec![0u8; 300_000],
        413,
        "too_large",
        None,
    );
    too_big.content_type = "application/octet-stream";
    let cases = vec![
        case(
            "POST",
            "/v1/sessions",
            "{bad json",
            400,
            "malformed_json",
            None,
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"width":0}}"#,
            400,
            "invalid_field",
            Some("render.width"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"width":100000}}"#,
            400,
            "invalid_field",
            Some("render.width"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"height":-3}}"#,
            400,
            "invalid_field",
            Some("render.height"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"widht":64}}"#,
            400,
            "invalid_field",
            Some("render.widht"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"colour":"red"}"#,
            400,
            "invalid_field",
            Some("colour"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"gi":{"rsm_size":1000000}}}"#,
            400,
            "invalid_field",
            Some("render.gi.rsm_size"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"gi":{"val_count":0}}}"#,
            400,
            "invalid_field",
            Some("render.gi.val_count"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"gi":{"view_samples":99999999}}}"#,
            400,
            "invalid_field",
            Some("render.gi.view_samples"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"gi":{"method":"photon"}}}"#,
            400,
            "invalid_field",
            Some("render.gi.method"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"gi":{"method":"brsm","indirect_downscale":3}}}"#,
            400,
            "invalid_field",
            Some("render.gi.indirect_downscale"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"gi":{"defensive":2}}}"#,
            400,
            "invalid_field",
            Some("render.gi.defensive"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"gi":{"cache_distance":1e-9}}}"#,
            400,
            "invalid_field",
            Some("render.gi.cache_distance"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"gi":{"cache_angle":120}}}"#,
            400,
            "invalid_field",
            Some("render.gi.cache_angle"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"gi":{"glossy_exponent":-4}}}"#,
            400,
            "invalid_field",
            Some("render.gi.glossy_exponent"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"camera":{"position":[1e39,0,0],"target":[0,0,0],"fov_y_degrees":45}}}"#,
            400,
            "invalid_field",
            Some("render.camera.position"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"camera":{"position":[0,0,1],"target":[0,0,1],"fov_y_degrees":45}}}"#,
            400,
            "invalid_field",
            Some("render.camera.target"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"camera":{"position":[0,0,1],"target":[0,0,0],"fov_y_degrees":0}}}"#,
            400,
            "invalid_field",
            Some("render.camera.fov_y_degrees"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"camera":{"position":[0,0,NaN],"target":[0,0,0],"fov_y_degrees":45}}}"#,
            400,
            "invalid_field",
            Some("render.camera.position[2]"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"light":{"kind":"laser","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0}}}"#,
            400,
            "invalid_field",
            Some("render.light.kind"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"light":{"kind":"sun","position":[0,1,0]}}}"#,
            400,
            "invalid_field",
            Some("render.light.kind"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"light":{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[-1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0}}}"#,
            400,
            "invalid_field",
            Some("render.light.color"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"lights":[{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"spot","position":[0,1,0],"direction":[0,-1,0],"color":[-1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0.5}]}}"#,
            400,
            "invalid_field",
            Some("render.lights[1].color"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"width":16,"height":16,"lights":[{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0}]}}"#,
            400,
            "invalid_field",
            Some("render.lights"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"environment":{"kind":"moon"}}}"#,
            400,
            "invalid_field",
            Some("render.environment.kind"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"environment":{"kind":"sky","turbidity":12}}}"#,
            400,
            "invalid_field",
            Some("render.environment.turbidity"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"width":16,"height":16,"environment":{"kind":"sky"},"light":{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0}}}"#,
            400,
            "invalid_field",
            Some("render.environment.kind"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"environment":{"intensity":-1}}}"#,
            400,
            "invalid_field",
            Some("render.environment.intensity"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"environment":{"intensity":1e35}}}"#,
            400,
            "invalid_field",
            Some("render.environment.intensity"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"environment":{"directions":16}}}"#,
            400,
            "invalid_field",
            Some("render.environment.directions"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"lights":3}}"#,
            400,
            "invalid_field",
            Some("render.lights"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"light":{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0},"lights":[{"kind":"point","position":[0,1,0],"direction":[0,-1,0],"color":[1,1,1],"intensity":1,"inner_cone":0,"outer_cone":0}]}}"#,
            400,
            "invalid_field",
            Some("render.lights"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"scene":"no-such-scene"}}"#,
            400,
            "invalid_field",
            Some("render.scene"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"view":"importance","gi":{"method":"lightskin"}}}"#,
            400,
            "invalid_field",
            Some("render.view"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"render":{"exposure":-1}}"#,
            400,
            "invalid_field",
            Some("render.exposure"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"fps_cap":0}"#,
            400,
            "invalid_field",
            Some("fps_cap"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"fps_cap":100000}"#,
            400,
            "invalid_field",
            Some("fps_cap"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"encoding":{"quality":0}}"#,
            400,
            "invalid_field",
            Some("encoding.quality"),
        ),
        case(
            "POST",
            "/v1/sessions",
            r#"{"encoding":{"codec":"gif"}}"#,
            400,
            "invalid_field",
            Some("encoding.codec"),
        ),
        case(
            "POST",
            "/v1/sessions",
            format!(r#"{{"pad":"{}"}}"#, "x".repeat(8000)),
            413,
            "too_large",
            None,
        ),
        case(
            "PATCH",
            &session,
            r#"{"render":{"gi":{"rsm_size":"big"}}}"#,
            400,
            "invalid_field",
            Some("render.gi.rsm_size"),
        ),
        case(
            "PATCH",
            &session,
            r#"{"render":{"gi":{"rsm_sise":64}}}"#,
            400,
            "invalid_field",
            Some("render.gi.rsm_sise"),
        ),
        case(
            "PATCH",
            &session,
            r#"{"render":{"gi":{"method":"fancy"}}}"#,
            400,
            "invalid_field",
            Some("render.gi.method"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"fancy"}}}"#,
            400,
            "invalid_field",
            Some("render.gi.method"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"Fancy-1"}}}"#,
            400,
            "invalid_field",
            Some("render.gi.method"),
        ),
        case("PATCH", &session, "[1,2,3]", 400, "malformed_json", None),
        case(
            "PATCH",
            "/v1/sessions/se_0000000000000000",
            "{}",
            404,
            "not_found",
            None,
        ),
        case("GET", "/v1/sessions/nope", "", 404, "not_found", None),
        case("DELETE", "/v1/scenes/default", "", 409, "conflict", None),
        case("DELETE", "/v1/scenes/unknown", "", 404, "not_found", None),
        case("GET", "/v1/nothing-here", "", 404, "not_found", None),
        case("PUT", "/v1/scenes", "", 405, "method_not_allowed", None),
        case(
            "POST",
            "/v1/scenes",
            r#"{"procedural":"street?blocks=100000"}"#,
            400,
            "invalid_field",
            Some("procedural"),
        ),
        case(
            "POST",
            "/v1/scenes",
            r#"{"procedural":"street?blocks=2000&detail=64"}"#,
            400,
            "invalid_field",
            Some("procedural"),
        ),
        case(
            "POST",
            "/v1/scenes",
            r#"{"procedural":"teapot"}"#,
            400,
            "invalid_field",
            Some("procedural"),
        ),
        truncated_glb,
        hostile_glb,
        garbage_upload,
        bomb,
        too_big,
        case(
            "POST",
            "/v1/render",
            r#"{"format":"raw_indirect","render":{"gi":{"method":"none"}}}"#,
            400,
            "invalid_field",
            Some("format"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"compare_to":"brsm"}"#,
            400,
            "invalid_field",
            Some("compare_to"),
        ),
        // Moving nodes (issue 35): unknown, not movable, huge, degenerate, misspelt, too
        // many, parameters whose data holds the rest pose only.
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"nodes":[{"node":7}]}}"#,
            400,
            "invalid_field",
            Some("render.nodes[0].node"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"nodes":[{"node":1},{"node":0,"translation":[0,0,0]}]}}"#,
            400,
            "invalid_field",
            Some("render.nodes[1].node"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"nodes":[{"node":1,"translation":[1e30,0,0]}]}}"#,
            400,
            "invalid_field",
            Some("render.nodes[0].translation"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"nodes":[{"node":1,"scale":[0,1,1]}]}}"#,
            400,
            "invalid_field",
            Some("render.nodes[0].scale"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"nodes":[{"node":1,"rotation":[0,0,0,0]}]}}"#,
            400,
            "invalid_field",
            Some("render.nodes[0].rotation"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"nodes":[{"node":1,"size":2}]}}"#,
            400,
            "invalid_field",
            Some("render.nodes[0].size"),
        ),
        case(
            "POST",
            "/v1/render",
            format!(
                r#"{{"render":{{"nodes":[{}]}}}}"#,
                vec![r#"{"node":1}"#; 10_000].join(",")
            ),
            413,
            "too_large",
            None,
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"lightskin","cache_visibility":8},"nodes":[{"node":1,"translation":[0,0.3,0]}]}}"#,
            400,
            "invalid_field",
            Some("render.gi.cache_visibility"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"compare_modelled":true}"#,
            400,
            "invalid_field",
            Some("compare_modelled"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"compare_to":"reference","compare_modelled":"yes"}"#,
            400,
            "invalid_field",
            Some("compare_modelled"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"compare_to":"reference","compare_spp":0}"#,
            400,
            "invalid_field",
            Some("compare_spp"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"reference","spp":100000}}}"#,
            400,
            "invalid_field",
            Some("render.gi.spp"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"clustered","vpl_count":100}}}"#,
            400,
            "invalid_field",
            Some("render.gi.vpl_count"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"clustered","cluster_count":0}}}"#,
            400,
            "invalid_field",
            Some("render.gi.cluster_count"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"clustered","blur_normal":1.5}}}"#,
            400,
            "invalid_field",
            Some("render.gi.blur_normal"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"clustered","cluster_position_weight":0,"cluster_normal_weight":0}}}"#,
            400,
            "invalid_field",
            Some("render.gi.cluster_position_weight"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"clustered","visibility":"sometimes"}}}"#,
            400,
            "invalid_field",
            Some("render.gi.visibility"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"clustered","paraboloid_size":100}}}"#,
            400,
            "invalid_field",
            Some("render.gi.paraboloid_size"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"clustered","cluster_count":256,"paraboloid_size":512}}}"#,
            400,
            "invalid_field",
            Some("render.gi.paraboloid_size"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"clustered","visibility":"vpl_shadows","vpl_count":16384,"paraboloid_size":256}}}"#,
            400,
            "invalid_field",
            Some("render.gi.paraboloid_size"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"clustered","fourier_terms":5}}}"#,
            400,
            "invalid_field",
            Some("render.gi.fourier_terms"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"gi":{"method":"clustered","cluster_count":8,"shadow_light":8}}}"#,
            400,
            "invalid_field",
            Some("render.gi.shadow_light"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"quality":101}"#,
            400,
            "invalid_field",
            Some("quality"),
        ),
        case(
            "POST",
            "/v1/render",
            r#"{"render":{"shadow_map_size":8}}"#,
            400,
            "invalid_field",
            Some("render.shadow_map_size"),
        ),
        case(
            "GET",
            &format!("{session}/stream"),
            "",
            426,
            "websocket_required",
            None,
        ),
    ];
    assert!(cases.len() >= 25);
    // Every case is checked and reported on its own; the test fails listing all that failed.
    let mut failures = Vec::new();
    for c in &cases {
        if let Err(e) = check(&server, c).await {
            failures.push(e);
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} bad inputs were not refused as expected:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
    keeps_serving(&server).await;
    server.stop().await;
}

/// The server still answers its health check and renders.
async fn keeps_serving(server: &TestServer) {
    let health = server
        .http
        .get(server.url("/healthz"))
        .send()
        .await
        .expect("healthz");
    assert_eq!(health.status(), 200);
    let (_, png) = render_small(server).await;
    assert!(!png.is_empty());
}

/// Sends `c` and compares the answer with what it expects.
async fn check(server: &TestServer, c: &Case) -> Result<(), String> {
    let method = reqwest::Method::from_bytes(c.method.as_bytes()).expect("method");
    let shown = String::from_utf8_lossy(&c.body[..c.body.len().min(120)]).into_owned();
    let at = format!("{} {} {shown}", c.method, c.path);
    let resp = server
        .http
        .request(method, server.url(&c.path))
        .header("content-type", c.content_type)
        .body(c.body.clone())
        .send()
        .await
        .map_err(|e| format!("{at}: {e}"))?;
    let status = resp.status().as_u16();
    let text = resp.text().await.map_err(|e| format!("{at}: {e}"))?;
    let body: Value =
        serde_json::from_str(&text).map_err(|_| format!("{at}: not JSON ({status}): {text}"))?;
    let got = (status, body["error"].as_str(), body["field"].as_str());
    if got != (c.status, Some(c.error), c.field) {
        return Err(format!(
            "{at}: expected {} {} {:?}, got {got:?}: {text}",
            c.status, c.error, c.field
        ));
    }
    if body["message"].as_str().is_none_or(str::is_empty) {
        return Err(format!("{at}: no message: {text}"));
    }
    Ok(())
}

/// The WebSocket: garbage in, precise error events out, the session goes on; an oversized
/// message or text that is not UTF-8 closes only that socket, and the server keeps serving.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_websocket_messages_get_precise_errors_and_the_server_keeps_serving() {
    let server = TestServer::start(&["--max-message-bytes", "4096"]).await;
    let created = server.create_session(small_session(32, 32), None).await;
    let mut stream = server.connect(&created).await;
    stream
        .send_raw(Message::Binary(vec![0xde, 0xad, 0xbe, 0xef].into()))
        .await;
    stream.send_raw(Message::Text("not json".into())).await;
    stream.send(json!({"type": "teleport"})).await;
    stream.send(json!({"type": "camera", "camera": {"position": [0, 0, 0], "target": [0, 0, 0], "fov_y_degrees": 45}})).await;
    stream
        .send(json!({"type": "update", "patch": {"render": {"gi": {"val_count": -1}}}}))
        .await;
    stream
        .send(json!({"type": "camera", "camera": {"position": [0, 0, 1], "target": [0, 0, 0], "fov_y_degrees": 45, "zoom": 2}}))
        .await;
    stream
        .send(json!({"type": "ping", "nonce": 1, "extra": true}))
        .await;
    // Values refused inside a message are named as the HTTP API names them (issue 30).
    stream.send(json!({"type": "ack", "seq": -1})).await;
    stream
        .send(json!({"type": "camera", "camera": {"position": ["x", 0, 1], "target": [0, 0, 0], "fov_y_degrees": 45}}))
        .await;
    stream
        .send_raw(Message::Text(
            r#"{"type": "camera", "camera": {"position": [NaN, 0, 1], "target": [0, 0, 0], "fov_y_degrees": 45}}"#.into(),
        ))
        .await;
    stream
        .send_raw(Message::Text(
            r#"{"type": "light", "light": {"kind": "point", "position": [0, 1e999, 0]}}"#.into(),
        ))
        .await;
    stream
        .send(json!({"type": "camera", "input_id": -2, "camera": {"position": [0, 0, 1], "target": [0, 0, 0], "fov_y_degrees": 45}}))
        .await;
    // The built-in scene has one light: index 1 is not one of the session's.
    stream
        .send(json!({"type": "light", "index": 1, "light": {"kind": "point", "position": [0, 1, 0], "direction": [0, -1, 0], "color": [1, 1, 1], "intensity": 1, "inner_cone": 0, "outer_cone": 0}}))
        .await;
    // Nodes (issue 35): an unknown one, a zero quaternion, a zero scale.
    stream
        .send(json!({"type": "nodes", "nodes": [{"node": 9}]}))
        .await;
    stream
        .send(
            json!({"type": "nodes", "nodes": [{"node": 1}, {"node": 2, "rotation": [0, 0, 0, 0]}]}),
        )
        .await;
    stream
        .send(json!({"type": "nodes", "nodes": [{"node": 1, "scale": [0, 1, 1]}]}))
        .await;
    // Picks outside the frame.
    stream
        .send(json!({"type": "pick", "x": 1.5, "y": 0.5}))
        .await;
    stream
        .send(json!({"type": "pick", "x": 0.5, "y": -0.1}))
        .await;
    let expected = [
        ("binary_not_accepted", None),
        ("malformed_json", None),
        ("invalid_field", Some("type")),
        ("invalid_field", Some("render.camera.target")),
        ("invalid_field", Some("render.gi.val_count")),
        ("invalid_field", Some("render.camera.zoom")),
        ("invalid_field", Some("extra")),
        ("invalid_field", Some("seq")),
        ("invalid_field", Some("render.camera.position[0]")),
        ("invalid_field", Some("render.camera.position[0]")),
        ("invalid_field", Some("render.light.position[1]")),
        ("invalid_field", Some("input_id")),
        ("invalid_field", Some("index")),
        ("invalid_field", Some("nodes[0].node")),
        ("invalid_field", Some("nodes[1].rotation")),
        ("invalid_field", Some("nodes[0].scale")),
        ("invalid_field", Some("x")),
        ("invalid_field", Some("y")),
    ];
    for (kind, field) in expected {
        let error = stream.next_error().await;
        assert_eq!(error.error, kind, "{error:?}");
        assert_eq!(error.field.as_deref(), field, "{error:?}");
    }
    let mut events = Vec::new();
    let frame = stream.next_frame(&mut events).await;
    assert_eq!(frame.header.width, 32);
    // An oversized message closes only that socket, saying why (1009); so does text that is
    // not UTF-8 (1007); the server keeps serving.
    stream
        .ws
        .send(Message::Text("x".repeat(10_000).into()))
        .await
        .ok();
    assert_eq!(
        stream.close_code().await,
        Some(1009),
        "an oversized message"
    );
    let other = server.create_session(small_session(32, 32), None).await;
    let mut stream = server.connect(&other).await;
    let not_utf8 = tokio_tungstenite::tungstenite::protocol::frame::Frame::message(
        vec![b'{', 0xff, 0xfe, b'}'],
        tokio_tungstenite::tungstenite::protocol::frame::coding::OpCode::Data(
            tokio_tungstenite::tungstenite::protocol::frame::coding::Data::Text,
        ),
        true,
    );
    stream.ws.send(Message::Frame(not_utf8)).await.ok();
    assert_eq!(
        stream.close_code().await,
        Some(1007),
        "text that is not UTF-8"
    );

    keeps_serving(&server).await;
    server.stop().await;
}
