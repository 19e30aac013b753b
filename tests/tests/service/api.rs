//! The HTTP API end to end: one-shot renders, scenes, auth, metrics, OpenAPI (bad input: `bad_inputs`).

use lightcast_e2e::{
    cornell_glb, direct_session, glb_to_gltf, small_session, Incoming, TestServer, PATIENCE,
};
use lightcast_protocol::{EnvironmentKind, RenderReport, Senders, ServerEvent};
use serde_json::{json, Value};
use std::time::Duration;
use tokio_tungstenite::tungstenite::Message;

fn report(resp: &reqwest::Response) -> RenderReport {
    let header = resp
        .headers()
        .get("x-lightcast-report")
        .expect("report header")
        .to_str()
        .expect("ASCII header");
    serde_json::from_str(header).expect("RenderReport JSON")
}

/// A multipart scene upload: a `.gltf` named `gltf_name` and its buffer `box.bin`.
fn gltf_upload(gltf: Vec<u8>, gltf_name: &str, bin: Vec<u8>) -> reqwest::multipart::Form {
    let part =
        |bytes, name: &str| reqwest::multipart::Part::bytes(bytes).file_name(name.to_string());
    reqwest::multipart::Form::new()
        .part("scene", part(gltf, gltf_name))
        .part("bin", part(bin, "box.bin"))
}

/// The sum of every pixel's RGB in a `raw_indirect` (or `raw_final`) body: float32 RGBA.
fn raw_sum(bytes: &[u8]) -> f64 {
    bytes
        .chunks_exact(16)
        .flat_map(|px| px[..12].chunks_exact(4))
        .map(|c| f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])))
        .sum()
}

async fn render(server: &TestServer, body: &Value) -> (RenderReport, Vec<u8>) {
    let resp = server
        .http
        .post(server.url("/v1/render"))
        .json(body)
        .send()
        .await
        .expect("render request");
    assert_eq!(resp.status(), 200, "render {body}");
    let report = report(&resp);
    (report, resp.bytes().await.expect("image").to_vec())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_shot_renders_are_reproducible_and_report_what_ran() {
    let server = TestServer::start(&[]).await;
    let request = json!({
        "render": {"width": 80, "height": 60, "shadow_map_size": 256,
                   "gi": {"rsm_size": 32, "val_count": 256, "view_samples": 64}},
        "format": "png"
    });
    let (a, png_a) = render(&server, &request).await;
    let (b, png_b) = render(&server, &request).await;
    assert_eq!(a.request_hash, b.request_hash);
    let (img_a, img_b) = (
        image::load_from_memory(&png_a).expect("png").to_rgba8(),
        image::load_from_memory(&png_b).expect("png").to_rgba8(),
    );
    assert_eq!(img_a.dimensions(), (80, 60));
    assert_eq!(img_a.as_raw(), img_b.as_raw(), "same request, same pixels");
    assert!(a.build.starts_with("lightcast-server "), "{}", a.build);
    assert!(!a.adapter.is_empty());
    assert!(a.stages.iter().any(|s| s.stage == "cache_lighting"));
    assert!(a.gpu_ms > 0.0);

    // Another camera: another hash and other pixels.
    let mut moved = request.clone();
    moved["render"]["camera"] =
        json!({"position": [0.5, 1.2, 3.0], "target": [0, 1, 0], "fov_y_degrees": 45});
    let (c, png_c) = render(&server, &moved).await;
    assert_ne!(c.request_hash, a.request_hash);
    assert_ne!(png_c, png_a);

    // Raw float buffers for analysis: indirect light alone, 16 bytes per pixel, finite, lit.
    let mut raw = request.clone();
    raw["format"] = json!("raw_indirect");
    let (r, bytes) = render(&server, &raw).await;
    assert_eq!(bytes.len(), 80 * 60 * 16);
    let floats: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    assert!(floats.iter().all(|v| v.is_finite()));
    assert!(
        floats.iter().any(|&v| v > 0.0),
        "indirect light is not all black"
    );
    assert_eq!(r.width, 80);

    // JPEG answers with its content type.
    let mut jpeg = request.clone();
    jpeg["format"] = json!("jpeg");
    jpeg["quality"] = json!(50);
    let resp = server
        .http
        .post(server.url("/v1/render"))
        .json(&jpeg)
        .send()
        .await
        .expect("jpeg render");
    assert_eq!(resp.headers()["content-type"], "image/jpeg");
    server.stop().await;
}

/// Issue 31: a one-shot `reference` that names no `spp` takes as many samples as half the
/// request budget buys (here, on a tiny frame, the most the server allows) and its report says
/// how noisy it still is; one that names its `spp` takes exactly those.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_one_shot_reference_without_spp_takes_what_the_budget_buys() {
    let server = TestServer::start(&[]).await;
    let limits = server.get_json("/v1/server").await["limits"].clone();
    let max_spp = limits["max_spp"].as_u64().expect("max_spp");
    let body = |gi: Value| json!({"render": {"width": 16, "height": 12, "gi": gi}});
    let (auto, _) = render(&server, &body(json!({"method": "reference"}))).await;
    let (four, _) = render(&server, &body(json!({"method": "reference", "spp": 4}))).await;
    assert_eq!(four.samples, Some(4));
    assert_eq!(auto.samples.map(u64::from), Some(max_spp), "{auto:?}");
    let (auto_error, four_error) = (
        auto.relative_error.expect("auto's noise"),
        four.relative_error.expect("4 spp's noise"),
    );
    // The noise falls as 1/√spp.
    assert!(
        auto_error > 0.0 && auto_error < 0.5 * four_error,
        "{auto_error} vs {four_error}"
    );
    server.stop().await;
}

/// `compare_to: reference` reports a method's errors against the path-traced reference lit by
/// the same sources; the reference itself compared with an equal reference has none (same
/// seed, same pixels), and a repeated comparison (served from the cache) reports the same
/// numbers.
/// Every method lights from every light: for each method `/v1/server` lists (at its small
/// setting, emitters off so only the punctual lights count), the indirect light of two lights
/// (the scene's spot and a point light) sums to within 20 % of the two alone, and the second
/// light adds at least a fifth of its own share (a method that ignored it would add none).
/// Sampling methods (BRSM's importance, clustered's k-means) are not exactly additive, hence
/// the band; the reference and the gather are exact up to noise.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_method_lights_from_every_light() {
    use lightcast_server::gi::{self, precompute::SceneFacts};
    let server = TestServer::start(&[]).await;
    let info = server.get_json("/v1/server").await;
    let facts = SceneFacts::of(&lightcast_server::scene::procedural::cornell_box());
    let scene = server.get_json("/v1/scenes/default").await;
    let spot = scene["default_light"].clone();
    let mut point = spot.clone();
    point["kind"] = json!("point");
    point["position"] = json!([0.0, 1.0, 0.0]);
    point["intensity"] = json!(spot["intensity"].as_f64().expect("intensity") * 0.5);
    for m in info["gi_methods"].as_array().expect("gi_methods") {
        let method = gi::parse_method(m["method"].as_str().expect("a name")).expect("registered");
        if method == gi::none::NONE {
            continue;
        }
        let mut small =
            serde_json::to_value((gi::table(method).testing.small)(&facts)).expect("json");
        small["emitters"] = json!(false);
        let indirect = |lights: Value| {
            json!({"render": {"width": 32, "height": 24, "gi": small, "lights": lights},
                   "format": "raw_indirect"})
        };
        let a = raw_sum(&render(&server, &indirect(json!([spot]))).await.1);
        let b = raw_sum(&render(&server, &indirect(json!([point]))).await.1);
        let ab = raw_sum(&render(&server, &indirect(json!([spot, point]))).await.1);
        assert!(
            a > 0.0 && b > 0.0,
            "{method}: each light alone lights: {a} {b}"
        );
        eprintln!(
            "{method}: spot {a:.4} + point {b:.4}; both {ab:.4} ({:+.2} %)",
            100.0 * (ab / (a + b) - 1.0)
        );
        assert!(
            (ab - (a + b)).abs() < 0.2 * (a + b),
            "{method}: two lights {ab} vs each alone {a} + {b}"
        );
        assert!(
            ab > a + 0.2 * b,
            "{method}: the second light adds {}",
            ab - a
        );
    }
    server.stop().await;
}

/// `render.lights`: the scene's default lights are listed; two lights render brighter than
/// the first alone at a fixed exposure, and the report names both.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_render_lights_with_every_light_it_lists() {
    let server = TestServer::start(&[]).await;
    let scene = server.get_json("/v1/scenes/default").await;
    let defaults = scene["default_lights"].as_array().expect("default_lights");
    assert_eq!(defaults.len(), 1, "{scene}");
    assert_eq!(defaults[0], scene["default_light"]);
    let first = defaults[0].clone();
    let mut second = first.clone();
    second["kind"] = json!("point");
    second["intensity"] = json!(first["intensity"].as_f64().expect("intensity") * 0.5);
    let mean = |png: &[u8]| {
        let image = image::load_from_memory(png).expect("png").to_rgb8();
        image
            .pixels()
            .map(|p| f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2]))
            .sum::<f64>()
            / image.pixels().len() as f64
    };
    let request = |lights: Value| {
        json!({"render": {"width": 32, "height": 24, "exposure": 0.5, "lights": lights,
                          "gi": {"method": "none"}}})
    };
    let (one, png_one) = render(&server, &request(json!([first]))).await;
    let (two, png_two) = render(&server, &request(json!([first, second]))).await;
    assert_eq!(one.lights.len(), 1);
    assert_eq!(two.lights.len(), 2);
    assert!(
        mean(&png_two) > mean(&png_one) * 1.05,
        "{} vs {}",
        mean(&png_two),
        mean(&png_one)
    );
    server.stop().await;
}

/// `render.environment`: a uniform sky brightens a frame, the report names it, the
/// comparison with the reference renders the reference under it too, and a session takes it
/// and drops it by patch.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_environment_lights_renders_comparisons_and_sessions() {
    let server = TestServer::start(&[]).await;
    let body = |environment: Value| {
        json!({"render": {"width": 32, "height": 24, "exposure": 0.5, "shadow_map_size": 256,
                          "environment": environment, "gi": {"method": "none"}},
               "format": "png"})
    };
    let mean = |png: &[u8]| {
        let image = image::load_from_memory(png).expect("png").to_rgb8();
        image
            .pixels()
            .map(|p| f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2]))
            .sum::<f64>()
            / image.pixels().len() as f64
    };
    let without = body(Value::Null);
    let with = body(json!({"kind": "uniform", "intensity": 0.5, "directions": 4}));
    let (report, dark) = render(&server, &without).await;
    assert_eq!(report.environment, None);
    let (report, lit) = render(&server, &with).await;
    let env = report
        .environment
        .expect("the report names the environment");
    assert_eq!(env.directions, 4);
    assert!(
        mean(&lit) > mean(&dark) * 1.1,
        "{} vs {}",
        mean(&lit),
        mean(&dark)
    );
    // Compared with the reference under the same sky: `none` has no indirect light of its
    // own, so without a sky it misses all of the reference's (bias −100 %); under a sky
    // bright enough to outshine the lamp's bounce, both count the sky's light on the
    // surfaces and the bias is what `none` misses of the rest.
    let bias = |environment: Value| {
        let mut compared = body(environment);
        compared["compare_to"] = json!("reference");
        compared["compare_spp"] = json!(16);
        let server = &server;
        async move {
            let (report, _) = render(server, &compared).await;
            report
                .comparison
                .expect("a comparison")
                .indirect_bias_relative
        }
    };
    let dark_bias = bias(Value::Null).await;
    let sky_bias = bias(json!({"kind": "uniform", "intensity": 20.0, "directions": 4})).await;
    assert!(dark_bias < -0.99, "{dark_bias}");
    assert!(sky_bias > -0.5, "{sky_bias}");

    let created = server
        .create_session(
            json!({"render": {"width": 32, "height": 24, "environment": {"kind": "uniform"}}}),
            None,
        )
        .await;
    let env = created.session.params.render.environment.clone();
    assert_eq!(env.map(|e| e.kind), Some(EnvironmentKind::Uniform));
    let path = format!("/v1/sessions/{}", created.session.id);
    let patch = |body: Value| {
        let (server, path) = (&server, &path);
        async move {
            let resp = server
                .http
                .patch(server.url(path))
                .json(&body)
                .send()
                .await
                .expect("patch");
            assert_eq!(resp.status(), 200, "{body}");
            resp.json::<Value>().await.expect("session")
        }
    };
    let patched = patch(json!({"render": {"environment": {"intensity": 2.0}}})).await;
    assert_eq!(
        patched["params"]["render"]["environment"]["intensity"],
        json!(2.0),
        "{patched}"
    );
    assert_eq!(
        patched["params"]["render"]["environment"]["kind"],
        json!("uniform")
    );
    let dropped = patch(json!({"render": {"environment": null}})).await;
    assert_eq!(
        dropped["params"]["render"]["environment"],
        Value::Null,
        "{dropped}"
    );
    server.stop().await;
}

/// A frame without punctual lights (`lights: []`): the Cornell box's lamp lights it through
/// `emitters` (on by default, its stand-in spot being absent) in an RSM method, the report has
/// no `light`, the comparison renders the reference from the lamp alone too; with `emitters`
/// off nothing lights it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_frame_lit_by_emissive_surfaces_alone() {
    let server = TestServer::start(&[]).await;
    let body = |emitters: Value| {
        json!({"render": {"width": 32, "height": 24, "shadow_map_size": 256, "lights": [],
                          "gi": {"method": "clustered", "rsm_size": 32, "emitters": emitters}},
               "format": "raw_indirect", "compare_to": "reference", "compare_spp": 16})
    };
    let (report, lit) = render(&server, &body(Value::Null)).await;
    assert_eq!(report.light, None);
    assert!(report.lights.is_empty());
    assert!(raw_sum(&lit) > 0.0, "the lamp lights the room");
    let comparison = report.comparison.expect("a comparison");
    assert!(
        comparison.indirect_bias_relative.abs() < 0.6,
        "{comparison:?}"
    );
    let (_, dark) = render(&server, &body(json!(false))).await;
    assert_eq!(raw_sum(&dark), 0.0);
    server.stop().await;
}

/// An equirectangular `width`×`height` Radiance file of `radiance` everywhere.
fn hdr_file(width: u32, height: u32, radiance: [f32; 3]) -> Vec<u8> {
    let texels = (0..width * height).flat_map(|_| radiance).collect();
    let buffer = image::Rgb32FImage::from_raw(width, height, texels).expect("size");
    let mut bytes = Vec::new();
    image::DynamicImage::ImageRgb32F(buffer)
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Hdr,
        )
        .expect("encode");
    bytes
}

/// `render.environment` of kind `image`: a `.hdr` uploaded with the scene is listed with it
/// and lights it exactly as a uniform environment of the same radiance does; a scene without
/// one, two images, a broken file and one over the texture budget are refused, naming why.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_environment_image_uploaded_with_the_scene_lights_it() {
    let server = TestServer::start(&["--max-scene-texture-bytes", "40000"]).await;
    let part =
        |bytes, name: &str| reqwest::multipart::Part::bytes(bytes).file_name(name.to_string());
    let upload = |files: Vec<(Vec<u8>, &'static str)>| {
        let server = &server;
        async move {
            let mut form =
                reqwest::multipart::Form::new().part("scene", part(cornell_glb(), "box.glb"));
            for (bytes, name) in files {
                form = form.part(name, part(bytes, name));
            }
            let resp = server
                .http
                .post(server.url("/v1/scenes"))
                .multipart(form)
                .send()
                .await
                .expect("upload");
            let status = resp.status().as_u16();
            (status, resp.json::<Value>().await.expect("JSON"))
        }
    };
    // 48×24 texels take 18,432 bytes decoded: within the 40,000-byte scene texture budget.
    let (status, info) = upload(vec![(hdr_file(48, 24, [0.5, 0.4, 0.3]), "sky.hdr")]).await;
    assert_eq!(status, 201, "{info}");
    assert_eq!(
        info["environment_image"],
        json!({"name": "sky.hdr", "width": 48, "height": 24, "kept_width": 48, "kept_height": 24})
    );
    let id = info["id"].as_str().expect("id").to_string();
    let listed = server.get_json(&format!("/v1/scenes/{id}")).await;
    assert_eq!(listed["environment_image"], info["environment_image"]);

    let frame = |scene: &str, environment: Value| {
        let body = json!({"render": {"scene": scene, "width": 32, "height": 24, "exposure": 0.5,
                                     "shadow_map_size": 256, "environment": environment,
                                     "gi": {"method": "none"}},
                          "format": "raw_final"});
        let server = &server;
        async move { render(server, &body).await }
    };
    let (report, image_lit) = frame(&id, json!({"kind": "image", "directions": 4})).await;
    assert_eq!(
        report.environment.map(|e| e.kind),
        Some(EnvironmentKind::Image)
    );
    let (_, uniform_lit) = frame(
        &id,
        json!({"kind": "uniform", "color": [0.5, 0.4, 0.3], "directions": 4}),
    )
    .await;
    let (_, dark) = frame(&id, Value::Null).await;
    let (a, b, d) = (raw_sum(&image_lit), raw_sum(&uniform_lit), raw_sum(&dark));
    assert!(
        a > d * 1.1,
        "the image lights the scene: {a} vs {d} without"
    );
    assert!(
        (a / b - 1.0).abs() < 0.02,
        "image {a} vs uniform of its radiance {b}"
    );

    // The built-in scene has no image.
    let resp = server
        .http
        .post(server.url("/v1/render"))
        .json(&json!({"render": {"width": 32, "height": 24, "environment": {"kind": "image"}}}))
        .send()
        .await
        .expect("render");
    assert_eq!(resp.status(), 400);
    let body: Value = resp.json().await.expect("error JSON");
    assert_eq!(body["field"], "render.environment.kind", "{body}");

    let (status, body) = upload(vec![
        (hdr_file(8, 4, [1.0; 3]), "a.hdr"),
        (hdr_file(8, 4, [1.0; 3]), "b.exr"),
    ])
    .await;
    assert_eq!(
        (status, body["field"].as_str()),
        (400, Some("files")),
        "{body}"
    );
    let (status, body) = upload(vec![(b"#?RADIANCE\nbroken".to_vec(), "sky.hdr")]).await;
    assert_eq!(
        (status, body["error"].as_str()),
        (400, Some("invalid_scene")),
        "{body}"
    );
    assert!(
        body["message"].as_str().unwrap_or("").contains("sky.hdr"),
        "{body}"
    );
    // 96×48 texels take 73,728 bytes decoded: over the budget, refused before decoding.
    let (status, body) = upload(vec![(hdr_file(96, 48, [1.0; 3]), "big.hdr")]).await;
    assert_eq!(
        (status, body["error"].as_str()),
        (413, Some("texture_budget")),
        "{body}"
    );
    // A 40,000×20,000 header over a few bytes: 12.8 GB decoded, refused from the header alone.
    let huge = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 20000 +X 40000\n\x02\x02".to_vec();
    let (status, body) = upload(vec![(huge, "huge.hdr")]).await;
    assert_eq!(
        (status, body["error"].as_str()),
        (413, Some("texture_budget")),
        "{body}"
    );
    assert!(
        body["message"]
            .as_str()
            .unwrap_or("")
            .contains("40000×20000"),
        "{body}"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn renders_compare_with_the_reference() {
    let server = TestServer::start(&[]).await;
    let brsm = json!({
        "render": {"width": 40, "height": 30, "shadow_map_size": 256,
                   "gi": {"rsm_size": 32, "val_count": 256, "view_samples": 64}},
        "compare_to": "reference", "compare_spp": 16
    });
    let (a, _) = render(&server, &brsm).await;
    let c = a.comparison.expect("a comparison");
    assert_eq!(c.reference_samples, 16);
    assert!(c.reference_relative_error > 0.0);
    assert!(c.indirect_mae > 0.0 && c.indirect_mae.is_finite());
    assert!(c.indirect_mae_relative > 0.0 && c.indirect_mae_relative < 10.0);
    assert!(c.final_psnr_db.is_some_and(|p| p > 5.0 && p < 100.0));
    assert!(c.final_flip > 0.0 && c.final_flip < 1.0, "{}", c.final_flip);
    let (again, _) = render(&server, &brsm).await;
    assert_eq!(again.comparison.expect("comparison"), c);
    assert_eq!(c.senders, Senders::Full);
    assert_eq!(again.comparison_modelled, None, "not asked for");

    // BRSM sends its texels' glossy lobes on by default (`senders: full`): it models the
    // whole transport, so there is no second comparison.
    let mut modelled = brsm.clone();
    modelled["compare_modelled"] = json!(true);
    let (m, _) = render(&server, &modelled).await;
    assert_eq!(m.comparison.as_ref(), Some(&c));
    assert_eq!(m.comparison_modelled, None, "glossy senders model it all");
    // With the papers' diffuse VALs: a second reference without the glossy reflections of the
    // light at the senders, so darker, and BRSM's bias against it larger.
    modelled["render"]["gi"]["senders"] = json!("diffuse");
    let (m, _) = render(&server, &modelled).await;
    let full = m.comparison.expect("a comparison");
    let d = m.comparison_modelled.expect("a modelled comparison");
    assert_eq!((d.senders, d.reference_samples), (Senders::Diffuse, 16));
    assert!(
        d.indirect_bias_relative > full.indirect_bias_relative,
        "{d:?} vs {full:?}"
    );

    let mut reference = brsm.clone();
    reference["render"]["gi"] = json!({"method": "reference", "spp": 16});
    let (r, _) = render(&server, &reference).await;
    assert_eq!(r.samples, Some(16));
    let same = r.comparison.expect("comparison");
    assert_eq!(same.indirect_mae, 0.0, "the reference equals itself");
    assert_eq!(same.final_psnr_db, None);
    assert_eq!(same.final_flip, 0.0);
    assert!(r.stages.iter().any(|s| s.stage == "path_trace"));
    // The reference models the whole transport: no second comparison; one of diffuse
    // senders is its own modelled reference.
    let mut asked = reference.clone();
    asked["compare_modelled"] = json!(true);
    assert_eq!(render(&server, &asked).await.0.comparison_modelled, None);
    asked["render"]["gi"]["senders"] = json!("diffuse");
    let (diffuse, _) = render(&server, &asked).await;
    let own = diffuse.comparison_modelled.expect("modelled");
    assert_eq!((own.senders, own.indirect_mae), (Senders::Diffuse, 0.0));
    let full = diffuse.comparison.expect("comparison");
    assert!(full.indirect_bias_relative < 0.0, "{full:?}");

    // The same light sources on both sides: BRSM lights from the punctual light alone, so its
    // reference leaves the lamp's emission out (its bias is the one against a reference with
    // `emitters` off, not on), while a reference with `emitters` off is compared with one
    // without them too (no error).
    let raw_indirect = |body: &Value| {
        let mut raw = body.clone();
        raw["format"] = json!("raw_indirect");
        raw
    };
    let (_, brsm_raw) = render(&server, &raw_indirect(&brsm)).await;
    let mut truth = Vec::new();
    for emitters in [json!(false), json!(true), Value::Null] {
        let mut body = raw_indirect(&reference);
        body["render"]["gi"]["emitters"] = emitters;
        body.as_object_mut().expect("object").remove("compare_to");
        truth.push(raw_sum(&render(&server, &body).await.1));
    }
    assert!(truth[1] > 1.01 * truth[0], "the lamp adds light: {truth:?}");
    // Issue 31: by default the Cornell box's lamp is not counted twice, once as the spot that
    // stands in for it and once as an emitter.
    assert_eq!(
        truth[2], truth[0],
        "the default counts the lamp once: {truth:?}"
    );
    // Under a light of the request's own, the lamp lights as well by default.
    let scene = server.get_json("/v1/scenes/default").await;
    let mut own_light = raw_indirect(&reference);
    own_light
        .as_object_mut()
        .expect("object")
        .remove("compare_to");
    own_light["render"]["light"] = scene["default_light"].clone();
    own_light["render"]["light"]["intensity"] = json!(
        scene["default_light"]["intensity"]
            .as_f64()
            .expect("intensity")
            * 0.5
    );
    let with_lamp = raw_sum(&render(&server, &own_light).await.1);
    own_light["render"]["gi"]["emitters"] = json!(false);
    let without_lamp = raw_sum(&render(&server, &own_light).await.1);
    assert!(
        with_lamp > 1.01 * without_lamp,
        "{with_lamp} vs {without_lamp}"
    );
    let bias = raw_sum(&brsm_raw) / truth[0] - 1.0;
    assert!(
        (c.indirect_bias_relative - bias).abs() < 1e-3,
        "comparison bias {} vs {bias} against the reference without emitters",
        c.indirect_bias_relative
    );
    let mut dark_reference = reference.clone();
    dark_reference["render"]["gi"]["emitters"] = json!(false);
    let (d, _) = render(&server, &dark_reference).await;
    assert_eq!(d.comparison.expect("comparison").indirect_mae, 0.0);

    // `clustered` through the API: its stages, the same pixels for the same request (k-means
    // restarts from the same seeds) and a comparison closer to the truth than no indirect
    // light (block error 1).
    let clustered = json!({
        "render": {"width": 40, "height": 30, "shadow_map_size": 256,
                   "gi": {"method": "clustered", "rsm_size": 32, "vpl_count": 256,
                          "cluster_count": 8}},
        "compare_to": "reference", "compare_spp": 16
    });
    let (k, png_k) = render(&server, &clustered).await;
    let (_, png_again) = render(&server, &clustered).await;
    assert_eq!(png_k, png_again, "same request, same pixels");
    for stage in [
        "rsm",
        "vpl_generation",
        "clustering",
        "clustered_indirect",
        "geometry_blur",
    ] {
        assert!(
            k.stages.iter().any(|s| s.stage == stage),
            "{stage}: {:?}",
            k.stages
        );
    }
    let kc = k.comparison.expect("comparison");
    assert!(
        kc.indirect_mae.is_finite() && kc.indirect_block_mae_relative < 0.8,
        "{kc:?}"
    );
    server.stop().await;
}

/// Issue 35 part 1: a scene lists its nodes (which may move, their bounds) and animations.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scenes_list_their_nodes_and_animations() {
    let server = TestServer::start(&[]).await;
    let cornell = server.get_json("/v1/scenes/default").await;
    let nodes: Vec<(String, bool)> = cornell["nodes"]
        .as_array()
        .expect("nodes")
        .iter()
        .map(|n| {
            (
                n["name"].as_str().unwrap_or("").to_owned(),
                n["movable"] == true,
            )
        })
        .collect();
    assert_eq!(
        nodes,
        [
            ("room".to_owned(), false),
            ("short box".to_owned(), true),
            ("tall box".to_owned(), true)
        ]
    );
    assert_eq!(cornell["nodes"][1]["parent"], 0);
    assert!(
        (cornell["nodes"][2]["bounds"]["max"][1]
            .as_f64()
            .unwrap_or(0.0)
            - 1.2)
            .abs()
            < 1e-4
    );
    assert_eq!(cornell["animations"], json!([]));

    let info = server
        .upload_glb("slide", lightcast_e2e::animated_glb())
        .await;
    assert_eq!(
        info["nodes"],
        json!([
            {"id": 0, "name": "ground", "movable": false,
             "bounds": {"min": [0.0, 0.0, 0.0], "max": [1.0, 0.5, 1.0]},
             "translation": [0.0, 0.0, 0.0], "rotation": [0.0, 0.0, 0.0, 1.0],
             "scale": [1.0, 1.0, 1.0],
             "world": [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0,
                       0.0, 0.0, 0.0, 1.0]},
            {"id": 1, "name": "mover", "parent": 0, "movable": true,
             "bounds": {"min": [0.0, 0.5, 0.0], "max": [1.0, 0.5, 1.0]},
             "translation": [0.0, 0.5, 0.0], "rotation": [0.0, 0.0, 0.0, 1.0],
             "scale": [1.0, 1.0, 1.0],
             "world": [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0,
                       0.0, 0.5, 0.0, 1.0]},
        ]),
        "{info}"
    );
    assert_eq!(
        info["animations"],
        json!([{"name": "slide", "duration": 2.0, "nodes": [1]}])
    );
    server.stop().await;
}

/// Issue 35 part 2: `render.nodes` moves a movable node in a one-shot render (reproducibly)
/// and in one session (over its WebSocket) without moving it for another session.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_move_nodes_per_render_and_per_session() {
    let server = TestServer::start(&[]).await;
    let moved = json!([{"node": 1, "translation": [-0.15, 0.0, 0.4]}]);
    let raw = |nodes: Value| {
        json!({"format": "raw_final", "render": {"width": 48, "height": 32,
               "shadow_map_size": 256, "gi": {"method": "none"}, "nodes": nodes}})
    };
    let render = |body: Value| {
        let server = &server;
        async move {
            let resp = server
                .http
                .post(server.url("/v1/render"))
                .json(&body)
                .send()
                .await
                .expect("render");
            assert_eq!(resp.status(), 200);
            let report: RenderReport = serde_json::from_str(
                resp.headers()["x-lightcast-report"]
                    .to_str()
                    .expect("ASCII"),
            )
            .expect("report");
            (report, resp.bytes().await.expect("image").to_vec())
        }
    };
    let (rest, rest_pixels) = render(raw(json!([]))).await;
    let (first, first_pixels) = render(raw(moved.clone())).await;
    let (again, again_pixels) = render(raw(moved.clone())).await;
    assert_ne!(first.request_hash, rest.request_hash);
    assert_eq!(first.request_hash, again.request_hash);
    assert_eq!(
        first_pixels, again_pixels,
        "a posed render replays bit for bit"
    );
    let floats = |b: &[u8]| -> Vec<f32> {
        b.chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()
    };
    let changed = floats(&rest_pixels)
        .iter()
        .zip(floats(&first_pixels))
        .filter(|(a, b)| (*a - b).abs() > 1e-3)
        .count();
    assert!(changed > 100, "the box moved: {changed} values changed");
    // `{"node": 1}` alone is the node where it is: the rest render.
    let (_, back) = render(raw(json!([{"node": 1}]))).await;
    assert_eq!(back, rest_pixels);
    // A posed render compared with the reference of the same poses.
    let resp = server
        .http
        .post(server.url("/v1/render"))
        .json(
            &json!({"render": {"width": 48, "height": 32, "shadow_map_size": 256,
                      "gi": {"method": "clustered"}, "nodes": moved},
                      "compare_to": "reference", "compare_spp": 16}),
        )
        .send()
        .await
        .expect("render");
    assert_eq!(resp.status(), 200);
    let report: RenderReport = serde_json::from_str(
        resp.headers()["x-lightcast-report"]
            .to_str()
            .expect("ASCII"),
    )
    .expect("report");
    let c = report.comparison.expect("compared");
    assert!(
        c.indirect_mae.is_finite() && c.reference_samples == 16,
        "{c:?}"
    );
    // Moving a node reruns no precomputation: each method's per-scene data (light caches,
    // BVH, surfels) is built once, whatever the poses.
    let mut built: Option<Value> = None;
    for x in [-0.15, 0.0, 0.1] {
        for gi in ["lightskin", "reference", "surfels"] {
            let resp = server
                .http
                .post(server.url("/v1/render"))
                .json(
                    &json!({"render": {"width": 32, "height": 32, "shadow_map_size": 256,
                              "gi": {"method": gi, "spp": 1},
                              "nodes": [{"node": 1, "translation": [x, 0.0, 0.4]}]},
                              "format": "png"}),
                )
                .send()
                .await
                .expect("render");
            assert_eq!(resp.status(), 200, "{gi} at {x}");
        }
        let precomputed = server.get_json("/v1/scenes/default").await["precomputed"].clone();
        match &built {
            None => built = Some(precomputed),
            Some(first) => assert_eq!(&precomputed, first, "built once, whatever the poses"),
        }
    }
    // More entries than movable nodes allow, inside the body limit.
    let many: Vec<Value> = (0..2000).map(|_| json!({"node": 1})).collect();
    let resp = server
        .http
        .post(server.url("/v1/render"))
        .json(&raw(json!(many)))
        .send()
        .await
        .expect("render");
    assert_eq!(resp.status(), 400);
    let body: Value = resp.json().await.expect("error");
    assert_eq!(body["field"], "render.nodes", "{body}");

    // Two sessions of one scene: one moves the tall box over its socket.
    let session = |gi: &str| {
        json!({"render": {"width": 32, "height": 32, "shadow_map_size": 256,
               "gi": {"method": gi}}, "fps_cap": 60, "encoding": {"codec": "png"}})
    };
    let a = server.create_session(session("clustered"), None).await;
    let b = server.create_session(session("clustered"), None).await;
    let mut stream = server.connect(&a).await;
    let mut events = Vec::new();
    let before = stream.next_frame(&mut events).await;
    stream
        .send(json!({"type": "nodes", "input_id": 5,
                     "nodes": [{"node": 2, "translation": [0.3, 0.0, -0.3]}]}))
        .await;
    let after = loop {
        let f = stream.next_frame(&mut events).await;
        if f.header.input_id == 5 {
            break f;
        }
    };
    assert_ne!(before.rgba, after.rgba, "the frame shows the moved box");
    // Clicks over the view (one at a time: a newer pick replaces one not yet rendered) find
    // the moved tall box, the short box and the room, which nothing drags.
    let mut found = std::collections::BTreeSet::new();
    for (i, (x, y)) in (1..8)
        .flat_map(|y| (1..8).map(move |x| (x as f32 / 8.0, y as f32 / 8.0)))
        .enumerate()
    {
        let nonce = 100 + i as u64;
        stream
            .send(json!({"type": "pick", "x": x, "y": y, "nonce": nonce}))
            .await;
        let picked = loop {
            match stream.next_event().await {
                ServerEvent::Picked {
                    nonce: n,
                    x: px,
                    y: py,
                    position,
                    node,
                    movable,
                    pose,
                } if n == nonce => {
                    assert_eq!((px, py), (x, y));
                    // A drag starts from the node as that frame posed it: the tall box where
                    // the socket moved it, the short box at rest.
                    let translation = pose.as_ref().and_then(|p| p.translation);
                    match movable {
                        Some(2) => assert_eq!(translation, Some([0.3, 0.0, -0.3])),
                        Some(1) => assert_eq!(translation, Some([0.33, 0.0, 0.37])),
                        _ => assert_eq!(pose, None),
                    }
                    break (position, node, movable);
                }
                _ => {}
            }
        };
        if let (Some(p), Some(node)) = (picked.0, picked.1) {
            assert!(p.iter().all(|c| c.is_finite()), "{p:?}");
            found.insert((node, picked.2));
        }
    }
    assert!(found.contains(&(2, Some(2))), "{found:?}");
    assert!(found.contains(&(1, Some(1))), "{found:?}");
    assert!(found.contains(&(0, None)), "{found:?}");
    let a_info = server
        .get_json(&format!("/v1/sessions/{}", a.session.id))
        .await;
    assert_eq!(
        a_info["params"]["render"]["nodes"][0]["node"], 2,
        "{a_info}"
    );
    let b_info = server
        .get_json(&format!("/v1/sessions/{}", b.session.id))
        .await;
    assert_eq!(b_info["params"]["render"].get("nodes"), None, "{b_info}");
    server.stop().await;
}

/// Issue 35: a light carried by an animated node moves with it: one-shot renders at the
/// animation's start and end differ where only the lamp moved, bit for bit the same when the
/// request brings a light of its own (which no node carries).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn lights_move_with_the_nodes_carrying_them() {
    let server = TestServer::start(&[]).await;
    let info = server.upload_glb("lamp", lightcast_e2e::lamp_glb()).await;
    let scene = info["id"].as_str().expect("id").to_owned();
    let render = |time: f32, own_light: bool| {
        let mut render = json!({"scene": scene, "width": 32, "height": 32,
            "camera": {"position": [1.5, 3.0, 4.0], "target": [1.5, 0.0, 1.5], "fov_y_degrees": 60},
            "shadow_map_size": 256, "gi": {"method": "none"},
            "animation": {"name": "swing", "time": time}});
        if own_light {
            render["light"] = json!({"kind": "spot", "position": [1.5, 1.0, 1.5],
                "direction": [0, -1, 0], "color": [1, 1, 1], "intensity": 20,
                "inner_cone": 0.3, "outer_cone": 0.6});
        }
        let server = &server;
        async move {
            let resp = server
                .http
                .post(server.url("/v1/render"))
                .json(&json!({"render": render}))
                .send()
                .await
                .expect("render");
            assert_eq!(resp.status(), 200);
            resp.bytes().await.expect("png").to_vec()
        }
    };
    let (start, end) = (render(0.0, false).await, render(2.0, false).await);
    assert_ne!(start, end, "the lamp's light moved with it");
    assert_eq!(
        start,
        render(0.0, false).await,
        "the same time, the same pixels"
    );
    assert_eq!(
        render(0.0, true).await,
        render(2.0, true).await,
        "a request's own light stays where it is"
    );
    server.stop().await;
}

/// Issue 35: a glTF animation poses a one-shot render at the time asked (the same pixels as
/// the node posed by hand, bit for bit on replay), and a session plays, pauses and scrubs it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn animations_pose_renders_and_play_in_sessions() {
    let server = TestServer::start(&[]).await;
    let info = server
        .upload_glb("slide", lightcast_e2e::animated_glb())
        .await;
    let scene = info["id"].as_str().expect("id").to_owned();
    let camera =
        json!({"position": [0.5, 2.0, 2.5], "target": [0.5, 0.0, 0.5], "fov_y_degrees": 60});
    let raw = |extra: Value| {
        let mut render = json!({"scene": scene, "width": 32, "height": 32, "camera": camera,
                                "shadow_map_size": 256, "gi": {"method": "none"}});
        if let (Some(r), Value::Object(extra)) = (render.as_object_mut(), extra) {
            r.extend(extra);
        }
        json!({"format": "raw_final", "render": render})
    };
    let post = |body: Value| {
        let server = &server;
        async move {
            let resp = server
                .http
                .post(server.url("/v1/render"))
                .json(&body)
                .send()
                .await
                .expect("render");
            let status = resp.status().as_u16();
            (status, resp.bytes().await.expect("body").to_vec())
        }
    };
    let at = |t: f32| raw(json!({"animation": {"name": "slide", "time": t}}));
    let (s0, start) = post(at(0.0)).await;
    let (s1, halfway) = post(at(1.0)).await;
    let (_, again) = post(at(1.0)).await;
    assert_eq!((s0, s1), (200, 200));
    assert!(start != halfway, "the mover moved");
    assert!(halfway == again, "a render at time t replays bit for bit");
    // At 1 s the channel has the mover at x = 0.5 on the ground's plane: as posed by hand.
    let (status, by_hand) = post(raw(
        json!({"nodes": [{"node": 1, "translation": [0.5, 0.0, 0.0]}]}),
    ))
    .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&by_hand));
    assert!(
        halfway == by_hand,
        "the animation at 1 s is the node posed so"
    );
    for (animation, field) in [
        (json!({"name": "spin"}), "render.animation.name"),
        (
            json!({"name": "slide", "time": -1.0}),
            "render.animation.time",
        ),
        (
            json!({"name": "slide", "speed": 1000.0}),
            "render.animation.speed",
        ),
        (
            json!({"name": "slide", "loop": true}),
            "render.animation.loop",
        ),
    ] {
        let (status, body) = post(raw(json!({"animation": animation}))).await;
        let body: Value = serde_json::from_slice(&body).expect("error");
        assert_eq!(
            (status, body["field"].as_str()),
            (400, Some(field)),
            "{body}"
        );
    }
    let (status, body) = post(raw(json!({"animation": {"name": "slide", "time": 1.0},
                                         "gi": {"method": "lightskin", "cache_visibility": 8}})))
    .await;
    let body: Value = serde_json::from_slice(&body).expect("error");
    assert_eq!(
        (status, body["field"].as_str()),
        (400, Some("render.gi.cache_visibility")),
        "{body}"
    );

    // A session plays it, and a pause keeps the time it reached.
    let created = server
        .create_session(
            json!({"render": {"scene": scene, "width": 32, "height": 32, "camera": camera,
                              "shadow_map_size": 256, "gi": {"method": "none"}},
                   "fps_cap": 30, "mode": "on_change", "encoding": {"codec": "png"}}),
            None,
        )
        .await;
    let mut stream = server.connect(&created).await;
    let mut events = Vec::new();
    stream.next_frame(&mut events).await;
    stream
        .send(json!({"type": "animation", "name": "slide", "input_id": 3}))
        .await;
    let mut frames = Vec::new();
    while frames.len() < 4 {
        let f = stream.next_frame(&mut events).await;
        if f.header.input_id == 3 {
            frames.push(f.rgba);
        }
    }
    assert!(
        frames.windows(2).any(|w| w[0] != w[1]),
        "frames keep changing while it plays"
    );
    stream
        .send(json!({"type": "animation", "name": "slide", "playing": false}))
        .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let info = server
        .get_json(&format!("/v1/sessions/{}", created.session.id))
        .await;
    let a = &info["params"]["render"]["animation"];
    assert_eq!(a["playing"], false, "{info}");
    assert!(
        a["time"].as_f64().unwrap_or(0.0) > 0.0,
        "paused where it had reached: {a}"
    );
    stream
        .send(json!({"type": "animation", "name": "spin"}))
        .await;
    let error = stream.next_error().await;
    assert_eq!(
        error.field.as_deref(),
        Some("render.animation.name"),
        "{error:?}"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scenes_upload_inspect_use_and_delete() {
    let server = TestServer::start(&[]).await;
    // A .glb body.
    let resp = server
        .http
        .post(server.url("/v1/scenes?name=box"))
        .header("content-type", "model/gltf-binary")
        .body(cornell_glb())
        .send()
        .await
        .expect("upload");
    assert_eq!(resp.status(), 201);
    let info: Value = resp.json().await.expect("SceneInfo");
    let id = info["id"].as_str().expect("id").to_string();
    assert_eq!(info["name"], "box");
    assert!(info["triangles"].as_u64().unwrap_or(0) > 100, "{info}");
    assert!(info["caches"][0]["state"].is_string());
    server.wait_caches_ready(&id).await;
    let ready = server.get_json(&format!("/v1/scenes/{id}")).await;
    assert!(
        ready["caches"][0]["caches"].as_u64().unwrap_or(0) > 100,
        "{ready}"
    );
    assert!(ready["caches"][0]["seconds"].as_f64().is_some());

    // The same scene as .gltf + .bin in one multipart upload.
    let (gltf, bin) = glb_to_gltf(&cornell_glb(), "box.bin");
    let form = gltf_upload(gltf, "box.gltf", bin);
    let resp = server
        .http
        .post(server.url("/v1/scenes"))
        .multipart(form)
        .send()
        .await
        .expect("multipart upload");
    assert_eq!(resp.status(), 201);
    let multi: Value = resp.json().await.expect("SceneInfo");
    assert_eq!(multi["triangles"], info["triangles"]);

    // A .gltf whose buffer points outside the upload is refused.
    let (mut gltf, bin) = glb_to_gltf(&cornell_glb(), "../../etc/passwd");
    gltf.extend_from_slice(b" ");
    let form = gltf_upload(gltf, "evil.gltf", bin);
    let resp = server
        .http
        .post(server.url("/v1/scenes"))
        .multipart(form)
        .send()
        .await
        .expect("upload");
    assert_eq!(resp.status(), 400);

    // A procedural scene.
    let resp = server
        .http
        .post(server.url("/v1/scenes"))
        .json(&json!({"procedural": "street?blocks=2"}))
        .send()
        .await
        .expect("procedural");
    assert_eq!(resp.status(), 201);

    let list = server.get_json("/v1/scenes").await;
    assert_eq!(list.as_array().map(Vec::len), Some(4));

    // In use by a session: cannot be deleted.
    let mut params = small_session(32, 32);
    params["render"]["scene"] = json!(id);
    let created = server.create_session(params, None).await;
    let resp = server
        .http
        .delete(server.url(&format!("/v1/scenes/{id}")))
        .send()
        .await
        .expect("delete");
    assert_eq!(resp.status(), 409);
    let used = server.get_json(&format!("/v1/scenes/{id}")).await;
    assert_eq!(used["sessions"], 1);
    server
        .http
        .delete(server.url(&format!("/v1/sessions/{}", created.session.id)))
        .send()
        .await
        .expect("delete session");
    let resp = server
        .http
        .delete(server.url(&format!("/v1/scenes/{id}")))
        .send()
        .await
        .expect("delete");
    assert_eq!(resp.status(), 204);
    let resp = server
        .http
        .get(server.url(&format!("/v1/scenes/{id}")))
        .send()
        .await
        .expect("get");
    assert_eq!(resp.status(), 404);
    server.stop().await;
}

pub(super) async fn render_small(server: &TestServer) -> (RenderReport, Vec<u8>) {
    render(
        server,
        &json!({"render": {"width": 32, "height": 24, "shadow_map_size": 128, "gi": {"method": "none"}}}),
    )
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rate_limited_messages_are_refused_not_fatal() {
    let server = TestServer::start(&["--max-messages-per-second", "5"]).await;
    let params = direct_session(32, 32);
    let created = server.create_session(params, None).await;
    let mut stream = server.connect(&created).await;
    for nonce in 0..30 {
        stream.send(json!({"type": "ping", "nonce": nonce})).await;
    }
    let (mut pongs, mut limited) = (0, 0);
    while pongs + limited < 30 {
        match stream.next_event().await {
            ServerEvent::Pong { .. } => pongs += 1,
            ServerEvent::Error { error } if error.error == "rate_limited" => limited += 1,
            _ => {}
        }
    }
    assert!(
        pongs >= 10 && limited >= 1,
        "{pongs} answered, {limited} limited"
    );
    // Binary messages are refused, and their refusals spend the same tokens (issue 30).
    tokio::time::sleep(Duration::from_millis(2500)).await;
    for _ in 0..30 {
        stream.send_raw(Message::Binary(vec![1, 2, 3].into())).await;
    }
    let (mut refused, mut limited) = (0, 0);
    while refused + limited < 30 {
        match stream.next_event().await {
            ServerEvent::Error { error } if error.error == "binary_not_accepted" => refused += 1,
            ServerEvent::Error { error } if error.error == "rate_limited" => limited += 1,
            _ => {}
        }
    }
    assert!(
        refused <= 15 && limited >= 15,
        "binary: {refused} answered, {limited} limited"
    );
    tokio::time::sleep(Duration::from_millis(400)).await;
    stream.send(json!({"type": "ping", "nonce": 99})).await;
    loop {
        if let ServerEvent::Pong { nonce } = stream.next_event().await {
            if nonce == 99 {
                break;
            }
        }
    }
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn acks_of_sent_frames_spend_no_rate_tokens_but_extra_acks_do() {
    // The bucket holds 2 × 2 tokens; 16 acked frames would empty it five times over.
    let server = TestServer::start(&["--max-messages-per-second", "2"]).await;
    let created = server.create_session(direct_session(32, 32), None).await;
    let mut stream = server.connect(&created).await;
    let mut seen = Vec::new();
    for _ in 0..16 {
        stream.next_frame(&mut seen).await;
    }
    let limited = |events: &[ServerEvent]| {
        events
            .iter()
            .filter(|e| matches!(e, ServerEvent::Error { error } if error.error == "rate_limited"))
            .count()
    };
    assert_eq!(limited(&seen), 0, "acks were rate limited: {seen:?}");

    // Acks for frames never sent are ordinary messages: 12 at once exceed the bucket.
    stream.send(json!({"type": "pause"})).await;
    for seq in 0..12 {
        stream
            .send(json!({"type": "ack", "seq": 1_000_000 + seq}))
            .await;
    }
    let mut refused = 0;
    // Only against a hang: a loaded machine may take seconds.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(120);
    while refused == 0 && tokio::time::Instant::now() < deadline {
        if let Incoming::Event(e) = stream.next().await {
            refused += limited(std::slice::from_ref(&e));
        }
    }
    assert!(refused > 0, "unsolicited acks were never rate limited");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn auth_guards_everything_but_health_and_sessions_belong_to_their_token() {
    let alice = "alice-token-0123456789";
    let bob = "bob-token-9876543210xx";
    let server = TestServer::start(&["--token", &format!("{alice},{bob}")]).await;
    for path in [
        "/v1/scenes",
        "/v1/sessions",
        "/metrics",
        "/openapi.json",
        "/v1/server",
    ] {
        let resp = server.get(path).await;
        assert_eq!(resp.status(), 401, "{path} without a token");
        let body: Value = resp.json().await.expect("JSON error");
        assert_eq!(body["error"], "unauthorized");
        let resp = server
            .http
            .get(server.url(path))
            .bearer_auth("wrong-token-000000000")
            .send()
            .await
            .expect("request");
        assert_eq!(resp.status(), 401, "{path} with a wrong token");
        let resp = server
            .http
            .get(server.url(path))
            .bearer_auth(alice)
            .send()
            .await
            .expect("request");
        assert_eq!(resp.status(), 200, "{path} with a token");
    }
    for path in ["/healthz", "/readyz"] {
        let resp = server.get(path).await;
        assert_eq!(resp.status(), 200, "{path} needs no token");
    }
    // The viewer's files load without a token (the page asks for one), as their own types,
    // under a content security policy; its page lives at `/` only.
    for (path, content_type) in [
        ("/", "text/html"),
        ("/viewer/js/main.js", "text/javascript"),
        ("/viewer/viewer.css", "text/css"),
        ("/viewer/index.html", "text/html"),
    ] {
        let resp = server.get(path).await;
        assert_eq!(resp.status(), 200, "{path} needs no token");
        assert_eq!(
            resp.url().path(),
            if content_type == "text/html" {
                "/"
            } else {
                path
            }
        );
        let header = |name: &str| {
            resp.headers()
                .get(name)
                .and_then(|v| v.to_str().ok())
                .unwrap_or_default()
                .to_string()
        };
        assert!(header("content-type").starts_with(content_type), "{path}");
        assert!(header("content-security-policy").contains("default-src 'self'"));
    }
    let resp = server.get("/viewer/missing.js").await;
    assert_eq!(resp.status(), 404);
    let params = direct_session(32, 32);
    let created = server.create_session(params, Some(alice)).await;
    let path = format!("/v1/sessions/{}", created.session.id);
    let resp = server
        .http
        .get(server.url(&path))
        .bearer_auth(bob)
        .send()
        .await
        .expect("get");
    assert_eq!(resp.status(), 404, "another token cannot see the session");
    let resp = server
        .http
        .patch(server.url(&path))
        .bearer_auth(bob)
        .body(r#"{"paused":true}"#)
        .send()
        .await
        .expect("patch");
    assert_eq!(resp.status(), 404, "nor steer it");
    let listed: Value = server
        .http
        .get(server.url("/v1/sessions"))
        .bearer_auth(bob)
        .send()
        .await
        .expect("list")
        .json()
        .await
        .expect("JSON");
    assert_eq!(listed.as_array().map(Vec::len), Some(0));

    // The WebSocket: no ticket → 401; the ticket works once.
    let bare = server.ws_url(&created.session.stream);
    assert!(tokio_tungstenite::connect_async(bare).await.is_err());
    let mut stream = server.connect(&created).await;
    let mut events = Vec::new();
    stream.next_frame(&mut events).await;
    drop(stream);
    tokio::time::sleep(Duration::from_millis(200)).await;
    let reused = server.ws_url(&format!(
        "{}?ticket={}",
        created.session.stream, created.ticket.ticket
    ));
    assert!(
        tokio_tungstenite::connect_async(reused).await.is_err(),
        "a ticket is single-use"
    );
    // Bob cannot get a ticket for Alice's session; Alice can.
    let resp = server
        .http
        .post(server.url(&format!("{path}/ticket")))
        .bearer_auth(bob)
        .send()
        .await
        .expect("ticket");
    assert_eq!(resp.status(), 404);
    let ticket: Value = server
        .http
        .post(server.url(&format!("{path}/ticket")))
        .bearer_auth(alice)
        .send()
        .await
        .expect("ticket")
        .json()
        .await
        .expect("JSON");
    let url = server.ws_url(&format!(
        "{}?ticket={}",
        created.session.stream,
        ticket["ticket"].as_str().expect("ticket")
    ));
    assert!(tokio_tungstenite::connect_async(url).await.is_ok());

    // Scenes are shared, but only the token that uploaded one can delete it.
    let uploaded: Value = server
        .http
        .post(server.url("/v1/scenes"))
        .bearer_auth(alice)
        .json(&json!({"procedural": "street?blocks=1"}))
        .send()
        .await
        .expect("upload")
        .json()
        .await
        .expect("JSON");
    let scene = format!("/v1/scenes/{}", uploaded["id"].as_str().expect("id"));
    let delete = |token| {
        server
            .http
            .delete(server.url(&scene))
            .bearer_auth(token)
            .send()
    };
    let resp = delete(bob).await.expect("delete");
    assert_eq!(resp.status(), 403);
    let body: Value = resp.json().await.expect("JSON error");
    assert_eq!(body["error"], "forbidden", "{body}");
    assert_eq!(delete(alice).await.expect("delete").status(), 204);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn metrics_openapi_and_readiness_describe_the_service() {
    let server = TestServer::start(&[]).await;
    let params = direct_session(32, 32);
    let created = server.create_session(params, None).await;
    let mut stream = server.connect(&created).await;
    let mut events = Vec::new();
    for _ in 0..2 {
        stream.next_frame(&mut events).await;
    }
    let metrics = server
        .http
        .get(server.url("/metrics"))
        .send()
        .await
        .expect("metrics")
        .text()
        .await
        .expect("text");
    for name in [
        "lightcast_sessions",
        "lightcast_frames_rendered_total",
        "lightcast_frames_sent_total",
        "lightcast_bytes_sent_total",
        "lightcast_session_capacity",
        "lightcast_stage_seconds_bucket{stage=\"gbuffer\",le=\"0.004\"}",
        "lightcast_encode_seconds_bucket",
        "lightcast_gpu_frame_seconds_count",
        "lightcast_readback_seconds_sum",
        "lightcast_stage_ms_bucket{stage=\"gbuffer\",le=\"4\"}",
        "lightcast_encode_ms_bucket",
        "lightcast_gpu_frame_ms_count",
        "lightcast_gpu_idle_seconds_sum",
    ] {
        assert!(metrics.contains(name), "/metrics lacks {name}:\n{metrics}");
    }
    // Every frame read back says how long the GPU waited for it.
    let idle_frames: f64 = metrics
        .lines()
        .find_map(|l| l.strip_prefix("lightcast_gpu_idle_seconds_count "))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("/metrics lacks the GPU idle count:\n{metrics}"));
    assert!(
        idle_frames >= 2.0,
        "{idle_frames} frames timed for GPU idle"
    );
    // Live GPU objects: a rendering server holds buffers, textures and bind groups.
    for gauge in [
        "lightcast_gpu_buffers",
        "lightcast_gpu_textures",
        "lightcast_gpu_bind_groups",
    ] {
        let value: f64 = metrics
            .lines()
            .find_map(|l| l.strip_prefix(&format!("{gauge} ")))
            .and_then(|v| v.trim().parse().ok())
            .unwrap_or_else(|| panic!("/metrics lacks {gauge}:\n{metrics}"));
        assert!(value >= 1.0, "{gauge} = {value}");
    }
    let doc = server.get_json("/openapi.json").await;
    assert!(doc["openapi"].as_str().is_some_and(|v| v.starts_with("3.")));
    for path in [
        "/v1/scenes",
        "/v1/scenes/{id}",
        "/v1/sessions",
        "/v1/sessions/{id}",
        "/v1/sessions/{id}/stream",
        "/v1/render",
        "/healthz",
        "/readyz",
        "/metrics",
        "/openapi.json",
    ] {
        assert!(doc["paths"][path].is_object(), "openapi.json lacks {path}");
    }
    for schema in [
        "SessionParams",
        "RenderRequest",
        "ClientMessage",
        "ServerEvent",
        "ErrorBody",
        "SceneInfo",
    ] {
        assert!(
            doc["components"]["schemas"][schema].is_object(),
            "openapi.json lacks schema {schema}"
        );
    }
    let ready = server
        .http
        .get(server.url("/readyz"))
        .send()
        .await
        .expect("readyz");
    assert_eq!(ready.status(), 200, "a CPU adapter counts when allowed");
    server.stop().await;

    // Without --allow-cpu-adapter a software adapter (lavapipe in CI) is not ready; a real GPU
    // is.
    let strict = TestServer::start_with(&[], false).await;
    let adapter = strict.get_json("/v1/server").await["adapter"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    let ready = strict
        .http
        .get(strict.url("/readyz"))
        .send()
        .await
        .expect("readyz");
    let software = adapter.contains("(Cpu,");
    assert_eq!(ready.status() == 503, software, "{adapter}");
    if software {
        let body: Value = ready.json().await.expect("JSON");
        assert_eq!(body["error"], "not_ready");
    }
    strict.stop().await;
}

/// A request that outlasts `--request-timeout-ms` (here a client that stops sending its body
/// halfway) is answered with the documented JSON error, and the server goes on serving.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn requests_over_the_time_limit_get_a_json_error() {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let server = TestServer::start(&["--request-timeout-ms", "300"]).await;
    let address = server.base.trim_start_matches("http://");
    let mut tcp = tokio::net::TcpStream::connect(address)
        .await
        .expect("connect");
    let head = format!(
        "POST /v1/scenes HTTP/1.1\r\nHost: {address}\r\nContent-Type: model/gltf-binary\r\n\
         Content-Length: 1000\r\nConnection: close\r\n\r\nglTF"
    );
    tcp.write_all(head.as_bytes()).await.expect("write");
    let mut response = Vec::new();
    tokio::time::timeout(PATIENCE, tcp.read_to_end(&mut response))
        .await
        .expect("answered in time")
        .expect("read");
    let response = String::from_utf8_lossy(&response);
    assert!(response.starts_with("HTTP/1.1 408"), "{response}");
    let body = response.split("\r\n\r\n").nth(1).unwrap_or_default();
    let error: Value = serde_json::from_str(body).expect("a JSON body");
    assert_eq!(error["error"], "request_timeout", "{error}");
    assert!(
        error["message"]
            .as_str()
            .is_some_and(|m| m.contains("300 ms")),
        "{error}"
    );
    assert_eq!(server.get("/healthz").await.status(), 200);
    server.stop().await;
}

/// The server's defaults fill what a request leaves out and nothing else: `--defaults
/// software` (what a CPU adapter gets with `auto`) gives smaller GI settings and indirect light
/// at half resolution, `--defaults gpu` the protocol's; `/v1/server` says which, and a patch's
/// `null` restores the server's default.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn requests_get_the_servers_defaults_for_what_they_leave_out() {
    let server = TestServer::start(&["--defaults", "software"]).await;
    let info = server.get_json("/v1/server").await;
    let defaults = &info["defaults"];
    assert_eq!(defaults["profile"], "software");
    assert_eq!(defaults["reason"], "--defaults software");
    assert_eq!(defaults["viewer_scale"], 0.5);
    assert_eq!(defaults["render"]["gi"]["rsm_size"], 112);
    assert_eq!(defaults["render"]["gi"]["indirect_downscale"], 2);
    let method = |name: &str| {
        info["gi_methods"]
            .as_array()
            .expect("gi_methods")
            .iter()
            .find(|m| m["method"] == name)
            .cloned()
            .expect("described")
    };
    let param = |m: &Value, name: &str| {
        m["parameters"]
            .as_array()
            .expect("parameters")
            .iter()
            .find(|p| p["name"] == name)
            .cloned()
    };
    let brsm = method("brsm");
    assert_eq!(param(&brsm, "rsm_size").expect("rsm_size")["default"], 112);
    assert_eq!(
        param(&brsm, "indirect_downscale").expect("listed")["default"],
        2
    );
    assert!(param(&method("reference"), "indirect_downscale").is_none());
    assert!(param(&method("none"), "indirect_downscale").is_none());

    // A render that sets only its size gets the reduce and upsample stages; one that sets
    // `indirect_downscale: 1` does not.
    let small = json!({"render": {"width": 64, "height": 36}});
    let (report, _) = render(&server, &small).await;
    let stages: Vec<&str> = report.stages.iter().map(|s| s.stage.as_str()).collect();
    assert!(
        stages.contains(&"gbuffer_reduce") && stages.contains(&"indirect_upsample"),
        "{stages:?}"
    );
    let full = json!({"render": {"width": 64, "height": 36, "gi": {"indirect_downscale": 1}}});
    let (report, _) = render(&server, &full).await;
    assert!(!report.stages.iter().any(|s| s.stage == "indirect_upsample"));

    let created = server
        .create_session(json!({"render": {"gi": {"rsm_size": 64}}}), None)
        .await;
    let gi = &created.session.params.render.gi;
    let number = |name: &str| gi.get(name).and_then(Value::as_u64);
    assert_eq!(number("rsm_size"), Some(64), "a set field is used as sent");
    assert_eq!(
        (number("val_count"), number("indirect_downscale")),
        (Some(512), Some(2))
    );
    assert_eq!(created.session.params.render.shadow_map_size, 1024);
    let path = format!("/v1/sessions/{}", created.session.id);
    let patched: Value = server
        .http
        .patch(server.url(&path))
        .header("content-type", "application/merge-patch+json")
        .body(r#"{"render": {"gi": {"rsm_size": null, "val_count": 300}}}"#)
        .send()
        .await
        .expect("patch")
        .json()
        .await
        .expect("session JSON");
    assert_eq!(patched["params"]["render"]["gi"]["rsm_size"], 112);
    assert_eq!(patched["params"]["render"]["gi"]["val_count"], 300);
    server.stop().await;

    // The paper's settings cost about 5 s a frame on lavapipe: over the default frame limit.
    let server = TestServer::start(&["--defaults", "gpu", "--max-frame-cost", "60"]).await;
    assert_eq!(
        server.get_json("/v1/server").await["defaults"]["profile"],
        "gpu"
    );
    let created = server.create_session(json!({}), None).await;
    let render = &created.session.params.render;
    assert_eq!(
        lightcast_protocol::RenderParams {
            gi: lightcast_protocol::GiParams::default(),
            ..render.clone()
        },
        lightcast_protocol::RenderParams::default()
    );
    // Every parameter of every method at its table's default, as `/v1/server` describes it.
    let info = server.get_json("/v1/server").await;
    for m in info["gi_methods"].as_array().expect("gi_methods") {
        for p in m["parameters"].as_array().expect("parameters") {
            let name = p["name"].as_str().expect("a name");
            assert_eq!(render.gi.get(name), Some(&p["default"]), "{name}");
        }
    }
    assert_eq!(render.gi.get("rsm_size"), Some(&json!(1024)));
    assert_eq!(render.gi.method.name(), "brsm");
    server.stop().await;
}

/// `surfels` through the API: its precomputation is built off the render loop and listed with
/// the scene, a render waits for it and reports the surfel stages, and its parameters and
/// budget are checked with errors naming the field.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn surfels_render_through_the_api_after_their_precomputation() {
    let server = TestServer::start(&["--max-total-surfel-links", "20000"]).await;
    let gi = json!({"method": "surfels", "surfel_count": 2048, "surfel_cache_spacing": 0.4,
                    "surfel_links": 16, "bounces": 2});
    let request = json!({"render": {"width": 48, "height": 36, "gi": gi}});
    let (report, png) = render(&server, &request).await;
    let stages: Vec<&str> = report.stages.iter().map(|s| s.stage.as_str()).collect();
    for stage in [
        "surfel_light",
        "surfel_pull",
        "surfel_cache_light",
        "surfel_shade",
    ] {
        assert!(stages.contains(&stage), "{stage} in {stages:?}");
    }
    assert_eq!(
        image::load_from_memory(&png)
            .expect("png")
            .to_rgba8()
            .dimensions(),
        (48, 36)
    );
    let scene = server.get_json("/v1/scenes/default").await;
    let sets: Vec<&Value> = scene["precomputed"]
        .as_array()
        .expect("precomputed")
        .iter()
        .filter(|p| p["kind"] == "surfel_links")
        .collect();
    assert_eq!(sets.len(), 1, "{scene}");
    assert_eq!(sets[0]["state"], "ready");
    assert_eq!(sets[0]["params"]["surfel_links"], 16.0);

    // The surfels' debug views, from the same set; other methods are refused them.
    for view in ["surfels", "surfel-links", "cache-sh"] {
        let request = json!({"render": {"width": 48, "height": 36, "gi": gi, "view": view}});
        let (_, png) = render(&server, &request).await;
        let image = image::load_from_memory(&png).expect("png").to_rgba8();
        let lit = image.pixels().filter(|p| p.0[..3] != [0; 3]).count();
        assert!(lit > 48 * 36 / 4, "{view}: {lit} pixels drawn");
        let resp = server
            .http
            .post(server.url("/v1/render"))
            .json(&json!({"render": {"width": 48, "height": 36, "view": view,
                                     "gi": {"method": "brsm"}}}))
            .send()
            .await
            .expect("request");
        assert_eq!(resp.status(), 400, "{view} with brsm");
        let body: Value = resp.json().await.expect("error JSON");
        assert_eq!(body["field"], "render.view", "{body}");
    }

    let refused = |gi: Value| json!({"render": {"width": 48, "height": 36, "gi": gi}});
    for (gi, field) in [
        (
            json!({"method": "surfels", "surfel_links": 8}),
            "render.gi.surfel_links",
        ),
        (
            json!({"method": "surfels", "sh_bands": 5}),
            "render.gi.sh_bands",
        ),
        (
            json!({"method": "surfels", "surfel_count": 100}),
            "render.gi.surfel_count",
        ),
        (
            json!({"method": "surfels", "surfel_cache_spacing": -1.0}),
            "render.gi.surfel_cache_spacing",
        ),
        // Link coefficients beyond one 128 MiB GPU binding.
        (
            json!({"method": "surfels", "surfel_cache_spacing": 0.05, "surfel_links": 64}),
            "render.gi.surfel_links",
        ),
        // 512 caches × 64 links exceed --max-total-surfel-links 20000.
        (
            json!({"method": "surfels", "surfel_count": 2048, "surfel_cache_spacing": 0.4,
                   "surfel_links": 64}),
            "render.gi.surfel_links",
        ),
    ] {
        let resp = server
            .http
            .post(server.url("/v1/render"))
            .json(&refused(gi.clone()))
            .send()
            .await
            .expect("request");
        assert_eq!(resp.status(), 400, "{gi}");
        let body: Value = resp.json().await.expect("error JSON");
        assert_eq!(body["field"], field, "{gi}: {body}");
    }
    server.stop().await;
}

/// Every method `/v1/server` lists, at its small setting (its table's `Testing::small`),
/// through the API: a one-shot render runs its own stages (after its precomputation),
/// `compare_to: reference` measures it against the truth, and each debug view it lists renders
/// while another method's frame is refused it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_listed_method_renders_compares_and_draws_its_views() {
    use lightcast_server::gi::{self, precompute::SceneFacts};
    let server = TestServer::start(&[]).await;
    let info = server.get_json("/v1/server").await;
    let listed = info["gi_methods"].as_array().expect("gi_methods");
    assert_eq!(listed.len(), gi::methods().count(), "{info}");
    let facts = SceneFacts::of(&lightcast_server::scene::procedural::cornell_box());
    for m in listed {
        let method = gi::parse_method(m["method"].as_str().expect("a name")).expect("registered");
        let small = (gi::table(method).testing.small)(&facts);
        let request = json!({"render": {"width": 32, "height": 24, "gi": small},
                             "compare_to": "reference", "compare_spp": 4});
        let (report, _) = render(&server, &request).await;
        let own: Vec<&str> = gi::entry(method)
            .1
            .stages
            .iter()
            .map(|s| s.name())
            .collect();
        assert!(
            report
                .stages
                .iter()
                .any(|s| own.contains(&s.stage.as_str())),
            "{method}: none of {own:?} in {:?}",
            report.stages
        );
        let comparison = report.comparison.expect("compared");
        assert!(
            comparison.indirect_mae.is_finite() && comparison.indirect_mae_relative.is_finite(),
            "{method}: {comparison:?}"
        );
        let other = listed
            .iter()
            .find_map(|o| {
                let other = gi::parse_method(o["method"].as_str()?).ok()?;
                (other != method).then_some(other)
            })
            .expect("another method");
        for view in m["views"].as_array().expect("views") {
            let view = view["view"].as_str().expect("a view name");
            let request = json!({"render": {"width": 32, "height": 24, "gi": small, "view": view}});
            let (_, png) = render(&server, &request).await;
            // A view may show a buffer at its own size (the RSM's flux at the RSM's side).
            let image = image::load_from_memory(&png).expect("png").to_rgba8();
            assert!(image.width() * image.height() > 0, "{method} {view}");
            let parsed = lightcast_protocol::View::parse(view).expect("a view name");
            let draws = gi::views::drawn_by(parsed).contains(&other);
            if !draws {
                let refused = json!({"render": {"width": 32, "height": 24, "view": view,
                                                "gi": {"method": other.name()}}});
                let resp = server
                    .http
                    .post(server.url("/v1/render"))
                    .json(&refused)
                    .send()
                    .await
                    .expect("request");
                assert_eq!(resp.status(), 400, "{view} with {other}");
            }
        }
    }
    server.stop().await;
}
