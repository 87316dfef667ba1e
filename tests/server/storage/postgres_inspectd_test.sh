#!/usr/bin/env bash
# inspectd on PostgreSQL end to end, with the real binaries and a real private PostgreSQL 15
# (initdb in a temporary folder, run as the postgres user: PostgreSQL refuses root):
#  1. the database is down when inspectd starts: inspectd waits with backoff (log lines say so;
#     its port answers health checks NOT_SERVING, nothing else), and listens once the database is
#     up (health SERVING);
#  2. a scan runs; its job is a row in PostgreSQL, not in a SQLite file;
#  3. inspectd restarted on the same database lists the job and serves its depth artifact;
#  4. a malformed URL is refused at start with exit 2 and a one-line message naming `database`;
#     the password never appears in inspectd's output.
# Waits poll a condition with a deadline.
#   postgres_inspectd_test.sh BIN_DIR
set -euo pipefail
bin="$(cd "$1" && pwd)"
pgbin=/usr/lib/postgresql/15/bin
work="$(mktemp -d /tmp/inspect-pgtest-XXXXXX)"
pid=""
fail() { echo "FAIL: $*"; echo "--- inspectd log"; tail -n 30 "$work/inspectd.log" 2>/dev/null || true; exit 1; }
[[ -x "$pgbin/initdb" ]] || fail "PostgreSQL 15 is not installed ($pgbin/initdb): apt-get install postgresql"
as_pg=()
[[ $(id -u) -eq 0 ]] && as_pg=(runuser -u postgres --)
cleanup() {
  [[ -n "$pid" ]] && kill -9 "$pid" 2>/dev/null
  "${as_pg[@]}" "$pgbin/pg_ctl" -D "$work/pg" -m immediate stop >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT
# shellcheck source=../../lib/poll.sh
source "$(dirname "${BASH_SOURCE[0]}")/../../lib/poll.sh"  # wait_for

password="pg-test-$RANDOM-secret"
echo "$password" >"$work/pw"
[[ $(id -u) -eq 0 ]] && chown -R postgres "$work"
"${as_pg[@]}" "$pgbin/initdb" -D "$work/pg" -U postgres -A scram-sha-256 --pwfile="$work/pw" --no-sync >"$work/initdb.log" 2>&1 ||
  fail "initdb: $(tail -n 3 "$work/initdb.log")"
port=$(/usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
start_pg() {
  "${as_pg[@]}" "$pgbin/pg_ctl" -D "$work/pg" -w -l "$work/pg.log" \
    -o "-k $work -p $port -c listen_addresses=127.0.0.1 -c fsync=off" start >/dev/null
}
url="postgresql://postgres@127.0.0.1:$port/postgres"
start_inspectd() {  # LOG
  "$bin/inspectd" --listen 127.0.0.1:0 --data-dir "$work/data" --camera-size 320x240 \
    --database "$url" --database-password-file "$work/pw" >"$1" 2>&1 &
  pid=$!
}
psql_q() { PGPASSWORD="$password" psql -h 127.0.0.1 -p "$port" -U postgres -d postgres -Atc "$1"; }

# 1. database down at start-up: inspectd waits with its health NOT_SERVING, then listens.
start_inspectd "$work/inspectd.log"
wait_for "inspectd to report the database down" 30 grep -q "retrying in" "$work/inspectd.log"
wait_for "inspectd's waiting health port" 30 grep -q "^inspectd health on .*: NOT_SERVING" "$work/inspectd.log"
! grep -q "inspectd listening on" "$work/inspectd.log" || fail "listened before its database was up"
kill -0 "$pid" || fail "inspectd exited instead of waiting for the database"
health_addr="$(sed -n 's/^inspectd health on \([^ ]*\): .*/\1/p' "$work/inspectd.log" | head -n1)"
for service in "" inspection.v1.InspectionService; do  # exit 4: NOT_SERVING (deploy/health_probe.cc)
  rc=0; "$bin/inspect-health-probe" --addr "$health_addr" --service "$service" --timeout 5 >"$work/probe.txt" 2>&1 || rc=$?
  [[ $rc -eq 4 ]] || fail "health '$service' while the database is down: probe exit $rc, expected 4 (NOT_SERVING): $(cat "$work/probe.txt")"
done
start_pg
wait_for "inspectd to listen once the database is up" 60 grep -q "inspectd listening on" "$work/inspectd.log"
addr="$(sed -n 's/^inspectd listening on \([^ ]*\).*/\1/p' "$work/inspectd.log" | head -n1)"
for service in "" inspection.v1.InspectionService; do
  rc=0; "$bin/inspect-health-probe" --addr "$addr" --service "$service" --timeout 5 >"$work/probe.txt" 2>&1 || rc=$?
  [[ $rc -eq 0 ]] || fail "health '$service' once the database is up: probe exit $rc, expected 0 (SERVING): $(cat "$work/probe.txt")"
done

# 2. a scan; its job is in PostgreSQL.
"$bin/inspectctl" --server "$addr" scan --out "$work/out" >"$work/scan.txt" 2>&1 || fail "scan: $(cat "$work/scan.txt")"
job="$(psql_q "SELECT job_id FROM jobs WHERE kind = 2")"  # JOB_KIND_SCAN
[[ "$job" == scan-* ]] || fail "no scan job row in PostgreSQL (got '$job')"
[[ "$(psql_q "SELECT state FROM jobs WHERE job_id = '$job'")" == 3 ]] || fail "job $job is not SUCCEEDED in the database"
[[ ! -e "$work/data/inspection.db" ]] || fail "a SQLite database was written although PostgreSQL is configured"

# 3. restart on the same database: the job and its artifacts are served.
kill -TERM "$pid"; wait "$pid" || true; pid=""
start_inspectd "$work/inspectd2.log"
wait_for "inspectd to listen again" 60 grep -q "inspectd listening on" "$work/inspectd2.log"
addr="$(sed -n 's/^inspectd listening on \([^ ]*\).*/\1/p' "$work/inspectd2.log" | head -n1)"
"$bin/inspectctl" --server "$addr" jobs >"$work/job.txt" 2>&1 || fail "jobs after restart: $(cat "$work/job.txt")"
grep "$job" "$work/job.txt" | grep -qi "succeeded" || fail "job $job not listed as succeeded after restart: $(cat "$work/job.txt")"
"$bin/inspectctl" --server "$addr" download "$job" --out "$work/dl" >"$work/dl.txt" 2>&1 || fail "download: $(cat "$work/dl.txt")"
[[ -s "$work/dl/depth.tiff" ]] || fail "depth.tiff not downloaded after restart: $(ls "$work/dl" 2>&1)"
kill -TERM "$pid"; wait "$pid" || true; pid=""

# 4. a malformed URL: exit 2, one line naming the key; no password anywhere.
rc=0
"$bin/inspectd" --listen 127.0.0.1:0 --data-dir "$work/data" --database "postgresql://postgres:$password@127.0.0.1:notaport/x" \
  >"$work/bad.txt" 2>&1 || rc=$?
[[ $rc -eq 2 ]] || fail "malformed URL: exit $rc, expected 2: $(cat "$work/bad.txt")"
[[ $(wc -l <"$work/bad.txt") -eq 1 ]] || fail "malformed URL: expected one line: $(cat "$work/bad.txt")"
grep -q "^inspectd: database: " "$work/bad.txt" || fail "malformed URL: message does not name database: $(cat "$work/bad.txt")"
! grep -rq "$password" "$work/bad.txt" "$work/inspectd.log" "$work/inspectd2.log" || fail "the password appears in inspectd's output"
echo "PASS: inspectd waited for PostgreSQL (health NOT_SERVING meanwhile), scanned into it, served the job after a restart; bad URL refused"
