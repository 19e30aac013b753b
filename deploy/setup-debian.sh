#!/usr/bin/env bash
# Installs what lightcast needs on a Debian machine, then returns. Idempotent.
#
#   deploy/setup-debian.sh           what the server needs
#   deploy/setup-debian.sh --tests   also what the tests need
#
# - libvulkan1: the Vulkan loader wgpu opens.
# - mesa-vulkan-drivers (lavapipe, a CPU Vulkan driver) only when no Vulkan driver is installed,
#   so machines without a GPU can still render (slowly) and run the tests.
# - fonts-dejavu-core: the font of the benchmark's PNG plots.
# - gcc and g++ where missing: cargo links with cc, and the FLIP metric builds C++.
# - with --tests: chromium, and nodejs + npm where Node.js is missing, for the browser viewer's
#   test (Debian's Chromium driven by playwright-core, which never downloads a browser), then
#   `npm ci` in client/web for playwright-core at the version its package-lock.json pins.
# - Rust itself is not installed here: cargo ≥ 1.87 must be on PATH (https://rustup.rs).
set -euo pipefail

tests=false
case "${1:-}" in
  "") ;;
  --tests) tests=true ;;
  *) echo "usage: $0 [--tests]" >&2; exit 2 ;;
esac

sudo=""
if [ "$(id -u)" -ne 0 ]; then
  sudo="sudo"
fi

packages=()
dpkg -s libvulkan1 >/dev/null 2>&1 || packages+=(libvulkan1)
icds=$(ls /usr/share/vulkan/icd.d/*.json /etc/vulkan/icd.d/*.json 2>/dev/null | wc -l || true)
if [ "$icds" -eq 0 ] && ! dpkg -s mesa-vulkan-drivers >/dev/null 2>&1; then
  packages+=(mesa-vulkan-drivers)
fi

[ -f /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ] || packages+=(fonts-dejavu-core)
# cargo links with cc, and nv-flip (the FLIP metric of comparisons) compiles C++.
command -v cc >/dev/null 2>&1 || packages+=(gcc libc6-dev)
command -v c++ >/dev/null 2>&1 || packages+=(g++)

if $tests; then
  command -v chromium >/dev/null 2>&1 || packages+=(chromium)
  command -v node >/dev/null 2>&1 || packages+=(nodejs)
  command -v npm >/dev/null 2>&1 || packages+=(npm)
fi

if [ ${#packages[@]} -gt 0 ]; then
  echo "setup: installing ${packages[*]}" >&2
  $sudo apt-get update -qq
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${packages[@]}" >/dev/null
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found; install Rust 1.87 or newer (https://rustup.rs) and run again" >&2
  exit 1
fi

if $tests; then
  web="$(cd "$(dirname "$0")/.." && pwd)/client/web"
  stamp="$web/node_modules/.installed-package-lock.json"
  if ! cmp -s "$web/package-lock.json" "$stamp"; then
    echo "setup: npm ci in client/web (playwright-core for the viewer test)" >&2
    (cd "$web" && npm ci --no-audit --no-fund --loglevel=error)
    cp "$web/package-lock.json" "$stamp"
  fi
fi
