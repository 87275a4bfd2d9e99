#!/usr/bin/env bash
# Installs what softshell needs (Debian packages, as root), builds it in
# Release, and runs every test on PoCL's CPU OpenCL device.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

install_deps
build_release
# Tests run on the CPU through PoCL unless the caller chose a device.
export SOFTSHELL_DEVICE="${SOFTSHELL_DEVICE:-cpu}"
cd "$BUILD_DIR"
# The OpenGL tests (label gl) need an X server: without a display, run the
# whole suite under Xvfb (Mesa's llvmpipe then gives OpenGL 4.5 core). They
# fail rather than skip when no display can be had.
if [ -z "${DISPLAY:-}" ] && command -v xvfb-run >/dev/null 2>&1; then
  xvfb-run -a -s "-screen 0 1280x1024x24" ctest --output-on-failure -j "$(nproc)" "$@"
else
  ctest --output-on-failure -j "$(nproc)" "$@"
fi
