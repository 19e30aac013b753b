# Shell functions of the bench scripts that run the service (sourced, not run).

# wait_ready URL PID LOG WHO: returns once the server PID answers URL/readyz (up to 120 s);
# else prints its LOG and exits, naming the script WHO.
wait_ready() {
  local url="$1" pid="$2" log="$3" who="$4"
  for _ in $(seq 600); do
    curl -fsS "$url/readyz" >/dev/null 2>&1 && return 0
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.2
  done
  cat "$log" >&2
  echo "$who: the server did not start" >&2
  exit 1
}

# warm_brsm URL: one small BRSM frame, which waits for the default scene's light caches, so
# that no measured run includes their build.
warm_brsm() {
  curl -fsS -o /dev/null -X POST "$1/v1/render" \
    -d '{"render": {"width": 64, "height": 36, "gi": {"method": "brsm"}}}'
}
