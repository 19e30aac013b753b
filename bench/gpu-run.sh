#!/usr/bin/env bash
# The GPU benchmarks the issues ask for, in one command, on a machine with a GPU:
#   - the paper's evaluation (`lightcast-server bench`, issue 3) at 1920×1080 on the
#     procedural street scene, LightSkin against BRSM over RSM sizes, VAL counts and view samples;
#   - seed 001's evaluation (`bench --gi surfels`, issue 12) on the Cornell box and the street;
#   - seed 003's evaluation (`bench --gi clustered`, issue 11) on the Cornell box (also at the
#     paper's 800×800) and the street;
#   - GI time and error against the light count (`bench/light-counts.sh`, issue 33): every
#     method with 1 … 16 lights on the Cornell box and the street; every method lit by
#     emissive surfaces alone against the reference (`bench/light_errors.py --case emitters`);
#   - the street against the truth (issue 34, `bench/light_errors.py --case street`): every
#     method as authored and all Lambertian, two views, against the full and the modelled
#     transport's reference, the sun's maps over the scene and fitted to the view, glossy
#     senders on and off;
#   - moving objects (issue 35, `bench/light_errors.py --case moving`): the Cornell box's short
#     box slid along a path, each method's error against the reference of every pose, its
#     change between poses against the reference's, and its GI ms at rest and moving;
#   - the service under load (`lightcast loadtest`, issue 4): 1, 4, 16 and 32 sessions at
#     1280×720 and 1920×1080;
#   - sessions sharing work (issue 36, `bench/pass-reuse.sh` at 1280×720), the render loop's
#     frames in flight (`bench/frames-in-flight.sh`, 16 sessions at 1280×720) and the G-buffer
#     and RSM as visibility buffers against every target rasterised
#     (`bench/visibility-buffer.sh`, 1080p street, 2048² RSM), all after the service runs;
#   - JPEG against H.264 (`bench/stream-codecs.sh`, issue 13): one camera path at 1280×720 and
#     1920×1080, in process (bytes, encode ms, PSNR/FLIP, the targets) and through the service
#     (input→frame latency); needs python3 for its tables.
#
#   bench/gpu-run.sh KIT_DIR OUT_DIR [gi|service|stream|all] [--quick]
#
# KIT_DIR comes from bench/gpu-kit.sh (binaries, font, Vulkan loader .debs). Results land in
# OUT_DIR: gpu-street.{md,json}, gpu-street-{error,fps}.png, gpu-surfels-{cornell,street}.{md,json,
# …png}, gpu-clustered-{cornell,cornell-800,street}.{md,json,…png},
# gpu-light-counts-{cornell,street}-{brsm,clustered,surfels,rsm_gather}.md, gpu-emitters-errors.md,
# gpu-street-truth.md, gpu-moving-box.md,
# gpu-service.md, gpu-pass-reuse.md, gpu-frames-in-flight.md, gpu-visibility-buffer.md,
# gpu-stream-codecs.{md,json}, environment.txt and
# run.log; copy them to bench/results/ with the GPU's name. --quick runs tiny sizes on any
# adapter (a software one included) to check this script; its numbers mean nothing.
set -euo pipefail
kit="$(cd "${1:?usage: $0 KIT_DIR OUT_DIR [gi|service|stream|all] [--quick]}" && pwd)"
out="${2:?usage: $0 KIT_DIR OUT_DIR [gi|service|stream|all] [--quick]}"
what="${3:-all}"
quick=false
[ "${4:-}" = "--quick" ] || [ "$what" = "--quick" ] && quick=true
[ "$what" = "--quick" ] && what=all
case "$what" in gi|service|stream|all) ;; *) echo "gpu-run: unknown part '$what'" >&2; exit 2 ;; esac
mkdir -p "$out"
exec > >(tee -a "$out/run.log") 2>&1

# Vulkan loader from the kit where the machine has none (the device machines ship only the
# NVIDIA driver's ICD).
if ! ldconfig -p | grep -q libvulkan.so.1 && ls "$kit"/gl/*.deb >/dev/null 2>&1; then
  for f in "$kit"/gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
fi
nvidia_icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
if [ -f "$nvidia_icd" ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
  export VK_DRIVER_FILES="$nvidia_icd"
fi
font_dir=/usr/share/fonts/truetype/dejavu
if [ ! -f "$font_dir/DejaVuSans.ttf" ]; then
  mkdir -p "$font_dir" && cp "$kit/DejaVuSans.ttf" "$font_dir/"
fi

server="$kit/lightcast-server"
client="$kit/lightcast"
# A light-cache store the caller already filled (LIGHTCAST_CACHE_DIR) is reused; otherwise a
# temporary one, removed at the end.
if [ -n "${LIGHTCAST_CACHE_DIR:-}" ]; then
  cache=""
  mkdir -p "$LIGHTCAST_CACHE_DIR"
else
  cache=$(mktemp -d)
  export LIGHTCAST_CACHE_DIR="$cache"
fi
cpu_flag=()
if $quick; then
  cpu_flag=(--allow-cpu-adapter)
fi

{
  echo "date: $(date -u +%FT%TZ)"
  echo "lightcast revision: $(cat "$kit/revision" 2>/dev/null || echo unknown)"
  echo "host: $(uname -srm), $(nproc) CPUs"
  if command -v nvidia-smi >/dev/null 2>&1; then
    nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv
  else
    echo "nvidia-smi: not found"
  fi
} > "$out/environment.txt"
cat "$out/environment.txt"

if [ "$what" = gi ] || [ "$what" = all ]; then
  if $quick; then
    sizes=(--width 160 --height 90 --rsm-sizes 32,64 --vals 256,512 --view-samples 64 --frames 2 --warmup 1
      --reference-spp 16)
    # cars=0 here and below: the street as it was before its parked car (issue 35), which the
    # recorded results were measured on.
    scene='procedural:street?blocks=2&cars=0'
  else
    # Every configuration is also compared with a 1024-spp path-traced reference (issue 10).
    sizes=(--width 1920 --height 1080 --reference-spp 1024)
    scene='procedural:street?blocks=40&detail=4&cars=0'
  fi
  echo "gpu-run: GI benchmark on $scene" >&2
  cmd=("$server" bench --scene "$scene" "${sizes[@]}" --json "$out/gpu-street.json"
    --markdown "$out/gpu-street.md" --plots "$out/gpu-street")
  echo "command: ${cmd[*]}" >> "$out/environment.txt"
  "${cmd[@]}"
  # Indirect light at half resolution against full (gi.indirect_downscale, issue 16): the
  # paper's default configuration twice, each with its error against the reference.
  if ! $quick; then
    for d in 1 2; do
      cmd=("$server" bench --scene "$scene" --width 1920 --height 1080 --reference-spp 256
        --rsm-sizes 1024 --vals 8192 --view-samples 512 --gi-param "indirect_downscale=$d"
        --json "$out/gpu-street-downscale-$d.json" --markdown "$out/gpu-street-downscale-$d.md")
      echo "command: ${cmd[*]}" >> "$out/environment.txt"
      "${cmd[@]}"
    done
  fi
  # Seed 001 (issue 12): surfels over n_S, n_L and SH bands around 32k / 128 / 3, error at one
  # and three bounces, on the Cornell box and the street (the precomputation runs on the CPU).
  if $quick; then
    surfel_runs=("procedural:cornell|--width 160 --height 90 --sweep-surfels 1024,2048 --sweep-links 16 --sweep-bands 3 --gi-param surfel_count=2048 --gi-param surfel_links=16 --gi-param surfel_cache_spacing=0.5 --frames 2 --warmup 1 --reference-spp 16")
  else
    surfel_runs=("procedural:cornell|--width 1920 --height 1080 --reference-spp 1024"
      "$scene|--width 1920 --height 1080 --reference-spp 256")
  fi
  for run in "${surfel_runs[@]}"; do
    s="${run%%|*}"
    name=$(case "$s" in *cornell*) echo cornell ;; *) echo street ;; esac)
    read -r -a flags <<< "${run#*|}"
    cmd=("$server" bench --gi surfels --scene "$s" "${flags[@]}"
      --json "$out/gpu-surfels-$name.json" --markdown "$out/gpu-surfels-$name.md"
      --plots "$out/gpu-surfels-$name")
    echo "command: ${cmd[*]}" >> "$out/environment.txt"
    "${cmd[@]}"
  done
  # Seed 003 (issue 11): clustered over VPL counts × VAL counts with per-VPL hard shadows and
  # no visibility as baselines (Tables 1–2, Figure 10), the other methods at equal time; the
  # paper's anchor is 800×800, 1,024 VPLs, 30 VALs (19.7 fps on a GeForce 8800 GTX).
  if $quick; then
    clustered_runs=("procedural:cornell|--width 160 --height 90 --gi-param rsm_size=64 --sweep-vpls 256 --sweep-clusters 5,30 --baseline-vpls 256 --paraboloid-size 32 --baseline-paraboloid-size 32 --frames 2 --warmup 1 --reference-spp 16")
  else
    clustered_runs=("procedural:cornell|--width 1920 --height 1080 --gi-param rsm_size=1024 --reference-spp 1024 --compare-methods"
      "procedural:cornell|--width 800 --height 800 --gi-param rsm_size=1024 --sweep-vpls 1024 --sweep-clusters 30 --baseline-vpls 1024 --reference-spp 256"
      "$scene|--width 1920 --height 1080 --gi-param rsm_size=1024 --reference-spp 256 --compare-methods")
  fi
  for run in "${clustered_runs[@]}"; do
    s="${run%%|*}"
    read -r -a flags <<< "${run#*|}"
    name=$(case "$s" in *cornell*) echo cornell ;; *) echo street ;; esac)
    case " ${flags[*]} " in *" 800 "*) name="$name-800" ;; esac
    cmd=("$server" bench --gi clustered --scene "$s" "${flags[@]}"
      --json "$out/gpu-clustered-$name.json" --markdown "$out/gpu-clustered-$name.md"
      --plots "$out/gpu-clustered-$name")
    echo "command: ${cmd[*]}" >> "$out/environment.txt"
    "${cmd[@]}"
  done
  # Issue 33: every method's GI time with 1, 2, 4, 8 and 16 lights (seed 001: surfels hardly
  # grow), as ratios within the run.
  light_flags=()
  if $quick; then light_flags=(--quick); fi
  cmd=("$(dirname "$0")/light-counts.sh" "$server" "$out" gpu "${light_flags[@]}")
  echo "command: ${cmd[*]}" >> "$out/environment.txt"
  "${cmd[@]}"
  # Issue 33 part 4: every method lit by emissive surfaces alone against the reference.
  if $quick; then emitter_size=(--width 64 --height 48 --spp 16); else emitter_size=(--width 1280 --height 720 --spp 1024); fi
  cmd=(python3 "$(dirname "$0")/light_errors.py" "$server" --case emitters "${emitter_size[@]}")
  echo "command: ${cmd[*]} > $out/gpu-emitters-errors.md" >> "$out/environment.txt"
  "${cmd[@]}" > "$out/gpu-emitters-errors.md"
  # Issue 34: every method on the street as authored and all Lambertian, down its middle street
  # and one street over, against the full reference and the modelled transport's, with the
  # sun's maps over the scene and fitted to the view, and the RSM methods' glossy senders on
  # and off (the same references: only the methods' renders double).
  if $quick; then truth_size=(--width 64 --height 36 --spp 16); else truth_size=(--width 1920 --height 1080 --spp 1024); fi
  cmd=(python3 "$(dirname "$0")/light_errors.py" "$server" --case street --senders full,diffuse "${truth_size[@]}")
  echo "command: ${cmd[*]} > $out/gpu-street-truth.md" >> "$out/environment.txt"
  "${cmd[@]}" > "$out/gpu-street-truth.md"
  # Issue 35: the short box moving through the Cornell box.
  if $quick; then moving_size=(--width 64 --height 48 --spp 16); else moving_size=(--width 1280 --height 720 --spp 1024); fi
  cmd=(python3 "$(dirname "$0")/light_errors.py" "$server" --case moving "${moving_size[@]}")
  echo "command: ${cmd[*]} > $out/gpu-moving-box.md" >> "$out/environment.txt"
  "${cmd[@]}" > "$out/gpu-moving-box.md"
fi

if [ "$what" = service ] || [ "$what" = all ]; then
  port=8090
  "$server" --listen "127.0.0.1:$port" "${cpu_flag[@]}" > "$out/server.log" 2>&1 &
  server_pid=$!
  trap 'kill $server_pid 2>/dev/null || true; [ -z "$cache" ] || rm -rf "$cache"' EXIT
  for _ in $(seq 1 300); do
    curl -fs "http://127.0.0.1:$port/readyz" >/dev/null 2>&1 && break
    kill -0 $server_pid 2>/dev/null || { echo "gpu-run: the server exited" >&2; cat "$out/server.log" >&2; exit 1; }
    sleep 0.2
  done
  curl -fs "http://127.0.0.1:$port/readyz" >/dev/null || { echo "gpu-run: the server is not ready" >&2; cat "$out/server.log" >&2; exit 1; }
  grep -m1 "adapter" "$out/server.log" | sed 's/\x1b\[[0-9;]*m//g' >> "$out/environment.txt" || true
  # Sessions would show direct light only while the default scene's light caches compute.
  for _ in $(seq 1 600); do
    curl -fs "http://127.0.0.1:$port/v1/scenes/default" | grep -q '"state":"ready"' && break
    sleep 0.5
  done
  if $quick; then
    runs=("64 36" "96 54"); sessions=1,4; duration=2; methods=(none)
  else
    runs=("1280 720" "1920 1080"); sessions=1,4,16,32; duration=10; methods=(brsm none)
  fi
  : > "$out/gpu-service.md"
  for gi in "${methods[@]}"; do
    for size in "${runs[@]}"; do
      set -- $size
      echo "gpu-run: service load test at $1×$2, GI $gi" >&2
      part="$out/service-$gi-$2.md"
      cmd=("$client" --server "http://127.0.0.1:$port" loadtest --sessions "$sessions"
        --duration "$duration" --ramp 2 --input-hz 30 --fps-cap 240 --width "$1" --height "$2"
        --scene default --gi "$gi" --markdown "$part")
      echo "command: ${cmd[*]}" >> "$out/environment.txt"
      "${cmd[@]}"
      { echo "## ${1}×${2}, GI $gi"; echo; cat "$part"; echo; } >> "$out/gpu-service.md"
      rm "$part"
    done
  done
  kill $server_pid
  wait $server_pid || true
  trap - EXIT
  rm "$out/server.log"
  # Issue 36: sessions of one scene with the camera-independent passes reused and not, under
  # one light and under a light each (the control).
  if ! $quick; then
    echo "gpu-run: pass reuse at 1280×720" >&2
    LIGHTCAST_SERVER_BIN="$server" LIGHTCAST_CLIENT_BIN="$client" \
      "$(dirname "$0")/pass-reuse.sh" 10 1280 720 > "$out/gpu-pass-reuse.md" \
      || echo "gpu-run: the pass-reuse run failed (the parts after it still run)" >&2
    # The render loop's queue depth: 16 sessions at 720p with 1, 2 and 3 frames in flight,
    # and how long the GPU waited for the loop.
    echo "gpu-run: frames in flight at 1280×720" >&2
    LIGHTCAST_SERVER_BIN="$server" LIGHTCAST_CLIENT_BIN="$client" \
      "$(dirname "$0")/frames-in-flight.sh" 10 1280 720 16 > "$out/gpu-frames-in-flight.md" \
      || echo "gpu-run: the frames-in-flight run failed (the parts after it still run)" >&2
    # The G-buffer and the RSM as visibility buffers and their resolves against every target
    # rasterised, at 1080p on the 1.2 M-triangle street with a 2048² RSM (the H200 run on
    # record: gbuffer 7.7 ms, rsm 13.5 ms).
    echo "gpu-run: visibility buffer at 1920×1080" >&2
    LIGHTCAST_SERVER_BIN="$server" "$(dirname "$0")/visibility-buffer.sh" 1920 1080 \
      'procedural:street?blocks=40&detail=4&cars=0' 30 2048 \
      > "$out/gpu-visibility-buffer.md" \
      || echo "gpu-run: the visibility-buffer run failed (the parts after it still run)" >&2
  fi
fi
if [ "$what" = stream ] || [ "$what" = all ]; then
  # The same flags as bench/results/lavapipe-stream-codecs.md, so the two compare: a drive
  # down the street at about 15 m/s, JPEG at four qualities (the equal-PSNR bracket) and H.264
  # at the automatic bitrate and 8000 kbit/s (cars=0: that file's street, before its parked car).
  stream_flags=(--scene 'procedural:street?blocks=8&cars=0' --stream-seconds 20)
  if $quick; then
    stream_flags+=(--quick)
  fi
  echo "gpu-run: JPEG against H.264" >&2
  cmd=("$(dirname "$0")/stream-codecs.sh" --bin "$kit" "${stream_flags[@]}"
    --out "$out/gpu-stream-codecs" -- --motion dolly --dolly-per-second 0.03
    --jpeg-qualities 50,70,80,90 --flip-every 2)
  echo "command: ${cmd[*]}" >> "$out/environment.txt"
  "${cmd[@]}" > /dev/null
fi
[ -z "$cache" ] || rm -rf "$cache"
echo "gpu-run: done; results in $out" >&2
