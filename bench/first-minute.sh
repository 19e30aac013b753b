#!/usr/bin/env bash
# The first minute on this machine (issue 16 §1), measured as a new user meets it: the
# README's `curl -o frame.png -X POST localhost:8080/v1/render -d '{}'` against a warm server,
# a viewer-sized GI stream and a direct-light-only stream, with the server's default profile.
#
#   bench/first-minute.sh [--defaults auto|gpu|software] [--canvas 1600x900] [--out FILE]
#
# --defaults   the server's `--defaults` (auto: software on a CPU adapter)
# --canvas     the viewer's canvas in device pixels (a 1920×1080 browser window less the
#              320-pixel panel); the stream is this times the server's `viewer_scale`
# --out        where the markdown report goes (default: stdout only)
#
# Targets on a 2-core machine with lavapipe: the curl answers in ≤ 3 s, the viewer-sized stream
# shows ≥ 1 GI frame per second, and direct light alone ≥ 5 frames per second.
set -euo pipefail
cd "$(dirname "$0")/.."

defaults=auto
canvas=1600x900
out=
while [ $# -gt 0 ]; do
  case "$1" in
    --defaults) defaults=$2; shift 2 ;;
    --canvas) canvas=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    *) echo "unknown option $1 (see the comment at the top of $0)" >&2; exit 2 ;;
  esac
done
case "$canvas" in
  *x*) canvas_w=${canvas%x*}; canvas_h=${canvas#*x} ;;
  *) echo "--canvas must be WIDTHxHEIGHT, not $canvas" >&2; exit 2 ;;
esac

echo "building (release)…" >&2
cargo build --release --quiet -p lightcast-server -p lightcast-client
server=target/release/lightcast-server
client=target/release/lightcast
port=${PORT:-8097}
url=http://127.0.0.1:$port
cache=$(mktemp -d)
log=$(mktemp)
# The limits are raised: this measures how fast a profile's frames are, and the gpu profile's
# (about 5 s a frame on lavapipe) would be refused by the default --max-frame-cost.
"$server" serve --listen "127.0.0.1:$port" --cache-dir "$cache" --allow-cpu-adapter \
  --defaults "$defaults" --max-frame-cost 60 --max-request-cost 120 >"$log" 2>&1 &
pid=$!
trap 'kill $pid 2>/dev/null; wait $pid 2>/dev/null; rm -rf "$cache" "$log"' EXIT

for _ in $(seq 240); do
  curl -sf "$url/readyz" >/dev/null 2>&1 && break
  kill -0 $pid 2>/dev/null || { cat "$log" >&2; echo "the server exited" >&2; exit 1; }
  sleep 0.5
done
curl -sf "$url/readyz" >/dev/null || { cat "$log" >&2; echo "not ready after 120 s" >&2; exit 1; }

info=$(curl -sf "$url/v1/server")
field() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)" <<<"$info"; }
adapter=$(field "d['adapter']")
profile=$(field "d['defaults']['profile']")
reason=$(field "d['defaults']['reason']")
scale=$(field "d['defaults']['viewer_scale']")
render_defaults=$(INFO=$info python3 - <<'PY'
import json, os
r = json.loads(os.environ["INFO"])["defaults"]["render"]
g = r["gi"]
print(f"{r['width']}×{r['height']}, shadow map {r['shadow_map_size']}², {g['method']} with RSM "
      f"{g['rsm_size']}², {g['view_samples']} view samples, {g['val_count']} VALs, occlusion "
      f"{str(g['occlusion']).lower()}, indirect light at 1/{g['indirect_downscale']} resolution")
PY
)
stream_w=$(python3 -c "print(max(16, round($canvas_w * $scale)))")
stream_h=$(python3 -c "print(max(16, round($canvas_h * $scale)))")

# The README's request, as curl times it (connection, render, PNG, transfer).
readme_curl() {
  curl -s -o /dev/null -w '%{http_code} %{time_total}\n' -X POST "$url/v1/render" -d '{}' |
    awk '{printf "%s %.2f\n", $1, $2}'
}
echo "first request (cold: the light caches may still be computing)…" >&2
cold=$(readme_curl)
warm=()
for i in 1 2 3 4 5; do
  echo "warm request $i/5…" >&2
  warm+=("$(readme_curl)")
done
median() { printf '%s\n' "$@" | awk '{print $2}' | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
curl_median=$(median "${warm[@]}")

stream() {
  "$client" --server "$url" --json stream --duration 20 --width "$stream_w" --height "$stream_h" "$@"
}
echo "streaming GI at ${stream_w}×${stream_h} for 20 s…" >&2
gi_json=$(stream)
echo "streaming direct light only at ${stream_w}×${stream_h} for 20 s…" >&2
direct_json=$(stream --gi none)
fps() { python3 -c "import json,sys; d=json.load(sys.stdin); print(f\"{d['fps']:.2f}\")" <<<"$1"; }
gpu_ms() { python3 -c "import json,sys; d=json.load(sys.stdin); print(f\"{d['split']['gpu_ms']:.1f}\")" <<<"$1"; }
gi_fps=$(fps "$gi_json")
direct_fps=$(fps "$direct_json")
verdict() { python3 -c "print('met' if $1 else 'NOT met')"; }

report=$(cat <<EOF
# First minute: $(date -u +%Y-%m-%d), $(nproc) cores

Command: \`bench/first-minute.sh --defaults $defaults --canvas $canvas\`

- adapter: $adapter
- defaults: **$profile** profile ($reason): $render_defaults; viewer scale $scale

| what | measured | target |
|---|---|---|
| README \`curl … /v1/render -d '{}'\`, cold (first request) | $(awk '{print $2}' <<<"$cold") s (HTTP $(awk '{print $1}' <<<"$cold")) | |
| README \`curl … /v1/render -d '{}'\`, warm, median of 5 | $curl_median s ($(printf '%s ' "${warm[@]}" | awk '{for (i=2;i<=NF;i+=2) printf "%s ", $i}')) | ≤ 3 s: $(verdict "$curl_median <= 3") |
| viewer-sized GI stream, ${stream_w}×${stream_h} JPEG, 20 s | $gi_fps fps (GPU $(gpu_ms "$gi_json") ms/frame by the adapter's timestamps) | ≥ 1 fps: $(verdict "$gi_fps >= 1") |
| direct light only (\`--gi none\`), same size | $direct_fps fps (GPU $(gpu_ms "$direct_json") ms/frame) | ≥ 5 fps: $(verdict "$direct_fps >= 5") |

The stream size is the canvas ($canvas device pixels) times the viewer scale the server
announces, as the viewer computes it. lavapipe's timestamps under-report some stages; the fps
and the curl times are wall clock.
EOF
)
echo "$report"
if [ -n "$out" ]; then
  echo "$report" >"$out"
  echo "wrote $out" >&2
fi
