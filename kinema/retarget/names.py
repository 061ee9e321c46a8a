"""Humanoid name tables: which joint of a rig is which humanoid bone, by name.

A humanoid here is the Unity/VRM bone set kinema needs to move a body: ``hips``, ``spine``, ``chest``,
``neck``, ``head`` and per side ``shoulder``, ``upper_arm``, ``lower_arm``, ``hand``, ``upper_leg``,
``lower_leg``, ``foot``, ``toes`` (slot names ``left_upper_leg`` ...). Fingers, twist bones and extra
spine joints are not slots: they keep their rest pose relative to their parent (kinema.retarget.core).

The tables below list the words each convention uses for a limb slot once prefixes (``mixamorig:``,
``DEF-``, ``J_Bip_L_``, ``Bip01 L``) and the side (``Left``/``_l``/``.L``/``_L``/``L``) are taken off:

==================  ===========  ============  =============  ==============  ===========  ===========  ================
slot                Mixamo       UE5           Unity / VRM    Rigify/metarig  CMU          Bandai       Quaternius
==================  ===========  ============  =============  ==============  ===========  ===========  ================
shoulder            Shoulder     clavicle      Shoulder       shoulder        Shoulder     Shoulder     Shoulder
upper_arm           Arm          upperarm      UpperArm       upper_arm       Arm          UpperArm     UpperArm
lower_arm           ForeArm      lowerarm      LowerArm       forearm         ForeArm      LowerArm     LowerArm
hand                Hand         hand          Hand           hand            Hand         Hand         Hand, Fist, Palm
upper_leg           UpLeg        thigh         UpperLeg       thigh           UpLeg        UpperLeg     UpperLeg
lower_leg           Leg          calf          LowerLeg       shin            Leg          LowerLeg     LowerLeg
foot                Foot         foot          Foot           foot            Foot         Foot         Foot
toes                ToeBase      ball          Toes           toe             ToeBase      Toes         (none)
==================  ===========  ============  =============  ==============  ===========  ===========  ================

The centre slots come from the tree, not from names, because conventions disagree there (Rigify's
hips is ``spine``; Quaternius' ``Hips`` sits beside the legs under ``Body``): ``hips`` is the lowest
common ancestor of both upper legs and the chest, ``chest`` the lowest common ancestor of both
upper arms (or shoulders), ``spine`` the first joint from the hips towards the chest, ``neck`` the
joint named neck (``neck``, ``neck_01``, ``Neck1``...) between chest and head, else the chest's child
towards the head, and ``head`` the joint named head. Names that carry a numeric segment suffix
(``thigh.L.001``, ``upperarm_twist_01_l``) are twist/segment bones, never slots.
"""

from __future__ import annotations

import re

from kinema import naming

SIDES = ("left", "right")
LIMB_PARTS = ("shoulder", "upper_arm", "lower_arm", "hand", "upper_leg", "lower_leg", "foot", "toes")
CENTRE_SLOTS = ("hips", "spine", "chest", "neck", "head")
#: every humanoid slot, parents before children
SLOTS = (
    "hips",
    "spine",
    "chest",
    "neck",
    "head",
    *(f"{side}_{part}" for side in SIDES for part in LIMB_PARTS),
)
#: slots a skeleton needs to count as a humanoid
REQUIRED = ("hips", "chest", *(f"{s}_{p}" for s in SIDES for p in ("upper_arm", "lower_arm", "upper_leg", "lower_leg")))

#: body-part words (lower case, no separators) of each limb slot, across the conventions above
LIMB_WORDS: dict[str, tuple[str, ...]] = {
    "shoulder": ("shoulder", "clavicle", "collar", "collarbone"),
    "upper_arm": ("arm", "upperarm", "armupper", "humerus"),
    "lower_arm": ("forearm", "lowerarm", "armlower", "elbow"),
    "hand": ("hand", "wrist", "fist", "palm"),
    "upper_leg": ("upleg", "upperleg", "thigh", "legupper", "femur"),
    "lower_leg": ("leg", "lowerleg", "calf", "shin", "knee", "leglower"),
    "foot": ("foot", "ankle"),
    "toes": ("toes", "toe", "toebase", "ball", "toe0", "toes0"),
}
NECK_WORDS = ("neck", "neck1", "neck01", "neck0")
HEAD_WORDS = ("head",)
#: prefixes beyond kinema.naming's (VRoid ``J_Bip_C_``/``J_Bip_L_``, UE ``ik_`` helpers handled apart)
_EXTRA_PREFIX = re.compile(r"^(j_bip_[clr]_|j_adj_[clr]_|j_sec_[clr]_|cc_base_|character\d*[:_])", re.I)
_VRM_SIDE = re.compile(r"^j_(?:bip|adj|sec)_([lr])_", re.I)
_CMU_SIDE = re.compile(r"^([LR])(?=[A-Z][a-z])")  # CMU LHipJoint, LThumb, RFingers
#: an IK helper that stands for a foot or hand (UE ``ik_foot_l``): it follows the limb's end
IK_PREFIX = re.compile(r"^ik[_ -]?", re.I)


def _word(text: str) -> str:
    return re.sub(r"[^a-z0-9]", "", text.lower())


def side_and_word(name: str) -> tuple[str | None, str]:
    """(``"left"``/``"right"``/None, body-part word) of a joint name, any convention above."""
    m = _VRM_SIDE.match(name)
    if m:
        side = "left" if m.group(1).lower() == "l" else "right"
        return side, _word(_EXTRA_PREFIX.sub("", name))
    base = _EXTRA_PREFIX.sub("", name)
    side, rest = naming.split_side(base)
    if side is None:
        stripped = naming.strip_prefix(base)
        m = _CMU_SIDE.match(stripped)
        if m:
            side, rest = m.group(1), stripped[1:]
    return ({"L": "left", "R": "right"}.get(side or ""), _word(rest))


def limb_part(name: str) -> tuple[str | None, str | None, bool]:
    """(side, limb part, is an IK helper) for a joint name; part None when it names no limb slot.

    Segment and twist bones (``thigh.L.001``, ``upperarm_twist_01_l``) are no slot: their trailing
    number or ``twist`` word makes the word unknown."""
    helper = bool(IK_PREFIX.match(naming.strip_prefix(name)))
    side, word = side_and_word(IK_PREFIX.sub("", naming.strip_prefix(name)) if helper else name)
    if side is None:
        return None, None, helper
    for part, words in LIMB_WORDS.items():
        if word in words:
            return side, part, helper
    return side, None, helper


def centre_word(name: str) -> str:
    """The side-less word of a joint name (``neck``, ``head``, ``spine01``...), '' for a sided joint."""
    side, word = side_and_word(name)
    return "" if side else word


__all__ = [
    "CENTRE_SLOTS",
    "HEAD_WORDS",
    "LIMB_PARTS",
    "LIMB_WORDS",
    "NECK_WORDS",
    "REQUIRED",
    "SIDES",
    "SLOTS",
    "centre_word",
    "limb_part",
    "side_and_word",
]
