#!/usr/bin/env bash
# One entry point for a fresh Debian 12 machine (README "Quick start"):
#   deploy/dev.sh demo   install what is missing, build, start inspectd on the simulated rig,
#                        scan, write the depth map files and print where they are
#   deploy/dev.sh test   install what is missing, build, run the whole test suite, run every
#                        libFuzzer target for FUZZ_SECONDS from its seed corpus, then build and
#                        run the unit tests again under AddressSanitizer + UBSan
# Environment: BUILD_DIR (default build), JOBS (default 2), SKIP_SANITIZERS=1 to skip the
# sanitizer pass, FUZZ_SECONDS (default 30 per target; 0 skips fuzzing), DEMO_OUT (default
# out/scan-<time>).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
mode="${1:-}"
jobs="${JOBS:-2}"
build="${BUILD_DIR:-build}"

# Every Debian package the project builds, tests or runs with. Keep in sync with README.
packages=(
  build-essential cmake pkg-config ccache git
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  libopencv-dev libeigen3-dev libsuitesparse-dev
  libaravis-dev aravis-tools aravis-tools-cli libusb-1.0-0-dev umockdev
  libspdlog-dev libgtest-dev libgmock-dev libbenchmark-dev
  libcli11-dev nlohmann-json3-dev libtiff-dev libzip-dev libsqlite3-dev libssl-dev
  libdeflate-dev  # core/png_frame_decode: the stack frames' PNG fast path
  gwyddion  # a real x3p reader: tests open our x3p with gwyddion-thumbnailer
  python3 python3-yaml  # deploy/validate_manifests.sh, tests/fault/kill9_test.sh (Debian's /usr/bin/python3)
  python3-grpcio python3-protobuf  # examples/python: the MES client (tests/mes)
  libcpp-httplib-dev  # inspectd's HTTP port: /metrics and the dashboard
  prometheus-cpp-dev  # server/http/metrics_registry: the /metrics registry and its text exposition
  zlib1g-dev  # core/io/depth_export: crc32 of the PNG chunks (OpenSSL EVP from libssl-dev: the x3p MD5)
  prometheus chromium chromium-driver python3-selenium  # tests/ops: real Prometheus scrape, dashboard in Chromium
  clang-15  # tests/fuzz: libFuzzer targets (-fsanitize=fuzzer,address,undefined)
)

install_missing() {
  local missing=()
  for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if ((${#missing[@]})); then
    echo "== installing: ${missing[*]}"
    local sudo=""
    [[ $(id -u) -ne 0 ]] && sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
  fi
}

configure_and_build() {  # dir, extra cmake args...
  local dir="$1"; shift
  export CCACHE_BASEDIR="$here"
  cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG" "$@" >"$dir.configure.log" 2>&1 ||
    { cat "$dir.configure.log"; exit 1; }
  cmake --build "$dir" -j "$jobs"
}

demo() {
  configure_and_build "$build"
  local data="${DEMO_DATA:-$here/data}"
  local out="${DEMO_OUT:-$here/out/scan-$(date +%Y%m%d-%H%M%S)}"
  local log
  log="$(mktemp)"
  "$build/bin/inspectd" --listen 127.0.0.1:0 --data-dir "$data" >"$log" 2>&1 &
  pid=$!  # global: the EXIT trap runs after this function returned
  trap 'kill $pid 2>/dev/null; wait $pid 2>/dev/null || true' EXIT
  local addr=""
  for _ in $(seq 1 100); do  # the server prints its address once it listens
    addr="$(sed -n 's/^inspectd listening on //p' "$log" | head -n1)"
    [[ -n "$addr" ]] && break
    kill -0 $pid 2>/dev/null || { cat "$log"; exit 1; }
    sleep 0.1
  done
  [[ -n "$addr" ]] || { echo "inspectd did not start"; cat "$log"; exit 1; }
  "$build/bin/inspectctl" --server "$addr" status
  "$build/bin/inspectctl" --server "$addr" scan --out "$out"
  echo "depth map files written to: $out"
  ls -l "$out"
}

test_all() {
  configure_and_build "$build"
  (cd "$build" && ctest --output-on-failure -j "$jobs" --timeout 600)
  if [[ "${FUZZ_SECONDS:-30}" != 0 ]]; then
    echo "== libFuzzer targets, ${FUZZ_SECONDS:-30} s each"
    FUZZ_BUILD_DIR="$build-fuzz" JOBS="$jobs" tests/fuzz/run_fuzz.sh "${FUZZ_SECONDS:-30}"
  fi
  if [[ "${SKIP_SANITIZERS:-0}" != 1 ]]; then
    echo "== AddressSanitizer + UndefinedBehaviorSanitizer build"
    # -O1 -g1: sanitizers need no more, and the build stays quick on two cores.
    configure_and_build "$build-asan" -DINSPECT_SANITIZE=ON -DINSPECT_BUILD_BENCH=OFF \
      -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG="-O1 -g1"
    (cd "$build-asan" && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
      ctest --output-on-failure -j "$jobs" --timeout 900 -LE nosanitize)
  fi
}

case "$mode" in
  demo) install_missing; demo ;;
  test) install_missing; test_all ;;
  *) echo "usage: $0 demo|test" >&2; exit 2 ;;
esac
