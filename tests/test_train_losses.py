"""Tests for kinema.train: the Eq. 1 loss (losses.py) and phase-2 constraint masks (constraints.py)."""

from __future__ import annotations

import math

import pytest
import torch

from kinema.errors import KinemaError
from kinema.geometry.rotations import axis_angle_to_quat, matrix_to_sixd, sixd_to_matrix
from kinema.motion.core import Motion
from kinema.representation.kimodo import motion_to_features
from kinema.representation.layout import FeatureLayout
from kinema.representation.stats import NormStats
from kinema.skeleton import Skeleton
from kinema.train.constraints import (
    effector_joints,
    end_effector_mask,
    fullbody_mask,
    max_keyframes_at,
    root_path_mask,
    sample_batch_masks,
    sample_constraint_mask,
)
from kinema.train.losses import TERMS, LossWeights, motion_loss

GROUPS = ("root_pos", "heading", "joint_pos", "joint_vel", "joint_rot", "contacts")


# ---------------------------------------------------------------------------- fixtures
def _skeleton() -> Skeleton:
    """A 20-joint humanoid with Bandai-style names (roles found by kinema.naming)."""
    joints = [
        ("Hips", -1, (0, 0.95, 0)),
        ("Spine", 0, (0, 0.1, 0)),
        ("Neck", 1, (0, 0.4, 0)),
        ("Head", 2, (0, 0.12, 0)),
    ]
    for side, sx in (("L", 1.0), ("R", -1.0)):
        base = len(joints)
        joints += [
            (f"Shoulder_{side}", 2, (0.05 * sx, 0, 0)),
            (f"UpperArm_{side}", base, (0.1 * sx, 0, 0)),
            (f"LowerArm_{side}", base + 1, (0.27 * sx, 0, 0)),
            (f"Hand_{side}", base + 2, (0.25 * sx, 0, 0)),
        ]
    for side, sx in (("L", 1.0), ("R", -1.0)):
        base = len(joints)
        joints += [
            (f"UpperLeg_{side}", 0, (0.1 * sx, -0.05, 0)),
            (f"LowerLeg_{side}", base, (0, -0.42, 0)),
            (f"Foot_{side}", base + 1, (0, -0.42, 0)),
            (f"Toes_{side}", base + 2, (0, -0.06, 0.13)),
        ]
    names, parents, offsets = zip(*joints, strict=True)
    return Skeleton(names, parents, offsets, name="test")


SKEL = _skeleton()
LAYOUT = FeatureLayout(SKEL.num_joints)


def _motion(T: int, seed: int) -> Motion:
    g = torch.Generator().manual_seed(seed)
    J = SKEL.num_joints
    aa = torch.cumsum(0.08 * torch.randn(T, J, 3, generator=g), dim=0)  # smooth-ish random rotations
    aa = aa.clamp(-1.2, 1.2)
    root = torch.zeros(T, 3)
    root[:, 0] = torch.linspace(0, 1.5, T)
    root[:, 1] = 0.95 + 0.03 * torch.sin(torch.arange(T) / 3.0)
    root[:, 2] = torch.linspace(0, 2.0, T) ** 1.2
    return Motion(SKEL, 30.0, root, axis_angle_to_quat(aa))


LENGTHS = (40, 27)
RAW = [motion_to_features(_motion(n, seed)) for seed, n in enumerate(LENGTHS)]
STATS = NormStats.compute(RAW)


def _batch() -> tuple[torch.Tensor, torch.Tensor]:
    """Normalised padded target (B, T, D) with zeros as padding, and the (B, T) validity mask."""
    T = max(LENGTHS)
    x = torch.zeros(len(LENGTHS), T, LAYOUT.dim)
    mask = torch.zeros(len(LENGTHS), T, dtype=torch.bool)
    for i, f in enumerate(RAW):
        x[i, : len(f)] = STATS.normalize(f)
        mask[i, : len(f)] = True
    return x, mask


def _loss(pred, target, mask, **kw):
    return motion_loss(pred, target, mask, LAYOUT, SKEL, STATS, **kw)


# ---------------------------------------------------------------------------- loss
def test_zero_for_identical_and_fk_consistent_with_features() -> None:
    target, mask = _batch()
    total, terms = _loss(target.clone(), target, mask)
    assert set(terms) == set(TERMS)
    assert total.item() < 1e-8
    assert terms["fk"].item() < 1e-8  # FK of the true rotations reproduces the true j_p


def test_positive_for_different_prediction_and_weights() -> None:
    target, mask = _batch()
    pred = target + 0.3 * torch.randn(target.shape, generator=torch.Generator().manual_seed(0))
    total, terms = _loss(pred, target, mask)
    assert all(terms[k].item() > 0 for k in TERMS)
    w = LossWeights()
    assert total.item() == pytest.approx(sum(getattr(w, k) * terms[k].item() for k in TERMS), rel=1e-5)
    assert w.to_dict()["fk"] == 5.0 and LossWeights.from_dict(w.to_dict()) == w
    assert (w.root_pos, w.heading, w.joint_pos, w.joint_vel, w.joint_rot, w.contacts) == (10, 2, 10, 3, 10, 4)
    total2, _ = _loss(pred, target, mask, weights=LossWeights(fk=0.0))
    assert total2.item() == pytest.approx(total.item() - 5.0 * terms["fk"].item(), rel=1e-5)


def test_constraint_term_pulls_only_on_constrained_entries() -> None:
    target, mask = _batch()
    cmask = torch.zeros_like(target)
    cmask[0, [3, 10], :3] = 1.0  # root position on two frames of clip 0
    cmask[1, 30:, :] = 1.0  # padded frames of clip 1: must not count
    pred = target.clone()
    pred[0, 3, 0] += 1.0  # one constrained entry off by 1 std (linear region: 1 - beta / 2)
    pred[0, 5, 0] += 1.0  # an unconstrained entry off: no constraint loss
    pred = pred.requires_grad_()
    w = LossWeights()
    total, terms = _loss(pred, target, mask, constraint_mask=cmask)
    assert terms["constraint"].item() == pytest.approx((1.0 - w.constraint_beta / 2) / 6, rel=1e-5)
    _, plain = _loss(pred, target, mask)
    base = sum(getattr(w, k) * plain[k].item() for k in TERMS)
    assert total.item() == pytest.approx(base + w.constraint * terms["constraint"].item(), rel=1e-5)
    total.backward()
    no_constr = torch.autograd.grad(_loss(pred, target, mask)[0], pred)[0]
    extra = pred.grad - no_constr
    assert extra[0, 3, 0].item() == pytest.approx(w.constraint / 6, rel=1e-4)
    assert extra[0, 5].abs().max().item() < 1e-6
    with pytest.raises(ValueError, match="constraint_mask"):
        _loss(pred, target, mask, constraint_mask=cmask[:, :, :5])


def test_padding_is_ignored_even_with_nan() -> None:
    target, mask = _batch()
    pred = target + 0.2 * torch.randn(target.shape, generator=torch.Generator().manual_seed(1))
    total, terms = _loss(pred, target, mask)
    junk_pred, junk_target = pred.clone(), target.clone()
    junk_pred[~mask] = torch.randn(int((~mask).sum()), LAYOUT.dim) * 100
    junk_target[~mask] = float("nan")
    junk_pred[1, -1, :5] = float("inf")
    junk_pred.requires_grad_(True)
    total2, terms2 = _loss(junk_pred, junk_target, mask)
    assert total2.item() == pytest.approx(total.item(), rel=1e-6)
    for k in TERMS:
        assert terms2[k].item() == pytest.approx(terms[k].item(), rel=1e-6, abs=1e-9)
    total2.backward()
    assert torch.isfinite(junk_pred.grad).all()
    assert (junk_pred.grad[~mask] == 0).all()
    assert junk_pred.grad[mask].abs().sum() > 0


def test_mean_over_valid_frames_only() -> None:
    """A term is a per-frame mean: one clip padded longer gives the same value."""
    target, mask = _batch()
    pred = target + 0.1
    _, terms = _loss(pred, target, mask)
    longer = torch.nn.functional.pad(target, (0, 0, 0, 13))
    longer_pred = torch.nn.functional.pad(pred, (0, 0, 0, 13), value=7.0)
    longer_mask = torch.nn.functional.pad(mask, (0, 13))
    _, terms2 = _loss(longer_pred, longer, longer_mask)
    for k in TERMS:
        assert terms2[k].item() == pytest.approx(terms[k].item(), rel=1e-6)


@pytest.mark.parametrize("group", GROUPS)
def test_each_term_responds_only_to_its_group(group: str) -> None:
    target, mask = _batch()
    pred = target.clone()
    sl = LAYOUT.slices[group]
    pred[..., sl] += 0.5 * torch.randn(pred[..., sl].shape, generator=torch.Generator().manual_seed(2))
    _, terms = _loss(pred, target, mask)
    changed = {k for k in TERMS if terms[k].item() > 1e-7}
    expected = {group, "fk"} if group == "joint_rot" else {group}
    assert changed == expected


def test_fk_term_for_90_degree_rotation_error() -> None:
    target, mask = _batch()
    raw = STATS.denormalize(target)
    rot = LAYOUT.split(raw)["joint_rot"].clone()  # (B, T, J, 6)
    knee = SKEL.index("left_knee")
    turn = torch.tensor([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # 90 degrees about x
    rot[..., knee, :] = matrix_to_sixd(turn @ sixd_to_matrix(rot[..., knee, :]))
    bad = raw.clone()
    bad[..., LAYOUT.slices["joint_rot"]] = rot.flatten(-2)
    pred = STATS.normalize(bad)
    _, terms = _loss(pred, target, mask)
    # rotating the knee moves the ankle and toe: the shin (0.42 m) swings 90 degrees, ~0.6 m of error on
    # two of J joints' 3 channels; in decimetres with beta 1 that is of order 0.1-1 per channel on average
    assert terms["fk"].item() > 0.1
    assert terms["joint_rot"].item() > 0


def test_gradients_finite() -> None:
    target, mask = _batch()
    pred = target + 0.3 * torch.randn(target.shape, generator=torch.Generator().manual_seed(3))
    pred.requires_grad_(True)
    total, _ = _loss(pred, target, mask)
    total.backward()
    assert torch.isfinite(pred.grad).all() and pred.grad.abs().sum() > 0
    zero = torch.zeros_like(target, requires_grad=True)  # degenerate 6D after unnormalising: still finite
    _loss(zero, target, mask)[0].backward()
    assert torch.isfinite(zero.grad).all()


def test_shape_errors() -> None:
    target, mask = _batch()
    with pytest.raises(ValueError):
        _loss(target[..., :-1], target[..., :-1], mask)
    with pytest.raises(ValueError):
        _loss(target, target, mask[:, :-1])


# ---------------------------------------------------------------------------- constraint masks
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
