"""Keyjoint trajectories: representation, masks, the denoiser's files, keyjoint-planned sampling, training."""

from __future__ import annotations

import json
import math

import pytest
import torch

from kinema.errors import KinemaError
from kinema.model.keyjoint import KeyjointConfig, KeyjointDenoiser, load_keyjoint_model, save_keyjoint_model
from kinema.motion.core import Motion
from kinema.representation.flat import FlatRepresentation
from kinema.representation.keyjoint import (
    HEADING,
    KEYJOINT_DIM,
    canonicalize_keyjoints,
    keyjoint_indices,
    keyjoints_from_features,
    sparse_mask,
    subsample_every,
)
from kinema.skeleton import Skeleton


def _skeleton() -> Skeleton:
    names = [
        "Hips",
        "Spine",
        "Head",
        "Hand_L",
        "Hand_R",
        "UpperLeg_L",
        "Foot_L",
        "Toes_L",
        "UpperLeg_R",
        "Foot_R",
        "Toes_R",
    ]
    parents = [-1, 0, 1, 1, 1, 0, 5, 6, 0, 8, 9]
    offsets = torch.tensor(
        [
            [0, 0, 0],
            [0, 0.3, 0],
            [0, 0.4, 0],
            [0.4, 0.2, 0],
            [-0.4, 0.2, 0],
            [0.1, -0.1, 0],
            [0, -0.8, 0],
            [0, -0.05, 0.15],
            [-0.1, -0.1, 0],
            [0, -0.8, 0],
            [0, -0.05, 0.15],
        ],
        dtype=torch.float32,
    )
    return Skeleton(names, parents, offsets)


def _motion(T: int = 30) -> Motion:
    g = torch.Generator().manual_seed(0)
    sk = _skeleton()
    q = torch.zeros(T, sk.num_joints, 4)
    q[..., 0] = 1.0
    q[..., 1:] = 0.2 * torch.randn(T, sk.num_joints, 3, generator=g).cumsum(0) / T
    q = q / q.norm(dim=-1, keepdim=True)
    root = torch.stack([0.3 * torch.arange(T) / 20, torch.full((T,), 0.9), torch.arange(T) / 20], -1)
    return Motion(sk, 20.0, root, q)


def test_keyjoints_are_the_joints_world_positions_and_heading() -> None:
    m = _motion()
    rep = FlatRepresentation.for_skeleton(m.skeleton, 20.0)
    idx = keyjoint_indices(m.skeleton)
    assert [m.skeleton.names[i] for i in idx] == ["Hips", "Head", "Hand_L", "Hand_R", "Foot_L", "Foot_R"]
    k = keyjoints_from_features(rep.from_motion(m).float(), rep, idx)
    assert k.shape == (30, KEYJOINT_DIM)
    assert torch.allclose(k[:, :18].reshape(30, 6, 3), m.positions[:, idx].float(), atol=1e-4)
    assert torch.allclose(k[:, HEADING].norm(dim=-1), torch.ones(30), atol=1e-4)


def test_canonicalize_puts_the_root_at_the_origin_facing_the_angle() -> None:
    m = _motion()
    rep = FlatRepresentation.for_skeleton(m.skeleton, 20.0)
    f = rep.from_motion(m).float()
    k = keyjoints_from_features(f, rep, keyjoint_indices(m.skeleton))
    c = canonicalize_keyjoints(k, f[0, rep.root_xz], torch.tensor(0.7))
    hc, hs = c[0, HEADING]
    assert math.atan2(float(hs), float(hc)) == pytest.approx(0.7, abs=1e-5)
    d0 = (k[:, :18].reshape(30, 6, 3)[:, None] - k[:, :18].reshape(30, 6, 3)[:, :, None]).norm(dim=-1)
    d1 = (c[:, :18].reshape(30, 6, 3)[:, None] - c[:, :18].reshape(30, 6, 3)[:, :, None]).norm(dim=-1)
    assert torch.allclose(d0, d1, atol=1e-5)  # a rigid motion


def test_sparse_masks_follow_the_schemes() -> None:
    g = torch.Generator().manual_seed(1)
    masks = [sparse_mask(60, g) for _ in range(400)]
    assert all(m.shape == (60, KEYJOINT_DIM) and float(m[:, HEADING].abs().sum()) == 0 for m in masks)
    joints = [set(torch.nonzero(m[:, :18].reshape(60, 6, 3)[..., 0].sum(0)).flatten().tolist()) for m in masks]
    assert {0} in joints and {2, 3} in joints and set(range(6)) in joints and set() in joints
    assert subsample_every(100, 20.0, 1.5) == [0, 30, 60, 90]


def test_model_files_round_trip_and_reject_unknown_keys(tmp_path) -> None:
    model = KeyjointDenoiser(KeyjointConfig(width=32, layers=1, heads=2, text_dim=8))
    model.set_normalization(torch.randn(KEYJOINT_DIM), torch.rand(KEYJOINT_DIM) + 0.5)
    save_keyjoint_model(model, tmp_path, {"steps": 3})
    back, info = load_keyjoint_model(tmp_path)
    assert info == {"steps": 3}
    for (k, a), (_, b) in zip(model.state_dict().items(), back.state_dict().items(), strict=True):
        assert torch.equal(a, b), k
    meta = json.loads((tmp_path / "keyjoint.json").read_text())
    meta["config"]["depth"] = 3
    (tmp_path / "keyjoint.json").write_text(json.dumps(meta))
    with pytest.raises(KinemaError, match="unknown keyjoint config keys: \\['depth'\\]"):
        load_keyjoint_model(tmp_path)


def test_training_runs_resumes_and_exports(tiny_data, tmp_path) -> None:
    from kinema.train.keyjoint import annealed_lr, ema_decay, main

    assert ema_decay(0) == pytest.approx(0.1) and ema_decay(10**6) == 0.999
    assert annealed_lr(3e-4, 3e-5, 0.0) == pytest.approx(3e-4) and annealed_lr(3e-4, 3e-5, 1.0) == pytest.approx(3e-5)
    assert annealed_lr(3e-4, 3e-5, 0.5) == pytest.approx(1.65e-4) and annealed_lr(3e-4, 3e-5, 2.0) == pytest.approx(
        3e-5
    )
    out = tmp_path / "kj"
    args = [
        "--data",
        str(tiny_data),
        "--out",
        str(out),
        "--minutes",
        "0.05",
        "--batch",
        "4",
        "--threads",
        "1",
        "--log-every",
        "1",
        "--save-every",
        "1000",
        "--text-encoder",
        "hash-test-32",
        "--text-cache",
        str(tmp_path),
    ]
    main(args)
    first = json.loads((out / "state.json").read_text())["step"]
    assert first >= 1
    main([*args, "--lr-end", "1e-5"])
    assert json.loads((out / "state.json").read_text())["step"] > first
    model, info = load_keyjoint_model(out / "export")
    assert (
        info["lr_end"] == 1e-5
        and info["steps"] > first
        and "CC BY-NC" in info["licence"]
        and model.config.text_dim == 32
    )
