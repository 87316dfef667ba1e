#!/usr/bin/env bash
# inspectd's configuration through the real binary (server/app/main.cc wiring of server_config):
# flags > INSPECTD_* environment > --config / INSPECTD_CONFIG file > defaults, unknown keys and
# bad values exit 2 with one line naming them, --print-config reads back as a config file.
#   deploy/inspectd_config_test.sh [INSPECTD]     (default build/bin/inspectd)
set -euo pipefail

inspectd="$(realpath "${1:-$(dirname "$0")/../build/bin/inspectd}")"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
passed=0
failed=0
check() {  # name, expected, actual
  if [[ "$2" == "$3" ]]; then
    passed=$((passed + 1))
    echo "ok    $1"
  else
    failed=$((failed + 1))
    echo "FAIL  $1: expected [$2], got [$3]"
  fi
}
field() { /usr/bin/python3 -c 'import json,sys; v=json.load(sys.stdin)[sys.argv[1]]; print(json.dumps(v))' "$1"; }
# The environment is cleared so that the caller's INSPECTD_* variables cannot leak in.
run() { env -i "$@"; }

cat >"$work/site.json" <<'EOF'
{"listen": "0.0.0.0:1001", "queue_capacity": 7, "specimen": "lens", "reflection": false, "seed": 5}
EOF
out="$(run INSPECTD_LISTEN=0.0.0.0:2002 INSPECTD_QUEUE_CAPACITY=9 INSPECTD_REFLECTION=true \
  "$inspectd" --config "$work/site.json" --listen 127.0.0.1:3003 --no-reflection --print-config)"
check "listen: flag over environment over file" '"127.0.0.1:3003"' "$(field listen <<<"$out")"
check "reflection: --no-reflection over INSPECTD_REFLECTION=true" 'false' "$(field reflection <<<"$out")"
check "queue_capacity: environment over file" '9' "$(field queue_capacity <<<"$out")"
check "specimen: file over default" '"lens"' "$(field specimen <<<"$out")"
check "camera_size: default" '"1024x768"' "$(field camera_size <<<"$out")"

out="$(run INSPECTD_CONFIG="$work/site.json" "$inspectd" --print-config)"
check "INSPECTD_CONFIG names the file" '5' "$(field seed <<<"$out")"
echo '{"seed": 6}' >"$work/other.json"
out="$(run INSPECTD_CONFIG="$work/site.json" "$inspectd" --config "$work/other.json" --print-config)"
check "--config over INSPECTD_CONFIG" '6' "$(field seed <<<"$out")"

run "$inspectd" --config "$work/site.json" --degraded --seed 77 --print-config >"$work/printed.json"
check "--print-config reads back unchanged" "$(cat "$work/printed.json")" \
  "$(run "$inspectd" --config "$work/printed.json" --print-config)"

echo '{"listen": "0.0.0.0:1", "queue_capacty": 3}' >"$work/typo.json"
set +e
err="$(run "$inspectd" --config "$work/typo.json" 2>&1 >/dev/null)"
code=$?
set -e
check "unknown key: exit 2" 2 "$code"
check "unknown key: one line naming it" \
  "inspectd: $work/typo.json: unknown key 'queue_capacty' (did you mean 'queue_capacity'?); known keys: listen, data_dir, database, database_password_file, rig_id, site_database, site_database_password_file, queue_capacity, reflection, tls_cert, tls_key, tls_client_ca, insecure, auth_token_file, token_file, policy, rig_config, degraded, specimen, seed, camera_size, log_level, log_format, no_rig, http_listen, scene_dir, audit_log, min_free_mb, retention_max_age_s, retention_max_mb, retention_keep_last, retention_interval_s, verification_interval_days, decode_threads, decode_budget_mb, artifact_threads, mqtt_host, mqtt_port, mqtt_site, mqtt_rig, mqtt_topic_prefix, mqtt_client_id, mqtt_username, mqtt_password_file, mqtt_tls_ca, mqtt_tls_cert, mqtt_tls_key, pool_lease_s, pool_workers, pool_poll_ms, drain_timeout_s, engine_threads" \
  "$err"
set +e
err="$(run INSPECTD_QUEUE_CAPACITY=lots "$inspectd" --print-config 2>&1 >/dev/null)"
code=$?
set -e
check "bad environment value: exit 2 naming the variable" \
  "2 inspectd: environment variable INSPECTD_QUEUE_CAPACITY 'lots' must be an integer" "$code $err"
set +e
err="$(run "$inspectd" --config "$work/absent.json" --print-config 2>&1 >/dev/null)"
code=$?
set -e
check "missing file: exit 2 naming it" "2 inspectd: config file '$work/absent.json' cannot be read" "$code $err"

echo "$passed passed, $failed failed"
[[ $failed == 0 ]]
