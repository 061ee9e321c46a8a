"""Constraints made from what the user does in the scene, as JSON-form dicts (docs/constraints.md).

The app keeps every constraint in its JSON form (the form it saves and ``generate`` reads), one dict
per item, with ``frame_indices`` at the model's fps. These helpers build them from a motion frame, a
click on the ground or a dragged gizmo, and read back where to draw them. Units: metres, radians,
world Y up; a heading ``h`` faces ``(sin h, 0, cos h)`` (0 = +Z), written as ``(cos h, sin h)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

from kinema.errors import KinemaError
from kinema.geometry.rotations import axis_angle_to_quat, quat_to_axis_angle
from kinema.motion.core import Motion

#: foot-contact presets: name -> flags for [L heel, L toe, R heel, R toe]
#: each preset sets both feet (heel, toe flags of [left heel, left toe, right heel, right toe]): the generator
#: reads 0 as "off the ground", so a preset planting one foot says that it lifts the other
CONTACT_PRESETS = {
    "left foot planted, right lifted": (1, 1, 0, 0),
    "right foot planted, left lifted": (0, 0, 1, 1),
    "both feet planted": (1, 1, 1, 1),
    "both feet lifted": (0, 0, 0, 0),
}
#: names of sessions saved before the presets said what the other foot does
OLD_PRESET_NAMES = {
    "left foot planted": "left foot planted, right lifted",
    "right foot planted": "right foot planted, left lifted",
}


def heading_vector(h: float) -> list[float]:
    """``(cos h, sin h)``: the JSON ``global_root_heading`` of a facing angle ``h`` (radians, 0 = +Z)."""
    return [math.cos(h), math.sin(h)]


def ground_point(origin: Sequence[float], direction: Sequence[float]) -> tuple[float, float] | None:
    """Where a pointer ray meets the ground plane y = 0, as (x, z); None when it misses (points up)."""
    oy, dy = float(origin[1]), float(direction[1])
    if dy >= -1e-9:
        return None
    t = -oy / dy
    return float(origin[0] + t * direction[0]), float(origin[2] + t * direction[2])


def waypoint(frame: int, x: float, z: float, heading: float | None = None) -> dict:
    """A ``root2d`` waypoint: the smoothed root at (x, z) on ``frame``, facing ``heading`` if given."""
    out = {"type": "root2d", "frame_indices": [int(frame)], "smooth_root_2d": [[float(x), float(z)]]}
    if heading is not None:
        out["global_root_heading"] = [heading_vector(heading)]
    return out


def path(points: Sequence[tuple[float, float]], start: int, end: int, *, headings: bool) -> dict:
    """A dense ``root2d`` path through ``points`` (x, z), walked from frame ``start`` to ``end`` at an
    even speed (keyframes spread by arc length); ``headings`` faces along the path."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts) < 2:
        raise KinemaError("a path needs at least two points: click the ground again")
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-3])
    pts, seg = pts[keep], seg[seg > 1e-3]
    if len(pts) < 2 or end - start < len(pts) - 1:
        raise KinemaError(f"a path of {len(pts)} points needs at least {len(pts)} frames between its start and end")
    s = np.concatenate([[0.0], np.cumsum(seg)]) / seg.sum()
    frames = [int(f) for f in np.round(start + s * (end - start))]
    for i in range(1, len(frames)):  # strictly increasing, last one at `end`
        frames[i] = max(frames[i], frames[i - 1] + 1)
    for i in range(len(frames) - 2, -1, -1):
        frames[i] = min(frames[i], frames[i + 1] - 1)
    out = {"type": "root2d", "frame_indices": frames, "smooth_root_2d": pts.tolist(), "dense": True}
    if headings:
        d = np.gradient(pts, axis=0)
        out["global_root_heading"] = [heading_vector(math.atan2(dx, dz)) for dx, dz in d]
    return out


def keyframe(motion: Motion, frame: int) -> dict:
    """A ``fullbody`` keyframe: the motion's whole pose (local rotations, root position) at ``frame``."""
    rots = quat_to_axis_angle(motion.local_rotations[frame].double())
    return {
        "type": "fullbody",
        "frame_indices": [int(frame)],
        "local_joints_rot": [rots.tolist()],
        "root_positions": [motion.root_translation[frame].double().tolist()],
    }


def target(motion: Motion, frame: int, joint: str, *, position: bool, rotation: bool) -> dict:
    """An ``end-effector`` target where ``joint`` is at ``frame`` (its position and/or global rotation)."""
    if not (position or rotation):
        raise KinemaError("a target needs its position, its rotation or both")
    j = motion.skeleton.index(joint)
    G, P = motion.global_transforms()
    out = {"type": "end-effector", "joint": joint, "frame_indices": [int(frame)]}
    if position:
        out["positions"] = [P[frame, j].double().tolist()]
    if rotation:
        out["rotations"] = [quat_to_axis_angle(G[frame, j].double()).tolist()]
    return out


def contacts(start: int, end: int, preset: str) -> dict:
    """A ``foot-contact`` constraint holding one preset (see ``CONTACT_PRESETS``) on frames start..end."""
    preset = OLD_PRESET_NAMES.get(preset, preset)
    if preset not in CONTACT_PRESETS:
        raise KinemaError(f"unknown contact preset {preset!r} (one of {list(CONTACT_PRESETS)})")
    lo, hi = sorted((int(start), int(end)))
    return {
        "type": "foot-contact",
        "frame_indices": list(range(lo, hi + 1)),
        "contacts": [list(CONTACT_PRESETS[preset])] * (hi - lo + 1),
    }


def frame_range(first, last, end: int) -> tuple[int, int]:
    """Typed frame numbers as a range inside ``0..end``, in order, at least one frame long."""
    lo, hi = sorted(int(round(float(v))) for v in (first, last))
    lo = min(max(lo, 0), max(end - 1, 0))
    return lo, min(max(hi, lo + 1), end)


def label(c: dict, fps: float) -> str:
    """A short description for the constraint list: kind, frame(s) and time, e.g. ``waypoint @ 40 (2.0 s)``
    or ``Hand_R pos @ 12 (0.6 s)``."""
    f = c.get("frame_indices", [0])
    span = f"{f[0]} ({f[0] / fps:.1f} s)" if len(f) == 1 else f"{f[0]}-{f[-1]} ({f[0] / fps:.1f}-{f[-1] / fps:.1f} s)"
    kind = c["type"]
    if kind == "root2d":
        return f"{'path' if c.get('dense') else 'waypoint'} @ {span}"
    if kind == "fullbody":
        return f"pose @ {span}"
    if kind == "end-effector":
        what = "+".join(k[:3] for k in ("positions", "rotations") if k in c)
        return f"{c['joint']} {what} @ {span}"
    flags = tuple(int(v) for v in c["contacts"][0])
    name = next((n for n, p in CONTACT_PRESETS.items() if p == flags), "contacts")
    return f"{name} @ {span}"


#: plain words for the ground speed a waypoint asks for: (at most this many m/s, words), a person's pace
SPEED_WORDS = ((0.3, "standing about"), (2.0, "a walk"), (4.0, "a jog"), (7.0, "a run"))
#: said of a waypoint asking for more than the last of `SPEED_WORDS`
TOO_FAST = "faster than a person runs: the motion will rush there and may stop short"


def waypoint_speeds(constraints: list[dict], fps: float) -> dict[int, float]:
    """{index in ``constraints``: ground speed (m/s)} each waypoint asks for, in time order: the straight
    distance from the waypoint before it (from the start, the origin at frame 0, for the first) over the
    time between them; inf for a move in no time. Paths (dense root2d) are left out."""
    points = sorted((c["frame_indices"][0], i, c["smooth_root_2d"][0]) for i, c in enumerate(constraints)
                    if c["type"] == "root2d" and not c.get("dense"))
    out: dict[int, float] = {}
    frame, at = 0, (0.0, 0.0)
    for f, i, xz in points:
        distance, seconds = math.dist(at, xz), (f - frame) / fps
        out[i] = distance / seconds if seconds > 0 else (0.0 if distance == 0 else math.inf)
        frame, at = f, xz
    return out


def speed_words(speed: float) -> str:
    """What a waypoint asking for ``speed`` m/s makes the character do, in plain words."""
    return next((words for most, words in SPEED_WORDS if speed <= most), TOO_FAST)


def anchor(c: dict) -> tuple[float, float, float]:
    """Where a constraint's move gizmo sits (world metres): the first waypoint / target / pose root."""
    if c["type"] == "root2d":
        x, z = c["smooth_root_2d"][0]
        return float(x), 0.0, float(z)
    if c["type"] == "end-effector" and "positions" in c:
        return tuple(float(v) for v in c["positions"][0])
    if c["type"] == "fullbody":
        return tuple(float(v) for v in c["root_positions"][0])
    return 0.0, 0.0, 0.0


def moved(c: dict, position: Sequence[float], wxyz: Sequence[float] | None = None) -> dict:
    """A copy of ``c`` moved so that its anchor is at ``position`` (paths and poses move on the ground
    only); an end-effector with a rotation also takes the gizmo's rotation ``wxyz``."""
    out = dict(c)
    dx, dy, dz = (float(p) - a for p, a in zip(position, anchor(c), strict=True))
    if c["type"] == "root2d":
        out["smooth_root_2d"] = [[x + dx, z + dz] for x, z in c["smooth_root_2d"]]
    elif c["type"] == "fullbody":
        out["root_positions"] = [[x + dx, y, z + dz] for x, y, z in c["root_positions"]]
    elif c["type"] == "end-effector":
        if "positions" in c:
            out["positions"] = [[float(v) for v in position]]
        if "rotations" in c and wxyz is not None:
            q = torch.tensor([float(v) for v in wxyz], dtype=torch.float64)
            out["rotations"] = [quat_to_axis_angle(q).tolist()]
    return out


def rotation_wxyz(c: dict) -> tuple[float, float, float, float]:
    """The gizmo orientation for a constraint: an end-effector's target rotation, else identity."""
    if c["type"] == "end-effector" and "rotations" in c:
        q = axis_angle_to_quat(torch.tensor(c["rotations"][0], dtype=torch.float64))
        return tuple(float(v) for v in q)
    return 1.0, 0.0, 0.0, 0.0


def retimed(c: dict, frame: int) -> dict:
    """A copy of ``c`` shifted in time so that its first keyframe is ``frame`` (the others keep their
    spacing); frames must stay >= 0."""
    f = c["frame_indices"]
    shift = int(frame) - int(f[0])
    if f[0] + shift < 0:
        raise KinemaError("cannot move a constraint before frame 0")
    return {**c, "frame_indices": [int(x) + shift for x in f]}


def spanned(c: dict, start: int, end: int) -> dict:
    """A foot-contact range or a dense path stretched over frames ``start..end`` (a path keeps its points
    and headings choice, a contact range its flags)."""
    if c["type"] == "foot-contact":
        flags = tuple(int(v) for v in c["contacts"][0])
        preset = next((n for n, p in CONTACT_PRESETS.items() if p == flags), None)
        out = contacts(start, end, preset or "both feet planted")
        out["contacts"] = [list(flags)] * len(out["frame_indices"])
        return out
    if c["type"] == "root2d" and c.get("dense"):
        return path(c["smooth_root_2d"], int(start), int(end), headings="global_root_heading" in c)
    raise KinemaError("only foot contacts and paths span a frame range; use 'to this frame' to move the others")


__all__ = [
    "CONTACT_PRESETS",
    "anchor",
    "contacts",
    "ground_point",
    "heading_vector",
    "keyframe",
    "label",
    "moved",
    "path",
    "retimed",
    "spanned",
    "rotation_wxyz",
    "target",
    "waypoint",
]
