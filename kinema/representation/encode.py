"""Constraints -> imputation targets over the Kimodo features (paper Sec. 4.2: ``x~ = m x_tgt + (1-m) x``).

`encode_constraints` returns `ConstraintTargets`: ``x_tgt (T, D)`` unnormalised features (metres,
radians, ...) and ``mask (T, D)`` in {0, 1} over the FeatureLayout channels, plus ``world_xz (T, J, 2)``
/ ``world_mask (T, J)`` for joint x/z given in the world frame at frames whose smoothed-root x/z is
not constrained, and ``kinds`` (which constraint touches which frames, for residual reports).

Channels per type (at the constraint's frames), as the model was trained (kinema.train.constraints):

- fullbody: FK of the pose gives global positions P and rotations G. root_pos = (x, z of
  ``smooth_root_2d`` if given, else of the pelvis: a documented approximation, Kimodo's files carry
  the smoothed root; y = pelvis height), heading from the hips, joint_pos y = P.y, joint_pos x/z =
  P.xz - root x/z, joint_rot = 6D(G); all masked (not joint_vel, not contacts).
- end-effector: rotation -> joint_rot 6D of the joint; position -> joint_pos y of the joint, and its
  world x/z (see below). ``smooth_root_2d`` -> root_pos x/z. ``left_foot`` is the ankle joint.
- root2d: root_pos x/z (+ heading when given); dense paths on every frame of their interval.
- foot-contact: the 4 contact channels.

Joint x/z are root-relative features, so every joint x/z target is first kept as a *world* position
and resolved at the end: at frames whose root_pos x/z is masked (by any constraint) it becomes
``joint_pos x/z = world - root`` (masked); elsewhere it stays in ``world_xz``/``world_mask`` and the
joint_pos x/z channels stay unmasked. A sampler handles those by `world_to_relative` at every
denoising step: with the current clean estimate's root x/z it builds the relative targets and
imputes them, so the target follows the root as the root is being denoised.

Overlaps: constraints apply in list order and a later one wins on every channel it sets (root x/z,
root y, heading, joint y, joint world x/z, joint rotation, contacts), also across types; channels it
does not set keep earlier targets. A fullbody pose whose root is later moved by a root2d waypoint
keeps its world joint positions (the relative x/z are computed from the final root).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from kinema.constraints.types import (
    Constraint,
    ConstraintError,
    EndEffectorConstraint,
    FootContactConstraint,
    FullBodyConstraint,
    Root2DConstraint,
    resolve_joint,
)
from kinema.errors import KinemaError
from kinema.geometry.rotations import axis_angle_to_quat, quat_to_sixd
from kinema.kinematics import forward_kinematics
from kinema.representation.kimodo_features import heading_from_positions
from kinema.representation.layout import FeatureLayout
from kinema.representation.masks import contacts_mask, fullbody_mask, root2d_mask, root_path_mask
from kinema.skeleton import Skeleton


@dataclass
class ConstraintTargets:
    """Imputation targets for one motion of ``T`` frames (see the module docstring).

    ``x_tgt (T, D)`` unnormalised features (zero where unconstrained), ``mask (T, D)`` {0, 1},
    ``world_xz (T, J, 2)`` world joint x/z in metres where ``world_mask (T, J)`` is 1, and ``kinds``:
    constraint kind -> sorted frames it touches (``fullbody``, ``end-effector:<joint name>``,
    ``root2d``, ``root2d:dense``, ``foot-contact``).
    """

    x_tgt: torch.Tensor
    mask: torch.Tensor
    world_xz: torch.Tensor
    world_mask: torch.Tensor
    kinds: dict[str, list[int]] = field(default_factory=dict)

    @property
    def has_world(self) -> bool:
        """True when some joint x/z targets need the sampler's root estimate."""
        return bool(self.world_mask.any())

    def frames_of(self, kind: str) -> list[int]:
        return self.kinds.get(kind, [])

    def to(self, device=None, dtype: torch.dtype | None = None) -> ConstraintTargets:
        def cast(x, floating=True):
            return x.to(device=device, dtype=dtype if floating and dtype is not None else x.dtype)

        return ConstraintTargets(cast(self.x_tgt), cast(self.mask), cast(self.world_xz), cast(self.world_mask),
                                 dict(self.kinds))


class _State:
    """Targets being accumulated in float64: feature targets + pending world joint x/z."""

    def __init__(self, T: int, layout: FeatureLayout):
        J = layout.num_joints
        self.layout = layout
        self.x = torch.zeros(T, layout.dim, dtype=torch.float64)
        self.m = torch.zeros(T, layout.dim, dtype=torch.bool)
        self.wxz = torch.zeros(T, J, 2, dtype=torch.float64)
        self.wm = torch.zeros(T, J, dtype=torch.bool)
        self.kinds: dict[str, set[int]] = {}
        self.root_xz = layout.root_xz

    def put_rows(self, frames: Sequence[int], rows: torch.Tensor, mask: torch.Tensor) -> None:
        """Write feature rows ``(K, D)`` at ``frames`` on the channels of ``mask (T, D)`` (later wins)."""
        full = torch.zeros_like(self.x)
        full[list(frames)] = rows
        mask = mask.bool()
        self.x = torch.where(mask, full, self.x)
        self.m |= mask

    def put(self, frames: Sequence[int], channels: Sequence[int], values: torch.Tensor) -> None:
        """Write ``values (K, C)`` on ``channels`` at ``frames``."""
        f = torch.as_tensor(list(frames), dtype=torch.long)[:, None]
        ch = torch.as_tensor(list(channels), dtype=torch.long)[None, :]
        self.x[f, ch] = values.to(self.x)
        self.m[f, ch] = True

    def put_world(self, frames: Sequence[int], joints: Sequence[int], xz: torch.Tensor) -> None:
        """World joint x/z ``(K, n, 2)`` of ``joints`` at ``frames`` (resolved in `finish`)."""
        f = torch.as_tensor(list(frames), dtype=torch.long)[:, None]
        j = torch.as_tensor(list(joints), dtype=torch.long)[None, :]
        self.wxz[f, j] = xz.to(self.wxz)
        self.wm[f, j] = True

    def touch(self, kind: str, frames) -> None:
        self.kinds.setdefault(kind, set()).update(int(f) for f in frames)

    def finish(self, dtype: torch.dtype) -> ConstraintTargets:
        """Turn world joint x/z into relative features where the root x/z is known."""
        known = self.m[:, self.root_xz].all(-1)[:, None] & self.wm  # (T, J)
        for axis, c in ((0, 0), (1, 2)):
            ch = self.layout.joint_axis("joint_pos", c)  # (J,)
            rel = self.wxz[..., axis] - self.x[:, self.root_xz[axis]][:, None]
            self.x[:, ch] = torch.where(known, rel, self.x[:, ch])
            self.m[:, ch] |= known
        wm = self.wm & ~known
        wxz = torch.where(wm[..., None], self.wxz, torch.zeros_like(self.wxz))
        return ConstraintTargets(self.x.to(dtype), self.m.to(dtype), wxz.to(dtype), wm.to(dtype),
                                 {k: sorted(v) for k, v in self.kinds.items()})


# ---------------------------------------------------------------------------- per type
def _fullbody(c: FullBodyConstraint, frames: list[int], st: _State, skeleton: Skeleton) -> None:
    layout, T = st.layout, st.x.shape[0]
    pelvis = skeleton.require_roles(["pelvis"])["pelvis"]
    G, P = forward_kinematics(axis_angle_to_quat(c.local_rotations), c.root_positions, skeleton.offsets,
                              skeleton.parents)
    root = P[:, pelvis].clone()
    if c.smooth_root_2d is not None:
        root[:, [0, 2]] = c.smooth_root_2d
    rows = torch.zeros(len(frames), layout.dim, dtype=torch.float64)
    parts = layout.split(rows)  # views into rows
    parts["root_pos"][:] = root
    parts["heading"][:] = heading_from_positions(P, skeleton)
    parts["joint_pos"][..., 1] = P[..., 1]
    parts["joint_rot"][:] = quat_to_sixd(G)
    mask = fullbody_mask(T, frames, layout).bool()
    J = layout.num_joints
    xz = layout.joint_channels("joint_pos", coords=[0, 2])
    mask[:, xz] = False  # joint x/z go through the world store, resolved against the final root
    st.put_rows(frames, rows, mask)
    st.put_world(frames, range(J), P[..., [0, 2]])
    st.touch("fullbody", frames)


def _end_effector(c: EndEffectorConstraint, frames: list[int], st: _State, skeleton: Skeleton) -> None:
    j = resolve_joint(skeleton, c.joint)
    if c.smooth_root_2d is not None:
        st.put(frames, st.root_xz, c.smooth_root_2d)
    if c.positions is not None:
        st.put(frames, st.layout.joint_channels("joint_pos", [j], [1]), c.positions[:, 1:2])
        st.put_world(frames, [j], c.positions[:, None, [0, 2]])
    if c.rotations is not None:
        st.put(frames, st.layout.joint_channels("joint_rot", [j]), quat_to_sixd(axis_angle_to_quat(c.rotations)))
    st.touch(f"end-effector:{skeleton.names[j]}", frames)


def _dense_path(c: Root2DConstraint, frames: list[int]) -> tuple[list[int], torch.Tensor, torch.Tensor | None]:
    """Keyframes -> every frame of [first, last] with linearly interpolated positions and headings."""
    full = np.arange(frames[0], frames[-1] + 1)
    key = np.asarray(frames, dtype=np.float64)
    pos = np.stack([np.interp(full, key, c.positions[:, k].numpy()) for k in range(2)], axis=-1)
    heading = None
    if c.heading is not None:
        angle = np.unwrap(np.arctan2(c.heading[:, 1].numpy(), c.heading[:, 0].numpy()))
        a = np.interp(full, key, angle)
        heading = torch.from_numpy(np.stack([np.cos(a), np.sin(a)], axis=-1))
    return full.tolist(), torch.from_numpy(pos), heading


def _root2d(c: Root2DConstraint, frames: list[int], st: _State, skeleton: Skeleton) -> None:
    layout, T = st.layout, st.x.shape[0]
    if c.dense:
        frames, pos, heading = _dense_path(c, frames)
        mask = root_path_mask(T, frames[0], frames[-1] + 1, layout, heading=heading is not None)
    else:
        pos = c.positions
        heading = None if c.heading is None else c.heading / c.heading.norm(dim=-1, keepdim=True)
        mask = root2d_mask(T, frames, layout, heading=heading is not None)
    rows = torch.zeros(len(frames), layout.dim, dtype=torch.float64)
    rows[:, st.root_xz] = pos.to(rows)
    if heading is not None:
        rows[:, layout.slices["heading"]] = heading.to(rows)
    st.put_rows(frames, rows, mask)
    st.touch("root2d:dense" if c.dense else "root2d", frames)


def _foot_contact(c: FootContactConstraint, frames: list[int], st: _State, skeleton: Skeleton) -> None:
    layout, T = st.layout, st.x.shape[0]
    rows = torch.zeros(len(frames), layout.dim, dtype=torch.float64)
    rows[:, layout.slices["contacts"]] = c.contacts
    st.put_rows(frames, rows, contacts_mask(T, frames, layout))
    st.touch("foot-contact", frames)


_ENCODERS = {FullBodyConstraint: _fullbody, EndEffectorConstraint: _end_effector, Root2DConstraint: _root2d,
             FootContactConstraint: _foot_contact}


# ---------------------------------------------------------------------------- public API
def encode_constraints(constraints: Sequence[Constraint], skeleton: Skeleton, layout: FeatureLayout, fps: float,
                       num_frames: int, dtype: torch.dtype = torch.float32) -> ConstraintTargets:
    """Targets ``(T = num_frames, D = layout.dim)`` for ``constraints`` (validated first; errors name
    the constraint index and field). See the module docstring for the channel mapping."""
    if layout.num_joints != skeleton.num_joints:
        raise KinemaError(f"feature layout has {layout.num_joints} joints, skeleton {skeleton.num_joints}")
    st = _State(int(num_frames), layout)
    for i, c in enumerate(constraints):
        encoder = _ENCODERS.get(type(c))
        if encoder is None:
            raise ConstraintError(f"not a constraint object: {type(c).__name__}", index=i)
        try:
            frames = c.check(skeleton, fps, num_frames)
            encoder(c, frames, st, skeleton)
        except ConstraintError as err:
            raise err.at(index=i, kind=c.kind) from None
        except KinemaError as err:  # e.g. a skeleton without the roles features need
            raise ConstraintError(str(err), index=i, kind=c.kind) from None
    return st.finish(dtype)


def world_to_relative(targets: ConstraintTargets, root_xz: torch.Tensor,
                      layout: FeatureLayout) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-step targets for a sampler: ``(x_tgt, mask)`` ``(..., T, D)`` with the world joint x/z of
    ``targets`` made relative to ``root_xz (..., T, 2)`` (the current clean estimate's root_pos x/z,
    unnormalised) and masked; other channels are ``targets.x_tgt``/``targets.mask``. Call it at every
    denoising step, after imputing the constrained root channels into the estimate."""
    x = targets.x_tgt.to(root_xz).expand(*root_xz.shape[:-1], layout.dim).clone()
    m = targets.mask.to(root_xz).expand_as(x).clone()
    if not targets.has_world:
        return x, m
    wm = targets.world_mask.to(root_xz).bool()  # (T, J)
    for axis, c in ((0, 0), (1, 2)):
        ch = layout.joint_axis("joint_pos", c, device=x.device)
        rel = targets.world_xz[..., axis].to(root_xz) - root_xz[..., axis:axis + 1]  # (..., T, J)
        x[..., ch] = torch.where(wm, rel, x[..., ch])
        m[..., ch] = torch.where(wm, torch.ones_like(rel), m[..., ch])
    return x, m
