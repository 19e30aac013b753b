#!/usr/bin/env bash
# Issue 36, thin raster passes: the G-buffer rasterised whole (44 bytes a pixel from the
# rasteriser) against the visibility buffer (12 bytes a pixel) and its compute resolve, in one
# run: `lightcast-server bench` twice on the same scene, size and a small BRSM configuration
# (the G-buffer does not depend on the method), with --visibility-buffer on and off. Prints a
# markdown report of the stage medians and ratios.
#
#   bench/visibility-buffer.sh [WIDTH HEIGHT [SCENE [FRAMES]]] > bench/results/<adapter>-visibility-buffer.md
#
# LIGHTCAST_SERVER_BIN names another server binary (bench/gpu-run.sh's kit).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
width="${1:-320}"
height="${2:-180}"
scene="${3:-procedural:cornell}"
frames="${4:-10}"
server="${LIGHTCAST_SERVER_BIN:-$root/target/release/lightcast-server}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for mode in thin fat; do
  extra=(--visibility-buffer on)
  [ "$mode" = fat ] && extra=(--visibility-buffer off)
  cmd=("$server" bench --gi brsm --scene "$scene" --width "$width" --height "$height"
    --rsm-sizes 64 --vals 256 --view-samples 16 --frames "$frames" --warmup 2
    --reference-spp 1 --json "$work/$mode.json" "${extra[@]}")
  echo "running: ${cmd[*]}" >&2
  echo "${cmd[*]}" >> "$work/commands.txt"
  "${cmd[@]}" > /dev/null
done
python3 - "$work" <<'PY'
import json, sys, pathlib
work = pathlib.Path(sys.argv[1])
runs = {m: json.loads((work / f"{m}.json").read_text()) for m in ("thin", "fat")}
thin, fat = runs["thin"], runs["fat"]
print(f"Adapter: {thin['adapter']}; timing: {thin['timing_source']}; scene {thin['scene']} "
      f"({thin['triangles']} triangles), {thin['width']}×{thin['height']}, BRSM, "
      f"{thin['frames']} timed frames each.")
print()
print("Commands:")
print()
print("```")
print((work / "commands.txt").read_text().strip())
print("```")
print()
# The BRSM row (the sweep measures LightSkin at the same RSM size first).
row = lambda run: next(r for r in run["rows"] if r["method"] == "brsm")
stage = lambda run, name: row(run)["stages"].get(name, {}).get("median_ms", 0.0)
print("| stage (median ms) | visibility buffer | every target rasterised | ratio |")
print("|---|---|---|---|")
for name in ("gbuffer", "gbuffer_resolve", "rsm", "shadow_map", "direct_light"):
    a, b = stage(thin, name), stage(fat, name)
    ratio = f"{a / b:.2f}" if b else "—"
    print(f"| {name} | {a:.3f} | {b:.3f} | {ratio} |")
g = stage(thin, "gbuffer") + stage(thin, "gbuffer_resolve")
print(f"| gbuffer + gbuffer_resolve | {g:.3f} | {stage(fat, 'gbuffer'):.3f} | "
      f"{g / stage(fat, 'gbuffer'):.2f} |")
a, b = row(thin)["frame"]["median_ms"], row(fat)["frame"]["median_ms"]
print(f"| frame | {a:.3f} | {b:.3f} | {a / b:.2f} |")
PY
