"""Constraint markers in the scene: waypoints (discs, heading arrows), paths (ground lines), targets
(spheres), keyframed poses (ghost skeletons), each labelled with its frame; the selected one is
highlighted. Positions are world metres, Y up (see kinema.app.edits for the JSON forms drawn)."""

from __future__ import annotations

import math

import numpy as np
import torch

from kinema.app.views import bone_pairs
from kinema.geometry.rotations import axis_angle_to_quat
from kinema.motion.contacts import contact_joints
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

MARK_COLOR = (70, 130, 240)
ACTIVE_COLOR = (240, 60, 60)
GHOST_COLOR = (120, 170, 255)
PLANT_COLOR = (40, 200, 90)
LIFT_COLOR = (230, 70, 70)


def pose_points(c: dict, skeleton: Skeleton, fps: float) -> np.ndarray:
    """(K, J, 3) joint positions of a ``fullbody`` constraint's poses."""
    rots = torch.tensor(c["local_joints_rot"], dtype=torch.float64)
    root = torch.tensor(c["root_positions"], dtype=torch.float64)
    return Motion(skeleton, fps, root, axis_angle_to_quat(rots)).positions.numpy()


def contact_flags_at(constraints: list[dict], frame: int) -> np.ndarray | None:
    """(4,) contact flags asked for at ``frame`` by the foot-contact constraints (the last one wins)."""
    flags = None
    for c in constraints:
        if c["type"] == "foot-contact" and frame in c["frame_indices"]:
            flags = np.asarray(c["contacts"][c["frame_indices"].index(frame)], dtype=bool)
    return flags


class Markers:
    """Scene nodes for the constraint list; ``draw`` replaces them all (lists are short)."""

    def __init__(self, scene, skeleton: Skeleton, fps: float, name: str = "/constraints"):
        self.scene, self.skeleton, self.fps, self.name = scene, skeleton, fps, name
        self.handles: list = []
        self.pending = None
        self.contact_marks = None
        self.pairs = bone_pairs(skeleton)

    def draw_pending(self, points: list[tuple[float, float]]) -> None:
        """The points of a path being clicked (not yet a constraint)."""
        if self.pending is not None:
            self.pending.remove()
            self.pending = None
        self.contact_marks = None
        if points:
            pts = np.array([(x, 0.01, z) for x, z in points], dtype=np.float32)
            self.pending = self.scene.add_point_cloud(
                f"{self.name}/pending", pts, ACTIVE_COLOR, point_size=0.08, point_shape="diamond"
            )

    def draw_contacts(self, motion: Motion, frame: int, flags: np.ndarray | None) -> None:
        """Rings under the contact joints of ``motion`` while a foot-contact constraint covers ``frame``:
        green where it plants the joint, red where it lifts it."""
        if self.contact_marks is not None:
            self.contact_marks.remove()
            self.contact_marks = None
        if flags is None or frame >= motion.num_frames:
            return
        P = motion.positions[frame, contact_joints(motion.skeleton)].detach().numpy().astype(np.float32)
        P[:, 1] = 0.015
        colors = np.array([PLANT_COLOR if f else LIFT_COLOR for f in flags], dtype=np.uint8)
        self.contact_marks = self.scene.add_point_cloud(
            f"{self.name}/contacts", P, colors, point_size=0.1, point_shape="square"
        )

    def clear(self) -> None:
        for h in self.handles:
            h.remove()
        self.handles = []

    def draw(self, constraints: list[dict], selected: int | None) -> None:
        self.clear()
        for i, c in enumerate(constraints):
            color = ACTIVE_COLOR if i == selected else MARK_COLOR
            name = f"{self.name}/c{i}"
            draw = {"root2d": self._root2d, "end-effector": self._target, "fullbody": self._pose}.get(c["type"])
            if draw is not None:
                draw(name, c, color)

    def _label(self, name: str, text: str, at) -> None:
        self.handles.append(self.scene.add_label(f"{name}/label", text, position=tuple(float(v) for v in at)))

    def _root2d(self, name: str, c: dict, color) -> None:
        pts = np.asarray(c["smooth_root_2d"], dtype=np.float32)
        ground = np.stack([pts[:, 0], np.full(len(pts), 0.01, np.float32), pts[:, 1]], axis=1)
        if c.get("dense"):
            segs = np.stack([ground[:-1], ground[1:]], axis=1)
            self.handles.append(self.scene.add_line_segments(f"{name}/line", segs, color, thickness=0.03))
            self.handles.append(
                self.scene.add_point_cloud(f"{name}/pts", ground, color, point_size=0.06, point_shape="circle")
            )
        else:
            self.handles.append(
                self.scene.add_cylinder(
                    f"{name}/disc",
                    radius=0.12,
                    height=0.02,
                    color=color,
                    position=tuple(ground[0]),
                    wxyz=(math.cos(math.pi / 4), math.sin(math.pi / 4), 0, 0),
                )
            )
        for k, hv in enumerate(c.get("global_root_heading", [])):
            if c.get("dense") and k % 4:
                continue
            start = ground[k] + np.array([0, 0.02, 0], np.float32)
            end = start + 0.35 * np.array([hv[1], 0.0, hv[0]], np.float32)
            self.handles.append(
                self.scene.add_line_segments(f"{name}/heading{k}", np.stack([start, end])[None], color, thickness=0.02)
            )
        self._label(name, f"{c['frame_indices'][0] / self.fps:.1f} s", ground[0] + np.array([0, 0.25, 0]))

    def _target(self, name: str, c: dict, color) -> None:
        if "positions" not in c:
            return
        p = tuple(float(v) for v in c["positions"][0])
        self.handles.append(self.scene.add_icosphere(f"{name}/ball", radius=0.05, color=color, position=p))
        self._label(name, f"{c['joint']} {c['frame_indices'][0] / self.fps:.1f} s", (p[0], p[1] + 0.3, p[2]))

    def _pose(self, name: str, c: dict, color) -> None:
        for k, P in enumerate(pose_points(c, self.skeleton, self.fps)):
            segs = P[self.pairs].astype(np.float32)
            self.handles.append(
                self.scene.add_line_segments(
                    f"{name}/ghost{k}", segs, GHOST_COLOR if color == MARK_COLOR else color, thickness=0.015
                )
            )
        P0 = pose_points(c, self.skeleton, self.fps)[0]
        self._label(
            name,
            f"pose {c['frame_indices'][0] / self.fps:.1f} s",
            P0[:, :].max(0) * (1, 1, 0) + P0[0] * (1, 0, 1) + (0, 0.15, 0),
        )
