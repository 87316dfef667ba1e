#!/usr/bin/python3
"""A real Prometheus scrapes a running inspectd: the scrape uses the same bearer token as gRPC,
a scan through inspectctl shows up in Prometheus's HTTP API as inspectd_jobs_total{kind="scan",
state="succeeded"} = 1 with its frames, duration histogram and gRPC call counts.

Usage: prometheus_scrape_test.py INSPECTD INSPECTCTL [WORK_DIR]
Exit 77 (CTest: skipped) only when the prometheus binary is absent. Every wait polls a
condition against a deadline; nothing sleeps to synchronise.
"""
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.parse
import urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ops_common import DEADLINE_S, stop_processes, wait_for  # noqa: E402


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def http_get(url, token=None):
    req = urllib.request.Request(url)
    if token:
        req.add_header("Authorization", "Bearer " + token)
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode()
    except (urllib.error.URLError, ConnectionError, socket.timeout):
        return None, ""


def main():
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    inspectd, inspectctl = sys.argv[1], sys.argv[2]
    prometheus = shutil.which("prometheus")
    if not prometheus:
        print("SKIP: prometheus not installed (apt-get install prometheus)")
        return 77
    work = tempfile.mkdtemp(prefix="inspect_prometheus_", dir=sys.argv[3] if len(sys.argv) > 3 else None)
    procs = []
    try:
        token = "prometheus-test-token"
        token_file = os.path.join(work, "token")
        with open(token_file, "w") as f:
            f.write(token + "\n")
        log_path = os.path.join(work, "inspectd.log")
        log = open(log_path, "w")
        err_path = os.path.join(work, "inspectd.stderr")
        procs.append(subprocess.Popen(
            [inspectd, "--listen", "127.0.0.1:0", "--http-listen", "127.0.0.1:0", "--data-dir",
             os.path.join(work, "data"), "--camera-size", "320x240", "--auth-token-file", token_file,
             "--log-format", "json"],
            stdout=log, stderr=open(err_path, "w"), env={}))

        def announced():
            grpc_addr = http_addr = None
            with open(log_path) as f:
                for line in f:
                    # --log-format json: every stdout line, the announcements too, is one JSON object.
                    try:
                        message = json.loads(line)["message"]
                    except (ValueError, KeyError):
                        raise SystemExit(f"FAIL: inspectd log line is not a JSON object with a message: {line!r}")
                    m = re.match(r"inspectd listening on (\S+)$", message)
                    grpc_addr = m.group(1) if m else grpc_addr
                    m = re.match(r"inspectd http on http://(\S+)/$", message)
                    http_addr = m.group(1) if m else http_addr
            if procs[0].poll() is not None:
                raise SystemExit("FAIL: inspectd exited:\n" + open(log_path).read() + open(err_path).read())
            return (grpc_addr, http_addr) if grpc_addr and http_addr else None

        grpc_addr, http_addr = wait_for("inspectd to announce its ports", announced)
        print(f"inspectd gRPC {grpc_addr}, HTTP {http_addr}")
        status, _ = http_get(f"http://{http_addr}/metrics")
        assert status == 401, f"/metrics without the token answered {status}, expected 401"

        prom_port = free_port()
        config = os.path.join(work, "prometheus.yml")
        with open(config, "w") as f:
            f.write(f"""global:
  scrape_interval: 1s
  scrape_timeout: 1s
scrape_configs:
  - job_name: inspectd
    metrics_path: /metrics
    authorization:
      type: Bearer
      credentials_file: {token_file}
    static_configs:
      - targets: ["{http_addr}"]
""")
        prom_log = open(os.path.join(work, "prometheus.log"), "w")
        procs.append(subprocess.Popen(
            [prometheus, f"--config.file={config}", f"--storage.tsdb.path={os.path.join(work, 'tsdb')}",
             f"--web.listen-address=127.0.0.1:{prom_port}", "--log.level=warn"],
            stdout=prom_log, stderr=subprocess.STDOUT))
        api = f"http://127.0.0.1:{prom_port}"
        wait_for("Prometheus to be ready", lambda: http_get(api + "/-/ready")[0] == 200)

        def query(expr):
            status, body = http_get(api + "/api/v1/query?" + urllib.parse.urlencode({"query": expr}))
            if status != 200:
                return None
            doc = json.loads(body)
            return doc if doc.get("status") == "success" else None

        def up():
            doc = query('up{job="inspectd"}')
            return doc if doc and doc["data"]["result"] and doc["data"]["result"][0]["value"][1] == "1" else None
        wait_for("Prometheus to scrape inspectd with the token (up == 1)", up)

        scan = subprocess.run([inspectctl, "--server", grpc_addr, "--token-file", token_file, "scan", "--out",
                               os.path.join(work, "scan"), "--z-step", "10", "--label", "prometheus-test"],
                              capture_output=True, text=True, timeout=DEADLINE_S)
        assert scan.returncode == 0, f"inspectctl scan exited {scan.returncode}:\n{scan.stdout}\n{scan.stderr}"

        expr = 'inspectd_jobs_total{kind="scan",state="succeeded"}'

        def scan_counted():
            doc = query(expr)
            return doc if doc and doc["data"]["result"] and doc["data"]["result"][0]["value"][1] == "1" else None
        doc = wait_for("Prometheus to show the scan in " + expr, scan_counted)
        print("query " + expr + ":\n" + json.dumps(doc, indent=1))
        result = doc["data"]["result"][0]["metric"]
        assert result["job"] == "inspectd" and result["kind"] == "scan" and result["state"] == "succeeded", result

        frames = query("inspectd_frames_acquired_total")["data"]["result"][0]["value"][1]
        durations = query('inspectd_job_duration_seconds_count{kind="scan"}')["data"]["result"][0]["value"][1]
        le_inf = query('inspectd_job_duration_seconds_bucket{kind="scan",le="+Inf"}')["data"]["result"][0]["value"][1]
        calls = query('inspectd_grpc_calls_total{method="inspection.v1.InspectionService/Scan",code="OK"}')
        print(f"frames acquired {frames}, scan durations observed {durations} (+Inf bucket {le_inf}), "
              f"Scan calls OK {calls['data']['result'][0]['value'][1]}")
        assert int(frames) >= 3, frames
        assert durations == "1" and le_inf == "1", (durations, le_inf)
        assert calls["data"]["result"][0]["value"][1] == "1", calls
        print("PASS")
        return 0
    finally:
        stop_processes(procs)
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
