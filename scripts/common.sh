# Shared by scripts/test.sh, demo.sh, sanitize.sh and fuzz.sh: dependency
# install and builds. Source it; it defines ROOT, BUILD_DIR, ASAN_BUILD_DIR,
# install_deps, build_release, build_sanitized and sanitizer_env.

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD_DIR="${SOFTSHELL_BUILD_DIR:-$ROOT/build}"
# The checking build: clang, AddressSanitizer + UndefinedBehaviorSanitizer,
# libFuzzer harnesses (docs/robustness.md).
ASAN_BUILD_DIR="${SOFTSHELL_ASAN_BUILD_DIR:-$ROOT/build-asan}"

# Debian 12 packages: compiler and CMake are assumed present; everything else
# is installed here. Viewer and test-display packages are included so the
# optional parts build and the GL tests can run under Xvfb; clang with its
# sanitizer and libFuzzer runtimes (libclang-rt-dev) and llvm (for
# llvm-symbolizer's readable reports) for the checking build.
SOFTSHELL_PACKAGES=(
  pkg-config
  ocl-icd-opencl-dev opencl-headers opencl-clhpp-headers pocl-opencl-icd clinfo
  libteem-dev zlib1g-dev libbz2-dev libpng-dev libnifti2-dev libgdcm-dev
  libcli11-dev libgtest-dev libeigen3-dev
  libglfw3-dev libglm-dev libgl-dev
  libepoxy-dev libimgui-dev libstb-dev fonts-dejavu-core
  libvolpack1-dev
  xvfb xauth
  clang libclang-rt-dev llvm
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

# build_release [TARGET...]: configures and builds everything, or only the
# given targets (the demo builds `softshell` alone, not the tests and
# benchmarks it never runs).
build_release() {
  local targets=()
  [ $# -gt 0 ] && targets=(--target "$@")
  log "configuring and building (Release${1:+: $*}) in $BUILD_DIR"
  cmake -S "$ROOT" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release >/dev/null
  if ! cmake --build "$BUILD_DIR" -j "$(nproc)" "${targets[@]}" >"$BUILD_DIR/build.log" 2>&1; then
    log "build failed; the end of $BUILD_DIR/build.log:"
    tail -n 60 "$BUILD_DIR/build.log" >&2
    return 1
  fi
}

build_sanitized() {
  log "configuring and building (clang, ASan + UBSan, libFuzzer harnesses) in $ASAN_BUILD_DIR"
  mkdir -p "$ASAN_BUILD_DIR"
  CC=clang CXX=clang++ cmake -S "$ROOT" -B "$ASAN_BUILD_DIR" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DSOFTSHELL_SANITIZE=ON -DSOFTSHELL_FUZZ=ON -DSOFTSHELL_BUILD_BENCH=OFF >/dev/null
  if ! cmake --build "$ASAN_BUILD_DIR" -j "$(nproc)" >"$ASAN_BUILD_DIR/build.log" 2>&1; then
    log "sanitizer build failed; the end of $ASAN_BUILD_DIR/build.log:"
    tail -n 60 "$ASAN_BUILD_DIR/build.log" >&2
    return 1
  fi
}

# Sanitizer settings for the checking build: every report stops the program
# (a test then fails); leaks are checked, with suppressions only for the
# OpenCL / GL driver stacks (scripts/sanitizer/lsan.supp says why each).
#
# intercept_tls_get_addr=0: up to LLVM 16 (Debian 12 has clang 14) the
# runtime's __tls_get_addr interceptor takes a dynamic TLS block whose start
# lies 16 bytes past a page boundary for a pre-2.25 glibc block with a header
# and reads the two words before it as the block's bounds. With glibc 2.36
# that header does not exist; a malloc'd block lands there by chance (PoCL
# and Mesa are dlopen'ed and use dynamic TLS), and LeakSanitizer's
# stop-the-world tracer then scans a garbage range at exit and dies ("Tracer
# caught signal 11") or hangs: the sanitized suite failed 5 tests so once,
# and a child that had answered in 0.05 s hung at exit once. Without the
# interceptor LSan still scans every thread's static TLS and stack and the
# heap; blocks only referenced from dlopen'ed libraries' dynamic TLS would
# show as leaks, and none do.
sanitizer_env() {
  export ASAN_OPTIONS="detect_leaks=1:abort_on_error=1:halt_on_error=1:strict_string_checks=1:check_initialization_order=1:intercept_tls_get_addr=0${ASAN_OPTIONS:+:$ASAN_OPTIONS}"
  export LSAN_OPTIONS="suppressions=$ROOT/scripts/sanitizer/lsan.supp:print_suppressions=0${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
  export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}"
  local symbolizer
  symbolizer="$(command -v llvm-symbolizer || true)"
  [ -n "$symbolizer" ] && export ASAN_SYMBOLIZER_PATH="$symbolizer"
  # Shared objects stay loaded until exit, so LSan sees what Mesa's unloaded
  # driver still references (scripts/sanitizer/keep_modules.c says why).
  local keep="$ASAN_BUILD_DIR/keep_modules.so"
  if [ ! -e "$keep" ] || [ "$ROOT/scripts/sanitizer/keep_modules.c" -nt "$keep" ]; then
    cc -shared -fPIC -O2 -o "$keep" "$ROOT/scripts/sanitizer/keep_modules.c"
  fi
  export LD_PRELOAD="$keep${LD_PRELOAD:+:$LD_PRELOAD}"
  return 0
}
