//! Sessions streaming frames over WebSocket, end to end on loopback.

use lightcast_e2e::{
    direct_session, mean_abs_diff, small_session, Incoming, ReceivedFrame, TestServer, PATIENCE,
};
use lightcast_protocol::frame::{FLAG_GI_PENDING, FLAG_STILL};
use lightcast_protocol::{Codec, ServerEvent};
use serde_json::json;
use std::time::Duration;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_session_streams_frames_and_follows_the_camera() {
    let server = TestServer::start(&[]).await;
    server.wait_caches_ready("default").await;
    let created = server.create_session(small_session(96, 64), None).await;
    let mut stream = server.connect(&created).await;
    let mut events = Vec::new();
    match stream.next().await {
        Incoming::Event(ServerEvent::Hello { session, .. }) => {
            assert_eq!(session.id, created.session.id)
        }
        _ => panic!("the first message must be hello"),
    }

    let first = stream.next_frame(&mut events).await;
    let mut last_seq = first.header.seq;
    for _ in 0..3 {
        let f = stream.next_frame(&mut events).await;
        assert!(f.header.seq > last_seq, "sequence numbers rise");
        last_seq = f.header.seq;
        assert_eq!((f.header.width, f.header.height), (96, 64));
        assert_eq!(f.rgba.dimensions(), (96, 64));
        assert_eq!(f.header.codec, Codec::Jpeg);
        assert_eq!(f.header.flags & FLAG_GI_PENDING, 0, "caches were ready");
        for stage in [
            "shadow_map",
            "gbuffer",
            "rsm",
            "importance",
            "val_select",
            "cache_lighting",
            "tonemap",
        ] {
            assert!(f.stage(stage).is_some(), "stage {stage} is timed");
        }
        assert!(f.header.gpu_ms > 0.0 && f.header.encode_ms > 0.0);
        assert!(f.header.send_us >= f.header.render_start_us);
    }

    // Move the camera to look at the red wall from the side: the frame tagged with the input id
    // shows it, and it differs clearly from before.
    stream
        .send(json!({"type": "camera", "input_id": 7, "camera": {
            "position": [0.9, 1.0, 2.5], "target": [-1.0, 1.0, 0.0], "fov_y_degrees": 50.0}}))
        .await;
    let moved = loop {
        let f = stream.next_frame(&mut events).await;
        if f.header.input_id == 7 {
            break f;
        }
        assert!(
            f.header.seq <= last_seq + 4,
            "the change shows within a few frames"
        );
    };
    let before = &first.rgba;
    let diff = mean_abs_diff(before, &moved.rgba);
    assert!(
        diff > 10.0,
        "moving the camera changed the image by only {diff:.2} levels"
    );
    assert!(
        events.iter().any(|e| matches!(e, ServerEvent::Updated { session } if session.params.render.camera.is_some())),
        "an updated event carries the new camera"
    );

    // The session's counters and last stage times are visible over HTTP.
    let info = server
        .get_json(&format!("/v1/sessions/{}", created.session.id))
        .await;
    assert!(
        info["stats"]["frames_sent"].as_u64().unwrap_or(0) >= 5,
        "{info}"
    );
    assert!(
        info["stats"]["frames_acked"].as_u64().unwrap_or(0) >= 1,
        "{info}"
    );
    assert!(info["connected"].as_bool().unwrap_or(false));

    // Deleting the session closes its stream with a reason.
    let resp = server
        .http
        .delete(server.url(&format!("/v1/sessions/{}", created.session.id)))
        .send()
        .await
        .expect("delete");
    assert_eq!(resp.status(), 204);
    let mut closing = None;
    loop {
        match stream.next().await {
            Incoming::Event(ServerEvent::Closing { reason }) => closing = Some(reason),
            Incoming::Closed => break,
            _ => {}
        }
    }
    assert_eq!(closing.as_deref(), Some("session deleted"));
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_resting_view_gets_a_lossless_still_and_on_change_mode_idles() {
    let server = TestServer::start(&[]).await;
    let mut params = direct_session(64, 48);
    params["mode"] = json!("on_change");
    params["encoding"] = json!({"still_after_ms": 150, "moving_quality": 40});
    let created = server.create_session(params, None).await;
    let mut stream = server.connect(&created).await;
    let mut events = Vec::new();
    let mut frames = Vec::new();
    loop {
        let f = stream.next_frame(&mut events).await;
        let still = f.header.flags & FLAG_STILL != 0;
        frames.push(f);
        if still {
            break;
        }
        assert!(frames.len() < 20, "a still follows once input rests");
    }
    let still = frames.last().expect("a still");
    assert_eq!(still.header.codec, Codec::Png);
    // Nothing changes: no further frames arrive until input does.
    let quiet = tokio::time::timeout(Duration::from_millis(800), stream.next()).await;
    assert!(
        !matches!(quiet, Ok(Incoming::Frame(_))),
        "an on_change session at rest sends nothing"
    );
    // A light change brings a low-quality moving frame, then a new still.
    stream
        .send(json!({"type": "light", "input_id": 3, "light": {
            "kind": "point", "position": [0.3, 1.5, 0.3], "direction": [0, -1, 0],
            "color": [1, 1, 1], "intensity": 20, "inner_cone": 0, "outer_cone": 0}}))
        .await;
    let moving = stream.next_frame(&mut events).await;
    assert_eq!(moving.header.input_id, 3);
    assert_eq!(moving.header.codec, Codec::Jpeg);
    assert_eq!(moving.header.quality, 40);
    let next_still = stream.next_frame(&mut events).await;
    assert_ne!(next_still.header.flags & FLAG_STILL, 0);
    // An explicit still request while paused still answers.
    stream.send(json!({"type": "pause"})).await;
    stream.send(json!({"type": "still"})).await;
    let asked = stream.next_frame(&mut events).await;
    assert_ne!(asked.header.flags & FLAG_STILL, 0);
    assert_eq!(asked.header.codec, Codec::Png);
    server.stop().await;
}

/// A session of two lights streams both; a `lights` message that removes one darkens the
/// frames (fixed exposure), and a `light` message with an index past the lights is refused.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn lights_are_added_and_removed_over_the_websocket() {
    let server = TestServer::start(&[]).await;
    let first = json!({"kind": "point", "position": [0.3, 1.5, 0.3], "direction": [0, -1, 0],
                       "color": [1, 1, 1], "intensity": 2, "inner_cone": 0, "outer_cone": 0});
    let mut second = first.clone();
    second["position"] = json!([-0.4, 1.2, 0.5]);
    let mut params = direct_session(64, 48);
    params["render"]["lights"] = json!([first, second]);
    params["render"]["exposure"] = json!(0.5);
    params["encoding"] = json!({"codec": "png", "still_after_ms": 0});
    let created = server.create_session(params, None).await;
    assert_eq!(
        created.session.params.render.lights.as_ref().map(Vec::len),
        Some(2)
    );
    let mut stream = server.connect(&created).await;
    let mut events = Vec::new();
    let mean = |f: &ReceivedFrame| {
        f.rgba
            .pixels()
            .map(|p| f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2]))
            .sum::<f64>()
            / f.rgba.pixels().len() as f64
    };
    let both = mean(&stream.next_frame(&mut events).await);
    stream
        .send(json!({"type": "lights", "input_id": 5, "lights": [first]}))
        .await;
    let one = loop {
        let f = stream.next_frame(&mut events).await;
        if f.header.input_id >= 5 {
            break mean(&f);
        }
    };
    assert!(one < both * 0.95, "one light {one} vs two {both}");
    let info = server
        .get_json(&format!("/v1/sessions/{}", created.session.id))
        .await;
    assert_eq!(
        info["params"]["render"]["lights"].as_array().map(Vec::len),
        Some(1),
        "{info}"
    );
    stream
        .send(json!({"type": "light", "index": 1, "light": first}))
        .await;
    let error = stream.next_error().await;
    assert_eq!(error.field.as_deref(), Some("index"), "{error:?}");
    server.stop().await;
}

/// A client that stops reading loses its own frames; another session keeps streaming.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_client_does_not_stall_another() {
    let server = TestServer::start(&[]).await;
    // The stalled session sends big lossless frames so its socket buffers fill quickly.
    let mut stalled_params = direct_session(256, 192);
    stalled_params["encoding"] = json!({"codec": "png", "still_after_ms": 0});
    stalled_params["fps_cap"] = json!(120);
    let stalled = server.create_session(stalled_params, None).await;
    let healthy_params = direct_session(48, 32);
    let healthy = server.create_session(healthy_params, None).await;

    let _stalled_stream = server.connect(&stalled).await; // never read from
    let mut stream = server.connect(&healthy).await;
    let mut events = Vec::new();

    // Wait until the stalled client's socket is full: its sent count stops moving for several
    // of the healthy client's frames while the server skips its ticks.
    let stalled_path = format!("/v1/sessions/{}", stalled.session.id);
    tokio::time::timeout(PATIENCE, async {
        let (mut last_sent, mut unchanged) = (u64::MAX, 0);
        loop {
            stream.next_frame(&mut events).await;
            let st = server.get_json(&stalled_path).await["stats"].clone();
            let sent = st["frames_sent"].as_u64().unwrap_or(0);
            unchanged = if sent == last_sent { unchanged + 1 } else { 0 };
            last_sent = sent;
            if unchanged >= 5 && st["frames_throttled"].as_u64().unwrap_or(0) > 0 {
                return;
            }
        }
    })
    .await
    .expect("the stalled session's socket fills and its ticks are skipped");
    let before = server.get_json(&stalled_path).await["stats"]["frames_rendered"]
        .as_u64()
        .unwrap_or(0);
    // The healthy client keeps getting fresh frames meanwhile.
    let mut seqs = Vec::new();
    for _ in 0..10 {
        seqs.push(stream.next_frame(&mut events).await.header.seq);
    }
    assert!(seqs.windows(2).all(|w| w[1] > w[0]));
    let after = server.get_json(&stalled_path).await["stats"].clone();
    let rendered_meanwhile = after["frames_rendered"].as_u64().unwrap_or(0) - before;
    assert!(
        rendered_meanwhile <= 4,
        "the stalled session should not use the GPU while its frames pile up: {rendered_meanwhile} frames rendered for it during 10 of the other's"
    );
    let metrics = server
        .http
        .get(server.url("/metrics"))
        .send()
        .await
        .expect("metrics")
        .text()
        .await
        .expect("text");
    assert!(
        metrics.contains("lightcast_frames_throttled_total"),
        "{metrics}"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_sessions_each_get_their_own_frames() {
    let server = TestServer::start(&[]).await;
    server.wait_caches_ready("default").await;
    let sizes = [(64u32, 48u32), (80, 40), (48, 48)];
    let mut tasks = Vec::new();
    for (w, h) in sizes {
        let created = server.create_session(small_session(w, h), None).await;
        let mut stream = server.connect(&created).await;
        tasks.push(tokio::spawn(async move {
            let mut events = Vec::new();
            let mut seqs = Vec::new();
            for _ in 0..4 {
                let f = stream.next_frame(&mut events).await;
                assert_eq!((f.header.width, f.header.height), (w, h));
                seqs.push(f.header.seq);
            }
            seqs
        }));
    }
    for t in tasks {
        let seqs = t.await.expect("session task");
        assert!(seqs.windows(2).all(|w| w[1] > w[0]), "{seqs:?}");
    }
    let sessions = server.get_json("/v1/sessions").await;
    assert_eq!(sessions.as_array().map(Vec::len), Some(3));
    server.stop().await;
}

/// Issue 36: sessions of one scene under one light share BRSM's light-side stages, and their
/// frame headers say so: a frame that reuses the cache lighting another session's frame made
/// flags it reused, and the frames of a tick say how many sessions' frames it serves.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sessions_of_one_scene_share_the_light_side_stages_and_say_so() {
    let server = TestServer::start(&[]).await;
    server.wait_caches_ready("default").await;
    let cache_lighting =
        lightcast_server::gi::stages::index_of("cache_lighting").expect("a registered stage");
    let mut tasks = Vec::new();
    for _ in 0..3 {
        let created = server.create_session(small_session(64, 48), None).await;
        let mut stream = server.connect(&created).await;
        tasks.push(tokio::spawn(async move {
            let mut events = Vec::new();
            let mut seen = Vec::new();
            for _ in 0..8 {
                let f = stream.next_frame(&mut events).await;
                let reused = f.header.reused.contains(&cache_lighting);
                let shared = f
                    .header
                    .shared
                    .iter()
                    .find(|(i, _)| *i == cache_lighting)
                    .map_or(0, |&(_, n)| n);
                seen.push((reused, shared));
            }
            seen
        }));
    }
    let mut frames = Vec::new();
    for t in tasks {
        frames.extend(t.await.expect("session task"));
    }
    assert!(
        frames.iter().any(|&(reused, shared)| reused && shared >= 2),
        "a frame reused the cache lighting another session's frame made: {frames:?}"
    );
    assert!(
        frames
            .iter()
            .any(|&(reused, shared)| !reused && shared >= 2),
        "a frame made it for several sessions: {frames:?}"
    );
    assert!(
        frames
            .iter()
            .all(|&(reused, shared)| !reused || shared >= 2),
        "a reused cache lighting serves several sessions: {frames:?}"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_sends_closing_to_open_streams() {
    let server = TestServer::start(&[]).await;
    let params = direct_session(32, 32);
    let created = server.create_session(params, None).await;
    let mut stream = server.connect(&created).await;
    let mut events = Vec::new();
    stream.next_frame(&mut events).await;
    let stopping = tokio::spawn(server.stop());
    assert_eq!(
        stream.closing_reason().await.as_deref(),
        Some("server shutting down")
    );
    stopping.await.expect("shutdown task");
}

/// A session whose client went away without deleting it ends after `--session-idle-secs`;
/// one with its stream attached lives on.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sessions_without_a_stream_end_after_the_idle_time() {
    let server = TestServer::start(&["--session-idle-secs", "1"]).await;
    assert_eq!(
        server.get_json("/v1/server").await["limits"]["session_idle_secs"],
        1
    );
    let params = direct_session(32, 24);
    let abandoned = server.create_session(params.clone(), None).await;
    let watched = server.create_session(params, None).await;
    let mut stream = server.connect(&watched).await;
    let mut events = Vec::new();
    let abandoned_path = format!("/v1/sessions/{}", abandoned.session.id);
    tokio::time::timeout(PATIENCE, async {
        loop {
            stream.next_frame(&mut events).await;
            let status = server.get(&abandoned_path).await.status();
            if status == 404 {
                return;
            }
            assert_eq!(status, 200);
        }
    })
    .await
    .expect("the abandoned session ends");
    // Well past the idle time, the watched session still streams and exists.
    tokio::time::sleep(std::time::Duration::from_millis(1500)).await;
    let seq = stream.next_frame(&mut events).await.header.seq;
    assert!(seq > 1);
    server
        .get_json(&format!("/v1/sessions/{}", watched.session.id))
        .await;
    drop(stream);
    server.stop().await;
}

/// A client that stops reading (so never answers the server's pings) loses its stream after
/// `--stream-silence-secs`, which frees the session for a new stream; one that keeps reading
/// but sends nothing of its own keeps its stream, because its WebSocket library answers pings.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn streams_of_clients_that_stop_answering_pings_close() {
    let server = TestServer::start(&["--stream-silence-secs", "1"]).await;
    let mut params = direct_session(32, 24);
    params["fps_cap"] = json!(10);
    let silent = server.create_session(params.clone(), None).await;
    let silent_path = format!("/v1/sessions/{}", silent.session.id);
    let silent_stream = server.connect(&silent).await;
    let connected = |info: serde_json::Value| info["connected"].as_bool();
    assert_eq!(connected(server.get_json(&silent_path).await), Some(true));

    let reading = server.create_session(params, None).await;
    let mut stream = server.connect(&reading).await;
    let mut events = Vec::new();
    // Reads for well past the silence time (and a few frames, however slow this machine).
    let until = tokio::time::Instant::now() + Duration::from_millis(3500);
    let mut frames = 0;
    tokio::time::timeout(PATIENCE, async {
        while tokio::time::Instant::now() < until || frames < 4 {
            stream.next_frame(&mut events).await;
            frames += 1;
        }
    })
    .await
    .expect("the reading client gets frames");
    assert!(
        !events
            .iter()
            .any(|e| matches!(e, ServerEvent::Closing { .. })),
        "a reading client keeps its stream: {events:?}"
    );

    tokio::time::timeout(PATIENCE, async {
        while connected(server.get_json(&silent_path).await) != Some(false) {
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    })
    .await
    .expect("the silent client's stream is closed");
    drop(silent_stream);
    let ticket: serde_json::Value = server
        .http
        .post(server.url(&format!("{silent_path}/ticket")))
        .send()
        .await
        .expect("ticket")
        .json()
        .await
        .expect("ticket json");
    let mut again = silent.clone();
    again.ticket.ticket = ticket["ticket"].as_str().expect("ticket").to_string();
    server.connect(&again).await.next_frame(&mut events).await;
    drop(stream);
    server.stop().await;
}

/// The reference's BVH is built off the render loop, like the light caches: a `reference`
/// session's first frames on a scene without one show direct light with the GI-pending flag and
/// a `caches_pending` event naming the BVH; once it is built the frames carry path-traced
/// samples, `caches_ready` follows, and the scene lists the BVH as a ready precomputation.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_reference_session_waits_for_the_bvh_built_in_the_background() {
    let server = TestServer::start(&[]).await;
    let info = server.get_json("/v1/scenes/default").await;
    let kinds: Vec<&str> = info["precomputed"]
        .as_array()
        .expect("precomputed list")
        .iter()
        .filter_map(|p| p["kind"].as_str())
        .collect();
    assert!(
        !kinds.contains(&"bvh"),
        "nothing asked for a BVH yet: {kinds:?}"
    );
    let mut params = small_session(48, 32);
    params["render"]["gi"] = json!({"method": "reference", "spp": 2});
    let created = server.create_session(params, None).await;
    let mut stream = server.connect(&created).await;
    let mut events = Vec::new();
    let first = stream.next_frame(&mut events).await;
    assert_ne!(
        first.header.flags & FLAG_GI_PENDING,
        0,
        "the first frame cannot have the BVH it asked for"
    );
    assert!(
        first.stage("path_trace").is_none(),
        "direct light only while pending"
    );
    let traced = loop {
        let f = stream.next_frame(&mut events).await;
        if f.header.flags & FLAG_GI_PENDING == 0 {
            break f;
        }
    };
    assert!(
        traced.stage("path_trace").is_some(),
        "path-traced once the BVH is there"
    );
    // The readiness event is queued with the first traced frame; read until it arrives.
    while !events
        .iter()
        .any(|e| matches!(e, ServerEvent::CachesReady { .. }))
    {
        stream.next_frame(&mut events).await;
    }
    let pending = events.iter().find_map(|e| match e {
        ServerEvent::CachesPending { scene, kind, what } => {
            Some((scene.clone(), kind.clone(), what.clone()))
        }
        _ => None,
    });
    assert_eq!(
        pending,
        Some(("default".to_string(), "bvh".to_string(), "BVH".to_string())),
        "{events:?}"
    );
    let info = server.get_json("/v1/scenes/default").await;
    let bvh = info["precomputed"]
        .as_array()
        .expect("precomputed list")
        .iter()
        .find(|p| p["kind"] == "bvh")
        .expect("the BVH is listed")
        .clone();
    assert_eq!(bvh["state"], "ready", "{bvh}");
    assert_eq!(bvh["label"], "BVH");
    assert_eq!(bvh["progress"], 1.0);
    assert!(bvh["seconds"].as_f64().is_some_and(|s| s >= 0.0), "{bvh}");
    // The old list holds light caches only.
    assert!(info["caches"]
        .as_array()
        .expect("caches list")
        .iter()
        .all(|c| c.get("cache_distance").is_some()));
}
