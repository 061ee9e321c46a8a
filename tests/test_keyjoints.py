"""Keyjoint targets, the representation's poser and the sampler's smooth joint displacement."""

from __future__ import annotations

import pytest
import torch

from kinema.human.keyjoints import KeyjointTargets, displace_joints, gaussian_spread
from kinema.representation.flat import FlatRepresentation
from kinema.representation.kimodo_features import features_to_motion
from kinema.representation.layout import FeatureLayout
from kinema.skeleton import Skeleton


def _skeleton() -> Skeleton:
    """pelvis -> spine -> hand chain plus a leg, 1-unit-ish bones; Y up."""
    names = ["Hips", "Spine", "Hand_L", "UpperLeg_L"]
    offsets = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.3, 0.0], [0.4, 0.0, 0.0], [0.1, -0.4, 0.0]])
    return Skeleton(names, [-1, 0, 1, 0], offsets)


def _rep(J: int = 4) -> FlatRepresentation:
    assert J == 4
    return FlatRepresentation.for_skeleton(_skeleton(), 20.0)


def _random_features(layout: FeatureLayout, T: int, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.randn(1, T, layout.dim, generator=g, dtype=torch.float64)


def test_poser_places_joints_like_features_to_motion() -> None:
    sk = _skeleton()
    layout = FeatureLayout(sk.num_joints)
    f = _random_features(layout, 7)
    P = _rep().pose(f.float())
    expected = features_to_motion(f[0], sk, 20.0).positions
    assert torch.allclose(P[0].double(), expected, atol=1e-4)


def test_keyjoint_targets_resolve_relative_and_world_xz() -> None:
    J, T = 4, 10
    layout = FeatureLayout(J)
    x, m = torch.zeros(1, T, layout.dim), torch.zeros(1, T, layout.dim)
    rx, rz = layout.root_xz
    jp = layout.slices["joint_pos"].start
    # frame 2: root known at (1, 2), hand (joint 2) relative (0.5, 1.0, -0.5)
    x[0, 2, [rx, rz]] = torch.tensor([1.0, 2.0])
    m[0, 2, [rx, rz]] = 1
    x[0, 2, jp + 6: jp + 9] = torch.tensor([0.5, 1.0, -0.5])
    m[0, 2, jp + 6: jp + 9] = 1
    # frame 5: only the hand height is a feature; its x/z wait in the world store
    x[0, 5, jp + 7] = 1.2
    m[0, 5, jp + 7] = 1
    wxz, wm = torch.zeros(1, T, J, 2), torch.zeros(1, T, J)
    wxz[0, 5, 2] = torch.tensor([3.0, 4.0])
    wm[0, 5, 2] = 1
    keys = KeyjointTargets(_rep(J), x, m, wxz, wm)
    assert torch.allclose(keys.pos[0, 2, 2], torch.tensor([1.5, 1.0, 1.5]))
    assert torch.allclose(keys.pos[0, 5, 2], torch.tensor([3.0, 1.2, 4.0]))
    assert keys.mask[0, 2, 2].tolist() == [1, 1, 1] and keys.mask[0, 5, 2].tolist() == [1, 1, 1]
    assert keys.mask.sum() == 6


def test_relative_xz_without_a_known_root_is_not_a_target() -> None:
    J, T = 4, 5
    layout = FeatureLayout(J)
    x, m = torch.zeros(1, T, layout.dim), torch.zeros(1, T, layout.dim)
    jp = layout.slices["joint_pos"].start
    m[0, 1, jp + 6: jp + 9] = 1  # x/y/z features but no root x/z target at that frame
    keys = KeyjointTargets(_rep(J), x, m)
    assert keys.mask[0, 1, 2].tolist() == [0, 1, 0]


def test_gaussian_spread_keeps_a_lone_keyframe_and_fades_around_it() -> None:
    T = 41
    r = torch.zeros(1, T, 1, 3)
    r[0, 20, 0] = torch.tensor([0.1, 0.0, -0.2])
    present = torch.zeros(1, T, 1, dtype=torch.bool)
    present[0, 20, 0] = True
    s = gaussian_spread(r, present, sigma_frames=4.0)
    assert torch.allclose(s[0, 20, 0], r[0, 20, 0])
    assert torch.allclose(s[0, 24, 0], r[0, 20, 0] * torch.exp(torch.tensor(-0.5)), atol=1e-6)
    assert s[0, :5].abs().max() < 1e-3 and s[0, -5:].abs().max() < 1e-3
    # two keyframes close together: each frame is a weighted average, never an overshoot
    r[0, 22, 0] = torch.tensor([0.1, 0.0, -0.2])
    present[0, 22, 0] = True
    s2 = gaussian_spread(r, present, sigma_frames=4.0)
    assert s2[0, 18:25, 0, 0].max() <= 0.1 + 1e-6


def test_displace_joints_moves_the_keyjoint_but_not_full_body_frames() -> None:
    sk = _skeleton()
    J, T = sk.num_joints, 30
    layout = FeatureLayout(J)
    rep = _rep(J)
    f = _random_features(layout, T, seed=3).float() * 0.1
    P = rep.pose(f)
    pos, mask = torch.zeros(1, T, J, 3), torch.zeros(1, T, J, 3)
    pos[0, 10, 2] = P[0, 10, 2] + torch.tensor([0.2, 0.1, 0.0])  # hand 20 cm right, 10 cm up
    mask[0, 10, 2] = 1
    pos[0, 25] = P[0, 25] + 0.3  # a full-body keyframe, missed by 30 cm on every joint
    mask[0, 25] = 1
    keys = KeyjointTargets.__new__(KeyjointTargets)
    keys.pos, keys.mask = pos, mask
    out = displace_joints(f, keys, rep, sigma_frames=3.0)
    jp = layout.split(out)["joint_pos"] - layout.split(f)["joint_pos"]
    assert torch.allclose(jp[0, 10, 2], torch.tensor([0.2, 0.1, 0.0]), atol=1e-5)
    assert jp[0, 10, [0, 1, 3]].abs().max() < 1e-6  # other joints keep their channels
    assert 0.0 < jp[0, 13, 2, 0] < 0.2  # neighbours bend part of the way
    assert jp[0, 25].abs().max() < 1e-3  # full-body frame untouched
    other = torch.ones(layout.dim, dtype=torch.bool)
    other[layout.slices["joint_pos"]] = False
    assert torch.equal(out[..., other], f[..., other])


@pytest.mark.parametrize("sigma", [0.0, 0.6])
def test_end_effector_displacement_switch(tiny_checkpoint, sigma) -> None:
    """joint_sigma = 0 turns the displacement off; text-only requests are never touched."""
    from kinema.generate import load_model

    model = load_model(tiny_checkpoint)
    cons = [{"type": "left-hand", "times": [1.0], "positions": [[0.3, 1.2, 0.5]]}]
    model.joint_sigma = sigma
    a = model.generate("a person waves", seconds=2.0, constraints=cons, seed=0, steps=4, postprocess=False)[0]
    t = model.generate("a person waves", seconds=2.0, seed=0, steps=4, postprocess=False)[0]
    model.joint_sigma = 0.6 if sigma == 0.0 else 0.0
    b = model.generate("a person waves", seconds=2.0, constraints=cons, seed=0, steps=4, postprocess=False)[0]
    t2 = model.generate("a person waves", seconds=2.0, seed=0, steps=4, postprocess=False)[0]
    assert not torch.allclose(a.positions, b.positions)
    assert torch.equal(t.positions, t2.positions)
