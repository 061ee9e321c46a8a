"""Headless Chromium for the app's browser tests: find Debian's chromium-headless-shell, launch it
with software WebGL (SwiftShader) and no network, and small helpers to drive viser's panel and to
turn world points into screen pixels with the camera the tab reports."""

from __future__ import annotations

import math
import shutil
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

#: where Debian's chromium-headless-shell package puts its binary (the /usr/bin one is a wrapper)
CHROMIUM_CANDIDATES = ("/usr/lib/chromium/chromium-headless-shell", "/usr/lib/chromium/headless_shell")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
]


def chromium_path() -> str | None:
    for c in CHROMIUM_CANDIDATES:
        if Path(c).is_file():
            return c
    return shutil.which("chromium-headless-shell")


def launch(playwright):
    return playwright.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)


@contextmanager
def chromium(sync_api):
    """A launched browser for the length of a ``with`` block (``sync_api``: playwright.sync_api)."""
    with sync_api.sync_playwright() as p:
        b = launch(p)
        yield b
        b.close()


def row_input(page, label: str):
    """The input on the panel row labelled ``label`` (viser's labels are not tied to their inputs)."""
    row = page.locator("div.mantine-Flex-root").filter(has=page.get_by_text(label, exact=True))
    return row.locator("input:not([type=hidden])").last


def button(page, text: str):
    return page.get_by_role("button", name=text, exact=True)


def folder_button(page, folder: str, label: str):
    """The button ``label`` in the panel ``folder`` (collapsed by default), opening the folder first
    when the button is hidden, so a test does not depend on an earlier test having opened it."""
    if not button(page, label).is_visible():
        page.get_by_text(folder, exact=True).click()
    return button(page, label)


def world_to_screen(camera, point, box: dict) -> tuple[float, float]:
    """Page pixel of a world point seen by ``camera`` (viser's CameraHandle: OpenCV convention, vertical
    fov) in a canvas at ``box`` (Playwright bounding box)."""
    w, x, y, z = (float(v) for v in camera.wxyz)
    R = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    pc = R.T @ (np.asarray(point, dtype=np.float64) - np.asarray(camera.position, dtype=np.float64))
    H, W = box["height"], box["width"]
    f = (H / 2) / math.tan(camera.fov / 2)
    return box["x"] + W / 2 + f * pc[0] / pc[2], box["y"] + H / 2 + f * pc[1] / pc[2]


def set_camera(camera, position, look_at, timeout: float = 30.0) -> None:
    """Move a tab's camera from the server and wait until the browser reports that pose back (clicks are
    aimed with the camera state the tab reports, which lags an assignment under load)."""
    camera.position = tuple(float(v) for v in position)  # (viser moves look_at along with the position)
    camera.look_at = tuple(float(v) for v in look_at)
    sent = time.time()
    while time.time() - sent < timeout:
        if (
            camera.update_timestamp > sent
            and np.allclose(camera.position, position, atol=1e-3)
            and np.allclose(camera.look_at, look_at, atol=1e-3)
        ):
            time.sleep(0.3)  # let the frame with that pose render
            return
        time.sleep(0.05)
    raise AssertionError(f"the browser did not report the camera at {position} looking at {look_at}")
