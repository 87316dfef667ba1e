"""Shared by the operations tests (tests/ops/*_test.py): bounded polling and process clean-up."""
import subprocess
import time

DEADLINE_S = 120  # generous for a loaded 2-core machine; the tests normally need ~10-30 s


def wait_for(what, condition, deadline_s=DEADLINE_S, interval_s=0.2):
    """Polls condition() until it returns a true value; fails the test naming `what` at the deadline."""
    end = time.monotonic() + deadline_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > end:
            raise SystemExit(f"FAIL: timed out after {deadline_s} s waiting for {what}")
        time.sleep(interval_s)  # poll interval, not synchronisation: the condition decides


def stop_processes(procs):
    """SIGTERM in reverse start order, SIGKILL after 30 s."""
    for p in reversed(procs):
        if p.poll() is None:
            p.terminate()
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
