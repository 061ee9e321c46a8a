"""The app's constraints (JSON-form dicts, world frame, docs/constraints.md) as the any-rig model's
(kinema.generate.anyrig_constraints), and their residuals on an any-rig motion.

- waypoints and dense paths (``root2d``) -> one `RootPath` (the root starts at the origin at frame 0,
  so a waypoint on frame 0 is left out; headings are left out: the path faces where it goes);
- end-effector positions -> `JointTarget`, which the any-rig model takes in the *character frame*:
  the world target is read relative to the *planned* root at its frame (on the root path, else at the
  origin facing +Z, the way the model faces a motion without a path) at the height of the rest pose's
  root above its lowest joint;
- full-body poses (``fullbody``) -> `Keyframe`;
- what the model cannot take (rotation targets, foot contacts, targets on the root joint or on the
  IK bones of a floor-level armature, which it moves by translation and does not bring to a target:
  kinema.generate.anyrig_api.floor_root_children) is left out and named in the returned notes.
Units: metres, radians, Y up, +Z forward; frames at the model's fps.
"""

from __future__ import annotations

import math

import torch

from kinema.generate.anyrig_api import floor_root_children
from kinema.generate.anyrig_constraints import Constraint, JointTarget, Keyframe, RootPath
from kinema.geometry.rotations import axis_angle_to_quat, quat_rotate
from kinema.motion.core import Motion
from kinema.representation.joint import JointRepresentation, yaw_quat
from kinema.rig import Rig
from kinema.rig.find import rest_positions
from kinema.skeleton import Skeleton


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
    """The any-rig model's constraints for the app's ``constraints`` on ``skeleton``, and notes naming
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


def waypoint_residual(c: dict, motion: Motion) -> str:
    """A waypoint's / path's largest ground distance (cm) of the rig's root at its frames: the joint the
    any-rig model's root path moves (unsmoothed, unlike the human model's waypoints)."""
    frames = [int(f) for f in c["frame_indices"]]
    if max(frames) >= motion.num_frames:
        return "beyond the motion"
    root = Rig.from_skeleton(motion.skeleton).root
    xz = motion.to(torch.float64).positions[frames, root][:, [0, 2]]
    err = (xz - torch.tensor(c["smooth_root_2d"], dtype=torch.float64)).norm(dim=-1).max()
    return f"{100 * float(err):.1f} cm"
