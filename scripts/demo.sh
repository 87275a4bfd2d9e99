#!/usr/bin/env bash
# The front door: installs, builds, runs softshell on a built-in test volume
# and on the real spine ultrasound in ../shared/data/plus-spine, and writes
# the outputs (volumes, reports, pictures) under out/.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

install_deps
build_release
ss="$BUILD_DIR/host/softshell"
out="$ROOT/out"
mkdir -p "$out"

log "OpenCL devices"
"$ss" devices

log "built-in input: a speckled sphere (96^3)"
"$ss" synthetic --size 96 --seed 1 -o "$out/synthetic.nrrd"
"$ss" info "$out/synthetic.nrrd" | tee "$out/synthetic-info.txt"
"$ss" lowpass "$out/synthetic.nrrd" --sigma 1.5 -o "$out/synthetic-lowpass.nrrd"
"$ss" slices "$out/synthetic.nrrd" "$out/synthetic-lowpass.nrrd" --height 192 -o "$out/synthetic-slices.png"

spine="$ROOT/../shared/data/plus-spine/SpinePhantomFreehandReconstructed.mha"
if [ -f "$spine" ]; then
  log "real 3D ultrasound: PLUS spine phantom"
  "$ss" info "$spine" | tee "$out/spine-info.txt"
  "$ss" lowpass "$spine" --sigma 1.0 -o "$out/spine-lowpass.nrrd"
  "$ss" slices "$spine" "$out/spine-lowpass.nrrd" --height 256 -o "$out/spine-slices.png"
else
  log "skipping the real spine volume: $spine not found"
fi

log "done; outputs in $out:"
ls -1 "$out" >&2
