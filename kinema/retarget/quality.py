"""How well a retargeted motion follows its source: the numbers docs/retarget.md tabulates per rig.

- ``direction_deg``: mean and largest angle (degrees) between each mapped bone's world direction on
  the target (joint -> mapped child) and the same bone on the source, over every frame (not the
  humanoid feet: they keep the character's own rest pitch);
- ``skate_cm_s``: foot skate of source and target (kinema.postprocess.footlock.foot_skate: mean
  horizontal speed of the contact joints over consecutive planted frames, the source's planted flags
  for both), the target's divided by the body scale so both are in source centimetres per second;
- ``lowest``: the target's lowest body joint over the clip and where its rest pose puts it, or 0 for a
  rest pose off the floor (kinema.retarget.proportions.rest_floor; a toe-off may dip below it, as the
  source's ball of the foot dips below its standing height);
- ``ankle_cm`` / ``ankle_source_cm``: feet on the floor, the median over the frames a source foot is
  planted of the target's ankle (heel planted) or ball of the foot (only the toe) above its rest
  height, divided by the body scale, and of the source's above its standing height, source
  centimetres (kinema.retarget.proportions.planted_joints);
- ``twist_deg`` / ``twist_bone``: the largest turn of a target bone about itself against its rest,
  relative to its parent (median over frames, degrees), and that bone: what a skin shows (a wrung
  torso or wrist) and joint positions cannot;
- ``bone_drift_mm``: the largest change of any bone length of the target against its rest offsets
  (joints placed in the world, such as the hips or IK feet, left out), in the target's units x 1000.
"""

from __future__ import annotations

import torch

from kinema.geometry.rotations import quat_inverse, quat_mul
from kinema.motion.core import Motion
from kinema.postprocess.footlock import foot_skate
from kinema.retarget.align import rest_frames, rest_locals, short_length
from kinema.retarget.core import source_planted
from kinema.retarget.mapping import JointMap
from kinema.retarget.proportions import (
    body_scale,
    planted_joints,
    rest_floor,
    rest_on_floor,
    source_standing_ankle,
    target_body,
    target_standing_height,
)


def _bones(jm: JointMap) -> list[tuple[int, int, int, int]]:
    """(target joint, target child, source joint, source child) of every mapped bone, less the humanoid
    feet (ankle -> toes), which keep the character's own rest pitch (kinema.retarget.proportions)."""
    feet = {g.foot for g in jm.legs}
    return [(p, c, jm.pairs[p], jm.pairs[c]) for c, p in jm.chain_parent.items() if p in jm.pairs and p not in feet]


def direction_errors(source: Motion, target: Motion, jm: JointMap) -> torch.Tensor:
    """(T, B) angles in degrees between target and source bone directions (module docstring); bones
    of no length at rest on either rig (CMU's ``Spine1 -> Neck``) have no direction and count 0."""
    Ps, Pt = source.positions.double(), target.positions.double()
    bones = _bones(jm)
    _, P0s = rest_frames(jm.source)
    _, P0t = rest_frames(jm.target)
    tiny_t, tiny_s = short_length(P0t), short_length(P0s)
    real = torch.tensor(
        [float((P0t[c] - P0t[p]).norm()) > tiny_t and float((P0s[d] - P0s[a]).norm()) > tiny_s for p, c, a, d in bones]
    )
    vt = torch.stack([Pt[:, c] - Pt[:, p] for p, c, _, _ in bones], dim=1)
    vs = torch.stack([Ps[:, c] - Ps[:, p] for _, _, p, c in bones], dim=1)
    cos = torch.nn.functional.cosine_similarity(vt, vs, dim=-1).clamp(-1, 1)
    return torch.where(real, torch.rad2deg(torch.arccos(cos)), torch.zeros_like(cos))


def _placed(jm: JointMap, target: Motion) -> set[int]:
    if target.local_translations is None:
        return set()
    off = target.skeleton.offsets.to(target.local_translations)
    moved = (target.local_translations - off).abs().amax(dim=(0, 2)) > 1e-6
    return {j for j in range(target.num_joints) if bool(moved[j])}


def bone_drift(target: Motion, jm: JointMap) -> float:
    """Largest bone length change (target units) of joints hung from their parent."""
    P = target.positions.double()
    skel = target.skeleton
    placed = _placed(jm, target)
    worst = 0.0
    for j, p in enumerate(skel.parents):
        if p < 0 or j in placed:
            continue
        length = (P[:, j] - P[:, p]).norm(dim=-1)
        worst = max(worst, float((length - skel.offsets[j].norm()).abs().max()))
    return worst


def bone_twists(motion: Motion) -> dict[str, float]:
    """{bone: median |turn| in degrees about itself against its rest, relative to its parent} of every
    joint with a parent and a child (its axis: towards its first child)."""
    sk = motion.skeleton
    L, L0, T = motion.local_rotations.double(), rest_locals(sk), motion.num_frames
    out = {}
    for j, p in enumerate(sk.parents):
        kids = [c for c, q in enumerate(sk.parents) if q == j and float(sk.offsets[c].norm()) > 1e-9]
        if p < 0 or not kids:
            continue
        rel = quat_mul(quat_inverse(L0[j]).expand(T, 4), L[:, j])
        axis = sk.offsets[kids[0]].double() / sk.offsets[kids[0]].double().norm()
        turn = torch.rad2deg(2 * torch.atan2(rel[:, 1:] @ axis, rel[:, 0]))
        out[sk.names[j]] = float(((turn + 180) % 360 - 180).abs().median())
    return out


def planted_ankles(source: Motion, target: Motion, jm: JointMap, planted: dict, s: float) -> dict:
    """``ankle_cm`` and ``ankle_source_cm`` of the module docstring ({} without planted feet): ankles
    while the heel is planted, balls of the feet while only the toe is (proportions.planted_joints)."""
    Ps, Pt = source.positions.double(), target.positions.double()
    on_floor = rest_on_floor(jm)
    mine, theirs = [], []
    for leg, joint, source_joint, on in planted_joints(jm, planted):
        stand = source_standing_ankle(jm, leg, Ps, on, source_joint)
        mine.append((Pt[on, joint, 1] - target_standing_height(jm, joint, stand, s, on_floor)) / s)
        theirs.append(Ps[on, source_joint, 1] - stand)
    if not mine:
        return {}
    return {
        "ankle_cm": 100 * float(torch.cat(mine).median()),
        "ankle_source_cm": 100 * float(torch.cat(theirs).median()),
    }


def retarget_report(source: Motion, target: Motion, jm: JointMap) -> dict:
    """The numbers of the module docstring as a JSON-friendly dict."""
    s = body_scale(jm)
    err = direction_errors(source, target, jm)
    out = {
        "scale": s,
        "direction_deg_mean": float(err.mean()),
        "direction_deg_max": float(err.max()),
        "bone_drift_mm": 1000.0 * bone_drift(target, jm),
    }
    twists = bone_twists(target)
    if twists:
        out["twist_bone"] = max(twists, key=twists.get)
        out["twist_deg"] = twists[out["twist_bone"]]
    body = target_body(jm)
    out["lowest"] = float(target.positions[:, body, 1].min())
    out["lowest_rest"] = rest_floor(jm)
    planted = source_planted(source)
    out.update(planted_ankles(source, target, jm, planted, s))
    feet = [(g.foot, g.source_foot) for g in jm.legs if g.source_foot in planted]
    if feet:
        flags = torch.stack([planted[a] for _, a in feet], dim=1)
        out["skate_source_cm_s"] = foot_skate(source, flags, [a for _, a in feet])
        out["skate_target_cm_s"] = foot_skate(target, flags, [t for t, _ in feet]) / s
    return out
