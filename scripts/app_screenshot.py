"""Screenshot of `kinema app` with a generated motion and constraints, for README.md and docs/app.md.

Starts the app in this process, opens it in headless Chromium (Debian's chromium-headless-shell,
software WebGL), lays two waypoints with real clicks on the ground, pins a hand target, plants a foot
over a range, generates two samples and saves the page at a frame where everything shows.

    python scripts/app_screenshot.py --out docs/images/app.png
    python scripts/app_screenshot.py --rig ../shared/datasets/quaternius/animals_pack/Fox.glb \
        --clip "AnimalArmature|Walk" --out docs/images/app_rig.png   # a GLB rig with its skin, its own clip
"""

from __future__ import annotations

import argparse
import socket
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import kinema  # noqa: E402
from kinema.app import edits  # noqa: E402
from kinema.app.rigs import load_rig  # noqa: E402
from kinema.app.server import AppServer  # noqa: E402
from tests.browser import button, launch, row_input, set_camera, world_to_screen  # noqa: E402

WAYPOINTS = ((50, 0.6, 2.4), (110, 2.0, 4.6))  # (frame, x, z) metres
SHOW_FRAME = 80


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(cond, timeout: float = 60.0):
    t0 = time.time()
    while time.time() - t0 < timeout:
        if cond():
            return
        time.sleep(0.1)
    raise SystemExit(f"timed out waiting for the app (line {cond.__code__.co_firstlineno})")


def seek(page, session, frame: int) -> None:
    box = row_input(page, "Frame")
    box.fill(str(frame))
    box.press("Enter")
    wait_for(lambda: session.player.frame == frame)


def author(page, session) -> None:
    """Waypoints by clicking the ground, a hand target and a planted foot, then generate."""
    row_input(page, "Prompt 1").fill("A person walks forward.")
    canvas = page.locator("canvas").first
    for frame, x, z in WAYPOINTS:
        seek(page, session, frame)
        page.mouse.click(*world_to_screen(session.client.camera, (x, 0.0, z), canvas.bounding_box()))
        wait_for(lambda f=frame: any(c["frame_indices"] == [f] for c in session.doc.constraints))
    session.doc.constraints.append(edits.contacts(150, 170, "left foot planted"))
    button(page, "Generate").click()
    wait_for(lambda: session.generated and session.job is None)
    seek(page, session, SHOW_FRAME)
    button(page, "Add target").click()
    wait_for(lambda: len(session.doc.constraints) == 4)
    button(page, "Generate").click()
    time.sleep(0.5)
    wait_for(lambda: session.job is None)
    seek(page, session, SHOW_FRAME)


def show_rig(page, session, clip: str | None) -> None:
    """The uploaded rig's clip at a frame mid-stride, the camera beside it."""
    page.get_by_text("Rig", exact=True).click()
    if clip is not None:
        session.show_clip(clip)
    motion = session.shown_motion()
    seek(page, session, motion.num_frames // 3)
    P = motion.positions[motion.num_frames // 3].double()
    size = float((P.max(0).values - P.min(0).values).norm())
    centre = (P.max(0).values + P.min(0).values) / 2
    look = centre.tolist()
    set_camera(session.client.camera, (look[0] + 0.9 * size, look[1] + 0.4 * size, look[2] + 0.7 * size), look)
    page.get_by_text("Show skin").scroll_into_view_if_needed()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "images" / "app.png")
    parser.add_argument("--steps", type=int, default=20, help="DDIM steps (default 20)")
    parser.add_argument("--rig", type=Path, help="show this GLB/BVH rig playing its own clip instead")
    parser.add_argument("--clip", help="the rig's clip to show (default: its first)")
    args = parser.parse_args()
    from playwright.sync_api import sync_playwright

    model = kinema.load_model("default")
    rig = None if args.rig is None else load_rig(args.rig, fps=model.fps)
    app = AppServer(model, rig=rig, port=free_port(), steps=args.steps)
    try:
        with sync_playwright() as p:
            browser = launch(p)
            page = browser.new_page(viewport={"width": 1500, "height": 1150})
            page.goto(app.url)
            page.get_by_text("Add prompt").wait_for(timeout=30000)
            wait_for(lambda: bool(app.sessions))
            session = next(iter(app.sessions.values()))
            show_rig(page, session, args.clip) if rig is not None else author(page, session)
            time.sleep(1.5)
            for close in page.locator(".mantine-Notification-closeButton").all():
                close.click()  # the "software WebGL" notice of a headless browser
            time.sleep(0.5)
            args.out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.out))
            browser.close()
    finally:
        app.stop()
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
