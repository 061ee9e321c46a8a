"""The any-rig model's root stage (issue 34): trained on the build, packed with the model, sampled first."""

from __future__ import annotations

import creature_fixtures
import pytest
import torch
from rig_fixtures import hexapod, quadruped, walking

from kinema.anyrig.pipeline import AnyRigModel
from kinema.anyrig.sampling import root_context, sample_features, sample_root, uses_root_stage
from kinema.anyrig.windows import single_plan
from kinema.constraints.character import JointTarget, Keyframe
from kinema.errors import KinemaError
from kinema.model.anyrig.config import get_anyrig_config
from kinema.model.anyrig.loading import load_anyrig
from kinema.model.export import export_model
from kinema.model.skeleton_codes import batch_codes, skeleton_codes
from kinema.pipeline.request import GenerationRequest
from kinema.representation.joint import (
    CONTACT,
    ROOT_HEADING_RATE,
    ROOT_HEIGHT,
    ROOT_PLACEMENT,
    JointRepresentation,
)
from kinema.rig import Rig
from kinema.text import get_text_encoder
from kinema.train.anyrig.data import GROUND_VELOCITY
from kinema.train.anyrig.root_stage import RootStageTrainConfig, RootStageTrainer, root_loss, root_masks

creature_cache, trained = creature_fixtures.creature_cache, creature_fixtures.trained  # module-scoped fixtures


@pytest.fixture(scope="module")
def packed(creature_cache, trained, tmp_path_factory):
    run = tmp_path_factory.mktemp("root-run")
    cfg = RootStageTrainConfig(model=str(trained), steps=4, ckpt_every=2, log_every=2, variants=1, warmup=2,
                               width=32, layers=1, heads=2, batch_size=8)
    trainer = RootStageTrainer(cfg, creature_cache, run, text_cache=None, log=lambda s: None)
    trainer.run()
    out = export_model(trained, tmp_path_factory.mktemp("packed") / "model", dtype="float32", root_stage=run)
    return run, out


def _model(folder) -> AnyRigModel:
    return AnyRigModel(load_anyrig(folder), get_text_encoder("hash-test-32"))


def test_the_packed_model_samples_the_root_first_and_the_body_keeps_it(packed, trained) -> None:
    run, folder = packed
    model = _model(folder)
    stage = model.loaded.root_stage
    assert stage is not None and model.loaded.info["root_stage"]["step"] == 4
    assert (folder / "root_stage.safetensors").is_file()
    rig = Rig.from_skeleton(quadruped())
    rep, _ = model._normalised(rig)
    codes = batch_codes([skeleton_codes(rep.rig, model.loaded.config)], max_hops=8)
    plan = single_plan(30, model.loaded.config.window)  # two windows of 16
    text = model._texts(["A quadruped walks."])
    guide = model.loaded.guidance
    feats = sample_features(model.loaded.denoiser, codes, GenerationRequest(steps=3, samples=2, seed=5), plan=plan,
                            text_emb=text, targets=None, sampler=model.loaded.sampler, guidance=guide,
                            root_stage=stage)
    rows = sample_root(stage, codes, 2, plan=plan, text_emb=text, targets=None, sampler=model.loaded.sampler,
                       steps=3, guidance=guide, generator=torch.Generator().manual_seed(5))
    given = ROOT_PLACEMENT + [ROOT_HEADING_RATE]
    # the body stage ends on the root stage's rows, sample by sample (the two samples differ)
    assert torch.allclose(feats[:, :, rig.root, given], rows[..., given], atol=1e-4)
    assert not torch.allclose(rows[0], rows[1])
    res = model.generate("A quadruped walks.", rig=rig, seconds=1.5, steps=3, seed=1)
    assert res.report.root_stage and torch.isfinite(res[0].positions).all()
    # a hand target on a frame whose root is free keeps the one-stage sampler (the root must move to reach it)
    target = JointTarget(joint="HeadA", frame=5, position=(0.0, 0.35, 0.5))
    res = model.generate("", rig=rig, seconds=0.6, steps=3, constraints=[target])
    assert not res.report.root_stage
    # a model folder without a stage samples in one stage
    assert not _model(trained).generate("A quadruped walks.", rig=rig, seconds=0.6, steps=2).report.root_stage


def test_which_targets_leave_the_root_to_the_stage() -> None:
    rig = Rig.from_skeleton(quadruped())
    rep = JointRepresentation(rig, 20.0)
    codes = batch_codes([skeleton_codes(rig, get_anyrig_config("anyrig-tiny", text_dim=32))], max_hops=8)
    head = JointTarget(joint="HeadA", frame=5, position=(0.0, 0.35, 0.5))
    pose = walking(rig.skeleton, frames=3)
    assert uses_root_stage(None, codes)
    assert not uses_root_stage(rep.encode([head], 1.0, 12), codes)
    assert uses_root_stage(rep.encode([Keyframe(frame=9, pose=pose)], 1.0, 12), codes)  # its root is pinned too


def test_root_context_and_training_masks() -> None:
    rig = Rig.from_skeleton(hexapod())
    codes = batch_codes([skeleton_codes(rig, get_anyrig_config("anyrig-tiny", text_dim=32))], max_hops=8)
    rows = torch.randn(3, 10, 13)
    ctx = root_context(rows, codes)
    J = codes.joint_mask.shape[1]
    assert ctx.x_tgt.shape == (3, 10, J, 13)
    assert torch.equal(ctx.x_tgt[:, :, rig.root], rows) and int(ctx.mask[:, :, rig.root].sum(-1).max()) == 12
    assert not ctx.mask[:, :, [j for j in range(J) if j != rig.root]].any()
    frame_mask = torch.zeros(40, 16, dtype=torch.bool)
    frame_mask[:, :12] = True
    channels = torch.zeros(40, 13, dtype=torch.bool)
    channels[:, :12] = True
    m = root_masks(frame_mask, channels, torch.Generator().manual_seed(0), 0.9)
    assert not m[:, 12:].any() and not m[..., 12].any()  # never on padding frames or a masked channel
    assert 20 <= int((m.flatten(1).sum(1) > 0).sum()) < 40  # most windows get a mask, not all


def test_the_path_loss_charges_a_steady_velocity_error_more_than_a_jittering_one() -> None:
    B, T = 2, 40
    x0 = torch.randn(B, T, 13)
    real = torch.ones(B, T, 13)
    real[1, 30:] = 0.0  # padding frames
    real[..., CONTACT] = 0.0  # a channel that holds no feature (the root has no contact)
    sign = torch.ones(T)
    sign[1::2] = -1.0
    steady, jitter, other = x0.clone(), x0.clone(), x0.clone()
    steady[..., list(GROUND_VELOCITY)] += 0.1  # the idles' creep: the same error on every frame
    jitter[..., list(GROUND_VELOCITY)] += 0.1 * sign[:, None]  # as large a frame, adding up to nothing
    other[..., ROOT_HEIGHT] += 0.1  # not a velocity channel (the path term ignores it)
    pad = x0.clone()
    pad[1, 30:] += 5.0  # errors on padding and on the empty channel cost nothing
    pad[..., CONTACT] += 5.0
    plain = [float(root_loss(p, x0, real)) for p in (steady, jitter)]
    assert plain[0] == pytest.approx(plain[1])
    path = [float(root_loss(p, x0, real, path_weight=1.0)) for p in (steady, jitter, other)]
    assert path[0] > 8 * path[1] and path[1] > plain[1]
    assert path[2] == pytest.approx(float(root_loss(other, x0, real)))
    assert float(root_loss(pad, x0, real, velocity_weight=4.0, path_weight=1.0)) == 0.0
    assert float(root_loss(steady, x0, real, velocity_weight=4.0)) == pytest.approx(4 * plain[0])


def test_export_refuses_a_foreign_root_stage(packed, trained, tmp_path) -> None:
    run, folder = packed
    with pytest.raises(KinemaError, match="not a root-stage run"):
        export_model(trained, tmp_path / "m", root_stage=trained)
    # re-exporting the model without the stage drops the stage's weights with its entry
    export_model(trained, folder, dtype="float32")
    assert not (folder / "root_stage.safetensors").exists() and load_anyrig(folder).root_stage is None


def test_the_cli_trains_a_root_stage_and_export_packs_it(creature_cache, trained, tmp_path, capsys) -> None:
    from kinema.cli import main

    out = tmp_path / "root"
    args = ["train-anyrig-root", "--model", str(trained), "--data", str(creature_cache), "--out", str(out),
            "--steps", "2", "--width", "32", "--layers", "1", "--batch-size", "4", "--variants", "0",
            "--threads", "1", "--cache-dir", str(tmp_path / "text")]
    assert main(args) == 0 and (out / "latest").read_text().strip() == "ckpt-00000002"
    assert main(args) == 2  # the run folder is taken: one line, no traceback
    err = capsys.readouterr().err
    assert "already holds a run; pass --resume" in err and "Traceback" not in err
    assert main(["export", str(trained), "--out", str(tmp_path / "m"), "--root-stage", str(out)]) == 0
    assert "with a root stage" in capsys.readouterr().out
    assert load_anyrig(tmp_path / "m").root_stage is not None


def test_a_packed_model_is_repacked_with_another_root_stage(packed, trained, tmp_path) -> None:
    run, _ = packed
    first = export_model(trained, tmp_path / "first", dtype="float32")
    again = export_model(first, tmp_path / "again", dtype="float32", root_stage=run)
    info = load_anyrig(again).info
    assert info["export"]["source"] == load_anyrig(first).info["export"]["source"] != str(first)
    assert info["export"]["repacked_from"] == str(first) and load_anyrig(again).root_stage is not None
    a, b = load_anyrig(first).denoiser.state_dict(), load_anyrig(again).denoiser.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)  # the body's weights are the same
    export_model(again, again, dtype="float32")  # re-packed in place without the stage: dropped
    assert load_anyrig(again).root_stage is None and not (again / "root_stage.safetensors").exists()


def test_content_shares_fix_the_share_of_a_batch_drawn_from_a_content(creature_cache, trained, tmp_path) -> None:
    """``{"sway": 0.5}``: at least half of every batch are sway windows (the rest are drawn from all clips
    alike, sways too); with no shares the batch is the uniform draw it always was; a content the build
    lacks, or shares over 1, are one-line errors."""
    base = RootStageTrainConfig(model=str(trained), variants=0, width=32, layers=1, heads=2, batch_size=16)

    def sways(cfg: RootStageTrainConfig, name: str) -> list[int]:
        tr = RootStageTrainer(cfg, creature_cache, tmp_path / name, text_cache=None, log=lambda s: None)
        gen = torch.Generator().manual_seed(0)
        return [sum("sway" in c for c in tr.sample_batch(gen).captions) for _ in range(20)]

    uniform = sways(base, "u")
    shared = sways(RootStageTrainConfig(**{**base.__dict__, "content_shares": {"sway": 0.5}}), "s")
    assert min(shared) >= 8 and sum(shared) > sum(uniform) + 20 * 2  # about 12 a batch against 8
    assert 0 < sum(uniform) < 20 * 16  # both contents are drawn without shares
    only = sways(RootStageTrainConfig(**{**base.__dict__, "content_shares": {"sway": 1.0}}), "o")
    assert only == [16] * 20
    with pytest.raises(KinemaError, match=r"no clips of content idle \(the build has: sway, walk\)"):
        RootStageTrainer(RootStageTrainConfig(**{**base.__dict__, "content_shares": {"idle": 0.25}}),
                         creature_cache, tmp_path / "x", text_cache=None, log=lambda s: None)
    with pytest.raises(KinemaError, match="add up to at most 1"):
        RootStageTrainConfig(content_shares={"sway": 0.6, "walk": 0.6})
    saved = RootStageTrainConfig.from_dict({**base.__dict__, "content_shares": {"sway": 0.5}})
    assert saved.content_shares == {"sway": 0.5}


def test_the_cli_takes_content_shares_and_refuses_a_bad_one(creature_cache, trained, tmp_path, capsys) -> None:
    import json

    from kinema.cli import main

    out = tmp_path / "root"
    args = ["train-anyrig-root", "--model", str(trained), "--data", str(creature_cache), "--out", str(out),
            "--steps", "1", "--width", "32", "--layers", "1", "--batch-size", "4", "--variants", "0",
            "--threads", "1", "--cache-dir", str(tmp_path / "text")]
    assert main([*args, "--content-share", "sway=0.5"]) == 0
    assert "4 windows a batch (50% sway)" in capsys.readouterr().out
    ckpt = out / (out / "latest").read_text().strip()
    saved = json.loads(next(p for p in ckpt.glob("*.json") if "train_config" in p.read_text()).read_text())
    assert saved["train_config"]["content_shares"] == {"sway": 0.5}
    for bad in ("sway", "sway=2", "=0.5"):
        with pytest.raises(SystemExit):
            main([*args[:6], str(tmp_path / "bad"), *args[7:], "--content-share", bad])
        err = capsys.readouterr().err
        assert "expected CONTENT=SHARE" in err and "Traceback" not in err
    assert main([*args[:6], str(tmp_path / "none"), *args[7:], "--content-share", "idle=0.25"]) == 2
    err = capsys.readouterr().err.strip()
    assert "no clips of content idle" in err and len(err.splitlines()) == 1
