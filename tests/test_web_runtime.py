"""`kinema web`'s page in headless Chromium (Playwright, Debian's chromium-headless-shell, software WebGL):
the JavaScript runtime (web/kinema-runtime.js on onnxruntime-web) makes Python's motion.

- Loaded with no console errors and no request outside the local server.
- ``window.kinema.generate`` given the initial noise of Python's ``generate(seed)`` returns the same
  joint positions (1 mm mean / 5 mm max, fp32).
- Seeded (the documented mulberry32 noise) with two waypoints: the same motion as the Python onnxruntime
  reference, and each waypoint met raw within 10 cm.
- A dense path and full-body keyframes: the same motion as the Python onnxruntime reference.
- The form: a typed prompt makes a 5-s walk (its time is printed), the BVH download holds the shown motion.
- Bad input is a one-line error.

Skipped when Playwright, the browser or the page's built vendor files are missing; .ci/run installs and
builds all three.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
import torch

from tests.browser import chromium_path, launch

if os.environ.get("KINEMA_REQUIRE_BROWSER") == "1":  # CI (.ci/run): a missing browser is a failure
    from playwright import sync_api

    assert chromium_path() is not None, "chromium-headless-shell is missing (see .ci/run)"
else:
    sync_api = pytest.importorskip("playwright.sync_api", reason="pip install playwright (see .ci/run)")
    if chromium_path() is None:
        pytest.skip("no chromium-headless-shell (apt-get install chromium-headless-shell)", allow_module_level=True)
pytest.importorskip("onnxruntime", reason="pip install 'kinema[onnx]'")
pytest.importorskip("onnxscript", reason="pip install 'kinema[onnx]'")

from kinema.errors import KinemaError  # noqa: E402
from kinema.geometry.rotations import matrix_to_quat, quat_to_axis_angle  # noqa: E402
from kinema.io.bvh import read_bvh  # noqa: E402
from kinema.motion.smoothing import smooth_time  # noqa: E402
from kinema.portable.runtime import OnnxHumanModel  # noqa: E402
from kinema.portable.sampler import sixd_to_matrix  # noqa: E402
from kinema.portable.serve import WebServer, check_page  # noqa: E402
from tests.onnx_export import export_once, fp32_pipeline  # noqa: E402

try:
    check_page()
except KinemaError as err:
    if os.environ.get("KINEMA_REQUIRE_BROWSER") == "1":
        raise
    pytest.skip(f"{err}", allow_module_level=True)

PROMPT = "A person walks forward."
#: onnxruntime-web's own start-up note (it cannot read the CPU vendor inside the wasm sandbox)
BENIGN = ("Unknown CPU vendor",)


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory):
    return export_once(tmp_path_factory)


@pytest.fixture(scope="module")
def page(model_dir):
    server = WebServer(model_dir, port=0)
    logs: list[str] = []
    with sync_api.sync_playwright() as p:
        browser = launch(p)
        pg = browser.new_page(viewport={"width": 1200, "height": 700}, accept_downloads=True)
        pg.on("console", lambda m: logs.append(f"{m.type}: {m.text}") if m.type == "error" else None)
        pg.on("pageerror", lambda e: logs.append(f"pageerror: {e}"))
        pg.on("request", lambda r: None if r.url.startswith(server.url) else logs.append(f"outside: {r.url}"))
        pg.goto(server.url)
        pg.wait_for_function("window.kinema && (window.kinema.ready || window.kinema.loadError)", timeout=180_000)
        pg.logs = logs
        yield pg
        browser.close()
    server.stop()


def test_page_loads_without_errors_or_outside_requests(page):
    assert page.evaluate("window.kinema.loadError") is None
    assert [line for line in page.logs if not any(b in line for b in BENIGN)] == []
    assert "CC BY-NC 4.0" in page.inner_text("#licence")


def test_page_makes_pythons_motion_from_the_same_noise(page):
    pipeline = fp32_pipeline()
    seed, seconds, steps = 3, 5.0, 20
    frames = round(seconds * pipeline.fps)
    noise = torch.randn((1, frames, pipeline.representation.dim), generator=torch.Generator().manual_seed(seed))[0]
    want = pipeline.generate(PROMPT, seconds=seconds, seed=seed, postprocess=False, steps=steps).motions[0]
    want = want.global_transforms()[1]
    got = page.evaluate("(a) => window.kinema.generate(a)", {"prompt": PROMPT, "seconds": seconds, "seed": 0,
                                                             "steps": steps, "noise": noise.flatten().tolist()})
    assert got["fps"] == pipeline.fps and got["names"] == list(pipeline.skeleton.names)
    pos = np.asarray(got["positions"]).reshape(frames, -1, 3)
    d = np.linalg.norm(pos - want.numpy(), axis=-1) * 1000
    print(f"browser vs generate ({steps} steps): {d.mean():.4f} mm mean, {d.max():.4f} mm max")
    assert d.mean() < 1.0 and d.max() < 5.0


def test_seeded_waypoints_match_the_reference_and_are_met(page, model_dir):
    seconds, steps = 5.0, 25
    waypoints = [{"x": 0.5, "z": 3.0, "time": 2.5}, {"x": 1.0, "z": 5.5, "time": 4.95}]
    got = page.evaluate("(a) => window.kinema.generate(a)",
                        {"prompt": PROMPT, "seconds": seconds, "seed": 5, "steps": steps, "waypoints": waypoints})
    ref = OnnxHumanModel(model_dir).generate(PROMPT, seconds, seed=5, steps=steps,
                                             waypoints=[(w["x"], w["z"], w["time"]) for w in waypoints])
    pos = np.asarray(got["positions"]).reshape(ref["positions"].shape)
    d = np.linalg.norm(pos - ref["positions"], axis=-1) * 1000
    assert d.mean() < 1.0 and d.max() < 5.0
    pelvis = smooth_time(torch.from_numpy(pos[:, 0, [0, 2]]), 0.5 * got["fps"]).numpy()
    misses = [float(np.hypot(*(pelvis[round(w["time"] * got["fps"])] - [w["x"], w["z"]]))) for w in waypoints]
    print(f"page waypoint residuals (raw, smoothed pelvis): {[round(m * 100, 1) for m in misses]} cm")
    assert max(misses) < 0.10


def test_dense_path_matches_the_reference(page, model_dir):
    path = [{"x": 0.0, "z": 0.5, "time": 0.5}, {"x": 0.6, "z": 2.0, "time": 2.0}, {"x": 1.5, "z": 3.5, "time": 3.5}]
    got = page.evaluate("(a) => window.kinema.generate(a)",
                        {"prompt": PROMPT, "seconds": 4.0, "seed": 2, "steps": 5, "path": path})
    ref = OnnxHumanModel(model_dir).generate(PROMPT, 4.0, seed=2, steps=5,
                                             path=[(w["x"], w["z"], w["time"]) for w in path])
    pos = np.asarray(got["positions"]).reshape(ref["positions"].shape)
    assert np.linalg.norm(pos - ref["positions"], axis=-1).max() < 0.005


def test_fullbody_keyframes_match_the_reference(page, model_dir):
    ref = OnnxHumanModel(model_dir)
    src = ref.generate(PROMPT, 5.0, seed=1, steps=5)
    sl, parents = ref.m["layout"]["slices"], ref.m["skeleton"]["parents"]
    G = sixd_to_matrix(src["features"][:, slice(*sl["joint_rot"])].reshape(len(src["positions"]), len(parents), 6))
    keyframes = []
    for f in (30, 70):  # the reference motion's poses as local axis-angle rotations
        local = np.stack([G[f, j] if p < 0 else G[f, p].T @ G[f, j] for j, p in enumerate(parents)])
        keyframes.append({"time": f / 20, "root": src["positions"][f, 0].tolist(),
                          "rotations": quat_to_axis_angle(matrix_to_quat(torch.from_numpy(local))).tolist()})
    got = page.evaluate("(a) => window.kinema.generate(a)",
                        {"prompt": PROMPT, "seconds": 5.0, "seed": 4, "steps": 5, "keyframes": keyframes})
    want = ref.generate(PROMPT, 5.0, seed=4, steps=5,
                        keyframes=[(k["time"], k["root"], k["rotations"]) for k in keyframes])["positions"]
    pos = np.asarray(got["positions"]).reshape(want.shape)
    assert np.linalg.norm(pos - want, axis=-1).max() < 0.005


def test_form_generates_and_downloads_the_shown_motion_as_bvh(page, tmp_path):
    page.fill("#prompt", "A person walks forward.")
    page.fill("#seconds", "5")
    page.fill("#seed", "5")
    page.click("#generate")
    page.wait_for_function("document.querySelector('#status').textContent.includes('100 frames')", timeout=180_000)
    print(f"page, typed prompt: {page.inner_text('#status').splitlines()[0]} (50 steps, wasm, 1 thread)")
    with page.expect_download() as download:
        page.click("#bvh")
    path = tmp_path / "page.bvh"
    download.value.save_as(path)
    motion = read_bvh(path)
    shown = np.asarray(page.evaluate("Array.from(window.kinema.lastPositions)"))
    assert motion.num_frames == 100 and motion.fps == pytest.approx(20.0)
    _, P = motion.global_transforms()
    assert shown.size == P.numel()
    assert np.abs(P.numpy().reshape(-1) - shown).max() < 1e-3  # the BVH poses the shown joints (1 mm)


def test_bad_input_is_a_one_line_error(page):
    for bad in ({"prompt": PROMPT, "seconds": 30}, {"prompt": " ", "seconds": 2},
                {"prompt": PROMPT, "seconds": 2, "waypoints": [{"x": 0, "z": 1, "time": 5}]}):
        msg = page.evaluate("(a) => window.kinema.generate(a).then(() => null, (e) => e.message)", bad)
        assert msg and "\n" not in msg
    assert "outside the motion" in page.inner_text("#error")
