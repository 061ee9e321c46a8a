"""Per-rig evaluation of an any-rig model against each rig's own clips (train and held-out rigs).

For every rig of a split of a multi-rig build, up to ``clips`` of its clips give a caption and a
length; the model generates one motion per caption on that rig (in the build's normalised units:
rest pose 1 across, so numbers compare across rigs) and each is compared with the rig's own clips:

- ``skate``: mean horizontal speed (units/s x 100, i.e. cm/s for a 1-m creature) of the rig's
  contact joints (`ground_joints`) over consecutive frames where they are within ``GROUND`` of the
  floor, for generated and reference clips alike; ``skate_ratio`` = generated / reference;
- ``planted`` / ``planted_ref``: the share of those joints' frames within ``GROUND`` of the floor,
  generated and reference: a motion whose feet float has no skate to measure, and this says so;
- ``jerk``: mean third difference of joint positions (units/s^3), generated and reference;
- ``stretch``: largest relative change of any bone length (bones moved by translation under a floor
  armature excepted: they are IK handles, not body bones; the others are FK of rotations, so this
  checks the pipeline, post-processing included);
- ``constraint_cm`` / ``constraint_deg``: error (cm at 1-m scale / degrees) of one joint target per
  motion after post-processing: the first end effector's position and rotation at the middle frame,
  taken from a reference clip (character frame);
- ``keyframe_cm``: largest joint error at a full-body keyframe, against the pose as the rig can take it
  (one extra motion per rig, `keyframe_error`);
- ``coverage`` / ``novelty``: Dragon App. C AUCs (kinema.evaluate.distribution) of 10-frame windows
  of root-relative joint positions in the heading frame, against the rig's own clips;
- ``retrieval_hits`` / ``retrieval_n`` / ``retrieval_chance``: caption retrieval among the rig's
  evaluated clips (picked with distinct captions): a motion generated from clip i's caption is a hit
  when the clip nearest to it by `motion_descriptor` has that caption; chance = the share of clips
  with it (1 / clips when the captions differ). Only for rigs with two or more distinct captions;
- ``similarity`` / ``nearest`` (held-out splits, with ``train_shapes``): the rig's class against the
  training rigs (kinema.evaluate.anyrig.groups);
- locomotion (kinema.evaluate.anyrig.locomotion; with ``probe_seconds`` > 0): one motion of
  ``probe_seconds`` per action the rig's own clips show (idle, walk, run or gallop), generated from
  that action's caption (a walk asked to go forward); ``gap_ratio``: the largest foot-to-leg gap (tied
  joint to its anchor, kinema.rig.ties) of every generated motion over the largest of the rig's own
  clips; ``<action>_speed`` / ``<action>_speed_ref``: ground speed (body sizes/s) of the probe and of
  the rig's own clips of that action; ``walk_forward_share``, ``walk_net_turn_deg``,
  ``walk_total_turn_deg`` of the walk probe; ``idle_drift`` (body sizes) of the idle probe;
  ``run_walk_ratio`` / ``run_walk_ratio_ref``: run (or gallop) ground speed over walk ground speed,
  generated and own clips.
"""

from __future__ import annotations

import time
from pathlib import Path

import torch

from kinema.anyrig.pipeline import AnyRigModel, JointTarget, Keyframe, floor_root_children
from kinema.anyrig.targets import post_targets
from kinema.data.multirig import MultiRigData
from kinema.evaluate.anyrig.groups import RigShape, classify, rig_shape
from kinema.evaluate.anyrig.locomotion import (
    clip_speeds,
    foot_gap_ratio,
    ground_measures,
    probe_prompts,
    rig_ties,
)
from kinema.evaluate.distribution import coverage_novelty_auc
from kinema.evaluate.metrics import position_jerk
from kinema.geometry.rotations import sixd_to_quat
from kinema.motion.core import Motion
from kinema.postprocess.footlock import foot_skate
from kinema.representation.joint import POS, ROOT_FORWARD, ROOT_HEIGHT, ROOT_LATERAL, ROT, JointRepresentation
from kinema.rig import Rig

WINDOW = 10
#: a joint this close to the floor (rig units: rest pose 1 across) counts as planted
GROUND = 0.03


def ground_joints(rig: Rig, motions: list[Motion]) -> list[int]:
    """The rig's contact joints, else (the rig layer finds none on many Quaternius rigs, whose root is a
    static armature joint on the floor) the leaf joints that come within ``GROUND`` of the floor in its
    own clips."""
    if rig.contacts:
        return list(rig.contacts)
    low = torch.stack([m.positions[..., 1].double().amin(0) for m in motions]).amin(0)  # (J,)
    kids = rig.skeleton.children
    return [j for j in range(rig.num_joints) if not kids[j] and j != rig.root and float(low[j]) < GROUND]


def _skate(m: Motion, joints: list[int]) -> float | None:
    """Skate (units/s x 100) of ``joints`` over frames where both ends are within ``GROUND`` of the floor."""
    if not joints:
        return None
    planted = m.positions[:, joints, 1] < GROUND
    return foot_skate(m, planted, joints)


def _planted(m: Motion, joints: list[int]) -> float | None:
    """Share of the frames of ``joints`` within ``GROUND`` of the floor (None without joints)."""
    if not joints:
        return None
    return float((m.positions[:, joints, 1] < GROUND).double().mean())


def _stretch(m: Motion) -> float:
    """Largest relative change of a bone's length over the clip; bones moved by translation under a
    floor-level armature (IK feet, the body) are not bones of the body and are left out."""
    P = m.positions.double()
    moved = set(floor_root_children(m.skeleton))
    joints = [j for j in range(1, m.num_joints) if j not in moved]
    if not joints:
        return 0.0
    parents = torch.tensor([m.skeleton.parents[j] for j in joints])
    lengths = (P[:, joints] - P[:, parents]).norm(dim=-1)
    rest = lengths[0].clamp_min(1e-6)
    return float(((lengths - lengths[0]).abs() / rest).max())


def _local_positions(m: Motion, rep: JointRepresentation) -> torch.Tensor:
    f = rep.from_motion(m.to(torch.float64))
    keep = [j for j in range(m.num_joints) if j != rep.rig.root]
    return f[:, keep, POS].reshape(f.shape[0], -1)


def _target(rig: Rig, ref: Motion, rep: JointRepresentation, frames: int) -> JointTarget | None:
    effectors = [j for j in rig.end_effectors.values() if j != rig.root] or [rig.num_joints - 1]
    j = effectors[0]
    if j == rig.root:
        return None
    f = min(frames, ref.num_frames) // 2
    feats = rep.from_motion(ref.to(torch.float64))[f, j]
    pos, rot = feats[POS], sixd_to_quat(feats[ROT])
    return JointTarget(joint=j, frame=f, position=tuple(float(v) for v in pos), rotation=tuple(float(v) for v in rot))


def keyframe_error(model: AnyRigModel, rig: Rig, ref: Motion, caption: str, *, steps: int, seed: int) -> float:
    """Largest joint error (x 100: cm at 1-m scale) at a full-body keyframe after post-processing: the
    pose of ``ref``'s frame at a third of its length, asked for at that frame of a motion as long as
    ``ref`` (at least two windows). Compared with the pose as the rig can take it, placed at the motion's
    root and heading there (kinema.anyrig.targets.post_targets: bones at their rest lengths
    except those moved by translation, a floor-level armature left on the floor) -- the clips stretch
    bones by translation, which a rotation can never match (the platformer character's armature: 72 cm)."""
    seconds = max(ref.duration, 2 * WINDOW / model.fps)
    f = min(round(seconds * model.fps) // 3, ref.num_frames - 1)
    keyframe = Keyframe(frame=f, pose=ref, pose_frame=f)
    m = model.generate(caption, rig=rig, seconds=seconds, steps=steps, seed=seed, constraints=[keyframe])[0]
    m = m.to(torch.float64)
    rep = JointRepresentation(rig, model.fps)
    targets = post_targets([keyframe], m, rep, 1.0, floor_root_children(rig.skeleton))
    P = m.positions
    return max(float(100 * (P[fr, j] - pos).norm(dim=-1).max()) for j, (fr, pos) in targets.joint_positions.items())


def motion_descriptor(m: Motion, rep: JointRepresentation) -> torch.Tensor:
    """A clip as one vector for caption retrieval (rig units): per joint but the root, the mean and the
    standard deviation over frames of its root-relative position in the heading frame (6 numbers: the
    pose and how much it moves), then the root's mean ground speed and its height's mean and std."""
    f = rep.from_motion(m.to(torch.float64))
    root = rep.rig.root
    pos = f[:, [j for j in range(m.num_joints) if j != root], POS]
    r = f[:, root]
    ground, height = r[:, [ROOT_LATERAL, ROOT_FORWARD]], r[:, ROOT_HEIGHT]
    tail = torch.stack([ground.norm(dim=-1).mean(), height.mean(), height.std()])
    return torch.cat([pos.mean(0).flatten(), pos.std(0).flatten(), tail])


def caption_retrieval(gen: list[Motion], refs: list[Motion], captions: list[str], rep) -> dict:
    """Hits, tries and chance of caption retrieval (see the module docstring); empty when not defined."""
    if len(refs) < 2 or len(set(captions)) < 2:
        return {}
    ref_d = torch.stack([motion_descriptor(m, rep) for m in refs])
    hits = 0
    for g, cap in zip(gen, captions, strict=True):
        nearest = int((ref_d - motion_descriptor(g, rep)).norm(dim=-1).argmin())
        hits += captions[nearest] == cap
    chance = sum(captions.count(c) for c in captions) / len(captions) ** 2
    return {"retrieval_hits": hits, "retrieval_n": len(gen), "retrieval_chance": chance}


def _mean(xs: list[float | None]) -> float | None:
    xs = [x for x in xs if x is not None]
    return sum(xs) / len(xs) if xs else None


def locomotion(
    model: AnyRigModel, rig: Rig, gen: list[Motion], own: list[tuple[Motion, str, str]], *, seconds: float,
    steps: int, seed: int = 0
) -> dict:
    """The locomotion columns of one rig (see the module docstring): ``gen`` the motions generated so
    far, ``own`` the rig's own clips as (motion, content, first caption), all on one skeleton."""
    rep = JointRepresentation(rig, model.fps)
    clips = [m for m, _, _ in own]
    contents = [c for _, c, _ in own]
    prompts = probe_prompts(contents, [cap for _, _, cap in own]) if seconds > 0 else {}
    out: dict = {}
    probes = {}
    for k, (action, prompt) in enumerate(sorted(prompts.items())):
        probes[action] = model.generate(prompt, rig=rig, seconds=seconds, steps=steps, seed=seed + k)[0]
        measured = ground_measures(probes[action], rep)
        out[f"{action}_speed"] = measured["speed"]
        if action == "walk":
            out["walk_prompt"] = prompt
            for key in ("forward_share", "net_turn_deg", "total_turn_deg"):
                out[f"walk_{key}"] = measured[key]
        if action == "idle":
            out["idle_drift"] = measured["drift"]
    for action, speed in clip_speeds(clips, contents, rep).items():
        out[f"{action}_speed_ref"] = speed
    for suffix in ("", "_ref"):
        walk, run = out.get(f"walk_speed{suffix}"), out.get(f"run_speed{suffix}")
        out[f"run_walk_ratio{suffix}"] = run / walk if walk and run is not None else None
    ties = rig_ties(rep, clips)
    gaps = [foot_gap_ratio(m, ties) for m in [*gen, *probes.values()]]
    out["ties"] = len(ties.ties)
    out["gap_ratio"] = max((g for g in gaps if g is not None), default=None)
    return out


def evaluate_rig(
    model: AnyRigModel,
    rig_id: str,
    motions: list[Motion],
    captions: list[str],
    *,
    steps: int,
    seed: int = 0,
    own: list[tuple[Motion, str, str]] | None = None,
    probe_seconds: float = 4.0,
) -> dict:
    """Metrics of one rig (see the module docstring); ``motions`` are its clips, ``captions`` one per
    clip; ``own``: all its clips on that skeleton as (motion, content, first caption), for the
    locomotion columns (default: ``motions`` with no contents, so no probes)."""
    rig = Rig.from_skeleton(motions[0].skeleton)
    rep = JointRepresentation(rig, model.fps)
    gen, cons, degs, t0 = [], [], [], time.perf_counter()
    for i, (ref, caption) in enumerate(zip(motions, captions, strict=True)):
        seconds = max(ref.duration, 2 * WINDOW / model.fps)
        target = _target(rig, ref, rep, round(seconds * model.fps))
        res = model.generate(
            caption, rig=rig, seconds=seconds, steps=steps, seed=seed + i, constraints=[target] if target else []
        )
        gen.append(res[0])
        cons += res.report.residuals_cm
        degs += res.report.residuals_deg
    ref_windows = [_local_positions(m, rep) for m in motions if m.num_frames >= WINDOW]
    gen_windows = [_local_positions(m, rep) for m in gen]
    cn = coverage_novelty_auc(gen_windows, ref_windows, ref_windows, window=WINDOW) if ref_windows else None
    feet = ground_joints(rig, motions)
    skate_gen, skate_ref = _mean([_skate(m, feet) for m in gen]), _mean([_skate(m, feet) for m in motions])
    return {
        "rig": rig_id,
        "joints": rig.num_joints,
        "contacts": len(feet),
        "motions": len(gen),
        "skate": skate_gen,
        "skate_ref": skate_ref,
        "skate_ratio": None if not skate_ref or skate_gen is None else skate_gen / skate_ref,
        "planted": _mean([_planted(m, feet) for m in gen]),
        "planted_ref": _mean([_planted(m, feet) for m in motions]),
        "jerk": _mean([position_jerk(m.positions, m.fps) for m in gen]),
        "jerk_ref": _mean([position_jerk(m.positions, m.fps) for m in motions]),
        "stretch": max(_stretch(m) for m in gen),
        "constraint_cm": max(cons) if cons else None,
        "constraint_deg": max(degs) if degs else None,
        "keyframe_cm": keyframe_error(model, rig, motions[0], captions[0], steps=steps, seed=seed),
        "coverage": None if cn is None else cn.coverage_auc,
        "novelty": None if cn is None else cn.novelty_auc,
        **caption_retrieval(gen, motions, captions, rep),
        **locomotion(model, rig, gen, own if own is not None else [(m, "", c) for m, c in zip(motions, captions,
                     strict=True)], seconds=probe_seconds, steps=steps, seed=seed),
        "seconds": time.perf_counter() - t0,
    }


def evaluate_split(
    model: AnyRigModel,
    data: str | Path,
    split: str,
    *,
    clips: int = 3,
    steps: int = 20,
    rigs: list[str] | None = None,
    train_shapes: list[RigShape] | None = None,
    probe_seconds: float = 4.0,
    log=print,
) -> list[dict]:
    """`evaluate_rig` for every rig of ``split`` (or the named ``rigs``), up to ``clips`` clips each,
    with different captions where the rig has them; rigs of a held-out split are classified against
    ``train_shapes`` (kinema.evaluate.anyrig.groups.training_shapes of the model) when given."""
    d = MultiRigData(data, split=split)
    by_rig: dict[str, list[int]] = {}
    for i, rec in enumerate(d.clips):
        by_rig.setdefault(rec["rig"], []).append(i)
    rows = []
    for rid, idx in sorted(by_rig.items()):
        if rigs and rid not in rigs:
            continue
        pick = _pick(idx, [d.clips[i]["captions"][0] for i in idx], clips)
        motions = [d.motion(i).to(torch.float32) for i in pick]
        caps = [d.clips[i]["captions"][0] for i in pick]
        same = [i for i in idx if d.clips[i].get("skeleton") == d.clips[pick[0]].get("skeleton")]
        own = [(d.motion(i), d.clips[i].get("content", ""), d.clips[i]["captions"][0]) for i in same]  # as stored: ties
        # are found at 1e-4 rig sizes (kinema.rig.ties), which float32 rounding of a standing armature exceeds
        row = evaluate_rig(model, rid, motions, caps, steps=steps, own=own, probe_seconds=probe_seconds)
        row["split"] = split
        if train_shapes is not None and split != "train":
            row["similarity"], row["nearest"] = classify(rig_shape(rid, motions[0].skeleton), train_shapes)
        rows.append(row)
        log(format_row(row))
    return rows


def _pick(idx: list[int], captions: list[str], n: int) -> list[int]:
    """Up to ``n`` of the clips ``idx``, spread over the list, first with captions not taken yet."""
    order = idx[:: max(1, len(idx) // n)] + idx
    taken, pick = set(), []
    for i in order:
        cap = captions[idx.index(i)]
        if i not in pick and cap not in taken and len(pick) < n:
            pick.append(i)
            taken.add(cap)
    for i in order:  # fewer distinct captions than n: fill with the spread clips
        if i not in pick and len(pick) < n:
            pick.append(i)
    return pick


def _f(x, digits: int = 2) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def format_row(r: dict) -> str:
    similarity = "training rig" if r["split"] == "train" else r.get("similarity", "-")
    if r.get("nearest"):
        similarity += f" ({r['nearest']})"
    retrieval = f"{r['retrieval_hits']}/{r['retrieval_n']}" if r.get("retrieval_n") else "-"
    return (
        f"| {r['rig']} | {r['split']} | {similarity} | {r['joints']} | {r['contacts']} | {_f(r['skate'])} "
        f"| {_f(r['skate_ref'])} | {_f(r['skate_ratio'])} | {_f(r.get('planted'))} | {_f(r.get('planted_ref'))} "
        f"| {_f(r['jerk'], 0)} | {_f(r['jerk_ref'], 0)} "
        f"| {r['stretch']:.1e} | {_f(r['constraint_cm'])} | {_f(r.get('constraint_deg'))} | {_f(r.get('keyframe_cm'))} "
        f"| {_f(r['coverage'])} | {_f(r['novelty'])} | {retrieval} |"
    )


def format_locomotion_row(r: dict) -> str:
    """One row of the locomotion table (`LOCOMOTION_HEADER`)."""
    speeds = " | ".join(f"{_f(r.get(f'{a}_speed'))} ({_f(r.get(f'{a}_speed_ref'))})" for a in ("idle", "walk", "run"))
    return (
        f"| {r['rig']} | {r['split']} | {r['contacts']} | {_f(r.get('gap_ratio'))} | {_f(r.get('walk_forward_share'))} "
        f"| {_f(r.get('walk_net_turn_deg'), 0)} | {_f(r.get('walk_total_turn_deg'), 0)} | {_f(r.get('idle_drift'))} "
        f"| {speeds} | {_f(r.get('run_walk_ratio'))} ({_f(r.get('run_walk_ratio_ref'))}) "
        f"| {_f(r['skate_ratio'])} | {_f(r['jerk'] / r['jerk_ref'] if r.get('jerk_ref') else None)} |"
    )


LOCOMOTION_HEADER = (
    "| rig | split | contacts | foot-to-leg gap (x own max) | walk forward share | walk net turn deg "
    "| walk summed turn deg | idle drift (body sizes) | idle speed (own clips) | walk speed (own clips) "
    "| run/gallop speed (own clips) | run / walk (own clips) | skate ratio | jerk ratio |\n|" + "---|" * 14
)


TABLE_HEADER = (
    "| rig | split | similarity (nearest training rig) | joints | contacts | skate | skate (own clips) | ratio "
    "| planted | planted (own clips) | jerk | jerk (own clips) | stretch | constraint cm | constraint deg "
    "| keyframe cm | coverage AUC | novelty AUC | retrieval |\n|" + "---|" * 19
)
