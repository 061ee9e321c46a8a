"""Screenshot of `kinema app` live mode for docs/app.md: the character walking on its own after a left
turn and a speed-up pressed on the keyboard (arrow keys), the readout showing the last command's latency.

Starts the app in this process, opens it in headless Chromium (Debian's chromium-headless-shell,
software WebGL), starts live mode, presses Left and Up on the page and saves it once the steered
frames show.

    python scripts/app_live_screenshot.py --out docs/images/app_live.png
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import kinema  # noqa: E402
from kinema.app.server import AppServer  # noqa: E402
from scripts.app_screenshot import free_port, wait_for  # noqa: E402
from tests.browser import button, launch  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "images" / "app_live.png")
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    server = AppServer(kinema.load_model("default"), port=free_port(), steps=4)
    try:
        with sync_playwright() as p:
            browser = launch(p)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(server.url)
            page.get_by_text("Add prompt").wait_for(timeout=90000)
            wait_for(lambda: server.sessions)
            session = next(iter(server.sessions.values()))
            for folder in ("Timeline", "Generate", "Playback", "Constraints"):  # closed: the Live folder shows whole
                page.get_by_text(folder, exact=True).first.click()
            page.get_by_text("Live", exact=True).click()
            button(page, "Start live").click()
            wait_for(lambda: session.live.run is not None and session.live.run.drawn > 60, timeout=180)
            page.evaluate("document.activeElement && document.activeElement.blur()")
            run = session.live.run
            page.keyboard.press("ArrowLeft")
            page.keyboard.press("ArrowUp")
            page.keyboard.press("ArrowUp")
            drawn = run.drawn
            wait_for(lambda: run.drawn > drawn + 60 and run.latencies, timeout=180)
            notice = page.get_by_text("Software WebGL rendering detected")  # the headless browser's, not a user's
            if notice.count():
                notice.locator("xpath=../..").get_by_role("button").first.click()
            time.sleep(1.0)
            args.out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.out))
            print(f"wrote {args.out}: {session.live.status.content!r}")
            session.live.stop()
            browser.close()
    finally:
        server.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
