//! The browser viewer in a real headless Chromium: `client/web/tests/viewer.test.mjs` (driven
//! by playwright-core, installed with Debian's `chromium` by `deploy/setup-debian.sh`) against a
//! server started here, and a second server with auth on for the token prompt. Its screenshot and the still it downloads are kept under
//! `target/tmp/viewer/`.

use lightcast_e2e::TestServer;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The whole browser session, all steps included: a normal run takes about 30 s on lavapipe,
/// so this only ends a hang (each step also has its own wait limit).
const BROWSER_TEST_LIMIT: Duration = Duration::from_secs(600);

fn chromium() -> PathBuf {
    std::env::var_os("LIGHTCAST_CHROMIUM")
        .map_or_else(|| PathBuf::from("/usr/bin/chromium"), PathBuf::from)
}

/// Every registered method's small setting on the built-in scene and its stage names: the
/// script opens a page per method `/v1/server` lists with these.
fn method_settings() -> serde_json::Value {
    use lightcast_server::gi::{self, precompute::SceneFacts};
    let facts = SceneFacts::of(&lightcast_server::scene::procedural::cornell_box());
    gi::methods()
        .map(|method| {
            let stages: Vec<&str> = gi::entry(method)
                .1
                .stages
                .iter()
                .map(|s| s.name())
                .collect();
            let gi = (gi::table(method).testing.small)(&facts);
            (
                method.name().to_string(),
                serde_json::json!({"gi": gi, "stages": stages}),
            )
        })
        .collect::<serde_json::Map<_, _>>()
        .into()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_viewer_streams_follows_input_and_recovers_in_chromium() {
    let web = Path::new(env!("CARGO_MANIFEST_DIR")).join("../client/web");
    let browser = chromium();
    assert!(
        browser.exists(),
        "Chromium not found at {}: run deploy/setup-debian.sh (or set LIGHTCAST_CHROMIUM)",
        browser.display()
    );
    assert!(
        web.join("node_modules/playwright-core/package.json")
            .exists(),
        "playwright-core is not installed in client/web: run deploy/setup-debian.sh \
         (it runs `npm ci` there)"
    );
    let upload = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/cornell-box/cornell-box.glb");
    assert!(upload.exists(), "{} is missing", upload.display());
    let artifacts = Path::new(env!("CARGO_TARGET_TMPDIR")).join("viewer");
    std::fs::create_dir_all(&artifacts).expect("artifacts folder");
    // A glTF animation for the page's play/pause control (issue 35).
    let animated = artifacts.join("slide.glb");
    std::fs::write(&animated, lightcast_e2e::animated_glb()).expect("animated scene written");
    let methods = method_settings();
    let server = TestServer::start(&[]).await;
    let token = "viewer-test-token-0123456789";
    let auth_server = TestServer::start(&["--token", token]).await;
    let run = tokio::process::Command::new("node")
        .arg("tests/viewer.test.mjs")
        .current_dir(&web)
        .env("LIGHTCAST_URL", &server.base)
        .env("LIGHTCAST_ARTIFACTS", &artifacts)
        .env("CHROMIUM", &browser)
        .env("LIGHTCAST_UPLOAD_SCENE", &upload)
        .env("LIGHTCAST_ANIMATED_SCENE", &animated)
        .env("LIGHTCAST_METHODS", methods.to_string())
        .env("LIGHTCAST_AUTH_URL", &auth_server.base)
        .env("LIGHTCAST_AUTH_TOKEN", token)
        .kill_on_drop(true)
        .status();
    // The script's step log goes straight to the terminal, so it survives a timeout too.
    let status = tokio::time::timeout(BROWSER_TEST_LIMIT, run)
        .await
        .expect("the browser test finishes within its limit")
        .expect("node runs (install Node.js: deploy/setup-debian.sh)");
    assert!(
        status.success(),
        "the viewer test failed ({status}); screenshots in {}",
        artifacts.display()
    );
    assert!(
        artifacts.join("viewer.png").exists(),
        "the screenshot artifact is missing"
    );
    server.stop().await;
    auth_server.stop().await;
}
