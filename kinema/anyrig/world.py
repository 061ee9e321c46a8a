"""World-frame constraints (docs/constraints.md, the human model's file format) for any-rig models.

The human model's constraints are in the world frame; the any-rig model's joint targets are in the
*character frame* (kinema.constraints.character). This module bridges them, for ``kinema generate
--model creatures --constraints FILE`` and the app (kinema.app.rig_constraints re-exports it):

- `json_form`: constraints read and checked by kinema.constraints.load_constraints against the rig's
  skeleton (joint names or roles, frames, shapes) -> the JSON form the app also uses: one dict per
  end-effector keyframe, frames as ``frame_indices`` at the model's fps, joint names resolved;
- `to_anyrig`: JSON form -> any-rig constraints, and notes naming what the model cannot take:
  waypoints and dense paths (``root2d``) -> one `RootPath` (the root starts at the origin at frame 0, so
  a waypoint on frame 0 is left out; headings are left out: the path faces where it goes); end-effector
  positions -> `JointTarget`, read in the character frame of a ``reference`` motion when given, else
  of the *planned* root (on the root path, else at the origin facing +Z) at the height of the rest
  pose's root above its lowest joint; full-body poses -> `Keyframe`; rotation targets, foot contacts,
  targets on the root joint or on the bones of a floor-level armature that the model moves by
  translation (kinema.anyrig.pipeline.floor_root_children) are left out;
- `generate_world`: when there are end-effector targets, a first raw pass without them gives the
  body's placement; the targets are read in its character frame and the second pass keeps its root
  (`RootMotion`: path, height, rotation, heading) up to the last target, so the world targets are
  exactly where the model is told they are and the exact pass of post-processing meets them.

Units: metres, radians, Y up, +Z forward; frames at the model's fps.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import torch

from kinema.anyrig.feet import floor_root_children
from kinema.constraints import Constraint as FileConstraint
from kinema.constraints import EndEffectorConstraint, constraint_to_json, load_constraints
from kinema.constraints.character import (
    CHARACTER_TYPES,
    Constraint,
    JointTarget,
    Keyframe,
    RootMotion,
    RootPath,
    check_constraints,
    parse_constraints,
)
from kinema.constraints.types import resolve_joint
from kinema.errors import KinemaError
from kinema.geometry.rotations import axis_angle_to_quat, quat_rotate
from kinema.motion.core import Motion
from kinema.representation.joint import JointRepresentation, yaw_quat
from kinema.rig import Rig
from kinema.rig.find import rest_positions
from kinema.skeleton import Skeleton


def json_form(constraints: list[FileConstraint], skeleton: Skeleton, fps: float, frames: int) -> list[dict]:
    """Checked file constraints as JSON-form dicts with ``frame_indices`` (see the module docstring)."""
    out = []
    for c in constraints:
        d = constraint_to_json(c)
        d.pop("times", None)
        d["frame_indices"] = c.frames(fps, frames)
        if isinstance(c, EndEffectorConstraint):
            d["joint"] = skeleton.names[resolve_joint(skeleton, c.joint)]
            for k, f in enumerate(d["frame_indices"]):
                one = {key: (v[k : k + 1] if isinstance(v, list) else v) for key, v in d.items()}
                out.append(one | {"frame_indices": [f]})
        else:
            out.append(d)
    return out


def root_waypoints(constraints: list[dict]) -> list[tuple[int, float, float]]:
    """Every ``root2d`` keyframe as (frame, x, z), sorted by frame, the first one kept per frame."""
    points: dict[int, tuple[float, float]] = {}
    for c in constraints:
        if c["type"] == "root2d":
            for f, (x, z) in zip(c["frame_indices"], c["smooth_root_2d"], strict=True):
                points.setdefault(int(f), (float(x), float(z)))
    return sorted((f, x, z) for f, (x, z) in points.items())


def planned_root(waypoints: list[tuple[int, float, float]], frame: int) -> tuple[float, float, float]:
    """(x, z, heading) of the root at ``frame`` on the straight-line path from the origin at frame 0
    through ``waypoints`` (the way `RootPath` moves it); heading 0 (+Z) without a path."""
    pts = [(0, 0.0, 0.0), *((f, x, z) for f, x, z in waypoints if f > 0)]
    if len(pts) == 1:
        return 0.0, 0.0, 0.0
    for (fa, xa, za), (fb, xb, zb) in zip(pts, pts[1:], strict=False):
        if frame <= fb or (fb, xb, zb) == pts[-1]:
            t = min(max((frame - fa) / (fb - fa), 0.0), 1.0)
            return xa + t * (xb - xa), za + t * (zb - za), math.atan2(xb - xa, zb - za)
    raise AssertionError("unreachable")


def character_frame(world: torch.Tensor, root: torch.Tensor, heading: float) -> torch.Tensor:
    """``world`` position(s) relative to ``root``, turned so that ``heading`` faces +Z."""
    return quat_rotate(yaw_quat(torch.tensor(-heading, dtype=torch.float64)), (world - root).double())


def local_target(c: dict, skeleton: Skeleton, waypoints, reference: Motion | None = None) -> torch.Tensor:
    """An end-effector's world position in the character frame at its frame: that of ``reference`` (a
    motion on ``skeleton``) when given, else that of the planned root (see the module docstring)."""
    f = int(c["frame_indices"][0])
    world = torch.tensor(c["positions"][0], dtype=torch.float64)
    if reference is not None and f < reference.num_frames:
        m = reference.to(torch.float64)
        rep = JointRepresentation(Rig.from_skeleton(skeleton), m.fps)
        G, P = m.global_transforms()
        return character_frame(world, P[f, rep.rig.root], float(rep.heading(G[f : f + 1])[0]))
    x, z, psi = planned_root(waypoints, f)
    rig = Rig.from_skeleton(skeleton)
    rest = rest_positions(skeleton)
    height = float(rest[rig.root, 1] - rest[:, 1].min())  # the root above the feet standing on the ground
    return character_frame(world, torch.tensor([x, height, z], dtype=torch.float64), psi)


def translated_bones(skeleton: Skeleton, root: int) -> set[int]:
    """The bones under a floor-level armature that the model moves by translation (its children off
    the path to ``root``, e.g. the Quaternius IK leg bones) and everything below them."""
    kids = set(floor_root_children(skeleton)) - set(skeleton.path_from_root(root))
    return {j for j in range(skeleton.num_joints) if kids & set(skeleton.path_from_root(j))}


def to_anyrig(
    constraints: list[dict], skeleton: Skeleton, fps: float, reference: Motion | None = None
) -> tuple[list[Constraint], list[str]]:
    """The any-rig model's constraints for JSON-form ``constraints`` on ``skeleton``, and notes naming
    what was left out; joint targets are read in the character frame of ``reference`` when given."""
    out: list[Constraint] = []
    left: dict[str, int] = {}
    root = Rig.from_skeleton(skeleton).root
    moved_bones, translated = translated_bones(skeleton, root), []
    wps = root_waypoints(constraints)
    if any(f == 0 for f, _, _ in wps):
        left["a waypoint on frame 0 (the root starts at the origin)"] = 1
    if any(c["type"] == "root2d" and "global_root_heading" in c for c in constraints):
        left["waypoint headings (the root faces where it goes)"] = 1
    moving = [(f, x, z) for f, x, z in wps if f > 0]
    if moving:
        out.append(RootPath(frames=[f for f, _, _ in moving], xz=[(x, z) for _, x, z in moving]))
    for c in constraints:
        kind = c["type"]
        if kind == "end-effector":
            if "rotations" in c:
                left["rotation targets"] = left.get("rotation targets", 0) + 1
            if "positions" not in c:
                continue
            j = skeleton.index(c["joint"])
            if j == root:
                left["targets on the root joint (use waypoints)"] = 1
                continue
            if j in moved_bones:
                translated.append(c["joint"])
                continue
            pos = local_target(c, skeleton, wps, reference)
            out.append(JointTarget(joint=j, frame=int(c["frame_indices"][0]), position=tuple(pos.tolist())))
        elif kind == "fullbody":
            rots = axis_angle_to_quat(torch.tensor(c["local_joints_rot"], dtype=torch.float64))
            pos = torch.tensor(c["root_positions"], dtype=torch.float64)
            pose = Motion(skeleton, fps, pos, rots)
            out += [Keyframe(frame=int(f), pose=pose, pose_frame=i) for i, f in enumerate(c["frame_indices"])]
        elif kind != "root2d":
            left[f"{kind} constraints"] = left.get(f"{kind} constraints", 0) + 1
    if translated:
        names = ", ".join(dict.fromkeys(translated))
        left[f"targets on bones it moves by translation ({names}; target a leg bone instead)"] = 1
    notes = []
    if left:
        notes.append("the any-rig model cannot take " + ", ".join(left) + "; they were left out")
    return out, notes


def generate_world(model, request, *, rig: Skeleton | Rig, constraints: list[dict], extra: list[Constraint] = (),
                   progress=None):
    """``model.sample_on_rig(request, rig=rig, ...)`` (kinema.anyrig.pipeline) for JSON-form world
    ``constraints`` (see the module docstring) and any-rig constraints ``extra`` (after them, so that
    their root rows win where both set the root, e.g. a stream's context), the result, the notes of
    what was left out, and the wall time of both passes (s). ``progress(done, total)`` runs over both
    passes as one bar; the first pass makes one sample without post-processing."""
    skeleton = rig.skeleton if isinstance(rig, Rig) else rig
    cons, notes = to_anyrig(constraints, skeleton, model.fps)
    cons += list(extra)
    targets = [c for c in cons if isinstance(c, JointTarget)]
    if not targets:
        res = model.sample_on_rig(request, rig=rig, constraints=cons, progress=progress)
        return res, notes, res.report.seconds
    first = model.sample_on_rig(request.replace(samples=1, postprocess=False), rig=rig, constraints=cons,
                                progress=_pass(progress, 0))
    reference = first.motions[0]
    cons, _ = to_anyrig(constraints, skeleton, model.fps, reference=reference)
    cons += [*extra, RootMotion(motion=reference, until=max(t.frame for t in targets) + 1)]
    res = model.sample_on_rig(request, rig=rig, constraints=cons, progress=_pass(progress, 1))
    return res, notes, first.report.seconds + res.report.seconds


def load_constraints_file(
    source, skeleton: Skeleton, fps: float, frames: int, source_fps: float | None = None
) -> tuple[list[Constraint], list[dict]]:
    """Constraints (a file path, or parsed JSON) for an any-rig model on ``skeleton`` and a motion of
    ``frames`` frames: either the any-rig list (``type`` ``joint`` / ``root_path`` / ``keyframe``:
    kinema.constraints.character.read_constraints), returned first, or a docs/constraints.md file or list
    (world frame), checked against the rig by kinema.constraints.load_constraints and returned second in
    `json_form`. Errors name the file."""
    if isinstance(source, str | Path):
        path = Path(source)
        if not path.is_file():
            raise KinemaError(f"{path}: no such constraints file")
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as err:
            raise KinemaError(f"{path}: cannot read constraints ({err})") from None
        where, base = str(path), path.parent
    else:
        data, where, base, path = source, "constraints", Path("."), source
    if isinstance(data, list) and any(isinstance(o, dict) and o.get("type") in CHARACTER_TYPES for o in data):
        if source_fps is not None:
            raise KinemaError(
                f"{where}: the any-rig list's frames are at the model's fps; a constraints fps "
                "applies to docs/constraints.md files"
            )
        cons = parse_constraints(data, where, base, fps)
        check_constraints(cons, skeleton, frames, where)
        return cons, []
    checked = load_constraints(path, skeleton, fps, frames, source_fps=source_fps)
    return [], json_form(checked, skeleton, fps, frames)


def _pass(progress, k: int):
    """``progress`` for pass ``k`` of two (one bar over both)."""
    if progress is None:
        return None
    return lambda done, total: progress(k * total + done, 2 * total)
