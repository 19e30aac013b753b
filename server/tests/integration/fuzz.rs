//! Property-based fuzzing of everything that parses what a client or a file sends: the glTF
//! loader, JSON requests with the service's limits, WebSocket control messages and the frame
//! header decoder. Every input must give a value or an error, never a panic (a panic fails the
//! case and proptest shrinks it to a small reproduction).
//!
//! Budget: `LIGHTCAST_FUZZ_CASES` cases per target (default 2048, seconds in CI) from
//! `LIGHTCAST_FUZZ_SEED` (default 0, so CI is repeatable); `bench/fuzz.sh` runs hours of it with
//! fresh seeds. Driven through `TestRunner` rather than the `proptest!` macro so the budget and
//! the seed come from the environment and the cases run are counted and printed.

use lightcast_protocol::{ClientMessage, FrameHeader, RenderRequest, SessionParams};
use lightcast_server::gi::precompute::Store;
use lightcast_server::scene::gltf_loader::{load_gltf_slice, LoadLimits};
use lightcast_server::scene::Scene;
use lightcast_server::service::error::{from_value, parse_json};
use lightcast_server::service::params;
use lightcast_server::service::scenes::SceneRegistry;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};
use serde_json::{json, Map, Value};

const CORNELL_GLB: &[u8] = include_bytes!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../tests/data/cornell-box/cornell-box.glb"
));

fn env_u64(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// A runner with this run's budget and seed; `target` names it in the output.
fn runner(target: &str) -> TestRunner {
    let cases = env_u64("LIGHTCAST_FUZZ_CASES", 2048) as u32;
    let seed = env_u64("LIGHTCAST_FUZZ_SEED", 0);
    let mut seed_bytes = [0u8; 32];
    seed_bytes[..8].copy_from_slice(&seed.to_le_bytes());
    seed_bytes[8..8 + target.len().min(24)]
        .copy_from_slice(&target.as_bytes()[..target.len().min(24)]);
    let config = Config {
        cases,
        // Failures are reported (and shrunk) in the output; no files are written.
        failure_persistence: None,
        ..Config::default()
    };
    TestRunner::new_with_rng(
        config,
        TestRng::from_seed(RngAlgorithm::ChaCha, &seed_bytes),
    )
}

/// Runs `test` over `strategy` and prints how many cases ran and how many of them `test`
/// accepted (returned `true` for: parsed, loaded), which shows how deep the inputs reach.
fn fuzz<S: Strategy>(
    target: &str,
    strategy: S,
    test: impl Fn(S::Value) -> Result<bool, TestCaseError>,
) {
    let mut runner = runner(target);
    let accepted = std::sync::atomic::AtomicU64::new(0);
    let result = runner.run(&strategy, |input| {
        if test(input)? {
            accepted.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
        Ok(())
    });
    if let Err(e) = result {
        panic!("fuzz target {target}: {e}");
    }
    eprintln!(
        "fuzz target {target}: {} cases, {} accepted, no failure",
        runner.config().cases,
        accepted.into_inner()
    );
}

// ---- JSON ---------------------------------------------------------------------------------

/// Field names of the protocol's request types, so generated objects reach deep into them
/// instead of failing at the first unknown key.
const KEYS: &[&str] = &[
    "render",
    "scene",
    "width",
    "height",
    "camera",
    "light",
    "exposure",
    "shadow_map_size",
    "gi",
    "view",
    "format",
    "quality",
    "compare_to",
    "compare_spp",
    "method",
    "rsm_size",
    "view_samples",
    "val_count",
    "defensive",
    "occlusion",
    "glossy_exponent",
    "cache_distance",
    "cache_angle",
    "bounces",
    "spp",
    "position",
    "target",
    "up",
    "fov_y_deg",
    "near",
    "far",
    "kind",
    "direction",
    "color",
    "intensity",
    "range",
    "inner_cone_deg",
    "outer_cone_deg",
    "fps_cap",
    "codec",
    "type",
    "patch",
    "input_id",
    "seq",
    "nonce",
    "paused",
    "x",
];

/// Strings the protocol gives meaning to, and some it does not.
const STRINGS: &[&str] = &[
    "brsm",
    "lightskin",
    "none",
    "reference",
    "final",
    "indirect",
    "rsm-flux",
    "importance",
    "selected-vals",
    "caches",
    "png",
    "jpeg",
    "raw_final",
    "raw_indirect",
    "directional",
    "point",
    "spot",
    "camera",
    "update",
    "pause",
    "resume",
    "still",
    "ack",
    "ping",
    "cornell",
    "procedural:street?blocks=2",
    "NaN",
    "inf",
    "-inf",
    "1e39",
    "",
    "\u{0}",
    "é\u{202e}",
];

fn json_leaf() -> impl Strategy<Value = Value> {
    prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::Bool),
        any::<i64>().prop_map(Value::from),
        any::<u64>().prop_map(Value::from),
        // Numbers near the limits the server checks, and far outside them.
        prop::sample::select(vec![
            0.0,
            -1.0,
            0.5,
            1.0,
            16.0,
            64.0,
            255.0,
            256.0,
            1024.0,
            4096.0,
            16384.0,
            65536.0,
            1e9,
            -1e9,
            1e30,
            f64::MAX,
            f64::MIN_POSITIVE,
            1e-30,
        ])
        .prop_map(Value::from),
        any::<f64>().prop_map(Value::from),
        prop::sample::select(STRINGS).prop_map(Value::from),
        "\\PC{0,12}".prop_map(Value::from),
    ]
}

fn json_value() -> impl Strategy<Value = Value> {
    json_leaf().prop_recursive(5, 64, 8, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..6).prop_map(Value::Array),
            prop::collection::vec(
                (
                    prop_oneof![
                        4 => prop::sample::select(KEYS).prop_map(str::to_string),
                        1 => "\\PC{0,8}",
                    ],
                    inner
                ),
                0..8
            )
            .prop_map(|fields| Value::Object(fields.into_iter().collect::<Map<_, _>>())),
        ]
    })
}

/// A scene entry for resolving requests, built once (the Cornell box, no GPU involved).
fn cornell_entry() -> std::sync::Arc<lightcast_server::service::scenes::SceneEntry> {
    let scene: Scene = load_gltf_slice(CORNELL_GLB, None, "cornell", LoadLimits::NONE)
        .expect("the Cornell box loads");
    // No light caches are queued for a detached scene: the store is never written.
    let store = Store::new(std::env::temp_dir().join("lightcast-fuzz-unused"));
    SceneRegistry::new(store, &default_limits(), None)
        .detached(scene, 0.0)
        .expect("the Cornell box is within the default budgets")
}

fn default_limits() -> lightcast_protocol::Limits {
    use clap::Parser;
    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        limits: lightcast_server::service::config::LimitArgs,
    }
    Cli::try_parse_from(["lightcast-server"])
        .expect("defaults parse")
        .limits
        .limits(0)
        .expect("default limits are valid")
}

/// Any JSON (and any bytes) as a render request, session parameters or a control message:
/// parsed with the service's strict parser, then, when it parses, checked against the
/// default limits and resolved into frame settings as a render would be.
#[test]
fn json_requests_and_messages_never_panic() {
    let entry = cornell_entry();
    let limits = default_limits();
    let check = |value: Value| {
        let bytes = serde_json::to_vec(&value).expect("serialises");
        let mut resolved = false;
        if let Ok(request) = parse_json::<RenderRequest>(&bytes) {
            resolved |= params::resolve(&request.render, &entry, &limits, 8192).is_ok();
            let _ = params::check_quality(request.quality);
        }
        if let Ok(session) = parse_json::<SessionParams>(&bytes) {
            resolved |= params::resolve(&session.render, &entry, &limits, 8192).is_ok();
        }
        let message = from_value::<ClientMessage>(value).is_ok();
        Ok(resolved || message)
    };
    // Whole requests, and values under `render` where most of the checks are.
    fuzz("json-any", json_value(), check);
    fuzz(
        "json-render",
        json_value().prop_map(|v| json!({ "render": v })),
        check,
    );
    fuzz(
        "json-bytes",
        prop::collection::vec(any::<u8>(), 0..512),
        |bytes| {
            let request = parse_json::<RenderRequest>(&bytes).is_ok();
            Ok(parse_json::<SessionParams>(&bytes).is_ok() || request)
        },
    );
}

// ---- Frame header -------------------------------------------------------------------------

fn frame_header() -> impl Strategy<Value = FrameHeader> {
    let stage = (
        0..lightcast_server::gi::stages::all().len() as u16,
        any::<f32>(),
        any::<bool>(),
    );
    (
        (any::<u64>(), any::<u64>(), any::<u64>(), any::<u64>()),
        (
            any::<u32>(),
            any::<u32>(),
            any::<bool>(),
            any::<u8>(),
            any::<u8>(),
        ),
        (any::<f32>(), any::<f32>(), any::<f32>()),
        prop::collection::vec(stage, 0..20),
        (any::<u32>(), any::<f32>()),
    )
        .prop_map(
            |(
                (seq, input_id, start, send),
                (w, h, png, flags, quality),
                (e, r, g),
                stages,
                (samples, err),
            )| {
                FrameHeader {
                    seq,
                    input_id,
                    render_start_us: start,
                    send_us: send,
                    width: w,
                    height: h,
                    codec: if png {
                        lightcast_protocol::Codec::Png
                    } else {
                        lightcast_protocol::Codec::Jpeg
                    },
                    flags,
                    quality,
                    encode_ms: e,
                    readback_ms: r,
                    gpu_ms: g,
                    payload_len: 0,
                    // A stage index is reused or not, every time it is listed.
                    reused: stages
                        .iter()
                        .filter(|&&(i, _, _)| stages.iter().any(|&(j, _, r)| j == i && r))
                        .map(|&(i, _, _)| i)
                        .collect(),
                    // Every third stage index serves several sessions, as many as its index
                    // says (2 to 251), every time it is listed.
                    shared: stages
                        .iter()
                        .filter(|&&(i, _, _)| i % 3 == 0)
                        .map(|&(i, _, _)| (i, (i % 250 + 2) as u8))
                        .collect(),
                    stages: stages.iter().map(|&(i, ms, _)| (i, ms)).collect(),
                    samples,
                    relative_error: err,
                }
            },
        )
}

/// Encoded headers decode to themselves; the same bytes with flips, truncations and random
/// lengths decode or fail, and a decoded payload always lies inside the message.
#[test]
fn frame_headers_round_trip_and_corrupt_ones_never_panic() {
    fuzz(
        "frame-header",
        (
            frame_header(),
            prop::collection::vec(any::<u8>(), 0..64),
            prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..6),
            any::<prop::sample::Index>(),
        ),
        |(header, payload, flips, cut)| {
            let message = header.encode_with(&payload);
            let (decoded, rest) = FrameHeader::decode(&message)
                .map_err(|e| TestCaseError::fail(format!("a valid header fails: {e}")))?;
            prop_assert_eq!(rest, &payload[..]);
            prop_assert_eq!(decoded.stages.len(), header.stages.len());
            prop_assert_eq!(decoded.seq, header.seq);
            let mut corrupt = message.clone();
            for (at, byte) in flips {
                let i = at.index(corrupt.len());
                corrupt[i] = byte;
            }
            corrupt.truncate(cut.index(corrupt.len() + 1));
            match FrameHeader::decode(&corrupt) {
                Ok((_, rest)) => {
                    prop_assert!(rest.len() <= corrupt.len());
                    Ok(true)
                }
                Err(_) => Ok(false),
            }
        },
    );
    fuzz(
        "frame-bytes",
        (any::<bool>(), prop::collection::vec(any::<u8>(), 0..200)),
        |(framed, mut bytes)| {
            // Half the inputs start like a frame so the decoder gets past the magic.
            if framed {
                bytes.splice(0..0, *b"LCFR\x01\x00");
            }
            Ok(FrameHeader::decode(&bytes).is_ok())
        },
    );
}

// ---- glTF ---------------------------------------------------------------------------------

/// The JSON and BIN chunks of a `.glb`.
fn split(glb: &[u8]) -> (Value, Vec<u8>) {
    let json_len = u32::from_le_bytes(glb[12..16].try_into().expect("4 bytes")) as usize;
    let json: Value = serde_json::from_slice(&glb[20..20 + json_len]).expect("JSON chunk");
    let bin_start = 20 + json_len + 8;
    (json, glb[bin_start..].to_vec())
}

/// A `.glb` of `json` and `bin` with correct chunk lengths and padding.
fn pack(json: &Value, bin: &[u8]) -> Vec<u8> {
    let mut j = serde_json::to_vec(json).expect("serialises");
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    let total = 12 + 8 + j.len() + 8 + b.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}

/// JSON pointers of every number in `value`, in document order.
fn numbers(value: &Value, at: String, out: &mut Vec<String>) {
    match value {
        Value::Number(_) => out.push(at),
        Value::Array(items) => {
            for (i, v) in items.iter().enumerate() {
                numbers(v, format!("{at}/{i}"), out);
            }
        }
        Value::Object(map) => {
            for (k, v) in map {
                numbers(
                    v,
                    format!("{at}/{}", k.replace('~', "~0").replace('/', "~1")),
                    out,
                );
            }
        }
        _ => {}
    }
}

/// Replaces the `which`-th number of `json` with `with`.
fn replace_number(json: &mut Value, which: prop::sample::Index, with: Value) {
    let mut pointers = Vec::new();
    numbers(json, String::new(), &mut pointers);
    if !pointers.is_empty() {
        if let Some(slot) = json.pointer_mut(&pointers[which.index(pointers.len())]) {
            *slot = with;
        }
    }
}

/// The Cornell box `.glb` with its JSON numbers set to extremes (counts, offsets, indices,
/// strides, component types, material factors…), its bytes flipped, truncated or extended,
/// loaded with an upload's limits: a scene or an error, never a panic.
#[test]
fn corrupted_gltf_files_never_panic() {
    let limits = LoadLimits::upload(2_000_000);
    let extremes = prop::sample::select(vec![
        json!(0),
        json!(1),
        json!(-1),
        json!(3),
        json!(4),
        json!(5120),
        json!(5126),
        json!(65535),
        json!(2147483647u64),
        json!(4294967295u64),
        json!(9007199254740993u64),
        json!(1e308),
        json!(-0.0),
        json!(0.5),
    ]);
    let (json, bin) = split(CORNELL_GLB);
    fuzz(
        "gltf-json-numbers",
        prop::collection::vec((any::<prop::sample::Index>(), extremes), 1..4),
        |edits| {
            let mut doc = json.clone();
            for (which, with) in edits {
                replace_number(&mut doc, which, with);
            }
            Ok(load_gltf_slice(&pack(&doc, &bin), None, "fuzz", limits).is_ok())
        },
    );
    fuzz(
        "gltf-bytes",
        (
            prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..16),
            // Truncated or extended in a quarter of the cases each: flips alone reach
            // further into the loader.
            prop::option::weighted(0.25, any::<prop::sample::Index>()),
            prop::option::weighted(0.25, prop::collection::vec(any::<u8>(), 1..32)),
        ),
        |(flips, cut, tail)| {
            let mut bytes = CORNELL_GLB.to_vec();
            for (at, byte) in flips {
                let i = at.index(bytes.len());
                bytes[i] = byte;
            }
            if let Some(cut) = cut {
                bytes.truncate(cut.index(bytes.len() + 1));
            }
            bytes.extend_from_slice(&tail.unwrap_or_default());
            Ok(load_gltf_slice(&bytes, None, "fuzz", limits).is_ok())
        },
    );
}
