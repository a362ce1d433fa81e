"""The screenshots of this folder: ``dtd explore`` on a trained FetchPush dtd run, in Debian's
chromium driven by Playwright, after the first epoch and after the last, with the same block
and goal, and with an episode played from that placement.

    python docs/results/explore/screenshots.py runs/explore-push docs/results/explore
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

from playwright.sync_api import sync_playwright

SETTLED = (
    "v => { const s = window.dtdExplore.state; const c = document.getElementById('table');"
    " return Number(c.dataset.version) > v && !s.inFlight && !s.pending && !s.dragging; }"
)
BLOCK_TO = (1.22, 0.62)
"""Where the block is dragged before the screenshots (from the page's default place)."""


def main(run_dir: str, out: str) -> None:
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    server = subprocess.Popen(
        [sys.executable, "-m", "dtd", "explore", run_dir, "--port", "0"], stdout=subprocess.PIPE, text=True
    )
    try:
        assert server.stdout is not None
        url = re.search(r"http://\S+/", server.stdout.readline()).group(0)
        with sync_playwright() as driver:
            browser = driver.chromium.launch(executable_path="/usr/bin/chromium", args=["--no-sandbox"])
            page = browser.new_page(viewport={"width": 1280, "height": 1020})
            page.goto(url)
            page.wait_for_function(SETTLED, arg=0)
            canvas = page.locator("#table")
            box = canvas.bounding_box()
            start = page.evaluate("window.dtdExplore.toPixels(window.dtdExplore.state.block)")
            target = page.evaluate("p => window.dtdExplore.toPixels(p)", list(BLOCK_TO))
            version = int(canvas.get_attribute("data-version"))
            page.mouse.move(box["x"] + start[0], box["y"] + start[1])
            page.mouse.down()
            page.mouse.move(box["x"] + target[0], box["y"] + target[1], steps=10)
            page.mouse.up()
            page.wait_for_function(SETTLED, arg=version)
            shown = {}
            for name, index in (("last-epoch", None), ("epoch-1", 0)):
                if index is not None:
                    version = int(canvas.get_attribute("data-version"))
                    page.locator("#epoch").fill(str(index))
                    page.wait_for_function(SETTLED, arg=version)
                epoch = canvas.get_attribute("data-epoch")
                page.locator("#play").click()
                page.wait_for_function(
                    "() => { const v = document.getElementById('video');"
                    " return !v.hidden && v.dataset.episode && v.readyState >= 2 && v.currentTime > 1.2; }",
                    timeout=300_000,
                )
                page.evaluate("document.getElementById('video').pause()")
                page.screenshot(path=folder / f"explore-{name}.png", full_page=True)
                shown[name] = {
                    "epoch": int(epoch),
                    "block": json.loads(canvas.get_attribute("data-block")),
                    "goal": json.loads(canvas.get_attribute("data-goal")),
                    "subgoal": json.loads(canvas.get_attribute("data-subgoal")),
                    "answered_in": page.locator("#map-time").inner_text(),
                    "plan": page.locator("#plan").inner_text(),
                }
                page.evaluate("document.getElementById('video').hidden = true")
            browser.close()
        (folder / "screenshots.json").write_text(json.dumps(shown, indent=1) + "\n")
        print(json.dumps(shown, indent=1))
    finally:
        server.terminate()
        server.wait(timeout=30)


if __name__ == "__main__":
    main(*sys.argv[1:3])
