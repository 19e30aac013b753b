//! Sessions across replicas (issue 14, part 3): two replicas sharing a routing key. A session's
//! id names the replica that holds it; the other replica answers 421 naming that owner for
//! every request about it (the WebSocket with a ticket included), a forged id is 404, and
//! every response names the replica that gave it.

use lightcast_e2e::{direct_session, Incoming, TestServer};
use lightcast_protocol::ServerEvent;
use serde_json::Value;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_session_is_found_on_its_replica_and_pointed_to_from_the_others() {
    let dir = tempfile::tempdir().expect("temp dir");
    let key = dir.path().join("routing.key");
    std::fs::write(&key, "0123456789abcdef0123456789abcdef\n").expect("key file");
    let key = key.to_string_lossy().into_owned();
    let start = |name: &'static str| {
        let key = key.clone();
        async move { TestServer::start(&["--replica", name, "--routing-key-file", &key]).await }
    };
    let (a, b) = (start("lightcast-0").await, start("lightcast-1").await);
    assert_eq!(a.get_json("/v1/server").await["replica"], "lightcast-0");
    let answered = a.get("/healthz").await;
    assert_eq!(answered.headers()["lightcast-replica"], "lightcast-0");

    let created = a.create_session(direct_session(64, 48), None).await;
    let id = created.session.id.clone();
    assert!(id.starts_with("lightcast-0.se_"), "{id}");
    assert_eq!(a.get(&format!("/v1/sessions/{id}")).await.status(), 200);

    // The other replica points at the owner for the session and for its ticket.
    let misdirected = b.get(&format!("/v1/sessions/{id}")).await;
    assert_eq!(misdirected.status(), 421);
    assert_eq!(misdirected.headers()["lightcast-owner"], "lightcast-0");
    assert_eq!(misdirected.headers()["lightcast-replica"], "lightcast-1");
    let body: Value = misdirected.json().await.expect("error JSON");
    assert_eq!(body["error"], "misdirected");
    assert!(
        body["message"]
            .as_str()
            .is_some_and(|m| m.contains("'lightcast-0'")),
        "{body}"
    );
    let stream = b
        .get(&format!(
            "{}?ticket={}",
            created.session.stream, created.ticket.ticket
        ))
        .await;
    assert_eq!(
        stream.status(),
        421,
        "a ticket presented to the wrong replica"
    );
    let ticket = b
        .http
        .post(b.url(&format!("/v1/sessions/{id}/ticket")))
        .send()
        .await
        .expect("request");
    assert_eq!(ticket.status(), 421);

    // A forged id (another owner under the same mac) is unknown everywhere.
    let forged = id.replacen("lightcast-0", "lightcast-1", 1);
    assert_eq!(b.get(&format!("/v1/sessions/{forged}")).await.status(), 404);
    assert_eq!(a.get(&format!("/v1/sessions/{forged}")).await.status(), 404);

    // The ticket was not spent by the misdirected attempt: the owner streams.
    let mut ws = a.connect(&created).await;
    match ws.next().await {
        Incoming::Event(ServerEvent::Hello { session, .. }) => assert_eq!(session.id, id),
        _ => panic!("the first message must be hello"),
    }
    a.stop().await;
    b.stop().await;
}

/// nginx in front of `replicas` with the chart's routing rule
/// (`deploy/helm/lightcast/files/routing.conf`): session paths to the replica their id names,
/// everything else round-robin over the replicas (a refused connection is retried on the next).
/// Stopped when dropped.
struct Proxy {
    child: std::process::Child,
    port: u16,
    _dir: tempfile::TempDir,
}

impl Proxy {
    fn start(replicas: &[(&str, u16)]) -> Self {
        let nginx = std::env::var("NGINX").unwrap_or_else(|_| "/usr/sbin/nginx".into());
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("a free port")
            .port();
        let rule = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../deploy/helm/lightcast/files/routing.conf"
        ))
        .expect("the chart's routing rule");
        let dir = tempfile::tempdir().expect("temp dir");
        let tmp = dir.path().display();
        let servers: String = replicas
            .iter()
            // As the chart's router, which resolves the pods per request and so keeps no
            // failure count: a full replica (429) is tried again by the next request.
            .map(|(_, p)| format!("server 127.0.0.1:{p} max_fails=0; "))
            .collect();
        let mut config = format!(
            "daemon off;\nworker_processes 1;\npid {tmp}/nginx.pid;\nerror_log {tmp}/error.log;\n\
             events {{ worker_connections 512; }}\nhttp {{\n\
             access_log off;\nclient_body_temp_path {tmp}/body;\nproxy_temp_path {tmp}/proxy;\n\
             fastcgi_temp_path {tmp}/fastcgi;\nuwsgi_temp_path {tmp}/uwsgi;\nscgi_temp_path {tmp}/scgi;\n\
             {rule}\nmap $http_upgrade $connection_upgrade {{ default upgrade; \"\" close; }}\n\
             upstream any {{ {servers}}}\n"
        );
        let mut names = String::new();
        for (name, p) in replicas {
            config += &format!("upstream {name} {{ server 127.0.0.1:{p}; }}\n");
            names += &format!("{name} {name}; ");
        }
        config += &format!(
            "map $lightcast_replica $lightcast_upstream {{ default any; {names}}}\n\
             server {{\n listen 127.0.0.1:{port};\n location / {{\n\
             proxy_pass http://$lightcast_upstream;\n proxy_http_version 1.1;\n\
             proxy_set_header Upgrade $http_upgrade;\n proxy_set_header Connection $connection_upgrade;\n\
             proxy_read_timeout 300s;\n }}\n}}\n}}\n"
        );
        let path = dir.path().join("nginx.conf");
        std::fs::write(&path, config).expect("nginx.conf");
        let child = std::process::Command::new(&nginx)
            .arg("-e")
            .arg(dir.path().join("error.log"))
            .arg("-c")
            .arg(&path)
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap_or_else(|e| {
                panic!("starting {nginx} ({e}): install it with deploy/setup-debian.sh --tests")
            });
        Self {
            child,
            port,
            _dir: dir,
        }
    }
}

impl Proxy {
    /// A client of the proxy, once it answers.
    async fn front(&self) -> TestServer {
        let front = TestServer::remote(format!("http://127.0.0.1:{}", self.port));
        tokio::time::timeout(lightcast_e2e::PATIENCE, async {
            while !matches!(front.http.get(front.url("/healthz")).send().await, Ok(r) if r.status() == 200) {
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            }
        })
        .await
        .expect("the proxy answers");
        front
    }
}

impl Drop for Proxy {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Frames of `stream` until `count` more have arrived; panics if it closes.
async fn frames(
    stream: &mut lightcast_e2e::Stream,
    count: usize,
) -> Vec<lightcast_e2e::ReceivedFrame> {
    let mut events = Vec::new();
    let mut out = Vec::new();
    while out.len() < count {
        out.push(stream.next_frame(&mut events).await);
    }
    out
}

/// Microseconds since the Unix epoch, the clock of a frame's `send_us` (the replicas run in
/// this process).
fn unix_us() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

/// Reads `stream` until `count` frames newer than `last_seq` and sent at or after `since_us`
/// have come, skipping frames that were on their way already; the newest one's `seq`.
async fn new_frames(
    stream: &mut lightcast_e2e::Stream,
    last_seq: u64,
    since_us: u64,
    count: usize,
) -> u64 {
    let mut events = Vec::new();
    let mut newest = last_seq;
    let mut new = 0;
    while new < count {
        let f = stream.next_frame(&mut events).await;
        if f.header.seq > last_seq && f.header.send_us >= since_us {
            new += 1;
            newest = f.header.seq;
        }
    }
    newest
}

/// Issue 14 part 4: three replicas behind a real nginx configured with the chart's routing rule.
/// Sessions created through it spread over the replicas, stream through it, follow camera
/// input and take tickets through it; when one replica stops, its client gets a clear close
/// and a new session lands on another replica while the others' streams go on. The sessions
/// use a scene uploaded through the proxy, which every replica loads from the shared store.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn three_replicas_behind_nginx_route_sessions_and_survive_one_stopping() {
    let dir = tempfile::tempdir().expect("temp dir");
    let key = dir.path().join("routing.key");
    std::fs::write(&key, "0123456789abcdef0123456789abcdef").expect("key file");
    let key = key.to_string_lossy().into_owned();
    let store = dir.path().join("scenes").to_string_lossy().into_owned();
    let names = ["lightcast-0", "lightcast-1", "lightcast-2"];
    let mut replicas = Vec::new();
    for name in names {
        replicas.push(
            TestServer::start(&[
                "--replica",
                name,
                "--routing-key-file",
                &key,
                "--scene-store",
                &store,
            ])
            .await,
        );
    }
    let ports: Vec<(&str, u16)> = names
        .iter()
        .copied()
        .zip(replicas.iter().map(TestServer::port))
        .collect();
    let proxy = Proxy::start(&ports);
    let front = proxy.front().await;

    // A scene uploaded through the proxy (to whichever replica it picks) serves sessions on
    // every replica: they share the scene store.
    let uploaded = front
        .http
        .post(front.url("/v1/scenes?name=box"))
        .header("content-type", "model/gltf-binary")
        .body(lightcast_e2e::cornell_glb())
        .send()
        .await
        .expect("upload");
    assert_eq!(uploaded.status(), 201);
    let scene: Value = uploaded.json().await.expect("SceneInfo");
    let mut on_uploaded = direct_session(32, 24);
    on_uploaded["render"]["scene"] = scene["id"].clone();

    // Three sessions through the proxy land on three replicas.
    let mut created = Vec::new();
    for _ in 0..3 {
        created.push(front.create_session(on_uploaded.clone(), None).await);
    }
    let owners: std::collections::BTreeSet<&str> = created
        .iter()
        .map(|c| c.session.id.split('.').next().expect("a replica part"))
        .collect();
    assert_eq!(
        owners.len(),
        3,
        "sessions spread over the replicas: {owners:?}"
    );

    // Each streams through the proxy with its ticket, and a session's requests reach its owner.
    let mut streams = Vec::new();
    for c in &created {
        let mut s = front.connect(c).await;
        frames(&mut s, 2).await;
        streams.push(s);
        let info = front.get(&format!("/v1/sessions/{}", c.session.id)).await;
        assert_eq!(info.status(), 200);
        let owner = c.session.id.split('.').next().expect("owner");
        assert_eq!(info.headers()["lightcast-replica"], owner);
    }
    let ticket = front
        .http
        .post(front.url(&format!("/v1/sessions/{}/ticket", created[1].session.id)))
        .send()
        .await
        .expect("request");
    assert_eq!(ticket.status(), 200, "a ticket through the proxy");

    // Camera input through the proxy shows in the frames.
    let before = frames(&mut streams[0], 1).await.remove(0);
    streams[0]
        .send(
            serde_json::json!({"type": "camera", "input_id": 9, "camera": {
            "position": [0.9, 1.0, 2.5], "target": [-1.0, 1.0, 0.0], "fov_y_degrees": 50.0}}),
        )
        .await;
    let mut events = Vec::new();
    let moved = loop {
        let f = streams[0].next_frame(&mut events).await;
        if f.header.input_id == 9 {
            break f;
        }
    };
    let diff = lightcast_e2e::mean_abs_diff(&before.rgba, &moved.rgba);
    assert!(
        diff > 5.0,
        "the camera moved the image by only {diff:.2} levels"
    );

    // Stop the replica holding the third session: its client is told and closed.
    let doomed = created[2]
        .session
        .id
        .split('.')
        .next()
        .expect("owner")
        .to_string();
    let index = names
        .iter()
        .position(|n| *n == doomed)
        .expect("a known replica");
    let mut last_seqs = Vec::new();
    for s in &mut streams[..2] {
        last_seqs.push(frames(s, 1).await[0].header.seq);
    }
    let stopping = tokio::spawn(replicas.remove(index).stop());
    let mut dying = streams.pop().expect("third stream");
    assert_eq!(
        dying.closing_reason().await.as_deref(),
        Some("server shutting down")
    );
    stopping.await.expect("stopped");

    // The other streams go on (frames sent after the stop, not ones queued before it), and a new
    // session lands on a replica still running.
    let stopped_us = unix_us();
    for (s, last) in streams.iter_mut().zip(&mut last_seqs) {
        *last = new_frames(s, *last, stopped_us, 3).await;
    }
    let again = front.create_session(direct_session(32, 24), None).await;
    let owner = again.session.id.split('.').next().expect("owner");
    assert_ne!(
        owner, doomed,
        "a new session does not land on the stopped replica"
    );
    let mut s = front.connect(&again).await;
    frames(&mut s, 1).await;
    let started_us = unix_us();
    for (s, last) in streams.iter_mut().zip(&last_seqs) {
        new_frames(s, *last, started_us, 2).await;
    }
    drop(proxy);
    for r in replicas {
        r.stop().await;
    }
}

/// A full replica answers 429 with `Retry-After`, and the proxy (the chart's routing rule) tries
/// another replica for a new session, so sessions fill every replica before any client is
/// refused; once all are full the client gets the 429 and its `Retry-After`.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_proxy_tries_another_replica_when_one_is_full() {
    let dir = tempfile::tempdir().expect("temp dir");
    let key = dir.path().join("routing.key");
    std::fs::write(&key, "0123456789abcdef0123456789abcdef").expect("key file");
    let key = key.to_string_lossy().into_owned();
    let names = ["lightcast-0", "lightcast-1", "lightcast-2"];
    let mut replicas = Vec::new();
    for name in names {
        replicas.push(
            TestServer::start(&[
                "--replica",
                name,
                "--routing-key-file",
                &key,
                "--max-sessions",
                "2",
            ])
            .await,
        );
    }
    // lightcast-0 is full before the proxy sends it anything.
    for _ in 0..2 {
        replicas[0]
            .create_session(direct_session(16, 16), None)
            .await;
    }
    let refused = replicas[0]
        .http
        .post(replicas[0].url("/v1/sessions"))
        .json(&direct_session(16, 16))
        .send()
        .await
        .expect("request");
    assert_eq!(refused.status(), 429);
    assert_eq!(refused.headers()["retry-after"], "2");

    let ports: Vec<(&str, u16)> = names
        .iter()
        .copied()
        .zip(replicas.iter().map(TestServer::port))
        .collect();
    let proxy = Proxy::start(&ports);
    let front = proxy.front().await;
    let mut owners = Vec::new();
    for _ in 0..4 {
        let created = front.create_session(direct_session(16, 16), None).await;
        owners.push(
            created
                .session
                .id
                .split('.')
                .next()
                .expect("owner")
                .to_string(),
        );
    }
    owners.sort();
    assert_eq!(
        owners,
        ["lightcast-1", "lightcast-1", "lightcast-2", "lightcast-2"],
        "the four sessions filled the replicas with room"
    );
    let full = front
        .http
        .post(front.url("/v1/sessions"))
        .json(&direct_session(16, 16))
        .send()
        .await
        .expect("request");
    assert_eq!(full.status(), 429, "every replica is full");
    assert_eq!(full.headers()["retry-after"], "2");
    drop(proxy);
    for r in replicas {
        r.stop().await;
    }
}
