#!/usr/bin/env bash
# A long fuzzing run: the property-based fuzz targets of server/tests/integration/fuzz.rs
# (glTF loader, JSON requests with limits, WebSocket control messages, frame-header decoder),
# round after round with fresh seeds, until the time is up or a case fails.
#
#   bench/fuzz.sh [MINUTES=60] [CASES_PER_ROUND=20000] [REPORT=bench/results/fuzz-DATE.md]
#
# Stops at the first failure (exit 1, the failing round's output in the report: proptest prints
# the shrunk input and the seed reproduces it with LIGHTCAST_FUZZ_SEED). CI runs the same
# targets with a small fixed budget on every change.
set -euo pipefail
cd "$(dirname "$0")/.."
minutes=${1:-60}
cases=${2:-20000}
report=${3:-bench/results/fuzz-$(date -u +%Y-%m-%d).md}
commit=$(git rev-parse --short HEAD)

echo "fuzz: building the test binary" >&2
binary=$(cargo test -p lightcast-server --test integration --no-run --message-format=json 2>/dev/null \
  | grep '"name":"integration"' | sed -n 's/.*"executable":"\([^"]*\)".*/\1/p' | tail -n1)
[ -x "$binary" ] || { echo "fuzz: no test binary found" >&2; exit 1; }
# A copy, so that builds during the run do not change what is being fuzzed.
copy=$(mktemp)
cp "$binary" "$copy"
chmod +x "$copy"
binary=$copy

start=$(date +%s)
deadline=$((start + minutes * 60))
round=0
declare -A total
log=$(mktemp)
trap 'rm -f "$log" "$copy"' EXIT
status=passed
while [ "$(date +%s)" -lt "$deadline" ]; do
  round=$((round + 1))
  seed=$((start + round))
  if ! LIGHTCAST_FUZZ_CASES=$cases LIGHTCAST_FUZZ_SEED=$seed "$binary" fuzz --test-threads 1 --nocapture >"$log" 2>&1; then
    status="FAILED in round $round (LIGHTCAST_FUZZ_SEED=$seed)"
    break
  fi
  while read -r target n; do
    total[$target]=$(( ${total[$target]:-0} + n ))
  done < <(sed -n 's/.*fuzz target \([a-z-]*\): \([0-9]*\) cases.*/\1 \2/p' "$log")
  minute=$(( ($(date +%s) - start) / 60 ))
  if [ "$minute" != "${shown:-}" ]; then
    shown=$minute
    echo "fuzz: $minute min, $round round(s) passed" >&2
  fi
done
elapsed=$(( $(date +%s) - start ))

{
  echo "# Fuzzing run, $(date -u +%Y-%m-%d)"
  echo
  echo "Command: \`bench/fuzz.sh $minutes $cases\` on $(nproc) cores ($(uname -m)), commit $commit (the fuzzed code)."
  echo "Result: **$status** after $round round(s), $((elapsed / 60)) min $((elapsed % 60)) s."
  echo
  echo "| target | cases run | crashes or panics |"
  echo "|---|---|---|"
  grand=0
  for target in $(printf '%s\n' "${!total[@]}" | sort); do
    echo "| \`$target\` | ${total[$target]} | 0 |"
    grand=$((grand + total[$target]))
  done
  echo "| all | $grand | $([ "$status" = passed ] && echo 0 || echo 1) |"
  if [ "$status" != passed ]; then
    echo; echo '```'; tail -n 60 "$log"; echo '```'
  fi
} > "$report"
echo "fuzz: $status; report in $report" >&2
[ "$status" = passed ]
