#!/usr/bin/env bash
# Issue 36: what reusing the camera-independent passes (shadow map, RSM) saves when sessions of
# one scene share a renderer. Runs the release server twice on one port (reuse on, then
# --no-pass-reuse) and `lightcast loadtest` against each with 1, 4 and 16 sessions of the
# built-in Cornell box under BRSM (the server's defaults for this adapter), once with every
# session under the scene's light (sharing possible) and once with --distinct-lights (every
# session's light of its own: no sharing, the control). Prints a markdown report.
#
#   bench/pass-reuse.sh [SECONDS [WIDTH HEIGHT]] > bench/results/lavapipe-pass-reuse.md
#
# LIGHTCAST_SERVER_BIN / LIGHTCAST_CLIENT_BIN name other binaries (bench/gpu-run.sh's kit).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
. "$root/bench/lib.sh"
seconds="${1:-10}"
width="${2:-320}"
height="${3:-180}"
port=8097
server="${LIGHTCAST_SERVER_BIN:-$root/target/release/lightcast-server}"
client="${LIGHTCAST_CLIENT_BIN:-$root/target/release/lightcast}"
work=$(mktemp -d)
pid=""
trap 'kill "$pid" 2>/dev/null || true; rm -rf "$work"' EXIT
run() { # $1: label, $2…: server flags
  local label="$1"
  shift
  LIGHTCAST_CACHE_DIR="$work/cache" "$server" --listen "127.0.0.1:$port" --allow-cpu-adapter "$@" \
    >"$work/server-$label.log" 2>&1 &
  pid=$!
  wait_ready "http://127.0.0.1:$port" "$pid" "$work/server-$label.log" pass-reuse
  curl -fsS "http://127.0.0.1:$port/v1/server" >"$work/server.json"
  warm_brsm "http://127.0.0.1:$port"
  for lights in shared distinct; do
    local extra=()
    [ "$lights" = distinct ] && extra=(--distinct-lights)
    echo "running: reuse $label, lights $lights" >&2
    "$client" --server "http://127.0.0.1:$port" --json loadtest --sessions 1,4,16 \
      --duration "$seconds" --ramp 2 --input-hz 20 --fps-cap 240 --width "$width" --height "$height" \
      --gi brsm ${extra[@]+"${extra[@]}"} >"$work/$label-$lights.json"
  done
  kill "$pid"
  wait "$pid" 2>/dev/null || true
  pid=""
}
run on
run off --no-pass-reuse
python3 - "$work" "$seconds" "$width" "$height" <<'PY'
import json, sys, pathlib
work, seconds, width, height = pathlib.Path(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4]
server = json.loads((work / "server.json").read_text())
print(f"Adapter: {server['adapter']}; build {server['build']}; {width}×{height}, BRSM at the "
      f"server's defaults, {seconds} s per run; GPU ms from the frame headers' stage times.")
print()
def load(name):
    data = json.loads((work / f"{name}.json").read_text())
    return {r["sessions"]: r for r in (data if isinstance(data, list) else [data])}
runs = {(reuse, lights): load(f"{reuse}-{lights}") for reuse in ("on", "off") for lights in ("shared", "distinct")}
print("| sessions | lights | fps total, reuse on | fps total, reuse off | on / off | GPU ms per frame, on / off |")
print("|---|---|---|---|---|---|")
for lights in ("shared", "distinct"):
    for n in sorted(runs[("on", lights)]):
        on, off = runs[("on", lights)][n], runs[("off", lights)][n]
        gpu = lambda r: r["split"].get("gpu_ms", float("nan"))
        ratio = on["fps_total"] / off["fps_total"] if off["fps_total"] else float("nan")
        print(f"| {n} | {lights} | {on['fps_total']:.1f} | {off['fps_total']:.1f} | {ratio:.2f} | {gpu(on):.2f} / {gpu(off):.2f} |")
PY
