//! What a hostile client tries (issue 15, sections 1 and 3): connections held idle or fed
//! slowly, bodies larger than their limits, JSON that is not an object, repeated keys, long
//! strings, and requests the HTTP layer refuses; every refusal is a JSON error and the server
//! keeps answering everyone else.

use lightcast_e2e::{cornell_glb, direct_session, TestServer, PATIENCE};
use serde_json::{json, Value};
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};
use tokio_tungstenite::tungstenite::Message;

/// A loopback source address: Linux routes all of 127.0.0.0/8 to the loopback interface, so
/// tests can be several clients as far as the server's per-address cap is concerned.
fn loopback(last: u8) -> IpAddr {
    IpAddr::V4(Ipv4Addr::new(127, 0, 0, last))
}

fn server_addr(server: &TestServer) -> SocketAddr {
    server
        .base
        .trim_start_matches("http://")
        .parse()
        .expect("the server's address")
}

/// A TCP connection to the server from `from`.
async fn connect_from(from: IpAddr, to: SocketAddr) -> TcpStream {
    let socket = TcpSocket::new_v4().expect("socket");
    socket.bind(SocketAddr::new(from, 0)).expect("bind");
    socket.connect(to).await.expect("connect")
}

/// Sends `request` from `from` and reads the whole answer (the request says
/// `Connection: close`, or the server closes): its status and JSON body.
async fn exchange(from: IpAddr, to: SocketAddr, request: &[u8]) -> (u16, Value) {
    let mut stream = connect_from(from, to).await;
    stream.write_all(request).await.expect("send the request");
    let mut answer = Vec::new();
    tokio::time::timeout(PATIENCE, stream.read_to_end(&mut answer))
        .await
        .expect("the server answers and closes in time")
        .expect("read");
    parse_answer(&answer)
}

fn parse_answer(answer: &[u8]) -> (u16, Value) {
    let text = String::from_utf8_lossy(answer);
    let status = text
        .split(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("an HTTP status line: {text}"));
    let body = text.split_once("\r\n\r\n").map_or("", |(_, b)| b);
    let json = serde_json::from_str(body).unwrap_or_else(|_| panic!("a JSON body: {text}"));
    (status, json)
}

fn assert_error(status: u16, body: &Value, want_status: u16, kind: &str, context: &str) {
    assert_eq!(status, want_status, "{context}: {body}");
    assert_eq!(body["error"], kind, "{context}: {body}");
    assert!(
        body["message"].as_str().is_some_and(|m| !m.is_empty()),
        "{context}: {body}"
    );
}

/// Reads until the server closes the connection; returns when it did.
async fn closed_by_server(mut stream: TcpStream) -> Instant {
    let mut buf = [0u8; 1024];
    loop {
        match stream.read(&mut buf).await {
            Ok(0) | Err(_) => return Instant::now(),
            Ok(_) => {}
        }
    }
}

const GET_HEALTHZ: &[u8] = b"GET /healthz HTTP/1.1\r\nHost: test\r\nConnection: close\r\n\r\n";

/// A connection from `from` that the server admitted: a keep-alive request on it was answered
/// 200, and it stays open, idle. Connections of earlier requests give their places back only
/// when the server's side of them has closed (after [`exchange`] returns, and a refused body
/// lingers up to two seconds), so a connection opened meanwhile may be refused: it is retried.
/// Without this a place freed after the connections were opened let a request through that the
/// test expected refused (CI, once).
async fn admitted_from(from: IpAddr, to: SocketAddr) -> TcpStream {
    const KEEP_ALIVE_HEALTHZ: &[u8] = b"GET /healthz HTTP/1.1\r\nHost: test\r\n\r\n";
    let admitted = tokio::time::timeout(PATIENCE, async {
        loop {
            let mut stream = connect_from(from, to).await;
            stream
                .write_all(KEEP_ALIVE_HEALTHZ)
                .await
                .expect("send the request");
            if read_one_answer(&mut stream).await == 200 {
                return stream;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    })
    .await;
    admitted.expect("the server admits a connection once earlier ones closed")
}

/// The status of one answer read off a keep-alive connection (its head and its
/// `Content-Length` body), leaving the connection open.
async fn read_one_answer(stream: &mut TcpStream) -> u16 {
    let mut answer = Vec::new();
    let mut buf = [0u8; 1024];
    loop {
        let text = String::from_utf8_lossy(&answer);
        if let Some((head, body)) = text.split_once("\r\n\r\n") {
            let length = head
                .lines()
                .filter_map(|line| line.split_once(':'))
                .find(|(name, _)| name.eq_ignore_ascii_case("content-length"))
                .and_then(|(_, value)| value.trim().parse::<usize>().ok())
                .unwrap_or_else(|| panic!("a Content-Length: {head}"));
            if body.len() >= length {
                return parse_answer(&answer).0;
            }
        }
        let n = stream.read(&mut buf).await.expect("read");
        assert!(n > 0, "the server closed before its answer ended: {text}");
        answer.extend_from_slice(&buf[..n]);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idle_and_slow_connections_are_capped_and_closed_while_others_are_served() {
    let server = TestServer::start(&[
        "--max-connections",
        "64",
        "--max-connections-per-address",
        "32",
        "--header-timeout-ms",
        "5000",
    ])
    .await;
    let addr = server_addr(&server);
    let attacker = loopback(1);
    let opened = Instant::now();
    // 24 connections that never send a byte, 8 that send a request head a line at a time.
    let mut idle = Vec::new();
    for _ in 0..24 {
        idle.push(connect_from(attacker, addr).await);
    }
    let mut slow = Vec::new();
    for _ in 0..8 {
        let mut stream = connect_from(attacker, addr).await;
        slow.push(tokio::spawn(async move {
            let _ = stream.write_all(b"GET /healthz HTTP/1.1\r\n").await;
            for i in 0..200 {
                tokio::time::sleep(Duration::from_millis(100)).await;
                if stream
                    .write_all(format!("x-slow-{i}: 1\r\n").as_bytes())
                    .await
                    .is_err()
                {
                    break;
                }
            }
            closed_by_server(stream).await
        }));
    }

    // The address holds its cap: a 33rd connection is refused with a JSON 429.
    let (status, body) = exchange(attacker, addr, GET_HEALTHZ).await;
    assert_error(
        status,
        &body,
        429,
        "too_many_connections",
        "33rd connection",
    );

    // Another client is served while all of them are held (they are still open afterwards:
    // reading finds nothing yet rather than the end).
    let other = lightcast_e2e::http_builder()
        .local_address(loopback(2))
        .build()
        .expect("client");
    let mut slowest = Duration::ZERO;
    for _ in 0..10 {
        let asked = Instant::now();
        let resp = tokio::time::timeout(PATIENCE, other.get(server.url("/healthz")).send())
            .await
            .expect("answered in time")
            .expect("healthz");
        assert_eq!(resp.status(), 200);
        slowest = slowest.max(asked.elapsed());
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    for stream in &idle {
        let still_open = matches!(
            stream.try_read(&mut [0u8; 16]),
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock
        );
        assert!(still_open, "the stalled connections were held meanwhile");
    }
    eprintln!("slowest /healthz of another client while 32 connections stalled: {slowest:?}");

    // The server closes every stalled connection itself once the header timeout passed.
    for stream in idle {
        let closed = tokio::time::timeout(PATIENCE, closed_by_server(stream))
            .await
            .expect("an idle connection is closed by the server");
        assert!(closed.duration_since(opened) >= Duration::from_millis(4900));
    }
    for task in slow {
        let closed = tokio::time::timeout(PATIENCE, task)
            .await
            .expect("a slow connection is closed by the server")
            .expect("the slow client task");
        assert!(closed.duration_since(opened) >= Duration::from_millis(4900));
    }
    // With its connections gone, the address is served again.
    let (status, body) = exchange(attacker, addr, GET_HEALTHZ).await;
    assert_eq!(status, 200, "{body}");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_connection_total_is_capped_and_oversized_bodies_are_refused_before_sending() {
    let server = TestServer::start(&[
        "--max-connections",
        "6",
        "--max-connections-per-address",
        "4",
        "--max-upload-bytes",
        "100000",
        "--max-message-bytes",
        "4096",
    ])
    .await;
    let addr = server_addr(&server);

    // `Expect: 100-continue` with a declared body over the limit: 413 at once, not `100
    // Continue` (the body is never sent here, so an answer proves it was not waited for).
    for (path, content_type, length) in [
        ("/v1/scenes", "model/gltf-binary", 1_000_000_000u64),
        (
            "/v1/render",
            "multipart/form-data; boundary=x",
            1_000_000_000,
        ),
        ("/v1/sessions", "application/json", 100_000),
        ("/v1/render", "application/json", 100_000),
        ("/v1/scenes", "application/json", 100_000),
    ] {
        let request = format!(
            "POST {path} HTTP/1.1\r\nHost: test\r\nContent-Type: {content_type}\r\n\
             Content-Length: {length}\r\nExpect: 100-continue\r\nConnection: close\r\n\r\n"
        );
        let (status, body) = exchange(loopback(1), addr, request.as_bytes()).await;
        assert_error(status, &body, 413, "too_large", path);
    }

    // A body refused unread closes its connection, and the answer says so, so a client does not
    // send its next request on a connection about to close.
    let resp = server
        .http
        .post(server.url("/v1/scenes"))
        .header("content-type", "model/gltf-binary")
        .body(vec![0u8; 300_000])
        .send()
        .await
        .expect("request");
    assert_eq!(resp.status(), 413);
    assert_eq!(
        resp.headers()
            .get("connection")
            .and_then(|v| v.to_str().ok()),
        Some("close")
    );

    // Four idle connections from one address, two from another: the total is reached. Each is
    // held only once the server admitted it, so the server's own count is known to include it.
    let mut held = Vec::new();
    for _ in 0..4 {
        held.push(admitted_from(loopback(1), addr).await);
    }
    let (status, body) = exchange(loopback(1), addr, GET_HEALTHZ).await;
    assert_error(
        status,
        &body,
        429,
        "too_many_connections",
        "5th from one address",
    );
    for _ in 0..2 {
        held.push(admitted_from(loopback(2), addr).await);
    }
    let (status, body) = exchange(loopback(3), addr, GET_HEALTHZ).await;
    assert_error(status, &body, 503, "too_many_connections", "over the total");
    drop(held);
    // Closed connections give their places back.
    let answered = tokio::time::timeout(PATIENCE, async {
        loop {
            let (status, _) = exchange(loopback(3), addr, GET_HEALTHZ).await;
            if status == 200 {
                return;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    })
    .await;
    assert!(answered.is_ok(), "served again once connections closed");
    server.stop().await;
}

/// One request with a JSON (or any) body; its status and JSON error.
async fn send(
    server: &TestServer,
    method: &str,
    path: &str,
    content_type: &str,
    body: impl Into<reqwest::Body>,
) -> (u16, Value) {
    let method = reqwest::Method::from_bytes(method.as_bytes()).expect("method");
    let resp = server
        .http
        .request(method, server.url(path))
        .header("content-type", content_type)
        .body(body)
        .send()
        .await
        .expect("request");
    let status = resp.status().as_u16();
    let text = resp.text().await.expect("body");
    let json = serde_json::from_str(&text).unwrap_or_else(|_| panic!("not JSON: {text}"));
    (status, json)
}

/// Method, path, content type, body; the status, error kind and field expected.
type Case<'a> = (
    &'a str,
    &'a str,
    &'a str,
    Vec<u8>,
    u16,
    &'a str,
    Option<&'a str>,
);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bodies_are_bounded_json_objects_and_every_error_names_its_field() {
    let server = TestServer::start(&[
        "--max-upload-bytes",
        "200000",
        "--max-message-bytes",
        "4096",
        "--max-header-bytes",
        "4096",
    ])
    .await;
    let created = server.create_session(direct_session(32, 32), None).await;
    let session = format!("/v1/sessions/{}", created.session.id);
    let long = "x".repeat(3000);
    let json = "application/json";
    let long_name = format!("/v1/scenes?name={long}");
    let long_uri = format!("/healthz?{}", "q".repeat(9000));
    let cases: Vec<Case> = vec![
        // JSON bodies are held to --max-message-bytes also where uploads are accepted.
        ("POST", "/v1/render", json, format!(r#"{{"pad":"{}"}}"#, "x".repeat(10_000)).into(), 413, "too_large", None),
        ("POST", "/v1/render", json, format!("{{}}{}", " ".repeat(10_000)).into(), 413, "too_large", None),
        ("POST", "/v1/render", "application/octet-stream", vec![b'z'; 100_000], 413, "too_large", None),
        ("POST", "/v1/scenes", json, format!(r#"{{"procedural":"cornell","name":"{}"}}"#, "x".repeat(10_000)).into(), 413, "too_large", None),
        // Every string the server keeps is bounded.
        ("POST", "/v1/scenes", json, format!(r#"{{"procedural":"cornell","name":"{long}"}}"#).into(), 400, "invalid_field", Some("name")),
        ("POST", "/v1/scenes", json, format!(r#"{{"procedural":"cornell?{long}"}}"#).into(), 400, "invalid_field", Some("procedural")),
        ("POST", &long_name, "model/gltf-binary", cornell_glb(), 400, "invalid_field", Some("name")),
        // Anything but an object is refused where an object is documented.
        ("POST", "/v1/sessions", json, b"[]".to_vec(), 400, "malformed_json", None),
        ("POST", "/v1/sessions", json, b"[{\"width\": 64}, 540]".to_vec(), 400, "malformed_json", None),
        ("POST", "/v1/sessions", json, b"null".to_vec(), 400, "malformed_json", None),
        ("POST", "/v1/sessions", json, b"\"{}\"".to_vec(), 400, "malformed_json", None),
        ("POST", "/v1/render", json, b"[]".to_vec(), 400, "malformed_json", None),
        ("POST", "/v1/render", json, b"[960, 540]".to_vec(), 400, "malformed_json", None),
        ("POST", "/v1/scenes", json, b"[\"cornell\"]".to_vec(), 400, "malformed_json", None),
        ("PATCH", &session, json, b"7".to_vec(), 400, "malformed_json", None),
        // Repeated keys and numbers sent as strings name the full path.
        ("POST", "/v1/sessions", json, br#"{"render":{"width":64,"width":32}}"#.to_vec(), 400, "invalid_field", Some("render.width")),
        ("POST", "/v1/sessions", json, br#"{"fps_cap":30,"fps_cap":31}"#.to_vec(), 400, "invalid_field", Some("fps_cap")),
        ("PATCH", &session, json, br#"{"render":{"gi":{"rsm_size":32,"rsm_size":64}}}"#.to_vec(), 400, "invalid_field", Some("render.gi.rsm_size")),
        ("POST", "/v1/render", json, br#"{"render":{"camera":{"position":[0,0,1],"position":[0,0,2],"target":[0,0,0],"fov_y_degrees":45}}}"#.to_vec(), 400, "invalid_field", Some("render.camera.position")),
        ("POST", "/v1/sessions", json, br#"{"render":{"width":"NaN"}}"#.to_vec(), 400, "invalid_field", Some("render.width")),
        ("POST", "/v1/sessions", json, br#"{"render":{"camera":{"position":"NaN","target":[0,0,0],"fov_y_degrees":45}}}"#.to_vec(), 400, "invalid_field", Some("render.camera.position")),
        ("POST", "/v1/sessions", json, br#"{"render":{"camera":{"position":[0,"NaN",1],"target":[0,0,0],"fov_y_degrees":45}}}"#.to_vec(), 400, "invalid_field", Some("render.camera.position[1]")),
        ("POST", "/v1/render", json, br#"{"render":{"exposure":"NaN"}}"#.to_vec(), 400, "invalid_field", Some("render.exposure")),
        // What the HTTP layer refuses is a JSON error too.
        ("GET", "/v1/scenes/%FF%FE", "", Vec::new(), 400, "bad_request", None),
        ("GET", "/v1/no-such-path", "", Vec::new(), 404, "not_found", None),
        ("DELETE", "/v1/render", "", Vec::new(), 405, "method_not_allowed", None),
        ("GET", &long_uri, "", Vec::new(), 414, "uri_too_long", None),
    ];
    for (method, path, content_type, body, status, kind, field) in cases {
        let shown = format!(
            "{method} {:.60} {:.80}",
            path,
            String::from_utf8_lossy(&body)
        );
        let (got, error) = send(&server, method, path, content_type, body).await;
        assert_error(got, &error, status, kind, &shown);
        assert_eq!(error["field"].as_str(), field, "{shown}: {error}");
    }

    // An error answered before the body is read (here from the query) closes the connection
    // and says so, or the client sends its next request on a connection about to close and
    // loses it (a flaky CI failure, `IncompleteMessage`).
    let resp = server
        .http
        .post(server.url(&long_name))
        .header("content-type", "model/gltf-binary")
        .body(cornell_glb())
        .send()
        .await
        .expect("request");
    assert_eq!(resp.status(), 400);
    assert_eq!(
        resp.headers().get("connection").map(|v| v.as_bytes()),
        Some(&b"close"[..]),
        "{:?}",
        resp.headers()
    );

    // A client that sends its whole body before reading gets the answer to it. The server
    // answers a body over its limit having read at most the limit; closing on the unread rest
    // made the kernel reset the connection and drop the answer unread (a flaky CI failure).
    let mut stream = connect_from(loopback(3), server_addr(&server)).await;
    let length = 4 << 20;
    let head = format!(
        "POST /v1/render HTTP/1.1\r\nHost: test\r\nContent-Type: application/json\r\n\
         Content-Length: {length}\r\n\r\n"
    );
    let first = 64 << 10;
    stream.write_all(head.as_bytes()).await.expect("the head");
    stream
        .write_all(&vec![b' '; first])
        .await
        .expect("the body's start");
    // Time for the server to answer and close before the rest comes.
    tokio::time::sleep(Duration::from_millis(300)).await;
    stream
        .write_all(&vec![b' '; length - first])
        .await
        .expect("the rest of the body is taken, not reset");
    let mut answer = Vec::new();
    tokio::time::timeout(PATIENCE, stream.read_to_end(&mut answer))
        .await
        .expect("the server closes in time")
        .expect("the answer is read, not reset");
    let (status, error) = parse_answer(&answer);
    assert_error(status, &error, 413, "too_large", "a 4 MiB body sent whole");

    // A long id a client sends is not echoed back whole.
    for path in ["/v1/render", "/v1/sessions"] {
        let body = json!({"render": {"scene": long}}).to_string();
        let (status, error) = send(&server, "POST", path, json, body).await;
        assert_error(status, &error, 400, "invalid_field", path);
        assert_eq!(error["field"], "render.scene");
        let message = error["message"].as_str().unwrap_or_default();
        assert!(message.len() < 300, "{path} echoes {} bytes", message.len());
    }

    // Request heads over --max-header-bytes or with too many headers: 431 with the JSON body.
    let mut big_head = server.http.get(server.url("/healthz"));
    for i in 0..30 {
        big_head = big_head.header(format!("x-pad-{i}"), "v".repeat(200));
    }
    let mut many = server.http.get(server.url("/healthz"));
    for i in 0..120 {
        many = many.header(format!("x-{i}"), "1");
    }
    for (what, request) in [("6 KB of headers", big_head), ("120 headers", many)] {
        let resp = request.send().await.expect("request");
        let status = resp.status().as_u16();
        let body: Value = resp.json().await.expect("a JSON body");
        assert_error(status, &body, 431, "headers_too_large", what);
    }

    // Control messages with fields they do not have are refused, also those without any.
    let mut stream = server.connect(&created).await;
    for (message, kind, field) in [
        (
            r#"{"type": "pause", "session": "se_0000000000000000"}"#,
            "invalid_field",
            Some("session"),
        ),
        (
            r#"{"type": "still", "extra": 1}"#,
            "invalid_field",
            Some("extra"),
        ),
        (
            r#"{"type": "resume", "session": "se_0000000000000000"}"#,
            "invalid_field",
            Some("session"),
        ),
        (r#"[{"type": "pause"}]"#, "malformed_json", None),
        (
            r#"{"type": "ping", "nonce": 1, "nonce": 2}"#,
            "invalid_field",
            Some("nonce"),
        ),
    ] {
        stream.send_raw(Message::Text(message.into())).await;
        let error = stream.next_error().await;
        assert_eq!(error.error, kind, "{message}: {error:?}");
        assert_eq!(error.field.as_deref(), field, "{message}: {error:?}");
    }
    // The session was not paused by the refused `pause`: frames keep coming.
    let mut seen = Vec::new();
    let frame = stream.next_frame(&mut seen).await;
    assert_eq!(frame.header.width, 32);
    server.stop().await;
}
