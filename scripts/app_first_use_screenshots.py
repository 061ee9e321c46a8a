"""Screenshots of `kinema app`'s first-use behaviour for docs/app.md (issues 33, 36, 39): a generation in
progress with its Cancel button, a session file refused whole, a generated walk framed and playing, a
humanoid character (Quaternius Character.glb) playing a generated walk on its skin, and the G1 robot
beside each sample (``--robot g1``).

    python scripts/app_first_use_screenshots.py --out-dir docs/images
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import kinema  # noqa: E402
from kinema.app.generation import AppRobot  # noqa: E402
from kinema.app.rigs import load_rig  # noqa: E402
from kinema.app.server import AppServer  # noqa: E402
from kinema.robot import load_robot  # noqa: E402
from scripts.app_screenshot import free_port, wait_for  # noqa: E402
from tests.browser import button, launch, row_input  # noqa: E402

CHARACTER = REPO.parent / "shared" / "datasets" / "quaternius" / "cyberpunk_pack" / "Character.glb"


def open_page(browser, app):
    page = browser.new_page(viewport={"width": 1500, "height": 1000})
    page.goto(app.url)
    page.get_by_text("Add prompt").wait_for(timeout=60000)
    wait_for(lambda: bool(app.sessions))
    return page, next(iter(app.sessions.values()))


def close_notifications(page) -> None:
    for close in page.locator(".mantine-Notification-closeButton").all():
        close.click()
    time.sleep(0.4)


def generate_and_pause(page, session, pause_at: int = 40) -> None:
    button(page, "Generate").click()
    wait_for(lambda: session.job is None and session.generated, timeout=600)
    wait_for(lambda: session.player.frame >= pause_at, timeout=30)
    button(page, "Pause").click()
    time.sleep(1.0)


def shoot_cancel_and_bad_session(browser, app, out: Path) -> None:
    page, session = open_page(browser, app)
    close_notifications(page)
    box = row_input(page, "Steps")
    box.fill("300")
    box.press("Enter")
    button(page, "Generate").click()
    wait_for(lambda: "step " in session.status.content and session.progress.value > 3)
    time.sleep(0.5)
    page.screenshot(path=str(out / "app_cancel.png"), timeout=180000)  # the CPU is busy generating
    button(page, "Cancel").click()
    wait_for(lambda: session.job is None)
    page.get_by_text("Files", exact=True).click()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "long_session.json"
        path.write_text(json.dumps({"kinema_session": 1, "timeline": [{"prompt": "A person walks.", "seconds": 500}]}))
        with page.expect_file_chooser() as fc:
            button(page, "Load session").click()
        fc.value.set_files(path)
        page.get_by_text("a segment lasts").first.wait_for(timeout=10000)
        time.sleep(0.6)
        page.screenshot(path=str(out / "app_bad_session.png"))
    page.close()


def shoot_generated(browser, app, out: Path, name: str) -> None:
    page, session = open_page(browser, app)
    close_notifications(page)
    generate_and_pause(page, session)
    close_notifications(page)
    page.screenshot(path=str(out / name), timeout=120000)
    page.close()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out-dir", type=Path, default=REPO / "docs" / "images")
    parser.add_argument("--steps", type=int, default=10, help="DDIM steps (default 10)")
    args = parser.parse_args()
    from playwright.sync_api import sync_playwright

    args.out_dir.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)  # leave a core to the software-rendering browser
    model = kinema.load_model("default")
    apps = {
        "app_framed.png": AppServer(model, port=free_port(), steps=args.steps),
        "app_character.png": AppServer(model, rig=load_rig(CHARACTER, fps=model.fps), port=free_port(),
                                       steps=args.steps),
        "app_robot.png": AppServer(model, port=free_port(), steps=args.steps,
                                   robot=AppRobot("g1", load_robot("g1"))),
    }
    try:
        with sync_playwright() as p:
            browser = launch(p)
            shoot_cancel_and_bad_session(browser, apps["app_framed.png"], args.out_dir)
            for name, app in apps.items():
                shoot_generated(browser, app, args.out_dir, name)
            browser.close()
    finally:
        for app in apps.values():
            app.stop()
    print(f"wrote {', '.join(['app_cancel.png', 'app_bad_session.png', *apps])} in {args.out_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
