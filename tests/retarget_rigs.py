"""Humanoid rigs built for the retargeting tests: Mixamo-, UE5- and CMU-named skeletons with chosen
proportions, T- or A-pose rests and bones along +Y (Mixamo/Blender), +X (UE) or none (BVH offsets).

A rig is described in world rest positions (metres, Y up, facing +Z, its left on +X), then turned into
a `Skeleton`: with an ``axis`` every joint's rest rotation points that local axis at its first child
(offsets in the parent's frame, as GLB and FBX rigs store them); without one the offsets are world
vectors and there are no rest rotations (as in BVH).
"""

from __future__ import annotations

import functools
import math

import torch

import kinema
from kinema.geometry.rotations import quat_between, quat_inverse, quat_mul, quat_rotate
from kinema.skeleton import Skeleton

# slot -> (parent slot, T-pose world position of a 1.0-scale body with unit ratios)
_BODY = {
    "hips": (None, (0.0, 1.0, 0.0)),
    "spine": ("hips", (0.0, 1.1, 0.0)),
    "spine_mid": ("spine", (0.0, 1.2, 0.0)),
    "chest": ("spine_mid", (0.0, 1.32, 0.0)),
    "neck": ("chest", (0.0, 1.5, 0.0)),
    "head": ("neck", (0.0, 1.6, 0.02)),
    "head_end": ("head", (0.0, 1.78, 0.02)),
}
_LEFT = {
    "shoulder": ("chest", (0.04, 1.45, 0.0)),
    "upper_arm": ("shoulder", (0.17, 1.45, 0.0)),
    "lower_arm": ("upper_arm", (0.45, 1.45, 0.0)),
    "hand": ("lower_arm", (0.7, 1.45, 0.0)),
    "finger": ("hand", (0.79, 1.45, 0.0)),
    "upper_leg": ("hips", (0.1, 0.95, 0.0)),
    "lower_leg": ("upper_leg", (0.1, 0.53, 0.01)),
    "foot": ("lower_leg", (0.1, 0.09, -0.02)),
    "toes": ("foot", (0.1, 0.02, 0.12)),
    "toe_end": ("toes", (0.1, 0.02, 0.2)),
}

MIXAMO = {
    "hips": "Hips",
    "spine": "Spine",
    "spine_mid": "Spine1",
    "chest": "Spine2",
    "neck": "Neck",
    "head": "Head",
    "head_end": "HeadTop_End",
    "shoulder": "{S}Shoulder",
    "upper_arm": "{S}Arm",
    "lower_arm": "{S}ForeArm",
    "hand": "{S}Hand",
    "finger": "{S}HandIndex1",
    "upper_leg": "{S}UpLeg",
    "lower_leg": "{S}Leg",
    "foot": "{S}Foot",
    "toes": "{S}ToeBase",
    "toe_end": "{S}Toe_End",
}
UE5 = {
    "hips": "pelvis",
    "spine": "spine_01",
    "spine_mid": "spine_02",
    "chest": "spine_03",
    "neck": "neck_01",
    "head": "head",
    "head_end": "head_end",
    "shoulder": "clavicle_{s}",
    "upper_arm": "upperarm_{s}",
    "lower_arm": "lowerarm_{s}",
    "hand": "hand_{s}",
    "finger": "index_01_{s}",
    "upper_leg": "thigh_{s}",
    "lower_leg": "calf_{s}",
    "foot": "foot_{s}",
    "toes": "ball_{s}",
    "toe_end": "ball_end_{s}",
}
CMU = {
    "hips": "Hips",
    "spine": "LowerBack",
    "spine_mid": "Spine",
    "chest": "Spine1",
    "neck": "Neck",
    "head": "Head",
    "head_end": "Head_End",
    "shoulder": "{S}Shoulder",
    "upper_arm": "{S}Arm",
    "lower_arm": "{S}ForeArm",
    "hand": "{S}Hand",
    "finger": "{L}Thumb",
    "upper_leg": "{S}UpLeg",
    "lower_leg": "{S}Leg",
    "foot": "{S}Foot",
    "toes": "{S}ToeBase",
    "toe_end": "{S}Toe_End",
}


def _name(table: dict, slot: str, side: str | None, prefix: str) -> str:
    pattern = table[slot]
    if side is None:
        return prefix + pattern
    return prefix + pattern.format(S=side.capitalize(), s=side[0], L=side[0].upper())


def _joints(legs: float, arms: float, a_pose: bool) -> list[tuple[str, str | None, str | None, tuple]]:
    """(slot, side, parent key, world position) in parent-first order; keys are 'slot' or 'side:slot'."""
    out = [(slot, None, parent, pos) for slot, (parent, pos) in _BODY.items()]
    for side, sign in (("left", 1.0), ("right", -1.0)):
        for slot, (parent, (x, y, z)) in _LEFT.items():
            key_parent = parent if parent in _BODY else f"{side}:{parent}"
            if slot in ("upper_leg", "lower_leg", "foot", "toes", "toe_end"):
                y = 0.95 - (0.95 - y) * legs
            elif slot in ("lower_arm", "hand", "finger"):
                dx = (x - 0.17) * arms
                x, y = (
                    (0.17 + dx * math.cos(math.radians(40)), 1.45 - dx * math.sin(math.radians(40)))
                    if a_pose
                    else (0.17 + dx, y)
                )
            out.append((slot, side, key_parent, (sign * x, y, z)))
    return out


def build_rig(
    table: dict,
    *,
    prefix: str = "",
    scale: float = 1.0,
    legs: float = 1.0,
    arms: float = 1.0,
    a_pose: bool = False,
    axis: str | None = "y",
    root: str | None = None,
    name: str = "rig",
) -> Skeleton:
    """A humanoid `Skeleton` (module docstring): ``scale`` every length (100 for centimetres), ``legs``
    / ``arms`` multiply those limbs' lengths, ``root`` adds a static joint at the origin above the hips
    (UE ``root``) with ``ik_foot_root``/``ik_foot_l``/``ik_foot_r`` helpers under it for UE tables."""
    joints = _joints(legs, arms, a_pose)
    lift = 0.95 * (legs - 1.0)
    names, parents, pos = [], [], []
    index: dict[str, int] = {}
    if root is not None:
        names.append(root)
        parents.append(-1)
        pos.append((0.0, 0.0, 0.0))
    for slot, side, parent, (x, y, z) in joints:
        key = slot if side is None else f"{side}:{slot}"
        index[key] = len(names)
        names.append(_name(table, slot, side, prefix))
        parents.append(index[parent] if parent is not None else (0 if root is not None else -1))
        pos.append((x, y + lift, z))
    if root is not None and table is UE5:
        names.append("ik_foot_root")
        parents.append(0)
        pos.append((0.0, 0.0, 0.0))
        for side in ("left", "right"):
            names.append(f"ik_foot_{side[0]}")
            parents.append(len(names) - 2 if side == "left" else len(names) - 3)
            pos.append(pos[index[f"{side}:foot"]])
    return _skeleton(names, parents, torch.tensor(pos, dtype=torch.float64) * scale, axis, name)


def _skeleton(names, parents, P: torch.Tensor, axis: str | None, name: str) -> Skeleton:
    J = len(names)
    if axis is None:
        offsets = torch.stack([P[j] - (P[p] if p >= 0 else 0 * P[j]) for j, p in enumerate(parents)])
        return Skeleton(names, parents, offsets, name=name)
    ref = torch.tensor({"x": (1.0, 0, 0), "y": (0, 1.0, 0), "z": (0, 0, 1.0)}[axis], dtype=torch.float64)
    G = torch.zeros(J, 4, dtype=torch.float64)
    for j in range(J):
        kids = [c for c in range(J) if parents[c] == j and (P[c] - P[j]).norm() > 1e-9]
        if kids:
            G[j] = quat_between(ref, (P[kids[0]] - P[j]) / (P[kids[0]] - P[j]).norm())
        else:
            G[j] = G[parents[j]] if parents[j] >= 0 else torch.tensor([1.0, 0, 0, 0], dtype=torch.float64)
    local = torch.stack([G[j] if p < 0 else quat_mul(quat_inverse(G[p]), G[j]) for j, p in enumerate(parents)])
    offsets = torch.stack(
        [P[j] if p < 0 else quat_rotate(quat_inverse(G[p]), P[j] - P[p]) for j, p in enumerate(parents)]
    )
    return Skeleton(names, parents, offsets, local, name=name)


@functools.lru_cache(maxsize=1)
def source_walk():
    """The default human model's 'A person walks forward.' (3 s, 10 steps: fast), made once per session."""
    return kinema.load_model().generate("A person walks forward.", seconds=3, steps=10)[0]
