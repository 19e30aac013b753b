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
        Incoming::Event(ServerEvent::Hello { session }) => assert_eq!(session.id, id),
        _ => panic!("the first message must be hello"),
    }
    a.stop().await;
    b.stop().await;
}
