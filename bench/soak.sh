#!/usr/bin/env bash
# A soak of the service on loopback: sessions joining and leaving (direct light and BRSM),
# load-test bursts, uploads and deletes, one-shot renders (with reference comparisons), clients
# that vanish mid-stream and clients that stall (a WebSocket nobody reads, headers sent byte by
# byte), all at small sizes so lavapipe keeps up. Every 10 s it records the server's resident
# memory, open file descriptors, threads and live GPU buffers/textures/bind groups; at the end it
# fails if any of them (or the open sessions) keeps growing after warm-up (RSS by more than 5 %,
# the others at all beyond a small slack) or if more than 5 % of any workload's runs fail, and writes a table and a plot. Sessions left without a stream (the
# vanished clients) are ended after 30 s (--session-idle-secs), so the reaper is exercised too.
#
#   bench/soak.sh [MINUTES=30] [OUT_PREFIX=bench/results/soak-lavapipe]
#
# Needs: the workspace built (`cargo build -p lightcast-server -p lightcast-client`, done
# here), curl, python3 (matplotlib is installed into target/soak-venv for the plot).
set -euo pipefail
cd "$(dirname "$0")/.."
minutes=${1:-30}
prefix=${2:-bench/results/soak-lavapipe}
commit=$(git rev-parse --short HEAD)
port=18181
base="http://127.0.0.1:$port"
work=$(mktemp -d)
pids=()

cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  [ -n "${server:-}" ] && kill -TERM "$server" 2>/dev/null || true
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT

echo "soak: building" >&2
cargo build -q -p lightcast-server -p lightcast-client
srv=target/debug/lightcast-server
cli=target/debug/lightcast
python3 -m venv target/soak-venv >/dev/null 2>&1 || true
target/soak-venv/bin/pip install -q 'matplotlib==3.9.*' >/dev/null 2>&1 || echo "soak: matplotlib not installed: no plot" >&2

LIGHTCAST_CACHE_DIR="$work/cache" "$srv" serve --listen "127.0.0.1:$port" --allow-cpu-adapter --session-idle-secs 30 \
  >"$work/server.log" 2>&1 &
server=$!
for _ in $(seq 120); do curl -fs "$base/healthz" >/dev/null 2>&1 && break; sleep 1; done
curl -fs "$base/healthz" >/dev/null || { cat "$work/server.log" >&2; exit 1; }

start=$(date +%s)
deadline=$((start + minutes * 60))
running() { [ "$(date +%s)" -lt "$deadline" ]; }
export LIGHTCAST_SERVER="$base"
small=(--width 48 --height 32 --shadow-map-size 256)

# Each workload loops until the deadline; failures of single requests are counted, not fatal
# (a refused request is the server working), but the server must stay up.
loop() {
  local name=$1; shift
  local n=0 failed=0
  while running; do
    n=$((n + 1))
    "$@" >>"$work/$name.log" 2>&1 || failed=$((failed + 1))
  done
  echo "$name $n $failed" >"$work/$name.count"
}

viewer() { "$cli" stream --duration 20 "${small[@]}" --gi none --fps-cap 10; }
gi_viewer() {
  "$cli" stream --duration 15 "${small[@]}" --gi brsm --gi-param rsm_size=64 \
    --gi-param val_count=256 --gi-param view_samples=32 --fps-cap 4
}
burst() { "$cli" loadtest --sessions 4 --duration 10 --ramp 1 "${small[@]}" --gi none --fps-cap 10; }
vanishing() { timeout -s KILL 3 "$cli" stream --duration 30 "${small[@]}" --gi none || true; }
upload_cycle() {
  local id
  id=$("$cli" --json scenes upload tests/data/cornell-box/cornell-box.glb \
    | python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])') || return 1
  curl -fs -o /dev/null -X POST "$base/v1/render" \
    -d "{\"render\":{\"scene\":\"$id\",\"width\":32,\"height\":32,\"gi\":{\"method\":\"none\"}}}" || return 1
  "$cli" scenes rm "$id"
}
one_shots() {
  local gi
  for gi in '{"method":"none"}' '{"method":"brsm","rsm_size":64,"val_count":256,"view_samples":32}' \
    '{"method":"reference","spp":2}'; do
    curl -fs -o /dev/null -X POST "$base/v1/render" \
      -d "{\"render\":{\"width\":32,\"height\":24,\"shadow_map_size\":256,\"gi\":$gi},\"compare_to\":\"reference\",\"compare_spp\":4}" \
      || return 1
  done
}
# A WebSocket opened and never read (the server must drop frames, not buffer them), then a
# request whose headers trickle in and stop.
stalled() {
  local id status
  id=$(curl -fs -X POST "$base/v1/sessions" \
    -d '{"render":{"width":32,"height":32,"gi":{"method":"none"}},"fps_cap":30}' \
    | python3 -c 'import json,sys; print(json.load(sys.stdin)["session"]["id"])') || return 1
  exec 3<>"/dev/tcp/127.0.0.1/$port"
  printf 'GET /v1/sessions/%s/stream HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n' "$id" >&3
  # The upgrade must be accepted; after that line nothing more is read for 15 s.
  read -r -t 10 status <&3 || status=""
  sleep 15
  exec 3>&-
  case "$status" in *" 101 "*) ;; *) echo "stalled: upgrade answered '$status'"; return 1 ;; esac
  curl -fs -o /dev/null -X DELETE "$base/v1/sessions/$id" || true
  exec 4<>"/dev/tcp/127.0.0.1/$port"
  printf 'GET /healthz HTTP/1.1\r\n' >&4
  sleep 5
  printf 'Host: x\r\n' >&4
  sleep 5
  exec 4>&-
}

for w in viewer gi_viewer burst vanishing upload_cycle one_shots stalled; do
  loop "$w" "$w" &
  pids+=($!)
done

csv="$work/samples.csv"
echo "seconds,rss_kib,fds,threads,gpu_buffers,gpu_textures,gpu_bind_groups,sessions" >"$csv"
sample() {
  local t rss fds threads metrics
  t=$(( $(date +%s) - start ))
  rss=$(awk '/^VmRSS/ {print $2}' "/proc/$server/status")
  threads=$(awk '/^Threads/ {print $2}' "/proc/$server/status")
  fds=$(ls "/proc/$server/fd" | wc -l)
  metrics=$(curl -fs --max-time 10 "$base/metrics" || true)
  g() { echo "$metrics" | awk -v n="$1" '$1 == n {print $2; exit}'; }
  echo "$t,$rss,$fds,$threads,$(g lightcast_gpu_buffers),$(g lightcast_gpu_textures),$(g lightcast_gpu_bind_groups),$(g lightcast_sessions)" >>"$csv"
}
echo "soak: $minutes min on $base; samples every 10 s" >&2
while running; do
  kill -0 "$server" 2>/dev/null || { tail -50 "$work/server.log" >&2; echo "soak: the server died" >&2; exit 1; }
  sample
  sleep 10
done
wait "${pids[@]}" 2>/dev/null || true
pids=()
# Idle after the load: what is still held once every client is gone.
sleep 15
sample
kill -0 "$server" 2>/dev/null || { echo "soak: the server died" >&2; exit 1; }

cat "$work"/*.count >"$work/workloads.txt"
cp "$csv" "$prefix.csv"
py=python3
[ -x target/soak-venv/bin/python ] && py=target/soak-venv/bin/python
"$py" - "$prefix" "$minutes" "$work/workloads.txt" "$commit" <<'EOF'
import csv, statistics, sys
prefix, minutes, workloads, commit = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
rows = list(csv.DictReader(open(prefix + ".csv")))
num = lambda r, k: float(r[k]) if r[k] else float("nan")
load, idle = rows[:-1], rows[-1]
# Warm-up: the first fifth of the run (at least 3 minutes, at most half of a short trial run):
# caches, pipelines and pools fill.
warm = min(max(180, int(minutes * 60 / 5)), int(load[-1]["seconds"]) // 2)
after = [r for r in load if int(r["seconds"]) >= warm]
first, last = after[: max(3, len(after) // 10)], after[-max(3, len(after) // 10):]
verdicts, lines = [], []
for key, rule in [("rss_kib", "rel"), ("fds", "abs"), ("threads", "abs"), ("gpu_buffers", "abs"),
                  ("gpu_textures", "abs"), ("gpu_bind_groups", "abs"), ("sessions", "abs")]:
    a = statistics.median(num(r, key) for r in first)
    b = statistics.median(num(r, key) for r in last)
    peak_warm = max(num(r, key) for r in load if int(r["seconds"]) < warm)
    if rule == "rel":
        ok = b <= a * 1.05
        limit = "≤ +5 %"
    else:
        # Counts move with the clients connected at the sampling instant; a leak shows as the
        # median drifting above everything seen during warm-up.
        ok = b <= max(a, peak_warm) + 8
        limit = "≤ warm-up peak + 8"
    verdicts.append(ok)
    lines.append(f"| {key} | {a:.0f} | {b:.0f} | {num(idle, key):.0f} | {limit} | {'ok' if ok else 'GROWING'} |")
counts = [l.split() for l in open(workloads) if l.strip()]
# A workload whose runs mostly fail means the service stopped serving it (refusals included).
for name, n, failed in counts:
    verdicts.append(int(failed) <= 0.05 * int(n))
with open(prefix + ".md", "w") as out:
    status = "passed" if all(verdicts) else "FAILED"
    out.write(f"# Soak, {minutes} min, lavapipe (2 cores), commit {commit}: **{status}**\n\n")
    out.write(f"Command: `bench/soak.sh {minutes}`. Samples every 10 s; warm-up {warm} s. ")
    out.write("Medians of the first and last tenth of the samples after warm-up, and one sample 15 s after every client left.\n\n")
    out.write("| measure | after warm-up | at the end | idle after | rule | verdict |\n|---|---|---|---|---|---|\n")
    out.write("\n".join(lines) + "\n\n")
    out.write("| workload | runs | failed runs |\n|---|---|---|\n")
    for name, n, failed in counts:
        out.write(f"| {name} | {n} | {failed} |\n")
    out.write(f"\nRaw samples: `{prefix.split('/')[-1]}.csv`.\n")
try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    t = [int(r["seconds"]) / 60 for r in rows]
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    for ax, keys, title in [(axes[0][0], ["rss_kib"], "resident memory (KiB)"),
                            (axes[0][1], ["fds", "threads"], "file descriptors, threads"),
                            (axes[1][0], ["gpu_buffers", "gpu_textures", "gpu_bind_groups"], "live GPU objects"),
                            (axes[1][1], ["sessions"], "sessions open")]:
        for k in keys:
            ax.plot(t, [num(r, k) for r in rows], label=k)
        ax.axvline(warm / 60, color="grey", linestyle=":")
        ax.set_title(title)
        ax.legend()
    for ax in axes[1]:
        ax.set_xlabel("minutes")
    fig.suptitle(f"lightcast soak, {minutes} min, lavapipe, commit {commit}")
    fig.tight_layout()
    fig.savefig(prefix + ".png", dpi=80)
except ImportError:
    pass
print(open(prefix + ".md").read())
sys.exit(0 if all(verdicts) else 1)
EOF
