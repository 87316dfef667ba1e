#!/usr/bin/env bash
# Builds the inspectd image (deploy/Containerfile) with podman from a local debootstrap base, runs
# it on the simulated rig, scans through the published gRPC port with the host's inspectctl,
# reads the Prometheus /metrics of the published HTTP port (9464) for that scan, checks the gRPC
# health service, the non-root user and the data volume, and stops it (SIGTERM, exit 0).
#
#   deploy/container_test.sh [INSPECTCTL]      (default build/bin/inspectctl; run as root)
# Environment:
#   IMAGE        tag to build and test (default localhost/inspectd:test)
#   BASE_IMAGE   bookworm base (default localhost/debian:bookworm-minbase; made when missing)
#   BASE_CACHE   where the debootstrap tarball is kept between runs
#                (default /var/cache/inspection-containers)
#   SKIP_BUILD=1 test an existing IMAGE;  KEEP_IMAGE=1 keep IMAGE afterwards (default: kept)
#   JOBS         compile jobs inside the build (default 2)
#   CCACHE_HOST_DIR  the host's ccache directory, mounted into the build stage so the image reuses
#                the host's objects (default: `ccache -k cache_dir`; empty = the build's own cache
#                mount only). docs/operations.md "Building the image fast".
#   NPM_CA       CA bundle passed to the gateway stage's npm as the build secret npm_ca, for a
#                TLS-inspecting proxy (default /etc/ssl/certs/ca-certificates.crt when it exists;
#                empty = none). docs/operations.md "Building behind a TLS-inspecting proxy".
# Podman on these machines needs --runtime runc, explicit ulimits and chroot isolation for builds
# (../shared/PLATFORM.md "Containers").
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
inspectctl="$(realpath "${1:-build/bin/inspectctl}")"
image="${IMAGE:-localhost/inspectd:test}"
base_image="${BASE_IMAGE:-localhost/debian:bookworm-minbase}"
base_cache="${BASE_CACHE:-/var/cache/inspection-containers}"
podman=(podman --runtime runc)
ulimits=(--ulimit nofile=4096:4096 --ulimit nproc=4096:4096)
name="inspectd-test-$$"
volume="inspectd-test-data-$$"
work="$(mktemp -d)"

step() { printf '== %s\n' "$*"; }
fail() { printf 'FAIL: %s\n' "$*" >&2; exit 1; }
cleanup() {
  "${podman[@]}" rm -f -t 0 "$name" >/dev/null 2>&1 || true
  "${podman[@]}" volume rm -f "$volume" >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT

[[ $(id -u) -eq 0 ]] || fail "run as root (podman with runc, as in ../shared/PLATFORM.md)"
command -v curl >/dev/null || fail "curl is needed to read /metrics (apt-get install curl)"
[[ -x "$inspectctl" ]] || fail "no inspectctl at $inspectctl (build it: cmake --build build --target inspectctl)"

# --- base image: podman's store, else the cached tarball, else debootstrap (~2 min) -------------
if "${podman[@]}" image exists "$base_image"; then
  step "base image $base_image present"
else
  tarball="$base_cache/bookworm-minbase.tar"
  if [[ ! -s "$tarball" ]]; then
    step "debootstrap bookworm (minbase) -> $tarball"
    command -v debootstrap >/dev/null || fail "debootstrap is not installed (apt-get install debootstrap)"
    mkdir -p "$base_cache"
    rootfs="$work/rootfs"
    debootstrap --variant=minbase bookworm "$rootfs" http://deb.debian.org/debian >"$work/debootstrap.log" 2>&1 ||
      { tail -20 "$work/debootstrap.log"; fail "debootstrap failed"; }
    tar -C "$rootfs" --numeric-owner -cf "$tarball.tmp" . && mv "$tarball.tmp" "$tarball"
    rm -rf "$rootfs"
  fi
  step "import $tarball as $base_image"
  "${podman[@]}" import -q "$tarball" "$base_image" >/dev/null
fi

# --- build ---------------------------------------------------------------------------------------
if [[ "${SKIP_BUILD:-0}" != 1 ]]; then
  step "build $image"
  start=$SECONDS
  cache_args=()
  ccache_dir="${CCACHE_HOST_DIR-$(ccache -k cache_dir 2>/dev/null || true)}"
  if [[ -n "$ccache_dir" ]]; then
    mkdir -p "$ccache_dir"
    cache_args=(--volume "$ccache_dir:/ccache" --build-arg CCACHE_DIR=/ccache)
    echo "   ccache: the host's $ccache_dir"
  fi
  npm_ca="${NPM_CA-/etc/ssl/certs/ca-certificates.crt}"
  if [[ -n "$npm_ca" && -s "$npm_ca" ]]; then
    cache_args+=(--secret "id=npm_ca,src=$npm_ca")
    echo "   npm CA bundle (build secret npm_ca): $npm_ca"
  fi
  "${podman[@]}" build --format docker --isolation chroot "${ulimits[@]}" "${cache_args[@]}" \
    --build-arg BASE_IMAGE="$base_image" --build-arg JOBS="${JOBS:-2}" \
    --ignorefile deploy/containerignore -f deploy/Containerfile -t "$image" . >"$work/build.log" 2>&1 ||
    { tail -40 "$work/build.log"; fail "image build failed"; }
  grep -E '^ccache this build: ' "$work/build.log" | sed 's/^/   /' || true
  echo "   build time: $((SECONDS - start)) s"
fi
size_bytes="$("${podman[@]}" image inspect --format '{{.Size}}' "$image")"
echo "   image size: $((size_bytes / 1000000)) MB ($size_bytes bytes)"
[[ "$size_bytes" -lt 900000000 ]] || fail "image is ${size_bytes} bytes, not under 0.9 GB"

# --- run on the simulated rig --------------------------------------------------------------------
step "run $image (simulated rig, 512x384 camera)"
"${podman[@]}" volume create "$volume" >/dev/null
"${podman[@]}" run -d --read-only --name "$name" "${ulimits[@]}" -p 127.0.0.1::50051 -p 127.0.0.1::9464 \
  -v "$volume:/var/lib/inspection" \
  -e INSPECTD_SPECIMEN=lens "$image" --camera-size 512x384 >/dev/null 2>"$work/run.err" ||
  { cat "$work/run.err"; fail "podman run failed"; }
port="$("${podman[@]}" port "$name" 50051/tcp | head -n1 | sed 's/.*://')"
[[ -n "$port" ]] || fail "no published port"
addr="127.0.0.1:$port"
http_port="$("${podman[@]}" port "$name" 9464/tcp | head -n1 | sed 's/.*://')"
[[ -n "$http_port" ]] || fail "no published HTTP port"
http_addr="127.0.0.1:$http_port"
echo "   gRPC published at $addr, HTTP (metrics, dashboard) at $http_addr"

# Health through the image's own HEALTHCHECK (inspect-health-probe -> grpc.health.v1.Health):
# podman here has no systemd to run it periodically, so run it on demand until it passes.
healthy=0
for _ in $(seq 1 120); do
  if "${podman[@]}" healthcheck run "$name" >/dev/null 2>&1; then healthy=1; break; fi
  [[ "$("${podman[@]}" inspect --format '{{.State.Running}}' "$name")" == true ]] ||
    { "${podman[@]}" logs "$name"; fail "container exited"; }
  sleep 0.5
done
[[ $healthy == 1 ]] || { "${podman[@]}" logs "$name"; fail "HEALTHCHECK never passed"; }
echo "   HEALTHCHECK: $("${podman[@]}" inspect --format '{{.State.Health.Status}}' "$name")"
rig_health="$("${podman[@]}" exec "$name" inspect-health-probe --service inspection.v1.InspectionService)"
echo "   $rig_health"
[[ "$rig_health" == *SERVING* && "$rig_health" != *NOT_SERVING* ]] || fail "rig health: $rig_health"
set +e
"${podman[@]}" exec "$name" inspect-health-probe --service no.such.Service >/dev/null 2>&1
code=$?
set -e
[[ $code == 3 ]] || fail "unknown health service: exit $code, expected 3"
echo "   unknown health service: exit 3 (NOT_FOUND), as expected"

step "configuration inside the container"
"${podman[@]}" exec "$name" inspectd --print-config >"$work/config.json"
grep -q '"listen": "0.0.0.0:50051"' "$work/config.json" || fail "listen not from the image's config file"
grep -q '"specimen": "lens"' "$work/config.json" || fail "INSPECTD_SPECIMEN not applied"
echo "   listen 0.0.0.0:50051 (file), specimen lens (INSPECTD_SPECIMEN)"
uid="$("${podman[@]}" exec "$name" id -u)"
[[ "$uid" == 10001 ]] || fail "runs as uid $uid, expected 10001"
echo "   runs as uid $uid"

step "status and scan through $addr with the host's inspectctl"
"$inspectctl" --server "$addr" status | sed 's/^/   /'
"$inspectctl" --server "$addr" scan --out "$work/scan" | sed 's/^/   /'
for f in depth.tiff confidence.tiff all_in_focus.png depth_preview.png; do
  [[ -s "$work/scan/$f" ]] || fail "scan result $f missing"
done

owner="$("${podman[@]}" exec "$name" sh -c 'find /var/lib/inspection -type f | head -n1 | xargs stat -c %u')"
[[ "$owner" == 10001 ]] || fail "data files owned by uid $owner"
echo "   data volume files owned by uid $owner"

step "Prometheus /metrics through the published HTTP port $http_addr"
curl -fsS --max-time 10 "http://$http_addr/metrics" >"$work/metrics.txt" || fail "GET /metrics failed"
grep -E '^inspectd_(jobs_total\{|frames_acquired_total |rig_state\{state="ready"\})' "$work/metrics.txt" | sed 's/^/   /'
grep -qx 'inspectd_jobs_total{kind="scan",state="succeeded"} 1' "$work/metrics.txt" ||
  fail "no inspectd_jobs_total{kind=\"scan\",state=\"succeeded\"} 1 after the scan"
curl -fsS --max-time 10 "http://$http_addr/" | grep -q '<title>inspectd</title>' || fail "dashboard page not served"
echo "   dashboard page served at http://$http_addr/"

step "stop (SIGTERM)"
"${podman[@]}" stop -t 30 "$name" >/dev/null
exit_code="$("${podman[@]}" inspect --format '{{.State.ExitCode}}' "$name")"
[[ "$exit_code" == 0 ]] || { "${podman[@]}" logs "$name" | tail; fail "inspectd exited with $exit_code"; }
echo "   inspectd exited with 0"
"${podman[@]}" logs "$name" 2>&1 | tail -n 3 | sed 's/^/   log: /'
[[ "${KEEP_IMAGE:-1}" == 1 ]] || "${podman[@]}" rmi "$image" >/dev/null
echo "PASS: container test"
