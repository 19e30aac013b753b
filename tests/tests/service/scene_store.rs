//! Uploaded scenes on every replica (issue 14, part 3): two replicas sharing a scene store
//! (`--scene-store`). A scene uploaded to one is listed, shown, rendered and streamed by the
//! other, which loads it from the store on first use; only the uploading token may delete it,
//! from either replica, and then both forget it. The store keeps no token.

use lightcast_e2e::{cornell_glb, TestServer};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

const ALICE: &str = "alice-token-0123456789abcdef";
const BOB: &str = "bob-token-0123456789abcdef";

fn files_under(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .expect("read_dir")
        .filter_map(Result::ok)
        .flat_map(|e| {
            let p = e.path();
            if p.is_dir() {
                files_under(&p)
            } else {
                vec![p]
            }
        })
        .collect()
}

async fn get(server: &TestServer, path: &str, token: &str) -> reqwest::Response {
    server
        .http
        .get(server.url(path))
        .bearer_auth(token)
        .send()
        .await
        .expect("request")
}

async fn delete(server: &TestServer, path: &str, token: &str) -> u16 {
    server
        .http
        .delete(server.url(path))
        .bearer_auth(token)
        .send()
        .await
        .expect("request")
        .status()
        .as_u16()
}

/// Deletes a scene as a client would: a session that was just deleted holds the scene until
/// its socket and last frame are done (409 meanwhile), so a 409 is retried for a while.
async fn delete_once_unused(server: &TestServer, path: &str, token: &str) -> u16 {
    let give_up = std::time::Instant::now() + std::time::Duration::from_secs(10);
    loop {
        let status = delete(server, path, token).await;
        if status != 409 || std::time::Instant::now() > give_up {
            return status;
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
}

async fn scene_ids(server: &TestServer) -> Vec<String> {
    let list: Vec<Value> = get(server, "/v1/scenes", BOB)
        .await
        .json()
        .await
        .expect("scene list");
    list.iter()
        .filter_map(|s| s["id"].as_str().map(str::to_string))
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scene_uploaded_to_one_replica_is_used_and_deleted_on_another() {
    let dir = tempfile::tempdir().expect("temp dir");
    let store = dir.path().join("scenes");
    let store_arg = store.to_string_lossy().into_owned();
    let tokens = format!("{ALICE},{BOB}");
    let args = [
        "--token",
        tokens.as_str(),
        "--scene-store",
        store_arg.as_str(),
    ];
    let (a, b) = (
        TestServer::start(&args).await,
        TestServer::start(&args).await,
    );

    let uploaded = a
        .http
        .post(a.url("/v1/scenes?name=box"))
        .bearer_auth(ALICE)
        .header("content-type", "model/gltf-binary")
        .body(cornell_glb())
        .send()
        .await
        .expect("upload");
    assert_eq!(uploaded.status(), 201);
    let info: Value = uploaded.json().await.expect("SceneInfo");
    let id = info["id"].as_str().expect("id").to_string();
    for file in files_under(&store) {
        let bytes = std::fs::read(&file).expect("read");
        assert!(
            !String::from_utf8_lossy(&bytes).contains(ALICE),
            "{} holds the token",
            file.display()
        );
    }

    // The other replica lists it before loading it, then shows and renders it.
    assert!(
        scene_ids(&b).await.contains(&id),
        "B lists the stored scene"
    );
    let shown = get(&b, &format!("/v1/scenes/{id}"), BOB).await;
    assert_eq!(shown.status(), 200);
    let shown: Value = shown.json().await.expect("SceneInfo");
    assert_eq!(
        (&shown["name"], &shown["triangles"]),
        (&info["name"], &info["triangles"])
    );
    let render = b
        .http
        .post(b.url("/v1/render"))
        .bearer_auth(BOB)
        .json(&json!({"render": {"scene": id, "width": 32, "height": 24,
                                  "gi": {"method": "none"}}}))
        .send()
        .await
        .expect("render");
    assert_eq!(
        render.status(),
        200,
        "{}",
        render.text().await.unwrap_or_default()
    );

    // A session on the other replica streams it.
    let created = b
        .create_session(
            json!({"render": {"scene": id, "width": 48, "height": 32, "gi": {"method": "none"}}}),
            Some(BOB),
        )
        .await;
    let mut stream = b.connect(&created).await;
    let mut seen = Vec::new();
    let frame = stream.next_frame(&mut seen).await;
    assert!(frame.header.width == 48 && frame.header.height == 32);
    drop(stream);
    assert_eq!(
        delete(&b, &format!("/v1/sessions/{}", created.session.id), BOB).await,
        204
    );

    // Only the uploading token deletes it, from the replica that did not upload it; then the
    // uploader forgets it too.
    assert_eq!(delete(&b, &format!("/v1/scenes/{id}"), BOB).await, 403);
    assert_eq!(
        delete_once_unused(&b, &format!("/v1/scenes/{id}"), ALICE).await,
        204
    );
    assert_eq!(
        get(&a, &format!("/v1/scenes/{id}"), ALICE).await.status(),
        404
    );
    assert!(!scene_ids(&a).await.contains(&id), "A forgot the scene");
    assert!(!scene_ids(&b).await.contains(&id), "B forgot the scene");
    assert!(files_under(&store).is_empty(), "the store is empty again");

    // A procedural scene added on one replica is rebuilt from its recipe on the other.
    let added = b
        .http
        .post(b.url("/v1/scenes"))
        .bearer_auth(BOB)
        .json(&json!({"procedural": "street?blocks=2", "name": "street"}))
        .send()
        .await
        .expect("add");
    assert_eq!(added.status(), 201);
    let street: Value = added.json().await.expect("SceneInfo");
    let street_id = street["id"].as_str().expect("id");
    let on_a: Value = get(&a, &format!("/v1/scenes/{street_id}"), BOB)
        .await
        .json()
        .await
        .expect("SceneInfo");
    assert_eq!(on_a["triangles"], street["triangles"]);
    assert_eq!(on_a["name"], "street");
    a.stop().await;
    b.stop().await;
}
