#!/usr/bin/env bash
# GI time and error against the light count (issue 33, part 2): every method at one
# configuration, with the scene's first light split into 1, 2, 4, 8 and 16 lights of 1/N of
# its intensity (`bench --light-counts`), on the Cornell box and the street; each row's GI time
# over the same configuration's with one light in the same run. Seed 001 claims the surfels'
# GI cost hardly grows with the light count (light is gathered on surfels once per frame).
#
#   bench/light-counts.sh SERVER OUT_DIR PREFIX [--quick] [-- EXTRA BENCH FLAGS]
#
# Writes OUT_DIR/PREFIX-light-counts-{cornell,street}-{brsm,clustered,surfels,rsm_gather}.md
# (`brsm` rows include LightSkin at the same RSM size). PREFIX names the adapter (`lavapipe`,
# `gpu-h200`). --quick: tiny sizes and few frames (software adapters); its numbers are only
# ratios within one run. LIGHT_COUNT_SCENES and LIGHT_COUNT_METHODS (space-separated) narrow
# the runs (LightSkin's cache lighting grows with every light's RSM: on lavapipe the street at
# 16 lights takes minutes per frame).
set -euo pipefail
server="${1:?usage: $0 SERVER OUT_DIR PREFIX [--quick] [-- FLAGS]}"
out="${2:?usage: $0 SERVER OUT_DIR PREFIX [--quick] [-- FLAGS]}"
prefix="${3:?usage: $0 SERVER OUT_DIR PREFIX [--quick] [-- FLAGS]}"
shift 3
quick=false
if [ "${1:-}" = "--quick" ]; then quick=true; shift; fi
[ "${1:-}" = "--" ] && shift
mkdir -p "$out"
if $quick; then
  size=(--width 64 --height 48 --frames 6 --warmup 2 --reference-spp 64)
  rsm=128; vals=1024; surfels=2048
else
  size=(--width 1280 --height 720 --frames 30 --warmup 5 --reference-spp 256)
  rsm=1024; vals=4096; surfels=32768
fi
counts=1,2,4,8,16
declare -A sweeps=(
  [brsm]="--rsm-sizes $rsm --vals $vals --view-samples 256"
  [clustered]="--gi-param rsm_size=$rsm --sweep-vpls 1024 --sweep-clusters 30 --baseline-vpls 0"
  [surfels]="--gi-param surfel_count=$surfels --gi-param surfel_links=64 --sweep-surfels $surfels --sweep-links 64 --sweep-bands 3"
  [rsm_gather]="--gi-param rsm_size=$rsm --gather-samples 400 --gather-radii 100"
)
# cars=0: the street as it was before its parked car (issue 35), which the recorded results were
# measured on.
read -r -a scenes <<< "${LIGHT_COUNT_SCENES:-procedural:cornell procedural:street?blocks=4&cars=0}"
read -r -a methods <<< "${LIGHT_COUNT_METHODS:-brsm clustered surfels rsm_gather}"
for scene in "${scenes[@]}"; do
  name=$(case "$scene" in *cornell*) echo cornell ;; *) echo street ;; esac)
  for gi in "${methods[@]}"; do
    read -r -a flags <<< "${sweeps[$gi]}"
    cmd=("$server" bench --gi "$gi" --scene "$scene" "${size[@]}" "${flags[@]}"
      --light-counts "$counts" --markdown "$out/$prefix-light-counts-$name-$gi.md" "$@")
    echo "light-counts: ${cmd[*]}" >&2
    "${cmd[@]}"
    echo >> "$out/$prefix-light-counts-$name-$gi.md"
    echo "Command: \`${cmd[*]}\`" >> "$out/$prefix-light-counts-$name-$gi.md"
  done
done
