"""Constraint objects, the JSON format, error messages and the encoding onto Kimodo features."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import torch

from kinema.constraints import (
    ConstraintError,
    EndEffectorConstraint,
    FootContactConstraint,
    Root2DConstraint,
    load_constraints,
    save_constraints,
)
from kinema.constraints.io import fullbody_from_bvh
from kinema.errors import KinemaError
from kinema.geometry.rotations import quat_to_axis_angle
from kinema.io.bvh import read_bvh
from kinema.representation.encode import encode_constraints, world_to_relative
from kinema.representation.kimodo_features import motion_to_features
from kinema.representation.layout import FeatureLayout
from kinema.skeleton import Skeleton

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((REPO / "examples/constraints").glob("*.json"))
FPS, T = 20.0, 120


@pytest.fixture(scope="module")
def clip(walk_clip) -> Path:
    """The Bandai walk (real, or the synthetic one of the same name: see conftest.py)."""
    return walk_clip


@pytest.fixture(scope="module")
def motion(clip):
    """The 21-joint clip at the model fps (as kinema.data.bandai.load_clip builds it)."""
    return read_bvh(clip, scale=0.01).prune(["joint_Root"]).resample(FPS)


@pytest.fixture(scope="module")
def skel(motion) -> Skeleton:
    return motion.skeleton


@pytest.fixture(scope="module")
def layout(skel) -> FeatureLayout:
    return FeatureLayout(skel.num_joints)


def encode(cs, skel, layout, num_frames=T):
    return encode_constraints(cs, skel, layout, FPS, num_frames, dtype=torch.float64)


# ---------------------------------------------------------------------------- examples
def test_examples_exist():
    names = {p.name for p in EXAMPLES}
    assert {"waypoints.json", "dense_path.json", "hands.json", "feet_contacts.json",
            "inbetween_from_bvh.json"} <= names


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_example_loads_and_encodes(path, skel, layout, monkeypatch, bandai_workdir):
    monkeypatch.chdir(bandai_workdir)  # the in-betweening example names its BVH relative to the repository root
    cs = load_constraints(path, skel, FPS, T)
    assert cs
    t = encode_constraints(cs, skel, layout, FPS, T)
    assert t.x_tgt.shape == t.mask.shape == (T, layout.dim)
    assert t.world_xz.shape == (T, skel.num_joints, 2) and t.world_mask.shape == (T, skel.num_joints)
    assert set(t.mask.unique().tolist()) <= {0.0, 1.0} and t.mask.sum() > 0
    assert torch.isfinite(t.x_tgt).all() and (t.x_tgt[t.mask == 0] == 0).all()
    assert t.kinds and all(f for f in t.kinds.values())


# ---------------------------------------------------------------------------- fullbody vs features
def test_fullbody_from_bvh_matches_features(clip, motion, skel, layout):
    feats = motion_to_features(motion)
    frames = [0, 30, 100, motion.num_frames - 1]
    c = fullbody_from_bvh(clip, frames, skeleton=skel, fps=FPS, scale=0.01)
    t = encode([c], skel, layout, motion.num_frames)
    got, want = layout.split(t.x_tgt[frames]), layout.split(feats[frames])
    m = layout.split(t.mask[frames])
    assert (m["joint_rot"] == 1).all() and (m["joint_pos"] == 1).all() and (m["root_pos"] == 1).all()
    assert (m["heading"] == 1).all() and (m["joint_vel"] == 0).all() and (m["contacts"] == 0).all()
    assert torch.allclose(got["joint_rot"], want["joint_rot"], atol=1e-9, rtol=0)
    assert torch.allclose(got["joint_pos"][..., 1], want["joint_pos"][..., 1], atol=1e-9, rtol=0)
    assert torch.allclose(got["root_pos"][:, 1], want["root_pos"][:, 1], atol=1e-9, rtol=0)
    assert torch.allclose(got["heading"], want["heading"], atol=1e-9, rtol=0)
    # global x/z = relative joint x/z + root x/z, exactly, whichever root each side uses
    world = got["joint_pos"][..., [0, 2]] + got["root_pos"][:, None, [0, 2]]
    assert torch.allclose(world, motion.positions[frames][..., [0, 2]], atol=1e-9, rtol=0)
    # the documented approximation: pelvis ground projection instead of the smoothed root
    pelvis = motion.positions[frames][:, 0]
    assert torch.allclose(got["root_pos"][:, [0, 2]], pelvis[:, [0, 2]], atol=1e-9, rtol=0)
    assert (got["root_pos"][:, [0, 2]] - want["root_pos"][:, [0, 2]]).norm(dim=-1).max() < 0.15
    # with Kimodo's smoothed root given, every constrained channel equals the features
    exact = c.copy(smooth_root_2d=feats[frames][:, [0, 2]])
    t2 = encode([exact], skel, layout, motion.num_frames)
    sel = t2.mask.bool()
    assert torch.allclose(t2.x_tgt[sel], feats[sel], atol=1e-9, rtol=0)


def test_fullbody_arrays_equal_bvh_source(clip, motion, skel, layout):
    frames = [3, 40]
    from_file = fullbody_from_bvh(clip, frames, skeleton=skel, fps=FPS, scale=0.01)
    obj = [{"type": "fullbody", "frame_indices": frames,
            "local_joints_rot": quat_to_axis_angle(motion.local_rotations[frames]).tolist(),
            "root_positions": motion.root_translation[frames].tolist()}]
    inline = load_constraints(obj, skel, FPS, T)[0]
    a, b = encode([from_file], skel, layout), encode([inline], skel, layout)
    assert torch.equal(a.mask, b.mask) and torch.allclose(a.x_tgt, b.x_tgt, atol=1e-9, rtol=0)


def test_from_bvh_native_fps_and_recenter(clip, skel, layout):
    c = fullbody_from_bvh(clip, None, skeleton=skel, fps=30.0, scale=0.01, source_times=[0.0, 3.0],
                                    recenter=True)
    assert c.times == (0.0, 3.0)
    assert torch.allclose(c.root_positions[0, [0, 2]], torch.zeros(2, dtype=torch.float64))
    assert c.root_positions[1, 2] > 1.0  # walked forward several metres


# ---------------------------------------------------------------------------- frames and times
def test_times_equal_frame_indices(skel, layout):
    def pair(**frames):
        return [Root2DConstraint(positions=[[0.0, 1.0], [2.0, 3.0]], heading=[[0.0, 2.0], [1.0, 0.0]], **frames),
                EndEffectorConstraint(joint="left_hand", positions=[[0.1, 1.0, 0.2], [0.0, 1.1, 0.3]],
                                      rotations=[[0.1, 0.2, 0.3], [0.0, 0.0, 1.0]], **frames),
                FootContactConstraint(contacts=[[1, 0, 1, 0], [0, 0, 1, 1]], **frames)]

    a = encode(pair(frame_indices=[10, 35]), skel, layout)
    b = encode(pair(times=[0.5, 1.75]), skel, layout)
    assert torch.equal(a.x_tgt, b.x_tgt) and torch.equal(a.mask, b.mask) and a.kinds == b.kinds
    assert torch.equal(a.world_xz, b.world_xz) and torch.equal(a.world_mask, b.world_mask)
    # round half up: 0.025 s at 20 fps is frame 1
    assert Root2DConstraint(positions=[[0.0, 0.0]], times=[0.025]).frames(FPS) == [1]


# ---------------------------------------------------------------------------- channel mapping
def test_end_effector_world_xz_and_root(skel, layout):
    j = skel.index("left_hand")
    pos = torch.tensor([[0.3, 1.1, 0.7]], dtype=torch.float64)
    s = layout.slices
    jx, jy, jz = (s["joint_pos"].start + 3 * j + k for k in range(3))
    t = encode([EndEffectorConstraint(joint="left_hand", frame_indices=[12], positions=pos)], skel, layout)
    assert t.mask[12, jy] == 1 and t.x_tgt[12, jy] == pytest.approx(1.1)
    assert t.mask[12, jx] == 0 and t.mask[12, jz] == 0 and t.mask[12, 0] == 0
    assert t.world_mask[12, j] == 1 and torch.allclose(t.world_xz[12, j], pos[0, [0, 2]])
    # the sampler's per-step conversion against its current root estimate
    root = torch.zeros(T, 2, dtype=torch.float64)
    root[12] = torch.tensor([0.1, 0.2])
    x, m = world_to_relative(t, root, layout)
    assert m[12, jx] == 1 and x[12, jx] == pytest.approx(0.2) and x[12, jz] == pytest.approx(0.5)
    # smoothed root given -> relative x/z written and masked directly, nothing left in world_xz
    c = EndEffectorConstraint(joint="Hand_L", frame_indices=[12], positions=pos, smooth_root_2d=[[0.1, 0.2]])
    t = encode([c], skel, layout)
    assert not t.has_world and t.mask[12, [0, 2, jx, jz]].eq(1).all()
    assert t.x_tgt[12, jx] == pytest.approx(0.2) and t.x_tgt[12, jz] == pytest.approx(0.5)
    # a root2d waypoint at the same frame also fixes the root x/z
    t = encode([EndEffectorConstraint(joint="left_hand", frame_indices=[12], positions=pos),
                Root2DConstraint(frame_indices=[12], positions=[[0.1, 0.2]])], skel, layout)
    assert not t.has_world and t.x_tgt[12, jx] == pytest.approx(0.2)


def test_foot_is_ankle_rotation_only(skel, layout):
    a = skel.index("left_ankle")
    t = encode([EndEffectorConstraint(joint="left_foot", frame_indices=[5], rotations=[[0.0, 0.5, 0.0]])],
               skel, layout)
    r = layout.slices["joint_rot"].start + 6 * a
    assert t.mask[5].sum() == 6 and (t.mask[5, r:r + 6] == 1).all() and t.kinds == {"end-effector:Foot_L": [5]}


def test_later_constraint_wins(skel, layout):
    t = encode([Root2DConstraint(frame_indices=[7], positions=[[1.0, 2.0]]),
                Root2DConstraint(frame_indices=[7, 8], positions=[[3.0, 4.0], [5.0, 6.0]])], skel, layout)
    assert t.x_tgt[7, [0, 2]].tolist() == [3.0, 4.0] and t.x_tgt[8, [0, 2]].tolist() == [5.0, 6.0]
    contacts = layout.slices["contacts"]
    t = encode([FootContactConstraint(frame_indices=[3], contacts=[[1, 1, 1, 1]]),
                FootContactConstraint(frame_indices=[3], contacts=[[0, 1, 0, 0]])], skel, layout)
    assert t.x_tgt[3, contacts].tolist() == [0.0, 1.0, 0.0, 0.0] and (t.mask[3, contacts] == 1).all()


def test_dense_path_interpolates_every_frame(skel, layout):
    c = Root2DConstraint(frame_indices=[10, 20], positions=[[0.0, 0.0], [1.0, 2.0]],
                         heading=[[1.0, 0.0], [0.0, 1.0]], dense=True)
    t = encode([c], skel, layout)
    assert t.kinds == {"root2d:dense": list(range(10, 21))}
    assert (t.mask[10:21, [0, 2, 3, 4]] == 1).all() and t.mask[10:21].sum() == 44
    assert t.mask[:10].sum() == 0 and t.mask[21:].sum() == 0
    assert t.x_tgt[15, [0, 2]].tolist() == pytest.approx([0.5, 1.0])
    assert t.x_tgt[15, 3:5].tolist() == pytest.approx([math.cos(math.pi / 4), math.sin(math.pi / 4)])


# ---------------------------------------------------------------------------- malformed input
GOOD = {"type": "root2d", "frame_indices": [0], "smooth_root_2d": [[0.0, 0.0]]}
BAD_CASES = {
    "unknown_type": ({"type": "teleport", "frame_indices": [1]}, "type", "unknown constraint type"),
    "unknown_joint": ({"type": "end-effector", "joint": "left_pinky", "frame_indices": [1],
                       "positions": [[0, 1, 0]]}, "joint", "unknown joint or role 'left_pinky'"),
    "beyond_duration": ({"type": "left-hand", "frame_indices": [150], "positions": [[0, 1, 0]]},
                        "frame_indices", "6.000 s"),
    "beyond_duration_times": ({"type": "left-hand", "times": [7.0], "positions": [[0, 1, 0]]}, "times", "6.000 s"),
    "negative_frame": ({"type": "root2d", "frame_indices": [-1], "smooth_root_2d": [[0, 0]]},
                       "frame_indices", "negative frame -1"),
    "wrong_shape": ({"type": "right-foot", "frame_indices": [1, 2], "positions": [[0, 1], [0, 1]]},
                    "positions", "expected shape (2, 3)"),
    "wrong_shape_fullbody": ({"type": "fullbody", "frame_indices": [1], "local_joints_rot": [[[0, 0, 0]]],
                              "root_positions": [[0, 1, 0]]}, "local_joints_rot", "expected shape (1, 21, 3)"),
    "nan": ({"type": "root2d", "frame_indices": [1], "smooth_root_2d": [[float("nan"), 0]]},
            "smooth_root_2d", "NaN or inf"),
    "inf": ({"type": "right-hand", "times": [1.0], "rotations": [[0, float("inf"), 0]]}, "rotations", "NaN or inf"),
    "missing_field": ({"type": "foot-contact", "frame_indices": [1]}, "contacts", "missing required field"),
    "missing_joint": ({"type": "end-effector", "frame_indices": [1], "positions": [[0, 1, 0]]},
                      "joint", "missing required field"),
    "both_frames_and_times": ({"type": "root2d", "frame_indices": [1], "times": [0.05],
                               "smooth_root_2d": [[0, 0]]}, "frame_indices", "exactly one"),
    "neither_frames_nor_times": ({"type": "root2d", "smooth_root_2d": [[0, 0]]}, "frame_indices", "exactly one"),
    "missing_bvh": ({"type": "fullbody", "bvh": "no/such/clip.bvh", "source_frames": [0], "scale": 0.01},
                    "bvh", "not found"),
    "typo_field": ({"type": "root2d", "frame_index": [1], "smooth_root_2d": [[0, 0]]}, "frame_index",
                   "unknown field"),
    "contact_values": ({"type": "foot-contact", "frame_indices": [1], "contacts": [[1, 0, 2, 0]]}, "contacts",
                       "0 or 1"),
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_malformed_constraint_messages(case, skel, tmp_path):
    bad, field, reason = BAD_CASES[case]
    path = tmp_path / "constraints.json"
    path.write_text(json.dumps([GOOD, bad]))
    with pytest.raises(ConstraintError) as err:
        load_constraints(path, skel, FPS, T)
    msg = str(err.value)
    assert isinstance(err.value, KinemaError)
    assert msg.startswith(f"{path}: constraint 1 ({bad['type']}): field '{field}': "), msg
    assert reason in msg, msg


def test_non_json_file_names_line(skel, tmp_path):
    path = tmp_path / "constraints.json"
    path.write_text('[\n  {"type": "root2d",\n   "frame_indices": [1]\n   "smooth_root_2d": [[0, 0]]}\n]\n')
    with pytest.raises(ConstraintError, match=r"constraints\.json: not valid JSON: line 4"):
        load_constraints(path, skel, FPS, T)


def test_python_objects_are_validated_too(skel, layout):
    with pytest.raises(ConstraintError, match=r"^constraint 1 \(end-effector\): field 'joint': unknown joint"):
        encode([Root2DConstraint(frame_indices=[0], positions=[[0.0, 0.0]]),
                EndEffectorConstraint(joint="tail", frame_indices=[0], positions=[[0.0, 1.0, 0.0]])], skel, layout)


def test_bvh_missing_joints_and_wrong_scale(clip, skel):
    names = [n if n != "Hand_L" else "LeftHandX" for n in skel.names]
    other = Skeleton(names, skel.parents, skel.offsets)
    with pytest.raises(ConstraintError, match="LeftHandX"):
        fullbody_from_bvh(clip, [0], skeleton=other, fps=FPS, scale=0.01)
    with pytest.raises(ConstraintError, match="field 'scale'"):
        fullbody_from_bvh(clip, [0], skeleton=skel, fps=FPS)  # centimetres read as metres


# ---------------------------------------------------------------------------- round trip
def test_save_load_round_trip(skel, layout, tmp_path, monkeypatch, bandai_workdir):
    monkeypatch.chdir(bandai_workdir)
    # one file per example: the examples' root targets together would ask for impossible speeds
    for k, p in enumerate(EXAMPLES):
        cs = load_constraints(p, skel, FPS, T)
        cs.append(EndEffectorConstraint(joint="Head", frame_indices=[3], rotations=[[0.1, -0.2, 0.3]]))
        path = save_constraints(cs, tmp_path / "out" / f"{k}.json")
        back = load_constraints(path, skel, FPS, T)
        assert len(back) == len(cs) and all(a.same_as(b) for a, b in zip(cs, back, strict=True))
        a, b = encode(cs, skel, layout), encode(back, skel, layout)
        assert torch.equal(a.x_tgt, b.x_tgt) and torch.equal(a.mask, b.mask)
    assert not list((tmp_path / "out").glob("*.tmp"))
