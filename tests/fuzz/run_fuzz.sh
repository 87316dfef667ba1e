#!/usr/bin/env bash
# Builds the libFuzzer targets with clang (-fsanitize=fuzzer,address,undefined) and runs each for
# SECONDS (default 60) from its committed corpus (tests/fuzz/corpus/<target>/). New inputs go to a
# scratch folder; afterwards the committed corpus and the new inputs are merged with -merge=1 into
# a fresh folder (minimised: only inputs that add coverage, each at most FUZZ_MAX_LEN bytes) which
# replaces tests/fuzz/corpus/<target>/ when it stays within FUZZ_CORPUS_MAX_KB (commit the change;
# ctest's fuzz_replay_<target> replays it in every build). Then every committed crash reproducer in
# tests/fuzz/regressions/<target>/ is replayed. Prints one line per target: executions, corpus
# files before and after the merge, crashes; exits 1 if any target crashed. JOBS targets fuzz at
# a time (one process each), each for the full SECONDS.
#   tests/fuzz/run_fuzz.sh [SECONDS]    env: FUZZ_BUILD_DIR (default build-fuzz), JOBS (2),
#                                       FUZZ_MAX_LEN (4096), FUZZ_CORPUS_MAX_KB (256 per target),
#                                       FUZZ_MERGE=0 leaves the committed corpora untouched
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$here"
secs="${1:-60}"
max_len="${FUZZ_MAX_LEN:-4096}"
max_kb="${FUZZ_CORPUS_MAX_KB:-256}"
build="${FUZZ_BUILD_DIR:-build-fuzz}"
targets=(fuzz_stack_manifest fuzz_png_frame_decode fuzz_rig_config fuzz_access_policy fuzz_request_validators fuzz_recipe_document)

export CCACHE_BASEDIR="$here" CCACHE_NOHASHDIR=1  # as deploy/dev.sh: keys without the checkout's path
CC=clang-15 CXX=clang++-15 cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DINSPECT_FUZZ=ON -DINSPECT_BUILD_BENCH=OFF \
  >"$build.configure.log" 2>&1 || { cat "$build.configure.log"; exit 1; }
cmake --build "$build" -j "${JOBS:-2}" --target "${targets[@]}"

scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
# One target: fuzz, merge, replay its reproducers. Its report goes to $scratch/$t/report (printed
# in target order once all have run) and its status to $scratch/$t/status.
run_target() {
  local t="$1" status=0 rc before after execs crashes log
  {
    mkdir -p "$scratch/$t/corpus" "$scratch/$t/crashes"
    log="$scratch/$t/log"
    rc=0
    mkdir -p "tests/fuzz/corpus/$t"
    before="$(find "tests/fuzz/corpus/$t" -type f | wc -l)"
    ASAN_OPTIONS=detect_leaks=1 "$build/fuzz/$t" -max_total_time="$secs" -print_final_stats=1 -timeout=10 \
      -rss_limit_mb=2048 -max_len="$max_len" -artifact_prefix="$scratch/$t/crashes/" \
      "$scratch/$t/corpus" "tests/fuzz/corpus/$t" >"$log" 2>&1 || rc=$?
    execs="$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n1)"
    crashes="$(find "$scratch/$t/crashes" -type f | wc -l)"
    after="$before"
    if ((rc == 0 && crashes == 0)) && [[ "${FUZZ_MERGE:-1}" != 0 ]]; then
      # Minimise the committed corpus together with the new inputs into a fresh folder.
      mkdir -p "$scratch/$t/merged"
      if ASAN_OPTIONS=detect_leaks=1 "$build/fuzz/$t" -merge=1 -max_len="$max_len" -timeout=10 -rss_limit_mb=2048 \
           "$scratch/$t/merged" "tests/fuzz/corpus/$t" "$scratch/$t/corpus" >"$scratch/$t/merge.log" 2>&1; then
        kb="$(du -sk --apparent-size "$scratch/$t/merged" | cut -f1)"
        if ((kb <= max_kb)) && compgen -G "$scratch/$t/merged/*" >/dev/null; then
          rm -f "tests/fuzz/corpus/$t/"*
          cp "$scratch/$t/merged/"* "tests/fuzz/corpus/$t/"
          after="$(find "tests/fuzz/corpus/$t" -type f | wc -l)"
        else
          echo "$t: merged corpus is $kb KiB, above FUZZ_CORPUS_MAX_KB=$max_kb; committed corpus kept"
        fi
      else
        echo "$t: corpus merge failed, committed corpus kept"; tail -n 20 "$scratch/$t/merge.log"
      fi
    fi
    printf '%-24s %12s %8s %8s %8s\n' "$t" "${execs:-?}" "$before" "$after" "$crashes"
    if ((rc != 0 || crashes > 0)); then
      status=1
      tail -n 40 "$log"
      mkdir -p "tests/fuzz/regressions/$t"
      cp "$scratch/$t/crashes/"* "tests/fuzz/regressions/$t/" 2>/dev/null || true
      echo "reproducers copied to tests/fuzz/regressions/$t/ (commit them with the fix)"
    fi
    if [[ -d "tests/fuzz/regressions/$t" ]] && compgen -G "tests/fuzz/regressions/$t/*" >/dev/null; then
      "$build/fuzz/$t" -runs=1 "tests/fuzz/regressions/$t/"* >"$scratch/$t/replay" 2>&1 ||
        { status=1; echo "$t: a committed reproducer crashes again"; tail -n 20 "$scratch/$t/replay"; }
    fi
  } >"$scratch/$t/report" 2>&1
  echo "$status" >"$scratch/$t/status"
}

# JOBS targets at a time (each fuzzer is one process): the same seconds per target in a fraction
# of the wall time.
printf '%-24s %12s %8s %8s %8s\n' target executions before after crashes
running=0
for t in "${targets[@]}"; do
  mkdir -p "$scratch/$t"
  run_target "$t" &
  running=$((running + 1))
  if ((running >= ${JOBS:-2})); then
    wait -n || true
    running=$((running - 1))
  fi
done
wait
failed=0
for t in "${targets[@]}"; do
  cat "$scratch/$t/report"
  [[ "$(cat "$scratch/$t/status" 2>/dev/null)" == 0 ]] || failed=1
done
exit "$failed"
