//! `h264` session streams end to end: the server's encoder against an independent decoder
//! (OpenH264's), keyframes when the stream needs them, and precise refusals.

use lightcast_e2e::{direct_session, mean_abs_diff, Incoming, ReceivedFrame, TestServer};
use lightcast_protocol::frame::FLAG_KEYFRAME;
use lightcast_protocol::{Codec, ServerEvent};
use serde_json::{json, Value};

fn h264_session(width: u32, height: u32) -> Value {
    let mut params = direct_session(width, height);
    params["encoding"] = json!({"codec": "h264", "still_after_ms": 0});
    params
}

fn keyframe(f: &ReceivedFrame) -> bool {
    f.header.flags & FLAG_KEYFRAME != 0
}

fn assert_no_render_errors(events: &[ServerEvent]) {
    assert!(
        !events
            .iter()
            .any(|e| matches!(e, ServerEvent::RenderError { .. })),
        "{events:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_h264_session_streams_decodable_video_with_keyframes_where_needed() {
    let server = TestServer::start(&[]).await;
    let info = server.get_json("/v1/server").await;
    assert_eq!(info["video"]["encoder"], "openh264", "{info}");
    assert_eq!(info["video"]["hardware"], false);
    assert!(info["stages"]
        .as_array()
        .is_some_and(|s| s.contains(&json!("yuv420"))));

    let created = server.create_session(h264_session(96, 64), None).await;
    let mut stream = server.connect(&created).await;
    match stream.next().await {
        Incoming::Event(ServerEvent::Hello {
            codecs,
            video_encoder,
            ..
        }) => {
            assert!(codecs.contains(&Codec::H264), "{codecs:?}");
            assert_eq!(video_encoder.as_deref(), Some("openh264"));
        }
        _ => panic!("the first message must be hello"),
    }
    let mut events = Vec::new();
    let first = stream.next_frame(&mut events).await;
    assert_eq!(first.header.codec, Codec::H264);
    assert!(keyframe(&first), "a stream starts with a keyframe");
    assert_eq!(
        first.rgba.dimensions(),
        (96, 64),
        "the decoder shows the frame"
    );
    assert!(first.stage("yuv420").is_some(), "converted on the GPU");
    // Annex B with the parameter sets in front of the picture.
    assert_eq!(&first.payload[..4], &[0, 0, 0, 1]);
    assert_eq!(first.payload[4] & 0x1f, 7, "SPS first");

    let mut deltas = 0;
    for _ in 0..4 {
        let f = stream.next_frame(&mut events).await;
        deltas += usize::from(!keyframe(&f));
        assert!(
            f.payload.len() < first.payload.len(),
            "P-frames are smaller"
        );
    }
    assert_eq!(deltas, 4, "no keyframe without a reason");

    // The picture follows the camera.
    stream
        .send(json!({"type": "camera", "input_id": 3, "camera": {
            "position": [0.9, 1.0, 2.5], "target": [-1.0, 1.0, 0.0], "fov_y_degrees": 50.0}}))
        .await;
    let moved = loop {
        let f = stream.next_frame(&mut events).await;
        if f.header.input_id == 3 {
            break f;
        }
    };
    let change = mean_abs_diff(&first.rgba, &moved.rgba);
    assert!(
        change > 5.0,
        "the camera move changed the decoded picture by {change:.1}"
    );

    // A client that lost its place asks for a keyframe.
    stream.send(json!({"type": "keyframe"})).await;
    let mut asked = false;
    for _ in 0..3 {
        asked |= keyframe(&stream.next_frame(&mut events).await);
    }
    assert!(asked, "a keyframe follows the request");

    // A new size starts a new stream at a keyframe the same decoder follows.
    stream
        .send(json!({"type": "update", "patch": {"render": {"width": 128, "height": 80}}}))
        .await;
    let resized = loop {
        let f = stream.next_frame(&mut events).await;
        if f.header.width == 128 {
            break f;
        }
    };
    assert!(
        keyframe(&resized),
        "the first frame of a new size is a keyframe"
    );
    assert_eq!(resized.rgba.dimensions(), (128, 80));

    // Every switch back to H.264 after JPEG frames starts at a keyframe: a client that
    // decoded JPEG meanwhile may have dropped its video decoder (issue 30: the second switch
    // sent a P slice first).
    for round in 0..2 {
        for codec in [Codec::Jpeg, Codec::H264] {
            let name = serde_json::to_value(codec).expect("codec");
            stream
                .send(json!({"type": "update", "patch": {"encoding": {"codec": name}}}))
                .await;
            let switched = loop {
                let f = stream.next_frame(&mut events).await;
                if f.header.codec == codec {
                    break f;
                }
            };
            if codec == Codec::H264 {
                assert!(
                    keyframe(&switched),
                    "switch {round}: the first H.264 frame is a P slice"
                );
            }
        }
    }
    assert_no_render_errors(&events);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_video_parameters_are_refused_naming_the_field() {
    let server = TestServer::start(&[]).await;
    let cases: [(Value, &str); 8] = [
        (json!({"encoding": {"codec": "h265"}}), "encoding.codec"),
        (
            json!({"encoding": {"codec": "h264", "bitrate_kbps": 50}}),
            "encoding.bitrate_kbps",
        ),
        (
            json!({"encoding": {"codec": "h264", "max_qp": 60}}),
            "encoding.max_qp",
        ),
        (
            json!({"encoding": {"still_codec": "h264"}}),
            "encoding.still_codec",
        ),
        (
            json!({"encoding": {"interactive_scale": 0.1}}),
            "encoding.interactive_scale",
        ),
        (
            json!({"encoding": {"interactive_scale": 1.5}}),
            "encoding.interactive_scale",
        ),
        (
            json!({"encoding": {"codec": "h264"}, "render": {"width": 97, "height": 64}}),
            "render.width",
        ),
        (
            json!({"encoding": {"codec": "h264"}, "render": {"width": 96, "height": 63}}),
            "render.height",
        ),
    ];
    for (params, field) in cases {
        let resp = server
            .http
            .post(server.url("/v1/sessions"))
            .json(&params)
            .send()
            .await
            .expect("request");
        assert_eq!(resp.status(), 400, "{params}");
        let body: Value = resp.json().await.expect("error JSON");
        assert_eq!(body["field"], field, "{params}: {body}");
    }
    // The same checks guard a running session: an odd size is refused, the session goes on.
    let created = server.create_session(h264_session(64, 48), None).await;
    let mut stream = server.connect(&created).await;
    stream
        .send(json!({"type": "update", "patch": {"render": {"width": 65}}}))
        .await;
    let error = stream.next_error().await;
    assert_eq!(error.field.as_deref(), Some("render.width"), "{error:?}");
    let mut events = Vec::new();
    let after = stream.next_frame(&mut events).await;
    assert_eq!(after.rgba.dimensions(), (64, 48));
    server.stop().await;
}

/// `interactive_scale`: while input keeps arriving the frames are rendered and encoded at half
/// the size (each size change a keyframe the same decoder follows); once input rests the
/// still and the frames after it are full size again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn interactive_scale_streams_smaller_frames_while_moving_and_full_ones_at_rest() {
    use lightcast_protocol::frame::{FLAG_MOVING, FLAG_STILL};
    let server = TestServer::start(&[]).await;
    let mut params = h264_session(128, 96);
    params["encoding"]["interactive_scale"] = json!(0.5);
    params["encoding"]["still_after_ms"] = json!(500);
    let created = server.create_session(params, None).await;
    let mut stream = server.connect(&created).await;
    let mut events = Vec::new();
    // Input on every frame: each one shows the newest camera and is "moving".
    let mut moving = Vec::new();
    for k in 1..=6u64 {
        let x = 0.2 * k as f32;
        stream
            .send(json!({"type": "camera", "input_id": k, "camera": {
                "position": [x, 1.0, 2.5], "target": [0.0, 1.0, 0.0], "fov_y_degrees": 50.0}}))
            .await;
        let f = loop {
            let f = stream.next_frame(&mut events).await;
            if f.header.input_id == k {
                break f;
            }
        };
        moving.push(f);
    }
    for f in &moving {
        assert!(
            f.header.flags & FLAG_MOVING != 0,
            "input {} moving",
            f.header.input_id
        );
        assert_eq!((f.header.width, f.header.height), (64, 48));
        assert_eq!(f.rgba.dimensions(), (64, 48), "decoded at the reduced size");
    }
    // At rest: the lossless still at full size, then full-size video again.
    let still = loop {
        let f = stream.next_frame(&mut events).await;
        if f.header.flags & FLAG_STILL != 0 {
            break f;
        }
    };
    assert_eq!(still.header.codec, Codec::Png);
    assert_eq!(still.rgba.dimensions(), (128, 96));
    let rest = stream.next_frame(&mut events).await;
    assert_eq!(rest.header.codec, Codec::H264);
    assert_eq!(rest.header.flags & FLAG_MOVING, 0);
    assert_eq!(rest.rgba.dimensions(), (128, 96));
    assert!(keyframe(&rest), "a new size starts at a keyframe");
    // The reduced frame shows the same view as the still, upscaled: close, not equal.
    let upscaled = image::imageops::resize(
        &moving[5].rgba,
        128,
        96,
        image::imageops::FilterType::Triangle,
    );
    let diff = mean_abs_diff(&upscaled, &still.rgba);
    assert!(
        diff < 12.0,
        "the half-size frame upscaled differs by {diff:.1}"
    );
    assert_no_render_errors(&events);
    server.stop().await;
}
