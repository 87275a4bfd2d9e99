#!/usr/bin/env bash
# Fuzzes softshell's readers and its classify pipeline with libFuzzer
# (docs/robustness.md, "Fuzzing").
#
#   scripts/fuzz.sh [SECONDS] [HARNESS ...]
#
# SECONDS (default 60) per harness; harnesses: nrrd metaimage raw nifti vti kretz dicom classify
# (default all). In the checking build (scripts/common.sh build_sanitized:
# clang, ASan + UBSan): the test suite writes the seed corpora
# (tests/test_fuzz_inputs.cpp), every file of tests/data/repro is run once
# through each harness as a regression input, then each harness fuzzes for
# SECONDS from its seeds and its own corpus (kept in build-asan/fuzz-corpus,
# so later runs go on from there). A crash, leak, timeout or broken
# invariant stops the script (exit 1) with the input saved in
# build-asan/fuzz-artifacts/. Prints executions, coverage and speed per
# harness. Runs under `nice -n 10`; FUZZ_JOBS=N runs N processes per harness.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

seconds="${1:-60}"
shift || true
harnesses=("$@")
[ ${#harnesses[@]} -eq 0 ] && harnesses=(nrrd metaimage raw nifti vti kretz dicom classify)
case "$seconds" in '' | *[!0-9]*) log "usage: scripts/fuzz.sh [SECONDS] [HARNESS ...]"; exit 2 ;; esac

install_deps
build_sanitized
sanitizer_env
export SOFTSHELL_DEVICE="${SOFTSHELL_DEVICE:-cpu}"

seeds="$ASAN_BUILD_DIR/fuzz-seeds"
corpus="$ASAN_BUILD_DIR/fuzz-corpus"
artifacts="$ASAN_BUILD_DIR/fuzz-artifacts"
mkdir -p "$seeds" "$corpus" "$artifacts"
log "writing the seed corpora (the test suite's FuzzSeeds test) to $seeds"
SOFTSHELL_FUZZ_SEEDS="$seeds" "$ASAN_BUILD_DIR/tests/softshell_tests" --gtest_filter='FuzzSeeds.*' >"$seeds/log.txt" 2>&1 || {
  tail -n 30 "$seeds/log.txt" >&2
  exit 1
}

summary="$ASAN_BUILD_DIR/fuzz-summary.txt"
: >"$summary"
for h in "${harnesses[@]}"; do
  exe="$ASAN_BUILD_DIR/fuzz/fuzz_$h"
  [ -x "$exe" ] || { log "no harness $h (expected $exe)"; exit 2; }
  # The pipeline harness runs OpenCL kernels: fewer bytes matter (dims <= 8)
  # and an input may take longer.
  max_len=65536 timeout=20
  [ "$h" = classify ] && max_len=2096 timeout=60
  mkdir -p "$corpus/$h"
  log "$h: the regression inputs of tests/data/repro"
  nice -n 10 "$exe" -timeout="$timeout" -rss_limit_mb=2560 -artifact_prefix="$artifacts/$h-regression-" "$ROOT"/tests/data/repro/* \
    >"$ASAN_BUILD_DIR/fuzz-$h-regression.log" 2>&1 || {
    tail -n 40 "$ASAN_BUILD_DIR/fuzz-$h-regression.log" >&2
    log "$h: a regression input failed"
    exit 1
  }
  log "$h: fuzzing for $seconds s"
  jobs=()
  [ -n "${FUZZ_JOBS:-}" ] && jobs=(-jobs="$FUZZ_JOBS" -workers="$FUZZ_JOBS")
  # The harness saves an input that breaks an invariant itself as well
  # (fuzz/fuzz_inputs.cpp, fail()): PoCL's LLVM replaces libFuzzer's
  # SIGABRT handler.
  if ! SOFTSHELL_FUZZ_ARTIFACT="$artifacts/$h-" nice -n 10 "$exe" "$corpus/$h" "$seeds/$h" -max_total_time="$seconds" -max_len="$max_len" \
    -timeout="$timeout" -rss_limit_mb=2560 -print_final_stats=1 -artifact_prefix="$artifacts/$h-" "${jobs[@]}" \
    >"$ASAN_BUILD_DIR/fuzz-$h.log" 2>&1; then
    tail -n 60 "$ASAN_BUILD_DIR/fuzz-$h.log" >&2
    log "$h: failed; the input is in $artifacts"
    exit 1
  fi
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$ASAN_BUILD_DIR/fuzz-$h.log" | grep -o '[0-9]*$' | tail -1)
  speed=$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$ASAN_BUILD_DIR/fuzz-$h.log" | grep -o '[0-9]*$' | tail -1)
  last=$(grep -E '^#[0-9]+' "$ASAN_BUILD_DIR/fuzz-$h.log" | tail -1)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")
  units=$(find "$corpus/$h" -type f | wc -l)
  printf '%-10s %12s executions in %6s s (%s/s), coverage %s edges, %s features, corpus %s\n' \
    "$h" "${runs:-?}" "$seconds" "${speed:-?}" "${cov:-?}" "${ft:-?}" "$units" | tee -a "$summary" >&2
done
log "summary in $summary"
