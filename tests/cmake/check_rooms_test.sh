#!/usr/bin/env bash
# cmake/check_rooms.py fails on what it must: an include of an undeclared room, another room's
# internal/ header, the generated API from a room without inspection_proto; and passes a tree
# that keeps to its declarations (transitive dependencies allowed).
#   check_rooms_test.sh PROJECT_SOURCE_DIR
set -euo pipefail
checker="$1/cmake/check_rooms.py"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
mkdir -p "$work/src/lo/internal" "$work/src/mid" "$work/src/hi"
cat >"$work/rooms.txt" <<'T'
lo=src/lo=
mid=src/mid=lo
hi=src/hi=mid,inspection_proto
T
echo '#pragma once' >"$work/src/lo/a.h"
echo '#pragma once' >"$work/src/lo/internal/k.h"
printf '#include "src/lo/a.h"\n#include "src/lo/internal/k.h"\n' >"$work/src/lo/a.cc"
echo '#include "src/lo/a.h"' >"$work/src/mid/m.h"
printf '#include "src/lo/a.h"\n#include "src/mid/m.h"\n#include "inspection/v1/inspection.pb.h"\n' >"$work/src/hi/h.cc"
python3 "$checker" "$work" "$work/rooms.txt" "$work/stamp" || fail "a clean tree was refused"

check_refused() {  # FILE CONTENT EXPECTED-TEXT
  local saved; saved="$(cat "$1")"
  echo "$2" >>"$1"
  local out rc=0
  out="$(python3 "$checker" "$work" "$work/rooms.txt" "$work/stamp" 2>&1)" || rc=$?
  printf '%s\n' "$saved" >"$1"
  [[ $rc -eq 1 ]] || fail "not refused: $2 in $1"
  grep -q "$3" <<<"$out" || fail "message for $2 does not say '$3': $out"
}
check_refused "$work/src/lo/a.cc" '#include "src/mid/m.h"' "lo includes src/mid/m.h of mid, not among its declared rooms"
check_refused "$work/src/mid/m.h" '#include "src/lo/internal/k.h"' "src/lo/internal/k.h is internal to lo"
check_refused "$work/src/mid/m.h" '#include "inspection/v1/inspection.pb.h"' "mid may not include the generated API"
check_refused "$work/src/mid/m.h" '#include "src/hi/x.h"' "not among its declared rooms"
echo "PASS: check_rooms.py refuses undeclared, internal and generated-API includes and passes a clean tree"
