#!/usr/bin/env bash
# The Python MES example on user scenes (inspectd --scene-dir), not built-in specimens: a 7 um
# step between two textured planes on a common tilt (0.3 deg x, 0.5 deg y), measured with the
# example's step recipe (7 +- 0.5 um, 2 um z steps) after the rig's z linearity is calibrated
# (uncalibrated, the +-1/2 step peak-locking bound makes U ~1 um on a step: NOT_DECIDABLE).
# Asserted: the conforming part (step 7.000 um) is OK and the part 1 um out of tolerance (step
# 8.000 um) NOT_OK, each with its value within U of the truth and 2U below the 1 um band.
#   mes_step_scenes_test.sh BIN_DIR
set -euo pipefail
bin="$(cd "$1" && pwd)"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
examples="$here/../../examples/python"
python=/usr/bin/python3  # Debian's, with python3-grpcio
work="$(mktemp -d)"
srv_log="$work/inspectd.log"
pid=""
cleanup() { [[ -n "$pid" ]] && kill "$pid" 2>/dev/null && wait "$pid" 2>/dev/null; rm -rf "$work"; }
trap cleanup EXIT
fail() { echo "FAIL: $*"; echo "--- inspectd log"; tail -n 30 "$srv_log" || true; exit 1; }
# shellcheck source=../lib/poll.sh
source "$here/../lib/poll.sh"  # wait_for

"$python" -c 'import grpc' 2>/dev/null || { echo "SKIP: python3-grpcio is not installed"; exit 77; }
bash "$examples/generate_stubs.sh" "$work/stubs" >/dev/null
"$python" "$here/write_step_scenes.py" "$work/scenes" 320x240 0.74 good=7.0 bad=8.0

"$bin/inspectd" --listen 127.0.0.1:0 --data-dir "$work/data" --camera-size 320x240 --scene-dir "$work/scenes" \
  >"$srv_log" 2>&1 &
pid=$!
wait_for "inspectd to listen" 60 grep -q "inspectd listening on" "$srv_log"
addr="$(sed -n 's/^inspectd listening on \([^ ]*\).*/\1/p' "$srv_log" | head -n1)"

# The z-linearity step of the calibration (docs/uncertainty.md): U from the rig's measured error.
"$bin/inspectctl" --server "$addr" -q calibrate --step z-linearity >/dev/null || fail "calibrate z-linearity failed"

out="$("$python" "$examples/mes_client.py" --server "$addr" --stubs "$work/stubs" \
  --recipe "$examples/recipe_step.json" --out "$work/reports" --station line-3 \
  --part P-GOOD=good --part P-BAD=bad 2>&1)" || fail "mes_client exited $?: $out"
echo "$out"
for expect in "P-GOOD=OK" "P-BAD=NOT_OK"; do
  grep -q "^verdicts: .*\b$expect\b" <<<"$out" || fail "expected $expect"
done
# Each part's value within its U of the truth, and U sharp enough to decide a +-0.5 um band.
check_part() {  # part, true step
  local line value u
  line="$(grep -A1 "part=$1 " <<<"$out" | tail -n1)"
  value="$(sed -n 's/.*shoulder: \([0-9.]*\) um U \([0-9.e-]*\),.*/\1/p' <<<"$line")"
  u="$(sed -n 's/.*shoulder: \([0-9.]*\) um U \([0-9.e-]*\),.*/\2/p' <<<"$line")"
  [[ -n "$value" && -n "$u" ]] || fail "no value for $1 in '$line'"
  awk -v v="$value" -v u="$u" -v t="$2" 'BEGIN { d = v - t; if (d < 0) d = -d; exit !(d <= u && 2 * u < 1.0) }' ||
    fail "$1: step $value um U $u against the truth $2 um"
  echo "$1: step $value um, U $u um, truth $2 um"
}
check_part P-GOOD 7.0
check_part P-BAD 8.0
echo "PASS"
