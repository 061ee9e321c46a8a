"""Drawing motions in the viser scene: a skeleton (bones + joints) with its foot contacts.

A view owns a few scene nodes under one name prefix and redraws them for a frame. Every view has
``set_motion(motion, offset)``, ``show(frame)`` and ``remove()``; the skinned-mesh view of a rig's skin
(kinema.app.mesh_view, viser's ``scene.add_mesh_skinned``) stands beside ``SkeletonView``.
Positions are world metres, Y up; ``offset`` shifts a whole motion (samples shown side by side).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
import torch

from kinema.errors import KinemaError
from kinema.motion.contacts import contact_joints
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

PLANTED_COLOR = (40, 200, 90)
SELECTED_COLOR = (240, 160, 40)
OTHER_COLOR = (140, 150, 170)
ROBOT_COLOR = (60, 130, 210)  # a robot retargeted from each sample (kinema app --robot)


class CharacterView(Protocol):
    """What the app needs from anything that draws a character."""

    def set_motion(self, motion: Motion, offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None: ...

    def show(self, frame: int) -> None: ...

    def remove(self) -> None: ...


def rest_motion(skeleton: Skeleton, fps: float) -> Motion:
    """One frame of the skeleton standing in its rest pose on the ground at the origin (before any
    generation, so that a new tab shows the character)."""
    rest = skeleton.rest_rotations
    local = torch.tensor([1.0, 0, 0, 0]).repeat(skeleton.num_joints, 1) if rest is None else rest.float()
    still = Motion(skeleton, fps, torch.zeros(1, 3), local[None].clone())
    lift = -float(still.positions[0, :, 1].min())
    return Motion(skeleton, fps, torch.tensor([[0.0, lift, 0.0]]), local[None].clone())


def first_motions(rig, fps: float) -> list[Motion]:
    """What a rig (kinema.app.rigs.AppRig) shows in a new tab before anything is generated: its first
    clip, else its rest pose."""
    return list(rig.clips.values())[:1] or [rest_motion(rig.skeleton, fps)]


def _human_contacts(skeleton: Skeleton) -> list[int]:
    """The human four contact joints, or none for a skeleton without them."""
    try:
        return contact_joints(skeleton)
    except KinemaError:
        return []


def bone_pairs(skeleton: Skeleton) -> np.ndarray:
    """(B, 2) joint indices (parent, child) of every bone."""
    return np.array([(p, j) for j, p in enumerate(skeleton.parents) if p >= 0], dtype=np.int64)


class SkeletonView:
    """Bones as lines, joints as dots, planted contact joints as green dots (``motion.foot_contacts``,
    one column per joint of ``contacts``: a rig's contact joints, default the human four); with
    ``bones=False`` (a skin drawn over it) only the planted joints and the trail."""

    def __init__(
        self,
        scene,
        name: str,
        skeleton: Skeleton,
        *,
        color=SELECTED_COLOR,
        thickness: float = 0.025,
        trail: bool = False,
        contacts: Sequence[int] | None = None,
        bones: bool = True,
    ):
        self.scene, self.name, self.color, self.thickness, self.trail = scene, name, color, thickness, trail
        self.draw_bones = bones  # False under a skin: only the trail and the planted contact joints
        self.pairs = bone_pairs(skeleton)
        self.contact_idx = list(contacts) if contacts is not None else _human_contacts(skeleton)
        self.positions: np.ndarray | None = None  # (T, J, 3)
        self.contacts: np.ndarray | None = None  # (T, 4)
        self.bones = self.joints = self.planted = self.path = None

    def set_motion(self, motion: Motion, offset=(0.0, 0.0, 0.0)) -> None:
        self.positions = motion.positions.detach().double().numpy() + np.asarray(offset, dtype=np.float64)
        flags = motion.foot_contacts
        fits = flags is not None and flags.shape[-1] == len(self.contact_idx)
        self.contacts = flags.detach().numpy() > 0.5 if fits else None

    def _frame_points(self, frame: int) -> tuple[np.ndarray, np.ndarray]:
        assert self.positions is not None
        f = int(np.clip(frame, 0, len(self.positions) - 1))
        P = self.positions[f].astype(np.float32)
        planted = P[self.contact_idx][self.contacts[f]] if self.contacts is not None else P[:0]
        return P, planted

    def show(self, frame: int) -> None:
        if self.positions is None:
            return
        P, planted = self._frame_points(frame)
        segs = P[self.pairs]
        if self.trail and self.path is None and len(self.positions) > 1:
            self._add_trail()
        if not self.draw_bones:
            self._show_contacts(planted)
            return
        if self.bones is None:
            self.bones = self.scene.add_line_segments(f"{self.name}/bones", segs, self.color, thickness=self.thickness)
            self.joints = self.scene.add_point_cloud(
                f"{self.name}/joints", P, self.color, point_size=0.035, point_shape="circle"
            )
        else:
            self.bones.points = segs
            self.joints.points = P
        self._show_contacts(planted)

    def _add_trail(self) -> None:
        """The pelvis' ground track over the whole motion (to compare with waypoints and paths)."""
        assert self.positions is not None
        track = self.positions[:, 0].astype(np.float32).copy()
        track[:, 1] = 0.005
        segs = np.stack([track[:-1], track[1:]], axis=1)
        self.path = self.scene.add_line_segments(f"{self.name}/trail", segs, self.color, thickness=0.012)

    def _show_contacts(self, planted: np.ndarray) -> None:
        if self.planted is not None:
            self.planted.remove()
            self.planted = None
        if len(planted):
            self.planted = self.scene.add_point_cloud(
                f"{self.name}/planted", planted, PLANTED_COLOR, point_size=0.07, point_shape="circle"
            )

    def remove(self) -> None:
        for h in (self.bones, self.joints, self.planted, self.path):
            if h is not None:
                h.remove()
        self.bones = self.joints = self.planted = self.path = None
