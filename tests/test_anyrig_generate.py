"""Any-rig training, checkpoint round trip and generation on rigs the model never saw (synthetic data)."""

from __future__ import annotations

import creature_fixtures
import pytest
import torch
from rig_fixtures import hexapod, quadruped, snake2, walking

from kinema.anyrig.feet import floor_root_children, lock_translated_feet, translated_feet, with_floor_translations
from kinema.anyrig.pipeline import AnyRigModel, JointTarget, Keyframe
from kinema.anyrig.post import pin_root, root_pins, unmet_warnings
from kinema.anyrig.sampling import FeatureTargets, sample_features, window_starts, window_weights
from kinema.anyrig.targets import post_targets
from kinema.anyrig.windows import single_plan
from kinema.errors import KinemaError
from kinema.geometry.rotations import quat_rotate
from kinema.model.anyrig.config import get_anyrig_config
from kinema.model.anyrig.loading import is_anyrig_checkpoint, load_anyrig
from kinema.model.skeleton_codes import batch_codes, skeleton_codes
from kinema.motion.core import Motion
from kinema.pipeline.request import GenerationRequest
from kinema.postprocess.targets import PostTargets
from kinema.representation.joint import JointRepresentation, yaw_quat
from kinema.rig import Rig
from kinema.skeleton import Skeleton
from kinema.text import get_text_encoder
from kinema.train.anyrig.trainer import AnyRigTrainConfig, AnyRigTrainer

creature_cache, trained = creature_fixtures.creature_cache, creature_fixtures.trained  # module-scoped fixtures


def test_training_writes_resumable_checkpoints(trained, creature_cache) -> None:
    assert (trained / "latest").read_text().strip() == "ckpt-00000004"
    assert is_anyrig_checkpoint(trained) and (trained / "log.jsonl").exists()
    cfg = get_anyrig_config("anyrig-tiny", text_dim=32)
    tc = AnyRigTrainConfig(steps=6, ckpt_every=2, log_every=2, variants=1, text_encoder="hash-test-32", warmup=2)
    again = AnyRigTrainer(cfg, tc, creature_cache, trained, text_cache=None, log=lambda s: None)
    assert again.resume() and again.step == 4
    loaded = load_anyrig(trained, ema=False)
    for k, v in loaded.denoiser.state_dict().items():
        assert torch.equal(v, again.model.state_dict()[k]), k
    other = AnyRigTrainer(
        get_anyrig_config("anyrig-tiny", text_dim=32, layers=2),
        tc,
        creature_cache,
        trained,
        text_cache=None,
        log=lambda s: None,
    )
    with pytest.raises(KinemaError, match="model config differs"):
        other.resume()


def test_fine_tune_starts_from_a_trained_models_weights(trained, creature_cache, tmp_path) -> None:
    """``--init-from``: the weights (not the normalisation) come from the trained model; another
    architecture is refused in one line."""
    cfg = get_anyrig_config("anyrig-tiny", text_dim=32)
    tc = AnyRigTrainConfig(steps=2, ckpt_every=2, log_every=2, variants=0, text_encoder="hash-test-32", warmup=1)
    tuned = AnyRigTrainer(cfg, tc, creature_cache, tmp_path / "ft", text_cache=None, log=lambda s: None)
    before = {k: v.clone() for k, v in tuned.model.state_dict().items()}
    tuned.init_weights(trained)
    src = load_anyrig(trained).denoiser.state_dict()
    for k, v in tuned.model.state_dict().items():
        if k in ("feat_mean", "feat_std"):
            assert torch.equal(v, before[k]), k  # this run's data's statistics
        else:
            assert torch.equal(v, src[k]) and torch.equal(tuned.ema.state_dict()[k], src[k]), k
    assert tuned.cfg.init_from == str(trained)
    other = AnyRigTrainer(
        get_anyrig_config("anyrig-tiny", text_dim=32, layers=2),
        tc,
        creature_cache,
        tmp_path / "o",
        text_cache=None,
        log=lambda s: None,
    )
    with pytest.raises(KinemaError, match="model config differs"):
        other.init_weights(trained)


def test_checkpoint_round_trip_gives_the_same_outputs(trained) -> None:
    a, b = load_anyrig(trained), load_anyrig(trained)
    rig = Rig.from_skeleton(quadruped())
    codes = batch_codes([skeleton_codes(rig, a.config)], max_hops=a.config.max_hops)
    x = torch.randn(1, 8, rig.num_joints, 13)
    t, text = torch.tensor([10]), torch.randn(1, 32)
    assert torch.equal(a.denoiser(x, t, text, codes), b.denoiser(x, t, text, codes))
    assert a.train_rigs and all("skeleton" in d for d in a.train_rigs.values())


def _model(trained) -> AnyRigModel:
    return AnyRigModel(load_anyrig(trained), get_text_encoder("hash-test-32"))


def test_generate_on_an_unseen_rig(trained) -> None:
    model = _model(trained)
    unseen = snake2()  # two joints, not a training topology
    res = model.generate("A snake slithers.", rig=unseen, seconds=0.6, steps=3, samples=2)
    assert len(res) == 2 and res.report.windows == 1
    for m in res:
        assert m.skeleton.names == unseen.names and m.num_frames == 12 and torch.isfinite(m.positions).all()
    long = model.generate("", rig=Rig.from_skeleton(hexapod()), seconds=2.5, steps=2)  # 50 frames > window 16
    assert long[0].num_frames == 50 and long.report.windows == len(window_starts(50, 16)) > 1
    with pytest.raises(KinemaError, match="not a training rig id"):
        model.generate("x", rig="no-such-rig", seconds=1.0)


def test_known_rigs_come_from_the_checkpoint(trained) -> None:
    model = _model(trained)
    ids = [r[0] for r in model.known_rigs()]
    assert ids and model.resolve_rig(ids[0]).num_joints == model.known_rigs()[0][1]


def test_constraint_imputation_meets_targets(trained) -> None:
    model = _model(trained)
    rig = Rig.from_skeleton(quadruped())
    rep = JointRepresentation(rig, 20.0)
    head = rig.skeleton.index("HeadA")
    target = JointTarget(joint="HeadA", frame=5, position=(0.0, 0.35, 0.5))
    feats = rep.encode([target], 1.0, 12)
    assert feats.mask[5, head, 0:3].eq(1).all() and int(feats.mask.sum()) == 3
    codes = batch_codes([skeleton_codes(rig, model.loaded.config)], max_hops=8)
    out = sample_features(
        model.loaded.denoiser,
        codes,
        GenerationRequest(steps=3, samples=1, seed=0),
        plan=single_plan(12, model.loaded.config.window),
        text_emb=None,
        targets=feats,
        sampler=model.loaded.sampler,
        guidance=model.loaded.guidance,
    )
    assert torch.allclose(out[0, 5, head, 0:3], torch.tensor([0.0, 0.35, 0.5]), atol=1e-5)
    # through the whole API: the residual is the head's distance from its target in the character frame
    # of the finished motion (its own root and heading at frame 5), and the head is close to it
    pose = walking(rig.skeleton, frames=3)
    res = model.generate("", rig=rig, seconds=0.6, steps=3, constraints=[target, Keyframe(frame=9, pose=pose)])
    m = res[0].to(torch.float64)
    G, P = m.global_transforms()
    local = quat_rotate(yaw_quat(-rep.heading(G)[5]), P[5, head] - P[5, rig.root])
    miss_cm = 100 * float((local - torch.tensor([0.0, 0.35, 0.5], dtype=torch.float64)).norm())
    assert res.report.residuals_cm[0] == pytest.approx(miss_cm, abs=1e-6)
    raw = model.generate("", rig=rig, seconds=0.6, steps=3, constraints=[target, Keyframe(frame=9, pose=pose)],
                         postprocess=False)
    assert miss_cm < 0.5 * raw.report.residuals_cm[0]  # the raw report measures the raw motion the same way


def test_window_weights_cover_every_frame() -> None:
    starts = window_starts(90, 40)
    assert starts[0] == 0 and starts[-1] == 50 and all(b - a <= 30 for a, b in zip(starts, starts[1:], strict=False))
    w = window_weights(starts, 40, 90)
    cover = torch.zeros(90)
    for k, s in enumerate(starts):
        cover[s : s + 40] += w[k]
    assert cover.min() > 0 and w[0, 0] == 1 and w[-1, -1] == 1
    assert isinstance(FeatureTargets(torch.zeros(1), torch.zeros(1)).any(), bool)


def _armature_motion(frames: int = 20) -> Motion:
    """A game-style rig: a static armature joint on the floor, a body and two IK feet moved by translation."""
    skel = Skeleton(
        ["Armature", "Body", "Head", "Foot1", "Foot2"],
        [-1, 0, 1, 0, 0],
        [[0, 0, 0], [0, 0.5, 0], [0, 0, 0.3], [0.1, 0, 0.2], [-0.1, 0, -0.2]],
        name="armature",
    )
    t = torch.arange(frames, dtype=torch.float64) / 20
    lt = skel.offsets[None].repeat(frames, 1, 1)
    lt[:, 1, 1] += 0.05 * torch.sin(2 * torch.pi * t)  # the body bobs
    lt[:, 3, 2] += 0.01 * t  # foot 1 creeps forward on the floor (skates)
    lt[:, 4, 1] += 0.2 + 0.05 * torch.sin(2 * torch.pi * t)  # foot 2 is in the air
    rots = torch.zeros(frames, 5, 4, dtype=torch.float64)
    rots[..., 0] = 1.0
    return Motion(skel, 20.0, torch.zeros(frames, 3, dtype=torch.float64), rots, None, lt)


def test_bones_under_a_floor_armature_take_predicted_translations_and_feet_lock() -> None:
    m = _armature_motion()
    rig = Rig.from_skeleton(m.skeleton)
    assert floor_root_children(m.skeleton) == [1, 3, 4]
    rep = JointRepresentation(rig, 20.0)
    f = rep.from_motion(m)
    posed = rep.to_motion(f)
    assert (posed.positions - m.positions).abs().max() > 0.01  # rotations alone lose the translations
    back = with_floor_translations(posed, f, rep)
    assert torch.allclose(back.positions, m.positions, atol=1e-9)  # the armature stays on the floor too
    feet = translated_feet(rig, rig.root)
    assert [f.joint for f in feet] == [3, 4]  # both stand on the floor at rest
    locked, rep = lock_translated_feet(back, feet, size=1.0)
    assert rep["translated_feet_segments"] == 1  # foot 1 only: foot 2 never comes down to the floor
    P = locked.positions
    assert float((P[1:, 3, [0, 2]] - P[:-1, 3, [0, 2]]).norm(dim=-1).max()) < 1e-9
    assert torch.allclose(P[:, [1, 2]], back.positions[:, [1, 2]])
    assert float((P[:, 4] - back.positions[:, 4]).norm(dim=-1).max()) < 0.005  # de-jittered only


def test_keyframes_keep_the_bone_translations_of_their_pose() -> None:
    m = _armature_motion()
    rep = JointRepresentation(Rig.from_skeleton(m.skeleton), 20.0)
    targets = rep.encode([Keyframe(frame=2, pose=m, pose_frame=7)], 1.0, 5)
    want = rep.from_motion(m)[7]
    body = [j for j in range(m.num_joints) if j != rep.rig.root]
    assert targets.mask[2, body, 0:9].eq(1).all()
    assert torch.allclose(targets.x_tgt[2, body, 0:9], want[body, 0:9].float(), atol=1e-6)  # the moved feet too


def test_keyframe_targets_keep_only_the_translations_generation_can_make() -> None:
    m = _armature_motion()
    lt = m.local_translations.clone()
    lt[:, 2, 2] += 0.1  # the clip also stretches the neck, which the rig cannot do by rotations
    m = Motion(m.skeleton, m.fps, m.root_translation, m.local_rotations, None, lt)
    rep = JointRepresentation(Rig.from_skeleton(m.skeleton), 20.0)
    t = post_targets([Keyframe(frame=5, pose=m, pose_frame=5)], m, rep, 1.0, translated=[1, 3, 4])
    P = m.positions
    assert torch.allclose(t.joint_positions[3][1][0], P[5, 3])  # the IK foot keeps its translation
    head = t.joint_positions[2][1][0] - t.joint_positions[1][1][0]
    assert torch.allclose(head, torch.tensor([0.0, 0.0, 0.3], dtype=head.dtype))  # the neck at its rest length
    assert float((P[5, 2] - P[5, 1]).norm()) > 0.39


def test_pin_root_puts_keyframed_roots_back_and_leaves_far_frames() -> None:
    m = _armature_motion(frames=40)
    root = 1
    P = m.positions
    targets = PostTargets(joint_positions={root: (torch.tensor([15, 20]), P[[15, 20], root] + 0.1)})
    pins = root_pins(targets, root, [], m, m)
    pinned = pin_root(m, pins, root, reach_s=0.25)  # 5 frames at 20 fps
    Q = pinned.positions
    assert torch.allclose(Q[[15, 20], root], P[[15, 20], root] + 0.1)  # exactly on the keyframes
    assert torch.allclose(Q[:10], P[:10]) and torch.allclose(Q[26:], P[26:])  # untouched beyond the fade
    assert torch.allclose(Q[12, 0] - P[12, 0], torch.full((3,), 0.04, dtype=P.dtype))  # fading in linearly
    assert pin_root(m, {}, root) is m and root_pins(None, root, [], m, m) == {}
    moved = pin_root(m, {30: P[30, root] + 0.2}, root)
    waypoint = root_pins(None, root, [30], m, moved)[30]  # ground position from before, height from after
    assert torch.allclose(waypoint, torch.stack([P[30, root, 0], P[30, root, 1] + 0.2, P[30, root, 2]]))
    assert unmet_warnings([(0.5, "Head", 3)], 20.0, []) == []
    text = unmet_warnings([(0.5, "Head", 3), (2.0, "Tail", 40)], 20.0, [])
    assert text == ["constraint not met after post-processing: Tail at frame 40 (2.00 s) 2.0 cm away"]
    assert unmet_warnings([(2.0, "Tail", 40)], 20.0, text) == []  # said once


def test_cli_lists_rigs_and_writes_a_motion(trained, tmp_path, capsys) -> None:
    from kinema.cli import main

    assert main(["generate", "--model", str(trained)]) == 0
    listing = capsys.readouterr().out
    rig_id = listing.splitlines()[1].split()[0]
    assert "joints" in listing.splitlines()[0]
    assert main(["generate", "A thing moves.", "--model", str(trained)]) == 2
    assert "needs --rig" in capsys.readouterr().err
    out = tmp_path / "m.bvh"
    args = ["generate", "A thing moves.", "--model", str(trained), "--rig", rig_id, "--seconds", "0.5", "--steps", "2"]
    assert main([*args, "--out", str(out)]) == 0 and out.exists()
    assert main([*args, "--out", str(tmp_path / "m.txt")]) == 2
    assert main(["generate", "x", "--rig", rig_id, "--out", str(tmp_path / "h.bvh")]) == 2  # the human model
    assert "drives its own skeleton" in capsys.readouterr().err


def test_per_rig_evaluation_rows(trained, creature_cache) -> None:
    from kinema.bench.anyrig import pick_rigs
    from kinema.evaluate.anyrig.suite import evaluate_split

    model = _model(trained)
    rows = evaluate_split(model, creature_cache, "train", clips=1, steps=2, probe_seconds=1.0, log=lambda s: None)
    assert rows and {r["split"] for r in rows} == {"train"}
    for r in rows:
        assert r["motions"] == 1 and r["stretch"] < 1e-6  # FK of rotations: bones never stretch
        assert r["jerk"] > 0 and r["jerk_ref"] >= 0 and 0 <= r["coverage"] <= 1 and 0 <= r["novelty"] <= 1
        assert r["constraint_cm"] is not None and r["constraint_cm"] < 10.0  # untrained: post-processing does it
        assert r["constraint_deg"] is not None and r["constraint_deg"] < 1.0  # the effector's rotation too
        assert r["keyframe_cm"] is not None and r["keyframe_cm"] < 1.0  # a full-body keyframe
    picks = pick_rigs([("a", 3, []), ("b", 40, []), ("c", 10, []), ("d", 2, [])])
    assert picks == [("a", 3), ("c", 10), ("b", 40)]
