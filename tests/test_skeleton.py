"""Skeleton: validation, roles across naming schemes, mirror pairs, pruning, tree info."""

from __future__ import annotations

import pytest
import torch

from kinema.errors import SkeletonError
from kinema.skeleton import Skeleton

BODY = ["hips", "spine", "neck", "head", "shoulder", "upper_arm", "elbow", "hand", "hip", "knee", "ankle", "toe"]

SCHEMES = {
    "bandai": {
        "pelvis": "Hips",
        "spine": "Spine",
        "neck": "Neck",
        "head": "Head",
        "left_shoulder": "Shoulder_L",
        "left_upper_arm": "UpperArm_L",
        "left_elbow": "LowerArm_L",
        "left_hand": "Hand_L",
        "left_hip": "UpperLeg_L",
        "left_knee": "LowerLeg_L",
        "left_ankle": "Foot_L",
        "left_toe": "Toes_L",
    },
    "mixamo": {
        "pelvis": "mixamorig:Hips",
        "spine": "mixamorig:Spine",
        "neck": "mixamorig:Neck",
        "head": "mixamorig:Head",
        "left_shoulder": "mixamorig:LeftShoulder",
        "left_upper_arm": "mixamorig:LeftArm",
        "left_elbow": "mixamorig:LeftForeArm",
        "left_hand": "mixamorig:LeftHand",
        "left_hip": "mixamorig:LeftUpLeg",
        "left_knee": "mixamorig:LeftLeg",
        "left_ankle": "mixamorig:LeftFoot",
        "left_toe": "mixamorig:LeftToeBase",
    },
    "biped": {
        "pelvis": "Bip01 Pelvis",
        "spine": "Bip01 Spine",
        "neck": "Bip01 Neck",
        "head": "Bip01 Head",
        "left_shoulder": "Bip01 L Clavicle",
        "left_upper_arm": "Bip01 L UpperArm",
        "left_elbow": "Bip01 L Forearm",
        "left_hand": "Bip01 L Hand",
        "left_hip": "Bip01 L Thigh",
        "left_knee": "Bip01 L Calf",
        "left_ankle": "Bip01 L Foot",
        "left_toe": "Bip01 L Toe0",
    },
    "blender": {
        "pelvis": "pelvis",
        "spine": "spine",
        "neck": "neck",
        "head": "head",
        "left_shoulder": "shoulder.L",
        "left_upper_arm": "upper_arm.L",
        "left_elbow": "forearm.L",
        "left_hand": "hand.L",
        "left_hip": "thigh.L",
        "left_knee": "shin.L",
        "left_ankle": "foot.L",
        "left_toe": "toe.L",
    },
    "lowercase_suffix": {
        "pelvis": "hips",
        "spine": "spine_01",
        "neck": "neck_01",
        "head": "head",
        "left_shoulder": "clavicle_l",
        "left_upper_arm": "upperarm_l",
        "left_elbow": "lowerarm_l",
        "left_hand": "hand_l",
        "left_hip": "thigh_l",
        "left_knee": "calf_l",
        "left_ankle": "foot_l",
        "left_toe": "ball_l",
    },
}


def humanoid(scheme: dict[str, str]) -> Skeleton:
    """A 20-joint humanoid in a given naming scheme (right side names made by swapping sides)."""
    from kinema.naming import swap_side

    left = {k: v for k, v in scheme.items() if k.startswith("left_")}
    names = [scheme["pelvis"], scheme["spine"], scheme["neck"], scheme["head"]]
    parents = [-1, 0, 1, 2]
    offsets = [[0, 0, 0], [0, 0.1, 0], [0, 0.4, 0], [0, 0.1, 0]]
    for sign in (1, -1):
        arm = ["left_shoulder", "left_upper_arm", "left_elbow", "left_hand"]
        leg = ["left_hip", "left_knee", "left_ankle", "left_toe"]
        for chain, root_parent, first in ((arm, 2, [0.05, 0.3, 0]), (leg, 0, [0.1, -0.05, 0])):
            prev = root_parent
            for i, role in enumerate(chain):
                name = left[role] if sign > 0 else swap_side(left[role])
                names.append(name)
                parents.append(prev)
                leg_off = [0, -0.05, 0.12] if i == 3 else [0, -0.4, 0]
                off = first if i == 0 else ([0.25, 0, 0] if chain is arm else leg_off)
                offsets.append([sign * off[0], off[1], off[2]])
                prev = len(names) - 1
    return Skeleton(names, parents, offsets)


@pytest.mark.parametrize("scheme", sorted(SCHEMES))
def test_roles_found_in_every_naming_scheme(scheme):
    skel = humanoid(SCHEMES[scheme])
    roles = skel.roles
    for role, name in SCHEMES[scheme].items():
        assert skel.names[roles[role]] == name, (scheme, role)
        right = role.replace("left_", "right_")
        if right != role:
            assert skel.names[roles[right]] != name
    assert skel.index("left_foot") == roles["left_ankle"]


@pytest.mark.parametrize("scheme", sorted(SCHEMES))
def test_mirror_map_pairs_left_and_right(scheme):
    skel = humanoid(SCHEMES[scheme])
    mmap = skel.mirror_map
    assert all(mmap[mmap[j]] == j for j in range(skel.num_joints))
    assert mmap[skel.roles["left_hand"]] == skel.roles["right_hand"]
    assert mmap[skel.roles["pelvis"]] == skel.roles["pelvis"]
    assert len(skel.mirror_pairs) == 8


def test_role_override_wins_and_unknown_override_is_an_error():
    skel = humanoid(SCHEMES["bandai"])
    over = Skeleton(skel.names, skel.parents, skel.offsets, role_overrides={"left_hand": "LowerArm_L"})
    assert over.names[over.roles["left_hand"]] == "LowerArm_L"
    with pytest.raises(SkeletonError, match="unknown joint 'Nope'"):
        Skeleton(skel.names, skel.parents, skel.offsets, role_overrides={"head": "Nope"})


def test_missing_role_error_names_the_role():
    skel = Skeleton(["a", "b"], [-1, 0], [[0, 0, 0], [0, 1, 0]])
    with pytest.raises(SkeletonError, match="left_hip"):
        skel.require_roles(["left_hip"])


@pytest.mark.parametrize(
    "names,parents,offsets,msg",
    [
        (["a", "a"], [-1, 0], [[0, 0, 0]] * 2, "duplicate"),
        (["a", "b"], [-1, 1], [[0, 0, 0]] * 2, "parents must be listed before"),
        (["a", "b"], [0, -1], [[0, 0, 0]] * 2, "root"),
        (["a", "b"], [-1, 0], [[0, 0, 0]], "offsets have shape"),
        (["a"], [-1, 0], [[0, 0, 0]], "parents for"),
    ],
)
def test_invalid_skeletons_raise(names, parents, offsets, msg):
    with pytest.raises(SkeletonError, match=msg):
        Skeleton(names, parents, offsets)


def test_tree_info():
    skel = humanoid(SCHEMES["bandai"])
    hand = skel.index("Hand_L")
    assert [skel.names[j] for j in skel.path_from_root(hand)] == [
        "Hips",
        "Spine",
        "Neck",
        "Shoulder_L",
        "UpperArm_L",
        "LowerArm_L",
        "Hand_L",
    ]
    assert skel.depths[hand] == 6
    d = skel.tree_distances()
    assert d[hand, hand] == 0 and d[hand, skel.index("Hand_R")] == 8
    assert torch.equal(d, d.T)


def test_prune_folds_offsets_and_rotations():
    # root -> a (rotated 90 deg about z at rest) -> b
    from kinema.geometry.rotations import axis_angle_to_quat

    rest = torch.zeros(3, 4, dtype=torch.float64)
    rest[:, 0] = 1
    rest[1] = axis_angle_to_quat(torch.tensor([0, 0, torch.pi / 2], dtype=torch.float64))
    skel = Skeleton(["root", "a", "b"], [-1, 0, 1], [[0, 0, 0], [1, 0, 0], [1, 0, 0]], rest_rotations=rest)
    pruned, keep = skel.prune(["a"])
    assert keep == [0, 2] and pruned.parents == (-1, 0)
    assert torch.allclose(pruned.offsets[1], torch.tensor([1.0, 1.0, 0.0], dtype=torch.float64), atol=1e-12)


def test_prune_root_makes_child_the_root_and_serialises():
    skel = Skeleton(["joint_Root", "Hips", "Spine"], [-1, 0, 1], [[0, 0, 0], [0, 1, 0], [0, 0.2, 0]])
    pruned, keep = skel.prune(["joint_Root"])
    assert pruned.names == ("Hips", "Spine") and pruned.parents == (-1, 0)
    again = Skeleton.from_dict(pruned.to_dict())
    assert again.same_topology(pruned) and torch.equal(again.offsets, pruned.offsets)
    with pytest.raises(SkeletonError, match="more than one root"):
        humanoid(SCHEMES["bandai"]).prune(["Hips"])
