"""Objectives: JSON parsing and errors, the terms' values and gradients, the time-agnostic path loss."""

from __future__ import annotations

import json
import math

import pytest
import torch

from kinema.human.objective_sampling import worse_than_raw
from kinema.objectives import ObjectiveError, bind_objectives, load_objectives
from kinema.objectives.path import PathTimeAgnostic, arc_resample
from kinema.objectives.terms import Avoid, JointDistance, Reach, StayWithin
from kinema.skeleton import Skeleton

FPS = 20.0


def _skeleton() -> Skeleton:
    names = ["Hips", "Spine", "Head", "Hand_L", "Hand_R"]
    offsets = torch.tensor([[0, 0, 0], [0, 0.3, 0], [0, 0.4, 0], [0.4, 0, 0], [-0.4, 0, 0]], dtype=torch.float32)
    return Skeleton(names, [-1, 0, 1, 1, 1], offsets)


def _bind(obj, T: int = 40):
    return bind_objectives(load_objectives([obj]), _skeleton(), FPS, T)[0]


def _positions(T: int = 40) -> torch.Tensor:
    """(1, T, 5, 3): the body walks along +Z at 1 m/s, joints at fixed offsets from the hips."""
    z = torch.arange(T, dtype=torch.float32) / FPS
    base = torch.stack([torch.zeros(T), torch.full((T,), 1.0), z], -1)
    off = torch.tensor([[0, 0, 0], [0, 0.3, 0], [0, 0.7, 0], [0.4, 0.3, 0], [-0.4, 0.3, 0]], dtype=torch.float32)
    return (base[:, None] + off)[None]


# ---------------------------------------------------------------------------- JSON
@pytest.mark.parametrize(
    "obj, message",
    [
        ({"type": "reach", "joint": "Hand_R", "target": [0, 1, 0], "speed": 2}, "objective 0 (reach): field 'speed'"),
        ({"type": "reach", "joint": "Hand_R"}, "field 'target': missing required field"),
        ({"type": "reach", "joint": "Hand_R", "target": [0, 1]}, "field 'target': expected a list of 3 numbers"),
        ({"type": "teleport"}, 'unknown objective type "teleport"'),
        ({"type": "avoid"}, "give at least one sphere or box"),
        ({"type": "avoid", "spheres": [{"center": [0, 1, 0], "radius": -1}]}, "radius must be positive"),
        ({"type": "stay-within"}, "give at least one bound"),
        ({"type": "path-time-agnostic", "joint": "Hips", "path": [[0, 0]]}, "at least 2 points"),
        ({"type": "path-time-agnostic", "joint": "Hips", "path": [[0, 0], [1, 2, 3]]}, "all be (x, y, z) or all"),
        ({"type": "joint-distance", "joints": ["Hand_R"]}, "expected a list of 2 joint names"),
        ({"type": "hand-to-head", "hand": "middle"}, "field 'hand'"),
        ({"type": "realism", "window": [2, 1]}, "field 'window'"),
    ],
)
def test_json_errors_are_one_line_and_name_the_field(obj, message) -> None:
    with pytest.raises(ObjectiveError) as err:
        load_objectives([obj])
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_bad_joint_names_and_windows_fail_at_binding(tmp_path) -> None:
    path = tmp_path / "c.json"
    path.write_text(json.dumps({"objectives": [{"type": "reach", "joint": "Tail", "target": [0, 1, 0]}]}))
    objs = load_objectives(path)
    with pytest.raises(ObjectiveError, match=r"objective 0 \(reach\): field 'joint': unknown joint or role 'Tail'"):
        bind_objectives(objs, _skeleton(), FPS, 40)
    late = load_objectives([{"type": "reach", "joint": "Hand_R", "target": [0, 1, 0], "window": [1.0, 5.0]}])
    with pytest.raises(ObjectiveError, match="window"):
        bind_objectives(late, _skeleton(), FPS, 40)


def test_comments_and_underscore_keys_are_ignored_and_plain_lists_have_no_objectives(tmp_path) -> None:
    objs = load_objectives([{"type": "hand-to-head", "comment": "x", "_note": 1, "hand": "left"}])
    assert isinstance(objs[0], JointDistance) and objs[0].joints == ("left_hand", "head")
    plain = tmp_path / "plain.json"
    plain.write_text("[]")
    assert load_objectives(plain) == []


# ---------------------------------------------------------------------------- values
def test_reach_error_is_the_closest_approach_in_the_window() -> None:
    P = _positions()
    b = _bind({"type": "reach", "joint": "Hand_R", "target": [-0.4, 1.3, 1.0], "window": [0.5, 1.5]})
    assert float(b.error(P)[0]) == pytest.approx(0.0, abs=1e-5)  # at t = 1 s the hand is exactly there
    far = _bind({"type": "reach", "joint": "Hand_R", "target": [-0.4, 1.3, 1.0], "window": [0.0, 0.5]})
    assert float(far.error(P)[0]) == pytest.approx(0.5, abs=1e-5)  # closest at t = 0.5 s


def test_joint_distance_any_and_all() -> None:
    P = _positions()
    any_ = _bind({"type": "joint-distance", "joints": ["Hand_R", "Head"], "distance": 0.3})
    all_ = _bind({"type": "joint-distance", "joints": ["Hand_R", "Head"], "distance": 0.3, "when": "all"})
    d = math.hypot(0.4, 0.4)
    assert float(any_.error(P)[0]) == pytest.approx(d - 0.3, abs=1e-5)
    assert float(all_.error(P)[0]) == pytest.approx(d - 0.3, abs=1e-5)


def test_avoid_and_stay_within_measure_penetration_and_excursion() -> None:
    P = _positions()
    av = _bind({"type": "avoid", "joints": ["Head"], "spheres": [{"center": [0, 1.7, 1.0], "radius": 0.25}]})
    assert float(av.error(P)[0]) == pytest.approx(0.25, abs=1e-5)
    box = _bind({"type": "avoid", "boxes": [{"min": [-1, 0, 5], "max": [1, 3, 6]}]})
    assert float(box.error(P)[0]) == 0.0  # the walk ends at z = 1.95
    sw = _bind({"type": "stay-within", "joints": ["Hips"], "min": [None, None, None], "max": [None, None, 1.5]})
    assert float(sw.error(P)[0]) == pytest.approx(1.95 - 1.5, abs=1e-5)
    assert isinstance(av.spec, Avoid) and isinstance(sw.spec, StayWithin)


def test_losses_have_gradients_that_reduce_them() -> None:
    wiggle = 0.02 * torch.sin(torch.arange(40.0) * 0.7)[None, :, None, None]  # some acceleration to reduce
    P = (_positions() + wiggle).requires_grad_(True)
    objs = [
        {"type": "reach", "joint": "Hand_R", "target": [0.5, 1.5, 1.0]},
        {"type": "stay-within", "min": [0.2, None, None]},
        {"type": "avoid", "spheres": [{"center": [0, 1.0, 1.0], "radius": 0.3}]},
        {"type": "path-time-agnostic", "joint": "Hips", "path": [[0.5, 0], [0.5, 2]], "window": [0, 1.95]},
        {"type": "realism"},
    ]
    for obj in objs:
        b = _bind(obj)
        loss = b.loss(P).sum()
        (g,) = torch.autograd.grad(loss, P)
        assert float(g.abs().sum()) > 0, obj["type"]
        stepped = P.detach() - 1e-3 * g / g.norm()
        assert float(b.loss(stepped).sum()) < float(loss.detach()), obj["type"]


# ---------------------------------------------------------------------------- time-agnostic path
def test_arc_resample_spaces_points_evenly() -> None:
    x = torch.tensor([[[0.0, 0.0], [0.1, 0.0], [3.0, 0.0], [4.0, 0.0]]])
    out = arc_resample(x, 5)
    assert torch.allclose(out[0, :, 0], torch.tensor([0.0, 1.0, 2.0, 3.0, 4.0]), atol=1e-6)


def test_time_agnostic_path_ignores_timing_but_not_geometry() -> None:
    T = 40
    u = torch.linspace(0, 1, T) ** 2  # accelerating along the path: no frame is where uniform timing puts it
    path = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]
    pts = torch.where(
        (u * 2 <= 1)[:, None], torch.stack([u * 2, torch.zeros(T)], -1), torch.stack([torch.ones(T), u * 2 - 1], -1)
    )
    P = torch.zeros(1, T, 5, 3)
    P[0, :, 0, 0], P[0, :, 0, 2] = pts[:, 0], pts[:, 1]
    obj = {"type": "path-time-agnostic", "joint": "Hips", "path": path, "window": [0, (T - 1) / FPS]}
    b = _bind(obj, T)
    assert isinstance(b.spec, PathTimeAgnostic) and b.spec.ground
    assert float(b.error(P)[0]) < 0.02
    assert float(b.loss(P)[0]) < 1e-3
    wrong = _bind(dict(obj, path=[[0.0, 0.0], [0.0, 1.0], [1.0, 1.0]]), T)
    assert float(wrong.error(P)[0]) > 0.3


def test_reach_objects_can_be_passed_directly() -> None:
    objs = load_objectives([Reach(joint="Hand_R", target=(0.0, 1.0, 0.0))])
    assert objs[0].kind == "reach"


def test_bench_settings_and_objective_table() -> None:
    from kinema.bench.objectives import parse_settings
    from kinema.cli.report import objective_table
    from kinema.errors import KinemaError

    assert parse_settings(["3x4", "5X12"]) == [(3, 4), (5, 12)]
    with pytest.raises(KinemaError, match="STEPSxITERS"):
        parse_settings(["five"])
    report = {
        "iterations": 8,
        "ddim_steps": 5,
        "seconds": 12.0,
        "objectives": [
            {"type": "reach", "before": [1.0], "optimised": [0.3], "after": [0.1], "final": [0.0]},
            {"type": "realism", "before": [20.0], "optimised": [18.0], "after": [17.0], "final": [9.0]},
        ],
    }
    table = objective_table(report)
    assert "objectives (8 noise iterations, 5 DDIM steps, 12.0 s):" in table
    assert "100.00 cm" in table and "10.00 cm" in table and "17.00 m/s^2" in table
    assert objective_table({}) == ""


def test_snap_imposes_the_timing_the_motion_reached() -> None:
    from kinema.constraints.types import EndEffectorConstraint, Root2DConstraint
    from kinema.objectives.snap import snap_constraints

    P = _positions()[0]
    root = P[:, 0, [0, 2]].clone()
    objs = [
        {"type": "reach", "joint": "Hand_R", "target": [-0.4, 1.3, 1.0], "window": [0.5, 1.5]},
        {"type": "reach", "joint": "Hand_R", "target": [1.6, 1.3, 1.0]},
        {"type": "stay-within", "min": [0.5, None, None], "window": [1.0, 1.5]},
        {"type": "path-time-agnostic", "joint": "Hips", "path": [[0, 0], [0, 3]], "window": [0, 1.95]},
    ]
    out = snap_constraints([_bind(o) for o in objs], P, _skeleton(), root)
    near, far, far_root, box, path = out
    assert isinstance(near, EndEffectorConstraint) and near.frame_indices == (20,)  # closest approach at 1 s
    assert isinstance(far_root, Root2DConstraint) and far_root.frame_indices == (20,)
    assert torch.allclose(far_root.positions[0].float(), torch.tensor([2.0, 1.0]))  # the root moves by the 2 m miss
    assert (
        isinstance(box, Root2DConstraint)
        and box.dense
        and torch.allclose(box.positions[:, 0].float(), torch.tensor(0.53))
    )
    assert isinstance(path, Root2DConstraint) and path.dense and len(path.frame_indices) == 40
    assert float(path.positions[-1, 1]) == pytest.approx(3.0) and float(path.positions[20, 1]) == pytest.approx(
        3.0 * 20 / 39, abs=1e-4
    )  # the pace the motion took: uniform here
    assert snap_constraints([_bind(objs[3])], P, _skeleton(), root, paths=False) == []


def test_an_objective_post_processing_made_worse_is_warned_of_with_both_values():
    report = {"objectives": [{"type": "reach", "after": [0.396, 0.10], "final": [1.166, 0.105]}]}
    assert worse_than_raw(report) == [
        "objective 0 (reach), sample 0: post-processing made it worse, 39.6 cm raw -> 116.6 cm final"
    ]
    assert worse_than_raw({"objectives": [{"type": "reach", "after": [0.4], "final": [0.0]}]}) == []
