//! `deploy/setup-debian.sh`, the first half of both README commands: it checks the versions
//! the build and the tests need and says how to fix them. Run with fake `cargo` and `node` in
//! front of PATH (everything else real), on a machine the script has already set up, so it
//! installs nothing here.

use crate::support::not_exercised;
use std::path::{Path, PathBuf};
use std::process::Command;

const ROOT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/..");

/// An executable shell script `name` in `dir`.
fn fake(dir: &Path, name: &str, script: &str) {
    let path = dir.join(name);
    std::fs::write(&path, format!("#!/bin/sh\n{script}\n")).expect("write fake");
    let mut perms = std::fs::metadata(&path).expect("stat").permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o755);
    std::fs::set_permissions(&path, perms).expect("chmod");
}

fn run_setup(fakes: &Path, args: &[&str]) -> (bool, String) {
    let path = format!(
        "{}:{}",
        fakes.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = Command::new("bash")
        .arg(Path::new(ROOT).join("deploy/setup-debian.sh"))
        .args(args)
        .env("PATH", path)
        .output()
        .expect("run bash");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn workspace_rust_version() -> String {
    let toml = std::fs::read_to_string(Path::new(ROOT).join("Cargo.toml")).expect("Cargo.toml");
    toml.lines()
        .find_map(|l| l.strip_prefix("rust-version = \""))
        .and_then(|v| v.strip_suffix('"'))
        .expect("the workspace declares rust-version")
        .to_string()
}

fn fakes_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("lightcast-setup-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// The script has nothing to install here only where an earlier run set the machine up (CI
/// runs it first); elsewhere these checks would need root, so they are not exercised.
fn set_up_already() -> bool {
    let dir = fakes_dir("probe");
    let (ok, stderr) = run_setup(&dir, &[]);
    std::fs::remove_dir_all(&dir).ok();
    if !ok || stderr.contains("installing") {
        not_exercised("deploy/setup-debian.sh has work to do on this machine");
        return false;
    }
    true
}

#[test]
fn refuses_a_rust_older_than_the_workspace_needs_and_names_both_versions() {
    if !set_up_already() {
        return;
    }
    let dir = fakes_dir("old-cargo");
    fake(&dir, "cargo", "echo 'cargo 1.70.0 (ec8a8a0ca 2023-04-25)'");
    let (ok, stderr) = run_setup(&dir, &[]);
    let needed = workspace_rust_version();
    assert!(!ok, "an old cargo must fail the set-up: {stderr}");
    assert!(
        stderr.contains("cargo 1.70.0 is older than the workspace's rust-version")
            && stderr.contains(&needed)
            && stderr.contains("rustup update"),
        "{stderr}"
    );
    fake(
        &dir,
        "cargo",
        &format!("echo 'cargo {needed}.0 (0000000 2026-01-01)'"),
    );
    let (ok, stderr) = run_setup(&dir, &[]);
    assert!(ok, "cargo at exactly rust-version passes: {stderr}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn refuses_a_node_older_than_playwright_core_needs() {
    if !set_up_already() {
        return;
    }
    let dir = fakes_dir("old-node");
    // The real node still answers the script's question about playwright-core's engines: the
    // fake only answers `--version`.
    let real_node = String::from_utf8(
        Command::new("bash")
            .args(["-c", "command -v node"])
            .output()
            .expect("bash")
            .stdout,
    )
    .expect("utf-8");
    let script = format!(
        "if [ \"$1\" = --version ]; then echo v16.20.0; else exec {} \"$@\"; fi",
        real_node.trim()
    );
    fake(&dir, "node", &script);
    let (ok, stderr) = run_setup(&dir, &["--tests"]);
    assert!(!ok, "Node.js 16 must fail the test set-up: {stderr}");
    assert!(
        stderr.contains("Node.js 16.20.0 is older than the 20"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The README names the same minimum Rust as Cargo.toml (the script reads Cargo.toml's).
#[test]
fn the_readme_names_the_workspace_rust_version() {
    let readme = std::fs::read_to_string(Path::new(ROOT).join("README.md")).expect("README");
    let needed = workspace_rust_version();
    assert!(
        readme.contains(&format!("Rust {needed} or newer")),
        "README.md must say `Rust {needed} or newer`"
    );
}
