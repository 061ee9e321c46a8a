"""Which robot body stands for which human joint: the G1's names, a name guess for other MJCF humanoids,
and a small JSON mapping file for robots whose names are not recognised.

Keys are robot-side landmarks (``ROBOT_POINTS``); each maps to a body of the MJCF and an optional point in
that body's frame (metres), e.g. the G1's head is a point 0.43 m above its torso frame. A JSON mapping is
an object of such keys, each a body name or ``{"body": NAME, "offset": [x, y, z]}``; keys it leaves out
are guessed from the body names, and a landmark that can be neither read nor guessed is an error that
names it. The feet's soles are not mapped: they are found from the foot bodies' geoms (kinema.robot.description).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinema.errors import KinemaError
from kinema.input_files import read_json_bounded

#: Robot landmarks, in the order the retargeting uses them. ``*_hip`` is the hip joint centre, ``*_foot``
#: the body that carries the sole (the last ankle link), ``*_hand`` the wrist.
ROBOT_POINTS = (
    "pelvis",
    "torso",
    "head",
    "left_hip",
    "left_knee",
    "left_foot",
    "right_hip",
    "right_knee",
    "right_foot",
    "left_shoulder",
    "left_elbow",
    "left_hand",
    "right_shoulder",
    "right_elbow",
    "right_hand",
)

#: The Unitree G1 (Menagerie's unitree_g1, 23- and 29-DoF variants): body names, and points in them.
G1_MAPPING: dict[str, tuple[str, tuple[float, float, float]]] = {
    "pelvis": ("pelvis", (0.0, 0.0, 0.0)),
    "torso": ("torso_link", (0.0, 0.0, 0.0)),
    "head": ("torso_link", (0.0, 0.0, 0.43)),
    "left_hip": ("left_hip_roll_link", (0.0, 0.0, 0.0)),
    "left_knee": ("left_knee_link", (0.0, 0.0, 0.0)),
    "left_foot": ("left_ankle_roll_link", (0.0, 0.0, 0.0)),
    "right_hip": ("right_hip_roll_link", (0.0, 0.0, 0.0)),
    "right_knee": ("right_knee_link", (0.0, 0.0, 0.0)),
    "right_foot": ("right_ankle_roll_link", (0.0, 0.0, 0.0)),
    "left_shoulder": ("left_shoulder_roll_link", (0.0, 0.0, 0.0)),
    "left_elbow": ("left_elbow_link", (0.0, 0.0, 0.0)),
    "left_hand": ("left_wrist_yaw_link", (0.0, 0.0, 0.0)),
    "right_shoulder": ("right_shoulder_roll_link", (0.0, 0.0, 0.0)),
    "right_elbow": ("right_elbow_link", (0.0, 0.0, 0.0)),
    "right_hand": ("right_wrist_yaw_link", (0.0, 0.0, 0.0)),
}

#: The Unitree H1 (Menagerie's unitree_h1): the hip is where the thigh turns (the hip-pitch link), the hand
#: the centre of the sphere at the end of the forearm, the head the centre of the helmet sphere.
H1_MAPPING: dict[str, tuple[str, tuple[float, float, float]]] = {
    "pelvis": ("pelvis", (0.0, 0.0, 0.0)),
    "torso": ("torso_link", (0.0, 0.0, 0.0)),
    "head": ("torso_link", (0.045, 0.0, 0.68)),
    **{f"{s}_{key}": (f"{s}_{body}", (0.0, 0.0, 0.0)) for s in ("left", "right") for key, body in (
        ("hip", "hip_pitch_link"), ("knee", "knee_link"), ("foot", "ankle_link"), ("shoulder", "shoulder_roll_link"),
        ("elbow", "elbow_link"))},
    "left_hand": ("left_elbow_link", (0.28, 0.0, -0.015)),
    "right_hand": ("right_elbow_link", (0.28, 0.0, -0.015)),
}
#: Built-in robots' landmark tables, by robot name.
BUILTIN_MAPPINGS = {"g1": G1_MAPPING, "h1": H1_MAPPING}

#: Words that identify a landmark in a body name (the last matching body of the chain wins for feet and
#: hands, the first for the rest: a hip or shoulder is where its first link starts; see _guess).
_WORDS = {
    "pelvis": ("pelvis", "base", "hips", "waist"),
    "torso": ("torso", "chest", "trunk", "upper_body", "body"),
    "head": ("head", "neck"),
    "hip": ("hip", "thigh", "upper_leg"),
    "knee": ("knee", "shin", "calf", "lower_leg"),
    "foot": ("ankle", "foot", "sole"),
    "shoulder": ("shoulder", "upper_arm"),
    "elbow": ("elbow", "forearm", "lower_arm"),
    "hand": ("wrist", "hand", "palm"),
}
_LAST_WINS = ("foot", "hand")  # the last link of an ankle or a wrist carries the sole or the hand
_FALLBACK = {"torso": "pelvis", "head": "torso"}  # a robot without a torso or head body uses the one below
_SIDE = {
    "left": re.compile(r"(^|[_\-. ])(left|l)([_\-. ]|$)|^left", re.I),
    "right": re.compile(r"(^|[_\-. ])(right|r)([_\-. ]|$)|^right", re.I),
}


@dataclass(frozen=True)
class BodyPoint:
    """A landmark: a body of the MJCF and a point in its frame (metres)."""

    body: str
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)


def _guess(key: str, body_names: list[str]) -> str | None:
    """The body whose name names ``key`` (``left_knee`` -> a body with 'left' and 'knee'), or None. Words
    are tried in their order in ``_WORDS``: a body called 'pelvis' wins over an earlier 'waist_lower'."""
    side, _, part = key.partition("_") if key.startswith(("left_", "right_")) else (None, "", key)
    sided = []
    for name in body_names:
        low = name.lower()
        if side is not None and not _SIDE[side].search(low):
            continue
        if side is None and (_SIDE["left"].search(low) or _SIDE["right"].search(low)):
            continue
        sided.append(name)
    for word in _WORDS[part]:
        matches = [name for name in sided if word in name.lower()]
        if matches:
            return matches[-1] if part in _LAST_WINS else matches[0]
    return None


def _read_entry(key: str, value, where: str) -> BodyPoint:
    """One entry: a BodyPoint, a body name or {"body": NAME, "offset": [x, y, z]}."""
    if isinstance(value, BodyPoint):
        return value
    if isinstance(value, str):
        return BodyPoint(value)
    if not isinstance(value, dict) or not isinstance(value.get("body"), str):
        raise KinemaError(f'{where}: {key!r} must be a body name or {{"body": NAME, "offset": [x, y, z]}}')
    offset = value.get("offset", [0.0, 0.0, 0.0])
    if not isinstance(offset, list | tuple) or len(offset) != 3 or not all(
        isinstance(x, int | float) and not isinstance(x, bool) and np.isfinite(float(x)) for x in offset
    ):
        raise KinemaError(f"{where}: {key!r} offset must be three finite numbers (metres), got {offset!r}")
    return BodyPoint(value["body"], tuple(float(x) for x in offset))


def read_mapping(source: str | Path | dict, where: str = "robot_mapping") -> dict[str, BodyPoint]:
    """A mapping from a JSON file path or an inline object (a request's ``robot_mapping``), validated for
    its keys and shapes the same way for both; errors name the file, or ``where`` for an inline one."""
    if isinstance(source, str | Path):
        where = str(source)
        source = read_json_bounded(source, "mapping file")
    if not isinstance(source, dict):
        raise KinemaError(f"{where}: a mapping must be a JSON object of landmark -> body")
    unknown = sorted(set(map(str, source)) - set(ROBOT_POINTS))
    if unknown:
        raise KinemaError(f"{where}: unknown landmark(s) {unknown}; expected some of {list(ROBOT_POINTS)}")
    return {key: _read_entry(key, value, where) for key, value in source.items()}


def resolve_mapping(
    body_names: list[str], given: dict[str, BodyPoint] | None, builtin: str | None, where: str
) -> dict[str, BodyPoint]:
    """Every landmark of ROBOT_POINTS as a BodyPoint: given entries first, then the table of a built-in
    robot (``builtin``: its name in BUILTIN_MAPPINGS), then a guess from the body names; an unknown body or
    an unguessable landmark is a KinemaError."""
    out: dict[str, BodyPoint] = {}
    missing = []
    for key in ROBOT_POINTS:
        if given and key in given:
            out[key] = given[key]
        elif builtin is not None:
            body, offset = BUILTIN_MAPPINGS[builtin][key]
            out[key] = BodyPoint(body, offset)
        else:
            guess = _guess(key, body_names)
            if guess is not None:
                out[key] = BodyPoint(guess)
            elif key in _FALLBACK and _FALLBACK[key] in out:
                out[key] = out[_FALLBACK[key]]
            else:
                missing.append(key)
    if missing:
        raise KinemaError(
            f"{where}: cannot tell which body is {missing}; name them in a mapping (a JSON object landmark "
            f"-> body name: --mapping FILE with --robot on any "
            f"command, or robot_mapping in a request; bodies: {body_names})"
        )
    for key, point in out.items():
        if point.body not in body_names:
            raise KinemaError(f"{where}: mapping {key!r} names body {point.body!r}, which the MJCF does not have")
    first: dict[BodyPoint, str] = {}
    for key, point in out.items():
        other = first.setdefault(point, key)
        if other != key and _FALLBACK.get(key) != other:
            raise KinemaError(f"{where}: the mapping puts {other!r} and {key!r} at the same point (body "
                              f"{point.body!r}); each landmark needs its own body or offset")
    return out
