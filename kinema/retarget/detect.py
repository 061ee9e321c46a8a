"""Humanoid detection: which joint of a skeleton is which humanoid slot (kinema.retarget.names).

Order of evidence, each filling only what the previous left open:

1. the rig overrides JSON (kinema.rig.overrides): ``root`` is the hips, ``limbs.left_leg`` /
   ``right_leg`` list ``[upper_leg, lower_leg, foot(, toes)]`` and ``limbs.left_arm`` / ``right_arm``
   ``[(shoulder,) upper_arm, lower_arm, hand]``, by joint name;
2. joint names (the tables of kinema.retarget.names), each slot taking the shallowest candidate that
   continues its chain (a lower leg below the upper leg, a foot below the lower leg when there is
   one); the centre slots come from the tree (hips = lowest common ancestor of both legs and the
   chest);
3. the rest-pose geometry (kinema.retarget.geometry) when names give no legs or arms.

An IK helper standing for a foot (UE5 ``ik_foot_l``), or a second foot candidate off the leg, is a
*follower* of that slot: it is moved to wherever the slot's joint goes, so a mesh weighted to it
follows the leg. A foot that hangs from the root instead of the lower leg (Quaternius ``Foot.L``) is
the foot slot itself, *detached*: retargeting puts it at the leg chain's end.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from kinema.retarget import geometry
from kinema.retarget.names import (
    CENTRE_SLOTS,
    HEAD_WORDS,
    LIMB_PARTS,
    NECK_WORDS,
    REQUIRED,
    SIDES,
    SLOTS,
    centre_word,
    limb_part,
)
from kinema.rig import overrides as ov
from kinema.skeleton import Skeleton

_LEG = ("upper_leg", "lower_leg", "foot", "toes")
#: unmapped joints named in a report before '... and N more'
LISTED = 24
_ARM = ("shoulder", "upper_arm", "lower_arm", "hand")


@dataclass(frozen=True)
class HumanoidMap:
    """Slot -> joint index on one skeleton, with the evidence used and the helpers that follow slots."""

    skeleton: Skeleton
    slots: Mapping[str, int]
    followers: Mapping[str, tuple[int, ...]] = field(default_factory=dict)
    found_by: Mapping[str, str] = field(default_factory=dict)  # slot -> "names" | "overrides" | "geometry" | "tree"

    @property
    def is_humanoid(self) -> bool:
        return all(s in self.slots for s in REQUIRED)

    @property
    def missing(self) -> list[str]:
        return [s for s in SLOTS if s not in self.slots]

    def unmapped(self) -> list[str]:
        """Joints that are neither a slot nor a follower (twist bones, fingers, helpers, extra spine)."""
        used = set(self.slots.values()) | {j for f in self.followers.values() for j in f}
        return [n for j, n in enumerate(self.skeleton.names) if j not in used]

    def detached(self, side: str) -> bool:
        """True when the foot of ``side`` does not hang below its lower leg (an IK foot bone)."""
        foot, lower = self.slots.get(f"{side}_foot"), self.slots.get(f"{side}_lower_leg")
        return foot is not None and lower is not None and lower not in self.skeleton.path_from_root(foot)

    def lines(self) -> list[str]:
        """Human-readable report (``kinema inspect``): the mapping found and what is unmapped."""
        names = self.skeleton.names
        kind = (
            "humanoid"
            if self.is_humanoid
            else "not a humanoid (needs " + ", ".join(s for s in REQUIRED if s not in self.slots) + ")"
        )
        out = [f"humanoid mapping: {kind}"]
        for slot in SLOTS:
            if slot in self.slots:
                extra = f" (by {self.found_by.get(slot, 'names')})"
                if slot.endswith("_foot") and self.detached(slot.split("_")[0]):
                    extra += ", IK foot off the leg: follows the leg chain's end"
                follow = self.followers.get(slot, ())
                if follow:
                    extra += ", followed by " + ", ".join(names[j] for j in follow)
                out.append(f"  {slot:<16} {names[self.slots[slot]]}{extra}")
        missing = ", ".join(self.missing) or "none"
        out += textwrap.wrap(missing, width=100, initial_indent="  not found: ", subsequent_indent="    ")
        rest = self.unmapped()
        shown = ", ".join(rest[:LISTED]) + (f", ... and {len(rest) - LISTED} more" if len(rest) > LISTED else "")
        out.append(f"  unmapped joints ({len(rest)}, keep their rest pose or follow their chain):")
        out += textwrap.wrap(shown or "none", width=100, initial_indent="    ", subsequent_indent="    ")
        return out


def _is_below(skeleton: Skeleton, joint: int, ancestor: int | None) -> bool:
    return ancestor is not None and joint != ancestor and ancestor in skeleton.path_from_root(joint)


def _pick_chain(skeleton: Skeleton, candidates: dict[str, list[int]], parts: tuple[str, ...]) -> dict[str, int]:
    """Per part, the shallowest candidate below the previous part's joint (any candidate when none is)."""
    out: dict[str, int] = {}
    above: int | None = None
    for part in parts:
        cands = sorted(candidates.get(part, []), key=lambda j: (skeleton.depths[j], j))
        if not cands:
            continue
        below = [j for j in cands if _is_below(skeleton, j, above)]
        out[part] = (below or cands)[0]
        if below or above is None:
            above = out[part]
    return out


def _named_limbs(skeleton: Skeleton) -> tuple[dict[str, int], dict[str, tuple[int, ...]]]:
    """(slots of the limbs found by name, followers: IK helpers and spare feet per slot)."""
    cands: dict[str, dict[str, list[int]]] = {s: {} for s in SIDES}
    helpers: dict[str, list[int]] = {}
    for j, name in enumerate(skeleton.names):
        side, part, helper = limb_part(name)
        if side is None or part is None:
            continue
        if helper:
            helpers.setdefault(f"{side}_{part}", []).append(j)
        else:
            cands[side].setdefault(part, []).append(j)
    slots: dict[str, int] = {}
    followers: dict[str, tuple[int, ...]] = {}
    for side in SIDES:
        for parts in (_LEG, _ARM):
            for part, j in _pick_chain(skeleton, cands[side], parts).items():
                slots[f"{side}_{part}"] = j
        lower = slots.get(f"{side}_lower_leg")
        feet = cands[side].get("foot", [])
        spare = [j for j in feet if j != slots.get(f"{side}_foot") and not _is_below(skeleton, j, lower)]
        extra = spare + helpers.get(f"{side}_foot", [])
        if extra and f"{side}_foot" in slots:
            followers[f"{side}_foot"] = tuple(extra)
    return slots, followers


def _between(skeleton: Skeleton, top: int, end: int) -> list[int]:
    """Joints strictly between ``top`` and ``end`` on ``end``'s path from the root ([] when ``top`` is
    not above ``end``)."""
    path = skeleton.path_from_root(end)
    return path[path.index(top) + 1 : -1] if top in path else []


def _centre(skeleton: Skeleton, slots: dict[str, int]) -> dict[str, int]:
    """hips, spine, chest, neck, head from the tree and the names (module docstring)."""
    out: dict[str, int] = {}
    arms = [slots[f"{s}_upper_arm"] for s in SIDES if f"{s}_upper_arm" in slots]
    legs = [slots[f"{s}_upper_leg"] for s in SIDES if f"{s}_upper_leg" in slots]
    heads = sorted(
        (j for j, n in enumerate(skeleton.names) if centre_word(n) in HEAD_WORDS), key=lambda j: skeleton.depths[j]
    )
    if len(arms) == 2:
        out["chest"] = geometry.common_ancestor(skeleton, arms)
    if len(legs) == 2:
        hips = geometry.common_ancestor(skeleton, legs + ([out["chest"]] if "chest" in out else []))
        if hips is not None and hips not in legs:
            out["hips"] = hips
    if "chest" in out and out["chest"] in arms:
        del out["chest"]
    if heads:
        out["head"] = heads[0]
    spine = _between(skeleton, out["hips"], out["chest"]) if "hips" in out and "chest" in out else []
    if spine:
        out["spine"] = spine[0]
    neck = _between(skeleton, out["chest"], out["head"]) if "chest" in out and "head" in out else []
    named = [j for j in neck if centre_word(skeleton.names[j]) in NECK_WORDS]
    if named or neck:
        out["neck"] = (named or neck)[0]
    return out


def _from_overrides(skeleton: Skeleton, overrides) -> dict[str, int]:
    over, source = ov.read_overrides(overrides)
    out: dict[str, int] = {}
    if "root" in over:
        out["hips"] = ov.joint(skeleton, over["root"], source, "root")
    limbs = ov.named_chains(skeleton, over["limbs"], source, "limbs") if "limbs" in over else {}
    for side in SIDES:
        leg, arm = limbs.get(f"{side}_leg"), limbs.get(f"{side}_arm")
        if leg:
            out.update({f"{side}_{p}": j for p, j in zip(_LEG, leg, strict=False)})
        if arm:
            parts = _ARM if len(arm) >= 4 else _ARM[1:]
            out.update({f"{side}_{p}": j for p, j in zip(parts, arm, strict=False)})
    return out


def find_humanoid(skeleton: Skeleton, overrides: str | Path | Mapping | None = None) -> HumanoidMap:
    """The humanoid slots of ``skeleton`` (see the module docstring); never raises for a non-humanoid
    (``HumanoidMap.is_humanoid`` says). ``overrides``: a rig overrides JSON path or mapping."""
    found_by: dict[str, str] = {}
    slots = _from_overrides(skeleton, overrides)
    found_by.update({s: "overrides" for s in slots})
    named, followers = _named_limbs(skeleton)
    limb_slots = [f"{s}_{p}" for s in SIDES for p in LIMB_PARTS]
    if not all(
        f"{s}_{p}" in slots | named for s in SIDES for p in ("upper_leg", "lower_leg", "upper_arm", "lower_arm")
    ):
        for slot, j in geometry.geometric_limbs(skeleton).items():
            named.setdefault(slot, j)
            found_by.setdefault(slot, "geometry")
    for slot in limb_slots:
        if slot not in slots and slot in named:
            slots[slot] = named[slot]
            found_by.setdefault(slot, "names")
    for slot, j in _centre(skeleton, slots).items():
        if slot not in slots:
            slots[slot] = j
            found_by[slot] = "names" if slot in ("head", "neck") else "tree"
    used = set(slots.values())
    followers = {k: tuple(j for j in v if j not in used) for k, v in followers.items() if k in slots}
    ordered = {s: slots[s] for s in SLOTS if s in slots and slots[s] is not None}
    return HumanoidMap(skeleton, ordered, {k: v for k, v in followers.items() if v}, found_by)


def is_humanoid(skeleton: Skeleton, overrides: str | Path | Mapping | None = None) -> bool:
    """True when ``skeleton`` has hips, chest and both arms' and legs' upper and lower bones."""
    return find_humanoid(skeleton, overrides).is_humanoid


__all__ = ["CENTRE_SLOTS", "HumanoidMap", "find_humanoid", "is_humanoid"]
