"""Proportions: the body scale between two rigs, where placed joints go, and the floor.

- Body scale ``s``: the target's hips height above its lowest rest joint over the source's (leg
  length; for non-humanoid maps the whole rest height), so root motion, heights and foot goals are
  scaled by leg length and the character walks as far, relative to its size, as the source. Units
  follow: a centimetre BVH character gets ``s`` near 100 for a metre source.
- A placed joint (the hips; for same-name maps every joint whose bone translation the source
  animates; humanoid feet are placed by the leg IK, kinema.retarget.legs) goes to
  ``P0_t + s (P_s - P0_s)``: its rest position plus the source's displacement from rest, scaled.
- Root motion: a static joint above the hips (an armature or ``Root`` bone at the origin) moves
  across the floor with the hips, at its rest height, so IK/pole helpers hanging from it come along.
- Floor: the whole motion is then shifted vertically so that its planted feet stand at their rest
  heights (else its lowest joint over the clip sits where the target's rest pose puts its lowest joint;
  helper bones left out, kinema.rig.find.helpers). That holds when the rest pose stands on the world
  floor (:func:`rest_on_floor`); a rest pose that does not (the hips at the origin and the feet 0.92 m
  below, as CMU-derived and some FBX rigs have, or Bandai's lying along +X) says nothing about the
  floor, and the world's y = 0 is the floor instead: planted feet at the source's scaled heights.

Shapes: positions ``(T, J, 3)``, float64.
"""

from __future__ import annotations

import torch

from kinema.errors import KinemaError
from kinema.geometry.rotations import quat_inverse, quat_mul, quat_rotate
from kinema.retarget.align import rest_frames
from kinema.retarget.mapping import JointMap, Leg
from kinema.rig.find import helpers
from kinema.skeleton import Skeleton

#: a rest pose stands on the world floor when its lowest joint is this fraction of its height from y = 0
REST_FLOOR_TOLERANCE = 0.1


def body_joints(skeleton: Skeleton, top: int | None = None, extra: tuple[int, ...] = ()) -> list[int]:
    """Joints that are part of the body: ``top`` (the hips) and the joints below it, plus ``extra``
    (feet that hang off the legs and the helpers that follow them), less IK/pole/control helpers by
    name; every non-helper joint when ``top`` is None. Static joints beside the body (an armature,
    ``Root``, UE's ``ik_foot_root`` at the origin) are left out."""
    skip = helpers(skeleton)
    joints = range(skeleton.num_joints)
    if top is not None:
        joints = [j for j in joints if top in skeleton.path_from_root(j) or j in extra]
    return [j for j in joints if j not in skip] or list(range(skeleton.num_joints))


def target_body(jm: JointMap) -> list[int]:
    """:func:`body_joints` of the target: below its hips, with its feet and their followers."""
    extra = tuple(g.foot for g in jm.legs) + tuple(f for fs in jm.followers.values() for f in fs)
    return body_joints(jm.target, jm.hips[0] if jm.hips else None, extra)


def source_body(jm: JointMap) -> list[int]:
    """:func:`body_joints` of the source: below its hips, with its feet and toes."""
    extra = tuple(j for g in jm.legs for j in (g.source_foot, g.source_toes) if j is not None)
    return body_joints(jm.source, jm.hips[1] if jm.hips else None, extra)


def lowest_rest_height(skeleton: Skeleton, body: list[int]) -> float:
    """Height (y) of the lowest of the ``body`` joints in the rest pose."""
    _, P0 = rest_frames(skeleton)
    return float(P0[body, 1].min())


def _chain_length(skeleton: Skeleton, joints: list[int]) -> float:
    _, P0 = rest_frames(skeleton)
    return float(sum((P0[b] - P0[a]).norm() for a, b in zip(joints, joints[1:], strict=False)))


def body_scale(jm: JointMap) -> float:
    """Target size over source size: the mean leg length (upper leg -> lower leg -> foot, summed) for
    humanoids, the summed length of the mapped bones otherwise. Both ignore the rest pose's posture,
    so a source whose rest pose lies along +X scales like one that stands."""
    if jm.legs:
        t = sum(_chain_length(jm.target, [g.upper, g.lower, g.foot]) for g in jm.legs)
        s = sum(_chain_length(jm.source, [g.source_upper, g.source_lower, g.source_foot]) for g in jm.legs)
    else:
        t = sum(_chain_length(jm.target, [c, b]) for b, c in jm.chain_parent.items())
        s = sum(_chain_length(jm.source, [jm.pairs[c], jm.pairs[b]]) for b, c in jm.chain_parent.items())
    if not (t > 0 and s > 0):
        raise KinemaError(
            f"cannot scale between {jm.source.name or 'the source'} and {jm.target.name or 'the target'}: "
            "the mapped bones have no length"
        )
    return t / s


def placed_positions(
    jm: JointMap, source_positions: torch.Tensor, moving: list[int], s: float
) -> dict[int, torch.Tensor]:
    """{target joint: (T, 3) world position} for the hips (or top joint) and, for maps by name, the
    targets of the ``moving`` source joints (humanoid feet are placed by the leg IK instead): rest
    position plus the scaled displacement of the source from its rest."""
    _, P0s = rest_frames(jm.source)
    _, P0t = rest_frames(jm.target)
    chosen = {} if jm.kind == "humanoid" else {b: a for b, a in jm.pairs.items() if a in moving}
    if jm.hips is not None:
        chosen[jm.hips[0]] = jm.hips[1]
    return {b: P0t[b] + s * (source_positions[:, a] - P0s[a]) for b, a in chosen.items()}


def ground_root(jm: JointMap, placed: dict[int, torch.Tensor]) -> dict[int, torch.Tensor]:
    """{0: (T, 3)} for a static top joint above the hips (an armature, Quaternius ``Root``, UE
    ``root``): it carries the root motion on the floor, keeping its rest offset to the hips across the
    ground and its rest height, so helpers hanging from it travel with the character. {} otherwise."""
    if jm.hips is None or jm.hips[0] == 0 or 0 in jm.pairs or 0 in placed or jm.hips[0] not in placed:
        return {}
    _, P0 = rest_frames(jm.target)
    root = P0[0].expand_as(placed[jm.hips[0]]).clone()
    root[:, [0, 2]] += placed[jm.hips[0]][:, [0, 2]] - P0[jm.hips[0], [0, 2]]
    return {0: root}


def standing_height(positions: torch.Tensor, joint: int, planted: torch.Tensor | None, body: list[int]) -> float:
    """Height of ``joint`` above the clip's lowest body joint while planted (median; the joint's lowest
    height when it never is)."""
    floor = float(positions[:, body, 1].min())
    y = positions[:, joint, 1]
    if planted is not None and bool(planted.any()):
        return float(y[planted].median()) - floor
    return float(y.min()) - floor


def rest_stands(skeleton: Skeleton, hips: int, leg: tuple[int, int, int]) -> bool:
    """Whether the rest pose stands: the hips above the foot of ``leg`` (upper, lower, foot) by more
    than half the leg's length (Bandai's rest pose lies along +X and does not)."""
    _, P0 = rest_frames(skeleton)
    return float(P0[hips, 1] - P0[leg[2], 1]) > 0.5 * _chain_length(skeleton, list(leg))


def rest_on_floor(jm: JointMap) -> bool:
    """Whether the target's rest pose stands on the world floor: it stands (:func:`rest_stands`, each leg)
    and its lowest body joint is within `REST_FLOOR_TOLERANCE` of its height from y = 0 (a sole's
    thickness, a toe joint above the ground)."""
    _, P0 = rest_frames(jm.target)
    body = target_body(jm)
    low = lowest_rest_height(jm.target, body)
    if jm.legs and not all(rest_stands(jm.target, jm.hips[0], (g.upper, g.lower, g.foot)) for g in jm.legs):
        return False
    height = float(P0[body, 1].max()) - low
    return abs(low) <= REST_FLOOR_TOLERANCE * height


def source_foot_height(jm: JointMap, leg: Leg, positions: torch.Tensor, heel: torch.Tensor) -> float:
    """How high the source's foot joint sits above its floor when standing: from its rest pose when
    that pose stands (:func:`rest_stands`), else from the clip (:func:`standing_height`)."""
    _, P0 = rest_frames(jm.source)
    body = source_body(jm)
    if rest_stands(jm.source, jm.hips[1], (leg.source_upper, leg.source_lower, leg.source_foot)):
        return float(P0[leg.source_foot, 1]) - lowest_rest_height(jm.source, body)
    return standing_height(positions, leg.source_foot, heel, body)


def _pitch(v: torch.Tensor) -> torch.Tensor:
    """Angle (radians) of ``v (..., 3)`` below the horizontal."""
    return torch.atan2(-v[..., 1], v[..., [0, 2]].norm(dim=-1))


def _standing_turns(
    jm: JointMap, leg: Leg, source_globals: torch.Tensor, R: torch.Tensor, planted: dict
) -> torch.Tensor:
    """(K, 4) world rotations ``Q R_b`` the transfer gives the target foot while the source stands: its
    rest pose when that pose stands (``R_b`` alone: identical rigs are left unchanged), else the frames
    its heel is planted (all frames when it never is)."""
    if rest_stands(jm.source, jm.hips[1], (leg.source_upper, leg.source_lower, leg.source_foot)):
        return R[leg.foot][None]
    G0s, _ = rest_frames(jm.source)
    a, T = jm.pairs[leg.foot], source_globals.shape[0]
    M = quat_mul(source_globals[:, a].double(), quat_mul(quat_inverse(G0s[a]), R[leg.foot]).expand(T, 4))
    on = planted.get(leg.source_foot)
    return M[on] if on is not None and bool(on.any()) else M


def foot_pitch_turns(
    jm: JointMap, source_globals: torch.Tensor, R: torch.Tensor, planted: dict
) -> dict[int, torch.Tensor]:
    """{target foot and toes: (4,) world rotation ``C``} applied after the rest alignment (``R_b C``) so
    that, over the frames the source's heel is planted (all frames when it never is), the target's
    foot (ankle -> toes) has its own rest pitch. Copying the source's world direction instead stands a
    flatter foot (a Mixamo ankle -> ball 27 degrees down, Bandai's 39) pitched down on its toes, its
    heel and the whole body lifted 4-5 cm off the floor. ``C`` turns about the axis that the transfer
    carries onto the standing foot's lateral axis, so it raises the toes whatever the rigs' bone rolls.
    Only for legs with toes on both rigs (kinema.retarget.align for ``R``)."""
    _, P0t = rest_frames(jm.target)
    up = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)
    out: dict[int, torch.Tensor] = {}
    for leg in jm.legs:
        if leg.toes is None or leg.source_toes is None:
            continue
        M = _standing_turns(jm, leg, source_globals, R, planted)
        d = P0t[leg.toes] - P0t[leg.foot]
        dw = quat_rotate(M, d.expand(M.shape[0], 3))
        lateral = torch.linalg.cross(dw, up.expand_as(dw))
        axis = quat_rotate(quat_inverse(M), lateral / lateral.norm(dim=-1, keepdim=True).clamp_min(1e-12)).mean(0)
        if float(axis.norm()) < 0.5:
            continue  # no consistent lateral axis (a foot pointing straight down while planted)
        half = (_pitch(dw).median() - _pitch(d)) / 2  # > 0: standing steeper than at rest, raise the toes
        out[leg.foot] = out[leg.toes] = torch.cat([half.cos()[None], half.sin() * axis / axis.norm()])
    return out


def floor_shift(jm: JointMap, positions: torch.Tensor) -> float:
    """Vertical shift putting the clip's lowest body joint at the rest pose's lowest joint height (at y = 0
    when the rest pose does not stand on the floor, :func:`rest_on_floor`)."""
    return rest_floor(jm) - float(positions[:, target_body(jm), 1].min())


def rest_floor(jm: JointMap) -> float:
    """Where the target's lowest body joint stands: its rest height when the rest pose stands on the floor
    (:func:`rest_on_floor`), else the world floor, 0."""
    return lowest_rest_height(jm.target, target_body(jm)) if rest_on_floor(jm) else 0.0


def target_standing_height(jm: JointMap, joint: int, source_stand: float, s: float, on_floor: bool) -> float:
    """Height of the target's ``joint`` standing: its rest height when the rest pose stands on the floor
    (``on_floor``, :func:`rest_on_floor`), else the source's standing height ``source_stand`` scaled."""
    _, P0t = rest_frames(jm.target)
    return float(P0t[joint, 1]) if on_floor else s * source_stand


def source_standing_ankle(
    jm: JointMap, leg: Leg, positions: torch.Tensor, heel: torch.Tensor, joint: int | None = None
) -> float:
    """Height (y, in the clip's frame) of the source's ankle (or ``joint`` of that leg, its toes) when it
    stands: its rest pose's when that pose stands on the clip's floor (its lowest joint within a tenth
    of the leg of the clip's lowest), else the median over the ``heel`` frames (planted; the lowest
    height when there are none)."""
    _, P0 = rest_frames(jm.source)
    joint = leg.source_foot if joint is None else joint
    chain = (leg.source_upper, leg.source_lower, leg.source_foot)
    body = source_body(jm)
    floor_gap = abs(lowest_rest_height(jm.source, body) - float(positions[:, body, 1].min()))
    if rest_stands(jm.source, jm.hips[1], chain) and floor_gap < 0.1 * _chain_length(jm.source, list(chain)):
        return float(P0[joint, 1])
    y = positions[:, joint, 1]
    return float(y[heel].median()) if bool(heel.any()) else float(y.min())


def planted_joints(jm: JointMap, planted: dict) -> list[tuple[Leg, int, int, torch.Tensor]]:
    """(leg, target joint, source joint, (T,) flags) standing on the floor: each ankle while its source
    heel is planted, each ball of the foot (toes on both rigs) while only the source's toe is."""
    out = []
    for leg in jm.legs:
        heel = planted.get(leg.source_foot)
        if heel is not None and bool(heel.any()):
            out.append((leg, leg.foot, leg.source_foot, heel))
        toe = planted.get(leg.source_toes) if leg.source_toes is not None else None
        if toe is not None and leg.toes is not None:
            only = toe & ~heel if heel is not None else toe
            if bool(only.any()):
                out.append((leg, leg.toes, leg.source_toes, only))
    return out


def planted_floor_shift(
    jm: JointMap, positions: torch.Tensor, source_positions: torch.Tensor, planted: dict
) -> float | None:
    """Vertical shift that stands a humanoid on its planted feet (:func:`planted_joints`): there the
    target joint goes to its rest height plus the source joint's scaled height above its own standing
    height (median over those frames). None without legs or planted frames (then :func:`floor_shift`).
    The clip's lowest joint is no reference here: at a toe-off the ball of the foot dips below its
    standing height (the default model's by 2 cm) and that lifted whole walks 3-4 cm off the floor. A rest
    pose off the floor (:func:`rest_on_floor`) gives no rest heights: there the target joint goes to the
    source joint's scaled height above the world floor."""
    s = body_scale(jm)
    on_floor = rest_on_floor(jm)
    gaps = []
    for leg, joint, source_joint, on in planted_joints(jm, planted):
        stand = source_standing_ankle(jm, leg, source_positions, on, source_joint)
        rest = target_standing_height(jm, joint, stand, s, on_floor)
        want = rest + s * (source_positions[on, source_joint, 1] - stand)
        gaps.append(want - positions[on, joint, 1])
    return float(torch.cat(gaps).median()) if gaps else None
