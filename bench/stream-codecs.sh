#!/usr/bin/env bash
# JPEG against H.264 streaming (issue 13), in one command:
#   1. `lightcast-server bench-stream`: one camera path at each size, rendered in process and
#      encoded as JPEG and H.264 (bytes per frame and per second, encode ms p50/p95, read-back
#      bytes, PSNR and FLIP against the lossless frames, the issue's targets at 1080p);
#   2. the same path through the service: `lightcast-server serve` on a local port and
#      `lightcast stream --camera-path` at each size, once as JPEG at the moving quality and
#      once as H.264 at the default bitrate (input→frame latency p50/p95, fps, bytes per
#      second as the client receives them, the server's per-frame split).
#
#   bench/stream-codecs.sh [--out PREFIX] [--bin DIR] [--scene SPEC] [--sizes 1280x720,1920x1080]
#       [--frames 60] [--gi none] [--stream-seconds 12] [--port 8091] [--quick]
#       [-- MORE BENCH-STREAM FLAGS, e.g. --motion dolly --jpeg-qualities 50,70,90]
#
# --out     write PREFIX.md (both parts, the commands and the machine at the top) and
#           PREFIX.json ({"bench": …, "service": […]}); default: the markdown on stdout only
# --bin     a directory with lightcast-server and lightcast (bench/gpu-kit.sh's kit);
#           default: release binaries built here
# --frames  frames of the in-process part per size (the service part streams for
#           --stream-seconds instead, as fast as the server renders)
# --quick   tiny sizes and few frames, to check the script; its numbers mean nothing
#
# The camera path is bench-stream's (`--write-path`), so flags after `--` that move the camera
# (--motion, --orbit-degrees-per-second, --dolly-per-second) apply to both parts.
# LIGHTCAST_CACHE_DIR, when set, keeps the service's light caches between runs.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"

out=
bin=
scene='procedural:cornell'
sizes=1280x720,1920x1080
frames=60
gi=none
stream_seconds=12
port=8091
quick=false
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    --bin) bin=$2; shift 2 ;;
    --scene) scene=$2; shift 2 ;;
    --sizes) sizes=$2; shift 2 ;;
    --frames) frames=$2; shift 2 ;;
    --gi) gi=$2; shift 2 ;;
    --stream-seconds) stream_seconds=$2; shift 2 ;;
    --port) port=$2; shift 2 ;;
    --quick) quick=true; shift ;;
    --) shift; break ;;
    *) echo "stream-codecs: unknown option $1 (see the comment at the top of $0)" >&2; exit 2 ;;
  esac
done
extra=("$@")
if $quick; then
  sizes=128x72,192x108; frames=4; stream_seconds=3
fi
command -v python3 >/dev/null || { echo "stream-codecs: needs python3 for the tables" >&2; exit 1; }

if [ -z "$bin" ]; then
  echo "stream-codecs: building release binaries" >&2
  (cd "$root" && cargo build --release --quiet -p lightcast-server -p lightcast-client)
  bin="$root/target/release"
fi
server="$bin/lightcast-server"
client="$bin/lightcast"
work=$(mktemp -d)
if [ -n "${LIGHTCAST_CACHE_DIR:-}" ]; then
  cache=$LIGHTCAST_CACHE_DIR
else
  cache="$work/cache"
fi
mkdir -p "$cache"
# A command as the shell would read it back (the scene's `?` and `&` quoted).
quoted() {
  local line
  printf -v line '%q ' "$@"
  echo "${line% }"
}
server_pid=
cleanup() {
  if [ -n "$server_pid" ]; then
    kill "$server_pid" 2>/dev/null || true
    wait "$server_pid" 2>/dev/null || true
  fi
  rm -rf "$work"
}
trap cleanup EXIT

# The service's own settings, shared by both parts: fps cap 30 (the bench's nominal fps), a
# 2048² shadow map, automatic exposure, JPEG at the moving quality, H.264 at its default
# (automatic) bitrate.
fps=30
shadow=2048
jpeg_quality=70
path_seconds=$((stream_seconds + 5)) # the path runs on while the session connects

bench_cmd=("$server" bench-stream --scene "$scene" --sizes "$sizes" --frames "$frames" --gi "$gi"
  --fps "$fps" --shadow-map-size "$shadow" --path-seconds "$path_seconds"
  --write-path "$work/path.json" --json "$work/bench.json" --markdown "$work/bench.md"
  "${extra[@]}")
echo "stream-codecs: $(quoted "${bench_cmd[@]}")" >&2
LIGHTCAST_CACHE_DIR="$cache" "${bench_cmd[@]}" >/dev/null

serve_cmd=("$server" serve --listen "127.0.0.1:$port" --allow-cpu-adapter --default-scene "$scene")
echo "stream-codecs: $(quoted "${serve_cmd[@]}")" >&2
LIGHTCAST_CACHE_DIR="$cache" "${serve_cmd[@]}" >"$work/server.log" 2>&1 &
server_pid=$!
url="http://127.0.0.1:$port"
for _ in $(seq 1 600); do
  curl -fs "$url/readyz" >/dev/null 2>&1 && break
  kill -0 "$server_pid" 2>/dev/null || { cat "$work/server.log" >&2; echo "stream-codecs: the server exited" >&2; exit 1; }
  sleep 0.2
done
curl -fs "$url/readyz" >/dev/null || { cat "$work/server.log" >&2; echo "stream-codecs: the server is not ready" >&2; exit 1; }
# The scene's light caches compute at start whatever the sessions use: wait for them so they
# do not share the CPU with the encoders being measured.
for _ in $(seq 1 1200); do
  curl -fs "$url/v1/scenes/default" | grep -q '"state":"ready"' && break
  sleep 0.5
done
curl -fs "$url/v1/server" > "$work/server.json"

runs=()
IFS=',' read -r -a size_list <<< "$sizes"
for size in "${size_list[@]}"; do
  w=${size%x*}; h=${size#*x}
  for codec in jpeg h264; do
    case $codec in
      jpeg) codec_flags=(--codec jpeg --quality "$jpeg_quality") ;;
      h264) codec_flags=(--codec h264) ;;
    esac
    cmd=("$client" --server "$url" --json stream --scene default --width "$w" --height "$h"
      --gi "$gi" --shadow-map-size "$shadow" --fps-cap "$fps" --input-hz "$fps"
      --camera-path "$work/path.json" --duration "$stream_seconds" "${codec_flags[@]}")
    echo "stream-codecs: $(quoted "${cmd[@]}")" >&2
    "${cmd[@]}" > "$work/stream-$w-$h-$codec.json"
    runs+=("$w|$h|$codec|$(quoted "${cmd[@]}")|$work/stream-$w-$h-$codec.json")
  done
done

# Both parts, the machine and the commands in one markdown file and one JSON file.
WORK="$work" BENCH_CMD="$(quoted "${bench_cmd[@]}")" SERVE_CMD="$(quoted "${serve_cmd[@]}")" \
  STREAM_SECONDS="$stream_seconds" FPS="$fps" SHADOW="$shadow" GI="$gi" SCENE="$scene" OUT="$out" \
  JPEG_QUALITY="$jpeg_quality" \
  REVISION="$(git -C "$root" rev-parse --short HEAD 2>/dev/null || cat "$bin/revision" 2>/dev/null || echo unknown)" \
  python3 - "${runs[@]}" <<'PY'
import json, os, platform, sys

env = os.environ
work = env["WORK"]
bench = json.load(open(f"{work}/bench.json"))
server = json.load(open(f"{work}/server.json"))
cpu = "unknown CPU"
try:
    for line in open("/proc/cpuinfo"):
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
except OSError:
    pass
software = "(Cpu," in bench["adapter"]

def short(command):
    # Commands name the temporary directory; the results name what it held.
    return command.replace(f"{work}/", "")

runs = []
for arg in sys.argv[1:]:
    w, h, codec, command, path = arg.split("|", 4)
    runs.append({"width": int(w), "height": int(h), "codec": codec,
                 "command": short(command), "result": json.load(open(path))})

md = ["# JPEG against H.264 streaming (issue 13)", ""]
if software:
    md += ["**A software adapter (lavapipe): render, read-back and latency numbers are not GPU "
           "numbers.** Encode times, bytes and quality are this CPU's and the codecs' own.", ""]
md += [f"Machine: {platform.system()} {platform.release()} {platform.machine()}, {cpu}, "
       f"{os.cpu_count()} CPU threads; adapter {bench['adapter']}; lightcast revision "
       f"{env['REVISION']}.", "",
       "Commands (`path.json` is the camera path the first writes):", "", "```",
       short(env["BENCH_CMD"]), short(env["SERVE_CMD"]) + " &"]
md += [r["command"] for r in runs]
md += ["```", "", "## In process (`lightcast-server bench-stream`)", "",
       open(f"{work}/bench.md").read().strip(), "",
       "## Through the service (`lightcast stream`)", "",
       f"The server's default scene is `{env['SCENE']}`; each run replays the same camera path "
       f"(camera messages at {env['FPS']} Hz) for {env['STREAM_SECONDS']} s, fps cap "
       f"{env['FPS']}, GI {env['GI']}, shadow map {env['SHADOW']}², exposure automatic; JPEG at "
       "the moving quality, H.264 at the default bitrate. Server and client share this "
       "machine. The server renders as fast as it can up to the cap, so where it falls short "
       "each frame shows more motion than at the nominal fps. Input→frame: from sending a camera message to receiving the first frame that "
       "shows it. Server split: the frame headers' means (GPU stages, waiting for the "
       "read-back, encoding).", "",
       "| size | codec | frames | fps | bytes/frame | kB/s | kbit/s | input→frame ms p50 / p95 (samples) | server GPU / read-back / encode ms | dropped / throttled | errors |",
       "|---|---|---|---|---|---|---|---|---|---|---|"]
for r in runs:
    s = r["result"]
    lat = s["input_to_frame_ms"]
    split = s["split"]
    per_frame = s["bytes_per_second"] / s["fps"] if s["fps"] > 0 else 0
    label = (f"JPEG q{env['JPEG_QUALITY']}" if r["codec"] == "jpeg"
             else "H.264 auto")
    md.append(
        f"| {r['width']}×{r['height']} | {label} | {s['frames']} | {s['fps']:.2f} | "
        f"{per_frame:.0f} | {s['bytes_per_second'] / 1e3:.0f} | {s['bytes_per_second'] * 8 / 1e3:.0f} | "
        f"{lat['p50']:.0f} / {lat['p95']:.0f} ({lat['samples']}) | "
        f"{split['gpu_ms']:.1f} / {split['readback_ms']:.1f} / {split['encode_ms']:.1f} | "
        f"{s['dropped']} / {s['throttled']} | {len(s['errors'])} |")
md.append("")
text = "\n".join(md)
print(text)
if env["OUT"]:
    with open(env["OUT"] + ".md", "w") as f:
        f.write(text)
    with open(env["OUT"] + ".json", "w") as f:
        json.dump({"bench": bench, "service": runs, "server": server}, f, indent=1)
        f.write("\n")
PY
echo "stream-codecs: done${out:+; wrote $out.md and $out.json}" >&2
