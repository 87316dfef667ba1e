#!/usr/bin/env bash
# One result feed for a site, end to end with the real binaries: a rig's inspectd forwards every
# inspection result to the site's PostgreSQL (--site-database); the site database is stopped for
# OUTAGE_SECONDS (default 8; the issue's run uses 30) in the middle of a run of recipe scans and
# started again. Asserted: the rig kept scanning (every scan succeeded) and kept its results; on a
# site replica (inspectd --no-rig on the site database) `inspectctl results list` shows every
# result of the rig exactly once, with its rig id and in the rig's order (rig_sequence 1..N, site
# sequence increasing). Waits poll with deadlines.
#   site_forwarding_outage_test.sh BIN_DIR [SCANS]
set -euo pipefail
bin="$(cd "$1" && pwd)"
scans="${2:-12}"
outage="${OUTAGE_SECONDS:-8}"
pgbin=/usr/lib/postgresql/15/bin
examples="$(cd "$(dirname "${BASH_SOURCE[0]}")/../../../examples/python" && pwd)"
work="$(mktemp -d /tmp/inspect-site-XXXXXX)"
rig_pid="" site_pid=""
fail() { echo "FAIL: $*"; echo "--- rig log (warnings)"; grep -i "warn\|error\|forward" "$work/rig.log" | tail -n 20 || true; exit 1; }
[[ -x "$pgbin/initdb" ]] || fail "PostgreSQL 15 is not installed ($pgbin/initdb): apt-get install postgresql"
as_pg=()
[[ $(id -u) -eq 0 ]] && as_pg=(runuser -u postgres --)
cleanup() {
  for p in $rig_pid $site_pid; do kill -9 "$p" 2>/dev/null || true; done
  "${as_pg[@]}" "$pgbin/pg_ctl" -D "$work/pg" -m immediate stop >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT
# shellcheck source=../../lib/poll.sh
source "$(dirname "${BASH_SOURCE[0]}")/../../lib/poll.sh"  # wait_for

password="site-$RANDOM-secret"
echo "$password" >"$work/pw"
[[ $(id -u) -eq 0 ]] && chown -R postgres "$work"
"${as_pg[@]}" "$pgbin/initdb" -D "$work/pg" -U postgres -A scram-sha-256 --pwfile="$work/pw" --no-sync >/dev/null 2>&1 ||
  fail "initdb failed"
port=$(/usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
pg() { "${as_pg[@]}" "$pgbin/pg_ctl" -D "$work/pg" -w -l "$work/pg.log" -o "-k $work -p $port -c listen_addresses=127.0.0.1" "$@" >/dev/null; }
pg start
url="postgresql://postgres@127.0.0.1:$port/postgres"
listen_addr() { sed -n 's/^inspectd listening on \([^ ]*\).*/\1/p' "$1" | head -n1; }

"$bin/inspectd" --listen 127.0.0.1:0 --data-dir "$work/rig" --rig-id line2-rig7 --specimen skew5 --camera-size 320x240 \
  --site-database "$url" --site-database-password-file "$work/pw" >"$work/rig.log" 2>&1 &
rig_pid=$!
wait_for "the rig to listen" 60 grep -q "inspectd listening on" "$work/rig.log"
rig="$(listen_addr "$work/rig.log")"
"$bin/inspectd" --listen 127.0.0.1:0 --data-dir "$work/site" --no-rig --database "$url" \
  --database-password-file "$work/pw" >"$work/site.log" 2>&1 &
site_pid=$!
wait_for "the site replica to listen" 60 grep -q "inspectd listening on" "$work/site.log"
site="$(listen_addr "$work/site.log")"
"$bin/inspectctl" --server "$rig" recipe create "$examples/recipe_tilt.json" >/dev/null || fail "recipe create"

stopped_at=$((scans / 3)) started_at=$((2 * scans / 3))
t_stop=0
for i in $(seq 1 "$scans"); do
  if [[ $i -eq $stopped_at ]]; then pg -m fast stop; t_stop=$SECONDS; echo "site database stopped before scan $i"; fi
  if [[ $i -eq $started_at ]]; then
    while ((SECONDS - t_stop < outage)); do
      "$bin/inspectctl" --server "$rig" scan --recipe tilt-5deg --part-id "P-$i-wait" --out "$work/out" >/dev/null 2>&1 ||
        fail "a scan failed while the site database was down"
    done
    pg start; echo "site database started again after $((SECONDS - t_stop)) s"
  fi
  "$bin/inspectctl" --server "$rig" scan --recipe tilt-5deg --part-id "P-$i" --out "$work/out" >/dev/null 2>&1 ||
    fail "scan $i failed"
done
rig_count=$("$bin/inspectctl" --server "$rig" results list --limit 500 | grep -c "P-" || true)
# Every result reaches the site (the forwarder retries with backoff up to 30 s).
site_rows() { PGPASSWORD="$password" psql -h 127.0.0.1 -p "$port" -U postgres -d postgres -Atc "$1"; }
# A function, so the count is asked again at every poll (a "$(...)" argument would be read once,
# when wait_for is called: a site still catching up then never looked complete).
site_holds() { [[ "$(site_rows 'SELECT count(*) FROM results')" -eq "$1" ]]; }
wait_for "the site to hold all $rig_count results" 180 site_holds "$rig_count"
[[ "$(site_rows "SELECT count(DISTINCT rig_sequence) FROM results WHERE rig_id = 'line2-rig7'")" -eq "$rig_count" ]] ||
  fail "duplicate or missing rig sequence numbers on the site"
[[ "$(site_rows "SELECT min(rig_sequence) || ' ' || max(rig_sequence) FROM results")" == "1 $rig_count" ]] ||
  fail "rig sequence numbers are not 1..$rig_count"
# The rig's order is the site's order.
ordered=$(site_rows "SELECT bool_and(rs > prev) FROM (SELECT rig_sequence AS rs, lag(rig_sequence, 1, 0) OVER (ORDER BY sequence) AS prev FROM results) t")
[[ "$ordered" == t ]] || fail "the site's order differs from the rig's"
# And a site replica serves them through the API, with the rig's id.
"$bin/inspectctl" --server "$site" results list --limit 500 >"$work/site_results.txt" || fail "results list on the site replica"
[[ $(grep -c "P-" "$work/site_results.txt") -eq "$rig_count" ]] || fail "site replica lists $(grep -c "P-" "$work/site_results.txt") of $rig_count"
echo "PASS: $rig_count results (scans during a $outage s site outage included) on the site once each, in the rig's order"
