#!/usr/bin/env bash
# The front door: installs, builds, and runs softshell's main job on a built-in
# fetal-face phantom (simulated B-mode ultrasound with ground truth) and on the
# real spine ultrasound shipped in data/plus-spine (data/README.md); writes
# volumes, reports and pictures under out/ and ends with an index of them.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

install_deps
build_release softshell  # the one program the demo runs: no tests, no benchmarks
ss="$BUILD_DIR/host/softshell"
out="$ROOT/out"
mkdir -p "$out"
start="$out/.demo-start"  # the index lists what is newer: this run's files only
touch "$start"

log "OpenCL devices"
"$ss" devices

log "built-in input: a fetal-face phantom, 96^3, with its true surfaces"
"$ss" phantom --shape face --size 96 --seed 1 -o "$out/face" --slices "$out/face-slices.png"
"$ss" info "$out/face/volume.nrrd" > "$out/face-info.txt"

# The variational classifier with every default, the isovalue included
# (`--iso auto`: the crest of the boundary echoes, docs/parameters.md); Levoy
# near its best setting of docs/baselines.md (lowpass 1.5 voxels, thickness 2,
# iso 0.8 of the way from the fluid to the tissue median; the study's tuned
# rows use the true surface's median, which a user does not have).
json="$out/face/phantom.json"
median() { sed -n "s/.*\"$1\": *\([0-9.]*\).*/\1/p" "$json" | head -n 1; }
levoy_iso=$(awk -v f="$(median fluid_median)" -v t="$(median tissue_median)" 'BEGIN { printf "%.0f", f + 0.8 * (t - f) }')
spacing=$(sed -n 's/.*"spacing_mm": *\([0-9.]*\).*/\1/p' "$json" | head -n 1)
sigma=$(awk -v h="${spacing:-1}" 'BEGIN { printf "%.3f", 1.5 * h }')
log "classifying: variational (defaults, --iso auto) and Levoy (iso $levoy_iso, lowpassed by 1.5 voxels)"
"$ss" classify "$out/face/volume.nrrd" --method levoy --iso "$levoy_iso" --sigma "$sigma" --thickness 2 \
  -o "$out/face-levoy.nrrd"
"$ss" classify "$out/face/volume.nrrd" --iso auto --stats -o "$out/face-variational.nrrd"
for m in levoy variational; do
  "$ss" evaluate "$out/face-$m.nrrd" "$out/face/truth_sdf.nrrd" | tee "$out/face-$m-metrics.txt"
done
"$ss" slices "$out/face/volume.nrrd" "$out/face-levoy.nrrd" "$out/face-variational.nrrd" --height 192 \
  --labels "B-mode input (face phantom),Levoy's classifier (lowpassed 1.5 voxels),variational classifier (defaults)" \
  -o "$out/face-classified.png"
log "the paper's Figure 2 on a slice of the face"
"$ss" figure2 "$out/face/volume.nrrd" --iso auto -o "$out/face-figure2.png"

# Shipped in data/ (data/README.md); ../shared/data beside the tree as a fallback.
spine="$ROOT/data/plus-spine/SpinePhantomFreehandReconstructed.mha"
[ -f "$spine" ] || spine="$ROOT/../shared/data/plus-spine/SpinePhantomFreehandReconstructed.mha"
if [ -f "$spine" ]; then
  log "real 3D ultrasound: PLUS spine phantom"
  "$ss" info "$spine" > "$out/spine-info.txt"
  "$ss" lowpass "$spine" --sigma 1.0 -o "$out/spine-lowpass.nrrd"
  "$ss" slices "$spine" "$out/spine-lowpass.nrrd" --height 256 \
    --labels "PLUS spine phantom sweep (real 3D ultrasound),lowpassed" -o "$out/spine-slices.png"
  # The defaults, no per-volume flag: unscanned voxels (the zero fill around
  # the sweep) are masked, the bright near-field band under the probe is held
  # at u = 0, and the isovalue follows the local brightness
  # (docs/real-data.md, docs/parameters.md).
  "$ss" classify "$spine" --iso auto -o "$out/spine-variational.nrrd"
  "$ss" classify "$spine" --method levoy --iso auto --sigma 1.0 -o "$out/spine-levoy.nrrd"
  "$ss" figure2 "$spine" --iso auto -o "$out/spine-figure2.png"
else
  log "skipping the real spine volume: $spine not found"
fi

# Oriented splatting (paper Section 4): headless renders of the classified
# volumes; under Xvfb when there is no display (docs/rendering.md).
gl=()
if [ -z "${DISPLAY:-}" ] && command -v xvfb-run >/dev/null 2>&1; then gl=(xvfb-run -a); fi
if "$ss" render --help >/dev/null 2>&1; then
  log "oriented splats of the classified face (the paper's Figure 1 right and Figure 3)"
  # The crop drops the uterine wall behind the head (z > 84 % of the depth).
  crop=0,1,0,1,0,0.84
  "${gl[@]}" "$ss" render "$out/face-variational.nrrd" --view -30,10 --crop "$crop" --size 600x600 \
    -o "$out/render-face-oriented.png"
  "${gl[@]}" "$ss" render "$out/face-variational.nrrd" --view -30,10 --crop "$crop" --size 600x600 \
    --method isosplat -o "$out/render-face-isotropic.png"
  "${gl[@]}" "$ss" render "$out/face-variational.nrrd" --view 0,0 --size 400x400 --benchmark 20 \
    -o "$out/render-face-front.png"
  # The face preset: colour by depth, splats oriented by the B-mode data
  # (docs/rendering.md, "Orientation by the data").
  "${gl[@]}" "$ss" render "$out/face-variational.nrrd" --volume "$out/face/volume.nrrd" --preset face \
    --view -30,10 --crop "$crop" --size 600x600 -o "$out/render-face-preset.png"
  mkdir -p "$out/turntable"
  "${gl[@]}" "$ss" render "$out/face-variational.nrrd" --view 0,10 --crop "$crop" --size 200x200 --turntable 12 \
    -q -o "$out/turntable/face-%03d.png"
  if [ -f "$out/spine-variational.nrrd" ]; then
    log "oriented splats of the real spine (classified with the defaults, --iso auto)"
    "${gl[@]}" "$ss" render "$out/spine-variational.nrrd" --view 0,35 --size 800x500 -o "$out/render-spine.png"
  fi
  if [ -n "${DISPLAY:-}" ] && [ -t 1 ]; then
    log "opening the viewer on the face (Esc quits)"
    "$ss" view "$out/face-variational.nrrd" --view -30,10 --crop "$crop" || true
  fi
else
  log "skipping rendering: softshell was built without the viewer (SOFTSHELL_BUILD_VIEWER=OFF)"
fi

# Marching Cubes on the classified face (docs/renderers.md): a binary PLY for MeshLab or
# ParaView, at the splats' epsilon.
log "Marching Cubes mesh of the classified face"
"$ss" mesh "$out/face-variational.nrrd" --level 0.2 -o "$out/face-mesh.ply"

# The paper's Figures 5 and 6 (docs/renderers.md): ray casting before / after classification, and
# ray casting, Marching Cubes, shear-warp, oriented splats of the same classified volume.
# A real-spine row below the face when the spine is there (its own view, no crop).
if "$ss" figure6 --help >/dev/null 2>&1; then
  face_row=(--view -30,10 --crop "$crop")
  if [ -f "$out/spine-variational.nrrd" ]; then
    log "the paper's Figures 5 and 6: the face and the real spine"
    rows=(--view -30,10 --view 0,35 --crop "$crop" --crop 0,1,0,1,0,1)
    "${gl[@]}" "$ss" figure5 "$out/face/volume.nrrd" "$spine" --iso auto "${rows[@]}" \
      --labels "face phantom (simulated),PLUS spine phantom (real 3D ultrasound)" -o "$out/figure5.png"
    "${gl[@]}" "$ss" figure6 "$out/face-variational.nrrd" "$out/spine-variational.nrrd" "${rows[@]}" \
      --labels "face phantom (simulated; the defaults),PLUS spine phantom (real 3D ultrasound; the same defaults)" \
      -o "$out/figure6.png"
  else
    log "the paper's Figures 5 and 6 on the face"
    "${gl[@]}" "$ss" figure5 "$out/face/volume.nrrd" --iso auto "${face_row[@]}" -o "$out/figure5.png"
    "${gl[@]}" "$ss" figure6 "$out/face-variational.nrrd" "${face_row[@]}" -o "$out/figure6.png"
  fi
fi

# An index of what this run wrote: every file under out/ newer than the
# start of the run, with its size and what it is; also saved as out/INDEX.txt.
describe() {
  case "$1" in
    face/volume.nrrd) echo "phantom: simulated B-mode volume (uint8)" ;;
    face/truth_sdf.nrrd) echo "phantom: true signed distance to the tissue boundary (voxels)" ;;
    face/labels.nrrd) echo "phantom: tissue labels" ;;
    face/phantom.json) echo "phantom: parameters and grey-level medians" ;;
    face-slices.png) echo "phantom mid-slices, true boundary in orange" ;;
    *-info.txt) echo "softshell info: dims, spacing, value range, histogram" ;;
    *-levoy.nrrd) echo "opacity, Levoy's isovalue-contour classifier" ;;
    *-variational.nrrd) echo "opacity, the variational classifier (defaults, --iso auto)" ;;
    *-metrics.txt) echo "evaluate: precision, recall, blobs, normal error against the truth" ;;
    *-classified.png) echo "mid-slices: input | Levoy | variational" ;;
    *-figure2.png) echo "the paper's Figure 2 on one slice" ;;
    spine-lowpass.nrrd) echo "the spine lowpassed (sigma 1 mm)" ;;
    spine-slices.png) echo "mid-slices of the spine, raw and lowpassed" ;;
    render-*-oriented.png) echo "oriented splats (the paper's renderer)" ;;
    render-*-isotropic.png) echo "isotropic splats, for comparison" ;;
    render-face-preset.png) echo "oriented splats, the face preset (depth colour, oriented by the data)" ;;
    render-*.png) echo "oriented splats" ;;
    turntable/*) echo "turntable frame (oriented splats)" ;;
    *.ply) echo "Marching Cubes mesh of the opacity at 0.2 (binary PLY)" ;;
    figure5*.png) echo "the paper's Figure 5: ray casting before / after classification" ;;
    figure6*.png) echo "the paper's Figure 6: ray casting, Marching Cubes, shear-warp, splats" ;;
    INDEX.txt) echo "this index" ;;
    *) echo "" ;;
  esac
}
{
  printf 'softshell demo outputs in %s\n\n' "$out"
  turntable=0
  while IFS= read -r f; do
    case "$f" in
      turntable/*) turntable=$((turntable + 1)); [ "$turntable" -gt 1 ] && continue ;;
    esac
    printf '  %-36s %9s  %s\n' "$f" "$(du -h "$out/$f" | cut -f1)" "$(describe "$f")"
  done < <(cd "$out" && find . -type f -newer "$start" ! -name INDEX.txt | sed 's|^\./||' | LC_ALL=C sort)
  [ "$turntable" -gt 1 ] && printf '  %-36s %9s  %s\n' "turntable/ ($turntable frames)" "" "one frame listed above"
} > "$out/INDEX.txt"
log "done; what this run wrote:"
cat "$out/INDEX.txt" >&2
