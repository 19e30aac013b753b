#!/usr/bin/env bash
# Issue 36, part 3 (a GPU that stays busy): the render loop with 1, 2 and 3 frames in flight
# (`--frames-in-flight`), `lightcast loadtest` with SESSIONS sessions of the built-in Cornell
# box under BRSM (one scene and light: the sessions share the light-side stages), in one run.
# Reports the total frames/s and, from `/metrics`, how long the GPU sat idle before frames
# while the render loop prepared them (`lightcast_gpu_idle_seconds`: at least that long) as a
# share of the loadtest's wall time (its ramp included). Prints a markdown report.
#
#   bench/frames-in-flight.sh [SECONDS [WIDTH HEIGHT [SESSIONS]]] > bench/results/<adapter>-frames-in-flight.md
#
# LIGHTCAST_SERVER_BIN / LIGHTCAST_CLIENT_BIN name other binaries (bench/gpu-run.sh's kit).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
. "$root/bench/lib.sh"
seconds="${1:-10}"
width="${2:-320}"
height="${3:-180}"
sessions="${4:-16}"
port=8098
server="${LIGHTCAST_SERVER_BIN:-$root/target/release/lightcast-server}"
client="${LIGHTCAST_CLIENT_BIN:-$root/target/release/lightcast}"
work=$(mktemp -d)
pid=""
trap 'kill "$pid" 2>/dev/null || true; rm -rf "$work"' EXIT
for depth in 1 2 3; do
  LIGHTCAST_CACHE_DIR="$work/cache" "$server" --listen "127.0.0.1:$port" --allow-cpu-adapter \
    --frames-in-flight "$depth" >"$work/server-$depth.log" 2>&1 &
  pid=$!
  wait_ready "http://127.0.0.1:$port" "$pid" "$work/server-$depth.log" frames-in-flight
  curl -fsS "http://127.0.0.1:$port/v1/server" >"$work/server.json"
  warm_brsm "http://127.0.0.1:$port"
  curl -fsS "http://127.0.0.1:$port/metrics" >"$work/before-$depth.txt"
  date +%s.%N >"$work/start-$depth.txt"
  echo "running: --frames-in-flight $depth, $sessions sessions" >&2
  "$client" --server "http://127.0.0.1:$port" --json loadtest --sessions "$sessions" \
    --duration "$seconds" --ramp 2 --input-hz 20 --fps-cap 240 --width "$width" --height "$height" \
    --gi brsm >"$work/load-$depth.json"
  date +%s.%N >"$work/end-$depth.txt"
  curl -fsS "http://127.0.0.1:$port/metrics" >"$work/after-$depth.txt"
  kill "$pid"
  wait "$pid" 2>/dev/null || true
  pid=""
done
python3 - "$work" "$seconds" "$width" "$height" "$sessions" <<'PY'
import json, sys, pathlib
work, seconds, width, height, sessions = pathlib.Path(sys.argv[1]), *sys.argv[2:]
server = json.loads((work / "server.json").read_text())
print(f"Adapter: {server['adapter']}; build {server['build']}; {sessions} sessions of the Cornell "
      f"box at {width}×{height}, BRSM at the server's defaults, one light (shared light-side "
      f"stages), {seconds} s per run.")
print()
def metric(path, name):
    for line in path.read_text().splitlines():
        if line.startswith(name + " "):
            return float(line.split()[1])
    return 0.0
print("| frames in flight | fps total | GPU idle before frames (s, at least) | share of the run | frames timed | mean idle per frame (ms) |")
print("|---|---|---|---|---|---|")
for depth in (1, 2, 3):
    data = json.loads((work / f"load-{depth}.json").read_text())
    run = data[0] if isinstance(data, list) else data
    d = lambda n: metric(work / f"after-{depth}.txt", n) - metric(work / f"before-{depth}.txt", n)
    idle, frames = d("lightcast_gpu_idle_seconds_sum"), d("lightcast_gpu_idle_seconds_count")
    per = 1e3 * idle / frames if frames else float("nan")
    wall = float((work / f"end-{depth}.txt").read_text()) - float((work / f"start-{depth}.txt").read_text())
    print(f"| {depth} | {run['fps_total']:.1f} | {idle:.2f} | {idle / wall:.1%} | {frames:.0f} | {per:.2f} |")
PY
