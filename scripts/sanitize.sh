#!/usr/bin/env bash
# The checking build: softshell's core, CLI, viewer and every test built by
# clang with AddressSanitizer and UndefinedBehaviorSanitizer (and libFuzzer's
# coverage hooks, so scripts/fuzz.sh shares it), and the whole test suite on
# it. Any sanitizer report fails its test. .ci/run runs this after
# scripts/test.sh; docs/robustness.md says what is checked and what is
# suppressed.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

install_deps
build_sanitized
sanitizer_env
export SOFTSHELL_DEVICE="${SOFTSHELL_DEVICE:-cpu}"
cd "$ASAN_BUILD_DIR"
if [ -z "${DISPLAY:-}" ] && command -v xvfb-run >/dev/null 2>&1; then
  xvfb-run -a -s "-screen 0 1280x1024x24" ctest --output-on-failure -j "$(nproc)" "$@"
else
  ctest --output-on-failure -j "$(nproc)" "$@"
fi
