#!/usr/bin/env bash
# Packs what bench/gpu-run.sh needs on a GPU machine that has no Rust toolchain and no network
# (the workplace's `device` machines): stripped release binaries, the plots' font, and the
# Vulkan loader packages. Run on the build machine (Debian, x86-64), from anywhere:
#
#   bench/gpu-kit.sh [KIT_DIR]        # default KIT_DIR: .gpu-kit in the repository (ignored by git)
#
# The kit is about 20 MB. Then, on the GPU machine, in a copy of the repository with the kit:
#   bench/gpu-run.sh .gpu-kit OUT_DIR
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
kit="${1:-$root/.gpu-kit}"
mkdir -p "$kit/gl"

echo "gpu-kit: building release binaries (a few minutes on a clean tree)" >&2
(cd "$root" && cargo build --release -q -p lightcast-server --features plots -p lightcast-client)
strip -o "$kit/lightcast-server" "$root/target/release/lightcast-server"
strip -o "$kit/lightcast" "$root/target/release/lightcast"
git -C "$root" rev-parse --short HEAD > "$kit/revision"

font=/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf
[ -f "$font" ] || "$root/deploy/setup-debian.sh"
cp "$font" "$kit/DejaVuSans.ttf"

# The Vulkan loader (and the GL/EGL libraries NVIDIA's driver loads beside it), as .debs to
# unpack there; fetched with a private APT state so this machine's own lists stay untouched.
if ! ls "$kit"/gl/libvulkan1_*.deb >/dev/null 2>&1; then
  echo "gpu-kit: downloading the Vulkan loader packages" >&2
  lists=$(mktemp -d)
  mkdir -p "$lists/partial"
  apt_opts=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 "-oDir::State::Lists=$lists")
  apt-get "${apt_opts[@]}" update -qq
  (cd "$kit/gl" && apt-get "${apt_opts[@]}" download -qq \
    libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
  rm -rf "$lists"
fi
du -sh "$kit" >&2
