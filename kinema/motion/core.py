"""`Motion`: a skeleton animated over time, with FK, resampling, cropping, concatenation and pruning.

Shapes and units (the contract every other module relies on):
- ``root_translation`` ``(T, 3)`` metres: world position of the root joint, Y up.
- ``local_rotations`` ``(T, J, 4)`` quaternions ``(w, x, y, z)``: full local rotation of each joint
  (parent frame -> joint frame), so all-identity is the skeleton's rest pose.
- ``foot_contacts`` optional ``(T, C)`` in [0, 1], one channel per contact joint of the rig
  (kinema.rig.Rig.contacts); the human rig has C = 4: left heel, left toe, right heel, right toe.
- ``local_translations`` optional ``(T, J, 3)`` metres: each joint's translation in its parent's frame
  for rigs that animate bone translations (glTF creatures: IK-driven feet, a moving body under a static
  root); ``None`` means the skeleton's constant offsets. Row 0 is unused (the root is ``root_translation``).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import torch

from kinema.errors import KinemaError
from kinema.geometry.rotations import (
    quat_inverse,
    quat_make_continuous,
    quat_mul,
    quat_normalize,
    quat_rotate,
    quat_slerp,
)
from kinema.kinematics import forward_kinematics
from kinema.motion.mirror import mirror_motion
from kinema.motion.writer import write_motion
from kinema.skeleton import Skeleton


@dataclass(eq=False)
class Motion:
    """A motion clip on one skeleton (see the module docstring for shapes and units)."""

    skeleton: Skeleton
    fps: float
    root_translation: torch.Tensor
    local_rotations: torch.Tensor
    foot_contacts: torch.Tensor | None = None
    local_translations: torch.Tensor | None = None

    def __post_init__(self) -> None:
        self.fps = float(self.fps)
        self.root_translation = torch.as_tensor(self.root_translation)
        self.local_rotations = torch.as_tensor(self.local_rotations)
        if not self.local_rotations.is_floating_point():
            self.local_rotations = self.local_rotations.float()
        self.root_translation = self.root_translation.to(self.local_rotations.dtype)
        T, J = self.local_rotations.shape[:2] if self.local_rotations.ndim == 3 else (None, None)
        if self.local_rotations.ndim != 3 or self.local_rotations.shape[-1] != 4:
            raise KinemaError(f"local_rotations must be (T, J, 4), got {tuple(self.local_rotations.shape)}")
        if J != self.skeleton.num_joints:
            raise KinemaError(f"local_rotations have {J} joints, skeleton has {self.skeleton.num_joints}")
        if self.root_translation.shape != (T, 3):
            raise KinemaError(f"root_translation must be ({T}, 3), got {tuple(self.root_translation.shape)}")
        if T == 0:
            raise KinemaError("a motion needs at least one frame")
        if not (self.fps > 0 and math.isfinite(self.fps)):
            raise KinemaError(f"fps must be positive, got {self.fps}")
        if self.foot_contacts is not None:
            self.foot_contacts = torch.as_tensor(self.foot_contacts, dtype=self.local_rotations.dtype)
            if self.foot_contacts.ndim != 2 or self.foot_contacts.shape[0] != T:
                raise KinemaError(
                    f"foot_contacts must be ({T}, C), one column per contact joint, got "
                    f"{tuple(self.foot_contacts.shape)}"
                )
        if self.local_translations is not None:
            self.local_translations = torch.as_tensor(self.local_translations, dtype=self.local_rotations.dtype)
            if self.local_translations.shape != (T, J, 3):
                raise KinemaError(
                    f"local_translations must be ({T}, {J}, 3), got {tuple(self.local_translations.shape)}"
                )

    # ------------------------------------------------------------------ basics
    @property
    def num_frames(self) -> int:
        return int(self.local_rotations.shape[0])

    @property
    def num_joints(self) -> int:
        return self.skeleton.num_joints

    @property
    def duration(self) -> float:
        """Seconds from the first to one frame past the last frame (``T / fps``)."""
        return self.num_frames / self.fps

    @property
    def dtype(self) -> torch.dtype:
        return self.local_rotations.dtype

    def is_finite(self) -> bool:
        return bool(torch.isfinite(self.local_rotations).all() and torch.isfinite(self.root_translation).all())

    def global_transforms(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(global rotations (T, J, 4), global positions (T, J, 3)) by forward kinematics."""
        offsets = self.skeleton.offsets if self.local_translations is None else self.local_translations
        return forward_kinematics(self.local_rotations, self.root_translation, offsets, self.skeleton.parents)

    @property
    def positions(self) -> torch.Tensor:
        """Global joint positions (T, J, 3), metres."""
        return self.global_transforms()[1]

    @property
    def global_rotations(self) -> torch.Tensor:
        """Global joint rotations (T, J, 4) wxyz."""
        return self.global_transforms()[0]

    def to(self, dtype: torch.dtype) -> Motion:
        contacts = None if self.foot_contacts is None else self.foot_contacts.to(dtype)
        trans = None if self.local_translations is None else self.local_translations.to(dtype)
        return replace(
            self,
            root_translation=self.root_translation.to(dtype),
            local_rotations=self.local_rotations.to(dtype),
            foot_contacts=contacts,
            local_translations=trans,
        )

    @classmethod
    def from_global(
        cls, skeleton: Skeleton, fps: float, root_translation, global_rotations, foot_contacts=None, positions=None
    ) -> Motion:
        """Build a motion from global rotations (T, J, 4): ``L_j = G_parent^-1 G_j``.

        With global ``positions`` (T, J, 3) the bone translations are solved too
        (``t_j = G_parent^-1 (p_j - p_parent)``) and kept as ``local_translations`` when they differ from
        the skeleton's offsets by more than 1e-6 m."""
        G = torch.as_tensor(global_rotations)
        parents = [max(p, 0) for p in skeleton.parents]
        local = quat_mul(quat_inverse(G[:, parents]), G)
        local[:, 0] = G[:, 0]
        trans = None
        if positions is not None:
            P = torch.as_tensor(positions).to(G.dtype)
            trans = quat_rotate(quat_inverse(G[:, parents]), P - P[:, parents])
            trans[:, 0] = skeleton.offsets[0].to(G.dtype)
            if (trans - skeleton.offsets.to(G.dtype)).abs().max() <= 1e-6:
                trans = None
        return cls(skeleton, fps, root_translation, quat_normalize(local), foot_contacts, trans)

    # ------------------------------------------------------------------ time edits
    def crop(self, start: int = 0, end: int | None = None) -> Motion:
        """Frames ``[start, end)`` (Python slice semantics, negative indices allowed)."""
        sl = slice(start, end)
        if len(range(self.num_frames)[sl]) == 0:
            raise KinemaError(f"crop [{start}, {end}) of a {self.num_frames}-frame motion is empty")
        contacts = None if self.foot_contacts is None else self.foot_contacts[sl]
        trans = None if self.local_translations is None else self.local_translations[sl]
        return replace(
            self,
            root_translation=self.root_translation[sl],
            local_rotations=self.local_rotations[sl],
            foot_contacts=contacts,
            local_translations=trans,
        )

    def resample(self, fps: float, *, keep_duration: bool = False) -> Motion:
        """Resample to another frame rate: slerp for rotations, linear for the root, nearest for contacts.

        Frame 0 is kept; the new frames cover the same time span ``[0, (T-1)/fps]``. With
        ``keep_duration`` the result has ``round(duration * fps)`` frames instead (the same `duration`,
        up to rounding, as a generated motion of that many seconds): frame ``i`` is the pose at time
        ``i / fps``, and a time past the last frame holds the last pose.
        """
        try:
            ok = not isinstance(fps, bool) and math.isfinite(float(fps)) and float(fps) > 0
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise KinemaError(f"fps must be a positive number, got {fps!r}")
        fps = float(fps)
        if abs(fps - self.fps) < 1e-9:
            return self
        T = self.num_frames
        if keep_duration:
            n_new = max(1, round(self.duration * fps))
        else:
            n_new = int(math.floor((T - 1) * fps / self.fps + 1e-6)) + 1
        src = (torch.arange(n_new, dtype=torch.float64) * (self.fps / fps)).clamp(max=T - 1)
        lo = src.floor().long().clamp(max=T - 1)
        hi = (lo + 1).clamp(max=T - 1)
        w = (src - lo.double()).to(self.dtype)
        q = quat_make_continuous(self.local_rotations, dim=0)
        rots = quat_slerp(q[lo], q[hi], w[:, None])
        root = self.root_translation[lo] * (1 - w[:, None]) + self.root_translation[hi] * w[:, None]
        contacts = None
        if self.foot_contacts is not None:
            contacts = self.foot_contacts[torch.where(w < 0.5, lo, hi)]
        trans = None
        if self.local_translations is not None:
            trans = (
                self.local_translations[lo] * (1 - w[:, None, None]) + self.local_translations[hi] * w[:, None, None]
            )
        return Motion(self.skeleton, fps, root, quat_normalize(rots), contacts, trans)

    def concatenate(self, other: Motion) -> Motion:
        """This motion followed by ``other`` (same skeleton topology and fps)."""
        if not self.skeleton.same_topology(other.skeleton):
            raise KinemaError("cannot concatenate motions on different skeletons")
        if abs(self.fps - other.fps) > 1e-6:
            raise KinemaError(f"cannot concatenate motions at {self.fps} and {other.fps} fps; resample first")
        contacts = None
        if self.foot_contacts is not None and other.foot_contacts is not None:
            contacts = torch.cat([self.foot_contacts, other.foot_contacts])
        trans = None
        if self.local_translations is not None or other.local_translations is not None:
            trans = torch.cat([self.translations_or_offsets(), other.translations_or_offsets().to(self.dtype)])
        return Motion(
            self.skeleton,
            self.fps,
            torch.cat([self.root_translation, other.root_translation.to(self.dtype)]),
            torch.cat([self.local_rotations, other.local_rotations.to(self.dtype)]),
            contacts,
            trans,
        )

    def translations_or_offsets(self) -> torch.Tensor:
        """(T, J, 3) bone translations: ``local_translations`` or the skeleton offsets repeated."""
        if self.local_translations is not None:
            return self.local_translations
        return self.skeleton.offsets.to(self.dtype).expand(self.num_frames, -1, -1).clone()

    # ------------------------------------------------------------------ skeleton edits
    def prune(self, drop: list[str], tolerance: float = 1e-3) -> Motion:
        """Remove joints (e.g. helper bones, Bandai's static ``joint_Root``), folding them into children.

        Kept joints keep their exact global rotations; a removed joint's offset and first-frame local
        rotation are folded into its children's offsets. If a removed joint moves, kept joints would
        drift: a warning names the largest position change when it exceeds ``tolerance`` metres.
        """
        if not drop:
            return self
        G, P = self.global_transforms()
        skel, keep = self.skeleton.prune(drop, fold_rotations=self.local_rotations[0].double())
        positions = None if self.local_translations is None else P[:, keep]
        out = Motion.from_global(skel, self.fps, P[:, keep[0]], G[:, keep], self.foot_contacts, positions)
        err = (out.positions - P[:, keep]).norm(dim=-1).max().item()
        if err > tolerance:
            warnings.warn(f"pruning {drop} moves kept joints by up to {err * 1000:.1f} mm", stacklevel=2)
        return out

    def mirror(self) -> Motion:
        """Left/right mirror image (reflection x -> -x, joints swapped); mirroring twice is the identity."""
        return mirror_motion(self)

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path, **options) -> Path:
        """Write the motion in the format its suffix names (``.bvh``, ``.bvh.gz``, ``.npz`` and whatever
        else is registered in kinema.io; docs/formats.md). ``options`` go to that format's writer (BVH:
        ``clean_rest``, ``scale``, ``order``). Motion knows no format: see kinema.motion.writer."""
        return write_motion(self, path, **options)

    def __repr__(self) -> str:
        return f"Motion({self.skeleton!r}, {self.num_frames} frames @ {self.fps:g} fps)"
