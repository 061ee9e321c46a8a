"""The app's first-use fixes without a browser (issue 36), and the character and robot paths of its
generation (issues 33 and 39): bounded session files, creature defaults, clamped boxes, frame ranges,
camera framing, short warnings, and a humanoid character / the G1 generated through the pipeline."""

from __future__ import annotations

import json
import math
import threading
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import kinema
from kinema.app import edits
from kinema.app.camera import character_extent, frame_view, opening_view
from kinema.app.constraint_panel import _default_joint
from kinema.app.document import (
    Settings,
    added_prompt,
    creature_prompts,
    default_document,
    load_document,
)
from kinema.app.generation import AppRobot, Cancelled, cannot_generate, is_character, outcome
from kinema.app.rigs import load_rig, model_rig, skeleton_size
from kinema.app.server import AppServer
from kinema.app.session import Session, summarize_warnings
from kinema.app.timeline_panel import MAX_SECONDS, MIN_SECONDS, clamp_seconds
from kinema.app.views import first_motions
from kinema.cli import build_parser
from kinema.errors import KinemaError
from kinema.robot import load_robot
from kinema.skeleton import Skeleton
from tests.server_process import free_port

DATA = Path("/work/shared/datasets/quaternius")
CHARACTER = DATA / "cyberpunk_pack" / "Character.glb"
FOX = DATA / "animals_pack" / "Fox.glb"


@pytest.fixture(scope="module")
def model():
    return kinema.load_model("default")


def _session(timeline, **extra) -> str:
    return json.dumps({"kinema_session": 1, "timeline": timeline, **extra})


def test_session_over_the_apps_limits_is_refused_with_one_line(model):
    for timeline, words in (
        ([{"prompt": "A person walks.", "seconds": 500}], "a segment lasts 0.5 to 60 s"),
        ([{"prompt": "A person walks.", "seconds": 0.1}], "a segment lasts 0.5 to 60 s"),
        ([{"prompt": "A person walks.", "seconds": 50}] * 4, "a session holds at most 180 s"),
    ):
        with pytest.raises(KinemaError, match=words) as err:
            load_document(_session(timeline), skeleton=model.skeleton, fps=model.fps, source="s.json")
        assert "\n" not in str(err.value) and str(err.value).startswith("s.json: ")
    with pytest.raises(KinemaError, match=r"'steps' must be an integer in \[1, 1000\]"):
        load_document(
            _session([{"prompt": "A person walks.", "seconds": 2}], settings={"steps": 1588}),
            skeleton=model.skeleton,
            fps=model.fps,
            max_steps=1000,
        )
    ok = load_document(
        _session([{"prompt": "A person walks.", "seconds": 60}] * 3), skeleton=model.skeleton, fps=model.fps
    )
    assert ok.seconds() == 180


def test_creature_defaults_name_the_rig_not_a_person():
    assert [s["prompt"] for s in creature_prompts("Fox.glb")] == ["A fox walks.", "A fox turns around."]
    assert creature_prompts("Alpaca.glb")[0]["prompt"] == "An alpaca walks."
    assert creature_prompts("0123.bvh")[0]["prompt"] == "A creature walks."
    doc = default_document(True, "Wolf.glb", Settings())
    assert all("person" not in s["prompt"].lower() for s in doc.timeline)
    assert added_prompt(True, "Wolf.glb") == "A wolf stands still."
    assert default_document(False, "default", Settings()).timeline[0]["prompt"] == "A person walks forward."


def test_default_joint_is_never_an_ik_helper():
    names = ["AnimalArmature", "Body", "Leg.L", "Paw.L", "IKBackLeg.L", "FFB.L", "IKFrontLeg.R", "FF.R", "Pole.R"]
    sk = Skeleton(names, [-1, 0, 1, 2, 0, 4, 0, 6, 0], torch.zeros(len(names), 3))
    assert _default_joint(sk) == "Paw.L"
    if FOX.is_file():
        fox = load_rig(FOX, fps=20).skeleton
        assert _default_joint(fox) == "Head"


def test_seconds_boxes_and_frame_boxes_keep_values_in_range():
    assert clamp_seconds(500) == MAX_SECONDS and clamp_seconds(-3) == MIN_SECONDS and clamp_seconds(2.5) == 2.5
    assert clamp_seconds("abc") == MIN_SECONDS and clamp_seconds(float("nan")) == MIN_SECONDS
    assert edits.frame_range(60, 110, 219) == (60, 110)  # typed frames are kept exactly
    assert edits.frame_range(110, 60, 219) == (60, 110)
    assert edits.frame_range(-5, 400, 219) == (0, 219)
    assert edits.frame_range(219, 219, 219) == (218, 219)


def test_contact_presets_say_what_the_other_foot_does():
    for name, flags in edits.CONTACT_PRESETS.items():
        if sum(flags) == 2:  # one foot planted: the name says the other is lifted
            assert "lifted" in name and "planted" in name
    assert edits.contacts(0, 2, "right foot planted")["contacts"][0] == [0, 0, 1, 1]  # old sessions still load


def test_framing_fits_a_small_and_a_large_character():
    fov = math.radians(75)
    for size in (0.3, 1.7, 5.0):
        points = np.array([[0, 0, 0], [0, size, 0], [size / 2, size / 2, size], [-size / 2, 0, -size / 2]])
        position, look_at = frame_view(points, fov)
        forward = (look_at - position) / np.linalg.norm(look_at - position)
        for p in points:
            v = p - position
            angle = math.acos(float(np.dot(v, forward)) / float(np.linalg.norm(v)))
            assert angle < fov / 2  # inside the view cone
        assert np.linalg.norm(position - look_at) < 12 * size + 2  # and not a speck
    positions = np.zeros((5, 3, 3))
    positions[:, :, 2] = np.arange(5)[:, None]  # walking along +Z
    ext = character_extent(positions, 4, [0.0, -1.6])
    assert ext[:, 0].min() == pytest.approx(-1.6) and ext[:, 2].max() == pytest.approx(4.0)


def test_a_new_tab_starts_framed_on_what_it_shows_first(model):
    """The view a page starts from (viser's initial camera) frames the rig's first motion: a page that
    sets up its starting view after the tab's framing (most tabs on a loaded machine) still frames it."""
    app = AppServer(model, port=free_port())
    try:
        start = app.server.initial_camera
        assert np.allclose(start.look_at, opening_view(first_motions(app.rig, model.fps)[0], float(start.fov))[1])
    finally:
        app.stop()
    for rig in (model_rig(model.skeleton), load_rig(FOX, fps=model.fps) if FOX.is_file() else None):
        if rig is None:
            continue
        motion = first_motions(rig, model.fps)[0]
        position, look_at = opening_view(motion, math.radians(75))
        body = motion.positions[0].double().numpy()
        size = float(np.linalg.norm(body.max(0) - body.min(0)))
        assert float(np.linalg.norm(look_at - body.mean(0))) < size  # looks at the character
        assert float(np.linalg.norm(position - look_at)) < 4 * size + 1  # from close enough to see it


def test_warnings_are_short_in_status_and_toast():
    keyframe_miss = "keyframe 40 not met:\n" + "\n".join(f"  joint {j}: 12.0 cm" for j in range(60))
    lines, toast = summarize_warnings([keyframe_miss, "x" * 500, "third", "third"])
    assert len(lines) == 2 and all(len(line) < 200 for line in lines)
    assert lines[-1].endswith("(+1 more)") and "\n" not in toast and len(toast) < 250
    assert summarize_warnings([]) == ([], "")


def test_samples_spacing_scales_with_the_rig(model):
    assert 1.2 < skeleton_size(model.skeleton) < 2.0
    small = Skeleton(["a", "b"], [-1, 0], torch.tensor([[0, 0.1, 0], [0, 0.2, 0]]))
    assert skeleton_size(small) == pytest.approx(0.2)


def _walk(model, rig, *, samples: int = 1, steps: int = 2, progress=None, robot=None):
    """A 2-s walk generated through the app's `outcome`."""
    return outcome(
        model,
        rig,
        [{"prompt": "A person walks forward.", "seconds": 2}],
        constraints=None,
        samples=samples,
        steps=steps,
        seed=0,
        progress=progress or (lambda d, t: None),
        robot=robot,
    )


def test_progress_can_cancel_a_generation(model):
    calls = []

    def stop(done, total):
        calls.append(done)
        raise Cancelled

    with pytest.raises(Cancelled):
        _walk(model, model_rig(model.skeleton), steps=10, progress=stop)
    assert calls == [1]  # stopped at the first step


@pytest.mark.skipif(not CHARACTER.is_file(), reason="the Quaternius Character.glb is not in the shared data folder")
def test_a_humanoid_character_is_generated_on_by_retargeting(model):
    character = load_rig(CHARACTER, fps=model.fps)
    assert character.humanoid and is_character(model, character)
    assert cannot_generate(model, character, "default") is None
    result = _walk(model, character)
    (motion,) = result.motions
    assert motion.skeleton.same_topology(character.skeleton) and motion.num_frames == round(2 * model.fps)
    assert "on Character.glb" in result.text
    assert float(motion.root_translation[-1, 2] - motion.root_translation[0, 2]) > 0.2  # it walks forward


def test_a_non_humanoid_keeps_its_message(model):
    chain = Skeleton(["a", "b", "c"], [-1, 0, 1], torch.tensor([[0, 1.0, 0], [0, 0.5, 0], [0, 0.5, 0]]))
    why = cannot_generate(model, model_rig(chain, name="chain"), "default")
    assert why is not None and "is not one" in why and "--model creatures" in why


def test_robot_is_drawn_beside_each_sample(model):
    robot = AppRobot("g1", load_robot("g1"))
    result = _walk(model, model_rig(model.skeleton), samples=2, robot=robot)
    assert len(result.robot_motions) == 2 and "robot g1" in result.text
    # the app shows each sample's MuJoCo inverse dynamics, and a sample that is not feasible also warns
    assert "sample 1 dynamics: peak torque" in result.text and "feasible in MuJoCo inverse dynamics" in result.text
    assert all(w.startswith("robot motion not feasible") for w in result.warnings if "feasible" in w)
    drawn = result.robot_motions[0]
    assert drawn.num_frames == result.motions[0].num_frames
    heights = drawn.positions[..., 1]
    assert float(heights.max()) > 1.0 and float(heights.min()) > -0.05  # a standing robot, Y up, on the floor


def test_app_command_takes_a_robot():
    args = build_parser().parse_args(["app", "--robot", "g1", "--steps", "4"])
    assert args.robot == "g1" and args.steps == 4
    assert build_parser().parse_args(["app"]).robot is None


def test_progress_names_post_processing_and_cancel_stops_it(model):
    session = Session.__new__(Session)  # only what the progress callback reads: no browser
    session.cancel, session.model, session.rig = threading.Event(), model, model_rig(model.skeleton)
    session.progress, session.status = SimpleNamespace(value=0.0), SimpleNamespace(content="")
    session.app = SimpleNamespace(robot=None)
    session._progress(26, 52)
    assert session.status.content == "Generating... step 26 of 52" and session.progress.value == 45.0
    session._progress(52, 52)  # the denoiser is done; post-processing follows, which reports no steps
    assert session.status.content.startswith("Post-processing (foot contacts, constraints)")
    assert session.progress.value == 90.0
    session.cancel.set()
    with pytest.raises(Cancelled):
        session._progress(52, 52)
