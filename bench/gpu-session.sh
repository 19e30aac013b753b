#!/usr/bin/env bash
# One bounded session on a lent GPU machine (the workplace's `device` tool, which runs a command
# in a copy of this repository and brings back at most 8 files from $OUT): a few single-frame
# probes of every GI method on the large street, then bench/gpu-run.sh's parts, each under its
# own time limit so that one slow part cannot cost the others, packed into files that fit the
# tool's limits. Build the kit first, here: bench/gpu-kit.sh; then run, with `.gpu-kit` carried:
#
#   bench/gpu-session.sh [gi|service|stream|all]   # results: $OUT/results.tgz, $OUT/probe.txt
set -u
root="$(cd "$(dirname "$0")/.." && pwd)"
kit="$root/.gpu-kit"
out="${OUT:?OUT: the folder whose files come back}"
part="${1:-all}"
r=/tmp/gpu-session
mkdir -p "$r"
start=$(date +%s)
log() { echo "[$(($(date +%s) - start))s] $*" | tee -a "$r/probe.txt"; }
{ head -2 /etc/os-release; ldd --version | head -1; nvidia-smi; } >>"$r/probe.txt" 2>&1
for f in "$kit"/gl/*.deb; do dpkg -x "$f" /; done
ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
export LIGHTCAST_CACHE_DIR=/tmp/lc-cache
server="$kit/lightcast-server"
# cars=0: the street as it was before its parked car (issue 35), as bench/gpu-run.sh runs it.
big='procedural:street?blocks=40&detail=4&cars=0'
if [ "$part" = gi ] || [ "$part" = all ]; then
  log "probe: cornell 320×180"
  timeout 40 "$server" render --width 320 --height 180 --out "$r/cornell.png" --json >>"$r/probe.txt" 2>&1
  log "rc=$?"
  for gi in brsm clustered none; do
    log "probe: $big, $gi, 1920×1080 (one cold frame)"
    timeout 100 "$server" render --scene "$big" --width 1920 --height 1080 --gi $gi \
      --out "$r/street-$gi.png" --json >"$r/street-$gi.json" 2>>"$r/probe.txt"
    log "rc=$?"
  done
  log "gi bench"
  timeout 330 "$root/bench/gpu-run.sh" "$kit" "$r" gi
  log "gi rc=$?"
fi
if [ "$part" = service ] || [ "$part" = all ]; then
  log "service bench"
  timeout 200 "$root/bench/gpu-run.sh" "$kit" "$r" service
  log "service rc=$?"
fi
if [ "$part" = stream ] || [ "$part" = all ]; then
  log "stream codecs bench"
  timeout 300 "$root/bench/gpu-run.sh" "$kit" "$r" stream
  log "stream rc=$?"
fi
# The 1080p difference pictures (2 MB each) would not fit the 16 MB a file may have.
tar czf "$out/results.tgz" --exclude='*-diff-*' -C "$r" .
cp "$r/probe.txt" "$out/"
log "done"
