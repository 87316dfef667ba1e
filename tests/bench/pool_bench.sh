#!/usr/bin/env bash
# The reconstruct pool's figures on this machine, written to tests/bench/pool_bench_output.md:
#   1. 3 replicas + PostgreSQL, JOBS uploads over channels to different replicas, one replica
#      killed with -9 mid-job and restarted later (the kill/restart table, every artifact
#      sha-verified from every replica);
#   2. throughput with 1 and 2 replicas (each replica's engine, decoding and artifact writing on
#      one thread each), with the replicas free on every core and confined to one core each;
#   3. one rig on SQLite against PostgreSQL: scan and reconstruct latency;
#   4. faults: the database stopped while a job runs, a SIGTERM drain, a full shared folder;
#   5. the site feed with its database stopped for 30 s (site_forwarding_outage_test.sh).
#   tests/bench/pool_bench.sh BUILD_DIR [JOBS]        (JOBS default 200)
set -euo pipefail
build="$(cd "$1" && pwd)"
jobs="${2:-200}"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
out="$here/pool_bench_output.md"
bench="$build/bin/pool-bench"
{
  echo "# Reconstruct pool bench ($(date -u +%Y-%m-%dT%H:%MZ), $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg))"
  echo
  echo "Produced by \`tests/bench/pool_bench.sh build $jobs\`; PostgreSQL 15 on loopback (fsync off), one shared folder."
  echo
  echo "## 1. $jobs reconstructs, 3 replicas, one killed with -9 and restarted"
  echo '```'
  "$bench" --bin "$build/bin" --scenario kill --jobs "$jobs" --replicas 3 --clients 6 --width 640 --height 480 --frames 16 2>&1
  echo '```'
  echo
  echo "## 2. Throughput, 1 against 2 replicas"
  echo '```'
  "$bench" --bin "$build/bin" --scenario throughput --jobs 40 --width 640 --height 480 --frames 16 2>&1
  echo '```'
  echo
  echo "## 3. One rig: SQLite against PostgreSQL"
  echo '```'
  "$bench" --bin "$build/bin" --scenario latency --jobs 10 2>&1
  echo '```'
  echo
  echo "## 4. Faults: the database lost mid-job, a full shared folder"
  echo '```'
  "$bench" --bin "$build/bin" --scenario faults --width 640 --height 480 --frames 24 2>&1
  echo '```'
  echo
  echo "## 5. Site feed: the site database stopped for 30 s during a run of rig scans"
  echo '```'
  OUTAGE_SECONDS=30 bash "$here/../server/results/site_forwarding_outage_test.sh" "$build/bin" 2>&1 | grep -v Killed
  echo '```'
} | tee "$out"
