#!/usr/bin/env bash
# Installs what lightcast needs on a Debian or Ubuntu machine, then returns. Idempotent.
#
#   deploy/setup-debian.sh           what the server needs
#   deploy/setup-debian.sh --tests   also what the tests need
#
# - libvulkan1: the Vulkan loader wgpu opens.
# - mesa-vulkan-drivers (lavapipe, a CPU Vulkan driver) only when no Vulkan driver is installed,
#   so machines without a GPU can still render (slowly) and run the tests.
# - fonts-dejavu-core: the font of the benchmark's PNG plots.
# - gcc and g++ where missing: cargo links with cc, and the FLIP metric and OpenH264 (the
#   `h264` stream encoder, built from the source its crate bundles) build C++.
# - nasm: OpenH264's assembly (several times faster encoding); without it the C code is used.
# - with --tests: chromium, and nodejs + npm where Node.js is missing, for the browser viewer's
#   test (Debian's Chromium driven by playwright-core, which never downloads a browser), then
#   `npm ci` in client/web for playwright-core at the version its package-lock.json pins.
#   Also python3-venv where `python3 -m venv` cannot work, for deploy/ci/check.sh's tools and
#   schemathesis (tests/requirements.txt, into target/test-tools/venv, for the OpenAPI test), and
#   nginx for the test of three replicas behind a proxy (the chart's router's rule) and of the
#   client over TLS, and openssl for that test's private CA.
# Checked, not installed: Rust (cargo at least the workspace's `rust-version` in Cargo.toml, from
# https://rustup.rs) and, with --tests, Node.js at least what the pinned playwright-core needs.
# Packages are installed as root, or through sudo for other users.
set -euo pipefail

tests=false
case "${1:-}" in
  "") ;;
  --tests) tests=true ;;
  *) echo "usage: $0 [--tests]" >&2; exit 2 ;;
esac

root="$(cd "$(dirname "$0")/.." && pwd)"
web="$root/client/web"

# True when version $1 ≥ version $2 (dotted numbers).
version_at_least() {
  [ "$(printf '%s\n%s\n' "$2" "$1" | sort -V | head -n1)" = "$2" ]
}

packages=()
dpkg -s libvulkan1 >/dev/null 2>&1 || packages+=(libvulkan1)
icds=$(ls /usr/share/vulkan/icd.d/*.json /etc/vulkan/icd.d/*.json 2>/dev/null | wc -l || true)
if [ "$icds" -eq 0 ] && ! dpkg -s mesa-vulkan-drivers >/dev/null 2>&1; then
  packages+=(mesa-vulkan-drivers)
fi

[ -f /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ] || packages+=(fonts-dejavu-core)
command -v cc >/dev/null 2>&1 || packages+=(gcc libc6-dev)
command -v c++ >/dev/null 2>&1 || packages+=(g++)
command -v nasm >/dev/null 2>&1 || packages+=(nasm)

if $tests; then
  command -v chromium >/dev/null 2>&1 || packages+=(chromium)
  # The three-replica routing test runs a real proxy.
  [ -x /usr/sbin/nginx ] || packages+=(nginx)
  command -v openssl >/dev/null 2>&1 || packages+=(openssl)
  command -v node >/dev/null 2>&1 || packages+=(nodejs)
  command -v npm >/dev/null 2>&1 || packages+=(npm)
  python3 -c 'import ensurepip, venv' >/dev/null 2>&1 || packages+=(python3-venv)
fi

if [ ${#packages[@]} -gt 0 ]; then
  if [ "$(id -u)" -eq 0 ]; then
    sudo=()
  elif command -v sudo >/dev/null 2>&1; then
    sudo=(sudo)
  else
    echo "setup: ${packages[*]} must be installed, which needs root: run this script as root or install sudo" >&2
    exit 1
  fi
  echo "setup: installing ${packages[*]}" >&2
  "${sudo[@]}" apt-get update -qq
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${packages[@]}" >/dev/null
fi

rust_version=$(sed -n 's/^rust-version = "\(.*\)"$/\1/p' "$root/Cargo.toml")
if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found; install Rust $rust_version or newer (https://rustup.rs) and run again" >&2
  exit 1
fi
cargo_version=$(cargo --version | awk '{print $2}')
if ! version_at_least "${cargo_version%%-*}" "$rust_version"; then
  echo "setup: cargo $cargo_version is older than the workspace's rust-version $rust_version; run \`rustup update\` (or install a newer Rust from https://rustup.rs) and run again" >&2
  exit 1
fi

if $tests; then
  # The lowest Node.js the pinned playwright-core declares (its engines field, ">=20").
  node_needs=$(node -e 'const p = require(process.argv[1]).packages["node_modules/playwright-core"];
    console.log(((p && p.engines && p.engines.node) || "").replace(/^>=\s*/, ""))' "$web/package-lock.json")
  node_version=$(node --version | sed 's/^v//')
  if [ -n "$node_needs" ] && ! version_at_least "$node_version" "$node_needs"; then
    echo "setup: Node.js $node_version is older than the $node_needs the viewer test's playwright-core needs; install a newer Node.js (https://nodejs.org, or Debian's backports) and run again" >&2
    exit 1
  fi
  # schemathesis for the OpenAPI property test, pinned in tests/requirements.txt.
  tools="$root/target/test-tools"
  if ! cmp -s "$root/tests/requirements.txt" "$tools/venv/.installed-requirements.txt" 2>/dev/null; then
    echo "setup: installing tests/requirements.txt (schemathesis) into $tools/venv" >&2
    rm -rf "$tools/venv"
    python3 -m venv "$tools/venv"
    "$tools/venv/bin/pip" install --quiet --disable-pip-version-check -r "$root/tests/requirements.txt"
    cp "$root/tests/requirements.txt" "$tools/venv/.installed-requirements.txt"
  fi
  stamp="$web/node_modules/.installed-package-lock.json"
  if ! cmp -s "$web/package-lock.json" "$stamp"; then
    echo "setup: npm ci in client/web (playwright-core for the viewer test)" >&2
    (cd "$web" && npm ci --no-audit --no-fund --loglevel=error)
    cp "$web/package-lock.json" "$stamp"
  fi
fi
