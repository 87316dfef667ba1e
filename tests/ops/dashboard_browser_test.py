#!/usr/bin/python3
"""The dashboard in a real headless Chromium (Selenium + chromedriver) against a running inspectd
with a bearer token: the page asks for the token, then shows the rig; a scan started through gRPC
(inspectctl) makes the live frame counter advance without a reload and ends as a SUCCEEDED row
with its depth preview in the recent jobs. Saves dashboard_live.png and dashboard_done.png in
WORK_DIR.

Usage: dashboard_browser_test.py INSPECTD INSPECTCTL WORK_DIR
Exit 77 (CTest: skipped) only when chromium or chromedriver is absent. Waits poll conditions
against deadlines (WebDriverWait); nothing sleeps to synchronise.
"""
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ops_common import DEADLINE_S, stop_processes, wait_for  # noqa: E402


def main():
    if len(sys.argv) < 4:
        raise SystemExit(__doc__)
    inspectd, inspectctl, out_dir = sys.argv[1], sys.argv[2], sys.argv[3]
    chromium = shutil.which("chromium")
    chromedriver = shutil.which("chromedriver")
    if not chromium or not chromedriver:
        print("SKIP: chromium or chromedriver not installed (apt-get install chromium chromium-driver)")
        return 77
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.common.exceptions import StaleElementReferenceException
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    os.makedirs(out_dir, exist_ok=True)
    work = tempfile.mkdtemp(prefix="inspect_dashboard_")
    procs, driver = [], None
    try:
        token = "dashboard-test-token"
        token_file = os.path.join(work, "token")
        with open(token_file, "w") as f:
            f.write(token + "\n")
        log_path = os.path.join(work, "inspectd.log")
        procs.append(subprocess.Popen(
            [inspectd, "--listen", "127.0.0.1:0", "--http-listen", "127.0.0.1:0", "--data-dir",
             os.path.join(work, "data"), "--auth-token-file", token_file, "--camera-size", "1024x768"],
            stdout=open(log_path, "w"), stderr=subprocess.STDOUT, env={}))

        def announced():
            text = open(log_path).read()
            if procs[0].poll() is not None:
                raise SystemExit("FAIL: inspectd exited:\n" + text)
            g = re.search(r"^inspectd listening on (\S+)$", text, re.M)
            h = re.search(r"^inspectd http on (http://\S+/)$", text, re.M)
            return (g.group(1), h.group(1)) if g and h else None
        grpc_addr, url = wait_for("inspectd to announce its ports", announced)
        print(f"inspectd gRPC {grpc_addr}, dashboard {url}")

        options = webdriver.ChromeOptions()
        options.binary_location = chromium
        for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                    "--window-size=1400,1100", f"--user-data-dir={os.path.join(work, 'chrome-profile')}"):
            options.add_argument(arg)
        driver = webdriver.Chrome(service=Service(chromedriver), options=options)
        driver.get(url)
        # Survives only as long as the page is not reloaded: checked at the end.
        driver.execute_script("window.inspectTestMarker = 'loaded once';")
        # The page redraws its tables on every poll, so an element found a moment ago may be gone:
        # checks read the page in one script where they can, and a stale element is retried.
        wait = WebDriverWait(driver, DEADLINE_S, poll_frequency=0.1,
                             ignored_exceptions=[StaleElementReferenceException])

        # Without the token the data endpoints answer 401 and the page asks for it.
        token_input = wait.until(lambda d: d.find_element(By.ID, "token-input")
                                 if d.find_element(By.ID, "token-form").is_displayed() else False)
        token_input.send_keys(token)
        driver.find_element(By.ID, "token-submit").click()
        wait.until(lambda d: d.find_element(By.ID, "rig-state").text == "READY")
        devices = driver.execute_script(
            "return Array.from(document.querySelectorAll('#devices tbody tr'), r => r.innerText.replace(/\\s+/g, ' '));")
        assert len(devices) == 3, f"expected camera, projector and stage, saw {devices}"
        print("rig READY, devices: " + "; ".join(devices))

        # A long scan through gRPC (a fine z step at 1024x768), so the browser's polls see it run.
        scan = subprocess.Popen([inspectctl, "--server", grpc_addr, "--token-file", token_file, "scan", "--out",
                                 os.path.join(work, "scan"), "--z-step", "1", "--label", "browser-test"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        procs.append(scan)

        def counter():
            text = driver.find_element(By.ID, "frame-counter").text
            m = re.match(r"(\d+) / (\d+)$", text)
            return (int(m.group(1)), int(m.group(2))) if m else None
        first = wait.until(lambda d: counter())
        # Read in one script call: the live panel re-renders on every poll, so an element found
        # first and read afterwards can already be stale.
        def text_of(element_id):
            return driver.execute_script("return document.getElementById(arguments[0]).innerText;", element_id)
        job_id = text_of("live-job-id")
        later = wait.until(lambda d: (c := counter()) and c[0] > first[0] and c)
        print(f"live job {job_id}: frame counter {first[0]} / {first[1]} advanced to {later[0]} / {later[1]}"
              f" without a reload; mean grey {text_of('live-mean')}")
        wait.until(lambda d: d.find_element(By.ID, "live-thumbnail").get_attribute("src").startswith("blob:"))
        driver.save_screenshot(os.path.join(out_dir, "dashboard_live.png"))

        out, err = scan.communicate(timeout=DEADLINE_S * 3)
        assert scan.returncode == 0, f"inspectctl scan exited {scan.returncode}:\n{out}\n{err}"
        row_selector = f'#jobs tbody tr[data-job-id="{job_id}"]'
        wait.until(lambda d: d.execute_script(
            "const r = document.querySelector(arguments[0]); return r && r.dataset.state;", row_selector) == "SUCCEEDED")
        wait.until(lambda d: d.execute_script(
            "const i = document.querySelector(arguments[0] + ' img'); return !!i && i.complete && i.naturalWidth > 0;",
            row_selector))
        row_text = driver.execute_script("return document.querySelector(arguments[0]).innerText;", row_selector)
        print("finished job row: " + row_text.replace("\n", " | ").replace("\t", " | "))
        verdict = driver.execute_script(
            "return document.querySelector(arguments[0] + ' td.verdict').innerText;", row_selector)
        assert verdict == "", f"a scan without a recipe has no verdict, the row shows {verdict!r}"

        # A recipe scan: the default specimen skew5 is a plane tilted by 5.000 deg, the recipe
        # accepts 5 +-0.5 deg, so its row shows the overall verdict OK (JobResult.inspection).
        recipe_file = os.path.join(work, "tilt-check.json")
        with open(recipe_file, "w") as f:
            json.dump({"recipe_id": "tilt-check", "scan": {"z_step_um": 10},
                       "measurements": [{"name": "tilt", "parameter": "tilt",
                                         "tolerance": {"nominal": 5.0, "lower": -0.5, "upper": 0.5}}]}, f)
        ctl = [inspectctl, "--server", grpc_addr, "--token-file", token_file]
        for args in (["recipe", "create", recipe_file],
                     ["scan", "--recipe", "tilt-check", "--part-id", "P-4711", "--out", os.path.join(work, "part")]):
            r = subprocess.run(ctl + args, capture_output=True, text=True, timeout=DEADLINE_S * 3)
            assert r.returncode == 0, f"inspectctl {' '.join(args)} exited {r.returncode}:\n{r.stdout}\n{r.stderr}"
        m = re.search(r"^job (\S+) ", r.stdout, re.M) or re.search(r"(scan-[0-9a-f]+)", r.stdout)
        assert m, f"no job id in inspectctl's output:\n{r.stdout}"
        recipe_job = m.group(1)
        print(f"recipe scan {recipe_job}: " + next(l for l in r.stdout.splitlines() if l.startswith("inspection:")))
        recipe_row = f'#jobs tbody tr[data-job-id="{recipe_job}"]'
        shown = wait.until(lambda d: d.execute_script(
            "const r = document.querySelector(arguments[0]);"
            "return r && r.dataset.verdict && [r.dataset.verdict, r.querySelector('td.verdict').innerText];",
            recipe_row))
        assert shown == ["OK", "OK"], f"recipe scan row: data-verdict / verdict text {shown}"
        print(f"recipe scan row shows verdict {shown[1]}")
        wait.until(lambda d: not d.find_element(By.ID, "live-view").is_displayed())
        path = os.path.join(out_dir, "dashboard_done.png")
        driver.save_screenshot(path)
        assert driver.execute_script("return window.inspectTestMarker") == "loaded once", "the page was reloaded"
        print(f"screenshots: {os.path.join(out_dir, 'dashboard_live.png')}, {path}")
        print("PASS")
        return 0
    finally:
        if driver:
            driver.quit()
        stop_processes(procs)
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
