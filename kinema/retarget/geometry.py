"""Humanoid limbs from the rest-pose geometry, for rigs whose joint names say nothing known.

In the rest pose (Y up, the character's left on +X as in every kinema rig), leaving out helper
bones (kinema.rig.find.helpers):

- the feet are the two lowest leaf joints on opposite sides of the body (x of opposite sign), both in
  the lowest ``FOOT_BAND`` of the height (a rig missing a leg has no second foot: its lowest leaf on
  that side is a hand, and its arm was driven as a leg, 177 deg off); each
  leg is the chain from just below their lowest common ancestor (the hips) down to the leaf: the
  last bone is a toe when it is more horizontal than vertical, so the chain ends ``upper_leg,
  lower_leg, foot, toes`` (a second flat bone after it is a toe end site and left out), else
  ``upper_leg, lower_leg, foot``;
- the hands are, among the other leaves, the two farthest from the body's centre line on opposite
  sides; each arm is the chain from just below their common ancestor (the chest): ``shoulder,
  upper_arm, lower_arm, hand`` when it has four joints or more (fingers past the fourth are left
  alone), ``upper_arm, lower_arm, hand`` with three.

A rig is only read this way when it stands like a person: at most two leaves in the lowest
``FOOT_BAND`` of its height (a quadruped has four) and the chest at least ``CHEST_RISE`` of the height
above the hips. Good enough for plain T- or A-pose characters; a rig overrides JSON (kinema.retarget.detect) settles
anything else.
"""

from __future__ import annotations

from kinema.rig.find import FOOT_BAND, helpers, rest_positions
from kinema.skeleton import Skeleton

#: the chest (the hands' common ancestor) sits at least this fraction of the height above the hips
CHEST_RISE = 0.1


def _chain_below(skeleton: Skeleton, top: int, leaf: int) -> list[int]:
    path = skeleton.path_from_root(leaf)
    return path[path.index(top) + 1 :] if top in path else []


def common_ancestor(skeleton: Skeleton, joints: list[int]) -> int:
    """The deepest joint on every one of ``joints``' paths from the root (a joint may be its own)."""
    common = 0
    for level in zip(*(skeleton.path_from_root(j) for j in joints), strict=False):
        if len(set(level)) != 1:
            break
        common = level[0]
    return common


def _pair(leaves: list[int], P, key) -> tuple[int, int] | None:
    """(left, right): the best leaf by ``key`` on each side of x = 0."""
    left = sorted((j for j in leaves if float(P[j, 0]) > 0), key=key)
    right = sorted((j for j in leaves if float(P[j, 0]) < 0), key=key)
    return (left[0], right[0]) if left and right else None


def _flat(P, a: int, b: int) -> bool:
    bone = P[b] - P[a]
    return float(abs(bone[1])) < float(bone[[0, 2]].norm())


def _leg_slots(skeleton: Skeleton, chain: list[int], P, side: str) -> dict[str, int]:
    while len(chain) > 4 and _flat(P, chain[-2], chain[-1]) and _flat(P, chain[-3], chain[-2]):
        chain = chain[:-1]  # a toe end site after the toe
    if len(chain) < 2:
        return {}
    toe = len(chain) >= 4 and _flat(P, chain[-2], chain[-1])
    parts = ("upper_leg", "lower_leg", "foot", "toes") if toe else ("upper_leg", "lower_leg", "foot")
    picked = chain[-len(parts) :] if len(chain) >= len(parts) else chain
    return {f"{side}_{p}": j for p, j in zip(parts, picked, strict=False)}


def _arm_slots(chain: list[int], side: str) -> dict[str, int]:
    parts = ("shoulder", "upper_arm", "lower_arm", "hand") if len(chain) >= 4 else ("upper_arm", "lower_arm", "hand")
    return {f"{side}_{p}": j for p, j in zip(parts, chain, strict=False)}


def geometric_limbs(skeleton: Skeleton) -> dict[str, int]:
    """Limb slots (``left_upper_leg`` ...) found from the rest pose (module docstring); {} when the
    rig shows no two feet or no two hands."""
    P = rest_positions(skeleton)
    skip = helpers(skeleton)
    leaves = [j for j in range(skeleton.num_joints) if not skeleton.children[j] and j not in skip and j != 0]
    if not leaves:
        return {}
    floor, top = float(P[leaves, 1].min()), float(P[:, 1].max())
    if sum(float(P[j, 1]) < floor + FOOT_BAND * (top - floor) for j in leaves) > 2:
        return {}
    feet = _pair(leaves, P, key=lambda j: float(P[j, 1]))
    if feet is None or any(float(P[j, 1]) >= floor + FOOT_BAND * (top - floor) for j in feet):
        return {}
    hips = common_ancestor(skeleton, list(feet))
    out: dict[str, int] = {}
    for side, foot in zip(("left", "right"), feet, strict=True):
        out.update(_leg_slots(skeleton, _chain_below(skeleton, hips, foot), P, side))
    rest = [j for j in leaves if j not in feet and hips in skeleton.path_from_root(j)]
    hands = _pair(rest, P, key=lambda j: -abs(float(P[j, 0])))
    if hands is None:
        return out
    chest = common_ancestor(skeleton, list(hands))
    if float(P[chest, 1] - P[hips, 1]) < CHEST_RISE * (top - floor):
        return out
    for side, hand in zip(("left", "right"), hands, strict=True):
        out.update(_arm_slots(_chain_below(skeleton, chest, hand), side))
    return out
