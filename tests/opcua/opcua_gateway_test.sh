#!/usr/bin/env bash
# The OPC UA gateway (gateway/opcua) end to end: a real inspectd on the simulated rig with mTLS and
# a roles policy, the gateway with its OPC UA certificate, trust list and users file, both reading
# one config file (the `opcua` block is the gateway's), and an independent node-opcua client
# (opcua_client_test.js) that browses, runs one inspection over SignAndEncrypt and checks every
# refused case's status code and audit line.
# With --rig-error, inspectd runs a configured rig whose devices are absent (--degraded: the rig is
# in Error) and opcua_rig_error_test.js checks the Error state and the admin-only Reset.
#   opcua_gateway_test.sh BIN_DIR [--rig-error]
set -euo pipefail
bin="$(cd "$1" && pwd)"
mode="${2:-}"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
gateway="$here/../../gateway/opcua"
work="$(mktemp -d)"
srv_log="$work/inspectd.log"
gw_log="$work/gateway.log"
pids=()
cleanup() {
  # The gateway first: inspectd's shutdown waits for open streams (the gateway's WatchResults).
  local i
  for ((i = ${#pids[@]} - 1; i >= 0; i--)); do kill "${pids[$i]}" 2>/dev/null && wait "${pids[$i]}" 2>/dev/null; done
  rm -rf "$work"
}
trap cleanup EXIT
fail() {
  echo "FAIL: $*"
  echo "--- inspectd log"; tail -n 20 "$srv_log" || true
  echo "--- gateway log"; tail -n 30 "$gw_log" || true
  exit 1
}
# shellcheck source=../lib/poll.sh
source "$here/../lib/poll.sh"  # wait_for

# Not skippable: CI must fail when the gateway's packages are not installed (deploy/dev.sh runs npm ci).
[[ -d "$gateway/node_modules/node-opcua" ]] || fail "gateway/opcua/node_modules is missing: run 'npm ci' in gateway/opcua (deploy/dev.sh does)"
command -v node >/dev/null || fail "node is not installed"

pki="$work/pki"
bash "$here/make_certs.sh" "$pki"
hash() { node "$gateway/src/main.js" hash-password <<<"$1"; }
cat >"$work/users.json" <<JSON
{"users": [{"name": "station-7", "password_hash": "$(hash s3cret-operator)"},
           {"name": "viewer-1", "password_hash": "$(hash s3cret-viewer)"},
           {"name": "it-admin", "password_hash": "$(hash s3cret-admin)"}]}
JSON
# One policy for both protocols: gRPC identities (certificate CNs) and OPC UA users.
cat >"$work/policy.json" <<'JSON'
{"identities": {"opcua-gateway": "admin", "mes-verifier": "engineer", "station-7": "operator", "viewer-1": "viewer",
                "qa-lead": "engineer", "it-admin": "admin"}}
JSON
rig=""
# A real rig's configuration whose camera, stage and projector are not here: inspectd starts degraded, in Error.
[[ $mode == --rig-error ]] && rig='"rig_config": "'"$here/../../deploy/compose/rig.json"'", "degraded": true,'
cat >"$work/inspectd.json" <<JSON
{"listen": "127.0.0.1:0", "data_dir": "$work/data", "camera_size": "320x240", "specimen": "skew5", $rig
 "tls_cert": "$pki/inspectd.crt", "tls_key": "$pki/inspectd.key", "tls_client_ca": "$pki/grpc-ca.crt",
 "policy": "$work/policy.json",
 "opcua": {"port": 0, "hostname": "localhost",
           "grpc_tls_ca": "$pki/grpc-ca.crt", "grpc_tls_cert": "$pki/gateway-grpc.crt", "grpc_tls_key": "$pki/gateway-grpc.key",
           "grpc_server_name": "localhost",
           "certificate": "$pki/opcua-server.crt", "private_key": "$pki/opcua-server.key",
           "trusted_client_certificates": ["$pki/mes-client.crt", "$pki/qa-lead.crt"],
           "users_file": "$work/users.json", "audit_log": "$work/opcua-audit.jsonl"}}
JSON

"$bin/inspectd" --config "$work/inspectd.json" >"$srv_log" 2>&1 &
pids+=($!)
wait_for "inspectd to listen" 60 grep -q "inspectd listening on" "$srv_log"
addr="$(sed -n 's/.*inspectd listening on \([0-9.:]*\).*/\1/p' "$srv_log" | head -n1)"
[[ -n "$addr" ]] || fail "no address in the inspectd log"
# The gateway reads the same file; only the bound gRPC port (0 above) is filled in.
node -e 'const f=process.argv[1], c=JSON.parse(require("fs").readFileSync(f)); c.opcua.inspectd=process.argv[2]; require("fs").writeFileSync(f, JSON.stringify(c, null, 1));' \
  "$work/inspectd.json" "$addr"

node "$gateway/src/main.js" --config "$work/inspectd.json" >"$gw_log" 2>&1 &
pids+=($!)
wait_for "the gateway to listen" 60 grep -q "inspect-opcua-gateway listening on" "$gw_log"
url="$(sed -n 's/^inspect-opcua-gateway listening on \(opc.tcp:[^ ]*\).*/\1/p' "$gw_log" | head -n1)"
grep "inspect-opcua-gateway listening on" "$gw_log"
wait_for "the gateway to reach inspectd" 30 grep -q "connected to inspectd" "$gw_log"

if [[ $mode == --rig-error ]]; then
  node "$here/opcua_rig_error_test.js" "$url" "$pki" "$work/opcua-audit.jsonl" || fail "the OPC UA client's checks failed"
else
  node "$here/opcua_client_test.js" "$url" "$pki" "$addr" "$work/opcua-audit.jsonl" "$here/../../examples/python/recipe_tilt.json" \
    || fail "the OPC UA client's checks failed"
fi
echo "PASS"
