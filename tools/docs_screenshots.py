"""The docs' pictures, made by programs so they can be remade: `python tools/docs_screenshots.py`.

- docs/img/pick_place.png and pick_place_cameras.png: `twin view --screenshot` of fresh runs;
- docs/img/pick_place_joints.png: the plot example of docs/how-to/datasets.md, run as written;
- docs/img/html-report.png: `twin check --html` of recordings/pick_place_mtb.mcap by a copy of
  this checkout's package whose pick point moved 2 mm, in headless Chromium: the top of the page
  and the first diverging field's error charts;
- with `--site OUT_DIR`: the built site (mkdocs build) opened in headless Chromium, screenshots of
  the home page, a how-to and a reference page, to look at before a docs change is done.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMG = ROOT / "docs" / "img"
SITE_PAGES = {"home": "", "how-to": "how-to/ci-goldens/", "reference": "reference/cli/"}


def _twin(*args: str, cwd: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "twin.cli", *args], cwd=cwd, check=True, stdout=subprocess.DEVNULL
    )


def viewer_pictures(work: Path) -> None:
    _twin(
        "run",
        "pick_place",
        "--record",
        "runs/pick_place.mcap",
        "--rrd",
        "runs/pick_place.rrd",
        cwd=work,
    )
    _twin(  # over the committed picture
        "view", "runs/pick_place.rrd", "--screenshot", str(IMG / "pick_place.png"), "--force",
        cwd=work,
    )
    _twin(
        "run",
        "pick_place",
        "--cycles",
        "1",
        "--camera",
        "overhead",
        "--camera",
        "wrist",
        "--record",
        "runs/cameras.mcap",
        "--rrd",
        "runs/cameras.rrd",
        cwd=work,
    )
    _twin(  # over the committed picture
        "view", "runs/cameras.rrd", "--screenshot", str(IMG / "pick_place_cameras.png"), "--force",
        cwd=work,
    )


def plot_picture(work: Path) -> None:
    page = (ROOT / "docs" / "how-to" / "datasets.md").read_text(encoding="utf-8")
    code = re.search(
        r"```python\n(import matplotlib\.pyplot as plt\n.*?)```", page, re.DOTALL
    ).group(1)
    (work / "recordings").symlink_to(ROOT / "recordings")
    (work / "docs" / "img").mkdir(parents=True)
    subprocess.run(
        [sys.executable, "-c", code], cwd=work, check=True, env={"MPLBACKEND": "Agg", "PATH": ""}
    )
    (IMG / "pick_place_joints.png").write_bytes(
        (work / "docs" / "img" / "pick_place_joints.png").read_bytes()
    )


def report_picture(work: Path) -> None:
    """The HTML report of a golden that differs (docs/how-to/ci-goldens.md shows it)."""
    from PIL import Image
    from playwright.sync_api import sync_playwright

    shutil.copytree(ROOT / "twin", work / "twin", ignore=shutil.ignore_patterns("__pycache__"))
    task = work / "twin" / "tasks" / "pick_place.py"
    moved = task.read_text().replace("POINT_A_M = (0.2, 0.7)", "POINT_A_M = (0.202, 0.7)")
    assert moved != task.read_text()
    task.write_text(moved)
    (work / "recordings").symlink_to(ROOT / "recordings")
    done = subprocess.run(
        [sys.executable, "-m", "twin.cli", "check", "recordings/pick_place_mtb.mcap", "--html",
         "r.html"], cwd=work, env={**os.environ, "PYTHONPATH": str(work)}, capture_output=True,
        check=False,
    )
    assert done.returncode == 1, done.stdout
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1150, "height": 900})
        page.route("**/*", lambda r: r.continue_() if r.request.url.startswith("file:")
                   else r.abort())
        page.goto((work / "r.html").as_uri())
        page.wait_for_selector("div.chart[data-drawn]")
        page.screenshot(path=str(work / "full.png"), full_page=True)
        top = page.locator(".grid2").first.bounding_box()["y"]
        charts = page.locator(".grid2").first.locator("div.chart")
        error = charts.nth(charts.count() - 1).bounding_box()  # the error around the onset
        browser.close()
    full = Image.open(work / "full.png").convert("RGB")
    head = full.crop((0, 0, full.width, int(top)))
    errors = full.crop((0, int(error["y"]), full.width, int(error["y"] + error["height"])))
    out = Image.new("RGB", (full.width, head.height + errors.height), "white")
    out.paste(head, (0, 0))
    out.paste(errors, (0, head.height))
    out.quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(
        IMG / "html-report.png", optimize=True
    )


def site_pictures(out: Path) -> list[Path]:
    """Build the site, serve it on 127.0.0.1 and screenshot three pages with headless Chromium."""
    from playwright.sync_api import sync_playwright

    site = out / "site"
    subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT,
        check=True,
        capture_output=True,
    )
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    shots = []
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path="/usr/bin/chromium")
            page = browser.new_page(viewport={"width": 1280, "height": 900})
            for name, path in SITE_PAGES.items():
                page.goto(f"http://127.0.0.1:{server.server_port}/{path}")
                page.wait_for_load_state("networkidle")
                shots.append(out / f"site-{name}.png")
                page.screenshot(path=str(shots[-1]))
            browser.close()
    finally:
        server.shutdown()
    return shots


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="docs_screenshots", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--site", metavar="OUT_DIR", help="also screenshot the built site into OUT_DIR"
    )
    parser.add_argument("--only-site", action="store_true", help="only the site's screenshots")
    args = parser.parse_args(argv)
    if not args.only_site:
        with tempfile.TemporaryDirectory() as tmp:
            viewer_pictures(Path(tmp))
        with tempfile.TemporaryDirectory() as tmp:
            plot_picture(Path(tmp))
        with tempfile.TemporaryDirectory() as tmp:
            report_picture(Path(tmp))
    if args.site or args.only_site:
        out = Path(args.site or ".")
        out.mkdir(parents=True, exist_ok=True)
        for shot in site_pictures(out):
            print(f"wrote {shot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
