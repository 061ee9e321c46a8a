"""The app's pure parts without a browser: constraints made from scene actions (valid for the
generator, placed where asked), the session file round trip and its errors, residuals, playback
stepping, and the `kinema app` command line."""

from __future__ import annotations

import json
import math

import pytest
import torch

import kinema
from kinema.app import edits
from kinema.app.document import Document, check_timeline, load_document
from kinema.app.playback import next_frame
from kinema.app.residuals import residual
from kinema.cli import build_parser, main
from kinema.constraints import load_constraints
from kinema.errors import KinemaError


@pytest.fixture(scope="module")
def model():
    return kinema.load_model("default")


@pytest.fixture(scope="module")
def motion(model):
    return model.generate("A person walks forward.", seconds=3, steps=2)[0]


def test_ground_point_intersects_the_floor():
    assert edits.ground_point((0.0, 2.0, 0.0), (0.0, -1.0, 1.0)) == pytest.approx((0.0, 2.0))
    assert edits.ground_point((1.0, 1.0, 1.0), (0.0, 0.5, 1.0)) is None  # looking up misses the ground


def test_path_spreads_frames_by_arc_length_strictly_increasing():
    c = edits.path([(0, 0), (0, 1), (0, 3)], 10, 40, headings=True)
    assert c["frame_indices"] == [10, 20, 40] and c["dense"] is True
    assert c["global_root_heading"][0] == pytest.approx([1.0, 0.0])  # walking along +Z faces heading 0
    crowded = edits.path([(0, 0), (0, 1), (0, 1.001), (0, 2)], 0, 3, headings=False)
    assert crowded["frame_indices"] == sorted(set(crowded["frame_indices"])) and crowded["frame_indices"][-1] == 3
    with pytest.raises(KinemaError, match="at least two points"):
        edits.path([(1, 1)], 0, 10, headings=False)


def test_scene_constraints_are_valid_and_hit_what_was_shown(model, motion):
    j = model.skeleton.index("Hand_R")
    made = [
        edits.waypoint(20, 0.5, 1.0, heading=math.pi / 2),
        edits.keyframe(motion, 10),
        edits.target(motion, 30, "Hand_R", position=True, rotation=True),
        edits.contacts(40, 30, "left foot planted"),
    ]
    cons = load_constraints(made, model.skeleton, model.fps, motion.num_frames)
    assert len(cons) == 4
    assert made[0]["global_root_heading"][0] == pytest.approx([0.0, 1.0])  # pi/2 faces +X
    assert residual(made[1], motion) == "0.0 cm"  # the pose kept is the pose shown
    assert residual(made[2], motion) == "0.0 cm, 0 deg"
    assert made[3]["frame_indices"] == list(range(30, 41)) and made[3]["contacts"][0] == [1, 1, 0, 0]
    moved = edits.moved(made[2], [0.1, 1.2, 0.3], (1.0, 0.0, 0.0, 0.0))
    assert moved["positions"] == [[0.1, 1.2, 0.3]] and moved["rotations"] == [[0.0, 0.0, 0.0]]
    assert residual(moved, motion).startswith(
        f"{100 * float((motion.positions[30, j] - torch.tensor([0.1, 1.2, 0.3])).norm()):.1f}"
    )
    assert edits.moved(made[0], (1.5, 0.0, 2.0))["smooth_root_2d"] == [[1.5, 2.0]]
    assert edits.retimed(made[3], 5)["frame_indices"] == list(range(5, 16))
    assert [edits.label(c, 20) for c in made] == [
        "waypoint @ 20 (1.0 s)",
        "pose @ 10 (0.5 s)",
        "Hand_R pos+rot @ 30 (1.5 s)",
        "left foot planted, right lifted @ 30-40 (1.5-2.0 s)",
    ]
    assert residual(edits.waypoint(500, 0, 0), motion) == "beyond the motion"
    assert edits.spanned(made[3], 5, 8)["frame_indices"] == [5, 6, 7, 8]
    assert edits.spanned(made[3], 5, 8)["contacts"] == [[1, 1, 0, 0]] * 4
    walk = edits.path([(0, 0), (0, 2)], 0, 10, headings=True)
    assert edits.spanned(walk, 20, 60)["frame_indices"] == [20, 60]
    with pytest.raises(KinemaError, match="only foot contacts and paths"):
        edits.spanned(made[0], 0, 5)


def test_session_file_round_trip_and_errors(model, motion):
    doc = Document(constraints=[edits.waypoint(20, 0.5, 1.0), edits.keyframe(motion, 10)])
    doc.settings.samples, doc.settings.steps = 3, 7
    again = load_document(doc.to_json(model.fps), skeleton=model.skeleton, fps=model.fps)
    assert again.timeline == doc.timeline and again.settings == doc.settings
    assert again.constraints[0] == doc.constraints[0]
    rots = [torch.tensor(d.constraints[1]["local_joints_rot"]) for d in (again, doc)]
    assert torch.allclose(*rots, atol=1e-9)
    obj = json.loads(doc.to_json(model.fps))
    for change, message in (
        ({"kinema_session": 2}, "not a kinema session file"),
        ({"extra": 1}, r"unknown keys \['extra'\]"),
        ({"settings": {"samples": 9}}, "'samples' must be an integer in \\[1, 4\\]"),
        ({"timeline": []}, "non-empty JSON list"),
        ({"constraints": [{"type": "root2d", "frame_indices": [900], "smooth_root_2d": [[0, 0]]}]}, "beyond"),
    ):
        with pytest.raises(KinemaError, match=message):
            load_document(json.dumps({**obj, **change}), skeleton=model.skeleton, fps=model.fps, source="s.json")
    with pytest.raises(KinemaError, match="s.json: not a JSON session file"):
        load_document("{", skeleton=model.skeleton, fps=model.fps, source="s.json")
    assert check_timeline([{"prompt": "a", "seconds": 2}]) == [{"prompt": "a", "seconds": 2.0}]


def test_next_frame_stops_or_loops():
    assert next_frame(3, 10, loop=False) == (4, True)
    assert next_frame(9, 10, loop=False) == (9, False)
    assert next_frame(9, 10, loop=True) == (0, True)


def test_cli_app_arguments(capsys):
    args = build_parser().parse_args(["app", "--port", "8090", "--steps", "10", "--host", "0.0.0.0"])
    assert (args.port, args.steps, args.host, args.model) == (8090, 10, "0.0.0.0", "default")
    assert main(["app", "--model", "/no/such/model"]) == 2
    assert "no such model folder" in capsys.readouterr().err


def test_waypoint_speeds_in_plain_words():
    """Issue 61: the speed each waypoint asks for, from the one before it in time (the origin at frame 0
    first), shown before generating; paths are left out."""
    from kinema.app.edits import TOO_FAST, speed_words, waypoint, waypoint_speeds

    fps = 20.0
    cs = [waypoint(100, 0.0, 8.0), waypoint(40, 0.0, 2.0), {"type": "root2d", "dense": True, "frame_indices": [1],
                                                            "smooth_root_2d": [[50.0, 0.0]]}, waypoint(110, 0.0, 92.0)]
    speeds = waypoint_speeds(cs, fps)
    assert set(speeds) == {0, 1, 3}
    assert speeds[1] == pytest.approx(1.0) and speeds[0] == pytest.approx(2.0) and speeds[3] == pytest.approx(168.0)
    assert [speed_words(speeds[i]) for i in (1, 0, 3)] == ["a walk", "a walk", TOO_FAST]
    assert speed_words(3.0) == "a jog" and speed_words(5.0) == "a run"
