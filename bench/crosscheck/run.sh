#!/bin/bash
# The cross-check on the independent simulator (docs/crosscheck.md).
# Usage: bench/crosscheck/run.sh SOFTSHELL OUTDIR [TAG [CLASSIFY_ARGS...]]
#   Simulates head, bone and cyst scans, seeds 1-12 (training: where the Levoy
#   baseline's isovalue is chosen) and 13-36 (held out), once (kept in OUTDIR);
#   classifies each with SOFTSHELL's defaults (or CLASSIFY_ARGS), evaluates it
#   against the truth, runs the baseline, and prints the tables
#   (OUTDIR/report-TAG.md). Needs python3-numpy and python3-scipy. About 5
#   minutes on 2 cores. SEEDS_TRAIN / SEEDS_TEST in the environment override
#   the seeds ("1 2 3").
set -eu
S=$(realpath "$1"); O=$2; TAG=${3:-defaults}; shift $(( $# < 3 ? $# : 3 ))
H=$(cd "$(dirname "$0")" && pwd)
TRAIN=${SEEDS_TRAIN:-$(seq -s' ' 1 12)}; TEST=${SEEDS_TEST:-$(seq -s' ' 13 36)}
PY=${PYTHON:-python3}  # Debian's python3 with python3-numpy and python3-scipy
export POCL_CACHE_DIR=${POCL_CACHE_DIR:-/tmp/softshell-pocl-cache}
mkdir -p "$O"
cases() { for sh in head bone cyst; do for s in $TRAIN $TEST; do echo "$sh $s"; done; done; }
echo "simulating (once) ..." >&2
cases | xargs -P2 -n2 sh -c '[ -f "'"$O"'/$0$1/volume.nrrd" ] || "'"$PY"'" "'"$H"'/indsim.py" $0 $1 "'"$O"'/$0$1" > /dev/null'
echo "classifying and evaluating ($TAG) ..." >&2
ARGS="$*"
# A case that fails (classify or evaluate) is named and scored as nothing drawn; the others go on.
cases | xargs -P2 -n2 sh -c 'd="'"$O"'/$0$1"; rm -f "$d/ev_'"$TAG"'.json"; { "'"$S"'" classify "$d/volume.nrrd" -o "$d/u_'"$TAG"'.nrrd" --iso auto -q '"$ARGS"' && "'"$S"'" evaluate --json "$d/u_'"$TAG"'.nrrd" "$d/truth_sdf.nrrd" > "$d/ev_'"$TAG"'.json.part" && mv "$d/ev_'"$TAG"'.json.part" "$d/ev_'"$TAG"'.json"; } || echo "$0$1 failed ('"$TAG"'): scored as nothing drawn" >&2'
LV=$(seq -s, 0.15 0.05 0.80)
if [ ! -f "$O/baseline.done" ]; then
  echo "baseline: lowpass 1 mm + Levoy at $LV on the training seeds ..." >&2
  for sh in head bone cyst; do for s in $TRAIN; do echo "$sh $s"; done; done | xargs -P2 -n2 sh -c 'd="'"$O"'/$0$1"; "'"$PY"'" "'"$H"'/levoy.py" "$d" '"$LV"' && for f in "$d"/u_lv*.nrrd; do t=$(basename "$f" .nrrd); "'"$S"'" evaluate --json "$f" "$d/truth_sdf.nrrd" > "$d/ev_${t#u_}.json"; rm "$f"; done'
  "$PY" "$H/report.py" choose "$O" "$TRAIN" > "$O/baseline.txt"
  while read -r sh t _; do for s in $TEST; do echo "$sh $s $t"; done; done < "$O/baseline.txt" | xargs -P2 -n3 sh -c 'd="'"$O"'/$0$1"; "'"$PY"'" "'"$H"'/levoy.py" "$d" $2 && "'"$S"'" evaluate --json "$d/u_lv$2.nrrd" "$d/truth_sdf.nrrd" > "$d/ev_lv$2.json"; rm "$d/u_lv$2.nrrd"'
  touch "$O/baseline.done"
fi
"$PY" "$H/report.py" table "$O" "$TEST" "$TAG" | tee "$O/report-$TAG.md"
