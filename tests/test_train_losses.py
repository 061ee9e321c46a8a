"""Tests for kinema.train.losses: the Eq. 1 loss and the foot-contact term. The phase-2 constraint masks
(kinema.train.constraints) are tests/test_train_constraints.py."""

from __future__ import annotations

import pytest
import torch

from kinema.geometry.rotations import axis_angle_to_quat, matrix_to_sixd, sixd_to_matrix
from kinema.motion.contacts import contact_joints
from kinema.motion.core import Motion
from kinema.representation.kimodo_features import features_to_motion, motion_to_features
from kinema.representation.layout import FeatureLayout
from kinema.representation.stats import NormStats
from kinema.skeleton import Skeleton
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


# ---------------------------------------------------------------------------- foot-contact term
def _with_contacts(x: torch.Tensor, value: float) -> torch.Tensor:
    """Normalised batch ``x`` with every raw contact flag set to ``value``."""
    raw = STATS.denormalize(x)
    raw[..., LAYOUT.slices["contacts"]] = value
    return STATS.normalize(raw)


def _planted_speed_loss(pred: torch.Tensor, mask: torch.Tensor, fps: float, unit: float) -> float:
    """The term by hand: contact-joint velocities of features_to_motion(pred), smooth L1 in ``unit``."""
    total, count = 0.0, 0
    for b in range(pred.shape[0]):
        n = int(mask[b].sum())
        motion = features_to_motion(STATS.denormalize(pred[b, :n]), SKEL, fps)
        _, pos = motion.global_transforms()
        v = (pos[1:, contact_joints(SKEL)] - pos[:-1, contact_joints(SKEL)]) * fps / unit
        total += torch.nn.functional.smooth_l1_loss(v, torch.zeros_like(v), reduction="sum").item()
        count += v.shape[0] * v.shape[1]
    return total / count


def test_foot_contact_term_is_planted_foot_speed_of_the_output_motion() -> None:
    target, mask = _batch()
    target = _with_contacts(target, 1.0)
    pred = target + 0.05 * torch.randn(target.shape, generator=torch.Generator().manual_seed(3))
    pred = _with_contacts(pred, 0.0)  # the term reads the *ground-truth* flags, not the predicted ones
    base, _ = _loss(pred, target, mask, fps=30.0)
    w = LossWeights(foot_contact=2.0)
    total, terms = _loss(pred, target, mask, weights=w, fps=30.0)
    expected = _planted_speed_loss(pred, mask, 30.0, w.foot_unit)
    assert expected > 1.0  # the fixture's root travels ~2 m in 1.3 s: its feet slide
    assert terms["foot_contact"].item() == pytest.approx(expected, rel=1e-4)
    assert total.item() == pytest.approx(base.item() + 2.0 * expected, rel=1e-5)


def test_foot_contact_term_only_on_planted_frames_and_needs_fps() -> None:
    target, mask = _batch()
    _, terms = _loss(target, _with_contacts(target, 0.0), mask, weights=LossWeights(foot_contact=1.0), fps=30.0)
    assert terms["foot_contact"].item() == 0.0
    _, off = _loss(target, target, mask)
    assert "foot_contact" not in off
    with pytest.raises(ValueError, match="fps"):
        _loss(target, target, mask, weights=LossWeights(foot_contact=1.0))


def test_foot_contact_gradient_slows_the_planted_feet() -> None:
    target, mask = _batch()
    target = _with_contacts(target, 1.0)
    pred = target.clone().requires_grad_(True)
    w = LossWeights(foot_contact=1.0)
    _, terms = _loss(pred, target, mask, weights=w, fps=30.0)
    before = terms["foot_contact"].item()
    total, _ = _loss(pred, target, mask, weights=w, fps=30.0)
    total.backward()
    assert torch.isfinite(pred.grad).all()
    stepped = (pred - 0.01 * pred.grad).detach()
    _, after = _loss(stepped, target, mask, weights=w, fps=30.0)
    assert after["foot_contact"].item() < before
