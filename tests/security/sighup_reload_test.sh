#!/usr/bin/env bash
# SIGHUP reload end to end: the real inspectd with named tokens and an access policy, the real
# inspectctl. An unknown token is UNAUTHENTICATED and a viewer's CancelJob PERMISSION_DENIED;
# after the token and policy files change and inspectd gets SIGHUP, the new token is accepted
# and the promoted identity passes the operator check (NOT_FOUND for an unknown job), with no
# restart. A broken policy on the next SIGHUP is refused and the previous policy stays. Waits
# poll the server's log line with a deadline (never a fixed sleep standing in for
# synchronisation).
#   sighup_reload_test.sh BIN_DIR
set -euo pipefail
bin="$(cd "$1" && pwd)"
work="$(mktemp -d)"
srv_log="$work/inspectd.log"
pid=""
cleanup() { [[ -n "$pid" ]] && kill -9 "$pid" 2>/dev/null; rm -rf "$work"; }
trap cleanup EXIT

fail() { echo "FAIL: $*"; echo "--- inspectd log"; tail -n 30 "$srv_log" || true; exit 1; }

# shellcheck source=../lib/poll.sh
source "$(dirname "${BASH_SOURCE[0]}")/../lib/poll.sh"  # wait_for

alice="alice-token-0123456789abcdef"
bob="bob-token-fedcba9876543210xyz"
echo "$alice" >"$work/alice.tok"
echo "$bob" >"$work/bob.tok"
printf '# identity token\nalice %s\n' "$alice" >"$work/tokens"
echo '{"identities": {"alice": "viewer"}}' >"$work/policy.json"

"$bin/inspectd" --listen 127.0.0.1:0 --data-dir "$work/data" --camera-size 320x240 \
  --token-file "$work/tokens" --policy "$work/policy.json" >"$srv_log" 2>&1 &
pid=$!
wait_for "inspectd to listen" 60 grep -q "inspectd listening on" "$srv_log"
addr="$(sed -n 's/^inspectd listening on \([^ ]*\).*/\1/p' "$srv_log" | head -n1)"

# expect CODE WHO ARGS...: inspectctl as WHO fails with the one-line error "inspectctl: CODE: ..."
# (or succeeds when CODE is OK).
expect() {
  local code="$1" who="$2"; shift 2
  local out rc=0
  out="$("$bin/inspectctl" --server "$addr" --token-file "$work/$who.tok" "$@" 2>&1)" || rc=$?
  if [[ "$code" == OK ]]; then
    ((rc == 0)) || fail "$who $*: expected success, got exit $rc: $out"
  else
    ((rc != 0)) || fail "$who $*: expected $code, got success: $out"
    [[ "$out" == "inspectctl: $code: "* ]] || fail "$who $*: expected $code, got: $out"
  fi
  echo "ok: $who $* -> $code"
}
reloads() { grep -c "SIGHUP: access policy and tokens reloaded" "$srv_log" || true; }
refusals() { grep -c "SIGHUP: access policy not reloaded" "$srv_log" || true; }
at_least() { local n; n="$("$1")"; ((n >= $2)); }

expect OK alice status
expect UNAUTHENTICATED bob status
expect PERMISSION_DENIED alice cancel job-does-not-exist

# New token for bob, alice promoted to operator; no restart.
printf 'alice %s\nbob %s\n' "$alice" "$bob" >"$work/tokens"
echo '{"identities": {"alice": "operator", "bob": "viewer"}}' >"$work/policy.json"
kill -HUP "$pid"
wait_for "the reload log line" 30 at_least reloads 1
expect OK bob status
expect NOT_FOUND alice cancel job-does-not-exist   # passed the operator check
expect PERMISSION_DENIED bob cancel job-does-not-exist

# A broken policy is refused on SIGHUP; the previous policy stays in force.
echo '{"identities": {"alice": "superuser"}}' >"$work/policy.json"
kill -HUP "$pid"
wait_for "the refusal log line" 30 at_least refusals 1
expect NOT_FOUND alice cancel job-does-not-exist
expect OK bob status
kill -0 "$pid" || fail "inspectd exited"
echo "PASS: SIGHUP reloads tokens and policy; a bad policy keeps the previous one"
