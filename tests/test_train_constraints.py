"""Tests for kinema.train.constraints: the phase-2 constraint masks (patterns, keyframe counts, mixing,
batch determinism, builders and their errors). The test skeleton and layout are tests/test_train_losses.py's."""

from __future__ import annotations

import math

import pytest
import torch

from kinema.errors import KinemaError
from kinema.train.constraints import (
    effector_joints,
    end_effector_mask,
    fullbody_mask,
    max_keyframes_at,
    root_path_mask,
    sample_batch_masks,
    sample_constraint_mask,
)
from tests.test_train_losses import GROUPS, LAYOUT, SKEL


def _sample(pattern: str, seed: int, T: int = 60, max_k: int = 8, **kw) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return sample_constraint_mask(
        torch.zeros(T, LAYOUT.dim), LAYOUT, SKEL, max_k, g, {pattern: 1.0}, p_none=0.0, p_pair=0.0, **kw
    )


def _frames(mask: torch.Tensor) -> torch.Tensor:
    return mask.any(-1).nonzero().flatten()


def _check_sparse(mask: torch.Tensor, max_k: int, T: int) -> dict[str, torch.Tensor]:
    frames = _frames(mask)
    assert 1 <= len(frames) <= min(max_k, T)
    rows = mask[frames]
    assert (rows == rows[0]).all()  # the same channels at every chosen frame
    return LAYOUT.split(rows[0])


def test_fullbody_pattern_channels() -> None:
    for seed in range(30):
        p = _check_sparse(_sample("fullbody", seed), 8, 60)
        for k in ("root_pos", "heading", "joint_pos", "joint_rot"):
            assert (p[k] == 1).all()
        assert (p["joint_vel"] == 0).all() and (p["contacts"] == 0).all()


def test_end_effector_pattern_channels() -> None:
    eff = {e: effector_joints(SKEL, e) for e in ("left_hand", "right_hand", "left_foot", "right_foot")}
    assert eff["left_foot"] == [SKEL.index("Foot_L"), SKEL.index("Toes_L")]
    assert eff["right_hand"] == [SKEL.index("Hand_R")]
    seen_modes = set()
    for seed in range(60):
        p = _check_sparse(_sample("end_effector", seed), 8, 60)
        assert p["root_pos"].tolist() == [1, 0, 1]
        assert (p["heading"] == 0).all() and (p["joint_vel"] == 0).all() and (p["contacts"] == 0).all()
        pos, rot = p["joint_pos"], p["joint_rot"]  # (J, 3), (J, 6)
        assert ((pos == 0) | (pos == 1)).all() and (pos.amin(-1) == pos.amax(-1)).all()  # whole joints
        assert (rot.amin(-1) == rot.amax(-1)).all()
        pos_j, rot_j = (
            set(pos[:, 0].nonzero().flatten().tolist()),
            set(rot[:, 0].nonzero().flatten().tolist()),
        )
        assert pos_j | rot_j
        for joints in eff.values():  # each effector: all its joints or none, per channel kind
            for chosen in (pos_j, rot_j):
                assert len(chosen & set(joints)) in (0, len(joints))
        assert pos_j | rot_j <= {j for js in eff.values() for j in js}
        seen_modes |= {("pos" if pos_j else "") + ("rot" if rot_j else "")}
    assert {"pos", "rot", "posrot"} <= seen_modes


def test_root2d_and_contacts_patterns() -> None:
    headings = set()
    for seed in range(40):
        p = _check_sparse(_sample("root2d", seed), 8, 60)
        assert p["root_pos"].tolist() == [1, 0, 1]
        headings.add(tuple(p["heading"].tolist()))
        for k in ("joint_pos", "joint_vel", "joint_rot", "contacts"):
            assert (p[k] == 0).all()
        c = _check_sparse(_sample("contacts", seed), 8, 60)
        assert (c["contacts"] == 1).all()
        assert sum(float(c[k].sum()) for k in GROUPS if k != "contacts") == 0
    assert headings == {(0.0, 0.0), (1.0, 1.0)}


def test_root_path_pattern() -> None:
    T = 60
    for seed in range(40):
        m = _sample("root_path", seed, T=T)
        frames = _frames(m)
        assert len(frames) >= math.ceil(T / 4)
        assert (frames == torch.arange(int(frames[0]), int(frames[-1]) + 1)).all()  # one dense interval
        p = LAYOUT.split(m[frames[0]])
        assert p["root_pos"].tolist() == [1, 0, 1]
        assert (m[frames] == m[frames[0]]).all()
        assert sum(float(p[k].sum()) for k in ("joint_pos", "joint_vel", "joint_rot", "contacts")) == 0


def test_keyframe_count_bounds_and_bias() -> None:
    counts = [len(_frames(_sample("contacts", s, T=60, max_k=20))) for s in range(1000)]
    assert min(counts) == 1 and max(counts) <= 20
    assert counts.count(1) > counts.count(5) > counts.count(15)
    assert sum(counts) / len(counts) < 8  # biased towards few keyframes
    assert all(len(_frames(_sample("fullbody", s, T=3, max_k=20))) <= 3 for s in range(50))
    assert all(len(_frames(_sample("fullbody", s, max_k=1))) == 1 for s in range(20))


def test_mixing_frequencies() -> None:
    """fullbody never sets contacts and contacts sets nothing else, so a pair is visible in the mask."""
    g = torch.Generator().manual_seed(0)
    feats = torch.zeros(50, LAYOUT.dim)
    n, none, pair = 2000, 0, 0
    for _ in range(n):
        p = LAYOUT.split(sample_constraint_mask(feats, LAYOUT, SKEL, 10, g, {"fullbody": 1, "contacts": 1}))
        has_c, has_f = bool(p["contacts"].any()), bool(p["joint_rot"].any())
        none += not (has_c or has_f)
        pair += has_c and has_f
    assert abs(none / n - 0.10) < 0.03
    assert abs(pair / n - 0.25) < 0.04
    # default mix over all patterns: still ~10% unconstrained
    empty = sum(not bool(sample_constraint_mask(feats, LAYOUT, SKEL, 10, g).any()) for _ in range(n))
    assert abs(empty / n - 0.10) < 0.03


def test_batch_masks_deterministic_and_padding_free() -> None:
    feats = torch.randn(6, 45, LAYOUT.dim)
    lengths = torch.tensor([45, 10, 30, 1, 45, 22])

    def run(seed):
        return sample_batch_masks(feats, lengths, LAYOUT, SKEL, 20, torch.Generator().manual_seed(seed))

    a, b, c = run(5), run(5), run(6)
    assert a.shape == feats.shape and torch.equal(a, b) and not torch.equal(a, c)
    assert set(a.unique().tolist()) <= {0.0, 1.0}
    for seed in range(30):
        m = run(seed)
        for i, n in enumerate(lengths.tolist()):
            assert not m[i, n:].any()


def test_builders_and_errors() -> None:
    m = fullbody_mask(10, [0, 9], LAYOUT)
    assert _frames(m).tolist() == [0, 9]
    m = end_effector_mask(10, [3], LAYOUT, SKEL, positions=["left_hand"], rotations=["right_foot"])
    p = LAYOUT.split(m[3])
    assert p["joint_pos"][SKEL.index("Hand_L")].tolist() == [1, 1, 1] and p["joint_pos"].sum() == 3
    assert p["joint_rot"].sum() == 12 and p["root_pos"].tolist() == [1, 0, 1]
    assert _frames(root_path_mask(10, 2, 6, LAYOUT)).tolist() == [2, 3, 4, 5]
    with pytest.raises(KinemaError):
        fullbody_mask(10, [10], LAYOUT)
    with pytest.raises(KinemaError):
        root_path_mask(10, 4, 12, LAYOUT)
    with pytest.raises(KinemaError):
        effector_joints(SKEL, "tail")
    with pytest.raises(KinemaError):
        _sample("cartwheel", 0)


def test_max_keyframes_ramp() -> None:
    assert max_keyframes_at(0, 500, 1000) == 1
    assert max_keyframes_at(500, 500, 1000) == 1
    assert max_keyframes_at(1000, 500, 1000) == 11
    assert max_keyframes_at(1499, 500, 1000) == 20
    assert max_keyframes_at(10**6, 500, 1000) == 20
    vals = [max_keyframes_at(s, 0, 1000) for s in range(0, 1001, 10)]
    assert vals == sorted(vals) and set(vals) == set(range(1, 21))
