"""Per-joint features (kinema.representation.joint): round trips on creature-like rigs, masks, padding."""

from __future__ import annotations

import math

import pytest
import torch
from rig_fixtures import fish, hexapod, human, quadruped, snake2, walking

from kinema.errors import KinemaError
from kinema.geometry.rotations import axis_angle_to_quat, quat_mul, quat_rotate
from kinema.motion.core import Motion
from kinema.representation.batching import pad_batch
from kinema.representation.joint import CONTACT, NUM_CHANNELS, JointRepresentation, JointStats
from kinema.rig import Rig
from kinema.skeleton import Skeleton


def _turning(skel: Skeleton, frames: int = 40) -> Motion:
    """``walking`` plus a root turning by 90 degrees over the clip and a start away from the origin."""
    m = walking(skel, frames=frames, speed=0.4)
    yaw = torch.linspace(0, math.pi / 2, frames, dtype=torch.float64)
    turn = axis_angle_to_quat(torch.stack([torch.zeros_like(yaw), yaw, torch.zeros_like(yaw)], -1))
    rots = m.local_rotations.clone()
    rots[:, 0] = quat_mul(turn, rots[:, 0])
    root = m.root_translation + torch.tensor([1.5, 0.0, -0.7], dtype=torch.float64)
    return Motion(skel, m.fps, root, rots)


@pytest.mark.parametrize("make", [quadruped, hexapod, fish, snake2, human])
def test_round_trip_reproduces_joint_positions(make) -> None:
    skel = make()
    rep = JointRepresentation(Rig.from_skeleton(skel), 20.0)
    motion = _turning(skel)
    f = rep.from_motion(motion)
    assert f.shape == (motion.num_frames, skel.num_joints, NUM_CHANNELS) and f.dtype == torch.float64
    start = motion.positions[0, rep.rig.root, [0, 2]]
    back = rep.to_motion(f, start_xz=start)
    err = (back.positions - motion.positions).norm(dim=-1).max()
    assert err < 1e-6, float(err)
    assert back.foot_contacts.shape == (motion.num_frames, len(rep.rig.contacts))


def test_heading_frame_makes_features_invariant_to_turning_the_world() -> None:
    skel = quadruped()
    rep = JointRepresentation(Rig.from_skeleton(skel), 20.0)
    motion = _turning(skel)
    turn = axis_angle_to_quat(torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64))
    rots = motion.local_rotations.clone()
    rots[:, 0] = quat_mul(turn, rots[:, 0])
    turned = Motion(skel, motion.fps, quat_rotate(turn.expand(motion.num_frames, 4), motion.root_translation), rots)
    a, b = rep.from_motion(motion), rep.from_motion(turned)
    body = torch.ones(skel.num_joints, dtype=torch.bool)
    body[rep.rig.root] = False
    assert torch.allclose(a[:, body], b[:, body], atol=1e-9)
    psi_a = torch.atan2(a[:, rep.rig.root, 10], a[:, rep.rig.root, 9])
    psi_b = torch.atan2(b[:, rep.rig.root, 10], b[:, rep.rig.root, 9])
    assert torch.allclose(torch.remainder(psi_b - psi_a, 2 * math.pi), torch.full_like(psi_a, 1.0), atol=1e-9)


def test_root_other_than_joint_zero() -> None:
    """A static helper joint above the hips (as in many GLB rigs): the rig's root is the hips."""
    base = quadruped()
    names = ["Armature", *base.names]
    offsets = torch.cat([torch.zeros(1, 3, dtype=torch.float64), base.offsets])
    skel = Skeleton(names, [-1, *[p + 1 for p in base.parents]], offsets)
    rig = Rig.from_skeleton(skel, overrides={"root": "Body"})
    rep = JointRepresentation(rig, 20.0)
    motion = _turning(skel)
    f = rep.from_motion(motion)
    back = rep.to_motion(f, start_xz=motion.positions[0, rig.root, [0, 2]])
    assert (back.positions - motion.positions)[:, 1:].norm(dim=-1).max() < 1e-6


def test_channel_masks_and_padding() -> None:
    quad, fish_rep = (JointRepresentation(Rig.from_skeleton(s), 20.0) for s in (quadruped(), fish()))
    assert quad.channel_mask[:, CONTACT].sum() == 8 and not fish_rep.channel_mask[:, CONTACT].any()
    assert quad.channel_mask[:, :CONTACT].all()
    a = quad.from_motion(walking(quad.rig.skeleton, frames=30))
    b = fish_rep.from_motion(walking(fish_rep.rig.skeleton, frames=20))
    batch = pad_batch([a, b], [quad, fish_rep])
    J = quad.num_joints
    assert batch.x.shape == (2, 30, J, NUM_CHANNELS)
    assert batch.frame_mask.sum(1).tolist() == [30, 20] and batch.joint_mask.sum(1).tolist() == [J, 7]
    assert torch.equal(batch.x[1, :20, :7], b) and batch.x[1, 20:].abs().sum() == 0
    assert not batch.loss_mask[1, :, 7:].any() and not batch.loss_mask[1, 20:].any()
    with pytest.raises(KinemaError, match="do not fit"):
        pad_batch([b], [quad])


def test_stats_normalise_and_skip_masked_channels() -> None:
    rep = JointRepresentation(Rig.from_skeleton(fish()), 20.0)
    clips = [rep.from_motion(walking(rep.rig.skeleton, frames=n)) for n in (20, 25)]
    stats = JointStats.compute(clips, rep.channel_mask)
    assert torch.all(stats.mean[:, CONTACT] == 0) and torch.all(stats.std[:, CONTACT] == 1)
    rep = JointRepresentation(rep.rig, 20.0, stats)
    x = clips[0]
    assert torch.allclose(rep.denormalize(rep.normalize(x)), x, atol=1e-5)
