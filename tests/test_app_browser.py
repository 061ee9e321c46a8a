"""`kinema app` end to end in headless Chromium (Playwright, Debian's chromium-headless-shell, software
WebGL): the page loads with no console errors and no outside requests, a typed prompt generates, the
played frame advances, ground clicks lay waypoints the regenerated root passes, a dragged gizmo moves
a target, the BVH download holds the shown motion, a saved session loads back, a bad upload is a
notification. The tests share one page and run in file order (each builds on the one before).
Skipped when Playwright or the browser is missing; .ci/run installs both."""

from __future__ import annotations

import io
import json
import os
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

import kinema
from tests.app_rig_data import synthetic_rig_glb
from tests.browser import button, chromium_path, folder_button, launch, row_input, set_camera, world_to_screen
from tests.server_process import free_port

if os.environ.get("KINEMA_REQUIRE_BROWSER") == "1":  # CI (.ci/run): a missing browser is a failure
    import viser  # noqa: F401
    from playwright import sync_api

    assert chromium_path() is not None, "chromium-headless-shell is missing (see .ci/run)"
else:
    sync_api = pytest.importorskip("playwright.sync_api", reason="pip install playwright (see .ci/run)")
    pytest.importorskip("viser", reason="pip install 'kinema[app]'")
    if chromium_path() is None:
        pytest.skip("no chromium-headless-shell (apt-get install chromium-headless-shell)", allow_module_level=True)

from kinema.app.mesh_view import MeshView  # noqa: E402
from kinema.app.residuals import residual  # noqa: E402
from kinema.app.server import CAMERA_LOOK_AT, CAMERA_POSITION, AppServer  # noqa: E402
from kinema.io.bvh import read_bvh  # noqa: E402
from kinema.io.gltf import read_gltf  # noqa: E402
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS, smooth_time  # noqa: E402

STEPS = 4  # DDIM steps: a draft is enough to test the UI
WAYPOINTS = ((40, 0.4, 2.2), (100, 1.2, 5.0))  # (frame, x, z)



def wait_for(cond, timeout: float = 60.0, what: str = "condition", fail: bool = True):
    t0 = time.time()
    while time.time() - t0 < timeout:
        value = cond()
        if value:
            return value
        time.sleep(0.1)
    if not fail:
        return None
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")


@pytest.fixture(scope="module")
def default_model():
    return kinema.load_model("default")


@pytest.fixture(scope="module")
def app(default_model):
    server = AppServer(default_model, port=free_port(), steps=STEPS)
    yield server
    server.stop()


@pytest.fixture(scope="module")
def browser():
    with sync_api.sync_playwright() as p:
        b = launch(p)
        yield b
        b.close()


@pytest.fixture(scope="module")
def tab(app, browser):
    """(page, session, log): one tab, its server-side Session, and what the page logged / requested."""
    page, session, log = open_tab(browser, app, accept_downloads=True)
    yield page, session, log
    page.close()


def open_tab(browser, app, **page_options):
    """(page, session, log) of a new tab on ``app`` once its panel is built: the tab's server-side
    Session and what the page logs (console errors, page errors) and requests."""
    log = {"errors": [], "requests": []}
    page = browser.new_page(viewport={"width": 1400, "height": 900}, **page_options)
    page.on("console", lambda m: log["errors"].append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: log["errors"].append(str(e)))
    page.on("request", lambda r: log["requests"].append(r.url))
    page.goto(app.url)
    page.get_by_text("Add prompt").wait_for(timeout=90000)
    session = wait_for(lambda: next(iter(app.sessions.values()), None), what="a session")
    return page, session, log


def generate(page, session) -> None:
    before = session.motions
    button(page, "Generate").click()
    wait_for(lambda: session.motions is not before and session.job is None, what="generation")
    assert "sample(s)," in session.status.content, session.status.content  # not "Failed: ..."
    page.get_by_text("sample(s),").first.wait_for(timeout=60000)  # and the page shows it
    button(page, "Pause").click()  # a new motion plays at once; the tests below drive the frame themselves
    wait_for(lambda: not session.player.playing, what="playback to pause")


def screen_step(camera, point: torch.Tensor, axis: int, box) -> float:
    """Pixels on screen between ``point`` and ``point`` + 0.25 m along world ``axis``."""
    step = torch.zeros(3, dtype=torch.float64)
    step[axis] = 0.25
    a = torch.tensor(world_to_screen(camera, point.tolist(), box))
    b = torch.tensor(world_to_screen(camera, (point + step).tolist(), box))
    return float(torch.linalg.vector_norm(b - a))


def drag(page, start, end, steps: int = 10) -> None:
    """Press at ``start``, move to ``end`` in small steps, release (page pixels)."""
    page.mouse.move(*start)
    page.mouse.down()
    for k in range(1, steps + 1):
        page.mouse.move(start[0] + (end[0] - start[0]) * k / steps, start[1] + (end[1] - start[1]) * k / steps)
        time.sleep(0.03)
    page.mouse.up()


def seek(page, frame: int, session=None) -> None:
    """Type a frame into the Frame box; with ``session``, wait until the tab shows it (typing again if
    the first entry was lost on a loaded machine)."""
    for _ in range(3):
        box = row_input(page, "Frame")
        box.fill(str(frame))
        box.press("Enter")
        if session is None or wait_for(lambda: session.player.frame == frame, timeout=10, fail=False):
            return
    raise AssertionError(
        f"the tab did not go to frame {frame} (at {session.player.frame}, playing={session.player.playing})"
    )


def test_page_loads_offline_without_console_errors(app, tab, browser):
    page, session, log = tab
    page.locator("canvas").first.wait_for()
    time.sleep(1.0)
    assert log["errors"] == []
    assert all(u.startswith(app.url) or u.startswith(("data:", "blob:")) for u in log["requests"]), log["requests"]
    other = browser.new_page()  # a second tab gets its own session
    other.goto(app.url)
    other.get_by_text("Add prompt").wait_for(timeout=90000)
    wait_for(lambda: len(app.sessions) == 2, what="two sessions")
    other.close()
    wait_for(lambda: len(app.sessions) == 1, what="the second tab to close")


def test_typed_prompt_generates(tab, default_model):
    page, session, _ = tab
    row_input(page, "Prompt 1").fill("A person jogs forward.")
    wait_for(lambda: session.doc.timeline[0]["prompt"] == "A person jogs forward.", what="the prompt to arrive")
    generate(page, session)
    assert len(session.motions) == 2  # two samples side by side
    frames = round(11.0 * default_model.fps)  # default timeline: 6 s + 5 s
    assert session.shown_motion().num_frames == frames
    assert session.result_motion() is not None


def test_played_frame_advances(tab):
    page, session, _ = tab
    seek(page, 0)
    button(page, "Play").click()
    first = wait_for(lambda: session.player.frame > 0 and session.player.frame, what="playback to start")
    time.sleep(1.0)
    assert session.player.frame > first + 5
    shown = page.get_by_text("(frame ").inner_text()
    button(page, "Pause").click()
    wait_for(lambda: not session.player.playing, what="playback to pause")
    assert "s / 10.95 s" in shown


def test_scrubbing_while_paused_keeps_the_character_in_view(tab):
    """Issue 61: after Pause, a scrubbed character walked out of a view that stayed put, and Play kept the
    offset; the camera now follows the scrubbed root (with "Follow character" on) at the angle it had."""
    page, session, _ = tab
    assert not session.player.playing and session.player.follow.value
    cam = session.client.camera
    motion = session.shown_motion()
    seek(page, 0, session)
    aim = np.asarray(cam.look_at, dtype=np.float64) - motion.positions[0, 0].double().numpy()
    last = motion.num_frames - 1
    seek(page, last, session)
    root = motion.positions[last, 0].double().numpy()
    assert float(np.linalg.norm((root - motion.positions[0, 0].double().numpy())[[0, 2]])) > 3.0
    wait_for(lambda: float(np.linalg.norm((np.asarray(cam.look_at) - root - aim)[[0, 2]])) < 0.1,
             what="the camera to follow the scrubbed character")
    assert float(np.abs((np.asarray(session.ground.position) - root)[[0, 2]]).max()) <= 4.0  # the ground came too
    start = round(6.0 * session.model.fps)  # where the default timeline's second segment starts
    page.get_by_text(f"segment 2 of 2 from frame {start} (6.00 s): A person waves.").wait_for(timeout=10000)
    seek(page, 0, session)

def test_ground_clicks_lay_waypoints_the_motion_passes(tab):
    page, session, log = tab
    canvas = page.locator("canvas").first
    session.player.follow.value = False  # clicks are aimed with the camera set here, not one following a scrub
    set_camera(session.client.camera, CAMERA_POSITION, CAMERA_LOOK_AT)  # the generated motion was framed closer
    for frame, x, z in WAYPOINTS:
        seek(page, frame, session)
        box = canvas.bounding_box()
        px, py = world_to_screen(session.client.camera, (x, 0.0, z), box)
        page.mouse.click(px, py)
        wait_for(lambda f=frame: any(c["frame_indices"] == [f] for c in session.doc.constraints), what="a waypoint")
    session.player.follow.value = True
    said = "2. waypoint @ 100 (5.0 s) asks 1.0 m/s, a walk"  # the pace it asks for, before generating
    assert session.constraints.items.value == said
    page.get_by_text(said, exact=True).wait_for(state="attached", timeout=10000)
    for (frame, x, z), c in zip(WAYPOINTS, session.doc.constraints, strict=True):
        cx, cz = c["smooth_root_2d"][0]
        assert c["frame_indices"] == [frame]
        assert abs(cx - x) < 0.05 and abs(cz - z) < 0.05, (c, x, z)  # the click landed where aimed
    generate(page, session)
    motion = session.shown_motion()
    pelvis = motion.positions[:, 0, [0, 2]].double()
    root = smooth_time(pelvis, DEFAULT_ROOT_SIGMA_SECONDS * motion.fps)  # what a waypoint targets
    for frame, x, z in WAYPOINTS:
        target = torch.tensor([x, z], dtype=torch.float64)
        assert float(torch.linalg.vector_norm(root[frame] - target)) < 0.05, f"smoothed root at frame {frame}"
        closest = float(torch.linalg.vector_norm(pelvis - target, dim=-1).min())
        assert closest < 0.2, f"the pelvis passes the waypoint at ({x}, {z}) {closest:.2f} m away at best"
    page.get_by_text("Residuals").wait_for()
    assert page.get_by_text(" cm").count() >= 2  # one residual line per waypoint
    assert log["errors"] == []


def test_drag_target_gizmo(tab):
    page, session, _ = tab
    if session.result_motion() is None:  # run alone (-k): nothing generated by the tests above yet
        generate(page, session)
    seek(page, 60, session)
    before = len(session.doc.constraints)
    button(page, "Add target").click()
    c0 = wait_for(lambda: session.doc.constraints[-1] if len(session.doc.constraints) == before + 1 else None,
                  what="a target")
    assert c0["type"] == "end-effector" and c0["frame_indices"] == [60]
    p0 = torch.tensor(c0["positions"][0], dtype=torch.float64)
    hand = session.shown_motion().positions[60, session.model.skeleton.index(c0["joint"])]
    assert float(torch.linalg.vector_norm(p0 - hand)) < 1e-4  # pinned where the joint is
    session.player.follow.value = False  # the camera stays where the test puts it
    try:
        cam = session.client.camera
        attempts, p = [], p0
        for _ in range(3):  # on a loaded machine the gizmo may not be drawn yet, or a frame may still move the view
            # come close, as a user would orbit and zoom in, so that the gizmo is large on screen
            set_camera(cam, (p + torch.tensor([2.0, 0.8, -0.8], dtype=torch.float64)).tolist(), p.tolist())
            box = page.locator("canvas").first.bounding_box()
            axis = max((0, 2), key=lambda a: screen_step(cam, p, a, box))  # the ground axis seen most across
            unit = torch.zeros(3, dtype=torch.float64)
            unit[axis] = 1.0
            centre = torch.tensor(world_to_screen(cam, p.tolist(), box))
            start = torch.tensor(world_to_screen(cam, (p + 0.25 * unit).tolist(), box))  # on the gizmo's arrow
            end = start + 100.0 * (start - centre) / torch.linalg.vector_norm(start - centre)
            drag(page, start.tolist(), end.tolist())
            moved = wait_for(
                lambda p=p: session.doc.constraints[-1]["positions"][0] != p.tolist() and session.doc.constraints[-1],
                timeout=5,
                what="the target to move",
                fail=False,
            )
            if not moved:
                attempts.append((axis, None))
                continue
            new = torch.tensor(moved["positions"][0], dtype=torch.float64)
            d = new - p
            others = [k for k in range(3) if k != axis]
            attempts.append((axis, d))
            if float(d[axis]) > 0.05 and all(abs(float(d[k])) < 0.02 for k in others):
                break
            p = new  # a drag that landed on another arrow: try again from where the target is now
        else:
            raise AssertionError(f"no drag along the gizmo's arrow moved the target along that axis: {attempts}")
    finally:
        session.player.follow.value = True


def test_download_bvh_holds_the_shown_motion(tab, tmp_path, default_model):
    page, session, _ = tab
    with page.expect_download() as dl:
        folder_button(page, "Files", "Download BVH").click()
    path = tmp_path / "motion.bvh"
    dl.value.save_as(path)
    assert path.read_text().startswith("HIERARCHY")
    motion = read_bvh(path)
    shown = session.shown_motion()
    assert motion.skeleton.names == default_model.skeleton.names
    assert motion.num_frames == shown.num_frames and motion.fps == shown.fps
    assert float((motion.positions - shown.positions).abs().max()) < 1e-3


def test_session_saves_and_loads_back(tab, tmp_path):
    page, session, _ = tab
    with page.expect_download() as dl:
        folder_button(page, "Files", "Download session").click()
    path = tmp_path / "session.json"
    dl.value.save_as(path)
    saved = json.loads(path.read_text())
    assert saved["timeline"][0]["prompt"] == "A person jogs forward."
    assert len(saved["constraints"]) == 3
    page.get_by_role("button", name="clear all").click()
    wait_for(lambda: not session.doc.constraints, what="constraints to clear")
    bad = tmp_path / "bad.json"
    bad.write_text('{"timeline": []}')
    with page.expect_file_chooser() as fc:
        folder_button(page, "Files", "Load session").click()
    fc.value.set_files(bad)
    page.get_by_text("Upload failed").wait_for(timeout=10000)  # an error is a notification, not a dead page
    # viser's own "File uploaded successfully." (before the app read the file) is replaced (kinema.app.page_script)
    page.get_by_text("Received; kinema reads it now").first.wait_for(state="attached", timeout=10000)
    assert page.get_by_text("File uploaded successfully.").count() == 0
    with page.expect_file_chooser() as fc:
        folder_button(page, "Files", "Load session").click()
    fc.value.set_files(path)
    wait_for(lambda: len(session.doc.constraints) == 3, what="the session to load")
    assert session.doc.timeline == saved["timeline"]
    assert session.doc.constraints[0]["smooth_root_2d"] == saved["constraints"][0]["smooth_root_2d"]
    assert row_input(page, "Prompt 1").input_value() == "A person jogs forward."


def test_uploaded_clip_keyframes_and_inbetweening(tab, tmp_path, default_model):
    page, session, _ = tab
    clip = default_model.generate("A person walks forward.", seconds=3, steps=2, seed=5)[0]
    path = tmp_path / "clip.bvh"
    clip.save(path, scale=100.0)  # centimetres: the panel's default BVH units
    with page.expect_file_chooser() as fc:
        folder_button(page, "Files", "Upload BVH clip").click()
    fc.value.set_files(path)
    wait_for(lambda: "clip.bvh" in session.status.content, what="the clip to show")
    shown = session.shown_motion()
    assert shown.num_frames == clip.num_frames
    start = clip.root_translation[0] * torch.tensor([1.0, 0.0, 1.0])  # the upload puts the first root over the origin
    assert float((shown.positions - (clip.positions - start)).abs().max()) < 2e-3
    page.get_by_role("button", name="clear all").click()
    for frame in (0, 50):
        seek(page, frame, session)
        button(page, "Keyframe pose").click()
        wait_for(lambda f=frame: any(c["frame_indices"] == [f] for c in session.doc.constraints), what="a pose")
    generate(page, session)
    for c in session.doc.constraints:
        cm = float(residual(c, session.shown_motion()).split()[0])
        assert cm < 5.0, f"the in-between misses the clip's pose at frame {c['frame_indices']} by {cm} cm"


def test_path_mode_clicks_make_a_dense_path(tab):
    page, session, _ = tab
    page.get_by_role("button", name="clear all").click()
    wait_for(lambda: not session.doc.constraints, what="constraints to clear")
    row_input(page, "Click ground").click()
    page.get_by_role("option", name="path", exact=True).click()
    wait_for(lambda: session.constraints.mode.value == "path", what="path mode")
    cam = session.client.camera
    set_camera(cam, (3.5, 3.5, -1.0), (0.0, 0.0, 1.0))
    box = page.locator("canvas").first.bounding_box()
    aimed = ((0.0, 0.5), (0.5, 1.5), (0.0, 2.5))
    for k, (x, z) in enumerate(aimed):
        page.mouse.click(*world_to_screen(cam, (x, 0.0, z), box))
        wait_for(lambda n=k + 1: len(session.constraints.path_points) == n, what=f"path point {k + 1}")
    button(page, "Finish path").click()
    c = wait_for(lambda: session.doc.constraints and session.doc.constraints[0], what="the path")
    lo, hi = session.constraints.range.value
    assert c["type"] == "root2d" and c["dense"] is True
    assert c["frame_indices"][0] == lo and c["frame_indices"][-1] == hi
    for (x, z), (cx, cz) in zip(aimed, c["smooth_root_2d"], strict=True):
        assert abs(cx - x) < 0.05 and abs(cz - z) < 0.05


FOX = Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets" / "quaternius" / "animals_pack" / "Fox.glb"


def canvas_pixels(page, box) -> np.ndarray:
    """RGB of the page inside ``box``. Software WebGL (swiftshader) on a loaded 2-core machine can take
    over playwright's default 30 s for a frame of a skinned rig, so the screenshot waits longer."""
    shot = page.screenshot(clip=box, timeout=120000)
    return np.asarray(Image.open(io.BytesIO(shot)).convert("RGB"), dtype=np.int16)


def test_glb_rig_shows_its_skin_and_downloads_as_glb(tab, tmp_path, default_model):
    page, session, log = tab
    if session.result_motion() is None:  # run alone (-k): nothing generated by the tests above yet
        generate(page, session)
    with page.expect_download() as dl:  # the human: GLB with kinema's generated bone mesh
        folder_button(page, "Files", "Download GLB").click()
    dl.value.save_as(tmp_path / "human.glb")
    human = read_gltf(tmp_path / "human.glb")
    assert human.skeleton.names == default_model.skeleton.names and human.skeleton.mesh is not None
    rig_file = FOX if FOX.is_file() else synthetic_rig_glb(tmp_path / "quad.glb")
    with page.expect_file_chooser() as fc:
        folder_button(page, "Rig", "Upload rig").click()
    fc.value.set_files(rig_file)
    wait_for(lambda: session.rig.name == rig_file.name and session.views, what="the rig to show")
    page.get_by_text("playback only").first.wait_for(timeout=20000)  # the human model cannot generate for it
    expected = read_gltf(rig_file, fps=default_model.fps)
    shown = session.shown_motion()
    assert shown.skeleton.names == expected.skeleton.names
    assert shown.num_frames == next(iter(expected.motions.values())).num_frames
    meshes = [v for v in session.views[0] if isinstance(v, MeshView)]
    assert meshes and meshes[0].handles, "the skin is not drawn"
    # the skin really renders: the canvas around the character changes when it is switched off
    set_camera(session.client.camera, (2.0, 1.2, 2.0), (0.0, 0.4, 0.0))
    box = page.locator("canvas").first.bounding_box()
    time.sleep(1.0)
    with_skin = canvas_pixels(page, box)
    page.get_by_label("Show skin").click()
    wait_for(lambda: not any(isinstance(v, MeshView) for v in session.views[0]), what="the skin to go")
    time.sleep(1.0)
    bones = canvas_pixels(page, box)
    changed = float((np.abs(with_skin - bones).sum(-1) > 40).mean())
    assert changed > 0.01, f"only {100 * changed:.2f} % of the canvas changed without the skin"
    page.get_by_label("Show skin").click()
    button(page, "Generate").click()
    page.get_by_text("Cannot generate for this rig").first.wait_for(timeout=10000)
    with page.expect_download() as dl:
        folder_button(page, "Files", "Download GLB").click()
    dl.value.save_as(tmp_path / "rig.glb")
    back = read_gltf(tmp_path / "rig.glb")
    assert back.skeleton.names == expected.skeleton.names and back.skeleton.mesh is not None
    assert back.skeleton.mesh.num_vertices == expected.skeleton.mesh.num_vertices
    clip = next(iter(back.motions.values()))
    assert clip.num_frames == shown.num_frames
    assert float((clip.positions - shown.positions.double()).abs().max()) < 1e-3
    assert log["errors"] == []
    button(page, "Use the model's skeleton").click()
    wait_for(lambda: session.rig.skeleton is default_model.skeleton, what="the model's skeleton")
