"""Screenshot of the browser viewer for the docs: two Stanford bunny scans registered by
``register()``, served by ``o3d_rpointhop.viewer`` and photographed in Debian's headless
Chromium (playwright). Needs the shared data, viser and playwright.

Usage::

    .venv/bin/python scripts/viewer_screenshot.py [--output docs/images/viewer.png]
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from playwright.sync_api import sync_playwright

from o3d_rpointhop import register
from o3d_rpointhop.datasets.bunny import load_bunny
from o3d_rpointhop.viewer import show_registration

FLAGS = [
    "--headless=new",
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path, default=Path("docs/images/viewer.png"))
    args = parser.parse_args()
    scans = load_bunny(("bun000", "bun045"))
    source, target = scans["bun045"].points, scans["bun000"].points
    result = register(source, target)
    server = show_registration(source, target, result, port=8765, block=False)
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=shutil.which("chromium"), args=FLAGS)
            page = browser.new_page(viewport={"width": 1200, "height": 750})
            page.goto("http://127.0.0.1:8765")
            page.wait_for_selector("canvas")
            page.get_by_role("checkbox").nth(0).click()  # the source as given
            page.get_by_role("checkbox").nth(3).click()  # the matches the global step kept
            page.wait_for_timeout(3000)
            notice = page.get_by_text("Software WebGL rendering detected")
            if notice.count():  # a headless browser renders without a GPU: close the notice
                box = notice.first.bounding_box()
                page.mouse.click(box["x"] + 253, box["y"] + 49)
            page.wait_for_timeout(500)
            page.screenshot(path=str(args.output))
            browser.close()
    finally:
        server.stop()
    print(f"written: {args.output}")


if __name__ == "__main__":
    main()
