"""The any-rig denoiser: shapes, skeleton codes, padding masks, config round trip, augmentation."""

from __future__ import annotations

import pytest
import torch
from rig_fixtures import fish, hexapod, quadruped, snake2, walking

from kinema.errors import KinemaError
from kinema.model.anyrig.config import AnyRigConfig, get_anyrig_config
from kinema.model.anyrig.denoiser import AnyRigDenoiser
from kinema.model.skeleton_codes import batch_codes, skeleton_codes
from kinema.rig import Rig
from kinema.train.anyrig import augment as aug


def _model(**over) -> AnyRigDenoiser:
    torch.manual_seed(0)
    model = AnyRigDenoiser(get_anyrig_config("anyrig-tiny", **over)).eval()
    with torch.no_grad():  # adaLN-Zero starts as the identity: give every weight a value so outputs vary
        for p in model.parameters():
            p.copy_(0.2 * torch.randn_like(p))
    return model


def _inputs(model, rigs, T, gen):
    codes = batch_codes([skeleton_codes(r, model.config) for r in rigs], max_hops=model.config.max_hops)
    B, J = codes.joint_mask.shape
    x = torch.randn(B, T, J, 13, generator=gen)
    return codes, x, torch.randint(0, 1000, (B,), generator=gen), torch.randn(B, 384, generator=gen)


def test_shapes_and_parameter_count() -> None:
    model = _model()
    gen = torch.Generator().manual_seed(1)
    codes, x, t, text = _inputs(model, [Rig.from_skeleton(quadruped()), Rig.from_skeleton(fish())], 12, gen)
    y = model(x, t, text, codes)
    assert y.shape == x.shape and torch.isfinite(y).all()
    small = AnyRigDenoiser(get_anyrig_config("anyrig-small"))
    assert 100_000 < small.num_parameters() < 2_000_000  # ships well under 25 MB as float32


def test_padding_joints_and_frames_do_not_change_real_outputs() -> None:
    """A fish alone equals the same fish padded to a quadruped's joints and extra frames holding garbage;
    fails if the spatial key mask or the temporal frame mask is dropped."""
    model = _model()
    gen = torch.Generator().manual_seed(2)
    f, q = Rig.from_skeleton(fish()), Rig.from_skeleton(quadruped())
    codes1, x1, t1, text1 = _inputs(model, [f], 10, gen)
    alone = model(x1, t1, text1, codes1)
    codes2, x2, _, _ = _inputs(model, [f, q], 14, gen)
    x2[0, :10, : f.num_joints] = x1[0]  # the rest of row 0 is garbage: padding joints and frames
    frame_mask = torch.ones(2, 14, dtype=torch.bool)
    frame_mask[0, 10:] = False
    batched = model(x2, torch.cat([t1, t1]), torch.cat([text1, text1]), codes2, frame_mask)
    assert torch.allclose(batched[0, :10, : f.num_joints], alone[0], rtol=1e-4, atol=1e-4)
    # and the garbage does matter where it is not masked: the same input without the frame mask differs
    unmasked = model(x2, torch.cat([t1, t1]), torch.cat([text1, text1]), codes2)
    assert not torch.allclose(unmasked[0, :10, : f.num_joints], alone[0], atol=1e-3)


def test_text_step_and_constraints_change_the_output() -> None:
    model = _model()
    gen = torch.Generator().manual_seed(3)
    codes, x, t, text = _inputs(model, [Rig.from_skeleton(hexapod())], 8, gen)
    y = model(x, t, text, codes)
    assert not torch.allclose(y, model(x, t, torch.zeros_like(text), codes))
    assert not torch.allclose(y, model(x, (t + 500) % 1000, text, codes))
    mask = torch.zeros_like(x)
    mask[:, 3] = 1.0
    assert not torch.allclose(y, model(x, t, text, codes, None, torch.zeros_like(x), mask))


def test_skeleton_codes_tell_joints_apart() -> None:
    cfg = get_anyrig_config("anyrig-tiny")
    rig = Rig.from_skeleton(quadruped())
    c = skeleton_codes(rig, cfg)
    J = rig.num_joints
    assert c.tree.shape == (J, cfg.tree_depth * cfg.tree_branch + 1) and c.flags[rig.root, 0] == 1
    assert len({tuple(row.tolist()) for row in c.tree}) == J  # every joint has its own path
    assert torch.equal(c.hops, rig.skeleton.tree_distances().clamp_max(cfg.max_hops))
    assert c.flags[list(rig.contacts), 1].eq(1).all() and int(c.flags[:, 1].sum()) == rig.num_contacts
    b = batch_codes([c, skeleton_codes(Rig.from_skeleton(snake2()), cfg)], max_hops=cfg.max_hops)
    assert b.joint_mask.sum(1).tolist() == [J, 2] and b.hops[1, 2:].eq(cfg.max_hops).all()


def test_config_round_trip_and_errors(tmp_path) -> None:
    cfg = get_anyrig_config("anyrig-small", tree_pe=False)
    path = tmp_path / "config.json"
    cfg.save_json(path)
    assert AnyRigConfig.load_json(path) == cfg
    with pytest.raises(KinemaError, match="unknown any-rig config keys"):
        AnyRigConfig.from_dict({**cfg.to_dict(), "depth": 3})
    with pytest.raises(KinemaError, match="not divisible"):
        get_anyrig_config("anyrig-tiny", heads=3)
    with pytest.raises(KinemaError, match="unknown any-rig preset"):
        get_anyrig_config("anyrig-huge")
    assert AnyRigDenoiser(cfg).tree_mlp is None


def test_rig_augmentation_keeps_the_motion() -> None:
    m = walking(quadruped(), frames=6)
    P = m.positions
    gen = torch.Generator().manual_seed(4)
    ins = aug.insert_joint(m, gen)
    keep = [ins.skeleton.names.index(n) for n in m.skeleton.names]
    assert ins.num_joints == m.num_joints + 1 and torch.allclose(ins.positions[:, keep], P, atol=1e-9)
    reset = aug.reset_rest(m, gen, fraction=1.0)
    assert torch.allclose(reset.positions, P, atol=1e-6)
    assert not torch.allclose(reset.global_rotations, m.global_rotations.double(), atol=1e-3)
    rm = aug.remove_leaf(m, gen)
    assert rm.num_joints == m.num_joints - 1
    scaled = aug.scale_bones(m, gen)
    ratio = scaled.skeleton.offsets[1:].norm(dim=-1) / m.skeleton.offsets[1:].norm(dim=-1)
    assert ratio.min() >= 0.8 - 1e-9 and ratio.max() <= 1.2 + 1e-9 and float(ratio.std()) > 0.01
    assert abs(float(scaled.positions[..., 1].min() - P[..., 1].min())) < 1e-9  # the lowest point stays
