"""Issue 33 through the one request: the human model on the user's humanoid character (kinema generate
--rig CHARACTER, model.generate(rig=...), result.retarget(...)), constraints naming the character's joints."""

from __future__ import annotations

import json

import pytest
import torch
from retarget_rigs import MIXAMO, build_rig

import kinema
from kinema.cli import main
from kinema.errors import KinemaError
from kinema.generate import GenerationRequest, load_model
from kinema.io.gltf import read_gltf
from tests.rig_fixtures import quadruped, walking


@pytest.fixture(scope="module")
def mixamo_glb(tmp_path_factory):
    """A Mixamo-named character in an A pose with long legs, as a GLB (no mesh: a bone mesh is generated)."""
    path = tmp_path_factory.mktemp("char") / "mixamo.glb"
    rig = build_rig(MIXAMO, prefix="mixamorig:", a_pose=True, legs=1.2, arms=0.9)
    return kinema.Motion(rig, 20.0, torch.zeros(1, 3), torch.tensor([1.0, 0, 0, 0]).repeat(1, rig.num_joints, 1)).save(
        path)


def test_generate_on_a_character_raises_its_left_hand(mixamo_glb, tmp_path, capsys) -> None:
    out = tmp_path / "hand.glb"
    assert main(["generate", "A person raises their left hand.", "--seconds", "3", "--steps", "10", "--rig",
                 str(mixamo_glb), "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "a humanoid: generating with the human model" in printed and "limb directions within" in printed
    m = read_gltf(out)
    motion = next(iter(m.motions.values()))
    n, P = motion.skeleton.names, motion.positions
    assert n == read_gltf(mixamo_glb).skeleton.names  # the character's own joints
    left, right, head = (P[:, n.index(f"mixamorig:{j}"), 1] for j in ("LeftHand", "RightHand", "Head"))
    top = int(torch.argmax(left))
    assert float(left[top] - head[top]) > 0.05 and float(left[top] - right[top]) > 0.3


def test_a_target_on_the_characters_joint_is_met_on_the_character(mixamo_glb, tmp_path) -> None:
    model = load_model()
    plain = model.generate("A person walks forward.", seconds=3, steps=10, rig=str(mixamo_glb))
    hand = plain[0].skeleton.index("mixamorig:LeftHand")
    goal = (plain[0].positions[40, hand] + torch.tensor([0.0, 0.3, 0.1])).tolist()
    cons = tmp_path / "c.json"
    cons.write_text(json.dumps([{"type": "end-effector", "joint": "mixamorig:LeftHand", "frame_indices": [40],
                                 "positions": [goal]}]))
    res = model.generate("A person walks forward.", seconds=3, steps=10, rig=str(mixamo_glb), constraints=str(cons))
    got = res[0].positions[40, hand]
    assert float((got - torch.tensor(goal)).norm()) < 0.01
    rep = res.report.character[0]
    assert rep["targets_cm"]["mixamorig:LeftHand"] < 1.0 and rep["bone_drift_mm"] < 0.1
    assert abs(rep["ankle_cm"] - rep["ankle_source_cm"]) < 1.0  # planted feet on the floor, as the source's


def test_result_retarget_and_non_humanoids(mixamo_glb, tmp_path) -> None:
    res = load_model().generate(GenerationRequest(prompt="A person walks.", seconds=1.0, steps=3))
    moved = res.retarget(str(mixamo_glb))
    assert moved[0].skeleton.names == read_gltf(mixamo_glb).skeleton.names and moved.report.character
    assert res[0].skeleton.num_joints == 21  # the result itself is left as it is
    fox = walking(quadruped()).save(tmp_path / "quad.glb")
    with pytest.raises(KinemaError, match="not a humanoid"):
        load_model().generate("A person walks.", seconds=1.0, steps=2, rig=str(fox))
