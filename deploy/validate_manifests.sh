#!/usr/bin/env bash
# Offline validation of the deployment files, no cluster and no container engine needed:
#   1. `kubectl kustomize` renders deploy/k8s/{rig,reconstruct,example} (kustomize errors: bad
#      patches, missing files, name collisions);
#   2. `kubectl set env --local` decodes every rendered object into its typed Kubernetes struct
#      (wrong field types, bad quantities) - the only typed check kubectl offers without a server;
#   3. check_manifests.py checks references and the rig / pool rules, and has inspectd load every
#      configuration file with the container's INSPECTD_* variables; a self-test breaks valid
#      manifests one rule at a time and requires each to be caught;
#   4. the compose files (compose.yaml, compose.sim.yaml) get the same configuration checks;
#   5. the OPC UA gateway's sidecar / service (same image and config file, its port and files),
#      and with Node.js the gateway's own check of the `opcua` block of each config file.
#
#   deploy/validate_manifests.sh [INSPECTD]     INSPECTD: the built binary (default build/bin/inspectd)
# Exit 0 when valid, 1 on a finding, 77 (CTest: skipped; a failure in CI, where ctest has no
# SKIP_RETURN_CODE) when kubectl with kustomize is missing: the kubectl-free compose and
# configuration checks still run then, and a finding there still exits 1.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
inspectd="$(realpath "${1:-$here/../build/bin/inspectd}")"
python=/usr/bin/python3  # Debian's, with python3-yaml (a pyenv python3 may lack it)
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

have_kubectl=1
if ! command -v kubectl >/dev/null || ! kubectl kustomize --help >/dev/null 2>&1; then
  echo "kubectl with kustomize is not installed (Debian: kubernetes-client): deploy/k8s not checked"
  have_kubectl=0
fi
[[ -x "$inspectd" ]] || { echo "FAIL: no inspectd at $inspectd"; exit 1; }
"$python" -c 'import yaml' 2>/dev/null || { echo "FAIL: $python lacks yaml (apt-get install python3-yaml)"; exit 1; }

# The OPC UA gateway checks its own block of every config file when Node.js is there (it needs no
# npm packages for that); without it the gateway's container rules are still checked.
gateway_args=()
if command -v node >/dev/null; then
  gateway_args=(--gateway "$here/../gateway/opcua/src/main.js")
else
  echo "node is not installed: the OPC UA gateway's own configuration check is left out"
fi

status=0
((have_kubectl)) && k8s_dirs=(rig reconstruct example) || k8s_dirs=()
for dir in "${k8s_dirs[@]}"; do
  out="$work/$dir.yaml"
  echo "== deploy/k8s/$dir"
  if ! kubectl kustomize "$here/k8s/$dir" >"$out" 2>"$work/err"; then
    echo "FAIL: kustomize: $(cat "$work/err")"
    status=1
    continue
  fi
  echo "   rendered $(grep -c '^kind:' "$out") objects: $(grep '^kind:' "$out" | sort | uniq -c | awk '{printf "%s %s, ", $1, $3}' | sed 's/, $//')"
  # Typed decoding: only "not a pod" refusals of objects without a pod template are expected.
  kubectl set env --local -f "$out" -o name VALIDATE=1 >"$work/decoded" 2>"$work/err" || true
  unexpected="$(grep -v -e '^$' -e 'the object is not a pod or does not have a pod template' "$work/err" || true)"
  if [[ -n "$unexpected" ]]; then
    echo "FAIL: typed decoding: $unexpected"
    status=1
  else
    echo "   typed decoding: ok ($(wc -l <"$work/decoded") workloads)"
  fi
  args=(k8s "$out" --inspectd "$inspectd" "${gateway_args[@]}")
  [[ $dir == rig ]] && args+=(--placeholders)  # the bare base keeps nodeSelector value RIG
  "$python" "$here/check_manifests.py" "${args[@]}" | sed 's/^/   /' || status=1
done

if ((have_kubectl)); then
  echo "== self-test: broken manifests must be caught"
  "$python" "$here/check_manifests.py" self-test "$work/example.yaml" --inspectd "$inspectd" "${gateway_args[@]}" | sed 's/^/   /' || status=1
fi

echo "== compose"
"$python" "$here/check_manifests.py" compose "$here/compose.yaml" --real-rig --inspectd "$inspectd" "${gateway_args[@]}" | sed 's/^/   /' || status=1
"$python" "$here/check_manifests.py" compose "$here/compose.sim.yaml" --inspectd "$inspectd" "${gateway_args[@]}" | sed 's/^/   /' || status=1

echo "== image configuration"
if INSPECTD_CONFIG="$here/config/inspectd.json" "$inspectd" --print-config >/dev/null 2>"$work/err"; then
  echo "   ok   deploy/config/inspectd.json"
else
  echo "   FAIL deploy/config/inspectd.json: $(cat "$work/err")"
  status=1
fi
if ((${#gateway_args[@]})); then
  if node "${gateway_args[1]}" --check-config --config "$here/config/inspectd.json" >/dev/null 2>"$work/err"; then
    echo "   ok   deploy/config/inspectd.json opcua block (the image's OPC UA gateway)"
  else
    echo "   FAIL deploy/config/inspectd.json opcua block: $(cat "$work/err")"
    status=1
  fi
fi

if [[ $status != 0 ]]; then
  echo "FAIL: deployment files have findings"
  exit 1
fi
if ((!have_kubectl)); then
  echo "SKIP: compose and configuration valid; deploy/k8s needs kubectl (apt-get install kubernetes-client)"
  exit 77
fi
echo "PASS: deployment files valid"
