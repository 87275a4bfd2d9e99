#!/bin/bash
# The five real volumes, five ways: splats (u > 0.2) in the first 8 mm below
# the skin line (first nonzero sample along the beam) / splats over the
# voxels the default mask calls scanned (splat count).
# docs/real-data.md, "The five real volumes with every default".
# Usage: bench/real_volumes/table.sh SOFTSHELL PLUS_SPINE_DIR OUTDIR
set -u
S=$1; D=$2; O=$3; H=$(dirname "$0"); mkdir -p "$O"
echo "| volume | beam | echo crest, near field kept | before (--reverb keep --small-volume 0) | today's defaults | Levoy | Slicer-style ramp |"
echo "|---|---|---|---|---|---|---|"
for f in SpinePhantomFreehandReconstructed vtkVolumeReconstructorTestNNMEANvolumeRef vtkVolumeReconstructorTestLNMAXIvolumeRef vtkVolumeReconstructorTestLNMEANvolumeRef vtkVolumeReconstructorTestIMLiFvolumeRef; do
  in=$D/$f.mha; beam=2; [[ $f == *IMLiF* ]] && beam=1
  $S classify $in --iso auto-ridge --near-field keep --reverb keep --small-volume 0 -o $O/$f-earlier.nrrd > $O/$f-earlier.txt 2>&1
  $S classify $in --iso auto --reverb keep --small-volume 0 -o $O/$f-before.nrrd > $O/$f-before.txt 2>&1
  $S classify $in --iso auto -o $O/$f-today.nrrd > $O/$f-today.txt 2>&1
  $S classify $in --method levoy --iso auto --sigma 1 -o $O/$f-levoy.nrrd > $O/$f-levoy.txt 2>&1
  $S classify $in --method levoy --iso auto-edge --sigma 1 --near-field keep --reverb keep --small-volume 0 -o $O/$f-edge.nrrd > $O/$f-edge.txt 2>&1
  iso=$(grep -o "iso [0-9.]*" $O/$f-edge.txt | head -1 | cut -d' ' -f2)
  $S lowpass $in --sigma 1 -o $O/$f-lp.nrrd > /dev/null
  python3 $H/ramp.py $in $O/$f-lp.nrrd $iso $O/$f-slicer.nrrd > $O/$f-slicer.txt
  dims=$(grep -o "volume   [0-9x]*" $O/$f-today.txt | head -1 | awk '{print $2}' | tr x ' ')
  total=$(echo $dims | awk '{print $1*$2*$3}')
  uns=$(grep -o "auto: [0-9]* voxels unscanned" $O/$f-today.txt | awk '{print $2}')
  row="| $f | $(echo xyz | cut -c$((beam+1))) |"
  for m in earlier before today levoy slicer; do
    row="$row $(python3 $H/measure.py $in $O/$f-$m.nrrd $beam $((total-uns))) |"
  done
  echo "$row"
done
