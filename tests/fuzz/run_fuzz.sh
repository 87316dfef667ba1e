#!/usr/bin/env bash
# Builds the libFuzzer targets with clang (-fsanitize=fuzzer,address,undefined) and runs each for
# SECONDS (default 60) from its committed seed corpus (tests/fuzz/corpus/<target>/; new inputs
# go to a scratch folder, the committed seeds stay as they are). Then every committed crash
# reproducer in tests/fuzz/regressions/<target>/ is replayed. Prints one line per target:
# executions, new corpus inputs, crashes; exits 1 if any target crashed.
#   tests/fuzz/run_fuzz.sh [SECONDS]        env: FUZZ_BUILD_DIR (default build-fuzz), JOBS (2)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$here"
secs="${1:-60}"
build="${FUZZ_BUILD_DIR:-build-fuzz}"
targets=(fuzz_stack_manifest fuzz_png_frame_decode fuzz_rig_config fuzz_access_policy fuzz_request_validators fuzz_recipe_document)

export CCACHE_BASEDIR="$here"
CC=clang-15 CXX=clang++-15 cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DINSPECT_FUZZ=ON -DINSPECT_BUILD_BENCH=OFF \
  >"$build.configure.log" 2>&1 || { cat "$build.configure.log"; exit 1; }
cmake --build "$build" -j "${JOBS:-2}" --target "${targets[@]}"

scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
failed=0
printf '%-22s %12s %8s %8s\n' target executions corpus crashes
for t in "${targets[@]}"; do
  mkdir -p "$scratch/$t/corpus" "$scratch/$t/crashes"
  log="$scratch/$t/log"
  rc=0
  ASAN_OPTIONS=detect_leaks=1 "$build/fuzz/$t" -max_total_time="$secs" -print_final_stats=1 -timeout=10 \
    -rss_limit_mb=2048 -artifact_prefix="$scratch/$t/crashes/" "$scratch/$t/corpus" "tests/fuzz/corpus/$t" \
    >"$log" 2>&1 || rc=$?
  execs="$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n1)"
  crashes="$(find "$scratch/$t/crashes" -type f | wc -l)"
  printf '%-22s %12s %8s %8s\n' "$t" "${execs:-?}" "$(find "$scratch/$t/corpus" -type f | wc -l)" "$crashes"
  if ((rc != 0 || crashes > 0)); then
    failed=1
    tail -n 40 "$log"
    mkdir -p "tests/fuzz/regressions/$t"
    cp "$scratch/$t/crashes/"* "tests/fuzz/regressions/$t/" 2>/dev/null || true
    echo "reproducers copied to tests/fuzz/regressions/$t/ (commit them with the fix)"
  fi
  if [[ -d "tests/fuzz/regressions/$t" ]] && compgen -G "tests/fuzz/regressions/$t/*" >/dev/null; then
    "$build/fuzz/$t" -runs=1 "tests/fuzz/regressions/$t/"* >"$scratch/$t/replay" 2>&1 ||
      { failed=1; echo "$t: a committed reproducer crashes again"; tail -n 20 "$scratch/$t/replay"; }
  fi
done
exit "$failed"
