"""Retargeting the default human model's walk onto other rigs (kinema.retarget.core), measured.

Source: the default model's 'A person walks forward.' (3 s, 10 steps). Targets: Mixamo-, UE5- and
CMU-named rigs built in tests/retarget_rigs.py with other proportions, A- and T-pose rests and bones
along +Y, +X or as plain BVH offsets; a Quaternius character whose feet are IK bones under the root;
and a Quaternius fox clip onto the wolf (same topology, no humanoid).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch
from retarget_rigs import CMU, MIXAMO, UE5, build_rig, source_walk

import kinema
from kinema.errors import KinemaError
from kinema.io import load_motion
from kinema.io.gltf_writer import write_glb
from kinema.motion.core import Motion
from kinema.retarget import (
    build_joint_map,
    load_character,
    meet_targets,
    retarget,
    retarget_report,
    save_character_motion,
)
from kinema.retarget.align import rest_frames
from kinema.retarget.core import retarget_with_map, source_planted
from kinema.retarget.quality import direction_errors

ROOT = Path(__file__).resolve().parents[1]
QUATERNIUS = Path(os.environ.get("KINEMA_QUATERNIUS", ROOT.parent / "shared/datasets/quaternius"))
needs_quaternius = pytest.mark.skipif(not QUATERNIUS.is_dir(), reason="shared Quaternius GLBs not found")


def _rest_motion(skeleton) -> Motion:
    rest = skeleton.rest_rotations
    if rest is None:
        rest = torch.zeros(skeleton.num_joints, 4, dtype=torch.float64)
        rest[:, 0] = 1
    return Motion(skeleton, 30, skeleton.offsets[0][None], rest[None])


def _checks(source: Motion, out: Motion, target, direction_deg: float = 3.0) -> dict:
    """The properties every humanoid retarget keeps; returns the report for rig-specific checks.
    ``direction_deg``: bound on the mean bone-direction error (legs included)."""
    jm = build_joint_map(source.skeleton, target)
    r = retarget_report(source, out, jm)
    assert out.skeleton.names == target.names
    assert torch.allclose(out.skeleton.offsets, target.offsets)
    assert r["bone_drift_mm"] < 1e-3 * max(1.0, r["scale"])  # bones keep their lengths
    # feet on the floor: planted ankles at their rest height, as high above it as the source's are
    assert abs(r["ankle_cm"] - r["ankle_source_cm"]) < 0.5, r
    assert r["direction_deg_mean"] < direction_deg, r
    assert r["skate_target_cm_s"] <= r["skate_source_cm_s"] + 0.5, r  # no added foot sliding
    err = direction_errors(source, out, jm)
    names = target.names
    feet = {g.foot for g in jm.legs}  # feet keep their own rest pitch: not in direction_errors
    bones = [(p, c) for c, p in jm.chain_parent.items() if p in jm.pairs and p not in feet]
    for k, (p, c) in enumerate(bones):
        if "Arm" in names[p] or "arm" in names[p] or "Spine" in names[p] or "spine" in names[p]:
            assert float(err[:, k].max()) < 1.0, (names[p], names[c])  # arms and spine follow exactly
    _left_stays_left(source, out, jm)
    return r


def _side(P: torch.Tensor, hand_l: int, hand_r: int, leg_l: int, leg_r: int) -> torch.Tensor:
    """(T,) how far the left hand is left of the right hand along the body's left axis."""
    left = P[:, leg_l] - P[:, leg_r]
    return ((P[:, hand_l] - P[:, hand_r]) * left).sum(-1) / left.norm(dim=-1)


def _left_stays_left(source: Motion, out: Motion, jm) -> None:
    s, t = source.skeleton.roles, jm
    hs = _side(source.positions.double(), s["left_hand"], s["right_hand"], s["left_hip"], s["right_hip"])
    inv = {a: b for b, a in jm.pairs.items()}
    ht = _side(out.positions.double(), *(inv[s[k]] for k in ("left_hand", "right_hand", "left_hip", "right_hip")))
    assert t is jm and bool(((hs > 0) == (ht > 0)).all()), "a hand crossed to the other side"


def test_walk_onto_a_mixamo_a_pose_glb_character(tmp_path):
    source = source_walk()
    rig = build_rig(MIXAMO, prefix="mixamorig:", a_pose=True, legs=1.2, arms=0.9, name="mixamo")
    glb = write_glb(_rest_motion(rig), tmp_path / "mixamo.glb")
    character = load_character(glb)
    out = retarget(source, character.skeleton)
    r = _checks(source, out, character.skeleton)
    # root motion scaled by leg length: the character walks as far, relative to its size
    travel_s = (source.root_translation[-1] - source.root_translation[0])[[0, 2]].norm()
    hips = out.skeleton.names.index("mixamorig:Hips")
    travel_t = (out.positions[-1, hips] - out.positions[0, hips])[[0, 2]].norm()
    assert abs(float(travel_t / travel_s) - r["scale"]) < 0.05 * r["scale"]
    # planted feet stay planted: the ankles barely move while the source's are planted
    planted = source_planted(source)
    foot = out.skeleton.names.index("mixamorig:LeftFoot")
    on = planted[source.skeleton.names.index("Foot_L")]
    step = (out.positions[1:, foot, [0, 2]] - out.positions[:-1, foot, [0, 2]]).norm(dim=-1) * out.fps
    assert float(step[on[1:] & on[:-1]].max()) < 0.01  # m/s
    assert out.foot_contacts is not None and out.foot_contacts.shape[1] == 4


def test_walk_onto_a_ue5_rig_with_bones_along_x_and_ik_feet():
    source = source_walk()
    rig = build_rig(UE5, axis="x", root="root", legs=0.85, scale=1.1, name="ue")
    out = retarget(source, rig)
    _checks(source, out, rig)
    P = out.positions
    names = out.skeleton.names
    for side in "lr":  # the IK foot helpers follow the feet they stand for
        gap = (P[:, names.index(f"ik_foot_{side}")] - P[:, names.index(f"foot_{side}")]).norm(dim=-1)
        assert float(gap.max()) < 1e-5
    root, pelvis = names.index("root"), names.index("pelvis")  # the root bone carries the root motion
    assert float((P[:, root, 1] - P[0, root, 1]).abs().max()) < 1e-9  # on the floor
    assert torch.allclose(
        P[:, root, [0, 2]] - P[:, pelvis, [0, 2]], P[0, root, [0, 2]] - P[0, pelvis, [0, 2]], atol=1e-5
    )


def test_walk_onto_a_cmu_bvh_in_centimetres_keeps_names_offsets_and_units(tmp_path):
    source = source_walk()
    rig = build_rig(CMU, axis=None, scale=100.0, arms=1.1, name="cmu")
    src_bvh = save_character_motion(_rest_motion(rig), tmp_path / "cmu_rest.bvh")
    character = load_character(src_bvh)
    out = retarget(source, character.skeleton)
    r = _checks(source, out, character.skeleton)
    assert 80 < r["scale"] < 130  # metres -> centimetres, absorbed by the leg-length scale
    written = save_character_motion(out, tmp_path / "walk.bvh")
    back = load_motion(written)
    assert back.skeleton.names == character.skeleton.names
    assert torch.allclose(back.skeleton.offsets[1:], character.skeleton.offsets[1:], atol=1e-4)  # root: frame 0
    assert float((back.positions - out.positions).abs().max()) < 1e-2  # centimetres, 6 decimals written


@needs_quaternius
def test_walk_onto_a_quaternius_character_moves_its_ik_feet_with_the_legs():
    source = source_walk()
    character = load_character(QUATERNIUS / "platformer_game_pack/Character.glb")
    out = retarget(source, character.skeleton)
    # its IK feet sit on the floor, not at the ankle: the shin-to-foot 'bone' leans unlike the source's
    r = _checks(source, out, character.skeleton, direction_deg=10.0)
    assert out.skeleton.mesh is not None  # the skin comes along
    names = out.skeleton.names
    P = out.positions.double()
    for side in "LR":  # Foot.X hangs from the root but stays at the lower leg's end: the mesh never tears
        gap = (P[:, names.index(f"Foot.{side}")] - P[:, names.index(f"LowerLeg.{side}")]).norm(dim=-1)
        assert float(gap.max() - gap.min()) < 1e-6
    assert r["skate_target_cm_s"] < 1.0


@needs_quaternius
def test_a_fox_clip_onto_the_wolf_through_the_same_code():
    fox = load_motion(QUATERNIUS / "animals_pack/Fox.glb", animation="Gallop")
    wolf = load_character(QUATERNIUS / "animals_pack/Wolf.glb")
    jm = build_joint_map(fox.skeleton, wolf.skeleton)
    assert jm.kind == "names" and len(jm.pairs) >= 0.9 * wolf.skeleton.num_joints
    out = retarget_with_map(fox, jm)
    err = direction_errors(fox, out, jm)
    assert float(err.mean()) < 2.0
    r = retarget_report(fox, out, jm)
    assert abs(r["lowest"] - r["lowest_rest"]) < 1e-6
    assert out.skeleton.names == wolf.skeleton.names and out.skeleton.mesh is not None


def test_a_raised_left_hand_is_the_characters_left_hand():
    """Issue 33's check: 'A person raises their left hand.' on a Mixamo-style A-pose character raises
    that character's left hand (above its head and the right hand), as on the source."""
    source = kinema.load_model().generate("A person raises their left hand.", seconds=3, steps=10)[0]
    rig = build_rig(MIXAMO, prefix="mixamorig:", a_pose=True, legs=1.2, arms=0.9)
    out = retarget(source, rig)
    n, P = out.skeleton.names, out.positions
    left, right, head = (P[:, n.index(f"mixamorig:{j}"), 1] for j in ("LeftHand", "RightHand", "Head"))
    top = int(torch.argmax(left))
    assert float(left[top] - head[top]) > 0.1 and float(left[top] - right[top]) > 0.3
    ns, Ps = source.skeleton.names, source.positions
    assert top == int(torch.argmax(Ps[:, ns.index("Hand_L"), 1]))  # at the source's moment


def test_a_hand_target_on_the_character_is_met_and_blended():
    """A constraint on the character's own joint (UE ``hand_l`` at a point on frame 30) is met after
    retargeting; frames far from it are untouched and the hand keeps its world rotation."""
    out = retarget(source_walk(), build_rig(UE5, axis="x", root="root", legs=0.85, scale=1.1))
    names, P = out.skeleton.names, out.positions
    hand = names.index("hand_l")
    want = P[30, hand] + torch.tensor([0.1, 0.25, 0.1])
    met = meet_targets(out, {"hand_l": {30: want.tolist()}})
    assert float((met.positions[30, hand] - want).norm()) < 1e-4
    assert float((met.positions[:20] - P[:20]).abs().max()) < 1e-5  # 0.15 s blends: frame 20 is untouched
    assert float((met.positions[:, names.index("hand_r")] - P[:, names.index("hand_r")]).abs().max()) < 1e-5
    assert torch.allclose(met.global_rotations[:, hand], out.global_rotations[:, hand], atol=1e-5)
    with pytest.raises(KinemaError, match="no hand or foot"):
        meet_targets(out, {"neck_01": {0: [0.0, 1.0, 0.0]}})


def test_a_motion_onto_its_own_skeleton_is_unchanged(tmp_path):
    """Retargeting is the identity between identical rigs: a walk on a Mixamo-named character,
    retargeted onto that same character again, keeps every joint where it was (the second source is
    a standing rest pose, unlike the Bandai one; its contacts are estimated from the clip, so a held
    foot may settle a few millimetres elsewhere on a frame: 2.4 mm at most here)."""
    rig = build_rig(MIXAMO, prefix="mixamorig:", a_pose=True, legs=1.1)
    once = retarget(source_walk(), rig)
    twice = retarget(once, rig)
    assert float((twice.positions - once.positions).norm(dim=-1).max()) < 3e-3


def test_a_flatter_foot_stands_at_its_rest_height_and_pitch():
    """The Mixamo rig's foot (ankle -> ball 27 degrees down) under the default model's steeper one (39):
    while the source stands, the character's foot keeps its own rest pitch and its ankle its rest height
    (copying the source's foot direction stood it on its toes, the ankle 4-5 cm up)."""
    source = kinema.load_model().generate("A person raises their left hand.", seconds=2, steps=10, seed=1)[0]
    rig = build_rig(MIXAMO, prefix="mixamorig:", a_pose=True, legs=1.1)
    out = retarget(source, rig)
    P, names = out.positions.double(), out.skeleton.names
    _, P0 = rest_frames(rig)
    for side in ("Left", "Right"):
        foot, toes = names.index(f"mixamorig:{side}Foot"), names.index(f"mixamorig:{side}ToeBase")
        d, d0 = P[:, toes] - P[:, foot], P0[toes] - P0[foot]
        pitch = torch.rad2deg(torch.atan2(-d[:, 1], d[:, [0, 2]].norm(dim=-1))).median()
        rest_pitch = torch.rad2deg(torch.atan2(-d0[1], d0[[0, 2]].norm()))
        assert abs(float(pitch - rest_pitch)) < 3.0, (side, float(pitch), float(rest_pitch))
        assert abs(float(P[:, foot, 1].median() - P0[foot, 1])) < 0.015, side  # metres


def test_a_bone_of_no_length_counts_no_direction_error():
    """CMU files such as 01_01.bvh put ``Neck`` on ``Spine1`` (offset 0 0 0): that bone has no direction,
    so it adds no error (it read 90 degrees on every frame)."""
    rig = build_rig(CMU, axis=None, scale=100.0, name="cmu")
    neck, head = rig.names.index("Neck"), rig.names.index("Head")
    offsets = rig.offsets.clone()
    offsets[head] += offsets[neck]
    offsets[neck] = 0.0
    rig = type(rig)(rig.names, rig.parents, offsets, name="cmu")
    source = source_walk()
    out = retarget(source, rig)
    r = retarget_report(source, out, build_joint_map(source.skeleton, rig))
    assert r["direction_deg_max"] < 45.0 and r["direction_deg_mean"] < 3.0, r


def test_a_skinned_characters_bones_do_not_turn_about_themselves():
    """The default model's spine, shoulders and arms come out turned 90-180 degrees about themselves
    (invisible in joint positions); copied onto a Mixamo A-pose character they wrung its torso by 175
    degrees against its hips. Each bone's own turn is rebuilt (kinema.retarget.align.least_twist_globals)."""
    rig = build_rig(MIXAMO, prefix="mixamorig:", a_pose=True, legs=1.2, arms=0.9, name="mixamo")
    hand = kinema.load_model().generate("A person raises their left hand.", seconds=3, steps=10, seed=2)[0]
    for source in (source_walk(), hand):
        r = retarget_report(source, retarget(source, rig), build_joint_map(source.skeleton, rig))
        assert r["twist_deg"] < 45.0, f"{r['twist_bone']} turns {r['twist_deg']:.0f} degrees about itself"
