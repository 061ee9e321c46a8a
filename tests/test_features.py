"""Kimodo features: layout, heading, smoothing, contacts, local root, and features -> motion round trips."""

from __future__ import annotations

import math

import pytest
import torch

from kinema.geometry.rotations import axis_angle_to_quat
from kinema.motion.core import Motion
from kinema.motion.smoothing import smooth_time
from kinema.representation.kimodo_features import (
    features_to_motion,
    global_to_local_root,
    heading_from_positions,
    local_to_global_root,
    motion_to_features,
)
from kinema.representation.layout import FeatureLayout
from kinema.representation.stats import NormStats
from tests.test_motion import random_motion
from tests.test_skeleton import SCHEMES, humanoid


def standing(T=20, yaw=0.0, speed=0.0, fps=20.0) -> Motion:
    """The test humanoid standing (rest pose), turned by ``yaw`` about +Y, sliding forward at ``speed``."""
    skel = humanoid(SCHEMES["bandai"])
    q = torch.zeros(T, skel.num_joints, 4, dtype=torch.float64)
    q[..., 0] = 1
    q[:, 0] = axis_angle_to_quat(torch.tensor([0.0, yaw, 0.0], dtype=torch.float64))
    t = torch.arange(T, dtype=torch.float64) / fps
    fwd = torch.tensor([math.sin(yaw), 0.0, math.cos(yaw)], dtype=torch.float64)
    root = torch.tensor([0.0, 0.9, 0.0], dtype=torch.float64) + speed * t[:, None] * fwd
    return Motion(skel, fps, root, q)


def test_layout_dimension_and_split():
    layout = FeatureLayout(21)
    assert layout.dim == 5 + 12 * 21 + 4 == 261
    parts = layout.split(torch.zeros(2, 7, layout.dim))
    assert parts["joint_rot"].shape == (2, 7, 21, 6) and parts["contacts"].shape == (2, 7, 4)


@pytest.mark.parametrize("yaw", [0.0, math.pi / 2, -2.5])
def test_heading_follows_the_body_facing(yaw):
    # the test humanoid's left side is +x at rest, so at yaw 0 it faces +z
    m = standing(yaw=yaw)
    h = heading_from_positions(m.positions, m.skeleton)
    assert torch.allclose(h[0], torch.tensor([math.cos(yaw), math.sin(yaw)], dtype=torch.float64), atol=1e-9)


def test_smoothing_keeps_straight_lines_and_removes_sway():
    t = torch.arange(100, dtype=torch.float64)[:, None]
    line = torch.cat([0.05 * t, 0.01 * t], dim=1)
    assert torch.allclose(smooth_time(line, 10.0), line, atol=1e-9)
    sway = line + torch.cat([0.05 * torch.sin(2 * math.pi * t / 20), 0 * t], dim=1)
    assert (smooth_time(sway, 10.0) - line).abs()[20:-20].max() < 1e-3


def test_contacts_standing_vs_in_the_air_vs_sliding():
    # the test humanoid stands with its ankles 5 cm and toes 0 cm above the floor
    m = standing()
    layout = FeatureLayout(m.num_joints)
    assert layout.split(motion_to_features(m))["contacts"].min() == 1.0
    lifted = Motion(
        m.skeleton, m.fps, m.root_translation + torch.tensor([0, 0.5, 0.0], dtype=torch.float64), m.local_rotations
    )
    assert layout.split(motion_to_features(lifted))["contacts"].max() == 0.0
    assert layout.split(motion_to_features(standing(speed=2.0)))["contacts"].max() == 0.0


def test_features_round_trip_synthetic():
    m = random_motion(T=25)
    m = Motion(m.skeleton, m.fps, m.root_translation, m.local_rotations)
    f = motion_to_features(m)
    back = features_to_motion(f, m.skeleton, m.fps)
    assert torch.allclose(back.positions, m.positions, atol=1e-9)
    parts = FeatureLayout(m.num_joints).split(f)
    vel = (m.positions[1:] - m.positions[:-1]) * m.fps
    assert torch.allclose(parts["joint_vel"][:-1], vel, atol=1e-9)


def test_local_root_round_trip_and_invariance():
    m = random_motion(T=30)
    root = motion_to_features(m)[:, :5]
    local = global_to_local_root(root, m.fps)
    assert torch.allclose(local_to_global_root(local, m.fps, root[0]), root, atol=1e-9)
    # turning the whole motion about +Y leaves the local root unchanged
    turn = axis_angle_to_quat(torch.tensor([0.0, 0.7, 0.0], dtype=torch.float64))
    from kinema.geometry.rotations import quat_mul, quat_rotate

    q = m.local_rotations.clone()
    q[:, 0] = quat_mul(turn.expand(m.num_frames, 4), q[:, 0])
    turned = Motion(m.skeleton, m.fps, quat_rotate(turn.expand(m.num_frames, 4), m.root_translation), q)
    local2 = global_to_local_root(motion_to_features(turned)[:, :5], m.fps)
    assert torch.allclose(local2, local, atol=1e-6)
    # batched and differentiable
    r = root.clone().requires_grad_(True)
    global_to_local_root(r[None].expand(2, -1, -1), m.fps).sum().backward()
    assert torch.isfinite(r.grad).all()


def test_norm_stats_round_trip():
    x = torch.randn(50, 6) * torch.tensor([1.0, 2, 3, 4, 5, 0])
    stats = NormStats.compute([x[:20], x[20:]])
    assert torch.allclose(stats.denormalize(stats.normalize(x)), x, atol=1e-5)
    assert stats.std[-1] > 0  # constant channel is not divided by zero
    again = NormStats.from_dict(stats.to_dict())
    assert torch.equal(again.mean, stats.mean)


@pytest.mark.parametrize(
    "clip",
    [
        "Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh.gz",
        "Bandai-Namco-Research-Motiondataset-1/data/dataset-1_dance-short_normal_001.bvh.gz",
        "Bandai-Namco-Research-Motiondataset-2/data/dataset-2_wave-left-hand_elderly_003.bvh.gz",
    ],
)
def test_real_clip_features_round_trip_within_a_millimetre(clip, bandai_root):
    """On Bandai clips (real, or the synthetic ones of the same names: see conftest.py)."""
    from kinema.io.bvh import read_bvh

    m = read_bvh(bandai_root / clip, scale=0.01).prune(["joint_Root"]).resample(20)
    f = motion_to_features(m)
    assert f.shape == (m.num_frames, FeatureLayout(21).dim)
    back = features_to_motion(f.float(), m.skeleton, m.fps)
    err = (back.positions.double() - m.positions.double()).norm(dim=-1).max().item()
    assert err < 1e-3
    parts = FeatureLayout(21).split(f)
    assert 0.0 < parts["contacts"].mean() < 1.0 or "wave" in clip
    mirrored = features_to_motion(motion_to_features(m.mirror()), m.skeleton, m.fps).mirror()
    assert (mirrored.positions - m.positions).norm(dim=-1).max() < 1e-3


def test_rotate_features_matches_rotating_the_motion():
    from kinema.geometry.rotations import quat_mul, quat_rotate
    from kinema.representation.transform import rotate_features

    m = random_motion(T=20)
    layout = FeatureLayout(m.num_joints)
    angle = 0.9
    turn = axis_angle_to_quat(torch.tensor([0.0, angle, 0.0], dtype=torch.float64)).expand(m.num_frames, 4)
    q = m.local_rotations.clone()
    q[:, 0] = quat_mul(turn, q[:, 0])
    turned = Motion(m.skeleton, m.fps, quat_rotate(turn, m.root_translation), q)
    expected = motion_to_features(turned)
    got = rotate_features(motion_to_features(m), torch.tensor(angle, dtype=torch.float64), layout)
    assert torch.allclose(got, expected, atol=1e-6)


def test_isotropic_stats_are_rotation_invariant():
    from kinema.representation.transform import rotate_features

    m = random_motion(T=30)
    layout = FeatureLayout(m.num_joints)
    f = motion_to_features(m)
    a = NormStats.compute([f], xz_pairs=layout.xz_pairs())
    b = NormStats.compute(
        [rotate_features(f, torch.tensor(2.0, dtype=torch.float64), layout)], xz_pairs=layout.xz_pairs()
    )
    assert torch.allclose(a.std, b.std, atol=1e-5) and torch.allclose(a.mean, b.mean, atol=1e-5)
    assert a.mean[layout.slices["heading"]].abs().max() == 0
