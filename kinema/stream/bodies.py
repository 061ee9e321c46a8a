"""What a stream needs to know of the body it moves: where the body faces, how a window's first frames
(the last ones generated) are imposed, and whether steered windows must be turned to face their path.

- `HumanBody`: a model with a skeleton of its own (the human model). Facing from the hips; the context
  is docs/constraints.md ``fullbody`` keyframes with the representation's smoothed root; while steering,
  a window is turned to face along its path (the denoiser moves the root along a ``root2d`` path but
  keeps the body facing where the prompt walks).
- `RigBody`: an any-rig model on the request's rig. Facing from the rig's root rotation carried
  forward (kinema.representation.joint, the heading the model's features use); the context is
  character-frame constraints (kinema.constraints.character): a `Keyframe` per context frame (every
  joint, bone translations included: the Quaternius rigs move the body and the IK feet by translation)
  and a `RootMotion` over them (the root's ground velocity, height, rotation and heading), so the
  window continues where and how the root was going. A steering path becomes the model's root path,
  which sets the heading too (it faces where it goes), so windows are not turned afterwards.

Units: metres, radians (0 faces +Z), frames at the model's fps.
"""

from __future__ import annotations

import torch

from kinema.constraints.character import Keyframe, RootMotion
from kinema.motion.core import Motion
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS, smooth_time
from kinema.representation.joint import JointRepresentation
from kinema.rig import Rig
from kinema.skeleton import Skeleton
from kinema.stream.controls import context_keyframes
from kinema.stream.frames import face_along, facing, shifted, turned


class HumanBody:
    """The human model's own skeleton (see the module docstring)."""

    turns_to_path = True

    def __init__(self, skeleton: Skeleton):
        self.skeleton = skeleton
        self._hips = skeleton.roles["left_hip"], skeleton.roles["right_hip"]

    def facing(self, motion: Motion) -> torch.Tensor:
        """Heading per frame ``(T,)``, radians, from the hips."""
        return facing(motion.positions, *self._hips)

    def origin(self, context: Motion, smooth_root: torch.Tensor) -> tuple[float, float]:
        """Where a window's frame is put (world x, z): the context's first smoothed root, where the
        human representation's root path starts."""
        return float(smooth_root[0, 0]), float(smooth_root[0, 1])

    def window_constraints(self, context: Motion, smooth_root: torch.Tensor, controls: list[dict]) -> list:
        """A window's constraints (window frame): ``context`` as fullbody keyframes on its first frames,
        then the ``controls`` (kinema.stream.controls JSON) as they are."""
        return [context_keyframes(context, smooth_root), *controls]

    def root_path(self, window: Motion, first: int) -> dict:
        """``window``'s own root path over its free frames ``[first - 1, T)`` as a dense ``root2d``
        constraint: its smoothed root (the representation's 0.5-s Gaussian) and its hips' facing."""
        xz = smooth_time(window.root_translation[:, [0, 2]].float(), DEFAULT_ROOT_SIGMA_SECONDS * window.fps)
        psi = self.facing(window).float()
        frames = list(range(first - 1, window.num_frames))
        return {"type": "root2d", "frame_indices": frames, "smooth_root_2d": xz[frames].tolist(),
                "global_root_heading": torch.stack([psi.cos(), psi.sin()], -1)[frames].tolist()}

    @staticmethod
    def postprocess(targets_held: bool) -> bool:
        """Windows are post-processed only while a target is held (its exact pass; ~1 s a window)."""
        return targets_held

    def face_path(self, window: Motion, headings: torch.Tensor, first: int, sigma_frames: float) -> Motion:
        """``window`` turned frame by frame from ``first`` on to face along ``headings`` (kinema.stream.frames)."""
        return face_along(window, headings, first, *self._hips, sigma_frames)


class RigBody:
    """An any-rig model's rig, in metres (see the module docstring)."""

    turns_to_path = False

    def __init__(self, rig: Rig, fps: float):
        self.rig = rig
        self.skeleton = rig.skeleton
        self._rep = JointRepresentation(rig, fps)

    def facing(self, motion: Motion) -> torch.Tensor:
        """Heading per frame ``(T,)``, radians: the rig's forward axis carried by its root joint."""
        G, _ = motion.to(torch.float64).global_transforms()
        return self._rep.heading(G).to(motion.dtype)

    def origin(self, context: Motion, smooth_root: torch.Tensor) -> tuple[float, float]:
        """Where a window's frame is put (world x, z): the rig root's ground position on the context's
        first frame, where the any-rig model starts the root (so world targets land where they are)."""
        p = context.positions[0, self.rig.root]
        return float(p[0]), float(p[2])

    def window_constraints(self, context: Motion, smooth_root: torch.Tensor, controls: list[dict]) -> list:
        """A window's constraints (window frame): ``context`` as one keyframe per frame and the root's
        motion over it; with a steering path (``root2d`` in ``controls``) the root motion goes on along
        the path (`planned`); the other controls (targets) as they are (the pipeline reads them in the
        character frame: kinema.anyrig.world)."""
        n = context.num_frames
        keys = [Keyframe(frame=i, pose=context, pose_frame=i) for i in range(n)]
        paths = [c for c in controls if c["type"] == "root2d"]
        root = context if not paths else self.planned(context, paths[0])
        return [*keys, RootMotion(motion=root, until=root.num_frames),
                *(c for c in controls if c["type"] != "root2d")]

    def planned(self, context: Motion, path: dict) -> Motion:
        """``context`` followed by its last frame carried along a steering ``path`` (kinema.stream.controls.
        steer_path, from the context's last frame): moved with the path and turned with its heading,
        about the rig's root. Its root is what the window's root motion copies: the any-rig model given
        only the path (a ``RootPath``) lifts the body (the Fox's from 0.6 to 1.6-1.8 m under any path,
        plain ``generate`` too, less with the constraint guidance at 1: 0.7-1.2 m), so while steering
        the root keeps the height and the tilt of the context's last frame; the legs are the model's."""
        last = context.crop(context.num_frames - 1)
        p = last.positions[0, self.rig.root]
        px, pz = float(p[0]), float(p[2])
        psi0 = float(self.facing(last)[0])
        xz = torch.as_tensor(path["smooth_root_2d"], dtype=torch.float64)
        heading = torch.as_tensor(path["global_root_heading"], dtype=torch.float64)
        psi = torch.atan2(heading[:, 1], heading[:, 0])
        at_origin = shifted(last, -px, -pz)
        steps = [shifted(turned(at_origin, float(psi[k]) - psi0), px + float(xz[k, 0] - xz[0, 0]),
                         pz + float(xz[k, 1] - xz[0, 1])) for k in range(1, len(xz))]
        out = context
        for step in steps:
            out = out.concatenate(step)
        return out

    @staticmethod
    def postprocess(targets_held: bool) -> bool:
        """Always: the any-rig model's post-processing puts the window on the floor (its raw root height
        drifts) and locks the feet, in ~0.04 s a window."""
        return True

    def face_path(self, window: Motion, headings: torch.Tensor, first: int, sigma_frames: float) -> Motion:
        return window
