//! schemathesis (PyPI; `deploy/setup-debian.sh --tests` installs it from
//! `tests/requirements.txt`) against a live server: requests generated from the server's own
//! OpenAPI document, each answer checked for a server error and against the document (status
//! codes, content types, response schemas). The example count is bounded and the seed fixed,
//! and the server's limits are small, so that every render it asks for is cheap on lavapipe.

use lightcast_e2e::TestServer;
use std::path::Path;
use std::time::Duration;

/// The whole run; a normal one takes well under a minute on lavapipe.
const LIMIT: Duration = Duration::from_secs(900);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn requests_generated_from_the_openapi_document_get_documented_answers() {
    let st = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/test-tools/venv/bin/st");
    assert!(
        st.exists(),
        "schemathesis is not installed at {}: run deploy/setup-debian.sh --tests",
        st.display()
    );
    let server = TestServer::start(&[
        "--max-request-cost",
        "0.3",
        "--max-precompute-cost",
        "5",
        "--max-triangles",
        "100000",
        "--max-width",
        "256",
        "--max-height",
        "256",
    ])
    .await;
    let report = tempfile::tempdir().expect("temp dir");
    let run = tokio::process::Command::new(&st)
        .args([
            "run",
            &server.url("/openapi.json"),
            "--checks",
            "not_a_server_error,status_code_conformance,content_type_conformance,response_schema_conformance",
            "--phases",
            "coverage,fuzzing",
            "--max-examples",
            "20",
            "--seed",
            "1",
            "--workers",
            "1",
            "--request-timeout",
            "60",
            "--generation-database",
            "none",
            "--no-color",
        ])
        .current_dir(report.path())
        .kill_on_drop(true)
        .output();
    let output = tokio::time::timeout(LIMIT, run)
        .await
        .expect("schemathesis finishes within its limit")
        .expect("schemathesis runs");
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "schemathesis found failures ({}):\n{text}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(text.contains("passed"), "{text}");
    server.stop().await;
}
