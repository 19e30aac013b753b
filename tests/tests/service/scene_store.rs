//! Uploaded scenes on every replica (issue 14, part 3): two replicas sharing a scene store
//! (`--scene-store`). A scene uploaded to one is listed, shown, rendered and streamed by the
//! other, which loads it from the store on first use; only the uploading token may delete it,
//! from either replica, and then both forget it. The store keeps no token.
//!
//! Issue 30, part 1: nothing a client sends becomes a path in the store. Display names and
//! uploaded file names are data; stored files are named by their hash, and a record naming
//! anything else is never followed.

use lightcast_e2e::{cornell_glb, triangle_glb, TestServer};
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
    // Generous: a loaded machine finishes the last frame late.
    let give_up = std::time::Instant::now() + std::time::Duration::from_secs(120);
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

/// `value` percent-encoded for a query string.
fn query_escape(value: &str) -> String {
    value
        .bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'~' => (b as char).to_string(),
            _ => format!("%{b:02X}"),
        })
        .collect()
}

async fn upload_named(server: &TestServer, name: &str, token: &str, glb: Vec<u8>) -> (u16, Value) {
    let response = server
        .http
        .post(server.url(&format!("/v1/scenes?name={}", query_escape(name))))
        .bearer_auth(token)
        .header("content-type", "model/gltf-binary")
        .body(glb)
        .send()
        .await
        .expect("upload");
    let status = response.status().as_u16();
    (status, response.json().await.unwrap_or(Value::Null))
}

async fn upload_multipart(server: &TestServer, file_name: &str, token: &str) -> (u16, Value) {
    let part = reqwest::multipart::Part::bytes(cornell_glb()).file_name(file_name.to_string());
    let response = server
        .http
        .post(server.url("/v1/scenes"))
        .bearer_auth(token)
        .multipart(reqwest::multipart::Form::new().part("scene", part))
        .send()
        .await
        .expect("upload");
    let status = response.status().as_u16();
    (status, response.json().await.unwrap_or(Value::Null))
}

/// Every file under `dir` with its bytes.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut files: Vec<_> = files_under(dir)
        .into_iter()
        .map(|p| {
            let bytes = std::fs::read(&p).expect("read");
            (p, bytes)
        })
        .collect();
    files.sort();
    files
}

fn staging_left(store: &Path) -> Vec<String> {
    std::fs::read_dir(store)
        .expect("read_dir")
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn names_a_client_sends_never_become_paths_in_the_store() {
    let dir = tempfile::tempdir().expect("temp dir");
    let store = dir.path().join("store");
    // The places the exact repros of issue 30 wrote to.
    let escape = dir.path().join("escape");
    let absolute = dir.path().join("absolute");
    for d in [&escape, &absolute] {
        std::fs::create_dir_all(d).expect("mkdir");
    }
    let store_arg = store.to_string_lossy().into_owned();
    let tokens = format!("{ALICE},{BOB}");
    let args = [
        "--token",
        tokens.as_str(),
        "--scene-store",
        store_arg.as_str(),
        "--max-scenes",
        "24",
        "--token-max-scenes",
        "10",
    ];
    let (a, b) = (
        TestServer::start(&args).await,
        TestServer::start(&args).await,
    );
    let mut added = Vec::new();

    // Relative and absolute paths as display names: kept as the name, written nowhere.
    let absolute_name = absolute.join("x.glb").to_string_lossy().into_owned();
    for name in [
        "../../escape/x.glb",
        absolute_name.as_str(),
        "a/b",
        ".",
        "..",
        "scene.json",
    ] {
        let (status, info) = upload_named(&a, name, ALICE, triangle_glb()).await;
        assert_eq!(status, 201, "name {name:?}: {info}");
        assert_eq!(info["name"], name);
        added.push(info["id"].as_str().expect("id").to_string());
    }
    assert!(
        files_under(&escape).is_empty(),
        "{:?}",
        files_under(&escape)
    );
    assert!(
        files_under(&absolute).is_empty(),
        "{:?}",
        files_under(&absolute)
    );
    assert!(
        staging_left(&store).is_empty(),
        "{:?}",
        staging_left(&store)
    );
    // `scene.json` as a name breaks nothing on the other replica.
    let json_named = &added[5];
    let shown = get(&b, &format!("/v1/scenes/{json_named}"), BOB).await;
    assert_eq!(shown.status(), 200);
    let shown: Value = shown.json().await.expect("SceneInfo");
    assert_eq!(shown["name"], "scene.json");
    assert_eq!(shown["triangles"], 1);

    // Names that cannot be kept as data are refused naming `name`, leaving nothing behind.
    for name in ["a\0b", "line\nbreak", ""] {
        let (status, body) = upload_named(&a, name, ALICE, triangle_glb()).await;
        assert_eq!(status, 400, "name {name:?}: {body}");
        assert_eq!(body["field"], "name", "{body}");
    }
    // A multipart upload's scene file name is checked like the files it references.
    let hostile_file = absolute.join("y.glb").to_string_lossy().into_owned();
    for file_name in [
        "../x.glb",
        "../../escape/y.glb",
        hostile_file.as_str(),
        ".glb",
    ] {
        let (status, body) = upload_multipart(&a, file_name, ALICE).await;
        assert_eq!(status, 400, "file name {file_name:?}: {body}");
        assert_eq!(body["field"], "files", "{body}");
    }
    assert!(
        staging_left(&store).is_empty(),
        "{:?}",
        staging_left(&store)
    );
    assert!(files_under(&escape).is_empty() && files_under(&absolute).is_empty());

    // Another token cannot overwrite a stored scene by naming its entry.
    let (status, victim) = upload_named(&a, "victim", ALICE, cornell_glb()).await;
    assert_eq!(status, 201);
    let victim_id = victim["id"].as_str().expect("id").to_string();
    let before = snapshot(&store.join(&victim_id));
    let (status, attacker) = upload_named(
        &a,
        &format!("../{victim_id}/victim.glb"),
        BOB,
        triangle_glb(),
    )
    .await;
    assert_eq!(status, 201, "{attacker}");
    assert_eq!(attacker["triangles"], 1);
    assert_eq!(snapshot(&store.join(&victim_id)), before);
    let on_b: Value = get(&b, &format!("/v1/scenes/{victim_id}"), BOB)
        .await
        .json()
        .await
        .expect("SceneInfo");
    assert_eq!(on_b["triangles"], victim["triangles"]);
    added.push(victim_id.clone());
    let attacker_id = attacker["id"].as_str().expect("id").to_string();

    // A record naming a file outside its entry is never followed: the other replica refuses
    // it and does not list it.
    let outside = dir.path().join("outside.glb");
    std::fs::write(&outside, triangle_glb()).expect("write");
    let mut record: Value = serde_json::from_slice(
        &std::fs::read(store.join(&attacker_id).join("scene.json")).expect("record"),
    )
    .expect("record JSON");
    let forged_id = "sc_forged";
    record["id"] = json!(forged_id);
    record["info"]["id"] = json!(forged_id);
    for named in [
        outside.to_string_lossy().into_owned(),
        "../outside.glb".into(),
    ] {
        record["recipe"]["upload"]["files"][0]["sha256"] = json!(named);
        std::fs::create_dir_all(store.join(forged_id)).expect("mkdir");
        std::fs::write(
            store.join(forged_id).join("scene.json"),
            serde_json::to_vec(&record).expect("JSON"),
        )
        .expect("write");
        let shown = get(&b, &format!("/v1/scenes/{forged_id}"), BOB).await;
        assert_eq!(shown.status(), 500, "{named}");
        let body: Value = shown.json().await.expect("error body");
        assert!(
            body["message"]
                .as_str()
                .is_some_and(|m| m.contains("not a record this server writes")),
            "{body}"
        );
        assert!(!scene_ids(&b).await.contains(&forged_id.to_string()));
    }
    std::fs::remove_dir_all(store.join(forged_id)).expect("remove the forged record");

    // Deleting every scene empties the store; nothing was ever written outside it.
    for id in added {
        assert_eq!(
            delete_once_unused(&a, &format!("/v1/scenes/{id}"), ALICE).await,
            204
        );
    }
    assert_eq!(
        delete_once_unused(&b, &format!("/v1/scenes/{attacker_id}"), BOB).await,
        204
    );
    assert!(files_under(&store).is_empty(), "{:?}", files_under(&store));
    assert!(files_under(&escape).is_empty() && files_under(&absolute).is_empty());
    assert_eq!(std::fs::read_dir(dir.path()).expect("read_dir").count(), 4);
    a.stop().await;
    b.stop().await;
}
