#!/usr/bin/env bash
# Issue 36, thin raster passes: the G-buffer and the RSM rasterised whole (44 and 56 bytes a
# texel from the rasteriser) against their visibility buffers (12 bytes a texel) and compute
# resolves, in one run: `lightcast-server bench` twice on the same scene and size under
# `rsm_gather` with one sample count and radius (neither raster depends on the method, and
# rsm_gather's gather is cheap at any RSM side; the RSM's side is RSM), with --visibility-buffer
# on and off. Prints a markdown report of the stage medians and ratios.
#
#   bench/visibility-buffer.sh [WIDTH HEIGHT [SCENE [FRAMES [RSM]]]] > bench/results/<adapter>-visibility-buffer.md
#
# LIGHTCAST_SERVER_BIN names another server binary (bench/gpu-run.sh's kit).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
width="${1:-320}"
height="${2:-180}"
scene="${3:-procedural:cornell}"
frames="${4:-10}"
rsm="${5:-256}"
server="${LIGHTCAST_SERVER_BIN:-$root/target/release/lightcast-server}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for mode in thin fat; do
  extra=(--visibility-buffer on)
  [ "$mode" = fat ] && extra=(--visibility-buffer off)
  cmd=("$server" bench --gi rsm_gather --scene "$scene" --width "$width" --height "$height"
    --gi-param rsm_size="$rsm" --gather-samples 16 --gather-radii 10 --frames "$frames" --warmup 2
    --reference-spp 1 --json "$work/$mode.json" "${extra[@]}")
  echo "running: ${cmd[*]}" >&2
  echo "${cmd[*]}" >> "$work/commands.txt"
  "${cmd[@]}" > /dev/null
done
python3 - "$work" <<'PY'
import json, sys, pathlib
work = pathlib.Path(sys.argv[1])
runs = {m: json.loads((work / f"{m}.json").read_text()) for m in ("thin", "fat")}
row = lambda run: run["rows"][0]
thin, fat = runs["thin"], runs["fat"]
print(f"Adapter: {thin['adapter']}; timing: {thin['timing_source']}; scene {thin['scene']} "
      f"({thin['triangles']} triangles), {thin['width']}×{thin['height']}, rsm_gather with an RSM "
      f"of {row(thin)['params'].get('rsm_size', '?')}² a face, {thin['frames']} timed frames each.")
print()
print("Commands:")
print()
print("```")
print((work / "commands.txt").read_text().strip())
print("```")
print()
stage = lambda run, name: row(run)["stages"].get(name, {}).get("median_ms", 0.0)
print("| stage (median ms) | visibility buffer | every target rasterised | ratio |")
print("|---|---|---|---|")
for name in ("gbuffer", "gbuffer_resolve", "rsm", "rsm_resolve", "shadow_map", "direct_light"):
    a, b = stage(thin, name), stage(fat, name)
    ratio = f"{a / b:.2f}" if b else "—"
    print(f"| {name} | {a:.3f} | {b:.3f} | {ratio} |")
for raster in ("gbuffer", "rsm"):
    t, f = stage(thin, raster) + stage(thin, raster + "_resolve"), stage(fat, raster)
    ratio = f"{t / f:.2f}" if f else "—"
    print(f"| {raster} + {raster}_resolve | {t:.3f} | {f:.3f} | {ratio} |")
a, b = row(thin)["frame"]["median_ms"], row(fat)["frame"]["median_ms"]
print(f"| frame | {a:.3f} | {b:.3f} | {a / b:.2f} |")
PY
