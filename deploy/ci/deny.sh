#!/usr/bin/env bash
# Dependency hygiene in CI: cargo-deny's licence, ban and source checks of every crate in
# Cargo.lock against deploy/ci/deny.toml, offline. cargo-deny is built once from crates.io
# into target/deploy-ci/cargo-deny and reused while its pinned version is unchanged. Its own
# release profile (fat LTO, one codegen unit) took 5.4 minutes of a 2-core CI run; built
# without LTO at opt-level 1 it takes 2.7, and checking this workspace still takes 2 s.
# Advisories need the RustSec database from GitHub, which CI cannot reach; see deny.toml.
set -euo pipefail
cd "$(dirname "$0")/../.."

version=0.20.2
root=target/deploy-ci/cargo-deny
if [ "$("$root/bin/cargo-deny" --version 2>/dev/null)" != "cargo-deny $version" ]; then
  echo "deny: installing cargo-deny $version into $root" >&2
  CARGO_PROFILE_RELEASE_LTO=false CARGO_PROFILE_RELEASE_CODEGEN_UNITS=16 \
    CARGO_PROFILE_RELEASE_OPT_LEVEL=1 \
    cargo install --quiet --locked --version "$version" --root "$root" cargo-deny
fi
# cargo-deny reads the metadata of every crate in Cargo.lock, for every target (wasi, android
# …), offline: fetch them first, since a build downloads only the host's (a fresh cargo home
# lacked `wasip2` and failed here).
cargo fetch --locked --quiet
"$root/bin/cargo-deny" --offline --manifest-path Cargo.toml --all-features \
  --config deploy/ci/deny.toml check licenses bans sources
