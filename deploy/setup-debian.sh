#!/usr/bin/env bash
# Installs what lightcast needs on a Debian machine, then returns. Idempotent.
#
# - libvulkan1: the Vulkan loader wgpu opens.
# - mesa-vulkan-drivers (lavapipe, a CPU Vulkan driver) only when no Vulkan driver is installed,
#   so machines without a GPU can still render (slowly) and run the tests.
# - fonts-dejavu-core: the font of the benchmark's PNG plots.
# - Rust itself is not installed here: cargo ≥ 1.87 must be on PATH (https://rustup.rs).
set -euo pipefail

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

if [ ${#packages[@]} -gt 0 ]; then
  echo "setup: installing ${packages[*]}" >&2
  $sudo apt-get update -qq
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${packages[@]}" >/dev/null
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found; install Rust 1.87 or newer (https://rustup.rs) and run again" >&2
  exit 1
fi
