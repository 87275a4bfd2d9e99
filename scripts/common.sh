# Shared by scripts/test.sh and scripts/demo.sh: dependency install and build.
# Source it; it defines ROOT, BUILD_DIR, install_deps and build_release.

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD_DIR="${SOFTSHELL_BUILD_DIR:-$ROOT/build}"

# Debian 12 packages: compiler and CMake are assumed present; everything else
# is installed here. Viewer and test-display packages are included so the
# optional parts build and the GL tests can run under Xvfb.
SOFTSHELL_PACKAGES=(
  pkg-config
  ocl-icd-opencl-dev opencl-headers opencl-clhpp-headers pocl-opencl-icd clinfo
  libteem-dev zlib1g-dev libbz2-dev libpng-dev
  libcli11-dev libgtest-dev libeigen3-dev
  libglfw3-dev libglm-dev libgl-dev
  libepoxy-dev libimgui-dev libstb-dev
  libvolpack1-dev
  xvfb xauth
)

log() { printf 'softshell: %s\n' "$*" >&2; }

install_deps() {
  local missing=() p
  for p in "${SOFTSHELL_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  local sudo=()
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then sudo=(sudo -n); else
      log "missing packages: ${missing[*]}; run as root or install them with apt-get"; return 2
    fi
  fi
  log "installing Debian packages: ${missing[*]}"
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq >/dev/null
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
    -o Dpkg::Use-Pty=0 "${missing[@]}" >/dev/null
}

build_release() {
  log "configuring and building (Release) in $BUILD_DIR"
  cmake -S "$ROOT" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release >/dev/null
  if ! cmake --build "$BUILD_DIR" -j "$(nproc)" >"$BUILD_DIR/build.log" 2>&1; then
    log "build failed; the end of $BUILD_DIR/build.log:"
    tail -n 60 "$BUILD_DIR/build.log" >&2
    return 1
  fi
}
