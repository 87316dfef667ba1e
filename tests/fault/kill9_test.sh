#!/usr/bin/env bash
# Fault test: inspectd is killed with SIGKILL during a scan, during a stack upload and during a
# download; after each restart the interrupted jobs end FAILED with ABORTED, no partial result is
# listed or served, downloads of finished artifacts still verify by sha256, and SQLite's
# PRAGMA integrity_check answers ok. Real binaries, real processes; waits poll a condition with a
# deadline (never a fixed sleep standing in for synchronisation).
#   kill9_test.sh BIN_DIR
set -euo pipefail
bin="$(cd "$1" && pwd)"
work="$(mktemp -d)"
data="$work/data"
srv_log="$work/inspectd.log"
pid=""
cleanup() { [[ -n "$pid" ]] && kill -9 "$pid" 2>/dev/null; rm -rf "$work"; }
trap cleanup EXIT
py=/usr/bin/python3

fail() { echo "FAIL: $*"; echo "--- inspectd log"; tail -n 30 "$srv_log" || true; exit 1; }

# shellcheck source=../lib/poll.sh
source "$(dirname "${BASH_SOURCE[0]}")/../lib/poll.sh"  # wait_for

start_server() {
  : >"$srv_log"
  "$bin/inspectd" --listen 127.0.0.1:0 --data-dir "$data" --camera-size 640x480 >"$srv_log" 2>&1 &
  pid=$!
  wait_for "inspectd to listen" 60 grep -q "inspectd listening on" "$srv_log"
  addr="$(sed -n 's/^inspectd listening on \([^ ]*\).*/\1/p' "$srv_log" | head -n1)"
}
kill_server() { kill -9 "$pid"; wait "$pid" 2>/dev/null || true; pid=""; }
ctl() { "$bin/inspectctl" --server "$addr" "$@"; }

# job_json ID: the job's JSON from `inspectctl --json jobs` (one line: {"jobs": [...]}).
job_json() {
  ctl --json jobs --limit 100 | $py -c "
import json,sys
for line in sys.stdin:
    for j in json.loads(line).get('jobs', []):
        if j.get('job_id') == sys.argv[1]: print(json.dumps(j))" "$1"
}

integrity() {
  $py -c "import sqlite3,sys; r=sqlite3.connect('$data/inspection.db').execute('PRAGMA integrity_check').fetchone()[0]; print(r); sys.exit(0 if r=='ok' else 1)"
}

check_aborted() {  # check_aborted JOB_ID WHAT
  local j state
  j="$(job_json "$1")"
  [[ -n "$j" ]] || fail "$2: job $1 is not listed after restart"
  state="$($py -c "import json,sys; j=json.loads(sys.argv[1]); print(j['state'], j.get('error_code', 0), len(j.get('result', {}).get('artifacts', [])))" "$j")"
  # Nothing partial is listed: a failed job has no artifacts.
  [[ "$state" == "JOB_STATE_FAILED 10 0" ]] ||
    fail "$2: job $1 is '$state' after restart, expected 'JOB_STATE_FAILED 10 0' (ABORTED, no artifacts)"
  echo "ok: $2: job $1 FAILED/ABORTED after restart, no artifacts"
}

first_job_id() { $py -c "
import json,sys
for line in open('$1'):
    try: o=json.loads(line)
    except Exception: continue
    j=o.get('event',{}).get('job_id') or o.get('job',{}).get('job_id')
    if j: print(j); break"; }
frames_seen() { $py -c "
import json,sys
n=0
for line in open('$1'):
    try: o=json.loads(line)
    except Exception: continue
    if o.get('event',{}).get('frame'): n+=1
sys.exit(0 if n>=$2 else 1)"; }

# --- 1. kill -9 during a scan
start_server
ctl --json scan --out "$work/scan1" >"$work/scan1.jsonl" 2>&1 &
cli=$!
wait_for "3 frame events of the scan" 120 frames_seen "$work/scan1.jsonl" 3
scan_job="$(first_job_id "$work/scan1.jsonl")"
[[ -n "$scan_job" ]] || fail "no job id in the scan's events"
kill_server
wait "$cli" && fail "inspectctl scan succeeded although the server died" || true
start_server
check_aborted "$scan_job" "scan"
integrity >/dev/null || fail "integrity_check after scan kill"

# A finished scan for the download case, and its stack for the upload case.
ctl --json scan --out "$work/scan2" --export ply >"$work/scan2.jsonl" || fail "second scan failed"
done_job="$(first_job_id "$work/scan2.jsonl")"

# --- 2. kill -9 during an upload: a stack big enough that the upload takes a while
$py - "$work/big" <<'PY'
import os, sys, json, zlib, struct
d = sys.argv[1]; os.makedirs(d)
def png(path, w, h, seed):
    # Incompressible grey PNG without numpy/opencv: random rows, zlib level 0.
    rnd = os.urandom(w * h)
    raw = b"".join(b"\x00" + rnd[y*w:(y+1)*w] for y in range(h))
    def chunk(t, b): return struct.pack(">I", len(b)) + t + b + struct.pack(">I", zlib.crc32(t + b) & 0xffffffff)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw, 0)) + chunk(b"IEND", b""))
frames = []
for k in range(40):
    name = "frame_%04d.png" % k
    png(os.path.join(d, name), 2048, 1536, k)
    frames.append({"file": name, "z_um": 5.0 * k})
json.dump({"format": "inspection-stack", "version": 1, "pixel_size_um": 1.0, "bit_depth": 8, "frames": frames},
          open(os.path.join(d, "stack.json"), "w"))
PY
uploads_busy() { [[ -n "$(find "$data/uploads" -type f -size +1M 2>/dev/null | head -n1)" ]]; }
ctl --json reconstruct --stack "$work/big" --out "$work/rec" >"$work/rec.jsonl" 2>&1 &
cli=$!
wait_for "upload bytes on the server" 120 uploads_busy
kill_server
wait "$cli" && fail "inspectctl reconstruct succeeded although the server died" || true
start_server
[[ -z "$(find "$data/uploads" -type f 2>/dev/null | head -n1)" ]] || fail "upload leftovers after restart"
upload_job="$(first_job_id "$work/rec.jsonl" || true)"
if [[ -n "$upload_job" ]]; then check_aborted "$upload_job" "upload"; else echo "ok: upload: killed before a job was created; no leftovers"; fi
integrity >/dev/null || fail "integrity_check after upload kill"

# --- 3. kill -9 during a download; the restarted server serves the same bytes (sha256 checked)
stack_art="$($py -c "
import json,sys
a=json.loads(sys.argv[1])['result']['artifacts']
z=[x for x in a if x['file_name']=='stack.zip']
print((z or a)[0]['artifact_id'])" "$(job_json "$done_job")")"
[[ -n "$stack_art" ]] || fail "no artifact to download"
ctl download "$stack_art" --out "$work/dl.bin" >/dev/null 2>&1 &
cli=$!
part_busy() { [[ -e "$work/dl.bin.part" || -e "$work/dl.bin" ]]; }
wait_for "the download to start" 60 part_busy
kill_server
wait "$cli" || true
start_server
ctl download "$stack_art" --out "$work/dl.bin" --resume >/dev/null || fail "resumed download after restart failed"
echo "ok: download: resumed after restart, sha256 verified by inspectctl"
check_aborted "$scan_job" "scan (after two more restarts)"
integrity >/dev/null || fail "integrity_check at the end"
echo "ok: PRAGMA integrity_check = ok after 3 kills"
echo "1 passed, 0 failed"
