"""Known-answer tests for kinema.evaluate (per-motion metrics and set-level distribution metrics)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from kinema.errors import KinemaError
from kinema.evaluate.distribution import (
    coverage_novelty_auc,
    diversity,
    fid,
    multimodality,
    r_precision,
    sliding_windows,
)
from kinema.evaluate.metrics import (
    contact_accuracy,
    end_effector_position_error,
    end_effector_rotation_error,
    foot_skate,
    foot_skate_with_count,
    fullbody_position_error,
    jerk,
    jitter,
    pelvis_deviation_p95,
    pelvis_deviations,
    root2d_error,
    smoothed_root_xz,
)
from kinema.geometry.rotations import axis_angle_to_quat, quat_mul
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

FPS = 30.0


def bandai_skeleton() -> Skeleton:
    """A small Bandai-named humanoid: pelvis 0.95 m up, ankles 8 cm and toes 2 cm above the floor."""
    joints = [
        ("Hips", None, (0.0, 0.0, 0.0)),  # placed 0.95 m up by root_translation
        ("Spine", "Hips", (0.0, 0.10, 0.0)),
        ("Chest", "Spine", (0.0, 0.15, 0.0)),
        ("Neck", "Chest", (0.0, 0.20, 0.0)),
        ("Head", "Neck", (0.0, 0.10, 0.0)),
    ]
    for side, s in (("L", 1.0), ("R", -1.0)):
        joints += [
            (f"Shoulder_{side}", "Chest", (s * 0.05, 0.15, 0.0)),
            (f"UpperArm_{side}", f"Shoulder_{side}", (s * 0.12, 0.0, 0.0)),
            (f"LowerArm_{side}", f"UpperArm_{side}", (s * 0.28, 0.0, 0.0)),
            (f"Hand_{side}", f"LowerArm_{side}", (s * 0.25, 0.0, 0.0)),
        ]
    for side, s in (("L", 1.0), ("R", -1.0)):
        joints += [
            (f"UpperLeg_{side}", "Hips", (s * 0.10, -0.05, 0.0)),
            (f"LowerLeg_{side}", f"UpperLeg_{side}", (0.0, -0.42, 0.0)),
            (f"Foot_{side}", f"LowerLeg_{side}", (0.0, -0.40, 0.0)),
            (f"Toes_{side}", f"Foot_{side}", (0.0, -0.06, 0.12)),
        ]
    names = [n for n, _, _ in joints]
    parents = [-1 if p is None else names.index(p) for _, p, _ in joints]
    return Skeleton(names, parents, [o for _, _, o in joints], name="test-bandai")


SKEL = bandai_skeleton()


def make_motion(root_xz: torch.Tensor, rotations: torch.Tensor | None = None, contacts=None) -> Motion:
    """Motion with the pelvis at height 0.95 following ``root_xz (T, 2)``; rest pose unless rotations given."""
    T = root_xz.shape[0]
    root = torch.zeros(T, 3, dtype=torch.float64)
    root[:, 0], root[:, 1], root[:, 2] = root_xz[:, 0], 0.95, root_xz[:, 1]
    if rotations is None:
        rotations = torch.zeros(T, SKEL.num_joints, 4, dtype=torch.float64)
        rotations[..., 0] = 1.0
    return Motion(SKEL, FPS, root, rotations, contacts)


def times(T: int) -> torch.Tensor:
    return torch.arange(T, dtype=torch.float64) / FPS


def random_rotations(T: int, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return axis_angle_to_quat(0.4 * torch.randn(T, SKEL.num_joints, 3, generator=g, dtype=torch.float64))


# ----------------------------------------------------------------------------- quality


def test_skeleton_stands_on_the_floor():
    P = make_motion(torch.zeros(1, 2, dtype=torch.float64)).positions[0]
    feet = [SKEL.index(n) for n in ("Foot_L", "Toes_L", "Foot_R", "Toes_R")]
    assert torch.allclose(P[feet, 1], torch.tensor([0.08, 0.02, 0.08, 0.02], dtype=torch.float64))
    assert SKEL.index("pelvis") == 0 and SKEL.index("left_toe") == SKEL.names.index("Toes_L")


def test_foot_sliding_at_10_cm_per_s_reads_10():
    T = 40
    xz = torch.stack([torch.zeros(T, dtype=torch.float64), 0.1 * times(T)], dim=1)  # 0.1 m/s along +z
    m = make_motion(xz, contacts=torch.ones(T, 4))
    skate, count = foot_skate_with_count(m)
    assert skate == pytest.approx(10.0, abs=1e-9) and count == 4 * T
    # the same slide flagged only on half the frames of one joint still averages 10 cm/s
    half = torch.zeros(T, 4)
    half[: T // 2, 1] = 1.0
    assert foot_skate(m, half) == pytest.approx(10.0, abs=1e-9)
    # the contact labels derived from the motion agree (slow and low): accuracy 1
    assert contact_accuracy(m) == pytest.approx(1.0)


def test_no_contact_frames_give_zero_skate_and_a_zero_count():
    T = 20
    xz = torch.stack([0.5 * times(T), torch.zeros(T, dtype=torch.float64)], dim=1)
    m = make_motion(xz, contacts=torch.zeros(T, 4))
    assert foot_skate_with_count(m) == (0.0, 0)
    assert contact_accuracy(m) == pytest.approx(1.0)  # 0.5 m/s is faster than the 0.3 m/s planted limit
    with pytest.raises(KinemaError):
        foot_skate(make_motion(xz))  # no contacts on the motion and none given


def test_contact_accuracy_counts_label_agreement():
    T = 10
    xz = torch.zeros(T, 2, dtype=torch.float64)  # standing still: every derived label is 1
    c = torch.ones(T, 4)
    c[:5, 0] = 0.2  # 5 of 40 labels predicted off
    assert contact_accuracy(make_motion(xz, contacts=c)) == pytest.approx(35 / 40)


def test_jerk_and_jitter_of_constant_velocity_are_zero():
    T = 30
    xz = torch.stack([0.7 * times(T), -0.3 * times(T)], dim=1)
    m = make_motion(xz)
    assert jerk(m) == pytest.approx(0.0, abs=1e-6)
    assert jitter(m) == pytest.approx(0.0, abs=1e-6)


def test_jerk_of_a_cubic_is_6a_and_jitter_its_mean_acceleration():
    a, T = 0.8, 25
    t = times(T)
    m = make_motion(torch.stack([torch.zeros_like(t), a * t**3], dim=1))
    assert jerk(m) == pytest.approx(6 * a, rel=1e-6)
    assert jitter(m) == pytest.approx(float((6 * a * t[1:-1]).abs().mean()), rel=1e-6)


# ----------------------------------------------------------------------------- constraint errors


def test_perfect_reconstruction_has_zero_constraint_errors():
    T = 30
    t = times(T)
    xz = torch.stack([0.3 * torch.sin(t), 1.2 * t], dim=1)
    m = make_motion(xz, random_rotations(T))
    P, G = m.positions, m.global_rotations
    frames = [0, 7, 15, 29]
    hand = SKEL.index("Hand_L")
    assert fullbody_position_error(m, frames, P[frames]) == pytest.approx(0.0, abs=1e-9)
    assert end_effector_position_error(m, "Hand_L", frames, P[frames, hand]) == pytest.approx(0.0, abs=1e-9)
    feet = ["left_foot", "right_toe"]
    idx = [SKEL.index(f) for f in feet]
    assert end_effector_position_error(m, feet, frames, P[frames][:, idx]) == pytest.approx(0.0, abs=1e-9)
    assert end_effector_rotation_error(m, hand, frames, G[frames, hand]) == pytest.approx(0.0, abs=1e-4)
    assert end_effector_rotation_error(m, hand, frames, -G[frames, hand]) == pytest.approx(0.0, abs=1e-4)
    assert root2d_error(m, frames, smoothed_root_xz(m)[frames]) == pytest.approx(0.0, abs=1e-9)
    assert pelvis_deviation_p95(m, frames, P[frames, 0][:, [0, 2]]) == pytest.approx(0.0, abs=1e-9)


def test_position_errors_are_in_centimetres():
    T = 5
    m = make_motion(torch.zeros(T, 2, dtype=torch.float64))
    P = m.positions
    frames = [1, 3]
    shifted = P[frames] + torch.tensor([0.0, 0.03, 0.04], dtype=torch.float64)  # 5 cm away
    assert fullbody_position_error(m, frames, shifted) == pytest.approx(5.0)
    assert end_effector_position_error(m, 3, frames, shifted[:, 3]) == pytest.approx(5.0)


def test_end_effector_rotation_off_by_a_quarter_turn_reads_90_degrees():
    T = 12
    m = make_motion(torch.zeros(T, 2, dtype=torch.float64), random_rotations(T, seed=3))
    hand = SKEL.index("Hand_R")
    frames = [2, 5, 11]
    turn = axis_angle_to_quat(torch.tensor([0.0, math.pi / 2, 0.0], dtype=torch.float64))
    target = quat_mul(turn, m.global_rotations[frames, hand])
    assert end_effector_rotation_error(m, "Hand_R", frames, target) == pytest.approx(90.0, abs=1e-6)


def test_root2d_error_of_a_straight_walk_against_its_line_is_zero():
    T = 90
    t = times(T)
    line = torch.stack([0.2 + 0.3 * t, 1.4 * t], dim=1)  # straight, constant speed
    m = make_motion(line)
    frames = list(range(0, T, 9)) + [T - 1]
    assert root2d_error(m, frames, line[frames]) == pytest.approx(0.0, abs=1e-6)


def test_pelvis_p95_of_a_sinusoidal_sway_is_the_sway_percentile():
    T, A, f = 120, 0.04, 1.0  # 4 cm side-to-side sway at 1 Hz while walking along z
    t = times(T)
    sway = A * torch.sin(2 * math.pi * f * t)
    m = make_motion(torch.stack([sway, 1.2 * t], dim=1))
    line = torch.stack([torch.zeros_like(t), 1.2 * t], dim=1)
    frames = torch.arange(T)
    expected = np.percentile(100 * np.abs(sway.numpy()), 95)
    assert pelvis_deviation_p95(m, frames, line) == pytest.approx(expected, abs=1e-9)
    assert pelvis_deviations(m, frames, line).max() == pytest.approx(100 * A, rel=1e-2)
    # the smoothed root (sigma 0.5 s) irons out most of the 1 Hz sway
    assert root2d_error(m, frames, line) < 0.2 * float(pelvis_deviations(m, frames, line).mean())


def test_constraint_shapes_are_checked():
    m = make_motion(torch.zeros(4, 2, dtype=torch.float64))
    with pytest.raises(KinemaError):
        root2d_error(m, [0, 1], torch.zeros(3, 2))
    with pytest.raises(KinemaError):
        fullbody_position_error(m, [9], torch.zeros(1, SKEL.num_joints, 3))


# ----------------------------------------------------------------------------- distribution metrics


def test_fid_of_identical_sets_is_zero_and_of_shifted_gaussians_the_squared_shift():
    g = torch.Generator().manual_seed(0)
    x = torch.randn(20000, 8, generator=g, dtype=torch.float64)
    assert fid(x, x) == pytest.approx(0.0, abs=1e-6)
    shift = torch.tensor([1.0, -2.0, 0.5, 0, 0, 0, 0, 3.0], dtype=torch.float64)
    assert fid(x, x + shift) == pytest.approx(float((shift**2).sum()), rel=1e-6)
    y = torch.randn(20000, 8, generator=g, dtype=torch.float64) + shift  # independent samples
    assert fid(x, y) == pytest.approx(float((shift**2).sum()), rel=0.03)


def test_fid_survives_singular_covariances():
    x = torch.randn(50, 4, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    x[:, 3] = 0.0  # a dead dimension
    assert math.isfinite(fid(x, x + 0.1)) and fid(x, x + 0.1) == pytest.approx(0.04, abs=1e-3)


def test_diversity_and_multimodality():
    g = torch.Generator().manual_seed(2)
    e = torch.zeros(400, 5, dtype=torch.float64)
    assert diversity(e, generator=g) == 0.0
    # points on two opposite corners of a line 2 apart: pairs differ with probability ~1/2
    e[200:, 0] = 2.0
    assert diversity(e, pairs=300, generator=g) == pytest.approx(1.0, abs=0.15)
    with pytest.raises(KinemaError):
        diversity(e[:10], pairs=300)
    # two samples per prompt at distance 3: every distinct pair reads exactly 3
    groups = [torch.tensor([[0.0, 0.0], [3.0, 0.0]]) + i for i in range(6)]
    assert multimodality(groups, pairs=10, generator=g) == pytest.approx(3.0)
    assert multimodality(torch.ones(4, 5, 3), generator=g) == 0.0


def test_r_precision_identical_embeddings_are_perfect_and_random_ones_chance():
    g = torch.Generator().manual_seed(3)
    emb = torch.randn(256, 16, generator=g)
    for batch in (None, 32):
        for metric in ("cosine", "euclidean"):
            r = r_precision(emb, emb, ks=(1, 3), batch_size=batch, generator=g, metric=metric)
            assert r == {1: 1.0, 3: 1.0}
    text, motion = torch.randn(3200, 16, generator=g), torch.randn(3200, 16, generator=g)
    r = r_precision(text, motion, ks=(1, 3), batch_size=32, generator=g, metric="euclidean")
    assert r[1] == pytest.approx(1 / 32, abs=0.012) and r[3] == pytest.approx(3 / 32, abs=0.02)
    text, motion = torch.randn(500, 16, generator=g), torch.randn(500, 16, generator=g)
    r = r_precision(text, motion, ks=(1, 50))  # whole set: chance k / N
    assert r[1] < 0.015 and r[50] == pytest.approx(0.1, abs=0.04)


def test_coverage_novelty_edge_cases():
    g = torch.Generator().manual_seed(4)
    train = torch.randn(40, 6, generator=g)
    test = torch.randn(30, 6, generator=g)
    for metric in ("cosine", "euclidean"):
        same_as_train = coverage_novelty_auc(train, train, test, metric=metric)
        assert same_as_train.novelty_auc == pytest.approx(0.0, abs=1e-6)
        same_as_test = coverage_novelty_auc(test, train, test, metric=metric)
        assert same_as_test.coverage_auc == pytest.approx(1.0, abs=1e-6)
    # curves: step functions of the threshold; the exact AUC matches a fine trapezoid sweep
    gen = torch.randn(50, 6, generator=g)
    thr = torch.linspace(0, 1, 20001)
    res = coverage_novelty_auc(gen, train, test, thresholds=thr)
    assert res.coverage[0] >= res.coverage[-1] and res.novelty[0] >= res.novelty[-1]
    assert float(torch.trapezoid(res.coverage, thr)) == pytest.approx(res.coverage_auc, abs=1e-3)
    assert float(torch.trapezoid(res.novelty, thr)) == pytest.approx(res.novelty_auc, abs=1e-3)
    assert 0.0 < res.coverage_auc < 1.0 and 0.0 < res.novelty_auc < 1.0


def test_coverage_novelty_on_windows_of_pose_sequences():
    g = torch.Generator().manual_seed(5)
    seqs = [torch.randn(L, 3, generator=g) for L in (12, 15)]
    w = sliding_windows(seqs, 10)
    assert w.shape == (3 + 6, 30) and torch.equal(w[1], seqs[0][1:11].reshape(-1))
    res = coverage_novelty_auc(seqs, seqs, seqs, window=10)
    assert res.coverage_auc == pytest.approx(1.0) and res.novelty_auc == pytest.approx(0.0, abs=1e-6)
