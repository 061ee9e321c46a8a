"""Humanoid detection (kinema.retarget.detect): name tables, the tree, geometry, overrides, inspect."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from retarget_rigs import CMU, MIXAMO, UE5, build_rig

from kinema.cli import main
from kinema.io.gltf_writer import write_glb
from kinema.motion.core import Motion
from kinema.retarget import constraint_joint_names, find_humanoid, is_humanoid, load_character, model_joint_name
from kinema.retarget.names import limb_part
from kinema.skeleton import Skeleton

ROOT = Path(__file__).resolve().parents[1]
QUATERNIUS = Path(os.environ.get("KINEMA_QUATERNIUS", ROOT.parent / "shared/datasets/quaternius"))
LIMBS = ("upper_arm", "lower_arm", "hand", "upper_leg", "lower_leg", "foot")


def _names(h, slots) -> dict[str, str]:
    return {s: h.skeleton.names[h.slots[s]] for s in slots if s in h.slots}


def test_mixamo_names_map_every_slot_and_leave_extras_unmapped():
    h = find_humanoid(build_rig(MIXAMO, prefix="mixamorig:", a_pose=True))
    assert h.is_humanoid and not h.missing
    got = _names(h, ["hips", "chest", "left_upper_arm", "left_lower_arm", "right_upper_leg", "right_toes", "neck"])
    assert got == {
        "hips": "mixamorig:Hips",
        "chest": "mixamorig:Spine2",
        "left_upper_arm": "mixamorig:LeftArm",
        "left_lower_arm": "mixamorig:LeftForeArm",
        "right_upper_leg": "mixamorig:RightUpLeg",
        "right_toes": "mixamorig:RightToeBase",
        "neck": "mixamorig:Neck",
    }
    assert {"mixamorig:Spine1", "mixamorig:LeftHandIndex1", "mixamorig:HeadTop_End"} <= set(h.unmapped())


def test_ue5_names_with_ik_foot_helpers_as_followers():
    h = find_humanoid(build_rig(UE5, axis="x", root="root"))
    assert h.is_humanoid
    assert _names(h, ["hips", "left_shoulder", "left_lower_leg", "left_toes", "chest"]) == {
        "hips": "pelvis",
        "left_shoulder": "clavicle_l",
        "left_lower_leg": "calf_l",
        "left_toes": "ball_l",
        "chest": "spine_03",
    }
    names = h.skeleton.names
    assert [names[j] for j in h.followers["left_foot"]] == ["ik_foot_l"]
    assert names[h.slots["left_foot"]] == "foot_l" and not h.detached("left")


def test_cmu_hip_joints_are_not_upper_legs():
    h = find_humanoid(build_rig(CMU, axis=None, scale=100.0))
    assert h.is_humanoid
    assert _names(h, ["hips", "spine", "chest", "left_upper_leg", "left_hand"]) == {
        "hips": "Hips",
        "spine": "LowerBack",
        "chest": "Spine1",
        "left_upper_leg": "LeftUpLeg",
        "left_hand": "LeftHand",
    }


@pytest.mark.parametrize(
    ("names", "expect"),
    [
        (
            ["J_Bip_C_Hips", "J_Bip_L_UpperLeg", "J_Bip_L_LowerLeg", "J_Bip_R_UpperArm"],
            [None, "left_upper_leg", "left_lower_leg", "right_upper_arm"],
        ),
        (
            ["DEF-spine", "DEF-thigh.L", "DEF-shin.L", "DEF-upper_arm.R"],
            [None, "left_upper_leg", "left_lower_leg", "right_upper_arm"],
        ),
        (["Hips", "UpperLeg.L", "LowerLeg.L", "Fist.R"], [None, "left_upper_leg", "left_lower_leg", "right_hand"]),
    ],
)
def test_vrm_rigify_quaternius_limb_words(names, expect):
    for name, slot in zip(names, expect, strict=True):
        side, part, _ = limb_part(name)
        assert (None if part is None else f"{side}_{part}") == slot
    assert limb_part("DEF-thigh.L.001")[1] is None  # a Rigify segment bone is no slot
    assert limb_part("upperarm_twist_01_l")[1] is None


def _renamed(skeleton: Skeleton, prefix: str) -> Skeleton:
    names = [f"{prefix}{j:02d}" for j in range(skeleton.num_joints)]
    return Skeleton(names, skeleton.parents, skeleton.offsets, skeleton.rest_rotations, name="odd")


def test_geometry_fallback_finds_limbs_of_unknown_names():
    rig = build_rig(MIXAMO, prefix="mixamorig:")
    odd = _renamed(rig, "bone")
    h = find_humanoid(odd)
    assert h.is_humanoid
    want = find_humanoid(rig)
    for side in ("left", "right"):
        for part in ("upper_leg", "lower_leg", "foot", "upper_arm", "lower_arm"):
            assert h.slots[f"{side}_{part}"] == want.slots[f"{side}_{part}"], (side, part)
            assert h.found_by[f"{side}_{part}"] == "geometry"


def test_overrides_json_settles_odd_names(tmp_path):
    rig = _renamed(build_rig(CMU, axis=None), "j")
    names = rig.names
    ref = find_humanoid(build_rig(CMU, axis=None))
    limbs = {
        f"{s}_leg": [names[ref.slots[f"{s}_{p}"]] for p in ("upper_leg", "lower_leg", "foot", "toes")]
        for s in ("left", "right")
    } | {
        f"{s}_arm": [names[ref.slots[f"{s}_{p}"]] for p in ("shoulder", "upper_arm", "lower_arm", "hand")]
        for s in ("left", "right")
    }
    path = tmp_path / "over.json"
    path.write_text(json.dumps({"root": names[ref.slots["hips"]], "limbs": limbs}))
    h = find_humanoid(rig, path)
    assert h.is_humanoid
    assert all(h.slots[k] == ref.slots[k] for k in ref.slots if k not in ("neck", "head")), h.slots
    assert h.found_by["left_hand"] == "overrides"


def test_a_fox_is_no_humanoid_but_quaternius_people_are():
    fox = QUATERNIUS / "animals_pack/Fox.glb"
    if not fox.is_file():
        pytest.skip("shared Quaternius GLBs not found")
    assert not is_humanoid(load_character(fox).skeleton)
    knight = load_character(QUATERNIUS / "single_knight_pack/KnightCharacter.glb")
    h = knight.humanoid()
    assert h.is_humanoid and h.detached("left") and h.skeleton.names[h.slots["left_foot"]] == "Foot.L"
    assert h.skeleton.names[h.slots["hips"]] == "Body"  # the common ancestor of legs and chest


def test_constraint_names_of_a_character_map_to_the_model_skeleton():
    model = build_rig(MIXAMO, axis=None, name="model")  # any humanoid stands in for the model here
    bandai_like = Skeleton([n.replace("mixamorig:", "") for n in model.names], model.parents, model.offsets, name="m")
    character = build_rig(MIXAMO, prefix="mixamorig:", a_pose=True)
    table = constraint_joint_names(character, bandai_like)
    assert table["mixamorig:LeftHand"] == "LeftHand" and table["mixamorig:RightFoot"] == "RightFoot"
    assert model_joint_name("mixamorig:LeftHand", character, bandai_like) == "LeftHand"
    with pytest.raises(Exception, match="no humanoid bone"):
        model_joint_name("mixamorig:LeftHandIndex1", character, bandai_like)


def test_inspect_prints_the_mapping_and_what_is_unmapped(tmp_path, capsys):
    rig = build_rig(UE5, axis="x", root="root", name="ue")
    motion = Motion(rig, 30, rig.offsets[0][None], rig.rest_rotations[None].float())
    glb = write_glb(motion, tmp_path / "ue.glb")
    assert main(["inspect", str(glb)]) == 0
    out = capsys.readouterr().out
    assert "humanoid mapping: humanoid" in out
    assert "left_lower_leg   calf_l (by names)" in out
    assert "followed by ik_foot_l" in out
    assert "unmapped joints" in out and "index_01_l" in out.split("unmapped joints")[1]
