"""Joint ties (kinema.rig.ties): IK foot bones tied to their leg chain's end, found from a rig's clips."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch

from kinema.io.gltf import read_gltf
from kinema.motion.core import Motion
from kinema.rig import Rig
from kinema.rig.ties import RigTies, find_ties, rest_ties, tie_ratios
from kinema.skeleton import Skeleton

SHARED_QUATERNIUS = (
    Path(os.environ.get("KINEMA_DATASETS") or Path(__file__).resolve().parents[2] / "shared/datasets") / "quaternius"
)


def _legged(frames: int = 30) -> Motion:
    """Armature (static) -> Body (root) -> Hip -> Knee, and an IK foot hanging from the armature that
    follows the knee's end (0.3 below it, swinging), plus a static helper and a pole that follows the hip."""
    skel = Skeleton(
        ["Armature", "Body", "Hip", "Knee", "IKFoot", "Static", "KneePole"],
        [-1, 0, 1, 2, 0, 0, 0],
        [[0, 0, 0], [0, 1.0, 0], [0, -0.1, 0], [0, -0.3, 0], [0, 0.3, 0], [0.5, 0, 0], [0, 0.7, 0.3]],
        name="legged",
    )
    t = torch.linspace(0, 2 * torch.pi, frames, dtype=torch.float64)
    rots = torch.zeros(frames, 7, 4, dtype=torch.float64)
    rots[..., 0] = 1.0
    rots[:, 2, 0], rots[:, 2, 1] = torch.cos(0.2 * torch.sin(t)), torch.sin(0.2 * torch.sin(t))  # hip swings
    root = torch.zeros(frames, 3, dtype=torch.float64)
    lt = skel.offsets[None].repeat(frames, 1, 1).clone()
    m = Motion(skel, 30.0, root, rots, None, lt)
    _, P = m.global_transforms()
    lt[:, 4] = P[:, 3] + torch.tensor([0.0, -0.3, 0.0], dtype=torch.float64)  # the foot at the shin's end
    lt[:, 6] = P[:, 3] + torch.tensor([0.0, 0.0, 0.3], dtype=torch.float64)  # the pole in front of the knee
    return Motion(skel, 30.0, root, rots, None, lt)


def test_ik_foot_and_pole_are_tied_to_the_chain_and_a_static_helper_is_fixed() -> None:
    m = _legged()
    G, P = m.global_transforms()
    ties = find_ties(m.skeleton, 1, [(P, G)])
    names = m.skeleton.names
    by = {names[t.joint]: t for t in ties.ties}
    assert set(by) == {"IKFoot", "KneePole"}
    assert names[by["IKFoot"].anchor] == "Knee" and by["IKFoot"].max_distance == pytest.approx(0.3)
    assert names[by["KneePole"].anchor] == "Knee" and by["KneePole"].min_distance == pytest.approx(0.3)
    assert [names[j] for j in ties.fixed] == ["Static"]
    assert set(ties.derived) == {4, 5, 6}
    # a foot pulled away from its leg reads as a gap above 1
    far = P.clone()
    far[:, 4, 0] += 0.3
    assert float(tie_ratios(far, [by["IKFoot"]]).max()) > 1.4
    assert float(tie_ratios(P, [by["IKFoot"]]).max()) == pytest.approx(1.0)
    back = RigTies.from_dict(ties.to_dict(names), names)
    assert back.ties == ties.ties and back.fixed == ties.fixed


def test_rest_ties_tie_each_ik_bone_to_its_nearest_body_joint() -> None:
    m = _legged()
    ties = rest_ties(m.skeleton, 1)
    names = m.skeleton.names
    assert {names[t.joint]: names[t.anchor] for t in ties.ties}["IKFoot"] == "Knee"
    foot = next(t for t in ties.ties if names[t.joint] == "IKFoot")
    assert foot.max_distance == pytest.approx(0.3) and foot.offset == pytest.approx((0.0, -0.3, 0.0))
    half = ties.scaled(0.5).tie_for(4)
    assert half.max_distance == pytest.approx(0.15) and half.offset == pytest.approx((0.0, -0.15, 0.0))


@pytest.mark.parametrize(
    ("file", "pairs"),
    [
        ("animals_pack/Fox.glb", {"IKFrontLeg.L": "FrontLowerLeg.L", "IKBackLeg.R": "BackLowerLeg.R"}),
        ("dinosaurs_pack/Parasaurolophus.glb", {"BackFoot.L": "BackLowLeg.L", "BackFoot.R": "BackLowLeg.R"}),
    ],
)
def test_quaternius_ik_feet_are_tied_to_their_lower_legs(file: str, pairs: dict[str, str]) -> None:
    path = SHARED_QUATERNIUS / file
    if not path.is_file():
        pytest.skip("needs the shared Quaternius data")
    asset = read_gltf(path, fps=20.0)
    rig = Rig.from_skeleton(asset.skeleton)
    clips = [m.global_transforms()[::-1] for m in asset.motions.values()]
    ties = find_ties(asset.skeleton, rig.root, clips)
    names = asset.skeleton.names
    found = {names[t.joint]: names[t.anchor] for t in ties.ties}
    for joint, anchor in pairs.items():
        assert found[joint] == anchor
        t = ties.tie_for(names.index(joint))
        assert t.spread < 0.15 * t.max_distance  # the chain carries the foot: it moves little in the leg frame
    # every clip stays within its own bound, by construction
    for P, _ in clips:
        assert float(tie_ratios(P, ties.ties).max()) <= 1.0 + 1e-9
