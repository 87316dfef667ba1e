#!/usr/bin/python3
"""A factory MES talking to inspectd (inspection.v1) with Debian's python3-grpcio only.

What an MES integration does, end to end:
  1. stores its recipe (CreateRecipe; UpdateRecipe makes a new version when it exists),
  2. follows the result feed (WatchResults) from the last sequence number it processed, so a
     restart or a network break loses no result and repeats none (--state keeps the number),
  3. scans each part (Scan with part_id, recipe_id, station) as the part arrives,
  4. for each result: prints the verdict and the measurements, downloads the HTML report
     (DownloadArtifact, sha256 checked) and records the sequence number.

Stubs: examples/python/generate_stubs.sh DIR, then --stubs DIR (Debian 12's python3-grpc-tools
cannot compile proto3 `optional`; Debian's protoc with grpc_python_plugin can).

  mes_client.py --server HOST:PORT --stubs DIR --recipe recipe.json --out reports \\
                --part P-1 --part P-2 [--station line-2] [--state mes.state] [--token-file F]
  On the simulated rig, --part ID=SPECIMEN loads that specimen first (SetSpecimen).

Output: one "RESULT ..." line per inspection, then its measurements; exit 0 when every part's
result arrived, 1 when a scan failed, 2 on bad usage, 3 when the server is unreachable.
"""
import argparse
import hashlib
import json
import os
import queue
import sys
import threading
import time


def parse_args():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--server", default="localhost:50051")
    p.add_argument("--stubs", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "stubs"))
    p.add_argument("--recipe", required=True, help="recipe document (protobuf JSON of inspection.v1.Recipe)")
    p.add_argument("--part", action="append", required=True, help="part id, or ID=SPECIMEN on the simulated rig")
    p.add_argument("--station", default="mes-example")
    p.add_argument("--out", default="reports", help="folder for the downloaded HTML reports")
    p.add_argument("--state", help="file keeping the last result sequence processed (resume point)")
    p.add_argument("--ca", help="CA certificate (PEM) for TLS")
    p.add_argument("--cert", help="client certificate (PEM) for mTLS")
    p.add_argument("--key", help="client key (PEM) for mTLS")
    p.add_argument("--token-file", help="bearer token file")
    p.add_argument("--timeout", type=float, default=600.0, help="seconds to wait for all results")
    return p.parse_args()


class Mes:
    def __init__(self, args, pb, rpc, grpc):
        self.args, self.pb, self.grpc = args, pb, grpc
        self.metadata = []
        if args.token_file:
            with open(args.token_file) as f:
                self.metadata.append(("authorization", "Bearer " + f.read().strip()))
        if args.ca:
            read = lambda path: open(path, "rb").read() if path else None
            creds = grpc.ssl_channel_credentials(read(args.ca), read(args.key), read(args.cert))
            self.channel = grpc.secure_channel(args.server, creds)
        else:
            self.channel = grpc.insecure_channel(args.server)
        self.inspection = rpc.InspectionServiceStub(self.channel)
        self.simulation = rpc.SimulationServiceStub(self.channel)
        self.results = queue.Queue()
        self.stop = threading.Event()

    # --- recipe -------------------------------------------------------------------------------
    def store_recipe(self):
        from google.protobuf import json_format
        with open(self.args.recipe) as f:
            recipe = json_format.Parse(f.read(), self.pb.Recipe())  # unknown fields are errors
        try:
            stored = self.inspection.CreateRecipe(self.pb.CreateRecipeRequest(recipe=recipe), metadata=self.metadata)
        except self.grpc.RpcError as e:
            if e.code() != self.grpc.StatusCode.ALREADY_EXISTS:
                raise
            stored = self.inspection.UpdateRecipe(self.pb.UpdateRecipeRequest(recipe=recipe), metadata=self.metadata)
        print(f"recipe {stored.recipe_id} version {stored.version} stored", flush=True)
        return stored

    # --- result feed --------------------------------------------------------------------------
    def start_sequence(self):
        if self.args.state and os.path.exists(self.args.state):
            with open(self.args.state) as f:
                return int(f.read().strip() or 0)
        # A new MES starts at the newest stored result: older ones belong to someone else's run.
        newest = self.inspection.ListResults(self.pb.ListResultsRequest(page_size=1), metadata=self.metadata)
        return newest.results[0].sequence if newest.results else 0

    def follow(self, after):
        """Feeds self.results; reconnects with the last sequence received after a break."""
        while not self.stop.is_set():
            call = self.inspection.WatchResults(self.pb.WatchResultsRequest(after_sequence=after),
                                                metadata=self.metadata)
            self.call = call
            try:
                for result in call:
                    after = result.sequence
                    self.results.put(result)
            except self.grpc.RpcError as e:
                if self.stop.is_set() or e.code() == self.grpc.StatusCode.CANCELLED:
                    return
                if e.code() not in (self.grpc.StatusCode.UNAVAILABLE, self.grpc.StatusCode.INTERNAL):
                    self.results.put(e)
                    return
                print(f"feed interrupted ({e.code().name}); resuming after {after}", flush=True)
                time.sleep(1.0)  # reconnect back-off

    # --- scans --------------------------------------------------------------------------------
    def scan(self, part, specimen, recipe_id):
        if specimen:
            self.simulation.SetSpecimen(self.pb.SetSpecimenRequest(specimen=specimen), metadata=self.metadata)
        request = self.pb.ScanRequest(part_id=part, recipe_id=recipe_id, station=self.args.station,
                                      request_id=f"mes-{part}-{int(time.time() * 1000)}")
        job = None
        for event in self.inspection.Scan(request, metadata=self.metadata):
            if event.HasField("job") and event.job.state >= self.pb.JOB_STATE_SUCCEEDED:
                job = event.job
        return job

    # --- reports ------------------------------------------------------------------------------
    def download(self, artifact_id, path):
        digest, expected = hashlib.sha256(), None
        with open(path + ".part", "wb") as f:
            for chunk in self.inspection.DownloadArtifact(self.pb.DownloadArtifactRequest(artifact_id=artifact_id),
                                                          metadata=self.metadata):
                f.write(chunk.data)
                digest.update(chunk.data)
                expected = chunk.sha256
        if expected and digest.hexdigest() != expected:
            os.remove(path + ".part")
            raise RuntimeError(f"report {artifact_id}: sha256 mismatch")
        os.replace(path + ".part", path)

    def record(self, result):
        pb = self.pb
        verdict = pb.Verdict.Name(result.verdict).replace("VERDICT_", "")
        report = ""
        if result.report_artifact_id:
            report = os.path.join(self.args.out, f"{result.part_id or 'part'}_{result.sequence}.html")
            self.download(result.report_artifact_id, report)
        print(f"RESULT seq={result.sequence} part={result.part_id} recipe={result.recipe_id} "
              f"v{result.recipe_version} verdict={verdict} job={result.job_id} report={report}", flush=True)
        for m in result.measurements:
            value = f"{m.value:.4g} {m.unit} U {m.expanded_uncertainty:.2g}" if m.measured else "not measured"
            print(f"  {m.name}: {value}, coverage {m.coverage_percent:.1f} %, "
                  f"{pb.Verdict.Name(m.verdict).replace('VERDICT_', '')} ({m.reason})", flush=True)
            if m.capability_warning:
                print(f"    warning: {m.capability_warning}", flush=True)
        if self.args.state:
            with open(self.args.state + ".tmp", "w") as f:
                f.write(str(result.sequence))
            os.replace(self.args.state + ".tmp", self.args.state)
        return verdict


def main():
    args = parse_args()
    sys.path.insert(0, args.stubs)
    try:
        import grpc
        from inspection.v1 import inspection_pb2 as pb
        from inspection.v1 import inspection_pb2_grpc as rpc
    except ImportError as e:
        print(f"mes_client: {e} (install python3-grpcio; generate stubs with generate_stubs.sh)", file=sys.stderr)
        return 2
    os.makedirs(args.out, exist_ok=True)
    mes = Mes(args, pb, rpc, grpc)
    try:
        grpc.channel_ready_future(mes.channel).result(timeout=30)
    except grpc.FutureTimeoutError:
        print(f"mes_client: server {args.server} unreachable", file=sys.stderr)
        return 3
    try:
        recipe = mes.store_recipe()
        after = mes.start_sequence()
    except grpc.RpcError as e:
        print(f"mes_client: {e.code().name}: {e.details()}", file=sys.stderr)
        return 1
    print(f"following results after sequence {after}", flush=True)
    feed = threading.Thread(target=mes.follow, args=(after,), daemon=True)
    feed.start()

    waiting, verdicts, failed = {}, {}, False
    for spec in args.part:
        part, _, specimen = spec.partition("=")
        try:
            job = mes.scan(part, specimen, recipe.recipe_id)
        except grpc.RpcError as e:
            print(f"scan of {part}: {e.code().name}: {e.details()}", flush=True)
            failed = True
            continue
        if job is None or job.state != pb.JOB_STATE_SUCCEEDED:
            print(f"scan of {part}: {pb.JobState.Name(job.state) if job else 'no terminal event'}"
                  f" {job.error_message if job else ''}", flush=True)
            failed = True
            continue
        print(f"scanned {part}: job {job.job_id}", flush=True)
        waiting[job.job_id] = part

    deadline = time.monotonic() + args.timeout
    while waiting and time.monotonic() < deadline:
        try:
            item = mes.results.get(timeout=max(0.1, deadline - time.monotonic()))
        except queue.Empty:
            break
        if isinstance(item, Exception):
            print(f"mes_client: feed failed: {item.code().name}: {item.details()}", file=sys.stderr)
            return 1
        verdicts[item.part_id] = mes.record(item)
        waiting.pop(item.job_id, None)
    mes.stop.set()
    if hasattr(mes, "call"):
        mes.call.cancel()
    print("verdicts: " + " ".join(f"{p}={v}" for p, v in verdicts.items()), flush=True)
    if waiting:
        print(f"mes_client: no result for {sorted(waiting.values())}", file=sys.stderr)
        return 1
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
