#!/usr/bin/env bash
# One entry point for a fresh Debian 12 machine (README.md "Quick start"):
#   deploy/dev.sh demo   install what is missing of its short package list (demo_packages), build
#                        only inspectd and inspectctl (build-demo/),
#                        start inspectd on the simulated rig with a shiny specimen (cutter),
#                        calibrate, scan under the default AUTO illumination with a recipe, and
#                        print the mode chosen and why, the valid pixels, the error against the
#                        simulated ground truth, the verdict, the files and the report
#   deploy/dev.sh test   install what is missing of the whole list (packages), build, run the
#                        whole test suite, run every
#                        libFuzzer target for FUZZ_SECONDS from its committed corpus (merged back,
#                        minimised, into tests/fuzz/corpus/), then build and run the unit tests
#                        again under AddressSanitizer + UBSan. With CI=true a test that cannot run
#                        fails instead of skipping.
# Environment: BUILD_DIR (default build), JOBS (default 2), SKIP_SANITIZERS=1 to skip the
# sanitizer pass, FUZZ_SECONDS (default 30 per target; 0 skips fuzzing), DEMO_OUT (default
# out/scan-<time>), DEMO_DATA (the demo server's data directory, default DEMO_OUT/server-data).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
mode="${1:-}"
jobs="${JOBS:-2}"
build="${BUILD_DIR:-build}"

# Every Debian package the project builds, tests or runs with. README.md and docs/ point here for the list.
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
  postgresql libpq-dev  # server/storage: the PostgreSQL backend (pool, site) and its tests' private server
  zlib1g-dev  # core/io/depth_export: crc32 of the PNG chunks (OpenSSL EVP from libssl-dev: the x3p MD5)
  prometheus chromium chromium-driver python3-selenium  # tests/ops: real Prometheus scrape, dashboard in Chromium
  clang-15  # tests/fuzz: libFuzzer targets (-fsanitize=fuzzer,address,undefined)
  libomp-15-dev  # tests/fuzz: clang links LibRaw's OpenMP (libraw_r.pc -fopenmp) against libomp
  libopencv-contrib-dev  # core/sff/dense_depth.cc: cv::ximgproc fast global smoother (dense depth)
  libmosquitto-dev mosquitto mosquitto-clients  # server/plant: MQTT publishing; its tests run a real broker and mosquitto_sub
  openssl  # tests/opcua/make_certs.sh: the OPC UA gateway test's certificates (the gateway itself: Node.js 20 + npm ci)
  libraw-dev  # core/io/raw_frame_decode: camera RAW stack frames (DNG, CR2, NEF, ARW, ...) through LibRaw
  libboost-math-dev  # core/metrology/capability: Student t quantiles of the Type-1 study's bias test
  prometheus-cpp-dev  # server/http/metrics_registry: the /metrics families and their text exposition
)

# What `demo` needs, and no more: configuring with INSPECT_BUILD_TESTS=OFF INSPECT_BUILD_BENCH=OFF
# (what CMakeLists.txt then requires), building inspectd and inspectctl, and running them on the
# simulated rig. No test-only package (GoogleTest, benchmark, PostgreSQL server, mosquitto broker,
# Prometheus, Chromium, gwyddion, clang, umockdev, kubectl).
demo_packages=(
  build-essential cmake pkg-config
  python3  # cmake/check_rooms.py: the room check every configuration defines
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  libopencv-dev libeigen3-dev libsuitesparse-dev  # core (libopencv-dev brings the contrib ximgproc)
  libaravis-dev libusb-1.0-0-dev  # devices/: the real drivers are built in the demo too (see demo())
  libspdlog-dev libcli11-dev nlohmann-json3-dev libtiff-dev libzip-dev libsqlite3-dev libssl-dev
  libdeflate-dev zlib1g-dev libraw-dev libboost-math-dev  # core/io: RAW frames; core/metrology: t quantiles
  libcpp-httplib-dev libpq-dev libmosquitto-dev prometheus-cpp-dev  # server/: HTTP port, PostgreSQL client, MQTT, metrics
)

install_missing() {  # packages...: installs those not yet installed
  local missing=()
  for p in "$@"; do
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

# ccache keys without the checkout's path: CCACHE_BASEDIR makes the paths relative, and
# CCACHE_NOHASHDIR leaves the working directory out of the key (with -g1 ccache hashes it by
# default), so a second checkout, a worktree, CI's fresh clone and the image build
# (deploy/Containerfile) reuse each other's objects. The debug info then names the directory of
# whichever build compiled the object first; nothing reads it.
ccache_env() {
  export CCACHE_BASEDIR="$here" CCACHE_NOHASHDIR=1
}

configure_and_build() {  # dir, extra cmake args...
  local dir="$1"; shift
  ccache_env
  cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG" "$@" >"$dir.configure.log" 2>&1 ||
    { cat "$dir.configure.log"; exit 1; }
  cmake --build "$dir" -j "$jobs"
}

demo() {
  # Only what the demo runs (inspectd, inspectctl): no tests, no benchmarks, in its own build
  # folder so that `test`'s build keeps every target. The real drivers stay in: switching them off
  # saves 2 of the 145 objects but changes a public definition, and then no object of the demo
  # build would be a ccache hit for `deploy/dev.sh test`.
  local dir="$build-demo"
  ccache_env
  cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG" \
    -DINSPECT_BUILD_TESTS=OFF -DINSPECT_BUILD_BENCH=OFF >"$dir.configure.log" 2>&1 ||
    { cat "$dir.configure.log"; exit 1; }
  cmake --build "$dir" -j "$jobs" --target inspectd inspectctl
  local out="${DEMO_OUT:-$here/out/scan-$(date +%Y%m%d-%H%M%S)}"
  local data="${DEMO_DATA:-$out/server-data}"
  mkdir -p "$out"
  local log="$out/inspectd.log"
  # The cutter: a ground rake face with polished glints and a polished land that saturate the
  # camera under uniform light, the case AUTO illumination is for.
  "$dir/bin/inspectd" --listen 127.0.0.1:0 --data-dir "$data" --specimen cutter >"$log" 2>&1 &
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
  local ctl=("$dir/bin/inspectctl" --server "$addr")
  "${ctl[@]}" status
  echo "== calibration: the steps AUTO's modes need (HF+ADAPT, ADAPT, TEXTURE)"
  "${ctl[@]}" calibrate --step camera-response --step projector-response --step geometry --step psf \
    --step scatter-matrix --label demo >"$out/calibrate.txt" || { cat "$out/calibrate.txt"; exit 1; }
  grep -E '^(job|calibration:) ' "$out/calibrate.txt"
  echo "(progress and every calibration figure: $out/calibrate.txt)"
  echo "== scan: default illumination (AUTO), with a recipe that measures the rake face's tilt"
  # The rake face is the left 55 % of the field, tilted 3 degrees (devices/sim/specimen.cc).
  cat >"$out/recipe.json" <<'JSON'
{"recipe_id": "demo-cutter", "description": "Cutter rake face tilt 3 +- 0.5 deg on 90 % of the face",
 "scan": {},
 "measurements": [{"name": "rake_tilt", "parameter": "tilt",
   "roi": {"shape": "SHAPE_RECTANGLE", "x": 40, "y": 40, "width": 480, "height": 680},
   "tolerance": {"nominal": 3.0, "lower": -0.5, "upper": 0.5, "min_coverage_percent": 90}}]}
JSON
  "${ctl[@]}" recipe get demo-cutter >/dev/null 2>&1 ||  # a DEMO_DATA of an earlier run has it
    "${ctl[@]}" recipe create "$out/recipe.json" >/dev/null
  "${ctl[@]}" scan --recipe demo-cutter --out "$out" >"$out/scan.txt" || { cat "$out/scan.txt"; exit 1; }
  echo "== summary"
  # What was measured and how well: the mode AUTO chose and why, the valid pixels, the error
  # against the simulated rig's ground truth (computed by the server), the recipe's verdict.
  grep -E '^(illumination|depth|vs ground truth|inspection|  rake_tilt)' "$out/scan.txt"
  echo "files in $out: $(cd "$out" && ls -d -- *.tiff *.png 2>/dev/null | tr '\n' ' ')"
  echo "report: $out/report.html (open it in a browser)"
  echo "server log: $log; server data directory: $data"
}

# CI (CI=true, or INSPECT_REQUIRE_ALL_TESTS=1 by hand): a test that cannot run fails instead of
# skipping (tests/CMakeLists.txt, tests/lib/skip_or_fail.h), and ctest's summary must report no
# test as skipped or "Not Run".
require_all=OFF
[[ "${CI:-}" == true || "${INSPECT_REQUIRE_ALL_TESTS:-0}" == 1 ]] && require_all=ON

ctest_counting_skips() {  # dir, ctest args...: runs ctest, prints the skip count, fails on a skip in CI
  local dir="$1"; shift
  local log="$dir/ctest-summary.log" rc=0
  (cd "$dir" && ctest --output-on-failure -j "$jobs" "$@") 2>&1 | tee "$log" || rc=$?
  local skipped
  local status_line='^ *[0-9]+/[0-9]+ Test +#[0-9]+: .*\*\*\*(Skipped|Not Run)'
  # A DISABLED_ gtest (an opt-in timing run) is ctest's "Not Run (Disabled)": deliberate, not a skip.
  skipped="$(grep -E "$status_line" "$log" | grep -vc "(Disabled)" || true)"
  echo "== ctest in $dir: $skipped skipped / not run"
  if [[ $require_all == ON && $skipped != 0 ]]; then
    grep -E "$status_line" "$log" | grep -v "(Disabled)"
    echo "FAIL: CI requires every test to run"
    return 1
  fi
  return "$rc"
}

# The OPC UA gateway's packages (gateway/opcua/package-lock.json) from the npm registry with the
# machine's Node.js 20; again only when the lock file changed since the last install.
npm_ci_gateway() {
  local dir="$here/gateway/opcua" stamp="$here/gateway/opcua/node_modules/.lock-sha256"
  local sum
  sum="$(sha256sum "$dir/package-lock.json" | cut -d' ' -f1)"
  [[ -f "$stamp" && "$(cat "$stamp")" == "$sum" ]] && return 0
  echo "== npm ci in gateway/opcua"
  (cd "$dir" && npm ci --no-audit --no-fund --loglevel=error) && echo "$sum" >"$stamp"
}

test_all() {
  npm_ci_gateway
  configure_and_build "$build" -DINSPECT_REQUIRE_ALL_TESTS=$require_all
  ctest_counting_skips "$build" --timeout 600
  if [[ "${FUZZ_SECONDS:-30}" != 0 ]]; then
    echo "== libFuzzer targets, ${FUZZ_SECONDS:-30} s each"
    FUZZ_BUILD_DIR="$build-fuzz" JOBS="$jobs" tests/fuzz/run_fuzz.sh "${FUZZ_SECONDS:-30}"
  fi
  if [[ "${SKIP_SANITIZERS:-0}" != 1 ]]; then
    echo "== AddressSanitizer + UndefinedBehaviorSanitizer build"
    # -O1 -g1: sanitizers need no more, and the build stays quick on two cores.
    configure_and_build "$build-asan" -DINSPECT_SANITIZE=ON -DINSPECT_BUILD_BENCH=OFF \
      -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG="-O1 -g1" -DINSPECT_REQUIRE_ALL_TESTS=$require_all
    ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
      ctest_counting_skips "$build-asan" --timeout 900 -LE nosanitize
  fi
}

case "$mode" in
  demo) install_missing "${demo_packages[@]}"; demo ;;
  test)
    # deploy/validate_manifests.sh (ctest deploy_manifests) needs kubectl kustomize. Debian's
    # kubernetes-client ships /usr/bin/kubectl and conflicts with an upstream kubectl package, so
    # it is installed only when no kubectl is on PATH.
    extra=()
    command -v kubectl >/dev/null || extra=(kubernetes-client)
    install_missing "${packages[@]}" "${extra[@]}"
    test_all
    ;;
  *) echo "usage: $0 demo|test" >&2; exit 2 ;;
esac
