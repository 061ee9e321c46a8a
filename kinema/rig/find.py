"""Finding a rig's parts: from joint names where the naming scheme is known (kinema.naming), from the
rest-pose geometry otherwise.

By name (human-like rigs): root = the pelvis, contacts = [left heel (the ankle when there is no heel),
left toe, right heel, right toe], end effectors = head, hands and feet, limbs = each leg from the hip to
the toe and each arm from the shoulder (or upper arm) to the hand.

By geometry (creatures whose joint names say nothing kinema knows): in the rest pose (Y up), a *foot*
is a leaf joint in the lowest band of the skeleton, ``height < floor + FOOT_BAND * (root height -
floor)``, on a skeleton that stands (its root clearly above its lowest joint: ``root height - floor >
STANDING_RATIO * extent``, so a fish lying flat has no feet). Each foot contributes its parent too
when that parent is also in the band (ankle, toe). Legs are the chains from just below the nearest
branching ancestor down to each foot; every other leaf is an end effector.

Shapes and units: rest positions ``(J, 3)`` metres, Y up.
"""

from __future__ import annotations

import torch

from kinema.kinematics import forward_kinematics
from kinema.skeleton import Skeleton

#: a foot lies in this fraction of the root's height above the lowest joint
FOOT_BAND = 0.15
#: a skeleton stands when its root is this fraction of its largest extent above its lowest joint
STANDING_RATIO = 0.15
#: end effectors found by role name, in this order
EFFECTOR_ROLES = ("head", "left_hand", "right_hand", "left_ankle", "right_ankle")


def rest_positions(skeleton: Skeleton) -> torch.Tensor:
    """Joint positions ``(J, 3)`` of the rest pose (the skeleton's rest rotations, else identity)."""
    J = skeleton.num_joints
    rots = skeleton.rest_rotations
    if rots is None:
        rots = torch.zeros(J, 4, dtype=torch.float64)
        rots[:, 0] = 1.0
    _, P = forward_kinematics(
        rots.double()[None], torch.zeros(1, 3, dtype=torch.float64), skeleton.offsets, skeleton.parents
    )
    return P[0]


def named_contacts(skeleton: Skeleton) -> tuple[int, ...] | None:
    """[L heel, L toe, R heel, R toe] (ankles standing in for heels) when names give all four, else None."""
    roles = skeleton.roles
    out = []
    for side in ("left", "right"):
        heel = roles.get(f"{side}_heel", roles.get(f"{side}_ankle"))
        toe = roles.get(f"{side}_toe")
        if heel is None or toe is None:
            return None
        out += [heel, toe]
    return tuple(out)


def named_limbs(skeleton: Skeleton) -> dict[str, tuple[int, ...]]:
    """Legs (hip..toe or hip..ankle) and arms (shoulder or upper arm..hand) whose roles all exist."""
    roles = skeleton.roles
    limbs = {}
    for side in ("left", "right"):
        leg_end = roles.get(f"{side}_toe", roles.get(f"{side}_ankle"))
        arm_top = roles.get(f"{side}_shoulder", roles.get(f"{side}_upper_arm"))
        for name, top, end in (
            (f"{side}_leg", roles.get(f"{side}_hip"), leg_end),
            (f"{side}_arm", arm_top, roles.get(f"{side}_hand")),
        ):
            chain = _chain(skeleton, top, end)
            if chain:
                limbs[name] = chain
    return limbs


def _chain(skeleton: Skeleton, top: int | None, end: int | None) -> tuple[int, ...] | None:
    """Joints from ``top`` down to ``end`` (both included) when ``top`` is an ancestor of ``end``."""
    if top is None or end is None:
        return None
    path = skeleton.path_from_root(end)
    return tuple(path[path.index(top) :]) if top in path and top != end else None


def named_effectors(skeleton: Skeleton) -> dict[str, int]:
    """Role name -> joint for the head, hands and feet (``left_foot`` is the ankle) that exist."""
    roles = skeleton.roles
    rename = {"left_ankle": "left_foot", "right_ankle": "right_foot"}
    return {rename.get(r, r): roles[r] for r in EFFECTOR_ROLES if r in roles}


def geometric_feet(skeleton: Skeleton, root: int) -> list[int]:
    """Leaf joints in the lowest band of a standing skeleton, ordered front to back, then left to right."""
    P = rest_positions(skeleton)
    if skeleton.num_joints < 2:
        return []
    floor = float(P[:, 1].min())
    extent = float((P.max(0).values - P.min(0).values).max())
    lift = float(P[root, 1]) - floor
    if extent <= 0 or lift <= STANDING_RATIO * extent:
        return []
    leaves = [j for j in range(skeleton.num_joints) if not skeleton.children[j] and j != root]
    feet = [j for j in leaves if float(P[j, 1]) < floor + FOOT_BAND * lift]
    return sorted(feet, key=lambda j: (-round(float(P[j, 2]), 4), -float(P[j, 0])))


def geometric_contacts(skeleton: Skeleton, feet: list[int], root: int) -> tuple[int, ...]:
    """Each foot preceded by its parent when that parent also lies in the foot band (ankle, toe)."""
    P = rest_positions(skeleton)
    floor = float(P[:, 1].min())
    band = floor + FOOT_BAND * (float(P[root, 1]) - floor)
    out: list[int] = []
    for foot in feet:
        parent = skeleton.parents[foot]
        if parent > 0 and parent != root and float(P[parent, 1]) < band and parent not in out:
            out.append(parent)
        out.append(foot)
    return tuple(out)


def geometric_limbs(skeleton: Skeleton, feet: list[int], root: int) -> dict[str, tuple[int, ...]]:
    """``leg_<k>``: from just below the nearest branching ancestor (or the root) down to foot k."""
    limbs = {}
    for k, foot in enumerate(feet):
        path = skeleton.path_from_root(foot)
        start = path.index(root) + 1 if root in path else 1
        for i in range(len(path) - 2, start - 1, -1):
            if len(skeleton.children[path[i]]) > 1:
                start = i + 1
                break
        chain = tuple(path[start:])
        if len(chain) >= 2:
            limbs[f"leg_{k}"] = chain
    return limbs


def leaf_effectors(skeleton: Skeleton, root: int, exclude: set[int]) -> dict[str, int]:
    """Every leaf joint (not the root, not in ``exclude``), keyed by its joint name."""
    return {
        skeleton.names[j]: j
        for j in range(skeleton.num_joints)
        if not skeleton.children[j] and j != root and j not in exclude
    }
