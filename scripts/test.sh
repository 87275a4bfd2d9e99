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
ctest --output-on-failure -j "$(nproc)" "$@"
