"""Tied joints in generated motion (kinema.anyrig.tied): the leg chain reaches its IK foot, a foot out
of reach is brought back to its chain, static helpers stay at rest (synthetic rig)."""

from __future__ import annotations

import torch

from kinema.anyrig.tied import hold_ties, ties_for
from kinema.motion.core import Motion
from kinema.rig import Rig
from kinema.rig.ties import RigTies, Tie, find_ties, tie_ratios
from kinema.skeleton import Skeleton

FRAMES = 12


def _rig_motion(foot_shift: float) -> tuple[Motion, RigTies]:
    """Armature -> Body (root) -> Hip -> Knee, an IK foot 0.3 below the knee hanging from the armature,
    a static helper; the ties found from the rig's own (still) clip; then the foot pushed forward by
    ``foot_shift`` (the generator drifting it off its leg) and the helper moved."""
    skel = Skeleton(
        ["Armature", "Body", "Hip", "Knee", "IKFoot", "Static"],
        [-1, 0, 1, 2, 0, 0],
        [[0, 0, 0], [0, 0.7, 0], [0, -0.1, 0], [0, -0.3, 0], [0, 0.0, 0], [0.5, 0, 0]],
        name="legged",
    )
    rots = torch.zeros(FRAMES, 6, 4, dtype=torch.float64)
    rots[..., 0] = 1.0
    bend = torch.linspace(0.0, 0.3, FRAMES, dtype=torch.float64)  # the hip swings a little
    rots[:, 2, 0], rots[:, 2, 1] = torch.cos(bend / 2), torch.sin(bend / 2)
    root = torch.zeros(FRAMES, 3, dtype=torch.float64)
    lt = skel.offsets[None].repeat(FRAMES, 1, 1).clone()
    own = Motion(skel, 20.0, root, rots, None, lt)
    G, P = own.global_transforms()
    lt[:, 4] = P[:, 3] + torch.einsum(
        "tij,j->ti", _rotmat(G[:, 3]), torch.tensor([0.0, -0.3, 0.0], dtype=torch.float64)
    )
    own = Motion(skel, 20.0, root, rots, None, lt.clone())
    G, P = own.global_transforms()
    ties = find_ties(skel, 1, [(P, G)])
    lt[:, 4, 2] += foot_shift
    lt[:, 4, 1] += 0.1  # and up: within the leg's reach (0.6) for a small shift
    lt[:, 5] += 0.2
    return Motion(skel, 20.0, root, rots, None, lt), ties


def _rotmat(q: torch.Tensor) -> torch.Tensor:
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            torch.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def test_the_leg_reaches_a_foot_within_reach_and_the_foot_stays() -> None:
    m, ties = _rig_motion(0.3)
    assert [m.skeleton.names[t.anchor] for t in ties.ties] == ["Knee"] and m.skeleton.names[ties.fixed[0]] == "Static"
    before = m.positions.clone()
    assert float(tie_ratios(before, ties.ties).max()) > 1.1  # torn: the foot left its shin
    out, report = hold_ties(m, ties, root=1)
    P = out.positions
    assert torch.allclose(P[:, 4], before[:, 4], atol=1e-9)  # the (locked) foot did not move
    assert float(tie_ratios(P, ties.ties).max()) <= 1.0 + 1e-6 and report["ties_clamped_frames"] == 0
    assert report["ties_solved"] == 1 and report["tie_gap_ratio_max"] <= 1.0 + 1e-6
    assert torch.allclose(P[:, 5], torch.tensor([0.5, 0.0, 0.0], dtype=P.dtype))  # the helper back at rest
    bones = [(2, 3), (1, 2)]  # no bone of the chain changes length
    for a, b in bones:
        assert torch.allclose((P[:, a] - P[:, b]).norm(dim=-1), (before[:, a] - before[:, b]).norm(dim=-1))


def test_a_foot_out_of_reach_is_brought_back_to_its_chain() -> None:
    m, ties = _rig_motion(1.0)
    out, report = hold_ties(m, ties, root=1)
    assert report["ties_clamped_frames"] == FRAMES
    assert float(tie_ratios(out.positions, ties.ties).max()) <= 1.0 + 1e-6


def test_ties_come_from_clips_else_storage_else_the_rest_pose() -> None:
    m, ties = _rig_motion(0.0)
    rig = Rig.from_skeleton(m.skeleton)
    stored = RigTies([Tie(4, 3, 0.5, 0.2)], ()).to_dict(m.skeleton.names)
    assert ties_for(rig, None, stored).ties[0].max_distance == 0.5
    rest = ties_for(rig, None, None)
    assert {t.joint for t in rest.ties} == {4, 5}  # nearest joints at rest, helper included
    assert ties_for(rig, [m], None).ties  # from the clip
