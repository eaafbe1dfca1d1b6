#!/usr/bin/env python3
"""Open validation/out/report.html in headless Chromium and check that it renders: every
image decoded, one verdict row per result in summary.json, the curves and the efficiency
table present. Also saves a screenshot (report.png) for people."""
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def chromium():
    for name in ("chromium", "chromium-browser", "google-chrome"):
        p = shutil.which(name)
        if p:
            return p
    sys.exit("check_report: no Chromium found (Debian: apt-get install chromium); the report was not checked")


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(HERE, "out")
    report = os.path.join(out, "report.html")
    with open(os.path.join(out, "summary.json")) as f:
        summary = json.load(f)
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", "--allow-file-access-from-files", "--virtual-time-budget=10000"]
    with tempfile.TemporaryDirectory() as profile:
        dom = subprocess.run([chromium(), *flags, f"--user-data-dir={profile}", "--dump-dom", "file://" + report], capture_output=True, text=True, timeout=120)
        subprocess.run([chromium(), *flags, f"--user-data-dir={profile}", f"--screenshot={os.path.join(out, 'report.png')}", "--window-size=1400,1000", "file://" + report], capture_output=True, text=True, timeout=120)
    html = dom.stdout
    m = re.search(r'data-images="(\d+)" data-images-ok="(\d+)"', html)
    if not m:
        sys.exit(f"check_report: the page did not finish loading in Chromium (no image count in the DOM): {dom.stderr[-500:]}")
    total, ok = int(m.group(1)), int(m.group(2))
    # One row with data-result per result in summary.json, across the tables.
    verdict_rows = len(re.findall(r"<tr data-result(?:=\"\")?>", html))
    problems = []
    if total == 0 or ok != total:
        problems.append(f"{total - ok} of {total} images did not render")
    if verdict_rows != len(summary["results"]):
        problems.append(f"verdict table has {verdict_rows} rows, summary.json {len(summary['results'])} results")
    # Curves plot relMSE on a log scale: a scene whose images are all exact (a black one) has none.
    plotted = any(p.get("rel_mse", 0) > 0 and p.get("seconds", 0) > 0 for r in summary["results"] for p in r.get("curve") or [])
    if 'id="efficiency"' not in html or (plotted and "<polyline" not in html):
        problems.append("efficiency table or error curves missing")
    if problems:
        sys.exit("check_report: " + "; ".join(problems))
    print(f"check_report: Chromium rendered {report}: {ok} images, {verdict_rows} verdict rows, curves and efficiency table")


if __name__ == "__main__":
    main()
