"""Joint-name conventions: which side a joint is on, its mirror partner's name, and its semantic role.

Covered schemes (case-insensitive): Bandai ``UpperLeg_L``; Mixamo/CMU ``LeftUpLeg``, ``LeftArm``;
``mixamorig:``/``mixamorig1:`` prefixes; 3ds Max biped ``Bip01 L Thigh``/``Bip001 R Foot``; Blender
``thigh.L``/``foot_l``; ``L_Hand``/``l_hand`` prefixes. Anything else can be named explicitly with
``Skeleton(role_overrides={"left_hand": "MyWeirdHandBone"})``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

#: Roles and the body-part words that identify them (after side and prefixes are stripped).
#: Order matters inside a tuple: the first word that matches wins for ties.
_PART_WORDS: dict[str, tuple[str, ...]] = {
    "pelvis": ("hips", "hip", "pelvis"),
    "spine": ("spine", "spine0", "spine1", "torso", "abdomen", "chest", "spine01"),
    "neck": ("neck", "neck1", "neck01"),
    "head": ("head",),
    "hip": ("upleg", "upperleg", "thigh", "hip", "legupper", "upperlegs"),
    "knee": ("leg", "lowerleg", "calf", "shin", "knee", "leglower"),
    "ankle": ("foot", "ankle"),
    "toe": ("toes", "toe", "toebase", "toe0", "ball", "toes0"),
    "heel": ("heel",),
    "shoulder": ("shoulder", "clavicle", "collar"),
    "elbow": ("forearm", "lowerarm", "elbow", "armlower"),
    "upper_arm": ("arm", "upperarm", "armupper"),
    "hand": ("hand", "wrist"),
}
_CENTRE_PARTS = ("pelvis", "spine", "neck", "head")

#: Alternative role names accepted wherever a role is looked up.
ROLE_ALIASES = {
    "left_foot": "left_ankle",
    "right_foot": "right_ankle",
    "root": "pelvis",
    "hips": "pelvis",
    "left_upper_leg": "left_hip",
    "right_upper_leg": "right_hip",
    "left_wrist": "left_hand",
    "right_wrist": "right_hand",
}

_PREFIX = re.compile(r"^(mixamorig\d*[:_]|bip0*1[ _]?|def[-_]|org[-_]|jnt[-_]|joint[-_]|b[-_]|bone[-_])", re.I)
_SIDE_PATTERNS = [  # (regex, side group, rest group)
    re.compile(r"^(?P<side>left|right)[ _.\-]?(?P<rest>.+)$", re.I),
    re.compile(r"^(?P<rest>.+?)[ _.\-]?(?P<side>left|right)$", re.I),
    re.compile(r"^(?P<side>[lr])[ _.\-](?P<rest>.+)$", re.I),
    re.compile(r"^(?P<rest>.+?)[ _.\-](?P<side>[lr])$", re.I),
]


def strip_prefix(name: str) -> str:
    """Remove rig prefixes such as ``mixamorig:`` or ``Bip01 `` (applied repeatedly)."""
    prev = None
    while prev != name:
        prev, name = name, _PREFIX.sub("", name, count=1)
    return name


def split_side(name: str) -> tuple[str | None, str]:
    """('L' | 'R' | None, body-part text) for a joint name."""
    base = strip_prefix(name)
    for pat in _SIDE_PATTERNS:
        m = pat.match(base)
        if m:
            return m.group("side")[0].upper(), m.group("rest")
    return None, base


def _normalise(part: str) -> str:
    return re.sub(r"[^a-z0-9]", "", part.lower())


def body_part(name: str) -> tuple[str | None, str | None]:
    """(side, part) where part is a key of the role table (``hip``, ``hand``...), or None if unknown."""
    side, rest = split_side(name)
    word = _normalise(rest)
    for part, words in _PART_WORDS.items():
        if word in words:
            if side is None and part == "hip":
                return None, "pelvis"  # a lone "Hip" is the pelvis
            return side, part
    return side, None


def swap_side(name: str) -> str | None:
    """The mirror partner's name (``Hand_L`` -> ``Hand_R``, ``LeftArm`` -> ``RightArm``), or None."""
    prefix_len = len(name) - len(strip_prefix(name))
    head, base = name[:prefix_len], name[prefix_len:]
    for pat in _SIDE_PATTERNS:
        m = pat.match(base)
        if not m:
            continue
        s = m.group("side")
        start, end = m.span("side")
        return head + base[:start] + _flip_word(s) + base[end:]
    return None


def _flip_word(side: str) -> str:
    table = {"l": "r", "r": "l", "left": "right", "right": "left"}
    flipped = table[side.lower()]
    if side.isupper():
        return flipped.upper()
    if side[0].isupper():
        return flipped.capitalize()
    return flipped


def find_roles(names: Sequence[str], depths: Sequence[int]) -> dict[str, int]:
    """Role name (``pelvis``, ``left_hand``...) -> joint index; the shallowest match wins."""
    best: dict[str, tuple[int, int]] = {}
    for j, name in enumerate(names):
        side, part = body_part(name)
        if part is None:
            continue
        if part in _CENTRE_PARTS:
            if side is not None:
                continue
            role = part
        else:
            if side is None:
                continue
            role = ("left_" if side == "L" else "right_") + part
        if role not in best or depths[j] < best[role][0]:
            best[role] = (depths[j], j)
    return {role: j for role, (_, j) in best.items()}
