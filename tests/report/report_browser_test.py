#!/usr/bin/python3
"""The inspection report in a real headless Chromium (Selenium + chromedriver):
report_sample writes a report of a synthetic step gauge (1024x768 depth map, two measurements
with different verdicts, one profile across a hole); the page is opened from the file, a
full-page screenshot is saved as OUT_DIR/report.png and decoded (stdlib zlib) to check it is not
blank and shows the red NOT OK banner; the DOM is checked: the #verdict element is displayed with
the expected text and colour, both images decoded (naturalWidth), user text came through the
escaping unchanged, the histogram and profile SVGs are laid out, and the browser logged no error
(a Content-Security-Policy violation would be one).

Usage: report_browser_test.py REPORT_SAMPLE OUT_DIR
Exit 77 (CTest: skipped) only when chromium or chromedriver is absent. Nothing sleeps: the page is
static, loaded synchronously by driver.get.
"""
import os
import re
import shutil
import subprocess
import sys
import tempfile

sys.dont_write_bytecode = True  # keep the source tree clean of __pycache__
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from png_stats import decode_png, rgb_pixels  # noqa: E402

EXPECTED_VERDICT = "NOT OK"  # report_sample: step OK, roughness NOT OK
EXPECTED_ROW_VERDICTS = ["OK", "NOT OK"]
RED = (198, 40, 40)  # --nok: #c62828
# The depth map (1024x768) is shown with its map part at 896x672 plus the 110 px colour bar panel;
# the all-in-focus image is at most 1024 px wide, so it stays as it is.
EXPECTED_IMAGE_SIZES = {"depth-preview": (1006, 672), "all-in-focus": (1024, 768)}
DESCRIPTION = "Step gauge 25 µm <type A> & roughness patch (Sa ≤ 0.4 µm)"


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
    report = os.path.join(out_dir, "report.html")
    run = subprocess.run([sample, report, "1024x768"], capture_output=True, text=True, timeout=300)
    check(run.returncode == 0, f"report_sample exited {run.returncode}:\n{run.stdout}\n{run.stderr}")
    print(run.stdout.strip())
    html = open(report, encoding="utf-8").read()
    size = os.path.getsize(report)
    print(f"report {report}: {size} bytes")
    lower = html.lower()
    for bad in ("http://", "https://", "<script"):
        check(bad not in lower, f"the report contains {bad!r}")

    work = tempfile.mkdtemp(prefix="inspect_report_")
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

        verdict = driver.find_element(By.ID, "verdict")
        check(verdict.is_displayed(), "#verdict is not displayed")
        check(verdict.text == EXPECTED_VERDICT, f"#verdict shows {verdict.text!r}, expected {EXPECTED_VERDICT!r}")
        background = driver.execute_script("return getComputedStyle(arguments[0]).backgroundColor;", verdict)
        check(background == "rgb(%d, %d, %d)" % RED, f"#verdict background {background}, expected red")
        rect = verdict.rect
        check(rect["width"] > 200 and rect["height"] > 50, f"#verdict is small: {rect}")
        print(f"#verdict: {verdict.text!r}, background {background}, {rect['width']:.0f}x{rect['height']:.0f} px")

        # Text from the recipe and the request: shown exactly as given, markup characters included.
        shown = driver.find_element(By.ID, "recipe-description").text
        check(shown == DESCRIPTION, f"recipe description shows {shown!r}")
        check(driver.find_element(By.ID, "part-id").text == "GAUGE-2026-0412", "part id")

        images = driver.execute_script(
            "return Array.from(document.images, i => [i.closest('figure').id, i.complete, i.naturalWidth,"
            " i.naturalHeight, i.getBoundingClientRect().width]);")
        check(len(images) == 2, f"expected 2 images, saw {images}")
        for fig, complete, nw, nh, shown_w in images:
            check(complete and nw > 0, f"image {fig} did not load: {images}")
            check((nw, nh) == EXPECTED_IMAGE_SIZES[fig], f"image {fig} is {nw}x{nh}")
            check(shown_w > 300, f"image {fig} is laid out {shown_w} px wide")
        print("images: " + ", ".join(f"{f} {nw}x{nh} (shown {w:.0f} px wide)" for f, _, nw, nh, w in images))

        rows = driver.execute_script(
            "return Array.from(document.querySelectorAll('#measurement-table tbody tr'),"
            " r => Array.from(r.cells, c => c.innerText));")
        check([r[9] for r in rows] == EXPECTED_ROW_VERDICTS, f"measurement verdicts {rows}")
        for r in rows:
            print("measurement: " + " | ".join(r))

        bars = driver.execute_script(
            "return Array.from(document.querySelectorAll('rect.hist-bar'),"
            " b => [Number(b.dataset.count), b.getBoundingClientRect().height]);")
        m = re.search(r"(\d+) of (\d+) pixels with a height", driver.find_element(By.ID, "histogram").text)
        check(m is not None, "histogram caption missing")
        check(len(bars) == 64 and sum(c for c, _ in bars) == int(m.group(1)),
              f"histogram: {len(bars)} bars, counts sum {sum(c for c, _ in bars)}, caption {m.group(0)}")
        check(max(h for _, h in bars) > 50, "histogram bars are not drawn")
        lines = driver.execute_script(
            "return Array.from(document.querySelectorAll('svg.profile-plot polyline.profile-line'),"
            " l => l.points.numberOfItems);")
        check(len(lines) >= 2, f"the profile across the hole should break into segments, saw {lines}")
        print(f"histogram: 64 bars, {m.group(0)}; profile segments (points): {lines}")

        # Full page: the window as tall as the document, then one screenshot.
        height, chrome = driver.execute_script(
            "return [document.documentElement.scrollHeight, window.outerHeight - window.innerHeight];")
        driver.set_window_size(1280, min(int(height) + int(chrome), 8000))
        shot = os.path.join(out_dir, "report.png")
        check(driver.save_screenshot(shot), "screenshot failed")

        errors = [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
        check(not errors, f"browser errors: {errors}")
    finally:
        if driver:
            driver.quit()
        shutil.rmtree(work, ignore_errors=True)

    width, height, bpp, pixels = decode_png(open(shot, "rb").read())
    sample_px = list(rgb_pixels(width, height, bpp, pixels, step=2))
    grey = [(r * 299 + g * 587 + b * 114) / 1000 for r, g, b in sample_px]
    mean = sum(grey) / len(grey)
    sigma = (sum((v - mean) ** 2 for v in grey) / len(grey)) ** 0.5
    colours = len(set(sample_px))
    red = sum(1 for r, g, b in sample_px if abs(r - RED[0]) <= 6 and abs(g - RED[1]) <= 6 and abs(b - RED[2]) <= 6)
    print(f"screenshot {shot}: {width}x{height} px, grey mean {mean:.1f} sigma {sigma:.1f}, "
          f"{colours} distinct colours, {red} red banner pixels (every 2nd px)")
    check(sigma > 20, "the screenshot is nearly uniform")
    check(colours > 1000, "the screenshot has few colours (the images did not render?)")
    check(red > 2000, "no red verdict banner in the screenshot")
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
