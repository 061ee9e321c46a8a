"""Kimodo's own example files (tests/data/kimodo, Apache-2.0, see its README): fps, meta.json, poses."""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from kinema.constraints import (
    ConstraintError,
    ConstraintWarning,
    EndEffectorConstraint,
    Root2DConstraint,
    load_constraints,
    read_kimodo_meta,
)
from kinema.errors import KinemaError
from kinema.geometry.rotations import axis_angle_to_quat, quat_to_axis_angle
from kinema.kinematics import forward_kinematics
from kinema.representation.encode import encode_constraints
from kinema.representation.layout import FeatureLayout
from kinema.skeleton import Skeleton

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests/data/kimodo"
FPS = 20.0


@pytest.fixture(scope="module")
def skel() -> Skeleton:
    """The shipped model's 21-joint skeleton."""
    ckpt = json.loads((REPO / "kinema/assets/models/default/checkpoint.json").read_text())
    return Skeleton.from_dict(ckpt["skeleton"])


def raw(name: str):
    return json.loads((DATA / name / "constraints.json").read_text())


def frames_for(name: str) -> int:
    """Motion length at the model fps for the example's meta.json duration (as `generate` rounds it)."""
    return round(read_kimodo_meta(DATA / name).seconds * FPS)


def load_quiet(path, skel, num_frames, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConstraintWarning)
        return load_constraints(path, skel, FPS, num_frames, **kw)


def test_root_path_loads_at_kimodo_fps(skel):
    """05: 300 per-frame points at 30 fps over 10 s -> a path on all 200 model frames, resampled by time."""
    T = frames_for("05_root_path")
    assert T == 200
    with pytest.warns(ConstraintWarning, match=r"meta\.json.*Kimodo's 30 fps"):
        (c,) = load_constraints(DATA / "05_root_path/constraints.json", skel, FPS, T)
    src = torch.tensor(raw("05_root_path")[0]["smooth_root_2d"], dtype=torch.float64)
    assert isinstance(c, Root2DConstraint) and c.frames(FPS, T) == list(range(200))
    assert torch.allclose(c.positions[::2], src[::3])  # model frame 2k is source frame 3k (same time)
    mid = (src[1] + src[2]) / 2  # model frame 1 = 0.05 s = source frame 1.5
    assert torch.allclose(c.positions[1], mid)


def test_root_waypoints_land_on_model_frames(skel):
    """06: waypoints at Kimodo frames 0, 90, 180 (30 fps) are model frames 0, 60, 120 (20 fps)."""
    with pytest.warns(ConstraintWarning, match="30 fps"):
        (c,) = load_constraints(DATA / "06_root_waypoints/constraints.json", skel, FPS, frames_for("06_root_waypoints"))
    assert c.frames(FPS) == [0, 60, 120]
    assert torch.allclose(c.positions, torch.tensor(raw("06_root_waypoints")[0]["smooth_root_2d"], dtype=torch.float64))


def test_soma_end_effectors_keep_their_root(skel):
    """04: four hand/foot constraints carrying a 30-joint SOMA pose -> one root2d constraint, warned."""
    path = DATA / "04_ee_constraint/constraints.json"
    T = frames_for("04_ee_constraint")
    with pytest.warns(ConstraintWarning) as record:
        cs = load_constraints(path, skel, FPS, T)
    text = " ".join(str(w.message) for w in record)
    for part in (
        "constraints 0 (right-foot), 1 (left-foot), 2 (left-hand), 3 (right-hand)",
        "30 joints",
        "has 21",
        "SOMA",
        "root2d",
        "dropped",
    ):
        assert part in text
    (c,) = cs  # Kimodo repeats the same pose in each of the four: kept once
    assert isinstance(c, Root2DConstraint) and c.frames(FPS, T) == [19, 63]  # Kimodo frames 28, 94
    assert torch.allclose(c.positions, torch.tensor(raw("04_ee_constraint")[0]["smooth_root_2d"], dtype=torch.float64))
    enc = encode_constraints(cs, skel, FeatureLayout(skel.num_joints), FPS, T, dtype=torch.float64)
    assert enc.kinds["root2d"] == [19, 63]


def test_soma_pose_error_names_the_mismatch(skel):
    path = DATA / "04_ee_constraint/constraints.json"
    with pytest.raises(ConstraintError) as err:
        load_quiet(path, skel, frames_for("04_ee_constraint"), foreign_poses="error")
    msg = str(err.value)
    assert msg.startswith(f"{path}: constraint 0 (right-foot): field 'local_joints_rot': has 30 joints")
    for part in ("skeleton (bandai-namco) has 21", "Kimodo SOMA", "smooth_root_2d", "can still be used"):
        assert part in msg
    assert "\n" not in msg
    with pytest.raises(ConstraintError, match=r"constraint 0 \(fullbody\): field 'local_joints_rot': has 30 joints"):
        load_quiet(DATA / "07_mixed_constraints/constraints.json", skel, 101, foreign_poses="error")
    odd = raw("04_ee_constraint")[:1]
    odd[0]["local_joints_rot"] = [row[:5] for row in odd[0]["local_joints_rot"]]  # not a Kimodo skeleton: a mistake
    with pytest.raises(ConstraintError, match=r"'local_joints_rot': expected shape \(2, 21, 3\) .* got \(2, 5, 3\)"):
        load_quiet(odd, skel, 101)


def test_mixed_example_loads(skel):
    """07: a SOMA fullbody pose at Kimodo frame 108 and a path over frames 0..151 (5.07 s -> 101 model frames)."""
    T = frames_for("07_mixed_constraints")
    pose, path = load_quiet(DATA / "07_mixed_constraints/constraints.json", skel, T)
    assert pose.frames(FPS, T) == [72] and isinstance(pose, Root2DConstraint)
    assert path.frames(FPS, T) == list(range(T))  # 5.033 s, the last point, ends on the last model frame


def test_unknown_keys_still_error(skel, tmp_path):
    obj = raw("04_ee_constraint")[:1]
    obj[0]["frame_indice"] = obj[0].pop("frame_indices")
    with pytest.raises(ConstraintError, match=r"constraint 0 \(right-foot\): field 'frame_indice': unknown field"):
        load_quiet(obj, skel, 101)
    with pytest.raises(ConstraintError, match=r"field 'fsp': unknown top-level field"):
        load_constraints({"fsp": 30, "constraints": raw("06_root_waypoints")}, skel, FPS, 121)
    waypoints = raw("06_root_waypoints")
    waypoints[0]["heading"] = waypoints[0]["smooth_root_2d"]
    waypoints[0]["headnig"] = 1
    with pytest.raises(ConstraintError, match="field 'headnig': unknown field"):
        load_constraints({"fps": 30, "constraints": waypoints}, skel, FPS, 121)


def test_fps_in_file_and_argument(skel, tmp_path):
    """A plain list without meta.json is at the model fps; the file's "fps" or source_fps say otherwise."""
    plain = tmp_path / "waypoints.json"
    shutil.copy(DATA / "06_root_waypoints/constraints.json", plain)
    with pytest.raises(ConstraintError, match="frame 180 is beyond the motion's duration"):
        load_constraints(plain, skel, FPS, 121)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an explicit fps is not announced
        assert load_constraints(plain, skel, FPS, 121, source_fps=30)[0].frames(FPS) == [0, 60, 120]
        assert load_constraints(DATA / "06_root_waypoints/constraints.json", skel, FPS, 121, source_fps=60)[0].frames(
            FPS
        ) == [0, 30, 60]  # overrides the meta.json guess
    with_fps = tmp_path / "with_fps.json"
    with_fps.write_text(json.dumps({"fps": 30, "constraints": raw("06_root_waypoints")}))
    assert load_constraints(with_fps, skel, FPS, 121)[0].frames(FPS) == [0, 60, 120]
    assert load_constraints(with_fps, skel, FPS, 121, source_fps=30.0)[0].frames(FPS) == [0, 60, 120]
    with pytest.raises(ConstraintError, match=r"field 'fps': the file says its frames are at 30 fps but 20 fps"):
        load_constraints(with_fps, skel, FPS, 121, source_fps=20)
    with pytest.raises(ConstraintError, match="field 'fps': expected a positive number"):
        load_constraints({"fps": 0, "constraints": []}, skel, FPS)
    (tmp_path / "meta.json").write_text(json.dumps({"fps": 20, "layout": {}}))  # not Kimodo's: no guess
    with pytest.raises(ConstraintError, match="frame 180 is beyond"):
        load_constraints(plain, skel, FPS, 121)


def test_frames_that_collide_after_conversion(skel):
    waypoints = [{"type": "root2d", "frame_indices": [10, 11, 40], "smooth_root_2d": [[0, 0], [0, 1], [1, 1]]}]
    with pytest.raises(ConstraintError, match=r"frames 10 and 11 at 30 fps both fall on frame 7 at the model's 20 fps"):
        load_constraints(waypoints, skel, FPS, 100, source_fps=30)
    contacts = [{"type": "foot-contact", "frame_indices": [1, 2], "contacts": [[1, 1, 0, 0]] * 2}]
    with pytest.raises(ConstraintError, match=r"constraint 0 \(foot-contact\): field 'frame_indices': frames 1 and 2"):
        load_constraints(contacts, skel, FPS, 100, source_fps=30)
    dense = [
        {
            "type": "root2d",
            "frame_indices": [0, 3, 4, 5],
            "dense": True,
            "smooth_root_2d": [[0, 0], [0, 0.3], [0, 0.4], [0, 0.5]],
        }
    ]  # 4 and 5 fall on model frame 3 (3 m/s: faster paths are refused, kinema.constraints.plausibility)
    (c,) = load_constraints(dense, skel, FPS, 100, source_fps=30)
    assert c.frames(FPS) == [0, 1, 2, 3]  # the polyline resampled at 0, 0.05, 0.1, 0.15 s
    assert torch.allclose(c.positions[:, 1], torch.tensor([0.0, 0.15, 0.3, 0.45], dtype=torch.float64))
    times = [{"type": "root2d", "times": [0.5], "smooth_root_2d": [[0, 0]]}]
    assert load_constraints({"fps": 30, "constraints": times}, skel, FPS, 100)[0].frames(FPS) == [10]


def test_whole_pose_end_effector_on_the_model_skeleton(skel):
    """Kimodo's end-effector form with a 21-joint pose: the joint's target comes from forward kinematics."""
    gen = torch.Generator().manual_seed(0)
    rots = torch.randn(2, skel.num_joints, 3, generator=gen, dtype=torch.float64) * 0.3
    root = torch.tensor([[0.1, 0.9, 0.2], [0.3, 0.95, 0.5]], dtype=torch.float64)
    obj = [
        {
            "type": "left-hand",
            "frame_indices": [3, 60],
            "local_joints_rot": rots.tolist(),
            "root_positions": root.tolist(),
            "smooth_root_2d": [[0.1, 0.2], [0.3, 0.5]],
        },
        {
            "type": "end-effector",
            "joint_names": ["right_foot"],
            "frame_indices": [30],
            "local_joints_rot": rots[:1].tolist(),
            "root_positions": root[:1].tolist(),
        },
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        hand, foot = load_constraints({"fps": 30, "constraints": obj}, skel, FPS, 100)
    G, P = forward_kinematics(axis_angle_to_quat(rots), root, skel.offsets, skel.parents)
    j = skel.index("Hand_L")
    assert isinstance(hand, EndEffectorConstraint) and hand.frames(FPS) == [2, 40]
    assert torch.allclose(hand.positions, P[:, j], atol=1e-9)
    expected = axis_angle_to_quat(quat_to_axis_angle(G[:, j]))
    assert torch.allclose(axis_angle_to_quat(hand.rotations), expected, atol=1e-9)
    assert hand.smooth_root_2d.tolist() == [[0.1, 0.2], [0.3, 0.5]]
    assert foot.joint == "right_foot" and foot.frames(FPS) == [20]
    assert np.allclose(foot.positions.numpy(), P[:1, skel.index("Foot_R")].numpy())
    obj[0]["positions"] = [[0, 0, 0]] * 2
    with pytest.raises(ConstraintError, match=r"constraint 0 \(left-hand\): .*not both \('positions' given\)"):
        load_constraints(obj, skel, FPS, 100)


def test_read_kimodo_meta(tmp_path):
    meta = read_kimodo_meta(DATA / "04_ee_constraint/meta.json")
    assert meta.prompt_or_timeline().startswith("A person picks up an object in front of them")
    assert meta.seconds == pytest.approx(5.0333333) and meta.seed == 48 and meta.steps == 100 and meta.samples == 1
    assert (meta.guidance.mode, meta.guidance.w_text, meta.guidance.w_constr) == ("separated", 2.0, 2.0)
    assert meta.fps == 30.0
    multi = {"texts": ["walk", "turn"], "durations": [3.5, 4.0], "seed": 1, "cfg": {"enabled": False}}
    (tmp_path / "meta.json").write_text(json.dumps(multi))
    m = read_kimodo_meta(tmp_path)
    assert m.prompt_or_timeline() == [{"prompt": "walk", "seconds": 3.5}, {"prompt": "turn", "seconds": 4.0}]
    assert m.guidance.mode == "none" and m.steps is None
    for bad, part in [
        ({"text": "a", "duration": -1}, "field 'duration': expected a positive number, got -1"),
        ({"texts": ["a", "b"], "durations": [1.0]}, "field 'durations': expected one duration"),
        ({"text": "a", "duration": 2, "diffusion_steps": 2.5}, "field 'diffusion_steps'"),
        ({"text": "a", "duration": 2, "cfg": {"text_weight": "x"}}, "field 'cfg.text_weight'"),
        ({"duration": 2}, "field 'text': missing required field"),
        ([], "expected a JSON object"),
    ]:
        (tmp_path / "meta.json").write_text(json.dumps(bad))
        with pytest.raises(KinemaError, match=f"^{tmp_path / 'meta.json'}: .*{part}"):
            read_kimodo_meta(tmp_path / "meta.json")
