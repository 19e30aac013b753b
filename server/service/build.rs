//! Records the git revision for the build id the service reports (`/v1/server`, render
//! reports), so results name exactly what produced them.

use std::path::{Path, PathBuf};
use std::process::Command;

fn main() {
    // Read when the script runs, not baked in when it is compiled: a build script binary is
    // reused by checkouts that share a target directory.
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("set by Cargo"));
    record_git_revision(&manifest.join("../.."));
}

fn record_git_revision(root: &Path) {
    for watched in [".git/HEAD", ".git/index"] {
        let path = root.join(watched);
        if path.exists() {
            println!("cargo:rerun-if-changed={}", path.display());
        }
    }
    let rev = Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .current_dir(root)
        .output()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string());
    let dirty = Command::new("git")
        .args(["status", "--porcelain", "--untracked-files=no"])
        .current_dir(root)
        .output()
        .ok()
        .filter(|o| o.status.success())
        .is_some_and(|o| !o.stdout.is_empty());
    if let Some(rev) = rev {
        let suffix = if dirty { "+modified" } else { "" };
        println!("cargo:rustc-env=LIGHTCAST_GIT_REV={rev}{suffix}");
    }
}
