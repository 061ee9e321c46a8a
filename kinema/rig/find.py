"""Finding a rig's parts: from joint names where the naming scheme is known (kinema.naming), from the
rest-pose geometry otherwise.

By name (human-like rigs): root = the pelvis, contacts = [left heel (the ankle when there is no heel),
left toe, right heel, right toe], end effectors = head, hands and feet, limbs = each leg from the hip to
the toe and each arm from the shoulder (or upper arm) to the hand.

By geometry (creatures whose joint names say nothing kinema knows): in the rest pose (Y up), a *foot*
is a leaf joint in the lowest band of the skeleton, ``height < floor + FOOT_BAND * (top - floor)``, on a
skeleton that stands (its height clearly more than a sliver of its size: ``top - floor >
STANDING_RATIO * extent``, so a fish lying flat has no feet). Each foot contributes its parent too
when that parent is also in the band (ankle, toe). Legs are the chains from just below the nearest
branching ancestor down to each foot; every other leaf is an end effector.

Helper bones (IK targets, pole targets, controllers: names matching `HELPER_NAME`, and everything
below them) are never feet, end effectors or the root. Without a pelvis role, the root is found by
walking down from joint 0 while the joint sits on the floor (an armature or ``Root`` bone at the
origin) into its largest non-helper subtree.

On the 35 distinct skeletons of the shared Quaternius GLBs (joints at their node rest positions): the
five animals get 4 legs of two contacts each, bipeds their two ``Foot`` bones, 8 of 10 fish and
flyers none; a few are wrong (a dinosaur's tail tips touch the floor and count, a crab's body). Many
of those rigs drive the feet with IK bones parented outside the legs, so their feet lie on no leg
chain of three joints and foot locking leaves them alone. A rig override JSON fixes any of this.

Shapes and units: rest positions ``(J, 3)`` metres, Y up.
"""

from __future__ import annotations

import re

import torch

from kinema.kinematics import forward_kinematics
from kinema.skeleton import Skeleton, side_contacts

#: a foot lies in this fraction of the skeleton's height above its lowest joint
FOOT_BAND = 0.15
#: a skeleton stands when its height is more than this fraction of its largest extent
STANDING_RATIO = 0.15
#: names of helper bones that drive a rig but are not part of the body
HELPER_NAME = re.compile(r"pole|target|ctrl|control", re.I)
#: end effectors found by role name, in this order
EFFECTOR_ROLES = ("head", "left_hand", "right_hand", "left_ankle", "right_ankle")


def rest_transforms(skeleton: Skeleton) -> tuple[torch.Tensor, torch.Tensor]:
    """Global rotations ``(J, 4)`` and positions ``(J, 3)`` of the rest pose (the skeleton's rest
    rotations, else identity; float64)."""
    J = skeleton.num_joints
    rots = skeleton.rest_rotations
    if rots is None:
        rots = torch.zeros(J, 4, dtype=torch.float64)
        rots[:, 0] = 1.0
    G, P = forward_kinematics(
        rots.double()[None], torch.zeros(1, 3, dtype=torch.float64), skeleton.offsets.double(), skeleton.parents
    )
    return G[0], P[0]


def rest_positions(skeleton: Skeleton) -> torch.Tensor:
    """Joint positions ``(J, 3)`` of the rest pose (the skeleton's rest rotations, else identity)."""
    return rest_transforms(skeleton)[1]


def named_contacts(skeleton: Skeleton) -> tuple[int, ...] | None:
    """[L heel, L toe, R heel, R toe] (ankles standing in for heels) when names give all four; [L ankle,
    R ankle] for a biped without toe joints; else None."""
    roles = skeleton.roles
    left, right = side_contacts(roles, "left"), side_contacts(roles, "right")
    if left is not None and right is not None:
        return (*left, *right)
    if "left_ankle" in roles and "right_ankle" in roles and not skeleton.children[roles["left_ankle"]]:
        return (roles["left_ankle"], roles["right_ankle"])
    return None


def helpers(skeleton: Skeleton) -> set[int]:
    """Helper bones (see `HELPER_NAME`) and all their descendants."""
    out: set[int] = set()
    for j, (name, p) in enumerate(zip(skeleton.names, skeleton.parents, strict=True)):
        if HELPER_NAME.search(name) or p in out:
            out.add(j)
    return out


def geometric_root(skeleton: Skeleton) -> int:
    """From joint 0, step into the largest non-helper subtree while the joint sits on the floor."""
    P, skip = rest_positions(skeleton), helpers(skeleton)
    body = [j for j in range(skeleton.num_joints) if j not in skip] or [0]
    floor, top = float(P[body, 1].min()), float(P[body, 1].max())
    size = [1] * skeleton.num_joints
    for j in range(skeleton.num_joints - 1, 0, -1):
        size[skeleton.parents[j]] += size[j]
    j = 0
    while top > floor and float(P[j, 1]) <= floor + FOOT_BAND * (top - floor):
        kids = [c for c in skeleton.children[j] if c not in skip]
        if not kids:
            break
        j = max(kids, key=lambda c: size[c])
    return j


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
    skip = helpers(skeleton)
    body = [j for j in range(skeleton.num_joints) if j not in skip]
    if len(body) < 2:
        return []
    floor, top = float(P[body, 1].min()), float(P[body, 1].max())
    extent = float((P[body].max(0).values - P[body].min(0).values).max())
    if extent <= 0 or top - floor <= STANDING_RATIO * extent:
        return []
    leaves = [j for j in range(skeleton.num_joints) if not skeleton.children[j] and j != root and j not in skip]
    feet = [j for j in leaves if float(P[j, 1]) < floor + FOOT_BAND * (top - floor)]
    return sorted(feet, key=lambda j: (-round(float(P[j, 2]), 4), -float(P[j, 0])))


def geometric_contacts(skeleton: Skeleton, feet: list[int], root: int) -> tuple[int, ...]:
    """Each foot preceded by its parent when that parent also lies in the foot band (ankle, toe)."""
    P, skip = rest_positions(skeleton), helpers(skeleton)
    body = [j for j in range(skeleton.num_joints) if j not in skip]
    floor, top = float(P[body, 1].min()), float(P[body, 1].max())
    band = floor + FOOT_BAND * (top - floor)
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
