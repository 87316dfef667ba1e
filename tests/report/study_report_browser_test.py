#!/usr/bin/python3
"""The Type-1 study report in a real headless Chromium (Selenium + chromedriver):
study_report_sample writes a report of 25 repeats of a step standard (one measurement not
capable, one capable) and prints the values and figures it put in; the page is opened from the
file and checked: #capability shows NOT CAPABLE on red, each measurement's run chart has one point
per repeat carrying exactly the printed value, laid out left to right in repeat order with the
reference and +-0.1 T lines drawn, its histogram's counts sum to the repeats, Cg and Cgk as
printed, user text came through the escaping unchanged, no browser error; a full-page screenshot
(OUT_DIR/study_report.png) is decoded and must show the red banner.

Usage: study_report_browser_test.py STUDY_REPORT_SAMPLE OUT_DIR
Exit 77 (CTest: skipped) only when chromium or chromedriver is absent. Nothing sleeps: the page is
static, loaded synchronously by driver.get.
"""
import os
import shutil
import subprocess
import sys
import tempfile

sys.dont_write_bytecode = True
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from png_stats import decode_png, rgb_pixels  # noqa: E402

RED = (198, 40, 40)  # --nok: #c62828
DESCRIPTION = "PGR step standard 1 um <ISO 5436-1 type A> & friends"


def check(condition, message):
    if not condition:
        raise SystemExit("FAIL: " + message)


def main():
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    sample, out_dir = sys.argv[1], sys.argv[2]
    chromium = shutil.which("chromium")
    chromedriver = shutil.which("chromedriver")
    if not chromium or not chromedriver:
        print("SKIP: chromium or chromedriver not installed (apt-get install chromium chromium-driver)")
        return 77
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By

    os.makedirs(out_dir, exist_ok=True)
    report = os.path.join(out_dir, "study_report.html")
    run = subprocess.run([sample, report], capture_output=True, text=True, timeout=120)
    check(run.returncode == 0, f"study_report_sample exited {run.returncode}:\n{run.stdout}\n{run.stderr}")
    values, figures = {}, {}
    for line in run.stdout.splitlines():
        parts = line.split()
        if parts and parts[0] == "values":
            values[parts[1]] = [float(v) for v in parts[2:]]
        elif parts and parts[0] == "figures":
            figures[parts[1]] = (float(parts[2]), float(parts[3]), parts[4] == "1")
    print(run.stdout.splitlines()[0])
    check(set(values) == {"step", "step_wide"}, f"sample printed {sorted(values)}")
    lower = open(report, encoding="utf-8").read().lower()
    for bad in ("http://", "https://", "<script"):
        check(bad not in lower, f"the report contains {bad!r}")

    work = tempfile.mkdtemp(prefix="inspect_study_report_")
    driver = None
    try:
        options = webdriver.ChromeOptions()
        options.binary_location = chromium
        for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                    "--window-size=1280,1000", "--hide-scrollbars",
                    f"--user-data-dir={os.path.join(work, 'chrome-profile')}"):
            options.add_argument(arg)
        options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
        driver = webdriver.Chrome(service=Service(chromedriver), options=options)
        driver.get("file://" + os.path.abspath(report))

        banner = driver.find_element(By.ID, "capability")
        check(banner.is_displayed() and banner.text == "NOT CAPABLE", f"#capability shows {banner.text!r}")
        background = driver.execute_script("return getComputedStyle(arguments[0]).backgroundColor;", banner)
        check(background == "rgb(%d, %d, %d)" % RED, f"#capability background {background}")
        shown = driver.find_element(By.CSS_SELECTOR, "p.description").text
        check(shown == DESCRIPTION, f"description shows {shown!r}")
        check("PGR-0815 <certified>" in driver.find_element(By.CSS_SELECTOR, ".ident").text, "part id escaping")

        for section in driver.find_elements(By.CSS_SELECTOR, "section.study-measurement"):
            name = section.get_attribute("data-name")
            points = driver.execute_script(
                "return Array.from(arguments[0].querySelectorAll('svg.run-chart circle.run-point'),"
                " p => [Number(p.dataset.repeat), Number(p.dataset.value), p.getBoundingClientRect().x,"
                " p.getBoundingClientRect().width]);", section)
            check(len(points) == 25, f"{name}: {len(points)} run-chart points")
            check([p[0] for p in points] == list(range(1, 26)), f"{name}: repeats out of order")
            for (_, v, _, _), want in zip(points, values[name]):
                check(abs(v - want) <= 1e-9 * max(1.0, abs(want)), f"{name}: point {v} != value {want}")
            xs = [p[2] for p in points]
            check(all(b > a for a, b in zip(xs, xs[1:])), f"{name}: points not laid out left to right")
            check(all(p[3] > 0 for p in points), f"{name}: points not drawn")
            refs = section.find_elements(By.CSS_SELECTOR, "svg.run-chart line.run-reference")
            limits = section.find_elements(By.CSS_SELECTOR, "svg.run-chart line.run-limit")
            check(len(refs) == 1 and len(limits) == 2, f"{name}: reference / limit lines {len(refs)} / {len(limits)}")
            counts = driver.execute_script(
                "return Array.from(arguments[0].querySelectorAll('svg.value-histogram rect.hist-bar'),"
                " b => Number(b.dataset.count));", section)
            check(sum(counts) == 25 and len(counts) >= 5, f"{name}: histogram counts {counts}")
            cg = float(section.find_element(By.CSS_SELECTOR, ".cg").text)
            cgk = float(section.find_element(By.CSS_SELECTOR, ".cgk").text)
            want_cg, want_cgk, capable = figures[name]
            check(abs(cg - want_cg) < 6e-4 and abs(cgk - want_cgk) < 6e-4, f"{name}: Cg {cg} Cgk {cgk}")
            tag = section.find_element(By.CSS_SELECTOR, "h2 .tag").text
            check(tag == ("capable" if capable else "not capable"), f"{name}: tag {tag!r}")
            print(f"{name}: 25 points as printed, histogram {counts}, Cg {cg:.3f} Cgk {cgk:.3f}, {tag}")

        height, chrome = driver.execute_script(
            "return [document.documentElement.scrollHeight, window.outerHeight - window.innerHeight];")
        driver.set_window_size(1280, min(int(height) + int(chrome), 8000))
        shot = os.path.join(out_dir, "study_report.png")
        check(driver.save_screenshot(shot), "screenshot failed")
        errors = [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
        check(not errors, f"browser errors: {errors}")
    finally:
        if driver:
            driver.quit()
        shutil.rmtree(work, ignore_errors=True)

    width, height, bpp, pixels = decode_png(open(shot, "rb").read())
    sample_px = list(rgb_pixels(width, height, bpp, pixels, step=2))
    red = sum(1 for r, g, b in sample_px if abs(r - RED[0]) <= 6 and abs(g - RED[1]) <= 6 and abs(b - RED[2]) <= 6)
    print(f"screenshot {shot}: {width}x{height} px, {red} red banner pixels (every 2nd px)")
    check(red > 1000, "no red banner in the screenshot")
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
