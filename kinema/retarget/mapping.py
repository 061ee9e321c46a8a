"""Which target joint follows which source joint: humanoid slots, same names, or an explicit table.

- Both skeletons humanoid (kinema.retarget.detect): slot to slot (the target's ``left_upper_leg``
  follows the source's), plus the legs the contact-aware IK works on and the IK helpers that follow
  a foot.
- Otherwise (creatures of one family, e.g. the Quaternius fox, wolf and husky): joints with the same
  name, compared without case, separators and rig prefixes.
- ``mapping={target joint: source joint}`` (names) replaces either for the joints it names.

Constraints written for a character (``mixamorig:LeftHand``) are turned into the model skeleton's
names by :func:`constraint_joint_names` through the same slots.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field

from kinema import naming
from kinema.errors import KinemaError
from kinema.retarget.align import body_frame
from kinema.retarget.detect import HumanoidMap, find_humanoid
from kinema.retarget.names import SIDES
from kinema.skeleton import Skeleton

#: a childless slot borrows the alignment of this slot (kinema.retarget.align)
CHAIN_PARENT = {
    "head": "neck",
    "neck": "chest",
    **{f"{s}_hand": f"{s}_lower_arm" for s in SIDES},
    **{f"{s}_foot": f"{s}_lower_leg" for s in SIDES},
    **{f"{s}_toes": f"{s}_foot" for s in SIDES},
    **{f"{s}_lower_arm": f"{s}_upper_arm" for s in SIDES},
    **{f"{s}_lower_leg": f"{s}_upper_leg" for s in SIDES},
}


@dataclass(frozen=True)
class Leg:
    """One leg on both skeletons: target joints (foot may hang off the leg), source joints."""

    side: str
    upper: int
    lower: int
    foot: int
    toes: int | None
    detached: bool
    source_upper: int
    source_lower: int
    source_foot: int
    source_toes: int | None


@dataclass(frozen=True)
class JointMap:
    """Target joint -> source joint, and what retargeting needs besides (see the module docstring)."""

    source: Skeleton
    target: Skeleton
    pairs: Mapping[int, int]
    chain_parent: Mapping[int, int] = field(default_factory=dict)
    hips: tuple[int, int] | None = None  # (target, source) joint placed in the world
    legs: tuple[Leg, ...] = ()
    followers: Mapping[int, tuple[int, ...]] = field(default_factory=dict)
    kind: str = "names"
    frames: tuple | None = None  # (target (2, 3), source (2, 3)) rest (forward, left) of humanoids
    primary: Mapping[int, int] = field(default_factory=dict)  # joint -> child whose direction is met exactly

    def describe(self) -> list[str]:
        t, s = self.target.names, self.source.names
        return [f"{t[b]} <- {s[a]}" for b, a in sorted(self.pairs.items())]


def _legs(src: HumanoidMap, tgt: HumanoidMap) -> tuple[Leg, ...]:
    out = []
    for side in SIDES:
        need = [f"{side}_{p}" for p in ("upper_leg", "lower_leg", "foot")]
        if not all(k in tgt.slots and k in src.slots for k in need):
            continue
        toes = f"{side}_toes"
        out.append(
            Leg(
                side,
                tgt.slots[need[0]],
                tgt.slots[need[1]],
                tgt.slots[need[2]],
                tgt.slots.get(toes),
                tgt.detached(side),
                src.slots[need[0]],
                src.slots[need[1]],
                src.slots[need[2]],
                src.slots.get(toes),
            )
        )
    return tuple(out)


def humanoid_joint_map(src: HumanoidMap, tgt: HumanoidMap) -> JointMap:
    """Slot-to-slot map of two humanoids (both ``is_humanoid``)."""
    pairs = {tgt.slots[k]: src.slots[k] for k in tgt.slots if k in src.slots}
    chain = {}
    for slot, parent in CHAIN_PARENT.items():
        if slot in tgt.slots and tgt.slots[slot] in pairs:
            p = parent
            while p in CHAIN_PARENT and (p not in tgt.slots or tgt.slots[p] not in pairs):
                p = CHAIN_PARENT[p]
            if p in tgt.slots and tgt.slots[p] in pairs:
                chain[tgt.slots[slot]] = tgt.slots[p]
    followers = {tgt.slots[k]: v for k, v in tgt.followers.items() if k in tgt.slots}
    hips = (tgt.slots["hips"], src.slots["hips"])
    frames = tuple(
        body_frame(h.skeleton, *(h.slots[k] for k in ("hips", "chest", "left_upper_leg", "right_upper_leg")))
        for h in (tgt, src)
    )
    spine_up = [k for k in ("hips", "spine", "chest", "neck", "head") if k in tgt.slots and tgt.slots[k] in pairs]
    primary = {tgt.slots[a]: tgt.slots[b] for a, b in zip(spine_up, spine_up[1:], strict=False)}
    return JointMap(
        src.skeleton, tgt.skeleton, pairs, chain, hips, _legs(src, tgt), followers, "humanoid", frames, primary
    )


def _key(name: str) -> str:
    return re.sub(r"[^a-z0-9]", "", naming.strip_prefix(name).lower())


def named_joint_map(source: Skeleton, target: Skeleton) -> JointMap:
    """Joints of the same (normalised) name; the shallowest shared joint is placed in the world."""
    by_key: dict[str, int] = {}
    for a, n in enumerate(source.names):
        by_key.setdefault(_key(n), a)
    pairs = {b: by_key[_key(n)] for b, n in enumerate(target.names) if _key(n) in by_key}
    if not pairs:
        raise KinemaError(
            f"rig {target.name or 'target'} shares no joint name with the motion's skeleton and is no humanoid "
            f"(or the motion's is not); pass mapping={{target joint: source joint}}"
        )
    return JointMap(source, target, pairs, _chain_parents(target, pairs), _top(target, pairs), (), {}, "names")


def _chain_parents(target: Skeleton, pairs: Mapping[int, int]) -> dict[int, int]:
    out = {}
    for b in pairs:
        p = target.parents[b]
        while p >= 0 and p not in pairs:
            p = target.parents[p]
        if p >= 0:
            out[b] = p
    return out


def _top(target: Skeleton, pairs: Mapping[int, int]) -> tuple[int, int]:
    b = min(pairs, key=lambda j: (target.depths[j], j))
    return b, pairs[b]


def explicit_joint_map(
    source: Skeleton, target: Skeleton, mapping: Mapping[str, str], base: JointMap | None
) -> JointMap:
    """``base`` (or an empty map) with ``mapping`` ({target joint name: source joint name}) applied."""
    pairs = dict(base.pairs) if base is not None else {}
    for t_name, s_name in mapping.items():
        for name, skel, what in ((t_name, target, "target"), (s_name, source, "source")):
            if name not in skel.names:
                raise KinemaError(f"mapping: {what} joint {name!r} not found; joints are {list(skel.names)}")
        pairs[target.names.index(t_name)] = source.names.index(s_name)
    if not pairs:
        raise KinemaError("mapping: empty joint table")
    if base is not None:
        return JointMap(
            source,
            target,
            pairs,
            {**_chain_parents(target, pairs), **base.chain_parent},
            base.hips,
            base.legs,
            base.followers,
            base.kind,
            base.frames,
            base.primary,
        )
    return JointMap(source, target, pairs, _chain_parents(target, pairs), _top(target, pairs), (), {}, "explicit")


def build_joint_map(
    source: Skeleton,
    target: Skeleton,
    mapping: Mapping[str, str] | None = None,
    target_overrides=None,
    source_overrides=None,
) -> JointMap:
    """The map retargeting uses (module docstring); overrides are rig overrides JSON (kinema.rig)."""
    src, tgt = find_humanoid(source, source_overrides), find_humanoid(target, target_overrides)
    if src.is_humanoid and tgt.is_humanoid:
        base = humanoid_joint_map(src, tgt)
    elif mapping:
        base = None
    else:
        base = named_joint_map(source, target)
    return explicit_joint_map(source, target, mapping, base) if mapping else base


def constraint_joint_names(character: Skeleton, model: Skeleton, overrides=None) -> dict[str, str]:
    """{character joint name: model joint name} for every humanoid slot both have (for constraints
    that name the character's joints, e.g. ``mixamorig:LeftHand`` -> ``Hand_L``)."""
    c, m = find_humanoid(character, overrides), find_humanoid(model)
    return {character.names[j]: model.names[m.slots[k]] for k, j in c.slots.items() if k in m.slots}


def model_joint_name(name: str, character: Skeleton, model: Skeleton, overrides=None) -> str:
    """The model skeleton's joint for a character joint name (names the model has pass through)."""
    if name in model.names:
        return name
    table = constraint_joint_names(character, model, overrides)
    if name not in table:
        known = ", ".join(sorted(table))
        raise KinemaError(
            f"constraint joint {name!r} is no humanoid bone of {character.name or 'the character'}; use one of {known}"
        )
    return table[name]
